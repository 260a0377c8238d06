"""The Gavin LM solver: cross-checks against optimistix and SciPy on the same residual."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import least_squares

from calib_jax.lm import GAVIN_DEFAULTS, Status, is_converged, lm_solve, optx_solve
from calib_jax.models.accel import normalized_sphere_residual
from calib_jax.simulate import random_params, simulate_accel

P0 = jnp.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])


def sphere(p, x):
    return normalized_sphere_residual(p, x, 1.0)


@functools.cache
def gavin(update_type, jacobian, rho_form, history=False):
    return jax.jit(
        lambda p0, x: lm_solve(
            sphere,
            p0,
            x,
            update_type=update_type,
            jacobian=jacobian,
            rho_form=rho_form,
            history=history,
        )
    )


@pytest.fixture(scope="module")
def problem(sim48):
    x = jnp.asarray(sim48.raw[sim48.static])
    J = jax.jit(jax.jacfwd(sphere))
    ref = least_squares(
        lambda p: np.asarray(sphere(jnp.asarray(p), x)),
        np.asarray(P0),
        jac=lambda p: np.asarray(J(jnp.asarray(p), x)),
        method="lm",
        xtol=1e-15,
        ftol=1e-15,
        gtol=1e-15,
    )
    assert ref.success
    return x, ref


@pytest.mark.parametrize("update_type", [1, 2, 3])
@pytest.mark.parametrize("jacobian", ["exact", "broyden"])
@pytest.mark.parametrize("rho_form", ["current", "paper"])
def test_gavin_matches_scipy(problem, tol, update_type, jacobian, rho_form):
    x, ref = problem
    r = gavin(update_type, jacobian, rho_form)(P0, x)
    assert is_converged(int(r.status)), Status(int(r.status))
    chi2_ref = 2 * ref.cost
    assert abs(float(r.chi2) - chi2_ref) <= tol.CHI2_REL * chi2_ref
    np.testing.assert_allclose(r.params, ref.x, rtol=tol.PARAM_REL, atol=tol.PARAM_REL)


def test_optimistix_matches_scipy(problem, tol):
    x, ref = problem
    r = jax.jit(lambda p0, x: optx_solve(sphere, p0, x))(P0, x)
    assert int(r.status) == Status.CONVERGED
    assert abs(float(r.chi2) - 2 * ref.cost) <= tol.CHI2_REL * 2 * ref.cost
    np.testing.assert_allclose(r.params, ref.x, rtol=tol.PARAM_REL, atol=tol.PARAM_REL)


def test_optimistix_out_of_steps_is_not_converged_not_failed(problem):
    """Two steps from the identity cannot reach the optimum: optimistix says
    nonlinear_max_steps_reached, which is MAX_ITERATIONS ("not_converged"), not FAILED (it was
    compared with lineax's max_steps_reached, a different enum member, and never matched)."""
    x, _ = problem
    r = jax.jit(lambda p0, x: optx_solve(sphere, p0, x, max_iter=2))(P0, x)
    assert int(r.status) == Status.MAX_ITERATIONS, Status(int(r.status))


def test_truth_recovered_within_stderr(problem, sim48, tol):
    x, _ = problem
    r = gavin(1, "exact", "current")(P0, x)
    z = (np.asarray(r.params) - sim48.params) / np.asarray(r.stderr)
    assert np.all(np.abs(z) < tol.N_SIGMA), z


def test_covariance_matches_independent_formula(problem):
    # cov = (J'J)^-1 * chi2/(m - n), computed here with numpy from SciPy's Jacobian
    x, ref = problem
    r = gavin(1, "exact", "current")(P0, x)
    J = ref.jac
    m, n = J.shape
    cov = np.linalg.inv(J.T @ J) * (2 * ref.cost) / (m - n)
    np.testing.assert_allclose(r.covariance, cov, rtol=1e-6)
    np.testing.assert_allclose(r.stderr, np.sqrt(np.diag(cov)), rtol=1e-6)
    assert 1.0 <= float(r.condition) < 1e4


def test_gavin_defaults_stop_early_and_ours_do_not(problem):
    # LM_SPEC: Gavin's eps3 = 0.1 on the reduced chi2 is met after the first accepted step on
    # well-scaled data, far from the optimum. Our defaults must not fall into that.
    x, ref = problem
    early = jax.jit(lambda p0, x: lm_solve(sphere, p0, x, **GAVIN_DEFAULTS._asdict()))(P0, x)
    assert int(early.status) == Status.CONVERGED_CHI2
    assert int(early.iterations) <= 2
    assert float(early.chi2) > 1.01 * 2 * ref.cost
    ours = gavin(1, "exact", "current")(P0, x)
    assert int(ours.iterations) > int(early.iterations)


def test_history_is_monotone(problem):
    x, _ = problem
    r = gavin(3, "exact", "current", history=True)(P0, x)
    it = int(r.iterations)
    chi2 = np.asarray(r.history.chi2)
    assert np.all(np.isfinite(chi2[:it])) and np.all(np.isnan(chi2[it:]))
    assert np.all(np.diff(chi2[:it]) <= 0)
    assert chi2[it - 1] == pytest.approx(float(r.chi2))


def test_vmap_over_sensors_equals_loop():
    logs = [
        simulate_accel(
            random_params(s), samples_per_pose=20, transition_samples=10, noise=1e-3, rng=s
        )
        for s in range(3)
    ]
    X = jnp.stack([jnp.asarray(lg.raw[lg.static]) for lg in logs])
    single = gavin(1, "exact", "current")
    batched = jax.jit(jax.vmap(lambda x: lm_solve(sphere, P0, x, update_type=1)))(X)
    for i in range(3):
        r = single(P0, X[i])
        # XLA vectorises batched reductions differently: last-bit differences (~1e-12) only
        np.testing.assert_allclose(batched.params[i], r.params, rtol=1e-10, atol=1e-13)
        # ... which can flip which convergence test fires first, at most one iteration apart
        assert abs(int(batched.iterations[i]) - int(r.iterations)) <= 1
        assert is_converged(int(batched.status[i])) and is_converged(int(r.status))


def test_zero_weights_equal_dropping_samples(problem, tol):
    # padding with weight-0 samples (how calibrate_accel shares compilations) changes nothing
    x, _ = problem
    n = x.shape[0]
    xp = jnp.concatenate([x, jnp.ones((64, 3)) * 5.0])
    w = jnp.concatenate([jnp.ones(n), jnp.zeros(64)])
    r1 = gavin(1, "exact", "current")(P0, x)
    r2 = jax.jit(lambda p0, x, w: lm_solve(sphere, p0, x, weights=w))(P0, xp, w)
    np.testing.assert_allclose(r2.params, r1.params, rtol=tol.PARAM_REL, atol=tol.PARAM_REL)
    np.testing.assert_allclose(r2.stderr, r1.stderr, rtol=1e-6)


def test_nonfinite_start_is_a_status():
    x = jnp.asarray(np.random.default_rng(0).normal(size=(20, 3))).at[3, 1].set(jnp.nan)
    r = gavin(1, "exact", "current")(P0, x)
    assert int(r.status) == Status.NONFINITE
    assert int(r.iterations) == 0


def test_unidentifiable_parameter():
    # e = y - p0 t: p1 has no effect. Type 1 scales the damping by diag(J'J) = 0 for p1, so its
    # system stays singular at every lambda (status SINGULAR); type 3 damps with lambda I and
    # converges, reporting p1's standard error as inf.
    t = jnp.linspace(0.0, 1.0, 30)
    y = 2.0 * t

    def f(p, _):
        return y - p[0] * t + 0.0 * p[1]

    r1 = lm_solve(f, jnp.array([1.0, 1.0]), None, update_type=1)
    assert int(r1.status) == Status.SINGULAR
    r3 = lm_solve(f, jnp.array([1.0, 1.0]), None, update_type=3)
    assert is_converged(int(r3.status))
    assert float(r3.params[0]) == pytest.approx(2.0, abs=1e-8)
    assert np.isinf(float(r3.stderr[1]))


@pytest.mark.parametrize("update_type", [1, 2, 3])
def test_general_residual_exponential_fit(update_type):
    # a classic nonlinear curve fit (not a calibration): y = a exp(-b t) + c, far start
    rng = np.random.default_rng(5)
    t = np.linspace(0, 4, 60)
    y = 3.0 * np.exp(-1.3 * t) + 0.5 + rng.normal(scale=0.01, size=t.size)

    def f(p, a):
        t, y = a
        return y - (p[0] * jnp.exp(-p[1] * t) + p[2])

    args = (jnp.asarray(t), jnp.asarray(y))
    r = lm_solve(f, jnp.array([1.0, 0.2, 0.0]), args, update_type=update_type)
    ref = least_squares(
        lambda p: np.asarray(f(jnp.asarray(p), args)),
        [1.0, 0.2, 0.0],
        method="lm",
        xtol=1e-15,
        ftol=1e-15,
        gtol=1e-15,
    )
    assert is_converged(int(r.status))
    np.testing.assert_allclose(r.params, ref.x, rtol=1e-7)


@pytest.mark.wrong_types
def test_bad_arguments_raise_with_the_fix():
    with pytest.raises(ValueError, match="update_type"):
        lm_solve(sphere, P0, jnp.ones((20, 3)), update_type=4)
    with pytest.raises(ValueError, match="more samples than parameters"):
        lm_solve(sphere, P0, jnp.ones((5, 3)))


@functools.cache
def _session_means(seed):
    # the 24 static-pose means of a simulated session, normalised as calibrate_accel does
    from calib_jax.geometry import sphere_fit
    from calib_jax.simulate import simulate_session
    from calib_jax.static import detect_static

    acc = simulate_session(poses=24, hold=1.0, move=0.3, rate=100, seed=seed)["acc"]
    means = detect_static(acc, sample_rate=100, window=25, min_duration=0.5).means()
    c, r = sphere_fit(jnp.asarray(means), jnp.ones(len(means)))
    return (means - np.asarray(c)) / float(r)


@pytest.mark.parametrize("update_type", [1, 2, 3])
def test_start_at_noise_floor_optimum_converges_whatever_the_roundoff(update_type):
    # Regression: 24 pose means at 2 mg noise sit at a noise-floor minimum (chi2 ~1.5e-6, e ~
    # 5e-4 against terms of size ~1), and the algebraic ellipsoid start is that minimum to
    # round-off. chi2 is then evaluated to ~1e-18, far above the old round-off bound 4 sqrt(m)
    # eps chi2 ~ 7e-21: the round-off stop never fired and each trial step was accepted or
    # rejected by the sign of the noise. One-ulp changes of the data (as between a strided
    # and a contiguous copy) sent some fits through nine rejections to lambda_max and on to the
    # 200-iteration budget. Every copy must now stop at once, at the same chi2.
    from calib_jax.accel import initial_guess

    x0 = _session_means(114)
    rng = np.random.default_rng(0)
    copies = [x0]
    for _ in range(63):
        i = np.arange(len(x0))
        k = rng.integers(0, 3, size=len(x0))
        x = x0.copy()
        x[i, k] = np.nextafter(x[i, k], rng.choice([-np.inf, np.inf], size=len(x0)))
        copies.append(x)
    X = jnp.asarray(np.stack(copies))
    w = jnp.ones(len(x0))
    fit = jax.jit(
        jax.vmap(lambda x: lm_solve(sphere, initial_guess(x, w), x, update_type=update_type))
    )
    r = fit(X)
    status = [Status(int(s)) for s in r.status]
    assert all(is_converged(int(s)) for s in status), status
    assert int(jnp.max(r.iterations)) <= 5, np.asarray(r.iterations)
    chi2 = np.asarray(r.chi2)
    np.testing.assert_allclose(chi2, chi2[0], rtol=1e-9)


def test_calibrate_accel_strided_and_contiguous_both_converge(tol):
    # the reported case: simulate_session(seed=114), lm1 gave "not_converged" after 200
    # iterations at the optimum; lm2 and optimistix converged
    from calib_jax import calibrate_accel
    from calib_jax.simulate import simulate_session

    s = simulate_session(poses=24, hold=1.0, move=0.3, rate=100, seed=114)
    rows = np.column_stack([s["t"], s["acc"]])
    kw = dict(sample_rate=100, window=25, min_duration=0.5)
    ref = calibrate_accel(np.ascontiguousarray(rows[:, 1:]), solver="optimistix", **kw)
    for acc in (rows[:, 1:], np.ascontiguousarray(rows[:, 1:])):
        cal = calibrate_accel(acc, solver="lm1", **kw)
        assert cal.status == "ok", (cal.status, cal.iterations, cal.solver_message)
        assert is_converged(cal.solver_status)
        assert cal.iterations <= 5
        np.testing.assert_allclose(cal.params, ref.params, rtol=tol.PARAM_REL, atol=tol.PARAM_REL)
