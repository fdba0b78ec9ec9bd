"""Physical effects that can be added to the base model H1 (eq. 31).

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
in a Python file.
"""
from __future__ import annotations

import importlib.util
import math
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from .parameters import ParameterError

__all__ = ["EffectParameter", "Effect", "EFFECTS", "register_effect", "load_plugin", "get_effect",
           "catalog_markdown"]


@dataclass(frozen=True)
class EffectParameter:
    """One parameter of an effect.

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

    def check(self, value, where: str = "") -> float:
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ParameterError(f"{where}parameter '{self.name}' must be a number, got {value!r}") from None
        if not math.isfinite(v) or not (self.lower <= v <= self.upper):
            raise ParameterError(f"{where}parameter '{self.name}' = {value!r} {self.unit} is outside "
                                 f"[{self.lower:g}, {self.upper:g}] {self.unit}")
        return v


class Effect:
    """Base class of all effects (see the module docstring)."""

    name: ClassVar[str] = ""
    summary: ClassVar[str] = ""
    physics: ClassVar[str] = ""
    equation: ClassVar[str] = ""
    signature: ClassVar[str] = ""
    reference: ClassVar[str] = ""
    parameters: ClassVar[tuple[EffectParameter, ...]] = ()
    #: True if the effect is linear and time-invariant (only ``factor``).
    lti: ClassVar[bool] = True
    #: True if the effect needs a long record (e.g. drifts) to be seen.
    needs_long_record: ClassVar[bool] = False

    def defaults(self) -> dict[str, float]:
        return {p.name: p.default for p in self.parameters}

    def validate(self, values: dict) -> dict[str, float]:
        known = {p.name: p for p in self.parameters}
        unknown = sorted(set(values) - set(known))
        if unknown:
            raise ParameterError(f"effect '{self.name}': unknown parameter(s) {unknown}; "
                                 f"known: {sorted(known)}")
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
        """Exact rational form of ``factor`` as continuous (zeros, poles, gain) in
        rad/s, if it has one (e.g. resonances, filters); None otherwise.  The
        reduction keeps such factors exactly instead of approximating them by
        real poles and zeros."""
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

    def inverse_output_transform(self, t: np.ndarray, i: np.ndarray, model, values: dict) -> np.ndarray:
        """Invert ``output_transform`` (for estimators); identity by default."""
        return i


EFFECTS: dict[str, Effect] = {}


def register_effect(cls):
    """Class decorator / function: register an :class:`Effect` subclass by its ``name``."""
    if not (isinstance(cls, type) and issubclass(cls, Effect)) or not cls.name:
        raise ParameterError(f"{cls!r} is not an Effect subclass with a name")
    if not cls.name.isidentifier():
        raise ParameterError(f"effect name {cls.name!r} must be an identifier")
    EFFECTS[cls.name] = cls()
    return cls


def get_effect(name: str) -> Effect:
    try:
        return EFFECTS[name]
    except KeyError:
        raise ParameterError(f"unknown effect '{name}'; known: {sorted(EFFECTS)} "
                             "(or load a plugin with --plugin FILE)") from None


def load_plugin(path: str | Path) -> list[str]:
    """Import a Python file and register every Effect subclass it defines.

    Returns the names registered.  Errors name the file.
    """
    path = Path(path)
    if not path.is_file():
        raise ParameterError(f"{path}: plugin file not found")
    spec = importlib.util.spec_from_file_location(f"ipmc_plugin_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except Exception as exc:  # a user's file: report any failure with its name
        raise ParameterError(f"{path}: plugin failed to import: {type(exc).__name__}: {exc}") from None
    names = []
    for obj in vars(module).values():
        if isinstance(obj, type) and issubclass(obj, Effect) and obj is not Effect and obj.name:
            register_effect(obj)
            names.append(obj.name)
    if not names:
        raise ParameterError(f"{path}: defines no Effect subclass with a 'name'")
    return names


def catalog_markdown() -> str:
    """The catalog as Markdown (used in the README and `ipmc-model effects`)."""
    lines = []
    for eff in EFFECTS.values():
        lines.append(f"### `{eff.name}`\n\n{eff.summary}\n")
        lines.append(f"* **Physics**: {eff.physics}")
        lines.append(f"* **Equation**: {eff.equation}")
        if eff.parameters:
            lines.append("* **Parameters**: " + "; ".join(
                f"`{p.name}` ({p.unit}; bounds {p.lower:g}..{p.upper:g}; typical "
                f"{p.typical[0]:g}..{p.typical[1]:g}): {p.description}" for p in eff.parameters))
        lines.append(f"* **Signature in residuals**: {eff.signature}")
        lines.append(f"* **Reference**: {eff.reference}\n")
    return "\n".join(lines)
