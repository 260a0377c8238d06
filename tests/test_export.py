"""Issue 18: a saved calibration in other tools' formats, and applied to logs.

Each format is checked by the tool's own reader where it runs here: gcc compiles the C header
and runs its function; a C++ reader that reads the imu_tk file the way imu_tk's
``CalibratedTriad_::load`` does (``>>`` into row-major T, K, then B) and applies its
X' = T K (X - B); imucal's ``CalibrationInfo.from_json_file`` and ``calibrate``; PyYAML for
imu_calib's YAML. Every round trip returns the correction to float64 round-off (17 digits
written: relative error below 1e-15; we allow 1e-13 for the products T K and inv(R) inv(K)).
``calib-jax apply`` is checked against the published imucal calibration of imucal's own
example session, and streamed output against the whole-file path.
"""

import json
import re
import shutil
import subprocess
import tracemalloc
import warnings

import numpy as np
import pytest

from calib_jax import export
from calib_jax.apply import apply_calibration
from calib_jax.calibration import FitStatusWarning
from calib_jax.cli import demo_log_path, main
from calib_jax.io import load_log

from .conftest import shared_file
from .test_input_checks import _accel_cal, _mag_cal

RNG = np.random.default_rng(7)
RAW = RNG.normal(size=(40, 3)) * np.array([1.0, 1.0, 1.0])
ROT = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # x <- +y, y <- +x, z <- -z


def _marg_dict():
    """A MARG record as ``calib-jax marg --json`` writes it, with permuted magnetometer axes."""
    c, s = np.cos(0.03), np.sin(0.03)
    R = ROT @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return {
        "format_version": 1,
        "kind": "marg",
        "status": "ok",
        "source": "board.csv",
        "R_mag_to_acc": R.tolist(),
        "accel": _accel_cal().to_dict(),
        "mag": _mag_cal(
            soft_iron=np.array([[1.1, 0.02, 0.0], [0.02, 0.9, 0.01], [0, 0.01, 1]])
        ).to_dict(),
    }


def _rel(a, b):
    return np.max(np.abs(np.asarray(a) - b)) / np.max(np.abs(b))


def _compile(tmp_path, name, source, compiler, flags):
    if shutil.which(compiler) is None:
        pytest.skip(f"no {compiler} on this machine")
    src = tmp_path / name
    src.write_text(source)
    exe = tmp_path / (name + ".exe")
    subprocess.run([compiler, *flags, str(src), "-o", str(exe)], check=True, capture_output=True)
    return exe


def _run(exe, *args, stdin: np.ndarray):
    text = "\n".join(" ".join(f"{v:.17g}" for v in row) for row in stdin)
    out = subprocess.run([str(exe), *args], input=text, capture_output=True, text=True, check=True)
    return np.array([[float(v) for v in ln.split()] for ln in out.stdout.splitlines()])


def test_c_header_compiles_and_corrects_like_python(tmp_path):
    """gcc -std=c99 -Wall -Wextra -pedantic -Werror compiles it; its float functions agree
    with the float64 correction to float32 round-off: constants rounded to float32 (9 digits)
    and three multiply-adds give a few ulp, so 2e-6 of |C| |raw - b| bounds it."""
    marg = _marg_dict()
    (tmp_path / "board_cal.h").write_text(export.write(marg, "c", name="board"))
    raw = RAW * 50.0
    main_c = """#include <stdio.h>
#include "board_cal.h"
int main(void) {
    float r[3], a[3], m[3];
    while (scanf("%f %f %f", &r[0], &r[1], &r[2]) == 3) {
        board_accel_correct(r, a);
        board_mag_correct(r, m);
        printf("%.9g %.9g %.9g %.9g %.9g %.9g\\n", a[0], a[1], a[2], m[0], m[1], m[2]);
    }
    return 0;
}
"""
    flags = ["-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", f"-I{tmp_path}"]
    out = _run(_compile(tmp_path, "main.c", main_c, "gcc", flags), stdin=raw)
    corr = export.corrections(marg)
    for cols, c in ((slice(0, 3), corr["accel"]), (slice(3, 6), corr["mag"])):
        scale = np.linalg.norm(c.matrix, 2) * np.linalg.norm(raw - c.bias, axis=1)[:, None]
        assert np.all(np.abs(out[:, cols] - c.apply(raw)) <= 2e-6 * scale)


IMU_TK_READER = """#include <fstream>
#include <iostream>
// reads the file the way imu_tk's CalibratedTriad_::load does: 9 numbers into the
// misalignment (row-major), 9 into the scale, 3 into the bias; applies X' = T K (X - B)
int main(int argc, char** argv) {
    std::ifstream f(argv[1]);
    double T[9], K[9], B[3];
    for (int i = 0; i < 9; i++) f >> T[i];
    for (int i = 0; i < 9; i++) f >> K[i];
    for (int i = 0; i < 3; i++) f >> B[i];
    if (!f) return 2;
    double x[3];
    std::cout.precision(17);
    while (std::cin >> x[0] >> x[1] >> x[2]) {
        double d[3], kd[3];
        for (int i = 0; i < 3; i++) d[i] = x[i] - B[i];
        for (int i = 0; i < 3; i++) kd[i] = K[3*i] * d[0] + K[3*i+1] * d[1] + K[3*i+2] * d[2];
        for (int i = 0; i < 3; i++)
            std::cout << T[3*i] * kd[0] + T[3*i+1] * kd[1] + T[3*i+2] * kd[2]
                      << (i < 2 ? " " : "\\n");
    }
    return 0;
}
"""


@pytest.mark.parametrize("sensor", ["accel", "mag"])
def test_imu_tk_file_reads_as_imu_tk_reads_it(tmp_path, sensor):
    """For the MARG record's accelerometer (T with imu_tk's unit diagonal) and its permuted
    magnetometer (column-norm K): imu_tk's reading of the file applies our correction to
    1e-13 relative."""
    marg = _marg_dict()
    path = tmp_path / "cal.txt"
    path.write_text(export.write(marg, "imu_tk", sensor=sensor))
    exe = _compile(tmp_path, "reader.cpp", IMU_TK_READER, "g++", ["-O1"])
    c = export.corrections(marg)[sensor]
    raw = RAW * 30.0
    assert _rel(_run(exe, str(path), stdin=raw), c.apply(raw)) < 1e-13
    T, K = export.imu_tk_factors(c)
    if sensor == "accel":
        np.testing.assert_array_equal(np.diag(T), 1.0)  # imu_tk's misalignment form
    np.testing.assert_allclose(T @ K, c.matrix, rtol=0, atol=1e-15 * np.abs(c.matrix).max())


def test_imucal_loads_our_json_and_corrects_like_us(tmp_path):
    """imucal's own loader and ``calibrate``: the accelerometer as ours to 1e-13, the
    gyroscope passed through unchanged (calib_jax writes identity gyro terms and says so in
    ``comment``); K_a R_a is Ferraris' form (K_a diagonal, R_a rows unit)."""
    imucal = pytest.importorskip("imucal")
    cal = _accel_cal(input_units="a.u.", output_units="m/s^2")
    path = tmp_path / "cal.json"
    path.write_text(export.write(cal, "imucal"))
    info = imucal.CalibrationInfo.from_json_file(path)
    assert type(info).__name__ == "FerrarisCalibrationInfo"
    assert "NOT calibrated" in info.comment
    gyr = RNG.normal(size=RAW.shape)
    acc, gyr_out = info.calibrate(RAW * 200, gyr, acc_unit="a.u.", gyr_unit=None)
    with pytest.warns(UserWarning, match="median magnitude"):  # random readings, off scale
        assert _rel(acc, cal.apply(RAW * 200)) < 1e-13
    np.testing.assert_array_equal(gyr_out, gyr)
    assert np.count_nonzero(info.K_a - np.diag(np.diag(info.K_a))) == 0
    np.testing.assert_allclose(np.linalg.norm(info.R_a, axis=1), 1.0, rtol=1e-15)


def test_ros_yaml_read_by_pyyaml_is_in_m_per_s2(tmp_path):
    """imu_calib applies corrected = SM raw - bias to sensor_msgs/Imu, in m/s^2: a calibration
    to g is scaled by 9.80665 (REP 103); PyYAML reads the block."""
    yaml = pytest.importorskip("yaml")
    cal = _accel_cal()  # output units g
    d = yaml.safe_load(export.write(cal, "ros"))
    SM, bias = np.reshape(d["SM"], (3, 3)), np.asarray(d["bias"])
    ros = RAW @ SM.T - bias
    assert _rel(ros, 9.80665 * cal.apply(RAW)) < 1e-14


def test_a_pipeline_fit_of_counts_exports_as_calibrate_accel_does():
    """A pipeline fit of raw counts made a record with output units 'counts' (from_fit used
    the input unit for both), so its ROS export skipped the g -> m/s^2 factor: SM 9.80665x too
    small beside calibrate_accel's record of the same poses (a new user's run). Now the output
    unit follows calibrate_accel's rule (g for counts) and the two exports agree to the fits'
    own agreement (the solvers stop at round-off: 1e-9 relative)."""
    import jax.numpy as jnp

    import calib_jax as cj
    from calib_jax import pipeline as pl

    cal = cj.calibrate_accel(demo_log_path())  # the shipped imu_tk Xsens log, in counts
    assert (cal.input_units, cal.output_units) == ("counts", "g")
    means = jnp.asarray(cal.static_means)
    rec = cj.AccelCalibration.from_fit(pl.fit_accel(means, 1.0), means, 1.0, units="counts")
    assert rec.output_units == "g"
    ours, theirs = (export.write(c, "ros") for c in (rec, cal))
    nums = [np.array(re.findall(r"-?\d+\.\d+(?:e[-+]?\d+)?", t), float) for t in (ours, theirs)]
    np.testing.assert_allclose(nums[0], nums[1], rtol=1e-9)


@pytest.mark.parametrize("fmt", ["imu_tk", "imucal", "ros"])
@pytest.mark.parametrize("sensor", ["accel", "mag"])
def test_round_trip_through_every_format(tmp_path, fmt, sensor):
    """write -> file -> export.read gives the same correction (17 digits written), for the
    MARG record's triads; imucal holds no magnetometer and says so."""
    marg = _marg_dict()
    c = export.corrections(marg)[sensor]
    if fmt == "imucal" and sensor == "mag":
        with pytest.raises(ValueError, match="no magnetometer|no mag"):
            export.write(marg, fmt, sensor=sensor)
        return
    path = tmp_path / f"cal.{fmt}"
    path.write_text(export.write(marg, fmt, sensor=sensor))
    back = export.read(path, sensor=sensor)[sensor]
    scale = 9.80665 if (fmt == "ros" and sensor == "accel") else 1.0  # g -> m/s^2 for ROS
    assert _rel(back.matrix, scale * c.matrix) < 1e-13
    assert _rel(back.bias, c.bias) < 1e-13
    if fmt == "ros":  # the units its comment states come back (they were None)
        out = "m/s^2" if sensor == "accel" else c.output_units
        assert (back.input_units, back.output_units) == (c.input_units, out), back


def test_marg_magnetometer_correction_is_in_the_accelerometer_frame():
    """C = R_mag_to_acc W: x = R W (raw - centre), the MARG record's frame convention."""
    marg = _marg_dict()
    corr = export.corrections(marg)
    W, ctr = np.asarray(marg["mag"]["soft_iron"]), np.asarray(marg["mag"]["center"])
    R = np.asarray(marg["R_mag_to_acc"])
    np.testing.assert_allclose(corr["mag"].apply(RAW), (RAW - ctr) @ W.T @ R.T, atol=1e-14)
    assert corr["mag"].frame == "accel"
    with pytest.raises(ValueError, match="accel and mag.*--sensor"):
        export.write(marg, "imu_tk")


def test_published_imucal_calibration_applied_to_its_session(tmp_path, capsys):
    """imucal's published example calibration (its regression snapshot) applied by
    ``calib-jax apply`` to the raw session it was computed from: both triads equal imucal's own
    ``calibrate`` (R_a^-1 K_a^-1 (raw - b_a); R_g^-1 K_g^-1 (raw - K_ga a - b_g) with the
    calibrated a) to 1e-11 (12 digits written), |a| on the six faces is 9.81 m/s^2 within
    0.5 % (raw: 1992-2139 a.u.), and streamed and whole-file outputs are the same bytes."""
    cal, log = (
        shared_file("imucal_ferraris/example_cal.json"),
        shared_file("imucal_ferraris/annotated_session.csv"),
    )
    out, out2 = tmp_path / "whole.csv", tmp_path / "streamed.csv"
    assert main(["apply", str(cal), str(log), "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "corrected gyro: x = C (raw - b - G a)" in said and "not applied" not in said
    assert main(["apply", str(cal), str(log), "--out", str(out2), "--chunk-rows", "700"]) == 0
    assert "streamed in chunks" in capsys.readouterr().out
    assert out.read_bytes() == out2.read_bytes()
    # a new file is readable like any the user writes (it came out 0600, a temporary file's)
    assert out.stat().st_mode & 0o777 == 0o644
    out.chmod(0o664)  # an existing file keeps its mode
    assert main(["apply", str(cal), str(log), "--out", str(out)]) == 0
    assert out.stat().st_mode & 0o777 == 0o664

    d = json.loads(cal.read_text())
    raw = load_log(log)
    ref = (raw.acc - d["b_a"]) @ (np.linalg.inv(d["R_a"]) @ np.linalg.inv(d["K_a"])).T
    got = load_log(out)
    assert len(got) == len(raw) == 9414
    assert _rel(got.acc, ref) < 1e-11
    imucal = pytest.importorskip("imucal")
    info = imucal.CalibrationInfo.from_json_file(cal)
    acc_ref, gyr_ref = info.calibrate(raw.acc, raw.gyro, acc_unit="a.u.", gyr_unit="a.u.")
    assert _rel(got.acc, acc_ref) < 1e-11
    assert _rel(got.gyro, gyr_ref) < 1e-11
    part = np.loadtxt(log, delimiter=",", skiprows=1, usecols=0, dtype=str)
    for face in ("x_p", "x_a", "y_p", "y_a", "z_p", "z_a"):
        norm = np.linalg.norm(got.acc[part == face].mean(axis=0))
        assert abs(norm / 9.81 - 1) < 5e-3, (face, norm)


def test_streaming_keeps_rows_and_time_and_bounds_memory(tmp_path):
    """A 60,000-row log with a time column in ms, a comment line, a NaN cell and one ragged
    row, applied in chunks of 1,500: the NaN row is kept (NaN out), the ragged row is skipped
    and counted as the loader counts it, the time is in seconds in every chunk, the output
    equals the whole-file path, and the peak of traced allocations stays under a fifth of
    what reading the log whole takes (the chunks are 1/40 of it)."""
    n = 60_000
    t_ms = np.arange(n) * 10.0
    acc = RNG.normal(size=(n, 3)) * 0.01 + [0.0, 0.0, 1.0]
    body = np.column_stack([t_ms, acc])
    body[1234, 2] = np.nan
    path = tmp_path / "log.csv"
    with open(path, "w") as fh:
        fh.write("time_ms,ax,ay,az\n")
        np.savetxt(fh, body[:30_000], fmt="%.10g", delimiter=",")
        fh.write("# a comment in the middle\n1,2\n")
        np.savetxt(fh, body[30_000:], fmt="%.10g", delimiter=",")
    cal = _accel_cal()

    tracemalloc.start()
    rep = apply_calibration(cal, path, tmp_path / "s.csv", chunk_rows=1_500)
    streamed_peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.reset_peak()
    whole = load_log(path)
    whole_peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()

    assert rep.streamed and rep.rows == n
    assert any("1 row had the wrong number of fields" in m for m in rep.notes)
    got = load_log(tmp_path / "s.csv")
    np.testing.assert_allclose(got.t, t_ms / 1000.0, rtol=1e-15)
    np.testing.assert_allclose(got.acc, cal.apply(whole.acc), rtol=1e-11, atol=1e-12)
    assert np.isnan(got.acc[1234]).all() and np.isfinite(np.delete(got.acc, 1234, 0)).all()
    assert streamed_peak < whole_peak / 5, (streamed_peak, whole_peak)


def test_apply_and_export_cli_errors_name_the_cause(tmp_path, capsys):
    """Arguments swapped, a missing calibration, a log without the calibrated sensor: exit 2
    with the cause, and nothing written."""
    cal = tmp_path / "acc.json"
    _accel_cal().save(cal)
    mag_only = tmp_path / "mag.csv"
    mag_only.write_text("mx,my,mz\n" + "\n".join("1,2,3" for _ in range(20)) + "\n")
    log = shared_file("imucal_ferraris/annotated_session.csv")
    cases = [
        (["apply", str(log), str(cal)], "calibration first, then the log"),
        (["apply", str(tmp_path / "none.json"), str(log)], "does not exist"),
        (["apply", str(cal), str(mag_only)], "no ax, ay, az columns"),
        (["export", str(_write_mag(tmp_path)), "--format", "imucal"], "no magnetometer"),
    ]
    for argv, says in cases:
        assert main(argv) == 2, argv
        assert says in capsys.readouterr().err, argv
    assert not (tmp_path / "mag.calibrated.csv").exists()


def test_apply_and_export_warn_of_a_calibration_that_is_not_ok(tmp_path, capsys):
    """A poorly determined calibration is still applied and exported (exit 0), with a warning
    on stderr naming its status (a C header got only a comment); an 'ok' one gets none."""
    import dataclasses

    cal = tmp_path / "acc.json"
    _accel_cal().save(cal)
    out = tmp_path / "acc.h"
    assert main(["export", str(cal), "--format", "c", "--out", str(out)]) == 0
    assert "warning" not in capsys.readouterr().err
    dataclasses.replace(_accel_cal(), status="poorly_determined").save(cal)
    log = tmp_path / "log.csv"
    log.write_text("ax,ay,az\n" + "\n".join("0.1,0.2,1.0" for _ in range(5)) + "\n")
    for argv in (["export", str(cal), "--format", "c"], ["apply", str(cal), str(log)]):
        assert main(argv) == 0, argv
        said = capsys.readouterr().err
        assert "warning: the accel calibration's status is 'poorly_determined'" in said, argv
    # a failed one: once on the command line, and in Python, where apply and export said
    # nothing (a Python user's trial applied and exported gains of 461, 1826 and 69)
    failed = dataclasses.replace(_accel_cal(), status="failed")
    failed.save(cal)
    assert main(["apply", str(cal), str(log)]) == 0
    assert capsys.readouterr().err.count("status is 'failed'") == 1
    for use in (
        lambda: failed.apply(np.ones((5, 3))),
        lambda: export.write(failed, "c"),
        lambda: apply_calibration(failed, log),
        lambda: apply_calibration(str(cal), log, tmp_path / "o.csv"),
    ):
        with pytest.warns(FitStatusWarning, match="status is 'failed'.*no calibration"):
            use()
    with warnings.catch_warnings():
        warnings.simplefilter("error", FitStatusWarning)
        dataclasses.replace(failed, status="poorly_determined").apply(np.ones((5, 3)))


def _write_mag(tmp_path):
    p = tmp_path / "mag.json"
    _mag_cal().save(p)
    return p


@pytest.mark.parametrize("make", [_accel_cal, _mag_cal], ids=["accel", "mag"])
def test_every_json_writes_both_linear_forms(make, tmp_path):
    """Issue 14: one convention in every calibration JSON: 'correction' (true = C (raw - b))
    and 'forward' (raw = A true + b). Applied by hand to raw readings, the correction gives
    what the calibration's own apply gives (to round-off, 1e-12 relative), the forward form
    undoes it, and A C = I; the file loads back equal (the blocks are derived, not read)."""
    cal = make()
    d = cal.to_dict()
    C, A = np.array(d["correction"]["matrix"]), np.array(d["forward"]["matrix"])
    b = np.array(d["correction"]["offset"])
    assert d["forward"]["offset"] == d["correction"]["offset"]
    np.testing.assert_allclose(A @ C, np.eye(3), atol=1e-12)
    raw = np.random.default_rng(0).normal(size=(50, 3)) * 30 + b
    true = (raw - b) @ C.T
    with warnings.catch_warnings():  # random readings: apply warns where they are off scale
        warnings.simplefilter("ignore", UserWarning)
        applied = cal.apply(raw)
    np.testing.assert_allclose(true, applied, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(true @ A.T + b, raw, rtol=1e-12)
    cal.save(tmp_path / "cal.json")
    assert type(cal).load(tmp_path / "cal.json") == cal


def _accel_gyro(asymmetry=None):
    """An accelerometer to m/s^2 and a gyroscope with g-sensitivity G (made-up numbers)."""
    acc = export.Correction(
        "accel", np.diag([9.7, 9.9, 9.8]) @ (np.eye(3) + 0.01 * ROT), np.array([0.02, -0.01, 0.03]),
        input_units="g", output_units="m/s^2", status="ok",
    )  # fmt: skip
    gyro = export.Correction(
        "gyro", 0.0175 * (np.eye(3) + 0.02 * RNG.normal(size=(3, 3))), np.array([0.5, -0.3, 0.1]),
        input_units="deg/s", output_units="rad/s", status="ok",
        g_sensitivity=0.01 * RNG.normal(size=(3, 3)), scale_asymmetry=asymmetry,
    )  # fmt: skip
    return {"accel": acc, "gyro": gyro}


def test_gyro_with_g_sensitivity_in_imucal_and_c_and_refused_elsewhere(tmp_path):
    """A gyroscope with G: imucal's own loader and calibrate give our rates (G as K_ga, the
    acceleration calibrated first) to 1e-13, and export.read returns C, b and G; the C header
    takes the acceleration and applies G and the scale asymmetry like Python (float32:
    2e-6 of the scale); imu_tk and imu_calib, which cannot hold G, refuse with the formats
    that can."""
    corr = _accel_gyro()
    acc_raw, gyr_raw = RAW + [0.0, 0.0, 1.0], 30.0 * RAW
    acc = corr["accel"].apply(acc_raw)
    want = corr["gyro"].apply(gyr_raw, acc=acc)
    assert _rel(want, corr["gyro"].apply(gyr_raw)) > 1e-3  # G matters here
    path = tmp_path / "cal.json"
    path.write_text(export.write(corr, "imucal"))
    imucal = pytest.importorskip("imucal")
    info = imucal.CalibrationInfo.from_json_file(path)
    a_imucal, w_imucal = info.calibrate(acc_raw, gyr_raw, acc_unit="g", gyr_unit="deg/s")
    assert _rel(a_imucal, acc) < 1e-13 and _rel(w_imucal, want) < 1e-13
    back = export.read(path)
    np.testing.assert_allclose(back["gyro"].g_sensitivity, corr["gyro"].g_sensitivity, rtol=1e-15)
    assert _rel(back["gyro"].matrix, corr["gyro"].matrix) < 1e-13

    asym = _accel_gyro(asymmetry=np.array([0.01, -0.02, 0.005]))
    (tmp_path / "imu_cal.h").write_text(export.write(asym, "c", name="imu"))
    main_c = """#include <stdio.h>
#include "imu_cal.h"
int main(void) {
    float r[3], a[3], w[3];
    while (scanf("%f %f %f %f %f %f", &r[0], &r[1], &r[2], &a[0], &a[1], &a[2]) == 6) {
        imu_gyro_correct(r, a, w);
        printf("%.9g %.9g %.9g\\n", w[0], w[1], w[2]);
    }
    return 0;
}
"""
    flags = ["-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", f"-I{tmp_path}"]
    exe = _compile(tmp_path, "gyro.c", main_c, "gcc", flags)
    out = _run(exe, stdin=np.hstack([gyr_raw, acc]))
    g = asym["gyro"]
    scale = np.linalg.norm(g.matrix, 2) * np.linalg.norm(gyr_raw - g.bias, axis=1)[:, None]
    assert np.all(np.abs(out - g.apply(gyr_raw, acc=acc)) <= 2e-6 * scale)
    for fmt in ("imu_tk", "ros"):
        with pytest.raises(ValueError, match="g-sensitivity G.*cannot hold.*imucal"):
            export.write(corr, fmt, sensor="gyro")
    with pytest.raises(ValueError, match="scale asymmetry s.*cannot hold"):
        export.write(asym, "imucal")


def test_apply_removes_g_sensitivity_with_the_corrected_acceleration(tmp_path):
    """calib-jax apply with an accelerometer and a gyroscope: G a uses the corrected
    acceleration of the same rows (in m/s^2); a gyroscope alone says G was not applied."""
    from calib_jax.io.files import SensorLog

    corr = _accel_gyro()
    log = SensorLog(acc=RAW + [0.0, 0.0, 1.0], gyro=30.0 * RAW, path="board.csv")
    both = apply_calibration(corr, log)
    acc = corr["accel"].apply(log.acc)
    np.testing.assert_allclose(both.gyro, corr["gyro"].apply(log.gyro, acc=acc), rtol=1e-14)
    alone = apply_calibration({"gyro": corr["gyro"]}, log)
    np.testing.assert_allclose(alone.gyro, corr["gyro"].apply(log.gyro), rtol=1e-14)
    assert any("g-sensitivity G is not applied" in n for n in alone.notes)
