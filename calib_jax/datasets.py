"""Real logs shipped inside the package (each with its NOTES.md for source and licence)."""

from __future__ import annotations

from importlib import resources
from pathlib import Path


def demo_log_path() -> Path:
    """The imu_tk Xsens accelerometer log (raw 16-bit counts, 100 Hz, 38 static poses).

    Tedaldi, Pretto, Menegatti, ICRA 2014; BSD. See ``data/imutk_xsens/NOTES.md``. Headerless
    text with columns t, ax, ay, az; imu_tk calibrates it with g = 9.81744 m/s^2.
    """
    return Path(str(resources.files("calib_jax") / "data" / "imutk_xsens" / "xsens_acc.mat"))


def gyro_demo_log_path() -> Path:
    """The gyro log recorded with :func:`demo_log_path`'s accelerometer (same rows and times;
    raw counts, columns t, gx, gy, gz). ``calib-jax gyro`` takes the two files together."""
    return Path(str(resources.files("calib_jax") / "data" / "imutk_xsens" / "xsens_gyro.mat"))


def mag_demo_log_path() -> Path:
    """CK-Explorer accelerometer + magnetometer tumble (12,000 samples, acc in g and already
    calibrated, magnetometer raw with a large hard iron; Apache-2.0). See
    ``data/ckexplorer_accmag/NOTES.md``. Columns ax, ay, az, mx, my, mz."""
    return Path(
        str(resources.files("calib_jax") / "data" / "ckexplorer_accmag" / "acc_mag_log.csv")
    )


BROAD_EXCERPTS = {
    "02": "02_undisturbed_slow_rotation_B_every10.csv",
    "05": "05_undisturbed_slow_rotation_with_breaks_B_every10.csv",
}
BROAD_EXCERPT_RATE = 285.714 / 10
"""Sample rate of the excerpts (Hz): every 10th sample of BROAD's 285.714 Hz."""


def broad_excerpt_path(trial: str = "02") -> Path:
    """Every 10th sample of BROAD trial 02 (slow rotation) or 05 (slow rotation with breaks)
    (CC-BY-4.0, Laidig et al. 2021), CSV with t, acc (m/s^2), mag (uT), optical quaternion
    qw..qz (sensor -> ENU) and movement. See ``data/broad_excerpt/NOTES.md``."""
    if trial not in BROAD_EXCERPTS:
        raise ValueError(f"trial must be one of {sorted(BROAD_EXCERPTS)}, got {trial!r}")
    return Path(
        str(resources.files("calib_jax") / "data" / "broad_excerpt" / BROAD_EXCERPTS[trial])
    )


def load_broad_excerpt(trial: str = "02") -> dict:
    """A BROAD excerpt as arrays: t, acc, mag, quat (NaN rows kept), movement (bool)."""
    import numpy as np

    d = np.genfromtxt(broad_excerpt_path(trial), delimiter=",", names=True)
    return {
        "t": d["t"],
        "acc": np.column_stack([d["ax"], d["ay"], d["az"]]),
        "mag": np.column_stack([d["mx"], d["my"], d["mz"]]),
        "quat": np.column_stack([d["qw"], d["qx"], d["qy"], d["qz"]]),
        "movement": d["movement"].astype(bool),
    }


def accel_tumble_log_path() -> Path:
    """CK-Explorer accelerometer-only log (16,000 samples in g: 160 poses of exactly 100
    samples; Apache-2.0). See ``data/ckexplorer_accmag/NOTES.md``. Columns ax, ay, az."""
    return Path(str(resources.files("calib_jax") / "data" / "ckexplorer_accmag" / "acc_log.csv"))


def qmc_log_path(which: str = "filtered") -> Path:
    """QMC5883L free-rotation magnetometer logs in raw counts, 50 Hz, the first 60 s static
    (MIT, Tomas Suarez 2025): ``which`` is "filtered" or "noisy". See
    ``data/tomisuarez_qmc5883l_mag/NOTES.md``."""
    if which not in ("filtered", "noisy"):
        raise ValueError(f"which must be 'filtered' or 'noisy', got {which!r}")
    return Path(
        str(
            resources.files("calib_jax")
            / "data"
            / "tomisuarez_qmc5883l_mag"
            / f"{which}_raw_data.csv"
        )
    )
