# SPDX-License-Identifier: Apache-2.0
"""
Where a motion that ends a rest began: the change point of the rest test's CUSUM.

At rest the filter measures the tip's velocity to be zero (:mod:`.rest`).  A motion that
starts gently (a crank spinning up, a minimum-jerk move) keeps its current within the noise
for some samples before the rest test can tell it; over those samples the pseudo-measurements
hold the deflection and take the motion's current for offset (tens of um on a crank from rest
with 1-2 % noise).  The test's two-sided CUSUM (:meth:`~.rest.RestTest.sample_ok`) says in
hindsight where the shift began: after the last sample at which the side that grew was at
zero (Page 1954: the CUSUM's estimate of a change point).  So at rest the filter keeps, for
each side, its state after that side's last zero and the samples since (:class:`Onset`); when
a sample ends the rest (a window test at its threshold says nothing of when), the older of
the two and the samples since are the motion's start
(``FilterState.ended``), and the estimator filters those samples again from that state as
motion (:func:`restart`: the rest test's verdict is overridden for them,
``FilterState.hold_off``).  The model then says the rest ended where the motion began, not
where the test could first tell it.  What was published stays; the smoothers follow the same
model (a part that starts there, with the state there: :meth:`~.kalman.KalmanEstimator`).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import NamedTuple

__all__ = ['Onset', 'Start', 'follow', 'follow_jump', 'track_onset', 'restart', 'due']


class Start(NamedTuple):
    """Where to filter samples again from: the state before the first, the samples since."""

    #: the filter's (x, P, moved, samples, innovations) before the first sample (never changed)
    state: tuple
    y: list
    steps: list
    #: the rest flag there
    still: bool = True
    #: the samples are taken as still (an offset that jumped: :mod:`.rest`), not as motion
    held_still: bool = False

    def copy(self) -> 'Start':
        return self._replace(y=list(self.y), steps=list(self.steps))


@dataclass(slots=True)
class Onset:
    """
    At rest: per CUSUM side, (state after its last zero, samples since, their steps).

    The state is the filter's (x, P, moved, samples, innovations), never changed (shared by
    copies); the lists grow.  None for a side that has not been at zero in this rest.
    """

    up: tuple | None = None
    down: tuple | None = None

    def copy(self) -> 'Onset':
        return Onset(*(None if s is None else (s[0], list(s[1]), list(s[2]))
                       for s in (self.up, self.down)))

    def start(self, y: float, step: int) -> Start | None:
        """Return the older side's :class:`Start`: the rest ended at sample ``y``."""
        sides = [s for s in (self.up, self.down) if s is not None]
        if not sides:
            return None
        state, ys, steps = max(sides, key=lambda s: len(s[1]))
        return Start(state, ys + [y], steps + [step])


def follow(onset: Onset | None, track: tuple | None, y: float, step: int, snapshot) -> Onset:
    """
    Return the onset after a rest sample ``y`` (``step`` periods after the one before).

    ``track``: the rest test's (CUSUM up, CUSUM down, ...) after it; ``snapshot()`` returns
    the filter's state after it (called only when a side is at zero).
    """
    old = (None, None) if onset is None else (onset.up, onset.down)
    levels = (1.0, 1.0) if track is None else track[:2]
    state = None
    sides = []
    for level, side in zip(levels, old):
        if level == 0.0:
            state = snapshot() if state is None else state
            sides.append((state, [], []))
        elif side is not None:
            side[1].append(y)
            side[2].append(step)
            sides.append(side)
        else:
            sides.append(None)
    return Onset(*sides)


def track_onset(accepted: Start | None, still: bool, was: bool, onset: Onset | None,
                ended: Start | None, win, y: float, t: float, snapshot) -> tuple:
    """
    Return (onset, ended) after a filter's sample.

    The offset jumped (``accepted``): the run again, still, from its start; at rest: where a
    motion that ends it would have begun (:func:`follow`); a rest that ended: whether a
    sample told it (:meth:`Onset.start`).  ``win``: the filter's rest window.
    """
    if accepted is not None:
        return None, accepted
    if still:
        return follow(onset, win.track, y, t, snapshot), ended
    if was and onset is not None:
        return None, onset.start(y, t) if win.quiet == 0 else None
    return onset, ended


def follow_jump(run: Start | None, quiet: int, verdict, y: float, step: int,
                snapshot, still: bool) -> Start | None:
    """
    Return the run of an offset's jump after sample ``y`` (:mod:`.rest`), or None.

    ``quiet``: the samples of the run so far (``RestWindow.jump_quiet``; 1: it starts at
    ``y``, from the filter's state ``snapshot()`` before it); ``verdict``: the rest test's
    against the filter's offset (a still window needs no jump); ``still``: the filter's rest
    flag before ``y`` (its :class:`Start` keeps it: a run out of a motion, or out of a hold
    the rest test has not confirmed, begins a rest, which releases the working point).
    """
    if verdict or not quiet:
        return None
    if quiet == 1:
        run = Start(snapshot(), [], [], still, True)
    elif run is None:               # a run begun under another model (carried): not this one's
        return None
    run.y.append(y)
    run.steps.append(step)
    return run


def due(state) -> bool:
    """Tell whether a sample that ended the rest left a motion's start to filter again."""
    return state.ended is not None and len(state.ended.y) >= 2


def restart(filt, state, held: int, lag=None):
    """
    Filter the motion's first samples again from where it began.

    ``state.ended`` (:class:`Start`): the state there, the samples since, their steps.  The
    run starts from the filter's state there with the rest test's window and noise meter as
    they are now (past those samples), and takes the samples as motion (``hold_off``), or as
    still after an offset that jumped (``held_still``; ``lag``: when it jumped in a motion
    before its run, :mod:`.jump_time`).
    Returns (the state the run started from, the filter's state there before it (without
    the jump's variance: what the smoothers pass back to), the state now, the forward record
    of the last ``held`` samples or None).
    """
    from .filter import ForwardRecord
    from .periodic import Stretch, refilter

    (x, P, moved, samples, innovations), ys, steps, still, held_still = state.ended
    start = replace(state, x=x, P=filt.with_jump(P, lag) if held_still else P, still=still,
                    moved=moved, samples=samples, onset=None, ended=None, hold_off=len(ys),
                    hold_still=held_still, innovations=innovations)
    before = replace(start, P=P) if held_still else start
    record = ForwardRecord.empty(held, filt.model.size) if held else None
    now = refilter(Stretch(filt, start, ys, steps), filt, record).now
    return start, before, now, record
