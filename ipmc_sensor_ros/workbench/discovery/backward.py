# SPDX-License-Identifier: Apache-2.0
"""
The backward check, after each addition: an earlier effect that the model no longer needs goes.

An effect chosen earlier is dropped when its own test (:mod:`.significance`: the offset's
chi-square, the BIC test) is not significant beside the effects chosen since **and** removing
it raises the held-out error by less than :data:`DROP_TOLERANCE`.  An effect whose own test
is significant stays, whatever the held-out error says.  A dropped effect is not offered again
(no add/drop cycles).
"""
from __future__ import annotations

from .significance import describe, own_test

__all__ = ['DROP_TOLERANCE', 'backward_check']

#: removing an effect may raise the held-out error by at most this fraction (1 %: the
#: scatter of the held-out error between refits of one model is a few tenths of a percent)
DROP_TOLERANCE = 0.01


def backward_check(state) -> None:
    """Drop each earlier effect (all but the last added) that neither test keeps."""
    for name, shape in list(state.chosen[:-1]):
        test, wo = own_test(state, name)
        if test['significant']:
            continue
        wo = state.score(wo)
        if wo.error > (1 + DROP_TOLERANCE) * state.current.error:
            continue
        state.record(name, 'dropped', wo,
                     f'its own test is not significant ({describe(test)}) and removing it '
                     f'costs nothing (held-out error {state.current.error:.4f} -> '
                     f'{wo.error:.4f})')
        state.chosen.remove((name, shape))
        state.adopt(wo)
