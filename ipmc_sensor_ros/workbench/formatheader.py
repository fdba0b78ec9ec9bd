# SPDX-License-Identifier: Apache-2.0
"""
Header and column-header line of the workbench text formats (no rclpy needed).

Shared by the readers (:mod:`.formatread`) and writers (:mod:`.formats`) of
``ipmc-timeseries/1`` and ``ipmc-frf/1``; the specification is the docstring
of :mod:`.formats`.  This module holds the format names, the accepted column
layouts and header keys of each format, and the parsing and validation of the
lines before the data rows: ``# key: value`` header lines (geometry checked by
:class:`~ipmc_sensor_ros.physics.parameters.Geometry`, known values by
:class:`~ipmc_sensor_ros.physics.parameters.MaterialParameters`) and the
column-header line (columns in other units mapped to their SI names and
factors).  Every problem raises :class:`DataFormatError` naming the file and
line.
"""
from __future__ import annotations

import difflib

import re
from dataclasses import dataclass
from typing import Sequence

from ..physics.parameters import Geometry, MaterialParameters, ParameterError
from .measurements import DataFormatError, PathLike
from .textread import TextSource, parse_number
from .units import LENGTH_UNITS, column_to_si, column_units, decimal_to_si, unit_factor

__all__ = [
    'TIMESERIES_FORMAT', 'FRF_FORMAT', 'FORMATS', 'TIMESERIES_COLUMNS',
    'TIMESERIES_COLUMNS_NO_DEFLECTION', 'FRF_COLUMNS', 'FRF_COHERENCE_COLUMN', 'FRF_STD_COLUMNS',
    'GEOMETRY_KEYS', 'KNOWN_KEYS', 'TIMESERIES_LAYOUTS', 'FRF_LAYOUTS', 'TIMESERIES_NUMERIC_KEYS',
    'FRF_NUMERIC_KEYS', 'RESERVED_KEYS', 'TIMESERIES_BASES', 'FRF_BASES', 'HEADER_KEY_PATTERN',
    'TextHeader', 'parse_header', 'header_format', 'validate_header', 'parse_columns',
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
TIMESERIES_LAYOUTS = (TIMESERIES_COLUMNS, TIMESERIES_COLUMNS_NO_DEFLECTION)
FRF_LAYOUTS = (
    FRF_COLUMNS,
    FRF_COLUMNS + (FRF_COHERENCE_COLUMN,),
    FRF_COLUMNS + FRF_STD_COLUMNS,
    FRF_COLUMNS + (FRF_COHERENCE_COLUMN,) + FRF_STD_COLUMNS,
)

GEOMETRY_KEYS = ('length_m', 'width_m', 'thickness_m')
#: Optional known physical values (header keys; :class:`MaterialParameters` names).
KNOWN_KEYS = ('temperature_k', 'youngs_modulus_pa', 'surface_resistance_ohm')
#: Numeric header keys of each format; keys the reader interprets (not kept as ``extra``).
TIMESERIES_NUMERIC_KEYS = GEOMETRY_KEYS + ('sample_rate_hz',) + KNOWN_KEYS
FRF_NUMERIC_KEYS = GEOMETRY_KEYS + KNOWN_KEYS
RESERVED_KEYS = ('format', 'sample') + GEOMETRY_KEYS + ('sample_rate_hz',) + KNOWN_KEYS
#: A header key that is not the format's but this close to one of its keys (difflib's
#: ratio: 'temperatur_k' 0.96, 'length' 0.86 against 'length_m') is taken for a misspelling
#: and refused, since a value meant for the model would otherwise be ignored; other keys
#: ('operator', 'amplifier_gain') are notes, kept as ``extra``.
NEAR_MISS = 0.85

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
#: Quantities of the columns of each format (column names without their unit).
TIMESERIES_BASES = ('time', 'deflection', 'current')
FRF_BASES = ('frequency', 'gain', 'phase', 'coherence', 'gain_std', 'phase_std')

#: A valid header key.
HEADER_KEY_PATTERN = re.compile(r'[A-Za-z][A-Za-z0-9_.\-]*')


# ---------------------------------------------------------------------------
# Text files: header and columns
# ---------------------------------------------------------------------------
@dataclass
class TextHeader:
    """The lines of a text file before its data rows, as read (values not yet checked)."""

    values: dict               # key -> raw string value
    lines: dict                # key -> 1-based line
    column_line: int | None    # 1-based line of the column-header line (None: end of file)
    column_text: str           # the column-header line ('' if none)
    n_lines: int               # lines read (all of them when column_line is None)


def parse_header(path: PathLike, source: TextSource) -> TextHeader:
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
            return TextHeader(values, where, None, '', source.lineno)
        s = line.strip()
        seen_text = seen_text or bool(s)
        if s and not s.startswith('#'):
            return TextHeader(values, where, source.lineno, line, source.lineno)
        body = s[1:].strip()
        if not body:
            continue
        lineno = source.lineno
        if ':' not in body:
            raise DataFormatError(path, lineno, f"header line without ':' separator: {s!r} "
                                  "(expected '# key: value')" + _import_hint(values))
        key, _, value = body.partition(':')
        key, value = key.strip(), value.strip()
        if not HEADER_KEY_PATTERN.fullmatch(key):
            raise DataFormatError(path, lineno, f'invalid header key {key!r} in {s!r} '
                                  "(expected '# key: value', key [A-Za-z][A-Za-z0-9_.-]*)"
                                  + _import_hint(values))
        if key in values:
            raise DataFormatError(path, lineno, f"duplicate header key '{key}' (first "
                                  f'given on line {where[key]})')
        values[key] = value
        where[key] = lineno


def _import_hint(values: dict) -> str:
    """Where no format line came yet, the file may be a lab program's own: say what reads it."""
    return '' if 'format' in values else f'; {OWN_FILE_HINT}'


#: a DAQ's or lab program's file is not one of ours: what converts it
OWN_FILE_HINT = "a DAQ's or lab program's own file is converted by `ipmc-model import`"


def header_format(path: PathLike, header: TextHeader) -> str:
    """Return the header's format, checked to be a known one."""
    if 'format' not in header.values:
        line = header.column_line or header.n_lines
        raise DataFormatError(path, line, "missing '# format: ...' header line (known formats: "
                              f"{', '.join(FORMATS)}; {OWN_FILE_HINT})")
    fmt = header.values['format']
    if fmt not in FORMATS:
        raise DataFormatError(path, header.lines['format'], f'unknown format {fmt!r} '
                              f"(known formats: {', '.join(FORMATS)})")
    return fmt


def _header_numbers(path, header: TextHeader, numeric_keys: Sequence[str]) -> dict[str, float]:
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


def _parameter_line(header: TextHeader, exc: ParameterError, keys: Sequence[str]) -> int:
    m = re.search(r"parameter '(\w+)'", str(exc))
    if m and m.group(1) in header.lines:
        return header.lines[m.group(1)]
    return min(header.lines[k] for k in keys if k in header.lines)


def _geometry_in_other_units(path, header: TextHeader, numbers: dict) -> None:
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


def validate_header(path, header: TextHeader, expected_format: str,
                    numeric_keys: Sequence[str], layouts: Sequence[tuple[str, ...]]):
    """Validate the header; return (sample, geometry, known, numbers, extra)."""
    fmt = header_format(path, header)
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
    extra = {k: v for k, v in header.values.items() if k not in RESERVED_KEYS}
    for key in extra:               # a misspelt key is named before it is missed
        near = difflib.get_close_matches(key, RESERVED_KEYS, n=1, cutoff=NEAR_MISS)
        if near:
            raise DataFormatError(path, header.lines.get(key), f'header key {key!r} is not '
                                  f'one of the format; did you mean {near[0]!r}? (keys that '
                                  'are not near one are kept as notes)')
    missing = [k for k in GEOMETRY_KEYS if k not in header.values]
    if missing:
        example = {'length_m': '0.022', 'width_m': '0.007', 'thickness_m': '0.00036'}
        raise DataFormatError(path, col_line, 'missing required header key(s) '
                              + ', '.join(f"'{k}'" for k in missing)
                              + f" (geometry in metres, e.g. '# {missing[0]}: "
                              + f"{example[missing[0]]}')")
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
    return sample, geometry, known, numbers, extra


def parse_columns(path, header: TextHeader, layouts: Sequence[tuple[str, ...]],
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
    other = FRF_LAYOUTS if layouts is TIMESERIES_LAYOUTS else TIMESERIES_LAYOUTS
    if tuple(canon) in other:
        this, that = ((TIMESERIES_FORMAT, FRF_FORMAT) if layouts is TIMESERIES_LAYOUTS
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
