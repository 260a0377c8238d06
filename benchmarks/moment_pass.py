"""The batch's moment pass alone: today's (the mean, then the 35 power sums about it,
calib_jax.batch._batch_moments) against the pass it replaced (mean, RMS distance, normalise,
then the 6 x 10 monomial product; written out below as the reference), in one process,
interleaved, medians. Writes benchmarks/results/moment_pass.json.

    .venv/bin/python benchmarks/moment_pass.py [--sensors 1000] [--repeats 15]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from calib_jax.batch import _batch_moments  # noqa: E402
from calib_jax.geometry import centre_and_scale  # noqa: E402


def _moments_6x10(x, w):
    """The moment matrix as it was computed before: the 6 x 10 product of the quadratic
    monomials with [q, x, 1]."""
    X, Y, Z = x[..., 0], x[..., 1], x[..., 2]
    Q = jnp.stack([X * X, Y * Y, Z * Z, X * Y, X * Z, Y * Z], -1)
    R = jnp.concatenate([Q, x, jnp.ones_like(X)[:, None]], -1)
    A = (Q * w[:, None]).T @ R
    s1 = jnp.concatenate([w @ x, jnp.sum(w)[None]])
    q1 = A[:, 9]
    xx = q1[jnp.array([[0, 3, 4], [3, 1, 5], [4, 5, 2]])]
    top = jnp.concatenate([A[:, 6:9].T, xx, s1[:3, None]], axis=1)
    bottom = jnp.concatenate([top, jnp.concatenate([q1, s1])[None, :]], axis=0)
    d = jnp.array([1, 1, 1, 2, 2, 2, 1, 1, 1, 1], x.dtype)
    return jnp.concatenate([A, bottom], axis=0) * d[:, None] * d[None, :]


def previous_pass(raw, valid):
    def one(args):
        r, v = args
        v = v & jnp.all(jnp.isfinite(r), axis=-1)
        r = jnp.where(v[:, None], r, 0.0)
        mean, k = centre_and_scale(r, v.astype(r.dtype))
        return _moments_6x10((r - mean) / k, v.astype(r.dtype)), mean, k

    return jax.lax.map(one, (raw, valid), batch_size=8)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--sensors", type=int, default=1000)
    ap.add_argument("--samples", type=int, default=4800)
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    d = rng.normal(size=(args.sensors, args.samples, 3))
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    raw = jnp.asarray(d * 1.02 + 0.05 + 2e-3 * rng.normal(size=d.shape))
    valid = jnp.ones(raw.shape[:2], bool)
    old, new = jax.jit(previous_pass), jax.jit(_batch_moments)
    s_old, s_new = old(raw, valid)[0], new(raw, valid)[0]
    diff = float(jnp.max(jnp.abs(s_old - s_new)) / jnp.max(jnp.abs(s_old)))
    times = {"previous": [], "current": []}
    for _ in range(args.repeats):
        for name, f in (("previous", old), ("current", new)):
            t = time.perf_counter()
            jax.block_until_ready(f(raw, valid))
            times[name].append(time.perf_counter() - t)
    ms = {k: 1e3 * statistics.median(v) / args.sensors for k, v in times.items()}
    row = {
        "sensors": args.sensors,
        "samples": args.samples,
        "previous_ms_per_sensor": ms["previous"],
        "current_ms_per_sensor": ms["current"],
        "speedup": ms["previous"] / ms["current"],
        "max_abs_diff_over_max_S": diff,
        "load": os.getloadavg()[0],
        "device": str(jax.devices()[0]),
    }
    print("| pass | ms per sensor |\n|---|---|")
    print(f"| previous (normalise, 6 x 10 product) | {ms['previous']:.4f} |")
    print(f"| current (mean, 35 power sums) | {ms['current']:.4f} |")
    print(
        f"speed-up {row['speedup']:.2f}x; S agrees to {diff:.1e} of its largest entry; "
        f"load {row['load']:.2f}; {row['device']}"
    )
    out = Path(args.out) / "moment_pass.json"
    out.write_text(json.dumps(row, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
