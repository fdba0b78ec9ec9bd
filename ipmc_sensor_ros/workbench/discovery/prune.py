# SPDX-License-Identifier: Apache-2.0
"""
C(s) pruned: elements a catalog effect is, and elements it fits better without, taken out.

Used by the outside stage (:mod:`.outside`) on each C(s) chosen by BIC (:func:`pruned`).
"""
from __future__ import annotations

import copy

import numpy as np

from ...physics.effects import effect_parameter
from .correction import (AMPLIFIER, ELEMENTS, POLE_PAIR, canonical, correction_name,
                         exchanged)
from .correction_fit import fit_structures, registered

__all__ = ['pruned', 'smaller', 'TWINS']

#: elements of C(s) that a catalog effect is: element -> (effect, parameter)
TWINS = {'low_pass': AMPLIFIER, 'delay': ('time_delay', 'delay_s')}


def pruned(view, best, band):
    """
    C(s) less its elements that a catalog effect is, then less those it fits better without.

    A low-pass whose corner an amplifier's bandwidth could be, a delay a channel skew could
    be: the catalog effect is the same factor and takes the element's place, and a tie goes
    to the catalog (the search beside C(s) names it if it is significant, started from
    this fit: :attr:`~.state.SearchState.known`); a low-pass beside a lead-lag is judged by the
    pole it takes (:func:`~.correction.canonical`: a 3.2 Hz low-pass beside a 7.8 Hz zero
    and a 216 Hz pole is a 216 Hz amplifier beside a lag network).  Then each element is
    taken out in turn and C(s) refitted from the values and material it had
    (:func:`smaller`): the lowest BIC wins, again until no removal lowers it.  The order
    chosen by BIC from a grid of starts can keep an element that does nothing (a low-pass
    run to its 100 kHz bound beside a lead-lag) when the smaller structure's own starts
    ended in a worse valley.  Returns the refitted smaller C(s), ``best`` itself when
    nothing is stripped, or None when nothing is left.
    """
    values = canonical(best.structure, best.fit.effect_values[correction_name(best.structure)])
    keep = tuple(e for e in best.structure if not (
        e in TWINS and _plausible(TWINS[e], values[ELEMENTS[e][0].name])))
    if keep != best.structure:
        twins = [(*TWINS[e], values[ELEMENTS[e][0].name]) for e in best.structure
                 if e not in keep]
        best = smaller(view, best, keep, band, twins)
    while best is not None:
        elements = [e for e in best.structure if e != 'gain']
        if len(elements) < 2:
            return best
        with registered([best.structure]):
            top = min((smaller(view, best, tuple(k for k in best.structure if k != e), band)
                       for e in elements), key=lambda c: c.fit.bic)
        if top.fit.bic >= best.fit.bic:
            return best
        best = top
    return None


def smaller(view, best, keep, band, twins=()):
    """
    C(s) of structure ``keep`` fitted from ``best``'s values and material (None if empty).

    ``twins``: ``(effect, parameter, value)`` of the catalog effects that take the place of
    the elements taken out (each added to the model, started at the element's value, unless
    the model has it already): the factor stays in the model C(s) is fitted in.  A twin
    fitted alone, before C(s), can run to a bound (a delay fitted to a resonance's phase ran
    to 0.1 s), so C(s) is fitted from both: the twin as fitted and at the element's value;
    the lower BIC is kept.

    Also from its values with a low-pass and a lead-lag's pole exchanged (the same C(s)), so
    that taking out either element can leave either pole (a lead-lag whose pole ran to its
    bound beside a low-pass at the lag's pole: without the low-pass, the lead-lag takes it).
    """
    if not keep or keep == ('gain',):
        return None
    name = correction_name(best.structure)
    values = best.fit.effect_values[name]
    known = [values]
    if set(POLE_PAIR) <= set(values):
        known.append(exchanged(values))
    base = view.without(name, best)
    at_value = np.array(base.x, float)
    for effect, param, value in twins:
        if all(e != effect for e, _ in base.spec.effect_params):
            base = view.job(base)((effect, (param,), [[float(np.log(value))]]))
            at_value = np.append(at_value, np.log(value))
    bases = [base]
    if at_value.size == base.x.size and not np.array_equal(at_value, base.x):
        bases.append(copy.copy(base))
        bases[-1].x = at_value
    return min((fit_structures(view, b, [keep], band, known, material_from=best)[0]
                for b in bases), key=lambda c: c.fit.bic)


def _plausible(twin, value) -> bool:
    lo, hi = effect_parameter(*twin).typical
    return lo <= value <= hi
