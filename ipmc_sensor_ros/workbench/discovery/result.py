# SPDX-License-Identifier: Apache-2.0
"""
The correction C(s) the outside stage (:mod:`.outside`) reports: values and 95 % intervals.

The search beside C(s) fits with a few dozen function evaluations, enough to rank
candidates.  The result's fit is run to convergence from three starts (:func:`_converged`);
each parameter of C(s) is then profiled a factor 2 either side (:func:`~.interval.
profile_scan`), the fit restarts from every local minimum of these scans and moves to a
deeper one (:func:`_deepest`: a corner and the material can hold several narrow minima far
apart), and the intervals are the profile-likelihood sets (:func:`~.interval.
profile_interval`).  A low-pass beside a lead-lag, C(s)'s own or a named amplifier's
bandwidth, is given the pole :func:`~.correction.assign_poles` says is its.
"""
from __future__ import annotations

import numpy as np

from .correction import (AMPLIFIER, POLE_PAIR, Correction, assign_poles, canonical,
                         correction_name)
from .fitting import lowest
from .interval import profile_interval, profile_scan, scan_minima

__all__ = ['result', 'CONVERGED_NFEV', 'RESTART_GAIN', 'MAX_RESTARTS']

#: function evaluations of the last fit, whose covariance gives the intervals (the search's
#: fits stop at 60: enough to rank candidates, not always to converge with three corners)
CONVERGED_NFEV = 300
#: a restart from a profile scan's minimum is taken when it lowers chi^2 by more than this
#: (far below an interval's level of 3.84-5.73, above what separates two stops of one local fit)
RESTART_GAIN = 0.1
#: restarts taken at most (each is scanned again)
MAX_RESTARTS = 2


def _converged(inner):
    """
    Return the current model fitted to convergence, the best of three starts.

    Its values, the baseline's material with them, and the records' nominal material with
    them: a material parameter can trade with a corner of C(s) (d with a lag's pole) and hold
    a fit that stopped early in the wrong valley.
    """
    cur = inner.current
    n_mat = len(cur.spec.material)
    nominal = np.log([getattr(inner.prepared[0].rec.model.material, n)
                      for n in cur.spec.material])
    starts = [cur.x, np.concatenate([inner.baseline.x[:n_mat], cur.x[n_mat:]]),
              np.concatenate([nominal, cur.x[n_mat:]])]
    return _lowest(inner, cur.spec, starts)


def _lowest(inner, spec, starts):
    """Fit to convergence from each start on its own; the lowest chi^2 (None: no start)."""
    return lowest(inner.prepared, spec, [[x] for x in starts], inner.folds,
                  inner.settings.fold_nfev, priors=inner.priors, max_nfev=CONVERGED_NFEV)


def _deepest(inner, cand, name):
    """
    ``cand`` moved to the deepest minimum its profile scans find, and those scans.

    Each parameter of C(s) is scanned (:func:`~.interval.profile_scan`); the fit restarts
    from every local minimum of the scans and moves when one ends lower by more than
    :data:`RESTART_GAIN`, then is scanned again (at most :data:`MAX_RESTARTS` moves).
    """
    params = [p for e, p in cand.spec.effect_params if e == name]
    for moves in range(MAX_RESTARTS + 1):
        inner.say('correction C(s): profile scans of ' + ', '.join(params))
        scans = {p: profile_scan(inner, cand, name, p) for p in params}
        if moves == MAX_RESTARTS:
            break           # the scans returned are those of the fit returned
        starts = [x for p in params for x in scan_minima(scans[p], cand.x)]
        best = _lowest(inner, cand.spec, starts)
        if best is None or best.fit.chi2 >= cand.fit.chi2 - RESTART_GAIN:
            break
        cand = best
    return cand, scans


def _amplifier_pole(inner, cand, name):
    """
    ``cand`` with an amplifier named beside C(s)'s lead-lag given its pole, or ``cand`` itself.

    The amplifier's bandwidth and the lead-lag's pole can exchange values (the same model);
    :func:`~.correction.assign_poles` says which is which, and the fit is run again from the
    exchanged values when it disagrees (and kept unless it ends higher by
    :data:`RESTART_GAIN`).
    """
    eps = cand.spec.effect_params
    if AMPLIFIER not in eps or (name, 'lead_lag_pole_hz') not in eps:
        return cand
    n_mat = len(cand.spec.material)
    i, j = n_mat + eps.index((name, 'lead_lag_pole_hz')), n_mat + eps.index(AMPLIFIER)
    zero = float(np.exp(cand.x[n_mat + eps.index((name, 'lead_lag_zero_hz'))]))
    pole, amplifier = float(np.exp(cand.x[i])), float(np.exp(cand.x[j]))
    if assign_poles(zero, (pole, amplifier)) == (pole, amplifier):
        return cand
    x = np.array(cand.x, float)
    x[i], x[j] = cand.x[j], cand.x[i]
    refit = _lowest(inner, cand.spec, [x])
    return refit if refit.fit.chi2 <= cand.fit.chi2 + RESTART_GAIN else cand


def result(inner, structure, tried) -> Correction:
    """C(s)'s values and 95 % intervals from the model beside which the search ended."""
    name = correction_name(structure)
    cand, scans = _deepest(inner, _converged(inner), name)
    exchanged = _amplifier_pole(inner, cand, name)
    if exchanged is not cand:
        inner.say('correction C(s): the amplifier takes its pole back; profile scans again')
        cand, scans = exchanged, {p: profile_scan(inner, exchanged, name, p) for p in scans}
    cand = inner.score(cand)
    inner.adopt(cand)
    n_mat = len(cand.spec.material)
    values, ci = {}, {}
    for k, (e, p) in enumerate(cand.spec.effect_params):
        if e == name:
            inner.say(f'correction C(s): profile interval of {p}')
            values[p] = float(np.exp(cand.x[n_mat + k]))
            ci[p] = profile_interval(inner, cand, name, p, scans)
    assigned = canonical(structure, values)
    if assigned != values:      # the two poles exchanged
        values, ci = assigned, {**ci, POLE_PAIR[0]: ci[POLE_PAIR[1]],
                                POLE_PAIR[1]: ci[POLE_PAIR[0]]}
    return Correction(tuple(structure), values, ci, cand.error, inner.noise_floor,
                      cand.fit.bic - inner.without(name).fit.bic, tried,
                      tuple(e for e, _ in inner.chosen),
                      {n: float(getattr(cand.fit.material, n)) for n in cand.spec.material})
