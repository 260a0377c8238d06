"""Closed-form starting points: algebraic sphere and ellipsoid fits (pure, jittable)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .linalg import cho_solve_small, eigh_small


def sphere_fit(x: jax.Array, w: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Weighted algebraic sphere fit |x - c|^2 = r^2 (linear in c, r^2 - |c|^2).

    Returns (centre (3,), radius). Solves the 4x4 normal equations of
    |x|^2 = 2 c.x + d, d = r^2 - |c|^2.
    """
    A = jnp.concatenate([2.0 * x, jnp.ones((x.shape[0], 1), x.dtype)], axis=1)
    b = jnp.sum(x * x, axis=1)
    Aw = A * w[:, None]
    sol = cho_solve_small(Aw.T @ A, Aw.T @ b)
    c, d = sol[:3], sol[3]
    return c, jnp.sqrt(jnp.maximum(d + c @ c, 0.0))


def ellipsoid_fit(x: jax.Array, w: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Weighted algebraic ellipsoid fit (x - c)' M (x - c) = 1 with M symmetric.

    Fits the quadric x' A x + v' x = 1 (nine unknowns) by linear least squares, then
    c = -A^-1 v / 2 and M = A / (1 + c' A c). For a usable start, data should be centred and
    scaled to about unit radius first. Returns (centre, M, ok) where ok says M is positive
    definite (an ellipsoid, not a hyperboloid: with poor coverage the unconstrained quadric
    can be either, and then the caller must fall back to a sphere).
    """
    X, Y, Z = x[:, 0], x[:, 1], x[:, 2]
    D = jnp.stack([X * X, Y * Y, Z * Z, 2 * X * Y, 2 * X * Z, 2 * Y * Z, X, Y, Z], axis=1)
    Dw = D * w[:, None]
    u = cho_solve_small(Dw.T @ D, Dw.T @ jnp.ones_like(X))
    A = jnp.array([[u[0], u[3], u[4]], [u[3], u[1], u[5]], [u[4], u[5], u[2]]])
    v = u[6:9]
    evals, evecs = eigh_small(A)
    pd = jnp.all(evals > 0) & jnp.all(jnp.isfinite(u))
    safe = jnp.where(pd, evals, 1.0)
    Ainv = (evecs / safe) @ evecs.T
    c = -0.5 * Ainv @ v
    s = 1.0 + c @ A @ c
    M = A / s
    ok = pd & (s > 0)
    return c, M, ok


def sqrtm_inv_spd(M: jax.Array) -> jax.Array:
    """M^(-1/2) for a symmetric positive-definite 3x3 M (symmetric result)."""
    evals, evecs = eigh_small(M)
    return (evecs / jnp.sqrt(evals)) @ evecs.T
