"""The SciPy anchor of benchmarks/cli.py: a plain script doing what ``calib-jax accel`` and
``calib-jax mag`` do, the way a user would write it without calib_jax (load, detect, fit,
write JSON), so the CLI's wall time has a peer measured in the same run.

    python benchmarks/scipy_anchor.py accel LOG OUT.json   # columns t ax ay az (imu_tk)
    python benchmarks/scipy_anchor.py mag LOG OUT.json     # CSV with mx my mz columns

accel: rests by a 1 s moving variance below ten times its median (imu_tk's rule of a
threshold times the quietest level), runs of at least 1 s, means; paper 1's nine parameters by
``scipy.optimize.least_squares`` (MINPACK LM) on 1 - |a|^2 / g^2 from the unit sphere at the
centroid. mag: the algebraic ellipsoid by linear least squares, refined by least_squares on
|W (m - c)| - 1 with W the symmetric square root. It prints the rms after the fit.
"""

from __future__ import annotations

import json
import sys

import numpy as np
from scipy.optimize import least_squares


def _alpha_inv(p):  # paper 1's symmetric alpha from [ax, ay, az, Sxy, Sxz, Syz]
    a = np.array([[p[0], p[3], p[4]], [p[3], p[1], p[5]], [p[4], p[5], p[2]]])
    return np.linalg.inv(a)


def accel(path: str, out: str) -> None:
    d = np.loadtxt(path)
    t, x = d[:, 0], d[:, 1:4]
    rate = 1.0 / np.median(np.diff(t))
    w = max(3, int(round(rate)))
    c1 = np.cumsum(np.vstack([np.zeros(3), x]), axis=0)
    c2 = np.cumsum(np.vstack([np.zeros(3), x * x]), axis=0)
    var = ((c2[w:] - c2[:-w]) / w - ((c1[w:] - c1[:-w]) / w) ** 2).sum(axis=1)
    quiet = np.zeros(len(x), bool)
    quiet[w // 2 : w // 2 + len(var)] = var < 10 * np.median(var)
    edges = np.flatnonzero(np.diff(np.r_[0, quiet.astype(int), 0]))
    runs = zip(edges[::2], edges[1::2], strict=True)
    means = np.array([x[a:b].mean(0) for a, b in runs if b - a >= w])
    m0 = means.mean(0)
    s = np.sqrt(np.mean(np.sum((means - m0) ** 2, axis=1)))
    xn = (means - m0) / s

    def residual(p):
        a = (xn - p[6:]) @ _alpha_inv(p).T
        return 1.0 - np.sum(a * a, axis=1)

    p0 = np.r_[np.ones(3), np.zeros(6)]
    r = least_squares(residual, p0, method="lm")
    g = 1.0
    params = np.r_[s * r.x[:6] / g, s * r.x[6:] + m0]
    rms = float(np.sqrt(np.mean(residual(r.x) ** 2)) / 2)
    json.dump({"params": params.tolist(), "n_means": len(means), "rms": rms}, open(out, "w"))
    print(f"{len(means)} rests, rms {rms:.3e}")


def mag(path: str, out: str) -> None:
    d = np.genfromtxt(path, delimiter=",", names=True)
    m = np.stack([d["mx"], d["my"], d["mz"]], axis=1)
    m0 = m.mean(0)
    s = np.sqrt(np.mean(np.sum((m - m0) ** 2, axis=1)))
    x, y, z = ((m - m0) / s).T
    D = np.stack([x * x, y * y, z * z, 2 * x * y, 2 * x * z, 2 * y * z, 2 * x, 2 * y, 2 * z], 1)
    v = np.linalg.lstsq(D, np.ones(len(x)), rcond=None)[0]
    A = np.array([[v[0], v[3], v[4]], [v[3], v[1], v[5]], [v[4], v[5], v[2]]])
    c = -np.linalg.solve(A, v[6:])
    M = A / (1.0 + c @ A @ c)
    e, V = np.linalg.eigh(M)
    W0 = V @ np.diag(np.sqrt(np.abs(e))) @ V.T
    iu = np.triu_indices(3)
    xn = (m - m0) / s

    def residual(p):
        W = np.zeros((3, 3))
        W[iu] = p[:6]
        W = W + np.triu(W, 1).T
        return np.linalg.norm((xn - p[6:]) @ W.T, axis=1) - 1.0

    r = least_squares(residual, np.r_[W0[iu], c], method="lm")
    rms = float(np.sqrt(np.mean(residual(r.x) ** 2)))
    json.dump({"params": (r.x).tolist(), "rms": rms, "scale": s}, open(out, "w"))
    print(f"{len(m)} samples, rms {rms:.3e}")


if __name__ == "__main__":
    {"accel": accel, "mag": mag}[sys.argv[1]](sys.argv[2], sys.argv[3])
