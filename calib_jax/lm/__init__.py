"""Least-squares solvers: Gavin's Levenberg-Marquardt in JAX and an optimistix cross-check."""

import functools
from collections.abc import Callable

import numpy as np

from ..status import (
    FIT_STATUSES,
    Status,
    fit_status,
    is_converged,
    is_usable,
    status_message,
    worst_status,
)
from .gavin import DEFAULTS, GAVIN_DEFAULTS, LMDefaults, finite_difference_jacobian, lm_solve
from .result import LMHistory, LMResult, uncertainty, uncertainty_cholesky

_SET_BY_CALLER = ("fun", "p0", "args", "weights", "update_type", "dof")
"""lm_solve / optx_solve arguments each fit sets itself (update_type from lm1, lm2, lm3)."""


def checked_solver_options(solver: str, options: dict | None) -> tuple:
    """``solver_options`` as the sorted tuple the compiled fits are keyed by, each name
    checked against the solver's own options (:func:`lm_solve` for lm1-lm3,
    :func:`optx_solve` for optimistix): a wrong one was a TypeError from inside a traced
    function; now a ValueError that lists what the solver takes."""
    import inspect

    if solver == "optimistix":
        from .optx import optx_solve as fn
    else:
        fn = lm_solve
    allowed = [k for k in inspect.signature(fn).parameters if k not in _SET_BY_CALLER]
    bad = sorted(set(options or {}) - set(allowed))
    if bad:
        why = " (update_type is chosen by the solver's name: lm1, lm2, lm3)" * (
            "update_type" in bad
        )
        raise ValueError(
            f"solver_options {bad} are not options of solver {solver!r}{why}; it takes "
            f"{', '.join(allowed)}"
        )
    return tuple(sorted((options or {}).items()))


def budget_apart(solver: str, options: tuple) -> tuple[tuple, np.ndarray | None]:
    """(the options a compiled fit is keyed by, its iteration budget as an argument) for the
    sorted ``options`` of :func:`checked_solver_options`. An LM fit takes ``max_iter`` as a
    traced argument (the loop only compares with it), so a new ``--max-iter`` reuses the
    compiled program instead of compiling another; optimistix's ``max_steps`` and the history
    buffers (``history=True``) are shapes, so there the budget stays in the key (None)."""
    opts = dict(options)
    if solver == "optimistix" or opts.get("history"):
        return options, None
    budget = np.asarray(opts.pop("max_iter", DEFAULTS.max_iter), np.int32)
    return tuple(sorted(opts.items())), budget


def budgeted_disk_jit(fun: Callable, key: str, options: tuple, budgeted: bool) -> Callable:
    """:func:`calib_jax.runtime.disk_jit` of ``fun(*data, **options)``; with ``budgeted`` the
    program takes the iteration budget as its last argument and passes it as ``max_iter``."""
    from ..runtime import disk_jit

    if not budgeted:
        return disk_jit(functools.partial(fun, **dict(options)), key)

    def run(*args):
        *data, max_iter = args
        return fun(*data, max_iter=max_iter, **dict(options))

    return disk_jit(run, f"{key} budget")


def with_budget(compiled: Callable, budget: np.ndarray | None) -> Callable:
    """``compiled`` itself where :func:`budget_apart` kept the budget in the key (None), else
    ``compiled`` with the budget as its last argument."""
    if budget is None:
        return compiled
    return lambda *args: compiled(*args, budget)


def __getattr__(name: str):
    # optx_solve on first use: optimistix takes 0.14 s to import, a tenth of a warm CLI call
    # that does not use it
    if name == "optx_solve":
        from .optx import optx_solve

        return optx_solve
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "DEFAULTS",
    "GAVIN_DEFAULTS",
    "LMDefaults",
    "LMHistory",
    "LMResult",
    "Status",
    "budget_apart",
    "budgeted_disk_jit",
    "checked_solver_options",
    "finite_difference_jacobian",
    "fit_status",
    "FIT_STATUSES",
    "is_usable",
    "worst_status",
    "is_converged",
    "lm_solve",
    "optx_solve",
    "status_message",
    "uncertainty",
    "uncertainty_cholesky",
    "with_budget",
]
