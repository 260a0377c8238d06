"""The base model with every catalogue effect, as one pure residual (jit, vmap, grad).

One observation is a point x (a static-interval mean, or a magnetometer sample), normalised
as x_n = (x - c0) / k0 so that the base calibration is close to alpha = I, b = 0, with its
drivers: tau (time, scaled to [-1/2, 1/2] over the log) and T (temperature, scaled the same
way; 0 without a temperature column). The calibrated vector and the residual are

    b(tau, T) = b + d1 tau + d2 tau^2 + c1 T + c2 T^2              bias / hard iron
    y         = alpha^-1 (x_n - b(tau, T)) / (1 + k1 T)             paper 1 eq. 1, gains(T)
    y_j      <- y_j - q_j y_j^2 - r_j y_j^3                          per-axis nonlinearity
    e         = det(alpha)^(1/3) (|y| - 1)                          fitted (see residual)

and |y| - 1, the relative magnitude error, is what the diagnosis reports.

with alpha symmetric (gains on the diagonal, paper 1's non-orthogonality off it). All 30
parameters live in one vector ``theta`` (layout in :data:`SLOTS`); which ones a fit frees is a
boolean mask ``free``. A parameter that is not free is multiplied out of the model and pinned
to 0 by one extra residual row, so every candidate model is the SAME compiled function: the
diagnosis fits the base model, each candidate, split halves and null simulations with one
compilation (:func:`fit_each`). The magnetometer's sphere model ties gains 2 and 3 to gain 1
and the cross terms to 0, its diagonal model the cross terms, unless the ``soft_iron`` slots
are free.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ..linalg import det3
from ..lm import lm_solve
from ..models.accel import correct
from ..models.layout import ALPHA_INDEX
from ..runtime import disk_jit

N_THETA = 30

SLOTS: dict[str, slice] = {
    "gains": slice(0, 3),
    "cross": slice(3, 6),
    "bias": slice(6, 9),
    "drift1": slice(9, 12),
    "drift2": slice(12, 15),
    "temp_bias1": slice(15, 18),
    "temp_bias2": slice(18, 21),
    "temp_scale1": slice(21, 24),
    "quadratic": slice(24, 27),
    "cubic": slice(27, 30),
}


def mask(*slots: str, base: str = "full") -> np.ndarray:
    """Free-parameter mask: the base model (the magnetometer's kinds of
    :func:`calib_jax.calibrate_mag`: "full": alpha and b; "diag": three gains and b; "sphere":
    one gain and b) plus the named slots (``"soft_iron"`` frees the gains and the cross
    terms: the rest of the full ellipsoid)."""
    free = np.zeros(N_THETA, bool)
    if base == "full":
        free[0:9] = True
    elif base == "diag":
        free[[0, 1, 2, 6, 7, 8]] = True
    elif base == "sphere":
        free[[0, 6, 7, 8]] = True
    else:
        raise ValueError(f"base must be 'full', 'diag' or 'sphere', got {base!r}")
    for s in slots:
        if s == "soft_iron":
            free[[1, 2, 3, 4, 5]] = True
        else:
            free[SLOTS[s]] = True
    return free


def base_alpha(theta, free, xp=jnp):
    """The base model's alpha from theta's first six entries (paper 1's layout,
    models.layout.ALPHA_INDEX); a sphere's gains 2 and 3 follow gain 1 and its cross terms are
    0. ``xp``: jnp inside the fits, np on the host."""
    g = xp.where(free[0:3], theta[0:3], theta[0])
    s = xp.where(free[3:6], theta[3:6], 0.0)
    return xp.concatenate([g, s])[ALPHA_INDEX]


def calibrated(theta, free, x, tau, temp):
    """The calibrated vector y (3,) of one observation (see the module docstring): paper 1's
    correction (:func:`calib_jax.models.accel.correct`, the model every fit uses) with the
    bias moved by the drift and temperature terms, then the gain(T) and nonlinearity effects."""
    th = jnp.where(free, theta, 0.0)
    g = jnp.where(free[0:3], theta[0:3], theta[0])  # the sphere's gains follow gain 1
    b = th[6:9] + th[9:12] * tau + th[12:15] * tau**2 + th[15:18] * temp + th[18:21] * temp**2
    y = correct(jnp.concatenate([g, th[3:6], b]), x) / (1.0 + th[21:24] * temp)
    return y - th[24:27] * y**2 - th[27:30] * y**3


def radius(theta, free):
    """det(alpha)^(1/3): the radius of the fitted sphere in normalised units (about 1)."""
    return jnp.cbrt(det3(base_alpha(theta, free)))


def _row(theta, x, tau, temp, free):
    """One data row of the residual: r (|y| - 1), r = det(alpha)^(1/3)."""
    y = calibrated(theta, free, x, tau, temp)
    return radius(theta, free) * (jnp.sqrt(jnp.sum(y * y)) - 1.0)


_ROWS = (None, 0, 0, 0, None)  # theta and the mask shared, one row of data each


def residual(theta, data):
    """Data rows r (|y_i| - 1) with r = det(alpha)^(1/3), then 30 pinning rows.

    The factor r makes the residual a distance in the data's units, not a fraction of the
    fitted radius: relative errors let a far-away, huge sphere fit a cap of the data with a
    small relative error (a magnetometer with a magnet attached, BROAD trial 34, ran away to
    0.03 % that way; the same runaway calib_jax.models.mag guards against).
    """
    x, tau, temp, w, free = data
    e = jax.vmap(_row, in_axes=_ROWS)(theta, x, tau, temp, free)
    return jnp.concatenate([e, jnp.where(free, 0.0, theta)])


def jacobian(theta, data):
    """The exact Jacobian of :func:`residual`: one reverse pass per data row (a vmap of its
    gradient), then the pinning rows' constant diagonal. ``jax.jacfwd`` pushes 30 tangents
    through every row instead: 17 ms against 2.1 ms at 4,096 rows (equal to 4e-16), and the
    Jacobian is most of a diagnosis fit's time (issue 17)."""
    x, tau, temp, w, free = data
    rows = jax.vmap(jax.grad(_row), in_axes=_ROWS)(theta, x, tau, temp, free)
    return jnp.concatenate([rows, jnp.diag(jnp.where(free, 0.0, 1.0).astype(rows.dtype))])


def _fit_one(theta0, x, tau, temp, w, free, max_iter):
    m = x.shape[0]
    weights = jnp.concatenate([w, jnp.ones(N_THETA, w.dtype)])
    dof = jnp.sum(w > 0) - jnp.sum(free)
    data = (x, tau, temp, w, free)
    res = lm_solve(
        residual,
        theta0,
        data,
        weights=weights,
        update_type=1,
        jacobian=jacobian,
        dof=dof,
        max_iter=max_iter,
        covariance_method="cholesky",
    )
    r = radius(res.params, free)
    e = residual(res.params, data)[:m] / r  # |y| - 1, the relative error reported
    J = jacobian(res.params, data)[:m] / r
    return res.params, res.stderr, res.status, e, J


@functools.lru_cache(maxsize=4)
def _compiled_fit(max_iter: int):
    return disk_jit(lambda *a: _fit_one(*a, max_iter), f"diagnose.fit_one {max_iter}")


def fit_each(compiled, *stacked, shared: tuple = ()) -> tuple[np.ndarray, ...]:
    """Run ``compiled(*problem, *shared)`` (one problem's jitted fit) on each problem of the
    stacked arrays (leading axis) in turn; numpy outputs stacked the same way. ``shared``
    arguments are the same for every problem.

    One problem at a time, not one vmapped call: under ``vmap`` the solver's while_loop runs
    every problem to the slowest one's iteration count, and a round's problems differ (most
    stop after 4-9 iterations, a few take 25-35). On the soft-iron simulation's 63 problems
    this takes 3.3 s where the vmapped call took 11 s (warm, issue 17), and the one compilation
    serves any number of problems.
    """
    # numpy in, numpy slices: eager jnp conversions and indexing each compile a program
    arrays = [np.asarray(a) for a in stacked]
    common = [np.asarray(a) for a in shared]
    outs = [compiled(*(a[k] for a in arrays), *common) for k in range(arrays[0].shape[0])]
    return tuple(np.stack([np.asarray(o[i]) for o in outs]) for i in range(len(outs[0])))


def fit_many(theta0, x, tau, temp, w, free, max_iter: int = 100):
    """Fit a stack of problems (leading axis), one compiled fit for all (:func:`fit_each`).

    Returns numpy arrays: params (P, 30), stderr (P, 30), status (P,), the relative errors
    e = |y| - 1 (P, m) of the data rows, and their Jacobian J (P, m, 30) at the solution (the
    fitted residual divided by the fitted radius, about 1).
    """
    return fit_each(_compiled_fit(int(max_iter)), theta0, x, tau, temp, w, free)
