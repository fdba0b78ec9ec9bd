# SPDX-License-Identifier: Apache-2.0
"""
The accounts of a stream: counters, their invariants, refusal reasons, and the value rules.

:class:`StreamAccounts` is the bookkeeping half of
:class:`~ipmc_sensor_ros.estimation.stream.StreamEstimator`: every sample that reaches a stream
is counted once as estimated (``samples_out``), refused (``samples_rejected``, and once in
``rejected_<reason>`` for its reason in :data:`REJECT_REASONS`), dropped (a non-finite estimate)
or estimated but not delivered (``samples_unpublished``)::

    samples_in == samples_out + samples_rejected + samples_dropped + samples_unpublished
    samples_rejected == sum of rejected_<reason>

Beside them: ``resets`` (``gaps`` longer than ``max_gap_s`` and jumps back among them),
``gaps_bridged`` and ``samples_lost`` (grid slots no sample arrived for: a refused sample fills
its slot in this count), ``rate_rebuilds``, and the source events the node counts here:
``messages_lost`` (sequence numbers), ``messages_lost_reported`` (the middleware's event),
``messages_ignored`` (other publishers), ``source_switches``.  ``messages_*`` count messages:
``messages_rejected`` those of which no sample was estimated.
"""
from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from ..errors import DataError
from .timebase import MAX_STAMP_S, REFUSAL_NAMES, Timebase

__all__ = ['StreamAccounts', 'validate_block', 'as_current_block', 'COUNTER_NAMES',
           'REJECT_REASONS', 'MAX_ABS_CURRENT_A', 'MAX_BLOCK_SAMPLES', 'record_summary']

#: Largest block accepted by default (samples).
MAX_BLOCK_SAMPLES = 1_000_000

#: Largest plausible sensing current, A (IPMC currents are nA..uA; 1 A means a wiring or
#: unit error).
MAX_ABS_CURRENT_A = 1.0

#: Why samples are refused; each has a counter ``rejected_<reason>``.
REJECT_REASONS = ('duplicate_stamp', 'stamp_behind', 'stamp_too_close', 'non_finite',
                  'out_of_range', 'malformed', 'too_long')

#: Counters kept per stream; see the module docstring for the invariants.
COUNTER_NAMES = ('messages_in', 'samples_in', 'samples_out', 'samples_rejected',
                 'messages_rejected', 'samples_dropped', 'samples_unpublished',
                 'messages_unpublished', 'resets', 'gaps', 'gaps_bridged', 'samples_lost',
                 'rate_rebuilds', 'messages_lost', 'messages_lost_reported',
                 'messages_ignored', 'source_switches') + tuple(
                     f'rejected_{r}' for r in REJECT_REASONS)

_WHY = {'duplicate_stamp': 'the same stamp as the previous sample',
        'stamp_behind': 'behind the previous sample',
        'stamp_too_close': 'on the grid slot of the previous sample',
        'non_finite': 'non-finite stamp or current',
        'out_of_range': f'stamps must lie in [0, {MAX_STAMP_S:.0f}] s and currents within '
                        f'+-{MAX_ABS_CURRENT_A} A'}


def validate_block(values, max_samples: int = MAX_BLOCK_SAMPLES,
                   max_abs_current_a: float = MAX_ABS_CURRENT_A) -> np.ndarray:
    """
    Check a whole block of current samples (offline tools that refuse a file as a whole).

    Returns a float64 1-D array, or raises :class:`~ipmc_sensor_ros.errors.DataError` saying why
    (empty, too long, non-finite or implausibly large values).  The stream itself refuses
    such values one sample at a time.
    """
    x = as_current_block(values, max_samples)
    if float(np.max(np.abs(x))) <= max_abs_current_a:   # one pass; NaN makes it False
        return x
    finite = np.isfinite(x)
    if not finite.all():
        first = int(np.argmin(finite))
        raise DataError(f'current block has {int((~finite).sum())} non-finite sample(s) '
                        f'(first at index {first})', index=first)
    k = int(np.argmax(np.abs(x) > max_abs_current_a))
    raise DataError(f'current block has |i| > {max_abs_current_a} A at index {k} '
                    f'({float(x[k])!r} A): not a sensing current', index=k)


def as_current_block(values, max_samples: int) -> np.ndarray:
    """Return ``values`` as a float64 1-D array of 1..max_samples; DataError saying why not."""
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
    return x


def record_summary(counters: dict) -> tuple[dict, str]:
    """
    Return what became of a record's rows: a JSON-able dict and one line of text.

    Rows given, estimated, refused (with the count per reason) and dropped (the estimator
    gave none: ``last_fault``), slots lost in the stamps and filter resets, from a stream's
    :data:`COUNTER_NAMES` counters.
    """
    by_reason = {r: counters[f'rejected_{r}'] for r in REJECT_REASONS if counters[f'rejected_{r}']}
    out = {'rows_given': counters['samples_in'], 'rows_estimated': counters['samples_out'],
           'rows_refused': counters['samples_rejected'], 'refused_by_reason': by_reason,
           'rows_dropped': counters['samples_dropped'], 'samples_lost': counters['samples_lost'],
           'resets': counters['resets']}
    why = ', '.join(f'{n} {r.replace("_", " ")}' for r, n in by_reason.items())
    text = (f"{out['rows_given']} rows, {out['rows_estimated']} estimated, "
            f"{out['rows_refused']} refused" + (f' ({why})' if why else '')
            + (f", {out['samples_lost']} missing in the stamps (bridged)"
               if out['samples_lost'] else '')
            + (f", {out['rows_dropped']} dropped with a filter reset (no finite estimate)"
               if out['rows_dropped'] else ''))
    return out, text


def _no_log(text: str) -> None:
    return None


class StreamAccounts:
    """
    Counters of one stream and the events that change them (module docstring).

    Parameters
    ----------
    source : str
        Where the samples come from (topic or file), named in every message.
    warn : callable, optional
        Receives the text of every reset, refusal and rate report (the node logs it).

    """

    timebase: Timebase
    estimator: Any          # the filter (reset when its samples are dropped)

    def __init__(self, source: str, warn: Callable[[str], None] | None = None):
        self.source = source
        self._warn = warn or _no_log
        self.counters: dict[str, int] = dict.fromkeys(COUNTER_NAMES, 0)
        self.last_rejection = ''
        self.last_warning = ''
        self.last_fault = ''                        # the last estimator fault said ('' none)
        self._refused_since = 0                     # refusals since the last accepted sample
        self._said: dict[str, int] = {}             # events of each kind said or not
        self._say_next: dict[str, int] = {}         # count at which a kind is said next

    def check_invariant(self) -> bool:
        """Tell whether the invariants of the module docstring hold."""
        c = self.counters
        return (c['samples_in'] == c['samples_out'] + c['samples_rejected']
                + c['samples_dropped'] + c['samples_unpublished']
                and c['samples_rejected'] == sum(c[f'rejected_{r}'] for r in REJECT_REASONS))

    def _say(self, text: str, kind: str = '') -> None:
        """
        Say ``text`` (``last_warning``, and the ``warn`` callback).

        An event of a ``kind`` that can repeat at the sample rate (a refusal reason, a reset,
        a loss) is passed on at its 1st, 10th, 100th, ... occurrence, with its count: a log
        bounded by the logarithm of the events, and no event of another kind hidden by it.
        """
        self.last_warning = text
        if kind:
            n = self._said[kind] = self._said.get(kind, 0) + 1
            if n < self._say_next.get(kind, 1):
                return
            self._say_next[kind] = 10 * n
            if n > 1:
                text = f'{text} [{n} so far]'
        self._warn(text)

    def reject(self, n_samples: int, reason: str, kind: str = 'malformed') -> None:
        """Count a message of ``n_samples`` claimed samples as received and refused whole."""
        c = self.counters
        c['messages_in'] += 1
        c['samples_in'] += n_samples
        c['messages_rejected'] += 1
        c['samples_rejected'] += n_samples
        c[f'rejected_{kind}'] += n_samples
        self.last_rejection = reason
        self._say(f'rejected message on {self.source} ({n_samples} sample(s)): {reason}', kind)

    def unpublished(self, n_samples: int, reason: str) -> None:
        """
        Move ``n_samples`` just counted as ``samples_out`` to ``samples_unpublished``.

        The estimate exists (the filter ran) but could not be delivered. No reset.
        """
        c = self.counters
        c['samples_out'] -= n_samples
        c['samples_unpublished'] += n_samples
        c['messages_unpublished'] += 1
        self._say(f'could not publish {n_samples} estimate(s) from {self.source}: {reason}',
                  'unpublished')

    def count(self, name: str, n: int = 1, text: str = '') -> None:
        """Add ``n`` to counter ``name`` (source events: ignored, lost, switches); say ``text``."""
        self.counters[name] += n
        if text:
            self._say(text, name if name != 'source_switches' else '')

    def _refuse(self, code: int, t: float, i: float) -> None:
        reason = REFUSAL_NAMES[code]
        c = self.counters
        c['samples_rejected'] += 1
        c[f'rejected_{reason}'] += 1
        self._refused_since += 1
        last = self.timebase.last_s
        where = '' if last is None else f' (previous sample at {last!r} s)'
        self.last_rejection = f'sample at {t!r} s, {i!r} A: {_WHY[reason]}{where}'
        self._say(f'refused a sample on {self.source}: {self.last_rejection}', reason)

    def _begin_run(self) -> None:
        """Count and say why a run began (a long gap, a jump back); the first is not counted."""
        tb = self.timebase
        if tb.break_kind == 'gap':
            self.counters['gaps'] += 1
            text = (f'gap of {tb.break_s:.6g} s (> max_gap_s = {tb.max_gap_s:g} s) on '
                    f'{self.source}: filter reset')
        elif tb.break_kind == 'back':
            text = (f'time jumped back by {tb.break_s:.6g} s on {self.source}: filter reset '
                    f'(a new run: more than max_gap_s = {tb.max_gap_s:g} s back)')
        else:
            return
        self.counters['resets'] += 1
        self._say(text, tb.break_kind)

    def _bridged(self, steps: int, refused: int) -> None:
        """Count a bridged gap of ``steps`` periods; slots no refused sample explains are lost."""
        c = self.counters
        c['gaps_bridged'] += 1
        lost = steps - 1 - refused
        if lost > 0:
            c['samples_lost'] += lost

    def _recount(self, timebase: Timebase) -> None:
        """Take off the slots and gaps a re-lock found were no lost samples."""
        lost, gaps = timebase.recounted
        c = self.counters
        c['samples_lost'] = max(c['samples_lost'] - lost, 0)
        c['gaps_bridged'] = max(c['gaps_bridged'] - gaps, 0)
        timebase.recounted = (0, 0)

    def _drop(self, n: int, why: str = 'non-finite estimate') -> None:
        """Drop ``n`` samples the estimator gave no finite estimate of; reset the filter."""
        self.estimator.reset()
        self.counters['samples_dropped'] += n
        self.counters['resets'] += 1
        self._say(f'{why} on {self.source}: {n} sample(s) dropped, filter reset', 'dropped')

    def _estimated(self, run: Callable[[], tuple], n: int) -> tuple | None:
        """
        Return ``run()``, the estimator's (time, deflection) of ``n`` samples, or None.

        None: an estimate was not finite, or the estimator raised.  Either drops the samples
        and resets the filter, counted and said (with the exception: a defect to report,
        since input is refused before it reaches the estimator); a live node loses ``n``
        samples, not its estimator.
        """
        try:
            t_out, w = run()
        except Exception as exc:  # noqa: BLE001 - a defect: counted and said, never fatal
            self.last_fault = f'estimator fault ({type(exc).__name__}: {exc})'
            self._drop(n, self.last_fault)
            return None
        if not (math.isfinite(w) if isinstance(w, float) else np.all(np.isfinite(w))):
            self._drop(n)
            return None
        return t_out, w
