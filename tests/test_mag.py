"""Ellipsoid calibration (paper 2, 2.2): geometry, the pure core, calibrate_mag, bad input."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from calib_jax.accel import calibrate_accel
from calib_jax.calibration import MagCalibration
from calib_jax.geometry import (
    compensation_matrix,
    ellipsoid_fit_constrained,
    ellipsoid_from_quadric,
    moments,
    quadric_matrix,
)
from calib_jax.lm import is_converged
from calib_jax.mag import calibrate_mag, fit_ellipsoid_normalized
from calib_jax.models.mag import (
    MAG_MODELS,
    natural_radius,
    pack,
    quadric_residual,
    soft_iron_matrix,
    unpack,
)
from calib_jax.simulate import random_directions, random_ellipsoid, random_rotation

N = 600  # one padded size (1024) for every simulated fit here: one compilation per model


def ellipsoid_points(seed, n=N, noise=0.005, radius=1.0, dirs=None, **kw):
    """Samples raw = W^-1 y + c, |y| = radius, with white noise ``noise * radius``."""
    rng = np.random.default_rng(seed)
    c, W = random_ellipsoid(rng, radius=radius, **kw)
    y = (random_directions(n, rng) if dirs is None else dirs) * radius
    raw = y @ np.linalg.inv(W).T + c
    return raw + rng.normal(scale=noise * radius, size=raw.shape), c, W


# ---------------------------------------------------------------------------------------------
# geometry


@given(seed=st.integers(0, 10_000), cap=st.sampled_from([-1.0, 0.0, 0.5, 0.8]))
def test_constrained_fit_is_always_an_ellipsoid(seed, cap):
    """Li-Griffiths never returns a hyperboloid, even from a small cap of noisy data, where the
    unconstrained quadric often is one."""
    rng = np.random.default_rng(seed)
    d = random_directions(4000, rng)
    d = d[d[:, 2] > cap][:300]
    x, _, _ = ellipsoid_points(seed, n=len(d), noise=0.02, dirs=d, center_spread=0.0)
    x = (x - x.mean(0)) / np.sqrt(np.mean(np.sum((x - x.mean(0)) ** 2, 1)))
    c, M, ok = ellipsoid_fit_constrained(jnp.asarray(x), jnp.ones(len(x)))
    assert bool(ok)
    assert np.all(np.linalg.eigvalsh(np.asarray(M)) > 0)


def test_constrained_fit_exact_on_noise_free_data():
    """Noise-free points of an ellipsoid within the k = 4 class: the fit is exact (round-off)."""
    x, c, W = ellipsoid_points(3, noise=0.0, axis_spread=0.25, center_spread=0.2)
    cf, M, ok = ellipsoid_fit_constrained(jnp.asarray(x), jnp.ones(N))
    assert bool(ok)
    np.testing.assert_allclose(np.asarray(cf), c, atol=1e-9)
    np.testing.assert_allclose(np.asarray(M), W.T @ W, atol=1e-9)


@given(seed=st.integers(0, 10_000))
def test_paper2_eigen_analysis_round_trip(seed):
    """Eq. 6-20: the matrix form S, translated and normalised, gives back the centre and shape;
    R D R' = A, R is a rotation, and the compensation R diag(r/axes) R' = r M^(1/2)."""
    rng = np.random.default_rng(seed)
    c, W = random_ellipsoid(rng, radius=1.0)
    M = W.T @ W
    S = quadric_matrix(jnp.asarray(c), jnp.asarray(M))
    c2, A, R, axes = ellipsoid_from_quadric(S)
    np.testing.assert_allclose(np.asarray(c2), c, atol=1e-10)
    np.testing.assert_allclose(np.asarray(A), M, atol=1e-10)
    R = np.asarray(R)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-10)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-10)
    np.testing.assert_allclose(R @ np.diag(np.asarray(axes) ** -2.0) @ R.T, M, atol=1e-10)
    comp = compensation_matrix(jnp.asarray(R), axes, 2.0)
    np.testing.assert_allclose(np.asarray(comp), np.asarray(soft_iron_matrix(M, 2.0)), atol=1e-10)
    # a point of the ellipsoid maps onto the sphere of radius 2
    y = random_directions(5, rng)
    x = y @ np.linalg.inv(W).T + c
    np.testing.assert_allclose(np.linalg.norm((x - c) @ np.asarray(comp).T, axis=1), 2.0)


@pytest.mark.parametrize("model", MAG_MODELS)
def test_pack_unpack_and_jacobian(model, tol):
    """The log-Cholesky packing round-trips, and the exact Jacobian of the quadric residual
    matches central differences (Tol.FD_ABS)."""
    rng = np.random.default_rng(0)
    c, W = random_ellipsoid(rng)
    M = W.T @ W
    if model == "sphere":
        M = np.eye(3) * 1.3
    elif model == "diag":
        M = np.diag(np.diag(M))
    p = pack(jnp.asarray(c), jnp.asarray(M), model)
    c2, M2 = unpack(p, model)
    np.testing.assert_allclose(np.asarray(c2), c, atol=1e-12)
    np.testing.assert_allclose(np.asarray(M2), M, atol=1e-12)
    x = jnp.asarray(rng.normal(size=(20, 3)))
    J = jax.jacfwd(quadric_residual)(p, x, model)
    h = 1e-6
    fd = np.stack(
        [
            (
                quadric_residual(p.at[k].add(h), x, model)
                - quadric_residual(p.at[k].add(-h), x, model)
            )
            / (2 * h)
            for k in range(len(p))
        ],
        axis=1,
    )
    np.testing.assert_allclose(np.asarray(J), fd, atol=tol.FD_ABS)


# ---------------------------------------------------------------------------------------------
# the pure core


def _normalised(seed, noise=0.005):
    x, _, _ = ellipsoid_points(seed, noise=noise)
    m = x.mean(0)
    s = np.sqrt(np.mean(np.sum((x - m) ** 2, 1)))
    return (x - m) / s


def test_vmap_equals_loop(tol):
    """Three sensors in one vmapped call give the per-sensor results, to the precision the
    minimum is defined at (Tol.PARAM_REL: the batched and single compilations round
    differently, and chi2 is flat to round-off within ~1e-8 of the optimum)."""
    xs = np.stack([_normalised(k) for k in range(3)])
    w = np.ones(N)
    fit = jax.jit(jax.vmap(lambda x, w: fit_ellipsoid_normalized(x, w, "full")))
    batch = fit(jnp.asarray(xs), jnp.asarray(np.stack([w] * 3)))
    one = jax.jit(lambda x, w: fit_ellipsoid_normalized(x, w, "full"))
    for k in range(3):
        r = one(jnp.asarray(xs[k]), jnp.asarray(w))
        np.testing.assert_allclose(
            np.asarray(batch.params[k]), np.asarray(r.params), rtol=tol.PARAM_REL, atol=1e-9
        )
        # both converged; which test fired first can differ by round-off between the batched
        # and the single compilation
        assert is_converged(int(batch.status[k])) and is_converged(int(r.status))


def test_lm_agrees_with_optimistix_and_scipy(tol):
    """Same quadric residual, three solvers: the same minimum (Tol.CHI2_REL on chi2, 1e-7 on
    the parameters: the minimum is well conditioned, cond ~ 10)."""
    from scipy.optimize import least_squares

    x = _normalised(11)
    w = np.ones(N)
    ours = fit_ellipsoid_normalized(jnp.asarray(x), jnp.asarray(w), "full", "lm1")
    ox = fit_ellipsoid_normalized(jnp.asarray(x), jnp.asarray(w), "full", "optimistix")
    ref = least_squares(
        lambda p: np.asarray(quadric_residual(jnp.asarray(p), jnp.asarray(x), "full")),
        np.asarray(ours.params) + 1e-3,
        method="lm",
        xtol=1e-15,
        ftol=1e-15,
        gtol=1e-15,
    )
    np.testing.assert_allclose(float(ours.chi2), float(ox.chi2), rtol=tol.CHI2_REL)
    np.testing.assert_allclose(float(ours.chi2), 2 * ref.cost, rtol=tol.CHI2_REL)
    np.testing.assert_allclose(np.asarray(ours.params), ref.x, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(np.asarray(ours.params), np.asarray(ox.params), rtol=1e-7, atol=1e-9)


def test_sphere_on_elongated_data_stays_at_the_data_size():
    """A sphere through elongated data (axes 1 : 1.5 : 2.2, the QMC5883L case) keeps a radius
    of the data's size (the real-data test shows the unscaled residual running away)."""
    rng = np.random.default_rng(5)
    d = random_directions(N, rng)
    x = d * np.array([1.0, 1.5, 2.2]) + rng.normal(scale=0.05, size=d.shape)
    x = (x - x.mean(0)) / np.sqrt(np.mean(np.sum((x - x.mean(0)) ** 2, 1)))
    r = fit_ellipsoid_normalized(jnp.asarray(x), jnp.ones(N), "sphere")
    _, M = unpack(r.params, "sphere")
    assert 0.5 < float(natural_radius(M)) < 2.0


# ---------------------------------------------------------------------------------------------
# calibrate_mag


@given(
    seed=st.integers(0, 10_000),
    noise=st.sampled_from([0.002, 0.01, 0.03]),
    radius=st.sampled_from([0.5, 45.0, 6000.0]),
)
def test_recovers_random_ellipsoids(seed, noise, radius, tol):
    """Centre and W within N_SIGMA standard errors of the truth (plus 1e-4 of the radius for the
    O(noise^2) bias of a quadric residual), at any scale (gauss, uT, counts)."""
    x, c, W = ellipsoid_points(seed, noise=noise, radius=radius)
    cal = calibrate_mag(x, model="full", field=radius)
    assert cal.status == "ok", cal.report()
    slack = 1e-4 * radius + 3 * noise**2 * radius
    assert np.all(np.abs(cal.center - c) < tol.N_SIGMA * cal.stderr_center + slack)
    # W is dimensionless (output per raw unit, both in the radius's unit); its quadric bias
    # grows with the noise seen through W
    w_slack = 1e-4 + 3 * (noise * np.abs(W).max()) ** 2
    assert np.all(np.abs(cal.soft_iron - W) < tol.N_SIGMA * cal.stderr_soft_iron + w_slack)
    # the after-RMS is the raw noise seen through W: radially, noise * sqrt(tr(W W') / 3) on
    # average over directions (15 %: the sample RMS of 600 residuals and the direction mix)
    expected = 100 * noise * np.sqrt(np.trace(W @ W.T) / 3)
    assert cal.rms_after_pct == pytest.approx(expected, rel=0.15)
    assert cal.rms_before_pct > cal.rms_after_pct


def test_auto_prefers_the_simplest_true_model():
    """BIC picks the sphere for a pure hard-iron offset, diag for axis-aligned gains and full
    for a rotated ellipsoid (noise 0.5 %, 600 samples)."""
    rng = np.random.default_rng(2)
    y = random_directions(N, rng)
    noise = rng.normal(scale=0.005, size=y.shape)
    c = np.array([0.3, -0.2, 0.1])
    sphere = y + c + noise
    diag = y * np.array([1.0, 1.2, 0.85]) + c + noise
    R = random_rotation(3, 60)
    full = (y * np.array([1.0, 1.2, 0.85])) @ R.T + c + noise
    assert calibrate_mag(sphere).model == "sphere"
    assert calibrate_mag(diag).model == "diag"
    assert calibrate_mag(full).model == "full"


def test_field_sets_the_output_scale():
    """Without a field, det W = 1 (magcal); with one, |W (x - c)| = field; centres agree."""
    x, _, _ = ellipsoid_points(4, radius=300.0)
    a = calibrate_mag(x, model="full")
    b = calibrate_mag(x, model="full", field=44.3)
    assert np.linalg.det(a.soft_iron) == pytest.approx(1.0, rel=1e-9)
    np.testing.assert_allclose(a.center, b.center, rtol=1e-9)
    np.testing.assert_allclose(b.soft_iron, a.soft_iron * 44.3 / a.radius, rtol=1e-9)
    assert np.median(np.linalg.norm(b.apply(x), axis=1)) == pytest.approx(44.3, rel=0.01)


def test_partial_coverage_warns_and_widens_errors(tol):
    """Data from a 60-degree cap: a warning, larger standard errors, and the truth still
    within them (the fit is honest about what the poses cannot pin down)."""
    rng = np.random.default_rng(8)
    d = random_directions(20000, rng)
    cap = d[d[:, 2] > 0.5][:N]
    full = random_directions(N, rng)
    xc, c, W = ellipsoid_points(8, dirs=cap, noise=0.005)
    xf, _, _ = ellipsoid_points(8, dirs=full, noise=0.005)
    a = calibrate_mag(xc, model="full", field=1.0)
    b = calibrate_mag(xf, model="full", field=1.0)
    assert any("cover" in w for w in a.warnings)
    assert a.coverage < 0.5 < b.coverage
    assert np.all(a.stderr_center > 3 * b.stderr_center)
    if a.status in ("ok", "poorly_determined"):
        assert np.all(np.abs(a.center - c) < tol.N_SIGMA * a.stderr_center + 1e-3)


def test_one_axis_turn_is_rejected_with_the_fix():
    t = np.linspace(0, 2 * np.pi, 500)
    x = np.stack([np.cos(t), np.sin(t), 0.3 + 0 * t], 1) + 0.001 * np.random.default_rng(0).normal(
        size=(500, 3)
    )
    with pytest.raises(ValueError, match="one plane.*Tumble"):
        calibrate_mag(x)


@pytest.mark.parametrize(
    "bad, match",
    [
        (np.zeros((100, 2)), "must be \\(samples, 3\\)"),
        (np.full((100, 3), np.nan), "only 0 finite samples"),
        (np.ones((100, 3)), "identical"),
    ],
)
def test_bad_input(bad, match):
    with pytest.raises(ValueError, match=match):
        calibrate_mag(bad)


@pytest.mark.wrong_types
def test_bad_options():
    x, _, _ = ellipsoid_points(0)
    with pytest.raises(ValueError, match="model must be"):
        calibrate_mag(x, model="ellipse")
    with pytest.raises(ValueError, match="field must be a positive"):
        calibrate_mag(x, field=-1.0)


def test_nan_rows_are_counted_not_fatal():
    x, _, _ = ellipsoid_points(1)
    x[::50] = np.nan
    cal = calibrate_mag(x, model="full")
    assert cal.n_samples == N - len(x[::50])
    assert any("NaN" in w for w in cal.warnings)


def test_json_round_trip(tmp_path):
    x, _, _ = ellipsoid_points(2)
    cal = calibrate_mag(x, model="full", field=1.0, units="gauss", sensor_id="board-7")
    cal.save(tmp_path / "m.json")
    d = json.loads((tmp_path / "m.json").read_text())
    for key in ("center", "soft_iron", "radius", "model", "status", "rms_before_pct"):
        assert key in d
    back = MagCalibration.load(tmp_path / "m.json")
    np.testing.assert_array_equal(back.apply(x), cal.apply(x))
    assert back.sensor_id == "board-7" and back.model == "full"
    d["format_version"] = 99
    (tmp_path / "bad.json").write_text(json.dumps(d))
    with pytest.raises(ValueError, match="format_version"):
        MagCalibration.load(tmp_path / "bad.json")


def test_full_ellipsoid_matches_paper1_on_accelerometer(sim48):
    """Paper 2 applies the ellipsoid to every sensor; on static accelerometer means the full
    ellipsoid with field = g is paper 1's nine-parameter family (W = alpha^-1 in the
    correction direction). Both fits agree to well within their standard errors."""
    acc = calibrate_accel(sim48.raw, sample_rate=sim48.sample_rate, window=25, min_samples=40)
    ell = calibrate_mag(acc.static_means, model="full", field=1.0, sensor="accel")
    alpha = np.asarray(acc.to_params().alpha)
    np.testing.assert_allclose(ell.center, acc.bias, atol=3 * acc.stderr[6:9].max())
    np.testing.assert_allclose(ell.soft_iron, np.linalg.inv(alpha), atol=3 * acc.stderr[:6].max())
    assert ell.rms_after_pct / 100 == pytest.approx(acc.rms_after, rel=0.05)


def test_moments_are_the_weighted_monomial_products():
    """geometry.moments assembles S from 35 power sums; against the definition
    S = sum w phi phi' with phi = [x^2, y^2, z^2, 2xy, 2xz, 2yz, x, y, z, 1] written out here.
    Both sum the same O(1)-scaled products: 1e-12 relative."""
    rng = np.random.default_rng(0)
    x, w = rng.normal(size=(200, 3)), rng.uniform(0.5, 2.0, 200)
    X, Y, Z = x.T
    phi = np.stack([X * X, Y * Y, Z * Z, 2 * X * Y, 2 * X * Z, 2 * Y * Z, X, Y, Z, 1 + 0 * X], 1)
    S = np.asarray(moments(jnp.asarray(x), jnp.asarray(w)))
    np.testing.assert_allclose(S, (phi * w[:, None]).T @ phi, rtol=1e-12, atol=1e-12 * w.sum())


def test_power_sums_against_exact_sums():
    """geometry.power_sums (one variadic reduce in float64) against math.fsum of the same
    monomials (exactly rounded): 1e-14 of the largest sum over 4,800 samples (observed 2.3e-15).
    float32 keeps jnp.sum's blocked sums: 1e-7 of the largest (observed 3.8e-8); the one loop
    that adds the samples in turn gave 1.1e-6 here."""
    import math

    from calib_jax.geometry import _monomials, power_sums

    rng = np.random.default_rng(3)
    d = rng.normal(size=(4800, 3))
    x = 1.02 * d / np.linalg.norm(d, axis=1, keepdims=True) + 0.05
    w = rng.uniform(0.5, 2.0, 4800)
    exact = np.array([math.fsum(m) for m in np.asarray(_monomials(jnp.asarray(x), jnp.asarray(w)))])
    scale = np.abs(exact).max()
    got = np.asarray(power_sums(jnp.asarray(x), jnp.asarray(w)))
    assert np.abs(got - exact).max() <= 1e-14 * scale
    x32, w32 = jnp.asarray(x, jnp.float32), jnp.asarray(w, jnp.float32)
    got32 = np.asarray(jax.jit(power_sums)(x32, w32), float)
    assert np.abs(got32 - exact).max() <= 1e-7 * scale


def test_moments_differentiate_in_both_modes(tol):
    """The power sums are one variadic lax.reduce, which JAX cannot differentiate; their
    derivative comes from geometry._sum_last_jvp. Against the definition written out here:
    d S / d w_i = phi_i phi_i' exactly (S is linear in w; 1e-12), and a direction in x against
    central differences of the numpy S (step 1e-6: tol.FD_ABS on O(1) entries), in forward and
    reverse mode, and through normalised_moments (forward against reverse, round-off)."""
    from calib_jax.geometry import normalised_moments

    rng = np.random.default_rng(2)
    x, w = rng.normal(size=(40, 3)), rng.uniform(0.5, 2.0, 40)

    def phi(x):
        X, Y, Z = x.T
        quad = [X * X, Y * Y, Z * Z, 2 * X * Y, 2 * X * Z, 2 * Y * Z]
        return np.stack([*quad, X, Y, Z, 1 + 0 * X], 1)

    def S_numpy(x):
        return (phi(x) * w[:, None]).T @ phi(x)

    P = phi(x)
    dS_dw = np.einsum("ia,ib->abi", P, P)
    for jac in (jax.jacfwd, jax.jacrev):
        got = np.asarray(jac(lambda w: moments(jnp.asarray(x), w))(jnp.asarray(w)))
        np.testing.assert_allclose(got, dS_dw, rtol=1e-12, atol=1e-12)
    v, h = rng.normal(size=x.shape), 1e-6
    fd = (S_numpy(x + h * v) - S_numpy(x - h * v)) / (2 * h)
    _, fwd = jax.jvp(lambda x: moments(x, jnp.asarray(w)), (jnp.asarray(x),), (jnp.asarray(v),))
    rev = np.einsum("abij,ij->ab", jax.jacrev(lambda x: moments(x, jnp.asarray(w)))(x), v)
    np.testing.assert_allclose(fwd, fd, atol=tol.FD_ABS * np.abs(fd).max())
    np.testing.assert_allclose(rev, fwd, rtol=1e-12, atol=1e-12)

    def normalised(x):
        return normalised_moments(x, jnp.asarray(w))[0]

    J_fwd = jax.jacfwd(normalised)(jnp.asarray(x))
    J_rev = jax.jacrev(normalised)(jnp.asarray(x))
    np.testing.assert_allclose(J_fwd, J_rev, rtol=1e-10, atol=1e-12)


def test_normalised_moments_are_the_moments_of_the_normalised_samples():
    """The batch's one pass (mean, then power sums about it, the scale from those sums) against
    centre_and_scale then moments of (x - mean) / scale, on a sphere far off the origin (raw
    counts: centre 30,000, radius 16,000) with padding rows holding NaN: the same numbers to
    round-off (the scale divides each sum by a power of it: no cancellation)."""
    from calib_jax.geometry import centre_and_scale, normalised_moments

    rng = np.random.default_rng(1)
    d = rng.normal(size=(300, 3))
    x = 30_000 + 16_000 * d / np.linalg.norm(d, axis=1, keepdims=True)
    x[-20:] = np.nan  # padding
    w = np.r_[rng.uniform(0.5, 2.0, 280), np.zeros(20)]
    S, mean, k = normalised_moments(jnp.asarray(x), jnp.asarray(w))
    m0, k0 = centre_and_scale(jnp.asarray(x), jnp.asarray(w))
    xn = (np.nan_to_num(x) - np.asarray(m0)) / float(k0)
    np.testing.assert_allclose(mean, m0, rtol=1e-14)
    np.testing.assert_allclose(k, k0, rtol=1e-13)
    ref = np.asarray(moments(jnp.asarray(xn), jnp.asarray(w)))
    np.testing.assert_allclose(S, ref, rtol=1e-12, atol=1e-12 * w.sum())


def test_the_logs_notes_are_notes_and_left_out_samples_are_warnings(tmp_path):
    """A headerless log's loader note (how its columns were read) is among the record's notes,
    and the rows left out (NaN) are a warning, not a note. Before, calibrate_mag replaced the
    loader's notes by the screening's warnings, so they were lost and the warnings doubled."""
    import calib_jax as cj

    x, _, _ = ellipsoid_points(2)
    x = np.array(x)
    x[5] = np.nan
    np.savetxt(tmp_path / "m.csv", x, delimiter=",")
    log = cj.load_log(tmp_path / "m.csv", sensor="mag")
    assert log.notes
    cal = calibrate_mag(log, model="full")
    assert cal.notes == list(log.notes)
    left_out = "rows with NaN or inf were left out of the fit"
    assert any(left_out in w for w in cal.warnings) and not any(left_out in n for n in cal.notes)
    # a unit the column names state labels the record (phyphox's 'X (µT)' was 'raw units');
    # units= still wins
    named = tmp_path / "named.csv"
    np.savetxt(named, x, delimiter=",", header="X (µT),Y (µT),Z (µT)", comments="")
    assert calibrate_mag(named, model="full").units == "uT"
    assert calibrate_mag(named, model="full", units="counts").units == "counts"


@pytest.mark.parametrize("model", ["auto", "sphere"])
def test_long_logs_are_fitted_from_their_moments_with_the_same_answer(model, monkeypatch):
    """Above MOMENT_FORM_ABOVE samples calibrate_mag fits the same chi2 from the samples'
    moment matrix (memory independent of the length: a 3-hour 1 kHz log needed over 10 GB
    the per-sample way). Forced on 20,000 samples here: the same model chosen, the centre and
    W to 1e-6 of their standard errors (measured: 2.5e-9; a sphere's W, exactly I, 1e-16
    absolute), the standard errors to 1e-5 relative (the moment form carries chi2 to about
    eps / rms^2 relative: rms 0.5 % here; measured 8e-10) and the same errors."""
    import calib_jax.mag as mag

    x, _, _ = ellipsoid_points(4, n=20_000)
    ref = calibrate_mag(x, model=model)
    monkeypatch.setattr(mag, "MOMENT_FORM_ABOVE", 1000)
    big = calibrate_mag(x, model=model)
    assert big.model == ref.model and big.status == ref.status == "ok"
    for v, e in (("center", "stderr_center"), ("soft_iron", "stderr_soft_iron")):
        # a sphere's W is exactly I with round-off standard errors (1e-19): floor them at 1e-9
        z = np.abs(getattr(big, v) - getattr(ref, v)) / np.maximum(getattr(ref, e), 1e-9)
        assert z.max() < 1e-6, (v, z)
        np.testing.assert_allclose(getattr(big, e), getattr(ref, e), rtol=1e-5, atol=1e-15)
    assert big.rms_after_pct == pytest.approx(ref.rms_after_pct, rel=1e-9)


def test_cell_hits_in_chunks_count_as_at_once():
    """sphere.cell_hits counts in chunks (bounded memory on long logs): any chunk size gives
    the counts of one product over all directions, and every direction is counted."""
    from calib_jax.sphere import cell_hits, sphere_cells

    d = random_directions(1000, 3)
    whole = np.bincount(np.argmax(d @ sphere_cells(100).T, axis=1), minlength=100)
    for chunk in (1, 7, 1000, 4096):
        np.testing.assert_array_equal(cell_hits(d, chunk=chunk), whole)
    assert whole.sum() == 1000


def test_a_hard_iron_that_jumps_in_a_noisy_log_is_not_ok():
    """A FreeIMU HMC5883L log (MapleHan/freeimu_gui, GPL-3) whose hard iron moved during the
    recording left 10.3 % after the full ellipsoid, 3.4x its sample-to-sample noise, and was
    'ok' without a word: above 5 % only a residual 6x the noise was judged implausible. Known
    truth: a smooth tumble with 3 % noise per axis is ok (3.0 %); the same with the hard iron
    jumping by 0.45 of the field halfway leaves 7.5 %, 2.5x the noise: poorly determined,
    with the warning that says why. The noise-dominated QMC5883L log (6.2 %, 1.1x its noise)
    stays ok (test_mag_real)."""
    n = 4000
    t = np.linspace(0, 1, n)
    th, ph = np.arccos(1 - 2 * t), 40 * np.pi * t
    d = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], 1)
    rng = np.random.default_rng(0)
    for jump, status in ((0.0, "ok"), (0.45, "poorly_determined")):
        shift = np.where(t[:, None] > 0.5, jump * 40 * np.array([0.6, 0.8, 0.0]), 0.0)
        x = 40 * d + np.array([10.0, -5.0, 3.0]) + shift + 1.2 * rng.normal(size=d.shape)
        cal = calibrate_mag(x)
        assert cal.status == status, (jump, cal.rms_after_pct, cal.warnings)
    assert any(w.startswith("implausible residual") for w in cal.warnings), cal.warnings


def test_a_noisy_turn_about_one_axis_is_rejected_too():
    """uBot's LSM303 on a robot turning on the floor: the field draws a noisy arc (thickness
    ~5 % of its radius), calib-jax mag exited 0 with a hard iron along the turn axis. The
    directions about a sphere fitted through a noisy circle look like a cone, so the flatness
    is judged on the samples themselves as well."""
    rng = np.random.default_rng(3)
    t = np.linspace(0, 2 * np.pi, 800)
    x = np.stack([12 * np.cos(t), 12 * np.sin(t), 0 * t], 1) + [-56.0, -59.0, -1.0]
    x += 0.55 * rng.normal(size=x.shape)
    with pytest.raises(ValueError, match="one plane.*Tumble"):
        calibrate_mag(x)
    # the batch judges it by the same threshold (its own, 5x lower, calibrated a compass
    # turned flat on a table that calib-jax mag refused: bugplus/magnetic-tools, MIT)
    from calib_jax.batch import calibrate_mag_batch
    from calib_jax.lm import Status

    assert int(calibrate_mag_batch(x[None]).status[0]) == Status.NO_COVERAGE
    # and the same magnetometer held still (noise 0.6 per axis about a reading of length 81):
    # the batch fitted a sphere to the noise ball and called it "ok"; calibrate_mag says the
    # field "barely changes"
    still = [-56.0, -59.0, -1.0] + 0.6 * rng.normal(size=x.shape)
    assert int(calibrate_mag_batch(still[None]).status[0]) == Status.NO_SHELL


def test_the_uncentred_before_is_left_out_where_the_offset_dwarfs_the_field():
    """With a hard iron 13 times the field (a phone: 585 against 45 uT) |raw| varies by about
    r / |c| whatever the calibration; the report printed 'before 41.5 % (...; 3.951 %
    uncentred), after 5.349 %', which a new user read as the fit making things worse. Beyond
    three times the field only the centred 'before' is printed; near zero both are."""
    rng = np.random.default_rng(3)
    d = rng.normal(size=(2000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    for centre, shown in (([218.0, 65.0, -538.0], False), ([5.0, -3.0, 4.0], True)):
        cal = calibrate_mag(45 * d + centre + 0.3 * rng.normal(size=d.shape))
        line = next(ln for ln in cal.report().splitlines() if ln.startswith("RMS of"))
        assert ("uncentred" in line) is shown, line
        assert np.isfinite(cal.rms_raw_pct)  # kept in the record either way


def test_a_report_without_units_names_the_unit_the_radius_says():
    """A trial's gauss log (sunsided/sensor-fusion's HMC5883L) read "radius after 0.532035 raw
    units": Earth's field is 25-65 uT, that is 0.25-0.65 gauss or 250-650 mG, so a radius in
    one of those ranges names its unit, by its size; a unit given, or a radius in none of
    them (counts), names none. Truth: the simulated radius."""
    d = random_directions(600, np.random.default_rng(2))
    for radius, said in ((0.53, "gauss"), (48.0, "uT"), (480.0, "mG"), (1500.0, None)):
        x = radius * d + [0.1 * radius, -0.2 * radius, 0.05 * radius]
        cal = calibrate_mag(x, model="sphere")
        assert abs(cal.radius / radius - 1) < 1e-6, cal.radius
        hint = [line for line in cal.report().splitlines() if "by its size" in line]
        if said is None:
            assert not hint, hint
        else:
            assert len(hint) == 1 and f"Earth's field in {said}, by its size" in hint[0], hint
        given = calibrate_mag(x, model="sphere", units="counts")
        assert "by its size" not in given.report()


def test_honest_standard_errors_follow_the_spread_over_correlated_noise():
    """The block jackknife's errors of the centre and W match the spread of the estimates
    over noise draws on one tumble, where the formal errors (independent samples) fall short:
    noise correlated over 1 s (AR(1), lag-1 0.98 at 50 Hz). benchmarks/mag_stderr.py, 40 draws
    each: jackknife / spread 1.00 (formal 0.11); white noise 1.03 (formal 1.03). Here 12 draws:
    the spread of 12 is known to about 20 %, so the ratio is asked within 0.5-2 and the formal
    one under 0.3; the white-noise log's jackknife agrees with its formal errors within 2x."""
    from calib_jax.simulate import correlated_noise, simulate_mag_log

    clean = simulate_mag_log(("soft_iron",), size=0.05, samples=6000, rest=0, noise=0.0, seed=0)
    cols = [0, 1, 2, 3, 4, 5, 7, 8, 11]  # the centre and W's upper triangle
    est, formal, honest = [], [], []
    for seed in range(1, 13):
        cal = calibrate_mag(clean.raw + correlated_noise(6000, 5e-3, 0.98, seed), model="full")
        est.append(np.r_[cal.center, cal.soft_iron.ravel()][cols])
        formal.append(np.r_[cal.stderr_center, cal.stderr_soft_iron.ravel()][cols])
        honest.append(np.r_[cal.stderr_center_honest, cal.stderr_soft_iron_honest.ravel()][cols])
    spread = np.std(est, axis=0, ddof=1)
    assert 0.5 < np.median(np.median(honest, axis=0) / spread) < 2.0
    assert np.median(np.median(formal, axis=0) / spread) < 0.3
    white = calibrate_mag(clean.raw + correlated_noise(6000, 5e-3, 0.0, 99), model="full")
    assert cal.center_stderr is cal.stderr_center_honest and cal.honest
    ratio = white.stderr_center_honest / white.stderr_center
    assert np.all((ratio > 0.5) & (ratio < 2.0)), ratio


def test_honest_errors_round_trip_and_older_files_have_none(tmp_path):
    """The JSON holds the honest errors beside the formal ones; a file written before them
    loads with NaN (not measured), and its report quotes the formal errors alone."""
    rng = np.random.default_rng(3)
    x = random_directions(2000, rng) * 40.0 + np.array([5.0, -3.0, 2.0])
    cal = calibrate_mag(x + 0.2 * rng.normal(size=x.shape), model="sphere")
    assert cal.honest
    path = tmp_path / "mag.json"
    cal.save(path)
    back = MagCalibration.load(path)
    assert back == cal
    np.testing.assert_array_equal(back.stderr_center_honest, cal.stderr_center_honest)
    d = json.loads(path.read_text())
    assert d["stderr"]["honest"]["method"].startswith("block jackknife")
    del d["stderr"]["honest"]
    old = MagCalibration.from_dict(d)
    assert not old.honest and np.all(np.isnan(old.stderr_soft_iron_honest))
    assert "formal" not in old.report() and "block jackknife" in cal.report()


def test_too_short_a_log_has_no_honest_errors():
    """Under 8 blocks of 50 samples the jackknife is not run: NaN, and the formal errors are
    the ones quoted."""
    rng = np.random.default_rng(4)
    x = random_directions(300, rng) * 40.0
    cal = calibrate_mag(x + 0.2 * rng.normal(size=x.shape), model="sphere")
    assert not cal.honest
    np.testing.assert_array_equal(cal.center_stderr, cal.stderr_center)
