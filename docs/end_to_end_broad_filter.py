"""All three sensors through the gyro-aided filter against BROAD's optical truth (issue 16):
writes docs/end_to_end/filter.md and filter.json.

Fits on one undisturbed trial and judges on the other, both ways, at the full rate (the
filter integrates every sample). Rows: BROAD's own calibration as read; calib_jax's two-stage
start (:func:`calib_jax.endtoend.filter_start`); then :func:`calib_jax.endtoend.end_to_end_filter`
with the blocks named. The fitted delay and reference offset are applied to the reference of
both trials (one rig). Needs ../shared/data/broad_myon. Run:
``.venv/bin/python docs/end_to_end_broad_filter.py`` (about 5 minutes on 2 cores).
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from calib_jax import endtoend as ee  # noqa: E402
from calib_jax.io.broad import load_broad  # noqa: E402
from calib_jax.pipeline import GyroParams, MagParams, MargParams  # noqa: E402

HERE = Path(__file__).resolve().parent
SHARED = HERE.parents[1] / "shared" / "data" / "broad_myon"
TRIALS = {
    "02": "02_undisturbed_slow_rotation_B.hdf5",
    "05": "05_undisturbed_slow_rotation_with_breaks_B.hdf5",
}
FITS = {  # row name: the blocks fitted (calib_jax.endtoend.FILTER_BLOCKS)
    name: tuple(name.split("+"))
    for name in (
        "delay",
        "delay+gyro_delay",
        "gyro",
        "gyro+delay",
        "gyro+delay+offset",
        "mag+gyro+delay",
        "accel+mag+gyro+delay",
    )
}


def load(trial: str) -> tuple[dict, float]:
    t = load_broad(SHARED / TRIALS[trial])
    d = {"acc": t.acc, "gyro": t.gyro, "mag": t.mag, "quat": t.quat, "movement": t.movement}
    return d, t.sample_rate


def as_read(d: dict) -> ee.MargGyroParams:
    """BROAD's factory calibration: the field scaled to unit length, no gyro bias."""
    scale = 1.0 / float(np.median(np.linalg.norm(d["mag"], axis=1)))
    zero = jnp.zeros((3, 3))
    marg = MargParams.identity()
    marg = MargParams(marg.acc, MagParams(jnp.zeros(3), scale * jnp.eye(3)), marg.mag_to_acc)
    return ee.MargGyroParams(marg, GyroParams(jnp.eye(3), jnp.zeros(3), zero, zero[0]))


def main() -> None:
    out = {"runs": {}, "load": os.getloadavg()[0]}
    lines = [
        "| fit -> held out | method | delay / gyro delay (ms) | gyro bias (deg/s) | gyro scales | "
        "fit trial: heading / incl. RMS (deg) | held out |",
        "|" + "---|" * 7,
    ]
    data = {k: load(k) for k in TRIALS}
    for fit, test in (("05", "02"), ("02", "05")):
        (df, rate), (dtest, _) = data[fit], data[test]
        dt = 1.0 / rate
        g = float(np.median(np.linalg.norm(df["acc"], axis=1)))
        start = ee.filter_start(df["acc"], df["gyro"], df["mag"], rate)
        rows = {
            "as_read": (as_read(df), g, None, 0.0, 0.0, None),
            "two_stage": (start, g, None, 0.0, 0.0, None),
        }
        for name, blocks in FITS.items():
            t0 = time.time()
            r = ee.end_to_end_filter(
                df["gyro"], df["acc"], df["mag"], df["quat"], dt, start, fit=blocks
            )
            seconds = time.time() - t0
            rows[name] = (r.params, r.g, r.offset, r.delay_s, r.gyro_delay_s, (r.result, seconds))
        run = {}
        for name, (p, gg, off, delay, gdelay, res) in rows.items():
            row = {
                split: ee.evaluate_filter(p, gg, d, dt, d["movement"], off, delay, gdelay)
                for split, d in (("fit", df), ("test", dtest))
            }
            row["delay_ms"] = 1e3 * delay
            row["gyro_delay_ms"] = 1e3 * gdelay
            row["gyro_bias_deg_s"] = np.degrees(np.asarray(p.gyro.bias)).tolist()
            row["gyro_matrix"] = np.asarray(p.gyro.matrix).tolist()
            row["offset"] = None if off is None else np.asarray(off).tolist()
            if res is not None:
                row |= {"status": int(res[0].status), "iterations": int(res[0].iterations)}
                row["seconds"] = res[1]
            run[name] = row
            cells = [
                f"{fit} -> {test}",
                name,
                f"{row['delay_ms']:.1f} / {row['gyro_delay_ms']:.1f}",
                ", ".join(f"{v:+.3f}" for v in row["gyro_bias_deg_s"]),
                ", ".join(f"{v:.4f}" for v in np.diag(np.asarray(p.gyro.matrix))),
            ]
            cells += [
                f"{row[s]['heading_rms']:.2f} / {row[s]['inclination_rms']:.2f}"
                for s in ("fit", "test")
            ]
            lines.append("| " + " | ".join(cells) + " |")
            print(lines[-1], flush=True)
        out["runs"][f"{fit}->{test}"] = run
    (HERE / "end_to_end").mkdir(exist_ok=True)
    (HERE / "end_to_end" / "filter.json").write_text(json.dumps(out, indent=1))
    head = (
        "# All three sensors through the filter against BROAD's optical truth\n\n"
        "Made by `docs/end_to_end_broad_filter.py` (full rate, 285.7 Hz). RMS heading / "
        "inclination error of the gyro-aided filter (`calib_jax.filter`, default gains without "
        "the integral term) on BROAD's movement samples, against the optical reference "
        "corrected by the fitted delay and offset (both trials: one rig).\n\n"
    )
    (HERE / "end_to_end" / "filter.md").write_text(head + "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
