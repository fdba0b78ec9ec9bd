"""ROS parameter specifications shared by the nodes, and model building from them.

Every parameter is declared with a ``ParameterDescriptor`` carrying a
description with its unit and, where a fixed range makes sense, a
``FloatingPointRange``/``IntegerRange`` (rclpy then refuses out-of-range values
itself, with a reason).  Everything else (e.g. material values, which have no
fixed bounds) is validated by actually building the core objects
(:class:`~ipmc_sensor_ros.physics.model.SensorModel`, the reduction, the
estimator), whose errors name the parameter.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterable, Mapping

from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                ParameterType)
from rclpy.exceptions import ParameterUninitializedException
from rclpy.parameter import Parameter
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy)

from ..physics.effects import load_plugin
from ..physics.model import BASES, SensorModel, parse_model_name
from ..physics.parameters import (GEOMETRY_LIMITS_M, Geometry, MaterialParameters,
                                  ParameterError)

__all__ = ["ConfigurationError", "Spec", "GEOMETRY_SPECS", "MATERIAL_SPECS", "MODEL_SPECS",
           "QOS_SPECS", "declare", "read", "build_sensor_model", "make_qos", "COUNTERS_QOS",
           "check_choice", "ParameterError", "MATERIAL_NAMES", "GEOMETRY_NAMES", "markdown_table"]

class ConfigurationError(ValueError):
    """A parameter value the node cannot start (or continue) with; the message names it."""


_TYPES = {float: ParameterType.PARAMETER_DOUBLE, int: ParameterType.PARAMETER_INTEGER,
          str: ParameterType.PARAMETER_STRING, bool: ParameterType.PARAMETER_BOOL,
          list: ParameterType.PARAMETER_STRING_ARRAY}


@dataclass(frozen=True)
class Spec:
    """One parameter: name, default, type, description (with unit), range, read-only flag.

    ``kind`` is float, int, str, bool or list (list = string array; its default
    must be empty: it is declared by type, unset means empty).
    """

    name: str
    default: Any
    kind: type
    description: str
    low: float | None = None
    high: float | None = None
    read_only: bool = False
    choices: tuple[str, ...] = ()

    def descriptor(self) -> ParameterDescriptor:
        d = ParameterDescriptor(name=self.name, type=_TYPES[self.kind],
                                description=self.description, read_only=self.read_only)
        if self.choices:
            d.additional_constraints = "one of: " + ", ".join(self.choices)
        if self.low is not None and self.kind is float:
            d.floating_point_range = [FloatingPointRange(from_value=float(self.low),
                                                         to_value=float(self.high), step=0.0)]
        elif self.low is not None and self.kind is int:
            d.integer_range = [IntegerRange(from_value=int(self.low), to_value=int(self.high),
                                            step=1)]
        return d


_M = MaterialParameters()
_SLIM = {"length_m": 0.022, "width_m": 0.007, "thickness_m": 0.00036}

GEOMETRY_SPECS = tuple(
    Spec(name, _SLIM[name], float, f"{text}, m (default: the paper's 'slim' sample)",
         low=GEOMETRY_LIMITS_M[name][0], high=GEOMETRY_LIMITS_M[name][1])
    for name, text in (("length_m", "free length L of the cantilever, clamp to tip"),
                       ("width_m", "width W of the sample"),
                       ("thickness_m", "total thickness 2h of the sample")))

MATERIAL_SPECS = (
    Spec("youngs_modulus_pa", _M.youngs_modulus_pa, float, "Young's modulus Y, Pa (> 0)"),
    Spec("surface_resistance_ohm", _M.surface_resistance_ohm, float,
         "surface-electrode resistance r0 per unit length and width, ohm (>= 0; H2 only)"),
    Spec("diffusivity_m2_per_s", _M.diffusivity_m2_per_s, float,
         "ionic diffusivity d, m^2/s (> 0)"),
    Spec("anion_concentration_mol_per_m3", _M.anion_concentration_mol_per_m3, float,
         "anion concentration C-, mol/m^3 (> 0)"),
    Spec("permittivity_f_per_m", _M.permittivity_f_per_m, float,
         "effective dielectric permittivity kappa_e, F/m (> 0)"),
    Spec("charge_stress_coupling_j_per_c", _M.charge_stress_coupling_j_per_c, float,
         "charge-stress coupling alpha0, J/C (> 0)"),
    Spec("temperature_k", _M.temperature_k, float, "absolute temperature T, K (> 0)"),
)

MODEL_SPECS = (
    Spec("model", "h2", str, "base model: 'h1' (eq. 31) or 'h2' (eq. 45, with surface "
         "resistance)", choices=tuple(sorted(BASES))),
    Spec("effects", [], list, "extra effects beyond the base model, each 'name' or "
         "'name(param=value, ...)' from the effects catalog, e.g. ['time_delay(delay_s=0.002)'];"
         " unknown names and effects already in the base model are refused"),
    Spec("plugins", [], list, "Python files defining more effects (Effect subclasses, see the "
         "README's plugin API), loaded before 'effects' is read", read_only=True),
)

QOS_SPECS = (
    Spec("qos_depth", 1000, int, "KEEP_LAST history depth of the data subscription and "
         "publishers, messages", low=1, high=100000, read_only=True),
    Spec("qos_reliability", "reliable", str, "'reliable' or 'best_effort' for the data topics",
         read_only=True, choices=("reliable", "best_effort")),
)

MATERIAL_NAMES = tuple(s.name for s in MATERIAL_SPECS)
GEOMETRY_NAMES = tuple(s.name for s in GEOMETRY_SPECS)


def declare(node, specs: Iterable[Spec]) -> None:
    """Declare ``specs`` on ``node`` (parameter overrides from --ros-args apply)."""
    for spec in specs:
        if spec.kind is list:
            node.declare_parameter(spec.name, Parameter.Type.STRING_ARRAY, spec.descriptor())
        else:
            node.declare_parameter(spec.name, spec.default, spec.descriptor())


def read(node, specs: Iterable[Spec]) -> dict[str, Any]:
    """Current values of ``specs`` as a dict (an unset string array reads as ``[]``)."""
    out = {}
    for spec in specs:
        try:
            value = node.get_parameter(spec.name).value
        except ParameterUninitializedException:
            value = None
        if spec.kind is list:
            value = list(value) if value is not None else []
        out[spec.name] = value
    return out


def check_choice(name: str, value: Any, choices: Iterable[str]) -> str:
    """Return ``value`` if it is one of ``choices``, else raise ParameterError naming ``name``."""
    choices = tuple(choices)
    if value not in choices:
        raise ParameterError(f"parameter '{name}' must be one of {list(choices)}, got {value!r}")
    return value


def build_sensor_model(values: Mapping[str, Any]) -> SensorModel:
    """SensorModel from geometry, material, ``model`` and ``effects`` parameter values.

    Raises :class:`ParameterError` naming the offending parameter.
    """
    for path in values.get("plugins") or ():
        try:
            load_plugin(path)
        except ParameterError as exc:
            raise ParameterError(f"parameter 'plugins': {exc}") from None
    geometry = Geometry(**{k: values[k] for k in GEOMETRY_NAMES})
    material = MaterialParameters(**{k: values[k] for k in MATERIAL_NAMES})
    _, base_effects = parse_model_name(values["model"])
    extra = tuple(str(e) for e in values.get("effects") or ())
    try:
        return SensorModel(geometry=geometry, material=material, effects=base_effects + extra)
    except ParameterError as exc:
        raise ParameterError(f"parameter 'effects' = {list(extra)} with model "
                             f"'{values['model']}': {exc}") from None


#: QoS of the JSON counters topics: reliable, keep the last one for late joiners.
COUNTERS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)


def make_qos(values: Mapping[str, Any]) -> QoSProfile:
    """KEEP_LAST(qos_depth), reliability per ``qos_reliability``, VOLATILE."""
    rel = check_choice("qos_reliability", values["qos_reliability"], ("reliable", "best_effort"))
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=int(values["qos_depth"]),
                      reliability=(ReliabilityPolicy.RELIABLE if rel == "reliable"
                                   else ReliabilityPolicy.BEST_EFFORT),
                      durability=DurabilityPolicy.VOLATILE)



def markdown_table(specs: Iterable[Spec]) -> str:
    """Parameter table (name, type, default, range, description) for the docs."""
    names = {float: "double", int: "int", str: "string", bool: "bool", list: "string[]"}
    rows = ["| parameter | type | default | range | description |", "|---|---|---|---|---|"]
    for s in specs:
        if s.kind is list:
            default = "[]"
        elif s.kind is str:
            default = f'"{s.default}"'
        else:
            default = f"{s.default:g}" if s.kind is float else str(s.default)
        fmt = "{:g}" if s.kind is float else "{}"
        rng = f"{fmt.format(s.low)} .. {fmt.format(s.high)}" if s.low is not None else (
            " \\| ".join(s.choices) if s.choices else "")
        ro = " **read-only**" if s.read_only else ""
        rows.append(f"| `{s.name}` | {names[s.kind]} | {default} | {rng} | {s.description}{ro} |")
    return "\n".join(rows)
