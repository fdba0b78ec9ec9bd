"""Units in column names and geometry strings, converted to SI (no rclpy needed).

One table per physical dimension maps a unit symbol to its factor to SI;
``u``, ``µ`` (U+00B5) and ``μ`` (U+03BC) all mean micro.  Lookup is exact
first, then case-insensitive (``MM`` = mm, ``ua`` = uA; each table has no two
symbols differing only in case).
"""
from __future__ import annotations

import math
import re
from decimal import Decimal

__all__ = ["TIME_UNITS", "LENGTH_UNITS", "CURRENT_UNITS", "VOLTAGE_UNITS", "QUANTITY_UNITS",
           "SI_SYMBOL", "unit_factor", "to_si", "decimal_to_si", "split_unit", "parse_length"]

TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6}
LENGTH_UNITS = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "nm": 1e-9}
CURRENT_UNITS = {"A": 1.0, "mA": 1e-3, "uA": 1e-6, "nA": 1e-9, "pA": 1e-12}
VOLTAGE_UNITS = {"V": 1.0, "mV": 1e-3}

#: Unit table of each time-series quantity.
QUANTITY_UNITS = {"time": TIME_UNITS, "deflection": LENGTH_UNITS, "current": CURRENT_UNITS}
#: SI symbol of each quantity (the canonical column is ``<quantity>_<symbol>``).
SI_SYMBOL = {"time": "s", "deflection": "m", "current": "A"}

def to_si(value, factor: float):
    """``value * factor``, computed as a division by the power of ten when ``factor`` is
    one (``360 * 1e-6`` gives 0.00035999999999999997; ``360 / 1e6`` gives 0.00036)."""
    if 0.0 < factor < 1.0:
        inverse = round(1.0 / factor)
        if inverse * factor == 1.0 or abs(inverse * factor - 1.0) < 1e-12:
            return value / inverse
    return value * factor


def decimal_to_si(value: str | float, factor: float) -> float:
    """One value in SI, rounded once from its decimal form (``'0.36'`` mm -> 0.00036 m,
    where ``0.36 / 1000`` gives 0.00035999999999999997)."""
    exponent = round(math.log10(factor))
    if math.isclose(10.0 ** exponent, factor, rel_tol=1e-12):
        return float(Decimal(str(value)).scaleb(exponent))
    return float(value) * factor


_MICRO = str.maketrans({"\u00b5": "u", "\u03bc": "u"})


def unit_factor(unit: str, table: dict) -> float | None:
    """Factor from ``unit`` to SI in ``table``, or None if ``unit`` is not in it."""
    u = unit.strip().translate(_MICRO)
    if u in table:
        return table[u]
    low = {k.lower(): v for k, v in table.items()}
    return low.get(u.lower())


_BRACKETED = re.compile(r"^(?P<stem>.*?)\s*(?:\[(?P<b>[^\]]*)\]|\((?P<p>[^)]*)\))\s*$")
_SUFFIX = re.compile(r"^(?P<stem>.+?)_(?P<u>[A-Za-z\u00b5\u03bc]+)$")


def split_unit(name: str) -> tuple[str, str | None]:
    """(stem, unit) of a column name: ``Time [s]``, ``Laser (mm)``, ``current_uA``.

    A ``_suffix`` counts as a unit only if it is a symbol of one of the
    tables; otherwise the whole name is the stem and the unit is None.
    """
    s = name.strip()
    m = _BRACKETED.match(s)
    if m:
        unit = m.group("b") if m.group("b") is not None else m.group("p")
        return m.group("stem").strip(), unit.strip()
    m = _SUFFIX.match(s)
    if m and any(unit_factor(m.group("u"), t) is not None
                 for t in (TIME_UNITS, LENGTH_UNITS, CURRENT_UNITS, VOLTAGE_UNITS)):
        return m.group("stem"), m.group("u")
    return s, None


_LENGTH_VALUE = re.compile(r"^\s*([+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?)"
                           r"\s*([A-Za-z\u00b5\u03bc]+)\s*$")


def parse_length(text: str) -> float:
    """Metres of a length with a unit: ``22mm``, ``360 um``, ``0.36 µm``, ``0.022 m``.

    A bare number is refused (the unit must be said); raises ValueError.
    """
    m = _LENGTH_VALUE.match(text)
    if not m or not m.group(1).isascii():
        raise ValueError(f"{text.strip()!r} is not a length with a unit (e.g. 22mm, 360um)")
    factor = unit_factor(m.group(2), LENGTH_UNITS)
    if factor is None:
        raise ValueError(f"{text.strip()!r}: unknown length unit {m.group(2)!r} "
                         f"(known: {', '.join(LENGTH_UNITS)})")
    return decimal_to_si(m.group(1), factor)
