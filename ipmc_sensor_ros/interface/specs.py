"""Parameters of the nodes and of ``ipmc-model estimate``, without ROS.

One source for the parameter names, defaults, units and ranges
(:class:`Spec`), for reading them from a ROS 2 params file
(:func:`load_params_file`, which ``--ros-args --params-file`` files also are)
and for building the sensor model and the estimator from them
(:func:`build_model`, :func:`build_estimator`).  The estimator node and the
offline ``ipmc-model estimate`` both go through :func:`build_estimator`: one
code path, one parameters file.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from ..estimation.deflection import DeflectionEstimator
from ..estimation.inverse import DEFAULT_LEAK_CORNER_HZ
from ..estimation.stream import MAX_BLOCK_SAMPLES
from ..physics.effects import load_plugin
from ..physics.model import BASES, SensorModel
from ..physics.parameters import GEOMETRY_LIMITS_M, Geometry, MaterialParameters, ParameterError
from ..lti.reduction import MAX_ORDER, ReducedModel, ReductionError

__all__ = ["Spec", "ConfigurationError", "GEOMETRY_SPECS", "MATERIAL_SPECS", "MODEL_SPECS",
           "QOS_SPECS", "ESTIMATOR_SPECS", "PUBLISH_POINTS", "MATERIAL_NAMES", "GEOMETRY_NAMES",
           "defaults", "load_params_file", "build_model", "build_estimator", "check_choice",
           "markdown_table"]


class ConfigurationError(ParameterError):
    """A parameter value the node cannot start (or continue) with; the message names it."""


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


#: Allowed values of ``publish_points``.
PUBLISH_POINTS = ("per_sample", "last_of_block", "none")  # not "off": YAML reads off as false

ESTIMATOR_SPECS = GEOMETRY_SPECS + MATERIAL_SPECS + MODEL_SPECS + (
    Spec("reduction_order", 4, int, "order n of the stable reduction of R(s) = H(s)/s",
         low=1, high=MAX_ORDER),
    Spec("band_low_hz", 0.1, float, "lower edge of the reduction fit band, Hz",
         low=1e-4, high=1e5),
    Spec("band_high_hz", 50.0, float, "upper edge of the reduction fit band, Hz",
         low=1e-4, high=1e5),
    Spec("sample_rate_hz", 1000.0, float, "sample rate of the current the filter is designed "
         "for, Hz; blocks whose median sample period differs by more than 1 % are rejected",
           low=1.0, high=1e6, read_only=True),
    Spec("leak_corner_hz", DEFAULT_LEAK_CORNER_HZ, float, "leaky-integration corner f_c, Hz "
         "(time constant 1/(2 pi f_c) of the initial-condition and held-step decay)",
           low=1e-6, high=1e4),
    Spec("offset_corner_hz", 0.0, float, "corner of the current-offset tracker, Hz "
         "(0 = off)", low=0.0, high=1e4),
    Spec("frame_id", "ipmc_clamp", str, "frame of the deflection points: origin at the "
         "clamp, x along the beam to the tip, z in the bending direction"),
    Spec("max_gap_s", 0.1, float, "largest time gap between consecutive samples bridged "
         "without a filter reset, s", low=1e-6, high=1e6),
    Spec("publish_points", "per_sample", str, "deflection PointStamped output: 'per_sample', "
         "'last_of_block' or 'none'", choices=PUBLISH_POINTS),
    Spec("max_block_samples", 100_000, int, "largest accepted input block, samples",
         low=1, high=MAX_BLOCK_SAMPLES, read_only=True),
) + QOS_SPECS


def check_choice(name: str, value: Any, choices: Iterable[str]) -> str:
    """Return ``value`` if it is one of ``choices``, else raise ParameterError naming ``name``."""
    choices = tuple(choices)
    if value not in choices:
        raise ParameterError(f"parameter '{name}' must be one of {list(choices)}, got {value!r}")
    return value


def build_model(values: Mapping[str, Any]) -> SensorModel:
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
    extra = tuple(str(e) for e in values.get("effects") or ())
    try:
        return SensorModel.named(values["model"], geometry, material, extra)
    except ParameterError as exc:
        raise ParameterError(f"parameter 'effects' = {list(extra)} with model "
                             f"'{values['model']}': {exc}") from None



def build_estimator(values: Mapping[str, Any], reduced: ReducedModel | None = None) -> DeflectionEstimator:
    """The core estimator from parameter values (``reduced`` reused when the model part
    did not change).  Raises ParameterError / ReductionError / EstimatorError /
    ConfigurationError naming the parameter."""
    model = build_model(values)
    band = (float(values["band_low_hz"]), float(values["band_high_hz"]))
    if not band[0] < band[1]:
        raise ReductionError(f"parameters 'band_low_hz' ({band[0]}) and 'band_high_hz' "
                             f"({band[1]}) must satisfy low < high")
    offset = float(values["offset_corner_hz"])
    if offset < 0.0:
        raise ConfigurationError(f"parameter 'offset_corner_hz' must be >= 0 Hz (0 = off), got {offset!r}")
    return DeflectionEstimator(model, float(values["sample_rate_hz"]),
                               reduction_order=int(values["reduction_order"]), band_hz=band,
                               leak_corner_hz=float(values["leak_corner_hz"]),
                               offset_corner_hz=offset if offset > 0.0 else None, reduced=reduced)


def defaults(specs: Iterable[Spec]) -> dict[str, Any]:
    """Default values of ``specs`` (string arrays default to empty lists)."""
    return {s.name: (list(s.default) if s.kind is list else s.default) for s in specs}


def _check_value(spec: Spec, value: Any, where: str) -> Any:
    if spec.kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigurationError(f"{where}: parameter '{spec.name}' must be a number, got {value!r}")
        value = float(value)
    elif spec.kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigurationError(f"{where}: parameter '{spec.name}' must be an integer, got {value!r}")
    elif spec.kind is str:
        if not isinstance(value, str):
            raise ConfigurationError(f"{where}: parameter '{spec.name}' must be a string, got {value!r}")
    elif spec.kind is bool:
        if not isinstance(value, bool):
            raise ConfigurationError(f"{where}: parameter '{spec.name}' must be true or false, got {value!r}")
    elif spec.kind is list:
        if isinstance(value, str) or not isinstance(value, (list, tuple)) \
                or not all(isinstance(v, str) for v in value):
            raise ConfigurationError(f"{where}: parameter '{spec.name}' must be a list of strings, "
                                     f"got {value!r}")
        value = [v for v in value if v]
    if spec.low is not None and not (spec.low <= value <= spec.high):
        raise ConfigurationError(f"{where}: parameter '{spec.name}' = {value!r} is outside "
                                 f"[{spec.low:g}, {spec.high:g}]")
    if spec.choices and value not in spec.choices:
        raise ConfigurationError(f"{where}: parameter '{spec.name}' must be one of "
                                 f"{list(spec.choices)}, got {value!r}")
    return value


def load_params_file(path: str | Path, node_name: str = "ipmc_estimator",
                     specs: Sequence[Spec] | None = None) -> dict[str, Any]:
    """Parameter values for ``node_name`` from a ROS 2 params file, on top of the defaults.

    Sections that apply: ``/**``, ``/**/<node_name>``, ``<node_name>`` and
    ``/<node_name>`` (later ones win), each with ``ros__parameters``.  Unknown
    keys, wrong types, out-of-range values and unit mistakes (e.g. a length in
    millimetres) raise :class:`ConfigurationError` naming the key and the file.
    ``use_sim_time`` is accepted and ignored here.
    """
    import yaml

    specs = ESTIMATOR_SPECS if specs is None else specs
    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise ConfigurationError(f"{path}: parameters file not found") from None
    except yaml.YAMLError as exc:
        raise ConfigurationError(f"{path}: not valid YAML: {exc}") from None
    if not isinstance(doc, dict):
        raise ConfigurationError(f"{path}: expected a mapping of node names to 'ros__parameters'")
    values = defaults(specs)
    by_name = {s.name: s for s in specs}
    found = False
    for key in ("/**", f"/**/{node_name}", node_name, f"/{node_name}"):
        section = doc.get(key)
        if section is None:
            continue
        if not isinstance(section, dict) or "ros__parameters" not in section:
            raise ConfigurationError(f"{path}: section '{key}' has no 'ros__parameters'")
        found = True
        for name, value in (section["ros__parameters"] or {}).items():
            if name == "use_sim_time":
                continue
            if name not in by_name:
                raise ConfigurationError(f"{path}: unknown parameter '{name}' in section '{key}' "
                                         f"(known: {sorted(by_name)})")
            values[name] = _check_value(by_name[name], value, str(path))
    if not found:
        raise ConfigurationError(f"{path}: no section for node '{node_name}' (expected one of "
                                 f"'/**', '/**/{node_name}', '{node_name}')")
    try:
        build_model(values)
    except ParameterError as exc:
        raise ConfigurationError(f"{path}: {exc}") from None
    return values


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
