"""The same least-squares problem through optimistix's LevenbergMarquardt, for cross-checks.

optimistix damps with lambda I (starting at 1), accepts at a ratio of 0.01 and stops when both
the step and the residual change fall below rtol/atol; compare it with the Gavin solver at
matched final chi2, not by iteration counts (LM_SPEC).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import optimistix as optx

from ..status import Status
from .result import LMResult, uncertainty, uncertainty_cholesky


def optx_solve(
    fun: Callable[[jax.Array, Any], jax.Array],
    p0: jax.Array,
    args: Any = None,
    *,
    weights: jax.Array | None = None,
    rtol: float = 1e-12,
    atol: float = 1e-14,
    max_iter: int = 256,
    absolute_sigma: bool = False,
    dof: jax.Array | float | None = None,
    covariance_method: str = "eigh",
) -> LMResult:
    """Minimise sum_i w_i e_i(p)^2 with ``optimistix.LevenbergMarquardt``.

    Jittable and vmappable (``throw=False``: the per-member outcome is in ``status``).
    ``nfev`` and ``njev`` are optimistix's step count (it does not report evaluations).
    ``covariance_method`` as :func:`calib_jax.lm.lm_solve`.
    """
    p0 = jnp.asarray(p0)
    e0 = fun(p0, args)
    m, n = e0.shape[0], p0.shape[0]
    if m <= n:
        raise ValueError(
            f"{m} residuals cannot determine {n} parameters; give more samples than parameters"
        )
    w = jnp.ones(m, p0.dtype) if weights is None else jnp.asarray(weights, p0.dtype)
    sw = jnp.sqrt(w)

    def weighted(p, a):
        return sw * fun(p, a)

    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    sol = optx.least_squares(weighted, solver, p0, args, max_steps=max_iter, throw=False)
    p = sol.value
    e = fun(p, args)
    chi2 = jnp.sum(w * e * e)
    J = jax.jacfwd(fun)(p, args)
    jtwj = (J * w[:, None]).T @ J
    if dof is None:
        dof = jnp.maximum(jnp.sum(w > 0) - n, 1).astype(p.dtype)
    else:
        dof = jnp.maximum(jnp.asarray(dof, p.dtype), 1.0)
    reduced = chi2 / dof
    unc = uncertainty if covariance_method == "eigh" else uncertainty_cholesky
    cov, stderr, corr, cond = unc(jtwj, reduced, absolute_sigma)
    steps = sol.stats["num_steps"]
    status = jnp.where(
        sol.result == optx.RESULTS.successful,
        int(Status.CONVERGED),
        jnp.where(
            sol.result == optx.RESULTS.nonlinear_max_steps_reached,
            int(Status.MAX_ITERATIONS),
            jnp.where(jnp.isfinite(chi2), int(Status.FAILED), int(Status.NONFINITE)),
        ),
    )
    return LMResult(
        params=p,
        chi2=chi2,
        reduced_chi2=reduced,
        iterations=steps,
        nfev=steps,
        njev=steps,
        status=status,
        covariance=cov,
        stderr=stderr,
        correlation=corr,
        condition=cond,
        history=None,
    )
