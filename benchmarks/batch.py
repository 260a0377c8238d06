"""Batch calibration speed: calib_jax's moment-form batch fit against a SciPy least_squares loop
and an optimistix vmapped sample-level fit, on the same simulated data, in the same run.

    .venv/bin/python benchmarks/batch.py [--sizes 1 10 100 1000 10000] [--stream 100000]
    XLA_FLAGS=--xla_force_host_platform_device_count=2 .venv/bin/python benchmarks/batch.py --shard

Each sensor: 4,800 samples of static gravity directions spread over the sphere, a random
nine-parameter truth (gains 1 +- 5 %, cross terms +- 2 %, biases +- 0.05 g), white noise 2 mg.
Times are medians of repeats (this machine is shared: medians and ratios, not single runs);
the peers run on at most --peer-max sensors and are reported per sensor. Writes
benchmarks/results/batch.json, batch.md and batch.png.

On a GPU the same command runs unchanged: the table names the device, results go to
batch_gpu.* beside the CPU's, and each size's fit runs once under
``jax.transfer_guard_device_to_host("disallow")`` (the batch must never copy back to the host
before its result; the guard cannot see copies on the CPU, where it records "not checked").

Peers:
- SciPy: ``least_squares(method="lm")`` per sensor, the same normalised residual, the default
  finite-difference Jacobian (what a SciPy user writes), data normalised the same way.
- optimistix: ``jit(vmap(...))`` of its LevenbergMarquardt on the sample-level residual, the
  obvious JAX design (a (sensors x samples x 9) Jacobian every step).
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import time
from pathlib import Path

import jax

from calib_jax.runtime import configure

# as a user's session (docs/index.md) and the CLI: float64 and XLA's short-compile CPU emitter
# (runtime.SHORT_COMPILES_FLAG); no compilation cache, so "first call" is a compile
configure(cache=False)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _device import describe, label, suffix  # noqa: E402

from calib_jax.batch import MOMENT_CHUNK, calibrate_accel_batch  # noqa: E402
from calib_jax.models.accel import distort, normalized_sphere_residual  # noqa: E402
from calib_jax.simulate import random_params  # noqa: E402

N_SAMPLES = 4800
NOISE = 2e-3


def simulate(n_sensors: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    P = np.stack([random_params(seed * 1_000_003 + k) for k in range(n_sensors)])
    d = rng.normal(size=(n_sensors, N_SAMPLES, 3))
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    raw = np.asarray(jax.jit(jax.vmap(distort))(jnp.asarray(P), jnp.asarray(d)))
    return raw + NOISE * rng.normal(size=raw.shape), P


def timed(f, repeats: int) -> tuple[float, float]:
    """(first call incl. compile, median of ``repeats`` warm calls), seconds."""
    t = time.perf_counter()
    jax.block_until_ready(f())
    first = time.perf_counter() - t
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(f())
        ts.append(time.perf_counter() - t)
    return first, statistics.median(ts)


def normalise(x):
    m = x.mean(0)
    k = np.sqrt(np.mean(np.sum((x - m) ** 2, 1)))
    return (x - m) / k, m, k


def scipy_loop(raw: np.ndarray) -> tuple[float, np.ndarray]:
    """Per-sensor median time of least_squares(method='lm') and the fitted parameters."""
    from scipy.optimize import least_squares

    def resid(p, x):
        A = np.array([[p[0], p[3], p[4]], [p[3], p[1], p[5]], [p[4], p[5], p[2]]])
        a = np.linalg.solve(A, (x - p[6:9]).T).T
        return 1.0 - np.sum(a * a, axis=1)

    ts, out = [], []
    for x in raw:
        xn, m, k = normalise(x)
        t = time.perf_counter()
        r = least_squares(resid, np.r_[1, 1, 1, 0, 0, 0, 0, 0, 0.0], args=(xn,), method="lm")
        ts.append(time.perf_counter() - t)
        p = r.x * k
        p[6:] += m
        out.append(p)
    return statistics.median(ts), np.stack(out)


def optx_vmapped(raw: np.ndarray, repeats: int) -> tuple[float, float, np.ndarray]:
    import optimistix as optx

    xs = [normalise(x) for x in raw]
    xn = jnp.asarray(np.stack([x[0] for x in xs]))

    def one(x):
        sol = optx.least_squares(
            lambda p, x: normalized_sphere_residual(p, x, 1.0),
            optx.LevenbergMarquardt(rtol=1e-12, atol=1e-14),
            jnp.array([1, 1, 1, 0, 0, 0, 0, 0, 0.0]),
            x,
            max_steps=256,
            throw=False,
        )
        return sol.value

    f = jax.jit(jax.vmap(one))
    first, warm = timed(lambda: f(xn), repeats)
    p = np.array(f(xn))
    for i, (_, m, k) in enumerate(xs):
        p[i] *= k
        p[i, 6:] += m
    return first, warm, p


def rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def stream(total: int, chunk: int, shard: bool) -> dict:
    """Calibrate ``total`` sensors in chunks from a generator: memory stays at one chunk."""
    before = rss_mb()
    t = time.perf_counter()
    done, fails = 0, 0
    for seed in range(-(-total // chunk)):
        n = min(chunk, total - done)
        raw, _ = simulate(n, seed=10_000 + seed)
        r = calibrate_accel_batch(raw, shard=shard)
        fails += int(np.sum(~r.success))
        done += n
        del raw
    elapsed = time.perf_counter() - t
    return {
        "sensors": total,
        "chunk": chunk,
        "seconds_incl_simulation": elapsed,
        "peak_rss_mb": rss_mb(),
        "rss_before_mb": before,
        "failed": fails,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--sizes", type=int, nargs="*", default=[1, 10, 100, 1000, 10000])
    ap.add_argument("--peer-max", type=int, default=100)
    ap.add_argument("--stream", type=int, default=0, help="sensors to stream in chunks")
    ap.add_argument("--chunk", type=int, default=1000)
    ap.add_argument(
        "--moment-chunk",
        type=int,
        default=None,
        help="sensors per step of the moment pass on this platform (calib_jax.batch.MOMENT_CHUNK)",
    )
    ap.add_argument("--shard", action="store_true", help="shard the batch over local devices")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = ap.parse_args()
    devices = len(jax.devices())
    info = describe()
    if args.moment_chunk is not None:
        MOMENT_CHUNK[info["platform"]] = args.moment_chunk
    info["moment_chunk"] = MOMENT_CHUNK.get(info["platform"], MOMENT_CHUNK["gpu"])
    print(label(info), f"moment pass: {info['moment_chunk']} sensors per step", flush=True)
    rows = []
    for n in args.sizes:
        raw, P = simulate(n)
        rj = jnp.asarray(raw)
        repeats = 5 if n <= 1000 else 2
        first, warm = timed(
            lambda rj=rj: calibrate_accel_batch(rj, shard=args.shard).params, repeats
        )
        r = calibrate_accel_batch(rj, shard=args.shard)
        guard = "not checked (the guard sees no copies on the CPU)"
        if info["platform"] != "cpu":
            try:
                with jax.transfer_guard_device_to_host("disallow"):
                    jax.block_until_ready(calibrate_accel_batch(rj, shard=args.shard))
                guard = "none (transfer guard)"
            except Exception as e:  # a copy found: record it, keep the timings
                guard = f"found: {str(e).splitlines()[0][:200]}"
        z = np.abs(np.asarray(r.params) - P) / np.asarray(r.stderr)
        row = {
            "sensors": n,
            "samples": N_SAMPLES,
            "devices": devices if args.shard else 1,
            "calib_jax_first_s": first,
            "calib_jax_ms_per_sensor": 1e3 * warm / n,
            "calib_jax_converged": int(np.sum(r.success)),
            "max_abs_z_vs_truth": float(np.nanmax(z)),
            "device_to_host_copies_in_fit": guard,
            # the samples read once per fit (float64 x 3 and the bool mask), over the warm time
            "input_gb_per_s": n * N_SAMPLES * (3 * 8 + 1) / warm / 1e9,
        }
        m = min(n, args.peer_max)
        t_sp, p_sp = scipy_loop(raw[:m])
        row["scipy_ms_per_sensor"] = 1e3 * t_sp
        row["scipy_max_rel_diff"] = float(
            np.max(np.abs(p_sp - np.asarray(r.params[:m])) / np.abs(p_sp).max(axis=1)[:, None])
        )
        o_first, o_warm, p_ox = optx_vmapped(raw[:m], 3 if m <= 10 else 1)
        row["optimistix_first_s"] = o_first
        row["optimistix_ms_per_sensor"] = 1e3 * o_warm / m
        row["optimistix_max_rel_diff"] = float(
            np.max(np.abs(p_ox - np.asarray(r.params[:m])) / np.abs(p_ox).max(axis=1)[:, None])
        )
        row["peer_sensors"] = m
        row["speedup_vs_scipy"] = row["scipy_ms_per_sensor"] / row["calib_jax_ms_per_sensor"]
        row["speedup_vs_optimistix"] = (
            row["optimistix_ms_per_sensor"] / row["calib_jax_ms_per_sensor"]
        )
        rows.append(row)
        print(
            f"{n:>6} sensors: calib_jax {row['calib_jax_ms_per_sensor']:.3f} ms/sensor "
            f"(first call {first:.1f} s), scipy {row['scipy_ms_per_sensor']:.2f} ms "
            f"({row['speedup_vs_scipy']:.0f}x), optimistix "
            f"{row['optimistix_ms_per_sensor']:.2f} ms ({row['speedup_vs_optimistix']:.0f}x)",
            flush=True,
        )
        del raw, rj
    result = {"rows": rows, "devices": devices, "shard": args.shard, "machine": info}
    if args.stream and rows:
        print("note: peak RSS is per process; run --stream with --sizes (none) to measure it alone")
    if args.stream:
        result["stream"] = stream(args.stream, args.chunk, args.shard)
        print("stream:", result["stream"])
    lines = [
        f"Batch accelerometer fits, {N_SAMPLES} samples per sensor, "
        f"{'sharded over ' + str(devices) + ' devices' if args.shard else '1 device'} "
        "(medians; peers on at most "
        f"{args.peer_max} sensors, per sensor), {label(info)}:",
        "",
        "| sensors | calib_jax ms/sensor | first call s | SciPy lm ms/sensor | ratio | "
        "optimistix vmap ms/sensor | ratio | max rel diff vs SciPy | input GB/s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['sensors']} | {r['calib_jax_ms_per_sensor']:.3f} | "
            f"{r['calib_jax_first_s']:.1f} | {r['scipy_ms_per_sensor']:.2f} | "
            f"{r['speedup_vs_scipy']:.0f}x | {r['optimistix_ms_per_sensor']:.2f} | "
            f"{r['speedup_vs_optimistix']:.0f}x | {r['scipy_max_rel_diff']:.1e} | "
            f"{r['input_gb_per_s']:.1f} |"
        )
    if args.stream:
        s = result["stream"]
        lines += [
            "",
            f"Streaming {s['sensors']} sensors in chunks of {s['chunk']}: "
            f"{s['seconds_incl_simulation']:.0f} s including simulation, peak RSS "
            f"{s['peak_rss_mb']:.0f} MB, {s['failed']} not converged.",
        ]
    md = "\n".join(lines) + "\n"
    print(md)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tag = ("_sharded" if args.shard else "") + ("" if rows else "_stream") + suffix(info)
    (out / f"batch{tag}.json").write_text(json.dumps(result, indent=2))
    (out / f"batch{tag}.md").write_text(md)
    if not rows:
        print(f"wrote {out / f'batch{tag}.json'} and .md")
        return
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6, 4))
    ax = fig.add_subplot(1, 1, 1)
    ns = [r["sensors"] for r in rows]
    ax.loglog(ns, [r["calib_jax_ms_per_sensor"] for r in rows], "o-", label="calib_jax batch")
    ax.loglog(ns, [r["scipy_ms_per_sensor"] for r in rows], "s--", label="SciPy lm loop")
    ax.loglog(ns, [r["optimistix_ms_per_sensor"] for r in rows], "^--", label="optimistix vmap")
    ax.axhline(0.25, color="0.5", lw=0.8, ls=":", label="target 0.25 ms")
    ax.set_xlabel("sensors in the batch")
    ax.set_ylabel("ms per sensor (warm, median)")
    ax.set_title(f"{N_SAMPLES} samples per sensor, 2-core CPU", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / f"batch{tag}.png", dpi=110)
    print(f"wrote {out / f'batch{tag}.json'}, .md and .png")


if __name__ == "__main__":
    main()
