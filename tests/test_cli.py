"""The command line, run in-process (same code path as the console script)."""

import json

import numpy as np

from calib_jax.cli import demo_log_path, main

from .conftest import shared_file


def test_accel_writes_the_documented_json(tmp_path, capsys):
    out = tmp_path / "cal.json"
    png = tmp_path / "cal.png"
    rc = main(
        [
            "accel",
            str(demo_log_path()),
            "--g",
            "9.81744",
            "--out-units",
            "m/s^2",
            "--json",
            str(out),
            "--plot",
            str(png),
        ]
    )
    assert rc == 0
    text = capsys.readouterr().out
    assert "alpha_x" in text and "beta_z" in text and "std. error" in text and "before" in text
    d = json.loads(out.read_text())
    for key in (
        "params",
        "stderr",
        "status",
        "iterations",
        "n_intervals",
        "units",
        "rms_before",
        "rms_after",
        "noise_floor",
    ):
        assert key in d, key
    assert set(d["params"]) == {"gains", "nonorth", "bias"}
    assert all(len(v) == 3 for v in d["params"].values())
    assert d["status"] == "ok" and d["units"]["input"] == "counts"
    assert d["rms_before"] / d["rms_after"] > 10
    assert png.stat().st_size > 10_000


def test_accel_solver_choice(tmp_path):
    out = tmp_path / "cal.json"
    assert main(["accel", str(demo_log_path()), "--solver", "lm3", "--json", str(out)]) == 0
    d = json.loads(out.read_text())
    assert d["solver"] == "lm3" and d["units"]["output"] == "g"
    np.testing.assert_allclose(d["units"]["g"], 1.0)


def test_bad_input_exits_2_with_the_fix(tmp_path, capsys):
    bad = tmp_path / "seven.txt"
    bad.write_text("\n".join(" ".join(["1"] * 7) for _ in range(10)))
    assert main(["accel", str(bad)]) == 2
    assert "--columns" in capsys.readouterr().err
    ferraris = shared_file("imucal_ferraris/example_ferraris_session.csv")
    assert main(["accel", str(ferraris), "--sample-rate", "102.4"]) == 2
    assert "accel6" in capsys.readouterr().err
    assert main(["accel", str(ferraris), "--sample-rate", "102.4", "--model", "accel6"]) == 0


def test_headerless_with_column_mapping(tmp_path):
    # imu_tk-style headerless text with columns in another order
    x = np.loadtxt(demo_log_path())[:, [0, 3, 2, 1]]  # t, az, ay, ax
    path = tmp_path / "swapped.txt"
    np.savetxt(path, x)
    out = tmp_path / "cal.json"
    assert main(["accel", str(path), "--columns", "t,az,ay,ax", "--json", str(out)]) == 0
    ref = tmp_path / "ref.json"
    assert main(["accel", str(demo_log_path()), "--json", str(ref)]) == 0
    a, b = json.loads(out.read_text()), json.loads(ref.read_text())
    np.testing.assert_allclose(a["params"]["bias"], b["params"]["bias"], rtol=1e-9)


def test_demo(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path)]) == 0
    assert "imu_tk" in capsys.readouterr().out
    assert (tmp_path / "demo_accel.png").exists()
    assert json.loads((tmp_path / "demo_calibration.json").read_text())["status"] == "ok"
