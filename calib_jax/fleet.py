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

import sys
import time
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from .io.files import load_log
from .lm import is_converged, status_message
from .padding import bucket

SENSORS = ("accel", "mag")


def prepare(
    path: str | Path, sensor: str = "accel", columns: str | None = None
) -> tuple[np.ndarray, np.ndarray, dict]:
    """Samples (N, 3), fit mask (N,) and notes for one log.

    Accelerometer: the static samples (moving-variance detector with its automatic threshold),
    i.e. paper 1's sample-level fit. Magnetometer: every finite sample.
    """
    if sensor not in SENSORS:
        raise ValueError(f"sensor must be one of {SENSORS}, got {sensor!r}")
    log = load_log(path, columns=columns, sensor=sensor)
    x = log.acc if sensor == "accel" else log.mag
    if x is None:
        raise ValueError(f"{path}: no {sensor} columns; map them with --columns")
    x = np.asarray(x, float)
    finite = np.all(np.isfinite(x), axis=1)
    info = {"samples": len(x), "notes": list(log.notes)}
    if sensor == "mag":
        return x, finite, info
    from .static import detect_static

    report = detect_static(x, sample_rate=log.sample_rate, valid=finite)
    info["static_intervals"] = report.n_intervals
    return x, report.mask & finite, info


def _fit_chunk(paths: list[str], sensor: str, columns: str | None, options: dict) -> list[dict]:
    """Prepare and fit one chunk of files (also the Dask task)."""
    import jax

    jax.config.update("jax_enable_x64", True)
    from .batch import (
        _units_from_norm,
        calibrate_accel_batch,
        calibrate_mag_batch,
        reference_for_log,
    )

    options = dict(options)
    g_given = options.pop("g", None) if sensor == "accel" else None
    prepared, out, gs = [], [], []
    for p in paths:
        try:
            x, m, info = prepare(p, sensor, columns)
            if sensor == "accel":
                # the reference magnitude follows each log's unit unless the user gave one,
                # which must then fit that unit (m/s^2 logs with g = 1 gave gains of 9.8)
                norm = float(np.median(np.linalg.norm(x[m], axis=1))) if m.any() else np.nan
                g = reference_for_log(norm, g_given)
                info.update(units=_units_from_norm(norm), g=g)
                gs.append(g)
            prepared.append((p, x, m, info))
        except Exception as exc:  # noqa: BLE001 - one bad file must never stop a fleet
            # ValueError/OSError carry a message meant for the user; anything else is a bug in
            # reading this file, reported with its type instead of aborting the other files
            known = isinstance(exc, ValueError | OSError)
            msg = str(exc) if known else f"{type(exc).__name__} while reading {p}: {exc}"
            out.append({"path": str(p), "status": "load_error", "message": msg})
    if prepared:
        n = bucket(max(len(x) for _, x, _, _ in prepared))
        raw = np.zeros((len(prepared), n, 3))
        mask = np.zeros((len(prepared), n), bool)
        for i, (_, x, m, _) in enumerate(prepared):
            raw[i, : len(x)] = np.where(np.isfinite(x), x, 0.0)
            mask[i, : len(x)] = m
        fit = calibrate_accel_batch if sensor == "accel" else calibrate_mag_batch
        if sensor == "accel":
            options["g"] = np.asarray(gs)
        r = fit(raw, mask, **options)
        params, stderr = np.asarray(r.params), np.asarray(r.stderr)
        for i, (p, _, _, info) in enumerate(prepared):
            code = int(r.status[i])
            out.append(
                {
                    "path": str(p),
                    "status": "ok" if is_converged(code) else "failed",
                    "solver_status": code,
                    "message": status_message(code),
                    "params": params[i].tolist(),
                    "stderr": stderr[i].tolist(),
                    "rms": float(r.rms[i]),
                    "iterations": int(r.iterations[i]),
                    "n_samples": int(r.n_samples[i]),
                    **info,
                }
            )
    order = {str(p): k for k, p in enumerate(paths)}
    return sorted(out, key=lambda d: order[d["path"]])


def _chunks(items: list, size: int) -> Iterator[list]:
    for i in range(0, len(items), size):
        yield items[i : i + size]


def calibrate_files(
    paths: Iterable[str | Path],
    *,
    sensor: str = "accel",
    chunk: int = 256,
    columns: str | None = None,
    progress: bool = True,
    **options,
) -> Iterator[dict]:
    """Calibrate many logs chunk by chunk, yielding one result dict per file, in order.

    ``options`` go to the batch fit (``g``, ``model``, ``solver``, ``field`` ...). Memory
    holds one chunk; with ``progress`` a line on stderr counts files, failures and rate.
    """
    paths = [str(p) for p in paths]
    t0, done, failed = time.perf_counter(), 0, 0
    for part in _chunks(paths, chunk):
        for res in _fit_chunk(part, sensor, columns, options):
            done += 1
            failed += res["status"] != "ok"
            yield res
        if progress:
            rate = done / max(time.perf_counter() - t0, 1e-9)
            print(
                f"\r[{done}/{len(paths)}] {100 * done / len(paths):5.1f} %  "
                f"{failed} not calibrated  {rate:.0f} files/s",
                end="",
                file=sys.stderr,
                flush=True,
            )
    if progress and paths:
        print(file=sys.stderr)


def calibrate_files_dask(
    paths: Iterable[str | Path],
    *,
    scheduler: str | None = None,
    n_workers: int = 2,
    sensor: str = "accel",
    chunk: int = 256,
    columns: str | None = None,
    **options,
) -> list[dict]:
    """:func:`calibrate_files` with the chunks spread over a Dask cluster.

    ``scheduler``: the address of a running scheduler (``tcp://host:8786``); default a
    ``LocalCluster`` with ``n_workers`` single-threaded worker processes on this machine.
    Needs ``dask[distributed]`` (``pip install 'calib_jax[dask]'``). Workers must be able to
    read the paths (a shared file system, or the same paths on every machine).
    """
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            "calibrate_files_dask needs dask[distributed]: pip install 'calib_jax[dask]'"
        ) from exc
    paths = [str(p) for p in paths]
    cluster = None
    if scheduler is None:
        cluster = LocalCluster(
            n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=None
        )
        client = Client(cluster)
    else:
        client = Client(scheduler)
    try:
        parts = list(_chunks(paths, chunk))
        futures = client.map(
            _fit_chunk, parts, sensor=sensor, columns=columns, options=options, pure=False
        )
        results = client.gather(futures)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return [r for part in results for r in part]
