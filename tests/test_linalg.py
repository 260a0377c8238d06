"""The plain-jnp linear algebra (calib_jax.linalg) against numpy on hard matrices."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from calib_jax.linalg import cho_solve_small, cholesky_small, eigh_small, inv3


def hard_symmetric(n, count=90, seed=0):
    """Eigenvalues spread over 10 decades, clustered to 1e-9, or of mixed sign."""
    rng = np.random.default_rng(seed)
    mats, evs = [], []
    for t in range(count):
        Q, _ = np.linalg.qr(rng.normal(size=(n, n)))
        ev = [10 ** rng.uniform(-10, 0, n), 1 + 1e-9 * rng.normal(size=n), rng.normal(size=n)][
            t % 3
        ]
        a = (Q * ev) @ Q.T
        mats.append(0.5 * (a + a.T))
        evs.append(np.sort(ev))
    return np.stack(mats), np.stack(evs)


@pytest.mark.parametrize("n", [3, 6, 9, 10])
def test_eigh_small_matches_numpy(n):
    """8 Jacobi sweeps reconstruct A and its eigenvalues to a few ulps of |A| (bound 5e-14;
    measured 1e-14 at n = 10), vmapped as the solvers use it."""
    A, ev = hard_symmetric(n)
    w, V = jax.jit(jax.vmap(eigh_small))(jnp.asarray(A))
    w, V = np.asarray(w), np.asarray(V)
    scale = np.abs(A).max(axis=(1, 2))
    rec = np.einsum("bij,bj,bkj->bik", V, w, V)
    assert np.all(np.abs(rec - A).max(axis=(1, 2)) < 5e-14 * scale)
    assert np.all(np.abs(w - ev).max(axis=1) < 5e-14 * np.abs(ev).max(axis=1))
    np.testing.assert_allclose(
        np.einsum("bji,bjk->bik", V, V), np.eye(n)[None].repeat(len(A), 0), atol=1e-13
    )


def test_cho_solve_and_inv3_match_numpy():
    rng = np.random.default_rng(1)
    B = rng.normal(size=(9, 9))
    A = B @ B.T + 9 * np.eye(9)
    b = rng.normal(size=9)
    np.testing.assert_allclose(
        np.asarray(cho_solve_small(jnp.asarray(A), jnp.asarray(b))),
        np.linalg.solve(A, b),
        rtol=1e-12,
    )
    M = rng.normal(size=(3, 3))
    np.testing.assert_allclose(np.asarray(inv3(jnp.asarray(M))), np.linalg.inv(M), rtol=1e-12)
    # not positive definite: NaN, never an exception
    assert np.all(np.isnan(np.asarray(cho_solve_small(-jnp.asarray(A), jnp.asarray(b)))))


def test_cholesky_small_and_matrix_right_hand_sides():
    """The column-loop Cholesky against numpy (to 1e-12 relative on a well-conditioned SPD
    matrix), several right-hand sides at once, and the semi-definite mode on a singular one."""
    rng = np.random.default_rng(2)
    B = rng.normal(size=(10, 10))
    A = B @ B.T + 10 * np.eye(10)
    L = np.asarray(jax.jit(cholesky_small)(jnp.asarray(A)))
    np.testing.assert_allclose(L, np.linalg.cholesky(A), rtol=1e-12, atol=1e-12)
    R = rng.normal(size=(10, 4))
    np.testing.assert_allclose(
        np.asarray(cho_solve_small(jnp.asarray(A), jnp.asarray(R))),
        np.linalg.solve(A, R),
        rtol=1e-11,
    )
    # rank 3 of 4: one zero column instead of NaN, and L L' still reproduces the matrix
    C = rng.normal(size=(4, 3))
    S = C @ C.T
    Ls = np.asarray(cholesky_small(jnp.asarray(S), semidefinite=True))
    assert np.all(np.isfinite(Ls))
    np.testing.assert_allclose(Ls @ Ls.T, S, atol=1e-7 * np.abs(S).max())
    assert np.all(np.isnan(np.asarray(cholesky_small(jnp.asarray(S - np.eye(4))))[-1]))


@pytest.mark.parametrize("n", [3, 9])
def test_uncertainty_cholesky_equals_eigh(n):
    """The batch fit's Cholesky covariance against the eigen-decomposition one: equal to
    1e-8 relative where J'WJ is well enough conditioned (condition < 1e6 here: both lose
    about cond * eps), and all standard errors inf where it is singular."""
    from calib_jax.lm import uncertainty, uncertainty_cholesky

    rng = np.random.default_rng(n)
    for _ in range(20):
        J = rng.normal(size=(40, n)) * 10 ** rng.uniform(-3, 3, n)
        JtJ = jnp.asarray(J.T @ J)
        ref = jax.jit(uncertainty, static_argnums=2)(JtJ, 2.0, False)
        got = jax.jit(uncertainty_cholesky, static_argnums=2)(JtJ, 2.0, False)
        for a, b in zip(ref[:3], got[:3], strict=True):
            np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=1e-8, atol=1e-12)
        assert np.isnan(float(got[3]))
    J[:, 1] = 2.0 * J[:, 0]  # one parameter is a copy of another
    cov, se, corr, _ = uncertainty_cholesky(jnp.asarray(J.T @ J), 2.0, False)
    assert np.all(np.isinf(np.asarray(se)))
    assert np.all(np.isnan(np.asarray(cov)))


def test_det3_and_the_alpha_layout_both_ways():
    """det3 against numpy's LU determinant (1e-12 relative on O(1) matrices), and
    models.layout's two maps: alpha = p[ALPHA_INDEX] and back, alpha[ALPHA_ENTRIES] = p[:6]."""
    from calib_jax.linalg import det3
    from calib_jax.models.layout import ALPHA_ENTRIES, ALPHA_INDEX

    a = np.random.default_rng(3).normal(size=(5, 3, 3))
    for m in a:
        assert float(det3(jnp.asarray(m))) == pytest.approx(np.linalg.det(m), rel=1e-12)
    p = np.arange(1.0, 10.0)
    alpha = p[ALPHA_INDEX]
    np.testing.assert_array_equal(alpha, alpha.T)
    np.testing.assert_array_equal(alpha[ALPHA_ENTRIES], p[:6])


def test_padding_helpers_keep_data_and_weigh_padding_zero():
    """pad_rows: the data first, the first row repeated (finite, in range), weights as given
    on the data and 0 on the padding; stack_rows: logs of different lengths in one stack with
    the same weights, extra entries all zero weight; bucket: powers of two from 64."""
    from calib_jax.padding import bucket, pad_rows, stack_rows

    assert [bucket(n) for n in (1, 64, 65, 1000)] == [64, 64, 128, 1024]
    x = np.arange(15.0).reshape(5, 3)
    xp, w = pad_rows(x, 8, weights=np.array([1.0, 0.0, 2.0, 1.0, 1.0]))
    np.testing.assert_array_equal(xp[:5], x)
    np.testing.assert_array_equal(xp[5:], np.repeat(x[:1], 3, axis=0))
    np.testing.assert_array_equal(w, [1, 0, 2, 1, 1, 0, 0, 0])
    s, sw = stack_rows([x, x[:2]], count=3)
    assert s.shape == (3, 64, 3) and sw.shape == (3, 64)
    np.testing.assert_array_equal(s[1, :2], x[:2])
    np.testing.assert_array_equal(sw.sum(axis=1), [5, 2, 0])
