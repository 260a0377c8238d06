"""Simulated logs with known truth: the one simulator of calib_jax.

A log is a sequence of static poses (gravity direction fixed in the sensor frame) joined by
hand-held transitions (the direction sweeps to the next pose while the hand adds a smooth
disturbance acceleration). The sensor reads a' = alpha a + beta + noise (paper 1, eq. 1),
optionally rounded to integer counts, and optionally with effects the model lacks (below).
MARG: both sensors along an attitude path (:func:`simulate_marg`), a recording session
(:func:`simulate_session`).

Effects (``effects=`` of :func:`simulate_accel`, :func:`simulate_accel_log` and
:func:`simulate_mag_log`; sizes in units of g or of the field), each in the form
:mod:`calib_jax.diagnose.model` fits it:

=====================  =========================================================
``bias_drift``         bias + d tau, d = ``size`` * (1, -0.7, 0.5), tau in [-1/2, 1/2]
``hard_iron_drift``    the same on the magnetometer centre
``temperature_bias``   bias + c T, T a two-cycle temperature swing scaled to [-1/2, 1/2]
``temperature_scale``  readings * (1 + k T), k = ``size`` * (1, -0.7, 0.5)
``scale_nonlinearity`` y_j + q_j y_j^2 with q = ``size`` * (0.6, -1, 0.8)
``outliers``           three poses disturbed by ``4 size`` along a random direction
``soft_iron``          (magnetometer) a full ellipsoid, declared as a sphere
``periodic_bias``      NOT in the diagnosis's catalogue: bias + ``size`` sin(2 pi 3 tau) on x
=====================  =========================================================

Host-side numpy: simulation makes test data, it is not part of a jitted pipeline.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .models.accel import PARAM_NAMES
from .models.layout import ALPHA_INDEX


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
    temp: np.ndarray | None = None
    """Temperature, degrees C (N,): a two-cycle swing, simulated when ``effects`` is given."""
    effects: tuple[str, ...] = ()
    effect_size: float = 0.0
    noise: float = 0.0
    disturbed: tuple[int, ...] = ()
    """Poses moved by the ``outliers`` effect."""

    @property
    def static(self) -> np.ndarray:
        """True where the sample was recorded at rest."""
        return self.pose >= 0

    @property
    def intervals(self) -> list[tuple[int, int]]:
        """The static poses as sample spans [start, stop)."""
        out = []
        for k in range(int(self.pose.max()) + 1):
            idx = np.flatnonzero(self.pose == k)
            out.append((int(idx[0]), int(idx[-1]) + 1))
        return out

    @property
    def param_names(self) -> tuple[str, ...]:
        return PARAM_NAMES


def alpha_beta(params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Paper 1's nine-vector as the gain matrix alpha (3 x 3, symmetric) and the bias beta;
    the reading is a' = alpha a + beta (numpy; :func:`calib_jax.models.accel.alpha_matrix` is
    the JAX one)."""
    p = np.asarray(params, float)
    return p[ALPHA_INDEX], p[6:9]


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


def pose_path(
    directions: np.ndarray,
    samples_per_pose: int | np.ndarray,
    transition_samples: int | np.ndarray,
    initial_rest: int = 0,
    hand_motion: float = 0.1,
    rng: np.random.Generator | int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """The specific force (in units of g, sensor frame) of a pose-and-move protocol, and the
    pose of each sample (-1 while moving): each unit gravity direction held for its samples
    (the first ``initial_rest`` longer), a slerp to the next over the transition samples plus
    a smooth hand acceleration of peak ``hand_motion`` (none drawn when it is 0)."""
    rng = np.random.default_rng(rng)
    dirs = np.asarray(directions, float)
    hold = np.broadcast_to(np.asarray(samples_per_pose, int), (len(dirs),))
    move = np.broadcast_to(np.asarray(transition_samples, int), (max(len(dirs) - 1, 0),))
    acc, pose = [], []
    for i, d in enumerate(dirs):
        n_hold = int(hold[i]) + (initial_rest if i == 0 else 0)
        acc.append(np.repeat(d[None], n_hold, axis=0))
        pose.append(np.full(n_hold, i))
        if i + 1 < len(dirs) and move[i] > 0:
            s = np.linspace(0.0, 1.0, int(move[i]) + 2)[1:-1]
            path = _slerp(d, dirs[i + 1], s)
            if hand_motion:
                bump = np.sin(np.pi * s)[:, None] * rng.normal(size=3)[None, :]
                path = path + bump * (hand_motion / max(np.abs(bump).max(), 1e-12))
            acc.append(path)
            pose.append(np.full(int(move[i]), -1))
    return np.concatenate(acc), np.concatenate(pose)


def simulate_accel(
    params: np.ndarray,
    directions: np.ndarray | None = None,
    *,
    samples_per_pose: int | np.ndarray = 100,
    transition_samples: int | np.ndarray = 60,
    initial_rest: int = 0,
    noise: float = 1e-3,
    hand_motion: float = 0.1,
    g: float = 1.0,
    sample_rate: float = 100.0,
    quantize: bool = False,
    effects: tuple[str, ...] | None = None,
    effect_size: float = 3e-3,
    rng: np.random.Generator | int = 0,
) -> SimulatedLog:
    """Simulate a multi-position static calibration log.

    Parameters
    ----------
    params : (9,) array
        True parameters (paper 1 order), in input units per reference unit.
    directions : (P, 3) array, optional
        Gravity directions of the poses; default :func:`paper48_directions`.
    samples_per_pose, transition_samples : int or (P,) / (P-1,) int arrays
        Samples held at each pose and spent moving between poses (one number for all, or one
        per pose / per transition: hand-held protocols hold some poses longer).
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
    effects : tuple of str, optional
        Effects the nine-parameter model lacks (module docstring), of size ``effect_size``.
        Given (even empty), the log also gets a temperature column.
    """
    rng = np.random.default_rng(rng)
    params = np.asarray(params, dtype=float)
    dirs = paper48_directions() if directions is None else np.asarray(directions, float)
    dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    alpha, beta = alpha_beta(params)
    a, pose = pose_path(dirs, samples_per_pose, transition_samples, initial_rest, hand_motion, rng)
    t = np.arange(len(a)) / sample_rate
    temp, disturbed = None, ()
    if effects is None:
        raw = (a * g) @ alpha.T + beta
    else:
        tau, temp, T = effect_drivers(t, rng)
        raw, disturbed = read_with_effects(
            a * g, alpha, beta, effects, effect_size, tau, T, rng, pose
        )
    raw = raw + rng.normal(scale=noise, size=a.shape)
    if quantize:
        raw = np.round(raw)
    return SimulatedLog(
        t=t,
        raw=raw,
        params=params,
        g=float(g),
        pose=pose,
        directions=dirs,
        sample_rate=float(sample_rate),
        temp=temp,
        effects=tuple(effects or ()),
        effect_size=float(effect_size) if effects else 0.0,
        noise=float(noise),
        disturbed=disturbed,
    )


# ---------------------------------------------------------------------------------------------
# effects the models lack (module docstring), for the close-the-loop diagnosis's checks

_EFFECT_DIRS = np.array([1.0, -0.7, 0.5])


def effect_drivers(t: np.ndarray, rng) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(tau, temp, T): time scaled to [-1/2, 1/2], a two-cycle temperature swing of 20 C
    around 30 C with a random phase, and that swing scaled to [-1/2, 1/2]."""
    tau = (t - t.min()) / np.ptp(t) - 0.5
    temp = 30 + 10 * np.sin(2 * np.pi * 2 * (tau + 0.5) + rng.uniform(0, 2 * np.pi))
    T = (temp - 0.5 * (temp.max() + temp.min())) / np.ptp(temp)
    return tau, temp, T


def read_with_effects(
    u, alpha, beta, effects, size, tau, T, rng, pose=None
) -> tuple[np.ndarray, tuple[int, ...]]:
    """Readings alpha y + bias (no noise) of true vectors u (N, 3) with the named effects, and
    the poses the ``outliers`` effect moved (it needs ``pose``, the pose of each sample)."""
    y = u.copy()
    if "scale_nonlinearity" in effects:
        y = y + size * np.array([0.6, -1.0, 0.8]) * y**2
    if "temperature_scale" in effects:
        y = y * (1 + size * _EFFECT_DIRS * T[:, None])
    bias = np.broadcast_to(beta, u.shape).copy()
    if "bias_drift" in effects or "hard_iron_drift" in effects:
        bias = bias + size * _EFFECT_DIRS * tau[:, None]
    if "temperature_bias" in effects:
        bias = bias + size * _EFFECT_DIRS * T[:, None]
    if "periodic_bias" in effects:
        bias[:, 0] += size * np.sin(2 * np.pi * 3 * tau)
    x = y @ alpha.T + bias
    disturbed: tuple[int, ...] = ()
    if "outliers" in effects and pose is not None:
        n_poses = pose.max() + 1
        disturbed = tuple(int(p) for p in rng.choice(np.arange(1, n_poses), 3, replace=False))
        for p in disturbed:
            d = rng.normal(size=3)
            x[pose == p] += 4 * size * d / np.linalg.norm(d)
    return x, disturbed


def _random_board(rng) -> np.ndarray:
    """A random nine-parameter calibration: gains 1 +- 0.05, non-orthogonality +- 0.02, bias
    +- 0.05 (the diagnosis's simulated sensors)."""
    return random_params(rng, gain_spread=0.05, nonorth_spread=0.02, bias_spread=0.05)


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
) -> SimulatedLog:
    """A random board (:func:`_random_board`) in ``poses`` uniformly random poses of ``hold``
    samples (the first ``first_hold``, like imu_tk's logs), moves without hand acceleration
    (the diagnosis reads the poses only), with ``effects`` of ``size``."""
    rng = np.random.default_rng(seed)
    params = _random_board(rng)
    dirs = random_directions(poses, rng)
    return simulate_accel(
        params,
        dirs,
        samples_per_pose=hold,
        transition_samples=move,
        initial_rest=first_hold - hold,
        noise=noise,
        hand_motion=0.0,
        sample_rate=rate,
        effects=tuple(effects),
        effect_size=size,
        rng=rng,
    )


def simulate_mag_log(
    effects: tuple[str, ...] = (),
    *,
    size: float = 0.02,
    samples: int = 6000,
    rest: int = 1500,
    rate: float = 50.0,
    noise: float = 5e-3,
    seed: int = 0,
) -> SimulatedLog:
    """A magnetometer of unit field on a random board (alpha, beta as the accelerometer's;
    ``soft_iron`` adds a full ellipsoid): a rest of ``rest`` samples, then
    :func:`tumble_quaternions`'s smooth tumble (one knot every 4 s), with ``effects``
    (``outliers`` left out: a tumble has no poses). ``pose`` is 0 during the rest."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    params = _random_board(rng)
    alpha, b = alpha_beta(params)
    if "soft_iron" in effects:
        alpha = alpha + np.diag(size * np.array([3.0, -2.0, 1.0]))
    n = samples
    quat = tumble_quaternions(n - rest, rng, knots=max(int((n - rest) / rate / 4.0), 2) + 1)
    C = Rotation.from_quat(np.roll(quat, -1, axis=1)).as_matrix()  # body -> nav, (w,x,y,z) in
    h = random_directions(1, rng)[0]
    v = np.concatenate([np.repeat(C[:1], rest, axis=0), C]).transpose(0, 2, 1) @ h  # C' h
    t = np.arange(n) / rate
    tau, temp, T = effect_drivers(t, rng)
    kept = tuple(e for e in effects if e != "outliers")
    x, _ = read_with_effects(v, alpha, b, kept, size, tau, T, rng)
    x = x + noise * rng.normal(size=x.shape)
    pose = np.where(np.arange(n) < rest, 0, -1)
    return SimulatedLog(
        t=t,
        raw=x,
        params=params,
        g=1.0,
        pose=pose,
        directions=h[None],
        sample_rate=float(rate),
        temp=temp,
        effects=tuple(effects),
        effect_size=float(size),
        noise=float(noise),
    )


# ---------------------------------------------------------------------------------------------
# MARG: accelerometer + magnetometer with known ellipsoid, misalignment and attitude


def random_rotation(rng: np.random.Generator | int = 0, max_angle_deg: float = 180.0) -> np.ndarray:
    """A random rotation matrix of angle up to ``max_angle_deg`` about a uniform axis."""
    rng = np.random.default_rng(rng)
    axis = random_directions(1, rng)[0]
    ang = np.deg2rad(rng.uniform(0.0, max_angle_deg))
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(ang * axis).as_matrix()


def random_ellipsoid(
    rng: np.random.Generator | int = 0,
    radius: float = 1.0,
    axis_spread: float = 0.3,
    center_spread: float = 0.5,
) -> tuple[np.ndarray, np.ndarray]:
    """(center, W) of a random ellipsoid: W = R diag(1/k) R' with k in 1 +- axis_spread, so
    raw = W^-1 y + center for y on the sphere of ``radius``; center within +-center_spread
    times the radius."""
    rng = np.random.default_rng(rng)
    R = random_rotation(rng)
    k = 1.0 + rng.uniform(-axis_spread, axis_spread, 3)
    W = (R / k) @ R.T
    c = rng.uniform(-center_spread, center_spread, 3) * radius
    return c, W


def _quat_to_dcm_np(q: np.ndarray) -> np.ndarray:
    """[w, x, y, z] quaternions (..., 4) -> direction cosine matrices (..., 3, 3), by SciPy."""
    from scipy.spatial.transform import Rotation

    q = np.asarray(q, float)
    flat = q.reshape(-1, 4)
    C = Rotation.from_quat(np.concatenate([flat[:, 1:], flat[:, :1]], axis=1)).as_matrix()
    return C.reshape(q.shape[:-1] + (3, 3))


def _dcm_to_quat_np(C: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(C).as_quat()  # x, y, z, w
    q = np.concatenate([q[..., 3:], q[..., :3]], axis=-1)
    return np.where(q[..., :1] < 0, -q, q)


@dataclass(frozen=True)
class SimulatedMARG:
    """A simulated accelerometer + magnetometer log with its truth.

    Frames: the board (body) frame, in which ``quat`` is body -> ENU; the accelerometer frame
    a_s = R_acc_board' a_body; the magnetometer frame m_s = R_mag_board' m_body. The raw
    magnetometer is W^-1 m_s + center (so the ellipsoid calibration recovers W, center).
    """

    acc: np.ndarray
    mag: np.ndarray
    quat: np.ndarray
    acc_true: np.ndarray
    """Noise-free accelerometer in its own frame (g)."""
    mag_true: np.ndarray
    """Noise-free field in the magnetometer frame (field units)."""
    center: np.ndarray
    soft_iron: np.ndarray
    field: float
    dip_deg: float
    R_acc_board: np.ndarray
    R_mag_board: np.ndarray
    sample_rate: float

    @property
    def R_acc_from_mag(self) -> np.ndarray:
        """m in the accelerometer frame = R m (magnetometer frame)."""
        return self.R_acc_board.T @ self.R_mag_board


def tumble_quaternions(n: int, rng: np.random.Generator | int = 0, knots: int = 24) -> np.ndarray:
    """A smooth random tumble through all orientations: slerp between random knots."""
    from scipy.spatial.transform import Rotation, Slerp

    rng = np.random.default_rng(rng)
    key = Rotation.random(knots, random_state=rng)
    return _dcm_to_quat_np(Slerp(np.linspace(0, 1, knots), key)(np.linspace(0, 1, n)).as_matrix())


def plane_turn_quaternions(
    n: int, incline_deg: float = 20.0, incline_azimuth_deg: float = 30.0, turns: float = 1.2
) -> np.ndarray:
    """The board on an inclined plane, turning about its own z axis (paper 2's test motion):
    C = R_incline Rz(psi), psi from 0 to ``turns`` revolutions."""
    from scipy.spatial.transform import Rotation

    az = np.deg2rad(incline_azimuth_deg)
    axis = np.array([np.cos(az), np.sin(az), 0.0])
    R_inc = Rotation.from_rotvec(axis * np.deg2rad(incline_deg))
    psi = np.linspace(0.0, 2 * np.pi * turns, n)
    C = R_inc * Rotation.from_euler("z", psi[:, None])
    return _dcm_to_quat_np(C.as_matrix())


def correlated_noise(
    n: int, sigma: float, corr: float, rng: np.random.Generator | int = 0, dims: int = 3
) -> np.ndarray:
    """(n, dims) stationary AR(1) noise: standard deviation ``sigma``, lag-1 correlation
    ``corr`` per axis (0: white). A hand's acceleration while turning a board, for
    ``simulate_marg(linear_acc=...)``: errors correlated over 1 / (1 - corr) samples, the case
    where a fit's formal standard errors are too small."""
    from scipy.signal import lfilter

    rng = np.random.default_rng(rng)
    e = rng.normal(size=(n, dims)) * sigma * np.sqrt(1.0 - corr**2)
    start = rng.normal(size=dims) * sigma
    x = lfilter([1.0], [1.0, -corr], e, axis=0, zi=(corr * start)[None, :])[0]
    return x


def simulate_marg(
    quat: np.ndarray,
    *,
    center: np.ndarray | None = None,
    soft_iron: np.ndarray | None = None,
    field: float = 45.0,
    dip_deg: float = 65.0,
    R_acc_board: np.ndarray | None = None,
    R_mag_board: np.ndarray | None = None,
    acc_center: np.ndarray | None = None,
    acc_soft_iron: np.ndarray | None = None,
    acc_params: np.ndarray | None = None,
    linear_acc: np.ndarray | None = None,
    acc_noise: float = 2e-3,
    mag_noise: float = 0.2,
    sample_rate: float = 100.0,
    rng: np.random.Generator | int = 0,
) -> SimulatedMARG:
    """Accelerometer (g) and raw magnetometer along an attitude path.

    The accelerometer reads the upward specific force (static: no linear acceleration), the
    magnetometer the field [0, cos dip, -sin dip] * field in ENU, each in its own frame,
    the magnetometer through the ellipsoid (raw = W^-1 m + center), the accelerometer through
    its own (``acc_center``, ``acc_soft_iron``; default none: already calibrated) or through
    paper 1's model (``acc_params``: a' = alpha a + beta), plus white noise. ``linear_acc``
    (N, 3), in g in the accelerometer frame, adds the hand's acceleration to the specific
    force (moves between poses).
    """
    rng = np.random.default_rng(rng)
    C = _quat_to_dcm_np(np.asarray(quat, float))  # body -> nav
    Ra = np.eye(3) if R_acc_board is None else np.asarray(R_acc_board, float)
    Rm = np.eye(3) if R_mag_board is None else np.asarray(R_mag_board, float)
    c = np.zeros(3) if center is None else np.asarray(center, float)
    W = np.eye(3) if soft_iron is None else np.asarray(soft_iron, float)
    d = np.deg2rad(dip_deg)
    g_nav = np.array([0.0, 0.0, 1.0])
    h_nav = field * np.array([0.0, np.cos(d), -np.sin(d)])
    a_body = np.einsum("nji,j->ni", C, g_nav)  # C' g
    m_body = np.einsum("nji,j->ni", C, h_nav)
    a_s = a_body @ Ra  # Ra' a  (row vectors)
    m_s = m_body @ Rm
    raw_m = m_s @ np.linalg.inv(W).T + c
    raw_a = a_s if linear_acc is None else a_s + np.asarray(linear_acc, float)
    if acc_params is not None:
        alpha, beta = alpha_beta(acc_params)
        raw_a = raw_a @ alpha.T + beta
    if acc_soft_iron is not None:
        raw_a = raw_a @ np.linalg.inv(np.asarray(acc_soft_iron, float)).T
    if acc_center is not None:
        raw_a = raw_a + np.asarray(acc_center, float)
    return SimulatedMARG(
        acc=raw_a + rng.normal(scale=acc_noise, size=a_s.shape),
        mag=raw_m + rng.normal(scale=mag_noise, size=raw_m.shape),
        quat=np.asarray(quat, float),
        acc_true=a_s,
        mag_true=m_s,
        center=c,
        soft_iron=W,
        field=float(field),
        dip_deg=float(dip_deg),
        R_acc_board=Ra,
        R_mag_board=Rm,
        sample_rate=float(sample_rate),
    )


# ---------------------------------------------------------------------------------------------
# a recording session: poses held still and hand-held moves, both sensors (the recorder's and
# the simulated serial board's data)


def simulate_session(
    *,
    poses: int = 24,
    hold: float = 1.0,
    move: float = 0.3,
    rate: float = 100.0,
    acc_noise: float = 2e-3,
    mag_noise: float = 0.2,
    field: float = 45.0,
    dip_deg: float = 60.0,
    hand_motion: float = 0.1,
    seed: int = 0,
) -> dict:
    """A board held in ``poses`` static poses (a Fibonacci lattice of gravity directions,
    random heading) for ``hold`` s each, joined by ``move`` s hand-held moves (a slerp plus a
    smooth acceleration of up to ``hand_motion`` g), read by :func:`simulate_marg` with a
    random paper-1 accelerometer (:func:`random_params`) and a random ellipsoid
    (:func:`random_ellipsoid`). Returns t (N,), acc (N, 3) in g, mag (N, 3) in uT, pose (N,)
    (index, -1 while moving) and the truth."""
    from scipy.spatial.transform import Rotation, Slerp

    from .sphere import sphere_cells

    rng = np.random.default_rng(seed)
    params = random_params(rng, gain_spread=0.05, nonorth_spread=0.02, bias_spread=0.05)
    center, W = random_ellipsoid(rng, radius=field, axis_spread=0.2, center_spread=0.5)
    rots = []
    for d in sphere_cells(poses):
        # sensor -> world rotation taking the measured 'up' direction d to world +z
        align, _ = Rotation.align_vectors([[0.0, 0.0, 1.0]], [d])
        rots.append(Rotation.from_euler("z", rng.uniform(0, 2 * np.pi)) * align)
    n_hold, n_move = max(int(round(hold * rate)), 1), max(int(round(move * rate)), 0)
    R_list, pose, bump = [], [], []
    for k in range(poses):
        R_list.append(np.repeat(rots[k].as_matrix()[None], n_hold, axis=0))
        pose.append(np.full(n_hold, k))
        bump.append(np.zeros((n_hold, 3)))
        if k + 1 < poses and n_move:
            s = np.linspace(0.0, 1.0, n_move + 2)[1:-1]
            key = Rotation.concatenate([rots[k], rots[k + 1]])
            R_list.append(Slerp([0.0, 1.0], key)(s).as_matrix())
            pose.append(np.full(n_move, -1))
            b = np.sin(np.pi * s)[:, None] * rng.normal(size=3)[None, :]
            bump.append(b * hand_motion / max(np.abs(b).max(), 1e-12))
    sim = simulate_marg(
        _dcm_to_quat_np(np.concatenate(R_list)),  # sensor -> world: the body -> nav attitude
        center=center,
        soft_iron=W,
        field=field,
        dip_deg=dip_deg,
        acc_params=params,
        linear_acc=np.concatenate(bump),
        acc_noise=acc_noise,
        mag_noise=mag_noise,
        sample_rate=rate,
        rng=rng,
    )
    return {
        "t": np.arange(len(sim.acc)) / rate,
        "acc": sim.acc,
        "mag": sim.mag,
        "pose": np.concatenate(pose),
        "truth": {
            "accel_params": params.tolist(),
            "mag_center": center.tolist(),
            "mag_soft_iron": W.tolist(),
            "field": field,
            "dip_deg": dip_deg,
            "acc_noise": acc_noise,
            "mag_noise": mag_noise,
            "poses": poses,
            "rate": rate,
        },
    }


@dataclass(frozen=True)
class SimulatedIMU:
    """A simulated accelerometer + gyroscope pose-and-turn log with its truth (the imu_tk
    protocol): still poses joined by smooth turns about random body axes."""

    t: np.ndarray
    acc: np.ndarray
    """Raw accelerometer, a' = alpha f + beta + noise, f the specific force in g (N, 3)."""
    gyro: np.ndarray
    """Raw gyro, C^-1 w + b + noise, w the body rate in rad/s (N, 3)."""
    rate_true: np.ndarray
    """w, rad/s (N, 3)."""
    mag: np.ndarray
    """The field in the sensor frame (calibrated, 45 uT, dip 65 deg, 0.2 uT noise) (N, 3)."""
    accel_params: np.ndarray
    gyro_matrix: np.ndarray
    """C, rad/s per raw unit: w = C (raw - b)."""
    gyro_bias: np.ndarray
    pose: np.ndarray
    """Index of the still pose of each sample, -1 while turning (N,)."""
    sample_rate: float
    temp: np.ndarray | None = None
    """Temperature (deg C) of each sample when ``temperature_coefficient`` was given."""


def random_gyro_matrix(
    rng: np.random.Generator | int = 0,
    scale: float = 1.0,
    scale_spread: float = 0.05,
    misalignment: float = 0.02,
) -> np.ndarray:
    """A plausible C: ``scale`` (rad/s per unit) times (1 +- scale_spread) per axis, with
    off-diagonal misalignment terms up to +-``misalignment``."""
    rng = np.random.default_rng(rng)
    C = np.eye(3) + rng.uniform(-misalignment, misalignment, (3, 3)) * (1 - np.eye(3))
    return C * (1.0 + rng.uniform(-scale_spread, scale_spread, 3))[None, :] * scale


def simulate_gyro_log(
    rng: np.random.Generator | int = 0,
    *,
    n_poses: int = 24,
    gyro_matrix: np.ndarray | None = None,
    gyro_bias: np.ndarray | None = None,
    accel_params: np.ndarray | None = None,
    sample_rate: float = 100.0,
    hold_s: float = 2.0,
    turn_s: float = 1.5,
    gyro_noise: float = 0.003,
    accel_noise: float = 0.002,
    axes: np.ndarray | None = None,
    g_sensitivity: np.ndarray | None = None,
    bias_drift: np.ndarray | None = None,
    temperature_coefficient: np.ndarray | None = None,
) -> SimulatedIMU:
    """Still poses of ``hold_s`` joined by turns of ``turn_s``: each turn is about a body axis
    (uniform on the sphere, or drawn from the rows of ``axes``) by 45-135 deg, with a smooth
    rate profile (zero at both ends). The attitude is composed exactly (SciPy), independently
    of calib_jax's integrator. Noise: per-sample standard deviations in rad/s and in g.
    ``g_sensitivity`` G (raw gyro units per m/s^2) adds G f to the raw gyro, f the specific
    force in m/s^2. ``bias_drift`` (raw units per second) adds a bias growing linearly over
    the log; ``temperature_coefficient`` (raw units per deg C) a bias following a temperature
    that warms by 6 deg C and swings +-2 deg C with a 90 s period (returned as ``temp``).
    """
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(rng)
    C = random_gyro_matrix(rng) if gyro_matrix is None else np.asarray(gyro_matrix, float)
    b = rng.uniform(-0.05, 0.05, 3) if gyro_bias is None else np.asarray(gyro_bias, float)
    p = random_params(rng) if accel_params is None else np.asarray(accel_params, float)
    hold, turn = int(round(hold_s * sample_rate)), int(round(turn_s * sample_rate))
    att = Rotation.random(random_state=rng)  # body -> nav
    field = 45.0 * np.array([0.0, np.cos(np.deg2rad(65.0)), -np.sin(np.deg2rad(65.0))])
    f, w, pose, m = [], [], [], []
    for i in range(n_poses):
        n_hold = hold * (3 if i == 0 else 1)
        f.append(np.repeat(att.inv().apply([0.0, 0.0, 1.0])[None], n_hold, axis=0))
        m.append(np.repeat(att.inv().apply(field)[None], n_hold, axis=0))
        w.append(np.zeros((n_hold, 3)))
        pose.append(np.full(n_hold, i))
        if i + 1 == n_poses:
            break
        axis = random_directions(1, rng)[0] if axes is None else axes[rng.integers(len(axes))]
        axis = axis / np.linalg.norm(axis)
        angle = np.deg2rad(rng.uniform(45.0, 135.0)) * rng.choice([-1.0, 1.0])
        u = np.arange(turn) / turn
        theta = angle * (u - np.sin(2 * np.pi * u) / (2 * np.pi))
        rate = angle / (turn / sample_rate) * (1 - np.cos(2 * np.pi * u))
        turned = att * Rotation.from_rotvec(theta[:, None] * axis[None, :])
        f.append(turned.inv().apply([0.0, 0.0, 1.0]))
        m.append(turned.inv().apply(field))
        w.append(rate[:, None] * axis[None, :])
        pose.append(np.full(turn, -1))
        att = att * Rotation.from_rotvec(angle * axis)
    f, w, pose = np.concatenate(f), np.concatenate(w), np.concatenate(pose)
    mag = np.concatenate(m)
    alpha, beta = alpha_beta(p)
    acc = f @ alpha.T + beta + rng.normal(0.0, accel_noise, f.shape)
    gyro = w @ np.linalg.inv(C).T + b + rng.normal(0.0, gyro_noise, w.shape) @ np.linalg.inv(C).T
    if g_sensitivity is not None:
        gyro = gyro + (f * 9.80665) @ np.asarray(g_sensitivity, float).T
    t = np.arange(len(f)) / sample_rate
    if bias_drift is not None:
        gyro = gyro + t[:, None] * np.asarray(bias_drift, float)
    temp = None
    if temperature_coefficient is not None:
        temp = 25.0 + 6.0 * t / t[-1] + 2.0 * np.sin(2 * np.pi * t / 90.0)
        gyro = gyro + (temp - 25.0)[:, None] * np.asarray(temperature_coefficient, float)
    mag = mag + rng.normal(0.0, 0.2, mag.shape)
    return SimulatedIMU(t, acc, gyro, w, mag, p, C, b, pose, sample_rate, temp)
