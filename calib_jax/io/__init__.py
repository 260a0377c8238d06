"""Input and output: log files and serial ports."""

from .files import SensorLog, canonical_name, load_log, parse_columns
from .serial import Batch, LogWriter, ReaderStats, Recording, SerialReader, parse_scale, record

__all__ = [
    "Batch",
    "LogWriter",
    "ReaderStats",
    "Recording",
    "SensorLog",
    "SerialReader",
    "canonical_name",
    "load_log",
    "parse_columns",
    "parse_scale",
    "record",
]
