# SPDX-License-Identifier: Apache-2.0
"""
The last values of a stream (:class:`SampleRing`): a ring buffer.

The estimator keeps the current it was fed (to replay it into a rebuilt core) and the
Kalman estimator the current on its sample grid (for the line and motion checks); both are
this ring.  Value ``j`` of the stream (``j`` from 0) sits in slot ``j % size``, so a saved
buffer and count restore it exactly.
"""
from __future__ import annotations

import numpy as np

__all__ = ['SampleRing', 'on_grid', 'hold_next']


def on_grid(values, slots) -> np.ndarray:
    """
    Return ``values`` on the sample grid: each in the last of its ``slots``, NaN before it.

    A sample ``slots`` periods after the one before leaves ``slots - 1`` grid slots the DAQ
    did not deliver (a dropped row, a burst): those are NaN, not a value.
    """
    slots = np.asarray(slots, dtype=int)
    out = np.full(int(slots.sum()), np.nan)
    out[np.cumsum(slots) - 1] = values
    return out


def hold_next(values: np.ndarray) -> np.ndarray:
    """Return ``values`` with each NaN slot holding the next value (the newest is a value)."""
    missing = np.isnan(values)
    if not missing.any():
        return values
    nxt = np.where(missing, values.size - 1, np.arange(values.size))
    return values[np.minimum.accumulate(nxt[::-1])[::-1]]


class SampleRing:
    """The last ``size`` values fed (:meth:`extend`, :meth:`push`), oldest first on request."""

    __slots__ = ('buffer', 'count')

    def __init__(self, size: int, buffer: np.ndarray | None = None, count: int = 0):
        self.buffer = np.zeros(int(size)) if buffer is None else np.array(buffer, dtype=float)
        #: values fed since the start (or :meth:`clear`)
        self.count = int(count)

    @property
    def size(self) -> int:
        """Return how many values it holds at most."""
        return self.buffer.size

    def extend(self, values: np.ndarray) -> None:
        """Append ``values`` (the newest last)."""
        m = len(values)
        k = min(m, self.size)
        self.buffer[np.arange(self.count + m - k, self.count + m) % self.size] = values[m - k:]
        self.count += m

    def push(self, value: float) -> None:
        """Append one value."""
        self.buffer[self.count % self.size] = value
        self.count += 1

    def values(self) -> np.ndarray:
        """Return the values held, oldest first (at most ``size``)."""
        held = min(self.count, self.size)
        return np.roll(self.buffer, -(self.count % self.size))[self.size - held:]

    def clear(self) -> None:
        """Forget what was fed."""
        self.count = 0

    def copy(self) -> 'SampleRing':
        return SampleRing(self.size, self.buffer, self.count)
