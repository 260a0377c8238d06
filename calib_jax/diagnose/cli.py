"""``calib-jax diagnose FILE --sensor accel|mag [--json OUT] [--report DIR]``."""

from __future__ import annotations

import argparse
import json
import sys


def add_parser(sub) -> None:
    """Add the ``diagnose`` subcommand to an argparse subparsers object (the parser itself
    lives in :mod:`calib_jax.cli`, which must not import this package for ``--help``)."""
    from ..cli import _add_diagnose_parser

    _add_diagnose_parser(sub)


def run(args: argparse.Namespace) -> int:
    from ..cli import _enable_x64, load_args

    _enable_x64()
    # marg: a headerless 6-column file is accelerometer then magnetometer (as for mag)
    log = load_args(args, sensor="mag" if args.sensor == "marg" else args.sensor)
    guessed = ""
    defaulted = args.sensor is None
    if args.sensor is None:  # the accelerometer, unless the log has only a magnetometer
        args.sensor = "mag" if log.acc is None and log.mag is not None else "accel"
        if log.acc is None and log.mag is None and log.gyro is not None:
            # a phone's Gyroscope.csv was told to map accelerometer columns with --columns
            raise ValueError(
                f"{args.file} holds a gyroscope only, and diagnose has no gyroscope diagnosis "
                "(it diagnoses accelerometers, magnetometers and the two together): calib-jax "
                "gyro ACC_FILE GYRO_FILE calibrates a gyroscope and tests its rest bias for "
                "g-sensitivity, drift and temperature, and its scale for asymmetry"
            )
        if args.sensor == "accel" and (guess := _sensor_guessed(log, args.file)):
            # said once, after the summary or the error (a trial read it twice)
            guessed = (
                f"note: {guess} diagnosed as an accelerometer; for a magnetometer give --sensor mag"
            )
    try:
        return _diagnose(args, log, guessed, defaulted)
    except ValueError:
        if guessed:  # before the error line, which names what was refused
            print(guessed, file=sys.stderr)
        raise


def _diagnose(args, log, guessed: str, defaulted: bool) -> int:
    """The diagnosis of the loaded log, its summary and outputs; the exit code."""
    from ..accel import MAGNETOMETER_IN_GAUSS
    from ..cli import detector_options, load_args
    from .loop import diagnose_accel, diagnose_mag

    detector = detector_options(args, args.sample_rate or log.sample_rate)
    if detector and args.sensor != "accel":
        print(
            f"note: --window/--threshold-factor/--min-static apply to --sensor accel; "
            f"ignored for {args.sensor}",
            file=sys.stderr,
        )
    progress = False if args.no_progress else None
    common = dict(sample_rate=args.sample_rate, degree=args.degree, seed=args.seed)
    common["progress"] = progress
    if args.sensor == "accel":
        # only the detector options given are passed, so the defaults stay the detector's
        d = diagnose_accel(log, block=args.block, **common, **detector)
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
            progress=progress,
            model="full" if args.model == "auto" else args.model,
        )
    else:
        d = diagnose_mag(log, model=args.model, **common)
    if guessed and d.verdict == "not_possible" and MAGNETOMETER_IN_GAUSS in d.notes[0]:
        # hamagure's x,y,z file in gauss: refused as an accelerometer, with the flag to give;
        # the guess was the command's, so it takes the reading the refusal names instead
        why = d.notes[0].split(": gains")[0].removeprefix("diagnosis not possible: ")
        print(
            f"note: {args.file}: {why}, but a magnetometer's in gauss (0.25-0.65): diagnosed as "
            "a magnetometer instead",
            file=sys.stderr,
        )
        args.sensor, guessed = "mag", ""
        d = diagnose_mag(load_args(args, sensor="mag"), model=args.model, **common)
    summary = d.summary()
    if d.verdict == "not_possible" and d.notes:  # its reason is the error line below
        summary = summary.replace(f"\n  note: {d.notes[0]}", "", 1)
    print(summary)
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

        written = write_report(d, args.report)
        for p in written:
            print(f"wrote {p}")
        if not written:  # a trial looked for figures that were never made
            print(f"note: no figures in {args.report}: there is no diagnosis to draw")
    if d.verdict == "not_possible":  # like every command: input that cannot be used, exit 2
        why = d.notes[0] if d.notes else "diagnosis not possible"
        print(f"error: {args.file}: {why}", file=sys.stderr)
        if guessed:
            print(guessed, file=sys.stderr)
        elif defaulted and args.sensor == "accel" and log.mag is not None:
            # the YEI log of scikit-kinematics: 2 poses, but a magnetometer the user was not told
            # could be diagnosed instead
            print(
                f"note: {args.file} also holds magnetometer columns: --sensor mag diagnoses "
                "them (--sensor marg, both sensors together)",
                file=sys.stderr,
            )
        return 2
    if guessed:
        print(guessed, file=sys.stderr)
    return 0


def _sensor_guessed(log, file) -> str:
    """Where neither a header nor the file's name said which sensor three columns are, the
    note's words for that (they end where the command's choice is named); else ''."""
    for n in log.notes:
        if "names the" in n:  # the file's name decided
            continue
        if n.startswith(("headerless 3-column", "headerless 4-column")):
            return f"{file} has no header: its three columns were"
        if " name no sensor: " in n:  # 'x,y,z'
            return f"{file}: its {n.split(' name no sensor')[0]} name no sensor: they were"
    return ""
