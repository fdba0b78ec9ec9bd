# SPDX-License-Identifier: Apache-2.0
"""
Outside the catalog: characterise what the named effects leave, then search again beside it.

Runs when the search ends above the noise floor (beyond ``stop_factor``) or a named effect is
implausible:

1. **C(s)** (:mod:`.correction_fit`) is fitted as a factor of the model the search ended with,
   less the named effects whose values are implausible (stand-ins: a 4 Hz amplifier pole),
   its order by BIC; it must also lower the held-out error as a step of the search must
   (:meth:`~.state.SearchState.needed_gain`), else nothing is reported and the implausible
   effects stay named as they were (a delay just past its plausible range that holds an
   amplifier's lag is still the best account of the data the catalog has).
   An element of C(s) that a catalog effect is, at a value plausible for it (a low-pass that
   an amplifier's bandwidth could be, a delay), is left to the catalog (:data:`~.prune.TWINS`), and
   an element C(s) fits better without (by BIC, refitted from where it was) is taken out
   (:mod:`.prune`).
2. **Search again beside C(s).**  The baseline times C(s) (its parameters free) starts a new
   search (offset test, forward, backward, swap and exchange) on the same records: a catalog
   effect is named only when it is significant beside C(s).  Each candidate starts from the
   current model and, on its own, from the fit in which C(s) was found (its material and
   values: C(s) refitted alone can fall into another valley).  The stand-ins of the first search
   (a delay for an AC coupling's phase lead, a 13 Hz amplifier pole for a lag network) are not.
3. **Better than C(s) of as many parameters.**  Each effect named beside C(s) stays only when
   it is plausible and C(s) grown by as many parameters as it has -- the best structure that
   holds C(s)'s elements and that many more, in the model without the effect -- does not beat
   it by ``min_delta_bic``.  An effect that fails is dropped (a step), and the forward
   search runs on without it (a delay that C(s) grown by a low-pass beats leaves room for
   the amplifier it stood in for).  C(s) is then chosen
   again on top of the effects named beside it; when its structure changes, steps 2-3 run
   again (at most :data:`MAX_ROUNDS` times).  The round whose named effects times C(s) have
   the lowest BIC is the result (all rounds fit the same records): a later round is a new
   candidate, not an improvement by construction.
4. **The result** (:func:`~.result.result`): C(s)'s values from a fit run to
   convergence, moved to the deepest minimum that profile scans of its parameters find,
   with 95 % profile-likelihood intervals (:mod:`.interval`), the
   held-out error of
   the named effects times C(s) against the floor.  The verdict's effects, and what keeps each
   (:mod:`.significance`), are those of the search beside C(s); its final model is theirs
   without C(s), fitted to the records.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..timefit import FitSpec
from .correction import ELEMENTS, correction_name, structures
from .correction_fit import (ALPHA0, band_hz, fit_structures, history_view, registered,
                             select_correction)
from .fitting import lowest, with_models
from .forward import catalog_search, forward_search
from .result import result
from .offset_test import OFFSET
from .prune import pruned
from .significance import membership

__all__ = ['outside_stage', 'MAX_ROUNDS']

#: C(s) is chosen again on top of the effects named beside it, at most this many times
MAX_ROUNDS = 3


def _triggered(state) -> bool:
    implausible = any(f.split('/')[0] in state.names() for f in state.current.flags)
    return implausible or not state.at_floor()


def _beside(view, best):
    """
    Return a fresh search state whose baseline is the view's baseline times ``best``'s C(s).

    Started from C(s) with the material it was fitted with and from the baseline's, each fit
    on its own and the lower chi^2 kept: its corners and the material lie in one narrow
    valley, and C(s) with another material can start a fit that ends in another (a lag
    network at the floor beside a 2.6 Hz low-pass restarted at 1.5x the floor; screened by
    their cost at the start, the baseline's material was refined and a lag network fitted
    beside a delay at the floor ended at 3.8x the floor without it).
    """
    name = correction_name(best.structure)
    values = best.fit.effect_values[name]
    base = view.baseline
    spec = FitSpec(base.spec.material, base.spec.effect_params
                   + tuple((name, p) for p in best.shape))
    models = [m.with_effect(name, **values) for m in base.fit.models]
    n_mat = len(base.spec.material)
    tail = best.x[-len(best.shape):]
    starts = [np.concatenate([base.x, tail])]
    if set(base.spec.effect_params) <= set(best.spec.effect_params):   # C(s)'s own material
        own = [n_mat + best.spec.effect_params.index(ep) for ep in base.spec.effect_params]
        starts.insert(0, np.concatenate([best.x[:n_mat], best.x[own], tail]))
    prepared = with_models(view.prepared, models)
    start = view.score(lowest(prepared, spec, [[x] for x in starts], view.folds,
                              view.settings.fold_nfev, priors=view.priors))
    inner = replace(view, baseline=start, chosen=[], steps=[], first_ranking=[],
                    first_ties=[], late_ties=[], replaced=set(), offset={}, kept_by={},
                    known=best)
    inner.adopt(start)
    return inner


def _rival(inner, name, structure, band):
    """C(s) grown by the parameters of ``name``, in the model without ``name`` (or None)."""
    k = sum(1 for e, _ in inner.current.spec.effect_params if e == name)
    order = sum(len(ELEMENTS[e]) for e in structure) + k
    if k == 0 or order > inner.settings.max_correction_order:
        return None
    grown = [st for st in structures(order, ALPHA0 not in inner.settings.free_material)
             if set(structure) <= set(st)]
    if not grown:
        return None
    cname = correction_name(structure)
    known = inner.current.fit.effect_values[cname]
    base = inner.without(cname, inner.without(name))
    cands = fit_structures(inner, base, grown, band, [known], material_from=inner.current)
    return min(cands, key=lambda c: c.fit.bic)


def _drop_failing(inner, structure, band) -> bool:
    """
    Drop each effect named beside C(s) that is implausible or C(s) grown beats (step 3).

    Returns True when one was dropped.
    """
    dropped = False
    for name, shape in list(inner.chosen):
        if name == OFFSET:
            continue
        why = None
        if any(f.startswith(f'{name}/') for f in inner.current.flags):
            why = 'implausible beside the correction C(s)'
        else:
            rival = _rival(inner, name, structure, band)
            if rival is not None and (rival.fit.bic
                                      <= inner.current.fit.bic - inner.settings.min_delta_bic):
                why = ('a correction C(s) with as many parameters fits better '
                       f"({'+'.join(rival.structure)}: BIC "
                       f'{rival.fit.bic - inner.current.fit.bic:+.0f})')
        if why:
            wo = inner.score(inner.without(name))
            inner.record(name, 'dropped', wo, why)
            inner.chosen.remove((name, shape))
            inner.adopt(wo)
            dropped = True
    return dropped


def _extend_steps(state, inner, outer) -> None:
    """
    Append the steps of the search beside C(s) as moves of the model the step list shows.

    That model holds the effects of the first search (``outer``) when C(s) is added, but the
    search beside C(s) starts again from the baseline times C(s): its first addition of one of
    them adds nothing to the list (``current_offset`` was listed as added twice).  It is
    listed as ``kept``, refitted beside C(s); one it never names is listed as ``dropped``.
    """
    touched = set()
    for st in inner.steps:
        if st.action == 'added' and st.effect in outer and st.effect not in touched:
            st = replace(st, action='kept', reason=(
                'in the model C(s) was fitted to; the search beside C(s), started from the '
                f'baseline times C(s), names it again: {st.reason}'))
        touched.add(st.effect)
        state.steps.append(st)
    for name in [n for n in outer if n not in touched]:
        state.record(name, 'dropped', inner.current,
                     'the search beside C(s), started from the baseline times C(s), does not '
                     f'name it (held-out error {inner.current.error:.4f} without it)')


def _adopt_inner(state, inner, best, structure) -> None:
    """
    Make the verdict's effects, steps and ties those of the search beside C(s).

    The final model (the named effects without C(s)) is fitted from the baseline, effect by
    effect, and from the fit beside C(s) less C(s); the lower chi^2 is kept (the first alone
    ended a lag network's plugin and an amplifier in another valley, 1.24x the floor, where
    the second is at the floor).
    """
    cname = correction_name(structure)
    state.record(cname, 'added', best,
                 f'the catalog left the held-out error at {state.current.error:.4f} '
                 f'({state.current.error / state.noise_floor:.2f}x the floor): C(s) = '
                 f"{' * '.join(structure)} fitted, searching again beside it")
    _extend_steps(state, inner, [n for n, _ in state.chosen])
    state.late_ties.extend([f'{t} (beside C(s))' for t in inner.first_ties] + inner.late_ties)
    state.chosen = list(inner.chosen)
    state.offset = inner.offset or state.offset
    state.kept_by = membership(inner)
    if not state.chosen:
        state.adopt(state.baseline)
        return
    fits = [state.refit_set(state.chosen), state.without(cname, inner.current)]
    state.adopt(state.score(min(fits, key=lambda c: c.fit.chi2)))


def _drop_implausible(state) -> None:
    """Drop named effects with implausible fitted values until none is left (stand-ins)."""
    while True:
        bad = [(n, sh) for n, sh in state.chosen
               if any(f.startswith(f'{n}/') for f in state.current.flags)]
        if not bad:
            return
        name, shape = bad[0]
        flags = [f for f in state.current.flags if f.startswith(f'{name}/')]
        wo = state.score(state.without(name))
        state.record(name, 'dropped', wo, 'implausible (' + '; '.join(flags) + '): the '
                     'correction C(s) is fitted without it')
        state.chosen.remove((name, shape))
        state.adopt(wo)


def _select(state, view, base, band):
    """C(s) on top of ``base``, pruned, scored; None unless it passes a step's rule."""
    best, tried = select_correction(view, base, band)
    if best is None:
        return None, tried
    with registered([best.structure]):
        best = pruned(view, best, band)
    if best is None:
        return None, tried
    with registered([best.structure]):
        best = view.score(best)
    gain = state.needed_gain(state.current.error)
    return (best if best.error <= (1 - gain) * state.current.error else None), tried


def outside_stage(state) -> None:
    """Run the stage (module docstring) when the search ended above the floor."""
    if not _triggered(state):
        return
    before = (list(state.chosen), state.current, len(state.steps))
    _drop_implausible(state)
    band = band_hz(state)
    view = history_view(state, band)
    best, tried = _select(state, view, view.current, band)
    if best is None:        # no C(s) stands for the dropped effects: they stay, as named
        state.chosen, current, n_steps = before
        del state.steps[n_steps:]
        state.adopt(current)
        return
    rounds = []         # (BIC of the named effects times C(s), C(s), the search beside it)
    for round_ in range(MAX_ROUNDS):
        with registered([best.structure]):
            state.say(f"correction C(s) = {' * '.join(best.structure)}: searching beside it")
            inner = _beside(view, best)
            catalog_search(inner)
            while _drop_failing(inner, best.structure, band):
                forward_search(inner, completion=False)     # a dropped effect is not offered
            rounds.append((inner.current.fit.bic, best, inner))
            catalog = inner.without(correction_name(best.structure))
        if round_ == MAX_ROUNDS - 1:
            break
        again, more = _select(state, view, catalog, band)
        if again is None or again.structure == best.structure:
            break
        best, tried = again, tried + more
    _, best, inner = min(rounds, key=lambda r: r[0])
    if len(rounds) > 1:
        state.say(f"correction C(s) = {' * '.join(best.structure)}: the lowest BIC of "
                  f'{len(rounds)} rounds')
    with registered([best.structure]):
        state.correction = result(inner, best.structure, tried)
        _adopt_inner(state, inner, best, best.structure)
