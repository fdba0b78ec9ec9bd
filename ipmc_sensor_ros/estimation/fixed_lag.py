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

What the filter's model changes under it (a mains line measured, a new design) ends the
record: what it holds is smoothed with the data there is and goes out (:meth:`flush`), as at
a reset.  With a lag longer than the record, the result is the fixed-interval smoother's.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import ParameterError
from .core import Estimate
from .filter import ForwardRecord, KalmanFilter
from .smoother import rts_backward

__all__ = ['FixedLagSmoother', 'MAX_LAG_SAMPLES', 'lag_smoother']

#: Longest lag, samples: 2 x 20000 covariances of a 15-state model are ~70 MB.
MAX_LAG_SAMPLES = 20_000


class FixedLagSmoother:
    """
    Smooth the live filter's output with a lag of ``lag_samples`` (module docstring).

    Feed it each forward record the filter filled (:meth:`push`); it returns what is ready.
    """

    def __init__(self, lag_samples: int):
        self.lag = int(lag_samples)
        self._parts: list[ForwardRecord] = []
        self._held = 0

    def push(self, filt: KalmanFilter, record: ForwardRecord) -> Estimate | None:
        """
        Add the forward record of the samples just filtered; return those now smoothed.

        The backward passes run at fixed sample counts (each time 2 L are held), so the
        result does not depend on how the stream was cut into blocks.
        """
        out = []
        a, n = 0, record.x_post.shape[0]
        while a < n:
            b = min(n, a + 2 * self.lag - self._held)
            self._parts.append(record if (a, b) == (0, n) else record.rows(a, b))
            self._held += b - a
            a = b
            if self._held == 2 * self.lag:
                out.append(self._emit(filt, keep=self.lag))
        if not out:
            return None
        return out[0] if len(out) == 1 else Estimate(*(np.concatenate(p) for p in zip(*out)))

    def flush(self, filt: KalmanFilter) -> Estimate | None:
        """Smooth everything held with the data there is (a reset, a new model, the end)."""
        return self._emit(filt, keep=0) if self._held else None

    def _emit(self, filt: KalmanFilter, keep: int) -> Estimate:
        rec = self._parts[0] if len(self._parts) == 1 else ForwardRecord(
            *(np.concatenate(arrays) for arrays in zip(*(
                (p.x_pred, p.P_pred, p.x_post, p.P_post, p.steps, p.still)
                for p in self._parts))))
        xs, pw, _ = rts_backward(filt, rec, None)
        n_out = rec.x_post.shape[0] - keep
        m = filt.model
        scale = float(m.scale[m.iw])
        out = Estimate(xs[:n_out, m.iw] * scale, np.sqrt(np.maximum(pw[:n_out], 0.0)) * scale,
                       rec.still[:n_out].copy())
        self._parts = [rec.rows(n_out, n_out + keep)] if keep else []
        self._held = keep
        return out


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
