"""Figures, one look for every sensor (CLI ``--plot``, ``calib-jax demo``, notebooks).

Three panels read at a glance:

1. where the data are: the directions on an equal-area map of the sphere (azimuth against
   cos(polar angle), so equal areas look equal), coloured by the error after calibration, with
   the empty cells of the coverage measure (:func:`calib_jax.sphere.sphere_coverage`, 100
   equal-area cells) marked;
2. the error against time (interval or sample order), before and after: drift and outliers
   show here;
3. the error histogram before and after, over the whole range of the data (nothing clipped).

The functions return the matplotlib Figure (no pyplot: the caller's backend is left alone)
and write it to ``path`` when one is given. :func:`view_3d` shows the same points in 3-D for a
notebook (plotly, an optional extra).
"""

from __future__ import annotations

import numpy as np

from .calibration import AccelCalibration, _raw_vectors
from .sphere import cell_hits, sphere_cells


def spherical_angles(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Paper 1 eq. 3-4 (garbled there; the standard form): theta = polar angle from +z,
    phi = azimuth in the xy plane, in degrees."""
    theta = np.degrees(np.arctan2(np.hypot(a[:, 0], a[:, 1]), a[:, 2]))
    phi = np.degrees(np.arctan2(a[:, 1], a[:, 0]))
    return theta, phi


def error_bins(*errors: np.ndarray, max_bins: int = 80) -> np.ndarray:
    """Histogram edges spanning every finite value of all ``errors`` (no clipping)."""
    x = np.concatenate([np.ravel(e) for e in errors])
    x = x[np.isfinite(x)]
    if x.size == 0:
        return np.linspace(-1.0, 1.0, 3)
    lo, hi = float(x.min()), float(x.max())
    if hi <= lo:
        lo, hi = lo - 0.5 * abs(lo or 1.0), hi + 0.5 * abs(hi or 1.0)
    return np.linspace(lo, hi, max_bins + 1)


def _figure(dirs, before, after, *, title: str, path, what: str, order: str, scale, unit):
    """The three panels of the module docstring, titled, written to ``path`` if given."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(15, 4.6))
    _panels(fig, dirs, before, after, what=what, order=order, scale=scale, unit=unit)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig


def _panels(fig, dirs, before, after, *, what: str, order: str, scale: float, unit: str):
    """The three panels of the module docstring on ``fig``."""
    dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    hits = cell_hits(dirs)
    gaps = sphere_cells()[hits == 0]
    th, ph = spherical_angles(dirs)
    ax = fig.add_subplot(1, 3, 1)
    sc = ax.scatter(ph, np.cos(np.radians(th)), c=after * scale, cmap="coolwarm", s=8)
    fig.colorbar(sc, ax=ax, label=f"error after ({unit})")
    if len(gaps):
        gth, gph = spherical_angles(gaps)
        ax.scatter(gph, np.cos(np.radians(gth)), marker="x", color="0.35", s=40, label="empty cell")
        ax.legend(loc="lower left", fontsize=7)
    ax.set_xlim(-180, 180)
    ax.set_ylim(-1, 1)
    ax.set_xlabel("azimuth (deg)")
    ax.set_ylabel("cos(polar angle) (equal area)")
    n_empty = int(np.sum(hits == 0))
    ax.set_title(
        f"coverage {100 - n_empty} % of 100 equal-area cells ({n_empty} empty, x)", fontsize=9
    )
    ax.grid(alpha=0.3)

    ax2 = fig.add_subplot(1, 3, 2)
    k = np.arange(len(after))
    ax2.plot(k, before * scale, ".", ms=3, color="tab:red", label="before")
    ax2.plot(k, after * scale, ".", ms=3, color="tab:blue", label="after")
    ax2.axhline(0, color="0.5", lw=0.6)
    ax2.set_xlabel(order)
    ax2.set_ylabel(f"{what} ({unit})")
    ax2.set_title("error against time", fontsize=9)
    ax2.legend(fontsize=7)

    ax3 = fig.add_subplot(1, 3, 3)
    bins = error_bins(before * scale, after * scale)
    ax3.hist(before * scale, bins=bins, alpha=0.6, color="tab:red", label="before")
    ax3.hist(after * scale, bins=bins, alpha=0.6, color="tab:blue", label="after")
    ax3.set_xlabel(f"{what} ({unit})")
    ax3.set_title("error histogram (full range)", fontsize=9)
    ax3.legend(fontsize=7)
    fig.tight_layout()


def _accel_points(cal: AccelCalibration):
    """Static-interval means before (the nominal conversion) and after calibration, in g."""
    raw_means = cal.static_means
    before = (raw_means - cal.nominal_offset) / cal.nominal_scale / cal.g
    after = cal.apply(raw_means) / cal.g
    title = (
        f"accelerometer: RMS(|a|/g - 1) {cal.rms_before:.2e} -> {cal.rms_after:.2e} over "
        f"{len(after)} static means; status {cal.status}"
    )
    return before, after, title


def _mag_points(cal, raw: np.ndarray, max_points: int = 5000):
    """Samples (at most ``max_points``, evenly spaced in time) before (centred on the mean,
    scaled to its mean norm, as ``rms_before_pct``) and after compensation, in radii."""
    raw = _raw_vectors(raw, cal.sensor)  # an array, a loaded log or its path, as cal.apply
    raw = raw[np.all(np.isfinite(raw), axis=1)]
    raw = raw[:: max(1, len(raw) // max_points)]
    centred = raw - raw.mean(axis=0)
    before = centred / np.linalg.norm(centred, axis=1).mean()
    after = cal.apply(raw) / cal.radius
    title = (
        f"{cal.sensor} ({cal.model} ellipsoid): RMS radial error {cal.rms_before_pct:.2f} % -> "
        f"{cal.rms_after_pct:.2f} % over {cal.n_samples} samples; status {cal.status}"
    )
    return before, after, title


def _radial_error(v: np.ndarray) -> np.ndarray:
    return np.linalg.norm(v, axis=1) - 1.0


def plot_accel(cal: AccelCalibration, path: str | None = None):
    """Static-interval means: directions and gaps, |a|/g - 1 against interval order, and its
    histogram, before (the nominal conversion) and after calibration."""
    before, after, title = _accel_points(cal)
    return _figure(
        after, _radial_error(before), _radial_error(after), title=title, path=path,
        what="|a|/g - 1", order="static interval (time order)", scale=1e3, unit="mg",
    )  # fmt: skip


def plot_mag(cal, raw: np.ndarray, path: str | None = None):
    """Samples (at most 5,000, evenly spaced in time): directions after compensation and
    gaps, |m|/r - 1 against sample order, and its histogram, before (centred on the mean,
    scaled to its mean norm, as ``rms_before_pct``) and after."""
    before, after, title = _mag_points(cal, raw)
    return _figure(
        after, _radial_error(before), _radial_error(after), title=title, path=path,
        what="|m|/r - 1", order="sample (time order)", scale=1e2, unit="%",
    )  # fmt: skip


def view_3d(cal, raw: np.ndarray | None = None, *, max_points: int = 3000):
    """An interactive 3-D view for a notebook (plotly: ``pip install 'calib_jax[interactive]'``).

    The same points as :func:`plot_accel` / :func:`plot_mag` (``raw``: the magnetometer's raw
    samples, at most ``max_points`` shown), in units of the reference: before calibration
    (grey; the accelerometer's nominal conversion, the magnetometer centred and scaled), after
    (coloured by the radial error), the unit sphere they should lie on, and the centres of
    the empty cells of the coverage measure (black x). Turn it to see where the ellipsoid
    was and which directions the log never visited. Returns a ``plotly.graph_objects.Figure``.
    """
    try:
        import plotly.graph_objects as go
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            "view_3d needs plotly: pip install 'calib_jax[interactive]' (or pip install plotly)"
        ) from exc
    if isinstance(cal, AccelCalibration):
        before, after, title = _accel_points(cal)
        scale, unit = 1e3, "mg"
    elif raw is None:
        raise ValueError("view_3d of a magnetometer calibration needs its raw samples: raw=")
    else:
        before, after, title = _mag_points(cal, raw, max_points)
        scale, unit = 1e2, "%"
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 37), np.linspace(0, np.pi, 19))
    sphere = go.Surface(
        x=np.cos(u) * np.sin(v), y=np.sin(u) * np.sin(v), z=np.cos(v), opacity=0.12,
        showscale=False, colorscale=[[0, "lightgrey"], [1, "lightgrey"]], hoverinfo="skip",
        name="unit sphere",
    )  # fmt: skip
    err = _radial_error(after) * scale
    lim = float(np.nanmax(np.abs(err))) if err.size else 1.0
    traces = [
        sphere,
        go.Scatter3d(
            x=before[:, 0], y=before[:, 1], z=before[:, 2], mode="markers", name="before",
            marker=dict(size=2, color="grey", opacity=0.5),
        ),
        go.Scatter3d(
            x=after[:, 0], y=after[:, 1], z=after[:, 2], mode="markers", name="after",
            marker=dict(size=3, color=err, colorscale="RdBu_r", cmin=-lim, cmax=lim,
                        colorbar=dict(title=f"error after ({unit})")),
            hovertemplate="%{marker.color:.3g} " + unit + "<extra>after</extra>",
        ),
    ]  # fmt: skip
    gaps = sphere_cells()[cell_hits(after / np.linalg.norm(after, axis=1, keepdims=True)) == 0]
    if len(gaps):
        traces.append(
            go.Scatter3d(
                x=gaps[:, 0], y=gaps[:, 1], z=gaps[:, 2], mode="markers", name="empty cell",
                marker=dict(size=4, color="black", symbol="x"),
            )
        )  # fmt: skip
    fig = go.Figure(traces)
    fig.update_layout(
        title=dict(text=title, font=dict(size=12)),
        scene=dict(aspectmode="cube", xaxis_title="x", yaxis_title="y", zaxis_title="z"),
        margin=dict(l=0, r=0, t=40, b=0),
        legend=dict(itemsizing="constant"),
    )
    return fig
