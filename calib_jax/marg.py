"""Paper 2's MARG routine end to end, and its evaluation by the Gauss-Newton attitude.

:func:`calibrate_marg_log` is the one-log version behind ``calib-jax marg``: accelerometer,
magnetometer ellipsoid and accel-mag rotation of one recording, as a :class:`MARGRecord` that
saves to and loads from versioned JSON (``kind: "marg"``).

:func:`calibrate_marg` runs the two routines of paper 2 on two recordings (a free tumble for
the ellipsoids, a turn about the board's z axis on a fixed plane for the sensor planes) and
adds the accel-mag rotation. :func:`evaluate_turn` reproduces the paper's evaluation (section 3,
Table 1 and Fig. 9): on a turn about z on an inclined plane, the attitude from raw,
compensated and aligned-compensated data, with the mean Gauss-Newton cost F(x) and the roll
and pitch deviation from the ideal 0 (relative to the starting pose).
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import jax.numpy as jnp
import numpy as np

from .align import (
    MagAccelAlignment,
    PlaneAlignment,
    align_mag_to_accel,
    dip_reading,
    plane_alignment,
)
from .attitude import estimate_attitude
from .calibration import (
    AccelCalibration,
    FitStatusWarning,
    MagCalibration,
    Record,
    _sanitize,
    _unsanitize,
)
from .gyro import GyroCalibration, calibrate_gyro
from .io.files import as_log
from .mag import calibrate_mag
from .models import layout
from .observations import TooFewPoses
from .status import is_usable, worst_status


def _check_accelerometer_unit(tumble_acc, acc) -> None:
    """A ValueError where the accelerometer's radius (its ellipsoid's, or the readings' median
    norm without one) is in no accelerometer unit (:data:`calib_jax.accel.UNIT_BANDS`): the
    two sensors passed the other way round were calibrated, 'ok', with the rotation inverted
    (a new user's trial; calibrate_accel refuses such readings)."""
    from .accel import _units_from_norm, no_accelerometer_unit

    x = np.asarray(tumble_acc, float)
    norm = float(np.nanmedian(np.linalg.norm(x, axis=1)))
    radius = None if acc is None else float(acc.radius)
    if _units_from_norm(norm if radius is None else radius) is None:
        raise ValueError(
            "tumble_acc: "
            + no_accelerometer_unit(norm, radius, False, radius is not None)
            + " (were tumble_acc and tumble_mag passed the other way round?)"
        )


def calibrate_marg(
    tumble_acc,
    tumble_mag: np.ndarray | None = None,
    turn_acc: np.ndarray | None = None,
    turn_mag: np.ndarray | None = None,
    *,
    acc_ellipsoid: bool = True,
    mag_model: str = "auto",
    acc_model: str = "full",
) -> MARGRecord:
    """Paper 2's calibration and compensation, sensor-plane alignment, and the accel-mag rotation.

    Returns the same :class:`MARGRecord` as ``calib-jax marg`` (``accel_method`` "ellipsoid",
    or "none" with ``acc_ellipsoid=False``), with the two plane alignments when a turn is given;
    it saves, loads and compares like every calibration record.

    Parameters
    ----------
    tumble_acc, tumble_mag : (N, 3)
        A free rotation through all orientations (slow, so the accelerometer sees gravity);
        or a loaded log or a log's path alone, holding both (as ``calibrate_accel`` and
        ``calibrate_mag`` take one; :func:`calibrate_marg_log` also finds its rests).
    turn_acc, turn_mag : (K, 3), optional
        A turn about the board's z axis with its XY plane on a fixed plane; without it the
        plane alignment is skipped.
    acc_ellipsoid : bool
        Compensate the accelerometer with its own ellipsoid (paper 2); False when it is
        already calibrated.
    """
    if tumble_mag is None:  # a log or its path (a trial passed the log it had loaded)
        log = as_log(tumble_acc, "mag")
        if isinstance(log, np.ndarray) or getattr(log, "acc", None) is None or log.mag is None:
            raise ValueError(
                "calibrate_marg takes the tumble's accelerometer and magnetometer (N, 3) "
                "arrays, or a log holding both (ax, ay, az, mx, my, mz)"
            )
        tumble_acc, tumble_mag = log.acc, log.mag
    warn: list[str] = []
    mag = calibrate_mag(tumble_mag, model=mag_model)
    acc = calibrate_mag(tumble_acc, model=acc_model, sensor="accel") if acc_ellipsoid else None
    _check_accelerometer_unit(tumble_acc, acc)
    a_t = np.asarray(tumble_acc, float) if acc is None else acc.apply(tumble_acc)
    rot = align_mag_to_accel(a_t, mag.apply(tumble_mag))
    warn += [f"alignment: {w}" for w in rot.warnings]
    record = _record(acc, "none" if acc is None else "ellipsoid", mag, rot, warn)
    if turn_acc is None or turn_mag is None:
        return record
    a_p, m_p = record.compensate(turn_acc, turn_mag)
    acc_plane, mag_plane = plane_alignment(a_p), plane_alignment(m_p)
    for name, pa in (("accelerometer", acc_plane), ("magnetometer", mag_plane)):
        if not pa.is_rotation:
            warn.append(f"{name} plane alignment: {pa.message}")
    return dataclasses.replace(record, acc_plane=acc_plane, mag_plane=mag_plane, warnings=warn)


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + 180.0) % 360.0 - 180.0


@dataclass(frozen=True)
class TurnEvaluation:
    """Paper 2 Table 1 and Fig. 9 for one version of the data."""

    label: str
    mean_cost: float
    """Mean Gauss-Newton cost F(x) (paper 2, Table 1)."""
    roll_rms_deg: float
    pitch_rms_deg: float
    """RMS roll / pitch relative to the start (ideally 0 on a turn about z)."""
    roll_max_deg: float
    pitch_max_deg: float
    yaw_span_deg: float
    """Total yaw turned (unwrapped), ideally the turn's angle."""
    euler_deg: np.ndarray
    cost: np.ndarray


def evaluate_turn(versions: dict[str, tuple[np.ndarray, np.ndarray]]) -> dict[str, TurnEvaluation]:
    """Attitude of each (acc, mag) version of a turn about the board's z axis (paper 2, 3).

    The reference vectors are the version's own first samples (``reference="first"``), so the
    ideal attitude is a pure yaw: roll = pitch = 0.
    """
    out = {}
    for label, (a, m) in versions.items():
        att = estimate_attitude(jnp.asarray(a), jnp.asarray(m), reference="first")
        eul = np.asarray(att.euler_deg)
        roll, pitch = _wrap(eul[:, 0]), _wrap(eul[:, 1])
        yaw = np.unwrap(np.radians(eul[:, 2]))
        out[label] = TurnEvaluation(
            label=label,
            mean_cost=float(np.mean(att.cost)),
            roll_rms_deg=float(np.sqrt(np.mean(roll**2))),
            pitch_rms_deg=float(np.sqrt(np.mean(pitch**2))),
            roll_max_deg=float(np.max(np.abs(roll))),
            pitch_max_deg=float(np.max(np.abs(pitch))),
            yaw_span_deg=float(np.degrees(np.ptp(yaw))),
            euler_deg=eul,
            cost=np.asarray(att.cost),
        )
    return out


def evaluation_table(ev: dict[str, TurnEvaluation]) -> str:
    """Markdown table of :func:`evaluate_turn`'s results."""
    lines = [
        "| data | mean F(x) | roll RMS (deg) | pitch RMS (deg) | roll max | pitch max | yaw span |",
        "|---|---|---|---|---|---|---|",
    ]
    for e in ev.values():
        lines.append(
            f"| {e.label} | {e.mean_cost:.3e} | {e.roll_rms_deg:.3f} | {e.pitch_rms_deg:.3f} | "
            f"{e.roll_max_deg:.2f} | {e.pitch_max_deg:.2f} | {e.yaw_span_deg:.0f} |"
        )
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# one log -> one record (calib-jax marg)

MARG_FORMAT_VERSION = 2
"""2 adds the plane alignments (``plane_alignment``); version 1 files still load."""
ACCEL_METHODS = ("auto", "static", "ellipsoid", "none")


@dataclass(frozen=True, eq=False)
class MARGRecord(Record):
    """One MARG calibration of one log: what ``calib-jax marg`` prints and writes.

    Frames: ``R_mag_to_acc`` takes magnetometer-frame vectors into the accelerometer frame,
    m_acc = R_mag_to_acc m_mag (the ``R_acc_from_mag`` of :class:`~calib_jax.align.
    MagAccelAlignment`); it includes the signed axis permutation ``permutation`` (text such as
    ``"x <- +y, y <- +x, z <- -z"``: the accelerometer's x is the magnetometer's +y) and the
    small rotation of ``rotation_deg`` degrees left after it. Angles in degrees.
    """

    kind: ClassVar[str] = "marg"
    what: ClassVar[str] = "a MARG calibration"

    accel: AccelCalibration | MagCalibration | None
    """Paper 1's model (``accel_method="static"``), the accelerometer's own ellipsoid
    (``"ellipsoid"``, paper 2), or None (``"none"``: the log's accelerometer used as given)."""
    accel_method: str
    mag: MagCalibration
    R_mag_to_acc: np.ndarray
    permutation: str
    permutation_matrix: np.ndarray
    rotation_deg: float
    dip_deg: float
    """Inclination of the field, positive when it points down (northern hemisphere)."""
    dip_stderr_deg: float
    dip_std_before_deg: float
    """Std of the gravity-field angle over the samples used, with R = I (after the ellipsoids)."""
    dip_std_after_deg: float
    """The same with the magnetometer rotated by ``R_mag_to_acc``."""
    n_used: int
    n_total: int
    alignment_status: str
    alignment_message: str
    status: str
    warnings: list[str] = field(default_factory=list)
    source: str | None = None
    date: str = ""
    acc_plane: PlaneAlignment | None = None
    """Paper 2's sensor-plane alignment of the accelerometer (from a turn log), or None."""
    mag_plane: PlaneAlignment | None = None
    dip_stderr_honest_deg: float = float("nan")
    """The dip's standard error from a block jackknife over the log (honest for a tumble's
    correlated samples; ``dip_stderr_deg`` is the fit's formal one, which assumes independent
    samples). NaN in records written before it existed."""
    gyro: GyroCalibration | None = None
    """The gyroscope, when the log has gyro columns and static poses with turns between them
    (:func:`calib_jax.calibrate_gyro`, in the accelerometer's frame); else None and a warning
    says why."""
    format_version: int = MARG_FORMAT_VERSION

    @property
    def success(self) -> bool:
        return is_usable(self.status)

    def _repr_html_(self) -> str:
        from .display import marg_html

        return marg_html(self)

    def __repr__(self) -> str:
        from .display import marg_repr

        return marg_repr(self)

    def to_params(self):
        """The board as a JAX pytree, :class:`calib_jax.pipeline.MargParams`, whose ``apply``
        gives what this record's calibration gives: both sensors calibrated, the magnetometer
        in the accelerometer's frame. The accelerometer's ellipsoid (``accel_method``
        "ellipsoid") is the nine-parameter model with alpha = W^-1, beta = c (W is
        symmetric); "none" is the identity. ``R_mag_to_acc`` becomes the rotation; an improper
        axis map (a mirror, det -1), which no rotation is, goes into the magnetometer's W
        instead and the rotation is the identity."""
        import jax.numpy as jnp
        from scipy.spatial.transform import Rotation as _R

        from .models.accel import AccelParams
        from .pipeline import MagParams, MargParams, Rotation

        if isinstance(self.accel, AccelCalibration):
            acc = self.accel.to_params()
        elif isinstance(self.accel, MagCalibration):
            alpha = np.linalg.inv(self.accel.soft_iron)
            alpha = 0.5 * (alpha + alpha.T)
            p = np.r_[alpha[layout.ALPHA_ENTRIES], self.accel.center]
            acc = AccelParams.from_vector(jnp.asarray(p))
        else:
            acc = AccelParams.identity()
        R = np.asarray(self.R_mag_to_acc, float)
        mag = self.mag.to_params()
        if np.linalg.det(R) > 0:
            return MargParams(acc, mag, Rotation(jnp.asarray(_R.from_matrix(R).as_rotvec())))
        folded = MagParams(mag.hard_iron, jnp.asarray(R @ np.asarray(mag.soft_iron)))
        return MargParams(acc, folded, Rotation.identity())

    # ---- applying it (paper 2's compensation and alignments) -------------------------------
    def compensate(self, acc: np.ndarray, mag: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each sensor calibrated and scaled to unit length (paper 2's 'compensated data'):
        the ellipsoids divided by their radius, paper 1's model by g, "none" as given."""
        if isinstance(self.accel, MagCalibration):
            a = self.accel.apply(acc) / self.accel.radius
        elif isinstance(self.accel, AccelCalibration):
            a = self.accel.apply(acc) / self.accel.g
        else:
            a = np.asarray(acc, float)
        return a, self.mag.apply(mag) / self.mag.radius

    def plane_aligned(self, acc: np.ndarray, mag: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Compensated, then each sensor multiplied by its plane alignment (paper 2); a sensor
        without one stays compensated."""
        a, m = self.compensate(acc, mag)
        if self.acc_plane is not None:
            a = a @ self.acc_plane.matrix.T
        if self.mag_plane is not None:
            m = m @ self.mag_plane.matrix.T
        return a, m

    def rotation_aligned(self, acc: np.ndarray, mag: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Compensated, the magnetometer rotated into the accelerometer frame (beyond the
        paper)."""
        a, m = self.compensate(acc, mag)
        return a, m @ np.asarray(self.R_mag_to_acc).T

    def aligned(self, acc: np.ndarray, mag: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Both: the magnetometer rotated into the accelerometer frame (3 degrees of freedom
        from the dip constancy), then both sensors by the accelerometer's plane alignment
        (its tilt against the board). The most complete correction here."""
        a, m = self.rotation_aligned(acc, mag)
        if self.acc_plane is not None:
            a, m = a @ self.acc_plane.matrix.T, m @ self.acc_plane.matrix.T
        return a, m

    def alignment_text(self) -> str:
        """One line on the accel-mag rotation (the demo's wording)."""
        return (
            f"accel-mag alignment on {self.n_used} of {self.n_total} samples (|a|, |m| within "
            f"5 % of their medians): axes {self.permutation}; rotation {self.rotation_deg:.2f} "
            f"deg; dip {self.dip_deg:.2f} +- {self.dip_stderr_honest_deg:.2f} deg (block "
            f"jackknife; formal +- {self.dip_stderr_deg:.2f}){dip_reading(self.dip_deg)}; "
            "spread of the "
            f"gravity-field angle {self.dip_std_before_deg:.2f} -> {self.dip_std_after_deg:.2f} "
            f"deg; {self.alignment_message}"
        )

    def report(self) -> str:
        how = {
            "static": "paper 1's nine-parameter model on the static poses",
            "ellipsoid": "its own ellipsoid (paper 2)",
            "none": "none (used as given)",
        }[self.accel_method]
        out = [f"accelerometer calibration: {how}"]
        if self.accel is not None:
            out.append(self.accel.report())
        out += ["", "magnetometer:", self.mag.report(), "", self.alignment_text()]
        if self.gyro is not None:
            out += ["", "gyroscope:", self.gyro.report()]
        out.append(f"status: {self.status}")
        out += [f"warning: {w}" for w in self.warnings]
        return "\n".join(out)

    # ---- JSON ------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        return _sanitize(
            {
                "format_version": self.format_version,
                "kind": self.kind,
                "date": self.date,
                "source": self.source,
                "status": self.status,
                "R_mag_to_acc": np.asarray(self.R_mag_to_acc).tolist(),
                "permutation": self.permutation,
                "permutation_matrix": np.asarray(self.permutation_matrix).tolist(),
                "rotation_deg": self.rotation_deg,
                "dip_deg": self.dip_deg,
                "dip_stderr_deg": self.dip_stderr_deg,
                "dip_stderr_honest_deg": self.dip_stderr_honest_deg,
                "dip_std_before_deg": self.dip_std_before_deg,
                "dip_std_after_deg": self.dip_std_after_deg,
                "n_used": self.n_used,
                "n_total": self.n_total,
                "alignment_status": self.alignment_status,
                "alignment_message": self.alignment_message,
                "accel_method": self.accel_method,
                "accel": None if self.accel is None else self.accel.to_dict(),
                "mag": self.mag.to_dict(),
                "plane_alignment": {
                    name: None if pa is None else pa.to_dict()
                    for name, pa in (("accel", self.acc_plane), ("mag", self.mag_plane))
                },
                "gyro": None if self.gyro is None else self.gyro.to_dict(),
                "warnings": list(self.warnings),
            }
        )

    @classmethod
    def from_dict(cls, d: dict, source: str | Path | None = None) -> MARGRecord:
        where = f"{source}: " if source else ""
        if not isinstance(d, dict):
            raise ValueError(f"{where}a MARG file holds a JSON object, got {type(d).__name__}")
        cls._check_kind(d, where, legacy=False)
        if d.get("format_version") not in (1, MARG_FORMAT_VERSION):  # 1: no plane alignment
            raise ValueError(
                f"{where}MARG format_version {d.get('format_version')!r} is not supported (this "
                f"calib_jax reads versions 1 to {MARG_FORMAT_VERSION})"
            )
        planes = {
            k: None if v is None else PlaneAlignment.from_dict(_unsanitize(v))
            for k, v in d.get("plane_alignment", {"accel": None, "mag": None}).items()
        }
        a = d.get("accel")
        if a is None:
            accel = None
        elif a.get("kind") == "ellipsoid":
            accel = MagCalibration.from_dict(a)
        else:
            accel = AccelCalibration.from_dict(a)
        return cls(
            accel=accel,
            accel_method=d["accel_method"],
            mag=MagCalibration.from_dict(d["mag"]),
            R_mag_to_acc=np.array(d["R_mag_to_acc"], float),
            permutation=d["permutation"],
            permutation_matrix=np.array(d["permutation_matrix"], float),
            rotation_deg=float(d["rotation_deg"]),
            dip_deg=float(d["dip_deg"]),
            dip_stderr_deg=float(d["dip_stderr_deg"]),
            dip_stderr_honest_deg=float(_unsanitize(d.get("dip_stderr_honest_deg", "nan"))),
            dip_std_before_deg=float(d["dip_std_before_deg"]),
            dip_std_after_deg=float(d["dip_std_after_deg"]),
            n_used=int(d["n_used"]),
            n_total=int(d["n_total"]),
            alignment_status=d["alignment_status"],
            alignment_message=d["alignment_message"],
            status=d["status"],
            warnings=list(d.get("warnings", [])),
            source=d.get("source"),
            date=d.get("date", ""),
            acc_plane=planes["accel"],
            mag_plane=planes["mag"],
            gyro=None if d.get("gyro") is None else GyroCalibration.from_dict(d["gyro"], source),
        )


def _own_flags(cal, which: str):
    """The ellipsoid fit's record with its advice in this command's words: ``calib-jax marg``
    sets each sensor's model with --acc-model / --mag-model (acc_model= / mag_model= in
    Python), not --model (a trial ran 'calib-jax marg --model sphere', 'unrecognized
    arguments')."""
    import re

    def own(w: str) -> str:
        return re.sub(r"--model\b", f"--{which}-model", re.sub(r"\bmodel=", f"{which}_model=", w))

    return dataclasses.replace(cal, warnings=[own(w) for w in cal.warnings])


def calibrate_marg_log(
    log,
    *,
    accel: str = "auto",
    mag_model: str = "auto",
    acc_model: str = "full",
    field: float | None = None,
    g: float | None = None,
    solver: str = "lm1",
    sensor_id: str | None = None,
    **static_options,
) -> MARGRecord:
    """Accelerometer, magnetometer ellipsoid and accel-mag rotation of one log (paper 2).

    Parameters
    ----------
    log : SensorLog
        A log with accelerometer and magnetometer columns, recorded through many orientations.
    accel : {"auto", "static", "ellipsoid", "none"}
        How to calibrate the accelerometer. "static": paper 1's nine-parameter model on the
        static poses (needs rests in at least nine orientations). "ellipsoid": paper 2's way,
        the accelerometer's own ellipsoid fitted to every sample (a tumble has no rests; motion
        adds to the spread of |a| but not to the centre). "none": the log's accelerometer is
        already calibrated. "auto" (default): "static" when the log has enough static poses,
        otherwise "ellipsoid", and "none" when that fit fails too (each step with a warning
        saying why).
    mag_model, acc_model : str
        Ellipsoid models, see :func:`calib_jax.calibrate_mag`.
    field, g : float, optional
        Known field magnitude, and the accelerometer's reference magnitude (static only).
    static_options
        Static detection for ``accel="static"``/``"auto"`` (window, threshold_factor,
        min_duration, min_samples, ...), passed to :func:`calib_jax.calibrate_accel`.

    Raises
    ------
    ValueError
        The log lacks accelerometer or magnetometer columns, ``accel`` is unknown, or the data
        cannot give a calibration or a rotation (with what to change).
    """
    from .accel import REST_RMS_LIMIT, calibrate_accel

    if accel not in ACCEL_METHODS:
        raise ValueError(f"accel must be one of {ACCEL_METHODS}, got {accel!r}")
    log = as_log(log)
    if log.acc is None or log.mag is None:
        read = [k for k in ("t", "ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz")
                if k in (log.columns or {})]  # fmt: skip
        what = (
            f"it has {', '.join(f'{k} ({log.columns[k]})' for k in read)}"
            if read
            else "none were read"
        )
        raise ValueError(
            f"{log.path}: a MARG calibration needs accelerometer and magnetometer columns "
            f"(ax, ay, az, mx, my, mz) of one recording; {what}. Map the columns with "
            "--columns if the file holds both sensors; one sensor's file calibrates with "
            "calib-jax accel or calib-jax mag"
        )
    warn: list[str] = []
    acal: AccelCalibration | MagCalibration | None = None
    method = accel
    if accel in ("auto", "static"):
        try:
            with warnings.catch_warnings():  # auto says below why it leaves a failed fit
                if accel == "auto":
                    warnings.simplefilter("ignore", FitStatusWarning)
                acal = calibrate_accel(
                    log, g=g, solver=solver, sensor_id=sensor_id, **static_options
                )
            method = "static"
            if accel == "auto" and not acal.rms_after < REST_RMS_LIMIT:
                # the detector finds short quiet moments in a tumble too
                raise ValueError(
                    f"the {acal.n_intervals} quiet stretches it found leave {acal.rms_after:.2g} "
                    f"of g after the fit (over {REST_RMS_LIMIT:g}): they are not rests"
                )
            if accel == "auto" and acal.status != "ok":
                # a tumble's quiet moments rarely hold the poses nine parameters need; the
                # ellipsoid of every sample usually does (sunsided's MPU6050 hand tumble: gain
                # x 0.94 +- 0.027 from 58 quiet stretches, 1.00 from the ellipsoid)
                raise ValueError(
                    f"its fit on {acal.n_intervals} quiet stretches is '{acal.status}'"
                    + (f": {', '.join(acal.poorly_determined)}" if acal.poorly_determined else "")
                )
        except ValueError as exc:
            if accel == "static":
                raise
            why = exc.finding if isinstance(exc, TooFewPoses) else str(exc)  # no accel flags here
            warn.append(
                f"accelerometer: paper 1's static calibration is not possible ({why}); its "
                "ellipsoid is fitted instead"
            )
            method = "ellipsoid"
    if method == "ellipsoid":
        with warnings.catch_warnings():  # a failed fit says why in its status and warnings
            warnings.simplefilter("ignore", FitStatusWarning)
            try:
                acal = _own_flags(
                    calibrate_mag(
                        log, model=acc_model, sensor="accel", solver=solver, sensor_id=sensor_id
                    ),
                    "acc",
                )
                why = "; ".join(acal.warnings) or acal.solver_message
            except ValueError as exc:  # gravity in one plane or direction: no ellipsoid
                if accel != "auto":
                    raise
                acal, why = None, str(exc)
        if accel == "auto" and (acal is None or not acal.success):
            # a failed ellipsoid (too little of the sphere covered) would spoil the rotation
            warn.append(
                f"accelerometer: its ellipsoid fit is '{acal.status if acal else 'failed'}' "
                f"({why}); the accelerometer is used as given"
            )
            acal, method = None, "none"
    with warnings.catch_warnings():  # its status and warnings are in the record's mag block
        warnings.simplefilter("ignore", FitStatusWarning)
        mcal = calibrate_mag(log, model=mag_model, field=field, solver=solver, sensor_id=sensor_id)
    mcal = _own_flags(mcal, "mag")
    acc = np.asarray(log.acc, float) if acal is None else acal.apply(log.acc)
    try:
        al = align_mag_to_accel(acc, mcal.apply(log.mag))
    except ValueError as exc:
        if mcal.success:
            raise
        why = "; ".join(mcal.warnings) or mcal.solver_message
        raise ValueError(  # the failed magnetometer first: the alignment's trouble follows
            f"the magnetometer's ellipsoid fit is '{mcal.status}': {why}; the alignment with "
            f"the accelerometer then fails too: {exc}"
        ) from exc
    if acal is not None:
        acal, method, al = _check_against_raw(acal, method, al, accel, log, mcal, warn)
    warn += [f"alignment: {w}" for w in al.warnings]
    gyro = _gyro_block(log, acal, method, warn)
    rec = _record(acal, method, mcal, al, warn, source=log.path)
    if gyro is None:
        return rec
    return dataclasses.replace(rec, gyro=gyro, status=worst_status(rec.status, gyro.status))


SPREAD_WORSE = 1.2
"""An accelerometer calibration that leaves the gravity-field angle spread more than this
factor wider than the readings as given does not describe the log (:func:`_check_against_raw`).
"""


def _check_against_raw(acal, method, al, accel, log, mcal, warn):
    """(acal, method, al) after the independent check of the accelerometer's calibration: the
    gravity-field angle, which is constant, must spread no wider with it than with the
    readings as given (after each one's own rotation fit). Wider by :data:`SPREAD_WORSE`: a
    warning, and with ``accel="auto"`` the readings are used as given (sunsided's roll-and-tilt
    log, whose quiet stretches are turns: 7.3 deg calibrated, 2.2 as given)."""
    try:
        raw = align_mag_to_accel(np.asarray(log.acc, float), mcal.apply(log.mag))
    except ValueError:
        return acal, method, al
    if not al.spread_after_deg > SPREAD_WORSE * raw.spread_after_deg:
        return acal, method, al
    text = (
        f"accelerometer: its {method} calibration leaves the gravity-field angle spread "
        f"{al.spread_after_deg:.3g} deg, against {raw.spread_after_deg:.3g} deg with its "
        "readings as given: it does not describe this log"
    )
    if accel != "auto":
        warn.append(f"{text} (--accel none uses the readings as given)")
        return acal, method, al
    warn.append(f"{text}; the accelerometer is used as given")
    return None, "none", raw


def _gyro_block(log, acal, method: str, warn: list[str]) -> GyroCalibration | None:
    """The gyroscope of a MARG log, or None with a warning saying why (appended to warn)."""
    if log.gyro is None:
        return None
    if method != "static":
        warn.append(
            "gyroscope: not calibrated: the gyro fit integrates the turns between static poses "
            "and this log has too few of them; record a pose log with turns between the poses "
            "(calib-jax gyro)"
        )
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FitStatusWarning)
            return calibrate_gyro(log, accel=acal)
    except ValueError as exc:
        warn.append(f"gyroscope: not calibrated: {exc}")
        return None


def _record(
    acal: AccelCalibration | MagCalibration | None,
    method: str,
    mcal: MagCalibration,
    al: MagAccelAlignment,
    warn: list[str],
    source: str | None = None,
) -> MARGRecord:
    """The MARG record of a board's fits and its accel-mag rotation (every path builds it so)."""
    statuses = [mcal.status, al.status] + ([] if acal is None else [acal.status])
    return MARGRecord(
        accel=acal,
        accel_method=method,
        mag=mcal,
        R_mag_to_acc=np.asarray(al.R_acc_from_mag, float),
        permutation=al.permutation_text,
        permutation_matrix=np.asarray(al.permutation, float),
        rotation_deg=float(al.rotation_deg),
        dip_deg=float(al.dip_deg),
        dip_stderr_deg=float(al.dip_stderr_deg),
        dip_stderr_honest_deg=float(al.dip_stderr_honest_deg),
        dip_std_before_deg=float(al.spread_before_deg),
        dip_std_after_deg=float(al.spread_after_deg),
        n_used=int(al.n_used),
        n_total=int(al.n_total),
        alignment_status=al.status,
        alignment_message=al.message,
        status=worst_status(*statuses),
        warnings=warn,
        source=source,
        date=_dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
    )
