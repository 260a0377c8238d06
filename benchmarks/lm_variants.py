"""Levenberg-Marquardt variants on one suite of problems: which update type, rho form and
Jacobian reaches the optimum, how many evaluations it needs and how long a warm solve takes.

    .venv/bin/python benchmarks/lm_variants.py [--seeds 5] [--repeats 5] [--budget 1000]
    .venv/bin/python benchmarks/lm_variants.py --from-json   # rescore, rewrite .md and .png

Variants (15):

- calib_jax ``lm_solve``: update type 1 (Marquardt), 2 (quadratic line search), 3 (Nielsen)
  x Jacobian "exact" (autodiff) or "broyden" (central differences + rank-1 updates) x rho
  "current" (the Gauss-Newton predicted decrease) or "paper" (paper 1 eq. 13), each with the
  library's calibration tolerances (eps1 1e-12, eps2 1e-10, eps3 off);
- optimistix LevenbergMarquardt through ``calib_jax.lm.optx_solve`` (rtol 1e-12, atol 1e-14);
- SciPy ``least_squares`` method "lm" (MINPACK) and "trf" with SciPy's default
  finite-difference Jacobian ("2-point", what a SciPy user writes) and ftol = xtol = gtol =
  --scipy-tol; the residual is the same JAX function, jitted, called with numpy arrays.

Every variant gets the same start and a budget of --budget iterations (calib_jax max_iter,
optimistix max_steps, SciPy max_nfev, which here does not count the finite-difference calls).

Problems (--seeds instances each for the simulated ones):

- accelerometer: paper 1's nine-parameter model and normalised sphere residual, 960 static
  samples: 20 per pose on the 48 poses of ``paper48_directions``, 32 per pose on 30 random
  poses, 20 per pose on 48 random poses in one hemisphere or in a cap of half-angle 60 degrees
  (poorly conditioned); white noise 1e-4, 2e-3, 1e-2 (the 60-degree cap: 1e-4, 2e-3); a random
  truth per seed; the data centred on its mean and divided by its RMS radius; start: calib_jax's
  algebraic ellipsoid (``initial_guess``), plus one set started from the unit sphere;
- ellipsoids: the full quadric model of ``calib_jax.models.mag``, 600 samples, 0.5 % noise,
  full coverage (from the algebraic ellipsoid start and from the algebraic sphere), a
  hemisphere and a 60-degree cap, start ``ellipsoid_start`` unless said otherwise;
- classic nonlinear least squares (More, Garbow, Hillstrom 1981), from x0 and from 10 x0.
  ``lm_solve`` needs more residuals than parameters, so the problems with the same number of
  parameters share one residual function (``lax.switch`` over the problems, padded with
  zero-weight residuals): one compilation per variant and parameter count instead of one per
  problem; the padding changes neither chi2 nor the steps. SciPy gets the unpadded residual;
- ill-posed, reported apart: the 60-degree cap with 1 % noise (accelerometer and ellipsoid).
  chi2 has no minimum there: it falls towards an infinitely large sphere or ellipsoid, so a
  solver either runs away (max |p| > 10 on normalised data) or stops early; not scored.

Success at matched final chi2: a run succeeds when the solver says it converged (a calib_jax
converged status, optimistix ``successful``, SciPy ``success``) and its chi2 <= best * (1 +
1e-8) + 1e-14, best being the lowest chi2 any variant reached on that instance (chi2 = sum of
squared residuals at the returned parameters).

Reported per variant: the success rate; medians over all runs of a group of the trial steps
(calib_jax and optimistix), nfev (residual evaluations, finite-difference columns included;
for optimistix its step count: one evaluation and one linearisation per step) and njev
(Jacobian evaluations: autodiff for exact, finite differences for broyden and SciPy; SciPy's
lm does not report it), and of the warm time per solve (each JAX variant compiled once per
problem shape, ahead of time; the median of up to --repeats calls after one untimed call). The
machine is shared: read the times as medians and ratios.

Writes benchmarks/results/lm_variants.json, lm_variants.md and lm_variants.png.
"""

from __future__ import annotations

import argparse
import itertools
import json
import platform
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import optimistix  # noqa: E402
import scipy  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402

from calib_jax.accel import initial_guess  # noqa: E402
from calib_jax.geometry import sphere_fit  # noqa: E402
from calib_jax.lm import Status, is_converged, lm_solve, optx_solve  # noqa: E402
from calib_jax.mag import ellipsoid_start  # noqa: E402
from calib_jax.models.accel import distort, normalized_sphere_residual  # noqa: E402
from calib_jax.models.mag import pack, quadric_residual  # noqa: E402
from calib_jax.simulate import (  # noqa: E402
    paper48_directions,
    random_directions,
    random_ellipsoid,
    random_params,
)

CHI2_REL = 1e-8
CHI2_ABS = 1e-14
N_ACCEL = 960
N_ELLIPSOID = 600
NOISE_ELLIPSOID = 5e-3
GROUPS = ("accel", "ellipsoid", "classic")
"""Scored groups; the "ill-posed" instances are reported apart."""
RUNAWAY = 10.0
"""A fit of normalised data (true parameters below 3 in size) that ends with max |p| above this
ran away towards the unbounded infimum of a cap problem."""
RUN_COLUMNS = [
    "variant",
    "group",
    "problem",
    "instance",
    "status",
    "converged",
    "success",
    "chi2",
    "best_chi2",
    "iterations",
    "nfev",
    "njev",
    "time_ms",
    "max_abs_param",
    "ran_away",
    "matched",
]
"""Fields of each run in the JSON (``runs.columns``; ``runs.rows`` holds one list per run)."""
SCIPY_STATUS = {
    -1: "improper input",
    0: "max_nfev",
    1: "gtol",
    2: "ftol",
    3: "xtol",
    4: "ftol+xtol",
}
JACOBIAN_LABEL = {"optimistix": "exact (autodiff)", "scipy": "2-point finite differences"}


# ---------------------------------------------------------------------------------------------
# variants


@dataclass(frozen=True)
class Variant:
    name: str
    kind: str  # "gavin", "optimistix" or "scipy"
    update_type: int = 0
    jacobian: str = "exact"
    rho_form: str = "current"
    method: str = ""
    short: str = ""


def _gavin_name(t: int, jac: str, rho: str) -> str:
    return (
        f"lm{t}" + ("-broyden" if jac == "broyden" else "") + ("-paper" if rho == "paper" else "")
    )


VARIANTS = [
    Variant(
        _gavin_name(t, jac, rho),
        "gavin",
        t,
        jac,
        rho,
        short=f"{t}{'B' if jac == 'broyden' else ''}{'p' if rho == 'paper' else ''}",
    )
    for t, jac, rho in itertools.product((1, 2, 3), ("exact", "broyden"), ("current", "paper"))
] + [
    Variant("optimistix", "optimistix", short="ox"),
    Variant("scipy-lm", "scipy", method="lm", short="sLM"),
    Variant("scipy-trf", "scipy", method="trf", short="sTR"),
]


# ---------------------------------------------------------------------------------------------
# classic problems (More, Garbow, Hillstrom, ACM TOMS 7, 1981), residuals in jnp


def _rosenbrock(x):
    return jnp.stack([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]])


def _freudenstein_roth(x):
    return jnp.stack(
        [
            -13.0 + x[0] + ((5.0 - x[1]) * x[1] - 2.0) * x[1],
            -29.0 + x[0] + ((x[1] + 1.0) * x[1] - 14.0) * x[1],
        ]
    )


def _powell_badly_scaled(x):
    return jnp.stack([1e4 * x[0] * x[1] - 1.0, jnp.exp(-x[0]) + jnp.exp(-x[1]) - 1.0001])


def _brown_badly_scaled(x):
    return jnp.stack([x[0] - 1e6, x[1] - 2e-6, x[0] * x[1] - 2.0])


_BEALE_Y = np.array([1.5, 2.25, 2.625])


def _beale(x):
    i = jnp.arange(1, 4)
    return _BEALE_Y - x[0] * (1.0 - x[1] ** i)


def _jennrich_sampson(x):
    i = jnp.arange(1, 11)
    return 2.0 + 2.0 * i - (jnp.exp(i * x[0]) + jnp.exp(i * x[1]))


def _helical_valley(x):
    x0 = jnp.where(x[0] == 0.0, 1e-300, x[0])
    theta = jnp.arctan(x[1] / x0) / (2.0 * jnp.pi) + jnp.where(x[0] < 0.0, 0.5, 0.0)
    return jnp.stack(
        [10.0 * (x[2] - 10.0 * theta), 10.0 * (jnp.sqrt(x[0] ** 2 + x[1] ** 2) - 1.0), x[2]]
    )


_BARD_Y = np.array(
    [0.14, 0.18, 0.22, 0.25, 0.29, 0.32, 0.35, 0.39, 0.37, 0.58, 0.73, 0.96, 1.34, 2.10, 4.39]
)


def _bard(x):
    u = jnp.arange(1.0, 16.0)
    v = 16.0 - u
    w = jnp.minimum(u, v)
    return _BARD_Y - (x[0] + u / (v * x[1] + w * x[2]))


def _box3d(x):
    t = 0.1 * jnp.arange(1, 11)
    return jnp.exp(-t * x[0]) - jnp.exp(-t * x[1]) - x[2] * (jnp.exp(-t) - jnp.exp(-10.0 * t))


_MEYER_Y = np.array(
    [34780, 28610, 23650, 19630, 16370, 13720, 11540, 9744, 8261, 7030, 6005, 5147, 4427]
    + [3820, 3307, 2872],
    dtype=float,
)


def _meyer(x):
    t = 45.0 + 5.0 * jnp.arange(1, 17)
    return x[0] * jnp.exp(x[1] / (t + x[2])) - _MEYER_Y


def _powell_singular(x):
    return jnp.stack(
        [
            x[0] + 10.0 * x[1],
            jnp.sqrt(5.0) * (x[2] - x[3]),
            (x[1] - 2.0 * x[2]) ** 2,
            jnp.sqrt(10.0) * (x[0] - x[3]) ** 2,
        ]
    )


def _wood(x):
    return jnp.stack(
        [
            10.0 * (x[1] - x[0] ** 2),
            1.0 - x[0],
            jnp.sqrt(90.0) * (x[3] - x[2] ** 2),
            1.0 - x[2],
            jnp.sqrt(10.0) * (x[1] + x[3] - 2.0),
            (x[1] - x[3]) / jnp.sqrt(10.0),
        ]
    )


_KO_Y = np.array(
    [0.1957, 0.1947, 0.1735, 0.1600, 0.0844, 0.0627, 0.0456, 0.0342, 0.0323, 0.0235, 0.0246]
)
_KO_U = np.array([4.0, 2.0, 1.0, 0.5, 0.25, 0.167, 0.125, 0.1, 0.0833, 0.0714, 0.0625])


def _kowalik_osborne(x):
    u = _KO_U
    return _KO_Y - x[0] * (u * u + u * x[1]) / (u * u + u * x[2] + x[3])


def _brown_dennis(x):
    t = jnp.arange(1, 21) / 5.0
    return (x[0] + t * x[1] - jnp.exp(t)) ** 2 + (x[2] + x[3] * jnp.sin(t) - jnp.cos(t)) ** 2


# name, residual, standard start x0, m; MGH's minimum sum of squares in the comments
CLASSIC: list[tuple[str, Callable, tuple[float, ...], int]] = [
    ("Rosenbrock", _rosenbrock, (-1.2, 1.0), 2),  # 0
    ("Freudenstein-Roth", _freudenstein_roth, (0.5, -2.0), 2),  # 0; local 48.9842
    ("Powell badly scaled", _powell_badly_scaled, (0.0, 1.0), 2),  # 0
    ("Brown badly scaled", _brown_badly_scaled, (1.0, 1.0), 3),  # 0
    ("Beale", _beale, (1.0, 1.0), 3),  # 0
    ("Jennrich-Sampson", _jennrich_sampson, (0.3, 0.4), 10),  # 124.362
    ("helical valley", _helical_valley, (-1.0, 0.0, 0.0), 3),  # 0
    ("Bard", _bard, (1.0, 1.0, 1.0), 15),  # 8.21487e-3; 17.4286 at x2, x3 -> -inf
    ("Box 3D", _box3d, (0.0, 10.0, 20.0), 10),  # 0
    ("Meyer", _meyer, (0.02, 4000.0, 250.0), 16),  # 87.9458
    ("Powell singular", _powell_singular, (3.0, -1.0, 0.0, 1.0), 4),  # 0
    ("Wood", _wood, (-3.0, -1.0, -3.0, -1.0), 6),  # 0
    ("Kowalik-Osborne", _kowalik_osborne, (0.25, 0.39, 0.415, 0.39), 11),  # 3.07505e-4
    ("Brown-Dennis", _brown_dennis, (25.0, 5.0, -5.0, -1.0), 20),  # 85822.2
]


# ---------------------------------------------------------------------------------------------
# problem shapes (one residual function each, compiled once per variant) and instances


@dataclass
class Shape:
    name: str
    fun: Callable  # fun(p, data) -> residual
    n: int


@dataclass
class Instance:
    group: str
    problem: str
    label: str
    shape: str
    p0: np.ndarray
    data: Any
    weights: np.ndarray
    scipy_fun: Callable[[np.ndarray], np.ndarray]


def _accel_fun(p, x):
    return normalized_sphere_residual(p, x, 1.0)


def _ellipsoid_fun(p, x):
    return quadric_residual(p, x, "full")


def _switch_fun(funs: list[Callable], m_max: int) -> Callable:
    def padded(f):
        def g(p):
            e = f(p)
            return jnp.pad(e, (0, m_max - e.shape[0]))

        return g

    branches = [padded(f) for f in funs]

    def fun(p, idx):
        return jax.lax.switch(idx, branches, p)

    return fun


def cap_directions(n: int, half_angle_deg: float, rng: np.random.Generator) -> np.ndarray:
    """n unit vectors uniform on a spherical cap of the given half-angle about a random axis."""
    axis = random_directions(1, rng)[0]
    z = 1.0 - rng.uniform(0.0, 1.0, n) * (1.0 - np.cos(np.deg2rad(half_angle_deg)))
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    s = np.sqrt(1.0 - z * z)
    u = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    return (s * np.cos(phi))[:, None] * u + (s * np.sin(phi))[:, None] * v + z[:, None] * axis


def _numpy_fun(f: Callable) -> Callable[[np.ndarray], np.ndarray]:
    return lambda p: np.asarray(f(p))


def normalise(raw: np.ndarray) -> np.ndarray:
    """Centre on the mean, divide by the RMS radius (as calib_jax does before a fit)."""
    c = raw - raw.mean(axis=0)
    return c / np.sqrt(np.mean(np.sum(c * c, axis=1)))


def build_suite(n_seeds: int) -> tuple[dict[str, Shape], list[Instance]]:
    shapes = {
        "accel": Shape("accel", _accel_fun, 9),
        "ellipsoid": Shape("ellipsoid", _ellipsoid_fun, 9),
    }
    instances: list[Instance] = []
    guess = jax.jit(initial_guess)
    ell_start = jax.jit(lambda x, w: ellipsoid_start(x, w, "full"))

    @jax.jit
    def sph_start(x, w):
        c, r = sphere_fit(x, w)
        return pack(c, jnp.eye(3, dtype=x.dtype) / r**2, "full")

    f_acc = jax.jit(_accel_fun)
    f_ell = jax.jit(_ellipsoid_fun)
    distort_j = jax.jit(distort)

    def scipy_data_fun(f, x):
        return lambda p: np.asarray(f(p, x))

    # accelerometer
    pose_sets = {
        "48 poses": lambda rng: paper48_directions(),
        "30 random poses": lambda rng: random_directions(30, rng),
        "hemisphere": lambda rng: cap_directions(48, 90.0, rng),
        "60-deg cap": lambda rng: cap_directions(48, 60.0, rng),
    }
    cases = [
        ("accel", ps, noise, "algebraic")
        for ps in pose_sets
        for noise in ((1e-4, 2e-3) if ps == "60-deg cap" else (1e-4, 2e-3, 1e-2))
    ]
    cases.append(("accel", "48 poses", 2e-3, "unit sphere"))
    # no minimum: chi2 falls towards an infinitely large sphere through the cap
    cases.append(("ill-posed", "60-deg cap", 1e-2, "algebraic"))
    w_acc = np.ones(N_ACCEL)
    for group, ps, noise, start in cases:
        problem = f"accel {ps}, noise {noise:g}" + (", unit start" if start != "algebraic" else "")
        for seed in range(n_seeds):
            rng = np.random.default_rng(1000 + seed)
            truth = random_params(rng)
            dirs = pose_sets[ps](rng)
            d = np.repeat(dirs, N_ACCEL // len(dirs), axis=0)
            raw = np.asarray(distort_j(jnp.asarray(truth), jnp.asarray(d)))
            raw = raw + noise * rng.normal(size=raw.shape)
            x = jnp.asarray(normalise(raw))
            if start == "algebraic":
                p0 = np.asarray(guess(x, jnp.asarray(w_acc)))
            else:
                p0 = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
            instances.append(
                Instance(
                    group,
                    problem,
                    f"seed {seed}",
                    "accel",
                    p0,
                    x,
                    w_acc,
                    scipy_data_fun(f_acc, x),
                )
            )

    # ellipsoids
    w_ell = np.ones(N_ELLIPSOID)
    ell_cases = [
        ("ellipsoid", "full coverage", None, NOISE_ELLIPSOID, "algebraic"),
        ("ellipsoid", "full coverage, sphere start", None, NOISE_ELLIPSOID, "sphere"),
        ("ellipsoid", "hemisphere", 90.0, NOISE_ELLIPSOID, "algebraic"),
        ("ellipsoid", "60-deg cap", 60.0, NOISE_ELLIPSOID, "algebraic"),
        ("ill-posed", "60-deg cap", 60.0, 0.01, "algebraic"),
    ]
    for group, label, cap, noise, start in ell_cases:
        problem = f"ellipsoid {label}, noise {noise:g}"
        for seed in range(n_seeds):
            rng = np.random.default_rng(2000 + seed)
            c, W = random_ellipsoid(rng)
            y = (
                random_directions(N_ELLIPSOID, rng)
                if cap is None
                else cap_directions(N_ELLIPSOID, cap, rng)
            )
            raw = y @ np.linalg.inv(W).T + c + noise * rng.normal(size=y.shape)
            x = jnp.asarray(normalise(raw))
            wj = jnp.asarray(w_ell)
            p0 = np.asarray(ell_start(x, wj) if start == "algebraic" else sph_start(x, wj))
            instances.append(
                Instance(
                    group,
                    problem,
                    f"seed {seed}",
                    "ellipsoid",
                    p0,
                    x,
                    w_ell,
                    scipy_data_fun(f_ell, x),
                )
            )

    # classic problems, one switch-residual per parameter count
    by_n: dict[int, list[tuple[str, Callable, tuple[float, ...], int]]] = {}
    for prob in CLASSIC:
        by_n.setdefault(len(prob[2]), []).append(prob)
    for n, probs in sorted(by_n.items()):
        m_max = max(m for *_, m in probs)
        m_max = max(m_max, n + 1)
        name = f"classic n={n}"
        shapes[name] = Shape(name, _switch_fun([f for _, f, _, _ in probs], m_max), n)
        for k, (pname, f, x0, m) in enumerate(probs):
            fj = jax.jit(f)
            w = np.zeros(m_max)
            w[:m] = 1.0
            for scale in (1.0, 10.0):
                instances.append(
                    Instance(
                        "classic",
                        pname,
                        "x0" if scale == 1.0 else "10 x0",
                        name,
                        scale * np.asarray(x0, float),
                        jnp.asarray(k, jnp.int32),
                        w,
                        _numpy_fun(fj),
                    )
                )
    return shapes, instances


# ---------------------------------------------------------------------------------------------
# running


def timed(call: Callable[[], Any], repeats: int, budget_s: float = 0.25) -> tuple[Any, float]:
    """Result and median seconds of up to ``repeats`` calls after one untimed call (only the
    first call when it takes longer than ``budget_s``: everything is compiled beforehand)."""
    t = time.perf_counter()
    out = jax.block_until_ready(call())
    first = time.perf_counter() - t
    if first > budget_s:  # slow (a run to the budget): the first call is warm enough
        return out, first
    k = max(1, min(repeats, int(budget_s / max(first, 1e-9))))
    ts = []
    for _ in range(k):
        t = time.perf_counter()
        out = jax.block_until_ready(call())
        ts.append(time.perf_counter() - t)
    return out, statistics.median(ts)


def compile_solver(v: Variant, shape: Shape, inst: Instance, budget: int):
    fun = shape.fun
    if v.kind == "gavin":

        def solve(p0, data, w):
            return lm_solve(
                fun,
                p0,
                data,
                weights=w,
                update_type=v.update_type,
                jacobian=v.jacobian,
                rho_form=v.rho_form,
                max_iter=budget,
            )

    else:

        def solve(p0, data, w):
            return optx_solve(fun, p0, data, weights=w, max_iter=budget)

    p0 = jnp.asarray(inst.p0)
    w = jnp.asarray(inst.weights)
    t = time.perf_counter()
    compiled = jax.jit(solve).lower(p0, inst.data, w).compile()
    return compiled, time.perf_counter() - t


def run_jax(v: Variant, compiled, inst: Instance, repeats: int) -> dict:
    p0 = jnp.asarray(inst.p0)
    w = jnp.asarray(inst.weights)
    r, sec = timed(lambda: compiled(p0, inst.data, w), repeats)
    status = int(r.status)
    return dict(
        chi2=float(r.chi2),
        converged=bool(is_converged(status)),
        status=Status(status).name,
        iterations=int(r.iterations),
        nfev=int(r.nfev),
        njev=int(r.njev),
        time_ms=round(1e3 * sec, 4),
        params=np.asarray(r.params).tolist(),
    )


def run_scipy(v: Variant, inst: Instance, repeats: int, tol: float, budget: int) -> dict:
    count = [0]

    def f(p):
        count[0] += 1
        return inst.scipy_fun(p)

    def call():
        count[0] = 0
        return least_squares(
            f, inst.p0, method=v.method, xtol=tol, ftol=tol, gtol=tol, max_nfev=budget
        )

    with np.errstate(all="ignore"):
        res, sec = timed(call, repeats)
    chi2 = float(np.sum(res.fun**2))
    return dict(
        chi2=chi2 if np.isfinite(chi2) else float("nan"),
        converged=bool(res.success),
        status=f"scipy {SCIPY_STATUS.get(res.status, res.status)}",
        iterations=None,
        nfev=int(count[0]),
        njev=None if res.njev is None else int(res.njev),
        time_ms=round(1e3 * sec, 4),
        params=np.asarray(res.x).tolist(),
    )


# ---------------------------------------------------------------------------------------------
# scoring and reporting


def score(runs: list[dict]) -> None:
    """Add the instance's best chi2, success and the run-away flag to every run."""
    by_inst: dict[tuple[str, str], list[dict]] = {}
    for r in runs:
        by_inst.setdefault((r["problem"], r["instance"]), []).append(r)
    for rs in by_inst.values():
        finite = [r["chi2"] for r in rs if np.isfinite(r["chi2"])]
        best = min(finite) if finite else float("nan")
        for r in rs:
            r["best_chi2"] = best
            ok = np.isfinite(r["chi2"]) and r["chi2"] <= best * (1 + CHI2_REL) + CHI2_ABS
            r["matched"] = bool(ok)
            r["success"] = bool(ok and r["converged"])
            if "params" in r:  # the JSON keeps only the size of the parameters
                r["max_abs_param"] = float(np.max(np.abs(r.pop("params"))))
            r["ran_away"] = bool(r["group"] != "classic" and not r["max_abs_param"] <= RUNAWAY)


def _median(xs: list) -> float | None:
    xs = [x for x in xs if x is not None]
    return float(statistics.median(xs)) if xs else None


def summarise(runs: list[dict]) -> dict:
    out = {}
    for v in VARIANTS:
        mine = [r for r in runs if r["variant"] == v.name]
        rs = [r for r in mine if r["group"] in GROUPS]
        s: dict[str, Any] = dict(
            runs=len(rs),
            success=sum(r["success"] for r in rs),
            not_converged=sum(not r["converged"] for r in rs),
            converged_above_best=sum(r["converged"] and not r["matched"] for r in rs),
            ran_away=sum(r["ran_away"] for r in rs),
            statuses={},
        )
        for r in rs:
            if not r["success"]:
                s["statuses"][r["status"]] = s["statuses"].get(r["status"], 0) + 1
        for g in GROUPS:
            gr = [r for r in rs if r["group"] == g]
            s[g] = dict(
                runs=len(gr),
                success=sum(r["success"] for r in gr),
                iterations=_median([r["iterations"] for r in gr]),
                nfev=_median([r["nfev"] for r in gr]),
                njev=_median([r["njev"] for r in gr]),
                time_ms=_median([r["time_ms"] for r in gr]),
            )
        ill = [r for r in mine if r["group"] == "ill-posed"]
        s["ill-posed"] = dict(
            runs=len(ill),
            ran_away=sum(r["ran_away"] for r in ill),
            ran_away_converged=sum(r["ran_away"] and r["converged"] for r in ill),
            bounded_converged=sum(r["converged"] and not r["ran_away"] for r in ill),
            bounded_not_converged=sum(not r["converged"] and not r["ran_away"] for r in ill),
            converged=sum(r["converged"] for r in ill),
            iterations=_median([r["iterations"] for r in ill]),
            nfev=_median([r["nfev"] for r in ill]),
            time_ms=_median([r["time_ms"] for r in ill]),
        )
        out[v.name] = s
    return out


def per_problem(runs: list[dict]) -> dict:
    """problem -> variant -> [successes, runs], scored groups only."""
    out: dict[str, dict[str, list[int]]] = {}
    for r in runs:
        if r["group"] not in GROUPS:
            continue
        cell = out.setdefault(r["problem"], {}).setdefault(r["variant"], [0, 0])
        cell[0] += int(r["success"])
        cell[1] += 1
    return out


def _fmt(x: float | None, digits: int = 0) -> str:
    if x is None:
        return "-"
    return f"{x:.{digits}f}"


def markdown(result: dict) -> str:
    summ, cfg = result["summary"], result["config"]
    lines = [
        "# Levenberg-Marquardt variants",
        "",
        f"{cfg['instances']} problem instances x {len(VARIANTS)} variants "
        f"(`benchmarks/lm_variants.py --seeds {cfg['seeds']} --repeats {cfg['repeats']} "
        f"--budget {cfg['budget']}`); jax {cfg['jax']}, optimistix {cfg['optimistix']}, "
        f"scipy {cfg['scipy']}, {cfg['machine']}; the run took {cfg['wall_s']:.0f} s "
        f"(compilation {cfg['compile_s']:.0f} s).",
        "",
        f"Success: the solver reports convergence and chi2 <= best * (1 + {CHI2_REL:g}) + "
        f"{CHI2_ABS:g}, best = the lowest chi2 any variant reached on the instance. Budget "
        f"{cfg['budget']} iterations (SciPy: max_nfev {cfg['budget']}, Jacobian calls not "
        f"counted). SciPy uses its default finite-difference Jacobian and ftol = xtol = gtol = "
        f"{cfg['scipy_tol']:g}; calib_jax its calibration defaults (eps1 1e-12, eps2 1e-10); "
        "optimistix rtol 1e-12, atol 1e-14.",
        "",
        "## Success at matched final chi2",
        "",
        "| variant | all | accel | ellipsoid | classic | not converged | converged above best "
        "| failures by status |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for v in VARIANTS:
        s = summ[v.name]
        cells = [f"{100 * s['success'] / s['runs']:.0f} % ({s['success']}/{s['runs']})"]
        for g in GROUPS:
            cells.append(f"{s[g]['success']}/{s[g]['runs']}")
        st = ", ".join(f"{k} {n}" for k, n in sorted(s["statuses"].items()))
        lines.append(
            f"| {v.name} | {' | '.join(cells)} | {s['not_converged']} | "
            f"{s['converged_above_best']} | {st or '-'} |"
        )
    lines += [
        "",
        "## Cost: medians over all runs of each group",
        "",
        "iterations = trial steps, accepted or not (SciPy does not report them); nfev = residual "
        "evaluations incl. finite-difference columns (optimistix: its steps, each one "
        "evaluation and one linearisation); njev = Jacobian evaluations (autodiff for exact, "
        "finite differences for broyden and SciPy; SciPy's lm does not report it); ms = warm "
        "time per solve (median).",
        "",
    ]
    for g in GROUPS:
        lines += [
            f"**{g}**",
            "",
            "| variant | iterations | nfev | njev | ms |",
            "|---|---|---|---|---|",
        ]
        for v in VARIANTS:
            s = summ[v.name][g]
            lines.append(
                f"| {v.name} | {_fmt(s['iterations'])} | {_fmt(s['nfev'])} | "
                f"{_fmt(s['njev'])} | {_fmt(s['time_ms'], 2)} |"
            )
        lines.append("")
    lines += [
        "## Successes per problem",
        "",
        "Columns: " + ", ".join(f"{v.short} = {v.name}" for v in VARIANTS) + ".",
        "",
        "| problem | " + " | ".join(v.short for v in VARIANTS) + " |",
        "|---|" + "---|" * len(VARIANTS),
    ]
    for prob, cells in result["per_problem"].items():
        row = []
        for v in VARIANTS:
            k, n = cells[v.name]
            row.append(f"**{k}/{n}**" if k < n else f"{k}/{n}")
        lines.append(f"| {prob} | " + " | ".join(row) + " |")
    ill = list(dict.fromkeys(r["problem"] for r in result["runs"] if r["group"] == "ill-posed"))
    lines += [
        "",
        "## Ill-posed: a 60-degree cap with 1 % noise",
        "",
        f"{', '.join(ill)}: chi2 has no minimum, it keeps falling towards an infinitely large "
        "sphere or ellipsoid through the cap, so success is not scored. Ran away = max |p| > "
        f"{RUNAWAY:g} at the end (the normalised truth is below 3); bounded = stopped near the "
        "data's scale.",
        "",
        "| variant | ran away | ran away, reported converged | bounded, converged | bounded, not "
        "converged | iterations | nfev | ms |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for v in VARIANTS:
        s = summ[v.name]["ill-posed"]
        lines.append(
            f"| {v.name} | {s['ran_away']}/{s['runs']} | {s['ran_away_converged']} | "
            f"{s['bounded_converged']} | "
            f"{s['bounded_not_converged']} | {_fmt(s['iterations'])} | {_fmt(s['nfev'])} | "
            f"{_fmt(s['time_ms'], 1)} |"
        )
    lines.append("")
    return "\n".join(lines)


def plot(result: dict, path: Path) -> None:
    from matplotlib.figure import Figure

    summ = result["summary"]
    names = [v.name for v in VARIANTS]
    y = np.arange(len(names))
    fig = Figure(figsize=(10, 5.5))
    ax1, ax2 = fig.subplots(1, 2, sharey=True)
    h = 0.27
    for k, g in enumerate(GROUPS):
        rate = [100 * summ[n][g]["success"] / summ[n][g]["runs"] for n in names]
        ax1.barh(y + (k - 1) * h, rate, h, label=g)
        nfev = [summ[n][g]["nfev"] for n in names]
        ax2.barh(y + (k - 1) * h, nfev, h, label=g)
    ax1.set_yticks(y, names)
    ax1.invert_yaxis()
    ax1.set_xlabel("success at matched chi2 (%)")
    ax2.legend(fontsize=8, loc="upper right")
    ax2.set_xscale("log")
    ax2.set_xlabel("median nfev (optimistix: steps)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)


# ---------------------------------------------------------------------------------------------


def _run_row(v, inst, r: dict) -> dict:
    """One result row: the variant and instance labels, then the run's numbers."""
    return dict(variant=v.name, group=inst.group, problem=inst.problem, instance=inst.label, **r)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=5, help="instances per simulated problem")
    ap.add_argument("--repeats", type=int, default=5, help="timed warm calls per solve (max)")
    ap.add_argument("--budget", type=int, default=1000, help="iteration budget")
    ap.add_argument("--scipy-tol", type=float, default=1e-12)
    ap.add_argument(
        "--from-json",
        action="store_true",
        help="no run: rescore results/lm_variants.json and rewrite its tables and figure",
    )
    args = ap.parse_args()
    out = Path(__file__).parent / "results"
    if args.from_json:
        result = json.loads((out / "lm_variants.json").read_text())
        table = result["runs"]
        result["runs"] = [dict(zip(table["columns"], row, strict=True)) for row in table["rows"]]
        write(result, out)
        return
    t_start = time.perf_counter()

    shapes, instances = build_suite(args.seeds)
    print(f"{len(instances)} instances, {len(shapes)} problem shapes, {len(VARIANTS)} variants")
    runs: list[dict] = []
    compile_s = 0.0
    for shape in shapes.values():
        insts = [i for i in instances if i.shape == shape.name]
        for v in VARIANTS:
            if v.kind == "scipy":
                continue
            compiled, c = compile_solver(v, shape, insts[0], args.budget)
            compile_s += c
            for inst in insts:
                runs.append(_run_row(v, inst, run_jax(v, compiled, inst, args.repeats)))
            print(f"  {shape.name:<12} {v.name:<20} compile {c:5.2f} s", flush=True)
    for v in VARIANTS:
        if v.kind != "scipy":
            continue
        for inst in instances:
            r = run_scipy(v, inst, args.repeats, args.scipy_tol, args.budget)
            runs.append(_run_row(v, inst, r))
        print(f"  scipy {v.method} done", flush=True)

    wall = time.perf_counter() - t_start
    result = dict(
        config=dict(
            seeds=args.seeds,
            repeats=args.repeats,
            budget=args.budget,
            scipy_tol=args.scipy_tol,
            chi2_rel=CHI2_REL,
            chi2_abs=CHI2_ABS,
            instances=len(instances),
            jax=jax.__version__,
            optimistix=getattr(optimistix, "__version__", "?"),
            scipy=scipy.__version__,
            machine=f"{platform.machine()}, {platform.python_version()}",
            wall_s=wall,
            compile_s=compile_s,
        ),
        variants=[
            dict(
                name=v.name,
                short=v.short,
                kind=v.kind,
                update_type=v.update_type or None,
                jacobian=JACOBIAN_LABEL.get(v.kind, v.jacobian),
                rho_form=v.rho_form if v.kind == "gavin" else None,
                method=v.method or None,
            )
            for v in VARIANTS
        ],
        runs=runs,
    )
    write(result, out)


def write(result: dict, out: Path) -> None:
    """Score the runs and write the JSON, the markdown tables and the figure."""
    runs = result["runs"]
    score(runs)
    result["summary"] = summarise(runs)
    result["per_problem"] = per_problem(runs)
    out.mkdir(exist_ok=True)
    # runs as a table (one row per line) to keep the file small
    head = json.dumps({k: v for k, v in result.items() if k != "runs"}, indent=1)
    rows = ",\n".join("   " + json.dumps([r[c] for c in RUN_COLUMNS]) for r in runs)
    (out / "lm_variants.json").write_text(
        f'{head[:-2]},\n "runs": {{\n  "columns": {json.dumps(RUN_COLUMNS)},\n  "rows": [\n'
        f"{rows}\n  ]\n }}\n}}\n"
    )
    md = markdown(result)
    print(md)
    (out / "lm_variants.md").write_text(md)
    plot(result, out / "lm_variants.png")
    print(f"wrote {out / 'lm_variants.json'}, .md and .png")


if __name__ == "__main__":
    main()
