"""Measurement-data I/O of the model-validation workbench (no rclpy needed).

Three inputs are read, each into a validated, SI-unit data class:

* ``ipmc-timeseries/1`` text files  -> :class:`TimeSeries`
* ``ipmc-frf/1`` text files         -> :class:`FrequencyResponseData`
* rosbag2 bags (sqlite3 or mcap)    -> :class:`TimeSeries`

Every problem with an input raises :class:`DataFormatError` (a
:class:`ValueError`) naming the file, the 1-based line where that applies and,
for bags, the topic::

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

Bags (rosbag2, read with ``rosbags``)
=====================================
``read_bag`` accepts a bag directory (with ``metadata.yaml``) or a single
``.mcap``/``.db3`` storage file.  Topics are matched with or without the
leading ``/``.

* current (default topic ``current``): ``std_msgs/msg/Float64MultiArray``
  blocks, ``layout.dim[0] = (label "sample", size n, stride 2n)``,
  ``layout.dim[1] = (label "time_s,current_A", size 2, stride 2)``,
  ``data = [t0, i0, t1, i1, ...]`` (seconds, amperes).  Samples must be
  strictly increasing in time in message order.
* deflection (default topic ``deflection_truth``; the estimator's output
  ``deflection/block`` has the same layout): the same block type with label
  ``"time_s,deflection_m"`` (metres), or ``geometry_msgs/msg/PointStamped``
  with ``point.z`` the deflection (m) at ``header.stamp``.  The deflection is
  aligned to the current sample times: ``deflection_alignment = "exact"`` when
  every current time has a deflection sample at the same time (within 1 ns
  plus float rounding, as when both come from the simulator), otherwise
  ``"linear"`` (linear interpolation; the deflection must cover the whole
  current time span, no extrapolation).  A missing deflection topic gives
  ``deflection_m = None`` unless ``require_deflection=True``.
* geometry: the ``geometry`` argument, else the YAML sidecar (argument
  ``sidecar``, default ``<bag dir>/ipmc.yaml``, for a single storage file the
  ``ipmc.yaml`` beside it)::

      geometry: {length_m: 0.022, width_m: 0.007, thickness_m: 0.00036, name: slim}
      material: {temperature_k: 300.0}     # optional, partial; -> known
      extra: {operator: jd}                # optional -> extra

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

import functools
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence, Union

import numpy as np

from ..interface.blocks import SAMPLE_LABEL, unpack_pairs
from ..physics.parameters import Geometry, MaterialParameters, ParameterError

__all__ = [
    "DataFormatError",
    "TimeSeries",
    "FrequencyResponseData",
    "TIMESERIES_FORMAT",
    "FRF_FORMAT",
    "TIMESERIES_COLUMNS",
    "TIMESERIES_COLUMNS_NO_DEFLECTION",
    "FRF_COLUMNS",
    "GEOMETRY_KEYS",
    "KNOWN_KEYS",
    "CURRENT_LABEL",
    "DEFLECTION_LABEL",
    "MULTIARRAY_TYPE",
    "POINT_STAMPED_TYPE",
    "read_timeseries",
    "write_timeseries",
    "read_frf",
    "write_frf",
    "read_bag",
    "write_bag",
    "read_any",
    "load_many",
]

PathLike = Union[str, Path]

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

#: Column label (dim[1].label) of current and deflection blocks in bags.
CURRENT_LABEL = "time_s,current_A"
DEFLECTION_LABEL = "time_s,deflection_m"
MULTIARRAY_TYPE = "std_msgs/msg/Float64MultiArray"
POINT_STAMPED_TYPE = "geometry_msgs/msg/PointStamped"
SIDECAR_NAME = "ipmc.yaml"
_SIDECAR_KEYS = ("geometry", "material", "extra", "model")

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
# Errors
# ---------------------------------------------------------------------------
class DataFormatError(ValueError):
    """An input file or bag that cannot be read as valid measurement data.

    Attributes
    ----------
    path : str, the file or bag (as given).
    line : int or None, 1-based line of the problem in a text file.
    topic : str or None, the bag topic concerned.
    reason : str, the message without the location prefix.

    ``str()`` is ``"<path>:<line>: <reason>"``, ``"<path>: topic '<topic>':
    <reason>"`` or ``"<path>: <reason>"``.
    """

    def __init__(self, path: PathLike, line: int | None, reason: str, *,
                 topic: str | None = None) -> None:
        self.path = str(path)
        self.line = line
        self.topic = topic
        self.reason = reason
        super().__init__(self._format())

    def _format(self) -> str:
        where = self.path
        if self.line is not None:
            where += f":{self.line}"
        if self.topic is not None:
            where += f": topic '{self.topic}'"
        return f"{where}: {self.reason}"

    def __str__(self) -> str:
        return self._format()

    def __reduce__(self):  # picklable despite the keyword-only argument
        return (_rebuild_error, (self.path, self.line, self.reason, self.topic))


def _rebuild_error(path, line, reason, topic):
    return DataFormatError(path, line, reason, topic=topic)


# ---------------------------------------------------------------------------
# Data classes
# ---------------------------------------------------------------------------
def _vector(name: str, values: Any, n: int | None = None) -> np.ndarray:
    arr = np.array(values, dtype=float, copy=True)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be 1-D, got shape {arr.shape}")
    if n is not None and arr.size != n:
        raise ValueError(f"{name} has {arr.size} values, expected {n}")
    return arr


@dataclass(frozen=True, eq=False)
class TimeSeries:
    """Synchronous samples of sensing current and (optionally) tip deflection, SI units.

    path : source file or bag ('' if built in memory).
    sample : sample name ('' if unknown).
    geometry : the cantilever geometry, metres.
    known : known physical values (subset of ``KNOWN_KEYS``; for bags, any
        :class:`MaterialParameters` field the sidecar gives), SI units.
    sample_rate_hz : nominal sampling rate, Hz.
    time_s : sample times, s, strictly increasing.
    current_a : sensing current, A.
    deflection_m : tip deflection, m, at ``time_s``; None if unknown.
    extra : unrecognised header keys (text values) / sidecar ``extra``.
    deflection_alignment : ``"exact"`` (measured at the sample times),
        ``"linear"`` (interpolated from other times, bags only) or None.
    """

    path: str
    sample: str
    geometry: Geometry
    known: dict
    sample_rate_hz: float
    time_s: np.ndarray
    current_a: np.ndarray
    deflection_m: np.ndarray | None = None
    extra: dict = field(default_factory=dict)
    deflection_alignment: str | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.geometry, Geometry):
            raise TypeError(f"geometry must be a Geometry, got {type(self.geometry).__name__}")
        t = _vector("time_s", self.time_s)
        object.__setattr__(self, "time_s", t)
        object.__setattr__(self, "current_a", _vector("current_a", self.current_a, t.size))
        if self.deflection_m is not None:
            object.__setattr__(self, "deflection_m",
                               _vector("deflection_m", self.deflection_m, t.size))
            if self.deflection_alignment is None:
                object.__setattr__(self, "deflection_alignment", "exact")
        elif self.deflection_alignment is not None:
            raise ValueError("deflection_alignment given but deflection_m is None")
        if self.deflection_alignment not in (None, "exact", "linear"):
            raise ValueError(f"deflection_alignment must be 'exact', 'linear' or None, "
                             f"got {self.deflection_alignment!r}")
        object.__setattr__(self, "sample_rate_hz", float(self.sample_rate_hz))
        object.__setattr__(self, "known", {str(k): float(v) for k, v in self.known.items()})
        object.__setattr__(self, "extra", dict(self.extra))
        object.__setattr__(self, "path", str(self.path))
        object.__setattr__(self, "sample", str(self.sample))

    @property
    def n_samples(self) -> int:
        return int(self.time_s.size)

    @property
    def has_deflection(self) -> bool:
        return self.deflection_m is not None

    @property
    def duration_s(self) -> float:
        return float(self.time_s[-1] - self.time_s[0]) if self.time_s.size else 0.0


@dataclass(frozen=True, eq=False)
class FrequencyResponseData:
    """A measured frequency response I/w of one sample, SI units.

    frequency_hz : Hz, > 0, strictly increasing.
    gain_a_per_m : |I/w|, A/m, > 0.
    phase_deg : arg(I/w), degrees.
    coherence : magnitude-squared coherence in [0, 1], or None.
    gain_std_a_per_m, phase_std_deg : standard uncertainties (A/m, degrees),
        both or neither.
    Other fields as in :class:`TimeSeries`.
    """

    path: str
    sample: str
    geometry: Geometry
    known: dict
    frequency_hz: np.ndarray
    gain_a_per_m: np.ndarray
    phase_deg: np.ndarray
    coherence: np.ndarray | None = None
    gain_std_a_per_m: np.ndarray | None = None
    phase_std_deg: np.ndarray | None = None
    extra: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.geometry, Geometry):
            raise TypeError(f"geometry must be a Geometry, got {type(self.geometry).__name__}")
        f = _vector("frequency_hz", self.frequency_hz)
        object.__setattr__(self, "frequency_hz", f)
        for name in ("gain_a_per_m", "phase_deg"):
            object.__setattr__(self, name, _vector(name, getattr(self, name), f.size))
        for name in ("coherence", "gain_std_a_per_m", "phase_std_deg"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, _vector(name, getattr(self, name), f.size))
        if (self.gain_std_a_per_m is None) != (self.phase_std_deg is None):
            raise ValueError("gain_std_a_per_m and phase_std_deg must be given together")
        object.__setattr__(self, "known", {str(k): float(v) for k, v in self.known.items()})
        object.__setattr__(self, "extra", dict(self.extra))
        object.__setattr__(self, "path", str(self.path))
        object.__setattr__(self, "sample", str(self.sample))

    @property
    def gain_std(self) -> np.ndarray | None:
        """Alias of ``gain_std_a_per_m``."""
        return self.gain_std_a_per_m

    @property
    def response(self) -> np.ndarray:
        """Complex response I/w = gain * exp(j * deg2rad(phase)), A/m."""
        return self.gain_a_per_m * np.exp(1j * np.deg2rad(self.phase_deg))


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


# ---------------------------------------------------------------------------
# Bags
# ---------------------------------------------------------------------------
@functools.lru_cache(maxsize=None)
def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def _topic_key(name: str) -> str:
    return name.strip().lstrip("/")


def _find_topic(where: str, topics: Mapping[str, Any], wanted: str):
    """(name, info) of ``wanted`` in the bag (leading '/' optional), or None."""
    matches = [name for name in topics if _topic_key(name) == _topic_key(wanted)]
    if len(matches) > 1:
        raise DataFormatError(where, None, f"ambiguous: the bag has both {matches}", topic=wanted)
    return (matches[0], topics[matches[0]]) if matches else None


def _describe_topics(topics: Mapping[str, Any]) -> str:
    if not topics:
        return "the bag has no topics"
    return "the bag has: " + ", ".join(f"{name} ({info.msgtype}, {info.msgcount} msgs)"
                                       for name, info in sorted(topics.items()))


def _unpack_block(msg, label: str) -> tuple[np.ndarray, np.ndarray]:
    """Times and values of a block message; ValueError (LayoutError) describing a bad layout."""
    return unpack_pairs(msg, label, values_only_ok=False)


def _read_topic(where: str, reader, name: str, info, label: str,
                quantity: str) -> tuple[np.ndarray, np.ndarray]:
    """All (time, value) samples of one topic, in time order, validated."""
    store = _typestore()
    msgtype = info.msgtype
    allowed = (MULTIARRAY_TYPE,) if quantity == "current" else (MULTIARRAY_TYPE, POINT_STAMPED_TYPE)
    if msgtype not in allowed:
        raise DataFormatError(where, None, f"has message type {msgtype!r}; expected "
                              + " or ".join(repr(a) for a in allowed), topic=name)
    times: list[np.ndarray] = []
    values: list[np.ndarray] = []
    count = 0
    prev_end: float | None = None
    for conn, _stamp, raw in reader.messages(connections=info.connections):
        count += 1
        try:
            msg = store.deserialize_cdr(raw, conn.msgtype)
        except Exception as exc:  # corrupt payload: any decoder failure
            raise DataFormatError(where, None, f"message {count}: cannot deserialize "
                                  f"{conn.msgtype}: {type(exc).__name__}: {exc}",
                                  topic=name) from exc
        if msgtype == POINT_STAMPED_TYPE:
            t = np.array([msg.header.stamp.sec + msg.header.stamp.nanosec / 1e9])
            v = np.array([float(msg.point.z)])
        else:
            try:
                t, v = _unpack_block(msg, label)
            except ValueError as exc:
                raise DataFormatError(where, None, f"message {count}: {exc}", topic=name) from None
        bad = ~(np.isfinite(t) & np.isfinite(v))
        if bad.any():
            k = int(np.argmax(bad))
            raise DataFormatError(where, None, f"message {count}, sample {k}: NaN/Inf "
                                  f"(time {_fmt(t[k])}, {quantity} {_fmt(v[k])})", topic=name)
        if msgtype == MULTIARRAY_TYPE and t.size:
            steps = np.diff(t)
            if (steps <= 0).any():
                k = int(np.argmax(steps <= 0)) + 1
                raise DataFormatError(where, None, f"message {count}, sample {k}: time "
                                      f"{_fmt(t[k])} s is not after {_fmt(t[k - 1])} s (sample "
                                      "times must be strictly increasing)", topic=name)
            if prev_end is not None and t[0] <= prev_end:
                raise DataFormatError(where, None, f"message {count} starts at {_fmt(t[0])} s, not "
                                      "after the previous message's last sample at "
                                      f"{_fmt(prev_end)} s (blocks overlap or are out of order)",
                                      topic=name)
            prev_end = float(t[-1])
        times.append(t)
        values.append(v)
    if count != info.msgcount and info.msgcount:
        raise DataFormatError(where, None, f"the bag lists {info.msgcount} messages but only "
                              f"{count} could be read (truncated bag?)", topic=name)
    t = np.concatenate(times) if times else np.empty(0)
    v = np.concatenate(values) if values else np.empty(0)
    if msgtype == POINT_STAMPED_TYPE and t.size:
        order = np.argsort(t, kind="stable")
        t, v = t[order], v[order]
        dup = np.diff(t) == 0
        if dup.any():
            k = int(np.argmax(dup))
            raise DataFormatError(where, None, f"two samples with the same stamp {_fmt(t[k])} s",
                                  topic=name)
    return t, v


def _align(where: str, name: str, tc: np.ndarray, td: np.ndarray,
           vd: np.ndarray) -> tuple[np.ndarray, str]:
    """Deflection at the current times ``tc``: exact match or linear interpolation."""
    if td.size == 0:
        raise DataFormatError(where, None, "has no deflection samples", topic=name)
    tol = 1e-9 + 4.0 * float(np.spacing(max(abs(tc).max(), abs(td).max())))
    idx = np.clip(np.searchsorted(td, tc), 1, max(td.size - 1, 1))
    lo = np.clip(idx - 1, 0, td.size - 1)
    hi = np.clip(idx, 0, td.size - 1)
    nearest = np.where(np.abs(td[lo] - tc) <= np.abs(td[hi] - tc), lo, hi)
    if np.all(np.abs(td[nearest] - tc) <= tol):
        return vd[nearest].copy(), "exact"
    if td.size < 2 or td[0] > tc[0] + tol or td[-1] < tc[-1] - tol:
        raise DataFormatError(where, None, f"deflection covers {_fmt(td[0])}..{_fmt(td[-1])} s "
                              f"but the current covers {_fmt(tc[0])}..{_fmt(tc[-1])} s: cannot "
                              "align without extrapolating (trim the recording)", topic=name)
    return np.interp(tc, td, vd), "linear"


def _yaml_line(text: str, keys: Sequence[str]) -> int | None:
    """1-based line of the nested mapping key ``keys`` in YAML ``text`` (best effort)."""
    import yaml

    try:
        node = yaml.compose(text)
    except yaml.YAMLError:
        return None
    line = None
    for key in keys:
        if not isinstance(node, yaml.MappingNode):
            break
        for k, v in node.value:
            if getattr(k, "value", None) == key:
                line, node = k.start_mark.line + 1, v
                break
        else:
            break
    return line


def _read_sidecar(bag: str, path: Path, need_geometry: bool):
    """(geometry or None, known, extra) from a YAML sidecar."""
    import yaml

    where = str(path)
    about = f"sidecar of bag '{bag}'"
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DataFormatError(where, None, f"{about} not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise DataFormatError(where, None, f"cannot read {about}: {exc}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        problem = getattr(exc, "problem", None) or exc
        raise DataFormatError(where, mark.line + 1 if mark else None,
                              f"{about} is not valid YAML: {problem}") from None
    data = {} if data is None else data
    if not isinstance(data, dict):
        raise DataFormatError(where, 1, f"{about} must be a mapping with a 'geometry' key")
    unknown = sorted(str(k) for k in set(data) - set(_SIDECAR_KEYS))
    if unknown:
        raise DataFormatError(where, _yaml_line(text, [unknown[0]]), f"unknown key(s) {unknown} "
                              f"in {about}; known: {list(_SIDECAR_KEYS)}")
    geometry = None
    if data.get("geometry") is not None:
        g = data["geometry"]
        if not isinstance(g, dict):
            raise DataFormatError(where, _yaml_line(text, ["geometry"]),
                                  f"'geometry' in {about} must be a mapping")
        try:
            geometry = Geometry.from_dict(g)
        except (ParameterError, TypeError) as exc:
            m = re.search(r"parameter '(\w+)'", str(exc))
            line = _yaml_line(text, ["geometry", m.group(1)] if m else ["geometry"])
            raise DataFormatError(where, line, f"geometry in {about}: {exc}") from None
    elif need_geometry:
        raise DataFormatError(where, None, f"{about} has no 'geometry' (length_m, width_m, "
                              "thickness_m in metres) and no geometry was passed")
    known: dict[str, float] = {}
    if data.get("material") is not None:
        mat = data["material"]
        if not isinstance(mat, dict):
            raise DataFormatError(where, _yaml_line(text, ["material"]),
                                  f"'material' in {about} must be a mapping")
        try:
            MaterialParameters.from_dict(mat)
        except (ParameterError, TypeError) as exc:
            raise DataFormatError(where, _yaml_line(text, ["material"]),
                                  f"material in {about}: {exc}") from None
        known = {str(k): float(v) for k, v in mat.items()}
    extra = data.get("extra") or {}
    if not isinstance(extra, dict):
        raise DataFormatError(where, _yaml_line(text, ["extra"]),
                              f"'extra' in {about} must be a mapping")
    extra = dict(extra)
    if "model" in data:
        extra["model"] = data["model"]
    return geometry, known, extra


def read_bag(path: PathLike, current_topic: str = "current",
             deflection_topic: str | None = "deflection_truth",
             geometry: Geometry | Mapping[str, Any] | None = None,
             sidecar: PathLike | None = None, *, require_deflection: bool = False) -> TimeSeries:
    """Read a rosbag2 bag (directory, ``.mcap`` or ``.db3``) into a :class:`TimeSeries`.

    ``current_topic`` must hold ``Float64MultiArray`` current blocks.
    ``deflection_topic`` (None: ignore) may hold deflection blocks or
    ``PointStamped``; it is aligned to the current sample times and
    ``deflection_alignment`` says how ("exact" or "linear").  If the topic is
    absent the deflection is None, unless ``require_deflection``.
    The geometry comes from ``geometry`` or else the sidecar (see the module
    docstring); a sidecar, when present, also gives ``known`` and ``extra``.
    Every problem raises :class:`DataFormatError` naming the bag and topic.
    """
    bag = Path(path)
    where = str(path)
    if not bag.exists():
        raise DataFormatError(where, None, "bag not found (no such file or directory)")
    if bag.is_dir():
        if not (bag / "metadata.yaml").is_file():
            content = sorted(p.name for p in bag.iterdir())[:8]
            raise DataFormatError(where, None, "not a rosbag2 bag: the directory has no "
                                  f"metadata.yaml (it contains {content})")
    elif bag.suffix not in (".mcap", ".db3"):
        raise DataFormatError(where, None, "not a rosbag2 bag: expected a bag directory, a .mcap "
                              "or a .db3 file")
    try:
        from rosbags.rosbag2 import Reader
    except ImportError as exc:  # pragma: no cover - rosbags is a workbench dependency
        raise ImportError("reading bags needs the 'rosbags' package "
                          "(pip install 'ipmc_sensor_ros[workbench]')") from exc

    reading: str | None = None
    try:
        with Reader(bag) as reader:
            topics = reader.topics
            found = _find_topic(where, topics, current_topic)
            if found is None:
                raise DataFormatError(where, None, f"current topic not found; "
                                      f"{_describe_topics(topics)}", topic=current_topic)
            cur_name, cur_info = found
            dfound = None
            if deflection_topic is not None:
                dfound = _find_topic(where, topics, deflection_topic)
                if dfound is None and require_deflection:
                    raise DataFormatError(where, None, f"deflection topic not found; "
                                          f"{_describe_topics(topics)}", topic=deflection_topic)
            reading = cur_name
            tc, current = _read_topic(where, reader, cur_name, cur_info, CURRENT_LABEL, "current")
            if tc.size < 2:
                raise DataFormatError(where, None, f"only {tc.size} current sample(s); at least 2 "
                                      "are needed", topic=cur_name)
            deflection = alignment = None
            if dfound is not None:
                reading = dfound[0]
                td, vd = _read_topic(where, reader, dfound[0], dfound[1], DEFLECTION_LABEL,
                                     "deflection")
                deflection, alignment = _align(where, dfound[0], tc, td, vd)
            reading = None
    except DataFormatError:
        raise
    except Exception as exc:  # rosbags/sqlite3/mcap raise many types on corrupt input
        raise DataFormatError(where, None, f"cannot read bag (corrupt or truncated?): "
                              f"{type(exc).__name__}: {exc}", topic=reading) from exc

    known: dict[str, float] = {}
    extra: dict[str, Any] = {}
    sidecar_path = Path(sidecar) if sidecar is not None else \
        (bag if bag.is_dir() else bag.parent) / SIDECAR_NAME
    if sidecar is not None or sidecar_path.is_file():
        side_geometry, known, extra = _read_sidecar(where, sidecar_path, geometry is None)
        if geometry is None:
            geometry = side_geometry
    if geometry is None:
        raise DataFormatError(where, None, "no geometry: pass geometry= or put an "
                              f"{SIDECAR_NAME} sidecar with 'geometry: {{length_m, width_m, "
                              "thickness_m}' (metres) next to the bag")
    if not isinstance(geometry, Geometry):
        try:
            geometry = Geometry.from_dict(dict(geometry))
        except (ParameterError, TypeError) as exc:
            raise DataFormatError(where, None, f"geometry argument: {exc}") from None
    rate = 1.0 / float(np.median(np.diff(tc)))
    return TimeSeries(path=where, sample=geometry.name, geometry=geometry, known=known,
                      sample_rate_hz=rate, time_s=tc, current_a=current, deflection_m=deflection,
                      extra=extra, deflection_alignment=alignment)


def _stamp_ns(t: float) -> int:
    return int(round(float(t) * 1e9))


def write_bag(path: PathLike, timeseries: TimeSeries, storage: str = "sqlite3",
              current_topic: str = "current", deflection_topic: str = "deflection_truth",
              block_size: int = 100, *, deflection_msgtype: str = MULTIARRAY_TYPE,
              sidecar: bool = True) -> None:
    """Write ``timeseries`` as a rosbag2 bag (format version 8) readable by :func:`read_bag`.

    Current (and deflection, if any) go out as ``Float64MultiArray`` blocks of
    up to ``block_size`` samples, each stamped with its last sample time;
    ``deflection_msgtype=POINT_STAMPED_TYPE`` writes one ``PointStamped`` per
    deflection sample instead.  Topic names get a leading '/'.  With
    ``sidecar`` the geometry, known values and extra go to ``<bag>/ipmc.yaml``.
    Sample times must be >= 0 (they become bag timestamps).
    """
    import yaml
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugins = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}
    if storage not in plugins:
        raise ValueError(f"storage must be 'sqlite3' or 'mcap', got {storage!r}")
    if int(block_size) != block_size or block_size < 1:
        raise ValueError(f"block_size must be a positive integer, got {block_size!r}")
    if deflection_msgtype not in (MULTIARRAY_TYPE, POINT_STAMPED_TYPE):
        raise ValueError(f"deflection_msgtype must be {MULTIARRAY_TYPE!r} or "
                         f"{POINT_STAMPED_TYPE!r}, got {deflection_msgtype!r}")
    ts = timeseries
    if ts.n_samples and ts.time_s.min() < 0.0:
        raise ValueError("sample times must be >= 0 to be written as bag timestamps")
    bag = Path(path)
    if bag.exists():
        raise FileExistsError(f"{bag} exists; write_bag does not overwrite")
    store = _typestore()
    types = store.types
    F64, Layout, Dim = (types["std_msgs/msg/Float64MultiArray"],
                        types["std_msgs/msg/MultiArrayLayout"],
                        types["std_msgs/msg/MultiArrayDimension"])

    def block(t: np.ndarray, v: np.ndarray, label: str):
        n = int(t.size)
        data = np.empty(2 * n)
        data[0::2], data[1::2] = t, v
        layout = Layout(dim=[Dim(label=SAMPLE_LABEL, size=n, stride=2 * n),
                             Dim(label=label, size=2, stride=2)], data_offset=0)
        return store.serialize_cdr(F64(layout=layout, data=data), MULTIARRAY_TYPE)

    def topic(name: str) -> str:
        return "/" + _topic_key(name)

    with Writer(bag, version=8, storage_plugin=plugins[storage]) as writer:
        cur = writer.add_connection(topic(current_topic), MULTIARRAY_TYPE, typestore=store)
        dconn = None
        if ts.deflection_m is not None:
            dconn = writer.add_connection(topic(deflection_topic), deflection_msgtype,
                                          typestore=store)
        for start in range(0, ts.n_samples, int(block_size)):
            sl = slice(start, start + int(block_size))
            t = ts.time_s[sl]
            stamp = _stamp_ns(t[-1])
            writer.write(cur, stamp, block(t, ts.current_a[sl], CURRENT_LABEL))
            if dconn is not None and deflection_msgtype == MULTIARRAY_TYPE:
                writer.write(dconn, stamp, block(t, ts.deflection_m[sl], DEFLECTION_LABEL))
        if dconn is not None and deflection_msgtype == POINT_STAMPED_TYPE:
            Point, PointStamped = types["geometry_msgs/msg/Point"], types[POINT_STAMPED_TYPE]
            Header, Time = types["std_msgs/msg/Header"], types["builtin_interfaces/msg/Time"]
            for t, d in zip(ts.time_s.tolist(), ts.deflection_m.tolist()):
                ns = _stamp_ns(t)
                sec, nsec = divmod(ns, 10**9)
                msg = PointStamped(header=Header(stamp=Time(sec=sec, nanosec=nsec),
                                                 frame_id="ipmc_tip"),
                                   point=Point(x=0.0, y=0.0, z=d))
                writer.write(dconn, ns, store.serialize_cdr(msg, POINT_STAMPED_TYPE))
    if sidecar:
        geometry = ts.geometry.to_dict()
        geometry["name"] = ts.sample or ts.geometry.name
        doc: dict[str, Any] = {"geometry": geometry}
        if ts.known:
            doc["material"] = dict(ts.known)
        if ts.extra:
            doc["extra"] = dict(ts.extra)
        (bag / SIDECAR_NAME).write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")


# ---------------------------------------------------------------------------
# Dispatch
# ---------------------------------------------------------------------------
def read_any(path: PathLike) -> TimeSeries | FrequencyResponseData:
    """Read any supported input.

    A directory or a ``.mcap``/``.db3`` file is read with :func:`read_bag`
    (default topics, sidecar geometry); a text file is dispatched on its
    ``# format:`` header line.
    """
    p = Path(path)
    if p.is_dir() or p.suffix in (".mcap", ".db3"):
        return read_bag(path)
    lines = _read_lines(path)
    header = _parse_header(path, lines)
    fmt = _format_of(path, lines, header)
    if fmt == TIMESERIES_FORMAT:
        return _timeseries_from_lines(path, lines, header)
    return _frf_from_lines(path, lines, header)


def load_many(paths: Iterable[PathLike]) -> list[TimeSeries | FrequencyResponseData]:
    """:func:`read_any` each path, in order; the first failure raises (naming its file)."""
    return [read_any(p) for p in paths]
