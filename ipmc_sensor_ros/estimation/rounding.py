# SPDX-License-Identifier: Apache-2.0
"""
The rounding a still reading keeps: its share of the published deflection's variance.

An ADC rounds to steps q.  The filter takes the rounding for white noise of variance q^2/12
(:mod:`.noise`), which averaging removes; but a still reading within a code or two of one
level is rounded the same way sample after sample, so the offset a rest measures is the true
one plus a rounding error beta of that level (a 12-bit ADC over +-10 uA rounds in 5-25 nA
steps: at 0.2 nA of noise a rest reads one code, and beta is up to half of it).  The filter
does not estimate beta (at rest it cannot be told from the offset; in motion the rounding is
white); its deflection error carries beta through the gains it used (a *consider* analysis,
Schmidt 1966; Bierman 1977, ch. VIII): with d the sensitivity of the state estimate to beta,
per ampere (scaled units, :mod:`.filter`)::

    predict   d- = F d
    update    d = d- + K (h - row d-)      K the update's gain; h = 1 for a current measured at
                                           rest (the reading and the window's mean carry beta),
                                           0 in motion and for the rest's pseudo-measurements

and the published variance of w is e_w P e_w' + Var(beta) (e_w d)^2 + f, f the shares of
the rests before (each rest rounds at its own level: when one begins, its predecessor's share
is folded into f and d restarts; when the model changes, d is carried as the state is,
:mod:`.carry`).  Var(beta) is the meter's (:meth:`.noise.NoiseMeter.rounding_bias_a2`) for
the noise measured at the rest and the step known when the deflection is published, so a
step the reading shows only once it moves still counts for the rest before.  The estimate
itself is not changed; without a quantiser step (or with a noise that dithers it) Var(beta)
is 0 and so is the share.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

__all__ = ['RoundingBias', 'RoundingTally']


class RoundingBias(NamedTuple):
    """The rounding's sensitivity a filter state keeps (module docstring)."""

    #: d: the state estimate's sensitivity to this rest's rounding error, per A (scaled)
    sensitivity: np.ndarray
    #: f: the shares of the rests before, m^2
    folded: float = 0.0
    #: the noise variance the meter measured at this rest, A^2 (inf: no rest yet)
    rest_noise_a2: float = math.inf

    def copy(self) -> 'RoundingBias':
        return self._replace(sensitivity=self.sensitivity.copy())


class RoundingTally:
    """
    d and f while the filter runs (mutable, one run's; :meth:`value` is what a state keeps).

    Parameters
    ----------
    bias : RoundingBias or None
        The state's (None: none yet, d = 0).
    size : int
        The model's state size.

    """

    __slots__ = ('d', 'folded', 'noise', 'zero', '_known')

    def __init__(self, bias: RoundingBias | None, size: int):
        bias = bias or RoundingBias(np.zeros(size))
        self.d, self.folded, self.noise = bias.sensitivity.copy(), bias.folded, bias.rest_noise_a2
        self.zero = not self.d.any()            # d = 0 stays 0 until a rest
        self._known = (None, 0.0)               # ((step, rest noise), Var(beta)) last asked

    def value(self) -> RoundingBias:
        return RoundingBias(self.d.copy(), self.folded, self.noise)

    def predict(self, F: np.ndarray, meter) -> None:
        """
        Predict d to the next sample, while this rest's rounding can matter.

        It cannot once the rest's noise dithers the meter's step past Var(beta) = 0
        (sigma > 4.2 q: exp(-4 pi^2 sigma^2 / q^2) underflows), as for any unquantised
        stream (its "step" is the smallest difference seen): d is then set to 0 (a rest
        whose rounding matters starts it again).
        """
        if not self.zero:
            if self._matters(meter):
                self.d = F @ self.d
            else:
                self.d, self.zero = np.zeros_like(self.d), True

    def update(self, gain: np.ndarray, row: np.ndarray, h: float, meter=None) -> None:
        """
        Follow an update of gain ``gain`` (K) on ``row``; ``h``: does it carry beta.

        ``meter``: the noise meter at a current measured at rest (its noise is this rest's).
        """
        if h and meter is not None:
            self.noise = meter.measured_a2
            if self.zero and not self._matters(meter):
                return
        if h or not self.zero:
            self.d = self.d + gain * (h - float(row @ self.d))
            self.zero = False

    def fold(self, w_row: np.ndarray, meter) -> None:
        """Fold the share of the rest before into f as a rest begins; d restarts."""
        if not self.zero:
            self.folded = self.variance(w_row, meter)
            self.d, self.zero = np.zeros_like(self.d), True

    def variance(self, w_row: np.ndarray, meter) -> float:
        """Return the share of the deflection's variance, m^2 (0 without a rest so far)."""
        if self.zero:
            return self.folded
        return self.folded + self._var_beta(meter) * float(w_row @ self.d) ** 2

    def _var_beta(self, meter) -> float:
        """Return Var(beta) for the meter's step and this rest's noise (kept while they stay)."""
        key = (meter.step_a, self.noise)
        if self._known[0] != key:
            self._known = key, meter.rounding_bias_a2(self.noise)
        return self._known[1]

    def _matters(self, meter) -> bool:
        """Tell whether this rest's rounding can matter: its step unknown yet, or not dithered."""
        return not math.isfinite(meter.step_a) or self._var_beta(meter) > 0.0
