"""The command line, run in-process (same code path as the console script)."""

import json

import numpy as np
import pytest

import calib_jax as cj
from calib_jax.cli import demo_log_path, main
from calib_jax.datasets import mag_demo_log_path

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
    # 8 headerless columns: no usual layout has that width (7 is read as t + accel + gyro)
    bad = tmp_path / "eight.txt"
    bad.write_text("\n".join(" ".join(["1"] * 8) for _ in range(10)))
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


def test_mag_writes_the_documented_json(tmp_path, capsys):
    """The issue's JSON contract on the shipped CK-Explorer tumble."""
    out, png = tmp_path / "mag.json", tmp_path / "mag.png"
    rc = main(["mag", str(mag_demo_log_path()), "--json", str(out), "--plot", str(png)])
    assert rc == 0
    d = json.loads(out.read_text())
    assert len(d["center"]) == 3 and np.array(d["soft_iron"]).shape == (3, 3)
    assert d["model"] in ("sphere", "diag", "full") and d["status"] == "ok"
    assert d["radius"] > 0
    # measured: 15.5 % before (centred on the data mean), 1.26 % after
    assert d["rms_after_pct"] < 2.0 < 10.0 < d["rms_before_pct"]
    W = np.array(d["soft_iron"])
    raw = cj.load_log(mag_demo_log_path()).mag
    after = np.linalg.norm((raw - d["center"]) @ W.T, axis=1) / d["radius"] - 1
    assert 100 * np.sqrt(np.mean(after**2)) == pytest.approx(d["rms_after_pct"], rel=1e-9)
    assert png.stat().st_size > 10_000
    assert "soft iron" in capsys.readouterr().out


def test_mag_model_choice_and_bad_input(tmp_path, capsys):
    assert main(["mag", str(mag_demo_log_path()), "--model", "sphere"]) == 0
    assert "model sphere" in capsys.readouterr().out
    f = tmp_path / "acc_only.csv"
    f.write_text("ax,ay,az\n" + "\n".join("0,0,1" for _ in range(50)))
    assert main(["mag", str(f)]) == 2
    assert "no mag columns" in capsys.readouterr().err
