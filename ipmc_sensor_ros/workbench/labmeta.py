# SPDX-License-Identifier: Apache-2.0
"""
Geometry and run metadata of a lab export, for :mod:`.labimport`.

Geometry (free length L, width W, total thickness 2h) comes from ``geometry``
(``"22mm,7mm,360um"``, a :class:`Geometry`, or a mapping in metres) and/or a
run-metadata file ``meta`` (JSON or YAML) with ``length_mm``/``width_mm``/``thickness_um``
(any length unit suffix, or values like ``"22 mm"``; optionally under ``geometry:``)
and/or the file's free-text header: a line such as ``Length: 22 mm``,
``thickness = 0.36 mm`` or ``Width [mm]: 7`` (English or German part names,
:data:`HEADER_GEOMETRY_NAMES`; ``:`` or ``=``; the unit after the value or in brackets;
several parts on one line separated by ``;`` or tabs).  When two sources give a value
and they differ, the import is refused naming both.
"""
from __future__ import annotations

import difflib
import json
import math
import os
import re
import stat
from pathlib import Path
from typing import Mapping

from ..physics.parameters import Geometry, MaterialParameters, ParameterError
from .formatheader import HEADER_KEY_PATTERN, KNOWN_KEYS, NEAR_MISS
from .measurements import DataFormatError, PathLike
from .units import LENGTH_UNITS, decimal_to_si, parse_length, unit_factor

__all__ = ['HEADER_GEOMETRY_NAMES', 'MAX_META_BYTES', 'GEOMETRY_PARTS', 'read_run_metadata',
           'geometry_from_header', 'resolve_geometry', 'meta_values', 'one_line']

#: The parts of a geometry, in the order of ``--geometry length,width,thickness``.
GEOMETRY_PARTS = ('length', 'width', 'thickness')
#: The keys a run-metadata file is read for; any other is kept as a note (``meta.<key>``).
META_KEYS = (('sample', 'geometry') + KNOWN_KEYS + GEOMETRY_PARTS
             + tuple(f'{part}_{unit}' for part in GEOMETRY_PARTS for unit in LENGTH_UNITS))
#: Largest run-metadata file read, bytes.
MAX_META_BYTES = 1 << 20


def read_run_metadata(meta: PathLike) -> dict:
    """Return the mapping of a run-metadata file (JSON by its suffix, else YAML)."""
    p = Path(meta)
    try:
        st = os.stat(p)
        if not stat.S_ISREG(st.st_mode) or st.st_size > MAX_META_BYTES:
            raise DataFormatError(meta, None, f'run metadata must be a regular file of at most '
                                  f'{MAX_META_BYTES} bytes')
        text = p.read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError) as exc:
        raise DataFormatError(meta, None, f'cannot read run metadata: {exc}') from None
    try:
        if p.suffix.lower() == '.json':
            data = json.loads(text)
        else:
            import yaml

            data = yaml.safe_load(text)
    except ValueError as exc:  # json.JSONDecodeError and yaml.YAMLError are ValueErrors or not
        raise DataFormatError(meta, getattr(exc, 'lineno', None),
                              f'run metadata is not valid JSON: {exc}') from None
    except Exception as exc:  # yaml.YAMLError
        mark = getattr(exc, 'problem_mark', None)
        raise DataFormatError(meta, mark.line + 1 if mark else None,
                              f'run metadata is not valid YAML: '
                              f"{getattr(exc, 'problem', None) or exc}") from None
    if not isinstance(data, dict):
        raise DataFormatError(meta, None, 'run metadata must be a mapping (JSON object)')
    inner = data.get('geometry')
    for key in list(data) + (list(inner) if isinstance(inner, dict) else []):
        if str(key).partition('_')[0] not in GEOMETRY_PARTS:
            _refuse_near_miss(meta, key)
    return data


def one_line(text) -> str:
    """Return ``text`` as one line: its words joined by single spaces (a header value)."""
    return ' '.join(str(text).split())


def meta_values(meta: PathLike, data: dict) -> tuple[dict, dict]:
    """
    Return (known values in SI units, notes) of run metadata (its geometry read elsewhere).

    ``temperature_k`` and the other known keys must be numbers, plausible together; any
    other key is a note ``meta.<key>`` (one line, 200 characters); a key no header line can
    hold (``HEADER_KEY_PATTERN``: ``Operator Name``, ``7``) is named under
    ``meta_keys_left_out``, not dropped unsaid.
    """
    known: dict[str, float] = {}
    notes: dict[str, str] = {}
    left_out: list[str] = []
    for key, value in data.items():
        if key in KNOWN_KEYS:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise DataFormatError(meta, None, f'run metadata {key}: {value!r} must be a '
                                      'number in SI units')
            known[key] = float(value)
        elif key in ('sample', 'geometry') or str(key).partition('_')[0] in GEOMETRY_PARTS:
            continue
        elif not HEADER_KEY_PATTERN.fullmatch(str(key)):
            left_out.append(str(key))
        elif isinstance(value, (str, int, float, bool)):
            text = one_line(value)[:200]
            if text:
                notes[f'meta.{key}'] = text
        else:
            notes[f'meta.{key}'] = '(nested value, not kept)'
    if left_out:
        notes['meta_keys_left_out'] = one_line(', '.join(left_out))[:200]
    try:
        MaterialParameters(**known)
    except (ParameterError, TypeError) as exc:
        raise DataFormatError(meta, None, f'implausible known value: {exc}') from None
    return known, notes


def _refuse_near_miss(meta: PathLike, key) -> None:
    """
    Refuse a run-metadata key that is not read but near one that is (a misspelling).

    As a data header's keys (:data:`.formatheader.NEAR_MISS`): ``temperatur_k`` would
    otherwise be kept as a note and the temperature it meant silently not used.
    """
    near = difflib.get_close_matches(str(key).lower(), META_KEYS, n=1, cutoff=NEAR_MISS)
    if near and near[0] != key:         # 'Temperature_K' too: the keys are read as written
        raise DataFormatError(meta, None, f'run metadata key {key!r} is not one it reads; did '
                              f'you mean {near[0]!r}? (keys that are not near one are kept as '
                              'notes)')


def _meta_geometry(meta: PathLike, data: dict) -> dict[str, tuple[float, str]]:
    """Map part -> (metres, 'key: value as written') from run metadata."""
    source = data.get('geometry', data)
    if not isinstance(source, dict):
        raise DataFormatError(meta, None, "'geometry' in run metadata must be a mapping")
    out: dict[str, tuple[float, str]] = {}
    for key, value in source.items():
        part, _, unit = str(key).partition('_')
        if part not in GEOMETRY_PARTS:
            continue
        try:
            if unit:
                factor = unit_factor(unit, LENGTH_UNITS)
                if (
                    factor is None
                    or isinstance(value, bool)
                    or not isinstance(value, (int, float))
                ):
                    raise ValueError(f'expected a number in {unit!r}, a length unit')
                metres = decimal_to_si(value, factor)
            elif isinstance(value, str):
                metres = parse_length(value)
            else:
                raise ValueError("give the unit: length_mm: 22 or length: '22 mm'")
        except ValueError as exc:
            raise DataFormatError(meta, None, f'run metadata {key}: {value!r}: {exc}') from None
        if part in out:
            raise DataFormatError(meta, None, f'run metadata gives the {part} twice '
                                  f'({out[part][1]} and {key}: {value})')
        out[part] = (metres, f'{key}: {value}')
    return out


#: Names of the geometry parts in a free-text header (English and, like the column names,
#: German: 'Länge: 22 mm').
HEADER_GEOMETRY_NAMES = {'length': 'length', 'länge': 'length', 'laenge': 'length',
                         'width': 'width', 'breite': 'width',
                         'thickness': 'thickness', 'dicke': 'thickness', 'stärke': 'thickness'}
#: A geometry line of a free-text header: part name, optional [unit], ':' or '=', value, unit.
_HEADER_GEOMETRY = re.compile(
    r'^\W*(' + '|'.join(HEADER_GEOMETRY_NAMES) + r')\s*(?:[\[(]\s*([^\])]+?)\s*[\])])?\s*[:=]\s*'
    r'([-+]?\d+(?:[.,]\d+)?(?:[eE][-+]?\d+)?)\s*([A-Za-zµμ]*)\s*[;,]?\s*$', re.IGNORECASE)


def geometry_from_header(path, notes) -> dict[str, tuple[float, str]]:
    """Map part -> (metres, 'file:line: text') from header lines such as ``Length: 22 mm``."""
    out: dict[str, tuple[float, str]] = {}
    for line, text in notes:
        for piece in re.split(r'[;\t]', text) if ';' in text or '\t' in text else [text]:
            m = _HEADER_GEOMETRY.match(piece.strip())
            if not m:
                continue
            part, unit = HEADER_GEOMETRY_NAMES[m.group(1).lower()], m.group(2) or m.group(4)
            where = f'line {line}: {piece.strip()}'
            try:
                metres = parse_length(f'{m.group(3).replace(",", ".")} {unit}')
            except ValueError as exc:
                raise DataFormatError(path, line, f'header {part}: {exc}') from None
            if part in out and not math.isclose(out[part][0], metres, rel_tol=1e-9):
                raise DataFormatError(path, line, f'the header gives the {part} twice '
                                      f'({out[part][1]} and {piece.strip()})')
            out[part] = (metres, where)
    return out


def _flag_geometry(geometry) -> dict[str, tuple[float, str]]:
    if isinstance(geometry, Geometry):
        return {p: (getattr(geometry, f'{p}_m'), f"{p}_m={getattr(geometry, f'{p}_m')!r}")
                for p in GEOMETRY_PARTS}
    if isinstance(geometry, Mapping):
        return {p: (float(geometry[f'{p}_m']), f"{p}_m={geometry[f'{p}_m']!r}")
                for p in GEOMETRY_PARTS if f'{p}_m' in geometry}
    parts = [s.strip() for s in str(geometry).split(',')]
    if len(parts) != 3:
        raise ValueError(f'geometry {geometry!r}: expected length,width,thickness with units, '
                         'e.g. 22mm,7mm,360um')
    return {p: (parse_length(v), v) for p, v in zip(GEOMETRY_PARTS, parts)}


def resolve_geometry(path, geometry, meta, meta_data: dict, sample: str, notes) -> tuple:
    """
    Return the geometry given by the argument, the run metadata and the header lines.

    And where it came from other than the argument: ``{source: [texts as written]}`` (the
    header's lines by number: their text is kept as notes; a part given twice alike is from
    the first).  Two sources that give a part differently are
    refused naming both; a part none of them gives is an error.
    """
    try:
        flag = _flag_geometry(geometry) if geometry is not None else {}
    except (ValueError, KeyError) as exc:
        raise DataFormatError(path, None, f'geometry argument: {exc}') from None
    sources = (('the geometry argument', flag),
               (f'run metadata {meta}', _meta_geometry(meta, meta_data) if meta is not None
                else {}),
               ('the file header', geometry_from_header(path, notes)))
    values, origin = {}, {}
    for part in GEOMETRY_PARTS:
        given = [(name, got[part]) for name, got in sources if part in got]
        for name, (metres, text) in given[1:]:
            first, (first_m, first_text) = given[0]
            if not math.isclose(metres, first_m, rel_tol=1e-9):
                raise DataFormatError(path, None, f'{part} conflict: {first} says {first_text} '
                                      f'({first_m!r} m) but {name} says {text} ({metres!r} m); '
                                      'fix one of them')
        if given:
            values[part] = given[0][1][0]
            name, (_, text) = given[0]
            if name == sources[2][0]:
                text = text.split(':')[0]      # 'line 2': its text is kept as a note
            if name != sources[0][0] and text not in origin.setdefault(name, []):
                origin[name].append(text)
    missing = [p for p in GEOMETRY_PARTS if p not in values]
    if missing:
        raise DataFormatError(path, None, f"no {', '.join(missing)}: give the geometry "
                              '(--geometry 22mm,7mm,360um, i.e. length,width,thickness), a run '
                              'metadata file (--meta) with length_mm, width_mm, thickness_um, '
                              "or header lines such as 'Length: 22 mm'")
    try:
        return Geometry(values['length'], values['width'], values['thickness'],
                        name=sample), origin
    except ParameterError as exc:
        raise DataFormatError(path, None, f'geometry out of physical range: {exc}') from None
