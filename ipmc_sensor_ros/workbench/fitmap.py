# SPDX-License-Identifier: Apache-2.0
"""
The fit vector of :func:`~.freqfit.fit_parameters`: its parameters and the model it stands for.

Which parameters are free, on which scale and within which bounds, and the material and
effects each value of the vector gives.

Material parameters are fitted as logarithms, within a factor of their start (they span
decades and are positive); an effect parameter on the scale its effect declares (log or
linear) within its declared bounds.  Names: a material field (:data:`FITTABLE`) or an effect
parameter, ``delay_s`` or qualified ``time_delay.delay_s`` (:func:`resolve_effect_parameter`).
"""
from __future__ import annotations

import numpy as np

from ..errors import did_you_mean
from ..physics.effects import EFFECTS, effect_parameter, get_effect
from ..physics.model import EffectSpec, parse_effects
from ..physics.parameters import MaterialParameters, ParameterError
from .identifiability import SYMBOLS

__all__ = ['FITTABLE', 'ParameterMap', 'effect_parameter_names', 'resolve_effect_parameter',
           'resolve_free', 'start_and_bounds']

#: Parameters that may be fitted (F and R are constants).
FITTABLE = ('temperature_k', 'youngs_modulus_pa', 'surface_resistance_ohm', 'diffusivity_m2_per_s',
            'anion_concentration_mol_per_m3', 'permittivity_f_per_m',
            'charge_stress_coupling_j_per_c')


def effect_parameter_names(effects) -> list[str]:
    """Qualified names ``effect.parameter`` of every parameter of ``effects``."""
    return [
        f'{e.name}.{p.name}' for e in parse_effects(effects) for p in get_effect(e.name).parameters
    ]


def resolve_effect_parameter(name: str, effects) -> tuple[str, str]:
    """
    Resolve ``delay_s`` or ``time_delay.delay_s`` to ``("time_delay", "delay_s")``.

    For a model with ``effects``; a clear error when unknown, ambiguous or its effect is not
    in the model.
    """
    specs = parse_effects(effects)
    in_model = [e.name for e in specs]
    if '.' in name:
        eff, par = name.split('.', 1)
        if eff not in in_model:
            raise ParameterError(
                f"cannot fit '{name}': effect '{eff}' is not in the model "
                f"({', '.join(in_model) or 'h1 only'}); add it with --effects {eff}"
            )
        if par not in {p.name for p in get_effect(eff).parameters}:
            raise ParameterError(f"cannot fit '{name}': effect '{eff}' has parameters "
                                 f'{[p.name for p in get_effect(eff).parameters]}')
        return eff, par
    owners = [e for e in in_model if name in {p.name for p in get_effect(e).parameters}]
    if len(owners) == 1:
        return owners[0], name
    if len(owners) > 1:
        raise ParameterError(f"parameter '{name}' is ambiguous (effects {owners}); qualify it, "
                             f'e.g. {owners[0]}.{name}')
    catalog = [n for n, e in EFFECTS.items() if name in {p.name for p in e.parameters}]
    if catalog:
        raise ParameterError(
            f"cannot fit '{name}': it belongs to effect '{catalog[0]}', which is not in "
            f'the model; add it with --effects {catalog[0]}'
        )
    ours = effect_parameter_names(specs)
    near = did_you_mean([name], [*FITTABLE, *(SYMBOLS[n] for n in FITTABLE),
                                 *(n.split('.', 1)[1] for n in ours)])
    raise ParameterError(
        f"cannot fit '{name}'; fittable: {', '.join(f'{n} ({SYMBOLS[n]})' for n in FITTABLE)} "
        f"or an effect parameter of the model ({', '.join(ours) or 'none'}){near}"
    )


class ParameterMap:
    """The fit vector theta: each entry's name and scale, and the model it stands for."""

    def __init__(self, free: tuple[str, ...], keys: list, is_log: np.ndarray,
                 material: MaterialParameters, effects: tuple):
        self.free, self.keys, self.is_log = free, keys, is_log
        self.material, self.effects = material, effects
        self.mat_free = tuple(k for k in keys if isinstance(k, str))

    def values_at(self, theta) -> dict[str, float]:
        """Parameter values (exp of log-scale entries) by qualified name."""
        return {n: float(np.exp(v)) if lg else float(v)
                for n, v, lg in zip(self.free, theta, self.is_log)}

    def material_at(self, theta) -> MaterialParameters:
        """Material parameters with the free ones set from ``theta``."""
        vals = self.values_at(theta)
        return self.material.replace(**{n: vals[n] for n in self.mat_free})

    def effects_at(self, theta) -> tuple:
        """Effect specifications with the free effect parameters set from ``theta``."""
        vals = self.values_at(theta)
        out = []
        for e in self.effects:
            d = e.as_dict()
            d.update(
                {
                    k[1]: vals[f'{k[0]}.{k[1]}']
                    for k in self.keys
                    if not isinstance(k, str) and k[0] == e.name
                }
            )
            out.append(EffectSpec(e.name, tuple(sorted(d.items()))))
        return tuple(out)


def resolve_free(free: tuple[str, ...], effects: tuple) -> tuple[list, tuple[str, ...]]:
    """Keys (material name or (effect, parameter)) and qualified names of ``free``."""
    keys: list = []                     # material name, or (effect, parameter)
    for name in free:
        keys.append(name if name in FITTABLE else resolve_effect_parameter(name, effects))
    free = tuple(k if isinstance(k, str) else f'{k[0]}.{k[1]}' for k in keys)
    if len(set(free)) != len(free):
        raise ParameterError(f'parameter listed twice in {list(free)}')
    return keys, free


def start_and_bounds(keys: list, material: MaterialParameters, effects: tuple,
                     bounds_factor: float):
    """Start vector theta0, its bounds and which entries are logarithms."""
    is_log = []
    theta0, lower, upper = [], [], []
    for k in keys:
        if isinstance(k, str):
            v0 = np.log(getattr(material, k) if getattr(material, k) > 0 else 1e-6)
            lo, hi = v0 - np.log(bounds_factor), v0 + np.log(bounds_factor)
            if k == 'surface_resistance_ohm' and material.surface_resistance_ohm == 0:
                lo = np.log(1e-6)
            is_log.append(True)
        else:
            par = effect_parameter(*k)
            v = next(e for e in effects if e.name == k[0]).as_dict()[k[1]]
            if par.log_scale:
                v0, lo, hi = np.log(v), np.log(par.lower), np.log(par.upper)
            else:
                v0, lo, hi = v, par.lower, par.upper
            is_log.append(par.log_scale)
        theta0.append(v0)
        lower.append(lo)
        upper.append(hi)
    return np.array(theta0), np.array(lower), np.array(upper), np.array(is_log)
