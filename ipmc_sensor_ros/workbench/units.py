# SPDX-License-Identifier: Apache-2.0
"""
Units in column names and geometry strings, converted to SI (no rclpy needed).

One table per physical dimension maps a unit symbol to its factor to SI;
``u``, ``µ`` (U+00B5) and ``μ`` (U+03BC) all mean micro.  Lookup is exact
first, then case-insensitive (``MM`` = mm, ``ua`` = uA; each table has no two
symbols differing only in case).
"""
from __future__ import annotations

import math
import re
from decimal import Decimal

import numpy as np

from ..errors import ParameterError

__all__ = ['TIME_UNITS', 'LENGTH_UNITS', 'CURRENT_UNITS', 'VOLTAGE_UNITS', 'QUANTITY_UNITS',
           'SI_SYMBOL', 'unit_factor', 'to_si', 'decimal_to_si',
           'column_to_si', 'column_units', 'split_unit', 'parse_length']

TIME_UNITS = {'s': 1.0, 'ms': 1e-3, 'us': 1e-6}
LENGTH_UNITS = {'m': 1.0, 'mm': 1e-3, 'um': 1e-6, 'nm': 1e-9}
CURRENT_UNITS = {'A': 1.0, 'mA': 1e-3, 'uA': 1e-6, 'nA': 1e-9, 'pA': 1e-12}
VOLTAGE_UNITS = {'V': 1.0, 'mV': 1e-3, 'uV': 1e-6}

#: Unit table of each time-series quantity.
QUANTITY_UNITS = {'time': TIME_UNITS, 'deflection': LENGTH_UNITS, 'current': CURRENT_UNITS}
#: SI symbol of each quantity (the canonical column is ``<quantity>_<symbol>``).
SI_SYMBOL = {'time': 's', 'deflection': 'm', 'current': 'A'}


def to_si(value, factor: float):
    """
    ``value * factor``; by a power of ten, each value's decimal form shifted.

    A file writes decimals: '0.1257' nA is the double nearest 1.257e-10 A, while a binary
    quotient lands an ulp off for about one value in four (0.1257 / 1e9 gives
    1.2570000000000002e-10), and every file written after shows it.  So each finite value's
    shortest decimal form (repr: what the file wrote, unless it held more than 17 digits) is
    read again with its exponent moved (~0.5 s per million values; ``360`` um: 0.00036 m, where
    ``360 * 1e-6`` gives 0.00035999999999999997).  Other factors (a transimpedance gain)
    multiply.
    """
    exponent = round(math.log10(factor)) if factor > 0.0 else 0
    if exponent == 0 or not math.isclose(10.0 ** exponent, factor, rel_tol=1e-12):
        return value * factor
    arr = np.asarray(value, dtype=float)
    out = np.array(arr * factor, dtype=float)           # NaN and Inf as they were
    finite = np.isfinite(arr)
    out[finite] = [_shifted(repr(v), exponent) for v in arr[finite].tolist()]
    return out if arr.ndim else float(out)


def _shifted(text: str, exponent: int) -> float:
    """Return the decimal ``text`` (a float's repr) times 10**exponent, rounded once."""
    mantissa, _, power = text.partition('e')
    return float(f'{mantissa}e{int(power or 0) + exponent}')


def decimal_to_si(value: str | float, factor: float) -> float:
    """
    One value in SI, rounded once from its decimal form.

    ``'0.36'`` mm -> 0.00036 m, where ``0.36 / 1000`` gives
    0.00035999999999999997.
    """
    exponent = round(math.log10(factor))
    if math.isclose(10.0 ** exponent, factor, rel_tol=1e-12):
        return float(Decimal(str(value)).scaleb(exponent))
    return float(value) * factor


_MICRO = str.maketrans({'\u00b5': 'u', '\u03bc': 'u'})


def unit_factor(unit: str, table: dict) -> float | None:
    """Factor from ``unit`` to SI in ``table``, or None if ``unit`` is not in it."""
    u = unit.strip().translate(_MICRO)
    if u in table:
        return table[u]
    low = {k.lower(): v for k, v in table.items()}
    return low.get(u.lower())


_BRACKETED = re.compile(r'^(?P<stem>.*?)\s*(?:\[(?P<b>[^\]]*)\]|\((?P<p>[^)]*)\))\s*$')
_SUFFIX = re.compile(r'^(?P<stem>.+?)_(?P<u>[A-Za-z\u00b5\u03bc]+)$')


def split_unit(name: str) -> tuple[str, str | None]:
    """
    (stem, unit) of a column name: ``Time [s]``, ``Laser (mm)``, ``current_uA``.

    A ``_suffix`` counts as a unit only if it is a symbol of one of the
    tables; otherwise the whole name is the stem and the unit is None.
    """
    s = name.strip()
    m = _BRACKETED.match(s)
    if m:
        unit = m.group('b') if m.group('b') is not None else m.group('p')
        return m.group('stem').strip(), unit.strip()
    m = _SUFFIX.match(s)
    if m and any(unit_factor(m.group('u'), t) is not None
                 for t in (TIME_UNITS, LENGTH_UNITS, CURRENT_UNITS, VOLTAGE_UNITS)):
        return m.group('stem'), m.group('u')
    return s, None


_LENGTH_VALUE = re.compile(r'^\s*([+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?)'
                           r'\s*([A-Za-z\u00b5\u03bc]+)\s*$')


def parse_length(text: str) -> float:
    """
    Metres of a length with a unit: ``22mm``, ``360 um``, ``0.36 µm``, ``0.022 m``.

    A bare number is refused (the unit must be said); raises ValueError.
    """
    m = _LENGTH_VALUE.match(text)
    if not m or not m.group(1).isascii():
        raise ParameterError(f'{text.strip()!r} is not a length with a unit (e.g. 22mm, 360um)')
    factor = unit_factor(m.group(2), LENGTH_UNITS)
    if factor is None:
        raise ParameterError(f'{text.strip()!r}: unknown length unit {m.group(2)!r} '
                             f"(known: {', '.join(LENGTH_UNITS)})")
    return decimal_to_si(m.group(1), factor)


FREQUENCY_UNITS = {'hz': 1.0, 'khz': 1e3, 'rad_s': 1.0 / (2.0 * math.pi)}
PHASE_UNITS = {'deg': 1.0, 'rad': 180.0 / math.pi}
#: Column bases of the text formats, longest first, with their SI column names.
_BASES = ('deflection', 'frequency', 'gain_std', 'phase_std', 'current', 'phase', 'gain', 'time')


def column_units(base: str) -> str:
    """Return the units accepted after ``<base>_`` in a column name, for messages."""
    if base in QUANTITY_UNITS:
        return ', '.join(QUANTITY_UNITS[base])
    if base == 'frequency':
        return ', '.join(FREQUENCY_UNITS)
    if base.startswith('phase'):
        return ', '.join(PHASE_UNITS)
    return '<current>_per_<length>, e.g. A_per_m, uA_per_mm'


def column_to_si(name: str) -> tuple[str, float] | None:
    """
    (SI column, factor to SI) of a column named with another unit, or None.

    ``deflection_mm`` -> ``('deflection_m', 1e-3)``, ``phase_rad`` ->
    ``('phase_deg', 57.29...)``, ``frequency_rad_s`` -> ``('frequency_hz', 1/2pi)``,
    ``gain_uA_per_mm`` -> ``('gain_A_per_m', 1e-3)``.
    """
    base = next((b for b in _BASES if name.startswith(b + '_')), None)
    if base is None:
        return None
    unit = name[len(base) + 1:]
    if base in QUANTITY_UNITS:
        factor = unit_factor(unit, QUANTITY_UNITS[base])
        return None if factor is None else (f'{base}_{SI_SYMBOL[base]}', factor)
    if base == 'frequency':
        factor = FREQUENCY_UNITS.get(unit.lower())
        return None if factor is None else ('frequency_hz', factor)
    if base.startswith('phase'):
        factor = PHASE_UNITS.get(unit.lower())
        return None if factor is None else (f'{base}_deg', factor)
    current, sep, length = unit.partition('_per_')
    amps = unit_factor(current, CURRENT_UNITS) if sep else None
    metres = unit_factor(length, LENGTH_UNITS) if sep else None
    if amps is None or metres is None:
        return None
    return f'{base}_A_per_m', amps / metres
