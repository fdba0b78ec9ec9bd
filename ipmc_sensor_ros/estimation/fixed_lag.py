# SPDX-License-Identifier: Apache-2.0
"""
Fixed-lag smoothing of the live filter: the deflection ``smoothed_lag_s`` after the fact.

The Rauch-Tung-Striebel backward pass of :mod:`.smoother`, run over the live filter's own
forward record (its predictions and updates, kept per sample while the option is on).  With a
lag of L samples, the record is kept until it holds 2 L samples; then one backward pass from
the newest sample smooths them all and the oldest L go out, each smoothed with at least L and
at most 2 L - 1 later samples.  So a consumer that can wait
receives each sample between ``smoothed_lag_s`` and twice that after it was measured,
smoothed with at least ``smoothed_lag_s`` of the data after it; the cost is two backward steps
per sample, and the memory 2 L of the filter's covariances.

A model change under the filter (a mains line measured; a periodic model, which takes over
from the start of its span and filters its samples again, :mod:`.periodic`) starts a new
part of the record: the samples held from the span are held again with the new model's
forward record (:meth:`replace_newest`), and the backward pass goes from one model's part
into the one before through the carry (:func:`~.smoother.across`), as the offline smoother
does (:meth:`~.kalman.KalmanEstimator.smooth`).  With a lag longer than the record, the
result is the fixed-interval smoother's.  A reset or a new design ends the record: what is
held is smoothed with the data there is and goes out (:meth:`flush`); :meth:`pop` returns
what is ready.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError
from .core import Estimate
from .filter import ForwardRecord, KalmanFilter, astuple_shallow
from .smoother import across, first_of, rts_backward

__all__ = ['FixedLagSmoother', 'MAX_LAG_SAMPLES', 'lag_smoother']

#: Longest lag, samples: 2 x 20000 covariances of a 15-state model are ~70 MB.
MAX_LAG_SAMPLES = 20_000


@dataclass
class _Part:
    """
    Forward record of one model's samples.

    ``link``: (the state it started from, carry_back) when it began at a model change whose
    samples before are held too.
    """

    filt: KalmanFilter
    rec: ForwardRecord
    link: tuple | None = None


class FixedLagSmoother:
    """
    Smooth the live filter's output with a lag of ``lag_samples`` (module docstring).

    Feed it each forward record the filter filled (:meth:`push`); it returns what is ready.
    """

    def __init__(self, lag_samples: int):
        self.lag = int(lag_samples)
        self._parts: list[_Part] = []
        self._held = 0
        self._link = None
        self._ready: list[Estimate] = []

    @property
    def held(self) -> int:
        """Return how many samples are held for their lag."""
        return self._held

    def begin(self, link: tuple) -> None:
        """Mark the next record as a new model's: (the state it starts from, carry_back)."""
        self._link = link if self._held else None

    def push(self, filt: KalmanFilter, record: ForwardRecord) -> None:
        """
        Add the forward record of the samples just filtered; what is smoothed is kept.

        The backward passes run at fixed sample counts (each time 2 L are held), so the
        result does not depend on how the stream was cut into blocks.
        """
        a, n = 0, record.x_post.shape[0]
        while a < n:
            b = min(n, a + 2 * self.lag - self._held)
            rec = record if (a, b) == (0, n) else record.rows(a, b)
            self._parts.append(_Part(filt, rec, self._link))
            self._link = None
            self._held += b - a
            a = b
            if self._held == 2 * self.lag:
                self._ready.append(self._emit(keep=self.lag))

    def flush(self) -> None:
        """Smooth everything held with the data there is (a reset, a new design, the end)."""
        self._link = None
        if self._held:
            self._ready.append(self._emit(keep=0))

    def pop(self, flush: bool = False) -> Estimate | None:
        """
        Return the estimates smoothed since the last call, oldest first (None: none).

        One per sample filtered, in order, each exactly once.  ``flush``: also those held for
        their lag, smoothed with the data there is (:meth:`flush`).
        """
        if flush:
            self.flush()
        parts, self._ready = [p for p in self._ready if p.deflection_m.size], []
        if len(parts) < 2:
            return parts[0] if parts else None
        return Estimate(*(np.concatenate(p) for p in zip(*parts)))

    def replace_newest(self, filt: KalmanFilter, record: ForwardRecord, link) -> None:
        """
        Hold the newest ``len(record)`` samples again, filtered under ``filt`` (``record``).

        ``link``: as :meth:`begin`, for the new model's start at the first of them.
        """
        n = record.x_post.shape[0]
        if not 0 < n <= self._held:
            raise RuntimeError(f'{n} samples to replace, {self._held} held')
        self._cut(0, self._held - n)
        self.begin(link)
        self.push(filt, record)             # fewer than 2 L held: nothing is due

    def _cut(self, start: int, stop: int) -> None:
        """Keep the held samples ``start`` to ``stop``; a part cut at its start loses its link."""
        parts, a = [], 0
        for p in self._parts:
            n = p.rec.x_post.shape[0]
            lo, hi = max(start - a, 0), min(stop - a, n)
            if lo < hi:
                link = p.link if lo == 0 and a >= start and parts else None
                parts.append(_Part(p.filt, p.rec if (lo, hi) == (0, n) else p.rec.rows(lo, hi),
                                   link))
            a += n
        self._parts, self._held = parts, stop - start

    def _emit(self, keep: int) -> Estimate:
        """Smooth everything held, back through each model change; the oldest go out."""
        segments: list[list] = []
        for p in self._parts:
            if p.link is not None or not segments or p.filt is not segments[-1][0]:
                segments.append([p.filt, [p.rec], p.link])
            else:
                segments[-1][1].append(p.rec)
        outs, end = [], None
        for filt, recs, link in reversed(segments):
            rec = recs[0] if len(recs) == 1 else ForwardRecord(
                *(np.concatenate(arrays) for arrays in zip(*map(astuple_shallow, recs))))
            w, pw, (x_first, P_first) = rts_backward(filt, rec, end)
            outs.append((w, np.sqrt(np.maximum(pw, 0.0)), rec.still))
            end = None if link is None else across(filt, link[0],
                                                   first_of(rec, x_first, P_first), link[1])
        n_out = self._held - keep
        w, std, still = (np.concatenate(p[::-1]) for p in zip(*outs))
        self._cut(n_out, self._held)
        return Estimate(w[:n_out], std[:n_out], still[:n_out].copy())


def lag_smoother(lag_s: float, sample_rate_hz: float) -> FixedLagSmoother | None:
    """Return the fixed-lag smoother of ``smoothed_lag_s`` (None: 0), checked."""
    if not (math.isfinite(lag_s) and lag_s >= 0.0):
        raise ParameterError(f"parameter 'smoothed_lag_s' must be >= 0 s, got {lag_s!r}")
    if lag_s == 0.0:
        return None
    n = max(1, int(round(lag_s * sample_rate_hz)))
    if n > MAX_LAG_SAMPLES:
        raise ParameterError(f"parameter 'smoothed_lag_s' = {lag_s:g} s is {n} samples at "
                             f'{sample_rate_hz:g} Hz; at most {MAX_LAG_SAMPLES} (the memory of '
                             'its covariances)')
    return FixedLagSmoother(n)
