# SPDX-License-Identifier: Apache-2.0
"""
Each effect's own test: what keeps an effect in the verdict.

An effect stays when its own test is significant at the stated level, whatever the held-out
error says (that metric, ``||y - y_hat|| / ||y - mean y||``, is dominated by the dynamics and
cannot see a small mean current):

* ``current_offset``: the offset test (:mod:`.offset_test`) on the model without it, chi-square
  p-value below ``offset_p`` (1e-6); or the BIC test below (its drift term can matter where
  the mean does not);
* every effect: the BIC test, removing it (every other parameter refitted) raises the BIC by
  at least ``min_delta_bic`` (20).  This is a likelihood-ratio test, ``delta chi^2 >= k ln n +
  20``, residuals in units of the noise; its chi-square p-value (k > 0 parameters) is reported
  too.

:func:`membership` gives, for every named effect, the test that keeps it -- the JSON's
``kept_by``; an effect kept only because removing it raises the held-out error is reported as
such.
"""
from __future__ import annotations

from scipy.stats import chi2 as chi2_dist

from .fitting import with_models
from .offset_test import OFFSET, offset_test

__all__ = ['own_test', 'describe', 'membership']


def own_test(state, name: str, base=None):
    """
    Return ``(test, without)``: effect ``name``'s own test in ``base`` (default: current).

    ``without`` is ``base`` without the effect, refitted (not scored).
    """
    base = base or state.current
    s = state.settings
    wo = state.without(name, base)
    k = sum(1 for e, _ in base.spec.effect_params if e == name)
    delta_chi2 = wo.fit.chi2 - base.fit.chi2
    test = {'test': 'BIC', 'delta_bic': wo.fit.bic - base.fit.bic, 'delta_chi2': delta_chi2,
            'n_params': k, 'level': s.min_delta_bic,
            'significant': wo.fit.bic - base.fit.bic >= s.min_delta_bic}
    if k > 0:
        test['p_value'] = float(chi2_dist.sf(max(delta_chi2, 0.0), k))
    if name == OFFSET:
        ot = offset_test(with_models(state.prepared, wo.fit.models), wo.fit.models,
                         state.drives)
        if ot['p_value'] < s.offset_p or not test['significant']:
            test = {'test': 'offset chi-square', **ot, 'level': s.offset_p,
                    'significant': ot['p_value'] < s.offset_p}
    return test, wo


def describe(test: dict) -> str:
    """One line: the test, its statistic and its level."""
    if test['test'] == 'offset chi-square':
        return (f"offset test chi2 {test['chi2']:.1f}/{test['dof']}, p = {test['p_value']:.2g} "
                f"(level {test['level']:g})")
    if test['test'] == 'held-out error':
        return (f"removing it raises the held-out error {test['error']:.4f} -> "
                f"{test['error_without']:.4f}")
    text = f"BIC +{test['delta_bic']:.0f} without it (level {test['level']:g})"
    return text + (f", LR p = {test['p_value']:.2g}" if 'p_value' in test else '')


def membership(state) -> dict:
    """For every named effect, the test that keeps it (JSON ``kept_by``)."""
    out = {}
    for name, _ in state.chosen:
        test, wo = own_test(state, name)
        if not test['significant']:
            wo = state.score(wo)
            test = {'test': 'held-out error', 'error': state.current.error,
                    'error_without': wo.error, 'own_test': test,
                    'significant': wo.error > state.current.error}
        test['summary'] = describe(test)
        out[name] = test
    return out
