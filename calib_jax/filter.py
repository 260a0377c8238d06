"""A gyro-aided attitude filter in JAX: Mahony's complementary filter on the quaternion.

The gyro carries the attitude from sample to sample (:func:`calib_jax.rotations.quat_exp` of
the corrected rate times dt); the accelerometer pulls the estimated "up" towards the measured
one and the magnetometer the heading towards magnetic north (its horizontal part only, so the
dip needs no estimate). Each pull is weighted down smoothly when its vector's magnitude leaves
the reference (motion acceleration, a nearby magnet): ``exp(-((|v| / ref - 1) / tol)^2)``.
An integral term estimates the gyro bias. Mahony, Hamel, Pflimlin, IEEE TAC 53(5), 2008.

One ``lax.scan`` over the samples: jittable, vmappable over logs of equal length, and
differentiable in the gains and in every input (so in the calibrations that produced them).
Quaternions are body -> ENU, [w, x, y, z], as everywhere in calib_jax.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from .attitude import reference_vectors, triad
from .rotations import quat_exp, quat_multiply, quat_to_dcm


class FilterGains(NamedTuple):
    """Gains of :func:`complementary_filter` (defaults: a hand-held IMU at 100-300 Hz)."""

    k_acc: float = 1.0
    """rad/s of correction per unit of the accelerometer's direction error."""
    k_mag: float = 1.0
    """The same for the magnetometer's horizontal direction."""
    k_bias: float = 0.02
    """Integral gain: rad/s^2 of bias change per unit of error."""
    acc_tol: float = 0.05
    """Relative deviation of |a| from g at which the accelerometer's weight falls to 1/e."""
    mag_tol: float = 0.05
    """The same for |m| against the field magnitude."""


def _weight(v, ref, tol):
    return jnp.exp(-(((jnp.linalg.norm(v) / ref - 1.0) / tol) ** 2))


def _step(gains: FilterGains, g: float | jax.Array, field: float | jax.Array, carry, sample):
    q, b = carry
    w, a, m, dt = sample
    C = quat_to_dcm(q)
    up = C[2]  # C' [0, 0, 1]: the estimated up in the body frame
    e_a = jnp.cross(a / jnp.linalg.norm(a), up) * _weight(a, g, gains.acc_tol)
    # heading: the field in ENU by the current estimate points east of north by psi; a turn
    # of +psi about the vertical (up, in the body frame) brings it back. sin(psi) is the pull
    h = C @ m
    sin_psi = h[0] / jnp.sqrt(h[0] ** 2 + h[1] ** 2 + 1e-30)
    e_m = sin_psi * up * _weight(m, field, gains.mag_tol)
    e = gains.k_acc * e_a + gains.k_mag * e_m
    q_new = quat_multiply(q, quat_exp((w - b + e) * dt))
    q_new = q_new / jnp.linalg.norm(q_new)
    b_new = b - gains.k_bias * (e_a + e_m) * dt
    return (q_new, b_new), (q_new, b_new)


def complementary_filter(
    gyro: ArrayLike,
    acc: ArrayLike,
    mag: ArrayLike,
    dt: ArrayLike,
    *,
    gains: FilterGains | None = None,
    g: float | jax.Array | None = None,
    field: float | jax.Array | None = None,
    q0: ArrayLike | None = None,
    bias0: ArrayLike | None = None,
) -> tuple[jax.Array, jax.Array]:
    """Attitude (N, 4) and gyro-bias estimate (N, 3) of a log.

    Parameters
    ----------
    gyro, acc, mag : (N, 3)
        Rates in rad/s, acceleration and field in any units, one clock.
    dt : scalar or (N,)
        Seconds from each sample to the next.
    gains : FilterGains, optional
        Default ``FilterGains()``.
    g, field : float, optional
        Reference magnitudes for the weights; default the medians of |a| and |m| (host-side
        numpy, so give them inside ``jit``/``grad``).
    q0 : (4,), optional
        Start; default TRIAD from the first sample.
    bias0 : (3,), optional
        Initial gyro bias, rad/s (default zero).
    """
    gains = FilterGains() if gains is None else gains
    gyro, acc, mag = (jnp.asarray(x) for x in (gyro, acc, mag))
    n = gyro.shape[0]
    dt = jnp.broadcast_to(jnp.asarray(dt, gyro.dtype), (n,))
    if g is None:
        g = float(np.median(np.linalg.norm(np.asarray(acc), axis=1)))
    if field is None:
        field = float(np.median(np.linalg.norm(np.asarray(mag), axis=1)))
    if q0 is None:
        dip = jnp.degrees(
            jnp.arcsin(
                -jnp.dot(acc[0], mag[0]) / (jnp.linalg.norm(acc[0]) * jnp.linalg.norm(mag[0]))
            )
        )
        r_a, r_m = reference_vectors(dip)
        q0 = triad(acc[0], mag[0], r_a, r_m)
    b0 = jnp.zeros(3, gyro.dtype) if bias0 is None else jnp.asarray(bias0, gyro.dtype)

    def step(carry, sample):
        return _step(gains, g, field, carry, sample)

    # the attitude after sample k is reached with sample k's rate over dt[k]: the first row
    # of the output is q0 itself
    _, (q, b) = jax.lax.scan(step, (jnp.asarray(q0, gyro.dtype), b0), (gyro, acc, mag, dt))
    q = jnp.concatenate([jnp.asarray(q0, gyro.dtype)[None], q[:-1]])
    b = jnp.concatenate([b0[None], b[:-1]])
    return jnp.where(q[:, :1] < 0, -q, q), b
