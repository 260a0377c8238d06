"""A single warm accelerometer fit on a 4,800-sample log: calib_jax against SciPy, same run.

Paper 1 fits 4,800 samples. The data is simulated (48 poses x 100 samples, 2 mg noise) and
normalised to unit radius once, so both solvers see the same residual (paper 1 eq. 6 / g^2)
from the same start. SciPy's least_squares (method "lm", MINPACK) gets the residual and the exact
Jacobian as jitted JAX functions converted to numpy, the fairest peer we can give it.

Prints a table of medians and writes benchmarks/results/single_fit.json. Run:

    .venv/bin/python benchmarks/single_fit.py [--repeats 30]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import jax

from calib_jax.runtime import configure

# as a user's session and the CLI: float64 and XLA's short-compile CPU emitter; no cache
configure(cache=False)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _device import describe, label, suffix  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402

from calib_jax.accel import _fit_program, initial_guess  # noqa: E402
from calib_jax.models.accel import normalized_sphere_residual  # noqa: E402
from calib_jax.simulate import random_params, simulate_accel  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=30)
    args = ap.parse_args()
    log = simulate_accel(
        random_params(0), samples_per_pose=100, transition_samples=0, noise=2e-3, rng=0
    )
    x = log.raw[log.static][:4800]
    x = jnp.asarray(x)
    w = jnp.ones(len(x))
    rows = {}

    for solver in ("lm1", "lm2", "lm3", "optimistix"):
        fit = _fit_program(solver, "accel9", ())
        t0 = time.perf_counter()
        r = fit(x, w)
        r.params.block_until_ready()
        compile_s = time.perf_counter() - t0
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            r = fit(x, w)
            r.params.block_until_ready()
            times.append(time.perf_counter() - t0)
        rows[f"calib_jax {solver}"] = dict(
            median_ms=1e3 * float(np.median(times)),
            compile_s=compile_s,
            iterations=int(r.iterations),
            chi2=float(r.chi2),
            params=np.asarray(r.params).tolist(),
        )

    f = jax.jit(lambda p: normalized_sphere_residual(p, x, 1.0))
    J = jax.jit(jax.jacfwd(lambda p: normalized_sphere_residual(p, x, 1.0)))
    p0 = np.asarray(jax.jit(initial_guess)(x, w))
    f(p0).block_until_ready()
    J(p0).block_until_ready()
    for method in ("lm", "trf"):
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            ref = least_squares(
                lambda p: np.asarray(f(p)),
                p0,
                jac=lambda p: np.asarray(J(p)),
                method=method,
                xtol=1e-15,
                ftol=1e-15,
                gtol=1e-15,
            )
            times.append(time.perf_counter() - t0)
        rows[f"scipy {method}"] = dict(
            median_ms=1e3 * float(np.median(times)),
            compile_s=0.0,
            iterations=int(ref.nfev),
            chi2=float(2 * ref.cost),
            params=ref.x.tolist(),
        )
    base = rows["scipy lm"]["median_ms"]
    info = describe()
    print(
        f"single fit, {len(x)} samples, median of {args.repeats} warm runs "
        f"({platform.machine()}; {label(info)})"
    )
    print(
        f"{'solver':<22}{'median ms':>10}{'vs scipy lm':>13}{'compile s':>11}{'iter/nfev':>11}"
        f"{'chi2 - scipy':>14}"
    )
    for name, r in rows.items():
        r["speedup_vs_scipy_lm"] = base / r["median_ms"]
        print(
            f"{name:<22}{r['median_ms']:>10.2f}{r['speedup_vs_scipy_lm']:>12.2f}x"
            f"{r['compile_s']:>11.2f}{r['iterations']:>11d}"
            f"{r['chi2'] - rows['scipy lm']['chi2']:>14.2e}"
        )
    out = Path(__file__).parent / "results"
    out.mkdir(exist_ok=True)
    name = f"single_fit{suffix(info)}.json"
    (out / name).write_text(
        json.dumps(
            dict(
                samples=len(x), repeats=args.repeats, jax=jax.__version__, machine=info, rows=rows
            ),
            indent=2,
        )
    )
    print(f"wrote {out / name}")


if __name__ == "__main__":
    main()
