# SPDX-License-Identifier: Apache-2.0
"""
A sensing model: material + geometry + base transfer function + effects.

``SensorModel`` is the one description that fitting, comparison, reduction,
the estimator and the simulator all take.  The base is the paper's H1
(eq. 31); ``h2`` (eq. 45) is exactly H1 with the ``surface_resistance``
effect.  Effects come from :mod:`ipmc_sensor_ros.physics.effects` (the
built-in catalog is :mod:`ipmc_sensor_ros.physics.catalog`; plugins register
more).

Text form (CLI ``--effects``, node parameter ``effects``, YAML ``model:``)::

    h2                                   # base name
    time_delay                           # effect with default parameters
    time_delay(delay_s=0.002)            # effect with parameter values
"""
from __future__ import annotations

import functools
import re
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping

import numpy as np

from . import catalog as _catalog  # noqa: F401  (registers the built-in effects)
from .effects import get_effect
from .parameters import PAPER_PARAMETERS, Geometry, MaterialParameters, ParameterError, short_repr

__all__ = [
    'SensorModel',
    'EffectSpec',
    'BASES',
    'model_effects',
    'parse_model_name',
    'parse_effects',
    'format_effect',
]

#: base name -> effects implied by it
BASES = {'h1': (), 'h2': ('surface_resistance',)}


@dataclass(frozen=True)
class EffectSpec:
    """One effect in a model: its name and parameter values (hashable)."""

    name: str
    values: tuple[tuple[str, float], ...] = ()

    def as_dict(self) -> dict[str, float]:
        return dict(self.values)


def _spec(name: str, values: Mapping[str, Any] | None = None) -> EffectSpec:
    effect = get_effect(name)
    checked = effect.validate(dict(values or {}))
    return EffectSpec(name, tuple(sorted(checked.items())))


_EFFECT_RE = re.compile(r'^\s*([A-Za-z_]\w*)\s*(?:\((.*)\))?\s*$')


def parse_effects(text: str | Iterable) -> tuple[EffectSpec, ...]:
    """Parse ``"a,b(p=1e-3),c"`` (or a list of such items) into effect specs."""
    if isinstance(text, str):
        items, depth, cur = [], 0, ''
        for ch in text:
            if ch == ',' and depth == 0:
                items.append(cur)
                cur = ''
                continue
            depth += ch == '('
            depth -= ch == ')'
            cur += ch
        items.append(cur)
    else:
        items = list(text)
    out = []
    for item in items:
        if isinstance(item, EffectSpec):
            out.append(item)
            continue
        if isinstance(item, tuple) and len(item) == 2:
            out.append(_spec(item[0], item[1]))
            continue
        if not str(item).strip():
            continue
        m = _EFFECT_RE.match(str(item))
        if not m:
            raise ParameterError(f'cannot parse effect {short_repr(str(item))}; expected name or '
                                 'name(param=value,...)')
        values = {}
        if m.group(2):
            for kv in m.group(2).split(','):
                if '=' not in kv:
                    raise ParameterError(f'effect {short_repr(str(item))}: expected param=value, '
                                         f'got {short_repr(kv)}')
                k, v = kv.split('=', 1)
                if k.strip() in values:
                    raise ParameterError(f'effect {short_repr(str(item))}: parameter '
                                         f'{short_repr(k.strip())} is given twice')
                values[k.strip()] = v.strip()
        out.append(_spec(m.group(1), values))
    return tuple(out)


def format_effect(spec: EffectSpec) -> str:
    if not spec.values:
        return spec.name
    return f"{spec.name}({', '.join(f'{k}={v:.6g}' for k, v in spec.values)})"


def model_effects(name: str, extra_effects: str | Iterable = ()) -> tuple[EffectSpec, ...]:
    """
    Return the effects of model ``name`` (``h1``/``h2``) plus ``extra_effects``.

    The one way a model description (CLI flags, node parameters, model files) becomes a list
    of effects. An extra effect that the base already contains, or one listed twice, is
    refused.
    """
    _, base = parse_model_name(name)
    extra = parse_effects(extra_effects)
    names = [e.name for e in extra]
    for e in names:
        if e in base:
            raise ParameterError(f"effect '{e}' is already part of model '{name}' "
                                 f'(h2 = h1 + surface_resistance)')
        if names.count(e) > 1:
            raise ParameterError(f"effect '{e}' listed twice")
    return tuple(parse_effects(base)) + tuple(extra)


def parse_model_name(name: str) -> tuple[str, tuple[str, ...]]:
    """'h2' -> ('h1', ('surface_resistance',)); refuse unknown names."""
    key = str(name).strip().lower()
    if key not in BASES:
        raise ParameterError(
            f'unknown model {short_repr(str(name))}; choose one of {sorted(BASES)}'
        )
    return 'h1', BASES[key]


@dataclass(frozen=True)
class SensorModel:
    """
    Deflection-to-current model of one sample.

    Parameters
    ----------
    geometry : sample geometry.
    material : material parameters (default: the paper's Tables 1-2).
    effects : ordered effects added to the base H1 (eq. 31): names, specs, or
        ``(name, {param: value})`` pairs.  ``("surface_resistance",)`` (the
        default) is the paper's H2 (eq. 45).

    """

    geometry: Geometry
    material: MaterialParameters = PAPER_PARAMETERS
    effects: tuple = field(default=('surface_resistance',))

    def __post_init__(self) -> None:
        specs = parse_effects(self.effects)
        names = [e.name for e in specs]
        if len(set(names)) != len(names):
            raise ParameterError(f'effect listed twice in {names}')
        object.__setattr__(self, 'effects', specs)

    # -- construction helpers ------------------------------------------------
    @classmethod
    def named(cls, name: str, geometry: Geometry, material: MaterialParameters = PAPER_PARAMETERS,
              extra_effects: str | Iterable = ()) -> 'SensorModel':
        """
        ``h1`` or ``h2`` (the paper's models) for ``geometry``.

        Plus ``extra_effects`` (:func:`model_effects`: an effect already in the base is
        refused, not ignored).
        """
        return cls(geometry=geometry, material=material,
                   effects=model_effects(name, extra_effects))

    @property
    def effect_names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.effects)

    @property
    def name(self) -> str:
        names = self.effect_names
        if names[:1] == ('surface_resistance',):
            return '+'.join(('h2',) + names[1:])
        return '+'.join(('h1',) + names)

    def describe(self) -> str:
        """Text form: base plus formatted effects."""
        names = self.effect_names
        if names[:1] == ('surface_resistance',):
            return ','.join(['h2'] + [format_effect(e) for e in self.effects[1:]])
        return ','.join(['h1'] + [format_effect(e) for e in self.effects])

    def has_effect(self, name: str) -> bool:
        return name in self.effect_names

    def effect_values(self, name: str) -> dict[str, float]:
        for e in self.effects:
            if e.name == name:
                return e.as_dict()
        raise ParameterError(f"model {self.name} has no effect '{name}'")

    def with_effect(self, name: str, **values) -> 'SensorModel':
        """Add (or replace the values of) an effect."""
        new = _spec(name, values)
        effects = [new if e.name == name else e for e in self.effects]
        if name not in self.effect_names:
            effects.append(new)
        return SensorModel(self.geometry, self.material, tuple(effects))

    def without_effect(self, name: str) -> 'SensorModel':
        return SensorModel(
            self.geometry, self.material, tuple(e for e in self.effects if e.name != name)
        )

    def with_material(self, material: MaterialParameters) -> 'SensorModel':
        return SensorModel(geometry=self.geometry, material=material, effects=self.effects)

    # -- evaluation (physics/pipeline.py holds the rules) -------------------------
    def __getstate__(self):
        """
        Pickle the description only.

        The compiled pipeline (which may hold closures, e.g. a drift's ``material_at``) is
        rebuilt on first use after unpickling.
        """
        state = dict(self.__dict__)
        state.pop('compiled', None)
        return state

    @functools.cached_property
    def compiled(self):
        """Return the model taken apart once (:class:`~.pipeline.CompiledModel`)."""
        from .pipeline import compile_model

        return compile_model(self)

    def transfer(self, s) -> np.ndarray:
        """
        i(s)/w(s) in A m^-1 at complex frequencies ``s`` (rad s^-1).

        H1 (eq. 31) times every effect's factor (non-LTI effects contribute their
        linear part only).
        """
        return self.compiled.transfer(s)

    def delay_s(self) -> float:
        """Total pure delay of the LTI part, s."""
        return self.compiled.delay_s

    def rational_factors(self) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """Continuous zpk (rad/s) of the effects whose factor is exactly rational."""
        return list(self.compiled.rational_factors)

    def diffusive_transfer(self, s) -> np.ndarray:
        """
        Return the diffusion-type part the reduction approximates.

        No rational factors, no delay.
        """
        return self.compiled.diffusive_transfer(s)

    def min_phase_transfer(self, s) -> np.ndarray:
        """``transfer`` with its pure delay removed (what a causal inverse can invert)."""
        return self.compiled.min_phase_transfer(s)

    def frequency_response(self, frequency_hz) -> np.ndarray:
        """H(j 2 pi f), A m^-1."""
        return self.transfer(2j * np.pi * np.asarray(frequency_hz, dtype=float))
