"""Static detection without flags over a grid of simulated protocols (issue 13).

Every cell is a log from :func:`calib_jax.simulate.simulate_accel` with known truth: 60 poses
in uniformly random directions, held ``hold`` seconds, joined by ``move`` seconds of hand
motion (a slerp to the next pose plus a smooth disturbance of up to 0.1 g), white noise of
``noise`` g per axis, optionally a 30 s rest before the first pose (imu_tk's protocol). Each
log goes through :func:`calib_jax.calibrate_accel` with no detector option (only the sample
rate, which a log's time column gives). Per cell:

- poses found: poses with at least one detected interval lying wholly inside it, of 60 held;
  "leaky": detected intervals that reach into a motion or span two poses;
- max |z|: the largest parameter error against the truth, in the fit's standard errors;
- p: the chi-square (9 degrees of freedom) probability of the parameter error's Mahalanobis
  distance under the fit's covariance: small only when the error is larger than the fit says,
  whatever the parameter (a |z| above 3 in one of 96 x 9 parameters happens by chance);
- rms / floor: the residual over the interval means against the white-noise floor;
- the setting the sweep chose (window in samples, threshold factor), and the detection time.

A last row times ``detect_static`` on a 10-million-sample log (1 kHz, 40 poses tiled).

    .venv/bin/python benchmarks/static_grid.py [--quick]

writes benchmarks/results/static_grid.json and static_grid.md.
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402

import calib_jax as cj  # noqa: E402
from calib_jax.simulate import random_directions, random_params, simulate_accel  # noqa: E402
from calib_jax.static import detect_static  # noqa: E402

OUT = Path(__file__).resolve().parent / "results"
POSES = 60
HOLDS = (0.5, 1.0, 2.0, 5.0)
MOVES = (0.5, 2.0)
RATES = (20.0, 100.0, 1000.0)
NOISES = (1e-3, 1e-2)
RESTS = (0.0, 30.0)


def cell(hold, move, rate, noise, rest, seed):
    log = simulate_accel(
        random_params(seed),
        random_directions(POSES, seed),
        samples_per_pose=int(round(hold * rate)),
        transition_samples=int(round(move * rate)),
        initial_rest=int(round(rest * rate)),
        noise=noise,
        sample_rate=rate,
        rng=seed,
    )
    t0 = time.perf_counter()
    rep = detect_static(log.raw, sample_rate=rate)
    t_det = time.perf_counter() - t0
    found, leaky = set(), 0
    for iv in rep.intervals:
        p = log.pose[iv.start : iv.stop]
        if p[0] >= 0 and np.all(p == p[0]):
            found.add(int(p[0]))
        else:
            leaky += 1
    row = dict(
        hold_s=hold,
        move_s=move,
        rate_hz=rate,
        noise_g=noise,
        rest_s=rest,
        seed=seed,
        samples=len(log.raw),
        poses_held=POSES,
        poses_found=len(found),
        intervals=rep.n_intervals,
        leaky=leaky,
        left_out=len(rep.rejected),
        window=rep.window,
        factor=rep.factor,
        how=rep.how,
        detect_s=t_det,
    )
    try:
        cal = cj.calibrate_accel(log.raw, sample_rate=rate)
        err = cal.params - log.params
        z = err / cal.stderr
        chi2 = float(err @ np.linalg.solve(cal.covariance, err))
        row.update(
            status=cal.status,
            max_abs_z=float(np.max(np.abs(z))),
            chi2=chi2,
            p_chi2=float(stats.chi2.sf(chi2, len(err))),
            rms=cal.rms_after,
            floor=cal.noise_floor,
            rms_over_floor=cal.rms_after / cal.noise_floor,
            error=None,
        )
    except ValueError as e:
        row.update(status="error", max_abs_z=None, chi2=None, p_chi2=None, rms=None, floor=None,
                   rms_over_floor=None)  # fmt: skip
        row["error"] = str(e)[:200]
    return row


def long_log_timing():
    log = simulate_accel(
        random_params(0),
        random_directions(40, 0),
        samples_per_pose=5000,
        transition_samples=1000,
        noise=2e-3,
        sample_rate=1000.0,
        rng=0,
    )
    reps = int(np.ceil(10_000_000 / len(log.raw)))
    x = np.tile(log.raw, (reps, 1))[:10_000_000]
    t0 = time.perf_counter()
    rep = detect_static(x, sample_rate=1000.0)
    dt = time.perf_counter() - t0
    return dict(samples=len(x), seconds=dt, intervals=rep.n_intervals, window=rep.window,
                factor=rep.factor, candidates=len(rep.candidates))  # fmt: skip


def fmt(v, f):
    return "-" if v is None else format(v, f)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="100 Hz only, no 10M-sample timing")
    args = ap.parse_args()
    rates = (100.0,) if args.quick else RATES
    rows = []
    t_start = time.perf_counter()
    head = (
        f"{'hold':>4} {'move':>4} {'rate':>5} {'noise':>6} {'rest':>4} | {'found':>7} "
        f"{'leaky':>5} {'out':>3} | {'max|z|':>6} {'p':>6} {'rms/floor':>9} | {'window':>6} "
        f"{'factor':>6} {'det s':>6}"
    )
    print(head)
    for k, (hold, move, rate, noise, rest) in enumerate(
        itertools.product(HOLDS, MOVES, rates, NOISES, RESTS)
    ):
        r = cell(hold, move, rate, noise, rest, seed=k)
        rows.append(r)
        print(
            f"{hold:>4} {move:>4} {rate:>5.0f} {noise * 1e3:>4.0f}mg {rest:>4.0f} | "
            f"{r['poses_found']:>3}/{r['poses_held']:<3} {r['leaky']:>5} {r['left_out']:>3} | "
            f"{fmt(r['max_abs_z'], '6.2f')} {fmt(r['p_chi2'], '6.3f')} "
            f"{fmt(r['rms_over_floor'], '9.2f')} | "
            f"{r['window']:>6} {fmt(r['factor'], '6g')} {r['detect_s']:>6.2f}"
            + (f"  {r['error'][:60]}" if r.get("error") else ""),
            flush=True,
        )
    total = time.perf_counter() - t_start
    long = None if args.quick else long_log_timing()
    ok_found = [r for r in rows if r["poses_found"] == r["poses_held"] and r["leaky"] == 0]
    ok_z = [r for r in rows if r["max_abs_z"] is not None and r["max_abs_z"] < 3.0]
    # by chance alone: a cell has some |z| > 3 among its 9 parameters with probability
    # 1 - (1 - 0.0027)^9 (independent normals), and p < 0.01 with probability 0.01
    p_any_z3 = 1.0 - (1.0 - 2.0 * stats.norm.sf(3.0)) ** 9
    low_p = [r for r in rows if r["p_chi2"] is not None and r["p_chi2"] < 0.01]
    summary = dict(
        cells=len(rows),
        every_pose_found_no_leak=len(ok_found),
        within_3_sigma=len(ok_z),
        expected_beyond_3_sigma_by_chance=len(rows) * p_any_z3,
        p_chi2_below_0_01=len(low_p),
        expected_p_below_0_01_by_chance=0.01 * len(rows),
        median_rms_over_floor=float(np.median([r["rms_over_floor"] for r in rows
                                               if r["rms_over_floor"] is not None])),
        seconds=total,
        long_log=long,
    )  # fmt: skip
    print(json.dumps(summary, indent=1))
    OUT.mkdir(exist_ok=True)
    name = "static_grid_quick" if args.quick else "static_grid"
    (OUT / f"{name}.json").write_text(json.dumps(dict(summary=summary, rows=rows), indent=1))
    md = [
        "# Static detection without flags (benchmarks/static_grid.py)",
        "",
        f"{POSES} poses per log, random directions, calibrate_accel with no detector option. "
        "found: poses with a detected interval wholly inside them; leaky: intervals reaching "
        "into a motion; out: quiet stretches left out as pauses in motion; max|z|: largest "
        "parameter error in standard errors; p: chi-square (9 dof) probability of the parameter "
        "error under the fit's covariance; rms/floor: residual over interval means against "
        "the white-noise floor.",
        "",
        f"Cells: {len(rows)}; every pose found with no leaky interval: {len(ok_found)}; all "
        f"parameters within 3 standard errors: {len(ok_z)} (by chance alone "
        f"{len(rows) * p_any_z3:.1f} cells would have a |z| > 3); chi-square p < 0.01: "
        f"{len(low_p)} (by chance {0.01 * len(rows):.1f}); median rms/floor "
        f"{summary['median_rms_over_floor']:.2f}; {total:.0f} s in all.",
        "",
    ]
    if long:
        md += [
            f"10-million-sample log (1 kHz): detect_static {long['seconds']:.1f} s, "
            f"{long['intervals']} intervals, {long['candidates']} candidates.",
            "",
        ]
    md += [
        "| hold s | move s | rate Hz | noise mg | rest s | found | leaky | out | max abs z | p | "
        "rms/floor | window | factor | detect s |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        md.append(
            f"| {r['hold_s']:g} | {r['move_s']:g} | {r['rate_hz']:g} | {r['noise_g'] * 1e3:g} | "
            f"{r['rest_s']:g} | {r['poses_found']}/{r['poses_held']} | {r['leaky']} | "
            f"{r['left_out']} | {fmt(r['max_abs_z'], '.2f')} | {fmt(r['p_chi2'], '.3f')} | "
            f"{fmt(r['rms_over_floor'], '.2f')} | {r['window']} | {fmt(r['factor'], 'g')} | "
            f"{r['detect_s']:.2f} |"
        )
    (OUT / f"{name}.md").write_text("\n".join(md) + "\n")
    print(f"wrote {OUT / (name + '.json')} and .md")


if __name__ == "__main__":
    main()
