"""Static-interval detection by moving variance (paper 1, section 3), settings chosen from the data.

"We need to exclude measurements where the sensor is not static ... by observing the temporal
variance of the data signal. In static position the accelerometer has a low variance."

One setting (window w, threshold factor f): the variance of each axis over a centred window of
w samples, summed over the axes, is compared with f times the noise level (the 10th percentile
of that moving variance: any calibration log spends well over 10 % of its time at rest). Runs of
static samples at least ``min_samples`` long are kept, and each run loses ``trim`` samples at
both ends (default half a window, at least 0.1 s) so that the slow start and end
of a hand motion, quiet enough to pass the threshold, do not leak into the interval means.

No one setting suits every log: a 1 s window merges 0.5 s poses into the motion around them, a
5-sample window splits a hand-held pose at its tremor. Like imu_tk (Tedaldi et al. 2014,
section IV-A), which sweeps the threshold multiplier and keeps the setting whose calibration
fits best, the detector sweeps a grid of (window, factor) candidates and scores each with a
cheap host-side fit of its interval means: an algebraic ellipsoid (nine parameters, the same
count as paper 1's model), with

    score = rms_dof / sqrt(n_poses),   rms_dof = sqrt(sum r_i^2 / (n - 9)),

r_i = sqrt((m_i - c)' M (m_i - c)) - 1 the radial residual of mean i, n the number of intervals
and n_poses the number of distinct gravity directions among them (10 degrees apart, greedy).
The score is a proxy for the standard error of the parameters: it falls with every genuine
pose found and with longer, quieter intervals; it rises when motion leaks into a mean (larger
residual), and splitting one pose in two adds intervals but no pose. A candidate needs at
least 12 intervals and 12 distinct poses (9 parameters and some redundancy). Quiet stretches
whose means lie far off the ellipsoid through the others (pauses inside a motion, where the
hand's acceleration adds to gravity) are left out and reported. A candidate whose means
misfit their ellipsoid by ``LEAK_RATIO`` times the sweep's median or more took motion for
poses (a six-face log whose slow turns a loose threshold counts) and is not scored. Ties
(scores within their own scatter) go to the most poses held, the fewest split, and the median
threshold factor (see ``_choose``). When no candidate qualifies (six-face protocols, one long
rest, tumbles), the setting kept is one that found the pose count most settings found, near
the classic factor 6, whose runs still hold those poses once refined (below); when no
setting found two poses, the classic setting: a 1 s window (100 samples without a rate),
factor 6, runs of at least one window.

The moving variance of a short window hides a slow motion under the noise (two poses a few
tens of degrees apart joined by a 2 s motion change the reading by less than the noise from one
sample to the next), so the chosen setting's runs can reach past the trim into a motion, or
span two poses. Each run is therefore tested as a whole, where all of its samples give the
reference mean: for a ramp starting in its last (or first) window plus twice the trim of
samples (a constant, then a straight line: the start of a motion), and for a change of mean
inside it (two poses joined by a quiet motion). The most significant (F statistic beyond
``RAMP_F``, or beyond ``RAMP_MEDIAN`` times the median over the runs when the noise is not
white) is cut off or split at, and the pieces are tested again. The runs are tested before
their trim, which is then applied to the pieces: the test sees all of a motion's start that
passed the threshold (the few samples of it a trimmed run keeps are too few to tell from
noise), and the trim stays as a margin, since a cut falls a sample or two into the motion as
often as before it. A change of mean splits a run only when the two means lie ``SPLIT`` of
the radius apart: a slow drift within one pose does not split it. Only the chosen setting is
refined (the sweep scores the raw runs), and an explicit ``trim`` turns it off.

Explicit ``window``, ``threshold_factor``, ``threshold``, ``min_duration`` / ``min_samples``
and ``trim`` fix their dimension of the sweep; the rest is still chosen.

Pose tables (one row per pose, already averaged, no time column; Magneto's input format) are
recognised before any of this: neighbouring rows lie far apart compared with the spread of the
data, they do not repeat, and there are few rows. Each row is then one interval of one sample.

Host-side numpy; the log is read once: cumulative sums of the centred data give every window's
moving variance and every interval's mean in O(N).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field, replace

import numpy as np

from .sphere import sphere_cells

# classic single setting (kept when no sweep candidate can be scored)
DEFAULT_FACTOR = 6.0
DEFAULT_WINDOW_S = 1.0
DEFAULT_WINDOW_SAMPLES = 100
# threshold multipliers swept (geometric, 1.5 ... 200: at a 3-sample window the 10th
# percentile of the moving variance at rest is ~0.4 of its mean and its 99.9th ~3.7, so static
# samples need factors near 10; a long window at rest scatters little and needs ~2)
FACTOR_GRID = (1.5, 2.0, 3.0, 4.0, 6.0, 9.0, 14.0, 20.0, 30.0, 50.0, 80.0, 150.0)
# windows swept: geometric from 3 samples (or 0.05 s) to 1 s (or, without a rate, to N/50,
# at most 1000 samples)
N_WINDOWS = 8
MIN_WINDOW_S = 0.05
# least trim at each end of a run, with a rate (s): a slow hand motion starts by less than the
# noise per sample (a 20-degree turn over 2 s at 20 Hz: 9 mg a sample against 10 mg), and no
# test tells its first one or two samples from the pose; 0.1 s is two samples at 20 Hz
MIN_TRIM_S = 0.1
# shortest run kept by the sweep when the rate is known (s); else one window
MIN_RUN_S = 0.25
# scoring
MIN_POSES = 12
FEWEST_POSES = 6
"""The fewest distinct poses any accelerometer model fits (six faces, six parameters)."""
PLATEAU = 0.1
"""The share of the settings tried that must find a pose count for the most-poses fallback to
prefer it to the commonest count when that one is too few to fit (:data:`FEWEST_POSES`)."""
N_PARAMS = 9
# means further than this many robust standard deviations off the fitted ellipsoid are pauses
# inside a motion (gravity plus the hand's acceleration), not poses
OFF_SPHERE = 8.0
# scores closer than this (relative) are statistically the same: the dof-corrected rms of
# n - 9 residuals scatters by 1 / sqrt(2 (n - 9)), 10 % at n = 60
SCORE_TIE = 0.1
# a candidate whose means misfit their ellipsoid by more than this many times the median
# misfit over the sweep took motion for poses, and is not scored: a six-face log with turns
# between the faces (sensbiotk's FOX calibration, 200 Hz) held its 6 faces at 1e-3 under most
# settings, and only loose thresholds found the 12 poses a score needs, by counting the slow
# parts of the turns, at 8e-3 to 2e-2 (7-17x the median). Scorable candidates of 15 real logs
# with genuine poses lie within 2.2x of their sweep's median (a hand-held MPU-9150 with pauses
# the highest), of the hand-held x-io log that is never turned over, 60x
# (benchmarks/detector_leaks.py)
LEAK_RATIO = 4.0
# consecutive interval means closer than this fraction of the radius (~6 degrees) are one pose
# (split by a noise spike, or the settling just after the pose was taken): protocols move
# further than that from one pose to the next
SPLIT = 0.1
# a ramp at a run's end (a slow motion starting) or a change of mean inside a run is cut off
# when its F statistic exceeds this (about the 99.9th percentile of the largest of a run's
# F values under white noise) or this many times the median over the runs (noise that is not
# white inflates every run's F alike)
RAMP_F = 12.0
RAMP_MEDIAN = 5.0
# longer logs are swept on every k-th sample (k = ceil(N / this)): the moving variance and
# the runs cost O(N) per candidate, and two million samples hold any protocol's poses
MAX_SWEEP_SAMPLES = 2_000_000
# pose tables
POSE_TABLE_MAX_ROWS = 10_000
POSE_TABLE_STEP = 0.1
"""Rows are poses when their 25th-percentile neighbour distance exceeds this fraction of the
data's rms radius (a time series at rest has neighbour distances at the noise level)."""
POSE_TABLE_DISTINCT = 0.5
"""A pose table's rows are means, which never repeat exactly; a time series read in coarse
steps does (an MPU-9150 lying still, printed to 0.01 g: 1700 rows, a few dozen distinct,
neighbour steps of one step against a spread of one step, on a lattice an ellipsoid can pass
through). At least this fraction of the rows must be distinct."""
SPHERE_RMS = 0.05
"""Points lie on one ellipsoid when the algebraic ellipsoid fit leaves a dof-corrected radial
rms below this fraction of its radius (poses: 1e-3 to 1e-2). The noise of one pose fills a
blob, not a shell (rms 0.4-0.5): a board that never moved, read in integer counts, has
neighbour steps of a whole count against a radius under one count and would otherwise pass
the step test of a pose table."""


@dataclass(frozen=True)
class StaticInterval:
    """One run of static samples, [start, stop) in sample indices of the log (after trimming)."""

    start: int
    stop: int
    mean: np.ndarray
    """Mean reading over the interval (3,)."""
    std: np.ndarray
    """Per-axis standard deviation of the readings (3,); NaN for a one-sample interval."""

    @property
    def n(self) -> int:
        return self.stop - self.start


@dataclass(frozen=True)
class Candidate:
    """One detector setting tried by the sweep, and how its interval means fit."""

    window: int
    factor: float | None
    """Threshold factor (None when a fixed threshold was given)."""
    threshold: float
    n_intervals: int
    n_poses: int
    """Distinct gravity directions among the interval means (10 degrees apart)."""
    rms: float
    """Dof-corrected radial rms of the algebraic ellipsoid fit to the means (fraction of the
    radius); NaN when it could not be scored."""
    score: float
    """rms / sqrt(n_poses); lower is better; inf when not scorable."""
    n_off: int = 0
    """Intervals left out as pauses in motion (off the fitted ellipsoid)."""
    n_split: int = 0
    """Intervals that repeat the pose before them (a pose split by a noise spike; a run cut
    by an invalid sample does not count)."""
    n_held: int = 0
    """Intervals that start a new pose (neither a split nor the rest of a run cut by an
    invalid sample): the poses found, closer than 10 degrees included."""
    motion: bool = False
    """Not scored: its means misfit their ellipsoid by ``LEAK_RATIO`` times the sweep's median
    or more (motion taken for poses)."""

    def to_dict(self) -> dict:
        return {
            "window": self.window,
            "factor": self.factor,
            "threshold": self.threshold,
            "n_intervals": self.n_intervals,
            "n_poses": self.n_poses,
            "rms": None if not np.isfinite(self.rms) else self.rms,
            "score": None if not np.isfinite(self.score) else self.score,
            "n_off": self.n_off,
            "n_split": self.n_split,
            "n_held": self.n_held,
            "motion": self.motion,
        }


@dataclass(frozen=True)
class StaticReport:
    """What the detector found, the settings that found it, and the candidates it tried."""

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
    """Shortest run kept, in samples (before trimming)."""
    automatic: bool = field(default=True)
    """True when the threshold came from the noise level (not a fixed ``threshold``)."""
    factor: float | None = None
    """Threshold factor of the chosen setting."""
    trim: int = 0
    """Samples cut from each end of every run."""
    kind: str = "log"
    """'log' (a time series), 'pose_table' (one row per pose) or 'blocks' (fixed blocks)."""
    how: str = "given"
    """'sweep' (chosen by score), 'default' (no candidate scorable: classic setting), 'given'
    (every setting explicit) or 'pose_table'."""
    candidates: list[Candidate] = field(default_factory=list)
    chosen: int | None = None
    """Index of the chosen setting in ``candidates``."""
    stride: int = 1
    """The detector read every ``stride``-th sample (logs longer than MAX_SWEEP_SAMPLES);
    window, trim and run lengths are given in samples of the full log."""
    rejected: list[tuple[int, int]] = field(default_factory=list)
    """Runs left out as pauses in motion: their means lie more than ``OFF_SPHERE`` robust
    standard deviations off the ellipsoid through the others."""
    extra_notes: list[str] = field(default_factory=list)
    """Anything else the detector did that a report should say (interleaved empty rows)."""

    @property
    def n_leaky(self) -> int:
        """Candidates not scored although they found enough poses: their means misfit their
        ellipsoid by ``LEAK_RATIO`` times the sweep's median or more (motion taken for poses)."""
        return sum(c.motion for c in self.candidates)

    @property
    def n_intervals(self) -> int:
        return len(self.intervals)

    def means(self) -> np.ndarray:
        """Interval means (n_intervals, 3)."""
        return np.array([iv.mean for iv in self.intervals]).reshape(-1, 3)

    def setting(self, sample_rate: float | None = None) -> str:
        """The chosen setting in words."""
        if self.kind == "pose_table":
            return f"pose table: {len(self.intervals)} rows, each row taken as one pose"
        if self.kind == "blocks":
            return (
                f"fixed blocks of {self.window} samples (--block): {len(self.intervals)} blocks "
                "with every sample usable, each taken as one pose; nothing detected"
            )
        w = f"window {self.window} samples"
        if sample_rate:
            w += f" ({self.window / sample_rate:.3g} s)"
        # the level is a variance summed over the axes: also said as the rms per axis, as the
        # readings are measured (two new users read "noise level 4.1e-05" of a log in g as a
        # standard deviation)
        f = (
            f"threshold {self.factor:g} x noise level {self.noise_level:.3g} (the moving "
            f"variance's 10th percentile, summed over the axes: "
            f"{np.sqrt(max(self.noise_level, 0.0) / 3):.3g} rms per axis, measured as the "
            "readings are)"
            if self.factor is not None
            else f"threshold {self.threshold:.3g} (given)"
        )
        none = (
            f"none of {len(self.candidates)} candidates found {MIN_POSES} distinct poses to score"
        )
        if self.n_leaky:
            none = (
                f"no candidate of {len(self.candidates)} could be scored: the {self.n_leaky} that "
                f"found {MIN_POSES} distinct poses or more took motion for poses, their means "
                f"misfitting their ellipsoid by {LEAK_RATIO:g}x the median over the candidates "
                "or more"
            )
        how = {
            "sweep": f"chosen by fit score from {len(self.candidates)} candidates"
            + (
                f"; {self.n_leaky} not scored: {'its' if self.n_leaky == 1 else 'their'} means "
                f"misfit {'its' if self.n_leaky == 1 else 'their'} ellipsoid "
                f"{LEAK_RATIO:g}x or more the median (motion taken for poses)"
                if self.n_leaky
                else ""
            ),
            "default": f"classic default: {none}",
            "given": "as given",
            "most_poses": f"{none}; kept a setting with the pose count most settings agree on",
        }[self.how]
        stride = f", on every {self.stride}th sample" if self.stride > 1 else ""
        return (
            f"static detection: {w}, {f}, runs of at least {self.min_samples} samples, "
            f"{self.trim} samples trimmed from each end ({how}{stride})"
        )

    def candidates_table(self, max_rows: int | None = None) -> str:
        """The candidates as a text table, best score first (``*`` marks the chosen one)."""
        if not self.candidates:
            return ""
        order = sorted(
            range(len(self.candidates)),
            key=lambda i: (not np.isfinite(self.candidates[i].score), self.candidates[i].score),
        )
        if max_rows is not None:
            order = order[:max_rows]
        lines = [
            f"  {'window':>6} {'factor':>6} {'intervals':>9} {'held':>4} {'split':>5} "
            f"{'poses':>5} {'rms':>9} score"
        ]
        for i in order:
            c = self.candidates[i]
            mark = "*" if i == self.chosen else " "
            fac = "-" if c.factor is None else f"{c.factor:g}"
            lines.append(
                f"{mark} {c.window:>6} {fac:>6} {c.n_intervals:>9} {c.n_held:>4} {c.n_split:>5} "
                f"{c.n_poses:>5} "
                f"{c.rms:>9.3g} {c.score:.3g}"
            )
        return "\n".join(lines)

    def poses_by_candidate(self) -> str:
        """One line: poses found by each window at each factor (a compact candidates table)."""
        if not self.candidates:
            return ""
        out = []
        for w in sorted({c.window for c in self.candidates}):
            row = [c for c in self.candidates if c.window == w]
            out.append(
                f"w={w}: "
                + " ".join(
                    f"{'-' if c.factor is None else f'{c.factor:g}'}:{c.n_held}" for c in row
                )
            )
        return "; ".join(out)

    def notes(self, sample_rate: float | None = None) -> list[str]:
        """What a calibration report should say about detection (setting, found, candidates)."""
        out = [self.setting(sample_rate), *self.extra_notes]
        if self.kind in ("pose_table", "blocks"):
            return out
        out.append(self.summary(sample_rate))
        if self.rejected:
            out.append(
                f"static detection left out {len(self.rejected)} quiet stretches whose means lie "
                f"more than {OFF_SPHERE:g} robust standard deviations off the ellipsoid through "
                "the others (pauses inside a motion, not poses): samples "
                + ", ".join(f"{a}-{b}" for a, b in self.rejected[:10])
                + (" ..." if len(self.rejected) > 10 else "")
            )
        if len(self.candidates) > 1:
            out.append(
                "static detection candidates (window: factor:poses held): "
                + self.poses_by_candidate()
            )
        return out

    def summary(self, sample_rate: float | None = None) -> str:
        """A one-paragraph report of the intervals found."""
        lens = np.array([iv.n for iv in self.intervals])
        unit = "samples"
        if sample_rate:
            lens = lens / sample_rate
            unit = "s"
        if self.kind in ("pose_table", "blocks"):
            return self.setting(sample_rate)
        if len(lens) == 0:
            return "no static intervals"
        how = "automatic" if self.automatic else "given"
        return (
            f"{len(lens)} static intervals, {int(self.mask.sum())} samples "
            f"({100 * self.mask.mean():.0f} % of the log); lengths {lens.min():.3g}-"
            f"{lens.max():.3g} {unit} (median {np.median(lens):.3g}); threshold "
            f"{self.threshold:.3g} ({how}), window {self.window} samples"
        )

    def to_dict(self) -> dict:
        """JSON-ready summary (no per-sample mask)."""
        return {
            "kind": self.kind,
            "how": self.how,
            "window": self.window,
            "factor": self.factor,
            "threshold": self.threshold,
            "noise_level": self.noise_level,
            "min_samples": self.min_samples,
            "trim": self.trim,
            "stride": self.stride,
            "n_intervals": self.n_intervals,
            "intervals": [[iv.start, iv.stop] for iv in self.intervals],
            "chosen": self.chosen,
            "rejected": [list(r) for r in self.rejected],
            "candidates": [c.to_dict() for c in self.candidates],
        }


# ---------------------------------------------------------------------------------------------
# building blocks


def _cumsums(
    x: np.ndarray, valid: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Mean of the valid rows of x, and cumulative sums over valid rows of the centred data,
    of its square (each (N+1, 3)) and of the valid count (N+1,)."""
    n = len(x)
    valid = np.ones(n, bool) if valid is None else valid
    mu = x[valid].mean(axis=0) if valid.any() else np.zeros(3)
    xc = np.where(valid[:, None], x - mu, 0.0)
    c1 = np.zeros((n + 1, 3))
    c2 = np.zeros((n + 1, 3))
    cn = np.zeros(n + 1)
    np.cumsum(xc, axis=0, out=c1[1:])
    np.cumsum(xc * xc, axis=0, out=c2[1:])
    np.cumsum(valid, out=cn[1:])
    return mu, c1, c2, cn


def _moving_variance(c1: np.ndarray, c2: np.ndarray, cn: np.ndarray, window: int) -> np.ndarray:
    """Summed per-axis variance of the valid samples in a centred window (inf with < 2).

    ``c2`` may be per axis (N+1, 3) or already summed over the axes (N+1,). Interior windows
    are differences of contiguous slices; only the 2 * (window // 2) edge samples index."""
    n = len(c1) - 1
    half = window // 2
    c2s = c2.sum(axis=1) if c2.ndim == 2 else c2
    m = min(half, n)
    k = max(n - half, m)
    edge_lo = np.concatenate([np.zeros(m, np.int64), np.maximum(np.arange(k, n) - half, 0)])
    edge_hi = np.concatenate([np.minimum(np.arange(m) + half + 1, n), np.full(n - k, n)])
    out = np.empty(n)
    # interior: i in [half, n - half): lo = i - half, hi = i + half + 1
    if k > m:
        w = 2 * half + 1
        s1 = c1[w : n + 1] - c1[0 : n + 1 - w]
        s2 = c2s[w : n + 1] - c2s[0 : n + 1 - w]
        cnt = cn[w : n + 1] - cn[0 : n + 1 - w]
        with np.errstate(invalid="ignore", divide="ignore"):
            var = s2 / cnt - np.einsum("ij,ij->i", s1, s1) / cnt**2
        out[m:k] = np.where(cnt >= 2, np.maximum(var, 0.0), np.inf)
    a, b = edge_lo, edge_hi
    cnt = cn[b] - cn[a]
    s1 = c1[b] - c1[a]
    with np.errstate(invalid="ignore", divide="ignore"):
        var = (c2s[b] - c2s[a]) / cnt - np.einsum("ij,ij->i", s1, s1) / cnt**2
    var = np.where(cnt >= 2, np.maximum(var, 0.0), np.inf)
    out[:m] = var[:m]
    out[k:] = var[m:]
    return out


def _noise_level(mv: np.ndarray) -> float:
    mv = mv[np.isfinite(mv)]
    if mv.size == 0:
        return float("nan")
    noise = float(np.percentile(mv, 10))
    if noise <= 0:  # quantised data resting on one count: use the quiet samples that move
        pos = mv[mv > 0]
        noise = float(np.percentile(pos, 10)) if pos.size else 0.0
    return noise


def _runs(still: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """[start, stop) of the runs of True."""
    if still.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    edges = np.flatnonzero(still[1:] != still[:-1]) + 1
    bounds = np.concatenate([[0], edges, [still.size]])
    first = 0 if still[0] else 1
    return bounds[first:-1:2], bounds[first + 1 :: 2]


def _trimmed(
    starts: np.ndarray, stops: np.ndarray, min_run: int, trim: int, valid: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Keep runs of at least ``min_run`` samples and trim ``trim`` from each end (at most a
    quarter of the run). An end where the run stops at an invalid sample (a NaN row inside a
    pose) is not a motion edge: it is not trimmed, and such a run needs half the length.
    Returns the kept [a, b) and which of them continue a run cut by an invalid sample."""
    a, b, cut, trim_a, trim_b = _kept_runs(starts, stops, min_run, trim, valid)
    return a + trim_a, b - trim_b, cut


def _kept_runs(
    starts: np.ndarray, stops: np.ndarray, min_run: int, trim: int, valid: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The runs ``_trimmed`` keeps, untrimmed, and the trim due at each end: (a, b, cut,
    trim_a, trim_b)."""
    n = len(valid)
    left_bad = (starts > 0) & ~valid[np.maximum(starts - 1, 0)]
    right_bad = (stops < n) & ~valid[np.minimum(stops, n - 1)]
    need = np.where(left_bad | right_bad, max(1, min_run // 2), min_run)
    trim_a = np.where(left_bad, 0, trim)
    trim_b = np.where(right_bad, 0, trim)
    keep = (stops - starts >= need) & (stops - starts - trim_a - trim_b >= max(2, min_run // 4))
    return starts[keep], stops[keep], left_bad[keep], trim_a[keep], trim_b[keep]


def _ramp_end(yc: np.ndarray, ss: float, span: int) -> tuple[float, int]:
    """Largest F statistic of a ramp (the start of a slow motion) in the last ``span`` samples
    of a run: yc the run's samples minus their mean (n, 3), ss their sum of squares. The model
    is a constant, then a straight line from sample t0 on (a hinge); returns (F, t0). Under
    white noise F ~ F(3, 3(n - 2)) at each t0."""
    n = len(yc)
    span = min(span, n - 3)
    if span < 2:
        return 0.0, n
    z = yc[n - span :]
    tau = np.arange(span, dtype=float)
    rs = np.cumsum(z[::-1], axis=0)[::-1]
    rts = np.cumsum((tau[:, None] * z)[::-1], axis=0)[::-1]
    j = np.arange(span - 1)
    num = rts[j] - j[:, None] * rs[j]  # sum over the ramp of (t - t0) * yc_t, per axis
    k = (span - j).astype(float)  # samples from t0 to the end
    sh = k * (k - 1) / 2.0
    var_h = (k - 1) * k * (2 * k - 1) / 6.0 - sh * sh / n
    gain = np.einsum("ij,ij->i", num, num) / var_h
    f = gain * (n - 2) / np.maximum(ss - gain, 1e-300)
    i = int(np.argmax(f))
    return float(f[i]), n - span + i


def _step(yc: np.ndarray, ss: float) -> tuple[float, int]:
    """Largest F statistic of a change of mean inside a run (two poses in one run, joined by a
    motion too slow for the moving variance): (F, k), the run split before sample k."""
    n = len(yc)
    c = np.cumsum(yc, axis=0)[:-1]
    k = np.arange(1, n, dtype=float)
    t = np.einsum("ij,ij->i", c, c) * n / (k * (n - k))
    f = t * (n - 2) / np.maximum(ss - t, 1e-300)
    f[:1] = f[-1:] = 0.0  # pieces of at least two samples
    i = int(np.argmax(f))
    return float(f[i]), i + 1


def _refined(
    x: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    cut: np.ndarray,
    trim_a: np.ndarray,
    trim_b: np.ndarray,
    span: int,
    min_len: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Runs with the slow starts and ends of motions cut off, and runs holding two poses split
    (module docstring).

    The runs come untrimmed, with the trim due at each end (``trim_a``, ``trim_b``), and are
    tested before it is applied: the ramp test then sees the whole start of a motion that the
    moving variance let through, not only the few samples the trim left of it, and finds where
    it starts. The trim is applied to the pieces the tests leave, at cut ends too: a cut is as
    likely to fall a sample or two into the motion as before it; and at both ends of a split,
    which lies inside the motion joining two poses (its ends are then cut at their ramps).

    Each run is tested for a ramp at either end (the last or first ``span`` samples of the
    trimmed run, and the trim beyond) and for a change of mean inside; the most significant, if
    beyond ``RAMP_F`` (or ``RAMP_MEDIAN`` times the median over the trimmed runs: correlated
    noise), is applied and the pieces tested again. A change of mean splits a run only when the
    two means lie ``SPLIT`` of the radius apart (two poses): a slow drift of one pose does not
    split it. Pieces shorter than ``min_len`` (after the trim) are dropped; pieces shorter than
    6 samples are kept untested."""
    if len(a) == 0:
        return a, b, cut
    trimmed = list(zip((a + trim_a).tolist(), (b - trim_b).tolist(), strict=True))
    stats = []
    for s, e in trimmed:
        y = x[s:e]
        yc = y - y.mean(axis=0)
        ss = float(np.sum(yc * yc))
        stats.append(max(_ramp_end(yc, ss, span)[0], _ramp_end(yc[::-1], ss, span)[0]))
    thr = max(RAMP_F, RAMP_MEDIAN * float(np.median(stats)))
    means = np.array([x[s:e].mean(axis=0) for s, e in trimmed])
    radius = float(np.median(np.linalg.norm(means - means.mean(axis=0), axis=1)))
    # the trim at a motion edge; an untrimmed run reaches up to this further into the motion
    edge_trim = int(max(trim_a.max(), trim_b.max()))
    reach = span + edge_trim
    out_a, out_b, out_c = [], [], []
    todo = list(
        zip(a.tolist(), b.tolist(), cut.tolist(), trim_a.tolist(), trim_b.tolist(), strict=True)
    )
    while todo:
        s, e, c, ta, tb = todo.pop()
        if e - s - ta - tb < min_len:
            continue
        if e - s - ta - tb < 6:
            out_a.append(s + ta), out_b.append(e - tb), out_c.append(c)
            continue
        y = x[s:e]
        yc = y - y.mean(axis=0)
        ss = float(np.sum(yc * yc))
        f_end, t_end = _ramp_end(yc, ss, reach)
        f_start, t_start = _ramp_end(yc[::-1], ss, reach)
        f_step, k = _step(yc, ss)
        if f_step > thr:
            d = np.linalg.norm(y[:k].mean(axis=0) - y[k:].mean(axis=0))
            if d < SPLIT * radius:
                f_step = 0.0
        best = max(f_end, f_start, f_step)
        if best <= thr:
            out_a.append(s + ta), out_b.append(e - tb), out_c.append(c)
        elif best == f_step:
            todo += [(s, s + k, c, ta, edge_trim), (s + k, e, False, edge_trim, tb)]
        elif best == f_end:
            todo.append((s, s + t_end, c, ta, tb))
        else:
            todo.append((e - t_start, e, c, ta, tb))
    order = np.argsort(out_a)
    return (
        np.asarray(out_a, np.int64)[order],
        np.asarray(out_b, np.int64)[order],
        np.asarray(out_c, bool)[order],
    )


_CELLS = sphere_cells(412)  # spacing ~ sqrt(4 pi / 412) rad: 10 degrees


def _ellipsoid(u: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """(M, c) of an algebraic ellipsoid fit to u (n, 3), (u - c)' M (u - c) = 1; None if the
    fit has no ellipsoid."""
    x, y, z = u.T
    D = np.stack([x * x, y * y, z * z, 2 * x * y, 2 * x * z, 2 * y * z, 2 * x, 2 * y, 2 * z], 1)
    v, *_ = np.linalg.lstsq(D, np.ones(len(u)), rcond=None)
    A = np.array([[v[0], v[3], v[4]], [v[3], v[1], v[5]], [v[4], v[5], v[2]]])
    try:
        c = -np.linalg.solve(A, v[6:9])
    except np.linalg.LinAlgError:
        return None
    M = A / (1.0 + c @ A @ c)
    if not np.all(np.isfinite(M)) or np.linalg.eigvalsh(M)[0] <= 0:
        return None
    return M, c


def _radial(u: np.ndarray, M: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Radial residuals of the points u (n, 3) off the ellipsoid (M, c), in radii."""
    d = u - c
    return np.sqrt(np.maximum(np.einsum("ni,ij,nj->n", d, M, d), 0.0)) - 1.0


def ellipsoid_score(means: np.ndarray) -> tuple[float, int, np.ndarray]:
    """(rms_dof, n_poses, off) of an algebraic ellipsoid fit to interval means.

    ``off`` marks means more than ``OFF_SPHERE`` robust standard deviations (1.4826 MAD) off
    the fitted ellipsoid: quasi-static pauses inside a motion, where the hand's acceleration
    adds to gravity. The fit is repeated without them, and the test with it, until the means
    off stop changing (a pause pulls the fit towards itself and widens the MAD, and can hide
    another: with 0.5 s poses and 2 s motions at 20 Hz, 10 mg, one pass left four of five
    pauses in). rms_dof and n_poses are those of the rest; rms_dof is NaN when no fit is
    possible (fewer than 10 means, or no ellipsoid).
    """
    m = np.asarray(means, float)
    n = len(m)
    off = np.zeros(n, bool)
    if n <= N_PARAMS:
        return float("nan"), 0, off
    m0 = m.mean(axis=0)
    s = float(np.sqrt(np.mean(np.sum((m - m0) ** 2, axis=1))))
    if not np.isfinite(s) or s <= 0:
        return float("nan"), 0, off
    u = (m - m0) / s
    fit = _ellipsoid(u)
    if fit is None:
        return float("nan"), 0, off
    for _ in range(10):  # a handful of passes at most; ten bounds a cycle
        r = _radial(u, *fit)
        med = np.median(r[~off])
        sigma = 1.4826 * np.median(np.abs(r[~off] - med))
        new = np.abs(r - med) > OFF_SPHERE * sigma
        if (~new).sum() <= N_PARAMS:
            new[:] = False
        if np.array_equal(new, off):
            break
        off = new
        fit = _ellipsoid(u[~off])
        if fit is None:
            return float("nan"), 0, off
    r = _radial(u[~off], *fit)
    rms = float(np.sqrt(np.sum(r * r) / (len(r) - N_PARAMS)))
    return rms, _count_directions(u[~off] - fit[1]), off


def _count_directions(d: np.ndarray, min_angle_deg: float = 10.0) -> int:
    """Distinct directions among the rows of d: greedy cover, each new direction claims all
    within ``min_angle_deg`` (like :func:`distinct_directions`, vectorised per row). Two
    means of one pose (a pose split by a noise spike) always count once."""
    dirs = d / np.linalg.norm(d, axis=1, keepdims=True)
    if len(dirs) > 4000:  # cells of a ~10 degree grid: O(n) for very many intervals
        return int(np.unique(np.argmax(dirs @ _CELLS.T, axis=1)).size)
    cos = dirs @ dirs.T
    cos_min = np.cos(np.deg2rad(min_angle_deg))
    covered = np.zeros(len(dirs), bool)
    count = 0
    for i in range(len(dirs)):
        if not covered[i]:
            count += 1
            covered |= cos[i] >= cos_min
    return count


def looks_like_pose_table(x: np.ndarray) -> bool:
    """True for few rows that lie far apart from their neighbours and on one ellipsoid
    (module docstring)."""
    x = np.asarray(x, float)
    n = len(x)
    if n < N_PARAMS + 1 or n > POSE_TABLE_MAX_ROWS:
        return False
    spread = float(np.sqrt(np.mean(np.sum((x - x.mean(0)) ** 2, axis=1))))
    if not np.isfinite(spread) or spread <= 0:
        return False
    step = np.linalg.norm(np.diff(x, axis=0), axis=1)
    if not np.percentile(step, 25) > POSE_TABLE_STEP * spread:
        return False
    if len(np.unique(x, axis=0)) < POSE_TABLE_DISTINCT * n:
        return False
    return bool(ellipsoid_score(x)[0] <= SPHERE_RMS)  # NaN (no ellipsoid) is not a table


def _window_grid(n: int, sample_rate: float | None) -> list[int]:
    if sample_rate:
        lo = max(3, int(round(MIN_WINDOW_S * sample_rate)))
        hi = max(lo, int(round(DEFAULT_WINDOW_S * sample_rate)))
    else:
        lo = 3
        hi = max(lo, min(1000, n // 50))
    hi = max(3, min(hi, max(3, n // 4)))
    lo = min(lo, hi)
    return sorted({int(round(w)) for w in np.geomspace(lo, hi, N_WINDOWS)})


def _splits(means: np.ndarray, cut: np.ndarray) -> tuple[int, int]:
    """(held, split): intervals that start a new pose (their mean differs from the previous
    one by more than ``SPLIT`` of the data's radius, or the run was not cut by an invalid
    sample), and intervals that repeat the previous pose although the run was not cut by an
    invalid sample (a pose split by a noise spike)."""
    if len(means) < 2:
        return len(means), 0
    radius = np.median(np.linalg.norm(means - means.mean(axis=0), axis=1))
    same = np.linalg.norm(np.diff(means, axis=0), axis=1) < SPLIT * radius
    return int(1 + np.sum(~same & ~cut[1:])), int(np.sum(same & ~cut[1:]))


def _choose(candidates: list[Candidate], covered: list[int]) -> int | None:
    """Index of the best candidate.

    Tied: scores within ``SCORE_TIE`` of the lowest, or within 1.5 standard deviations of
    the lowest score's own scatter if that is more (a candidate with few intervals can score
    low by chance). Among the tied, those with the most poses held (intervals that start a
    new pose), then the fewest poses split in two by the detector; among these, the one with
    the median threshold factor (lowest score among equal factors). The strictest factor
    cuts intervals short at noise spikes; the loosest lets the quiet ends of motions reach
    past the trim; the middle of the plateau is the setting least sensitive to either."""
    ok = [i for i, c in enumerate(candidates) if np.isfinite(c.score)]
    if not ok:
        return None
    best = min(ok, key=lambda i: candidates[i].score)
    lowest = candidates[best].score
    # the best score's own scatter: its rms has n - 9 degrees of freedom (2 sigma)
    tie = max(SCORE_TIE, 1.5 / np.sqrt(2.0 * max(candidates[best].n_intervals - N_PARAMS, 1)))
    tied = [i for i in ok if candidates[i].score <= lowest * (1 + tie)]
    top = min((-candidates[i].n_held, candidates[i].n_split) for i in tied)
    plateau = sorted(
        (i for i in tied if (-candidates[i].n_held, candidates[i].n_split) == top),
        key=lambda i: (candidates[i].factor or 0.0, candidates[i].score),
    )
    factors = sorted({candidates[i].factor or 0.0 for i in plateau})
    mid = factors[(len(factors) - 1) // 2]
    return min(
        (i for i in plateau if (candidates[i].factor or 0.0) == mid),
        key=lambda i: candidates[i].score,
    )


def check_sample_rate(sample_rate) -> None:
    """A ValueError unless ``sample_rate`` is None or a positive, finite number of Hz (-5 and
    0 were taken, and a window of 3 samples reported as "-0.6 s")."""
    if sample_rate is None:
        return
    number = isinstance(sample_rate, (int, float, np.integer, np.floating))
    if not number or isinstance(sample_rate, bool) or not 0 < sample_rate < np.inf:
        raise ValueError(
            f"sample_rate={sample_rate!r}: the sampling rate must be a positive number of Hz "
            "(--sample-rate 100), or left out where the log has a time column"
        )


def _check_options(window, threshold, threshold_factor, min_duration, min_samples, trim):
    if window is not None and (not np.isfinite(window) or int(window) != window or window < 3):
        raise ValueError(
            f"window={window!r}: the moving-variance window must be a whole number of at least "
            "3 samples; pass a larger --window, or leave it out to let the detector choose"
        )
    if threshold_factor is not None and not (
        np.isfinite(threshold_factor) and threshold_factor > 0
    ):
        raise ValueError(
            f"threshold_factor={threshold_factor!r}: it multiplies the noise level and must be "
            "a positive number (6 is the classic value); leave it out to let the detector choose"
        )
    if threshold is not None and not (np.isfinite(threshold) and threshold > 0):
        raise ValueError(
            f"threshold={threshold!r}: a fixed threshold on the moving variance must be a "
            "positive number in input units squared; leave it out for an automatic one"
        )
    if min_duration is not None and not (np.isfinite(min_duration) and min_duration >= 0):
        raise ValueError(
            f"min_duration={min_duration!r}: the shortest static interval must be zero or more "
            "seconds; pass a non-negative --min-static, or leave it out"
        )
    if min_samples is not None and not (np.isfinite(min_samples) and min_samples >= 0):
        raise ValueError(
            f"min_samples={min_samples!r}: the shortest static interval must be zero or more "
            "samples; pass a non-negative value, or leave it out"
        )
    if trim is not None and not (np.isfinite(trim) and trim >= 0):
        raise ValueError(
            f"trim={trim!r}: samples cut from each end of an interval must be zero or more; "
            "leave it out for half a window"
        )


def _pose_table_report(x: np.ndarray, valid: np.ndarray) -> StaticReport:
    idx = np.flatnonzero(valid)
    intervals = [
        StaticInterval(start=int(i), stop=int(i) + 1, mean=x[i].copy(), std=np.full(3, np.nan))
        for i in idx
    ]
    return StaticReport(
        intervals=intervals,
        mask=valid.copy(),
        threshold=float("nan"),
        noise_level=float("nan"),
        window=1,
        min_samples=1,
        automatic=False,
        kind="pose_table",
        how="pose_table",
    )


def _block_report(x: np.ndarray, valid: np.ndarray, block: int) -> StaticReport:
    if block < 1:
        raise ValueError(f"block must be a positive number of samples, got {block}")
    nb = len(x) // block  # whole blocks, in one pass (a loop of slices took 6.6 s at block 1)
    xb = x[: nb * block].reshape(nb, block, -1)
    keep = np.flatnonzero(valid[: nb * block].reshape(nb, block).all(1))
    means, stds = xb[keep].mean(1), xb[keep].std(1)
    intervals = [
        StaticInterval(start=int(k) * block, stop=(int(k) + 1) * block, mean=mu, std=sd)
        for k, mu, sd in zip(keep, means, stds, strict=True)
    ]
    mask = np.zeros(len(x), bool)
    for iv in intervals:
        mask[iv.start : iv.stop] = True
    return StaticReport(
        intervals=intervals,
        mask=mask,
        threshold=float("nan"),
        noise_level=float("nan"),
        window=block,
        min_samples=block,
        automatic=False,
        kind="blocks",
        how="blocks",
    )


# ---------------------------------------------------------------------------------------------
# the detector


def detect_static(
    x: np.ndarray,
    *,
    sample_rate: float | None = None,
    window: int | None = None,
    threshold: float | None = None,
    threshold_factor: float | None = None,
    min_duration: float | None = None,
    min_samples: int | None = None,
    valid: np.ndarray | None = None,
    trim: int | None = None,
    pose_table: bool | None = None,
    block: int | None = None,
) -> StaticReport:
    """Find the static intervals of a log of 3-axis readings (module docstring).

    Parameters
    ----------
    x : (N, 3) array
        Readings, any unit.
    sample_rate : float, optional
        Hz. Sets the window grid (0.05 s to 1 s) and the shortest run (0.25 s); without it the
        windows run from 3 samples to N/50 (at most 1000).
    window : int, optional
        Moving-window length in samples (at least 3). Default: swept.
    threshold : float, optional
        Fixed threshold on the summed moving variance (input units squared). Default: a factor
        times the noise level.
    threshold_factor : float, optional
        Multiple of the noise level (positive). Default: swept over ``FACTOR_GRID``.
    min_duration : float, optional
        Shortest run kept, in seconds (needs ``sample_rate``); or give ``min_samples``. Default:
        one window, and with a rate at least 0.25 s.
    valid : (N,) bool array, optional
        Samples allowed in intervals (False for non-finite or saturated samples).
    trim : int, optional
        Samples cut from each end of every run (a run left shorter than a quarter of
        ``min_samples`` is dropped). Default: half a window, and the ramps at the ends of the
        runs cut off (module docstring); an explicit trim fixes the edges.
    pose_table : bool, optional
        True: every row is a pose; False: never; default: recognised when there is no explicit
        window, threshold or minimum length, few rows and neighbouring rows far apart (with or
        without a sample rate).
    block : int, optional
        The log was recorded pose by pose in blocks of this many samples (CK-Explorer's 160
        poses x 100): the blocks are the intervals (those with a sample not ``valid`` are left
        out), and nothing is detected.

    Raises
    ------
    ValueError
        For an invalid explicit option (window < 3, threshold or factor not positive, negative
        minimum duration or trim), or ``min_duration`` without ``sample_rate``.
    """
    _check_options(window, threshold, threshold_factor, min_duration, min_samples, trim)
    check_sample_rate(sample_rate)
    x = np.asarray(x, float)
    if x.ndim != 2 or x.shape[1] != 3:  # was a numpy broadcasting error (a trial's x.T)
        raise ValueError(
            f"readings must be (samples, 3), got shape {x.shape}"
            + (" (transposed? pass x.T)" if x.ndim == 2 and x.shape[0] == 3 else "")
        )
    n = len(x)
    valid = np.ones(n, bool) if valid is None else np.asarray(valid, bool)
    if block is not None:
        given = [
            k
            for k, v in (
                ("window", window),
                ("threshold", threshold),
                ("threshold_factor", threshold_factor),
                ("min_duration", min_duration),
                ("min_samples", min_samples),
                ("trim", trim),
            )
            if v is not None
        ]
        if given:
            raise ValueError(
                f"block replaces detection: leave out {', '.join(given)} (--window, "
                "--threshold-factor, --min-static) or the block"
            )
        return _block_report(x, valid, int(block))
    if min_duration is not None and min_samples is None and not sample_rate:
        raise ValueError("min_duration needs sample_rate; or give min_samples instead")

    if _interleaved_gaps(valid):
        return _compressed(
            x,
            valid,
            sample_rate,
            dict(
                window=window,
                threshold=threshold,
                threshold_factor=threshold_factor,
                min_duration=min_duration,
                min_samples=min_samples,
                trim=trim,
                pose_table=pose_table,
            ),
        )

    if window is None and n > MAX_SWEEP_SAMPLES:
        return _strided(
            x, valid, sample_rate, threshold, threshold_factor, min_duration, min_samples, trim
        )

    # a window or a fixed threshold says the rows are a time series; a factor alone does not
    # (the CLI passes one by default), nor does a sample rate: rows that each lie far from
    # their neighbours on one ellipsoid are poses however often they came (a 24-pose table
    # given --sample-rate 10 was searched for still runs and refused as 'only 3 poses')
    explicit = window is not None or threshold is not None
    if pose_table is None:
        pose_table = not explicit and min_samples is None and looks_like_pose_table(x[valid])
    if pose_table:
        return _pose_table_report(x, valid)

    mu, c1, c2, cn = _cumsums(x, valid)
    c2 = c2.sum(axis=1)  # the moving variance needs only the sum over the axes
    all_valid = bool(valid.all())

    windows = [int(window)] if window is not None else _window_grid(n, sample_rate)
    if threshold is not None:
        factors: list[float | None] = [None]
    elif threshold_factor is not None:
        factors = [float(threshold_factor)]
    else:
        factors = list(FACTOR_GRID)

    def min_run_for(w: int) -> int:
        if min_samples is not None:
            return int(min_samples)
        if min_duration is not None:
            return int(round(min_duration * sample_rate))
        if sample_rate and window is None:
            return max(w, int(round(MIN_RUN_S * sample_rate)))
        return w

    def trim_for(w: int) -> int:
        if trim is not None:
            return int(trim)
        # half a window, and with a rate at least MIN_TRIM_S: a short window reacts to the
        # first samples of a motion only once they have moved more than the noise
        return max(w // 2, int(round(MIN_TRIM_S * sample_rate)) if sample_rate else 0)

    def run(w: int, f: float | None, mv: np.ndarray, noise: float, refine: bool = False):
        thr = threshold if f is None else (f * noise if noise > 0 else np.finfo(float).tiny)
        starts, stops = _runs(mv <= thr if all_valid else (mv <= thr) & valid)
        if refine:
            a, b, cut, trim_a, trim_b = _kept_runs(
                starts, stops, min_run_for(w), trim_for(w), valid
            )
            a, b, cut = _refined(
                x, a, b, cut, trim_a, trim_b, w + trim_for(w), max(2, min_run_for(w) // 4)
            )
        else:
            a, b, cut = _trimmed(starts, stops, min_run_for(w), trim_for(w), valid)
        return float(thr), a, b, cut

    single = len(windows) * len(factors) == 1
    candidates: list[Candidate] = []
    settings: list[tuple[int, float | None, float, float]] = []  # (w, f, thr, noise)
    noises: dict[int, float] = {}
    covered: list[int] = []
    for w in windows:
        mv = _moving_variance(c1, c2, cn, w)
        noise = _noise_level(mv[valid])
        noises[w] = noise
        for f in factors:
            thr, a, b, cut = run(w, f, mv, noise)
            if single:
                settings.append((w, f, thr, noise))
                break
            means = (c1[b] - c1[a]) / (b - a)[:, None] + mu if len(a) else np.zeros((0, 3))
            rms, n_poses, off = ellipsoid_score(means)
            if not np.isfinite(rms) and len(a) >= 2:
                # too few means for an ellipsoid: count the raw means' own directions (the
                # bias is small next to the reference), so a short log of a few poses says how
                # many it holds instead of "no static interval"
                n_poses = _count_directions(means)
            n_held, n_split = _splits(means[~off], cut[~off]) if len(a) else (0, 0)
            n_kept = int(len(a) - off.sum())
            ok = np.isfinite(rms) and n_kept >= MIN_POSES and n_poses >= MIN_POSES
            score = rms / np.sqrt(n_poses) if ok else float("inf")
            candidates.append(
                Candidate(
                    w, f, thr, n_kept, n_poses, rms, float(score), int(off.sum()), n_split, n_held
                )
            )
            settings.append((w, f, thr, noise))
            covered.append(int(np.sum(b - a)))

    candidates = _without_leaks(candidates)
    best = _choose(candidates, covered)
    few = None  # nothing scorable, but settings found several poses: the count most settings
    # agree on (ties: the larger). Not the most any found: the loosest threshold lets a turn in
    # as one pose more (a hand-held MPU-6050 log: 11 poses at 150x the noise, 10 at the rest)
    counts = Counter(c.n_poses for c in candidates if c.n_poses >= 2)
    if best is None and not single and counts:
        most = max(counts, key=lambda k: (counts[k], k))
        if most < FEWEST_POSES:  # refused whatever is fitted: a count that can be fitted, if
            # a plateau of settings holds one (AirbrakesV2's six hand-held faces at 1 kHz: 44
            # strict settings saw the 2 quietest, 21 looser ones all 6)
            plateau = [
                k for k, m in counts.items() if k >= FEWEST_POSES and m >= PLATEAU * len(candidates)
            ]
            most = max(plateau, default=most)

        def rank(i: int):
            c = candidates[i]
            spread = abs(np.log((c.factor or DEFAULT_FACTOR) / DEFAULT_FACTOR))
            return (-spread, c.n_held, -c.n_split)

        ranked = sorted(
            (i for i, c in enumerate(candidates) if c.n_poses == most), key=rank, reverse=True
        )

        def refined_poses(i: int) -> int:
            # the sweep counts the raw runs; the chosen setting's runs are then refined, and a
            # pose held with a slight wobble can lose its run there (a six-face FOX log lost
            # its +x face at a 1 s window, and with it the six-parameter fit)
            w, f, _, noise = settings[i]
            _, a, b, _ = run(w, f, _moving_variance(c1, c2, cn, w), noise, refine=trim is None)
            means = (c1[b] - c1[a]) / (b - a)[:, None] + mu if len(a) else np.zeros((0, 3))
            rms, n_poses, _ = ellipsoid_score(means)
            return n_poses if np.isfinite(rms) else _count_directions(means) if len(a) else 0

        few = next((i for i in ranked if refined_poses(i) >= most), ranked[0])

    if single:
        how, chosen = "given", None
        w, f, thr, noise = settings[0]
    elif best is not None:
        how, chosen = "sweep", best
        w, f, thr, noise = settings[best]
    elif few is not None:
        how, chosen = "most_poses", few
        w, f, thr, noise = settings[few]
    else:  # nothing scorable: the classic setting (or the closest to it in the grid)
        how = "default"
        w0 = window or (
            int(round(DEFAULT_WINDOW_S * sample_rate)) if sample_rate else DEFAULT_WINDOW_SAMPLES
        )
        w0 = max(3, min(w0, max(3, n // 4))) if window is None else w0
        f0 = None if threshold is not None else (threshold_factor or DEFAULT_FACTOR)
        chosen = next(
            (i for i, (ww, ff, _, _) in enumerate(settings) if ww == w0 and ff == f0), None
        )
        w, f = w0, f0
        noise = noises.get(w0)
        if noise is None:
            noise = _noise_level(_moving_variance(c1, c2, cn, w0)[valid])
        thr = threshold if f is None else (f * noise if noise > 0 else np.finfo(float).tiny)

    mv = _moving_variance(c1, c2, cn, w)
    # the ramps at the ends of the chosen setting's runs are cut (an explicit trim fixes the
    # edges: detect_rest, --trim)
    thr, a, b, _ = run(w, f, mv, noise, refine=trim is None)
    rejected: list[tuple[int, int]] = []
    if how == "sweep":  # leave out the pauses in motion, off the ellipsoid through the poses
        _, _, off = ellipsoid_score((c1[b] - c1[a]) / (b - a)[:, None] + mu)
        rejected = [(int(s), int(e)) for s, e in zip(a[off], b[off], strict=True)]
        a, b = a[~off], b[~off]
    intervals = []
    mask = np.zeros(n, bool)
    for s, e in zip(a, b, strict=True):
        seg = x[s:e]
        std = seg.std(0, ddof=1) if e - s > 1 else np.full(3, np.nan)
        intervals.append(StaticInterval(start=int(s), stop=int(e), mean=seg.mean(0), std=std))
        mask[s:e] = True
    return StaticReport(
        intervals=intervals,
        mask=mask,
        threshold=float(thr),
        noise_level=float(noise),
        window=int(w),
        min_samples=int(min_run_for(w)),
        automatic=threshold is None,
        factor=f,
        trim=int(trim_for(w)),
        kind="log",
        how=how,
        candidates=candidates,
        chosen=chosen,
        rejected=rejected,
    )


def _without_leaks(candidates: list[Candidate]) -> list[Candidate]:
    """The candidates, those that took motion for poses marked and made unscorable (score
    inf; see :data:`LEAK_RATIO`)."""
    rms = np.array([c.rms for c in candidates], float)
    finite = np.isfinite(rms)
    if not finite.any():
        return candidates
    limit = LEAK_RATIO * float(np.median(rms[finite]))
    return [
        replace(c, score=float("inf"), motion=True) if np.isfinite(c.score) and c.rms > limit else c
        for c in candidates
    ]


def _interleaved_gaps(valid: np.ndarray) -> bool:
    """Many invalid rows in short runs: another packet type interleaved with the sensor's rows
    (the MicroStrain logs leave the accelerometer cells of every third row empty). Cutting runs
    at each of them would leave no static interval at all."""
    bad = ~valid
    if bad.mean() < 0.05 or bad.all():
        return False
    d = np.diff(np.concatenate([[0], bad.astype(np.int8), [0]]))
    lengths = np.flatnonzero(d == -1) - np.flatnonzero(d == 1)
    return bool(np.median(lengths) <= 2)


def _compressed(x, valid, sample_rate, options: dict):
    """Detection on the valid rows alone (at their own effective rate), mapped back to the
    log: intervals span the interleaved invalid rows, their means and the mask use only the
    valid ones."""
    idx = np.flatnonzero(valid)
    frac = len(idx) / len(valid)
    sub = detect_static(x[idx], sample_rate=sample_rate * frac if sample_rate else None, **options)
    intervals = []
    mask = np.zeros(len(valid), bool)
    for iv in sub.intervals:
        a, b = int(idx[iv.start]), int(idx[iv.stop - 1]) + 1
        intervals.append(StaticInterval(a, b, iv.mean, iv.std))
        mask[idx[iv.start : iv.stop]] = True
    note = (
        f"{int((~valid).sum())} of {len(valid)} rows interleaved without this sensor's values "
        "(another packet type): detected on the other rows"
    )
    return replace(
        sub,
        intervals=intervals,
        mask=mask,
        rejected=[(int(idx[a]), int(idx[min(b, len(idx)) - 1]) + 1) for a, b in sub.rejected],
        extra_notes=[*sub.extra_notes, note],
    )


def _strided(x, valid, sample_rate, threshold, threshold_factor, min_duration, min_samples, trim):
    """The sweep on every k-th sample of a very long log (k = ceil(N / MAX_SWEEP_SAMPLES)),
    a sample kept only when its whole block of k is valid; the intervals found are mapped back
    to the full log and their means and scatter taken from every sample."""
    n = len(x)
    k = int(np.ceil(n / MAX_SWEEP_SAMPLES))
    m = n // k
    vb = valid[: m * k].reshape(m, k).all(axis=1)
    sub = detect_static(
        x[: m * k : k],
        sample_rate=sample_rate / k if sample_rate else None,
        threshold=threshold,
        threshold_factor=threshold_factor,
        min_duration=min_duration,
        min_samples=None if min_samples is None else max(1, int(min_samples) // k),
        valid=vb,
        trim=None if trim is None else int(trim) // k,
        pose_table=False,
    )
    intervals = []
    mask = np.zeros(n, bool)
    for iv in sub.intervals:
        a, b = iv.start * k, iv.stop * k
        seg = x[a:b]
        intervals.append(StaticInterval(a, b, seg.mean(0), seg.std(0, ddof=1)))
        mask[a:b] = True
    return replace(
        sub,
        intervals=intervals,
        mask=mask,
        window=sub.window * k,
        min_samples=sub.min_samples * k,
        trim=sub.trim * k,
        rejected=[(a * k, b * k) for a, b in sub.rejected],
        stride=k,
    )


def quarter_turn(v: np.ndarray) -> tuple[float, float]:
    """(angle, noise), radians: the angle between the mean directions of the first and last
    quarters of vectors ``v`` (N, 3), and its standard error from the quarters' scatter; (0,
    inf) with fewer than 8 vectors. Whether a rest held a field's direction (the gyro's rests,
    diagnose's magnetometer floor)."""
    q = len(v) // 4
    if q < 2:
        return 0.0, float("inf")
    u = v / np.linalg.norm(v, axis=1, keepdims=True)
    a, b = u[:q], u[-q:]
    ma, mb = np.nanmean(a, axis=0), np.nanmean(b, axis=0)
    noise = np.sqrt((np.nansum(np.nanvar(a, axis=0)) + np.nansum(np.nanvar(b, axis=0))) / q)
    cos = float(ma @ mb / (np.linalg.norm(ma) * np.linalg.norm(mb)))
    return float(np.arccos(np.clip(cos, -1.0, 1.0))), float(noise)


def detect_rest(
    x: np.ndarray, *, sample_rate: float | None = None, valid: np.ndarray | None = None
) -> StaticReport:
    """Rests of a log with the classic single setting, untrimmed (no sweep).

    For noise floors from the longest rest of a tumble (magnetometer, MARG): the sweep's
    score needs poses spread over the sphere, and a tumble's slow stretches fit an ellipsoid
    too. Window 1 s (100 samples without a rate), factor 6, runs of at least one window.
    """
    n = len(np.asarray(x))
    w = int(round(DEFAULT_WINDOW_S * sample_rate)) if sample_rate else DEFAULT_WINDOW_SAMPLES
    return detect_static(
        x,
        window=max(3, min(w, max(3, n // 4))),
        threshold_factor=DEFAULT_FACTOR,
        min_samples=max(3, min(w, max(3, n // 4))),
        trim=0,
        valid=valid,
        pose_table=False,
    )


def distinct_directions(points: np.ndarray, centre: np.ndarray, min_angle_deg: float = 10.0) -> int:
    """Number of distinct directions among ``points - centre`` (greedy, min_angle apart)."""
    v = np.asarray(points, float) - centre
    nrm = np.linalg.norm(v, axis=1)
    v = v[nrm > 0] / nrm[nrm > 0, None]
    cos_min = np.cos(np.deg2rad(min_angle_deg))
    # in order, each point not within the angle of an earlier representative is one, and
    # marks the later points within its angle (a Python product per point took 6 s on 51,175)
    covered = np.zeros(len(v), bool)
    count = 0
    for i in range(len(v)):
        if not covered[i]:
            count += 1
            covered[i + 1 :] |= v[i + 1 :] @ v[i] >= cos_min
    return count
