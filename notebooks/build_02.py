"""Build notebooks/02_magnetometer_marg.ipynb (paper 2) and execute it once, outputs saved.

Run from anywhere: ``.venv/bin/python notebooks/build_02.py``. The notebook is executed in a
temporary directory (as the test suite does), so it must not read or write relative paths
other than its own figure.
"""

from __future__ import annotations

from pathlib import Path

from _nbbuild import recorder, run

OUT = Path(__file__).resolve().parent / "02_magnetometer_marg.ipynb"

cells: list[tuple[str, str]] = []
md, code = recorder(cells)


# ---------------------------------------------------------------------------------------------
md(
    """
# Paper 2: MARG calibration: ellipsoid compensation, sensor-plane alignment, attitude

This notebook walks through paper 2 in `shared/papers/` (calibration, sensor-plane alignment
and distortion compensation of a low-cost MARG board for 3D scanning) with calib_jax. The paper
has two routines and one test:

- **Calibration and compensation** (section 2.2, Fig. 2): tumble the board through all
  orientations; the readings of each sensor lie on an ellipsoid. Fit it (eq. 4), write it in
  matrix form (eq. 6-8), move its centre to the origin and reduce it to canonical form
  (eq. 9-15), and read the axes (the DCM, eigenvectors) and semi-axes (eigenvalues) off an
  eigen-analysis (eq. 16-20). Compensation rotates each sample into the ellipsoid's axes,
  rescales each axis onto a sphere and rotates back.
- **Sensor-plane alignment** (section 2.1, Fig. 1): turn the board about its z axis with its
  XY plane held on a fixed plane; each sensor's vector tip draws a circle. The plane of the
  circle (eq. 1), its normal (eq. 2) and two rotations (eq. 3) align each sensor to the board.
- **Evaluation** (section 3): a Gauss-Newton quaternion attitude from accelerometer and
  magnetometer, on a turn on an *inclined* plane: roll and pitch should stay at 0 (Fig. 9),
  and the mean Gauss-Newton cost F(x) measures how consistent the two sensors are (Table 1,
  Fig. 10).

What calib_jax adds: the algebraic fit is ellipsoid-specific (Li-Griffiths, never a
hyperboloid) and is only the start of a Levenberg-Marquardt refinement of the quadric residual;
the model (sphere = hard iron only, axis-aligned, full ellipsoid) is chosen by BIC; standard
errors and a status say when the recording does not determine the fit; and a rotation from the
magnetometer to the accelerometer frame is estimated from the constant angle between gravity
and the field. Sections 1-5 use simulated data with known truth and the real CK-Explorer
tumble; section 6 compares against BROAD's optical ground truth. It runs in the test suite.
"""
)
code(
    """
import jax

from calib_jax.runtime import configure

configure()  # float64, and compiled fits kept on disk for the next kernel (runtime.py)
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Image, Markdown, display

import calib_jax as cj
from calib_jax import geometry as geo
from calib_jax import simulate as sim
from calib_jax.marg import evaluation_table
from calib_jax.rotations import heading_inclination_error_deg, rotation_angle_deg
"""
)

# ---------------------------------------------------------------------------------------------
md(
    """
## 1. Paper 2's ellipsoid algebra, step by step

A simulated magnetometer with a known hard iron c and soft iron W: raw = W^-1 y + c, with y
the 45 uT field seen in 3000 random orientations, plus 0.2 uT of noise. calibrate_mag fits
normalised data (centred on the mean, unit RMS radius) so that the algebra works with numbers
of order one; we do the same.
"""
)
code(
    """
rng = np.random.default_rng(2)
c_true, W_true = sim.random_ellipsoid(rng, radius=45.0, center_spread=0.8)
y = sim.random_directions(3000, rng) * 45.0  # the field in the sensor frame, uT
raw = y @ np.linalg.inv(W_true).T + c_true + rng.normal(scale=0.2, size=y.shape)
mean = raw.mean(axis=0)
s = np.sqrt(np.mean(np.sum((raw - mean) ** 2, axis=1)))
xn = jnp.asarray((raw - mean) / s)
print("true centre (uT):   ", c_true.round(3))
print("true semi-axes (uT):", np.sort(45.0 / np.linalg.eigvalsh(W_true))[::-1].round(3))
"""
)
md(
    """
**Find the ellipsoid** (Fig. 2, eq. 4). An unconstrained algebraic fit of the ten
coefficients can return a hyperboloid when the orientations cover little of the sphere; the
Li-Griffiths constraint 4J - I^2 = 1 admits only ellipsoids. The result in the **matrix form**
of eq. 6-8, X S X' = 0 with X = [x, y, z, 1]:
"""
)
code(
    """
c_n, M_n, ok = geo.ellipsoid_fit_constrained(xn, jnp.ones(len(xn)))
print("an ellipsoid:", bool(ok))
S = geo.quadric_matrix(c_n, M_n)  # eq. 8
print("S =\\n", np.asarray(S).round(5))
X = np.column_stack([np.asarray(xn), np.ones(len(xn))])
print("RMS of X S X' over the data:", np.sqrt(np.mean(np.einsum("ni,ij,nj->n", X, S, X) ** 2)))
"""
)
md(
    """
**Centre, canonical form, eigen-analysis** (eq. 9-20). The centre is where the gradient of
X S X' vanishes (eq. 9); the translation T (eq. 10-11) removes the linear terms, and dividing
by the constant term gives the canonical form x' A x = 1 (eq. 12-15). A = R D R' (eq. 16):
the eigenvectors, as columns, make the DCM R (eq. 18), and the semi-axes are 1/sqrt(D)
(eq. 19-20). Back in microtesla: centre = mean + s * centre_n, semi-axes times s.
"""
)
code(
    """
centre_n, A, R, axes_n = geo.ellipsoid_from_quadric(S)
A, R = np.asarray(A), np.asarray(R)
print("A (eq. 13) =\\n", A.round(5))
print("R' A R = D (eq. 16) =\\n", (R.T @ A @ R).round(6))
print("DCM R (eq. 18) =\\n", R.round(4), "\\ndet R =", round(float(np.linalg.det(R)), 6))
centre = mean + s * np.asarray(centre_n)
semi_axes = s * np.asarray(axes_n)
print("centre (uT):   ", centre.round(3))
print("semi-axes (uT):", semi_axes.round(3))
"""
)
md(
    """
**Compensate** (Fig. 2, step 4): rotate each centred sample into the ellipsoid's axes (R'),
scale each axis by radius / semi-axis, and restore the orientation with the inverse DCM (R).
As one matrix, W = R diag(r / semi-axes) R'. calibrate_mag starts from the same algebraic fit
and refines it by Levenberg-Marquardt:
"""
)
code(
    """
W_alg = np.asarray(geo.compensation_matrix(jnp.asarray(R), jnp.asarray(semi_axes), 45.0))
r_alg = np.linalg.norm((raw - centre) @ W_alg.T, axis=1)
print(f"|y| after the algebraic compensation: {r_alg.mean():.3f} +- {r_alg.std():.3f} uT")
cal_sim = cj.calibrate_mag(raw, model="full", field=45.0, units="uT")
print(cal_sim.report())
"""
)
code(
    """
print("algebra vs LM, max |difference|:")
print(f"  centre {np.abs(centre - cal_sim.center).max():.2e} uT")
print(f"  W      {np.abs(W_alg - cal_sim.soft_iron).max():.2e}")
print("against the truth, max |error|:   algebra     LM")
print(
    f"  centre (uT)                 {np.abs(centre - c_true).max():.2e}  "
    f"{np.abs(cal_sim.center - c_true).max():.2e}"
)
print(
    f"  W                           {np.abs(W_alg - W_true).max():.2e}  "
    f"{np.abs(cal_sim.soft_iron - W_true).max():.2e}"
)
"""
)
md(
    """
On a well-covered, low-noise recording the LM refinement hardly moves the algebraic answer,
and both are as close to the truth as the noise allows. The refinement is there for noisier or
partial data, where the algebraic residual is not the error one cares about; it also gives the
standard errors in the report.

## 2. A real magnetometer: the CK-Explorer tumble

12,000 samples of a gentle hand tumble (CK-Explorer, Apache-2.0): the accelerometer in g and
already calibrated, the magnetometer raw (unit not stated, probably gauss) with a large hard
iron. `model="auto"` fits the sphere, the axis-aligned and the full ellipsoid and keeps the
lowest BIC.
"""
)
code(
    """
log = cj.load_log(cj.mag_demo_log_path())
cal = cj.calibrate_mag(log)  # model="auto"
print(cal.report())
"""
)
md(
    """
Paper 2's Fig. 8: the raw samples (centred on their mean and scaled, blue) and the compensated
ones (red) against the unit sphere, and the histogram of |m| / radius. The figure is written to
the working directory and shown from there:
"""
)
code(
    """
from calib_jax.plots import plot_mag

plot_mag(cal, log.mag, "02_ck_mag.png")
Image("02_ck_mag.png")
"""
)
md(
    """
The full ellipsoid wins clearly (its semi-axes differ by several percent: real soft iron, or
unequal axis gains), and the radial error drops from about 15 % to about 1.3 %. What is left
is noise and whatever the model does not describe; the log has no static part from which to
tell the two apart.

## 3. The same ellipsoid on an accelerometer

Paper 2 compensates every sensor with its own ellipsoid. The CK-Explorer accelerometer was
calibrated before it was logged, so the honest expectation is an ellipsoid close to the unit
sphere: W close to the identity and a small centre.
"""
)
code(
    """
acal = cj.calibrate_mag(log, sensor="accel", field=1.0, units="g")
print(acal.report())
acal_full = cj.calibrate_mag(log, sensor="accel", field=1.0, model="full")
print(
    f"\\nfull model: max |W - I| = {np.abs(acal_full.soft_iron - np.eye(3)).max():.4f}, "
    f"|centre| = {1000 * np.linalg.norm(acal_full.center):.1f} mg"
)
na = np.linalg.norm(log.acc, axis=1)
print(f"|a| over the log: {na.mean():.4f} g +- {100 * na.std() / na.mean():.1f} %")
"""
)
md(
    """
BIC keeps the sphere: the data give no evidence for unequal gains or cross-axis terms, and the
centre is a few mg. The 4 % residual is the motion: the tumble was done by hand while logging,
so the accelerometer also sees the hand's accelerations. They also lengthen |a| on average,
which most likely explains the common factor in W (a fitted radius about 0.5 % above 1 g),
though a gain error of that size common to all axes cannot be told apart from it here. This
recording confirms that the accelerometer was calibrated; it cannot calibrate one at the
sub-percent level. For that, use static poses (paper 1, notebook 01).

## 4. Accelerometer-magnetometer rotation on the CK-Explorer log

Not in paper 2: for a static sensor the angle between gravity and the field is constant, so
the rotation R (magnetometer -> accelerometer frame) should make angle(a, R m) the same in every
sample. calib_jax first scores the 48 signed axis permutations, then refines R and the angle by
LM; the dip is the angle minus 90 degrees. Samples whose |a| or |m| is more than 5 % from
its median are left out (the sensor was moving).
"""
)
code(
    """
al = cj.align_mag_to_accel(log.acc, cal.apply(log.mag))
print(f"samples used: {al.n_used} of {al.n_total}; status {al.status}")
print("axis permutation:", al.permutation_text)
print(
    f"gravity-field angle {90 + al.dip_deg:.2f} deg: dip {al.dip_deg:+.2f} "
    f"+- {al.dip_stderr_deg:.2f} deg"
)
print(
    f"rotation mag -> acc: {al.rotation_deg:.2f} deg "
    f"(std. errors {al.rotvec_stderr_deg.round(3)} deg)"
)
print(
    f"spread (std) of the angle: {al.spread_before_deg:.2f} deg with R = I, "
    f"{al.spread_after_deg:.2f} deg with R"
)
"""
)
md(
    """
Is that rotation a property of the board or of this recording? Fit it on each half of the log
separately, and once more on the quietest samples only (|a| and |m| within 1 %):
"""
)
code(
    """
h = len(log.acc) // 2
mag_cal = cal.apply(log.mag)
al1 = cj.align_mag_to_accel(log.acc[:h], mag_cal[:h])
al2 = cj.align_mag_to_accel(log.acc[h:], mag_cal[h:])
between = rotation_angle_deg(al1.R_acc_from_mag.T @ al2.R_acc_from_mag)
print(
    f"halves: rotation {al1.rotation_deg:.2f} and {al2.rotation_deg:.2f} deg, "
    f"{between:.2f} deg apart; dip {al1.dip_deg:+.2f} and {al2.dip_deg:+.2f} deg"
)
al_q = cj.align_mag_to_accel(log.acc, mag_cal, static_tol=0.01)
print(
    f"quietest {al_q.n_used} samples: spread {al_q.spread_before_deg:.2f} -> "
    f"{al_q.spread_after_deg:.2f} deg, rotation {al_q.rotation_deg:.2f} deg"
)
"""
)
md(
    """
What this shows: the axes already agree (identity permutation), and the angle between gravity
and the field is about 72 degrees, i.e. |dip| about 18 degrees (negative here: the field points
up relative to the accelerometer's 'up', as south of the magnetic equator, or the board uses
the opposite sign for the accelerometer; the log does not say where it was recorded). The
rotation, about one degree, comes out within a few tenths of a degree from either half of the
log, so it is a stable property of this board and this calibration; the formal standard errors
(hundredths of a degree) are too optimistic, since the motion does not give independent
errors. What it does not show is where the degree comes from: a physical misalignment of the
chips, or the ellipsoid fit itself (the fit determines only W'W, and calib_jax takes the
symmetric W, so any rotation inside the true distortion ends up here; that is one reason to
estimate this rotation at all). Nor does it clean the data much: the spread of the angle drops
only a little, because most of it is motion (the hand's acceleration tilts the apparent
gravity) and the magnetometer's 1.3 % residual, which no rotation can remove.

## 5. Paper 2's evaluation, reproduced on simulation

There is no real inclined-plane recording in the shipped data, so the test of section 3 of
the paper is simulated: a board whose magnetometer has a large hard and soft iron (each
hard-iron component up to 0.8 of the 45 uT field, semi-axes within 30 % of it), whose
accelerometer is slightly distorted (semi-axes within 5 % of 1 g, bias components up to
0.05 g), and whose sensors are rotated against the board by a few degrees about random axes
(up to 3 degrees for the accelerometer, 5 for the magnetometer). Three recordings: a tumble
of 3000 samples (for the ellipsoids and the accel-mag rotation), a turn about the board's z
axis on a level plane (for the plane alignment) and a turn on a plane inclined by 25 degrees
(for the evaluation).
"""
)
code(
    """
def make_board(seed):
    rng = np.random.default_rng(seed)
    c_m, W_m = sim.random_ellipsoid(rng, radius=45.0, center_spread=0.8)
    c_a, W_a = sim.random_ellipsoid(rng, radius=1.0, axis_spread=0.05, center_spread=0.05)
    board = dict(
        center=c_m,
        soft_iron=W_m,
        acc_center=c_a,
        acc_soft_iron=W_a,
        R_acc_board=sim.random_rotation(rng, 3),
        R_mag_board=sim.random_rotation(rng, 5),
    )
    tumble = sim.simulate_marg(sim.tumble_quaternions(3000, rng), rng=rng, **board)
    level = sim.simulate_marg(sim.plane_turn_quaternions(600, incline_deg=0.0), rng=rng, **board)
    inclined = sim.simulate_marg(
        sim.plane_turn_quaternions(600, incline_deg=25.0), rng=rng, **board
    )
    return tumble, level, inclined


tumble, level, inclined = make_board(1)
marg = cj.calibrate_marg(tumble.acc, tumble.mag, level.acc, level.mag)
print("magnetometer:", marg.mag.model, marg.mag.status, f"{marg.mag.rms_after_pct:.2f} % after")
print("accelerometer:", marg.acc.model, marg.acc.status, f"{marg.acc.rms_after_pct:.2f} % after")
print("warnings:", marg.warnings)
"""
)
md(
    """
The plane alignments against the truth. The tilt of a sensor is the angle between its z axis
and the board's; after alignment, the board's z axis seen by the sensor should be [0, 0, 1].
On the level turn gravity lies along the turning axis and draws no circle, so for the
accelerometer its mean direction is the axis (calib_jax says so in `method`).
"""
)
code(
    """
for name, pa, R_true in (
    ("accelerometer", marg.acc_plane, tumble.R_acc_board),
    ("magnetometer", marg.mag_plane, tumble.R_mag_board),
):
    z_board = R_true[2]  # the board's z axis in the sensor frame
    tilt = np.degrees(np.arccos(z_board[2]))
    left = np.degrees(np.arccos(np.clip((pa.matrix @ z_board)[2], -1.0, 1.0)))
    print(
        f"{name}: {pa.method}, eps_x {pa.eps_x_deg:+.3f}, eps_y {pa.eps_y_deg:+.3f} deg; "
        f"true tilt {tilt:.3f} deg, left after alignment {left:.3f} deg"
    )
rot = marg.mag_to_acc
err = rotation_angle_deg(rot.R_acc_from_mag.T @ tumble.R_acc_from_mag)
print(
    f"accel-mag rotation: {rot.rotation_deg:.3f} deg (true "
    f"{rotation_angle_deg(tumble.R_acc_from_mag):.3f}), error {err:.3f} deg; "
    f"dip {rot.dip_deg:.2f} deg (true {tumble.dip_deg:.0f})"
)
"""
)
md(
    """
Now the paper's test on the inclined turn. Following the paper, the attitude's reference is
the board's starting pose, so ideally roll = pitch = 0 throughout and the yaw turns through
the whole turn (1.2 revolutions, 432 degrees). Four versions of the same data: raw,
ellipsoid-compensated, compensated and plane-aligned (the paper's 'aligned-compensated'), and
compensated with the magnetometer rotated into the accelerometer frame (calib_jax's rotation
instead of the plane alignment). As a floor, the same turn on an ideal board (no distortion,
no misalignment) with the same sensor noise.
"""
)
code(
    """
ideal = sim.simulate_marg(sim.plane_turn_quaternions(600, incline_deg=25.0), rng=9)
ev = cj.evaluate_turn(
    {
        "raw": (inclined.acc, inclined.mag),
        "compensated": marg.compensate(inclined.acc, inclined.mag),
        "aligned-compensated": marg.plane_aligned(inclined.acc, inclined.mag),
        "rotation-aligned": marg.rotation_aligned(inclined.acc, inclined.mag),
        "ideal board (noise only)": (ideal.acc, ideal.mag),
    }
)
display(Markdown(evaluation_table(ev)))
"""
)
md(
    """
Fig. 9 and Fig. 10 of the paper for this run: roll, pitch and yaw, and the Gauss-Newton cost
F(x), sample by sample. (plot_mag above switched matplotlib to its non-interactive Agg
backend, so these figures are saved and shown as images as well.)
"""
)
code(
    """
fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
for e in ev.values():
    for k, ax in enumerate(axes):
        ax.plot(e.euler_deg[:, k], lw=1, label=e.label)
for ax, name in zip(axes, ["roll (deg)", "pitch (deg)", "yaw (deg)"], strict=True):
    ax.set_ylabel(name)
axes[0].set_ylim(-8, 8)
axes[1].set_ylim(-8, 8)
axes[0].legend(fontsize=7, ncol=5)
axes[-1].set_xlabel("sample")
fig.suptitle("turn on a 25-degree incline (cf. paper 2, Fig. 9)")
fig.tight_layout()
fig.savefig("02_fig9.png", dpi=80)
plt.close(fig)
Image("02_fig9.png")
"""
)
code(
    """
fig, ax = plt.subplots(figsize=(9, 3.5))
for e in ev.values():
    ax.semilogy(e.cost, lw=1, label=f"{e.label} (mean {e.mean_cost:.1e})")
ax.set_xlabel("sample")
ax.set_ylabel("F(x)")
ax.legend(fontsize=8)
ax.set_title("Gauss-Newton cost (cf. paper 2, Fig. 10 and Table 1)")
fig.tight_layout()
fig.savefig("02_fig10.png", dpi=80)
plt.close(fig)
Image("02_fig10.png")
"""
)
md(
    """
One random board is one draw; the same comparison over six boards (the one above is seed 1):
"""
)
code(
    """
labels = ["raw", "compensated", "aligned-compensated", "rotation-aligned"]
print(f"{'seed':<5}" + "".join(f"{lab:>22}" for lab in labels))
print(f"{'':<5}" + "    mean F  roll/pitch" * len(labels))
for seed in range(6):
    t, lv, inc = make_board(seed)
    m = cj.calibrate_marg(t.acc, t.mag, lv.acc, lv.mag)
    e = cj.evaluate_turn(
        {
            "raw": (inc.acc, inc.mag),
            "compensated": m.compensate(inc.acc, inc.mag),
            "aligned-compensated": m.plane_aligned(inc.acc, inc.mag),
            "rotation-aligned": m.rotation_aligned(inc.acc, inc.mag),
        }
    )
    row = "".join(
        f"{e[lab].mean_cost:>10.1e}{e[lab].roll_rms_deg:>6.2f}/{e[lab].pitch_rms_deg:<5.2f}"
        for lab in labels
    )
    print(f"{seed:<5}{row}")
"""
)
md(
    """
Paper 2's Table 1 gives, as we read it, a mean F(x) of about 8.5e-4 for raw data, 1.1e-4
compensated and 2.2e-5 aligned-compensated (the text of the table is garbled in our copy, so
take these as orders of magnitude), and the text a mean roll/pitch error of about 0.32 degrees
after alignment. The simulation reproduces the pattern: each step lowers F(x), compensation
by one to three orders of magnitude (most of our random boards have a more distorted
magnetometer than the paper's, so their raw F and raw angles are larger), alignment by a
further factor of two to a few hundred, ending near 1e-5 with roll and pitch RMS of 0.2-0.3
degrees, about what the ideal board with the same noise gives. Both 'aligned' versions reach
the same low F(x): they make the two sensors consistent. But only the paper's plane alignment
puts them in the *board's* frame: with the rotation alone, the accelerometer's own tilt
against the board (up to 3 degrees) remains, and roll and pitch wobble by an amount of the
order of that tilt as the board turns. F(x) cannot see that error; the roll/pitch test can.

## 6. Attitude against optical ground truth: BROAD trial 02

An excerpt of BROAD trial 02 (slow rotations, undisturbed field; every 10th sample, 28.6 Hz;
CC-BY-4.0, Laidig et al. 2021): a myon aktos-t IMU with manufacturer-calibrated accelerometer
(m/s^2) and magnetometer (uT), and the orientation from an optical tracking system (NaN rows
where tracking was lost). The Gauss-Newton attitude from each sample's accelerometer and
magnetometer alone (no gyroscope, no filter), with BROAD's split of the error into heading and
inclination:
"""
)
code(
    """
broad = cj.load_broad_excerpt()
acc_b, mag_b, q_ref = broad["acc"], broad["mag"], broad["quat"]
tracked = np.all(np.isfinite(q_ref), axis=1)
print(f"{len(acc_b)} samples, {int((~tracked).sum())} without optical truth")


def attitude_errors(acc, mag, rows):
    att = cj.estimate_attitude(acc[rows], mag[rows])
    ok = tracked[rows]
    err = jax.vmap(heading_inclination_error_deg)(att.quat[ok], jnp.asarray(q_ref[rows][ok]))
    err = np.asarray(err)
    return float(att.dip_deg), np.median(err, axis=0), np.sqrt(np.mean(err**2, axis=0))


def show(label, result):
    dip, med, rms = result
    print(
        f"{label:<34} dip {dip:5.1f}  heading median {med[0]:5.2f} RMS {rms[0]:5.2f}  "
        f"inclination median {med[1]:4.2f} RMS {rms[1]:4.2f} deg"
    )


everything = np.ones(len(acc_b), bool)
show("manufacturer calibration", attitude_errors(acc_b, mag_b, everything))
"""
)
md(
    """
A median error of about 3 degrees in heading and 1 in inclination, from single samples during
slow motion (the RMS is about twice the median: a tail of larger errors). Can our ellipsoid do
better than the manufacturer? Fit the magnetometer
(|B| = 44.3 uT) on the first half of the trial and evaluate the attitude on the second half:
"""
)
code(
    """
half = len(acc_b) // 2
first, second = np.arange(len(acc_b)) < half, np.arange(len(acc_b)) >= half
cal_1 = cj.calibrate_mag(mag_b[first], field=44.3, units="uT")
print(cal_1.report())
show("second half, manufacturer", attitude_errors(acc_b, mag_b, second))
show("second half, refit on the first", attitude_errors(acc_b, cal_1.apply(mag_b), second))
cal_1f = cj.calibrate_mag(mag_b[first], model="full", field=44.3, units="uT")
print(f"forcing the full ellipsoid: status {cal_1f.status}")
show("second half, full refit on first", attitude_errors(acc_b, cal_1f.apply(mag_b), second))
"""
)
md(
    """
The first half of the trial covers about a fifth of the sphere of directions, so an ellipsoid is
not determined along the unseen axis. calib_jax warns about the coverage, and `auto` falls back
from the full ellipsoid (poorly determined there, and much worse held out, as the last line
shows) to the best well-determined model, the sphere; even that makes the heading
worse than the manufacturer's calibration on the second half. Partial coverage cannot be
fixed by modelling. The fair test goes the other way round: fit on the second half, which covers
most of the sphere, and evaluate on the first.
"""
)
code(
    """
cal_2 = cj.calibrate_mag(mag_b[second], field=44.3, units="uT")
print(
    f"fit on the second half: model {cal_2.model}, status {cal_2.status}, "
    f"{100 * cal_2.coverage:.0f} % covered, centre {cal_2.center.round(2)} uT, "
    f"max |W - I| {np.abs(cal_2.soft_iron - np.eye(3)).max():.3f}"
)
show("first half, manufacturer", attitude_errors(acc_b, mag_b, first))
show("first half, refit on the second", attitude_errors(acc_b, cal_2.apply(mag_b), first))
"""
)
md(
    """
With good coverage the refit is close to the identity (centre well under 1 uT, W within a
few percent of I) and the attitude errors stay about where they were: no gain. That is the
correct finding for manufacturer-calibrated data: the remaining errors must come from
elsewhere, presumably the motion (the accelerometer sees more than gravity), the noise and the
lab's field, not the magnetometer's calibration.

## 7. Summary

Every number below is computed in this notebook.
"""
)
code(
    """
aligned = ev["aligned-compensated"]
dW = np.abs(W_alg - cal_sim.soft_iron).max()
print(f"paper 2 algebra vs LM (simulated):  max |dW| {dW:.1e}")
print(
    f"CK-Explorer magnetometer:           {cal.model}, radial error "
    f"{cal.rms_before_pct:.1f} % -> {cal.rms_after_pct:.2f} %"
)
print(
    f"CK-Explorer accelerometer:          {acal.model}, max |W - I| "
    f"{np.abs(acal.soft_iron - np.eye(3)).max():.3f}, |centre| "
    f"{1000 * np.linalg.norm(acal.center):.1f} mg"
)
print(
    f"CK-Explorer accel-mag:              dip {al.dip_deg:+.1f} deg, rotation "
    f"{al.rotation_deg:.2f} deg (halves {between:.2f} deg apart), spread "
    f"{al.spread_before_deg:.2f} -> {al.spread_after_deg:.2f} deg"
)
print(
    "simulated inclined turn, mean F:    "
    + ", ".join(f"{e.label} {e.mean_cost:.1e}" for e in ev.values())
)
print(
    f"  roll/pitch RMS, raw -> aligned:   {ev['raw'].roll_rms_deg:.2f}/"
    f"{ev['raw'].pitch_rms_deg:.2f} -> {aligned.roll_rms_deg:.2f}/"
    f"{aligned.pitch_rms_deg:.2f} deg"
)
"""
)
md(
    """
- Paper 2's algebra (constrained fit, matrix form, canonical form, eigen-analysis,
  compensation matrix) is reproduced step by step and agrees with calibrate_mag's LM result on
  well-covered data.
- On the real CK-Explorer tumble the full ellipsoid is chosen by BIC and removes most of the
  radial error; the already-calibrated accelerometer comes out as a near-unit sphere, as it
  should.
- The accel-mag rotation finds consistent axes, a dip of about -18 degrees and a rotation of
  about one degree on CK-Explorer, reproducible between the two halves of the log; it barely
  reduces the spread of the gravity-field angle, which the hand's motion dominates.
- On simulation, paper 2's sequence raw -> compensated -> aligned-compensated lowers the mean
  Gauss-Newton cost by orders of magnitude and brings roll and pitch on an inclined turn to
  a few tenths of a degree, as in the paper's Table 1 and Fig. 9. The accel-mag rotation
  reaches the same consistency but not the board frame: both tests are needed.
- On BROAD's manufacturer-calibrated data, refitting the magnetometer brings no gain when the
  fit is well determined, and calibrate_mag flags the fit that is not.
"""
)


if __name__ == "__main__":
    run(cells, OUT)
