"""A simulated IMU board on a pseudo-terminal: try ``calib-jax record`` without hardware.

::

    python -m calib_jax.io.sim_device --link /tmp/imu0 --sensor marg --header &
    calib-jax record --port /tmp/imu0 --out session.csv --sensor marg

The simulator opens a pseudo-terminal (``os.openpty``, raw mode) and publishes its slave side
under the symlink ``--link``, which is what the reader opens (as it would open
``/dev/ttyACM0``). It then prints one line per sample, like a board on USB serial: the board
is held in ``--poses`` static poses spread over the sphere, joined by hand-held moves, as
:func:`calib_jax.simulate.simulate_session` simulates them (paper 1's accelerometer, paper 2's
ellipsoid for the magnetometer).

Time: ``t`` is the board's clock at ``--rate`` Hz; ``--speed`` plays it faster than real time
(the tests run a 100 Hz board ten times faster).

Faults (``--faults``): the first line after each connection starts mid-line; malformed lines
(wrong field count, non-numeric fields) and garbage bytes (invalid UTF-8) every
``--fault-every`` lines; one over-long line; a stall followed by a burst of the backlog; an
unplug (the line in flight is cut, the symlink disappears, the pty closes) and a replug (a new
pty under the same symlink) while samples are lost.

Ground truth (``--truth FILE.json``): the true parameters, the number of each fault injected
(by the reason a reader should give) and the count of well-formed lines; every well-formed
line is also appended to ``FILE.sent`` (exactly as sent, before it is written to the pty) so a
test can check that a log holds each of them once and in order. Before hanging up, the
simulator waits until the reader has taken every byte (the kernel drops unread input when the
master closes), so the counts are exact whenever a reader is attached.
"""

from __future__ import annotations

import argparse
import fcntl
import json
import os
import signal
import struct
import subprocess
import sys
import termios
import time
import tty
from pathlib import Path

import numpy as np

from ..simulate import simulate_session

FAULT_REASONS = ("partial", "decode", "too_long", "field_count", "non_numeric")


def format_lines(
    session: dict,
    columns: list[str],
    *,
    delimiter: str = ",",
    acc_lsb: float | None = None,
    mag_lsb: float | None = None,
) -> list[str]:
    """The text of each sample's line in ``columns`` order; with an LSB the sensor sends
    integer counts (value / lsb, rounded)."""
    cols = {"t": session["t"]}
    for i, x in enumerate("xyz"):
        cols["a" + x] = session["acc"][:, i]
        cols["m" + x] = session["mag"][:, i]
    out = []
    fmt = {}
    for c in columns:
        if c == "t":
            fmt[c] = lambda v: f"{v:.4f}"
        elif c[0] == "a":
            fmt[c] = (lambda v: str(int(round(v / acc_lsb)))) if acc_lsb else (lambda v: f"{v:.5f}")
        else:
            fmt[c] = (lambda v: str(int(round(v / mag_lsb)))) if mag_lsb else (lambda v: f"{v:.3f}")
    n = len(session["t"])
    for i in range(n):
        out.append(delimiter.join(fmt[c](cols[c][i]) for c in columns))
    return out


# ---------------------------------------------------------------------------------------------
# the pseudo-terminal


def _inq(fd: int) -> int:
    """Bytes waiting in the pty's input queue (written by us, not yet read by the reader)."""
    return struct.unpack("i", fcntl.ioctl(fd, termios.TIOCINQ, b"\0\0\0\0"))[0]


class _Pty:
    """A raw pseudo-terminal published under a symlink; we keep the slave open too, so data
    written before the reader opens waits in the queue instead of being lost."""

    def __init__(self, link: Path) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        tmp = link.with_name(link.name + ".tmp")
        if tmp.is_symlink() or tmp.exists():
            tmp.unlink()
        os.symlink(os.ttyname(self.slave), tmp)
        os.replace(tmp, link)  # atomic: the reader sees the old pty or the new one
        self.link = link

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            n = os.write(self.master, view)
            view = view[n:]

    def drain(self, timeout: float = 10.0) -> bool:
        """Wait until the reader has taken everything (True) or ``timeout`` passed."""
        time.sleep(0.05)  # let the kernel move the bytes from the master to the input queue
        end = time.monotonic() + timeout
        quiet = 0
        while time.monotonic() < end:
            quiet = quiet + 1 if _inq(self.slave) == 0 else 0
            if quiet >= 3:
                return True
            time.sleep(0.02)
        return False

    def hang_up(self) -> None:
        if self.link.is_symlink() and os.readlink(self.link) == os.ttyname(self.slave):
            self.link.unlink()
        os.close(self.master)
        os.close(self.slave)


# ---------------------------------------------------------------------------------------------
# the board


def run_device(
    link: str | Path,
    *,
    truth: str | Path | None = None,
    sensor: str = "accel",
    rate: float = 100.0,
    speed: float = 1.0,
    poses: int = 24,
    hold: float = 1.0,
    move: float = 0.3,
    send_t: bool = True,
    header: bool = False,
    counts: bool = False,
    delimiter: str = ",",
    crlf: bool = False,
    faults: bool = False,
    fault_every: int = 150,
    stall: float = 0.6,
    unplug: float = 0.3,
    seed: int = 0,
    wait_reader: float = 30.0,
) -> dict:
    """Play a simulated session into a pty published at ``link``; returns the truth dict.

    See the module docstring. ``wait_reader``: seconds to wait at the end (and before the
    unplug) for a reader to take the bytes still queued.
    """
    link = Path(link)
    if sensor not in ("accel", "mag", "marg"):
        raise ValueError(f"sensor must be accel, mag or marg, got {sensor!r}")
    sess = simulate_session(poses=poses, hold=hold, move=move, rate=rate, seed=seed)
    columns = (["t"] if send_t else []) + {
        "accel": ["ax", "ay", "az"],
        "mag": ["mx", "my", "mz"],
        "marg": ["ax", "ay", "az", "mx", "my", "mz"],
    }[sensor]
    acc_lsb = 0.001 if counts else None  # 1 mg per count
    mag_lsb = 0.1 if counts else None  # 0.1 uT per count
    lines = format_lines(sess, columns, delimiter=delimiter, acc_lsb=acc_lsb, mag_lsb=mag_lsb)
    n = len(lines)
    eol = b"\r\n" if crlf else b"\n"
    rng = np.random.default_rng(seed + 1)
    injected = dict.fromkeys(FAULT_REASONS, 0)
    head_line = delimiter.join(columns).encode() + eol
    truth_path = Path(truth) if truth is not None else None
    sent_file = open(truth_path.with_suffix(".sent"), "w") if truth_path else None  # noqa: SIM115
    info = {
        **sess["truth"],
        "columns": columns,
        "delimiter": delimiter,
        "scale": {"a": acc_lsb, "m": mag_lsb} if counts else None,
        "speed": speed,
        "sensor": sensor,
        "header": header,
        "faults": injected,
        "sent_lines": 0,
        "stalls": 0,
        "disconnects": 0,
        "complete": False,
    }

    # where the faults go (sample indices)
    stall_at = int(0.4 * n) if faults else -1
    unplug_at = int(0.6 * n) if faults else -1
    long_at = int(0.25 * n) if faults else -1
    bad_at = set(range(fault_every, n, fault_every)) if faults else set()
    cycle = ("field_count", "non_numeric", "decode")

    def bad_line(i: int, kind: str) -> bytes:
        fields = lines[i].split(delimiter)
        if kind == "field_count":
            fields = fields[:-1] if i % 2 else [*fields, fields[-1]]
            return delimiter.join(fields).encode() + eol
        if kind == "non_numeric":
            fields[len(fields) // 2] = ("ovf", "1.2.3", "--", "NaNx")[i % 4]
            return delimiter.join(fields).encode() + eol
        junk = bytes(rng.integers(0x80, 0x100, size=int(rng.integers(4, 24)), dtype=np.uint8))
        return b"\xff" + junk + eol  # 0xFF is never valid UTF-8

    def connect_preamble() -> bytes:
        # the board was already talking: the reader catches the end of a line
        injected["partial"] += 1
        out = lines[int(rng.integers(0, n))][5:].encode() + eol
        return out + (head_line if header else b"")

    # the truth as set up is on disk before the link appears, so a board stopped any way at
    # all (even killed) leaves its parameters; the counts are final when "complete" is true
    # or the board was stopped by SIGTERM
    _write_truth(truth_path, info)

    def on_term(signum, frame):  # noqa: ARG001
        raise SystemExit(0)

    old = signal.signal(signal.SIGTERM, on_term)
    # a blocked SIGTERM inherited from the parent would leave the board deaf to its stop signal
    signal.pthread_sigmask(signal.SIG_UNBLOCK, [signal.SIGTERM])
    pty = _Pty(link)
    try:
        pty.write(connect_preamble())
        period = 1.0 / (rate * speed)
        start = time.monotonic()
        i = 0
        while i < n:
            due = min(n, int((time.monotonic() - start) / period) + 1)
            if due <= i:
                time.sleep(min(period, 0.005))
                continue
            chunk, good = [], []
            while i < due:
                if i == stall_at:
                    stall_at = -1
                    break
                if i == unplug_at:
                    break
                if i in bad_at:
                    kind = cycle[(i // fault_every) % 3]
                    injected[kind] += 1
                    chunk.append(bad_line(i, kind))
                if i == long_at:
                    injected["too_long"] += 1
                    chunk.append(b"1," * 3000 + b"1" + eol)
                chunk.append(lines[i].encode() + eol)
                good.append(lines[i])
                i += 1
            if sent_file is not None and good:
                sent_file.write("\n".join(good) + "\n")
                sent_file.flush()
            info["sent_lines"] += len(good)
            if chunk:
                pty.write(b"".join(chunk))
            if i < due and i != unplug_at:  # a stall: nothing for a while, then the backlog
                info["stalls"] += 1
                time.sleep(stall)
            elif i == unplug_at and i < n:
                unplug_at = -1
                injected["partial"] += 1
                pty.write(lines[i].encode()[: len(lines[i]) // 2])  # cut mid-line
                pty.drain(wait_reader)
                pty.hang_up()
                info["disconnects"] += 1
                time.sleep(unplug)
                pty = _Pty(link)
                # samples due while unplugged are lost; the board carries on from now
                i = min(n, int((time.monotonic() - start) / period) + 1)
                pty.write(connect_preamble())
        pty.drain(wait_reader)
        info["complete"] = True
    finally:
        signal.signal(signal.SIGTERM, old)
        try:
            pty.hang_up()
        except OSError:
            pass
        if sent_file is not None:
            sent_file.close()
        _write_truth(truth_path, info)
    return info


def _write_truth(path: Path | None, info: dict) -> None:
    """Write ``info`` as JSON at ``path`` atomically (a reader never sees half a file)."""
    if path is not None:
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(info, indent=1))
        os.replace(tmp, path)


def spawn(link: str | Path, truth: str | Path | None = None, **options) -> subprocess.Popen:
    """Start :func:`run_device` in a new process (``python -m calib_jax.io.sim_device``).

    Keyword options are the command-line flags with underscores (``speed=10``,
    ``faults=True``).
    """
    cmd = [sys.executable, "-m", "calib_jax.io.sim_device", "--link", str(link)]
    if truth is not None:
        cmd += ["--truth", str(truth)]
    for k, v in options.items():
        flag = "--" + k.replace("_", "-")
        if k == "send_t":  # the flag is --no-t; sending t is the default
            cmd += [] if v else ["--no-t"]
        elif v is True:
            cmd.append(flag)
        elif v is not None and v is not False:
            cmd += [flag, str(v)]
    return subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stdin=subprocess.DEVNULL)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m calib_jax.io.sim_device",
        description="A simulated IMU on a pseudo-terminal (see the module docstring).",
    )
    p.add_argument("--link", required=True, help="symlink path for the reader, e.g. /tmp/imu0")
    p.add_argument("--truth", default=None, help="write the ground truth JSON here")
    p.add_argument("--sensor", default="accel", choices=["accel", "mag", "marg"])
    p.add_argument("--rate", type=float, default=100.0, help="board sample rate (Hz)")
    p.add_argument("--speed", type=float, default=1.0, help="play faster than real time")
    p.add_argument("--poses", type=int, default=24)
    p.add_argument("--hold", type=float, default=2.5, help="seconds per pose (board time)")
    p.add_argument("--move", type=float, default=1.0, help="seconds per move (board time)")
    p.add_argument("--no-t", dest="send_t", action="store_false", help="send no time column")
    p.add_argument("--header", action="store_true", help="print a header line on connect")
    p.add_argument("--counts", action="store_true", help="integer counts: 1 mg, 0.1 uT per LSB")
    p.add_argument("--delimiter", default=",", help="field separator (',', tab, ' ')")
    p.add_argument("--crlf", action="store_true", help="end lines with CR LF")
    p.add_argument("--faults", action="store_true", help="inject the faults listed above")
    p.add_argument("--fault-every", type=int, default=150)
    p.add_argument("--stall", type=float, default=0.6, help="stall length (real seconds)")
    p.add_argument("--unplug", type=float, default=0.3, help="unplugged time (real seconds)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--wait-reader", type=float, default=30.0)
    args = p.parse_args(argv)
    delim = {"tab": "\t", "\\t": "\t", "space": " "}.get(args.delimiter, args.delimiter)
    print(f"simulated board on {args.link} (Ctrl-C to stop)", flush=True)
    try:
        info = run_device(
            args.link,
            truth=args.truth,
            sensor=args.sensor,
            rate=args.rate,
            speed=args.speed,
            poses=args.poses,
            hold=args.hold,
            move=args.move,
            send_t=args.send_t,
            header=args.header,
            counts=args.counts,
            delimiter=delim,
            crlf=args.crlf,
            faults=args.faults,
            fault_every=args.fault_every,
            stall=args.stall,
            unplug=args.unplug,
            seed=args.seed,
            wait_reader=args.wait_reader,
        )
    except KeyboardInterrupt:
        return 130
    print(f"sent {info['sent_lines']} lines; faults {info['faults']}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
