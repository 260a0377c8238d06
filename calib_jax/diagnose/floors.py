"""Noise floors: what the residual of a perfect model would still be.

Two floors, both reported, the larger one used (issue 6): on the imu_tk Xsens log the white
floor alone (0.034 mg) would call a clean nine-parameter fit (0.10 mg) 3x above noise, while
the Allan deviation at the interval length (0.12 mg) shows the means wander that much anyway.

* white: the standard error of each interval mean from its own scatter, std / sqrt(n), RMS
  over the intervals. Right for white noise, too small for anything slower.
* Allan: the overlapping Allan deviation of the calibrated norm at the interval length, from
  the longest rest in the log: how far two consecutive averages of that length differ by
  themselves (flicker, random walk, slow thermal wander included).
"""

from __future__ import annotations

import numpy as np


def allan_deviation(y: np.ndarray, n: int) -> float:
    """Overlapping Allan deviation of the series y at cluster size n (samples).

    sigma^2(n) = 1 / (2 (N - 2n + 1)) sum_k (mean(y[k+n : k+2n]) - mean(y[k : k+n]))^2.
    NaN when the series is shorter than 2n.
    """
    y = np.asarray(y, float)
    N = len(y)
    n = int(n)
    if n < 1 or N < 2 * n:
        return float("nan")
    c = np.concatenate([[0.0], np.cumsum(y - y.mean())])
    avg = (c[n:] - c[:-n]) / n  # moving averages, N - n + 1 of them
    d = avg[n:] - avg[:-n]
    return float(np.sqrt(0.5 * np.mean(d * d)))


def white_floor(norms: list[np.ndarray]) -> float:
    """RMS over intervals of std(|y|) / sqrt(n): the white-noise error of interval means."""
    se = [np.std(v, ddof=1) / np.sqrt(len(v)) for v in norms if len(v) > 1]
    return float(np.sqrt(np.mean(np.square(se)))) if se else float("nan")


def difference_noise(y: np.ndarray) -> float:
    """Per-sample white noise of a slowly varying series from its first differences (robust:
    1.4826 MAD / sqrt 2), for logs without rests (a magnetometer turned by hand)."""
    d = np.diff(np.asarray(y, float))
    if len(d) < 2:
        return float("nan")
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(2.0))


def lag1_correlation(r: np.ndarray) -> float:
    """Lag-1 autocorrelation of a residual series in time order, clipped to [0, 0.999]: the
    AR(1) coefficient the driver tests and the rest floor correct for (a negative estimate is
    noise around zero on white residuals, and correcting for it would add power, not remove
    false alarms)."""
    r = np.asarray(r, float) - np.mean(r)
    den = float(r @ r)
    if len(r) < 3 or den <= 0:
        return 0.0
    return float(np.clip(r[1:] @ r[:-1] / den, 0.0, 0.999))


def _ar1_times(x: np.ndarray, phi: float) -> np.ndarray:
    """R x for the AR(1) correlation matrix R_ij = phi^|i - j| (a forward and a backward
    recursion: no n x n matrix for rests of thousands of samples)."""
    from scipy.signal import lfilter

    f = lfilter([1.0], [1.0, -phi], x, axis=0)
    b = lfilter([1.0], [1.0, -phi], x[::-1], axis=0)[::-1]
    return f + b - x


def rest_floor(rest: np.ndarray, degree: int = 2) -> tuple[float, float]:
    """(per-sample noise, lag-1 correlation) of a rest's series: its scatter about a trend of
    ``degree`` (slow effects are what the loop looks for, not noise), with the degrees of
    freedom the trend takes from AR(1) noise of the correlation it shows.

    A trend fitted to noise correlated over many samples absorbs much of that noise: on AR(1)
    noise with lag-1 correlation 0.99 over a 480-sample rest, the plain scatter about a
    quadratic (``std(ddof=3)``, exact for white noise and what this was before) gave 0.57 of the
    noise (median of 200 series), this 0.67 (0.95 with the true correlation: the estimated
    one is low on a rest only 5 correlation times long); over 2,000 samples 0.86 and 0.95.
    White noise: identical (1.00). E[RSS] = sigma^2 trace(M R), M the trend's residual maker,
    R the AR(1) correlation; trace(M R) = n - trace((X'X)^-1 X' R X)."""
    y = np.asarray(rest, float)
    n = len(y)
    if n <= degree + 2:
        return float("nan"), 0.0
    t = np.linspace(-1.0, 1.0, n)
    X = np.vander(t, degree + 1)
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ coef
    phi = lag1_correlation(r)
    dof = n - float(np.trace(np.linalg.solve(X.T @ X, X.T @ _ar1_times(X, phi))))
    return float(np.sqrt(r @ r / max(dof, 1.0))), phi


def correlated_rest_note(phi: float, n: int) -> str:
    """What the rest's noise correlation means for its floor, or '' when it is short."""
    length = 1.0 / max(1.0 - phi, 1e-3)
    if length < 10 or n >= 20 * length:
        return ""
    return (
        f"; its noise is correlated over about {length:.0f} samples (lag-1 {phi:.3f}), and a "
        f"rest {n / length:.0f}x that long shows only part of noise that slow: the floor may be "
        "low"
    )
