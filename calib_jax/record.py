"""Guided recording: live coverage feedback while a board is turned, then its calibration.

One reader thread per port (:class:`calib_jax.io.serial.SerialReader`), each with its own
append-only log. The main thread, once a ``progress_interval``, runs the static detector on
each device's accumulated accelerometer data and reports what paper 1's protocol still lacks:

* poses: distinct static directions (10 degrees apart, :func:`calib_jax.static.distinct_directions`)
  against paper 1's 48-pose target;
* faces: whether some pose has had each of +x, -x, +y, -y, +z, -z pointing up (within 45
  degrees; the accelerometer reads the upward specific force);
* octants of the sphere of directions no pose has visited yet;
* for a magnetometer, the share of the sphere of field directions covered
  (:func:`calib_jax.sphere.sphere_coverage`, 100 equal-area cells) and the faces not yet seen;
* for a gyroscope (``gyro``, or ``marg`` with gyro columns), the axes hardly turned about yet
  (:func:`calib_jax.gyro.turn_axes_missing`): its fit needs turns about all three.

With ``resume``, the rows already in a log count towards its coverage (they are calibrated
too). A log this session wrote nothing into is not calibrated as if it were this session's.

The session stops at ``seconds``, when every device's coverage is enough (``auto_stop``), when
every device has gone away for longer than ``max_reconnect_seconds``, or on Ctrl-C; the logs
are flushed and synced in every case. Then each log is read back with
:func:`calib_jax.io.load_log` (the file is what gets calibrated, whatever happened in memory)
and calibrated: one device with :func:`calib_jax.calibrate_accel` /
:func:`calib_jax.calibrate_mag` (and for ``marg`` both, plus the magnetometer-to-accelerometer
rotation), several devices with one vmapped batch fit
(:func:`calib_jax.batch.calibrate_accel_batch` / :func:`calib_jax.batch.calibrate_mag_batch`).
Results are written as JSON beside each log (``FILE`` -> ``FILE.calib.json``, or
``FILE.accel.calib.json`` and ``FILE.mag.calib.json`` for ``marg``).

Host side only: threads, files and printing; the fits are the package's jitted cores.
"""

from __future__ import annotations

import itertools
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .calibration import BatchRecord
from .io.serial import Batch, SerialReader, log_columns
from .observations import detector_keywords
from .progress import progress_bar
from .static import detect_static, distinct_directions

PAPER1_POSES = 48
"""Paper 1's protocol: 48 static orientations."""
MAG_TARGET = 0.7
"""Share of the sphere of field directions a magnetometer session should cover (calibrate_mag
warns below 0.5)."""
FACE_COS = np.cos(np.deg2rad(45.0))
SENSORS = ("accel", "mag", "marg", "gyro")
_FACES = ("+x", "-x", "+y", "-y", "+z", "-z")


# ---------------------------------------------------------------------------------------------
# coverage


def _sphere_centre(points: np.ndarray) -> np.ndarray:
    """Algebraic sphere-fit centre of ``points`` (n, 3), or the origin when they do not pin
    one down (too few, or all on one side)."""
    if len(points) < 6:
        return np.zeros(3)
    A = np.column_stack([2.0 * points, np.ones(len(points))])
    b = np.sum(points * points, axis=1)
    sol, _, rank, sv = np.linalg.lstsq(A, b, rcond=None)
    c = sol[:3]
    r2 = sol[3] + c @ c
    if rank < 4 or sv[-1] < 1e-6 * sv[0] or not r2 > 0 or np.linalg.norm(c) > np.sqrt(r2):
        return np.zeros(3)
    return c


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=1, keepdims=True)
    return v[n[:, 0] > 0] / n[n[:, 0] > 0]


def _faces_missing(dirs: np.ndarray) -> list[str]:
    axes = np.vstack([np.eye(3), -np.eye(3)])[[0, 3, 1, 4, 2, 5]]
    if len(dirs) == 0:
        return list(_FACES)
    return [f for f, a in zip(_FACES, axes, strict=True) if not np.any(dirs @ a >= FACE_COS)]


def _octants_missing(dirs: np.ndarray) -> list[str]:
    seen = {tuple(bool(v) for v in d >= 0) for d in dirs}
    out = []
    for signs in itertools.product((True, False), repeat=3):
        if signs not in seen:
            out.append("".join(("+" if s else "-") + a for s, a in zip(signs, "xyz", strict=True)))
    return out


def _detector(window, threshold_factor, min_static, sample_rate) -> dict:
    """The static detector's keywords for one recorded log (a minimum duration in seconds
    only where the log has a rate)."""
    return detector_keywords(
        window=window,
        threshold_factor=threshold_factor,
        min_static=min_static if sample_rate else None,
        sample_rate=sample_rate,
    )


@dataclass(frozen=True)
class Coverage:
    """What one device's recording covers so far."""

    sensor: str
    samples: int
    static_intervals: int = 0
    poses: int = 0
    """Distinct static directions, 10 degrees apart."""
    target_poses: int = PAPER1_POSES
    faces_missing: list[str] = field(default_factory=lambda: list(_FACES))
    """Axes no static pose has had pointing up yet (accelerometer)."""
    octants_missing: list[str] = field(default_factory=list)
    mag_fraction: float | None = None
    """Share of the sphere of field directions covered (magnetometer)."""
    mag_target: float = MAG_TARGET
    mag_faces_missing: list[str] = field(default_factory=list)
    turn_axes_missing: list[str] | None = None
    """Gyro axes hardly turned about yet (:func:`calib_jax.gyro.turn_axes_missing`); None when
    no gyro is recorded."""

    @property
    def uses_accel(self) -> bool:
        return self.sensor in ("accel", "marg", "gyro")

    @property
    def uses_gyro(self) -> bool:
        return self.turn_axes_missing is not None

    @property
    def uses_mag(self) -> bool:
        return self.sensor in ("mag", "marg")

    @property
    def enough(self) -> bool:
        ok = True
        if self.uses_accel:
            ok &= (
                self.poses >= self.target_poses
                and not self.faces_missing
                and not self.octants_missing
            )
        if self.uses_mag:
            ok &= (self.mag_fraction or 0.0) >= self.mag_target and not self.mag_faces_missing
        if self.uses_gyro:
            ok &= not self.turn_axes_missing
        return bool(ok)

    @property
    def fraction(self) -> float:
        """How far along to enough, 0 to 1: the lower of poses / target poses and sphere
        share / target share (below 1 until :attr:`enough`, whatever else is missing)."""
        parts = [1.0]
        if self.uses_accel:
            parts.append(self.poses / self.target_poses)
        if self.uses_mag:
            parts.append((self.mag_fraction or 0.0) / self.mag_target)
        return 1.0 if self.enough else min(min(parts), 0.99)

    def missing(self) -> str:
        """What is still missing, in words ('' when enough)."""
        parts = []
        if self.uses_accel:
            if self.faces_missing:
                parts.append("no pose with " + ", ".join(self.faces_missing) + " up yet")
            if self.octants_missing:
                parts.append("octants not visited: " + " ".join(self.octants_missing))
            if self.poses < self.target_poses:
                parts.append(f"{self.target_poses - self.poses} more poses")
        if self.uses_mag:
            if self.mag_faces_missing:
                parts.append("field never along " + ", ".join(self.mag_faces_missing))
            if (self.mag_fraction or 0.0) < self.mag_target:
                parts.append("tumble through more orientations")
        if self.turn_axes_missing:
            parts.append(
                "no turn about the gyro's "
                + ", ".join(self.turn_axes_missing)
                + f" ax{'i' if len(self.turn_axes_missing) == 1 else 'e'}s yet (between poses, "
                "turn the board about each of its axes)"
            )
        return "; ".join(parts)

    def line(self) -> str:
        """One progress line."""
        out = [f"{self.samples} samples"]
        if self.uses_accel:
            out.append(f"{self.static_intervals} static, {self.poses}/{self.target_poses} poses")
        if self.uses_mag and self.mag_fraction is not None:
            out.append(
                f"mag {100 * self.mag_fraction:.0f} % of the sphere "
                f"(target {100 * self.mag_target:.0f} %)"
            )
        miss = self.missing()
        return ", ".join(out) + (f"; missing: {miss}" if miss else "; coverage enough")


def assess_coverage(
    acc: np.ndarray | None,
    mag: np.ndarray | None,
    gyro: np.ndarray | None = None,
    *,
    sensor: str = "accel",
    sample_rate: float | None = None,
    window: int | None = None,
    min_duration: float | None = None,
    threshold_factor: float | None = None,
    target_poses: int = PAPER1_POSES,
    mag_target: float = MAG_TARGET,
) -> Coverage:
    """The coverage of a recording so far (see the module docstring)."""
    if sensor not in SENSORS:
        raise ValueError(f"sensor must be one of {SENSORS}, got {sensor!r}")
    n = max(len(acc) if acc is not None else 0, len(mag) if mag is not None else 0)
    kw: dict = {"sensor": sensor, "samples": n, "target_poses": target_poses}
    kw["mag_target"] = mag_target
    if sensor == "gyro" or (sensor == "marg" and gyro is not None):
        from .gyro import turn_axes_missing

        g = np.zeros((0, 3)) if gyro is None else np.asarray(gyro, float)
        kw["turn_axes_missing"] = turn_axes_missing(g[np.all(np.isfinite(g), axis=1)])
    if sensor in ("accel", "marg", "gyro") and acc is not None and len(acc) >= 8:
        x = np.asarray(acc, float)
        ok = np.all(np.isfinite(x), axis=1)
        rep = detect_static(
            x,
            sample_rate=sample_rate,
            valid=ok,
            **_detector(window, threshold_factor, min_duration, sample_rate),
        )
        means = rep.means()
        centre = _sphere_centre(means)
        dirs = _unit(means - centre)
        kw.update(
            static_intervals=rep.n_intervals,
            poses=distinct_directions(means, centre) if len(means) else 0,
            faces_missing=_faces_missing(dirs),
            octants_missing=_octants_missing(dirs),
        )
    elif sensor in ("accel", "marg", "gyro"):
        kw.update(octants_missing=_octants_missing(np.zeros((0, 3))))
    if sensor in ("mag", "marg") and mag is not None and len(mag) >= 8:
        from .sphere import sphere_coverage

        m = np.asarray(mag, float)
        m = m[np.all(np.isfinite(m), axis=1)]
        m = m[:: max(1, len(m) // 5000)]  # a few thousand directions say as much
        dirs = _unit(m - _sphere_centre(m))
        frac = sphere_coverage(dirs)[0] if len(dirs) else 0.0
        kw.update(mag_fraction=float(frac), mag_faces_missing=_faces_missing(dirs))
    elif sensor in ("mag", "marg"):
        kw.update(mag_fraction=0.0, mag_faces_missing=list(_FACES))
    return Coverage(**kw)


def _rate(t: np.ndarray) -> float | None:
    dt = np.diff(t[-4000:])
    dt = dt[dt > 0]
    return float(1.0 / np.median(dt)) if dt.size else None


# ---------------------------------------------------------------------------------------------
# the session


def device_paths(out: str | Path, n: int) -> list[Path]:
    """The log of each device: ``out`` itself for one, ``STEM.devK.SUFFIX`` for several."""
    out = Path(out)
    if n == 1:
        return [out]
    suffix = out.suffix or ".csv"
    return [out.with_name(f"{out.stem}.dev{k}{suffix}") for k in range(n)]


def calibration_paths(log: str | Path, sensor: str) -> dict[str, Path]:
    """Where the JSON of each calibrated sensor goes, beside the log."""
    log = Path(log)
    if sensor == "marg":
        return {
            "accel": log.with_suffix(".accel.calib.json"),
            "mag": log.with_suffix(".mag.calib.json"),
            "marg": log.with_suffix(".marg.json"),
        }
    return {sensor: log.with_suffix(".calib.json")}


@dataclass
class Device:
    """One port of a session: its reader, what it has read, and its coverage."""

    url: str
    path: Path
    reader: SerialReader
    batches: list[Batch] = field(default_factory=list)
    coverage: Coverage | None = None
    error: str | None = None
    thread: threading.Thread | None = None
    lock: threading.Lock = field(default_factory=threading.Lock)

    def data(self) -> Batch:
        with self.lock:
            merged = Batch.concat(self.batches)
            self.batches = [merged] if len(merged) else []
        return merged

    @property
    def done(self) -> bool:
        return self.thread is not None and not self.thread.is_alive()


@dataclass
class Session:
    """A finished recording: the devices and why it stopped."""

    devices: list[Device]
    sensor: str
    reason: str
    """'seconds', 'covered', 'devices_gone' or 'interrupted'."""
    seconds: float


def _run_reader(dev: Device, stop: threading.Event) -> None:
    try:
        with dev.reader as r:
            for batch in r:
                if len(batch):
                    with dev.lock:
                        dev.batches.append(batch)
                if stop.is_set():
                    break
    except Exception as exc:  # noqa: BLE001 - reported by the main thread, never swallowed
        dev.error = f"{type(exc).__name__}: {exc}"


def _stderr(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def record_session(
    ports: Sequence[str],
    out: str | Path,
    *,
    sensor: str = "accel",
    seconds: float | None = None,
    auto_stop: bool = True,
    target_poses: int = PAPER1_POSES,
    mag_target: float = MAG_TARGET,
    window: int | None = None,
    min_static: float | None = None,
    threshold_factor: float | None = None,
    progress_interval: float = 1.0,
    echo: Callable[[str], None] | None = _stderr,
    progress: bool | None = None,
    **reader_options,
) -> Session:
    """Record from every port at once until time, coverage, devices gone, or Ctrl-C.

    ``reader_options`` go to each :class:`SerialReader` (``baudrate``, ``columns``,
    ``scale``, ``resume``, ``overwrite``, ``max_reconnect_seconds`` ...). Errors a reader
    would raise at the start (an existing log without ``resume``) are raised here, before
    any port is opened.

    ``progress``: a progress bar of the coverage (:attr:`Coverage.fraction`, the least
    covered device) with the coverage line beside it, in place of a line every
    ``progress_interval``; None: on a terminal or in a notebook, lines otherwise.
    """
    if sensor not in SENSORS:
        raise ValueError(f"sensor must be one of {SENSORS}, got {sensor!r}")
    ports = list(ports)
    if not ports:
        raise ValueError("give at least one port (--port URL)")
    if len(set(ports)) != len(ports):
        raise ValueError(f"a port is given twice: {ports}")
    say = echo or (lambda s: None)
    detector = {"window": window, "min_static": min_static, "threshold_factor": threshold_factor}
    paths = device_paths(out, len(ports))
    devices = []
    for k, (url, path) in enumerate(zip(ports, paths, strict=True)):
        tag = f"[{k}] " if len(ports) > 1 else ""
        reader = SerialReader(
            url, log=path, on_message=lambda s, tag=tag: say(tag + s), **reader_options
        )
        devices.append(Device(url=url, path=path, reader=reader))
        if reader_options.get("resume"):
            _seed_from_log(devices[-1], say)
    stop = threading.Event()
    for dev in devices:
        dev.thread = threading.Thread(
            target=_run_reader, args=(dev, stop), name=f"serial {dev.url}", daemon=True
        )
    say(
        f"recording {sensor} from {', '.join(ports)} into {', '.join(map(str, paths))}; "
        "Ctrl-C stops and calibrates"
    )
    t0 = time.monotonic()
    reason = "devices_gone"
    bar = progress_bar(100, progress, f"recording {sensor}", unit="%")
    show = say if bar.disable else (lambda line: _to_bar(bar, devices))
    try:
        for dev in devices:
            dev.thread.start()
        next_report = t0 + progress_interval
        while True:
            stop.wait(min(0.1, progress_interval))
            now = time.monotonic()
            if seconds is not None and now - t0 >= seconds:
                reason = "seconds"
                break
            if all(dev.done for dev in devices):
                reason = "devices_gone"
                break
            if now >= next_report:
                next_report = now + progress_interval
                _assess(devices, sensor, detector, target_poses, mag_target)
                show(_progress(devices, now - t0))
                if auto_stop and all(d.coverage is not None and d.coverage.enough for d in devices):
                    reason = "covered"
                    break
    except KeyboardInterrupt:
        reason = "interrupted"
    finally:
        stop.set()
        for dev in devices:
            if dev.thread.is_alive():
                dev.thread.join(timeout=10.0)
            if dev.thread.is_alive():  # stuck in a driver call: close from here
                dev.reader.close()
    _assess(devices, sensor, detector, target_poses, mag_target)
    elapsed = time.monotonic() - t0
    if not bar.disable:
        _to_bar(bar, devices)
        bar.close()
    say(_progress(devices, elapsed))
    words = {
        "seconds": "time is up",
        "covered": "coverage is enough",
        "devices_gone": "every device has gone",
        "interrupted": "interrupted (Ctrl-C)",
    }
    say(f"stopped after {elapsed:.1f} s: {words[reason]}")
    for k, dev in enumerate(devices):
        tag = f"[{k}] " if len(devices) > 1 else ""
        say(f"{tag}{dev.url}: {dev.reader.stats.summary()}; log {dev.path}")
        if dev.error:
            say(f"{tag}{dev.url}: reader stopped on an error: {dev.error}")
    return Session(devices=devices, sensor=sensor, reason=reason, seconds=elapsed)


def _seed_from_log(dev: Device, say: Callable[[str], None]) -> None:
    """A resumed log's rows count towards the coverage, as they count in the fit."""
    from .io.files import load_log

    if not dev.path.exists() or dev.path.stat().st_size == 0:
        return
    try:
        lg = load_log(dev.path)
    except ValueError as exc:
        say(f"{dev.path}: its rows do not count towards the coverage shown ({exc})")
        return
    if not len(lg):
        return
    t = lg.t if lg.t is not None else np.zeros(len(lg))
    cols = tuple(log_columns(list(lg.columns)))
    dev.batches.append(Batch(t=t, acc=lg.acc, gyro=lg.gyro, mag=lg.mag, temp=lg.temp, columns=cols))
    say(f"{dev.path}: {len(lg)} rows from before count towards the coverage")


def _assess(devices, sensor, detector, target_poses, mag_target) -> None:
    for dev in devices:
        b = dev.data()
        dev.coverage = assess_coverage(
            b.acc,
            b.mag,
            b.gyro,
            sensor=sensor,
            sample_rate=_rate(b.t) if len(b) > 1 else None,
            window=detector.get("window"),
            min_duration=detector.get("min_static"),
            threshold_factor=detector.get("threshold_factor"),
            target_poses=target_poses,
            mag_target=mag_target,
        )


def _to_bar(bar, devices: list[Device]) -> None:
    """The bar at the least covered device's share, its coverage line beside it."""
    least = min(devices, key=lambda d: d.coverage.fraction)
    bar.n = round(100 * least.coverage.fraction)
    covered = sum(d.coverage.enough for d in devices)
    tag = f"{covered}/{len(devices)} covered; least: " if len(devices) > 1 else ""
    bar.set_postfix_str(tag + least.coverage.line())


def _progress(devices: list[Device], elapsed: float) -> str:
    parts = []
    for k, dev in enumerate(devices):
        tag = f"[{k}] " if len(devices) > 1 else ""
        status = dev.reader.status
        state = "" if status in ("connected", "closed") else f" ({status})"
        if dev.error:
            state = f" (stopped on an error: {dev.error})"
        parts.append(f"{tag}{dev.coverage.line()}{state}")
    sep = "\n  " if len(parts) > 1 else ""
    return f"{elapsed:6.1f} s  " + sep + sep.join(parts)


# ---------------------------------------------------------------------------------------------
# calibration of what was recorded


def calibrate_recording(
    path: str | Path,
    sensor: str,
    *,
    g: float | None = None,
    field: float | None = None,
    window: int | None = None,
    min_static: float | None = None,
    threshold_factor: float | None = None,
    sensor_id: str | None = None,
    solver: str = "lm1",
    echo: Callable[[str], None] | None = print,
) -> dict[str, object]:
    """Calibrate one recorded log and write the JSON beside it; returns {name: result}.

    The JSON is written atomically; when it cannot be (a full disk) the error is printed and
    listed under ``"save_errors"``, and the log is left as it is.

    ``accel``: :class:`calib_jax.AccelCalibration`; ``mag``: :class:`calib_jax.MagCalibration`;
    ``gyro``: :class:`calib_jax.GyroCalibration` (its accelerometer fitted first);
    ``marg``: the first two and, when the data allow it, the magnetometer-to-accelerometer
    rotation (:func:`calib_jax.align_mag_to_accel`) and the gyroscope when the log has one,
    written as ``.marg.json``: the board's :class:`calib_jax.marg.MARGRecord`, as ``calib-jax
    marg`` writes it).
    """
    from .accel import calibrate_accel
    from .io.files import load_log
    from .mag import calibrate_mag

    say = echo or (lambda s: None)
    log = load_log(path)
    out = calibration_paths(path, sensor)
    results: dict[str, object] = {}
    errors: list[str] = []  # JSON files that could not be written (a full disk)
    if sensor in ("accel", "marg"):
        cal = calibrate_accel(
            log,
            g=g,
            sensor_id=sensor_id,
            solver=solver,
            **_detector(window, threshold_factor, min_static, log.sample_rate),
        )
        wrote = _save(lambda: cal.save(out["accel"]), out["accel"], errors)
        say(f"accelerometer, {path}:\n{cal.report()}\n{wrote[2:]}")
        results["accel"] = cal
    if sensor in ("mag", "marg"):
        mcal = calibrate_mag(log, field=field, sensor_id=sensor_id, solver=solver)
        wrote = _save(lambda: mcal.save(out["mag"]), out["mag"], errors)
        say(f"magnetometer, {path}:\n{mcal.report()}\n{wrote[2:]}")
        results["mag"] = mcal
    if sensor == "gyro":
        from .gyro import calibrate_gyro

        detector = _detector(window, threshold_factor, min_static, log.sample_rate)
        gcal = calibrate_gyro(
            log, sensor_id=sensor_id, solver=solver, accel_options={"g": g, **detector}
        )
        wrote = _save(lambda: gcal.save(out["gyro"]), out["gyro"], errors)
        say(f"gyroscope, {path}:\n{gcal.report()}\n{wrote[2:]}")
        results["gyro"] = gcal
    if sensor == "marg":
        from .align import align_mag_to_accel
        from .marg import _gyro_block, _record
        from .status import worst_status

        try:
            al = align_mag_to_accel(results["accel"].apply(log.acc), results["mag"].apply(log.mag))
        except ValueError as exc:
            say(f"no accel-mag rotation: {exc}")
        else:
            warn = [f"alignment: {w}" for w in al.warnings]
            gyro = _gyro_block(log, results["accel"], "static", warn)
            rec = _record(results["accel"], "static", results["mag"], al, warn, source=str(path))
            if gyro is not None:
                rec = replace(rec, gyro=gyro, status=worst_status(rec.status, gyro.status))
            wrote = _save(lambda: rec.save(out["marg"]), out["marg"], errors)
            say(rec.alignment_text() + wrote)
            results["marg"] = rec
    if errors:
        results["save_errors"] = errors
    return results


def calibrate_devices(
    paths: Sequence[str | Path],
    sensor: str,
    *,
    g: float | None = None,
    field: float | None = None,
    window: int | None = None,
    min_static: float | None = None,
    threshold_factor: float | None = None,
    sensor_ids: Sequence[str] | None = None,
    solver: str = "lm1",
    echo: Callable[[str], None] | None = print,
) -> list[dict]:
    """Several recorded logs in one vmapped batch fit per sensor; JSON beside each log.

    Each log goes through the front door of ``calib-jax batch`` (:func:`calib_jax.fleet.
    prepare_log` and :func:`calib_jax.fleet.fit_prepared`), so a device gets the parameters
    ``calibrate_accel`` / ``calibrate_mag`` give its log alone. Accelerometer: the fit of the
    static-interval means; magnetometer: the full ellipsoid on every finite sample. ``g``
    defaults to each log's unit (1 g, or 9.80665 for m/s^2; batch.reference_for_log); a
    given ``g`` that contradicts a log's unit is a ValueError naming the log, before anything
    is written. A log that cannot be prepared gets a ``not_fitted`` entry; the others are
    fitted. Each device's sensor is written where a single port writes it
    (:func:`calibration_paths`) as a :class:`calib_jax.BatchRecord` of one entry (load it with
    ``BatchRecord.load``). Returns one dict per device: ``{"sensor_id", "source", "accel":
    entry, "mag": entry}`` (the sensors recorded), with ``save_error`` when a file could not be
    written.
    """
    from .batch import reference_for_log
    from .fleet import fit_prepared, prepare_log
    from .io.files import load_log

    say = echo or (lambda s: None)
    logs = [load_log(p) for p in paths]
    ids = list(sensor_ids) if sensor_ids is not None else [str(p) for p in paths]
    results: list[dict] = [
        {"sensor_id": i, "source": str(p)} for i, p in zip(ids, paths, strict=True)
    ]
    kinds = {"accel": ["accel"], "mag": ["mag"], "marg": ["accel", "mag"], "gyro": ["gyro"]}
    kinds = kinds[sensor]
    for kind in kinds:
        if kind == "gyro":  # each log through calibrate_gyro, as calib-jax batch does
            from .fleet import _gyro_entry

            detector = {"window": window, "threshold_factor": threshold_factor}
            detector["min_static"] = min_static
            for i, p in enumerate(paths):
                entry = _gyro_entry(p, None, {"g": g}, detector)
                results[i]["gyro"] = {**entry, "sensor_id": ids[i]}
            continue
        prepared = []
        for i, (lg, p) in enumerate(zip(logs, paths, strict=True)):
            detector = {}
            if kind == "accel":
                detector = _detector(window, threshold_factor, min_static, lg.sample_rate)
            try:
                pts, info = prepare_log(lg, kind, **detector)
            except ValueError as exc:
                results[i][kind] = {"path": str(p), "status": "not_fitted", "message": str(exc)}
                continue
            if kind == "accel":
                try:
                    reference_for_log(
                        info["static_norm"],
                        g,
                        info.get("fit_norm"),
                        info.get("radius_determined", False),
                    )
                except ValueError as exc:
                    raise ValueError(f"{p}: {exc}") from None
            prepared.append((i, pts, info))
        options = {"g": g} if kind == "accel" else {"field": field}
        for r in fit_prepared(prepared, kind, {**options, "solver": solver}):
            i = int(r["path"])
            results[i][kind] = {**r, "path": str(paths[i]), "sensor_id": ids[i]}
    for i, (res, p) in enumerate(zip(results, paths, strict=True)):
        errors: list[str] = []
        wrote = ""
        targets = calibration_paths(p, sensor)
        for kind in kinds:
            rec = BatchRecord(sensor=kind, entries=[res[kind]])
            target = targets[kind]
            wrote += _save(lambda t=target, r=rec: r.save(t), target, errors)
        say(f"[{i}] {res['sensor_id']}: " + _batch_line(res) + wrote)
        if errors:
            res["save_error"] = errors[0]  # not in the file (it could not be written)
    return results


def _save(write: Callable[[], None], target: Path, errors: list[str]) -> str:
    """Run ``write`` (an atomic JSON write); an OSError (a full disk) is reported on stderr
    and appended to ``errors``, not raised: the recorded log stays as it is, and no partial
    JSON is left behind."""
    try:
        write()
    except OSError as exc:
        msg = f"could not write {target}: {exc}"
        errors.append(msg)
        _stderr(
            f"{msg}. The log is intact; free some space and calibrate it again "
            "(calib-jax accel/mag LOG)"
        )
        return f"; NOT written: {target} ({exc.strerror or exc})"
    return f"; wrote {target}"


def _batch_line(res: dict) -> str:
    out = []
    for kind in ("accel", "mag", "gyro"):
        e = res.get(kind)
        if e is None:
            continue
        if e["status"] in ("load_error", "not_fitted"):
            out.append(f"{kind} not calibrated: {e['message']}")
            continue
        p = e["params"]
        if kind == "gyro":
            out.append(f"gyro {e['status']} bias {_fmt(p[9:12])} miss {e['rms']:.3g} deg")
            continue
        what = (
            f"gains {_fmt(p[0:3])} bias {_fmt(p[6:9])}"
            if kind == "accel"
            else f"center {_fmt(p[0:3])}"
        )
        out.append(f"{kind} {e['status']} {what} rms {e['rms']:.2e}")
    return "; ".join(out)


def _fmt(v) -> str:
    return "[" + ", ".join(f"{x:.5g}" for x in v) + "]"


def session_ok(results: Sequence[dict | object]) -> bool:
    """True when every calibration in ``results`` succeeded."""
    ok = True
    for r in results:
        if isinstance(r, dict):
            for kind in ("accel", "mag", "gyro"):
                item = r.get(kind)
                if isinstance(item, dict):
                    ok &= item.get("status") == "ok"
                elif item is not None:
                    ok &= bool(item.success)
        else:
            ok &= bool(r.success)
    return bool(ok)


def run(args) -> int:
    """The ``calib-jax record`` command (arguments from :func:`calib_jax.cli.build_parser`)."""
    session = record_session(
        args.port,
        args.out,
        sensor=args.sensor,
        seconds=args.seconds,
        auto_stop=not args.no_auto_stop,
        target_poses=args.target_poses,
        window=args.window,
        min_static=args.min_static,
        threshold_factor=args.threshold_factor,
        baudrate=args.baud,
        columns=args.columns,
        scale=args.scale,
        delimiter=args.delimiter,
        resume=args.resume,
        overwrite=args.overwrite,
        max_reconnect_seconds=args.max_reconnect,
        progress=False if args.no_progress else None,
    )
    # what gets calibrated is each log as it is on disk: this session's lines, plus the earlier
    # ones with --resume; a file this session wrote nothing into is not this session's result
    empty = [
        d
        for d in session.devices
        if not d.path.exists() or (d.reader.stats.lines_ok == 0 and not args.resume)
    ]
    if empty:
        old = [str(d.path) for d in empty if d.path.exists()]
        msg = (
            f"nothing was recorded into {', '.join(str(d.path) for d in empty)} (no well-formed "
            "line arrived); check --port, --baud and --columns"
            + (f"; {', '.join(old)} is left as it was" if old else "")
        )
        if len(empty) == len(session.devices):
            raise ValueError(msg)
        # one dead board must not cost the others their calibration: go on without it
        _stderr(f"{msg}; calibrating the other {len(session.devices) - len(empty)} device(s)")
    live = [d for d in session.devices if d not in empty]
    paths = [d.path for d in live]
    try:
        if len(live) == 1:
            dev = live[0]
            res = calibrate_recording(
                dev.path,
                args.sensor,
                g=args.g,
                field=args.field,
                window=args.window,
                min_static=args.min_static,
                threshold_factor=args.threshold_factor,
                sensor_id=dev.url,
                solver=args.solver,
            )
            ok = session_ok(list(res[k] for k in res if k in ("accel", "mag", "gyro")))
            ok &= not res.get("save_errors")
        else:
            res = calibrate_devices(
                paths,
                args.sensor,
                g=args.g,
                field=args.field,
                window=args.window,
                min_static=args.min_static,
                threshold_factor=args.threshold_factor,
                sensor_ids=[d.url for d in live],
                solver=args.solver,
            )
            ok = session_ok(res) and not any("save_error" in r for r in res)
        ok &= not any(d.error for d in session.devices)  # said at the end of the session
        ok &= not empty
    except ValueError as exc:
        raise ValueError(
            f"{exc}\nthe recording is kept in {', '.join(map(str, paths))}; add to it with "
            "--resume, or calibrate it with calib-jax accel/mag FILE"
        ) from None
    return 0 if ok else 1
