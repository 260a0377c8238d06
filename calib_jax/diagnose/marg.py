"""Close the loop on a MARG log: the gravity-field angle.

After each sensor is calibrated on its own (accelerometer and magnetometer ellipsoids), the
angle between gravity and the field must be constant (90 deg + dip). The declared model says
the two sensors share a frame and a clock:

    e_i = angle(a(t_i), R P m(t_i + dt)) - theta          (radians)

with R = I, P = I, dt = 0 in the base model (theta alone is fitted). Candidates:

* ``axis_permutation`` (a finding, not a fit): the 48 signed axis permutations are scored by
  the spread of a . P m (:func:`calib_jax.align.permutation_search`); a map other than the
  identity that wins by 3x over the identity and the next map is taken first and reported
  in words (``Diagnosis.findings``);
* ``sensor_misalignment``: R = exp([v]x) (3 parameters) after the best P;
* ``timing_offset``: dt (1 parameter), the magnetometer smoothed over
  :data:`MAG_SMOOTHING` samples and interpolated linearly between them (the full-rate
  series, so dt is not limited to the observation spacing).

The acceptance tests are those of :mod:`calib_jax.diagnose.loop` (BIC, a null test with
block-bootstrapped angle errors put into the accelerometer (:func:`_null_directions`),
plausibility: |R| <= 15 deg beyond the permutation, |dt| <= 0.5 s) and the honest tests of
:mod:`calib_jax.diagnose.honest` (held-out blocks, split halves against honest errors,
Hotelling's T^2) over
:data:`calib_jax.align.JACKKNIFE_BLOCKS` stretches of the log: a tumble's samples are
correlated. The floors come from the longest rest.
"""

from __future__ import annotations

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.spatial.transform import Rotation

from ..align import (
    JACKKNIFE_BLOCKS,
    PERMUTATION_MARGIN,
    permutation_search,
    time_blocks,
)
from ..calibration import FitStatusWarning
from ..lm import lm_solve
from ..progress import finish, progress_bar
from ..rotations import describe_permutation, rotvec_to_dcm
from ..runtime import disk_jit
from ..static import detect_rest
from .floors import allan_deviation, correlated_rest_note, difference_noise, rest_floor
from .honest import HELD_OUT_GAIN, held_out_rms, judge
from .loop import (
    BIC_MIN,
    MIN_OBSERVATIONS,
    NULL_SIMS,
    Diagnosis,
    Observations,
    _not_possible,
    _step,
    _summary,
    driver_designs,
    regress_drivers,
)
from .model import fit_each

N_P = 5  # rotvec (3), theta, dt
SLOTS = {"sensor_misalignment": [0, 1, 2], "timing_offset": [4]}
BOUNDS = {"rotation_deg": 15.0, "dt_s": 0.5}
MAG_SMOOTHING = 1.5
"""Samples: the standard deviation of the Gaussian kernel that smooths the calibrated
magnetometer series before it is interpolated in time. Linear interpolation between noisy
samples averages their noise, so without it the angle's error dips at every half-sample shift
and rises at every whole one: a timing fit started at 0 stopped in the first dip (a 50 ms lead
at 6 mg / 0.6 uT fitted as 19 ms, and rejected), and on clean logs every fit found a dip
(+-5 ms, Hotelling p ~ 0). Over a kernel of 1.5 samples the interpolated noise no longer
depends on the shift: that lead is fitted as 48-52 ms in five of five logs, and a clean log's
offset is no longer significant (p 0.15-0.99 on 20 logs with a 2 deg rotation). A tumble turns
little in 1.5 samples (at 1 rad/s and 20 Hz, 0.075 rad: the smoothed direction is off by
under 0.2 deg)."""


def _interp(t, tm, m):
    return jnp.stack([jnp.interp(t, tm, m[:, j]) for j in range(3)], axis=1)


def angle_residual(p, data):
    """Data rows e_i (radians), then the pinning rows of parameters that are not free."""
    a, t, tm, m, P, free = data
    q = jnp.where(free, p, 0.0)
    mi = _interp(t + q[4], tm, m)
    mi = mi / jnp.linalg.norm(mi, axis=1, keepdims=True)
    Rm = mi @ (rotvec_to_dcm(q[:3]) @ P).T
    c = jnp.sum(a * Rm, axis=1)
    s = jnp.linalg.norm(jnp.cross(a, Rm), axis=1)
    return jnp.concatenate([jnp.arctan2(s, c) - p[3], jnp.where(free, 0.0, p)])


def _fit_one(p0, a, t, tm, m, P, w, free):
    n = a.shape[0]
    data = (a, t, tm, m, P, free)
    res = lm_solve(
        angle_residual,
        p0,
        data,
        weights=jnp.concatenate([w, jnp.ones(N_P, w.dtype)]),
        update_type=1,
        dof=jnp.sum(w > 0) - jnp.sum(free),
        max_iter=100,
        covariance_method="cholesky",
    )
    e = angle_residual(res.params, data)[:n]
    J = jax.jacfwd(angle_residual)(res.params, data)[:n]
    return res.params, res.stderr, res.status, e, J


def _fit_one_reordered(p0, P, w, free, a, t, tm, m):
    return _fit_one(p0, a, t, tm, m, P, w, free)


_compiled = disk_jit(_fit_one_reordered, "diagnose.marg.fit_one")


def _run(rows, t, tm, m):
    """rows: (p0, P, w, free, a) per problem (``a``: the accelerometer's directions at the
    observations), fitted in turn by one compiled fit on the magnetometer series ``m``."""
    p0, Ps, w, fr, As = (np.stack([r[i] for r in rows]) for i in range(5))
    out = fit_each(_compiled, p0, Ps, w, fr, As, shared=(t, tm, m))
    return [_summary(*(o[k] for o in out), w[k], fr[k]) for k in range(len(rows))]


DRIVER_SMOOTHING_S = 0.05
"""Seconds: the Gaussian kernel's standard deviation (at least 3 samples) that smooths the
gravity direction before the structure tests regress the angle's residual on it. The
accelerometer's own noise (a hand's acceleration) is in both the angle and an unsmoothed
direction, so a regression on one fits the other: on simulated clean tumbles with a white
0.02 g hand acceleration, the angle 'followed time' at p 1e-101 (size 0.49 deg) in every
log; with the direction smoothed over 3 samples p was 0.003, over 10 0.02, the size at
chance level."""


HAND_CAUSE = (
    "a hand's acceleration, if the board was turned by hand: correlated over a second or more, "
    "it is a slowly changing offset of the accelerometer, which over {span} the "
    "driver tests cannot tell from a calibration error"
)
"""What the time driver's note adds as a cause, where its size is at most
:data:`HAND_MAX_RAD`. On simulated clean tumbles (30 s, the hand's
0.02 g correlated over 1 s, benchmarks/diagnosis_power.py) the angle follows time at p 1e-5 to
1e-13 in about half of the logs at low noise: the residual is the hand's slow acceleration
seen along a turning direction, e_t = u_t . h_t, the very form of the time driver's vector
columns (u_j x f(t)). No whitening of the angle's residual as a stationary series (AR(1),
ARMA(1,1); branch try/arma11-whitening) separates the two; docs/close_the_loop.md, "Verdicts"."""

HAND_MAX_RAD = 0.1
"""The largest angle error (radians, 5.7 deg) :data:`HAND_CAUSE` is offered for: a hand turning
a board slowly accelerates it by a few hundredths of g, 0.1 g at most (0.1 rad). On a real
MPU-9150 log whose angle followed time by 43.8 deg (a magnetometer far off its sphere) the note
named the hand, which cannot do that."""


def _time_causes(size: float, span: str) -> str:
    """The causes the note of an angle that follows time by ``size`` (radians) offers, over a
    log of ``span``: a calibration error always, a hand's acceleration up to HAND_MAX_RAD."""
    hand = f"; so does {HAND_CAUSE.format(span=span)}" if size <= HAND_MAX_RAD else ""
    return (
        " (an error in either sensor's calibration changes the angle with the board's whole "
        f"orientation, which a tumble turns through in time{hand})"
    )


def _smooth_gravity(Afn: np.ndarray, tm: np.ndarray) -> np.ndarray:
    """The unit gravity direction smoothed over :data:`DRIVER_SMOOTHING_S` (``tm``: the
    samples' times, for the rate)."""
    dt = float(np.median(np.diff(tm))) if len(tm) > 1 else 0.0
    width = DRIVER_SMOOTHING_S / dt if dt > 0 else 0.0
    s = gaussian_filter1d(Afn, max(3.0, width), axis=0, mode="nearest")
    return s / np.linalg.norm(s, axis=1, keepdims=True)


def _angles(a, m):
    return np.arctan2(np.linalg.norm(np.cross(a, m), axis=1), np.sum(a * m, axis=1))


def _null_directions(a, m_full, tm, t_obs, R, dt, theta, eps_obs, rng, L):
    """Accelerometer directions at the observations on the current model (R, dt, theta),
    their angle errors block-bootstrapped from the observation residuals. The errors go into
    the accelerometer, which is never interpolated: a timing candidate on a null log then
    shifts the same magnetometer series as on the data (with the errors in an interpolated
    magnetometer every sub-sample shift averaged them, a gain the data do not have: a 10 ms
    lead failed the null test at BIC gains of 300-400 against nulls' 730-810)."""
    n = len(eps_obs)
    starts = rng.integers(0, n, size=-(-n // L))
    idx = np.concatenate([(np.arange(s, s + L) % n) for s in starts])[:n]
    target = theta + eps_obs[idx]
    ms = np.stack([np.interp(t_obs + dt, tm, m_full[:, k]) for k in range(3)], axis=1)
    Rm = (ms / np.linalg.norm(ms, axis=1, keepdims=True)) @ R.T
    # turn a in the plane (Rm, a) to make the target angle with Rm
    perp = a - np.sum(a * Rm, axis=1, keepdims=True) * Rm
    perp /= np.linalg.norm(perp, axis=1, keepdims=True)
    return np.cos(target)[:, None] * Rm + np.sin(target)[:, None] * perp


def _judge(c, fits, i, nb, cur, held_cur, block, w, P_best, tried):
    """One candidate's round entry: its fit (``fits[i]``), the two halves' fits after it,
    the :data:`JACKKNIFE_BLOCKS` leave-one-block-out fits after those and its null fits after
    those, against the current model ``cur`` and the null baselines' BIC ``nb``; accepted
    when every test passes (the honest tests: :mod:`calib_jax.diagnose.honest`)."""
    fit, h1, h2 = fits[i], fits[i + 1], fits[i + 2]
    jack = fits[i + 3 : i + 3 + JACKKNIFE_BLOCKS]
    nulls = fits[i + 3 + JACKKNIFE_BLOCKS : i + 3 + JACKKNIFE_BLOCKS + NULL_SIMS]
    dbic = cur["bic"] - fit["bic"]
    null_gain = max(nb[k] - f["bic"] for k, f in enumerate(nulls))
    sl = SLOTS[c]
    h = judge(
        fit["theta"][sl],
        h1["theta"][sl],
        h2["theta"][sl],
        np.stack([f["theta"][sl] for f in jack]),
        np.sqrt(h1["stderr"][sl] ** 2 + h2["stderr"][sl] ** 2),
        fit["stderr"][sl],
        tried,
    )
    held = held_out_rms([f["e"] for f in jack], block, w)
    rot = math.degrees(float(np.linalg.norm(fit["theta"][:3])))
    plaus = rot <= BOUNDS["rotation_deg"] and abs(fit["theta"][4]) <= BOUNDS["dt_s"]
    tests = {
        "converged": fit["converged"],
        "bic": dbic > BIC_MIN,
        "held_out": 1 - held / held_cur > HELD_OUT_GAIN,
        "halves": h.pop("halves"),
        "honest": h.pop("honest"),
        "null": dbic > null_gain,
        "plausible": bool(plaus),
    }
    entry = {
        "effect": c,
        "accepted": all(tests.values()),
        "delta_bic": dbic,
        "loo_gain": 1 - fit["loo_rms"] / cur["loo_rms"],
        "held_out_gain": 1 - held / held_cur,
        **h,
        "stderr_formal": fit["stderr"][sl],
        "null_max_delta_bic": null_gain,
        "rms": fit["rms"],
        "loo_rms": fit["loo_rms"],
        "tests": tests,
    }
    if c == "sensor_misalignment":
        entry["permutation"] = describe_permutation(P_best)
        entry["rotation_deg"] = rot
    else:
        entry["dt_s"] = float(fit["theta"][4])
    return entry


def _coefficients(c: str, fit: dict, P, honest: np.ndarray) -> dict:
    """An accepted effect's coefficients for its step: the rotation (after the axis map P) or
    the time offset, with the honest (block jackknife) and the formal standard errors."""
    if c == "sensor_misalignment":
        return {
            "permutation": describe_permutation(P),
            "rotvec_deg": np.degrees(fit["theta"][:3]),
            "rotvec_stderr_deg": np.degrees(honest),
            "rotvec_stderr_formal_deg": np.degrees(fit["stderr"][:3]),
        }
    return {
        "dt_s": float(fit["theta"][4]),
        "dt_stderr_s": float(honest[0]),
        "dt_stderr_formal_s": float(fit["stderr"][4]),
    }


def _permutation_entry(search) -> dict:
    """The permutation search as a round entry (in the JSON whether accepted or not)."""
    return {
        "effect": "axis_permutation",
        "accepted": search.found,
        "permutation": describe_permutation(search.permutation),
        "spread": float(search.spreads[search.index]),
        "spread_as_labelled": search.spread_as_labelled,
        "spread_next": search.spread_next,
        "margin": search.margin,
        "tests": {
            "not_identity": not search.is_identity,
            "margin": search.margin >= PERMUTATION_MARGIN,
        },
    }


def _angle_floors(Af, Afn, Mn, sample_rate) -> tuple[float, float, str]:
    """(white, Allan, note): the gravity-field angle's noise floors over the longest rest,
    or, without a rest, a white floor from first differences and no Allan floor. All three
    series hold the finite rows only, so the rest's indices are theirs (found on the whole
    log with its gaps, they pointed 400 samples off in a log that starts with 400 empty
    rows)."""
    rep = detect_rest(Af, sample_rate=sample_rate)
    if rep.intervals:
        iv = max(rep.intervals, key=lambda v: v.n)
        rest = _angles(Afn[iv.start : iv.stop], Mn[iv.start : iv.stop])
        white, phi = rest_floor(rest)
        note = f"floors from the longest rest ({iv.n} samples)" + correlated_rest_note(phi, iv.n)
        return white, allan_deviation(rest, 1), note
    white = difference_noise(_angles(Afn, Mn))
    note = "no rest in the log: white floor from first differences, no Allan floor"
    return white, float("nan"), note


def diagnose_marg(
    acc: np.ndarray,
    mag: np.ndarray,
    *,
    t: np.ndarray | None = None,
    sample_rate: float | None = None,
    max_points: int = 3000,
    static_tol: float = 0.05,
    seed: int = 0,
    source: str | None = None,
    progress: bool | None = None,
    model: str = "full",
) -> Diagnosis:
    """The loop on simultaneous accelerometer and magnetometer samples (module docstring).

    ``acc`` and ``mag`` are raw (N, 3); each is calibrated first with
    :func:`calib_jax.calibrate_mag` (``sensor="accel"`` for the accelerometer), with the
    ellipsoid ``model`` ("full", "diag", "sphere" or "auto"): a log that turns too little
    for a full ellipsoid, whose fit the verdict then calls failed, can be judged on spheres.
    Observations
    are quasi-static samples (|a| within ``static_tol`` of g), every k-th to at most
    ``max_points``. rms values are in radians (the summary prints degrees). ``progress``: a
    bar over the rounds, as in :func:`calib_jax.diagnose.diagnose_accel`.
    """
    from ..mag import calibrate_mag

    acc = np.asarray(acc, float)
    mag = np.asarray(mag, float)
    if acc.shape != mag.shape or acc.ndim != 2 or acc.shape[1] != 3:
        raise ValueError(f"acc and mag must both be (N, 3), got {acc.shape} and {mag.shape}")
    N = len(acc)
    timed = t is not None or bool(sample_rate)  # else t counts samples
    t = np.arange(N) / (sample_rate or 1.0) if t is None else np.asarray(t, float)
    ok = np.all(np.isfinite(acc), axis=1) & np.all(np.isfinite(mag), axis=1)
    with warnings.catch_warnings():  # a failed fit's reasons are in the verdict below
        warnings.simplefilter("ignore", FitStatusWarning)
        ca = calibrate_mag(acc[ok], sensor="accel", field=1.0, model=model)
        cm = calibrate_mag(mag[ok], model=model)
    for name, c in (("accelerometer", ca), ("magnetometer", cm)):
        if c.status in ("failed", "not_converged"):
            return _not_possible(
                "marg",
                int(ok.sum()),
                "a converged ellipsoid for each sensor",
                f"the {name} ellipsoid fit is '{c.status}' ("
                + ("; ".join(c.warnings) or c.solver_message)
                + "); the angle between miscalibrated vectors says nothing about alignment or "
                "timing. Record more orientations (both hemispheres)",
                source,
            )
    A = (acc - ca.center) @ np.asarray(ca.soft_iron).T
    Mg = (mag - cm.center) @ np.asarray(cm.soft_iron).T
    # the full-rate series (finite rows) for interpolation
    tm, Af = t[ok], A[ok]
    Mf = gaussian_filter1d(Mg[ok], MAG_SMOOTHING, axis=0, mode="nearest")
    na = np.linalg.norm(Af, axis=1)
    quiet = np.abs(na - 1.0) < static_tol
    k = max(1, -(-int(quiet.sum()) // max_points))
    keep = np.flatnonzero(quiet)[::k]
    keep = keep[(keep > 0) & (keep < len(tm) - 1)]  # room to interpolate either way
    m = len(keep)
    if m < MIN_OBSERVATIONS:
        return _not_possible(
            "marg",
            m,
            f"{MIN_OBSERVATIONS} quasi-static samples",
            "too few quasi-static samples",
            source,
        )
    a = Af[keep] / na[keep, None]
    tob = tm[keep]
    Mn = Mf / np.linalg.norm(Mf, axis=1, keepdims=True)
    Afn = Af / na[:, None]
    eye = np.eye(3)
    theta0 = float(np.mean(_angles(a, Mn[keep])))
    base_free = np.array([False, False, False, True, False])
    w = np.ones(m)
    [base] = _run([(np.array([0, 0, 0, theta0, 0.0]), eye, w, base_free, a)], tob, tm, Mf)
    # permutation search for the misalignment candidate
    search = permutation_search(a, Mn[keep])
    P_best = search.permutation
    notes = ["angles in radians in the JSON; the summary prints degrees"]
    perm = _permutation_entry(search)
    order = np.arange(m)
    first = (order * 8 // m) % 2 == 0
    block = time_blocks(m)  # contiguous in time
    rng = np.random.default_rng(seed)
    L = max(1, int(round(m ** (1 / 3))))
    cur, free, P_cur, effects, steps, rounds = base, base_free.copy(), eye, [], [], []
    steps.append(_step("base", base, 0))
    findings = []
    if search.found:
        # a discrete finding, taken before the rounds: the candidates then fit what is left
        P_cur = P_best
        th0 = np.array([0, 0, 0, float(np.mean(_angles(a, Mn[keep] @ P_best.T))), 0.0])
        [cur] = _run([(th0, P_best, w, base_free, a)], tob, tm, Mf)
        effects.append("axis_permutation")
        steps.append(_step("base+axis_permutation", cur, 0, effect="axis_permutation"))
        steps[-1]["coefficients"] = {"permutation": perm["permutation"]}
        findings.append(search.finding())
    remaining = ["sensor_misalignment", "timing_offset"]
    bar = progress_bar(2, progress, "diagnosing marg", unit="round")
    for _ in range(2):
        bar.set_postfix_str(f"{len(remaining)} candidates, {NULL_SIMS} null fits each")
        rows, idx = [], {}
        th = cur["theta"]
        R_cur = Rotation.from_rotvec(np.array(th[:3] * free[:3])).as_matrix() @ P_cur
        nulls = [
            _null_directions(a, Mf, tm, tob, R_cur, th[4] * free[4], th[3], cur["e"], rng, L)
            for _ in range(NULL_SIMS)
        ]
        for c in remaining:
            fc = free.copy()
            fc[SLOTS[c]] = True
            P = P_best if c == "sensor_misalignment" else P_cur
            idx[c] = len(rows)
            rows += [(th, P, w, fc, a), (th, P, w * first, fc, a), (th, P, w * ~first, fc, a)]
            rows += [(th, P, w * (block != b), fc, a) for b in range(JACKKNIFE_BLOCKS)]
            rows += [(th, P, w, fc, an) for an in nulls]
        nb0 = len(rows)
        rows += [(th, P_cur, w, free, an) for an in nulls]
        jb0 = len(rows)  # the current model without each block: its held-out errors
        rows += [(th, P_cur, w * (block != b), free, a) for b in range(JACKKNIFE_BLOCKS)]
        fits = _run(rows, tob, tm, Mf)
        nb = [f["bic"] for f in fits[nb0:jb0]]
        held_cur = held_out_rms([f["e"] for f in fits[jb0:]], block, w)
        n = len(remaining)
        log = [_judge(c, fits, idx[c], nb, cur, held_cur, block, w, P_best, n) for c in remaining]
        if not rounds:
            log.insert(0, perm)  # the permutation search, accepted or not, in the JSON
        rounds.append(log)
        bar.update(1)
        accepted = [e for e in log if e["accepted"] and e["effect"] in remaining]
        if not accepted:
            break
        best = max(accepted, key=lambda e: e["delta_bic"])
        c = best["effect"]
        cur = fits[idx[c]]
        free[SLOTS[c]] = True
        if c == "sensor_misalignment":
            P_cur = P_best
        effects.append(c)
        remaining.remove(c)
        steps.append(_step("+".join(["base", *effects]), cur, 0, effect=c))
        steps[-1]["coefficients"] = _coefficients(c, cur, P_cur, best["stderr_honest"])
    finish(bar)
    # floors: the angle over the longest rest, with the final model's rotation
    R_fin = Rotation.from_rotvec(np.array(cur["theta"][:3] * free[:3])).as_matrix() @ P_cur
    Mn = Mn @ R_fin.T
    white, allan, note = _angle_floors(Af, Afn, Mn, sample_rate)
    notes.append(note)
    floor = float(np.nanmax([white, allan]))

    rms_before = base["rms"]
    rms_after = cur["rms"]
    dip = math.degrees(cur["theta"][3]) - 90.0
    notes.append(f"dip {dip:.2f} deg (angle between gravity and field minus 90)")
    # structure left in the angle: time, orientation of gravity, motion (rate of change of a)
    tau = (tob - tob.min()) / max(np.ptp(tob), 1e-12) - 0.5
    rate = np.linalg.norm(np.gradient(Afn, axis=0), axis=1)[keep]
    span = f"{np.ptp(tob):.0f} s" if timed else f"{N} samples"  # the log's length
    structure = regress_drivers(
        cur["e"], driver_designs(_smooth_gravity(Afn, tm)[keep], tau, None, rate), floor
    )
    for s_ in structure:
        if s_["above_floor"]:
            notes.append(
                f"the angle follows {s_['driver']} (p = {s_['p_value']:.1e}, size "
                f"{math.degrees(s_['size']):.3g} deg) and no catalogue effect explains it"
                + (_time_causes(s_["size"], span) if s_["driver"] == "time" else "")
            )
    excess = rms_after > 2 * floor or any(s_["above_floor"] for s_ in structure)
    if rms_after > 2 * floor:
        notes.append(
            f"rms after ({math.degrees(rms_after):.3g} deg) is {rms_after / floor:.1f}x the "
            "floor: the angle still varies more than noise (motion, disturbed field, or "
            "calibration errors of either sensor)"
        )
    elif rms_after <= 1.5 * floor and not excess:
        notes.append("at the noise floor: nothing beyond noise")
    obs = Observations(
        x=a,
        t=tob,
        temp=None,
        motion=np.zeros(m),
        spans=[(int(i), int(i) + 1) for i in keep],
        c0=np.zeros(3),
        k0=1.0,
        theta0=np.zeros(5),
        base="marg",
        sensor="marg",
        kind=f"quasi-static samples (every {k})",
    )
    return Diagnosis(
        sensor="marg",
        verdict="unexplained_structure" if excess else ("effects_added" if effects else "at_floor"),
        steps=steps,
        effects=effects,
        rms_before=rms_before,
        rms_after=rms_after,
        noise_floor=floor,
        noise_floor_white=white,
        noise_floor_allan=allan,
        unexplained_structure=bool(excess),
        structure=structure,
        notes=notes,
        rejected=[],
        rounds=rounds,
        groups={},
        n_observations=m,
        observations=obs.kind,
        units="radians (angle between gravity and field)",
        source=source,
        findings=findings,
        obs=obs,
        theta_base=base["theta"],
        theta_final=cur["theta"],
        free_base=base_free,
        free_final=free,
        weights_final=w,
        e_base=base["e"],
        e_final=cur["e"],
    )
