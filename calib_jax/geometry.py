"""Closed-form starting points: algebraic sphere and ellipsoid fits (pure, jittable)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .linalg import cho_solve_small, eigh_small, inv3
from .padding import pad_rows
from .runtime import disk_jit
from .status import Status

# The 35 monomials x^a y^b z^c of degree <= 4, each built from an earlier one times x, y or z;
# the moment matrix gathers them: phi_i phi_j is the monomial of the summed exponents.
_POWERS = [
    (a, b, d - a - b) for d in range(5) for a in range(d, -1, -1) for b in range(d - a, -1, -1)
]
_POWER_INDEX = {e: i for i, e in enumerate(_POWERS)}
_PHI_POWERS = [(2, 0, 0), (0, 2, 0), (0, 0, 2), (1, 1, 0), (1, 0, 1), (0, 1, 1)]
_PHI_POWERS += [(1, 0, 0), (0, 1, 0), (0, 0, 1), (0, 0, 0)]
_PHI_GATHER = np.array(
    [[_POWER_INDEX[tuple(np.add(a, b))] for b in _PHI_POWERS] for a in _PHI_POWERS]
)
_PHI_FACTOR = np.array([1, 1, 1, 2, 2, 2, 1, 1, 1, 1.0])  # phi = factor * monomial
_POWER_DEGREE = np.array([sum(e) for e in _POWERS])


def _monomials(x: jax.Array, w: jax.Array) -> tuple[jax.Array, ...]:
    """w x^a y^b z^c per sample for the 35 exponents of ``_POWERS``, each built from an earlier
    one times x, y or z (one product per monomial and sample)."""
    X, Y, Z = x[..., 0], x[..., 1], x[..., 2]
    mono = {(0, 0, 0): w}
    for e in _POWERS[1:]:
        a, b, c = e
        lower, factor = ((a - 1, b, c), X) if a else ((a, b - 1, c), Y) if b else ((a, b, c - 1), Z)
        mono[e] = mono[lower] * factor
    return tuple(mono[e] for e in _POWERS)


@jax.custom_jvp
def sum_last(terms: tuple[jax.Array, ...]) -> tuple[jax.Array, ...]:
    """Each array of ``terms`` summed over its last axis, all in one variadic ``lax.reduce``:
    XLA emits a single loop over the samples with one accumulator per term, where separate
    ``jnp.sum`` calls write each term out and read it back. The 35 power sums of 1,000 sensors
    x 4,800 samples: 0.009 ms per sensor this way against 0.059 ms as 35 sums (2-core CPU,
    benchmarks/moment_pass.py). JAX has no derivative for a reduce with a user-written body;
    the sums are linear, so the tangents are summed by ``jnp.sum`` (:func:`_sum_last_jvp`).

    The loop adds the samples one after the other: in float32 that is 0.4-1.1e-6 of the
    largest power sum over 4,800 samples, against 1.4-3.8e-8 for ``jnp.sum``'s blocked sums
    (float64: 1-2e-15 of an exactly rounded sum). Below float64 the terms are summed by
    ``jnp.sum``, as before (tests/test_mag.py::test_power_sums_against_exact_sums).

    On every device: on a lent H200 (``benchmarks/moment_pass.py --sensors 10000``, three runs)
    the mean by a product and one reduce took 0.47-0.48 us per sensor against 0.53-0.55 for
    separate sums (the copy ceiling: 0.10); until then it ran on the CPU only."""
    if any(t.dtype != jnp.float64 for t in terms):
        return tuple(jnp.sum(t, axis=-1) for t in terms)
    return variadic_sum(terms)


def variadic_sum(terms: tuple[jax.Array, ...]) -> tuple[jax.Array, ...]:
    """:func:`sum_last`'s one ``lax.reduce`` on any device and dtype (not differentiable)."""
    zeros = tuple(jnp.zeros((), t.dtype) for t in terms)
    return jax.lax.reduce(
        tuple(terms),
        zeros,
        lambda a, b: tuple(p + q for p, q in zip(a, b, strict=True)),
        (terms[0].ndim - 1,),
    )


@sum_last.defjvp
def _sum_last_jvp(primals, tangents):
    (terms,), (dterms,) = primals, tangents
    return sum_last(terms), tuple(jnp.sum(t, axis=-1) for t in dterms)


def power_sums(x: jax.Array, w: jax.Array) -> jax.Array:
    """The 35 weighted power sums sum_i w_i x_i^a y_i^b z_i^c, a + b + c <= 4 (order of
    ``_POWERS``), of samples x (N, 3), in one pass over the samples (:func:`sum_last`)."""
    return jnp.stack(sum_last(_monomials(x, w)), axis=-1)


def moments_from_power_sums(P: jax.Array, scale: jax.Array | float = 1.0) -> jax.Array:
    """S (10 x 10) of the samples divided by ``scale`` from their power sums :func:`power_sums`
    (a monomial of degree d scales by scale^-d: exact, no cancellation)."""
    # constants from Python numbers, so they take the dtypes of the tracing context (module-level
    # int64 arrays broke under jax.enable_x64 in a process with x64 off)
    inv = 1.0 / jnp.asarray(scale, P.dtype)
    P = P * jnp.stack([inv ** int(d) for d in _POWER_DEGREE])
    factor = jnp.asarray(_PHI_FACTOR.tolist(), P.dtype)
    return P[jnp.asarray(_PHI_GATHER.tolist())] * factor[:, None] * factor[None, :]


def moments(x: jax.Array, w: jax.Array) -> jax.Array:
    """S = sum_i w_i phi(x_i) phi(x_i)' (10 x 10) for samples x (N, 3), weights w (N,), with
    the monomials phi(x) = [x^2, y^2, z^2, 2xy, 2xz, 2yz, x, y, z, 1]. Every sphere and
    quadric residual here is linear in phi, so the fits below (and the batch LM of
    :mod:`calib_jax.batch`) need only S. S holds only the 35 distinct power sums of degree
    <= 4, gathered from :func:`power_sums`."""
    return moments_from_power_sums(power_sums(x, w))


def normalised_moments(x: jax.Array, w: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    """(S, mean, scale): the moments of (x - mean) / scale with the weighted mean and the RMS
    distance from it (:func:`centre_and_scale`'s normalisation), from one pass for the mean and
    one for the power sums about it; the scale comes from those sums. Weight-0 rows may hold
    anything (NaN too)."""
    use = w > 0
    x = jnp.where(use[:, None], x, 0.0)
    n, *sums = sum_last((w, w * x[:, 0], w * x[:, 1], w * x[:, 2]))  # one pass, as below
    n = jnp.where(n > 0, n, 1.0)
    mean = jnp.stack(sums) / n
    P = power_sums(jnp.where(use[:, None], x - mean, 0.0), w)
    square = P[_POWER_INDEX[(2, 0, 0)]] + P[_POWER_INDEX[(0, 2, 0)]] + P[_POWER_INDEX[(0, 0, 2)]]
    k = jnp.sqrt(square / n)
    k = jnp.where(k > 0, k, 1.0)
    return moments_from_power_sums(P, k), mean, k


def stand_in_directions() -> np.ndarray:
    """26 directions on the unit sphere (the cube's faces, edges and corners): the well-posed
    problem the batch and the pipeline fit in place of data refused before the fit, so the
    (discarded) solve converges at once instead of running to its iteration budget."""
    d = np.array(
        [(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1) if i or j or k],
        float,
    )
    return d / np.linalg.norm(d, axis=1, keepdims=True)


NO_SHELL = 0.12
"""A fit whose relative RMS radial error is above this describes no ellipsoid shell: the
samples are a noise cloud (a sensor held still, 28-39 %), motion, or a field that changed (a
hard iron jumping by 2/3 of the field, 15 %); a tumble reaches 0.5-2 %. The single fits
(calib_jax.mag.RMS_NO_SHELL_PCT), the batch and the pipeline (:func:`shell_status`)."""


def prefit_status(S, n_params: int, min_points: int, flat_below: float, count=None):
    """The status before a moment-form or pipeline fit, inside jit: INSUFFICIENT_DATA for fewer
    valid points than ``min_points`` or than the parameters (as many is an exact fit, as in the
    single fits); NO_COVERAGE for points in one plane, whose covariance (S's second moments
    of the centred samples, :func:`normalised_moments`) has a smallest to largest eigenvalue
    ratio below ``flat_below`` (the single fits' own thresholds,
    :data:`calib_jax.accel.FLAT_POSES` and :data:`calib_jax.mag.FLAT_POINTS`); -1 otherwise.
    ``count``: the number of valid points where S was summed with weights other than 0/1 (the
    pipeline's 1/sigma^2); by default S's weight sum, the batch's count."""
    n = S[9, 9]
    scatter = S[6:9, 6:9] / jnp.maximum(n, 1.0)
    ev, _ = eigh_small(scatter)
    flat = ev[0] <= flat_below * jnp.maximum(ev[2], 1e-300)
    too_few = (n if count is None else count) < max(min_points, n_params)
    return jnp.where(
        too_few,
        int(Status.INSUFFICIENT_DATA),
        jnp.where(flat, int(Status.NO_COVERAGE), -1),
    )


RUNAWAY = 10.0
"""A fitted ellipsoid whose geometric-mean radius is this many times the samples' RMS spread
about their mean ran away: a cap of data too small (one pose held still, or a few close
together) lets any large ellipsoid through it. A tumble's ratio is about 1 (the single
magnetometer fit, calib_jax.mag; the batch and the pipeline, :func:`shell_status`)."""


def shell_status(status, rms_relative, radius_over_spread):
    """A fit's status with NO_SHELL where its relative RMS radial error is above
    :data:`NO_SHELL`, and RAN_AWAY where its ellipsoid is over :data:`RUNAWAY` times the
    samples' spread (inside jit). A fit refused before it ran, or one that failed (NONFINITE,
    SINGULAR, FAILED), keeps its code."""
    kept = (Status.INSUFFICIENT_DATA, Status.NO_COVERAGE, Status.FAILED, Status.NONFINITE)
    refused = jnp.isin(status, jnp.asarray([int(c) for c in (*kept, Status.SINGULAR)]))
    code = jnp.where(rms_relative > NO_SHELL, int(Status.NO_SHELL), status)
    code = jnp.where(radius_over_spread > RUNAWAY, int(Status.RAN_AWAY), code)  # NaN: not
    return jnp.where(refused, status, code).astype(jnp.asarray(status).dtype)


def centre_and_scale(x: jax.Array, w: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Weighted mean (3,) and RMS distance from it of samples x (N, 3): the one normalisation
    of the batch and pipeline fits (x -> (x - mean) / scale). Weight-0 rows are padding and
    may hold anything; no spread gives scale 1."""
    use = w > 0
    x = jnp.where(use[:, None], x, 0.0)
    n = jnp.sum(w)
    n = jnp.where(n > 0, n, 1.0)
    mean = (w @ x) / n
    d = jnp.where(use[:, None], x - mean, 0.0)
    k = jnp.sqrt(jnp.sum(w * jnp.sum(d * d, axis=1)) / n)
    return mean, jnp.where(k > 0, k, 1.0)


def sphere_fit(x: jax.Array, w: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Weighted algebraic sphere fit |x - c|^2 = r^2, see :func:`sphere_fit_moments`."""
    return sphere_fit_moments(moments(x, w))


def sphere_fit_points(x: np.ndarray) -> tuple[np.ndarray, float]:
    """:func:`sphere_fit` of host points (N, 3), equal weights: padded to a power of two and
    compiled once per size (kept on disk, :class:`calib_jax.runtime.DiskJit`). For the
    host-side checks of the single fits; eager, its few dozen operations each cost a dispatch.
    """
    c, r = _SPHERE_FIT(*pad_rows(np.asarray(x, float)))
    return np.asarray(c), float(r)


def sphere_fit_moments(S: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Algebraic sphere fit from the moment matrix: |x|^2 = 2 c.x + d, d = r^2 - |c|^2.

    The 4x4 normal equations use the columns [2x, 2y, 2z, 1] = phi[6:10] * [2, 2, 2, 1] and the
    target |x|^2 = phi[0] + phi[1] + phi[2]. Returns (centre (3,), radius).
    """
    k = jnp.array([2.0, 2.0, 2.0, 1.0], S.dtype)
    AtA = S[6:10, 6:10] * jnp.outer(k, k)
    Atb = k * (S[6:10, 0] + S[6:10, 1] + S[6:10, 2])
    sol = cho_solve_small(AtA, Atb)
    c, d = sol[:3], sol[3]
    return c, jnp.sqrt(jnp.maximum(d + c @ c, 0.0))


_SPHERE_FIT = disk_jit(sphere_fit, "geometry.sphere_fit")


def ellipsoid_fit_moments(S: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Algebraic ellipsoid fit (x - c)' M (x - c) = 1 with M symmetric, from the moments.

    Fits the quadric x' A x + v' x = 1 (nine unknowns, design phi[0:9]) by linear least
    squares, then c = -A^-1 v / 2 and M = A / (1 + c' A c). For a usable start, data should be
    centred and scaled to about unit radius first. Returns (centre, M, ok) where ok says M is
    positive definite (an ellipsoid, not a hyperboloid: with poor coverage the unconstrained
    quadric can be either, and then the caller must fall back to a sphere).
    """
    u = cho_solve_small(S[:9, :9], S[:9, 9])
    A = jnp.array([[u[0], u[3], u[4]], [u[3], u[1], u[5]], [u[4], u[5], u[2]]])
    v = u[6:9]
    evals, evecs = eigh_small(A)
    pd = jnp.all(evals > 0) & jnp.all(jnp.isfinite(u))
    safe = jnp.where(pd, evals, 1.0)
    Ainv = (evecs / safe) @ evecs.T
    c = -0.5 * Ainv @ v
    s = 1.0 + c @ A @ c
    M = A / s
    ok = pd & (s > 0)
    return c, M, ok


def sqrtm_inv_spd(M: jax.Array) -> jax.Array:
    """M^(-1/2) for a symmetric positive-definite 3x3 M (symmetric result)."""
    evals, evecs = eigh_small(M)
    return (evecs / jnp.sqrt(evals)) @ evecs.T


# ---------------------------------------------------------------------------------------------
# Paper 2, section 2.2: the quadric, its matrix form and its eigen-analysis


# Li-Griffiths' design [x^2, y^2, z^2, 2yz, 2xz, 2xy, 2x, 2y, 2z, 1] = phi @ _LG
_LG = np.zeros((10, 10))
for _col, (_row, _k) in enumerate(
    [(0, 1), (1, 1), (2, 1), (5, 1), (4, 1), (3, 1), (6, 2), (7, 2), (8, 2), (9, 1)]
):
    _LG[_row, _col] = _k


def ellipsoid_fit_constrained(
    x: jax.Array, w: jax.Array, k: float = 4.0
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Ellipsoid-specific fit of samples, see :func:`ellipsoid_fit_constrained_moments`."""
    return ellipsoid_fit_constrained_moments(moments(x, w), k)


def ellipsoid_fit_constrained_moments(
    Sphi: jax.Array, k: float = 4.0
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Ellipsoid-specific algebraic fit (Li and Griffiths 2004), pure and jittable.

    Fits paper 2's quadric (eq. 4) ``a x^2 + b y^2 + c z^2 + 2f yz + 2g xz + 2h xy + 2p x + 2q y
    + 2r z + d = 0`` by weighted linear least squares subject to ``k J - I^2 = 1`` with
    ``I = a + b + c`` and ``J = ab + bc + ca - f^2 - g^2 - h^2``. With k = 4 the constraint
    admits only ellipsoids, so the fit is never a hyperboloid, whatever the coverage (it favours
    ellipsoids whose shortest axis is at least half the longest; the LM refinement removes that
    bias). The constrained problem is the generalised eigenproblem ``M v = lam C v`` of
    Li-Griffiths, solved here as a symmetric one, ``H C H u = (1/lam) u`` with
    ``H = M^(-1/2)``, so it needs only the Jacobi ``eigh_small``.

    x should be centred and scaled to about unit radius. Returns (centre, M, ok) with the
    ellipsoid ``(x - c)' M (x - c) = 1``; ok is False for degenerate data (a plane, a line).
    """
    T = jnp.asarray(_LG, Sphi.dtype)
    S = T.T @ Sphi @ T
    S11, S12, S22 = S[:6, :6], S[:6, 6:], S[6:, 6:]
    S22inv_S21 = cho_solve_small(S22, S12.T)
    Mr = S11 - S12 @ S22inv_S21
    Mr = 0.5 * (Mr + Mr.T)
    d, V = eigh_small(Mr)
    # noise-free data make Mr singular (the exact quadric is its null vector): floor the
    # eigenvalues at round-off, so the null direction dominates H C H as it should
    floor = 1e-13 * jnp.max(d)
    d_ok = jnp.all(d > -1e-9 * jnp.max(d)) & (jnp.max(d) > 0)
    H = (V / jnp.sqrt(jnp.maximum(d, floor))) @ V.T
    h = k / 2.0 - 1.0
    dt = Sphi.dtype
    C = jnp.zeros((6, 6), dt)
    C = C.at[:3, :3].set(jnp.array([[-1.0, h, h], [h, -1.0, h], [h, h, -1.0]], dt))
    C = C.at[3:, 3:].set(-k * jnp.eye(3, dtype=dt))
    mu, U = eigh_small(H @ C @ H)
    v1 = H @ U[:, -1]  # the single positive eigenvalue (C has inertia (1, 5))
    v1 = jnp.where(v1[0] + v1[1] + v1[2] < 0, -v1, v1)
    v2 = -S22inv_S21 @ v1
    a, b, c, f, g, hh = v1
    A = jnp.array([[a, hh, g], [hh, b, f], [g, f, c]])
    centre = -inv3(A) @ v2[:3]
    k0 = centre @ A @ centre - v2[3]
    M = A / k0
    evals, _ = eigh_small(M)
    ok = d_ok & (mu[-1] > 0) & jnp.all(evals > 0) & jnp.all(jnp.isfinite(M))
    ok = ok & jnp.all(jnp.isfinite(centre))
    return centre, M, ok


def quadric_matrix(centre: jax.Array, M: jax.Array) -> jax.Array:
    """Paper 2's matrix form S (eq. 6-8) of the ellipsoid (x - c)' M (x - c) = 1.

    X S X' = 0 with X = [x, y, z, 1]; S is scaled so that its (4, 4) entry is ``c'Mc - 1``.
    """
    top = jnp.concatenate([M, -(M @ centre)[:, None]], axis=1)
    bottom = jnp.concatenate([-(M @ centre), jnp.array([centre @ M @ centre - 1.0])])
    return jnp.concatenate([top, bottom[None, :]], axis=0)


def ellipsoid_from_quadric(S: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
    """Paper 2's eigen-analysis (eq. 9-20) of a quadric in matrix form S (4 x 4, eq. 8).

    Centre: the point where the gradient of X S X' vanishes (eq. 9). Translation T (eq. 10):
    S* = T S T' (eq. 11) has no linear terms; dividing by its constant term gives the canonical
    form x' A x = 1 (eq. 12-15). The eigen-decomposition A = R D R' (eq. 16-18) gives the DCM R
    (eigenvectors as columns, det +1) and the semi-axes 1/sqrt(D) (eq. 19-20).

    Returns (centre, A, R, semi_axes), the semi-axes ascending in eigenvalue order
    (descending in length).
    """
    A3 = S[:3, :3]
    centre = -inv3(A3) @ S[:3, 3]
    T = jnp.eye(4, dtype=S.dtype).at[3, :3].set(centre)
    Sc = T @ S @ T.T
    A = -Sc[:3, :3] / Sc[3, 3]
    evals, R = eigh_small(0.5 * (A + A.T))
    R = R * jnp.where(jnp.linalg.det(R) < 0, -1.0, 1.0)
    return centre, A, R, 1.0 / jnp.sqrt(evals)


def compensation_matrix(R: jax.Array, semi_axes: jax.Array, radius: float | jax.Array) -> jax.Array:
    """Paper 2's compensation as one matrix: rotate into the ellipsoid's axes (R'), scale each
    axis to the sphere of ``radius``, rotate back (R). Equals ``radius * sqrtm(M)``."""
    return (R * (radius / semi_axes)) @ R.T
