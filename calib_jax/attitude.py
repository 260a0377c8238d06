"""Attitude from accelerometer + magnetometer by Gauss-Newton on the quaternion (paper 2, sec. 3).

For one sample, the quaternion q (body -> navigation, ENU) that rotates the reference vectors
onto the measured ones::

    eps(q) = [a; m] - [C(q)' r_a; C(q)' r_m]          (6 components, unit vectors)
    F(q)   = eps' eps                                  (the paper's cost, Table 1)

with r_a = [0, 0, 1] (the accelerometer measures the upward specific force at rest) and
r_m = [0, cos(dip), -sin(dip)] (the field points north and down by the dip angle). Paper 2
takes the Gauss-Newton method from its ref. [11]; here each step solves
(J'J + q q') dq = -J' eps (q q' fills the null direction the unit norm leaves in J) and then
renormalises q. F measures how inconsistent the two sensors are: with perfect data it is
the noise, and a wrong dip, a distorted or a misaligned sensor raise it.

The start is TRIAD (closed form from the same two vectors), so the iterations only refine it;
``q0`` overrides it (e.g. the previous sample's estimate). Everything is pure and per sample;
:func:`estimate_attitude` vmaps over samples.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .linalg import cho_solve_small
from .padding import pad_rows
from .rotations import dcm_to_quat, euler_zyx_deg, quat_normalize, quat_to_dcm


def reference_vectors(dip_deg: float | jax.Array) -> tuple[jax.Array, jax.Array]:
    """(r_a, r_m) in ENU for a field with inclination ``dip_deg`` (positive: pointing down)."""
    d = jnp.radians(jnp.asarray(dip_deg, dtype=float))
    r_a = jnp.array([0.0, 0.0, 1.0])
    r_m = jnp.stack([0.0 * d, jnp.cos(d), -jnp.sin(d)])
    return r_a, r_m


def triad(a: jax.Array, m: jax.Array, r_a: jax.Array, r_m: jax.Array) -> jax.Array:
    """TRIAD quaternion (body -> nav) trusting a exactly and m for the heading."""

    def frame(u, v):
        t1 = u / jnp.linalg.norm(u)
        t2 = jnp.cross(t1, v)
        t2 = t2 / jnp.linalg.norm(t2)
        return jnp.stack([t1, t2, jnp.cross(t1, t2)], axis=1)

    C = frame(r_a, r_m) @ frame(a, m).T
    return dcm_to_quat(C)


def gn_residual(q: jax.Array, a: jax.Array, m: jax.Array, r_a, r_m) -> jax.Array:
    C = quat_to_dcm(quat_normalize(q))
    return jnp.concatenate([a - C.T @ r_a, m - C.T @ r_m])


def gauss_newton_quaternion(
    a: Float[Array, "3"],
    m: Float[Array, "3"],
    r_a: Float[Array, "3"],
    r_m: Float[Array, "3"],
    q0: Float[Array, "4"] | None = None,
    iterations: int = 6,
) -> tuple[jax.Array, jax.Array]:
    """One sample: (q, F) after ``iterations`` Gauss-Newton steps. Inputs need not be unit
    vectors (they are normalised); q is body -> nav with w >= 0."""
    a = a / jnp.linalg.norm(a)
    m = m / jnp.linalg.norm(m)
    r_a = r_a / jnp.linalg.norm(r_a)
    r_m = r_m / jnp.linalg.norm(r_m)
    q = triad(a, m, r_a, r_m) if q0 is None else quat_normalize(q0)
    jac = jax.jacfwd(gn_residual)

    def step(_, q):
        e = gn_residual(q, a, m, r_a, r_m)
        J = jac(q, a, m, r_a, r_m)
        dq = cho_solve_small(J.T @ J + jnp.outer(q, q), -J.T @ e)
        q_new = quat_normalize(q + dq)
        return jnp.where(jnp.all(jnp.isfinite(q_new)), q_new, q)

    q = jax.lax.fori_loop(0, iterations, step, q)
    q = jnp.where(q[0] < 0, -q, q)
    e = gn_residual(q, a, m, r_a, r_m)
    return q, e @ e


class Attitude(eqx.Module):
    """Per-sample attitude: quaternions body -> ENU, Euler angles and the GN cost."""

    quat: Float[Array, "N 4"]
    euler_deg: Float[Array, "N 3"]
    """[roll, pitch, yaw] in degrees, ZYX."""
    cost: Float[Array, " N"]
    """F(x) of paper 2 (Table 1): squared residual of the unit vectors at the solution."""
    dip_deg: Float[Array, ""]


@functools.partial(jax.jit, static_argnames=("iterations",))
def _batch(acc, mag, r_a, r_m, iterations):
    q, F = jax.vmap(lambda a, m: gauss_newton_quaternion(a, m, r_a, r_m, None, iterations))(
        acc, mag
    )
    return q, jax.vmap(euler_zyx_deg)(q), F


def dip_from_data(acc: np.ndarray, mag: np.ndarray) -> float:
    """Dip angle (deg, positive down) from the median angle between a (up) and m."""
    a = acc / np.linalg.norm(acc, axis=1, keepdims=True)
    m = mag / np.linalg.norm(mag, axis=1, keepdims=True)
    ang = np.degrees(np.arccos(np.clip(np.sum(a * m, axis=1), -1, 1)))
    return float(np.median(ang) - 90.0)


def estimate_attitude(
    acc: np.ndarray | jax.Array,
    mag: np.ndarray | jax.Array,
    *,
    dip_deg: float | None = None,
    reference: tuple | str | None = None,
    iterations: int = 6,
) -> Attitude:
    """Gauss-Newton attitude for every sample (jitted, vmapped over samples).

    Parameters
    ----------
    acc, mag : (N, 3)
        Accelerometer and magnetometer in the same (body) frame; any units.
    dip_deg : float, optional
        Field inclination; default the median measured angle between a and m minus 90 deg.
    reference : (r_a, r_m) or "first", optional
        Reference vectors instead of ENU with ``dip_deg``; "first" takes the mean of the first
        1 % of samples (at least 10), so the attitude is relative to the starting pose (paper
        2's inclined-plane test: ideally roll = pitch = 0 while the board turns).
    """
    acc = jnp.asarray(acc, float)
    mag = jnp.asarray(mag, float)
    if acc.shape != mag.shape or acc.ndim != 2 or acc.shape[1] != 3:
        raise ValueError(f"acc and mag must both be (N, 3), got {acc.shape} and {mag.shape}")
    if isinstance(reference, str):
        if reference != "first":
            raise ValueError(f"reference must be 'first' or (r_a, r_m), got {reference!r}")
        k = max(10, len(acc) // 100)
        r_a, r_m = acc[:k].mean(axis=0), mag[:k].mean(axis=0)
        dip = float(np.degrees(np.arccos(r_a @ r_m / np.linalg.norm(r_a) / np.linalg.norm(r_m))))
        dip -= 90.0
    elif reference is not None:
        r_a, r_m = (jnp.asarray(v, float) for v in reference)
        dip = float(np.degrees(np.arccos(r_a @ r_m / np.linalg.norm(r_a) / np.linalg.norm(r_m))))
        dip -= 90.0
    else:
        dip = dip_from_data(np.asarray(acc), np.asarray(mag)) if dip_deg is None else dip_deg
        r_a, r_m = reference_vectors(dip)
    # pad to a power of two (repeating a row) so that logs of similar length share a compilation
    n = acc.shape[0]
    q, eul, F = _batch(
        jnp.asarray(pad_rows(np.asarray(acc))[0]),
        jnp.asarray(pad_rows(np.asarray(mag))[0]),
        r_a,
        r_m,
        iterations,
    )
    return Attitude(quat=q[:n], euler_deg=eul[:n], cost=F[:n], dip_deg=jnp.asarray(dip))
