"""End-to-end calibration against a reference attitude, by gradients through the whole pipeline.

The two-stage way (what :func:`calib_jax.calibrate_marg` does) fits each sensor to its own
sphere, aligns the magnetometer to the accelerometer by the constancy of the angle between
them, and only then estimates attitude. Every stage minimises its own error, not the attitude
error. Given a reference attitude (an optical tracker, as in the BROAD benchmark), the
calibration can instead minimise the attitude error itself::

    raw acc, raw mag --(MargParams)--> a, m --(Gauss-Newton, paper 2 sec. 3)--> q(theta)
    e_i = 2 vec(q_i(theta) (x) q_ref,i^-1)         (about the rotation error in rad, 3 per sample)

over theta = (magnetometer hard iron c, symmetric soft iron W, the accel-mag rotation, the
dip), by Levenberg-Marquardt with exact Jacobians: forward-mode autodiff through the vmapped
Gauss-Newton iterations, the TRIAD start and the calibration. The Gauss-Newton estimator
normalises m, so the scale of W is not observable; one extra residual holds the mean
calibrated |m| at 1.

Both start from the same two-stage result and are judged by :func:`attitude_errors` (BROAD's
heading and inclination error) on a trial that was not used for fitting.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .align import align_mag_to_accel
from .filter import FilterGains, complementary_filter
from .lm import LMResult, lm_solve
from .models.accel import AccelParams, alpha_matrix
from .models.gyro import GyroParams
from .padding import pad_rows
from .pipeline import (
    MagParams,
    MargParams,
    Rotation,
    attitude,
    block_covariance,
    fit_mag,
)
from .rotations import heading_inclination_error_deg, quat_conj, quat_exp, quat_multiply


@jax.jit  # eager, the vmap ran (and compiled) each quaternion operation on its own
def attitude_errors(q_est: jax.Array, q_ref: jax.Array) -> jax.Array:
    """(N, 2): BROAD's [heading, inclination] error in degrees of each sample."""
    return jax.vmap(heading_inclination_error_deg)(q_est, q_ref)


def rotation_residual(q_est: jax.Array, q_ref: jax.Array) -> jax.Array:
    """(N, 3): 2 vec(q_est (x) q_ref^-1) with w >= 0, the rotation error in rad to first order
    (earth frame; its z component is the heading error)."""
    e = jax.vmap(lambda a, b: quat_multiply(a, quat_conj(b)))(q_est, q_ref)
    e = jnp.where(e[:, :1] < 0, -e, e)
    return 2.0 * e[:, 1:]


# The adjusted parameters as one vector, blocks in this order, each present when fitted:
#   calibration (12): hard iron (3), symmetric soft iron (6, paper 1's alpha layout xx yy zz xy
#                     xz yz), rotation vector mag -> acc (3)
#   dip (1):          degrees
#   offset (4):       a constant error of the reference itself: body rotation vector between the
#                     reference's body frame and the accelerometer's (3), heading offset of the
#                     reference's north (1, rad); q_ref -> q_z(h) (x) q_ref (x) q(v)
BLOCKS = (("calibration", 12), ("dip", 1), ("offset", 4))


def pack(params: MargParams, dip_deg: float | jax.Array) -> jax.Array:
    """The calibration block and the dip (13,) of ``params``."""
    W = params.mag.soft_iron
    return jnp.concatenate(
        [
            params.mag.hard_iron,
            jnp.stack([W[0, 0], W[1, 1], W[2, 2], W[0, 1], W[0, 2], W[1, 2]]),
            params.mag_to_acc.rotvec,
            jnp.asarray(dip_deg, W.dtype)[None],
        ]
    )


def unpack(theta: jax.Array, base: MargParams) -> MargParams:
    """The calibration block (12,) -> MargParams (the accelerometer from ``base``)."""
    # symmetric W from paper 1's alpha layout [xx yy zz xy xz yz] (the zeros fill the bias)
    W = alpha_matrix(jnp.concatenate([theta[3:9], jnp.zeros(3, theta.dtype)]))
    return MargParams(base.acc, MagParams(theta[:3], W), Rotation(theta[9:12]))


@jax.jit
def offset_reference(q_ref: jax.Array, offset: jax.Array) -> jax.Array:
    """q_z(h) (x) q_ref (x) q(v) for offset = [v (3), h]: the reference corrected by a constant
    body-frame rotation and a heading offset."""
    qb = quat_exp(offset[:3])
    qh = quat_exp(offset[3] * jnp.array([0.0, 0.0, 1.0], q_ref.dtype))
    return jax.vmap(lambda q: quat_multiply(qh, quat_multiply(q, qb)))(q_ref)


N_THETA = sum(n for _, n in BLOCKS)


def free_mask(fitted: tuple[str, ...]) -> np.ndarray:
    """(N_THETA,) bool: the entries of the blocks in ``fitted``."""
    return np.concatenate([np.full(n, name in fitted) for name, n in BLOCKS])


def _residual(theta, args):
    """Attitude residuals (3 per sample, weighted), the scale row of W, and one pinning row per
    parameter: theta - default where the parameter is held (``free`` False), else 0. The
    parameters are always all N_THETA (one compiled fit whatever is held); a held one
    has a Jacobian column of its pinning row only and a zero residual there, so the LM step
    leaves it at its default exactly and the free ones see the problem without it."""
    base, default, free, acc, mag, q_ref, w = args
    t = jnp.where(free, theta, default)
    p = unpack(t[:12], base)
    q = attitude(p, acc, mag, t[12])
    e = rotation_residual(q, offset_reference(q_ref, t[13:17])) * jnp.sqrt(w)[:, None]
    # the estimator normalises m: hold the scale of W by the mean calibrated |m| = 1 (a row
    # that is zero while the calibration is held)
    norm = jnp.sum(w * jnp.linalg.norm(p.mag.apply(mag), axis=1)) / jnp.sum(w)
    scale_row = jnp.where(free[0], (norm - 1.0) * jnp.sqrt(jnp.sum(w)), 0.0)
    pin = jnp.where(free, 0.0, theta - default)
    return jnp.concatenate([e.ravel(), scale_row[None], pin])


@dataclass(frozen=True)
class TwoStage:
    params: MargParams
    dip_deg: float
    mag_fit_status: int
    alignment_status: str
    alignment_message: str
    covariance: np.ndarray
    """Over ``ravel_pytree(params)[0]``: zero for the accelerometer (used as given), the
    ellipsoid fit's for the magnetometer, the alignment's standard errors (uncorrelated) for
    the rotation vector; for :func:`calib_jax.pipeline.attitude_std`."""


_fit_mag_jit = jax.jit(fit_mag)


def two_stage(acc: np.ndarray, mag: np.ndarray) -> TwoStage:
    """Fit the magnetometer ellipsoid (:func:`calib_jax.pipeline.fit_mag`, unit field), then
    the accel-mag rotation and dip by the angle constancy (:func:`calib_jax.align_mag_to_accel`).
    The accelerometer is used as given."""
    acc = np.asarray(acc, float)
    mag = np.asarray(mag, float)
    ok = np.all(np.isfinite(mag), axis=1)  # NaN rows: zero weight and a finite stand-in
    # padded to a power of two (weight 0): one compilation serves trials of similar length
    stand_in, w = pad_rows(np.where(ok[:, None], mag, 0.0), weights=ok)
    fit = _fit_mag_jit(jnp.asarray(stand_in), 1.0, jnp.asarray(w))
    m = np.asarray(fit.params.apply(jnp.asarray(mag)))  # NaN rows stay NaN; align drops them
    al = align_mag_to_accel(acc, m, search_permutations=False)
    rot = Rotation(jnp.asarray(_rotvec(al.R_acc_from_mag)))

    params = MargParams(AccelParams.identity(), fit.params, rot)
    cov = block_covariance(
        jnp.zeros((9, 9)), fit.covariance, jnp.diag(np.radians(al.rotvec_stderr_deg) ** 2)
    )
    return TwoStage(params, al.dip_deg, int(fit.status), al.status, al.message, np.asarray(cov))


def _rotvec(R: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation as _R

    return _R.from_matrix(R).as_rotvec()


@dataclass(frozen=True)
class EndToEnd:
    params: MargParams
    dip_deg: float
    offset: np.ndarray
    """[body rotation vector (3, rad), heading offset (rad)] of the reference (zero unless
    fitted)."""
    result: LMResult
    """The LM fit of the fitted blocks (see :data:`BLOCKS`)."""
    fitted: tuple[str, ...]


def end_to_end(
    acc: np.ndarray,
    mag: np.ndarray,
    quat_ref: np.ndarray,
    start: TwoStage,
    *,
    weights: np.ndarray | None = None,
    fit_calibration: bool = True,
    fit_dip: bool = False,
    fit_offset: bool = False,
    max_iter: int = 50,
) -> EndToEnd:
    """Adjust the magnetometer calibration and the accel-mag rotation (and optionally the dip,
    and a constant offset of the reference itself) so that the Gauss-Newton attitude matches
    ``quat_ref`` ([w, x, y, z], body -> ENU) in least squares, from ``start``. Rows of
    ``quat_ref`` that are not finite are left out."""
    acc = np.asarray(acc, float)
    mag = np.asarray(mag, float)
    quat_ref = np.asarray(quat_ref, float)
    ok = np.all(np.isfinite(quat_ref), axis=1) & np.all(np.isfinite(acc), axis=1)
    ok &= np.all(np.isfinite(mag), axis=1)
    w = np.where(ok, 1.0 if weights is None else np.asarray(weights, float), 0.0)
    # rows left out get harmless finite stand-ins (a zero weight does not stop NaN: 0 * NaN)
    q_ref = np.where(ok[:, None], quat_ref, np.array([1.0, 0, 0, 0]))
    q_ref = q_ref / np.linalg.norm(q_ref, axis=1, keepdims=True)
    acc = np.where(ok[:, None], acc, np.array([0.0, 0.0, 1.0]))
    mag = np.where(ok[:, None], mag, np.array([0.0, 1.0, 0.0]))
    if ok.sum() < 50:
        raise ValueError(f"only {int(ok.sum())} samples have a finite reference attitude")
    # padded to a power of two with weight 0: trials of similar length share one compilation
    (acc, _), (mag, _), (q_ref, w) = (pad_rows(a, weights=w) for a in (acc, mag, q_ref))
    fitted = tuple(
        name
        for name, on in (("calibration", fit_calibration), ("dip", fit_dip), ("offset", fit_offset))
        if on
    )
    if not fitted:
        raise ValueError("nothing to fit: set fit_calibration, fit_dip or fit_offset")
    default = jnp.concatenate([pack(start.params, start.dip_deg), jnp.zeros(4)])
    free = free_mask(fitted)
    args = (
        start.params,
        default,
        jnp.asarray(free),
        jnp.asarray(acc),
        jnp.asarray(mag),
        jnp.asarray(q_ref),
        jnp.asarray(w),
    )
    # degrees of freedom: three per sample with a reference, plus the scale row, less the
    # free parameters (the pinning rows and padded samples add none)
    dof = 3 * int(ok.sum()) + int(fit_calibration) - int(free.sum())
    full = _run(default, args, max_iter, float(dof))
    res = _restrict(full, free)
    t = np.asarray(full.params)
    return EndToEnd(
        unpack(jnp.asarray(t[:12]), start.params),
        float(t[12]),
        t[13:17],
        res,
        fitted,
    )


@functools.partial(jax.jit, static_argnames=("max_iter",))
def _run(theta0, args, max_iter, dof):
    return lm_solve(_residual, theta0, args, max_iter=max_iter, dof=dof)


def _restrict(res: LMResult, free: np.ndarray) -> LMResult:
    """The LM result over the free parameters only (the held ones have pinning rows, not
    data: their standard errors mean nothing)."""
    idx = np.flatnonzero(free)
    # numpy indexing: a jax index compiles one small program per shape
    sub = tuple(
        jnp.asarray(np.asarray(a)[ix])
        for a, ix in (
            (res.params, idx),
            (res.covariance, np.ix_(idx, idx)),
            (res.stderr, idx),
            (res.correlation, np.ix_(idx, idx)),
        )
    )
    return eqx.tree_at(lambda r: (r.params, r.covariance, r.stderr, r.correlation), res, sub)


# ---------------------------------------------------------------------------------------------
# the BROAD comparison (docs/end_to_end_broad.py, notebooks/05_in_a_jax_pipeline.ipynb)


def rate_from_quat(quat: np.ndarray, sample_rate: float) -> np.ndarray:
    """Angular rate (deg/s) from consecutive reference quaternions (NaN where either is
    missing); used to tell quasi-static samples, where the Gauss-Newton estimator's model
    (the accelerometer sees only gravity) holds, from fast motion, where it does not."""
    q = np.asarray(quat, float)
    e = np.asarray(jax.vmap(lambda a, b: quat_multiply(a, quat_conj(b)))(q[1:], q[:-1]))
    ang = 2.0 * np.arctan2(np.linalg.norm(e[:, 1:], axis=1), np.abs(e[:, 0]))
    r = np.degrees(ang) * sample_rate
    out = np.full(len(q), np.nan)
    out[1:] = r
    out[0] = r[0] if len(r) else np.nan
    # centred: the mean of the steps before and after
    out[1:-1] = 0.5 * (r[:-1] + r[1:])
    return out


QUASI_STATIC_DEG_S = 5.0
"""Samples turning slower than this (by the reference) count as quasi-static."""
RATE_SCALE_DEG_S = 20.0
"""Fit weight 1 / (1 + (rate / RATE_SCALE)^2): fast samples, where the accelerometer sees
more than gravity and the estimator's tilt error (times tan(dip) in heading) is not the
calibration's, count less."""


def rate_weights(rate: np.ndarray) -> np.ndarray:
    r = np.nan_to_num(np.asarray(rate, float), nan=np.inf)
    return 1.0 / (1.0 + (r / RATE_SCALE_DEG_S) ** 2)


def evaluate(
    params: MargParams, dip_deg: float, acc, mag, quat_ref, mask: np.ndarray
) -> dict[str, float]:
    """RMS and median heading and inclination error (deg) over the samples in ``mask``."""
    k = np.asarray(mask, bool) & np.all(np.isfinite(quat_ref), axis=1)
    k &= np.all(np.isfinite(acc), axis=1) & np.all(np.isfinite(mag), axis=1)
    ref = quat_ref[k] / np.linalg.norm(quat_ref[k], axis=1, keepdims=True)
    # padded to a power of two (the first row repeated): one compilation serves every mask
    rows = [pad_rows(a[k])[0] for a in (acc, mag)]
    q = _attitude_jit(params, *(jnp.asarray(r) for r in rows), jnp.asarray(dip_deg))
    e = np.asarray(attitude_errors(q, jnp.asarray(pad_rows(ref)[0])))[: int(k.sum())]
    return _error_summary(e)


_attitude_jit = jax.jit(attitude)


def _error_summary(e: np.ndarray) -> dict[str, float]:
    """RMS and median of the (n, 2) heading and inclination errors, and n."""
    return {
        "n": len(e),
        "heading_rms": float(np.sqrt(np.mean(e[:, 0] ** 2))),
        "inclination_rms": float(np.sqrt(np.mean(e[:, 1] ** 2))),
        "heading_median": float(np.median(e[:, 0])),
        "inclination_median": float(np.median(e[:, 1])),
    }


def compare(fit: dict, test: dict, *, sample_rate: float, offsets: bool = False) -> dict:
    """Before / two-stage / end-to-end (dip held) / end-to-end (dip fitted) on a fitting and a
    held-out trial, each a dict with ``acc``, ``mag``, ``quat`` (and ``movement``, bool).

    ``offsets=True`` adds two diagnostic rows that ask whether a constant error of the
    reference explains what is left: "reference_offset" (two-stage calibration, only the
    reference's body rotation and heading offset fitted) and "end_to_end_offset" (both); they
    are judged against the reference corrected by the fitted offset.

    Returns ``{"methods": {name: {"params", "dip_deg", "offset", "fit": {...}, "test": {...}}}}``
    where each of "fit" and "test" has the errors on quasi-static samples (reference rate below
    :data:`QUASI_STATIC_DEG_S`) and on BROAD's movement samples.
    """
    from .attitude import dip_from_data

    rates = {k: rate_from_quat(d["quat"], sample_rate) for k, d in (("fit", fit), ("test", test))}
    start = two_stage(fit["acc"], fit["mag"])
    w = rate_weights(rates["fit"])

    def e2e(**flags):
        return end_to_end(fit["acc"], fit["mag"], fit["quat"], start, weights=w, **flags)

    zero = np.zeros(4)
    methods = {
        "before": (MargParams.identity(), dip_from_data(fit["acc"], fit["mag"]), zero, None),
        "two_stage": (start.params, start.dip_deg, zero, None),
    }
    runs = {"end_to_end": e2e(), "end_to_end_dip": e2e(fit_dip=True)}
    if offsets:
        runs["reference_offset"] = e2e(fit_calibration=False, fit_offset=True)
        runs["end_to_end_offset"] = e2e(fit_offset=True)
    for name, r in runs.items():
        methods[name] = (r.params, r.dip_deg, r.offset, r.result)
    out = {}
    for name, (p, dip, off, res) in methods.items():
        row = {"params": p, "dip_deg": float(dip), "offset": np.asarray(off)}
        if res is not None:
            row["status"] = int(res.status)
            row["iterations"] = int(res.iterations)
        for split, d in (("fit", fit), ("test", test)):
            qs = rates[split] < QUASI_STATIC_DEG_S
            mov = np.asarray(d.get("movement", np.ones(len(d["acc"]), bool)), bool)
            ref = d["quat"]
            if np.any(off != 0):
                ok = np.all(np.isfinite(ref), axis=1)
                fixed = np.asarray(
                    offset_reference(jnp.asarray(np.where(ok[:, None], ref, 1.0)), jnp.asarray(off))
                )
                ref = np.where(ok[:, None], fixed, np.nan)
            row[split] = {
                "quasi_static": evaluate(p, dip, d["acc"], d["mag"], ref, qs),
                "movement": evaluate(p, dip, d["acc"], d["mag"], ref, mov),
            }
        out[name] = row
    return {"methods": out, "two_stage_alignment": start.alignment_status, "start": start}


# ---------------------------------------------------------------------------------------------
# all three sensors through the gyro-aided filter


# The filter's adjusted parameters, blocks in this order (each fitted or held at its start):
#   accel (9):  paper 1's vector [gains, non-orthogonality, bias]
#   mag (12):   as the calibration block above (hard iron, symmetric soft iron, mag -> acc)
#   gyro (12):  C row by row (true rate = C (raw - b)), then the bias b
#   offset (4): the reference's constant body rotation and heading offset, as above
#   delay (1):  seconds by which the reference runs ahead of the sensors (read at t - delay)
#   gyro_delay (1): seconds by which the gyro lags the accelerometer and magnetometer (its
#               reading at t belongs to t - gyro_delay)
FILTER_BLOCKS = (
    ("accel", 9),
    ("mag", 12),
    ("gyro", 12),
    ("offset", 4),
    ("delay", 1),
    ("gyro_delay", 1),
)


class MargGyroParams(eqx.Module):
    """A whole MARG board: accelerometer, magnetometer (with its rotation into the
    accelerometer's frame) and gyroscope (in the accelerometer's frame through its C)."""

    marg: MargParams
    gyro: GyroParams


def filter_pack(params: MargGyroParams) -> jax.Array:
    """The accel, mag and gyro blocks (33,) of ``params``."""
    p = params
    return jnp.concatenate(
        [p.marg.acc.to_vector(), pack(p.marg, 0.0)[:12], p.gyro.matrix.ravel(), p.gyro.bias]
    )


def filter_unpack(theta: jax.Array) -> MargGyroParams:
    """The first 33 entries of a filter parameter vector -> MargGyroParams."""
    acc = AccelParams.from_vector(theta[:9])
    marg = unpack(theta[9:21], MargParams(acc, MagParams.identity(), Rotation.identity()))
    zero = jnp.zeros((3, 3), theta.dtype)
    gyro = GyroParams(theta[21:30].reshape(3, 3), theta[30:33], zero, zero[0])
    return MargGyroParams(marg, gyro)


def filter_attitude(
    params: MargGyroParams,
    gyro,
    acc,
    mag,
    dt,
    *,
    g: float | jax.Array,
    gains: FilterGains | None = None,
    gyro_delay_samples: float | jax.Array = 0.0,
) -> jax.Array:
    """The filter's attitude (N, 4) from raw readings through ``params``: calibrated rates,
    acceleration and the field in the accelerometer's frame (unit field), TRIAD start.
    ``g``: the calibrated accelerometer's gravity magnitude (the filter's weight reference).
    Default gains: :class:`calib_jax.filter.FilterGains` without the integral term (the gyro
    bias is a calibration parameter here). ``gyro_delay_samples``: the gyro is read that many
    samples later (fractional), to undo a gyro that lags the other two sensors."""
    gains = FilterGains(k_bias=0.0) if gains is None else gains
    a, m = params.marg.apply(acc, mag)
    rates = params.gyro.apply(_shifted(jnp.asarray(gyro), gyro_delay_samples)[0])
    q, _ = complementary_filter(rates, a, m, dt, gains=gains, g=g, field=1.0)
    return q


def _shifted(x: jax.Array, shift):
    """The rows read ``shift`` samples later, by linear interpolation between neighbours
    (differentiable in the shift; the edge rows held), with where that stays inside the log,
    the left neighbour's index and the right one's weight: (x(k + shift), inside, i0, f)."""
    n = x.shape[0]
    pos = jnp.arange(n, dtype=x.dtype) + shift
    i0 = jnp.clip(jnp.floor(pos).astype(jnp.int32), 0, n - 2)
    f = jnp.clip(pos - i0, 0.0, 1.0)[:, None]
    inside = (pos >= 0) & (pos <= n - 1)
    return (1.0 - f) * x[i0] + f * x[i0 + 1], inside, i0, f


def delayed_reference(q_ref: jax.Array, w: jax.Array, delay_samples: jax.Array):
    """(q, w): the reference read ``delay_samples`` earlier (fractional: normalised linear
    interpolation between neighbours, their signs aligned; differentiable in the delay) and
    its weights (zero where either neighbour has weight zero or lies outside the log)."""
    _, inside, i0, f = _shifted(q_ref, -delay_samples)
    a, b = q_ref[i0], q_ref[i0 + 1]
    b = jnp.where(jnp.sum(a * b, axis=1, keepdims=True) < 0, -b, b)
    q = (1.0 - f) * a + f * b
    return q / jnp.linalg.norm(q, axis=1, keepdims=True), jnp.where(inside, w[i0] * w[i0 + 1], 0.0)


def _filter_residual(theta, args):
    """Attitude residuals of the filter, two scale rows (the filter sees the directions of a
    and m, their magnitudes only through its weights: mean calibrated |a| held at g and |m|
    at 1 while fitted) and the pinning rows of the held parameters (as in :func:`_residual`)."""
    default, free, gyro, acc, mag, dt, q_ref, w, g = args
    t = jnp.where(free, theta, default)
    p = filter_unpack(t)
    q = filter_attitude(p, gyro, acc, mag, dt, g=g, gyro_delay_samples=t[38] / dt[0])
    q_ref, w = delayed_reference(q_ref, w, t[37] / dt[0])
    e = rotation_residual(q, offset_reference(q_ref, t[33:37])) * jnp.sqrt(w)[:, None]
    sw = jnp.sum(w)

    def mean_norm(v):
        return jnp.sum(w * jnp.linalg.norm(v, axis=1)) / sw

    rows = jnp.stack(
        [
            jnp.where(free[0], (mean_norm(p.marg.acc.apply(acc)) / g - 1.0) * jnp.sqrt(sw), 0.0),
            jnp.where(free[9], (mean_norm(p.marg.mag.apply(mag)) - 1.0) * jnp.sqrt(sw), 0.0),
        ]
    )
    return jnp.concatenate([e.ravel(), rows, jnp.where(free, 0.0, theta - t)])


@dataclass(frozen=True)
class FilterEndToEnd:
    params: MargGyroParams
    offset: np.ndarray
    """[body rotation vector (3, rad), heading offset (rad)] of the reference."""
    delay_s: float
    """Seconds by which the reference runs ahead of the sensors."""
    gyro_delay_s: float
    """Seconds by which the gyro lags the accelerometer and magnetometer."""
    result: LMResult
    """The LM fit over the fitted blocks (see :data:`FILTER_BLOCKS`)."""
    fitted: tuple[str, ...]
    g: float


def end_to_end_filter(
    gyro: np.ndarray,
    acc: np.ndarray,
    mag: np.ndarray,
    quat_ref: np.ndarray,
    dt: float,
    start: MargGyroParams,
    *,
    weights: np.ndarray | None = None,
    fit: tuple[str, ...] = ("accel", "mag", "gyro"),
    max_iter: int = 30,
) -> FilterEndToEnd:
    """Calibrate the blocks in ``fit`` (of :data:`FILTER_BLOCKS`) so that the gyro-aided
    filter's attitude matches ``quat_ref`` ([w, x, y, z], body -> ENU; non-finite rows left
    out) in least squares, from ``start``: LM with exact Jacobians, forward mode through the
    filter's ``lax.scan``. The readings must be finite (the filter integrates every sample)."""
    gyro, acc, mag, quat_ref = (np.asarray(x, float) for x in (gyro, acc, mag, quat_ref))
    bad = ~np.all(np.isfinite(np.hstack([gyro, acc, mag])), axis=1)
    if bad.any():
        raise ValueError(
            f"{int(bad.sum())} rows hold NaN or inf in the gyro, accelerometer or magnetometer: "
            "the filter integrates every sample; cut or fill them first"
        )
    unknown = set(fit) - {name for name, _ in FILTER_BLOCKS}
    if unknown or not fit:
        raise ValueError(f"fit must name some of {[n for n, _ in FILTER_BLOCKS]}, got {fit}")
    ok = np.all(np.isfinite(quat_ref), axis=1)
    if ok.sum() < 50:
        raise ValueError(f"only {int(ok.sum())} samples have a finite reference attitude")
    w = np.where(ok, 1.0 if weights is None else np.asarray(weights, float), 0.0)
    q_ref = np.where(ok[:, None], quat_ref, np.array([1.0, 0, 0, 0]))
    q_ref = q_ref / np.linalg.norm(q_ref, axis=1, keepdims=True)
    # padded at the end with zero steps and weights: the filter's earlier output is unchanged
    steps = pad_rows(np.full(len(w), float(dt)))[1] * dt
    (gyro, _), (acc, _), (mag, _) = (pad_rows(a) for a in (gyro, acc, mag))
    q_ref, w = pad_rows(q_ref, weights=w)
    g = float(
        np.median(
            np.linalg.norm(np.asarray(start.marg.acc.apply(jnp.asarray(acc[: len(ok)]))), axis=1)
        )
    )
    default = jnp.concatenate([filter_pack(start), jnp.zeros(6)])
    free = np.concatenate([np.full(n, name in fit) for name, n in FILTER_BLOCKS])
    args = (default, jnp.asarray(free)) + tuple(
        jnp.asarray(a) for a in (gyro, acc, mag, steps, q_ref, w)
    )
    dof = 3 * int(ok.sum()) + int("accel" in fit) + int("mag" in fit) - int(free.sum())
    full = _run_filter(default, args + (g,), max_iter, float(dof))
    t = jnp.asarray(full.params)
    params = filter_unpack(t)
    offset, delays = np.asarray(t[33:37]), (float(t[37]), float(t[38]))
    return FilterEndToEnd(params, offset, *delays, _restrict(full, free), fit, g)


@functools.partial(jax.jit, static_argnames=("max_iter",))
def _run_filter(theta0, args, max_iter, dof):
    return lm_solve(_filter_residual, theta0, args, max_iter=max_iter, dof=dof)


def evaluate_filter(
    params: MargGyroParams,
    g: float,
    trial: dict,
    dt: float,
    mask: np.ndarray,
    offset: np.ndarray | None = None,
    delay_s: float = 0.0,
    gyro_delay_s: float = 0.0,
) -> dict[str, float]:
    """RMS and median heading and inclination error (deg) of the filter's attitude over the
    samples in ``mask`` of ``trial`` (``gyro``, ``acc``, ``mag``, ``quat``), against the
    reference corrected by ``offset`` and read ``delay_s`` earlier, the gyro read
    ``gyro_delay_s`` later (as fitted)."""
    readings = (jnp.asarray(trial[k]) for k in ("gyro", "acc", "mag"))
    q = filter_attitude(params, *readings, dt, g=g, gyro_delay_samples=gyro_delay_s / dt)
    ref = np.asarray(trial["quat"], float)
    ok = np.all(np.isfinite(ref), axis=1)
    ref = np.where(ok[:, None], ref, np.array([1.0, 0, 0, 0]))
    ref = jnp.asarray(ref / np.linalg.norm(ref, axis=1, keepdims=True))
    ref, w = delayed_reference(ref, jnp.asarray(ok, float), jnp.asarray(delay_s / dt))
    if offset is not None:
        ref = offset_reference(ref, jnp.asarray(offset))
    k = np.asarray(mask, bool) & (np.asarray(w) > 0)
    e = np.asarray(attitude_errors(q, ref))[k]
    return _error_summary(e)


def rest_gyro_bias(acc, gyro, mag, sample_rate: float, min_rest_s: float = 2.0) -> np.ndarray:
    """The gyro bias (raw units) measured at a log's rests: the accelerometer's static
    intervals (:func:`calib_jax.static.detect_static`) narrowed to where the gyro is still and
    the field direction does not turn (:func:`calib_jax.gyro.gyro_still_intervals`: a steady
    turn about the vertical leaves the accelerometer and the gyro quiet; ``mag`` None skips
    that test), ``min_rest_s`` or longer. No such rest: a ValueError."""
    from .gyro import gyro_still_intervals
    from .static import detect_static

    gyro = np.asarray(gyro, float)
    found = detect_static(np.asarray(acc, float), sample_rate=sample_rate).intervals
    found = np.array([[i.start, i.stop] for i in found]).reshape(-1, 2)
    m = None if mag is None else np.asarray(mag, float)
    still = gyro_still_intervals(gyro, found, m, sample_rate)
    still = still[still[:, 1] - still[:, 0] >= min_rest_s * sample_rate]
    if len(still) == 0:
        raise ValueError(
            f"no rest of {min_rest_s:g} s or longer in this log: the gyro bias needs one (hold "
            "the sensor still for a few seconds, or give the bias)"
        )
    return np.concatenate([gyro[s:e] for s, e in still]).mean(axis=0)


def filter_start(acc, gyro, mag, sample_rate: float, min_rest_s: float = 2.0) -> MargGyroParams:
    """The two-stage start of :func:`end_to_end_filter`: the accelerometer as given, the
    magnetometer by :func:`two_stage` (ellipsoid to the unit sphere, then the accel-mag
    rotation), the gyro C = I (rad/s as read) with the bias of :func:`rest_gyro_bias`."""
    bias = rest_gyro_bias(acc, gyro, mag, sample_rate, min_rest_s)
    zero = jnp.zeros((3, 3))
    gyro_params = GyroParams(jnp.eye(3), jnp.asarray(bias), zero, zero[0])
    return MargGyroParams(two_stage(acc, mag).params, gyro_params)
