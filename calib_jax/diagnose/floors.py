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
