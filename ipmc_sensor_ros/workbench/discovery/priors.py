# SPDX-License-Identifier: Apache-2.0
"""
Priors of effect parameters from data headers.

Data headers may give ``amplifier_bandwidth_hz``, ``time_delay_s``, ``current_offset_a`` or
``effect.parameter``: :func:`priors_from_headers`.  ``diagnose`` starts its fits there and flags
a fitted value more than :data:`PRIOR_FACTOR` away from its prior as implausible.
"""
from __future__ import annotations

from typing import Sequence

from ...errors import DataFormatError
from ...physics.effects import EFFECTS

__all__ = ['PRIOR_KEYS', 'PRIOR_FACTOR', 'priors_from_headers']

#: a fitted value more than this factor from its header prior is implausible (a header
#: states the instrument's setting; a factor 3 is beyond any tolerance of one)
PRIOR_FACTOR = 3.0

#: data-header keys that give a prior value of an effect parameter
PRIOR_KEYS = {'amplifier_bandwidth_hz': ('amplifier_bandwidth', 'corner_hz'),
              'time_delay_s': ('time_delay', 'delay_s'),
              'current_offset_a': ('current_offset', 'offset_a')}


def priors_from_headers(series: Sequence) -> dict[tuple[str, str], float]:
    """
    Effect-parameter priors from data headers; the first file giving a key wins.

    Keys: ``extra`` keys of :data:`PRIOR_KEYS` or ``effect.parameter``.
    """
    out: dict[tuple[str, str], float] = {}
    for ts in series:
        for key, raw in getattr(ts, 'extra', {}).items():
            target = PRIOR_KEYS.get(key) or (tuple(key.split('.', 1)) if '.' in key else None)
            if target is None or target[0] not in EFFECTS:
                continue
            try:
                out.setdefault(target, float(raw))
            except (TypeError, ValueError):
                raise DataFormatError(ts.path, None, f"header key '{key}' must be a number, "
                                      f'got {raw!r}') from None
    return out
