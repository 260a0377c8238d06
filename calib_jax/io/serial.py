"""Live sensors over pyserial: line records to arrays, with an append-only log that loses nothing.

A board on USB serial prints one record per line (``0.012,-0.998,0.031`` or
``t ax ay az mx my mz``). :class:`SerialReader` opens any pyserial URL (a device path such as
``/dev/ttyACM0``, ``loop://``, ``socket://host:port``, ``rfc2217://host:port``), splits the byte
stream into lines, parses them with a column layout and per-column scale (raw counts to
units), and hands out :class:`Batch` es of arrays, by iteration (notebooks) or through a
callback (live plots). Every well-formed line goes to an append-only CSV log as it arrives,
in canonical columns (``t,ax,ay,az,...``, after scaling) that :func:`calib_jax.io.load_log`
and ``calib-jax accel FILE`` read directly.

What real boards do, and what the reader does about it (every dropped line is counted by
reason in :attr:`SerialReader.stats`):

* the port opens in the middle of a line: the text before the first line end after every
  (re)open is dropped as ``partial`` (unless it is a header); so is an incomplete line left
  when the device goes away;
* garbage bytes (noise at power-up, a wrong baud rate): lines that are not UTF-8 are dropped
  as ``decode``; lines longer than ``max_line_bytes`` as ``too_long``;
* lines with the wrong number of fields (``field_count``) or fields that are not numbers
  (``non_numeric``); ``no_columns`` before the layout is known; ``header_mismatch`` for a
  header that contradicts the layout in use;
* bursts (a backlog arriving at once) are read whole; stalls (no data for ``stall_seconds``)
  are counted and reported;
* unplug and replug: a read error closes the port and reopens the same URL with exponential
  backoff (``backoff_initial`` doubling up to ``backoff_max``), with a visible message; after
  ``max_reconnect_seconds`` without a connection the reader stops with status ``"gave_up"``.
  A port that opens but fails again before sending anything (a flaky cable, another program
  on the port, a server that hangs up) does not end the outage: it keeps backing off and is
  given up the same way. What was read before the loss is flushed and fsynced at once.

Lines end at ``\\n`` or ``\\r`` (so ``\\r\\n`` works); blank lines are ignored. Fields are
separated by commas, tabs, semicolons or whitespace (detected per line unless ``delimiter``
is given); a separator after the last field is allowed. A header line (every field a known
column name, see :func:`calib_jax.io.canonical_name`) sets the layout when ``columns`` is not
given. Without a ``t`` column the host's clock (``time.monotonic`` from the session start)
stamps the lines, spread evenly over the interval in which each read arrived.

Durability: rows are written in whole lines and handed to the OS (written and flushed) after
every read from the port, so a killed process (even SIGKILL) loses no line it has read; they
are ``os.fsync``-ed every ``fsync_interval`` seconds, when the connection is lost, and on close
(also on Ctrl-C inside ``with``), so a power loss loses at most the last ``fsync_interval``.
(:class:`LogWriter` used on its own flushes every ``flush_interval`` seconds or ``flush_lines``
rows.) A killed process leaves every line up to the last flush intact; a line cut off by the
end of the session is counted as ``partial``. An existing log is never truncated unless
``overwrite=True``; ``resume=True`` appends to it after checking that its header matches.

By default pyserial's flush of the OS input buffer on open is skipped (``keep_pending``):
bytes the device sent while the port was closed are data too.
"""

from __future__ import annotations

import logging
import math
import os
import re
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import serial  # pyserial (absolute import: this module is calib_jax.io.serial)

from .files import _CANON, canonical_name, parse_columns

DROP_REASONS = (
    "partial",
    "decode",
    "too_long",
    "field_count",
    "non_numeric",
    "no_columns",
    "header_mismatch",
)
"""Reasons a line is dropped, the keys of :attr:`ReaderStats.dropped`."""

_SKIP = ("_", "-", "skip")
_DELIMS = {",": ",", "comma": ",", "\t": "\t", "tab": "\t", ";": ";", "semicolon": ";"}
_DELIMS.update({" ": None, "space": None, "whitespace": None, "auto": "auto"})
_LINE_END = re.compile(rb"[\r\n]")
_GROUPS = {
    "a": ("ax", "ay", "az"),
    "acc": ("ax", "ay", "az"),
    "g": ("gx", "gy", "gz"),
    "gyro": ("gx", "gy", "gz"),
    "m": ("mx", "my", "mz"),
    "mag": ("mx", "my", "mz"),
}
_SENSOR_COLS = ("ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz")
_DROP_NOTE_AFTER = 20  # dropped lines, none accepted: say what to change

logger = logging.getLogger(__name__)


# ---------------------------------------------------------------------------------------------
# layout, scale and values


def parse_layout(
    columns: str | Sequence[str] | None,
) -> tuple[list[str | None] | None, dict[str, str]]:
    """A column spec -> (positional layout or None, header renames {device name: canonical}).

    ``"t,ax,ay,az,mx,my,mz"`` (positional; ``_`` skips a field) fixes the layout;
    ``"ax=AccX,ay=AccY,az=AccZ"`` (canonical=device name) renames the fields of the header
    the device sends.
    """
    if columns is None:
        return None, {}
    parts = columns.split(",") if isinstance(columns, str) else list(columns)
    parts = [p.strip() for p in parts if p.strip()]
    if not parts:
        raise ValueError("columns is empty; give e.g. columns='t,ax,ay,az'")
    named = parse_columns(parts)  # validates the names, raises with the list of known ones
    if all("=" in p for p in parts):
        return None, {src.lower(): canon for canon, src in named.items()}
    layout = [None if p in _SKIP else p.lower() for p in parts]
    _check_layout(layout, "columns")
    return layout, {}


def _check_layout(layout: list[str | None], what: str) -> None:
    names = [c for c in layout if c is not None]
    dup = sorted({c for c in names if names.count(c) > 1})
    if dup:
        raise ValueError(f"{what} names {dup} more than once; each column may appear once")
    for axes in _GROUPS.values():
        have = [a in names for a in axes]
        if any(have) and not all(have):
            raise ValueError(
                f"{what} has some but not all of {list(axes)}; give all three axes of a sensor"
            )
    if not any(c in _SENSOR_COLS for c in names):
        raise ValueError(f"{what} {layout} has no sensor axes; name them, e.g. 'ax,ay,az'")


def parse_scale(spec: str | float | dict[str, float] | None) -> dict[str, float]:
    """A scale spec -> {key: factor} (raw value times factor = value in units).

    A number applies to every sensor axis (not ``t`` or ``temp``); a mapping (or the string
    ``"a=0.000061,m=0.15,t=0.001"``) names canonical columns or the groups ``a``/``acc``,
    ``g``/``gyro``, ``m``/``mag``.
    """
    if spec is None:
        return {}
    if isinstance(spec, int | float):
        items: dict[str, float] = {"*": float(spec)}
    elif isinstance(spec, str):
        parts = [p.strip() for p in spec.split(",") if p.strip()]
        if len(parts) == 1 and "=" not in parts[0]:
            items = {"*": _to_float(parts[0], spec)}
        elif all("=" in p for p in parts):
            items = {
                k.strip().lower(): _to_float(v, spec) for k, v in (p.split("=", 1) for p in parts)
            }
        else:
            raise ValueError(
                f"scale {spec!r}: give one number for every axis, or key=value pairs such as "
                "'a=0.000061,m=0.15,t=0.001'"
            )
    else:
        items = {str(k).lower(): float(v) for k, v in dict(spec).items()}
    for k, v in items.items():
        if k != "*" and k not in _CANON and k not in _GROUPS:
            raise ValueError(
                f"unknown scale key {k!r}; use a column ({', '.join(_CANON)}) or a group (a, g, m)"
            )
        if not (math.isfinite(v) and v != 0.0):
            raise ValueError(f"scale for {k!r} must be a finite, non-zero number, got {v}")
    return items


def _to_float(s: str, spec: str) -> float:
    try:
        return float(s)
    except ValueError:
        raise ValueError(f"scale {spec!r}: {s!r} is not a number") from None


def _factor(scale: dict[str, float], col: str) -> float:
    if col in scale:
        return scale[col]
    for g, axes in _GROUPS.items():
        if col in axes and g in scale:
            return scale[g]
    return scale.get("*", 1.0) if col in _SENSOR_COLS else 1.0


def log_columns(layout: Sequence[str | None]) -> list[str]:
    """The log's columns for a device layout: canonical order, always with ``t``."""
    have = {c for c in layout if c is not None} | {"t"}
    return [c for c in _CANON if c in have]


def format_row(values: Sequence[float] | np.ndarray) -> str:
    """One log line (without its newline): shortest round-trip repr of each value."""
    return ",".join(repr(float(v)) for v in values)


@dataclass(frozen=True)
class Batch:
    """Samples that arrived together: host or device time and the sensor triples, in units.

    Arrays are ``(n,)`` for ``t`` and ``temp`` and ``(n, 3)`` for ``acc``, ``gyro``, ``mag``;
    a sensor the device does not send is None.
    """

    t: np.ndarray
    acc: np.ndarray | None = None
    gyro: np.ndarray | None = None
    mag: np.ndarray | None = None
    temp: np.ndarray | None = None
    columns: tuple[str, ...] = ("t",)

    def __len__(self) -> int:
        return len(self.t)

    @classmethod
    def from_rows(cls, columns: Sequence[str], rows: Sequence[Sequence[float]]) -> Batch:
        """Rows in ``columns`` order (canonical names) -> a batch."""
        a = np.asarray(rows, float).reshape(len(rows), len(columns))
        idx = {c: i for i, c in enumerate(columns)}

        def triple(p: str) -> np.ndarray | None:
            keys = [p + x for x in "xyz"]
            return a[:, [idx[k] for k in keys]] if all(k in idx for k in keys) else None

        return cls(
            t=a[:, idx["t"]] if "t" in idx else np.zeros(len(a)),
            acc=triple("a"),
            gyro=triple("g"),
            mag=triple("m"),
            temp=a[:, idx["temp"]] if "temp" in idx else None,
            columns=tuple(columns),
        )

    @classmethod
    def concat(cls, batches: Sequence[Batch]) -> Batch:
        """Batches of the same columns, joined in order (an empty ``t`` batch for none)."""
        batches = [b for b in batches if len(b)]
        if not batches:
            return cls(t=np.zeros(0))

        def cat(name: str) -> np.ndarray | None:
            parts = [getattr(b, name) for b in batches]
            return None if parts[0] is None else np.concatenate(parts)

        return cls(
            t=cat("t"),
            acc=cat("acc"),
            gyro=cat("gyro"),
            mag=cat("mag"),
            temp=cat("temp"),
            columns=batches[0].columns,
        )


@dataclass
class ReaderStats:
    """Counts of one reader's session."""

    lines_ok: int = 0
    """Well-formed data lines accepted (and logged)."""
    dropped: dict[str, int] = field(default_factory=lambda: dict.fromkeys(DROP_REASONS, 0))
    """Dropped lines by reason (:data:`DROP_REASONS`)."""
    header_lines: int = 0
    reconnects: int = 0
    """Successful reopens after the connection was lost."""
    stalls: int = 0
    """Gaps of more than ``stall_seconds`` without data while connected."""
    bytes: int = 0
    lines_logged: int = 0
    """Rows handed to the OS (flushed) in the log file."""

    @property
    def dropped_total(self) -> int:
        return sum(self.dropped.values())

    def summary(self) -> str:
        drops = ", ".join(f"{k} {v}" for k, v in self.dropped.items() if v) or "none"
        return (
            f"{self.lines_ok} lines ok, dropped: {drops}; {self.header_lines} header lines, "
            f"{self.reconnects} reconnects, {self.stalls} stalls, {self.bytes} bytes"
        )


# ---------------------------------------------------------------------------------------------
# the log


def _split_csv(line: str) -> list[str]:
    return [c.strip() for c in line.split(",")]


class LogWriter:
    """Append-only canonical CSV log, written in whole lines and flushed on a cadence.

    The file is opened when :meth:`open` is called with its columns. Creating a writer for a
    path that exists raises unless ``resume`` (append after checking the header) or
    ``overwrite`` (start afresh) is given. A writer opens its file once: after :meth:`close`
    it refuses rows instead of opening (and truncating) the file again. Its methods may be
    called from several threads (a reader thread appends while another closes).
    """

    def __init__(
        self,
        path: str | Path,
        *,
        resume: bool = False,
        overwrite: bool = False,
        flush_interval: float = 0.2,
        flush_lines: int = 500,
        fsync_interval: float = 1.0,
    ) -> None:
        if resume and overwrite:
            raise ValueError("resume and overwrite exclude each other; choose one")
        self.path = Path(path)
        self.resume = resume
        self.overwrite = overwrite
        self.flush_interval = float(flush_interval)
        self.flush_lines = int(flush_lines)
        self.fsync_interval = float(fsync_interval)
        self.columns: list[str] | None = None
        self.existing_rows = 0
        self.last_t: float | None = None
        """Largest time in the file before this session (resume), or None."""
        self._header: list[str] | None = None
        self._ends_mid_line = self._header_unended = False
        self._file = None
        self._closed = False
        self._lock = threading.RLock()
        self._pending: list[str] = []
        self._last_flush = self._last_fsync = time.monotonic()
        self.rows_written = 0
        if self.path.exists() and not self.path.is_file():
            raise ValueError(f"{self.path} is not a regular file; choose a file path for the log")
        exists = self.path.exists() and self.path.stat().st_size > 0
        if exists and not (resume or overwrite):
            raise ValueError(
                f"{self.path} already exists; pass resume=True (--resume) to append to it, "
                "overwrite=True (--overwrite) to replace it, or choose another file"
            )
        if exists and resume:
            self._scan_existing()

    def _scan_existing(self) -> None:
        with open(self.path, "rb") as f:
            data = f.read()
        text = data.decode("utf-8", errors="replace")
        lines = [ln for ln in text.split("\n") if ln.strip()]
        self._header = _split_csv(lines[0]) if lines else None
        self._ends_mid_line = bool(lines) and not data.endswith(b"\n")
        self._header_unended = self._ends_mid_line and b"\n" not in data.strip()
        complete = lines[1:-1] if self._ends_mid_line else lines[1:]
        self.existing_rows = len(complete)
        if self._header and "t" in self._header:
            j = self._header.index("t")
            for ln in reversed(complete):
                cells = _split_csv(ln)
                try:
                    self.last_t = float(cells[j])
                    break
                except (IndexError, ValueError):
                    continue

    def check(self, columns: Sequence[str]) -> None:
        """Raise if resuming a file whose header differs from ``columns``."""
        if self._header is not None and list(self._header) != list(columns):
            raise ValueError(
                f"{self.path} has columns {','.join(self._header)} but this session records "
                f"{','.join(columns)}; resume with the same columns (e.g. columns="
                f"'{','.join(self._header)}'), or record into a new file"
            )

    def open(self, columns: Sequence[str]) -> None:
        """Open the file for ``columns`` (canonical names), writing the header if new."""
        columns = list(columns)
        with self._lock:
            if self._file is not None or self._closed:
                raise ValueError(
                    f"{self.path} was already opened by this writer; a writer opens its file "
                    "once (to add to it later, make a new one with resume=True)"
                )
            self.check(columns)
            self.columns = columns
            if self._header is not None:  # resume into a non-empty file
                self._file = open(self.path, "a", encoding="utf-8", newline="")  # noqa: SIM115
                if self._ends_mid_line:
                    # the previous session died mid-line: end the fragment so that no reader
                    # takes it for a row (an extra non-numeric field: skipped or NaN, never
                    # data); a header that only lacks its line end just gets it
                    self._file.write("\n" if self._header_unended else ",incomplete\n")
            else:
                # "x" refuses to clobber a file created since the check; an empty file is reused
                created = not self.path.exists()
                mode = "w" if (self.overwrite or self.resume or not created) else "x"
                self._file = open(self.path, mode, encoding="utf-8", newline="")  # noqa: SIM115
                self._file.write(",".join(columns) + "\n")
                if created:
                    _fsync_dir(self.path.parent)  # the new name survives a crash too
            self._file.flush()
            os.fsync(self._file.fileno())
            self._last_flush = self._last_fsync = time.monotonic()

    @property
    def is_open(self) -> bool:
        return self._file is not None

    @property
    def closed(self) -> bool:
        """True once :meth:`close` has run (the writer takes no more rows)."""
        return self._closed

    def append(self, line: str) -> None:
        """Queue one row (no newline); it reaches the file at the next flush."""
        with self._lock:
            if self._file is None:
                raise ValueError(
                    f"the log {self.path} is "
                    + ("closed; this row was not written" if self._closed else "not open yet")
                )
            self._pending.append(line)

    def maybe_flush(self, now: float | None = None) -> None:
        """Flush when ``flush_interval`` has passed or ``flush_lines`` rows wait; fsync when
        ``fsync_interval`` has passed."""
        with self._lock:
            if self._file is None:
                return
            now = time.monotonic() if now is None else now
            if self._pending and (
                now - self._last_flush >= self.flush_interval
                or len(self._pending) >= self.flush_lines
            ):
                self.flush()
            if now - self._last_fsync >= self.fsync_interval:
                os.fsync(self._file.fileno())
                self._last_fsync = now

    def flush(self, fsync: bool = False) -> None:
        """Write the queued rows in one call, flush to the OS, and optionally fsync."""
        with self._lock:
            if self._file is None:
                return
            if self._pending:
                # take the rows off the queue before writing them: an exception (Ctrl-C)
                # between the two can end the log early, but never write a row twice
                rows, self._pending = self._pending, []
                self._file.write("\n".join(rows) + "\n")
                self.rows_written += len(rows)
            self._file.flush()
            self._last_flush = time.monotonic()
            if fsync:
                os.fsync(self._file.fileno())
                self._last_fsync = self._last_flush

    def close(self) -> None:
        """Flush, fsync and close (idempotent)."""
        with self._lock:
            self._closed = True
            if self._file is None:
                return
            try:
                self.flush(fsync=True)
            finally:
                self._file.close()
                self._file = None


def _fsync_dir(folder: Path) -> None:
    """fsync a folder so that a file just created in it is there after a crash (POSIX)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass  # not supported for folders here (e.g. Windows): nothing more to do
    finally:
        os.close(fd)


# ---------------------------------------------------------------------------------------------
# the reader


class SerialReader:
    """Read line records from a pyserial URL into batches, logging every well-formed line.

    Use as a context manager (closing flushes and fsyncs the log, also on Ctrl-C) and iterate:
    each iteration returns the :class:`Batch` of the lines that arrived in about
    ``batch_seconds`` (possibly empty during a stall or a reconnect, so a loop can check its
    own stop condition); iteration ends when the reader gives up reconnecting or is closed.

    Parameters
    ----------
    url : str
        Any pyserial URL or device path: ``/dev/ttyUSB0``, ``COM3``, ``loop://``,
        ``socket://host:port``, ``rfc2217://host:port``.
    baudrate : int
        Serial speed (ignored by ``loop://`` and ``socket://``).
    columns : str or list, optional
        Field order, canonical names (``"t,ax,ay,az,mx,my,mz,temp"``, ``_`` skips a field), or
        renames for the device's header (``"ax=AccX,ay=AccY,az=AccZ"``). Default: from the
        device's header line; a headerless 3- or 4-field stream is read as ``ax,ay,az`` or
        ``t,ax,ay,az`` (as :func:`calib_jax.io.load_log` does) once two lines in a row agree.
    scale : float, str or dict, optional
        Raw value times scale = value in units, see :func:`parse_scale`.
    delimiter : str, optional
        ``","``, ``"\\t"``, ``";"``, ``" "`` (whitespace) or ``"auto"`` (default, per line).
    log : path, optional
        Append-only CSV log of every well-formed line (canonical columns, after scaling).
    resume, overwrite : bool
        What to do when ``log`` exists (see :class:`LogWriter`); neither: ValueError.
    flush_interval, flush_lines, fsync_interval : float, int, float
        Log durability cadence (seconds, rows, seconds).
    timeout : float
        pyserial read timeout (s): the longest a read blocks.
    batch_seconds, max_batch : float, int
        A batch closes after this long or this many lines.
    stall_seconds : float
        A gap without data this long while connected counts as a stall (reported once).
    reconnect : bool
        Reopen the URL after a read error (else stop with status ``"disconnected"``).
    backoff_initial, backoff_max : float
        Reconnect delays: the first, doubling up to the cap (s).
    max_reconnect_seconds : float or None
        Give up (status ``"gave_up"``) after this long without a connection; None: never.
    max_line_bytes : int
        Longer lines are dropped as ``too_long``.
    keep_pending : bool
        Skip pyserial's input flush on open (keep what the device sent before).
    on_message : callable, optional
        ``on_message(text)`` for connection events, stalls and format notes; default: the
        ``calib_jax.io.serial`` logger.
    callback : callable, optional
        ``callback(batch)`` for every non-empty batch (live plots).
    serial_options : dict, optional
        More keyword arguments for ``serial.serial_for_url`` (``parity``, ``rtscts`` ...).
    """

    def __init__(
        self,
        url: str,
        *,
        baudrate: int = 115200,
        columns: str | Sequence[str] | None = None,
        scale: str | float | dict[str, float] | None = None,
        delimiter: str | None = "auto",
        log: str | Path | None = None,
        resume: bool = False,
        overwrite: bool = False,
        flush_interval: float = 0.2,
        flush_lines: int = 500,
        fsync_interval: float = 1.0,
        timeout: float = 0.05,
        batch_seconds: float = 0.1,
        max_batch: int = 10_000,
        stall_seconds: float = 2.0,
        reconnect: bool = True,
        backoff_initial: float = 0.1,
        backoff_max: float = 2.0,
        max_reconnect_seconds: float | None = 60.0,
        max_line_bytes: int = 4096,
        keep_pending: bool = True,
        on_message: Callable[[str], None] | None = None,
        callback: Callable[[Batch], None] | None = None,
        serial_options: dict | None = None,
    ) -> None:
        if delimiter is None:
            delimiter = " "
        if delimiter not in _DELIMS:
            raise ValueError(
                f"delimiter must be one of ',', '\\t', ';', ' ', 'auto'; got {delimiter!r}"
            )
        if timeout <= 0 or batch_seconds <= 0:
            raise ValueError("timeout and batch_seconds must be positive (seconds)")
        self.url = str(url)
        self.baudrate = int(baudrate)
        self._delim = _DELIMS[delimiter]
        self._layout, self._renames = parse_layout(columns)
        self._scale = parse_scale(scale)
        self.timeout = float(timeout)
        self.batch_seconds = float(batch_seconds)
        self.max_batch = int(max_batch)
        self.stall_seconds = float(stall_seconds)
        self.reconnect = bool(reconnect)
        self.backoff_initial = float(backoff_initial)
        self.backoff_max = float(backoff_max)
        self.max_reconnect_seconds = max_reconnect_seconds
        self.max_line_bytes = int(max_line_bytes)
        self.keep_pending = bool(keep_pending)
        self.on_message = on_message
        self.callback = callback
        self.serial_options = dict(serial_options or {})
        self.stats = ReaderStats()
        self.status = "connecting"
        """connecting, connected, reconnecting, gave_up, disconnected or closed."""
        self.status_message = ""
        self.port = None
        """The open pyserial object (None while disconnected)."""
        self._writer = (
            LogWriter(
                log,
                resume=resume,
                overwrite=overwrite,
                flush_interval=flush_interval,
                flush_lines=flush_lines,
                fsync_interval=fsync_interval,
            )
            if log is not None
            else None
        )
        self._t0 = time.monotonic()
        self._t_offset = 0.0
        if self._writer is not None and self._writer.last_t is not None:
            # host time continues after the resumed log's last sample, so t stays increasing
            self._t_offset = self._writer.last_t
        self._log_cols: list[str] | None = None
        self._plan: list[tuple[int, int, float]] = []  # (field index, log index, factor)
        self._t_index: int | None = None
        if self._layout is not None:
            self._set_layout(self._layout)
        self._buf = bytearray()
        self._skip_long = False
        self._first_segment = True
        self._header_note_done = False
        self._no_columns_note = False
        self._mismatch_note = False
        self._drop_note = False
        self._held: tuple[list[float], float, str] | None = None  # a line awaiting the layout
        self._ever_connected = False
        self._down_since: float | None = time.monotonic()
        self._next_attempt = 0.0
        self._backoff = self.backoff_initial
        self._outage_noted = False
        self._outage_start: float | None = None
        self._conn_data = False
        self._connected_at = -math.inf
        self._last_data = time.monotonic()
        self._in_stall = False
        self._last_chunk = None
        self._last_t = -math.inf
        self._rows: list[tuple[float, ...]] = []

    # ---- properties ------------------------------------------------------------------------
    @property
    def columns(self) -> list[str] | None:
        """The log's (and batches') columns once the layout is known."""
        return None if self._log_cols is None else list(self._log_cols)

    @property
    def connected(self) -> bool:
        return self.port is not None

    @property
    def log_path(self) -> Path | None:
        return None if self._writer is None else self._writer.path

    # ---- context manager and iteration -----------------------------------------------------
    def __enter__(self) -> SerialReader:
        self._connect_step(time.monotonic())
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __iter__(self) -> Iterator[Batch]:
        while True:
            batch = self.read_batch()
            if batch is None:
                return
            yield batch

    def close(self) -> None:
        """Flush and fsync the log, close the port (idempotent)."""
        if self._buf.strip() and not self._skip_long:
            self._drop("partial", bytes(self._buf))  # a line the end of the session cut off
        if self._held is not None:  # the only line of a headerless stream: never confirmed
            self._drop("no_columns", self._held[2])
            self._held = None
        self._buf.clear()
        self._skip_long = False
        try:
            if self._writer is not None:
                self._writer.close()
                self.stats.lines_logged = self._writer.rows_written
        finally:
            self._close_port()
            if self.status not in ("gave_up", "disconnected"):
                self.status = "closed"

    # ---- messages --------------------------------------------------------------------------
    def _say(self, text: str, level: int = logging.WARNING) -> None:
        text = f"{self.url}: {text}"
        if self.on_message is not None:
            self.on_message(text)
        else:
            logger.log(level, text)

    # ---- layout ----------------------------------------------------------------------------
    def _set_layout(self, layout: list[str | None]) -> None:
        cols = log_columns(layout)
        if self._writer is not None:
            self._writer.check(cols)
        self._layout = list(layout)
        self._log_cols = cols
        where = {c: j for j, c in enumerate(cols)}
        self._plan = [
            (i, where[c], _factor(self._scale, c)) for i, c in enumerate(layout) if c is not None
        ]
        self._t_index = where["t"] if "t" not in layout else None  # host time goes here

    def _open_log(self) -> None:
        """Open the log at the first accepted line (no empty logs for silent ports)."""
        self._writer.open(self._log_cols)
        if self._writer.existing_rows:
            self._say(
                f"resuming {self._writer.path} ({self._writer.existing_rows} rows already there)",
                logging.INFO,
            )

    def _header_layout(self, fields: list[str]) -> list[str | None] | None:
        """The layout a header line declares, or None if the line is not a header."""
        out = []
        for f in fields:
            c = self._renames.get(f.strip().lower()) or canonical_name(f)
            if c is None:
                known = sum(
                    1 for g in fields if self._renames.get(g.strip().lower()) or canonical_name(g)
                )
                if known >= 2 and not self._header_note_done:
                    self._header_note_done = True
                    self._say(
                        f"a line looks like a header but {f!r} is not a known column; map it "
                        "with columns='name=canonical' or give the layout, e.g. "
                        "columns='t,ax,ay,az,_' ('_' skips a field)"
                    )
                return None
            out.append(c)
        if len(set(out)) != len(out) or not any(c in _SENSOR_COLS for c in out):
            return None
        try:
            _check_layout(out, "the header")
        except ValueError:
            return None
        return out

    # ---- connection ------------------------------------------------------------------------
    def _close_port(self) -> None:
        if self.port is not None:
            try:
                self.port.close()
            except Exception:  # noqa: BLE001 - the port is gone anyway
                pass
            self.port = None

    def _open_port(self):
        port = serial.serial_for_url(
            self.url,
            do_not_open=True,
            baudrate=self.baudrate,
            timeout=self.timeout,
            **self.serial_options,
        )
        if self.keep_pending and hasattr(port, "_reset_input_buffer"):
            port._reset_input_buffer = lambda: None  # keep what the device already sent
        port.open()
        return port

    def _connect_step(self, now: float) -> bool:
        """Try to (re)open when due. False when the reader has given up."""
        if self.port is not None:
            return True
        if self.status in ("gave_up", "disconnected", "closed"):
            return False
        if now < self._next_attempt:
            return True
        try:
            self.port = self._open_port()
        except (serial.SerialException, OSError, ValueError) as exc:
            if self._give_up(now, exc):
                return False
            if not self._outage_noted:
                self._outage_noted = True
                check = (
                    ""
                    if self._ever_connected
                    else "check the port name (--port) and that the device is plugged in; "
                )
                self._say(
                    f"cannot open ({exc}); {check}retrying with backoff up to "
                    f"{self.backoff_max:g} s"
                    + (
                        f" for {self.max_reconnect_seconds:g} s"
                        if self.max_reconnect_seconds is not None
                        else ""
                    )
                )
            self._next_attempt = now + self._backoff
            self._backoff = min(2.0 * self._backoff, self.backoff_max)
            return True
        down = now - (self._down_since or now)
        if self._ever_connected:
            self.stats.reconnects += 1
            self._say(f"reconnected after {down:.1f} s")
        else:
            self._say("connected", logging.INFO)
        self._ever_connected = True
        self.status = "connected"
        self.status_message = ""
        # the outage ends, and the backoff starts afresh, once data arrives: a port that opens
        # and fails before sending anything (a flaky cable, another program on the port, a
        # server that hangs up) goes on backing off and is given up like one that won't open
        self._outage_start, self._down_since = self._down_since, None
        self._conn_data = False
        self._connected_at = now
        self._buf.clear()
        self._skip_long = False
        self._first_segment = True
        self._last_data = now
        self._last_chunk = now
        self._in_stall = False
        return True

    def _lost(self, exc: BaseException, now: float) -> None:
        self._close_port()
        if self._buf.strip() and not self._skip_long:
            self._drop("partial", bytes(self._buf))
        self._buf.clear()
        self._skip_long = False
        if self._writer is not None:
            # everything read so far goes to disk now: an outage may last minutes, and the
            # read loop (which flushes on its cadence) only turns again once reconnected
            self._writer.flush(fsync=True)
            self.stats.lines_logged = self._writer.rows_written
        if not self.reconnect:
            self.status = "disconnected"
            self.status_message = f"connection lost: {exc}"
            self._say(self.status_message)
            return
        self.status = "reconnecting"
        if self._conn_data or now - self._connected_at >= self.backoff_max:
            # a connection that worked (data, or it lasted): a new outage, retried at once
            self._down_since = now
            self._next_attempt = now
            self._backoff = self.backoff_initial
            self._say(f"connection lost ({exc}); reconnecting")
            return
        # it opened but failed before any data: the same outage goes on, backing off
        self._down_since = self._outage_start if self._outage_start is not None else now
        if self._give_up(now, exc):
            return
        self._next_attempt = now + self._backoff
        self._say(f"connection lost again before any data ({exc}); retry in {self._backoff:g} s")
        self._backoff = min(2.0 * self._backoff, self.backoff_max)

    def _give_up(self, now: float, exc: BaseException) -> bool:
        """Give up (status ``gave_up``) when the outage has lasted ``max_reconnect_seconds``."""
        down = now - (self._down_since or now)
        if self.max_reconnect_seconds is None or down < self.max_reconnect_seconds:
            return False
        self.status = "gave_up"
        self.status_message = (
            f"no connection for {down:.1f} s (max_reconnect_seconds="
            f"{self.max_reconnect_seconds}); last error: {exc}"
        )
        self._say(f"giving up: {self.status_message}")
        return True

    def _read_chunk(self) -> bytes:
        port = self.port
        try:
            n = port.in_waiting
        except (AttributeError, NotImplementedError):
            n = 0
        return bytes(port.read(max(1, min(int(n), 1 << 16))))

    # ---- parsing ---------------------------------------------------------------------------
    def _drop(self, reason: str, raw: bytes | str = b"") -> None:
        self.stats.dropped[reason] += 1
        if self.stats.lines_ok or self._drop_note or reason == "partial":
            return
        if sum(v for k, v in self.stats.dropped.items() if k != "partial") < _DROP_NOTE_AFTER:
            return
        self._drop_note = True
        counts = {k: v for k, v in self.stats.dropped.items() if v and k != "partial"}
        worst = max(counts, key=counts.get)
        example = raw if isinstance(raw, str) else raw[:60]
        fix = {
            "decode": "bytes that are not text usually mean the wrong baud rate "
            "(baudrate=, --baud)",
            "too_long": "lines this long usually mean the wrong baud rate (baudrate=, --baud)",
            "field_count": "the lines have another number of fields than columns= (--columns) "
            "names; fix it ('_' skips a field)",
            "non_numeric": "fields that are not numbers: check delimiter= (--delimiter) and "
            "columns= (--columns; '_' skips a text field)",
            "no_columns": "say what the fields are with columns= (--columns)",
            "header_mismatch": "the device's header contradicts columns= (--columns); fix it",
        }[worst]
        drops = ", ".join(f"{k} {v}" for k, v in counts.items())
        self._say(f"no line accepted yet, {drops} dropped (e.g. {example!r}); {fix}")

    def _split(self, text: str) -> list[str]:
        d = self._delim
        if d == "auto":
            d = "\t" if "\t" in text else "," if "," in text else ";" if ";" in text else None
        if d is None:
            return text.split()
        fields = [f.strip() for f in text.split(d)]
        if len(fields) > 1 and not fields[-1]:
            fields.pop()  # a separator after the last field, as many sketches print
        return fields

    def _feed(self, data: bytes, now: float) -> None:
        self.stats.bytes += len(data)
        self._buf.extend(data)
        parts = _LINE_END.split(bytes(self._buf))
        rest = parts.pop()
        self._buf = bytearray(rest)
        n = len(parts)
        # host time: spread the lines of this read over the time since the previous one
        prev = self._last_chunk if self._last_chunk is not None else now
        span = min(max(now - prev, 0.0), 0.5)
        self._last_chunk = now
        for k, raw in enumerate(parts):
            first, self._first_segment = self._first_segment, False
            if self._skip_long:  # the tail of a line already dropped as too long
                self._skip_long = False
                continue
            t_host = now - self._t0 + self._t_offset - span * (n - 1 - k) / max(n, 1)
            self._line(raw, first, t_host)
        if len(self._buf) > self.max_line_bytes:
            if not self._skip_long:
                self._drop("too_long", bytes(self._buf[:60]))
            self._skip_long = True
            self._first_segment = False
            self._buf.clear()

    def _line(self, raw: bytes, first: bool, t_host: float) -> None:
        if not raw.strip():
            return
        if len(raw) > self.max_line_bytes:
            self._drop("too_long", raw[:60])
            return
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError:
            self._drop("partial" if first else "decode", raw)
            return
        fields = self._split(text.strip())
        values = []
        numeric = True
        for f in fields:
            try:
                values.append(float(f))
            except ValueError:
                numeric = False
                break
        if not numeric:
            head = self._header_layout(fields)
            if head is not None:
                self._header(head)
                return
            self._drop("partial" if first else "non_numeric", text)
            return
        if first:  # the port opened in the middle of this line
            self._drop("partial")
            return
        if self._layout is None:
            guess = {3: ["ax", "ay", "az"], 4: ["t", "ax", "ay", "az"]}.get(len(values))
            if guess is None:
                self._drop("no_columns", text)
                if not self._no_columns_note:
                    self._no_columns_note = True
                    self._say(
                        f"lines have {len(values)} fields and no header came; say what they "
                        "are with columns=, e.g. columns='t,ax,ay,az,mx,my,mz'"
                    )
                return
            # a guess waits for a second line of the same width (as load_log's does): one odd
            # line at power-up must not fix the layout of the whole session
            held, self._held = self._held, (values, t_host, text)
            if held is None or len(held[0]) != len(values):
                if held is not None:
                    self._drop("field_count", held[2])
                return
            self._held = None
            self._say(
                f"no header and no columns: reading {len(values)} fields as {','.join(guess)}",
                logging.INFO,
            )
            self._set_layout(guess)
            self._accept(held[0], held[1])
        if len(values) != len(self._layout):
            self._drop("field_count", text)
            return
        self._accept(values, t_host)

    def _accept(self, values: list[float], t_host: float) -> None:
        """A well-formed line: scale it into a log row, log it, keep it for the batch."""
        row = [0.0] * len(self._log_cols)
        for i, j, s in self._plan:
            row[j] = values[i] * s if s != 1.0 else values[i]
        if self._t_index is not None:
            t = max(t_host, self._last_t)
            self._last_t = t
            row[self._t_index] = round(t, 6)
        if self._writer is not None:  # the log first: a row counted ok is a row logged
            if not (self._writer.is_open or self._writer.closed):
                self._open_log()
            self._writer.append(format_row(row))
        self.stats.lines_ok += 1
        self._rows.append(tuple(row))

    def _header(self, head: list[str | None]) -> None:
        if self._layout is None:
            self._say(f"header from the device: {','.join(c or '_' for c in head)}", logging.INFO)
            self._set_layout(head)
            self.stats.header_lines += 1
            held, self._held = self._held, None  # a line that waited for the layout
            if held is not None and len(held[0]) == len(head):
                self._accept(held[0], held[1])
            elif held is not None:
                self._drop("field_count", held[2])
        elif len(head) == len(self._layout) and all(
            c is None or c == h for c, h in zip(self._layout, head, strict=True)
        ):  # the same layout (a field the layout skips may have any name)
            self.stats.header_lines += 1
        else:
            self._drop("header_mismatch", ",".join(c or "_" for c in head))
            if not self._mismatch_note:
                self._mismatch_note = True
                self._say(
                    f"the device's header {','.join(c or '_' for c in head)} differs from the "
                    f"layout in use {','.join(c or '_' for c in self._layout)}; keeping the "
                    "layout in use (fix columns= if it is wrong)"
                )

    # ---- the loop --------------------------------------------------------------------------
    def read_batch(self) -> Batch | None:
        """Read for about ``batch_seconds``; the batch (maybe empty), or None once stopped."""
        if self.status in ("gave_up", "disconnected", "closed") and not self._rows:
            return None
        start = time.monotonic()
        deadline = start + self.batch_seconds
        while True:
            now = time.monotonic()
            if self.port is None:
                if not self._connect_step(now):
                    break
                if self.port is None:
                    wait = min(self._next_attempt, deadline) - time.monotonic()
                    if wait > 0:
                        time.sleep(wait)
                    if time.monotonic() >= deadline:
                        break
                    continue
            try:
                data = self._read_chunk()
            except (serial.SerialException, OSError) as exc:
                self._lost(exc, time.monotonic())
                if time.monotonic() >= deadline:  # a batch ends on time, whatever the port does
                    break
                continue
            now = time.monotonic()
            if data:
                if not self._conn_data:  # this connection works: the outage is over
                    self._conn_data = True
                    self._backoff = self.backoff_initial
                    self._outage_noted = False
                if now - self._last_data > self.stall_seconds and not self._in_stall:
                    self._stall(now)
                self._in_stall = False
                self._last_data = now
                self._feed(data, now)
                if self._writer is not None:
                    # hand the rows of this read to the OS at once (write + flush, no fsync):
                    # a killed process (SIGKILL) then loses nothing it has read; fsync stays on
                    # its schedule (maybe_flush below), as it costs a disk round trip
                    self._writer.flush()
            elif now - self._last_data > self.stall_seconds and not self._in_stall:
                self._stall(now)
                self._in_stall = True
            if self._writer is not None:
                self._writer.maybe_flush(now)
                self.stats.lines_logged = self._writer.rows_written
            if len(self._rows) >= self.max_batch or now >= deadline:
                break
        rows, self._rows = self._rows, []
        if self._log_cols is None:
            batch = Batch(t=np.zeros(0))
        else:
            batch = Batch.from_rows(self._log_cols, rows)
        if self.callback is not None and len(batch):
            self.callback(batch)
        return batch

    def _stall(self, now: float) -> None:
        self.stats.stalls += 1
        self._say(f"no data for {now - self._last_data:.1f} s (stall)", logging.INFO)


# ---------------------------------------------------------------------------------------------
# record


@dataclass(frozen=True)
class Recording:
    """What :func:`record` recorded."""

    path: Path | None
    stats: ReaderStats
    status: str
    """'seconds' (time is up), 'stopped' (stop condition), 'interrupted' (Ctrl-C),
    'gave_up' (no reconnection in time) or 'disconnected'."""
    message: str
    seconds: float
    data: Batch | None
    """Everything read (when ``keep``), concatenated."""


def record(
    url: str,
    out: str | Path | None = None,
    *,
    seconds: float | None = None,
    stop: Callable[[Batch, ReaderStats], bool] | None = None,
    callback: Callable[[Batch], None] | None = None,
    keep: bool = True,
    **options,
) -> Recording:
    """Record from ``url`` into the log ``out`` until ``seconds``, ``stop`` or Ctrl-C.

    ``stop(batch, stats)`` is called after every batch and ends the recording when it returns
    True. Ctrl-C (KeyboardInterrupt) ends it too, after flushing and fsyncing the log.
    ``options`` go to :class:`SerialReader` (``baudrate``, ``columns``, ``scale``, ``resume``
    ...). Returns a :class:`Recording`.
    """
    batches: list[Batch] = []
    t0 = time.monotonic()
    status, message = "gave_up", ""
    reader = SerialReader(url, log=out, callback=callback, **options)
    try:
        with reader:
            for batch in reader:
                if keep and len(batch):
                    batches.append(batch)
                if seconds is not None and time.monotonic() - t0 >= seconds:
                    status, message = "seconds", f"recorded for {seconds:g} s"
                    break
                if stop is not None and stop(batch, reader.stats):
                    status, message = "stopped", "the stop condition was met"
                    break
            else:
                status, message = reader.status, reader.status_message
    except KeyboardInterrupt:
        status, message = "interrupted", "interrupted (Ctrl-C); the log is flushed and synced"
    return Recording(
        path=None if out is None else Path(out),
        stats=reader.stats,
        status=status,
        message=message,
        seconds=time.monotonic() - t0,
        data=Batch.concat(batches) if keep else None,
    )
