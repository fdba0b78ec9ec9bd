# SPDX-License-Identifier: Apache-2.0
"""
The offset test: a mean current is an offset, because the sensor has H(0) = 0.

The sensor cannot produce a mean current (H1, eq. 31, and every catalog factor keep the
``s`` of eq. 31), so the mean residual over whole stimulus periods is an offset whatever the
model's dynamics.  Per record its z-score is ``mean / (sigma / sqrt(n))``; their chi-square
over the records has ``n_records`` degrees of freedom.  When its p-value is below
``offset_p`` (1e-6), ``current_offset`` is named and added before the stepwise search, and the
same test, on the model without the offset, is the offset's own test of membership
(:mod:`.significance`): it sees a mean that the held-out error ``||y - y_hat|| / ||y -
mean y||``, dominated by the dynamics, does not.
"""
from __future__ import annotations

import numpy as np
from scipy.stats import chi2 as chi2_dist

from ..timepredict import predict
from .drive import drive_of

__all__ = ['offset_test', 'add_offset']

OFFSET = 'current_offset'


def _whole_periods(p, t, r, drive=None):
    """Return the residual over whole stimulus periods (all of it for a non-periodic stimulus)."""
    f0 = (drive or drive_of(p.rec)).frequency_hz
    if f0 is None:
        return r
    n_per = int((t[-1] - t[0]) * f0)
    return r[t < t[0] + n_per / f0] if n_per >= 1 else r


def offset_test(prepared, models, drives=None) -> dict:
    """
    Mean residual over whole stimulus periods per record; chi-square of the z-scores.

    ``drives``: the records' :class:`~.drive.Drive` (found here when not given).
    """
    zs, means, ns = [], [], []
    for k, (p, m) in enumerate(zip(prepared, models)):
        t, r = p.t[p.keep], (p.y - predict(p, m))[p.keep]
        r = _whole_periods(p, t, r, drives[k] if drives else None)
        zs.append(float(np.mean(r) / (p.sigma / np.sqrt(r.size))))
        means.append(float(np.mean(r)))
        ns.append(r.size)
    c2 = float(np.sum(np.square(zs)))
    return {'mean_a': float(np.average(means, weights=ns)), 'chi2': c2, 'dof': len(zs),
            'p_value': float(chi2_dist.sf(c2, len(zs))), 'max_abs_z': float(np.max(np.abs(zs)))}


def add_offset(state) -> None:
    """Run the offset test on the current model; add ``current_offset`` when it is significant."""
    if OFFSET not in state.pool or state.settings.max_effects == 0:
        return
    state.offset = offset_test(state.prepared, state.current.fit.models, state.drives)
    if state.offset['p_value'] >= state.settings.offset_p:
        return
    state.say('mean current found: fitting current_offset')
    shape = state.first_shape(OFFSET)
    c = state.score(state.job()((OFFSET, shape)))
    state.record(OFFSET, 'added', c,
                 f"mean residual current {state.offset['mean_a'] * 1e9:.3g} nA (offset test "
                 f"p = {state.offset['p_value']:.2g}; the sensor has H(0) = 0)")
    state.chosen.append((OFFSET, shape))
    state.adopt(c)
