# SPDX-License-Identifier: Apache-2.0
"""
Front door of the workbench's measurement-data input and output (no rclpy needed).

Everything a verb reads goes through :func:`read_any` (one path) or
:func:`read_records` (paths and directories).  The formats live in their own
modules, re-exported here:

* :mod:`.measurements`: :class:`TimeSeries`, :class:`FrequencyResponseData`,
  :class:`DataFormatError`;
* :mod:`.formats`: ``ipmc-timeseries/1`` and ``ipmc-frf/1`` text files;
* :mod:`.bags`: rosbag2 bags (sqlite3 or mcap), their topics' messages in
  :mod:`.bagtopics`;
* :mod:`.labimport`: free-form lab exports (LabVIEW-style headers, units in
  column names) converted to ``ipmc-timeseries/1``;
* :mod:`.textread`: the streaming reader under both (regular files only,
  ``max_bytes`` / ``max_rows`` limits); :mod:`.units`: unit tables.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Iterable, Mapping, NamedTuple

from .bags import read_bag, write_bag
from .bagtopics import (bag_typestore, CURRENT_LABEL, DEFLECTION_LABEL, MULTIARRAY_TYPE,
                        POINT_STAMPED_TYPE)
from .formats import (FRF_COLUMNS, FRF_FORMAT, GEOMETRY_KEYS, KNOWN_KEYS, TIMESERIES_COLUMNS,
                      TIMESERIES_COLUMNS_NO_DEFLECTION, TIMESERIES_FORMAT, read_frf, read_text,
                      read_timeseries, write_frf, write_timeseries)
from ..physics.parameters import Geometry
from .measurements import DataFormatError, FrequencyResponseData, PathLike, TimeSeries
from .textread import MAX_BYTES, MAX_ROWS

__all__ = [
    'DataFormatError', 'TimeSeries', 'FrequencyResponseData', 'TIMESERIES_FORMAT', 'FRF_FORMAT',
    'TIMESERIES_COLUMNS', 'TIMESERIES_COLUMNS_NO_DEFLECTION', 'FRF_COLUMNS', 'GEOMETRY_KEYS',
    'KNOWN_KEYS', 'CURRENT_LABEL', 'DEFLECTION_LABEL', 'MULTIARRAY_TYPE', 'POINT_STAMPED_TYPE',
    'bag_typestore', 'read_timeseries', 'write_timeseries', 'read_frf', 'write_frf', 'read_bag',
    'write_bag',
    'read_any', 'load_many', 'read_records', 'Records', 'natural_key', 'DATA_SUFFIXES',
]


# ---------------------------------------------------------------------------
# Dispatch
# ---------------------------------------------------------------------------
#: Files of a (non-bag) directory that :func:`read_records` reads.
DATA_SUFFIXES = ('.csv', '.txt')


def read_any(path: PathLike, *, max_bytes: int | None = MAX_BYTES,
             max_rows: int | None = MAX_ROWS) -> TimeSeries | FrequencyResponseData:
    """
    Read any supported input.

    A directory or a ``.mcap``/``.db3`` file is read with :func:`read_bag`
    (default topics, sidecar geometry); a text file is dispatched on its
    ``# format:`` header line.
    """
    p = Path(path)
    if p.is_dir() or p.suffix in ('.mcap', '.db3'):
        return read_bag(path)
    return read_text(path, max_bytes=max_bytes, max_rows=max_rows)


def load_many(paths: Iterable[PathLike]) -> list[TimeSeries | FrequencyResponseData]:
    """:func:`read_any` each path, in order; the first failure raises (naming its file)."""
    return [read_any(p) for p in paths]


def natural_key(path: PathLike) -> list:
    """
    Sort key of a file name with its numbers compared as numbers.

    ``short_1Hz`` < ``short_1.5Hz`` < ``short_2Hz`` < ``short_13Hz`` (text sorting
    puts 13 before 2).
    """
    parts = re.split(r'([0-9]+(?:\.[0-9]+)?)', Path(path).name.lower())
    return [float(p) if k % 2 else p for k, p in enumerate(parts)] + [str(path)]


class Records(NamedTuple):
    """What :func:`read_records` read: the records, and the files it skipped with why."""

    records: list
    skipped: list  # [(path, reason)]


def _is_bag_dir(p: Path) -> bool:
    return p.is_dir() and (p / 'metadata.yaml').is_file()


def read_records(paths: Iterable[PathLike] | PathLike, need_deflection: bool = True, *,
                 current_topic: str = 'current',
                 deflection_topic: str | None = 'deflection_truth',
                 geometry: Geometry | Mapping | None = None,
                 max_bytes: int | None = MAX_BYTES, max_rows: int | None = MAX_ROWS) -> Records:
    """
    Read files, bags and directories of them, in natural name order within a directory.

    A directory that is not a bag contributes its ``.csv``/``.txt`` files and
    its bag subdirectories, sorted by :func:`natural_key`.  With
    ``need_deflection`` a time series without deflection found in a directory
    is skipped and listed in ``skipped`` as ``(path, reason)``; one named
    directly is an error (it was asked for by name).  Bags are read with
    ``current_topic``, ``deflection_topic`` and ``geometry`` (else the sidecar).
    Every other problem raises :class:`DataFormatError` naming the file.
    """
    if isinstance(paths, (str, Path)):
        paths = [paths]
    records: list = []
    skipped: list = []

    def one(p: Path, listed: bool) -> None:
        if _is_bag_dir(p) or (p.is_file() and p.suffix in ('.mcap', '.db3')):
            item = read_bag(p, current_topic, deflection_topic, geometry)
        else:
            item = read_text(p, max_bytes=max_bytes, max_rows=max_rows)
        if need_deflection and isinstance(item, TimeSeries) and item.deflection_m is None:
            reason = 'no deflection column (current only)'
            if not listed:
                raise DataFormatError(p, None, f'{reason}: this needs measured deflection')
            skipped.append((str(p), reason))
            return
        records.append(item)

    for path in paths:
        p = Path(path)
        if p.is_dir() and not _is_bag_dir(p):
            members = sorted((x for x in p.iterdir()
                              if (x.is_file() and x.suffix in DATA_SUFFIXES) or _is_bag_dir(x)),
                             key=natural_key)
            if not members:
                raise DataFormatError(p, None, 'directory holds no .csv/.txt files or bags and '
                                      'is not a bag')
            for x in members:
                one(x, True)
        else:
            one(p, False)
    if not records:
        raise DataFormatError(', '.join(str(p) for p in paths) or '(none)', None,
                              'no usable records' + (f' ({len(skipped)} skipped: no deflection)'
                                                     if skipped else ''))
    return Records(records, skipped)
