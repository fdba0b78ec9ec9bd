# SPDX-License-Identifier: Apache-2.0
"""
Physical effects that can be added to the base model H1 (eq. 31).

A model is ``h1`` plus an ordered list of effects; the paper's H2 (eq. 45) is
exactly ``h1 + surface_resistance``.  Each effect is documented here, in one
place: physics, equation, parameters (SI units, bounds, typical values), the
signature it leaves in residuals, and a reference.

An effect may act in three places of the prediction ``w(t) -> i(t)``:

1. ``input_transform`` -- a static map of the deflection before the linear
   dynamics (e.g. ``nonlinearity``);
2. ``factor(s, ...)`` -- a multiplicative factor of the transfer function
   (linear time-invariant effects; ``delay_s`` reports any pure delay, which an
   estimator cannot invert causally and handles by re-stamping instead);
3. ``output_transform`` -- applied to the current afterwards (e.g.
   ``current_offset``);

and time-varying effects (``hydration_drift``) give the time-varying material
through ``material_at``.  Effects that are not LTI are therefore simulated in
the time domain by :func:`ipmc_sensor_ros.simulation.sensor.predict_current`.

User-defined effects subclass :class:`Effect`, set ``name`` and ``parameters``
and override what they need; :func:`load_plugin` registers every subclass found
in a Python file.  A plugin is arbitrary Python code run with the rights of the
process: each file is executed once (its sha256 recorded, see
:func:`loaded_plugins`) and never re-read, and it cannot replace a built-in effect
or another plugin's.
"""
from __future__ import annotations

import hashlib
import importlib.util
import math
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from ..errors import did_you_mean
from .parameters import ParameterError, parse_number, short_repr

__all__ = [
    'EffectParameter',
    'Effect',
    'EFFECTS',
    'register_effect',
    'load_plugin',
    'load_plugins',
    'loaded_plugins',
    'get_effect',
    'effect_parameter',
    'catalog_markdown',
    'SCOPES',
    'split_by_scope',
]

#: The values of :attr:`Effect.scope`.
SCOPES = ('sensor', 'recording')


@dataclass(frozen=True)
class EffectParameter:
    """
    One parameter of an effect.

    ``lower``/``upper`` are hard bounds used by fits; ``typical`` is the
    plausible physical range (a fitted value outside it is flagged).
    ``log_scale``: fit in log space (strictly positive quantities).
    """

    name: str
    unit: str
    default: float
    lower: float
    upper: float
    typical: tuple[float, float]
    description: str
    log_scale: bool = True

    def check(self, value, where: str = '') -> float:
        try:
            v = parse_number(value)
        except (TypeError, ValueError, OverflowError):
            raise ParameterError(f"{where}parameter '{self.name}' must be a number, "
                                 f'got {short_repr(value)}') from None
        if not math.isfinite(v) or not (self.lower <= v <= self.upper):
            raise ParameterError(
                f"{where}parameter '{self.name}' = {short_repr(value)} {self.unit} "
                f'is outside [{self.lower:g}, {self.upper:g}] {self.unit}'
            )
        return v


class Effect:
    """Base class of all effects (see the module docstring)."""

    name: ClassVar[str] = ''
    summary: ClassVar[str] = ''
    physics: ClassVar[str] = ''
    equation: ClassVar[str] = ''
    signature: ClassVar[str] = ''
    reference: ClassVar[str] = ''
    parameters: ClassVar[tuple[EffectParameter, ...]] = ()
    #: True if the effect is linear and time-invariant (only ``factor``).
    lti: ClassVar[bool] = True
    #: True if the effect needs a long record (e.g. drifts) to be seen.
    needs_long_record: ClassVar[bool] = False
    #: What the effect belongs to: ``'sensor'`` (the sample, its electrodes and its amplifier:
    #: travels with a saved model to every later recording) or ``'recording'`` (one recording's
    #: offset, drift, channel skew: kept in a model file under the calibration's provenance and
    #: not applied to other records unless asked for; the estimator learns its own offset).
    scope: ClassVar[str] = 'sensor'
    #: The material (name -> value, SI) the defaults were fitted with, when they were fitted
    #: jointly with it (a correction C(s) saved by ``diagnose --save-plugin``): a fit that
    #: adds the effect starts there as well as from the current material, since a correction
    #: and the material it was found with lie in one valley.  Empty for the catalog.
    fitted_material: ClassVar[dict] = {}

    def defaults(self) -> dict[str, float]:
        return {p.name: p.default for p in self.parameters}

    def validate(self, values: dict) -> dict[str, float]:
        known = {p.name: p for p in self.parameters}
        unknown = sorted(str(k) for k in set(values) - set(known))
        if unknown:
            raise ParameterError(
                f"effect '{self.name}': unknown parameter(s) {short_repr(unknown)}; "
                f'known: {sorted(known)}' + did_you_mean(unknown, known)
            )
        out = self.defaults()
        for k, v in values.items():
            out[k] = known[k].check(v, f"effect '{self.name}': ")
        return out

    # -- hooks (identity by default) -------------------------------------------
    def factor(self, s: np.ndarray, model, values: dict) -> np.ndarray | None:
        """Multiplicative factor of H(s), or None for none."""
        return None

    def delay_s(self, values: dict) -> float:
        """Pure time delay contained in ``factor``, s."""
        return 0.0

    def rational(self, model, values: dict):
        """
        Exact rational form of ``factor`` as continuous (zeros, poles, gain) in rad/s.

        If it has one (e.g. resonances, filters); None otherwise. The
        reduction keeps such factors exactly instead of approximating them by
        real poles and zeros.
        """
        return None

    # Times ``t`` given to the hooks are seconds since the start of the record
    # (or of the stream, for the nodes).
    def input_transform(self, t: np.ndarray, w: np.ndarray, model, values: dict) -> np.ndarray:
        return w

    def output_transform(self, t: np.ndarray, i: np.ndarray, model, values: dict) -> np.ndarray:
        return i

    def material_at(self, model, values: dict):
        """For time-varying effects: a function ``elapsed_s -> MaterialParameters``; else None."""
        return None

    def inverse_input_transform(self, w_prime: np.ndarray, model, values: dict) -> np.ndarray:
        """Invert ``input_transform`` (for estimators); identity by default."""
        return w_prime

    def inverse_output_transform(
        self, t: np.ndarray, i: np.ndarray, model, values: dict
    ) -> np.ndarray:
        """Invert ``output_transform`` (for estimators); identity by default."""
        return i


EFFECTS: dict[str, Effect] = {}

#: Where each registered effect came from: "built-in" or the plugin file.
_SOURCES: dict[str, str] = {}

#: Plugin files loaded so far: resolved path -> (sha256 of the executed bytes, effect names).
_PLUGINS: dict[str, tuple[str, tuple[str, ...]]] = {}
_PLUGIN_CLASSES: dict[str, list[type]] = {}


def register_effect(cls, source: str = 'built-in'):
    """
    Class decorator / function: register an :class:`Effect` subclass by its ``name``.

    A name already registered from another source (a built-in effect, another plugin)
    is refused: a plugin cannot silently replace an effect.
    """
    if not (isinstance(cls, type) and issubclass(cls, Effect)) or not cls.name:
        raise ParameterError(f'{short_repr(cls)} is not an Effect subclass with a name')
    if not isinstance(cls.name, str) or not cls.name.isidentifier():
        raise ParameterError(f'effect name {short_repr(cls.name)} must be an identifier')
    if cls.scope not in SCOPES:
        raise ParameterError(f"effect '{cls.name}': scope must be one of {SCOPES}, "
                             f'got {short_repr(cls.scope)}')
    previous = _SOURCES.get(cls.name)
    if previous is not None and previous != source:
        what = 'a built-in effect' if previous == 'built-in' else f'defined by plugin {previous}'
        raise ParameterError(f"effect '{cls.name}' is {what}; a plugin cannot replace it "
                             "(give the plugin's effect another name)")
    EFFECTS[cls.name] = cls()
    _SOURCES[cls.name] = source
    return cls


def split_by_scope(specs) -> tuple[tuple, tuple]:
    """
    Split effect specs (anything with a ``name``) into (sensor, recording) by :attr:`Effect.scope`.

    The one rule that decides what a saved model carries to other recordings.
    """
    sensor, recording = [], []
    for spec in specs:
        (recording if get_effect(spec.name).scope == 'recording' else sensor).append(spec)
    return tuple(sensor), tuple(recording)


def get_effect(name: str) -> Effect:
    try:
        return EFFECTS[name]
    except (KeyError, TypeError):
        raise ParameterError(f'unknown effect {short_repr(name)}; known: {sorted(EFFECTS)} '
                             "(a plugin defines more: --plugin FILE, node parameter 'plugins')"
                             + did_you_mean([str(name)], EFFECTS)) from None


def effect_parameter(effect_name: str, parameter_name: str) -> EffectParameter:
    """Return the :class:`EffectParameter` ``parameter_name`` of the registered effect."""
    for p in get_effect(effect_name).parameters:
        if p.name == parameter_name:
            return p
    raise ParameterError(f"effect '{effect_name}' has no parameter '{parameter_name}'")


def load_plugin(path: str | Path) -> list[str]:
    """
    Execute a Python file once and register every Effect subclass it defines.

    Returns the names registered.  A file already loaded (same resolved path) is not
    executed again: its names are returned, whatever the file holds now.  Errors
    name the file, including a plugin that raises KeyboardInterrupt or SystemExit
    while loading (which would otherwise end the process silently).
    """
    path = Path(path)
    if not path.is_file():
        raise ParameterError(f'{path}: plugin file not found (or not a regular file)')
    key = str(path.resolve())
    if key in _PLUGINS:
        for obj in _PLUGIN_CLASSES[key]:      # re-register (not re-run) if one was removed
            if obj.name not in EFFECTS:
                register_effect(obj, source=_SOURCES.get(obj.name, str(path)))
        return list(_PLUGINS[key][1])
    source = path.read_bytes()
    digest = hashlib.sha256(source).hexdigest()
    spec = importlib.util.spec_from_file_location(f'ipmc_plugin_{path.stem}', path)
    module = importlib.util.module_from_spec(spec)
    try:
        # the bytes hashed are the bytes run (not a second read of the file)
        exec(compile(source, str(path), 'exec'), module.__dict__)
    except (KeyboardInterrupt, SystemExit) as exc:
        raise ParameterError(f'{path}: plugin raised {type(exc).__name__} while loading') from None
    except BaseException as exc:  # a user's file: report any failure with its name
        text = ' '.join(str(exc).split())[:200]
        raise ParameterError(
            f'{path}: plugin failed to import: {type(exc).__name__}: {text}'
        ) from None
    classes = [obj for obj in vars(module).values()
               if isinstance(obj, type) and issubclass(obj, Effect) and obj is not Effect
               and obj.name and obj.__module__ == module.__name__]
    if not classes:
        raise ParameterError(f"{path}: defines no Effect subclass with a 'name'")
    for obj in classes:   # check all names before registering any
        previous = _SOURCES.get(obj.name)
        if previous is not None:
            what = (
                'a built-in effect' if previous == 'built-in' else f'defined by plugin {previous}'
            )
            raise ParameterError(f"{path}: effect '{obj.name}' is {what}; a plugin cannot "
                                 "replace it (give the plugin's effect another name)")
    for obj in classes:
        register_effect(obj, source=str(path))
    names = tuple(obj.name for obj in classes)
    _PLUGINS[key] = (digest, names)
    _PLUGIN_CLASSES[key] = classes
    return list(names)


def load_plugins(paths) -> dict[str, tuple[str, tuple[str, ...]]]:
    """
    Load each plugin file once (:func:`load_plugin`).

    Returns ``{path: (sha256, names)}`` of these files.
    """
    out = {}
    for path in paths:
        if path:
            load_plugin(path)
            out[str(path)] = _PLUGINS[str(Path(path).resolve())]
    return out


def loaded_plugins() -> dict[str, tuple[str, tuple[str, ...]]]:
    """Every plugin executed in this process: resolved path -> (sha256, effect names)."""
    return dict(_PLUGINS)


def catalog_markdown() -> str:
    """Return the catalog as Markdown (used in the README and `ipmc-model effects`)."""
    lines = []
    for eff in EFFECTS.values():
        lines.append(f'### `{eff.name}`\n\n{eff.summary}\n')
        lines.append(f'* **Physics**: {eff.physics}')
        lines.append(f'* **Equation**: {eff.equation}')
        if eff.parameters:
            lines.append('* **Parameters**: ' + '; '.join(
                f'`{p.name}` ({p.unit}; bounds {p.lower:g}..{p.upper:g}; typical '
                f'{p.typical[0]:g}..{p.typical[1]:g}): {p.description}' for p in eff.parameters))
        lines.append(f'* **Belongs to**: the {eff.scope}'
                     + (' (not carried to other recordings by a saved model)'
                        if eff.scope == 'recording' else ''))
        lines.append(f'* **Signature in residuals**: {eff.signature}')
        lines.append(f'* **Reference**: {eff.reference}\n')
    return '\n'.join(lines)
