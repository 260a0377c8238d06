"""calib_jax: triaxial accelerometer and magnetometer calibration in JAX.

Public API (re-exports only; each concept lives in its own module):

- :func:`calibrate_accel`: raw log -> :class:`AccelCalibration` (paper 1, end to end).
- :func:`calibrate_mag`: free-rotation log -> :class:`MagCalibration` (paper 2 ellipsoid).
- :func:`calibrate_marg`, :func:`evaluate_turn`: paper 2's routine and its evaluation.
- :mod:`calib_jax.align`: sensor-plane alignment, accel-mag rotation.
- :mod:`calib_jax.attitude`: Gauss-Newton quaternion attitude from accelerometer + magnetometer.
- :mod:`calib_jax.models.mag`: the ellipsoid model and its quadric residual.
- :mod:`calib_jax.models.accel`: the nine-parameter model, ``correct``, ``sphere_residual``.
- :mod:`calib_jax.lm`: Gavin's Levenberg-Marquardt (``lm_solve``) and ``optx_solve``.
- :mod:`calib_jax.static`: static-interval detection.
- :mod:`calib_jax.io`: log loaders.
- :mod:`calib_jax.simulate`: logs with known truth.
- :mod:`calib_jax.pipeline`: the library face for JAX pipelines: calibrations as equinox
  pytrees, ``apply``/``residual``/``fit_accel``/``fit_mag``/``fit_batch``/``attitude``,
  implicit gradients through the fits, covariance propagated to samples and roll/pitch/yaw.
- :mod:`calib_jax.endtoend`: calibration against a reference attitude (BROAD's optical truth).
"""

from . import pipeline
from .accel import calibrate_accel, fit_normalized, initial_guess
from .align import align_mag_to_accel, plane_alignment
from .attitude import estimate_attitude, gauss_newton_quaternion
from .batch import BatchResult, calibrate_accel_batch, calibrate_mag_batch
from .calibration import AccelCalibration, MagCalibration
from .datasets import broad_excerpt_path, demo_log_path, load_broad_excerpt, mag_demo_log_path
from .implicit import solve_implicit
from .io import SensorLog, load_log
from .lm import LMResult, Status, lm_solve, optx_solve
from .mag import calibrate_mag, fit_ellipsoid_normalized
from .marg import calibrate_marg, evaluate_turn
from .models.accel import AccelParams, correct, distort, sphere_residual
from .static import StaticReport, detect_static

__version__ = "0.1.0"

__all__ = [
    "pipeline",
    "BatchResult",
    "calibrate_accel_batch",
    "calibrate_mag_batch",
    "solve_implicit",
    "MagCalibration",
    "align_mag_to_accel",
    "broad_excerpt_path",
    "calibrate_mag",
    "calibrate_marg",
    "estimate_attitude",
    "evaluate_turn",
    "fit_ellipsoid_normalized",
    "gauss_newton_quaternion",
    "load_broad_excerpt",
    "mag_demo_log_path",
    "plane_alignment",
    "AccelCalibration",
    "AccelParams",
    "LMResult",
    "SensorLog",
    "StaticReport",
    "Status",
    "calibrate_accel",
    "correct",
    "demo_log_path",
    "detect_static",
    "distort",
    "fit_normalized",
    "initial_guess",
    "lm_solve",
    "load_log",
    "optx_solve",
    "sphere_residual",
]
