"""Close the loop: trace the residual of a calibration to the effect its model lacks."""

from .floors import allan_deviation, white_floor
from .loop import CATALOGUE, Diagnosis, diagnose_accel, diagnose_mag
from .marg import diagnose_marg

__all__ = [
    "CATALOGUE",
    "Diagnosis",
    "allan_deviation",
    "diagnose_accel",
    "diagnose_mag",
    "diagnose_marg",
    "white_floor",
]
