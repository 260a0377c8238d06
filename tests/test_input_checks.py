"""Issue 13: wrong answers reported as ok and foreign exceptions. One test per class of bad
input, each against a known truth: a fit on data that no ellipsoid explains is not "ok",
nonsense reference magnitudes and masks are refused with the value named, a corrupt
calibration file is refused with the file and the key named, a kill or a full disk during a
recording loses nothing that was read."""

import errno
import json
import re
import time
import warnings

import numpy as np
import pytest

import calib_jax as cj
from calib_jax import calibrate_accel
from calib_jax.calibration import AccelCalibration, MagCalibration, write_json_atomic
from calib_jax.io.files import SensorLog

# ---------------------------------------------------------------------------------------------
# calibration records


def _accel_cal(**kw) -> AccelCalibration:
    p = np.array([1.01, 0.99, 1.02, 0.001, -0.002, 0.003, 0.01, -0.02, 0.03])
    base = dict(
        params=p,
        stderr=np.full(9, 1e-4),
        covariance=np.eye(9) * 1e-8,
        correlation=np.eye(9),
        condition=12.0,
        status="ok",
        input_units="g",
        output_units="g",
        g=1.0,
        solver="lm1",
        solver_status=0,
        solver_message="converged",
        iterations=5,
        nfev=6,
        use="means",
        n_intervals=12,
        n_points=12,
        rms_before=1e-2,
        rms_after=1e-4,
        noise_floor=1e-4,
        static_means=np.ones((2, 3)),
        sensor_id="u1",
        date="2026-01-01T00:00:00+00:00",
    )
    base.update(kw)
    return AccelCalibration(**base)


def _mag_cal(**kw) -> MagCalibration:
    base = dict(
        center=np.array([10.0, -5.0, 3.0]),
        soft_iron=np.diag([1.1, 0.9, 1.0]),
        radius=44.3,
        model="full",
        status="ok",
        rms_before_pct=10.0,
        rms_after_pct=0.5,
        semi_axes=np.array([40.0, 45.0, 50.0]),
        dcm=np.eye(3),
        stderr_center=np.full(3, 0.1),
        stderr_soft_iron=np.full((3, 3), np.nan),
        condition=3.0,
        solver="lm1",
        solver_status=0,
        solver_message="converged",
        iterations=7,
        n_samples=500,
        coverage=0.9,
        field=44.3,
        units="uT",
        model_selection={"full": {"bic": 1.0, "rms_pct": float("nan")}},
        date="2026-01-01T00:00:00+00:00",
    )
    base.update(kw)
    return MagCalibration(**base)


# (edit of the saved text, key the error must name, what it must say)
_ACCEL_FAULTS = [
    (lambda d: d["params"].__setitem__("gains", ["NaN", 1.0, 1.0]), "params.gains", "finite"),
    (lambda d: d["params"]["gains"].__setitem__(1, 0.0), r"params.gains\[1\]", "zero gain|is 0"),
    (lambda d: d["units"].__setitem__("g", -1.0), "units.g", "positive"),
    (lambda d: d.pop("solver_status"), "solver_status", "missing"),
    (lambda d: d["params"].__setitem__("bias", [0.0, "x", 0.0]), "params.bias", "numbers"),
]
_MAG_FAULTS = [
    (lambda d: d.__setitem__("center", [1.0, "inf", 0.0]), "center", "finite"),
    (lambda d: d.__setitem__("soft_iron", [[0.0] * 3] * 3), "soft_iron", "singular"),
    (lambda d: d.__setitem__("radius", 0.0), "radius", "positive"),
    (lambda d: d.pop("center"), "center", "missing"),
    (lambda d: d.__setitem__("soft_iron", [1.0, 2.0, 3.0]), "soft_iron", "3x3"),
]


@pytest.mark.parametrize(
    "cls,make,faults",
    [(AccelCalibration, _accel_cal, _ACCEL_FAULTS), (MagCalibration, _mag_cal, _MAG_FAULTS)],
    ids=["accel", "mag"],
)
def test_calibration_file_validated_on_load(tmp_path, cls, make, faults):
    """A corrupt file never loads as ok: NaN/Infinity (as strings or as the bare tokens
    Python's json accepts), zero gains, singular matrices, non-positive magnitudes, missing
    keys, wrong types and a top level that is not an object are each a ValueError naming the
    file and the key; a good file round-trips to an equal record."""
    cal = make()
    good = tmp_path / "good.json"
    cal.save(good)
    assert cls.load(good) == cal  # field-wise equality (NaN == NaN in arrays and dicts)
    assert cls.load(good) != make(sensor_id="other")
    for i, (edit, key, what) in enumerate(faults):
        d = json.loads(good.read_text())
        edit(d)
        bad = tmp_path / f"bad{i}.json"
        bad.write_text(json.dumps(d))
        with pytest.raises(ValueError, match=f"bad{i}.json.*{key}.*({what})") as e:
            cls.load(bad)
        assert re.search(what, str(e.value)), str(e.value)
    # the bare tokens NaN / Infinity (not valid JSON, but accepted by Python's json)
    first = "gains" if cls is AccelCalibration else "radius"
    text = good.read_text()
    for token in ("NaN", "Infinity", "-Infinity"):
        k = text.index(f'"{first}"')
        j = text.index(":", k) + 1
        stop = min(text.index(",", j), text.index("\n", j + 2))
        if first == "gains":  # the first gain: the line after '"gains": ['
            j = text.index("[", k) + 1
            stop = text.index(",", j)
        bad = tmp_path / "token.json"
        bad.write_text(text[:j] + f" {token}" + text[stop:])
        with pytest.raises(ValueError, match=f"token.json.*{first}.*{token}"):
            cls.load(bad)
    for top in ("[1, 2, 3]", "42", '"calibration"'):
        bad = tmp_path / "top.json"
        bad.write_text(top)
        with pytest.raises(ValueError, match="top.json.*JSON object"):
            cls.load(bad)


def test_apply_checks_shape_and_takes_a_log():
    """apply takes one reading (3,), many (N, 3) or a loaded log (its acc resp. mag columns);
    any other shape (an (N, 1) column would broadcast to (N, 3)) is a ValueError."""
    acc, mag = _accel_cal(), _mag_cal()
    rng = np.random.default_rng(0)
    a, m = rng.normal(size=(5, 3)), 40 * rng.normal(size=(5, 3))
    log = SensorLog(acc=a, mag=m, path="x.csv")
    np.testing.assert_array_equal(acc.apply(log), acc.apply(a))
    np.testing.assert_array_equal(mag.apply(log), mag.apply(m))
    np.testing.assert_allclose(mag.apply(m[0]), mag.apply(m)[0])
    np.testing.assert_allclose(acc.apply(a[0]), acc.apply(a)[0])
    # truth: W (m - c)
    np.testing.assert_allclose(mag.apply(m), (m - mag.center) @ mag.soft_iron.T)
    for cal in (acc, mag):
        for shape in ((5, 1), (5,), (5, 4), (2, 5, 3), ()):
            with pytest.raises(ValueError, match=r"\(3,\) or many \(N, 3\)"):
                cal.apply(np.ones(shape))
    with pytest.raises(ValueError, match="x.csv: the log has no mag columns"):
        mag.apply(SensorLog(acc=a, path="x.csv"))


def test_json_written_atomically_on_full_disk(tmp_path, monkeypatch):
    """A full disk while saving leaves the previous file (or none), no 0-byte file and no
    temporary file, and raises the OSError."""
    import os

    cal = _mag_cal()
    path = tmp_path / "m.calib.json"
    cal.save(path)
    before = path.read_bytes()
    real_fsync = os.fsync

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(OSError, match="No space"):
        _mag_cal(radius=50.0).save(path)
    with pytest.raises(OSError, match="No space"):
        write_json_atomic(tmp_path / "new.json", {"a": 1})
    monkeypatch.setattr(os, "fsync", real_fsync)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.calib.json"]


# ---------------------------------------------------------------------------------------------
# magnetometer fits on data that no ellipsoid explains

B = 45.0  # uT
CENTRE = np.array([10.0, -20.0, 5.0])
A = np.diag([1.1, 0.95, 1.0])


def _tumble(n=2000, passes=2, noise=0.2, seed=0):
    """A slow tumble in time order: ``passes`` spirals from pole to pole (consecutive samples
    are neighbours on the sphere, as in a real log), through soft and hard iron."""
    rng = np.random.default_rng(seed)
    u = np.linspace(0, passes, n, endpoint=False) % 1.0
    z = 1 - 2 * u
    phi = 2 * np.pi * 25 * u
    r = np.sqrt(1 - z * z)
    d = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    return (B * d) @ A.T + CENTRE + noise * rng.normal(size=(n, 3))


def _fit(x, **kw):
    import warnings

    from calib_jax.mag import calibrate_mag

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return calibrate_mag(x, field=B, **kw)


def test_mag_fit_not_ok_off_an_ellipsoid_shell():
    """A noise cloud and a hyperboloid are no ellipsoid: status failed (success False), the
    warning says so and what to check. Known truth for the control: the clean tumble is ok
    with its true centre and a residual at the noise (0.45 % of the field)."""
    rng = np.random.default_rng(1)
    clean = _fit(_tumble())
    assert clean.status == "ok" and clean.rms_after_pct < 1.0, clean.report()
    np.testing.assert_allclose(clean.center, CENTRE, atol=0.1)
    u, th = rng.uniform(-2, 2, 2000), rng.uniform(0, 2 * np.pi, 2000)
    hyperboloid = 30 * np.stack([np.cosh(u) * np.cos(th), np.cosh(u) * np.sin(th), np.sinh(u)], 1)
    cloud = B * rng.normal(size=(2000, 3))
    for x in (hyperboloid, cloud):
        cal = _fit(x)
        assert cal.status == "failed" and not cal.success, cal.report()
        assert any("do not lie on an ellipsoid shell" in w for w in cal.warnings)


def test_mag_fit_flags_a_field_change_during_the_log():
    """The hard iron jumps by 10 uT (and by 30 uT) halfway through a tumble: no single
    ellipsoid fits, the residual (5.7 %, 15 %) far exceeds the sample-to-sample noise
    (0.4 %), so the fit is not ok and the warning names the likely cause."""
    x = _tumble()
    for jump, status in ((10.0, "poorly_determined"), (30.0, "failed")):
        y = x.copy()
        y[len(y) // 2 :, 0] += jump
        cal = _fit(y)
        assert cal.status == status, cal.report()
        assert any("changed during the recording" in w or "jumped" in w for w in cal.warnings)


def test_mag_fit_leaves_saturated_samples_out():
    """Axis x clipped at +-30 uT (the field along it reaches 59 uT): the clipped samples are
    left out with a warning naming the axis, and the fit of the rest recovers the true hard
    iron and soft iron (without the check: 7.6 % residual, status ok)."""
    x = _tumble(seed=2)
    x[:, 0] = np.clip(x[:, 0], -30.0, 30.0)
    cal = _fit(x)
    sat = [w for w in cal.warnings if "saturated" in w]
    assert len(sat) == 2 and all("axis x" in w for w in sat), cal.warnings
    assert cal.rms_after_pct < 1.0
    np.testing.assert_allclose(cal.center, CENTRE, atol=0.5)
    np.testing.assert_allclose(cal.soft_iron, np.linalg.inv(A), atol=0.02)  # W (m - c) = B d


def test_a_reading_held_over_rows_is_not_a_clip():
    """A magnetometer read on a faster clock repeats each reading over several rows (a Pololu
    MinIMU-9 log: 93 % of its rows; 'axis y is saturated at its max (806, 29 samples)' was
    reported for an axis far from its range). Each held reading counts once; a real clip in
    such a log is still found."""
    from calib_jax.observations import saturated_axes

    x = np.round(_tumble(n=400, seed=4), 1)
    x[[10, 200, 300], 0] = x[:, 0].max() + 0.1  # three readings at the top of axis x
    held = np.repeat(x, 8, axis=0)  # every reading held for 8 rows: 24 rows at the top
    assert saturated_axes(x) == [] and saturated_axes(held) == []
    clipped = held.copy()
    clipped[:, 0] = np.minimum(clipped[:, 0], 30.0)
    assert (0, "max", 30.0) in saturated_axes(clipped)


@pytest.mark.parametrize("scale", [1e300, 1e200, 1e-200])
def test_mag_fit_extreme_values_are_a_value_error(scale):
    """Values whose squares over- or underflow float64 (and a corrupt row of 1e308) are a
    ValueError saying so, not numpy's LinAlgError 'Eigenvalues did not converge'."""
    x = _tumble(n=500)
    with pytest.raises(ValueError, match="float64"):
        _fit(x * scale)
    x[7] = [1e308, 0.0, 0.0]
    with pytest.raises(ValueError, match="sample 7 holds 1e\\+308"):
        _fit(x)


# ---------------------------------------------------------------------------------------------
# the recorder: a kill or a full disk loses nothing that was read


def test_recorder_hands_every_read_to_the_os_before_the_next(tmp_path):
    """With the flush cadence off (as if the process were SIGKILLed before it came round),
    every line read so far is in the file on disk (read through another descriptor: the
    process's buffers are not visible there) before the next read from the port."""
    import os
    import tty

    from calib_jax.io.serial import SerialReader

    master, slave = os.openpty()
    tty.setraw(slave)
    log = tmp_path / "k.csv"
    r = SerialReader(
        os.ttyname(slave),
        log=log,
        columns="ax,ay,az",
        flush_interval=1e9,
        flush_lines=10**9,
        fsync_interval=1e9,
        on_message=lambda s: None,
    )
    checks = []
    real = r._read_chunk

    def read_after_check():
        if log.exists():
            on_disk = log.read_bytes()
            assert os.stat(log).st_size == len(on_disk)
            checks.append((r.stats.lines_ok, max(on_disk.count(b"\n") - 1, 0)))
        return real()

    r._read_chunk = read_after_check
    sent = 0
    try:
        with r:
            for chunk in range(20):
                lines = b"".join(b"%d,%d,3\n" % (sent + k, chunk) for k in range(7))
                # the first line after a connection counts as cut off: start with a line end
                os.write(master, (b"\n" if chunk == 0 else b"") + lines)
                sent += 7
                end = time.monotonic() + 10
                while r.stats.lines_ok < sent:
                    assert time.monotonic() < end, r.stats.summary()
                    r.read_batch()
            read_after_check()  # the state after the last read
    finally:
        os.close(master)
        os.close(slave)
    assert checks and checks[-1] == (sent, sent)
    assert all(read == logged for read, logged in checks), checks


def test_recorder_calibration_json_on_a_full_disk(tmp_path, monkeypatch, capsys):
    """The disk fills up when the calibration JSON is written: no 0-byte .calib.json and no
    temporary file are left, the error is reported (stderr, save_errors) instead of raised,
    the calibration is still returned, and the log is untouched."""
    import os

    from calib_jax.io.serial import LogWriter
    from calib_jax.record import calibrate_recording
    from calib_jax.simulate import random_directions

    rng = np.random.default_rng(3)
    m = (45.0 * random_directions(1500, rng)) @ A.T + CENTRE + 0.2 * rng.normal(size=(1500, 3))
    log = tmp_path / "rec.csv"
    w = LogWriter(log)
    w.open(["mx", "my", "mz"])
    for row in m:
        w.append(",".join(f"{v:.6f}" for v in row))
    w.close()
    before = log.read_bytes()

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    res = calibrate_recording(log, "mag", field=45.0, echo=None)
    monkeypatch.undo()
    assert res["mag"].status == "ok"
    np.testing.assert_allclose(res["mag"].center, CENTRE, atol=0.1)
    assert len(res["save_errors"]) == 1 and "No space left" in res["save_errors"][0]
    assert "could not write" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec.csv"]
    assert log.read_bytes() == before


# ---------------------------------------------------------------------------------------------
# batch fits: reference magnitudes and masks


@pytest.mark.wrong_types
def test_batch_rejects_bad_magnitudes_and_masks():
    """g / field = 0, -1, NaN, inf (scalar or one per sensor) and a mask that is not boolean
    or 0/1 (a NaN in a float mask used to count as True) are each a ValueError naming the
    value; a per-sensor g is honoured (known truth: each sensor's output has its own |g|)."""
    from calib_jax.batch import calibrate_accel_batch, calibrate_mag_batch
    from calib_jax.simulate import random_directions

    rng = np.random.default_rng(4)
    raw = np.stack([random_directions(300, rng) * s + 0.01 * s for s in (1.0, 9.81)])
    for bad in (0.0, -1.0, float("nan"), float("inf"), [1.0, -9.81], [1.0, float("nan")]):
        with pytest.raises(ValueError, match=r"g must be a positive, finite magnitude, got"):
            calibrate_accel_batch(raw, g=bad)
        with pytest.raises(ValueError, match=r"field must be a positive, finite magnitude, got"):
            calibrate_mag_batch(raw, field=bad)
    with pytest.raises(ValueError, match=r"one per sensor \(2,\)"):
        calibrate_accel_batch(raw, g=[1.0, 2.0, 3.0])
    mask = np.ones(raw.shape[:2])
    mask[1, 17] = np.nan
    with pytest.raises(ValueError, match=r"mask\[1, 17\] is nan \(NaN\)"):
        calibrate_accel_batch(raw, mask)
    mask[1, 17] = 0.5
    with pytest.raises(ValueError, match=r"mask\[1, 17\] is 0.5"):
        calibrate_accel_batch(raw, mask)
    mask[1, 17] = 0.0  # 0/1 floats are a mask
    r = calibrate_accel_batch(raw, mask, g=[1.0, 9.81])
    assert np.all(r.success) and list(np.asarray(r.n_samples)) == [300, 299]
    gains = np.asarray(r.params)[:, :3]  # raw = g_true * a: gain = raw per output unit = 1
    np.testing.assert_allclose(gains, 1.0, atol=1e-6)


def test_reference_magnitude_must_match_the_unit():
    """check_reference_magnitude: g = 1 on m/s^2 data (static norm 9.8) or g = 9.81 on data
    in g is a ValueError naming both; within a factor of 2, and counts, pass."""
    from calib_jax.batch import check_reference_magnitude

    with pytest.raises(ValueError, match=r"g = 1 does not match.*norm 9.79, i.e. m/s\^2"):
        check_reference_magnitude(1.0, None, 9.79)
    with pytest.raises(ValueError, match=r"g = 9.81 does not match.*\bg\b"):
        check_reference_magnitude(9.81, "g", 1.0)
    with pytest.raises(ValueError, match="positive, finite"):
        check_reference_magnitude(-9.81, "m/s^2", 9.8)
    check_reference_magnitude(9.80665, "auto", 9.79)
    check_reference_magnitude(1.0, "g", 1.01)
    check_reference_magnitude(1.0, None, 16384.0)  # counts: any output unit
    check_reference_magnitude([1.0, 1.0], "g", 1.0)


# ---------------------------------------------------------------------------------------------
# pipeline fits: the reference magnitude


def test_pipeline_fit_rejects_a_nonpositive_magnitude():
    """fit_accel / fit_mag with magnitude -1, 0, NaN or inf: a ValueError when the value is
    concrete (it used to converge to negative gains), status FAILED with NaN params under jit
    (where nothing can raise); the same fit with magnitude 1 recovers the truth."""
    import jax
    import jax.numpy as jnp

    import calib_jax.pipeline as pl
    from calib_jax.lm import Status
    from calib_jax.simulate import random_directions

    rng = np.random.default_rng(5)
    truth_c = np.array([0.3, -0.2, 0.1])
    raw = jnp.asarray(2.0 * random_directions(200, rng) + truth_c)
    for fit in (pl.fit_accel, pl.fit_mag):
        for bad in (-1.0, 0.0, float("nan"), float("inf")):
            with pytest.raises(ValueError, match="magnitude must be a positive, finite"):
                fit(raw, bad)
        jitted = jax.jit(fit)
        f = jitted(raw, -1.0)
        assert int(f.status) == Status.FAILED and not bool(f.converged)
        assert all(np.all(np.isnan(np.asarray(a))) for a in jax.tree.leaves(f.params))
        good = jitted(raw, 1.0)
        assert bool(good.converged)
        c = good.params.bias if fit is pl.fit_accel else good.params.hard_iron
        np.testing.assert_allclose(np.asarray(c), truth_c, atol=1e-8)
        with pytest.raises(ValueError, match="sensor 1: magnitude must be"):
            pl.fit_batch(fit, jnp.stack([raw, raw]), jnp.asarray([1.0, -1.0]))


def test_a_coarse_still_log_is_one_pose_not_a_table_and_not_saturated():
    """The MPU-9150 log of tests/NOTES (lying flat, printed to 0.01 g, no time column) read as
    a 1700-row pose table by diagnose (its rows sit on a lattice an ellipsoid passes through)
    and had its quantised extremes flagged as saturation. Simulated the same way: no
    saturation note, not a pose table, and calibrate_accel and diagnose_accel both refuse it
    for having one pose."""
    from calib_jax.diagnose import diagnose_accel
    from calib_jax.observations import screen_samples
    from calib_jax.static import detect_static

    rng = np.random.default_rng(0)
    x = np.round((np.array([0.0, 0.0, 1.005]) + 0.006 * rng.normal(size=(1700, 3))) / 0.01) * 0.01
    valid, notes = screen_samples(x, "accel")
    assert valid.all() and notes == []
    assert detect_static(x).kind == "log"
    with pytest.raises(ValueError, match="only 1 distinct pose"):
        calibrate_accel(x)
    d = diagnose_accel(x)
    assert d.verdict == "not_possible" and "only 1 distinct pose" in d.notes[0]


def test_a_stuck_axis_is_named():
    """One axis constant while the board is turned through 30 poses: the error names the axis
    (it used to read as 'all poses lie near one plane')."""
    from calib_jax.simulate import random_directions, random_params, simulate_accel

    s = simulate_accel(random_params(1), random_directions(30, 1), noise=2e-3, rng=1)
    raw = s.raw.copy()
    raw[:, 1] = 0.25
    with pytest.raises(ValueError, match="axis y reads 0.25 in every sample while the others"):
        calibrate_accel(raw, sample_rate=s.sample_rate)


def test_a_magnetometer_that_never_turned_is_no_calibration():
    """uBot's LSM303 'no movement' log (512 samples): calib-jax mag reported a hard iron (the
    field itself), a radius of 1.8 uT, 26 % coverage, status poorly_determined and exit 0.
    (Its coverage is now NaN, 'not measured'.)
    A log spreading by no more than 3x its sample-to-sample noise, on no shell, fails and says
    why; a shuffled cap of a tumble (no time order, on its shell) is not refused by this."""
    rng = np.random.default_rng(5)
    still = np.array([-37.6, -62.5, 1.3]) + 0.4 * rng.normal(size=(512, 3))
    cal = _fit(still)
    assert cal.status == "failed"
    assert any("the field barely changes" in w for w in cal.warnings), cal.warnings
    # nor any coverage: directions about a 'centre' that is the field spread over the sphere
    # (a GGIR AX6 log's 'magnetometer', a still gyro, was '83 % of the sphere covered')
    assert np.isnan(cal.coverage)
    assert "(coverage not measured: no shell to measure it on)" in cal.report()
    x = _tumble(seed=1)
    cap = x[(x - CENTRE) @ np.array([0.0, 0.0, 1.0]) > 0]
    cap = cap[rng.permutation(len(cap))]
    shuffled = _fit(cap)
    assert not any("the field barely changes" in w for w in shuffled.warnings)


def test_a_long_still_magnetometer_whose_noise_ball_fits_well_is_no_calibration():
    """An MPU-9250 board lying still for 103,939 samples (MyFreertosLab/my_mpu9250_thing's
    imu-data.csv, CC0: counts spread 7.3 about a field of 226): so many samples determine a
    sphere of radius 8 through the noise well, so the fit was not "poorly determined" and the
    never-turned test, which asked for that, did not run. The user read "100 % of the sphere
    of directions covered" and advice to check columns, units and saturation. Simulated here
    with the same field, the same noise and integer counts (20,000 samples)."""
    rng = np.random.default_rng(3)
    still = np.round(np.array([56.8, 202.0, -84.2]) + 4.2 * rng.normal(size=(20_000, 3)))
    cal = _fit(still)
    assert cal.status == "failed"
    assert any("the field barely changes" in w for w in cal.warnings), cal.warnings
    assert not any("column mapping" in w for w in cal.warnings), cal.warnings
    assert np.isnan(cal.coverage)
    # refused for what the data are, a budget that ran out is not advice to raise it (a trial
    # was told both, raised --max-iter, and got the same refusal)
    from calib_jax.status import Status, status_message

    ran_out = status_message(Status.MAX_ITERATIONS, refused=True)
    assert "will not help" in ran_out and "--max-iter" not in ran_out
    assert "--max-iter" in status_message(Status.MAX_ITERATIONS)
    assert status_message(Status.CONVERGED_CHI2, refused=True) == status_message(
        Status.CONVERGED_CHI2
    )
    assert cal.solver_message == status_message(cal.solver_status, refused=True)
    # an accelerometer lying still (ActiGraph's IMU example, a new-user trial) is named so:
    # 'the field barely changes' was said of its gravity
    with pytest.warns(cj.FitStatusWarning):
        acc = cj.calibrate_mag(still / 226.0, sensor="accel")
    assert any(w.startswith("gravity barely changes") for w in acc.warnings), acc.warnings
    assert "'centre' is gravity itself" in acc.warnings[-1]


def test_an_accelerometer_without_gravity_is_named_so():
    """Altus Metrum's TeleMega export (RocketPy's data, MIT): accelerometer columns near 0 in
    every row (half of them exactly 0). `calib-jax accel` said 'no static interval ... noise
    level nan', `diagnose` 'axis x is saturated: use a wider range'. A log that is mostly
    exact zeros has no signal; one near 0 with no pose found holds no gravity in any unit
    (linear acceleration looks the same)."""
    rng = np.random.default_rng(0)
    # TeleMega's pattern: x held at a few hundredths for a dozen rows at a time, y and z 0
    # but for a rare count; the detector finds no pose in it
    held = np.zeros((3000, 3))
    held[:, 0] = np.repeat(rng.choice([0.0, 0.01, 0.02, 0.08], 250), 12)
    held[::500, 1], held[::700, 2] = 0.01, 0.01
    with pytest.raises(ValueError, match=r"reads about 0 \(median \|a\| 0\.02\).*no gravity"):
        cj.calibrate_accel(held, sample_rate=100.0)
    dead = 0.02 * rng.normal(size=(3000, 3))
    dead[::3] = 0.0
    dead[1::3] = 0.0
    with pytest.raises(ValueError, match="reads exactly 0 on every axis in 2000 of 3000 rows"):
        cj.calibrate_accel(dead, sample_rate=100.0)
    with pytest.raises(ValueError, match="magnetometer reads exactly 0"):
        cj.calibrate_mag(dead)
    # one still pose of 0.07 'g' (wadpac/GGIR's Axivity AX6 test export, a trial): refused for
    # its one pose alone, though its size fits no accelerometer: both are said now
    still = np.array([0.007, 0.07, 0.008]) + 0.003 * rng.normal(size=(3000, 3))
    with pytest.raises(ValueError, match=r"only 1 distinct pose.*Besides, the static readings "
                       r"have median norm 0\.07.*run calib-jax gyro") as err:  # fmt: skip
        cj.calibrate_accel(still, sample_rate=100.0)
    assert isinstance(err.value, cj.observations.TooFewPoses)
    with pytest.raises(ValueError, match="only 1 distinct pose") as err:  # counts: any size
        cj.calibrate_accel(still, sample_rate=100.0, units="counts")
    assert "Besides" not in str(err.value)


def test_solver_options_are_checked_against_the_solver():
    """A new user's calls: solver_options a solver does not take were a TypeError from inside
    the traced fit ('optx_solve() got an unexpected keyword argument ...', JAX's internal
    frames removed). Now a ValueError naming the bad options and listing the solver's own, on
    every path that takes solver_options (single fits and batches), before any fitting."""
    from calib_jax.cli import demo_log_path

    log = cj.load_log(demo_log_path())
    with pytest.raises(ValueError, match=r"\['jacobian'\] are not options of solver 'optimistix'"):
        calibrate_accel(log, solver="optimistix", solver_options={"jacobian": "broyden"})
    with pytest.raises(ValueError, match=r"\['max_iters'\] .* it takes .*max_iter"):
        calibrate_accel(log, solver_options={"max_iters": 2})
    with pytest.raises(ValueError, match="chosen by the solver's name"):
        cj.calibrate_mag(log.acc, solver="lm2", solver_options={"update_type": 3})
    with pytest.raises(ValueError, match=r"\['max_iters'\]"):
        cj.calibrate_accel_batch(log.acc[None], g=1.0, solver_options={"max_iters": 2})
    assert calibrate_accel(log, solver_options={"max_iter": 50}).success  # a real one works


def test_normalised_readings_are_refused_not_fitted_to_the_identity():
    """IvanVnucec/cubesat-adcs's magnetometer log (MIT) holds unit vectors, 1.000002 +- 2.9e-5:
    calib-jax mag returned W = I, a centre of 1e-6 and 'after 0.003 %' without a word. Now a
    ValueError says the readings were normalised; readings of a real ellipsoid pass."""
    rng = np.random.default_rng(0)
    u = rng.normal(size=(1500, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    with pytest.raises(ValueError, match=r"every sample's length is 1 within .*normalised"):
        cj.calibrate_mag(u + 1e-6 * rng.normal(size=u.shape))
    cal = cj.calibrate_mag(45.0 * u * [1.05, 0.97, 1.0] + [3.0, -2.0, 1.0] + 0.1 * rng.normal(
        size=u.shape))  # fmt: skip
    assert cal.status == "ok"


def test_a_log_of_one_face_is_not_told_to_fit_its_samples():
    """AirbrakesV2's xplus.csv, one face: every setting found one pose, and the refusal
    advised '--use samples --window 10 --threshold-factor 20', which found one pose too."""
    rng = np.random.default_rng(1)
    x = np.array([0.02, -0.01, 1.01]) + 2e-3 * rng.normal(size=(3000, 3))
    with pytest.raises(ValueError, match="only 1 distinct pose") as info:
        calibrate_accel(x, sample_rate=100.0)
    assert "--use samples" not in str(info.value) and "use='samples'" not in str(info.value)


@pytest.mark.wrong_types
def test_python_callers_wrong_types_are_named():
    """Arguments of the wrong type, as a notebook user passes them (the next test says which
    trial): an array to load_log, one candidate's name as a string."""
    from calib_jax.diagnose import diagnose_mag

    with pytest.raises(ValueError, match="load_log reads a file; it was given a ndarray"):
        cj.load_log(np.zeros((5, 3)))
    with pytest.raises(ValueError, match=r"unknown candidate effect\(s\) \['outliers'\]"):
        diagnose_mag(_tumble(seed=1), candidates="outliers", progress=False)  # one candidate
    # the second trial (2026-11-28): g as a string was "'<=' not supported between 'str' and
    # 'int'"; a sample rate of -5 or 0 Hz was taken ("window 3 samples (-0.6 s)")
    x = np.zeros((100, 3))
    with pytest.raises(ValueError, match=r"g='9.81': the reference magnitude must be a number"):
        cj.calibrate_accel(x, g="9.81")
    for rate in (-5, 0, float("nan")):
        with pytest.raises(ValueError, match="the sampling rate must be a positive number"):
            cj.calibrate_accel(x, sample_rate=rate)
    # a path where the pure fit takes an array (jit: 'not marked as static'); a MagParams given
    # to the accelerometer's from_params (float()'s TypeError)
    from calib_jax import pipeline as pl

    with pytest.raises(ValueError, match="fit_accel takes an \\(N, 3\\) array of readings"):
        pl.fit_accel(cj.mag_demo_log_path())
    with pytest.raises(ValueError, match="takes AccelParams, got MagParams"):
        cj.AccelCalibration.from_params(pl.MagParams(np.zeros(3), np.eye(3)))
    # jit of a host-side fit: TracerArrayConversionError, with no word of the pipeline
    import jax

    with pytest.raises(ValueError, match="inside JAX use calib_jax.pipeline"):
        jax.jit(cj.calibrate_accel)(np.zeros((100, 3)))
    # and apply takes a log's path as it takes the loaded log ("could not convert string")
    path = cj.mag_demo_log_path()
    np.testing.assert_array_equal(_accel_cal().apply(path), _accel_cal().apply(cj.load_log(path)))


def test_python_callers_mistakes_are_named():
    """A new user's notebook (this session's trial of the Python API): load_log given an array
    raised pathlib's TypeError (the README's comment said it took one); a misspelt diagnosis
    candidate was a bare KeyError, and one name as a string KeyError 'o' (iterated letter by
    letter); a (3, N) array was 'too few samples (3 finite)'; a gyro log's time in ms gave 697
    'poses' of a 38-pose log and a gyro scale of 1e-7 with no word of the time; a calibration
    applied to readings in another unit gave |a| 13.9 g on every row, silently; calibrate_marg
    took the magnetometer as the accelerometer."""
    import warnings

    from calib_jax.diagnose import diagnose_accel, diagnose_mag
    from calib_jax.simulate import simulate_gyro_log

    x = _tumble(seed=1)
    with pytest.raises(ValueError, match=r"unknown candidate effect\(s\) \['temperture'\]"):
        diagnose_accel(x, candidates=("temperture",), progress=False)
    with pytest.raises(ValueError, match=r"got shape \(3, 2000\); transpose it"):
        diagnose_mag(x.T, progress=False)
    s = simulate_gyro_log(6, n_poses=12)
    with pytest.raises(ValueError, match=r"steps by 10 s \(0.1 Hz\).*milliseconds"):
        cj.calibrate_gyro(s.acc, s.gyro, t=1000 * s.t)
    cal = _fit(x)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cal.apply(x)  # its own readings: no warning
    with pytest.warns(UserWarning, match=r"median magnitude of 5.066e\+04, where the field is 45:"):
        cal.apply(1000 * x)
    # the two sensors of calibrate_marg the other way round: 'ok', the rotation inverted
    tumble = cj.load_log(cj.mag_demo_log_path())
    with pytest.raises(ValueError, match="radius 0.3086.*passed the other way round"):
        cj.calibrate_marg(tumble.mag, tumble.acc)


def test_apply_on_the_command_line_exits_1_on_the_wrong_unit_and_times_rows_by_the_rate(
    tmp_path, capsys
):
    """A new-user trial: ``calib-jax apply`` of an Xsens record (counts) to a log in g wrote
    |a| of 79 m/s^2 on every axis, warned, and exited 0 (a script took it for success); and
    ``--sample-rate 90`` on a log without a time column wrote no ``t``. It now exits 1 with
    the file written, and ``t`` is the row number over the rate (the streamed path too)."""
    from calib_jax.cli import main

    log = tmp_path / "in_g.csv"
    rng = np.random.default_rng(5)
    d = rng.normal(size=(300, 3))
    np.savetxt(log, d / np.linalg.norm(d, axis=1, keepdims=True), delimiter=",",
               header="ax,ay,az", comments="")  # fmt: skip
    a = _accel_cal()
    counts = _accel_cal(params=a.params * np.r_[np.full(6, 4000.0), np.full(3, 1.0)],
                        input_units="counts")  # fmt: skip
    cal = tmp_path / "counts.json"
    counts.save(cal)
    own = tmp_path / "own.json"
    a.save(own)
    out = tmp_path / "out.csv"
    assert main(["apply", str(cal), str(log), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "not in counts" in err and f"{out} was written" in err
    assert out.read_text().startswith("ax,ay,az\n")  # no rate: no t
    for chunk in ("100", "1000000"):  # streamed in blocks of 100 rows, and read whole
        args = ["apply", str(own), str(log), "--out", str(out), "--sample-rate", "90"]
        assert main([*args, "--chunk-rows", chunk]) == 0
        table = np.loadtxt(out, delimiter=",", skiprows=1)
        np.testing.assert_allclose(table[:, 0], np.arange(300) / 90.0, rtol=1e-15)
        assert "row number over the sample rate (90 Hz)" in capsys.readouterr().out


def test_records_equal_whenever_fitted_and_apply_to_a_file_says_the_unit_is_wrong(tmp_path):
    """A Python user's trial (2026-11-28): two fits of one log a second apart were unequal
    (``==`` compared the fit's date), and an Xsens record (counts) applied to a log in g
    wrote |a| of 136 m/s^2 on every row without a word, where ``cal.apply(array)`` warned.
    apply_calibration now warns and notes it, in memory and to a file; the record's own log
    is written without a note."""
    import dataclasses

    from calib_jax.apply import apply_calibration

    a = _accel_cal()
    assert a == dataclasses.replace(a, date="2001-01-01T00:00:00+00:00")
    assert a != dataclasses.replace(a, params=a.params * 1.001)
    # nor how the log was named (a path as typed, none for an array: a Python user's trial)
    assert a == dataclasses.replace(a, source="../repo/log.csv")
    assert a != dataclasses.replace(a, sensor_id="board-2")  # which sensor it is still counts
    # a MARG record's dict nests its sensors' records, each with its own date (a review)
    from calib_jax.calibration import _without_provenance

    marg = {"kind": "marg", "date": "x", "accel": a.to_dict(), "mag": {"date": "y", "k": [1]}}
    assert _without_provenance(marg) == {"kind": "marg", "accel": _without_provenance(a.to_dict()),
                                    "mag": {"k": [1]}}  # fmt: skip
    assert "date" in a.to_dict() and "date" not in _without_provenance(a.to_dict())
    log = tmp_path / "in_g.csv"
    rng = np.random.default_rng(5)
    d = rng.normal(size=(200, 3))
    np.savetxt(log, d / np.linalg.norm(d, axis=1, keepdims=True), delimiter=",",
               header="ax,ay,az", comments="")  # fmt: skip
    counts = _accel_cal(params=a.params * np.r_[np.full(6, 4000.0), np.full(3, 1.0)],
                        input_units="counts")  # fmt: skip
    for out in (None, tmp_path / "out.csv"):
        with pytest.warns(UserWarning, match="not in counts"):
            res = apply_calibration(counts, log, out)
        assert any("median magnitude" in n for n in res.notes), res.notes
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = apply_calibration(a, log, tmp_path / "own.csv")
    assert not any("median magnitude" in n for n in res.notes)


@pytest.mark.wrong_types  # a list where the batch's annotation says an array
def test_python_callers_get_calib_jax_errors_not_numpys(tmp_path):
    """A Python user's trial met numpy's or the OS's errors where calib_jax knew better: a
    list of logs of two lengths to the batch ('inhomogeneous shape'), detect_static and
    from_fit of (3, N) readings (broadcasting), save() into a missing folder (the error named
    a temporary file), a JSON that is no calibration ('format_version None ... upgrade
    calib_jax'), apply_calibration of an array (os.fspath) and plot_mag of a loaded log."""
    from calib_jax.apply import apply_calibration
    from calib_jax.batch import calibrate_accel_batch
    from calib_jax.static import detect_static

    x = np.random.default_rng(0).normal(size=(500, 3))
    with pytest.raises(ValueError, match=r"different lengths \(500, 400\).*stack_rows"):
        calibrate_accel_batch([x, x[:400]])
    with pytest.raises(ValueError, match=r"\(samples, 3\), got shape \(3, 500\) \(transposed"):
        detect_static(x.T)
    a = _accel_cal()
    with pytest.raises(FileNotFoundError, match="its folder .*missing does not exist"):
        a.save(tmp_path / "missing" / "cal.json")
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"name": "imu", "gains": [1, 2, 3]}))
    with pytest.raises(ValueError, match=r"not a calib_jax calibration .*keys: name, gains"):
        AccelCalibration.load(other)
    out = apply_calibration(a, x, tmp_path / "out.csv")  # the one sensor a calibration holds
    np.testing.assert_allclose(np.loadtxt(tmp_path / "out.csv", delimiter=",", skiprows=1),
                               a.apply(x), rtol=1e-11, atol=1e-11)  # fmt: skip
    assert out.rows == 500
    log = cj.load_log(cj.mag_demo_log_path())
    mag = cj.calibrate_mag(log)
    from calib_jax.plots import plot_mag

    fig = plot_mag(mag, log)  # a loaded log, as calibrate_mag takes it
    # calibrate_marg took arrays only, and MARGRecord, which load errors name, was not
    # calib_jax's to import
    marg = cj.calibrate_marg(log)
    assert isinstance(marg, cj.MARGRecord) and marg == cj.calibrate_marg(log.acc, log.mag)
    with pytest.raises(ValueError, match="accelerometer and magnetometer"):
        cj.calibrate_marg(log.mag)
    assert len(fig.axes) >= 2
    with pytest.raises(ValueError, match=r"got shape \(3, 12000\) \(transposed\? pass raw.T\)"):
        plot_mag(mag, log.mag.T)
