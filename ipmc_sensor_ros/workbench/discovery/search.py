# SPDX-License-Identifier: Apache-2.0
"""
The order of the stages of a diagnosis.

0. Mains lines are found in what the starting model leaves of the measured current and
   removed (:mod:`.residual`, :mod:`.lines`).  After stage 3 they are looked for again under
   the final model; when a strong line comes or goes (the starting model's error stood at a
   drive harmonic), stages 0-3 run again with the final model's lines.
1. The baseline (the given model, its free material and ``fit_effects`` parameters) is fitted
   to the line-free records and scored; the noise floor is measured.  Periodic records are
   predicted with the periodic history their FFT holds (:mod:`.history`).
2. The offset test (:mod:`.offset_test`) names ``current_offset`` when the mean residual
   current is significant.
3. Stepwise forward search (:mod:`.forward`) with the backward and swap checks after each
   addition, then the exchange pass when it ended above the floor (:mod:`.exchange`); once
   more if the exchange left the budget unspent above the floor, with replaced effects
   offered again (an amplifier pole that replaced a 3.3 ms delay as its tie, beside surface
   resistance, blocked the delay's return).
4. Outside the catalog (:mod:`.outside`): when the search ends above the floor, or a named
   effect is implausible, a low-order correction C(s) is fitted, and stages 2-3 run again with
   it in the model: the catalog effects named are those significant beside C(s).
5. The verdict: each named effect with the test that keeps it (:mod:`.significance`);
   ``explained`` when the final held-out error is at most ``explained_factor`` x floor + 0.001.
"""
from __future__ import annotations

import numpy as np

from ...physics.effects import EFFECTS, get_effect
from ..timefit import FitSpec
from .correction_fit import is_correction
from .drive import drive_of
from .fitting import evaluate, held_out, make_folds
from .forward import catalog_search
from .history import prepare_with_history
from .lines import parse_mains, summarize_lines
from .outside import outside_stage
from .ranking import baseline_starts
from .residual import clean, detect_lines, line_test, lines_changed, noise_floor
from .significance import membership
from .state import SearchState
from .verdict import Diagnosis

__all__ = ['run_search']


def _pool(records, settings) -> list[str]:
    present = set(records[0].model.effect_names)
    names = settings.candidates if settings.candidates is not None else [
        n for n in EFFECTS if not is_correction(n)]
    return [n for n in names if n not in present]


def _start(records, raw, drives, settings, priors, say, given=None) -> SearchState:
    """
    Lines out, baseline fitted and scored, noise floor measured (stages 0 and 1).

    ``raw``: the records as measured, prepared; ``drives``: their drives; ``given``: ``(lines,
    fitted)`` found already (under a final model), else found under the baseline fitted to
    ``raw``.
    """
    s = settings
    spec = FitSpec(s.free_material, tuple((e, p.name) for e in s.fit_effects
                                          for p in get_effect(e).parameters))
    folds, cv = make_folds(raw, s.n_folds)
    starts = baseline_starts(spec, priors, records[0].model)
    say('fitting baseline')
    fit, lines, fitted, left = None, [], [np.zeros(p.t.size) for p in raw], []
    if given is not None:
        lines, fitted, left = given
    elif parse_mains(s.mains) is not None:
        fit = evaluate(raw, spec, starts, folds, s.fold_nfev, priors=priors, scored=False)
        lines, fitted, left = detect_lines(records, raw, fit.fit.models, s, drives)
    prepared = clean(records, raw, fitted, s.settle_s, drives)
    if fit is not None and prepared is raw:         # no line: the fit is the baseline's
        baseline = held_out(raw, fit, folds, s.fold_nfev)
    else:
        baseline = evaluate(prepared, spec, [fit.x] if fit is not None else starts, folds,
                            s.fold_nfev, priors=priors)
    baseline.params = {**baseline.params, **{f'{e}.{n}': baseline.fit.effect_values[e][n]
                                             for e, n in spec.effect_params}}
    state = SearchState(s, prepared, folds, cv, spec, priors, _pool(records, s), say,
                        noise_floor=noise_floor(prepared), baseline=baseline,
                        lines=summarize_lines(lines), line_test=line_test(s, lines, left))
    state.line_rows, state.drives = lines, drives
    state.given_material = records[0].model.material
    state.adopt(baseline)
    return state


def _change(before: float, after: float) -> str:
    """
    Say what a held-out error did, in words that agree with its numbers.

    ``lowers the held-out error 0.0663 -> 0.0463 (1.43x)``, ``raises the held-out error
    0.0663 -> 0.0665 (+0.35 %)``: a change under 5 % is given in percent (a ratio rounds it
    to 1.00x).
    """
    if after == before:
        return f'leaves the held-out error at {before:.4f}'
    verb = 'lowers' if after < before else 'raises'
    tail = (f'{before / after:.2f}x' if abs(after / before - 1) >= 0.05
            else f'{100 * (after / before - 1):+.2g} %')
    return f'{verb} the held-out error {before:.4f} -> {after:.4f} ({tail})'


def _named_by(state, missing) -> str:
    """``name by its test (numbers)`` of each named effect (:func:`~.significance.membership`)."""
    kept = state.kept_by or {}
    return ', '.join(f"{n} by its {kept[n]['test']} ({kept[n]['summary']})" if n in kept
                     else n for n in missing)


def _reason(state, missing, explained) -> str:
    """
    Return the verdict's reason: what the named effects did to the held-out error, what kept them.

    An effect is named either because it lowers the held-out error (a step of the search) or
    because its own test keeps it (the offset's chi-square: ``||y - y_hat|| / ||y - mean y||``
    cannot see a mean current beside the dynamics).  When the error did not fall, the second
    is the reason, and the verdict says so with the test's numbers.
    """
    base, cur, floor = state.baseline, state.current, state.noise_floor
    if missing:
        text = f"adding {', '.join(missing)} {_change(base.error, cur.error)}"
        if cur.error >= base.error:
            text += ('; kept by ' + ('its own test' if len(missing) == 1 else 'their own tests')
                     + ', not by the held-out error: ' + _named_by(state, missing))
        return text + ('' if explained else f'; the residual stays above the noise floor '
                       f'{floor:.4f}: something else is missing too')
    if explained:
        return (f'baseline error {base.error:.4f} is at the noise floor ({floor:.4f}) and no '
                'effect improves it significantly: nothing is missing')
    return (f'baseline error {base.error:.4f} is above the noise floor {floor:.4f} and no '
            'catalog effect explains it')


def run_search(records, settings, priors, say) -> Diagnosis:
    """Run the stages of the module docstring; return the verdict."""
    drives = [drive_of(r) for r in records]
    raw = prepare_with_history(records, settings.settle_s, drives)
    state = _start(records, raw, drives, settings, priors, say)
    catalog_search(state)
    if parse_mains(settings.mains) is not None:
        final = detect_lines(records, raw, state.current.fit.models, settings, drives)
        if lines_changed(state.line_rows, final[0]):
            say('the lines under the final model differ from those under the baseline: '
                'searching again on the records without them')
            state = _start(records, raw, drives, settings, priors, say, given=final)
            catalog_search(state)
    if settings.correction:
        outside_stage(state)
    if not state.correction:
        state.kept_by = membership(state)
    missing = [e for e, _ in state.chosen]
    explained = bool(state.current.error <= state.explained_threshold)
    return Diagnosis(baseline=state.baseline, candidates=state.first_ranking,
                     noise_floor=state.noise_floor,
                     missing_effect=missing[0] if missing else None, explained=explained,
                     reason=_reason(state, missing, explained),
                     ties=state.first_ties + state.late_ties, prepared=state.prepared,
                     cv=state.cv, steps=state.steps, missing_effects=missing,
                     final=state.current, interference=state.lines,
                     offset_test=state.offset, line_test=state.line_test,
                     kept_by=state.kept_by, correction=state.correction,
                     unranked=state.unranked)
