"""Status codes of the least-squares solvers and the status words of the calibration records.

Inside ``jit`` a solver never raises: it returns one of these integers. The host side turns
them into messages (:func:`status_message`) and, where the user asked for it, exceptions.
"""

from __future__ import annotations

import enum


class Status(enum.IntEnum):
    """Why a least-squares solve stopped."""

    CONVERGED_GRADIENT = 0
    """max |J'W e| < eps1 (LM_SPEC convergence test 1)."""
    CONVERGED_PARAMETERS = 1
    """max |h_i| / (|p_i| + tiny) < eps2 (test 2)."""
    CONVERGED_CHI2 = 2
    """chi2 / (m - n) < eps3 (test 3, an absolute threshold)."""
    MAX_ITERATIONS = 3
    """The iteration or function-evaluation budget ran out before any test was met."""
    NONFINITE = 4
    """The residual is NaN or inf at the starting point; nothing was fitted."""
    SINGULAR = 5
    """The damped normal equations could not be solved even at the largest lambda."""
    CONVERGED = 6
    """An external solver (optimistix) met its own rtol/atol criteria."""
    FAILED = 7
    """An external solver reported a failure other than the budget."""
    CONVERGED_ROUNDOFF = 8
    """A step was rejected because neither the actual nor the predicted change of chi2 rose
    above round-off (4 eps (sqrt(m) chi2 + 2 sum w|e|s), s the size of the terms each
    residual is computed from; see calib_jax.lm.gavin): the fit is at the optimum to machine
    precision, though the absolute tests 1-3 did not trigger (typical with many samples,
    where the gradient at the optimum is dominated by round-off)."""
    INSUFFICIENT_DATA = 9
    """Batch and pipeline fits: too few valid samples for the model (checked inside jit;
    nothing fitted)."""
    NO_COVERAGE = 10
    """Batch and pipeline fits: the valid samples lie in one plane of directions; nothing
    fitted."""
    NO_SHELL = 11
    """Batch and pipeline fits: fitted, but the RMS radial error is above
    :data:`calib_jax.geometry.NO_SHELL`: the samples lie on no ellipsoid shell (a sensor held
    still, motion, a field that changed); no calibration."""
    RAN_AWAY = 12
    """Batch and pipeline fits: fitted, but the ellipsoid is over
    :data:`calib_jax.geometry.RUNAWAY` times the samples' spread: a cap of data too small
    (one pose held still) lets any large ellipsoid through; no calibration."""
    NOT_AT_REST = 13
    """Accelerometer batch and pipeline fits: fitted, but the points leave more than
    :data:`calib_jax.accel.REST_FAIL` of g after the fit: they include motion (a whole log
    given where its static samples were meant); no calibration."""


NO_CALIBRATION = (Status.NO_SHELL, Status.RAN_AWAY, Status.NOT_AT_REST)
"""Fitted, then refused by the batch's and the pipeline's checks after the fit
(:func:`calib_jax.geometry.shell_status`): parameters exist but are no calibration."""

CONVERGED_STATUSES = (
    Status.CONVERGED_GRADIENT,
    Status.CONVERGED_PARAMETERS,
    Status.CONVERGED_CHI2,
    Status.CONVERGED,
    Status.CONVERGED_ROUNDOFF,
)

_MESSAGES = {
    Status.CONVERGED_GRADIENT: "converged: the gradient is below eps1",
    Status.CONVERGED_PARAMETERS: "converged: the parameter step is below eps2 (relative)",
    Status.CONVERGED_CHI2: "converged: the reduced chi2 is below eps3",
    Status.MAX_ITERATIONS: (
        "not converged: the iteration budget ran out, most often because the data do not "
        "determine the model (poses too few or too close together, or motion taken for "
        "poses); with data that do, raise the iteration budget (--max-iter on calib-jax "
        "accel, mag and batch; solver_options={'max_iter': ...} in Python)"
    ),
    Status.NONFINITE: (
        "not fitted: the residual is NaN or inf at the starting point; remove non-finite "
        "samples or give a finite initial guess"
    ),
    Status.SINGULAR: (
        "not converged: the normal equations are singular; the data does not determine "
        "every parameter (add poses that cover the sphere)"
    ),
    Status.CONVERGED: "converged: the external solver met its tolerances",
    Status.FAILED: "not converged: the external solver reported a failure",
    Status.CONVERGED_ROUNDOFF: "converged: chi2 no longer changes beyond round-off",
    Status.INSUFFICIENT_DATA: (
        "not fitted: too few valid samples (finite and inside the mask) for the model"
    ),
    Status.NO_COVERAGE: (
        "not fitted: the samples' directions lie in one plane; record more orientations"
    ),
    Status.NO_SHELL: (
        "no calibration: the samples lie on no ellipsoid shell (RMS radial error above 12 %): "
        "a sensor held still (a noise cloud), motion, or a field that changed during the "
        "recording; record a tumble through all orientations"
    ),
    Status.NOT_AT_REST: (
        "no calibration: the points leave more than 3 % of g after the fit, where readings "
        "held still leave under 1 %: they include motion. Fit the static samples (a mask or "
        "weights from calib_jax.static.detect_static) or the static intervals' means; "
        "calibrate_accel finds them in a whole log"
    ),
    Status.RAN_AWAY: (
        "no calibration: the fitted ellipsoid is over 10 times the samples' spread, so the "
        "samples cover too small a cap of directions (one pose held still, or a few close "
        "together) and any large ellipsoid passes through them; record poses or a tumble "
        "through all orientations"
    ),
}


def status_message(status: int, refused: bool = False) -> str:
    """Human-readable message for a status code. ``refused``: the data were refused for
    what they are (a sensor held still, no shell), so an iteration budget that ran out says
    that more iterations will not help instead of how to raise it (a new-user trial was told
    both on one screen, raised --max-iter, and got the same refusal)."""
    if refused and Status(int(status)) == Status.MAX_ITERATIONS:
        return (
            "not converged: the iteration budget ran out, and more iterations will not help: "
            "the data are no calibration (the warnings say why)"
        )
    return _MESSAGES[Status(int(status))]


def is_converged(status: int) -> bool:
    """True for the statuses that mean the solver found a minimum."""
    return Status(int(status)) in CONVERGED_STATUSES


FIT_STATUSES = {
    "ok": "converged, and the data determine every parameter",
    "poorly_determined": (
        "converged, but some parameter is not pinned down by the data (see the record's "
        "poorly_determined and warnings); usable with care"
    ),
    "not_converged": "the solver's budget ran out; the parameters are its last iterate",
    "failed": "nothing usable: not fitted, a singular or non-finite problem, or a result the "
    "data contradict (see the record's warnings)",
    "not_fitted": "a batch entry whose log was read but holds nothing this fit can use (no "
    "columns of the sensor, too few poses, a unit the reference does not fit); nothing was "
    "fitted (its message says why, its notes what the loader found)",
    "load_error": "a batch entry whose file could not be read; nothing was fitted (its message "
    "says why)",
}
"""The status word of every calibration record (accelerometer, ellipsoid, MARG, batch entry),
best first. Solver codes (:class:`Status`) map onto the first four with :func:`fit_status`."""


def is_usable(word: str) -> bool:
    """True for the status words whose parameters may be used: "ok", "poorly_determined"."""
    return word in ("ok", "poorly_determined")


def worst_status(*words: str) -> str:
    """The worst of several status words (an unknown word counts as "failed")."""
    rank = list(FIT_STATUSES)
    return max(words, key=lambda w: rank.index(w) if w in rank else len(rank))


def fit_status(status: int, usable: bool = True) -> str:
    """The calibration records' status word for a solver status: "failed" (nothing usable:
    non-finite, singular, an external failure, refused before the fit or no calibration after
    it (INSUFFICIENT_DATA, NO_COVERAGE, NO_SHELL, RAN_AWAY), or ``usable`` False),
    "not_converged" (the budget ran out) or "ok"; callers refine "ok" to "poorly_determined"."""
    bad = (Status.NONFINITE, Status.SINGULAR, Status.FAILED, Status.INSUFFICIENT_DATA)
    if int(status) in (*bad, Status.NO_COVERAGE, *NO_CALIBRATION) or not usable:
        return "failed"
    return "ok" if is_converged(status) else "not_converged"
