"""Static-interval detection by moving variance (paper 1, section 3).

"We need to exclude measurements where the sensor is not static ... by observing the temporal
variance of the data signal. In static position the accelerometer has a low variance."

The detector computes the variance of each axis over a centred moving window, sums the three,
and calls a sample static when that sum is below a threshold. Runs of static samples shorter
than a minimum duration are dropped. Host-side numpy: it runs once per log, before any fit.

Automatic threshold: the 10th percentile of the moving variance is taken as the noise level
(any calibration log spends well over 10 % of its time at rest) and the threshold is
``threshold_factor`` (default 6) times that. With a centred window of w samples the variance
of pure white noise scatters by about sqrt(2/w) of its mean, so 6x the noise level rejects
motion without cutting static poses at their noisier samples.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class StaticInterval:
    """One run of static samples, [start, stop) in sample indices of the log."""

    start: int
    stop: int
    mean: np.ndarray
    """Mean reading over the interval (3,)."""
    std: np.ndarray
    """Per-axis standard deviation of the readings (3,)."""

    @property
    def n(self) -> int:
        return self.stop - self.start


@dataclass(frozen=True)
class StaticReport:
    """What the detector found, and the settings that found it."""

    intervals: list[StaticInterval]
    mask: np.ndarray
    """True for samples inside a kept interval, (N,)."""
    threshold: float
    """Threshold on the summed moving variance, in input units squared."""
    noise_level: float
    """The noise level the automatic threshold is based on (10th percentile)."""
    window: int
    """Moving-window length in samples."""
    min_samples: int
    """Shortest interval kept, in samples."""
    automatic: bool = field(default=True)

    @property
    def n_intervals(self) -> int:
        return len(self.intervals)

    def means(self) -> np.ndarray:
        """Interval means (n_intervals, 3)."""
        return np.array([iv.mean for iv in self.intervals]).reshape(-1, 3)

    def summary(self, sample_rate: float | None = None) -> str:
        """A one-paragraph report of the intervals found."""
        lens = np.array([iv.n for iv in self.intervals])
        unit = "samples"
        if sample_rate:
            lens = lens / sample_rate
            unit = "s"
        if len(lens) == 0:
            return "no static intervals"
        how = "automatic" if self.automatic else "given"
        return (
            f"{len(lens)} static intervals, {int(self.mask.sum())} samples "
            f"({100 * self.mask.mean():.0f} % of the log); lengths {lens.min():.3g}-"
            f"{lens.max():.3g} {unit} (median {np.median(lens):.3g}); threshold "
            f"{self.threshold:.3g} ({how}), window {self.window} samples"
        )


def moving_variance(x: np.ndarray, window: int) -> np.ndarray:
    """Sum over axes of the per-axis variance in a centred window of ``window`` samples.

    Edges use the part of the window inside the log. Computed with cumulative sums of the
    mean-removed data (O(N), numerically safe for raw counts near 32768).
    """
    x = np.asarray(x, float)
    x = x - x.mean(axis=0)
    n = len(x)
    half = window // 2
    c1 = np.vstack([np.zeros((1, 3)), np.cumsum(x, axis=0)])
    c2 = np.vstack([np.zeros((1, 3)), np.cumsum(x * x, axis=0)])
    idx = np.arange(n)
    lo = np.clip(idx - half, 0, n)
    hi = np.clip(idx + half + 1, 0, n)
    cnt = (hi - lo)[:, None]
    s1 = c1[hi] - c1[lo]
    s2 = c2[hi] - c2[lo]
    var = np.maximum(s2 / cnt - (s1 / cnt) ** 2, 0.0)
    return var.sum(axis=1)


def detect_static(
    x: np.ndarray,
    *,
    sample_rate: float | None = None,
    window: int | None = None,
    threshold: float | None = None,
    threshold_factor: float = 6.0,
    min_duration: float | None = None,
    min_samples: int | None = None,
    valid: np.ndarray | None = None,
) -> StaticReport:
    """Find the static intervals of a log of 3-axis readings.

    Parameters
    ----------
    x : (N, 3) array
        Readings, any unit.
    sample_rate : float, optional
        Hz. With it, ``window`` defaults to 1 s and ``min_duration`` to 1 s; without it, to
        100 samples and 100 samples.
    threshold : float, optional
        Fixed threshold on the summed moving variance (input units squared). Default: automatic
        (module docstring).
    threshold_factor : float
        Multiple of the noise level used by the automatic threshold.
    min_duration : float, optional
        Shortest interval kept, in seconds (needs ``sample_rate``); or give ``min_samples``.
    valid : (N,) bool array, optional
        Samples allowed in intervals (False for non-finite or saturated samples).
    """
    x = np.asarray(x, float)
    n = len(x)
    if window is None:
        window = int(round(sample_rate)) if sample_rate else 100
    window = max(int(window), 3)
    if min_samples is None:
        if min_duration is not None:
            if not sample_rate:
                raise ValueError("min_duration needs sample_rate; or give min_samples instead")
            min_samples = int(round(min_duration * sample_rate))
        else:
            min_samples = window
    valid = np.ones(n, bool) if valid is None else np.asarray(valid, bool)
    mv = moving_variance(np.where(valid[:, None], x, np.nan_to_num(x[valid].mean(axis=0))), window)
    usable = mv[valid]
    noise = float(np.percentile(usable, 10)) if usable.size else float("nan")
    automatic = threshold is None
    if automatic:
        threshold = threshold_factor * noise if noise > 0 else float(np.finfo(float).tiny)
    still = (mv <= threshold) & valid
    # runs of True
    d = np.diff(np.concatenate([[0], still.astype(np.int8), [0]]))
    starts = np.flatnonzero(d == 1)
    stops = np.flatnonzero(d == -1)
    intervals = []
    mask = np.zeros(n, bool)
    for a, b in zip(starts, stops, strict=True):
        if b - a >= min_samples:
            seg = x[a:b]
            intervals.append(
                StaticInterval(start=int(a), stop=int(b), mean=seg.mean(0), std=seg.std(0, ddof=1))
            )
            mask[a:b] = True
    return StaticReport(
        intervals=intervals,
        mask=mask,
        threshold=float(threshold),
        noise_level=noise,
        window=window,
        min_samples=int(min_samples),
        automatic=automatic,
    )


def distinct_directions(points: np.ndarray, centre: np.ndarray, min_angle_deg: float = 10.0) -> int:
    """Number of distinct directions among ``points - centre`` (greedy, min_angle apart)."""
    v = np.asarray(points, float) - centre
    nrm = np.linalg.norm(v, axis=1)
    v = v[nrm > 0] / nrm[nrm > 0, None]
    cos_min = np.cos(np.deg2rad(min_angle_deg))
    reps: list[np.ndarray] = []
    for u in v:
        if not reps or np.max(np.array(reps) @ u) < cos_min:
            reps.append(u)
    return len(reps)
