# SPDX-License-Identifier: Apache-2.0
"""
A low-order multiplicative correction C(s) of the model, in physical words.

C(s) is a product of **elements**, each a small rational factor with real poles and zeros, a
second-order resonance, or a pure delay (and a gain when alpha0 is not free to take it)::

    low_pass    1 / (1 + s/w_p)                      a pole: an amplifier's bandwidth
    high_pass   s / (s + w_c)                        a zero at 0 and a pole: AC coupling
    lead_lag    (1 + s/w_z) / (1 + s/w_p)            a real zero and pole: an RC network
    resonance   w_n^2 / (s^2 + 2 zeta w_n s + w_n^2)  a complex pole pair: a mechanical mode
    delay       exp(-s tau)                           channel skew
    gain        g                                     a calibration factor

with ``w = 2 pi f``.  A **structure** is a set of elements (at most one of each); its order is
its number of parameters.  :func:`correction_class` makes an :class:`~ipmc_sensor_ros.physics.
effects.Effect` of a structure, whose ``rational`` gives the exact zeros, poles and gain (the
delay apart, as the pipeline takes every effect's delay), so that fitting, reduction and the
estimator treat it like a catalog effect.  :class:`Correction` is the fitted result: values,
simultaneous 95 % profile-likelihood intervals (:mod:`.interval`), and the sentence that says
what it is.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...physics.effects import Effect, EffectParameter, effect_parameter

__all__ = ['ELEMENTS', 'PREFIX', 'POLE_PAIR', 'AMPLIFIER', 'structures', 'assign_poles',
           'canonical', 'exchanged', 'correction_name', 'correction_class', 'Correction']

#: internal effect names of C(s) start with this (never offered as catalog candidates)
PREFIX = 'correction_'

_CORNER = dict(unit='Hz', default=1.0, lower=1e-3, upper=1e5, typical=(1e-3, 1e5))


def _par(name, description, **kw):
    spec = {**_CORNER, **kw}
    return EffectParameter(name, spec['unit'], spec['default'], spec['lower'], spec['upper'],
                           spec['typical'], description)


#: element -> its parameters (fit in log space; bounds are the fit's, typical = bounds: C(s)
#: is empirical, nothing about it is implausible)
ELEMENTS = {
    'low_pass': (_par('low_pass_corner_hz', 'corner f_p of the pole'),),
    'high_pass': (_par('high_pass_corner_hz', 'corner f_c of the high-pass'),),
    'lead_lag': (_par('lead_lag_zero_hz', 'corner f_z of the zero'),
                 _par('lead_lag_pole_hz', 'corner f_p of the pole')),
    'resonance': (_par('resonance_frequency_hz', 'natural frequency f_n'),
                  _par('resonance_damping_ratio', 'damping ratio zeta', unit='1', default=0.2,
                       lower=1e-3, upper=5.0, typical=(1e-3, 5.0))),
    'delay': (_par('correction_delay_s', 'pure delay tau', unit='s', default=1e-3,
                   lower=1e-7, upper=0.1, typical=(1e-7, 0.1)),),
    'gain': (_par('correction_gain', 'gain g', unit='1', lower=1e-3, upper=1e3,
                  typical=(1e-3, 1e3)),),
}
_ORDER = ('gain', 'high_pass', 'low_pass', 'lead_lag', 'resonance', 'delay')


def structures(order: int, with_gain: bool) -> list[tuple[str, ...]]:
    """All structures of ``order`` parameters (at most one of each element; 'gain' forced)."""
    pool = [e for e in _ORDER if e != 'gain']
    need = order - (1 if with_gain else 0)
    out = []

    def grow(start, chosen, n):
        if n == need and chosen:
            out.append((('gain',) if with_gain else ()) + tuple(chosen))
            return
        for k in range(start, len(pool)):
            size = len(ELEMENTS[pool[k]])
            if n + size <= need:
                grow(k + 1, chosen + [pool[k]], n + size)

    grow(0, [], 0)
    return out


def correction_name(structure) -> str:
    """Return the internal effect name of a structure, e.g. ``correction_high_pass_delay``."""
    return PREFIX + '_'.join(e for e in structure if e != 'gain') + (
        '_gain' if 'gain' in structure else '')


#: the two parameters that a low-pass beside a lead-lag can exchange (the same C(s))
POLE_PAIR = ('low_pass_corner_hz', 'lead_lag_pole_hz')
#: the catalog's low-pass (effect, parameter), which can exchange its corner with a lead-lag's
#: pole as C(s)'s own low-pass can
AMPLIFIER = ('amplifier_bandwidth', 'corner_hz')


def assign_poles(zero_hz: float, poles_hz) -> tuple[float, float]:
    """
    Return ``(lead-lag's pole, low-pass's pole)`` of two poles beside a lead-lag's zero.

    ``(1 + s/w_z) / ((1 + s/w_p)(1 + s/w_a))`` is symmetric in ``w_p`` and ``w_a``: a low-pass
    (C(s)'s own, or an amplifier's bandwidth named beside C(s)) and a lead-lag are the same
    factor with either pole in either element.  The low-pass takes the pole an amplifier's
    bandwidth can be (its plausible range); when both or neither can, the one farther from
    the zero (a 6.9 Hz lag network behind a 37 Hz amplifier came out as a 37 Hz lag pole
    beside a 6.9 Hz amplifier; a 2.6 Hz one behind a 149 Hz amplifier as a 2.6 Hz low-pass
    beside a 5.4 Hz zero with a 149 Hz pole).
    """
    lo, hi = effect_parameter(*AMPLIFIER).typical
    a, b = poles_hz
    fits = [lo <= a <= hi, lo <= b <= hi]
    if fits[0] != fits[1]:
        return (b, a) if fits[0] else (a, b)
    far = abs(math.log(a / zero_hz)) >= abs(math.log(b / zero_hz))
    return (b, a) if far else (a, b)


def exchanged(values: dict) -> dict:
    """Exchange the low-pass's corner and the lead-lag's pole of ``values`` (the same C(s))."""
    low, pole = POLE_PAIR
    return {**values, low: values[pole], pole: values[low]}


def canonical(structure, values: dict) -> dict:
    """``values`` with a low-pass and a lead-lag's pole assigned by :func:`assign_poles`."""
    if not {'low_pass', 'lead_lag'} <= set(structure):
        return dict(values)
    pole, low = assign_poles(values['lead_lag_zero_hz'], [values[n] for n in POLE_PAIR])
    return exchanged(values) if values[POLE_PAIR[0]] != low else dict(values)


def _zpk(structure, v) -> tuple[list, list, float]:
    """Zeros, poles (rad/s) and gain of the rational part of C(s)."""
    z, p, k = [], [], 1.0
    for e in structure:
        if e == 'low_pass':
            w = 2 * math.pi * v['low_pass_corner_hz']
            p, k = p + [-w], k * w
        elif e == 'high_pass':
            z, p = z + [0.0], p + [-2 * math.pi * v['high_pass_corner_hz']]
        elif e == 'lead_lag':
            wz, wp = 2 * math.pi * v['lead_lag_zero_hz'], 2 * math.pi * v['lead_lag_pole_hz']
            z, p, k = z + [-wz], p + [-wp], k * wp / wz
        elif e == 'resonance':
            wn, zeta = 2 * math.pi * v['resonance_frequency_hz'], v['resonance_damping_ratio']
            p, k = p + list(np.roots([1.0, 2 * zeta * wn, wn * wn])), k * wn * wn
        elif e == 'gain':
            k *= v['correction_gain']
    return z, p, k


def correction_class(structure, name: str | None = None) -> type:
    """Return an Effect subclass for ``structure`` (module docstring); not registered."""
    structure = tuple(structure)
    params = tuple(p for e in structure for p in ELEMENTS[e])

    def rational(self, model, values):
        z, p, k = _zpk(structure, values)
        return np.asarray(z, complex), np.asarray(p, complex), k

    def factor(self, s, model, values):
        z, p, k = self.rational(model, values)
        s = np.asarray(s, complex)
        out = k * np.prod(s[..., None] - z, axis=-1) / np.prod(s[..., None] - p, axis=-1)
        return out * np.exp(-s * self.delay_s(values))

    def delay_s(self, values):
        return float(values.get('correction_delay_s', 0.0))

    body = {'name': name or correction_name(structure), 'structure': structure,
            'parameters': params, 'summary': 'Correction C(s) fitted by diagnose',
            'equation': ' * '.join(structure), 'rational': rational, 'factor': factor,
            'delay_s': delay_s}
    return type(f"C_{'_'.join(structure)}", (Effect,), body)


def _interval(value, lo, hi, unit='', scale=1.0) -> str:
    """``value unit [lo, hi]``, with digits enough to show the interval's width (2 of it)."""
    value, lo, hi = value * scale, lo * scale, hi * scale
    half = max(0.5 * (hi - lo), abs(value) * 1e-9)
    digits = int(min(9, max(3, np.ceil(np.log10(max(abs(value), 1e-300) / half)) + 1)))
    unit = f' {unit}' if unit else ''
    return f'{value:.{digits}g}{unit} [{lo:.{digits}g}, {hi:.{digits}g}]'


@dataclass
class Correction:
    """A fitted C(s): structure, values, simultaneous 95 % intervals, what it explains."""

    structure: tuple
    values: dict
    ci95: dict
    error: float                 # held-out error of the catalog model times C(s)
    noise_floor: float
    delta_bic: float             # BIC of the catalog model times C(s) minus the catalog model's
    tried: list = field(default_factory=list)    # (structure, BIC) of every structure fitted
    model_effects: tuple = ()     # the catalog effects it was fitted with
    material: dict = field(default_factory=dict)    # the free material it was fitted with

    def words(self) -> str:
        """Return the elements in physical words with their simultaneous 95 % intervals."""
        v, ci, out = self.values, self.ci95, []

        def iv(name, unit='Hz', scale=1.0):
            return _interval(v[name], *ci[name], unit, scale)

        for e in self.structure:
            if e == 'high_pass':
                tau = 1 / (2 * math.pi * v['high_pass_corner_hz'])
                out.append(f"a first-order high-pass, corner {iv('high_pass_corner_hz')}, e.g. "
                           f'an AC-coupled amplifier (time constant {tau:.3g} s)')
            elif e == 'low_pass':
                out.append(f"a first-order low-pass, corner {iv('low_pass_corner_hz')}, e.g. an "
                           "amplifier's bandwidth or an anti-alias filter")
            elif e == 'lead_lag':
                kind = 'lag' if v['lead_lag_zero_hz'] > v['lead_lag_pole_hz'] else 'lead'
                hf = v['lead_lag_pole_hz'] / v['lead_lag_zero_hz']
                out.append(f"a {kind} network, pole {iv('lead_lag_pole_hz')}, zero "
                           f"{iv('lead_lag_zero_hz')} (high-frequency gain {hf:.3g}), e.g. an "
                           'RC network in the signal chain')
            elif e == 'resonance':
                out.append(f"a second-order resonance at {iv('resonance_frequency_hz')}, "
                           f"damping ratio {iv('resonance_damping_ratio', '')}, e.g. a "
                           'mechanical mode of the rig or the clamp')
            elif e == 'delay':
                out.append(f"a pure delay {iv('correction_delay_s', 'ms', 1e3)}, e.g. channel "
                           'skew')
            elif e == 'gain':
                out.append(f"a gain {iv('correction_gain', '')}")
        return '; '.join(out)

    def sentence(self) -> str:
        """Return what it is and how far it takes the error (the verdict's line)."""
        return (f'{self.words()} (simultaneous 95 % intervals); explains the residual to '
                f'{self.error / self.noise_floor:.2f}x the noise floor (held-out error '
                f'{self.error:.4f}, BIC {self.delta_bic:+.0f})')

    def to_json(self) -> dict:
        return {'structure': list(self.structure), 'values': self.values,
                'ci95': {k: list(v) for k, v in self.ci95.items()}, 'error': self.error,
                'error_over_floor': self.error / self.noise_floor, 'delta_bic': self.delta_bic,
                'description': self.sentence(), 'model_effects': list(self.model_effects),
                'material': self.material,
                'tried': [{'structure': list(s), 'delta_bic': b} for s, b in self.tried]}
