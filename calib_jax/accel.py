"""From a raw accelerometer log to a calibration (paper 1, end to end).

Host side (checks, units, static detection) around a pure jitted core:

1. drop non-finite rows and samples on a saturated axis (counted, reported);
2. units: counts, g or m/s^2, given or detected from the static norm;
3. static intervals by moving variance (:mod:`calib_jax.static`);
4. coverage checks: enough distinct poses, not all in one plane (error), not all in one
   hemisphere (warning);
5. normalise: x_n = (x - c0) / k with c0, k from an algebraic sphere fit, so the solver works on
   unit-radius data whatever the input unit (tolerances then mean the same thing for counts and
   for g); start from an algebraic ellipsoid fit (alpha = M^(-1/2), the nine-parameter model
   *is* a centred ellipsoid with symmetric shape);
6. fit the sphere residual (paper 1, eq. 6, divided by g^2) with the chosen solver;
7. map back to input units (alpha = k alpha_n / g, beta = k beta_n + c0; covariance likewise),
   and report the error before and after, the noise floor and what is poorly determined.

The jitted core is compiled once per (solver, padded size): fit points are padded to a power
of two with zero weights, so logs of similar length share one compilation.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import warnings as _warnings
from collections.abc import Callable
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .calibration import AccelCalibration, FitStatusWarning, accel_output_units, apply_params
from .geometry import (
    ellipsoid_fit_moments,
    moments,
    sphere_fit_moments,
    sphere_fit_points,
    sqrtm_inv_spd,
)
from .implicit import solve_implicit
from .io.files import SensorLog, as_log
from .lm import (
    LMResult,
    budget_apart,
    budgeted_disk_jit,
    checked_solver_options,
    fit_status,
    lm_solve,
    status_message,
    with_budget,
)
from .models.accel import ALPHA_ENTRIES, ALPHA_INDEX, PARAM_NAMES, normalized_sphere_residual
from .observations import (
    AccelObservations,
    TooFewPoses,
    accel_observations,
    detection_found,
    most_poses_found,
)
from .padding import pad_rows
from .runtime import disk_jit
from .static import StaticReport, check_sample_rate, distinct_directions
from .status import CONVERGED_STATUSES, Status

G_STANDARD = 9.80665
SOLVERS = ("lm1", "lm2", "lm3", "optimistix")
Units = Literal["auto", "counts", "g", "m/s^2"]
_UNIT_ALIASES = {
    "g": "g",
    "m/s^2": "m/s^2",
    "m/s2": "m/s^2",
    "mps2": "m/s^2",
    "counts": "counts",
    "count": "counts",
    "raw": "counts",
    "lsb": "counts",
    "a.u.": "counts",
    "au": "counts",
}

# A parameter is "poorly determined" when its standard error, in units of the reference
# magnitude, exceeds this: 1 % of g is the accuracy paper 1 claims for the whole calibration.
POOR_STDERR = 1e-2
POOR_CONDITION = 1e8
RESIDUAL_OVER_FLOOR = 10.0
"""A fit whose interval-mean residual exceeds this many noise floors gets a warning: on real
logs the fit leaves 0.3-3 floors (imu_tk's Xsens 3.1, CK-Explorer 2.0 and 2.2, a wrist log 1.0,
a hand-held MPU-6050 0.3); a magnetometer's tumble fitted as an accelerometer left 14."""
REST_RMS_LIMIT = 1e-2
"""Poses held still leave less than this RMS of (|a| - g)/g after the fit (real multi-pose
logs here: 1e-4 to 3e-3); more, and the quiet stretches the detector found are pauses in a
hand-held motion, not rests (a micropython-fusion MPU-9150 log: 0.012). ``calib-jax marg``
then fits the accelerometer's ellipsoid instead; the accelerometer and gyro fits warn."""

REST_FAIL = 3e-2
"""Poses that leave this much of g after the fit (three times :data:`REST_RMS_LIMIT`) are no
rests at all, and the fit to them is no calibration: a phone's hand-held magnetometer tumble
(tyrex-team's Nexus 5) gave 12 'poses' that left 0.074 of g, 1x lower than before, exit 0 as
usable, and on the same phone's held poses that calibration left 5.7 % of g where the raw
readings left 1.5 %."""

REFUSALS = ("the fitted gains are", "the poses do not determine", "the poses are no rests")
"""How the warnings that make a fit that ran 'failed' begin (:func:`implausible_gains`,
:func:`undetermined`, :func:`not_rests`): the gyro gives them as its reason to refuse."""


# ---------------------------------------------------------------------------------------------
# pure core


def initial_guess(x: jax.Array, w: jax.Array) -> jax.Array:
    """Start for the normalised fit: algebraic ellipsoid, or unit sphere at the fitted centre.

    x is centred and scaled to about unit radius. Returns p_n (9,).
    """
    return initial_guess_moments(moments(x, w))


def initial_guess_points(x: np.ndarray) -> np.ndarray:
    """:func:`initial_guess` of host points (N, 3), equal weights: padded to a power of two
    and compiled once per size, kept on disk (eagerly it took 2 s of a warm CLI call)."""
    return np.asarray(_INITIAL_GUESS(*pad_rows(np.asarray(x, float))))


def initial_guess_moments(S: jax.Array) -> jax.Array:
    """:func:`initial_guess` from the moment matrix of the (normalised) samples."""
    c, M, ok = ellipsoid_fit_moments(S)
    alpha = sqrtm_inv_spd(jnp.where(ok, M, jnp.eye(3, dtype=S.dtype)))
    p_ell = jnp.concatenate([alpha[ALPHA_ENTRIES], c])
    cs, r = sphere_fit_moments(S)
    p_sph = jnp.concatenate([jnp.full(3, r), jnp.zeros(3, S.dtype), cs])
    use_ell = ok & jnp.all(jnp.isfinite(p_ell))
    return jnp.where(use_ell, p_ell, p_sph)


_INITIAL_GUESS = disk_jit(initial_guess, "accel.initial_guess")


MODELS = {
    "accel9": (True,) * 9,
    # the six-element model (gains and biases, alpha diagonal): all that six-face data such as
    # the Ferraris protocol can determine
    "accel6": (True, True, True, False, False, False, True, True, True),
}


def fit_normalized(
    x: jax.Array,
    w: jax.Array,
    solver: str = "lm1",
    model: str = "accel9",
    g: float | jax.Array = 1.0,
    implicit: bool = False,
    **options,
) -> LMResult:
    """Pure core: fit paper 1's model to data x (N, 3) of radius about ``g`` with weights w (N,).

    The one accelerometer fit: :func:`calibrate_accel` calls it on unit-radius interval means,
    :func:`calib_jax.pipeline.fit_accel` with ``implicit=True``. The residual is
    :func:`calib_jax.models.accel.normalized_sphere_residual`, 1 - |a|^2 / g^2, and the start
    the algebraic ellipsoid (:func:`calib_jax.geometry.initial_guess`) scaled to radius g.
    Jittable and vmappable over sensors. ``solver``, ``model``, ``implicit`` and ``options``
    are static. For ``model="accel6"`` the non-orthogonality terms are held at zero; the result
    still has nine entries (zero standard error and covariance for the fixed ones).
    ``implicit=True`` (LM solvers only): ``params`` are differentiable in x, w and g by the
    implicit function theorem (:func:`calib_jax.implicit.solve_implicit`).
    """
    free = np.asarray(MODELS[model])
    idx = np.flatnonzero(free)
    p0 = initial_guess(x, w)
    p0 = jnp.concatenate([p0[:6] / g, p0[6:]])  # the algebraic start is for |a| = 1
    p0 = jnp.where(jnp.asarray(free), p0, 0.0)

    def embed(q):
        return jnp.zeros(9, q.dtype).at[idx].set(q)

    def residual(q, data):
        x, _, g = data
        return normalized_sphere_residual(embed(q), x, g)

    data = (x, w, g)
    if solver == "optimistix":
        if implicit:
            raise ValueError("implicit=True needs an LM solver (lm1, lm2, lm3)")
        from .lm.optx import optx_solve

        res = optx_solve(residual, p0[idx], data, weights=w, **options)
    else:
        update_type = {"lm1": 1, "lm2": 2, "lm3": 3}[solver]
        if implicit:
            q, res = solve_implicit(
                residual, p0[idx], data, weights=lambda d: d[1], update_type=update_type,
                **options,
            )  # fmt: skip
            res = eqx.tree_at(lambda r: r.params, res, q)
        else:
            res = lm_solve(residual, p0[idx], data, weights=w, update_type=update_type, **options)
    if len(idx) == 9:
        return res
    full = np.zeros((9, len(idx)))
    full[idx, np.arange(len(idx))] = 1.0
    E = jnp.asarray(full, res.params.dtype)
    corr = E @ res.correlation @ E.T + jnp.diag(jnp.asarray(~free, res.params.dtype))
    return eqx.tree_at(
        lambda r: (r.params, r.stderr, r.covariance, r.correlation),
        res,
        (embed(res.params), E @ res.stderr, E @ res.covariance @ E.T, corr),
    )


@functools.lru_cache(maxsize=64)
def _compiled(solver: str, model: str, options: tuple, budgeted: bool) -> Callable:
    return budgeted_disk_jit(
        functools.partial(fit_normalized, solver=solver, model=model),
        f"accel.fit_normalized {solver} {model} {options!r}",
        options,
        budgeted,
    )


def _fit_program(solver: str, model: str, options: tuple) -> Callable:
    """The compiled fit ``(x, w) -> LMResult`` for these solver options; the iteration budget
    is its argument, not its key (:func:`calib_jax.lm.budget_apart`)."""
    key, budget = budget_apart(solver, options)
    return with_budget(_compiled(solver, model, key, budget is not None), budget)


# ---------------------------------------------------------------------------------------------
# host-side helpers


UNIT_BANDS = {"g": (0.7, 1.4), "m/s^2": (7.0, 14.0), "counts": (30.0, np.inf)}
"""Static norms an accelerometer reads in each unit: |g| within a gain error of 30-40 % (one
beyond that is no accelerometer in that unit: a magnetometer in gauss reads 0.25-0.65, a
gyroscope at rest near 0). Raw counts have any scale above 30."""

_UNIT_RANGES = ", ".join(
    f"{u}: {lo:g}-{hi:g}" if np.isfinite(hi) else f"{u}: above {lo:g}"
    for u, (lo, hi) in UNIT_BANDS.items()
)


def _units_from_norm(norm: float) -> str | None:
    """The unit whose band (:data:`UNIT_BANDS`) holds this static norm, or None."""
    return next((u for u, (lo, hi) in UNIT_BANDS.items() if lo <= norm <= hi), None)


def detect_units(
    static_norm: float, fit_norm: float | None = None, radius_determined: bool = False
) -> str | None:
    """The accelerometer's unit from the median norm of its static readings, else from the
    radius of the sphere through them (a large bias moves the norm, not the radius): the one
    rule of the single fit and the batch. ``radius_determined`` (:func:`radius_determined`):
    the readings surround their fitted centre, so the radius is |g| in their unit whatever the
    bias, and it alone decides: a magnetometer in gauss with a hard-iron offset of 0.77 had a
    median norm of 0.89 'g' about zero and was calibrated with gains of 0.4, status ok."""
    if radius_determined and fit_norm is not None:
        return _units_from_norm(fit_norm)
    return _units_from_norm(static_norm) or (
        _units_from_norm(fit_norm) if fit_norm is not None else None
    )


BLOB_SPREAD = 0.3
"""Distances from a fitted centre that scatter by more than this fraction of their mean lie
in a blob, not on a sphere: a 3-D Gaussian cloud's scatter by 0.42 of it (a chi with three
degrees), a sphere of readings' by the calibration's error (under 0.1 for an uncalibrated
sensor)."""


def radius_determined(points: np.ndarray, centre: np.ndarray) -> bool:
    """Whether the points reach beyond a hemisphere about ``centre`` (the smallest cosine of
    their directions to the mean direction is negative), so a sphere through them determines
    its radius; poses seen from one side leave it to the bias and the gains. Points that
    surround their centre as a blob does (distances scattered by more than :data:`BLOB_SPREAD`
    of their mean) determine nothing: a robot driving on one pose, fitted sample by sample,
    gave a 'sphere' of radius 0.116 about its own readings (norm 9.80 m/s^2), and the refusal
    said no accelerometer reads 0.116 and proposed the gyroscope."""
    d = np.asarray(points, float) - centre
    n = np.linalg.norm(d, axis=1)
    if len(d) < 4 or not np.all(n > 0) or np.std(n) > BLOB_SPREAD * np.mean(n):
        return False
    return _coverage(np.asarray(points, float), d / n[:, None])[2] < 0


# the refusal's words for readings whose radius is a magnetometer's in gauss; calib-jax diagnose
# looks for them to diagnose a log whose columns name no sensor as the magnetometer instead
MAGNETOMETER_IN_GAUSS = "A magnetometer in gauss reads 0.25-0.65"


def no_accelerometer_unit(
    norm: float,
    fit_norm: float | None = None,
    units_option: bool = True,
    radius_determined: bool = False,
) -> str:
    """Why a static norm fits no accelerometer unit, and what to do: the one message of the
    single fit, the batch, the recorder and (``units_option`` False: it has no --units) the
    diagnosis. ``radius_determined``: the radius about the fitted centre decided (it is |g|
    in the readings' unit), not the norm."""
    radius = f" (radius {fit_norm:.4g} about their fitted centre)" if fit_norm else ""
    what = f"the static readings have median norm {norm:.4g}{radius}, which is"
    if radius_determined and fit_norm is not None:
        what = (
            f"the static readings surround their fitted centre on a sphere of radius "
            f"{fit_norm:.4g} (their median norm about zero is {norm:.4g}: an offset), and that "
            "radius, gravity in their unit, is"
        )
        norm = fit_norm
    like = ""
    if 0.15 <= norm < 0.7:
        like = (
            f" {MAGNETOMETER_IN_GAUSS}: if this is one, run calib-jax mag "
            "(or diagnose --sensor mag)."
        )
    elif norm < 0.15:
        like = " A gyroscope at rest reads near zero: if this is one, run calib-jax gyro."
    return (
        f"{what} no accelerometer "
        f"reading in any unit considered ({_UNIT_RANGES}): gains would absorb the difference "
        f"and the calibration would look fine while being wrong.{like} If it is an "
        + (
            "accelerometer in another scale, say so: calib-jax accel --units counts "
            "(units='counts' in Python; any scale, output in g)"
            if units_option
            else "accelerometer in another scale, convert it to g or m/s^2 first"
        )
    )


def _nominal(
    x_static: np.ndarray, units: str, g: float, out_units: str | None = None
) -> tuple[np.ndarray, float]:
    """The 'before' conversion: offset and scale a user would assume without calibration
    (readings / scale are in the output unit).

    Physical units: offset 0, scale 1, or the unit's conversion to ``out_units`` (g to m/s^2:
    1 / 9.80665; the 'before' of a log in g fitted to m/s^2 was 0.90, |a| in g over 9.81).
    Counts: offset 2^(bits-1) for unsigned data (all readings positive and centred near
    mid-range, like imu_tk's 16-bit Xsens counts), else 0; scale = median static norm / g.
    """
    if units != "counts":
        in_ms2 = {"g": G_STANDARD, "m/s^2": 1.0}
        a, b = in_ms2.get(units), in_ms2.get(_UNIT_ALIASES.get(str(out_units).lower(), units))
        return np.zeros(3), (b / a if a and b else 1.0)
    offset = np.zeros(3)
    lo, hi = x_static.min(), x_static.max()
    if lo > 0:
        bits = int(np.ceil(np.log2(hi + 1)))
        mid = 2.0 ** (bits - 1)
        if lo < mid < hi:
            offset = np.full(3, mid)
    scale = float(np.median(np.linalg.norm(x_static - offset, axis=1)) / g)
    return offset, scale


def _coverage(pts: np.ndarray, dirs: np.ndarray) -> tuple[float, np.ndarray, float, np.ndarray]:
    """Flatness of the fit points (smallest / largest eigenvalue of their covariance: 0 = all
    in one plane) and the plane's normal; the smallest cosine of the directions to their mean
    direction (> 0 = one hemisphere) and that direction. The plane test uses the points, not
    directions from a fitted centre: a sphere fit to coplanar points puts the centre anywhere
    along the normal."""
    evals, evecs = np.linalg.eigh(np.cov(pts.T))
    flat = float(evals[0] / evals[2]) if evals[2] > 0 else 0.0
    mean = dirs.mean(axis=0)
    mn = np.linalg.norm(mean)
    axis = mean / mn if mn > 0 else np.array([0.0, 0.0, 1.0])
    return flat, evecs[:, 0], float(np.min(dirs @ axis)), axis


# fit points whose covariance's smallest / largest eigenvalue is below this lie in one plane
# (the single fit, the batch and the pipeline: calib_jax.geometry.prefit_status)
FLAT_POSES = 1e-3


def _check_plane(flatness: float, normal: np.ndarray) -> None:
    if flatness < FLAT_POSES:
        raise ValueError(
            f"all poses lie near one plane (normal {_vec(normal)} in the sensor frame); the "
            "gain and bias along that normal are unobservable. Add poses tilted out of the plane"
        )


def _vec(v: np.ndarray) -> str:
    return "[" + ", ".join(f"{x:+.2f}" for x in v) + "]"


# one compiled call (reloaded from the persistent cache) instead of ~25 eager operations, each
# traced and looked up in a new process: 1.6 s of a 5 s warm `calib-jax accel`


def nominal_centre_of(obs: AccelObservations) -> np.ndarray:
    """The nominal zero of the fit points (zero, or mid-range for unsigned counts) in the unit
    their norm suggests: where poses are judged from when a fitted centre may mislead."""
    return _nominal(obs.points, _units_from_norm(obs.static_norm) or "counts", 1.0)[0]


def check_poses(
    obs: AccelObservations, model: str, sample_rate: float | None = None
) -> tuple[np.ndarray, float]:
    """The sphere through the fit points (centre, radius) after checking that they can
    determine the model: a ValueError, reported as a detection or coverage problem, when
    there are fewer distinct poses than free parameters or all poses lie in one plane.
    ``calibrate_accel`` and the batch paths (:mod:`calib_jax.fleet`) both call it."""
    pts = obs.points
    c_s, r_s = sphere_fit_points(pts)
    if not np.isfinite(r_s) or r_s <= 0:
        c_s, r_s = pts.mean(axis=0), float(np.median(np.linalg.norm(pts - pts.mean(0), axis=1)))
    # counted about the fitted centre and about the nominal one (zero, or mid-range for
    # unsigned counts): points of a single pose fit no sphere, and about their own arbitrary
    # centre the noise looked like several poses (a board lying flat gave "5 distinct poses")
    nominal_centre = nominal_centre_of(obs)
    n_fitted, n_nominal = (
        max(1, distinct_directions(pts, c)) for c in (c_s, nominal_centre)
    )  # one point about its own centre has no direction: still one pose
    if len(pts) < 4:  # no sphere passes through fewer than 4 points: its centre is arbitrary
        # (a Pololu log's two opposite poses counted as 1 distinct pose about it)
        n_fitted = n_nominal
    n_distinct = min(n_fitted, n_nominal)
    about = ""
    if n_fitted != n_nominal:  # say which count this is: the detector's counts are the other
        centre = ", ".join(f"{v:.3g}" for v in nominal_centre)
        about = (
            f", about the nominal centre ({centre}); {n_fitted} about the sphere fitted "
            "through them"
            if n_nominal < n_fitted
            else f", about the sphere fitted through them; {n_nominal} about the nominal centre"
        )
        if n_nominal == 1 < n_fitted:  # a sphere through one pose's means centres anywhere
            about = f", about the nominal centre ({centre}): the readings point one way"
    n_free = int(sum(MODELS[model]))
    if len(obs.means) >= n_free:  # enough poses, but coplanar: the sphere centre is arbitrary
        _check_plane(*_coverage(pts, np.ones((1, 3)))[:2])
    if n_distinct < n_free:
        raise TooFewPoses(
            f"only {n_distinct} distinct pose{'s' if n_distinct != 1 else ''} (gravity "
            f"directions at least 10 degrees apart"
            f"{about}) among the {len(pts)} fit points: static detection "
            f"{detection_found(obs.report, sample_rate)}; the {n_free}-parameter model needs at "
            f"least {n_free} poses spread over the sphere (paper 1 uses 48)",
            n_distinct,
            model,
            samples_tried=obs.use == "samples"
            or obs.report.kind == "pose_table"
            or _one_way(obs.report),
        )

    return c_s, r_s


def _one_way(report) -> bool:
    """Every detector setting tried found one pose at most: the readings point one way
    throughout (a log of one face), and fitting its quasi-static samples is no advice to give
    (AirbrakesV2's xplus.csv was told to try --use samples, which found one pose too)."""
    return bool(report.candidates) and most_poses_found(report) <= 1


def _holds_six_faces(pts: np.ndarray, centre: np.ndarray, within_deg: float = 30.0) -> bool:
    """Whether some pose has each sensor axis up and some each axis down (within
    ``within_deg``): the six faces that determine gains and biases without cross terms."""
    d = pts - centre
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    cos = np.cos(np.deg2rad(within_deg))
    return bool(np.all(d.max(axis=0) >= cos) and np.all(-d.min(axis=0) >= cos))


def _check_poses_for(
    model: str, obs: AccelObservations, sample_rate: float | None, notes: list[str]
) -> tuple[np.ndarray, float, str]:
    """:func:`check_poses` for ``model``; "auto" is paper 1's nine parameters, or six (with a
    note) where the log holds 6-8 distinct poses that include each axis up and down."""
    if model != "auto":
        return (*check_poses(obs, model, sample_rate), model)
    try:
        return (*check_poses(obs, "accel9", sample_rate), "accel9")
    except TooFewPoses as exc:
        if exc.n_distinct < 6:
            raise
        c_s, r_s = check_poses(obs, "accel6", sample_rate)
        # about the fitted centre and the nominal one: a sphere through a cap of poses puts
        # its centre anywhere, and about it the cap showed 'each axis up and down' (a EuRoC
        # flight, every pose within 28 deg of one direction)
        nominal = nominal_centre_of(obs)
        if not (_holds_six_faces(obs.points, c_s) and _holds_six_faces(obs.points, nominal)):
            raise TooFewPoses(
                f"{exc.finding}; nor do the poses hold each axis pointing up and down, which "
                "the six-parameter model needs",
                exc.n_distinct,
                "auto",
                exc.samples_tried,
            ) from None
        notes.append(
            f"model accel6 (gains and biases; the cross terms held at zero): the log holds "
            f"{exc.n_distinct} distinct poses with each axis up and down, too few for paper "
            "1's nine parameters (model='accel9', --model accel9, insists)"
        )
        return c_s, r_s, "accel6"


# ---------------------------------------------------------------------------------------------
# the public entry point


def calibrate_accel(
    data: np.ndarray | SensorLog | str | os.PathLike,
    *,
    g: float | None = None,
    units: Units = "auto",
    output_units: str | None = None,
    solver: str = "lm1",
    model: Literal["accel9", "accel6", "auto"] = "auto",
    use: Literal["means", "samples"] = "means",
    sample_rate: float | None = None,
    window: int | None = None,
    threshold: float | None = None,
    threshold_factor: float | None = None,
    min_duration: float | None = None,
    min_samples: int | None = None,
    block: int | None = None,
    solver_options: dict | None = None,
    sensor_id: str | None = None,
) -> AccelCalibration:
    """Calibrate a triaxial accelerometer from a multi-position log (paper 1).

    Parameters
    ----------
    data : (N, 3) array, SensorLog or path
        Raw readings (any unit), a loaded log (its ``acc`` and ``sample_rate`` are used) or a
        log file (read with :func:`calib_jax.load_log`, as ``calib-jax accel FILE`` reads it).
    g : float, optional
        Reference magnitude in output units. Default: 1 for g and counts (output in g),
        9.80665 for m/s^2.
    units : {"auto", "counts", "g", "m/s^2"}
        Input units; "auto" decides from the static norm (0.7-1.4: g, 7-14: m/s^2, above 30:
        counts; any other norm is an error naming the sensor it looks like). A declared unit
        that contradicts the data is an error.
    output_units : str, optional
        Label of the calibrated output; default the input unit, or "g" for counts. Give it with
        ``g`` when calibrating counts to m/s^2 (``g=9.81744, output_units="m/s^2"``).
    solver : {"lm1", "lm2", "lm3", "optimistix"}
        Gavin LM update type 1-3, or optimistix's LevenbergMarquardt.
    model : {"accel9", "accel6", "auto"}
        Paper 1's nine parameters, or six (gains and biases; non-orthogonality held at zero),
        for six-face protocols that cannot determine the cross terms; "auto" (the default, as
        ``calib-jax accel``'s: a Python user's trial got TooFewPoses for the log the command
        fitted) takes nine where the log holds nine distinct poses or more and determines
        them, else six where it holds each axis up and down (a note says so).
    use : {"means", "samples"}
        Fit the static-interval means (each pose weighs the same; default) or every static
        sample (paper 1's choice; long rests weigh more).
    sample_rate, window, threshold, threshold_factor, min_duration, min_samples
        Static detection, see :func:`calib_jax.static.detect_static`. Left out, the detector
        chooses its window and threshold from the data (a sweep scored by a fit of the interval
        means) and recognises pose tables (one row per pose); what it chose is reported in
        ``notes`` (lines starting "static detection"); ``warnings`` holds problems to act on.
    block : int, optional
        The log holds its poses as consecutive blocks of this many samples (recorded pose by
        pose): the blocks are the intervals and nothing is detected.
    solver_options : dict, optional
        Passed to the solver (e.g. ``{"jacobian": "broyden", "rho_form": "paper"}``).

    Raises
    ------
    ValueError
        With what to change, for input that cannot give a calibration: wrong shape, nothing
        finite, no static interval, too few distinct poses, all poses in one plane, units that
        contradict the data.
    """
    log_notes: list[str] = []
    source = None
    data = as_log(data, "accel")
    if isinstance(data, SensorLog):
        sample_rate = sample_rate or data.sample_rate
        log_notes = list(data.notes)
        source = data.path
        x = data.vectors("accel")
    else:
        x = np.asarray(data, float)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"accelerometer data must be (samples, 3), got shape {x.shape}")
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
    if model not in (*MODELS, "auto"):
        raise ValueError(f"model must be one of {(*MODELS, 'auto')}, got {model!r}")
    units = _UNIT_ALIASES.get(str(units).lower(), units) if units != "auto" else "auto"
    if units not in ("auto", "counts", "g", "m/s^2"):
        raise ValueError(f"units must be auto, counts, g or m/s^2, got {units!r}")
    if g is not None and (not isinstance(g, (int, float, np.number)) or isinstance(g, bool)):
        raise ValueError(
            f"g={g!r}: the reference magnitude must be a number in the output unit (9.81744, "
            "not a string), or left out"
        )
    check_sample_rate(sample_rate)

    obs = accel_observations(
        x,
        use=use,
        sample_rate=sample_rate,
        window=window,
        threshold=threshold,
        threshold_factor=threshold_factor,
        min_duration=min_duration,
        min_samples=min_samples,
        block=block,
    )
    warn: list[str] = list(obs.warnings)
    notes: list[str] = log_notes + obs.notes
    report, means, pts = obs.report, obs.means, obs.points

    asked = model
    try:
        c_s, r_s, model = _check_poses_for(model, obs, sample_rate, notes)
    except TooFewPoses as exc:
        if units != "auto" or detect_units(obs.static_norm) is not None:
            raise
        # too few poses, and of no accelerometer's size: both, or the user fixes the poses
        # and meets the second refusal next (an Axivity AX6 export at 0.07 'g', a trial)
        raise TooFewPoses(
            f"{exc.finding}. Besides, {no_accelerometer_unit(obs.static_norm)}",
            exc.n_distinct,
            exc.model,
            exc.samples_tried,
        ) from None
    static_norm = obs.static_norm

    fit_norm = r_s if use == "means" else float(np.median(np.linalg.norm(means - c_s, axis=1)))
    units = _resolve_units(
        units, report.n_intervals, static_norm, fit_norm, radius_determined(pts, c_s)
    )
    g = _reference_magnitude(g, units, static_norm, output_units)
    out_units = accel_output_units(units, output_units)

    # normalise (centre and radius of the points' sphere) and fit
    k = r_s
    n = len(pts)
    opts = checked_solver_options(solver, solver_options)
    if jax.dtypes.canonicalize_dtype(np.float64) != np.float64:  # (no eager program)
        _warnings.warn(
            "jax_enable_x64 is off: calibrating in float32 loses ~1e-7 relative accuracy; "
            "call jax.config.update('jax_enable_x64', True) first",
            stacklevel=2,
        )
    xpad, wpad = pad_rows((pts - c_s) / k)
    fit = _fit_normalised(solver, model, opts, xpad, wpad, k, g, c_s)
    if asked == "auto" and _six_would_serve(fit, model):
        six = _fit_normalised(solver, "accel6", opts, xpad, wpad, k, g, c_s)
        # six parameters serve where they are determined (every gain and bias within 1 % of
        # g) and the cross terms the nine did determine explain little: at most twice the
        # nine's chi2. (An F test has one to three degrees of freedom on 10-12 poses and
        # passed a hand-held MPU-6050 whose x-z and y-z terms are real: chi2 57x, rms 7.7e-5
        # -> 5.9e-4; a Nexus 5 turned about x or y alone: 1.4x.)
        if six.status == "ok" and float(six.res.chi2) <= 2.0 * float(fit.res.chi2):
            notes.append(
                "model accel6 (gains and biases; the cross terms held at zero): with nine "
                f"parameters {', '.join(fit.poor)} were poorly determined, the poses not "
                "mixing the axes a cross term couples, and the cross terms explain little "
                f"(chi2 {float(fit.res.chi2):.3g} with them, {float(six.res.chi2):.3g} "
                "without); model='accel9' (--model accel9) insists"
            )
            fit, model = six, "accel6"
    res, params, cov, stderr, corr = fit.res, fit.params, fit.cov, fit.stderr, fit.corr
    condition, solver_status, status, poor = fit.condition, fit.solver_status, fit.status, fit.poor
    warn += _coverage_warnings(
        pts,
        c_s,
        int(sum(MODELS[model])),
        _nominal(pts, units, g)[0],
        pose_table=report.kind == "pose_table",
    )
    warn += fit.warnings
    refusal = fit.refusal  # gains no accelerometer has
    if status in ("ok", "poorly_determined"):
        refusal = undetermined(fit.stderr_n, model)
        if refusal:
            status = "failed"
            warn.append(refusal)

    # errors before/after over interval means, noise floor from within-interval scatter
    x_static = x[report.mask & obs.valid]
    offset, scale = _nominal(x_static, units, g, out_units)
    before = np.linalg.norm((means - offset) / scale, axis=1) / g - 1.0
    after, floor = interval_errors(params, g, x, report)
    if status != "failed" and (no_rests := not_rests(after, len(means))):
        status, refusal = "failed", no_rests
        warn.append(refusal)
    elif after >= REST_RMS_LIMIT:
        warn.append(
            f"the {len(means)} poses leave {after:.2g} of g after the fit (held rests leave "
            f"under {REST_RMS_LIMIT:g}): they look like pauses in a motion, not rests; hold "
            "each pose still for a few seconds on a support"
        )
    elif after > RESIDUAL_OVER_FLOOR * floor > 0:
        warn.append(
            f"the fit leaves {after / floor:.0f}x the noise floor (RMS of (|a| - g)/g {after:.3g} "
            f"against {floor:.3g}): the model does not describe these poses. Check that the "
            "columns are the accelerometer's and that each pose was held still, or find the "
            "effect the model lacks (calib-jax diagnose)"
        )
    cal = AccelCalibration(
        params=params,
        stderr=stderr,
        covariance=cov,
        correlation=corr,
        condition=condition,
        status=status,
        input_units=units,
        output_units=out_units,
        g=float(g),
        solver=solver,
        model=model,
        solver_status=solver_status,
        # refused for what the data are: no advice to raise the budget beside "will not help"
        solver_message=status_message(solver_status, refused=bool(refusal)),
        iterations=int(res.iterations),
        nfev=int(res.nfev),
        use=use,
        n_intervals=report.n_intervals,
        n_points=n,
        rms_before=float(np.sqrt(np.mean(before**2))),
        rms_after=after,
        noise_floor=floor,
        poorly_determined=poor,
        warnings=warn,
        notes=notes,
        static_means=means,
        static_intervals=np.array([[iv.start, iv.stop] for iv in report.intervals], int).reshape(
            -1, 2
        ),
        nominal_offset=offset,
        nominal_scale=scale,
        sensor_id=sensor_id,
        source=source,
    )
    if status in ("failed", "not_converged"):
        _warnings.warn(  # a fit refused after it ran says why, not the solver's "converged"
            f"accelerometer calibration {status}: {refusal or cal.solver_message}",
            FitStatusWarning,
            stacklevel=2,
        )
    return cal


def not_at_rest(status, rms_relative):
    """A converged accelerometer fit's status with NOT_AT_REST where its points leave at least
    :data:`REST_FAIL` of g (inside jit: the batch's and the pipeline's form of
    :func:`not_rests`; a whole log given where its static samples were meant gave gains 1 %
    off, 19 of their standard errors, status ok: a Python user's trial)."""
    converged = jnp.isin(status, jnp.asarray([int(c) for c in CONVERGED_STATUSES]))
    return jnp.where(
        converged & (rms_relative >= REST_FAIL), int(Status.NOT_AT_REST), status
    ).astype(jnp.asarray(status).dtype)


def not_rests(after: float, n_poses: int) -> str | None:
    """Why poses that leave ``after`` of g after the fit are no calibration (at least
    :data:`REST_FAIL`), else None: the one rule of the single fit and the batch."""
    if not after >= REST_FAIL:
        return None
    return (
        f"the poses are no rests: the {n_poses} of them leave {after:.2g} of g after the fit, "
        f"{after / REST_RMS_LIMIT:.0f} times what held rests leave ({REST_RMS_LIMIT:g}), so the "
        "quiet stretches the detector found are pauses in a motion (a tumble?) and a fit to "
        "them is no calibration; hold each pose still for a few seconds on a support"
    )


def _resolve_units(
    units: str, n_intervals: int, static_norm: float, fit_norm: float, determined: bool = False
) -> str:
    """The input unit: the one the static norm fits ("auto"), or the declared one checked
    against it (counts have any scale); a ValueError saying which unit the data look like.
    ``determined``: the fitted radius decides (:func:`detect_units`)."""
    detected = detect_units(static_norm, fit_norm, determined)
    if units == "auto":
        if detected is None:
            raise ValueError(no_accelerometer_unit(static_norm, fit_norm, True, determined))
        return detected
    if detected != units and units != "counts":
        raise ValueError(
            f"units={units!r}, but the static readings have norm {static_norm:.4g}, which looks "
            f"like {detected or 'no known unit'} ({_UNIT_RANGES}); pass units="
            f"{detected or 'counts'!r} (--units {detected or 'counts'}), or fix the scaling of "
            "the log"
        )
    return units


ACCEL6_OPTION = "--model accel6, model='accel6'"
"""How a refusal names the six-parameter model (``calib-jax gyro`` says its own flag)."""

OUTPUT_G_RANGE = {"g": (0.99, 1.01), "m/s^2": (9.7, 9.9)}
"""Gravity in each output unit it has (Earth's surface: 9.78-9.83 m/s^2); a ``g`` outside
is another unit's number."""


def _reference_magnitude(
    g: float | None, units: str, static_norm: float, output_units: str | None
) -> float:
    """g in output units: given, or 1 (g, counts) / 9.80665 (m/s^2). A given g off the data's
    unit (m/s^2 data with g = 1) would silently rescale the output, so it is refused unless
    ``output_units`` states the conversion."""
    out = _UNIT_ALIASES.get(str(output_units).lower()) if output_units is not None else None
    if g is None:
        # the output unit, where it is one of gravity's, decides (output_units='m/s^2' alone
        # gave readings in g labelled m/s^2, status ok: a ROS export 9.8x too small, a trial)
        g = G_STANDARD if (out or units) == "m/s^2" else 1.0
    elif out in OUTPUT_G_RANGE and not OUTPUT_G_RANGE[out][0] <= g <= OUTPUT_G_RANGE[out][1]:
        lo, hi = OUTPUT_G_RANGE[out]
        raise ValueError(
            f"g={g:g} in the output unit {output_units!r}, where gravity is {lo:g}-{hi:g}: give "
            f"the local gravity in {out} (or leave g out: {G_STANDARD if out == 'm/s^2' else 1:g})"
        )
    elif output_units is None:
        from .batch import check_reference_magnitude

        try:
            check_reference_magnitude(g, units, static_norm)
        except ValueError as exc:
            raise ValueError(
                f"{exc}; or give the output unit (output_units=, --out-units) to convert"
            ) from None
    if g <= 0 or not np.isfinite(g):
        raise ValueError(f"g must be a positive number, got {g}")
    return g


SPREAD_MIN = 0.2
"""RMS component of gravity's direction along some axis over the poses below which that axis
counts as hardly tilted (0.58 for poses all round; BROAD trial 05's x axis: 0.15)."""


def _coverage_warnings(
    pts: np.ndarray,
    c_s: np.ndarray,
    n_free: int,
    nominal: np.ndarray | None = None,
    pose_table: bool = False,
) -> list[str]:
    """What the poses' spread leaves poorly determined (a ValueError when they lie in one
    plane): one hemisphere or a narrower cap only, or hardly more fit points than parameters.
    The spread is judged about the fitted centre and, where given, the nominal one (zero, or
    mid-range counts), whichever sees the poses more bunched: a sphere through a cap of poses
    puts its centre almost anywhere, and about that centre the cap can look spread."""
    warn = []
    flatness, normal = _coverage(pts, np.ones((1, 3)))[:2]
    _check_plane(flatness, normal)
    caps = []
    for c in (c_s,) if nominal is None else (c_s, nominal):
        d = pts - c
        norms = np.linalg.norm(d, axis=1, keepdims=True)
        if np.all(norms > 0):
            caps.append(_coverage(pts, d / norms)[2:])
    min_cos, hemi_axis = max(caps, key=lambda cap: cap[0])
    # an axis hardly ever tilted towards the vertical: the poses' directions (about the
    # nominal centre, which a cap of poses cannot move) barely vary along it
    d = pts - (c_s if nominal is None else nominal)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    evals, evecs = np.linalg.eigh(d.T @ d / len(d))
    for ev, axis in zip(evals, evecs.T, strict=True):
        if ev < SPREAD_MIN**2:
            warn.append(
                f"gravity hardly varies along {_vec(axis)} in the sensor frame: its RMS "
                f"component there is {np.sqrt(max(ev, 0.0)):.2f} of |g| over the poses "
                f"({1 / np.sqrt(3):.2f} for poses all round), so that axis was hardly tilted "
                "towards up or down and its gain, cross terms and bias are poorly determined "
                "(a fit that does not converge or lands far from nominal is the symptom); add "
                "poses with that axis pointing up and down"
            )
    if min_cos > 0.05:
        warn.append(
            f"all poses lie within {np.degrees(np.arccos(min(min_cos, 1.0))):.0f} deg of "
            f"{_vec(hemi_axis)} in the sensor frame (less than a hemisphere): gravity was seen "
            "from one side only, so "
            "gains, cross terms and biases cannot be told apart; add poses with each axis up "
            "and down"
        )
    elif min_cos > -0.05:
        warn.append(
            f"all poses lie in one hemisphere around {_vec(hemi_axis)}: gain and bias along it "
            "are correlated and poorly determined; add poses from the opposite side"
        )
    if len(pts) - n_free < 3:
        warn.append(
            f"{len(pts)} fit points for {n_free} parameters: "
            + (
                "the fit passes through every point, so its standard errors and 'after' error "
                "estimate nothing"
                if len(pts) <= n_free
                else "almost no redundancy, so the standard errors and the residual say little"
            )
            + (
                "; record more poses (a pose table has no samples to fit instead)"
                if pose_table
                else "; fit every static sample (--use samples, use='samples') for errors from "
                "their scatter, or record more poses"
            )
        )
    return warn


GAINS_PLAUSIBLE = (0.5, 2.0)
"""The range of the gains (the eigenvalues of alpha) in units of the data's own scale, g over
the radius of the readings, that any accelerometer's lie in: a real sensor's differ from its
nominal sensitivity by a few percent. A fit outside it has run off to a shape no sensor has,
where the points do not pin it down: 20 'poses' of a phone's hand-held walk (Sensor Logger,
|a| 0.97-1.19 g about intervals of 0.18 s) gave gains of 69-4,540 and biases of 250-5,080 g;
with the budget it advised raised, the fit "converged", its rms "6,698x lower", exit 0."""


def implausible_gains(params_n) -> str | None:
    """Why a fit's gains are no accelerometer's (None when they are): ``params_n`` the nine
    parameters of a fit to unit-radius points (gains and cross terms in units of g over the
    data's scale); the one rule of the single fit and the batch."""
    p = np.asarray(params_n, float)  # accel6's cross terms are zeros here
    ev = np.linalg.eigvalsh(p[ALPHA_INDEX]) if np.all(np.isfinite(p[:6])) else None
    lo, hi = GAINS_PLAUSIBLE
    if ev is None or (ev.min() >= lo and ev.max() <= hi):
        return None
    return (
        f"the fitted gains are {ev.min():.3g} to {ev.max():.3g} times the data's own scale, "
        f"where any accelerometer's lie within {lo:g}-{hi:g} of it: the points do not determine "
        "the model, so the fit ran to a shape no sensor has. Most often motion was taken for "
        "poses (see the static-detection notes) or the poses are too few or too alike; more "
        "iterations will not help. Record the sensor held still in at least 9 "
        "distinct orientations; this is no calibration"
    )


UNDETERMINED_STDERR = 0.1
"""A free parameter whose standard error exceeds this, in units of g, is not determined at all,
and a fit with one is no calibration ("failed"): poses that cover less than a hemisphere
(pms67's hand-tilted MPU-6050, tests/data/pms67_mpu6050: z gain 1.51 +- 0.157 and z bias
-0.67 +- 0.157 g, a calibration that would move every reading by a third of g). Ten times
POOR_STDERR: between them a fit is "poorly_determined", usable with its warning."""


def undetermined(se_n, model: str) -> str | None:
    """Why the poses leave the fit no calibration (None when they do not): some free
    parameter's standard error in units of g exceeds UNDETERMINED_STDERR, or is not finite;
    the one rule of the single fit and the batch. The advice names the poses each parameter
    needs: a cross term, tilts between its two axes; an axis's gain and bias (unless a cross
    term on that axis explains them), that axis up and down."""
    free = np.asarray(MODELS[model])
    se = np.asarray(se_n, float)
    bad = [i for i in range(9) if free[i] and not se[i] <= UNDETERMINED_STDERR]
    if not bad:
        return None
    worst = max(float(se[i]) for i in bad)
    size = f"up to {worst:.0%} of g" if np.isfinite(worst) else "not finite"
    pairs = [PARAM_NAMES[i][2:] for i in bad if 3 <= i <= 5]  # "xy", ...
    # a gain collinear with an undetermined cross term is undetermined through it (poses
    # turned about x and about y, never between: alpha_x, alpha_y and S_xy together)
    axes = sorted({"xyz"[i % 3] for i in bad if i < 3 or i > 5} - set("".join(pairs)))
    needs = [f"with the {a} axis pointing up and with it down" for a in axes]
    needs += [f"tilted between the {a} and {b} axes" for a, b in pairs]
    cross_only = not axes
    return (
        f"the poses do not determine {', '.join(PARAM_NAMES[i] for i in bad)} (standard errors "
        f"{size}; a calibration needs under {POOR_STDERR:.0%}): the fit would move readings by "
        f"as much. Add poses held still {', and '.join(needs)}"
        + (f", or fit gains and biases alone ({ACCEL6_OPTION})" if cross_only else "")
        + "; this is no calibration"
    )


def poorly_determined(se_n, model: str) -> list[str]:
    """The free parameters whose standard error in units of g (a unit-radius fit:
    gains and cross terms as they are, biases over the radius) exceeds POOR_STDERR; the one
    rule of the single fit and the batch."""
    free = np.asarray(MODELS[model])
    bad = ~np.isfinite(se_n) | (np.asarray(se_n) > POOR_STDERR)
    return [PARAM_NAMES[i] for i in range(9) if free[i] and bad[i]]


@dataclasses.dataclass(frozen=True)
class _NormalisedFit:
    """One model's fit of the normalised points, back in raw units, with its status."""

    res: object
    params: np.ndarray
    cov: np.ndarray
    stderr: np.ndarray
    stderr_n: np.ndarray  # in units of g (the unit-radius fit's)
    corr: np.ndarray
    condition: float
    solver_status: int
    status: str
    poor: list[str]
    warnings: list[str]
    refusal: str | None  # why a fit that ran is no calibration


def _fit_normalised(solver, model, opts, xpad, wpad, k, g, c_s) -> _NormalisedFit:
    """Fit ``model`` to the padded unit-radius points; parameters back in raw units (gains and
    cross terms scale by k / g, biases by k and shift by the centre c_s)."""
    res = _fit_program(solver, model, opts)(xpad, wpad)
    T = np.concatenate([np.full(6, k / g), np.full(3, k)])
    params = np.asarray(res.params, float) * T
    params[6:9] += c_s
    se_n = np.asarray(res.stderr, float)  # in units of g (unit-radius fit)
    corr = np.asarray(res.correlation, float)
    warn: list[str] = []
    status, poor = _status(int(res.status), params, se_n, corr, float(res.condition), model, warn)
    implausible = implausible_gains(res.params)
    if implausible:
        status = "failed"
        warn.append(implausible)
    return _NormalisedFit(
        res=res,
        params=params,
        cov=np.asarray(res.covariance, float) * np.outer(T, T),
        stderr=se_n * T,
        stderr_n=se_n,
        corr=corr,
        condition=float(res.condition),
        solver_status=int(res.status),
        status=status,
        poor=poor,
        warnings=warn,
        refusal=implausible,
    )


def _six_would_serve(fit: _NormalisedFit, model: str) -> bool:
    """The automatic model tries six parameters where nine leave a cross term undetermined
    (poses that tilt about x or about y, never between: a phone turned on a table edge)."""
    return (
        model == "accel9"
        and fit.status == "poorly_determined"
        and any(p.startswith("S_") for p in fit.poor)
    )


def _status(solver_status, params, se_n, corr, condition, model, warn) -> tuple[str, list[str]]:
    """The record's status word and the poorly determined parameters; appends the reasons
    (collinear parameters, ill-conditioning, large standard errors) to ``warn``."""
    status = fit_status(solver_status, bool(np.all(np.isfinite(params))))
    free = np.asarray(MODELS[model])
    poor = poorly_determined(se_n, model)
    hi_corr = [
        f"{PARAM_NAMES[i]}~{PARAM_NAMES[j]} ({corr[i, j]:+.4f})"
        for i in range(9)
        for j in range(i + 1, 9)
        if free[i] and free[j] and abs(corr[i, j]) > 0.999
    ]
    if hi_corr:
        warn.append("nearly collinear parameters: " + ", ".join(hi_corr))
    ill = not np.isfinite(condition) or condition > POOR_CONDITION
    if ill:
        warn.append(f"the normal equations are ill-conditioned (condition {condition:.3g})")
    if status == "ok" and (poor or ill):
        status = "poorly_determined"
        if poor:
            warn.append(POORLY_DETERMINED.format(", ".join(poor)))
    return status, poor


POORLY_DETERMINED = (
    "poorly determined (std. error above 1 % of g): {}; add poses that cover the sphere"
)


def interval_errors(
    params: np.ndarray, g: float, x: np.ndarray, report: StaticReport
) -> tuple[float, float]:
    """RMS over static intervals of (|mean corrected a| - g)/g, and its white-noise floor.

    The floor is the same RMS expected from within-interval scatter alone: for each interval
    the standard error of the mean of the corrected norm, std(|a|)/sqrt(n)/g. Rows that are
    not finite (another packet type's rows, blank cells) are left out, as the fit leaves them.
    """
    errs, floors = [], []
    for iv in report.intervals:
        a = apply_params(params, x[iv.start : iv.stop])
        a = a[np.isfinite(a).all(axis=1)]
        nrm = np.linalg.norm(a, axis=1)
        errs.append(np.linalg.norm(a.mean(axis=0)) / g - 1.0)
        if len(nrm) > 1:  # a pose-table row is one sample: no scatter to measure
            floors.append(nrm.std(ddof=1) / np.sqrt(len(nrm)) / g)
    floor = float(np.sqrt(np.mean(np.square(floors)))) if floors else float("nan")
    return float(np.sqrt(np.mean(np.square(errs)))), floor
