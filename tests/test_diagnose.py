"""Close the loop (issue 6): simulated logs with known effects, clean logs, an effect outside the
catalogue, too few poses, and what the loop finds on the real logs.

Tolerances: "within 1.5x of the floor" is the issue's acceptance; coefficient recovery is
checked within 5 standard errors (Tol.N_SIGMA). All simulated accelerometer logs have 60
poses (one compile of the vmapped fit for every test), magnetometer logs 6,000 samples.
"""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from calib_jax.cli import main
from calib_jax.datasets import accel_tumble_log_path, demo_log_path, qmc_log_path
from calib_jax.diagnose import allan_deviation, diagnose_accel, diagnose_mag
from calib_jax.diagnose import model as M
from calib_jax.io.files import load_log
from calib_jax.simulate import simulate_accel_log, simulate_mag_log

from .conftest import Tol


def run_accel(effects, seed=1, **kw):
    s = simulate_accel_log(effects, seed=seed, **kw)
    return s, diagnose_accel(s.raw, t=s.t, temp=s.temp, intervals=s.intervals)


def run_mag(effects, seed=1, model="full"):
    s = simulate_mag_log(effects, seed=seed)
    return s, diagnose_mag(s.raw, t=s.t, temp=s.temp, sample_rate=s.sample_rate, model=model)


def test_residual_jacobian_is_exact():
    """jacfwd of the residual with every effect free against central differences (FD_ABS)."""
    rng = np.random.default_rng(0)
    x = rng.normal(size=(12, 3))
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    tau, T = rng.uniform(-0.5, 0.5, 12), rng.uniform(-0.5, 0.5, 12)
    free = np.ones(M.N_THETA, bool)
    theta = np.zeros(M.N_THETA)
    theta[:3] = 1.0
    theta[3:] = 0.01 * rng.normal(size=M.N_THETA - 3)
    data = tuple(jnp.asarray(a) for a in (x, tau, T, np.ones(12), free))
    J = np.asarray(jax.jacfwd(M.residual)(jnp.asarray(theta), data))
    h = 1e-6
    fd = np.stack(
        [
            (
                np.asarray(M.residual(jnp.asarray(theta + h * e), data))
                - np.asarray(M.residual(jnp.asarray(theta - h * e), data))
            )
            / (2 * h)
            for e in np.eye(M.N_THETA)
        ],
        axis=1,
    )
    np.testing.assert_allclose(J, fd, atol=Tol.FD_ABS)


def _slow_vector_noise(rng, shape, phi, s2):
    """Stationary AR(1) along axis 1 (per column of the last axis), variance s2."""
    from scipy.signal import lfilter

    innov = rng.normal(size=shape) * np.sqrt(s2 * (1 - phi**2))
    start = rng.normal(size=(shape[0], 1, shape[2])) * np.sqrt(s2)
    steps = phi ** np.arange(shape[1])[None, :, None]
    return lfilter([1.0], [1.0, -phi], innov, axis=1) + start * steps


def _turning(m, turns=1.5):
    a = 2 * np.pi * turns * np.arange(m) / m
    u = np.column_stack([np.cos(a), np.sin(a), 0.5 * np.ones(m)])
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def test_sandwich_covariance_under_slow_vector_noise_against_monte_carlo():
    """honest.sandwich_cov: least-squares coefficients of a regression on a turning board,
    noise e = u . n + v with n a slow vector (AR(1), phi 0.97, variance 1 per axis) and v
    white (0.25). Over 3,000 draws each coefficient's variance is estimated to about 2.6 %
    (sqrt(2 / 3000)), so 10 % is 4 of those; the formal covariance (independent samples) is
    30-40x too small here, which is what the test is for."""
    from calib_jax.diagnose.honest import SlowNoise, sandwich_cov

    rng = np.random.default_rng(0)
    m, phi, s2, w2 = 600, 0.97, 1.0, 0.25
    t = np.arange(m) / m - 0.5
    u = _turning(m)
    J = np.column_stack([np.ones(m), t, u[:, 0] * t, u[:, 1]])
    n = _slow_vector_noise(rng, (3000, m, 3), phi, s2)
    e = np.einsum("dmk,mk->dm", n, u) + np.sqrt(w2) * rng.normal(size=(3000, m))
    coef = np.linalg.lstsq(J, e.T, rcond=None)[0].T
    empirical = np.diag(np.cov(coef.T))
    np.testing.assert_allclose(
        np.diag(sandwich_cov(J, u, SlowNoise(s2, phi, w2))), empirical, rtol=0.1
    )
    assert np.all(np.diag((s2 + w2) * np.linalg.inv(J.T @ J)) < 0.1 * empirical)


def test_slow_noise_is_recovered_and_white_noise_has_none():
    """honest.slow_noise on 20,000 samples of the noise above (about 600 independent
    stretches: s2 to about 6 %, 1 - phi to about 10 %; bounds twice that) and on white noise,
    where the slow part must be under 1 % of the variance."""
    from calib_jax.diagnose.honest import slow_noise

    rng = np.random.default_rng(1)
    m = 20_000
    u = _turning(m, turns=50)
    e = np.sum(_slow_vector_noise(rng, (1, m, 3), 0.97, 1.0)[0] * u, axis=1)
    est = slow_noise(e + 0.5 * rng.normal(size=m), u, longest=300)
    assert est.s2 == pytest.approx(1.0, rel=0.12) and est.w2 == pytest.approx(0.25, rel=0.12)
    assert 1 - est.phi == pytest.approx(0.03, rel=0.2)
    white = slow_noise(rng.normal(size=2000), u[:2000], longest=125)
    assert white.s2 < 0.01 * white.w2


def test_allan_deviation_of_white_noise():
    """White noise: sigma_A(n) = sigma / sqrt(n). 200,000 samples estimate it to ~1 % at n = 10
    (about 20,000 independent differences), so 5 % is a loose bound."""
    y = np.random.default_rng(0).normal(size=200_000)
    for n in (1, 10, 100):
        assert allan_deviation(y, n) == pytest.approx(1 / np.sqrt(n), rel=0.05)
    assert np.isnan(allan_deviation(y[:10], 6))


@pytest.mark.parametrize(
    "effect",
    ["bias_drift", "temperature_bias", "temperature_scale", "scale_nonlinearity", "outliers"],
)
def test_accel_effect_is_found_and_brings_the_residual_to_the_floor(effect):
    s, d = run_accel((effect,))
    assert d.effects == [effect], d.rounds
    assert d.rms_before > 2 * d.noise_floor  # the effect was visible
    assert d.rms_after <= 1.5 * d.noise_floor, d.summary()
    assert not d.unexplained_structure
    assert [st["added_effect"] for st in d.steps] == [None, effect]
    # the summary says how large it is, as the JSON does (a trial found sizes only there)
    lines = d.summary().splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.lstrip().startswith(effect))
    if effect == "outliers":
        assert lines[i + 1].startswith(f"    rejected {d.steps[1]['n_rejected']} observations")
    else:
        slot, c = next(iter(d.steps[1]["coefficients"].items()))
        assert lines[i + 1].startswith(f"    {slot}: {1e3 * c['value'][0]:+.3g} +- ")
        assert lines[i + 1].endswith(f" mg ({c['meaning']})"), lines[i + 1]
    # "before" and "after" are the steps table's first and last rows (issue 14 defect: before
    # was the base fit on the observations left after rejecting outliers)
    assert (d.rms_before, d.rms_after) == (d.steps[0]["rms"], d.steps[-1]["rms"])
    if effect == "scale_nonlinearity":
        # q recovered: the simulator reads y = a + size * (0.6, -1, 0.8) a^2; the model corrects
        # a = y - q y^2 in normalised units (gains ~ 1 +- 5 %), so q ~ size * (0.6, -1, 0.8)
        q = np.asarray(d.steps[-1]["coefficients"]["quadratic"]["value"])
        se = np.asarray(d.steps[-1]["coefficients"]["quadratic"]["stderr"])
        truth = s.effect_size * np.array([0.6, -1.0, 0.8])
        assert np.all(np.abs(q - truth) < Tol.N_SIGMA * se + 0.05 * np.abs(truth)), (q, truth)
    if effect == "outliers":
        assert {r["index"] for r in d.rejected} == set(s.disturbed)


@pytest.mark.parametrize(
    "effect, model",
    [("soft_iron", "sphere"), ("hard_iron_drift", "full"), ("temperature_bias", "full")],
)
def test_mag_effect_is_found(effect, model):
    _, d = run_mag((effect,), model=model)
    assert d.effects == [effect], d.rounds
    assert d.rms_after <= 1.5 * d.noise_floor, d.summary()
    assert not d.unexplained_structure


@pytest.mark.parametrize("size, seed", [(0.12, 0), (0.0, 1), (0.0, 0), (0.0, 13)])
def test_mag_drift_with_correlated_noise_judged_honestly(size, seed):
    """Issue 15 for the magnetometer loop: sample noise correlated over ~2 s (AR(1), 0.99 at
    50 Hz, 0.5 % of the field) on a 40 s log. Formal errors are ~10x too small here: the
    drift's halves differ by z 3.9 in them. With a hard-iron drift of 0.12 of the field over
    the log (seed 0) the drift passes every test: the halves agree in honest errors (their
    own times the jackknife's correlation factor: z 0.4), Hotelling's p is 1e-4 and the
    slow-noise Wald test's 0.0017 (honest.sandwich_cov), both under the 0.0025 that four
    candidates leave each (honest.HONEST_ALPHA); the coefficients lie within 4 honest
    standard errors (+5 % for the field's scale k0 ~ 1 +- 0.05) of the truth. 0.1 of the field
    is refused by the slow-noise test (p 0.0026): its noise is estimated from the residual
    without the drift, which holds the drift too (conservative, as a score test is).
    Without the drift nothing is added: seed 0's clean log was a false alarm while each
    candidate had 0.01 (temperature bias, p 0.008, held-out gain 25 %: the noise has power at
    the temperature swing's frequency), seed 13's while Hotelling's test judged alone
    (temperature bias, p 1e-4; slow-noise p 0.003). The rates are measured in
    benchmarks/diagnosis_power.py."""
    from calib_jax.simulate import _EFFECT_DIRS, correlated_noise, simulate_mag_log

    s = simulate_mag_log(
        ("hard_iron_drift",), size=size, samples=2000, rest=500, rate=50.0, seed=seed, noise=0.0
    )
    raw = s.raw + correlated_noise(2000, 5e-3, 0.99, rng=seed + 2000)
    d = diagnose_mag(raw, t=s.t, temp=s.temp, sample_rate=50.0, progress=False)
    if size == 0:
        # no structure either: the driver tests assumed independent samples and found time,
        # temperature and orientation at p < 1e-30 in every such log (now prewhitened by the
        # residual's lag-1 correlation, loop.regress_drivers)
        assert d.effects == [] and d.verdict != "unexplained_structure", d.summary()
        return
    assert d.effects == ["hard_iron_drift"], d.rounds
    e = next(x for x in d.rounds[0] if x["effect"] == "hard_iron_drift")
    assert e["halves_max_z"] < 3 < e["halves_max_z_formal"] and e["p_honest"] < 0.01
    c = d.steps[1]["coefficients"]["drift1"]
    assert f"    drift1: {100 * c['value'][0]:+.3g} +- " in d.summary()  # in % of the field
    truth = size * _EFFECT_DIRS
    miss = np.abs(np.asarray(c["value"]) - truth)
    assert np.all(miss < 4 * np.asarray(c["stderr"]) + 0.05 * np.abs(truth)), (c, truth)


def test_a_real_drift_is_not_refused_by_halves_that_cannot_fit_the_ellipsoid():
    """The split halves are the jackknife's even and odd stretches (loop.BLOCKS), not
    alternate eighths. benchmarks/diagnosis_power.py's log of seed 17 (a hard-iron drift of
    0.036 of the field over 40 s, 1.4x the floor, white noise 0.5 % of the field): the drift
    passed every test (Hotelling p 4e-9, held-out error 29 % lower) but the halves, each of
    which refitted the full ellipsoid and the drift from 15 s of the tumble, fell 3.1x the
    effect apart (z 10.3 in their inflated errors), so the verdict was 'unexplained
    structure'. The optimal test finds such a drift in every log (benchmarks/oracle_power.py:
    non-centrality ~750). Now the halves agree (z under 3) and the drift is found, within 4
    honest standard errors (+5 % for the field's scale) of the truth."""
    from calib_jax.simulate import _EFFECT_DIRS

    size = 0.0362
    s = simulate_mag_log(
        ("hard_iron_drift",), size=size, samples=2000, rest=500, rate=50.0, seed=17, noise=0.0
    )
    raw = s.raw + 5e-3 * np.random.default_rng(17 + 3000).normal(size=s.raw.shape)
    d = diagnose_mag(raw, t=s.t, temp=s.temp, sample_rate=50.0, model="full", progress=False)
    assert d.effects == ["hard_iron_drift"], d.summary()
    e = next(x for x in d.rounds[0] if x["effect"] == "hard_iron_drift")
    assert e["halves_max_z"] < 3 and e["p_honest"] < 1e-6, e
    c = d.steps[1]["coefficients"]["drift1"]
    truth = size * _EFFECT_DIRS
    miss = np.abs(np.asarray(c["value"]) - truth)
    assert np.all(miss < 4 * np.asarray(c["stderr"]) + 0.05 * np.abs(truth)), (c, truth)


def test_soft_iron_is_judged_against_a_sphere_not_against_zero_gains():
    """Soft iron's coefficients in the honest tests are gains 2 and 3 less gain 1 and the
    cross terms: a sphere has none. They were the gains themselves (about 1), so Hotelling's
    test rejected 'no soft iron' at p ~ 1e-25 on every clean spherical board and the halves
    always agreed within a quarter of the 'effect'. A clean sphere with noise correlated over
    ~2 s (benchmarks/diagnosis_power.py's clean mag log, seed 2: p was 1.2e-25, now 0.62)."""
    from calib_jax.simulate import alpha_beta, correlated_noise

    s = simulate_mag_log((), size=0.0, samples=2000, rest=500, rate=50.0, seed=2, noise=0.0)
    alpha, b = alpha_beta(s.params)
    raw = (s.raw - b) @ np.linalg.inv(alpha).T + b  # the board made a sphere
    raw = raw + correlated_noise(len(raw), 5e-3, 0.99, rng=2002)
    d = diagnose_mag(raw, t=s.t, temp=s.temp, sample_rate=50.0, model="sphere", progress=False)
    e = next(x for x in d.rounds[0] if x["effect"] == "soft_iron")
    assert e["p_honest"] > 0.05 and not e["tests"]["honest"], e
    assert "soft_iron" not in d.effects


@pytest.mark.parametrize(
    "effect, size, model", [("hard_iron_drift", 0.11, "full"), ("soft_iron", 0.04, "sphere")]
)
def test_large_magnetometer_effects_are_plausible(effect, size, model):
    """The magnetometer's plausibility bounds are its own (loop.BOUNDS): with the
    accelerometer's, a hard-iron drift of 0.11 of the field over the log (3x the floor in
    benchmarks/diagnosis_power.py) was 'coefficient 0.111 beyond 0.1', and soft iron of 12 %
    on a board declared a sphere (10x) 'moves the base bias by 0.088 (bound 0.05)': the sphere's
    centre is off by that much, which freeing the shape corrects. Both were rejected in every
    simulated log and the verdict was unexplained structure. Now found, and the residual falls
    to the floor (within 1.5x)."""
    s = simulate_mag_log((effect,), size=size, samples=2000, rest=500, rate=50.0, seed=1)
    if model == "sphere":  # the power study's spherical board, with the soft iron asked for
        from calib_jax.simulate import alpha_beta

        alpha, b = alpha_beta(s.params)
        s0 = simulate_mag_log((), samples=2000, rest=500, rate=50.0, seed=1, noise=0.0)
        v = (s0.raw - b) @ np.linalg.inv(alpha).T
        raw = v * (1.0 + size * np.array([3.0, -2.0, 1.0])) + b
        raw = raw + 5e-3 * np.random.default_rng(3001).normal(size=raw.shape)
    else:
        raw = s.raw
    d = diagnose_mag(raw, t=s.t, temp=s.temp, sample_rate=50.0, model=model, progress=False)
    assert d.effects == [effect], d.rounds
    assert d.rms_after <= 1.5 * d.noise_floor, d.summary()


def test_two_effects_at_once():
    _, d = run_accel(("bias_drift", "scale_nonlinearity"))
    assert sorted(d.effects) == ["bias_drift", "scale_nonlinearity"]
    assert d.rms_after <= 1.5 * d.noise_floor
    assert "scale_nonlinearity" in d.groups  # reported as a group, not a confident pick


def test_clean_logs_add_nothing():
    """The issue: over at least 20 seeds at most one false addition."""
    false = []
    for seed in range(100, 120):
        _, d = run_accel((), seed=seed)
        if d.effects or d.unexplained_structure:
            false.append((seed, d.effects, d.unexplained_structure))
        assert d.verdict in ("at_floor", "effects_added", "unexplained_structure")
    assert len(false) <= 1, false


def test_effect_outside_the_catalogue_is_reported_unexplained():
    """A bias that oscillates 3 times over the log: no catalogue effect fits it; the residual
    must be flagged, naming time as the driver."""
    _, d = run_accel(("periodic_bias",))
    assert d.unexplained_structure
    assert d.verdict == "unexplained_structure"
    drivers = [s["driver"] for s in d.structure if s["above_floor"]]
    assert "time" in drivers
    assert any("time" in n for n in d.notes)


def test_an_effect_too_large_for_the_sensor_is_named_not_hidden():
    """A bias drift of 0.25 g over the log explains the residual (BIC and the null test pass)
    but exceeds the plausibility bound (0.1 of g over the log), so it is not accepted. The
    notes used to say "no catalogue effect explains it"; they must name the effect, what it
    would do to the rms, why it is refused and where else to look."""
    _, d = run_accel(("bias_drift",), size=0.25)
    assert d.verdict == "unexplained_structure" and d.effects == []
    assert not any("no catalogue effect explains it" in n for n in d.notes), d.notes
    [note] = [n for n in d.notes if n.startswith("bias_drift would take the rms")]
    assert "beyond 0.1" in note and "relative to g" in note and "cause outside the sensor" in note
    assert not any("pauses in a motion" in n for n in d.notes), d.notes  # the drift explains it


def test_too_few_poses_is_its_own_verdict():
    _, d = run_accel((), poses=10)
    assert d.verdict == "not_possible"
    assert "10 static intervals for 9 parameters" in d.notes[0]
    # what to record, and that calib-jax accel fits the log as it is (a new user's MPU-9150
    # log of 22 poses was refused with the count alone)
    assert "record 20 or more further poses" in d.notes[0] and "calib-jax accel" in d.notes[0]
    assert d.to_dict()["steps"] == []


def test_one_sample_per_observation_has_no_floor_and_no_verdict(tmp_path):
    """A pose table (here the Xsens interval means written one per row) or --block 1 leaves
    nothing to measure a noise floor with; the diagnosis said at_floor / effects_added against
    a NaN floor. It must be not_possible, and the CLI exit 2 naming the reason."""
    log = load_log(demo_log_path())
    d = diagnose_accel(log, block=1)
    assert d.verdict == "not_possible" and "noise floor cannot be measured" in d.notes[0]
    from calib_jax.static import detect_static

    means = detect_static(log.acc, sample_rate=log.sample_rate).means()
    table = tmp_path / "poses.txt"
    np.savetxt(table, means)
    assert main(["diagnose", str(table)]) == 2


# ----------------------------------------------------------------------------- real logs


def test_xsens_is_at_the_floor_with_nine_parameters(capsys):
    """imu_tk Xsens (38 poses): the issue's analysis found white 0.034 mg, Allan 0.12 mg,
    residual 0.10 mg and nothing to add. Here: white 0.031, Allan 0.098, residual 0.100 (the
    static detector's intervals differ slightly from that analysis; 25 % bounds).
    The progress bar (forced on) counts the one round that found nothing and then reads
    complete, 1/1, not 1 of the 6 rounds allowed."""
    d = diagnose_accel(load_log(demo_log_path(), columns="t,ax,ay,az"), progress=True)
    bar = capsys.readouterr().err
    assert "diagnosing accel" in bar and "1/1" in bar and "null fits each" in bar, bar
    assert len(d.rounds) == 1
    assert d.effects == []
    assert d.verdict == "at_floor"
    assert d.n_observations == 38
    assert d.noise_floor_white == pytest.approx(0.034e-3, rel=0.25)
    assert d.noise_floor_allan == pytest.approx(0.12e-3, rel=0.25)
    assert d.rms_after == pytest.approx(0.10e-3, rel=0.1)
    # Issue 14: the base model is calibrate_accel's fit of the same interval means, with the
    # diagnosis's residual det(alpha)^(1/3) (|y| - 1) (so that effects compose with one
    # residual for both sensors) instead of 1 - |a|^2 / g^2: the two differ at second order in
    # the residuals, measured 9e-4 standard errors on this log; bound 1e-2
    from calib_jax import calibrate_accel
    from calib_jax.diagnose.model import SLOTS
    from calib_jax.models.accel import alpha_matrix

    cal = calibrate_accel(load_log(demo_log_path(), columns="t,ax,ay,az"))
    # y = A^-1 ((x - c0) / k0 - b) with |y| = 1 is x = (k0 A / g) a + c0 + k0 b with |a| = g
    th, o = d.theta_base, d.obs
    A = np.asarray(alpha_matrix(np.r_[th[SLOTS["gains"]], th[SLOTS["cross"]], np.zeros(3)]))
    alpha = o.k0 * A / cal.g
    beta = o.c0 + o.k0 * th[SLOTS["bias"]]
    p = np.r_[np.diag(alpha), alpha[0, 1], alpha[0, 2], alpha[1, 2], beta]
    z = (p - cal.params) / cal.stderr
    assert np.abs(z).max() < 1e-2, z


def test_diagnosis_record_round_trips(tmp_path):
    """Issue 14: a diagnosis is a record like the calibrations: kind, format_version, save,
    load, ==; a calibration loader refuses it by its kind, and it refuses a calibration."""
    from calib_jax import AccelCalibration
    from calib_jax.diagnose import Diagnosis

    log = load_log(demo_log_path(), columns="t,ax,ay,az")
    d = diagnose_accel(log)
    path = tmp_path / "diagnosis.json"
    d.save(path)
    back = Diagnosis.load(path)
    assert back == d and back.to_dict()["kind"] == "diagnosis"
    assert back.verdict == d.verdict and back.rms_after == d.rms_after
    with pytest.raises(ValueError, match="kind is 'diagnosis'"):
        AccelCalibration.load(path)
    from calib_jax import calibrate_accel

    cal = tmp_path / "cal.json"
    calibrate_accel(log).save(cal)
    with pytest.raises(ValueError, match="not a diagnosis"):
        Diagnosis.load(cal)


def test_ckexplorer_scale_asymmetry(tmp_path):
    """CK-Explorer tumble, 160 poses of 100 samples. The issue's analysis: a +g/-g asymmetry of
    about +4 mg on y and -3 mg on z, residual about 1.04 -> 0.75 mg. Found here: the same sizes
    with the opposite sign, because calib_jax reports the asymmetry of the READING
    ((|y(+g)| - |y(-g)|) / 2 = q, -3.9 mg on y, +3.2 mg on z) and the issue's numbers are the
    correction coefficient (a = y + c y^2, c = -q). Through the CLI."""
    out = tmp_path / "ck.json"
    rep = tmp_path / "report"
    rc = main(
        ["diagnose", str(accel_tumble_log_path()), "--block", "100", "--json", str(out),
         "--report", str(rep)]
    )  # fmt: skip
    assert rc == 0
    d = json.loads(out.read_text())
    assert d["effects"] == ["scale_nonlinearity"]
    assert d["rms_before"] == pytest.approx(1.04e-3, rel=0.05)
    assert d["rms_after"] == pytest.approx(0.75e-3, rel=0.05)
    asym = np.array(d["steps"][-1]["coefficients"]["scale_asymmetry"]["value"])
    se = np.array(d["steps"][-1]["coefficients"]["scale_asymmetry"]["stderr"])
    assert asym[1] == pytest.approx(-4e-3, abs=3 * se[1])
    assert asym[2] == pytest.approx(3e-3, abs=3 * se[2])
    assert abs(asym[0]) < 3 * se[0] + 1e-3
    assert [s["model"] for s in d["steps"]][0] == "base"
    for k in ("model", "added_effect", "n_params", "rms", "bic", "loo_rms"):
        assert k in d["steps"][0]
    for k in ("noise_floor", "noise_floor_white", "noise_floor_allan", "unexplained_structure"):
        assert k in d
    assert sorted(p.name for p in rep.iterdir()) == [
        "model_comparison.png",
        "residual_motion.png",
        "residual_sphere.png",
        "residual_time.png",
    ]


def test_qmc_filtered_time_structure_and_noisy_null():
    """QMC5883L. Filtered log: the issue's analysis saw a hard-iron drift of 1.7-2.7 % of the
    field over 455 s. Here a linear centre drift passes BIC (gain ~124), the held-out blocks
    (gain ~1.3 %), the null test and plausibility; the halves agree once judged with honest
    errors (formal z ~ 4.3, block-jackknife z ~ 1.2), but the drift is not significant with
    them (Hotelling p ~ 0.02 against 0.01: the filtered samples are correlated over seconds),
    and the residual keeps a time structure of about 1.2 % of the field (p ~ 1e-130): the loop
    reports that structure as unexplained instead of a confident drift. Noisy log: the
    polynomial terms that BIC alone would take are rejected (null test or plausibility) and
    nothing is added."""
    filt = diagnose_mag(load_log(qmc_log_path("filtered")))
    drift = [e for e in filt.rounds[0] if e["effect"] == "hard_iron_drift"][0]
    assert drift["tests"]["bic"] and drift["tests"]["null"] and drift["tests"]["held_out"]
    assert drift["halves_max_z"] < 3 < drift["halves_max_z_formal"]
    assert not drift["tests"]["honest"] and not drift["accepted"]
    assert filt.unexplained_structure
    time_ = [s for s in filt.structure if s["driver"] == "time"][0]
    assert time_["above_floor"] and 0.005 < time_["size"] < 0.03
    noisy = diagnose_mag(load_log(qmc_log_path("noisy")))
    assert "scale_nonlinearity" not in noisy.effects
    assert "hard_iron_drift" not in noisy.effects
    nl = [e for e in noisy.rounds[0] if e["effect"] == "scale_nonlinearity"][0]
    assert nl["tests"]["bic"] and not nl["accepted"]  # BIC alone would have taken it


# ----------------------------------------------------------------------------- MARG


def _marg_log(
    rot_deg=0.0, perm=False, shift=0, seed=0, n=6000, hand_g=0.0, noise=None, knots=30,
    hand_corr=0.99,
):  # fmt: skip
    """Tumble at 100 Hz; the magnetometer rotated by rot_deg (and axis-swapped with perm)
    against the accelerometer, and ``shift`` samples ahead of it in time. ``hand_g``: the
    hand's acceleration (g, AR(1) with lag-1 correlation ``hand_corr``, 0.99: about 1 s) in the
    accelerometer, so the angle errors are correlated over many samples. ``noise``: (g, uT)
    white sample noise of the accelerometer and the magnetometer, the simulator's default if
    None. ``knots``: the tumble's turns (fewer: slower)."""
    from calib_jax.rotations import rotvec_to_dcm
    from calib_jax.simulate import correlated_noise, simulate_marg, tumble_quaternions

    q = tumble_quaternions(n + 50, rng=seed, knots=knots)
    R = np.asarray(rotvec_to_dcm(jnp.asarray(np.radians(rot_deg) * np.array([0.6, -0.5, 0.62]))))
    if perm:
        R = R @ np.array([[0, 1, 0], [1, 0, 0], [0, 0, -1.0]])
    kw = dict(center=np.array([10.0, -5, 3]), soft_iron=np.diag([1.1, 0.95, 1.0]), R_mag_board=R)
    if noise:
        kw.update(acc_noise=noise[0], mag_noise=noise[1])
    hand = correlated_noise(n, hand_g, hand_corr, rng=seed + 100) if hand_g else None
    s1 = simulate_marg(q[:n], rng=seed, linear_acc=hand, **kw)
    s2 = simulate_marg(q[shift : shift + n], rng=seed + 1, **kw)
    return s1.acc, s2.mag


@pytest.mark.parametrize(
    "kw, effect",
    [
        ({}, None),
        ({"rot_deg": 3.0}, "sensor_misalignment"),
        ({"rot_deg": 2.0, "perm": True}, "sensor_misalignment"),
        ({"shift": 5}, "timing_offset"),
    ],
)
def test_marg_misalignment_and_timing(kw, effect):
    """Known rotation (recovered to 0.1 deg: the angle noise is 0.28 deg per sample over 3,000
    samples) and a 5-sample (0.05 s) lead of the magnetometer (recovered to 5 ms)."""
    from calib_jax.diagnose import diagnose_marg

    acc, mag = _marg_log(**kw)
    d = diagnose_marg(acc, mag, sample_rate=100.0, progress=False)
    if kw.get("perm"):  # issue 15: the swapped axes are a finding, reported first, in words
        assert d.effects == ["axis_permutation", effect], d.rounds
        assert d.findings and "x <- +y, y <- +x, z <- -z" in d.findings[0]
        assert d.summary().splitlines()[1].startswith("  FOUND: the magnetometer's axes")
    else:
        assert d.effects == ([effect] if effect else []), d.rounds
        assert d.findings == []
    assert d.rms_after <= 1.5 * d.noise_floor, d.summary()
    if effect == "sensor_misalignment":
        rot = [e for e in d.rounds[0] if e["effect"] == effect][0]
        assert rot["rotation_deg"] == pytest.approx(kw["rot_deg"], abs=0.1)
        assert rot["permutation"] == ("x <- +y, y <- +x, z <- -z" if kw.get("perm") else
                                      "x <- +x, y <- +y, z <- +z")  # fmt: skip
    if effect == "timing_offset":
        assert d.steps[-1]["coefficients"]["dt_s"] == pytest.approx(-0.05, abs=5e-3)


@pytest.mark.parametrize("shift, noise", [(5, (6e-3, 0.6)), (1, (2e-3, 0.2))])
def test_marg_timing_found_through_noise_between_samples(shift, noise):
    """A 50 ms lead of the magnetometer with noisy samples (6 mg, 0.6 uT; 3,000 samples at
    100 Hz, as the power benchmark's "high" noise). Linear interpolation between noisy samples
    averages their noise, so the angle's error fell at every half-sample shift: the timing fit
    started at 0 stopped in the first such dip (dt -19 ms), its block refits scattered (honest
    error 12 ms, Hotelling p 0.17) and the offset was rejected. Over the magnetometer smoothed
    by marg.MAG_SMOOTHING it is accepted, within 2 ms of the truth (five seeds: 48-52 ms;
    an honest error of 0.2-0.4 ms, a fifth of the tolerance).

    A 10 ms lead at low noise (2 mg, 0.2 uT; both on the power benchmark's slower tumble of 16
    turns in 30 s) was fitted right and failed the null test: the
    null logs carried their errors in the magnetometer, whose interpolation averaged them
    (null gains 730-810 against the data's 300-400). With the errors in the accelerometer
    (marg._null_directions) the nulls gain under 30."""
    from calib_jax.diagnose import diagnose_marg

    acc, mag = _marg_log(shift=shift, n=3000, noise=noise, knots=16)
    d = diagnose_marg(acc, mag, sample_rate=100.0, progress=False)
    assert "timing_offset" in d.effects, d.rounds
    assert d.steps[-1]["coefficients"]["dt_s"] == pytest.approx(-shift / 100, abs=2e-3)


def test_marg_floors_are_those_of_the_rest_when_rows_are_missing():
    """Rows without a finite reading are left out before the floors are measured; the rest
    was found on the whole log but sliced from the finite rows, so 400 empty rows at the start
    moved the floor's window 400 samples (white floor 2.71e-3 instead of 2.89e-3 rad)."""
    from calib_jax.diagnose import diagnose_marg

    acc, mag = _marg_log(n=3000)
    pad = np.full((400, 3), np.nan)
    d0 = diagnose_marg(acc, mag, sample_rate=100.0, progress=False)
    d1 = diagnose_marg(
        np.vstack([pad, acc]), np.vstack([pad, mag]), sample_rate=100.0, progress=False
    )
    assert d1.noise_floor_white == pytest.approx(d0.noise_floor_white, rel=1e-9)
    assert d1.noise_floor_allan == pytest.approx(d0.noise_floor_allan, rel=1e-9)


@pytest.mark.parametrize("rot_deg", [0.0, 4.0])
def test_marg_correlated_errors_honest_standard_errors(rot_deg):
    """Issue 15: with the hand's acceleration in the log (0.02 g, correlated over ~1 s) the
    formal standard errors of the rotation are ~8x too small; with them, the split-halves test
    rejected a real 4 deg misalignment (z 7-16) and BIC, leave-one-out and the null test
    accepted a spurious 0.5-0.9 deg one on a clean log (4 of 6 seeds). The block jackknife's
    standard errors see the correlation: measured over seeds 0-5 (clean) and 0-3 (4 deg), the
    clean logs give nothing (Hotelling p >= 0.01) and the 4 deg rotation is accepted, found
    within 4 honest standard errors of the truth. Under white noise the jackknife's errors
    agree with the formal ones within the jackknife's own spread (measured ratios 0.55-1.4 on
    the 2 deg permuted log above; eight blocks give a standard error to about +-27 %)."""
    from calib_jax.diagnose import diagnose_marg

    acc, mag = _marg_log(rot_deg=rot_deg, hand_g=0.02, seed=1)
    d = diagnose_marg(acc, mag, sample_rate=100.0, progress=False)
    e = next(x for x in d.rounds[0] if x["effect"] == "sensor_misalignment")
    ratio = np.asarray(e["stderr_honest"]) / np.asarray(e["stderr_formal"])
    assert np.all(ratio > 3), ratio  # correlated samples: the formal errors are too small
    if rot_deg == 0:
        assert d.effects == [] and not e["tests"]["honest"], e
    else:
        assert d.effects == ["sensor_misalignment"], e["tests"]
        assert e["halves_max_z"] < 3 < e["halves_max_z_formal"]
        truth = np.radians(4.0) * np.array([0.6, -0.5, 0.62])  # the simulator's rotation vector
        coef = d.steps[-1]["coefficients"]
        err = np.radians(coef["rotvec_deg"]) - truth
        assert np.all(np.abs(err) < 4 * np.radians(coef["rotvec_stderr_deg"])), err


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_marg_clean_tumble_with_a_hands_acceleration_has_no_structure(seed):
    """A clean tumble (3,000 samples, benchmarks/diagnosis_power.py's) with a white 0.02 g
    hand acceleration in the accelerometer: the structure tests regressed the angle's error on
    the gravity direction taken from that same noisy accelerometer, whose noise is in the
    angle too, so 'the angle follows time' at p 1e-101 (size 0.49 deg) on seed 0 and the verdict
    was unexplained structure on every clean log. The direction is smoothed first
    (marg.DRIVER_SMOOTHING_S): no driver above the floor on these seeds."""
    from calib_jax.diagnose import diagnose_marg

    acc, mag = _marg_log(n=3000, hand_g=0.02, hand_corr=0.0, seed=seed, knots=16)
    d = diagnose_marg(acc, mag, sample_rate=100.0, progress=False)
    assert d.effects == [], d.rounds
    assert not [s["driver"] for s in d.structure if s["above_floor"]], d.structure
    assert d.verdict == "at_floor", d.summary()


def test_a_clean_hand_turned_tumble_that_follows_time_names_the_hands_acceleration():
    """A clean tumble (30 s, low noise) with the hand's 0.02 g acceleration correlated over 1 s:
    on this seed the angle follows time (p ~ 1e-5; about half of such logs, known and not
    met: docs/close_the_loop.md, "Verdicts"). The residual is the hand's slow acceleration
    seen along a turning direction, the very form of the time driver, and no stationary
    whitening separated them (branch try/arma11-whitening). The note said only that a
    calibration error does this; the user who turned the board by hand is now told that the
    hand's acceleration does too. Should a later change clear this log, this test must move to
    a log whose angle still follows time."""
    from calib_jax.diagnose import diagnose_marg

    acc, mag = _marg_log(n=3000, hand_g=0.02, noise=(2e-3, 0.2), seed=5, knots=16)
    d = diagnose_marg(acc, mag, sample_rate=100.0, progress=False)
    assert d.effects == [], d.rounds
    assert [s["driver"] for s in d.structure if s["above_floor"]] == ["time"], d.structure
    [note] = [n for n in d.notes if n.startswith("the angle follows time")]
    assert "a hand's acceleration" in note and "over 30 s" in note, note


def test_an_angle_error_no_hand_can_make_is_not_blamed_on_the_hand():
    """marg.HAND_MAX_RAD: a magnet moving near the board (a field offset of 0.9 of the field
    that grows over the log) makes the angle follow time by 9 deg, beyond what a hand's
    acceleration (0.1 g at most) can. On a real MPU-9150 log (43.8 deg) the note named the
    hand; now only the calibration error is offered."""
    from calib_jax.diagnose import diagnose_marg

    acc, mag = _marg_log(n=3000, seed=5, knots=16)
    mag = mag + np.linspace(0.0, 1.0, len(mag))[:, None] ** 2 * np.array([36.0, -18.0, 12.0])
    d = diagnose_marg(acc, mag, sample_rate=100.0, progress=False)
    [time_entry] = [s for s in d.structure if s["driver"] == "time"]
    assert time_entry["above_floor"] and time_entry["size"] > 0.1, d.structure
    [note] = [n for n in d.notes if n.startswith("the angle follows time")]
    assert "calibration" in note and "hand" not in note, note


def test_rest_floor_holds_correlated_noise_and_is_the_plain_scatter_for_white():
    """floors.rest_floor: the scatter about a quadratic with the degrees of freedom the trend
    takes from AR(1) noise of the rest's own lag-1 correlation. White noise: the plain
    std(ddof=3) it replaced, to round-off. AR(1) noise with lag-1 correlation 0.99 over 480
    samples (the power benchmark's magnetometer rest): the plain scatter is 0.57 of the noise
    (median over 200 series), this 0.67, larger in every series (1.07-1.4x; it cannot see more
    of noise that slow from a rest only 5 correlation times long: 0.95 with the true
    correlation)."""
    from calib_jax.diagnose.floors import rest_floor
    from calib_jax.simulate import correlated_noise

    y = np.random.default_rng(0).normal(size=500)
    t = np.arange(500.0)
    plain = np.std(y - np.polyval(np.polyfit(t, y, 2), t), ddof=3)
    white, phi = rest_floor(y)
    assert phi < 0.1 and white == pytest.approx(plain, rel=0.02 * phi + 1e-12)
    new, old = [], []
    for seed in range(200):
        y = correlated_noise(480, 1.0, 0.99, rng=seed, dims=1)[:, 0]
        new.append(rest_floor(y)[0])
        old.append(np.std(y - np.polyval(np.polyfit(t[:480], y, 2), t[:480]), ddof=3))
    new, old = np.array(new), np.array(old)
    assert np.all(new > old) and np.median(old) < 0.6 and 0.64 < np.median(new) < 0.7, (
        np.median(old),
        np.median(new),
    )


def test_marg_ckexplorer_through_the_cli(tmp_path):
    """The CK-Explorer acc+mag tumble: the small accel-mag rotation found by `calib-jax demo`
    (about 1 deg, angle spread 2.49 -> 2.43 deg) is accepted; figures written."""
    from calib_jax.datasets import mag_demo_log_path

    out = tmp_path / "marg.json"
    rc = main(["diagnose", str(mag_demo_log_path()), "--sensor", "marg", "--json", str(out),
               "--report", str(tmp_path / "rep"), "--no-progress"])  # fmt: skip
    assert rc == 0
    d = json.loads(out.read_text())
    assert d["effects"] == ["sensor_misalignment"]
    assert np.degrees(d["rms_before"]) == pytest.approx(2.49, abs=0.05)
    assert np.degrees(d["rms_after"]) == pytest.approx(2.44, abs=0.05)
    assert (tmp_path / "rep" / "angle_time.png").exists()


def test_marg_on_spheres_where_the_verdict_advises_them(tmp_path, capsys):
    """The x-io hand-held log turns too little for a full accelerometer ellipsoid: the MARG
    diagnosis is not possible and its reason says to fit a sphere (--model sphere). That flag
    used to reach only the magnetometer diagnosis, so following the advice changed nothing;
    with it the two sensors are calibrated on spheres and the angle is judged."""
    from .conftest import shared_file

    log = str(shared_file("xio_fusion_sensor_data/sensor_data.csv"))
    assert main(["diagnose", log, "--sensor", "marg", "--no-progress"]) != 0
    assert "--model sphere" in capsys.readouterr().err
    out = tmp_path / "d.json"
    cmd = ["diagnose", log, "--sensor", "marg", "--model", "sphere", "--no-progress"]
    assert main([*cmd, "--json", str(out)]) == 0
    assert json.loads(out.read_text())["verdict"] != "not_possible"


def test_a_base_fit_that_does_not_converge_gives_no_verdict(monkeypatch):
    """RocketPy's CATS Vega flight log (a descent read as poses): the base fit ran out of
    iterations and `calib-jax diagnose` still gave 'unexplained_structure' with exit 0,
    judging effects against a calibration that was never found. Here the solver's budget is
    cut to one iteration, so the base fit of a clean log cannot converge: no verdict, and no
    advice to raise --max-iter (calib-jax diagnose has no such option)."""
    compiled = M._compiled_fit
    monkeypatch.setattr(M, "_compiled_fit", lambda max_iter: compiled(1))
    s = simulate_accel_log((), seed=2)
    d = diagnose_accel(s.raw, t=s.t, temp=s.temp, intervals=s.intervals)
    assert d.verdict == "not_possible"
    assert "the base model's fit (accel9) did not converge" in d.notes[0], d.notes
    assert "--max-iter" not in d.notes[0] and "calib-jax accel on this log" in d.notes[0]


def test_a_tumble_without_a_rest_takes_no_quiet_stretch_for_one():
    """A tumble with no rest: the rest detector's threshold (6 noise levels) let slow
    stretches of the turn through, and the longest became 'the longest rest' whose scatter
    set the noise floor (a Razor AHRS tumble: floor 6.3 % above the fit's 5.6 % RMS). A rest
    holds the field's direction; these turn by 20-140 deg, are left out with a note, and the
    floor comes from first differences."""
    s = simulate_mag_log(seed=1, rest=0)
    d = diagnose_mag(s.raw, t=s.t, sample_rate=50.0, progress=False)
    assert any("left out as rests: the field direction turns" in n for n in d.notes)
    assert "no rest in the log: white floor from first differences, no Allan floor" in d.notes


@pytest.mark.filterwarnings("ignore::calib_jax.calibration.FitStatusWarning")  # the failed fit
def test_a_magnetometer_fit_that_failed_says_why():
    """A phone's walk (Aymdi/DeadReckoning): 'not possible: the declared model's fit is
    failed (converged ...); record more orientations', though no model was declared and the
    fit failed because no ellipsoid describes the data. It now names the model calib-jax mag
    chose and gives that fit's own reason. Here a field that changes halfway (radius 1, then
    1.4)."""
    rng = np.random.default_rng(3)
    u = rng.normal(size=(800, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    m = 30 * u * np.where(np.arange(800) < 400, 1.0, 1.4)[:, None] + 5
    d = diagnose_mag(m + 0.05 * rng.normal(size=m.shape), sample_rate=50.0)
    assert d.verdict == "not_possible"
    assert "calib-jax mag's choice) is 'failed'" in d.notes[0]
    assert "no ellipsoid describes the data" in d.notes[0]


def test_the_declared_magnetometer_model_is_calib_jax_mags_choice():
    """diagnose_mag declared the full ellipsoid whatever the log: on a CMU ALFA flight that
    `calib-jax mag` fitted with a sphere (full 'not determined') the diagnosis fitted the full
    model without a word. By default it now declares the model calibrate_mag chooses."""
    rng = np.random.default_rng(5)
    d = rng.normal(size=(3000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    raw = 45.0 * d + np.array([12.0, -7.0, 30.0]) + 0.2 * rng.normal(size=d.shape)
    diag = diagnose_mag(raw, sample_rate=100.0, progress=False)
    assert diag.steps[0]["model"] == "base" and diag.obs.base == "sphere"
    assert any("declared model: sphere, as calib-jax mag chooses" in n for n in diag.notes)
    with pytest.raises(ValueError, match="model must be 'auto', 'full', 'diag' or 'sphere'"):
        diagnose_mag(raw, model="ellipse")


def test_a_diagonal_base_tests_the_cross_terms_as_soft_iron():
    """calib-jax mag chooses among sphere, diagonal and full ellipsoids; the diagnosis had two
    bases, sphere and full, so mag's diagonal choice was diagnosed on the full ellipsoid (on a
    partial tumble that base did not converge). The diagnosis now has mag's three kinds. On a
    diagonal base, soft iron is the cross terms alone: the base's own unequal gains are not
    part of the effect (counted in, they made every honest test of a diagonal base see an
    'effect' of the size of the gain spread). Known truth: a simulated board whose soft iron
    has gains 1, 1.12, 0.9 and cross terms 0.03, -0.03, 0, declared diagonal."""
    rng = np.random.default_rng(7)
    d = rng.normal(size=(3000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    A = np.array([[1.0, 0.03, 0.0], [0.03, 1.12, -0.03], [0.0, -0.03, 0.9]])
    raw = 45.0 * d @ A.T + np.array([12.0, -7.0, 30.0]) + 0.2 * rng.normal(size=d.shape)
    diag = diagnose_mag(
        raw,
        model="diag",
        sample_rate=100.0,
        candidates=("soft_iron",),
        max_points=1000,
        progress=False,
    )
    assert diag.obs.base == "diag" and diag.steps[0]["n_params"] == 6
    assert diag.effects == ["soft_iron"], diag.rounds
    (entry,) = [e for r in diag.rounds for e in r if e.get("effect") == "soft_iron"][:1]
    assert entry["accepted"] and len(entry["stderr_formal"]) == 3  # the cross terms only
    # the final model is the full ellipsoid: its shape is the board's, to 2e-3 (each sample's
    # noise is 0.44 % of the field; 1,000 samples determine the shape to about 3e-4)
    alpha = M.base_alpha(diag.theta_final, diag.free_final, np)
    assert (
        np.abs(alpha / np.cbrt(np.linalg.det(alpha)) - A / np.cbrt(np.linalg.det(A))).max() < 2e-3
    )


def test_a_partial_tumble_whose_ellipsoid_base_fails_is_diagnosed_from_the_sphere(
    capsys, monkeypatch
):
    """scikit-kinematics' YEI 3-Space log (tests/data/skinematics, BSD-3): a hand-held
    magnetometer record covering about a third of the sphere. calib-jax mag chose the
    diagonal ellipsoid there (it keeps the sphere now: test_mag_real); the diagnosis's base
    then containing it, the full ellipsoid, did not converge, and calib-jax diagnose --sensor
    mag failed after 16 s saying to raise --max-iter, an option it has not, and that
    calib-jax mag 'says why' (it had converged). The diagnosis now starts from mag's own kind
    (a diagonal base converges on this log); where that base fails, it starts from the
    sphere, says why in a note and tests soft iron as an effect. Here mag's choice is made the
    full ellipsoid, reported converged, so that the diagnosis's full base fails as it did;
    the sphere base converges and the loop runs (the verdict itself is the loop's)."""
    import dataclasses
    from pathlib import Path

    import calib_jax.mag

    fit = calib_jax.mag.calibrate_mag

    def old_choice(x, model="auto", **kw):
        if model != "auto":
            return fit(x, model=model, **kw)
        with pytest.warns(UserWarning, match="not_converged"):  # mag's own full fit, too
            full = fit(x, model="full", **kw)
        return dataclasses.replace(full, status="ok", warnings=[])

    path = Path(__file__).parent / "data" / "skinematics" / "data_yei.txt"
    monkeypatch.setattr(calib_jax.mag, "calibrate_mag", old_choice)
    # soft iron alone of the candidates (the one the fallback adds), every 3rd sample: 17 -> 11 s
    d = diagnose_mag(
        load_log(path, sensor="mag"), candidates=("soft_iron",), max_points=1000, progress=False
    )
    monkeypatch.undo()
    assert d.obs.base == "sphere", d.notes
    assert any(
        "the full ellipsoid base (calib-jax mag's choice) did not converge" in n for n in d.notes
    ), d.notes
    assert d.verdict != "not_possible" and np.isfinite(d.steps[0]["rms"])
    assert any(e["effect"] == "soft_iron" for r in d.rounds for e in r), d.rounds
    # without --sensor the accelerometer is diagnosed (2 poses: not possible), and the refusal
    # now points at the magnetometer the log also holds
    assert main(["diagnose", str(path), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "only 2 distinct poses" in err and "also holds magnetometer columns: --sensor mag" in err
    # the pose count the model needs, said once (it followed as "; it needs at least 9 ...")
    assert "needs at least 9 poses" in err and "it needs at least" not in err, err
