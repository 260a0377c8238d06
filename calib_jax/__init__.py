"""calib_jax: triaxial accelerometer and magnetometer calibration in JAX.

Public API (re-exports only; each concept lives in its own module):

- :func:`calibrate_accel`: raw log -> :class:`AccelCalibration` (paper 1, end to end).
- :mod:`calib_jax.models.accel`: the nine-parameter model, ``correct``, ``sphere_residual``.
- :mod:`calib_jax.lm`: Gavin's Levenberg-Marquardt (``lm_solve``) and ``optx_solve``.
- :mod:`calib_jax.static`: static-interval detection.
- :mod:`calib_jax.io`: log loaders.
- :mod:`calib_jax.simulate`: logs with known truth.
"""

from .accel import calibrate_accel, fit_normalized, initial_guess
from .calibration import AccelCalibration
from .datasets import demo_log_path
from .io import SensorLog, load_log
from .lm import LMResult, Status, lm_solve, optx_solve
from .models.accel import AccelParams, correct, distort, sphere_residual
from .static import StaticReport, detect_static

__version__ = "0.1.0"

__all__ = [
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
