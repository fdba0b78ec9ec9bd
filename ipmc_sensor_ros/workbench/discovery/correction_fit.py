# SPDX-License-Identifier: Apache-2.0
"""
Fitting a correction C(s) (:mod:`.correction`) as a factor of a model, its order by BIC.

* :func:`history_view`: the state on records with a longer periodic history (:mod:`.history`),
  :data:`HISTORY_TIME_CONSTANTS` time constants of the slowest corner a fit starts from, so
  that a slow C(s) enters each record in steady state.
* :func:`fit_structures`: each structure fitted from a grid of corners and from starts
  fitted to the records' frequency responses (:mod:`.freqstart`).
* :func:`select_correction`: every structure up to ``max_correction_order`` parameters fitted
  as a factor of a model (all records and samples, every free parameter refitted; corners
  started across the records' band); an order is taken when its best structure lowers the
  BIC by ``min_delta_bic`` below the best lower order (or the model without correction).
* The correction's effects are registered only while they are fitted (:func:`registered`):
  they are not catalog effects and are never offered as candidates (:func:`is_correction`).
"""
from __future__ import annotations

from contextlib import contextmanager
from dataclasses import replace

import numpy as np

from ...physics.effects import EFFECTS, register_effect
from ..timepredict import prepare
from .correction import ELEMENTS, PREFIX, correction_class, correction_name, structures
from .fitting import evaluate, make_folds, with_models
from .freqstart import frequency_starts, response_points
from .history import with_history

__all__ = ['is_correction', 'registered', 'band_hz', 'history_view', 'fit_structures',
           'select_correction', 'HISTORY_TIME_CONSTANTS', 'HISTORY_MAX_S']

SOURCE = 'ipmc-model diagnose (correction C(s))'
#: history prepended to periodic records, in time constants of the slowest corner a fit starts
#: from (a fifth of the lowest drive frequency): a transient decays to exp(-5) < 1 % by then
HISTORY_TIME_CONSTANTS = 5.0
#: longest history, s (a corner below 0.02 Hz is not resolved by records of seconds anyway)
HISTORY_MAX_S = 40.0
ALPHA0 = 'charge_stress_coupling_j_per_c'


def is_correction(name: str) -> bool:
    """Return True for the internal effects of C(s)."""
    return name.startswith(PREFIX)


@contextmanager
def registered(structs):
    """Register the effects of ``structs`` while the block runs."""
    names = []
    try:
        for st in structs:
            name = correction_name(st)
            if name not in EFFECTS:
                register_effect(correction_class(st), source=SOURCE)
                names.append(name)
        yield
    finally:
        for name in names:
            EFFECTS.pop(name, None)


def band_hz(state) -> tuple[float, float]:
    """Lowest and highest drive frequency of the records (or 1/T and a tenth of the rate)."""
    found = dict(response_points(state))
    lo, hi = [], []
    for k, p in enumerate(state.prepared):
        if k in found:
            lo.append(found[k].frequency_hz)
            hi.append(found[k].frequency_hz)
        else:
            t = p.t[p.keep]
            lo.append(1.0 / (t[-1] - t[0]))
            hi.append(0.1 * (t.size - 1) / (t[-1] - t[0]))
    return min(lo), max(hi)


def history_view(state, band):
    """
    Return the state on records with a longer periodic history, its current model refitted there.

    :data:`HISTORY_TIME_CONSTANTS` time constants of the slowest corner a fit starts from; the
    state itself when its records hold that much already.
    """
    history_s = min(HISTORY_MAX_S, HISTORY_TIME_CONSTANTS / (2 * np.pi * band[0] / 5))
    if all(p.t[p.keep][0] - p.t[0] >= history_s + state.settings.settle_s
           for p in state.prepared):
        return state
    prepared = []
    for p, drive in zip(state.prepared, state.drives):
        rec = with_history(p.rec, history_s, drive)
        start = float(p.t[p.keep][0])
        use = rec or p.rec
        prepared.append(prepare([use], settle_s=start - float(use.time_s[0]))[0])
    view = replace(state, prepared=prepared,
                   folds=make_folds(prepared, state.settings.n_folds)[0])
    cur = state.current
    view.adopt(evaluate(with_models(prepared, cur.fit.models), cur.spec, [cur.x], view.folds,
                        state.settings.fold_nfev, priors=state.priors, scored=False))
    return view


def starts(structure, band) -> list[list[float]]:
    """Return starting points (fit space): corners across the band, a few dampings and delays."""
    lo, hi = band
    corners = np.log(np.geomspace(lo / 5, hi * 5, 4))
    grids = {'low_pass': [[c] for c in corners], 'high_pass': [[c] for c in corners],
             'lead_lag': [[a, b] for a in corners for b in corners if a != b],
             'resonance': [[c, np.log(z)] for c in corners for z in (0.1, 0.5)],
             'delay': [[np.log(1e-4)], [np.log(1e-3)]], 'gain': [[0.0]]}
    out = [[]]
    for e in structure:
        out = [a + b for a in out for b in grids[e]]
    return out


def _known_start(names, known, band) -> list[float]:
    """Return a start from known values (a smaller correction's), the rest mid-band."""
    middle = {'resonance_damping_ratio': 0.2, 'correction_delay_s': 1e-3, 'correction_gain': 1.0}
    return [float(np.log(known.get(n, middle.get(n, np.sqrt(band[0] * band[1])))))
            for n in names]


def fit_structures(state, base, structs, band, known=(), material_from=None):
    """
    Fit each structure as a factor of ``base``; the candidates, each with ``structure``.

    ``known``: sets of parameter values (another correction's) to start from as well, and
    with them the material of ``material_from`` (the model they were fitted in: a corner and
    the material lie in one narrow valley); starts from the records' frequency responses
    (:mod:`.freqstart`) join the grid.
    """
    items, points = [], response_points(state)
    n_mat = len(base.spec.material)
    for st in structs:
        names = [p.name for e in st for p in ELEMENTS[e]]
        own = [_known_start(names, k, band) for k in known]
        grid = starts(st, band) + own
        whole = frequency_starts(state, base, st, grid, points)
        if material_from is not None:
            whole += [np.concatenate([material_from.x[:n_mat], base.x[n_mat:], x]) for x in own]
        items.append((correction_name(st), tuple(names), grid, whole))
    with registered(structs):
        out = state.run(state.job(base), items)
    for c, st in zip(out, structs):
        c.structure = st
    return out


def select_correction(state, base, band):
    """Return ``(best, tried)``: C(s) chosen by BIC on top of ``base`` (None if none helps)."""
    s = state.settings
    with_gain = ALPHA0 not in s.free_material
    best, ref, tried = None, base.fit.bic, []
    for order in range(1, s.max_correction_order + 1):
        structs = structures(order, with_gain)
        if not structs:
            continue
        state.say(f'correction C(s): {len(structs)} structure(s) of order {order}')
        cands = fit_structures(state, base, structs, band)
        tried += [(c.structure, c.fit.bic - base.fit.bic) for c in cands]
        top = min(cands, key=lambda c: c.fit.bic)
        if top.fit.bic <= ref - s.min_delta_bic:
            best, ref = top, top.fit.bic
    return best, tried
