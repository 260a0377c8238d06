"""What a user waits for at the command line: ``--help``, and each command on shipped data,
cold (empty compilation cache) and warm (the cache the cold run filled), against a plain SciPy
script doing the same job in the same run (benchmarks/scipy_anchor.py: load, detect, fit,
write JSON).

Every row is a new process, timed from start to exit (``subprocess.run``), the median of
``--repeats`` runs; cold runs each get a new empty cache directory (CALIB_JAX_CACHE_DIR).
Targets (issue 17): help under 0.3 s; accel warm 1.5 s, cold 8 s; mag, marg, diagnose warm
3 s. Prints a table with the machine's load and writes benchmarks/results/cli.json and .md.

    .venv/bin/python benchmarks/cli.py [--repeats 3] [--only accel,mag]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from calib_jax.datasets import demo_log_path, mag_demo_log_path  # noqa: E402

BIN = Path(sys.executable).parent
CLI = str(BIN / "calib-jax")
ANCHOR = [sys.executable, str(ROOT / "benchmarks" / "scipy_anchor.py")]
XSENS = str(demo_log_path())
CK = str(mag_demo_log_path())

# name: (command without the output path, target warm s, target cold s, anchor command)
JOBS = {
    "accel": ([CLI, "accel", XSENS, "--json"], 1.5, 8.0, [*ANCHOR, "accel", XSENS]),
    "mag": ([CLI, "mag", CK, "--json"], 3.0, None, [*ANCHOR, "mag", CK]),
    "marg": ([CLI, "marg", CK, "--json"], 3.0, None, None),
    "diagnose": ([CLI, "diagnose", XSENS, "--sensor", "accel", "--json"], 3.0, None, None),
}
HELP = ["", "accel", "mag", "marg", "diagnose", "batch", "record", "demo"]


def timed(cmd: list[str], env: dict, cwd: str) -> tuple[float, int]:
    t0 = time.perf_counter()
    r = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True, timeout=900)
    dt = time.perf_counter() - t0
    if r.returncode not in (0, 1):  # 1: fitted, not to be trusted (still a full run)
        sys.exit(f"{' '.join(cmd)} exited {r.returncode}:\n{r.stdout[-2000:]}{r.stderr[-2000:]}")
    return dt, r.returncode


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--only", default=",".join(JOBS))
    args = ap.parse_args()
    work = tempfile.mkdtemp(prefix="calib_jax_cli_bench_")
    base = dict(os.environ)
    load = os.getloadavg()[0]
    rows = {}

    # --help: no cache involved; the slowest subcommand is the row's value
    helps = {}
    for sub in HELP:
        cmd = [CLI, *([sub] if sub else []), "--help"]
        helps[sub or "(top)"] = statistics.median(
            timed(cmd, base, work)[0] for _ in range(args.repeats)
        )
    rows["--help"] = {"warm_s": max(helps.values()), "per_command_s": helps, "target_s": 0.3}

    for name in args.only.split(","):
        cmd, warm_target, cold_target, anchor = JOBS[name]
        cold, warm = [], []
        for k in range(args.repeats):
            cache = Path(work) / f"cache-{name}-{k}"
            env = {**base, "CALIB_JAX_CACHE_DIR": str(cache)}
            cold.append(timed([*cmd, f"{work}/{name}-cold.json"], env, work)[0])
            warm.append(timed([*cmd, f"{work}/{name}-warm.json"], env, work)[0])
            shutil.rmtree(cache, ignore_errors=True)
        row = {
            "cold_s": statistics.median(cold),
            "warm_s": statistics.median(warm),
            "cold_runs_s": cold,
            "warm_runs_s": warm,
            "target_warm_s": warm_target,
            "target_cold_s": cold_target,
        }
        if anchor is not None:
            out_json = f"{work}/{name}-scipy.json"
            a = [timed([*anchor, out_json], base, work)[0] for _ in range(args.repeats)]
            row["scipy_s"] = statistics.median(a)
            row["warm_over_scipy"] = row["warm_s"] / row["scipy_s"]
        rows[name] = row

    out = {
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, {platform.python_version()}",
        "load_1min_at_start": load,
        "load_1min_at_end": os.getloadavg()[0],
        "repeats": args.repeats,
        "rows": rows,
    }
    head = "| command | cold s | warm s | target warm / cold s | SciPy script s | warm / SciPy |"
    lines = [head, "|---|---|---|---|---|---|"]
    for name, r in rows.items():
        tgt = f"{r.get('target_warm_s', r.get('target_s'))}"
        if r.get("target_cold_s"):
            tgt += f" / {r['target_cold_s']}"
        lines.append(f"| {name} | {r['cold_s']:.1f} | " if "cold_s" in r else f"| {name} | - | ")
        lines[-1] += f"{r['warm_s']:.2f} | {tgt} | "
        lines[-1] += (
            f"{r['scipy_s']:.2f} | {r['warm_over_scipy']:.1f}x |" if "scipy_s" in r else "- | - |"
        )
    text = "\n".join(lines)
    text += f"\n\nmedians of {args.repeats} new processes; load {load:.2f} at start, "
    text += f"{out['load_1min_at_end']:.2f} at end; {out['machine']}\n"
    print(text)
    res = ROOT / "benchmarks" / "results"
    (res / "cli.json").write_text(json.dumps(out, indent=1) + "\n")
    (res / "cli.md").write_text(text)
    shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
