"""The MARG diagnosis's power and false alarms on simulated tumbles (issue 15).

    .venv/bin/python benchmarks/diagnosis_power.py [--seeds 20] [--parts misalignment timing
        permutation] [--out benchmarks/results]

For each effect size, two noise levels and two sample correlations, ``--seeds`` simulated
tumbles (3,000 samples at 100 Hz, ellipsoids fitted as a user's log would be) go through
:func:`calib_jax.diagnose.diagnose_marg` with its acceptance tests (BIC, leave-one-out, null
simulations, split halves and Hotelling's T^2 with block-jackknife errors, plausibility):

* ``misalignment``: the magnetometer rotated against the accelerometer by 0 (the false-alarm
  rate), 0.5, 1, 2, 5 and 10 deg about a fixed axis;
* ``timing``: the magnetometer ahead by 0, 1, 2, 5 and 10 samples (10-100 ms);
* ``permutation``: the magnetometer's axes mapped by one map of each kind (a swap of two axes
  with one negated, a cyclic shift, a negation of two axes, the MPU-9250's AK8963 map) with a
  further 5 deg rotation: the map must be named exactly.

Noise: white 2 mg / 0.2 uT ("low") or 6 mg / 0.6 uT ("high"); the hand's acceleration in the
accelerometer, 0.02 g, white ("independent") or AR(1) with lag-1 correlation 0.99, about 1 s
("correlated"). Each row gives the detection rate (the effect accepted, and for a permutation
the right map), the rate of any other effect accepted (false alarms), and the effect's size in
units of the diagnosis's noise floor (median over seeds; for timing a rough proxy, the median
rate of change of the accelerometer times the offset). Targets (issue 15): detection >= 95 %
at 3x the floor, false alarms <= 5 % per log, every map named at 5 deg of misalignment.

Writes diagnosis_power.json, diagnosis_power.md and diagnosis_power.png; the rows of parts not
run this time are kept from the JSON already there (each part's command and time are listed).
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from calib_jax.diagnose import diagnose_marg  # noqa: E402
from calib_jax.rotations import describe_permutation, rotvec_to_dcm  # noqa: E402
from calib_jax.simulate import correlated_noise, simulate_marg, tumble_quaternions  # noqa: E402

N = 3000
RATE = 100.0
AXIS = np.array([0.6, -0.5, 0.62]) / np.linalg.norm([0.6, -0.5, 0.62])
NOISE = {"low": (2e-3, 0.2), "high": (6e-3, 0.6)}
CORRELATION = {"independent": 0.0, "correlated": 0.99}
HAND_G = 0.02
MAPS = {
    "AK8963 (x<-y, y<-x, z<-(-z))": [[0, 1, 0], [1, 0, 0], [0, 0, -1]],
    "cyclic (x<-y, y<-z, z<-x)": [[0, 1, 0], [0, 0, 1], [1, 0, 0]],
    "swap x,y, negate x": [[0, -1, 0], [1, 0, 0], [0, 0, 1]],
    "negate x and y": [[-1, 0, 0], [0, -1, 0], [0, 0, 1]],
}


def simulate(seed, noise, corr, rot_deg=0.0, shift=0, P=None):
    """(acc, mag) of one tumble; the magnetometer is R P-mapped and ``shift`` samples ahead."""
    acc_noise, mag_noise = NOISE[noise]
    q = tumble_quaternions(N + 20, rng=seed, knots=16)
    R = np.asarray(rotvec_to_dcm(jnp.asarray(np.radians(rot_deg) * AXIS)))
    if P is not None:
        R = R @ np.asarray(P, float)
    hand = correlated_noise(N, HAND_G, CORRELATION[corr], rng=seed + 1000)
    c, W = np.array([10.0, -5, 3]), np.diag([1.1, 0.95, 1.0])
    common = dict(center=c, soft_iron=W, R_mag_board=R, acc_noise=acc_noise, mag_noise=mag_noise)
    s1 = simulate_marg(q[:N], linear_acc=hand, rng=seed, **common)
    s2 = simulate_marg(q[shift : shift + N], rng=seed + 1, **common)
    return s1.acc, s2.mag


def run_point(part, size, noise, corr, seeds, P=None):
    """One grid point over the seeds: detections, false alarms, size / floor."""
    want = {"misalignment": "sensor_misalignment", "timing": "timing_offset"}.get(part)
    hits = others = 0
    ratio = []
    for seed in range(seeds):
        kw = {"rot_deg": size} if part == "misalignment" else {"shift": int(size)}
        if part == "permutation":
            kw = {"rot_deg": 5.0, "P": P}
        acc, mag = simulate(seed, noise, corr, **kw)
        d = diagnose_marg(acc, mag, sample_rate=RATE, seed=seed, progress=False)
        effects = set(d.effects)
        if part == "permutation":
            entry = next(e for e in d.rounds[0] if e["effect"] == "axis_permutation")
            named = entry["permutation"] == describe_permutation(np.asarray(P, float))
            hit = "axis_permutation" in effects and named
            effects -= {"axis_permutation", "sensor_misalignment"}
        else:
            hit = want in effects and size > 0
            effects.discard(want if size > 0 else "")
        hits += bool(hit)
        others += bool(effects)
        if d.noise_floor and math.isfinite(d.noise_floor):
            if part == "misalignment":
                ratio.append(math.radians(size) / d.noise_floor)
            elif part == "timing":
                rate = np.median(np.linalg.norm(np.diff(acc, axis=0), axis=1)) * RATE  # g/s
                ratio.append(size / RATE * rate / d.noise_floor)
    return {
        "part": part,
        "size": size,
        "noise": noise,
        "correlation": corr,
        "seeds": seeds,
        "detection_rate": hits / seeds,
        "other_effects_rate": others / seeds,
        "size_over_floor": float(np.median(ratio)) if ratio else None,
    }


def grid(parts, seeds):
    for part in parts:
        if part == "misalignment":
            sizes = [0.0, 0.5, 1.0, 2.0, 5.0, 10.0]
        elif part == "timing":
            sizes = [0, 1, 2, 5, 10]
        else:
            sizes = list(MAPS)
        for noise in NOISE:
            for corr in CORRELATION:
                for size in sizes:
                    if part == "permutation":
                        row = run_point(part, 5.0, noise, corr, seeds, P=MAPS[size])
                        row["map"] = size
                    else:
                        row = run_point(part, size, noise, corr, seeds)
                    yield row


def markdown(rows, meta) -> str:
    out = [
        "# MARG diagnosis: detection and false alarms on simulated tumbles",
        "",
        *[
            f"- `{m['command']}`: {m['seeds']} seeds per row; {m['seconds']:.0f} s on "
            f"{m['machine']} (load {m['load']})."
            for m in meta["runs"]
        ],
        "",
        "| part | size | noise | samples | size / floor | detected | other effects |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        size = r.get("map") or (
            f"{r['size']:g} deg" if r["part"] == "misalignment" else f"{r['size']:g} samples"
        )
        sof = "-" if r["size_over_floor"] is None else f"{r['size_over_floor']:.2g}"
        det = "-" if r["part"] != "permutation" and r["size"] == 0 else f"{r['detection_rate']:.0%}"
        out.append(
            f"| {r['part']} | {size} | {r['noise']} | {r['correlation']} | {sof} | {det} | "
            f"{r['other_effects_rate']:.0%} |"
        )
    return "\n".join(out) + "\n"


def figure(rows, path: Path) -> None:
    from matplotlib.figure import Figure

    parts = [p for p in ("misalignment", "timing") if any(r["part"] == p for r in rows)]
    fig = Figure(figsize=(5 * max(len(parts), 1), 3.8))
    for k, part in enumerate(parts):
        ax = fig.add_subplot(1, len(parts), k + 1)
        for noise in NOISE:
            for corr in CORRELATION:
                pts = [
                    r
                    for r in rows
                    if r["part"] == part and r["noise"] == noise and r["correlation"] == corr
                    and r["size"] > 0 and r["size_over_floor"] is not None
                ]  # fmt: skip
                if pts:
                    ax.plot(
                        [r["size_over_floor"] for r in pts],
                        [100 * r["detection_rate"] for r in pts],
                        "o-",
                        label=f"{noise} noise, {corr}",
                    )
        ax.axvline(3, color="0.5", lw=0.8)
        ax.axhline(95, color="0.5", lw=0.8, ls="--")
        ax.set_xscale("log")
        ax.set_xlabel("effect size / noise floor")
        ax.set_ylabel("detected (%)")
        ax.set_title(part, fontsize=10)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--parts", nargs="+", default=["misalignment", "timing", "permutation"])
    ap.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    load = Path("/proc/loadavg").read_text().split()[0] if Path("/proc/loadavg").exists() else "?"
    rows = []
    for row in grid(args.parts, args.seeds):
        rows.append(row)
        print(json.dumps(row), flush=True)
    run = {
        "command": "benchmarks/diagnosis_power.py --seeds "
        f"{args.seeds} --parts {' '.join(args.parts)}",
        "parts": args.parts,
        "seeds": args.seeds,
        "seconds": time.perf_counter() - t0,
        "machine": f"{platform.machine()}, {jax.devices()[0].device_kind}",
        "load": load,
    }
    old = out / "diagnosis_power.json"
    runs = [run]
    if old.exists():  # keep the parts not run this time
        prev = json.loads(old.read_text())
        kept = [r for r in prev["rows"] if r["part"] not in args.parts]
        rows = kept + rows
        earlier = prev.get("runs") or [prev["meta"]]
        for m in earlier:
            m.setdefault("parts", m["command"].split("--parts ")[1].split())
        runs = [m for m in earlier if not set(m["parts"]) & set(args.parts)] + runs
    meta = {"runs": runs}
    (out / "diagnosis_power.json").write_text(json.dumps(meta | {"rows": rows}, indent=1))
    (out / "diagnosis_power.md").write_text(markdown(rows, meta))
    figure(rows, out / "diagnosis_power.png")
    print(markdown(rows, meta))


if __name__ == "__main__":
    main()
