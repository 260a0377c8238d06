"""The sphere of directions on the host (numpy only): equal-area cells and coverage.

One home for the coverage measure every command reports (:func:`sphere_coverage`, used by the
ellipsoid fit, the recorder's live feedback and the figures' gap map).
"""

from __future__ import annotations

import numpy as np


def sphere_cells(cells: int = 100) -> np.ndarray:
    """Centres (cells, 3) of ``cells`` equal-area cells: a Fibonacci lattice; a direction
    belongs to the cell whose centre is nearest."""
    k = np.arange(cells) + 0.5
    z = 1.0 - 2.0 * k / cells
    phi = np.pi * (1.0 + 5**0.5) * k
    rz = np.sqrt(1.0 - z * z)
    return np.stack([rz * np.cos(phi), rz * np.sin(phi), z], axis=1)


def cell_hits(dirs: np.ndarray, cells: int = 100, chunk: int = 1 << 16) -> np.ndarray:
    """Directions (N, 3) per cell of :func:`sphere_cells` (a count per cell). In chunks of
    ``chunk`` directions: the (N, cells) products of a 3-hour 1 kHz log at once were 8.6 GB."""
    dirs, centres = np.asarray(dirs), sphere_cells(cells)
    hits = np.zeros(cells, np.int64)
    for i in range(0, len(dirs), chunk):
        hits += np.bincount(np.argmax(dirs[i : i + chunk] @ centres.T, axis=1), minlength=cells)
    return hits


def sphere_coverage(dirs: np.ndarray, cells: int = 100) -> tuple[float, float, np.ndarray]:
    """Coverage of unit directions (N, 3): the fraction of ``cells`` equal-area cells (a
    Fibonacci lattice) holding at least one direction, the smallest eigenvalue of the
    direction scatter (1/3 uniform, 0 planar) and its eigenvector (the unseen axis)."""
    return coverage_about(np.asarray(dirs), np.zeros(3), cells=cells)


def coverage_about(
    points: np.ndarray,
    centre: np.ndarray,
    W: np.ndarray | None = None,
    *,
    cells: int | None = 100,
    norms_out: np.ndarray | None = None,
    chunk: int = 1 << 16,
) -> tuple[float, float, np.ndarray]:
    """:func:`sphere_coverage` of the directions of W (points - centre) (W None: the
    identity), made ``chunk`` rows at a time: no (N, 3) copy of the points (a 3-hour 1 kHz log
    is 260 MB a copy, and calib-jax mag made three). ``cells`` None skips the cell count
    (fraction NaN: the scatter alone, for the one-plane test); ``norms_out`` (N,) receives
    |W (points - centre)|. Non-finite rows give (0.0, NaN, NaN)."""
    hits = np.zeros(cells or 1, np.int64)
    scatter = np.zeros((3, 3))
    finite = True
    for i in range(0, len(points), chunk):
        d = points[i : i + chunk] - centre
        if W is not None:
            d = d @ np.asarray(W).T
        n = np.sqrt(np.einsum("ij,ij->i", d, d))
        if norms_out is not None:
            norms_out[i : i + chunk] = n
        if not np.all(np.isfinite(n)):
            finite = False
            continue
        d /= np.maximum(n, 1e-300)[:, None]
        if cells:
            hits += cell_hits(d, cells)
        scatter += d.T @ d
    if not finite:
        return 0.0, float("nan"), np.full(3, np.nan)
    evals, evecs = np.linalg.eigh(scatter / len(points))
    frac = np.count_nonzero(hits) / cells if cells else float("nan")
    return frac, float(evals[0]), evecs[:, 0]
