"""Many sensors in one jitted call: the moment form of the sphere and quadric fits.

Both residuals are quadrics in the data. With the monomials
phi(x) = [x^2, y^2, z^2, 2xy, 2xz, 2yz, x, y, z, 1] every residual is linear in them,

    e_i(p) = phi(x_i)' theta(p),

so chi2(p) = theta' S theta with the 10 x 10 moment matrix S = sum_i w_i phi_i phi_i'. Two passes
over the samples give S (the mean, then the 35 power sums of degree <= 4 about it:
:func:`calib_jax.geometry.normalised_moments`); after that the LM iterations never touch the
samples again. With
S = L L' (a symmetric square root), the ten "virtual residuals" r(p) = L' theta(p) have
|r|^2 = chi2 and J_r' J_r = D' S D (D = dtheta/dp): the very normal equations of the
sample-level fit, which the unchanged LM solver (:func:`calib_jax.lm.lm_solve`) then solves,
with the samples' degrees of freedom for the covariance.

Per sensor the work is two passes over N samples (about 80 N flops for S) plus a few dozen
10 x 9 operations per iteration, instead of an (N x 9) Jacobian per iteration. Everything is
vmapped over sensors with per-member state; a sensor with too few valid samples, or with all
directions in one plane, gets its own status (nothing fitted, NaN parameters), and one whose
fit is no calibration (a sensor held still: NO_SHELL, RAN_AWAY) is "failed"; either way the
others are unchanged.

Precision: theta' S theta cancels terms of size N to leave chi2 ~ N sigma^2, so chi2 carries a
relative round-off of about eps / sigma^2 (1e-10 at sigma = 1e-3 of the radius). The fitted
parameters agree with the sample-level fit to ~1e-10 relative (tests/test_batch.py).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int, Real, Shaped

from .accel import (
    FLAT_POSES,
    _units_from_norm,
    detect_units,
    initial_guess_moments,
    no_accelerometer_unit,
    not_at_rest,
)
from .accel import MODELS as ACCEL_MODELS
from .calibration import BatchRecord
from .geometry import (
    moments,
    normalised_moments,
    prefit_status,
    shell_status,
    stand_in_directions,
)
from .linalg import cholesky_small, det3, inv3
from .lm import budget_apart, checked_solver_options, lm_solve, with_budget
from .mag import FLAT_POINTS, ellipsoid_start_moments
from .models.accel import alpha_matrix
from .models.mag import (
    N_PARAMS,
    log_radius_scale,
    natural_radius,
    raw_calibration,
    raw_covariance,
    unpack,
)
from .status import fit_status, is_converged, status_message

MIN_SAMPLES = 20
# |g| in the physical units an accelerometer log comes in (counts: any output unit)
G_IN_UNITS = {"g": 1.0, "m/s^2": 9.80665}


def check_magnitude(value, name: str, n: int | None = None) -> np.ndarray:
    """A reference magnitude (``g`` or ``field``) as a float array, scalar or one per sensor
    ((n,) when ``n`` is given); a ValueError naming the value unless every entry is a
    positive finite number. Works on host values only (not on tracers)."""
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number, got {value!r}") from None
    if a.ndim > 1 or (a.ndim == 1 and n is not None and a.shape != (n,)):
        want = "a scalar" + (f" or one per sensor ({n},)" if n is not None else "")
        raise ValueError(f"{name} must be {want}, got shape {a.shape}")
    bad = ~(np.isfinite(a) & (a > 0))
    if np.any(bad):
        where = "" if a.ndim == 0 else f" (sensor {int(np.flatnonzero(bad)[0])})"
        v = a[np.flatnonzero(bad)[0]] if a.ndim else a
        raise ValueError(
            f"{name} must be a positive, finite magnitude, got {float(v)!r}{where}: it is the "
            "field magnitude the calibrated output should have (1 for g, 9.80665 for m/s^2)"
        )
    return a


def check_reference_magnitude(g, units: str | None, norm: float) -> None:
    """Raise a ValueError when the reference magnitude ``g`` and the data's unit disagree by
    more than a factor of 2 (data in m/s^2, static norm ~9.8, with g = 1, or data in g with
    g = 9.81). ``units`` is the data's unit ("g", "m/s^2", "counts"; None or "auto": the one
    the static norm ``norm`` suggests); counts take any g (the output unit is free). ``g``
    may be one per sensor. Also rejects a non-positive or non-finite g."""
    ga = check_magnitude(g, "g")
    unit = units if units not in (None, "auto") else _units_from_norm(float(norm))
    expected = G_IN_UNITS.get(unit or "")
    if expected is None:
        return
    for v in np.atleast_1d(ga):
        if not 0.5 <= v / expected <= 2.0:
            raise ValueError(
                f"g = {v:g} does not match the data's unit: the static readings have norm "
                f"{float(norm):.4g}, i.e. {unit}, where |g| is {expected:g}; pass g = "
                f"{expected:g} (--g {expected:g}), or convert the data to the unit of g"
            )


def reference_for_log(
    norm: float, g=None, fit_norm: float | None = None, radius_determined: bool = False
) -> float:
    """The accelerometer reference magnitude for one log from its static norm (and the radius
    of the sphere through its poses, ``fit_norm``): the given ``g`` (checked against the log's
    unit, :func:`check_reference_magnitude`), else the |g| of the unit the norms suggest (1
    for g and counts, 9.80665 for m/s^2; :func:`calib_jax.accel.detect_units`, as the single
    fit decides; ``radius_determined``: the radius decides), a ValueError when they suggest
    none."""
    if g is None:
        unit = detect_units(float(norm), fit_norm, radius_determined)
        if unit is None:
            raise ValueError(no_accelerometer_unit(float(norm), fit_norm, True, radius_determined))
        return G_IN_UNITS.get(unit, 1.0)
    check_reference_magnitude(g, None, norm)
    return float(g)


def quadric_theta(Q: jax.Array, c: jax.Array, scale: float | jax.Array) -> jax.Array:
    """theta such that phi(x)' theta = scale ((x - c)' Q (x - c) - 1)."""
    Qc = Q @ c
    return scale * jnp.concatenate(
        [
            jnp.stack([Q[0, 0], Q[1, 1], Q[2, 2], Q[0, 1], Q[0, 2], Q[1, 2]]),
            -2.0 * Qc,
            (c @ Qc - 1.0)[None],
        ]
    )


def accel_theta(p: jax.Array) -> jax.Array:
    """Paper 1's normalised sphere residual 1 - |alpha^-1 (x - beta)|^2 in moment form."""
    Ai = inv3(alpha_matrix(p))
    return quadric_theta(Ai.T @ Ai, p[6:9], -1.0)


def mag_theta(p: jax.Array, model: str) -> jax.Array:
    """:func:`calib_jax.models.mag.quadric_residual` in moment form."""
    c, M = unpack(p, model)
    return quadric_theta(M, c, log_radius_scale(p, model))


def sqrt_factor(S: jax.Array) -> jax.Array:
    """L' with L L' = S + tau I, the lower Cholesky factor (calib_jax.linalg.cholesky_small).

    tau = 1e-14 tr(S) keeps noise-free (singular) moment matrices factorable; it shifts chi2 by
    tau |theta|^2, below the round-off of the moment form itself. A pivot that still comes out
    non-positive gives a zero column (S is positive semi-definite by construction).
    """
    return cholesky_small(0.5 * (S + S.T), jitter=1e-14, semidefinite=True).T


class BatchResult(eqx.Module):
    """Per-sensor results of a batch fit (leading axis: sensors), in input units."""

    params: Float[Array, "S n"]
    stderr: Float[Array, "S n"]
    status: Int[Array, " S"]
    """calib_jax.lm.Status codes; INSUFFICIENT_DATA / NO_COVERAGE mean nothing was fitted."""
    rms: Float[Array, " S"]
    """RMS over the valid samples of the relative norm error (|y| - r) / r after calibration,
    from chi2 (to first order in the error: the fit never passes over the samples again)."""
    chi2: Float[Array, " S"]
    iterations: Int[Array, " S"]
    n_samples: Int[Array, " S"]
    stderr_normalised: Float[Array, "S p"] | None = None
    """Standard errors of the fitted parameters in the normalised problem (units of the data's
    radius; the magnetometer's packed form, see calib_jax.mag.PARAM_NAMES): what the single
    fit's poorly-determined rule reads (calib_jax.mag.poorly_determined)."""

    @property
    def sensor(self) -> str:
        """'accel' (nine parameters) or 'mag' (the ellipsoid's centre and W, twelve)."""
        return "accel" if self.params.shape[-1] == 9 else "mag"

    @property
    def statuses(self) -> list[str]:
        """The records' status word per sensor (:func:`calib_jax.status.fit_status`)."""
        return [fit_status(int(s)) for s in np.asarray(self.status)]

    @property
    def success(self) -> np.ndarray:
        return np.array([is_converged(int(s)) for s in np.asarray(self.status)])

    def entries(self, names: Sequence | None = None) -> list[dict]:
        """One :class:`calib_jax.BatchRecord` entry per sensor (``names`` labels them, e.g.
        their files; default the index)."""
        return batch_entries(
            self.status, self.params, self.stderr, self.rms, self.iterations, self.n_samples, names
        )

    def to_record(self, names: Sequence | None = None) -> BatchRecord:
        """The batch as a record that saves, loads and compares (:class:`calib_jax.BatchRecord`)."""
        return BatchRecord(sensor=self.sensor, entries=self.entries(names))

    def to_params(self):
        """Every sensor's parameters as one stacked pytree (leading axis: sensors):
        :class:`calib_jax.pipeline.AccelParams` or :class:`calib_jax.pipeline.MagParams`; vmap
        over it. Sensors that were not fitted are in it too: mask them with :attr:`success`."""
        from .models.accel import AccelParams
        from .pipeline import MagParams

        if self.sensor == "accel":
            return jax.vmap(AccelParams.from_vector)(self.params)
        return jax.vmap(MagParams.from_vector)(self.params)

    def rows(self, names=None) -> list[dict]:
        """One flat dict per sensor: file (``names`` or the index), status, message, each
        parameter and its standard error by name, rms, iterations, points."""
        from .display import fleet_rows

        return fleet_rows(self.entries(names), self.sensor)

    def to_dataframe(self, names=None):
        """:meth:`rows` as a pandas DataFrame."""
        from .display import to_dataframe

        return to_dataframe(self.rows(names))

    def __repr__(self) -> str:
        from .display import batch_repr

        return batch_repr("BatchResult", self.sensor, self.statuses)

    def _repr_html_(self) -> str:
        from .display import rows_html

        ok = int(self.success.sum())
        n = len(self.success)
        return f"<b>BatchResult</b>: {ok} of {n} sensors converged" + rows_html(self.rows())


def batch_entries(status, params, stderr, rms, iterations, n_points, names=None) -> list[dict]:
    """The :class:`calib_jax.BatchRecord` entries of stacked fits (one row per sensor of each
    array; ``names`` label them, default the index): the one entry layout of the batch, the
    fleet, the recorder and the pipeline's fit_batch."""
    params, stderr = np.asarray(params, float), np.asarray(stderr, float)
    out = []
    for i, code in enumerate(int(s) for s in np.asarray(status)):
        out.append(
            {
                "path": names[i] if names is not None else i,
                "status": fit_status(code, bool(np.all(np.isfinite(params[i])))),
                "solver_status": code,
                "message": status_message(code),
                "params": params[i].tolist(),
                "stderr": stderr[i].tolist(),
                "rms": float(np.asarray(rms)[i]),
                "iterations": int(np.asarray(iterations)[i]),
                "n_points": int(np.asarray(n_points)[i]),
                **_linear_forms(params[i]),
            }
        )
    return out


def _linear_forms(p: np.ndarray) -> dict:
    """The forward model and the correction matrix of one entry (calibration.linear_forms, as
    every calibration JSON writes them); none for a fit without finite parameters."""
    from .calibration import linear_forms
    from .models.layout import ALPHA_INDEX

    if not np.all(np.isfinite(p)):
        return {}
    if len(p) == 9:  # paper 1: raw = alpha a + beta
        return linear_forms(offset=p[6:9], forward=p[ALPHA_INDEX])
    return linear_forms(offset=p[:3], correction=p[3:].reshape(3, 3))  # y = W (raw - c)


# Sensors per step of the moment pass, by JAX platform (0: all at once, one vmap).
MOMENT_CHUNK = {"cpu": 8, "gpu": 1024}


def _batch_moments(raw, valid, chunk: int | None = None):
    """(S, mean, k) per sensor: moments of the normalised samples, ``chunk`` sensors at a time
    (default by platform, :data:`MOMENT_CHUNK`).

    CPU: lax.map in chunks of 8 sensors, not one vmap over all: a chunk's samples (0.9 MB for
    4,800 each) stay in cache between the mean and the power sums (each one variadic reduce,
    :func:`calib_jax.geometry.sum_last`); chunks of 4, 8, 16 and 64 measured 0.017, 0.018,
    0.044 and 0.052 ms per sensor (benchmarks/moment_pass.py times the pass). A GPU runs each
    step as a few kernel launches, so it takes far larger chunks: on an H200 at 10,000
    sensors, with the variadic reduce, 256, 512, 1024 and 4096 per step took 0.45-0.47,
    0.40-0.42, 0.34-0.35 and 0.47-0.48 us per sensor (two runs; with the earlier 35 separate
    sums 8, 64, 512 and 4096 took 6.3, 0.86, 0.52 and 0.50; benchmarks/results/
    moment_pass_gpu.json, ``moment_pass.py --chunks``).
    """
    if chunk is None:
        chunk = MOMENT_CHUNK.get(jax.default_backend(), MOMENT_CHUNK["gpu"])

    def one(args):
        r, v = args
        # non-finite samples are masked out here, inside the passes over the data (an eager
        # isfinite + where before the call read and wrote all of it twice more)
        v = v & jnp.all(jnp.isfinite(r), axis=-1)
        return normalised_moments(r, v.astype(r.dtype))

    if chunk == 0 or chunk >= raw.shape[0]:
        return jax.vmap(lambda r, v: one((r, v)))(raw, valid)
    return jax.lax.map(one, (raw, valid), batch_size=chunk)


def _unit_sphere_moments(dtype) -> jax.Array:
    """Moments of :func:`calib_jax.geometry.stand_in_directions`: the stand-in problem for
    sensors that fail the checks."""
    d = stand_in_directions()
    return moments(jnp.asarray(d, dtype), jnp.ones(len(d), dtype))


def _solve(theta_fn, p0, S, dof, solver, options):
    Lt = sqrt_factor(S)

    def residual(p, Lt):
        return Lt @ theta_fn(p)

    # Cholesky covariance: the Jacobi eigh was 0.1 of the 0.12 ms per sensor of the LM stage
    options = {"covariance_method": "cholesky", **options}
    if solver == "optimistix":
        from .lm.optx import optx_solve

        return optx_solve(residual, p0, Lt, dof=dof, **options)
    update_type = {"lm1": 1, "lm2": 2, "lm3": 3}[solver]
    return lm_solve(residual, p0, Lt, update_type=update_type, dof=dof, **options)


def _accel_one(S, mean, k, g, model, solver, options, min_points):
    free = np.asarray(ACCEL_MODELS[model])
    idx = np.flatnonzero(free)
    pre = prefit_status(S, len(idx), min_points, FLAT_POSES)
    S = jnp.where(pre >= 0, _unit_sphere_moments(S.dtype), S)
    p0 = jnp.where(jnp.asarray(free), initial_guess_moments(S), 0.0)
    n = S[9, 9]

    def theta(q):
        return accel_theta(jnp.zeros(9, q.dtype).at[idx].set(q))

    res = _solve(theta, p0[idx], S, n - len(idx), solver, options)
    pn = jnp.zeros(9, S.dtype).at[idx].set(res.params)
    se_n = jnp.zeros(9, S.dtype).at[idx].set(res.stderr)
    T = jnp.concatenate([jnp.full(6, k / g), jnp.full(3, k)])
    params = pn * T + jnp.concatenate([jnp.zeros(6, S.dtype), mean])
    # e = 1 - |a|^2 ~ -2 (|a| - 1): the RMS relative norm error to first order
    rms = jnp.sqrt(res.chi2 / jnp.maximum(n, 1.0)) / 2.0
    # the semi-axes in units of the samples' spread k (a unit-radius fit of (x - mean) / k)
    radius = jnp.cbrt(jnp.abs(det3(alpha_matrix(pn))))
    status = not_at_rest(shell_status(jnp.where(pre >= 0, pre, res.status), rms, radius), rms)
    return params, se_n * T, status, rms, res, pre >= 0


def _mag_one(S, mean, k, field, model, solver, options, min_points):
    pre = prefit_status(S, N_PARAMS[model], min_points, FLAT_POINTS)
    S = jnp.where(pre >= 0, _unit_sphere_moments(S.dtype), S)
    p0 = ellipsoid_start_moments(S, model)
    n = S[9, 9]
    res = _solve(lambda p: mag_theta(p, model), p0, S, n - N_PARAMS[model], solver, options)
    _, M_n = unpack(res.params, model)
    center, W = raw_calibration(res.params, model, mean, k, field)
    # e = r_n (q - 1) ~ 2 r_n (|y| / r - 1) in normalised units
    rms = jnp.sqrt(res.chi2 / jnp.maximum(n, 1.0)) / (2.0 * natural_radius(M_n))
    params = jnp.concatenate([center, W.ravel()])
    cov = raw_covariance(res.params, res.covariance, model, mean, k, field)
    stderr = jnp.sqrt(jnp.maximum(jnp.diagonal(cov), 0.0))
    status = shell_status(jnp.where(pre >= 0, pre, res.status), rms, natural_radius(M_n))
    return params, stderr, status, rms, res, pre >= 0


@functools.lru_cache(maxsize=32)
def _compiled(
    kind: str,
    model: str,
    solver: str,
    options: tuple,
    shard: bool,
    min_points: int = MIN_SAMPLES,
    budgeted: bool = False,
):
    """The batch fit ``(raw, valid, ref) -> BatchResult``, and with ``budgeted`` the iteration
    budget as a last argument (:func:`calib_jax.lm.budget_apart`).

    Two compiled programs: the moment pass (:func:`_compiled_moments`, the only one that sees
    the samples) and the fit of the 10 x 10 moments, whose shape is the sensor count's alone.
    As one program every new sample count compiled the whole fit again: 18 compiles of 6-15 s
    in the test suite (issue 17's profile), and a user's next batch of longer logs paid it
    again. The moments pass from one to the other on the device."""
    one = _accel_one if kind == "accel" else _mag_one

    def fit(S, mean, k, ref, *budget):
        opts = dict(options) | ({"max_iter": budget[0]} if budget else {})
        params, stderr, status, rms, res, bad = jax.vmap(
            lambda S, m, k, r: one(S, m, k, r, model, solver, opts, min_points)
        )(S, mean, k, ref)
        nan = jnp.nan
        return BatchResult(
            params=jnp.where(bad[:, None], nan, params),
            stderr=jnp.where(bad[:, None], nan, stderr),
            status=status,
            rms=jnp.where(bad, nan, rms),
            chi2=jnp.where(bad, nan, res.chi2),
            iterations=res.iterations,
            n_samples=jnp.round(S[:, 9, 9]).astype(jnp.int_),  # the count of valid samples
            stderr_normalised=jnp.where(bad[:, None], nan, res.stderr),
        )

    if shard:
        from jax.sharding import Mesh, PartitionSpec

        mesh = Mesh(np.array(jax.devices()), ("sensors",))
        P = PartitionSpec("sensors")
        specs = (P, P, P, P) + (PartitionSpec(),) * budgeted  # the budget: one for all devices
        fit = jax.shard_map(fit, mesh=mesh, in_specs=specs, out_specs=P, check_vma=False)
    fit, moments = jax.jit(fit), _compiled_moments(shard)

    def run(raw, valid, ref, *budget):
        return fit(*moments(raw, valid), ref, *budget)

    return run


@functools.lru_cache(maxsize=2)
def _compiled_moments(shard: bool):
    """The batch's moment pass ``(raw, valid) -> (S, mean, k)``, compiled per sample shape."""
    moments = _batch_moments
    if shard:
        from jax.sharding import Mesh, PartitionSpec

        mesh = Mesh(np.array(jax.devices()), ("sensors",))
        P = PartitionSpec("sensors")
        moments = jax.shard_map(
            _batch_moments, mesh=mesh, in_specs=(P, P), out_specs=P, check_vma=False
        )
    return jax.jit(moments)


def sensor_bucket(n: int, devices: int = 1) -> int:
    """Padded sensor count: a multiple of 8 (and of the device count). Every batch of a size
    compiles once, and a sensor's lanes run the same instructions whatever else is in the
    batch, so adding a bad sensor leaves the others bit for bit unchanged."""
    step = int(np.lcm(8, devices))
    return max(step, -(-n // step) * step)


def _stackable(raw) -> None:
    """A ValueError for a list of logs of different lengths (numpy's 'inhomogeneous shape'
    was the error a trial met), naming the helper that pads them."""
    if isinstance(raw, list | tuple) and len({np.shape(r)[:1] for r in raw}) > 1:
        lengths = ", ".join(str(len(r)) for r in raw[:6]) + (", ..." if len(raw) > 6 else "")
        raise ValueError(
            f"the logs have different lengths ({lengths}): pad them into one (sensors, "
            "samples, 3) array with weights, raw, w = calib_jax.padding.stack_rows(logs), and "
            "pass mask=w > 0"
        )


def _prepare(raw, mask, ref, shard):
    raw = jnp.asarray(raw)
    if raw.ndim != 3 or raw.shape[-1] != 3:
        raise ValueError(
            f"raw must be (sensors, samples, 3), got shape {raw.shape}; stack logs of different "
            "lengths by padding them and passing mask"
        )
    if not jnp.issubdtype(raw.dtype, jnp.floating):
        raw = raw.astype(float)
    mask = jnp.ones(raw.shape[:2], bool) if mask is None else _bool_mask(mask)
    if mask.shape != raw.shape[:2]:
        raise ValueError(f"mask must be (sensors, samples) = {raw.shape[:2]}, got {mask.shape}")
    valid = mask  # non-finite samples are masked inside the jitted moment pass
    n = raw.shape[0]
    ref = jnp.broadcast_to(jnp.asarray(ref, raw.dtype), (n,))
    size = sensor_bucket(n, len(jax.devices()) if shard else 1)
    if size > n:  # padding sensors: all samples masked out (INSUFFICIENT_DATA, sliced off)
        raw = jnp.concatenate([raw, jnp.zeros((size - n, *raw.shape[1:]), raw.dtype)])
        valid = jnp.concatenate([valid, jnp.zeros((size - n, valid.shape[1]), bool)])
        ref = jnp.concatenate([ref, jnp.ones(size - n, raw.dtype)])
    if shard:
        raw, valid, ref = shard_batch(raw), shard_batch(valid), shard_batch(ref)
    return raw, valid, ref


def _bool_mask(mask) -> jax.Array:
    """A boolean mask; a numeric one only if every entry is 0 or 1 (a float mask with NaN
    would otherwise count as all-true). A boolean array on the device stays there (a GPU batch
    never copies its samples or mask to the host)."""
    if isinstance(mask, jax.core.Tracer) or (isinstance(mask, jax.Array) and mask.dtype == bool):
        return jnp.asarray(mask, bool)
    m = np.asarray(mask)
    if m.dtype == bool:
        return jnp.asarray(m)
    if m.dtype.kind not in "iuf":
        raise ValueError(f"mask must be boolean (True = use the sample), got dtype {m.dtype}")
    bad = ~((m == 0) | (m == 1))
    if np.any(bad):
        i = tuple(int(k) for k in np.argwhere(bad)[0])
        raise ValueError(
            f"mask must be boolean or 0/1, but mask{list(i)} is {m[i].item()!r}"
            + (" (NaN)" if m.dtype.kind == "f" and np.isnan(m[i]) else "")
            + ": pass a boolean array (True = use the sample)"
        )
    return jnp.asarray(m, bool)


def shard_batch(x: jax.Array) -> jax.Array:
    """Place the leading (sensor) axis across all local devices (jax.sharding); the count
    must be a multiple of the device count (the batch functions pad to one)."""
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    devices = np.array(jax.devices())
    if x.shape[0] % len(devices):
        raise ValueError(
            f"{x.shape[0]} sensors do not split over {len(devices)} devices; pad the batch to a "
            "multiple (all-False mask rows are fitted as INSUFFICIENT_DATA and cost little)"
        )
    mesh = Mesh(devices, ("sensors",))
    spec = PartitionSpec("sensors", *([None] * (x.ndim - 1)))
    return jax.device_put(x, NamedSharding(mesh, spec))


def calibrate_accel_batch(
    raw: Real[ArrayLike, "S N 3"],
    mask: Shaped[ArrayLike, "S N"] | None = None,
    *,
    g: float | Sequence[float] | Float[ArrayLike, " S"] = 1.0,
    model: str = "accel9",
    solver: str = "lm1",
    solver_options: dict | None = None,
    shard: bool = False,
    min_points: int = MIN_SAMPLES,
) -> BatchResult:
    """Paper 1's sample-level fit for many accelerometers in one jitted, vmapped call.

    Parameters
    ----------
    raw : (sensors, samples, 3)
        Readings in any unit; logs of different lengths are padded and masked.
    mask : (sensors, samples) bool, optional
        Samples to fit (e.g. the static ones from :func:`calib_jax.static.detect_static`).
        Non-finite samples are always left out. A numeric mask must hold only 0 and 1.
    g : float or (sensors,) array
        Reference magnitude in output units (positive and finite: a ValueError names a bad
        value; :func:`check_reference_magnitude` checks it against the data's unit).
    model, solver, solver_options
        As :func:`calib_jax.calibrate_accel`.
    shard : bool
        Split the sensors over all local devices (jax.sharding).
    min_points : int
        Fewer valid rows than this (or than the free parameters) is INSUFFICIENT_DATA. The
        default suits samples; interval means that passed :func:`calib_jax.accel.check_poses`
        need only as many as the parameters (six faces for ``accel6``: an exact fit, as
        ``calibrate_accel`` gives).

    Returns
    -------
    BatchResult
        ``params`` (S, 9) in paper 1's order and input units, as ``calibrate_accel``.
    """
    if model not in ACCEL_MODELS:
        raise ValueError(f"model must be one of {tuple(ACCEL_MODELS)}, got {model!r}")
    if solver not in ("lm1", "lm2", "lm3", "optimistix"):
        raise ValueError(f"solver must be lm1, lm2, lm3 or optimistix, got {solver!r}")
    _stackable(raw)
    n = np.shape(raw)[0]
    g = check_magnitude(g, "g", n)
    raw, valid, ref = _prepare(raw, mask, g, shard)
    opts = checked_solver_options(solver, solver_options)
    key, budget = budget_apart(solver, opts)
    fit = _compiled("accel", model, solver, key, shard, int(min_points), budget is not None)
    out = with_budget(fit, budget)(raw, valid, ref)
    return jax.tree.map(lambda a: a[:n], out)


def calibrate_mag_batch(
    raw: Real[ArrayLike, "S N 3"],
    mask: Shaped[ArrayLike, "S N"] | None = None,
    *,
    field: float | Sequence[float] | Float[ArrayLike, " S"] | None = None,
    model: str = "full",
    solver: str = "lm1",
    solver_options: dict | None = None,
    shard: bool = False,
) -> BatchResult:
    """The ellipsoid fit of :func:`calib_jax.calibrate_mag` for many sensors in one call.

    ``params`` (S, 12) is [center (3), W (9, row-major)]: y = W (raw - center) has magnitude
    ``field`` (a positive number, or one per sensor; or det W = 1 without it). ``stderr``
    holds their standard errors in the same order (those of :func:`calib_jax.calibrate_mag`,
    from the moment-form chi2). The model is fixed (no automatic choice in a batch).
    """
    if model not in N_PARAMS:
        raise ValueError(f"model must be one of {tuple(N_PARAMS)}, got {model!r}")
    if solver not in ("lm1", "lm2", "lm3", "optimistix"):
        raise ValueError(f"solver must be lm1, lm2, lm3 or optimistix, got {solver!r}")
    _stackable(raw)
    n = np.shape(raw)[0]
    field = np.nan if field is None else check_magnitude(field, "field", n)
    raw, valid, ref = _prepare(raw, mask, field, shard)
    opts = checked_solver_options(solver, solver_options)
    key, budget = budget_apart(solver, opts)
    fit = _compiled("mag", model, solver, key, shard, MIN_SAMPLES, budget is not None)
    out = with_budget(fit, budget)(raw, valid, ref)
    return jax.tree.map(lambda a: a[:n], out)
