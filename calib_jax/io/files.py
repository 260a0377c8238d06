"""Loading sensor logs from text files and MATLAB .mat files.

Supported:

* CSV, TSV, semicolon-, pipe- or whitespace-separated text with a header row. Column names are
  matched case-insensitively, ignoring units in brackets (``t[s]``) and separators: ``t``/``time``/
  ``timestamp``; ``ax ay az`` (also ``acc_x``, ``accx``, ``a_x``); ``gx gy gz`` (``gyr_x``,
  ``gyro_x``); ``mx my mz`` (``mag_x``); ``temp``/``temperature``. Other names are mapped with
  ``columns``. A preamble of ``key,value`` lines before the header (``Fs,50.00``) is read for the
  sample rate.
* Headerless numeric text with a ``columns`` mapping such as ``"t,ax,ay,az"`` (the imu_tk
  files). Without a mapping the width decides, and a note names the guess: 3 columns are
  ``ax ay az`` (``mx my mz`` with ``sensor="mag"``, ``gx gy gz`` with ``sensor="gyro"``; without
  ``sensor``, the one sensor the file's name names: ``xsens_gyro.txt``, ``Magnetometer.csv``),
  4 are ``t`` and those, 6 ``ax ay az gx gy gz`` (``ax ay az mx my mz`` with ``sensor="mag"``),
  7 ``t`` and those, 9 ``ax ay az gx gy gz mx my mz`` and 10 ``t`` and those; any other width is
  an error that asks for the mapping. A file named for another sensor than ``sensor`` is
  refused (a phone's Gyroscope.csv read by ``calib-jax mag``).
* Vendor layouts read without flags: Empatica E4 (a start-time row and a rate row before the
  samples), a rate in a comment line alone or among settings (``# Config: data_rate = 2000.0
  Hz``), ISO dates and times in a column (read as Unix seconds), a header naming a last field
  only some rows have (Mind Monitor's ``Elements``), a header of ``X,Y,Z`` alone (the caller's
  ``sensor`` or the file's name, as for a headerless file: Sensor Logger's
  ``GyroscopeUncalibrated.csv`` with ``time,seconds_elapsed,z,y,x``). Each adds a note.
* UTF-8 (with or without a byte-order mark), UTF-16/32 with a byte-order mark, Latin-1; gzip,
  bzip2 or xz compression (found by the file's first bytes, not its name); decimal commas
  (``1,234;0,998``) when the separator is not a comma. Each of these adds a note.
* MATLAB .mat (real binary MAT files through scipy.io, v7.3 ones through h5py; imu_tk's
  ``.mat`` files are text and are read as text): variables named like columns (``ax``,
  ``acc_x``, ...), N x 3 matrices named for a sensor (``acc``, ``gyro``, ``mag``) or one N x k
  matrix read like headerless text.
* JSON exports, by the same names: a list of records (``[{"t": 0.0, "ax": ...}, ...]``), JSON
  Lines of them, or an object whose (nested) arrays are named like columns or sensors; other
  documents get an error naming their numeric arrays.
* An Arduino sketch's serial output: lines of labelled values (``ax: -12 ay: -812``, ``AcX = 1
  | AcY = 2``) by their labels; a label in every row before the numbers (``a/g:``) left out.
* ArduPilot dataflash logs in text form (``FMT`` lines, then one message a line), by message
  (:mod:`calib_jax.io.dataflash`).
* HDF5 in the BROAD benchmark's layout (``imu_acc``, ``imu_gyr``, ``imu_mag``, the rate in the
  ``sampling_rate`` attribute), through h5py (``pip install 'calib_jax[hdf5]'``); its optical
  truth is read by :func:`calib_jax.io.broad.load_broad`. Other HDF5 layouts: an error naming
  their (N, 3) datasets.

Rows with the wrong number of fields are skipped and counted; cells that are not numbers become
NaN and, with inf and absurd magnitudes, are counted per column in the notes (dropping them is the
caller's job). Whatever cannot be read raises ValueError saying what was found and what to change.
Nothing here modifies the file.
"""

from __future__ import annotations

import bz2
import codecs
import csv
import dataclasses
import gzip
import io
import lzma
import os
import re
import zlib
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .dataflash import looks_like_dataflash, read_dataflash

_CANON = ("t", "ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "temp")

_ALIASES = {
    "t": "t",
    "time": "t",
    "timestamp": "t",
    "times": "t",
    "temp": "temp",
    "tmp": "temp",
    "temperature": "temp",
    "millis": "t",
    "micros": "t",
}
# a time column named with its unit (time_ms, t_us, TimeStamp_ns): the unit itself is read from
# the median step (_time_in_seconds), the name only says which column is time
# chiptime: YEI 3-Space's clock; zeit, tiempo, tempo, tijd: a spreadsheet saved in another language
for _base in ("t", "time", "timestamp", "ts", "chiptime", "zeit", "tiempo", "tempo", "tijd"):
    for _unit in ("", "s", "sec", "ms", "msec", "us", "usec", "ns", "nsec"):
        _ALIASES[_base + _unit] = "t"
_SENSOR_NAMES = {
    "a": ("a", "ac", "acc", "accel", "accelerometer", "acceleration"),  # ac: AcX (Arduino)
    "g": ("g", "gy", "gyr", "gyro", "gyroscope", "w", "angvel", "angularvelocity"),
    "m": ("m", "mag", "magn", "magnetometer", "compass"),
}
for _k, _names in _SENSOR_NAMES.items():
    for _n in _names:
        for _ax in "xyz":
            _ALIASES[f"{_n}{_ax}"] = f"{_k}{_ax}"
            if len(_n) > 1:
                _ALIASES[f"{_ax}{_n}"] = f"{_k}{_ax}"
                # MicroStrain/MSCL (scaledAccelX) and other vendors' raw/calibrated prefixes
                for _pre in ("scaled", "raw", "cal", "imu"):
                    _ALIASES[f"{_pre}{_n}{_ax}"] = f"{_k}{_ax}"
# an N x 3 MATLAB variable named for a sensor ('acc', 'gyro', 'mag') holds its x, y, z
_MATRIX_NAMES = {n: k for k, names in _SENSOR_NAMES.items() for n in names if len(n) > 1}

_SENSORS = {None: "a", "accel": "a", "acc": "a", "mag": "m", "gyro": "g"}
_SENSOR_LABELS = {"a": "accelerometer", "g": "gyroscope", "m": "magnetometer"}
_COMMAND_SENSOR = {"a": "accel", "g": "gyro", "m": "mag"}


def sensor_named_by(path: str | os.PathLike | None) -> str | None:
    """The one sensor ("accel", "gyro" or "mag") a file's name names, word by word
    (``Gyroscope.csv``, ``xsens_gyro.mat``, ``MagnetometerUncalibrated.csv``); None when it
    names none or several. Used only for columns that name no sensor (``x, y, z``, or none)."""
    if path is None:
        return None
    stem = Path(os.fsdecode(path)).name.split(".")[0]
    words = {w.lower() for w in re.findall(r"[A-Z]+(?![a-z])|[A-Z]?[a-z]+", stem)}
    # the words that name a sensor in a column name (one-letter ones are not among them), or
    # their plural (gyros.csv)
    found = {_SENSOR_WORDS.get(w) or _SENSOR_WORDS.get(w.removesuffix("s")) for w in words}
    found.discard(None)
    return _COMMAND_SENSOR[found.pop()] if len(found) == 1 else None


class OtherSensorsFile(ValueError):
    """A file whose name names another sensor than the one asked for, and whose columns name
    none: read, but not this sensor's (a batch entry ``not_fitted``, not ``load_error``)."""


def _sensor_of_bare_columns(
    path,
    sensor: str | None,
    what: str,
    names: tuple[str, str, str] = ("x", "y", "z"),
    timed: bool = False,
) -> tuple[str | None, str]:
    """Which sensor columns that name none (``what``: 'columns x, y, z' or 'headerless 3
    columns') hold: the command's, else the one the file's name names; and why, for the note.
    A name that names another sensor than the command's is refused: a phone's Gyroscope.csv
    read by calib-jax mag would be calibrated as a magnetometer. ``timed``: a headerless
    file's first column is its time (four columns), which a positional --columns must name."""
    named = sensor_named_by(path)
    if named is None or (sensor is not None and _SENSORS[named] == _SENSORS[sensor]):
        return sensor, ""
    if sensor is None:
        label = _SENSOR_LABELS[_SENSORS[named]]
        return named, f"the file's name, {Path(path).name}, names the {label}"
    want, have = _SENSOR_LABELS[_SENSORS[sensor]], _SENSOR_LABELS[_SENSORS[named]]
    p = _SENSORS[sensor]
    alone = (
        f"calib-jax gyro ACC_FILE {Path(path).name}"
        if named == "gyro"
        else f"calib-jax {named} {Path(path).name}"
    )
    raise OtherSensorsFile(
        f"{path}: its {what} name no sensor, and the file's name names the {have}, not the "
        f"{want} this command reads. For the {want}, give its own file (a phone app writes one "
        "file per sensor: calib-jax marg Accelerometer.csv Magnetometer.csv, calib-jax gyro "
        f"Accelerometer.csv Gyroscope.csv); this file calibrates with {alone}; if it does hold "
        f"the {want}, say so with --columns "
        + ",".join(
            f"'{p}{a}={n}'" if " " in n else f"{p}{a}={n}"
            for a, n in zip("xyz", names, strict=True)
        )
        + f" (by position for a headerless file: --columns {'t,' * timed}{p}x,{p}y,{p}z)"
    )


_HUGE = 1e150  # no sensor reads this; its square overflows float64 sums
_HEAD_CHARS = 1 << 16  # the start of the file searched for the header
_TAIL_CHARS = 1 << 15  # the end of the file sampled for the separator and the row width


def _clean(name: str) -> str:
    name = re.sub(r"[\[\(].*?[\]\)]", "", name.strip().lower())
    return re.sub(r"[^a-z0-9]", "", name)


def canonical_name(name: str) -> str | None:
    """The canonical column ('t', 'ax', ..., 'temp') a header name stands for, or None.

    A name in the alias table (``AccX``, ``gyro_z``, ``time_ms``) first; else a name read word
    by word (:func:`_name_by_words`): ROS ``field.linear_acceleration.x``, PX4
    ``accelerometer_m_s2[0]``, phyphox ``X (m/s^2)``."""
    clean = _clean(name)
    if clean not in _ALIASES and (m := re.fullmatch(r"(.+[xyz])[0-9]", clean)):
        # the device's number after the axis (WitMotion's dual logger: AccX1, AccX2), the
        # second device then named twice (_named_twice says how to read it)
        return _ALIASES.get(m[1]) or _name_by_words(name)
    return _ALIASES.get(clean) or _name_by_words(name)


# words that name a sensor in a longer column name, the unit in brackets that does, and the
# words that may stand beside them (units, ROS's 'field', vendors' 'raw'); any other word
# (covariance, delta, est, gravity, orientation, velocity alone) makes the name no reading
_SENSOR_WORDS = {
    **{w: "a" for w in ("acc", "accel", "accelerometer", "acceleration", "accelerations")},
    **{w: "g" for w in ("gyr", "gyro", "gyroscope", "gyrometer")},
    **{w: "m" for w in ("mag", "magn", "magneto", "magnetometer", "magnetic", "compass")},
}
_UNIT_SENSOR = {
    **{u: "a" for u in ("m/s^2", "m/s2", "m/s²", "ms^-2", "m s^-2", "g")},
    **{u: "g" for u in ("rad/s", "deg/s", "dps", "°/s", "rad s^-1")},
    **{u: "m" for u in ("ut", "µt", "μt", "nt", "mt", "gauss", "ga")},
}
_FILLER_WORDS = {
    "field", "linear", "data", "raw", "scaled", "imu", "sensor", "value", "values", "reading",
    "vector", "m", "s", "s2", "ms2", "mps2", "rad", "rads", "deg", "degs", "dps", "ga",
    "gauss", "ut", "nt", "mt", "ln", "wr", "shimmer",
}  # fmt: skip
# words that may follow the axis: the vendor's calibrated / raw variant ('Gyro_X_CAL')
_STATE_WORDS = {"cal", "calibrated", "uncal", "uncalibrated", "raw", "adc"}


_UNIT_LABELS = {
    **{u: "m/s^2" for u in ("m/s^2", "m/s2", "m/s²", "ms^-2", "m s^-2", "ms2", "mps2")},
    **{u: "rad/s" for u in ("rad/s", "rad s^-1", "rad")},
    **{u: "deg/s" for u in ("deg/s", "dps", "°/s")},
    **{u: "uT" for u in ("ut", "µt", "μt")},
    **{u: "gauss" for u in ("gauss", "ga")},
    "nt": "nT",
    "mt": "mT",
    "g": "g",
}


def unit_in_name(name: str) -> str | None:
    """The unit a column name states, in brackets ('X (µT)', 'acc_x [m/s^2]') or as PX4's
    last word ('accelerometer_m_s2[0]', 'magnetometer_ga[0]'); None when it states none."""
    low = name.strip().lower()
    for u in re.findall(r"[\(\[]([^\)\]]*)[\)\]]", low):
        if u.strip() in _UNIT_LABELS:
            return _UNIT_LABELS[u.strip()]
    bare = re.sub(r"\[\s*[012]\s*\]\s*$", "", low)
    if bare.endswith(("_m_s2", "_ms2")):
        return "m/s^2"
    last = re.split(r"[^a-z0-9]+", bare)[-1] if bare else ""
    return {"ga": "gauss", "rad": "rad/s", "ut": "uT"}.get(last) if "_" in bare else None


def bare_axis(name: str) -> str | None:
    """'x', 'y' or 'z' for a column name that names an axis and no sensor: 'X', 'x-axis',
    x-IMU3's 'X Axis (a.u.)' (its Magnetometer.csv); None otherwise."""
    words = re.findall(r"[a-z]+", re.sub(r"[\[\(].*?[\]\)]", " ", name.lower()))
    if words[-1:] == ["axis"]:
        words.pop()
    return words[0] if len(words) == 1 and words[0] in ("x", "y", "z") else None


def _name_by_words(name: str) -> str | None:
    """'field.angular_velocity.x' -> 'gx', 'accelerometer_m_s2[0]' -> 'ax', 'X (µT)' -> 'mx':
    one sensor (named by a word, or by the unit in brackets), one axis (a last word x, y or z,
    or an index [0]-[2], or _0-_2 as OpenAXES's 'ACCEL_BMI160_0') and no word beside them but
    units and fillers."""
    low = name.strip().lower()
    index = re.search(r"\[\s*([012])\s*\]\s*$", low)
    units = [u.strip() for u in re.findall(r"[\(\[]([^\)\]]*)[\)\]]", low)]
    bare = re.sub(r"[\[\(].*?[\]\)]", " ", name.strip())
    words = [
        w.lower()
        for w in re.findall(r"[A-Z]?[a-z]+[0-9]*|[A-Z]+[0-9]*(?![a-z])|[0-9]+[A-Za-z0-9]*", bare)
    ]
    if len(words) > 1 and words[-1] in _STATE_WORDS:
        words.pop()  # Shimmer's 'Shimmer_40AC_Accel_LN_X_CAL'
    # a word with both letters and digits is a device or part name (Shimmer's '40AC'), not a
    # quantity
    words = [w for w in words if not (re.search(r"\d", w) and re.search(r"[a-z]", w))]
    axis = "xyz"[int(index.group(1))] if index else None
    # an index 0-2 as the last word, after a separator: OpenAXES's 'ACCEL_BMI160_0', 'GYRO_2'
    trailing = re.search(r"[_.\- ]([012])$", low)
    if axis is None and trailing and words and words[-1] == trailing.group(1):
        axis = "xyz"[int(words.pop())]
    if axis is None and words and words[-1] in ("x", "y", "z"):
        axis = words.pop()
    if axis is None and set(words) - _FILLER_WORDS - {"unix"} == {"timestamp"}:
        return "t"  # 'Shimmer_40AC_Timestamp_Unix_CAL'; plain time names are aliases
    if "angular" in words and "velocity" in words:  # ROS sensor_msgs/Imu's angular_velocity
        words = [w for w in words if w not in ("angular", "velocity")] + ["gyro"]
    sensors = {_SENSOR_WORDS[w] for w in words if w in _SENSOR_WORDS}
    sensors |= {_UNIT_SENSOR[u] for u in units if u in _UNIT_SENSOR}
    others = [w for w in words if w not in _SENSOR_WORDS and w not in _FILLER_WORDS]
    if any(u in _UNIT_SENSOR for u in units):  # EuRoC/Kalibr's 'a_RS_S_x [m s^-2]': frame
        others = [w for w in others if len(w) > 2]  # letters beside a unit that names the sensor
    if axis is None or len(sensors) != 1 or others:
        return None
    return sensors.pop() + axis


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
    units: dict[str, str] = field(default_factory=dict)
    """Sensor ("accel", "gyro", "mag") -> the unit its column names state ('X (µT)',
    PX4's 'magnetometer_ga[0]'), where all three agree; used as the report's label."""
    layout: dict | None = field(default=None, repr=False, compare=False)
    """Where the rows of a plain text file sit (encoding, first data line, delimiter, column
    indices, time unit), for :func:`iter_rows`; None for MAT and compressed files."""

    def __len__(self) -> int:
        for a in (self.acc, self.mag, self.gyro):
            if a is not None:
                return len(a)
        return 0

    def vectors(self, sensor: str) -> np.ndarray:
        """The (N, 3) float readings of ``sensor`` ("accel", "gyro" or "mag"); a ValueError
        naming the file and the columns to map when the log has none."""
        x = {"accel": self.acc, "gyro": self.gyro, "mag": self.mag}[sensor]
        if x is None:
            cols = {"accel": "ax, ay, az", "gyro": "gx, gy, gz", "mag": "mx, my, mz"}[sensor]
            have = [n for n, a in (("accel", self.acc), ("gyro", self.gyro), ("mag", self.mag))
                    if a is not None]  # fmt: skip
            raise ValueError(
                f"{self.path}: the log has no {sensor} columns ({cols})"
                + (f"; it holds {' and '.join(have)} columns only" if have else "")
                + f"; map them with {COLUMNS_OPTION} if they are there under other names"
            )
        return np.asarray(x, float)


def parse_columns(spec: str | dict[str, str] | list[str] | None) -> dict[str, str] | None:
    """Parse a ``--columns`` mapping.

    ``"t,ax,ay,az"`` (positional, for headerless files) or ``"ax=AccX,ay=AccY,az=AccZ"``
    (canonical=file name, for headers with other names). Returns {canonical: source}, where the
    source of a positional mapping is the column index as a string. Raises ValueError for
    unknown or repeated names and for empty entries.
    """
    if spec is None:
        return None
    if isinstance(spec, dict):
        items = {str(k): str(v) for k, v in spec.items()}
    else:
        parts = spec.split(",") if isinstance(spec, str) else [str(p) for p in spec]
        parts = [p.strip() for p in parts if p.strip()]
        if not parts:
            raise ValueError(
                f"--columns {spec!r} names no columns; use e.g. 't,ax,ay,az' or "
                "'ax=AccX,ay=AccY,az=AccZ'"
            )
        if all("=" in p for p in parts):
            items = {}
            for p in parts:
                k, v = p.split("=", 1)
                if k.strip().lower() in items:
                    raise ValueError(f"--columns maps {k.strip()!r} twice in {spec!r}")
                items[k.strip().lower()] = v
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
                if p.lower() in items:
                    raise ValueError(
                        f"--columns names {p!r} twice in {spec!r}; each column once ('_' skips "
                        "a column)"
                    )
                items[p.lower()] = str(i)
    out = {}
    for k, v in items.items():
        canon = k.strip().lower()
        if canon not in _CANON:
            raise ValueError(
                f"unknown column {k!r} in --columns; use names from {', '.join(_CANON)} "
                "('_' skips a column)"
            )
        if not v.strip():
            raise ValueError(f"--columns gives no file column for {canon!r} in {spec!r}")
        out[canon] = v.strip()
    return out


# ------------------------------------------------------------------------------------------
# bytes -> text


def _read_bytes(path: Path, ends: int | None = None) -> bytes | tuple[bytes, bytes]:
    """The file's bytes; with `ends`, only its first `ends` and last `ends // 2` bytes."""
    if path.is_dir():
        raise ValueError(
            f"{path} is a directory, not a log file; give one file (calib-jax batch calibrates "
            "every log in a folder)"
        )
    if not path.is_file():  # a pipe or a device would be read forever
        raise ValueError(f"{path} is not a regular file (a pipe or a device?); give a log file")
    try:
        if ends is None:
            return path.read_bytes()
        with open(path, "rb") as fh:
            head = fh.read(ends)
            fh.seek(max(0, os.fstat(fh.fileno()).st_size - ends // 2))
            return head, fh.read()
    except PermissionError as e:
        raise ValueError(
            f"{path} cannot be read: permission denied ({e.strerror}); make it readable "
            f"(chmod +r {path}) or run as a user who may read it"
        ) from None
    except OSError as e:
        raise ValueError(f"{path} cannot be read: {e.strerror or e}") from None


_COMPRESSED = (
    (b"\x1f\x8b", "gzip", gzip.decompress, (OSError, EOFError, zlib.error)),
    (b"BZh", "bzip2", bz2.decompress, (OSError, EOFError, ValueError)),
    (b"\xfd7zXZ\x00", "xz", lzma.decompress, (lzma.LZMAError, EOFError)),
)


def _decompress(raw: bytes, path: Path, notes: list[str]) -> tuple[bytes, bool]:
    for magic, name, fn, errors in _COMPRESSED:
        if raw.startswith(magic) and (name != "bzip2" or raw[3:4].isdigit()):
            try:
                out = fn(raw)
            except errors as e:
                raise ValueError(
                    f"{path} is {name}-compressed but does not decompress ({e}); it is probably "
                    "truncated: copy it again, or decompress it yourself to see what is left"
                ) from None
            notes.append(f"{name}-compressed file, decompressed in memory")
            return out, True
    return raw, False


class ConvertibleFile(ValueError):
    """A binary log whose format the loader names, with the converter whose output it reads
    (a PX4 ULog, an ArduPilot .bin): the CLI keeps this message instead of its own 'a binary
    file'."""


def _binary(path: Path, what: str, how: str | None = None) -> ValueError:
    if how is not None:
        return ConvertibleFile(f"{path} is not a text log ({what}); {how}")
    return ValueError(
        f"{path} is not a text log ({what}); export it as CSV or text with one row per sample "
        "(or a MATLAB .mat file)"
    )


def _decode(raw: bytes, path: Path, notes: list[str], partial: bool = False) -> tuple[str, str]:
    """The text and the codec name that decodes it (for np.loadtxt to read the file itself).

    `partial`: `raw` is the start of a longer file, possibly cut inside a character.
    """
    if raw.startswith(_HDF5_MAGIC):
        raise _binary(path, "an HDF5 file; read it with h5py")
    if raw.startswith(b"PK\x03\x04"):
        raise _binary(path, "a zip archive, or an Excel/ODF workbook; unzip it or save as CSV")
    if raw.startswith(b"ULog\x01\x12\x35"):
        raise _binary(
            path,
            "a PX4 ULog",
            "pyulog's ulog2csv writes its topics as CSV files that calib-jax reads: pip install "
            "pyulog; ulog2csv FILE; the accelerometer and gyroscope are then in "
            "*_sensor_combined_0.csv, the magnetometer in *_sensor_mag_0.csv",
        )
    if raw.startswith(b"\xa3\x95\x80"):  # a dataflash header, then the FMT message (128)
        raise _binary(
            path,
            "an ArduPilot dataflash .bin",
            "write its IMU and MAG messages as CSV with pymavlink (mavlogdump.py --format csv "
            "--types IMU FILE > imu.csv, and --types MAG), or save it as a text .log with "
            "Mission Planner, which calib-jax reads as it is",
        )
    boms = (
        (codecs.BOM_UTF32_LE, "utf-32", "UTF-32"),
        (codecs.BOM_UTF32_BE, "utf-32", "UTF-32"),
        (codecs.BOM_UTF8, "utf-8-sig", "UTF-8 with a byte-order mark"),
        (codecs.BOM_UTF16_LE, "utf-16", "UTF-16"),
        (codecs.BOM_UTF16_BE, "utf-16", "UTF-16"),
    )
    enc = None
    for bom, codec, label in boms:
        if raw.startswith(bom):
            enc = codec
            notes.append(f"text encoded as {label}")
            break
    if enc is None:
        sample = raw[:4096]
        if b"\0" in sample:
            even, odd = sample[0::2], sample[1::2]
            if len(sample) >= 4 and odd.count(0) > 0.9 * len(odd) and even.count(0) == 0:
                enc = "utf-16-le"
            elif len(sample) >= 4 and even.count(0) > 0.9 * len(even) and odd.count(0) == 0:
                enc = "utf-16-be"
            else:
                raise _binary(path, f"{sample.count(0)} NUL bytes in its first {len(sample)}")
            notes.append("text encoded as UTF-16 without a byte-order mark")
    if enc is None:
        try:
            try:
                text = raw.decode("utf-8")
            except UnicodeDecodeError as e:
                if not (partial and e.start >= len(raw) - 3):
                    raise
                text = raw[: e.start].decode("utf-8")  # cut inside the last character
            enc = "utf-8"
        except UnicodeDecodeError:
            enc = "latin-1"
            text = raw.decode("latin-1")
            notes.append("not valid UTF-8: read as Latin-1 (only header names can differ)")
    else:
        text = raw.decode(enc, errors="replace")
    sample_text = text[:4096]
    odd_chars = sum(
        1
        for ch in sample_text
        if (ord(ch) < 32 and ch not in "\t\n\r\f\v\x1a") or 0x7F <= ord(ch) < 0xA0 or ch == "\ufffd"
    )
    if sample_text and odd_chars > max(2, 0.01 * len(sample_text)):
        raise _binary(
            path, f"{odd_chars} control or undecodable characters in its first {len(sample_text)}"
        )
    return text, enc


# ------------------------------------------------------------------------------------------
# text -> header, preamble and a float matrix


def _split_lines(text: str) -> list[str]:
    # the line ends np.loadtxt knows (universal newlines), so line numbers agree with skiprows
    return text.replace("\r\n", "\n").replace("\r", "\n").split("\n")


_COMMENTS = ("#", "%", "//")


def _skip(line: str) -> bool:
    s = line.strip()
    return not s or s.startswith(_COMMENTS)


def _num(cell: str) -> bool:
    try:
        float(cell)
        return True
    except ValueError:
        return False


def _strip_cell(c: str) -> str:
    return c.strip().strip("\"'").strip()


def _cells(line: str, delim: str | None) -> list[str]:
    return line.split() if delim is None else line.split(delim)


_DELIMS = ("\t", ";", ",", "|", None)
_DELIM_NAMES = {"\t": "tab", ";": "';'", ",": "','", "|": "'|'", None: "whitespace"}


def _comment_text(line: str) -> str:
    text = line.strip()
    for mark in _COMMENTS:
        if text.startswith(mark):
            return text[len(mark) :].strip()
    return text


def _names_in_comment(line: str, delim: str | None, width: int) -> list[str] | None:
    """Column names in a comment line, when it lists one per column and at least three are
    sensor or time names: '# Data format: "%int(ChipTimeUS),%float(RawGyroX),..."' (a label
    before a colon, quotes and printf wrappers are dropped)."""
    text = _comment_text(line)
    label, colon, rest = text.partition(":")
    if colon and (delim is None or delim not in label):
        text = rest
    text = re.sub(r"%\w+\(([^)]*)\)", r"\1", text.strip().strip("\"'"))
    names = _header_cells(text, delim)
    known = sum(canonical_name(n) is not None for n in names)
    return names if len(names) == width and known >= 3 else None


def _unit_in_comment(line: str) -> dict[str, str]:
    """A sensor's unit stated alone in a comment line, by sensor prefix: '#\tMagneto: gauss'
    (sensbiotk's FOX logs) gives {'m': 'gauss'}; anything else gives {}."""
    m = re.fullmatch(r"([A-Za-z]+)\s*:\s*(\S+)", _comment_text(line))
    if not m:
        return {}
    sensor = _SENSOR_WORDS.get(m.group(1).lower())
    unit = _UNIT_LABELS.get(m.group(2).lower().replace(".", "/", 1).replace("/s^-2", "/s^2"))
    return {sensor: unit} if sensor and unit and _UNIT_SENSOR.get(unit.lower()) == sensor else {}


def _rate_in_comment(line: str) -> float | None:
    """A sample rate stated in a comment line ('// Sample rate: 50.0Hz', '# fs = 100'), alone
    or as one of its settings ('# Config: data_rate = 2000.0 Hz, filter = 488 Hz': PicoQuake)."""
    text = _comment_text(line)
    m = re.fullmatch(r"([A-Za-z _]+?)\s*[:=]\s*([0-9.]+)\s*(hz)?", text, re.I)
    if m and m.group(1).strip().lower() in _RATE_KEYS:
        value = m.group(2)
    else:
        keys = "|".join(k.replace(" ", "[ _]") for k in _RATE_KEYS_NAMED)
        m = re.search(rf"(?<![a-z])(?:{keys})\s*[:=]\s*([0-9.]+)\s*hz\b", text, re.I)
        value = m.group(1) if m else None
    try:
        return None if value is None else float(value)
    except ValueError:
        return None


def _rate_in_banner(line: str) -> float | None:
    """The rate in a device's banner line above the data, as ActiLife writes it: '---- Data
    File Created By ActiGraph GT3X+ ActiLife v6.13.3 ... date format M/d/yyyy at 90 Hz
    Filter Normal ----' (a new-user trial's raw export was fitted in samples, not seconds).
    Only ActiGraph's banner: elsewhere 'at N Hz' can be a filter's cut-off, not the rate."""
    if not re.search(r"actigraph|actilife", line, re.I):
        return None
    m = re.search(r"(?<![a-z])at\s+([0-9]+(?:\.[0-9]+)?)\s*hz\b", line, re.I)
    return float(m.group(1)) if m else None


def _start_and_rate_rows(rows: list[list[str]], num, value) -> tuple[float, float] | None:
    """Empatica E4's header (ACC.csv, BVP.csv, ...): before the samples, a row of the start
    time in Unix seconds and a row of the sample rate in Hz, each the same in every column.
    (start time, rate) when the first two of ``rows`` are those and the third is a sample;
    ``num`` says whether a cell is a number, ``value`` reads it."""
    if len(rows) < 3 or len(rows[0]) < 2 or not all(num(c) for r in rows[:2] for c in r):
        return None
    first, second = ({value(c) for c in r} for r in rows[:2])
    if len(first) != 1 or len(second) != 1 or len(set(map(_strip_cell, rows[2]))) == 1:
        return None
    t0, rate = first.pop(), second.pop()
    return (t0, rate) if t0 > 1e8 and 0 < rate <= 1e5 else None


def _line_end(line: str, delim: str) -> str:
    """The line without its trailing white space, a tab kept when tabs separate the fields
    (Xsens MT Manager ends every row with one: '1\t2\t3\t')."""
    return line.rstrip(" \r\n\f\v" if delim == "\t" else None)


def _sniff(lines: list[str], head: list[str] = ()) -> tuple[str | None, bool, int, bool]:
    """Separator, decimal commas, the usual row width, and whether rows end in a separator."""
    best = (0.0, 0, None, False, 0, False)
    for rank, d in enumerate(_DELIMS):
        rows = [[_strip_cell(c) for c in _cells(ln, d)] for ln in lines]
        # a separator ending most rows ('1,2,3,') does not start an empty last column
        # (in 9 of 10 rows at both ends: an empty last column at the end of a log is not one)
        trailing = d is not None and all(
            10 * sum(_line_end(ln, d).endswith(d) for ln in part) >= 9 * len(part)
            for part in (lines, head or lines)
        )
        if trailing:
            rows = [r[:-1] if len(r) > 1 and r[-1] == "" else r for r in rows]
        counts = Counter(len(r) for r in rows)
        w, nw = max(counts.items(), key=lambda kv: (kv[1], kv[0]))
        if w < 2:
            continue
        cells = [c for r in rows if len(r) == w for c in r if c]
        if not cells:
            continue
        share = nw / len(rows)
        plain = share * sum(map(_num, cells)) / len(cells)
        for score, dec in ((plain, False), (0.0, True)):
            if dec and d != "," and any("," in c for c in cells):
                score = 0.99 * share * sum(_num(c.replace(",", ".")) for c in cells) / len(cells)
            if (score, -rank) > (best[0], -best[1]):
                best = (score, rank, d, dec, w, trailing)
    if best[0] <= 0:
        raise ValueError("no rows of numbers found")
    return best[2], best[3], best[4], best[5]


@dataclass
class _Table:
    header: list[str] | None
    data: np.ndarray
    bad: int = 0
    preamble: dict[str, float] = field(default_factory=dict)
    odd_header: list[str] | None = None
    layout: dict | None = None
    """How the rows sit in a plain text file on disk (see :func:`iter_rows`), else None."""
    units: dict[str, str] = field(default_factory=dict)
    """Units comment lines state per sensor ('# Magneto: gauss'), by sensor prefix a, g, m."""


def _parse_rows(
    rows: list[str],
    delim: str | None,
    width: int,
    dec: bool,
    trailing: bool,
    text_cols: frozenset[int] = frozenset(),
) -> tuple[np.ndarray, int]:
    """A float matrix of the rows with `width` fields (others skipped and counted).

    `text_cols`: columns of labels (no numbers in the sample), left NaN without parsing,
    except a column of dates and times ('2021-04-05 15:48:04.834', ISO 8601), read as Unix
    seconds (:func:`_datetimes`).
    """
    if dec:
        rows = [ln.replace(",", ".") for ln in rows]
    if trailing:
        ends = (_line_end(ln, delim) for ln in rows)  # once per row: this runs on every row
        rows = [e[:-1] if e.endswith(delim) else ln for ln, e in zip(rows, ends, strict=True)]
    rows = [ln.split("#", 1)[0] if "#" in ln else ln for ln in rows]
    if delim is None:
        widths = [len(ln.split()) for ln in rows]
    else:
        widths = [ln.count(delim) + 1 for ln in rows]
    good = [ln for ln, w in zip(rows, widths, strict=True) if w == width]
    bad = len(rows) - len(good)
    out = np.full((len(good), width), np.nan)

    def by_line(lo: int, lines: list[str]) -> None:
        for i, ln in enumerate(lines):
            for j, c in enumerate(_cells(ln, delim)):
                try:
                    out[lo + i, j] = float(_strip_cell(c))
                except ValueError:
                    pass  # not a number (a label, an empty cell): NaN, counted by the caller

    def fast(lo: int, lines: list[str]) -> int | None:
        """Parse with numpy; None when done, else the row numpy stopped at (or -1)."""
        try:
            block = _loadtxt(lines, delim, 0, usecols=numeric)
        except ValueError as e:
            m = re.search(r"at row (\d+)", str(e))  # numpy names the bad row: a hint only
            return int(m.group(1)) if m else -1
        if block.shape != (len(lines), len(numeric)):
            return -1
        out[lo : lo + len(lines), numeric] = block
        return None

    # the rows all have `width` fields here, so numpy may skip the label columns
    numeric = [j for j in range(width) if j not in text_cols]

    step = 4096
    for lo in range(0, len(good), step):
        chunk = good[lo : lo + step]
        i, tries = 0, 0
        while i < len(chunk):
            k = fast(lo + i, chunk[i:])
            if k is None:
                break
            tries += 1
            if not 0 <= k < len(chunk) - i or tries > 64:
                by_line(lo + i, chunk[i:])  # no usable hint: the rest of the chunk line by line
                break
            if k and fast(lo + i, chunk[i : i + k]) is not None:
                by_line(lo + i, chunk[i : i + k])
            by_line(lo + i + k, chunk[i + k : i + k + 1])
            i += k + 1
    for j in text_cols:
        stamps = _datetimes([_cells(ln, delim)[j] for ln in good])
        if stamps is not None:
            out[:, j] = stamps
    return out, bad


_CLOCK = re.compile(r"(\d{1,2}):(\d{2}):(\d{2}(?:\.\d*)?)")


def _clock_times(cells: list[str]) -> np.ndarray | None:
    """Times of day ('10:41:11.376', '16:21:10': a WitMotion logger's, a Sense HAT's) as
    seconds, a day added at each midnight; None when a cell is something else."""
    found = [_CLOCK.fullmatch(c) if c else None for c in cells]
    if not any(found) or any(c and m is None for c, m in zip(cells, found, strict=True)):
        return None
    out = np.array(
        [int(m[1]) * 3600 + int(m[2]) * 60 + float(m[3]) if m else np.nan for m in found]
    )
    ok = np.isfinite(out)
    back = np.zeros(len(out))
    back[np.flatnonzero(ok)[1:]] = np.diff(out[ok]) < -43200  # past midnight
    return out + 86400.0 * np.cumsum(back)


def _datetimes(cells: list[str]) -> np.ndarray | None:
    """ISO 8601 dates and times ('2021-04-05 15:48:04.834') as Unix seconds, or times of day
    as seconds (:func:`_clock_times`); NaN for an empty cell, None when a cell is something
    else."""
    cells = [_strip_cell(c) for c in cells]
    if any(cells) and (clock := _clock_times(cells)) is not None:
        return clock
    if not any(cells) or not all(len(c) >= 10 and c[4] == "-" for c in cells if c):
        return None
    try:
        stamps = np.array([c or "NaT" for c in cells], dtype="datetime64[us]")
    except ValueError:
        return None
    out = stamps.astype("int64") / 1e6
    out[np.isnat(stamps)] = np.nan
    return out


def iter_rows(path: str | Path, layout: dict, rows: int = 262_144):
    """The data rows of a plain text log, in order, ``rows`` lines at a time: yields
    ``(block, n_skipped)``, a float matrix of the file's columns and the count of rows with
    the wrong number of fields (skipped, as :func:`load_log` skips them). ``layout`` is a
    loaded log's :attr:`SensorLog.layout` (``load_log(path, max_rows=...)`` finds it from the
    head); memory stays bounded by ``rows`` whatever the file's length."""
    import itertools

    args = (layout["delim"], layout["width"], layout["dec"], layout["trailing"])
    with open(path, encoding=layout["enc"], newline=None, errors="replace") as fh:
        for _ in itertools.islice(fh, layout["start"]):
            pass
        while lines := list(itertools.islice(fh, rows)):
            body = [ln for ln in lines if (s := ln.lstrip()) and not s.startswith(_COMMENTS)]
            yield _parse_rows(body, *args, layout["text_cols"])


def _refuse_epoch_counts(path, preamble: list[str]) -> None:
    """ActiLife's export of activity counts (an 'Epoch Period' other than 00:00:00 in its
    preamble): counts summed over each epoch, not readings, so no calibration can use them."""
    for line in preamble:
        m = re.search(r"Epoch Period \(hh:mm:ss\) (\d\d:\d\d:\d\d)", line)
        if m and m.group(1) != "00:00:00":
            raise ValueError(
                f"{path} is an ActiGraph export of activity counts per {m.group(1)} epoch, not "
                "accelerometer readings: a calibration needs the raw samples (in ActiLife, "
                "export the .gt3x file's raw data to CSV: 'Accelerometer X, Y, Z' in g)"
            )


def _unbracket(text: str) -> str | None:
    """Lines that are JSON lists or Python tuples of numbers (``[[ax, ay, az], [gx, gy, gz],
    t]``, as micropython-fusion logs; ``((ax, ay, az), (mx, my, mz))``, a MicroPython print of
    a driver's readings): the text without the brackets, so each line reads as a row of its
    numbers; None when most lines are something else."""
    lines = [s for ln in text[:_HEAD_CHARS].splitlines()[:60] if (s := ln.strip())][:50]
    pairs = (("[", "]"), ("(", ")"))
    for left, right in pairs:
        listed = sum(s.startswith(left) and s.endswith(right) for s in lines)
        if len(lines) >= 2 and listed >= 0.8 * len(lines):
            return text.translate({ord(left): None, ord(right): None})
    return None


_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_LABELLED = re.compile(
    rf"\s*([A-Za-z][\w./]*(?: [A-Za-z][\w./]*)?)\s*[:=]\s*({_NUMBER})\s*(?:[|,;\t]\s*)?"
)


def _labelled_pairs(line: str) -> list[tuple[str, str]] | None:
    """The (label, number) pairs a whole line is made of ('AcX = 11219 | AcY = 4382', 'ax: -12
    ay: -812'), else None."""
    line, pos, out = line.rstrip(), 0, []
    while pos < len(line):
        m = _LABELLED.match(line, pos)
        if m is None or m.end() == pos:
            return None
        out.append(m.groups())
        pos = m.end()
    return out or None


def _labels(text: str) -> tuple[str, ...] | None:
    """The labels of a log of labelled values, an Arduino sketch's serial output (``AcX =
    11219 | AcY = 4382 | ...``, ``ax: -12 ay: -812 az: 15032``): those most of its first lines
    are made of, in their order (three or more); None for any other text."""
    head = [ln for ln in _split_lines(text[:_HEAD_CHARS])[:200] if ln.strip()]
    keys = [tuple(k for k, _ in p) for ln in head if (p := _labelled_pairs(ln)) and len(p) >= 3]
    if len(keys) < 5 or len(keys) < 0.5 * len(head):
        return None
    labels, n = Counter(keys).most_common(1)[0]
    return labels if n >= 0.8 * len(keys) and len(set(labels)) == len(labels) else None


def _unlabel(text: str, labels: tuple[str, ...], notes: list[str]) -> str:
    """The log of labelled values as a table whose header is ``labels``: a line of one pair
    above the data (``Fs: 100.00``) becomes a preamble entry, lines of other labels among the
    data are left out, counted in a note."""
    out, rows, other = [], [], 0
    for ln in _split_lines(text):
        p = _labelled_pairs(ln) if ln.strip() else None
        if p and tuple(k for k, _ in p) == labels:
            rows.append(",".join(v for _, v in p))
        elif not rows and p and len(p) == 1:
            out.append(",".join(p[0]))
        elif not rows and not p:
            out.append(ln)  # a banner line: the reader notes it
        elif ln.strip():
            other += 1
    notes.append(
        f"lines of labelled values read as columns named by their labels ({', '.join(labels)})"
        + (f"; {other} other line(s) among them left out" if other else "")
    )
    return "\n".join([*out, ",".join(labels), *rows]) + "\n"


def _tail_codec(enc: str, head: bytes) -> str:
    if enc == "utf-8-sig":
        return "utf-8"
    if enc in ("utf-16", "utf-32"):
        le = head.startswith((codecs.BOM_UTF32_LE, codecs.BOM_UTF16_LE))
        return enc + ("-le" if le else "-be")
    return enc


def _read_text(
    path: Path,
    raw: bytes,
    on_disk: bool,
    notes: list[str],
    tail_raw: bytes | None = None,
    max_rows: int | None = None,
) -> _Table:
    """Header (or None), a float matrix and preamble key/values; bad rows skipped and counted.

    A preamble of ``key,value`` lines before the header (``Fs,50.00``) is returned as a dict;
    the header is the text line (no numbers) just before the first data row, with as many
    fields as the data rows have (rows of numbers in between are ragged data, skipped).

    With `tail_raw`, `raw` is only the start of a big file on disk and `tail_raw` its end: a
    clean file then goes from disk to numpy's parser without being decoded here.
    With `max_rows`, only the first `max_rows` data rows are read (the rest can be streamed
    with the returned layout, :func:`iter_rows`).
    """
    big = tail_raw is not None
    text, enc = _decode(raw, path, notes, partial=big)
    if (unbracketed := _unbracket(text)) is not None:
        notes.append(
            "lines of bracketed lists ('[[ax, ay, az], ...]', '((ax, ay, az), ...)') read as "
            "rows of their numbers"
        )
        if big:  # read it all: the rows are parsed from this text, not from the file
            unbracketed = _unbracket(_decode(_read_bytes(path), path, [])[0])
            big, tail_raw = False, None
        text, on_disk = unbracketed, False
    elif (labels := _labels(text)) is not None:
        whole = _decode(_read_bytes(path), path, [])[0] if big else text
        text, on_disk = _unlabel(whole, labels, notes), False
        big, tail_raw = False, None
    cache = {"text": None if big else text}

    def whole_text() -> str:
        if cache["text"] is None:
            more: list[str] = []
            cache["text"], _ = _decode(_read_bytes(path), path, more)
            notes.extend(n for n in more if n not in notes)
        return cache["text"]

    whole = not big and len(text) <= _HEAD_CHARS + _TAIL_CHARS
    head = _split_lines(text if whole else text[:_HEAD_CHARS])
    if not whole:
        head = head[:-1]  # cut mid-line
    if big:
        tail = _split_lines(tail_raw.decode(_tail_codec(enc, raw), errors="replace"))[1:]
    else:
        tail = head if whole else _split_lines(text[-_TAIL_CHARS:])[1:]
    sample = [ln for ln in tail if not _skip(ln)]
    if len(sample) < 20 and tail is not head:  # the end is mostly comments: use the start too
        sample = [ln for ln in head if not _skip(ln)] + sample
    if not sample:
        if not text.strip():
            raise ValueError(f"{path} is empty: no rows to read")
        if not whole:  # lines longer than the head read: a few rows of very many numbers?
            rows = [ln for ln in _split_lines(whole_text()) if ln.strip() and not _skip(ln)]
            cells = min(max(len(_cells(r, d)) for d in _DELIMS) for r in rows[:TRANSPOSED_ROWS])
            _refuse_transposed(path, len(rows), cells)
        raise ValueError(f"{path} has no data rows (only blank or comment lines)")
    sample = sample[-200:] if len(sample) > 200 else sample
    try:
        first_rows = [ln for ln in head[:300] if not _skip(ln) and any(map(str.isdigit, ln))]
        delim, dec, width, trailing = _sniff(sample, first_rows[:100])
    except ValueError:
        first = next((ln for ln in head if not _skip(ln)), "")
        raise ValueError(
            f"{path} has no rows of numbers with at least two columns (first line: "
            f"{first[:80]!r}); a log needs one row per sample, e.g. 't,ax,ay,az' then numbers"
        ) from None
    if dec:
        notes.append(
            f"decimal commas read as decimal points ({_DELIM_NAMES[delim]}-separated file)"
        )

    def num(c: str) -> bool:
        c = _strip_cell(c)
        return _num(c.replace(",", ".") if dec else c)

    def split(line: str) -> list[str]:
        cells = _cells(line, delim)
        if trailing and len(cells) > 1 and not cells[-1].strip():
            cells = cells[:-1]
        return cells

    def data_like(cells: list[str]) -> bool:
        full = [c for c in cells if c.strip()]
        n = sum(map(num, full))
        return n >= 1 and 2 * n >= len(full)

    lines = head
    start = next(
        (
            i
            for i, ln in enumerate(lines)
            if not _skip(ln) and len(split(ln)) == width and data_like(split(ln))
        ),
        None,
    )
    if start is None and not whole:
        lines = _split_lines(whole_text())
        start = next(
            (
                i
                for i, ln in enumerate(lines)
                if not _skip(ln) and len(split(ln)) == width and data_like(split(ln))
            ),
            None,
        )
    if start is not None and trailing:
        # every row ending in a separator may end in an empty last column instead: a header
        # naming one field more than the rows keep, and not itself ending in the separator,
        # says so (TWLogger's 21 names, the last GPS fields empty in every row but a fix's)
        above = next((ln for ln in reversed(lines[:start]) if not _skip(ln)), None)
        names = _cells(_line_end(above, delim), delim) if above is not None else []
        if len(names) == width + 1 and _strip_cell(names[-1]) and not any(map(num, names)):
            trailing, width = False, width + 1
    if start is None:
        first = next((ln.strip() for ln in lines if not _skip(ln)), "")
        raise ValueError(
            f"{path}: no row of {width} plain numbers found (first line: {first[:80]!r}); a log "
            "holds one sample per line, numbers separated by commas, semicolons, tabs or "
            "spaces (brackets or other text around them are not read): convert it, e.g. "
            "'t,ax,ay,az' then one row of numbers per sample"
        )

    def value(c: str) -> float:
        c = _strip_cell(c)
        return float(c.replace(",", ".") if dec else c)

    e4 = _start_and_rate_rows([split(ln) for ln in lines[start : start + 3]], num, value)
    if e4 is not None:  # Empatica E4: the start time and the rate stand as two rows of data
        start += 2
        notes.append(
            f"rows 1-2 read as Empatica E4's start time ({e4[0]:.0f} s, Unix time) and sample "
            "rate, each repeated in every column, not as samples"
        )

    # walk back from the first data row: ragged rows of numbers, then the header (a text line,
    # possibly followed by a units line), then the preamble
    bad = 0
    header_rows: list[tuple[int, list[str]]] = []
    odd_header = None
    stop = 0
    j = start - (1 if e4 is None else 3)
    while j >= 0:
        ln = lines[j]
        if _skip(ln):
            j -= 1
            continue
        cells = split(ln)
        full = [c for c in cells if c.strip()]
        nnum = sum(map(num, full))
        if nnum == 0 and full:
            names = _header_cells(ln, delim)
            while len(names) > width and not names[-1]:
                names.pop()
            if len(names) == width and (width < 2 or sum(bool(n.strip()) for n in names) >= 2):
                # (one name padded with empty cells is a title, e.g. ActiLife's preamble lines)
                header_rows.append((j, names))
                j -= 1
                continue  # a units line under the names: look one further up
            if not header_rows and len(names) >= 2 and any(map(canonical_name, names)):
                odd_header, odd_at = names, j  # a header, by its names, that does not fit
            stop = j + 1
            break
        if header_rows:
            stop = j + 1
            break
        if len(full) == 2 and not num(full[0]) and num(full[1]) and width != 2:
            stop = j + 1
            break  # key,value preamble
        if data_like(cells):
            bad += 1  # a ragged row of numbers between the header and the data
            j -= 1
            continue
        stop = j + 1
        break
    header = None
    if header_rows:
        # the names line is the one with most recognised names; ties go to the upper line
        best = max(
            header_rows, key=lambda r: (sum(canonical_name(c) is not None for c in r[1]), r[0] * -1)
        )
        header = best[1]
        others = [r for r in header_rows if r is not best]
        joined = _group_and_axis(header_rows)
        if joined is not None:
            header, others = joined, []
            notes.append(
                f"header lines {header_rows[1][0] + 1}-{header_rows[0][0] + 1} read together, "
                f"group names over axis names: {', '.join(n for n in joined if n)}"
            )
        if others:
            notes.append(
                f"header line {best[0] + 1} read ({','.join(best[1])[:80]}); "
                + "; ".join(f"line {r[0] + 1} skipped ({','.join(r[1])[:80]})" for r in others)
            )
        stop = min(r[0] for r in header_rows)
    if odd_header is not None and len(odd_header) > width:
        # names for trailing fields most rows leave out (Mind Monitor's 'Elements', written on
        # marker rows only): the header fits the rows that have them, the first names the rest
        rows_seen = [split(ln) for ln in lines[start:] + sample if ln != lines[odd_at]]
        if any(len(r) == len(odd_header) for r in rows_seen):
            extra = odd_header[width:]
            notes.append(
                f"the header has {len(odd_header)} names and most rows {width} fields: the last "
                f"name(s) {', '.join(map(repr, extra))} are fields only some rows have; those "
                "rows are skipped"
            )
            header, odd_header, stop = odd_header[:width], None, odd_at
    if header is None:  # names in a comment line above the data (YEI 3-Space's '# Data format')
        for ln in reversed(lines[:start]):
            names = _names_in_comment(ln, delim, width) if _skip(ln) and ln.strip() else None
            if names:
                header = names
                line = ln.strip()  # cut after a name, not inside one (EuRoC's "[rad ")
                cut = line.rfind(delim or " ", 0, 70)
                shown = line if len(line) <= 70 else line[: cut if cut > 0 else 70] + " ..."
                notes.append(f"column names read from the comment line {shown!r}")
                break
    preamble: dict[str, float] = {} if e4 is None else {"sample rate": e4[1]}
    ignored = []
    units: dict[str, str] = {}
    for k, ln in enumerate(lines[:start]):  # comment lines anywhere above the data, and the
        # preamble above the header (a file of comments then data has stop 0: sensbiotk's FOX)
        if _skip(ln):
            rate = _rate_in_comment(ln)
            if rate is not None:
                preamble["sample rate"] = rate
            units.update(_unit_in_comment(ln))
            continue
        if k >= stop:
            continue
        cells = [_strip_cell(c) for c in _cells(ln, delim)]
        cells = [c for c in cells if c] if delim is not None else cells
        if len(cells) == 2 and not _num(cells[0]) and num(cells[1]):
            preamble[cells[0].lower().rstrip(":= ")] = value(cells[1])  # 'Fs: 100.00'
        elif len(cells) == 2 and (rate := _rate_in_comment(" ".join(cells))) is not None:
            preamble["sample rate"] = rate  # 'OutputRate:,60Hz' (Xsens DOT)
        else:
            if (rate := _rate_in_banner(ln)) is not None:
                preamble["sample rate"] = rate
            ignored.append(ln.strip())
    if ignored:
        _refuse_epoch_counts(path, ignored)
        notes.append(f"{len(ignored)} line(s) before the data ignored (first: {ignored[0][:60]!r})")

    # label columns: a word in every cell of the first and the last rows (an empty cell or one
    # number and the column is parsed)
    rows = [split(ln) for ln in lines[start : start + 50] + sample if not _skip(ln)]
    rows = [r for r in rows if len(r) == width]
    text_cols = frozenset(
        j
        for j in range(width)
        if len(rows) >= 5 and all(_strip_cell(r[j]) and not num(r[j]) for r in rows)
    )
    plain = on_disk and path.suffix.lower() not in (".gz", ".bz2", ".xz", ".lzma", ".zip")
    layout = None
    if plain:
        layout = dict(
            enc=enc, start=start, delim=delim, dec=dec, width=width, trailing=trailing,
            text_cols=text_cols,
        )  # fmt: skip
    data = None
    if not dec:
        # the fast path: numpy's C parser on the rows (reading the file itself when nothing had
        # to be decompressed); it refuses ragged rows and non-numbers, which go line by line
        try:
            if plain:
                # numpy opening the file itself is ~10 % faster than reading our handle
                block = _loadtxt(str(path), delim, start, enc, max_rows=max_rows)
            elif on_disk:  # our own handle: numpy would decompress by the name
                with open(path, encoding=enc, newline=None) as fh:
                    block = _loadtxt(fh, delim, start, max_rows=max_rows)
            else:
                block = _loadtxt(_split_lines(text)[start:], delim, 0, max_rows=max_rows)
            if block.shape[1] == width:
                data = block
        except (ValueError, OSError):  # UnicodeError is a ValueError
            data = None
    if data is None:
        body = [
            ln
            for ln in _split_lines(whole_text())[start:]
            if (s := ln.lstrip()) and not s.startswith(_COMMENTS)
        ]
        data, more = _parse_rows(body[:max_rows], delim, width, dec, trailing, text_cols)
        bad += more
    return _Table(header, data, bad, preamble, odd_header, layout, units)


def _loadtxt(
    src,
    delim: str | None,
    skip: int,
    enc: str | None = None,
    usecols: list[int] | None = None,
    max_rows: int | None = None,
) -> np.ndarray:
    return np.loadtxt(
        src,
        delimiter=delim,
        skiprows=skip,
        ndmin=2,
        dtype=float,
        quotechar='"',
        comments="#",
        encoding=enc,
        usecols=usecols,
        max_rows=max_rows,
    )


def _group_and_axis(header_rows: list[tuple[int, list[str]]]) -> list[str] | None:
    """One header from two lines, a group's name over the first of its columns and an axis
    name under each (repoIMU's 'IMU Acceleration;;;' over 'X;Y;Z;'): the group name carried
    right over the empty cells and joined to each axis ('IMU Acceleration X'). None unless the
    joined names recognise more columns than either line alone. ``header_rows``: (line index,
    names) walking up from the data, so the axis line comes first."""
    if len(header_rows) < 2 or header_rows[1][0] != header_rows[0][0] - 1:
        return None
    axes, groups = header_rows[0][1], header_rows[1][1]
    if all(g.strip() for g in groups):
        return None
    joined, group = [], ""
    for g, a in zip(groups, axes, strict=True):
        group = g.strip() or group
        joined.append(f"{group} {a.strip()}".strip() if a.strip() else g.strip())

    def known(names):
        return sum(canonical_name(n) is not None for n in names if n)

    return joined if known(joined) > max(known(axes), known(groups)) else None


def _header_cells(line: str, delim: str | None) -> list[str]:
    if delim is None:
        cells = line.split()
    else:
        try:
            cells = next(csv.reader([line], delimiter=delim))
        except (csv.Error, StopIteration):
            cells = line.split(delim)
    return [_strip_cell(c).lstrip("\ufeff") for c in cells]


COLUMNS_OPTION = "--columns (columns= of load_log in Python)"
"""How a loader message names the column mapping, for the command line and for Python (a
Python user read 'pass --columns' in every report)."""
_RATE_KEYS = (
    "fs", "sample rate", "sample_rate", "samplerate", "rate", "hz", "frequency",
    "sampling rate", "sampling frequency", "sample frequency", "data rate", "output rate",
    "outputrate", "update rate",  # Xsens: MT Manager '// Update Rate: 100.0Hz', DOT 'OutputRate'
)  # fmt: skip
# the names a comment line may give a rate among other settings, with the unit Hz after it
_RATE_KEYS_NAMED = ("sample rate", "sampling rate", "samplerate", "data rate", "odr", "fs")


def _is_mat(raw: bytes, path: Path) -> bool:
    return raw[:6] == b"MATLAB" and (
        path.suffix.lower() == ".mat" or raw[126:128] in (b"IM", b"MI")
    )


def _read_mat73(path: Path) -> dict[str, np.ndarray]:
    """The numeric variables of a MATLAB v7.3 file (HDF5 underneath; MATLAB writes each
    matrix transposed, so they are turned back), through h5py."""
    try:
        import h5py
    except ImportError:
        raise ValueError(
            f"{path} is a MATLAB v7.3 (HDF5) file: reading it needs h5py (pip install h5py, "
            "or pip install 'calib_jax[hdf5]'); or in MATLAB save it with save(..., '-v7'), or "
            "export a CSV"
        ) from None
    numeric = {b"double", b"single", b"int8", b"int16", b"int32", b"int64", b"uint8"}
    numeric |= {b"uint16", b"uint32", b"uint64", b"logical"}
    try:
        with h5py.File(path, "r") as f:
            return {
                k: np.asarray(v[()], float).T
                for k, v in f.items()
                if isinstance(v, h5py.Dataset) and v.attrs.get("MATLAB_class") in numeric
            }
    except OSError as exc:
        why = f"{path} looks like a MATLAB v7.3 file but h5py cannot read it: {exc}"
        raise ValueError(why) from None


def _read_mat(raw: bytes, path: Path, notes: list[str]) -> _Table:
    import scipy.io

    try:
        mat = scipy.io.loadmat(io.BytesIO(raw))
    except NotImplementedError:  # v7.3: HDF5 underneath
        mat = _read_mat73(path)
        notes.append("MATLAB v7.3 file, read with h5py")
    except Exception as e:  # scipy raises many kinds for a damaged file
        raise ValueError(
            f"{path} is not a readable MATLAB file ({type(e).__name__}: {e}); it may be "
            "truncated or corrupt: save or copy it again, or export a CSV"
        ) from None
    arrays = {
        k: np.asarray(v, float)
        for k, v in mat.items()
        if not k.startswith("__")
        and isinstance(v, np.ndarray)
        and v.dtype.kind in "fiub"
        and v.size
    }
    return _table_of_arrays(arrays, path, notes, "MATLAB variable")


def _json_arrays(obj, name: str = "") -> dict[str, np.ndarray]:
    """The numeric arrays of a parsed JSON document by dotted path: a list of numbers (null
    read as NaN), a list of equal-length lists of numbers (a matrix), and a list of records
    (objects), one array per key whose values are numbers; objects are walked into."""

    def number(v) -> bool:
        return v is None or (isinstance(v, int | float) and not isinstance(v, bool))

    def at(key: str) -> str:
        return f"{name}.{key}" if name else key

    out: dict[str, np.ndarray] = {}
    if isinstance(obj, dict):
        for k, v in obj.items():
            out.update(_json_arrays(v, at(str(k))))
    elif isinstance(obj, list) and obj:
        if all(number(v) for v in obj):
            out[name or "[]"] = np.array([np.nan if v is None else v for v in obj], float)
        elif all(isinstance(v, list) and v and all(number(x) for x in v) for v in obj):
            if len({len(v) for v in obj}) == 1:
                rows = [[np.nan if x is None else x for x in v] for v in obj]
                out[name or "[]"] = np.array(rows, float)
        elif all(isinstance(v, dict) for v in obj):
            keys = dict.fromkeys(k for v in obj for k in v)  # first-seen order
            for k in keys:
                vals = [v.get(k) for v in obj]
                if all(number(x) for x in vals) and any(x is not None for x in vals):
                    out[at(str(k))] = np.array([np.nan if x is None else x for x in vals], float)
    return out


def _looks_like_json(raw: bytes) -> bool:
    return raw.lstrip(b"\xef\xbb\xbf \t\r\n")[:1] in (b"{", b"[")


def _parse_json(raw: bytes):
    """The parsed document; JSON Lines of objects as their list; None where the text is no
    JSON (a text log whose first line is a bracketed section name, '[Data]', and one JSON list
    per line, micropython-fusion's, are read as text)."""
    import json

    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return None
    try:
        return json.loads(text)
    except ValueError:
        pass
    try:
        lines = [json.loads(line) for line in text.splitlines() if line.strip()]
    except ValueError:
        return None
    return lines if lines and all(isinstance(v, dict) for v in lines) else None


def _read_json(doc, path: Path, notes: list[str]) -> _Table:
    """A JSON export: its numeric arrays (:func:`_json_arrays`) read as a MATLAB file's
    variables are, by name (``ax``, ``acc_x``; an N x 3 ``acc``); a list of records by its keys.
    Before, a JSON file was read as one text row of hundreds of columns."""
    arrays = {k: v for k, v in _json_arrays(doc).items() if v.size}
    notes.append("JSON document, read by the names of its numeric arrays")
    return _table_of_arrays(arrays, path, notes, "JSON array")


def _table_of_arrays(
    arrays: dict[str, np.ndarray], path: Path, notes: list[str], what: str
) -> _Table:
    """Named numeric arrays (a MATLAB file's variables, a JSON document's arrays) as a table:
    arrays named like columns (``ax``, ``acc_x``) or an N x 3 matrix named for a sensor
    (``acc``), else the one N x k matrix. ``what`` names them in messages ("MATLAB variable")."""
    cols: dict[str, np.ndarray] = {}
    for k, v in arrays.items():
        leaf = k.rsplit(".", 1)[-1]  # a JSON path's last key
        canon = canonical_name(leaf)
        vector = v.ndim == 1 or (v.ndim == 2 and min(v.shape) == 1)
        if canon is not None and vector and canon not in cols:
            cols[canon] = v.ravel()
        sensor = _MATRIX_NAMES.get(_clean(leaf))
        if sensor is not None and v.ndim == 2 and 3 in v.shape:
            m = v if v.shape[1] == 3 else v.T
            for i, a in enumerate("xyz"):
                cols.setdefault(f"{sensor}{a}", m[:, i])
    if cols:
        lengths = Counter(len(v) for v in cols.values())
        n = max(lengths, key=lambda L: (lengths[L], L))
        left = sorted(k for k, v in cols.items() if len(v) != n)
        if left:
            notes.append(
                f"{what}s left out for a different length than the "
                f"{n} samples of the others: " + ", ".join(f"{k} ({len(cols[k])})" for k in left)
            )
        names = [k for k in cols if len(cols[k]) == n]
        return _Table(names, np.column_stack([cols[k] for k in names]))
    mats = [(k, v) for k, v in arrays.items() if v.ndim == 2 and min(v.shape) >= 3]
    if len(mats) != 1:
        found = [f"{k} {'x'.join(map(str, v.shape))}" for k, v in arrays.items()]
        if len(found) > 12:
            found = [*found[:12], f"and {len(found) - 12} more"]
        raise ValueError(
            f"{path}: cannot tell which {what} holds the data (found: "
            f"{', '.join(found) or f'no numeric {what}s'}); save one N x k matrix or "
            f"{what}s named ax, ay, az (or an N x 3 'acc')"
        )
    [(name, m)] = mats
    notes.append(
        f"{what} {name} ({'x'.join(map(str, m.shape))}) holds the data; its columns are read as "
        "a headerless file's"
    )
    if m.shape[0] < m.shape[1]:
        m = m.T
    return _Table(None, m)


def _time_last(cols: list[str], why: str, data: np.ndarray | None, path) -> tuple[list, str]:
    """A headerless layout with time first (``cols[0] == 't'``) checked against the data: time
    goes last when the last column rises and the first does not (micropython-fusion's
    ``ax..mz, ticks``); neither rising is an error, not a clock made from a sensor axis."""
    if data is None or cols[0] != "t" or len(data) < 2 or _rising(data[:, 0]):
        return cols, why
    if _rising(data[:, -1]):
        return [*cols[1:], "t"], why + "; time last: the last column rises, the first does not"
    width = len(cols)
    raise ValueError(
        f"{path} has no header and {width} columns, the layout of a time column and "
        f"{width - 1} sensor columns, but neither the first column nor the last rises like a "
        f"time ({_describe_columns(data)}); say what they are with --columns, e.g. --columns "
        f"{','.join(cols[1:])},_ ('_' skips a column), and give --sample-rate"
    )


def _clocks_at_an_end(
    width: int, data: np.ndarray | None, sensor: str | None
) -> tuple[list[str], str] | None:
    """Headerless columns that are a known layout (6 or 9 sensor columns) beside one or two
    columns that only rise, all at one end: logger clocks. Pololu's MinIMU-9 logs
    (scikit-kinematics) end with the acc/gyro and the magnetometer clocks in ms, and were
    refused for 11 columns, with a --columns example for mag that named the accelerometer's
    columns. The first clock is read as time, a second one is left out."""
    if data is None or len(data) < 2:
        return None
    rising = [j for j in range(width) if _rising(data[:, j])]
    k = len(rising)
    if k not in (1, 2) or rising not in (list(range(k)), list(range(width - k, width))):
        return None
    known = _guess(width - k, sensor)
    if known is None or "t" in known[0] or width - k < 6:
        return None
    clocks = ["t", *["_"] * (k - 1)]
    first = rising[0] == 0
    cols = [*clocks, *known[0]] if first else [*known[0], *clocks]
    where = ", ".join(str(j + 1) for j in rising)
    return cols, (
        f"{known[1]}; column{'s' if k > 1 else ''} {where} only rise: "
        + ("the first read as time, the other left out" if k > 1 else "read as time")
    )


HELD_CHANGES = 0.02
"""Columns that change on at most this fraction of rows are held values, an estimate updated
now and then, not readings."""


def _last_three_held(data: np.ndarray | None) -> bool:
    """The last three columns hold their values, changing on at most :data:`HELD_CHANGES` of
    the rows, while the three before them move on most rows: a sensor's readings followed by
    the operating system's estimate of their bias (Android's uncalibrated events). A phone's
    magnetometer whose estimate Android updated 15 times during a tumble was read as an
    accelerometer then a magnetometer, and its bias columns calibrated, exit 0."""
    if data is None or len(data) < 10:
        return False
    last, before = data[:, -3:], data[:, -6:-3]
    ok = np.all(np.isfinite(last), axis=1) & np.all(np.isfinite(before), axis=1)
    if ok.sum() < 10:
        return False
    changes = np.any(np.diff(last[ok], axis=0) != 0, axis=1).mean()
    moves = np.any(np.diff(before[ok], axis=0) != 0, axis=1).mean()
    return bool(changes <= HELD_CHANGES and moves > 0.5)


def _steady_magnitude(v: np.ndarray) -> float | None:
    """Median over 95th percentile of a triple's magnitude: near 1 for an accelerometer (about
    g whether still or turned), near 0 for a gyroscope (still most of the time, fast in the
    turns); None without 10 finite rows or with all of them zero. Read on at most about
    100,000 evenly spaced rows: a 3-hour 1 kHz log costs no more than a short one."""
    v = v[:: max(1, len(v) // 100_000)]
    with np.errstate(over="ignore"):  # a corrupt 1e308 cell: its norm is inf, as it should be
        n = np.linalg.norm(v[np.all(np.isfinite(v), axis=1)], axis=1)
    top = np.percentile(n, 95) if len(n) >= 10 else 0.0
    return float(np.median(n) / top) if top > 0 else None


def _gyro_before_accel(cols: list[str], why: str, data: np.ndarray | None) -> tuple[list, str]:
    """A headerless layout guessed as accelerometer then gyroscope, checked against the data:
    x-io's sensor_data.csv writes the gyroscope first. Its magnitude rests near
    zero and the next three columns hold a steady one, so read as ax.. it gave a gyro
    'accelerometer' that failed on 'only 6 distinct poses' (x-io's log without its header).
    The names are swapped only when both triples say so clearly."""
    if data is None or "ax" not in cols or "gx" not in cols:
        return cols, why
    a, g = cols.index("ax"), cols.index("gx")
    first, second = _steady_magnitude(data[:, a : a + 3]), _steady_magnitude(data[:, g : g + 3])
    if first is None or second is None or not (first < 0.3 and second > 0.7):
        return cols, why
    swapped = list(cols)
    swapped[a : a + 3], swapped[g : g + 3] = cols[g : g + 3], cols[a : a + 3]
    return swapped, (
        f"gyroscope first: columns {a + 1}-{a + 3} rest near zero and jump (median magnitude "
        f"{first:.2f} of its 95th percentile), columns {g + 1}-{g + 3} hold a steady one "
        f"({second:.2f})"
    )


def _headerless_guess(
    path: Path, width: int, data: np.ndarray, sensor: str | None
) -> tuple[list[str], str]:
    """The columns of a headerless file of ``width`` columns, by their count, their values and
    the file's name (``sensor``: the command's), and the reason the note gives."""
    by_name = ""
    if width in (3, 4):  # one sensor's x, y, z (and a time): which, the name may say
        which, by_name = _sensor_of_bare_columns(
            path, sensor, f"headerless {width} columns", timed=width == 4
        )
        sensor = which
    guess = _guess(width, sensor)
    if width in (6, 7) and _last_three_held(data):
        # Android's uncalibrated events: x, y, z and the OS's bias estimate, held for long
        # stretches (a phone's gyroscope.txt, t x y z bx by bz); read as a second sensor
        # they gave a gyro 'calibration' of constants and exit 0
        which, named = _sensor_of_bare_columns(
            path,
            sensor,
            f"headerless {width} columns (x, y, z and three held values)",
            timed=width == 7,
        )
        p = _SENSORS[which]
        held = "three held columns (an Android uncalibrated event's bias estimate)"
        guess = (
            [*(["t"] if width == 7 else []), p + "x", p + "y", p + "z", "_", "_", "_"],
            (named or f"sensor {_SENSOR_LABELS[p]}") + f", then {held}, left out",
        )
    if guess is None:
        guess = _clocks_at_an_end(width, data, sensor)
    if guess is None:
        if width < 3:
            raise ValueError(
                f"{path} has no header and only {width} column(s) per row; a sensor log "
                "needs x, y and z (at least 3)"
            )
        _refuse_transposed(path, len(data), width)
        # the example maps the sensor the file's name names (magnetometer-calibrated.txt's
        # five columns were offered as t,ax,ay,az,_); another command's sensor is refused
        timed = bool(len(data)) and _rising(data[:, 0])
        which, _ = _sensor_of_bare_columns(path, sensor, f"headerless {width} columns", timed=timed)
        raise ValueError(
            f"{path} has no header and {width} columns ({_describe_columns(data)}); say "
            f"what they are with --columns, e.g. --columns {_example(width, data, which)} "
            "('_' skips a column; t for a time column, else give --sample-rate)"
        )
    cols, why = _time_last(guess[0], by_name or guess[1], data, path)
    return _gyro_before_accel(cols, why, data)


TRANSPOSED_ROWS = 12
"""A table of at most this many rows, each wider than it is long (and at least 20 numbers),
holds one row per axis: a log saved transposed (MATLAB's 3 x N habit)."""


def _refuse_transposed(path, rows: int, width: int) -> None:
    """A ValueError for a table of a few rows of many numbers: a log saved one row per axis
    (a trial's np.savetxt(G.T) was 'no data rows', a 3 x 200 table 'no header and 200
    columns' with a 200-name --columns example)."""
    if 1 <= rows <= TRANSPOSED_ROWS and width >= max(20, 2 * rows):
        raise ValueError(
            f"{path} holds {rows} row(s) of {width} numbers: one row per axis, the table "
            "transposed; a log needs one row per sample. Save it the other way round (numpy: "
            "np.savetxt(path, x.T, delimiter=',')), or read it with numpy.loadtxt(path, "
            "delimiter=',').T and pass the (N, 3) array"
        )


def _label_columns(data: np.ndarray) -> list[int]:
    """Columns that hold no number in any row: a label an Arduino sketch prints before its
    values on every line (i2cdevlib's MPU6050_raw: 'a/g:' then six numbers)."""
    if not len(data):
        return []
    return [j for j in range(data.shape[1]) if np.isnan(data[:, j]).all()]


def _guess(width: int, sensor: str | None) -> tuple[list[str], str] | None:
    """Headerless columns by width: the names and the reason given in the note."""
    p = _SENSORS[sensor]
    xyz = [p + a for a in "xyz"]
    if p == "m":
        six, why6 = ["ax", "ay", "az", "mx", "my", "mz"], "accelerometer then magnetometer"
    else:
        six, why6 = ["ax", "ay", "az", "gx", "gy", "gz"], "the usual IMU order"
    nine = ["ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz"]
    table = {
        3: (
            xyz,
            f"sensor {sensor}"
            if sensor
            else "an accelerometer, unless the command or sensor= names another",
        ),
        4: (["t", *xyz], "the imu_tk layout" if p == "a" else f"sensor {sensor}"),
        6: (six, why6),
        7: (["t", *six], why6),
        9: (nine, "the usual IMU order"),
        10: (["t", *nine], "the usual IMU order"),
    }
    return table.get(width)


_HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
_BROAD_DATASETS = {"acc": "imu_acc", "gyro": "imu_gyr", "mag": "imu_mag"}


def _read_hdf5(path: Path, sample_rate: float | None, max_rows: int | None) -> SensorLog:
    """An HDF5 file in BROAD's layout (``imu_acc``, ``imu_gyr``, ``imu_mag``, (N, 3) each, the
    rate in the ``sampling_rate`` attribute); any other layout: a ValueError listing the
    (N, 3) datasets found and what to do."""
    try:
        import h5py
    except ImportError:
        raise ValueError(
            f"{path} is an HDF5 file: reading it needs h5py (pip install h5py, or "
            "pip install 'calib_jax[hdf5]'), or export the sensor columns to CSV"
        ) from None
    try:
        with h5py.File(path, "r") as f:
            shapes = {k: f[k].shape for k in f if isinstance(f[k], h5py.Dataset)}
            if _BROAD_DATASETS["acc"] not in shapes:
                triples = [f"{k} {v}" for k, v in shapes.items() if len(v) == 2 and v[1] == 3]
                raise ValueError(
                    f"{path} is an HDF5 file without BROAD's datasets (imu_acc, imu_gyr, imu_mag)"
                    f"; its (N, 3) datasets: {', '.join(triples) or 'none'}. Export the "
                    "sensor columns to CSV (ax, ay, az, gx, ... as the header)"
                )
            rows = slice(None, max_rows)
            vec = {
                k: np.asarray(f[name][rows], float) if name in shapes else None
                for k, name in _BROAD_DATASETS.items()
            }
            rate = sample_rate or float(f.attrs.get("sampling_rate", 0.0)) or None
    except OSError as exc:
        raise ValueError(f"{path} looks like HDF5 but h5py cannot read it: {exc}") from None
    found = [name for k, name in _BROAD_DATASETS.items() if vec[k] is not None]
    notes = [
        f"HDF5 in BROAD's layout: {', '.join(found)}"
        + (f" at {rate:g} Hz" if rate else ", no sampling_rate attribute (give --sample-rate)")
        + "; the optical truth, if any, is read by calib_jax.io.broad.load_broad"
    ]
    columns = {k: name for k, name in _BROAD_DATASETS.items() if vec[k] is not None}
    return SensorLog(
        acc=vec["acc"],
        gyro=vec["gyro"],
        mag=vec["mag"],
        sample_rate=rate,
        path=str(path),
        columns=columns,
        notes=notes,
    )


def load_log(
    path: str | Path,
    columns: str | dict[str, str] | None = None,
    sample_rate: float | None = None,
    sensor: str | None = None,
    max_rows: int | None = None,
    instance: int | None = None,
) -> SensorLog:
    """Load a sensor log (see the module docstring for the formats).

    Parameters
    ----------
    path : path
        The file.
    columns : str or dict, optional
        Column mapping, see :func:`parse_columns`; it overrides the header and any guess.
    sample_rate : float, optional
        Hz, when the file has no time column (or to override it).
    sensor : {"accel", "mag", "gyro"}, optional
        Which sensor the caller wants: decides how a headerless 3- or 4-column file (and a
        6- or 7-column one for "mag") is read. A note names every guess.
    max_rows : int, optional
        Read only the first ``max_rows`` data rows of a text file (MAT files are read whole);
        :func:`iter_rows` streams the rest of a plain text file in bounded memory.
    instance : int, optional
        For a file whose rows interleave several sensors, told apart by an instance column
        (ArduPilot's ``I``; :data:`INSTANCE_NAMES`): the instance to read. Default: the one
        in the first row, with a note naming the others.

    Raises
    ------
    ValueError
        For anything that cannot be read, saying what was found and what to change.
    """
    if not isinstance(path, str | os.PathLike):  # pathlib's TypeError named no way out
        raise ValueError(
            f"load_log reads a file; it was given a {type(path).__name__}. Pass an array or "
            "DataFrame of readings to calibrate_accel, calibrate_mag or calibrate_gyro "
            "directly, or build a SensorLog(acc=..., gyro=..., mag=..., t=...)"
        )
    if sensor not in _SENSORS:
        raise ValueError(f"sensor={sensor!r}: use 'accel', 'mag', 'gyro' or None")
    try:
        rate_ok = sample_rate is None or (np.isfinite(sample_rate) and sample_rate > 0)
    except TypeError:
        rate_ok = False
    if not rate_ok:
        raise ValueError(f"sample rate {sample_rate!r} Hz: give a positive number")
    path = Path(path)
    if not path.exists():
        raise ValueError(f"{path} does not exist")
    mapping = parse_columns(columns)
    notes: list[str] = []
    raw = _read_bytes(path, ends=_HEAD_CHARS)
    if raw[0].startswith(_HDF5_MAGIC):
        return _read_hdf5(path, sample_rate, max_rows)
    if looks_like_dataflash(raw[0][:_HEAD_CHARS].decode("latin-1")):
        text = _decode(_read_bytes(path), path, notes)[0]
        tab = read_dataflash(text, path, sensor, notes)
        return _assemble(path, tab, mapping, sensor, sample_rate, notes, instance)
    big = len(raw[1]) == _HEAD_CHARS // 2 and len(raw[0]) == _HEAD_CHARS
    lazy = (
        big
        and path.suffix.lower() != ".mat"
        and not any(raw[0].startswith(m) for m, *_ in _COMPRESSED)
        and not _is_mat(raw[0], path)
        and not _looks_like_json(raw[0])
    )
    if lazy:
        # a big file that is not compressed and not a MAT file: read its ends only, numpy's
        # parser reads the rest from disk
        tab = _read_text(path, raw[0], True, notes, tail_raw=raw[1], max_rows=max_rows)
        return _assemble(path, tab, mapping, sensor, sample_rate, notes, instance)
    raw = raw[0] if not big else _read_bytes(path)
    if not raw:
        raise ValueError(f"{path} is empty (0 bytes): nothing to calibrate")
    raw, compressed = _decompress(raw, path, notes)
    if _is_mat(raw, path):
        tab = _read_mat(raw, path, notes)
    elif path.suffix.lower() == ".mat" and b"\0" in raw[:4096]:
        # a binary .mat without the version-5 text header: MATLAB v4
        tab = _read_mat(raw, path, notes)
    elif _looks_like_json(raw) and (doc := _parse_json(raw)) is not None:
        tab = _read_json(doc, path, notes)
    else:
        tab = _read_text(path, raw, not compressed, notes, max_rows=max_rows)
    return _assemble(path, tab, mapping, sensor, sample_rate, notes, instance)


def as_log(data, sensor: str | None = None):
    """A file path (str or path-like) loaded with :func:`load_log`; anything else (a
    :class:`SensorLog`, an array) returned as it is. Every fit's way in, so
    ``calibrate_accel("log.csv")`` reads the file as ``calib-jax accel log.csv`` does."""
    if isinstance(data, str | bytes) or hasattr(data, "__fspath__"):
        return load_log(os.fsdecode(data), sensor=sensor)
    if type(data).__name__.endswith("Tracer"):  # jax.jit(calibrate_accel): jax's error named
        raise ValueError(  # no way out (TracerArrayConversionError)
            "the calibrate_* functions run on the host (pose detection, checks, reports) and "
            "cannot be traced by jit, vmap or grad: inside JAX use calib_jax.pipeline "
            "(fit_accel, fit_mag, fit_gyro, fit_batch), which are pure and differentiable"
        )
    return data


def join_logs(log: SensorLog, other: SensorLog, sensor: str = "gyro") -> SensorLog:
    """The accelerometer's log with the ``sensor`` ("gyro" or "mag") readings of another file
    of the same recording (imu_tk's two-file layout, a phone's Accelerometer.csv beside its
    Gyroscope.csv or Magnetometer.csv). Files that share one clock row by row (the same number
    of rows and, where both have one, the same time column) are joined as they are. Files with
    time columns of their own (a phone writes each sensor when it has a sample) get the other
    sensor interpolated linearly onto the accelerometer's times, and the accelerometer's rows
    outside the other file's time span are left out, with a note. A ValueError names both
    files when neither works. The logs given are left as they are (a new SensorLog is
    returned)."""
    a, o = log.path or "the accelerometer's log", other.path or f"the {sensor}'s log"
    why = f"the fit needs the accelerometer and the {sensor} sample by sample on one clock"
    field_name = {"gyro": "gyro", "mag": "mag"}[sensor]
    # how the other file was read, and the unit it states, go with its readings (the joined
    # log said only how the accelerometer's file was read: FreeIMU's acc.txt + magn.txt)
    name = Path(os.fsdecode(other.path)).name if other.path else o
    carried = {
        "notes": [*log.notes, *(f"{name}: {n}" for n in other.notes)],
        "units": {**log.units, **{k: u for k, u in other.units.items() if k == sensor}},
    }
    same_rows = len(log) == len(other)
    if same_rows and (log.t is None or other.t is None or np.allclose(log.t, other.t)):
        return dataclasses.replace(log, **{field_name: other.vectors(sensor)}, **carried)
    if log.t is None or other.t is None:
        raise ValueError(f"{a} has {len(log)} rows and {o} {len(other)}: {why}")
    log = _without_repeated_rows(log, a, carried["notes"])
    other = _without_repeated_rows(other, o, carried["notes"])
    ta, to = np.asarray(log.t, float), np.asarray(other.t, float)
    for path, t in ((a, ta), (o, to)):
        rows = np.flatnonzero(np.isfinite(t))
        back = rows[np.flatnonzero(~(np.diff(t[rows]) > 0))]
        if back.size:
            raise ValueError(
                f"{path}: {back.size} of its time steps do not increase (the first after data "
                f"row {back[0] + 1}, t {t[back[0]]:.6g} s), so its readings cannot be put on the "
                f"other file's times: {why}"
            )
    inside = (ta >= np.nanmin(to)) & (ta <= np.nanmax(to))
    if inside.sum() < 0.5 * len(ta):
        raise ValueError(
            f"{a} ({len(log)} rows, t {np.nanmin(ta):.6g}-{np.nanmax(ta):.6g} s) and {o} "
            f"({len(other)} rows, t {np.nanmin(to):.6g}-{np.nanmax(to):.6g} s) overlap in less "
            f"than half of the accelerometer's time: {why}"
        )
    v, ok = other.vectors(sensor), np.isfinite(to)
    joined = np.column_stack([np.interp(ta[inside], to[ok], v[ok, k]) for k in range(3)])
    keep = {
        name: None if (x := getattr(log, name)) is None else np.asarray(x)[inside]
        for name in ("acc", "gyro", "mag", "temp", "t")
        if name != field_name
    }
    note = (
        f"the {sensor} of {o} ({len(other)} rows) interpolated linearly onto the "
        f"accelerometer's {int(inside.sum())} times"
        + (f"; {int((~inside).sum())} accelerometer rows outside the {sensor}'s time span left "
           "out" if not inside.all() else "")
    )  # fmt: skip
    carried["notes"].append(note)
    return dataclasses.replace(log, **keep, **{field_name: joined}, **carried, layout=None)


def _without_repeated_rows(log: SensorLog, name: str, notes: list[str]) -> SensorLog:
    """``log`` without the rows that repeat the row before exactly, time and readings (a
    logger that wrote a row twice: a phone's 100 Hz export repeats 7 % of its rows after
    30 s), with a note in ``notes``; the log itself where there are none or no time column."""
    if log.t is None:
        return log
    fields = [f for f in ("t", "acc", "gyro", "mag", "temp") if getattr(log, f) is not None]
    table = np.column_stack([np.asarray(getattr(log, f), float) for f in fields])
    repeat = np.r_[False, np.all(table[1:] == table[:-1], axis=1)]
    if not repeat.any():
        return log
    notes.append(
        f"{name}: {int(repeat.sum())} rows repeat the row before exactly (time and readings) "
        "and were read once"
    )
    keep = {f: np.asarray(getattr(log, f))[~repeat] for f in fields}
    return dataclasses.replace(log, **keep, layout=None)


def _assemble(
    path: Path,
    tab: _Table,
    mapping: dict[str, str] | None,
    sensor: str | None,
    sample_rate: float | None,
    notes: list[str],
    instance: int | None = None,
) -> SensorLog:
    """Columns to sensors: the header, --columns or the headerless guess; notes on the cells."""
    header, data, preamble = tab.header, tab.data, tab.preamble
    width = data.shape[1]
    if preamble:
        notes.append("preamble: " + ", ".join(f"{k}={v:g}" for k, v in preamble.items()))
    if tab.bad:
        notes.append(
            f"{tab.bad} rows had the wrong number of fields (not {width}) and were skipped"
        )
    if len(data) == 0:
        raise ValueError(f"{path} has a header but no data rows: {header}")
    if tab.odd_header is not None:
        if mapping is None or any(not s.isdigit() for s in mapping.values()):
            raise ValueError(
                f"{path}: the line {','.join(tab.odd_header)!r} looks like a header with "
                f"{len(tab.odd_header)} names, but the data rows have {width} fields; fix the "
                "header or say what the columns are, by position, with --columns (e.g. "
                f"--columns {_example(width)})"
            )
        notes.append(
            f"header {','.join(tab.odd_header)!r} ignored ({len(tab.odd_header)} names for "
            f"{width} fields); columns taken by position from --columns"
        )
    names = header if header is not None else [str(i) for i in range(width)]
    source: dict[str, int] = {}
    if mapping is not None:
        for canon, src in mapping.items():
            if src.isdigit() and (header is None or src not in header):
                j = int(src)
                if j >= width:
                    raise ValueError(
                        f"--columns puts {canon} in column {j + 1}, but {path} has only {width} "
                        f"columns ({', '.join(names)}); name {width} or fewer, e.g. "
                        f"--columns {_example(width)}"
                    )
                source[canon] = j
            elif header is not None:
                lowered = [h.lower() for h in header]
                cleaned = [_clean(h) for h in header]
                if src.lower() in lowered:
                    source[canon] = lowered.index(src.lower())
                elif _clean(src) and _clean(src) in cleaned:
                    source[canon] = cleaned.index(_clean(src))
                else:
                    raise ValueError(
                        f"--columns names {src!r} for {canon}, which is not in the header "
                        f"{header}; use one of those names"
                    )
            else:
                raise ValueError(
                    f"{path} has no header, so --columns cannot name columns ({src!r}); give "
                    f"them by position, e.g. --columns {_example(width)}"
                )

    def _numeric(j: int) -> bool:
        return bool(np.isfinite(data[: min(len(data), 1000), j]).any())

    def _ticks(j: int) -> bool:
        """The column holds numbers that change on most rows: a clock of whole seconds
        ('05:34:44', now read as seconds) beside a millisecond counter does not."""
        col = data[: min(len(data), 1000), j]
        col = col[np.isfinite(col)]
        return bool(col.size > 1 and np.mean(np.diff(col) != 0) > 0.5) and _rising(col)

    if header is not None:
        again: dict[str, int] = {}  # a name read a second time: its first such column
        for j, h in enumerate(header):
            canon = canonical_name(h)
            if canon is not None and canon not in source:
                source[canon] = j
            elif (
                canon == "t"
                and mapping is None
                and (_numeric(j) > _numeric(source["t"]) or _ticks(j) > _ticks(source["t"]))
            ):
                # a clock of whole seconds or of text ('Time(hh:mm:ss)') before a counter
                # ('Timestamp(Ms)'): TWLogger's order
                notes.append(
                    f"column {header[source['t']]!r} reads as t but does not tick with the rows: "
                    f"{h!r} is used"
                )
                source["t"] = j
            elif canon is not None and mapping is None and source[canon] != j:
                again.setdefault(canon, j)
        if again:
            notes.append(_named_twice(header, source, again))
        bare = {a: j for j, h in enumerate(header) if (a := bare_axis(h)) is not None}
        if len(bare) == 3 and not any(k[0] in "agm" for k in source):
            # 'X,Y,Z' alone (Faros's ACC.csv): one sensor, read as a headerless file's would be
            xyz = tuple(header[bare[a]] for a in "xyz")
            names_xyz = ", ".join(xyz)
            which, by_name = _sensor_of_bare_columns(path, sensor, f"columns {names_xyz}", xyz)
            cols, why = _guess(3, which)
            why = by_name or why
            source.update({c: bare[a] for c, a in zip(cols, "xyz", strict=True)})
            notes.append(
                f"columns {names_xyz} name no sensor: read as {' '.join(cols)} ({why}); pass "
                f"{COLUMNS_OPTION} to override"
            )
    elif mapping is None:
        labels = _label_columns(data)
        keep = [j for j in range(width) if j not in labels]
        if labels and len(keep) >= 3:
            sub, why_sub = _headerless_guess(path, len(keep), data[:, keep], sensor)
            cols = ["_"] * width
            for j, c in zip(keep, sub, strict=True):
                cols[j] = c
            where = ", ".join(str(j + 1) for j in labels)
            why = f"{why_sub}; column {where} holds text in every row (a label), left out"
        else:
            cols, why = _headerless_guess(path, width, data, sensor)
        source = {c: i for i, c in enumerate(cols) if c != "_"}
        notes.append(
            f"headerless {width}-column file read as {' '.join(cols)} ({why}); pass "
            f"{COLUMNS_OPTION} to override"
        )

    data, layout = _one_instance(path, header, data, instance, notes), tab.layout
    if len(data) < len(tab.data):
        layout = None  # a streamed reader would read every instance's rows
    # cells the caller will have to drop, counted per column it uses. A finite value beyond
    # 1e150 is no reading (a corrupt cell: its square overflows any sum); it is read as +-inf
    # so that it is dropped with the other non-finite cells instead of wrecking a fit.
    used = [c for c in _CANON if c in source]
    idx = [source[c] for c in used]
    if data.size and np.isfinite(data).all() and max(-data.min(), data.max()) <= _HUGE:
        n_bad = n_huge = [0] * len(idx)  # the usual case, in two quick passes
    else:
        with np.errstate(invalid="ignore"):  # boolean passes only: no float temporaries
            n_bad = (~np.isfinite(data)).sum(axis=0)[idx]
            huge = (data > _HUGE) | (data < -_HUGE)
            huge &= np.isfinite(data)
        n_huge = huge.sum(axis=0)[idx]
        if huge.any():
            data = data.copy() if not data.flags.writeable else data
            data[huge] = np.copysign(np.inf, data[huge])
    bad_cells = [f"{c} {n}" for c, n in zip(used, n_bad, strict=True) if n]
    huge_cells = [f"{c} {n}" for c, n in zip(used, n_huge, strict=True) if n]
    if bad_cells:
        notes.append(
            "cells that are not finite numbers (NaN, inf, empty or text), kept for the "
            "calibration to drop: " + ", ".join(bad_cells)
        )
    if huge_cells:
        notes.append(
            f"cells beyond +-{_HUGE:g}, which no sensor reads (a corrupt cell?), read as +-inf "
            "for the calibration to drop: " + ", ".join(huge_cells)
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
        cols = [source[k] for k in keys]
        if cols[1] == cols[0] + 1 and cols[2] == cols[0] + 2:
            return data[:, cols[0] : cols[0] + 3]  # a view: no copy of a big log
        return data[:, cols]

    acc, gyro, mag = triple("a"), triple("g"), triple("m")
    if acc is None and mag is None and gyro is None:
        derived = [h for h in header or [] if _DERIVED.search(str(h))]
        if len(derived) >= 3:
            raise ValueError(
                f"{path}: the columns hold a sensor-fusion output ({', '.join(derived[:7])}"
                f"{', ...' if len(derived) > 7 else ''}): an orientation, or acceleration with "
                "gravity removed, not raw sensor readings, so there is nothing here to "
                "calibrate; export the raw accelerometer, gyroscope or magnetometer (Xsens: "
                "Acc, Gyr, Mag; a phone: the uncalibrated sensors), or map raw columns this "
                "file holds with --columns"
            )
        if header is not None:
            eg = _named_example(header, data, sensor)
        else:
            eg = _example(width, data, sensor)
        raise ValueError(
            f"{path}: no sensor columns recognised in {header if header is not None else names}; "
            f"map them with --columns, e.g. --columns {eg}"
        )
    t = data[:, source["t"]].copy() if "t" in source else None
    temp = data[:, source["temp"]].copy() if "temp" in source else None
    rate = sample_rate
    if rate is None:
        rate = next((preamble[k] for k in _RATE_KEYS if k in preamble), None)
        if rate is not None and not (np.isfinite(rate) and rate > 0):
            notes.append(f"preamble sample rate {rate:g} ignored (not a positive number)")
            rate = None
    time_scale = 1.0
    if t is not None:
        t, unit_note, time_scale = _time_in_seconds(t)
        if unit_note and header is not None:  # which column, where several look like one
            unit_note = unit_note.replace("time column", f"time column {header[source['t']]!r}", 1)
        if unit_note:
            notes.append(unit_note)
    if sample_rate is not None and t is not None and (mapping is None or "t" not in mapping):
        with np.errstate(invalid="ignore"):
            steps = np.diff(t[np.isfinite(t)])
        if np.any(steps <= 0):  # --sample-rate given for a clock that does not tick forward
            bad = int(np.sum(steps <= 0))
            notes.append(
                f"the time column {names[source['t']]!r} does not increase ({bad} steps); the "
                f"given sample rate ({sample_rate:g} Hz) is used instead"
            )
            t, layout = None, None
            source = {k: v for k, v in source.items() if k != "t"}
    if rate is None and t is not None:
        with np.errstate(over="ignore", invalid="ignore"):
            dt = np.diff(t[np.isfinite(t)])
            dt = dt[np.isfinite(dt) & (dt > 0)]
            if dt.size:
                rate = rate_from_steps(dt, notes)
    units = {}
    for sensor_name, p in (("accel", "a"), ("gyro", "g"), ("mag", "m")):
        stated = {unit_in_name(names[source[p + a]]) for a in "xyz" if p + a in source}
        if len(stated) == 1 and None not in stated:
            units[sensor_name] = stated.pop()
        elif stated == {None} and p in tab.units:  # names silent, a comment line states it
            units[sensor_name] = tab.units[p]
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
        units=units,
        layout=None if layout is None else {**layout, "source": source, "time_scale": time_scale},
    )


INSTANCE_NAMES = ("i", "instance", "inst", "sensorinstance", "imuinstance", "sensorid", "imuid")
"""Header names (cleaned) of a column that tells interleaved sensors apart (ArduPilot's IMU and
MAG messages carry ``I``: 0, 1, 2 for the first, second, third IMU)."""


def _one_instance(
    path: Path, header: list[str] | None, data: np.ndarray, instance: int | None, notes: list
) -> np.ndarray:
    """The rows of one sensor instance, when an instance column (:data:`INSTANCE_NAMES`) holds
    2-8 small whole numbers that take turns row by row; else ``data`` as it is. Two IMUs read
    as one gave 'the time column must increase' and, for the accelerometer, one pose of their
    average."""
    j = next((j for j, h in enumerate(header or []) if _clean(h) in INSTANCE_NAMES), None)
    if j is None:
        return data
    col = data[:, j]
    values = np.unique(col[np.isfinite(col)])
    whole = values.size and np.all(values == np.round(values)) and values.min() >= 0
    if not (whole and 2 <= values.size <= 8) or np.mean(np.diff(col) != 0) < 0.25:
        if instance is not None:
            raise ValueError(
                f"{path}: instance {instance} asked for, but its column {header[j]!r} does not "
                "tell interleaved sensors apart (it needs 2-8 whole numbers taking turns)"
            )
        return data
    chosen = int(col[0]) if instance is None else int(instance)
    if chosen not in values:
        raise ValueError(
            f"{path}: no rows of instance {chosen}: column {header[j]!r} holds "
            + ", ".join(f"{v:g}" for v in values)
        )
    keep = col == chosen
    others = ", ".join(f"{v:g}" for v in values if v != chosen)
    notes.append(
        f"column {header[j]!r} interleaves {values.size} sensors' rows: read those of "
        f"{header[j]} = {chosen} ({int(keep.sum())} of {len(col)} rows); the others ({others}) "
        "with --instance (instance= in Python)"
    )
    return data[keep]


UNEVEN_STEPS = 0.25
"""The mean time step (pauses left out) and the median differ by more than this fraction: the
stamps are when a logger delivered the samples, in bursts, not when they were taken; the rate
is the stamps' slope against the sample number (:func:`rate_from_steps`), and the gyro
integrates at that rate."""
PAUSE_STEPS = 10.0
"""A time step longer than this many times the 99th percentile of the steps is a pause (the
logger stopped), not part of the sampling: :func:`rate_from_steps` leaves it out."""


def rate_from_steps(dt: np.ndarray, notes: list[str]) -> float | None:
    """Samples per second from the time steps: the median step's rate, unless the steps are
    so uneven that it misleads (a logger writing in bursts: sunsided's MPU6050 log has a
    median step of 2.2 ms and a mean of 10.1 ms, 99.3 Hz). Then, with a note, the slope of
    the stamps against the sample number, by least squares: a burst's stamps lie on both sides
    of the sampling times, which the slope averages out, where the mean step (the end stamps
    over the count) carries the end bursts' offsets (0.2 % on a 45 s simulated log). Pauses
    are closed up first: steps over :data:`PAUSE_STEPS` times the 99th percentile (the 1 %
    longest, left out before, were that log's longest burst gaps, not pauses: 107 Hz)."""
    r = float(1.0 / np.median(dt))
    pause = dt > PAUSE_STEPS * np.percentile(dt, 99)
    if np.all(pause) or abs(float(np.median(dt) / np.mean(dt[~pause])) - 1.0) <= UNEVEN_STEPS:
        return r if np.isfinite(r) and r > 0 else None
    t = np.cumsum(np.where(pause, np.mean(dt[~pause]), dt))
    i = np.arange(len(t)) - (len(t) - 1) / 2.0
    r_fit = float(i @ i / (i @ (t - t.mean())))
    if not (np.isfinite(r_fit) and r_fit > 0):
        return r if np.isfinite(r) and r > 0 else None
    notes.append(
        f"timestamps uneven (median step {1e3 / r:.3g} ms, mean {1e3 / r_fit:.3g} ms): sample "
        f"rate taken as {r_fit:.4g} Hz from the stamps' slope; give --sample-rate if that is "
        "wrong"
    )
    return r_fit


_TIME_UNITS = ((1.0, "s"), (1e-3, "ms"), (1e-6, "us"), (1e-9, "ns"))
_PLAUSIBLE_RATE = (2.0, 20_000.0)  # Hz: what an IMU log is recorded at


def _time_in_seconds(t: np.ndarray) -> tuple[np.ndarray, str | None, float]:
    """The time column in seconds, a note when it was in ms, us or ns, and the factor.

    Loggers write milliseconds (Arduino ``millis()``), microseconds or nanoseconds since boot
    or the epoch as often as seconds. Read as seconds, a 1 kHz log in nanoseconds has a rate of
    1e-6 Hz and every duration-based setting (the static detector's window, the shortest pose)
    is wrong by 1e9. The unit is the first of s, ms, us, ns that puts the median sample
    interval at a plausible IMU rate (2 Hz to 20 kHz); a column no unit makes plausible is
    left as it is.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        dt = np.diff(t[np.isfinite(t)])
        dt = dt[np.isfinite(dt) & (dt > 0)]
    if dt.size == 0:
        return t, None, 1.0
    step = float(np.median(dt))
    lo, hi = _PLAUSIBLE_RATE
    for scale, unit in _TIME_UNITS:
        if lo <= 1.0 / (step * scale) <= hi:
            if scale == 1.0:
                return t, None, 1.0
            return (
                t * scale,
                f"time column read as {unit} (median step {step:g}: {1.0 / (step * scale):.4g} "
                f"Hz); converted to seconds",
                scale,
            )
    return t, None, 1.0


def _rising(col: np.ndarray) -> bool:
    """A column that goes up (a time or sample counter): its finite values rise somewhere and
    fall at 1 % of the steps at most (a clock that wraps, as MicroPython's ticks_us does every
    18 min, or a glitch; ties allowed, as a clock of whole seconds at 50 Hz has 98 %)."""
    d = np.diff(col[np.isfinite(col)])
    return bool(d.size > 1 and np.any(d > 0) and np.mean(d >= 0) >= 0.99)


def _describe_columns(data: np.ndarray) -> str:
    """Each column's range, and which only rise (time?): what a user needs to map them; the
    first 16 of a wider file (a JSON document read as one row of 583 was 9,992 characters)."""
    parts = []
    shown = 16 if data.shape[1] > 20 else data.shape[1]
    for j in range(shown):
        c = data[:, j][np.isfinite(data[:, j])]
        if c.size == 0:
            parts.append(f"{j + 1}: empty")
            continue
        rng = f"{c.min():.4g}..{c.max():.4g}"
        parts.append(f"{j + 1}: {rng}" + (" rising (time?)" if _rising(data[:, j]) else ""))
    if shown < data.shape[1]:
        parts.append(f"... and {data.shape[1] - shown} more")
    return "columns " + ", ".join(parts)


def _named_twice(header: list[str], source: dict[str, int], again: dict[str, int]) -> str:
    """The note for sensor columns a header names twice (gaitmap's two foot IMUs, left_sensor
    and right_sensor, both acc_x ... gyr_z): the first of each is read, and a positional
    --columns reads the others."""
    which = ", ".join(  # gaitmap's names are the same twice, OpenAXES's differ by chip
        f"{header[j]} (columns {source[c] + 1} and {j + 1})"
        if header[j] == header[source[c]]
        else f"{c} ({header[source[c]]}, column {source[c] + 1}, and {header[j]}, {j + 1})"
        for c, j in again.items()
    )
    pick = ["_"] * len(header)
    if "t" in source and "t" not in again:
        pick[source["t"]] = "t"
    for canon, j in again.items():
        pick[j] = canon
    return (
        f"the header names {which} twice: two sensors in one file? The first of each is read; "
        f"--columns {','.join(pick)} reads the others"
    )


def _example(width: int, data: np.ndarray | None = None, sensor: str | None = None) -> str:
    """A positional --columns example with `width` entries: t at the first column that only
    rises (none: no t), then the sensor's x, y, z (ax, ay, az unless ``sensor`` says) at the
    first three others."""
    names = ["_"] * max(width, 3)
    rising = [] if data is None else [j for j in range(width) if _rising(data[:, j])]
    if data is None and width >= 4:
        rising = [0]
    if rising:
        names[rising[0]] = "t"
    free = [j for j in range(len(names)) if names[j] == "_"]
    for axis, j in zip("xyz", free, strict=False):
        names[j] = _SENSORS.get(sensor, "a") + axis
    return ",".join(names)


# names of sensor-fusion outputs, never raw readings: quaternions, Euler angles, rotation
# matrices, acceleration with gravity removed, gravity itself (Xsens DOT's Quat_W and FreeAcc_X
# were offered as the accelerometer in the --columns example)
_DERIVED = re.compile(
    r"quat|euler|roll|pitch|yaw|heading|free_?acc|lin(ear)?[_ ]?acc|gravity|^q[0-3wxyz]$"
    r"|^mat\[",
    re.I,
)


_SENSOR_HINTS = {
    "accel": ("acc", "vel", "lin"),
    "gyro": ("gyr", "ang", "rot", "rate"),
    "mag": ("mag", "comp", "field"),
}


def _named_example(header: list[str], data: np.ndarray, sensor: str | None) -> str:
    """A --columns example for a header whose names were not recognised: t for a time-like
    name (else the first column that only rises), the sensor's x, y, z for the first three
    other columns that do not only rise, quoted for the shell when a name needs it."""
    t = next((j for j, h in enumerate(header) if canonical_name(h) == "t"), None)
    rising = [j for j in range(len(header)) if _rising(data[:, j])]
    if len(rising) == len(header):  # every column rises: that says nothing of time
        rising = []
    if t is None and rising:
        t = rising[0]
    free = [j for j in range(len(header)) if j != t and j not in rising]

    # constant columns (device ids, flags) are no sensor axis; names that hint at the sensor
    # come first (PX4's vehicle_imu: accel_device_id and gyro_device_id were offered as ax, ay)
    def varies(j: int) -> bool:  # an all-NaN (text) column neither varies nor warns
        col = data[:, j][np.isfinite(data[:, j])]
        return bool(col.size and col.max() > col.min())

    free = [j for j in free if varies(j)] or free
    hint = _SENSOR_HINTS.get(sensor or "accel", ())
    free.sort(key=lambda j: not any(h in str(header[j]).lower() for h in hint))
    pairs = [("t", t)] if t is not None else []
    pairs += [(_SENSORS.get(sensor, "a") + a, j) for a, j in zip("xyz", free, strict=False)]
    text = ",".join(f"{c}={header[j]}" for c, j in pairs)
    return f"'{text}'" if re.search(r"[^\w,=.\-\[\]]", text) else text
