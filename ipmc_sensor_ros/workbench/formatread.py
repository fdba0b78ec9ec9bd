# SPDX-License-Identifier: Apache-2.0
"""
Readers of the workbench text formats ``ipmc-timeseries/1`` and ``ipmc-frf/1`` (no rclpy needed).

:func:`read_timeseries`, :func:`read_frf` and :func:`read_text` (either format,
dispatched on the ``# format:`` line) stream the data rows through
:func:`~.textread.read_table` and check each row as it comes (strictly
increasing time or frequency, positive gain, coherence in [0, 1], ...), then
convert columns in other units to SI.  The header and column-header line are
parsed by :mod:`.formatheader`; the specification is the docstring of
:mod:`.formats`, which also holds the writers and re-exports these readers.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from .formatheader import (FRF_BASES, FRF_COHERENCE_COLUMN, FRF_FORMAT, FRF_LAYOUTS,
                           FRF_NUMERIC_KEYS, FRF_STD_COLUMNS, header_format, parse_columns,
                           parse_header, TextHeader, TIMESERIES_BASES, TIMESERIES_FORMAT,
                           TIMESERIES_LAYOUTS, TIMESERIES_NUMERIC_KEYS, validate_header)
from .measurements import DataFormatError, FrequencyResponseData, PathLike, TimeSeries
from .stamps import measured_rate_hz
from .textread import MAX_BYTES, MAX_ROWS, TextSource, first_bad, increasing_check, read_table
from .units import to_si

__all__ = ['SAMPLE_RATE_TOLERANCE', 'read_timeseries', 'read_frf', 'read_text', 'incomplete_notes',
           'format_exact']

#: Relative tolerance between ``sample_rate_hz`` and 1 / median time step.
SAMPLE_RATE_TOLERANCE = 0.01


def _block_check(bad_rows: Callable[[np.ndarray, int], np.ndarray], row_check: Callable):
    """
    Return a block check for :func:`read_table`.

    ``bad_rows(rows, n_prev)`` marks suspect rows (``rows`` starts with the previous
    row when there is one), ``row_check`` raises the message of the first of them.
    """
    def check(block: np.ndarray, prev: np.ndarray | None, line0: int) -> None:
        rows = block if prev is None else np.vstack([prev, block])
        offset = 0 if prev is None else 1
        k = first_bad(bad_rows(rows, offset))
        if k is not None:
            line = line0 + k - offset
            row_check(rows[k], rows[k - 1] if k else None, line, line - 1)
    return check


def _read_rows(source: TextSource, header: TextHeader, check, max_rows) -> list[np.ndarray]:
    raw_names = [c.strip() for c in header.column_text.split(',')]
    data, _ = read_table(source, raw_names, check, max_rows=max_rows,
                         header_line=header.column_line)
    return data


def incomplete_notes(path, source: TextSource) -> tuple[str, ...]:
    """Return the note of a last line without a line end, not read (:mod:`.textread`)."""
    if source.incomplete_line is None:
        return ()
    return (f'{path}:{source.incomplete_line}: last line has no line end (file still being '
            'written?): not read',)


def format_exact(x: float) -> str:
    """Return ``x`` as the shortest decimal text that reads back as the same float (``repr``)."""
    return repr(float(x))


# ---------------------------------------------------------------------------
# ipmc-timeseries/1
# ---------------------------------------------------------------------------
def _timeseries_from(path, source: TextSource, header: TextHeader, max_rows) -> TimeSeries:
    sample, geometry, known, numbers, extra = validate_header(
        path, header, TIMESERIES_FORMAT, TIMESERIES_NUMERIC_KEYS, TIMESERIES_LAYOUTS)
    columns, factors = parse_columns(path, header, TIMESERIES_LAYOUTS, TIMESERIES_BASES)
    tname = header.column_text.split(',')[0].strip()
    tunit = tname.partition('_')[2]

    data = _read_rows(source, header, increasing_check(path, tname, tunit), max_rows)
    data = [to_si(col, factor) if factor != 1.0 else col for col, factor in zip(data, factors)]
    t = data[0]
    if np.any(np.diff(t) <= 0):  # a sub-ns step in ms/us lost to rounding when converted
        k = int(np.argmax(np.diff(t) <= 0)) + 1
        raise DataFormatError(path, header.column_line + 1 + k, f'time step below float '
                              f'resolution after conversion to seconds at {format_exact(t[k])} s')
    median_dt = float(np.median(np.diff(t)))
    rate = numbers.get('sample_rate_hz')
    if rate is None:
        rate = measured_rate_hz(t)
    elif rate <= 0.0:
        raise DataFormatError(path, header.lines['sample_rate_hz'], f'sample_rate_hz must be > 0, '
                              f'got {format_exact(rate)}')
    elif abs(rate * median_dt - 1.0) > SAMPLE_RATE_TOLERANCE:
        raise DataFormatError(path, header.lines['sample_rate_hz'],
                              f'sample_rate_hz = {format_exact(rate)} disagrees with the time '
                              f'column: median step {median_dt:.6g} s -> {1 / median_dt:.6g} Hz '
                              f'(tolerance {SAMPLE_RATE_TOLERANCE:.0%})')
    deflection = data[1] if 'deflection_m' in columns else None
    current = data[columns.index('current_A')]
    del data
    return TimeSeries(path=str(path), sample=sample, geometry=geometry, known=known,
                      sample_rate_hz=rate, time_s=t, current_a=current,
                      deflection_m=deflection, extra=extra,
                      deflection_alignment='exact' if deflection is not None else None,
                      first_row_line=header.column_line + 1,
                      notes=incomplete_notes(path, source))


def read_timeseries(path: PathLike, *, max_bytes: int | None = MAX_BYTES,
                    max_rows: int | None = MAX_ROWS) -> TimeSeries:
    """Read an ``ipmc-timeseries/1`` file (see the docstring of :mod:`.formats`)."""
    with TextSource(path, max_bytes=max_bytes) as source:
        return _timeseries_from(path, source, parse_header(path, source), max_rows)


# ---------------------------------------------------------------------------
# ipmc-frf/1
# ---------------------------------------------------------------------------
def _frf_from(path, source: TextSource, header: TextHeader, max_rows) -> FrequencyResponseData:
    sample, geometry, known, _numbers, extra = validate_header(
        path, header, FRF_FORMAT, FRF_NUMERIC_KEYS, FRF_LAYOUTS)
    columns, factors = parse_columns(path, header, FRF_LAYOUTS, FRF_BASES)
    coh = columns.index(FRF_COHERENCE_COLUMN) if FRF_COHERENCE_COLUMN in columns else None
    std = [columns.index(c) for c in FRF_STD_COLUMNS if c in columns]

    def row_check(row, prev, lineno, prev_line):
        f = row[0]
        if f <= 0.0:
            raise DataFormatError(path, lineno, f'non-positive frequency {format_exact(f)} Hz '
                                  '(frequency_hz must be > 0)')
        if prev is not None and f <= prev[0]:
            what = 'duplicate frequency' if f == prev[0] else 'frequency decreases:'
            raise DataFormatError(path, lineno, f'{what} {format_exact(f)} Hz after '
                                  f'{format_exact(prev[0])} Hz on line {prev_line}; '
                                  'frequency_hz must be strictly increasing')
        if row[1] <= 0.0:
            raise DataFormatError(path, lineno, f'non-positive gain {format_exact(row[1])} in '
                                  'column gain_A_per_m (a magnitude, must be > 0)')
        if coh is not None and not 0.0 <= row[coh] <= 1.0:
            raise DataFormatError(path, lineno,
                                  f'coherence {format_exact(row[coh])} outside [0, 1]')
        for k in std:
            if row[k] < 0.0:
                raise DataFormatError(path, lineno, f'negative standard uncertainty '
                                      f'{format_exact(row[k])} in column {columns[k]}')

    def bad_rows(rows, offset):
        bad = (rows[:, 0] <= 0) | (rows[:, 1] <= 0)
        bad[1:] |= np.diff(rows[:, 0]) <= 0
        if coh is not None:
            bad |= ~((rows[:, coh] >= 0) & (rows[:, coh] <= 1))
        for k in std:
            bad |= rows[:, k] < 0
        bad[:offset] = False  # the previous row was checked with its own block
        return bad

    data = _read_rows(source, header, _block_check(bad_rows, row_check), max_rows)
    data = [to_si(col, factor) if factor != 1.0 else col for col, factor in zip(data, factors)]
    return FrequencyResponseData(
        path=str(path), sample=sample, geometry=geometry, known=known,
        frequency_hz=data[0], gain_a_per_m=data[1], phase_deg=data[2],
        coherence=data[coh] if coh is not None else None,
        gain_std_a_per_m=data[std[0]] if std else None,
        phase_std_deg=data[std[1]] if std else None, extra=extra)


def read_frf(path: PathLike, *, max_bytes: int | None = MAX_BYTES,
             max_rows: int | None = MAX_ROWS) -> FrequencyResponseData:
    """Read an ``ipmc-frf/1`` file (see the docstring of :mod:`.formats`)."""
    with TextSource(path, max_bytes=max_bytes) as source:
        return _frf_from(path, source, parse_header(path, source), max_rows)


def read_text(path: PathLike, *, max_bytes: int | None = MAX_BYTES,
              max_rows: int | None = MAX_ROWS) -> TimeSeries | FrequencyResponseData:
    """Read a text file of either format, dispatched on its ``# format:`` line."""
    with TextSource(path, max_bytes=max_bytes) as source:
        header = parse_header(path, source)
        if header_format(path, header) == TIMESERIES_FORMAT:
            return _timeseries_from(path, source, header, max_rows)
        return _frf_from(path, source, header, max_rows)
