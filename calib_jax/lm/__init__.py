"""Least-squares solvers: Gavin's Levenberg-Marquardt in JAX and an optimistix cross-check."""

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
]
