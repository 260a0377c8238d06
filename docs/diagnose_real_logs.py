"""Run the close-the-loop diagnosis on every real log in ../shared/data and record what it finds.

    .venv/bin/python docs/diagnose_real_logs.py [--figures xsens ck_accel ...]

Writes docs/diagnosis/<log>/diagnosis.json for every log, the report figures for the logs
named in --figures (default: a few, to keep the repository small), and docs/diagnosis/README.md
with one table row per log. Logs missing from ../shared/data are skipped with a message.

    .venv/bin/python docs/diagnose_real_logs.py --compare REV [--no-run]

also writes docs/diagnosis/before_after.md: every candidate's decision in the JSON committed
at git revision REV against the JSON written now (``--no-run``: the JSON already there), with
the tests that failed, so a change to the acceptance tests shows what it changed on real data.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
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


def _candidates(d: dict) -> dict:
    """(round, effect) -> the entry, for the fitted candidates of a diagnosis JSON."""
    return {
        (r, e["effect"]): e
        for r, log in enumerate(d.get("rounds") or [], 1)
        for e in log
        if "tests" in e
    }


def _decision(e: dict | None) -> str:
    if e is None:
        return "not tried"
    if e["accepted"]:
        return "**accepted**"
    failed = [k for k, ok in e["tests"].items() if not ok]
    return "failed " + ", ".join(failed)


def _z(e: dict | None) -> str:
    if e is None or e.get("halves_max_z") is None:
        return "-"
    formal = e.get("halves_max_z_formal")
    honest = f" (formal {formal:.1f})" if formal is not None else ""
    return f"{e['halves_max_z']:.1f}{honest}"


def compare(rev: str) -> Path:
    """Write before_after.md: the decisions in the JSON at ``rev`` against those now."""
    rows = []
    for folder in sorted(p for p in OUT.iterdir() if (p / "diagnosis.json").exists()):
        new = json.loads((folder / "diagnosis.json").read_text())
        rel = (folder / "diagnosis.json").relative_to(ROOT.parent)
        try:
            text = subprocess.run(
                ["git", "show", f"{rev}:{rel}"], capture_output=True, check=True, text=True
            ).stdout
        except subprocess.CalledProcessError:
            continue  # a log new since rev
        old = json.loads(text)
        verdict = f"{old['verdict']} -> {new['verdict']}"
        if old["verdict"] == new["verdict"]:
            verdict = f"{new['verdict']} (same)"
        before, after = _candidates(old), _candidates(new)
        keys = sorted(set(before) | set(after))
        for k, (r, effect) in enumerate(keys):
            b, a = before.get((r, effect)), after.get((r, effect))
            p = a.get("p_honest") if a else None
            rows.append(
                f"| {folder.name if k == 0 else ''} | {verdict if k == 0 else ''} | {r} | "
                f"{effect} | {_decision(b)} | {_z(b)} | {_decision(a)} | {_z(a)} | "
                f"{'-' if p is None else f'{p:.2g}'} |"
            )
        if not keys:
            rows.append(f"| {folder.name} | {verdict} | | (no candidate fitted) | | | | | |")
    path = OUT / "before_after.md"
    path.write_text(
        "\n".join(
            [
                f"# Acceptance tests before and after: the JSON at {rev} against now",
                "",
                "Written by `.venv/bin/python docs/diagnose_real_logs.py --compare "
                f"{rev} --no-run`. Halves z: the largest difference between the two halves' "
                "coefficients in standard errors (before: formal, independent samples; after: "
                "block jackknife, with the formal in brackets). p: Hotelling's T^2 with the "
                "jackknife covariance (the `honest` test: p < 0.01 over the round's candidates, "
                "`honest_alpha` in the JSON; 0.01 for each before 8ab2e27). `-`: not computed (the "
                "honest tests run only for candidates that pass BIC, null and plausibility).",
                "",
                "| log | verdict | round | candidate | before | halves z | after | halves z | p |",
                "|---|---|---|---|---|---|---|---|---|",
                *rows,
                "",
            ]
        )
    )
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument(
        "--figures", nargs="*", default=["xsens", "ck_accel", "qmc_filtered", "ck_marg"]
    )
    ap.add_argument("--compare", metavar="REV", help="also write before_after.md against REV")
    ap.add_argument("--no-run", action="store_true", help="only compare (with --compare)")
    args = ap.parse_args()
    if not args.no_run:
        run_all(args.figures)
    if args.compare:
        print(f"wrote {compare(args.compare)}")


def run_all(figures: list[str]) -> None:
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
        if name in figures:
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
