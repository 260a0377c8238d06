"""The ellipsoid (hard-iron / soft-iron) model of paper 2, section 2.2, and its quadric residual.

A sensor that measures a vector of constant magnitude (the earth's field for a magnetometer,
gravity for a static accelerometer) traces an ellipsoid::

    (x - c)' M (x - c) = 1,        M symmetric positive definite,

with x the raw reading, c the centre (hard iron / bias, raw units) and M the shape (soft iron,
gains and non-orthogonality, 1 / raw units^2). The compensation (paper 2, Fig. 2, step 4)
rotates into the ellipsoid's axes, scales each axis onto a sphere of radius r and rotates
back::

    y = W (x - c),     W = r * M^(1/2) = R diag(r / semi_axes) R'      (symmetric)

The quadric residual ``e = r ((x - c)' M (x - c) - 1)``, r = det(M)^(-1/6), is polynomial in
the data (so its sums reduce to moments). With M = alpha^2 / g^2 the full ellipsoid is paper
1's nine-parameter model (the same family: W = alpha up to the radius); its residual is paper
1's normalised sphere residual times r, which moves the optimum only at second order in the
residuals.

Parameter vectors (all pure, one sensor, jittable, differentiable). The shape is kept positive
definite by a Cholesky factor with log-diagonal, M = L L'::

    sphere : [log s, c_x, c_y, c_z]                       M = s^2 I          (4)
    diag   : [l_x, l_y, l_z, c_x, c_y, c_z]               M = diag(e^(2l))   (6)
    full   : [l_xx, l_yy, l_zz, l_yx, l_zx, l_zy, c...]   L lower, diag e^l  (9)
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..linalg import inv3

MAG_MODELS = ("sphere", "diag", "full")
N_PARAMS = {"sphere": 4, "diag": 6, "full": 9}
PARAM_NAMES = {
    "sphere": ("log_s", "c_x", "c_y", "c_z"),
    "diag": ("l_x", "l_y", "l_z", "c_x", "c_y", "c_z"),
    "full": ("l_xx", "l_yy", "l_zz", "l_yx", "l_zx", "l_zy", "c_x", "c_y", "c_z"),
}


class EllipsoidParams(eqx.Module):
    """An ellipsoid (x - c)' M (x - c) = 1 in raw units."""

    center: Float[Array, "3"]
    """c: the hard-iron offset / bias, raw units."""
    shape: Float[Array, "3 3"]
    """M: symmetric positive definite, 1 / raw units^2."""


def unpack(p: Float[Array, " n"], model: str) -> tuple[jax.Array, jax.Array]:
    """Parameter vector -> (centre, M) for ``model`` (static)."""
    if model == "sphere":
        s2 = jnp.exp(2.0 * p[0])
        return p[1:4], s2 * jnp.eye(3, dtype=p.dtype)
    if model == "diag":
        return p[3:6], jnp.diag(jnp.exp(2.0 * p[:3]))
    if model == "full":
        d = jnp.exp(p[:3])
        z = jnp.zeros((), p.dtype)
        L = jnp.stack(
            [
                jnp.stack([d[0], z, z]),
                jnp.stack([p[3], d[1], z]),
                jnp.stack([p[4], p[5], d[2]]),
            ]
        )
        return p[6:9], L @ L.T
    raise ValueError(f"model must be one of {MAG_MODELS}, got {model!r}")


def pack(centre: jax.Array, M: jax.Array, model: str) -> jax.Array:
    """(centre, M) -> parameter vector (the closest one for sphere and diag models)."""
    if model == "sphere":
        return jnp.concatenate([0.5 * jnp.log(jnp.trace(M) / 3.0)[None], centre])
    if model == "diag":
        return jnp.concatenate([0.5 * jnp.log(jnp.diag(M)), centre])
    if model == "full":
        L = cholesky3(M)
        return jnp.concatenate(
            [jnp.log(jnp.diag(L)), jnp.stack([L[1, 0], L[2, 0], L[2, 1]]), centre]
        )
    raise ValueError(f"model must be one of {MAG_MODELS}, got {model!r}")


def cholesky3(M: jax.Array) -> jax.Array:
    """Lower Cholesky factor of a 3x3 SPD matrix in jnp operations (NaN if not SPD)."""
    l00 = jnp.sqrt(M[0, 0])
    l10 = M[1, 0] / l00
    l20 = M[2, 0] / l00
    l11 = jnp.sqrt(M[1, 1] - l10 * l10)
    l21 = (M[2, 1] - l20 * l10) / l11
    l22 = jnp.sqrt(M[2, 2] - l20 * l20 - l21 * l21)
    z = jnp.zeros((), M.dtype)
    return jnp.stack([jnp.stack([l00, z, z]), jnp.stack([l10, l11, z]), jnp.stack([l20, l21, l22])])


def quadric_residual(p: Float[Array, " n"], x: Float[Array, "N 3"], model: str) -> jax.Array:
    """e_i = r (q_i - 1), q_i = (x_i - c)' M (x_i - c), r = det(M)^(-1/6) (data units).

    The quadric q - 1 scaled by the ellipsoid's mean radius, so that e is about twice the
    distance from the surface in data units. Unscaled, q - 1 is relative to the radius, and a
    misfitting model (a sphere through an elongated ellipsoid) lowers it without bound by
    growing the radius (the sphere through the data of ``tomisuarez_qmc5883l_mag`` ran off to
    150 times the field). Still a polynomial in the data.
    """
    c, M = unpack(p, model)
    d = x - c
    return log_radius_scale(p, model) * (jnp.einsum("ni,ij,nj->n", d, M, d) - 1.0)


def log_radius_scale(p: Float[Array, " n"], model: str) -> jax.Array:
    """det(M)^(-1/6) from the packed parameters, without a decomposition."""
    if model == "sphere":
        return jnp.exp(-p[0])
    return jnp.exp(-jnp.sum(p[:3]) / 3.0)


def radial_error(centre: ArrayLike, M: ArrayLike, x: ArrayLike, xp=jnp) -> ArrayLike:
    """Relative radial error |M^(1/2) (x - c)| - 1 of each sample (dimensionless). ``xp``: jnp
    inside the fits, np for host samples of a long log (no device copy)."""
    d = x - centre
    return xp.sqrt(xp.maximum(xp.einsum("ni,ij,nj->n", d, M, d), 0.0)) - 1.0


def sqrtm_spd(M: Float[ArrayLike, "3 3"], iterations: int = 12) -> jax.Array:
    """Principal square root of a 3x3 SPD matrix by Denman-Beavers iterations.

    Smooth in M (unlike a Jacobi eigen-decomposition, whose derivative through the rotation
    choices is NaN), so Jacobians of W give standard errors. M is scaled to unit mean
    eigenvalue first; 12 quadratically converging iterations reach float64 round-off for
    condition numbers up to ~1e4 (ellipsoid axis ratios up to 100).
    """
    s = jnp.trace(M) / 3.0
    Y = M / s
    Z = jnp.eye(3, dtype=M.dtype)

    def step(_, yz):
        Y, Z = yz
        return 0.5 * (Y + inv3(Z)), 0.5 * (Z + inv3(Y))

    Y, _ = jax.lax.fori_loop(0, iterations, step, (Y, Z))
    Y = 0.5 * (Y + Y.T)
    return Y * jnp.sqrt(s)


def soft_iron_matrix(M: Float[ArrayLike, "3 3"], radius: float | jax.Array) -> jax.Array:
    """W = radius * M^(1/2), symmetric: maps centred raw data onto the sphere of ``radius``."""
    return radius * sqrtm_spd(M)


def natural_radius(M: Float[ArrayLike, "3 3"], xp=jnp) -> ArrayLike:
    """det(M)^(-1/6): the radius that keeps det W = 1 (MATLAB magcal's convention), i.e. the
    geometric mean of the semi-axes, in raw units. ``xp``: np on the host (no eager program)."""
    return xp.linalg.det(M) ** (-1.0 / 6.0)


def raw_calibration(
    p: Float[Array, " n"],
    model: str,
    mean: Float[ArrayLike, "3"],
    scale: Float[ArrayLike, ""],
    field: Float[ArrayLike, ""],
) -> tuple[jax.Array, jax.Array]:
    """(c, W) in raw units from the packed parameters of a fit to x = (raw - mean) / scale.

    c = mean + scale c_n. W = radius M^(1/2) with M = M_n / scale^2: radius ``field`` (the
    output then has that magnitude), or, where ``field`` is NaN, det(M)^(-1/6) (det W = 1,
    dimensionless whatever the raw unit). The one definition of the magnetometer's (c, W):
    differentiate it for their standard errors (:func:`calib_jax.calibrate_mag`, the batch
    and :func:`calib_jax.pipeline.fit_mag` all do).
    """
    c_n, M_n = unpack(p, model)
    k = jnp.where(jnp.isnan(field), natural_radius(M_n), field / scale)
    return mean + scale * c_n, k * sqrtm_spd(M_n)


def raw_covariance(
    p: Float[Array, " n"],
    covariance: Float[Array, "n n"],
    model: str,
    mean: Float[ArrayLike, "3"],
    scale: Float[ArrayLike, ""],
    field: Float[ArrayLike, ""],
) -> Float[Array, "12 12"]:
    """Covariance of [c, ravel(W)] (:func:`raw_calibration`) from that of the packed
    parameters, to first order."""
    J = jax.jacfwd(
        lambda q: jnp.concatenate(
            [a.ravel() for a in raw_calibration(q, model, mean, scale, field)]
        )
    )(p)
    return J @ covariance @ J.T


def compensate(params: EllipsoidParams, raw: jax.Array, radius: float | jax.Array) -> jax.Array:
    """Paper 2's compensation of raw samples (..., 3) onto the sphere of ``radius``."""
    W = soft_iron_matrix(params.shape, radius)
    return (raw - params.center) @ W.T
