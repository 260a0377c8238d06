"""``calib-jax diagnose FILE --sensor accel|mag [--json OUT] [--report DIR]``."""

from __future__ import annotations

import argparse
import json
import sys


def add_parser(sub) -> None:
    p = sub.add_parser(
        "diagnose",
        help="trace the residual of a calibration to effects its model lacks",
        description="Fit the declared model, measure the noise floors, add catalogue effects "
        "(bias drift, temperature, scale nonlinearity, outliers, hard-iron drift, soft iron; "
        "for MARG the accel-mag misalignment and timing offset) "
        "only where every acceptance test passes, and report the error before and after.",
    )
    p.add_argument("file", help="log file (CSV/TSV/text/.mat)")
    p.add_argument("--sensor", choices=("accel", "mag", "marg"), default="accel")
    p.add_argument("--columns", help="column mapping for headerless files, e.g. t,ax,ay,az")
    p.add_argument("--sample-rate", type=float, help="Hz, when the log has no time column")
    p.add_argument(
        "--block",
        type=int,
        help="accel: observations are consecutive blocks of this many samples (logs recorded "
        "pose by pose with a fixed count) instead of detected static intervals",
    )
    p.add_argument(
        "--model",
        choices=("full", "sphere"),
        default="full",
        help="mag: the declared model (sphere makes soft_iron a candidate)",
    )
    p.add_argument("--degree", type=int, choices=(1, 2), default=1, help="effect polynomial degree")
    p.add_argument("--seed", type=int, default=0, help="seed of the null-test simulations")
    p.add_argument("--json", dest="json_out", help="write the diagnosis JSON here ('-': stdout)")
    p.add_argument("--report", help="write the figures into this directory")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    from ..io.files import load_log
    from .loop import diagnose_accel, diagnose_mag

    log = load_log(args.file, columns=args.columns)
    if args.sensor == "accel":
        d = diagnose_accel(
            log, sample_rate=args.sample_rate, block=args.block, degree=args.degree, seed=args.seed
        )
    elif args.sensor == "marg":
        from .marg import diagnose_marg

        if log.acc is None or log.mag is None:
            raise ValueError(
                f"{args.file}: --sensor marg needs accelerometer and magnetometer columns "
                "(ax, ay, az, mx, my, mz); map them with --columns"
            )
        d = diagnose_marg(
            log.acc,
            log.mag,
            t=log.t,
            sample_rate=args.sample_rate or log.sample_rate,
            seed=args.seed,
            source=log.path,
        )
    else:
        d = diagnose_mag(
            log, model=args.model, sample_rate=args.sample_rate, degree=args.degree, seed=args.seed
        )
    print(d.summary())
    if args.json_out:
        text = json.dumps(d.to_dict(), indent=2)
        if args.json_out == "-":
            sys.stdout.write(text + "\n")
        else:
            with open(args.json_out, "w") as fh:
                fh.write(text + "\n")
            print(f"wrote {args.json_out}")
    if args.report:
        from .report import write_report

        for p in write_report(d, args.report):
            print(f"wrote {p}")
    return 0
