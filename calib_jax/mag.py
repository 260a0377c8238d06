"""From a raw log to an ellipsoid (hard/soft-iron) calibration (paper 2, section 2.2).

Host side (checks, normalisation, model choice) around a pure jitted core:

1. drop non-finite rows (counted, reported);
2. coverage: the directions from the data centre must not lie in one plane (error, with the
   fix); one hemisphere or a small part of the sphere is a warning (the shape is then poorly
   determined, which the standard errors show);
3. normalise: x_n = (x - mean) / s, s the RMS distance from the mean, so tolerances mean the
   same for counts, gauss and microtesla;
4. start from the ellipsoid-specific algebraic fit (Li-Griffiths, never a hyperboloid; see
   :func:`calib_jax.geometry.ellipsoid_fit_constrained`) and refine the quadric residual
   (:func:`calib_jax.models.mag.quadric_residual`) with the LM solver and exact Jacobians;
5. model: sphere (hard iron only), diag (axis-aligned ellipsoid), full, or ``auto``: the one
   with the lowest BIC of the radial error among those the data determine (every standard
   error under 1 %), else the sphere (the fewest parameters, with a warning naming the
   lowest-BIC model; if the sphere runs away, the lowest BIC among the bounded fits);
6. radius: the known field magnitude if given (output in its units), else det(M)^(-1/6) in raw
   units (det W = 1, MATLAB magcal's convention);
7. report the RMS radial error before (centred on the data mean) and after, in percent;
8. plausibility: a residual no magnetometer ellipsoid fit reaches is not "ok" (see
   RMS_PLAUSIBLE_PCT, RMS_NO_SHELL_PCT, AXES_RATIO below; saturated samples are left out
   before the fit).

The same routine calibrates an accelerometer (paper 2 applies it to every sensor): give static
samples and ``field=1`` (g). With ``model="full"`` it is paper 1's nine-parameter model with a
different parametrisation (W = alpha, c = beta), so both fits agree.
"""

from __future__ import annotations

import functools
import os
import warnings as _warnings
from typing import Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .calibration import FitStatusWarning, MagCalibration, ellipsoid_axes
from .geometry import (
    NO_SHELL,
    RUNAWAY,
    ellipsoid_fit_constrained_moments,
    moments,
    sphere_fit_moments,
    sphere_fit_points,
)
from .implicit import solve_implicit
from .io.files import SensorLog, as_log
from .lm import (
    LMResult,
    budget_apart,
    budgeted_disk_jit,
    checked_solver_options,
    fit_status,
    is_converged,
    lm_solve,
    status_message,
    with_budget,
)
from .models.mag import (
    MAG_MODELS,
    N_PARAMS,
    PARAM_NAMES,
    natural_radius,
    pack,
    quadric_residual,
    radial_error,
    raw_calibration,
    raw_covariance,
    unpack,
)
from .observations import screen_samples
from .padding import pad_rows
from .runtime import disk_jit
from .sphere import (
    coverage_about,
    sphere_coverage,  # noqa: F401  (re-exported: calib_jax.mag.sphere_coverage)
)
from .status import is_usable

SOLVERS = ("lm1", "lm2", "lm3", "optimistix")
MagModel = Literal["sphere", "diag", "full", "auto"]

# normalised standard error (units of the radius) above which a parameter is poorly determined
POOR_STDERR = 1e-2
POORLY_DETERMINED = (
    "poorly determined (normalised std. error above 1 %): {}; cover more orientations"
)


def poorly_determined(se_n, model: str) -> list[str]:
    """The parameters of ``model`` (its packed, normalised form: units of the data's radius)
    whose standard error is not finite or exceeds POOR_STDERR; the one rule of the single fit
    and the batch (:attr:`calib_jax.batch.BatchResult.stderr_normalised`)."""
    se_n = np.asarray(se_n, float)
    return [n for n, e in zip(PARAM_NAMES[model], se_n, strict=True) if not e <= POOR_STDERR]


# coverage: smallest eigenvalue of the direction scatter (1/3 for a uniform sphere, 0 for a
# circle in one plane); below FLAT the shape along the normal is unobservable
FLAT = 0.01
# the same judged on the samples themselves (smallest / largest eigenvalue of their covariance):
# a sphere fit through a circle puts its centre anywhere along the normal, and about such a
# centre a noisy circle's directions look like a cone (uBot's robot turning on the floor:
# 0.0022 here, a 17-degree cap about 0.005)
FLAT_POINTS = 0.005
# plausibility of the RMS radial error after the fit (percent of the field), from real logs:
# clean magnetometer tumbles reach 0.5-2 % (CK-Explorer 1.26 %, BROAD 1.5-1.9 %), the noisy
# QMC5883L log 6.2 % (all of it sample-to-sample noise: 5.6 %), BROAD trial 34 with a magnet
# attached for part of the log 7.6 % (sample-to-sample noise 0.4 %, ratio 19; clean logs 1-4,
# all of them below RMS_PLAUSIBLE_PCT). Above RMS_PLAUSIBLE_PCT a residual that the
# sample-to-sample scatter does not explain (more than NOISE_RATIO times it: three quarters of
# its variance or more is slow structure) means the data are not one ellipsoid:
# "poorly_determined". At 6 (the clean logs' ratios, which never reach this test) a FreeIMU
# HMC5883L log whose hard iron moved during the recording (10.3 %, ratio 3.4) and a PX4 flight
# whose |m| stepped (11.5 %, ratio 3.0) were "ok" without a word
RMS_PLAUSIBLE_PCT = 5.0
NOISE_RATIO = 2.0
# above this no ellipsoid describes the data (a noise cloud 28-39 %, a hyperboloid 28-46 %,
# a hard iron jumping by 2/3 of the field 15 %): "failed"
RMS_NO_SHELL_PCT = 100 * NO_SHELL
# largest / smallest semi-axis: soft iron this strong is not a magnetometer (QMC5883L 2.2,
# the strongest of the real logs; others 1.03-1.4)
AXES_RATIO = 4.0
# data whose squares overflow or underflow float64 (the ellipsoid matrix is 1 / radius^2)
EXTREME = 1e100
MOMENT_FORM_ABOVE = 1 << 20
"""Logs with more samples than this are fitted through their 10 x 10 moment matrix, the batch's
form of the same chi2 (:mod:`calib_jax.batch`): memory independent of the log's length. Below,
the LM keeps a residual and a Jacobian row per sample (about 1 kB each per model)."""


# ---------------------------------------------------------------------------------------------
# pure core


def ellipsoid_start(x: jax.Array, w: jax.Array, model: str) -> jax.Array:
    """Start for the normalised fit: the constrained algebraic ellipsoid (full), or the
    algebraic sphere (sphere, diag; and full when the algebraic fit fails)."""
    return ellipsoid_start_moments(moments(x, w), model)


def ellipsoid_start_moments(S: jax.Array, model: str) -> jax.Array:
    """:func:`ellipsoid_start` from the moment matrix of the (normalised) samples."""
    cs, r = sphere_fit_moments(S)
    eye = jnp.eye(3, dtype=S.dtype)
    p_sph = pack(cs, eye / (r * r), model)
    if model != "full":
        return p_sph
    c, M, ok = ellipsoid_fit_constrained_moments(S)
    p_ell = pack(c, jnp.where(ok, M, eye), "full")
    return jnp.where(ok & jnp.all(jnp.isfinite(p_ell)), p_ell, p_sph)


def fit_ellipsoid_normalized(
    x: jax.Array,
    w: jax.Array,
    model: str = "full",
    solver: str = "lm1",
    implicit: bool = False,
    **options,
) -> LMResult:
    """Pure core: fit the quadric residual to unit-scale data x (N, 3) with weights w (N,).

    The one ellipsoid fit: :func:`calibrate_mag` calls it on normalised samples,
    :func:`calib_jax.pipeline.fit_mag` with ``implicit=True`` (then ``params`` are
    differentiable in x and w by the implicit function theorem,
    :func:`calib_jax.implicit.solve_implicit`; LM solvers only). Jittable and vmappable over
    sensors; ``model``, ``solver``, ``implicit`` and ``options`` are static. Returns the
    LMResult of the packed parameters (see :mod:`calib_jax.models.mag`).
    """
    p0 = ellipsoid_start(x, w, model)

    def residual(p, data):
        return quadric_residual(p, data[0], model)

    if solver == "optimistix":
        if implicit:
            raise ValueError("implicit=True needs an LM solver (lm1, lm2, lm3)")
        from .lm.optx import optx_solve

        return optx_solve(residual, p0, (x, w), weights=w, **options)
    update_type = {"lm1": 1, "lm2": 2, "lm3": 3}[solver]
    if implicit:
        p, res = solve_implicit(
            residual, p0, (x, w), weights=lambda d: d[1], update_type=update_type, **options
        )
        return eqx.tree_at(lambda r: r.params, res, p)
    return lm_solve(residual, p0, (x, w), weights=w, update_type=update_type, **options)


def _fit_measured(x, w, *, solver: str, model: str, **options):
    """The fit and what the host asks of it: centre, M, each sample's relative radial error
    and the natural radius (computed here: eagerly they were dozens of dispatches per model)."""
    res = fit_ellipsoid_normalized(x, w, solver=solver, model=model, **options)
    c, M = unpack(res.params, model)
    return res, c, M, radial_error(c, M, x), natural_radius(M)


@functools.lru_cache(maxsize=64)
def _compiled(solver: str, model: str, options: tuple, budgeted: bool, moments: bool = False):
    """The compiled fit of padded samples (x, w), or of their moments (S) with ``moments``;
    ``budgeted``: the iteration budget is its last argument (:func:`calib_jax.lm.budget_apart`)."""
    fit, what = (
        (_fit_from_moments, "fit_from_moments") if moments else (_fit_measured, "fit_measured")
    )
    return budgeted_disk_jit(
        functools.partial(fit, solver=solver, model=model),
        f"mag.{what} {solver} {model} {options!r}",
        options,
        budgeted,
    )


def _fit_program(solver: str, model: str, options: tuple, moments: bool = False):
    key, budget = budget_apart(solver, options)
    return with_budget(_compiled(solver, model, key, budget is not None, moments), budget)


@functools.lru_cache(maxsize=8)
def _raw_calibration(model: str):
    """Jitted (c, W, covariance of [c, ravel W]) from a normalised fit (see
    :func:`calib_jax.models.mag.raw_calibration`)."""

    def f(p, cov, mean, scale, field):
        c, W = raw_calibration(p, model, mean, scale, field)
        return c, W, raw_covariance(p, cov, model, mean, scale, field)

    return disk_jit(f, f"mag.raw_calibration {model}")


# ---------------------------------------------------------------------------------------------
# host side


def _vec(v: np.ndarray) -> str:
    return "[" + ", ".join(f"{x:+.2f}" for x in v) + "]"


def _spread(x: np.ndarray) -> tuple[np.ndarray, float]:
    """Mean and RMS distance from it; a ValueError when float64 cannot resolve the spread."""
    mean = x.mean(axis=0)
    # centred squares in chunks: a long log's (N, 3) temporaries were 0.3 GB each
    step = MOMENT_FORM_ABOVE
    ss = sum(float(np.sum((x[i : i + step] - mean) ** 2)) for i in range(0, len(x), step))
    s = float(np.sqrt(ss / len(x)))
    if np.all(x == x[0]):
        raise ValueError("all samples are identical: the sensor did not move or is stuck")
    if not s >= 1e-9 * float(np.max(np.abs(mean))) or not s > 1 / EXTREME:
        centre = ", ".join(f"{v:.3g}" for v in mean)
        raise ValueError(
            f"the samples vary by only {s:.3g} around [{centre}]: too little for float64 to "
            "resolve an ellipsoid (values below 1e-100, or an offset 1e9 times the spread); "
            "the sensor did not move, or rescale the data or subtract the offset first"
        )
    return mean, s


def _fit(xn: np.ndarray, model: str, solver: str, opts: tuple):
    """(LMResult, centre, M, relative radial errors (N,), natural radius) of the normalised
    samples, centre and M as numpy. Above MOMENT_FORM_ABOVE samples, from their moments."""
    if len(xn) > MOMENT_FORM_ABOVE:
        S = moments_of(xn)
        res, c, M, radius = _fit_program(solver, model, opts, moments=True)(S)
        c, M = np.asarray(c), np.asarray(M)
        return res, c, M, radial_error(c, M, xn, xp=np), float(radius)
    xpad, wpad = pad_rows(xn)
    res, c, M, rel, radius = _fit_program(solver, model, opts)(xpad, wpad)
    return res, np.asarray(c), np.asarray(M), np.asarray(rel)[: len(xn)], float(radius)


def moments_of(x: np.ndarray, chunk: int = MOMENT_FORM_ABOVE) -> np.ndarray:
    """geometry.moments of host samples (N, 3), equal weights, summed over chunks of a fixed
    size (one compilation; the last chunk padded with weight 0): memory of one chunk."""
    S = np.zeros((10, 10))
    for i in range(0, len(x), chunk):
        S += np.asarray(_MOMENTS(*pad_rows(x[i : i + chunk], chunk)))
    return S


_MOMENTS = disk_jit(moments, "geometry.moments")


def _fit_from_moments(S, *, solver: str, model: str, **options):
    """:func:`_fit_measured` from the moment matrix: the batch's solve of the same chi2
    (residual L' theta(p) with L L' = S), without the per-sample radial errors."""
    from .batch import _solve, mag_theta

    p0 = ellipsoid_start_moments(S, model)
    dof = S[9, 9] - N_PARAMS[model]
    res = _solve(lambda p: mag_theta(p, model), p0, S, dof, solver, options)
    c, M = unpack(res.params, model)
    return res, c, M, natural_radius(M)


HONEST_MIN_BLOCK = 50
"""Samples a jackknife block needs at the least (fewer: no honest errors, NaN)."""


class HonestErrors(NamedTuple):
    """Block-jackknife standard errors of a magnetometer fit (:func:`honest_stderr`)."""

    center: np.ndarray
    """(3,) the centre's, raw units."""
    soft_iron: np.ndarray
    """(3, 3) W's, output units per raw unit."""
    normalised: np.ndarray
    """The packed parameters' (units of the data's radius), as :func:`poorly_determined`
    reads them."""


def honest_stderr(
    xn: np.ndarray,
    model: str,
    solver: str,
    opts: tuple,
    mean: np.ndarray,
    scale: float,
    field: float | None,
) -> HonestErrors:
    """Standard errors of the centre, W and the packed parameters from a block jackknife over
    :data:`calib_jax.align.JACKKNIFE_BLOCKS` contiguous stretches of the normalised samples
    ``xn`` in time order (issue 15): honest where the samples are correlated, as a tumble's
    are, where the formal errors assume independent samples.

    Each refit leaves one stretch out of the moment matrix (the batch's form of the same chi2:
    the stretch's moments subtracted, one compiled fit for all). NaN when a stretch is shorter
    than :data:`HONEST_MIN_BLOCK` samples or a refit does not converge to a finite W."""
    from .align import JACKKNIFE_BLOCKS, block_jackknife_cov

    k = JACKKNIFE_BLOCKS
    nan = HonestErrors(
        np.full(3, np.nan), np.full((3, 3), np.nan), np.full(N_PARAMS[model], np.nan)
    )
    if len(xn) < k * HONEST_MIN_BLOCK:
        return nan
    edges = np.linspace(0, len(xn), k + 1).astype(int)
    blocks = [xn[a:b] for a, b in zip(edges[:-1], edges[1:], strict=True)]
    chunk = min(MOMENT_FORM_ABOVE, 1 << int(np.ceil(np.log2(max(map(len, blocks))))))
    S_blocks = [moments_of(b, chunk) for b in blocks]
    S_all = sum(S_blocks)
    fit = _fit_program(solver, model, opts, moments=True)
    raw = _raw_calibration(model)
    estimates = []
    for S_b in S_blocks:
        res, _, _, _ = fit(S_all - S_b)
        c, W, _ = raw(res.params, res.covariance, mean, scale, np.nan if field is None else field)
        c, W = np.asarray(c), np.asarray(W)
        if not (is_converged(int(res.status)) and np.all(np.isfinite(W))):
            return nan
        estimates.append(np.concatenate([c, W.ravel(), np.asarray(res.params)]))
    se = np.sqrt(np.clip(np.diag(block_jackknife_cov(np.array(estimates))), 0.0, None))
    return HonestErrors(se[:3], se[3:12].reshape(3, 3), se[12:])


def _input_vectors(data, sensor: str) -> tuple[np.ndarray, str | None, list[str], str | None]:
    """(N, 3) float vectors, the source path, the loader's notes and the unit the column
    names state (None: not stated), from an array, a log or a file."""
    data = as_log(data, sensor)
    if not isinstance(data, SensorLog):
        x = np.asarray(data, float)
        source, notes, unit = None, [], None
    else:
        x, source, notes = data.vectors(sensor), data.path, list(data.notes)
        unit = data.units.get(sensor)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"{sensor} data must be (samples, 3), got shape {x.shape}")
    return x, source, notes, unit


def _check_options(model: str, solver: str, field: float | None) -> None:
    if model not in (*MAG_MODELS, "auto"):
        raise ValueError(f"model must be one of sphere, diag, full, auto; got {model!r}")
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
    if field is not None and not (np.isfinite(field) and field > 0):
        raise ValueError(f"field must be a positive magnitude, got {field!r}")
    if jax.dtypes.canonicalize_dtype(np.float64) != np.float64:  # (no eager program)
        _warnings.warn(
            "jax_enable_x64 is off: fitting in float32 loses ~1e-7 relative accuracy; call "
            "jax.config.update('jax_enable_x64', True) first",
            stacklevel=3,
        )


def _screened(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, list[str]]:
    """The samples to fit (finite, off a saturated axis), their mean and RMS spread, and the
    warnings about what was left out; a ValueError for data no ellipsoid can be fitted to."""
    finite = np.all(np.isfinite(x), axis=1)
    if finite.sum() < 20:
        raise ValueError(
            f"only {int(finite.sum())} finite samples; an ellipsoid needs many more (record a "
            "slow tumble through all orientations, a few hundred samples at least)"
        )
    xf = x if finite.all() else x[finite]  # no copy of a clean log
    if max(float(xf.max()), -float(xf.min())) > EXTREME:
        big = np.max(np.abs(xf), axis=1)
        k = int(np.flatnonzero(finite)[np.argmax(big)])
        raise ValueError(
            f"sample {k} holds {big.max():.3g}: values beyond {EXTREME:.0e} cannot be fitted in "
            "float64 (the ellipsoid matrix is 1 / radius^2); convert the data to a physical "
            "unit, or drop the corrupt rows"
        )
    _spread(xf)  # all samples identical (a stuck sensor) is that error, not saturation
    valid, warn = screen_samples(x, "mag")
    xv = x if valid.all() else x[valid]
    if len(xv) < 20:
        raise ValueError(f"only {len(xv)} unsaturated finite samples; record within range")
    mean, s = _spread(xv)
    return xv, mean, s, warn


BARELY_TURNED = 3.0
"""A log whose RMS spread is within this many times its sample-to-sample noise was hardly
turned (a tumble spreads by hundreds of times its noise). Samples out of time order look the
same to this test, so it refuses only a fit that runs away or leaves a residual no shell
explains, of samples far from zero next to their spread (one field plus noise; a shuffled cap
of a tumble lies on its shell, a cloud about zero is no field held). It once also asked for a
poorly determined fit: 103,939 samples of a board lying still (an MPU-9250's log, spread 7.3
counts about a field of 226) determined a sphere of radius 8 through their noise well, and the
user read "100 % of the sphere covered" and advice about columns, units and saturation."""


def _barely_turned(xv: np.ndarray, spread: float) -> bool:
    """Whether the samples spread by no more than :data:`BARELY_TURNED` times their noise,
    estimated from consecutive differences (rows that repeat the row before, a reading held
    over a faster clock, left out)."""
    d = np.diff(xv, axis=0)
    d = d[np.any(d != 0, axis=1)]
    if len(d) < 10:
        return True  # nothing but held readings: the field never changed
    noise = float(np.sqrt(np.sum((1.4826 * np.median(np.abs(d), axis=0) / np.sqrt(2)) ** 2)))
    return spread <= BARELY_TURNED * noise


def _relative(norms: np.ndarray, reference: float) -> np.ndarray:
    """norms / reference - 1, in place (a 3-hour 1 kHz log: 86 MB an array): the relative
    radial errors of calibrate_mag and judge_fit."""
    norms /= reference
    norms -= 1.0
    return norms


def _rms_pct(e: np.ndarray) -> float:
    """100 sqrt(mean(e^2)) of a relative error, without an e^2 temporary."""
    return float(100 * np.sqrt(np.dot(e, e) / len(e))) if len(e) else float("nan")


def _norms(v: np.ndarray) -> np.ndarray:
    """Row norms of v (N, 3) without an (N, 3) temporary (np.linalg.norm squares into one)."""
    return np.sqrt(np.einsum("ij,ij->i", v, v))


def _check_not_flat(
    xn: np.ndarray, xv: np.ndarray, mean: np.ndarray, s: float, what: str = "field"
) -> None:
    """A ValueError when the normalised samples' directions lie in one plane (``xv``, their
    mean and spread ``s``: the samples as read, to tell a sensor that hardly moved; ``what``
    the vector measured, "field" or "gravity", for the message)."""
    evals, evecs = np.linalg.eigh(np.cov(xn[:: max(1, len(xn) // 100_000)].T))
    normal = evecs[:, 0] if evals[0] < FLAT_POINTS * evals[2] else None
    if normal is None:
        if len(xn) > MOMENT_FORM_ABOVE:
            cs = np.asarray(sphere_fit_moments(jnp.asarray(moments_of(xn)))[0])
        else:
            cs, _ = sphere_fit_points(xn)
        _, min_eig, unseen = coverage_about(xn, cs, cells=None)
        normal = unseen if min_eig < FLAT else None
    if normal is None:
        return
    if np.linalg.norm(mean) > 3 * s and _barely_turned(xv, s):
        raise ValueError(
            f"the {what} barely changes in the sensor frame: the samples spread by {s:.3g} "
            f"(RMS) about {_vec(mean)}, within {BARELY_TURNED:g}x of their sample-to-sample "
            "noise: the sensor was hardly turned. Record a slow tumble through all orientations"
        )
    raise ValueError(_one_plane(normal, what))


NORMALISED = 1e-4
"""Samples whose lengths about zero agree within this (relative RMS) were normalised, or
calibrated, before they were logged: no sensor's raw readings are that steady (a magnetometer's
noise alone is 0.1 % or more)."""


def _check_not_normalised(xv: np.ndarray) -> None:
    """A ValueError for readings that are unit vectors or already calibrated: their lengths
    are constant, so the fit returns the identity (cubesat-adcs' MPU9250 log, 1.000002 +-
    2.9e-5: 'after 0.003 %' with W = I and no word of why)."""
    n = _norms(xv[:: max(1, len(xv) // 100_000)])
    med = float(np.median(n))
    spread = float(np.sqrt(np.mean((n / med - 1.0) ** 2))) if med > 0 else np.inf
    if spread < NORMALISED:
        raise ValueError(
            f"every sample's length is {med:.6g} within {spread:.1g} (relative RMS): the "
            "readings were normalised (unit vectors) or calibrated before they were logged, so "
            "they hold no offset or gain to find. Log the sensor's raw readings"
        )


def _one_plane(normal: np.ndarray, what: str = "field") -> str:
    return (
        f"the {what} directions lie in one plane (normal {_vec(normal)} in the sensor frame): "
        "this looks like a turn about a single axis, which cannot determine an ellipsoid. "
        "Tumble the sensor through all orientations; a one-axis turn is what the plane "
        "alignment (calib_jax.align.plane_alignment) needs instead"
    )


def _fit_candidates(xn, model, solver, opts, warn) -> tuple[dict, str, dict]:
    """Fit every candidate model and choose one: (fits, chosen, the selection table).

    fits: model -> (result, c_n, M_n, mean square radial error in units of s, BIC, mean square
    relative radial error |W (x - c)| / r - 1). ``model="auto"`` takes the lowest BIC among
    the fits that converged to a bounded, well-determined ellipsoid; when none is well
    determined, the sphere (the lowest BIC of the bounded fits if the sphere is not one), with
    a warning in ``warn``."""
    candidates = MAG_MODELS if model == "auto" else (model,)
    n = len(xn)
    fits: dict[str, tuple[LMResult, np.ndarray, np.ndarray, float, float, float]] = {}
    for m in candidates:
        res, c_n, M_n, rel, radius = _fit(xn, m, solver, opts)
        # the BIC's radial error is in units of s, not relative to the fitted radius (which a
        # misfitting model lowers by growing: see quadric_residual)
        ms = float(np.mean((rel * radius) ** 2))
        bic = n * np.log(max(ms, 1e-300)) + N_PARAMS[m] * np.log(n)
        fits[m] = (res, c_n, M_n, ms, bic, float(np.mean(rel**2)))
    usable = {
        m: f
        for m, f in fits.items()
        if is_converged(int(f[0].status)) and natural_radius(f[2], np) < RUNAWAY
    }
    # prefer models whose parameters the data pin down: on partial coverage a full ellipsoid
    # can win the BIC by fitting directions it has not seen (BROAD trial 02, first half: full
    # 21 deg median heading error held out, sphere 6.9 deg)
    determined = {m: f for m, f in usable.items() if np.all(np.asarray(f[0].stderr) <= POOR_STDERR)}
    # rms_pct: the RMS of |W (x - c)| / r - 1 in percent, what the chosen model reports as
    # rms_after_pct
    selection = {
        m: {
            "bic": f[4],
            "rms_pct": 100 * np.sqrt(f[5]),
            "usable": m in usable,
            "well_determined": m in determined,
        }
        for m, f in fits.items()
    }
    if model != "auto":
        return fits, model, selection
    # the lowest BIC among the well-determined fits; when none is, the sphere, the fewest
    # parameters (on a third of the sphere, scikit-kinematics' YEI log, the lowest BIC was a
    # diagonal soft iron with one semi-axis 3.4x shorter than the others, saved with exit 0),
    # unless the sphere itself did not converge to a bounded fit: then the lowest BIC of those
    # that did; none at all, the sphere
    if determined:
        return fits, min(determined, key=lambda m: determined[m][4]), selection
    if not usable:
        return fits, "sphere", selection
    best = min(usable, key=lambda m: usable[m][4])
    if "sphere" not in usable:
        warn.append("no candidate model is well determined by these data")
        return fits, best, selection
    warn.append(
        "no candidate model is well determined by these data: the sphere (hard iron only) is kept"
        + (
            f"; {best} had the lowest BIC (rms {selection[best]['rms_pct']:.3g} % against "
            f"{selection['sphere']['rms_pct']:.3g} %), but its soft iron is not pinned down; "
            "record more orientations, or declare it (model=..., --model)"
            if best != "sphere"
            else ""
        )
    )
    return fits, "sphere", selection


def calibrate_mag(
    data: np.ndarray | SensorLog | str | os.PathLike,
    *,
    model: MagModel = "auto",
    field: float | None = None,
    units: str | None = None,
    sensor: Literal["mag", "accel"] = "mag",
    solver: str = "lm1",
    solver_options: dict | None = None,
    sensor_id: str | None = None,
) -> MagCalibration:
    """Fit an ellipsoid to a free-rotation log and map it onto a sphere (paper 2, 2.2).

    Parameters
    ----------
    data : (N, 3) array, SensorLog or path
        Raw vectors (any unit), a loaded log or a log file (its ``mag`` columns, or ``acc`` with
        ``sensor="accel"``). Rotate the sensor through as many orientations as possible.
    model : {"auto", "sphere", "diag", "full"}
        Hard iron only (centre and radius), an axis-aligned ellipsoid, a full ellipsoid, or
        the lowest-BIC of the three.
    field : float, optional
        Known magnitude of the field (e.g. 44.3 uT, or 1 g): the calibrated output then has
        this magnitude, in its units. Default: det(W) = 1 and output in raw units.
    units : str, optional
        Label for the raw units (reported only).
    solver : {"lm1", "lm2", "lm3", "optimistix"}
    solver_options : dict, optional
        Passed to the solver.

    Returns
    -------
    MagCalibration
        ``apply(raw)`` gives W (raw - c); ``status`` says whether to trust it: "ok";
        "poorly_determined" (converged, but a parameter is poorly pinned down, the residual
        is implausibly large for a magnetometer and not explained by the sample-to-sample
        noise, or the semi-axes differ by more than 4x); "not_converged"; "failed" (nothing
        usable, including data that lie on no ellipsoid shell: RMS radial error above 12 %).
        ``warnings`` give the cause and what to do. Axes saturated at their extreme value
        are left out of the fit, with a warning.

    Raises
    ------
    ValueError
        With what to change: wrong shape, fewer than 20 finite samples, all directions in one
        plane (a turn about a single axis), an unknown model or solver, a bad field value,
        values float64 cannot fit (beyond 1e100, or a spread below 1e-100 or 1e-9 of the
        offset).
    """
    x, source, notes, stated_unit = _input_vectors(data, sensor)
    units = units or stated_unit  # the header's 'X (µT)' labels the report, as --units does
    _check_options(model, solver, field)
    xv, mean, s, warn = _screened(x)
    xn = xv - mean
    xn /= s  # in place: a 3-hour 1 kHz log's samples are 260 MB a copy
    _check_not_flat(xn, xv, mean, s, "gravity" if sensor == "accel" else "field")
    _check_not_normalised(xv)
    opts = checked_solver_options(solver, solver_options)
    fits, chosen, selection = _fit_candidates(xn, model, solver, opts, warn)
    res, c_n, M_n = fits[chosen][:3]

    M = M_n / s**2
    c, W, cov_cw = _raw_calibration(chosen)(
        res.params, res.covariance, mean, s, np.nan if field is None else float(field)
    )
    centre, W = np.asarray(c), np.asarray(W)
    radius = float(field) if field is not None else float(natural_radius(M, np))
    semi_axes, R = ellipsoid_axes(M)  # NaN for a failed solve or a non-ellipsoid

    # standard errors of the returned centre (raw units) and W (output units per raw unit)
    se = np.sqrt(np.clip(np.diag(np.asarray(cov_cw)), 0.0, None))
    stderr_center = se[:3]
    stderr_soft_iron = se[3:].reshape(3, 3)
    honest = honest_stderr(xn, chosen, solver, opts, mean, s, field)
    # the status reads the larger of the formal and the honest errors (NaN: not measured)
    se_n = np.fmax(np.asarray(res.stderr, float), honest.normalised)

    solver_status = int(res.status)
    runaway = not float(natural_radius(M_n, np)) < RUNAWAY
    if runaway:
        r_fit = float(natural_radius(M, np))
        warn.append(
            f"the {chosen} ellipsoid ran away (mean radius {r_fit:.4g} against a data radius "
            f"of {s:.4g}): the data cover too little of the sphere for "
            + (
                "any ellipsoid; record a slow tumble through all orientations"
                if chosen == "sphere"
                else "this model; fit a sphere (--model sphere, model='sphere') or record "
                "more orientations"
            )
        )
    status = fit_status(solver_status, bool(np.all(np.isfinite(W))) and not runaway)
    poor = poorly_determined(se_n, chosen)
    if status == "ok" and poor:
        status = "poorly_determined"
        warn.append(POORLY_DETERMINED.format(", ".join(poor)))
        formal_poor = poorly_determined(res.stderr, chosen)
        if len(formal_poor) < len(poor):
            warn[-1] += (
                f" ({', '.join(p for p in poor if p not in formal_poor)} by the block "
                "jackknife's errors: the formal ones, which take the samples as independent, "
                "are smaller)"
            )

    frac, ny = _calibrated_coverage(xv, centre, W, status, warn)
    # relative radial errors, each made in place from its norms (a 3-hour 1 kHz log: 86 MB
    # an array; the peak memory of `calib-jax mag` was here and in _plausibility)
    before = _norms(xn)  # |x - mean| / s: the scale cancels below, and no (N, 3) temporary
    before = _relative(before, before.mean())
    raw_err = _norms(xv)
    raw_err = _relative(raw_err, raw_err.mean())
    after = _relative(ny, radius)
    rms_after = _rms_pct(after)

    if (
        # off any shell (a ball of noise), or a shell that ran away to pass through the ball
        (runaway or not rms_after <= RMS_PLAUSIBLE_PCT)
        and np.linalg.norm(mean) > 3 * s  # about a field far from zero: one field held
        and _barely_turned(xv, s)
    ):
        # nor a coverage: directions about a 'centre' that is the field say nothing
        warn[:] = [w for w in warn if "ran away" not in w and "sphere of directions" not in w]
        what = "gravity" if sensor == "accel" else "the field"
        warn.append(
            f"{what} barely changes in the sensor frame: the samples spread by {s:.3g} "
            f"(RMS), within {BARELY_TURNED:g}x of their sample-to-sample noise, and "
            + (
                "the only shell through them runs away, far larger than the data"
                if runaway
                else f"lie on no shell (RMS radial error {rms_after:.3g} % after the fit)"
            )
            + ": the sensor was hardly "
            f"turned and this is no calibration (the 'centre' is {what} itself). Record a "
            "slow tumble through all orientations"
        )
        status = "failed"
        frac = float("nan")  # directions about a 'centre' that is the field: no coverage

    def full_rms() -> float:
        """RMS radial error (percent of the data radius) of the full ellipsoid: whether the
        data lie on an ellipsoid shell at all, whatever model was asked for."""
        if "full" not in fits:
            res_f, c_f, M_f, rel_f, radius_f = _fit(xn, "full", solver, opts)
            fits["full"] = (res_f, c_f, M_f, float(np.mean((rel_f * radius_f) ** 2)), 0, 0)
        return float(100 * np.sqrt(fits["full"][3]))

    full_determined = selection.get("full", {}).get("well_determined", True)
    status = _plausibility(
        status, chosen, rms_after, full_rms, before, after, semi_axes, sensor, warn,
        full_determined,
    )  # fmt: skip
    cal = MagCalibration(
        center=centre,
        soft_iron=W,
        radius=radius,
        model=chosen,
        status=status,
        rms_before_pct=_rms_pct(before),
        rms_after_pct=rms_after,
        rms_raw_pct=_rms_pct(raw_err),
        semi_axes=semi_axes,
        dcm=R,
        stderr_center=stderr_center,
        stderr_soft_iron=stderr_soft_iron,
        stderr_center_honest=honest.center,
        stderr_soft_iron_honest=honest.soft_iron,
        condition=float(res.condition),
        solver=solver,
        solver_status=solver_status,
        solver_message=status_message(solver_status, refused=status == "failed" and bool(warn)),
        iterations=int(res.iterations),
        n_samples=int(len(xv)),
        coverage=float(frac),
        field=None if field is None else float(field),
        units=units,
        sensor=sensor,
        model_selection=selection,
        poorly_determined=poor,
        warnings=warn,
        notes=notes,
        sensor_id=sensor_id,
        source=source,
    )
    if status in ("failed", "not_converged"):
        cause = cal.solver_message
        if is_converged(solver_status) and warn:
            cause = warn[-1]  # converged, but the data are not an ellipsoid
        _warnings.warn(f"ellipsoid calibration {status}: {cause}", FitStatusWarning, stacklevel=2)
    return cal


def _calibrated_coverage(
    x: np.ndarray, centre: np.ndarray, W: np.ndarray, status: str, warn: list[str]
) -> tuple[float, np.ndarray]:
    """(the share of the sphere of directions the calibrated samples cover, their norms |y|),
    y = W (x - c); below half, unless the fit failed anyway, a warning in ``warn``. Taken on
    the calibrated sphere: directions about a sphere fitted to distorted data overstate it."""
    ny = np.empty(len(x))  # W (x - c) chunk by chunk (x W^T - c W^T would cancel)
    frac, _, unseen = coverage_about(x, centre, W, norms_out=ny)
    if frac < 0.5 and status != "failed":
        warn.append(
            f"the data cover {100 * frac:.0f} % of the sphere of directions (least seen axis "
            f"{_vec(unseen)}): the shape is poorly determined there; tumble through more "
            "orientations"
        )
    return float(frac), ny


def judge_fit(
    x: np.ndarray, centre: np.ndarray, W: np.ndarray, status: str, model: str, radius: float
) -> tuple[str, list[str]]:
    """The single fit's checks on a fit made elsewhere (a batch entry): the coverage of the
    calibrated sphere and :func:`_plausibility` (a shell no ellipsoid describes, an implausible
    residual, a non-ellipsoid or extreme semi-axes). Returns the status and the warnings."""
    warn: list[str] = []
    _, ny = _calibrated_coverage(x, centre, W, status, warn)
    before = _norms(x - x.mean(axis=0))
    before = _relative(before, before.mean())
    after = _relative(ny, radius)
    rms_after = _rms_pct(after)
    semi_axes, _ = ellipsoid_axes(W.T @ W / radius**2)
    status = _plausibility(
        status, model, rms_after, lambda: rms_after, before, after, semi_axes, "mag", warn
    )
    return status, warn


def _plausibility(
    status: str,
    model: str,
    rms_after: float,
    full_rms,
    before: np.ndarray,
    after: np.ndarray,
    semi_axes: np.ndarray,
    sensor: str,
    warn: list[str],
    full_determined: bool = True,
) -> str:
    """Downgrade a converged fit that no magnetometer ellipsoid explains (see the limits at the
    top of the module); appends the cause and the remedy to ``warn``. ``full_determined``:
    whether the data pin the full ellipsoid down (model='auto' passed it over if not: then
    more orientations, not model='full', is the remedy)."""
    if not is_usable(status):
        return status
    what = "magnetometer" if sensor == "mag" else "sensor"
    rms_before = _rms_pct(before)
    # sample-to-sample scatter of the calibrated norm: the noise (in time order)
    d = np.diff(after)
    np.abs(d, out=d)
    noise = float(100 * 1.4826 * np.median(d, overwrite_input=True) / np.sqrt(2)) if len(d) else 0.0
    implausible = rms_after > RMS_PLAUSIBLE_PCT and rms_after > NOISE_RATIO * noise
    if not (np.isfinite(rms_after) and rms_after <= RMS_NO_SHELL_PCT) or implausible:
        best = rms_after if model == "full" else full_rms()
        if not best <= RMS_NO_SHELL_PCT:
            warn.append(
                f"the samples do not lie on an ellipsoid shell: RMS radial error {best:.3g} % "
                f"after the full ellipsoid fit ({rms_before:.3g} % before), where a {what} "
                f"tumble reaches 0.5-2 % (above {RMS_NO_SHELL_PCT:g} % no ellipsoid describes "
                "the data). Check the column mapping and units, that the field did not change "
                "during the recording (a magnet or iron moving with the sensor, a hard iron "
                "that jumped), and that the sensor was not saturated; then record a new "
                "tumble. Do not use this calibration"
            )
            return "failed"
        if model != "full" and (best <= RMS_PLAUSIBLE_PCT or best <= 0.5 * rms_after):
            remedy = (
                "model='full' (or 'auto', --model full)"
                if full_determined
                else "a full ellipsoid, which these data do not determine: tumble through "
                "more orientations"
            )
            warn.append(
                f"the {model} model leaves an RMS radial error of {rms_after:.3g} % of its "
                f"radius where a full ellipsoid leaves {best:.3g} % of the data's spread: "
                f"this {what}'s soft iron needs {remedy}"
            )
            return "poorly_determined"
        warn.append(
            f"implausible residual: RMS radial error {rms_after:.3g} % after the fit, where a "
            f"clean {what} tumble reaches 0.5-2 %, and the sample-to-sample noise explains only "
            f"{noise:.2g} %: the field or the hard iron probably changed during the recording "
            "(a magnet or iron object moved with the sensor, a motor or current switched, the "
            "sensor was re-mounted). Record again away from them, or fit the undisturbed "
            "segments separately"
        )
        status = "poorly_determined"
    if not np.all(np.isfinite(semi_axes)):
        warn.append(
            "the fitted quadric is not an ellipsoid (an axis with a non-positive eigenvalue): "
            "the data do not lie on an ellipsoid shell; do not use this calibration"
        )
        return "failed"
    ratio = float(np.max(semi_axes) / np.min(semi_axes))
    if not ratio <= AXES_RATIO:
        warn.append(
            f"the ellipsoid's semi-axes differ by a factor {ratio:.3g} (above {AXES_RATIO:g}; "
            f"{_vec(semi_axes)}): soft iron this strong is implausible for a {what}; the data "
            "probably do not lie on one ellipsoid (a changing field, wrong columns) or cover "
            "too little of it"
        )
        status = "poorly_determined"
    return status
