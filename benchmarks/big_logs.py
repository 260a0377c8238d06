"""Big logs (issue 17): a long 1 kHz accelerometer + magnetometer log through ``calib-jax
accel``, ``mag`` and ``diagnose``, each a new process timed from start to exit, with its peak
resident memory (polled from /proc every 0.1 s; a run over ``--max-gb`` is stopped and
reported as such, so a big fit cannot take the machine down). In the same run: the time
``numpy.loadtxt`` needs just to read the same file, the floor any reader of a CSV sits on.

The log: :func:`calib_jax.simulate.simulate_session` (48 poses held still, hand-held moves),
at 1 kHz for ``--hours`` (the issue's target is 3 h, about 11 million rows, under 60 s and
2 GB per command), written as CSV (t, ax, ay, az, mx, my, mz). Writes
benchmarks/results/big_logs.json and .md.

    .venv/bin/python benchmarks/big_logs.py [--hours 3] [--max-gb 12] [--only accel,mag]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from calib_jax.simulate import simulate_session  # noqa: E402

CLI = str(Path(sys.executable).parent / "calib-jax")
TARGET_S, TARGET_GB = 60.0, 2.0


def write_log(path: Path, hours: float) -> int:
    """A 48-pose session at 1 kHz lasting about ``hours``; returns its rows."""
    poses, move = 48, 1.0
    hold = hours * 3600.0 / poses - move
    s = simulate_session(poses=poses, hold=hold, move=move, rate=1000.0, seed=0)
    data = np.column_stack([s["t"], s["acc"], s["mag"]])
    with open(path, "w") as f:
        f.write("t,ax,ay,az,mx,my,mz\n")
        np.savetxt(f, data, delimiter=",", fmt="%.6f")
    return len(data)


def _rss_gb(pid: int) -> float:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1e6
    except OSError:
        pass
    return 0.0


def run(cmd: list[str], max_gb: float, cwd: str) -> dict:
    """Wall time, peak RSS (GB) and exit code of ``cmd``; stopped above ``max_gb``."""
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    peak, stopped = 0.0, False
    while p.poll() is None:
        peak = max(peak, _rss_gb(p.pid))
        if peak > max_gb:
            p.kill()
            stopped = True
        time.sleep(0.1)
    out = p.stdout.read().decode(errors="replace") if p.stdout else ""
    return {
        "seconds": time.perf_counter() - t0,
        "peak_gb": peak,
        "exit": p.returncode,
        "stopped_over_gb": stopped,
        "tail": out.strip().splitlines()[-3:],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=3.0)
    ap.add_argument("--max-gb", type=float, default=12.0)
    ap.add_argument("--only", default="accel,mag,diagnose")
    args = ap.parse_args()
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "big.csv"
        t0 = time.perf_counter()
        rows = write_log(log, args.hours)
        print(f"{rows:,} rows, {log.stat().st_size / 1e6:.0f} MB, written in "
              f"{time.perf_counter() - t0:.0f} s")  # fmt: skip
        read = f"import numpy; numpy.loadtxt({str(log)!r}, delimiter=',', skiprows=1)"
        cmd_loadtxt = [sys.executable, "-c", read]
        results = {"numpy.loadtxt (read only)": run(cmd_loadtxt, args.max_gb, tmp)}
        jobs = {
            "accel": [CLI, "accel", str(log), "--json", str(Path(tmp) / "a.json")],
            "mag": [CLI, "mag", str(log), "--json", str(Path(tmp) / "m.json")],
            "diagnose": [CLI, "diagnose", str(log), "--sensor", "accel"],
        }
        for name in args.only.split(","):
            # the cold run fills the compilation cache (a new one here); the time that matters
            # for a long log is the warm one, so both are kept
            env_cache = str(Path(tmp) / "cache")
            os.environ["CALIB_JAX_CACHE_DIR"] = env_cache
            results[f"calib-jax {name} (cold)"] = run(jobs[name], args.max_gb, tmp)
            results[f"calib-jax {name} (warm)"] = run(jobs[name], args.max_gb, tmp)
    ref = results["numpy.loadtxt (read only)"]["seconds"]
    lines = [
        f"# Big logs: {rows:,} rows at 1 kHz ({args.hours:g} h), CSV",
        "",
        f"Load {load0:.1f} at the start, {os.getloadavg()[0]:.1f} at the end; "
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores. Targets: "
        f"under {TARGET_S:g} s and {TARGET_GB:g} GB per command (issue 17, for 3 h).",
        "",
        "| command | s | x numpy.loadtxt | peak GB | exit |",
        "|---|---|---|---|---|",
    ]
    for name, r in results.items():
        ex = "stopped over the memory cap" if r["stopped_over_gb"] else str(r["exit"])
        s, gb = r["seconds"], r["peak_gb"]
        lines.append(f"| {name} | {s:.1f} | {s / ref:.1f} | {gb:.2f} | {ex} |")
    text = "\n".join(lines)
    print(text)
    out = ROOT / "benchmarks" / "results"
    (out / "big_logs.md").write_text(text + "\n")
    (out / "big_logs.json").write_text(
        json.dumps({"rows": rows, "hours": args.hours, "load": load0, "results": results}, indent=1)
        + "\n"
    )


if __name__ == "__main__":
    main()
