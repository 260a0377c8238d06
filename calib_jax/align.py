"""Alignment: sensor-plane alignment (paper 2, section 2.1) and the accel-mag rotation.

Sensor-plane alignment. The board turns about its z axis with its XY plane held on a fixed
plane; every sensor's vector tip then draws a circle in a plane parallel to the board's XY
plane. Fit the plane z = alpha x + beta y + gamma to the tips (eq. 1), take its normal
n = [-alpha, -beta, 1] (eq. 2), and rotate it onto [0, 0, 1]: first about x by eps_x, then
about y by eps_y, giving Align = Ry(eps_y) Rx(eps_x) (eq. 3). A vector that lies along the
turning axis (gravity on a level plane) draws no circle: its mean direction is then the axis.

Accel-mag alignment (beyond the paper). For a static sensor the angle between gravity and the
field is constant, so with unit vectors a_i (accelerometer frame) and m_i (magnetometer frame)
the rotation R (magnetometer -> accelerometer frame) makes angle(a_i, R m_i) = theta for all i.
First the 48 signed axis permutations are scored by the spread of a . P m (chips that mount the
magnetometer with swapped or negated axes show up here), then R = exp([v]x) P and theta are
refined by the LM solver on e_i = angle(a_i, R m_i) - theta. The dip is theta - 90 deg.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np
from scipy.spatial.transform import Rotation

from .lm import lm_solve, status_message
from .padding import pad_rows
from .rotations import describe_permutation, rotation_angle_deg, rotvec_to_dcm, signed_permutations
from .runtime import disk_jit
from .status import fit_status

# ---------------------------------------------------------------------------------------------
# sensor plane alignment: pure parts


def fit_plane(v: jax.Array, w: jax.Array | None = None) -> jax.Array:
    """Least-squares plane z = alpha x + beta y + gamma through points v (N, 3) (paper 2 eq. 1).

    Returns [alpha, beta, gamma]."""
    A = jnp.stack([v[:, 0], v[:, 1], jnp.ones_like(v[:, 0])], axis=1)
    w = jnp.ones(v.shape[0], v.dtype) if w is None else w
    Aw = A * w[:, None]
    return jnp.linalg.solve(Aw.T @ A, Aw.T @ v[:, 2])


def plane_normal(coef: jax.Array) -> jax.Array:
    """Unit normal [-alpha, -beta, 1] / |.| of the plane (paper 2 eq. 2)."""
    n = jnp.stack([-coef[0], -coef[1], jnp.ones_like(coef[0])])
    return n / jnp.linalg.norm(n)


def alignment_angles(n: jax.Array) -> jax.Array:
    """[eps_x, eps_y] (radians): Rx(eps_x) then Ry(eps_y) take the unit normal n to [0,0,1]."""
    ex = jnp.arctan2(n[1], n[2])
    zp = jnp.sqrt(n[1] ** 2 + n[2] ** 2)
    ey = jnp.arctan2(-n[0], zp)
    return jnp.stack([ex, ey])


def alignment_matrix(eps: jax.Array) -> jax.Array:
    """Paper 2 eq. 3: Align = Ry(eps_y) Rx(eps_x)."""
    cx, sx = jnp.cos(eps[0]), jnp.sin(eps[0])
    cy, sy = jnp.cos(eps[1]), jnp.sin(eps[1])
    z = jnp.zeros_like(cx)
    return jnp.stack(
        [
            jnp.stack([cy, sy * sx, sy * cx]),
            jnp.stack([z, cx, -sx]),
            jnp.stack([-sy, sx * cy, cx * cy]),
        ]
    )


@dataclass(frozen=True)
class PlaneAlignment:
    """Result of :func:`plane_alignment` for one sensor."""

    matrix: np.ndarray
    """Align (3 x 3): multiply the sensor's (compensated) vectors by it."""
    eps_x_deg: float
    eps_y_deg: float
    normal: np.ndarray
    """The turning axis in the sensor frame."""
    plane: np.ndarray
    """[alpha, beta, gamma] of z = alpha x + beta y + gamma."""
    circle_radius: float
    """Radius of the circle the tips draw, relative to the mean vector length."""
    out_of_plane: float
    """RMS distance of the tips from the plane, relative to the circle radius."""
    turn_deg: float
    """How much of the circle the tips cover (10-degree bins), degrees."""
    method: str
    """'plane' (paper 2) or 'mean_direction' (the vector lies along the axis)."""
    is_rotation: bool
    message: str
    warnings: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        """JSON-ready fields (arrays as lists; a MARG record keeps its plane alignments so)."""
        d = {f: getattr(self, f) for f in self.__dataclass_fields__}
        return {k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in d.items()}

    @classmethod
    def from_dict(cls, d: dict) -> PlaneAlignment:
        arrays = ("matrix", "normal", "plane")
        return cls(**{k: np.array(v, float) if k in arrays else v for k, v in d.items()})


def _align_from_normal(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    eps = np.asarray(alignment_angles(jnp.asarray(n)))
    return eps, np.asarray(alignment_matrix(jnp.asarray(eps)))


def plane_alignment(
    v: np.ndarray,
    *,
    max_out_of_plane: float = 0.15,
    min_turn_deg: float = 270.0,
    min_circle: float = 0.05,
) -> PlaneAlignment:
    """Paper 2's sensor-plane alignment from a turn about the board's z axis.

    Parameters
    ----------
    v : (N, 3)
        One sensor's vectors during the turn, compensated (ellipsoid) first: the soft-iron
        matrix changes the plane's normal, so align after compensating, as the paper does.
    max_out_of_plane : float
        Largest RMS distance from the plane, relative to the circle's radius, for the
        recording to count as a turn about one axis.
    min_turn_deg : float
        Smallest part of the circle that must be covered.
    min_circle : float
        A circle smaller than this (relative to |v|) means the vector lies along the axis:
        the mean direction is the axis then.

    ``is_rotation`` is False (with the reason in ``message``) when the recording is not such a
    turn; the matrix is still computed, but do not use it.
    """
    v = np.asarray(v, float)
    v = v[np.all(np.isfinite(v), axis=1)]
    if v.ndim != 2 or v.shape[1] != 3 or len(v) < 10:
        raise ValueError(f"need at least 10 finite (N, 3) vectors, got shape {v.shape}")
    scale = float(np.mean(np.linalg.norm(v, axis=1)))
    centroid = v.mean(axis=0)
    spread = float(np.sqrt(np.mean(np.sum((v - centroid) ** 2, axis=1))))
    circle = spread / scale
    warn: list[str] = []
    if circle < min_circle:
        n = centroid / np.linalg.norm(centroid)
        n = n if n[2] >= 0 else -n
        coef = np.array([-n[0] / n[2], -n[1] / n[2], 0.0])
        eps, A = _align_from_normal(n)
        return PlaneAlignment(
            matrix=A,
            eps_x_deg=float(np.degrees(eps[0])),
            eps_y_deg=float(np.degrees(eps[1])),
            normal=n,
            plane=coef,
            circle_radius=circle,
            out_of_plane=float("nan"),
            turn_deg=float("nan"),
            method="mean_direction",
            is_rotation=True,
            message=(
                f"the vector stays within {100 * circle:.1f} % of its length of one direction "
                "(it lies along the turning axis, e.g. gravity on a level plane): its mean "
                "direction is taken as the axis; the turn itself cannot be checked"
            ),
        )
    coef = np.asarray(fit_plane(jnp.asarray(v)))
    n = np.asarray(plane_normal(jnp.asarray(coef)))
    dist = (v - centroid) @ n
    oop = float(np.sqrt(np.mean(dist**2)) / spread)
    # angular coverage around the axis
    e1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    d = v - centroid
    ang = np.degrees(np.arctan2(d @ e2, d @ e1)) % 360.0
    turn = 10.0 * len(np.unique((ang // 10).astype(int)))
    eps, A = _align_from_normal(n)
    problems = []
    if oop > max_out_of_plane:
        problems.append(
            f"the tips leave the plane by {100 * oop:.0f} % of the circle radius (limit "
            f"{100 * max_out_of_plane:.0f} %): the board was not turned about one axis with its "
            "XY plane held on a fixed plane"
        )
    if turn < min_turn_deg:
        problems.append(
            f"the tips cover {turn:.0f} degrees of the circle (need {min_turn_deg:.0f}): turn "
            "the board through a full revolution"
        )
    if abs(n[2]) < 0.5:
        warn.append(
            f"the turning axis {np.round(n, 3)} is far from the sensor's z axis: is this the "
            "right sensor and the right turn?"
        )
    return PlaneAlignment(
        matrix=A,
        eps_x_deg=float(np.degrees(eps[0])),
        eps_y_deg=float(np.degrees(eps[1])),
        normal=n,
        plane=coef,
        circle_radius=circle,
        out_of_plane=oop,
        turn_deg=turn,
        method="plane",
        is_rotation=not problems,
        message="; ".join(problems) if problems else "a turn about one axis",
        warnings=warn,
    )


# ---------------------------------------------------------------------------------------------
# accel-mag alignment


def dip_residual(p: jax.Array, data) -> jax.Array:
    """e_i = angle(a_i, exp([v]x) P m_i) - theta (radians), p = [v (3), theta].

    The angle, not the cosine: a cosine residual a.Rm - cos(theta) weighs a degree by
    sin(theta), so the fit gains by tilting the field towards 0 or 180 degrees from gravity,
    where the cosine is flat (on BROAD it moved the dip by 3 degrees and widened the spread of
    the angle).
    """
    a, m, P = data
    Rm = m @ (rotvec_to_dcm(p[:3]) @ P).T
    c = jnp.sum(a * Rm, axis=1)
    s = jnp.linalg.norm(jnp.cross(a, Rm), axis=1)
    return jnp.arctan2(s, c) - p[3]


@functools.lru_cache(maxsize=8)
def _compiled_dip(max_iter: int):
    def solve(p0, a, m, P, w):
        return lm_solve(dip_residual, p0, (a, m, P), weights=w, update_type=1, max_iter=max_iter)

    return disk_jit(solve, f"align.dip {max_iter}")


JACKKNIFE_BLOCKS = 8
"""Contiguous blocks in time for the honest standard errors (:func:`block_jackknife_cov`)."""
PERMUTATION_MARGIN = 3.0
"""A signed axis permutation other than the identity is a finding when the spread of a . P m
is this many times smaller with it than with the axes as labelled and with the next best
permutation (other than its negative, which gives the same spread)."""


def block_jackknife_cov(estimates: np.ndarray) -> np.ndarray:
    """Covariance from K leave-one-block-out estimates (K, p):
    (K - 1) / K * sum_k (theta_k - mean)(theta_k - mean)'. With blocks longer than the time
    over which the samples are correlated, it sees the correlation that a fit's formal
    covariance (independent samples) does not."""
    k = len(estimates)
    d = estimates - estimates.mean(axis=0)
    return (k - 1) / k * d.T @ d


NEGATIVE_DIP_DEG = 10.0
"""A dip below minus this says the field points up: south of the magnetic equator, or an
accelerometer that reads gravity instead of the specific force (an iPhone 5's CoreMotion
readings gave -52 deg where an Android phone in the same city gave +60, and nothing said why;
a new-user trial on tyrex-team's calibration recordings). The data cannot tell which, so it is
said beside the dip (:func:`dip_reading`), not warned of: a southern site's every log would
warn."""


def dip_reading(dip_deg: float) -> str:
    """What a dip below -:data:`NEGATIVE_DIP_DEG` can mean, for the line that reports it; ''
    otherwise."""
    if not dip_deg < -NEGATIVE_DIP_DEG:
        return ""
    return (
        " (negative: the field points up, as south of the magnetic equator; north of it, "
        "negate an accelerometer that reads gravity rather than the specific force, as iOS's "
        "CoreMotion does, or pass hemisphere='north' for a left-handed magnetometer mount)"
    )


def time_blocks(n: int, k: int = JACKKNIFE_BLOCKS) -> np.ndarray:
    """Block index 0..k-1 of each of n samples in time order (contiguous, equal sizes)."""
    return np.arange(n) * k // max(n, 1)


@dataclass(frozen=True)
class PermutationSearch:
    """The 48 signed axis maps P scored by the spread of a . P m (the gravity-field cosine)."""

    permutation: np.ndarray
    index: int
    spreads: np.ndarray
    spread_as_labelled: float
    spread_next: float
    """The best spread among the maps other than the chosen one and its negative."""
    angle_spreads_deg: tuple[float, float, float]
    """The standard deviation of the gravity-field angle itself (degrees) with the chosen
    map, with the axes as labelled and with the next best map."""

    @property
    def margin(self) -> float:
        best = float(self.spreads[self.index])
        return min(self.spread_as_labelled, self.spread_next) / max(best, 1e-300)

    @property
    def is_identity(self) -> bool:
        return bool(np.allclose(self.permutation, np.eye(3)))

    @property
    def found(self) -> bool:
        """A map other than the identity that wins by :data:`PERMUTATION_MARGIN`."""
        return not self.is_identity and self.margin >= PERMUTATION_MARGIN

    def finding(self) -> str:
        """The finding in plain words (spreads of the angle, degrees, to first order)."""
        best, labelled, nxt = self.angle_spreads_deg
        return (
            "the magnetometer's axes are not the accelerometer's: "
            f"{describe_permutation(self.permutation)} (the angle between gravity and the "
            f"field varies by {best:.2g} deg with this map, {labelled:.2g} deg with the axes "
            f"as labelled and {nxt:.2g} deg with the next best map); map the magnetometer's "
            "axes this way before fusing the two sensors"
        )


def permutation_search(
    a: np.ndarray, m: np.ndarray, hemisphere: str | None = None
) -> PermutationSearch:
    """Score the 48 signed axis permutations P of unit vectors m against unit vectors a by the
    spread of a . P m. P and -P have the same spread: the tie is broken by the dip's sign
    (``hemisphere`` "north": the field points down) or else by det P = +1."""
    if hemisphere not in (None, "north", "south"):
        raise ValueError(f"hemisphere must be 'north', 'south' or None, got {hemisphere!r}")
    Ps = signed_permutations()
    dots = np.einsum("ni,kij,nj->kn", a, Ps, m)
    spreads, means = dots.std(axis=1), dots.mean(axis=1)
    if hemisphere is not None:
        tie = np.where((means < 0) == (hemisphere == "north"), 0.0, 1.0)
    else:
        tie = np.where(np.linalg.det(Ps) > 0, 0.0, 1.0)
    best = int(np.lexsort((tie, np.round(spreads, 12)))[0])
    P = Ps[best]
    same = [i for i, Q in enumerate(Ps) if np.allclose(Q, P) or np.allclose(Q, -P)]
    ident = next(i for i, Q in enumerate(Ps) if np.allclose(Q, np.eye(3)))
    others = np.setdiff1d(np.arange(len(Ps)), same)
    nxt = int(others[np.argmin(spreads[others])])
    angle = [
        float(np.degrees(np.std(np.arccos(np.clip(dots[i], -1, 1))))) for i in (best, ident, nxt)
    ]
    return PermutationSearch(
        permutation=P,
        index=best,
        spreads=spreads,
        spread_as_labelled=float(spreads[ident]),
        spread_next=float(spreads[nxt]),
        angle_spreads_deg=(angle[0], angle[1], angle[2]),
    )


@dataclass(frozen=True)
class MagAccelAlignment:
    """Rotation from the magnetometer frame to the accelerometer frame: m_acc = R m_mag."""

    R_acc_from_mag: np.ndarray
    permutation: np.ndarray
    """The signed axis permutation found first (identity when the axes already agree)."""
    permutation_text: str
    rotation_deg: float
    """Angle of R P^T: the small rotation left after the permutation, degrees."""
    dip_deg: float
    """Inclination of the field (theta - 90 deg, positive: field points down)."""
    dip_stderr_deg: float
    spread_before_deg: float
    """Std of the gravity-field angle over the samples used, before (R = I)."""
    spread_after_deg: float
    rotvec_stderr_deg: np.ndarray
    """Formal standard errors (independent samples): too small for a tumble, whose samples are
    correlated; see the ``*_honest_deg`` fields."""
    n_used: int
    n_total: int
    status: str
    message: str
    permutation_scores: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    dip_stderr_honest_deg: float = float("nan")
    """Block jackknife over :data:`JACKKNIFE_BLOCKS` contiguous stretches of the log: honest
    for correlated samples (on CK-Explorer's tumble 0.10 deg, 4x the formal 0.025 deg)."""
    rotvec_stderr_honest_deg: np.ndarray | None = None
    permutation_found: bool = False
    """The map wins by :data:`PERMUTATION_MARGIN` (:class:`PermutationSearch`)."""

    def apply(self, mag: np.ndarray) -> np.ndarray:
        """Magnetometer vectors expressed in the accelerometer frame."""
        return np.asarray(mag, float) @ self.R_acc_from_mag.T


def _angles_deg(a: np.ndarray, m: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.sum(a * m, axis=1), -1.0, 1.0)))


MIN_SAMPLES = 12
"""Samples the rotation needs at the least: three angles and the dip from the angle between
gravity and the field, with room to see the residual (a 24-pose table is enough; 50 refused
it)."""


def align_mag_to_accel(
    acc: np.ndarray,
    mag: np.ndarray,
    *,
    static_tol: float = 0.05,
    search_permutations: bool = True,
    hemisphere: str | None = None,
    max_iter: int = 100,
) -> MagAccelAlignment:
    """Estimate R (magnetometer -> accelerometer frame) from the constant gravity-field angle.

    Parameters
    ----------
    acc, mag : (N, 3)
        Simultaneous calibrated accelerometer and magnetometer vectors (any units), covering
        many orientations. Samples whose |a| or |m| differs from its median by more than
        ``static_tol`` (relative) are left out: a moving sensor's accelerometer sees more than
        gravity, and a disturbed field changes the angle.
    search_permutations : bool
        Score the 48 signed axis permutations first (swapped or negated magnetometer axes).
    hemisphere : {"north", "south"}, optional
        Where the recording was made (north: the field points down, dip > 0). The angle
        constancy cannot tell P from -P (the angle becomes 180 deg minus itself, the dip
        changes sign), so without it the permutation with det +1 is preferred, which is right
        unless the magnetometer's frame is left-handed against the accelerometer's.
    """
    for name, v in (("acc", acc), ("mag", mag)):
        if hasattr(v, "apply") and not hasattr(v, "__array__"):
            raise TypeError(
                f"align_mag_to_accel takes calibrated samples, got a {type(v).__name__} as "
                f"{name}; pass its output instead, e.g. {name}_cal.apply(raw_{name})"
            )
    acc = np.asarray(acc, float)
    mag = np.asarray(mag, float)
    if acc.shape != mag.shape or acc.ndim != 2 or acc.shape[1] != 3:
        raise ValueError(f"acc and mag must both be (N, 3), got {acc.shape} and {mag.shape}")
    ok = np.all(np.isfinite(acc), axis=1) & np.all(np.isfinite(mag), axis=1)
    na = np.linalg.norm(acc, axis=1)
    nm = np.linalg.norm(mag, axis=1)
    ok &= np.abs(na / np.median(na[ok]) - 1.0) < static_tol
    ok &= np.abs(nm / np.median(nm[ok]) - 1.0) < static_tol
    warn = []
    if ok.sum() < MIN_SAMPLES:
        n_finite = int(np.sum(np.isfinite(na) & np.isfinite(nm)))
        raise ValueError(
            f"only {int(ok.sum())} samples have |a| and |m| within {100 * static_tol:.0f} % of "
            f"their medians (of {n_finite} finite samples; the rotation needs {MIN_SAMPLES}); "
            + (
                "record more orientations"
                if n_finite < MIN_SAMPLES
                else "record slower motion (in Python, align_mag_to_accel's static_tol widens "
                "the band)"
            )
        )
    a = acc[ok] / na[ok, None]
    m = mag[ok] / nm[ok, None]
    # orientation diversity: the rotation is unobservable about a direction all a_i share
    evals = np.linalg.eigvalsh(a.T @ a / len(a))
    if evals[1] < 0.01:
        raise ValueError(
            "gravity stays in about one direction (or one plane) in the sensor frame: the "
            "rotation about it is unobservable. Tilt the sensor through many orientations"
        )
    if hemisphere not in (None, "north", "south"):
        raise ValueError(f"hemisphere must be 'north', 'south' or None, got {hemisphere!r}")
    search = permutation_search(a, m, hemisphere) if search_permutations else None
    # a map is applied only where it wins by the margin the diagnosis asks of a finding: with
    # few samples or little coverage several maps fit about as well, and the best of them
    # means nothing (an Xsens MTi's factory-aligned axes read 'y <- -z, z <- +y' from 61
    # samples at 26 % coverage)
    P = search.permutation if search is not None and search.found else np.eye(3)
    scores = {}
    if search is not None:
        Ps = signed_permutations()
        scores = {
            describe_permutation(Q): float(v) for Q, v in zip(Ps, search.spreads, strict=True)
        }
        spreads = (
            f"spread of a.m {search.spreads[search.index]:.4f} against "
            f"{search.spread_as_labelled:.4f} unpermuted and {search.spread_next:.4f} for the "
            "next map"
        )
        if search.found:
            warn.append(
                "the magnetometer axes look permuted against the accelerometer: "
                f"{describe_permutation(P)} (det {np.linalg.det(P):+.0f}; {spreads})"
            )
        elif not search.is_identity:
            warn.append(
                f"the map {describe_permutation(search.permutation)} of the magnetometer axes "
                f"fits best ({spreads}), but not {PERMUTATION_MARGIN:g}x better than both the "
                "axes as labelled and the next map: these data cannot tell the maps apart, so "
                "the axes are kept as labelled; tumble through more orientations to decide"
            )
    theta0 = float(np.mean(np.arccos(np.clip(np.sum(a * (m @ P.T), axis=1), -1.0, 1.0))))
    p0 = np.array([0.0, 0.0, 0.0, theta0])
    # pad to a power of two with zero weights: one compilation for logs of similar length
    n = len(a)
    a, w = pad_rows(a)
    m, _ = pad_rows(m)
    solve = _compiled_dip(max_iter)
    args = (a, m, P)  # numpy: the compiled solve puts them on the device
    res = solve(p0, *args, w)
    p = np.asarray(res.params)
    # honest errors: the same fit without each of the contiguous blocks (same shapes: no
    # new compilation), from the full fit's solution
    block = np.concatenate([time_blocks(n), np.full(len(w) - n, -1)])
    jack = np.stack(
        [
            np.asarray(solve(res.params, *args, w * (block != b)).params)
            for b in range(JACKKNIFE_BLOCKS)
        ]
    )
    se_honest = np.degrees(np.sqrt(np.diag(block_jackknife_cov(jack))))
    R = Rotation.from_rotvec(np.array(p[:3])).as_matrix() @ P  # on the host: no eager jnp programs
    theta = np.degrees(p[3])
    se = np.asarray(res.stderr)
    dip_se = float(np.degrees(se[3]))
    a, m = a[:n], m[:n]
    before = _angles_deg(a, m)
    after = _angles_deg(a, m @ R.T)
    status = fit_status(int(res.status), usable=bool(np.all(np.isfinite(p))))
    if status == "ok" and np.any(np.degrees(se[:3]) > 1.0):
        status = "poorly_determined"
        warn.append(
            "the rotation is poorly determined (std. error above 1 degree); cover more orientations"
        )
    dip = float(theta - 90.0)
    return MagAccelAlignment(
        R_acc_from_mag=R,
        permutation=P,
        permutation_text=describe_permutation(P),
        rotation_deg=rotation_angle_deg(R @ P.T),
        dip_deg=dip,
        dip_stderr_deg=dip_se,
        spread_before_deg=float(np.std(before)),
        spread_after_deg=float(np.std(after)),
        rotvec_stderr_deg=np.degrees(se[:3]),
        n_used=int(ok.sum()),
        n_total=len(acc),
        status=status,
        message=status_message(int(res.status)),
        permutation_scores=scores,
        warnings=warn,
        dip_stderr_honest_deg=float(se_honest[3]),
        rotvec_stderr_honest_deg=se_honest[:3],
        permutation_found=bool(search is not None and search.found),
    )
