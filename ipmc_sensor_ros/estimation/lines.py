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
  exponential with mean the local level);
* the frequency's variance is the Cramér–Rao bound of a harmonic family in white noise
  (Kay, *Fundamentals of Statistical Signal Processing I*, eq. 3.41, each harmonic k adding
  k^2 times its signal-to-noise ratio): var f = 12 fs^2 / ((2 pi)^2 N (N^2 - 1)
  sum_k k^2 eta_k), eta_k = A_k^2 / (2 sigma_k^2), the noise sigma_k^2 read from the local
  level (a Hann-windowed bin of white noise holds 3N/8 sigma^2).

The line is one frequency measured again at every check, so the measurements are joined
(:meth:`Line.joined`: the inverse-variance mean, a Kalman filter on a constant) and the
model follows the joined frequency once the modelled one is unlikely and its phasors would
drift faster than their walk follows (:meth:`Line.follows`). A line with 20-40 % hum (3 uA
on 0.12 uA of noise) was measured to 50.1180 Hz on the first 0.5 s and kept within a 0.02 Hz
tolerance though every 2 s window after it read 50.1143 +- 0.0003 Hz (the truth 50.1143):
its phasors turned 0.023 rad/s, the walk lagged them by up to a microampere and the
innovations' variance grew to 38 times the model's over 20 s.
"""
from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np
from scipy.ndimage import maximum_filter1d
from scipy.stats import norm

from ..lti.discretize import USABLE_BAND_FRACTION

__all__ = ['measure_line', 'Line', 'NOMINAL_LINES_HZ', 'SEARCH_HZ', 'FIND_FALSE_ALARM', 'PAD',
           'family_peak', 'vertex', 'local_level', 'local_levels']

#: Nominal mains frequencies, Hz.
NOMINAL_LINES_HZ = (50.0, 60.0)
#: Search half-width about a nominal frequency, Hz: a grid's tolerance (European and North
#: American grids stay within +-0.2 Hz in normal operation; 1 % of 50 Hz covers islanded
#: supplies and DAQ clock errors).
SEARCH_HZ = 0.5
#: False-alarm level of finding a mains line or a periodic motion in one window: what is
#: found is a candidate (a line's states learn ~0 where there is none; a motion's model must
#: explain the current at ``false_alarm`` before it is taken), what is missed is not modelled
#: at all, so the search is the more permissive of the two.
FIND_FALSE_ALARM = 1e-4
#: Zero-padding factor of the periodogram (frequency grid 1/(PAD T)).
PAD = 8
#: the level (A^2) taken for a noise-free line: its information huge but finite, even at
#: the 1 A input limit
_TINY = 1e-300


class Line(NamedTuple):
    """A mains line measured: its fundamental, its amplitude, how well its frequency is known."""

    #: fundamental, Hz (0: no line)
    hz: float = 0.0
    #: amplitude of its strongest harmonic, A
    amplitude_a: float = 0.0
    #: variance of ``hz``, Hz^2 (the Cramér–Rao bound of the window it was measured on)
    hz_var: float = math.inf
    #: how fast a frequency error turns the line's phasors: 2 pi max_k k A_k, A/s per Hz
    drift_a_per_hz: float = 0.0

    def joined(self, new: 'Line', shared: float, false_alarm: float) -> 'Line':
        """
        Return this line's frequency joined with a new measurement of it (inverse variance).

        ``shared``: the fraction of the new window's samples the last window measured too
        (windows of 2 s every second: 0.5); the new measurement counts for 1 - ``shared``
        of its information.  A measurement farther from this one than chance puts it once in
        1 / ``false_alarm`` checks (:func:`_new_line_z` standard deviations) starts afresh (a
        grid whose frequency stepped, another line); no line measured keeps this one.
        """
        if not new.hz:
            return self
        var = new.hz_var / max(1.0 - shared, 1e-12)
        z = _new_line_z(false_alarm)
        if not self.hz or (new.hz - self.hz) ** 2 > z * z * (self.hz_var + var):
            return new._replace(hz_var=var)
        joined_var = 1.0 / (1.0 / self.hz_var + 1.0 / var)
        hz = joined_var * (self.hz / self.hz_var + new.hz / var)
        return new._replace(hz=hz, hz_var=joined_var)

    def follows(self, model_hz: float, config) -> bool:
        """
        Tell whether line states at ``model_hz`` follow this line: keep them.

        A frequency error df turns harmonic k's phasor by 2 pi k df rad/s: its states move by
        ``drift_a_per_hz`` df in a second, against ``walk_a`` (A/sqrt(s): their walk's RMS
        over a second; ``config.line_walk_a``); beyond it the states lag the line and its
        residual grows.  And a ``model_hz`` not a new line (:meth:`joined`, at
        ``config.false_alarm``) is as likely as the joined frequency (retuning to it would
        chase the measurements' noise).
        """
        error, z = abs(self.hz - model_hz), _new_line_z(config.false_alarm)
        return (self.drift_a_per_hz * error <= config.line_walk_a
                or error * error <= z * z * self.hz_var)


@functools.lru_cache(maxsize=8)
def _new_line_z(false_alarm: float) -> float:
    """Return the standard deviations beyond which a measurement is a new line (two-sided)."""
    return float(norm.isf(0.5 * false_alarm))


def measure_line(current_a, sample_rate_hz: float, nominal=NOMINAL_LINES_HZ,
                 harmonics: int = 3, false_alarm: float = FIND_FALSE_ALARM) -> Line:
    """
    Return the strongest mains line (:class:`Line`; ``Line()`` when there is none).

    ``nominal``: the nominal frequencies searched (one for a configured ``mains_hz``).
    """
    x = np.asarray(current_a, dtype=float)
    fs = float(sample_rate_hz)
    if x.size < 64 or not np.all(np.isfinite(x)):
        return Line()
    x = (x - x.mean()) * np.hanning(x.size)
    # grid at most 0.02 Hz (the parabola's vertex then errs far below the grid)
    n_fft = 1 << int(math.ceil(math.log2(max(PAD * x.size, fs / 0.02))))
    power = np.abs(np.fft.rfft(x, n_fft)) ** 2
    df = fs / n_fft
    best, top_hz = (0.0, -1.0), USABLE_BAND_FRACTION * fs
    for f0 in nominal:
        ks = [k for k in range(1, harmonics + 1) if k * (f0 + SEARCH_HZ) < top_hz]
        if not ks:
            continue
        cand = np.arange(int((f0 - SEARCH_HZ) / df), int((f0 + SEARCH_HZ) / df) + 1)
        peak_bin, top = family_peak(power, cand, ks, max(1, n_fft // x.size))
        if top > best[1]:
            best = (peak_bin * df, top)
    f_line = best[0]
    if not f_line:
        return Line()
    # every zero-padded bin searched, at each harmonic, is a chance: P(exp(1) > factor) = that
    searched = max(1, int(2 * SEARCH_HZ / df) * len(nominal) * harmonics)
    factor = math.log(searched / false_alarm)
    n = x.size
    amp, drift, info = 0.0, 0.0, 0.0
    for k in range(1, harmonics + 1):
        if k * f_line >= top_hz:
            break
        j = int(round(k * f_line / df))
        level = local_level(power, j, df)
        a_k = 4.0 * math.sqrt(power[j]) / n     # the Hann window sums to n/2: A = 2|X|/sum
        # eta_k = A_k^2 / (2 sigma^2), sigma^2 = level / (3n/8): the line's power above noise
        info += k * k * 3.0 * max(power[j] - level, 0.0) / (n * max(level, _TINY))
        if power[j] > factor * level:
            amp, drift = max(amp, a_k), max(drift, 2.0 * math.pi * k * a_k)
    if not amp:
        return Line()
    hz_var = 12.0 * fs * fs / ((2.0 * math.pi) ** 2 * n * (n * n - 1.0) * info)
    return Line(float(f_line), float(amp), float(hz_var), float(drift))


def family_peak(power: np.ndarray, cand: np.ndarray, ks, reach: int = 1) -> tuple[float, float]:
    """
    Return (fractional bin, summed power) of the strongest family: power summed at k c.

    ``cand``: candidate fundamental bins; ``ks``: the harmonics summed; ``reach``: bins per
    resolution bin (1 / T).  Only a family whose summed power peaks within a resolution bin
    either side is one (the flank of a stronger line beside the range is not: a 24.3 Hz
    crank's second harmonic, 1.6 Hz below a 50.3 Hz line, put the maximum at the range's
    edge, 49.51 Hz); (0.0, -1.0) when none does.  The edges of ``cand`` only serve the
    parabolic vertex.
    """
    wide = np.arange(cand[0] - reach, cand[-1] + reach + 1)
    summed = sum(power[np.clip(k * wide, 0, power.size - 1)] for k in ks)
    peaks = summed >= maximum_filter1d(summed, 2 * reach + 1, mode='nearest')
    inner = np.flatnonzero(peaks[reach + 1:reach + cand.size - 1]) + 1     # bins of cand
    if not inner.size:
        return 0.0, -1.0
    summed = summed[reach:reach + cand.size]
    j = int(inner[np.argmax(summed[inner])])
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
