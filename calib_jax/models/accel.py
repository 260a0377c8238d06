"""Paper 1's nine-parameter accelerometer model (eq. 1) and its sphere residual (eq. 5-7).

Measured a' = alpha a + beta + noise, with alpha symmetric::

    alpha = [[alpha_x, S_xy,    S_xz   ],
             [S_xy,    alpha_y, S_yz   ],
             [S_xz,    S_yz,    alpha_z]]

The gains and the non-orthogonality terms are in input units per reference unit (dimensionless
when the log is already in g or m/s^2 and the reference is in the same unit; counts per g for
raw counts); beta is in input units. The parameter vector is paper 1's order
p = [alpha_x, alpha_y, alpha_z, S_xy, S_xz, S_yz, beta_x, beta_y, beta_z].

Everything here is pure, works on one sensor (no batch axis), and is jittable, vmappable and
differentiable.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..linalg import inv3
from .layout import ALPHA_ENTRIES, ALPHA_INDEX, PARAM_NAMES  # noqa: F401  (re-exported)


class AccelParams(eqx.Module):
    """The nine calibration parameters of one accelerometer (paper 1, eq. 1)."""

    gains: Float[Array, "3"]
    """alpha_x, alpha_y, alpha_z: input units per reference unit."""
    nonorth: Float[Array, "3"]
    """S_xy, S_xz, S_yz: off-diagonal terms of alpha, same unit as the gains."""
    bias: Float[Array, "3"]
    """beta_x, beta_y, beta_z: input units (the reading at zero acceleration)."""

    @classmethod
    def from_vector(cls, p: Float[Array, "*batch 9"]) -> AccelParams:
        """Build from paper 1's parameter vector p."""
        p = jnp.asarray(p)
        return cls(gains=p[0:3], nonorth=p[3:6], bias=p[6:9])

    def to_vector(self) -> Float[Array, "*batch 9"]:
        """Paper 1's parameter vector p."""
        return jnp.concatenate([self.gains, self.nonorth, self.bias], axis=-1)

    @property
    def alpha(self) -> Float[Array, "3 3"]:
        """The symmetric gain/non-orthogonality matrix alpha."""
        return alpha_matrix(self.to_vector())

    def apply(self, raw: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
        """Calibrated acceleration alpha^-1 (a' - beta), in the reference magnitude's unit."""
        return (raw - self.bias) @ inv3(self.alpha).T

    @classmethod
    def identity(cls, dtype=jnp.float64) -> AccelParams:
        """Unit gains, no cross terms, no bias (a reference point, never a fit result)."""
        return cls(gains=jnp.ones(3, dtype), nonorth=jnp.zeros(3, dtype), bias=jnp.zeros(3, dtype))


def alpha_matrix(p: Float[ArrayLike, "9"]) -> Float[Array, "3 3"]:
    """alpha from the parameter vector (symmetric, paper 1 eq. 1)."""
    return jnp.asarray(p)[ALPHA_INDEX]


def correct(p: Float[Array, "9"], raw: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
    """Calibrated acceleration a = alpha^-1 (a' - beta), in reference units.

    Works on one sample (3,) or many (..., 3). alpha^-1 is the closed-form 3x3 inverse
    (calib_jax.linalg explains why not LAPACK).
    """
    return (raw - p[6:9]) @ inv3(alpha_matrix(p)).T


def distort(p: Float[Array, "9"], a: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
    """The forward model a' = alpha a + beta (no noise): what the sensor reads."""
    return a @ alpha_matrix(p).T + p[6:9]


def sphere_residual(
    p: Float[Array, "9"], raw: Float[Array, "N 3"], g: float | Float[Array, ""]
) -> Float[Array, " N"]:
    """Paper 1 eq. 6: e(t) = |g|^2 - (a'(t) - beta)' (alpha^-1)^2 (a'(t) - beta).

    ``g`` is the reference magnitude in the unit the calibrated output should have (1 for g,
    9.80665 for m/s^2, a local value); e is in that unit squared. For raw counts the gains
    absorb the unknown scale, so ``g`` only fixes the output unit.
    """
    a = correct(p, raw)
    return g * g - jnp.sum(a * a, axis=-1)


def normalized_sphere_residual(
    p: Float[Array, "9"], raw: Float[Array, "N 3"], g: float | Float[Array, ""]
) -> Float[Array, " N"]:
    """eq. 6 divided by g^2: dimensionless, so solver tolerances do not depend on the unit.

    The minimiser is the same as for :func:`sphere_residual` (chi2 is scaled by 1/g^4).
    """
    a = correct(p, raw) / g
    return 1.0 - jnp.sum(a * a, axis=-1)
