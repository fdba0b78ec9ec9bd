# SPDX-License-Identifier: Apache-2.0
"""
Outside the catalog: characterise what the named effects leave, and hold them to it.

Runs when the search ends above the noise floor (beyond ``stop_factor``) or a named effect is
implausible:

1. **C(s) by BIC.**  Every structure of :mod:`.correction` up to ``max_correction_order``
   parameters is fitted as a factor of the current model (all records and samples, every free
   parameter refitted; corners started across the records' band).  Periodic records get their
   periodic history (:mod:`.history`), :data:`HISTORY_TIME_CONSTANTS` time constants of the
   slowest corner started from, so that a slow C(s) enters each record in steady state.  An
   order is taken when its best structure lowers the BIC by ``min_delta_bic`` below the best
   lower order (or the model without correction).
   C(s) must also pass the rule of a step of the search: lower the held-out error by the
   needed gain (:meth:`~.state.SearchState.needed_gain`).
2. **The named effects against C(s).**  A catalog effect stays named only when it is plausible,
   its own test (:mod:`.significance`) is significant beside C(s), and it is better than C(s)
   grown by as many parameters as it has: the model without it, with the best structure that
   holds C(s)'s elements and that many parameters more, must not beat it by
   ``min_delta_bic``.  An effect that fails is dropped (a step), and C(s) is chosen again.
3. The result (:class:`~.correction.Correction`): values with 95 % intervals from the fit's
   covariance, the held-out error of the model times C(s) against the floor.

The correction's effects are registered only while this stage runs (they are not catalog
effects); :mod:`.plugin` writes one as a plugin file for later runs.
"""
from __future__ import annotations

from contextlib import contextmanager
from dataclasses import replace

import numpy as np

from ...physics.effects import EFFECTS, register_effect
from .correction import ELEMENTS, PREFIX, Correction, correction_class, correction_name, \
    structures
from ..timefit import prepare
from .fitting import evaluate, make_folds, with_models
from .history import with_history
from .offset_test import OFFSET
from .significance import describe, own_test

__all__ = ['is_correction', 'outside_stage', 'registered']

SOURCE = 'ipmc-model diagnose (correction C(s))'
#: history prepended to periodic records, in time constants of the slowest corner a fit starts
#: from (a fifth of the lowest drive frequency): a transient decays to exp(-5) < 1 % by then
HISTORY_TIME_CONSTANTS = 5.0
#: longest history, s (a corner below 0.02 Hz is not resolved by records of seconds anyway)
HISTORY_MAX_S = 40.0
ALPHA0 = 'charge_stress_coupling_j_per_c'


def is_correction(name: str) -> bool:
    """True for the internal effects of C(s)."""
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


def _band_hz(state) -> tuple[float, float]:
    """Lowest and highest drive frequency of the records (or 1/T and a tenth of the rate)."""
    from ..freqresp import fundamental_response

    lo, hi = [], []
    for p in state.prepared:
        t = p.t[p.keep]
        try:
            f0 = fundamental_response(t, p.w[p.keep], p.y[p.keep]).frequency_hz
            lo.append(f0)
            hi.append(f0)
        except ValueError:
            lo.append(1.0 / (t[-1] - t[0]))
            hi.append(0.1 * (t.size - 1) / (t[-1] - t[0]))
    return min(lo), max(hi)


def history_view(state, band):
    """
    The state on records with a longer periodic history, its current model refitted there.

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


def _starts(structure, band) -> list[list[float]]:
    """Starting points (fit space): corners across the band, a few dampings and delays."""
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


def _fit(state, base, structs, band):
    """Fit each structure as a factor of ``base``; the candidates, each with ``structure``."""
    items = [(correction_name(st), tuple(p.name for e in st for p in ELEMENTS[e]),
              _starts(st, band)) for st in structs]
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
        cands = _fit(state, base, structs, band)
        tried += [(c.structure, c.fit.bic - base.fit.bic) for c in cands]
        top = min(cands, key=lambda c: c.fit.bic)
        if top.fit.bic <= ref - s.min_delta_bic:
            best, ref = top, top.fit.bic
    return best, tried


def _rival(state, best, name, band):
    """C(s) grown by the parameters of ``name``, in the model without ``name``."""
    k = sum(1 for e, _ in state.current.spec.effect_params if e == name)
    order = len(best.shape) + k
    if k == 0 or order > state.settings.max_correction_order:
        return None
    with_gain = ALPHA0 not in state.settings.free_material
    structs = [st for st in structures(order, with_gain) if set(best.structure) <= set(st)]
    if not structs:
        return None
    cands = _fit(state, state.without(name), structs, band)
    return min(cands, key=lambda c: c.fit.bic)


def _failing(state, best, band):
    """The first named effect that fails step 2 of the module docstring, and why."""
    level = state.settings.min_delta_bic
    for name, _ in state.chosen:
        if name == OFFSET:
            continue
        if any(f.startswith(f'{name}/') for f in best.flags):
            return name, 'implausible beside the correction C(s)'
        with registered([best.structure]):
            test, _ = own_test(state, name, base=best)
        if not test['significant']:
            return name, f'not significant beside the correction C(s) ({describe(test)})'
        rival = _rival(state, best, name, band)
        if rival is not None and rival.fit.bic <= best.fit.bic - level:
            grown = '+'.join(rival.structure)
            return name, ('a correction C(s) with as many parameters fits better '
                          f'({grown}: BIC {rival.fit.bic - best.fit.bic:+.0f})')
    return None


def _result(state, best, tried) -> Correction:
    """Turn the scored fit of C(s) into a :class:`Correction` with 95 % intervals."""
    n = len(best.shape)
    cov = best.fit.covariance
    sd = np.sqrt(np.clip(np.diag(cov)[-n:], 0, None)) if cov is not None else np.full(n, np.nan)
    values, ci = {}, {}
    for name, x, s in zip(best.shape, best.x[-n:], sd):
        values[name] = float(np.exp(x))
        ci[name] = (float(np.exp(x - 1.96 * s)), float(np.exp(x + 1.96 * s)))
    return Correction(best.structure, values, ci, best.error, state.noise_floor,
                      best.fit.bic - state.current.fit.bic, tried,
                      tuple(e for e, _ in state.chosen))


def outside_stage(state) -> None:
    """Run the stage (module docstring) when the search ended above the floor."""
    implausible = any(f.split('/')[0] in state.names() for f in state.current.flags)
    if state.at_floor() and not implausible:
        return
    band = _band_hz(state)
    for _ in range(len(state.chosen) + 1):
        view = history_view(state, band)
        best, tried = select_correction(view, view.current, band)
        if best is None:
            return
        with registered([best.structure]):
            best = view.score(best)
        if best.error > (1 - state.needed_gain(state.current.error)) * state.current.error:
            return              # not significant by the held-out error: no correction
        failing = _failing(view, best, band)
        if failing is None:
            state.correction = _result(view, best, tried)
            return
        name, why = failing
        wo = state.score(state.without(name))
        state.record(name, 'dropped', wo, why)
        state.chosen = [c for c in state.chosen if c[0] != name]
        state.adopt(wo)
