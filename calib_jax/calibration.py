"""A fitted accelerometer calibration: the record users keep, apply and save.

Saved as versioned JSON (``format_version``), checked on load. Parameters are in input units
(gains and non-orthogonality: input units per output unit; bias: input units), so the same
file applies to new raw data from the same sensor: a = alpha^-1 (a' - beta).
"""

from __future__ import annotations

import contextlib
import dataclasses as _dc
import datetime as _dt
import errno
import json
import math
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import numpy as np

from .models.layout import ALPHA_INDEX, PARAM_NAMES
from .status import FIT_STATUSES, is_usable

FORMAT_VERSION = 1
MODELS = ("accel9", "accel6")


class OffScaleWarning(UserWarning):
    """Calibrated readings far from the calibration's magnitude: readings in another unit, or
    of another sensor (:func:`off_scale`); ``calib-jax apply`` exits 1 on it."""


class FitStatusWarning(UserWarning):
    """A calibration whose status is not ok. The result's ``status`` and ``warnings`` say the
    same, so the CLI, which prints them, leaves this one out; filter it the same way when you
    read the status yourself (``warnings.simplefilter("ignore", FitStatusWarning)``)."""


class Record:
    """What every result record shares (accel, ellipsoid, marg, batch, diagnosis): its
    ``kind`` (written in its JSON), an atomic :meth:`save`, a :meth:`load` whose errors name
    the file, a loader that refuses another kind by name, and ``==`` (not hashable: records
    hold arrays). Subclasses give ``kind``, ``what``, ``to_dict`` and ``from_dict(d, source)``.
    """

    kind: ClassVar[str]
    what: ClassVar[str]
    """How a refusal names the kind, e.g. "an accelerometer calibration"."""

    def save(self, path: str | Path) -> None:
        """Write the JSON atomically (:func:`write_json_atomic`): a full disk leaves the old
        file (or none), never a truncated one."""
        write_json_atomic(path, self.to_dict())

    @classmethod
    def load(cls, path: str | Path):
        """Read a saved record; a ValueError names the file, the key and the fault."""
        return cls.from_dict(_read_json(path), source=path)

    @classmethod
    def _check_kind(cls, d: dict, where: str, legacy: bool = True) -> None:
        """Refuse a file of another kind by name (``legacy``: files written before 'kind'
        was, which have none, are this kind)."""
        kind = d.get("kind", cls.kind if legacy else None)
        if kind != cls.kind:
            raise ValueError(
                f"{where}not {cls.what}: kind is {kind!r} (each kind loads with its class: "
                "AccelCalibration, MagCalibration, GyroCalibration, MARGRecord, BatchRecord, "
                "Diagnosis; calib_jax.export.read reads any calibration)"
            )

    def __eq__(self, other) -> bool:
        """Equal records write the same JSON, but for ``date`` (when the fit ran: two fits
        of one log a second apart were unequal) and ``source`` (how the log was named: a
        path as typed, or none for an array; the same log by the command line and by Python
        gave unequal records)."""
        if type(other) is not type(self):
            return NotImplemented
        return _without_provenance(self.to_dict()) == _without_provenance(other.to_dict())

    __hash__ = None  # type: ignore[assignment]


_PROVENANCE = ("date", "source")
"""Fields that say when a fit ran and how its log was named, not what it found: ``==`` on
records leaves them out."""


def _without_provenance(d):
    """A record's dict without its ``date`` and ``source`` keys, nested records' included (a
    MARG record holds its sensors' records, each with the second its fit ran)."""
    if isinstance(d, dict):
        return {k: _without_provenance(v) for k, v in d.items() if k not in _PROVENANCE}
    if isinstance(d, list):
        return [_without_provenance(v) for v in d]
    return d


def _utc_now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


@dataclass(frozen=True, eq=False, kw_only=True)
class SensorCalibration(Record):
    """What the one-sensor calibrations (accelerometer, ellipsoid, gyroscope) share after
    their own fields: what the fit could not pin down and what to act on, how the way in read
    the file, who and when; ``success`` from the status word and ``==`` field by field
    (arrays with numpy.array_equal, NaN equal to NaN), ``date`` left out: two fits of one log
    are equal whenever they ran. Keyword-only in the constructors."""

    poorly_determined: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    """Problems a user should act on (rows left out, saturation, coverage, conditioning)."""
    notes: list[str] = field(default_factory=list)
    """What the way in found and chose: how the file was read, the detector's setting and
    why (calib_jax.observations)."""
    sensor_id: str | None = None
    date: str = field(default_factory=_utc_now)
    source: str | None = None
    format_version: int = FORMAT_VERSION
    status: str
    """"ok", "poorly_determined", "not_converged" or "failed" (calib_jax.status)."""
    condition: float
    """Of the fit's normal matrix; NaN where the fit did not measure it."""
    solver: str
    solver_status: int
    solver_message: str
    iterations: int

    @property
    def success(self) -> bool:
        return is_usable(self.status)

    def _header(self) -> dict:
        """The JSON keys that open every sensor record: its version, kind and whose it is."""
        keys = ("format_version", "kind", "sensor_id", "date", "source")
        return {k: getattr(self, k) for k in keys}

    def _solver_dict(self) -> dict:
        """The JSON keys of the fit's outcome, the same in every sensor record."""
        keys = ("condition", "status", "solver", "solver_status", "solver_message", "iterations")
        return {k: getattr(self, k) for k in keys}

    def _findings(self) -> dict:
        """The JSON keys that close every sensor record: what to act on and what was chosen."""
        keys = ("poorly_determined", "warnings", "notes")
        return {k: list(getattr(self, k)) for k in keys}

    @classmethod
    def _open(cls, d: object, source, legacy: bool = False) -> tuple[_Doc, dict]:
        """Check a saved record's version and kind, and read the fields every sensor record
        has (:meth:`_header`, :meth:`_solver_dict`, :meth:`_findings`): the reader for the
        rest and those fields as keyword arguments."""
        r = _Doc(d, source)
        _check_version(r.d, r.where)
        cls._check_kind(r.d, r.where, legacy=legacy)
        shared = {
            "sensor_id": r.text("sensor_id", optional=True),
            "date": r.text("date"),
            "source": r.text("source", optional=True),
            "condition": r.num("condition", finite=False),
            "status": r.text("status"),
            "solver": r.text("solver"),
            "solver_status": r.integer("solver_status"),
            "solver_message": r.text("solver_message"),
            "iterations": r.integer("iterations"),
            **{k: r.strings(k) for k in ("poorly_determined", "warnings", "notes")},
        }
        return r, shared

    def __eq__(self, other) -> bool:
        return _fields_equal(self, other)

    __hash__ = None  # type: ignore[assignment]


def accel_output_units(units: str, output_units: str | None = None) -> str:
    """The calibrated accelerometer's unit: the one given, else g for counts (a unit sphere)
    and the input unit otherwise."""
    return output_units or ("g" if units == "counts" else units)


_FROM_PARAMS_NOTE = (
    "from parameters (from_params): no fit behind this record, so no standard errors, errors or "
    "checks of the data; status ok only means the parameters are finite and invertible"
)


def _from_params_outcome() -> dict:
    """The solver fields of a record made from parameters, with no fit behind it."""
    return {
        "condition": float("nan"),
        "status": "ok",
        "solver": "params",
        "solver_status": 0,
        "solver_message": "no fit: the record was made from parameters",
        "iterations": 0,
    }


def pipeline_outcome(fit, solver: str, finite: bool) -> dict:
    """The solver fields of a record made from a :mod:`calib_jax.pipeline` fit: its status
    word from the solver's code (``finite``: the parameters are finite) and no condition
    number (the pipeline does not measure it)."""
    from .status import fit_status, status_message

    code = int(fit.status)
    return {
        "condition": float("nan"),
        "status": fit_status(code, finite),
        "solver": solver,
        "solver_status": code,
        "solver_message": status_message(code),
        "iterations": int(fit.iterations),
    }


@dataclass(frozen=True, eq=False)
class AccelCalibration(SensorCalibration):
    """Outcome of :func:`calib_jax.calibrate_accel`.

    ``status`` is "ok", "poorly_determined" (converged, but some parameter is not pinned down
    by the poses: see ``poorly_determined`` and ``warnings``), "not_converged" or "failed".
    """

    kind: ClassVar[str] = "accel"
    what: ClassVar[str] = "an accelerometer calibration"
    params: np.ndarray
    """Paper 1's p = [alpha_x, alpha_y, alpha_z, S_xy, S_xz, S_yz, beta_x, beta_y, beta_z]."""
    stderr: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    input_units: str
    output_units: str
    g: float
    """Reference magnitude, in output units."""
    nfev: int
    use: str
    """'means' (interval means) or 'samples' (all static samples)."""
    n_intervals: int
    n_points: int
    """Points the fit used (interval means or samples)."""
    rms_before: float
    rms_after: float
    noise_floor: float
    static_means: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    """Raw means of the static intervals (n_intervals, 3), input units."""
    static_intervals: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), int))
    """Where the static intervals lie in the log, [start, stop) sample indices
    (n_intervals, 2); empty for a fit of given points. The gyroscope fit integrates between
    them (calib_jax.gyro)."""
    nominal_offset: np.ndarray = field(default_factory=lambda: np.zeros(3))
    nominal_scale: float = 1.0
    """The 'before' conversion (raw - nominal_offset) / nominal_scale, see calib_jax.accel."""
    model: str = "accel9"
    """'accel9' (paper 1) or 'accel6' (non-orthogonality held at zero)."""

    # ---- use -------------------------------------------------------------------------------
    @property
    def gains(self) -> np.ndarray:
        return self.params[0:3]

    @property
    def nonorth(self) -> np.ndarray:
        return self.params[3:6]

    @property
    def bias(self) -> np.ndarray:
        return self.params[6:9]

    def to_params(self):
        """The parameters as a JAX pytree (:class:`calib_jax.models.accel.AccelParams`), for
        use inside jitted pipelines (JAX is imported here, not when a file is read)."""
        import jax.numpy as jnp

        from .models.accel import AccelParams

        return AccelParams.from_vector(jnp.asarray(self.params))

    @classmethod
    def from_params(
        cls,
        params,
        *,
        g: float = 1.0,
        units: str = "g",
        output_units: str | None = None,
        sensor_id: str | None = None,
        source: str | None = None,
    ) -> AccelCalibration:
        """The record of parameters made or changed inside a JAX pipeline (an
        :class:`calib_jax.models.accel.AccelParams`, e.g. after a gradient step, or paper 1's
        9-vector), to save, report or export without a refit; :meth:`to_params` gives them
        back. ``g``, ``units`` and ``output_units`` as in :meth:`from_fit`. No fit stands
        behind it: standard errors, covariance and errors are NaN, the solver is 'params' and
        the status 'ok' says only that the gains are finite and invertible (a note says so; a
        ValueError otherwise, as on loading a file)."""
        _check_params_kind(params, "AccelParams", "AccelCalibration")
        vec = params.to_vector() if hasattr(params, "to_vector") else params
        p = np.array(vec, float).reshape(-1)
        if p.shape != (9,) or not np.all(np.isfinite(p)):
            raise ValueError(f"params must be 9 finite numbers (paper 1's order), got {p}")
        if not np.linalg.cond(p[ALPHA_INDEX]) < 1e12:
            raise ValueError("params give a singular gain matrix: no calibration inverts it")
        nan9 = np.full(9, np.nan)
        return cls(
            **_from_params_outcome(),
            params=p,
            stderr=nan9,
            covariance=np.full((9, 9), np.nan),
            correlation=np.full((9, 9), np.nan),
            input_units=units,
            output_units=accel_output_units(units, output_units),
            g=float(g),
            nfev=0,
            use="params",
            n_intervals=0,
            n_points=0,
            rms_before=float("nan"),
            rms_after=float("nan"),
            noise_floor=float("nan"),
            notes=[_FROM_PARAMS_NOTE],
            sensor_id=sensor_id,
            source=source,
        )

    @classmethod
    def from_fit(
        cls,
        fit,
        points,
        g: float,
        *,
        units: str = "g",
        output_units: str | None = None,
        sensor_id: str | None = None,
        source: str | None = None,
    ) -> AccelCalibration:
        """The record of a :func:`calib_jax.pipeline.fit_accel` result (one sensor), to save,
        report or export like a :func:`calib_jax.calibrate_accel` result. ``points`` are the
        (N, 3) readings it was fitted to, ``g`` the magnitude it was given, ``units`` the
        readings' unit and ``output_units`` the calibrated one (by default as
        :func:`calib_jax.calibrate_accel` has it: g for counts, else the input unit; the
        exports scale by it). The status is the solver's (the fit refuses too few rows, a
        sensor held still and poses in one plane), made "failed" where the gains are no
        accelerometer's (:func:`calib_jax.accel.implausible_gains`, the single fit's rule);
        there is no pose detection or coverage report (give ``calibrate_accel`` the log)."""
        p = np.asarray(fit.params.to_vector(), float)
        cov = np.asarray(fit.covariance, float)
        se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        with np.errstate(invalid="ignore", divide="ignore"):
            corr = cov / np.outer(se, se)
        from .accel import implausible_gains
        from .geometry import NO_SHELL
        from .status import Status

        x = _raw_vectors(points, "accel")
        if x.ndim != 2:
            raise ValueError(f"points must be the (N, 3) readings the fit was given, got {x.shape}")
        x = x[np.all(np.isfinite(x), axis=1)]  # the rows the fit used (it masks the others)
        a = apply_params(p, x)
        g = float(g)
        norm = np.linalg.norm(x, axis=1)
        outcome = pipeline_outcome(fit, "pipeline.fit_accel", bool(np.all(np.isfinite(p))))
        # the single fit's rule on the gains, in units of the points' scale (motion taken for
        # poses gave "converged" with gains of 7,978)
        # the data's scale: the points' RMS distance from the fitted offset, not from zero
        # (counts about 32768 would make every gain look tiny), as the single fit's fit_norm
        r = float(np.sqrt(np.mean(np.sum((x - p[6:9]) ** 2, axis=1)))) if len(x) else np.nan
        rms_after = float(np.sqrt(np.mean((np.linalg.norm(a, axis=1) / g - 1.0) ** 2)))
        usable = outcome["status"] in ("ok", "not_converged") and np.isfinite(rms_after)
        implausible = implausible_gains(p / np.concatenate([np.full(6, r / g), np.full(3, r)]))
        if usable and rms_after > NO_SHELL:  # a g the fit was not given (its gains look wrong)
            med = float(np.median(np.linalg.norm(a, axis=1)))
            implausible = (
                f"the calibrated points miss g = {g:g} by {rms_after:.3g} RMS (relative), "
                f"above {NO_SHELL:g} (their median |a| is {med:.4g}): give from_fit the "
                "magnitude the fit was given and the points it was fitted to; if you did, the "
                "parameters are no calibration of these points"
            )
        if implausible and outcome["status"] in ("ok", "not_converged"):
            outcome["status"] = "failed"
        return cls(
            **outcome,
            params=p,
            stderr=se,
            covariance=cov,
            correlation=corr,
            input_units=units,
            output_units=accel_output_units(units, output_units),
            g=g,
            nfev=0,
            use="points",
            n_intervals=0,
            n_points=len(x),
            rms_before=float(np.sqrt(np.mean((norm / norm.mean() - 1.0) ** 2))),
            rms_after=rms_after,
            noise_floor=float("nan"),
            # points that include motion are refused by the fit itself (NOT_AT_REST): said
            warnings=[implausible or outcome["solver_message"]]
            if implausible or int(fit.status) == Status.NOT_AT_REST
            else [],
            notes=[
                "from calib_jax.pipeline.fit_accel: no pose detection; the gains' plausibility "
                "checked, the coverage only as the fit does (one plane, one reading)"
            ],
            static_means=x,
            sensor_id=sensor_id,
            source=source,
        )

    def apply(self, raw) -> np.ndarray:
        """Calibrated acceleration in output units, a = alpha^-1 (raw - beta), for one
        reading (3,), many (N, 3), or a loaded log or a log's path (its ``acc`` columns; to
        write a corrected file, :func:`calib_jax.apply.apply_calibration`)."""
        warn_if_unusable(self.status, self.what, self.source)
        a = apply_params(self.params, _raw_vectors(raw, "accel"))
        _warn_if_off_scale(a, self.g, f"{self.input_units} (this accelerometer's input)", "g")
        return a

    # ---- report ----------------------------------------------------------------------------
    def __repr__(self) -> str:
        from .display import accel_repr

        return accel_repr(self)

    def _repr_html_(self) -> str:
        from .display import accel_html

        return accel_html(self)

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

    def _improvement(self) -> str:
        """The headline after the errors: how much lower, unless that says nothing (a fit that
        did not converge, or one with no more fit points than parameters)."""
        if self.status == "failed":  # the solver may have converged: its own words mislead
            return "no calibration: the fit failed (the warnings say why)"
        if not is_usable(self.status):
            return f"no calibration: the fit is {self.status.replace('_', ' ')}"
        n_free = 6 if self.model == "accel6" else 9
        if self.n_points <= n_free:
            return (
                f"an exact fit ({self.n_points} fit points for {n_free} parameters): nothing "
                "is left over to judge it or its standard errors by"
            )
        return f"{self.rms_before / max(self.rms_after, 1e-300):.0f}x lower"

    def _floor_words(self) -> str:
        if np.isfinite(self.noise_floor):
            return f"noise floor {self.noise_floor:.3e}"
        return "noise floor unknown: one sample per pose, no scatter to measure it by"

    def report(self) -> str:
        """Table, error before and after, status and warnings, as printed by the CLI."""
        out = [
            self.table(),
            "",
            f"fit on {self.n_points} {self.use} from {self.n_intervals} static intervals; "
            f"solver {self.solver}: {self.solver_message} ({self.iterations} iterations, "
            f"{self.nfev} evaluations)",
            f"RMS of (|a| - g)/g over interval means: before {self.rms_before:.3e}, "
            f"after {self.rms_after:.3e} ({self._floor_words()}); " + self._improvement(),
            f"condition number {self.condition:.3g}; status: {self.status}",
        ]
        if self.poorly_determined:
            out.append("poorly determined: " + ", ".join(self.poorly_determined))
        out += [f"note: {n}" for n in self.notes]
        out += [f"warning: {w}" for w in self.warnings]
        return "\n".join(out)

    # ---- JSON ------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        p, s = self.params, self.stderr
        d = {
            **self._header(),
            "model": self.model,
            "units": {"input": self.input_units, "output": self.output_units, "g": self.g},
            "params": split_params(p),
            "stderr": split_params(s),
            **linear_forms(forward=np.asarray(p)[ALPHA_INDEX], offset=self.bias),
            "covariance": self.covariance.tolist(),
            "correlation": self.correlation.tolist(),
            **self._solver_dict(),
            "nfev": self.nfev,
            "use": self.use,
            "n_intervals": self.n_intervals,
            "n_points": self.n_points,
            "rms_before": self.rms_before,
            "rms_after": self.rms_after,
            "noise_floor": self.noise_floor,
            **self._findings(),
            "static_means": np.asarray(self.static_means).tolist(),
            "static_intervals": np.asarray(self.static_intervals, int).tolist(),
            "nominal": {
                "offset": np.asarray(self.nominal_offset).tolist(),
                "scale": self.nominal_scale,
            },
        }
        # the JSON standard has no inf/nan: write them as strings, read back by float()
        return _sanitize(d)

    @classmethod
    def from_dict(cls, d: object, source: str | Path | None = None) -> AccelCalibration:
        """Rebuild from :meth:`to_dict`'s layout, validated: a ValueError names ``source``
        (the file), the key and what is wrong (missing, not a number, non-finite, a zero
        gain, a singular gain matrix, a non-positive g)."""
        r, shared = cls._open(d, source, legacy=True)
        if r.d.get("model") not in MODELS:
            raise ValueError(
                f"{r.where}not an accelerometer calibration: model is {r.d.get('model')!r}"
            )

        def vec(block, finite):
            return np.concatenate(
                [r.arr(f"{block}.{k}", (3,), finite=finite) for k in ("gains", "nonorth", "bias")]
            )

        params = vec("params", True)
        for i in np.flatnonzero(params[0:3] == 0):
            raise ValueError(
                f"{r.where}key 'params.gains[{i}]' is 0: a zero gain cannot be inverted"
            )
        alpha = params[ALPHA_INDEX]
        if not np.linalg.cond(alpha) < 1e12:
            raise ValueError(
                f"{r.where}keys 'params.gains'/'params.nonorth' give a singular gain matrix "
                f"(condition number {np.linalg.cond(alpha):.3g}); refit the calibration"
            )
        return cls(
            **shared,
            params=params,
            stderr=vec("stderr", False),
            covariance=r.arr("covariance", (9, 9), finite=False),
            correlation=r.arr("correlation", (9, 9), finite=False),
            input_units=r.text("units.input"),
            output_units=r.text("units.output"),
            g=r.num("units.g", positive=True),
            nfev=r.integer("nfev"),
            use=r.text("use"),
            n_intervals=r.integer("n_intervals"),
            n_points=r.integer("n_points"),
            rms_before=r.num("rms_before", finite=False),
            rms_after=r.num("rms_after", finite=False),
            noise_floor=r.num("noise_floor", finite=False),
            static_means=r.arr("static_means", (-1, 3), default=[], finite=False),
            static_intervals=r.arr("static_intervals", (-1, 2), default=[]).astype(int),
            nominal_offset=r.arr("nominal.offset", (3,), default=[0.0, 0.0, 0.0]),
            nominal_scale=r.num("nominal.scale", default=1.0, positive=True),
            model=r.d["model"],
        )


def linear_forms(*, offset, forward=None, correction=None) -> dict:
    """Both forms of a sensor's linear model, as every calibration JSON writes them (one
    convention for all sensors): ``forward`` maps the true vector to the raw reading,
    raw = A y + b; ``correction`` maps it back, y = C (raw - b), C = A^-1. Give one matrix;
    the other is its inverse. Written for other programs to read; the loaders read the
    parameters they were fitted as (alpha and beta, or the centre and W)."""
    A = np.linalg.inv(correction) if forward is None else np.asarray(forward, float)
    C = np.linalg.inv(forward) if correction is None else np.asarray(correction, float)
    b = np.asarray(offset, float).tolist()
    return {
        "forward": {"matrix": A.tolist(), "offset": b, "model": "raw = matrix @ true + offset"},
        "correction": {
            "matrix": C.tolist(),
            "offset": b,
            "model": "true = matrix @ (raw - offset)",
        },
    }


def split_params(p: np.ndarray) -> dict:
    """Paper 1's nine-vector as the JSON's {gains, nonorth, bias} lists."""
    p = np.asarray(p)
    return {"gains": p[0:3].tolist(), "nonorth": p[3:6].tolist(), "bias": p[6:9].tolist()}


def ellipsoid_axes(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(semi-axes, R) of the ellipsoid (x - c)' M (x - c) = 1: R's columns are its axes (a
    rotation, det +1; paper 2 eq. 18), semi-axes 1 / sqrt(eigenvalues) in their order. NaN
    for a non-finite M (a failed solve: eigh would raise) and for an eigenvalue <= 0."""
    M = np.asarray(M, float)
    if not np.all(np.isfinite(M)):
        return np.full(3, np.nan), np.full((3, 3), np.nan)
    evals, R = np.linalg.eigh(M)
    if np.linalg.det(R) < 0:
        R[:, 0] = -R[:, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        return 1.0 / np.sqrt(evals), R


def apply_params(params: np.ndarray, raw: np.ndarray) -> np.ndarray:
    """a = alpha^-1 (raw - beta) in host-side numpy (no per-shape compilation; inside JAX use
    ``models.accel.correct``)."""
    params = np.asarray(params)
    return (raw - params[6:9]) @ np.linalg.inv(params[ALPHA_INDEX]).T


class _Token:
    """A bare NaN / Infinity / -Infinity in a JSON file (Python's json accepts them; the JSON
    standard does not, and :meth:`AccelCalibration.to_dict` writes them as strings)."""

    def __init__(self, name: str) -> None:
        self.name = name


def _find_token(o, key: str = "") -> tuple[str, str] | None:
    if isinstance(o, _Token):
        return key, o.name
    if isinstance(o, dict):
        items = ((f"{key}.{k}" if key else str(k), v) for k, v in o.items())
    elif isinstance(o, list):
        items = ((f"{key}[{i}]", v) for i, v in enumerate(o))
    else:
        return None
    for k, v in items:
        hit = _find_token(v, k)
        if hit is not None:
            return hit
    return None


def _read_json(path: str | Path) -> object:
    try:
        d = json.loads(Path(path).read_text(), parse_constant=_Token)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path} is not a calibration JSON file: {exc}") from exc
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path} is not a calibration JSON file (not UTF-8 text): {exc}") from exc
    hit = _find_token(d)
    if hit is not None:
        raise ValueError(
            f"{path}: key {hit[0]!r} holds the non-standard JSON token {hit[1]} (not a number "
            "calib_jax writes); the file was edited or written by another program: refit or "
            "correct the value"
        )
    return d


_MISSING = object()


class _Doc:
    """Typed, validated access to a calibration dict; errors name the file and the key."""

    def __init__(self, d, source) -> None:
        self.where = f"{source}: " if source is not None else ""
        if not isinstance(d, dict):
            raise ValueError(
                f"{self.where}a calibration file holds a JSON object, got a {type(d).__name__}"
            )
        self.d = d

    def get(self, key: str, default=_MISSING):
        o = self.d
        for part in key.split("."):
            if not isinstance(o, dict) or part not in o:
                if default is not _MISSING:
                    return default
                raise ValueError(f"{self.where}key {key!r} is missing")
            o = o[part]
        return o

    def num(self, key, *, finite=True, positive=False, default=_MISSING) -> float:
        v = self.get(key, default)
        if isinstance(v, bool) or not isinstance(v, int | float | str):
            raise ValueError(f"{self.where}key {key!r} must be a number, got {v!r}")
        try:
            x = float(v)
        except ValueError:
            raise ValueError(f"{self.where}key {key!r} must be a number, got {v!r}") from None
        if (finite or positive) and not math.isfinite(x):
            raise ValueError(f"{self.where}key {key!r} must be finite, got {v!r}")
        if positive and not x > 0:
            raise ValueError(f"{self.where}key {key!r} must be positive, got {v!r}")
        return x

    def integer(self, key) -> int:
        x = self.num(key)
        if x != int(x):
            raise ValueError(f"{self.where}key {key!r} must be an integer, got {x!r}")
        return int(x)

    def text(self, key, optional=False) -> str | None:
        v = self.get(key, None if optional else _MISSING)
        if v is None and optional:
            return None
        if not isinstance(v, str):
            raise ValueError(f"{self.where}key {key!r} must be a string, got {v!r}")
        return v

    def strings(self, key) -> list[str]:
        v = self.get(key, [])
        if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
            raise ValueError(f"{self.where}key {key!r} must be a list of strings, got {v!r}")
        return list(v)

    def arr(self, key, shape, *, finite=True, default=_MISSING) -> np.ndarray:
        v = self.get(key, default)
        try:
            a = np.array(v, dtype=float)
        except (ValueError, TypeError):
            raise ValueError(f"{self.where}key {key!r} must hold numbers, got {v!r}") from None
        if shape[0] == -1 and a.size == 0:
            a = a.reshape(0, *shape[1:])
        ok = a.ndim == len(shape) and all(s in (-1, n) for s, n in zip(shape, a.shape, strict=True))
        if not ok:
            want = "x".join("N" if s == -1 else str(s) for s in shape)
            raise ValueError(f"{self.where}key {key!r} must be {want} numbers, got shape {a.shape}")
        if finite and not np.all(np.isfinite(a)):
            bad = np.argwhere(~np.isfinite(a))[0]
            raise ValueError(
                f"{self.where}key {key!r} holds {a[tuple(bad)]} at {list(map(int, bad))}: "
                "the parameters must be finite"
            )
        return a

    def invertible(self, key: str) -> np.ndarray:
        """A finite 3 x 3 matrix that can be inverted (a correction or shape matrix)."""
        m = self.arr(key, (3, 3))
        if not np.linalg.cond(m) < 1e12:
            raise ValueError(
                f"{self.where}key {key!r} is a singular matrix (condition number "
                f"{np.linalg.cond(m):.3g}): it would map every reading onto a plane; refit"
            )
        return m


APPLY_SCALE = (0.5, 2.0)
"""Calibrated readings whose median magnitude is outside this range of the expected one (g,
the field) were not in the calibration's input units: an Xsens record (counts) applied to a
log in g gave |a| about 13.9 g on every row, written without a word."""


def off_scale(y: np.ndarray, expected: float, units: str, what: str) -> str | None:
    """Why 10 or more calibrated readings ``y`` are not in the calibration's input units (a
    median magnitude outside :data:`APPLY_SCALE` of ``expected``; ``what``: "g" or "the
    field"), None when they may be: the rule of ``apply`` on arrays and on files."""
    y = np.asarray(y)
    if y.ndim != 2 or len(y) < 10 or not np.isfinite(expected) or expected <= 0:
        return None
    n = np.linalg.norm(y, axis=1)
    med = float(np.median(n[np.isfinite(n)])) if np.isfinite(n).any() else float("nan")
    lo, hi = APPLY_SCALE
    if not np.isfinite(med) or lo * expected <= med <= hi * expected:
        return None
    return (
        f"calibrated, these readings have a median magnitude of {med:.4g}, where {what} is "
        f"{expected:.4g}: they are not in {units}, or not from this sensor; check their unit "
        "and columns against the calibration's"
    )


def _warn_if_off_scale(y: np.ndarray, expected: float, units: str, what: str) -> None:
    """A UserWarning with :func:`off_scale`'s finding, if any."""
    why = off_scale(y, expected, units, what)
    if why:
        import warnings

        warnings.warn(why, OffScaleWarning, stacklevel=3)


def warn_if_unusable(status: str | None, what: str, source: str | None = None) -> None:
    """A :class:`FitStatusWarning` where a calibration whose status is "failed" or
    "not_converged" is used (applied, exported): a Python user's trial applied and exported
    a failed record (gains 461, 1826 and 69) without a word, where the command line warns."""
    if status in (None, "ok", "poorly_determined"):
        return
    import warnings

    warnings.warn(
        f"using {what} whose status is {status!r} (from {source or 'an unnamed log'}): it is "
        "no calibration; its warnings say why",
        FitStatusWarning,
        stacklevel=3,
    )


def _check_params_kind(params, wanted: str, record: str) -> None:
    """A ValueError for a pipeline Fit, or another sensor's parameters, given to a
    ``from_params`` (they were float()'s TypeError)."""
    kind = type(params).__name__
    if kind == "Fit":
        raise ValueError(
            f"{record}.from_params takes the parameters; a pipeline Fit becomes a record with "
            f"{record}.from_fit(fit, points, ...), or give fit.params"
        )
    if kind.endswith("Params") and kind != wanted:
        raise ValueError(f"{record}.from_params takes {wanted}, got {kind} (another sensor's)")


def _raw_vectors(raw, sensor: str) -> np.ndarray:
    """(3,) or (N, 3) float array from an array, or the ``sensor`` columns of a loaded log or
    of a log file (read with :func:`calib_jax.load_log`)."""
    from .io.files import SensorLog, load_log

    if "Tracer" in type(raw).__name__:  # jax.jit(cal.apply): TracerArrayConversionError
        raise TypeError(
            f"{sensor} calibration's apply works on host arrays (numpy); inside jit, grad or "
            "vmap use calib_jax.pipeline.apply(cal.to_params(), raw)"
        )
    if isinstance(raw, (str, os.PathLike)):  # was "could not convert string to float"
        raw = load_log(raw, sensor=sensor)
    x = raw.vectors(sensor) if isinstance(raw, SensorLog) else np.asarray(raw, float)
    if x.ndim not in (1, 2) or x.shape[-1] != 3:
        raise ValueError(
            f"raw must be one reading (3,) or many (N, 3), columns x, y, z; got shape {x.shape}"
            + (" (transposed? pass raw.T)" if x.ndim == 2 and x.shape[0] == 3 else "")
        )
    return x


def _value_equal(x, y) -> bool:
    if isinstance(x, np.ndarray | np.generic) or isinstance(y, np.ndarray | np.generic):
        x, y = np.asarray(x), np.asarray(y)
        nan_ok = x.dtype.kind in "fc" and y.dtype.kind in "fc"
        return x.shape == y.shape and bool(np.array_equal(x, y, equal_nan=nan_ok))
    if isinstance(x, dict) and isinstance(y, dict):
        return x.keys() == y.keys() and all(_value_equal(x[k], y[k]) for k in x)
    if isinstance(x, list | tuple) and isinstance(y, list | tuple):
        return len(x) == len(y) and all(_value_equal(a, b) for a, b in zip(x, y, strict=True))
    if isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y):
        return True
    return bool(x == y)


def _selection_flag(v: dict) -> str:
    """Why a candidate magnetometer model could not be chosen, for the BIC line."""
    if not v.get("usable", True):
        return "; not converged or ran away"
    if not v.get("well_determined", True):
        return "; not determined"
    return ""


def _fields_equal(a, b):
    if type(a) is not type(b):
        return NotImplemented
    return all(
        _value_equal(getattr(a, f.name), getattr(b, f.name))
        for f in _dc.fields(a)
        if f.name not in _PROVENANCE
    )


@contextlib.contextmanager
def atomic_write(path: str | Path, suffix: str = ".tmp", newline: str | None = None):
    """A text file to write that appears at ``path`` only when the block ends without an
    error: a temporary file in the same folder, fsynced, then ``os.replace``. It gets the old
    file's mode, else 0644 (mkstemp makes 0600: an applied log came out unreadable to the
    user's group). On an error (a full disk: OSError ENOSPC) the temporary file is removed and
    the error re-raised; ``path`` keeps its old content, or stays absent, never a truncated
    file."""
    path = Path(path).expanduser()  # '~/cal.json' named a folder '~' (a trial)
    if not path.parent.is_dir():  # the temporary file's name was the error's (a trial)
        raise FileNotFoundError(
            errno.ENOENT, f"cannot write {path}: its folder {path.parent} does not exist"
        )
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent or ".")
    try:
        if hasattr(os, "fchmod"):
            os.fchmod(fd, path.stat().st_mode & 0o777 if path.exists() else 0o644)
        with os.fdopen(fd, "w", encoding="utf-8", newline=newline) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def write_json_atomic(path: str | Path, obj) -> None:
    """Write ``obj`` as JSON to ``path`` atomically (:func:`atomic_write`)."""
    text = json.dumps(obj, indent=2) + "\n"
    with atomic_write(path) as f:
        f.write(text)


def _check_version(d: dict, where: str = "") -> None:
    version = d.get("format_version")
    if version is None and "kind" not in d:  # not ours at all: no 'upgrade calib_jax' advice
        keys = ", ".join(list(d)[:6]) or "none"
        raise ValueError(
            f"{where}not a calib_jax calibration (no 'format_version' or 'kind'; its keys: "
            f"{keys}); calib_jax.export.read reads imucal, imu_tk and ROS files"
        )
    if version != FORMAT_VERSION:
        raise ValueError(
            f"{where}calibration format_version {version!r} is not supported (this calib_jax "
            f"reads version {FORMAT_VERSION}); refit with this version or upgrade calib_jax"
        )


def _unsanitize(o):
    """Inverse of :func:`_sanitize` for free-form blocks: 'nan', 'inf', '-inf' back to float."""
    if isinstance(o, dict):
        return {k: _unsanitize(v) for k, v in o.items()}
    if isinstance(o, list):
        return [_unsanitize(v) for v in o]
    if isinstance(o, str) and o in ("nan", "inf", "-inf"):
        return float(o)
    return o


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


HONEST_METHOD = "block jackknife over contiguous stretches of the log"
"""How the honest standard errors of a magnetometer's calibration were found (JSON and report)."""


@dataclass(frozen=True, eq=False)
class MagCalibration(SensorCalibration):
    """Outcome of :func:`calib_jax.calibrate_mag`: y = W (raw - center), |y| = radius.

    ``status`` is "ok", "poorly_determined", "not_converged" or "failed" (as for
    :class:`AccelCalibration`; see :func:`calib_jax.calibrate_mag` for the plausibility
    checks behind them). Errors are RMS of (|m| - radius) / radius in percent, before
    (raw data centred on its mean, radius its mean norm) and after calibration.
    """

    kind: ClassVar[str] = "ellipsoid"
    what: ClassVar[str] = "an ellipsoid calibration"
    center: np.ndarray
    """Hard-iron offset (bias), raw units."""
    soft_iron: np.ndarray
    """W (3 x 3, symmetric): maps centred raw data onto the sphere of ``radius``."""
    radius: float
    """The field magnitude after calibration: ``field`` if given, else det(M)^(-1/6) in raw
    units (det W = 1)."""
    model: str
    rms_before_pct: float
    rms_after_pct: float
    semi_axes: np.ndarray
    """Ellipsoid semi-axes in raw units, in the order of the columns of ``dcm``."""
    dcm: np.ndarray
    """R of paper 2 eq. 18: columns are the ellipsoid's axes in the sensor frame."""
    stderr_center: np.ndarray
    stderr_soft_iron: np.ndarray
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
    """Per candidate model: BIC and the RMS of |W (x - c)| / radius - 1 in percent."""
    stderr_center_honest: np.ndarray = _field(default_factory=lambda: np.full(3, np.nan))
    """The centre's standard errors from a block jackknife over contiguous stretches of the
    log (:func:`calib_jax.mag.honest_stderr`): honest where the samples are correlated, as a
    tumble's are; ``stderr_center`` assumes independent samples. NaN: not measured."""
    stderr_soft_iron_honest: np.ndarray = _field(default_factory=lambda: np.full((3, 3), np.nan))
    """W's, the same way."""

    @property
    def honest(self) -> bool:
        """Whether the honest (block jackknife) standard errors were measured."""
        return bool(np.all(np.isfinite(self.stderr_center_honest)))

    @property
    def center_stderr(self) -> np.ndarray:
        """The centre's standard errors to quote: the honest ones where measured, else the
        formal ones (on CK-Explorer's tumble the honest are 14-22x the formal)."""
        return self.stderr_center_honest if self.honest else self.stderr_center

    def apply(self, raw) -> np.ndarray:
        """Calibrated vectors W (raw - center) for one reading (3,), many (N, 3), or a loaded
        log or a log's path (its ``mag`` columns, ``acc`` for an accelerometer fit), in
        host-side numpy; inside JAX use
        :func:`calib_jax.models.mag.compensate`."""
        warn_if_unusable(self.status, self.what, self.source)
        x = _raw_vectors(raw, self.sensor)
        y = (x - self.center) @ self.soft_iron.T
        what = "g" if self.sensor == "accel" else "the field"
        _warn_if_off_scale(y, self.radius, f"{self.units or 'the units'} of the fitted log", what)
        return y

    def to_params(self):
        """The calibration as a JAX pytree, :class:`calib_jax.pipeline.MagParams` (c, W) with
        the same ``apply``, for use inside jitted pipelines (JAX is imported here, not when a
        file is read)."""
        import jax.numpy as jnp

        from .pipeline import MagParams

        return MagParams(hard_iron=jnp.asarray(self.center), soft_iron=jnp.asarray(self.soft_iron))

    @classmethod
    def from_params(
        cls,
        params,
        *,
        field: float = 1.0,
        model: str = "full",
        units: str | None = None,
        sensor: str = "mag",
        sensor_id: str | None = None,
        source: str | None = None,
    ) -> MagCalibration:
        """The record of a :class:`calib_jax.pipeline.MagParams` (c, W) made or changed inside
        a JAX pipeline, to save, report or export without a refit; :meth:`to_params` gives it
        back. ``field``: the magnitude W maps onto (the pipeline's default 1; a
        :func:`calibrate_mag` record's ``radius``). No fit stands behind it: standard errors
        and errors are NaN, the solver 'params', the status 'ok' only says W is finite and
        invertible (a note says so; a ValueError otherwise)."""
        _check_params_kind(params, "MagParams", "MagCalibration")
        c = np.array(params.hard_iron, float).reshape(-1)
        W = np.array(params.soft_iron, float)
        if c.shape != (3,) or W.shape != (3, 3) or not np.all(np.isfinite(W)):
            raise ValueError("params must hold a finite centre (3,) and soft iron W (3, 3)")
        if not np.all(np.isfinite(c)) or not np.linalg.cond(W) < 1e12:
            raise ValueError("params give a non-finite centre or a singular W: no calibration")
        radius = float(field)
        axes, R = ellipsoid_axes(W.T @ W / radius**2)
        return cls(
            **_from_params_outcome(),
            center=c,
            soft_iron=W,
            radius=radius,
            model=model,
            rms_before_pct=float("nan"),
            rms_after_pct=float("nan"),
            semi_axes=axes,
            dcm=R,
            stderr_center=np.full(3, np.nan),
            stderr_soft_iron=np.full((3, 3), np.nan),
            n_samples=0,
            coverage=float("nan"),
            field=radius,
            units=units,
            sensor=sensor,
            notes=[_FROM_PARAMS_NOTE],
            sensor_id=sensor_id,
            source=source,
        )

    @classmethod
    def from_fit(
        cls,
        fit,
        raw,
        field: float,
        *,
        model: str = "full",
        units: str | None = None,
        sensor: str = "mag",
        sensor_id: str | None = None,
        source: str | None = None,
    ) -> MagCalibration:
        """The record of a :func:`calib_jax.pipeline.fit_mag` result (one sensor), to save,
        report or export like a :func:`calib_jax.calibrate_mag` result: ``raw`` the (N, 3)
        samples it was fitted to, ``field`` and ``model`` the magnitude and model it was given.
        The status is the solver's, after the pipeline's own checks (too few rows, one plane,
        no shell, a fit that ran away); there is no coverage report (a note says so)."""
        from .sphere import sphere_coverage

        c = np.asarray(fit.params.hard_iron, float)
        W = np.asarray(fit.params.soft_iron, float)
        se = np.sqrt(np.clip(np.diag(np.asarray(fit.covariance, float)), 0.0, None))
        x = _raw_vectors(raw, sensor)
        if x.ndim != 2:
            raise ValueError(f"raw must be the (N, 3) samples the fit was given, got {x.shape}")
        y = (x - c) @ W.T
        r_y = np.linalg.norm(y, axis=1)
        radius = float(field)
        ok = bool(np.all(np.isfinite(W)))
        axes, R = ellipsoid_axes(W.T @ W / radius**2)
        cover = sphere_coverage(y / r_y[:, None])[0] if ok else 0.0
        r0 = np.linalg.norm(x - x.mean(axis=0), axis=1)
        nr = np.linalg.norm(x, axis=1)
        pct = lambda e: float(100 * np.sqrt(np.mean(e**2)))  # noqa: E731
        return cls(
            **pipeline_outcome(fit, "pipeline.fit_mag", ok),
            center=c,
            soft_iron=W,
            radius=radius,
            model=model,
            rms_before_pct=pct(r0 / r0.mean() - 1.0),
            rms_after_pct=pct(r_y / radius - 1.0),
            semi_axes=axes,
            dcm=R,
            stderr_center=se[:3],
            stderr_soft_iron=se[3:].reshape(3, 3),
            n_samples=len(x),
            coverage=float(cover),
            rms_raw_pct=pct(nr / nr.mean() - 1.0),
            field=radius,
            units=units,
            sensor=sensor,
            notes=["from calib_jax.pipeline.fit_mag: no coverage or plausibility checks"],
            sensor_id=sensor_id,
            source=source,
        )

    def __repr__(self) -> str:
        from .display import mag_repr

        return mag_repr(self)

    def _repr_html_(self) -> str:
        from .display import mag_html

        return mag_html(self)

    def _uncentred(self) -> str:
        """The uncentred 'before' for the report, where it means something (the fair figure
        for data calibrated already). With a hard iron many times the field, |raw| varies by
        about r / |c| of the offset's length whatever the calibration (a phone's 585 against a
        45 uT field: 3.95 % 'before', 5.3 % after, which a new user read as the fit making it
        worse); beyond three times the field the centred figure stands alone."""
        r = float(np.mean(self.semi_axes))
        if np.isfinite(r) and float(np.linalg.norm(self.center)) > 3 * r:
            return ""
        return f"; {self.rms_raw_pct:.3f} % uncentred"

    def _unit_by_size(self) -> str:
        """Where no unit was given, the one a magnetometer's radius says: Earth's field is
        25-65 uT, 0.25-0.65 gauss, 250-650 mG (a trial read 'radius after 0.532 raw
        units' of a gauss log)."""
        if self.units or not self.sensor == "mag" or not np.isfinite(self.radius):
            return ""
        for lo, unit in ((0.25, "gauss"), (25.0, "uT"), (250.0, "mG")):
            if 0.8 * lo <= self.radius <= 1.2 * 2.6 * lo:
                return f"; Earth's field in {unit}, by its size"
        return ""

    def report(self) -> str:
        unit = self.units or "raw units"
        c, sc = self.center, self.stderr_center
        mag = self.sensor == "mag"
        out = [
            f"model {self.model} on {self.n_samples} samples "
            + (
                f"({100 * self.coverage:.0f} % of the sphere of directions covered)"
                if np.isfinite(self.coverage)
                else "(coverage not measured: no shell to measure it on)"
            ),
            ("center (hard iron): " if mag else "center (bias): ")
            + ", ".join(f"{v:.6g} +- {e:.2g}" for v, e in zip(c, self.center_stderr, strict=True))
            + f" {unit}"
            + (
                f" ({HONEST_METHOD}; formal +- " + ", ".join(f"{e:.2g}" for e in sc) + ")"
                if self.honest
                else ""
            ),
            "soft iron W:" if mag else "gain and cross-axis matrix W:",
            *("  " + "  ".join(f"{v:+.6f}" for v in row) for row in self.soft_iron),
            "semi-axes: " + ", ".join(f"{v:.6g}" for v in self.semi_axes) + f" {unit}; "
            f"radius after {self.radius:.6g}"
            + (
                " (the given field magnitude, in its units)"
                if self.field is not None
                else f" {unit} (det W = 1{self._unit_by_size()})"
            ),
            f"RMS of (|m| - r)/r: before {self.rms_before_pct:.3f} % (centred on the data "
            f"mean{self._uncentred()}), after {self.rms_after_pct:.3f} %",
            f"solver {self.solver}: {self.solver_message} ({self.iterations} iterations); "
            f"condition {self.condition:.3g}; status: {self.status}",
        ]
        if len(self.model_selection) > 1:
            out.append(
                "model choice (BIC, lower is better, among the models the data determine, else "
                "the sphere): "
                + ", ".join(
                    f"{m} {v['bic']:.1f} ({v['rms_pct']:.3f} %{_selection_flag(v)})"
                    for m, v in self.model_selection.items()
                )
            )
        out += [f"note: {n}" for n in self.notes]
        out += [f"warning: {w}" for w in self.warnings]
        return "\n".join(out)

    def to_dict(self) -> dict:
        return _sanitize(
            {
                **self._header(),
                "sensor": self.sensor,
                "model": self.model,
                "units": self.units,
                "field": self.field,
                "center": np.asarray(self.center).tolist(),
                "soft_iron": np.asarray(self.soft_iron).tolist(),
                **linear_forms(correction=self.soft_iron, offset=self.center),
                "radius": self.radius,
                "rms_before_pct": self.rms_before_pct,
                "rms_after_pct": self.rms_after_pct,
                "rms_raw_pct": self.rms_raw_pct,
                "semi_axes": np.asarray(self.semi_axes).tolist(),
                "dcm": np.asarray(self.dcm).tolist(),
                "stderr": {
                    "center": np.asarray(self.stderr_center).tolist(),
                    "soft_iron": np.asarray(self.stderr_soft_iron).tolist(),
                    "honest": {
                        "method": HONEST_METHOD,
                        "center": np.asarray(self.stderr_center_honest).tolist(),
                        "soft_iron": np.asarray(self.stderr_soft_iron_honest).tolist(),
                    },
                },
                **self._solver_dict(),
                "n_samples": self.n_samples,
                "coverage": self.coverage,
                "model_selection": self.model_selection,
                **self._findings(),
            }
        )

    @classmethod
    def from_dict(cls, d: object, source: str | Path | None = None) -> MagCalibration:
        """Rebuild from :meth:`to_dict`'s layout, validated as :meth:`AccelCalibration.from_dict`
        (centre and W finite, W invertible, radius and field positive)."""
        r, shared = cls._open(d, source)
        if r.d.get("model") not in MAG_MODELS:
            raise ValueError(
                f"{r.where}not an ellipsoid calibration: model is {r.d.get('model')!r}, not one "
                f"of {MAG_MODELS}"
            )
        W = r.invertible("soft_iron")
        nan3, nan33 = [np.nan] * 3, [[np.nan] * 3] * 3
        ms = r.get("model_selection", {})
        if not isinstance(ms, dict):
            raise ValueError(f"{r.where}key 'model_selection' must be an object, got {ms!r}")
        return cls(
            **shared,
            center=r.arr("center", (3,)),
            soft_iron=W,
            radius=r.num("radius", positive=True),
            model=r.d["model"],
            rms_before_pct=r.num("rms_before_pct", finite=False),
            rms_after_pct=r.num("rms_after_pct", finite=False),
            rms_raw_pct=r.num("rms_raw_pct", finite=False, default="nan"),
            semi_axes=r.arr("semi_axes", (3,), finite=False),
            dcm=r.arr("dcm", (3, 3), finite=False),
            stderr_center=r.arr("stderr.center", (3,), finite=False),
            stderr_soft_iron=r.arr("stderr.soft_iron", (3, 3), finite=False),
            # files written before the honest errors were have none: NaN, not measured
            stderr_center_honest=r.arr("stderr.honest.center", (3,), finite=False, default=nan3),
            stderr_soft_iron_honest=r.arr(
                "stderr.honest.soft_iron", (3, 3), finite=False, default=nan33
            ),
            n_samples=r.integer("n_samples"),
            coverage=r.num("coverage", finite=False),
            field=None if r.get("field", None) is None else r.num("field", positive=True),
            units=r.text("units", optional=True),
            sensor=r.text("sensor", optional=True) or "mag",
            model_selection=_unsanitize(ms),
        )


_TEXT_KEYS = ("path", "status", "message", "units", "use", "notes", "warnings")
"""Batch entry keys holding text: a file named 'nan' stays a name."""


@dataclass(frozen=True, eq=False)
class BatchRecord(Record):
    """Many sensors' calibrations, one entry per log: what :func:`calib_jax.fleet.calibrate_files`
    yields and ``calib-jax batch --json`` writes, and :meth:`calib_jax.BatchResult.to_record`
    gives for an in-memory batch.

    Each entry is a dict: ``path`` (the log, or the sensor's name or index), ``status`` (a
    :data:`calib_jax.status.FIT_STATUSES` word), ``solver_status``, ``message``, ``params``
    (paper 1's nine for an accelerometer, the ellipsoid's centre and W row-major for a
    magnetometer, C row-major and b for a gyroscope, whose entries add ``g_sensitivity`` and
    ``scale_asymmetry``; empty when nothing was fitted), ``stderr``, ``rms``, ``iterations``,
    ``n_points`` and what the way in found (units, g, static intervals, notes).
    """

    kind: ClassVar[str] = "batch"
    what: ClassVar[str] = "a batch of calibrations"
    sensor: str
    """'accel', 'mag' or 'gyro'."""
    entries: list[dict]
    format_version: int = FORMAT_VERSION

    def __len__(self) -> int:
        return len(self.entries)

    def __repr__(self) -> str:
        from .display import batch_repr

        return batch_repr("BatchRecord", self.sensor, self.statuses)

    def _repr_html_(self) -> str:
        from .display import batch_record_html

        return batch_record_html(self)

    @property
    def statuses(self) -> list[str]:
        return [e.get("status", "failed") for e in self.entries]

    @property
    def success(self) -> np.ndarray:
        """Per entry: the parameters may be used (:func:`calib_jax.status.is_usable`)."""
        return np.array([is_usable(s) for s in self.statuses], bool)

    def to_params(self) -> dict:
        """``{path: pytree}`` for every usable entry: :class:`calib_jax.pipeline.AccelParams`,
        :class:`calib_jax.pipeline.MagParams` or :class:`calib_jax.pipeline.GyroParams` (JAX
        is imported here)."""
        import jax.numpy as jnp

        from .models.accel import AccelParams
        from .models.gyro import GyroParams
        from .pipeline import MagParams

        out = {}
        for e, ok in zip(self.entries, self.success, strict=True):
            if not ok:
                continue
            p = jnp.asarray(e["params"], jnp.float64)
            if self.sensor == "accel":
                out[e["path"]] = AccelParams.from_vector(p)
            elif self.sensor == "gyro":
                G = e.get("g_sensitivity")
                s = e.get("scale_asymmetry")
                G = jnp.asarray(np.zeros(9) if G is None else G, jnp.float64)
                s = jnp.asarray(np.zeros(3) if s is None else s, jnp.float64)
                out[e["path"]] = GyroParams(p[:9].reshape(3, 3), p[9:], G.reshape(3, 3), s)
            else:
                out[e["path"]] = MagParams.from_vector(p)
        return out

    @classmethod
    def from_fit(cls, fit, n_points, names=None) -> BatchRecord:
        """The record of a :func:`calib_jax.pipeline.fit_batch` result (a Fit whose leaves have
        a sensor axis), to save, load and export like ``calib-jax batch``'s. ``n_points``: the
        samples each sensor was fitted to (its weights' nonzero count), one number or one per
        sensor. ``rms`` is the pipeline's, in the unit of the magnitude it was given."""
        import jax
        from jax.flatten_util import ravel_pytree

        from .batch import batch_entries

        params = jax.vmap(lambda p: ravel_pytree(p)[0])(fit.params)
        sensor = "accel" if params.shape[-1] == 9 else "mag"
        k = len(params)
        entries = batch_entries(
            fit.status,
            params,
            fit.stderr,
            fit.rms,
            fit.iterations,
            np.broadcast_to(np.asarray(n_points), (k,)),
            names,
        )
        return cls(sensor=sensor, entries=entries)

    def to_dataframe(self):
        """One row per entry, the parameters by name (pandas; see
        :func:`calib_jax.display.fleet_rows`)."""
        from .display import fleet_rows, to_dataframe

        return to_dataframe(fleet_rows(self.entries, self.sensor))

    def __eq__(self, other) -> bool:
        """Field by field; NaN equal to NaN."""
        return _fields_equal(self, other)

    def to_dict(self) -> dict:
        return {
            "format_version": self.format_version,
            "kind": self.kind,
            "sensor": self.sensor,
            "results": _sanitize(self.entries),
        }

    @classmethod
    def from_dict(cls, d: object, source: str | Path | None = None) -> BatchRecord:
        """Rebuild from :meth:`to_dict`'s layout (also ``calib-jax batch --json`` files written
        before 'kind' was, which have none); a ValueError names the file, the entry and the
        fault."""
        r = _Doc(d, source)
        _check_version(r.d, r.where)
        cls._check_kind(r.d, r.where)
        sensor = r.text("sensor")
        if sensor not in ("accel", "mag", "gyro"):
            raise ValueError(
                f"{r.where}key 'sensor' must be 'accel', 'mag' or 'gyro', got {sensor!r}"
            )
        results = r.get("results")
        if not isinstance(results, list) or not all(isinstance(e, dict) for e in results):
            raise ValueError(f"{r.where}key 'results' must be a list of objects")
        n = 9 if sensor == "accel" else 12  # mag: centre and W; gyro: C and b
        for i, e in enumerate(results):
            status, params = e.get("status"), e.get("params") or []
            if status not in FIT_STATUSES:
                raise ValueError(
                    f"{r.where}results[{i}] ({e.get('path')}): status {status!r} is not one of "
                    f"{list(FIT_STATUSES)}"
                )
            if is_usable(status) and len(params) != n:
                raise ValueError(
                    f"{r.where}results[{i}] ({e.get('path')}): a {sensor} calibration has {n} "
                    f"parameters, got {len(params)}"
                )
        entries = [
            {k: v if k in _TEXT_KEYS else _unsanitize(v) for k, v in e.items()} for e in results
        ]
        return cls(sensor=sensor, entries=entries, format_version=r.d["format_version"])
