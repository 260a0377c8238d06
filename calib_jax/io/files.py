"""Loading sensor logs from text files and MATLAB .mat files.

Supported:

* CSV, TSV or whitespace-separated text with a header row. Column names are matched
  case-insensitively, ignoring units in brackets (``t[s]``) and separators: ``t``/``time``/
  ``timestamp``; ``ax ay az`` (also ``acc_x``, ``accx``, ``a_x``); ``gx gy gz`` (``gyr_x``,
  ``gyro_x``); ``mx my mz`` (``mag_x``); ``temp``/``temperature``. Other names are mapped with
  ``columns``.
* Headerless numeric text with a ``columns`` mapping such as ``"t,ax,ay,az"`` (the imu_tk
  files). Without a mapping, 3 columns are read as ``ax ay az`` and 4 as ``t ax ay az``;
  anything else is an error that asks for the mapping.
* MATLAB .mat (real binary MAT files through scipy.io; imu_tk's ``.mat`` files are text and
  are read as text).

Nothing here modifies the file; rows that cannot be used are counted, never rewritten.
"""

from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

_CANON = ("t", "ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "temp")

_ALIASES = {
    "t": "t",
    "time": "t",
    "timestamp": "t",
    "times": "t",
    "temp": "temp",
    "temperature": "temp",
}
for _k, _names in {
    "a": ("a", "acc", "accel", "accelerometer", "acceleration"),
    "g": ("g", "gyr", "gyro", "gyroscope", "w"),
    "m": ("m", "mag", "magn", "magnetometer"),
}.items():
    for _n in _names:
        for _ax in "xyz":
            _ALIASES[f"{_n}{_ax}"] = f"{_k}{_ax}"
            if len(_n) > 1:
                _ALIASES[f"{_ax}{_n}"] = f"{_k}{_ax}"


def _clean(name: str) -> str:
    name = re.sub(r"[\[\(].*?[\]\)]", "", name.strip().lower())
    return re.sub(r"[^a-z0-9]", "", name)


def canonical_name(name: str) -> str | None:
    """The canonical column ('t', 'ax', ..., 'temp') a header name stands for, or None."""
    return _ALIASES.get(_clean(name))


@dataclass
class SensorLog:
    """A loaded log: arrays by sensor, each (N, 3) or None, plus provenance."""

    acc: np.ndarray | None
    gyro: np.ndarray | None = None
    mag: np.ndarray | None = None
    temp: np.ndarray | None = None
    t: np.ndarray | None = None
    sample_rate: float | None = None
    path: str | None = None
    columns: dict[str, str] = field(default_factory=dict)
    """Canonical name -> the file's column name (or index) it came from."""
    notes: list[str] = field(default_factory=list)
    """What the loader assumed or dropped, for the report."""

    def __len__(self) -> int:
        for a in (self.acc, self.mag, self.gyro):
            if a is not None:
                return len(a)
        return 0


def parse_columns(spec: str | dict[str, str] | list[str] | None) -> dict[str, str] | None:
    """Parse a ``--columns`` mapping.

    ``"t,ax,ay,az"`` (positional, for headerless files) or ``"ax=AccX,ay=AccY,az=AccZ"``
    (canonical=file name, for headers with other names). Returns {canonical: source}, where the
    source of a positional mapping is the column index as a string.
    """
    if spec is None:
        return None
    if isinstance(spec, dict):
        items = spec
    else:
        parts = spec.split(",") if isinstance(spec, str) else list(spec)
        parts = [p.strip() for p in parts if p.strip()]
        if all("=" in p for p in parts):
            items = dict(p.split("=", 1) for p in parts)
        elif any("=" in p for p in parts):
            raise ValueError(
                f"--columns mixes positional and named entries: {spec!r}; use either "
                "'t,ax,ay,az' or 'ax=AccX,ay=AccY,az=AccZ'"
            )
        else:
            items = {}
            for i, p in enumerate(parts):
                if p in ("_", "-", "skip"):
                    continue
                items[p] = str(i)
    out = {}
    for k, v in items.items():
        canon = k.strip().lower()
        if canon not in _CANON:
            raise ValueError(
                f"unknown column {k!r} in --columns; use names from {', '.join(_CANON)} "
                "('_' skips a column)"
            )
        out[canon] = v.strip()
    return out


def _sniff_delimiter(first: str) -> str | None:
    if "\t" in first:
        return "\t"
    if "," in first:
        return ","
    if ";" in first:
        return ";"
    return None  # whitespace


def _is_number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


def _read_text(path: Path) -> tuple[list[str] | None, np.ndarray, int, dict[str, float]]:
    """Header (or None), a float matrix and preamble key/values; bad rows become NaN rows.

    A preamble of ``key,value`` lines before the header (``Fs,50.00``) is skipped and returned
    as a dict; the header is the non-numeric line just before the first numeric row.
    """
    text = path.read_text(errors="replace")
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise ValueError(f"{path} has no data rows")
    delim = _sniff_delimiter(lines[-1])

    def split(line: str) -> list[str]:
        if delim is None:
            return line.split()
        return next(csv.reader(io.StringIO(line), delimiter=delim))

    def numeric(cells: list[str]) -> bool:
        return all(_is_number(c) for c in cells if c.strip())

    # first numeric row whose width the next row repeats: the data starts there
    start = 0
    for i in range(min(len(lines), 64)):
        cells = split(lines[i])
        nxt = split(lines[i + 1]) if i + 1 < len(lines) else cells
        if numeric(cells) and len(nxt) == len(cells):
            start = i
            break
    preamble: dict[str, float] = {}
    header = None
    if start > 0:
        head = split(lines[start - 1])
        if not numeric(head) and len(head) == len(split(lines[start])):
            header = [c.strip() for c in head]
        for line in lines[: start - 1 if header is not None else start]:
            cells = [c.strip() for c in split(line)]
            if len(cells) == 2 and _is_number(cells[1]):
                preamble[cells[0].lower()] = float(cells[1])
    elif not numeric(split(lines[0])):
        header = [c.strip() for c in split(lines[0])]
        start = 1
    body = lines[start:]
    width = len(header) if header is not None else len(split(body[0])) if body else 0
    rows = np.full((len(body), width), np.nan)
    bad = 0
    for i, line in enumerate(body):
        cells = split(line)
        if len(cells) != width:
            bad += 1
            continue
        # non-numeric cells (a 'part' label column, say) become NaN; the calibration counts
        # non-finite values in the columns it uses
        rows[i] = [float(c) if _is_number(c) else np.nan for c in cells]
    return header, rows, bad, preamble


_RATE_KEYS = ("fs", "sample rate", "sample_rate", "samplerate", "rate", "hz", "frequency")


def _read_mat(path: Path) -> tuple[list[str] | None, np.ndarray, int]:
    import scipy.io

    mat = scipy.io.loadmat(path)
    arrays = {
        k: np.asarray(v, float)
        for k, v in mat.items()
        if not k.startswith("__") and isinstance(v, np.ndarray) and v.dtype.kind in "fiu"
    }
    named = {canonical_name(k): v.ravel() for k, v in arrays.items() if v.size and v.ndim <= 2}
    named = {k: v for k, v in named.items() if k is not None and v.ndim == 1}
    if named:
        n = max(len(v) for v in named.values())
        names = list(named)
        return names, np.column_stack([named[k] for k in names if len(named[k]) == n]), 0, {}
    mats = [v for v in arrays.values() if v.ndim == 2 and min(v.shape) >= 3]
    if len(mats) != 1:
        raise ValueError(
            f"{path}: cannot tell which MATLAB variable holds the data "
            f"(found {sorted(arrays)}); save one N x k matrix or variables named ax, ay, az"
        )
    m = mats[0]
    if m.shape[0] < m.shape[1]:
        m = m.T
    return None, m, 0, {}


def load_log(
    path: str | Path,
    columns: str | dict[str, str] | None = None,
    sample_rate: float | None = None,
) -> SensorLog:
    """Load a sensor log (see the module docstring for the formats).

    Parameters
    ----------
    path : path
        The file.
    columns : str or dict, optional
        Column mapping, see :func:`parse_columns`.
    sample_rate : float, optional
        Hz, when the file has no time column (or to override it).
    """
    path = Path(path)
    if not path.exists():
        raise ValueError(f"{path} does not exist")
    mapping = parse_columns(columns)
    is_binary_mat = path.suffix.lower() == ".mat" and path.read_bytes()[:6] == b"MATLAB"
    header, data, bad, preamble = _read_mat(path) if is_binary_mat else _read_text(path)
    notes = []
    if preamble:
        notes.append("preamble: " + ", ".join(f"{k}={v:g}" for k, v in preamble.items()))
    if bad:
        notes.append(f"{bad} rows had the wrong number of fields and were skipped")
    source: dict[str, int] = {}
    if mapping is not None:
        for canon, src in mapping.items():
            if src.isdigit() and (header is None or src not in header):
                source[canon] = int(src)
            elif header is not None:
                lowered = [h.lower() for h in header]
                if src.lower() not in lowered:
                    raise ValueError(
                        f"--columns names {src!r}, which is not in the header {header}"
                    )
                source[canon] = lowered.index(src.lower())
            else:
                raise ValueError(
                    f"{path} has no header; give --columns positionally, e.g. 't,ax,ay,az'"
                )
    if header is not None:
        for j, h in enumerate(header):
            canon = canonical_name(h)
            if canon is not None and canon not in source:
                source[canon] = j
    elif mapping is None:
        width = data.shape[1]
        if width == 3:
            source = {"ax": 0, "ay": 1, "az": 2}
            notes.append("headerless 3-column file read as ax ay az")
        elif width == 4:
            source = {"t": 0, "ax": 1, "ay": 2, "az": 3}
            notes.append("headerless 4-column file read as t ax ay az (the imu_tk layout)")
        else:
            raise ValueError(
                f"{path} has no header and {width} columns; say what they are with --columns, "
                "e.g. --columns t,ax,ay,az,gx,gy,gz"
            )

    def triple(prefix: str) -> np.ndarray | None:
        keys = [prefix + a for a in "xyz"]
        have = [k in source for k in keys]
        if not any(have):
            return None
        if not all(have):
            missing = [k for k, h in zip(keys, have, strict=True) if not h]
            raise ValueError(
                f"{path}: found some but not all of {keys}; map {missing} with --columns"
            )
        return data[:, [source[k] for k in keys]]

    acc, gyro, mag = triple("a"), triple("g"), triple("m")
    if acc is None and mag is None and gyro is None:
        raise ValueError(
            f"{path}: no sensor columns recognised in {header}; map them with --columns, "
            "e.g. --columns ax=AccX,ay=AccY,az=AccZ"
        )
    t = data[:, source["t"]] if "t" in source else None
    temp = data[:, source["temp"]] if "temp" in source else None
    rate = sample_rate
    if rate is None:
        rate = next((preamble[k] for k in _RATE_KEYS if k in preamble), None)
    if rate is None and t is not None:
        dt = np.diff(t[np.isfinite(t)])
        dt = dt[dt > 0]
        if dt.size:
            rate = float(1.0 / np.median(dt))
    names = header if header is not None else [str(i) for i in range(data.shape[1])]
    return SensorLog(
        acc=acc,
        gyro=gyro,
        mag=mag,
        temp=temp,
        t=t,
        sample_rate=rate,
        path=str(path),
        columns={k: names[v] for k, v in source.items()},
        notes=notes,
    )
