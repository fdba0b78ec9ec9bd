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

from typing import Any, Iterable, Mapping

from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                ParameterType)
from rclpy.exceptions import ParameterUninitializedException
from rclpy.parameter import Parameter
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy)

from ..interface.specs import (GEOMETRY_NAMES, GEOMETRY_SPECS, MATERIAL_NAMES, MATERIAL_SPECS,
                      MODEL_SPECS, QOS_SPECS, ConfigurationError, Spec, check_choice,
                      markdown_table)
from ..interface.specs import build_model as build_sensor_model
from ..physics.parameters import ParameterError

__all__ = ["ConfigurationError", "Spec", "GEOMETRY_SPECS", "MATERIAL_SPECS", "MODEL_SPECS",
           "QOS_SPECS", "declare", "read", "build_sensor_model", "make_qos", "COUNTERS_QOS",
           "check_choice", "ParameterError", "MATERIAL_NAMES", "GEOMETRY_NAMES", "markdown_table",
           "params_files", "check_unknown_overrides"]

_TYPES = {float: ParameterType.PARAMETER_DOUBLE, int: ParameterType.PARAMETER_INTEGER,
          str: ParameterType.PARAMETER_STRING, bool: ParameterType.PARAMETER_BOOL,
          list: ParameterType.PARAMETER_STRING_ARRAY}


def descriptor(spec: Spec) -> ParameterDescriptor:
    """The rclpy descriptor of a core parameter spec (description, range, read-only)."""
    d = ParameterDescriptor(name=spec.name, type=_TYPES[spec.kind],
                            description=spec.description, read_only=spec.read_only)
    if spec.choices:
        d.additional_constraints = "one of: " + ", ".join(str(c) for c in spec.choices)
    if spec.low is not None and spec.kind is float:
        d.floating_point_range = [FloatingPointRange(from_value=float(spec.low),
                                                     to_value=float(spec.high), step=0.0)]
    elif spec.low is not None and spec.kind is int:
        d.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high),
                                        step=1)]
    return d


def params_files(cli_args: Iterable[str] | None = None) -> list[str]:
    """The ``--params-file`` paths given to this process or node (for error messages)."""
    import sys

    out = []
    for args in (list(cli_args or ()), sys.argv):
        for k, a in enumerate(args[:-1]):
            if a == "--params-file":
                out.append(args[k + 1])
    return out


def check_unknown_overrides(node, specs: Iterable[Spec], cli_args=None) -> None:
    """Refuse parameter overrides (from params files or -p) that the node does not declare:
    rclpy would ignore them silently, so a typo ('lenght_m') would go unnoticed."""
    known = {s.name for s in specs} | {"use_sim_time", "start_type_description_service"}
    unknown = sorted(set(node._parameter_overrides) - known)
    if unknown:
        files = params_files(cli_args)
        where = f" in {', '.join(files)}" if files else ""
        raise ConfigurationError(f"unknown parameter(s) {unknown}{where} for node "
                                 f"'{node.get_name()}'; known: {sorted(known - {'use_sim_time'})}")


def declare(node, specs: Iterable[Spec]) -> None:
    """Declare ``specs`` on ``node`` (parameter overrides from --ros-args apply)."""
    for spec in specs:
        if spec.kind is list:
            node.declare_parameter(spec.name, Parameter.Type.STRING_ARRAY, descriptor(spec))
        else:
            node.declare_parameter(spec.name, spec.default, descriptor(spec))


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



