"""The tables of docs/performance.md (and close_the_loop.md's error table) that come from
committed benchmark JSON, written from it.

    .venv/bin/python benchmarks/tables.py           # rewrite the tables in the docs
    .venv/bin/python benchmarks/tables.py --check   # exit 1 if a table differs from its JSON

Each table sits between ``<!-- generated: NAME -->`` and ``<!-- end: NAME -->``; the prose
around it is written by hand. tests/test_docs.py runs the check, so a benchmark re-run without
its table (or a table edited by hand) fails the suite.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
DOC = Path(__file__).resolve().parents[1] / "docs" / "performance.md"


def _g(x: float) -> str:
    """Three significant figures, trailing zeros kept (0.120, 8.70, 0.000793)."""
    return f"{x:#.3g}".rstrip(".")


def _ratio(x: float) -> str:
    return f"{x:.0f}x" if x >= 10 else f"{x:.2g}x"


def _batch_row(r: dict, label: str) -> str:
    return (
        f"| {label} | {_g(r['calib_jax_ms_per_sensor'])} | {r['calib_jax_first_s']:.1f} | "
        f"{_g(r['scipy_ms_per_sensor'])} | {_ratio(r['speedup_vs_scipy'])} | "
        f"{_g(r['optimistix_ms_per_sensor'])} | {_ratio(r['speedup_vs_optimistix'])} |"
    )


def batch_cpu(results: Path = RESULTS) -> str:
    """This machine's batch rows (batch.json), the sharded run's after the size it shares."""
    head = (
        "| sensors | calib_jax ms/sensor | first call s | SciPy lm loop ms/sensor | ratio | "
        "optimistix vmap ms/sensor | ratio |\n|---|---|---|---|---|---|---|"
    )
    rows = json.loads((results / "batch.json").read_text())["rows"]
    sharded = json.loads((results / "batch_sharded.json").read_text())
    lines = [head]
    for r in rows:
        lines.append(_batch_row(r, str(r["sensors"])))
        for s in sharded["rows"]:
            if s["sensors"] == r["sensors"]:
                label = f"{s['sensors']}, sharded over {s['devices']} host devices"
                lines.append(_batch_row(s, label))
    return "\n".join(lines)


def batch_gpu(results: Path = RESULTS) -> str:
    """The GPU run's rows (batch_gpu.json) and that machine's CPU baseline
    (gpu_host_cpu/batch.json), with the input bandwidth each fit reached."""
    head = (
        "| sensors | device | calib_jax ms/sensor | first call s | SciPy lm loop ms/sensor | "
        "ratio | optimistix vmap ms/sensor | ratio | input GB/s |\n"
        "|---|---|---|---|---|---|---|---|---|"
    )
    lines = [head]
    for path, device in (
        (results / "batch_gpu.json", None),
        (results / "gpu_host_cpu" / "batch.json", "that machine's CPU"),
    ):
        d = json.loads(path.read_text())
        m = d["machine"]
        name = device or m["device_kind"].removeprefix("NVIDIA ")
        if device:
            name += f" ({m['host_cores']} cores)"
        for r in d["rows"]:
            row = _batch_row(r, f"{r['sensors']} | {name}")
            lines.append(f"{row} {r['input_gb_per_s']:.3g} |")
    return "\n".join(lines)


_CLI_ROWS = (
    ("accel", "`accel` Xsens"),
    ("mag", "`mag` CK-Explorer"),
    ("marg", "`marg` CK-Explorer"),
    ("diagnose", "`diagnose --sensor accel` Xsens"),
)


def cli(results: Path = RESULTS) -> str:
    """benchmarks/cli.py's rows (cli.json): each command cold and warm, its target, and the
    SciPy script's time where there is one."""
    d = json.loads((results / "cli.json").read_text())["rows"]
    lines = [
        "| command | cold s | warm s | issue 17 target warm / cold s | SciPy script s | "
        "warm / SciPy |",
        "|---|---|---|---|---|---|",
        f"| `--help` (slowest of {len(d['--help']['per_command_s'])}) | - | "
        f"{d['--help']['warm_s']:.2f} | {d['--help']['target_s']:g} | - | - |",
    ]
    for key, label in _CLI_ROWS:
        r = d[key]
        target = f"{r['target_warm_s']:.1f}" + (
            f" / {r['target_cold_s']:.1f}" if r.get("target_cold_s") else ""
        )
        scipy = f"{r['scipy_s']:.2f} | {r['warm_over_scipy']:.1f}x" if r.get("scipy_s") else "- | -"
        lines.append(f"| {label} | {r['cold_s']:.1f} | {r['warm_s']:.2f} | {target} | {scipy} |")
    return "\n".join(lines)


def mag_stderr(results: Path = RESULTS) -> str:
    """benchmarks/mag_stderr.py: the formal and the jackknife errors over the true spread."""
    d = json.loads((results / "mag_stderr.json").read_text())
    lines = [
        "| noise correlated over | formal / true (range) | jackknife / true (range) |",
        "|---|---|---|",
    ]
    for r in d["rows"]:
        when = "white" if r["rho"] == 0 else f"{r['correlated_over_s']:.1f} s"
        f, h = r["formal_over_true_range"], r["honest_over_true_range"]
        lines.append(
            f"| {when} | {r['formal_over_true']:.2f} ({f[0]:.2f}-{f[1]:.2f}) "
            f"| {r['honest_over_true']:.2f} ({h[0]:.2f}-{h[1]:.2f}) |"
        )
    return "\n".join(lines)


TABLES = {"cli": cli, "batch-cpu": batch_cpu, "batch-gpu": batch_gpu}
CLOSE_THE_LOOP = DOC.with_name("close_the_loop.md")
OTHER_TABLES = {CLOSE_THE_LOOP: {"mag_stderr": mag_stderr}}
"""Generated tables in other pages than performance.md, by page."""


def render(text: str, results: Path = RESULTS, tables: dict | None = None) -> str:
    """``text`` with every generated table written anew from the JSON (``tables``: name ->
    maker, default performance.md's)."""
    for name, make in (TABLES if tables is None else tables).items():
        pattern = re.compile(
            rf"(<!-- generated: {name} -->\n).*?(\n<!-- end: {name} -->)", flags=re.DOTALL
        )
        if not pattern.search(text):
            raise ValueError(f"{DOC.name} has no '<!-- generated: {name} -->' block")
        text = pattern.sub(lambda m, make=make: m.group(1) + make(results) + m.group(2), text)
    return text


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--check", action="store_true", help="exit 1 if a table is out of date")
    args = ap.parse_args()
    stale = 0
    for doc, tables in ((DOC, None), *OTHER_TABLES.items()):
        text = doc.read_text()
        new = render(text, tables=tables)
        if args.check:
            if new != text:
                print(f"{doc} is out of date: run benchmarks/tables.py", file=sys.stderr)
                stale = 1
            continue
        doc.write_text(new)
        print(f"wrote the tables of {doc}")
    return stale


if __name__ == "__main__":
    sys.exit(main())
