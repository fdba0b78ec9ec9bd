# SPDX-License-Identifier: Apache-2.0
"""
Mains interference: streaming notch at 50 or 60 Hz and harmonics, and a line detector.

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

from ..lti.discretize import USABLE_BAND_FRACTION
from .inverse import ParameterError

__all__ = ['MainsFilter', 'mains_sos', 'line_level', 'detect_lines', 'LINE_WARN_RATIO']

#: Line RMS / signal RMS above which a line component is reported as present.
LINE_WARN_RATIO = 0.01


def mains_sos(mains_hz: float, sample_rate_hz: float, quality: float = 30.0,
              max_harmonics: int = 10) -> np.ndarray:
    """Second-order sections of notches at k * mains_hz (k = 1.. below 0.45 fs)."""
    if mains_hz not in (0, 50, 60):
        raise ParameterError(f"parameter 'mains_hz' must be 0, 50 or 60, got {mains_hz!r}")
    rows = []
    k = 1
    while mains_hz and k * mains_hz < USABLE_BAND_FRACTION * sample_rate_hz and k <= max_harmonics:
        b, a = sig.iirnotch(k * mains_hz, quality, fs=sample_rate_hz)
        rows.append(np.concatenate([b, a]))
        k += 1
    return np.array(rows) if rows else np.zeros((0, 6))


def line_level(
    current_a, sample_rate_hz: float, mains_hz: float = 50.0, quality: float = 30.0
) -> float:
    """
    RMS of the line component over the RMS of the current (0 .. 1).

    Line component: fundamental and harmonics; the current has its mean removed.
    """
    x = np.asarray(current_a, float) - np.mean(current_a)
    sos = mains_sos(mains_hz, sample_rate_hz, quality)
    if sos.shape[0] == 0 or not np.any(x):
        return 0.0
    clean = sig.sosfiltfilt(sos, x)
    return float(np.sqrt(np.mean((x - clean) ** 2)) / np.sqrt(np.mean(x ** 2)))


class MainsFilter:
    """
    Streaming mains notch (``mains_hz`` 0, 50 or 60) with a line detector.

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


#: :func:`detect_lines` first averages blocks of samples down to a rate of at least this, Hz:
#: well above the 5th harmonic of 60 Hz and its neighbour bins, and it bounds the cost of the
#: status at high sample rates.
DETECT_RATE_HZ = 2000.0


def detect_lines(current_a, sample_rate_hz: float, families=(50.0, 60.0), n_harmonics: int = 5,
                 threshold: float = 20.0) -> dict:
    """
    Mains lines in a stretch of current: which family (50 or 60 Hz) is present and how large.

    Each harmonic's power is a single-bin DFT (lock-in) at exactly k f_mains over the record,
    compared with the mean power at 6 neighbouring frequencies 3..8 bins away (the local
    noise floor); a harmonic is a line when it exceeds ``threshold`` times that floor (white
    noise exceeds 20x with probability e^-20 per bin).  Returns ``{"mains_hz": 50/60 or 0,
    "level": line RMS / RMS of the current (mean removed), "harmonics": [k, ...]}``.  Works on
    any stretch of at least 5 mains periods; broadband noise alone gives ``mains_hz = 0``.
    """
    x = np.asarray(current_a, float)
    out = {'mains_hz': 0, 'level': 0.0, 'harmonics': []}
    if x.size < 8 or not np.any(x):
        return out
    x = x - x.mean()
    total = float(np.sqrt(np.mean(x * x)))
    # mean of blocks of d samples: the lock-ins then cost O(n / d) (a 0.5 s history at 500 kHz
    # took 0.5 s of CPU per status); the block mean's gain at f is corrected below
    d = max(1, int(sample_rate_hz // DETECT_RATE_HZ))
    n = x.size // d
    x = x[x.size - n * d:].reshape(n, d).mean(axis=1)
    rate = sample_rate_hz / d
    t = np.arange(n) / rate
    df = rate / n
    best = (0.0, 0, [])
    for f0 in families:
        if n * f0 / rate < 5:
            continue
        line_power, found = 0.0, []
        for k in range(1, n_harmonics + 1):
            f = k * f0
            if f + 8 * df >= 0.5 * rate:
                break
            amp2 = abs(np.dot(x, np.exp(-2j * np.pi * f * t))) ** 2
            neigh = [abs(np.dot(x, np.exp(-2j * np.pi * (f + s * m * df) * t))) ** 2
                     for m in (3, 5, 8) for s in (-1, 1)]
            if amp2 > threshold * float(np.mean(neigh)):
                found.append(k)
                gain = np.sinc(f / rate) / np.sinc(f / sample_rate_hz)  # block mean's, at f
                line_power += 2.0 * amp2 / (gain * n) ** 2   # RMS^2 of a sinusoid of that DFT
        level = float(np.sqrt(line_power)) / total if total > 0 else 0.0
        if found and level > best[0]:
            best = (level, int(f0), found)
    if best[2]:
        out.update(mains_hz=best[1], level=best[0], harmonics=best[2])
    return out
