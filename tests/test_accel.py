"""calibrate_accel end to end on simulated logs with known truth, and every bad input."""

import json
import re
import warnings

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import calib_jax as cj
from calib_jax.calibration import FitStatusWarning
from calib_jax.models.accel import distort
from calib_jax.simulate import paper48_directions, random_directions, random_params, simulate_accel

from .conftest import Tol

# detector settings for the short simulated poses (100 samples at 100 Hz)
DET = dict(sample_rate=100.0, window=25, min_samples=40)


def sim(seed=0, dirs=None, noise=2e-3, scale=1.0, quantize=False, **kw):
    p = random_params(seed, scale=scale)
    return simulate_accel(
        p,
        dirs,
        samples_per_pose=100,
        transition_samples=30,
        noise=noise * scale,
        quantize=quantize,
        rng=seed,
        **kw,
    )


@given(
    seed=st.integers(0, 10_000),
    noise=st.sampled_from([5e-4, 2e-3, 5e-3]),
    poses=st.sampled_from(["paper48", "random30", "random60"]),
    unit=st.sampled_from(["g", "m/s^2", "counts"]),
)
def test_parameter_recovery(seed, noise, poses, unit, tol):
    dirs = {
        "paper48": paper48_directions(),
        "random30": random_directions(30, seed),
        "random60": random_directions(60, seed),
    }[poses]
    scale, g, quant = {
        "g": (1.0, 1.0, False),
        "m/s^2": (9.80665, 9.80665, False),
        "counts": (4096.0, 1.0, True),
    }[unit]
    # the simulator's reference magnitude is g in output units: readings = alpha (g u) + beta
    log = simulate_accel(
        random_params(seed, scale=scale / g),
        dirs,
        samples_per_pose=100,
        transition_samples=30,
        noise=noise * scale,
        quantize=quant,
        g=g,
        rng=seed,
    )
    cal = cj.calibrate_accel(log.raw, units=unit, g=g, **DET)
    assert cal.status == "ok", cal.report()
    assert cal.n_intervals == len(dirs)
    z = (cal.params - log.params) / cal.stderr
    assert np.all(np.abs(z) < tol.N_SIGMA), (z, cal.report())
    assert cal.rms_after < cal.rms_before


def test_static_detection_finds_every_pose():
    log = sim(1)
    rep = cj.detect_static(log.raw, **DET)
    assert rep.n_intervals == len(log.directions)
    for iv in rep.intervals:
        poses = log.pose[iv.start : iv.stop]
        assert np.all(poses == poses[0]) and poses[0] >= 0  # never straddles a transition
    assert "48 static intervals" in rep.summary(100.0)


def test_a_residual_far_above_the_noise_floor_is_a_warning():
    """A magnetometer tumble fitted as an accelerometer (Razor AHRS, GPL-3) left 14x the noise
    floor with status poorly_determined and no word. Here the poses of a simulated log, half
    of them at 1.03 times the magnitude (no ellipsoid holds both halves): the warning names the
    ratio; the clean log, at about 1 floor, has none."""
    p = random_params(3)
    log = simulate_accel(p, samples_per_pose=300, transition_samples=20, noise=2e-3, rng=3)
    beta = p[6:]
    raw = log.raw.copy()
    half = len(raw) // 2
    raw[half:] = beta + 1.03 * (raw[half:] - beta)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", cj.FitStatusWarning)
        bad = cj.calibrate_accel(raw, sample_rate=100.0)
    said = [w for w in bad.warnings if w.startswith("the fit leaves")]
    assert said and f"{bad.rms_after / bad.noise_floor:.0f}x the noise floor" in said[0]
    clean = cj.calibrate_accel(log.raw, sample_rate=100.0)
    assert clean.rms_after < 3 * clean.noise_floor
    assert not any(w.startswith("the fit leaves") for w in clean.warnings)


def test_means_and_samples_both_available(tol):
    log = sim(2)
    a = cj.calibrate_accel(log.raw, use="means", **DET)
    b = cj.calibrate_accel(log.raw, use="samples", **DET)
    assert a.n_points == 48 and b.n_points > 40 * 48
    for cal in (a, b):
        assert np.all(np.abs(cal.params - log.params) < tol.N_SIGMA * cal.stderr)


def test_json_roundtrip_and_apply(tmp_path):
    log = sim(3)
    cal = cj.calibrate_accel(log.raw, sensor_id="unit-7", **DET)
    path = tmp_path / "cal.json"
    cal.save(path)
    d = json.loads(path.read_text())
    assert d["format_version"] == 1 and d["params"]["gains"] and d["units"]["input"] == "g"
    back = cj.AccelCalibration.load(path)
    np.testing.assert_array_equal(back.params, cal.params)
    np.testing.assert_array_equal(back.stderr, cal.stderr)
    assert back.sensor_id == "unit-7" and back.status == cal.status
    # what the detector chose is a note, kept in the file; a file written before notes
    # existed (no "notes" key) still loads
    assert back.notes == cal.notes and any(n.startswith("static detection") for n in d["notes"])
    assert not any(w.startswith("static detection") for w in cal.warnings)
    old = {k: v for k, v in d.items() if k != "notes"}
    path.with_suffix(".old.json").write_text(json.dumps(old))
    assert cj.AccelCalibration.load(path.with_suffix(".old.json")).notes == []
    a = back.apply(log.raw[log.static])
    err = np.abs(np.linalg.norm(a, axis=1) - 1.0)
    assert np.median(err) < 5e-3  # per-sample noise is 2 mg
    d["format_version"] = 99
    path.write_text(json.dumps(d))
    with pytest.raises(ValueError, match="format_version"):
        cj.AccelCalibration.load(path)


# ---- bad input --------------------------------------------------------------------------------


def test_nan_rows_are_dropped_and_reported(tol):
    log = sim(4)
    raw = log.raw.copy()
    raw[[5, 500, 1200]] = np.nan
    raw[800, 1] = np.inf
    ref = cj.calibrate_accel(log.raw, **DET)
    cal = cj.calibrate_accel(raw, **DET)
    assert any("4 rows with NaN or inf" in w for w in cal.warnings)
    # a NaN row inside a pose splits its interval (the pose then counts twice among the means),
    # so the estimate moves a little, well within its uncertainty
    assert np.all(np.abs(cal.params - ref.params) < 0.5 * ref.stderr)


def test_all_nan_is_an_error():
    with pytest.raises(ValueError, match="no finite"):
        cj.calibrate_accel(np.full((100, 3), np.nan))


def test_wrong_shape_is_an_error():
    with pytest.raises(ValueError, match=r"\(samples, 3\)"):
        cj.calibrate_accel(np.zeros((100, 2)))


def test_too_few_poses_says_what_to_do():
    faces = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1.0]])
    log = sim(5, faces)
    with pytest.raises(ValueError, match="only 6 distinct poses.*accel6"):
        cj.calibrate_accel(log.raw, model="accel9", **DET)
    cal = cj.calibrate_accel(log.raw, model="accel6", use="samples", **DET)
    assert cal.status == "ok" and np.all(cal.nonorth == 0)
    # the default, as calib-jax accel's, is "auto": six faces get six parameters, said so
    auto = cj.calibrate_accel(log.raw, use="samples", **DET)
    assert auto.model == "accel6" and np.array_equal(auto.params, cal.params)
    assert any(n.startswith("model accel6") for n in auto.notes), auto.notes


def test_all_poses_in_one_plane_is_an_error():
    ang = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    dirs = np.stack([np.cos(ang), np.sin(ang), np.zeros_like(ang)], axis=1)
    with pytest.raises(ValueError, match="one plane"):
        cj.calibrate_accel(sim(6, dirs).raw, **DET)


def test_one_hemisphere_is_flagged():
    d = random_directions(200, 8)
    d = d[d[:, 2] > 0.3][:30]
    cal = cj.calibrate_accel(sim(8, d).raw, **DET)
    assert any("hemisphere" in w for w in cal.warnings)
    # the z gain and bias trade off: their correlation is strong and reported
    i, j = 2, 8
    assert abs(cal.correlation[i, j]) > 0.9


def test_an_axis_never_tilted_is_named():
    # 30 poses whose y component stays within +-0.12 g (RMS about 0.07): the y axis was never
    # turned towards up or down. Not a plane (the tilt is small, not zero), so the fit runs and
    # the warning names the axis; BROAD trial 05 (RMS 0.15 along y) is the real case
    rng = np.random.default_rng(3)
    ang = rng.uniform(0, 2 * np.pi, 30)
    y = rng.uniform(-0.12, 0.12, 30)
    d = np.stack([np.cos(ang), y, np.sin(ang)], axis=1)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    cal = cj.calibrate_accel(sim(9, d).raw, **DET)
    hit = [w for w in cal.warnings if w.startswith("gravity hardly varies")]
    assert len(hit) == 1 and re.search(r"along \[[+-]0\.0\d, [+-]1\.00, [+-]0\.0\d\]", hit[0])
    good = cj.calibrate_accel(sim(9, paper48_directions()).raw, **DET)
    assert not any(w.startswith("gravity hardly varies") for w in good.warnings)


def test_saturated_axis_is_excluded_and_reported():
    log = sim(9)
    raw = log.raw.copy()
    top = np.quantile(raw[:, 0], 0.97)
    raw[:, 0] = np.minimum(raw[:, 0], top)
    cal = cj.calibrate_accel(raw, **DET)
    assert any("axis x is saturated" in w for w in cal.warnings)


def test_no_static_interval_is_an_error():
    rng = np.random.default_rng(0)
    walk = np.cumsum(rng.normal(scale=0.05, size=(3000, 3)), axis=0)
    with pytest.raises(ValueError, match="no static interval"):
        cj.calibrate_accel(walk, threshold=1e-12, **DET)


@pytest.mark.wrong_types
def test_wrong_units_are_caught():
    # readings in m/s^2 (gains ~9.8 per unit of g), declared as g
    log = simulate_accel(
        random_params(10, scale=9.80665),
        samples_per_pose=100,
        transition_samples=30,
        noise=0.01,
        rng=10,
    )
    with pytest.raises(ValueError, match="looks like m/s\\^2"):
        cj.calibrate_accel(log.raw, units="g", **DET)
    with pytest.raises(ValueError, match="units must be"):
        cj.calibrate_accel(log.raw, units="furlongs", **DET)


def test_failed_fit_is_never_a_silent_identity():
    # use="samples": on the interval means the algebraic start is already the optimum to
    # round-off, so one iteration converges; on the samples it is not, and one runs out
    log = sim(11)
    with pytest.warns(UserWarning, match="not_converged"):
        cal = cj.calibrate_accel(log.raw, use="samples", solver_options={"max_iter": 1}, **DET)
    assert cal.status == "not_converged" and not cal.success
    assert "iteration budget" in cal.solver_message


def test_float32_warns():
    import jax

    log = sim(12)
    jax.config.update("jax_enable_x64", False)
    try:
        with warnings.catch_warnings(record=True) as rec:
            warnings.simplefilter("always")
            try:
                cj.calibrate_accel(log.raw, **DET)
            except Exception:
                pass
        assert any("float32" in str(r.message) for r in rec)
    finally:
        jax.config.update("jax_enable_x64", True)


def test_a_board_that_never_moved_is_one_pose(tmp_path):
    """A flat board quantised to 0.01 g (the Arduino-MARG raw_data log): about the centre of a
    sphere fit through one cluster the noise looked like 5 distinct poses; counted about the
    nominal centre (zero for g) it is the one pose it is, and the error says so."""
    rng = np.random.default_rng(0)
    x = np.round(np.array([0.02, -0.01, 1.0]) + 0.01 * rng.normal(size=(1600, 3)), 2)
    with pytest.raises(ValueError, match="only 1 distinct pose"):
        cj.calibrate_accel(x)


def test_g_that_contradicts_the_unit_is_an_error(sim48):
    """m/s^2 data with g = 1 used to calibrate to |a| = 1 with gains of 9.8 and status ok; it
    is an error unless the output unit is given (then the conversion is intended)."""
    raw = sim48.raw * 9.80665
    with pytest.raises(ValueError, match="does not match the data's unit"):
        cj.calibrate_accel(raw, g=1.0)
    cal = cj.calibrate_accel(raw, g=1.0, output_units="g")
    in_g = cj.calibrate_accel(sim48.raw)
    assert cal.success and abs(cal.params[0] / 9.80665 - in_g.params[0]) < 1e-6
    # the 'before' converts the unit as the output asks (it read |a| in m/s^2 against 1)
    assert abs(cal.rms_before - in_g.rms_before) < 1e-12, (cal.rms_before, in_g.rms_before)
    # the output unit alone sets g (a Python user's trial: output_units="m/s^2" without g
    # gave readings in g labelled m/s^2, status ok, and a ROS export 9.8x too small)
    to_ms2 = cj.calibrate_accel(sim48.raw, output_units="m/s^2")
    assert to_ms2.g == 9.80665 and to_ms2.output_units == "m/s^2"
    np.testing.assert_allclose(to_ms2.params[:6] * 9.80665, in_g.params[:6], rtol=1e-7)
    assert abs(to_ms2.rms_before - in_g.rms_before) < 1e-12
    norms = np.linalg.norm(to_ms2.apply(sim48.raw), axis=1)
    assert abs(np.median(norms) - 9.80665) < 0.01
    for units, bad in (("m/s^2", 1.0), ("m/s2", 1.0), ("g", 9.81)):  # another unit's gravity
        with pytest.raises(ValueError, match=rf"g={bad:g} in the output unit .* where gravity"):
            cj.calibrate_accel(sim48.raw, output_units=units, g=bad)
    assert cj.calibrate_accel(sim48.raw, output_units="m/s^2", g=9.81744).g == 9.81744


def test_declared_counts_are_never_refused_for_their_scale(sim48):
    """A log in small raw units (norm 0.05: no unit the table knows) was refused both with
    --units g and with --units counts, each time advising --units counts. Counts take any
    scale; g still has to look like g."""
    raw = 0.05 * sim48.raw
    with pytest.raises(ValueError, match=r"pass units=.counts. \(--units counts\)"):
        cj.calibrate_accel(raw, units="g")
    cal = cj.calibrate_accel(raw, units="counts")
    assert cal.success and cal.input_units == "counts"


FACES = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1.0]])


def test_six_faces_get_the_six_parameter_model_by_default_and_say_so():
    """model='auto' (the CLI's default): a six-face log (the Ferraris protocol, imucal's
    sessions) is fitted with gains and biases instead of being refused for paper 1's nine;
    the result is the model='accel6' fit itself. Poses that are few and do not hold each axis
    up and down are still refused, saying why."""
    log = sim(5, FACES)
    auto = cj.calibrate_accel(log.raw, model="auto", use="samples", **DET)
    six = cj.calibrate_accel(log.raw, model="accel6", use="samples", **DET)
    assert auto.model == "accel6" and any("model accel6" in n for n in auto.notes)
    np.testing.assert_array_equal(auto.params, six.params)
    # eight poses in the upper half only: too few for nine, and no face points x down
    tilted = random_directions(40, 3)
    tilted = tilted[tilted[:, 2] > 0.5][:8]
    with pytest.raises(cj.TooFewPoses, match="up and down") as e:
        cj.calibrate_accel(sim(6, tilted).raw, model="auto", **DET)
    assert "--model accel6" not in str(e.value)


def test_exact_fit_and_unconverged_fit_claim_no_improvement():
    """Six interval means for six parameters pass through every point: the report used to
    print '8706099938787x lower' (imucal's annotated session); a fit that did not converge
    printed '81x lower' beside wild gains."""
    cal = cj.calibrate_accel(sim(5, FACES).raw, model="accel6", **DET)
    assert cal.n_points == 6
    text = cal.report()
    assert "an exact fit (6 fit points for 6 parameters)" in text and "x lower" not in text
    assert any("passes through every point" in w for w in cal.warnings)
    import dataclasses

    stuck = dataclasses.replace(cal, status="not_converged")
    assert "no calibration: the fit is not converged" in stuck.report()
    assert "x lower" not in stuck.report()


def test_another_sensors_log_is_refused_by_every_accelerometer_path(tmp_path):
    """A magnetometer log in gauss (|m| ~ 0.55) read as an accelerometer: the norm fitted 'g'
    (0.3-3), and calib-jax accel / batch returned gains of 0.55 with status ok. Now both
    refuse it with the same message naming the magnetometer."""
    from calib_jax.fleet import calibrate_files

    log = sim(4, paper48_directions(), scale=0.55)
    with pytest.raises(ValueError, match=r"0\.5\d.*magnetometer in gauss.*calib-jax mag"):
        cj.calibrate_accel(log.raw, **DET)
    path = tmp_path / "mag.csv"
    t = np.arange(len(log.raw)) / 100.0
    np.savetxt(path, np.column_stack([t, log.raw]), delimiter=",", header="t,ax,ay,az")
    (entry,) = calibrate_files([path], progress=False, detector={"window": 25})
    assert entry["status"] == "not_fitted" and "magnetometer in gauss" in entry["message"]
    # declared counts (any scale) is the way to fit it anyway
    assert cj.calibrate_accel(log.raw, units="counts", **DET).status == "ok"


def test_rows_of_another_packet_leave_the_error_after_finite():
    """AirbrakesV2's MicroStrain CX5 log interleaves estimate rows whose accelerometer cells
    are blank: the fit dropped them, the 'after' error did not, and `calib-jax accel` printed
    'after nan (noise floor nan); nanx lower' with status ok. Every second row blanked here:
    the error after and its floor are finite and those of the same samples without the blank
    rows (the intervals hold the same samples; the RMS is over their means, to round-off)."""
    log = sim(7, FACES)
    raw = np.full((2 * len(log.raw), 3), np.nan)
    raw[::2] = log.raw
    # the detector runs on the valid rows alone, at their own rate (half of 200 Hz)
    gappy = cj.calibrate_accel(raw, model="accel6", **{**DET, "sample_rate": 200.0})
    clean = cj.calibrate_accel(log.raw, model="accel6", **DET)
    assert np.isfinite(gappy.rms_after) and np.isfinite(gappy.noise_floor)
    assert "nan" not in gappy.report()
    # same poses, so the same error to the accuracy of slightly different interval edges
    assert gappy.rms_after == pytest.approx(clean.rms_after, rel=0.3)


def test_pose_advice_is_not_the_setting_already_used():
    """The too-few-poses refusal advised `--use samples --window 10 --threshold-factor 20` to
    a user who had just run exactly that (xioTechnologies/Fusion's hand-held log), and
    `--use samples` to a pose table, which has one sample a pose."""
    tilted = random_directions(40, 3)
    tilted = tilted[tilted[:, 2] > 0.5][:8]
    with pytest.raises(cj.TooFewPoses) as means:
        cj.calibrate_accel(sim(6, tilted).raw, **DET)
    assert "--use samples" in str(means.value)
    with pytest.raises(cj.TooFewPoses) as samples:
        cj.calibrate_accel(sim(6, tilted).raw, use="samples", **DET)
    assert "--use samples" not in str(samples.value)
    assert "Record more orientations" in str(samples.value)


def test_auto_fits_six_parameters_where_the_poses_never_mix_x_and_y():
    """A phone turned on a table's edge, about x or about y but never between (tyrex-team's
    Nexus 5 and iPhone 4S sessions): paper 1's S_xy is not determined, and the default fitted
    it anyway (0.06-0.09, status poorly determined, exit 0), a calibration that turns a 1 g
    reading at 45 deg between x and y into 0.91-1.08 g. --model auto now fits six parameters
    there, with a note, where the cross terms the nine do determine explain little (at most
    twice the nine's chi2); --model accel9 still fits nine. Truth: no cross terms, then one."""
    th = np.deg2rad(np.arange(0, 360, 30))
    about_x = np.column_stack([0 * th, np.sin(th), np.cos(th)])
    about_y = np.column_stack([np.sin(th), 0 * th, np.cos(th)])
    dirs = np.unique(np.round(np.vstack([about_x, about_y]), 12), axis=0)
    p = np.array([1.02, 0.97, 1.01, 0, 0, 0, 0.03, -0.02, 0.01])
    log = simulate_accel(p, dirs, samples_per_pose=100, transition_samples=30, noise=2e-3, rng=4)
    with pytest.warns(FitStatusWarning, match="failed"):
        nine = cj.calibrate_accel(log.raw, model="accel9", **DET)
    assert nine.status == "failed" and "S_xy" in nine.poorly_determined
    auto = cj.calibrate_accel(log.raw, model="auto", **DET)
    assert (auto.model, auto.status) == ("accel6", "ok")
    assert any("model accel6" in n and "S_xy" in n for n in auto.notes), auto.notes
    # the six-parameter fit finds the truth within its standard errors
    free = [0, 1, 2, 6, 7, 8]
    z = (auto.params[free] - p[free]) / auto.stderr[free]
    assert np.all(np.abs(z) < Tol.N_SIGMA), z
    # and a reading between x and y comes out at 1 g
    d45 = np.array([[np.sqrt(0.5), np.sqrt(0.5), 0.0]])
    raw45 = np.asarray(distort(jnp.asarray(p), jnp.asarray(d45)))
    assert abs(np.linalg.norm(auto.apply(raw45)) - 1) < 5e-3
    # a real x-z cross term, which turns about y do determine, keeps the nine parameters (a
    # hand-held MPU-6050's x-z and y-z terms: six parameters left 7.6x its residual). Their
    # S_xy is not determined at all (-0.18 +- 0.15 where the truth is 0: a reading between x
    # and y would move by a fifth of g), and was "poorly_determined", exit 0: it is no
    # calibration (accel.UNDETERMINED_STDERR, 10 % of g), and the message names the poses
    # that would determine it
    p[4] = 0.02
    log = simulate_accel(p, dirs, samples_per_pose=100, transition_samples=30, noise=2e-3, rng=4)
    with pytest.warns(FitStatusWarning, match="failed"):
        auto = cj.calibrate_accel(log.raw, model="auto", **DET)
    assert (auto.model, auto.status) == ("accel9", "failed")
    assert auto.stderr[3] > 0.1 and all(auto.stderr[i] < 0.01 for i in (2, 4, 5, 6, 7, 8))
    [why] = [w for w in auto.warnings if w.startswith("the poses do not determine")]
    assert "S_xy" in why and "alpha_z" not in why and "beta" not in why, why
    assert "tilted between the x and y axes" in why and "--model accel6" in why, why


def test_quiet_stretches_of_a_tumble_are_no_calibration(tmp_path):
    """A phone's hand-held magnetometer tumble fitted as an accelerometer (tyrex-team's Nexus 5,
    a new-user trial): its slow parts were taken for 31 poses that left 0.074 of g after the
    fit, 1x lower than before, and the fit was 'poorly_determined', exit 0; on the same phone's
    held poses that calibration left 5.7 % of g where the raw readings left 1.5 %. Simulated
    here: a smooth tumble at 50 Hz with the hand's acceleration (0.8 m/s^2, correlated over
    20 samples). Poses that leave over accel.REST_FAIL (three times what held rests ever
    leave) are now no calibration, and say so in words the gyro gives as its reason."""
    import jax

    from calib_jax.accel import REFUSALS, REST_FAIL
    from calib_jax.rotations import quat_to_dcm
    from calib_jax.simulate import correlated_noise, tumble_quaternions

    C = np.asarray(jax.vmap(quat_to_dcm)(tumble_quaternions(6000, rng=0, knots=12)))
    gravity = np.einsum("nji,j->ni", C, [0.0, 0.0, 9.81])  # in the sensor frame
    rng = np.random.default_rng(0)
    acc = gravity + correlated_noise(6000, 0.8, 0.95, rng=0) + 0.02 * rng.normal(size=(6000, 3))
    with pytest.warns(FitStatusWarning, match="the poses are no rests"):
        cal = cj.calibrate_accel(acc, sample_rate=50.0)
    assert cal.status == "failed" and not cal.success
    assert cal.rms_after > REST_FAIL and cal.rms_after > 0.9 * cal.rms_before  # no better
    assert any(w.startswith(REFUSALS) for w in cal.warnings), cal.warnings
    # the batch's entry, by the same rule (fleet._judge_accel)
    from calib_jax.fleet import calibrate_files

    path = tmp_path / "tumble.csv"
    np.savetxt(path, np.column_stack([np.arange(6000) / 50.0, acc]), delimiter=",",
               header="t,ax,ay,az", comments="")  # fmt: skip
    (entry,) = calibrate_files([str(path)], progress=False)
    assert entry["status"] == "failed" and "the poses are no rests" in entry["message"], entry
