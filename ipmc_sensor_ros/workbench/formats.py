"""The workbench's text formats ``ipmc-timeseries/1`` and ``ipmc-frf/1`` (no rclpy needed).

Every problem with an input raises :class:`DataFormatError` (a
:class:`ValueError`) naming the file and the 1-based line where that applies::

    data/x.csv:17: non-numeric cell 'abc' in column current_A

Nothing is silently dropped or repaired: a bad row, a duplicate time, an
unknown column, a NaN is an error, never a skipped line.

Text formats
============

Both text formats are UTF-8, ``\\n`` or ``\\r\\n`` line ends, and share one
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
  width W and total thickness 2h of the cantilever, metres.  They are checked
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

Column names are exact.  A known quantity with another unit (``time_ms``,
``deflection_mm``, ``current_uA``, ``phase_rad``...) is reported as "wrong
units" naming the expected column.

Rows
----
Comma separated, as many cells as columns, each a finite decimal number
(spaces around a cell are allowed).  At least two data rows.  Empty lines
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

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ..physics.parameters import Geometry, MaterialParameters, ParameterError
from .measurements import DataFormatError, FrequencyResponseData, PathLike, TimeSeries

__all__ = [
    "TIMESERIES_FORMAT", "FRF_FORMAT", "TIMESERIES_COLUMNS", "TIMESERIES_COLUMNS_NO_DEFLECTION",
    "FRF_COLUMNS", "GEOMETRY_KEYS", "KNOWN_KEYS",
    "read_timeseries", "write_timeseries", "read_frf", "write_frf", "read_text",
]

TIMESERIES_FORMAT = "ipmc-timeseries/1"
FRF_FORMAT = "ipmc-frf/1"
FORMATS = (TIMESERIES_FORMAT, FRF_FORMAT)

TIMESERIES_COLUMNS = ("time_s", "deflection_m", "current_A")
TIMESERIES_COLUMNS_NO_DEFLECTION = ("time_s", "current_A")
FRF_COLUMNS = ("frequency_hz", "gain_A_per_m", "phase_deg")
FRF_COHERENCE_COLUMN = "coherence"
FRF_STD_COLUMNS = ("gain_std_A_per_m", "phase_std_deg")

#: Accepted column-header lines of each format.
_TIMESERIES_LAYOUTS = (TIMESERIES_COLUMNS, TIMESERIES_COLUMNS_NO_DEFLECTION)
_FRF_LAYOUTS = (
    FRF_COLUMNS,
    FRF_COLUMNS + (FRF_COHERENCE_COLUMN,),
    FRF_COLUMNS + FRF_STD_COLUMNS,
    FRF_COLUMNS + (FRF_COHERENCE_COLUMN,) + FRF_STD_COLUMNS,
)

GEOMETRY_KEYS = ("length_m", "width_m", "thickness_m")
#: Optional known physical values (header keys; :class:`MaterialParameters` names).
KNOWN_KEYS = ("temperature_k", "youngs_modulus_pa", "surface_resistance_ohm")
_TIMESERIES_NUMERIC_KEYS = GEOMETRY_KEYS + ("sample_rate_hz",) + KNOWN_KEYS
_FRF_NUMERIC_KEYS = GEOMETRY_KEYS + KNOWN_KEYS
_RESERVED_KEYS = ("format", "sample") + GEOMETRY_KEYS + ("sample_rate_hz",) + KNOWN_KEYS

#: Relative tolerance between ``sample_rate_hz`` and 1 / median time step.
SAMPLE_RATE_TOLERANCE = 0.01


#: Expected column of each known quantity and a description of its unit, used
#: to say "wrong units" when a column names the right quantity in another unit.
_COLUMN_UNITS = {
    "time": ("time_s", "seconds"),
    "deflection": ("deflection_m", "metres"),
    "current": ("current_A", "amperes"),
    "frequency": ("frequency_hz", "hertz"),
    "gain": ("gain_A_per_m", "amperes per metre"),
    "phase": ("phase_deg", "degrees"),
    "coherence": ("coherence", "dimensionless, 0..1"),
    "gain_std": ("gain_std_A_per_m", "amperes per metre"),
    "phase_std": ("phase_std_deg", "degrees"),
}
_TIMESERIES_BASES = ("time", "deflection", "current")
_FRF_BASES = ("frequency", "gain", "phase", "coherence", "gain_std", "phase_std")

_NUMBER = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?")
_NONFINITE = {"nan", "inf", "infinity"}
_KEY = re.compile(r"[A-Za-z][A-Za-z0-9_.\-]*")



# ---------------------------------------------------------------------------
# Text files: low level
# ---------------------------------------------------------------------------
def _read_lines(path: PathLike) -> list[str]:
    """Decode ``path`` as UTF-8 text lines (``\\r\\n`` accepted) or raise DataFormatError."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise DataFormatError(path, None, "file not found") from None
    except IsADirectoryError:
        raise DataFormatError(path, None, "is a directory, expected a text file "
                              "(bags are read with read_bag or read_any)") from None
    except OSError as exc:
        raise DataFormatError(path, None, f"cannot read file: {exc.strerror or exc}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise DataFormatError(path, line, f"not UTF-8 text (binary file?): byte "
                              f"0x{raw[exc.start]:02x} at offset {exc.start} cannot be "
                              "decoded") from None
    if text.startswith("\ufeff"):  # byte-order mark written by some editors
        text = text[1:]
    if "\x00" in text:
        pos = text.index("\x00")
        raise DataFormatError(path, text.count("\n", 0, pos) + 1,
                              "binary file: NUL byte in text")
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    return [ln[:-1] if ln.endswith("\r") else ln for ln in lines]


@dataclass
class _Header:
    values: dict            # key -> raw string value
    lines: dict             # key -> 1-based line
    column_index: int       # 0-based index of the column-header line (len(lines) if none)


def _parse_header(path: PathLike, lines: list[str]) -> _Header:
    if not any(ln.strip() for ln in lines):
        raise DataFormatError(path, 1, "empty file (expected a '# format: ...' header line)")
    values: dict[str, str] = {}
    where: dict[str, int] = {}
    i = 0
    while i < len(lines):
        s = lines[i].strip()
        if s and not s.startswith("#"):
            break
        body = s[1:].strip()
        if body:
            if ":" not in body:
                raise DataFormatError(path, i + 1, f"header line without ':' separator: {s!r} "
                                      "(expected '# key: value')")
            key, _, value = body.partition(":")
            key, value = key.strip(), value.strip()
            if not _KEY.fullmatch(key):
                raise DataFormatError(path, i + 1, f"invalid header key {key!r} in {s!r} "
                                      "(expected '# key: value', key [A-Za-z][A-Za-z0-9_.-]*)")
            if key in values:
                raise DataFormatError(path, i + 1, f"duplicate header key '{key}' (first "
                                      f"given on line {where[key]})")
            values[key] = value
            where[key] = i + 1
        i += 1
    return _Header(values, where, i)


def _format_of(path: PathLike, lines: list[str], header: _Header) -> str:
    """The header's format, checked to be a known one."""
    if "format" not in header.values:
        line = min(header.column_index + 1, len(lines))
        raise DataFormatError(path, line, "missing '# format: ...' header line (known formats: "
                              f"{', '.join(FORMATS)})")
    fmt = header.values["format"]
    if fmt not in FORMATS:
        raise DataFormatError(path, header.lines["format"], f"unknown format {fmt!r} "
                              f"(known formats: {', '.join(FORMATS)})")
    return fmt


def _parse_number(text: str) -> float | None:
    """Finite float of a decimal number string, or None."""
    s = text.strip()
    if not _NUMBER.fullmatch(s):
        return None
    v = float(s)
    return v if math.isfinite(v) else None


def _cell_error(path, lineno: int, cell: str, column: str) -> DataFormatError:
    s = cell.strip()
    if not s:
        return DataFormatError(path, lineno, f"empty cell in column {column}")
    if s.lower().lstrip("+-") in _NONFINITE:
        return DataFormatError(path, lineno, f"NaN/Inf cell {s!r} in column {column} "
                               "(every value must be a finite number)")
    if _NUMBER.fullmatch(s):
        return DataFormatError(path, lineno, f"NaN/Inf: cell {s!r} in column {column} "
                               "overflows to infinity")
    return DataFormatError(path, lineno, f"non-numeric cell {s!r} in column {column}")


def _header_numbers(path, header: _Header, numeric_keys: Sequence[str]) -> dict[str, float]:
    out: dict[str, float] = {}
    for key in sorted((k for k in numeric_keys if k in header.values),
                      key=lambda k: header.lines[k]):
        raw = header.values[key]
        value = _parse_number(raw)
        if value is None:
            what = "empty" if not raw else repr(raw)
            raise DataFormatError(path, header.lines[key], f"header key '{key}' must be a finite "
                                  f"number in SI units (no unit suffix), got {what}")
        out[key] = value
    return out


def _parameter_line(header: _Header, exc: ParameterError, keys: Sequence[str]) -> int:
    m = re.search(r"parameter '(\w+)'", str(exc))
    if m and m.group(1) in header.lines:
        return header.lines[m.group(1)]
    return min(header.lines[k] for k in keys if k in header.lines)


def _common_header(path, lines: list[str], header: _Header, expected_format: str,
                   numeric_keys: Sequence[str], layouts: Sequence[tuple[str, ...]]):
    """Validate the header; return (sample, geometry, known, numbers, extra)."""
    fmt = _format_of(path, lines, header)
    if fmt != expected_format:
        reader = "read_frf" if fmt == FRF_FORMAT else "read_timeseries"
        raise DataFormatError(path, header.lines["format"], f"format is {fmt!r}, expected "
                              f"{expected_format!r} (read it with {reader} or read_any)")
    numbers = _header_numbers(path, header, numeric_keys)
    if header.column_index >= len(lines):
        raise DataFormatError(path, len(lines), "the header is not followed by a column header "
                              "line (expected " + " or ".join(repr(",".join(c)) for c in layouts)
                              + ") and data rows")
    col_line = header.column_index + 1
    missing = [k for k in GEOMETRY_KEYS if k not in header.values]
    if missing:
        raise DataFormatError(path, col_line, "missing required header key(s) "
                              + ", ".join(f"'{k}'" for k in missing)
                              + " (geometry in metres, e.g. '# length_m: 0.022')")
    sample = header.values.get("sample", "")
    try:
        geometry = Geometry(numbers["length_m"], numbers["width_m"], numbers["thickness_m"],
                            name=sample)
    except ParameterError as exc:
        raise DataFormatError(path, _parameter_line(header, exc, GEOMETRY_KEYS),
                              f"geometry out of physical range: {exc}") from None
    known = {k: numbers[k] for k in KNOWN_KEYS if k in numbers}
    try:
        MaterialParameters(**known)
    except ParameterError as exc:
        raise DataFormatError(path, _parameter_line(header, exc, tuple(known)),
                              f"implausible known value: {exc}") from None
    extra = {k: v for k, v in header.values.items() if k not in _RESERVED_KEYS}
    return sample, geometry, known, numbers, extra


def _parse_columns(path, lines: list[str], header: _Header,
                   layouts: Sequence[tuple[str, ...]], bases: Sequence[str]) -> tuple[str, ...]:
    col_line = header.column_index + 1
    raw = lines[header.column_index]
    names = tuple(c.strip() for c in raw.split(","))
    if names in layouts:
        return names
    expected = " or ".join(repr(",".join(c)) for c in layouts)
    allowed = {n for c in layouts for n in c}
    if all(_parse_number(n) is not None for n in names):
        raise DataFormatError(path, col_line, f"missing column header line: found a data row "
                              f"{raw.strip()!r}; expected {expected}")
    other = _FRF_LAYOUTS if layouts is _TIMESERIES_LAYOUTS else _TIMESERIES_LAYOUTS
    if names in other:
        this, that = ((TIMESERIES_FORMAT, FRF_FORMAT) if layouts is _TIMESERIES_LAYOUTS
                      else (FRF_FORMAT, TIMESERIES_FORMAT))
        raise DataFormatError(path, col_line, f"the file declares format {this!r} but has the "
                              f"columns of {that!r}; expected {expected}")
    for name in names:
        if name in allowed:
            continue
        low = name.lower()
        match = [b for b in bases if low == b or low.startswith(b + "_")]
        if match:
            base = max(match, key=len)
            good, unit = _COLUMN_UNITS[base]
            raise DataFormatError(path, col_line, f"wrong units in column header: {name!r} "
                                  f"should be '{good}' ({unit}); expected {expected}")
        raise DataFormatError(path, col_line, f"unknown column {name!r}; expected {expected}")
    if (FRF_STD_COLUMNS[0] in names) != (FRF_STD_COLUMNS[1] in names):
        raise DataFormatError(path, col_line, f"columns {FRF_STD_COLUMNS[0]} and "
                              f"{FRF_STD_COLUMNS[1]} must come together; expected {expected}")
    raise DataFormatError(path, col_line, f"unexpected column header {raw.strip()!r} (columns "
                          f"missing, repeated or out of order); expected {expected}")


RowCheck = Callable[[np.ndarray, "np.ndarray | None", int, int], None]


def _parse_rows(path, lines: list[str], header: _Header, columns: tuple[str, ...],
                check: RowCheck) -> tuple[np.ndarray, list[int]]:
    """Parse the data rows below the column header; ``check(row, prev, line, prev_line)``."""
    start = header.column_index + 1
    end = len(lines)
    while end > start and not lines[end - 1].strip():
        end -= 1  # empty lines at the very end carry nothing
    ncol = len(columns)
    rows: list[list[float]] = []
    row_lines: list[int] = []
    prev: np.ndarray | None = None
    for i in range(start, end):
        text = lines[i]
        lineno = i + 1
        s = text.strip()
        if not s:
            raise DataFormatError(path, lineno, "blank line between data rows "
                                  "(data rows must be contiguous)")
        if s.startswith("#"):
            raise DataFormatError(path, lineno, "header/comment line after the column header "
                                  "(header lines must come first)")
        cells = text.split(",")
        if len(cells) != ncol:
            hint = " (cells are separated by ',', not ';')" if ";" in text else ""
            raise DataFormatError(path, lineno, f"wrong number of cells: expected {ncol} "
                                  f"({','.join(columns)}), got {len(cells)}{hint}")
        row = []
        for cell, column in zip(cells, columns):
            v = _parse_number(cell)
            if v is None:
                raise _cell_error(path, lineno, cell, column)
            row.append(v)
        arr = np.array(row)
        check(arr, prev, lineno, row_lines[-1] if row_lines else 0)
        rows.append(row)
        row_lines.append(lineno)
        prev = arr
    if not rows:
        raise DataFormatError(path, header.column_index + 1, "no data rows after the column "
                              "header (at least 2 are needed)")
    if len(rows) < 2:
        raise DataFormatError(path, row_lines[0], "only 1 data row; at least 2 are needed")
    return np.array(rows, dtype=float), row_lines


def _fmt(x: float) -> str:
    return repr(float(x))


# ---------------------------------------------------------------------------
# ipmc-timeseries/1
# ---------------------------------------------------------------------------
def _timeseries_from_lines(path, lines: list[str], header: _Header) -> TimeSeries:
    sample, geometry, known, numbers, extra = _common_header(
        path, lines, header, TIMESERIES_FORMAT, _TIMESERIES_NUMERIC_KEYS, _TIMESERIES_LAYOUTS)
    columns = _parse_columns(path, lines, header, _TIMESERIES_LAYOUTS, _TIMESERIES_BASES)

    def check(row, prev, lineno, prev_line):
        if prev is not None:
            if row[0] == prev[0]:
                raise DataFormatError(path, lineno, f"duplicate time {_fmt(row[0])} s (same as "
                                      f"line {prev_line}); time_s must be strictly increasing")
            if row[0] < prev[0]:
                raise DataFormatError(path, lineno, f"time decreases: {_fmt(row[0])} s after "
                                      f"{_fmt(prev[0])} s on line {prev_line}; time_s must be "
                                      "strictly increasing")

    data, _ = _parse_rows(path, lines, header, columns, check)
    t = data[:, 0]
    median_dt = float(np.median(np.diff(t)))
    measured_rate = 1.0 / median_dt
    rate = numbers.get("sample_rate_hz")
    if rate is None:
        rate = measured_rate
    elif rate <= 0.0:
        raise DataFormatError(path, header.lines["sample_rate_hz"], f"sample_rate_hz must be > 0, "
                              f"got {_fmt(rate)}")
    elif abs(rate * median_dt - 1.0) > SAMPLE_RATE_TOLERANCE:
        raise DataFormatError(path, header.lines["sample_rate_hz"],
                              f"sample_rate_hz = {_fmt(rate)} disagrees with the time column: "
                              f"median step {median_dt:.6g} s -> {measured_rate:.6g} Hz "
                              f"(tolerance {SAMPLE_RATE_TOLERANCE:.0%})")
    deflection = data[:, 1] if "deflection_m" in columns else None
    return TimeSeries(path=str(path), sample=sample, geometry=geometry, known=known,
                      sample_rate_hz=rate, time_s=t, current_a=data[:, columns.index("current_A")],
                      deflection_m=deflection, extra=extra,
                      deflection_alignment="exact" if deflection is not None else None)


def read_timeseries(path: PathLike) -> TimeSeries:
    """Read an ``ipmc-timeseries/1`` file (see the module docstring)."""
    lines = _read_lines(path)
    return _timeseries_from_lines(path, lines, _parse_header(path, lines))


def _header_text(fmt: str, sample: str, geometry: Geometry, numbers: Sequence[tuple[str, float]],
                 known: Mapping[str, float], extra: Mapping[str, Any], path) -> list[str]:
    def single_line(what: str, text: str) -> str:
        text = str(text)
        if "\n" in text or "\r" in text or text != text.strip():
            raise DataFormatError(path, None, f"cannot write {what} {text!r}: it must be one line "
                                  "without leading/trailing spaces")
        return text

    out = [f"# format: {fmt}"]
    if sample:
        out.append(f"# sample: {single_line('sample name', sample)}")
    out += [f"# length_m: {_fmt(geometry.length_m)}", f"# width_m: {_fmt(geometry.width_m)}",
            f"# thickness_m: {_fmt(geometry.thickness_m)}"]
    out += [f"# {k}: {_fmt(v)}" for k, v in numbers]
    for key in KNOWN_KEYS:
        if key in known:
            out.append(f"# {key}: {_fmt(known[key])}")
    unknown_known = sorted(set(known) - set(KNOWN_KEYS))
    if unknown_known:
        raise DataFormatError(path, None, f"cannot write known value(s) {unknown_known} in a text "
                              f"file; the header knows {list(KNOWN_KEYS)}")
    for key, value in extra.items():
        key = single_line("extra key", key)
        if not _KEY.fullmatch(key) or key in _RESERVED_KEYS:
            raise DataFormatError(path, None, f"cannot write extra header key {key!r}: invalid or "
                                  "reserved")
        out.append(f"# {key}: {single_line(f'value of extra key {key!r}', value)}")
    return out


def _write_checked(path, text: str, parse: Callable[[list[str]], Any], what: str) -> None:
    """Parse ``text`` back before writing it, so only readable files are ever written."""
    lines = text.split("\n")[:-1]
    try:
        parse(lines)
    except DataFormatError as exc:
        where = f" (line {exc.line} of the output)" if exc.line is not None else ""
        raise DataFormatError(path, None, f"refusing to write an invalid {what}: "
                              f"{exc.reason}{where}") from None
    Path(path).write_text(text, encoding="utf-8", newline="\n")


def write_timeseries(path: PathLike, ts: TimeSeries) -> None:
    """Write ``ts`` as ``ipmc-timeseries/1``; floats in repr precision (exact round trip).

    The text is validated with the reader before it is written: an invalid
    series (non-increasing time, NaN, ...) raises :class:`DataFormatError`.
    """
    sample = ts.sample or ts.geometry.name
    lines = _header_text(TIMESERIES_FORMAT, sample, ts.geometry,
                         [("sample_rate_hz", ts.sample_rate_hz)], ts.known, ts.extra, path)
    if ts.deflection_m is None:
        lines.append(",".join(TIMESERIES_COLUMNS_NO_DEFLECTION))
        lines += [f"{t!r},{i!r}" for t, i in zip(ts.time_s.tolist(), ts.current_a.tolist())]
    else:
        lines.append(",".join(TIMESERIES_COLUMNS))
        lines += [f"{t!r},{d!r},{i!r}" for t, d, i in
                  zip(ts.time_s.tolist(), ts.deflection_m.tolist(), ts.current_a.tolist())]
    text = "\n".join(lines) + "\n"
    _write_checked(path, text, lambda ls: _timeseries_from_lines(path, ls, _parse_header(path, ls)),
                   "time series")


# ---------------------------------------------------------------------------
# ipmc-frf/1
# ---------------------------------------------------------------------------
def _frf_from_lines(path, lines: list[str], header: _Header) -> FrequencyResponseData:
    sample, geometry, known, _numbers, extra = _common_header(
        path, lines, header, FRF_FORMAT, _FRF_NUMERIC_KEYS, _FRF_LAYOUTS)
    columns = _parse_columns(path, lines, header, _FRF_LAYOUTS, _FRF_BASES)
    coh = columns.index(FRF_COHERENCE_COLUMN) if FRF_COHERENCE_COLUMN in columns else None
    std = [columns.index(c) for c in FRF_STD_COLUMNS if c in columns]

    def check(row, prev, lineno, prev_line):
        f = row[0]
        if f <= 0.0:
            raise DataFormatError(path, lineno, f"non-positive frequency {_fmt(f)} Hz "
                                  "(frequency_hz must be > 0)")
        if prev is not None and f <= prev[0]:
            what = "duplicate frequency" if f == prev[0] else "frequency decreases:"
            raise DataFormatError(path, lineno, f"{what} {_fmt(f)} Hz after {_fmt(prev[0])} Hz on "
                                  f"line {prev_line}; frequency_hz must be strictly increasing")
        if row[1] <= 0.0:
            raise DataFormatError(path, lineno, f"non-positive gain {_fmt(row[1])} in column "
                                  "gain_A_per_m (a magnitude, must be > 0)")
        if coh is not None and not 0.0 <= row[coh] <= 1.0:
            raise DataFormatError(path, lineno, f"coherence {_fmt(row[coh])} outside [0, 1]")
        for k in std:
            if row[k] < 0.0:
                raise DataFormatError(path, lineno, f"negative standard uncertainty "
                                      f"{_fmt(row[k])} in column {columns[k]}")

    data, _ = _parse_rows(path, lines, header, columns, check)
    return FrequencyResponseData(
        path=str(path), sample=sample, geometry=geometry, known=known,
        frequency_hz=data[:, 0], gain_a_per_m=data[:, 1], phase_deg=data[:, 2],
        coherence=data[:, coh] if coh is not None else None,
        gain_std_a_per_m=data[:, std[0]] if std else None,
        phase_std_deg=data[:, std[1]] if std else None, extra=extra)


def read_frf(path: PathLike) -> FrequencyResponseData:
    """Read an ``ipmc-frf/1`` file (see the module docstring)."""
    lines = _read_lines(path)
    return _frf_from_lines(path, lines, _parse_header(path, lines))


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
    lines.append(",".join(columns))
    lines += [",".join(repr(v) for v in row) for row in zip(*(d.tolist() for d in data))]
    text = "\n".join(lines) + "\n"
    _write_checked(path, text, lambda ls: _frf_from_lines(path, ls, _parse_header(path, ls)),
                   "frequency response")


def read_text(path: PathLike) -> TimeSeries | FrequencyResponseData:
    """Read a text file of either format, dispatched on its ``# format:`` line."""
    lines = _read_lines(path)
    header = _parse_header(path, lines)
    if _format_of(path, lines, header) == TIMESERIES_FORMAT:
        return _timeseries_from_lines(path, lines, header)
    return _frf_from_lines(path, lines, header)
