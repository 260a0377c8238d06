"""Gradients through a fit by the implicit function theorem, not by unrolling the LM loop.

At the optimum p* of chi2(p, d) = sum_i w_i e_i(p, d)^2 the gradient vanishes,

    F(p*, d) = d chi2 / dp (p*, d) = 0,

so for any data or hyperparameter d (samples, weights, a reference magnitude, ...)

    dp*/dd = -(dF/dp)^-1 dF/dd        (dF/dp: the full Hessian of chi2, not J'J).

:func:`solve_implicit` runs :func:`calib_jax.lm.lm_solve` forward and attaches this rule with
``jax.lax.custom_root``: ``jax.jvp``, ``jax.jacfwd``, ``jax.grad`` and ``jax.vjp`` of the
fitted parameters with respect to ``args`` cost one n x n solve, whatever the number of LM
iterations, and never differentiate through the loop. ``tests/test_implicit.py`` checks it
against finite differences of a full refit, against forward-mode differentiation of the
unrolled LM loop and against optimistix's implicit adjoint.

At a fit that did not converge, F(p, d) != 0 and the rule describes a point that is not the
returned one: the derivative is that of the optimum near it, not of what the solver returned.
Its error is first order in the distance to the optimum (on the 40-pose accelerometer of
``tests/test_implicit.py``, about eight times that distance relative to the derivative's
scale: 3 % after one LM iteration, 2e-4 after two), while forward mode through the same
iterations, the derivative of the returned point, is off by 14 %. The ``status`` of the
forward solve says which case you are in; check it (outside jit) before trusting a
gradient. Where the Hessian is singular (a parameter the data do not determine)
the derivative is NaN or inf, as the standard error is.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from .linalg import cho_solve_small
from .lm import LMResult, lm_solve


def _objective(residual, weights):
    def chi2(p, args):
        e = residual(p, args)
        w = jnp.ones_like(e) if weights is None else weights(args)
        return jnp.sum(w * e * e)

    return chi2


def solve_implicit(
    residual: Callable[[jax.Array, Any], jax.Array],
    p0: jax.Array,
    args: Any,
    *,
    weights: Callable[[Any], jax.Array] | None = None,
    **lm_options,
) -> tuple[jax.Array, LMResult]:
    """Fit ``residual(p, args)`` by LM; the parameters are differentiable in ``args``.

    Parameters
    ----------
    residual : callable ``residual(p, args) -> e`` (m,)
        Differentiable in p and in args.
    p0 : (n,)
        Start. It is not differentiated (a start does not move a converged optimum).
    args : pytree
        Data and hyperparameters; every floating leaf gets a derivative.
    weights : callable ``weights(args) -> w`` (m,), optional
        Per-residual weights as a function of args (so they can be differentiated too).
    lm_options
        Passed to :func:`calib_jax.lm.lm_solve` (update_type, eps1, max_iter, ...).

    Returns
    -------
    (params, result)
        ``params`` carries the implicit derivative; ``result`` is the forward LMResult
        (status, stderr, ...), not differentiated.
    """
    chi2 = _objective(residual, weights)

    def F(p, args):
        return jax.grad(chi2)(p, args)

    def tangent_solve(g, y):
        # g is the linear map v -> (dF/dp) v (the Hessian of chi2, symmetric); n is small, so
        # build the matrix and solve by Cholesky (NaN if it is not positive definite: then the
        # returned point is not a minimum and has no implicit derivative)
        n = y.shape[0]
        H = jax.vmap(g)(jnp.eye(n, dtype=y.dtype))
        return cho_solve_small(0.5 * (H + H.T), y)

    a = jax.lax.stop_gradient(args)
    res = lm_solve(
        residual,
        jax.lax.stop_gradient(p0),
        a,
        weights=None if weights is None else weights(a),
        **lm_options,
    )

    def solve(f, p_init):
        return res.params  # the forward fit above (custom_root only needs the root)

    # custom_root differentiates the values f closes over (here: args) implicitly
    params = jax.lax.custom_root(lambda p: F(p, args), res.params, solve, tangent_solve)
    return params, res
