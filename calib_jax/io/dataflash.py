"""ArduPilot dataflash logs in their text form (Mission Planner's and mavlogdump's ``.log``).

Every line is one message: its name, then its values (``IMU, 95892, 0.01, ..., -9.79``).
``FMT`` lines name each message's columns (``FMT, 131, 31, IMU, Iffffff, TimeMS, GyrX, GyrY,
GyrZ, AccX, AccY, AccZ``); dozens of message types take turns (GPS, ATT, RCIN, PARM, ...).
Read as one table, rows of equal width from unrelated messages ran together and the file was
"no header and 8 columns". Here one sensor's messages are taken by their columns' names:

* the accelerometer and gyroscope from the message with the most of ``AccX..Z`` and
  ``GyrX..Z`` (``IMU``), the magnetometer from the one with ``MagX..Z`` (``MAG``);
* a second or third sensor is the same message with a digit (``IMU2``, ``MAG3``; ArduCopter
  3.x) or an instance column ``I`` (later firmware): both become the instance column that
  ``--instance`` picks (:func:`calib_jax.io.files._one_instance`);
* for the magnetometer (``sensor="mag"``: ``calib-jax mag``, ``marg``), each magnetometer
  row also gets the accelerometer row nearest in time (recorded values, not interpolated,
  within one accelerometer step), so that the board's attitude can be judged; the IMU runs
  faster than the compass (50 against 10 Hz in ArduCopter 3.1);
* ArduPilot's units: m/s^2, rad/s and milligauss. A magnetometer row of 0, 0, 0 is a compass
  that has not answered yet: its cells are read as NaN, noted, for the fits to drop.
"""

from __future__ import annotations

import re
from collections import Counter

import numpy as np

_PROBE_LINES = 400  # the FMT block opens the log (after a firmware banner)
_UNITS = {"a": "m/s^2", "g": "rad/s"}  # AP_Logger's IMU; MAG is in milligauss (no label)


def looks_like_dataflash(head: str) -> bool:
    """The text opens with ArduPilot's ``FMT`` lines (at least three, within its first
    :data:`_PROBE_LINES` lines)."""
    lines = head.splitlines()[:_PROBE_LINES]
    return sum(1 for line in lines if re.match(r"\s*FMT\s*,\s*\d+\s*,", line)) >= 3


def _formats(lines: list[str]) -> dict[str, list[str]]:
    """Message name -> its column names, from the FMT lines (the last definition wins)."""
    out = {}
    for line in lines:
        if not line.lstrip().startswith("FMT"):
            continue
        cells = [c.strip() for c in line.split(",")]
        if len(cells) >= 6 and cells[0] == "FMT" and cells[3]:
            out[cells[3]] = [c for c in cells[5:] if c]
    return out


def _canon(cols: list[str]) -> list[str | None]:
    from .files import canonical_name

    return [canonical_name(c) for c in cols]


def _sensor_columns(cols: list[str]) -> set[str]:
    """Sensor prefixes (a, g, m) whose x, y and z all are among ``cols``."""
    canon = set(_canon(cols))
    return {p for p in "agm" if {p + a for a in "xyz"} <= canon}


def _group(name: str) -> str:
    """A message's family: ``IMU2`` and ``IMU`` are one (the second IMU of ArduCopter 3.x)."""
    return re.sub(r"\d+$", "", name)


def _rows(
    lines: list[str], names: set[str], widths: dict[str, int], notes: list[str]
) -> dict[str, np.ndarray]:
    """The numeric rows of the messages ``names`` (cells that are no number read as NaN);
    rows whose field count is not their FMT line's are skipped and counted in ``notes``."""
    out: dict[str, list[list[float]]] = {n: [] for n in names}
    skipped: Counter = Counter()
    for line in lines:
        head, _, rest = line.partition(",")
        name = head.strip()
        if name not in out:
            continue
        cells = rest.split(",")
        if len(cells) != widths[name]:
            skipped[name] += 1
            continue
        row = []
        for c in cells:
            try:
                row.append(float(c))
            except ValueError:
                row.append(np.nan)
        out[name].append(row)
    if skipped:
        notes.append(
            "rows skipped for a number of fields other than their FMT line's: "
            + ", ".join(f"{n} {k}" for n, k in sorted(skipped.items()))
        )
    return {n: np.array(r, float).reshape(-1, widths[n]) for n, r in out.items()}


def _family(
    formats: dict[str, list[str]], counts: Counter, prefix: str
) -> tuple[list[str], list[str]] | None:
    """(message names in instance order, columns) of the family holding sensor ``prefix``
    with the most sensors (IMU before ACC), then the most rows."""
    fams: dict[str, list[str]] = {}
    for name, cols in formats.items():
        if prefix in _sensor_columns(cols) and counts[name]:
            fams.setdefault(_group(name), []).append(name)
    if not fams:
        return None

    def score(f):
        return (len(_sensor_columns(formats[fams[f][0]])), sum(counts[n] for n in fams[f]))

    best = max(fams, key=score)
    names = sorted(fams[best], key=lambda n: (n != best, n))  # IMU, IMU2, IMU3
    cols = formats[names[0]]
    names = [n for n in names if formats[n] == cols]
    return names, cols


def _stacked(rows: dict[str, np.ndarray], names: list[str], cols: list[str]):
    """One family's rows in time order; messages IMU, IMU2, ... become instance 0, 1, ...
    in a column ``I`` (a family that already has ``I`` keeps its own)."""
    if len(names) == 1:
        return list(cols), rows[names[0]]
    parts = [np.column_stack([np.full(len(rows[n]), k), rows[n]]) for k, n in enumerate(names)]
    data = np.concatenate(parts)
    canon = _canon(cols)
    if "t" in canon:
        data = data[np.argsort(data[:, 1 + canon.index("t")], kind="stable")]
    return ["I", *cols], data


def _instance_zero(header: list[str], data: np.ndarray) -> np.ndarray:
    from .files import INSTANCE_NAMES, _clean

    j = next((j for j, h in enumerate(header) if _clean(h) in INSTANCE_NAMES), None)
    return data if j is None else data[data[:, j] == np.nanmin(data[:, j])]


def _nearest_rows(t_to: np.ndarray, t_from: np.ndarray, data: np.ndarray) -> np.ndarray:
    """The rows of ``data`` (times ``t_from``, rising) nearest in time to each of ``t_to``;
    NaN where the nearest is more than one median step of ``t_from`` away."""
    out = np.full((len(t_to), data.shape[1]), np.nan)
    if len(t_from) < 2:
        return out
    step = float(np.median(np.diff(t_from)))
    i = np.clip(np.searchsorted(t_from, t_to), 1, len(t_from) - 1)
    i = np.where(np.abs(t_from[i - 1] - t_to) <= np.abs(t_from[i] - t_to), i - 1, i)
    ok = np.abs(t_from[i] - t_to) <= step
    out[ok] = data[i[ok]]
    return out


def read_dataflash(text: str, path, sensor: str | None, notes: list[str]):
    """The table (:class:`calib_jax.io.files._Table`) of the sensor wanted (``sensor``:
    None, "accel" and "gyro" read the IMU; "mag" the compass with the IMU's accelerometer
    row nearest in time beside each row). A ValueError names the messages the log holds when
    none carries that sensor."""
    from .files import _Table

    lines = text.splitlines()
    formats = _formats(lines)
    counts = Counter(line.partition(",")[0].strip() for line in lines)
    prefix = "m" if sensor == "mag" else ("g" if sensor == "gyro" else "a")
    fam = _family(formats, counts, prefix)
    if fam is None:
        held = ", ".join(f"{n} {c}" for n, c in counts.most_common(12) if n in formats)
        label = {"a": "accelerometer (AccX..Z)", "g": "gyroscope (GyrX..Z)"}
        raise ValueError(
            f"{path}: an ArduPilot log whose messages carry no "
            f"{label.get(prefix, 'magnetometer (MagX..Z)')} columns (messages: {held}); log "
            "IMU and MAG (LOG_BITMASK) or export them with --columns from a CSV"
        )
    names, cols = fam
    widths = {n: len(formats[n]) for n in formats}
    want = set(names)
    imu = _family(formats, counts, "a") if prefix == "m" else None
    if imu is not None:
        want |= set(imu[0])
    rows = _rows(lines, want, widths, notes)
    header, data = _stacked(rows, names, cols)
    canon = _canon(header)
    units = {p: u for p, u in _UNITS.items() if p in _sensor_columns(header)}
    others = sorted(n for n, c in counts.items() if n in formats and n not in want and c)
    notes.append(
        f"ArduPilot log: read message {' and '.join(names)} ({', '.join(cols)}; "
        f"{len(data)} rows) of {len(others) + len(want)} message types"
    )
    if prefix == "m":
        mag = [canon.index("m" + a) for a in "xyz"]
        zero = np.all(data[:, mag] == 0, axis=1)
        if zero.any():
            data = data.copy()
            data[np.ix_(zero, mag)] = np.nan
            notes.append(
                f"{int(zero.sum())} magnetometer rows of 0, 0, 0 (no reading yet) read as NaN "
                "for the fits to drop"
            )
        if imu is not None and "t" in canon:
            ih, idata = _stacked(rows, *imu)
            idata = _instance_zero(ih, idata)
            ic = _canon(ih)
            acc = [ic.index("a" + a) for a in "xyz"]
            t_imu = idata[:, ic.index("t")]
            near = _nearest_rows(data[:, canon.index("t")], t_imu, idata[:, acc])
            header, data = [*header, *(ih[j] for j in acc)], np.column_stack([data, near])
            units["a"] = _UNITS["a"]
            notes.append(
                f"beside each {names[0]} row the {imu[0][0]} accelerometer row nearest in time "
                f"({int(np.isfinite(near[:, 0]).sum())} of {len(near)} within one "
                f"{imu[0][0]} step)"
            )
    elif "m" not in _sensor_columns(header):
        mag = _family(formats, counts, "m")
        if mag is not None:
            notes.append(
                f"its magnetometer ({' and '.join(mag[0])}, {sum(counts[n] for n in mag[0])} "
                "rows at its own rate) is read by calib-jax mag and marg"
            )
    return _Table(header, data, units=units)
