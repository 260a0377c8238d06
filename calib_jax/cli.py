"""Command line: ``calib-jax accel|mag|gyro|marg|diagnose FILE``, ``calib-jax batch DIR``,
``calib-jax record``, ``calib-jax apply CAL LOG``, ``calib-jax export CAL`` and
``calib-jax demo``.

Exit codes: 0 calibrated (a poorly determined calibration too: it names the parameters);
1 the fit ran but did not converge or failed (for ``batch``: some file was not calibrated);
2 the input or an option cannot give a calibration (``error: ...`` says which and what to
change); 3 an internal error (one line; ``CALIB_JAX_DEBUG=1`` shows the traceback); 130
interrupted. Nothing here imports JAX until a command runs, so ``--help`` is instant.
"""

from __future__ import annotations

import argparse
import collections
import inspect
import math
import os
import sys
import warnings
from pathlib import Path

from .datasets import demo_log_path

LOG_SUFFIXES = tuple(base + z for base in (".csv", ".tsv") for z in ("", ".gz", ".bz2", ".xz")) + (
    ".mat",
)
"""What ``calib-jax batch`` reads without --pattern: tables and MATLAB files (not .txt, which
holds READMEs and licences as often as logs)."""
_LOG_NAMES = ".csv, .tsv (also gzip, bzip2 or xz compressed) or .mat"
_DOC_SUFFIXES = frozenset(
    (
        ".md .rst .pdf .png .jpg .jpeg .gif .svg .html .py .ipynb .json .yaml .yml .toml "
        ".properties .ini .cfg .conf .xml"
    ).split()
)
"""Suffixes of what sits beside logs (a NOTES.md, a plot, a calibration written earlier, a
recorder's settings: tyrex-team's record.properties): never the ones ``batch`` proposes to
read, nor counted as logs it left out."""

# ---------------------------------------------------------------------------------------------
# option types: a bad value is a usage error (exit 2) naming the option and the value


def _number(kind, low: float, strict: bool, what: str):
    def parse(text: str):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if not math.isfinite(v) or v < low or (strict and v == low):
            raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}")
        return v

    parse.__name__ = what  # argparse names the type in its messages
    return parse


_pos_int = _number(int, 0, True, "a positive integer")
_pos_float = _number(float, 0.0, True, "a positive number")
_nonneg_float = _number(float, 0.0, False, "a number >= 0")


def _add_fit_options(
    p: argparse.ArgumentParser,
    columns: str,
    json_what: str,
    plot_what: str | None = None,
    *,
    detector: bool = True,
    solvers: tuple[str, ...] | None = None,
) -> None:
    """The options every one-log fit shares: the solver, how to read the file (``columns`` an
    example mapping), the static detector's, the sensor's id and where to write the result
    (``json_what``) and its figure (``plot_what``, if it has one)."""
    p.add_argument("--solver", default="lm1", choices=solvers or _SOLVERS)
    p.add_argument("--columns", default=None, help=f"e.g. {columns}")
    p.add_argument("--sample-rate", type=_pos_float, default=None, help="Hz, if no time column")
    if detector:
        _add_detector_options(p)
    p.add_argument("--sensor-id", default=None)
    p.add_argument("--json", default=None, help=f"write {json_what} here")
    if plot_what is not None:
        p.add_argument("--plot", default=None, help=f"write {plot_what} here")


def _add_max_iter(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--max-iter",
        type=_pos_int,
        default=None,
        help="the solver's iteration budget (default 200 for lm1-lm3, 256 for optimistix)",
    )


def _solver_options(args: argparse.Namespace) -> dict | None:
    """solver_options from --max-iter (and accel's --broyden); None when neither is given."""
    opts = {}
    if getattr(args, "broyden", False):
        opts["jacobian"] = "broyden"
    if getattr(args, "max_iter", None) is not None:
        opts["max_iter"] = args.max_iter
    return opts or None


def _add_detector_options(p: argparse.ArgumentParser, *, block: bool = True) -> None:
    """The static detector's options, the same on every command; None means automatic."""
    g = p.add_argument_group(
        "static detection", "defaults: automatic (chosen from the log's rate and noise)"
    )
    g.add_argument("--window", type=_pos_int, default=None, help="moving-variance window (samples)")
    g.add_argument(
        "--threshold-factor",
        type=_pos_float,
        default=None,
        help="threshold as a multiple of the noise level",
    )
    g.add_argument(
        "--min-static",
        type=_nonneg_float,
        default=None,
        help="shortest pose (s, or samples when the log has no rate)",
    )
    if block:
        g.add_argument(
            "--block",
            type=_pos_int,
            default=None,
            help="the log was recorded pose by pose in blocks of this many samples: use the "
            "blocks instead of detecting rests",
        )


def detector_options(args: argparse.Namespace, sample_rate: float | None) -> dict:
    """The detector keywords of :func:`calib_jax.calibrate_accel` that were given (the rest
    stay automatic). ``--min-static`` is seconds with a sample rate, else samples."""
    from .observations import detector_keywords

    return detector_keywords(sample_rate=sample_rate, **_detector_args(args))


def _detector_args(args: argparse.Namespace) -> dict:
    """The detector options as given on the command line (None: automatic)."""
    return {k: getattr(args, k, None) for k in ("window", "threshold_factor", "min_static")}


def _accel_detector(args: argparse.Namespace, sample_rate: float | None) -> dict:
    out = detector_options(args, sample_rate)
    if getattr(args, "block", None) is not None:
        out["block"] = args.block
    return out


# ---------------------------------------------------------------------------------------------
# inputs and outputs


_MAGIC = {b"\x89HDF": "an HDF5 file", b"PK\x03\x04": "a zip archive", b"\x1f\x8b": "a gzip file"}


def _binary_kind(p: Path) -> str | None:
    """'a binary file' (or its kind) when the file's start has NUL bytes, else None."""
    try:
        with open(p, "rb") as fh:
            head = fh.read(4096)
    except OSError:
        return None
    if head.startswith(b"MATLAB"):  # a .mat file the loader failed on: its reason says why
        return None
    for magic, kind in _MAGIC.items():
        if head.startswith(magic) or (kind == "an HDF5 file" and b"\x89HDF\r\n" in head):
            return kind
    return "a binary file" if b"\x00" in head else None


def _unreadable(path: str, why: str, named: bool = False) -> ValueError:
    """``named``: the loader named the file's format and how to convert it
    (:class:`calib_jax.io.files.ConvertibleFile`), which says more than its kind."""
    kind = _binary_kind(Path(path))
    if kind is not None and not named:  # the loader's reason quotes binary junk: say the kind
        return ValueError(
            f"{path} is {kind}, not a text log (CSV, TSV, whitespace-separated) or a MATLAB "
            ".mat file; export the sensor columns to CSV"
        )
    return ValueError(why if str(path) in why else f"{path}: {why}")


class _OutputError(ValueError):
    """An output path that cannot be written (named by its option, not the input file)."""


def load_input(
    path: str,
    *,
    columns: str | dict[str, str] | None = None,
    sample_rate: float | None = None,
    sensor: str | None = None,
    instance: int | None = None,
):
    """:func:`calib_jax.io.load_log` for the CLI: every way a file can fail to be a log becomes
    a ValueError naming the file and the cause (exit 2), never a traceback.

    ``sensor`` ("accel" or "mag") tells the loader which sensor a headerless 3-column file
    holds; it is passed only when the loader accepts it. ``instance``: which sensor to read of
    a log that interleaves several (--instance).
    """
    from .io import load_log

    p = Path(path)
    if p.is_dir():
        raise ValueError(f"{path} is a directory, not a log file")
    if not p.exists():
        raise ValueError(f"{path} does not exist")
    kw = {}
    if sensor is not None and "sensor" in inspect.signature(load_log).parameters:
        kw["sensor"] = sensor
    if instance is not None:
        kw["instance"] = instance
    try:
        log = load_log(path, columns=columns, sample_rate=sample_rate, **kw)
    except UnicodeError as exc:
        raise _unreadable(path, f"not text: {exc.reason}") from exc
    except OSError as exc:
        raise ValueError(f"{path}: cannot read it: {exc.strerror or exc}") from exc
    # a file the loader chokes on, in any way, is an input problem
    except Exception as exc:  # noqa: BLE001
        from .io.files import ConvertibleFile

        why = str(exc) if isinstance(exc, ValueError) else f"{type(exc).__name__}: {exc}"
        raise _unreadable(path, why, named=isinstance(exc, ConvertibleFile)) from exc
    if len(log) == 0:
        raise ValueError(f"{path} has no data rows")
    _LOADER_NOTES.extend(log.notes)
    return log


def load_args(args, *, sensor=None, columns=None):
    """:func:`load_input` of ``args.file`` with a one-log command's options (--columns unless
    ``columns`` is given, --sample-rate, --instance)."""
    return load_input(
        args.file,
        columns=args.columns if columns is None else columns,
        sample_rate=args.sample_rate,
        sensor=sensor,
        instance=args.instance,
    )


# What the loader noted about the file (rows skipped, cells not finite, guessed columns): an
# error later on prints them first, since they are often its real cause.
_LOADER_NOTES: list[str] = []


def _writable_parent(path: str, option: str) -> None:
    p = Path(path)
    if p.is_dir():
        raise _OutputError(f"{option} {path} is a directory; give a file name")
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _OutputError(
            f"{option} {path}: cannot create the folder {p.parent} ({exc.strerror or exc})"
        ) from None
    if not os.access(p.parent, os.W_OK) or (p.exists() and not os.access(p, os.W_OK)):
        raise _OutputError(f"{option} {path}: not writable")


def _writable_dir(path: str, option: str) -> None:
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise _OutputError(f"{option} {path} is a file; give a folder")
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _OutputError(f"{option} {path}: cannot create it ({exc.strerror or exc})") from None
    if not os.access(p, os.W_OK):
        raise _OutputError(f"{option} {path}: not writable")


def _prepare_outputs(args: argparse.Namespace) -> None:
    """Create the folders of every output path before any compute, or fail fast (exit 2)."""
    for attr, option in getattr(args, "output_files", ()):
        value = getattr(args, attr, None)
        if value and value != "-":
            _writable_parent(value, option)
    for attr, option in getattr(args, "output_dirs", ()):
        value = getattr(args, attr, None)
        if value:
            _writable_dir(value, option)


def _enable_x64() -> None:
    """float64 and the persistent compilation cache (calib_jax.runtime): a command's fits
    compile once per machine instead of once per call."""
    from .runtime import configure

    configure()


def _json_out(cal, path: str | None) -> None:
    if path:
        cal.save(path)
        print(f"wrote {path}")


def run_accel(args: argparse.Namespace) -> int:
    _enable_x64()
    from .accel import calibrate_accel

    # calibrate_accel raises ValueError (exit 2 in main) when the log has no accelerometer
    log = load_args(args, sensor="accel")
    cal = calibrate_accel(
        log,
        g=args.g,
        units=args.units,
        output_units=args.out_units,
        solver=args.solver,
        model=args.model,
        use=args.use,
        solver_options=_solver_options(args),
        sensor_id=args.sensor_id,
        **_accel_detector(args, log.sample_rate),
    )
    print(f"calib-jax accel: {args.file}")
    print(cal.report())
    _json_out(cal, args.json)
    _plot(cal, args.plot)
    return 0 if cal.success else 1


def run_mag(args: argparse.Namespace) -> int:
    _enable_x64()
    from .mag import calibrate_mag

    log = load_args(args, sensor=args.sensor)
    cal = calibrate_mag(
        log,
        model=args.model,
        field=args.field,
        units=args.units,
        sensor=args.sensor,
        solver=args.solver,
        solver_options=_solver_options(args),
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


WARNED_SHOWN = 10  # calibrated files whose first warning batch prints; --json holds them all


def run_batch(args: argparse.Namespace) -> int:
    _enable_x64()
    import json

    from .fleet import calibrate_files, calibrate_files_dask

    # folders are searched for logs; files named on the command line are taken as they are
    # (`calib-jax batch logs/*.csv` was "unrecognized arguments")
    roots = [Path(a) for a in args.dir]
    for r in roots:
        if not r.exists():
            raise ValueError(f"{r}: no such file or directory")
    dirs = [r for r in roots if r.is_dir()]
    root = roots[0] if len(roots) == 1 else f"{len(roots)} paths"
    held = {  # each folder's files, walked once
        d: sorted(p for p in d.rglob("*") if p.is_file() and not p.name.startswith("."))
        for d in dirs
    }
    every = sorted(p for files in held.values() for p in files)

    def logs_in(d: Path) -> list[str]:
        if args.pattern is None:
            return [str(p) for p in held[d] if p.name.lower().endswith(LOG_SUFFIXES)]
        return sorted(str(p) for p in d.rglob(args.pattern) if p.is_file())

    # in the order given, each file once
    paths = list(dict.fromkeys(p for r in roots for p in (logs_in(r) if r.is_dir() else [str(r)])))
    if not paths:
        wanted = repr(args.pattern) if args.pattern else "a log's name (" + _LOG_NAMES + ")"
        suffixes = collections.Counter(p.suffix.lower() for p in every if p.suffix)
        if not every:
            raise ValueError(f"no files matching {wanted} under {root}: it is empty")
        if not suffixes:
            raise ValueError(
                f"no files matching {wanted} under {root}: its {len(every)} file(s) have no "
                "suffix; name them with --pattern (e.g. --pattern '*')"
            )
        found = ", ".join(f"{n} {sfx}" for sfx, n in suffixes.most_common(4))
        data = [(n, sfx) for sfx, n in suffixes.most_common() if sfx not in _DOC_SUFFIXES]
        if not data:
            raise ValueError(
                f"no files matching {wanted} under {root}; it holds {len(every)} file(s) "
                f"({found}), none of them a log by its name; name the logs with --pattern"
            )
        common = data[0][1]
        raise ValueError(
            f"no files matching {wanted} under {root}; it holds {len(every)} file(s) ({found}): "
            f"--pattern '*{common}' takes the {common} ones"
        )
    chosen = set(paths)
    others = [p for p in every if str(p) not in chosen and p.suffix.lower() not in _DOC_SUFFIXES]
    options = {}
    if args.sensor == "accel":
        options.update(g=args.g, model=args.model or "accel9")
    elif args.sensor == "gyro":
        options.update(g=args.g)  # each log's accelerometer, fitted first
    else:
        options.update(field=args.field, model=args.model or "full")
    if args.max_iter is not None:
        if args.sensor == "gyro":
            raise ValueError(
                "--max-iter sets the batch fit's budget for --sensor accel and mag; a gyro "
                "batch fits each log with calib-jax gyro's own solvers"
            )
        options["solver_options"] = {"max_iter": args.max_iter}
    files = f"{len(paths)} file{'s' if len(paths) != 1 else ''}"
    # one model for every log of a batch (calib-jax accel / mag choose per log)
    model = f", model {options['model']} for every log" if "model" in options else ""
    place = f" under {root}" if dirs else ""  # files named on the command line: no place
    print(f"calib-jax batch: {files}{place}, sensor {args.sensor}{model}")
    if others:
        shown = ", ".join(p.name for p in others[:4]) + (", ..." if len(others) > 4 else "")
        which = f"matching {args.pattern!r}" if args.pattern else f"named like a log ({_LOG_NAMES})"
        print(
            f"left out: {len(others)} other file(s), not {which}: {shown}; set --pattern to "
            "read them"
        )
    if args.dask is not None:
        results = calibrate_files_dask(
            paths,
            scheduler=args.dask or None,
            n_workers=args.workers,
            sensor=args.sensor,
            chunk=args.chunk,
            columns=args.columns,
            use=args.use,
            detector=_detector_args(args),
            sample_rate=args.sample_rate,
            progress=False if args.no_progress else None,
            **options,
        )
    else:
        results = calibrate_files(
            paths,
            sensor=args.sensor,
            chunk=args.chunk,
            columns=args.columns,
            use=args.use,
            progress=False if args.no_progress else None,
            detector=_detector_args(args),
            sample_rate=args.sample_rate,
            **options,
        )
    from .calibration import FORMAT_VERSION, _sanitize  # the layout of calib_jax.BatchRecord

    out = open(args.json, "w") if args.json else None  # noqa: SIM115
    from .status import is_usable

    n_ok = n_all = n_poor = 0  # usable (as calib-jax accel/mag exit 0), of all, poorly determined
    not_ok: list[str] = []
    warned: list[str] = []  # calibrated, with a warning (a calib-jax accel run prints it)
    table_rows: list[dict] = []
    try:
        if out:
            head = json.dumps(
                {"format_version": FORMAT_VERSION, "kind": "batch", "sensor": args.sensor}
            )[:-1]
            out.write(head + ', "results": [\n')
        for r in results:
            table_rows.append(r)
            # written as they arrive: a crash keeps what was calibrated so far
            if out:
                out.write(("" if n_all == 0 else ",\n") + json.dumps(_sanitize(r)))
                out.flush()
            n_all += 1
            n_ok += is_usable(r["status"])
            n_poor += r["status"] == "poorly_determined"
            if r["status"] != "ok":
                not_ok.append(f"{r['path']}: {r['status']}: {r.get('message', '')}")
            elif r.get("warnings"):
                n_w = len(r["warnings"])
                warned.append(f"{r['path']}: ok, {n_w} warning(s): {r['warnings'][0]}")
        if out:
            out.write("\n]}\n")
    finally:
        if out:
            out.close()
    # after the progress line: why each file was not calibrated, without opening the JSON
    for line in not_ok:
        print(line)
    for line in warned[:WARNED_SHOWN]:
        print(line)
    if len(warned) > WARNED_SHOWN:
        print(
            f"... and {len(warned) - WARNED_SHOWN} more calibrated with warnings (--json has them)"
        )
    if not (args.json or args.table):  # nothing kept on disk: show the results themselves
        _print_batch_results(table_rows, args.sensor)
    poor = f" ({n_poor} poorly determined: usable with care, see why above)" if n_poor else ""
    print(f"{n_ok} of {n_all} calibrated{poor}" + (f"; wrote {args.json}" if args.json else ""))
    readings = collections.Counter(
        n.split(" (", 1)[0].split(" read as ", 1)[-1]
        for r in table_rows
        for n in r.get("notes") or []
        if n.startswith("headerless")
    )
    if readings:
        how = ", ".join(f"{k} ({v})" for k, v in readings.most_common())
        print(
            f"note: {sum(readings.values())} file(s) have no header; their columns were read "
            f"as {how} (each file's notes say why; --columns says otherwise)"
        )
    said = {  # the loader's words for a file of the other sensor: its columns, or its name
        "mag": ("holds mag columns only", "name names the magnetometer"),
        "accel": ("holds accel columns only", "name names the accelerometer"),
    }
    other = collections.Counter(
        sensor
        for r in table_rows
        for sensor in ("mag", "accel")
        if sensor != args.sensor
        and r["status"] == "not_fitted"
        and any(w in (r.get("message") or "") for w in said[sensor])
    )  # a folder of one sensor's logs batched as the other: say the option that takes them
    for sensor, k in other.items():
        kind = {"mag": "magnetometer", "accel": "accelerometer"}[sensor]
        print(
            f"note: {k} file(s) are {kind} logs (by their columns or their name): --sensor "
            f"{sensor} calibrates them"
        )
    if args.table:
        from .display import fleet_rows, write_table

        write_table(fleet_rows(table_rows, args.sensor), args.table)
        print(f"wrote {args.table} ({n_all} rows)")
    return 0 if n_ok == n_all else 1  # every file usable, as a single fit's exit 0


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

    from .datasets import mag_demo_log_path
    from .marg import calibrate_marg_log
    from .plots import plot_mag

    mpath = mag_demo_log_path()
    print(
        "\ncalib-jax demo, magnetometer (paper 2): CK-Explorer accelerometer + magnetometer "
        f"tumble (Apache-2.0; see {mpath.parent / 'NOTES.md'})\n"
    )
    mlog = load_log(mpath)
    # the CK-Explorer accelerometer is already calibrated (NOTES.md): used as given
    marg = calibrate_marg_log(mlog, accel="none", solver=args.solver)
    print(marg.mag.report())
    print("\n" + marg.alignment_text())
    _json_out(marg.mag, str(out / "demo_mag.json"))
    _json_out(marg, str(out / "demo_marg.json"))
    plot_mag(marg.mag, mlog.mag, str(out / "demo_mag.png"))
    print(f"wrote {out / 'demo_mag.png'}")
    return 0 if cal.success and marg.success else 1


def run_marg(args: argparse.Namespace) -> int:
    _enable_x64()
    from .marg import calibrate_marg_log

    # sensor="mag": a headerless 6-column file is accelerometer then magnetometer, as calib-jax
    # mag reads it (it was read as accelerometer + gyro, and marg then asked for mx, my, mz)
    if args.mag_file is None:
        log = load_args(args, sensor="mag")
    else:  # a phone's Accelerometer.csv and Magnetometer.csv
        log = _two_files(args, args.mag_file, "mag")
    if args.accel in ("ellipsoid", "none") and (
        detector_options(args, log.sample_rate) or args.block is not None
    ):
        print(f"note: the detector options are not used with --accel {args.accel}", file=sys.stderr)
    rec = calibrate_marg_log(
        log,
        accel=args.accel,
        mag_model=args.mag_model,
        acc_model=args.acc_model,
        field=args.field,
        g=args.g,
        solver=args.solver,
        sensor_id=args.sensor_id,
        **(_accel_detector(args, log.sample_rate) if args.accel in ("auto", "static") else {}),
    )
    print(f"calib-jax marg: {args.file}" + (f" + {args.mag_file}" if args.mag_file else ""))
    print(rec.report())
    _json_out(rec, args.json)
    if args.plot:
        from .plots import plot_mag

        plot_mag(rec.mag, log.mag, args.plot)
        print(f"wrote {args.plot}")
    return 0 if rec.success else 1


BATCH_ROWS_SHOWN = 20


def _print_batch_results(results: list[dict], sensor: str) -> None:
    """Each calibrated file's parameters, one line each (the first BATCH_ROWS_SHOWN), when the
    batch writes neither --json nor --table."""
    from .display import param_names

    ok = [r for r in results if r["status"] == "ok"]
    for r in ok[:BATCH_ROWS_SHOWN]:
        names = param_names(sensor)
        values = " ".join(f"{n} {v:.6g}" for n, v in zip(names, r["params"], strict=False))
        print(f"{r['path']}: {values}" + (f"; rms {r['rms']:.3g}" if "rms" in r else ""))
    more = f"{len(ok) - BATCH_ROWS_SHOWN} more results and " if len(ok) > BATCH_ROWS_SHOWN else ""
    if ok:
        print(f"({more}standard errors: write them with --json OUT.json or --table OUT.csv)")


def _split_columns(spec: str | None, prefix: str) -> tuple[dict | None, dict | None]:
    """--columns for two files (``calib-jax gyro ACC_FILE GYRO_FILE``, ``calib-jax marg
    ACC_FILE MAG_FILE``): the second sensor's entries (``prefix`` g or m: gx, gy, gz) name
    columns of its own file, with t where given; the rest the accelerometer's."""
    from .io.files import parse_columns

    mapping = parse_columns(spec)
    if not mapping or not any(k.startswith(prefix) for k in mapping):
        return mapping, None
    other = {k: v for k, v in mapping.items() if k.startswith(prefix) or k == "t"}
    acc = {k: v for k, v in mapping.items() if not k.startswith(prefix)}
    # a mapping of the second file alone (--columns t,gx,gy,gz,_,_,_) leaves the
    # accelerometer's file to its header or the guess: its time alone maps no sensor (it was
    # read with t only and refused: "no sensor columns recognised in ['0', '1', '2', '3']")
    return (acc if any(k != "t" for k in acc) else None), other


def _two_files(args: argparse.Namespace, second: str, sensor: str):
    """The accelerometer's log of ``args.file`` joined with ``sensor``'s own file ``second``
    (:func:`calib_jax.io.files.join_logs`: row by row, or by their time columns)."""
    from .io.files import join_logs, sensor_named_by

    if sensor_named_by(args.file) == sensor and sensor_named_by(second) == "accel":
        command = "marg" if sensor == "mag" else "gyro"
        raise ValueError(
            f"the two files are the other way round: {args.file}'s name names the "
            f"{ {'mag': 'magnetometer', 'gyro': 'gyroscope'}[sensor] } and "
            f"{second}'s the accelerometer, whose file comes first: calib-jax {command} "
            f"{second} {args.file}"
        )
    acc_columns, own = _split_columns(args.columns, sensor[0])
    log = load_input(  # None: its header or the guess (load_args would take --columns whole)
        args.file,
        columns=acc_columns,
        sample_rate=args.sample_rate,
        sensor="accel",
        instance=args.instance,
    )
    other = load_input(  # its own columns only (None: its header or the guess)
        second, columns=own, sample_rate=args.sample_rate, sensor=sensor, instance=args.instance
    )
    return join_logs(log, other, sensor)


def run_gyro(args: argparse.Namespace) -> int:
    _enable_x64()
    from .gyro import calibrate_gyro

    if args.gyro_file is None:
        log = load_args(args)
        if log.gyro is None:
            raise ValueError(
                f"{args.file}: the log has no gyro columns (gx, gy, gz): map them with "
                "--columns, or give the gyro's own file after the accelerometer's "
                "(calib-jax gyro ACC_FILE GYRO_FILE)"
            )
    else:
        log = _two_files(args, args.gyro_file, "gyro")
    cal = calibrate_gyro(
        log,
        units=args.gyro_units,
        solver=args.solver,
        sensor_id=args.sensor_id,
        accel_options={
            "g": args.g,
            "units": args.units,
            "model": args.accel_model,
            **_accel_detector(args, log.sample_rate),
        },
    )
    print(f"calib-jax gyro: {args.file}" + (f" + {args.gyro_file}" if args.gyro_file else ""))
    print(cal.report())
    _json_out(cal, args.json)
    return 0 if cal.success else 1


def run_apply(args: argparse.Namespace) -> int:
    from .apply import apply_calibration
    from .calibration import FitStatusWarning, OffScaleWarning
    from .export import read, status_warnings

    corr = read(args.calibration, sensor=args.sensor)
    for w in status_warnings(corr):
        print(f"warning: {w}", file=sys.stderr)
    log = Path(args.file)
    if log.is_dir() or not log.exists():
        raise ValueError(f"{log} {'is a directory' if log.is_dir() else 'does not exist'}")
    out = args.out or str(log.with_name(log.stem + ".calibrated.csv"))
    _writable_parent(out, "--out")
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", UserWarning)
            rep = apply_calibration(
                corr,
                args.file,
                out,
                columns=args.columns,
                sample_rate=args.sample_rate,
                chunk_rows=args.chunk_rows,
            )
    except (UnicodeError, OSError) as exc:
        raise _unreadable(args.file, f"cannot read it: {exc}") from exc
    # a failed calibration's warning was said above (status_warnings), once
    said = [str(w.message) for w in caught if not issubclass(w.category, FitStatusWarning)]
    off = [w for w in caught if issubclass(w.category, OffScaleWarning)]
    for w in said:  # readings in another unit: a warning, not again among the notes
        print(f"warning: {w}", file=sys.stderr)
    rep.notes = [n for n in rep.notes if n not in said]
    print(f"calib-jax apply: {args.calibration} -> {args.file}")
    print(rep.report())
    if off:  # written, as asked, but not usable: a script checking the exit code must know
        print(
            f"error: {rep.out} was written, but its readings are not in the calibration's unit "
            "(the warning above); check the log's unit and columns",
            file=sys.stderr,
        )
    return 1 if off else 0


def run_export(args: argparse.Namespace) -> int:
    from . import export

    corr = export.read(args.calibration)
    text = export.write(corr, args.format, sensor=args.sensor, name=args.name)
    for w in export.status_warnings(corr, args.sensor):
        print(f"warning: {w}", file=sys.stderr)
    if args.out in (None, "-"):
        sys.stdout.write(text)
    else:
        Path(args.out).write_text(text)
        print(f"wrote {args.out} ({args.format})")
    return 0


def run_record(args: argparse.Namespace) -> int:
    _enable_x64()
    from .record import run

    return run(args)


_SOLVERS = ["lm1", "lm2", "lm3", "optimistix"]
_FILE_OUTPUTS = (("json", "--json"), ("plot", "--plot"))


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="calib-jax", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = p.add_subparsers(dest="command", required=True)

    a = sub.add_parser("accel", help="calibrate an accelerometer from a multi-position log")
    a.add_argument("file")
    a.add_argument("--g", type=_pos_float, default=None, help="reference magnitude, output units")
    a.add_argument("--units", default="auto", help="input units: auto, counts, g, m/s^2")
    a.add_argument("--out-units", default=None, help="label of the calibrated output (with --g)")
    a.add_argument(
        "--model",
        default="auto",
        choices=["auto", "accel9", "accel6"],
        help="paper 1's nine parameters, or six (no cross terms) for six-face logs; default "
        "auto: nine where the log holds nine distinct poses and determines them, else six",
    )
    a.add_argument("--use", default="means", choices=["means", "samples"])
    a.add_argument("--broyden", action="store_true", help="finite differences + Broyden (paper 1)")
    _add_max_iter(a)
    _add_fit_options(
        a, "t,ax,ay,az or ax=AccX,ay=AccY,az=AccZ", "the calibration JSON", "a PNG figure"
    )
    a.set_defaults(func=run_accel, output_files=_FILE_OUTPUTS)

    m = sub.add_parser(
        "mag", help="ellipsoid (hard/soft iron) calibration from a free-rotation log (paper 2)"
    )
    m.add_argument("file")
    m.add_argument(
        "--model",
        default="auto",
        choices=["sphere", "diag", "full", "auto"],
        help="hard iron only, axis-aligned ellipsoid, full ellipsoid, or (auto) the lowest "
        "BIC among the models the data determine (the sphere when none is)",
    )
    m.add_argument(
        "--field", type=_pos_float, default=None, help="known field magnitude (output scale)"
    )
    m.add_argument("--units", default=None, help="label of the raw units (report only)")
    m.add_argument(
        "--sensor",
        default="mag",
        choices=["mag", "accel"],
        help="which columns to fit (a headerless 3-column file is read as this sensor)",
    )
    _add_max_iter(m)
    _add_fit_options(
        m, "mx,my,mz or mx=MagX,my=MagY,mz=MagZ", "the calibration JSON", "a PNG figure",
        detector=False,
    )  # fmt: skip
    m.set_defaults(func=run_mag, output_files=_FILE_OUTPUTS)

    g = sub.add_parser(
        "marg",
        help="accelerometer + magnetometer (MARG) calibration of one tumble log (paper 2)",
        description="Paper 2's routine on one log with accelerometer and magnetometer columns: "
        "the accelerometer's calibration, the magnetometer's ellipsoid, then the rotation from "
        "the magnetometer to the accelerometer frame (with the signed axis permutation when the "
        "magnetometer's axes are swapped or negated) from the constant angle between gravity "
        "and the field; reports the dip and the spread of that angle before and after.\n\n"
        "The accelerometer (--accel): a tumble has no rests, so paper 1's static calibration "
        "is usually impossible; 'auto' tries it on the static poses the detector finds and "
        "falls back to the accelerometer's own ellipsoid (paper 2 compensates every sensor "
        "with its ellipsoid; motion widens the spread of |a| but leaves the centre), and uses "
        "the accelerometer as given when that fit fails too (too little of the sphere). 'none' "
        "uses the accelerometer as given (already calibrated, like the CK-Explorer demo log).",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    g.add_argument("file", help="log with accelerometer and magnetometer columns")
    g.add_argument(
        "mag_file",
        nargs="?",
        default=None,
        help="the magnetometer's own file, when it is apart from the accelerometer's (same "
        "rows, or each with a time column: joined by time)",
    )
    g.add_argument(
        "--accel",
        default="auto",
        choices=["auto", "static", "ellipsoid", "none"],
        help="how to calibrate the accelerometer (see above; default auto)",
    )
    g.add_argument(
        "--mag-model",
        default="auto",
        choices=["sphere", "diag", "full", "auto"],
        help="magnetometer ellipsoid model (default: the lowest BIC among the models the data "
        "determine)",
    )
    g.add_argument(
        "--acc-model",
        default="full",
        choices=["sphere", "diag", "full"],
        help="the accelerometer's ellipsoid model (--accel ellipsoid; default full)",
    )
    g.add_argument("--field", type=_pos_float, default=None, help="known field magnitude")
    g.add_argument("--g", type=_pos_float, default=None, help="accelerometer reference (static)")
    _add_fit_options(
        g, "ax,ay,az,mx,my,mz or ax=AccX,...", "the MARG record (kind 'marg')",
        "the magnetometer figure (PNG)",
    )  # fmt: skip
    g.set_defaults(func=run_marg, output_files=_FILE_OUTPUTS)

    gy = sub.add_parser(
        "gyro",
        help="gyroscope scale, misalignment and bias from a multi-position log (imu_tk method)",
        description="The imu_tk method (Tedaldi et al. 2014): the accelerometer is calibrated "
        "on the log's static poses, the gyro bias is its mean at rest, and the nine entries of "
        "C in w = C (raw - b) are fitted so that the rates integrated between consecutive "
        "poses turn one pose's gravity direction onto the next's. Needs accelerometer and gyro "
        "columns on one clock (one file, or the accelerometer's file then the gyro's) and the "
        "time (a time column or --sample-rate). Reports the rotation error between poses, in "
        "degrees, before and after, beside what the gyro's rest noise alone would leave.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    gy.add_argument("file", help="log with accelerometer and gyro columns (or accelerometer only)")
    gy.add_argument(
        "gyro_file",
        nargs="?",
        default=None,
        help="the gyro's own file (same rows, or each with a time column: joined by time)",
    )
    gy.add_argument(
        "--gyro-units",
        default="auto",
        choices=["auto", "counts", "rad/s", "deg/s"],
        help="of the gyro readings (checked against the fitted scale; default recognised)",
    )
    gy.add_argument("--g", type=_pos_float, default=None, help="accelerometer reference")
    gy.add_argument("--units", default="auto", help="accelerometer units: auto, counts, g, m/s^2")
    gy.add_argument(
        "--accel-model",
        default="auto",
        choices=["auto", "accel9", "accel6"],
        help="the accelerometer fit's model (as calib-jax accel --model)",
    )
    _add_fit_options(
        gy, "t,ax,ay,az,gx,gy,gz", "the gyro calibration (kind 'gyro')",
        solvers=("lm1", "lm2", "lm3"),
    )  # fmt: skip
    gy.set_defaults(func=run_gyro, output_files=(("json", "--json"),))

    b = sub.add_parser(
        "batch",
        help="calibrate every log under a directory or named, in chunks (or on a Dask cluster)",
    )
    b.add_argument(
        "dir", nargs="+", metavar="PATH", help="folders (searched for logs) or log files"
    )
    b.add_argument(
        "--pattern",
        default=None,
        help=f"file glob, searched recursively (default: names ending {_LOG_NAMES})",
    )
    b.add_argument(
        "--sensor",
        default="accel",
        choices=["accel", "mag", "gyro"],
        help="gyro: each log through calib-jax gyro's fit (poses with turns, a time column or "
        "--sample-rate); rms is then the miss between poses in degrees",
    )
    b.add_argument(
        "--model",
        default=None,
        help="accel9|accel6 (default accel9) or sphere|diag|full (default full): one model for "
        "every log, where calib-jax accel and mag choose per log",
    )
    b.add_argument(
        "--g",
        type=_pos_float,
        default=None,
        help="accelerometer reference magnitude (default: each log's unit: 1 g or 9.80665 m/s^2)",
    )
    b.add_argument("--field", type=_pos_float, default=None, help="magnetometer field magnitude")
    b.add_argument("--columns", default=None, help="column mapping for every file")
    b.add_argument(
        "--sample-rate",
        type=_pos_float,
        default=None,
        help="Hz, for logs without a time column (every file)",
    )
    b.add_argument(
        "--use",
        default="means",
        choices=["means", "samples"],
        help="accelerometer fit points, as calib-jax accel: static-interval means or samples",
    )
    b.add_argument("--chunk", type=_pos_int, default=256, help="files per batch fit")
    _add_max_iter(b)
    _add_detector_options(b, block=False)
    b.add_argument(
        "--dask",
        nargs="?",
        const="",
        default=None,
        help="spread chunks over Dask: a scheduler address, or none for a local cluster",
    )
    b.add_argument("--workers", type=_pos_int, default=2, help="local Dask workers")
    b.add_argument("--json", default=None, help="write all results here (streamed)")
    b.add_argument(
        "--table",
        default=None,
        help="write one row per file (parameters, standard errors, status, rms, notes) as CSV, "
        "or Parquet for a .parquet name (needs pandas and pyarrow)",
    )
    b.add_argument("--no-progress", action="store_true", help="no progress bar")
    b.set_defaults(func=run_batch, output_files=(("json", "--json"), ("table", "--table")))

    d = sub.add_parser(
        "demo", help="calibrate the accelerometer and magnetometer logs shipped with the package"
    )
    d.add_argument("--out", default="calib_jax_demo", help="folder for the JSON and the figures")
    d.add_argument("--solver", default="lm1", choices=_SOLVERS)
    d.set_defaults(func=run_demo, output_dirs=(("out", "--out"),))

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
    r.add_argument("--baud", type=_pos_int, default=115200)
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
    r.add_argument("--sensor", default="accel", choices=["accel", "mag", "marg", "gyro"])
    r.add_argument("--seconds", type=_pos_float, default=None, help="stop after this long")
    r.add_argument("--resume", action="store_true", help="append to an existing log")
    r.add_argument("--overwrite", action="store_true", help="replace an existing log")
    r.add_argument("--no-auto-stop", action="store_true", help="keep going once covered")
    r.add_argument(
        "--no-progress", action="store_true", help="a coverage line a second, not a progress bar"
    )
    r.add_argument("--target-poses", type=_pos_int, default=48, help="distinct poses (paper 1: 48)")
    r.add_argument(
        "--max-reconnect",
        type=_nonneg_float,
        default=30.0,
        help="seconds to keep reconnecting an unplugged device before it counts as gone",
    )
    r.add_argument("--g", type=_pos_float, default=None, help="accelerometer reference magnitude")
    r.add_argument("--field", type=_pos_float, default=None, help="known field magnitude (mag)")
    _add_detector_options(r, block=False)
    r.add_argument("--solver", default="lm1", choices=_SOLVERS)
    r.set_defaults(func=run_record, output_files=(("out", "--out"),))

    ap = sub.add_parser(
        "apply",
        help="apply a saved calibration to a log (streamed) and write the corrected CSV",
        description="Correct the accelerometer, gyro and magnetometer columns of LOG with the "
        "calibration in CAL (calib_jax's accel, mag, gyro or marg JSON, or an imu_tk, imucal or "
        "imu_calib file) and write CSV: t, each sensor's x, y, z (corrected where CAL has its "
        "calibration, else as read) and the temperature. Other columns (labels, a vendor's "
        "extra fields) are not copied. A plain text log is streamed in chunks (memory does not "
        "grow with its length).",
    )
    ap.add_argument("calibration", metavar="CAL", help="the saved calibration")
    ap.add_argument("file", metavar="LOG", help="the log to correct")
    ap.add_argument("--out", default=None, help="output CSV (default: LOG.calibrated.csv)")
    ap.add_argument("--columns", default=None, help="column mapping, as for calib-jax accel")
    ap.add_argument("--sample-rate", type=_pos_float, default=None, help="Hz, if no time column")
    ap.add_argument(
        "--sensor",
        default=None,
        choices=["accel", "mag"],
        help="which sensor an imu_tk file holds (its text does not say; default accel)",
    )
    ap.add_argument("--chunk-rows", type=_pos_int, default=262_144, help="lines per chunk")
    ap.set_defaults(func=run_apply, output_files=(("out", "--out"),))

    ex = sub.add_parser(
        "export",
        help="write a saved calibration for firmware (C header), imu_tk, imucal or ROS",
        description="Write CAL in another tool's format: 'c' (a C header: float constants and "
        "an inline correction function), 'imu_tk' (CalibratedTriad_ text: T, K, B), 'imucal' "
        "(FerrarisCalibrationInfo JSON: accelerometer and gyroscope, G as K_ga) or 'ros' "
        "(imu_calib's YAML: SM, bias). Every format holds the same correction x = C (raw - b); "
        "a gyroscope's g-sensitivity G goes to c and imucal only (imu_tk and ros refuse it).",
    )
    ex.add_argument("calibration", metavar="CAL", help="the saved calibration (JSON)")
    ex.add_argument("--format", required=True, choices=["c", "imu_tk", "imucal", "ros"])
    ex.add_argument("--out", default=None, help="output file (default: standard output)")
    ex.add_argument(
        "--sensor",
        default=None,
        choices=["accel", "mag"],
        help="the triad to write, for single-triad formats and a MARG calibration",
    )
    ex.add_argument("--name", default="calib", help="prefix of the C header's identifiers")
    ex.set_defaults(func=run_export, output_files=(("out", "--out"),))

    _add_diagnose_parser(sub)
    for name in ("accel", "mag", "marg", "gyro", "diagnose"):  # the one-log commands
        sub.choices[name].add_argument(
            "--instance",
            type=int,
            default=None,
            help="a log that interleaves several sensors' rows, told apart by an instance "
            "column (ArduPilot's I): the one to read (default: the first row's)",
        )
    for command in sub.choices.values():  # what each command can be told to change
        command.set_defaults(option_strings=frozenset(_option_strings(command)))
    return p


def _option_strings(parser: argparse.ArgumentParser):
    return (s for action in parser._actions for s in action.option_strings)


def _add_diagnose_parser(sub) -> None:
    # defined here, not in calib_jax.diagnose, whose package import starts JAX
    p = sub.add_parser(
        "diagnose",
        help="trace the residual of a calibration to effects its model lacks",
        description="Fit the declared model, measure the noise floors, add catalogue effects "
        "(bias drift, temperature, scale nonlinearity, outliers, hard-iron drift, soft iron; "
        "for MARG the accel-mag misalignment and timing offset) "
        "only where every acceptance test passes, and report the error before and after.",
    )
    p.add_argument("file", help="log file (CSV/TSV/text/.mat)")
    p.add_argument(
        "--sensor",
        choices=("accel", "mag", "marg"),
        help="the sensor to diagnose; default: the accelerometer, or the magnetometer of a log "
        "that has no accelerometer columns (a headerless 3-column file is read as an "
        "accelerometer)",
    )
    p.add_argument("--columns", help="column mapping for headerless files, e.g. t,ax,ay,az")
    p.add_argument("--sample-rate", type=_pos_float, help="Hz, when the log has no time column")
    _add_detector_options(p, block=False)
    p.add_argument(
        "--block",
        type=_pos_int,
        help="accel: observations are consecutive blocks of this many samples (logs recorded "
        "pose by pose with a fixed count) instead of detected static intervals",
    )
    p.add_argument(
        "--model",
        choices=("auto", "full", "diag", "sphere"),
        default="auto",
        help="mag: the declared model; auto (default): the one calib-jax mag chooses for the "
        "log (on sphere or diag, soft_iron is a candidate: the rest of the full ellipsoid). "
        "marg: the ellipsoid fitted to each sensor first (auto: full; diag or sphere for a "
        "log that turns too little for an ellipsoid)",
    )
    p.add_argument("--degree", type=int, choices=(1, 2), default=1, help="effect polynomial degree")
    p.add_argument("--seed", type=int, default=0, help="seed of the null-test simulations")
    p.add_argument("--no-progress", action="store_true", help="no progress bar over the rounds")
    p.add_argument("--json", dest="json_out", help="write the diagnosis JSON here ('-': stdout)")
    p.add_argument("--report", help="write the figures into this directory")
    p.set_defaults(
        func=_run_diagnose,
        output_files=(("json_out", "--json"),),
        output_dirs=(("report", "--report"),),
    )


def _run_diagnose(args: argparse.Namespace) -> int:
    from .diagnose.cli import run

    return run(args)


def _is_input_error(exc: BaseException) -> bool:
    """Exceptions that mean 'this file or option cannot give a calibration' (exit 2)."""
    if isinstance(exc, ValueError | OSError | EOFError):  # UnicodeError, LinAlgError, gzip
        return True
    import zipfile

    return isinstance(exc, zipfile.BadZipFile)


def _error_text(exc: BaseException, args: argparse.Namespace) -> str:
    from .observations import TooFewPoses  # numpy only: no JAX import on an error path

    if isinstance(exc, OSError) and exc.strerror:
        msg = f"{exc.strerror}: {exc.filename}" if exc.filename else exc.strerror
    elif isinstance(exc, TooFewPoses):  # advice in this command's own flags
        msg = f"{exc.finding}. {exc.advice(getattr(args, 'option_strings', ()))}"
    else:
        msg = str(exc) or type(exc).__name__
    where = getattr(args, "file", None) or getattr(args, "dir", None)
    if isinstance(where, list):  # batch's paths: one names the place, several do not
        where = where[0] if len(where) == 1 else None
    named = [str(w) for w in (where, getattr(args, "calibration", None)) if w]
    if where and not isinstance(exc, _OutputError) and not any(w in msg for w in named):
        msg = f"{where}: {msg}"
    return msg


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning as one line, like the notes; no source path (CALIB_JAX_DEBUG=1 keeps it)."""
    print(f"warning: {message}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns the exit code (module docstring) and prints no traceback."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help (0) or a usage error (2): argparse has said why
        return exc.code if isinstance(exc.code, int) else 2
    debug = os.environ.get("CALIB_JAX_DEBUG", "") not in ("", "0")
    _LOADER_NOTES.clear()
    try:
        _prepare_outputs(args)
        with warnings.catch_warnings():
            if not debug:  # numpy's 'Mean of empty slice' on odd input: the error line says it
                warnings.simplefilter("ignore", RuntimeWarning)
                from .calibration import FitStatusWarning

                warnings.simplefilter("ignore", FitStatusWarning)  # the report says it
                warnings.showwarning = _show_warning
            return args.func(args)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    # the front door prints one line, never a traceback
    except Exception as exc:  # noqa: BLE001
        if debug:
            raise
        if _is_input_error(exc):
            for note in _LOADER_NOTES:
                print(f"note: {note}", file=sys.stderr)
            print(f"error: {_error_text(exc, args)}", file=sys.stderr)
            return 2
        print(
            f"internal error: {type(exc).__name__}: {exc} (please report; rerun with "
            "CALIB_JAX_DEBUG=1 for the traceback)",
            file=sys.stderr,
        )
        return 3


if __name__ == "__main__":
    sys.exit(main())
