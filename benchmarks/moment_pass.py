"""The batch's moment pass alone: today's (the mean, then the 35 power sums about it, each
pass one variadic reduce, calib_jax.batch._batch_moments) against the two passes it replaced,
written out below as references: the same sums as 35 ``jnp.sum`` calls after a mean by a
matrix product, and before that mean, RMS distance, normalise, then the 6 x 10 monomial
product. In one process, interleaved, medians, with the device's memory ceiling measured in
the same run (a jitted ``raw + 1``: every byte read once and written once) and the fraction of
it each pass reaches (the pass must read the samples and the mask once). Run as a user's
session is (runtime.configure: x64 and the short-compile CPU emitter). Writes
benchmarks/results/moment_pass.json (moment_pass_gpu.json on a GPU).

    .venv/bin/python benchmarks/moment_pass.py [--sensors 1000] [--repeats 15]
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import statistics
import time
from pathlib import Path

import jax

from calib_jax.runtime import configure

configure(cache=False)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _device import describe, label, suffix  # noqa: E402

from calib_jax.batch import MOMENT_CHUNK, _batch_moments  # noqa: E402
from calib_jax.geometry import (  # noqa: E402
    _POWER_INDEX,
    _monomials,
    centre_and_scale,
    moments_from_power_sums,
    variadic_sum,
)


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


def sums_pass(raw, valid, variadic: bool = False):
    """The pass before the variadic reduce: the mean by a matrix product, then the 35 power
    sums about it as separate ``jnp.sum`` calls (each monomial written out and read back).
    ``variadic``: the sums by geometry.variadic_sum on any device (calib_jax takes it on the
    CPU only until a GPU has measured it: the "variadic (forced)" row)."""

    def one(args):
        r, v = args
        v = v & jnp.all(jnp.isfinite(r), axis=-1)
        w = v.astype(r.dtype)
        x = jnp.where(v[:, None], r, 0.0)
        n = jnp.sum(w)
        n = jnp.where(n > 0, n, 1.0)
        mean = (w @ x) / n
        mono = _monomials(jnp.where(v[:, None], x - mean, 0.0), w)
        if variadic:
            P = jnp.stack(variadic_sum(mono), axis=-1)
        else:
            P = jnp.stack([jnp.sum(m, axis=-1) for m in mono], axis=-1)
        square = sum(P[_POWER_INDEX[e]] for e in [(2, 0, 0), (0, 2, 0), (0, 0, 2)])
        k = jnp.sqrt(square / n)
        k = jnp.where(k > 0, k, 1.0)
        return moments_from_power_sums(P, k), mean, k

    chunk = min(MOMENT_CHUNK.get(jax.default_backend(), MOMENT_CHUNK["gpu"]), raw.shape[0])
    return jax.lax.map(one, (raw, valid), batch_size=chunk)


def first_pass(raw, valid):
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
    ap.add_argument(
        "--chunks",
        type=int,
        nargs="*",
        default=[],
        help="also time the current pass at these sensors per step (0: one vmap over all)",
    )
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    d = rng.normal(size=(args.sensors, args.samples, 3))
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    raw = jnp.asarray(d * 1.02 + 0.05 + 2e-3 * rng.normal(size=d.shape))
    valid = jnp.ones(raw.shape[:2], bool)
    info = describe()
    first, old, new = jax.jit(first_pass), jax.jit(sums_pass), jax.jit(_batch_moments)
    copy = jax.jit(lambda x: x + 1.0)
    jax.block_until_ready(copy(raw))
    s_first, s_old, s_new = first(raw, valid)[0], old(raw, valid)[0], new(raw, valid)[0]
    diff = float(jnp.max(jnp.abs(s_old - s_new)) / jnp.max(jnp.abs(s_old)))
    diff_first = float(jnp.max(jnp.abs(s_first - s_new)) / jnp.max(jnp.abs(s_first)))
    forced = jax.jit(functools.partial(sums_pass, variadic=True))
    passes = {
        "first": first,
        "previous": old,
        "current": new,
        "variadic": forced,
        "copy": lambda r, v: copy(r),
    }
    for c in args.chunks:
        passes[f"chunk {c}"] = jax.jit(functools.partial(_batch_moments, chunk=c))
        s_c = passes[f"chunk {c}"](raw, valid)[0]
        assert float(jnp.max(jnp.abs(s_c - s_new))) <= 1e-12 * float(jnp.max(jnp.abs(s_new)))
    times = {k: [] for k in passes}
    for _ in range(args.repeats):
        for name, f in passes.items():
            t = time.perf_counter()
            jax.block_until_ready(f(raw, valid))
            times[name].append(time.perf_counter() - t)
    ms = {k: 1e3 * statistics.median(v) / args.sensors for k, v in times.items()}
    copy_gbs = 2 * raw.nbytes / (ms["copy"] * args.sensors / 1e3) / 1e9
    pass_bytes = raw.nbytes + valid.nbytes
    gbs = {k: pass_bytes / (ms[k] * args.sensors / 1e3) / 1e9 for k in ms if k != "copy"}
    row = {
        "sensors": args.sensors,
        "samples": args.samples,
        "previous_ms_per_sensor": ms["previous"],
        "current_ms_per_sensor": ms["current"],
        "speedup": ms["previous"] / ms["current"],
        "max_abs_diff_over_max_S": diff,
        "first_ms_per_sensor": ms["first"],
        "first_max_abs_diff_over_max_S": diff_first,
        "copy_ceiling_gb_per_s": copy_gbs,
        "previous_gb_per_s": gbs["previous"],
        "current_gb_per_s": gbs["current"],
        "current_fraction_of_copy_ceiling": gbs["current"] / copy_gbs,
        "variadic_forced_ms_per_sensor": ms["variadic"],
        "default_chunk": MOMENT_CHUNK.get(jax.default_backend(), MOMENT_CHUNK["gpu"]),
        "chunks_ms_per_sensor": {k[6:]: ms[k] for k in ms if k.startswith("chunk ")},
        "best_chunk": min(args.chunks, key=lambda c: ms[f"chunk {c}"]) if args.chunks else None,
        "load": os.getloadavg()[0],
        "device": str(jax.devices()[0]),
        "machine": info,
    }
    print(label(info))
    print("| pass | ms per sensor | GB/s | fraction of the copy ceiling |\n|---|---|---|---|")
    names = {
        "first": "first (normalise, 6 x 10 product)",
        "previous": "previous (mean by a product, 35 separate sums)",
        "current": f"current (one reduce per pass), {row['default_chunk']} sensors per step",
        "variadic": "variadic (forced on any device: the mean by a product, one reduce)",
    }
    names.update({f"chunk {c}": f"current, {c or 'all'} sensors per step" for c in args.chunks})
    for k, name in names.items():
        print(f"| {name} | {ms[k]:.5f} | {gbs[k]:.1f} | {gbs[k] / copy_gbs:.3f} |")
    print(f"| copy ceiling (raw + 1, read and write) | {ms['copy']:.5f} | {copy_gbs:.1f} | 1 |")
    print(
        f"speed-up over previous {row['speedup']:.2f}x; S agrees to {diff:.1e} of its largest "
        f"entry ({diff_first:.1e} with the first); "
        f"load {row['load']:.2f}; {row['device']}"
    )
    Path(args.out).mkdir(parents=True, exist_ok=True)
    out = Path(args.out) / f"moment_pass{suffix(info)}.json"
    out.write_text(json.dumps(row, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
