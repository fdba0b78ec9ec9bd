"""A sensing model: material + geometry + base transfer function (+ effects).

``SensorModel`` is the one description that fitting, comparison, reduction, the
estimator and the simulator all take.  The base is the paper's H1 (eq. 31);
``h2`` (eq. 45) is H1 with the ``surface_resistance`` effect.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .parameters import PAPER_PARAMETERS, Geometry, MaterialParameters, ParameterError
from .sensing import h1, surface_resistance_factor

__all__ = ["SensorModel", "BASES", "parse_model_name"]

#: base name -> effects implied by it
BASES = {"h1": (), "h2": ("surface_resistance",)}

#: Linear time-invariant multiplicative factors, keyed by effect name.
#: Each maps (s, material, geometry) -> dimensionless complex factor.
_LTI_FACTORS: dict[str, Callable] = {
    "surface_resistance": surface_resistance_factor,
}


def parse_model_name(name: str) -> tuple[str, tuple[str, ...]]:
    """'h2' -> ('h1', ('surface_resistance',)); refuse unknown names."""
    key = str(name).strip().lower()
    if key not in BASES:
        raise ParameterError(f"unknown model '{name}'; choose one of {sorted(BASES)}")
    return "h1", BASES[key]


@dataclass(frozen=True)
class SensorModel:
    """Deflection-to-current model of one sample.

    Parameters
    ----------
    geometry : sample geometry.
    material : material parameters (default: the paper's Tables 1-2).
    effects : ordered names of effects added to the base H1 (eq. 31).  With
        ``("surface_resistance",)`` the model is the paper's H2 (eq. 45).
    """

    geometry: Geometry
    material: MaterialParameters = PAPER_PARAMETERS
    effects: tuple[str, ...] = field(default=("surface_resistance",))

    def __post_init__(self) -> None:
        effects = tuple(self.effects)
        for name in effects:
            if name not in _LTI_FACTORS:
                raise ParameterError(f"unknown effect '{name}'; known: {sorted(_LTI_FACTORS)}")
        if len(set(effects)) != len(effects):
            raise ParameterError(f"effect listed twice in {list(effects)}")
        object.__setattr__(self, "effects", effects)

    @classmethod
    def named(cls, name: str, geometry: Geometry,
              material: MaterialParameters = PAPER_PARAMETERS) -> "SensorModel":
        """Build ``h1`` or ``h2`` (the paper's two models) for ``geometry``."""
        _, effects = parse_model_name(name)
        return cls(geometry=geometry, material=material, effects=effects)

    @property
    def name(self) -> str:
        if self.effects == ("surface_resistance",):
            return "h2"
        return "+".join(("h1",) + self.effects)

    def transfer(self, s) -> np.ndarray:
        """i(s)/w(s) in A m^-1 at complex frequencies ``s`` (rad s^-1)."""
        s = np.asarray(s, dtype=complex)
        out = h1(s, self.material, self.geometry)
        for name in self.effects:
            out = out * _LTI_FACTORS[name](s, self.material, self.geometry)
        return out

    def frequency_response(self, frequency_hz) -> np.ndarray:
        """H(j 2 pi f), A m^-1."""
        return self.transfer(2j * np.pi * np.asarray(frequency_hz, dtype=float))

    def charge_gain_dc(self) -> float:
        """lim_{s->0} H(s)/s, A s m^-1 (= C m^-1): static charge per unit tip deflection."""
        s = np.array([1e-9j])
        return float(np.real(self.transfer(s)[0] / s[0]))

    def with_geometry(self, geometry: Geometry) -> "SensorModel":
        return SensorModel(geometry=geometry, material=self.material, effects=self.effects)

    def with_material(self, material: MaterialParameters) -> "SensorModel":
        return SensorModel(geometry=self.geometry, material=material, effects=self.effects)
