"""A fitted accelerometer calibration: the record users keep, apply and save.

Saved as versioned JSON (``format_version``), checked on load. Parameters are in input units
(gains and non-orthogonality: input units per output unit; bias: input units), so the same
file applies to new raw data from the same sensor: a = alpha^-1 (a' - beta).
"""

from __future__ import annotations

import datetime as _dt
import json
from dataclasses import dataclass, field
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from .models.accel import PARAM_NAMES, AccelParams

FORMAT_VERSION = 1
MODELS = ("accel9", "accel6")


@dataclass(frozen=True)
class AccelCalibration:
    """Outcome of :func:`calib_jax.calibrate_accel`.

    ``status`` is "ok", "poorly_determined" (converged, but some parameter is not pinned down
    by the poses: see ``poorly_determined`` and ``warnings``), "not_converged" or "failed".
    """

    params: np.ndarray
    """Paper 1's p = [alpha_x, alpha_y, alpha_z, S_xy, S_xz, S_yz, beta_x, beta_y, beta_z]."""
    stderr: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    condition: float
    status: str
    input_units: str
    output_units: str
    g: float
    """Reference magnitude, in output units."""
    solver: str
    solver_status: int
    solver_message: str
    iterations: int
    nfev: int
    use: str
    """'means' (interval means) or 'samples' (all static samples)."""
    n_intervals: int
    n_points: int
    """Points the fit used (interval means or samples)."""
    rms_before: float
    rms_after: float
    noise_floor: float
    poorly_determined: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    static_means: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    """Raw means of the static intervals (n_intervals, 3), input units."""
    nominal_offset: np.ndarray = field(default_factory=lambda: np.zeros(3))
    nominal_scale: float = 1.0
    """The 'before' conversion (raw - nominal_offset) / nominal_scale, see calib_jax.accel."""
    sensor_id: str | None = None
    date: str = field(
        default_factory=lambda: _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    )
    source: str | None = None
    model: str = "accel9"
    """'accel9' (paper 1) or 'accel6' (non-orthogonality held at zero)."""
    format_version: int = FORMAT_VERSION

    # ---- use -------------------------------------------------------------------------------
    @property
    def success(self) -> bool:
        return self.status in ("ok", "poorly_determined")

    @property
    def gains(self) -> np.ndarray:
        return self.params[0:3]

    @property
    def nonorth(self) -> np.ndarray:
        return self.params[3:6]

    @property
    def bias(self) -> np.ndarray:
        return self.params[6:9]

    def to_params(self) -> AccelParams:
        """The parameters as a JAX pytree, for use inside jitted pipelines."""
        return AccelParams.from_vector(jnp.asarray(self.params))

    def apply(self, raw: np.ndarray) -> np.ndarray:
        """Calibrated acceleration in output units, a = alpha^-1 (raw - beta), for (..., 3)."""
        raw = np.asarray(raw, float)
        if raw.shape[-1] != 3:
            raise ValueError(f"raw must have 3 columns (x, y, z), got shape {raw.shape}")
        return apply_params(self.params, raw)

    # ---- report ----------------------------------------------------------------------------
    def table(self) -> str:
        """Paper 1 Table 1 layout: each parameter with its standard error."""
        same = self.input_units == self.output_units
        unit_g = "1 (dimensionless)" if same else f"{self.input_units} per {self.output_units}"
        unit = {0: unit_g, 3: unit_g, 6: self.input_units}
        lines = [f"{'parameter':<10} {'value':>14} {'std. error':>12}  unit"]
        for i, name in enumerate(PARAM_NAMES):
            u = unit[3 * (i // 3)]
            lines.append(f"{name:<10} {self.params[i]:>14.6g} {self.stderr[i]:>12.3g}  {u}")
        return "\n".join(lines)

    def report(self) -> str:
        """Table, error before and after, status and warnings, as printed by the CLI."""
        out = [
            self.table(),
            "",
            f"fit on {self.n_points} {self.use} from {self.n_intervals} static intervals; "
            f"solver {self.solver}: {self.solver_message} ({self.iterations} iterations, "
            f"{self.nfev} evaluations)",
            f"RMS of (|a| - g)/g over interval means: before {self.rms_before:.3e}, "
            f"after {self.rms_after:.3e} (noise floor {self.noise_floor:.3e}); "
            f"{self.rms_before / max(self.rms_after, 1e-300):.0f}x lower",
            f"condition number {self.condition:.3g}; status: {self.status}",
        ]
        if self.poorly_determined:
            out.append("poorly determined: " + ", ".join(self.poorly_determined))
        out += [f"warning: {w}" for w in self.warnings]
        return "\n".join(out)

    # ---- JSON ------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        p, s = self.params, self.stderr
        d = {
            "format_version": self.format_version,
            "model": self.model,
            "sensor_id": self.sensor_id,
            "date": self.date,
            "source": self.source,
            "units": {"input": self.input_units, "output": self.output_units, "g": self.g},
            "params": split_params(p),
            "stderr": split_params(s),
            "covariance": self.covariance.tolist(),
            "correlation": self.correlation.tolist(),
            "condition": self.condition,
            "status": self.status,
            "solver": self.solver,
            "solver_status": self.solver_status,
            "solver_message": self.solver_message,
            "iterations": self.iterations,
            "nfev": self.nfev,
            "use": self.use,
            "n_intervals": self.n_intervals,
            "n_points": self.n_points,
            "rms_before": self.rms_before,
            "rms_after": self.rms_after,
            "noise_floor": self.noise_floor,
            "poorly_determined": list(self.poorly_determined),
            "warnings": list(self.warnings),
            "static_means": np.asarray(self.static_means).tolist(),
            "nominal": {
                "offset": np.asarray(self.nominal_offset).tolist(),
                "scale": self.nominal_scale,
            },
        }
        # the JSON standard has no inf/nan: write them as strings, read back by float()
        return _sanitize(d)

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def from_dict(cls, d: dict) -> AccelCalibration:
        _check_version(d)
        if d.get("model") not in MODELS:
            raise ValueError(f"not an accelerometer calibration: model is {d.get('model')!r}")

        def vec(block):
            return np.array(
                [float(v) for k in ("gains", "nonorth", "bias") for v in block[k]], float
            )

        def mat(m):
            return np.array([[float(v) for v in row] for row in m], float)

        return cls(
            params=vec(d["params"]),
            stderr=vec(d["stderr"]),
            covariance=mat(d["covariance"]),
            correlation=mat(d["correlation"]),
            condition=float(d["condition"]),
            status=d["status"],
            input_units=d["units"]["input"],
            output_units=d["units"]["output"],
            g=float(d["units"]["g"]),
            solver=d["solver"],
            solver_status=int(d["solver_status"]),
            solver_message=d["solver_message"],
            iterations=int(d["iterations"]),
            nfev=int(d["nfev"]),
            use=d["use"],
            n_intervals=int(d["n_intervals"]),
            n_points=int(d["n_points"]),
            rms_before=float(d["rms_before"]),
            rms_after=float(d["rms_after"]),
            noise_floor=float(d["noise_floor"]),
            poorly_determined=list(d.get("poorly_determined", [])),
            warnings=list(d.get("warnings", [])),
            static_means=np.array(d.get("static_means", []), float).reshape(-1, 3),
            nominal_offset=np.array(d.get("nominal", {}).get("offset", [0.0, 0.0, 0.0]), float),
            nominal_scale=float(d.get("nominal", {}).get("scale", 1.0)),
            sensor_id=d.get("sensor_id"),
            date=d["date"],
            source=d.get("source"),
            model=d["model"],
        )

    @classmethod
    def load(cls, path: str | Path) -> AccelCalibration:
        return cls.from_dict(_read_json(path))


def split_params(p: np.ndarray) -> dict:
    """Paper 1's nine-vector as the JSON's {gains, nonorth, bias} lists."""
    p = np.asarray(p)
    return {"gains": p[0:3].tolist(), "nonorth": p[3:6].tolist(), "bias": p[6:9].tolist()}


def apply_params(params: np.ndarray, raw: np.ndarray) -> np.ndarray:
    """a = alpha^-1 (raw - beta) in host-side numpy (no per-shape compilation; inside JAX use
    ``models.accel.correct``)."""
    alpha = np.asarray(AccelParams.from_vector(jnp.asarray(params)).alpha)
    return (raw - params[6:9]) @ np.linalg.inv(alpha).T


def _read_json(path: str | Path) -> dict:
    try:
        return json.loads(Path(path).read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path} is not a calibration JSON file: {exc}") from exc


def _check_version(d: dict) -> None:
    version = d.get("format_version")
    if version != FORMAT_VERSION:
        raise ValueError(
            f"calibration format_version {version!r} is not supported (this calib_jax "
            f"reads version {FORMAT_VERSION}); refit with this version or upgrade calib_jax"
        )


def _sanitize(o):
    if isinstance(o, dict):
        return {k: _sanitize(v) for k, v in o.items()}
    if isinstance(o, list | tuple):
        return [_sanitize(v) for v in o]
    if isinstance(o, np.generic):
        o = o.item()
    if isinstance(o, float) and not np.isfinite(o):
        return str(o)  # 'nan', 'inf', '-inf'
    return o


MAG_MODELS = ("sphere", "diag", "full")
_field = field  # MagCalibration has an attribute named field


@dataclass(frozen=True)
class MagCalibration:
    """Outcome of :func:`calib_jax.calibrate_mag`: y = W (raw - center), |y| = radius.

    ``status`` is "ok", "poorly_determined", "not_converged" or "failed" (as for
    :class:`AccelCalibration`). Errors are RMS of (|m| - radius) / radius in percent, before
    (raw data centred on its mean, radius its mean norm) and after calibration.
    """

    center: np.ndarray
    """Hard-iron offset (bias), raw units."""
    soft_iron: np.ndarray
    """W (3 x 3, symmetric): maps centred raw data onto the sphere of ``radius``."""
    radius: float
    """The field magnitude after calibration: ``field`` if given, else det(M)^(-1/6) in raw
    units (det W = 1)."""
    model: str
    status: str
    rms_before_pct: float
    rms_after_pct: float
    semi_axes: np.ndarray
    """Ellipsoid semi-axes in raw units, in the order of the columns of ``dcm``."""
    dcm: np.ndarray
    """R of paper 2 eq. 18: columns are the ellipsoid's axes in the sensor frame."""
    stderr_center: np.ndarray
    stderr_soft_iron: np.ndarray
    condition: float
    solver: str
    solver_status: int
    solver_message: str
    iterations: int
    n_samples: int
    coverage: float
    """Fraction of 100 equal-area cells of the sphere of directions holding data."""
    rms_raw_pct: float = float("nan")
    """RMS of (|m| - mean |m|) / mean |m| of the raw data, not centred: the error of data that
    was calibrated before (a centred 'before' penalises it for uneven coverage)."""
    field: float | None = None
    units: str | None = None
    sensor: str = "mag"
    model_selection: dict = _field(default_factory=dict)
    """Per candidate model: BIC and RMS radial error (percent of the RMS data radius)."""
    poorly_determined: list[str] = _field(default_factory=list)
    warnings: list[str] = _field(default_factory=list)
    sensor_id: str | None = None
    date: str = _field(
        default_factory=lambda: _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    )
    source: str | None = None
    format_version: int = FORMAT_VERSION

    @property
    def success(self) -> bool:
        return self.status in ("ok", "poorly_determined")

    def apply(self, raw: np.ndarray) -> np.ndarray:
        """Calibrated vectors W (raw - center), in host-side numpy; inside JAX use
        :func:`calib_jax.models.mag.compensate`."""
        return (np.asarray(raw, float) - self.center) @ self.soft_iron.T

    def report(self) -> str:
        unit = self.units or "raw units"
        c, sc = self.center, self.stderr_center
        mag = self.sensor == "mag"
        out = [
            f"model {self.model} on {self.n_samples} samples "
            f"({100 * self.coverage:.0f} % of the sphere of directions covered)",
            ("center (hard iron): " if mag else "center (bias): ")
            + ", ".join(f"{v:.6g} +- {e:.2g}" for v, e in zip(c, sc, strict=True))
            + f" {unit}",
            "soft iron W:" if mag else "gain and cross-axis matrix W:",
            *("  " + "  ".join(f"{v:+.6f}" for v in row) for row in self.soft_iron),
            "semi-axes: " + ", ".join(f"{v:.6g}" for v in self.semi_axes) + f" {unit}; "
            f"radius after {self.radius:.6g}"
            + (
                " (the given field magnitude, in its units)"
                if self.field is not None
                else f" {unit} (det W = 1)"
            ),
            f"RMS of (|m| - r)/r: before {self.rms_before_pct:.3f} % (centred on the data "
            f"mean; {self.rms_raw_pct:.3f} % uncentred), after {self.rms_after_pct:.3f} %",
            f"solver {self.solver}: {self.solver_message} ({self.iterations} iterations); "
            f"condition {self.condition:.3g}; status: {self.status}",
        ]
        if len(self.model_selection) > 1:
            out.append(
                "model choice (BIC, lower is better): "
                + ", ".join(
                    f"{m} {v['bic']:.1f} ({v['rms_pct']:.3f} %)"
                    for m, v in self.model_selection.items()
                )
            )
        out += [f"warning: {w}" for w in self.warnings]
        return "\n".join(out)

    def to_dict(self) -> dict:
        return _sanitize(
            {
                "format_version": self.format_version,
                "kind": "ellipsoid",
                "sensor": self.sensor,
                "model": self.model,
                "sensor_id": self.sensor_id,
                "date": self.date,
                "source": self.source,
                "units": self.units,
                "field": self.field,
                "center": np.asarray(self.center).tolist(),
                "soft_iron": np.asarray(self.soft_iron).tolist(),
                "radius": self.radius,
                "status": self.status,
                "rms_before_pct": self.rms_before_pct,
                "rms_after_pct": self.rms_after_pct,
                "rms_raw_pct": self.rms_raw_pct,
                "semi_axes": np.asarray(self.semi_axes).tolist(),
                "dcm": np.asarray(self.dcm).tolist(),
                "stderr": {
                    "center": np.asarray(self.stderr_center).tolist(),
                    "soft_iron": np.asarray(self.stderr_soft_iron).tolist(),
                },
                "condition": self.condition,
                "solver": self.solver,
                "solver_status": self.solver_status,
                "solver_message": self.solver_message,
                "iterations": self.iterations,
                "n_samples": self.n_samples,
                "coverage": self.coverage,
                "model_selection": self.model_selection,
                "poorly_determined": list(self.poorly_determined),
                "warnings": list(self.warnings),
            }
        )

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def from_dict(cls, d: dict) -> MagCalibration:
        _check_version(d)
        if d.get("kind") != "ellipsoid" or d.get("model") not in MAG_MODELS:
            raise ValueError(
                f"not an ellipsoid calibration (kind {d.get('kind')!r}, model "
                f"{d.get('model')!r}); load accelerometer files with AccelCalibration.load"
            )

        def arr(v):
            return np.array(v, dtype=float)

        return cls(
            center=arr(d["center"]),
            soft_iron=arr(d["soft_iron"]),
            radius=float(d["radius"]),
            model=d["model"],
            status=d["status"],
            rms_before_pct=float(d["rms_before_pct"]),
            rms_after_pct=float(d["rms_after_pct"]),
            rms_raw_pct=float(d.get("rms_raw_pct", "nan")),
            semi_axes=arr(d["semi_axes"]),
            dcm=arr(d["dcm"]),
            stderr_center=arr(d["stderr"]["center"]),
            stderr_soft_iron=arr(d["stderr"]["soft_iron"]),
            condition=float(d["condition"]),
            solver=d["solver"],
            solver_status=int(d["solver_status"]),
            solver_message=d["solver_message"],
            iterations=int(d["iterations"]),
            n_samples=int(d["n_samples"]),
            coverage=float(d["coverage"]),
            field=None if d.get("field") is None else float(d["field"]),
            units=d.get("units"),
            sensor=d.get("sensor", "mag"),
            model_selection=d.get("model_selection", {}),
            poorly_determined=list(d.get("poorly_determined", [])),
            warnings=list(d.get("warnings", [])),
            sensor_id=d.get("sensor_id"),
            date=d["date"],
            source=d.get("source"),
        )

    @classmethod
    def load(cls, path: str | Path) -> MagCalibration:
        return cls.from_dict(_read_json(path))
