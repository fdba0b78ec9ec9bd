# SPDX-License-Identifier: Apache-2.0
"""
Measurement data classes of the workbench and the one error they raise (no rclpy needed).

:class:`TimeSeries` (current and optional tip deflection, SI units),
:class:`FrequencyResponseData` (a measured I/w) and :class:`DataFormatError`,
raised by every reader (text formats, lab import, bags) with the file, line
and topic of the problem.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Union

import numpy as np

from ..physics.parameters import Geometry
from ..errors import DataError, DataFormatError

__all__ = ['DataFormatError', 'TimeSeries', 'FrequencyResponseData', 'PathLike',
           'RATE_DIGITS', 'round_rate_hz', 'geometry_label', 'sample_label']

PathLike = Union[str, Path]

#: Significant digits kept of a sample rate (1 ppb: a DAQ clock is specified to ppm, while
#: 1/median(dt) of float time stamps carries float noise, e.g. 999.9999999999991 Hz).
RATE_DIGITS = 9


def round_rate_hz(rate_hz: float) -> float:
    """Return a (measured) sample rate rounded to :data:`RATE_DIGITS` significant digits."""
    return float(f'{float(rate_hz):.{RATE_DIGITS}g}')


def geometry_label(geometry: Geometry) -> str:
    """Name of an unnamed sample from its geometry, L x W x T in mm: ``22x7x0.36mm``."""
    return 'x'.join(f'{v * 1e3:.4g}' for v in (geometry.length_m, geometry.width_m,
                                               geometry.thickness_m)) + 'mm'


def sample_label(data) -> str:
    """
    Return the label of a record's sample: its name, else its geometry's name, else the geometry.

    Two unnamed samples of different geometry never share a label.
    """
    return str(getattr(data, 'sample', '') or data.geometry.name or geometry_label(data.geometry))


# ---------------------------------------------------------------------------
# Data classes
# ---------------------------------------------------------------------------
def _vector(name: str, values: Any, n: int | None = None) -> np.ndarray:
    arr = np.array(values, dtype=float, copy=True)
    if arr.ndim != 1:
        raise DataError(f'{name} must be 1-D, got shape {arr.shape}')
    if n is not None and arr.size != n:
        raise DataError(f'{name} has {arr.size} values, expected {n}')
    return arr


@dataclass(frozen=True, eq=False)
class TimeSeries:
    """
    Synchronous samples of sensing current and (optionally) tip deflection, SI units.

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
    first_row_line : 1-based line of the first data row of a text file (rows are
        contiguous: sample k is on line ``first_row_line + k``); None for bags.
    notes : what the reader left out and why, one line each naming the place (e.g. an
        incomplete last line of a file still being written).
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
    first_row_line: int | None = None
    notes: tuple = ()

    def __post_init__(self) -> None:
        if not isinstance(self.geometry, Geometry):
            raise TypeError(f'geometry must be a Geometry, got {type(self.geometry).__name__}')
        t = _vector('time_s', self.time_s)
        object.__setattr__(self, 'time_s', t)
        object.__setattr__(self, 'current_a', _vector('current_a', self.current_a, t.size))
        if self.deflection_m is not None:
            object.__setattr__(self, 'deflection_m',
                               _vector('deflection_m', self.deflection_m, t.size))
            if self.deflection_alignment is None:
                object.__setattr__(self, 'deflection_alignment', 'exact')
        elif self.deflection_alignment is not None:
            raise DataError('deflection_alignment given but deflection_m is None')
        if self.deflection_alignment not in (None, 'exact', 'linear'):
            raise DataError(f"deflection_alignment must be 'exact', 'linear' or None, "
                            f'got {self.deflection_alignment!r}')
        object.__setattr__(self, 'sample_rate_hz', round_rate_hz(self.sample_rate_hz))
        object.__setattr__(self, 'known', {str(k): float(v) for k, v in self.known.items()})
        object.__setattr__(self, 'extra', dict(self.extra))
        object.__setattr__(self, 'path', str(self.path))
        object.__setattr__(self, 'sample', str(self.sample))

    @property
    def label(self) -> str:
        """Return the sample's name, else its geometry's (:func:`sample_label`)."""
        return sample_label(self)

    @property
    def n_samples(self) -> int:
        return int(self.time_s.size)

    def where(self, k: int) -> str:
        """Return where sample ``k`` is: ``path:line`` in a text file, else path and time."""
        if self.first_row_line is not None:
            return f'{self.path}:{self.first_row_line + int(k)}'
        return f'{self.path}: sample {int(k)} (t = {float(self.time_s[k])!r} s)'

    @property
    def has_deflection(self) -> bool:
        return self.deflection_m is not None

    @property
    def duration_s(self) -> float:
        return float(self.time_s[-1] - self.time_s[0]) if self.time_s.size else 0.0


@dataclass(frozen=True, eq=False)
class FrequencyResponseData:
    """
    A measured frequency response I/w of one sample, SI units.

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
            raise TypeError(f'geometry must be a Geometry, got {type(self.geometry).__name__}')
        f = _vector('frequency_hz', self.frequency_hz)
        object.__setattr__(self, 'frequency_hz', f)
        for name in ('gain_a_per_m', 'phase_deg'):
            object.__setattr__(self, name, _vector(name, getattr(self, name), f.size))
        for name in ('coherence', 'gain_std_a_per_m', 'phase_std_deg'):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, _vector(name, getattr(self, name), f.size))
        if (self.gain_std_a_per_m is None) != (self.phase_std_deg is None):
            raise DataError('gain_std_a_per_m and phase_std_deg must be given together')
        object.__setattr__(self, 'known', {str(k): float(v) for k, v in self.known.items()})
        object.__setattr__(self, 'extra', dict(self.extra))
        object.__setattr__(self, 'path', str(self.path))
        object.__setattr__(self, 'sample', str(self.sample))

    @property
    def label(self) -> str:
        """Return the sample's name, else its geometry's (:func:`sample_label`)."""
        return sample_label(self)

    @property
    def gain_std(self) -> np.ndarray | None:
        """Alias of ``gain_std_a_per_m``."""
        return self.gain_std_a_per_m

    @property
    def response(self) -> np.ndarray:
        """Complex response I/w = gain * exp(j * deg2rad(phase)), A/m."""
        return self.gain_a_per_m * np.exp(1j * np.deg2rad(self.phase_deg))
