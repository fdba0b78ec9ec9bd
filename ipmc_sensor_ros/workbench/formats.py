# SPDX-License-Identifier: Apache-2.0
r"""
The workbench's text formats ``ipmc-timeseries/1`` and ``ipmc-frf/1`` (no rclpy needed).

Every problem with an input raises :class:`DataFormatError` (a
:class:`ValueError`) naming the file and the 1-based line where that applies::

    data/x.csv:17: non-numeric cell 'abc' in column current_A

Nothing is silently dropped or repaired: a bad row, a duplicate time, an
unknown column, a NaN is an error, never a skipped line.

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
  it must agree with ``1 / median(diff(time_s))`` within 1 %.
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
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

import numpy as np

from ..physics.parameters import Geometry, MaterialParameters, ParameterError
from .measurements import DataFormatError, FrequencyResponseData, PathLike, TimeSeries
from .textread import (MAX_BYTES, MAX_ROWS, TextSource, first_bad, increasing_check, parse_number,
                       read_table)
from .units import LENGTH_UNITS, column_to_si, column_units, decimal_to_si, to_si, unit_factor

__all__ = [
    'TIMESERIES_FORMAT', 'FRF_FORMAT', 'TIMESERIES_COLUMNS', 'TIMESERIES_COLUMNS_NO_DEFLECTION',
    'FRF_COLUMNS', 'GEOMETRY_KEYS', 'KNOWN_KEYS',
    'read_timeseries', 'write_timeseries', 'read_frf', 'write_frf', 'read_text',
]

TIMESERIES_FORMAT = 'ipmc-timeseries/1'
FRF_FORMAT = 'ipmc-frf/1'
FORMATS = (TIMESERIES_FORMAT, FRF_FORMAT)

TIMESERIES_COLUMNS = ('time_s', 'deflection_m', 'current_A')
TIMESERIES_COLUMNS_NO_DEFLECTION = ('time_s', 'current_A')
FRF_COLUMNS = ('frequency_hz', 'gain_A_per_m', 'phase_deg')
FRF_COHERENCE_COLUMN = 'coherence'
FRF_STD_COLUMNS = ('gain_std_A_per_m', 'phase_std_deg')

#: Accepted column-header lines of each format.
_TIMESERIES_LAYOUTS = (TIMESERIES_COLUMNS, TIMESERIES_COLUMNS_NO_DEFLECTION)
_FRF_LAYOUTS = (
    FRF_COLUMNS,
    FRF_COLUMNS + (FRF_COHERENCE_COLUMN,),
    FRF_COLUMNS + FRF_STD_COLUMNS,
    FRF_COLUMNS + (FRF_COHERENCE_COLUMN,) + FRF_STD_COLUMNS,
)

GEOMETRY_KEYS = ('length_m', 'width_m', 'thickness_m')
#: Optional known physical values (header keys; :class:`MaterialParameters` names).
KNOWN_KEYS = ('temperature_k', 'youngs_modulus_pa', 'surface_resistance_ohm')
_TIMESERIES_NUMERIC_KEYS = GEOMETRY_KEYS + ('sample_rate_hz',) + KNOWN_KEYS
_FRF_NUMERIC_KEYS = GEOMETRY_KEYS + KNOWN_KEYS
_RESERVED_KEYS = ('format', 'sample') + GEOMETRY_KEYS + ('sample_rate_hz',) + KNOWN_KEYS

#: Relative tolerance between ``sample_rate_hz`` and 1 / median time step.
SAMPLE_RATE_TOLERANCE = 0.01


#: Expected column of each known quantity and a description of its unit, used
#: to say "wrong units" when a column names the right quantity in another unit.
_COLUMN_UNITS = {
    'time': ('time_s', 'seconds'),
    'deflection': ('deflection_m', 'metres'),
    'current': ('current_A', 'amperes'),
    'frequency': ('frequency_hz', 'hertz'),
    'gain': ('gain_A_per_m', 'amperes per metre'),
    'phase': ('phase_deg', 'degrees'),
    'coherence': ('coherence', 'dimensionless, 0..1'),
    'gain_std': ('gain_std_A_per_m', 'amperes per metre'),
    'phase_std': ('phase_std_deg', 'degrees'),
}
_TIMESERIES_BASES = ('time', 'deflection', 'current')
_FRF_BASES = ('frequency', 'gain', 'phase', 'coherence', 'gain_std', 'phase_std')

_KEY = re.compile(r'[A-Za-z][A-Za-z0-9_.\-]*')


# ---------------------------------------------------------------------------
# Text files: header and columns
# ---------------------------------------------------------------------------
@dataclass
class _Header:
    values: dict               # key -> raw string value
    lines: dict                # key -> 1-based line
    column_line: int | None    # 1-based line of the column-header line (None: end of file)
    column_text: str           # the column-header line ('' if none)
    n_lines: int               # lines read (all of them when column_line is None)


def _parse_header(path: PathLike, source: TextSource) -> _Header:
    """Read header lines up to and including the column-header line."""
    values: dict[str, str] = {}
    where: dict[str, int] = {}
    seen_text = False
    while True:
        line = source.next_line()
        if line is None:
            if not seen_text:
                raise DataFormatError(path, 1, "empty file (expected a '# format: ...' header "
                                      'line)')
            return _Header(values, where, None, '', source.lineno)
        s = line.strip()
        seen_text = seen_text or bool(s)
        if s and not s.startswith('#'):
            return _Header(values, where, source.lineno, line, source.lineno)
        body = s[1:].strip()
        if not body:
            continue
        lineno = source.lineno
        if ':' not in body:
            raise DataFormatError(path, lineno, f"header line without ':' separator: {s!r} "
                                  "(expected '# key: value')")
        key, _, value = body.partition(':')
        key, value = key.strip(), value.strip()
        if not _KEY.fullmatch(key):
            raise DataFormatError(path, lineno, f'invalid header key {key!r} in {s!r} '
                                  "(expected '# key: value', key [A-Za-z][A-Za-z0-9_.-]*)")
        if key in values:
            raise DataFormatError(path, lineno, f"duplicate header key '{key}' (first "
                                  f'given on line {where[key]})')
        values[key] = value
        where[key] = lineno


def _format_of(path: PathLike, header: _Header) -> str:
    """Return the header's format, checked to be a known one."""
    if 'format' not in header.values:
        line = header.column_line or header.n_lines
        raise DataFormatError(path, line, "missing '# format: ...' header line (known formats: "
                              f"{', '.join(FORMATS)})")
    fmt = header.values['format']
    if fmt not in FORMATS:
        raise DataFormatError(path, header.lines['format'], f'unknown format {fmt!r} '
                              f"(known formats: {', '.join(FORMATS)})")
    return fmt


def _header_numbers(path, header: _Header, numeric_keys: Sequence[str]) -> dict[str, float]:
    out: dict[str, float] = {}
    for key in sorted((k for k in numeric_keys if k in header.values),
                      key=lambda k: header.lines[k]):
        raw = header.values[key]
        value = parse_number(raw)
        if value is None:
            what = 'empty' if not raw else repr(raw)
            raise DataFormatError(path, header.lines[key], f"header key '{key}' must be a finite "
                                  f'number in SI units (no unit suffix), got {what}')
        out[key] = value
    return out


def _parameter_line(header: _Header, exc: ParameterError, keys: Sequence[str]) -> int:
    m = re.search(r"parameter '(\w+)'", str(exc))
    if m and m.group(1) in header.lines:
        return header.lines[m.group(1)]
    return min(header.lines[k] for k in keys if k in header.lines)


def _geometry_in_other_units(path, header: _Header, numbers: dict) -> None:
    """Accept ``length_mm``, ``thickness_um``... as ``length_m``, ``thickness_m`` (in place)."""
    for key in GEOMETRY_KEYS:
        part = key[:-2]
        given = [k for k in header.values if k.startswith(part + '_') and k != key
                 and unit_factor(k[len(part) + 1:], LENGTH_UNITS) is not None]
        if not given:
            continue
        keys = ([key] if key in header.values else []) + given
        if len(keys) > 1:
            raise DataFormatError(path, header.lines[given[-1]], f'the {part} is given twice: '
                                  + ', '.join(f"'{k}'" for k in keys))
        other = given[0]
        raw = header.values.pop(other)
        if parse_number(raw) is None:
            raise DataFormatError(path, header.lines[other], f"header key '{other}' must be a "
                                  f'finite number, got {raw!r}')
        numbers[key] = decimal_to_si(raw.strip(), unit_factor(other[len(part) + 1:],
                                                              LENGTH_UNITS))
        header.values[key] = raw
        header.lines[key] = header.lines.pop(other)


def _common_header(path, header: _Header, expected_format: str,
                   numeric_keys: Sequence[str], layouts: Sequence[tuple[str, ...]]):
    """Validate the header; return (sample, geometry, known, numbers, extra)."""
    fmt = _format_of(path, header)
    if fmt != expected_format:
        reader = 'read_frf' if fmt == FRF_FORMAT else 'read_timeseries'
        raise DataFormatError(path, header.lines['format'], f'format is {fmt!r}, expected '
                              f'{expected_format!r} (read it with {reader} or read_any)')
    numbers = _header_numbers(path, header, numeric_keys)
    if header.column_line is None:
        raise DataFormatError(
            path,
            header.n_lines,
            'the header is not followed by a column header '
            'line (expected '
            + ' or '.join(repr(','.join(c)) for c in layouts)
            + ') and data rows',
        )
    col_line = header.column_line
    _geometry_in_other_units(path, header, numbers)
    missing = [k for k in GEOMETRY_KEYS if k not in header.values]
    if missing:
        raise DataFormatError(path, col_line, 'missing required header key(s) '
                              + ', '.join(f"'{k}'" for k in missing)
                              + " (geometry in metres, e.g. '# length_m: 0.022')")
    sample = header.values.get('sample', '')
    try:
        geometry = Geometry(numbers['length_m'], numbers['width_m'], numbers['thickness_m'],
                            name=sample)
    except ParameterError as exc:
        raise DataFormatError(path, _parameter_line(header, exc, GEOMETRY_KEYS),
                              f'geometry out of physical range: {exc}') from None
    known = {k: numbers[k] for k in KNOWN_KEYS if k in numbers}
    try:
        MaterialParameters(**known)
    except ParameterError as exc:
        raise DataFormatError(path, _parameter_line(header, exc, tuple(known)),
                              f'implausible known value: {exc}') from None
    extra = {k: v for k, v in header.values.items() if k not in _RESERVED_KEYS}
    return sample, geometry, known, numbers, extra


def _parse_columns(path, header: _Header, layouts: Sequence[tuple[str, ...]],
                   bases: Sequence[str]) -> tuple[tuple[str, ...], tuple[float, ...]]:
    """(SI column names, factor of each column to SI) of the column-header line."""
    col_line = header.column_line
    raw = header.column_text
    names = tuple(c.strip() for c in raw.split(','))
    factors = [1.0] * len(names)
    canon = list(names)
    allowed = {n for c in layouts for n in c}
    for k, name in enumerate(names):
        if name not in allowed:
            found = column_to_si(name)
            if found is not None:
                canon[k], factors[k] = found
    if tuple(canon) in layouts:
        return tuple(canon), tuple(factors)
    expected = ' or '.join(repr(','.join(c)) for c in layouts)
    if all(parse_number(n) is not None for n in names):
        raise DataFormatError(path, col_line, f'missing column header line: found a data row '
                              f'{raw.strip()!r}; expected {expected}')
    other = _FRF_LAYOUTS if layouts is _TIMESERIES_LAYOUTS else _TIMESERIES_LAYOUTS
    if tuple(canon) in other:
        this, that = ((TIMESERIES_FORMAT, FRF_FORMAT) if layouts is _TIMESERIES_LAYOUTS
                      else (FRF_FORMAT, TIMESERIES_FORMAT))
        raise DataFormatError(path, col_line, f'the file declares format {this!r} but has the '
                              f'columns of {that!r}; expected {expected}')
    for name, good_name in zip(names, canon):
        if good_name in allowed:
            continue
        low = name.lower()
        match = [b for b in bases if low == b or low.startswith(b + '_')]
        if match:
            base = max(match, key=len)
            good, unit = _COLUMN_UNITS[base]
            accepted = f' or another unit of it ({column_units(base)})' if base != 'coherence' \
                else ''
            raise DataFormatError(path, col_line, f'wrong units in column header: {name!r} '
                                  f"should be '{good}' ({unit}){accepted}; expected {expected}")
        raise DataFormatError(path, col_line, f'unknown column {name!r}; expected {expected}')
    if (FRF_STD_COLUMNS[0] in names) != (FRF_STD_COLUMNS[1] in names):
        raise DataFormatError(path, col_line, f'columns {FRF_STD_COLUMNS[0]} and '
                              f'{FRF_STD_COLUMNS[1]} must come together; expected {expected}')
    raise DataFormatError(path, col_line, f'unexpected column header {raw.strip()!r} (columns '
                          f'missing, repeated or out of order); expected {expected}')


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


def _read_rows(source: TextSource, header: _Header, check, max_rows) -> list[np.ndarray]:
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


def _fmt(x: float) -> str:
    return repr(float(x))


# ---------------------------------------------------------------------------
# ipmc-timeseries/1
# ---------------------------------------------------------------------------
def _timeseries_from(path, source: TextSource, header: _Header, max_rows) -> TimeSeries:
    sample, geometry, known, numbers, extra = _common_header(
        path, header, TIMESERIES_FORMAT, _TIMESERIES_NUMERIC_KEYS, _TIMESERIES_LAYOUTS)
    columns, factors = _parse_columns(path, header, _TIMESERIES_LAYOUTS, _TIMESERIES_BASES)
    tname = header.column_text.split(',')[0].strip()
    tunit = tname.partition('_')[2]

    data = _read_rows(source, header, increasing_check(path, tname, tunit), max_rows)
    data = [to_si(col, factor) if factor != 1.0 else col for col, factor in zip(data, factors)]
    t = data[0]
    if np.any(np.diff(t) <= 0):  # a sub-ns step in ms/us lost to rounding when converted
        k = int(np.argmax(np.diff(t) <= 0)) + 1
        raise DataFormatError(path, header.column_line + 1 + k, f'time step below float '
                              f'resolution after conversion to seconds at {_fmt(t[k])} s')
    median_dt = float(np.median(np.diff(t)))
    measured_rate = 1.0 / median_dt
    rate = numbers.get('sample_rate_hz')
    if rate is None:
        rate = measured_rate
    elif rate <= 0.0:
        raise DataFormatError(path, header.lines['sample_rate_hz'], f'sample_rate_hz must be > 0, '
                              f'got {_fmt(rate)}')
    elif abs(rate * median_dt - 1.0) > SAMPLE_RATE_TOLERANCE:
        raise DataFormatError(path, header.lines['sample_rate_hz'],
                              f'sample_rate_hz = {_fmt(rate)} disagrees with the time column: '
                              f'median step {median_dt:.6g} s -> {measured_rate:.6g} Hz '
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
    """Read an ``ipmc-timeseries/1`` file (see the module docstring)."""
    with TextSource(path, max_bytes=max_bytes) as source:
        return _timeseries_from(path, source, _parse_header(path, source), max_rows)


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
    out += [f'# length_m: {_fmt(geometry.length_m)}', f'# width_m: {_fmt(geometry.width_m)}',
            f'# thickness_m: {_fmt(geometry.thickness_m)}']
    out += [f'# {k}: {_fmt(v)}' for k, v in numbers]
    for key in KNOWN_KEYS:
        if key in known:
            out.append(f'# {key}: {_fmt(known[key])}')
    unknown_known = sorted(set(known) - set(KNOWN_KEYS))
    if unknown_known:
        raise DataFormatError(path, None, f'cannot write known value(s) {unknown_known} in a text '
                              f'file; the header knows {list(KNOWN_KEYS)}')
    for key, value in extra.items():
        key = single_line('extra key', key)
        if not _KEY.fullmatch(key) or key in _RESERVED_KEYS:
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


# ---------------------------------------------------------------------------
# ipmc-frf/1
# ---------------------------------------------------------------------------
def _frf_from(path, source: TextSource, header: _Header, max_rows) -> FrequencyResponseData:
    sample, geometry, known, _numbers, extra = _common_header(
        path, header, FRF_FORMAT, _FRF_NUMERIC_KEYS, _FRF_LAYOUTS)
    columns, factors = _parse_columns(path, header, _FRF_LAYOUTS, _FRF_BASES)
    coh = columns.index(FRF_COHERENCE_COLUMN) if FRF_COHERENCE_COLUMN in columns else None
    std = [columns.index(c) for c in FRF_STD_COLUMNS if c in columns]

    def row_check(row, prev, lineno, prev_line):
        f = row[0]
        if f <= 0.0:
            raise DataFormatError(path, lineno, f'non-positive frequency {_fmt(f)} Hz '
                                  '(frequency_hz must be > 0)')
        if prev is not None and f <= prev[0]:
            what = 'duplicate frequency' if f == prev[0] else 'frequency decreases:'
            raise DataFormatError(path, lineno, f'{what} {_fmt(f)} Hz after {_fmt(prev[0])} Hz on '
                                  f'line {prev_line}; frequency_hz must be strictly increasing')
        if row[1] <= 0.0:
            raise DataFormatError(path, lineno, f'non-positive gain {_fmt(row[1])} in column '
                                  'gain_A_per_m (a magnitude, must be > 0)')
        if coh is not None and not 0.0 <= row[coh] <= 1.0:
            raise DataFormatError(path, lineno, f'coherence {_fmt(row[coh])} outside [0, 1]')
        for k in std:
            if row[k] < 0.0:
                raise DataFormatError(path, lineno, f'negative standard uncertainty '
                                      f'{_fmt(row[k])} in column {columns[k]}')

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
    """Read an ``ipmc-frf/1`` file (see the module docstring)."""
    with TextSource(path, max_bytes=max_bytes) as source:
        return _frf_from(path, source, _parse_header(path, source), max_rows)


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


def read_text(path: PathLike, *, max_bytes: int | None = MAX_BYTES,
              max_rows: int | None = MAX_ROWS) -> TimeSeries | FrequencyResponseData:
    """Read a text file of either format, dispatched on its ``# format:`` line."""
    with TextSource(path, max_bytes=max_bytes) as source:
        header = _parse_header(path, source)
        if _format_of(path, header) == TIMESERIES_FORMAT:
            return _timeseries_from(path, source, header, max_rows)
        return _frf_from(path, source, header, max_rows)
