# SPDX-License-Identifier: Apache-2.0
"""
The stream core: sample blocks in, deflection blocks out, with every rule of a live stream.

:class:`StreamEstimator` is what the estimator node, ``ipmc-model estimate`` and bag replay
run; the node only unpacks messages, calls :meth:`StreamEstimator.feed` (a block) or
:meth:`StreamEstimator.feed_one` (a one-sample message) and publishes.  Every rule decides one
*sample*, so the result does not depend on how the stream is cut into messages:

* **values**: a current that is not finite or has ``|i| > MAX_ABS_CURRENT_A`` is refused
  (that sample only);
* **time** (:mod:`~ipmc_sensor_ros.estimation.timebase`): samples are taken at their stamps,
  on the nearest slot of a grid that follows them (jitter up to 25 % of the period); the
  slots since the previous accepted sample plus the stamp's offset from its slot are the
  ``steps`` handed to the filter (``DeflectionEstimator.process``): missing samples and gaps up to
  ``max_gap_s`` are bridged by its prediction (``gaps_bridged``, ``samples_lost``).  A
  duplicated stamp, a stamp behind the previous one by at most ``max_gap_s`` or on the previous
  sample's slot is refused (that sample; no reset).  A longer gap (``gaps``) or jump back (a
  bag loop, a new run) starts a new run: filter reset (``resets``).  The output time of a
  sample is its stamp (minus a model delay);
* **rate**: measured from the stamps (``measured_rate_hz``), said once if off ``sample_rate_hz``
  by more than ``rate_tolerance`` (slots a re-lock shows were no loss leave the counts);
  the filter follows it (bumpless) beyond ``RATE_FOLLOW_FRACTION`` (``rate_rebuilds``);
* **smoothed output** (``smoothed_lag_s`` > 0): :meth:`StreamEstimator.pop_smoothed` returns
  each estimated sample once more, smoothed with that lag, in order; an estimator replaced
  hands over what it holds first;
* **messages**: a block longer than ``max_block_samples`` (``too_long``) or one that cannot be
  read (``malformed``, :meth:`reject`) is refused whole;
* **accounting** (:class:`~ipmc_sensor_ros.estimation.accounting.StreamAccounts`): every
  sample counted once, as estimated, refused (per reason), dropped or undelivered; a refused
  sample never touches the filter; a non-finite estimate drops its samples and resets; an
  estimate that could not be delivered (:meth:`~StreamAccounts.unpublished`) is counted and
  changes nothing.  The node counts its source events here too (other publishers ignored,
  messages lost before it; :mod:`~ipmc_sensor_ros.interface.sources`).

One rule per sample: :meth:`StreamEstimator.feed_one` applies it to one sample;
:meth:`StreamEstimator.feed` applies it to a block, running its leading samples that are
accepted without a refusal or a new run through the same grid expression in numpy
(:meth:`~ipmc_sensor_ros.estimation.timebase.Timebase.admit_plain`).  Rule violations are
named in ``last_rejection`` / ``last_warning`` with the values and the topic or file.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from ..errors import DataError
from .accounting import (COUNTER_NAMES, MAX_ABS_CURRENT_A, MAX_BLOCK_SAMPLES, REJECT_REASONS,
                         StreamAccounts, as_current_block, validate_block)
from .deflection import DeflectionEstimator
from .timebase import (JITTER_FRACTION, MAX_STAMP_S, NON_FINITE, OUT_OF_RANGE, RATE_WINDOW_S,
                       START, Timebase)

__all__ = ['StreamEstimator', 'validate_block', 'COUNTER_NAMES', 'REJECT_REASONS',
           'MAX_ABS_CURRENT_A', 'MAX_BLOCK_SAMPLES', 'MAX_STAMP_S', 'JITTER_FRACTION',
           'RATE_WINDOW_S', 'RATE_FOLLOW_FRACTION']

#: The filter is rebuilt at the measured rate when it differs from the filter's by more than
#: this fraction.  The sensor differentiates, so a relative rate error is the same relative
#: amplitude error: 0.2 % is a fifth of the 1 % accuracy the estimator is held to, and 20 times
#: the ~100 ppm a DAQ crystal is off the host clock (which never causes a rebuild).
RATE_FOLLOW_FRACTION = 0.002


class StreamEstimator(StreamAccounts):
    """
    Stream rules and accounting around a :class:`DeflectionEstimator` (module docstring).

    Parameters
    ----------
    estimator : DeflectionEstimator
        The model-aware filter; replaced bumplessly with :meth:`replace_estimator`.  Its
        sample rate is the nominal one (``sample_rate_hz``).
    max_gap_s : float
        Longest gap (or jump back) bridged without a reset, s.
    max_block_samples : int
        Longest block accepted.
    source : str
        Where the samples come from (topic or file), named in every message.
    now_s : callable, optional
        Time of a block without sample times when nothing came before (the node's clock).
    warn : callable, optional
        Receives the text of every reset, refusal and rate report (the node logs it).
    rate_tolerance : float
        Relative rate mismatch reported (``rate_tolerance`` of the diagnostics).

    """

    def __init__(self, estimator: DeflectionEstimator, *, max_gap_s: float = 0.1,
                 max_block_samples: int = MAX_BLOCK_SAMPLES, source: str = 'current',
                 now_s: Callable[[], float] | None = None,
                 warn: Callable[[str], None] | None = None, rate_tolerance: float = 0.05):
        if not (math.isfinite(max_gap_s) and max_gap_s > 0.0):
            raise DataError(f'max_gap_s must be > 0 s, got {max_gap_s!r}')
        super().__init__(source, warn)
        self.estimator = estimator
        self.max_block_samples = int(max_block_samples)
        self.rate_tolerance = float(rate_tolerance)
        self._now_s = now_s or (lambda: 0.0)
        self.nominal_rate_hz = float(estimator.sample_rate_hz)
        self.timebase = Timebase(1.0 / self.nominal_rate_hz, max_gap_s)
        # of the last feed: input samples with output, each stamp's offset from its slot
        self.accepted, self.offsets = np.zeros(0, dtype=bool), np.zeros(0)
        self._filter_hz = self.nominal_rate_hz      # rate the filter is (to be) built for
        self._rate_reported = False
        self._stamp_floor_s: float | None = None    # output stamps must pass it (delay grew)
        self._smoothed: list[tuple] = []    # smoothed by estimators replaced (pop_smoothed)

    # -- configuration --------------------------------------------------------------
    @property
    def sample_rate_hz(self) -> float:
        """Return the rate the filter runs at (the measured one once it is followed), Hz."""
        return float(self.estimator.sample_rate_hz)

    @property
    def measured_rate_hz(self) -> float | None:
        """Return the rate measured from the stamps (None before a full window), Hz."""
        return None if self.timebase.measured is None else 1.0 / self.timebase.measured

    @property
    def max_gap_s(self) -> float:
        return self.timebase.max_gap_s

    @max_gap_s.setter
    def max_gap_s(self, value: float) -> None:
        self.timebase.max_gap_s = float(value)

    @property
    def last_time_s(self) -> float | None:
        """Return the stamp of the last accepted sample, s."""
        return self.timebase.last_s

    def replace_estimator(self, new: DeflectionEstimator) -> None:
        """
        Swap in ``new`` (parameter change); its output continues from the old one's.

        ``new``'s rate is the nominal one; a measured rate the filter follows is kept.  Should
        the hand-over itself fail, ``new`` starts afresh and that is counted as a reset.
        """
        self.nominal_rate_hz = float(new.sample_rate_hz)
        old = self.estimator
        if self.last_time_s is not None and new.delay_s > old.delay_s:
            self._stamp_floor_s = self.last_time_s - old.delay_s   # the last output stamp
        try:
            if abs(self._filter_hz / new.sample_rate_hz - 1.0) > RATE_FOLLOW_FRACTION:
                new = new.rebuilt(sample_rate_hz=self._filter_hz)
            new.continue_from(self.estimator)
        except Exception as exc:  # never lose the stream over a hand-over
            new.reset()
            self.counters['resets'] += 1
            self._say(f'filter rebuilt without continuity on {self.source} '
                      f'({type(exc).__name__}): filter reset')
        self._hand_over(new)

    def _hand_over(self, new: DeflectionEstimator) -> None:
        """Make ``new`` the estimator; what the old one smoothed goes out first."""
        done = self.estimator.pop_smoothed(flush=True)
        if done is not None:
            self._smoothed.append(done)
        self.estimator = new

    def pop_smoothed(self, flush: bool = False):
        """Return (times, deflection, std) smoothed since last asked (``flush``: all), or None."""
        ready = self.estimator.pop_smoothed(flush)
        parts, self._smoothed = self._smoothed + ([ready] if ready is not None else []), []
        if not parts:
            return None
        t, w, std = (np.concatenate(p) for p in zip(*parts))
        ok = np.isfinite(w)             # a non-finite estimate's samples were dropped live
        return (t, w, std) if ok.all() else (t[ok], w[ok], std[ok])

    def restart(self) -> None:
        """Begin a new stream (a managed node activated again): filter reset, stamps forgotten."""
        self.estimator.reset()
        self.timebase.forget()
        self._refused_since = 0
        self._stamp_floor_s = None

    def status(self) -> dict:
        """Return the stream's time state for counters and diagnostics (JSON-able)."""
        return {'measured_rate_hz': self.measured_rate_hz, 'filter_rate_hz': self.sample_rate_hz,
                'grid_period_s': self.timebase.period_s}

    def _rate_action(self) -> float | None:
        """Judge a freshly measured rate: report a mismatch once; return a rate to follow."""
        self.timebase.fresh = False
        self._recount(self.timebase)
        hz = self.measured_rate_hz
        off = hz / self.nominal_rate_hz - 1.0
        if abs(off) > self.rate_tolerance:
            if not self._rate_reported:
                self._say(f'measured sample rate {hz:.6g} Hz on {self.source} is {off:+.2%} off '
                          f'sample_rate_hz = {self.nominal_rate_hz:g} Hz (rate_tolerance '
                          f'{self.rate_tolerance:g}): estimating at the measured rate')
            self._rate_reported = True
        else:
            self._rate_reported = False
        if abs(hz / self._filter_hz - 1.0) > RATE_FOLLOW_FRACTION:
            self._filter_hz = hz
            return hz
        return None

    def _follow_rate(self, hz: float) -> None:
        """Rebuild the filter at ``hz`` (bumpless); on failure keep the old one and say why."""
        try:
            self._hand_over(self.estimator.rebuilt(sample_rate_hz=hz))
        except Exception as exc:  # an unusable rate must not stop the stream
            self._say(f'could not rebuild the filter at the measured {hz:.6g} Hz on '
                      f'{self.source}: {type(exc).__name__}: {exc}')
            return
        self.counters['rate_rebuilds'] += 1

    # -- the rule for one sample ----------------------------------------------------
    def _admit(self, t: float, i: float) -> int:
        """
        Decide one sample (module docstring): steps >= 1, ``START`` (0) or -1 (refused).

        Everything is counted here; a run's start is counted and said (:meth:`_begin_run`).
        """
        if -MAX_ABS_CURRENT_A <= i <= MAX_ABS_CURRENT_A:
            code = self.timebase.admit(t)
        else:
            code = OUT_OF_RANGE if math.isfinite(i) else NON_FINITE
        if code >= 0:               # accepted: a gap bridged, or the first of a run
            if code > 1:
                self._bridged(code, self._refused_since)
            self._refused_since = 0
            if code == START:
                self._begin_run()
            return code
        self._refuse(code, t, i)
        return -1

    def _admit_block(self, t: np.ndarray, i: np.ndarray):
        """
        :meth:`_admit` for every sample of a block, the plain runs of samples in numpy.

        Returns (codes, rate cuts): per sample steps >= 1, 0 (START) or -1, and the
        ``(index, rate)`` after which the filter follows a measured rate; ``offsets``: each
        accepted stamp's offset from its slot, periods.
        """
        n, tb, cuts = t.size, self.timebase, []
        codes, self.offsets = np.empty(n, dtype=np.int64), np.zeros(n)
        offsets = self.offsets
        ok = (i >= -MAX_ABS_CURRENT_A) & (i <= MAX_ABS_CURRENT_A)
        bad = np.flatnonzero(~ok).tolist() + [n]
        b = k = 0
        while k < n:
            plain = tb.admit_plain(t, k, bad[b]) if k < bad[b] else ()
            if len(plain):
                m = len(plain)
                codes[k:k + m], offsets[k:k + m] = plain, tb.plain_offsets
                for j in np.flatnonzero(plain > 1).tolist():   # rare: a Python loop
                    self._bridged(int(plain[j]), self._refused_since if j == 0 else 0)
                self._refused_since = 0
                k += m
            else:
                b += k == bad[b]
                codes[k] = self._admit(float(t[k]), float(i[k]))
                offsets[k] = tb.slot_offset if codes[k] >= 0 else 0.0
                k += 1
            if tb.fresh:
                hz = self._rate_action()
                if hz is not None:
                    cuts.append((k - 1, hz))
        return codes, cuts

    # -- data path ----------------------------------------------------------------------
    def feed_one(self, time_s: float, current_a: float):
        """
        One timed sample (a one-sample message): ``(time_out, deflection)`` as floats.

        ``None`` when the sample was refused or its estimate dropped (counted, with
        ``last_rejection`` / ``last_warning`` saying why).  The same rule as :meth:`feed`.
        """
        c = self.counters
        c['messages_in'] += 1
        c['samples_in'] += 1
        code = self._admit(time_s, current_a)
        if code < 0:
            c['messages_rejected'] += 1
            return None
        if code == START:
            self.estimator.reset()
        out = self._estimated(lambda: self.estimator.process_one(
            time_s, current_a, (code or 1) + self.timebase.slot_offset), 1)
        if self.timebase.fresh:
            hz = self._rate_action()
            if hz is not None:
                self._follow_rate(hz)
        if out is None:
            return None
        t_out, w = out
        c['samples_out'] += 1
        if self._stamp_floor_s is not None:
            kept = self._past_floor(np.array([t_out]), np.array([w]))
            return None if kept is None else (float(kept[0][0]), float(kept[1][0]))
        return t_out, w

    def feed(self, times, currents, claimed: int | None = None):
        """
        Estimate one block.

        Parameters
        ----------
        times : array_like or None
            Sample times, s (``None``: continue the stream on its grid).
        currents : array_like
            Sensing current, A.
        claimed : int, optional
            Samples the message claims (accounting of a message that cannot be read); defaults
            to the number of currents.

        Returns
        -------
        (time_s, deflection_m) arrays of the accepted samples (:attr:`accepted` marks them in
        the input), or ``None`` when none was (counted, ``last_rejection`` says why).

        """
        n_claimed = claimed if claimed is not None else int(np.size(currents))
        self.accepted = np.zeros(0, dtype=bool)
        if np.size(currents) > self.max_block_samples:
            self.reject(n_claimed, f'block of {np.size(currents)} samples, more than the limit '
                                   f'{self.max_block_samples} (max_block_samples)', 'too_long')
            return None
        try:
            current = as_current_block(currents, self.max_block_samples)
            t = self.timebase.block_times(times, current.size, self._now_s)
        except DataError as exc:
            self.reject(n_claimed, str(exc))
            return None
        c = self.counters
        c['messages_in'] += 1
        c['samples_in'] += current.size
        codes, cuts = self._admit_block(t, current)
        t_out, w = self._filter(t, current, codes, cuts)
        if t_out is None:
            c['messages_rejected'] += 1
            return None
        if self._stamp_floor_s is not None:
            return self._past_floor(t_out, w)
        return t_out, w

    def _past_floor(self, t_out: np.ndarray, w: np.ndarray):
        """
        Output stamps strictly increase: withhold estimates stamped at or before the floor.

        After ``time_delay`` grew, the first estimates (stamped ``t - delay``) fall on instants
        already published (to within half a period): counted in ``samples_dropped``.
        """
        keep = t_out > self._stamp_floor_s + 0.5 / self.sample_rate_hz
        withheld = int(t_out.size - np.count_nonzero(keep))
        if withheld:
            c = self.counters
            c['samples_out'] -= withheld
            c['samples_dropped'] += withheld
            if self.accepted.size:
                self.accepted[np.flatnonzero(self.accepted)[~keep]] = False
            self._say(f'time_delay grew on {self.source}: {withheld} estimate(s) stamped at or '
                      f'before the last published one ({self._stamp_floor_s!r} s) not published '
                      '(output stamps strictly increase)')
        if not keep.any():
            return None
        self._stamp_floor_s = None
        return t_out[keep], w[keep]

    def _filter(self, t, current, codes, cuts):
        """Run the filter over the accepted samples, resetting and rebuilding where decided."""
        events = sorted([(int(k), 1, None) for k in np.flatnonzero(codes == START)]
                        + [(k + 1, 0, hz) for k, hz in cuts])
        accepted = codes >= 0
        parts = []
        start = 0
        for stop, kind, hz in events + [(t.size, 2, None)]:
            sel = np.flatnonzero(accepted[start:stop]) + start
            if sel.size:
                out = self._estimated(lambda: self.estimator.process(
                    t[sel], current[sel], np.maximum(codes[sel], 1) + self.offsets[sel]),
                    sel.size)
                if out is not None:
                    parts.append((*out, self.estimator.last_std_m))
                    self.counters['samples_out'] += sel.size
                else:
                    accepted[sel] = False
            if kind == 1:
                self.estimator.reset()
            elif kind == 0:
                self._follow_rate(hz)
            start = stop
        self.accepted = accepted
        self.codes = codes
        if not parts:
            self.last_std_m = np.zeros(0)
            return None, None
        self.last_std_m = np.concatenate([p[2] for p in parts])
        if len(parts) == 1:
            return parts[0][:2]
        return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])
