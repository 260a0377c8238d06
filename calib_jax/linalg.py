"""Small dense linear algebra in plain jnp operations.

The calibration problems solve 3x3 and ~10x10 systems, millions of times under vmap. XLA's
CPU LAPACK custom calls are a poor fit for that: per-call overhead dominates, and on this
2-core machine jaxlib 0.10's batched triangular solve (``ParallelBatchMap`` on the Eigen
intra-op pool) deadlocked intermittently inside a ``while_loop`` (seen here: the process
sleeps at 0 % CPU forever; see also PyAutoFit issue #1528, the same wedge). Writing these
solves out in elementwise operations avoids both: no custom call, no thread pool, and
vmap turns them into vector arithmetic across sensors.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

_LOOP_MAX = 32  # Cholesky: column loops, compile time independent of n
_JACOBI_MAX = 16  # Jacobi eigh: 8 sweeps are ample up to here


def det3(a: jax.Array) -> jax.Array:
    """Determinant of a 3x3 matrix by cofactors (no LAPACK call: see the module docstring)."""
    return (
        a[0, 0] * (a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1])
        + a[0, 1] * (a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2])
        + a[0, 2] * (a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0])
    )


def inv3(a: jax.Array) -> jax.Array:
    """Inverse of a 3x3 matrix by the adjugate (NaN/inf when singular, never an exception)."""
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
    c01 = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
    c02 = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
    c10 = a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2]
    c11 = a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]
    c12 = a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]
    c20 = a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]
    c21 = a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]
    c22 = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02
    adj = jnp.stack(
        [jnp.stack([c00, c10, c20]), jnp.stack([c01, c11, c21]), jnp.stack([c02, c12, c22])]
    )
    return adj / det


def cholesky_small(a: jax.Array, jitter: float = 0.0, semidefinite: bool = False) -> jax.Array:
    """Lower Cholesky factor L (L L' = a + jitter tr(a) I) of a small symmetric matrix.

    Column by column in a ``fori_loop``: n iterations of O(n^2) vector work, so the program
    (and the compile time) does not grow with n^2 the way a fully unrolled factorisation does
    (inside the batch LM that took 1.2 s of a 5 s compile). With ``semidefinite=False`` a
    non-positive pivot gives NaN (callers treat it as a failed solve); with True it gives a
    zero column, the factor of a positive semi-definite matrix.
    """
    n = a.shape[0]
    if jitter:
        a = a + jitter * jnp.trace(a) * jnp.eye(n, dtype=a.dtype)
    idx = jnp.arange(n)

    def column(j, L):
        # s_i = a_ij - sum_k<j L_ik L_jk (columns >= j of L are still zero)
        s = a[:, j] - jnp.sum(L * L[j][None, :], axis=1)
        pos = s[j] > 0
        if semidefinite:
            d = jnp.sqrt(jnp.where(pos, s[j], 0.0))
            below = jnp.where(pos, s / jnp.where(pos, d, 1.0), 0.0)
        else:
            d = jnp.sqrt(jnp.where(pos, s[j], jnp.nan))
            below = s / d
        return L.at[:, j].set(jnp.where(idx == j, d, jnp.where(idx > j, below, 0.0)))

    return jax.lax.fori_loop(0, n, column, jnp.zeros_like(a))


def cho_solve_small(a: jax.Array, b: jax.Array) -> jax.Array:
    """Solve a x = b for a symmetric positive-definite n x n matrix by Cholesky.

    b is (n,) or (n, k). Loops over rows (see :func:`cholesky_small`) for n <= 32; larger
    systems use jax.scipy's LAPACK Cholesky. Returns NaN when a is not positive definite (the
    caller treats that as a failed step).
    """
    n = a.shape[0]
    if n > _LOOP_MAX:
        return jax.scipy.linalg.cho_solve(jax.scipy.linalg.cho_factor(a), b)
    L = cholesky_small(a)
    vector = b.ndim == 1
    B = b[:, None] if vector else b

    def forward(i, y):  # L y = b
        # products and sums, not dot: a batched dot under vmap may go to the Eigen pool
        return y.at[i].set((B[i] - jnp.sum(L[i][:, None] * y, axis=0)) / L[i, i])

    def backward(k, x):  # L' x = y
        i = n - 1 - k
        return x.at[i].set((y[i] - jnp.sum(L[:, i][:, None] * x, axis=0)) / L[i, i])

    y = jax.lax.fori_loop(0, n, forward, jnp.zeros_like(B))
    x = jax.lax.fori_loop(0, n, backward, jnp.zeros_like(B))
    return x[:, 0] if vector else x


def eigh_small(a: jax.Array, sweeps: int = 8) -> tuple[jax.Array, jax.Array]:
    """Eigen-decomposition of a small symmetric matrix by cyclic Jacobi rotations.

    Returns (eigenvalues ascending, eigenvectors as columns), like ``jnp.linalg.eigh``, in
    plain jnp operations (see the module docstring for why). Quadratic convergence: 8 sweeps
    are ample for n <= 16 in float64.
    """
    n = a.shape[0]
    if n > _JACOBI_MAX:
        return jnp.linalg.eigh(a)
    pairs = [(p, q) for p in range(n - 1) for q in range(p + 1, n)]
    ps = jnp.array([p for p, _ in pairs])
    qs = jnp.array([q for _, q in pairs])
    eye = jnp.eye(n, dtype=a.dtype)

    def rotate(k, carry):
        # one Jacobi rotation on the pair (p, q): only rows and columns p, q change, O(n)
        # work instead of two n x n products; a loop over pairs (not unrolled) keeps the
        # compile short (unrolled, a 9 x 9 took 4 s to compile)
        A, V = carry
        p, q = ps[k], qs[k]
        apq = A[p, q]
        app, aqq = A[p, p], A[q, q]
        active = jnp.abs(apq) > 0
        theta = (aqq - app) / (2.0 * jnp.where(active, apq, 1.0))
        t = jnp.sign(theta) / (jnp.abs(theta) + jnp.sqrt(theta * theta + 1.0))
        t = jnp.where(theta == 0, 1.0, t)
        t = jnp.where(active, t, 0.0)
        c = 1.0 / jnp.sqrt(t * t + 1.0)
        s = t * c
        rp, rq = A[p, :], A[q, :]
        A = A.at[p, :].set(c * rp - s * rq).at[q, :].set(s * rp + c * rq)
        cp, cq = A[:, p], A[:, q]
        A = A.at[:, p].set(c * cp - s * cq).at[:, q].set(s * cp + c * cq)
        vp, vq = V[:, p], V[:, q]
        V = V.at[:, p].set(c * vp - s * vq).at[:, q].set(s * vp + c * vq)
        return A, V

    def sweep(_, carry):
        return jax.lax.fori_loop(0, len(pairs), rotate, carry)

    A, V = jax.lax.fori_loop(0, sweeps, sweep, (a, eye))
    w = jnp.diag(A)
    order = jnp.argsort(w)
    return w[order], V[:, order]
