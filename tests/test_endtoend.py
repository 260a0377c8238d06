"""End-to-end calibration against a reference attitude (issue 7): known truth on simulated data,
the Jacobian through the Gauss-Newton estimator, and the BROAD excerpt."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import calib_jax as cj
from calib_jax import endtoend as ee
from calib_jax import pipeline as pl
from calib_jax.attitude import reference_vectors
from calib_jax.rotations import dcm_to_quat, quat_multiply, rotvec_to_dcm

DIP = 66.0


def _simulated(seed=0, n=300):
    """A board turned through n orientations (tilt up to 60 deg, any heading), a magnetometer
    with hard and soft iron rotated 4 deg against the accelerometer, and a reference whose
    body frame is off by 2 deg and whose north by 3 deg."""
    rng = np.random.default_rng(seed)
    r_a, r_m = (np.asarray(v) for v in reference_vectors(DIP))
    tilt = rng.uniform(0, np.radians(60), n)
    az = rng.uniform(0, 2 * np.pi, n)
    head = rng.uniform(-np.pi, np.pi, n)
    rv = np.column_stack([tilt * np.cos(az), tilt * np.sin(az), np.zeros(n)])
    # vmapped: one program each (called per sample, eager jnp took 50 s of the file's 310)
    dcms = jax.jit(jax.vmap(rotvec_to_dcm))
    heading = np.column_stack([np.zeros((n, 2)), head])
    Cs = np.asarray(dcms(jnp.asarray(heading))) @ np.asarray(dcms(jnp.asarray(rv)))
    W = np.array([[1.05, 0.03, -0.02], [0.03, 0.95, 0.01], [-0.02, 0.01, 1.0]])
    c = np.array([0.2, -0.1, 0.3])
    R = np.asarray(rotvec_to_dcm(jnp.radians(jnp.array([3.0, -2.0, 1.5]))))  # mag -> acc
    acc = np.stack([C.T @ r_a for C in Cs]) + 1e-3 * rng.normal(size=(n, 3))
    m_acc = np.stack([C.T @ r_m for C in Cs])
    mag = (m_acc @ R) @ np.linalg.inv(W).T + c + 1e-3 * rng.normal(size=(n, 3))
    off = np.array([np.radians(1.5), np.radians(-1.0), np.radians(0.8), np.radians(3.0)])
    q_true = np.asarray(jax.jit(jax.vmap(dcm_to_quat))(jnp.asarray(Cs)))
    # the reference is off by the offset: fix(q_ref) = q_z(h) q_ref q_b(v) = q_true, so
    # q_ref = q_z(-h) q_true q_b(v)^-1
    qz_inv = jnp.array([np.cos(-off[3] / 2), 0, 0, np.sin(-off[3] / 2)])
    qb_inv = dcm_to_quat(rotvec_to_dcm(jnp.asarray(off[:3])).T)
    q_ref = np.asarray(
        jax.jit(jax.vmap(lambda q: quat_multiply(qz_inv, quat_multiply(q, qb_inv))))(q_true)
    )
    return acc, mag, q_ref, dict(W=W, c=c, R=R, offset=off)


def test_recovers_calibration_and_reference_offset():
    acc, mag, q_ref, truth = _simulated()
    start = ee.two_stage(acc, mag)
    fit = ee.end_to_end(acc, mag, q_ref, start, fit_offset=True, fit_dip=True)
    assert int(fit.result.status) in (0, 1, 8), fit.result.message
    np.testing.assert_allclose(fit.offset, truth["offset"], atol=np.radians(0.05))
    # the calibration reaches the truth up to the scale (held by the mean |m| = 1) and the
    # noise (1e-3 of the field: parameters to ~1e-3)
    np.testing.assert_allclose(fit.params.mag.hard_iron, truth["c"], atol=5e-3)
    np.testing.assert_allclose(fit.params.mag.soft_iron, truth["W"], atol=5e-3)
    R_fit = np.asarray(fit.params.mag_to_acc.matrix)
    ang = np.degrees(np.arccos(np.clip((np.trace(R_fit @ truth["R"].T) - 1) / 2, -1, 1)))
    assert ang < 0.1
    assert abs(fit.dip_deg - DIP) < 0.05
    # and the attitude errors against the corrected reference vanish to the noise
    fixed = np.asarray(ee.offset_reference(jnp.asarray(q_ref), jnp.asarray(fit.offset)))
    e = ee.evaluate(fit.params, fit.dip_deg, acc, mag, fixed, np.ones(len(acc), bool))
    assert e["heading_rms"] < 0.2 and e["inclination_rms"] < 0.1


def test_residual_jacobian_through_the_estimator():
    """The LM uses forward-mode Jacobians through calibration, TRIAD and Gauss-Newton; check
    two columns against central differences (h = 1e-6: 1e-8 absolute)."""
    acc, mag, q_ref, _ = _simulated(n=60)
    start = ee.two_stage(acc, mag)
    packed = ee.pack(start.params, start.dip_deg)
    default = jnp.concatenate([packed, jnp.zeros(4)])
    free = jnp.asarray(ee.free_mask(("calibration", "dip", "offset")))
    theta = jnp.concatenate([packed, jnp.array([0.01, -0.02, 0.005, 0.03])])
    args = (
        start.params,
        default,
        free,
        jnp.asarray(acc),
        jnp.asarray(mag),
        jnp.asarray(q_ref),
        jnp.ones(len(acc)),
    )
    f = jax.jit(lambda t: ee._residual(t, args))
    J = jax.jit(jax.jacfwd(lambda t: ee._residual(t, args)))(theta)
    for k in (1, 4, 10, 12, 16):
        e = jnp.zeros_like(theta).at[k].set(1e-6)
        fd = (f(theta + e) - f(theta - e)) / 2e-6
        np.testing.assert_allclose(J[:, k], fd, atol=1e-7)


@pytest.fixture(scope="module")
def broad():
    d = cj.load_broad_excerpt("02")
    return {k: v[::4] for k, v in d.items()}


def test_broad_end_to_end_lowers_the_attitude_error(broad):
    """On a quarter of the BROAD 02 excerpt: the end-to-end fit starts at the two-stage
    calibration, so its weighted attitude cost can only fall; it converges, and its
    quasi-static heading error on the data it was fitted to falls below the two-stage one."""
    rate = cj.datasets.BROAD_EXCERPT_RATE / 4
    r = ee.rate_from_quat(broad["quat"], rate)
    w = ee.rate_weights(r)
    start = ee.two_stage(broad["acc"], broad["mag"])
    fit = ee.end_to_end(broad["acc"], broad["mag"], broad["quat"], start, weights=w)
    assert fit.result.success, fit.result.message
    qs = r < ee.QUASI_STATIC_DEG_S
    before = ee.evaluate(start.params, start.dip_deg, broad["acc"], broad["mag"], broad["quat"], qs)
    after = ee.evaluate(fit.params, fit.dip_deg, broad["acc"], broad["mag"], broad["quat"], qs)
    assert after["heading_rms"] < before["heading_rms"]
    assert before["n"] > 200
    # the calibrated field keeps unit mean norm (the scale the estimator cannot see)
    m = np.linalg.norm(np.asarray(pl.apply(fit.params.mag, jnp.asarray(broad["mag"]))), axis=1)
    assert abs(np.mean(m[np.all(np.isfinite(broad["quat"]), axis=1)] * 1.0) - 1.0) < 0.02


def test_missing_rows_are_left_out_not_propagated():
    """NaN rows in acc, mag or the reference get zero weight and finite stand-ins (0 * NaN is
    NaN, so a weight alone would poison the whole fit): the fit equals the one without them."""
    acc, mag, q_ref, _ = _simulated(seed=2)  # the length of the test above: its programs
    start = ee.two_stage(acc, mag)
    clean = ee.end_to_end(acc, mag, q_ref, start)
    a2, m2, q2 = acc.copy(), mag.copy(), q_ref.copy()
    a2[5] = np.nan
    m2[17, 1] = np.nan
    q2[40] = np.nan
    keep = np.ones(len(acc), bool)
    keep[[5, 17, 40]] = False
    start2 = ee.two_stage(a2, m2)
    holed = ee.end_to_end(a2, m2, q2, start2)
    ref = ee.end_to_end(acc[keep], mag[keep], q_ref[keep], start2)
    assert holed.result.success and clean.result.success
    np.testing.assert_allclose(
        ee.pack(holed.params, 0.0), ee.pack(ref.params, 0.0), rtol=1e-7, atol=1e-9
    )
