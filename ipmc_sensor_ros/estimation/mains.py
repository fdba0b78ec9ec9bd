"""Mains interference: streaming notch at 50 or 60 Hz and harmonics, and a line detector.

A DAQ near mains wiring picks up the line frequency and its odd/even harmonics.
:class:`MainsFilter` removes them with one :func:`scipy.signal.iirnotch` second-order
section per harmonic below 0.45 fs (quality factor ``quality``: -3 dB width
f/Q, 1.7 Hz at 50 Hz for Q = 30), cascaded as SOS with explicit state, so blocks
of any size give identical output.  ``mains_hz = 0`` passes the current through.

:func:`line_level` (and :attr:`MainsFilter.line_ratio`) measures the line
component: the RMS of what the notch removed relative to the RMS of the
signal, per block; :data:`LINE_WARN_RATIO` (1 %) is the level above which a
line component is "present".
"""
from __future__ import annotations

import numpy as np
import scipy.signal as sig

from .inverse import EstimatorError

__all__ = ["MainsFilter", "mains_sos", "line_level", "LINE_WARN_RATIO"]

#: Line RMS / signal RMS above which a line component is reported as present.
LINE_WARN_RATIO = 0.01


def mains_sos(mains_hz: float, sample_rate_hz: float, quality: float = 30.0,
              max_harmonics: int = 10) -> np.ndarray:
    """Second-order sections of notches at k * mains_hz (k = 1.. below 0.45 fs)."""
    if mains_hz not in (0, 50, 60):
        raise EstimatorError(f"parameter 'mains_hz' must be 0, 50 or 60, got {mains_hz!r}")
    rows = []
    k = 1
    while mains_hz and k * mains_hz < 0.45 * sample_rate_hz and k <= max_harmonics:
        b, a = sig.iirnotch(k * mains_hz, quality, fs=sample_rate_hz)
        rows.append(np.concatenate([b, a]))
        k += 1
    return np.array(rows) if rows else np.zeros((0, 6))


def line_level(current_a, sample_rate_hz: float, mains_hz: float = 50.0, quality: float = 30.0) -> float:
    """RMS of the line component (fundamental and harmonics) over the RMS of the
    current with its mean removed (0 .. 1)."""
    x = np.asarray(current_a, float) - np.mean(current_a)
    sos = mains_sos(mains_hz, sample_rate_hz, quality)
    if sos.shape[0] == 0 or not np.any(x):
        return 0.0
    clean = sig.sosfiltfilt(sos, x)
    return float(np.sqrt(np.mean((x - clean) ** 2)) / np.sqrt(np.mean(x ** 2)))


class MainsFilter:
    """Streaming mains notch (``mains_hz`` 0, 50 or 60) with a line detector.

    ``process(block)`` returns the filtered current; ``line_ratio`` is the RMS of
    the removed component over the RMS of the block's input (its mean removed),
    and ``line_present`` is ``line_ratio > LINE_WARN_RATIO``.
    """

    def __init__(self, mains_hz: float, sample_rate_hz: float, quality: float = 30.0):
        self.mains_hz = mains_hz
        self.sample_rate_hz = float(sample_rate_hz)
        self.sos = mains_sos(mains_hz, self.sample_rate_hz, quality)
        self.reset()

    def reset(self) -> None:
        self._zi = np.zeros((self.sos.shape[0], 2))
        self.line_ratio = 0.0

    @property
    def line_present(self) -> bool:
        return self.line_ratio > LINE_WARN_RATIO

    def process(self, current_a) -> np.ndarray:
        x = np.asarray(current_a, float)
        if self.sos.shape[0] == 0 or x.size == 0:
            return x
        y, self._zi = sig.sosfilt(self.sos, x, zi=self._zi)
        if x.size > 1:
            ac = x - x.mean()
            denom = float(np.sqrt(np.mean(ac * ac)))
            self.line_ratio = float(np.sqrt(np.mean((x - y) ** 2)) / denom) if denom > 0 else 0.0
        return y
