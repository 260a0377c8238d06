"""Command line: ``calib-jax accel FILE``, ``calib-jax mag FILE``, ``calib-jax record`` and
``calib-jax demo``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .datasets import demo_log_path


def _enable_x64() -> None:
    import jax

    jax.config.update("jax_enable_x64", True)


def _json_out(cal, path: str | None) -> None:
    if path:
        cal.save(path)
        print(f"wrote {path}")


def run_accel(args: argparse.Namespace) -> int:
    _enable_x64()
    from .accel import calibrate_accel
    from .io import load_log

    # calibrate_accel raises ValueError (exit 2 in main) when the log has no accelerometer
    log = load_log(args.file, columns=args.columns, sample_rate=args.sample_rate)
    cal = calibrate_accel(
        log,
        g=args.g,
        units=args.units,
        output_units=args.out_units,
        solver=args.solver,
        model=args.model,
        use=args.use,
        window=args.window,
        threshold_factor=args.threshold_factor,
        min_duration=args.min_static if log.sample_rate else None,
        min_samples=None if log.sample_rate or args.min_static is None else int(args.min_static),
        solver_options={"jacobian": "broyden"} if args.broyden else None,
        sensor_id=args.sensor_id,
    )
    print(f"calib-jax accel: {args.file}")
    print(cal.report())
    _json_out(cal, args.json)
    _plot(cal, args.plot)
    return 0 if cal.success else 1


def run_mag(args: argparse.Namespace) -> int:
    _enable_x64()
    from .io import load_log
    from .mag import calibrate_mag

    log = load_log(args.file, columns=args.columns, sample_rate=args.sample_rate)
    cal = calibrate_mag(
        log,
        model=args.model,
        field=args.field,
        units=args.units,
        sensor=args.sensor,
        solver=args.solver,
        sensor_id=args.sensor_id,
    )
    print(f"calib-jax mag: {args.file}")
    print(cal.report())
    _json_out(cal, args.json)
    if args.plot:
        from .plots import plot_mag

        plot_mag(cal, log.mag if args.sensor == "mag" else log.acc, args.plot)
        print(f"wrote {args.plot}")
    return 0 if cal.success else 1


def run_batch(args: argparse.Namespace) -> int:
    _enable_x64()
    import json

    from .fleet import calibrate_files, calibrate_files_dask

    root = Path(args.dir)
    if not root.is_dir():
        raise ValueError(f"{root} is not a directory")
    paths = sorted(str(p) for p in root.rglob(args.pattern) if p.is_file())
    if not paths:
        raise ValueError(f"no files matching {args.pattern!r} under {root}; set --pattern")
    options = {}
    if args.sensor == "accel":
        options.update(g=args.g, model=args.model or "accel9")
    else:
        options.update(field=args.field, model=args.model or "full")
    print(f"calib-jax batch: {len(paths)} files under {root}, sensor {args.sensor}")
    if args.dask is not None:
        results = calibrate_files_dask(
            paths,
            scheduler=args.dask or None,
            n_workers=args.workers,
            sensor=args.sensor,
            chunk=args.chunk,
            columns=args.columns,
            **options,
        )
    else:
        results = calibrate_files(
            paths, sensor=args.sensor, chunk=args.chunk, columns=args.columns, **options
        )
    out = open(args.json, "w") if args.json else None  # noqa: SIM115
    n_ok = n_all = 0
    try:
        if out:
            head = json.dumps({"format_version": 1, "sensor": args.sensor})[:-1]
            out.write(head + ', "results": [\n')
        for r in results:
            # written as they arrive: a crash keeps what was calibrated so far
            if out:
                out.write(("" if n_all == 0 else ",\n") + json.dumps(r))
                out.flush()
            n_all += 1
            n_ok += r["status"] == "ok"
        if out:
            out.write("\n]}\n")
    finally:
        if out:
            out.close()
    print(f"{n_ok} of {n_all} calibrated" + (f"; wrote {args.json}" if args.json else ""))
    return 0 if n_ok == n_all else 1


def _plot(cal, path: str | None) -> None:
    if path:
        from .plots import plot_accel

        plot_accel(cal, path)
        print(f"wrote {path}")


def run_demo(args: argparse.Namespace) -> int:
    _enable_x64()
    from .accel import calibrate_accel
    from .io import load_log

    path = demo_log_path()
    print(
        "calib-jax demo: imu_tk Xsens log (Tedaldi, Pretto, Menegatti, ICRA 2014; BSD; see "
        f"{path.parent / 'NOTES.md'})\nraw 16-bit counts, 100 Hz, reference g = 9.81744 m/s^2 "
        "(imu_tk's value)\n"
    )
    log = load_log(path)
    cal = calibrate_accel(log, g=9.81744, output_units="m/s^2", solver=args.solver)
    print(cal.report())
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    _json_out(cal, str(out / "demo_calibration.json"))
    _plot(cal, str(out / "demo_accel.png"))

    from .align import align_mag_to_accel
    from .datasets import mag_demo_log_path
    from .mag import calibrate_mag
    from .plots import plot_mag

    mpath = mag_demo_log_path()
    print(
        "\ncalib-jax demo, magnetometer (paper 2): CK-Explorer accelerometer + magnetometer "
        f"tumble (Apache-2.0; see {mpath.parent / 'NOTES.md'})\n"
    )
    mlog = load_log(mpath)
    mcal = calibrate_mag(mlog, solver=args.solver)
    print(mcal.report())
    al = align_mag_to_accel(mlog.acc, mcal.apply(mlog.mag))
    print(
        f"\naccel-mag alignment on {al.n_used} of {al.n_total} samples (|a|, |m| within 5 % of "
        f"their medians): axes {al.permutation_text}; rotation {al.rotation_deg:.2f} deg; dip "
        f"{al.dip_deg:.2f} +- {al.dip_stderr_deg:.2f} deg; spread of the gravity-field angle "
        f"{al.spread_before_deg:.2f} -> {al.spread_after_deg:.2f} deg; {al.message}"
    )
    _json_out(mcal, str(out / "demo_mag.json"))
    plot_mag(mcal, mlog.mag, str(out / "demo_mag.png"))
    print(f"wrote {out / 'demo_mag.png'}")
    return 0 if cal.success and mcal.success else 1


def run_record(args: argparse.Namespace) -> int:
    _enable_x64()
    from .record import run

    return run(args)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="calib-jax", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)

    a = sub.add_parser("accel", help="calibrate an accelerometer from a multi-position log")
    a.add_argument("file")
    a.add_argument("--g", type=float, default=None, help="reference magnitude in output units")
    a.add_argument("--units", default="auto", help="input units: auto, counts, g, m/s^2")
    a.add_argument("--out-units", default=None, help="label of the calibrated output (with --g)")
    a.add_argument("--solver", default="lm1", choices=["lm1", "lm2", "lm3", "optimistix"])
    a.add_argument("--model", default="accel9", choices=["accel9", "accel6"])
    a.add_argument("--use", default="means", choices=["means", "samples"])
    a.add_argument("--broyden", action="store_true", help="finite differences + Broyden (paper 1)")
    a.add_argument("--columns", default=None, help="e.g. t,ax,ay,az or ax=AccX,ay=AccY,az=AccZ")
    a.add_argument("--sample-rate", type=float, default=None, help="Hz, if the log has no time")
    a.add_argument("--window", type=int, default=None, help="moving-variance window (samples)")
    a.add_argument("--threshold-factor", type=float, default=6.0)
    a.add_argument(
        "--min-static",
        type=float,
        default=None,
        help="shortest pose (s, or samples without a rate)",
    )
    a.add_argument("--sensor-id", default=None)
    a.add_argument("--json", default=None, help="write the calibration JSON here")
    a.add_argument("--plot", default=None, help="write a PNG figure here")
    a.set_defaults(func=run_accel)

    m = sub.add_parser(
        "mag", help="ellipsoid (hard/soft iron) calibration from a free-rotation log (paper 2)"
    )
    m.add_argument("file")
    m.add_argument(
        "--model",
        default="auto",
        choices=["sphere", "diag", "full", "auto"],
        help="hard iron only, axis-aligned ellipsoid, full ellipsoid, or the lowest BIC",
    )
    m.add_argument(
        "--field", type=float, default=None, help="known field magnitude (sets the output scale)"
    )
    m.add_argument("--units", default=None, help="label of the raw units (report only)")
    m.add_argument("--sensor", default="mag", choices=["mag", "accel"], help="which columns to fit")
    m.add_argument("--solver", default="lm1", choices=["lm1", "lm2", "lm3", "optimistix"])
    m.add_argument("--columns", default=None, help="e.g. mx,my,mz or mx=MagX,my=MagY,mz=MagZ")
    m.add_argument("--sample-rate", type=float, default=None, help="Hz, if the log has no time")
    m.add_argument("--sensor-id", default=None)
    m.add_argument("--json", default=None, help="write the calibration JSON here")
    m.add_argument("--plot", default=None, help="write a PNG figure here")
    m.set_defaults(func=run_mag)

    b = sub.add_parser(
        "batch", help="calibrate every log under a directory, in chunks (or on a Dask cluster)"
    )
    b.add_argument("dir")
    b.add_argument("--pattern", default="*.csv", help="file glob, searched recursively")
    b.add_argument("--sensor", default="accel", choices=["accel", "mag"])
    b.add_argument("--model", default=None, help="accel9|accel6 or sphere|diag|full")
    b.add_argument("--g", type=float, default=1.0, help="accelerometer reference magnitude")
    b.add_argument("--field", type=float, default=None, help="magnetometer field magnitude")
    b.add_argument("--columns", default=None, help="column mapping for every file")
    b.add_argument("--chunk", type=int, default=256, help="files per batch fit")
    b.add_argument(
        "--dask",
        nargs="?",
        const="",
        default=None,
        help="spread chunks over Dask: a scheduler address, or none for a local cluster",
    )
    b.add_argument("--workers", type=int, default=2, help="local Dask workers")
    b.add_argument("--json", default=None, help="write all results here (streamed)")
    b.set_defaults(func=run_batch)

    d = sub.add_parser(
        "demo", help="calibrate the accelerometer and magnetometer logs shipped with the package"
    )
    d.add_argument("--out", default="calib_jax_demo", help="folder for the JSON and the figure")
    d.add_argument("--solver", default="lm1", choices=["lm1", "lm2", "lm3", "optimistix"])
    d.set_defaults(func=run_demo)

    r = sub.add_parser(
        "record",
        help="record from serial ports with live coverage feedback, then calibrate",
        description="Record line records from one or more serial ports (any pyserial URL) "
        "into append-only CSV logs, showing the static poses and sphere coverage found so far; "
        "stop at --seconds, when coverage is enough, when the devices go away, or on Ctrl-C; "
        "then calibrate (one port: the full report; several: one batch fit) and write the "
        "JSON beside each log.",
    )
    r.add_argument(
        "--port",
        action="append",
        required=True,
        help="device path or pyserial URL (/dev/ttyACM0, socket://host:port); repeat for more",
    )
    r.add_argument("--baud", type=int, default=115200)
    r.add_argument(
        "--columns",
        default=None,
        help="field order, e.g. t,ax,ay,az,mx,my,mz ('_' skips); default: the device's header",
    )
    r.add_argument(
        "--scale", default=None, help="raw to units: one number, or a=0.000061,m=0.15,t=0.001"
    )
    r.add_argument(
        "--delimiter", default="auto", choices=["auto", "comma", "tab", "semicolon", "space"]
    )
    r.add_argument("--out", required=True, help="log file (several ports: FILE.devK.csv)")
    r.add_argument("--sensor", default="accel", choices=["accel", "mag", "marg"])
    r.add_argument("--seconds", type=float, default=None, help="stop after this long")
    r.add_argument("--resume", action="store_true", help="append to an existing log")
    r.add_argument("--overwrite", action="store_true", help="replace an existing log")
    r.add_argument("--no-auto-stop", action="store_true", help="keep going once covered")
    r.add_argument("--target-poses", type=int, default=48, help="distinct poses (paper 1: 48)")
    r.add_argument(
        "--max-reconnect",
        type=float,
        default=30.0,
        help="seconds to keep reconnecting an unplugged device before it counts as gone",
    )
    r.add_argument("--g", type=float, default=None, help="accelerometer reference magnitude")
    r.add_argument("--field", type=float, default=None, help="known field magnitude (mag)")
    r.add_argument("--window", type=int, default=None, help="moving-variance window (samples)")
    r.add_argument("--min-static", type=float, default=None, help="shortest pose (s)")
    r.add_argument("--solver", default="lm1", choices=["lm1", "lm2", "lm3", "optimistix"])
    r.set_defaults(func=run_record)

    from .diagnose.cli import add_parser as add_diagnose

    add_diagnose(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
