"""The one way from a sensor's samples to the points a fit sees.

Every path that fits an accelerometer or a magnetometer (``calibrate_accel``, ``calibrate_mag``,
``calib-jax batch`` through :mod:`calib_jax.fleet`, the recorder's batch fit) screens the
samples and, for an accelerometer, detects the static poses here, so that the same log gives
the same fit points, the same notes and the same errors whichever path it takes.

- :func:`screen_samples`: rows with NaN or inf, and samples on a saturated axis, are left out
  (counted, with a note naming the axis and what to change);
- :func:`accel_observations`: screening, then static detection
  (:func:`calib_jax.static.detect_static`: intervals, or a pose table's rows), then the fit
  points: the interval means (one per pose, each weighing the same) or every static sample.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .static import SPHERE_RMS, StaticReport, detect_static

USES = ("means", "samples")

_SATURATION_ADVICE = {
    "accel": "use a wider range setting or avoid poses that drive it to the limit",
    "mag": (
        "the field along it exceeds the sensor's range; use a wider range setting, or move "
        "away from the magnet or iron that drives it to the limit"
    ),
}


def saturated_axes(
    x: np.ndarray, min_count: int = 20, min_fraction: float = 0.005
) -> list[tuple[int, str, float]]:
    """Axes whose extreme value is held by many samples: (axis, 'max'|'min', value).

    A sensor at the end of its range repeats the same extreme reading; ``min_count`` samples
    (and at least ``min_fraction`` of them) at exactly the maximum or minimum of an axis, more
    than hold the next value inward, mark it as clipped. The last condition is the pile-up a
    clip makes: a coarsely quantised axis (an MPU-9150 log printed to 0.01 g) repeats its
    extreme too, but its tail thins out towards the extreme. ``x`` holds finite rows only.

    A sensor read faster than it updates repeats whole readings (a Pololu MinIMU-9 log's
    magnetometer: 93 % of its rows equal the row before); its extremes repeat with the rest,
    and counting them read as a clip. When over 30 % of the rows repeat the row before, each
    held reading counts once: a clipped axis still piles up (its other axes move on).
    """
    held = np.r_[False, np.all(x[1:] == x[:-1], axis=1)] if len(x) > 1 else np.zeros(len(x), bool)
    if held.mean() > 0.3:
        x = x[~held]
    out = []
    n = len(x)
    for ax in range(3):
        values, counts = np.unique(x[:, ax], return_counts=True)
        if len(values) < 2:
            continue  # a constant axis is a stuck sensor, not a clip: screen_samples says so
        for kind, cnt, inner, v in (
            ("max", counts[-1], counts[-2], values[-1]),
            ("min", counts[0], counts[1], values[0]),
        ):
            if cnt >= max(min_count, min_fraction * n) and cnt > inner:
                out.append((ax, kind, float(v)))
    return out


NO_GRAVITY = 0.1
"""An accelerometer log in which no pose is found and whose median |a| is below this holds no
gravity in any unit (g's band starts at 0.7; accel.UNIT_BANDS): a dead sensor or linear
acceleration. Altus Metrum's TeleMega export, IMU columns near 0, was 'no static interval,
noise level nan'. (Declared counts of any scale that do hold poses are fitted.)"""


def screen_samples(x: np.ndarray, sensor: str = "accel") -> tuple[np.ndarray, list[str]]:
    """The usable samples of an (N, 3) array: a boolean mask (finite and not on a saturated
    axis) and a note for each kind of sample left out. Raises a ValueError when no row is
    finite. ``sensor`` ("accel" or "mag") picks the advice in the saturation note."""
    finite = np.all(np.isfinite(x), axis=1)
    if not finite.any():
        what = "accelerometer" if sensor == "accel" else "magnetometer"
        raise ValueError(f"no finite {what} samples: every row has NaN or inf")
    what = "accelerometer" if sensor == "accel" else "magnetometer"
    xf = x if finite.all() else x[finite]  # no copy of a clean log
    zero = np.all(xf == 0, axis=1)
    if zero.mean() > 0.5:  # a live sensor never reads exactly 0 on all three axes for long
        raise ValueError(
            f"the {what} reads exactly 0 on every axis in {int(zero.sum())} of {len(xf)} rows: "
            "no signal (a sensor that was off or not logged, an unused field of the export, "
            "or the wrong columns); check the column mapping (--columns)"
        )
    # one axis constant while the others swing (the board moved): that axis is stuck. A
    # board that never moved, read coarsely, can hold every axis constant: the pose checks
    # then say "one pose", which is the cause
    moved = np.ptp(xf, axis=0).max() > 0.1 * np.median(np.linalg.norm(xf, axis=1))
    for ax in range(3):
        if moved and np.all(xf[:, ax] == xf[0, ax]):
            raise ValueError(
                f"{what} axis {'xyz'[ax]} reads {xf[0, ax]:g} in every sample while the others "
                "swing: a stuck axis, or a column that is not a reading; check the sensor and "
                "the column mapping (--columns)"
            )
    notes = []
    n_bad = int((~finite).sum())
    if n_bad:
        notes.append(f"{n_bad} rows with NaN or inf were left out of the fit")
    valid = finite.copy()
    for ax, kind, v in saturated_axes(xf):
        hit = finite & (x[:, ax] == v)
        valid &= ~hit
        notes.append(
            f"axis {'xyz'[ax]} is saturated at its {kind} ({v:g}, {int(hit.sum())} samples left "
            f"out): {_SATURATION_ADVICE[sensor]}"
        )
    return valid, notes


def detector_keywords(
    *,
    window: int | None = None,
    threshold_factor: float | None = None,
    min_static: float | None = None,
    sample_rate: float | None = None,
) -> dict:
    """The :func:`calib_jax.static.detect_static` keywords for the detector options every
    command takes (``--window``, ``--threshold-factor``, ``--min-static``); the ones left None
    stay automatic. ``min_static`` is seconds with a sample rate, else samples."""
    out: dict = {}
    if window is not None:
        out["window"] = int(window)
    if threshold_factor is not None:
        out["threshold_factor"] = float(threshold_factor)
    if min_static is not None:
        if sample_rate:
            out["min_duration"] = float(min_static)
        else:
            out["min_samples"] = int(min_static)
    return out


@dataclass
class AccelObservations:
    """What an accelerometer fit sees of a log."""

    points: np.ndarray
    """(n, 3) fit points in input units: interval means or static samples (``use``)."""
    means: np.ndarray
    """(intervals, 3) the static-interval means (a pose table: its rows)."""
    report: StaticReport
    """The detector's report: intervals, the setting it chose and why."""
    valid: np.ndarray
    """(N,) bool: samples that are finite and not on a saturated axis."""
    use: str
    warnings: list[str] = field(default_factory=list)
    """Samples left out by screening (non-finite rows, a saturated axis), with the remedy."""
    notes: list[str] = field(default_factory=list)
    """What the detector found and chose (:meth:`calib_jax.static.StaticReport.notes`)."""

    @property
    def static_norm(self) -> float:
        """Median norm of the interval means (what decides the unit)."""
        return float(np.median(np.linalg.norm(self.means, axis=1)))


def accel_observations(
    x: np.ndarray,
    *,
    use: str = "means",
    sample_rate: float | None = None,
    **detector,
) -> AccelObservations:
    """Screen an (N, 3) accelerometer array, detect its static poses and return the fit points.

    ``detector`` holds :func:`calib_jax.static.detect_static`'s options (window, threshold,
    threshold_factor, min_duration, min_samples); left out, the detector chooses its own.
    Raises a ValueError naming what the detector found when there is no static interval.
    """
    x = np.asarray(x, float)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"accelerometer data must be (samples, 3), got shape {x.shape}")
    if use not in USES:
        raise ValueError(f"use must be 'means' or 'samples', got {use!r}")
    valid, warnings = screen_samples(x, "accel")
    report = detect_static(x, sample_rate=sample_rate, valid=valid, **detector)
    notes = report.notes(sample_rate)
    if report.n_intervals == 0:
        level = float(np.median(np.linalg.norm(x[np.isfinite(x).all(axis=1)], axis=1)))
        if level < NO_GRAVITY:  # the cause, not the detector's miss
            raise ValueError(
                f"the accelerometer reads about 0 (median |a| {level:.3g}): gravity reads 1 in "
                "g, 9.8 in m/s^2 and hundreds or more in counts, so these readings hold no "
                "gravity (a sensor that was off, gravity already removed (linear acceleration), "
                "an unused field of the export, or the wrong columns); check the column mapping "
                "(--columns)"
            )
        raise ValueError(
            "static detection found no static interval: "
            + detection_found(report, sample_rate)
            + "; hold each pose still for at least half a second, or set the detector "
            "(--window, --threshold-factor, --min-static)"
        )
    means = report.means()
    points = means if use == "means" else x[report.mask]
    lengths = np.array([iv.stop - iv.start for iv in report.intervals])
    if sample_rate is None and report.kind == "log" and np.median(lengths) < SHORT_POSE:
        # no clock: the detector judged poses in samples, and took stretches of a few samples
        # for rests (a gesture log without a time column: 50 'poses' of median 3 samples)
        warnings.append(
            f"the log has no time column and no rate, so the poses were found in samples: "
            f"{report.n_intervals} of {int(lengths.min())}-{int(lengths.max())} samples "
            f"(median {np.median(lengths):.0f}), too short to be held rests at a usual rate; "
            "give the rate (--sample-rate HZ, sample_rate= in Python) so poses are judged in "
            "seconds, or record poses held still for a few seconds"
        )
    return AccelObservations(
        points=points,
        means=means,
        report=report,
        valid=valid,
        use=use,
        warnings=warnings,
        notes=notes,
    )


SHORT_POSE = 10  # samples: the median pose of a log without a clock below this is no rest


def detection_found(report: StaticReport, sample_rate: float | None) -> str:
    """What the detector found, for an error message."""
    if report.kind == "pose_table":
        return report.setting(sample_rate)
    tried = len(report.candidates)
    on_sphere = _on_sphere(report)
    most = most_poses_found(report)
    setting = report.setting(sample_rate).removeprefix("static detection: ")
    found = f"found {report.n_intervals} static intervals with {setting}"
    if tried > 1:
        found += (
            f"; of the {tried} settings tried, the most distinct poses any found was {most} "
            "(each about the ellipsoid fitted through its own interval means)"
        )
    if tried > 1 and most <= 1 and len(on_sphere) < tried:
        found += (
            f" (no setting's interval means lay on one ellipsoid within {100 * SPHERE_RMS:g} % "
            "of its radius: the log looks like one pose held throughout, or motion throughout)"
        )
    return found


def _on_sphere(report: StaticReport) -> list:
    # a setting whose means scatter off every ellipsoid found noise, not poses: its count of
    # directions about the fitted centre means nothing (a board that never moved has dozens)
    # (nor does one that took motion for poses: a six-face log counted its turns)
    return [c for c in report.candidates if not c.rms > SPHERE_RMS and not c.motion]


def most_poses_found(report: StaticReport) -> int:
    """The most distinct poses any detector setting found whose means lie on an ellipsoid."""
    return max((c.n_poses for c in _on_sphere(report)), default=0)


class TooFewPoses(ValueError):
    """The poses cannot determine the model: fewer distinct ones than it has parameters.
    ``str()`` gives the finding and advice in Python keywords and the flags ``calib-jax
    accel`` and ``batch`` share; :meth:`advice` words it for a command with other options."""

    def __init__(self, finding: str, n_distinct: int, model: str, samples_tried: bool = False):
        self.finding, self.n_distinct, self.model = finding, n_distinct, model
        self.samples_tried = samples_tried
        """The fit already used every quasi-static sample, or the log is a pose table (one
        sample a pose): fitting samples is no advice to give."""
        super().__init__(f"{finding}. {self.advice({'--use', '--model'})}")

    def advice(self, options) -> str:
        """What to do, naming only the flags in ``options`` (a command's option strings)."""
        samples, six = "", ""
        if "--use" in options and not self.samples_tried:
            samples = (
                "; if the log does hold more orientations than were found (slow tilting with "
                "no still poses), fit its quasi-static samples: --use samples --window 10 "
                "--threshold-factor 20 (use='samples', window=10, threshold_factor=20 in Python)"
            )
        if self.model == "accel9" and self.n_distinct >= 6:
            six = " With six faces (the Ferraris protocol) fit the six-parameter model: " + (
                "--model accel6 (model='accel6')."
                if "--model" in options
                else "calib-jax accel and batch do so with --model accel6."
            )
        return (
            "Record more orientations and hold each still for at least half a second"
            + samples
            + "."
            + six
        )
