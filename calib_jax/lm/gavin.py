"""Levenberg-Marquardt after Gavin's ``lm.m``, as fixed in ``shared/docs/LM_SPEC.md``.

Paper 1 (section 2.4-2.5) uses this algorithm; its text is garbled, so the facts below follow
the spec. Notation: residual e(p) = y - y_hat(p) (m values), weights w (the diagonal of W),
chi2 = e'We, J = de/dp (so J'WJ is the spec's J'WJ and g = -J'We is the spec's J'W(y - y_hat)).

Update types (a static choice, one compilation each):

=====  =========================  ==============================  ===========================
type   system                     accept                          reject
=====  =========================  ==============================  ===========================
1      (J'WJ + lam diag(J'WJ)) h  lam = max(lam / L_down, lo)     lam = min(lam * L_up, hi)
2      (J'WJ + lam I) h, then     lam = max(lam / (1 + a), lo)    lam += |dchi2| / (2 a)
       h <- a h with a = g'h / (dchi2/2 + 2 g'h)
3      (J'WJ + lam I) h           lam *= max(1/3, 1-(2rho-1)^3)   lam *= nu; nu *= 2
=====  =========================  ==============================  ===========================

A step is accepted when rho > eps4, with rho = (chi2(p) - chi2(p+h)) / |h'(lam D h + g)|
(``rho_form="current"``: the Gauss-Newton model's predicted decrease, D = diag(J'WJ) for type
1 and I otherwise) or / (2 |h'(lam h + g)|) (``rho_form="paper"``, paper 1 eq. 13, Gavin 2013).

Decisions where Gavin's code is odd (LM_SPEC "Known quirks"):

* chi2 is monotone: a rejected step never changes the reference chi2 (Gavin restores the chi2
  of the previous accepted point, which lets a later uphill step through).
* With ``jacobian="broyden"`` the finite-difference Jacobian is recomputed at the first
  iteration, every 2n iterations and after every rejected step (Gavin's "after a rise in chi2"
  trigger, which never fires in his loop, fires here); the rank-1 update is applied after every
  trial step, accepted or not, since the secant is valid either way. A convergence test
  (tests 1-2, round-off) only counts with a fresh finite-difference Jacobian: with a Broyden
  one the loop can settle where only the approximate gradient vanishes (seen with type 2,
  1e-7 above the optimum chi2), so such a stop triggers a refresh instead.
* lambda stays within [lambda_min, lambda_max] for all three types. A step that cannot be
  solved (non-finite h) counts as a rejection; at lambda_max it ends the fit as ``SINGULAR``.
* Besides tests 1-3, a rejected step whose actual and predicted chi2 changes are both below
  the round-off of chi2 ends the fit as ``CONVERGED_ROUNDOFF``: with thousands of samples the
  gradient at the optimum is round-off, so the absolute tests alone can loop until the budget.
  This test needs no accepted step (a start already at the optimum).
* The round-off of chi2 is 4 eps (sqrt(m) chi2 + 2 sum w_i |e_i| s_i), s_i = |e_i| +
  sum_j |J_ij p_j|: the sum's own round-off plus each residual's. A residual is a difference of
  terms of size ~s_i (1 - |a|^2 with |a| ~ 1 for the sphere), so it carries eps s_i absolute
  error, not eps |e_i|. At a noise-floor minimum |e_i| << s_i: with 24 pose means and 2 mg
  noise, chi2 = 1.5e-6 is evaluated to ~1e-18, while 4 sqrt(m) eps chi2 (the only term before)
  is 7e-21. Every trial step then changed chi2 by more than that bound, so the test never
  fired, and the sign of the round-off decided whether a step was accepted: one-ulp changes of
  the data (a strided vs a contiguous copy) sent 3 % (type 1) to 16 % (type 3) of such fits
  through nine rejections to lambda_max and on to the 200-iteration budget, the others
  converging in a few iterations. The larger bound stops a fit within ~1e-11 relative of the
  minimum chi2 there, far below its statistical resolution.
* Convergence tests 1-3 run after at least one accepted step. The parameter test looks at the last
  trial step whether or not it was accepted (as Gavin does); eps2 is tight by default, so a
  heavily damped step only passes it once lambda has grown by many orders of magnitude.

Calibration defaults: Gavin's eps1 = eps2 = 1e-3 and eps3 = 1e-1 stop a well-scaled calibration
after two or three iterations, far from the optimum (tests/test_lm.py shows it). calib_jax uses
eps1 = 1e-12, eps2 = 1e-10 and eps3 = 0 (the reduced-chi2 test off), so fits end at the optimum
to ~1e-10 relative and agree with SciPy's least_squares; set eps3 > 0 only with weights 1/sigma^2.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Literal, NamedTuple

import jax
import jax.numpy as jnp

from ..linalg import cho_solve_small
from ..status import Status
from .result import LMHistory, LMResult, uncertainty, uncertainty_cholesky

_RUNNING = -1

UpdateType = Literal[1, 2, 3]
JacobianMode = Literal["exact", "broyden"]


class LMDefaults(NamedTuple):
    """Calibration defaults (see the module docstring for why they differ from Gavin's)."""

    eps1: float = 1e-12
    eps2: float = 1e-10
    eps3: float = 0.0
    eps4: float = 1e-1
    lambda0: float = 1e-2
    lambda_up: float = 11.0
    lambda_down: float = 9.0
    lambda_min: float = 1e-7
    lambda_max: float = 1e7
    max_iter: int = 200


DEFAULTS = LMDefaults()
GAVIN_DEFAULTS = LMDefaults(eps1=1e-3, eps2=1e-3, eps3=1e-1)
"""Gavin's own defaults, kept for benchmarks and for showing the early-stop trap."""


class _Carry(NamedTuple):
    p: jax.Array
    e: jax.Array
    chi2: jax.Array
    J: jax.Array
    jtwj: jax.Array
    g: jax.Array
    lam: jax.Array
    nu: jax.Array
    it: jax.Array
    nfev: jax.Array
    njev: jax.Array
    n_acc: jax.Array
    fresh: jax.Array
    status: jax.Array
    hist_chi2: jax.Array
    hist_lam: jax.Array
    hist_acc: jax.Array


def _safe_div(a, b, fallback):
    """a / b where b != 0 and the result is finite, else fallback (NaN-safe double where)."""
    ok = b != 0
    q = a / jnp.where(ok, b, 1.0)
    return jnp.where(ok & jnp.isfinite(q), q, fallback)


def finite_difference_jacobian(
    fun: Callable, p: jax.Array, args: Any, delta: float, scheme: str
) -> jax.Array:
    """J_ij = d e_i / d p_j by forward or central differences, step delta (1 + |p_j|).

    Paper 1 eq. 14 (forward) and eq. 15 (central, the default).
    """
    n = p.shape[0]
    steps = delta * (1.0 + jnp.abs(p))
    basis = jnp.eye(n, dtype=p.dtype) * steps[:, None]
    plus = jax.vmap(lambda dp: fun(p + dp, args))(basis)  # (n, m)
    if scheme == "central":
        minus = jax.vmap(lambda dp: fun(p - dp, args))(basis)
        return ((plus - minus) / (2.0 * steps[:, None])).T
    base = fun(p, args)
    return ((plus - base[None, :]) / steps[:, None]).T


def lm_solve(
    fun: Callable[[jax.Array, Any], jax.Array],
    p0: jax.Array,
    args: Any = None,
    *,
    weights: jax.Array | None = None,
    update_type: UpdateType = 1,
    rho_form: Literal["current", "paper"] = "current",
    jacobian: JacobianMode | Callable[[jax.Array, Any], jax.Array] = "exact",
    fd_scheme: Literal["central", "forward"] = "central",
    fd_delta: float = 1e-6,
    eps1: float = DEFAULTS.eps1,
    eps2: float = DEFAULTS.eps2,
    eps3: float = DEFAULTS.eps3,
    eps4: float = DEFAULTS.eps4,
    lambda0: float = DEFAULTS.lambda0,
    lambda_up: float = DEFAULTS.lambda_up,
    lambda_down: float = DEFAULTS.lambda_down,
    lambda_min: float = DEFAULTS.lambda_min,
    lambda_max: float = DEFAULTS.lambda_max,
    max_iter: int | jax.Array = DEFAULTS.max_iter,
    max_nfev: int | None = None,
    history: bool = False,
    absolute_sigma: bool = False,
    dof: jax.Array | float | None = None,
    covariance_method: Literal["eigh", "cholesky"] = "eigh",
) -> LMResult:
    """Minimise chi2(p) = sum_i w_i e_i(p)^2 by Gavin's Levenberg-Marquardt.

    Pure and jittable; ``vmap`` it over sensors (every state variable is per member, and a
    finished member is frozen while the others iterate).

    Parameters
    ----------
    fun : callable ``fun(p, args) -> e``
        Residual vector (m,), m > n. Differentiable in p for ``jacobian="exact"``.
    p0 : (n,) array
        Initial parameters.
    weights : (m,) array, optional
        Diagonal of W; zero weights mask samples out (padding). Default all ones.
    update_type : {1, 2, 3}
        Marquardt, quadratic line-search, Nielsen (LM_SPEC table). Static.
    rho_form : {"current", "paper"}
        Denominator of the acceptance ratio (see module docstring). Static.
    jacobian : {"exact", "broyden"} or callable
        Autodiff Jacobian every accepted step (``jax.jacfwd``), or paper 1's finite
        differences plus Broyden rank-1 updates; or the exact Jacobian as a function
        ``jacobian(p, args) -> (m, n)``, for a residual whose structure autodiff can use
        better (a residual of rows, each a function of all of p: a vmap of each row's
        ``grad`` is one reverse pass per row instead of n forward passes through every row).
        Static.
    eps1, eps2, eps3, eps4 : float
        Gradient, parameter, reduced-chi2 and acceptance thresholds.
    max_iter, max_nfev : int
        Iteration and residual-evaluation budgets (static; ``max_iter`` may also be a traced
        integer scalar, the loop only comparing with it, so that one compiled fit serves every
        budget: :func:`calib_jax.lm.budget_apart`; not with ``history``, whose buffers it
        sizes).
    history : bool
        Keep per-iteration chi2, lambda and acceptance in fixed buffers of length max_iter.
    absolute_sigma : bool
        Weights are 1/sigma^2: do not scale the covariance by the reduced chi2.
    dof : scalar, optional
        Degrees of freedom for the reduced chi2 and the covariance; default the number of
        non-zero weights minus n.
    covariance_method : {"eigh", "cholesky"}
        How the covariance is taken from J'WJ at the end: ``"eigh"`` names the parameters a
        singular J'WJ leaves undetermined (:func:`calib_jax.lm.uncertainty`); ``"cholesky"`` is
        about 10x cheaper under vmap and marks all of them (:func:`uncertainty_cholesky`).

    Returns
    -------
    LMResult
    """
    if update_type not in (1, 2, 3):
        raise ValueError(f"update_type must be 1, 2 or 3, got {update_type!r}")
    if rho_form not in ("current", "paper"):
        raise ValueError(f"rho_form must be 'current' or 'paper', got {rho_form!r}")
    jac_fun = None
    if callable(jacobian):
        jac_fun, jacobian = jacobian, "exact"
    if jacobian not in ("exact", "broyden"):
        raise ValueError(f"jacobian must be 'exact', 'broyden' or a function, got {jacobian!r}")
    if fd_scheme not in ("central", "forward"):
        raise ValueError(f"fd_scheme must be 'central' or 'forward', got {fd_scheme!r}")
    p0 = jnp.asarray(p0)
    if not jnp.issubdtype(p0.dtype, jnp.floating):
        p0 = p0.astype(jnp.result_type(float))
    dtype = p0.dtype
    n = p0.shape[0]
    e0 = fun(p0, args)
    m = e0.shape[0]
    if m <= n:
        raise ValueError(
            f"{m} residuals cannot determine {n} parameters; give more samples than parameters"
        )
    w = jnp.ones(m, dtype) if weights is None else jnp.asarray(weights, dtype)
    # Degrees of freedom count only samples with non-zero weight (padding is weight 0); a
    # caller whose residual vector is a compressed stand-in for the samples (the moment form
    # in calib_jax.batch) passes the samples' dof instead.
    if dof is None:
        dof = jnp.maximum(jnp.sum(w > 0) - n, 1).astype(dtype)
    else:
        dof = jnp.maximum(jnp.asarray(dof, dtype), 1.0)
    P = _Problem(
        fun=fun,
        args=args,
        w=w,
        dof=dof,
        n=n,
        dtype=dtype,
        update_type=update_type,
        rho_form=rho_form,
        jacobian=jacobian,
        fd_scheme=fd_scheme,
        fd_delta=fd_delta,
        eps1=eps1,
        eps2=eps2,
        eps3=eps3,
        eps4=eps4,
        lambda0=lambda0,
        lambda_up=lambda_up,
        lambda_down=lambda_down,
        lambda_min=lambda_min,
        lambda_max=lambda_max,
        max_iter=max_iter,
        max_nfev=10**9 if max_nfev is None else int(max_nfev),
        hist_len=max_iter if history else 1,
        history=history,
        jac_fun=jac_fun,
    )
    final = jax.lax.while_loop(
        lambda c: c.status == _RUNNING, lambda c: _iteration(P, c), _init(P, p0, e0)
    )
    return _finish(P, final, absolute_sigma, covariance_method)


# ---------------------------------------------------------------------------------------------
# the parts of lm_solve, in the order one iteration uses them


class _Problem(NamedTuple):
    """What does not change during a solve: the residual, its data and weights, the options."""

    fun: Callable
    args: Any
    w: jax.Array
    dof: jax.Array
    n: int
    dtype: Any
    update_type: int
    rho_form: str
    jacobian: str
    fd_scheme: str
    fd_delta: float
    eps1: float
    eps2: float
    eps3: float
    eps4: float
    lambda0: float
    lambda_up: float
    lambda_down: float
    lambda_min: float
    lambda_max: float
    max_iter: int | jax.Array
    max_nfev: int
    hist_len: int
    history: bool
    jac_fun: Callable | None = None
    """The caller's exact Jacobian ``jac_fun(p, args)``; None: ``jax.jacfwd`` of ``fun``."""

    @property
    def n_fd(self) -> int:
        """Residual evaluations of one finite-difference Jacobian."""
        return 2 * self.n if self.fd_scheme == "central" else self.n

    def residual(self, p):
        return self.fun(p, self.args)

    def jac_exact(self, p):
        return (self.jac_fun or jax.jacfwd(self.fun))(p, self.args)

    def jac_fd(self, p):
        return finite_difference_jacobian(self.fun, p, self.args, self.fd_delta, self.fd_scheme)

    def normal(self, J, e):
        """J'WJ and the descent direction -J'We."""
        jw = J * self.w[:, None]
        return jw.T @ J, -(jw.T @ e)

    def chi2(self, e):
        return jnp.sum(self.w * e * e)


def _init(P: _Problem, p0: jax.Array, e0: jax.Array) -> _Carry:
    """The state before the first iteration: Jacobian at the start, lambda_0 (scaled by the
    largest diagonal of J'WJ for types 2 and 3), NONFINITE at once for a non-finite start."""
    if P.jacobian == "exact":
        J0, nfev0 = P.jac_exact(p0), 1
    else:
        J0, nfev0 = P.jac_fd(p0), 1 + P.n_fd
    jtwj0, g0 = P.normal(J0, e0)
    chi2_0 = P.chi2(e0)
    lam0 = P.lambda0 if P.update_type == 1 else P.lambda0 * jnp.max(jnp.diag(jtwj0))
    finite0 = jnp.isfinite(chi2_0) & jnp.all(jnp.isfinite(J0))
    return _Carry(
        p=p0,
        e=e0,
        chi2=chi2_0,
        J=J0,
        jtwj=jtwj0,
        g=g0,
        lam=jnp.asarray(lam0, P.dtype),
        nu=jnp.asarray(2.0, P.dtype),
        it=jnp.asarray(0),
        nfev=jnp.asarray(nfev0),
        njev=jnp.asarray(1),
        n_acc=jnp.asarray(0),
        fresh=jnp.asarray(True),
        status=jnp.where(finite0, _RUNNING, int(Status.NONFINITE)),
        hist_chi2=jnp.full(P.hist_len, jnp.nan, P.dtype),
        hist_lam=jnp.full(P.hist_len, jnp.nan, P.dtype),
        hist_acc=jnp.zeros(P.hist_len, bool),
    )


class _Trial(NamedTuple):
    h: jax.Array
    h_ok: jax.Array
    p: jax.Array
    e: jax.Array
    chi2: jax.Array
    nfev: jax.Array
    alpha: jax.Array
    pred: jax.Array
    """The predicted decrease of chi2 (the acceptance ratio's denominator)."""


def _trial_step(P: _Problem, c: _Carry) -> _Trial:
    """Solve (J'WJ + lambda D) h = J'W e (D = diag(J'WJ) for type 1, I otherwise), evaluate
    p + h; type 2 then scales h by the quadratic line search's alpha and evaluates again."""
    dj = jnp.diag(c.jtwj)
    D = dj if P.update_type == 1 else jnp.ones_like(dj)
    A = c.jtwj + c.lam * D * jnp.eye(P.n, dtype=P.dtype)
    h = cho_solve_small(A, c.g)
    h_ok = jnp.all(jnp.isfinite(h))
    h = jnp.where(h_ok, h, 0.0)
    p_try = c.p + h
    e_try = P.residual(p_try)
    chi2_try = P.chi2(e_try)
    nfev = c.nfev + 1
    alpha = jnp.asarray(1.0, P.dtype)
    if P.update_type == 2:
        gh = c.g @ h
        alpha = _safe_div(gh, (chi2_try - c.chi2) / 2.0 + 2.0 * gh, 1.0)
        h = alpha * h
        p_try = c.p + h
        e_try = P.residual(p_try)
        chi2_try = P.chi2(e_try)
        nfev = nfev + 1
    if P.rho_form == "paper":
        pred = 2.0 * jnp.abs(h @ (c.lam * h + c.g))
    else:
        pred = jnp.abs(h @ (c.lam * D * h + c.g))
    return _Trial(h, h_ok, p_try, e_try, chi2_try, nfev, alpha, pred)


# The three lambda updates of LM_SPEC's table: (carry, trial, accepted?, rho, problem) ->
# (lambda after an accepted step, lambda after a rejected one, nu)


def _lambda_marquardt(c, t, accept, rho, P):
    return c.lam / P.lambda_down, c.lam * P.lambda_up, c.nu


def _lambda_quadratic(c, t, accept, rho, P):
    lam_rej = c.lam + _safe_div(jnp.abs(t.chi2 - c.chi2), 2.0 * t.alpha, jnp.inf)
    lam_rej = jnp.where(jnp.isfinite(lam_rej) & (lam_rej > c.lam), lam_rej, c.lam * P.lambda_up)
    return c.lam / (1.0 + t.alpha), lam_rej, c.nu


def _lambda_nielsen(c, t, accept, rho, P):
    lam_acc = c.lam * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
    return lam_acc, c.lam * c.nu, jnp.where(accept, 2.0, c.nu * 2.0)


LAMBDA_UPDATES = {1: _lambda_marquardt, 2: _lambda_quadratic, 3: _lambda_nielsen}


def _roundoff_bound(P: _Problem, c: _Carry) -> jax.Array:
    """The round-off of chi2 = sum w e^2 at the current point: the sum's own (sqrt(m) eps chi2)
    plus each residual's. A residual is a difference of terms of size s_i ~ |e_i| +
    sum_j |J_ij p_j|, so it carries ~eps s_i of absolute error, and chi2 ~2 eps sum w_i |e_i|
    s_i; at a noise-floor minimum (|e_i| << s_i) that term dominates (see "Decisions")."""
    s = jnp.abs(c.e) + jnp.abs(c.J) @ jnp.abs(c.p)
    return (
        4.0
        * jnp.finfo(P.dtype).eps
        * (jnp.sqrt(P.dof + P.n) * c.chi2 + 2.0 * jnp.sum(P.w * jnp.abs(c.e) * s))
    )


def _refresh_jacobian(P: _Problem, c: _Carry, t: _Trial, accept, p, nfev, stale):
    """The Jacobian for the next iteration -> (J, nfev, njev, fresh). Exact: autodiff at an
    accepted point. Broyden: a rank-1 update, replaced by finite differences every 2n
    iterations, after a rejected step, and when a stop is about to be judged on a Broyden
    Jacobian (``stale``: a step computed from it can look converged where only the
    approximate gradient vanishes)."""
    if P.jacobian == "exact":
        J = jax.lax.cond(accept, lambda: P.jac_exact(t.p), lambda: c.J)
        return J, nfev, c.njev + accept.astype(c.njev.dtype), jnp.asarray(True)
    hh = t.h @ t.h
    upd = jnp.outer(t.e - c.e - c.J @ t.h, t.h) / jnp.where(hh > 0, hh, 1.0)
    J_b = jnp.where((hh > 0) & jnp.all(jnp.isfinite(upd)), c.J + upd, c.J)
    refresh = ((c.it + 1) % (2 * P.n) == 0) | ~accept | stale
    J = jax.lax.cond(refresh, lambda: P.jac_fd(p), lambda: J_b)
    nfev = nfev + jnp.where(refresh, P.n_fd, 0)
    return J, nfev, c.njev + refresh.astype(c.njev.dtype), refresh


def _status(conv_g, conv_p, conv_c, conv_r, singular, out_of_budget) -> jax.Array:
    """The first condition that holds, in this order, else still running."""
    return jnp.select(
        [conv_g, conv_p, conv_c, conv_r, singular, out_of_budget],
        [
            int(Status.CONVERGED_GRADIENT),
            int(Status.CONVERGED_PARAMETERS),
            int(Status.CONVERGED_CHI2),
            int(Status.CONVERGED_ROUNDOFF),
            int(Status.SINGULAR),
            int(Status.MAX_ITERATIONS),
        ],
        _RUNNING,
    )


def _iteration(P: _Problem, c: _Carry) -> _Carry:
    """One LM iteration: trial step, acceptance, lambda update, stopping tests."""
    t = _trial_step(P, c)
    rho = _safe_div(c.chi2 - t.chi2, t.pred, -jnp.inf)
    accept = t.h_ok & jnp.isfinite(t.chi2) & (rho > P.eps4)
    lam_acc, lam_rej, nu = LAMBDA_UPDATES[P.update_type](c, t, accept, rho, P)
    lam = jnp.clip(jnp.where(accept, lam_acc, lam_rej), P.lambda_min, P.lambda_max)

    p = jnp.where(accept, t.p, c.p)
    e = jnp.where(accept, t.e, c.e)
    chi2 = jnp.where(accept, t.chi2, c.chi2)
    n_acc = c.n_acc + accept.astype(c.n_acc.dtype)
    it = c.it + 1
    started = n_acc > 0
    tiny_chi2 = _roundoff_bound(P, c)
    small_step = started & (jnp.max(jnp.abs(t.h) / (jnp.abs(p) + 1e-12)) < P.eps2)
    # not gated on an accepted step: a start already at the optimum (the algebraic
    # ellipsoid start often is, to round-off) would otherwise reject until the budget
    roundoff = ~accept & t.h_ok & (jnp.abs(c.chi2 - t.chi2) <= tiny_chi2) & (t.pred <= tiny_chi2)
    stale = (small_step | roundoff) & ~c.fresh
    J, nfev, njev, fresh = _refresh_jacobian(P, c, t, accept, p, t.nfev, stale)
    jtwj, g = P.normal(J, e)

    status = _status(
        conv_g=started & fresh & (jnp.max(jnp.abs(g)) < P.eps1),
        conv_p=small_step & c.fresh,
        conv_c=started & (chi2 / P.dof < P.eps3),
        conv_r=roundoff & c.fresh,
        singular=~t.h_ok & (c.lam >= P.lambda_max),
        out_of_budget=(it >= P.max_iter) | (nfev >= P.max_nfev),
    )
    idx = jnp.minimum(c.it, P.hist_len - 1)
    return _Carry(
        p=p,
        e=e,
        chi2=chi2,
        J=J,
        jtwj=jtwj,
        g=g,
        lam=lam,
        nu=nu,
        it=it,
        nfev=nfev,
        njev=njev,
        n_acc=n_acc,
        fresh=fresh,
        status=status,
        hist_chi2=c.hist_chi2.at[idx].set(chi2) if P.history else c.hist_chi2,
        hist_lam=c.hist_lam.at[idx].set(c.lam) if P.history else c.hist_lam,
        hist_acc=c.hist_acc.at[idx].set(accept) if P.history else c.hist_acc,
    )


def _finish(P: _Problem, final: _Carry, absolute_sigma: bool, covariance_method: str):
    """The LMResult: reduced chi2, covariance from J'WJ at the solution (a finite-difference
    Jacobian for Broyden: the uncertainty needs a real one), the history if kept."""
    jtwj = final.jtwj
    nfev = final.nfev
    if P.jacobian == "broyden":
        jtwj, _ = P.normal(P.jac_fd(final.p), final.e)
        nfev = nfev + P.n_fd
    reduced = final.chi2 / P.dof
    unc = uncertainty if covariance_method == "eigh" else uncertainty_cholesky
    cov, stderr, corr, cond = unc(jtwj, reduced, absolute_sigma)
    hist = (
        LMHistory(chi2=final.hist_chi2, lam=final.hist_lam, accepted=final.hist_acc)
        if P.history
        else None
    )
    return LMResult(
        params=final.p,
        chi2=final.chi2,
        reduced_chi2=reduced,
        iterations=final.it,
        nfev=nfev,
        njev=final.njev,
        status=final.status,
        covariance=cov,
        stderr=stderr,
        correlation=corr,
        condition=cond,
        history=hist,
    )
