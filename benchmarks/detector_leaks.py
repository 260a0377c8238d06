"""How far the static detector's candidates misfit, against the sweep's median, on real logs:
the evidence behind :data:`calib_jax.static.LEAK_RATIO`.

For each accelerometer log: the setting the sweep chose (window, factor, how), its misfit
(the dof-corrected radial rms of the ellipsoid through its interval means) over the median
misfit of every candidate, the lowest such ratio among the scorable candidates, and how many
candidates were marked as taking motion for poses. A log whose genuine poses are found has
its scorable candidates near 1x its median; sensbiotk's FOX six-face log (GPL-3, not shipped)
had only turn-counting candidates scorable, at 7-17x.

    .venv/bin/python benchmarks/detector_leaks.py [EXTRA_LOG ...]

Logs come from ../shared/data and tests/data (missing ones are skipped); extra paths (logs
kept outside the repository with their NOTES.md) are added by name. Writes
benchmarks/results/detector_leaks.json and prints the table.
"""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

import numpy as np

from calib_jax.io import load_log
from calib_jax.static import LEAK_RATIO, detect_static

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
LOGS = {
    "imutk_xsens": SHARED / "imutk_xsens/xsens_acc.mat",
    "imucal_ferraris": SHARED / "imucal_ferraris/example_ferraris_session.csv",
    "imucal_annotated": SHARED / "imucal_ferraris/annotated_session.csv",
    "ckexplorer_acc": SHARED / "ckexplorer_accmag/acc_log.csv",
    "ckexplorer_accmag": SHARED / "ckexplorer_accmag/acc_mag_log.csv",
    "xio_fusion": SHARED / "xio_fusion_sensor_data/sensor_data.csv",
    "mpu6050": ROOT / "tests/data/mpu6050/example_data_calibration.csv",
    "mpu9150_fusion": ROOT / "tests/data/mpu9150_fusion/mpudata",
    "skinematics_pololu": ROOT / "tests/data/skinematics/data_polulu.txt",
    "skinematics_xsens": ROOT / "tests/data/skinematics/data_xsens.txt",
    "skinematics_yei": ROOT / "tests/data/skinematics/data_yei.txt",
}


def row(name: str, path: Path) -> dict:
    log = load_log(path, sensor="accel")
    rep = detect_static(log.acc, sample_rate=log.sample_rate)
    rms = np.array([c.rms for c in rep.candidates], float)
    median = float(np.nanmedian(rms)) if np.isfinite(rms).any() else float("nan")
    scorable = [c.rms for c in rep.candidates if np.isfinite(c.score)]
    chosen = rep.candidates[rep.chosen] if rep.chosen is not None else None
    return {
        "log": name,
        "how": rep.how,
        "window": rep.window,
        "factor": rep.factor,
        "poses_chosen": chosen.n_poses if chosen else None,
        "chosen_over_median": chosen.rms / median if chosen else None,
        "lowest_scorable_over_median": min(scorable) / median if scorable else None,
        "n_scorable": len(scorable),
        "n_motion": rep.n_leaky,
        "n_candidates": len(rep.candidates),
    }


def main() -> None:
    logs = dict(LOGS)
    logs.update({Path(p).parent.name or Path(p).stem: Path(p) for p in sys.argv[1:]})
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, path in logs.items():
            if not path.exists():
                print(f"{name}: {path} not found, skipped")
                continue
            rows.append(row(name, path))
    fmt = "{:<28} {:<10} {:>6} {:>6} {:>5} {:>8} {:>8} {:>9} {:>6}"
    print(
        fmt.format(
            "log", "how", "window", "factor", "poses", "chosen", "lowest", "scorable", "motion"
        )
    )
    for r in rows:
        ratio = [
            "-" if r[k] is None or not np.isfinite(r[k]) else f"{r[k]:.2f}x"
            for k in ("chosen_over_median", "lowest_scorable_over_median")
        ]
        print(
            fmt.format(
                r["log"], r["how"], r["window"], f"{r['factor']:g}" if r["factor"] else "-",
                r["poses_chosen"] if r["poses_chosen"] is not None else "-", *ratio,
                f"{r['n_scorable']}/{r['n_candidates']}", r["n_motion"],
            )
        )  # fmt: skip
    out = ROOT / "benchmarks/results/detector_leaks.json"
    out.write_text(json.dumps({"leak_ratio": LEAK_RATIO, "rows": rows}, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
