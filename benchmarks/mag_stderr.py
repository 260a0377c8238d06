"""Whether a magnetometer calibration's standard errors are honest (issue 15).

    .venv/bin/python benchmarks/mag_stderr.py --seeds 40

One clean tumble (:func:`calib_jax.simulate.simulate_mag_log`, soft iron, 6,000 samples at
50 Hz) is read again and again with new noise: white, or AR(1) with lag-1 correlation rho per
sample (0.9: 0.2 s; 0.98: 1 s; 0.995: 4 s), the same standard deviation. Over the seeds, the
spread of each estimated parameter (centre and W, the calibration's units) is the truth a
standard error should match. The table gives, per noise, the median over the 12 parameters of
(median reported standard error) / (spread over seeds), for the formal errors (independent
samples) and for the block jackknife's (:func:`calib_jax.mag.honest_stderr`); 1 is honest.
Writes ``benchmarks/results/mag_stderr.{json,md}``.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=40)
    ap.add_argument("--rhos", type=float, nargs="+", default=[0.0, 0.9, 0.98, 0.995])
    ap.add_argument("--noise", type=float, default=5e-3)
    ap.add_argument("--out", default="benchmarks/results/mag_stderr")
    a = ap.parse_args()

    import calib_jax as cj
    from calib_jax.runtime import configure
    from calib_jax.simulate import correlated_noise, simulate_mag_log

    configure()
    clean = simulate_mag_log(("soft_iron",), size=0.05, samples=6000, rest=0, noise=0.0, seed=0)
    rows = []
    t0 = time.time()
    for rho in a.rhos:
        est, formal, honest = [], [], []
        for seed in range(1, a.seeds + 1):
            x = clean.raw + correlated_noise(len(clean.raw), a.noise, rho, seed)
            cal = cj.calibrate_mag(x, model="full")
            est.append(np.concatenate([cal.center, cal.soft_iron.ravel()]))
            formal.append(np.concatenate([cal.stderr_center, cal.stderr_soft_iron.ravel()]))
            honest.append(
                np.concatenate([cal.stderr_center_honest, cal.stderr_soft_iron_honest.ravel()])
            )
        est, formal, honest = map(np.array, (est, formal, honest))
        keep = [0, 1, 2, 3, 4, 5, 7, 8, 11]  # centre and W's upper triangle (W is symmetric)
        truth = est.std(axis=0, ddof=1)[keep]
        r_formal = np.median(formal, axis=0)[keep] / truth
        r_honest = np.median(honest, axis=0)[keep] / truth
        rows.append(
            {
                "rho": rho,
                "correlated_over_s": round(1 / (1 - rho) / clean.sample_rate, 3),
                "seeds": a.seeds,
                "formal_over_true": float(np.median(r_formal)),
                "formal_over_true_range": [float(r_formal.min()), float(r_formal.max())],
                "honest_over_true": float(np.median(r_honest)),
                "honest_over_true_range": [float(r_honest.min()), float(r_honest.max())],
            }
        )
        print(rows[-1], flush=True)
    load = os.getloadavg()[0]
    head = (
        "| noise correlated over | formal / true (range) | jackknife / true (range) |\n"
        "|---|---|---|\n"
    )
    md = head + "".join(
        f"| {'white' if r['rho'] == 0 else str(r['correlated_over_s']) + ' s'} "
        f"| {r['formal_over_true']:.2f} ({r['formal_over_true_range'][0]:.2f}-"
        f"{r['formal_over_true_range'][1]:.2f}) "
        f"| {r['honest_over_true']:.2f} ({r['honest_over_true_range'][0]:.2f}-"
        f"{r['honest_over_true_range'][1]:.2f}) |\n"
        for r in rows
    )
    print(md)
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = {
        "noise": a.noise,
        "samples": 6000,
        "rate_hz": 50,
        "load": load,
        "seconds": time.time() - t0,
    }
    out.with_suffix(".json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
    out.with_suffix(".md").write_text(md)


if __name__ == "__main__":
    main()
