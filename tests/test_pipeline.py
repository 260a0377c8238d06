"""calib_jax.pipeline as a JAX library (issue 7): pytrees, jit/vmap/grad in every order,
implicit gradients of the public fits, uncertainty to calibrated samples and attitude against
Monte Carlo, float32 and float64."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.flatten_util import ravel_pytree

import calib_jax as cj
from calib_jax import export
from calib_jax import pipeline as pl
from calib_jax.attitude import reference_vectors
from calib_jax.models.accel import distort
from calib_jax.observations import accel_observations
from calib_jax.rotations import rotvec_to_dcm

RNG = np.random.default_rng(7)
N_ACC, N_MAG = 30, 60
SIG_A, SIG_M = 2e-3, 1e-2  # accel noise (g), mag noise (unit field)
P_ACC = np.array([1.02, 0.98, 1.01, 0.01, -0.02, 0.005, 0.03, -0.01, 0.02])
W_MAG = np.array([[1.1, 0.05, 0.02], [0.05, 0.9, -0.03], [0.02, -0.03, 1.0]])
C_MAG = np.array([0.3, -0.2, 0.1])


def _dirs(n, rng):
    d = rng.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


D_ACC = _dirs(N_ACC, RNG)
D_MAG = _dirs(N_MAG, RNG)
CLEAN_ACC = np.asarray(distort(jnp.asarray(P_ACC), jnp.asarray(D_ACC)))
CLEAN_MAG = D_MAG @ np.linalg.inv(W_MAG).T + C_MAG


def _noisy(rng):
    return (
        CLEAN_ACC + SIG_A * rng.normal(size=CLEAN_ACC.shape),
        CLEAN_MAG + SIG_M * rng.normal(size=CLEAN_MAG.shape),
    )


ACC, MAG = _noisy(RNG)
FIT_A = jax.jit(pl.fit_accel, static_argnames=("max_iter", "absolute_sigma"))
FIT_M = jax.jit(pl.fit_mag, static_argnames=("max_iter", "absolute_sigma"))
DIP = 65.0


@pytest.fixture(scope="module")
def fits():
    return FIT_A(jnp.asarray(ACC), 1.0), FIT_M(jnp.asarray(MAG), 1.0)


def fd_grad(f, x, h):
    """Central differences of a scalar f along every entry of a flat vector x."""
    x = np.asarray(x, float)
    g = np.zeros_like(x)
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = h
        g[i] = (float(f(x + e)) - float(f(x - e))) / (2 * h)
    return g


# ---------------------------------------------------------------------------------------------
# fits recover the truth, the public objects are pytrees


def test_fits_recover_the_truth(fits, tol):
    fa, fm = fits
    assert bool(fa.converged) and bool(fm.converged)
    pa = np.asarray(fa.params.to_vector())
    assert np.all(np.abs(pa - P_ACC) < tol.N_SIGMA * np.asarray(fa.stderr)), pa - P_ACC
    flat = np.asarray(ravel_pytree(fm.params)[0])
    truth = np.concatenate([C_MAG, W_MAG.ravel()])
    assert np.all(np.abs(flat - truth) < tol.N_SIGMA * np.asarray(fm.stderr)), flat - truth
    # the residual at the optimum is the noise: rms ~ sigma (accel: 1 dof of 3 per sample)
    assert 0.5 * SIG_A < float(fa.rms) < 1.5 * SIG_A
    assert 0.5 * SIG_M < float(fm.rms) < 1.5 * SIG_M
    # pytrees: leaves are arrays, tree_map works, covariance matches ravel_pytree order
    assert len(jax.tree_util.tree_leaves(fa)) == 7
    assert fm.covariance.shape == (12, 12)


def test_fit_keeps_the_magnitude_unit(fits):
    """magnitude sets the output unit: a field of 48 uT gives outputs of 48 and a W 48 times
    larger, with the same hard iron."""
    fm48 = FIT_M(jnp.asarray(MAG), 48.0)
    np.testing.assert_allclose(fm48.params.soft_iron, 48.0 * fits[1].params.soft_iron, rtol=1e-9)
    np.testing.assert_allclose(fm48.params.hard_iron, fits[1].params.hard_iron, atol=1e-10)
    y = pl.apply(fm48.params, jnp.asarray(MAG))
    assert abs(float(jnp.mean(jnp.linalg.norm(y, axis=1))) - 48.0) < 0.1


@pytest.mark.wrong_types
def test_bad_input_says_what_to_change():
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        pl.fit_accel(jnp.zeros((20, 2)))
    with pytest.raises(ValueError, match="record >= 10"):
        pl.fit_mag(jnp.asarray(MAG[:5]))
    with pytest.raises(ValueError, match="one per sample"):
        pl.fit_accel(jnp.asarray(ACC), 1.0, jnp.ones(N_ACC + 1))
    with pytest.raises(ValueError, match="magnitude must be a scalar"):
        pl.fit_accel(jnp.asarray(ACC), jnp.ones(2))
    with pytest.raises(ValueError, match=r"\(S, N, 3\)"):
        pl.fit_batch(pl.fit_accel, jnp.asarray(ACC))
    # a Python user's trial: a KeyError, a 53-line dtype error, a broadcasting error from
    # inside JAX, and TracerArrayConversionError, each now says what to change
    with pytest.raises(ValueError, match="model must be one of sphere, diag, full"):
        pl.fit_mag(jnp.asarray(MAG), 1.0, model="ellipsoid")
    with pytest.raises(ValueError, match="magnitude must be a number, got the string '9.81'"):
        pl.fit_accel(jnp.asarray(ACC), "9.81")
    params = pl.AccelParams(jnp.ones(3), jnp.zeros(3), jnp.zeros(3))
    with pytest.raises(ValueError, match=r"got shape \(3, \d+\) \(transposed\? pass raw.T\)"):
        pl.apply(params, jnp.asarray(ACC[:20]).T)
    np.testing.assert_array_equal(pl.apply(params, ACC[:4].tolist()), ACC[:4])  # a list
    cal = cj.AccelCalibration.from_params(params, g=1.0)
    np.testing.assert_array_equal(pl.apply(cal, ACC[:4]), ACC[:4])  # a record, outside jit
    with pytest.raises(TypeError, match=r"inside jit.*pipeline.apply\(cal.to_params\(\), raw\)"):
        jax.jit(cal.apply)(jnp.asarray(ACC[:4]))


def test_integer_counts_keep_a_float_magnitude(fits):
    """Raw int16-like counts: the fleet fit must not truncate 9.80665 to the data's dtype."""
    counts = jnp.asarray(np.round(ACC * 2000.0).astype(np.int32))[None]
    fb = pl.fit_batch(pl.fit_accel, counts, 9.80665)
    a = pl.apply(jax.tree_util.tree_map(lambda x: x[0], fb.params), counts[0].astype(float))
    assert abs(float(jnp.mean(jnp.linalg.norm(a, axis=1))) - 9.80665) < 0.01
    # and every calibration has the same apply method
    np.testing.assert_allclose(
        fits[0].params.apply(jnp.asarray(ACC)), pl.apply(fits[0].params, jnp.asarray(ACC))
    )


def test_fit_accel_is_calibrate_accel(sim48):
    """One residual on every path: fit_accel on calibrate_accel's fit points (the interval
    means) gives its parameters and standard errors. The two normalise differently and their
    solvers stop at different round-off points: measured 2e-7 standard errors apart; with
    |a| / g - 1 as the residual (before this test) they were 1.6e-3 SE apart."""
    cal = cj.calibrate_accel(sim48.raw)
    points = accel_observations(sim48.raw).points
    assert len(points) == cal.n_intervals == 48
    f = pl.fit_accel(jnp.asarray(points), cal.g)
    dp = np.asarray(f.params.to_vector()) - cal.params
    assert np.all(np.abs(dp) < 1e-5 * cal.stderr), dp / cal.stderr
    np.testing.assert_allclose(np.asarray(f.stderr), cal.stderr, rtol=1e-8)


def test_a_sensor_held_still_is_refused_and_a_nan_row_is_masked(fits):
    """The batch's checks, inside jit. One pose held still was fitted through its noise cloud
    (fit_mag: converged; fit_accel: gains of 1.0-1.6 from 1e-3 g of noise). The magnetometer's
    sphere through the cloud is now NO_SHELL (its RMS radial error far above
    calib_jax.geometry.NO_SHELL, 12 %), the accelerometer's ellipsoid about 1,000 times the
    cloud's spread RAN_AWAY (calib_jax.geometry.RUNAWAY, 10). Poses in one plane
    are NO_COVERAGE before the fit, with NaN parameters. A row with a NaN made the whole fit
    NONFINITE; it is masked out as in the batch, so the fit equals the fit with that row's
    weight 0 (the same arithmetic: to round-off)."""
    rng = np.random.default_rng(11)
    Status = cj.lm.Status
    # the shapes of `fits`: no new compilation
    for fit, raw, code in ((FIT_A, ACC, Status.RAN_AWAY), (FIT_M, MAG, Status.NO_SHELL)):
        still = raw[0] + 1e-3 * rng.normal(size=raw.shape)
        f = fit(jnp.asarray(still), 1.0)
        assert int(f.status) == code and not bool(f.converged)
        assert f.message.startswith("no calibration:"), f.message
        record = cj.AccelCalibration if fit is FIT_A else cj.MagCalibration
        rec = record.from_fit(f, still, 1.0)
        assert rec.status == "failed"
        assert not any("the magnitude the fit was given" in w for w in rec.warnings)
        flat = raw.copy()
        flat[:, 2] = 0.3
        f = fit(jnp.asarray(flat), 1.0)
        assert int(f.status) == cj.lm.Status.NO_COVERAGE
        assert np.all(np.isnan(ravel_pytree(f.params)[0])) and np.isnan(float(f.rms))
    bad = ACC.copy()
    bad[5, 1] = np.nan
    w = np.ones(N_ACC)
    w[5] = 0.0
    f_nan = FIT_A(jnp.asarray(bad), 1.0)
    f_w0 = FIT_A(jnp.asarray(ACC), 1.0, jnp.asarray(w))
    # weights that sum to 1 are as many rows as weights of 1 (the row count is checked, not
    # the weights' sum: a first version refused them as INSUFFICIENT_DATA)
    f_unit = FIT_A(jnp.asarray(ACC), 1.0, jnp.full(N_ACC, 1.0 / N_ACC))
    assert bool(f_unit.converged), f_unit.message
    np.testing.assert_allclose(
        ravel_pytree(f_unit.params)[0], ravel_pytree(fits[0].params)[0], rtol=1e-7, atol=1e-9
    )
    assert bool(f_nan.converged)
    np.testing.assert_allclose(
        ravel_pytree(f_nan.params)[0], ravel_pytree(f_w0.params)[0], rtol=1e-12, atol=1e-14
    )
    # and the masked fit is a different fit from the full one (the row counted there)
    assert not np.allclose(ravel_pytree(f_nan.params)[0], ravel_pytree(fits[0].params)[0])


def test_not_converged_is_reported():
    f = FIT_A(jnp.asarray(ACC), 1.0, max_iter=1)
    assert not bool(f.converged)


# ---------------------------------------------------------------------------------------------
# derivatives against finite differences


def _marg(fa, fm):
    return pl.MargParams(fa.params, fm.params, pl.Rotation(jnp.array([0.01, -0.02, 0.03])))


def _check_grad(f, params, h=1e-6, rtol=1e-6):
    """grad of a scalar f(params) against central differences over ravel_pytree(params).

    Central differences with h = 1e-6 on O(1) functions: truncation h^2 f''' ~ 1e-12,
    round-off eps / h ~ 1e-10; the tolerance 1e-6 of the gradient's scale leaves room for
    the Gauss-Newton iterations' conditioning."""
    flat, unravel = ravel_pytree(params)
    g = ravel_pytree(jax.grad(f)(params))[0]
    fj = jax.jit(lambda v: f(unravel(v)))
    g_fd = fd_grad(fj, flat, h)
    np.testing.assert_allclose(np.asarray(g), g_fd, atol=rtol * np.abs(g_fd).max())


def test_apply_and_residual_gradients(fits):
    fa, fm = fits
    a, m = jnp.asarray(ACC[:8]), jnp.asarray(MAG[:8])
    _check_grad(lambda p: jnp.sum(jnp.sin(pl.apply(p, a))), fa.params)
    _check_grad(lambda p: jnp.sum(jnp.sin(pl.apply(p, m))), fm.params)
    _check_grad(lambda p: jnp.sum(jnp.sin(jnp.stack(pl.apply(p, a, m)))), _marg(fa, fm))
    _check_grad(lambda p: jnp.sum(pl.residual(p, a, 1.0) ** 2), fa.params)
    _check_grad(lambda p: jnp.sum(pl.residual(p, m, 1.3) ** 2), fm.params)
    # and in the data and the magnitude
    ga = jax.grad(lambda x, g: jnp.sum(pl.residual(fa.params, x, g) ** 3), (0, 1))(a, 1.1)
    fx = jax.jit(lambda v: jnp.sum(pl.residual(fa.params, v[:-1].reshape(8, 3), v[-1]) ** 3))
    g_fd = fd_grad(fx, np.append(np.asarray(a).ravel(), 1.1), 1e-6)
    np.testing.assert_allclose(np.append(np.ravel(ga[0]), ga[1]), g_fd, atol=1e-8)


def test_attitude_gradient(fits):
    """Through the calibration, the TRIAD start and six Gauss-Newton steps, in the parameters
    and in the dip."""
    fa, fm = fits
    a, m = jnp.asarray(ACC[:6]), jnp.asarray(MAG[:6])
    wq = jnp.asarray(RNG.normal(size=(6, 4)))

    def f(p, dip=DIP):
        return jnp.sum(wq * pl.attitude(p, a, m, dip))

    _check_grad(f, _marg(fa, fm), rtol=1e-6)
    gd = jax.grad(lambda d: f(_marg(fa, fm), d))(DIP)
    fd = (f(_marg(fa, fm), DIP + 1e-5) - f(_marg(fa, fm), DIP - 1e-5)) / 2e-5
    assert abs(float(gd) - float(fd)) < 1e-6 * max(1.0, abs(float(fd)))


def _gain_sum(raw, g=1.0, w=None):
    return jnp.sum(pl.fit_accel(raw, g, w).params.gains)


def test_fit_gradient_against_refits():
    """The implicit derivative of the public fit (through its internal normalisation) against
    central differences of full refits. The refits stop at relative steps of 1e-10 (eps2), so
    with h = 1e-5 the differences carry ~1e-5 relative noise: tolerance 1e-4."""
    raw = jnp.asarray(ACC)
    w = jnp.ones(N_ACC)
    g_raw, g_g, g_w = jax.jit(jax.grad(_gain_sum, (0, 1, 2)))(raw, 1.0, w)
    f = jax.jit(_gain_sum)
    h = 1e-5
    for i, j in [(0, 0), (11, 2), (29, 1)]:
        e = jnp.zeros_like(raw).at[i, j].set(h)
        fd = (f(raw + e) - f(raw - e)) / (2 * h)
        assert abs(float(g_raw[i, j] - fd)) < 1e-4 * float(jnp.abs(g_raw).max()), (i, j)
    fd = (f(raw, 1.0 + h) - f(raw, 1.0 - h)) / (2 * h)
    # exact law: alpha scales as 1 / g, so d(sum gains)/dg = -sum gains at g = 1
    assert abs(float(g_g - fd)) < 1e-4 * abs(float(fd))
    assert abs(float(g_g) + float(_gain_sum(raw))) < 1e-8
    # weight derivatives are ~1e-4 of the gains, so refit noise (1e-10 / 2h) needs a larger
    # step: h = 1e-2, truncation h^2 ~ 1e-4 relative
    hw = 1e-2
    for k in (4, 17):
        e = jnp.zeros(N_ACC).at[k].set(hw)
        fd = (f(raw, 1.0, w + e) - f(raw, 1.0, w - e)) / (2 * hw)
        assert abs(float(g_w[k] - fd)) < 1e-3 * float(jnp.abs(g_w).max()), k


def test_mag_fit_gradient_against_refits():
    raw = jnp.asarray(MAG)

    def f(r, b=1.0):
        p = pl.fit_mag(r, b).params
        return jnp.sum(p.soft_iron * jnp.arange(9.0).reshape(3, 3)) + jnp.sum(p.hard_iron)

    g_raw, g_b = jax.jit(jax.grad(f, (0, 1)))(raw, 1.0)
    fj = jax.jit(f)
    h = 1e-5
    for i, j in [(0, 0), (33, 2)]:
        e = jnp.zeros_like(raw).at[i, j].set(h)
        fd = (fj(raw + e) - fj(raw - e)) / (2 * h)
        assert abs(float(g_raw[i, j] - fd)) < 1e-4 * float(jnp.abs(g_raw).max()), (i, j)
    fd = (fj(raw, 1.0 + h) - fj(raw, 1.0 - h)) / (2 * h)
    assert abs(float(g_b - fd)) < 1e-4 * abs(float(fd))


# ---------------------------------------------------------------------------------------------
# jit, vmap and grad in every order

RAW2 = jnp.stack([jnp.asarray(ACC), jnp.asarray(_noisy(np.random.default_rng(3))[0])])


@pytest.fixture(scope="module")
def reference_grads():
    return np.stack([np.asarray(jax.jit(jax.grad(_gain_sum))(r)) for r in RAW2])


ORDERS = {
    "grad(jit)": lambda: np.stack([jax.grad(jax.jit(_gain_sum))(r) for r in RAW2]),
    "jit(vmap(grad))": lambda: jax.jit(jax.vmap(jax.grad(_gain_sum)))(RAW2),
    "vmap(jit(grad))": lambda: jax.vmap(jax.jit(jax.grad(_gain_sum)))(RAW2),
    "jit(grad(sum(vmap)))": lambda: jax.jit(jax.grad(lambda R: jnp.sum(jax.vmap(_gain_sum)(R))))(
        RAW2
    ),
    "grad(fit_batch)": lambda: jax.jit(
        jax.grad(lambda R: jnp.sum(pl.fit_batch(pl.fit_accel, R).params.gains))
    )(RAW2),
    "jit(jacrev)": lambda: np.stack([jax.jit(jax.jacrev(_gain_sum))(r) for r in RAW2]),
    "jit(jacfwd)": lambda: np.stack([jax.jit(jax.jacfwd(_gain_sum))(r) for r in RAW2]),
}


@pytest.mark.parametrize("order", list(ORDERS))
def test_fit_composes(order, reference_grads):
    """Every composition is the same derivative (one implicit solve at the optimum). Each
    compilation runs its own forward fit, which stops at relative steps below 1e-10 (eps2) at
    a slightly different point, so they agree to ~1e-9 of the scale, not to round-off."""
    g = np.asarray(ORDERS[order]())
    np.testing.assert_allclose(g, reference_grads, atol=1e-8 * np.abs(reference_grads).max())


def test_apply_residual_attitude_compose(fits):
    fa, fm = fits
    mp = _marg(fa, fm)
    batch = jnp.stack([jnp.asarray(ACC[:5]), jnp.asarray(ACC[5:10])])
    mags = jnp.stack([jnp.asarray(MAG[:5]), jnp.asarray(MAG[5:10])])

    def f(p, a, m):
        return jnp.sum(pl.attitude(p, a, m, DIP) ** 2 * jnp.arange(4.0)) + jnp.sum(
            pl.residual(p.acc, a) ** 2
        )

    ref = [jax.jit(jax.grad(f))(mp, a, m) for a, m in zip(batch, mags, strict=True)]
    ref = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *ref)
    variants = [
        jax.jit(jax.vmap(jax.grad(f), (None, 0, 0)))(mp, batch, mags),
        jax.vmap(jax.jit(jax.grad(f)), (None, 0, 0))(mp, batch, mags),
    ]
    gsum = jax.jit(jax.grad(lambda p: jnp.sum(jax.vmap(f, (None, 0, 0))(p, batch, mags))))(mp)
    for v in variants:
        for x, y in zip(jax.tree_util.tree_leaves(v), jax.tree_util.tree_leaves(ref), strict=True):
            np.testing.assert_allclose(x, y, rtol=1e-10, atol=1e-14)  # summation order
    for x, y in zip(jax.tree_util.tree_leaves(gsum), jax.tree_util.tree_leaves(ref), strict=True):
        np.testing.assert_allclose(x, y.sum(0), rtol=1e-10, atol=1e-14)
    # vmap over calibrations too (a fleet of boards)
    mps = jax.tree_util.tree_map(lambda x: jnp.stack([x, 1.01 * x]), mp)
    q = jax.jit(jax.vmap(pl.attitude, (0, None, None, None)))(mps, batch[0], mags[0], DIP)
    assert q.shape == (2, 5, 4) and bool(jnp.all(jnp.isfinite(q)))


def test_fit_batch_equals_single_fits_and_masks_padding():
    fb = pl.fit_batch(pl.fit_accel, RAW2)
    for k in range(2):
        fk = FIT_A(RAW2[k], 1.0)
        np.testing.assert_allclose(fb.params.to_vector()[k], fk.params.to_vector(), atol=1e-12)
    # a sensor with 5 padded rows (zero weight) equals the fit without them
    padded = jnp.concatenate([RAW2[1], jnp.full((5, 3), 7.0)])
    w = jnp.concatenate([jnp.ones(N_ACC), jnp.zeros(5)])
    fp = FIT_A(padded, 1.0, w)
    # The padded rows change the order of the sums, so the two fits stop at different points
    # of the round-off plateau of chi2: the solver's round-off stop (CONVERGED_ROUNDOFF, see
    # calib_jax.lm.gavin) accepts any point whose chi2 is within B = 4 eps (sqrt(m) chi2 +
    # 2 sum w |e| s) of the minimum. There chi2 - chi2_min = dp' J'WJ dp, so each fit lies
    # within sqrt(B (m - n) / chi2) standard errors of the optimum and the two within twice
    # that (s ~ 1 + |e|: the residual |a| / g - 1 is a difference of terms of size 1). On this
    # board that is ~1e-5 standard errors, ~1e-8 relative: an rtol of 1e-9 passed or failed
    # with the CPU's floating-point path (8.3e-9 seen on CI's machine).
    a, b = np.asarray(fp.params.to_vector()), np.asarray(fb.params.to_vector()[1])
    e = np.asarray(pl.residual(fp.params, RAW2[1], 1.0))
    m, n = e.size, a.size
    chi2 = float(e @ e)
    eps = np.finfo(np.float64).eps
    bound = 4 * eps * (np.sqrt(m) * chi2 + 2 * np.sum(np.abs(e) * (1 + np.abs(e))))
    radius = np.sqrt(bound * (m - n) / chi2)
    assert np.all(np.abs(a - b) <= 2 * radius * np.asarray(fp.stderr)), (
        (a - b) / np.asarray(fp.stderr),
        radius,
    )


# ---------------------------------------------------------------------------------------------
# uncertainty to the outputs against Monte Carlo

K_MC = 400


@pytest.fixture(scope="module")
def monte_carlo():
    """K_MC noisy repeats of the same recording, each fitted (vmapped); the spread of the
    outputs is the truth the propagated covariance must match."""
    rng = np.random.default_rng(11)
    draws = [_noisy(rng) for _ in range(K_MC)]
    A = jnp.asarray(np.stack([d[0] for d in draws]))
    M = jnp.asarray(np.stack([d[1] for d in draws]))
    wa = jnp.full((K_MC, N_ACC), 1.0 / SIG_A**2)
    # both residuals are |y| / magnitude - 1, whose sigma is the noise along the radius
    fa = jax.jit(lambda R, W: pl.fit_batch(pl.fit_accel, R, 1.0, W, absolute_sigma=True))(A, wa)
    wm = jnp.full((K_MC, N_MAG), 1.0 / SIG_M**2)
    fm = jax.jit(lambda R, W: pl.fit_batch(pl.fit_mag, R, 1.0, W, absolute_sigma=True))(M, wm)
    assert bool(jnp.all(fa.converged)) and bool(jnp.all(fm.converged))
    return fa, fm


# test poses: attitude of 5 board orientations, raw readings made with the true calibration
R_TEST = [
    np.asarray(rotvec_to_dcm(jnp.asarray(v)))
    for v in _dirs(5, RNG) * [[0.3], [1], [2], [2.5], [0.8]]
]
R_A, R_M = (np.asarray(v) for v in reference_vectors(DIP))
A_TEST = np.asarray(distort(jnp.asarray(P_ACC), jnp.asarray(np.stack([R.T @ R_A for R in R_TEST]))))
M_TEST = np.stack([R.T @ R_M for R in R_TEST]) @ np.linalg.inv(W_MAG).T + C_MAG


def _ratio_ok(propagated, mc, name):
    """With K_MC = 400 repeats the Monte Carlo std has ~3.5 % relative error (1/sqrt(2K)); the
    first-order propagation is exact for the linear apply and differs at second order for
    the fit and the attitude. Each ratio within [0.8, 1.25], their median within 10 %."""
    r = np.asarray(propagated) / np.asarray(mc)
    assert np.all((r > 0.8) & (r < 1.25)), f"{name}: {r}"
    assert abs(np.median(r) - 1.0) < 0.1, f"{name}: {r}"


def test_covariance_to_calibrated_samples(monte_carlo):
    fa, fm = monte_carlo
    one_a = jax.tree_util.tree_map(lambda x: x[0], fa)
    C = pl.calibrated_covariance(one_a.params, one_a.covariance, jnp.asarray(A_TEST))
    mc = jax.vmap(lambda p: pl.apply(p, jnp.asarray(A_TEST)))(fa.params)
    _ratio_ok(np.sqrt(np.diagonal(C, axis1=1, axis2=2)), np.std(np.asarray(mc), axis=0), "acc")
    one_m = jax.tree_util.tree_map(lambda x: x[0], fm)
    C = pl.calibrated_covariance(one_m.params, one_m.covariance, jnp.asarray(M_TEST))
    mc = jax.vmap(lambda p: pl.apply(p, jnp.asarray(M_TEST)))(fm.params)
    _ratio_ok(np.sqrt(np.diagonal(C, axis1=1, axis2=2)), np.std(np.asarray(mc), axis=0), "mag")


def test_covariance_to_roll_pitch_yaw(monte_carlo):
    fa, fm = monte_carlo
    rot = pl.Rotation.identity()

    def marg(a, m):
        return pl.MargParams(a, m, rot)

    one = marg(
        jax.tree_util.tree_map(lambda x: x[0], fa.params),
        jax.tree_util.tree_map(lambda x: x[0], fm.params),
    )
    cov = pl.block_covariance(fa.covariance[0], fm.covariance[0], jnp.zeros((3, 3)))
    std = pl.attitude_std(one, cov, jnp.asarray(A_TEST), jnp.asarray(M_TEST), DIP)
    eul = jax.jit(
        jax.vmap(
            lambda a, m: pl.euler_deg(
                pl.attitude(marg(a, m), jnp.asarray(A_TEST), jnp.asarray(M_TEST), DIP)
            )
        )
    )(fa.params, fm.params)
    eul = np.asarray(eul)
    d = (eul - eul[:1] + 180.0) % 360.0 - 180.0  # wrap yaw before the spread
    mc = np.std(d, axis=0)
    assert np.all(np.asarray(std) > 0.01)  # not vacuous: tenths of a degree
    _ratio_ok(std, mc, "roll/pitch/yaw")


# ---------------------------------------------------------------------------------------------
# float32


def test_float32_runs_with_documented_accuracy(fits):
    """float32 in, float32 out. The fits (on data normalised to unit scale) stop at float32
    round-off near the float64 optimum, at a point that depends on the data's rounding, so the
    bounds come from 40 simulated boards like this one (benchmarks/float32_accuracy.py,
    largest difference over them in brackets; this test's board lands closer):
    parameters within 3 % of their standard error (1 %, 8.4e-6 absolute), the implicit
    derivative within 3e-4 of its scale (5.2e-5), roll/pitch/yaw within 5e-3 deg (1.8e-3).
    docs/pipeline.md quotes these bounds."""
    fa, fm = fits
    a32, m32 = jnp.asarray(ACC, jnp.float32), jnp.asarray(MAG, jnp.float32)
    fa32 = FIT_A(a32, jnp.float32(1.0))
    fm32 = FIT_M(m32, jnp.float32(1.0))
    assert fa32.params.gains.dtype == jnp.float32 and fm32.params.soft_iron.dtype == jnp.float32
    assert bool(fa32.converged) and bool(fm32.converged)
    d_acc = np.abs(np.asarray(fa32.params.to_vector()) - np.asarray(fa.params.to_vector()))
    assert np.all(d_acc < 0.03 * np.asarray(fa.stderr)), d_acc / np.asarray(fa.stderr)
    d_mag = np.abs(
        np.asarray(ravel_pytree(fm32.params)[0]) - np.asarray(ravel_pytree(fm.params)[0])
    )
    assert np.all(d_mag < 0.03 * np.asarray(fm.stderr)), d_mag / np.asarray(fm.stderr)
    g32 = jax.jit(jax.grad(_gain_sum))(a32, jnp.float32(1.0))
    g64 = jax.jit(jax.grad(_gain_sum))(jnp.asarray(ACC), 1.0)
    assert g32.dtype == jnp.float32
    np.testing.assert_allclose(g32, g64, atol=3e-4 * float(jnp.abs(g64).max()))
    mp32 = pl.MargParams(fa32.params, fm32.params, pl.Rotation.identity(jnp.float32))
    e32 = pl.euler_deg(
        pl.attitude(
            mp32,
            jnp.asarray(A_TEST, jnp.float32),
            jnp.asarray(M_TEST, jnp.float32),
            jnp.float32(DIP),
        )
    )
    mp64 = pl.MargParams(fa.params, fm.params, pl.Rotation.identity())
    e64 = pl.euler_deg(pl.attitude(mp64, jnp.asarray(A_TEST), jnp.asarray(M_TEST), DIP))
    assert e32.dtype == jnp.float32
    np.testing.assert_allclose(e32, e64, atol=5e-3)


# ---------------------------------------------------------------------------------------------
# records <-> pytrees


def test_pipeline_fits_become_records_that_round_trip(fits, tmp_path):
    """Issue 14: a pipeline Fit becomes the same record a calibrate_* call returns (from_fit),
    which saves, loads, compares equal and converts back to the Fit's pytree exactly; its
    standard errors are the Fit's, and for the magnetometer also calibrate_mag's on the same
    samples (one core: to 1e-6 relative, the two normalise with their own sums)."""
    fa, fm = fits
    acc = cj.AccelCalibration.from_fit(fa, ACC, 1.0, sensor_id="board-1")
    mag = cj.MagCalibration.from_fit(fm, MAG, 1.0, units="unit field")
    assert acc.status == "ok" and mag.status == "ok"
    assert any("no pose detection" in n for n in acc.notes)
    for rec, fit in ((acc, fa), (mag, fm)):
        path = tmp_path / f"{type(rec).__name__}.json"
        rec.save(path)
        back = type(rec).load(path)
        assert back == rec
        p = back.to_params()
        for x, y in zip(jax.tree.leaves(p), jax.tree.leaves(fit.params), strict=True):
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    np.testing.assert_allclose(acc.stderr, fa.stderr, rtol=1e-12)
    np.testing.assert_allclose(acc.apply(ACC), pl.apply(fa.params, jnp.asarray(ACC)), rtol=1e-12)
    # the after-RMS is that of the Fit (|a| / g - 1, unit g)
    assert acc.rms_after == pytest.approx(float(fa.rms), rel=1e-9)
    assert mag.rms_after_pct == pytest.approx(100 * float(fm.rms), rel=1e-9)
    ref = cj.calibrate_mag(MAG, model="full", field=1.0)
    np.testing.assert_allclose(mag.stderr_soft_iron, ref.stderr_soft_iron, rtol=1e-6)
    np.testing.assert_allclose(mag.stderr_center, ref.stderr_center, rtol=1e-6)
    np.testing.assert_allclose(mag.semi_axes, ref.semi_axes, rtol=1e-6)
    # parameters that miss the points (gains 30x theirs; motion taken for poses "converged"
    # with gains of 7,978) make the record failed, whatever the solver said
    p = np.asarray(fa.params.to_vector()).copy()
    p[:3] *= 30.0
    wild = eqx.tree_at(lambda f: f.params, fa, pl.AccelParams.from_vector(jnp.asarray(p)))
    bad = cj.AccelCalibration.from_fit(wild, ACC, 1.0)
    assert bool(wild.converged) and bad.status == "failed"
    assert any("no calibration of these points" in w for w in bad.warnings), bad.warnings
    # counts about a 32768 offset: the gains are judged against the points' spread about the
    # fitted offset, not their distance from zero (a review found 'failed' at 0.07x)
    counts = 4096.0 * ACC + 32768.0
    rec = cj.AccelCalibration.from_fit(FIT_A(jnp.asarray(counts), 1.0), counts, 1.0)
    assert rec.status == "ok", rec.warnings
    # a g the fit was not given (a user's trial: 9.81 for a fit to 1 gave "ok", rms 0.898)
    wrong_g = cj.AccelCalibration.from_fit(fa, ACC, 9.81)
    assert wrong_g.status == "failed" and wrong_g.rms_after > 0.5
    [said] = [w for w in wrong_g.warnings if "the magnitude the fit was given" in w]
    assert abs(float(said.split("median |a| is ")[1].split(")")[0]) - 1.0) < 0.01, said


def test_parameters_changed_in_a_pipeline_become_records(fits, tmp_path):
    """Issue 14's from_params: parameters made or changed inside JAX (here a gradient step
    away from the fit) become a record without a refit (a new user found none: from_fit needs
    a Fit). The record applies exactly as the pipeline does, exports, saves, loads equal, says
    no fit stands behind it, and to_params gives the pytree back exactly; singular or
    non-finite parameters are refused as on loading a file."""
    fa, fm = fits
    g = jax.grad(lambda p: jnp.sum(pl.apply(p, jnp.asarray(ACC))[:, 0]))(fa.params)
    stepped = jax.tree.map(lambda p, d: p - 1e-4 * d, fa.params, g)
    acc = cj.AccelCalibration.from_params(stepped, units="counts")
    mag = cj.MagCalibration.from_params(fm.params, field=1.0)
    np.testing.assert_allclose(acc.apply(ACC), pl.apply(stepped, jnp.asarray(ACC)), rtol=1e-12)
    np.testing.assert_allclose(mag.apply(MAG), pl.apply(fm.params, jnp.asarray(MAG)), rtol=1e-12)
    assert acc.output_units == "g" and "9.80665" in export.write(acc, "ros")
    for rec, params in ((acc, stepped), (mag, fm.params)):
        assert rec.status == "ok" and any("no fit behind this record" in n for n in rec.notes)
        path = tmp_path / f"{type(rec).__name__}.json"
        rec.save(path)
        back = type(rec).load(path)
        assert back == rec
        for x, y in zip(jax.tree.leaves(back.to_params()), jax.tree.leaves(params), strict=True):
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    with pytest.raises(ValueError, match="singular gain matrix"):
        cj.AccelCalibration.from_params(np.zeros(9))
    with pytest.raises(ValueError, match="singular W"):
        cj.MagCalibration.from_params(pl.MagParams(jnp.zeros(3), jnp.zeros((3, 3))))


def test_a_pipeline_batch_becomes_a_batch_record(tmp_path):
    """fit_batch's stacked Fit becomes the BatchRecord that calib-jax batch writes
    (BatchRecord.from_fit): it saves, loads, compares equal, and its to_params gives each
    sensor's pytree back exactly; a sensor the fit could not calibrate is 'failed' and left
    out of to_params."""
    raw = np.stack([ACC, ACC[::-1] * 1.01, np.full_like(ACC, np.nan)])
    fb = pl.fit_batch(pl.fit_accel, jnp.asarray(raw), 1.0)
    rec = cj.BatchRecord.from_fit(fb, len(ACC), names=["a", "b", "nan"])
    assert [e["status"] for e in rec.entries] == ["ok", "ok", "failed"]
    rec.save(tmp_path / "b.json")
    assert cj.BatchRecord.load(tmp_path / "b.json") == rec
    back = rec.to_params()
    assert sorted(back) == ["a", "b"]
    for k, name in enumerate(("a", "b")):
        np.testing.assert_array_equal(
            np.asarray(back[name].to_vector()), np.asarray(fb.params.to_vector())[k]
        )
    assert "correction" in rec.entries[0] and "correction" not in rec.entries[2]


def _dot_precisions(jaxpr) -> list:
    """The precision of every dot_general in a jaxpr and the jaxprs inside it."""
    out = []
    for e in jaxpr.eqns:
        if e.primitive.name == "dot_general":
            out.append(e.params.get("precision"))
        for v in e.params.values():
            for sub in v if isinstance(v, list | tuple) else [v]:
                inner = getattr(sub, "jaxpr", sub)
                if hasattr(inner, "eqns"):
                    out += _dot_precisions(inner)
                elif hasattr(getattr(inner, "jaxpr", None), "eqns"):
                    out += _dot_precisions(inner.jaxpr)
    return out


def test_float32_products_are_full_precision_on_any_device():
    """On a GPU JAX multiplies float32 matrices in TF32 by default: on an H200 the float32
    fits then missed the float64 ones by up to 33 % of a standard error (magnetometer), the
    implicit derivative by 3.2e-3 and the attitude by 0.054 deg, and one fit in 40 did not
    converge (benchmarks/results/float32_accuracy_gpu_tf32.json). The pipeline's functions now
    trace every product at full float32 precision (H200 after: 0.16 %, 1.3e-4, 0.0027 deg, all
    converged; float32_accuracy_gpu.json). Checked here in the traced program, which is what a
    GPU compiles: every dot_general of the fits, their gradient and the attitude is HIGHEST."""
    a32, m32 = jnp.asarray(ACC, jnp.float32), jnp.asarray(MAG, jnp.float32)
    one = jnp.float32(1.0)
    programs = {
        "fit_accel": jax.make_jaxpr(pl.fit_accel)(a32, one),
        "fit_mag": jax.make_jaxpr(pl.fit_mag)(m32, one),
        "grad": jax.make_jaxpr(jax.grad(_gain_sum))(a32, one),
    }
    fa, fm = FIT_A(a32, one), FIT_M(m32, one)
    mp = pl.MargParams(fa.params, fm.params, pl.Rotation.identity(jnp.float32))
    a_t, m_t = jnp.asarray(A_TEST, jnp.float32), jnp.asarray(M_TEST, jnp.float32)
    programs["attitude"] = jax.make_jaxpr(lambda p: pl.attitude(p, a_t, m_t, DIP))(mp)
    highest = (jax.lax.Precision.HIGHEST, jax.lax.Precision.HIGHEST)
    for name, jp in programs.items():
        precisions = _dot_precisions(jp.jaxpr)
        assert precisions, name  # not vacuous: the program multiplies matrices
        assert all(p == highest for p in precisions), (name, set(map(str, precisions)))
