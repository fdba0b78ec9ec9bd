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

import difflib
import weakref
from typing import Any, Iterable, Mapping

from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                ParameterType)
from rclpy.exceptions import ParameterUninitializedException
from rclpy.parameter import Parameter

from ..errors import did_you_mean
from ..interface.specs import (GEOMETRY_NAMES, GEOMETRY_SPECS, MATERIAL_NAMES, MATERIAL_SPECS,
                               MODEL_SPECS, QOS_SPECS, ParameterError, Spec, check_choice,
                               check_values, markdown_table)
from ..interface.builders import build_model as build_sensor_model
from ..interface.builders import model_file_summary as build_model_file_summary
from ..physics.parameters import read_yaml

__all__ = ['ParameterError', 'Spec', 'GEOMETRY_SPECS', 'MATERIAL_SPECS', 'MODEL_SPECS',
           'QOS_SPECS', 'declare', 'read', 'build_sensor_model', 'check_choice',
           'MATERIAL_NAMES', 'GEOMETRY_NAMES', 'markdown_table', 'params_files',
           'check_unknown_overrides', 'section_matches', 'params_file_sections',
           'parameter_overrides', 'log_model_files', 'node_help', 'ros_arguments',
           'wants_help']

_TYPES = {float: ParameterType.PARAMETER_DOUBLE, int: ParameterType.PARAMETER_INTEGER,
          str: ParameterType.PARAMETER_STRING, bool: ParameterType.PARAMETER_BOOL,
          list: ParameterType.PARAMETER_STRING_ARRAY}


def descriptor(spec: Spec) -> ParameterDescriptor:
    """Return the rclpy descriptor of a core parameter spec (description, range, read-only)."""
    d = ParameterDescriptor(name=spec.name, type=_TYPES[spec.kind],
                            description=spec.description, read_only=spec.read_only)
    if spec.numbers_as_text:            # an integer from a shared params file is accepted
        d.type, d.dynamic_typing = ParameterType.PARAMETER_NOT_SET, True
    if spec.choices:
        d.additional_constraints = 'one of: ' + ', '.join(str(c) for c in spec.choices)
    if spec.low is not None and spec.kind is float:
        d.floating_point_range = [FloatingPointRange(from_value=float(spec.low),
                                                     to_value=float(spec.high), step=0.0)]
    elif spec.low is not None and spec.kind is int:
        d.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high),
                                        step=1)]
    return d


def wants_help(args: Iterable[str]) -> bool:
    """
    Return True if ``-h`` or ``--help`` is among the non-ROS arguments of a process.

    The ROS part (``--ros-args ... [--]``) is skipped without asking rcl, which would parse
    every params file it names first.
    """
    in_ros = False
    for a in list(args)[1:]:
        if a == '--ros-args':
            in_ros = True
        elif a == '--' and in_ros:
            in_ros = False
        elif not in_ros and a in ('-h', '--help'):
            return True
    return False


def ros_arguments(args: Iterable[str]) -> list[str]:
    """Return the part of a process's arguments from the first ``--ros-args`` on."""
    args = list(args)
    return args[args.index('--ros-args'):] if '--ros-args' in args else []


def params_files(cli_args: Iterable[str] | None) -> list[str]:
    """Return the ``--params-file`` paths in ``cli_args`` (the node's or the process's)."""
    args = list(cli_args or ())
    return [args[k + 1] for k, a in enumerate(args[:-1]) if a == '--params-file']


def _ros_arg_params(cli_args: Iterable[str] | None) -> set[str]:
    """Names set with ``-p name:=value`` in ``cli_args``."""
    args = list(cli_args or ())
    return {args[k + 1].split(':=', 1)[0] for k, a in enumerate(args[:-1])
            if a in ('-p', '--param') and ':=' in args[k + 1]}


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
    doc = read_yaml(path, 'parameters file')
    if not isinstance(doc, dict):
        return []
    return [(str(k), dict((v or {}).get('ros__parameters') or {}))
            for k, v in doc.items() if isinstance(v, dict)]


def parameter_overrides(node) -> dict[str, Parameter]:
    """
    Return the parameter overrides rcl parsed for ``node`` (params files and ``-p``), read only.

    rclpy 9.1.2 has no public getter for them; they are read here, in one place, and never
    written.
    """
    return dict(node._parameter_overrides)


#: Values of sections keyed by a renamed node's default name, per node (see
#: :func:`check_unknown_overrides`); :func:`declare` starts from them.
_FILE_DEFAULTS: 'weakref.WeakKeyDictionary' = weakref.WeakKeyDictionary()


def _file_sections(node, cli_args, default_name):
    """
    Sort the params-file sections of ``cli_args`` that concern ``node``.

    Returns (names set by an exact section, {name: where} of names set only by a wildcard
    section, values of sections keyed by the node's default name when it was renamed,
    where those came from).
    """
    fqn = node.get_fully_qualified_name()
    ns = node.get_namespace().rstrip('/')
    renamed = default_name is not None and default_name != node.get_name()
    exact: set[str] = set()
    wildcard: dict[str, str] = {}
    fallback: dict[str, Any] = {}
    origins = []
    for path in params_files(cli_args):
        keys, used = [], False
        for key, section in params_file_sections(path):
            own = '*' not in key.rsplit('/', 1)[-1]   # '/**' is any node; '/**/name' is not
            keys.append(key)
            if section_matches(key, fqn):
                used = True
                if own:
                    exact.update(section)
                else:
                    for name in section:
                        wildcard.setdefault(name, f"{path} section '{key}'")
            elif renamed and own and section_matches(key, f'{ns}/{default_name}'):
                used = True
                fallback.update(section)
                origins.append(f"{path} section '{key}'")
        if not used:
            _say_unused(node, path, keys, default_name or node.get_name())
    return exact, wildcard, fallback, origins


def _say_unused(node, path: str, keys: list, name: str) -> None:
    """Warn that no section of params file ``path`` applies to ``node`` (a misspelt key?)."""
    near = [k.rpartition('/')[0] + k.rpartition('/')[1] for k in keys
            if difflib.SequenceMatcher(None, k.rpartition('/')[2], name).ratio() >= 0.8]
    hint = f"; did you mean '{near[0]}{name}'?" if near else ''
    node.get_logger().warning(
        f'{path}: no section applies to {node.get_fully_qualified_name()} (sections: '
        f"{keys}; expected '/**', '/**/{name}' or '{name}'): its values are not used{hint}")


def check_unknown_overrides(node, specs: Iterable[Spec], cli_args=None,
                            default_name: str | None = None) -> None:
    """
    Apply the params-file rules of the nodes, then refuse unknown overrides.

    ``cli_args``: the node's arguments (the runner passes the process's, so every
    ``--params-file`` and ``-p`` is seen here as rcl saw it).

    * A node renamed at start-up (``-r __node:=left_ipmc``) also takes the
      sections keyed by its default name ``default_name`` (``/**/ipmc_estimator``,
      ``ipmc_estimator``): rcl matches the new name only, and the file would be
      silently ignored.  Sections naming the new name, and ``-p``, win (they are rcl's
      overrides; the default-name values become the starting values of :func:`declare`).
    * Parameters the node does not declare are refused when they come from
      ``-p`` or a section naming this node (a typo such as ``lenght_m`` must not
      go unnoticed), but only warned about when they come from a wildcard
      section (``/**``) of a file shared with other nodes (never declared, so unused).
    * ``qos_overrides.<topic>.<publisher|subscription>.<policy>`` are the standard
      QoS parameters (checked by :func:`check_qos_overrides` once the topics exist).

    Raises :class:`ParameterError` naming the parameters and the files.
    """
    known = {s.name for s in specs} | {'use_sim_time', 'start_type_description_service'}
    exact, wildcard, fallback, origins = _file_sections(node, cli_args, default_name)
    overrides = parameter_overrides(node)
    if fallback:
        applied = sorted(n for n in fallback
                         if n not in overrides and n not in _ros_arg_params(cli_args))
        _FILE_DEFAULTS[node] = {n: fallback[n] for n in applied}
        node.get_logger().info(f"node renamed from '{default_name}': applying "
                               f"{', '.join(origins)} ({len(applied)} parameter(s))")
        exact |= set(fallback)
    names = set(overrides) | set(fallback)
    unknown = sorted(n for n in names if n not in known and not n.startswith('qos_overrides.'))
    fatal = [n for n in unknown if n in exact or n not in wildcard]
    for name in unknown:
        if name not in fatal:
            node.get_logger().warning(f"ignoring parameter '{name}' from {wildcard[name]}: "
                                      f'not a parameter of {node.get_fully_qualified_name()} '
                                      "(another node's?)")
    if fatal:
        files = params_files(cli_args)
        where = f" in {', '.join(files)}" if files else ''
        ours = sorted(known - {'use_sim_time', 'start_type_description_service'})
        raise ParameterError(f'unknown parameter(s) {fatal}{where} for node '
                             f"'{node.get_name()}'{did_you_mean(fatal, ours)}; known: {ours}")


def declare(node, specs: Iterable[Spec]) -> None:
    """
    Declare ``specs`` on ``node`` (parameter overrides from --ros-args apply).

    A renamed node starts from the values of its default-name sections
    (:func:`check_unknown_overrides`), else from the specs' defaults.  The overrides are
    checked first by the rules a params file meets offline (:func:`check_values`: one
    wording, "parameter 'x' = v is outside [lo, hi]", not rcl's descriptor message).
    """
    check_values({n: p.value for n, p in parameter_overrides(node).items()}, specs)
    start = _FILE_DEFAULTS.get(node, {})
    for spec in specs:
        if spec.name in start:
            node.declare_parameter(spec.name, start[spec.name], descriptor(spec))
        elif spec.kind is list:
            node.declare_parameter(spec.name, Parameter.Type.STRING_ARRAY, descriptor(spec))
        else:
            node.declare_parameter(spec.name, spec.default, descriptor(spec))


def log_model_files(node, values: Mapping[str, Any]) -> None:
    """Log what the node's model files hold and whether their recording effects apply."""
    warn = bool(values.get('apply_recording_effects'))
    for line in build_model_file_summary(values):
        if warn and 'APPLIED' in line:
            node.get_logger().warning(line)
        else:
            node.get_logger().info(line)


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


#: What each node does, for ``-h`` / ``--help``.
_NODE_TEXT = {
    'ipmc_estimator': ('sensing current (A) in, tip deflection (m) out',
                       'subscribes current; publishes deflection, deflection/block, '
                       'estimator/counters, /diagnostics'),
    'ipmc_simulator': ('a simulated IPMC sensor and DAQ: stimulus -> current',
                       'publishes current, deflection_truth, simulator/counters, /diagnostics'),
}


def node_help(executable: str) -> str:
    """Return the ``-h`` / ``--help`` text of a node executable (no node is started)."""
    from ..interface.simulator import SIMULATOR_SPECS
    from ..interface.specs import ESTIMATOR_SPECS

    node = 'ipmc_simulator' if executable.startswith('ipmc_simulator') else 'ipmc_estimator'
    specs = SIMULATOR_SPECS if node == 'ipmc_simulator' else ESTIMATOR_SPECS
    does, topics = _NODE_TEXT[node]
    managed = executable.endswith('_managed')
    kinds = {float: 'double', int: 'int', str: 'string', bool: 'bool', list: 'string[]'}
    lines = [f'usage: {executable} [-h] [--ros-args [-p NAME:=VALUE] [--params-file FILE] '
             '[-r FROM:=TO] ...]', '',
             f"ROS 2 node '{node}'{' (managed: lifecycle services)' if managed else ''}: "
             f'{does}; {topics}.', '',
             'parameters (name type default; ranges and descriptions: docs/ros_interface.md):']
    for s in specs:
        default = '[]' if s.kind is list else repr(s.default)
        lines.append(f'  {s.name:<32} {kinds[s.kind]:<8} {default}'
                     f"{'  (read-only)' if s.read_only else ''}")
    if managed:
        lines.append(f"  {'autostart':<32} {'bool':<8} False  (read-only; configure and "
                     'activate at start)')
    lines += ['', f'example: {executable} --ros-args --params-file node.yaml -r current:=/daq/ch0']
    return '\n'.join(lines)
