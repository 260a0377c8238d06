"""A saved calibration as the correction other tools apply, written and read in their formats.

Every calibration calib_jax saves is, per sensor, one affine correction

    x = C (raw - b)

- accelerometer (paper 1): C = alpha^-1, b = beta;
- ellipsoid (paper 2, ``calib-jax mag``): C = W (the soft-iron matrix), b = the centre;
- MARG (``calib-jax marg``): the accelerometer's, and the magnetometer's with the rotation
  folded in, C = R_mag_to_acc W, so its output is in the accelerometer's frame.

:class:`Correction` holds that form; :func:`corrections` takes it from any saved calibration
(object, dict or JSON path). The writers and readers below hold each tool's convention:

========  =============================================  ======================================
format    file                                           the tool's equation
========  =============================================  ======================================
c         a C header for firmware (float constants and   x = C (raw - b)
          an inline function)
imu_tk    ``CalibratedTriad_::save``'s text: T, K        X' = T K (X - B)
          (3 x 3 each, row-major) and B
imucal    ``FerrarisCalibrationInfo`` JSON               a = R_a^-1 K_a^-1 (raw - b_a)
ros       ``imu_calib``'s YAML (``SM``, ``bias``)        corrected = SM raw - bias
========  =============================================  ======================================

Numbers are written with 17 significant digits (float64 round trip) except in the C header,
whose float constants carry 9 (float32 round trip). Nothing here imports JAX.
"""

from __future__ import annotations

import datetime as _dt
import json
import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .calibration import (
    AccelCalibration,
    BatchRecord,
    MagCalibration,
    _read_json,
    warn_if_unusable,
)
from .models.layout import ALPHA_INDEX

FORMATS = ("c", "imu_tk", "imucal", "ros")
G_STANDARD = 9.80665
"""m/s^2 per g: ROS messages carry accelerations in m/s^2 (REP 103)."""


@dataclass(frozen=True)
class Correction:
    """x = matrix @ (raw - bias) for one sensor triad."""

    sensor: str
    """'accel', 'gyro' or 'mag'."""
    matrix: np.ndarray
    """C (3 x 3)."""
    bias: np.ndarray
    """b (3,), in input units."""
    input_units: str | None = None
    output_units: str | None = None
    frame: str = "sensor"
    """'sensor', or 'accel' for a MARG magnetometer rotated into the accelerometer's frame."""
    status: str | None = None
    source: str | None = None
    notes: tuple[str, ...] = ()
    """What the file held that this correction does not apply."""
    g_sensitivity: np.ndarray | None = None
    """Gyroscope only: G (3 x 3), input units per m/s^2 of calibrated acceleration a, removed
    as raw - b - G a (imucal's K_ga). None: no such term."""
    scale_asymmetry: np.ndarray | None = None
    """Gyroscope only: s (3,), x -> x (1 + s sign(x)) per axis before C. None: none."""

    @property
    def needs_acc(self) -> bool:
        """True when :meth:`apply` needs the calibrated acceleration (a non-zero G)."""
        return self.g_sensitivity is not None and bool(np.any(self.g_sensitivity != 0))

    def apply(self, raw, acc=None) -> np.ndarray:
        """Corrected vectors for one reading (3,) or many (N, 3); ``acc`` the calibrated
        acceleration in m/s^2 of the same samples, used where G is not zero (left out, G is
        not applied: :attr:`needs_acc` tells)."""
        x = np.asarray(raw, float) - self.bias
        if acc is not None and self.needs_acc:
            x = x - np.asarray(acc, float) @ self.g_sensitivity.T
        if self.scale_asymmetry is not None and np.any(self.scale_asymmetry != 0):
            x = x * (1.0 + self.scale_asymmetry * np.sign(x))
        return x @ self.matrix.T

    def describe(self) -> str:
        """One line: the sensor, the equation, the units and the frame."""
        units = f"{self.input_units or 'raw units'} -> {self.output_units or 'calibrated units'}"
        frame = ", in the accelerometer's frame" if self.frame == "accel" else ""
        inner = "raw - b - G a" if self.needs_acc else "raw - b"
        if self.scale_asymmetry is not None and np.any(self.scale_asymmetry != 0):
            return f"{self.sensor}: x = C ((1 + s sign(d)) d), d = {inner}, {units}{frame}"
        return f"{self.sensor}: x = C ({inner}), {units}{frame}"

    def _refuse_effects(self, fmt: str) -> None:
        """A ValueError when this correction has terms ``fmt`` cannot hold (G, s)."""
        lost = [
            name
            for name, v in (
                ("g-sensitivity G", self.g_sensitivity),
                ("scale asymmetry s", self.scale_asymmetry),
            )
            if v is not None and np.any(np.asarray(v) != 0)
        ]
        if lost:
            raise ValueError(
                f"the {self.sensor} calibration has {' and '.join(lost)}, which {fmt}'s format "
                "cannot hold; export it as c (the header applies them) or imucal (G as K_ga)"
            )


# ---------------------------------------------------------------------------------------------
# from calib_jax's own records


def corrections(cal) -> dict[str, Correction]:
    """The corrections a saved calibration applies, by sensor ('accel', 'mag').

    ``cal``: an :class:`~calib_jax.AccelCalibration`, :class:`~calib_jax.MagCalibration`,
    :class:`~calib_jax.marg.MARGRecord`, their ``to_dict()``, or the path of their JSON (or of
    a file in one of :data:`FORMATS`, read by :func:`read`). Raises ValueError naming the file
    and the fault for anything else. A MARG record whose accelerometer was used as given
    (``--accel none``) has no accelerometer correction.
    """
    if isinstance(cal, str | Path):
        return read(cal)
    if isinstance(cal, Correction):
        return {cal.sensor: cal}
    if isinstance(cal, dict) and cal and all(isinstance(v, Correction) for v in cal.values()):
        return dict(cal)
    if isinstance(cal, AccelCalibration):
        return {"accel": _accel(cal)}
    if isinstance(cal, MagCalibration):
        return {cal.sensor: _ellipsoid(cal)}
    d = cal.to_dict() if hasattr(cal, "to_dict") else cal
    if not isinstance(d, dict):
        raise ValueError(
            f"expected a calibration (AccelCalibration, MagCalibration, MARGRecord, a dict or "
            f"a JSON path), got {type(cal).__name__}"
        )
    return _from_dict(d, d.get("source"))


def _accel(cal: AccelCalibration) -> Correction:
    return Correction(
        sensor="accel",
        matrix=np.linalg.inv(cal.params[ALPHA_INDEX]),
        bias=np.array(cal.bias, float),
        input_units=cal.input_units,
        output_units=cal.output_units,
        status=cal.status,
        source=cal.source,
    )


def _ellipsoid(cal: MagCalibration) -> Correction:
    if cal.field is not None:
        out = f"the field's units (|x| = {cal.field:g})"
    else:
        out = cal.units  # det W = 1: the raw units' scale
    return Correction(
        sensor=cal.sensor,
        matrix=np.array(cal.soft_iron, float),
        bias=np.array(cal.center, float),
        input_units=cal.units,
        output_units=out,
        status=cal.status,
        source=cal.source,
    )


def _gyro(g) -> Correction:
    """The correction of a :class:`~calib_jax.GyroCalibration`: C, b, and G and s where the
    fit found them."""
    return Correction(
        sensor="gyro",
        matrix=np.array(g.matrix, float),
        bias=np.array(g.bias, float),
        input_units=g.input_units,
        output_units=g.output_units,
        status=g.status,
        source=g.source,
        g_sensitivity=np.array(g.g_sensitivity, float),
        scale_asymmetry=np.array(g.scale_asymmetry, float),
    )


def correction_from_result(r: dict, sensor: str | None = None) -> Correction:
    """The correction of one fleet result (:func:`calib_jax.fleet.calibrate_files`, or an entry
    of ``calib-jax batch --json``): 9 parameters are paper 1's accelerometer vector, 12 the
    ellipsoid's centre and W (row-major), or with ``sensor="gyro"`` C (row-major) and b. A
    ValueError for a file that was not calibrated."""
    if r.get("status") != "ok" or not r.get("params"):
        raise ValueError(
            f"{r.get('path')}: not calibrated ({r.get('status')}: {r.get('message', '')}); "
            "there is no correction to export"
        )
    p = np.asarray(r["params"], float)
    units = r.get("units")
    if sensor == "gyro" and p.size == 12:
        G, asym = r.get("g_sensitivity"), r.get("scale_asymmetry")
        c = Correction(
            "gyro", p[:9].reshape(3, 3), p[9:], units, "rad/s",
            g_sensitivity=None if G is None else np.reshape(np.asarray(G, float), (3, 3)),
            scale_asymmetry=None if asym is None else np.asarray(asym, float),
        )  # fmt: skip
    elif p.size == 9:
        out = None if units == "counts" else units  # counts are fitted to the reference g
        c = Correction("accel", np.linalg.inv(p[ALPHA_INDEX]), p[6:9], units, out)
    elif p.size == 12:
        c = Correction("mag", p[3:].reshape(3, 3), p[:3], units, units)
    else:
        raise ValueError(f"{r.get('path')}: {p.size} parameters are neither accel (9) nor mag (12)")
    return _checked(replace(c, status="ok", source=r.get("path")), r.get("path"))


def _from_dict(d: dict, where) -> dict[str, Correction]:
    kind = d.get("kind")
    if kind == "marg":
        out = {}
        a = d.get("accel")
        if a is not None:
            out.update(_from_dict(a, where))
        mag = _ellipsoid(MagCalibration.from_dict(d["mag"], source=where))
        R = np.asarray(d["R_mag_to_acc"], float)
        if R.shape != (3, 3) or not np.all(np.isfinite(R)):
            raise ValueError(f"{where}: key 'R_mag_to_acc' is not a finite 3 x 3 matrix")
        out["mag"] = Correction(
            sensor="mag",
            matrix=R @ mag.matrix,
            bias=mag.bias,
            input_units=mag.input_units,
            output_units=mag.output_units,
            frame="accel",
            status=d.get("status"),
            source=d.get("source"),
        )
        if d.get("gyro") is not None:
            out.update(_from_dict(d["gyro"], where))
        return out
    if kind == "gyro":
        from .gyro import GyroCalibration

        return {"gyro": _gyro(GyroCalibration.from_dict(d, source=where))}
    if kind == "ellipsoid":
        cal = MagCalibration.from_dict(d, source=where)
        return {cal.sensor: _ellipsoid(cal)}
    if kind == "batch":
        rec = BatchRecord.from_dict(d, source=where)
        if len(rec) != 1:
            raise ValueError(
                f"{where or 'this BatchRecord'}: a batch of {len(rec)} calibrations; export "
                "one entry in Python (calib_jax.export.correction_from_result(record.entries[i],"
                " record.sensor), record = BatchRecord.load(path) or the one in memory)"
            )
        return {rec.sensor: correction_from_result(rec.entries[0], rec.sensor)}
    return {"accel": _accel(AccelCalibration.from_dict(d, source=where))}


# ---------------------------------------------------------------------------------------------
# writers


def write(cal, fmt: str, *, sensor: str | None = None, name: str = "calib") -> str:
    """The text of ``cal`` in format ``fmt`` (one of :data:`FORMATS`).

    ``sensor`` picks one triad for the single-triad formats (imu_tk, ros) when the calibration
    holds two (MARG); ``name`` prefixes the C header's identifiers. A calibration that
    failed or did not converge is written, with a :class:`~calib_jax.FitStatusWarning`.
    """
    corr = corrections(cal)
    warn_unusable(corr)
    if fmt == "c":
        return to_c_header(corr, name=name)
    if fmt == "imucal":
        if sensor is not None:
            return to_imucal_json(*_imucal_pair({sensor: _one(corr, sensor, fmt)}))
        return to_imucal_json(*_imucal_pair(corr))
    if fmt == "imu_tk":
        return to_imu_tk(_one(corr, sensor, fmt))
    if fmt == "ros":
        return to_ros_yaml(_one(corr, sensor, fmt))
    raise ValueError(f"unknown export format {fmt!r}; use one of {', '.join(FORMATS)}")


def _one(corr: dict[str, Correction], sensor: str | None, fmt: str) -> Correction:
    if sensor is None:
        if len(corr) > 1:
            raise ValueError(
                f"the calibration holds {' and '.join(corr)}; a {fmt} file holds one triad: "
                f"choose with --sensor ({' or '.join(corr)})"
            )
        return next(iter(corr.values()))
    if sensor not in corr:
        why = (
            "imucal's FerrarisCalibrationInfo holds an accelerometer (and a gyroscope), no "
            "magnetometer; export it as c, imu_tk or ros"
            if fmt == "imucal"
            else f"choose one of {', '.join(corr)}"
        )
        raise ValueError(f"the calibration has no {sensor} correction to write as {fmt}: {why}")
    return corr[sensor]


def _imucal_pair(corr: dict[str, Correction]) -> tuple[Correction | None, Correction | None]:
    """(accelerometer, gyroscope) for imucal's file, which holds those two and no more."""
    if "accel" not in corr and "gyro" not in corr:
        raise ValueError(
            "imucal's FerrarisCalibrationInfo holds an accelerometer and a gyroscope, no "
            "magnetometer; export the magnetometer as c, imu_tk or ros"
        )
    return corr.get("accel"), corr.get("gyro")


def _header_lines(corr: dict[str, Correction]) -> list[str]:
    c0 = next(iter(corr.values()))
    lines = [f"calib_jax calibration from {c0.source or 'an unnamed log'}"]
    lines.append(
        "written "
        + _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
        + "; status "
        + ", ".join(f"{k} {c.status}" for k, c in corr.items())
    )
    lines += [c.describe() for c in corr.values()]
    return lines


def to_c_header(corr: dict[str, Correction] | Correction, name: str = "calib") -> str:
    """A C99 header: ``<NAME>_<SENSOR>_C[3][3]`` and ``_B[3]`` float constants and an inline
    ``<name>_<sensor>_correct(const float raw[3], float out[3])`` per sensor."""
    if isinstance(corr, Correction):
        corr = {corr.sensor: corr}
    ident = re.sub(r"\W", "_", name).strip("_") or "calib"
    if ident[0].isdigit():
        ident = "c_" + ident
    up = ident.upper()
    guard = f"{up}_CALIBRATION_H"
    out = ["/*"]
    out += [f" * {ln}" for ln in _header_lines(corr)]
    out += [
        " *",
        " * out = C (raw - b): raw in the input units above, out in the output units.",
        " */",
        f"#ifndef {guard}",
        f"#define {guard}",
        "",
    ]
    for s, c in corr.items():
        out += _c_block(c, f"{up}_{s.upper()}", f"{ident}_{s}")
    out += [f"#endif /* {guard} */", ""]
    return "\n".join(out)


def _c_matrix(name: str, m: np.ndarray) -> str:
    rows = ",\n".join("    {" + ", ".join(_cfloat(v) for v in row) + "}" for row in m)
    return f"static const float {name}[3][3] = {{\n{rows}\n}};"


def _c_vector(name: str, v: np.ndarray) -> str:
    return f"static const float {name}[3] = {{" + ", ".join(_cfloat(x) for x in v) + "};"


def _c_block(c: Correction, const: str, fun: str) -> list[str]:
    """One triad's constants and its inline correct function; a gyroscope with
    g-sensitivity takes the calibrated acceleration (m/s^2) too, one with scale asymmetry
    scales each axis by 1 + s sign(d)."""
    asym = c.scale_asymmetry is not None and bool(np.any(c.scale_asymmetry != 0))
    lines = [f"/* {c.describe()} */", _c_matrix(f"{const}_C", c.matrix)]
    lines.append(_c_vector(f"{const}_B", c.bias))
    d = [f"raw[{i}] - {const}_B[{i}]" for i in range(3)]
    args = "const float raw[3], float out[3]"
    if c.needs_acc:
        lines.append(
            f"/* G, {c.input_units or 'input units'} per m/s^2 of calibrated acceleration */"
        )
        lines.append(_c_matrix(f"{const}_G", c.g_sensitivity))
        args = "const float raw[3], const float acc[3], float out[3]"
        d = [
            f"{d[i]} - ({const}_G[{i}][0] * acc[0] + {const}_G[{i}][1] * acc[1] + "
            f"{const}_G[{i}][2] * acc[2])"
            for i in range(3)
        ]
    if asym:
        lines.append(_c_vector(f"{const}_S", c.scale_asymmetry))
    lines += ["", f"static inline void {fun}_correct({args})", "{", "    float d[3];"]
    lines += [f"    d[{i}] = {d[i]};" for i in range(3)]
    if asym:
        lines += [
            "    for (int i = 0; i < 3; ++i)",
            f"        d[i] *= 1.0f + (d[i] > 0.0f ? {const}_S[i] : d[i] < 0.0f ? -{const}_S[i] "
            ": 0.0f);",
        ]
    lines += [
        "    for (int i = 0; i < 3; ++i)",
        f"        out[i] = {const}_C[i][0] * d[0] + {const}_C[i][1] * d[1] + "
        f"{const}_C[i][2] * d[2];",
        "}",
        "",
    ]
    return lines


def _cfloat(v: float) -> str:
    """A C float literal that round-trips float32 (``1.0f``, not the invalid ``1f``)."""
    s = f"{v:.9g}"
    return (s if any(c in s for c in ".e") else s + ".0") + "f"


def _num(v: float) -> str:
    return f"{v:.17g}"


def imu_tk_factors(c: Correction) -> tuple[np.ndarray, np.ndarray]:
    """imu_tk's misalignment T and scale K with T K = C.

    K is C's diagonal, so T has imu_tk's unit diagonal; when some diagonal entry is small next
    to its column (a MARG magnetometer whose axes are permuted into the accelerometer's), K is
    the column norms instead and T's columns are unit vectors."""
    C = np.asarray(c.matrix, float)
    d = np.diag(C).copy()
    norms = np.linalg.norm(C, axis=0)
    k = d if np.all(np.abs(d) >= 0.5 * norms) else norms
    return C / k, np.diag(k)


def to_imu_tk(c: Correction) -> str:
    """imu_tk's calibration text (``CalibratedTriad_::load`` reads it): T, K and B, numbers
    only, as imu_tk writes them (a comment would break its reader)."""
    c._refuse_effects("imu_tk")
    T, K = imu_tk_factors(c)

    def block(m):
        return "\n".join(" ".join(_num(v) for v in row) for row in np.atleast_2d(m))

    return f"{block(T)}\n\n{block(K)}\n\n{block(c.bias.reshape(3, 1))}\n\n"


def to_imucal_json(c: Correction | None, gyro: Correction | None = None) -> str:
    """imucal's ``FerrarisCalibrationInfo`` JSON (``CalibrationInfo.from_json_file`` reads it).

    imucal applies a = R_a^-1 K_a^-1 (raw - b_a) and w = R_g^-1 K_g^-1 (raw - K_ga a - b_g):
    K R = C^-1, K the row norms of C^-1 (the sensitivities) and R its rows made unit (the
    axes' directions, Ferraris' form); K_ga is calib_jax's g-sensitivity G (per m/s^2, as
    imucal's). A triad not given is written as the identity (passed through unchanged) and
    the ``comment`` field says so. Scale asymmetry has no place in the file: an error.
    """
    for x in (c, gyro):
        if x is not None and x.sensor == "mag":
            _imucal_pair({"mag": x})
    if gyro is not None and gyro.scale_asymmetry is not None:
        replace(gyro, g_sensitivity=None)._refuse_effects("imucal")

    def factors(x: Correction | None):
        if x is None:
            return np.eye(3), np.eye(3), np.zeros(3)
        M = np.linalg.inv(x.matrix)
        k = np.linalg.norm(M, axis=1)
        return np.diag(k), M / k[:, None], np.asarray(x.bias, float)

    lead = c if c is not None else gyro
    comment = "calib_jax: " + "; ".join(x.describe() for x in (c, gyro) if x is not None)
    comment += f"; from {lead.source or 'an unnamed log'}, status {lead.status}"
    for name, x in (("accelerometer", c), ("gyroscope", gyro)):
        if x is None:
            comment += f"; {name} NOT calibrated by calib_jax: identity terms pass it through"
    (Ka, Ra, ba), (Kg, Rg, bg) = factors(c), factors(gyro)
    G = gyro.g_sensitivity if gyro is not None and gyro.needs_acc else np.zeros((3, 3))
    d = {
        "acc_unit": None if c is None else c.output_units,
        "gyr_unit": None if gyro is None else gyro.output_units,
        "from_acc_unit": None if c is None else c.input_units,
        "from_gyr_unit": None if gyro is None else gyro.input_units,
        "comment": comment,
        "K_a": Ka.tolist(),
        "R_a": Ra.tolist(),
        "b_a": ba.tolist(),
        "K_g": Kg.tolist(),
        "R_g": Rg.tolist(),
        "K_ga": np.asarray(G, float).tolist(),
        "b_g": bg.tolist(),
        "cal_type": "Ferraris",
        "_format_version": "2.0.0",
    }
    return json.dumps(d, indent=4) + "\n"


def to_ros_yaml(c: Correction) -> str:
    """``imu_calib``'s YAML (``SM`` row-major, ``bias``): corrected = SM raw - bias, so
    SM = C and bias = C b. An accelerometer calibrated to g is scaled to m/s^2, the unit of
    ``sensor_msgs/Imu`` (REP 103); the comment says what was done."""
    c._refuse_effects("imu_calib's YAML")
    C, bias = np.asarray(c.matrix, float), c.matrix @ c.bias
    out_units = c.output_units
    lines = ["# " + ln for ln in _header_lines({c.sensor: c})]
    if c.sensor == "accel" and out_units == "g":
        C, bias, out_units = C * G_STANDARD, bias * G_STANDARD, "m/s^2"
        lines.append(f"# scaled from g to m/s^2 (x {G_STANDARD}) for sensor_msgs/Imu")
    lines.append(
        f"# corrected = SM raw - bias; raw in {c.input_units or 'raw units'}, "
        f"corrected in {out_units or 'calibrated units'}"
    )
    if c.sensor != "accel":
        lines.append(
            "# imu_calib's apply_calib node applies this form to sensor_msgs/Imu; apply it to "
            "the magnetometer in your own node"
        )
    lines.append(f"sensor: {c.sensor}")
    lines.append("SM: [" + ", ".join(_num(v) for v in C.ravel()) + "]")
    lines.append("bias: [" + ", ".join(_num(v) for v in bias) + "]")
    return "\n".join(lines) + "\n"


def save(cal, fmt: str, path: str | Path, **kw) -> Path:
    """Write :func:`write`'s text to ``path``; returns the path."""
    path = Path(path)
    path.write_text(write(cal, fmt, **kw))
    return path


# ---------------------------------------------------------------------------------------------
# readers


def warn_unusable(corr: dict[str, Correction]) -> None:
    """:func:`calib_jax.calibration.warn_if_unusable` for each correction."""
    for name, c in corr.items():
        warn_if_unusable(c.status, f"the {name} calibration", c.source)


def status_warnings(corr: dict[str, Correction], sensor: str | None = None) -> list[str]:
    """A line for each correction (of ``sensor``, or all) whose fit was not 'ok': what
    ``calib-jax apply`` and ``export`` say on stderr before using it (a poorly determined
    matrix went into a C header with only a comment saying so)."""
    return [
        f"the {name} calibration's status is '{c.status}' (from {c.source or 'an unnamed log'})"
        ": the data did not determine all of it; read its warnings before using it"
        for name, c in corr.items()
        if (sensor is None or name == sensor) and c.status not in (None, "ok")
    ]


def read(path: str | Path, sensor: str | None = None) -> dict[str, Correction]:
    """The corrections in a file: calib_jax's JSON (accel, ellipsoid, MARG), imucal's JSON,
    imu_calib's YAML or imu_tk's text, told apart by their content. ``sensor`` names the
    triad of an imu_tk file (its text does not say; default 'accel')."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(
            f"calibration {path} {'is a directory' if path.is_dir() else 'does not exist'}"
        )
    try:
        text = path.read_text()
    except UnicodeDecodeError:
        raise ValueError(f"{path} is not a calibration file (not text)") from None
    head = text.lstrip()
    if head.startswith("{"):
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path} is not a calibration JSON file: {exc}") from None
        if isinstance(d, dict) and "cal_type" in d:
            return from_imucal_json(text, source=str(path))
        d = _read_json(path)  # calib_jax's own: NaN tokens and versions checked
        return _from_dict(d, str(path))
    if re.search(r"^\s*SM\s*:", text, re.M):
        c = from_ros_yaml(text, source=str(path))
        return {c.sensor: c}
    try:
        c = from_imu_tk(text, sensor=sensor or "accel", source=str(path))
    except ValueError as exc:
        raise ValueError(
            f"{path} is not a calibration file ({exc}); calib_jax reads its own JSON (calib-jax "
            "accel, mag, marg --json), imucal's JSON, imu_calib's YAML (SM, bias) and imu_tk's "
            "text (21 numbers). Is it a log? calib-jax apply takes the calibration first, then "
            "the log"
        ) from None
    return {c.sensor: c}


def from_imu_tk(text: str, sensor: str = "accel", source: str | None = None) -> Correction:
    """Read imu_tk's text (T, K, B): 21 numbers, as its ``load`` reads them."""
    try:
        v = np.array([float(t) for t in text.split()])
    except ValueError:
        raise ValueError(
            "not an imu_tk calibration either (it holds only numbers: the misalignment and "
            "scale matrices, row-major, then the bias)"
        ) from None
    if v.size != 21:
        raise ValueError(
            f"{source or 'text'}: an imu_tk calibration holds 21 numbers (T, K, B); found {v.size}"
        )
    T, K, B = v[:9].reshape(3, 3), v[9:18].reshape(3, 3), v[18:]
    return _checked(Correction(sensor, T @ K, B, source=source), source)


def from_imucal_json(text: str, source: str | None = None) -> dict[str, Correction]:
    """The corrections of imucal's Ferraris (or Turntable) JSON: the accelerometer, and the
    gyroscope (with K_ga as its g-sensitivity) unless the file passes it through (identity
    K_g and R_g, zero b_g and K_ga)."""
    d = json.loads(text)
    if d.get("cal_type") not in ("Ferraris", "Turntable"):
        raise ValueError(
            f"{source or 'text'}: imucal calibration type {d.get('cal_type')!r} is not read "
            "here (Ferraris and Turntable are)"
        )

    def matrices(*keys):
        try:
            return [np.asarray(d[k], float) for k in keys]
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{source or 'text'}: imucal JSON without a usable {exc}") from None

    K, R, b = matrices("K_a", "R_a", "b_a")
    out = {
        "accel": _checked(
            Correction(
                "accel", np.linalg.inv(R) @ np.linalg.inv(K), b, input_units=d.get("from_acc_unit"),
                output_units=d.get("acc_unit"), source=source,
            ),
            source,
        )
    }  # fmt: skip
    if d.get("K_g") is None:
        return out
    Kg, Rg, bg, Kga = matrices("K_g", "R_g", "b_g", "K_ga")
    if np.allclose(Kg @ Rg, np.eye(3)) and not np.any(bg) and not np.any(Kga):
        return out  # the gyroscope passed through
    gyro = Correction(
        "gyro", np.linalg.inv(Rg) @ np.linalg.inv(Kg), bg, input_units=d.get("from_gyr_unit"),
        output_units=d.get("gyr_unit"), source=source, g_sensitivity=Kga,
    )  # fmt: skip
    out["gyro"] = _checked(gyro, source)
    return out


def _yaml_list(text: str, key: str) -> np.ndarray | None:
    """A list of numbers under ``key``: flow (``key: [1, 2]``) or block (``- 1`` lines), the
    two styles yaml-cpp and PyYAML write."""
    m = re.search(rf"^{key}\s*:\s*\[([^\]]*)\]", text, re.M)
    if m:
        items = m.group(1).split(",")
    else:
        m = re.search(rf"^{key}\s*:\s*\n((?:[ \t]*-[^\n]*\n?)+)", text, re.M)
        if not m:
            return None
        items = [ln.strip()[1:] for ln in m.group(1).splitlines() if ln.strip()]
    return np.array([float(s) for s in items if s.strip()])


def from_ros_yaml(text: str, source: str | None = None) -> Correction:
    """``imu_calib``'s YAML: SM (9, row-major) and bias (3); corrected = SM raw - bias."""
    try:
        SM, bias = _yaml_list(text, "SM"), _yaml_list(text, "bias")
    except ValueError:
        SM = bias = None
    if SM is None or bias is None or SM.size != 9 or bias.size != 3:
        raise ValueError(
            f"{source or 'text'}: not an imu_calib YAML (it needs 'SM' with 9 numbers and "
            "'bias' with 3)"
        )
    m = re.search(r"^sensor\s*:\s*(\w+)", text, re.M)
    # the units to_ros_yaml states in its comment (a user's round trip lost them)
    said = r"^#\s*corrected = SM raw - bias; raw in (.+?), corrected in (.+?)\s*$"
    u = re.search(said, text, re.M)
    units = [None, None] if u is None else [u.group(1), u.group(2)]
    units = [None if v in ("raw units", "calibrated units") else v for v in units]
    C = SM.reshape(3, 3)
    c = Correction(
        m.group(1) if m else "accel",
        C,
        np.linalg.solve(C, bias),
        input_units=units[0],
        output_units=units[1],
        source=source,
    )
    return _checked(c, source)


def _checked(c: Correction, source) -> Correction:
    if not (np.all(np.isfinite(c.matrix)) and np.all(np.isfinite(c.bias))):
        raise ValueError(f"{source or 'text'}: the calibration holds non-finite numbers")
    if not np.linalg.cond(c.matrix) < 1e12:
        raise ValueError(f"{source or 'text'}: the correction matrix is singular")
    return c
