# SPDX-License-Identifier: Apache-2.0
"""
When each sample was taken: on its slot of the sample clock, or at its stamp.

A DAQ on its own clock samples on the slots, and the host stamps each sample late by a
varying delay; a DAQ the host times samples when it stamps.  The filter's state is on the
slots (:mod:`.timebase`); a sample d periods off its slot measures c e^{A d/fs} x if taken
at its stamp and c x if on its slot.  With p the probability of the first, the filter
(:mod:`.filter`) uses the mixture's mean row (1 - p) c + p c e^{A d/fs}, adds the mixture's
spread p (1 - p) g^2 to R (g = (c e^{A d/fs} - c) x-, the current the offset would add), and
publishes the tip where the sample was taken (:class:`OffSlot`).  p starts at
``sampled_at_stamp_prior`` and is revised by the innovations (:class:`StampEvidence`,
:func:`at_stamp`).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .statespace import OFF_SLOT_STEPS

__all__ = ['OffSlot', 'StampEvidence', 'StampTally', 'at_stamp', 'STAMP_WINDOW', 'ON_SLOT']

#: A sample closer to its slot than this (periods) is on it: half a row of the table
#: (:meth:`OffSlot.index` picks the slot's own row there, so it changes no estimate).  The stamps
#: of an exact grid land ~1e-10 periods off their slots by float rounding alone; they take the
#: slot's path and add no evidence on where the samples were taken.
ON_SLOT = 0.5 / OFF_SLOT_STEPS


class OffSlot:
    """
    The rows of a sample off its slot, as a table over the period.

    Parameters
    ----------
    model : StateSpaceModel
        Its :attr:`~.statespace.StateSpaceModel.off_slot_rows` (built when first needed).
    w_row : numpy.ndarray
        The row of the published deflection on the slot (m per scaled state).

    """

    def __init__(self, model, w_row: np.ndarray):
        self.model, self.w_row = model, w_row
        self._mixed = (None, None)

    @staticmethod
    def index(d: float) -> int:
        """Return the table row nearest to ``d`` periods off the slot."""
        return int((d + 0.5) * OFF_SLOT_STEPS + 0.5)

    def mixed(self, p: float) -> tuple:
        """
        Return tables (dc, current rows, deflection rows) for the probability ``p``.

        Row j is for d = j / OFF_SLOT_STEPS - 1/2 (:meth:`index`): dc the current row less
        the slot's (g = dc x, the current the offset adds), the mixture's mean current row
        c + p dc and deflection row likewise.  The last ``p``'s are kept (it changes only
        as a window of evidence closes).
        """
        if self._mixed[0] != p:
            tc, tw = self.model.off_slot_rows
            dc = tc - self.model.c
            self._mixed = p, (dc, self.model.c + p * dc, self.w_row + p * (tw - self.w_row))
        return self._mixed[1]


#: Samples off their slots per window of the stamps' evidence: the regression's variance is
#: an asymptotic one (White 1980), within ~10 % of the truth from a few tens of samples, and a
#: window confines a burst of innovations (a release, a start) to its own weight.
STAMP_WINDOW = 128


class StampEvidence(NamedTuple):
    """
    The regression of the innovations on what a sample's offset from its slot would explain.

    For a sample taken d periods off its slot, g = (c(d) - c) x- is the current the offset
    would add (:meth:`OffSlot.mixed`); the innovation on the slot is
    z = beta g + e, beta = 1 if the sample was taken at its stamp and 0 if on its slot.
    Over each window of ``STAMP_WINDOW`` such samples, sums of z g, g^2, (z g)^2, z g^3 and
    g^4 give the least-squares beta and its heteroscedasticity-consistent variance V (White
    1980), which holds whatever the innovations' own spread, mean and correlation: the
    offsets are the stamps' jitter, independent from sample to sample.  V is itself an
    estimate, from as many samples as carry g: n_eff = (sum g^2)^2 / sum g^4 (a start from
    rest puts a window's g into a few samples), so beta is Student-t with n_eff - 1 degrees
    of freedom about 1 or 0, and a window's log-likelihood ratio of beta = 1 against
    beta = 0 is that of the two t densities ((2 beta - 1) / (2 V) when n_eff is large); the
    windows' add (``llr``).  z and g are over sqrt(S) of the sample before, not of this sample's
    row: that S depends on the offset, and a systematic innovation over it would bias beta
    towards the row the filter used.  The filter keeps the sums (:mod:`.filter`).
    """

    zg: float = 0.0
    gg: float = 0.0
    zzgg: float = 0.0
    zggg: float = 0.0
    gggg: float = 0.0
    #: samples in the open window, and the closed windows' log-likelihood ratio
    n: int = 0
    llr: float = 0.0
    #: sqrt(S) of the last sample: the next one's unit (it does not depend on that offset)
    scale: float = 0.0

    def window_llr(self) -> float:
        """Return the window's log-likelihood ratio (0 if it says nothing)."""
        if self.gg <= 0.0 or self.n < 2:
            return 0.0
        beta = self.zg / self.gg
        resid = self.zzgg - 2.0 * beta * self.zggg + beta * beta * self.gggg
        var = resid / self.gg ** 2 * self.n / (self.n - 1)
        if not var > 0.0:
            return 0.0
        dof = max(self.gg * self.gg / self.gggg - 1.0, 1.0)
        return 0.5 * (dof + 1.0) * (math.log1p(beta * beta / (dof * var))
                                    - math.log1p((beta - 1.0) ** 2 / (dof * var)))


def at_stamp(evidence: StampEvidence, prior: float) -> float:
    """
    Return the probability that the samples were taken at their stamps, not on their slots.

    A DAQ on its own clock samples on the slots and the host stamps late by a varying
    delay; a DAQ timed by the host samples when it stamps.  The windows' log-likelihood
    ratio (:class:`StampEvidence`) is added to the prior's log-odds
    (``sampled_at_stamp_prior``; 0 or 1 is not revised).
    """
    if not 0.0 < prior < 1.0:
        return prior
    odds = evidence.llr + math.log(prior / (1.0 - prior))
    return 1.0 / (1.0 + math.exp(-min(max(odds, -700.0), 700.0)))


class StampTally:
    """
    The stamps' evidence while the filter runs, and the rows of a sample off its slot.

    Mutable (one run's; :meth:`value` is the :class:`StampEvidence` a state keeps).  p, the
    probability that the samples were taken at their stamps, is revised as each window of
    ``STAMP_WINDOW`` samples off their slots closes (:func:`at_stamp`), and the mixture's
    rows with it (:meth:`OffSlot.mixed`).
    """

    __slots__ = ('zg', 'gg', 'zzgg', 'zggg', 'gggg', 'n', 'llr', 'scale', 'prior', 'p', 'off',
                 'tables')

    def __init__(self, evidence: StampEvidence, off: OffSlot, prior: float):
        (self.zg, self.gg, self.zzgg, self.zggg, self.gggg, self.n, self.llr,
         self.scale) = evidence
        self.prior, self.off = prior, off
        self.p = at_stamp(evidence, prior)
        self.tables = off.mixed(self.p)

    def value(self) -> StampEvidence:
        """Return the sums as they stand."""
        return StampEvidence(self.zg, self.gg, self.zzgg, self.zggg, self.gggg, self.n,
                             self.llr, self.scale)

    def row(self, d: float, x: np.ndarray, var: float):
        """
        Return (current row, deflection row, R, g) of a sample ``d`` periods off its slot.

        The mixture's mean rows, R grown by its spread p (1 - p) g^2 (module docstring).
        """
        j = self.off.index(d)
        dc, mixed_c, mixed_w = self.tables
        g = float(dc[j] @ x)
        return mixed_c[j], mixed_w[j], var + self.p * (1.0 - self.p) * g * g, g

    def add(self, d: float, z: float, r: float, g: float) -> None:
        """
        Add a sample's innovation ``z`` (over ``r`` = sqrt(S)) and ``g`` if it was off its slot.

        Both over sqrt(S) of the sample before (:class:`StampEvidence`); a window closed adds
        its log-likelihood ratio and revises p.
        """
        if d:
            unit = self.scale or r
            zk, gk = (z * r + self.p * g) / unit, g / unit
            self.zg, self.gg = self.zg + zk * gk, self.gg + gk * gk
            self.zzgg, self.zggg = self.zzgg + (zk * gk) ** 2, self.zggg + zk * gk ** 3
            self.gggg, self.n = self.gggg + gk ** 4, self.n + 1
            if self.n == STAMP_WINDOW:
                self.llr += self.value().window_llr()
                self.zg = self.gg = self.zzgg = self.zggg = self.gggg = 0.0
                self.n, self.p = 0, at_stamp(StampEvidence(llr=self.llr), self.prior)
                self.tables = self.off.mixed(self.p)
        self.scale = r
