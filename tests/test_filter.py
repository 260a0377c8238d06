"""The gyro-aided attitude filter: against simulated truth, its bias estimate, its gradient,
vmap, and against BROAD's optical truth in motion."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from calib_jax.endtoend import attitude_errors
from calib_jax.filter import FilterGains, complementary_filter
from calib_jax.simulate import simulate_marg, tumble_quaternions

from .conftest import shared_file

RATE = 100.0


def _tumble(seed: int, n: int = 3000, bias=(0.0, 0.0, 0.0), noise: float = 0.002):
    """A simulated tumble: accelerometer and magnetometer from simulate_marg, the gyro from
    the exact rotation between consecutive truth quaternions (SciPy), plus bias and noise."""
    rng = np.random.default_rng(seed)
    quat = tumble_quaternions(n, rng, knots=8)
    sim = simulate_marg(quat, sample_rate=RATE, rng=rng, dip_deg=65.0)
    R = Rotation.from_quat(np.column_stack([quat[:, 1:], quat[:, :1]]))
    rv = (R[:-1].inv() * R[1:]).as_rotvec() * RATE  # body rate over each step
    gyro = np.vstack([rv, rv[-1:]]) + np.asarray(bias) + rng.normal(0, noise, (n, 3))
    return gyro, sim.acc, sim.mag, quat


def _errors(q, truth):
    return np.asarray(attitude_errors(jnp.asarray(q), jnp.asarray(truth)))


def test_follows_a_simulated_tumble_from_a_wrong_start():
    # truth known exactly; start 30 deg off. The pulls remove it within 10 s (time constant
    # 1 / k = 1 s); the bias integrator, fed by the transient, learns a spurious 0.004 rad/s
    # and sheds it slowly: measured heading / inclination RMS 0.23 / 0.27 deg over the last
    # 20 s with the default gains (0.03 / 0.01 with k_bias = 0)
    gyro, acc, mag, quat = _tumble(1)
    q0 = (
        Rotation.from_quat(np.r_[quat[0, 1:], quat[0, :1]])
        * Rotation.from_rotvec([0.0, np.deg2rad(30.0), 0.0])
    ).as_quat()
    q, _ = complementary_filter(gyro, acc, mag, 1 / RATE, q0=np.r_[q0[3], q0[:3]])
    e = _errors(q, quat)
    assert e[0].max() > 20.0  # it did start far off
    assert np.sqrt(np.mean(e[1000:] ** 2, axis=0)).max() < 0.5


def test_estimates_a_constant_gyro_bias():
    # integral term: a 0.02 rad/s bias (1.1 deg/s) is learnt to within 10 % by the end
    bias = np.array([0.02, -0.01, 0.015])
    gyro, acc, mag, quat = _tumble(2, n=6000, bias=bias)
    gains = FilterGains(k_bias=0.1)
    q, b = complementary_filter(gyro, acc, mag, 1 / RATE, gains=gains)
    np.testing.assert_allclose(np.asarray(b[-1]), bias, atol=0.1 * np.abs(bias).max())
    assert np.sqrt(np.mean(_errors(q, quat)[3000:] ** 2, axis=0)).max() < 0.5


def test_gradient_in_the_gains_matches_finite_differences_and_vmap_matches_single_runs():
    gyro, acc, mag, quat = _tumble(3, n=600, bias=(0.01, 0.0, -0.01))
    ref = jnp.asarray(quat)

    def loss(k_acc, gyro=gyro):
        q, _ = complementary_filter(
            gyro, acc, mag, 1 / RATE, gains=FilterGains(k_acc=k_acc), g=1.0, field=45.0
        )
        return jnp.mean(jnp.sum((q - ref) ** 2, axis=1))

    grad = jax.grad(loss)(1.0)
    h = 1e-4
    fd = (loss(1.0 + h) - loss(1.0 - h)) / (2 * h)
    assert np.isfinite(grad) and grad == pytest.approx(float(fd), rel=1e-5)
    # two logs at once: vmapped over the gyro input, the same as one at a time
    both = jax.vmap(lambda gy: complementary_filter(gy, acc, mag, 1 / RATE, g=1.0, field=45.0)[0])(
        jnp.stack([gyro, gyro * 1.01])
    )
    one = complementary_filter(gyro * 1.01, acc, mag, 1 / RATE, g=1.0, field=45.0)[0]
    np.testing.assert_allclose(both[1], one, atol=1e-12)


def test_broad_heading_in_motion_with_the_gyro_and_a_rest_bias_from_another_trial():
    """BROAD (manufacturer-calibrated myon, optical truth), movement samples of trial 02.
    Measured: paper 2's accelerometer + magnetometer attitude (no gyro) 7.99 / 3.17 deg
    heading / inclination RMS; the filter with its bias estimate 1.51 / 0.66; without the
    integral term 1.61 / 0.82 as read, and with the gyro bias measured at the rests of trial
    05 (found by calib_jax's static detector on 05's accelerometer, no truth used) subtracted
    instead, 1.47 / 0.64 (fitted on one trial, judged on the other)."""
    from calib_jax.attitude import estimate_attitude
    from calib_jax.endtoend import rest_gyro_bias
    from calib_jax.io.broad import load_broad

    d = "broad_myon/{}.hdf5"
    t02 = load_broad(shared_file(d.format("02_undisturbed_slow_rotation_B")))
    t05 = load_broad(shared_file(d.format("05_undisturbed_slow_rotation_with_breaks_B")))
    ok = np.all(np.isfinite(t02.quat), axis=1) & t02.movement
    truth = t02.quat[ok] / np.linalg.norm(t02.quat[ok], axis=1, keepdims=True)
    gn = _errors(estimate_attitude(t02.acc, t02.mag).quat[ok], truth)
    # rests: the accelerometer's static intervals narrowed to where the gyro is still and
    # the field does not turn, of 2 s or more: 5 of the detector's 65 intervals on 05
    bias = rest_gyro_bias(t05.acc, t05.gyro, t05.mag, t05.sample_rate)
    # trial 02 has no breaks: its quiet stretches include a steady 26 deg/s turn about the
    # vertical, which only the magnetometer tells from a rest. With it, 02's bias agrees with
    # 05's (measured 0.007 deg/s apart at most); without, by 0.97 deg/s
    b02 = rest_gyro_bias(t02.acc, t02.gyro, t02.mag, t02.sample_rate)
    assert np.degrees(np.abs(b02 - bias)).max() < 0.03
    blind = rest_gyro_bias(t02.acc, t02.gyro, None, t02.sample_rate)
    assert np.degrees(np.abs(blind - bias)).max() > 0.3
    rms = {}
    for name, gains, b0 in [
        ("estimated", FilterGains(), None),
        ("as read", FilterGains(k_bias=0.0), None),
        ("rest bias", FilterGains(k_bias=0.0), bias),
    ]:
        q, _ = complementary_filter(
            t02.gyro, t02.acc, t02.mag, 1 / t02.sample_rate, gains=gains, bias0=b0
        )
        rms[name] = np.sqrt(np.mean(_errors(np.asarray(q)[ok], truth) ** 2, axis=0))
    rms_gn = np.sqrt(np.mean(gn**2, axis=0))
    assert rms_gn[0] > 6.0
    assert rms["estimated"][0] < 2.0 and rms["estimated"][1] < 1.0
    assert rms["rest bias"][0] < rms["as read"][0] and rms["rest bias"][1] < rms["as read"][1]


def test_end_to_end_through_the_filter_recovers_gyro_and_delay():
    """calib_jax.endtoend.end_to_end_filter on a simulated tumble with known truth: the raw
    gyro is C^-1 w + b (C 2 % from I, b ~ 0.6 deg/s), the reference runs 13.7 ms ahead of the
    sensors, accelerometer and unit field with noise 5e-4. Fitting C, b and the delay
    recovers them; over four seeds the largest errors were 4e-4 (C), 1.7e-4 rad/s (b) and
    2.2e-4 s, all proportional to the noise (four times larger at 2e-3) and 8-30 times the
    formal standard errors, which assume independent residuals where the filter's are
    correlated over its time constant: tolerances 1e-3, 5e-4 rad/s and 5e-4 s. Fitting the
    gyro alone, the delay leaks into C (measured 2.0e-2): why the delay is a
    block of its own. A gyro lagging the other sensors is told from the reference's delay.
    Bad input is named."""
    from scipy.spatial.transform import Slerp

    from calib_jax import endtoend as ee
    from calib_jax.pipeline import GyroParams, MargParams

    rng = np.random.default_rng(3)
    rates, _, _, quat = _tumble(4, noise=0.0)
    # unit field, as the start's unit magnetometer calibration expects
    sim = simulate_marg(quat, field=1.0, acc_noise=5e-4, mag_noise=5e-4, rng=rng)
    acc, mag = sim.acc, sim.mag
    C = np.eye(3) + 0.02 * rng.normal(size=(3, 3))
    b = 0.01 * rng.normal(size=3)
    gyro = rates @ np.linalg.inv(C).T + b + rng.normal(0, 1e-4, rates.shape)
    t = np.arange(len(quat)) / RATE
    delay = 0.0137
    R = Rotation.from_quat(np.column_stack([quat[:, 1:], quat[:, :1]]))
    ahead = Slerp(t, R)(np.clip(t + delay, 0, t[-1])).as_quat()
    q_ref = np.column_stack([ahead[:, 3:], ahead[:, :3]])
    q_ref[t + delay > t[-1]] = np.nan  # beyond the recording
    zero = jnp.zeros((3, 3))
    start = ee.MargGyroParams(
        MargParams.identity(), GyroParams(jnp.eye(3), jnp.zeros(3), zero, zero[0])
    )

    def fit(blocks):
        return ee.end_to_end_filter(gyro, acc, mag, q_ref, 1 / RATE, start, fit=blocks)

    r = fit(("gyro", "delay"))
    assert np.abs(np.asarray(r.params.gyro.matrix) - C).max() < 1e-3
    assert np.abs(np.asarray(r.params.gyro.bias) - b).max() < 5e-4
    assert r.delay_s == pytest.approx(delay, abs=5e-4)
    alone = fit(("gyro",))
    assert np.abs(np.asarray(alone.params.gyro.matrix) - C).max() > 3e-3
    # a gyro that lags the accelerometer and magnetometer by 23 ms (its reading at t is the
    # rate at t - 23 ms) beside the reference's 13.7 ms: the two delays separate (the other
    # sensors are not late), measured 23.1 and 13.70 ms; without the gyro's block the
    # reference delay absorbs it (20.7 ms) and C is 1.6e-2 off
    lagged = np.column_stack([np.interp(t - 0.023, t, rates[:, i]) for i in range(3)])
    gyro = lagged @ np.linalg.inv(C).T + b + rng.normal(0, 1e-4, rates.shape)
    both = fit(("gyro", "delay", "gyro_delay"))
    assert both.gyro_delay_s == pytest.approx(0.023, abs=1e-3)
    assert both.delay_s == pytest.approx(delay, abs=5e-4)
    assert np.abs(np.asarray(both.params.gyro.matrix) - C).max() < 1e-3
    with pytest.raises(ValueError, match="fit must name some of"):
        fit(("temperature",))
    bad = gyro.copy()
    bad[10] = np.nan
    with pytest.raises(ValueError, match="1 rows hold NaN"):
        ee.end_to_end_filter(bad, acc, mag, q_ref, 1 / RATE, start, fit=("gyro",))
