# SPDX-License-Identifier: Apache-2.0
"""
Measure the mains line in a stretch of current: is there hum, and at what frequency.

The estimator models the hum as states (:mod:`.statespace`) at a line frequency measured
from the data (``mains_hz: auto``: near 50 or 60 Hz; ``50``/``60``: near that one).  Grids
run up to +-0.5 Hz off nominal, so the fundamental is measured, not assumed:

* periodogram of the stretch (Hann window, zero-padded to ``PAD`` x its length and to a
  grid of at most 0.02 Hz);
* for each candidate f within +-``SEARCH_HZ`` of a nominal, the summed power at k f,
  k = 1..3 below 0.45 fs (the harmonics move together);
* the best candidate's fundamental by a parabolic vertex of the summed power;
* a line is *present* when, at some harmonic, the power exceeds the local level (median of
  the periodogram within 2..8 Hz of that harmonic, excluding the line) by the chi-square
  factor of ``false_alarm`` over the candidates searched (a periodogram bin of noise is
  exponential with mean the local level).
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ['measure_line', 'NOMINAL_LINES_HZ', 'SEARCH_HZ', 'PAD', 'family_peak', 'vertex',
           'local_level', 'local_levels']

#: Nominal mains frequencies, Hz.
NOMINAL_LINES_HZ = (50.0, 60.0)
#: Search half-width about a nominal frequency, Hz (grids stay within +-0.5 Hz).
SEARCH_HZ = 0.5
#: Zero-padding factor of the periodogram (frequency grid 1/(PAD T)).
PAD = 8


def measure_line(current_a, sample_rate_hz: float, nominal=NOMINAL_LINES_HZ,
                 harmonics: int = 3, false_alarm: float = 1e-4) -> tuple[float, float]:
    """
    Return (line frequency Hz, amplitude A) of the strongest mains line, or (0.0, 0.0).

    ``nominal``: the nominal frequencies searched (one for a configured ``mains_hz``).
    """
    x = np.asarray(current_a, dtype=float)
    fs = float(sample_rate_hz)
    if x.size < 64 or not np.all(np.isfinite(x)):
        return 0.0, 0.0
    x = (x - x.mean()) * np.hanning(x.size)
    # grid at most 0.02 Hz (the parabola's vertex then errs far below the grid)
    n_fft = 1 << int(math.ceil(math.log2(max(PAD * x.size, fs / 0.02))))
    power = np.abs(np.fft.rfft(x, n_fft)) ** 2
    df = fs / n_fft
    best = (0.0, -1.0)
    for f0 in nominal:
        ks = [k for k in range(1, harmonics + 1) if k * (f0 + SEARCH_HZ) < 0.45 * fs]
        if not ks:
            continue
        cand = np.arange(int((f0 - SEARCH_HZ) / df), int((f0 + SEARCH_HZ) / df) + 1)
        peak_bin, top = family_peak(power, cand, ks)
        if top > best[1]:
            best = (peak_bin * df, top)
    f_line = best[0]
    if not f_line:
        return 0.0, 0.0
    # every zero-padded bin searched, at each harmonic, is a chance: P(exp(1) > factor) = that
    searched = max(1, int(2 * SEARCH_HZ / df) * len(nominal) * harmonics)
    factor = math.log(searched / false_alarm)
    window_sum = 0.5 * x.size                   # sum of the Hann window: amplitude = 2|X|/sum
    amp = 0.0
    for k in range(1, harmonics + 1):
        if k * f_line >= 0.45 * fs:
            break
        j = int(round(k * f_line / df))
        level = local_level(power, j, df)
        if power[j] > factor * level:
            amp = max(amp, 2.0 * math.sqrt(power[j]) / window_sum)
    return (f_line, amp) if amp else (0.0, 0.0)


def family_peak(power: np.ndarray, cand: np.ndarray, ks) -> tuple[float, float]:
    """
    Return (fractional bin, summed power) of the strongest family: power summed at k c.

    ``cand``: candidate fundamental bins; ``ks``: the harmonics summed.  The edges of
    ``cand`` only serve the parabolic vertex.
    """
    summed = sum(power[np.minimum(k * cand, power.size - 1)] for k in ks)
    j = int(np.argmax(summed[1:-1])) + 1
    return vertex(cand, summed, j), float(summed[j])


def vertex(cand: np.ndarray, summed: np.ndarray, j: int) -> float:
    """Fractional bin of the maximum (parabola through the three bins about it)."""
    if 0 < j < summed.size - 1:
        a, b, c = summed[j - 1], summed[j], summed[j + 1]
        den = a - 2 * b + c
        # within half a bin of a maximum; a larger neighbour outside the searched range (a
        # flank: b is the largest inside only) could put it anywhere
        if den < 0:
            return float(cand[j]) + float(np.clip(0.5 * (a - c) / den, -0.5, 0.5))
    return float(cand[j])


def local_level(power: np.ndarray, j: int, df: float) -> float:
    """Median periodogram 2..8 Hz either side of bin j (the noise level about a line)."""
    return float(local_levels(power, np.array([j]), df)[0])


def local_levels(power: np.ndarray, bins: np.ndarray, df: float) -> np.ndarray:
    """Return :func:`local_level` of each of ``bins`` (those away from the edges at once)."""
    lo, hi = int(2.0 / df), int(8.0 / df)
    bins = np.asarray(bins, dtype=np.int64)
    out = np.empty(bins.size)
    inner = (bins - hi >= 1) & (bins + hi <= power.size)
    if inner.any():
        offsets = np.r_[np.arange(-hi, -lo), np.arange(lo, hi)]
        out[inner] = np.median(power[bins[inner, None] + offsets], axis=1)
    for k in np.flatnonzero(~inner):
        j = int(bins[k])
        side = np.r_[power[max(j - hi, 1):max(j - lo, 1)], power[j + lo:j + hi]]
        out[k] = np.median(side) if side.size else math.inf
    # the median of an exponential is ln 2 times its mean
    return out / math.log(2.0)
