"""Acceptance tests that stay honest when samples are correlated (issue 15).

A fit's formal standard errors assume independent samples. The samples of a tumble are
correlated over seconds (the hand's acceleration, a filtered magnetometer), so formal errors
can be 5-10x too small: a real, large effect then fails the split-halves test and a spurious
small one passes significance. Every diagnosis (accelerometer, magnetometer, MARG) judges a
candidate effect with the same three honest tests, all from leave-one-block-out refits over
contiguous stretches of the log (:func:`calib_jax.align.block_jackknife_cov`):

* ``honest``: "no effect" is rejected at :data:`HONEST_ALPHA` over the round's candidates
  twice: by Hotelling's T^2 with the jackknife covariance (:func:`hotelling_p`, F(p, K - p)
  for K blocks) and by a Wald test whose covariance models the slow noise
  (:func:`slow_noise`, :func:`sandwich_cov`). Each alone lets false effects through on logs
  whose noise is correlated over about a block: the jackknife of 16 blocks of 125 samples
  under AR(1) noise with phi 0.99 gives 0.40 / 0.51 / 0.69 of the true variance of a mean, a
  trend and a slow sine (1,000 draws each), and on simulated 40 s magnetometer tumbles with
  noise correlated over 2 s Hotelling alone accepted a false effect on 4 of 40 clean logs.
  The Wald test's p-values there were 0.003-0.07 where Hotelling's were 1e-4 to 2e-3;
  together, none of the 40 kept a false effect;
* ``halves``: the effect fitted on two halves of the log agrees within :data:`HALVES_Z` of the
  halves' formal errors inflated by the correlation factor the jackknife finds on the full
  log, or within :data:`HALVES_STABLE` of the effect's size;
* ``held_out``: the errors each block gets from the fit without it fall by more than
  :data:`HELD_OUT_GAIN` against the current model's (:func:`held_out_rms`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..align import block_jackknife_cov

HALVES_Z = 3.0
"""The halves' difference, in their formal errors inflated by the correlation factor."""
HALVES_STABLE = 0.25
"""Halves that differ by less than this fraction of the effect's size agree, whatever the
standard errors say: a large effect stable in sign and size is real for a user."""
HONEST_ALPHA = 0.01
"""The effect's coefficients must differ from zero at this level by Hotelling's T^2 with the
jackknife covariance: a significance that holds for correlated samples, where BIC,
leave-one-out and the null test's likelihoods assume independence. Familywise over the
candidates tried in a round (Bonferroni: each at HONEST_ALPHA / their number): a clean log
is judged once per candidate, and the false-alarm target is per log. Measured on simulated
magnetometer tumbles with noise correlated over 2 s (10 seeds each, ``benchmarks/
diagnosis_power.py``'s logs), 0.01 per candidate accepted a term on 4 of 10 clean logs with
the full ellipsoid declared and 2 of 10 with a sphere (temperature bias at p 0.004-0.009); per
log, 0 and 1 of 10, while a 3x drift was found as often (4 of 10) and 3x soft iron in 4 of
10 instead of 6."""
HELD_OUT_GAIN = 0.01
"""The held-out RMS must fall by more than 1 %."""


class SlowNoise(NamedTuple):
    """Noise of the magnitude residual e_t = u_t . n_t + v_t: a slow vector noise n_t in the
    sensor frame, each axis AR(1) with coefficient ``phi`` per observation and variance ``s2``,
    seen through the unit direction u_t of the reading, plus white noise of variance ``w2``.
    While the board turns, n_t stays coherent: to the residual it looks like a hard iron (or
    bias) that wanders in time, which no stationary model of e alone describes (branch
    try/gls-ar1: fits whitened by an AR(1) of e found a drift at p 1e-4 to 7e-7 in 5 of 10
    clean logs)."""

    s2: float
    phi: float
    w2: float


def slow_noise(e: np.ndarray, u: np.ndarray, longest: float) -> SlowNoise:
    """:class:`SlowNoise` fitted to the autocovariance of ``e`` (rows in time order, ``u``
    their unit directions) at lags 0..min(3 ``longest``, m / 4): for each phi on a grid of
    correlation times -1 / ln(phi) from 0.3 to ``longest`` observations, s2 and w2 by
    non-negative least squares on gamma(k) = s2 phi^k c(k) + w2 [k = 0], c(k) the mean of
    u_t . u_(t+k); the phi that fits best is kept. Lags count observations, evenly spaced or
    not (a pose table's means: their order).

    ``longest`` must stay well below the log's length: noise correlated over much of the log
    is, to any test, the effect itself (a bias that wanders over the whole log is a drift),
    and a model allowed such noise explained a real drift at 1.4x the floor as noise (the
    diagnosis passes one jackknife block, :data:`calib_jax.diagnose.loop.BLOCKS`)."""
    from scipy.optimize import nnls

    e = np.asarray(e, float) - np.mean(e)
    m = len(e)
    lags = np.arange(max(1, min(int(3 * longest), m // 4)) + 1)
    g = np.array([e[: m - k] @ e[k:] / m for k in lags])
    c = np.array([np.mean(np.sum(u[: m - k] * u[k:], axis=1)) for k in lags])
    best = (np.inf, SlowNoise(0.0, 0.0, float(g[0])))
    for phi in np.exp(-1.0 / np.geomspace(0.3, max(longest, 0.3), 120)):
        A = np.column_stack([phi**lags * c, (lags == 0).astype(float)])
        x, r = nnls(A, g)
        if r < best[0]:
            best = (r, SlowNoise(float(x[0]), float(phi), float(x[1])))
    return best[1]


def sandwich_cov(J: np.ndarray, u: np.ndarray, noise: SlowNoise) -> np.ndarray:
    """Covariance of least-squares parameters under :class:`SlowNoise`: (J'J)^-1 J' S J
    (J'J)^-1 with S_st = s2 phi^|s-t| u_s . u_t + w2 [s = t] (rows of J and u in time order;
    S applied by a forward and a backward AR(1) recursion per axis, never formed)."""
    from .floors import _ar1_times

    JtJ = J.T @ J
    B = noise.w2 * JtJ
    for a in range(3):
        Z = J * u[:, [a]]
        B = B + noise.s2 * Z.T @ _ar1_times(Z, noise.phi)
    Ji = np.linalg.inv(JtJ)
    return Ji @ B @ Ji


def wald_p(theta: np.ndarray, cov: np.ndarray) -> float:
    """p-value of theta = 0 with a known covariance (chi2 with len(theta) degrees)."""
    from scipy import stats

    try:
        t2 = float(theta @ np.linalg.solve(cov, theta))
    except np.linalg.LinAlgError:
        return float("nan")
    return float(stats.chi2.sf(t2, len(theta)))


def hotelling_p(theta: np.ndarray, cov: np.ndarray, k: int) -> float:
    """p-value of theta = 0 with a covariance estimated from k blocks (T^2 -> F(p, k - p))."""
    from scipy import stats

    p = len(theta)
    if k <= p:
        return float("nan")
    try:
        t2 = float(theta @ np.linalg.solve(cov, theta))
    except np.linalg.LinAlgError:
        return float("nan")
    return float(stats.f.sf((k - p) / (p * (k - 1)) * t2, p, k - p))


def held_out_rms(jack_errors: list[np.ndarray], block: np.ndarray, w: np.ndarray) -> float:
    """RMS of each block's errors predicted by the fit without that block (``jack_errors[b]``,
    every observation's error under the fit that left block b out): what the model predicts
    on data it has not seen, where a tumble's neighbouring samples (which single-sample
    leave-one-out keeps in the fit) are correlated."""
    e = np.concatenate([eb[(block == b) & (w > 0)] for b, eb in enumerate(jack_errors)])
    return float(np.sqrt(np.mean(e**2)))


def judge(
    coef: np.ndarray,
    half1: np.ndarray,
    half2: np.ndarray,
    jack: np.ndarray,
    formal_se_halves: np.ndarray,
    formal_se: np.ndarray,
    tried: int = 1,
    slow_cov: np.ndarray | None = None,
) -> dict:
    """The honest numbers and two of the tests for one effect's coefficients ``coef``: its
    fits on the two halves, its K leave-one-block-out fits ``jack`` (K, p), the halves'
    combined formal standard error sqrt(se1^2 + se2^2) and the full fit's formal standard
    errors; ``tried``: how many candidates the round judges (:data:`HONEST_ALPHA`);
    ``slow_cov``: the coefficients' covariance under the log's slow noise
    (:func:`sandwich_cov`), for the second half of the ``honest`` test (None: Hotelling's
    alone, as the MARG loop judges).

    The halves' difference is judged against their own formal errors (a half can determine
    an effect much worse than the full log, beyond the factor 2 of its sample count: a tumble's
    halves cover fewer orientations per time) inflated by the correlation factor the full log
    shows, jackknife over formal error (at least 1: below, it is the jackknife's own noise)."""
    cov = block_jackknife_cov(jack)
    se = np.sqrt(np.diag(cov))
    p = hotelling_p(coef, cov, len(jack))
    diff = half1 - half2
    inflation = np.maximum(se / formal_se, 1.0)
    z = np.abs(diff) / (formal_se_halves * inflation)
    size = float(np.linalg.norm(coef))
    stable = bool(np.linalg.norm(diff) <= HALVES_STABLE * size)
    finite = bool(np.all(np.isfinite(z)))
    alpha = HONEST_ALPHA / max(tried, 1)
    p_slow = float("nan") if slow_cov is None else wald_p(coef, slow_cov)
    return {
        "stderr_honest": se,
        "p_honest": p,
        "halves_max_z": float(np.max(z)) if z.size else 0.0,
        "halves_max_z_formal": float(np.max(np.abs(diff) / formal_se_halves)) if z.size else 0.0,
        "halves_difference_of_size": float(np.linalg.norm(diff)) / max(size, 1e-300),
        "halves": finite and (float(np.max(z, initial=0.0)) < HALVES_Z or stable),
        "p_slow_noise": p_slow,
        "honest_alpha": alpha,
        "honest": bool(p < alpha and (slow_cov is None or p_slow < alpha)),
    }
