"""Paper 1's parameter vector layout, in plain numpy (no JAX import), so that reading,
applying and exporting a saved calibration starts in a fraction of a second.

:mod:`calib_jax.models.accel` re-exports both names; this is their one home.
"""

from __future__ import annotations

import numpy as np

PARAM_NAMES = (
    "alpha_x",
    "alpha_y",
    "alpha_z",
    "S_xy",
    "S_xz",
    "S_yz",
    "beta_x",
    "beta_y",
    "beta_z",
)

ALPHA_INDEX = np.array([[0, 3, 4], [3, 1, 5], [4, 5, 2]])
"""Where alpha's entries sit in paper 1's vector [ax, ay, az, Sxy, Sxz, Syz, bx, by, bz]
(alpha is symmetric): ``p[ALPHA_INDEX]`` is alpha, in JAX or, on the host, in numpy."""

ALPHA_ENTRIES = (np.array([0, 1, 2, 0, 0, 1]), np.array([0, 1, 2, 1, 2, 2]))
"""The way back: ``alpha[ALPHA_ENTRIES]`` is [ax, ay, az, Sxy, Sxz, Syz], the vector's first
six entries (the upper triangle of a symmetric alpha)."""
