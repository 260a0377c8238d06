"""Close the loop: residual -> effect the model lacks -> refit -> error before and after.

:func:`diagnose_accel` and :func:`diagnose_mag` fit the declared model, measure two noise
floors, then repeatedly try every catalogue effect (:data:`CATALOGUE`) and add the best one
that passes ALL of these tests (issue 6: an information criterion alone accepted nonlinear
terms on hand-held data that moved a bias by hundreds of g):

1. criterion: BIC falls by more than :data:`BIC_MIN`;
2. held out: the errors of each of :data:`BLOCKS` contiguous stretches of the log, predicted
   by the fit without that stretch, fall by more than
   :data:`calib_jax.diagnose.honest.HELD_OUT_GAIN` (single-sample leave-one-out keeps a
   sample's correlated neighbours in the fit; its gain is still reported);
3. split halves and honest significance (:mod:`calib_jax.diagnose.honest`): the effect's
   coefficients fitted on two halves of the log (the even and the odd of the :data:`BLOCKS`
   stretches, so both span the drivers' ranges) agree within 3 of their standard errors
   inflated by the block jackknife's correlation factor (or within a quarter of the effect's
   size), and Hotelling's T^2 with the jackknife covariance rejects zero. Formal errors
   assume independent samples and a tumble's are not (issue 15);
4. null test: the BIC gain beats every one of :data:`NULL_SIMS` simulations of the current
   model (same points, times and temperatures) whose magnitude errors are block-bootstrapped
   from the current residuals (so they keep their size and their correlation in time), put
   through the same candidate;
5. plausibility: the effect's size over the log and the shift it causes in the base biases
   and gains stay within physical bounds (:data:`BOUNDS`).

``outliers`` is tested when no effect passes in a round, against the best model so far:
observations whose leave-one-out residual is beyond a Bonferroni-corrected robust z
(familywise 1 %) and above 3x the noise floor are rejected (weight 0) and listed, and the
effects are tried again without them (tested first, an unfitted drift made the poses at the
ends of the log look like outliers: 6 of 20 simulated logs with a 3x-floor drift lost good
poses). The loop ends when nothing passes; the residual is then
regressed on every driver (time, temperature, orientation, motion) and significant structure
above the floor that no effect explained is reported as ``unexplained_structure``.

Everything fitted goes through one compiled LM (:mod:`calib_jax.diagnose.model`): one call
per round fits the candidates, their halves and the null simulations; a second fits the
leave-one-block-out refits of the candidates that passed the cheap tests (BIC, null,
plausibility), started at their full fit.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from scipy import stats

from ..accel import REST_RMS_LIMIT
from ..align import block_jackknife_cov, time_blocks
from ..calibration import Record
from ..io.files import SensorLog, as_log
from ..lm import is_converged
from ..models.layout import ALPHA_ENTRIES
from ..observations import TooFewPoses, accel_observations, screen_samples
from ..padding import pad_rows
from ..progress import finish, progress_bar
from ..static import detect_rest, quarter_turn
from ..status import status_message
from . import model as M
from .floors import (
    allan_deviation,
    correlated_rest_note,
    difference_noise,
    lag1_correlation,
    rest_floor,
    white_floor,
)
from .honest import HELD_OUT_GAIN, SlowNoise, held_out_rms, judge, sandwich_cov, slow_noise

BIC_MIN = 10.0  # "very strong" evidence on the Kass-Raftery scale
BLOCKS = 16
"""Contiguous stretches of the log for the leave-one-block-out (jackknife) refits. The split
halves are its even and its odd blocks: both halves span the whole time (and temperature)
range and, in a tumble, nearly every orientation. With alternate eighths instead, a 40 s
magnetometer tumble's half held 15 s of motion, too few orientations to fit the full
ellipsoid and a drift again: the halves' errors were 3-11x the whole log's (about 1.4x
expected), and real drifts passing every other test (Hotelling p 1e-9..1e-16, held-out error
28-70 % lower) were refused by the halves alone, in 5-20 % of simulated logs at any size
(benchmarks/oracle_power.py: any good test finds them all). On the even and odd sixteenths
the halves' errors are 2.3-3.3x and those logs pass. The MARG diagnosis uses
:data:`calib_jax.align.JACKKNIFE_BLOCKS` (8) for at most 3 coefficients; an effect here has up
to 6 (degree 2), and Hotelling's F(p, K - p) needs K well above p."""
NULL_SIMS = 8  # beat all 8: a chance pass has probability 1/9 per candidate
OUTLIER_FAMILYWISE = 0.01
MIN_OBSERVATIONS = 30  # below: each half has too few points for the split test
MAX_ROUNDS = 6
SLOW_NOISE_LAG1_Z = 3.0  # a rest's lag-1 correlation beyond this many 1 / sqrt(n): not white
STRUCTURE_P = 1e-3  # per-driver significance (before Bonferroni over drivers)

BOUNDS = {
    "accel": {"effect": 0.1, "nonlinear": 0.05, "bias_shift": 0.05, "gain_shift": 0.05},
    "mag": {"effect": 0.5, "nonlinear": 0.05, "bias_shift": 0.5, "gain_shift": 0.3},
}
"""Per sensor: |effect over the log| and |shift of the base biases / gains| it causes,
relative to g or to the field. The accelerometer's keep hand-held logs from buying a fit
with terms that move a bias by hundreds of g (issue 6). A magnetometer's hard iron can drift
by a large part of the field when a current or a magnetised part nearby changes, and a sphere
fitted to an ellipsoid puts its centre off by several % of the field, which freeing the shape
corrects: with the accelerometer's bounds a drift of 0.11 of the field over the log (3x the
floor) and soft iron of 12 % (10x) were rejected as implausible in every simulated log.
The nonlinearity bound stays: a magnetometer's own is under 1 % (QMC5883L: 0.1 % of full
scale), and on the QMC noisy log a quadratic of 0.086 passed every other test while the fit
was already under the floor (6.2 % against 7.5 %)."""

ACCEL_CANDIDATES = ("bias_drift", "temperature_bias", "temperature_scale", "scale_nonlinearity")
MAG_CANDIDATES = (
    "soft_iron",
    "hard_iron_drift",
    "temperature_bias",
    "temperature_scale",
    "scale_nonlinearity",
)

CATALOGUE = {
    "temperature_bias": "bias linear in temperature",
    "temperature_scale": "gains linear in temperature",
    "bias_drift": "bias linear in time",
    "scale_nonlinearity": "per-axis quadratic in the axis' own reading (+g/-g asymmetry)",
    "outliers": "observations inconsistent with the rest, rejected",
    "hard_iron_drift": "magnetometer centre linear in time",
    "soft_iron": "sphere or diagonal ellipsoid to the full ellipsoid",
    "sensor_misalignment": "rotation between magnetometer and accelerometer frames (MARG)",
    "timing_offset": "time shift between accelerometer and magnetometer samples (MARG)",
}

# effects the norm of the vector cannot tell apart: reported as one group, simplest fitted
GROUPS = {
    "scale_nonlinearity": [
        "scale_nonlinearity (per-axis quadratic, fitted)",
        "cross-axis products x_i x_j",
        "third-degree orientation terms",
    ]
}


def _slots(effect: str, degree: int = 1) -> tuple[str, ...]:
    table = {
        "bias_drift": ("drift1", "drift2"),
        "hard_iron_drift": ("drift1", "drift2"),
        "temperature_bias": ("temp_bias1", "temp_bias2"),
        "temperature_scale": ("temp_scale1",),
        "scale_nonlinearity": ("quadratic", "cubic"),
        "soft_iron": ("soft_iron",),
    }
    s = table[effect]
    return s[: max(1, min(degree, len(s)))] if effect != "soft_iron" else s


def _checked_candidates(candidates, allowed: tuple[str, ...]) -> tuple[str, ...]:
    """``candidates`` as a tuple (one name alone is one candidate: a str was iterated letter by
    letter, KeyError 'o'), each one of ``allowed`` (a misspelt name was a bare KeyError)."""
    if isinstance(candidates, str):
        candidates = (candidates,)
    unknown = [c for c in candidates if c not in allowed]
    if unknown:
        raise ValueError(
            f"unknown candidate effect(s) {unknown}: this diagnosis tests {list(allowed)} "
            "(outliers are tested always)"
        )
    return tuple(candidates)


def _indices(slots: tuple[str, ...]) -> np.ndarray:
    idx = []
    for s in slots:
        idx += [1, 2, 3, 4, 5] if s == "soft_iron" else list(range(M.N_THETA))[M.SLOTS[s]]
    return np.array(idx, int)


# --------------------------------------------------------------------------- observations


@dataclass
class Observations:
    """What the loop fits: normalised points with their drivers (host numpy)."""

    x: np.ndarray  # (m, 3) normalised: (raw - c0) / k0
    t: np.ndarray  # (m,) seconds (or sample index / rate)
    temp: np.ndarray | None  # (m,) as recorded, or None
    motion: np.ndarray  # (m,) within-interval scatter / rate of change, relative
    spans: list[tuple[int, int]]  # sample ranges [start, stop) of each observation
    c0: np.ndarray
    k0: float
    theta0: np.ndarray
    base: str  # "full", "diag" or "sphere" (mag; accel: "full")
    sensor: str
    kind: str  # "interval means" or "samples"
    notes: list[str] = field(default_factory=list)
    poses_poor: list[str] = field(default_factory=list)
    """What the poses' spread leaves poorly determined in the base calibration (calib-jax
    accel's coverage warnings), said with the verdict: a floor reached says nothing of them."""

    @property
    def m(self) -> int:
        return len(self.x)

    def tau(self) -> np.ndarray:
        span = np.ptp(self.t)
        return (self.t - self.t.min()) / span - 0.5 if span > 0 else np.zeros(self.m)

    def T(self) -> np.ndarray:
        if self.temp is None:
            return np.zeros(self.m)
        span = np.ptp(self.temp)
        mid = 0.5 * (self.temp.max() + self.temp.min())
        return (self.temp - mid) / span if span > 0 else np.zeros(self.m)


def _theta_from_alpha(alpha_n: np.ndarray, b_n: np.ndarray) -> np.ndarray:
    th = np.zeros(M.N_THETA)
    th[0:6] = alpha_n[ALPHA_ENTRIES]
    th[6:9] = b_n
    return th


def _alpha(theta: np.ndarray, free: np.ndarray) -> np.ndarray:
    return np.asarray(M.base_alpha(theta, free, np))


# --------------------------------------------------------------------------- fitting helpers


class _Problems:
    """A stack of problems over the same observations (padded to a bucket), fitted at once."""

    def __init__(self, obs: Observations, tau: np.ndarray, T: np.ndarray):
        self.obs = obs
        self.x, _ = pad_rows(obs.x)  # weight 0 in every problem's row of weights (add)
        self.size = len(self.x)
        self.tau, _ = pad_rows(tau)
        self.T, _ = pad_rows(T)
        self.rows: list[tuple] = []

    def add(self, theta0, w, free, x=None):
        wp = np.zeros(self.size)
        wp[: self.obs.m] = w
        xp = self.x if x is None else np.concatenate([x, self.x[self.obs.m :]])
        self.rows.append((np.asarray(theta0, float), xp, wp, np.asarray(free, bool)))
        return len(self.rows) - 1

    def run(self) -> list[dict]:
        if not self.rows:
            return []
        P = len(self.rows)
        th = np.stack([r[0] for r in self.rows])
        x = np.stack([r[1] for r in self.rows])
        w = np.stack([r[2] for r in self.rows])
        free = np.stack([r[3] for r in self.rows])
        tau = np.broadcast_to(self.tau, (P, self.size))
        T = np.broadcast_to(self.T, (P, self.size))
        params, se, status, e, J = M.fit_many(th, x, tau, T, w, free)
        out = []
        m = self.obs.m
        for k in range(P):
            out.append(_summary(params[k], se[k], status[k], e[k, :m], J[k, :m], w[k, :m], free[k]))
        self.rows = []
        return out


def _summary(theta, se, status, e, J, w, free) -> dict:
    act = w > 0
    m = int(act.sum())
    k = int(free.sum())
    rss = float(np.sum(w * e * e))
    rms = math.sqrt(rss / max(m, 1))
    bic = m * math.log(max(rss, 1e-300) / max(m, 1)) + k * math.log(max(m, 1))
    Jf = J[:, free] * np.sqrt(w)[:, None]
    try:
        C = np.linalg.inv(Jf.T @ Jf)
        h = np.einsum("ij,jk,ik->i", Jf, C, Jf)
        loo = e / np.clip(1.0 - h, 1e-6, None)
        loo_rms = float(np.sqrt(np.mean(loo[act] ** 2)))
    except np.linalg.LinAlgError:
        loo = np.full_like(e, np.nan)
        loo_rms = float("nan")
    return {
        "theta": theta,
        "stderr": se,
        "status": int(status),
        "converged": is_converged(int(status)),
        "e": e,
        "J": J,
        "loo": loo,
        "rms": rms,
        "bic": bic,
        "loo_rms": loo_rms,
        "n_params": k,
        "m": m,
    }


def _null_points(obs, tau, T, theta, free, e, rng, count) -> list[np.ndarray]:
    """Points on the current model, moved radially by block-bootstrapped residuals."""
    m = obs.m
    order = np.argsort(obs.t, kind="stable")
    L = max(1, int(round(m ** (1.0 / 3.0))))
    bias = _bias_at(theta, free, tau, T)
    d = obs.x - bias
    out = []
    for _ in range(count):
        starts = rng.integers(0, m, size=-(-m // L))
        idx = np.concatenate([(np.arange(s, s + L) % m) for s in starts])[:m]
        eps = np.empty(m)
        eps[order] = e[order][idx]
        target = 1.0 + eps
        # secant on the ray bias + s d: |y(s)| = target
        s0, s1 = np.ones(m), np.full(m, 1.001)
        f0 = _norm(theta, free, bias + s0[:, None] * d, tau, T) - target
        for _ in range(8):
            f1 = _norm(theta, free, bias + s1[:, None] * d, tau, T) - target
            ds = s1 - s0
            df = np.where(np.abs(f1 - f0) > 0, f1 - f0, 1.0)
            s0, f0, s1 = s1, f1, s1 - f1 * ds / df
        out.append(bias + s1[:, None] * d)
    return out


def _bias_at(theta, free, tau, T):
    th = np.where(free, theta, 0.0)
    return (
        th[6:9]
        + th[9:12] * tau[:, None]
        + th[12:15] * tau[:, None] ** 2
        + th[15:18] * T[:, None]
        + th[18:21] * T[:, None] ** 2
    )


def _calibrated(theta, free, x, tau, T):
    """:func:`calib_jax.diagnose.model.calibrated` in numpy, for many points (no compiles
    for every new length)."""
    th = np.where(free, theta, 0.0)
    y = (x - _bias_at(theta, free, tau, T)) @ np.linalg.inv(_alpha(theta, free)).T
    y = y / (1.0 + th[21:24] * T[:, None])
    return y - th[24:27] * y**2 - th[27:30] * y**3


def _norm(theta, free, x, tau, T):
    return np.linalg.norm(_calibrated(theta, free, x, tau, T), axis=1)


# --------------------------------------------------------------------------- result


DIAGNOSIS_FORMAT_VERSION = 1
_JSON_FIELDS = (
    "sensor verdict steps effects rms_before rms_after noise_floor noise_floor_white "
    "noise_floor_allan unexplained_structure structure notes rejected rounds groups "
    "n_observations observations units source findings"
).split()
_OPTIONAL_FIELDS = ("source", "findings")  # absent from files written before they existed
_FLOAT_FIELDS = "rms_before rms_after noise_floor noise_floor_white noise_floor_allan".split()


@dataclass(eq=False)
class Diagnosis(Record):
    """The loop's outcome; :meth:`to_dict` is the ``calib-jax diagnose --json`` content."""

    kind: ClassVar[str] = "diagnosis"
    what: ClassVar[str] = "a diagnosis"
    sensor: str
    verdict: str  # "at_floor", "effects_added", "unexplained_structure", "not_possible"
    steps: list[dict]
    effects: list[str]
    rms_before: float
    rms_after: float
    noise_floor: float
    noise_floor_white: float
    noise_floor_allan: float
    unexplained_structure: bool
    structure: list[dict]
    notes: list[str]
    rejected: list[dict]
    rounds: list[list[dict]]
    groups: dict
    n_observations: int
    observations: str
    units: str
    source: str | None = None
    findings: list[str] = field(default_factory=list)
    """Discrete structural findings in plain words, printed first (MARG: the magnetometer's
    axes are a signed permutation of the accelerometer's)."""
    # arrays for the report (not in the JSON)
    obs: Observations | None = None
    theta_base: np.ndarray | None = None
    theta_final: np.ndarray | None = None
    free_base: np.ndarray | None = None
    free_final: np.ndarray | None = None
    weights_final: np.ndarray | None = None
    e_base: np.ndarray | None = None
    e_final: np.ndarray | None = None

    def to_dict(self) -> dict:
        """The JSON record: ``kind`` "diagnosis", ``format_version``, then every field but the
        arrays kept for the report (non-finite numbers as null)."""
        head = {"kind": self.kind, "format_version": DIAGNOSIS_FORMAT_VERSION}
        return head | _jsonable({k: getattr(self, k) for k in _JSON_FIELDS})

    @classmethod
    def from_dict(cls, d: object, source=None) -> Diagnosis:
        """Rebuild from :meth:`to_dict`'s layout (without the report's arrays); a ValueError
        names what is wrong. Files from before ``kind`` was written (no kind, no version) are
        read as version 1."""
        where = f"{source}: " if source else ""
        if not isinstance(d, dict):
            raise ValueError(f"{where}a diagnosis file holds a JSON object, got {type(d).__name__}")
        cls._check_kind(d, where)
        version = d.get("format_version", 1)
        if version != DIAGNOSIS_FORMAT_VERSION:
            raise ValueError(
                f"{where}diagnosis format_version {version!r} is not supported (this calib_jax "
                f"reads version {DIAGNOSIS_FORMAT_VERSION})"
            )
        missing = [k for k in _JSON_FIELDS if k not in d and k not in _OPTIONAL_FIELDS]
        if missing:
            raise ValueError(f"{where}not a diagnosis: missing {', '.join(missing)}")
        kw = {k: d.get(k) for k in _JSON_FIELDS}
        kw["findings"] = kw["findings"] or []
        for k in (
            "rms_before",
            "rms_after",
            "noise_floor",
            "noise_floor_white",
            "noise_floor_allan",
        ):
            kw[k] = float("nan") if kw[k] is None else float(kw[k])
        return cls(**kw)

    def _repr_html_(self) -> str:
        from ..display import diagnosis_html

        return diagnosis_html(self)

    def __repr__(self) -> str:
        from ..display import diagnosis_repr

        return diagnosis_repr(self)

    def _sizes(self, step: dict, f: float, u: str) -> list[str]:
        """How large an accepted effect is, in the summary's unit, with its honest error (a
        trial found the sizes only in the JSON): per coefficient the x, y, z values, a MARG
        rotation or time offset, the observations an outlier step rejected."""
        c, effect = step.get("coefficients") or {}, step.get("added_effect")
        if effect == "outliers":
            times = [r["t"] for r in self.rejected if r.get("t") is not None]
            when = f", at {min(times):.4g}-{max(times):.4g} s" if times else ""
            return [f"rejected {step.get('n_rejected', 0)} observations{when} (JSON: rejected)"]
        if effect == "soft_iron":
            return ["the ellipsoid's shape (W's off-sphere terms) freed: see calib-jax mag"]
        out = []
        if "rotvec_deg" in c:
            r, e = np.asarray(c["rotvec_deg"]), np.asarray(c["rotvec_stderr_deg"])
            out.append(
                f"rotation magnetometer -> accelerometer {np.linalg.norm(r):.3g} deg; about x, "
                "y, z "
                + ", ".join(f"{v:+.3g} +- {s:.2g}" for v, s in zip(r, e, strict=True))
                + " deg"
            )
        if "permutation" in c and c["permutation"] != "x <- +x, y <- +y, z <- +z":
            out.append(f"axes: {c['permutation']}")
        if "dt_s" in c:
            dt, e = 1e3 * c["dt_s"], 1e3 * c["dt_stderr_s"]
            who = "lags" if dt > 0 else "leads"
            out.append(f"the magnetometer {who} the accelerometer by {abs(dt):.3g} +- {e:.2g} ms")
        for slot, v in c.items():
            if isinstance(v, dict) and "value" in v:
                vals = np.asarray(v["value"], float) * f
                errs = np.asarray(v["stderr"], float) * f
                out.append(
                    f"{slot}: "
                    + ", ".join(f"{a:+.3g} +- {b:.2g}" for a, b in zip(vals, errs, strict=True))
                    + f"{u} ({v.get('meaning', '')})"
                )
        return out

    def summary(self) -> str:
        from ..display import diagnosis_unit

        u, f = diagnosis_unit(self.sensor)
        u = " " + u
        if self.verdict == "not_possible":
            return f"diagnosis ({self.sensor}): not possible\n  note: " + "\n  note: ".join(
                self.notes
            )
        lines = [f"diagnosis ({self.sensor}, {self.n_observations} {self.observations}):"]
        lines += [f"  FOUND: {x}" for x in self.findings]
        for s in self.steps:
            lines.append(
                f"  {s['added_effect'] or 'base':<20s} params {s['n_params']:>2d}  rms "
                f"{s['rms'] * f:8.4f}{u}  loo {s['loo_rms'] * f:8.4f}{u}  BIC {s['bic']:10.1f}"
            )
            lines += [f"    {x}" for x in self._sizes(s, f, u)]
        lines.append(
            "  (rms: each model's error; loo: each stretch of the log predicted by the fit "
            "without it; BIC: lower is better)"
        )
        lines.append(
            f"  floor {self.noise_floor * f:.4f}{u} (white {self.noise_floor_white * f:.4f}, "
            f"Allan {self.noise_floor_allan * f:.4f}); rms {self.rms_before * f:.4f} -> "
            f"{self.rms_after * f:.4f}{u} (the base calibration -> with the effects added)"
        )
        lines.append(f"  verdict: {self.verdict}")
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


def _jsonable(v):
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return _jsonable(v.tolist())
    if isinstance(v, (np.floating, float)):
        return None if not math.isfinite(float(v)) else float(v)
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.bool_,)):
        return bool(v)
    return v


# --------------------------------------------------------------------------- the loop


SAMPLE_CLOCK_NOTE = (
    "no time column and no sample rate: 'time' is the sample number (in the tests in time "
    "and the figures' time axis too); give --sample-rate for seconds"
)
"""Said where a log has no clock (a trial read 'time [s]' running to 12,000 on CK-Explorer)."""

_MEANING = {
    "drift1": "bias change over the whole log, per axis (x, y, z)",
    "drift2": "quadratic bias term over the log (value at the ends minus the middle, x4)",
    "temp_bias1": "bias change over the recorded temperature range, per axis",
    "temp_bias2": "quadratic bias term over the temperature range",
    "temp_scale1": "relative gain change over the recorded temperature range, per axis",
    "quadratic": "q in a = y - q y^2 (y: linearly calibrated reading, a: corrected)",
    "cubic": "r in y - r y^3",
}


def _coefficients(effect, theta, se, se_formal) -> dict:
    """An accepted effect's coefficients, relative to g or to the field, with their meaning,
    their honest (block jackknife) standard errors and the formal ones (independent samples)."""
    out = {}
    for slot in _slots(effect, 2):
        if slot == "soft_iron":
            continue
        sl = M.SLOTS[slot]
        if np.any(theta[sl] != 0):
            errors = {"stderr": se[sl], "stderr_formal": se_formal[sl]}
            out[slot] = {"value": theta[sl], **errors, "meaning": _MEANING[slot]}
            if slot == "quadratic":
                # the sensor reads y = a + q a^2 (to first order): |y| at +1 minus |y| at -1
                # along an axis is 2 q
                out["scale_asymmetry"] = {
                    "value": theta[sl],
                    **errors,
                    "meaning": "(|reading at +1| - |reading at -1|) / 2 per axis",
                }
    return out


def coefficient_bound(effect: str, bounds: dict) -> float:
    """The largest plausible |coefficient| of ``effect`` under a sensor's :data:`BOUNDS`."""
    return bounds["nonlinear"] if effect == "scale_nonlinearity" else bounds["effect"]


def _plausible(effect, theta_new, theta_cur, free_new, bounds: dict) -> tuple[bool, str]:
    special = ("soft_iron", "outliers")
    idx = _indices(_slots(effect, 2)) if effect not in special else np.array([], int)
    idx = idx[free_new[idx]] if idx.size else idx
    size = float(np.max(np.abs(theta_new[idx]))) if idx.size else 0.0
    lim = coefficient_bound(effect, bounds)
    db = float(np.max(np.abs(theta_new[6:9] - theta_cur[6:9])))
    dg = float(np.max(np.abs(theta_new[0:3] / theta_cur[0] - theta_cur[0:3] / theta_cur[0])))
    if effect == "soft_iron":
        dg = 0.0  # freeing the shape is the point of this effect
    reasons = []
    if size > lim:
        reasons.append(f"coefficient {size:.3g} beyond {lim:g}")
    if db > bounds["bias_shift"]:
        reasons.append(f"moves the base bias by {db:.3g} (bound {bounds['bias_shift']:g})")
    if dg > bounds["gain_shift"]:
        reasons.append(f"moves the base gains by {dg:.3g} (bound {bounds['gain_shift']:g})")
    return not reasons, "; ".join(reasons)


def _step(label, fit, n_rejected, effect=None) -> dict:
    return {
        "model": label,
        "added_effect": effect,
        "n_params": fit["n_params"],
        "rms": fit["rms"],
        "bic": fit["bic"],
        "loo_rms": fit["loo_rms"],
        "n_observations": fit["m"],
        "n_rejected": n_rejected,
    }


def _cheap_tests(c, d, fits, nb, cur, bounds) -> dict:
    """A candidate's round entry with the tests that need no refit: convergence, BIC, the
    null test (its gain beats each null simulation's) and plausibility."""
    fit = fits[d["real"]]
    dbic = cur["bic"] - fit["bic"]
    null_gain = max(nb[k] - fits[i]["bic"] for k, i in enumerate(d["null"]))
    ok_plaus, why = _plausible(c, fit["theta"], cur["theta"], d["free"], bounds)
    entry = {
        "effect": c,
        "accepted": False,
        "delta_bic": dbic,
        "loo_gain": 1.0 - fit["loo_rms"] / cur["loo_rms"],
        "null_max_delta_bic": null_gain,
        "rms": fit["rms"],
        "loo_rms": fit["loo_rms"],
        "tests": {
            "converged": fit["converged"],
            "bic": dbic > BIC_MIN,
            "null": dbic > null_gain,
            "plausible": ok_plaus,
        },
    }
    if not ok_plaus:
        entry["implausible"] = why
    return entry


def _jackknife(P: _Problems, theta, w, free, block) -> list[dict]:
    """The fit without each of the :data:`BLOCKS` blocks, started at ``theta`` (a fit on the
    whole log, so a few iterations each)."""
    for b in range(BLOCKS):
        P.add(theta, w * (block != b), free)
    return P.run()


def _effect_of(effect, sl, fit) -> tuple[np.ndarray, np.ndarray]:
    """An effect's coefficients in a fit, zero where the effect is absent, and their formal
    standard errors. ``sl``: the parameters the effect frees beyond the current model. Soft
    iron's are gains 2 and 3 less gain 1 (on a sphere base), and the cross terms: its
    absence is a sphere, not zero gains (which Hotelling's test then rejected at p ~ 1e-25 on
    every clean log, and whose halves always agreed within a quarter of a gain of about 1).
    The difference's error is taken as sqrt(se_j^2 + se_1^2), the covariance left out."""
    theta, se = fit["theta"][sl], fit["stderr"][sl]
    if effect != "soft_iron":
        return theta, se
    gain = np.isin(sl, (1, 2))
    coef = np.where(gain, theta - fit["theta"][0], theta)
    return coef, np.where(gain, np.hypot(se, fit["stderr"][0]), se)


def _effect_map(effect, sl) -> np.ndarray:
    """The matrix A (len(sl), 30) with an effect's coefficients = A theta (:func:`_effect_of`)."""
    A = np.zeros((len(sl), M.N_THETA))
    A[np.arange(len(sl)), sl] = 1.0
    if effect == "soft_iron":
        A[np.isin(sl, (1, 2)), 0] = -1.0
    return A


@dataclass
class _SlowNoise:
    """The current model's residual noise (:func:`.honest.slow_noise`) and what the sandwich
    needs with it: the observations' time order, which of them are fitted, their directions."""

    order: np.ndarray
    active: np.ndarray  # in time order
    u: np.ndarray  # (active observations, 3), time order
    noise: SlowNoise

    @classmethod
    def of(cls, obs: Observations, cur: dict, w: np.ndarray, free: np.ndarray) -> _SlowNoise:
        order = np.argsort(obs.t, kind="stable")
        active = (w > 0)[order]
        y = _calibrated(
            cur["theta"],
            free,
            obs.x[order][active],
            obs.tau()[order][active],
            obs.T()[order][active],
        )
        u = y / np.linalg.norm(y, axis=1, keepdims=True)
        # noise correlated over at most one jackknife block (slow_noise)
        noise = slow_noise(cur["e"][order][active], u, longest=active.sum() / BLOCKS)
        return cls(order, active, u, noise)

    def covariance(self, fit: dict, free: np.ndarray, A: np.ndarray) -> np.ndarray:
        """Covariance of A theta for a fit with parameters ``free`` under this noise."""
        fr = np.flatnonzero(free)
        J = fit["J"][self.order][self.active][:, fr]
        return A[:, fr] @ sandwich_cov(J, self.u, self.noise) @ A[:, fr].T


def _honest_tests(entry, d, fits, jack, held_cur, block, w, free, degree, tried, slow) -> None:
    """Add the held-out, halves and honest-significance tests (:mod:`.honest`) to a
    candidate's entry, from its halves (``fits``), leave-one-block-out refits ``jack`` and
    the residual's slow noise ``slow`` (:class:`_SlowNoise`); ``free``: the current model's
    mask (a diagonal base's gains are not soft iron's to test); ``tried``: the round's number
    of candidates."""
    c = entry["effect"]
    sl = _indices(_slots(c, degree))
    sl = sl[d["free"][sl] & ~free[sl]]
    (coef, se), (c1, se1), (c2, se2) = (_effect_of(c, sl, fits[d[k]]) for k in ("real", "h1", "h2"))
    fit = fits[d["real"]]
    h = judge(
        coef,
        c1,
        c2,
        np.stack([_effect_of(c, sl, f)[0] for f in jack]),
        np.sqrt(se1**2 + se2**2),
        se,
        tried,
        slow_cov=None if slow is None else slow.covariance(fit, d["free"], _effect_map(c, sl)),
    )
    held = held_out_rms([f["e"] for f in jack], block, w)
    entry["held_out_gain"] = 1.0 - held / held_cur
    entry["tests"]["held_out"] = entry["held_out_gain"] > HELD_OUT_GAIN
    entry["tests"]["halves"] = h.pop("halves")
    entry["tests"]["honest"] = h.pop("honest")
    entry.update(h, stderr_formal=se)


def _outlier_pass(P: _Problems, cur, w, free, floor, n_rejected, bounds):
    """Reject the worst observation, refit, re-test, one at a time (a gross outlier distorts
    the fit and would otherwise drag good neighbours out with it): observations whose
    leave-one-out residual is beyond a Bonferroni-corrected robust z and above 3x the floor,
    at most 10 % of them. Returns the fit without them, the weights, the rejected indices and
    the round's log entries."""
    m = len(w)
    log: list[dict] = []
    newly: list[int] = []
    limit = max(1, int(0.1 * m))
    while True:
        act = w > 0
        loo = cur["loo"]
        med = np.median(loo[act])
        sig = 1.4826 * np.median(np.abs(loo[act] - med))
        z = stats.norm.isf(OUTLIER_FAMILYWISE / (2 * act.sum()))
        score = np.where(act, np.abs(loo - med) / max(sig, 1e-300), 0.0)
        worst = int(np.argmax(score))
        if score[worst] <= z or abs(cur["e"][worst]) <= 3 * floor:
            break
        if n_rejected + len(newly) >= limit:
            log.append(
                {
                    "effect": "outliers",
                    "accepted": False,
                    "reason": f"more than {limit} observations (10 %) beyond the robust "
                    "limit: that is structure, not outliers",
                }
            )
            break
        w_try = np.where(np.arange(m) == worst, 0.0, w)
        P.add(cur["theta"], w_try, free)
        fit = P.run()[0]
        ok_plaus, why = _plausible("outliers", fit["theta"], cur["theta"], free, bounds)
        if not (fit["converged"] and ok_plaus):
            log.append(
                {
                    "effect": "outliers",
                    "accepted": False,
                    "reason": f"the refit without observation {worst} "
                    + ("did not converge" if not fit["converged"] else why)
                    + ": the data, not one observation, disagree with the model",
                }
            )
            break
        w, cur = w_try, fit
        newly.append(worst)
    if newly:
        log.insert(0, {"effect": "outliers", "accepted": True, "rejected": newly})
    return cur, w, newly, log


def _run(
    obs: Observations,
    candidates: tuple[str, ...],
    floor: float,
    seed: int,
    degree: int,
    progress: bool | None = None,
    slow_noise_test: bool = False,
) -> dict:
    """The rounds of the loop (the module docstring). ``slow_noise_test``: the log's rest
    shows correlated noise, so a candidate must also pass the Wald test whose covariance
    models slow noise (:class:`_SlowNoise`). It is not run otherwise: on white noise the
    residual of a model without a real drift holds the drift, which that noise model then
    takes for slow noise (a drift at 1.4x the floor was refused at p 0.003)."""
    tau, T = obs.tau(), obs.T()
    m = obs.m
    rng = np.random.default_rng(seed)
    base_free = M.mask(base=obs.base)
    P = _Problems(obs, tau, T)
    w = np.ones(m)
    P.add(obs.theta0, w, base_free)
    base = P.run()[0]
    cur, free, effects = base, base_free.copy(), []
    steps = [_step(obs.base if obs.sensor == "mag" else "accel9", base, 0)]
    steps[0]["model"] = "base"
    if not base["converged"]:  # nothing to judge effects against: no rounds (_finish says so)
        return {"base": base, "final": base, "steps": steps}
    rounds: list[list[dict]] = []
    rejected: list[int] = []
    remaining = [c for c in candidates]
    order = np.argsort(obs.t, kind="stable")
    block = np.empty(m, int)
    block[order] = time_blocks(m, BLOCKS)  # contiguous stretches in time
    first = block % 2 == 0  # the halves (BLOCKS)
    jack_cur = None  # the current model's leave-one-block-out fits, once computed

    bar = progress_bar(MAX_ROUNDS, progress, f"diagnosing {obs.sensor}", unit="round")
    for _ in range(MAX_ROUNDS):
        bar.set_postfix_str(f"{len(remaining)} candidates, {NULL_SIMS} null fits each")
        log: list[dict] = []
        # --- parametric candidates: real, halves, null sims, one compiled fit for all
        nulls = _null_points(obs, tau, T, cur["theta"], free, cur["e"], rng, NULL_SIMS)
        idx: dict[str, dict] = {}
        for c in remaining:
            fc = M.mask(*_slots(c, degree), base=obs.base) | free
            th0 = cur["theta"].copy()
            th0[1:3] = np.where(free[1:3], th0[1:3], th0[0])  # freed gains start at the tie
            idx[c] = {
                "free": fc,
                "real": P.add(th0, w, fc),
                "h1": P.add(th0, w * first, fc),
                "h2": P.add(th0, w * ~first, fc),
                "null": [P.add(th0, w, fc, x=xn) for xn in nulls],
            }
        null_base = [P.add(cur["theta"], w, free, x=xn) for xn in nulls]
        fits = P.run()
        nb = [fits[i]["bic"] for i in null_base]
        entries = {c: _cheap_tests(c, idx[c], fits, nb, cur, BOUNDS[obs.sensor]) for c in remaining}
        # --- the honest tests, for the candidates that passed the cheap ones, best BIC gain
        # first: the first to pass them is the round's best (the rest are not refitted)
        judged = [c for c in remaining if all(entries[c]["tests"].values())]
        judged.sort(key=lambda c: -entries[c]["delta_bic"])
        best = None
        slow = _SlowNoise.of(obs, cur, w, free) if judged and slow_noise_test else None
        for c in judged:
            d, fit = idx[c], fits[idx[c]["real"]]
            if jack_cur is None:  # the current model without each block: its held-out errors
                jack_cur = _jackknife(P, cur["theta"], w, free, block)
            jack = _jackknife(P, fit["theta"], w, d["free"], block)
            held_cur = held_out_rms([f["e"] for f in jack_cur], block, w)
            _honest_tests(
                entries[c], d, fits, jack, held_cur, block, w, free, degree, len(remaining), slow
            )
            if all(entries[c]["tests"].values()):
                best = (c, fit, d["free"], jack)
                break
        for c in remaining:
            e = entries[c]
            if "held_out" not in e["tests"]:
                e["not_run"] = (
                    f"held_out, halves, honest: {best[0]} passed them first (larger BIC gain)"
                    if best and all(e["tests"].values())
                    else "held_out, halves, honest: the tests above failed"
                )
            e["accepted"] = all(e["tests"].values()) and "not_run" not in e
        log += [entries[c] for c in remaining]
        if best is None:
            # --- outliers, only when no effect passes: judged against the best model so far
            # (an effect not yet fitted, a drift, makes its extreme observations look like
            # outliers); after a rejection the candidates are tried again without them
            fit, w_new, newly, out_log = _outlier_pass(
                P, cur, w, free, floor, len(rejected), BOUNDS[obs.sensor]
            )
            log = out_log + log
            rounds.append(log)
            bar.update(1)
            if not newly:
                break
            w, cur, jack_cur = w_new, fit, None
            rejected += newly
            st = _step("+".join(["base", *effects, "outliers"]), cur, len(rejected))
            st["added_effect"] = "outliers"
            steps.append(st)
            if "outliers" not in effects:
                effects.append("outliers")
            continue
        rounds.append(log)
        bar.update(1)
        c, fit, fc, jack_cur = best  # the accepted fit's jackknife is the new model's
        cur, free = fit, fc
        effects.append(c)
        remaining.remove(c)
        st = _step("+".join(["base", *effects]), fit, len(rejected))
        st["added_effect"] = c
        steps.append(st)
    finish(bar)
    # honest standard errors of the final model (block jackknife), for its coefficients
    honest = np.full_like(cur["theta"], np.nan)
    if any(e != "outliers" for e in effects):
        if jack_cur is None:
            jack_cur = _jackknife(P, cur["theta"], w, free, block)
        honest = np.sqrt(np.diag(block_jackknife_cov(np.stack([f["theta"] for f in jack_cur]))))
    return {
        "stderr_honest": honest,
        "base": base,
        "base_free": base_free,
        "final": cur,
        "free": free,
        "w": w,
        "steps": steps,
        "effects": effects,
        "rounds": rounds,
        "rejected": rejected,
    }


def _structure(obs, e, w, theta, free, floor) -> list[dict]:
    """Regress the final residual on every driver; F-test each against a constant."""
    act = w > 0
    tau, T = obs.tau()[act], obs.T()[act]
    y = _calibrated(theta, free, obs.x[act], tau, T)
    u = y / np.linalg.norm(y, axis=1, keepdims=True)
    has_T = obs.temp is not None and np.ptp(obs.temp) > 0
    return regress_drivers(
        e[act], driver_designs(u, tau, T if has_T else None, obs.motion[act]), floor
    )


def driver_designs(u, tau, T, motion) -> dict[str, np.ndarray]:
    """Design matrices of the drivers: time, temperature (T None: none), orientation (u: the
    unit direction of each observation), motion."""
    m = len(u)
    drivers = {}
    # time: a magnitude that follows time, and (bias-like) a vector effect that follows time,
    # seen in the norm as u . b(t): products of the direction with the time basis
    if m >= 150:
        k = np.arange(1, 4)
        f = [tau, tau**2, tau**3]
    elif m >= 60:
        k = np.arange(1, 4)
        f = [tau]
    else:
        k = np.arange(1, 2)
        f = [tau]
    f = np.column_stack(
        [*f, np.sin(2 * np.pi * np.outer(tau, k)), np.cos(2 * np.pi * np.outer(tau, k))]
    )
    drivers["time"] = np.column_stack([f, *(u[:, [j]] * f for j in range(3))])
    if T is not None:
        ft = np.column_stack([T, T**2])
        drivers["temperature"] = np.column_stack([ft, *(u[:, [j]] * ft for j in range(3))])
    X, Y, Z = u.T
    orient = [X, Y, Z, X * Y, X * Z, Y * Z, X * X - Y * Y, Z * Z]
    if m >= 60:
        orient += [
            X**3,
            Y**3,
            Z**3,
            X * Y * Z,
            X * X * Y,
            X * X * Z,
            Y * Y * X,
            Y * Y * Z,
            Z * Z * X,
            Z * Z * Y,
        ]
    drivers["orientation"] = np.column_stack(orient)
    mo = motion
    if np.all(np.isfinite(mo)) and np.ptp(mo) > 0:
        mo = (mo - mo.mean()) / mo.std()
        drivers["motion"] = np.column_stack([mo, mo**2])
    return drivers


def _prewhiten(x: np.ndarray, phi: float) -> np.ndarray:
    """x_t - phi x_{t-1}, the first row scaled by sqrt(1 - phi^2) (Prais-Winsten): rows with
    independent errors when x's errors are AR(1) with coefficient phi; x itself for phi 0."""
    w = np.empty_like(x, dtype=float)
    w[0] = np.sqrt(1.0 - phi**2) * x[0]
    w[1:] = x[1:] - phi * x[:-1]
    return w


def regress_drivers(e, drivers, floor) -> list[dict]:
    """F-test of each driver's design against a constant; structure "above the floor" when
    significant (Bonferroni over drivers) and at least a fifth of the floor in size.

    The residuals come in time order and may be correlated (a tumble's noise, a hand's
    acceleration): each test is made on the series prewhitened by the residual's own lag-1
    correlation about its mean (an AR(1) under "no structure", Prais-Winsten), so a slow
    wander of the noise is not read as structure. On simulated magnetometer tumbles with noise
    correlated over 2 s, the plain F-test found time, temperature and orientation at p < 1e-30
    in every clean log; white residuals give a correlation near 0 and the plain test. The
    correlation is the null's, not the one left after each driver's regression
    (Cochrane-Orcutt): the time driver's 36 columns absorb the slow noise (0.91 left of 0.99)
    and the prewhitened test still found time at p 1e-100 in clean logs. Under real slow
    structure the null's correlation is larger than the noise's, so the test is conservative;
    the floor's excess test (rms over twice the floor) still sees that structure's size.
    """
    m = len(e)
    out = []
    phi = lag1_correlation(e)
    e_w = _prewhiten(e, phi)
    rss_plain = float(np.sum((e - e.mean()) ** 2))
    for name, D in drivers.items():
        A = np.column_stack([np.ones(m), D])
        p = A.shape[1] - 1
        if m - p - 1 < 5:
            continue
        coef, *_ = np.linalg.lstsq(A, e, rcond=None)
        fitted = A @ coef
        A_w = _prewhiten(A, phi)
        one = A_w[:, 0]
        rss0 = float(np.sum((e_w - one * (one @ e_w) / (one @ one)) ** 2))
        c_w, *_ = np.linalg.lstsq(A_w, e_w, rcond=None)
        rss1 = float(np.sum((e_w - A_w @ c_w) ** 2))
        F = ((rss0 - rss1) / p) / max(rss1 / (m - p - 1), 1e-300)
        pval = float(stats.f.sf(F, p, m - p - 1))
        size = float(np.sqrt(np.mean((fitted - e.mean()) ** 2)))
        significant = pval < STRUCTURE_P / len(drivers)
        out.append(
            {
                "driver": name,
                "p_value": pval,
                "size": size,
                "significant": bool(significant),
                # significant AND big enough to matter: a fifth of the floor (a single-sample
                # floor is large against structure shared by thousands of samples)
                "above_floor": bool(significant and size > 0.2 * floor),
                "share_of_variance": (
                    1.0 - float(np.sum((e - fitted) ** 2)) / rss_plain if rss_plain > 0 else 0.0
                ),
                "lag1_correlation": phi,
            }
        )
    return out


OUTSIDE_CAUSES = {
    "accel": "the board moving or tilting on its support between poses, a log that joins two "
    "sessions, a mount that heats or bends",
    "mag": "a magnet, a current or iron moving near the board, a log that joins two places",
}


def _too_large_to_accept(rounds, rms, sensor, scale_to_output, units) -> tuple[list[str], float]:
    """Notes for the last round's candidates that explain the residual (they converge and
    pass BIC and the null test) but fail plausibility, and the lowest rms they reach (inf if
    none): without them the user read "no catalogue effect explains it", and that the poses
    looked like pauses in a motion, beside a drift that took the rms from 30 to 5 mg and was
    refused only for being larger than a sensor's bias moves (issue 15's power study: the
    accelerometer rows at 10-20x the floor that detect 0 %)."""
    out, best = [], float("inf")
    for e in rounds[-1] if rounds else []:
        t = e.get("tests", {})
        if "implausible" in e and t.get("converged") and t.get("bic") and t.get("null"):
            ref = "g" if sensor == "accel" else "the field"
            out.append(
                f"{e['effect']} would take the rms from {rms * scale_to_output:.3g} to "
                f"{e['rms'] * scale_to_output:.3g} {units} (BIC gain {e['delta_bic']:.0f}) but "
                f"is larger than the sensor's own effect can be ({e['implausible']}; relative "
                f"to {ref}), so it is not accepted; look for a cause outside the sensor: "
                f"{OUTSIDE_CAUSES[sensor]}"
            )
            best = min(best, e["rms"])
    return out, best


def _finish(obs, res, floors, units, source, scale_to_output) -> Diagnosis:
    white, allan = floors
    floor = (
        float(np.nanmax([white, allan])) if np.any(np.isfinite([white, allan])) else float("nan")
    )
    fin, base = res["final"], res["base"]
    if not base["converged"]:  # no calibration to judge effects against (a rocket's descent
        # read as poses: 'unexplained structure', exit 0, beside a base fit that diverged)
        return _not_possible(
            obs.sensor,
            obs.m,
            "observations that determine the base calibration",
            f"the base model's fit ({obs.base if obs.sensor == 'mag' else 'accel9'}) did not "
            f"converge: {_base_failure_advice(obs, base['status'])}",
            source,
        )
    w = res["w"]
    # before and after are the first and last steps' rms, as the steps table shows them: the
    # base model on every observation, the final one on those kept (outliers rejected). Before
    # issue 14 "before" was the base fit's residual on the kept observations only.
    rms_before, rms_after = res["steps"][0]["rms"], res["steps"][-1]["rms"]
    notes = list(obs.notes)
    structure = _structure(obs, fin["e"], w, fin["theta"], res["free"], floor)
    drivers_above = [s for s in structure if s["above_floor"]]
    excess = np.isfinite(floor) and rms_after > 2.0 * floor
    unexplained = bool(drivers_above) or bool(excess)
    too_large, rms_if_accepted = _too_large_to_accept(
        res["rounds"], fin["rms"], obs.sensor, scale_to_output, units
    )
    for s in drivers_above:
        notes.append(
            f"residual follows {s['driver']} (p = {s['p_value']:.1e}, size "
            f"{s['size'] * scale_to_output:.3g} {units}, {100 * s['share_of_variance']:.0f} % of "
            f"its variance) and no {'plausible ' if too_large else ''}catalogue effect explains it"
        )
    if unexplained:
        notes += too_large
    if excess and not drivers_above:
        notes.append(
            f"rms after ({rms_after * scale_to_output:.3g} {units}) is "
            f"{rms_after / floor:.1f}x the floor with no driver it follows: excess scatter "
            "between observations (disturbed poses, or a floor that underestimates the noise)"
        )
    if obs.sensor == "accel" and min(rms_before, rms_if_accepted) >= REST_RMS_LIMIT:
        notes.append(
            f"the poses leave {rms_before:.2g} of g after the base fit (held rests leave under "
            f"{REST_RMS_LIMIT:g}): they look like pauses in a motion, and the floor measured "
            "in them holds that motion too, so being at or near it says little about the sensor; "
            "record poses held still for a few seconds on a support"
        )
    elif not unexplained and rms_after <= 1.5 * floor:
        notes.append(
            f"at the noise floor: rms {rms_after * scale_to_output:.3g} {units} against a floor of "
            f"{floor * scale_to_output:.3g} {units}; nothing beyond noise (an effect smaller than "
            "the floor would not show in this log)"
            + (
                " that these poses can show; the base calibration itself is poorly determined "
                "(the next note)"
                if obs.poses_poor
                else ""
            )
        )
    elif not unexplained:
        notes.append(
            f"rms {rms_after / floor:.2f}x the floor without significant structure in any driver"
        )
    notes += [f"the poses: {w}" for w in obs.poses_poor]
    groups = {}
    for eff in res["effects"]:
        if eff in GROUPS:
            groups[eff] = GROUPS[eff]
            notes.append(
                f"{eff}: the vector's magnitude cannot tell apart "
                + ", ".join(GROUPS[eff])
                + "; the simplest member is fitted, not a confident pick"
            )
    # coefficients of the accepted effects (output units)
    for st in res["steps"]:
        eff = st["added_effect"]
        if eff and eff not in ("outliers", "soft_iron"):
            st["coefficients"] = _coefficients(
                eff, fin["theta"], res["stderr_honest"], fin["stderr"]
            )
    rejected = [
        {
            "index": i,
            "samples": list(obs.spans[i]),
            "t": float(obs.t[i]),
            "residual": float(res["base"]["e"][i]),
            "motion": float(obs.motion[i]),
        }
        for i in res["rejected"]
    ]
    verdict = (
        "unexplained_structure"
        if unexplained
        else ("effects_added" if res["effects"] else "at_floor")
    )
    return Diagnosis(
        sensor=obs.sensor,
        verdict=verdict,
        steps=res["steps"],
        effects=res["effects"],
        rms_before=rms_before,
        rms_after=rms_after,
        noise_floor=floor,
        noise_floor_white=float(white),
        noise_floor_allan=float(allan),
        unexplained_structure=unexplained,
        structure=structure,
        notes=notes,
        rejected=rejected,
        rounds=res["rounds"],
        groups=groups,
        n_observations=obs.m,
        observations=obs.kind,
        units="relative to g" if obs.sensor == "accel" else "relative to the field",
        source=source,
        obs=obs,
        theta_base=base["theta"],
        theta_final=fin["theta"],
        free_base=res["base_free"],
        free_final=res["free"],
        weights_final=w,
        e_base=base["e"],
        e_final=fin["e"],
    )


_ELLIPSOID = {"full": "full ellipsoid", "diag": "diagonal ellipsoid", "sphere": "sphere"}


def _base_failure_advice(obs, status: int) -> str:
    """Why a diagnosis's base fit failed and what to change, in this command's own options
    (status_message's advice names --max-iter, which calib-jax diagnose has not)."""
    why = status_message(status).split("; with data that do")[0]
    if obs.sensor == "mag" and obs.base != "sphere":
        simpler = "--model diag or --model sphere" if obs.base == "full" else "--model sphere"
        return (
            f"{why}; the {_ELLIPSOID[obs.base]} is not determined by these samples: declare a "
            f"simpler base ({simpler}), or record more orientations"
        )
    return f"{why}; calib-jax {obs.sensor} on this log says what the fit lacks"


def _not_possible(sensor, m, need, why, source) -> Diagnosis:
    return Diagnosis(
        sensor=sensor,
        verdict="not_possible",
        steps=[],
        effects=[],
        rms_before=float("nan"),
        rms_after=float("nan"),
        noise_floor=float("nan"),
        noise_floor_white=float("nan"),
        noise_floor_allan=float("nan"),
        unexplained_structure=False,
        structure=[],
        notes=[f"diagnosis not possible: {why}" + (f"; it needs at least {need}" if need else "")],
        rejected=[],
        rounds=[],
        groups={},
        n_observations=m,
        observations="",
        units="",
        source=source,
    )


# --------------------------------------------------------------------------- accelerometer


def _load(data, sensor):
    data = as_log(data)
    if isinstance(data, SensorLog):
        return data.vectors(sensor), data.t, data.temp, data.sample_rate, data.path
    x = np.asarray(data, float)
    if x.ndim != 2 or x.shape[1] != 3:  # a (3, N) array read as 3 samples: 'too few samples'
        raise ValueError(
            f"data must be (samples, 3), got shape {x.shape}"
            + ("; transpose it (data.T)" if x.ndim == 2 and x.shape[0] == 3 else "")
        )
    return x, None, None, None, None


def diagnose_accel(
    data,
    *,
    t: np.ndarray | None = None,
    temp: np.ndarray | None = None,
    sample_rate: float | None = None,
    block: int | None = None,
    intervals: list[tuple[int, int]] | None = None,
    candidates: tuple[str, ...] = ACCEL_CANDIDATES,
    degree: int = 1,
    seed: int = 0,
    progress: bool | None = None,
    **static_options,
) -> Diagnosis:
    """Close the loop on an accelerometer multi-position log (module docstring).

    Parameters
    ----------
    data : (N, 3) array, SensorLog or path
        Raw readings; a log's time, temperature and sample rate are used.
    t, temp : (N,) arrays, optional
        Sample times (s) and temperature for an array input.
    block : int, optional
        Observations are consecutive blocks of this many samples (logs recorded pose by pose
        with a fixed count, like CK-Explorer's 160 x 100) instead of detected static intervals.
    intervals : list of (start, stop), optional
        The static intervals, as sample ranges, instead of detecting them.
    candidates : tuple of str
        Catalogue effects to try (``outliers`` is always tested). Temperature effects are
        skipped without a temperature column.
    degree : int
        1: effects linear in their driver (per-axis quadratic for scale_nonlinearity); 2:
        quadratic in time / temperature and cubic nonlinearity.
    progress : bool, optional
        A progress bar over the rounds (each fits every candidate, its halves and the null
        simulations); None: on a terminal or in a notebook only
        (:func:`calib_jax.progress.progress_bar`).
    static_options
        Passed to :func:`calib_jax.static.detect_static` (window, threshold_factor, ...).
    """
    candidates = _checked_candidates(candidates, ACCEL_CANDIDATES)
    x, t_log, temp_log, rate, source = _load(data, "accel")
    t = t_log if t is None else t
    temp = temp_log if temp is None else temp
    sample_rate = sample_rate or rate
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"accelerometer data must be (samples, 3), got shape {x.shape}")
    n = len(x)
    clock = [] if t is not None or sample_rate else [SAMPLE_CLOCK_NOTE]
    if t is None:
        t = np.arange(n) / (sample_rate or 1.0)
    t = np.asarray(t, float)
    ok, det_notes = screen_samples(x, "accel")  # the way in of calibrate_accel
    det_notes = clock + det_notes
    poses_poor: list[str] = []
    if intervals is not None:
        spans = [(int(a), int(b)) for a, b in intervals if b - a > 1 and ok[a:b].all()]
    else:
        # calibrate_accel's way in: the same screen, detector (a sweep scored by the fit, or
        # fixed blocks) and pose checks, so a log it refuses is not diagnosed either
        from ..accel import (
            _coverage_warnings,
            check_poses,
            detect_units,
            no_accelerometer_unit,
            nominal_centre_of,
            radius_determined,
        )

        need: str | None = "9 distinct static poses"
        try:
            found = accel_observations(
                x, sample_rate=sample_rate, block=block or None, **static_options
            )
            centre, radius = check_poses(found, "accel9", sample_rate)
            around = radius_determined(found.points, centre)
            if detect_units(found.static_norm, radius, around) is None:  # another sensor's log
                need = None  # the message says what the readings are and what to run
                raise ValueError(no_accelerometer_unit(found.static_norm, radius, False, around))
        except ValueError as exc:
            why = str(exc)
            if isinstance(exc, TooFewPoses):  # none of calib-jax accel's remedies apply here
                why = exc.finding + (
                    " (calib-jax accel fits such a log with six parameters)"
                    if exc.n_distinct >= 6
                    else ""
                )
                need = None  # the finding says how many poses the model needs
            d = _not_possible("accel", 0, need, why, source)
            d.notes.extend(det_notes)
            return d
        spans = [(iv.start, iv.stop) for iv in found.report.intervals]
        det_notes += found.report.notes(sample_rate)
        # calib-jax accel's warnings on the poses' spread (a hand-tilted log whose poses
        # lay within 73 deg of up was "at_floor ... nothing beyond noise", no word of them)
        poses_poor = _coverage_warnings(
            found.points,
            centre,
            9,
            nominal_centre_of(found),
            pose_table=found.report.kind == "pose_table",
        )
    m = len(spans)
    if m < MIN_OBSERVATIONS:
        d = _not_possible(
            "accel",
            m,
            f"{MIN_OBSERVATIONS} static intervals",
            f"{m} static intervals for 9 parameters: the split-half and leave-one-out tests "
            f"cannot run (record {MIN_OBSERVATIONS - m} or more further poses, each held still "
            "for a second or more, in new orientations; calib-jax accel fits the log as it is "
            "and says whether that is a calibration)",
            source,
        )
        d.notes.extend(det_notes)
        return d
    if max(b - a for a, b in spans) < 2:  # before the fits: --block 1 on a long log took 38 s
        return _no_floor(m, spans, source, det_notes)
    means = np.array([x[a:b].mean(0) for a, b in spans])
    from ..accel import initial_guess_points
    from ..geometry import sphere_fit_points

    c0, k0 = sphere_fit_points(means)
    xn = (means - c0) / k0
    theta0 = np.r_[initial_guess_points(xn), np.zeros(M.N_THETA - 9)]  # paper 1's layout first
    motion = np.array([np.linalg.norm(x[a:b].std(0)) for a, b in spans]) / k0
    tm = np.array([t[a:b].mean() for a, b in spans])
    tp = None if temp is None else np.array([np.nanmean(temp[a:b]) for a, b in spans])
    cands = tuple(c for c in candidates if temp is not None or not c.startswith("temperature"))
    obs = Observations(
        x=xn,
        t=tm,
        temp=tp,
        motion=motion,
        spans=spans,
        c0=c0,
        k0=k0,
        theta0=theta0,
        base="full",
        sensor="accel",
        kind="static intervals" if not block else f"blocks of {block}",
        poses_poor=poses_poor,
    )
    obs.notes.extend(det_notes)
    if temp is None:
        obs.notes.append("no temperature column: temperature effects not tested")
    # floors from the base calibration applied to every sample
    res0 = _run_base_only(obs)
    free0 = M.mask()
    norms = []
    for a, b in spans:
        xs = (x[a:b] - c0) / k0
        norms.append(_norm(res0, free0, xs, np.zeros(b - a), np.zeros(b - a)))
    white = white_floor(norms)
    L = int(np.median([b - a for a, b in spans]))
    # the longest rest; among equally long ones (fixed blocks) the stillest
    longest = max(range(m), key=lambda i: (spans[i][1] - spans[i][0], -motion[i]))
    a, b = spans[longest]
    rest = norms[longest]
    if b - a < 2 * L:
        obs.notes.append(
            f"the longest rest ({b - a} samples) is shorter than twice the interval length "
            f"({L}): Allan floor at {(b - a) // 2} samples instead"
        )
        L = (b - a) // 2
    allan = allan_deviation(rest, L)
    if not np.any(np.isfinite([white, allan])):
        return _no_floor(m, spans, source, obs.notes)
    floor = float(np.nanmax([white, allan]))
    res = _run(obs, cands, floor, seed, degree, progress)
    return _finish(obs, res, (white, allan), "mg", source, 1e3)


def _no_floor(m, spans, source, notes) -> Diagnosis:
    """One sample per observation (a pose table, --block 1): no floor to judge effects by; a
    verdict against a NaN floor would be a guess."""
    d = _not_possible(
        "accel",
        m,
        "observations of several samples each",
        f"the {m} observations have {int(np.median([b - a for a, b in spans]))} sample(s) "
        "each (a pose table, or --block 1): the noise floor cannot be measured, so no "
        "effect can be judged against it; diagnose the recording itself (its static "
        "intervals, or --block with the samples per pose)",
        source,
    )
    d.notes.extend(notes)
    return d


def _run_base_only(obs: Observations) -> np.ndarray:
    P = _Problems(obs, obs.tau(), obs.T())
    P.add(obs.theta0, np.ones(obs.m), M.mask(base=obs.base))
    return P.run()[0]["theta"]


# --------------------------------------------------------------------------- magnetometer


REST_TURN_DEG = 5.0
"""A magnetometer's rest turns its field direction by at most this between its first and last
quarters (a still sensor: the noise of two averages, hundredths of a degree); a slow stretch of
a tumble that the detector's threshold lets through turns by 20-140 deg."""


def diagnose_mag(
    data,
    *,
    model: str = "auto",
    t: np.ndarray | None = None,
    temp: np.ndarray | None = None,
    sample_rate: float | None = None,
    max_points: int = 4000,
    candidates: tuple[str, ...] = MAG_CANDIDATES,
    degree: int = 1,
    seed: int = 0,
    progress: bool | None = None,
) -> Diagnosis:
    """Close the loop on a magnetometer free-rotation log (module docstring).

    Observations are samples (every k-th, at most ``max_points``); the error is
    (|m| - radius) / radius. ``model`` is the declared model, one of
    :func:`calib_jax.calibrate_mag`'s kinds: "full" (ellipsoid), "diag" (axis-aligned
    ellipsoid; ``soft_iron`` then tests the cross terms) or "sphere" (hard iron only;
    ``soft_iron`` tests the whole ellipsoid); "auto" (the default) declares the model
    calibrate_mag chooses for the log, so the diagnosis starts from the calibration
    ``calib-jax mag`` gives. Where that model's base does not converge here (a partial tumble),
    the diagnosis starts from the sphere instead, with a note. Floors, from the longest rest if the
    log has one: the per-sample scatter of the calibrated magnitude about a quadratic trend
    (white) and its Allan deviation at one sample; without a rest, the first-difference noise.
    ``progress``: a bar over the rounds, as in :func:`diagnose_accel`.
    """
    candidates = _checked_candidates(candidates, MAG_CANDIDATES)
    from ..mag import calibrate_mag

    x, t_log, temp_log, rate, source = _load(data, "mag")
    t = t_log if t is None else t
    temp = temp_log if temp is None else temp
    sample_rate = sample_rate or rate
    if model not in ("auto", *_ELLIPSOID):
        raise ValueError(f"model must be 'auto', 'full', 'diag' or 'sphere', got {model!r}")
    ok, screen_notes = screen_samples(x, "mag")  # the way in of calibrate_mag
    n = len(x)
    if t is None and not sample_rate:
        screen_notes = [SAMPLE_CLOCK_NOTE, *screen_notes]
    if t is None:
        t = np.arange(n) / (sample_rate or 1.0)
    t = np.asarray(t, float)
    k = max(1, -(-int(ok.sum()) // max_points))
    keep = np.flatnonzero(ok)[::k]
    if len(keep) < MIN_OBSERVATIONS:
        return _not_possible(
            "mag",
            len(keep),
            f"{MIN_OBSERVATIONS} samples",
            f"too few samples ({len(keep)} finite, unsaturated ones)",
            source,
        )
    declared = "declared" if model != "auto" else "calib-jax mag's choice"
    cal = calibrate_mag(x[ok], model=model)
    chose = []
    if model == "auto":  # calib-jax mag's choice (the ROS flight's full ellipsoid was 'not
        # determined' for mag and declared here, fitted without a word)
        model = cal.model
        others = " or ".join(k for k in _ELLIPSOID if k != model)
        chose.append(
            f"declared model: {model}, as calib-jax mag chooses for this log; --model {others} "
            "declares another"
        )
    if cal.status in ("failed", "not_converged"):
        return _not_possible(
            "mag",
            len(keep),
            "a converged ellipsoid fit",
            f"the ellipsoid fit (model {cal.model}, {declared}) is '{cal.status}': "
            + (
                cal.warnings[-1]
                if cal.warnings
                else f"{cal.solver_message}; record more orientations"
            ),
            source,
        )
    loop = functools.partial(
        _mag_loop,
        x,
        ok,
        keep,
        t,
        temp,
        k,
        candidates=candidates,
        sample_rate=sample_rate,
        seed=seed,
        degree=degree,
        progress=progress,
    )
    obs, res, floors = loop(cal, model, chose + screen_notes)
    if not res["base"]["converged"] and declared != "declared" and model != "sphere":
        # calib-jax mag chose an ellipsoid whose base does not converge here (a partial
        # tumble: the YEI 3-Space log of scikit-kinematics, 32 % of the sphere, failed with
        # the full base and pointed at an iteration budget diagnose has not): start from the
        # sphere and test soft iron as an effect instead
        sphere = calibrate_mag(x[ok], model="sphere")
        if sphere.status not in ("failed", "not_converged"):
            note = (
                f"declared model: sphere; the {_ELLIPSOID[model]} base (calib-jax mag's "
                "choice) did not converge on this log, so the diagnosis starts from the sphere "
                f"and tests soft iron as an effect; --model {model} declares that base"
            )
            obs, res, floors = loop(sphere, "sphere", [note, *screen_notes])
    return _finish(obs, res, floors, "% of the field", source, 1e2)


def _mag_loop(
    x, ok, keep, t, temp, k, cal, model, notes, *, candidates, sample_rate, seed, degree, progress
):
    """diagnose_mag's observations from the base calibration ``cal`` (``model``: its kind,
    "sphere", "diag" or "full"), its floors, and the loop's result: (obs, res, (white,
    allan))."""
    W, c, R = np.asarray(cal.soft_iron), np.asarray(cal.center), float(cal.radius)
    k0 = R / np.cbrt(np.linalg.det(W))
    alpha_n = np.linalg.inv(W * k0 / R)
    theta0 = _theta_from_alpha(0.5 * (alpha_n + alpha_n.T), np.zeros(3))
    xn = (x[keep] - c) / k0
    nrm_all = np.linalg.norm((x - c) @ W.T, axis=1) / R
    # motion: rate of change of the direction between neighbouring kept samples
    xs = np.where(ok[:, None], x, np.nan)
    d = np.linalg.norm(np.gradient(xs, axis=0), axis=1) / k0
    obs = Observations(
        x=xn,
        t=t[keep],
        temp=None if temp is None else np.asarray(temp, float)[keep],
        motion=d[keep],
        spans=[(int(i), int(i) + 1) for i in keep],
        c0=c,
        k0=k0,
        theta0=theta0,
        base=model,
        sensor="mag",
        kind=f"samples (every {k})",
    )
    obs.notes.extend(notes)
    cands = tuple(
        cc
        for cc in candidates
        if (temp is not None or not cc.startswith("temperature"))
        and (cc != "soft_iron" or model != "full")
    )
    if temp is None:
        obs.notes.append("no temperature column: temperature effects not tested")
    rep = detect_rest(x, sample_rate=sample_rate, valid=ok)
    # a rest holds the field's direction: a quiet stretch of a slow tumble turns by tens of
    # degrees (a Razor AHRS tumble gave its 'longest rest' a floor above the fit's RMS)
    rests = [
        v
        for v in rep.intervals
        if np.degrees(quarter_turn((x[v.start : v.stop] - c) @ W.T)[0]) <= REST_TURN_DEG
    ]
    if len(rests) < len(rep.intervals):
        obs.notes.append(
            f"{len(rep.intervals) - len(rests)} quiet stretch(es) left out as rests: the field "
            f"direction turns by more than {REST_TURN_DEG:g} deg across them (a slow part of the "
            "tumble)"
        )
    slow = False
    if rests:
        iv = max(rests, key=lambda v: v.n)
        rest = nrm_all[iv.start : iv.stop]
        # per-sample scatter about a quadratic trend, for the noise's correlation (rest_floor),
        # and the Allan deviation at one sample (the observation length)
        white, phi = rest_floor(rest)
        allan = allan_deviation(rest, 1)
        obs.notes.append(
            f"floors from the longest rest, samples {iv.start}-{iv.stop} ({iv.n} samples)"
            + correlated_rest_note(phi, iv.n)
        )
        # white noise gives a lag-1 correlation within about 1 / sqrt(n) of 0
        slow = bool(phi > SLOW_NOISE_LAG1_Z / np.sqrt(iv.n))
        if slow:
            obs.notes.append(
                f"the rest's noise is correlated (lag-1 {phi:.2f}): an effect must also be "
                "significant with that slow noise modelled (a Wald test, honest.sandwich_cov)"
            )
    else:
        white = difference_noise(nrm_all[ok])
        allan = float("nan")
        obs.notes.append("no rest in the log: white floor from first differences, no Allan floor")
    floor = float(np.nanmax([white, allan]))
    res = _run(obs, cands, floor, seed, degree, progress, slow_noise_test=slow)
    return obs, res, (white, allan)
