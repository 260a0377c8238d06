"""Fleets of logs: chunked streaming batch fits, and the same spread over a Dask cluster.

File-level work (reading, static detection) runs on the host per file; the fits run chunk by
chunk through :func:`calib_jax.calibrate_accel_batch` / :func:`calib_jax.calibrate_mag_batch`,
so memory holds one chunk whatever the fleet's size. A file that cannot be read or prepared
gets its own entry with the error and never stops the others. Results come back in input
order, one plain dict per file (JSON-ready).

Beyond one machine: :func:`calibrate_files_dask` hands chunks of files to a Dask cluster (a
local one by default, or a scheduler address), each worker running the same chunk function.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from .io.files import OtherSensorsFile, SensorLog, load_log
from .observations import accel_observations, detector_keywords, screen_samples
from .padding import stack_rows
from .progress import progress_bar

SENSORS = ("accel", "mag", "gyro")


def prepare_log(
    log: SensorLog,
    sensor: str = "accel",
    *,
    model: str | None = None,
    use: str = "means",
    **detector,
) -> tuple[np.ndarray, dict]:
    """The fit points (n, 3) of one loaded log and what was found, through the same front door
    as :func:`calib_jax.calibrate_accel` / :func:`calib_jax.calibrate_mag`
    (:mod:`calib_jax.observations`), so a batch fits what the single fit would.

    Accelerometer: the static-interval means (``use="means"``, the default of
    ``calibrate_accel``) or every static sample (``use="samples"``), after the same pose
    checks (:func:`calib_jax.accel.check_poses`: a ValueError when the poses cannot determine
    ``model``). Magnetometer: every finite sample off a saturated axis.
    """
    if sensor not in SENSORS[:2]:
        raise ValueError(f"sensor must be one of {SENSORS[:2]}, got {sensor!r}")
    x = log.vectors(sensor)
    info: dict = {"samples": len(x)}
    if sensor == "mag":
        valid, notes = screen_samples(x, "mag")
        info["notes"] = list(log.notes) + notes
        return x[valid], info
    from .accel import MODELS, _coverage_warnings, check_poses, nominal_centre_of, radius_determined

    obs = accel_observations(x, use=use, sample_rate=log.sample_rate, **detector)
    centre, radius = check_poses(obs, model or "accel9", log.sample_rate)
    n_free = int(sum(MODELS[model or "accel9"]))
    nominal = nominal_centre_of(obs)
    info.update(
        # what the single fit warns of the poses' spread (one hemisphere, a cap), as it words it
        warnings=_coverage_warnings(
            obs.points, centre, n_free, nominal, pose_table=obs.report.kind == "pose_table"
        ),
        notes=list(log.notes) + obs.warnings + obs.notes,
        static_intervals=obs.report.n_intervals,
        use=use,
        static_norm=obs.static_norm,
        fit_norm=float(radius),
        radius_determined=radius_determined(obs.points, centre),
    )
    return obs.points, info


def fit_prepared(
    prepared: list[tuple[str | int, np.ndarray, dict]], sensor: str, options: dict
) -> list[dict]:
    """One batch fit of prepared logs ``(name, points, info)``: one result dict per log.

    The accelerometer's reference magnitude follows each log's unit unless ``options["g"]``
    gives one, which must then fit that unit (:func:`calib_jax.batch.reference_for_log`; a log
    it does not fit gets a ``not_fitted`` entry). Used by :func:`calibrate_files` and by the
    recorder's multi-device fit.
    """
    import jax

    from .accel import detect_units
    from .batch import (
        calibrate_accel_batch,
        calibrate_mag_batch,
        reference_for_log,
    )

    options = dict(options)
    out, fit, gs = [], [], []
    g_given = options.pop("g", None) if sensor == "accel" else None
    for name, pts, info in prepared:
        if sensor == "accel":
            try:
                g = reference_for_log(
                    info["static_norm"],
                    g_given,
                    info.get("fit_norm"),
                    info.get("radius_determined", False),
                )
            except ValueError as exc:  # read and prepared, but the reference does not fit
                out.append({"path": str(name), "status": "not_fitted", "message": str(exc)})
                continue
            units = detect_units(
                info["static_norm"], info.get("fit_norm"), info.get("radius_determined", False)
            )
            info = {**info, "units": units or "counts", "g": g}
            gs.append(g)
        fit.append((name, pts, info))
    if not fit:
        return out
    raw, w = stack_rows([x for _, x, _ in fit])
    mask = w > 0
    # float64 for this fit only: the caller's (or a Dask worker's) jax setting is left as it was
    with jax.enable_x64(True):
        if sensor == "accel":
            # interval means: the pose checks ran on the host; the batch's own floor is the
            # model's parameter count (six faces for accel6, as calibrate_accel fits them)
            r = calibrate_accel_batch(raw, mask, g=np.asarray(gs), min_points=1, **options)
        else:
            r = calibrate_mag_batch(raw, mask, **options)
        entries = r.entries([str(name) for name, _, _ in fit])
        se_n = np.asarray(r.stderr_normalised)
    ref = {"field": options.get("field")} if sensor == "mag" else {}  # accel: each info's g
    for e, (_, pts, info), se in zip(entries, fit, se_n, strict=True):
        e["rms"] = _norm_rms(e, pts, info, sensor, options)
        if sensor == "accel":
            _judge_accel(e, info, options.get("model") or "accel9")
            out.append({**e, **info, **ref})
        else:
            out.append({**e, **info, **ref, **_judge_mag(e, pts, se, options)})
    return out


def _norm_rms(entry: dict, pts: np.ndarray, info: dict, sensor: str, options: dict) -> float:
    """The RMS of |calibrated| / magnitude - 1 over the points fitted, the quantity the single
    fits report (``rms_after`` of interval means; ``rms_after_pct`` / 100 of a magnetometer's
    samples, the radius its mean calibrated norm unless a field is given). The batch's own
    ``rms`` comes from the moment form, RMS(1 - |a|^2/g^2) / 2: equal to first order, 0.4 %
    apart on a hand-held log, so the table and the single fit disagreed."""
    p = np.asarray(entry["params"], float)
    if not np.all(np.isfinite(p)):
        return entry["rms"]
    if sensor == "accel":
        from .calibration import apply_params

        return float(
            np.sqrt(np.mean((np.linalg.norm(apply_params(p, pts), axis=1) / info["g"] - 1) ** 2))
        )
    r, radius = _mag_norms(p, pts, options)
    return float(np.sqrt(np.mean((r / radius - 1.0) ** 2)))


def _mag_norms(p: np.ndarray, pts: np.ndarray, options: dict) -> tuple[np.ndarray, float]:
    """A magnetometer entry's calibrated norms |W (x - c)| and the radius they are judged
    against: the field if given, else their mean (one rule for the rms and the verdict)."""
    r = np.linalg.norm((pts - p[:3]) @ p[3:].reshape(3, 3).T, axis=1)
    return r, options.get("field") or float(np.mean(r))


def _judge_mag(entry: dict, pts: np.ndarray, se_n: np.ndarray, options: dict) -> dict:
    """The single fit's checks on a batch entry: its poorly-determined rule on the normalised
    standard errors ``se_n`` (:func:`calib_jax.mag.poorly_determined`; the batch called 'ok'
    a phone's hand-held log whose full ellipsoid calib-jax mag --model full calls poorly
    determined) and :func:`calib_jax.mag.judge_fit` (the batch called 'ok' a phone's walk with
    a 14 % radial error that calib-jax mag calls failed, 'do not use'). The status, the
    warnings and, for a downgraded entry, its message."""
    from .mag import POORLY_DETERMINED, judge_fit, poorly_determined
    from .status import NO_CALIBRATION, is_usable, worst_status

    # fitted, then refused by the batch's own shell checks (NO_SHELL, RAN_AWAY): the single
    # fit's judgement still gives the words and warnings calib-jax mag would
    p = np.asarray(entry["params"], float)
    refused = entry.get("solver_status") in NO_CALIBRATION
    refused &= bool(np.all(np.isfinite(p)))
    if not is_usable(entry["status"]) and not refused:
        return {}
    centre, W = p[:3], p[3:].reshape(3, 3)
    radius = _mag_norms(p, pts, options)[1]
    model = options.get("model") or "full"
    status, warn = ("ok" if refused else entry["status"]), []
    poor = poorly_determined(se_n, model)
    if status == "ok" and poor:
        status = "poorly_determined"
        warn.append(POORLY_DETERMINED.format(", ".join(poor)))
    judged, more = judge_fit(pts, centre, W, status, model, radius)
    warn += more
    if refused:  # never better than the batch's verdict
        judged = worst_status(judged, entry["status"])
    out: dict = {"status": judged, "warnings": warn}
    if poor:
        out["poorly_determined"] = poor
    if refused and more:
        out["message"] = more[-1]
    elif judged != entry["status"]:  # the message says why: the last check that downgraded it
        out["message"] = more[-1] if judged != status and more else warn[0]
    return out


def _judge_accel(entry: dict, info: dict, model: str) -> None:
    """The single fit's status rule on a batch entry: a fit whose standard errors exceed 1 %
    of g is poorly determined, with the coverage warnings that say why (the batch called a
    one-hemisphere log with a z gain of 1.51 'ok' where calib-jax accel said so), and its rule
    that gains no accelerometer has, poses that are no rests, or parameters the poses do not
    determine at all, are no calibration (:func:`calib_jax.accel.implausible_gains`,
    :func:`calib_jax.accel.not_rests`, :func:`calib_jax.accel.undetermined`)."""
    from .accel import (
        POORLY_DETERMINED,
        implausible_gains,
        not_rests,
        poorly_determined,
        undetermined,
    )

    # parameters and standard errors in units of g: gains and cross terms over r / g,
    # biases over r
    from .status import NO_CALIBRATION

    r, g = info["fit_norm"], info["g"]
    scale = np.concatenate([np.full(6, r / g), np.full(3, r)])
    # fitted, then refused by the batch's shell checks (a walk taken for poses runs away):
    # the single fit's rule gives calib-jax accel's words for it
    refused = entry.get("solver_status") in NO_CALIBRATION
    if entry["status"] in ("ok", "not_converged") or refused:
        implausible = implausible_gains(np.asarray(entry["params"], float) / scale)
        if implausible:
            entry["status"] = "failed"
            entry["message"] = implausible
            return
        no_rests = not_rests(entry.get("rms", np.nan), info["static_intervals"])
        if no_rests:
            entry["status"] = "failed"
            entry["message"] = no_rests
            return
    if entry["status"] != "ok":
        return
    se_n = np.asarray(entry["stderr"], float) / scale
    why = undetermined(se_n, model)
    if why:
        entry["status"] = "failed"
        entry["message"] = why
        return
    poor = poorly_determined(se_n, model)
    if poor:
        entry["status"] = "poorly_determined"
        entry["message"] = POORLY_DETERMINED.format(", ".join(poor))
        entry["poorly_determined"] = poor


def _fit_chunk(
    paths: list[str],
    sensor: str,
    columns: str | None,
    options: dict,
    use: str = "means",
    detector: dict | None = None,
    sample_rate: float | None = None,
) -> list[dict]:
    """Prepare and fit one chunk of files (also the Dask task); ``detector`` holds the
    detector options (window, threshold_factor, min_static), converted per log by
    :func:`calib_jax.observations.detector_keywords`."""
    if sensor == "gyro":
        return [_gyro_entry(p, columns, options, detector, sample_rate) for p in paths]
    prepared, out = [], []
    for p in paths:
        log = None
        try:
            log = load_log(p, columns=columns, sensor=sensor, sample_rate=sample_rate)
            found = detector_keywords(sample_rate=log.sample_rate, **(detector or {}))
            pts, info = prepare_log(log, sensor, model=options.get("model"), use=use, **found)
            prepared.append((p, pts, info))
        except Exception as exc:  # noqa: BLE001 - one bad file must never stop a fleet
            out.append(_unfitted(p, exc, log))
    out += fit_prepared(prepared, sensor, options)
    order = {str(p): k for k, p in enumerate(paths)}
    return sorted(out, key=lambda d: order[d["path"]])


def _unfitted(p, exc: Exception, log=None) -> dict:
    """The entry of a file that was not fitted: ``load_error`` when it could not be read
    (``log`` None), ``not_fitted`` when it was read but holds nothing the fit can use (then
    with the loader's notes). ValueError/OSError carry a message meant for the user; anything
    else is a bug in this file's path, reported with its type instead of aborting the others."""
    known = isinstance(exc, ValueError | OSError)
    doing = "reading" if log is None else "preparing"
    msg = str(exc) if known else f"{type(exc).__name__} while {doing} {p}: {exc}"
    if isinstance(exc, OtherSensorsFile):  # read: another sensor's file of the recording
        return {"path": str(p), "status": "not_fitted", "message": msg}
    if log is None:
        return {"path": str(p), "status": "load_error", "message": msg}
    return {"path": str(p), "status": "not_fitted", "message": msg, "notes": list(log.notes)}


def _gyro_entry(
    p, columns, options: dict, detector: dict | None, sample_rate: float | None = None
) -> dict:
    """One gyro log through :func:`calib_jax.calibrate_gyro` (the same fit, candidate effects
    and checks as ``calib-jax gyro``; its compiled parts are shared by every log of a padded
    shape): the batch entry, with C row by row then b as ``params`` and the miss between
    poses in degrees as ``rms``."""
    from .gyro import calibrate_gyro

    log = None
    try:
        log = load_log(p, columns=columns, sample_rate=sample_rate)
        found = detector_keywords(sample_rate=log.sample_rate, **(detector or {}))
        cal = calibrate_gyro(log, accel_options={"g": options.get("g"), **found})
    except Exception as exc:  # noqa: BLE001 - one bad file must never stop a fleet
        return _unfitted(p, exc, log)
    return {
        "path": str(p),
        "status": cal.status,
        "solver_status": cal.solver_status,
        "message": cal.solver_message,
        "params": [*np.ravel(cal.matrix), *cal.bias],
        "stderr": [*np.ravel(cal.stderr_matrix), *cal.stderr_bias],
        "rms": cal.rms_after_deg,
        "rms_before_deg": cal.rms_before_deg,
        "noise_floor_deg": cal.noise_floor_deg,
        "iterations": cal.iterations,
        "n_points": cal.n_motions,
        "units": cal.input_units,
        "g_sensitivity": np.ravel(cal.g_sensitivity).tolist(),
        "scale_asymmetry": list(cal.scale_asymmetry),
        "notes": cal.warnings + cal.notes,
    }


def _chunks(items: list, size: int) -> Iterator[list]:
    for i in range(0, len(items), size):
        yield items[i : i + size]


def calibrate_files(
    paths: Iterable[str | Path],
    *,
    sensor: str = "accel",
    chunk: int = 256,
    columns: str | None = None,
    use: str = "means",
    progress: bool | None = None,
    detector: dict | None = None,
    sample_rate: float | None = None,
    **options,
) -> Iterator[dict]:
    """Calibrate many logs chunk by chunk, yielding one result dict per file, in order.

    Each log is prepared as :func:`calib_jax.calibrate_accel` / :func:`calib_jax.calibrate_mag`
    would prepare it (:func:`prepare_log`; ``use`` as in ``calibrate_accel``), so a file gets
    the parameters its single fit gives. ``detector``: the static detector's options for every
    log (``window``, ``threshold_factor``, ``min_static`` in seconds, or samples for a log
    without a rate; default automatic). ``sample_rate``: Hz for logs without a time column
    (every file). ``options`` go to the batch fit (``g``, ``model``,
    ``solver``, ``field`` ...). Memory holds one chunk. ``progress``: a progress bar
    counting files and failures (:func:`calib_jax.progress.progress_bar`; None: on a
    terminal or in a notebook only).
    """
    paths = _checked_request(paths, sensor, options)
    results = (
        res
        for part in _chunks(paths, chunk)
        for res in _fit_chunk(part, sensor, columns, options, use, detector, sample_rate)
    )
    return _counted(results, len(paths), progress, sensor)


def _checked_request(paths, sensor: str, options: dict) -> list[str]:
    """The paths as strings, with what every file shares checked once, when the call is made:
    a model the batch cannot fit ('auto' is a single fit's choice) came back as each file's
    'load_error' with a bare KeyError, and one path given as a string was read letter by
    letter."""
    if isinstance(paths, str | os.PathLike):
        raise TypeError(
            f"paths must be a list of log files, got one path {str(paths)!r}: pass "
            f"[{str(paths)!r}], or sorted(Path(folder).glob('*.csv')) for a folder's logs"
        )
    from .batch import ACCEL_MODELS
    from .models.mag import N_PARAMS

    models = {"accel": tuple(ACCEL_MODELS), "mag": tuple(N_PARAMS)}.get(sensor)
    model = options.get("model")
    if models is not None and model is not None and model not in models:
        raise ValueError(
            f"model must be one of {models} for a batch of {sensor} logs (one model for every "
            f"file; 'auto' chooses per log in calib_jax.calibrate_{sensor}), got {model!r}"
        )
    return [str(p) for p in paths]


def _counted(results: Iterator[dict], total: int, progress, sensor: str) -> Iterator[dict]:
    """Pass the results through, counting files and failures on a progress bar."""
    failed = 0
    with progress_bar(total, progress, f"calibrating {sensor}") as bar:
        for res in results:
            failed += res["status"] != "ok"
            bar.update(1)
            bar.set_postfix(not_calibrated=failed, refresh=False)
            yield res


def to_dataframe(results, sensor: str | None = None):
    """The result dicts of :func:`calibrate_files` (or ``calib-jax batch --json``'s
    ``results``) as a pandas DataFrame, one row per file (:func:`calib_jax.display.fleet_rows`)."""
    from .display import fleet_rows
    from .display import to_dataframe as frame

    return frame(fleet_rows(results, sensor))


def calibrate_files_dask(
    paths: Iterable[str | Path],
    *,
    scheduler: str | None = None,
    n_workers: int = 2,
    sensor: str = "accel",
    chunk: int = 256,
    columns: str | None = None,
    use: str = "means",
    detector: dict | None = None,
    sample_rate: float | None = None,
    progress: bool | None = None,
    **options,
) -> Iterator[dict]:
    """:func:`calibrate_files` with the chunks spread over a Dask cluster; each file's result
    is yielded as soon as its chunk is done (chunks in the order they finish, files in order
    within a chunk: sort by ``path`` if you need the input order, or ``list()`` it).

    ``scheduler``: the address of a running scheduler (``tcp://host:8786``); default a
    ``LocalCluster`` with ``n_workers`` single-threaded worker processes on this machine,
    started when the first result is asked for and closed after the last (or when the
    iterator is closed). Needs ``dask[distributed]`` (``pip install 'calib_jax[dask]'``).
    Workers must be able to read the paths (a shared file system, or the same paths on every
    machine). ``progress``: as in :func:`calibrate_files`, advancing as chunks finish.
    """
    try:
        import dask.distributed  # noqa: F401
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            "calibrate_files_dask needs dask[distributed]: pip install 'calib_jax[dask]'"
        ) from exc
    parts = list(_chunks(_checked_request(paths, sensor, options), chunk))
    task = dict(sensor=sensor, columns=columns, options=options, use=use, detector=detector)
    task["sample_rate"] = sample_rate
    return _stream_from_dask(parts, task, scheduler, n_workers, progress)


def _stream_from_dask(parts, task, scheduler, n_workers, progress) -> Iterator[dict]:
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler is None:
        cluster = LocalCluster(
            n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=None
        )
        client = Client(cluster)
    else:
        client = Client(scheduler)
    try:
        futures = client.map(_fit_chunk, parts, pure=False, **task)
        results = (res for future in as_completed(futures) for res in future.result())
        total = sum(len(p) for p in parts)
        yield from _counted(results, total, progress, task["sensor"])
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
