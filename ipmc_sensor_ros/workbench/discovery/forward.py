# SPDX-License-Identifier: Apache-2.0
"""
Stepwise forward selection: one effect at a time, the best significant one.

At each step every catalog (and plugin) effect not yet in the model is added in turn and every
free parameter refitted (material, the effects chosen so far, the candidate's, from several
starts across its plausible range).  Only the candidates whose full-data BIC drops by at least
``min_delta_bic`` are scored by their held-out error (at most ``max_cv`` of them, the lowest
BIC: the others cannot be significant).  They are ranked (:func:`~.ranking.rank`) and the
winner is added if it is significant: it lowers the held-out error by at least the needed
gain (:meth:`~.state.SearchState.needed_gain`) **and** the BIC by ``min_delta_bic``.  Each
addition is followed by the backward check (:mod:`.backward`) and the swap check
(:mod:`.exchange`).
"""
from __future__ import annotations

from .backward import backward_check
from .exchange import exchange_pass, swap_check
from .offset_test import add_offset
from .ranking import merge_shapes, rank, shapes

__all__ = ['forward_search', 'forward_step', 'catalog_search']


def _score_step(state, items):
    """Fit ``items`` on the current model; score the contenders; return them ranked."""
    s = state.settings
    job = state.job()
    fitted = state.run(job, items)
    contenders = sorted((c for c in fitted
                         if c.fit.bic <= state.current.fit.bic - s.min_delta_bic),
                        key=lambda c: c.fit.bic)[:s.max_cv]
    state.say(f'step {len(state.steps) + 1}: held-out error of {len(contenders)} contender(s)')
    scored = state.run(job, contenders)
    ranked = merge_shapes(scored, s.tie_tol)
    shown = {c.effect for c in ranked}          # one shape per effect, in-sample ones too
    others = merge_shapes([c for c in fitted if not any(c is k for k in contenders)
                           and c.effect not in shown], s.tie_tol)
    return rank(ranked, s.tie_tol) + sorted(others, key=lambda c: c.error)


def _passes(state, c) -> bool:
    """Return the rule of a step: held-out gain and BIC drop against the current model."""
    cur = state.current
    return (c.held_out and c.error <= (1 - state.needed_gain(cur.error)) * cur.error
            and c.fit.bic <= cur.fit.bic - state.settings.min_delta_bic)


def forward_step(state, excluded: set) -> bool:
    """Add the best significant effect not in ``excluded``; False when none passes."""
    remaining = [n for n in state.pool if n not in state.names() | excluded]
    if not remaining:
        return False
    items = [(n, sh) for n in remaining for sh in shapes(n)]
    state.say(f'step {len(state.steps) + 1}: {len(items)} candidate fits on '
              f'{min(state.settings.workers, len(items))} process(es)')
    ranked = _score_step(state, items)
    first = not state.first_ranking
    if first:
        state.first_ranking = ranked
    best = ranked[0]
    if not _passes(state, best):
        return False
    cur, tol = state.current, state.settings.tie_tol
    ties = [c for c in ranked[1:] if c.error <= (1 + tol) * best.error and _passes(state, c)]
    if first:
        state.first_ties = [c.effect for c in ties]
    else:
        state.late_ties.extend(
            f'{c.effect} instead of {best.effect} (held-out error {c.error:.4f} vs '
            f'{best.error:.4f}, dBIC {c.fit.bic - best.fit.bic:+.0f})' for c in ties)
    reason = (f'held-out error {cur.error:.4f} -> {best.error:.4f} '
              f'({cur.error / best.error:.2f}x), BIC -{cur.fit.bic - best.fit.bic:.0f}')
    if ties:
        reason += '; tie broken by ' + (
            'plausibility' if best.plausible and any(not t.plausible for t in ties) else 'BIC')
    tie_rows = [{'effect': t.effect, 'error': t.error, 'delta_bic': t.fit.bic - best.fit.bic,
                 'params': t.params, 'flags': t.flags} for t in ties]
    state.record(best.effect, 'added', best, reason, ties=tie_rows,
                 alternatives=[c.effect for c in ranked[1:] if c.held_out and c.plausible])
    state.chosen.append((best.effect, best.shape))
    state.adopt(best)
    backward_check(state)
    swap_check(state)
    return True


def forward_search(state, completion: bool) -> None:
    """
    Add effects until the floor, the budget or nothing significant is left.

    An effect dropped by the backward check is not offered again; one replaced by a swap is
    offered again only in the ``completion`` pass (:mod:`.search`).
    """
    s = state.settings
    if not state.first_ranking:
        state.unranked = _unranked(state)
    while len(state.chosen) < s.max_effects and not state.at_floor():
        excluded = {st.effect for st in state.steps if st.action == 'dropped'}
        if not completion:
            excluded |= state.replaced
        if not forward_step(state, excluded):
            break


def _unranked(state) -> str:
    """Return why the forward search would rank no effect now ('' when it will rank)."""
    s, names = state.settings, ', '.join(name for name, _ in state.chosen)
    if len(state.chosen) >= s.max_effects:
        return f'--max-effects {s.max_effects} used up by {names} (the offset test)'
    if state.at_floor():
        return (f'the held-out error {state.current.error:.4f} is within {s.stop_factor:g} x '
                f'the noise floor {state.noise_floor:.4f}'
                + (f' once {names} (the offset test) is in' if names else ''))
    return ''


def catalog_search(state) -> None:
    """
    Return the offset test, then the forward search and its checks, then the exchange pass.

    Once more when the exchange left the budget unspent above the floor, with the effects a
    swap had replaced offered again (an amplifier pole that replaced a 3.3 ms delay as its
    tie, beside surface resistance, blocked the delay's return).
    """
    add_offset(state)
    for completion in (False, True):
        if completion and (len(state.chosen) >= state.settings.max_effects
                           or state.at_floor() or not state.replaced):
            break               # (nothing replaced: the pass would repeat the last step)
        n_steps = len(state.steps)
        forward_search(state, completion)
        if completion and len(state.steps) == n_steps:
            break                   # nothing added: the exchange pass would repeat itself
        exchange_pass(state)
