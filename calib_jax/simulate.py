"""Simulated accelerometer logs with known truth.

A log is a sequence of static poses (gravity direction fixed in the sensor frame) joined by
hand-held transitions (the direction sweeps to the next pose while the hand adds a smooth
disturbance acceleration). The sensor reads a' = alpha a + beta + noise (paper 1, eq. 1),
optionally rounded to integer counts.

Host-side numpy: simulation makes test data, it is not part of a jitted pipeline.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .models.accel import PARAM_NAMES


def paper48_directions() -> np.ndarray:
    """48 gravity directions covering the sphere, for paper 1's 48-pose protocol.

    Paper 1 tilts the sensor to 48 angles on a rig; the angles are not listed, so this uses
    8 azimuths (45 degrees apart) at 6 elevations (+-15, +-45, +-75 degrees), the azimuths of
    neighbouring bands offset by 22.5 degrees. Returns unit vectors (48, 3).
    """
    dirs = []
    for k, el in enumerate((-75.0, -45.0, -15.0, 15.0, 45.0, 75.0)):
        for j in range(8):
            az = np.deg2rad(45.0 * j + 22.5 * (k % 2))
            e = np.deg2rad(el)
            dirs.append([np.cos(e) * np.cos(az), np.cos(e) * np.sin(az), np.sin(e)])
    return np.asarray(dirs)


def random_directions(n: int, rng: np.random.Generator | int = 0) -> np.ndarray:
    """n unit vectors uniformly distributed on the sphere."""
    rng = np.random.default_rng(rng)
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def random_params(
    rng: np.random.Generator | int = 0,
    gain_spread: float = 0.05,
    nonorth_spread: float = 0.02,
    bias_spread: float = 0.05,
    scale: float = 1.0,
) -> np.ndarray:
    """A plausible true parameter vector: gains 1 +- gain_spread, etc., times ``scale``.

    ``scale`` turns the model into raw counts (counts per reference unit); the bias is then in
    counts as well.
    """
    rng = np.random.default_rng(rng)
    gains = 1.0 + rng.uniform(-gain_spread, gain_spread, 3)
    nonorth = rng.uniform(-nonorth_spread, nonorth_spread, 3)
    bias = rng.uniform(-bias_spread, bias_spread, 3)
    return np.concatenate([gains, nonorth, bias]) * scale


@dataclass(frozen=True)
class SimulatedLog:
    """A simulated log and the truth behind it."""

    t: np.ndarray
    """Time in seconds, (N,)."""
    raw: np.ndarray
    """Sensor readings a', (N, 3)."""
    params: np.ndarray
    """True parameter vector (paper 1 order, see ``PARAM_NAMES``)."""
    g: float
    """Reference magnitude used to simulate."""
    pose: np.ndarray
    """Index of the static pose each sample belongs to, -1 during transitions, (N,)."""
    directions: np.ndarray
    """Unit gravity direction of each pose in the sensor frame, (P, 3)."""
    sample_rate: float

    @property
    def static(self) -> np.ndarray:
        """True where the sample was recorded at rest."""
        return self.pose >= 0

    @property
    def param_names(self) -> tuple[str, ...]:
        return PARAM_NAMES


def _slerp(a: np.ndarray, b: np.ndarray, s: np.ndarray) -> np.ndarray:
    cos = np.clip(a @ b, -1.0, 1.0)
    ang = np.arccos(cos)
    if ang < 1e-9:
        return np.repeat(a[None], len(s), axis=0)
    if np.pi - ang < 1e-6:  # antipodal: go round through any perpendicular direction
        perp = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(perp) < 1e-6:
            perp = np.cross(a, [0.0, 1.0, 0.0])
        perp /= np.linalg.norm(perp)
        th = s[:, None] * np.pi
        return np.cos(th) * a + np.sin(th) * perp
    sa = np.sin(ang)
    return (np.sin((1 - s) * ang)[:, None] * a + np.sin(s * ang)[:, None] * b) / sa


def simulate_accel(
    params: np.ndarray,
    directions: np.ndarray | None = None,
    *,
    samples_per_pose: int = 100,
    transition_samples: int = 60,
    initial_rest: int = 0,
    noise: float = 1e-3,
    hand_motion: float = 0.1,
    g: float = 1.0,
    sample_rate: float = 100.0,
    quantize: bool = False,
    rng: np.random.Generator | int = 0,
) -> SimulatedLog:
    """Simulate a multi-position static calibration log.

    Parameters
    ----------
    params : (9,) array
        True parameters (paper 1 order), in input units per reference unit.
    directions : (P, 3) array, optional
        Gravity directions of the poses; default :func:`paper48_directions`.
    samples_per_pose, transition_samples : int
        Samples held at each pose and spent moving between poses.
    initial_rest : int
        Extra samples at the first pose (a long rest at the start, like imu_tk's logs).
    noise : float
        White noise standard deviation per axis, in input units.
    hand_motion : float
        Peak disturbance acceleration during transitions, in reference units.
    g : float
        Reference magnitude |a| at rest, in reference units.
    quantize : bool
        Round readings to integers (raw counts).
    """
    rng = np.random.default_rng(rng)
    params = np.asarray(params, dtype=float)
    dirs = paper48_directions() if directions is None else np.asarray(directions, float)
    dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    alpha = np.array(
        [
            [params[0], params[3], params[4]],
            [params[3], params[1], params[5]],
            [params[4], params[5], params[2]],
        ]
    )
    beta = params[6:9]
    acc, pose = [], []
    for i, d in enumerate(dirs):
        n_hold = samples_per_pose + (initial_rest if i == 0 else 0)
        acc.append(np.repeat(d[None] * g, n_hold, axis=0))
        pose.append(np.full(n_hold, i))
        if i + 1 < len(dirs) and transition_samples > 0:
            s = np.linspace(0.0, 1.0, transition_samples + 2)[1:-1]
            path = _slerp(d, dirs[i + 1], s) * g
            bump = np.sin(np.pi * s)[:, None] * rng.normal(size=3)[None, :]
            bump *= hand_motion * g / max(np.abs(bump).max(), 1e-12)
            acc.append(path + bump)
            pose.append(np.full(transition_samples, -1))
    a = np.concatenate(acc)
    raw = a @ alpha.T + beta + rng.normal(scale=noise, size=a.shape)
    if quantize:
        raw = np.round(raw)
    t = np.arange(len(raw)) / sample_rate
    return SimulatedLog(
        t=t,
        raw=raw,
        params=params,
        g=float(g),
        pose=np.concatenate(pose),
        directions=dirs,
        sample_rate=float(sample_rate),
    )
