# SPDX-License-Identifier: Apache-2.0
"""
Glue of the discovery loop for the command line: which names are fitted, what to run next.

* ``--effects name`` without values means *fit its parameters* (in ``fit`` and
  ``diagnose``): :func:`effects_to_fit`.
* ``--free`` takes material symbols (d, alpha0, ...), full material names and
  effect parameters (``delay_s``, or ``time_delay.delay_s`` when ambiguous):
  :func:`free_names`.
* The printed verdict ends with the exact next command: :func:`next_command`.
* Data headers may give priors of effect parameters: :mod:`.priors`.
"""
from __future__ import annotations

import shlex
from typing import Sequence

from ...physics.effects import get_effect
from ...physics.model import parse_effects
from ..fitmap import FITTABLE
from ..identifiability import SYMBOLS

__all__ = [
    'SYMBOL_TO_NAME',
    'free_names',
    'effects_to_fit',
    'effect_free_names',
    'acts_on_transfer',
    'next_command',
    'diagnosis_next_command',
]

#: The paper's symbol of each fittable material parameter -> its name (one table: SYMBOLS).
SYMBOL_TO_NAME = {symbol: name for name, symbol in SYMBOLS.items() if name in FITTABLE}


def free_names(text: str) -> tuple[str, ...]:
    """
    Comma list -> names: material symbols mapped to full names.

    Effect parameters kept (resolved against the model by
    :func:`~ipmc_sensor_ros.workbench.fitmap.resolve_effect_parameter`).
    """
    return tuple(
        SYMBOL_TO_NAME.get(x, x) for x in (s.strip() for s in (text or '').split(',')) if x
    )


def effects_to_fit(text: str) -> list[str]:
    """
    Return the effects of an ``--effects`` text given by name only (no ``(...)``).

    Their parameters are fitted.
    """
    out, depth, cur = [], 0, ''
    for ch in (text or '') + ',':
        if ch == ',' and depth == 0:
            item = cur.strip()
            if item and '(' not in item:
                out.append(item)
            cur = ''
            continue
        depth += (ch == '(') - (ch == ')')
        cur += ch
    parse_effects(','.join(out))          # unknown names: the usual clear error
    return [n for n in out if get_effect(n).parameters]


def effect_free_names(effects: Sequence[str], frequency_domain: bool = False) -> tuple[str, ...]:
    """
    Qualified parameter names of ``effects``.

    ``frequency_domain``: only of effects that act on the transfer function, the only
    ones a frequency-response fit can see.
    """
    return tuple(f'{e}.{p.name}' for e in effects for p in get_effect(e).parameters
                 if not frequency_domain or acts_on_transfer(e))


def acts_on_transfer(name: str) -> bool:
    """Return True if effect ``name`` changes H(s) (overrides ``factor``)."""
    from ...physics.effects import Effect

    return type(get_effect(name)).factor is not Effect.factor


def next_command(verb: str, data: Sequence[str], model_file: str | None, extra: str = '') -> str:
    """``ipmc-model VERB DATA... --model-file FILE`` quoted for a POSIX shell."""
    parts = ['ipmc-model', verb, *[str(d) for d in data]]
    if model_file:
        parts += ['--model-file', str(model_file)]
    return ' '.join(shlex.quote(p) for p in parts) + (f' {extra}' if extra else '')


def diagnosis_next_command(diag, data: Sequence[str], model_file: str | None,
                           base: str = 'h1', plugin_file: str | None = None) -> str:
    """
    Return what to run after a diagnosis.

    With a saved correction plugin: diagnose again with it; with a saved model: check it on
    the data (compare); otherwise fit the named effects, or, when ``fit`` cannot see any of
    them (an offset: no frequency response shows it), diagnose again keeping the model.
    """
    if plugin_file:
        return ('next (the correction C(s) as a candidate effect): '
                + next_command('diagnose', data, None, f'--model {base} --plugin '
                               + shlex.quote(str(plugin_file))))
    if model_file:
        return 'next: ' + next_command('compare', data, model_file)
    if diag.missing_effects:
        names = [e for e in diag.missing_effects if e != 'surface_resistance']
        b = 'h2' if 'surface_resistance' in diag.missing_effects or base == 'h2' else 'h1'
        if names and not any(acts_on_transfer(e) for e in names):
            them = 'it' if len(names) == 1 else 'them'
            return ('next (a frequency-response fit cannot see ' + ', '.join(names) + '; the '
                    f'diagnosis fitted {them} in time: keep {them} in a model file): '
                    + next_command('diagnose', data, None, f'--model {b} --save-model model.yaml'))
        effects = ','.join(names)
        cmd = ['ipmc-model', 'fit', *map(str, data), '--model', b] + (
            ['--effects', effects] if effects else []
        )
        return (
            "next (fits the named effects' parameters with the material; add --save-model FILE "
            'to keep them): ' + ' '.join(shlex.quote(p) for p in cmd)
        )
    return 'next: ' + next_command('compare', data, None, f'--model {base}')
