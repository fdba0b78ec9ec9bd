# SPDX-License-Identifier: Apache-2.0
"""
95 % profile-likelihood intervals of the correction's parameters.

The covariance of a fit gives intervals that are right when chi^2 is quadratic in the
parameters.  A correction's corner often trades with a material parameter along a curved
valley (a lag network's pole with the diffusivity d, both shaping the low-frequency phase),
where the quadratic interval is far too short.  The profile interval of a parameter is where
chi^2, minimised over every other parameter, stays within ``3.84 s^2`` of its minimum (3.84:
the 95 % point of chi^2 with one degree of freedom; ``s^2 = max(1, chi^2/dof)`` as for the
covariance).  It is found by stepping out from the optimum in the log of the parameter, 1, 2,
4, ... times its quadratic standard deviation, refitting the rest from the previous step, and
interpolating where the profile crosses the level (:func:`profile_interval`); the steps stop
at the parameter's bounds, and an interval that does not close before a bound ends there.
"""
from __future__ import annotations

import numpy as np

from ...physics.effects import get_effect
from ..timefit import FitSpec, fit_model
from .fitting import fit_vector, with_models

__all__ = ['PROFILE_DELTA_CHI2', 'profile_interval']

#: chi^2 rise that bounds a 95 % interval of one parameter
PROFILE_DELTA_CHI2 = 3.84
#: steps out from the optimum on each side (1, 2, 4, ... 32 quadratic standard deviations)
PROFILE_STEPS = 6
#: function evaluations of each profile refit (warm start at the previous step)
PROFILE_NFEV = 40


def _profile_chi2(state, cand, effect, param, value, start, spec):
    """chi^2 minimised with ``effect.param`` held at ``value``, and the refitted vector."""
    models = []
    for m in cand.fit.models:
        values = dict(m.effect_values(effect), **{param: float(value)})
        models.append(m.with_effect(effect, **values))
    fit = fit_model(with_models(state.prepared, models), spec, starts=[start],
                    max_nfev=PROFILE_NFEV)
    return fit.chi2, fit_vector(fit, spec)


def profile_interval(state, cand, effect: str, param: str) -> tuple[float, float]:
    """Return the 95 % profile interval of a log-scale ``effect.param`` of ``cand`` (docstring)."""
    n_mat = len(cand.spec.material)
    k = n_mat + cand.spec.effect_params.index((effect, param))
    spec = FitSpec(cand.spec.material,
                   tuple(ep for ep in cand.spec.effect_params if ep != (effect, param)))
    dof = max(cand.fit.n_rows - cand.fit.n_params, 1)
    level = PROFILE_DELTA_CHI2 * max(1.0, cand.fit.chi2 / dof)
    sd = float(np.sqrt(max(cand.fit.covariance[k, k], 0.0))) or 1e-3
    x0 = float(cand.x[k])
    par = next(q for q in get_effect(effect).parameters if q.name == param)
    ends = []
    for sign, bound in ((-1.0, np.log(par.lower)), (1.0, np.log(par.upper))):
        prev_x, prev_d, start = x0, 0.0, np.delete(cand.x, k)
        end = None
        for step in range(PROFILE_STEPS):
            if prev_x == bound:
                break       # the interval reaches the parameter's bound
            x = x0 + sign * sd * 2 ** step
            x = max(x, bound) if sign < 0 else min(x, bound)
            value = float(np.clip(np.exp(x), par.lower, par.upper))     # exp(log) rounding
            chi2, start = _profile_chi2(state, cand, effect, param, value, start, spec)
            d = chi2 - cand.fit.chi2
            if d >= level:
                end = prev_x + (x - prev_x) * (level - prev_d) / max(d - prev_d, 1e-12)
                break
            prev_x, prev_d = x, max(d, 0.0)
        ends.append(prev_x if end is None else end)
    return float(np.exp(ends[0])), float(np.exp(ends[1]))
