"""How far float32 runs of calib_jax.pipeline land from float64, over many simulated boards.

The float32 fit stops at float32 round-off (status CONVERGED_ROUNDOFF after 2-4 iterations), at
a point that depends on the data's rounding: one board is no measure of the accuracy. This
script fits ``--boards`` simulated boards (the board of tests/test_pipeline.py with fresh
directions and noise: accelerometer at rest in 30 orientations with 2 mg noise, magnetometer
in 60 with 1 % noise) in float64 and in float32 and reports, per quantity, the median, 90th
percentile and largest difference:

- parameters, as a fraction of their float64 standard error (and in absolute terms);
- the implicit derivative d(sum of gains)/d(samples), relative to its largest entry;
- roll/pitch/yaw of five test poses through both calibrations, degrees.

The test suite's float32 bounds (tests/test_pipeline.py) and the README quote these numbers.

    .venv/bin/python benchmarks/float32_accuracy.py [--boards 40]

writes benchmarks/results/float32_accuracy.json.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _device import describe, label, suffix  # noqa: E402
from jax.flatten_util import ravel_pytree  # noqa: E402

from calib_jax import pipeline as pl  # noqa: E402
from calib_jax.attitude import reference_vectors  # noqa: E402
from calib_jax.models.accel import distort  # noqa: E402
from calib_jax.rotations import rotvec_to_dcm  # noqa: E402

P_ACC = np.array([1.02, 0.98, 1.01, 0.01, -0.02, 0.005, 0.03, -0.01, 0.02])
W_MAG = np.array([[1.1, 0.05, 0.02], [0.05, 0.9, -0.03], [0.02, -0.03, 1.0]])
C_MAG = np.array([0.3, -0.2, 0.1])
DIP = 65.0
OUT = Path(__file__).resolve().parent / "results" / "float32_accuracy.json"


def _dirs(n, rng):
    d = rng.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _board(rng):
    acc = np.asarray(distort(jnp.asarray(P_ACC), jnp.asarray(_dirs(30, rng))))
    mag = _dirs(60, rng) @ np.linalg.inv(W_MAG).T + C_MAG
    return acc + 2e-3 * rng.normal(size=acc.shape), mag + 1e-2 * rng.normal(size=mag.shape)


def _gain_sum(raw, g=1.0):
    return jnp.sum(pl.fit_accel(raw, g).params.gains)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--boards", type=int, default=40)
    args = ap.parse_args(argv)

    fit_a, fit_m = jax.jit(pl.fit_accel), jax.jit(pl.fit_mag)
    grad = jax.jit(jax.grad(_gain_sum))
    euler = jax.jit(lambda mp, a, m, d: pl.euler_deg(pl.attitude(mp, a, m, d)))
    poses = _dirs(5, np.random.default_rng(99)) * [[0.3], [1], [2], [2.5], [0.8]]
    Rs = [np.asarray(rotvec_to_dcm(jnp.asarray(v))) for v in poses]
    r_a, r_m = (np.asarray(v) for v in reference_vectors(DIP))
    a_test = np.asarray(distort(jnp.asarray(P_ACC), jnp.asarray(np.stack([R.T @ r_a for R in Rs]))))
    m_test = np.stack([R.T @ r_m for R in Rs]) @ np.linalg.inv(W_MAG).T + C_MAG

    quantities = ("acc_per_stderr", "mag_per_stderr", "acc_abs", "mag_abs", "grad_rel", "euler_deg")
    rows = {k: [] for k in quantities}
    not_converged = 0
    f32 = jnp.float32
    for seed in range(args.boards):
        acc, mag = _board(np.random.default_rng(seed))
        a64, a32 = fit_a(jnp.asarray(acc), 1.0), fit_a(jnp.asarray(acc, f32), f32(1.0))
        m64, m32 = fit_m(jnp.asarray(mag), 1.0), fit_m(jnp.asarray(mag, f32), f32(1.0))
        not_converged += (not bool(a32.converged)) + (not bool(m32.converged))
        da = np.abs(np.asarray(a32.params.to_vector()) - np.asarray(a64.params.to_vector()))
        dm = np.abs(
            np.asarray(ravel_pytree(m32.params)[0]) - np.asarray(ravel_pytree(m64.params)[0])
        )
        rows["acc_abs"].append(da.max())
        rows["mag_abs"].append(dm.max())
        rows["acc_per_stderr"].append((da / np.asarray(a64.stderr)).max())
        rows["mag_per_stderr"].append((dm / np.asarray(m64.stderr)).max())
        g64 = np.asarray(grad(jnp.asarray(acc), 1.0))
        g32 = np.asarray(grad(jnp.asarray(acc, f32), f32(1.0)))
        rows["grad_rel"].append(np.abs(g32 - g64).max() / np.abs(g64).max())
        e64 = euler(
            pl.MargParams(a64.params, m64.params, pl.Rotation.identity()),
            jnp.asarray(a_test),
            jnp.asarray(m_test),
            DIP,
        )
        e32 = euler(
            pl.MargParams(a32.params, m32.params, pl.Rotation.identity(f32)),
            jnp.asarray(a_test, f32),
            jnp.asarray(m_test, f32),
            f32(DIP),
        )
        d = (np.asarray(e32, float) - np.asarray(e64) + 180.0) % 360.0 - 180.0
        rows["euler_deg"].append(np.abs(d).max())

    summary = {
        k: {
            "median": float(np.median(v)),
            "p90": float(np.quantile(v, 0.9)),
            "max": float(np.max(v)),
        }
        for k, v in rows.items()
    }
    info = describe()
    out = OUT.with_name(f"float32_accuracy{suffix(info)}.json")
    print(
        f"float32 against float64 over {args.boards} simulated boards "
        f"({not_converged} float32 fits not converged); {label(info)}"
    )
    print(f"{'quantity':<16} {'median':>10} {'p90':>10} {'max':>10}")
    for k, s in summary.items():
        print(f"{k:<16} {s['median']:>10.2e} {s['p90']:>10.2e} {s['max']:>10.2e}")
    out.parent.mkdir(exist_ok=True)
    out.write_text(
        json.dumps(
            {
                "boards": args.boards,
                "not_converged": not_converged,
                "jax": jax.__version__,
                "machine": info,
                "summary": summary,
            },
            indent=2,
        )
    )
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
