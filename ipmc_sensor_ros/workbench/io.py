"""Front door of the workbench's measurement-data input and output (no rclpy needed).

Everything a verb reads goes through :func:`read_any` (one path) or
:func:`read_records` (paths and directories).  The formats live in their own
modules, re-exported here:

* :mod:`.measurements`: :class:`TimeSeries`, :class:`FrequencyResponseData`,
  :class:`DataFormatError`;
* :mod:`.formats`: ``ipmc-timeseries/1`` and ``ipmc-frf/1`` text files;
* :mod:`.bags`: rosbag2 bags (sqlite3 or mcap);
* :mod:`.labimport`: free-form lab exports (LabVIEW-style headers, units in
  column names) converted to ``ipmc-timeseries/1``.
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterable

from .bags import (CURRENT_LABEL, DEFLECTION_LABEL, MULTIARRAY_TYPE, POINT_STAMPED_TYPE,
                   _typestore, read_bag, write_bag)
from .formats import (FRF_COLUMNS, FRF_FORMAT, GEOMETRY_KEYS, KNOWN_KEYS, TIMESERIES_COLUMNS,
                      TIMESERIES_COLUMNS_NO_DEFLECTION, TIMESERIES_FORMAT, read_frf, read_text,
                      read_timeseries, write_frf, write_timeseries)
from .measurements import DataFormatError, FrequencyResponseData, PathLike, TimeSeries

__all__ = [
    "DataFormatError", "TimeSeries", "FrequencyResponseData", "TIMESERIES_FORMAT", "FRF_FORMAT",
    "TIMESERIES_COLUMNS", "TIMESERIES_COLUMNS_NO_DEFLECTION", "FRF_COLUMNS", "GEOMETRY_KEYS",
    "KNOWN_KEYS", "CURRENT_LABEL", "DEFLECTION_LABEL", "MULTIARRAY_TYPE", "POINT_STAMPED_TYPE",
    "read_timeseries", "write_timeseries", "read_frf", "write_frf", "read_bag", "write_bag",
    "read_any", "load_many",
]
_ = _typestore  # re-exported for the test corpus generator


# ---------------------------------------------------------------------------
# Dispatch
# ---------------------------------------------------------------------------
def read_any(path: PathLike) -> TimeSeries | FrequencyResponseData:
    """Read any supported input.

    A directory or a ``.mcap``/``.db3`` file is read with :func:`read_bag`
    (default topics, sidecar geometry); a text file is dispatched on its
    ``# format:`` header line.
    """
    p = Path(path)
    if p.is_dir() or p.suffix in (".mcap", ".db3"):
        return read_bag(path)
    return read_text(path)


def load_many(paths: Iterable[PathLike]) -> list[TimeSeries | FrequencyResponseData]:
    """:func:`read_any` each path, in order; the first failure raises (naming its file)."""
    return [read_any(p) for p in paths]

