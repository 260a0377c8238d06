"""Figures: static means against the unit sphere, and paper 1's (theta, phi) coverage map."""

from __future__ import annotations

import numpy as np

from .calibration import AccelCalibration


def spherical_angles(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Paper 1 eq. 3-4 (garbled there; the standard form): theta = polar angle from +z,
    phi = azimuth in the xy plane, in degrees."""
    theta = np.degrees(np.arctan2(np.hypot(a[:, 0], a[:, 1]), a[:, 2]))
    phi = np.degrees(np.arctan2(a[:, 1], a[:, 0]))
    return theta, phi


def plot_accel(cal: AccelCalibration, path: str) -> None:
    """Write a two-panel figure to ``path``.

    Left: static-interval means before (nominal conversion) and after calibration, divided by g,
    with the unit sphere. Right: the 2-D projection (theta, phi) of the corrected means,
    showing which orientations the log covers.
    """
    from matplotlib.figure import Figure  # no pyplot: leaves the caller's backend alone

    raw_means = cal.static_means
    before = (raw_means - cal.nominal_offset) / cal.nominal_scale / cal.g
    after = cal.apply(raw_means) / cal.g
    fig = Figure(figsize=(11, 5))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    u, v = np.mgrid[0 : 2 * np.pi : 40j, 0 : np.pi : 20j]
    ax.plot_wireframe(
        np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v), color="0.8", linewidth=0.4
    )
    ax.scatter(*before.T, color="tab:red", s=14, label="raw (nominal scale)")
    ax.scatter(*after.T, color="tab:blue", s=14, label="calibrated")
    ax.set_xlabel("x / g")
    ax.set_ylabel("y / g")
    ax.set_zlabel("z / g")
    ax.set_title(
        f"static means: RMS(|a|/g - 1) {cal.rms_before:.2e} -> {cal.rms_after:.2e}", fontsize=9
    )
    ax.legend(loc="upper left", fontsize=8)
    ax2 = fig.add_subplot(1, 2, 2)
    th, ph = spherical_angles(after)
    err = np.linalg.norm(after, axis=1) - 1.0
    sc = ax2.scatter(ph, th, c=err * 1e6, cmap="coolwarm", s=30)
    fig.colorbar(sc, ax=ax2, label="|a|/g - 1 after (ppm)")
    ax2.set_xlim(-180, 180)
    ax2.set_ylim(180, 0)
    ax2.set_xlabel("phi (deg)")
    ax2.set_ylabel("theta (deg)")
    ax2.set_title(f"coverage: {len(after)} static means (paper 1, 2-D projection)", fontsize=9)
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def plot_mag(cal, raw: np.ndarray, path: str) -> None:
    """Paper 2 Fig. 8: raw samples (centred on their mean, scaled to the radius) and the
    compensated ones, with the sphere; plus the histogram of |m| / radius before and after."""
    from matplotlib.figure import Figure  # no pyplot: leaves the caller's backend alone

    raw = np.asarray(raw, float)
    raw = raw[np.all(np.isfinite(raw), axis=1)]
    step = max(1, len(raw) // 3000)
    raw = raw[::step]
    centred = raw - raw.mean(axis=0)
    before = centred / np.linalg.norm(centred, axis=1).mean()
    after = cal.apply(raw) / cal.radius
    fig = Figure(figsize=(11, 5))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    u, v = np.mgrid[0 : 2 * np.pi : 40j, 0 : np.pi : 20j]
    ax.plot_wireframe(
        np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v), color="0.8", linewidth=0.4
    )
    ax.scatter(*before.T, color="tab:blue", s=2, alpha=0.5, label="raw (centred, scaled)")
    ax.scatter(*after.T, color="tab:red", s=2, alpha=0.5, label="compensated")
    ax.set_box_aspect((1, 1, 1))
    ax.set_title(f"{cal.model} ellipsoid, {cal.n_samples} samples", fontsize=9)
    ax.legend(loc="upper left", fontsize=8)
    ax2 = fig.add_subplot(1, 2, 2)
    bins = np.linspace(0.5, 1.5, 101)
    ax2.hist(np.linalg.norm(before, axis=1), bins=bins, alpha=0.6, label="raw")
    ax2.hist(np.linalg.norm(after, axis=1), bins=bins, alpha=0.6, label="compensated")
    ax2.set_xlabel("|m| / radius")
    ax2.set_title(
        f"RMS radial error {cal.rms_before_pct:.2f} % -> {cal.rms_after_pct:.2f} %", fontsize=9
    )
    ax2.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
