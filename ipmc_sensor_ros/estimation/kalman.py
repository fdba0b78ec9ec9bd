# SPDX-License-Identifier: Apache-2.0
"""
The Kalman deflection estimator: model, filter, smoother and the lines measured.

The parts: :mod:`.statespace` (model), :mod:`.filter`, :mod:`.smoother`, :mod:`.lines`.
:class:`KalmanEstimator` implements :class:`~.core.EstimatorCore`.  It owns one
:class:`~.filter.FilterState` and advances it sample by sample; a block and single samples
run the same recursion.  The mains line (``mains_hz``: ``'auto'``, 50, 60 or 0 = none) is
measured every ``CHECK_S`` of data on the last ``LINE_WINDOW_S`` of current, at fixed
sample counts (so the result does not depend on how the stream is cut into blocks); the
measurements are joined (:class:`~.lines.Line`); when a line appears, or its joined
frequency moves further than the line states' walk follows, line states at that frequency
take over from the start of the stretch since the last check if it is likelier under them
(:func:`~.periodic.refilter`; a measurement is a candidate, and the likelihood judges).

A periodic motion is measured at the same checks, on the last 1, 2, ..., 8 s of current
(:func:`~.motionline.measure_recent`); when two checks in a row say it appeared, went or
moved, the model with periodic states at the measured fundamental (a small remainder:
:mod:`.statespace`) takes over from the start of those stretches, whose samples are
filtered again (:mod:`.periodic`); it must explain the current of its span, and then, as each
of its blocks (one period) closes, of the stretch so far (its innovations' chi-square).  When
it fails, the current since the last state that passed is filtered again without it, and
with a jump of the offset under it; the more likely takes over (a crank that stops goes
within a period).  Without one, the broad prior's upper corner is chosen by the same
likelihood at each check (:mod:`.motion_band`).  A motion that ends a rest is filtered
again from where the rest test's CUSUM says it began (:mod:`.onset`); a jump of the offset
found at the hold after it is taken with its likely time in the motion (:mod:`.jump_time`).

``smoothed_lag_s`` > 0 also smooths the live output with that lag (:class:`~.fixed_lag.
FixedLagSmoother`): :meth:`KalmanEstimator.pop_smoothed` returns what is ready, oldest first.
"""
from __future__ import annotations

import math

import numpy as np

from ..lti.reduction import ReducedModel
from .carry import Changes
from .config import EstimatorConfig, parse_mains
from .core import Estimate, forgets_s
from .filter import FilterState, ForwardRecord, KalmanFilter
from .fixed_lag import lag_smoother
from .lines import NOMINAL_LINES_HZ, SEARCH_HZ, Line, measure_line
from .motion_band import likelier_band
from .motionline import MOTION_LONGEST_S, MOTION_PERIODS, MOTION_SHORTEST_S, measure_recent
from .innovations import explains
from .onset import due
from .jump_time import MotionLog, restart_after_motion
from .kalman_state import KalmanState
from .periodic import (StretchLog, after_refutation, likeliest, nll_of, refilter,
                       remainder_configs, same_motion)
from .ring import SampleRing, hold_next, on_grid
from .smoother import smooth_segments
from .phasors import line_frequencies_hz
from .statespace import StateSpaceModel
from .timebase import slots_of

__all__ = ['KalmanEstimator', 'CHECK_S', 'LINE_WINDOW_S']

#: Data between two checks of the mains line and the periodic motion, s (a stretch,
#: :mod:`.periodic`): the shortest stretch a periodic motion is judged on, so a motion is
#: judged as soon as a stretch of it can be; the delay of a periodic model, modelled at the
#: second check that measures it; a check costs 10-20 ms on 8 s of 1 kHz current, 10-20 us
#: a sample.  The first check comes half of this early (the line to ~0.05 Hz).
CHECK_S = MOTION_SHORTEST_S
LINE_FIRST_S = 0.5 * CHECK_S
#: The mains line is measured on the last this of current, s: the window that resolves the
#: search half-width (``1 / SEARCH_HZ``, 2 s) and, zero-padded, finds the line to ~0.01 Hz
#: at 3 % hum.
LINE_WINDOW_S = 1.0 / SEARCH_HZ


class KalmanEstimator(KalmanState):
    """
    Streaming Kalman estimate of tip deflection (m) from sensing current (A).

    Parameters
    ----------
    reduced : ReducedModel
        The sensor's reduced model.
    sample_rate_hz : float
        Sample rate of the current, Hz.
    config : EstimatorConfig, optional
        Priors and rest test (defaults documented there).
    mains_hz : 'auto', 0, 50 or 60
        Mains line handling (module docstring).
    smoothed_lag_s : float, optional
        Lag of the fixed-lag smoothed output, s (0: none; module docstring).

    """

    name = 'kalman'

    def __init__(self, reduced: ReducedModel, sample_rate_hz: float,
                 config: EstimatorConfig | None = None, mains_hz='auto',
                 smoothed_lag_s: float = 0.0):
        self.reduced = reduced
        self.config = config or EstimatorConfig()
        self.mains_hz = parse_mains(mains_hz)
        fs = float(sample_rate_hz)
        self.smoothed_lag_s = float(smoothed_lag_s)
        self._lag = lag_smoother(self.smoothed_lag_s, fs)
        self._changes = Changes()       # the segments only for :meth:`smooth`
        # until measured: a line at each nominal frequency (hum at the start must not be
        # taken for an offset), then the measured one
        nominal_line = () if self.mains_hz == 0.0 else self._nominal()
        self._check_n = max(64, int(round(CHECK_S * fs)))
        self._line_n = max(64, int(round(LINE_WINDOW_S * fs)))
        self._window_n = max(self._line_n, int(round(MOTION_LONGEST_S * fs)))   # both windows
        self._first_n = max(64, int(round(LINE_FIRST_S * fs)))
        self._filter = self._new_filter(StateSpaceModel(reduced, self.config, fs, nominal_line))
        self._state: FilterState | None = None
        self.offset_jumps = 0           # jumps of the offset taken (:mod:`.rest`)
        self.reset()

    def _new_filter(self, model: StateSpaceModel) -> KalmanFilter:
        """Build the filter; its rest test fits the nominal lines until one is modelled."""
        return KalmanFilter(model, tuple(f for f0 in self._nominal() if f0 for f in (
            line_frequencies_hz(f0, model.sample_rate_hz, self.config.line_harmonics))))

    def _nominal(self) -> tuple:
        return NOMINAL_LINES_HZ if self.mains_hz == 'auto' else (self.mains_hz,)

    def _next_check(self, samples: int) -> int:
        """Return the sample count of the next line measurement after ``samples``."""
        first, second = self._first_n, 2 * self._first_n
        if samples < second:
            return first if samples < first else second
        return second + ((samples - second) // self._check_n + 1) * self._check_n

    # -- properties ---------------------------------------------------------------------
    @property
    def sample_rate_hz(self) -> float:
        return self._filter.model.sample_rate_hz

    @property
    def model(self) -> StateSpaceModel:
        return self._filter.model

    @property
    def mean_corner_hz(self) -> float:
        """Corner of a nonlinear sensor's mean restored while moving, Hz (the setting)."""
        return self.config.nonlinear_mean_corner_hz

    def reset(self) -> None:
        """Start afresh: the nominal lines (the measured ones are measured again) and the prior."""
        if self._state is not None and self._lag is not None:
            self._lag.flush()
        nominal = () if self.mains_hz == 0.0 else self._nominal()
        if (self.model.fundamentals_hz, self.model.motion_hz, self.model.config) != (
                tuple(nominal), 0.0, self.config):
            self._filter = self._new_filter(StateSpaceModel(self.reduced, self.config,
                                                            self.sample_rate_hz, nominal))
        self._state = self._filter.initial_state()
        self._log = StretchLog(self._filter, self._state)
        self._moving = MotionLog(int(self.config.jump_search_s * self.sample_rate_hz))
        self._recent = SampleRing(self._window_n)    # on the sample grid: bridged slots too
        self._first_rest_n = None
        self._line = Line()             # the mains line measured so far (joined)

    # -- streaming ------------------------------------------------------------------------
    def estimate(self, current_a, steps=None) -> Estimate:
        y = np.asarray(current_a, dtype=float)
        st = np.ones(y.size) if steps is None else np.asarray(steps, dtype=float)
        parts, a = [], 0
        while a < y.size:
            # cut where the line check falls due (a fixed sample count, however cut)
            due = self._next_check(self._state.samples)
            b = min(y.size, a + due - self._state.samples)
            closes = self._filter.to_block_end(self._state)     # a periodic model's period
            b = min(b, a + closes) if closes else b
            blocks = self._state.innovations.blocks
            rec = None if self._lag is None else ForwardRecord.empty(b - a, self.model.size)
            self._state, w, s, still = self._filter.run(self._state, y[a:b], st[a:b],
                                                        record=rec, copy=False,
                                                        until_motion=True)
            b = a + w.size              # a rest ended there: its motion is filtered again
            if rec is not None:
                self._lag.push(self._filter, rec.rows(0, w.size))
            self._remember(y[a:b], st[a:b], still)
            ys, ss = y[a:b].tolist(), st[a:b].tolist()
            self._log.add(ys, ss, still)
            self._moving.add(ys, ss, bool(still[-1]))       # both extend: ys not kept
            parts.append((w, s, still))
            a = b
            self._after_run(blocks)
            if self._state.samples == due:
                self._check_line()
        if not parts:
            return Estimate(np.zeros(0), np.zeros(0), np.zeros(0, dtype=bool))
        return Estimate(*(np.concatenate(p) for p in zip(*parts)))

    def estimate_one(self, current_a: float, steps: float = 1) -> tuple[float, float]:
        """One sample through the same recursion (:meth:`estimate` without its arrays)."""
        n = self._state.samples
        if n + 1 == self._next_check(n) or self._lag is not None:
            est = self.estimate(np.array([current_a], dtype=float),
                                None if steps == 1 else np.array([steps]))
            return float(est.deflection_m[0]), float(est.std_m[0])
        blocks = self._state.innovations.blocks
        self._state, w, s, still = self._filter.run(self._state, [float(current_a)],
                                                    [float(steps)], copy=False,
                                                    until_motion=True)
        self._log.add_one(float(current_a), float(steps), bool(still[0]))
        self._moving.add([float(current_a)], [float(steps)], bool(still[0]))
        for k in range(slots_of(float(steps)), 0, -1):     # a bridged slot: no value
            self._recent.push(current_a if k == 1 else math.nan)
        if self._first_rest_n is None and still[0]:
            self._first_rest_n = n
        self._after_run(blocks)
        return float(w[0]), float(s[0])

    def _after_run(self, blocks: int) -> None:
        """Filter a motion's start again; test a periodic model if a block closed."""
        closed = self._state.innovations.blocks != blocks
        self._restart_motion()
        if closed:
            self._block_closed()

    def _restart_motion(self) -> None:
        """Filter a motion that ended a rest again from where it began (:mod:`.onset`)."""
        if not due(self._state):
            return
        held = 0 if self._lag is None else min(len(self._state.ended.y), self._lag.held)
        start, before, self._state, rec = restart_after_motion(self._filter, self._state, held,
                                                               self._moving)
        self.offset_jumps += bool(start.hold_still)
        link = self._begin_segment(self._filter, start, self._filter, before)
        if rec is not None:
            self._lag.replace_newest(self._filter, rec, link if held == start.hold_off else None)

    def _remember(self, y: np.ndarray, steps: np.ndarray, still: np.ndarray) -> None:
        """
        Keep the last motion window of current on the sample grid; note the first rest.

        A bridged slot is NaN: the line check holds the next sample's value there (the hum's
        phase where it was), the motion's measurement leaves it out (:mod:`.motionline`).
        """
        if self._first_rest_n is None and still.any():
            self._first_rest_n = self._state.samples - y.size + int(np.argmax(still))
        self._recent.extend(on_grid(y, slots_of(steps)))

    def _check_line(self) -> None:
        recent = self._recent.values()
        self._check_mains(hold_next(recent[-self._line_n:]))
        self._check_motion(recent)
        band = likelier_band(self._log.current, self._filter, self._state, self.config,
                             self.reduced, self._new_filter)
        if band is not None:            # the broad prior's upper corner (.motion_band)
            self._take_over(band[0], self._log.current, run=band[1])
        self._log.mark(self._filter, self._state)

    def _check_mains(self, recent: np.ndarray) -> None:
        if self.mains_hz == 0.0:
            return
        seen = measure_line(recent, self.sample_rate_hz, self._nominal(),
                            self.config.line_harmonics)
        shared = max(0.0, 1.0 - self._check_n / recent.size) if self._line.hz else 0.0
        self._line = self._line.joined(seen, shared, self.config.false_alarm)
        f_line, old = seen.hz and self._line.hz, self.model.fundamentals_hz
        if f_line and len(old) == 1 and self._line.follows(old[0], self.config):
            return
        if not f_line and (len(old) < 2 or self._state.samples > self._first_n):
            return        # no line: keep what is modelled (the nominal pair only at the start)
        span, m = self._log.current, self.model                          # its remainder too
        filt = self._new_filter(StateSpaceModel(self.reduced, m.config, m.sample_rate_hz,
                                                f_line or (), m.motion_fundamentals_hz))
        run, ours = refilter(span, filt), nll_of(span, self._filter, self._state)
        if run.nll < ours:              # a measurement is a candidate (module docstring)
            self._take_over(filt, span, run=run)

    def _begin_segment(self, filt, state, old, old_state) -> tuple | None:
        """Return the smoothers' link of a change (:meth:`~.carry.Changes.begin`), if one runs."""
        if self._changes.segments is None and self._lag is None:
            return None
        return self._changes.begin(filt, state, old, old_state)

    def _block_closed(self) -> None:
        """
        Test the periodic model as each of its blocks closes: it goes once it fails.

        When the closed blocks of the stretch (since the last check) fail the model's test
        (:meth:`~.periodic.StretchLog.refuted`), the current since the last state the test
        passed (the stretch before too, when it ran the same model: its last block was
        still open at its check; a jump taken at its end, on the few samples of a change
        then, is judged again) is explained by a jump of the offset or by the end of the
        periodic motion, whichever is more likely (:func:`~.periodic.after_refutation`), and
        the stretch ends (with a jump, or measured without periodic motion); a jump too
        recent to judge is judged as the next block closes, the stretch running on past a
        check meanwhile.  A crank that stops is dropped within a period of it.
        """
        span = self._log.refuted(self._state)
        if span is None:
            return
        m, before, whole = self.model, self._log.earlier, span
        if before is not None and same_motion(before.filter.model.motion_fundamentals_hz,
                                              m.motion_fundamentals_hz):
            whole = before.then(span)       # a jump taken at its end is judged again
        drop = self._new_filter(StateSpaceModel(self.reduced, self.config, self.sample_rate_hz,
                                                m.fundamentals_hz))
        change = after_refutation(whole, self._filter, drop, bool(self.config.offset_jump_a),
                                  wait=not span.deferred)
        if change is None:              # judged again as the next block closes, once
            span.measured_hz, span.deferred = None, True
            return
        self._take_over(change.filter, change.span, jump_at=change.jump_at)
        if change.jump_at is not None:
            span.measured_hz, span.jumped = m.motion_fundamentals_hz, True
            self.offset_jumps += 1
        self._log.mark(self._filter, self._state)

    def _check_motion(self, recent: np.ndarray) -> None:
        """Measure the periodic motion: a model from its span, while it explains the current."""
        if self._log.current.deferred:      # a failed model's judgement waits: it runs on
            return
        f0 = measure_recent(recent, self.sample_rate_hz, self.model, self.config)
        floor = MOTION_PERIODS / min(recent.size / self.sample_rate_hz, MOTION_LONGEST_S)
        span = self._log.span_for(f0, self._first_rest_n is None, floor)
        if span is None or same_motion(f0, self.model.motion_fundamentals_hz):
            return
        filters = [self._new_filter(StateSpaceModel(self.reduced, config, self.sample_rate_hz,
                                                    self.model.fundamentals_hz, f0))
                   for config in (remainder_configs(self.config) if f0 else (self.config,))]
        filt, run = likeliest(span, filters)
        if not self._take_over(filt, span, lambda run: not f0 or explains(
                run.now.innovations, run.start.innovations, self.config.false_alarm), run=run):
            self._log.current.measured_hz = ()          # refused: it counts as none

    def _take_over(self, filt: KalmanFilter, span, accept=None, jump_at=None,
                   run=None) -> bool:
        """
        Let ``filt`` take over from the start of ``span``, filtered again under it.

        Returns False, changing nothing, when ``accept(run)`` (:func:`~.periodic.refilter`'s
        result) refuses the run.  ``jump_at``: the offset jumped before that sample.  ``run``:
        the span already filtered again under ``filt`` (without a jump; again when a
        fixed-lag smoother holds samples of it: they are recorded).
        """
        held = 0 if self._lag is None else min(len(span.y), self._lag.held)
        rec = ForwardRecord.empty(held, filt.model.size) if held else None
        if run is None or rec is not None:
            run = refilter(span, filt, rec, jump_at)
        if accept is not None and not accept(run):
            return False
        link = self._begin_segment(filt, run.start, span.filter, span.state)
        for begun, before in run.restarts:      # a motion's start (or a jump) in the span:
            self._begin_segment(filt, begun, filt, before)     # a part from there
        if rec is not None:             # the span's samples held are the new model's
            self._lag.replace_newest(filt, rec, link if held == len(span.y) else None)
        rested = bool(run.still.any())
        if span is self._log.current:   # what the rest test says of the stretch now
            span.rest, span.moved = rested, not run.still.all()
        if self._first_rest_n is None and rested:
            self._first_rest_n = run.start.samples + int(np.argmax(run.still))
        self._filter, self._state = filt, run.now
        return True

    # -- fixed-lag output -------------------------------------------------------------------
    def pop_smoothed(self, flush: bool = False) -> Estimate | None:
        """Return the fixed-lag smoothed estimates ready, oldest first (``FixedLagSmoother``)."""
        return None if self._lag is None else self._lag.pop(flush)

    # -- offline --------------------------------------------------------------------------
    def smooth(self, current_a, steps=None) -> Estimate:
        """
        Smoothed estimate of a whole record from a fresh start (fixed-interval RTS).

        It follows the live model: the record runs through a fresh estimator with the live
        rules (the mains line and a periodic motion measured at the same checks, a periodic
        model taking over from the start of its span), and the backward pass runs over each
        model's part and on through each change (:func:`~.smoother.smooth_segments`): the
        fixed-lag smoother with a lag longer than the record.  Leaves this estimator's
        stream state untouched.
        """
        y = np.asarray(current_a, dtype=float)
        st = np.ones(y.size) if steps is None else np.asarray(steps, dtype=float)
        live = KalmanEstimator(self.reduced, self.sample_rate_hz, self.config, self.mains_hz)
        live._changes.segments = [(0, live._filter, live._state.copy(), None)]
        still = live.estimate(y, st).still
        return Estimate(*smooth_segments(live._changes.segments, y, st), still)

    # -- reporting (status: :class:`~.kalman_state.KalmanState`) ----------------------------
    def settling(self) -> tuple[float, str]:
        if self._first_rest_n is not None:
            return self._first_rest_n / self.sample_rate_hz, 'its level learned at its first rest'
        why = 'five time constants of motion_corner_hz: no rest in it'
        return forgets_s(self.config.motion_corner_hz), why
