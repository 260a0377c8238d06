"""Gyroscope calibration from a multi-position log (imu_tk's method, Tedaldi et al. 2014).

The log is the accelerometer's: static poses with rotations between them, recorded with the
gyroscope on the same clock. The accelerometer is calibrated first (:func:`calibrate_accel`,
the same front door and static detector); its static intervals give

* the gyro bias: the mean gyro reading at rest (Earth's rate, 7e-5 rad/s, is left in it);
* the rest noise, from which the error floor of the fit is predicted;
* the gravity direction of every pose, from the calibrated accelerometer.

Between consecutive poses the calibrated rates C (raw - b), integrated
(:func:`calib_jax.rotations.integrate_rates`), must turn the first pose's gravity direction
onto the second's; Levenberg-Marquardt fits the nine entries of C to that residual
(:func:`calib_jax.models.gyro.gravity_residual`), from a start found by a scan over one common
scale, so raw counts, deg/s and rad/s need no unit or initial guess.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from .calibration import (
    AccelCalibration,
    SensorCalibration,
    _raw_vectors,
    _sanitize,
    _unsanitize,
    linear_forms,
    warn_if_unusable,
)
from .io.files import UNEVEN_STEPS, SensorLog, as_log, join_logs, rate_from_steps
from .lm import fit_status, lm_solve, status_message
from .models.gyro import (
    Motions,
    asymmetric,
    gravity_residual,
    gravity_residual_asymmetric,
    to_imu_tk,
)
from .observations import TooFewPoses
from .padding import bucket
from .runtime import disk_jit
from .static import looks_like_pose_table, quarter_turn

UNIT_SCALES = {"rad/s": 1.0, "deg/s": np.pi / 180.0}
"""rad/s per unit of the readings a gyroscope may log (counts have no nominal scale)."""
MAX_MOTION_S = 60.0
"""Motions longer than this are left out: a missed pose, not a rotation to integrate."""
MIN_MOTIONS = 4
GAP_S = 0.25
GAP_STEPS = 10
"""A step of the time column longer than both (seconds, and median steps) is a gap in the
recording: the rotation during it was not sampled, so a motion across it is left out."""
_SCAN = np.concatenate([np.logspace(-7.0, 2.0, 97), -np.logspace(-7.0, 2.0, 97)])
"""The start's first scan: common scales of 1e-7 to 100 rad/s per unit, either sign."""


@dataclass(frozen=True, eq=False)
class GyroCalibration(SensorCalibration):
    """Outcome of :func:`calibrate_gyro`: w = C (raw - b) in rad/s.

    Errors are the angles (degrees, RMS over the motions) by which the integrated rotation
    misses the next pose's gravity direction: ``rms_raw_deg`` with the readings as logged (a
    nominal unit scale and no bias; NaN for counts), ``rms_before_deg`` with the nominal scale
    (for counts: the best single scale) and the rest bias removed, ``rms_after_deg``
    calibrated; ``noise_floor_deg`` is what the gyro's rest noise alone would leave.
    """

    kind: ClassVar[str] = "gyro"
    what: ClassVar[str] = "a gyroscope calibration"
    matrix: np.ndarray
    """C (3 x 3): scale and misalignment, rad/s per input unit."""
    bias: np.ndarray
    """b (3,), input units: the mean reading at rest."""
    stderr_matrix: np.ndarray
    stderr_bias: np.ndarray
    covariance: np.ndarray
    """Of C's entries row by row (9 x 9)."""
    input_units: str
    nfev: int
    n_poses: int
    n_motions: int
    rms_raw_deg: float
    rms_before_deg: float
    rms_after_deg: float
    noise_floor_deg: float
    motion_errors_deg: np.ndarray
    """Per motion used, calibrated (n_motions,)."""
    rest_noise: np.ndarray
    """Per-axis standard deviation of one calibrated sample at rest, rad/s (3,)."""
    bias_spread: np.ndarray
    """Standard deviation of the per-pose rest means about the bias, rad/s (3,): drift."""
    sample_rate: float
    output_units: str = "rad/s"
    angle_random_walk: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    """Per axis, rad/s/sqrt(Hz) (= rad/sqrt(s)): the Allan deviation's white-noise line at
    tau = 1 s, from the longest rest; NaN when the rest is too short to show it."""
    bias_instability: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    """Per axis, rad/s: the Allan deviation's minimum / 0.664 (its flat floor), if the longest
    rest reaches it (else the smallest value seen, a bound from above)."""
    allan_rest_s: float = float("nan")
    """Length of the rest the Allan deviation was taken from, s."""
    g_sensitivity: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    """G (3 x 3), input units per m/s^2 of calibrated acceleration: w = C (raw - b - G a).
    Zero unless the protocol measured it (Ferraris: imucal's K_ga)."""
    scale_asymmetry: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """s per axis: a reading x = raw - b - G a is taken as x (1 + s sign(x)) before C. s is
    the correction: an axis whose positive turns read 1 % high (and negative ones 1 % low)
    has s about -0.01. Zero unless the test in ``effects`` accepted it."""
    effects: dict = field(default_factory=dict)
    """Effects beyond the model that were tested and added, with the error without and with
    each (``g_sensitivity``: its F test, the rest spread and the miss before and after)."""
    method: str = "poses"
    """'poses' (imu_tk: gravity carried between static poses) or 'ferraris' (known turns)."""

    def apply(self, raw, acc=None) -> np.ndarray:
        """Calibrated rates C x, x = raw - b - G a (times 1 + s sign(x) with scale asymmetry),
        rad/s, for one reading (3,), many (N, 3), or the gyro columns of a loaded log or a
        log's path; ``acc`` the
        calibrated acceleration (m/s^2) of the same samples when G is not zero. Inside JAX
        use :meth:`to_params` (:class:`calib_jax.models.gyro.GyroParams`)."""
        warn_if_unusable(self.status, self.what, self.source)
        x = _raw_vectors(raw, "gyro") - self.bias
        if acc is not None:
            x = x - np.asarray(acc, float) @ self.g_sensitivity.T
        elif np.any(self.g_sensitivity != 0):
            import warnings

            # the README's example once left it out: rates at rest 10x those with it
            warnings.warn(
                "this gyroscope's g-sensitivity G is not zero, and no acc= was given: the rates "
                f"keep G a, up to {np.linalg.norm(self.g_sensitivity, 2) * 9.80665:.3g} "
                f"{self.input_units} at 1 g. Pass the calibrated acceleration of the same "
                "samples in m/s^2 (acc=accel_cal.apply(log) with output_units='m/s^2')",
                stacklevel=2,
            )
        if np.any(self.scale_asymmetry != 0):
            x = x * (1.0 + self.scale_asymmetry * np.sign(x))
        return x @ self.matrix.T

    def to_params(self):
        """The calibration as a JAX pytree, :class:`calib_jax.models.gyro.GyroParams`, with
        the same ``apply``, for use inside jitted pipelines."""
        from .models.gyro import GyroParams

        return GyroParams(
            matrix=jnp.asarray(self.matrix),
            bias=jnp.asarray(self.bias),
            g_sensitivity=jnp.asarray(self.g_sensitivity),
            scale_asymmetry=jnp.asarray(self.scale_asymmetry),
        )

    def imu_tk(self) -> tuple[np.ndarray, np.ndarray]:
        """imu_tk's (T, K): misalignment with unit diagonal and diagonal scale, C = T K."""
        return to_imu_tk(self.matrix)

    def __repr__(self) -> str:
        return (
            f"GyroCalibration(status={self.status!r}, {self.n_motions} motions, rotation error "
            f"{self.rms_before_deg:.3g} -> {self.rms_after_deg:.3g} deg)"
        )

    def _repr_html_(self) -> str:
        from .display import gyro_html

        return gyro_html(self)

    def report(self) -> str:
        """What the CLI prints: C with its standard errors, b, the errors and the status."""
        T, K = self.imu_tk()
        out = [f"C (rad/s per {self.input_units}), w = C (raw - b), +- standard error:"]
        for i in range(3):
            out.append(
                "  "
                + "  ".join(
                    f"{self.matrix[i, j]:>12.6g} +-{self.stderr_matrix[i, j]:<9.2g}"
                    for j in range(3)
                )
            )
        pairs = zip(self.bias, self.stderr_bias, strict=True)
        out.append(
            f"bias b ({self.input_units}): " + ", ".join(f"{b:.6g} +- {s:.2g}" for b, s in pairs)
        )
        rows = np.linalg.norm(self.matrix, axis=1)
        if np.all(np.abs(np.diag(self.matrix)) > 0.5 * rows):
            out.append(
                "imu_tk form: scale K = "
                + ", ".join(f"{k:.6g}" for k in np.diag(K))
                + "; misalignment T off-diagonal = "
                + ", ".join(f"{T[i, j]:+.4f}" for i in range(3) for j in range(3) if i != j)
            )
        else:  # imu_tk's T (unit diagonal) K has no rotated axes: K near 0, T in thousands
            axis = ["x", "y", "z"]
            out.append(
                "the gyro's axes are turned against the accelerometer's: its x, y, z read "
                + ", ".join(
                    f"{'+-'[int(self.matrix[j, i] < 0)]}{axis[j]}"
                    for i, j in enumerate(np.argmax(np.abs(self.matrix), axis=0))
                )
                + " of the accelerometer's frame (C holds the turn; imu_tk's T K form, with "
                "T's diagonal 1, cannot)"
            )
        raw = "" if np.isnan(self.rms_raw_deg) else f"as read {self.rms_raw_deg:.3g}, "
        if np.any(self.g_sensitivity != 0):
            out.append(
                "g-sensitivity G (input units per m/s^2), rows: "
                + "; ".join(", ".join(f"{v:+.4g}" for v in row) for row in self.g_sensitivity)
            )
        if self.method != "ferraris":
            out.append(
                f"rotation error between poses (RMS over {self.n_motions} motions, degrees): "
                f"{raw}nominal scale and rest bias {self.rms_before_deg:.3g}, calibrated "
                f"{self.rms_after_deg:.3g} (the rest noise alone: {self.noise_floor_deg:.3g})"
            )
        out.append(
            "rest noise per sample (rad/s): "
            + ", ".join(f"{s:.3g}" for s in self.rest_noise)
            + "; pose-to-pose bias spread (rad/s): "
            + ", ".join(f"{s:.3g}" for s in self.bias_spread)
        )
        if np.all(np.isfinite(self.angle_random_walk)):
            arw = np.degrees(self.angle_random_walk) * 60.0
            out.append(
                f"Allan deviation of the {self.allan_rest_s:.3g} s rest: angle random walk "
                + ", ".join(f"{v:.3g}" for v in arw)
                + " deg/sqrt(h); bias instability "
                + ", ".join(f"{v:.3g}" for v in np.degrees(self.bias_instability) * 3600)
                + " deg/h"
            )
        out.append(
            f"solver {self.solver}: {self.solver_message} ({self.iterations} iterations); "
            f"condition number {self.condition:.3g}; status: {self.status}"
        )
        if self.poorly_determined:
            out.append("poorly determined: " + ", ".join(self.poorly_determined))
        out += [f"note: {n}" for n in self.notes]
        out += [f"warning: {w}" for w in self.warnings]
        return "\n".join(out)

    def to_dict(self) -> dict:
        T, K = self.imu_tk()
        return _sanitize(
            {
                **self._header(),
                "units": {"input": self.input_units, "output": self.output_units},
                **linear_forms(correction=self.matrix, offset=self.bias),
                "imu_tk": {"misalignment": T.tolist(), "scale": np.diag(K).tolist()},
                "g_sensitivity": {
                    "matrix": np.asarray(self.g_sensitivity).tolist(),
                    "model": "true = correction.matrix @ (raw - offset - matrix @ a), a in m/s^2",
                },
                "method": self.method,
                "scale_asymmetry": np.asarray(self.scale_asymmetry).tolist(),
                "effects": self.effects,
                "stderr": {
                    "correction": np.asarray(self.stderr_matrix).tolist(),
                    "offset": np.asarray(self.stderr_bias).tolist(),
                },
                "covariance": np.asarray(self.covariance).tolist(),
                **self._solver_dict(),
                "nfev": self.nfev,
                "n_poses": self.n_poses,
                "n_motions": self.n_motions,
                "sample_rate": self.sample_rate,
                "rms_raw_deg": self.rms_raw_deg,
                "rms_before_deg": self.rms_before_deg,
                "rms_after_deg": self.rms_after_deg,
                "noise_floor_deg": self.noise_floor_deg,
                "motion_errors_deg": np.asarray(self.motion_errors_deg).tolist(),
                "rest_noise": np.asarray(self.rest_noise).tolist(),
                "bias_spread": np.asarray(self.bias_spread).tolist(),
                "allan": {
                    "angle_random_walk": np.asarray(self.angle_random_walk).tolist(),
                    "bias_instability": np.asarray(self.bias_instability).tolist(),
                    "rest_s": self.allan_rest_s,
                    "units": "rad/s/sqrt(Hz), rad/s, s",
                },
                **self._findings(),
            }
        )

    @classmethod
    def from_dict(cls, d: object, source: str | Path | None = None) -> GyroCalibration:
        """Rebuild from :meth:`to_dict`'s layout; C must be finite and invertible."""
        r, shared = cls._open(d, source)
        return cls(
            **shared,
            matrix=r.invertible("correction.matrix"),
            bias=r.arr("correction.offset", (3,)),
            stderr_matrix=r.arr("stderr.correction", (3, 3), finite=False),
            stderr_bias=r.arr("stderr.offset", (3,), finite=False),
            covariance=r.arr("covariance", (9, 9), finite=False),
            input_units=r.text("units.input"),
            output_units=r.text("units.output"),
            nfev=r.integer("nfev"),
            n_poses=r.integer("n_poses"),
            n_motions=r.integer("n_motions"),
            sample_rate=r.num("sample_rate", positive=True),
            rms_raw_deg=r.num("rms_raw_deg", finite=False),
            rms_before_deg=r.num("rms_before_deg", finite=False),
            rms_after_deg=r.num("rms_after_deg", finite=False),
            noise_floor_deg=r.num("noise_floor_deg", finite=False),
            motion_errors_deg=r.arr("motion_errors_deg", (-1,), finite=False),
            rest_noise=r.arr("rest_noise", (3,), finite=False),
            bias_spread=r.arr("bias_spread", (3,), finite=False),
            angle_random_walk=r.arr("allan.angle_random_walk", (3,), finite=False),
            bias_instability=r.arr("allan.bias_instability", (3,), finite=False),
            allan_rest_s=r.num("allan.rest_s", finite=False),
            g_sensitivity=r.arr("g_sensitivity.matrix", (3, 3), default=np.zeros((3, 3))),
            method=r.text("method"),
            scale_asymmetry=r.arr("scale_asymmetry", (3,), default=[0.0, 0.0, 0.0]),
            effects=_unsanitize(r.get("effects", {})),
        )


# ---------------------------------------------------------------------------------------------
# the compiled parts: one program per padded shape


def _angles(c9, motions: Motions) -> jax.Array:
    """Per-motion miss angle, radians: 2 asin(|r| / 2) of the gravity residual r."""
    r = gravity_residual(c9, motions).reshape(-1, 3)
    return 2.0 * jnp.arcsin(jnp.clip(jnp.linalg.norm(r, axis=1) / 2.0, 0.0, 1.0))


def _scan_costs(scales, motions: Motions, weights) -> jax.Array:
    """Sum of weighted squared miss angles for C = s I, for each s in ``scales``."""
    eye = jnp.eye(3, dtype=motions.rates.dtype).ravel()
    return jax.vmap(lambda s: jnp.sum(weights * _angles(s * eye, motions) ** 2))(scales)


def _fit(p0, motions: Motions, weights, update_type: int, asymmetric: bool = False):
    """LM on the gravity residual (C, nine entries) or, with ``asymmetric``, on C and the
    three scale asymmetries. A miss between unit vectors has no component along gravity to
    first order: each motion gives two independent residuals, not three."""
    return lm_solve(
        gravity_residual_asymmetric if asymmetric else gravity_residual,
        p0,
        motions,
        weights=jnp.repeat(weights, 3),
        update_type=update_type,
        dof=2.0 * jnp.sum(weights) - p0.shape[0],
    )


@functools.lru_cache(maxsize=8)
def _compiled(name: str, update_type: int = 1):
    if name == "fit":
        return disk_jit(functools.partial(_fit, update_type=update_type), f"gyro.fit {update_type}")
    if name == "fit_asymmetric":
        fun = functools.partial(_fit, update_type=update_type, asymmetric=True)
        return disk_jit(fun, f"gyro.fit_asymmetric {update_type}")
    fun = {"angles": _angles, "start": start_scale}[name]
    return disk_jit(fun, f"gyro.{name}")


# ---------------------------------------------------------------------------------------------
# host side


TIES_MAX = 0.05
"""At most this share of a time column's steps may be zero (a clock coarser than the sampling
writes some stamps twice, e.g. ms stamps at 52 Hz): each run of equal stamps is then spread
evenly up to the next one. More, or any step back, is a clock the fit cannot use."""


MIN_RATE_HZ = 5.0
"""A time column whose steps give a rate below this is in the wrong unit: a gyro log in
milliseconds given as seconds (100 Hz read as 0.1 Hz) found 697 'poses' in a 38-pose log and
a gyro scale of 1e-7, and no note named the time."""


def _time_steps(t, sample_rate, n: int, notes: list[str]) -> tuple[np.ndarray, float]:
    """(dt (N,), the time from each sample to the next; the sample rate) from the time column
    or the sample rate; a ValueError saying what to give when neither is there. Repeated
    stamps (:data:`TIES_MAX`) are spread, with a note."""
    if t is not None:
        t = np.asarray(t, float)
        dt = np.diff(t)
        ties = int(np.sum(dt == 0))
        if ties and np.all(np.isfinite(dt)) and np.all(dt >= 0) and ties <= TIES_MAX * len(dt):
            first = np.flatnonzero(np.r_[True, dt > 0])  # where each run of equal stamps starts
            run = np.diff(np.r_[first, len(t)])
            ends = np.r_[t[first[1:]], t[-1] + np.median(dt[dt > 0])]
            step = np.repeat((ends - t[first]) / run, run)
            t = t + step * (np.arange(len(t)) - np.repeat(first, run))
            dt = np.diff(t)
            notes.append(
                f"{ties} time stamps repeat the one before (a clock coarser than the samples); "
                "each run of equal stamps was spread evenly to the next"
            )
        if not np.isfinite(t).any():
            raise ValueError(
                f"the column read as time holds no numbers ({len(t)} cells are text or empty): "
                "map the columns with --columns, _ for the one to skip (e.g. _,ax,ay,az,gx,gy,gz"
                ",...), and give the sample rate, --sample-rate"
            )
        if len(t) != n or not np.all(np.isfinite(dt)) or np.any(dt <= 0):
            bad = int(np.sum(~(dt > 0)))
            raise ValueError(
                f"the time column must increase from sample to sample: {bad} steps do not; "
                "gyro integration needs the time between samples (fix the column, or leave it "
                "out and give the sample rate, --sample-rate)"
            )
        rate = sample_rate or rate_from_steps(dt, [])
        if sample_rate is None and rate and rate < MIN_RATE_HZ:
            step = float(np.median(dt))
            raise ValueError(
                f"the time column steps by {step:.4g} s ({rate:.3g} Hz): integrating a turn "
                f"needs {MIN_RATE_HZ:g} samples a second or more, and a gyro log has tens or "
                f"hundreds. If the column is in milliseconds, divide it by 1,000 ({step / 1e3:.3g}"
                f" s, {rate * 1e3:.4g} Hz); in microseconds by 1,000,000; or leave it out and "
                "give the sample rate (--sample-rate)"
            )
        if rate and abs(rate * float(np.median(dt)) - 1.0) > UNEVEN_STEPS:
            # stamps of delivery, not of sampling (a logger writing in bursts), or a rate the
            # user gave against the column: each sample is one period of the rate
            notes.append(
                f"the time stamps step unevenly (median {1e3 * float(np.median(dt)):.3g} ms, "
                f"mean {1e3 * float(np.mean(dt)):.3g} ms) against the sample rate "
                f"{rate:.4g} Hz: the rates are integrated at one sample per 1/{rate:.4g} s"
            )
            return np.full(n, 1.0 / rate), float(rate)
        return np.append(dt, 0.0), float(rate or 1.0 / np.median(dt))
    if sample_rate is None:
        raise ValueError(
            "the gyro fit integrates the rates over time, and the log has neither a time "
            "column nor a sample rate: give the rate (--sample-rate HZ on the command line, "
            "sample_rate= in Python)"
        )
    return np.full(n, 1.0 / sample_rate), float(sample_rate)


def _at_extreme(g: np.ndarray) -> np.ndarray:
    """(N, 3) True where an axis reads its log-wide maximum or minimum, for an extreme read in
    3 or more samples: a clipped reading (or, near rest, a quantised one)."""
    out = np.zeros(g.shape, bool)
    for ax in range(3):
        col = g[:, ax]
        for ext in (col.max(), col.min()):
            hit = col == ext
            if hit.sum() >= 3:
                out[:, ax] |= hit
    return out


def _saturated(g: np.ndarray, bias: np.ndarray, noise: np.ndarray) -> np.ndarray:
    """(N, 3) True where an axis sits at its log-wide extreme, far from rest, in 3 or more
    samples: the reading clipped at the gyro's range."""
    return _at_extreme(g) & (np.abs(g - bias) > 50 * np.maximum(noise, 1e-12))


MAX_REST_TURN_DEG_S = 0.1
"""deg/s: a rest whose magnetic field direction turns faster than this is a steady turn (BROAD
trial 02: a 26 deg/s turn about the vertical passed the accelerometer and gyro tests, its
field turned 12 deg/s; true rests there turn < 0.025 deg/s)."""


def gyro_still_intervals(
    g: np.ndarray,
    intervals: np.ndarray,
    mag: np.ndarray | None = None,
    sample_rate: float | None = None,
) -> np.ndarray:
    """The accelerometer's static intervals narrowed to where the gyro is still too.

    A turn that starts slowly about an axis near gravity barely moves the gravity direction,
    so the accelerometer's intervals can reach into it; the gyro sees it. Within each
    interval the longest run of samples within 3 median deviations of the interval's median
    rate is kept (3 x the median of a three-axis noise norm is 2 standard deviations past its
    99.9th percentile). A steady turn about gravity leaves both quiet; with the magnetometer
    (``mag`` on the same clock, and ``sample_rate``) an interval whose field direction turns
    faster than :data:`MAX_REST_TURN_DEG_S` (first quarter against last) is dropped."""
    out = []
    for s, e in intervals:
        dev = np.linalg.norm(g[s:e] - np.median(g[s:e], axis=0), axis=1)
        quiet = np.concatenate([[False], dev <= 3.0 * np.median(dev), [False]])
        edges = np.flatnonzero(np.diff(quiet.astype(int)))
        starts, stops = edges[0::2], edges[1::2]
        j = int(np.argmax(stops - starts))
        s, e = s + starts[j], s + stops[j]
        if (
            mag is None
            or sample_rate is None
            or _field_turn_deg_s(mag[s:e], sample_rate) <= (MAX_REST_TURN_DEG_S)
        ):
            out.append((s, e))
    return np.array(out, int).reshape(-1, 2)


def _field_turn_deg_s(m: np.ndarray, sample_rate: float) -> float:
    """How fast the field direction turns over a stretch: the angle between the mean
    directions of its first and last quarters over the time between their centres; 0 when
    too short, or when that angle is within 4 standard errors of the quarters' noise (a short
    rest's few samples cannot tell a slow turn from noise)."""
    angle, noise = quarter_turn(m)
    if angle <= 4.0 * noise:
        return 0.0
    return float(np.degrees(angle)) / ((len(m) - len(m) // 4) / sample_rate)


def _motion_windows(intervals: np.ndarray) -> list[tuple[int, int, int]]:
    """(pose i, first, stop) sample ranges from the last static sample of pose i to the first
    of pose i + 1."""
    iv = np.asarray(intervals).tolist()
    return [(i, iv[i][1] - 1, iv[i + 1][0] + 1) for i in range(len(iv) - 1)]


def _pad_motions(windows, rates_of, dt, dirs) -> tuple[Motions, np.ndarray]:
    """Motions padded to powers of two in count and length (zero rates and steps, weight 0);
    ``rates_of(s, e)`` gives the de-biased raw rates of samples [s, e)."""
    k = bucket(len(windows)) if len(windows) > 8 else 8
    length = bucket(max(e - s for _, s, e in windows))
    rates = np.zeros((k, length, 3))
    steps = np.zeros((k, length))
    before = np.tile([0.0, 0.0, 1.0], (k, 1))
    after = before.copy()
    for j, (i, s, e) in enumerate(windows):
        rates[j, : e - s] = rates_of(s, e)
        steps[j, : e - s - 1] = dt[s : e - 1]
        before[j], after[j] = dirs[i], dirs[i + 1]
    w = np.zeros(k)
    w[: len(windows)] = 1.0
    return Motions(rates, steps, before, after), w  # numpy: the compiled fits take it over


def _nested_f_test(rss0: float, rss1: float, extra: int, dof: int) -> tuple[float, float]:
    """(F, p) of ``extra`` added parameters from residual sums rss0 -> rss1, with ``dof``
    degrees of freedom left in the larger model; NaN when the test is not defined."""
    from scipy.stats import f as f_dist

    if dof < 3 or not rss1 > 0:
        return float("nan"), float("nan")
    F = ((rss0 - rss1) / extra) / (rss1 / dof)
    return float(F), float(f_dist.sf(F, extra, dof))


@dataclass(frozen=True)
class _RestCandidate:
    """A quantity the rest bias may follow: its value at each pose (P, k) and at any stretch
    of samples (``of(s, e)`` -> (n, k)), and the words of the report."""

    name: str
    at_poses: np.ndarray
    of: object
    label: str
    present: str
    absent: str
    applied: str
    unit: str
    reference: float | None = None


def _rest_candidates(
    log: _PoseLog, accel, to_ms2: float, tt, notes: list, temperature: bool = True
) -> list:
    """The candidates a log allows, in the order they are tested: the acceleration (always),
    the time, the temperature (with ``temperature``, and a temperature column that varies)."""
    iv = log.intervals
    pose_t = np.array([tt[s:e].mean() for s, e in iv])
    t0 = float(pose_t.mean())
    out = [
        _RestCandidate(
            "g_sensitivity",
            log.pose_out * to_ms2,
            lambda s, e: accel.apply(log.acc[s:e]) * to_ms2,
            "g-sensitivity",
            "the rest bias follows the acceleration, b + G a",
            "at p < 1e-3 the rest bias does not follow the acceleration",
            "G is applied during the turns and kept in the calibration",
            "{units} per m/s^2",
        ),
        _RestCandidate(
            "bias_drift",
            (pose_t - t0)[:, None],
            lambda s, e: (tt[s:e] - t0)[:, None],
            "bias drift",
            "the rest bias drifts over the session, b + d (t - t0)",
            "at p < 1e-3 the rest bias does not drift over the session",
            "the drift is removed during this log's turns (it is this session's, not the "
            "sensor's: it is not applied to other logs)",
            "{units} per s",
            t0,
        ),
    ]
    if temperature and log.temp is not None:
        temp = log.temp
        pose_T = np.array([np.nanmean(temp[s:e]) for s, e in iv])
        if np.all(np.isfinite(pose_T)) and np.ptp(pose_T) >= 0.1:
            T0 = float(pose_T.mean())
            out.append(
                _RestCandidate(
                    "temperature",
                    (pose_T - T0)[:, None],
                    lambda s, e: (temp[s:e] - T0)[:, None],
                    "temperature",
                    "the rest bias follows the temperature, b + k (T - T0)",
                    "at p < 1e-3 the rest bias does not follow the temperature",
                    "removed during the turns; the coefficient k is reported, not applied to "
                    "other logs",
                    "{units} per deg C",
                    T0,
                )
            )
        else:
            notes.append(
                "temperature not tested: the poses' temperatures span less than 0.1 deg C "
                "(or hold NaN)"
            )
    return out


def _design(cands: list, with_intercept: bool = True) -> np.ndarray:
    """The pose design matrix [1, each candidate's columns]."""
    cols = [c.at_poses for c in cands]
    n = len(cands[0].at_poses) if cands else 0
    if with_intercept:
        cols = [np.ones((n, 1))] + cols
    return np.hstack(cols)


def _rest_test(pose_means: np.ndarray, accepted: list, cand: _RestCandidate) -> dict:
    """Does ``cand`` explain the pose means beyond the ``accepted`` candidates? Least squares
    of the pose means on both designs, a nested F test of the candidate's 3 k coefficients
    (accepted at p < 1e-3), the spread of the pose means about each model."""
    n = len(pose_means)
    X0 = _design(accepted) if accepted else np.ones((n, 1))
    X1 = _design([*accepted, cand])
    r0 = pose_means - X0 @ np.linalg.lstsq(X0, pose_means, rcond=None)[0]
    coef = np.linalg.lstsq(X1, pose_means, rcond=None)[0]
    r1 = pose_means - X1 @ coef
    extra = 3 * cand.at_poses.shape[1]
    F, p = _nested_f_test(float(np.sum(r0**2)), float(np.sum(r1**2)), extra, 3 * (n - X1.shape[1]))
    # standard errors of every coefficient, per axis: s_j^2 (X'X)^-1 (the pose means taken as
    # independent, which the F test assumes too)
    var = np.sum(r1**2, axis=0) / max(n - X1.shape[1], 1)
    unscaled = np.diag(np.linalg.pinv(X1.T @ X1))
    return {
        "F": F,
        "p": p,
        "accepted": bool(p < 1e-3),
        "coef": coef,
        "stderr": np.sqrt(np.outer(unscaled, var)),
        "spread_before": r0.std(axis=0),
        "spread_after": r1.std(axis=0),
    }


def _rest_coefficients(cands: list, coef: np.ndarray) -> dict:
    """Each candidate's block of the joint coefficients: G (3, 3) for the acceleration, a
    (3,) vector for the time and the temperature."""
    blocks = _blocks(cands, coef)
    return {c.name: b.T if len(b) > 1 else b[0] for c, b in zip(cands, blocks, strict=True)}


def _rest_model(g: np.ndarray, cands: list, coef: np.ndarray):
    """``rates_of(s, e)``: the raw rates less the rest model b + sum of each candidate's
    coefficients times its value at those samples."""

    def rates_of(s, e):
        x = g[s:e] - coef[0]
        for c, block in zip(cands, _blocks(cands, coef), strict=True):
            x = x - c.of(s, e) @ block
        return x

    return rates_of


def _blocks(cands: list, coef: np.ndarray) -> list:
    """The rows of the joint coefficients (after the intercept) of each candidate, (k, 3)."""
    ends = np.cumsum([1] + [c.at_poses.shape[1] for c in cands])
    return [coef[a:b] for a, b in zip(ends[:-1], ends[1:], strict=True)]


def _fit_scaled(motions: Motions, w: np.ndarray, scale: float, solver: str):
    """The LM fit of C in units of the start scale (C_n near the identity): (C, covariance,
    standard errors, the solver's result, per-motion miss in degrees)."""
    k = int(w.sum())
    motions = motions._replace(rates=motions.rates * scale)
    res = _compiled("fit", int(solver[-1]))(np.eye(3).ravel(), motions, w)
    miss = np.degrees(np.asarray(_compiled("angles")(res.params, motions))[:k])
    return (*_unscaled(res, scale), res, miss)


def _unscaled(res, scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(C, its covariance, its standard errors; inf where the solver found none) back in raw
    units from a fit in units of the start scale; C's nine entries lead ``res.params``."""
    C = np.asarray(res.params[:9]).reshape(3, 3) * scale
    cov = np.asarray(res.covariance)[:9, :9] * scale**2
    stderr = np.sqrt(np.clip(np.diag(cov), 0, None)).reshape(3, 3)
    stderr = np.where(np.isfinite(np.asarray(res.stderr[:9]).reshape(3, 3)), stderr, np.inf)
    return C, cov, stderr


def _turning(g: np.ndarray) -> np.ndarray:
    """The readings of the turns, less the median reading: the samples more than 5 noise
    levels from the median (a pose log is mostly at rest). Rows where an axis reads its
    log-wide extreme 3 or more times are left out: a clipped reading says nothing of the axis
    turned about (a PicoQuake log starts with 32 rows of -250 deg/s on every axis, which read
    as 'turns about one axis only')."""
    g = g[~_at_extreme(g).any(axis=1)]
    dev = g - np.median(g, axis=0)
    size = np.linalg.norm(dev, axis=1)
    return dev[size > 5.0 * 1.4826 * np.median(size) + 1e-300]


TURN_SHARE_MIN = 0.2
"""A raw axis whose RMS rate during the turns is below this share of the largest axis's has
hardly been turned about (guidance while recording; the fit's own test is stricter)."""


def turn_axes_missing(g: np.ndarray) -> list[str]:
    """The gyro axes ('x', 'y', 'z') hardly turned about so far (:data:`TURN_SHARE_MIN`); all
    three when nothing has turned yet. For the recorder's guidance."""
    dev = _turning(np.asarray(g, float))
    if len(dev) < 10:
        return ["x", "y", "z"]
    rms = np.sqrt(np.mean(dev**2, axis=0))
    return [a for a, r in zip("xyz", rms, strict=True) if r < TURN_SHARE_MIN * rms.max()]


def _check_turn_axes(g: np.ndarray) -> None:
    """A ValueError naming the axes no turn in the log went about (their columns of C cannot
    be fitted). The turns are :func:`_turning`'s samples; their second moment sum
    (g - med)(g - med)' has an eigenvalue near zero, below 1e-3 of the largest, for each raw
    axis nothing turned about."""
    dev = _turning(g)
    if len(dev) < 10:
        return  # nothing turned at all: the motion count says so
    evals, evecs = np.linalg.eigh(dev.T @ dev)
    weak = [i for i in range(3) if evals[i] < 1e-3 * evals[-1]]
    if not weak:
        return
    v = evecs[:, weak[-1]]
    raise ValueError(
        f"the turns in this log go about {'one axis' if len(weak) == 2 else 'two axes'} only "
        f"(mostly the sensor's {_axis_name(evecs[:, -1])}): nothing turned about "
        f"{_axis_name(v)}, so the scale and misalignment of gyro axis "
        f"{'xyz'[int(np.argmax(np.abs(v)))]} cannot be determined; between poses turn the "
        "sensor about all three of its axes"
    )


def _axis_name(v: np.ndarray) -> str:
    v = v / np.linalg.norm(v)
    i = int(np.argmax(np.abs(v)))
    if abs(v[i]) > 0.95:
        return f"{'xyz'[i]} axis"
    return "axis [" + ", ".join(f"{c:+.2f}" for c in v) + "]"


SCAN_BLOCK = 8
"""The start's scans integrate blocks of this many samples as one step (8x faster; the start
needs the scale to a few per cent, the LM refines it on every sample)."""


def _coarse(motions: Motions, block: int = SCAN_BLOCK) -> Motions:
    """The motions with ``block`` consecutive steps merged: mean rate, summed time."""
    k, length = motions.dt.shape
    if length % block:
        return motions
    dt = motions.dt.reshape(k, length // block, block)
    steps = dt.sum(axis=2)
    rates = (motions.rates.reshape(k, length // block, block, 3) * dt[..., None]).sum(axis=2)
    rates = rates / jnp.where(steps > 0, steps, 1.0)[..., None]
    return motions._replace(rates=rates, dt=steps)


def start_scale(motions: Motions, weights: jax.Array) -> jax.Array:
    """The common scale s (rad/s per unit) with the smallest miss for C = s I: a log scan of
    1e-7 to 100 either sign, then a fine one around the best, on merged steps. Pure and
    jittable (the pipeline's start); the fit needs no unit or initial guess."""
    motions = _coarse(motions)
    scan = jnp.asarray(_SCAN, motions.rates.dtype)
    s0 = scan[jnp.nanargmin(_scan_costs(scan, motions, weights))]
    fine = s0 * jnp.exp(jnp.linspace(-0.25, 0.25, len(_SCAN), dtype=scan.dtype))
    return fine[jnp.nanargmin(_scan_costs(fine, motions, weights))]


COUNT_SCALES = (1e-6, 1e-2)
"""rad/s per count that a gyro's raw counts can have (an MPU-6050 at +-250 deg/s: 1.3e-4)."""


def _resolve_units(units: str, scale: float) -> tuple[str, list[str]]:
    """The input unit: declared (checked against the fitted scale) or recognised from it."""
    if units in UNIT_SCALES:
        ratio = scale / UNIT_SCALES[units]
        if not 0.5 < ratio < 2.0:
            found = [u for u, f in UNIT_SCALES.items() if 0.7 < scale / f < 1.4]
            say = f"they are {found[0]}" if found else "they look like raw counts"
            raise ValueError(
                f"units={units!r}, but the rotations between poses need {scale:.4g} rad/s per "
                f"unit of the readings ({ratio:.3g} x the {units} scale): {say}; give "
                f"units={found[0] if found else 'counts'!r} (--gyro-units) or 'auto'"
            )
        return units, []
    if units not in ("auto", "counts"):
        raise ValueError(f"units must be auto, counts, rad/s or deg/s, got {units!r}")
    for u, f in UNIT_SCALES.items():
        if units == "auto" and 0.8 < scale / f < 1.25:
            return u, [f"gyro units: {u} (the fitted scale is {scale / f:.3f} x the {u} scale)"]
    if not COUNT_SCALES[0] <= abs(scale) <= COUNT_SCALES[1]:
        return "counts", [
            f"gyro units: none fits: the rotations between poses need {scale:.4g} rad/s per "
            "unit of the readings, which is neither rad/s nor deg/s nor a gyro's count "
            f"({COUNT_SCALES[0]:g} to {COUNT_SCALES[1]:g} rad/s): the turns may not join the "
            "poses (too small, or a pose missed); --gyro-units declares the unit"
        ]
    return "counts", [f"gyro units: raw counts, {1 / scale:.5g} counts per rad/s"]


ASYMMETRY_PLAUSIBLE = 0.1
"""A scale asymmetry (or its standard error) above this on any axis is no gyroscope's (MEMS
parts stay within about 1 %): a hand-tilted MPU-6050 log gave s_z = -2.4 +- 3.4 at F = 95,
"found", with a z scale of 0.14. The refit is then not applied."""


def implausible_scale(C: np.ndarray, nominal: float, units: str) -> str | None:
    """Why a gyro fit's scale is no gyroscope's (None when it is): the singular values of C
    against the nominal scale of ``units`` (for counts, the data's own starting scale) outside
    :data:`calib_jax.accel.GAINS_PLAUSIBLE`, the accelerometer's rule."""
    from .accel import GAINS_PLAUSIBLE

    C = np.asarray(C, float)
    if not np.all(np.isfinite(C)):
        return "the fitted scale is not finite: this is no calibration"
    sv = np.linalg.svd(C, compute_uv=False) / abs(nominal)
    lo, hi = GAINS_PLAUSIBLE
    if sv.min() >= lo and sv.max() <= hi:
        return None
    return (
        f"the fitted scale is {sv.min():.3g} to {sv.max():.3g} times the {units} scale (the "
        f"singular values of C), where any gyroscope's lies within {lo:g}-{hi:g} of it: the "
        "motions do not determine the model (turns about too few axes, rests that moved, "
        "clipped rates, or gravity directions from a poorly determined accelerometer fit). "
        "Record poses held still with turns about all three axes between them; this is no "
        "calibration"
    )


def _test_asymmetry(motions: Motions, w: np.ndarray, scale: float, solver: str, res) -> dict:
    """Refit with a scale asymmetry per axis (12 parameters) from the nine-parameter optimum
    ``res``; an F test of the three on the LM chi2, accepted at p < 1e-3 where every
    coefficient and its standard error are within :data:`ASYMMETRY_PLAUSIBLE`."""
    k = int(w.sum())
    scaled = motions._replace(rates=motions.rates * scale)
    p0 = np.concatenate([np.asarray(res.params), np.zeros(3)])
    r12 = _compiled("fit_asymmetric", int(solver[-1]))(p0, scaled, w)
    F, p = _nested_f_test(float(res.chi2), float(r12.chi2), 3, 2 * k - 12)
    angles_of = _compiled("angles")
    corrected = scaled._replace(rates=asymmetric(scaled.rates, np.asarray(r12.params[9:]), np))
    miss = np.degrees(np.asarray(angles_of(r12.params[:9], corrected))[:k])
    coef, se = np.asarray(r12.params[9:]), np.asarray(r12.stderr[9:])
    plausible = bool(np.all(np.abs(coef) <= ASYMMETRY_PLAUSIBLE))
    plausible &= bool(np.all(se <= ASYMMETRY_PLAUSIBLE))  # NaN is not
    significant = bool(p < 1e-3) and bool(np.isfinite(F))
    return {
        "effect": {
            "accepted": significant and plausible,
            "significant": significant,
            "F": F,
            "p": p,
            "coefficients": coef.tolist(),
            "stderr": se.tolist(),
        },
        "fit": (*_unscaled(r12, scale), r12, miss),
        "miss": miss,
    }


def _allan_fields(g, intervals, bias, C, rate) -> dict:
    """The Allan noise terms of the longest rest, calibrated (rad/s)."""
    s, e = max(np.asarray(intervals).tolist(), key=lambda se: se[1] - se[0])
    arw, bi = allan_noise((g[s:e] - bias) @ C.T, rate)
    return {"angle_random_walk": arw, "bias_instability": bi, "allan_rest_s": (e - s) / rate}


def _poorly_determined(stderr: np.ndarray, C: np.ndarray) -> list[str]:
    """The entries of C whose standard error exceeds 5 % of their row's scale (the row's
    norm: a gyro mounted rotated has near-zero diagonal entries, which made every entry
    'poorly determined' against them)."""
    out = []
    for i in range(3):
        for j in range(3):
            se, ref = stderr[i, j], float(np.linalg.norm(C[i]))
            if not np.isfinite(se) or se > 0.05 * ref:
                out.append(f"C[{i},{j}]")
    return out


def allan_deviation(
    x: np.ndarray, sample_rate: float, taus: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Overlapping Allan deviation of rate samples x (N,) or (N, k): (taus in s, sigma (T,) or
    (T, k)). Default taus: 40 log-spaced cluster sizes from one sample to a ninth of the
    record (the estimate needs many clusters)."""
    x = np.asarray(x, float)
    n = len(x)
    tau0 = 1.0 / sample_rate
    if taus is None:
        m = np.unique(np.logspace(0, np.log10(max(n // 9, 1)), 40).astype(int))
    else:
        m = np.unique(np.maximum(np.round(np.asarray(taus) / tau0), 1).astype(int))
    m = m[m < n // 2]
    theta = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(x, axis=0) * tau0])
    out = []
    for k in m:
        d = theta[2 * k :] - 2.0 * theta[k:-k] + theta[: -2 * k]
        out.append(np.sqrt(np.mean(d**2, axis=0) / (2.0 * (k * tau0) ** 2)))
    return m * tau0, np.array(out)


def allan_noise(x: np.ndarray, sample_rate: float) -> tuple[np.ndarray, np.ndarray]:
    """(angle random walk N, bias instability B) per column of rest rates x (N, k).

    N: the white-noise line sigma(tau) sqrt(tau) read where the deviation still falls as
    tau^-1/2 (the median over taus up to 1/20 of the record, whose slope must lie within 0.15
    of -1/2; else NaN). B: min sigma / 0.664 (IEEE 952; a bound when the record is too short
    for the floor)."""
    taus, sig = allan_deviation(x, sample_rate)
    if len(taus) < 4:
        return np.full(x.shape[1], np.nan), np.full(x.shape[1], np.nan)
    short = taus <= max(taus[0] * 4, len(x) / sample_rate / 20)
    slope = np.polyfit(np.log(taus[short]), np.log(sig[short]), 1)[0]
    arw = np.median(sig[short] * np.sqrt(taus[short])[:, None], axis=0)
    arw = np.where(np.abs(slope + 0.5) < 0.15, arw, np.nan)
    return arw, sig.min(axis=0) / 0.664


@dataclass
class _PoseLog:
    """A gyro log cut into rests and motions (host side): what :func:`calibrate_gyro` and
    :func:`calib_jax.pipeline.gyro_inputs` both fit."""

    acc: np.ndarray
    g: np.ndarray
    dt: np.ndarray
    rate: float
    accel: AccelCalibration
    intervals: np.ndarray
    """(P, 2) still sample ranges of the poses."""
    windows: list
    """(pose i, first, stop) of each usable motion."""
    dirs: np.ndarray
    """(P, 3) unit gravity directions of the poses, from the calibrated accelerometer."""
    pose_out: np.ndarray
    notes: list
    warn: list
    source: object
    bias: np.ndarray
    """(3,) the mean raw reading over every rest sample."""
    noise: np.ndarray
    """(3,) the raw readings' white noise at rest (:func:`_rest_noise`)."""
    n_rest: int
    """Rest samples in all."""
    temp: np.ndarray | None = None
    """Temperature of each sample (deg C), when the log has it."""


def _pose_log(data, gyro, t, sample_rate, accel, accel_options, temp=None) -> _PoseLog:
    """Check the log, calibrate its accelerometer if not given, find the rests and the usable
    motions between them; a ValueError saying what to change where that fails."""
    from .accel import ACCEL6_OPTION, REFUSALS, REST_RMS_LIMIT, calibrate_accel

    notes: list[str] = []
    warn: list[str] = []
    source = None
    mag = None  # with a magnetometer, a steady turn about gravity is not taken for a rest
    data = as_log(data, None if gyro is None else "accel")
    if gyro is not None and isinstance(data, SensorLog):  # the gyro's own file or readings
        gyro = as_log(gyro, "gyro")
        if not isinstance(gyro, SensorLog):
            gyro = SensorLog(acc=None, gyro=np.asarray(gyro, float), t=data.t)
        data = join_logs(data, gyro)
    if isinstance(data, SensorLog):
        if data.acc is None and data.gyro is not None:
            raise ValueError(
                f"{data.path or 'the log'} holds the gyro but no accelerometer, and the fit "
                "needs gravity's direction at each pose: give the accelerometer's file first "
                "(calib-jax gyro ACC_FILE GYRO_FILE; calibrate_gyro(acc_log, gyro_log) in "
                "Python), or map its columns with --columns if this file has them"
            )
        acc, g = data.vectors("accel"), data.vectors("gyro")
        mag = None if data.mag is None else np.asarray(data.mag, float)
        temp = data.temp
        t, sample_rate = data.t, sample_rate or data.sample_rate
        notes += list(data.notes)
        source = data.path
    else:
        if gyro is None:
            raise ValueError("give the gyro readings: calibrate_gyro(acc, gyro, ...)")
        acc, g = np.asarray(data, float), np.asarray(gyro, float)
    if g.ndim != 2 or g.shape[1] != 3:
        raise ValueError(f"gyro data must be (samples, 3), got shape {g.shape}")
    if len(acc) != len(g):
        raise ValueError(
            f"the accelerometer has {len(acc)} samples and the gyro {len(g)}: they must share "
            "one clock, sample for sample (resample one onto the other's times first)"
        )
    rows = np.isfinite(g).all(axis=1) & np.isfinite(acc).all(axis=1)
    if not rows.all():
        if t is None or not np.isfinite(np.asarray(t, float)[rows]).all():
            raise ValueError(
                f"{int((~rows).sum())} rows hold NaN or inf in the accelerometer or gyro: the "
                "rates are integrated sample by sample, so without a time column those rows "
                "cannot be skipped; fill or cut them first"
            )
        # with a time column a row without readings is a gap the time steps span
        notes.append(
            f"{int((~rows).sum())} rows without a finite accelerometer and gyro reading left "
            "out (the time column spans them)"
        )
        acc, g, t = acc[rows], g[rows], np.asarray(t, float)[rows]
        mag = None if mag is None else mag[rows]
        temp = None if temp is None else np.asarray(temp, float)[rows]
    if looks_like_pose_table(acc):
        raise ValueError(
            f"the {len(acc)} rows look like a pose table (one averaged row per pose, each far "
            "from the next): the gyro fit integrates the turns between poses, and a pose "
            "table holds none. Give the log the table was made from (every sample, with a "
            "time column or --sample-rate)"
        )
    held = [ax for ax in range(3) if np.all(g[:, ax] == g[0, ax])]
    if held:
        axes = ", ".join(f"{'xyz'[ax]} reads {g[0, ax]:g}" for ax in held)
        raise ValueError(
            f"the gyro's {axes} in every sample: a stuck axis or a column that is no reading "
            "(an Android uncalibrated event's bias estimate is constant); check which columns "
            "were read as gx, gy, gz (the note above) and map them with --columns"
        )
    dt, rate = _time_steps(t, sample_rate, len(g), notes)
    _check_turn_axes(g)
    own_accel = accel is None
    if accel is None:
        # six-face logs: gravity's direction needs no cross terms
        try:
            accel = calibrate_accel(
                acc, sample_rate=rate, **{"model": "auto", **(accel_options or {})}
            )
        except TooFewPoses as exc:  # say whose poses: a gyro user read only of "the model"
            raise TooFewPoses(
                "the gyro is fitted to the turns between the accelerometer's static poses, "
                f"and the accelerometer has {exc.finding}",
                exc.n_distinct,
                exc.model,
                exc.samples_tried,
            ) from None
        accel_rows = f"{len(acc)} accelerometer rows with a gyro reading"
        notes.append(
            f"accelerometer calibrated first on the {accel_rows}: {accel.n_intervals} static "
            f"poses, status {accel.status}, RMS (|a| - g)/g {accel.rms_after:.2g}"
        )
    if accel.status == "poorly_determined":  # the gravity directions rest on it, given or not
        warn.append(
            "the accelerometer calibration the gyro fit rests on is poorly determined ("
            + "; ".join(accel.warnings or [", ".join(accel.poorly_determined)])
            + "): gravity directions from it carry its errors into the gyro's"
        )
    if not accel.success:
        why = [w for w in accel.warnings if w.startswith(("all poses lie", "gravity hardly"))]
        refusals = [w for w in accel.warnings if w.startswith(REFUSALS)]
        # gains no accelerometer has, none determined, or poses that are no rests: the
        # solver's "raise the budget" would contradict them
        reasons = "; ".join(refusals + why if refusals else [accel.solver_message, *why])
        # the accelerometer's own flags are the gyro's --accel-* (a trial ran --model accel6)
        reasons = reasons.replace(
            ACCEL6_OPTION,
            "--accel-model accel6 on calib-jax gyro, accel_options={'model': 'accel6'} in Python",
        )
        raise ValueError(
            "the accelerometer calibration "
            + ("failed" if accel.status == "failed" else "did not converge")
            + " ("
            + reasons
            + "): the gravity directions the gyro is fitted to would be wrong; fix the "
            "accelerometer fit first"
            + (
                f" (fitted here to the {accel_rows}; the notes say which rows were left out, "
                "so calib-jax accel on the whole file can fit differently)"
                if own_accel
                else ""
            )
        )
    iv = np.asarray(accel.static_intervals, int).reshape(-1, 2)
    if len(iv) == 0 or iv[-1, 1] > len(g):
        raise ValueError(
            "the accelerometer calibration holds no static intervals of this log (it was "
            "fitted to other data, or loaded from a file written before they were kept): "
            "leave accel= out to fit it here"
        )

    # rests: bias and noise (for the clipping test)
    iv = gyro_still_intervals(g, iv, mag, rate)
    moving = _moving_rests(g, iv)
    if moving.any():
        notes.append(
            f"{int(moving.sum())} of {len(iv)} static poses left out as rests: the gyro turned "
            f"or shook during them (a mean rate or a scatter more than {MOVING_REST:g}x the "
            "rests' typical scatter away from the others), motion the accelerometer did not "
            "see: samples "
            + ", ".join(f"[{s}, {e}) ({s / rate:.1f}-{e / rate:.1f} s)" for s, e in iv[moving][:6])
            + (", ..." if moving.sum() > 6 else "")
        )
        iv = iv[~moving]
    rest = np.concatenate([g[s:e] for s, e in iv])
    bias = rest.mean(axis=0)
    noise_raw = _rest_noise(g, iv)
    pose_out = accel.apply(np.array([acc[s:e].mean(axis=0) for s, e in iv]))  # output units
    dirs = pose_out / np.linalg.norm(pose_out, axis=1, keepdims=True)

    # motions between consecutive poses
    if own_accel and accel.rms_after >= REST_RMS_LIMIT:
        warn.append(
            f"the accelerometer's {accel.n_intervals} poses leave {accel.rms_after:.2g} of g "
            f"after its fit (held rests leave under {REST_RMS_LIMIT:g}): they look like pauses "
            "in a motion, not rests, and the gyro's bias and the gravity directions it turns "
            "between come from them"
        )
    windows = _motion_windows(iv)
    gap = max(GAP_S, GAP_STEPS / rate)
    longest_step = [dt[s : e - 1].max(initial=0.0) for _, s, e in windows]
    gapped = [w for w, step in zip(windows, longest_step, strict=True) if step > gap]
    gap_warning = ""
    if gapped:
        gap_warning = (
            f"{len(gapped)} of {len(windows)} motions span a gap in the time column (up to "
            f"{max(longest_step):.3g} s without a sample, at {rate:.4g} Hz): the rotation "
            "during a gap was not recorded, so those motions were left out (a log joined from "
            "several recordings, or a logger that paused)"
        )
        warn.append(gap_warning)
    windows = [w for w in windows if w not in gapped]
    too_long = [(i, s, e) for i, s, e in windows if dt[s : e - 1].sum() > MAX_MOTION_S]
    if too_long:
        notes.append(
            f"{len(too_long)} motions longer than {MAX_MOTION_S:g} s left out (a pose the "
            "detector missed, or a pause in motion; its gyro drift would dominate)"
        )
    clipped = _saturated(g, bias, noise_raw)
    sat = [(i, s, e) for i, s, e in windows if clipped[s:e].any()]
    if sat:
        axes = [ax for a, ax in enumerate("xyz") if any(clipped[s:e, a].any() for _, s, e in sat)]
        warn.append(
            f"the gyro reads its extreme value in {int(clipped.any(axis=1).sum())} samples during "
            f"{len(sat)} motions (axes {', '.join(axes)}): those motions were left out; turn "
            "more slowly or choose a larger gyro range"
        )
    windows = [w for w in windows if w not in too_long and w not in sat]
    if len(windows) < MIN_MOTIONS:
        raise ValueError(
            f"{len(windows)} usable motions between {len(iv)} static poses: the gyro fit needs "
            f"at least {MIN_MOTIONS} rotations from one still pose to the next, about all "
            "three axes; record more poses with turns between them"
            + (f" ({gap_warning})" if gap_warning else "")
        )

    if temp is not None:
        temp = np.asarray(temp, float).ravel()
        if len(temp) != len(g):
            raise ValueError(
                f"the temperature has {len(temp)} samples and the gyro {len(g)}: one per sample"
            )
    return _PoseLog(
        acc, g, dt, rate, accel, iv, windows, dirs, pose_out, notes, warn, source,
        bias, noise_raw, len(rest), temp,
    )  # fmt: skip


MOVING_REST = 10.0
"""A rest whose mean rate lies further than this many times the rests' median scatter from
the rests' median rate, or whose own scatter is this many times the median, moved: a hand-held
board's fast turn that the accelerometer's detector took for a pose (MPU-6050 log of
tomisuarez2/ImuCalibration: 55 deg/s in a 'rest'). A sensor's bias moves by a fraction of its
per-sample noise between poses, so a clean log loses none."""


def _moving_rests(g: np.ndarray, intervals: np.ndarray) -> np.ndarray:
    """(n_intervals,) True for the rests that moved (:data:`MOVING_REST`); none with fewer
    than 4 rests (no majority to judge by)."""
    if len(intervals) < 4:
        return np.zeros(len(intervals), bool)
    means = np.array([g[s:e].mean(axis=0) for s, e in intervals])
    scatter = np.array([g[s:e].std(axis=0) for s, e in intervals])
    typical = np.maximum(np.median(scatter, axis=0), np.finfo(float).tiny)
    off = np.abs(means - np.median(means, axis=0))
    return np.any(off > MOVING_REST * typical, axis=1) | np.any(
        scatter > MOVING_REST * typical, axis=1
    )


def _rest_noise(g: np.ndarray, intervals) -> np.ndarray:
    """Per-axis white noise of the readings at rest (raw units), about each pose's mean."""
    n = sum(e - s for s, e in intervals)
    sq = sum(((g[s:e] - g[s:e].mean(0)) ** 2).sum(0) for s, e in intervals)
    return np.sqrt(sq / max(n - len(intervals), 1))


def calibrate_gyro(
    data: SensorLog | np.ndarray | str | os.PathLike,
    gyro: np.ndarray | SensorLog | str | os.PathLike | None = None,
    *,
    t: np.ndarray | None = None,
    sample_rate: float | None = None,
    accel: AccelCalibration | None = None,
    units: str = "auto",
    solver: str = "lm1",
    sensor_id: str | None = None,
    accel_options: dict | None = None,
    g_sensitivity: bool = True,
    scale_asymmetry: bool = True,
    bias_drift: bool = True,
    temperature: bool = True,
    temp: np.ndarray | None = None,
) -> GyroCalibration:
    """Calibrate a gyroscope from a multi-position log with rotations between the poses.

    Parameters
    ----------
    data : SensorLog, path or (N, 3) array
        A log (or log file) with accelerometer and gyro columns (and a time column or
        ``sample_rate``), or the accelerometer's readings or log with ``gyro`` the gyro's on
        the same clock.
    gyro : (N, 3) array, SensorLog or path, optional
        The gyro readings, or the gyro's own file of the same recording (imu_tk's two files:
        the same rows, and the same time column where both have one).
    t : (N,) array, optional
        Sample times in seconds (arrays only; a log brings its own).
    sample_rate : float, optional
        Hz, when there is no time column.
    accel : AccelCalibration, optional
        A calibration of this log's accelerometer from :func:`calibrate_accel` (its static
        intervals are used); default: fitted here.
    accel_options : dict, optional
        :func:`calibrate_accel`'s keywords for that fit (``g``, ``units``, detector settings).
    units : {"auto", "counts", "rad/s", "deg/s"}
        Of the gyro readings. The fit needs none (its start scans the scale); a declared unit
        that contradicts the fitted scale is an error, and "auto" names rad/s or deg/s when
        the scale is within 25 % of theirs.
    solver : {"lm1", "lm2", "lm3"}
        Gavin LM update type.
    g_sensitivity : bool
        Test whether the rest bias follows the acceleration (the pose means regressed on
        b + G a, an F test of G at p < 1e-3) and, when it does, remove b + G a during the
        turns and refit; the record's ``effects`` holds the test and the miss with and without.
    scale_asymmetry : bool
        Test whether turns read a different scale one way than the other (three more
        parameters, an F test at p < 1e-3 on the fit's chi2); kept when accepted.
    bias_drift, temperature : bool
        Test, as g-sensitivity and given what was accepted before, whether the rest bias
        drifts linearly over the session, or follows the temperature (a log with a
        temperature column, or ``temp``, whose poses differ by 0.1 deg C or more); an
        accepted one is removed during the turns and reported in ``effects`` (coefficients
        per second or per deg C), not applied to other logs.
    temp : (N,) array, optional
        Temperature of each sample, deg C (arrays only; a log brings its own column).

    Raises
    ------
    ValueError
        With what to change: no gyro columns, different lengths, no time, fewer than
        ``MIN_MOTIONS`` usable motions, rotations about fewer than three axes, contradictory
        units, or an accelerometer calibration that is not usable.
    """
    if solver not in ("lm1", "lm2", "lm3"):
        raise ValueError(f"solver must be lm1, lm2 or lm3, got {solver!r}")
    log = _pose_log(data, gyro, t, sample_rate, accel, accel_options, temp)
    acc, g, dt, rate, accel, iv = log.acc, log.g, log.dt, log.rate, log.accel, log.intervals
    windows, dirs, notes, warn = log.windows, log.dirs, log.notes, log.warn
    bias, noise_raw = log.bias, log.noise
    pose_means = np.array([g[s:e].mean(axis=0) for s, e in iv])
    motions, w = _pad_motions(windows, lambda s, e: g[s:e] - bias, dt, dirs)
    k = len(windows)
    scale = float(_compiled("start")(motions, w))  # C = s I: the fit's start, not its scale
    C, cov, stderr, res, after = _fit_scaled(motions, w, scale, solver)
    # the unit from the fitted C's singular values: a gyro mounted rotated or mirrored against
    # the accelerometer is no s I, and the start's s was 7x off on one turned 90 deg about z
    # (a correct fit then called 'failed', units 'none fits': a new-user trial)
    fitted = np.linalg.svd(C, compute_uv=False) if np.all(np.isfinite(C)) else None
    units, unit_notes = _resolve_units(
        units, float(np.median(fitted)) if fitted is not None else abs(scale)
    )
    notes += unit_notes
    angles = _compiled("angles")
    rms = lambda a: float(np.sqrt(np.mean(a**2)))  # noqa: E731
    nominal = UNIT_SCALES.get(
        units, float(np.median(fitted)) if fitted is not None else abs(scale)
    ) * np.sign(scale)
    before = np.degrees(np.asarray(angles(np.eye(3).ravel() * nominal, motions))[:k])
    rms_raw = float("nan")
    if units in UNIT_SCALES:
        raw_motions, _ = _pad_motions(windows, lambda s, e: g[s:e], dt, dirs)
        raw_angles = angles(jnp.eye(3).ravel() * nominal, raw_motions)
        rms_raw = rms(np.degrees(np.asarray(raw_angles)[:k]))

    # close the loop on the rests: does the rest bias follow the acceleration (g-sensitivity;
    # G per m/s^2: an output in g, or counts fitted to a reference g, is scaled so that gravity
    # reads standard gravity), the time (drift over the session) or the temperature? Each is
    # tested given those already accepted; an accepted one is removed during the turns too
    to_ms2 = 1.0 if accel.output_units == "m/s^2" else 9.80665 / accel.g
    tt = np.concatenate([[0.0], np.cumsum(dt[:-1])])  # seconds from the first sample
    wanted = {"g_sensitivity": g_sensitivity, "bias_drift": bias_drift, "temperature": temperature}
    found_in_log = _rest_candidates(log, accel, to_ms2, tt, notes, temperature)
    candidates = [c for c in found_in_log if wanted[c.name]]
    effects: dict = {}
    accepted: list[_RestCandidate] = []
    coef = pose_means.mean(axis=0, keepdims=True)  # the joint model's coefficients, (1 + K, 3)
    current = motions
    for cand in candidates:
        test = _rest_test(pose_means, accepted, cand)
        if not np.isfinite(test["F"]):
            continue
        effects[cand.name] = {"accepted": test["accepted"], "F": test["F"], "p": test["p"]}
        found = f"(F = {test['F']:.3g} over {len(pose_means)} poses, p = {test['p']:.2g})"
        if not test["accepted"]:
            notes.append(f"{cand.label} tested and not found {found}: {cand.absent}")
            continue
        accepted.append(cand)
        coef = test["coef"]
        motions_c, _ = _pad_motions(windows, _rest_model(g, accepted, coef), dt, dirs)
        fit_c = _fit_scaled(motions_c, w, scale, solver)
        effects[cand.name] |= {
            "coefficients": _rest_coefficients(accepted, coef)[cand.name].tolist(),
            "stderr": _rest_coefficients(accepted, test["stderr"])[cand.name].tolist(),
            "unit": cand.unit.format(units=units),
            "reference": cand.reference,
            "rest_spread_before": test["spread_before"].tolist(),
            "rest_spread_after": test["spread_after"].tolist(),
            "rms_without_deg": rms(after),
            "rms_with_deg": rms(fit_c[4]),
        }
        notes.append(
            f"{cand.label}: {cand.present} {found}; it takes the spread of the pose means "
            "from "
            + ", ".join(f"{v:.3g}" for v in test["spread_before"])
            + " to "
            + ", ".join(f"{v:.3g}" for v in test["spread_after"])
            + f" {units}, and the miss between poses from {rms(after):.3g} to "
            f"{rms(fit_c[4]):.3g} deg; {cand.applied}"
        )
        C, cov, stderr, res, after = fit_c
        current = motions_c
    G = np.zeros((3, 3))
    if accepted:
        bias = coef[0]
        pose_means = pose_means - _design(accepted, with_intercept=False) @ coef[1:]
        G = _rest_coefficients(accepted, coef).get("g_sensitivity", G)

    asym = np.zeros(3)
    if scale_asymmetry:
        fit_a = _test_asymmetry(current, w, scale, solver, res)
        effects["scale_asymmetry"] = fit_a["effect"] | {"rms_without_deg": rms(after)}
        effects["scale_asymmetry"]["rms_with_deg"] = rms(fit_a["miss"])
        F, p = fit_a["effect"]["F"], fit_a["effect"]["p"]
        testable = bool(np.isfinite(F))
        verdict = (
            "found"
            if fit_a["effect"]["accepted"]
            else f"fits better but is no gyroscope's (|s| or its error above "
            f"{ASYMMETRY_PLAUSIBLE:g}), so not applied"
            if fit_a["effect"]["significant"]
            else "tested and not found"
            if testable
            else "not testable (too few motions left for its F test)"
        )
        notes.append(
            f"scale asymmetry {verdict}: s = "
            + ", ".join(f"{v:+.2g}" for v in fit_a["effect"]["coefficients"])
            + " +- "
            + ", ".join(f"{v:.2g}" for v in fit_a["effect"]["stderr"])
            + (f" (F = {F:.3g}, p = {p:.2g})" if testable else "")
            + f"; miss {rms(after):.3g} -> {rms(fit_a['miss']):.3g} deg"
        )
        if fit_a["effect"]["accepted"]:
            C, cov, stderr, res, after = fit_a["fit"]
            asym = np.asarray(fit_a["effect"]["coefficients"]) * np.sign(scale)

    # what the rest noise alone leaves, in the two directions gravity can see: white rate
    # noise integrated over each motion, and the noise of the two poses' mean directions
    noise = np.sqrt(np.diag(C @ np.diag(noise_raw**2) @ C.T))
    durations = np.array([np.sum(dt[s : e - 1]) for _, s, e in windows])
    pose_dir_var = (
        np.array([np.mean(np.var(accel.apply(acc[s:e]), axis=0)) / (e - s) for s, e in iv])
        / np.mean(np.linalg.norm(accel.apply(accel.static_means), axis=1)) ** 2
    )
    ends = np.array([pose_dir_var[i] + pose_dir_var[i + 1] for i, _, _ in windows])
    floor = np.degrees(np.sqrt(2.0 * noise.mean() ** 2 * durations / rate + 2.0 * ends))
    spread = np.std((pose_means - bias) @ C.T, axis=0)

    solver_status = int(res.status)
    status = fit_status(solver_status)
    implausible = implausible_scale(C, nominal, units)
    if implausible and status != "failed":
        status = "failed"
        warn.append(implausible)
    poor = _poorly_determined(stderr, C)
    if status == "ok" and poor:
        status = "poorly_determined"
    if status == "ok" and rms(after) > 5.0:
        warn.append(
            f"the calibrated rotations still miss the poses by {rms(after):.2g} deg RMS: check "
            "that the accelerometer and gyro share one clock and one frame"
        )
    if rms(after) > 2.0 * rms(floor):
        drift = np.degrees(np.sqrt(2.0) * np.linalg.norm(spread) / np.sqrt(3.0))
        drift *= float(np.median(durations))
        notes.append(
            f"unexplained: the calibrated rotations miss by {rms(after):.2g} deg, "
            f"{rms(after) / rms(floor):.1f} x what the rest noise leaves. The rest bias still "
            f"moves between poses by {np.linalg.norm(spread) / np.sqrt(3.0):.2g} rad/s (std), "
            f"{drift:.2g} deg over the median turn of {np.median(durations):.2g} s"
        )
    notes.append(
        f"{k} motions between {len(iv)} static poses integrated; bias from "
        f"{log.n_rest} rest samples (Earth's rate, up to 7.3e-5 rad/s, stays in it)"
    )
    return GyroCalibration(
        matrix=C,
        bias=bias,
        stderr_matrix=stderr,
        stderr_bias=np.std(pose_means, axis=0) / np.sqrt(len(iv)),
        covariance=cov,
        condition=float(res.condition),
        status=status,
        input_units=units,
        solver=solver,
        solver_status=solver_status,
        solver_message=status_message(solver_status),
        iterations=int(res.iterations),
        nfev=int(res.nfev),
        n_poses=len(iv),
        n_motions=k,
        rms_raw_deg=rms_raw,
        rms_before_deg=rms(before),
        rms_after_deg=rms(after),
        noise_floor_deg=rms(floor),
        motion_errors_deg=after,
        rest_noise=noise,
        bias_spread=spread,
        **_allan_fields(g, iv, bias, C, rate),
        sample_rate=rate,
        g_sensitivity=G,
        scale_asymmetry=asym,
        effects=effects,
        poorly_determined=poor,
        warnings=warn,
        notes=notes,
        sensor_id=sensor_id,
        source=log.source,
    )


FERRARIS_FACES = ("x_p", "x_a", "y_p", "y_a", "z_p", "z_a")
FERRARIS_TURNS = ("x_rot", "y_rot", "z_rot")


def calibrate_gyro_ferraris(
    acc: np.ndarray,
    gyro: np.ndarray,
    sections: dict[str, tuple],
    sample_rate: float,
    *,
    angle_deg: float = -360.0,
    g: float = 9.81,
    sensor_id: str | None = None,
) -> GyroCalibration:
    """The gyroscope from a Ferraris session (imucal's protocol and equations, Ferraris et al.
    1995): six still faces and one full turn about each axis.

    ``sections`` maps imucal's section names (``x_p``, ``x_a``, ... ``z_a``, ``x_rot``,
    ``y_rot``, ``z_rot``; ``_p`` the axis up, ``_a`` down) to [start, stop) sample ranges, as
    imucal's section list does. The bias is the mean over the faces; the g-sensitivity G =
    (U_p - U_a) / 2g from the faces' means; the accelerometer's own Ferraris correction
    (faces' half-differences and means) removes G a during the turns; then the rates summed
    over each turn, W (columns x, y, z), must equal ``angle_deg`` about that axis, so
    C = angle W^-1. imucal's default angle is -360 (its protocol turns clockwise, seen from
    above). The turns are summed, not integrated as rotations (a full turn is the identity
    rotation, so only its unwrapped angle says anything): the turns must stay about one axis.
    Three turns determine C exactly: the standard errors come from the rest noise alone.
    """
    acc, gyro = np.asarray(acc, float), np.asarray(gyro, float)
    missing = [k for k in FERRARIS_FACES + FERRARIS_TURNS if k not in sections]
    if missing:
        raise ValueError(
            f"a Ferraris session needs the sections {', '.join(FERRARIS_FACES + FERRARIS_TURNS)}"
            f"; missing: {', '.join(missing)}"
        )
    part = {k: slice(*map(int, sections[k])) for k in FERRARIS_FACES + FERRARIS_TURNS}
    for k, sl in part.items():
        if sl.stop - sl.start < 2 or sl.start < 0 or sl.stop > len(gyro):
            raise ValueError(f"section {k} = [{sl.start}, {sl.stop}) is not inside the log")
    mean = {k: gyro[part[k]].mean(axis=0) for k in FERRARIS_FACES}
    amean = {k: acc[part[k]].mean(axis=0) for k in FERRARIS_FACES}
    faces = np.concatenate([gyro[part[k]] for k in FERRARIS_FACES])
    bias = faces.mean(axis=0)
    up = np.column_stack([mean[f"{a}_p"] for a in "xyz"])
    down = np.column_stack([mean[f"{a}_a"] for a in "xyz"])
    G = (up - down) / (2.0 * g)
    # the accelerometer's Ferraris correction: raw = A a + b_a with A's columns the faces'
    # half-differences per g
    A = (
        np.column_stack([amean[f"{a}_p"] for a in "xyz"])
        - np.column_stack([amean[f"{a}_a"] for a in "xyz"])
    ) / (2.0 * g)
    b_a = np.mean([amean[k] for k in FERRARIS_FACES], axis=0)
    W = np.zeros((3, 3))
    n_turn = np.zeros(3)
    for j, k in enumerate(FERRARIS_TURNS):
        a_cal = np.linalg.solve(A, (acc[part[k]] - b_a).T).T
        W[:, j] = np.sum(gyro[part[k]] - bias - a_cal @ G.T, axis=0) / sample_rate
        n_turn[j] = part[k].stop - part[k].start
    angle = np.deg2rad(angle_deg)
    C = angle * np.linalg.inv(W)
    # rest noise per axis, propagated through C = angle W^-1 (dC = -C dW W^-1)
    noise_raw = np.sqrt(np.mean([np.var(gyro[part[k]], axis=0) for k in FERRARIS_FACES], axis=0))
    s_w = noise_raw[:, None] * np.sqrt(n_turn)[None, :] / sample_rate  # sd of W[l, j]
    Winv = np.linalg.inv(W)
    se = np.sqrt(np.einsum("il,jk,lj->ik", C**2, Winv**2, s_w**2))
    face_means = np.array([mean[k] for k in FERRARIS_FACES])
    # the unit from C's scale, as calibrate_gyro's (it said 'counts' of imucal's deg/s file)
    units, _ = _resolve_units("auto", float(np.median(np.linalg.svd(C, compute_uv=False))))
    return GyroCalibration(
        matrix=C,
        bias=bias,
        stderr_matrix=se,
        stderr_bias=noise_raw / np.sqrt(len(faces)),
        covariance=np.diag(se.ravel() ** 2),
        condition=float(np.linalg.cond(W)),
        status="ok",
        input_units=units,
        solver="ferraris",
        solver_status=-1,
        solver_message="closed form (imucal's Ferraris equations): three turns, nine entries",
        iterations=0,
        nfev=0,
        n_poses=6,
        n_motions=3,
        rms_raw_deg=float("nan"),
        rms_before_deg=float("nan"),
        rms_after_deg=float("nan"),
        noise_floor_deg=float("nan"),
        motion_errors_deg=np.zeros(0),
        rest_noise=np.sqrt(np.diag(C @ np.diag(noise_raw**2) @ C.T)),
        bias_spread=np.std((face_means - bias) @ C.T, axis=0),
        sample_rate=float(sample_rate),
        g_sensitivity=G,
        method="ferraris",
        notes=[
            f"Ferraris turns of {angle_deg:g} deg each; exactly determined, so no residual: "
            "the standard errors are the rest noise propagated",
            "the covariance holds the variances only (the entries' correlations are not "
            "propagated)",
        ],
        sensor_id=sensor_id,
    )
