# SPDX-License-Identifier: Apache-2.0
"""
When the Kalman estimator's model takes periodic-motion states, and from when.

At each line check the estimator measures the fundamental of a periodic motion on the
last 1, 2, ..., 8 s of current (:func:`~.motionline.measure_recent`; 0: none; None: a check
before 1 s of current is too short to judge, and its stretch runs on into the next).  The
model changes (periodic states at that fundamental appear, move by more than
:data:`~.statespace.MOTION_WOBBLE` of it, a motor's speed wobble that the periodic states'
walk follows, or go: :mod:`.statespace`) when the measurement differs from the model and
agrees with the one of the check before: two stretches in a row say so.  A check that
found none speaks only of the fundamentals it could see (at least
:data:`~.motionline.MOTION_PERIODS` periods in the current it judged): a 2 Hz crank is not
contradicted by a check on the first second.  Periodic
states also need a last stretch without rest (a motion starting or stopping is not
periodic).  The first stretch judged needs no earlier one when the sensor has not rested
since the start (moving since power-on).

The new model takes over from the start of its span: the last two stretches when both
measured that periodic motion and neither had a rest, or when the tip has not rested since
the start (it moved periodically from the start); else the last one (a motion that went is
dropped from the last stretch on).  The span's samples are filtered again under it from
the state there (:class:`StretchLog` keeps states and samples; :func:`~.carry.carry_state`
joins the new periodic states to what was known), so its state now is as if it had been
chosen then; what was published stays.  A periodic model is taken only if it explains the
current of its span, and kept only while it explains the stretch so far as each of its
blocks closes (:func:`~.innovations.explains`: its innovations below the motion's period;
:meth:`StretchLog.refuted`); a stretch it does not explain counts as one without periodic
motion, and ends there (the estimator filters it again: :mod:`.kalman`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import NamedTuple

import numpy as np

from .carry import carry_state
from .config import fractions_of
from .filter import FilterState, ForwardRecord, KalmanFilter
from .innovations import block_samples, explains
from .onset import due, restart
from .statespace import MOTION_WOBBLE
from .step_glr import offset_step_at

__all__ = ['Stretch', 'StretchLog', 'Refiltered', 'refilter', 'same_motion', 'design',
           'likeliest', 'REMAINDER_CHOICES', 'remainder_configs', 'offset_step_at', 'Change',
           'after_refutation', 'nll_of']


#: The periodic remainders a model is tried with, relative to ``periodic_remainder_rms_m``
#: (the largest): the likeliest on the span it takes over from is taken (:func:`likeliest`).
#: A clean crank leaves micrometres; its model's test, and the jumps found under it, are as
#: sensitive as its remainder is small (a 6 nA step under a 2.65 Hz crank was found 1.8 s
#: late with 20 um, on its sample with 1.25); a rig that shakes keeps the largest.  Steps of
#: four: the likelihood tells a remainder from one four times it in a few periods.
REMAINDER_CHOICES = (1.0, 0.25, 0.0625)


def remainder_configs(config) -> list:
    """Return ``config`` with each remainder tried, the largest first (within its range)."""
    return [config.replace(periodic_remainder_rms_m=value) for value in
            fractions_of(config, 'periodic_remainder_rms_m', REMAINDER_CHOICES)]


def design(model) -> tuple:
    """
    Return what tells a model from another of the same estimator.

    Its lines, periodic motion, remainder and upper corner (the last two chosen by the data:
    :func:`likeliest`, :mod:`.motion_band`).
    """
    return (model.fundamentals_hz, model.motion_fundamentals_hz,
            model.config.periodic_remainder_rms_m,
            model.config.motion_bandwidth_hz)


def likeliest(span: Stretch, filters) -> tuple:
    """
    Return (filter, its run) under which ``span`` is likeliest, of those that explain it.

    Each filters the span again from its start (:func:`refilter`); twice the negative
    log-likelihood of the span's innovations (``Innovations.nll``) decides.  None explains
    it: the first (its refusal is :func:`~.innovations.explains`'s to say).
    """
    best, lowest = None, math.inf
    for filt in filters:
        run = refilter(span, filt)
        if best is None:
            best = filt, run
        if not explains(run.now.innovations, run.start.innovations,
                        filt.model.config.false_alarm):
            continue
        if run.nll < lowest:
            best, lowest = (filt, run), run.nll
    return best


def nll_of(span: Stretch, filt: KalmanFilter, state: FilterState) -> float:
    """
    Return twice the negative log-likelihood of ``span``'s innovations under ``filt``.

    From the filter's own sums when the span ran wholly under ``filt`` (to ``state``, its
    state now), else from ``span`` filtered again under it.
    """
    if span.filter is filt:
        return state.innovations.nll - span.state.innovations.nll
    return refilter(span, filt).nll


def same_motion(a_hz: tuple, b_hz: tuple) -> bool:
    """Tell whether two measured sets of fundamentals (() none) are the same motions."""
    if len(a_hz) != len(b_hz):
        return False
    return all(abs(a - b) <= MOTION_WOBBLE * max(a, b)     # the walk follows less
               for a, b in zip(sorted(a_hz), sorted(b_hz)))


@dataclass
class Stretch:
    """The samples between two checks and the filter and state at the first."""

    filter: KalmanFilter
    state: FilterState
    y: list = field(default_factory=list)
    steps: list = field(default_factory=list)
    #: a sample in it was still (the rest test's verdict, as published live)
    rest: bool = False
    #: a sample in it was not still
    moved: bool = False
    #: the fundamentals measured at its end's check, Hz (() none; None: not judged)
    measured_hz: tuple | None = None
    #: the lowest fundamental the measurement could see, Hz
    floor_hz: float = 0.0
    #: a jump of the offset was taken at its end's check, filtering again from before its
    #: start: its start state is not the one its samples now follow, so no span starts there
    jumped: bool = False
    #: the periodic model failed its test in it, a jump was the more likely and too recent
    #: to judge (:func:`after_refutation`): the next failure decides
    deferred: bool = False

    def then(self, later: 'Stretch') -> 'Stretch':
        """Return the span from this stretch's start through the end of ``later``."""
        return Stretch(self.filter, self.state, self.y + later.y, self.steps + later.steps)

    def values(self) -> tuple:
        """Return (its model by :func:`design`, start state copied, samples, steps)."""
        return (*design(self.filter.model), self.state.copy(), list(self.y), list(self.steps))

    @classmethod
    def from_values(cls, values, make_filter, **more) -> 'Stretch':
        """Return the stretch of :meth:`values`; ``make_filter(*design)`` builds its filter."""
        lines, motion, remainder, band, state, y, steps = values
        filt = make_filter(tuple(lines), tuple(motion), float(remainder), float(band))
        if state.x.shape != (filt.model.size,):
            raise ValueError('a stretch state of another design')
        return cls(filt, state.copy(), list(y), list(steps), **more)

    def start_under(self, filt: KalmanFilter) -> FilterState:
        """Return the state at its start under ``filt`` (carried when it ran another)."""
        if self.filter is filt:
            return self.state
        return carry_state(self.filter, filt, self.state)


class StretchLog:
    """The last two stretches between checks (what a change of motion model refilters)."""

    def __init__(self, filt: KalmanFilter, state: FilterState):
        self.earlier: Stretch | None = None
        self.current = Stretch(filt, state.copy())

    def mark(self, filt: KalmanFilter, state: FilterState) -> None:
        """End the current stretch at a check (one not judged runs on); a new one starts."""
        if self.current.measured_hz is not None:
            self.earlier, self.current = self.current, Stretch(filt, state.copy())

    def add(self, y: list, steps: list, still: np.ndarray) -> None:
        """
        Append samples to the current one.

        ``y``, ``steps``: values and sample periods since the one before; ``still``: per
        sample, the rest test found it still.
        """
        cur = self.current
        cur.y += y
        cur.steps += steps
        cur.rest = cur.rest or bool(still.any())
        cur.moved = cur.moved or not still.all()

    def add_one(self, y: float, steps: int, still: bool) -> None:
        """Append one sample (the node's path: no lists built)."""
        cur = self.current
        cur.y.append(y)
        cur.steps.append(steps)
        cur.rest = cur.rest or still
        cur.moved = cur.moved or not still

    def saved(self) -> tuple:
        """Return the log as plain values (models by :func:`design`; states copied)."""
        return tuple(None if st is None else (
            *st.values(), st.rest, st.moved, st.measured_hz, st.floor_hz, st.jumped,
            st.deferred) for st in (self.earlier, self.current))

    @classmethod
    def restored(cls, saved, make_filter) -> 'StretchLog':
        """Return the log of :meth:`saved`; ``make_filter(*design)`` builds filters."""
        parts = []
        for item in saved:
            if item is None:
                parts.append(None)
                continue
            rest, moved, measured, floor, jumped, deferred = item[7:]
            parts.append(Stretch.from_values(
                item[:7], make_filter, rest=bool(rest), moved=bool(moved),
                measured_hz=None if measured is None else tuple(measured),
                floor_hz=float(floor), jumped=bool(jumped), deferred=bool(deferred)))
        log = cls.__new__(cls)
        log.earlier, log.current = parts
        if log.current is None:
            raise ValueError('no current stretch')
        return log

    def refuted(self, state: FilterState) -> Stretch | None:
        """
        Return the current stretch if its periodic model does not explain it (``explains``).

        ``state``: the filter's now.  The motion measured there then counts as none.
        """
        cur = self.current
        if (not cur.filter.model.motion_hz
                or explains(state.innovations, cur.state.innovations,
                            cur.filter.model.config.false_alarm)):
            return None
        cur.measured_hz = ()
        return cur

    def span_for(self, measured_hz: tuple | None, never_rested: bool,
                 floor_hz: float = 0.0) -> Stretch | None:
        """
        Record the current stretch's measurement; return the span a new model starts at.

        The model has those fundamentals ((): none, down to ``floor_hz``); None: it may not
        take over (module docstring).
        """
        cur, before = self.current, self.earlier
        cur.measured_hz, cur.floor_hz = measured_hz, floor_hz
        if measured_hz is None or (measured_hz and cur.rest):
            return None
        if (before is None or before.measured_hz is None         # the first stretch judged
                or before.measured_hz == () and measured_hz
                and min(measured_hz) < before.floor_hz):
            if not never_rested:
                return None
        elif not same_motion(measured_hz, before.measured_hz):
            return None
        if (before is not None and not before.jumped
                and (never_rested or measured_hz and not before.rest)):
            return before.then(cur)
        return cur


class Refiltered(NamedTuple):
    """What :func:`refilter` returns."""

    #: the new model's state at the start of the span (carried there)
    start: FilterState
    #: its state now, at the end of the span
    now: FilterState
    #: (the state, the state before it) each motion that ended a rest (or each offset that
    #: jumped) in the span was filtered again from (:func:`~.onset.restart`)
    restarts: list
    #: per sample of the span: the rest test found it still (as published live)
    still: np.ndarray

    @property
    def nll(self) -> float:
        """Twice the negative log-likelihood of the span's innovations (Σ z² + ln S)."""
        return self.now.innovations.nll - self.start.innovations.nll


def refilter(span: Stretch, filt: KalmanFilter, record: ForwardRecord | None = None,
             jump_at: int | None = None) -> Refiltered:
    """
    Filter the samples of ``span`` again under ``filt``, taking over at its start.

    The span's state is carried onto ``filt`` (:func:`~.carry.carry_state`), or taken as it
    is when the span ran under ``filt`` (a motion's start filtered again: :mod:`.onset`).
    The samples run through the live rules: a motion that ends a rest is filtered again from
    where it began (:func:`~.onset.restart`), so the state now is the one the live filter
    would have had under ``filt`` from the span's start.

    ``record``: filled with the forward pass over the span's last ``len(record)`` samples
    (what a fixed-lag smoother still holds of it).  ``jump_at``: the offset jumped before
    that sample of the span (:func:`offset_step_at`): there the offset's variance grows by a
    jump's (``KalmanFilter.with_jump``), a change the smoothers pass back through as at a
    jump found at rest (a restart).
    """
    start = span.start_under(filt)
    n = len(span.y)
    cut = n - (0 if record is None else record.x_post.shape[0])
    state, a, restarts, flags = start, 0, [], []
    while a < n:
        if a == jump_at:
            before, state = state, replace(state, P=filt.with_jump(state.P))
            restarts.append((state, before))
        b = cut if a < cut else n
        b = jump_at if jump_at is not None and a < jump_at < b else b
        state, w, _, still = filt.run(state, span.y[a:b], span.steps[a:b],
                                      record=None if a < cut else record, offset=a - cut,
                                      until_motion=True)
        flags.append(still)
        a += w.size
        if due(state):
            held = min(len(state.ended.y), max(a - cut, 0))
            begun, before, state, rows = restart(filt, state, held)
            restarts.append((begun, before))
            if rows is not None:
                _put(record, a - cut - held, rows)
    return Refiltered(start, state, restarts,
                      np.concatenate(flags) if flags else np.zeros(0, dtype=bool))


class Change(NamedTuple):
    """What takes over where a periodic model failed: a filter, from a span's start."""

    filter: KalmanFilter
    span: Stretch
    #: the offset jumped before this sample of the span (the filter is the periodic one)
    jump_at: int | None = None


def after_refutation(whole: Stretch, filt: KalmanFilter, drop: KalmanFilter,
                     jumps: bool, wait: bool = True) -> Change | None:
    """
    Return what takes over where the periodic model ``filt`` failed its test on ``whole``.

    ``whole``: the current since the model's last state that passed; ``drop``: the model
    without periodic states.  The offset jumped under the periodic motion, where a jump is
    most likely (:func:`offset_step_at`), when ``jumps``, the model so explains ``whole``
    (:func:`~.innovations.explains`) and the current is more likely so than if the
    periodic motion had ended instead: the samples after a change point filtered under
    ``drop`` from the periodic model's state there, the point tried at the jump's sample
    and every half period over the last two (the innovations' sums keep twice the negative
    log-likelihood, ``nll``).  A crank that stopped leaves a residual at the harmonics that
    the test cannot see, so a jump passes it; the likelihood tells.  Else the motion ended:
    ``drop`` takes over from the start of ``whole`` (not from the change point: the
    periodic model's state there has taken part of the change for offset and level).  None
    (only when ``wait``): the jump is the more likely but fewer than two periods follow it
    (a crank slowing to a stop fits a jump and the periodic model for a few samples better
    than a model that knows nothing of the motion does): judged again as the next block
    closes.
    """
    at = offset_step_at(whole, filt) if jumps else None
    if at is None:
        return Change(drop, whole)
    jumped = refilter(whole, filt, jump_at=at)
    if not explains(jumped.now.innovations, jumped.start.innovations,
                    filt.model.config.false_alarm):
        return Change(drop, whole)
    n = len(whole.y)
    period = block_samples(filt.model.motion_fundamentals_hz, filt.model.sample_rate_hz)
    ended, state, done = math.inf, whole.start_under(filt), 0
    for p in sorted({q for q in (at, *(n - j * (period // 2) for j in range(1, 5))) if q > 0}):
        state = refilter(Stretch(filt, state, whole.y[done:p], whole.steps[done:p]), filt).now
        done = p
        tail = Stretch(filt, state, whole.y[p:], whole.steps[p:])
        ended = min(ended, refilter(tail, drop).now.innovations.nll)
    if jumped.now.innovations.nll >= ended:
        return Change(drop, whole)
    return None if wait and at > n - 2 * period else Change(filt, whole, at)


def _put(record: ForwardRecord, at: int, rows: ForwardRecord) -> None:
    """Write ``rows`` into ``record`` from its row ``at`` on."""
    n = rows.x_post.shape[0]
    for f in fields(ForwardRecord):
        getattr(record, f.name)[at:at + n] = getattr(rows, f.name)
