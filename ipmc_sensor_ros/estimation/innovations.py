# SPDX-License-Identifier: Apache-2.0
"""
Whether a model explains the current: the test of its innovations below the motion's period.

Under the model each innovation over its predicted standard deviation, z_k = nu_k / sqrt(S_k),
is N(0, 1) and independent of the others (the innovations of a Kalman filter on the right
model are white).  So the sum of z over a block of n samples, over sqrt(n), is N(0, 1) too,
and the squares of such sums over B disjoint blocks add to a chi-square with B degrees of
freedom.  The filter keeps these sums (:class:`Innovations`) for blocks one period of the
model's periodic motion long (:func:`block_samples`): a model's residual at the motion's
harmonics (a motor's speed wobble the periodic states' walk follows late, an amplitude
learned within its noise) adds to nearly nothing over a whole period, while a current the
model does not produce below the motion's fundamental (a slow move under a crank, which
the periodogram cannot see in a few periods and which the model would take for offset: the
level would follow it) adds up block after block.  The test is what matters for the
estimate: a periodic model that misreads the low frequencies misreads the level (H(0) = 0).
A block also closes early, as soon as its innovations have grown past the model's: Page's
CUSUM of the log-likelihood ratio of N(0, CUSUM_RATIO) against N(0, 1) per sample,
0.5 (z^2 (1 - 1/rho) - ln rho), reset at each block, passing :func:`cusum_limit`.  A crank that
stops, the end of a slow motion a periodic model took, or a jump of the offset under it is
then judged within tens of milliseconds instead of at the period's end (the estimate
published meanwhile stays: on `slim-crank-stop` seed 1 the stop read 3.2 % with a
1.25 um remainder when the test waited, 1.3 % now).  The partial block is one more
chi-square term like any other (under the model its sum over its root size is N(0, 1)).
The sums also keep twice the negative log-likelihood of the current under the model
(sum of z^2 + ln S): what tells a jump of the offset under a periodic motion from the end
of that motion when the test fails (:func:`~.periodic.after_refutation`).

A 20 Hz crank with a 1 % speed wobble at 1-2 % noise: the squared innovations sum to
1.3-1.6 per sample (a plain chi-square of the squares refuses the right model), the block
test reads 3-12 over 20 blocks against a limit of 65.  Two sines a slow move joins
(slim-motion-hold-0.2na, seed 5, a 1.05 Hz model: blocks of 949 samples): 16 over the one
block closed a second after the move began, against 24; 1,577 over the next.
"""
from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np
from scipy.stats import chi2 as chi2_dist

from .instants import StampEvidence

__all__ = ['Innovations', 'Tally', 'block_samples', 'explains', 'cusum_limit',
           'CUSUM_CHANGE_SIGMAS', 'CUSUM_RATIO', 'CUSUM_STEP']

#: The smallest change the CUSUMs must see quickly, in predicted standard deviations: one.
#: The model's (below) looks for innovations whose standard deviation grew by it, a variance
#: (1 + 1)^2 = 4 times the model's: what a crank that stops gives within ~0.1 s (z^2 3-7,
#: then 100), while a model right but for a speed wobble reads 1.3-1.6 (the CUSUM drifts
#: down).  The rest test's (:mod:`.rest`) looks for a mean shifted by it: a motion whose
#: current is one noise sigma (smaller ones are left to the window's level test).
CUSUM_CHANGE_SIGMAS = 1.0
#: The variance, over the model's, of the innovations that close a block early (Page's
#: CUSUM of log-likelihood ratios).
CUSUM_RATIO = (1.0 + CUSUM_CHANGE_SIGMAS) ** 2
#: Its step per sample is CUSUM_STEP[0] z^2 - CUSUM_STEP[1].
CUSUM_STEP = (0.5 * (1.0 - 1.0 / CUSUM_RATIO), 0.5 * math.log(CUSUM_RATIO))


class Innovations(NamedTuple):
    """The test's sums, kept by the filter (not over its first ``noise_average_s``; nll is)."""

    #: sum over the closed blocks of (sum of z)^2 / samples in the block
    chi2: float = 0.0
    #: closed blocks (the chi-square's degrees of freedom)
    blocks: int = 0
    #: the open block's sum of z and its samples
    open_sum: float = 0.0
    open_n: int = 0
    #: sum over the samples of z^2 + ln S, S the innovation's variance (A^2): twice the
    #: negative log-likelihood of the current under the model, less a constant per sample;
    #: from the first sample (R not measured yet is the same for every model compared)
    nll: float = 0.0
    #: the evidence of the samples taken off their slots on when they were taken
    stamps: StampEvidence = StampEvidence()
    #: Page's CUSUM of the open block's innovations against a variance CUSUM_RATIO times
    #: the model's: past :func:`cusum_limit` the block closes early (the model is tested)
    cusum: float = 0.0

    def closed(self) -> 'Innovations':
        """Return the sums without the open block (a block belongs to one model)."""
        return self._replace(open_sum=0.0, open_n=0, cusum=0.0)


class Tally:
    """
    The sums of :class:`Innovations` while the filter runs (mutable; :meth:`value` is theirs).

    ``block``: samples per block (:func:`block_samples`; 1: no periodic model, no CUSUM);
    ``limit``: the CUSUM's (:func:`cusum_limit`).
    """

    __slots__ = ('chi2', 'blocks', 'open_sum', 'open_n', 'nll', 'cusum', 'block', 'limit')

    def __init__(self, sums: Innovations, block: int, limit: float):
        self.chi2, self.blocks, self.open_sum, self.open_n, self.nll = sums[:5]
        self.cusum, self.block, self.limit = sums.cusum, block, limit

    def value(self, stamps: StampEvidence) -> Innovations:
        """Return the sums as they stand, with the stamps' evidence ``stamps``."""
        return Innovations(self.chi2, self.blocks, self.open_sum, self.open_n, self.nll,
                           stamps, self.cusum)

    def add(self, z: float, r: float, tested: bool) -> bool:
        """
        Add a normalised innovation ``z`` (``r`` = sqrt(S)); return whether the CUSUM alarmed.

        The likelihood counts every sample; the test only those ``tested`` (R measured).
        """
        self.nll += z * z + 2.0 * math.log(r)
        if not tested:
            return False
        self.open_sum, self.open_n = self.open_sum + z, self.open_n + 1
        if self.block > 1:
            self.cusum = max(0.0, self.cusum + CUSUM_STEP[0] * z * z - CUSUM_STEP[1])
        alarm = self.cusum > self.limit and self.open_n < self.block
        if self.open_n == self.block or alarm:
            self.chi2 += self.open_sum * self.open_sum / self.open_n
            self.blocks, self.open_sum, self.open_n, self.cusum = self.blocks + 1, 0.0, 0, 0.0
        return alarm


def block_samples(motion_hz, sample_rate_hz: float) -> int:
    """
    Return the samples in one block: a period of the periodic motion; 1 without one.

    ``motion_hz``: its fundamental(s), Hz (several: the slowest one's period).
    """
    slowest = min((f for f in np.atleast_1d(motion_hz) if f), default=0.0)
    return max(1, round(sample_rate_hz / slowest)) if slowest else 1


def explains(now: Innovations, then: Innovations, false_alarm: float) -> bool:
    """
    Tell whether the model explains the current between two of its states' sums.

    The closed blocks' chi-square against its 1 - ``false_alarm`` quantile (the setting
    ``false_alarm``: a model that explains the current is refused or dropped by chance once
    in 10^6 stretches at 1e-6, 11 days of checks); no closed block says nothing against it.
    """
    dof = now.blocks - then.blocks
    return dof <= 0 or now.chi2 - then.chi2 <= _limit(dof, false_alarm)


@functools.lru_cache(maxsize=256)
def _limit(dof: int, false_alarm: float) -> float:
    """Return the test's limit for ``dof`` blocks (asked as each block closes: kept)."""
    return float(chi2_dist.isf(false_alarm, dof))


def cusum_limit(false_alarm: float) -> float:
    """
    Return the CUSUM's limit, ln(1 / ``false_alarm``).

    A false alarm once in ~1 / ``false_alarm`` samples of a model that explains the current
    (Wald's bound on the run length).
    """
    return math.log(1.0 / false_alarm)
