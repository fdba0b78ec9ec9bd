"""What a streaming estimator does with the model's effects besides the LTI filter.

:func:`ipmc_sensor_ros.reduction.reduce_model` reduces the *minimum-phase LTI
part* of the model; the rest is handled around the filter, per block:

* a pure delay (``time_delay``; ``SensorModel.delay_s``) cannot be inverted
  causally: the estimate of the deflection at time ``t`` is available when the
  current sample of time ``t + delay`` arrives, so output samples are
  re-stamped ``t_out = t_in - delay`` (s);
* effects with an ``output_transform`` (e.g. ``current_offset``) are undone on
  the current before the filter with their ``inverse_output_transform``; time
  in those transforms runs from the first sample after the last filter reset;
* effects with an ``input_transform`` (e.g. ``nonlinearity``) are undone on the
  filter output with their ``inverse_input_transform``;
* time-varying effects (``material_at``, e.g. ``hydration_drift``) and effects
  that transform without providing the inverse are refused: a fixed filter
  cannot follow them.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..physics.effects import Effect, get_effect
from ..physics.model import SensorModel
from ..physics.parameters import ParameterError

__all__ = ["InverseEffects"]


def _overrides(effect: Effect, name: str) -> bool:
    return getattr(type(effect), name) is not getattr(Effect, name)


@dataclass
class InverseEffects:
    """Per-block pre/post-processing of the estimator for ``model``'s effects."""

    model: SensorModel
    delay_s: float = 0.0
    _current: list = field(default_factory=list)      # (effect, values), applied in reverse
    _deflection: list = field(default_factory=list)   # (effect, values), applied in reverse
    _t0: float | None = None

    @classmethod
    def for_model(cls, model: SensorModel) -> "InverseEffects":
        """Build the hooks; raise ParameterError naming an effect that cannot be inverted."""
        out = cls(model=model, delay_s=float(model.delay_s()))
        for spec in model.effects:
            eff, values = get_effect(spec.name), spec.as_dict()
            if _overrides(eff, "material_at"):
                raise ParameterError(
                    f"parameter 'effects': '{spec.name}' is time-varying; the estimator's fixed "
                    "filter cannot follow it (leave it out of the estimator's effects)")
            if _overrides(eff, "output_transform"):
                if not _overrides(eff, "inverse_output_transform"):
                    raise ParameterError(f"parameter 'effects': '{spec.name}' transforms the "
                                         "current but defines no inverse_output_transform")
                out._current.append((eff, values))
            if _overrides(eff, "input_transform"):
                if not _overrides(eff, "inverse_input_transform"):
                    raise ParameterError(f"parameter 'effects': '{spec.name}' transforms the "
                                         "deflection but defines no inverse_input_transform")
                out._deflection.append((eff, values))
        return out

    @property
    def trivial(self) -> bool:
        return self.delay_s == 0.0 and not self._current and not self._deflection

    def reset(self) -> None:
        """Restart the time origin of the current transforms (after a filter reset)."""
        self._t0 = None

    def current_in(self, times_s: np.ndarray, current_a: np.ndarray) -> np.ndarray:
        """Undo the output transforms on a block of current (A) at ``times_s`` (s)."""
        if not self._current:
            return current_a
        if self._t0 is None:
            self._t0 = float(times_s[0])
        # The hooks measure time from their first argument sample: prepend the origin.
        t = np.concatenate([[self._t0], times_s])
        i = np.concatenate([[0.0], current_a])
        for eff, values in reversed(self._current):
            i = eff.inverse_output_transform(t, i, self.model, values)
        return np.asarray(i[1:], dtype=float)

    def deflection_out(self, times_s: np.ndarray, deflection_m: np.ndarray):
        """(output times, deflection): undo input transforms, re-stamp by the delay."""
        w = deflection_m
        for eff, values in reversed(self._deflection):
            w = np.asarray(eff.inverse_input_transform(w, self.model, values), dtype=float)
        return (times_s - self.delay_s if self.delay_s else times_s), w
