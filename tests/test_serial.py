"""The serial adapter on real serial plumbing: loop://, pseudo-terminals and a simulated board.

The simulated board (calib_jax.io.sim_device) runs in its own process and writes to a pty; it
records every well-formed line it sent and every fault it injected, so the tests can check the
log line by line and the drop counts reason by reason. Its 100 Hz board clock is played ten
times faster than real time (1,000 lines/s) to keep the suite short.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
import tty
from pathlib import Path

import numpy as np
import pytest
import serial

from calib_jax import AccelCalibration, calibrate_mag
from calib_jax.io import load_log
from calib_jax.io.serial import DROP_REASONS, LogWriter, SerialReader, format_row, record
from calib_jax.io.sim_device import FAULT_REASONS, _inq, spawn
from calib_jax.record import calibrate_recording

# A board in tests: 24 poses held 1.0 s and moved 0.3 s (board time) at 100 Hz, played at
# 10x: about 3 s of real time per session. Static detection then needs a short window.
SIM = {"speed": 10, "hold": 1.0, "move": 0.3}
DETECT = {"window": 25, "min_static": 0.5}
WAIT = 60.0  # seconds: generous bound for a process to start (imports JAX) on a loaded CI box


def _wait_for(cond, what: str, proc: subprocess.Popen | None = None, timeout: float = WAIT):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return
        if proc is not None and proc.poll() is not None and not cond():
            raise AssertionError(f"process ended (rc {proc.returncode}) before {what}")
        time.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")


def _read_until(r: SerialReader, n: int, timeout: float = 10.0) -> None:
    """Read batches until ``n`` lines were accepted (a bounded wait, never a hang)."""
    end = time.monotonic() + timeout
    while r.stats.lines_ok < n:
        assert time.monotonic() < end, f"{r.stats.lines_ok} of {n} lines: {r.stats.summary()}"
        r.read_batch()


def _stop(proc: subprocess.Popen) -> None:
    """End a process this test started (by its handle), if it is still running."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)


def _start_board(tmp_path: Path, name: str, **options):
    link = tmp_path / name
    proc = spawn(link, tmp_path / f"{name}.json", **{**SIM, **options})
    _wait_for(link.is_symlink, f"the board at {link}", proc)
    return proc, link


def _n_rows(path: Path) -> int:
    """Complete rows in a log so far (0 before it exists)."""
    return max(path.read_bytes().count(b"\n") - 1, 0) if path.exists() else 0


def _log_rows(path: Path) -> tuple[list[str], list[list[float]], str]:
    """Header, the complete rows as floats, and any trailing partial line."""
    text = path.read_text()
    lines = text.split("\n")
    tail = lines.pop()  # '' when the file ends with a newline
    return lines[0].split(","), [[float(c) for c in ln.split(",")] for ln in lines[1:]], tail


def _expected(sent_path: Path, columns: list[str], scale: dict | None) -> list[list[float]]:
    """The log rows the sent lines must become (same columns; raw value times scale)."""
    factors = [((scale or {}).get(c[0]) or 1.0) if c != "t" else 1.0 for c in columns]
    rows = []
    for ln in sent_path.read_text().splitlines():
        vals = [float(v) for v in ln.split(",")]
        rows.append([v * f if f != 1.0 else v for v, f in zip(vals, factors, strict=True)])
    return rows


# ---------------------------------------------------------------------------------------------
# loop://


def test_loop_url_parses_counts_and_logs(tmp_path):
    """Every fault kind through loop://, with a device header, CRLF, scale and host time."""
    log = tmp_path / "loop.csv"
    got, msgs = [], []
    with SerialReader(
        "loop://",
        log=log,
        scale="a=0.001",
        max_line_bytes=64,
        callback=got.append,
        on_message=msgs.append,
    ) as r:
        r.port.write(
            b"23,-41\r\n"  # the tail of a line: the port opened mid-line
            b"ax,ay,az\r\n"  # header
            b"1000,-2000,500\r\n"
            b"1,2\r\n"  # field_count
            b"\xff\xfe\x80\r\n"  # decode
            b"1,x,3\r\n" + b"9" * 100 + b"\r\n"  # non_numeric  # too_long
            b"\t\r\n"  # blank: ignored
            b"ax,ay,gz\r\n"  # header with a partial triple: not a header -> non_numeric
            b"4 5 6\n"  # whitespace-separated
            b"7;8;9\n"
        )
        _read_until(r, 3)
        r.read_batch()  # nothing more may come
    assert r.stats.lines_ok == 3
    assert r.stats.header_lines == 1
    want = {"partial": 1, "decode": 1, "too_long": 1, "field_count": 1, "non_numeric": 2}
    assert r.stats.dropped == {k: want.get(k, 0) for k in DROP_REASONS}
    assert r.status == "closed" and "loop://: connected" in msgs
    header, rows, tail = _log_rows(log)
    assert header == ["t", "ax", "ay", "az"] and tail == ""
    counts = np.array([[1000, -2000, 500], [4, 5, 6], [7, 8, 9]], float)
    np.testing.assert_array_equal(np.array(rows)[:, 1:], counts * 0.001)  # exactly raw * scale
    t = np.array(rows)[:, 0]
    assert np.all(np.diff(t) >= 0) and np.all(t >= 0)  # host time: non-decreasing from 0
    # batches carry the same numbers as the log, through the callback too
    acc = np.concatenate([b.acc for b in got])
    np.testing.assert_array_equal(acc, np.array(rows)[:, 1:])
    assert got[0].columns == ("t", "ax", "ay", "az") and got[0].mag is None
    log_read = load_log(log)
    np.testing.assert_array_equal(log_read.acc, acc)


def test_loop_explicit_columns_and_header_mismatch():
    with SerialReader("loop://", columns="t,_,ax,ay,az", scale={"t": 1e-3}) as r:
        r.port.write(
            b"\n5,99,1,2,3\n"
            b"t,x,ax,ay,az\n"  # 'x' is no column name: a non-numeric line
            b"t,temp,ax,ay,az\n"  # agrees with the layout (which skips the second field)
            b"t,ax,ay,az,temp\n"  # contradicts it
            b"6,99,4,5,6\n"
        )
        batches = [r.read_batch() for _ in range(3)]
    acc = np.concatenate([b.acc for b in batches if len(b)])
    t = np.concatenate([b.t for b in batches if len(b)])
    np.testing.assert_array_equal(acc, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(t, [0.005, 0.006])
    assert r.stats.dropped["header_mismatch"] == 1 and r.stats.dropped["non_numeric"] == 1
    assert r.stats.header_lines == 1
    assert r.stats.dropped["partial"] == 0  # the port opened at a line boundary


def test_bad_settings_are_errors_that_say_what_to_change(tmp_path):
    with pytest.raises(ValueError, match="ax, ay, az|some but not all"):
        SerialReader("loop://", columns="t,ax,ay")
    with pytest.raises(ValueError, match="unknown column"):
        SerialReader("loop://", columns="t,acc,ay,az")
    with pytest.raises(ValueError, match="unknown scale key"):
        SerialReader("loop://", columns="ax,ay,az", scale="q=2")
    with pytest.raises(ValueError, match="non-zero"):
        SerialReader("loop://", columns="ax,ay,az", scale=0)
    existing = tmp_path / "x.csv"
    existing.write_text("t,ax,ay,az\n0,1,2,3\n")
    with pytest.raises(ValueError, match="resume=True.*overwrite=True"):
        SerialReader("loop://", log=existing)
    with pytest.raises(ValueError, match="exclude each other"):
        SerialReader("loop://", log=existing, resume=True, overwrite=True)
    with pytest.raises(ValueError, match="has columns t,ax,ay,az but this session records"):
        SerialReader("loop://", log=existing, resume=True, columns="ax,ay,az,mx,my,mz")
    assert existing.read_text() == "t,ax,ay,az\n0,1,2,3\n"  # never touched


def test_resume_appends_and_overwrite_replaces(tmp_path):
    path = tmp_path / "session.csv"
    # a previous session that died mid-line
    path.write_text("t,ax,ay,az\n1.5,0.1,0.2,0.3\n2.0,0.4,0.5")
    with SerialReader("loop://", log=path, resume=True, columns="ax,ay,az") as r:
        r.port.write(b"\n1,2,3\n4,5,6\n")
        _read_until(r, 2)
    text = path.read_text()
    assert text.count("t,ax,ay,az") == 1
    lines = text.splitlines()
    assert lines[1] == "1.5,0.1,0.2,0.3" and lines[2] == "2.0,0.4,0.5,incomplete"
    rows = [[float(c) for c in ln.split(",")] for ln in lines[3:]]
    assert [r_[1:] for r_ in rows] == [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]
    assert all(r_[0] >= 1.5 for r_ in rows)  # host time carries on after the old log
    log = load_log(path)  # the ended fragment is skipped or NaN, never a reading
    assert np.isfinite(log.acc).all(axis=1).sum() == 3
    with SerialReader("loop://", log=path, overwrite=True, columns="ax,ay,az") as r:
        r.port.write(b"\n7,8,9\n")
        _read_until(r, 1)
    assert path.read_text().splitlines()[1:][0].endswith("7.0,8.0,9.0")
    assert len(path.read_text().splitlines()) == 2


def test_log_writer_flushes_whole_lines(tmp_path):
    w = LogWriter(tmp_path / "w.csv", flush_interval=1e9, flush_lines=3)
    w.open(["t", "ax", "ay", "az"])
    for k in range(5):
        w.append(format_row([k, 1, 2, 3]))
        w.maybe_flush()
    # three rows reached the file at the third append; two still wait
    assert (tmp_path / "w.csv").read_text().count("\n") == 1 + 3
    w.close()
    assert (tmp_path / "w.csv").read_text().count("\n") == 1 + 5 and w.rows_written == 5


def test_trailing_separator_and_a_note_when_nothing_gets_through():
    """'1,2,3,' (a sketch printing a comma after every field) is a record; a stream of which
    nothing parses gets one message saying what to change."""
    msgs = []
    with SerialReader("loop://", on_message=msgs.append) as r:
        r.port.write(b"\nax,ay,az,\r\n1,2,3,\r\n4;5;6;\r\n")
        _read_until(r, 2)
    assert r.stats.header_lines == 1 and r.stats.dropped_total == 0
    msgs.clear()
    with SerialReader("loop://", columns="ax,ay,az", on_message=msgs.append) as r:
        # what a wrong baud rate looks like: bytes that are not text, now and then a line end
        r.port.write(b"\n" + b"\xe3\x9f\xa0\xff\x13\n" * 30)
        r.read_batch()
    assert r.stats.dropped["decode"] == 30 and r.stats.lines_ok == 0
    notes = [m for m in msgs if "no line accepted yet" in m]
    assert len(notes) == 1 and "baud" in notes[0], msgs


def test_headerless_layout_waits_for_two_lines_that_agree():
    """One odd line at power-up must not fix the layout for the whole session."""
    with SerialReader("loop://", on_message=lambda s: None) as r:
        r.port.write(b"\n7,8,9\n0.01,1,2,3\n0.02,4,5,6\n0.03,7,8,9\n")
        _read_until(r, 3)
    assert r.columns == ["t", "ax", "ay", "az"] and r.stats.dropped["field_count"] == 1
    with SerialReader("loop://", on_message=lambda s: None) as r:
        r.port.write(b"\n1,2,3\n")  # one line and no more: never confirmed, counted
        r.read_batch()
    assert r.stats.lines_ok == 0 and r.stats.dropped["no_columns"] == 1


def test_log_writer_takes_no_rows_after_close(tmp_path):
    """A late row (a reader thread that outlived its session's close) must not reopen, and
    so truncate, the log: it is refused."""
    path = tmp_path / "w.csv"
    w = LogWriter(path)
    w.open(["t", "ax", "ay", "az"])
    w.append(format_row([0, 1, 2, 3]))
    w.close()
    before = path.read_text()
    with pytest.raises(ValueError, match="closed"):
        w.append(format_row([1, 1, 2, 3]))
    with pytest.raises(ValueError, match="once"):
        w.open(["t", "ax", "ay", "az"])
    assert path.read_text() == before == "t,ax,ay,az\n0.0,1.0,2.0,3.0\n"
    # a log whose header lost its line end (a crash right at the start) resumes cleanly
    path.write_text("t,ax,ay,az")
    w = LogWriter(path, resume=True)
    w.open(["t", "ax", "ay", "az"])
    w.append(format_row([0, 1, 2, 3]))
    w.close()
    assert path.read_text() == "t,ax,ay,az\n0.0,1.0,2.0,3.0\n"


class _FlakyPort:
    """A port that opens and then fails on the first read (a flaky cable, another program on
    the port, a server that hangs up at once)."""

    opened = 0
    in_waiting = 0

    def __init__(self):
        _FlakyPort.opened += 1
        assert _FlakyPort.opened < 100, "reopened without backing off"

    def read(self, n):
        raise serial.SerialException("device reports readiness to read but returned no data")

    def close(self):
        pass


def test_port_that_fails_before_any_data_backs_off_and_gives_up(monkeypatch):
    """Opening is not enough to end an outage: without data the delays keep doubling, the
    reader gives up on time, and every batch still ends on time (its loop's stop checks)."""
    _FlakyPort.opened = 0
    monkeypatch.setattr(SerialReader, "_open_port", lambda self: _FlakyPort())
    msgs = []
    r = SerialReader(
        "flaky://",
        columns="ax,ay,az",
        backoff_initial=0.02,
        backoff_max=0.08,
        max_reconnect_seconds=0.5,
        on_message=msgs.append,
    )
    t0 = time.monotonic()
    with r:
        batches = list(r)
    assert r.status == "gave_up" and "max_reconnect_seconds" in r.status_message
    assert len(batches) >= 3  # the loop got control back while the port kept failing
    delays = [m.rsplit("retry in ", 1)[1] for m in msgs if "retry in" in m]
    assert delays[:4] == ["0.02 s", "0.04 s", "0.08 s", "0.08 s"], msgs  # doubling, capped
    assert _FlakyPort.opened <= 12 and time.monotonic() - t0 < WAIT


def test_lost_connection_flushes_what_was_read(tmp_path):
    """Lines read before an unplug are in the file at once, not when (if ever) the device
    comes back: the flush cadence is off here, yet every read is handed to the OS (issue 13),
    and the loss fsyncs them."""
    master, slave = os.openpty()
    tty.setraw(slave)
    log = tmp_path / "u.csv"
    r = SerialReader(
        os.ttyname(slave),
        log=log,
        columns="ax,ay,az",
        flush_interval=1e9,
        flush_lines=10**9,
        fsync_interval=1e9,
        on_message=lambda s: None,
    )
    try:
        with r:
            os.write(master, b"\n" + b"".join(b"%d,2,3\n" % k for k in range(50)) + b"7,8")
            _read_until(r, 50)
            assert _n_rows(log) == 50  # each read reaches the OS at once (issue 13)
            os.close(master)  # unplugged, mid-line
            master = None
            end = time.monotonic() + 5.0
            while r.connected and time.monotonic() < end:
                r.read_batch()
            assert r.status == "reconnecting" and r.stats.dropped["partial"] == 1
            assert _n_rows(log) == 50 and r.stats.lines_logged == 50
    finally:
        if master is not None:
            os.close(master)
        os.close(slave)
    assert [row[1:] for row in _log_rows(log)[1]] == [[float(k), 2.0, 3.0] for k in range(50)]


# Popen is replaced by a function that returns the command, not a Popen
@pytest.mark.wrong_types
def test_simulator_flags(monkeypatch):
    """spawn() turns keyword options into the simulator's own flags (send_t is --no-t)."""
    monkeypatch.setattr(subprocess, "Popen", lambda cmd, **kw: cmd)
    cmd = spawn("/tmp/imu", send_t=True, faults=True, header=False, speed=10)
    assert cmd[3:] == ["--link", "/tmp/imu", "--faults", "--speed", "10"]
    assert spawn("/tmp/imu", send_t=False)[-1] == "--no-t"


def test_unreachable_port_gives_up_with_a_status(tmp_path):
    msgs = []
    r = SerialReader(
        str(tmp_path / "no-such-device"),
        columns="ax,ay,az",
        max_reconnect_seconds=0.3,
        on_message=msgs.append,
    )
    with r:
        batches = list(r)
    assert all(len(b) == 0 for b in batches)
    assert r.status == "gave_up" and "max_reconnect_seconds" in r.status_message
    assert any("retrying" in m for m in msgs) and any("giving up" in m for m in msgs)
    assert not (tmp_path / "no-such-device").exists()


# ---------------------------------------------------------------------------------------------
# a pty in this process


def test_record_stops_on_ctrl_c_with_the_log_flushed(tmp_path):
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        lines = [f"{k * 0.01:.2f},{k},{-k},{2 * k}" for k in range(400)]
        os.write(master, ("\n" + "\n".join(lines) + "\n").encode())
        seen = []

        def stop(batch, stats):
            seen.append(len(batch))
            if stats.lines_ok >= 400:
                raise KeyboardInterrupt  # what Ctrl-C does in the loop
            return False

        rec = record(os.ttyname(slave), tmp_path / "r.csv", stop=stop, fsync_interval=0.0)
    finally:
        os.close(master)
        os.close(slave)
    assert rec.status == "interrupted" and "flushed" in rec.message
    assert rec.stats.lines_ok == 400 and rec.stats.lines_logged == 400
    header, rows, tail = _log_rows(tmp_path / "r.csv")
    assert header == ["t", "ax", "ay", "az"] and tail == ""
    assert rows == [[float(v) for v in ln.split(",")] for ln in lines]
    np.testing.assert_array_equal(rec.data.acc, np.array(rows)[:, 1:])


def test_record_on_a_real_ctrl_c_logs_each_line_once(tmp_path, default_sigint):
    """SIGINT lands wherever the reading loop is (parsing, flushing): the log still holds the
    lines from the first on, each once, in whole rows."""
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    done = threading.Event()

    def board():  # ~2,000 numbered lines a second until the test is over
        pending = memoryview(b"\n")
        k = 0
        while not done.is_set():
            if not pending:
                pending = memoryview(b"".join(b"%d,%d,1\n" % (j, -j) for j in range(k, k + 20)))
                k += 20
            try:
                pending = pending[os.write(master, pending) :]
            except BlockingIOError:
                pass  # the reader has stopped reading: wait for the end of the test
            time.sleep(0.01)

    writer = threading.Thread(target=board, daemon=True)
    timer = threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGINT))

    def press_soon(batch):  # armed from inside the loop: the SIGINT can only land in there
        if not timer.is_alive() and not timer.finished.is_set():
            timer.start()

    writer.start()
    try:
        rec = record(
            os.ttyname(slave),
            tmp_path / "c.csv",
            seconds=WAIT,
            columns="ax,ay,az",
            callback=press_soon,
        )
    finally:
        timer.cancel()
        done.set()
        writer.join(10)
        os.close(master)
        os.close(slave)
    assert rec.status == "interrupted", default_sigint
    header, rows, tail = _log_rows(tmp_path / "c.csv")
    assert header == ["t", "ax", "ay", "az"] and tail == ""
    assert 100 <= len(rows) == rec.stats.lines_logged
    assert [r_[1] for r_ in rows] == list(range(len(rows)))  # from the first, once, in order


def test_record_until_seconds_on_a_silent_port(tmp_path):
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        rec = record(os.ttyname(slave), tmp_path / "s.csv", seconds=0.3, stall_seconds=0.1)
    finally:
        os.close(master)
        os.close(slave)
    assert rec.status == "seconds" and rec.stats.lines_ok == 0 and rec.stats.stalls == 1
    assert not (tmp_path / "s.csv").exists()  # no empty log for a port that sent nothing


# ---------------------------------------------------------------------------------------------
# the simulated board


def test_board_with_faults_loses_no_line_and_counts_every_drop(tmp_path, tol):
    proc, link = _start_board(
        tmp_path, "imu", sensor="marg", faults=True, header=True, counts=True, crlf=True
    )
    msgs = []
    log = tmp_path / "session.csv"
    end = time.monotonic() + 2 * WAIT
    try:
        with SerialReader(
            str(link),
            log=log,
            scale="a=0.001,m=0.1",  # the board sends counts: 1 mg and 0.1 uT per LSB
            stall_seconds=0.3,
            max_reconnect_seconds=WAIT,
            on_message=msgs.append,
        ) as r:
            for _ in r:
                # the board drains its pty before it exits: once it has gone and the reader
                # has lost it, every byte it sent has been read
                if proc.poll() is not None and not r.connected:
                    break
                assert time.monotonic() < end, f"the board did not finish: {r.stats.summary()}"
        assert proc.wait(WAIT) == 0
    finally:
        _stop(proc)
    truth = json.loads((tmp_path / "imu.json").read_text())
    assert truth["complete"] and truth["disconnects"] == 1 and truth["stalls"] == 1

    # every well-formed line, once, in order, scaled
    header, rows, tail = _log_rows(log)
    assert header == ["t", "ax", "ay", "az", "mx", "my", "mz"] and tail == ""
    want = _expected(tmp_path / "imu.sent", truth["columns"], truth["scale"])
    assert len(rows) == truth["sent_lines"] == len(want) > 2000
    assert rows == want

    # every injected fault counted under its reason, and nothing else dropped
    injected = truth["faults"]
    assert set(injected) == set(FAULT_REASONS)
    assert injected["partial"] == 3 and min(injected.values()) >= 1
    assert r.stats.dropped == {k: injected.get(k, 0) for k in DROP_REASONS}
    assert r.stats.lines_ok == truth["sent_lines"] and r.stats.reconnects == 1
    assert r.stats.header_lines == 2  # on connect and again after the replug
    assert r.stats.stalls >= 1  # the stall (a loaded machine may add one, never remove it)
    assert any("connection lost" in m for m in msgs) and any("reconnected" in m for m in msgs)

    # the calibration of the log recovers the board's parameters (the magnetometer with the
    # full model directly: 'auto' would compile three models for the same check)
    # lm2: which samples a session loses to the unplug depends on timing, and lm1's stopping
    # test can miss convergence at such a noise-floor minimum (status not_converged at the
    # right parameters); the point here is the recovery, not the solver
    acc = calibrate_recording(log, "accel", solver="lm2", echo=None, **DETECT)["accel"]
    mag = calibrate_mag(load_log(log), model="full", field=truth["field"])
    assert acc.status == "ok" and mag.success
    # the fit's standard errors come from the scatter of the static means (noise 2 mg over
    # ~75 samples per pose, 1 mg counts): the truth must lie within N_SIGMA of them
    p = np.asarray(truth["accel_params"])
    assert np.all(np.abs(acc.params - p) <= tol.N_SIGMA * acc.stderr), (acc.params - p) / acc.stderr
    c, W = np.asarray(truth["mag_center"]), np.asarray(truth["mag_soft_iron"])
    assert np.all(np.abs(mag.center - c) <= tol.N_SIGMA * mag.stderr_center)
    assert np.all(np.abs(mag.soft_iron - W) <= tol.N_SIGMA * mag.stderr_soft_iron)
    assert AccelCalibration.load(log.with_suffix(".calib.json")).source == str(log)


def test_killed_recorder_leaves_the_log_intact(tmp_path):
    """SIGKILL the recorder mid-session: every complete line is a prefix of what was sent."""
    board, link = _start_board(tmp_path, "imu", poses=60)  # 8 s: long enough to kill mid-way
    out = tmp_path / "killed.csv"
    cmd = [sys.executable, "-m", "calib_jax.cli", "record", "--port", str(link)]
    cmd += ["--out", str(out), "--columns", "t,ax,ay,az", "--seconds", "120"]
    rec = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        # kill once the log holds a few hundred rows and the board is still sending
        _wait_for(lambda: _n_rows(out) >= 300, "rows in the log", rec)
        rec.send_signal(signal.SIGKILL)
        rec.wait(WAIT)
    finally:
        _stop(rec)
        _stop(board)
    truth = json.loads((tmp_path / "imu.json").read_text())
    assert not truth["complete"]  # the board was stopped mid-session: this was mid-session
    header, rows, tail = _log_rows(out)
    assert header == ["t", "ax", "ay", "az"]
    want = _expected(tmp_path / "imu.sent", truth["columns"], truth["scale"])
    assert 300 <= len(rows) < len(want)
    assert rows == want[: len(rows)]
    # at most one partial line, and it is the start of the next one
    assert tail == "" or format_row(want[len(rows)]).startswith(tail)
    # and the log is what the other commands read (a partial line would be a NaN row)
    np.testing.assert_array_equal(load_log(out).acc[: len(rows)], np.array(rows)[:, 1:])


def test_sigkill_loses_no_line_the_recorder_had_read(tmp_path):
    """Issue 13: SIGKILL the recorder while a board streams 1,000 lines a second. Every line
    the board sent is either in the log or still unread in the port's input queue, which this
    test reads after the kill; the recorder may hold back at most one line it had only partly
    received. Before each read batch was handed to the OS at once, ~85 lines were lost."""
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    paused, idle, done = threading.Event(), threading.Event(), threading.Event()
    sent = [0]

    def board():  # numbered lines, 10 every 10 ms, until paused
        pending = memoryview(b"\n")  # a line end first: the recorder drops a first partial line
        while not done.is_set():
            if paused.is_set() and not pending:
                idle.set()
                time.sleep(0.005)
                continue
            if not pending:
                k = sent[0]
                pending = memoryview(b"".join(b"%d,%d,1\n" % (j, -j) for j in range(k, k + 10)))
                sent[0] += 10
            try:
                pending = pending[os.write(master, pending) :]
            except BlockingIOError:
                pass
            time.sleep(0.01)

    out = tmp_path / "k.csv"
    cmd = [sys.executable, "-m", "calib_jax.cli", "record", "--port", os.ttyname(slave)]
    cmd += ["--out", str(out), "--columns", "ax,ay,az", "--seconds", "120"]
    writer = threading.Thread(target=board, daemon=True)
    writer.start()
    rec = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        _wait_for(lambda: _n_rows(out) >= 300, "rows in the log", rec)
        paused.set()  # the board stops between two whole lines: `sent` is final
        assert idle.wait(10)
        # killed once it has taken every line and the log has not grown for 50 ms: a batch
        # read and not yet written is a window no recorder can close, and a loaded CI box
        # (tests 2x slower) hit it with 315 lines. A recorder that holds read lines for its
        # 0.2 s flush (the defect this guards against) still loses them here, most times.
        quiet, rows = time.monotonic(), _n_rows(out)
        end = time.monotonic() + WAIT
        while time.monotonic() < end and (_inq(slave) or time.monotonic() - quiet < 0.05):
            if _n_rows(out) != rows:
                quiet, rows = time.monotonic(), _n_rows(out)
            if rec.poll() is not None:
                break
            time.sleep(0.02)
        rec.send_signal(signal.SIGKILL)
        rec.wait(WAIT)
    finally:
        _stop(rec)
        done.set()
        writer.join(10)
    os.set_blocking(slave, False)
    unread = b""
    try:
        while chunk := os.read(slave, 65536):
            unread += chunk
    except BlockingIOError:
        pass
    os.close(master)
    os.close(slave)
    header, rows, tail = _log_rows(out)
    assert header == ["t", "ax", "ay", "az"]
    logged = [int(r_[1]) for r_ in rows]
    assert logged == list(range(len(logged)))  # from the first line, once each, in order
    if tail:  # a row cut by the kill inside its write: it reached the log, in part
        rest = tail.split(",", 1)[1] if "," in tail else ""  # after the host's time stamp
        assert format_row([len(logged), -len(logged), 1]).startswith(rest)
        logged.append(len(logged))
    assert unread == b"" or unread.endswith(b"\n")  # the board paused between whole lines

    def whole(line: str) -> bool:  # "j,-j,1"; a line's tail read off its front is not
        f = line.split(",")
        return len(f) == 3 and f[0].isdigit() and int(f[1]) == -int(f[0]) and f[2] == "1"

    left = unread.decode().splitlines()
    if not left:  # the recorder had read everything the board sent
        consumed, partial = sent[0], 0
    elif whole(left[0]):
        consumed, partial = int(left[0].split(",")[0]), 0
    else:  # the queue starts with the tail of a line the recorder held in part
        consumed, partial = int(left[1].split(",")[0]) if len(left) > 1 else sent[0], 1
    lost = consumed - partial - len(logged)
    assert lost == 0, f"{lost} lines read by the recorder are neither in the log nor unread"
    assert len(logged) >= 300
