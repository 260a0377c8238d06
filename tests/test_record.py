"""Guided recording: coverage feedback, Ctrl-C, and several boards feeding one batch fit."""

from __future__ import annotations

import json
import os
import signal
import threading
import tty

import numpy as np
import pytest

import calib_jax as cj
from calib_jax.cli import main
from calib_jax.io.serial import LogWriter, format_row
from calib_jax.record import (
    PAPER1_POSES,
    assess_coverage,
    calibrate_devices,
    calibrate_recording,
    calibration_paths,
    device_paths,
    record_session,
)
from calib_jax.simulate import (
    paper48_directions,
    plane_turn_quaternions,
    random_params,
    simulate_accel,
    simulate_marg,
    simulate_session,
    tumble_quaternions,
)

from .test_serial import DETECT, WAIT, _expected, _log_rows, _n_rows, _start_board, _stop

# ---------------------------------------------------------------------------------------------
# coverage


def test_paper48_protocol_is_enough():
    sim = simulate_accel(random_params(3), samples_per_pose=250, transition_samples=40, rng=3)
    cov = assess_coverage(sim.raw, None, sample_rate=sim.sample_rate)
    assert cov.static_intervals == 48 and cov.poses == PAPER1_POSES
    assert cov.faces_missing == [] and cov.octants_missing == [] and cov.enough
    assert cov.fraction == 1.0
    assert cov.line().endswith("coverage enough")


def test_upper_hemisphere_says_what_is_missing():
    dirs = paper48_directions()
    sim = simulate_accel(
        random_params(4), dirs[dirs[:, 2] > 0.5], samples_per_pose=250, transition_samples=40
    )
    cov = assess_coverage(sim.raw, None, sample_rate=sim.sample_rate)
    assert cov.poses == 16 and not cov.enough
    assert "-z" in cov.faces_missing and "+z" not in cov.faces_missing
    assert sorted(cov.octants_missing) == ["+x+y-z", "+x-y-z", "-x+y-z", "-x-y-z"]
    text = cov.missing()
    assert "no pose with" in text and "-z" in text and f"{PAPER1_POSES - 16} more poses" in text


def test_magnetometer_coverage_tumble_against_one_axis_turn():
    tumble = simulate_marg(tumble_quaternions(3000, rng=1), rng=1)
    turn = simulate_marg(plane_turn_quaternions(3000, incline_deg=0.0), rng=1)
    full = assess_coverage(tumble.acc, tumble.mag, sensor="mag")
    flat = assess_coverage(turn.acc, turn.mag, sensor="mag")
    assert full.mag_fraction > 0.7 and full.enough and full.mag_faces_missing == []
    assert flat.mag_fraction < 0.3 and not flat.enough
    assert "tumble through more orientations" in flat.missing()


def test_gyro_coverage_names_the_axes_not_turned_about_and_the_post_fit_is_calibrate_gyro(
    tmp_path,
):
    """A pose log whose turns all go about z: the guidance names x and y (the fit would refuse
    it); with turns about all axes nothing is missing. The recorder's post-fit of one gyro log
    (calibrate_gyro, written beside the log) and of several (the batch's gyro entries) agree
    to 1e-12."""
    from calib_jax.gyro import GyroCalibration
    from calib_jax.simulate import simulate_gyro_log

    only_z = simulate_gyro_log(1, n_poses=12, axes=np.array([[0.0, 0.0, 1.0]]))
    cov = assess_coverage(only_z.acc, None, only_z.gyro, sensor="gyro", sample_rate=100.0)
    assert cov.turn_axes_missing == ["x", "y"] and not cov.enough
    assert "no turn about the gyro's x, y axes yet" in cov.missing()
    full = simulate_gyro_log(5, n_poses=12)
    cov = assess_coverage(full.acc, None, full.gyro, sensor="gyro", sample_rate=100.0)
    assert cov.turn_axes_missing == [] and "turn" not in cov.missing()
    assert assess_coverage(full.acc, None, sensor="accel").turn_axes_missing is None

    paths = []
    for k, s in enumerate((full, simulate_gyro_log(6, n_poses=12))):
        paths.append(tmp_path / f"g{k}.csv")
        table = np.column_stack([s.t, s.acc, s.gyro])
        np.savetxt(paths[-1], table, delimiter=",", header="t,ax,ay,az,gx,gy,gz", comments="")
    one = calibrate_recording(paths[0], "gyro", echo=None)["gyro"]
    assert GyroCalibration.load(calibration_paths(paths[0], "gyro")["gyro"]) == one
    both = calibrate_devices(paths, "gyro", echo=None)
    assert [r["gyro"]["status"] for r in both] == ["ok", "ok"]
    np.testing.assert_allclose(both[0]["gyro"]["params"][:9], one.matrix.ravel(), rtol=1e-12)
    assert one.rms_after_deg < 2.0 * one.noise_floor_deg  # a real fit, not a pass-through


def test_file_names():
    assert device_paths("s.csv", 1)[0].name == "s.csv"
    assert [p.name for p in device_paths("d/s.csv", 2)] == ["s.dev0.csv", "s.dev1.csv"]
    assert calibration_paths("s.csv", "accel")["accel"].name == "s.calib.json"
    names = {k: v.name for k, v in calibration_paths("s.dev1.csv", "marg").items()}
    assert names == {
        "accel": "s.dev1.accel.calib.json",
        "mag": "s.dev1.mag.calib.json",
        "marg": "s.dev1.marg.json",
    }


# ---------------------------------------------------------------------------------------------
# recording from simulated boards


def test_ctrl_c_stops_flushes_and_calibrates(tmp_path, tol, default_sigint):
    """A real SIGINT to this process while recording: the session stops as interrupted, the log
    holds every line read, in order, and what was recorded calibrates."""
    board, link = _start_board(tmp_path, "imu")
    out = tmp_path / "rec.csv"
    main_thread = threading.main_thread()
    session_rows = 24 * 130  # 24 poses of 100 + 30 samples

    pressed = []

    def echo(text: str) -> None:
        # progress lines come from the main loop; press Ctrl-C once, when most poses are in
        if (
            not pressed
            and threading.current_thread() is main_thread
            and _n_rows(out) >= 0.9 * session_rows
        ):
            pressed.append(text)
            os.kill(os.getpid(), signal.SIGINT)

    try:
        session = record_session(
            [str(link)],
            out,
            columns="t,ax,ay,az",
            seconds=WAIT,
            progress_interval=0.2,
            echo=echo,
            max_reconnect_seconds=WAIT,
            **DETECT,
        )
    finally:
        _stop(board)
    assert session.reason == "interrupted", default_sigint
    stats = session.devices[0].reader.stats
    truth = json.loads((tmp_path / "imu.json").read_text())
    header, rows, tail = _log_rows(out)
    assert tail == "" and len(rows) == stats.lines_ok == stats.lines_logged
    assert rows == _expected(tmp_path / "imu.sent", truth["columns"], None)[: len(rows)]
    # lm2: where Ctrl-C falls changes the samples, and lm1's stopping test can miss
    # convergence at a noise-floor minimum (see test_serial); recovery is the point here
    cal = calibrate_recording(out, "accel", solver="lm2", echo=None, **DETECT)["accel"]
    p = np.asarray(truth["accel_params"])
    # within N_SIGMA standard errors of the fit (2 mg noise over ~75 samples per pose)
    assert cal.status == "ok" and np.all(np.abs(cal.params - p) <= tol.N_SIGMA * cal.stderr)


def test_record_command_two_boards_one_batch_fit(tmp_path, capsys, tol):
    boards = [_start_board(tmp_path, f"imu{k}", seed=k, header=k == 0) for k in range(2)]
    out = tmp_path / "rec.csv"
    try:
        rc = main(
            [
                "record",
                *("--port", str(boards[0][1]), "--port", str(boards[1][1])),
                *("--out", str(out), "--sensor", "accel", "--columns", "t,ax,ay,az"),
                *("--seconds", str(WAIT), "--max-reconnect", "2", "--target-poses", "20"),
                *("--window", "25", "--min-static", "0.5"),
            ]
        )
    finally:
        for proc, _ in boards:
            _stop(proc)
    captured = capsys.readouterr()
    assert rc == 0, captured.out + captured.err
    assert "poses" in captured.err and "stopped after" in captured.err
    for k in range(2):
        log = tmp_path / f"rec.dev{k}.csv"
        rec = cj.BatchRecord.load(tmp_path / f"rec.dev{k}.calib.json")
        assert rec.sensor == "accel" and len(rec) == 1
        a = rec.entries[0]
        assert a["path"] == str(log) and a["status"] == "ok" and a["static_intervals"] >= 20
        truth = json.loads((tmp_path / f"imu{k}.json").read_text())
        p, se = np.asarray(a["params"]), np.asarray(a["stderr"])
        # the fit of the interval means (2 mg noise over ~20 poses of ~75 samples each)
        assert np.all(np.abs(p - truth["accel_params"]) <= tol.N_SIGMA * se), (
            p - truth["accel_params"]
        ) / se
        assert f"rec.dev{k}.calib.json" in captured.out
    # each device's log is what `calib-jax accel FILE` reads (lm2: the solver the other
    # recordings here are calibrated with, so this reuses its compilation)
    dev1 = str(tmp_path / "rec.dev1.csv")
    assert main(["accel", dev1, "--window", "25", "--min-static", "0.5", "--solver", "lm2"]) == 0


def _write_log(path, session, columns=("t", "ax", "ay", "az")):
    """A log as a recording writes it, from a simulated session."""
    w = LogWriter(path)
    w.open(list(columns))
    data = {"t": session["t"][:, None], "ax": session["acc"], "mx": session["mag"]}
    for row in np.column_stack([data[c] for c in columns if c in data]):
        w.append(format_row(row))
    w.close()


def _silent_port():
    master, slave = os.openpty()
    tty.setraw(slave)
    return master, slave


def test_nothing_recorded_is_an_error_and_the_old_file_is_left(tmp_path, capsys):
    """--overwrite on a port that sends nothing: the previous session's file must not be
    calibrated as if it were this one's."""
    out = tmp_path / "rec.csv"
    _write_log(out, simulate_session(poses=24, hold=1.0, move=0.3, rate=100.0, seed=3))
    before = out.read_bytes()
    master, slave = _silent_port()
    try:
        rc = main(
            ["record", "--port", os.ttyname(slave), "--out", str(out), "--overwrite"]
            + ["--seconds", "0.3", "--columns", "t,ax,ay,az"]
        )
    finally:
        os.close(master)
        os.close(slave)
    err = capsys.readouterr().err
    assert rc != 0 and "nothing was recorded" in err and "left as it was" in err, err
    assert out.read_bytes() == before and not out.with_suffix(".calib.json").exists()


# a SimpleNamespace stands in for the SerialReader
@pytest.mark.wrong_types
def test_one_dead_board_does_not_cost_the_other_its_calibration(tmp_path, capsys, monkeypatch):
    """Two ports, one of which sent nothing: the live board's complete log is calibrated and its
    JSON written, the dead one is named on stderr, and the exit code says not everything
    worked (it used to refuse the whole session)."""
    import types

    import calib_jax.record as record

    good, dead = tmp_path / "rec.dev0.csv", tmp_path / "rec.dev1.csv"
    _write_log(good, simulate_session(poses=24, hold=1.5, move=0.4, rate=100.0, seed=5))

    def device(path, lines):
        stats = types.SimpleNamespace(lines_ok=lines)
        return record.Device(url=str(path), path=path, reader=types.SimpleNamespace(stats=stats))

    session = record.Session(
        devices=[device(good, 1000), device(dead, 0)],
        sensor="accel",
        reason="devices_gone",
        seconds=1.0,
    )
    monkeypatch.setattr(record, "record_session", lambda *a, **k: session)
    rc = main(["record", "--port", "a", "--port", "b", "--out", str(tmp_path / "rec.csv")])
    err = capsys.readouterr().err
    assert rc == 1, err
    assert "nothing was recorded into" in err and str(dead) in err
    assert "calibrating the other 1 device" in err
    # one live board: calibrated as a single port calibrates, an AccelCalibration
    assert cj.AccelCalibration.load(good.with_suffix(".calib.json")).status == "ok"
    assert not dead.with_suffix(".calib.json").exists()


@pytest.mark.parametrize("progress", [False, True])
def test_resumed_rows_count_towards_the_coverage(tmp_path, capsys, progress):
    """--resume to add the missing poses: the progress counts the poses already in the log;
    with the progress bar on, the bar stands at their share of the 48 poses."""
    out = tmp_path / "rec.csv"
    _write_log(out, simulate_session(poses=24, hold=1.0, move=0.3, rate=100.0, seed=4))
    rows = _n_rows(out)
    master, slave = _silent_port()
    lines = []
    try:
        session = record_session(
            [os.ttyname(slave)],
            out,
            columns="t,ax,ay,az",
            seconds=0.3,
            resume=True,
            echo=lines.append,
            progress=progress,
            **DETECT,
        )
    finally:
        os.close(master)
        os.close(slave)
    cov = session.devices[0].coverage
    assert cov.samples == rows and cov.poses >= 20, "\n".join(lines)
    assert 0 < cov.fraction == cov.poses / PAPER1_POSES < 1 and not cov.enough
    bar = capsys.readouterr().err
    if progress:
        share = round(100 * cov.poses / PAPER1_POSES)
        assert "recording accel" in bar and f"{share}/100" in bar and cov.line() in bar, bar
    else:
        assert bar == ""  # the lines went to echo
    assert any(f"{rows} rows from before" in m for m in lines)
    assert _n_rows(out) == rows  # nothing new came, nothing was changed


def test_batch_of_marg_logs(tmp_path):
    """The magnetometer half of the batch path, on logs written as a recording writes them."""
    paths, truths = [], []
    for k in range(2):
        s = simulate_session(poses=24, hold=1.0, move=0.3, rate=100.0, seed=10 + k)
        _write_log(tmp_path / f"m{k}.csv", s, ("t", "ax", "ay", "az", "mx", "my", "mz"))
        paths.append(tmp_path / f"m{k}.csv")
        truths.append(s["truth"])
    res = calibrate_devices(paths, "marg", field=45.0, echo=None, **DETECT)
    for r, tr in zip(res, truths, strict=True):
        assert r["accel"]["status"] == "ok" and r["mag"]["status"] == "ok"
        # centre: well inside the 0.2 uT noise times a few over thousands of samples
        params = r["mag"]["params"]
        np.testing.assert_allclose(params[:3], tr["mag_center"], atol=0.05)
        np.testing.assert_allclose(np.reshape(params[3:], (3, 3)), tr["mag_soft_iron"], atol=2e-3)
    # each sensor where a single port writes it: a BatchRecord of one entry
    for p, r in zip(paths, res, strict=True):
        for kind in ("accel", "mag"):
            rec = cj.BatchRecord.load(p.with_suffix(f".{kind}.calib.json"))
            assert rec == cj.BatchRecord(kind, [r[kind]])
        assert rec.entries[0]["field"] == 45.0
        hard_iron = rec.to_params()[str(p)].hard_iron
        np.testing.assert_array_equal(hard_iron, r["mag"]["params"][:3])
        # and `calib-jax export` reads it (a one-entry batch is that sensor's calibration)
        from calib_jax import export

        corr = export.read(p.with_suffix(".mag.calib.json"))["mag"]
        np.testing.assert_array_equal(corr.bias, r["mag"]["params"][:3])


def test_one_marg_log_gets_the_marg_record(tmp_path):
    """A single ``--sensor marg`` log: the accelerometer and magnetometer JSON, and the board's
    MARG record as ``calib-jax marg`` writes it (kind 'marg', not a free-form alignment dict
    as before issue 14). The simulated board has no mounting rotation, a 60 deg dip and
    0.2 uT noise: the dip within 0.5 deg and the rotation within 1 deg of the identity."""
    from calib_jax.marg import MARGRecord
    from calib_jax.record import calibrate_recording

    s = simulate_session(poses=24, hold=1.0, move=0.3, rate=100.0, seed=3)
    path = tmp_path / "m.csv"
    _write_log(path, s, ("t", "ax", "ay", "az", "mx", "my", "mz"))
    res = calibrate_recording(path, "marg", field=45.0, echo=None, **DETECT)
    rec = res["marg"]
    assert rec.status == "ok" and rec.accel_method == "static"
    assert rec == MARGRecord.load(path.with_suffix(".marg.json"))
    assert rec.accel == cj.AccelCalibration.load(path.with_suffix(".accel.calib.json"))
    assert abs(rec.dip_deg - 60.0) < 0.5 and rec.rotation_deg < 1.0


def test_batch_path_checks_g_against_the_unit(tmp_path):
    """Issue 13: logs in m/s^2 (static norm 9.8) calibrated with g = 1 are refused with the
    log named (the output would silently be in g with gains of 9.8); g = 9.80665 or no g
    (detected from the norm) calibrate."""
    paths = []
    for k in range(2):
        s = simulate_session(poses=24, hold=1.0, move=0.3, rate=100.0, seed=20 + k)
        s = {**s, "acc": 9.80665 * s["acc"]}
        _write_log(tmp_path / f"a{k}.csv", s)
        paths.append(tmp_path / f"a{k}.csv")
    with pytest.raises(ValueError, match=r"a0.csv: g = 1 does not match.*m/s\^2"):
        calibrate_devices(paths, "accel", g=1.0, echo=None, **DETECT)
    assert not any(p.with_suffix(".calib.json").exists() for p in paths)
    for g in (9.80665, None):
        res = calibrate_devices(paths, "accel", g=g, echo=None, **DETECT)
        assert all(r["accel"]["status"] == "ok" and r["accel"]["g"] == 9.80665 for r in res)
