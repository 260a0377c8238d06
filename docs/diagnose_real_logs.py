"""Run the close-the-loop diagnosis on every real log in ../shared/data and record what it finds.

    .venv/bin/python docs/diagnose_real_logs.py [--figures xsens ck_accel ...]

Writes docs/diagnosis/<log>/diagnosis.json for every log, the report figures for the logs
named in --figures (default: a few, to keep the repository small), and docs/diagnosis/README.md
with one table row per log. Logs missing from ../shared/data are skipped with a message.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

from calib_jax.datasets import (  # noqa: E402
    accel_tumble_log_path,
    demo_log_path,
    mag_demo_log_path,
    qmc_log_path,
)
from calib_jax.diagnose import diagnose_accel, diagnose_mag, diagnose_marg  # noqa: E402
from calib_jax.diagnose.report import write_report  # noqa: E402
from calib_jax.io.files import load_log  # noqa: E402

ROOT = Path(__file__).resolve().parent
SHARED = ROOT.parent.parent / "shared" / "data"
OUT = ROOT / "diagnosis"


def logs():
    """(name, description, thunk) for every real log."""
    yield (
        "xsens",
        "imu_tk Xsens accel, 38 poses",
        lambda: diagnose_accel(load_log(demo_log_path(), columns="t,ax,ay,az")),
    )
    yield (
        "ck_accel",
        "CK-Explorer accel, 160 x 100-sample poses",
        lambda: diagnose_accel(load_log(accel_tumble_log_path()), block=100),
    )
    ck = load_log(mag_demo_log_path())
    yield "ck_mag", "CK-Explorer magnetometer tumble", lambda: diagnose_mag(ck)
    yield "ck_marg", "CK-Explorer accel + mag tumble", lambda: diagnose_marg(ck.acc, ck.mag)
    for which in ("filtered", "noisy"):
        yield (
            f"qmc_{which}",
            f"QMC5883L {which}, 455 s",
            lambda w=which: diagnose_mag(load_log(qmc_log_path(w))),
        )
    imucal = SHARED / "imucal_ferraris" / "annotated_session.csv"
    if imucal.exists():
        yield (
            "imucal",
            "imucal Ferraris session (6 faces + rotations)",
            lambda: diagnose_accel(
                load_log(imucal, columns={"ax": "acc_x", "ay": "acc_y", "az": "acc_z"}),
                sample_rate=102.4,
            ),
        )
    xio = SHARED / "xio_fusion_sensor_data" / "sensor_data.csv"
    if xio.exists():
        log = load_log(xio)
        yield "xio_accel", "x-io hand-held, never upside down", lambda: diagnose_accel(log)
        yield (
            "xio_marg",
            "x-io hand-held accel + mag",
            lambda: diagnose_marg(log.acc, log.mag, t=log.t),
        )
    from calib_jax.io.broad import load_broad

    for trial in (
        "02_undisturbed_slow_rotation_B",
        "05_undisturbed_slow_rotation_with_breaks_B",
        "34_disturbed_attached_magnet_3cm",
    ):
        path = SHARED / "broad_myon" / f"{trial}.hdf5"
        if not path.exists():
            continue
        short = "broad" + trial[:2]
        tr = load_broad(path)
        ok = np.all(np.isfinite(tr.mag), axis=1) & np.all(np.isfinite(tr.acc), axis=1)
        yield (
            f"{short}_mag",
            f"BROAD trial {trial}, magnetometer",
            lambda tr=tr: diagnose_mag(tr.mag, t=tr.t, sample_rate=tr.sample_rate),
        )
        yield (
            f"{short}_marg",
            f"BROAD trial {trial}, accel + mag",
            lambda tr=tr, ok=ok: diagnose_marg(
                tr.acc[ok], tr.mag[ok], t=tr.t[ok], sample_rate=tr.sample_rate
            ),
        )


def fmt(d, v):
    if v is None or not np.isfinite(v):
        return "-"
    if d.sensor == "accel":
        return f"{1e3 * v:.3f} mg"
    if d.sensor == "mag":
        return f"{1e2 * v:.2f} %"
    return f"{math.degrees(v):.2f} deg"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument(
        "--figures", nargs="*", default=["xsens", "ck_accel", "qmc_filtered", "ck_marg"]
    )
    args = ap.parse_args()
    rows = []
    for name, desc, run in logs():
        t0 = time.perf_counter()
        try:
            d = run()
        except ValueError as exc:  # a log the loop cannot use says why
            print(f"{name}: {exc}")
            rows.append(f"| {name} | {desc} | error: {exc} | | | | |")
            continue
        dt = time.perf_counter() - t0
        out = OUT / name
        out.mkdir(parents=True, exist_ok=True)
        (out / "diagnosis.json").write_text(json.dumps(d.to_dict(), indent=1) + "\n")
        if name in args.figures:
            write_report(d, out)
        print(f"== {name} ({dt:.1f} s)\n{d.summary()}\n")
        # the way in (detector settings and candidates) is in each JSON; the table keeps findings
        way_in = ("no temperature", "angles in", "static detection", "fixed blocks")
        notes = "; ".join(
            [f"FOUND: {x}" for x in d.findings]
            + [n for n in d.notes if not n.startswith(way_in) and " static intervals, " not in n]
        )
        rows.append(
            f"| {name} | {desc} | {d.verdict} | {', '.join(d.effects) or '-'} | "
            f"{fmt(d, d.rms_before)} -> {fmt(d, d.rms_after)} | {fmt(d, d.noise_floor)} "
            f"(white {fmt(d, d.noise_floor_white)}, Allan {fmt(d, d.noise_floor_allan)}) | "
            f"{notes} |"
        )
    text = [
        "# What the close-the-loop diagnosis finds on the real logs",
        "",
        "Written by `.venv/bin/python docs/diagnose_real_logs.py` (the JSON of each run is in "
        "the log's folder, figures for some).",
        "",
        "| log | what | verdict | effects accepted | rms before -> after | floor | notes |",
        "|---|---|---|---|---|---|---|",
        *rows,
        "",
    ]
    (OUT / "README.md").write_text("\n".join(text))
    print(f"wrote {OUT / 'README.md'}")


if __name__ == "__main__":
    main()
