# SPDX-License-Identifier: Apache-2.0
"""
Sensor arrays: N sensing currents sampled together, one :class:`StreamEstimator` per channel.

A block of an array carries one time column and one current column per channel
(:func:`~ipmc_sensor_ros.interface.blocks.current_columns`). :class:`ArrayStream` feeds each column
with the shared times to its own :class:`~ipmc_sensor_ros.estimation.stream.StreamEstimator`, so
every time, value, gap and reset rule is the one of a single sensor (it lives in ``stream.py``
only) and each channel's output is bit-identical to a single-sensor run on the same data.
Accounting is per channel: each channel keeps the counters of
:data:`~ipmc_sensor_ros.estimation.stream.COUNTER_NAMES` with their invariants; a bad value in one
channel (NaN, ``|i| > 1 A``) refuses that channel's sample only, while a bad stamp refuses the
sample in every channel and a message that cannot be read is refused whole (every channel
counts them). An output row carries NaN in a channel that has no estimate for it.
:meth:`ArrayStream.totals` sums the channels.
"""
from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from ..errors import ParameterError
from .deflection import DeflectionEstimator
from .stream import COUNTER_NAMES, MAX_BLOCK_SAMPLES, StreamEstimator

__all__ = ['ArrayStream', 'check_array_estimators']


def check_array_estimators(estimators: Sequence[DeflectionEstimator],
                           where: str = 'model_files') -> None:
    """
    Refuse channel estimators that cannot share one block's time column.

    The channels must have one sample rate and one output delay (a ``time_delay`` effect shifts
    the output times; one time column cannot hold two shifts).  Raises
    :class:`~ipmc_sensor_ros.errors.ParameterError` naming ``where`` and the channel.
    """
    if not estimators:
        raise ParameterError(f'{where}: a sensor array needs at least one channel')
    fs0, d0 = estimators[0].sample_rate_hz, estimators[0].delay_s
    for c, est in enumerate(estimators[1:], start=1):
        if est.sample_rate_hz != fs0:
            raise ParameterError(f'{where}: channel {c} samples at {est.sample_rate_hz} Hz, '
                                 f'channel 0 at {fs0} Hz')
        if est.delay_s != d0:
            raise ParameterError(f'{where}: channel {c} has an output delay of {est.delay_s} s, '
                                 f'channel 0 of {d0} s: one block has one time column')


class ArrayStream:
    """
    N channels of sensing current in, N deflections out (module docstring).

    Parameters
    ----------
    estimators : sequence of DeflectionEstimator
        One per channel (:func:`check_array_estimators`).
    max_gap_s, max_block_samples, now_s, warn, rate_tolerance
        As for :class:`StreamEstimator` (shared by the channels).
    source : str
        Topic or file; channel ``c`` is named ``"<source> ch<c>"`` in its messages.

    """

    def __init__(self, estimators: Sequence[DeflectionEstimator], *, max_gap_s: float = 0.1,
                 max_block_samples: int = MAX_BLOCK_SAMPLES, source: str = 'current',
                 now_s: Callable[[], float] | None = None,
                 warn: Callable[[str], None] | None = None, rate_tolerance: float = 0.05):
        check_array_estimators(estimators)
        self.source = source
        self.channels = [StreamEstimator(e, max_gap_s=max_gap_s,
                                         max_block_samples=max_block_samples,
                                         source=f'{source} ch{c}', now_s=now_s, warn=warn,
                                         rate_tolerance=rate_tolerance)
                         for c, e in enumerate(estimators)]

    def __len__(self) -> int:
        return len(self.channels)

    @property
    def sample_rate_hz(self) -> float:
        return self.channels[0].sample_rate_hz

    @property
    def max_gap_s(self) -> float:
        return self.channels[0].max_gap_s

    @max_gap_s.setter
    def max_gap_s(self, value: float) -> None:
        for ch in self.channels:
            ch.max_gap_s = float(value)

    def replace_estimators(self, estimators: Sequence[DeflectionEstimator]) -> None:
        """Swap in new estimators (parameter change), each continuing from its channel's."""
        check_array_estimators(estimators)
        if len(estimators) != len(self.channels):
            raise ParameterError(f'{len(estimators)} estimators for {len(self.channels)} '
                                 'channels')
        for ch, new in zip(self.channels, estimators):
            ch.replace_estimator(new)

    def restart(self) -> None:
        """Begin a new stream in every channel (:meth:`StreamEstimator.restart`)."""
        for ch in self.channels:
            ch.restart()

    # -- accounting -------------------------------------------------------------------
    def counters(self) -> list[dict[str, int]]:
        """Return copies of the per-channel counters."""
        return [dict(ch.counters) for ch in self.channels]

    def totals(self) -> dict[str, int]:
        """Each counter summed over the channels (``messages_*`` count channel-messages)."""
        return {k: sum(ch.counters[k] for ch in self.channels) for k in COUNTER_NAMES}

    def check_invariant(self) -> bool:
        """Tell whether the stream invariant holds in every channel."""
        return all(ch.check_invariant() for ch in self.channels)

    def reject(self, n_samples: int, reason: str) -> None:
        """Count a message that cannot be read: ``n_samples`` rejected in every channel."""
        for ch in self.channels:
            ch.reject(n_samples, reason)

    def count(self, name: str, n: int = 1, text: str = '') -> None:
        """Count a source event in every channel (:meth:`StreamEstimator.count`)."""
        for k, ch in enumerate(self.channels):
            ch.count(name, n, text if k == 0 else '')

    def unpublished(self, n_samples: int, reason: str, has_estimate: Sequence[bool]) -> None:
        """
        Count an output block that could not be delivered.

        Moves the channels' estimates to ``samples_unpublished``
        (:meth:`StreamEstimator.unpublished`).
        """
        for ch, ok in zip(self.channels, has_estimate):
            if ok:
                ch.unpublished(n_samples, reason)

    # -- data path ----------------------------------------------------------------------
    def feed(self, times, currents, claimed: int | None = None):
        """
        Estimate one block of every channel.

        Parameters
        ----------
        times : array_like or None
            Shared sample times, s (``None``: continue the stream at ``1/fs``).
        currents : array_like, shape (n, channels)
            Sensing currents, A, one column per channel.
        claimed : int, optional
            Samples (rows) the message claims.

        Returns
        -------
        ``(time_s, deflection_m, std_m, has_estimate)``: arrays of shape (n,), (n, channels),
        (n, channels) and (channels,) bool — a channel without an estimate (its samples
        rejected or dropped, counted in that channel) is NaN; ``None`` when no channel has one.

        """
        table = np.asarray(currents, dtype=float)
        if table.ndim != 2 or table.shape[1] != len(self.channels):
            n = claimed if claimed is not None else int(table.shape[0]) if table.ndim else 1
            self.reject(n, f'current block has shape {table.shape}, expected (n, '
                           f'{len(self.channels)}): one column per channel')
            return None
        n = table.shape[0]
        if n == 1 and times is not None and claimed in (None, 1):   # the one-sample path
            return self.feed_one(float(np.asarray(times, dtype=float).ravel()[0]),
                                 table[0].tolist())
        k = len(self.channels)
        t_all = np.full(n, np.nan)
        w = np.full((n, k), np.nan)
        std = np.full_like(w, np.nan)
        has = np.zeros(k, dtype=bool)
        rows = np.zeros(n, dtype=bool)
        for c, ch in enumerate(self.channels):
            out = ch.feed(times, table[:, c], claimed=claimed)
            if out is None:
                continue
            mask = ch.accepted
            t_all[mask], w[mask, c] = out
            std[mask, c] = ch.estimator.std_m
            has[c] = True
            rows |= mask
        if not has.any():
            return None
        return t_all[rows], w[rows], std[rows], has

    def feed_one(self, time_s: float, currents: Sequence[float]):
        """
        One timed sample of every channel: as :meth:`feed` with ``n = 1``.

        Each channel takes :meth:`StreamEstimator.feed_one`.
        """
        k = len(self.channels)
        if len(currents) != k:
            return self.feed(np.array([time_s]), np.asarray(currents, dtype=float)[None, :],
                             claimed=1)
        w = np.full((1, k), np.nan)
        std = np.full_like(w, np.nan)
        has = np.zeros(k, dtype=bool)
        t_out = None
        for c, (ch, i) in enumerate(zip(self.channels, currents)):
            out = ch.feed_one(time_s, float(i))
            if out is None:
                continue
            t_out, w[0, c] = out
            std[0, c] = ch.estimator.std_m
            has[c] = True
        if t_out is None:
            return None
        return np.array([t_out]), w, std, has
