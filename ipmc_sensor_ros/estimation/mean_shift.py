# SPDX-License-Identifier: Apache-2.0
"""
A shift of a white sequence's mean, of any size: likelihood ratios over dyadic memories.

The rest test (:mod:`.rest`) tells a still sensor's innovations z_k, N(0, 1) while nothing
changes, from a sensor whose offset stepped.  Its CUSUM is designed for a shift of one sigma
(:data:`~.innovations.CUSUM_CHANGE_SIGMAS`): with a drift of half that, a shift of a
quarter sigma never accumulates (drawn record 291: a 14.6 nA offset step at rest under
59 nA of noise per sample), while the window's mean, over 0.2 s, showed it at 4.4 sigma,
inside its limit of 4.9; the filter's offset followed through its walk at a tenth in half a
second, and the rest's zero-velocity measurement took the rest into the deflection (43 um
over ten seconds, 4.6 %).

The likelihood ratio of a shift delta that began A samples ago against none, delta
maximised, is (sum of the last A z)^2 / A, delta^2 A on average: any shift is told once it
is old enough.  Over every onset that is a sum per sample; at dyadic ages exponentially
weighted sums stand in (the EWMA chart's statistic, Roberts 1959)::

    S_j <- lambda_j S_j + z,   W_j <- lambda_j^2 W_j + 1,   T_j = S_j^2 / W_j,
    lambda_j = 1 - 2^-j

S_j is N(0, W_j) under no shift, so T_j is chi2_1 at every sample, and a shift older than
2^j samples gives T_j ~ delta^2 (1 + lambda_j) / (1 - lambda_j) ~ delta^2 2^(j+1).  The
memories used at a sample are those up to the time the still sensor's filter takes to follow
a step on its own, (R + P_b) / P_b samples (its offset gain's inverse): a step older than
that is in the offset already, and a longer sum would only weigh what the model leaves out
(a drift its walk lags).  The test alarms when one of the K used passes chi2_1 at
``false_alarm`` / K (Bonferroni: on white noise, restarted after each alarm, the statistic
alarms at 4-6 % of ``false_alarm`` per sample, measured; the memories' sums are strongly
correlated).  The memories are 2^1 .. 2^52 samples (52: the bits of a float's mantissa, the
longest forgetting factor it holds); a shift shorter than two samples is the per-sample
test's and the CUSUM's.
"""
from __future__ import annotations

import bisect
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

__all__ = ['ShiftTest']


@dataclass(frozen=True)
class ShiftTest:
    """The memories, their forgetting factors, and the limit by how many are used."""

    #: the memories, samples: 2^1 .. 2^52
    memories: tuple
    #: lambda_j and lambda_j^2
    forget: tuple
    forget_sq: tuple
    #: the alarm limit when the first k + 1 memories are used
    limits: tuple

    @classmethod
    def design(cls, false_alarm: float) -> 'ShiftTest':
        """Memories 2^1 .. 2^52 samples; limits chi2_1 at false_alarm / K, K = 1 .. 52."""
        bits = np.finfo(float).nmant
        memories = 2.0 ** np.arange(1, bits + 1)
        forget = 1.0 - 1.0 / memories
        used = np.arange(1, bits + 1)
        return cls(tuple(memories.tolist()), tuple(forget.tolist()),
                   tuple((forget * forget).tolist()),
                   tuple(chi2.isf(false_alarm / used, 1).tolist()))

    def step(self, sums: tuple | None, z: float, follow_samples: float) -> tuple[tuple, bool]:
        """
        Return the sums after innovation ``z`` (None: the first) and whether a shift is told.

        ``follow_samples``: (R + P_b) / P_b, the longest memory that is tested (module
        docstring; inf: all).  Only the memories tested are kept: one that comes into use
        starts from the longest kept (its S is N(0, W) under no shift, as its own would be).
        """
        used = max(1, bisect.bisect_right(self.memories, follow_samples))
        limit = self.limits[used - 1]
        if sums is None:
            return ([z] * used, [1.0] * used), z * z > limit
        old_s, old_w = sums
        if len(old_s) < used:
            old_s = old_s + [old_s[-1]] * (used - len(old_s))
            old_w = old_w + [old_w[-1]] * (used - len(old_w))
        s = [f * a + z for f, a in zip(self.forget[:used], old_s)]
        w = [f * b + 1.0 for f, b in zip(self.forget_sq[:used], old_w)]
        return (s, w), any(a * a > limit * b for a, b in zip(s, w))
