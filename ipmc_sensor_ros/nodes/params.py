# SPDX-License-Identifier: Apache-2.0
"""
ROS parameter specifications shared by the nodes, and model building from them.

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
from rclpy.publisher import Publisher
from rclpy.subscription import Subscription
from rclpy.timer import Timer
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy)

from ..interface.specs import (GEOMETRY_NAMES, GEOMETRY_SPECS, MATERIAL_NAMES, MATERIAL_SPECS,
                               MODEL_SPECS, QOS_SPECS, ParameterError, Spec, check_choice,
                               markdown_table)
from ..interface.specs import build_model as build_sensor_model

__all__ = ['ParameterError', 'Spec', 'GEOMETRY_SPECS', 'MATERIAL_SPECS', 'MODEL_SPECS',
           'QOS_SPECS', 'declare', 'read', 'build_sensor_model', 'make_qos', 'COUNTERS_QOS',
           'check_choice', 'ParameterError', 'MATERIAL_NAMES', 'GEOMETRY_NAMES', 'markdown_table',
           'params_files', 'check_unknown_overrides', 'section_matches', 'params_file_sections',
           'create_publisher', 'create_subscription', 'check_qos_overrides',
           'qos_overriding_options', 'destroy_io']

_TYPES = {float: ParameterType.PARAMETER_DOUBLE, int: ParameterType.PARAMETER_INTEGER,
          str: ParameterType.PARAMETER_STRING, bool: ParameterType.PARAMETER_BOOL,
          list: ParameterType.PARAMETER_STRING_ARRAY}


def descriptor(spec: Spec) -> ParameterDescriptor:
    """Return the rclpy descriptor of a core parameter spec (description, range, read-only)."""
    d = ParameterDescriptor(name=spec.name, type=_TYPES[spec.kind],
                            description=spec.description, read_only=spec.read_only)
    if spec.choices:
        d.additional_constraints = 'one of: ' + ', '.join(str(c) for c in spec.choices)
    if spec.low is not None and spec.kind is float:
        d.floating_point_range = [FloatingPointRange(from_value=float(spec.low),
                                                     to_value=float(spec.high), step=0.0)]
    elif spec.low is not None and spec.kind is int:
        d.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high),
                                        step=1)]
    return d


def params_files(cli_args: Iterable[str] | None = None) -> list[str]:
    """Return the ``--params-file`` paths given to this process or node (for error messages)."""
    import sys

    out = []
    for args in (list(cli_args or ()), sys.argv):
        for k, a in enumerate(args[:-1]):
            if a == '--params-file':
                out.append(args[k + 1])
    return out


def _ros_arg_params(cli_args) -> set[str]:
    """Names set with ``-p name:=value`` in ``cli_args`` and this process's argv."""
    import sys

    out = set()
    for args in (list(cli_args or ()), sys.argv):
        for k, a in enumerate(args[:-1]):
            if a in ('-p', '--param') and ':=' in args[k + 1]:
                out.add(args[k + 1].split(':=', 1)[0])
    return out


def section_matches(key: str, fqn: str) -> bool:
    """
    Return True if a params-file section ``key`` applies to the node ``fqn``.

    ``key``: ``/**``, ``/**/name``, ``name``, ``/ns/*``; ``fqn``: the node's fully qualified
    name; rcl's matching rules.
    """
    import re

    key = key if key.startswith('/') else '/' + key
    pattern = re.escape(key).replace(r'/\*\*', '(/[^/]+)*').replace(r'\*', '[^/]+')
    return re.fullmatch(pattern, fqn) is not None


def params_file_sections(path: str) -> list[tuple[str, dict]]:
    """``(section key, ros__parameters dict)`` of a params file, in file order."""
    import yaml

    try:
        with open(path, encoding='utf-8') as f:
            doc = yaml.safe_load(f)
    except (OSError, yaml.YAMLError) as exc:
        raise ParameterError(f'parameters file {path}: cannot read: {exc}') from None
    if not isinstance(doc, dict):
        return []
    return [(str(k), dict((v or {}).get('ros__parameters') or {}))
            for k, v in doc.items() if isinstance(v, dict)]


def check_unknown_overrides(node, specs: Iterable[Spec], cli_args=None,
                            default_name: str | None = None) -> None:
    """
    Apply the params-file rules of the nodes, then refuse unknown overrides.

    * A node renamed at start-up (``-r __node:=left_ipmc``) also takes the
      sections keyed by its default name ``default_name`` (``/**/ipmc_estimator``,
      ``ipmc_estimator``): rcl matches the new name only, and the file would be
      silently ignored.  Sections naming the new name, and ``-p``, win.
    * Parameters the node does not declare are refused when they come from
      ``-p`` or a section naming this node (a typo such as ``lenght_m`` must not
      go unnoticed), but only warned about when they come from a wildcard
      section (``/**``) of a file shared with other nodes.
    * ``qos_overrides.<topic>.<publisher|subscription>.<policy>`` are the standard
      QoS parameters (checked by :func:`check_qos_overrides` once the topics exist).

    Raises :class:`ParameterError` naming the parameters and the files.
    """
    known = {s.name for s in specs} | {'use_sim_time', 'start_type_description_service'}
    fqn = node.get_fully_qualified_name()
    ns = node.get_namespace().rstrip('/')
    files = params_files(cli_args)
    exact_keys: set[str] = set()
    wildcard_only: dict[str, str] = {}
    fallback: dict[str, Any] = {}
    fallback_files = []
    renamed = default_name is not None and default_name != node.get_name()
    for path in files:
        for key, section in params_file_sections(path):
            if section_matches(key, fqn):
                if '*' in key.rsplit('/', 1)[-1]:     # '/**' (any node), not '/**/ipmc_estimator'
                    for name in section:
                        wildcard_only.setdefault(name, f"{path} section '{key}'")
                else:
                    exact_keys.update(section)
            elif renamed and section_matches(key, f'{ns}/{default_name}') and '*' not in \
                    key.rsplit('/', 1)[-1]:
                fallback.update(section)
                fallback_files.append(f"{path} section '{key}'")
    if fallback:
        explicit = exact_keys | _ros_arg_params(cli_args)
        applied = sorted(n for n in fallback if n not in explicit)
        for name in applied:
            node._parameter_overrides[name] = Parameter(name, value=fallback[name])
        node.get_logger().info(f"node renamed from '{default_name}': applying "
                               f"{', '.join(fallback_files)} ({len(applied)} parameter(s))")
        exact_keys |= set(fallback)
    unknown = sorted(n for n in node._parameter_overrides
                     if n not in known and not n.startswith('qos_overrides.'))
    fatal = [n for n in unknown if n in exact_keys or n not in wildcard_only]
    for name in unknown:
        if name not in fatal:
            node.get_logger().warning(f"ignoring parameter '{name}' from {wildcard_only[name]}: "
                                      f"not a parameter of {fqn} (another node's?)")
            del node._parameter_overrides[name]
    if fatal:
        where = f" in {', '.join(files)}" if files else ''
        raise ParameterError(f'unknown parameter(s) {fatal}{where} for node '
                             f"'{node.get_name()}'; known: {sorted(known - {'use_sim_time'})}")


#: QoS parameters of a topic are declared read-only by rclpy as
#: ``qos_overrides.<fully qualified topic>.<publisher|subscription>.<policy>``.
QOS_OVERRIDE_POLICIES = ('history', 'depth', 'reliability', 'durability')


def qos_overriding_options():
    """
    Return the standard ``qos_overrides.*`` parameters.

    History, depth, reliability, durability.
    """
    from rclpy.qos_overriding_options import QoSOverridingOptions

    return QoSOverridingOptions.with_default_policies()


def create_publisher(node, msg_type, topic: str, qos: QoSProfile):
    """
    Create a publisher with the standard QoS override parameters.

    A lifecycle node gets a lifecycle publisher (enabled by its ``on_activate``).
    """
    create = getattr(node, 'create_lifecycle_publisher', node.create_publisher)
    return create(msg_type, topic, qos, qos_overriding_options=qos_overriding_options())


def destroy_io(node, names: Iterable[str]) -> None:
    """
    Destroy the entities held by the attributes ``names`` of ``node``.

    Timers, publishers and subscriptions are destroyed through the node, anything else
    (a :class:`~ipmc_sensor_ros.nodes.diagnostics.DiagnosticsPublisher`) by its
    ``destroy()``, lists and tuples item by item; each attribute becomes None, and None
    attributes are skipped.
    """
    for name in names:
        held = getattr(node, name, None)
        setattr(node, name, None)
        for entity in held if isinstance(held, (list, tuple)) else (held,):
            _destroy(node, entity)


def _destroy(node, entity) -> None:
    if entity is not None:
        if isinstance(entity, Timer):
            node.destroy_timer(entity)
        elif isinstance(entity, Publisher):
            node.destroy_publisher(entity)
        elif isinstance(entity, Subscription):
            node.destroy_subscription(entity)
        else:
            entity.destroy()


def create_subscription(node, msg_type, topic: str, callback, qos: QoSProfile, raw=False):
    """``node.create_subscription`` with the standard QoS override parameters."""
    return node.create_subscription(msg_type, topic, callback, qos, raw=raw,
                                    qos_overriding_options=qos_overriding_options())


def check_qos_overrides(node) -> None:
    """
    Refuse ``qos_overrides.*`` overrides naming no topic of the node.

    Call after creating the topics: a misspelt topic would otherwise be ignored silently.
    """
    declared = set(node._parameters)
    stray = sorted(n for n in node._parameter_overrides
                   if n.startswith('qos_overrides.') and n not in declared)
    if stray:
        valid = sorted(n for n in declared if n.startswith('qos_overrides.'))
        raise ParameterError(f'unknown QoS override(s) {stray} for node '
                             f"'{node.get_name()}'; valid: {valid}")


def declare(node, specs: Iterable[Spec]) -> None:
    """Declare ``specs`` on ``node`` (parameter overrides from --ros-args apply)."""
    for spec in specs:
        if spec.kind is list:
            node.declare_parameter(spec.name, Parameter.Type.STRING_ARRAY, descriptor(spec))
        else:
            node.declare_parameter(spec.name, spec.default, descriptor(spec))


def read(node, specs: Iterable[Spec]) -> dict[str, Any]:
    """Return the current values of ``specs`` as a dict (an unset string array reads as ``[]``)."""
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
    rel = check_choice('qos_reliability', values['qos_reliability'], ('reliable', 'best_effort'))
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=int(values['qos_depth']),
                      reliability=(ReliabilityPolicy.RELIABLE if rel == 'reliable'
                                   else ReliabilityPolicy.BEST_EFFORT),
                      durability=DurabilityPolicy.VOLATILE)
