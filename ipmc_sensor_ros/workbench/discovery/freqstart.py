# SPDX-License-Identifier: Apache-2.0
"""
A start for C(s) from the records' frequency responses: measured over model at each drive.

The time-domain fit of a structure of C(s) (:func:`~.correction_fit.fit_structures`) starts
from a grid of corners on the current model's material, bounded near it.  When the model
without C(s) cannot follow the data, that material says nothing about the sample: a resonance
at 3 Hz turns the current's sign above it, the best H2 alone predicts almost nothing
(alpha0 5e5, d 7e-15, held-out error 1.0), and no corner started there comes back.

The measured response ``H_m(f_k)`` at each record's drive fundamental
(:func:`~..freqresp.fundamental_response`, eq. 45's input-output ratio) against the model's
gives C(s) in a small least-squares problem with no simulation: the misfit of
``ln(H(j w_k; material) C(j w_k; theta) / H_m(f_k))`` in magnitude and phase, each over its
measured uncertainty (:func:`~..freqfit.misfit`, as the frequency-domain ``fit`` weighs it).
The material is held, the records' own (the model file's) and the current one, each giving a
start: from one point per record its diffusion corner trades with a low-pass, and a fit of
both ran to the diffusivity's physical limit.  Which of the two is right is the time-domain
fit's to say (a lag network on a delay's stand-in model: the current material, 5x low in d,
fitted the fundamentals better and its start ended at 2.4x the floor; the records' own ended
at the floor).  The corners start from the time-domain fit's grid, the :data:`REFINED`
cheapest refined.  The time-domain fit refines each start beside the grid's cheapest and
keeps the lowest chi^2 (:class:`~.fitting.Job`): where the frequency-domain starts are no
better, nothing changes (screened with the grid by its cost at the start, one was refined
instead of the grid's and ended higher: a lag network came out as a high-pass beside a
lead-lag).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.optimize import least_squares

from ..freqfit import misfit
from ..freqresp import fundamental_response
from .correction import ELEMENTS, correction_class

__all__ = ['response_points', 'frequency_starts', 'REFINED', 'MAX_NFEV']

#: starts refined in the frequency domain (the cheapest by their cost at the start)
REFINED = 3
#: evaluations per refinement (a few points, a handful of parameters)
MAX_NFEV = 40


def response_points(state) -> list:
    """
    Return ``(record index, FrequencyPoint)`` at each record's drive fundamental.

    Measured once per search state (``SearchState.drive_points``; views of it on records with
    a periodic history keep the same rows).
    """
    if getattr(state, 'drive_points', None) is not None:
        return state.drive_points
    out = []
    for k, p in enumerate(state.prepared):
        try:
            out.append((k, fundamental_response(p.t[p.keep], p.w[p.keep], p.y[p.keep])))
        except ValueError:      # no periodic drive: the record gives no point
            continue
    state.drive_points = out
    return out


def _groups(models, points):
    """Group the points by model (records of one sample share it): model -> (s, H_m, sd)."""
    by: dict = {}
    for k, pt in points:
        by.setdefault(models[k], []).append(pt)
    return [(m, 2j * np.pi * np.array([p.frequency_hz for p in pts]),
             np.array([p.response for p in pts]),
             np.array([max(p.sd_log_mag, 1e-12) for p in pts]),
             np.array([max(p.sd_phase_rad, 1e-12) for p in pts])) for m, pts in by.items()]


def _fit(groups, factor, names, material, grid):
    """Return ``(cost, C(s)'s parameters)`` fitted on ``material`` from the cheapest starts."""
    models = [(m.with_material(material).transfer(s), s, h_m, sd_m, sd_p)
              for m, s, h_m, sd_m, sd_p in groups]
    pars = {p.name: p for e in ELEMENTS.values() for p in e}
    lo = np.log([pars[n].lower for n in names])
    hi = np.log([pars[n].upper for n in names])

    def residual(v):
        values = dict(zip(names, np.exp(v)))
        return np.concatenate([misfit(h * factor(s, None, values), h_m, sd_mag, sd_phase)
                               for h, s, h_m, sd_mag, sd_phase in models])

    starts = [np.clip(np.asarray(c, float), lo, hi) for c in grid]
    costs = [float(np.sum(residual(v) ** 2)) for v in starts]
    best = None
    for k in np.argsort(costs)[:REFINED]:
        fit = least_squares(residual, starts[k], bounds=(lo, hi), max_nfev=MAX_NFEV)
        if best is None or fit.cost < best.cost:
            best = fit
    return best.cost, best.x


def frequency_starts(state, base, structure, grid, points) -> list[np.ndarray]:
    """
    Return starts (fit space: ``base.spec`` then C(s)'s parameters) for ``structure``.

    One per material held (the records' own, the current one), the one that fits the
    responses better first.  ``grid``: the time-domain fit's starts of C(s)'s parameters;
    ``points``: :func:`response_points`.  Empty without points enough to fit.
    """
    names = [p.name for e in structure for p in ELEMENTS[e]]
    mat_names = tuple(base.spec.material)
    n_mat = len(mat_names)
    if 2 * len(points) < len(names) + 1:
        return []
    groups = _groups(base.fit.models, points)
    factor = correction_class(structure)().factor
    given = state.given_material or base.fit.material
    fitted = []
    for v in (np.log([getattr(given, n) for n in mat_names]), base.x[:n_mat]):
        material = replace(base.fit.material, **{n: float(np.exp(x))
                                                 for n, x in zip(mat_names, v)})
        cost, tail = _fit(groups, factor, names, material, grid)
        fitted.append((cost, np.concatenate([v, base.x[n_mat:], tail])))
    fitted.sort(key=lambda f: f[0])
    return [x for _, x in fitted]
