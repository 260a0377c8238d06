"""The diagnosis's power and false alarms on simulated logs (issue 15).

    .venv/bin/python benchmarks/diagnosis_power.py [--seeds 20] [--parts misalignment timing
        permutation accel mag] [--workers 2] [--out benchmarks/results]

Accelerometer and magnetometer (parts ``accel`` and ``mag``): each catalogue effect alone at
multiples of the noise floor of a clean log of the same kind (the median over the seeds;
0.5, 1, 3, 10, 20x for the accelerometer, 1, 3, 10x for the magnetometer, a diagnosis of
which takes ~5 s), and clean logs (the false-alarm rate), through
:func:`calib_jax.diagnose.diagnose_accel` (60 poses of 1 s at 100 Hz after a 20 s rest, with a
temperature column) or
:func:`calib_jax.diagnose.diagnose_mag` (a 10 s rest and a 30 s tumble at 50 Hz;
``soft_iron`` on a spherical board with a sphere declared, so the clean log has no soft iron;
``hard_iron_drift`` with the full ellipsoid declared). An effect's size is what it changes in
the calibrated norm: the standard deviation of that change over the observations (pose means,
or samples), or for ``outliers`` the largest (a disturbed pose's), over the diagnosis's floor
(:func:`effect_size`). Sample noise white or AR(1) with lag-1 correlation 0.99 (about 1 s, as
long as a pose), 2 or 6 mg (accel), 0.5 or 1.5 % of the field (mag; ``--noise`` picks).

MARG:

for each effect size, two noise levels and two sample correlations, ``--seeds`` simulated
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
the right map), the rate of any other effect accepted (false alarms), the rate of verdicts
'unexplained structure' (on a clean log, a false alarm too: the user is told the model misses
something), and the effect's size in
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

from calib_jax.diagnose import diagnose_accel, diagnose_mag, diagnose_marg  # noqa: E402
from calib_jax.diagnose.loop import BOUNDS, coefficient_bound  # noqa: E402
from calib_jax.rotations import describe_permutation, rotvec_to_dcm  # noqa: E402
from calib_jax.simulate import (  # noqa: E402
    alpha_beta,
    correlated_noise,
    simulate_accel_log,
    simulate_mag_log,
    simulate_marg,
    tumble_quaternions,
)

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


ACCEL_EFFECTS = ("bias_drift", "temperature_bias", "temperature_scale", "scale_nonlinearity")
ACCEL_EFFECTS += ("outliers",)
MAG_EFFECTS = {"hard_iron_drift": "full", "soft_iron": "sphere"}  # effect: declared model
MULTIPLES = {"accel": (0.5, 1.0, 3.0, 10.0, 20.0), "mag": (1.0, 3.0, 10.0)}
SENSOR_NOISE = {"accel": {"low": 2e-3, "high": 6e-3}, "mag": {"low": 5e-3, "high": 1.5e-2}}
MAG_SAMPLES, MAG_REST, MAG_RATE = 2000, 500, 50.0
SOFT_IRON_GAINS = np.array([3.0, -2.0, 1.0])  # a spherical board's gains: 1 + size * these


def simulate_sensor(sensor, effect, size, noise, corr, seed, model="full"):
    """(log, raw, effect_on_norm) of one simulated accelerometer or magnetometer log with
    ``effect`` (None: clean) of ``size``; the sample noise white or AR(1). ``effect_on_norm``:
    what the effect changes in the calibrated norm, per observation (pose means for the
    accelerometer, samples for the magnetometer), without noise."""
    sigma = SENSOR_NOISE[sensor][noise]
    rho = CORRELATION[corr]
    s, clean = _noise_free(sensor, effect, size, seed, model)
    _, without = _noise_free(sensor, effect, 0.0, seed, model)
    alpha, b = alpha_beta(s.params)
    if sensor == "mag" and model == "sphere":
        alpha = np.eye(3)  # the spherical board of _noise_free

    def norm(x):
        return np.linalg.norm((x - b) @ np.linalg.inv(alpha).T, axis=1)

    change = norm(clean) - norm(without)
    if sensor == "accel":
        change = np.array([change[a:z].mean() for a, z in s.intervals])
    rng = np.random.default_rng(seed + 3000)
    raw = clean + (0.0 if rho else sigma) * rng.normal(size=clean.shape)
    if rho:
        raw = raw + correlated_noise(len(raw), sigma, rho, rng=seed + 2000)
    return s, raw, change


def _noise_free(sensor, effect, size, seed, model):
    eff = (effect,) if effect else ()
    if sensor == "accel":
        s = simulate_accel_log(eff, size=size, noise=0.0, seed=seed)
        return s, s.raw
    sphere = model == "sphere"
    kw = dict(samples=MAG_SAMPLES, rest=MAG_REST, rate=MAG_RATE, seed=seed)
    s = simulate_mag_log(() if sphere else eff, size=size, noise=0.0, **kw)
    raw = s.raw
    if sphere:  # the board's ellipsoid replaced by a sphere (+ the soft iron asked for)
        alpha, b = alpha_beta(s.params)
        v = (raw - b) @ np.linalg.inv(alpha).T
        gains = 1.0 + (size * SOFT_IRON_GAINS if effect else 0.0)
        raw = v * gains + b
    return s, raw


def effect_size(effect, change) -> float:
    """The effect's size, relative to g or the field: the standard deviation over observations
    of its change of the norm (the mean removed: a gain absorbs it); for ``outliers`` the
    largest change (a disturbed pose's)."""
    if effect == "outliers":
        return float(np.max(np.abs(change)))
    return float(np.std(change))


def beyond_bound(row) -> float | None:
    """The simulated effect's largest coefficient over the diagnosis's plausibility bound
    for it (:data:`calib_jax.diagnose.loop.BOUNDS`), for the accelerometer and magnetometer
    rows with a bounded coefficient, else None. The simulator's coefficients are ``size``
    times a vector whose largest entry is 1 (:mod:`calib_jax.simulate`), so the largest is
    ``size``. Above 1 the diagnosis is right to refuse the effect as larger than a sensor's
    own can be (its note names the effect and points outside the sensor): such a row's
    detection rate of 0 is the plausibility test working, not a miss."""
    if row["part"] not in ("accel", "mag") or row["effect"] in ("soft_iron", "outliers"):
        return None
    if not row["size"]:
        return None
    return row["size"] / coefficient_bound(row["effect"], BOUNDS[row["part"]])


def diagnose_sensor(sensor, effect, s, raw, seed, model="full"):
    if sensor == "accel":
        kw = dict(t=s.t, temp=s.temp, intervals=s.intervals)
        return diagnose_accel(raw, seed=seed, progress=False, **kw)
    kw = dict(t=s.t, temp=s.temp, sample_rate=s.sample_rate, model=model)
    return diagnose_mag(raw, seed=seed, progress=False, **kw)


def sensor_points(sensor, noise, corr, seeds, multiples=None):
    """Rows for one sensor, noise and correlation: the clean logs (the false-alarm rate, and
    the floor that sets the sizes) and every effect at every multiple of that floor, the
    effect's size being :func:`effect_size` (scaled from a unit-size log of seed 0)."""
    effects = ACCEL_EFFECTS if sensor == "accel" else tuple(MAG_EFFECTS)
    multiples = multiples or MULTIPLES[sensor]
    models = ("full",) if sensor == "accel" else tuple(sorted(set(MAG_EFFECTS.values())))
    floors = {}
    for model in models:
        found, unexplained, fl = 0, 0, []
        for seed in range(seeds):
            s, raw, _ = simulate_sensor(sensor, None, 0.0, noise, corr, seed, model)
            d = diagnose_sensor(sensor, None, s, raw, seed, model)
            found += bool(d.effects)
            unexplained += d.verdict == "unexplained_structure"
            fl.append(d.noise_floor)
        floors[model] = float(np.nanmedian(fl))
        yield {
            "part": sensor,
            "effect": f"clean ({model})" if sensor == "mag" else "clean",
            "size": 0.0,
            "noise": noise,
            "correlation": corr,
            "seeds": seeds,
            "detection_rate": 0.0,
            "other_effects_rate": found / seeds,
            "unexplained_rate": unexplained / seeds,
            "size_over_floor": 0.0,
            "floor": floors[model],
        }
    for effect in effects:
        model = MAG_EFFECTS.get(effect, "full")
        unit = 1e-3
        per_unit = effect_size(
            effect, simulate_sensor(sensor, effect, unit, noise, corr, 0, model)[2]
        )
        for k in multiples:
            size = k * floors[model] / per_unit * unit
            hits = others = unexplained = 0
            ratio = []
            for seed in range(seeds):
                s, raw, change = simulate_sensor(sensor, effect, size, noise, corr, seed, model)
                d = diagnose_sensor(sensor, effect, s, raw, seed, model)
                hits += effect in d.effects
                others += bool(set(d.effects) - {effect})
                unexplained += d.verdict == "unexplained_structure"
                if math.isfinite(d.noise_floor) and d.noise_floor > 0:
                    ratio.append(effect_size(effect, change) / d.noise_floor)
            yield {
                "part": sensor,
                "effect": effect,
                "size": size,
                "multiple": k,
                "noise": noise,
                "correlation": corr,
                "seeds": seeds,
                "detection_rate": hits / seeds,
                "other_effects_rate": others / seeds,
                "unexplained_rate": unexplained / seeds,
                "size_over_floor": float(np.median(ratio)) if ratio else None,
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
    hits = others = unexplained = 0
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
        unexplained += d.verdict == "unexplained_structure"
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
        "unexplained_rate": unexplained / seeds,
        "size_over_floor": float(np.median(ratio)) if ratio else None,
    }


def groups(parts, noises=tuple(NOISE)) -> list[tuple[str, str, str]]:
    """(part, noise, correlation) of every group of rows, in the table's order: a group's
    clean logs set the sizes of its effects, so it runs whole, in one process."""
    return [(part, noise, corr) for part in parts for noise in noises for corr in CORRELATION]


def run_group(part, noise, corr, seeds) -> list[dict]:
    if part in ("accel", "mag"):
        return list(sensor_points(part, noise, corr, seeds))
    if part == "permutation":
        rows = []
        for name, P in MAPS.items():
            rows.append(run_point(part, 5.0, noise, corr, seeds, P=P) | {"map": name})
        return rows
    sizes = [0.0, 0.5, 1.0, 2.0, 5.0, 10.0] if part == "misalignment" else [0, 1, 2, 5, 10]
    return [run_point(part, size, noise, corr, seeds) for size in sizes]


def markdown(rows, meta) -> str:
    out = [
        "# The diagnosis: detection and false alarms on simulated logs",
        "",
        *[
            f"- `{m['command']}`: {m['seeds']} seeds per row; {m['seconds']:.0f} s on "
            f"{m['machine']} (load {m['load']}); the rows of parts {', '.join(m['parts'])}."
            for m in meta["runs"]
        ],
        "",
        "| part | size | noise | samples | size / floor | coefficient / bound | detected | "
        "other effects | unexplained structure |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        size = r.get("map") or (
            f"{r['size']:g} deg" if r["part"] == "misalignment" else f"{r['size']:g} samples"
        )
        if r["part"] in ("accel", "mag"):
            size = r["effect"] + (f", {r['multiple']:g}x floor" if r["size"] else "")
        sof = "-" if r["size_over_floor"] is None else f"{r['size_over_floor']:.2g}"
        det = "-" if r["part"] != "permutation" and r["size"] == 0 else f"{r['detection_rate']:.0%}"
        over = beyond_bound(r)
        bound = "-" if over is None else f"{over:.2g}" + (" (refused)" if over > 1 else "")
        out.append(
            f"| {r['part']} | {size} | {r['noise']} | {r['correlation']} | {sof} | {bound} | "
            f"{det} | "
            f"{r['other_effects_rate']:.0%} | "
            + (f"{r['unexplained_rate']:.0%} |" if "unexplained_rate" in r else "- |")
        )
    return "\n".join(out + ["", *target_lines(rows)]) + "\n"


def target_lines(rows) -> list[str]:
    """Issue 15's targets against the rows: detection at about 3x the floor (the rows whose
    size is 2-5x; those beyond a plausibility bound apart), false alarms on clean logs (any
    effect, or the verdict 'unexplained structure'), and the maps named."""
    sized = [r for r in rows if r["part"] != "permutation" and r["size"]]
    near3 = [r for r in sized if r.get("size_over_floor") and 2 <= r["size_over_floor"] <= 5]
    refused = [r for r in sized if (beyond_bound(r) or 0) > 1]
    clean = [r for r in rows if r["part"] != "permutation" and not r["size"]]
    perms = [r for r in rows if r["part"] == "permutation"]

    def share(rs, ok):
        return f"{sum(ok(r) for r in rs)} of {len(rs)}"

    missed = sorted(
        {f"{r['part']} {r.get('effect') or ''} {r['correlation']}".replace("  ", " ")
         for r in near3 if r["detection_rate"] < 0.95}
    )  # fmt: skip
    detected = share(near3, lambda r: r["detection_rate"] >= 0.95)
    quiet = share(clean, lambda r: r["other_effects_rate"] <= 0.05)
    no_structure = share(clean, lambda r: r.get("unexplained_rate", 0) <= 0.05)
    named = share(perms, lambda r: r["detection_rate"] == 1)
    return [
        "Targets (issue 15), counted over the rows above:",
        "",
        f"- detection >= 95 % at 2-5x the floor: {detected} rows (those that miss: "
        f"{', '.join(missed) or 'none'});",
        f"- clean logs with no effect accepted in >= 95 %: {quiet} rows; with no 'unexplained "
        f"structure' in >= 95 %: {no_structure};",
        f"- every axis map named (5 deg beside it): {named} rows;",
        "- rows whose simulated coefficient is beyond the diagnosis's plausibility bound "
        f"(`calib_jax.diagnose.loop.BOUNDS`, column 'coefficient / bound' > 1): {len(refused)}, "
        f"detected in {share(refused, lambda r: r['detection_rate'] > 0)} (refusing them is the "
        "bound working: the note names the effect and points to causes outside the sensor).",
    ]


def figure(rows, path: Path) -> None:
    from matplotlib.figure import Figure

    panels = [(p, None) for p in ("misalignment", "timing") if any(r["part"] == p for r in rows)]
    panels += [
        (p, c) for p in ("accel", "mag") for c in CORRELATION if any(r["part"] == p for r in rows)
    ]
    cols = min(len(panels), 3) or 1
    fig = Figure(figsize=(5 * cols, 3.8 * math.ceil(len(panels) / cols)))
    for k, (part, corr_only) in enumerate(panels):
        ax = fig.add_subplot(math.ceil(len(panels) / cols), cols, k + 1)
        lines = []
        for noise in NOISE:
            for corr in CORRELATION:
                if corr_only and corr != corr_only:
                    continue
                effects = sorted({r.get("effect") for r in rows if r["part"] == part})
                for effect in effects:
                    pts = [
                        r
                        for r in rows
                        if r["part"] == part and r["noise"] == noise and r["correlation"] == corr
                        and r.get("effect") == effect and r["size"] > 0
                        and r["size_over_floor"] is not None
                    ]  # fmt: skip
                    if not pts:
                        continue
                    name = f"{effect}, {noise}" if effect else f"{noise} noise, {corr}"
                    style = "o-" if noise == "low" else "s--"
                    x = [r["size_over_floor"] for r in pts]
                    lines.append(ax.plot(x, [100 * r["detection_rate"] for r in pts], style,
                                         label=name, ms=4))  # fmt: skip
        ax.axvline(3, color="0.5", lw=0.8)
        ax.axhline(95, color="0.5", lw=0.8, ls="--")
        ax.set_xscale("log")
        ax.set_xlabel("effect size / noise floor")
        ax.set_ylabel("detected (%)")
        ax.set_title(part + (f" ({corr_only} samples)" if corr_only else ""), fontsize=10)
        ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def _load() -> str:
    """The machine's 1-minute load average ('?' where /proc/loadavg is not)."""
    f = Path("/proc/loadavg")
    return f.read_text().split()[0] if f.exists() else "?"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--parts", nargs="+", default=["misalignment", "timing", "permutation"])
    ap.add_argument("--noise", nargs="+", default=list(NOISE), choices=list(NOISE))
    ap.add_argument("--out", default=str(Path(__file__).parent / "results"))
    ap.add_argument("--workers", type=int, default=1, help="processes, each a whole group")
    ap.add_argument(
        "--redraw", action="store_true", help="rewrite the table and figure from the JSON only"
    )
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.redraw:
        saved = json.loads((out / "diagnosis_power.json").read_text())
        (out / "diagnosis_power.md").write_text(markdown(saved["rows"], saved))
        figure(saved["rows"], out / "diagnosis_power.png")
        return
    t0 = time.perf_counter()
    load = _load()
    todo = groups(args.parts, tuple(args.noise))
    rows = []
    if args.workers > 1:  # whole groups in worker processes (each compiles its own fits)
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(args.workers, mp_context=ctx) as pool:
            jobs = [pool.submit(run_group, *g, args.seeds) for g in todo]
            for job in jobs:  # in the table's order, each as its group ends
                for row in job.result():
                    rows.append(row)
                    print(json.dumps(row), flush=True)
    else:
        for g in todo:
            for row in run_group(*g, args.seeds):
                rows.append(row)
                print(json.dumps(row), flush=True)
    run = {
        "command": "benchmarks/diagnosis_power.py --seeds "
        f"{args.seeds} --parts {' '.join(args.parts)} --noise {' '.join(args.noise)}"
        + (f" --workers {args.workers}" if args.workers > 1 else ""),
        "parts": args.parts,
        "seeds": args.seeds,
        "seconds": time.perf_counter() - t0,
        "machine": f"{platform.machine()}, {jax.devices()[0].device_kind}",
        "load": f"{load} at the start, {_load()} at the end",  # the 1-minute averages
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
        runs = [  # an earlier run stays listed for the parts whose rows are still its own
            m | {"parts": [q for q in m["parts"] if q not in args.parts]}
            for m in earlier
            if set(m["parts"]) - set(args.parts)
        ] + runs
    meta = {"runs": runs}
    (out / "diagnosis_power.json").write_text(json.dumps(meta | {"rows": rows}, indent=1))
    (out / "diagnosis_power.md").write_text(markdown(rows, meta))
    figure(rows, out / "diagnosis_power.png")
    print(markdown(rows, meta))


if __name__ == "__main__":
    main()
