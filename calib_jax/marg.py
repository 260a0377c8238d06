"""Paper 2's MARG routine end to end, and its evaluation by the Gauss-Newton attitude.

:func:`calibrate_marg` runs the two routines of paper 2 on two recordings (a free tumble for
the ellipsoids, a turn about the board's z axis on a fixed plane for the sensor planes) and
adds the accel-mag rotation. :func:`evaluate_turn` reproduces the paper's evaluation (section 3,
Table 1 and Fig. 9): on a turn about z on an inclined plane, the attitude from raw,
compensated and aligned-compensated data, with the mean Gauss-Newton cost F(x) and the roll
and pitch deviation from the ideal 0 (relative to the starting pose).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import jax.numpy as jnp
import numpy as np

from .align import MagAccelAlignment, PlaneAlignment, align_mag_to_accel, plane_alignment
from .attitude import estimate_attitude
from .calibration import MagCalibration
from .mag import calibrate_mag


@dataclass(frozen=True)
class MARGCalibration:
    """Ellipsoid calibrations, plane alignments and the accel-mag rotation of one board."""

    mag: MagCalibration
    acc: MagCalibration | None
    """Paper 2 compensates every sensor with its ellipsoid; None leaves the accelerometer as
    given (e.g. already calibrated with paper 1's model)."""
    acc_plane: PlaneAlignment | None
    mag_plane: PlaneAlignment | None
    mag_to_acc: MagAccelAlignment | None
    warnings: list[str] = field(default_factory=list)

    def compensate(self, acc: np.ndarray, mag: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ellipsoid compensation only (paper 2 'compensated data'), unit radius."""
        a = np.asarray(acc, float) if self.acc is None else self.acc.apply(acc) / self.acc.radius
        return a, self.mag.apply(mag) / self.mag.radius

    def plane_aligned(self, acc: np.ndarray, mag: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Compensated, then each sensor multiplied by its alignment matrix (paper 2)."""
        a, m = self.compensate(acc, mag)
        if self.acc_plane is not None:
            a = a @ self.acc_plane.matrix.T
        if self.mag_plane is not None:
            m = m @ self.mag_plane.matrix.T
        return a, m

    def rotation_aligned(self, acc: np.ndarray, mag: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Compensated, magnetometer rotated into the accelerometer frame (beyond the paper)."""
        a, m = self.compensate(acc, mag)
        if self.mag_to_acc is not None:
            m = self.mag_to_acc.apply(m)
        return a, m

    def aligned(self, acc: np.ndarray, mag: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Both: the magnetometer rotated into the accelerometer frame (3 degrees of freedom
        from the dip constancy), then both sensors by the accelerometer's plane alignment
        (its tilt against the board). The most complete correction here."""
        a, m = self.rotation_aligned(acc, mag)
        if self.acc_plane is not None:
            a, m = a @ self.acc_plane.matrix.T, m @ self.acc_plane.matrix.T
        return a, m


def calibrate_marg(
    tumble_acc: np.ndarray,
    tumble_mag: np.ndarray,
    turn_acc: np.ndarray | None = None,
    turn_mag: np.ndarray | None = None,
    *,
    acc_ellipsoid: bool = True,
    mag_model: str = "auto",
    acc_model: str = "full",
) -> MARGCalibration:
    """Paper 2's calibration and compensation, sensor-plane alignment, and the accel-mag rotation.

    Parameters
    ----------
    tumble_acc, tumble_mag : (N, 3)
        A free rotation through all orientations (slow, so the accelerometer sees gravity).
    turn_acc, turn_mag : (K, 3), optional
        A turn about the board's z axis with its XY plane on a fixed plane; without it the
        plane alignment is skipped.
    acc_ellipsoid : bool
        Compensate the accelerometer with its own ellipsoid (paper 2); False when it is
        already calibrated.
    """
    warn: list[str] = []
    mag = calibrate_mag(tumble_mag, model=mag_model)
    acc = calibrate_mag(tumble_acc, model=acc_model, sensor="accel") if acc_ellipsoid else None
    partial = MARGCalibration(mag, acc, None, None, None)
    a_t, m_t = partial.compensate(tumble_acc, tumble_mag)
    rot = align_mag_to_accel(a_t, m_t)
    warn += rot.warnings
    acc_plane = mag_plane = None
    if turn_acc is not None and turn_mag is not None:
        a_p, m_p = partial.compensate(turn_acc, turn_mag)
        acc_plane, mag_plane = plane_alignment(a_p), plane_alignment(m_p)
        for name, pa in (("accelerometer", acc_plane), ("magnetometer", mag_plane)):
            if not pa.is_rotation:
                warn.append(f"{name} plane alignment: {pa.message}")
    return MARGCalibration(mag, acc, acc_plane, mag_plane, rot, warn)


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
