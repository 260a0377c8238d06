"""Figures of a diagnosis (``calib-jax diagnose --report DIR``), with matplotlib's object API.

* ``residual_time.png``: the residual against time, before and after, the floors as bands;
* ``residual_sphere.png``: the residual on the sphere of directions (longitude / latitude of
  the calibrated vector), before and after, with the coverage gaps;
* ``residual_motion.png``: the residual against within-observation motion, rejected outliers
  labelled;
* ``angle_time.png`` (MARG, instead of the sphere and motion figures): the gravity-field
  angle over time, before and after;
* ``model_comparison.png``: every candidate of every round with its BIC gain, the best null
  gain, the leave-one-out gain and the split-half z, accepted ones marked.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from .honest import HALVES_Z, HELD_OUT_GAIN
from .loop import Diagnosis, _calibrated


def _scale(d: Diagnosis) -> tuple[float, str]:
    return {"accel": (1e3, "mg"), "mag": (1e2, "% of field")}.get(d.sensor, (180 / np.pi, "deg"))


def _lonlat(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    u = y / np.linalg.norm(y, axis=1, keepdims=True)
    return np.degrees(np.arctan2(u[:, 1], u[:, 0])), np.degrees(np.arcsin(np.clip(u[:, 2], -1, 1)))


def _time_label(d: Diagnosis) -> str:
    """The time axis' label: seconds, or the sample number of a log without a clock."""
    from .loop import SAMPLE_CLOCK_NOTE

    return "sample number (no clock)" if SAMPLE_CLOCK_NOTE in d.notes else "time [s]"


def residual_time(d: Diagnosis) -> Figure:
    f, unit = _scale(d)
    fig = Figure(figsize=(9, 4), layout="constrained")
    ax = fig.add_subplot()
    t = d.obs.t
    act = d.weights_final > 0
    ax.axhspan(-d.noise_floor * f, d.noise_floor * f, color="0.85", label="floor (larger)")
    ax.axhspan(-d.noise_floor_white * f, d.noise_floor_white * f, color="0.7", label="white floor")
    ax.plot(t, d.e_base * f, ".", ms=3, color="tab:red", alpha=0.6, label="base model")
    ax.plot(t[act], d.e_final[act] * f, ".", ms=3, color="tab:blue", label="final model")
    if (~act).any():
        ax.plot(t[~act], d.e_base[~act] * f, "kx", ms=7, label="rejected")
    ax.set_xlabel(_time_label(d))
    ax.set_ylabel(f"{'angle - fitted' if d.sensor == 'marg' else '|y| - 1'} [{unit}]")
    ax.set_title(f"residual against time: {', '.join(d.effects) or 'nothing added'}")
    ax.legend(fontsize=8, loc="upper right")
    return fig


def residual_sphere(d: Diagnosis) -> Figure:
    f, unit = _scale(d)
    o = d.obs
    tau, T = o.tau(), o.T()
    fig = Figure(figsize=(11, 4), layout="constrained")
    lim = np.percentile(np.abs(d.e_base), 98) * f
    for k, (name, theta, free, e) in enumerate(
        [
            ("before (base model)", d.theta_base, d.free_base, d.e_base),
            ("after (final model)", d.theta_final, d.free_final, d.e_final),
        ]
    ):
        ax = fig.add_subplot(1, 2, k + 1)
        lon, lat = _lonlat(_calibrated(theta, free, o.x, tau, T))
        # coverage gaps: 30 x 15 deg cells with no observation
        H, xe, ye = np.histogram2d(lon, lat, bins=[12, 12], range=[[-180, 180], [-90, 90]])
        ax.pcolormesh(xe, ye, (H.T == 0), cmap="Greys", vmin=0, vmax=3, alpha=0.6)
        sc = ax.scatter(lon, lat, c=e * f, s=8, cmap="coolwarm", vmin=-lim, vmax=lim)
        ax.set_xlim(-180, 180)
        ax.set_ylim(-90, 90)
        ax.set_xlabel("longitude of the calibrated vector [deg]")
        ax.set_ylabel("latitude [deg]")
        covered = 100 * np.mean(H > 0)
        ax.set_title(f"{name}; {covered:.0f} % of cells visited (grey: gaps)", fontsize=9)
    fig.colorbar(sc, ax=fig.axes, label=f"|y| - 1 [{unit}]")
    return fig


def residual_motion(d: Diagnosis) -> Figure:
    f, unit = _scale(d)
    fig = Figure(figsize=(6, 4), layout="constrained")
    ax = fig.add_subplot()
    act = d.weights_final > 0
    mo = d.obs.motion * f
    ax.plot(mo[act], d.e_final[act] * f, ".", ms=4, label="kept (final model)")
    for r in d.rejected:
        i = r["index"]
        ax.plot(mo[i], d.e_base[i] * f, "rx", ms=8)
        ax.annotate(f"#{i}", (mo[i], d.e_base[i] * f), fontsize=8, color="r")
    ax.axhspan(-d.noise_floor * f, d.noise_floor * f, color="0.85", zorder=0)
    ax.set_xlabel(f"within-observation motion [{unit}]")
    ax.set_ylabel(f"|y| - 1 [{unit}]")
    ax.set_title("residual against motion (red: rejected, base-model residual)", fontsize=9)
    return fig


def model_comparison(d: Diagnosis) -> Figure:
    skip = ("outliers", "axis_permutation")  # not fits with a BIC: the summary reports them
    rows = [(r, e) for r, log in enumerate(d.rounds) for e in log if e["effect"] not in skip]
    fig = Figure(figsize=(10, 1.2 + 0.35 * max(len(rows), 1)), layout="constrained")
    axs = fig.subplots(1, 4, sharey=True)
    labels = [f"round {r + 1}: {e['effect']}" for r, e in rows]
    y = np.arange(len(rows))
    colours = ["tab:green" if e["accepted"] else "0.6" for _, e in rows]

    def val(e, k):
        v = e.get(k)
        return np.nan if v is None or not np.isfinite(v) else v

    axs[0].barh(y, [val(e, "delta_bic") for _, e in rows], color=colours)
    axs[0].plot([val(e, "null_max_delta_bic") for _, e in rows], y, "k|", ms=12, label="null max")
    axs[0].axvline(10, color="r", lw=0.8)
    axs[0].set_xlabel("BIC gain (| null max)")
    axs[0].set_xscale("symlog")
    # the honest tests run only for candidates that passed BIC, null and plausibility
    axs[1].barh(y, [100 * val(e, "held_out_gain") for _, e in rows], color=colours)
    axs[1].axvline(100 * HELD_OUT_GAIN, color="r", lw=0.8)
    axs[1].set_xlabel("held-out gain [%]")
    axs[2].barh(y, [val(e, "halves_max_z") for _, e in rows], color=colours)
    axs[2].axvline(HALVES_Z, color="r", lw=0.8)
    axs[2].set_xlabel("split-half max |z| (honest errors)")
    f, unit = _scale(d)
    axs[3].barh(y, [val(e, "rms") * f for _, e in rows], color=colours)
    axs[3].axvline(d.noise_floor * f, color="k", lw=0.8)
    axs[3].set_xlabel(f"rms [{unit}] (| floor)")
    axs[0].set_yticks(y, labels, fontsize=8)
    axs[0].invert_yaxis()
    fig.suptitle("candidates (green: accepted; red lines: thresholds)", fontsize=10)
    return fig


def angle_time(d: Diagnosis) -> Figure:
    """MARG: the gravity-field angle over time, before (same frame and clock) and after."""
    fig = Figure(figsize=(9, 4), layout="constrained")
    ax = fig.add_subplot()
    t = d.obs.t
    for name, theta, e, c in (
        ("before", d.theta_base, d.e_base, "tab:red"),
        ("after", d.theta_final, d.e_final, "tab:blue"),
    ):
        ax.plot(t, np.degrees(theta[3] + e), ".", ms=2, color=c, label=f"{name}")
    ax.set_xlabel(_time_label(d))
    ax.set_ylabel("angle between gravity and field [deg]")
    ax.set_title(f"gravity-field angle: {', '.join(d.effects) or 'nothing added'}", fontsize=9)
    ax.legend(fontsize=8)
    return fig


def write_report(d: Diagnosis, outdir: str | Path) -> list[Path]:
    """Write the figures (PNG) into ``outdir``; returns their paths. A diagnosis that was not
    possible has nothing to draw."""
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    if d.obs is None:
        return []
    paths = []
    figures = (
        [("residual_time", residual_time), ("angle_time", angle_time)]
        if d.sensor == "marg"
        else [
            ("residual_time", residual_time),
            ("residual_sphere", residual_sphere),
            ("residual_motion", residual_motion),
        ]
    )
    for name, fn in [*figures, ("model_comparison", model_comparison)]:
        p = out / f"{name}.png"
        fn(d).savefig(p, dpi=110)
        paths.append(p)
    return paths
