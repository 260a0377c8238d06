"""Magnetometer, alignment and attitude on real logs (each folder's NOTES.md says what it is)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import calib_jax as cj
from calib_jax.cli import main
from calib_jax.lm import lm_solve
from calib_jax.models.mag import natural_radius, unpack
from calib_jax.rotations import heading_inclination_error_deg

from .conftest import shared_file

herr = jax.jit(jax.vmap(heading_inclination_error_deg))


def heading_incl(q_est, q_ref):
    ok = np.all(np.isfinite(q_ref), axis=1)
    return np.asarray(herr(jnp.asarray(q_est)[ok], jnp.asarray(q_ref[ok])))


# ---------------------------------------------------------------------------------------------
# QMC5883L against its published calibration


@pytest.fixture(scope="module")
def qmc_reference():
    ref = np.loadtxt(
        shared_file("tomisuarez_qmc5883l_mag/reference/paramters_mag.csv"), delimiter=","
    ).ravel()
    return ref[:9].reshape(3, 3), ref[9:]


@pytest.fixture(scope="module")
def qmc_noisy():
    return cj.load_log(shared_file("tomisuarez_qmc5883l_mag/noisy_raw_data.csv"))


def test_qmc_matches_published_calibration(qmc_noisy, qmc_reference):
    """Same data as the authors' fit (Dorveaux, m_cal = A m + B): the same RMS radial error
    (6.19 % both; ours is the minimum of a slightly different cost, so within 1 %), the same
    centre within 1 % of the radius (measured 0.5 %), and the same shape within 5 % (measured
    2.3 %, after removing the rotation A leaves free: compare A'A)."""
    A, B = qmc_reference
    cal = cj.calibrate_mag(qmc_noisy, model="auto")
    assert cal.status == "ok" and cal.model == "full", cal.report()
    assert cal.n_samples == 22743 and cal.rms_before_pct > 25  # NOTES.md: |m| +- 9 % raw
    # issue 14: the model table's RMS is the RMS after of the chosen model (was 2.633 vs 2.804)
    assert cal.model_selection["full"]["rms_pct"] == pytest.approx(cal.rms_after_pct, rel=1e-9)
    y = qmc_noisy.mag @ A.T + B
    n = np.linalg.norm(y, axis=1)
    ref_rms = 100 * np.sqrt(np.mean((n / n.mean() - 1) ** 2))
    assert ref_rms == pytest.approx(6.2, abs=0.1)  # NOTES.md: 0.996 +- 6.2 %
    assert cal.rms_after_pct == pytest.approx(ref_rms, rel=0.01)
    assert cal.rms_after_pct <= ref_rms + 1e-3
    c_ref = -np.linalg.solve(A, B)
    assert np.all(np.abs(cal.center - c_ref) < 0.01 * cal.radius)
    Wn = cal.soft_iron / cal.radius
    Mo, Mr = Wn @ Wn, A.T @ A
    Mo, Mr = Mo / np.linalg.det(Mo) ** (1 / 3), Mr / np.linalg.det(Mr) ** (1 / 3)
    assert np.abs(Mo - Mr).max() < 0.05
    # NOTES.md: radii 749 / 1029 / 1626 counts from an algebraic fit
    np.testing.assert_allclose(np.sort(cal.semi_axes), [749, 1029, 1626], rtol=0.05)


def test_qmc_sphere_needs_the_scaled_residual(qmc_noisy):
    """On this strongly anisotropic sensor a sphere with the plain quadric residual q - 1 runs
    away to a huge radius (a sphere far away fits a cap with a small relative error); the
    radius-scaled residual keeps it at the data's size."""
    cal = cj.calibrate_mag(qmc_noisy, model="sphere")
    # converged, but a sphere leaves 17.7 % where the full ellipsoid leaves 6.2 % (issue 13:
    # not "ok"; the warning says to use the full model)
    assert cal.status == "poorly_determined" and cal.solver_status in (0, 1, 2, 8)
    assert any("model='full'" in w for w in cal.warnings), cal.warnings
    assert 800 < cal.radius < 1600  # semi-axes 749..1626 counts
    x = qmc_noisy.mag
    xn = (x - x.mean(0)) / np.sqrt(np.mean(np.sum((x - x.mean(0)) ** 2, 1)))

    def unscaled(p, data):
        c, M = unpack(p, "sphere")
        d = data - c
        return jnp.einsum("ni,ij,nj->n", d, M, d) - 1.0

    res = lm_solve(unscaled, jnp.zeros(4), jnp.asarray(xn), max_iter=200)
    _, M = unpack(res.params, "sphere")
    assert float(natural_radius(M)) > 20  # in units of the data's RMS radius


def test_qmc_cli_json(tmp_path, capsys):
    path = shared_file("tomisuarez_qmc5883l_mag/filtered_raw_data.csv")
    out = tmp_path / "m.json"
    assert main(["mag", str(path), "--json", str(out), "--model", "full"]) == 0
    import json

    d = json.loads(out.read_text())
    assert d["model"] == "full" and d["status"] == "ok"
    assert np.array(d["soft_iron"]).shape == (3, 3)
    assert d["rms_after_pct"] < 3.0 < 25.0 < d["rms_before_pct"]  # measured 2.80 / 29.3


# ---------------------------------------------------------------------------------------------
# CK-Explorer accelerometer + magnetometer tumble (shipped with the package)


@pytest.fixture(scope="module")
def ck():
    return cj.load_log(cj.mag_demo_log_path())


@pytest.fixture(scope="module")
def ck_cal(ck):
    return cj.calibrate_mag(ck)


def test_ck_magnetometer(ck_cal):
    """NOTES.md's independent ellipsoid fit: centre (0.148, 0.390, -0.059), radii 0.298 /
    0.303 / 0.325, residual 1.27 %."""
    cal = ck_cal
    assert cal.status == "ok" and cal.model == "full"
    np.testing.assert_allclose(cal.center, [0.148, 0.390, -0.059], atol=2e-3)
    np.testing.assert_allclose(np.sort(cal.semi_axes), [0.298, 0.303, 0.325], atol=3e-3)
    assert cal.rms_after_pct == pytest.approx(1.27, abs=0.05)
    assert cal.model_selection["full"]["bic"] < cal.model_selection["diag"]["bic"]


def test_ck_accel_mag_angle(ck, ck_cal):
    """NOTES.md: angle between accelerometer and corrected magnetometer 72.1 +- 2.9 deg, so
    |dip| about 18 deg. The rotation fit narrows the spread only a little (2.49 -> 2.43 deg
    measured on the 81 % of samples within 5 % of the median norms): the spread is mostly the
    gentle tumble's linear acceleration and noise, not misalignment. The estimated rotation
    (about 1 deg) is small and determined to better than 0.1 deg."""
    al = cj.align_mag_to_accel(ck.acc, ck_cal.apply(ck.mag))
    assert al.status == "ok"
    assert al.permutation_text == "x <- +x, y <- +y, z <- +z"
    assert al.dip_deg == pytest.approx(-17.9, abs=0.5)
    assert al.spread_after_deg <= al.spread_before_deg
    assert al.rotation_deg < 3.0
    assert np.all(al.rotvec_stderr_deg < 0.1)


# ---------------------------------------------------------------------------------------------
# BROAD: attitude against optical ground truth


def test_broad_excerpt_attitude_against_optical_truth():
    """Gauss-Newton attitude from the shipped excerpt of trial 02 (manufacturer-calibrated):
    median heading error 3.0 deg and inclination error 1.2 deg measured against the optical
    truth (slow rotations; the accelerometer sees some motion). Limits: 4 and 2 deg."""
    d = cj.load_broad_excerpt()
    att = cj.estimate_attitude(d["acc"], d["mag"])
    assert float(att.dip_deg) == pytest.approx(69.5, abs=1.0)  # NOTES.md: dip about 69 deg
    e = heading_incl(att.quat, d["quat"])
    assert np.median(e[:, 0]) < 4.0
    assert np.median(e[:, 1]) < 2.0


@pytest.fixture(scope="module")
def broad34():
    pytest.importorskip("h5py")
    from calib_jax.io.broad import load_broad

    return load_broad(shared_file("broad_myon/34_disturbed_attached_magnet_3cm.hdf5"))


def test_broad_magnet_hard_iron_held_out(broad34):
    """Trial 34, magnet attached 40-100 s: fit the ellipsoid on alternate 5 s blocks, judge the
    heading on the others. Measured: median heading error 23.7 deg raw -> 13.6 deg calibrated
    (full model). The disturbance is not a clean ellipsoid (NOTES.md), so much stays
    unexplained; the test asserts the calibration at least removes a quarter of it."""
    seg = broad34.segment(40, 100)
    blk = (np.arange(len(seg.acc)) // int(5 * seg.sample_rate)) % 2 == 0
    cal = cj.calibrate_mag(seg.mag[blk], field=44.3)
    assert cal.success
    assert cal.center[2] > 5.0  # NOTES.md: the centre moves to about (-1.8, 0.3, 19) uT
    test = ~blk
    dip = 68.7  # from the undisturbed first 38 s
    raw = cj.estimate_attitude(seg.acc[test], seg.mag[test], dip_deg=dip)
    fixed = cj.estimate_attitude(seg.acc[test], cal.apply(seg.mag[test]), dip_deg=dip)
    e_raw = np.median(heading_incl(raw.quat, seg.quat[test])[:, 0])
    e_cal = np.median(heading_incl(fixed.quat, seg.quat[test])[:, 0])
    assert e_cal < 0.75 * e_raw


def test_magnetometer_one_answer_on_every_path(ck, tmp_path, capsys):
    """Issue 14: the CK-Explorer magnetometer through ``calib-jax mag``, ``calib-jax batch
    --sensor mag``, :func:`calib_jax.calibrate_mag`, the batch and the JAX pipeline's
    ``fit_mag`` gives the same centre, soft-iron matrix and standard errors: one core
    (``fit_ellipsoid_normalized``) and one map to raw units (``raw_calibration``) on every path.
    The paths differ only in round-off: each normalises the samples with its own sums (numpy,
    jnp with weights, moments) and the solver's round-off stop accepts any point on the
    round-off plateau of chi2 (see test_pipeline's padding test), so they agree to 1e-7 of a
    standard error (measured: the CLI 0, the pipeline 5e-9, the batch 4e-12 on this log and
    1e-13 to 4e-12 on simulated ones) and the standard errors to 1e-5 relative. The diagnosis
    refits its own base model (``diagnose_mag``: the radial residual on every k-th sample, to
    compose with its effects), so it is not one of them."""
    import json
    import shutil

    from jax.flatten_util import ravel_pytree

    from calib_jax import pipeline as pl

    field = 0.31  # about the log's field in its unit (NOTES.md: gauss)
    cal = cj.calibrate_mag(ck, model="full", field=field)
    se = np.concatenate([cal.stderr_center, cal.stderr_soft_iron.ravel()])
    ref = np.concatenate([cal.center, cal.soft_iron.ravel()])

    def close(p, s, tol_se, tol_rel, name):
        z = np.abs(np.asarray(p) - ref) / se
        assert z.max() <= tol_se, (name, z)
        np.testing.assert_allclose(np.asarray(s), se, rtol=tol_rel, err_msg=name)

    mp = cal.to_params()  # the record as the pipeline's pytree
    close(ravel_pytree(mp)[0], se, 0, 0, "MagCalibration.to_params")
    f = pl.fit_mag(jnp.asarray(ck.mag), field)
    close(ravel_pytree(f.params)[0], f.stderr, 1e-7, 1e-5, "pipeline.fit_mag")
    b = cj.calibrate_mag_batch(ck.mag[None], field=field)
    close(b.params[0], b.stderr[0], 1e-7, 1e-5, "calibrate_mag_batch")

    src = cj.mag_demo_log_path()
    d = tmp_path / "logs"
    d.mkdir()
    shutil.copy(src, d / src.name)
    out = tmp_path / "one.json"
    assert (
        main(["mag", str(src), "--model", "full", "--field", str(field), "--json", str(out)]) == 0
    )
    argv = ["batch", str(d), "--sensor", "mag", "--model", "full", "--field", str(field)]
    assert main([*argv, "--pattern", "*" + src.suffix, "--json", str(tmp_path / "b.json")]) == 0
    capsys.readouterr()
    one = cj.MagCalibration.load(out)
    close(
        np.concatenate([one.center, one.soft_iron.ravel()]),
        np.concatenate([one.stderr_center, one.stderr_soft_iron.ravel()]),
        1e-7,
        1e-5,
        "calib-jax mag",
    )
    [r] = json.loads((tmp_path / "b.json").read_text())["results"]
    assert r["status"] == "ok"
    close(r["params"], r["stderr"], 1e-7, 1e-5, "calib-jax batch --sensor mag")
    for form in ("forward", "correction"):  # both linear forms, as every calibration JSON
        np.testing.assert_allclose(r[form]["matrix"], one.to_dict()[form]["matrix"], rtol=1e-6)
        np.testing.assert_allclose(r[form]["offset"], one.to_dict()[form]["offset"], rtol=1e-6)


def test_soft_iron_standard_errors_do_not_follow_the_unit(ck):
    """Issue 14 defect: the same log in another unit (x 1000, mG for G) has the same W
    (det W = 1 without a field) and must have the same standard errors of W; those of the
    centre scale with the unit. Before, the W errors were multiplied by the raw radius."""
    a = cj.calibrate_mag(ck.mag, model="full")
    b = cj.calibrate_mag(1000.0 * ck.mag, model="full")
    np.testing.assert_allclose(b.soft_iron, a.soft_iron, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(b.stderr_soft_iron, a.stderr_soft_iron, rtol=1e-6)
    np.testing.assert_allclose(b.stderr_center, 1000.0 * a.stderr_center, rtol=1e-6)
    assert np.all(a.stderr_soft_iron < 0.05)  # dimensionless W ~ 1, well determined


def test_no_determined_model_keeps_the_sphere():
    """scikit-kinematics' YEI 3-Space log (tests/data/skinematics, BSD-3): a hand-held record
    covering about a third of the sphere, where no model's parameters are pinned down. The
    lowest BIC was then taken anyway: a diagonal soft iron with semi-axes 0.463, 0.392 and
    0.156 gauss for a 0.53-gauss field (one axis 3x shorter, no magnetometer's soft iron),
    saved with exit 0. Now the sphere is kept and the warning names the model the BIC
    preferred; a declared model is still fitted as asked."""
    from pathlib import Path

    path = Path(__file__).parent / "data" / "skinematics" / "data_yei.txt"
    cal = cj.calibrate_mag(path)
    sel = cal.model_selection
    assert not any(v["well_determined"] for v in sel.values()), sel
    assert sel["diag"]["bic"] < sel["sphere"]["bic"]  # what the BIC alone would choose
    assert cal.model == "sphere" and cal.status == "poorly_determined"
    assert any(
        "the sphere (hard iron only) is kept; diag had the lowest BIC" in w for w in cal.warnings
    )
    assert cj.calibrate_mag(path, model="diag").model == "diag"
