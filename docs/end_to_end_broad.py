"""End-to-end against two-stage calibration on BROAD (issue 7): writes docs/end_to_end/.

Fits on one undisturbed trial and evaluates on the other, both ways, for every ``--step``-th
sample of the full HDF5 trials in ../shared/data/broad_myon (or the package's excerpts with
``--excerpt``, which are every 10th sample). Prints a table and writes results.json and
README.md. Run: ``.venv/bin/python docs/end_to_end_broad.py [--step 10] [--excerpt]``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import calib_jax as cj  # noqa: E402
from calib_jax import endtoend as ee  # noqa: E402

HERE = Path(__file__).resolve().parent
SHARED = HERE.parents[1] / "shared" / "data" / "broad_myon"
TRIALS = {
    "02": "02_undisturbed_slow_rotation_B.hdf5",
    "05": "05_undisturbed_slow_rotation_with_breaks_B.hdf5",
}


def load(trial: str, step: int, excerpt: bool) -> tuple[dict, float]:
    if excerpt:
        d = cj.load_broad_excerpt(trial)
        sl = slice(None, None, step)
        return {k: v[sl] for k, v in d.items()}, cj.datasets.BROAD_EXCERPT_RATE / step
    from calib_jax.io.broad import load_broad

    t = load_broad(SHARED / TRIALS[trial])
    sl = slice(None, None, step)
    d = {"acc": t.acc[sl], "mag": t.mag[sl], "quat": t.quat[sl], "movement": t.movement[sl]}
    return d, t.sample_rate / step


def table(res: dict, fit: str, test: str) -> list[str]:
    rows = []
    for name, r in res["methods"].items():
        cells = [name, f"{r['dip_deg']:.1f}"]
        for split in ("fit", "test"):
            for kind in ("quasi_static", "movement"):
                e = r[split][kind]
                cells.append(f"{e['heading_rms']:.2f} / {e['inclination_rms']:.2f}")
        rows.append(f"| {fit} -> {test} | " + " | ".join(cells) + " |")
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--step", type=int, default=10)
    ap.add_argument("--excerpt", action="store_true")
    ap.add_argument(
        "--offsets",
        action="store_true",
        help="add the rows that fit a constant offset of the optical reference",
    )
    ap.add_argument("--out", type=Path, default=HERE / "end_to_end")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    head = (
        "| fit -> held out | method | dip (deg) | fit trial, quasi-static: heading / incl. RMS "
        "(deg) | fit trial, movement | held out, quasi-static | held out, movement |"
    )
    lines = [head, "|" + "---|" * 7]
    out = {"step": args.step, "excerpt": args.excerpt, "runs": {}}
    for fit, test in (("02", "05"), ("05", "02")):
        (df, rate), (dt, _) = (
            load(fit, args.step, args.excerpt),
            load(test, args.step, args.excerpt),
        )
        t0 = time.perf_counter()
        res = ee.compare(df, dt, sample_rate=rate, offsets=args.offsets)
        secs = time.perf_counter() - t0
        lines += table(res, fit, test)
        run = {"seconds": secs, "alignment": res["two_stage_alignment"], "methods": {}}
        for name, r in res["methods"].items():
            p = r["params"]
            run["methods"][name] = {
                **{k: v for k, v in r.items() if k not in ("params", "offset")},
                "hard_iron_uT": np.asarray(p.mag.hard_iron).tolist(),
                "soft_iron": np.asarray(p.mag.soft_iron).tolist(),
                "mag_to_acc_rotvec_deg": np.degrees(np.asarray(p.mag_to_acc.rotvec)).tolist(),
                "reference_offset_deg": np.degrees(r["offset"]).tolist(),
            }
        out["runs"][f"{fit}->{test}"] = run
        print(f"{fit} -> {test}: {secs:.1f} s")
    text = "\n".join(lines)
    print(text)
    (args.out / "results.json").write_text(json.dumps(out, indent=1))
    (args.out / "README.md").write_text(
        "# End-to-end against two-stage calibration on BROAD\n\n"
        f"Made by `docs/end_to_end_broad.py --step {args.step}"
        f"{' --excerpt' if args.excerpt else ''}{' --offsets' if args.offsets else ''}` "
        f"(every {args.step}th sample"
        f"{' of the excerpts' if args.excerpt else ' of the full trials'}). "
        "RMS heading / inclination error of the Gauss-Newton attitude against the optical truth, "
        "degrees. Quasi-static: reference rate below 5 deg/s; movement: BROAD's movement "
        "samples.\n\n" + text + "\n"
    )


if __name__ == "__main__":
    main()
