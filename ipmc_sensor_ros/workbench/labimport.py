# SPDX-License-Identifier: Apache-2.0
"""
Import of lab exports (DAQ, LabVIEW, spreadsheets) into ``ipmc-timeseries/1``.

A lab file is free text, then one column-header line, then numeric rows::

    LabVIEW Measurement
    Operator    jd
    Date        2024/03/12
    ...
    Time [s],Laser [mm],Current [uA]
    0.000,0.0012,0.031
    0.001,0.0013,0.029

* The column-header line is the last line before the first data row (a
  line of at least two numbers with the same cell count as the line above
  it); every non-empty line before it is kept as a note (``note_01``,
  ``note_02``... in ``extra``).
* Cells are separated by tab, ``;`` or ``,``; with tab or ``;`` the decimal
  mark may be ``,`` (``0,0012``).  Found from the first data row.
* Columns are found by name: time (``Time``, ``t``), deflection (``Laser``,
  ``deflection``, ``displacement``, ``tip``), current (``Current``, ``I``);
  ``columns={"time": ..., "deflection": ..., "current": ...}`` names them
  explicitly (an explicit name may add a unit, ``"t [ms]"``, for a column
  whose header has none).  Units come from ``[unit]``, ``(unit)`` or a
  ``_unit`` suffix: s, ms, us; m, mm, um/µm, nm; A, mA, uA/µA, nA, pA; V, mV or
  uV for a current measured as a transimpedance-amplifier voltage, which needs
  ``current_gain_a_per_v``.  A column without a unit is refused, never
  guessed.  The deflection column is optional (current-only records).
* A row whose time equals the row before's (a host that stamped twice in one clock tick)
  is not imported, as the estimator node refuses such a sample; the output's header and
  ``ipmc-model import`` say how many and where.  A time that decreases is an error.
* Geometry (free length L, width W, total thickness 2h) comes from the
  ``geometry`` argument, a run-metadata file ``meta`` and/or header lines
  such as ``Length: 22 mm``; two sources that differ are refused (see
  :mod:`.labmeta`).
"""
from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np

from ..errors import ParameterError
from .formatread import incomplete_notes
from .formats import write_timeseries
from .labmeta import (meta_values, one_line, read_run_metadata,
                      resolve_geometry)
from .measurements import DataFormatError, PathLike, TimeSeries
from .metrics import held_at_limit
from .stamps import measured_rate_hz
from .textread import (MAX_BYTES, MAX_ROWS, TextSource, increasing_check, parse_number,
                       read_table)
from .units import (CURRENT_UNITS, LENGTH_UNITS, TIME_UNITS, VOLTAGE_UNITS, split_unit, to_si,
                    unit_factor)

__all__ = ['import_lab_file', 'import_lab_files', 'parse_columns_spec', 'ROLE_NAMES']

#: Words that name each column role (matched against the words of a column stem).
ROLE_NAMES = {
    'time': ('time', 't', 'zeit'),
    'deflection': ('deflection', 'displacement', 'laser', 'tip', 'position', 'auslenkung'),
    'current': ('current', 'i', 'strom'),
}
_ROLE_UNITS = {'time': TIME_UNITS, 'deflection': LENGTH_UNITS, 'current': CURRENT_UNITS}
#: Encoding of a lab export that is not UTF-8: Windows' Western code page, in which LabVIEW and
#: spreadsheet exports on European lab PCs write 'µA' or 'Länge'.  Said in the output file
#: (``text_encoding``) and by ``ipmc-model import``.
LEGACY_ENCODING = 'cp1252'
#: The output header's key for rows dropped because their time repeats the row before's (a
#: host that stamps twice in one tick): the estimator node's counter of the same samples.
REPEATED_KEY = 'rejected_duplicate_stamp'
#: Most lines of free text searched for the column header.
MAX_HEADER_LINES = 500
_DIALECTS = (('\t', '.'), ('\t', ','), (';', '.'), (';', ','), (',', '.'))


def _is_row(line: str, delimiter: str, decimal: str) -> int:
    """
    Return the number of cells if ``line`` is a row of >= 2 numbers in this dialect, else 0.

    A delimiter that ends the line (spreadsheets write one) leaves an empty last cell, counted.
    """
    cells = line.rstrip('\r\n').split(delimiter)
    numbers = cells[:-1] if len(cells) > 2 and not cells[-1].strip() else cells
    if len(numbers) < 2:
        return 0
    return len(cells) if all(parse_number(c, decimal) is not None for c in numbers) else 0


def _find_table(path, source: TextSource):
    """
    Return (notes as (line, text), column-header cells, its line, delimiter, decimal).

    Source at the first row.
    """
    previous: list[tuple[int, str]] = []
    while True:
        line = source.next_line()
        if line is None or source.lineno > MAX_HEADER_LINES:
            where = 'the file' if line is None else f'the first {MAX_HEADER_LINES} lines'
            raise DataFormatError(path, source.lineno or 1, f'no table found in {where}: expected '
                                  'a column-header line followed by rows of numbers separated '
                                  "by tab, ';' or ','")
        if previous and line.strip():
            head_line, head = previous[-1]
            for delimiter, decimal in _DIALECTS:
                n = _is_row(line, delimiter, decimal)
                if n and len(head.split(delimiter)) == n and not _is_row(head, delimiter,
                                                                         decimal):
                    source.unread(line)
                    cells = [c.strip() for c in head.split(delimiter)]
                    names = _names_above_units(previous, cells, delimiter)
                    if names:                       # a names row, then a units row
                        head_line, cells = previous[-2][0], names
                        previous = previous[:-1]
                    notes = [(n, text.strip()) for n, text in previous[:-1] if text.strip()]
                    return notes, cells, head_line, delimiter, decimal
        if line.strip():
            previous.append((source.lineno, line))


def _names_above_units(previous, cells: list[str], delimiter: str) -> list[str] | None:
    """
    Return the column names with their units when ``cells`` is a row of units under them.

    Spreadsheet and LabVIEW exports often put the units in a row of their own (``Time,Laser,I``
    then ``s,mm,uA``): the names become ``Time [s]`` ...  None: ``cells`` are names.
    """
    if len(previous) < 2:
        return None
    units = [c.strip('[]() ') for c in cells]
    tables = (TIME_UNITS, LENGTH_UNITS, CURRENT_UNITS, VOLTAGE_UNITS)
    if not any(units) or not all(not u or any(unit_factor(u, t) is not None for t in tables)
                                 for u in units):
        return None
    names = [c.strip() for c in previous[-2][1].split(delimiter)]
    if len(names) != len(units) or not all(names):
        return None
    return [f'{n} [{u}]' if u else n for n, u in zip(names, units)]


def parse_columns_spec(text: str) -> dict[str, str]:
    """
    ``"time=Time [s],current=I (nA)"`` -> ``{"time": "Time [s]", "current": "I (nA)"}``.

    The text form of the ``columns`` argument (a CLI flag); raises ValueError
    naming the bad item, an unknown role or a role given twice.
    """
    out: dict[str, str] = {}
    for item in text.split(','):
        role, sep, name = item.partition('=')
        role, name = role.strip(), name.strip()
        if not sep or not name:
            raise ParameterError(f'columns: {item.strip()!r} is not role=column '
                                 '(e.g. time=Time [s],current=I (nA))')
        if role not in ROLE_NAMES:
            raise ParameterError(f'columns: unknown role {role!r}; roles are {list(ROLE_NAMES)}')
        if role in out:
            raise ParameterError(f'columns: role {role!r} given twice')
        out[role] = name
    return out


def _words(stem: str) -> list[str]:
    return [w for w in re.split(r'[^a-z0-9]+', stem.lower()) if w]


def _assign(path, cells: list[str], line: int, columns: Mapping[str, str] | None,
            current_in_volts: bool = False):
    """
    Map role -> (index, unit) of the file's columns.

    With ``current_in_volts`` (a transimpedance gain was given) and no column named as a current,
    the one remaining column whose unit is a voltage is the current.
    """
    found: dict[str, tuple[int, str | None]] = {}
    wanted = dict(columns or {})
    unknown = sorted(set(wanted) - set(ROLE_NAMES))
    if unknown:
        raise DataFormatError(path, None, f'columns: unknown role(s) {unknown}; roles are '
                              f'{list(ROLE_NAMES)}')
    for role, name in wanted.items():
        if name in cells:
            found[role] = (cells.index(name), split_unit(name)[1])
            continue
        stem, unit = split_unit(name)
        if stem in cells:
            file_unit = split_unit(stem)[1]
            found[role] = (cells.index(stem), unit or file_unit)
            continue
        raise DataFormatError(path, line, f'columns: {role}={name!r} is not a column of the file '
                              f'(columns: {cells})')
    for role, names in ROLE_NAMES.items():
        if role in found:
            continue
        hits = [k for k, c in enumerate(cells) if k not in {i for i, _ in found.values()}
                and set(_words(split_unit(c)[0])) & set(names)]
        if len(hits) > 1:
            raise DataFormatError(path, line, f'two columns could be the {role}: '
                                  f'{[cells[k] for k in hits]}; choose one with '
                                  f'--columns {role}=NAME')
        if hits:
            found[role] = (hits[0], split_unit(cells[hits[0]])[1])
    if 'current' not in found and current_in_volts:
        taken = {i for i, _ in found.values()}
        volts = [k for k, c in enumerate(cells) if k not in taken
                 and unit_factor(split_unit(c)[1] or '', VOLTAGE_UNITS) is not None]
        if len(volts) == 1:
            found['current'] = (volts[0], split_unit(cells[volts[0]])[1])
    for role in ('time', 'current'):
        if role not in found:
            raise DataFormatError(path, line, f'no {role} column among {cells}; name it with '
                                  f'--columns {role}=NAME')
    return found


def _factor(path, line: int, role: str, cell: str, unit: str | None,
            gain: float | None) -> float:
    """Factor from the column's unit to SI (A for a current measured in V, via ``gain``)."""
    if unit is None:
        raise DataFormatError(path, line, f'column {cell!r} ({role}) has no unit: write it as '
                              f"'{cell} [unit]' or name it with --columns '{role}={cell} [unit]'; "
                              f"units: {', '.join(_ROLE_UNITS[role])}")
    factor = unit_factor(unit, _ROLE_UNITS[role])
    if role == 'current':
        volts = unit_factor(unit, VOLTAGE_UNITS)
        if volts is not None:
            if gain is None:
                raise DataFormatError(path, line, f'column {cell!r} is a voltage: give the '
                                      'transimpedance of the current amplifier (--current-gain '
                                      'V_PER_A; current_gain_a_per_v in Python) to convert it '
                                      'to a current')
            return volts * gain
        if factor is not None and gain is not None:
            raise DataFormatError(path, line, f'current_gain_a_per_v = {gain!r} given but column '
                                  f'{cell!r} is already a current ({unit})')
    if factor is None:
        raise DataFormatError(path, line, f'column {cell!r} ({role}): unit {unit!r} is not a '
                              f"unit of {role}; units: {', '.join(_ROLE_UNITS[role])}")
    return factor


def import_lab_file(path: PathLike, *, geometry=None, meta: PathLike | None = None,
                    columns: Mapping[str, str] | None = None,
                    current_gain_a_per_v: float | None = None, sample: str | None = None,
                    max_bytes: int | None = MAX_BYTES,
                    max_rows: int | None = MAX_ROWS) -> TimeSeries:
    """
    Read a lab export into a :class:`TimeSeries` in SI units (see the module docstring).

    Parameters
    ----------
    path
        The lab file (CSV, TSV or ';'-separated text with a free header).
    geometry
        ``"22mm,7mm,360um"`` (length, width, total thickness), a
        :class:`Geometry` or a mapping with ``length_m``, ``width_m``, ``thickness_m``.
    meta
        Run-metadata JSON/YAML (geometry in any length unit, ``sample``,
        known values such as ``temperature_k``, anything else kept in ``extra``).
    columns
        Role -> column name (``time``, ``deflection``, ``current``).
    current_gain_a_per_v
        Transimpedance gain, A/V, for a current column in V.
    sample
        Sample name (else the metadata's ``sample``); a conflict is refused.
    max_bytes, max_rows
        Limits of the file (see :mod:`.textread`).

    """
    if current_gain_a_per_v is not None and not (math.isfinite(current_gain_a_per_v)
                                                 and current_gain_a_per_v > 0):
        raise DataFormatError(path, None, f'current_gain_a_per_v must be a finite number > 0, '
                              f'got {current_gain_a_per_v!r}')
    meta_data = read_run_metadata(meta) if meta is not None else {}
    meta_sample = meta_data.get('sample')
    if sample and meta_sample and str(meta_sample) != sample:
        raise DataFormatError(path, None, f'sample conflict: argument says {sample!r} but run '
                              f'metadata {meta} says {meta_sample!r}')
    name = one_line(sample or meta_sample or '')
    with TextSource(path, max_bytes=max_bytes, fallback_encoding=LEGACY_ENCODING) as source:
        notes, cells, line, delimiter, decimal = _find_table(path, source)
        geo, geometry_from = resolve_geometry(path, geometry, meta, meta_data, name, notes)
        roles = _assign(path, cells, line, columns, current_gain_a_per_v is not None)
        factors = {role: _factor(path, line, role, cells[k], unit, current_gain_a_per_v)
                   for role, (k, unit) in roles.items()}
        t_index, t_unit = roles['time']
        data, first_row = read_table(
            source, cells, increasing_check(path, cells[t_index], t_unit or '', t_index, True),
            delimiter=delimiter, decimal=decimal, max_rows=max_rows, header_line=line,
            empty_last=cells[-1] == '')
    repeated = np.flatnonzero(np.diff(data[t_index]) == 0) + 1
    if data[t_index].size - repeated.size < 2:
        raise DataFormatError(path, first_row + int(repeated[0]), 'only 1 data row with a time '
                              'of its own (the others repeat it); at least 2 are needed')
    kept = np.ones(data[t_index].size, bool)
    kept[repeated] = False              # a repeated stamp: the row after is refused, as the
    picked = {role: to_si(data[k][kept], factors[role])        # node refuses the sample
              for role, (k, _) in roles.items()}
    k_current = roles['current'][0]     # (a deflection holds its top for a hold: not said)
    held = held_at_limit(data[k_current][kept])
    limits = {'current_at_limit': f'{cells[k_current]}: {held}'} if held else {}
    del data
    t = picked['time']
    steps = np.diff(t)
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0)) + 1
        raise DataFormatError(path, line + 1 + k, f'time step below float resolution after '
                              f'conversion to seconds at {t[k]!r} s')
    extra: dict[str, str] = {f'note_{k + 1:02d}': one_line(n)
                             for k, (_, n) in enumerate(notes)}
    extra['lab_columns'] = one_line(', '.join(f'{role}={cells[k]}'
                                              for role, (k, _) in roles.items()))
    if geometry_from:
        extra['geometry_from'] = one_line('; '.join(f"{source} ({', '.join(texts)})"
                                                    for source, texts in geometry_from.items()))
    extra.update(limits)
    if source.encoding != 'utf-8':
        extra['text_encoding'] = source.encoding
    if repeated.size:
        lines = ', '.join(str(first_row + k) for k in repeated[:5])
        extra[REPEATED_KEY] = f"{repeated.size} (line{'s' if repeated.size > 1 else ''} " \
                              f"{lines}{', ...' if repeated.size > 5 else ''})"
    used = {k for k, _ in roles.values()}
    unused = [c for k, c in enumerate(cells) if k not in used and c]   # '': a trailing delimiter
    if unused:
        extra['unused_columns'] = one_line(', '.join(unused))
    if current_gain_a_per_v is not None:
        extra['current_gain_a_per_v'] = repr(float(current_gain_a_per_v))
    known, notes = meta_values(meta, meta_data)
    extra.update(notes)
    return TimeSeries(path=str(path), sample=name, geometry=geo, known=known,
                      sample_rate_hz=measured_rate_hz(t), time_s=t,
                      current_a=picked['current'], deflection_m=picked.get('deflection'),
                      extra=extra, notes=incomplete_notes(path, source))


#: What the import says of a file (``notice``), by the output header key that records it.
_NOTICES = (
    ('text_encoding', 'not UTF-8 text: read as {} (Windows Western); check the units and '
                      'names it printed'),
    ('unused_columns', 'column(s) not imported: {} (name one with --columns deflection=NAME '
                       'or current=NAME)'),
    (REPEATED_KEY, 'row(s) with the time of the row before not imported: {} (the estimator '
                   'node refuses such a sample too)'),
    ('meta_keys_left_out', 'run metadata key(s) not kept as notes (a header key is a letter, '
                           "then letters, digits, '_', '.' or '-'): {}"),
    ('geometry_from', 'geometry from {}'),
    ('current_at_limit', '{} (an amplifier rail or the ADC range clips it there: no sensor '
                         'model predicts those rows)'),
)


def import_lab_files(paths: Iterable[PathLike], out_dir: PathLike, *,
                     overwrite: bool = False, notice=None, **options) -> list[Path]:
    """
    Import each lab file and write it as ``<out_dir>/<stem>.csv`` (``ipmc-timeseries/1``).

    All files are read first and nothing is written if any fails; an existing
    output is refused unless ``overwrite``.  ``options`` are those of
    :func:`import_lab_file`.  ``notice(text)`` is told what was read other than as asked (a
    file that is not UTF-8, geometry taken from a file header).  Returns the written paths, in
    input order.
    """
    paths = [Path(p) for p in paths]
    out = Path(out_dir)
    targets = [out / f'{p.stem}.csv' for p in paths]
    seen: dict[Path, Path] = {}
    for src, dst in zip(paths, targets):
        if dst in seen:
            raise DataFormatError(src, None, f'same output name {dst.name} as {seen[dst]}; '
                                  'rename one of the files')
        seen[dst] = src
        if dst.exists() and not overwrite:
            raise DataFormatError(dst, None, 'output exists; not replaced (pass --overwrite to '
                                  'replace it, or choose another --out)')
    series = [import_lab_file(p, **options) for p in paths]
    for src, ts in zip(paths, series if notice is not None else ()):
        for note in ts.notes:
            notice(note)
        for key, text in _NOTICES:
            if key in ts.extra:
                notice(f'{src}: ' + text.format(ts.extra[key])
                       + ('; no deflection column found' if key == 'unused_columns'
                          and ts.deflection_m is None else ''))
    out.mkdir(parents=True, exist_ok=True)
    for ts, dst in zip(series, targets):
        write_timeseries(dst, ts)
    return targets
