"""Loader for the BROAD benchmark trials (Laidig et al. 2021, CC-BY-4.0), HDF5 via h5py.

A trial has the IMU's accelerometer (m/s^2), gyroscope (rad/s) and magnetometer (uT) at
285.714 Hz, and the optical ground truth ``opt_quat`` ([w, x, y, z], sensor -> ENU, NaN where
tracking was lost). See ``shared/data/broad_myon/NOTES.md``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class BroadTrial:
    acc: np.ndarray
    gyro: np.ndarray
    mag: np.ndarray
    quat: np.ndarray
    """Ground truth, [w, x, y, z], sensor -> ENU; NaN rows where tracking was lost."""
    movement: np.ndarray
    sample_rate: float
    name: str

    @property
    def t(self) -> np.ndarray:
        return np.arange(len(self.acc)) / self.sample_rate

    def segment(self, start_s: float, stop_s: float) -> BroadTrial:
        """The samples between two times in seconds."""
        sl = slice(int(start_s * self.sample_rate), int(stop_s * self.sample_rate))
        return BroadTrial(
            self.acc[sl],
            self.gyro[sl],
            self.mag[sl],
            self.quat[sl],
            self.movement[sl],
            self.sample_rate,
            f"{self.name}[{start_s:g}-{stop_s:g} s]",
        )


def load_broad(path: str | Path) -> BroadTrial:
    """Read one BROAD ``.hdf5`` trial (needs h5py: ``pip install h5py``)."""
    try:
        import h5py
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            "reading BROAD HDF5 trials needs h5py: pip install h5py (or pip install "
            "'calib_jax[hdf5]')"
        ) from exc
    path = Path(path)
    if not path.exists():
        raise ValueError(f"{path} does not exist")
    with h5py.File(path, "r") as f:
        missing = [k for k in ("imu_acc", "imu_gyr", "imu_mag", "opt_quat") if k not in f]
        if missing:
            raise ValueError(f"{path} is not a BROAD trial: datasets {missing} are missing")
        rate = float(f.attrs.get("sampling_rate", 285.714))
        mov = np.asarray(f["movement"], bool) if "movement" in f else np.ones(len(f["imu_acc"]))
        return BroadTrial(
            acc=np.asarray(f["imu_acc"], float),
            gyro=np.asarray(f["imu_gyr"], float),
            mag=np.asarray(f["imu_mag"], float),
            quat=np.asarray(f["opt_quat"], float),
            movement=mov.astype(bool),
            sample_rate=rate,
            name=path.stem,
        )
