# SPDX-License-Identifier: Apache-2.0
"""
The white-noise variance per sample the Kalman filter measures (R of :mod:`.filter`).

R, the white-noise variance per sample, is measured on the current less the lines the filter
holds: the third difference i_k - 3 i_{k-1} + 3 i_{k-2} - i_{k-3} has variance 20 R for white
noise and passes a current at f only as (2 sin(pi f / fs))^6 (4e-6 at 20 Hz, 0.06 at 150 Hz,
at 1 kHz), so its square / 20, averaged over the setting ``noise_average_s`` (weights
normalised, so the first differences already give R; ``current_noise_a`` until then), is R.
A hum is not small there (0.56 at 150 Hz: a 2 % hum with harmonics read a 0.5 nA noise as
3.9 nA), so the lines' own third difference is taken off first, as the filter predicts it
from its state before the four samples (:attr:`.filter.KalmanFilter.line_difference`: the
phasors turned on; the state after them has fitted their noise, and a second's lines taken
from it read a 20 nA noise as 16 nA).  Differences across a bridged gap are skipped.

An ADC's rounding is noise of variance q^2 / 12 for a step q (uniform within a step), which
the third difference misses while the reading sits on one code: R is at least that, q the
smallest change between two successive samples seen (``step_a``; for unquantised data it
shrinks below any noise).  A still reading that steps by one code now and then is then
within the rest test's per-sample limit, not a 5.7 sigma outlier (16 bits over +-100 uA at
0.37 nA of noise).  Averaging removes the rounding only where the noise dithers it: a still
reading within a code or two of one level is rounded the same way sample after sample
(:meth:`NoiseMeter.rounding_bias_a2`, :mod:`.rounding`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .rest import RestWindow

__all__ = ['NoiseMeter', 'NOISE_CLIP', 'NOISE_FLOOR_A']

#: One sample counts at most this many times the measured variance in the noise average (a
#: step in the current moves the measured noise by at most this, not by its square).
NOISE_CLIP = 25.0
#: The measured noise stays above this, A RMS (below any DAQ's noise; a noise-free record would
#: otherwise drive the gain to infinity).
NOISE_FLOOR_A = 1e-12
#: sum over k >= 4 of 1 / k^2 (:meth:`NoiseMeter.rounding_bias_a2`)
_TAIL = math.pi ** 2 / 6.0 - 1.0 - 0.25 - 1.0 / 9.0


@dataclass(slots=True)
class NoiseMeter:
    """The white-noise variance per sample (module docstring), A^2: measured, quantiser's."""

    #: what the filter takes: the measured average, at least the quantiser's step^2 / 12
    var_a2: float
    weight: float = 0.0
    #: samples in a row one period apart (a third difference needs four)
    contiguous: int = 0
    #: the lines' third difference over the next four samples, as predicted after each of the
    #: last four (oldest first; empty when no lines are modelled), A
    ahead: tuple = ()
    #: the third differences' average, A^2 (weight 0: none yet)
    measured_a2: float = 0.0
    #: the smallest change between two samples seen (an ADC's step), A (inf: none yet)
    step_a: float = math.inf

    def add(self, current_a: float, steps: int, window: RestWindow, alpha: float,
            lines_next: float | None = None) -> None:
        """
        Take the newest sample (``window`` holds it and the three before).

        ``lines_next``: the lines' third difference over the four samples after this one, as
        the filter predicts it now (A); None: no lines are modelled.
        """
        ahead = self.ahead
        w, pos, n = window.samples, window.pos, window.samples.size
        if steps == 1 and self.contiguous:          # the sample before is in the window
            change = abs(current_a - w[(pos - 2) % n])
            if 0.0 < change < self.step_a:
                self.step_a = change
        if lines_next is not None:
            self.ahead = (ahead + (lines_next,))[-4:] if steps == 1 else (lines_next,)
        if steps != 1:
            self.contiguous = 0
            return
        if self.contiguous < 3:
            self.contiguous += 1
            return
        if lines_next is not None and len(ahead) < 4:
            return
        lines_a = ahead[0] if lines_next is not None else 0.0
        d = (current_a - 3.0 * w[(pos - 2) % n] + 3.0 * w[(pos - 3) % n] - w[(pos - 4) % n]
             - lines_a)
        value = d * d / 20.0
        if self.weight:
            value = min(value, NOISE_CLIP * self.var_a2)
        weight = (1.0 - alpha) * self.weight
        self.measured_a2 = (weight * self.measured_a2 + value) / (weight + 1.0)
        quantiser = self.step_a ** 2 / 12.0 if math.isfinite(self.step_a) else 0.0
        self.var_a2 = max(self.measured_a2, quantiser, NOISE_FLOOR_A ** 2)
        self.weight = weight + 1.0

    def rounding_bias_a2(self, noise_a2: float | None = None) -> float:
        """
        Return the variance of the mean rounding error at a still level, A^2 (0: no step seen).

        ``noise_a2``: the measured variance there (None: the meter's now).

        For a level at u within a step q and Gaussian noise sigma, the mean reading is off by
        the rounding's sawtooth smoothed by the noise, sum_k (-1)^(k+1) q / (pi k)
        sin(2 pi k u / q) exp(-2 pi^2 k^2 sigma^2 / q^2), of variance over u
        sum_k q^2 / (2 pi^2 k^2) exp(-4 pi^2 k^2 sigma^2 / q^2): q^2 / 12 without noise,
        below 1e-4 q^2 once sigma > q / 2 (terms past the third taken at k = 4).  sigma^2 is
        the measured variance less q^2 / 4, the most a still level's rounding adds (a
        reading toggling between two codes half the time): the least noise it can have had.
        """
        measured = self.measured_a2 if noise_a2 is None else noise_a2
        if not math.isfinite(self.step_a) or not math.isfinite(measured):
            return 0.0
        q2 = self.step_a ** 2
        c = 4.0 * math.pi ** 2 * max(measured - q2 / 4.0, 0.0) / q2
        if c > 700.0:               # e^-c underflows
            return 0.0
        e = math.exp(-c)
        terms = e + e ** 4 / 4.0 + e ** 9 / 9.0 + _TAIL * e ** 16
        return q2 / (2.0 * math.pi ** 2) * terms
