"""Paper 2's evaluation, reproduced: Table 1 / Fig. 9 on simulation, and the Gauss-Newton
attitude against BROAD's optical ground truth.

    .venv/bin/python benchmarks/marg_eval.py [--shared ../shared/data] [--out benchmarks/results]

Writes marg_eval.json and marg_eval.md. Accuracy, not speed: every number is an error against
known truth (simulation) or an independent reference (optical tracking).

BROAD part (needs h5py and the shared data):
- trials 02 and 05 (undisturbed, manufacturer-calibrated): attitude from the data as shipped,
  and after our ellipsoid recalibration fitted on trial 02 (so trial 05 is held out);
- trial 34 (magnet attached 40-100 s): the ellipsoid fitted on alternate 5 s blocks of the
  magnet segment, judged on the other blocks, for each model.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import calib_jax as cj  # noqa: E402
from calib_jax.marg import evaluation_table  # noqa: E402
from calib_jax.rotations import heading_inclination_error_deg  # noqa: E402
from calib_jax.simulate import (  # noqa: E402
    plane_turn_quaternions,
    random_ellipsoid,
    random_rotation,
    simulate_marg,
    tumble_quaternions,
)

herr = jax.jit(jax.vmap(heading_inclination_error_deg))


def errors(q_est, q_ref) -> dict:
    ok = np.all(np.isfinite(q_ref), axis=1)
    e = np.asarray(herr(jnp.asarray(q_est)[ok], jnp.asarray(q_ref[ok])))
    return {
        "heading_median_deg": float(np.median(e[:, 0])),
        "heading_rms_deg": float(np.sqrt(np.mean(e[:, 0] ** 2))),
        "inclination_median_deg": float(np.median(e[:, 1])),
        "inclination_rms_deg": float(np.sqrt(np.mean(e[:, 1] ** 2))),
        "n": int(ok.sum()),
    }


def simulation(seeds: int) -> dict:
    rows = {}
    for s in range(seeds):
        c, W = random_ellipsoid(10 * s + 1, radius=45.0, center_spread=0.8)
        ca, Wa = random_ellipsoid(10 * s + 5, radius=1.0, axis_spread=0.05, center_spread=0.05)
        kw = dict(
            center=c,
            soft_iron=W,
            R_acc_board=random_rotation(10 * s + 2, 3),
            R_mag_board=random_rotation(10 * s + 3, 5),
            acc_center=ca,
            acc_soft_iron=Wa,
        )
        tum = simulate_marg(tumble_quaternions(3000, 10 * s + 4), rng=10 * s + 1, **kw)
        level = simulate_marg(plane_turn_quaternions(1500, incline_deg=0.0), rng=s + 2, **kw)
        turn = simulate_marg(
            plane_turn_quaternions(1500, incline_deg=25.0, incline_azimuth_deg=70),
            rng=s + 3,
            **kw,
        )
        cal = cj.calibrate_marg(tum.acc, tum.mag, level.acc, level.mag)
        a, m = turn.acc, turn.mag
        ev = cj.evaluate_turn(
            {
                "raw": (a, m),
                "compensated": cal.compensate(a, m),
                "aligned-compensated (paper 2)": cal.plane_aligned(a, m),
                "compensated + accel-mag rotation": cal.rotation_aligned(a, m),
                "rotation + accelerometer plane": cal.aligned(a, m),
            }
        )
        if s == 0:
            print("simulation, seed 0 (paper 2 Table 1 / Fig. 9):")
            print(evaluation_table(ev))
        for k, e in ev.items():
            rows.setdefault(k, []).append(
                [e.mean_cost, e.roll_rms_deg, e.pitch_rms_deg, e.roll_max_deg, e.pitch_max_deg]
            )
    out = {}
    for k, v in rows.items():
        v = np.array(v)
        out[k] = {
            "mean_cost_median": float(np.median(v[:, 0])),
            "roll_rms_deg_median": float(np.median(v[:, 1])),
            "pitch_rms_deg_median": float(np.median(v[:, 2])),
            "roll_max_deg_median": float(np.median(v[:, 3])),
            "pitch_max_deg_median": float(np.median(v[:, 4])),
        }
    return out


def broad(shared: Path) -> dict:
    from calib_jax.io.broad import load_broad

    d = shared / "broad_myon"
    t2 = load_broad(d / "02_undisturbed_slow_rotation_B.hdf5")
    t5 = load_broad(d / "05_undisturbed_slow_rotation_with_breaks_B.hdf5")
    t34 = load_broad(d / "34_disturbed_attached_magnet_3cm.hdf5")
    res: dict = {}
    cal = cj.calibrate_mag(t2.mag, field=44.3)
    rot = cj.align_mag_to_accel(t2.acc, cal.apply(t2.mag))
    res["fit_on_02"] = {
        "model": cal.model,
        "center_uT": cal.center.tolist(),
        "rms_raw_pct": cal.rms_raw_pct,
        "rms_after_pct": cal.rms_after_pct,
        "accel_mag_rotation_deg": rot.rotation_deg,
        "dip_deg": rot.dip_deg,
        "angle_spread_before_deg": rot.spread_before_deg,
        "angle_spread_after_deg": rot.spread_after_deg,
    }
    for name, tr in (("02 (fit data)", t2), ("05 (held out)", t5)):
        versions = {
            "as shipped": tr.mag,
            "ellipsoid": cal.apply(tr.mag),
            "ellipsoid + rotation": rot.apply(cal.apply(tr.mag)),
        }
        res[name] = {
            k: errors(cj.estimate_attitude(tr.acc, m).quat, tr.quat) for k, m in versions.items()
        }
    dip = float(cj.estimate_attitude(t34.segment(0, 38).acc, t34.segment(0, 38).mag).dip_deg)
    seg = t34.segment(40, 100)
    blk = (np.arange(len(seg.acc)) // int(5 * seg.sample_rate)) % 2 == 0
    test = ~blk
    r34 = {"dip_deg_undisturbed": dip}
    r34["as shipped"] = errors(
        cj.estimate_attitude(seg.acc[test], seg.mag[test], dip_deg=dip).quat, seg.quat[test]
    )
    for model in ("sphere", "diag", "full", "auto"):
        c = cj.calibrate_mag(seg.mag[blk], model=model, field=44.3)
        e = errors(
            cj.estimate_attitude(seg.acc[test], c.apply(seg.mag[test]), dip_deg=dip).quat,
            seg.quat[test],
        )
        e.update(status=c.status, chosen=c.model, rms_after_pct=c.rms_after_pct)
        r34[f"ellipsoid {model}"] = e
    res["34 magnet, held-out blocks"] = r34
    return res


def markdown(sim: dict, br: dict | None) -> str:
    lines = [
        "# Paper 2's evaluation and BROAD attitude",
        "",
        "Simulation (medians over seeds): a turn about z on a 25 deg inclined plane, reference",
        "vectors from the first samples, so roll and pitch should stay 0.",
        "",
        "| data | mean F(x) | roll RMS (deg) | pitch RMS (deg) | roll max | pitch max |",
        "|---|---|---|---|---|---|",
    ]
    for k, v in sim.items():
        lines.append(
            f"| {k} | {v['mean_cost_median']:.2e} | {v['roll_rms_deg_median']:.3f} | "
            f"{v['pitch_rms_deg_median']:.3f} | {v['roll_max_deg_median']:.2f} | "
            f"{v['pitch_max_deg_median']:.2f} |"
        )
    if br:
        lines += [
            "",
            "BROAD (Gauss-Newton attitude against optical truth, degrees):",
            "",
            "| trial | magnetometer | heading median | heading RMS | inclination median |",
            "|---|---|---|---|---|",
        ]
        for trial, rows in br.items():
            if trial == "fit_on_02":
                continue
            for k, e in rows.items():
                if not isinstance(e, dict):
                    continue
                lines.append(
                    f"| {trial} | {k} | {e['heading_median_deg']:.2f} | "
                    f"{e['heading_rms_deg']:.2f} | {e['inclination_median_deg']:.2f} |"
                )
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    here = Path(__file__).resolve().parent
    ap.add_argument("--shared", default=str(here.parents[1] / "shared" / "data"))
    ap.add_argument("--out", default=str(here / "results"))
    ap.add_argument("--seeds", type=int, default=5)
    args = ap.parse_args()
    sim = simulation(args.seeds)
    br = None
    shared = Path(args.shared)
    if (shared / "broad_myon").exists():
        br = broad(shared)
    else:
        print(f"no BROAD data under {shared}; simulation only")
    md = markdown(sim, br)
    print(md)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "marg_eval.json").write_text(json.dumps({"simulation": sim, "broad": br}, indent=2))
    (out / "marg_eval.md").write_text(md)
    print(f"wrote {out / 'marg_eval.json'} and {out / 'marg_eval.md'}")


if __name__ == "__main__":
    main()
