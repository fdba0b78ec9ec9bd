# SPDX-License-Identifier: Apache-2.0
"""
Two pieces of :class:`~.deflection.DeflectionEstimator` that act on the core's output.

* :class:`InputInverse`: the model's input transforms T (e.g. ``nonlinearity``) undone on
  the core's deflection, with the running mean m = <T(w) - w> the sensor cannot see
  (H(0) = 0) added back while the tip moves (module docstring of :mod:`.deflection`);
* :class:`LagOutput`: the output times of the samples the core holds for its smoothing lag
  (``smoothed_lag_s``), and what it has smoothed since last asked.
"""
from __future__ import annotations

from collections import deque

import numpy as np
from scipy.signal import lfilter

from .core import Estimate

__all__ = ['InputInverse', 'LagOutput']


class InputInverse:
    """The input transforms ``(effect, values)`` of ``model`` undone, with m (module doc)."""

    def __init__(self, transforms, model):
        self.transforms = transforms
        self.model = model
        self.reset()

    def __bool__(self) -> bool:
        return bool(self.transforms)

    def reset(self) -> None:
        self.bias_m = 0.0
        self._zi = np.zeros(1)

    def apply(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return (w + m, the input transforms undone on it)."""
        w_prime = w + self.bias_m
        w = w_prime
        for eff, values in reversed(self.transforms):
            w = np.asarray(eff.inverse_input_transform(w, self.model, values), dtype=float)
        return w_prime, w

    def undo(self, est: Estimate, corner_hz: float, sample_rate_hz: float) -> np.ndarray:
        """Return the deflection with T undone; m follows at ``corner_hz`` while moving."""
        w = est.deflection_m
        if not self.transforms:
            return w
        w_prime, w = self.apply(w)
        gap = (w_prime - w)[~est.still]
        a = float(np.exp(-2 * np.pi * corner_hz / sample_rate_hz))
        if gap.size:
            avg, self._zi = lfilter([1 - a], [1, -a], gap, zi=self._zi)
            self.bias_m = float(avg[-1])
        return w


class LagOutput:
    """Output times of the samples held for the lag; the smoothed parts not yet popped."""

    def __init__(self):
        self.times: deque = deque()
        self._parts: list[tuple] = []

    def collect(self, est: Estimate | None, inverse: InputInverse) -> None:
        """Take the core's smoothed samples ``est`` (None: none) with their output times."""
        if est is None:
            return
        times = np.array([self.times.popleft() for _ in range(est.deflection_m.size)])
        w = inverse.apply(est.deflection_m)[1] if inverse else est.deflection_m
        self._parts.append((times, w, est.std_m))

    def pop(self):
        """Return (output times, deflection, std) collected since last asked, or None."""
        if not self._parts:
            return None
        parts, self._parts = self._parts, []
        return parts[0] if len(parts) == 1 else tuple(np.concatenate(p) for p in zip(*parts))
