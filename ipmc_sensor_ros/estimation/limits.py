# SPDX-License-Identifier: Apache-2.0
r"""
What a cantilever's tip can do: the deflection beyond which an estimate is not physical.

The rule
--------
An estimate is **beyond the limit** when

.. math:: |w| > w_{max} = L / 2                                             (1)

with L the free length of the sample (the node's ``length_m``, the model's geometry).
Why L/2: an inextensible beam's tip can never be farther than L from the clamp axis; a
beam bent to uniform curvature (an IPMC's own bending shape) reaches w = L/2 at a tip
rotation of 64 deg, (1 - cos theta) / theta = 1/2, far outside the small-deflection beam of
the model the estimate rests on (paper eq. 21: w'' = M / (E I), valid for rotations of a
few degrees) and beyond the strain an IPMC sensor survives repeatedly.  An estimate past
(1) therefore says the estimate is wrong (an offset or drift integrated, a wrong model or
geometry), not that the beam moved there.

Where the flag goes (one name everywhere: ``deflection_beyond_limit``)
-----------------------------------------------------------------------
* ``deflection/block`` and ``ipmc-estimate/1`` files: the estimate as computed, and the
  column ``deflection_beyond_limit``: 1.0 beyond (1), 0.0 within;
* ``deflection`` (``PointStamped``, which has no field for a flag): ``point.z`` is
  +inf / -inf beyond (1), the convention of REP 117 for a reading out of range;
* ``/diagnostics``: ERROR while the counter ``samples_beyond_limit`` rises
  (:mod:`ipmc_sensor_ros.interface.health`), with ``deflection_limit_m`` in its values.
"""
from __future__ import annotations

import numpy as np

__all__ = ['DEFLECTION_LIMIT_PER_LENGTH', 'deflection_limit_m', 'beyond_limit', 'LimitCheck']

#: w_max / L of eq. (1) (module docstring: a 64 deg tip rotation at uniform curvature).
DEFLECTION_LIMIT_PER_LENGTH = 0.5


def deflection_limit_m(length_m: float) -> float:
    """Return w_max of eq. (1) for a free length ``length_m`` (m), m."""
    return DEFLECTION_LIMIT_PER_LENGTH * float(length_m)


def beyond_limit(deflection_m, limit_m: float):
    """
    Return the flag of eq. (1): 1.0 where ``|deflection_m| > limit_m``, else 0.0.

    A float for a float (no numpy on the one-sample path), an array for an array.
    """
    if isinstance(deflection_m, float):
        return 0.0 if -limit_m <= deflection_m <= limit_m else 1.0
    w = np.asarray(deflection_m, dtype=float)
    # no estimate (a refused sample of an array: NaN) has no flag either
    return np.where(np.isnan(w), np.nan, (np.abs(w) > limit_m).astype(float))


class LimitCheck:
    """
    Flags estimates of one channel by eq. (1) and counts those beyond.

    The limit follows the estimator handed in (a parameter change may change L).
    """

    def __init__(self):
        self.count = 0          #: estimates beyond the limit (``samples_beyond_limit``)
        self.limit_m: float | None = None     #: w_max of the last estimator seen, m
        self._estimator = None

    def _follow(self, estimator) -> float:
        if estimator is not self._estimator:
            self._estimator = estimator
            self.limit_m = deflection_limit_m(estimator.model.geometry.length_m)
        return self.limit_m

    def flag_one(self, estimator, deflection_m: float) -> float:
        """Return the flag of one estimate (counted when beyond)."""
        flag = beyond_limit(deflection_m, self._follow(estimator))
        if flag:
            self.count += 1
        return flag

    def flags(self, estimator, deflection_m: np.ndarray) -> np.ndarray:
        """Return the flags of a block of estimates (those beyond counted)."""
        out = beyond_limit(deflection_m, self._follow(estimator))
        self.count += int(np.count_nonzero(out))
        return out
