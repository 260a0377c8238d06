"""Calibration as a JAX library: pytrees in, pytrees out, composable with jit, vmap and grad.

For users who embed calibration in a larger JAX estimation pipeline (an attitude filter, a
navigation solution, a learned model). Everything here is pure, works on one sensor (``vmap``
for many), keeps the dtype of its inputs (float64 or float32) and is differentiable:

Calibrations (``equinox`` modules, hence pytrees):

- :class:`AccelParams` (paper 1, eq. 1): raw ``a' = alpha a + beta``; ``apply`` returns
  ``a = alpha^-1 (a' - beta)`` in the unit of the reference magnitude.
- :class:`MagParams`: hard iron ``c`` (raw units) and a soft-iron matrix ``W`` (output units
  per raw unit); ``apply`` returns ``W (m' - c)`` (paper 2's compensation, section 2.2).
- :class:`Rotation`: a rotation vector (rad); ``apply`` rotates row vectors, v -> R v.
- :class:`MargParams`: accelerometer, magnetometer, and the rotation that takes the
  calibrated magnetometer into the accelerometer's frame.
- :class:`GyroParams`: ``apply`` returns the rates C (raw - b) in rad/s (g-sensitivity and
  scale asymmetry zero unless :func:`calib_jax.calibrate_gyro` found them).

Frames: every calibrated vector is in the sensor's own (body) frame, except that
:class:`MargParams` returns the magnetometer in the accelerometer's frame. Attitude
quaternions are [w, x, y, z] and rotate body vectors into ENU (the BROAD convention).

Functions:

- :func:`apply`, :func:`residual`: calibrated samples and the sphere residual.
- :func:`fit_accel`, :func:`fit_mag`, :func:`fit_gyro`: the fit of one sensor, returning a
  :class:`Fit` whose ``params`` are differentiable in the samples, the weights and the
  reference magnitude (for the gyro: the rates, time steps, gravity directions and rests) by
  the implicit function theorem (:func:`calib_jax.implicit.solve_implicit`), never by
  unrolling the LM loop. :func:`fit_batch` vmaps the first two over a leading sensor axis;
  :func:`fit_gyro` takes :class:`GyroInputs` (:func:`gyro_inputs` cuts a log into them,
  :func:`stack_gyro_inputs` stacks several for ``vmap``).
- :func:`attitude`: the Gauss-Newton quaternion (paper 2, sec. 3) of every sample from raw
  accelerometer and magnetometer through a :class:`MargParams`.
- :func:`propagate`, :func:`calibrated_covariance`, :func:`attitude_std`: the parameter
  covariance carried to any output by its Jacobian (first order).

Not converged: a :class:`Fit` carries the solver ``status`` (``Fit.converged`` inside jit).
The implicit derivative is that of the optimum near the returned point; where the fit did not
converge it does not describe the returned parameters (see :mod:`calib_jax.implicit`).

float32: supported with a documented accuracy (docs/pipeline.md): the fits work on
data normalised to unit scale and stop at float32 round-off; tested within 3 % of a standard
error of the float64 parameters, 3e-4 of the derivatives' scale and 5e-3 deg of attitude
(``benchmarks/float32_accuracy.py`` measures the spread over many boards). float64 is the
default for calibration (``jax_enable_x64``).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from jaxtyping import Array, ArrayLike, Float, Int, Real

from .accel import FLAT_POSES, fit_normalized, not_at_rest
from .attitude import gauss_newton_quaternion, reference_vectors
from .geometry import (
    centre_and_scale,
    moments,
    prefit_status,
    shell_status,
    stand_in_directions,
)
from .gyro import _angles, _pad_motions, _pose_log, start_scale
from .implicit import solve_implicit
from .linalg import det3
from .mag import FLAT_POINTS, fit_ellipsoid_normalized
from .models.accel import AccelParams, alpha_matrix
from .models.gyro import GyroParams, Motions, gravity_residual
from .models.mag import N_PARAMS, natural_radius, raw_calibration, raw_covariance, unpack
from .padding import bucket, stack_rows
from .rotations import euler_zyx_deg, rotvec_to_dcm
from .status import CONVERGED_STATUSES, Status, status_message

__all__ = [
    "AccelParams",
    "Fit",
    "GyroInputs",
    "GyroParams",
    "MagParams",
    "MargParams",
    "Rotation",
    "apply",
    "attitude",
    "attitude_std",
    "block_covariance",
    "calibrated_covariance",
    "euler_deg",
    "fit_accel",
    "fit_batch",
    "fit_gyro",
    "gyro_inputs",
    "fit_mag",
    "propagate",
    "residual",
    "stack_gyro_inputs",
]


def _full_float32(f: Callable) -> Callable:
    """``f`` with its matrix products at full float32 precision when traced in float32.

    On a GPU, JAX multiplies float32 matrices in TF32 (a 10-bit mantissa) unless told
    otherwise: the float32 fits here then stopped far from the float64 optimum. Measured on an
    H200 over 40 boards (benchmarks/float32_accuracy.py, largest values): magnetometer
    parameters 33 % of a standard error off (0.2 % on the CPU), the implicit derivative 3.2e-3
    of its scale (5.2e-5), roll/pitch/yaw 0.054 deg (0.0018), one fit of 40 not converged.
    float64 and the CPU are unchanged (their products are exact already)."""

    @functools.wraps(f)
    def wrapped(*args, **kwargs):
        with jax.default_matmul_precision("highest"):
            return f(*args, **kwargs)

    return wrapped


# ---------------------------------------------------------------------------------------------
# calibrations


class MagParams(eqx.Module):
    """Hard and soft iron of one magnetometer (or any ellipsoid-to-sphere map)."""

    hard_iron: Float[Array, "3"]
    """c: the reading at zero field, raw units."""
    soft_iron: Float[Array, "3 3"]
    """W: output units per raw unit; :func:`fit_mag` returns it symmetric (paper 2's
    compensation matrix R diag(r / semi_axes) R')."""

    def apply(self, raw: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
        """Calibrated field W (m' - c), in the unit of the fit's reference magnitude."""
        return (raw - self.hard_iron) @ self.soft_iron.T

    @classmethod
    def from_vector(cls, p: Float[Array, "12"]) -> MagParams:
        """From the batch layout: the centre (3), then W row by row (9)."""
        p = jnp.asarray(p)
        return cls(hard_iron=p[:3], soft_iron=p[3:].reshape(3, 3))

    @classmethod
    def identity(cls, dtype=jnp.float64) -> MagParams:
        """No hard iron, unit soft iron (a reference point, never a fit result)."""
        return cls(hard_iron=jnp.zeros(3, dtype), soft_iron=jnp.eye(3, dtype=dtype))


class Rotation(eqx.Module):
    """A rotation by its rotation vector (axis times angle, rad): smooth near identity."""

    rotvec: Float[Array, "3"]

    @property
    def matrix(self) -> Float[Array, "3 3"]:
        return rotvec_to_dcm(self.rotvec)

    def apply(self, v: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
        """v -> R v for row vectors (..., 3)."""
        return v @ self.matrix.T

    @classmethod
    def identity(cls, dtype=jnp.float64) -> Rotation:
        return cls(rotvec=jnp.zeros(3, dtype))


class MargParams(eqx.Module):
    """One accelerometer + magnetometer board: both calibrations and the accel-mag rotation."""

    acc: AccelParams
    mag: MagParams
    mag_to_acc: Rotation
    """Rotates the calibrated magnetometer into the accelerometer's frame."""

    def apply(
        self, acc_raw: Float[Array, "... 3"], mag_raw: Float[Array, "... 3"]
    ) -> tuple[jax.Array, jax.Array]:
        """(accelerometer, magnetometer), both calibrated and in the accelerometer's frame."""
        return self.acc.apply(acc_raw), self.mag_to_acc.apply(self.mag.apply(mag_raw))

    @classmethod
    def identity(cls, dtype=jnp.float64) -> MargParams:
        return cls(AccelParams.identity(dtype), MagParams.identity(dtype), Rotation.identity(dtype))


Calibration = AccelParams | MagParams


@_full_float32
def apply(params: Calibration | MargParams, *raw: jax.Array):
    """Calibrated samples: ``apply(accel_or_mag_params, raw)`` -> (..., 3), or
    ``apply(marg_params, acc_raw, mag_raw)`` -> (acc, mag) in the accelerometer's frame.
    ``raw`` may be any array-like (a list, numpy) whose last axis is x, y, z. A record
    (``AccelCalibration``, ...) is taken outside jit; under jit give ``cal.to_params()``."""
    if hasattr(params, "to_params") and not isinstance(params, eqx.Module):
        params = params.to_params()  # a record, outside jit (jit takes only its pytree)
    raw = tuple(jnp.asarray(r) for r in raw)
    for r in raw:
        if r.ndim == 0 or r.shape[-1] != 3:  # was a broadcasting error from inside JAX
            raise ValueError(
                f"raw must be (..., 3), the last axis x, y, z, got shape {r.shape}"
                + (" (transposed? pass raw.T)" if r.ndim == 2 and r.shape[0] == 3 else "")
            )
    return params.apply(*raw)


@_full_float32
def residual(params: Calibration, raw: Float[Array, "N 3"], magnitude=1.0) -> jax.Array:
    """|apply(params, raw)| - magnitude for each sample, in the unit of ``magnitude`` (the
    sphere residual as a distance; paper 1's eq. 6 is its product with |a| + magnitude)."""
    y = apply(params, raw)
    return jnp.sqrt(jnp.sum(y * y, axis=-1)) - magnitude


# ---------------------------------------------------------------------------------------------
# fits


class Fit(eqx.Module):
    """A fitted calibration with its uncertainty and the solver's account.

    ``covariance`` is over ``jax.flatten_util.ravel_pytree(params)[0]`` (for
    :class:`AccelParams` that is paper 1's order [gains, nonorth, bias]; for
    :class:`MagParams` [hard_iron, soft_iron row-major], singular because W is symmetric),
    scaled by the reduced chi2 unless the weights were 1/sigma^2 (``absolute_sigma=True``).

    Only ``params`` carries a derivative (the implicit one): ``covariance`` and ``stderr``
    are computed from the forward solve and are constants under ``grad``; ``rms`` follows the
    data only through its explicit dependence. To optimise an experiment design on the
    uncertainty, rebuild (J'WJ)^-1 from :func:`residual` at ``params`` inside your function.
    """

    params: AccelParams | MagParams | GyroParams
    covariance: Float[Array, "n n"]
    status: Int[Array, ""]
    """:class:`calib_jax.lm.Status` code; see ``converged``."""
    rms: Float[Array, ""]
    """Weighted RMS of :func:`residual` at the optimum, unit of the magnitude (the gyro:
    of the angle by which the integrated rotations miss the next pose, radians)."""
    iterations: Int[Array, ""]

    @property
    def converged(self) -> jax.Array:
        """Boolean array (usable inside jit and vmap)."""
        return jnp.isin(self.status, jnp.asarray([int(c) for c in CONVERGED_STATUSES]))

    @property
    def message(self) -> str:
        """The status in words, for one concrete fit (host side; ``status`` is the code):
        :func:`calib_jax.lm.status_message`."""
        return status_message(int(self.status))

    @property
    def stderr(self) -> jax.Array:
        """Standard errors in the order of ``covariance``."""
        return jnp.sqrt(jnp.diagonal(self.covariance, axis1=-2, axis2=-1))


def _normalisation(raw, w):
    """geometry.centre_and_scale, held constant under differentiation: the fit is an exact
    reparametrisation, so centre and scale only condition the solve."""
    m, s = centre_and_scale(raw, w)
    return jax.lax.stop_gradient(m), jax.lax.stop_gradient(s)


def _prepare(raw, magnitude, weights):
    raw = jnp.asarray(raw)
    if raw.ndim != 2 or raw.shape[-1] != 3:
        raise ValueError(f"raw must be (N, 3) for one sensor (vmap for many), got {raw.shape}")
    if raw.shape[0] < 10:
        raise ValueError(f"{raw.shape[0]} samples cannot determine 9 parameters: record >= 10")
    dtype = _float_dtype(raw)
    raw = raw.astype(dtype)
    w = jnp.ones(raw.shape[0], dtype) if weights is None else jnp.asarray(weights, dtype)
    if w.shape != raw.shape[:1]:
        raise ValueError(f"weights must be ({raw.shape[0]},), one per sample, got {w.shape}")
    g = jnp.asarray(magnitude, dtype)
    if g.ndim != 0:
        raise ValueError(
            f"magnitude must be a scalar for one sensor, got shape {g.shape} (fit_batch takes "
            "one per sensor)"
        )
    # a row with a NaN or inf is masked out (weight 0, read as 0), as in the batch: one such
    # row made the whole fit NONFINITE
    finite = jnp.all(jnp.isfinite(raw), axis=1)
    return jnp.where(finite[:, None], raw, 0.0), g, jnp.where(finite, w, 0.0)


def _magnitude_ok(g: jax.Array):
    """A concrete magnitude must be positive and finite (ValueError naming it); a traced one
    (under jit, vmap or grad) cannot raise: returns the traced test, which :func:`_refusal`
    turns into status FAILED with NaN parameters. Concrete: returns True."""
    if isinstance(g, jax.core.Tracer):
        return jnp.isfinite(g) & (g > 0)
    if not (bool(jnp.isfinite(g)) and float(g) > 0):
        raise ValueError(
            f"magnitude must be a positive, finite field magnitude (1 for unit output, 9.80665 "
            f"for m/s^2, the local field in uT ...), got {float(g)!r}"
        )
    return True


def _refusal(g_ok, x, w, n_params: int, flat_below: float):
    """The status code that refuses a fit before it runs, -1 for none (under jit): FAILED for a
    traced magnitude that is not positive and finite (``g_ok``, :func:`_magnitude_ok`), else
    :func:`calib_jax.geometry.prefit_status` of the centred samples ``x`` (too few valid ones;
    one plane), the batch's own checks."""
    pre = prefit_status(moments(x, w), n_params, 10, flat_below, count=jnp.sum(w > 0))
    return pre if g_ok is True else jnp.where(g_ok, pre, int(Status.FAILED))


def _stand_in(x, w, code):
    """The batch's stand-in directions (:func:`calib_jax.geometry.stand_in_directions`,
    repeated to N rows) in place of refused samples, so that the solve that runs anyway under
    jit is well posed and short."""
    d = jnp.asarray(np.resize(stand_in_directions(), x.shape), x.dtype)
    refused = code >= 0
    return jnp.where(refused, d, x), jnp.where(refused, 1.0, w)


def _refuse(fit: Fit, code) -> Fit:
    """The fit with status ``code`` and NaN params and rms where ``code`` >= 0."""
    refused = code >= 0
    nan_params = jax.tree.map(lambda a: jnp.where(refused, jnp.nan, a), fit.params)
    status = jnp.where(refused, code, fit.status).astype(fit.status.dtype)
    rms = jnp.where(refused, jnp.nan, fit.rms)
    return eqx.tree_at(lambda f: (f.params, f.status, f.rms), fit, (nan_params, status, rms))


def _float_dtype(raw: jax.Array):
    """The input's float dtype; integer counts are fitted in float64."""
    return raw.dtype if jnp.issubdtype(raw.dtype, jnp.floating) else jnp.float64


def _finish(params, res, cov, raw, w, magnitude, radius, rests: bool = False):
    """The Fit, its status judged as the batch's (:func:`calib_jax.geometry.shell_status`:
    a noise cloud fits no shell; an ellipsoid ``radius`` times the samples' spread ran
    away; ``rests``, an accelerometer's: points that leave 3 % of g include motion,
    :func:`calib_jax.accel.not_at_rest`)."""
    e = residual(params, raw, magnitude)
    rms = jnp.sqrt(jnp.sum(w * e * e) / jnp.sum(w))
    status = shell_status(res.status, rms / magnitude, radius)
    if rests:
        status = not_at_rest(status, rms / magnitude)
    return Fit(params=params, covariance=cov, status=status, rms=rms, iterations=res.iterations)


@_full_float32
def fit_accel(
    raw: Real[ArrayLike, "N 3"],
    magnitude: float | jax.Array = 1.0,
    weights: Float[Array, " N"] | None = None,
    *,
    update_type: int = 1,
    max_iter: int = 100,
    absolute_sigma: bool = False,
) -> Fit:
    """Paper 1's nine-parameter fit of one accelerometer (static samples or interval means):
    minimise sum w (1 - |a|^2 / g^2)^2 / 4, a = alpha^-1 (a' - beta), from the algebraic
    ellipsoid: the residual of :func:`calib_jax.calibrate_accel` and of the batch, so the
    same points give the same parameters on every path.

    Parameters
    ----------
    raw : (N, 3)
        Readings in any unit (counts, g, m/s^2), at rest in N >= 10 orientations.
    magnitude : scalar
        The reference |g| in the unit the calibrated output should have. Differentiable.
        Must be positive and finite: a concrete value that is not raises ValueError; under
        ``jit`` / ``vmap`` (a traced value) the Fit instead has status
        :attr:`calib_jax.lm.Status.FAILED` (``converged`` False) and NaN ``params``.
    weights : (N,), optional
        Per-sample weights (0 masks a sample out; so does a NaN or inf in the row).
        Differentiable. With ``absolute_sigma=True`` they are 1 / sigma^2, sigma the noise of
        |a| / g.
    update_type, max_iter : static
        Paper 1's lambda scheme (1, 2, 3) and the iteration budget.

    Returns
    -------
    Fit
        Its ``params`` (:class:`AccelParams`) are differentiable in ``raw``, ``magnitude``
        and ``weights`` by the implicit function theorem. Data that cannot determine the
        model are refused before the fit, with NaN ``params`` and ``rms``, by the batch's
        checks (:func:`calib_jax.geometry.prefit_status`): status INSUFFICIENT_DATA for fewer
        than 10 valid rows, NO_COVERAGE for poses in one plane. A fit through a sensor held
        still is no calibration either (fitted, params kept): NO_SHELL for a relative RMS
        above 12 %, RAN_AWAY for an ellipsoid over 10 times the samples' spread
        (:func:`calib_jax.geometry.shell_status`).
        Jittable and vmappable (see
        :func:`fit_batch`); one compile per (N, dtype, static options), also when called
        eagerly (the fit is jitted inside).
    """
    _check_readings(raw, "fit_accel")
    _check_magnitude(magnitude)
    return _fit_accel(
        raw,
        magnitude,
        weights,
        update_type=update_type,
        max_iter=max_iter,
        absolute_sigma=absolute_sigma,
    )


def _check_readings(raw, fit: str) -> None:
    """A ValueError for a path or a loaded log where the pure fits take an array (jit's own
    error said the argument was not "marked as static")."""
    import os

    from .io.files import SensorLog

    if isinstance(raw, (str, os.PathLike, SensorLog)):
        raise ValueError(
            f"{fit} takes an (N, 3) array of readings, got a {type(raw).__name__}: load the log "
            "first (load_log(path).acc, or the static means calibrate_accel fits: "
            "calib_jax.observations.accel_observations(log.acc).points), or give the file to "
            "calib_jax.calibrate_accel / calibrate_mag, which do"
        )


def _check_magnitude(magnitude) -> None:
    """The concrete check of :func:`_magnitude_ok`, before the jitted fit (which sees a
    traced magnitude and can only mark the fit FAILED)."""
    if isinstance(magnitude, str | bytes):  # was a 53-line dtype error from inside JAX
        raise ValueError(f"magnitude must be a number, got the string {magnitude!r}")
    if not isinstance(magnitude, jax.core.Tracer) and jnp.ndim(magnitude) == 0:
        _magnitude_ok(jnp.asarray(magnitude))  # a shape error is _prepare's to name


# Jitted, so that an eager call compiles the fit as one program: run op by op, the docs'
# pipeline example took 70 s, mostly compiling hundreds of single operations
@functools.partial(jax.jit, static_argnames=("update_type", "max_iter", "absolute_sigma"))
def _fit_accel(raw, magnitude, weights, *, update_type, max_iter, absolute_sigma) -> Fit:
    raw, g, w = _prepare(raw, magnitude, weights)
    g_ok = _magnitude_ok(g)
    m, s = _normalisation(raw, w)
    x = (raw - m) / s
    code = _refusal(g_ok, x, w, 9, FLAT_POSES)
    x, w_fit = _stand_in(x, w, code)
    # calibrate_accel's fit (one minimiser on every path). Its residual 1 - |a|^2 / g^2 is
    # twice 1 - |a| / g to first order: weights w / 4 (exact in binary) keep w meaning
    # 1 / sigma^2 of |a| / g, as in fit_mag
    res = fit_normalized(
        x,
        w_fit / 4.0,
        solver=f"lm{update_type}",
        g=g,
        implicit=True,
        max_iter=max_iter,
        absolute_sigma=absolute_sigma,
    )
    pn = res.params
    # back to raw units: alpha = s alpha_n, beta = s beta_n + m (exact for the model)
    p = jnp.concatenate([s * pn[:6], s * pn[6:] + m])
    params = AccelParams.from_vector(p)
    cov = s * s * res.covariance
    # the semi-axes g eig(alpha_n) of the normalised fit, in units of the spread s
    radius = g * jnp.cbrt(jnp.abs(det3(alpha_matrix(pn))))
    return _refuse(_finish(params, res, cov, raw, w, g, radius, rests=True), code)


@_full_float32
def fit_mag(
    raw: Real[ArrayLike, "N 3"],
    magnitude: float | jax.Array = 1.0,
    weights: Float[Array, " N"] | None = None,
    *,
    model: str = "full",
    update_type: int = 1,
    max_iter: int = 100,
    absolute_sigma: bool = False,
) -> Fit:
    """Hard and soft iron of one magnetometer: paper 2's ellipsoid (x - c)' M (x - c) = 1,
    fitted by :func:`calib_jax.calibrate_mag`'s core
    (:func:`calib_jax.mag.fit_ellipsoid_normalized`, the quadric residual from the constrained
    algebraic ellipsoid), returned as the map onto a sphere of radius ``magnitude``:
    c and the symmetric W = B M^(1/2), so that |W (m' - c)| = B on the ellipsoid. The same
    samples give :func:`calib_jax.calibrate_mag`'s parameters (``model`` and ``field=B``).

    ``magnitude`` B is the field the output should have (1 for unit vectors, the local field in
    uT, ...); positive and finite, checked as in :func:`fit_accel` (ValueError when concrete;
    status FAILED and NaN ``params`` under ``jit``). ``model`` (static): "full" (9
    parameters), "diag" (an axis-aligned ellipsoid) or "sphere" (hard iron only). With
    ``absolute_sigma=True`` the weights are 1 / sigma^2, sigma the noise of |W (m' - c)| / B.
    Rows with a NaN or inf are masked out, and data that cannot determine the model are refused
    as in :func:`fit_accel` (INSUFFICIENT_DATA, NO_COVERAGE; NaN ``params``).
    Returns a :class:`Fit` with :class:`MagParams`, differentiable in ``raw``, ``magnitude``
    and ``weights``; jittable and vmappable. Needs a well-covered sphere of orientations (see
    :func:`calib_jax.calibrate_mag` for the coverage checks and the model choice).
    """
    _check_readings(raw, "fit_mag")
    _check_magnitude(magnitude)
    if model not in N_PARAMS:  # was KeyError: 'ellipsoid'
        raise ValueError(f"model must be one of {', '.join(N_PARAMS)}, got {model!r}")
    return _fit_mag(
        raw,
        magnitude,
        weights,
        model=model,
        update_type=update_type,
        max_iter=max_iter,
        absolute_sigma=absolute_sigma,
    )


@functools.partial(jax.jit, static_argnames=("model", "update_type", "max_iter", "absolute_sigma"))
def _fit_mag(raw, magnitude, weights, *, model, update_type, max_iter, absolute_sigma) -> Fit:
    raw, B, w = _prepare(raw, magnitude, weights)
    B_ok = _magnitude_ok(B)
    m, s = _normalisation(raw, w)
    x = (raw - m) / s
    code = _refusal(B_ok, x, w, N_PARAMS[model], FLAT_POINTS)
    x, w_fit = _stand_in(x, w, code)
    res = fit_ellipsoid_normalized(
        x,
        w_fit,
        model,
        solver=f"lm{update_type}",
        implicit=True,
        max_iter=max_iter,
        absolute_sigma=absolute_sigma,
    )

    c, W = raw_calibration(res.params, model, m, s, B)
    params = MagParams(hard_iron=c, soft_iron=W)
    sg = jax.lax.stop_gradient  # the covariance is a constant under grad (see Fit)
    cov = raw_covariance(sg(res.params), res.covariance, model, m, s, sg(B))
    r = natural_radius(unpack(res.params, model)[1])  # in units of the spread s
    if absolute_sigma:
        # The quadric residual e = r (|u|^2 - 1) is 2 r (|u| - 1) to first order, |u| - 1 being
        # the residual the weights are for (r = det(M_n)^(-1/6)): its covariance is 4 r^2 that
        # of the fit with the weights as given
        cov = 4.0 * sg(r) ** 2 * cov
    return _refuse(_finish(params, res, cov, raw, w, B, r), code)


@_full_float32
def fit_batch(
    fit: Callable[..., Fit],
    raw: Real[ArrayLike, "S N 3"],
    magnitude: float | Float[Array, " S"] = 1.0,
    weights: Float[Array, "S N"] | None = None,
    **options,
) -> Fit:
    """``fit`` (:func:`fit_accel` or :func:`fit_mag`) over a leading sensor axis: a Fit whose
    leaves have that axis. ``magnitude`` is shared or per sensor; pad unequal logs with zero
    weights. Same derivatives as the single fit."""
    raw = jnp.asarray(raw)
    if raw.ndim != 3 or raw.shape[-1] != 3:
        raise ValueError(
            f"raw must be (S, N, 3): sensors, samples, axes (pad unequal logs with zero "
            f"weights), got {raw.shape}"
        )
    dtype = _float_dtype(raw)
    raw = raw.astype(dtype)
    mag = jnp.broadcast_to(jnp.asarray(magnitude, dtype), raw.shape[:1])
    if not isinstance(mag, jax.core.Tracer):  # concrete: say which sensor (vmap would not)
        for k, v in enumerate(mag):
            try:
                _magnitude_ok(v)
            except ValueError as exc:
                raise ValueError(f"sensor {k}: {exc}") from None
    if weights is None:
        weights = jnp.ones(raw.shape[:2], dtype)
    return jax.vmap(lambda r, g, w: fit(r, g, w, **options))(raw, mag, weights)


# ---------------------------------------------------------------------------------------------
# gyroscope


class GyroInputs(NamedTuple):
    """What :func:`fit_gyro` fits, padded to fixed shapes (weight 0 marks padding).

    ``motions``: the raw gyro readings (not de-biased) from the last still sample of one pose
    to the first of the next, their time steps and the two poses' unit gravity directions
    (from the calibrated accelerometer); ``weights`` (K,) 1 per motion. ``rest`` (P, L, 3):
    the raw readings of each still pose, ``rest_weights`` (P, L). Build it from a log with
    :func:`gyro_inputs`; every floating leaf is differentiable.
    """

    motions: Motions
    weights: jax.Array
    rest: jax.Array
    rest_weights: jax.Array


def gyro_inputs(
    data,
    gyro=None,
    *,
    t=None,
    sample_rate: float | None = None,
    accel=None,
    accel_options: dict | None = None,
) -> GyroInputs:
    """Cut a multi-position log into :class:`GyroInputs` (host side, NumPy): the same rests,
    motions and gravity directions :func:`calib_jax.calibrate_gyro` fits, with its checks
    and errors (``data``, ``gyro``, ``t``, ``sample_rate``, ``accel`` and ``accel_options``
    as there). Motions are padded to powers of two in count and length, rests likewise."""
    log = _pose_log(data, gyro, t, sample_rate, accel, accel_options)
    g = log.g
    motions, w = _pad_motions(log.windows, lambda s, e: g[s:e], log.dt, log.dirs)
    rests = [g[s:e] for s, e in log.intervals]
    rest, rest_w = stack_rows(rests, count=bucket(len(rests)))
    return GyroInputs(motions, jnp.asarray(w), jnp.asarray(rest), jnp.asarray(rest_w))


def stack_gyro_inputs(*inputs: GyroInputs) -> GyroInputs:
    """Several logs' :class:`GyroInputs` padded to one shape (zeros, weight 0) and stacked on
    a leading axis, for ``jax.vmap(fit_gyro)``."""

    def stack(*leaves):
        shape = np.max([np.shape(a) for a in leaves], axis=0)
        pad = [[(0, n - m) for n, m in zip(shape, np.shape(a), strict=True)] for a in leaves]
        return jnp.stack([np.pad(a, p) for a, p in zip(leaves, pad, strict=True)])

    return jax.tree.map(stack, *inputs)


@_full_float32
def fit_gyro(inputs: GyroInputs, *, update_type: int = 1, max_iter: int = 100) -> Fit:
    """The gyroscope of one multi-position log: bias b from the rests, then the nine entries
    of C (true rate = C (raw - b), rad/s) by LM on the gravity residual
    (:func:`calib_jax.models.gyro.gravity_residual`) from the scanned common scale: the fit
    of :func:`calib_jax.calibrate_gyro` without its candidate effects (g-sensitivity and
    scale asymmetry stay zero in the returned :class:`GyroParams`; test them there).

    ``params`` are differentiable in every floating leaf of ``inputs`` (rates, time steps,
    gravity directions, rest readings) by the implicit function theorem for C and the
    weighted mean for b. ``covariance`` is over ``ravel_pytree(params)[0]`` (matrix, bias,
    g_sensitivity, scale_asymmetry): C's block from the fit, conditional on the bias; b's
    from the spread of the pose means (std / sqrt(poses), as the record); zero for the two
    effects, which are held at zero. ``rms``: radians of miss per motion. Jittable and
    vmappable (:func:`stack_gyro_inputs`); one compile per padded shape.
    """
    return _fit_gyro(inputs, update_type=update_type, max_iter=max_iter)


def _gyro_bias(rest, rest_w):
    """(b, its covariance): the mean of all rest samples; std of the pose means / sqrt(P)."""
    n_pose = jnp.sum(rest_w, axis=1)
    b = jnp.sum(rest_w[..., None] * rest, axis=(0, 1)) / jnp.sum(n_pose)
    pose = n_pose > 0
    means = jnp.sum(rest_w[..., None] * rest, axis=1) / jnp.where(pose, n_pose, 1.0)[:, None]
    p = jnp.sum(pose)
    centre = jnp.sum(jnp.where(pose[:, None], means, 0.0), axis=0) / p
    var = jnp.sum(jnp.where(pose[:, None], (means - centre) ** 2, 0.0), axis=0) / p
    return b, jnp.diag(var / p)


def _gyro_residual(c9, args):
    motions, bias, scale = args
    return gravity_residual(c9, motions._replace(rates=(motions.rates - bias) * scale))


@functools.partial(jax.jit, static_argnames=("update_type", "max_iter"))
def _fit_gyro(inputs: GyroInputs, *, update_type, max_iter) -> Fit:
    motions, w = inputs.motions, inputs.weights
    dtype = motions.rates.dtype
    bias, bias_cov = _gyro_bias(inputs.rest, inputs.rest_weights)
    sg = jax.lax.stop_gradient
    # the start scale only conditions the solve (C = scale C_n exactly), so it is a constant
    scale = sg(start_scale(motions._replace(rates=motions.rates - bias), w))
    pn, res = solve_implicit(
        _gyro_residual,
        jnp.eye(3, dtype=dtype).ravel(),
        (motions, bias, scale),
        weights=lambda args: jnp.repeat(sg(w), 3),
        update_type=update_type,
        max_iter=max_iter,
        dof=2.0 * jnp.sum(w) - 9.0,  # each motion gives two independent residuals
    )
    C = (pn * scale).reshape(3, 3)
    zero = jnp.zeros((3, 3), dtype)
    params = GyroParams(matrix=C, bias=bias, g_sensitivity=zero, scale_asymmetry=zero[0])
    cov = jax.scipy.linalg.block_diag(res.covariance * scale**2, sg(bias_cov), jnp.zeros((12, 12)))
    miss = _angles(pn, motions._replace(rates=(motions.rates - bias) * scale))
    rms = jnp.sqrt(jnp.sum(w * miss**2) / jnp.sum(w))
    return Fit(params=params, covariance=cov, status=res.status, rms=rms, iterations=res.iterations)


# ---------------------------------------------------------------------------------------------
# attitude


@_full_float32
def attitude(
    params: MargParams,
    acc_raw: Float[Array, "N 3"],
    mag_raw: Float[Array, "N 3"],
    dip_deg: float | jax.Array,
    iterations: int = 6,
) -> Float[Array, "N 4"]:
    """Gauss-Newton quaternion (body -> ENU, paper 2 sec. 3) of every sample, from raw data
    through ``params``. Differentiable in the parameters, the data and the dip (through the
    fixed number of Gauss-Newton steps, from the TRIAD start). ``iterations`` must be static
    (``jax.jit(attitude, static_argnames="iterations")``): traced, the loop becomes a
    while_loop that reverse mode cannot differentiate."""
    if isinstance(iterations, jax.core.Tracer):
        return _attitude(params, acc_raw, mag_raw, dip_deg, iterations)
    return _attitude_jit(params, acc_raw, mag_raw, dip_deg, iterations)


def _attitude(params, acc_raw, mag_raw, dip_deg, iterations):
    a, m = params.apply(acc_raw, mag_raw)
    r_a, r_m = reference_vectors(dip_deg)
    r_a, r_m = r_a.astype(a.dtype), r_m.astype(a.dtype)
    return jax.vmap(lambda ai, mi: gauss_newton_quaternion(ai, mi, r_a, r_m, None, iterations)[0])(
        a, m
    )


# jitted for eager calls, as the fits (one program instead of a compile per operation)
_attitude_jit = jax.jit(_attitude, static_argnames="iterations")


def euler_deg(quat: Float[Array, "... 4"]) -> Float[Array, "... 3"]:
    """[roll, pitch, yaw] in degrees (ZYX) of body -> ENU quaternions (..., 4)."""
    flat = quat.reshape(-1, 4)
    return jax.vmap(euler_zyx_deg)(flat).reshape(quat.shape[:-1] + (3,))


# ---------------------------------------------------------------------------------------------
# uncertainty to the outputs


@_full_float32
def propagate(
    f: Callable[[object], jax.Array], params, covariance: Float[Array, "n n"]
) -> jax.Array:
    """First-order covariance of ``f(params)`` (..., k) per leading index: J C J' (..., k, k),
    J = d f / d ravel_pytree(params), by forward-mode autodiff. ``covariance`` is over
    ``ravel_pytree(params)[0]`` (what :class:`Fit` reports; block-diagonal for independent
    fits, see :func:`block_covariance`)."""
    flat, unravel = ravel_pytree(params)

    def g(v):
        return f(unravel(v))

    J = jax.jacfwd(g)(flat)  # (..., k, n)
    return jnp.einsum("...in,nm,...jm->...ij", J, covariance, J)


def block_covariance(*covs: jax.Array) -> jax.Array:
    """Block-diagonal covariance for independent parts, in the given order."""
    return jax.scipy.linalg.block_diag(*covs)


@_full_float32
def calibrated_covariance(
    params: Calibration,
    covariance: Float[Array, "n n"],
    raw: Float[Array, "N 3"],
    noise_cov: Float[Array, "3 3"] | None = None,
) -> Float[Array, "N 3 3"]:
    """Covariance (N, 3, 3) of the calibrated samples from the parameter covariance (the
    calibration's share of the error), plus the raw noise ``noise_cov`` carried through the
    calibration when given."""
    C = propagate(lambda p: apply(p, raw), params, covariance)
    if noise_cov is not None:
        G = jax.jacfwd(lambda r: apply(params, r))(raw[0])  # linear in raw: same for all
        C = C + G @ noise_cov @ G.T
    return C


@_full_float32
def attitude_std(
    params: MargParams,
    covariance: Float[Array, "n n"],
    acc_raw: Float[Array, "N 3"],
    mag_raw: Float[Array, "N 3"],
    dip_deg: float | jax.Array,
    iterations: int = 6,
) -> Float[Array, "N 3"]:
    """Standard deviation (deg) of [roll, pitch, yaw] of every sample due to the calibration's
    uncertainty (``covariance`` over ``ravel_pytree(params)[0]``), to first order. Wrap-around
    of yaw near +-180 deg is taken care of by differentiating the angle itself (smooth away
    from the gimbal lock at pitch +-90 deg, where roll and yaw are undefined)."""
    return _attitude_std(params, covariance, acc_raw, mag_raw, dip_deg, iterations)


@functools.partial(jax.jit, static_argnames="iterations")
def _attitude_std(params, covariance, acc_raw, mag_raw, dip_deg, iterations):
    C = propagate(
        lambda p: euler_deg(attitude(p, acc_raw, mag_raw, dip_deg, iterations)), params, covariance
    )
    return jnp.sqrt(jnp.diagonal(C, axis1=-2, axis2=-1))
