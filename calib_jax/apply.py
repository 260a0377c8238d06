"""Apply a saved calibration to a log: ``calib-jax apply CAL LOG`` and :func:`apply_calibration`.

The calibration is any file :func:`calib_jax.export.read` reads (calib_jax's accelerometer,
ellipsoid and MARG JSON; imu_tk, imucal and imu_calib files) or a calibration object. The
log is read by the same front door as every command (:func:`calib_jax.io.load_log`: header or
guessed columns, units of time); a plain text log is streamed ``chunk_rows`` lines at a time,
so memory does not grow with its length. Compressed and MAT files are read whole.

The output CSV holds one row per data row of the log, in order: ``t`` (seconds, as the loader
reads the time column; without one, the row number over the sample rate where that is known,
given or stated above the data), the corrected ``ax, ay, az``, ``gx, gy, gz`` and
``mx, my, mz`` (each triad the calibration corrects; the others as read), and the temperature
unchanged. Rows
with a non-finite cell keep it (NaN in, NaN out); rows with the wrong number of fields are
skipped, as every command skips them, and counted.
Numbers are written with 12 significant digits (the time with 17), more than any sensor
resolves. Nothing here imports JAX.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .calibration import OffScaleWarning, atomic_write, off_scale
from .export import G_STANDARD, Correction, corrections, warn_unusable
from .io.files import SensorLog, iter_rows, load_log

_TRIADS = (("acc", "a", "accel"), ("gyro", "g", "gyro"), ("mag", "m", "mag"))


@dataclass
class ApplyReport:
    """What :func:`apply_calibration` wrote."""

    out: str
    rows: int
    columns: list[str]
    corrected: list[str]
    """One line per corrected sensor (:meth:`Correction.describe`)."""
    streamed: bool
    """True when the log was read in chunks (a plain text file), False when read whole."""
    notes: list[str] = field(default_factory=list)

    def report(self) -> str:
        how = "streamed in chunks" if self.streamed else "read whole"
        out = [f"wrote {self.rows} rows ({', '.join(self.columns)}) to {self.out} ({how})"]
        out += [f"corrected {c}" for c in self.corrected]
        out += [f"note: {n}" for n in self.notes]
        return "\n".join(out)


def _plan(corr: dict[str, Correction], log: SensorLog) -> tuple[dict[str, Correction], list]:
    """Which of the log's triads each correction applies to; an error when none applies."""
    use = {attr: corr[s] for attr, _, s in _TRIADS if s in corr and getattr(log, attr) is not None}
    notes = [
        f"the calibration corrects the {s}, but the log has no {p}x, {p}y, {p}z columns: "
        "nothing to correct there"
        for attr, p, s in _TRIADS
        if s in corr and getattr(log, attr) is None
    ]
    if not use:
        wanted = " and ".join(f"{p}x, {p}y, {p}z" for _, p, s in _TRIADS if s in corr)
        raise ValueError(
            f"{log.path}: the calibration corrects {' and '.join(corr)}, but the log has no "
            f"{wanted} columns (found: {', '.join(log.columns) or 'none'}); map them with "
            "--columns"
        )
    if "gyro" in use and use["gyro"].needs_acc and _to_ms2(use.get("acc")) is None:
        notes.append(
            "the gyroscope's g-sensitivity G is not applied: it needs the calibrated "
            "acceleration in m/s^2, and the calibration has no accelerometer correction to m/s^2 "
            "or g (apply a MARG record holding both, or in Python "
            "Correction.apply(raw, acc=...)); the rates are off by up to |G| g"
        )
    return use, notes


def _to_ms2(acc: Correction | None) -> float | None:
    """m/s^2 per unit of the accelerometer correction's output (None: no usable unit)."""
    if acc is None:
        return None
    return {"m/s^2": 1.0, "g": G_STANDARD}.get(acc.output_units or "")


def _corrected(use: dict[str, Correction], raw: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Each triad in ``use`` corrected; the gyroscope's g-sensitivity with the corrected
    acceleration of the same rows, in m/s^2, where the calibration gives it."""
    out = {attr: c.apply(raw[attr]) for attr, c in use.items() if attr != "gyro"}
    if "gyro" in use:
        scale = _to_ms2(use.get("acc"))
        acc = None if scale is None else scale * out["acc"]
        out["gyro"] = use["gyro"].apply(raw["gyro"], acc=acc)
    return out


def _off_scale_notes(use: dict[str, Correction], acc: np.ndarray | None) -> list[str]:
    """A note, and a UserWarning, when the corrected acceleration ``acc`` is not near g in the
    correction's output unit (the rule of ``AccelCalibration.apply``: an Xsens record in
    counts applied to a log in g wrote |a| of 136 m/s^2 on every row, without a word)."""
    scale = _to_ms2(use.get("acc"))
    if acc is None or scale is None:
        return []
    units = f"{use['acc'].input_units or 'the input unit'} (the calibration's input)"
    why = off_scale(acc, G_STANDARD / scale, units, "g")
    if not why:
        return []
    import warnings

    warnings.warn(why, OffScaleWarning, stacklevel=3)
    return [why]


def correct_log(cal, log: SensorLog) -> SensorLog:
    """A copy of a loaded log with each triad the calibration holds corrected (a MARG
    magnetometer rotated into the accelerometer's frame, a gyroscope's g-sensitivity removed
    with the corrected acceleration); the other columns as they were. A note (and a
    UserWarning) where the corrected acceleration is far from g: readings in another unit."""
    use, notes = _plan(corrections(cal), log)
    new = _corrected_log(use, log)
    notes += _off_scale_notes(use, new.acc if "acc" in use else None)
    return replace(new, notes=[*log.notes, *notes])


def _corrected_log(use: dict[str, Correction], log: SensorLog) -> SensorLog:
    """``log`` with the triads in ``use`` corrected (no notes: the caller's)."""
    new = _corrected(use, {attr: getattr(log, attr) for attr in use})
    return replace(log, **new, layout=None)


def apply_calibration(
    cal,
    log,
    out: str | Path | None = None,
    *,
    columns=None,
    sample_rate: float | None = None,
    chunk_rows: int = 262_144,
) -> SensorLog | ApplyReport:
    """Apply ``cal`` to ``log``.

    Parameters
    ----------
    cal : calibration object, dict or path
        Anything :func:`calib_jax.export.corrections` takes.
    log : path, SensorLog or (N, 3) array
        The log to correct (an array: of the one sensor the calibration corrects).
    out : path, optional
        Write the corrected log here as CSV (streamed, see the module docstring) and return an
        :class:`ApplyReport`. Without it, return the corrected :class:`SensorLog` in memory.
    columns, sample_rate
        As :func:`calib_jax.load_log` (for headerless logs).
    chunk_rows : int
        Lines per chunk when streaming.
    """
    corr = corrections(cal)
    warn_unusable(corr)
    # a headerless 3- or 4-column log holds the one sensor a single-sensor calibration corrects
    hint = {"sensor": next(iter(corr))} if len(corr) == 1 else {}
    if not isinstance(log, SensorLog | str | Path):  # an array (was os.fspath's TypeError)
        log = _array_log(log, corr)
    if isinstance(log, SensorLog):
        if out is None:
            return correct_log(corr, log)
        fixed = _corrected_log(_plan(corr, log)[0], log)  # _write says what _plan found
        return _write(out, [(_columns(fixed), 0)], log, corr, False)
    if out is None:
        return correct_log(corr, load_log(log, columns=columns, sample_rate=sample_rate, **hint))
    if Path(out).resolve() == Path(log).resolve():
        raise ValueError(f"--out {out} is the log itself: write the corrected log elsewhere")
    head = load_log(log, columns=columns, sample_rate=sample_rate, max_rows=chunk_rows, **hint)
    use, _ = _plan(corr, head)  # refuse before writing anything
    if head.layout is None and len(head) >= chunk_rows:
        head = load_log(log, columns=columns, sample_rate=sample_rate, **hint)  # whole
    if head.layout is None or len(head) < chunk_rows:
        fixed = _corrected_log(use, head)
        return _write(out, [(_columns(fixed), 0)], head, corr, False)
    return _write(out, _stream(log, head, use, chunk_rows), head, corr, True)


def _array_log(x, corr: dict[str, Correction]) -> SensorLog:
    """An (N, 3) array as the log of the one sensor the calibration corrects."""
    x = np.asarray(x, float)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"log must be a path, a SensorLog or an (N, 3) array, got {x.shape}")
    if len(corr) != 1:
        raise ValueError(
            f"the calibration corrects {' and '.join(corr)}: an array does not say which "
            "sensor it holds; pass a SensorLog (calib_jax.load_log) or a path"
        )
    attr = next(a for a, _, s in _TRIADS if s in corr)
    return SensorLog(**{"acc": None, attr: x})


def _columns(log: SensorLog, first_row: int = 0) -> dict[str, np.ndarray]:
    """The output columns of a (corrected) log, in the output's order; a log without a time
    column whose rate is known (given, or stated above the data) gets ``t`` from it, the row
    ``first_row`` at ``first_row / rate``."""
    cols: dict[str, np.ndarray] = {}
    if log.t is not None:
        cols["t"] = log.t
    elif log.sample_rate:
        cols["t"] = (first_row + np.arange(len(log))) / log.sample_rate
    for attr, p, _ in _TRIADS:
        x = getattr(log, attr)
        if x is not None:
            cols.update({p + a: x[:, i] for i, a in enumerate("xyz")})
    if log.temp is not None:
        cols["temp"] = log.temp
    return cols


def _stream(path, head: SensorLog, use: dict[str, Correction], chunk_rows: int):
    """The whole file in blocks, as (output columns, rows skipped), corrected, in order
    (``use``: the correction of each of the log's triads, from :func:`_plan`)."""
    lay = head.layout
    src = lay["source"]
    done = 0
    for block, bad in iter_rows(path, lay, chunk_rows):
        part = SensorLog(acc=None, sample_rate=head.sample_rate)
        if "t" in src:
            part.t = block[:, src["t"]] * lay["time_scale"]
        if "temp" in src:
            part.temp = block[:, src["temp"]]
        raw = {
            attr: block[:, [src[p + a] for a in "xyz"]]
            for attr, p, _ in _TRIADS
            if getattr(head, attr) is not None
        }
        for attr, x in (raw | _corrected(use, raw)).items():
            setattr(part, attr, x)
        yield _columns(part, done), bad
        done += len(block)


def _write(out, blocks, head: SensorLog, corr, streamed: bool) -> ApplyReport:
    """Write the blocks to a temporary file beside ``out``, then rename it: an error midway
    leaves no half-written log under ``out``."""
    out = Path(out)
    use, plan_notes = _plan(corr, head)
    names: list[str] | None = None
    rows = skipped = 0
    with atomic_write(out, suffix=".part", newline="\n") as fh:
        for cols, bad in blocks:
            skipped += bad
            if names is None:
                names = list(cols)
                fh.write(",".join(names) + "\n")
                if "ax" in cols and "acc" in use:  # judged on the first block
                    acc = np.column_stack([cols["ax"], cols["ay"], cols["az"]])
                    plan_notes += _off_scale_notes(use, acc)
            n = len(cols[names[0]])
            if n:
                fmt = ["%.17g" if c == "t" else "%.12g" for c in names]
                table = np.column_stack([cols[c] for c in names])
                np.savetxt(fh, table, fmt=fmt, delimiter=",")
                rows += n
    notes = list(head.notes) + plan_notes + [n for c in use.values() for n in c.notes]
    if head.t is None and head.sample_rate and names and "t" in names:
        notes.append(
            f"t is the row number over the sample rate ({head.sample_rate:g} Hz): the log has "
            "no time column"
        )
    if skipped:
        notes.append(
            f"{skipped} row{'s' if skipped > 1 else ''} had the wrong number of fields and "
            f"{'were' if skipped > 1 else 'was'} skipped"
        )
    return ApplyReport(
        out=str(out),
        rows=rows,
        columns=names or [],
        corrected=[c.describe() for c in use.values()],
        streamed=streamed,
        notes=notes,
    )
