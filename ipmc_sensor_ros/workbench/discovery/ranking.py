# SPDX-License-Identifier: Apache-2.0
"""
How candidates are started, shaped and ranked.

* Starts: each free effect parameter from the ends and middle of its plausible range (and
  its header prior): :func:`start_grid`.
* Shapes: ``hydration_drift`` is tried as the plain exponential of d and as a relaxation
  toward an equilibrium (:data:`SHAPES`); the shape with the lower held-out error is kept,
  BIC deciding within ``tie_tol`` (:func:`merge_shapes`).
* Ranking: candidates within ``tie_tol`` of the best held-out error are ties; among them a
  plausible one (no parameter at a bound, outside its plausible range or far from a header
  prior) comes before an implausible one, then the lower BIC (:func:`rank`).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ...physics.effects import effect_parameter, get_effect
from ..timefit import FitSpec, ModelFit
from .verdict import Candidate

__all__ = ['SHAPES', 'shapes', 'start_grid', 'baseline_starts', 'merge_shapes', 'rank',
           'model_values']

#: effects tried in several shapes: name -> tuples of free parameters (the rest stay at default)
SHAPES = {
    'hydration_drift': (
        ('diffusivity_rate_per_s',),
        ('diffusivity_rate_per_s', 'equilibrium_ratio'),
    )
}


def shapes(name: str) -> tuple[tuple[str, ...], ...]:
    """Return the free-parameter sets an effect is tried in (SHAPES, else all its parameters)."""
    return SHAPES.get(name, (tuple(p.name for p in get_effect(name).parameters),))


def start_grid(effect_name: str, shape: Sequence[str], priors: dict) -> list[list[float]]:
    """Return the starting values (fit space) of an effect's free parameters."""
    pars = {p.name: p for p in get_effect(effect_name).parameters}
    grids = []
    for name in shape:
        par = pars[name]
        lo, hi = par.typical
        if par.log_scale:
            pts = list(np.linspace(np.log(max(lo, par.lower)), np.log(min(hi, par.upper)), 3))
        else:
            pts = [lo, 0.0 if lo < 0 < hi else 0.5 * (lo + hi), hi]
        if (effect_name, name) in priors:
            v = priors[(effect_name, name)]
            pts = [np.log(v) if par.log_scale else v] + pts
        grids.append(pts)
    if not grids:
        return [[]]
    mid = [g[1] if len(g) == 3 else g[0] for g in grids]
    if len(grids) == 1:
        return [[v] for v in grids[0]]
    return [mid] + [[g[j] if i == k else mid[i] for i, g in enumerate(grids)]
                    for k in range(len(grids)) for j in (0, len(grids[k]) - 1)]


def baseline_starts(spec: FitSpec, priors: dict, model) -> list[np.ndarray]:
    """Return the baseline fit's start: the model's material, its effects' values or priors."""
    x = [np.log(getattr(model.material, n)) for n in spec.material]
    for e, n in spec.effect_params:
        v = priors.get((e, n), model.effect_values(e)[n])
        x.append(np.log(v) if effect_parameter(e, n).log_scale else v)
    return [np.asarray(x, float)]


def merge_shapes(cands: list[Candidate], tie_tol: float) -> list[Candidate]:
    """Keep one shape per effect: the lower held-out error (BIC decides within ``tie_tol``)."""
    by: dict[str, Candidate] = {}
    for c in cands:
        o = by.get(c.effect)
        if o is None:
            by[c.effect] = c
        elif abs(c.error - o.error) <= tie_tol * min(c.error, o.error):
            by[c.effect] = c if c.fit.bic < o.fit.bic else o
        else:
            by[c.effect] = c if c.error < o.error else o
    return list(by.values())


def rank(cands: list[Candidate], tie_tol: float) -> list[Candidate]:
    """
    Ties (within ``tie_tol`` of the best held-out error) first, plausible before implausible.

    Then by BIC; the rest by held-out error.
    """
    if not cands:
        return []
    best = min(c.error for c in cands)
    tied = [c for c in cands if c.error <= (1 + tie_tol) * best]
    rest = sorted((c for c in cands if c not in tied), key=lambda c: c.error)
    return sorted(tied, key=lambda c: (not c.plausible, c.fit.bic)) + rest


def model_values(fit: ModelFit, material_names) -> dict:
    """Fitted values of a model: effect -> {parameter: value}, plus 'material'."""
    m = fit.models[0]
    out = {e.name: e.as_dict() for e in m.effects if e.as_dict()}
    out['material'] = {n: getattr(fit.material, n) for n in material_names}
    return out
