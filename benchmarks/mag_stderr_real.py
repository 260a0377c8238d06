"""The magnetometer's honest (block jackknife) standard errors against the formal ones on every
real log here (issue 15): how much the formal errors understate them, and the honest centre
error as a fraction of the field.

    .venv/bin/python benchmarks/mag_stderr_real.py

Reads the shipped logs and ../shared/data (those absent are skipped). Prints a table; the
numbers of 2026-11-28 are in the closing note of that session and docs/close_the_loop.md.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"


def logs():
    """(name, (N, 3) magnetometer samples) for every real magnetometer log found."""
    from calib_jax.datasets import mag_demo_log_path, qmc_log_path
    from calib_jax.io.files import load_log

    yield "ck_explorer", load_log(mag_demo_log_path()).mag
    for which in ("filtered", "noisy"):
        yield f"qmc_{which}", load_log(qmc_log_path(which)).mag
    xio = SHARED / "xio_fusion_sensor_data" / "sensor_data.csv"
    if xio.exists():
        yield "xio_hand_held", load_log(xio).mag
    for trial in ("02_undisturbed_slow_rotation_B", "05_undisturbed_slow_rotation_with_breaks_B",
                  "34_disturbed_attached_magnet_3cm"):  # fmt: skip
        path = SHARED / "broad_myon" / f"{trial}.hdf5"
        if path.exists():
            from calib_jax.io.broad import load_broad

            m = load_broad(path).mag
            yield f"broad{trial[:2]}", m[np.all(np.isfinite(m), axis=1)]
    for folder in ("hamagure_mag", "ximu3_mag", "skinematics"):
        for f in sorted((ROOT / "tests" / "data" / folder).glob("*")):
            if f.suffix in (".csv", ".txt"):
                try:
                    log = load_log(f, sensor="mag")
                except ValueError:
                    continue
                if log.mag is not None:
                    yield f"{folder}/{f.name}", log.mag


def main() -> None:
    import calib_jax as cj
    from calib_jax.runtime import configure

    configure()
    print(f"{'log':34s} {'n':>6s} {'model':6s} {'status':18s} {'centre honest/formal':>22s} "
          f"{'centre honest / field':>22s}")  # fmt: skip
    for name, m in logs():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                cal = cj.calibrate_mag(m)
            except ValueError as exc:
                print(f"{name:34s} refused: {str(exc)[:70]}")
                continue
        ratio = cal.stderr_center_honest / cal.stderr_center
        field = float(np.mean(cal.semi_axes))
        share = 100 * float(np.max(cal.stderr_center_honest)) / field
        print(f"{name:34s} {cal.n_samples:6d} {cal.model:6s} {cal.status:18s} "
              f"{np.min(ratio):10.1f} - {np.max(ratio):7.1f} {share:20.3f} %")  # fmt: skip


if __name__ == "__main__":
    main()
