"""Fleets of log files: chunked streaming, the batch CLI, a Dask cluster, broken files."""

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

import calib_jax as cj
from calib_jax.cli import main
from calib_jax.fleet import calibrate_files, calibrate_files_dask
from calib_jax.simulate import random_params, simulate_accel


@pytest.fixture(scope="module")
def fleet_dir(tmp_path_factory):
    """Five simulated 48-pose logs (CSV with t, ax, ay, az; 3 s poses at 100 Hz: the default
    detector needs a moving window plus 1 s of rest) and one unreadable file."""
    d = tmp_path_factory.mktemp("fleet")
    truth = {}
    for k in range(5):
        p = random_params(k)
        log = simulate_accel(p, samples_per_pose=300, transition_samples=20, noise=2e-3, rng=k)
        path = d / f"imu{k}.csv"
        np.savetxt(
            path,
            np.column_stack([log.t, log.raw]),
            delimiter=",",
            header="t,ax,ay,az",
            comments="",
        )
        truth[str(path)] = p
    (d / "broken.csv").write_text("this is,not,a log\n1,2\n")
    return d, truth


@pytest.mark.parametrize("use", ["means", "samples"])
def test_streamed_results_match_calibrate_accel(fleet_dir, use):
    """Chunks of 2 files: every log gets the fit calibrate_accel(use=...) gives it alone (the
    same fit points from the same front door, the same chi2 evaluated in moment form), the
    broken file an error entry, in order. Tolerance 1e-9 of the parameter scale: both solves
    stop on LM's relative tolerances (1e-10 to 1e-12 here) from different starts."""
    d, truth = fleet_dir
    paths = sorted(str(p) for p in d.glob("*.csv"))
    res = list(calibrate_files(paths, chunk=2, use=use, progress=False))
    assert [r["path"] for r in res] == paths
    broken = [r for r in res if r["path"].endswith("broken.csv")]
    assert broken[0]["status"] == "load_error" and "broken.csv" in broken[0]["message"]
    for r in res:
        if r["path"] in truth:
            assert r["status"] == "ok", r
            single = cj.calibrate_accel(cj.load_log(r["path"]), use=use)
            p = np.array(r["params"])
            np.testing.assert_allclose(p, single.params, rtol=1e-9, atol=1e-9 * np.abs(p).max())
            # standard errors: the moment form's chi2 carries a relative round-off of about
            # eps / sigma^2 (sigma ~ 1e-4 of g for these means), seen as 1e-6 here
            np.testing.assert_allclose(r["stderr"], single.stderr, rtol=1e-5)
            assert r["n_points"] == single.n_points and r["use"] == use
            assert np.all(np.abs(p - truth[r["path"]]) < 5 * np.array(r["stderr"]))


def test_batch_cli_and_accel_cli_agree_on_a_real_log(tmp_path, capsys):
    """Issue 14: for the same file ``calib-jax accel`` and ``calib-jax batch`` fit the same
    points (the static-interval means from one front door) and give the same parameters, to
    1e-6 of a standard error (LM stopping tolerances; measured 4e-7 on the shipped Xsens log)."""
    import shutil

    src = Path(cj.__file__).parent / "data" / "imutk_xsens" / "xsens_acc.mat"
    d = tmp_path / "logs"
    d.mkdir()
    shutil.copy(src, d / "xsens_acc.mat")
    assert main(["accel", str(d / "xsens_acc.mat"), "--json", str(tmp_path / "one.json")]) == 0
    assert main(["batch", str(d), "--pattern", "*.mat", "--json", str(tmp_path / "b.json")]) == 0
    capsys.readouterr()
    one = cj.AccelCalibration.load(tmp_path / "one.json")
    [b] = json.loads((tmp_path / "b.json").read_text())["results"]
    assert b["status"] == "ok" and b["n_points"] == one.n_points
    z = np.abs(np.array(b["params"]) - one.params) / one.stderr
    assert z.max() < 1e-6, z
    # the detector options reach every log of a batch as they reach calib-jax accel (issue 13:
    # every command takes them): a fixed 0.3 s window and 2 s poses give other intervals
    opts = ["--window", "30", "--min-static", "2"]
    assert main(["accel", str(d / "xsens_acc.mat"), *opts, "--json", str(tmp_path / "o.json")]) == 0
    argv = ["batch", str(d), "--pattern", "*.mat", *opts, "--json", str(tmp_path / "c.json")]
    assert main(argv) == 0
    one_opts = cj.AccelCalibration.load(tmp_path / "o.json")
    [c] = json.loads((tmp_path / "c.json").read_text())["results"]
    assert c["static_intervals"] == one_opts.n_intervals and "window 30" in " ".join(c["notes"])
    assert one_opts.n_points != one.n_points or np.any(one_opts.params != one.params)
    z = np.abs(np.array(c["params"]) - one_opts.params) / one_opts.stderr
    assert z.max() < 1e-6, z


def test_an_unexpected_error_in_one_file_is_that_files_entry(fleet_dir, monkeypatch, capsys):
    """Any exception while reading one file (here an IndexError, as a --columns mapping wider
    than the file once raised) becomes that file's load_error entry; the others are fitted."""
    import calib_jax.fleet as fleet

    d, truth = fleet_dir
    paths = sorted(truth)[:2]
    real = fleet.load_log

    def flaky(path, **kw):
        if path == paths[0]:
            raise IndexError("index 7 is out of bounds for axis 1 with size 4")
        return real(path, **kw)

    monkeypatch.setattr(fleet, "load_log", flaky)
    res = list(calibrate_files(paths, progress=True))
    # the progress bar (forced on; off by default when stderr is not a terminal) counts the
    # files and the one not calibrated
    bar = capsys.readouterr().err
    assert "calibrating accel" in bar and "2/2" in bar and "not_calibrated=1" in bar, bar
    assert res[0]["status"] == "load_error" and "IndexError" in res[0]["message"]
    assert paths[0] in res[0]["message"]
    assert res[1]["status"] == "ok"


def test_reference_magnitude_follows_each_logs_unit(fleet_dir, tmp_path):
    """Without g each log is fitted to its own unit's |g| (a log in m/s^2 is the same board as
    its copy in g: same gains, bias x 9.80665); a g that contradicts a log's unit is that log's
    error, not gains of 9.8 reported as ok."""
    d, truth = fleet_dir
    src = sorted(truth)[0]
    log = np.loadtxt(src, delimiter=",", skiprows=1)
    ms2 = tmp_path / "imu_ms2.csv"
    log[:, 1:] *= 9.80665
    np.savetxt(ms2, log, delimiter=",", header="t,ax,ay,az", comments="")
    res = list(calibrate_files([src, str(ms2)], progress=False))
    assert [r["status"] for r in res] == ["ok", "ok"], res
    assert res[0]["g"] == 1.0 and res[1]["g"] == 9.80665 and res[1]["units"] == "m/s^2"
    p_g, p_ms2 = np.array(res[0]["params"]), np.array(res[1]["params"])
    np.testing.assert_allclose(p_ms2[:6], p_g[:6], rtol=1e-7)  # gains: reading per reference
    np.testing.assert_allclose(p_ms2[6:], 9.80665 * p_g[6:], rtol=1e-6, atol=1e-9)
    res = list(calibrate_files([src, str(ms2)], g=1.0, progress=False))
    assert res[0]["status"] == "ok"
    assert res[1]["status"] == "not_fitted"  # read; the given g does not fit its unit
    assert "does not match the data's unit" in res[1]["message"]


def test_batch_cli_streams_json(fleet_dir, tmp_path, capsys):
    """The JSON streams every file's result; ``--table`` writes the same results one row per
    file (parameters by name, their standard errors, status and why), and
    ``fleet.to_dataframe`` gives the same table as a DataFrame."""
    import csv

    from calib_jax.fleet import to_dataframe

    d, truth = fleet_dir
    out = tmp_path / "fleet.json"
    table = tmp_path / "fleet.csv"
    rc = main(["batch", str(d), "--json", str(out), "--chunk", "4", "--table", str(table)])
    assert rc == 1  # one file could not be calibrated
    doc = json.loads(out.read_text())
    assert doc["format_version"] == 1 and len(doc["results"]) == 6
    assert sum(r["status"] == "ok" for r in doc["results"]) == 5
    printed = capsys.readouterr().out
    assert "5 of 6 calibrated" in printed
    # the file that failed is named on the terminal with its reason
    assert any("broken.csv: load_error: " in line for line in printed.splitlines())
    rows = list(csv.DictReader(table.open()))
    assert [r["file"] for r in rows] == [r["path"] for r in doc["results"]]
    for row, res in zip(rows, doc["results"], strict=True):
        assert row["status"] == res["status"]
        if res["status"] == "ok":
            assert float(row["alpha_x"]) == res["params"][0]  # repr round-trips a float
            assert float(row["se_beta_z"]) == res["stderr"][8]
        else:
            assert row["message"] == res["message"] and row["alpha_x"] == ""
    # the file is a BatchRecord: it loads, saves and loads again equal (a file written before
    # 'kind' was, without it, loads too); its pytrees are the printed parameters
    rec = cj.BatchRecord.load(out)
    assert rec.sensor == "accel" and rec.statuses == [r["status"] for r in doc["results"]]
    rec.save(tmp_path / "again.json")
    assert cj.BatchRecord.load(tmp_path / "again.json") == rec
    old = {k: v for k, v in doc.items() if k != "kind"}
    assert cj.BatchRecord.from_dict(old) == rec
    params = rec.to_params()
    assert list(params) == [r["path"] for r in doc["results"] if r["status"] == "ok"]
    for r in doc["results"]:
        if r["status"] == "ok":
            np.testing.assert_array_equal(params[r["path"]].to_vector(), r["params"])
    with pytest.raises(ValueError, match="not one of"):
        cj.BatchRecord.from_dict({**doc, "results": [{**doc["results"][0], "status": "fine"}]})
    with pytest.raises(ValueError, match="not a batch"):
        cj.BatchRecord.from_dict({**doc, "kind": "accel"})
    pd = pytest.importorskip("pandas")
    frame = to_dataframe(doc["results"])
    assert isinstance(frame, pd.DataFrame) and len(frame) == 6
    ok = frame[frame.status == "ok"]
    np.testing.assert_array_equal(
        ok["S_xy"], [r["params"][3] for r in doc["results"] if r["status"] == "ok"]
    )


def test_batch_reads_compressed_logs_and_names_what_it_left_out(fleet_dir, tmp_path, capsys):
    """Without --pattern the batch reads every kind of log the loader reads (a gzip CSV was
    passed over in silence: '*.csv' was the default) and names the files it did not read."""
    import gzip

    src, truth = fleet_dir
    d = tmp_path / "logs"
    d.mkdir()
    (d / "imu0.csv.gz").write_bytes(gzip.compress((src / "imu0.csv").read_bytes()))
    (d / "NOTES.md").write_text("where the logs came from\n")
    (d / "imu1.dat").write_text("1 2 3\n")
    out = tmp_path / "b.json"
    assert main(["batch", str(d), "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "1 file under" in printed and "left out: 1 other file(s)" in printed
    # what sits beside logs (NOTES.md, a plot, a calibration written earlier) is not named
    assert "imu1.dat; set --pattern to read them" in printed and "NOTES.md" not in printed
    (entry,) = json.loads(out.read_text())["results"]
    assert entry["status"] == "ok" and entry["path"].endswith("imu0.csv.gz")
    # files named on the command line are read as they are, beside folders (`batch logs/*`
    # was "unrecognized arguments"); a path that does not exist is named
    assert main(["batch", str(d / "imu0.csv.gz"), str(src / "imu1.csv"), "--json", str(out)]) == 0
    assert "calib-jax batch: 2 files, sensor accel" in capsys.readouterr().out
    got = json.loads(out.read_text())["results"]
    assert [Path(e["path"]).name for e in got] == ["imu0.csv.gz", "imu1.csv"]
    assert got[0]["params"] == entry["params"]
    assert main(["batch", str(d), str(tmp_path / "missing.csv")]) == 2
    assert "missing.csv: no such file or directory" in capsys.readouterr().err


def test_batch_magnetometer_entries_get_the_single_fits_verdict(tmp_path):
    """A magnetometer whose field changed halfway (radius 1, then 1.4: no ellipsoid through
    both) and a quarter-sphere tumble: calib-jax batch called both 'ok' with no warning where
    calibrate_mag calls the first failed and warns of the second's coverage (a phone's walk,
    Aymdi/DeadReckoning: 'ok' at a 14 % radial error in the batch table, 'failed, do not use'
    alone). Each entry now has the single fit's status and warnings."""
    rng = np.random.default_rng(3)
    u = rng.normal(size=(800, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    jump = u * np.where(np.arange(800) < 400, 1.0, 1.4)[:, None] + 0.002 * rng.normal(size=u.shape)
    cap = u[(u[:, 0] > 0) & (u[:, 1] > 0)] + 0.002 * rng.normal(size=(1, 3))
    paths = []
    for name, m in (("jump", jump), ("cap", cap)):
        paths.append(tmp_path / f"{name}.csv")
        np.savetxt(paths[-1], 30 * m + 5, delimiter=",", header="mx,my,mz", comments="")
    entries = list(calibrate_files([str(p) for p in paths], sensor="mag", progress=False))
    for p, e in zip(paths, entries, strict=True):
        with warnings.catch_warnings():  # the failed fit's FitStatusWarning: its status says it
            warnings.simplefilter("ignore", cj.FitStatusWarning)
            alone = cj.calibrate_mag(str(p), model="full")
        assert e["status"] == alone.status, (p.name, e["status"], alone.status)
        cover = [w for w in alone.warnings if w.startswith("the data cover")]
        assert [w for w in e["warnings"] if w.startswith("the data cover")] == cover
    assert entries[0]["status"] == "failed" and "no ellipsoid describes" in entries[0]["message"]
    assert entries[1]["status"] != "failed" and entries[1]["warnings"]


def test_a_request_no_file_can_meet_is_refused_when_made(fleet_dir):
    """A new user's calls: model='auto' (a single fit's option) came back as every file's
    'load_error' with a bare KeyError ('auto'), and one path given as a string was read letter
    by letter (52 entries such as 'w does not exist'). Both are refused at the call, saying
    what to pass, for the local and the Dask fleet alike; a good request still streams."""
    paths = sorted(fleet_dir[1])  # the five simulated logs
    for fleet in (calibrate_files, calibrate_files_dask):
        with pytest.raises(ValueError, match=r"model must be one of \('accel9', 'accel6'\)"):
            fleet(paths, model="auto")
        with pytest.raises(TypeError, match=r"got one path .* pass \["):
            fleet(paths[0])
    with pytest.raises(ValueError, match="sphere"):
        calibrate_files(paths, sensor="mag", model="ellipsoid")
    assert next(iter(calibrate_files(paths[:1])))["status"] == "ok"


def test_the_tables_rms_is_the_single_fits():
    """The batch table's 'rms' was the moment form's RMS(1 - |a|^2/g^2) / 2 (0.0123685 on this
    hand-held log) beside calibrate_accel's RMS(|a|/g - 1) of 0.0123146: now the same quantity,
    equal to the fits' agreement (1e-9). The magnetometer's is the single fit's rms_after_pct
    / 100 to 1e-3: its radius there is the ellipsoid's (det W = 1), here the mean calibrated
    norm (tests/data/mpu9150_fusion: 3.0158 against 3.0148 %)."""
    path = str(Path(__file__).parent / "data" / "mpu9150_fusion" / "mpudata")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", cj.calibration.FitStatusWarning)
        acc, mag = cj.calibrate_accel(path), cj.calibrate_mag(path)
    [ea] = calibrate_files([path], progress=False)
    [em] = calibrate_files([path], sensor="mag", progress=False)
    assert ea["rms"] == pytest.approx(acc.rms_after, rel=1e-9)
    assert 100 * em["rms"] == pytest.approx(mag.rms_after_pct, rel=1e-3)


def test_a_log_read_but_with_too_few_poses_keeps_its_notes(tmp_path):
    """A log that loads but holds too few poses is a not_fitted entry whose message says why
    (the single fit's TooFewPoses) and whose notes say what the loader found (a new user's
    table showed NaN units and no notes for imucal's six-face session). It was labelled
    load_error, which a new user read as a file the loader could not read (a GGIR AX6 export
    read right, one pose); a file that cannot be read keeps that word."""
    t = np.arange(3000) / 100.0
    acc = np.tile([0.0, 0.0, 1.0], (3000, 1)) + 1e-3 * np.random.default_rng(0).normal(
        size=(3000, 3)
    )
    path = tmp_path / "one_pose.csv"
    np.savetxt(path, np.column_stack([t, acc]), delimiter=",")  # headerless: the loader notes
    unreadable = tmp_path / "words.csv"
    unreadable.write_text("no numbers here\njust words\n")
    gyro = tmp_path / "Gyroscope.csv"  # a phone app's other file: read, not an accelerometer
    gyro.write_text("time,x,y,z\n" + "".join(f"{k},0.1,0.2,0.3\n" for k in range(50)))
    e, u, g = calibrate_files([path, unreadable, gyro], progress=False)
    assert e["status"] == "not_fitted" and "distinct poses" in e["message"]
    assert any("headerless 4-column file read as t ax ay az" in n for n in e["notes"]), e
    assert u["status"] == "load_error" and "notes" not in u
    assert g["status"] == "not_fitted" and "names the gyroscope" in g["message"]


def test_batch_cli_bad_directory(tmp_path, capsys):
    assert main(["batch", str(tmp_path / "nope")]) == 2
    assert "nope: no such file or directory" in capsys.readouterr().err
    assert main(["batch", str(tmp_path), "--pattern", "*.xyz"]) == 2
    assert "no files matching '*.xyz'" in capsys.readouterr().err
    # a folder of Xsens MT Manager .txt exports (no log suffix): the refusal said only "set
    # --pattern"; it now says what the folder holds and the pattern that takes its logs
    for k in range(3):
        (tmp_path / f"MT_{k}.txt").write_text("PacketCounter\tAcc_X\tAcc_Y\tAcc_Z\n")
    (tmp_path / "NOTES.md").write_text("notes\n")
    assert main(["batch", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "it holds 4 file(s) (3 .txt, 1 .md): --pattern '*.txt' takes the .txt ones" in err
    # an ArduPilot .log beside its NOTES.md: the pattern offered was '*.md' (a new-user trial)
    other = tmp_path / "flight"
    other.mkdir()
    (other / "00000012.log").write_text("FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format\n")
    (other / "NOTES.md").write_text("notes\n")
    assert main(["batch", str(other)]) == 2
    err = capsys.readouterr().err
    assert "(1 .log, 1 .md): --pattern '*.log' takes the .log ones" in err
    # a phone recorder's folder: 14 .txt, its settings in 2 .properties (tyrex-team's), notes
    for k in range(3):
        (other / f"sensor{k}.txt").write_text("1 2 3 4\n")
    for k in range(4):
        (other / f"record{k}.properties").write_text("device=Nexus 5\n")
    assert main(["batch", str(other)]) == 2
    assert "--pattern '*.txt' takes the .txt ones" in capsys.readouterr().err
    for f in (*other.glob("*.txt"), *other.glob("*.properties")):
        f.unlink()
    (other / "00000012.log").unlink()
    assert main(["batch", str(other)]) == 2
    assert "none of them a log by its name; name the logs with --pattern" in capsys.readouterr().err


def test_batch_prints_the_warning_of_a_log_it_calibrated(tmp_path, capsys):
    """A TWLogger tag (MIT) whose x axis was hardly tilted: calib-jax accel warns, and batch
    printed only '1 of 1 calibrated' (the warning was in --json alone). Simulated here: 40
    poses whose gravity has an RMS x component of about 0.17 g."""
    rng = np.random.default_rng(1)
    d = rng.normal(size=(40, 3))
    d[:, 0] *= 0.15
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    log = simulate_accel(
        random_params(1), d, samples_per_pose=300, transition_samples=20, noise=2e-3, rng=1
    )
    np.savetxt(
        tmp_path / "tag.csv", np.column_stack([log.t, log.raw]), delimiter=",",
        header="t,ax,ay,az", comments="",
    )  # fmt: skip
    assert main(["batch", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "tag.csv: ok, 1 warning(s): gravity hardly varies along [+1.00" in out, out


def test_batch_of_magnetometer_logs_names_the_option_that_takes_them(tmp_path, capsys):
    """A folder of compass logs (bugplus/magnetic-tools, MIT: mag_x, mag_y, mag_z, pitch, roll)
    batched with the default sensor: each file said 'map them with --columns if they are there
    under other names', and nothing said --sensor mag."""
    d = np.random.default_rng(0).normal(size=(200, 3))
    for k in range(2):
        np.savetxt(
            tmp_path / f"calib_{k}_raw.csv",
            185 * d,
            delimiter=",",
            header="mag_x,mag_y,mag_z",
            comments="",
        )
    assert main(["batch", str(tmp_path)]) == 1
    out = capsys.readouterr().out
    assert "0 of 2 calibrated" in out
    note = "note: 2 file(s) are magnetometer logs (by their columns or their name): --sensor mag"
    assert note in out, out
    # a headerless 3-column file that its name calls the magnetometer (FreeIMU's magn.txt,
    # MapleHan/freeimu_gui, GPL-3) is one too
    for k in range(2):
        (tmp_path / f"calib_{k}_raw.csv").unlink()
    np.savetxt(tmp_path / "magn.txt", 185 * d, delimiter=" ")
    assert main(["batch", str(tmp_path), "--pattern", "*.txt"]) == 1
    assert "note: 1 file(s) are magnetometer logs" in capsys.readouterr().out


def test_dask_local_cluster_gives_the_same_results(fleet_dir, tmp_path, capsys):
    """A scheduler and two worker processes on the loopback, chunks of 3 files: the Python
    stream and ``calib-jax batch --dask ADDRESS`` give the in-process stream's results
    (parameters to 1e-12 relative), and the unreadable file is that file's entry."""
    pytest.importorskip("dask.distributed")
    from dask.distributed import LocalCluster

    d, _ = fleet_dir
    paths = sorted(str(p) for p in d.glob("imu*.csv"))
    local = list(calibrate_files(paths, chunk=3, progress=False))
    cluster = LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    )
    try:
        address = cluster.scheduler_address
        assert address.startswith("tcp://127.0.0.1:")
        stream = calibrate_files_dask(paths, scheduler=address, chunk=3, progress=True)
        assert not isinstance(stream, list)  # an iterator: results come back as chunks finish
        dist = sorted(stream, key=lambda r: r["path"])
        bar = capsys.readouterr().err  # the progress bar counted every file as chunks came back
        assert "calibrating accel" in bar and f"{len(paths)}/{len(paths)}" in bar, bar
        out = tmp_path / "fleet.json"
        argv = ["batch", str(d), "--dask", address, "--chunk", "3", "--json", str(out)]
        assert main(argv) == 1  # broken.csv
    finally:
        cluster.close()
    assert [r["path"] for r in dist] == paths
    cli = {e["path"]: e for e in cj.BatchRecord.load(out).entries}
    assert cli[str(d / "broken.csv")]["status"] == "load_error"
    for a, b in zip(local, dist, strict=True):
        np.testing.assert_allclose(a["params"], b["params"], rtol=1e-12)
        np.testing.assert_allclose(a["params"], cli[a["path"]]["params"], rtol=1e-12)
        assert a["status"] == b["status"] == cli[a["path"]]["status"] == "ok"


def test_a_fleet_fit_leaves_the_callers_jax_setting_alone(fleet_dir):
    """Issue 17: calibrate_files fits in float64 without switching jax_enable_x64 on for the
    caller (it used to set it globally). In a fresh process with x64 off: the flag is still off
    afterwards and the parameters are the float64 ones of this (x64) process to 1e-12."""
    import subprocess
    import sys

    d, _ = fleet_dir
    path = str(d / "imu0.csv")
    code = (
        "import json, jax; from calib_jax.fleet import calibrate_files; "
        f"[r] = calibrate_files([{path!r}], progress=False); "
        "print(json.dumps([jax.config.jax_enable_x64, r['params']]))"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    x64, params = json.loads(run.stdout.splitlines()[-1])
    assert x64 is False
    [here] = calibrate_files([path], progress=False)
    np.testing.assert_allclose(params, here["params"], rtol=1e-12)


def test_a_one_hemisphere_log_is_poorly_determined_in_the_batch_too(tmp_path):
    """pms67/Attitude-Estimation's hand-tilted MPU-6050 log: `calib-jax accel` said
    poorly_determined (z gain 1.51, every pose within 73 deg of +z) and `calib-jax batch`
    called the same parameters ok, with no warning. The batch entry now takes the single
    fit's rule (standard errors above 1 % of g) and its coverage warnings."""
    rng = np.random.default_rng(3)
    dirs = rng.normal(size=(400, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    dirs = dirs[dirs[:, 2] > np.cos(np.radians(45))][:14]  # a cap: no pose with z down
    log = simulate_accel(random_params(3), dirs, samples_per_pose=300, transition_samples=20,
                         noise=2e-3, rng=3)  # fmt: skip
    path = tmp_path / "cap.csv"
    np.savetxt(path, np.column_stack([log.t, log.raw]), delimiter=",", header="t,ax,ay,az",
               comments="")  # fmt: skip
    single = cj.calibrate_accel(cj.load_log(path))
    (entry,) = calibrate_files([str(path)], progress=False)
    assert single.status == "poorly_determined"
    assert entry["status"] == single.status, entry
    assert entry["poorly_determined"] == single.poorly_determined
    assert any("hemisphere" in w or "all poses lie" in w for w in entry["warnings"])


def test_a_poorly_determined_magnetometer_is_so_in_the_batch_too(tmp_path):
    """The single fit's poorly-determined rule (normalised standard error above 1 %) on a
    batch entry: `calib-jax batch --sensor mag` called 'ok' a phone's hand-held log whose full
    ellipsoid `calib-jax mag --model full` calls poorly determined (c_x). Here a 70-degree cap
    of directions: the single fit and the batch name the same parameters; a full tumble is ok
    in both."""
    rng = np.random.default_rng(1)
    paths, singles = [], []
    for cap in (70, 180):
        d = rng.normal(size=(3000, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        d = d[d[:, 2] >= np.cos(np.radians(cap))][:1500]
        x = 45 * d * [1.05, 0.97, 1.0] + [20, -10, 30] + 0.4 * rng.normal(size=d.shape)
        paths.append(tmp_path / f"cap{cap}.csv")
        np.savetxt(paths[-1], x, delimiter=",", header="mx,my,mz", comments="")
        singles.append(cj.calibrate_mag(x, model="full"))
    entries = list(calibrate_files(paths, sensor="mag", model="full", progress=False))
    assert [s.status for s in singles] == ["poorly_determined", "ok"]
    assert [e["status"] for e in entries] == ["poorly_determined", "ok"]
    assert entries[0]["poorly_determined"] == singles[0].poorly_determined == ["l_zz", "c_z"]
    assert "normalised std. error above 1 %" in entries[0]["message"]


def test_the_batch_counts_a_poorly_determined_fit_as_calibrated(tmp_path, capsys):
    """`calib-jax accel` exits 0 on a poorly determined fit (usable with care); `calib-jax
    batch` on the same log said '0 of 1 calibrated' and exited 1 (a new user's phone log).
    It now counts usable fits, says how many are poorly determined and why, and exits 0 when
    every file is usable."""
    rng = np.random.default_rng(1)
    d = rng.normal(size=(3000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d = d[d[:, 2] >= np.cos(np.radians(70))][:1500]
    x = 45 * d * [1.05, 0.97, 1.0] + [20, -10, 30] + 0.4 * rng.normal(size=d.shape)
    logs = tmp_path / "logs"
    logs.mkdir()
    np.savetxt(logs / "cap70.csv", x, delimiter=",", header="mx,my,mz", comments="")
    rc = main(["batch", str(logs), "--sensor", "mag", "--no-progress"])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "1 of 1 calibrated (1 poorly determined" in out
    assert "cap70.csv: poorly_determined: poorly determined" in out
