# SPDX-License-Identifier: Apache-2.0
"""
When an offset's jump found at a hold happened in the motion before it.

The rest test finds a jump of the offset only where the sensor is still (:mod:`.rest`): a
run of samples still at another offset.  Out of a motion the jump may have happened
anywhere in it: the offset's model walks by picoamperes a second, so a jump of nanoamperes
while the tip moved was read as motion, a ramp of the tip of J / R_n(0) a second (H(0) =
0), and the level the hold starts from is off by J times the time since the jump
(:func:`~.rest_jump.jump_covariance`; drawn record 187: 9.25 nA, 148 um at a std of
10 um).  Where in the motion is told by the motion's own current: a jump of ``a`` amperes
before sample t of the motion leaves its signature rho_k(t) on the normalised
innovations after it, and twice the log-likelihood ratio of that jump against none is
2 a sum_k rho_k z_k - a^2 sum_k rho_k^2 (:func:`~.step_glr.jump_signatures`, Willsky and
Jones 1976), ``a`` the jump the run measured.  With every sample of the motion equally
likely a priori (and the run's first: a jump as the motion ended), the ratios give the
jump's time a posterior; its mean and variance say what the offset measured at the hold
moves the level by and how well the level is then known (:class:`~.rest_jump.JumpLag`).
A jump too small to leave a signature above the noise has a flat posterior: the level
moves by half the motion's ramp, its std says the rest.

So the estimator keeps the motion since the last rest (:class:`MotionLog`: the state where
it began and its samples, up to ``jump_search_s``; a longer motion is not searched, its
jump taken at its run as before), and a jump's run out of it is filtered again with the
lag (:func:`restart_after_motion`).
"""
from __future__ import annotations

import numpy as np

from .onset import restart
from .periodic import Stretch
from .rest_jump import JumpLag
from .step_glr import jump_signatures

__all__ = ['MotionLog', 'restart_after_motion']


class MotionLog:
    """The motion since the last rest: where it began (a :class:`~.periodic.Stretch`)."""

    __slots__ = ('span', 'limit')

    def __init__(self, limit: int, span: Stretch | None = None):
        self.limit, self.span = limit, span

    def begin(self, filt, state, y: list, steps: list) -> None:
        """Start where a motion began: ``state`` under ``filt``, its samples ``y``, ``steps``."""
        self.span = Stretch(filt, state.copy(), list(y), list(steps))

    def add(self, y: list, steps: list, still: bool) -> None:
        """Append samples; ``still``: the last was still (the motion ended: none kept)."""
        span = self.span
        if span is None:
            return
        if still or len(span.y) + len(y) > self.limit:
            self.span = None
            return
        span.y += y
        span.steps += steps

    def saved(self) -> tuple | None:
        """Return the motion as plain values (:meth:`~.periodic.Stretch.values`), or None."""
        return None if self.span is None else self.span.values()

    @classmethod
    def restored(cls, limit: int, saved, make_filter) -> 'MotionLog':
        """Return the log of :meth:`saved`; ``make_filter(*design)`` builds its filter."""
        return cls(limit, None if saved is None else Stretch.from_values(saved, make_filter))


def restart_after_motion(filt, state, held: int, log: MotionLog):
    """
    :func:`~.onset.restart`, a jump's run out of a motion taken with its lag in that motion.

    ``log``: the motion since the last rest (its samples through the run's); a motion
    that began here starts it anew.
    """
    ended = state.ended
    out = restart(filt, state, held)
    span, n_run = log.span, len(ended.y)
    if not ended.held_still:
        log.begin(filt, out[0], ended.y, ended.steps)
        return out
    log.span = None
    if span is None or ended.still or len(span.y) - n_run < 2:
        return out
    m = filt.model                  # the run without a lag measured the jump's size
    jump = float(out[2].x[m.ib] - out[1].x[m.ib]) * float(m.scale[m.ib])
    motion = Stretch(span.filter, span.state, span.y[:-n_run], span.steps[:-n_run])
    lag = _lag(motion, jump, filt)
    return out if lag is None else restart(filt, state, held, lag)


def _lag(motion: Stretch, jump_a: float, filt) -> JumpLag | None:
    """
    Return the lag of a jump of ``jump_a`` before the run that ends ``motion``, or None.

    Judged under ``filt``, the model now (the motion's start carried onto it): the data may
    have chosen another upper corner since the motion began (:mod:`.motion_band`), and
    under the one they chose the jump's signature is the clearer (drawn record 247: 92
    against 5.8 in a^2 sum rho^2).
    """
    fit, power = jump_signatures(motion, filt)
    ratio = np.append(2.0 * jump_a * fit - jump_a * jump_a * power, 0.0)     # as it ended
    if not np.all(np.isfinite(ratio)):
        return None
    weight = np.exp(0.5 * (ratio - ratio.max()))
    weight /= weight.sum()
    steps = np.append(np.asarray(motion.steps, dtype=float), 0.0)
    lag_s = np.cumsum(steps[::-1])[::-1] / motion.filter.model.sample_rate_hz
    mean = float(weight @ lag_s)
    return JumpLag(mean, max(float(weight @ (lag_s - mean) ** 2), 0.0), jump_a)
