# SPDX-License-Identifier: Apache-2.0
"""
A fitted correction C(s) written as an effect plugin (``diagnose --save-plugin FILE``).

The file is plain Python that a user can read and edit: one
:class:`~ipmc_sensor_ros.physics.effects.Effect` subclass named after the file
(``ac_coupling.py`` -> ``ac_coupling``) when its name is a Python identifier, else
``measured_<elements>`` (e.g. ``measured_high_pass``), whose parameters default to the
fitted values, whose plausible range spans a factor 3 around them (the range a later fit
starts from and flags outside of), whose ``fitted_material`` is the material it was fitted
with (a later fit that adds it starts there too), and whose ``rational`` gives the exact
zeros, poles and gain (the delay apart), as the catalog effects do.  ``--plugin FILE`` loads
it in every verb (:func:`~ipmc_sensor_ros.physics.effects.load_plugin`); ``diagnose DATA
--plugin FILE`` then offers it as a candidate like any catalog effect.
"""
from __future__ import annotations

import datetime
import keyword
from pathlib import Path

from .correction import ELEMENTS, Correction

__all__ = ['plugin_name', 'plugin_source', 'write_plugin']

#: a plugin parameter's plausible range: this factor either side of the fitted value
TYPICAL_FACTOR = 3.0

_ELEMENT_CODE = {
    'gain': ["gain *= values['correction_gain']"],
    'low_pass': ["w = 2 * math.pi * values['low_pass_corner_hz']",
                 'poles.append(-w)', 'gain *= w'],
    'high_pass': ['zeros.append(0.0)',
                  "poles.append(-2 * math.pi * values['high_pass_corner_hz'])"],
    'lead_lag': ["wz = 2 * math.pi * values['lead_lag_zero_hz']",
                 "wp = 2 * math.pi * values['lead_lag_pole_hz']",
                 'zeros.append(-wz)', 'poles.append(-wp)', 'gain *= wp / wz'],
    'resonance': ["wn = 2 * math.pi * values['resonance_frequency_hz']",
                  "zeta = values['resonance_damping_ratio']",
                  'poles.extend(np.roots([1.0, 2 * zeta * wn, wn * wn]))', 'gain *= wn * wn'],
    'delay': [],
}
_EQUATION = {'gain': 'g', 'low_pass': '1/(1 + s/w_p)', 'high_pass': 's/(s + w_c)',
             'lead_lag': '(1 + s/w_z)/(1 + s/w_p)',
             'resonance': 'w_n^2/(s^2 + 2 zeta w_n s + w_n^2)', 'delay': 'exp(-s tau)'}


def plugin_name(structure, path=None) -> str:
    """Return the effect name: the file's stem if an identifier, else ``measured_<elements>``."""
    stem = Path(path).stem if path is not None else ''
    if stem.isidentifier() and not keyword.iskeyword(stem):
        return stem
    return 'measured_' + '_'.join(e for e in structure)


def _parameter_code(c: Correction, name: str) -> str:
    par = next(p for e in c.structure for p in ELEMENTS[e] if p.name == name)
    v = c.values[name]
    lo, hi = max(par.lower, v / TYPICAL_FACTOR), min(par.upper, v * TYPICAL_FACTOR)
    return (f'        EffectParameter({name!r}, {par.unit!r}, {v!r}, {par.lower!r}, '
            f'{par.upper!r},\n                        ({lo!r}, {hi!r}), '
            f'{par.description!r}),')


def plugin_source(c: Correction, name: str, data_files=(),
                  tool: str = 'ipmc-model diagnose') -> str:
    """Return the Python source of the plugin of ``c`` defining ``name`` (module docstring)."""
    cls = ''.join(part.capitalize() for part in name.split('_')) or 'Correction'
    stamp = f'{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC'
    files = ', '.join(str(f) for f in data_files) or 'the records given'
    sentence = c.sentence()
    body = '\n'.join(f'        {line}' for e in c.structure for line in _ELEMENT_CODE[e])
    params = '\n'.join(_parameter_code(c, p.name) for e in c.structure for p in ELEMENTS[e])
    material = '\n'.join(f'        {n!r}: {v!r},' for n, v in c.material.items())
    return f'''# SPDX-License-Identifier: Apache-2.0
"""
Correction C(s) found by {tool} on {stamp}.

{sentence}.

Data: {files}.  Load with ``--plugin THIS_FILE`` in any verb; ``ipmc-model diagnose DATA
--plugin THIS_FILE`` offers the effect ``{name}`` as a candidate.
"""
import math

import numpy as np

from ipmc_sensor_ros.physics.effects import Effect, EffectParameter


class {cls}(Effect):
    """C(s) = {' * '.join(_EQUATION[e] for e in c.structure)}, fitted (module docstring)."""

    name = {name!r}
    summary = {('Measured correction: ' + c.words())!r}
    physics = {sentence!r}
    equation = {('H -> H * ' + ' * '.join(_EQUATION[e] for e in c.structure))!r}
    signature = 'the residual the catalog left, fitted as a factor of H(s) over all records'
    reference = {f'{tool}, {stamp}, data: {files}'!r}
    parameters = (
{params}
    )
    fitted_material = {{
{material}
    }}

    def rational(self, model, values):
        """Zeros, poles (rad/s) and gain of C(s) without its delay."""
        zeros, poles, gain = [], [], 1.0
{body or '        pass'}
        return np.array(zeros, complex), np.array(poles, complex), gain

    def factor(self, s, model, values):
        zeros, poles, gain = self.rational(model, values)
        s = np.asarray(s, complex)
        out = gain * np.prod(s[..., None] - zeros, axis=-1) / np.prod(s[..., None] - poles,
                                                                      axis=-1)
        return out * np.exp(-s * self.delay_s(values))

    def delay_s(self, values):
        return float(values.get('correction_delay_s', 0.0))
'''


def write_plugin(path, c: Correction, data_files=(), tool: str = 'ipmc-model diagnose',
                 name: str | None = None) -> str:
    """Write the plugin of ``c`` to ``path``; return the effect's name (:func:`plugin_name`)."""
    name = name or plugin_name(c.structure, path)
    Path(path).write_text(plugin_source(c, name, data_files, tool))
    return name
