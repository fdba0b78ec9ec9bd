# SPDX-License-Identifier: Apache-2.0
"""
The one interface of an estimator core: current samples in, deflection and its std out.

:class:`~ipmc_sensor_ros.estimation.deflection.DeflectionEstimator` (what the node and
``ipmc-model estimate`` run) wraps a core and the model's effects around it; it never asks
which core it holds.  Two cores implement :class:`EstimatorCore`:

* ``kalman`` (:class:`~.kalman.KalmanEstimator`, the default): the state-space model of
  :mod:`.statespace`, its filter (:mod:`.filter`) and smoother (:mod:`.smoother`);
* ``leaky`` (:class:`~.inverse.InverseEstimator`): the leaky inverse, the simple baseline
  (no uncertainty: its std is NaN; no rest, offset or hum model).
"""
from __future__ import annotations

import math
from typing import Any, NamedTuple, Protocol, runtime_checkable

import numpy as np

__all__ = ['Estimate', 'EstimatorCore', 'ESTIMATORS', 'forgets_s']

#: Names of the cores (node parameter ``estimator``, CLI ``--estimator``).
ESTIMATORS = ('kalman', 'leaky')


def forgets_s(corner_hz: float) -> float:
    """
    Return how long a first-order corner at ``corner_hz`` takes to forget a level, s.

    Five time constants (e^-5, below 1 %): the settling a core reports
    (:meth:`EstimatorCore.settling`).
    """
    return 5.0 / (2.0 * math.pi * corner_hz)


class Estimate(NamedTuple):
    """Per-sample output of a core: deflection (m), its standard deviation (m), at rest."""

    deflection_m: np.ndarray
    std_m: np.ndarray
    still: np.ndarray


@runtime_checkable
class EstimatorCore(Protocol):
    """What :class:`~ipmc_sensor_ros.estimation.deflection.DeflectionEstimator` needs."""

    name: str

    @property
    def sample_rate_hz(self) -> float: ...

    @property
    def mean_corner_hz(self) -> float:
        """Corner of the running mean of a nonlinear sensor's T(w) - w while moving, Hz."""

    def estimate(self, current_a: np.ndarray, steps: np.ndarray | None = None) -> Estimate:
        """Filter a block; ``steps[k]`` sample periods since the sample before (None: 1)."""

    def estimate_one(self, current_a: float, steps: int = 1) -> tuple[float, float]:
        """One sample: (deflection, std), the same recursion as :meth:`estimate`."""

    def smooth(self, current_a: np.ndarray, steps: np.ndarray | None = None) -> Estimate:
        """Offline estimate of a whole record from a fresh start (non-causal where it can)."""

    def pop_smoothed(self, flush: bool = False) -> Estimate | None:
        """Return the fixed-lag smoothed estimates ready since the last call (None: none)."""

    def reset(self) -> None:
        """Start afresh (the state of a new stream)."""

    def get_state(self) -> Any:
        """Return the whole state (restorable with :meth:`set_state`)."""

    def set_state(self, state: Any) -> None:
        """Restore a state from :meth:`get_state`."""

    def rebuilt(self, reduced, recent_input=None, **changes) -> 'EstimatorCore':
        """Return a core for a new design whose output continues from this one's."""

    def status(self) -> dict:
        """Return the JSON-able state for counters and diagnostics."""

    def settling(self) -> tuple[float, str]:
        """Return (seconds since the start, why) before the estimate is comparable."""
