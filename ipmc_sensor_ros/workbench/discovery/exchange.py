# SPDX-License-Identifier: Apache-2.0
"""
Exchanges: an early pick that stood in for what was missing is replaced.

* **Swap check** (after each addition): an earlier pick against its plausible scored
  runners-up of the step that chose it, now that the model holds more (e.g. an amplifier
  droop that stood in for delay + beam inertia).  A swap needs a lower BIC and a lower
  held-out error; a runner-up within ``tie_tol`` is reported as a tie.  The set without the
  earlier pick is also built afresh from the baseline (the kept effects' values may sit in
  the removed effect's basin), the lower BIC kept.
* **Exchange pass** (when the search ended above the noise floor, whether or not the result
  counts as explained): each chosen effect but the offset is tried against every effect not
  in the model, all refitted; the best exchange that passes the significance rule is made,
  until none does (from H1, a 5 ms delay took the slot of surface resistance and a 50 Hz
  amplifier pole together; a 44 Hz pole stood in for a 3.3 ms delay and beam inertia at 23 Hz).
"""
from __future__ import annotations

from .offset_test import OFFSET
from .ranking import shapes

__all__ = ['swap_check', 'exchange_pass']


def _tie_or_swap(state, name, shape, alt, alt_shape, cand) -> bool:
    """Report ``cand`` (``alt`` instead of ``name``) as a tie, make the swap if it wins."""
    cur, tol = state.current, state.settings.tie_tol
    # a tie whichever BIC is lower (e.g. delay + beam inertia vs amplifier + beam inertia,
    # 0.6 % apart); a swap only with the lower BIC and held-out error
    if cand.error <= (1 + tol) * cur.error and (
            cand.error >= cur.error or cand.fit.bic >= cur.fit.bic):
        state.late_ties.append(f'{alt} instead of {name} (held-out error {cand.error:.4f} vs '
                               f'{cur.error:.4f}, dBIC {cand.fit.bic - cur.fit.bic:+.0f})')
    if not (cand.error < cur.error and cand.fit.bic < cur.fit.bic):
        return False
    state.record(alt, 'swapped', cand,
                 f'replaces {name} (its tie): held-out error {cur.error:.4f} -> '
                 f'{cand.error:.4f}, BIC -{cur.fit.bic - cand.fit.bic:.0f}')
    state.chosen[state.chosen.index((name, shape))] = (alt, alt_shape)
    state.replaced.add(name)
    state.adopt(cand)
    return True


def swap_check(state) -> None:
    """Try each earlier pick against the plausible runners-up of the step that added it."""
    for name, shape in list(state.chosen[:-1]):
        if (name, shape) not in state.chosen:
            continue
        added = [st for st in state.steps
                 if st.effect == name and st.action in ('added', 'swapped')]
        base = None
        for alt in [a for st in added[-1:] for a in st.alternatives]:
            if alt in state.names() or alt in state.replaced:
                continue
            if base is None:        # the model without `name`: the same for every alt
                base = state.without(name)
            alt_shape = shapes(alt)[0]
            cand = state.job(base)((alt, alt_shape))
            fresh = state.refit_set([(alt, alt_shape)]
                                    + [c for c in state.chosen if c != (name, shape)])
            if fresh.fit.bic < cand.fit.bic:
                cand = fresh
            if not cand.plausible:
                continue
            if _tie_or_swap(state, name, shape, alt, alt_shape, state.score(cand)):
                break


def _best_exchange(state):
    """Return the best significant exchange of one chosen effect (but the offset), or None."""
    s = state.settings
    best = None
    for name, shape in [c for c in state.chosen if c[0] != OFFSET]:
        base = state.without(name)
        job = state.job(base)
        items = [(n, sh) for n in state.pool if n not in state.names() for sh in shapes(n)]
        state.say(f'exchange {name}: {len(items)} candidate fits')
        # plausible in its own parameters (the model kept may carry flags of its own, e.g.
        # an offset drift beyond the typical range, shared by every candidate)
        fitted = [c for c in state.run(job, items)
                  if not any(f.startswith(f'{c.effect}/') for f in c.flags)
                  and c.fit.bic <= state.current.fit.bic - s.min_delta_bic]
        fitted = sorted(fitted, key=lambda c: c.fit.bic)[:s.max_cv]
        gain = state.needed_gain(state.current.error)
        for cand in state.run(job, fitted):
            if cand.held_out and cand.error <= (1 - gain) * state.current.error and (
                    best is None or cand.error < best[1].error):
                best = ((name, shape), cand)
    return best


def exchange_pass(state) -> None:
    """Make the best significant exchange until none passes or the floor is reached."""
    for _ in range(len(state.chosen)):
        if state.at_floor():
            break
        best = _best_exchange(state)
        if best is None:
            break
        (name, shape), cand = best
        cur = state.current
        state.record(cand.effect, 'swapped', cand,
                     f'replaces {name} (exchange pass, the search had ended above the '
                     f'noise floor): held-out error {cur.error:.4f} -> {cand.error:.4f}, '
                     f'BIC -{cur.fit.bic - cand.fit.bic:.0f}')
        state.chosen[state.chosen.index((name, shape))] = (cand.effect, cand.shape)
        state.replaced.add(name)
        state.adopt(cand)
