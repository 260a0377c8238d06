"""Pad sample arrays to power-of-two lengths so that jitted fits of similar logs share one
compilation (the padding carries weight 0, or is sliced off)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def bucket(n: int) -> int:
    """The padded length for n samples: the next power of two, at least 64."""
    return max(64, 1 << int(np.ceil(np.log2(max(n, 1)))))


def pad_rows(
    x: np.ndarray, size: int | None = None, weights: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(x padded to ``size`` rows (default ``bucket(len(x))``) by repeating its first row, so
    the padding stays finite and in range; the weights: ``weights`` (default 1) on x's rows,
    0 on the padding)."""
    n = len(x)
    size = bucket(n) if size is None else size
    xp = np.concatenate([np.asarray(x), np.repeat(np.asarray(x)[:1], size - n, axis=0)])
    w = np.zeros(size)
    w[:n] = 1.0 if weights is None else np.asarray(weights, float)
    return xp, w


def stack_rows(
    arrays: Sequence[np.ndarray], size: int | None = None, count: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Arrays of different lengths as one stack (count, size, ...): each padded by
    :func:`pad_rows` to ``size`` (default the bucket of the longest), then ``count`` entries
    in all (default one per array; the extra ones zero, with weight 0). Returns the stack and
    its weights (count, size): 1 on data, 0 on padding."""
    size = bucket(max(len(a) for a in arrays)) if size is None else size
    count = len(arrays) if count is None else count
    x = np.zeros((count, size, *np.shape(arrays[0])[1:]))
    w = np.zeros((count, size))
    for i, a in enumerate(arrays):
        x[i], w[i] = pad_rows(a, size)
    return x, w
