"""Issue 18: results as Jupyter shows them. Every result's ``_repr_html_`` is well-formed HTML
that holds its numbers (each parameter and standard error as the table prints them), its
status and its warnings (escaped); plain ``repr`` stays one short line; a batch result is a
table with one row per sensor whose numbers are the result's own."""

from html.parser import HTMLParser

import numpy as np
import pytest

import calib_jax as cj
from calib_jax.calibration import AccelCalibration
from calib_jax.models.layout import PARAM_NAMES

from .test_input_checks import _accel_cal, _mag_cal

VOID = {"br", "hr", "img", "meta", "input"}


class _Balance(HTMLParser):
    """Checks that every opened tag is closed, in order."""

    def __init__(self):
        super().__init__()
        self.stack: list[str] = []
        self.text: list[str] = []

    def handle_starttag(self, tag, attrs):
        if tag not in VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        assert self.stack and self.stack[-1] == tag, (tag, self.stack)
        self.stack.pop()

    def handle_data(self, data):
        self.text.append(data)


def _parsed_text(html: str) -> str:
    p = _Balance()
    p.feed(html)
    p.close()
    assert p.stack == [], p.stack
    return " ".join(p.text)


def test_accel_html_holds_the_table_status_and_escaped_warnings():
    cal = _accel_cal(warnings=["only 5 poses < 9 parameters"], notes=["read as g"])
    html = cal._repr_html_()
    text = _parsed_text(html)
    for i, name in enumerate(PARAM_NAMES):
        assert name in text
        assert f"{cal.params[i]:.6g}" in text and f"{cal.stderr[i]:.6g}" in text
    assert "ok" in text and "only 5 poses < 9 parameters" in text  # decoded from &lt;
    assert "&lt;" in html and "< 9" not in html
    assert "read as g" in text
    r = repr(cal)
    assert "\n" not in r and len(r) < 250 and "status='ok'" in r


def test_mag_and_marg_html():
    from calib_jax.marg import MARGRecord

    mag = _mag_cal(warnings=["coverage 40 %"])
    text = _parsed_text(mag._repr_html_())
    for v in (*mag.center, *mag.stderr_center, *mag.soft_iron.ravel(), *mag.semi_axes):
        assert f"{v:.6g}" in text
    assert "coverage 40 %" in text
    assert len(repr(mag)) < 250 and "\n" not in repr(mag)
    rec = MARGRecord(
        accel=_accel_cal(),
        accel_method="static",
        mag=mag,
        R_mag_to_acc=np.eye(3),
        permutation="x <- +x, y <- +y, z <- +z",
        permutation_matrix=np.eye(3),
        rotation_deg=0.5,
        dip_deg=60.0,
        dip_stderr_deg=0.1,
        dip_std_before_deg=2.0,
        dip_std_after_deg=0.3,
        n_used=900,
        n_total=1000,
        alignment_status="ok",
        alignment_message="converged",
        status="ok",
    )
    text = _parsed_text(rec._repr_html_())
    assert "AccelCalibration" in text and "MagCalibration" in text and "dip 60.00" in text
    short = repr(rec)  # one line with the numbers a user looks for first, not a field dump
    assert "\n" not in short and len(short) < 250 and "R_mag_to_acc" not in short
    assert "rotation 0.5 deg (x <- +x, y <- +y, z <- +z)" in short and "10 % -> 0.5 %" in short


def test_diagnosis_html_has_the_steps_and_the_candidates():
    from calib_jax.diagnose import Diagnosis

    steps = [
        {"added_effect": None, "n_params": 9, "rms": 2e-3, "loo_rms": 2.1e-3, "bic": -500.0},
        {"added_effect": "bias_drift", "n_params": 12, "rms": 5e-4, "loo_rms": 6e-4, "bic": -700.0},
    ]
    rounds = [
        [
            {"effect": "bias_drift", "accepted": True, "delta_bic": 200.0, "loo_gain": 0.7,
             "tests": {"bic": True, "loo": True}},
            {"effect": "temperature", "accepted": False, "delta_bic": 3.0, "loo_gain": 0.01,
             "tests": {"bic": False, "loo": False}},
        ]
    ]  # fmt: skip
    d = Diagnosis(
        sensor="accel", verdict="effects_added", steps=steps, effects=["bias_drift"],
        rms_before=2e-3, rms_after=5e-4, noise_floor=4e-4, noise_floor_white=4e-4,
        noise_floor_allan=4.5e-4, unexplained_structure=False, structure=[], notes=["n1"],
        rejected=[], rounds=rounds, groups={}, n_observations=40, observations="intervals",
        units="g", findings=["the magnetometer's axes are not the accelerometer's: x <- +y"],
    )  # fmt: skip
    text = _parsed_text(d._repr_html_())
    assert text.index("found:") < text.index("magnetometer's axes") < text.index("base 9")
    assert "bias_drift" in text and "base" in text and "effects_added" in text
    # each step's row: effect, parameters, rms and leave-one-out rms in mg, BIC
    assert "base 9 2 2.1 -500" in text and "bias_drift 12 0.5 0.6 -700" in text
    assert "temperature" in text and "bic, loo" in text  # the failed tests are named
    assert repr(d) == (
        "Diagnosis(sensor='accel', verdict='effects_added', effects=['bias_drift'], rms 2 -> "
        "0.5 mg (floor 0.4), 40 intervals, source=None)"
    )


def test_batch_result_rows_are_its_numbers(tmp_path):
    """BatchResult.rows / to_dataframe: one row per sensor, the parameters by name."""
    import jax.numpy as jnp

    from calib_jax.batch import BatchResult
    from calib_jax.lm import Status

    p = np.arange(18.0).reshape(2, 9) / 10 + 1
    r = BatchResult(
        params=jnp.asarray(p),
        stderr=jnp.full((2, 9), 1e-3),
        status=jnp.asarray([int(Status.CONVERGED_GRADIENT), int(Status.INSUFFICIENT_DATA)]),
        rms=jnp.asarray([1e-3, np.nan]),
        chi2=jnp.zeros(2),
        iterations=jnp.asarray([5, 0]),
        n_samples=jnp.asarray([400, 3]),
    )
    # the stacked pytree and the record (the failed sensor's NaN rms survives the JSON)
    np.testing.assert_array_equal(r.to_params().to_vector(), p)
    assert r.statuses == ["ok", "failed"]
    rec = r.to_record(names=["a.csv", "b.csv"])
    rec.save(tmp_path / "batch.json")
    assert cj.BatchRecord.load(tmp_path / "batch.json") == rec
    assert np.isnan(rec.entries[1]["rms"]) and rec.entries[0]["n_points"] == 400
    rows = r.rows(names=["a.csv", "b.csv"])
    assert [row["file"] for row in rows] == ["a.csv", "b.csv"]
    assert [row["status"] for row in rows] == ["ok", "failed"]
    assert [rows[0][n] for n in PARAM_NAMES] == p[0].tolist()
    text = _parsed_text(r._repr_html_())
    assert "1 of 2 sensors converged" in text
    assert repr(r) == "BatchResult(accel, 2 sensors: 1 ok, 1 failed)"
    assert repr(rec) == "BatchRecord(accel, 2 sensors: 1 ok, 1 failed)"
    # the record (what fleets and `calib-jax batch --json` give) shows its rows too; a long
    # message is cut to one line in the cell, the whole of it in the cell's hover text
    rec.entries[1]["message"] = "not fitted: " + "too few valid samples " * 5
    html = rec._repr_html_()
    text = _parsed_text(html)
    assert "1 of 2 entries usable" in text and "a.csv" in text and f"{p[0, 8]:.6g}" in text
    assert "too few valid samples " * 5 in html and "too few valid samples " * 5 not in text
    pd = pytest.importorskip("pandas")
    frame = r.to_dataframe()
    assert isinstance(frame, pd.DataFrame) and frame.shape[0] == 2
    np.testing.assert_array_equal(frame["beta_z"], p[:, 8])


def test_accel_repr_is_not_the_dataclass_dump():
    assert "covariance" not in repr(_accel_cal())
    assert AccelCalibration.__repr__ is not object.__repr__


def test_figures_mark_the_gaps_and_clip_nothing(tmp_path):
    """The coverage panel marks exactly the empty cells of the coverage measure; the histogram
    spans every error (an outlier at +40 % is inside its range, where the old 0.5-1.5 bins
    dropped it); the figure is written."""
    from calib_jax.plots import plot_accel, plot_mag
    from calib_jax.sphere import cell_hits

    rng = np.random.default_rng(3)
    d = rng.normal(size=(60, 3))
    d[:, 2] = np.abs(d[:, 2])  # upper hemisphere only: half the cells empty
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    cal = _accel_cal(static_means=d * 1.01 + 0.01)
    fig = plot_accel(cal, str(tmp_path / "a.png"))
    assert (tmp_path / "a.png").stat().st_size > 10_000
    after = cal.apply(cal.static_means)
    empty = int(np.sum(cell_hits(after / np.linalg.norm(after, axis=1, keepdims=True)) == 0))
    assert 30 < empty < 70
    gap_marks = [c for c in fig.axes[0].collections if c.get_label() == "empty cell"]
    assert len(gap_marks) == 1 and len(gap_marks[0].get_offsets()) == empty

    raw = rng.normal(size=(2000, 3))
    raw = raw / np.linalg.norm(raw, axis=1, keepdims=True) * 44.3
    raw[7] *= 1.4  # an outlier 40 % out
    mag = _mag_cal(center=np.zeros(3), soft_iron=np.eye(3), radius=44.3)
    fig = plot_mag(mag, raw)
    [hist] = [a for a in fig.axes if "histogram" in a.get_title()]
    edges = [p.get_x() for p in hist.patches] + [p.get_x() + p.get_width() for p in hist.patches]
    assert min(edges) <= 0.0 and max(edges) >= 39.0  # percent: the outlier is in range


def test_interactive_3d_view_shows_the_points_of_the_figures():
    """plotly's 3-D view (the 'interactive' extra) holds the same points as the matplotlib
    figure: the calibrated static means in g, coloured by their radial error in mg, the
    uncalibrated ones, the unit sphere and exactly the figure's empty cells; a magnetometer
    view asks for its raw samples and thins them to max_points; the figure writes to HTML."""
    pytest.importorskip("plotly")  # in the test extra; optional for users
    from calib_jax.plots import plot_accel, view_3d

    rng = np.random.default_rng(3)
    d = rng.normal(size=(60, 3))
    d[:, 2] = np.abs(d[:, 2])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    cal = _accel_cal(static_means=d * 1.01 + 0.01)
    fig = view_3d(cal)
    traces = {t.name: t for t in fig.data}
    assert set(traces) == {"unit sphere", "before", "after", "empty cell"}
    after = cal.apply(cal.static_means) / cal.g
    got = np.column_stack([traces["after"].x, traces["after"].y, traces["after"].z])
    np.testing.assert_allclose(got, after, rtol=1e-12)
    err_mg = (np.linalg.norm(after, axis=1) - 1.0) * 1e3
    np.testing.assert_allclose(traces["after"].marker.color, err_mg, rtol=1e-12)
    [gaps] = [c for c in plot_accel(cal).axes[0].collections if c.get_label() == "empty cell"]
    assert len(traces["empty cell"].x) == len(gaps.get_offsets()) > 20
    assert "plotly" in fig.to_html(include_plotlyjs=False)

    raw = rng.normal(size=(10_000, 3)) * 44.3
    mag = _mag_cal(center=np.zeros(3), soft_iron=np.eye(3), radius=44.3)
    with pytest.raises(ValueError, match="raw samples"):
        view_3d(mag)
    fig = view_3d(mag, raw, max_points=1000)
    assert len(fig.data[2].x) == 1000 and fig.data[2].name == "after"


def test_gyro_html_holds_c_b_the_miss_and_the_candidates():
    from calib_jax.simulate import simulate_gyro_log

    sim = simulate_gyro_log(5, n_poses=12)
    cal = cj.calibrate_gyro(sim.acc, sim.gyro, t=sim.t)
    text = _parsed_text(cal._repr_html_())
    for v in (*cal.matrix.ravel(), *cal.stderr_matrix.ravel(), *cal.bias, *cal.stderr_bias):
        assert f"{v:.6g}" in text
    assert f"{cal.rms_after_deg:.3g}" in text and f"{cal.noise_floor_deg:.3g}" in text
    assert all(name in text for name in cal.effects) and "not found" in text
    assert "GyroCalibration" in text and cal.status in text
    assert len(repr(cal)) < 250 and "\n" not in repr(cal)
