# SPDX-License-Identifier: Apache-2.0
"""
Simultaneous 95 % profile-likelihood intervals of the correction's parameters.

The covariance of a fit gives intervals that are right when chi^2 is quadratic in the
parameters.  A correction's corner often trades with a material parameter along a curved
valley (a lag network's pole with the diffusivity d, both shaping the low-frequency phase),
where the quadratic interval is far too short.  The profile interval of a parameter is where
chi^2, minimised over every other parameter, stays within ``q s^2`` of its minimum
(``s^2 = max(1, chi^2/dof)`` as for the covariance).  C(s) is one claim about all its
parameters (a lead-lag is right when its zero *and* its pole are), so the intervals are
simultaneous: ``q`` is the ``1 - 0.05/k`` point of chi^2 with one degree of freedom for the
k parameters of C(s) (Bonferroni: 3.84 for one, 5.02 for two, 5.73 for three), and all k
intervals hold the truth together in at least 95 % of records (:func:`interval_level`).
It is found by stepping out from the optimum in the log of the parameter, 1, 2, 4, ... times
its quadratic standard deviation, refitting the rest from the previous step, and interpolating
where the profile crosses the level (:func:`profile_interval`); the steps stop at the
parameter's bounds, and an interval that does not close before a bound ends there.
Where the profile crosses the level is found by interpolating its square root (the signed root
of the likelihood ratio, linear in the parameter where chi^2 is quadratic; chi^2 itself,
interpolated linearly across a steep rise, ends the interval short), refined by
:data:`CROSSING_REFITS` profile refits at the interpolated point (:func:`_crossing`).

The valley can also hold several minima, narrow and far apart in the other parameters (a lag
network's pole at 8.9 Hz with d = 2.1e-11 m^2/s and at 6.9 Hz with d = 3.6e-11, chi^2 3.9
apart, a barrier of thousands between them along the straight line).  A local fit stays in
the one it starts in.  :func:`profile_scan` therefore follows the profile a factor
:data:`SCAN_REACH` either side in steps of :data:`SCAN_STEP`; the fit restarts from each local
minimum of the scan (:func:`scan_minima`, used by the caller), and the interval takes in every
scanned value whose profile lies below the level, as the profile-likelihood set it is, the
parameter's value in every fit of the other parameters' scans that lies below the level (its
profile is no higher there), and the scan's crossings of the level beyond its outermost
values inside, found between the 5 % steps as the stepped interval's are.
"""
from __future__ import annotations

import numpy as np
from scipy.stats import chi2 as chi2_dist

from ...physics.effects import effect_parameter
from ..timefit import FitSpec, fit_model
from .fitting import fit_vector, with_models

__all__ = ['JOINT_CONFIDENCE', 'interval_level', 'profile_interval', 'profile_scan',
           'scan_minima']

#: the probability that every interval of C(s) holds its parameter's truth at once
JOINT_CONFIDENCE = 0.95
#: steps out from the optimum on each side (1, 2, 4, ... 32 quadratic standard deviations)
PROFILE_STEPS = 6
#: function evaluations of each profile refit (warm start at the previous step)
PROFILE_NFEV = 40
#: step of the profile scan in the log of a parameter (5 %: a valley whose refitted profile is
#: a few percent wide is not stepped over) and its reach either side (a factor 2)
SCAN_STEP = float(np.log(1.05))
SCAN_REACH = float(np.log(2.0))
#: profile refits that place each end of an interval between the last step inside and the first
#: outside (each halves the error of the interpolation at least; two bring a 5 % step's to
#: well below the spread of the refits themselves)
CROSSING_REFITS = 2


def _profile_chi2(state, cand, effect, param, value, start, spec):
    """chi^2 minimised with ``effect.param`` held at ``value``, and the refitted vector."""
    models = []
    for m in cand.fit.models:
        values = dict(m.effect_values(effect), **{param: float(value)})
        models.append(m.with_effect(effect, **values))
    fit = fit_model(with_models(state.prepared, models), spec, starts=[start],
                    max_nfev=PROFILE_NFEV)
    return fit.chi2, fit_vector(fit, spec)


def _setup(cand, effect, param):
    """Index of ``effect.param`` in the fit vector, the spec without it, its bounds."""
    k = len(cand.spec.material) + cand.spec.effect_params.index((effect, param))
    spec = FitSpec(cand.spec.material,
                   tuple(ep for ep in cand.spec.effect_params if ep != (effect, param)))
    par = effect_parameter(effect, param)
    return k, spec, (par.lower, par.upper)


def interval_level(n_params: int) -> float:
    """Return the chi^2 rise bounding each of ``n_params`` simultaneous intervals (docstring)."""
    return float(chi2_dist.ppf(1.0 - (1.0 - JOINT_CONFIDENCE) / max(n_params, 1), 1))


def _level(cand, effect) -> float:
    dof = max(cand.fit.n_rows - cand.fit.n_params, 1)
    n_params = sum(e == effect for e, _ in cand.spec.effect_params)
    return interval_level(n_params) * max(1.0, cand.fit.chi2 / dof)


def _crossing(profile, inside, outside, level) -> float:
    """
    Return where the profile crosses ``level`` between a value inside and one outside.

    ``inside``: ``(x, delta chi^2, start)``, ``outside``: ``(x, delta chi^2)``;
    ``profile(x, start)`` returns the delta chi^2 at ``x`` and its refitted vector.  The
    square root of delta chi^2 is interpolated; each of :data:`CROSSING_REFITS` refits at the
    interpolated point replaces the end of the bracket it falls on.
    """
    for refit in range(CROSSING_REFITS + 1):
        (xi, di, start), (xo, do) = inside, outside
        ri, ro = np.sqrt(max(di, 0.0)), np.sqrt(max(do, 0.0))
        x = xi + (xo - xi) * (np.sqrt(level) - ri) / max(ro - ri, 1e-12)
        if refit == CROSSING_REFITS:
            return float(x)
        d, vector = profile(x, start)
        if d < level:
            inside = (x, d, vector)
        else:
            outside = (x, d)


def _profile(state, cand, effect, param):
    """``profile(x, start)`` of :func:`_crossing` for ``effect.param`` (log value ``x``)."""
    _, spec, bounds = _setup(cand, effect, param)

    def profile(x, start):
        value = float(np.clip(np.exp(x), *bounds))     # exp(log) rounding
        chi2, vector = _profile_chi2(state, cand, effect, param, value, start, spec)
        return chi2 - cand.fit.chi2, vector
    return profile


def profile_scan(state, cand, effect: str, param: str) -> list[tuple[float, float, np.ndarray]]:
    """
    Profile a log-scale ``effect.param`` on a grid around ``cand``'s value (docstring).

    Returns ``(log value, chi^2, full fit vector)`` sorted by value, ``cand`` itself included;
    each side is followed outwards, every refit starting from the previous one.
    """
    k, _, bounds = _setup(cand, effect, param)
    lo, hi = np.log(bounds)
    profile = _profile(state, cand, effect, param)
    x0 = float(cand.x[k])
    points = [(x0, float(cand.fit.chi2), np.asarray(cand.x, float))]
    for sign in (-1.0, 1.0):
        start = np.delete(cand.x, k)
        for j in range(1, int(round(SCAN_REACH / SCAN_STEP)) + 1):
            x = float(np.clip(x0 + sign * j * SCAN_STEP, lo, hi))
            d, start = profile(x, start)
            points.append((x, float(cand.fit.chi2) + d, np.insert(start, k, x)))
            if x in (lo, hi):
                break
    return sorted(points, key=lambda q: q[0])


def scan_minima(points, centre: np.ndarray) -> list[np.ndarray]:
    """Full fit vectors at the local minima of a scan's profile, ``centre`` (its fit) excluded."""
    chi2 = [q[1] for q in points]
    out = []
    for i in range(len(points)):
        left = chi2[i - 1] if i else np.inf
        right = chi2[i + 1] if i + 1 < len(points) else np.inf
        if chi2[i] < left and chi2[i] < right and not np.array_equal(points[i][2], centre):
            out.append(points[i][2])
    return out


def _scan_ends(points, k, chi2_min, level, profile) -> list[float]:
    """
    Where a scan of parameter ``k`` crosses the level beyond its outermost values below it.

    Found between the last value inside and the next one out (:func:`_crossing`), as the
    stepped interval's ends are; the outermost value itself at the end of the scan.
    """
    xs = [q[2][k] for q in points]
    ds = [q[1] - chi2_min for q in points]
    inside = [i for i, d in enumerate(ds) if d < level]
    out = []
    for i, j in ((inside[0], inside[0] - 1), (inside[-1], inside[-1] + 1)) if inside else ():
        if 0 <= j < len(xs):
            start = np.delete(points[i][2], k)
            out.append(_crossing(profile, (xs[i], ds[i], start), (xs[j], ds[j]), level))
        else:
            out.append(xs[i])
    return out


def profile_interval(state, cand, effect: str, param: str,
                     scans=None) -> tuple[float, float]:
    """
    Return the simultaneous profile interval of a log-scale ``effect.param`` (docstring).

    ``scans``: the :func:`profile_scan` of each parameter of ``cand`` (name -> points).  The
    interval holds this parameter's value in every scanned fit below the level, of its own
    scan and of the others' (each such fit bounds the profile from above there: a second
    valley met while scanning the pole holds the zero that goes with it), and its own scan's
    crossings of the level beyond them.
    """
    k, _, bounds = _setup(cand, effect, param)
    lo_bound, hi_bound = np.log(bounds)
    level = _level(cand, effect)
    profile = _profile(state, cand, effect, param)
    sd = float(np.sqrt(max(cand.fit.covariance[k, k], 0.0))) or 1e-3
    x0 = float(cand.x[k])
    ends = []
    for sign, bound in ((-1.0, lo_bound), (1.0, hi_bound)):
        last = (x0, 0.0, np.delete(cand.x, k))     # the last step inside
        end = None
        for step in range(PROFILE_STEPS):
            if last[0] == bound:
                break       # the interval reaches the parameter's bound
            x = x0 + sign * sd * 2 ** step
            x = max(x, bound) if sign < 0 else min(x, bound)
            d, vector = profile(x, last[2])
            if d >= level:
                end = _crossing(profile, last, (x, d), level)
                break
            last = (x, max(d, 0.0), vector)
        ends.append(last[0] if end is None else end)
    scans = scans or {}
    inside = [q[2][k] for points in scans.values() for q in points
              if q[1] - cand.fit.chi2 < level]
    inside += _scan_ends(scans.get(param, ()), k, cand.fit.chi2, level, profile)
    return float(np.exp(min([ends[0], *inside]))), float(np.exp(max([ends[1], *inside])))
