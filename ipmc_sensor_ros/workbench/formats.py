# SPDX-License-Identifier: Apache-2.0
r"""
The workbench's text formats ``ipmc-timeseries/1`` and ``ipmc-frf/1`` (no rclpy needed).

Every problem with an input raises :class:`DataFormatError` (a
:class:`ValueError`) naming the file and the 1-based line where that applies::

    data/x.csv:17: non-numeric cell 'abc' in column current_A

Nothing is silently dropped or repaired: a bad row, a duplicate time, an
unknown column, a NaN is an error, never a skipped line.

This module is the specification below, the writers and the public names of
both formats.  The readers (:func:`read_timeseries`, :func:`read_frf`,
:func:`read_text`) live in :mod:`.formatread` and the header and column-header
parsing in :mod:`.formatheader`; the readers and format constants are
re-exported here.

Text formats
============

Both text formats are UTF-8, ``\n`` or ``\r\n`` line ends, and share one
layout: header lines, then one column-header line, then numeric rows::

    # format: ipmc-timeseries/1
    # sample: slim
    # length_m: 0.022
    # width_m: 0.007
    # thickness_m: 0.00036
    # sample_rate_hz: 1000.0
    # temperature_k: 300.0
    #
    # operator: jd
    time_s,deflection_m,current_A
    0.0,0.0,0.0
    0.001,1.2e-05,-3.4e-08

Header
------
* Each header line is ``# key: value`` (``#``, optional spaces, the key, a
  colon, the value; the value is everything after the first colon, stripped).
  A line holding only ``#`` (and spaces) is allowed, so is an empty line.  A
  ``#`` line with text but no ``:`` is an error (free-text comments would be
  lost), so is a key given twice.  Keys match ``[A-Za-z][A-Za-z0-9_.-]*``.
* ``format`` (required): ``ipmc-timeseries/1`` or ``ipmc-frf/1``.
* ``sample`` (optional): name of the sample; also the :class:`Geometry` name.
* ``length_m``, ``width_m``, ``thickness_m`` (required): free length L,
  width W and total thickness 2h of the cantilever, metres (or in another
  length unit named by the key: ``length_mm: 22``, ``thickness_um: 360``).  They are checked
  by :class:`~ipmc_sensor_ros.physics.parameters.Geometry`, whose plausible
  ranges catch unit mistakes (``length_m: 22`` is 22 m: refused).
* ``temperature_k`` (K), ``youngs_modulus_pa`` (Pa), ``surface_resistance_ohm``
  (r0, ohm) (optional): physical values known for this sample; they end up in
  ``known`` and are checked by
  :class:`~ipmc_sensor_ros.physics.parameters.MaterialParameters`.
* ``sample_rate_hz`` (optional, time series only): nominal sampling rate, Hz;
  it must agree with ``1 / median(diff(time_s))`` within 1 % (without it, the rate the
  stamps say is taken: :func:`~.stamps.measured_rate_hz`).
* Every other key is kept, as a string, in ``extra``.
* Known numeric keys must be finite decimal numbers (``1e-3``, ``0.022``);
  NaN, Inf, units (``22 mm``) and empty values are errors.

``ipmc-timeseries/1`` columns
-----------------------------
Exactly ``time_s,deflection_m,current_A`` or ``time_s,current_A`` (no
deflection known, e.g. a field recording to be estimated):

* ``time_s``: sample time, seconds, strictly increasing (a duplicate or a
  decrease is an error at the line where it happens); any origin.
* ``deflection_m``: tip deflection, metres.
* ``current_A``: short-circuit sensing current, amperes.

``ipmc-frf/1`` columns
----------------------
``frequency_hz,gain_A_per_m,phase_deg[,coherence][,gain_std_A_per_m,phase_std_deg]``
(the optional groups in this order; the two std columns come together):

* ``frequency_hz``: frequency, Hz, > 0, strictly increasing.
* ``gain_A_per_m``: |I/w|, current per tip deflection, A/m, > 0.
* ``phase_deg``: arg(I/w), degrees (any finite value; not unwrapped here).
* ``coherence``: magnitude-squared coherence, dimensionless, in [0, 1].
* ``gain_std_A_per_m`` (A/m), ``phase_std_deg`` (degrees): standard
  uncertainties, >= 0.

Time-series columns may carry another unit of the same quantity, converted
to SI on reading: ``time_ms``/``time_us``; ``deflection_mm``,
``deflection_um`` (or ``µm``), ``deflection_nm``; ``current_mA``,
``current_uA`` (or ``µA``), ``current_nA``, ``current_pA`` (case-insensitive
unit).  ``ipmc-frf/1`` likewise: ``frequency_khz``, ``frequency_rad_s``
(divided by 2 pi), ``phase_rad``/``phase_std_rad``, and any
``<current unit>_per_<length unit>`` for the gain and its std
(``gain_uA_per_mm``).  A unit of another dimension (``deflection_A``,
``time_m``, ``phase_m``) is refused as "wrong units".  Files are always
written with the SI columns.

Rows
----
Comma separated, as many cells as columns, each a finite decimal number
(ASCII digits only; spaces around a cell are allowed).  At least two data
rows, at most ``max_rows`` (default 10 million), in a regular file of at most
``max_bytes`` (default 2 GiB): a FIFO or a device is refused, not read.  Empty lines
are allowed only at the end of the file; a blank or ``#`` line between data
rows is an error.

Writing
=======
:func:`write_timeseries` and :func:`write_frf` write floats with ``repr``
(shortest exact form), so write -> read returns identical arrays and header
values.  The text is parsed back before it is written: an invalid object
(non-increasing time, NaN, a multi-line extra value, a known value the header
has no key for) raises :class:`DataFormatError` and nothing is written.  The
``sample`` field (else ``geometry.name``) is written as ``# sample:``; on
reading it names both ``sample`` and the geometry.  :func:`write_bag` writes a
bag (and its sidecar) that :func:`read_bag` reads back exactly (the sample
rate is recomputed from the times).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

import numpy as np

from ..physics.parameters import Geometry
from .formatheader import (FRF_COHERENCE_COLUMN, FRF_COLUMNS, FRF_FORMAT, FRF_STD_COLUMNS,
                           GEOMETRY_KEYS, HEADER_KEY_PATTERN, KNOWN_KEYS, RESERVED_KEYS,
                           TIMESERIES_COLUMNS, TIMESERIES_COLUMNS_NO_DEFLECTION,
                           TIMESERIES_FORMAT)
from .formatread import format_exact, read_frf, read_text, read_timeseries
from .measurements import DataFormatError, FrequencyResponseData, PathLike, TimeSeries

__all__ = [
    'TIMESERIES_FORMAT', 'FRF_FORMAT', 'TIMESERIES_COLUMNS', 'TIMESERIES_COLUMNS_NO_DEFLECTION',
    'FRF_COLUMNS', 'GEOMETRY_KEYS', 'KNOWN_KEYS',
    'read_timeseries', 'write_timeseries', 'read_frf', 'write_frf', 'read_text',
]


def _header_text(fmt: str, sample: str, geometry: Geometry, numbers: Sequence[tuple[str, float]],
                 known: Mapping[str, float], extra: Mapping[str, Any], path) -> list[str]:
    def single_line(what: str, text: str) -> str:
        text = str(text)
        if '\n' in text or '\r' in text or text != text.strip():
            raise DataFormatError(path, None, f'cannot write {what} {text!r}: it must be one line '
                                  'without leading/trailing spaces')
        return text

    out = [f'# format: {fmt}']
    if sample:
        out.append(f"# sample: {single_line('sample name', sample)}")
    out += [f'# length_m: {format_exact(geometry.length_m)}',
            f'# width_m: {format_exact(geometry.width_m)}',
            f'# thickness_m: {format_exact(geometry.thickness_m)}']
    out += [f'# {k}: {format_exact(v)}' for k, v in numbers]
    for key in KNOWN_KEYS:
        if key in known:
            out.append(f'# {key}: {format_exact(known[key])}')
    unknown_known = sorted(set(known) - set(KNOWN_KEYS))
    if unknown_known:
        raise DataFormatError(path, None, f'cannot write known value(s) {unknown_known} in a text '
                              f'file; the header knows {list(KNOWN_KEYS)}')
    for key, value in extra.items():
        key = single_line('extra key', key)
        if not HEADER_KEY_PATTERN.fullmatch(key) or key in RESERVED_KEYS:
            raise DataFormatError(path, None, f'cannot write extra header key {key!r}: invalid or '
                                  'reserved')
        out.append(f"# {key}: {single_line(f'value of extra key {key!r}', value)}")
    return out


def _write_checked(path, lines: Sequence[str], rows: Iterator[str], read: Callable,
                   what: str) -> None:
    """
    Write header ``lines`` and row chunks to a temporary file beside ``path``.

    Read it back with ``read`` and move it into place: only readable files are ever
    written.
    """
    target = Path(path)
    tmp = target.with_name(f'.{target.name}.{os.getpid()}.tmp')
    try:
        with open(tmp, 'w', encoding='utf-8', newline='\n') as f:
            f.write('\n'.join(lines) + '\n')
            for chunk in rows:
                f.write(chunk)
        try:
            read(tmp)
        except DataFormatError as exc:
            where = f' (line {exc.line} of the output)' if exc.line is not None else ''
            raise DataFormatError(path, None, f'refusing to write an invalid {what}: '
                                  f'{exc.reason}{where}') from None
        os.replace(tmp, target)
    finally:
        if tmp.exists():
            tmp.unlink()


def _row_chunks(columns: Sequence[np.ndarray], size: int = 100_000) -> Iterator[str]:
    """repr-formatted CSV text of ``columns``, ``size`` rows at a time."""
    n = columns[0].size
    for start in range(0, n, size):
        cells = [c[start:start + size].tolist() for c in columns]
        yield ''.join(','.join(map(repr, row)) + '\n' for row in zip(*cells))


def write_timeseries(path: PathLike, ts: TimeSeries) -> None:
    """
    Write ``ts`` as ``ipmc-timeseries/1``; floats in repr precision (exact round trip).

    The file is read back before it is put in place: an invalid series
    (non-increasing time, NaN, ...) raises :class:`DataFormatError` and
    nothing is written.
    """
    sample = ts.sample or ts.geometry.name
    lines = _header_text(TIMESERIES_FORMAT, sample, ts.geometry,
                         [('sample_rate_hz', ts.sample_rate_hz)], ts.known, ts.extra, path)
    if ts.deflection_m is None:
        lines.append(','.join(TIMESERIES_COLUMNS_NO_DEFLECTION))
        columns = [ts.time_s, ts.current_a]
    else:
        lines.append(','.join(TIMESERIES_COLUMNS))
        columns = [ts.time_s, ts.deflection_m, ts.current_a]
    _write_checked(path, lines, _row_chunks(columns),
                   lambda p: read_timeseries(p, max_bytes=None, max_rows=None), 'time series')


def write_frf(path: PathLike, frf: FrequencyResponseData) -> None:
    """Write ``frf`` as ``ipmc-frf/1`` (exact round trip; validated before writing)."""
    sample = frf.sample or frf.geometry.name
    lines = _header_text(FRF_FORMAT, sample, frf.geometry, [], frf.known, frf.extra, path)
    columns = list(FRF_COLUMNS)
    data = [frf.frequency_hz, frf.gain_a_per_m, frf.phase_deg]
    if frf.coherence is not None:
        columns.append(FRF_COHERENCE_COLUMN)
        data.append(frf.coherence)
    if frf.gain_std_a_per_m is not None:
        columns += FRF_STD_COLUMNS
        data += [frf.gain_std_a_per_m, frf.phase_std_deg]
    lines.append(','.join(columns))
    _write_checked(path, lines, _row_chunks(data),
                   lambda p: read_frf(p, max_bytes=None, max_rows=None), 'frequency response')
