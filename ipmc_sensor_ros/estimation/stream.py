# SPDX-License-Identifier: Apache-2.0
"""
The stream core: sample blocks in, deflection blocks out, with every rule of a live stream.

:class:`StreamEstimator` is what the estimator node, ``ipmc-model estimate`` and bag replay
run; the node only unpacks messages, calls :meth:`StreamEstimator.feed` and publishes.  It owns

* **value rules** (:func:`validate_block`): a block is 1-D, non-empty, at most
  ``max_block_samples`` long, finite and within ``|i| <= MAX_ABS_CURRENT_A``;
* **time rules** (:meth:`StreamEstimator.check_times`): sample times strictly increasing, finite,
  within ``[0, MAX_STAMP_S]`` (``builtin_interfaces/Time.sec`` is int32), and a median period
  within ``PERIOD_TOLERANCE`` of ``1/sample_rate_hz``; a block (also of one sample) may not start
  less than ``(1 - PERIOD_TOLERANCE)/fs`` after the previous valid sample (a stream faster than
  ``sample_rate_hz`` is refused, however it is cut into messages); blocks without times (1-D
  messages) continue the previous time at ``1/fs`` (or start at ``now_s()``) and obey the same
  range rule;
* **continuity rules**: time stepping back between blocks (a new run, a bag loop) or a gap longer
  than ``max_gap_s`` resets the filter (the missing current is unknown); a shorter gap is bridged
  (the filter runs on, counted in ``gaps_bridged``); a gap inside a block is treated as if the
  block had been cut there (the result does not depend on how the stream is cut into messages);
* **accounting**: the counters of :data:`COUNTER_NAMES` with the invariant
  ``samples_in == samples_out + samples_rejected + samples_dropped + samples_unpublished``.
  Rejected blocks never touch filter state; a non-finite estimate drops the block and resets;
  an estimate that could not be delivered (:meth:`StreamEstimator.unpublished`, output
  back-pressure) is counted, and neither resets nor changes the filter.

Every rule lives here once; a rule violation is a :class:`~ipmc_sensor_ros.errors.DataError`
whose text names the rule, the values and (``source``) the topic or file.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from ..errors import DataError
from .deflection import DeflectionEstimator

__all__ = ['StreamEstimator', 'validate_block', 'COUNTER_NAMES', 'MAX_ABS_CURRENT_A',
           'MAX_BLOCK_SAMPLES', 'MAX_STAMP_S', 'PERIOD_TOLERANCE', 'estimate_record',
           'smooth_record']

#: Largest block accepted by default (samples).
MAX_BLOCK_SAMPLES = 1_000_000

#: Largest plausible sensing current, A (IPMC currents are nA..uA; 1 A means a wiring or
#: unit error).
MAX_ABS_CURRENT_A = 1.0

#: Largest representable stamp (``builtin_interfaces/Time.sec`` is int32), s.
MAX_STAMP_S = 2.0 ** 31 - 1.0

#: Relative tolerance of a sample period against ``1/sample_rate_hz``.
PERIOD_TOLERANCE = 0.01

#: A step between blocks longer than this many periods is a gap (bridged or, beyond
#: ``max_gap_s``, a reset).
GAP_PERIODS = 1.5

#: Counters kept per stream; see the module docstring for the invariant.
COUNTER_NAMES = ('messages_in', 'samples_in', 'samples_out', 'samples_rejected',
                 'messages_rejected', 'samples_dropped', 'samples_unpublished',
                 'messages_unpublished', 'resets', 'gaps', 'gaps_bridged')


def validate_block(values, max_samples: int = MAX_BLOCK_SAMPLES,
                   max_abs_current_a: float = MAX_ABS_CURRENT_A) -> np.ndarray:
    """
    Check a block of current samples before it touches filter state.

    Returns a float64 1-D array, or raises :class:`~ipmc_sensor_ros.errors.DataError` saying why
    (empty, too long, non-finite or implausibly large values).  Rejecting the whole block, rather
    than patching samples, keeps the filter state clean and the sample accounting exact.
    """
    try:
        x = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise DataError('current block is not numeric') from None
    if x.ndim != 1:
        raise DataError(f'current block must be 1-D, got shape {x.shape}')
    if x.size == 0:
        raise DataError('current block is empty')
    if x.size > max_samples:
        raise DataError(f'current block has {x.size} samples, more than the limit {max_samples}')
    if float(np.max(np.abs(x))) <= max_abs_current_a:   # one pass; NaN makes it False
        return x
    finite = np.isfinite(x)
    if not finite.all():
        raise DataError(f'current block has {int((~finite).sum())} non-finite sample(s) '
                        f'(first at index {int(np.argmin(finite))})', index=int(np.argmin(finite)))
    k = int(np.argmax(np.abs(x) > max_abs_current_a))
    raise DataError(f'current block has |i| > {max_abs_current_a} A at index {k} '
                    f'({float(x[k])!r} A): not a sensing current', index=k)


def _no_log(text: str) -> None:
    return None


class StreamEstimator:
    """
    Stream rules and accounting around a :class:`DeflectionEstimator` (module docstring).

    Parameters
    ----------
    estimator : DeflectionEstimator
        The model-aware filter; replaced bumplessly with :meth:`replace_estimator`.
    max_gap_s : float
        Longest gap bridged without a reset, s.
    max_block_samples : int
        Longest block accepted.
    source : str
        Where the samples come from (topic or file), named in every message.
    now_s : callable, optional
        Time of a block without sample times when nothing came before (the node's clock).
    warn : callable, optional
        Receives the text of every reset, dropped block and rejection (the node logs it).

    """

    def __init__(self, estimator: DeflectionEstimator, *, max_gap_s: float = 0.1,
                 max_block_samples: int = MAX_BLOCK_SAMPLES, source: str = 'current',
                 now_s: Callable[[], float] | None = None,
                 warn: Callable[[str], None] | None = None):
        if not (math.isfinite(max_gap_s) and max_gap_s > 0.0):
            raise DataError(f'max_gap_s must be > 0 s, got {max_gap_s!r}')
        self.estimator = estimator
        self.max_gap_s = float(max_gap_s)
        self.max_block_samples = int(max_block_samples)
        self.source = source
        self._now_s = now_s or (lambda: 0.0)
        self._warn = warn or _no_log
        self.counters: dict[str, int] = dict.fromkeys(COUNTER_NAMES, 0)
        self.last_rejection = ''
        self.last_warning = ''
        self.last_time_s: float | None = None   # last sample fed to the filter
        self._last_valid_s: float | None = None  # last well-formed sample time seen (period rule)
        self._fs = float(estimator.sample_rate_hz)
        self._stamp_floor_s: float | None = None   # output stamps must pass it (delay grew)

    # -- configuration --------------------------------------------------------------
    @property
    def sample_rate_hz(self) -> float:
        return self._fs

    def replace_estimator(self, new: DeflectionEstimator) -> None:
        """
        Swap in ``new`` (parameter change); its output continues from the old one's.

        Should the hand-over itself fail, ``new`` starts afresh and that is counted as a
        reset.
        """
        old = self.estimator
        if self.last_time_s is not None and new.delay_s > old.delay_s:
            self._stamp_floor_s = self.last_time_s - old.delay_s   # the last output stamp
        try:
            new.continue_from(self.estimator)
        except Exception as exc:  # never lose the stream over a hand-over
            new.reset()
            self.counters['resets'] += 1
            self._say(f'filter rebuilt without continuity on {self.source} '
                      f'({type(exc).__name__}): filter reset')
        self.estimator = new
        self._fs = float(new.sample_rate_hz)

    def restart(self) -> None:
        """
        Begin a new stream: filter reset.

        Previous sample times forgotten (not counted as a reset; e.g. a managed
        node activated again).
        """
        self.estimator.reset()
        self.last_time_s = self._last_valid_s = self._stamp_floor_s = None

    def check_invariant(self) -> bool:
        c = self.counters
        return c['samples_in'] == (c['samples_out'] + c['samples_rejected'] + c['samples_dropped']
                                   + c['samples_unpublished'])

    # -- events -------------------------------------------------------------------------
    def _say(self, text: str) -> None:
        self.last_warning = text
        self._warn(text)

    def reject(self, n_samples: int, reason: str) -> None:
        """Count a message of ``n_samples`` claimed samples as received and rejected."""
        c = self.counters
        c['messages_in'] += 1
        c['samples_in'] += n_samples
        c['messages_rejected'] += 1
        c['samples_rejected'] += n_samples
        self.last_rejection = reason
        self._say(f'rejected message on {self.source} ({n_samples} sample(s)): {reason}')

    def unpublished(self, n_samples: int, reason: str) -> None:
        """
        Move ``n_samples`` just counted as ``samples_out`` to ``samples_unpublished``.

        The estimate exists (the filter ran) but could not be delivered. No reset.
        """
        c = self.counters
        c['samples_out'] -= n_samples
        c['samples_unpublished'] += n_samples
        c['messages_unpublished'] += 1
        self._say(f'could not publish {n_samples} estimate(s) from {self.source}: {reason}')

    def _reset(self, text: str) -> None:
        self.estimator.reset()
        self.counters['resets'] += 1
        self._say(text)

    # -- rules --------------------------------------------------------------------------
    def check_times(self, times: np.ndarray | None, n: int) -> np.ndarray:
        """
        Sample times of a block of ``n`` samples, checked (or inferred when ``None``).

        Raises :class:`~ipmc_sensor_ros.errors.DataError` naming the rule broken.
        """
        fs = self._fs
        if times is None:
            start = self._now_s() if self.last_time_s is None else self.last_time_s + 1.0 / fs
            times = start + np.arange(n) / fs
        elif times.size != n:
            raise DataError(f'{times.size} sample times for {n} samples')
        # strictly increasing with finite ends implies all finite and within the ends
        # (NaN fails 'dt > 0'), so the range is checked on the first and last time only
        dt = np.diff(times)
        if not (dt > 0.0).all():
            if not np.all(np.isfinite(times)):
                raise DataError('sample times contain non-finite values')
            k = int(np.argmax(~(dt > 0.0)))
            raise DataError(f'sample times are not strictly increasing (index {k + 1}: '
                            f'{times[k + 1]!r} s after {times[k]!r} s)')
        first, last = float(times[0]), float(times[-1])
        if not (math.isfinite(first) and math.isfinite(last)):
            raise DataError('sample times contain non-finite values')
        if first < 0.0 or last > MAX_STAMP_S:
            raise DataError(f'sample times must lie in [0, {MAX_STAMP_S:.0f}] s '
                            f'(got {first!r} .. {last!r} s)')
        if n >= 2:
            period = float(np.median(dt))
            if abs(period * fs - 1.0) > PERIOD_TOLERANCE:
                raise DataError(f'median sample period {period:.6g} s does not match '
                                f'sample_rate_hz = {fs:g} Hz (1/fs = {1.0 / fs:.6g} s, '
                                f'tolerance {PERIOD_TOLERANCE:.0%})')
        previous, self._last_valid_s = self._last_valid_s, last
        if previous is not None and 0.0 < (first - previous) * fs < 1.0 - PERIOD_TOLERANCE:
            raise DataError(f'sample at {first!r} s only {first - previous:.6g} s after the '
                            f'previous one at {previous!r} s: faster than sample_rate_hz = '
                            f'{fs:g} Hz (1/fs = {1.0 / fs:.6g} s)')
        return times

    def _continuity(self, first_time_s: float) -> None:
        """Reset on a backward jump or a long gap; count a bridged gap."""
        if self.last_time_s is None:
            return
        step = first_time_s - self.last_time_s
        if step <= 0.0:
            self._reset(f'time jumped back by {-step:.6g} s on {self.source}: filter reset')
        elif step > self.max_gap_s:
            self.counters['gaps'] += 1
            self._reset(f'gap of {step:.6g} s (> max_gap_s = {self.max_gap_s:g} s) on '
                        f'{self.source}: filter reset')
        elif step * self._fs > GAP_PERIODS:
            self.counters['gaps_bridged'] += 1

    # -- data path ----------------------------------------------------------------------
    def feed(self, times, currents, claimed: int | None = None):
        """
        Estimate one block.

        Parameters
        ----------
        times : array_like or None
            Sample times, s (``None``: continue the stream at ``1/fs``).
        currents : array_like
            Sensing current, A.
        claimed : int, optional
            Samples the message claims (accounting of a message that cannot be read); defaults
            to the number of currents.

        Returns
        -------
        (time_s, deflection_m) arrays, or ``None`` when the block was rejected or dropped
        (counted, with ``last_rejection`` / ``last_warning`` saying why).

        """
        try:
            current = validate_block(currents, max_samples=self.max_block_samples)
            t = self.check_times(None if times is None else np.asarray(times, dtype=float),
                                 current.size)
        except DataError as exc:
            n = claimed if claimed is not None else int(np.size(currents))
            self.reject(n, str(exc))
            return None
        c = self.counters
        c['messages_in'] += 1
        c['samples_in'] += current.size
        # a gap inside a block obeys the rules of a gap between blocks
        cuts = np.flatnonzero(np.diff(t) * self._fs > GAP_PERIODS) + 1 if t.size > 1 else ()
        if len(cuts):
            parts = []
            for a, b in zip([0, *cuts], [*cuts, t.size]):
                self._continuity(float(t[a]))
                parts.append(self.estimator.process(t[a:b], current[a:b]))
                self.last_time_s = float(t[b - 1])
            t_out = np.concatenate([p[0] for p in parts])
            w = np.concatenate([p[1] for p in parts])
        else:
            self._continuity(float(t[0]))
            t_out, w = self.estimator.process(t, current)
        if not np.all(np.isfinite(w)):
            self.estimator.reset()
            c['samples_dropped'] += current.size
            c['resets'] += 1
            self._say(f'non-finite estimate on {self.source}: block dropped, filter reset')
            return None
        self.last_time_s = float(t[-1])
        if self._stamp_floor_s is not None:
            return self._past_floor(t_out, w)
        c['samples_out'] += current.size
        return t_out, w

    def _past_floor(self, t_out: np.ndarray, w: np.ndarray):
        """
        Output stamps strictly increase: withhold estimates stamped at or before the floor.

        After ``time_delay`` grew by d, the first estimates (stamped ``t - delay``) fall on
        instants already published (within rounding: less than half a period after the last
        stamp); they are counted in ``samples_dropped``, not published.
        """
        keep = t_out > self._stamp_floor_s + 0.5 / self._fs
        n_keep = int(np.count_nonzero(keep))
        c = self.counters
        c['samples_out'] += n_keep
        if n_keep < t_out.size:
            c['samples_dropped'] += t_out.size - n_keep
            self._say(f'time_delay grew on {self.source}: {t_out.size - n_keep} estimate(s) '
                      f'stamped at or before the last published one ({self._stamp_floor_s!r} s) '
                      'not published (output stamps strictly increase)')
        if not n_keep:
            return None
        self._stamp_floor_s = None
        return t_out[keep], w[keep]

    def feed_one(self, time_s: float, current_a: float):
        """
        One timed sample on the lean path: ``(time_out, deflection)`` as floats.

        ``None`` if the estimate was non-finite (dropped and counted, as :meth:`feed` does);
        ``False`` — having touched nothing — when the sample needs the general path
        (:meth:`feed`: a rule to enforce, a reset, a gap, or effects around the filter).
        Identical results and counters to :meth:`feed` (tested).
        """
        t, i = time_s, current_a
        # NaN fails every comparison, so non-finite values leave through the general path
        if not (0.0 <= t <= MAX_STAMP_S and -MAX_ABS_CURRENT_A <= i <= MAX_ABS_CURRENT_A):
            return False
        last = self.last_time_s
        if last is None or self._last_valid_s != last or self._stamp_floor_s is not None:
            return False
        step = (t - last) * self._fs
        if not (1.0 - PERIOD_TOLERANCE <= step <= GAP_PERIODS and t - last <= self.max_gap_s):
            return False
        est = self.estimator
        if not est.plain:
            return False
        t_out, w = est.process_one(t, i)
        c = self.counters
        c['messages_in'] += 1
        c['samples_in'] += 1
        if not math.isfinite(w):
            est.reset()
            c['samples_dropped'] += 1
            c['resets'] += 1
            self._say(f'non-finite estimate on {self.source}: block dropped, filter reset')
            self._last_valid_s = t
            return None
        self.last_time_s = self._last_valid_s = t
        c['samples_out'] += 1
        return t_out, w

    def run_record(self, time_s, current_a, block_samples: int = 1000):
        """
        Feed a whole record (offline) in blocks of ``block_samples``.

        Cut also where time does not increase (a record may hold several concatenated runs:
        each is a new run, as a bag loop is live). Returns (output times, deflection, kept):
        ``kept`` marks the input samples that have an estimate (rejected or dropped blocks have
        none; see :attr:`counters`).
        """
        t = np.asarray(time_s, float)
        i = np.asarray(current_a, float)
        kept = np.zeros(t.size, dtype=bool)
        cuts = list(np.flatnonzero(~(np.diff(t) > 0.0)) + 1) + [t.size]
        # estimates go straight into record-length arrays (a list of per-block arrays
        # joined at the end held them twice)
        out_t, out_w = np.empty(t.size), np.empty(t.size)
        n_out, start = 0, 0
        for stop in cuts:
            for k in range(start, stop, block_samples):
                end = min(k + block_samples, stop)
                res = self.feed(t[k:end], i[k:end])
                if res is not None:
                    m = res[0].size
                    out_t[n_out:n_out + m] = res[0]
                    out_w[n_out:n_out + m] = res[1]
                    n_out += m
                    kept[k:end] = True
            start = stop
        if n_out == 0:
            return np.zeros(0), np.zeros(0), kept
        return out_t[:n_out], out_w[:n_out], kept


def estimate_record(estimator: DeflectionEstimator, time_s, current_a, *, max_gap_s: float = 0.1,
                    block_samples: int = 1000, source: str = 'record'):
    """
    Offline estimate of a whole record with the live stream's rules.

    :meth:`StreamEstimator.run_record`. Returns (output times, deflection, stream) — the
    stream's ``counters`` say how many samples were rejected and how often it reset. Only
    samples with an estimate are returned: ``stream.kept`` marks them in the input.
    """
    stream = StreamEstimator(estimator, max_gap_s=max_gap_s,
                             max_block_samples=max(block_samples, 1), source=source)
    t, w, stream.kept = stream.run_record(time_s, current_a, block_samples=block_samples)
    return t, w, stream


def smooth_record(estimator: DeflectionEstimator, time_s, current_a, max_gap_s: float = 0.1):
    """
    Offline smoothed estimate of the samples a stream kept: (times, deflection, std).

    The record is cut where the live stream would reset (time stepping back, or a gap longer
    than ``max_gap_s``); each piece is smoothed from a fresh start
    (:meth:`DeflectionEstimator.smooth`), its missing samples bridged (``steps`` from the
    stamps at ``estimator.sample_rate_hz``).
    """
    t = np.asarray(time_s, float)
    i = np.asarray(current_a, float)
    dt = np.diff(t)
    cuts = np.flatnonzero(~((dt > 0.0) & (dt <= max_gap_s))) + 1
    steps = np.ones(t.size, dtype=np.int64)
    steps[1:] = np.maximum(1, np.rint(dt * estimator.sample_rate_hz)).astype(np.int64)
    out = [estimator.smooth(t[a:b], i[a:b], steps[a:b])
           for a, b in zip([0, *cuts], [*cuts, t.size]) if b > a]
    if not out:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    return tuple(np.concatenate(p) for p in zip(*out))
