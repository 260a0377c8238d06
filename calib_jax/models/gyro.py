"""The gyroscope model: true rate = C (raw - b).

C is a general 3 x 3 matrix (nine parameters: three scales and six misalignment terms) and b
the bias, in raw units. The peers write the same model factored: imu_tk's w = T K (raw - b),
K the diagonal scale and T the misalignment with unit diagonal (:func:`to_imu_tk`), and
imucal's w = (K_g R_g)^-1 (raw - b_g) (:mod:`calib_jax.export`). One nine-vector, C row by row,
is the fitted parameter vector.

The residual is imu_tk's (Tedaldi et al., ICRA 2014): between two consecutive static poses the
calibrated rates, integrated, must turn the gravity direction of the first pose (from the
calibrated accelerometer) onto that of the second.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.typing import ArrayLike

from ..rotations import integrate_rates, quat_to_dcm


class Motions(NamedTuple):
    """The rotations between consecutive static poses, padded to one length.

    ``rates`` (K, L, 3) are the raw gyro readings minus the bias, from the last sample of one
    pose to the first of the next; ``dt`` (K, L) the time from each sample to the next (zero
    past a motion's end, where the rates are zero too: an identity step); ``before`` and
    ``after`` (K, 3) the unit gravity directions of the two poses in the sensor frame.
    """

    rates: jax.Array
    dt: jax.Array
    before: jax.Array
    after: jax.Array


class GyroParams(eqx.Module):
    """One gyroscope's calibration as a JAX pytree: w = C x, x = raw - b - G a, times
    1 + s sign(x) per axis (:func:`asymmetric`). G and s are zero unless the fit found them."""

    matrix: jax.Array
    """C (3 x 3), rad/s per raw unit."""
    bias: jax.Array
    """b (3,), raw units."""
    g_sensitivity: jax.Array
    """G (3 x 3), raw units per m/s^2."""
    scale_asymmetry: jax.Array
    """s (3,)."""

    def apply(self, raw: ArrayLike, acc: ArrayLike | None = None) -> jax.Array:
        """Calibrated rates (..., 3) in rad/s; ``acc`` the calibrated acceleration in m/s^2
        of the same samples (needed when G is not zero). Jittable and differentiable; the
        sign of the asymmetry is taken exactly here (the fit uses a smooth one)."""
        x = jnp.asarray(raw) - self.bias
        if acc is not None:
            x = x - jnp.asarray(acc) @ self.g_sensitivity.T
        x = x * (1.0 + self.scale_asymmetry * jnp.sign(x))
        return x @ self.matrix.T


def motion_rotation(c9: ArrayLike, rates: ArrayLike, dt: ArrayLike) -> jax.Array:
    """The rotation matrix R of one motion, v_before = R v_after, from de-biased raw rates."""
    return quat_to_dcm(integrate_rates(jnp.asarray(rates) @ jnp.reshape(c9, (3, 3)).T, dt))


def gravity_residual(c9: ArrayLike, motions: Motions) -> jax.Array:
    """Residual (3K,): R_k' g_before - g_after for every motion, unit gravity directions.

    Its size is the angle (radians, for small errors) by which the integrated rotation misses
    the second pose's gravity direction. A rotation about gravity itself leaves it unchanged,
    so only motions with varied axes determine all nine parameters.
    """

    def one(rates, dt, u0, u1):
        return motion_rotation(c9, rates, dt).T @ u0 - u1

    return jax.vmap(one)(motions.rates, motions.dt, motions.before, motions.after).ravel()


ASYMMETRY_SOFTNESS = 1e-3
"""rad/s: the smooth sign tanh(w / this) of :func:`asymmetric` (differentiable at rest)."""


def asymmetric(rates: ArrayLike, asym: ArrayLike, xp=jnp) -> ArrayLike:
    """Rates read with a different scale one way than the other: w (1 + s sign(w)) per axis
    (a smooth sign, so rest and the Jacobian stay well defined). ``xp``: np on the host."""
    rates = xp.asarray(rates)
    return rates * (1.0 + asym * xp.tanh(rates / ASYMMETRY_SOFTNESS))


def gravity_residual_asymmetric(p12: ArrayLike, motions: Motions) -> jax.Array:
    """:func:`gravity_residual` with scale asymmetry: ``p12`` is C row by row, then the three
    asymmetries s of :func:`asymmetric` (applied to the de-biased rates before C)."""
    return gravity_residual(p12[:9], motions._replace(rates=asymmetric(motions.rates, p12[9:])))


def to_imu_tk(C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T, K) with C = T K: K the diagonal scale, T the misalignment with unit diagonal."""
    C = np.asarray(C, float)
    k = np.diag(C).copy()
    return C / k[None, :], np.diag(k)


def from_imu_tk(T: np.ndarray, K: np.ndarray) -> np.ndarray:
    """C = T K from imu_tk's misalignment and scale matrices."""
    return np.asarray(T, float) @ np.asarray(K, float)
