"""Implicit gradients through the fit (issue 7, first part): calib_jax.implicit.solve_implicit
against reverse mode, the unrolled LM loop, finite differences of a full refit, optimistix's
implicit adjoint and an exact scaling law."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

from calib_jax.accel import initial_guess
from calib_jax.implicit import solve_implicit
from calib_jax.lm import Status, lm_solve
from calib_jax.models.accel import distort, normalized_sphere_residual

RNG = np.random.default_rng(0)
_D = RNG.normal(size=(40, 3))
_D /= np.linalg.norm(_D, axis=1, keepdims=True)
P_TRUE = np.array([1.02, 0.98, 1.01, 0.01, -0.02, 0.005, 0.03, -0.01, 0.02])
X = jnp.asarray(np.asarray(distort(jnp.asarray(P_TRUE), jnp.asarray(_D))))
X = X + 1e-3 * jnp.asarray(RNG.normal(size=(40, 3)))
P0 = initial_guess(X, jnp.ones(40))


def resid(p, args):
    x, g = args
    return normalized_sphere_residual(p, x, g)


@jax.jit
def implicit(x, g):
    return solve_implicit(resid, P0, (x, g))[0]


@jax.jit
def unrolled(x, g):
    return lm_solve(resid, P0, (x, g)).params


@pytest.fixture(scope="module")
def J():
    return np.asarray(jax.jit(jax.jacfwd(implicit))(X, 1.0))


def test_forward_and_reverse_mode_agree(J):
    """One linear solve either way: equal to round-off (1e-12 of the largest entry)."""
    Jr = np.asarray(jax.jit(jax.jacrev(implicit))(X, 1.0))
    np.testing.assert_allclose(Jr, J, atol=1e-12 * np.abs(J).max())


def test_equals_the_unrolled_loop_at_convergence(J):
    """Forward-mode through the LM iterations converges to the implicit derivative with the
    iterates, but more slowly than they do (linearly, where the iterates converge
    quadratically), and the fit stops on the iterates. Here it stops after 3 iterations: when
    the third step is accepted the tangent is 4e-8 of the scale off; when it is rejected at the
    round-off stop (CONVERGED_ROUNDOFF) the tangent is one step behind, 8.1e-5 off. Which of
    the two happens turns on the last bits: P0 moved by 1e-15 relative flips it (so did the
    batch moments' variadic reduce, through initial_guess), and 1e-6 failed. 1e-3 of the scale
    allows one step's lag; a wrong derivative (a missing term) is off by O(1)."""
    Ju = np.asarray(jax.jit(jax.jacfwd(unrolled))(X, 1.0))
    np.testing.assert_allclose(Ju, J, atol=1e-3 * np.abs(J).max())


@pytest.mark.parametrize("k", [(0, 0), (7, 1), (23, 2)])
def test_equals_finite_differences_of_a_refit(J, k):
    """Central differences of two full refits, h = 1e-4: truncation ~h^2 and the refits'
    own precision (1e-10 relative) / h ~ 1e-6, so 1e-4 of the column's scale."""
    h = 1e-4
    fd = np.asarray(unrolled(X.at[k].add(h), 1.0)) - np.asarray(unrolled(X.at[k].add(-h), 1.0))
    fd /= 2 * h
    np.testing.assert_allclose(J[:, k[0], k[1]], fd, atol=1e-4 * np.abs(fd).max())


def test_equals_optimistix_implicit_adjoint(J):
    """optimistix's least_squares differentiates by its own implicit adjoint."""

    def optx_fit(x):
        sol = optx.least_squares(
            lambda p, a: resid(p, a),
            optx.LevenbergMarquardt(rtol=1e-12, atol=1e-14),
            P0,
            (x, 1.0),
            max_steps=256,
        )
        return sol.value

    Jo = np.asarray(jax.jit(jax.jacfwd(optx_fit))(X))
    np.testing.assert_allclose(Jo, J, atol=1e-6 * np.abs(J).max())


def test_reference_magnitude_scaling_law():
    """The model is homogeneous in g: alpha(g) = alpha(1) / g, beta unchanged, so
    d alpha / d g = -alpha at g = 1 exactly (to the fit's 1e-10 precision)."""
    p = np.asarray(implicit(X, 1.0))
    dp = np.asarray(jax.jacfwd(implicit, argnums=1)(X, 1.0))
    np.testing.assert_allclose(dp[:6], -p[:6], atol=1e-8)
    np.testing.assert_allclose(dp[6:], 0.0, atol=1e-8)


def test_weights_are_differentiable():
    """Doubling every weight leaves the optimum unchanged: the derivative along w = 1 is 0;
    one weight's derivative against central differences of refits, h = 1e-2: the refits'
    precision (1e-10) / h is 2.5e-5 of this derivative's scale (2e-4), truncation ~h^2, so
    5e-4 of the scale."""

    def resid_w(p, args):  # the residual ignores w; the weights function reads it
        return resid(p, args[:2])

    def fit_w(w):
        return solve_implicit(resid_w, P0, (X, 1.0, w), weights=lambda a: a[2])[0]

    w = jnp.ones(40)
    Jw = np.asarray(jax.jit(jax.jacfwd(fit_w))(w))
    np.testing.assert_allclose(Jw @ np.ones(40), 0.0, atol=1e-9)
    h = 1e-2

    def refit(w):
        return np.asarray(lm_solve(resid_w, P0, (X, 1.0, w), weights=w).params)

    fd = (refit(w.at[5].add(h)) - refit(w.at[5].add(-h))) / (2 * h)
    np.testing.assert_allclose(Jw[:, 5], fd, atol=5e-4 * np.abs(fd).max())


def test_unconverged_fit_says_so(J):
    """With a budget of one iteration the forward status is not converged, and the implicit
    derivative is that of the optimum near the point: its error is first order in the
    distance to the optimum (8.1-8.4 times it, relative to the derivative's scale, after 1, 2
    and 3 iterations here; bound 20), and it is not the derivative of the returned iterate
    (forward mode through those iterations), which differs from it by 0.1 of the scale after
    one iteration. So the status is what to check."""
    p_star = np.asarray(implicit(X, 1.0))
    scale = np.abs(J).max()
    errors = []

    @jax.jit  # the budget traced: one compile serves both budgets
    def stopped_after(x, iters):
        def fit(x):
            p, res = solve_implicit(resid, P0 * 1.05, (x, 1.0), max_iter=iters, eps1=0.0, eps2=0.0)
            return p, (p, res.status)

        # one forward solve gives the point, its status and its derivative
        return jax.jacfwd(fit, has_aux=True)(x)

    for iters in (1, 2):
        Jk, (p, status) = stopped_after(X, iters)
        assert int(status) == Status.MAX_ITERATIONS
        dist = np.abs(np.asarray(p) - p_star).max()
        err = np.abs(np.asarray(Jk) - J).max() / scale
        assert err < 20 * dist, (iters, err, dist)
        errors.append(err)
    assert errors[1] < 0.1 * errors[0]  # falls with the distance
    # the derivative of the returned iterate itself is another thing
    Ju = jax.jit(
        jax.jacfwd(
            lambda x: lm_solve(resid, P0 * 1.05, (x, 1.0), max_iter=1, eps1=0.0, eps2=0.0).params
        )
    )(X)
    assert np.abs(np.asarray(Ju) - J).max() / scale > 2 * errors[0]


def test_effect_hyperparameter_reference_temperature():
    """An effect hyperparameter: the reference temperature T_ref of the temperature-bias effect
    of the diagnosis model, b(T) = b + c1 (T - T_ref) + c2 (T - T_ref)^2. Moving T_ref only
    re-expresses the same curve, so the exact law is db/dT_ref = c1, dc1/dT_ref = 2 c2,
    dc2/dT_ref = 0, and the gains do not move (1e-8 of scale); and refit differences agree."""
    from calib_jax.diagnose import model as dm

    rng = np.random.default_rng(5)
    n = 80
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    T = rng.uniform(-0.5, 0.5, n)
    c1, c2 = np.array([0.02, -0.01, 0.015]), np.array([0.01, 0.02, -0.01])
    x = u @ np.diag([1.02, 0.99, 1.01]) + 0.01 + c1 * T[:, None] + c2 * T[:, None] ** 2
    x += 1e-4 * rng.normal(size=x.shape)
    free = jnp.asarray(dm.mask("temp_bias1", "temp_bias2"))
    theta0 = jnp.zeros(dm.N_THETA).at[0:3].set(1.0)

    def resid(theta, args):
        x, T, Tref, free = args
        return dm.residual(theta, (x, jnp.zeros_like(T), T - Tref, jnp.ones_like(T), free))

    def fitted(Tref):
        return solve_implicit(
            resid, theta0, (jnp.asarray(x), jnp.asarray(T), Tref, free), max_iter=100
        )[0]

    th = jax.jit(fitted)(0.1)
    d = np.asarray(jax.jit(jax.jacfwd(fitted))(0.1))
    s = dm.SLOTS
    np.testing.assert_allclose(d[s["bias"]], np.asarray(th[s["temp_bias1"]]), atol=1e-8)
    np.testing.assert_allclose(d[s["temp_bias1"]], 2 * np.asarray(th[s["temp_bias2"]]), atol=1e-8)
    np.testing.assert_allclose(d[s["temp_bias2"]], 0.0, atol=1e-8)
    np.testing.assert_allclose(d[s["gains"]], 0.0, atol=1e-8)
    f = jax.jit(fitted)
    fd = (np.asarray(f(0.1 + 1e-4)) - np.asarray(f(0.1 - 1e-4))) / 2e-4
    np.testing.assert_allclose(d, fd, atol=1e-5)
