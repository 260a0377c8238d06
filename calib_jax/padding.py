"""Pad sample arrays to power-of-two lengths so that jitted fits of similar logs share one
compilation (the padding carries weight 0, or is sliced off)."""

from __future__ import annotations

import numpy as np


def bucket(n: int) -> int:
    """The padded length for n samples: the next power of two, at least 64."""
    return max(64, 1 << int(np.ceil(np.log2(max(n, 1)))))


def pad_rows(x: np.ndarray, size: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(x padded to ``bucket(len(x))`` rows by repeating its first row, weights 1 / 0)."""
    n = len(x)
    size = bucket(n) if size is None else size
    xp = np.concatenate([np.asarray(x), np.repeat(np.asarray(x)[:1], size - n, axis=0)])
    w = np.zeros(size)
    w[:n] = 1.0
    return xp, w
