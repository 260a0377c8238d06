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
