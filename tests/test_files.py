"""The log loader (calib_jax.io.files): any real log, no flags (issue 13).

Each test covers a class of file, not one case: a layout that is guessed, a wrong answer that
must not come back, an error that must say what to change, an encoding that must be read.
"""

from __future__ import annotations

import bz2
import gzip
import os
import string
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from calib_jax.io import canonical_name, load_log, parse_columns
from calib_jax.io import files as F

ROWS = np.array(
    [
        [0.01 * i, 10 + i, 20 + i, 30 + i, 40 + i, 50 + i, 60 + i, 70 + i, 80 + i, 90 + i]
        for i in range(8)
    ],
    dtype=float,
)


def _write(tmp_path, text, name="log.csv", encoding="utf-8"):
    p = tmp_path / name
    if isinstance(text, bytes):
        p.write_bytes(text)
    else:
        p.write_bytes(text.encode(encoding))
    return p


def _table(rows, delim=","):
    return "\n".join(delim.join(f"{v:g}" for v in r) for r in rows) + "\n"


# ---------------------------------------------------------------- headerless layouts by width

NINE = ["ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz"]


@pytest.mark.parametrize(
    "width, sensor, names",
    [
        (3, None, ["ax", "ay", "az"]),
        (3, "accel", ["ax", "ay", "az"]),
        (3, "mag", ["mx", "my", "mz"]),
        (3, "gyro", ["gx", "gy", "gz"]),
        (4, None, ["t", "ax", "ay", "az"]),
        (4, "mag", ["t", "mx", "my", "mz"]),
        (6, None, NINE[:6]),
        (6, "mag", ["ax", "ay", "az", "mx", "my", "mz"]),
        (7, None, ["t", *NINE[:6]]),
        (9, None, NINE),
        (9, "mag", NINE),
        (10, None, ["t", *NINE]),
    ],
)
def test_headerless_width_decides_and_the_note_names_the_guess(tmp_path, width, sensor, names):
    rows = ROWS[:, :width] if names[0] == "t" else ROWS[:, 1 : width + 1]
    p = _write(tmp_path, _table(rows, " "), "log.txt")
    log = load_log(p, sensor=sensor)
    assert list(log.columns) == names and list(log.columns.values()) == [
        str(i) for i in range(width)
    ]
    for key, arr in (("a", log.acc), ("g", log.gyro), ("m", log.mag)):
        cols = [names.index(key + a) for a in "xyz"] if key + "x" in names else None
        if cols is None:
            assert arr is None
        else:
            np.testing.assert_array_equal(arr, rows[:, cols])
    note = next(n for n in log.notes if n.startswith(f"headerless {width}-column file read as"))
    # the flag and its Python form: a report read in Python named only the flag (a trial)
    assert " ".join(names) in note and "--columns (columns= of load_log in Python)" in note


def test_columns_override_the_guess(tmp_path):
    p = _write(tmp_path, _table(ROWS[:, 1:10], ","))
    log = load_log(p, columns="mx,my,mz,_,_,_,ax,ay,az", sensor="gyro")
    np.testing.assert_array_equal(log.mag, ROWS[:, 1:4])
    np.testing.assert_array_equal(log.acc, ROWS[:, 7:10])
    assert log.gyro is None and not any("headerless" in n for n in log.notes)


@pytest.mark.parametrize("width", [5, 8, 11, 12])
def test_other_widths_say_the_width_and_give_a_columns_example(tmp_path, width):
    # no column only rises, so the example names no time column and asks for the rate
    p = _write(tmp_path, _table(np.ones((6, width)), "\t"))
    example = rf"no header and {width} columns.*--columns ax,ay,az,_.*else give --sample-rate"
    with pytest.raises(ValueError, match=example):
        load_log(p)


@pytest.mark.parametrize("width", [1, 2])
def test_too_few_columns_is_an_error(tmp_path, width):
    p = _write(tmp_path, _table(np.ones((6, width)), ","))
    with pytest.raises(ValueError, match="column"):
        load_log(p)


def test_bad_sensor_or_rate_argument(tmp_path):
    p = _write(tmp_path, _table(ROWS[:, 1:4]))
    with pytest.raises(ValueError, match="sensor="):
        load_log(p, sensor="magnetometer")
    with pytest.raises(ValueError, match="sample rate"):
        load_log(p, sample_rate=-5)


# ---------------------------------------------------------------- wrong answers that must stop


def test_header_kept_when_the_first_data_row_is_one_field_short(tmp_path):
    # the old loader took the first row whose width the next repeats as the data start, lost
    # the header, and read t,ay,ax,az as the headerless t ax ay az
    text = "t,ay,ax,az\n0.5,2,3\n" + _table(ROWS[:, :4])
    log = load_log(_write(tmp_path, text))
    np.testing.assert_array_equal(log.acc, ROWS[:, [2, 1, 3]])  # ax from the ax column
    assert log.columns == {"t": "t", "ay": "ay", "ax": "ax", "az": "az"}
    assert any("1 rows had the wrong number of fields" in n for n in log.notes)
    assert not any("headerless" in n for n in log.notes)


@pytest.mark.parametrize("bad", ["1,2", "1,2,3,4,5", "1,2,3,4,5,6,7"])
def test_ragged_rows_anywhere_are_skipped_and_counted_header_kept(tmp_path, bad):
    body = _table(ROWS[:, :4]).splitlines()
    lines = ["t,ay,ax,az", bad, *body[:3], bad, *body[3:], bad]
    log = load_log(_write(tmp_path, "\n".join(lines)))
    np.testing.assert_array_equal(log.acc, ROWS[:, [2, 1, 3]])
    assert np.array_equal(log.t, ROWS[:, 0])
    assert any(n.startswith("3 rows had the wrong number of fields") for n in log.notes)


def test_header_order_is_honoured(tmp_path):
    # t second in the header (its column holds 100 Hz times: whole-second steps would be read
    # as milliseconds, see test_time_in_ms_us_ns_is_converted_to_seconds)
    log = load_log(_write(tmp_path, "az;t;ax;ay\n" + _table(ROWS[:, [1, 0, 2, 3]], ";")))
    np.testing.assert_array_equal(log.acc, ROWS[:, [2, 3, 1]])
    np.testing.assert_array_equal(log.t, ROWS[:, 0])


def test_units_line_under_the_header(tmp_path):
    text = "Time,AccX,AccY,AccZ\ns,g,g,g\n" + _table(ROWS[:, :4])
    log = load_log(_write(tmp_path, text))
    np.testing.assert_array_equal(log.acc, ROWS[:, 1:4])
    said = "header line 1 read (Time,AccX,AccY,AccZ); line 2 skipped (s,g,g,g)"
    assert any(said in n for n in log.notes), log.notes


def test_header_with_another_width_is_not_guessed_past(tmp_path):
    # 3 names over 4 fields: which is which? An error, unless --columns says by position
    p = _write(tmp_path, "ax,ay,az\n" + _table(ROWS[:, :4]))
    with pytest.raises(ValueError, match="looks like a header with 3 names.*4 fields"):
        load_log(p)
    log = load_log(p, columns="t,ax,ay,az")
    np.testing.assert_array_equal(log.acc, ROWS[:, 1:4])
    assert any("ignored" in n for n in log.notes)


def test_preamble_title_and_comments(tmp_path):
    text = "# logger v2\nFs,50.00\nInitialization time,60\n\nmx,my,mz\n% comment\n" + _table(
        ROWS[:, 1:4]
    )
    log = load_log(_write(tmp_path, text))
    assert log.sample_rate == 50.0 and log.mag.shape == (8, 3)
    for title in ("Sensor log 2024", "Xsens raw log"):  # a title is not a header
        log = load_log(_write(tmp_path, title + "\n" + _table(ROWS[:, :4], " "), "t.txt"))
        assert any("before the data ignored" in n for n in log.notes)
        np.testing.assert_array_equal(log.acc, ROWS[:, 1:4])


def test_empatica_start_time_and_rate_rows_are_not_samples(tmp_path):
    # Empatica E4's ACC.csv (hpi-dhc/devicely, collab-uniba/BiometricsMSR2023): a row of the
    # start time (Unix s) and a row of the rate, each repeated in every column, then the counts.
    # They were read as two samples of 1.7e9 and 32 counts.
    head = "1680686620.000000, 1680686620.000000, 1680686620.000000\n" + "32.000000, " * 2
    head += "32.000000\n"
    log = load_log(_write(tmp_path, head + _table(ROWS[:, 1:4])))
    np.testing.assert_array_equal(log.acc, ROWS[:, 1:4])
    assert log.sample_rate == 32.0
    assert any("Empatica E4's start time (1680686620 s" in n for n in log.notes)
    assert not any("wrong number of fields" in n for n in log.notes)
    # a log whose first rows merely repeat one value (a sensor at rest) keeps them
    still = np.vstack([np.full((2, 3), 5.0), ROWS[:, 1:4]])
    np.testing.assert_array_equal(load_log(_write(tmp_path, _table(still))).acc, still)


def test_trailing_separator_and_quoted_cells(tmp_path):
    text = '"t","ax","ay","az",\n' + "".join(
        ",".join(f'"{v:g}"' for v in r) + ",\n" for r in ROWS[:, :4]
    )
    log = load_log(_write(tmp_path, text))
    np.testing.assert_array_equal(log.acc, ROWS[:, 1:4])


# ---------------------------------------------------------------- non-finite and absurd cells


def test_nonfinite_and_huge_cells_load_and_are_counted_per_column(tmp_path):
    lines = _table(ROWS[:, :4]).splitlines()
    lines[1] = "0.01,inf,21,1e308"
    lines[2] = "0.02,nan,abc,"
    lines[3] = "0.03,12,-inf,33"
    log = load_log(_write(tmp_path, "t,ax,ay,az\n" + "\n".join(lines)))
    assert log.acc.shape == (8, 3)  # nothing dropped: that is the caller's job
    # 1e308 is no reading: read as inf, so the calibration drops it with the other non-finite
    # cells (kept as 1e308 it overflowed calibrate_mag's sums into a LinAlgError)
    assert np.isposinf(log.acc[1, 2]) and np.isinf(log.acc[1, 0]) and np.isnan(log.acc[2, 1])
    bad = next(n for n in log.notes if n.startswith("cells that are not finite"))
    assert "ax 2" in bad and "ay 2" in bad and "az 1" in bad and " t " not in bad
    huge = next(n for n in log.notes if n.startswith("cells beyond"))
    assert "az 1" in huge and "ax" not in huge


def test_label_column_does_not_count_but_fast_and_slow_paths_agree(tmp_path):
    clean = _write(tmp_path, "t,ax,ay,az\n" + _table(ROWS[:, :4]), "a.csv")
    dirty = _write(
        tmp_path,
        "part,t,ax,ay,az\n" + "".join(f"x_a,{r}" for r in _table(ROWS[:, :4]).splitlines(True)),
        "b.csv",
    )
    a, b = load_log(clean), load_log(dirty)
    np.testing.assert_array_equal(a.acc, b.acc)
    assert b.notes == []  # the label column is not one the calibration uses


def test_clean_files_take_numpys_parser(tmp_path, monkeypatch):
    # the speed class: plain numeric text never goes through the line-by-line path
    def refuse(*a, **k):
        raise AssertionError("line-by-line path used for a clean file")

    monkeypatch.setattr(F, "_parse_rows", refuse)
    rng = np.random.default_rng(0)
    x = rng.normal(size=(5000, 7))
    x[:, 0] = np.arange(5000) / 100.0  # the time (a headerless file's first column must rise)
    for name, delim, head in [("a.csv", ",", "t,ax,ay,az,gx,gy,gz\n"), ("b.txt", " ", "")]:
        p = tmp_path / name
        np.savetxt(p, x, delimiter=delim, header=head.strip(), comments="")
        log = load_log(p)
        np.testing.assert_allclose(log.gyro, x[:, 4:7], rtol=1e-15)


@pytest.mark.parametrize(
    "case",
    [
        "clean",
        "utf16",
        "latin1_late",
        "ragged_late",
        "long_preamble",
        "comment_tail",
        "labels",
        "empty_tail",
    ],
)
def test_big_files_read_from_their_ends_agree_with_the_whole(tmp_path, case):
    # files over 64 kB are sniffed from their first and last bytes and parsed by numpy from
    # disk; whatever that path cannot take must fall back to the whole text and agree
    n = 6000
    x = np.column_stack([np.arange(n) / 100, np.arange(n) % 97, np.arange(n) % 89, -np.ones(n)])
    lines = [",".join(f"{v:g}" for v in r) for r in x]
    head = ["t,ax,ay,az"]
    enc = "utf-8"
    if case == "utf16":
        enc = "utf-16"
    elif case == "latin1_late":
        lines[5000] = lines[5000] + ",\xb5"  # a 5th field with a non-UTF-8 byte, far down
        enc = "latin-1"
    elif case == "ragged_late":
        lines[5000] = "1,2"
    elif case == "long_preamble":
        head = [f"# note {i} " + "x" * 60 for i in range(1200)] + ["Fs,100"] + head
    if case == "labels":  # a label column (imucal's 'part'), and one text cell in a sensor
        lines = [f"pose_{i // 500}," + ln for i, ln in enumerate(lines)]
        head = ["part,t,ax,ay,az"]
        lines[3000] = lines[3000].replace(",-1", ",oops")
    if case == "empty_tail":  # a column that ends empty is still parsed where it has numbers
        lines = [ln + ("," if i > n - 300 else ",7") for i, ln in enumerate(lines)]
        head = ["t,ax,ay,az,temp"]
    if case == "comment_tail":
        lines += ["# end of log " + "-" * 40] * 1500
    p = _write(tmp_path, "\n".join(head + lines) + "\n", encoding=enc)
    assert p.stat().st_size > 70_000
    log = load_log(p)
    keep = np.ones(n, bool)
    if case in ("latin1_late", "ragged_late"):
        keep[5000] = False
        assert any(s_.startswith("1 rows had the wrong number") for s_ in log.notes)
    if case == "labels":
        assert np.isnan(log.acc[3000, 2]) and "az 1" in log.notes[-1]
        log.acc[3000, 2] = -1
    if case == "empty_tail":
        assert np.all(log.temp[: n - 300] == 7) and np.isnan(log.temp[-1])
    np.testing.assert_array_equal(log.acc, x[keep, 1:4])
    np.testing.assert_array_equal(log.t, x[keep, 0])
    if case == "latin1_late":
        assert any("Latin-1" in s_ for s_ in log.notes)
    if case == "long_preamble":
        assert log.sample_rate == 100


# ---------------------------------------------------------------- clear errors


def test_directory_or_pipe(tmp_path):
    with pytest.raises(ValueError, match="is a directory"):
        load_log(tmp_path)
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    with pytest.raises(ValueError, match="not a regular file"):
        load_log(fifo)


def test_missing_file(tmp_path):
    with pytest.raises(ValueError, match="does not exist"):
        load_log(tmp_path / "nope.csv")


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads files whatever their mode")
def test_unreadable_file_by_mode(tmp_path):
    p = _write(tmp_path, "ax,ay,az\n1,2,3\n")
    p.chmod(0)
    try:
        with pytest.raises(ValueError, match="permission denied"):
            load_log(p)
    finally:
        p.chmod(0o644)


def test_unreadable_file(tmp_path, monkeypatch):
    # the same class where the suite runs as root: the OS refusing the read
    p = _write(tmp_path, "ax,ay,az\n1,2,3\n")

    def deny(name, *a, **k):
        raise PermissionError(13, "Permission denied", str(name))

    monkeypatch.setattr(type(p), "read_bytes", deny)
    monkeypatch.setattr(F, "open", deny, raising=False)  # the loader's own open()
    with pytest.raises(ValueError, match="permission denied.*chmod"):
        load_log(p)


@pytest.mark.parametrize(
    "content, match",
    [
        (b"", "empty"),
        (b"\n\n   \n", "empty"),
        (b"# only\n# comments\n", "no data rows"),
        (b"t,ax,ay,az\n", "no rows of numbers"),
        (b"hello world\nthis is prose\n", "no rows of numbers"),
    ],
)
def test_empty_and_dataless_files(tmp_path, content, match):
    with pytest.raises(ValueError, match=match):
        load_log(_write(tmp_path, content))


@pytest.mark.parametrize(
    "content, match",
    [
        (bytes(range(256)) * 20, "not a text log"),
        (np.random.default_rng(1).bytes(5000), "not a text log"),
        (b"\x89HDF\r\n\x1a\n" + bytes(500), "HDF5"),
        (b"PK\x03\x04" + bytes(500), "zip"),
    ],
)
def test_binary_files(tmp_path, content, match):
    with pytest.raises(ValueError, match=match):
        load_log(_write(tmp_path, content, "log.dat"))


def test_hdf5_in_broads_layout_loads_and_any_other_is_named(tmp_path):
    # BROAD's trials (imu_acc, imu_gyr, imu_mag, the rate as an attribute) load like any log;
    # another HDF5 layout says which (N, 3) datasets it holds and what to do
    h5py = pytest.importorskip("h5py")
    x = ROWS[:, 1:4]
    with h5py.File(tmp_path / "trial.hdf5", "w") as f:
        f["imu_acc"], f["imu_gyr"], f["imu_mag"] = x, 0.1 * x, 40 * x
        f["opt_quat"] = np.tile([1.0, 0, 0, 0], (len(x), 1))
        f.attrs["sampling_rate"] = 285.714
    log = load_log(tmp_path / "trial.hdf5")
    np.testing.assert_array_equal(log.acc, x)
    np.testing.assert_array_equal(log.gyro, 0.1 * x)
    np.testing.assert_array_equal(log.mag, 40 * x)
    assert log.sample_rate == pytest.approx(285.714) and "BROAD" in log.notes[0]
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["accel"], f["temperature"] = x, x[:, 0]
    with pytest.raises(ValueError, match=r"without BROAD's datasets.*accel \(\d+, 3\)"):
        load_log(tmp_path / "other.h5")


def _mat73(path, **variables):
    """A MATLAB v7.3 file as MATLAB writes one: HDF5 behind a 512-byte MAT header, each
    matrix stored transposed with its MATLAB_class (sunsided/sensor-fusion's logs)."""
    h5py = pytest.importorskip("h5py")
    with h5py.File(path, "w", userblock_size=512) as f:
        for name, value in variables.items():
            f[name] = np.asarray(value, float).T
            f[name].attrs["MATLAB_class"] = np.bytes_(b"double")
        f.create_group("#refs#")
    text = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: test HDF5 schema 1.00 ."
    header = text.ljust(116, b" ") + bytes(8) + b"\x00\x02IM"
    with open(path, "r+b") as fh:
        fh.write(header.ljust(512, b"\x00"))


def test_mat_v73_reads_through_h5py(tmp_path):
    """v7.3 files were refused ('scipy cannot read'); with h5py they read like v7 ones."""
    _mat73(tmp_path / "v73.mat", accelBuffer=ROWS[:, :4])
    scipy.io.savemat(tmp_path / "v7.mat", {"accelBuffer": ROWS[:, :4]})
    new, old = load_log(tmp_path / "v73.mat"), load_log(tmp_path / "v7.mat")
    np.testing.assert_array_equal(new.acc, old.acc)
    np.testing.assert_array_equal(new.t, old.t)
    assert "MATLAB v7.3 file, read with h5py" in new.notes


def test_uneven_timestamps_give_the_mean_rate_with_a_note(tmp_path):
    """A logger writing in bursts: three samples 2 ms apart then a 26 ms wait (mean 10 ms,
    100 Hz). The median step said 500 Hz, and every window of the detector was five times
    too long in samples (sunsided's MPU6050 log: median step 2.1 ms, mean 9.5 ms)."""
    n = 600
    steps = np.tile([0.002, 0.002, 0.026], n // 3)[: n - 1]
    t = np.r_[0.0, np.cumsum(steps)]
    log = load_log(_write(tmp_path, _table(np.column_stack([t, np.ones((n, 3))])), "bursts.csv"))
    assert log.sample_rate == pytest.approx(100.0, rel=0.02)
    assert any("timestamps uneven" in note for note in log.notes)
    steady = np.r_[0.0, np.cumsum(np.full(n - 1, 0.01))]
    plain = load_log(_write(tmp_path, _table(np.column_stack([steady, np.ones((n, 3))])), "e.csv"))
    assert plain.sample_rate == pytest.approx(100.0) and not any("uneven" in m for m in plain.notes)


def test_a_rate_among_settings_in_a_comment_line(tmp_path):
    """PicoQuake's export (plab-io/picoquake, GPL-3) states its rate among other settings:
    '# Config: data_rate = 2000.0 Hz, filter = 488 Hz, ...'. It was not read: the gyro asked
    for --sample-rate and the accelerometer's detector ran without a rate. Other numbers in Hz
    on such a line (the filter) are not the rate."""
    head = "# PLab PicoQuake Data\n# Config: data_rate = 2000.0 Hz, filter = 488 Hz, "
    head += "acc_range = 4 g\ncount,a_x,a_y,a_z\n"
    log = load_log(_write(tmp_path, head + _table(ROWS[:, :4])))
    assert log.sample_rate == 2000.0
    other = "# filter = 488 Hz\nt_s,ax,ay,az\n" + _table(ROWS[:, :4])
    assert load_log(_write(tmp_path, other, "b.csv")).sample_rate == pytest.approx(100.0)


def test_xsens_rates_and_fusion_outputs(tmp_path):
    """Two Xsens layouts a new user's run met (Allwillcome/XsensDot2Mtw4OpenSense, MIT). An
    MT Manager export states '// Update Rate: 100.0Hz', and an Xsens DOT export a 'sep=,'
    preamble with 'OutputRate:,60Hz': neither rate was read, so the detector ran in samples.
    The DOT file holds only Quat_* and FreeAcc_* (gravity removed): it was refused with a
    --columns example that mapped Quat_W, Quat_X, Quat_Y onto the accelerometer; it now says
    that such columns are a fusion output, with nothing to calibrate."""
    rows = [[472 + i, 9.3, 0.8, -3.1] for i in range(40)]
    mtw = ["// Start Time: Unknown", "// Update Rate: 100.0Hz", "// Filter Profile: human"]
    mtw += ["PacketCounter\tAcc_X\tAcc_Y\tAcc_Z"] + ["\t".join(map(str, r)) for r in rows]
    assert load_log(_write(tmp_path, "\n".join(mtw) + "\n", "mtw.txt")).sample_rate == 100.0
    dot = ["sep=,", "DeviceTag:,Yao", "OutputRate:,60Hz", "StartTime: ,2021-08-20_20:21:13"]
    dot += ["", "PacketCounter,SampleTimeFine,Quat_W,Quat_X,Quat_Y,Quat_Z,FreeAcc_X,FreeAcc_Y,"]
    dot[-1] += "FreeAcc_Z,Status"
    dot += [f"{i},{16667 * i},1,0,0,0,0.01,0.02,-0.03,0" for i in range(40)]
    path = _write(tmp_path, "\n".join(dot) + "\n", "dot.csv")
    with pytest.raises(ValueError, match="sensor-fusion output .*nothing here to calibrate"):
        load_log(path)
    head = "\n".join(dot[:5] + ["PacketCounter,SampleTimeFine,Acc_X,Acc_Y,Acc_Z"]) + "\n"
    raw = _write(tmp_path, head + "".join(f"{i},{i},9.8,0.1,0.2\n" for i in range(40)), "r.csv")
    assert load_log(raw).sample_rate == 60.0


def test_actilife_raw_export_states_its_rate_in_the_banner(tmp_path):
    """ActiLife's raw export (paulhibbing/AGread's exampleRAW.csv, MIT: a new-user trial)
    states its rate only in the banner above the data, '... date format M/d/yyyy at 90 Hz
    Filter Normal ---': it was fitted in samples, and refused with 'all poses lie near one
    plane' for three perpendicular faces. The rate is read; 'Filter ... 488 Hz' in a settings
    line does not count, nor a word ending in 'at'."""
    banner = (
        "------------ Data File Created By ActiGraph GT3X+ ActiLife v6.13.3 Firmware v1.7.2 "
        "date format M/d/yyyy at 90 Hz  Filter Normal -----------,,"
    )
    head = [banner, "Serial Number: TAS1E31150129,,", "Start Time 08:58:00,,",
            "Epoch Period (hh:mm:ss) 00:00:00,,", "-" * 50 + ",,",
            "Accelerometer X,Accelerometer Y,Accelerometer Z"]  # fmt: skip
    rows = "".join(f"{0.01 * (i % 3)},-0.008,0.961\n" for i in range(40))
    log = load_log(_write(tmp_path, "\n".join(head) + "\n" + rows, "exampleRAW.csv"))
    assert log.sample_rate == 90.0 and log.t is None
    other = [f"Device format {x} Hz,," for x in ("flat 488", "at488")] + head[1:]
    log = load_log(_write(tmp_path, "\n".join(other) + "\n" + rows, "b.csv"))
    assert log.sample_rate is None


def test_a_table_saved_one_row_per_axis_is_named_transposed(tmp_path):
    """A Python user's trial saved np.savetxt(G.T): 3 rows of 16,000 numbers was 'no data
    rows' (each line longer than the head the loader reads), and 3 rows of 200 'no header and
    200 columns' with a 200-name --columns example. Both now say transposed, and how to fix."""
    x = np.random.default_rng(0).normal(size=(16000, 3))
    for n, name in ((200, "short.csv"), (16000, "long.csv")):
        path = tmp_path / name
        np.savetxt(path, x[:n].T, delimiter=",")
        with pytest.raises(ValueError, match=rf"holds 3 row\(s\) of {n} numbers: one row per axis"):
            load_log(path)
    np.savetxt(tmp_path / "ok.csv", x[:200], delimiter=",")  # the same numbers the right way
    assert load_log(tmp_path / "ok.csv").acc.shape == (200, 3)


def test_units_and_rate_stated_in_comment_lines_above_headerless_data(tmp_path):
    """sensbiotk's FOX logs (GPL-3, not shipped) open with comment lines only: the column
    names, then '# Units:' and one line per sensor ('#\tMagneto: gauss'). The names were read
    but the units not (calib-jax mag said 'raw units' for a log in gauss), and a rate in a
    comment line above data with no header row was never read: only lines above a header
    were searched, and such a file has none."""
    head = "# FOX Logger (IMU file)\n# id\tt\tax\tay\taz\tmx\tmy\tmz\tgx\tgy\tgz\n#\n"
    head += "# Units:\n#\tTime: s\n#\tAcceleration: m.s^-2\n#\tMagneto: gauss\n"
    head += "#\tGyrometer: rad/s\n#\n"
    rows = "".join(
        f"{i}\t{0.005 * i:.3f}\t0.1\t0.2\t-10.4\t-0.7\t0.2\t-0.8\t0.01\t0.02\t0.03\n"
        for i in range(40)
    )
    log = load_log(_write(tmp_path, head + rows, "fox.csv"))
    assert log.units == {"accel": "m/s^2", "gyro": "rad/s", "mag": "gauss"}
    assert log.sample_rate == pytest.approx(200.0)
    rate = "# Sample rate: 50 Hz\n" + "".join(f"{i},9.8,0.1,0.2\n" for i in range(40))
    assert load_log(_write(tmp_path, rate, "r.csv")).sample_rate == 50.0


def test_an_empty_last_column_is_a_column_not_a_trailing_separator(tmp_path):
    """JustinPringle/TWLogger's logs (MIT): 21 names, and rows whose GPS fields are empty
    unless the tag has a fix, so every row but a fix's ends in a comma. The comma was taken
    for a trailing separator: 20 fields against 21 names, every command refused the file, the
    fix's row was the one dropped, and the --columns example it offered read the date as t.
    Also its first clock is text ('Time(hh:mm:ss)', NaN as numbers): the numeric one after it
    ('Timestamp(Ms)') is now the time."""
    head = "Date(MM/DD/YYYY),Time(hh:mm:ss),Timestamp(Ms),Temp(Raw),ACCELX,ACCELY,ACCELZ,"
    head += "MAGX,MAGY,MAGZ,Sats,HDOP,Latitude,Longitude,FixAge,DateUTC,TimeUTC,DateAge,"
    head += "Altitude,Course,Speed\n"
    row = "07/11/2018,05:34:44,{t},0,1488.00,976.00,-4832.00,89.00,-10.00,-327.00"
    rows = [row.format(t=15225 + 16 * i) + ",,,,,,,,,,," for i in range(40)]
    rows[20] = row.format(t=15225 + 16 * 20) + ",7,1.2,-27.1,153.0,120,11072018,53444,5,12,0,0"
    log = load_log(_write(tmp_path, head + "\n".join(rows) + "\n", "T1D0711-00.CSV"))
    assert len(log.acc) == 40 and log.columns["ax"] == "ACCELX" and log.columns["mz"] == "MAGZ"
    np.testing.assert_array_equal(log.mag[20], [89.0, -10.0, -327.0])
    assert log.columns["t"] == "Timestamp(Ms)" and log.sample_rate == pytest.approx(62.5)


def test_the_columns_example_skips_constant_columns_and_prefers_sensor_names(tmp_path):
    """PX4's vehicle_imu export (roboto-ai/robologs-px4-actions, MPL-2.0): no column is a raw
    sensor axis, and the refusal's example mapped accel_device_id and gyro_device_id (constant
    ids) onto the accelerometer. Constant columns are left out and names that hint at the
    sensor come first."""
    head = "timestamp,timestamp_sample,accel_device_id,gyro_device_id,delta_angle[0],"
    head += "delta_angle[1],delta_angle[2],delta_velocity[0],delta_velocity[1],delta_velocity[2]\n"
    rng = np.random.default_rng(0)
    rows = "".join(
        f"{1715966 + 4000 * i},{1715243 + 4000 * i},2490386,2490386,"
        + ",".join(f"{v:.6g}" for v in rng.normal(size=6))
        + "\n"
        for i in range(40)
    )
    path = _write(tmp_path, head + rows, "vehicle_imu_0.csv")
    with pytest.raises(ValueError, match="no sensor columns recognised") as err:
        load_log(path)
    example = str(err.value).split("e.g. --columns ")[1]
    assert "device_id" not in example and "ax=delta_velocity[0]" in example, example


def test_a_joined_file_keeps_how_it_was_read_and_its_unit(tmp_path):
    """FreeIMU's capture (MapleHan/freeimu_gui, GPL-3) writes acc.txt and magn.txt, headerless:
    `calib-jax marg acc.txt magn.txt` said how acc.txt was read and nothing of magn.txt, and a
    unit the second file states was dropped."""
    d = np.random.default_rng(0).normal(size=(50, 3))
    np.savetxt(tmp_path / "acc.txt", d)
    np.savetxt(tmp_path / "magn.txt", d, header="\tMagneto: gauss")
    acc, mag = load_log(tmp_path / "acc.txt"), load_log(tmp_path / "magn.txt")
    joined = F.join_logs(acc, mag, "mag")
    assert any(
        n.startswith("magn.txt: headerless 3-column file read as mx my mz") for n in joined.notes
    )
    assert joined.units.get("mag") == "gauss" and joined.mag is not None


def test_vendor_exports_read_without_flags(tmp_path):
    """Three real layouts a new user's run met (scikit-kinematics' test data, BSD-3): an Xsens
    MT Manager export ('//' comment lines, one stating the rate, a tab-separated header, and
    every row ending in a tab: it was refused as '14 names but 15 fields'); a YEI 3-Space log
    whose names sit in a '# Data format:' comment (it was read as 't, accel, gyro, mag' by
    width: the gyro fitted as the accelerometer); an 11-column headerless Pololu log, refused
    with the columns described and an example that puts t where a column only rises."""
    rows = [[0.5 * i, 9.8, 0.1, 0.2, 0.01, 0.02, 0.03, 0.4, 0.5, 0.6] for i in range(40)]
    xsens = ["// Start Time: 0", "// Sample rate: 50.0Hz", "// Scenario: 4.9"]
    xsens += ["Counter\tAcc_X\tAcc_Y\tAcc_Z\tGyr_X\tGyr_Y\tGyr_Z\tMag_X\tMag_Y\tMag_Z"]
    xsens += [" " + "\t".join(f"{v:g}" for v in r) + "\t" for r in rows]
    log = load_log(_write(tmp_path, "\n".join(xsens) + "\n", "xsens.txt"))
    np.testing.assert_array_equal(log.acc[0], [9.8, 0.1, 0.2])
    np.testing.assert_array_equal(log.mag[0], [0.4, 0.5, 0.6])
    assert log.sample_rate == 50.0
    yei = '# Data format: "%int(ChipTimeUS),%float(RawGyroX),%float(RawGyroY),%float(RawGyroZ),'
    yei += "%float(RawCompassX),%float(RawCompassY),%float(RawCompassZ),%float(RawAccelX),"
    yei += '%float(RawAccelY),%float(RawAccelZ)"\n'
    yei += "".join(f"{9000 * i},0.01,0.02,0.03,0.4,0.5,0.6,0.0,0.1,0.99\n" for i in range(40))
    log = load_log(_write(tmp_path, yei, "yei.txt"))
    np.testing.assert_array_equal(log.acc[0], [0.0, 0.1, 0.99])
    np.testing.assert_array_equal(log.gyro[0], [0.01, 0.02, 0.03])
    np.testing.assert_array_equal(log.mag[0], [0.4, 0.5, 0.6])
    assert log.sample_rate == pytest.approx(1e6 / 9000)
    assert any("column names read from the comment line" in n for n in log.notes)
    pololu = "".join(
        f"{(-1) ** i * 100} {50 - i} {1000 - i % 3} 1 2 3 4 5 6 {7 * i + 2} {7 * i + 3}\n"
        for i in range(40)
    )
    log = load_log(_write(tmp_path, pololu, "pololu.txt"))  # 9 sensor columns, then 2 clocks
    np.testing.assert_array_equal(log.acc[0], [100, 50, 1000])
    np.testing.assert_array_equal(log.mag[1], [4, 5, 6])
    np.testing.assert_allclose(log.t[:2], [0.002, 0.009])  # the first clock, ms -> s


SKINEMATICS = Path(__file__).parent / "data" / "skinematics"


def test_scikit_kinematics_vendor_logs(capsys):
    """The three real files behind test_vendor_exports_read_without_flags (NOTES.md beside
    them): each layout read without flags, checked against its vendor's documented columns and
    units (scikit-kinematics' own readers), and the Pololu refusal through the CLI (two
    poses: too few)."""
    from calib_jax.cli import main

    xsens = load_log(SKINEMATICS / "data_xsens.txt")
    assert xsens.sample_rate == 50.0 and xsens.acc.shape == (953, 3)
    assert 5 < np.median(np.linalg.norm(xsens.acc, axis=1)) < 15  # m/s^2, hand-held
    yei = load_log(SKINEMATICS / "data_yei.txt")
    assert yei.sample_rate == pytest.approx(109.9, abs=0.1)  # us time column
    assert np.median(np.linalg.norm(yei.acc, axis=1)) == pytest.approx(1.0, abs=0.02)  # g
    assert np.median(np.linalg.norm(yei.mag, axis=1)) == pytest.approx(0.53, abs=0.05)  # gauss
    assert np.median(np.linalg.norm(yei.gyro, axis=1)) < 0.1  # rad/s, mostly still
    # Pololu MinIMU-9: 9 sensor columns in the usual order, then two clocks in ms (acc/gyro,
    # mag). It was refused for 11 columns, with a --columns example for mag naming the
    # accelerometer's columns; now read by its data (columns checked against numpy.loadtxt)
    raw = np.loadtxt(SKINEMATICS / "data_polulu.txt")
    polulu = load_log(SKINEMATICS / "data_polulu.txt")
    np.testing.assert_array_equal(polulu.acc, raw[:, :3])
    np.testing.assert_array_equal(polulu.gyro, raw[:, 3:6])
    np.testing.assert_array_equal(polulu.mag, raw[:, 6:9])
    np.testing.assert_allclose(polulu.t, raw[:, 9] / 1e3)  # ms -> s, the first clock
    assert polulu.sample_rate == pytest.approx(142.9, abs=0.1)
    assert "columns 10, 11 only rise: the first read as time" in polulu.notes[0]
    # two opposite poses: refused, and counted as two (the sphere 'fitted' through two points
    # had made them one)
    assert main(["accel", str(SKINEMATICS / "data_polulu.txt")]) == 2
    err = capsys.readouterr().err
    assert "only 2 distinct poses" in err and "no header" not in err


def test_truncated_or_corrupt_mat(tmp_path):
    good = tmp_path / "good.mat"
    scipy.io.savemat(good, {"data": ROWS[:, :4]})
    raw = good.read_bytes()
    for name, content in [
        ("trunc.mat", raw[: len(raw) // 2]),
        ("zeros.mat", raw[:128] + bytes(len(raw) - 128)),
        ("header.mat", b"MATLAB 5.0 MAT-file" + bytes(200)),
    ]:
        with pytest.raises(ValueError, match="MATLAB"):
            load_log(_write(tmp_path, content, name))


def test_columns_beyond_the_file_or_not_in_the_header(tmp_path):
    p = _write(tmp_path, _table(ROWS[:, 1:4], " "), "three.txt")
    with pytest.raises(ValueError, match="column 4, but .* has only 3 columns"):
        load_log(p, columns="t,ax,ay,az")
    h = _write(tmp_path, "A,B,C\n" + _table(ROWS[:, 1:4]))
    with pytest.raises(ValueError, match="'Q'.*not in the header"):
        load_log(h, columns="ax=A,ay=B,az=Q")
    with pytest.raises(ValueError, match="by position"):
        load_log(p, columns="ax=A,ay=B,az=C")
    with pytest.raises(ValueError, match="twice"):
        parse_columns("ax,ax,az")
    with pytest.raises(ValueError, match="unknown column"):
        parse_columns("t,ax,ay,bz")
    log = load_log(h, columns="ax=a,ay=b,az=c")  # header names match case-insensitively
    np.testing.assert_array_equal(log.acc, ROWS[:, 1:4])


def test_header_without_sensor_names_suggests_a_mapping(tmp_path):
    p = _write(tmp_path, "foo,bar,baz\n" + _table(ROWS[:, 1:4]))
    with pytest.raises(ValueError, match="--columns ax=foo,ay=bar,az=baz"):
        load_log(p)


# ---------------------------------------------------------------- encodings and compression

TEXT = "Time (s),Acc X (g),Acc Y (g),Acc Z (g)\n" + _table(ROWS[:, :4])


@pytest.mark.parametrize(
    "encoding, note",
    [
        ("utf-8", None),
        ("utf-8-sig", "byte-order mark"),
        ("utf-16", "UTF-16"),
        ("utf-16-le", "UTF-16 without a byte-order mark"),
        ("utf-32", "UTF-32"),
    ],
)
def test_encodings(tmp_path, encoding, note):
    log = load_log(_write(tmp_path, TEXT, encoding=encoding))
    np.testing.assert_array_equal(log.acc, ROWS[:, 1:4])
    assert log.columns["ax"] == "Acc X (g)"  # no BOM glued to the first name
    assert (note is None and log.notes == []) or any(note in n for n in log.notes)


def test_latin1_header(tmp_path):
    text = "t,ax,ay,az,Temp (\xb0C)\n" + _table(ROWS[:, :5])
    log = load_log(_write(tmp_path, text, encoding="latin-1"))
    assert log.columns["temp"] == "Temp (\xb0C)" and any("Latin-1" in n for n in log.notes)
    np.testing.assert_array_equal(log.temp, ROWS[:, 4])


@pytest.mark.parametrize("name", ["log.csv.gz", "log.csv", "log.gz"])
def test_gzip_found_by_its_bytes(tmp_path, name):
    log = load_log(_write(tmp_path, gzip.compress(TEXT.encode()), name))
    np.testing.assert_array_equal(log.acc, ROWS[:, 1:4])
    assert any("gzip" in n for n in log.notes)
    log = load_log(_write(tmp_path, bz2.compress(TEXT.encode()), "b.bz2"))
    np.testing.assert_array_equal(log.acc, ROWS[:, 1:4])


def test_truncated_gzip(tmp_path):
    raw = gzip.compress((TEXT * 50).encode())
    with pytest.raises(ValueError, match="gzip-compressed but does not decompress"):
        load_log(_write(tmp_path, raw[: len(raw) // 2], "log.csv.gz"))


def test_plain_text_named_gz_is_text(tmp_path):
    log = load_log(_write(tmp_path, TEXT, "log.csv.gz"))
    np.testing.assert_array_equal(log.acc, ROWS[:, 1:4])


@pytest.mark.parametrize("delim", [";", "\t", " "])
def test_decimal_commas(tmp_path, delim):
    body = _table(ROWS[:, :4] + 0.25, delim).replace(".", ",")
    log = load_log(_write(tmp_path, delim.join(["t", "ax", "ay", "az"]) + "\n" + body))
    np.testing.assert_array_equal(log.acc, ROWS[:, 1:4] + 0.25)
    np.testing.assert_array_equal(log.t, ROWS[:, 0] + 0.25)
    assert any("decimal commas" in n for n in log.notes)


def test_comma_separated_with_spaces_is_not_decimal_commas(tmp_path):
    log = load_log(_write(tmp_path, _table(ROWS[:, 1:4] + 0.5, ", ")))
    np.testing.assert_array_equal(log.acc, ROWS[:, 1:4] + 0.5)
    assert not any("decimal" in n for n in log.notes)


# ---------------------------------------------------------------- MATLAB files


def test_mat_variables_of_other_lengths_are_left_out_and_named(tmp_path):
    p = tmp_path / "v.mat"
    n = 8
    scipy.io.savemat(
        p,
        {
            "t": ROWS[:, 0],
            "temp": np.arange(3.0),  # a different length: must not shift the others
            "ax": ROWS[:, 1],
            "ay": ROWS[:, 2],
            "az": ROWS[:, 3],
        },
    )
    log = load_log(p)
    np.testing.assert_array_equal(log.acc, ROWS[:, 1:4])
    np.testing.assert_array_equal(log.t, ROWS[:n, 0])
    assert log.temp is None
    assert any("left out" in n and "temp (3)" in n for n in log.notes)


def test_mat_sensor_matrices_and_single_matrix(tmp_path):
    p = tmp_path / "m.mat"
    scipy.io.savemat(p, {"acc": ROWS[:, 1:4], "gyro": ROWS[:, 4:7].T, "time": ROWS[:, 0]})
    log = load_log(p)
    np.testing.assert_array_equal(log.acc, ROWS[:, 1:4])
    np.testing.assert_array_equal(log.gyro, ROWS[:, 4:7])
    np.testing.assert_array_equal(log.t, ROWS[:, 0])
    q = tmp_path / "one.mat"
    scipy.io.savemat(q, {"data": ROWS[:, 1:4]})
    log = load_log(q, sensor="mag")
    np.testing.assert_array_equal(log.mag, ROWS[:, 1:4])
    r = tmp_path / "two.mat"
    scipy.io.savemat(r, {"a1": ROWS[:, 1:4], "b2": ROWS[:, 4:8]})
    with pytest.raises(ValueError, match="cannot tell which MATLAB variable"):
        load_log(r)


# ---------------------------------------------------------------- anything at all


JUNK = ["", "abc", "nan", "inf", "-inf", "1e308", "1,5", '"3"', "NaN", "--", "1.2.3", "\u00b5"]
DELIMS = [",", ";", "\t", " ", "|", ", "]


@st.composite
def log_files(draw):
    width = draw(st.integers(1, 12))
    delim = draw(st.sampled_from(DELIMS))
    n = draw(st.integers(0, 20))
    number = st.one_of(
        st.integers(-40000, 40000).map(str),
        st.floats(allow_nan=True, allow_infinity=True).map(repr),
        st.floats(-10, 10, allow_nan=False).map(lambda v: f"{v:.6g}"),
    )
    cell = st.one_of(number, number, number, number, st.sampled_from(JUNK))
    header_kind = draw(st.sampled_from(["none", "canon", "alias", "junk", "short", "long"]))
    canon = list(F._CANON)
    names: list[str] | None = None
    if header_kind in ("canon", "alias", "short", "long"):
        pool = canon + ["part", "acc_x", "Gyroscope X (deg/s)", "Mag Z", "n_samples"]
        k = {"short": max(1, width - 1), "long": width + 1}.get(header_kind, width)
        names = draw(st.lists(st.sampled_from(pool), min_size=k, max_size=k))
    elif header_kind == "junk":
        names = draw(
            st.lists(
                st.text(string.ascii_letters + " _()", min_size=1, max_size=6),
                min_size=width,
                max_size=width,
            )
        )
    lines = []
    if draw(st.booleans()):
        lines += draw(
            st.lists(
                st.sampled_from(["Fs,50.00", "# comment", "", "title line", "rate,0"]), max_size=3
            )
        )
    if names is not None:
        lines.append(delim.join(names))
    for _ in range(n):
        w = width + draw(st.sampled_from([0, 0, 0, 0, 0, -1, 1]))
        lines.append(delim.join(draw(st.lists(cell, min_size=max(w, 0), max_size=max(w, 0)))))
    text = "\n".join(lines) + draw(st.sampled_from(["", "\n", "\r\n"]))
    if delim in (";", "\t") and draw(st.booleans()):
        text = text.replace(".", ",")
    raw = text.encode(
        draw(st.sampled_from(["utf-8", "utf-8-sig", "utf-16", "latin-1"])), errors="replace"
    )
    if draw(st.integers(0, 9)) == 0:
        raw = gzip.compress(raw)
    spec = draw(
        st.one_of(
            st.none(),
            st.lists(st.sampled_from(canon + ["_"]), min_size=1, max_size=12).map(",".join),
            st.lists(
                st.tuples(st.sampled_from(canon), st.sampled_from((names or []) + ["x", "0", "3"])),
                min_size=1,
                max_size=4,
            ).map(lambda kv: ",".join(f"{k}={v}" for k, v in kv)),
            st.text(max_size=12),
        )
    )
    sensor = draw(st.sampled_from([None, "accel", "mag", "gyro"]))
    return raw, spec, sensor, len(lines)  # no more samples than lines


@settings(
    max_examples=120,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(case=log_files())
def test_any_file_loads_consistently_or_raises_valueerror(tmp_path, case):
    raw, spec, sensor, n_lines = case
    p = tmp_path / "fuzz.csv"
    p.write_bytes(raw)
    try:
        log = load_log(p, columns=spec, sensor=sensor)
    except ValueError:
        return
    arrays = [a for a in (log.acc, log.gyro, log.mag) if a is not None]
    assert arrays, "a log without any sensor must be a ValueError"
    n = len(arrays[0])
    assert 0 < n <= n_lines and len(log) == n
    for a in arrays:
        assert a.shape == (n, 3) and a.dtype == np.float64
    for a in (log.t, log.temp):
        assert a is None or a.shape == (n,)
    assert all(isinstance(s, str) for s in log.notes)
    assert set(log.columns) <= set(F._CANON)
    assert log.sample_rate is None or (np.isfinite(log.sample_rate) and log.sample_rate > 0)
    used = np.column_stack(arrays)
    if not np.isfinite(used).all():  # every cell not read as a finite number is named
        said = ("cells that are not finite", "cells beyond")
        assert any(s.startswith(said) for s in log.notes), log.notes


@settings(max_examples=60, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(raw=st.binary(max_size=400), suffix=st.sampled_from([".csv", ".mat", ".gz", ".txt"]))
def test_any_bytes_load_or_raise_valueerror(tmp_path, raw, suffix):
    p = tmp_path / f"b{suffix}"
    p.write_bytes(raw)
    try:
        log = load_log(p)
    except ValueError:
        return
    assert len(log) > 0


@pytest.mark.parametrize(("scale", "unit"), [(1.0, None), (1e3, "ms"), (1e6, "us"), (1e9, "ns")])
@pytest.mark.parametrize("rate", [20.0, 100.0, 1000.0])
def test_time_in_ms_us_ns_is_converted_to_seconds(tmp_path, scale, unit, rate):
    """Loggers write millis(), micros() or nanoseconds since the epoch; read as seconds a 1 kHz
    log in ns had a rate of 1e-6 Hz (the AirBrakes MicroStrain logs). The rate must come out
    as recorded and t in seconds, with a note naming the unit."""
    n = 50
    t0 = 1.7e9 if unit == "ns" else 0.0  # epoch seconds: 1.7e18 ns still resolves 1 ms steps
    t = (t0 + np.arange(n) / rate) * scale
    path = tmp_path / "log.csv"
    fmt = ".6f" if unit is None else ".0f"  # integer ticks, as loggers write them
    path.write_text("t,ax,ay,az\n" + "".join(f"{v:{fmt}},0,0,1\n" for v in t))
    log = load_log(path)
    assert log.sample_rate == pytest.approx(rate, rel=1e-3)
    assert np.median(np.diff(log.t)) == pytest.approx(1 / rate, rel=1e-3)
    noted = [s for s in log.notes if s.startswith("time column")]
    assert (f"time column 't' read as {unit} " in noted[0]) if unit else not noted, log.notes


def test_vendor_prefixed_names_are_recognised(tmp_path):
    """MicroStrain/MSCL exports name the calibrated accelerometer scaledAccelX."""
    path = tmp_path / "mscl.csv"
    path.write_text(
        "timestamp,scaledAccelX,scaledAccelY,scaledAccelZ,scaledGyroX,scaledGyroY,scaledGyroZ\n"
        "0,0.1,0.2,0.9,0,0,0\n0.01,0.1,0.2,0.9,0,0,0\n"
    )
    log = load_log(path)
    assert log.columns["ax"] == "scaledAccelX" and log.columns["gz"] == "scaledGyroZ"
    np.testing.assert_allclose(log.acc[0], [0.1, 0.2, 0.9])


def test_every_fit_takes_a_file_path(tmp_path):
    """A new user's first call, ``calibrate_accel("log.csv")``, raised a TypeError about
    float() and a PosixPath. Every fit now loads a path (str or pathlib) with load_log, as the
    command line does: the same parameters as loading first (bit for bit: the same arrays)."""
    import calib_jax as cj
    from calib_jax.datasets import demo_log_path, mag_demo_log_path
    from calib_jax.marg import calibrate_marg_log

    acc = cj.calibrate_accel(str(demo_log_path()))
    np.testing.assert_array_equal(acc.params, cj.calibrate_accel(load_log(demo_log_path())).params)
    assert acc.source == str(demo_log_path())
    mag = cj.calibrate_mag(mag_demo_log_path())
    np.testing.assert_array_equal(
        mag.center, cj.calibrate_mag(load_log(mag_demo_log_path())).center
    )
    marg = calibrate_marg_log(mag_demo_log_path())
    np.testing.assert_array_equal(marg.mag.soft_iron, mag.soft_iron)  # (dates and notes differ)
    assert marg.source == str(mag_demo_log_path())
    missing = tmp_path / "nope.csv"
    with pytest.raises(ValueError, match="nope.csv"):
        cj.calibrate_accel(missing)


def test_rows_in_brackets_say_what_was_found(tmp_path):
    """uBot's LSM303 logs print a Python tuple per sample: the error quoted nothing and said
    'no row of 6 numbers found' of rows that hold six numbers in brackets; then it quoted the
    first line. Lines that are all tuples are now read as rows of their numbers; a line with
    other text around its brackets is still refused, quoting it."""
    rows = "".join(f"(({i}.5, -0.05, 10.5), (-38.7, -60.9, 0.9))\n" for i in range(30))
    log = load_log(_write(tmp_path, rows, "tuples.txt"))
    np.testing.assert_array_equal(log.acc[:, 0], np.arange(30) + 0.5)
    labelled = "".join(f"sample (({i}.5, -0.05, 10.5), (-38.7, -60.9, 0.9))\n" for i in range(30))
    with pytest.raises(ValueError, match=r"first line: 'sample \(\(0\.5, -0\.05.*brackets"):
        load_log(_write(tmp_path, labelled, "labelled.txt"))


def test_json_list_lines_read_with_the_time_column_where_it_rises(tmp_path):
    """micropython-fusion logs one JSON list per line, ``[[ax, ay, az], [gx, gy, gz], [mx, my,
    mz], ticks_us]``, with a text marker between: refused before ('no row of 10 plain
    numbers'), and with the brackets stripped the headerless ten columns were read time first,
    accelerometer x taking the time's place. Now the lists are rows, the time is the column that
    rises (here the last; the first is a sensor axis), and the marker is a skipped row."""
    rows = [
        f"[[{0.1 * np.sin(i):.4f}, 0.01, -0.98], [0.5, -0.2, 0.1], [12.0, -3.5, 40.2], "
        f"{842_331_904 + 20_000 * i}]"
        for i in range(40)
    ]
    rows.insert(20, "cal_end")
    log = load_log(_write(tmp_path, "\n".join(rows) + "\n", "mpudata"))
    assert log.acc.shape == (40, 3) and log.mag.shape == (40, 3)
    np.testing.assert_allclose(log.acc[:, 2], -0.98)
    np.testing.assert_allclose(log.mag[0], [12.0, -3.5, 40.2])
    np.testing.assert_allclose(np.diff(log.t), 0.02)  # microseconds to seconds
    assert any("bracketed lists" in n for n in log.notes)
    assert any("time last" in n for n in log.notes)
    assert any("1 rows had the wrong number of fields" in n for n in log.notes)


def test_json_exports_are_read_by_their_arrays_names(tmp_path):
    """A JSON export was read as one text row (a Unlicense'd cave-surveying device's
    calibration file: "no header and 583 columns", 9,992 characters, and a --columns example
    of 580 underscores that led to "no finite samples"). Now a JSON document is read by the
    names of its numeric arrays, as a MATLAB file's variables are: a list of records (and
    JSON Lines of them) by its keys, an object's arrays by their last key, an N x 3 'acc'; a
    document whose arrays name no sensor is refused in one line naming them. The samples
    must come back exactly as written (JSON keeps a float64's 17 digits)."""
    import json

    rng = np.random.default_rng(5)
    t = np.arange(200) / 50.0
    acc = rng.normal(size=(200, 3))
    records = [
        {"t": a, "ax": b[0], "ay": b[1], "az": b[2], "id": "x"} for a, b in zip(t, acc, strict=True)
    ]
    nested = {"device": "imu", "data": {"time": t.tolist(), "acc": acc.tolist()}}
    lines = "\n".join(json.dumps(r) for r in records) + "\n"
    for name, text in (
        ("records.json", json.dumps(records)),
        ("nested.json", json.dumps(nested)),
        ("lines.jsonl", lines),
    ):
        log = load_log(_write(tmp_path, text, name))
        np.testing.assert_array_equal(log.acc, acc, err_msg=name)
        np.testing.assert_allclose(log.sample_rate, 50.0, rtol=1e-9, err_msg=name)
        assert any("JSON document" in n for n in log.notes), (name, log.notes)
    shots = {"shots": {"grav": acc.ravel().tolist(), "mag": acc.ravel().tolist()}}
    with pytest.raises(ValueError, match=r"which JSON array .*found: shots\.grav 600") as e:
        load_log(_write(tmp_path, json.dumps(shots), "ab.json"))
    assert len(str(e.value)) < 300, str(e.value)
    # a text log opening with a bracketed section name is still read as text
    rows = "[Data]\nt,ax,ay,az\n" + "".join(
        f"{a},{b[0]},{b[1]},{b[2]}\n" for a, b in zip(t, acc, strict=True)
    )
    np.testing.assert_array_equal(load_log(_write(tmp_path, rows, "sectioned.csv")).acc, acc)


def test_a_headerless_time_layout_without_a_rising_column_is_refused(tmp_path):
    """Ten headerless columns read as t then nine sensor columns; when neither the first
    column nor the last rises, no clock is made from a sensor axis (it was: accelerometer x
    as the time, and a 'sample rate' from its steps): the error says so and what to pass."""
    rng = np.random.default_rng(0)
    rows = "".join(",".join(f"{v:.4f}" for v in rng.normal(size=10)) + "\n" for _ in range(40))
    with pytest.raises(ValueError, match="neither the first column nor the last rises"):
        load_log(_write(tmp_path, rows, "nine_and_noise.csv"))
    # a clock of whole seconds at 50 Hz (98 % ties) still rises: time first, as before
    coarse = "".join(
        f"{i // 50}," + ",".join(f"{v:.4f}" for v in rng.normal(size=9)) + "\n" for i in range(200)
    )
    log = load_log(_write(tmp_path, coarse, "coarse_clock.csv"))
    first = [float(v) for v in coarse.splitlines()[0].split(",")]
    np.testing.assert_array_equal(log.acc[0], first[1:4])  # column 1 taken as the time
    assert log.t is not None and np.all(np.diff(log.t) >= 0)


def test_actigraph_epoch_counts_refused_by_name_and_its_raw_export_read(tmp_path):
    """ActiLife's CSV opens with ten preamble lines, each one text cell padded with commas to
    the data's nine fields (the lines below are GGIR's test file's, wadpac/GGIR, Apache-2.0;
    the rows are made up). The first line was taken as a header and the error proposed
    '--columns ax=------------ Data File Created By ...,ay=,az='. Counts per 5 s epoch are no
    readings: the error now says what the file is and what to export; the raw export (epoch
    00:00:00, 'Accelerometer X' columns) reads, its preamble left out with a note."""
    pre = [
        "------------ Data File Created By ActiGraph wGT3XBT ActiLife v6.13.3 Firmware v1.8.0 "
        "date format M/d/yyyy Filter Normal Multiple Incline Limb: Waist -----------",
        "Serial Number: MOS2D16160581",
        "Start Time 21:35:00",
        "Start Date 8/15/2016",
        "Epoch Period (hh:mm:ss) 00:00:05",
        "Download Time 18:59:15",
        "Download Date 8/24/2016",
        "Current Memory Address: 0",
        "Current Battery Voltage: 4.03     Mode = 61",
        "--------------------------------------------------",
    ]
    counts = "".join(f"{i % 300},{i % 7},{i % 11},2,0,0,5,0,0\n" for i in range(60))
    text = "".join(line + ",,,,,,,,\n" for line in pre) + counts
    with pytest.raises(ValueError, match=r"activity counts per 00:00:05 epoch.*raw"):
        load_log(_write(tmp_path, text, "ActiGraph61.csv"))
    raw = [line.replace("00:00:05", "00:00:00") + ",," for line in pre]
    raw.append("Accelerometer X,Accelerometer Y,Accelerometer Z")
    raw += [f"{0.01 * np.sin(i):.3f},-0.020,0.980" for i in range(60)]
    log = load_log(_write(tmp_path, "\n".join(raw) + "\n", "raw.csv"))
    np.testing.assert_allclose(log.acc[:, 2], 0.98)
    assert any("10 line(s) before the data ignored" in n for n in log.notes)


def test_ros_px4_and_phone_export_names_read_without_flags(tmp_path):
    """Headers a fourth new user's run met, none recognised before (each needed --columns, and
    the error's example mapped time and gyro as the accelerometer): ROS ``rostopic echo -p``
    (a '%time' header line, ``field.linear_acceleration.x``; its covariance columns are no
    readings), PX4 ``ulog2csv`` (``accelerometer_m_s2[0]``), phyphox (the sensor only in the
    unit, ``X (µT)``). The header lines are these tools' own; the rows are made up."""
    ros = "%time,field.header.seq,field.orientation.x,field.angular_velocity.x,"
    ros += "field.angular_velocity.y,field.angular_velocity.z,field.angular_velocity_covariance0,"
    ros += "field.linear_acceleration.x,field.linear_acceleration.y,field.linear_acceleration.z\n"
    ros += "".join(f"{10**8 * i},{i},0,0.1,0.2,0.3,-1,1.5,2.5,9.7\n" for i in range(1, 41))
    log = load_log(_write(tmp_path, ros, "ros.csv"))
    assert log.columns["gx"] == "field.angular_velocity.x"
    np.testing.assert_array_equal(log.acc[0], [1.5, 2.5, 9.7])
    np.testing.assert_array_equal(log.gyro[0], [0.1, 0.2, 0.3])
    assert log.sample_rate == pytest.approx(10.0)  # ns stamps, 0.1 s apart
    px4 = "timestamp,gyro_rad[0],gyro_rad[1],gyro_rad[2],gyro_integral_dt,"
    px4 += "accelerometer_m_s2[0],accelerometer_m_s2[1],accelerometer_m_s2[2],"
    px4 += "accelerometer_integral_dt,magnetometer_ga[0],magnetometer_ga[1],magnetometer_ga[2]\n"
    px4 += "".join(
        f"{4000 * i},0.01,0.02,0.03,0.004,1.1,-0.4,-9.6,0.004,0.1,0.2,0.4\n" for i in range(40)
    )
    log = load_log(_write(tmp_path, px4, "px4.csv"))
    np.testing.assert_array_equal(log.acc[0], [1.1, -0.4, -9.6])
    np.testing.assert_array_equal(log.mag[0], [0.1, 0.2, 0.4])
    np.testing.assert_array_equal(log.gyro[0], [0.01, 0.02, 0.03])
    # the units the names state label the reports (the magnetometer's was 'raw units')
    assert log.units == {"accel": "m/s^2", "gyro": "rad/s", "mag": "gauss"}
    phone = '"Time (s)","X (µT)","Y (µT)","Z (µT)"\n'
    phone += "".join(f"{0.01 * i},18.4,3.5,-35.5\n" for i in range(40))
    log = load_log(_write(tmp_path, phone, "Magnetometer.csv"))
    assert log.acc is None and log.columns["mx"] == "X (µT)"
    np.testing.assert_array_equal(log.mag[0], [18.4, 3.5, -35.5])
    assert log.units == {"mag": "uT"}


@pytest.mark.parametrize(
    "name, canon",
    [
        ("field.magnetic_field.z", "mz"),
        ("X (m/s^2)", "ax"),
        ("Z (rad/s)", "gz"),
        ("angularVelocityY", "gy"),
        ("Accel X (g)", "ax"),
        ("w_RS_S_x [rad s^-1]", "gx"),  # EuRoC / Kalibr imu0/data.csv
        ("a_RS_S_z [m s^-2]", "az"),
        ("p_RS_R_x [m]", None),  # EuRoC ground truth: a position
        # no reading: a covariance, an orientation, an estimate, a bare axis, a mixed name
        ("field.linear_acceleration_covariance0", None),
        ("field.orientation.x", None),
        ("estGravityVectorX", None),
        ("accelerometer_integral_dt", None),
        ("X", None),
        ("field.gyro.x (m/s^2)", None),
        # Shimmer3 (Consensys export, hpi-dhc/devicely): a device id before, CAL after the axis
        ("Shimmer_40AC_Accel_LN_X_CAL", "ax"),
        ("Shimmer_40AC_Gyro_Y_CAL", "gy"),
        ("Shimmer_40AC_Mag_Z_CAL", "mz"),
        ("Shimmer_40AC_Timestamp_Unix_CAL", "t"),
        ("Shimmer_40AC_GSR_Skin_Conductance_CAL", None),
        ("Shimmer_40AC_Ext_Exp_A15_CAL", None),
        ("ICM20948_accel_x", "ax"),
    ],
)
def test_names_read_word_by_word(name, canon):
    assert canonical_name(name) == canon


def test_trailing_field_of_marker_rows_and_datetime_stamps(tmp_path):
    """Mind Monitor's Muse export (hpi-dhc/devicely): the header names a last field,
    'Elements', that only marker rows write, and the time is a date and time. It was refused
    ('39 names, but the data rows have 38 fields', with an example mapping EEG columns as the
    accelerometer) and the time column was text."""
    text = "TimeStamp,Accelerometer_X,Accelerometer_Y,Accelerometer_Z,Elements\n"
    for i in range(40):
        text += f"2021-04-05 15:48:{4 + 0.02 * i:06.3f},{0.1 * i:g},0.5,0.9\n"
        if i == 7:
            text += "2021-04-05 15:48:04.150,,,,/muse/elements/blink\n"
    log = load_log(_write(tmp_path, text))
    assert log.columns == {"t": "TimeStamp", "ax": "Accelerometer_X", "ay": "Accelerometer_Y",
                           "az": "Accelerometer_Z"}  # fmt: skip
    np.testing.assert_allclose(log.acc[:, 0], 0.1 * np.arange(40))
    np.testing.assert_allclose(np.diff(log.t), 0.02, atol=1e-6)  # ms stamps
    assert log.t[0] == pytest.approx(1617637684.0)  # Unix seconds of 2021-04-05 15:48:04 UTC
    assert log.sample_rate == pytest.approx(50.0)
    assert any("'Elements' are fields only some rows have" in n for n in log.notes)
    assert not any("before the data ignored" in n for n in log.notes)
    # without rows of the header's width it is no such header: still refused
    bad = "t,ax,ay,az,Elements\n" + _table(ROWS[:, :4])
    with pytest.raises(ValueError, match="looks like a header with 5 names"):
        load_log(_write(tmp_path, bad, "b.csv"))


def test_bare_axis_names_are_the_command_sensor(tmp_path):
    """A header of X, Y, Z alone (Faros 180's ACC.csv, hpi-dhc/devicely) names no sensor: it
    is read as a headerless 3-column file is, the command's sensor, with a note (it was 'no
    sensor columns recognised in ['X', 'Y', 'Z']' on every command)."""
    path = _write(tmp_path, "X,Y,Z\n" + _table(ROWS[:, 1:4]))
    log = load_log(path, sensor="mag")
    np.testing.assert_array_equal(log.mag, ROWS[:, 1:4])
    assert log.acc is None and any("name no sensor: read as mx my mz" in n for n in log.notes)
    np.testing.assert_array_equal(load_log(path).acc, ROWS[:, 1:4])


def test_unrecognised_names_get_an_example_for_the_command_sensor(tmp_path):
    """The example maps the sensor the command asked for, leaves the rising column (time) out
    of the axes and is quoted for the shell when a name has spaces."""
    text = "Zeit [s],Kanal 1,Kanal 2,Kanal 3\n" + "".join(
        f"{0.01 * i},{18 + i % 3},{3 - i % 2},{-35 + i % 5}\n" for i in range(40)
    )
    with pytest.raises(ValueError, match=r"--columns 't=Zeit \[s\],mx=Kanal 1,my=Kanal 2,"):
        load_log(_write(tmp_path, text, "k.csv"), sensor="mag")


def test_interleaved_sensor_instances_are_read_one_at_a_time(tmp_path):
    """ArduPilot's IMU and MAG messages (mavlogdump --format csv) interleave every IMU's rows,
    told apart by the instance column I: read as one sensor, two IMUs gave 'the time column
    must increase' (each time stamp twice) and one pose of their readings mixed. The first
    row's instance is read, with a note naming the others; instance= picks another."""
    head = "timestamp,TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,T\n"
    rows = "".join(
        f"{0.04 * k:.2f},{40000 * k},{i},0.01,0.02,0.03,{0.6 - i},0.9,-9.8,{37 - 9 * i}\n"
        for k in range(20)
        for i in (0, 1)
    )
    p = _write(tmp_path, head + rows, "IMU.csv")
    first = load_log(p)
    assert len(first) == 20 and np.all(first.acc[:, 0] == 0.6)
    assert np.all(np.diff(first.t) > 0)
    assert any(
        "column 'I' interleaves 2 sensors' rows: read those of I = 0" in n for n in first.notes
    )
    second = load_log(p, instance=1)
    assert len(second) == 20 and np.all(second.acc[:, 0] == -0.4)
    with pytest.raises(ValueError, match="no rows of instance 4: column 'I' holds 0, 1"):
        load_log(p, instance=4)
    # a column named I that does not take turns (a current, a counter) is read as it is
    plain = head + "".join(f"{0.04 * k:.2f},{40000 * k},{k},0,0,0,0,0,-9.8,37\n" for k in range(20))
    assert len(load_log(_write(tmp_path, plain, "plain.csv"))) == 20


def test_a_given_sample_rate_replaces_a_time_column_that_does_not_tick(tmp_path):
    """RocketPy's TeleMega export repeats time stamps (511 steps do not rise): the gyro fit
    said 'leave the time column out and give --sample-rate', and with --sample-rate (and
    --columns naming no time) it read the same column again and said the same. A given rate
    now replaces a time column that does not increase, with a note; a rising one is kept."""
    rows = "".join(f"{0.01 * (k // 2):.2f},0.1,0.2,0.9\n" for k in range(40))
    p = _write(tmp_path, "time,ax,ay,az\n" + rows)
    assert load_log(p).t is not None  # without a rate: kept, for the fit to refuse and say why
    log = load_log(p, sample_rate=100.0)
    assert log.t is None and log.sample_rate == 100.0
    assert any("does not increase (20 steps)" in n for n in log.notes)
    good = "".join(f"{0.01 * k:.2f},0.1,0.2,0.9\n" for k in range(40))
    assert (
        load_log(_write(tmp_path, "time,ax,ay,az\n" + good, "g.csv"), sample_rate=50.0).t
        is not None
    )


def test_a_file_named_for_one_sensor_gives_its_bare_columns_that_sensor(tmp_path):
    """Sensor Logger (iOS, Android) writes one file per sensor, Accelerometer.csv,
    GyroscopeUncalibrated.csv, MagnetometerUncalibrated.csv, each with the columns time,
    seconds_elapsed, z, y, x (a new user's copy of simorxb/quaternion-complementary-filter).
    Every file's x, y, z were read as an accelerometer: `diagnose` diagnosed the magnetometer
    file as an accelerometer, `batch` fitted the gyroscope's as one, and `marg` read the
    accelerometer's file as a magnetometer. The file's name now says which sensor bare columns
    hold, and a name that contradicts the command's sensor is refused with what to do."""
    rng = np.random.default_rng(0)
    t = 1.7e18 + 1e7 * np.arange(200)  # ns since the epoch, 100 Hz
    rows = np.column_stack([t, np.arange(200) / 100, rng.normal(size=(200, 3))])
    for name in ("GyroscopeUncalibrated.csv", "MagnetometerUncalibrated.csv", "data.csv"):
        np.savetxt(tmp_path / name, rows, delimiter=",", header="time,seconds_elapsed,z,y,x",
                   comments="", fmt="%.17g")  # fmt: skip
    gyro = load_log(tmp_path / "GyroscopeUncalibrated.csv")
    assert gyro.acc is None and gyro.mag is None
    np.testing.assert_array_equal(gyro.gyro, rows[:, [4, 3, 2]])  # x, y, z by name
    assert any("names the gyroscope" in n for n in gyro.notes), gyro.notes
    mag = load_log(tmp_path / "MagnetometerUncalibrated.csv")
    assert mag.acc is None and mag.mag is not None
    assert load_log(tmp_path / "MagnetometerUncalibrated.csv", sensor="mag").mag is not None
    assert load_log(tmp_path / "data.csv").acc is not None  # no name, no change
    with pytest.raises(ValueError, match=r"names the magnetometer, not the accelerometer.*"
                       r"--columns ax=x,ay=y,az=z"):  # fmt: skip
        load_log(tmp_path / "MagnetometerUncalibrated.csv", sensor="accel")
    explicit = load_log(tmp_path / "MagnetometerUncalibrated.csv", columns="ax=x,ay=y,az=z")
    assert explicit.acc is not None  # --columns overrides the name
    # headerless: a 4-column file named for the gyroscope
    np.savetxt(tmp_path / "xsens_gyro.txt", rows[:, [1, 2, 3, 4]])
    assert load_log(tmp_path / "xsens_gyro.txt").gyro is not None
    # the positional advice names the time column the file was read with (it said --columns
    # ax,ay,az, which read the time as ax; a trial on sunsided/sensor-fusion's 4-column files)
    with pytest.raises(ValueError, match=r"headerless file: --columns t,ax,ay,az\)"):
        load_log(tmp_path / "xsens_gyro.txt", sensor="accel")
    advised = load_log(tmp_path / "xsens_gyro.txt", columns="t,ax,ay,az")
    np.testing.assert_array_equal(advised.acc, rows[:, 2:5])
    named = {
        "xsens_gyro.mat": "gyro",
        "Accelerometer.csv": "accel",
        "imu_acc.csv": "accel",
        "compass_log.csv": "mag",
        "AccelGyro.csv": None,  # two sensors: no word from the name
        "image_stack.csv": None,  # 'mag' inside a word is no name
        "imu.csv": None,
    }
    assert {k: F.sensor_named_by(k) for k in named} == named


def test_an_android_uncalibrated_event_file_reads_its_readings_not_its_bias(tmp_path):
    """Android's uncalibrated gyroscope and magnetometer events carry x, y, z and the OS's bias
    estimate; a phone logger wrote them as `t x y z bx by bz` with the bias constant
    (tyrex-team/benchmarks-attitude-smartphones' Nexus 5). The 7 columns were read as
    t ax ay az gx gy gz: `calib-jax gyro ACC GYRO` fitted the three constants as the gyro and
    exited 0, and `calib-jax mag` called the sensor stuck. Three constant last columns after
    three that move are now that layout, for the command's sensor or the file's name's."""
    rng = np.random.default_rng(0)
    t = 0.5 + 0.005 * np.arange(300)
    xyz = rng.normal(size=(300, 3))
    rows = np.column_stack([t, xyz, np.tile([0.0085, -0.0040, 0.0688], (300, 1))])
    np.savetxt(tmp_path / "gyroscope.txt", rows)
    np.savetxt(tmp_path / "magnetometer.txt", rows)
    gyro = load_log(tmp_path / "gyroscope.txt")
    assert gyro.acc is None and gyro.mag is None
    np.testing.assert_array_equal(gyro.gyro, xyz)
    assert "three held columns" in gyro.notes[0], gyro.notes
    np.testing.assert_array_equal(load_log(tmp_path / "gyroscope.txt", sensor="gyro").gyro, xyz)
    np.testing.assert_array_equal(load_log(tmp_path / "magnetometer.txt", sensor="mag").mag, xyz)
    # the positional advice names the time first (ax,ay,az read the time as ax; a trial)
    refusal = r"names the gyroscope, not the accelerometer.*headerless file: --columns t,ax,ay,az"
    with pytest.raises(ValueError, match=refusal):
        load_log(tmp_path / "gyroscope.txt", sensor="accel")
    # an estimate Android updated now and then during the log (15 times in a 2-minute tumble
    # of the same phone's magnetometer): its bias columns were calibrated as the magnetometer
    held = rows.copy()
    held[150:, 4:] += [0.3, -0.1, 0.2]
    held[250:, 4:] += [0.1, 0.1, -0.1]
    np.savetxt(tmp_path / "magnetometer.txt", held)
    np.testing.assert_array_equal(load_log(tmp_path / "magnetometer.txt").mag, xyz)
    # the usual IMU order, whose last three columns move, reads as before
    rows[:, 4:] = rng.normal(size=(300, 3))
    np.savetxt(tmp_path / "imu.txt", rows)
    imu = load_log(tmp_path / "imu.txt")
    np.testing.assert_array_equal(imu.acc, xyz)
    np.testing.assert_array_equal(imu.gyro, rows[:, 4:])


@pytest.mark.parametrize("with_time", [False, True])
def test_a_headerless_log_with_the_gyroscope_first_is_read_by_its_data(tmp_path, with_time):
    """x-io's hand-held log (shared data) without its header: gyroscope (deg/s), accelerometer
    (g), magnetometer (uT), as x-io and many loggers write them. It was read in the usual IMU
    order, accelerometer first, and `calib-jax accel` then failed on 'only 6 distinct poses',
    the gyro's readings taken for gravity. Now the columns whose magnitude rests near zero and
    jumps (median 0.008 of the 95th percentile here) are read as the gyroscope and those with a
    steady one (0.94) as the accelerometer; the arrays equal the header's reading exactly. A
    file in the usual order is unchanged (test_headerless_width_decides_and_the_note_names_the
    _guess)."""
    from .conftest import shared_file

    src = shared_file("xio_fusion_sensor_data/sensor_data.csv")
    named = load_log(src)
    table = np.loadtxt(src, delimiter=",", skiprows=1)
    p = tmp_path / "headerless.csv"
    np.savetxt(p, table if with_time else table[:, 1:], delimiter=",")
    log = load_log(p, sample_rate=None if with_time else 100.0)
    for arr, ref in ((log.acc, named.acc), (log.gyro, named.gyro), (log.mag, named.mag)):
        np.testing.assert_allclose(arr, ref, rtol=1e-15)
    note = next(n for n in log.notes if n.startswith("headerless"))
    assert "gx gy gz ax ay az mx my mz" in note and "gyroscope first" in note, note


def test_sensor_names_with_an_index_after_a_chip_read_as_axes(tmp_path):
    """OpenAXES's logs (OpenAXES-IMU/OpenAXES; not shipped, its licence unclear): ';'-separated,
    a MAC address and an IMU name in text, TIME in us, four QUATERNION_n columns of zeros, two
    accelerometers ACCEL_ADXL355_0..2 and ACCEL_BMI160_0..2 (m/s^2), GYRO_0..2 (rad/s) and
    GYRO_ECC_0..2. Every command refused it: 'a sensor-fusion output (QUATERNION_0, ...),
    nothing here to calibrate'. An index 0-2 after a separator is an axis, as [0]-[2] was; the
    second accelerometer gets the two-sensors note, naming both chips."""
    rng = np.random.default_rng(0)
    n = 40
    adxl, bmi, gyro = rng.normal(size=(3, n, 3))
    names = ["MAC", "IMU", "TIME", "INDEX", *(f"QUATERNION_{k}" for k in range(4))]
    names += [f"ACCEL_ADXL355_{k}" for k in range(3)] + [f"ACCEL_BMI160_{k}" for k in range(3)]
    names += [f"GYRO_{k}" for k in range(3)] + [f"GYRO_ECC_{k}" for k in range(3)]
    rows = [
        ";".join(
            ["18:04:ED:C4:75:1A", "imu9", str(1655928838621431 + 11213 * i), str(51 + i)]
            + ["0.000000"] * 4
            + [f"{v:.6f}" for v in (*adxl[i], *bmi[i], *gyro[i])]
            + ["0"] * 3
        )
        for i in range(n)
    ]
    p = tmp_path / "log_imu9.csv"
    p.write_text(";".join(names) + "\n" + "\n".join(rows) + "\n")
    log = load_log(p)
    np.testing.assert_allclose(log.acc, adxl, atol=5e-7)  # 6 decimals in the file
    np.testing.assert_allclose(log.gyro, gyro, atol=5e-7)
    assert log.mag is None and log.t[1] - log.t[0] == pytest.approx(0.011213, abs=1e-6)  # us
    [twice] = [x for x in log.notes if "twice" in x]
    assert "ax (ACCEL_ADXL355_0, column 9, and ACCEL_BMI160_0, 12)" in twice, twice
    other = load_log(p, columns=twice.split("--columns ")[1].split()[0])
    np.testing.assert_allclose(other.acc, bmi, atol=5e-7)
    for name in ("GYRO_ECC_0", "QUATERNION_0", "INDEX", "acc2"):
        assert canonical_name(name) is None, name


def test_a_header_naming_two_sensors_says_so_and_how_to_read_the_second(tmp_path):
    """gaitmap's example (mad-lab-fau/gaitmap, MIT): a line 'sensor,left_sensor,...,
    right_sensor,...' over 'axis,acc_x,...,gyr_z,acc_x,...,gyr_z', two foot IMUs. Six notes
    said 'column acc_x also reads as ax' and the upper line was 'under the header'. One note
    now names the repeated columns, and the --columns it offers reads the right foot."""
    left, right = np.arange(60.0).reshape(10, 6), 100.0 + np.arange(60.0).reshape(10, 6)
    names = ["acc_x", "acc_y", "acc_z", "gyr_x", "gyr_y", "gyr_z"]
    text = (
        "sensor," + ",".join(["left_sensor"] * 6 + ["right_sensor"] * 6) + "\n"
        "axis," + ",".join(names * 2) + "\n"
        + _table(np.column_stack([np.arange(10.0), left, right]))
    )  # fmt: skip
    p = _write(tmp_path, text)
    log = load_log(p)
    np.testing.assert_array_equal(log.acc, left[:, :3])
    said = [n for n in log.notes if "twice" in n]
    assert len(said) == 1 and "acc_x (columns 2 and 8)" in said[0], log.notes
    read = [n for n in log.notes if n.startswith("header line 2 read (axis,acc_x")]
    assert len(read) == 1 and "line 1 skipped (sensor,left_sensor" in read[0], log.notes
    columns = said[0].split("--columns ")[1].split()[0]
    other = load_log(p, columns=columns)
    np.testing.assert_array_equal(other.acc, right[:, :3])
    np.testing.assert_array_equal(other.gyro, right[:, 3:])


def _dataflash_row(name, *values) -> str:
    """One message line as ArduPilot writes it; floats by repr, so they read back exactly."""
    cells = [str(v) if isinstance(v, int | np.integer) else repr(float(v)) for v in values]
    return ", ".join([name, *cells])


def test_ardupilot_text_logs_are_read_by_message(tmp_path):
    """ArduPilot's dataflash text log (Mission Planner's .log; a new-user trial on ArduPilot's
    own example log, ArduCopter 3.1, GPL-3.0, not shipped: this file has its shape) was read
    as one table of the rows of the commonest width: IMU, IMU2, ATT and CURR ran together as
    "no header and 8 columns", and the --columns advice put ax on the messages' names. Now the
    FMT lines name each message's columns: the IMU's accelerometer and gyroscope, IMU2 as
    instance 1, MAG (at a fifth of the IMU's rate) for the magnetometer with the IMU row
    nearest in time beside each row, a compass's 0, 0, 0 rows read as NaN, and later
    firmware's instance column I. Every value must come back exactly as written."""
    rng = np.random.default_rng(7)
    n = 200
    t_ms = 95892 + 20 * np.arange(n)  # 50 Hz
    gyr, acc, acc2 = (rng.normal(size=(n, 3)) for _ in range(3))
    mag = 300 * rng.normal(size=(n // 5, 3))
    mag[:3] = 0.0  # the compass not yet answering
    t_mag = t_ms[::5] + 3
    lines = [
        "ArduCopter V3.1",
        "",
        "FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format",
        "FMT, 131, 31, IMU, Iffffff, TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ",
        "FMT, 135, 31, IMU2, Iffffff, TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ",
        "FMT, 1, 19, ATT, IccccCC, TimeMS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw",
        "FMT, 15, 25, MAG, Ihhhhhhhhh, TimeMS,MagX,MagY,MagZ,OfsX,OfsY,OfsZ,MOfsX,MOfsY,MOfsZ",
        "PARM, SYSID_SW_MREV, 120",
    ]
    for i in range(n):
        lines.append(_dataflash_row("IMU", t_ms[i], *gyr[i], *acc[i]))
        lines.append(_dataflash_row("IMU2", t_ms[i], *gyr[i], *acc2[i]))
        lines.append(_dataflash_row("ATT", t_ms[i], 1, 2, 3, 4, 5, 6))  # as wide as IMU
        if i % 5 == 0:
            lines.append(_dataflash_row("MAG", t_mag[i // 5], *mag[i // 5], *[0] * 6))
    path = _write(tmp_path, "\n".join(lines) + "\n", "00000012.log")

    log = load_log(path)
    np.testing.assert_array_equal(log.acc, acc)
    np.testing.assert_array_equal(log.gyro, gyr)
    assert log.mag is None and log.units == {"accel": "m/s^2", "gyro": "rad/s"}
    np.testing.assert_allclose(log.sample_rate, 50.0, rtol=1e-9)
    assert any("ArduPilot log: read message IMU and IMU2" in s for s in log.notes), log.notes
    assert any("magnetometer (MAG" in s for s in log.notes), log.notes
    np.testing.assert_array_equal(load_log(path, instance=1).acc, acc2)

    mlog = load_log(path, sensor="mag")
    np.testing.assert_array_equal(mlog.mag[3:], mag[3:])
    assert np.isnan(mlog.mag[:3]).all()
    np.testing.assert_array_equal(mlog.acc, acc[::5])  # the IMU rows 3 ms before each MAG row
    np.testing.assert_allclose(mlog.sample_rate, 10.0, rtol=1e-9)
    assert any("3 magnetometer rows of 0, 0, 0" in s for s in mlog.notes), mlog.notes

    # later firmware: one IMU message with an instance column I, time in microseconds
    fmt = "FMT, 172, 43, IMU, QBffffff, TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ"
    rows = [fmt, "FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format,Columns", lines[5]]
    for i in range(n):
        rows += [_dataflash_row("IMU", 1000 * int(t_ms[i]), k, *gyr[i], *a[i]) for k, a in
                 enumerate((acc, acc2))]  # fmt: skip
    new = _write(tmp_path, "\n".join(rows) + "\n", "00000013.log")
    np.testing.assert_array_equal(load_log(new).acc, acc)
    np.testing.assert_array_equal(load_log(new, instance=1).acc, acc2)

    with pytest.raises(ValueError, match=r"ArduPilot log whose messages carry no accel.*ATT 200"):
        att = [line for line in lines if line.startswith(("FMT", "ATT"))]
        load_log(_write(tmp_path, "\n".join(att) + "\n", "att.log"))


def test_arduino_serial_captures_are_read_by_their_labels(tmp_path):
    """An Arduino sketch's serial output, as a new user saves it from the Serial Monitor (a
    new-user trial re-wrote tomisuarez2/ImuCalibration's MPU-6050 log, MIT, this way): the
    labelled values 'ax: -12 ay: -812 az: 15032' were 12 columns of 'no header', whose
    --columns advice read labels as numbers ('no finite samples'); the Arduino playground's
    'AcX = 11219 | AcY = 4382 | ... | Tmp = 36.50 | GyX = ...' was 'no row of 27 plain
    numbers'; i2cdevlib's MPU6050_raw 'a/g:' before six numbers was 'no header and 7
    columns'; a German spreadsheet's 'Zeit (s)' was no time column ('give --sample-rate').
    Now labels name the columns, a label column is left out, 'Fs: 100.00' above the data is
    the rate, and every value comes back exactly."""
    rng = np.random.default_rng(11)
    v = rng.integers(-16000, 16000, size=(300, 6))
    banner = "Initializing MPU...\nMPU6050 connection successful\nFs: 100.00\n"
    lines = [f"ax: {a} ay: {b} az: {c}\tgx: {d} gy: {e} gz: {f}" for a, b, c, d, e, f in v]
    log = load_log(_write(tmp_path, banner + "\n".join(lines) + "\n", "serial.txt"))
    np.testing.assert_array_equal(log.acc, v[:, :3])
    np.testing.assert_array_equal(log.gyro, v[:, 3:])
    assert log.sample_rate == 100.0, log.notes
    assert any("named by their labels (ax, ay, az, gx, gy, gz)" in n for n in log.notes)

    temp = 36.5 + 0.01 * np.arange(300)
    short = "".join(
        f"AcX = {a} | AcY = {b} | AcZ = {c} | Tmp = {float(t)!r} | "
        f"GyX = {d} | GyY = {e} | GyZ = {f}\n"
        for (a, b, c, d, e, f), t in zip(v, temp, strict=True)
    )
    log = load_log(_write(tmp_path, short, "short.txt"))
    np.testing.assert_array_equal(log.acc, v[:, :3])
    np.testing.assert_array_equal(log.gyro, v[:, 3:])
    np.testing.assert_array_equal(log.temp, temp)

    raw = "".join("a/g:\t" + "\t".join(map(str, row)) + "\n" for row in v)
    log = load_log(_write(tmp_path, banner + raw, "raw.txt"))
    np.testing.assert_array_equal(log.acc, v[:, :3])
    np.testing.assert_array_equal(log.gyro, v[:, 3:])
    assert any("column 1 holds text in every row (a label), left out" in n for n in log.notes)

    rows = "".join(f"{k / 100:.2f};{a};{b};{c}\n".replace(".", ",") for k, (a, b, c, *_) in
                   enumerate(v))  # fmt: skip
    log = load_log(_write(tmp_path, "Zeit (s);ax (g);ay (g);az (g)\n" + rows, "de.csv"))
    assert log.columns["t"] == "Zeit (s)"
    np.testing.assert_allclose(log.sample_rate, 100.0, rtol=1e-9)


def test_flight_logs_in_binary_say_how_to_convert_them(tmp_path, capsys):
    """A PX4 ULog (pyulog's sample.ulg, BSD-3, a new-user trial) was 'a binary file ... export
    the sensor columns to CSV', by every command, with no word of ULog or ulog2csv, though the
    loader reads ulog2csv's columns; an ArduPilot .bin the same. Each names its format and
    the converter whose output calib-jax reads, in load_log and through the CLI."""
    from calib_jax.cli import main

    ulog = _write(tmp_path, b"ULog\x01\x12\x35\x00" + bytes(range(256)) * 8, "flight.ulg")
    with pytest.raises(ValueError, match=r"a PX4 ULog\); pyulog's ulog2csv .*sensor_combined"):
        load_log(ulog)
    dataflash = _write(tmp_path, b"\xa3\x95\x80\x80\x59FMT\x00" + bytes(range(256)) * 8, "0.bin")
    with pytest.raises(ValueError, match=r"ArduPilot dataflash \.bin\); .*mavlogdump"):
        load_log(dataflash)
    assert main(["mag", str(ulog)]) == 2
    err = capsys.readouterr().err
    assert "ulog2csv" in err and "Traceback" not in err


def test_a_headerless_file_of_no_known_width_is_mapped_by_its_name(tmp_path):
    """iOS's magnetometer-calibrated.txt (tyrex-team, CeCILL-2.1, a new-user trial): five
    headerless columns, t x y z and an accuracy flag, whose refusal offered --columns
    t,ax,ay,az,_ (the magnetometer read as an accelerometer). The example now maps the sensor
    the file's name names, and a command for another sensor is told which one it holds."""
    rng = np.random.default_rng(2)
    rows = np.column_stack([136800 + 0.02 * np.arange(200), rng.normal(size=(200, 3)),
                            np.zeros(200)])  # fmt: skip
    np.savetxt(tmp_path / "magnetometer-calibrated.txt", rows)
    with pytest.raises(ValueError, match=r"--columns t,mx,my,mz,_ "):
        load_log(tmp_path / "magnetometer-calibrated.txt")
    with pytest.raises(ValueError, match="names the magnetometer, not the accelerometer"):
        load_log(tmp_path / "magnetometer-calibrated.txt", sensor="accel")


def test_clock_times_device_numbers_and_python_tuples_are_read(tmp_path):
    """Three layouts of a third new-user trial: WitMotion's dual logger (e-ke/get_bwt901cl_data,
    MIT) writes 'Time, AccX1, ..., AccX2, ..., AngVelX1, ...' with times of day
    ('10:41:11.376'), which were NaN (the gyro then had no clock and no way out), and its
    columns were 'no sensor columns'; a MicroPython driver's printed tuples '((ax, ay, az),
    (mx, my, mz))' (hu-zza/uBot_firmware, MIT) were 'no row of 6 plain numbers', though the
    same shape in JSON lists was read. Now times of day are seconds (a day added past
    midnight), a device number after the axis is read with the two-sensors note, and tuples
    are rows of their numbers."""
    rng = np.random.default_rng(4)
    acc, acc2, gyr = (rng.normal(size=(100, 3)) for _ in range(3))
    t = 86390.0 + 0.1 * np.arange(100)  # through midnight
    clock = [f"{int(s // 3600) % 24:02d}:{int(s % 3600 // 60):02d}:{s % 60:06.3f}" for s in t]
    rows = "".join(
        f"{c}, {', '.join(repr(float(v)) for v in [*a, *b, *w])}\n"
        for c, a, b, w in zip(clock, acc, acc2, gyr, strict=True)
    )
    header = "Time, AccX1, AccY1, AccZ1, AccX2, AccY2, AccZ2, AngVelX1, AngVelY1, AngVelZ1\n"
    log = load_log(_write(tmp_path, header + rows, "sensor_data.csv"))
    np.testing.assert_allclose(log.t - log.t[0], t - t[0], atol=1e-6)
    np.testing.assert_allclose(log.sample_rate, 10.0, rtol=1e-6)
    np.testing.assert_array_equal(log.acc, acc)
    np.testing.assert_array_equal(log.gyro, gyr)
    assert any("twice: two sensors in one file?" in n for n in log.notes), log.notes

    tuples = "".join(
        "(({!r}, {!r}, {!r}), ({!r}, {!r}, {!r}))\n".format(*(float(v) for v in [*a, *m]))
        for a, m in zip(acc, 40 * acc2, strict=True)
    )
    log = load_log(_write(tmp_path, tuples, "LSM303_log"), sensor="mag")
    np.testing.assert_array_equal(log.acc, acc)
    np.testing.assert_array_equal(log.mag, 40 * acc2)
