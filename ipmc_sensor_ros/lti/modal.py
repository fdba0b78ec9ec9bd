# SPDX-License-Identifier: Apache-2.0
"""
The modal (diagonal) realisation of a reduced sensor model, R_n(s) = D + sum_i r_i / (s - p_i).

The reduced model (:mod:`.reduction`: H_n(s) = s R_n(s), eq. 45 (H2) or eq. 31 (H1) fitted by
real poles and zeros, R_n in A s/m) is kept as zeros, poles and a gain; the estimator's state
space (:mod:`~ipmc_sensor_ros.estimation.statespace`) takes it as first-order lags of the tip
velocity, one per pole, whose residues weigh them into the current.
"""
from __future__ import annotations

import numpy as np

from ..errors import ParameterError

__all__ = ['modal_realisation', 'spread', 'REPEATED_POLE', 'POLE_SPREAD']

#: Poles of a reduction closer than this (relative) are one repeated pole; its m copies are
#: set POLE_SPREAD apart about it (:func:`spread`).
REPEATED_POLE, POLE_SPREAD = 1e-6, 1e-3


def spread(poles) -> np.ndarray:
    """
    Return real ``poles`` (order kept) with a repeated one's m copies spread about it.

    A reduction can coalesce poles (a fitted material's order-4 fit had -3244.5375 twice);
    the modal form needs them distinct.  Copies at p (1 + e (j - (m - 1)/2)), j < m, sum to
    m p, so the denominator moves by O(e^2): R_n by under 1e-5 relative for m <= 4, below the
    reduction's own error; the residues grow as 1 / e^(m - 1) (1e-7 of precision left at m = 4).
    """
    p = np.asarray(poles, float)
    order = np.argsort(p)
    q, out, start = p[order], p.copy(), 0
    for k in range(1, q.size + 1):
        if k == q.size or abs(q[k] - q[k - 1]) > REPEATED_POLE * abs(q[k - 1]):
            m = k - start
            if m > 1:
                out[order[start:k]] = np.mean(q[start:k]) * (
                    1.0 + POLE_SPREAD * (np.arange(m) - (m - 1) / 2.0))
            start = k
    return out


def modal_realisation(reduced):
    """
    Return R_n(s) = D + sum_i r_i / (s - p_i) (real poles, :func:`spread`) as (A, B, C, D).

    A diagonal realisation: each state is a first-order lag of the velocity.
    """
    z = np.real(np.asarray(reduced.zeros_rad_s))
    p = spread(np.real(np.asarray(reduced.poles_rad_s)))
    k = float(reduced.gain)
    if z.size > p.size:
        raise ParameterError(f'reduced model has more zeros ({z.size}) than poles ({p.size}); '
                             'the estimator needs a proper R_n(s)')
    r = np.array([k * np.prod(pi - z) / np.prod([pi - pj for pj in p if pj != pi]) for pi in p])
    d = k if z.size == p.size else 0.0      # strictly proper with an amplifier pole
    return np.diag(p), np.ones(p.size), r, d
