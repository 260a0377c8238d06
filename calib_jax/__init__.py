"""calib_jax: triaxial accelerometer, gyroscope and magnetometer calibration in JAX.

Public API (re-exports only; each concept lives in its own module):

- :func:`calibrate_accel`: raw log -> :class:`AccelCalibration` (paper 1, end to end).
- :func:`calibrate_gyro`: multi-position log with turns -> :class:`GyroCalibration` (imu_tk's
  method: integrated rates must carry gravity from pose to pose).
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

# Imported on first use (PEP 562), so ``calib-jax --help`` and ``import calib_jax`` do not
# start JAX; ``from calib_jax import X`` and ``calib_jax.X`` work as before.
_LAZY = {
    "pipeline": (".pipeline", None),
    "calibrate_accel": (".accel", "calibrate_accel"),
    "fit_normalized": (".accel", "fit_normalized"),
    "initial_guess": (".accel", "initial_guess"),
    "align_mag_to_accel": (".align", "align_mag_to_accel"),
    "plane_alignment": (".align", "plane_alignment"),
    "estimate_attitude": (".attitude", "estimate_attitude"),
    "gauss_newton_quaternion": (".attitude", "gauss_newton_quaternion"),
    "BatchResult": (".batch", "BatchResult"),
    "BatchRecord": (".calibration", "BatchRecord"),
    "calibrate_accel_batch": (".batch", "calibrate_accel_batch"),
    "calibrate_mag_batch": (".batch", "calibrate_mag_batch"),
    "AccelCalibration": (".calibration", "AccelCalibration"),
    "FitStatusWarning": (".calibration", "FitStatusWarning"),
    "OffScaleWarning": (".calibration", "OffScaleWarning"),
    "MagCalibration": (".calibration", "MagCalibration"),
    "broad_excerpt_path": (".datasets", "broad_excerpt_path"),
    "demo_log_path": (".datasets", "demo_log_path"),
    "gyro_demo_log_path": (".datasets", "gyro_demo_log_path"),
    "calibrate_gyro": (".gyro", "calibrate_gyro"),
    "calibrate_gyro_ferraris": (".gyro", "calibrate_gyro_ferraris"),
    "GyroCalibration": (".gyro", "GyroCalibration"),
    "load_broad_excerpt": (".datasets", "load_broad_excerpt"),
    "mag_demo_log_path": (".datasets", "mag_demo_log_path"),
    "solve_implicit": (".implicit", "solve_implicit"),
    "SensorLog": (".io", "SensorLog"),
    "load_log": (".io", "load_log"),
    "LMResult": (".lm", "LMResult"),
    "Status": (".lm", "Status"),
    "lm_solve": (".lm", "lm_solve"),
    "optx_solve": (".lm", "optx_solve"),
    "calibrate_mag": (".mag", "calibrate_mag"),
    "fit_ellipsoid_normalized": (".mag", "fit_ellipsoid_normalized"),
    "calibrate_marg": (".marg", "calibrate_marg"),
    "calibrate_marg_log": (".marg", "calibrate_marg_log"),
    "MARGRecord": (".marg", "MARGRecord"),
    "evaluate_turn": (".marg", "evaluate_turn"),
    "AccelParams": (".models.accel", "AccelParams"),
    "correct": (".models.accel", "correct"),
    "distort": (".models.accel", "distort"),
    "sphere_residual": (".models.accel", "sphere_residual"),
    "StaticReport": (".static", "StaticReport"),
    "TooFewPoses": (".observations", "TooFewPoses"),
    "detect_static": (".static", "detect_static"),
}


def __getattr__(name: str):
    import importlib

    if name not in _LAZY:  # a submodule, as eager imports used to leave them (cj.datasets)
        try:
            return importlib.import_module(f".{name}", __name__)
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise
            raise AttributeError(f"module 'calib_jax' has no attribute {name!r}") from None
    module, attr = _LAZY[name]
    mod = importlib.import_module(module, __name__)
    value = mod if attr is None else getattr(mod, attr)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


__version__ = "0.1.0"

__all__ = [
    "pipeline",
    "BatchResult",
    "BatchRecord",
    "calibrate_accel_batch",
    "calibrate_mag_batch",
    "solve_implicit",
    "MagCalibration",
    "align_mag_to_accel",
    "broad_excerpt_path",
    "calibrate_mag",
    "calibrate_marg",
    "calibrate_marg_log",
    "MARGRecord",
    "estimate_attitude",
    "evaluate_turn",
    "fit_ellipsoid_normalized",
    "gauss_newton_quaternion",
    "load_broad_excerpt",
    "mag_demo_log_path",
    "plane_alignment",
    "AccelCalibration",
    "FitStatusWarning",
    "OffScaleWarning",
    "AccelParams",
    "LMResult",
    "SensorLog",
    "StaticReport",
    "Status",
    "TooFewPoses",
    "calibrate_accel",
    "calibrate_gyro",
    "calibrate_gyro_ferraris",
    "GyroCalibration",
    "gyro_demo_log_path",
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
