"""The plain-jnp linear algebra (calib_jax.linalg) against numpy on hard matrices."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from calib_jax.linalg import cho_solve_small, eigh_small, inv3


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
