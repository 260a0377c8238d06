"""Simulated logs with known effects, to check that the loop finds what is there (and only that).

The effects layer of :mod:`calib_jax.simulate` (which gives the poses, the base calibration
and the moves). Accelerometer: ``poses`` static poses of ``hold`` samples at ``rate`` Hz
(uniformly random gravity directions, the first pose ``first_hold`` samples long, like the
rest imu_tk logs start with), joined by short moves (:func:`calib_jax.simulate.pose_path`),
a random nine-parameter base calibration (:func:`calib_jax.simulate.random_params`), white
noise, and any of the effects below added in the same form :mod:`calib_jax.diagnose.model`
fits them.
Magnetometer: a rest, then :func:`calib_jax.simulate.tumble_quaternions`'s smooth tumble, on a
random ellipsoid; ``samples`` samples in all.

Effects (all sizes in units of g or of the field):

=====================  =========================================================
``bias_drift``         bias + d tau, d = ``size`` * (1, -0.7, 0.5), tau in [-1/2, 1/2]
``hard_iron_drift``    the same on the magnetometer centre
``temperature_bias``   bias + c T, T a two-cycle temperature swing scaled to [-1/2, 1/2]
``temperature_scale``  readings * (1 + k T), k = ``size`` * (1, -0.7, 0.5)
``scale_nonlinearity`` y_j + q_j y_j^2 with q = ``size`` * (0.6, -1, 0.8)
``outliers``           three poses disturbed by ``4 size`` along a random direction
``soft_iron``          (magnetometer) a full ellipsoid, declared as a sphere
``periodic_bias``      NOT in the catalogue: bias + ``size`` sin(2 pi 3 tau) on x
=====================  =========================================================
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..simulate import alpha_beta, pose_path, random_directions, random_params, tumble_quaternions

DIRS = np.array([1.0, -0.7, 0.5])


@dataclass
class SimulatedEffectsLog:
    raw: np.ndarray  # (N, 3)
    t: np.ndarray  # (N,) s
    temp: np.ndarray  # (N,) degrees C
    intervals: list[tuple[int, int]]  # the static poses [start, stop)
    effects: tuple[str, ...]
    size: float
    noise: float
    sample_rate: float
    disturbed: tuple[int, ...] = ()  # poses moved by ``outliers``


def _random_base(rng) -> tuple[np.ndarray, np.ndarray]:
    """A random nine-parameter base calibration (gains 1 +- 0.05, non-orthogonality +- 0.02,
    bias +- 0.05), as (alpha, beta)."""
    return alpha_beta(random_params(rng, gain_spread=0.05, nonorth_spread=0.02, bias_spread=0.05))


def _drivers(t, rng):
    tau = (t - t.min()) / np.ptp(t) - 0.5
    temp = 30 + 10 * np.sin(2 * np.pi * 2 * (tau + 0.5) + rng.uniform(0, 2 * np.pi))
    T = (temp - 0.5 * (temp.max() + temp.min())) / np.ptp(temp)
    return tau, temp, T


def _apply(effects, size, u, tau, T, alpha, b, rng, pose_of_sample):
    """Readings x for true unit vectors u (N, 3) with the declared effects."""
    y = u.copy()
    if "scale_nonlinearity" in effects:
        y = y + size * np.array([0.6, -1.0, 0.8]) * y**2
    if "temperature_scale" in effects:
        y = y * (1 + size * DIRS * T[:, None])
    bias = np.broadcast_to(b, u.shape).copy()
    if "bias_drift" in effects or "hard_iron_drift" in effects:
        bias = bias + size * DIRS * tau[:, None]
    if "temperature_bias" in effects:
        bias = bias + size * DIRS * T[:, None]
    if "periodic_bias" in effects:
        bias[:, 0] += size * np.sin(2 * np.pi * 3 * tau)
    x = y @ alpha.T + bias
    disturbed = ()
    if "outliers" in effects and pose_of_sample is not None:
        n_poses = pose_of_sample.max() + 1
        disturbed = tuple(int(p) for p in rng.choice(np.arange(1, n_poses), 3, replace=False))
        for p in disturbed:
            d = rng.normal(size=3)
            x[pose_of_sample == p] += 4 * size * d / np.linalg.norm(d)
    return x, disturbed


def simulate_accel_log(
    effects: tuple[str, ...] = (),
    *,
    size: float = 3e-3,
    poses: int = 60,
    hold: int = 100,
    first_hold: int = 2000,
    move: int = 30,
    rate: float = 100.0,
    noise: float = 2e-3,
    seed: int = 0,
) -> SimulatedEffectsLog:
    rng = np.random.default_rng(seed)
    alpha, b = _random_base(rng)
    dirs = random_directions(poses, rng)
    # the moves carry no hand acceleration: the diagnosis reads the poses only
    u, pose = pose_path(dirs, hold, move, first_hold - hold, hand_motion=0.0, rng=rng)
    first = [int(np.argmax(pose == k)) for k in range(poses)]
    intervals = [(i, i + int(np.sum(pose == k))) for k, i in enumerate(first)]
    t = np.arange(len(u)) / rate
    tau, temp, T = _drivers(t, rng)
    x, disturbed = _apply(effects, size, u, tau, T, alpha, b, rng, pose)
    x = x + noise * rng.normal(size=x.shape)
    return SimulatedEffectsLog(x, t, temp, intervals, tuple(effects), size, noise, rate, disturbed)


def simulate_mag_log(
    effects: tuple[str, ...] = (),
    *,
    size: float = 0.02,
    samples: int = 6000,
    rest: int = 1500,
    rate: float = 50.0,
    noise: float = 5e-3,
    seed: int = 0,
) -> SimulatedEffectsLog:
    rng = np.random.default_rng(seed)
    alpha, b = _random_base(rng)
    if "soft_iron" in effects:
        alpha = alpha + np.diag(size * np.array([3.0, -2.0, 1.0]))
    # the field's direction in the sensor frame: a rest, then the simulator's smooth tumble
    # (slerp between random attitudes, one knot every 4 s)
    n = samples
    quat = tumble_quaternions(n - rest, rng, knots=max(int((n - rest) / rate / 4.0), 2) + 1)
    C = Rotation.from_quat(np.roll(quat, -1, axis=1)).as_matrix()  # body -> nav, (w,x,y,z) in
    h = random_directions(1, rng)[0]
    v = np.concatenate([np.repeat(C[:1], rest, axis=0), C]).transpose(0, 2, 1) @ h  # C' h
    t = np.arange(n) / rate
    tau, temp, T = _drivers(t, rng)
    x, _ = _apply(
        tuple(e for e in effects if e != "outliers"), size, v, tau, T, alpha, b, rng, None
    )
    x = x + noise * rng.normal(size=x.shape)
    return SimulatedEffectsLog(x, t, temp, [(0, rest)], tuple(effects), size, noise, rate)
