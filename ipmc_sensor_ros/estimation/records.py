# SPDX-License-Identifier: Apache-2.0
"""
Whole records offline with the live stream's rules: ``ipmc-model estimate``, bag replay, benches.

:func:`estimate_record` feeds a record to a :class:`~.stream.StreamEstimator` in blocks
(:func:`run_record`), so refusals, bridged gaps and new runs are decided exactly as live;
:func:`smooth_record` then smooths each run the stream began from a fresh start, with the
sample periods the stream handed the filter; a run whose smoothing raises (a defect) keeps
its live estimate, said through ``warn``.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from .deflection import DeflectionEstimator
from .stream import StreamEstimator
from .timebase import START

__all__ = ['run_record', 'estimate_record', 'smooth_record']


def run_record(stream: StreamEstimator, time_s, current_a, block_samples: int = 1000):
    """
    Feed a whole record (offline) to ``stream`` in blocks of ``block_samples``.

    Returns (output times, deflection, kept): ``kept`` marks the input samples that have
    an estimate (refused or dropped ones have none; see the stream's counters).  The rules
    are the live ones: a jump back by more than ``max_gap_s`` starts a new run, as a bag loop
    does live; a record that starts before 0 s is fed from 0 s (live stamps are >= 0).  Per
    kept sample it also keeps ``record_time_s``, ``record_deflection_m`` and ``record_std_m``
    (the published estimate and standard deviation) and ``record_steps`` (the sample periods
    handed to the filter: the slots since the sample before plus the stamp's offset from its
    slot; 0 where a new run began), which :func:`smooth_record` reuses.
    """
    t = np.asarray(time_s, float)
    i = np.asarray(current_a, float)
    # a record's time is its own: a pre-trigger's rows before 0 s (or host jitter on the first
    # stamp) are fed from 0 s, as live stamps are, and published at their own times
    shift = min(float(t[0]), 0.0) if t.size else 0.0
    kept = np.zeros(t.size, dtype=bool)
    out_t, out_w, out_s = np.empty(t.size), np.empty(t.size), np.empty(t.size)
    steps = np.empty(t.size)
    n_out = 0
    for k in range(0, t.size, block_samples):
        end = min(k + block_samples, t.size)
        res = stream.feed(t[k:end] - shift, i[k:end])
        if res is not None:
            m = res[0].size
            out_t[n_out:n_out + m] = t[k:end][stream.accepted] if shift else res[0]
            out_w[n_out:n_out + m] = res[1]
            out_s[n_out:n_out + m] = stream.last_std_m if stream.last_std_m.size == m else np.nan
            steps[n_out:n_out + m] = (stream.codes + stream.offsets)[stream.accepted]
            n_out += m
            kept[k:end] = stream.accepted
    stream.record_std_m, stream.record_steps = out_s[:n_out], steps[:n_out]
    stream.record_time_s, stream.record_deflection_m = out_t[:n_out], out_w[:n_out]
    return out_t[:n_out], out_w[:n_out], kept


def estimate_record(estimator: DeflectionEstimator, time_s, current_a, *, max_gap_s: float = 0.1,
                    block_samples: int = 1000, source: str = 'record'):
    """
    Offline estimate of a whole record with the live stream's rules.

    :func:`run_record`. Returns (output times, deflection, stream) — the
    stream's ``counters`` say how many samples were refused (per reason) and how often it
    reset. Only samples with an estimate are returned: ``stream.kept`` marks them in the input.
    """
    stream = StreamEstimator(estimator, max_gap_s=max_gap_s,
                             max_block_samples=max(block_samples, 1), source=source)
    t, w, stream.kept = run_record(stream, time_s, current_a, block_samples=block_samples)
    return t, w, stream


def smooth_record(estimator: DeflectionEstimator, stream: StreamEstimator, time_s, current_a,
                  warn: Callable[[str], None] | None = None):
    """
    Offline smoothed estimate of the samples ``stream`` kept: (times, deflection, std).

    ``stream`` ran the record (:func:`estimate_record`); its decisions are reused, not made
    again: each run it began is smoothed from a fresh start (:meth:`DeflectionEstimator.smooth`)
    with the sample periods it handed the filter (missing samples bridged).  A run whose
    smoothing raises keeps the stream's live estimate, and ``warn`` is told (the exception's
    text: a defect to report, as the stream's estimator fault): nothing is lost.
    """
    t = np.asarray(time_s, float)[stream.kept]
    i = np.asarray(current_a, float)[stream.kept]
    steps = stream.record_steps
    cuts = [int(k) for k in np.flatnonzero(steps == START) if k > 0]
    periods = np.where(steps == START, 1.0, steps)      # a run's first sample: on its slot
    out = [_smoothed_run(estimator, stream, t, i, periods, a, b, warn)
           for a, b in zip([0, *cuts], [*cuts, t.size]) if b > a]
    if not out:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    return tuple(np.concatenate(p) for p in zip(*out))


def _smoothed_run(estimator, stream, t, i, periods, a: int, b: int, warn) -> tuple:
    """Return the smoothed run of kept samples a..b-1, or its live estimate if smoothing fails."""
    try:
        return estimator.smooth(t[a:b], i[a:b], periods[a:b])
    except Exception as exc:  # noqa: BLE001 - a defect: said, the run's live estimate kept
        if warn is not None:
            warn(f'smoother fault ({type(exc).__name__}: {exc}) on {stream.source}, kept '
                 f'samples {a}..{b - 1}: their live (causal) estimate is given instead')
        return (stream.record_time_s[a:b], stream.record_deflection_m[a:b],
                stream.record_std_m[a:b])
