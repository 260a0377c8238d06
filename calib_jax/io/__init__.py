"""Input and output: log files (and, in later issues, serial ports)."""

from .files import SensorLog, canonical_name, load_log, parse_columns

__all__ = ["SensorLog", "canonical_name", "load_log", "parse_columns"]
