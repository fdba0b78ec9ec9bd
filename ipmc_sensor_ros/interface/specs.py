# SPDX-License-Identifier: Apache-2.0
"""
Parameters of the nodes and of ``ipmc-model estimate``, without ROS.

One source for the parameter names, defaults, units and ranges
(:class:`Spec`), for reading them from a ROS 2 params file
(:func:`load_params_file`, which ``--ros-args --params-file`` files also are)
and for checking them (:func:`check_values`).  The sensor model and the
estimators are built from them in :mod:`.builders`.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from ..errors import ParameterError, did_you_mean
from ..estimation.deflection import ESTIMATORS
from ..estimation.config import CONFIG_FIELDS, SETTINGS
from ..estimation.inverse import DEFAULT_LEAK_CORNER_HZ
from ..estimation.stream import MAX_BLOCK_SAMPLES
from ..physics.effects import load_plugins  # noqa: F401 (re-exported for the node)
from ..physics.model import BASES
from ..physics.parameters import (GEOMETRY_LIMITS_M, MATERIAL_LIMITS, MaterialParameters,
                                  read_yaml, short_repr)
from ..lti.reduction import MAX_ORDER

__all__ = ['Spec', 'ParameterError', 'GEOMETRY_SPECS', 'MATERIAL_SPECS', 'MODEL_SPECS',
           'QOS_SPECS', 'ESTIMATOR_SPECS', 'PUBLISH_POINTS', 'MATERIAL_NAMES', 'GEOMETRY_NAMES',
           'ARRAY_SPECS', 'MAX_CHANNELS', 'defaults', 'load_params_file', 'check_choice',
           'check_values', 'markdown_table', 'FRAME_ID_PATTERN', 'DIAGNOSTICS_SPECS',
           'STREAM_DIAGNOSTICS_SPECS', 'describe_exception']


@dataclass(frozen=True)
class Spec:
    """
    One parameter: name, default, type, description (with unit), range, read-only flag.

    ``kind`` is float, int, str, bool or list (list = string array; its default
    must be empty: it is declared by type, unset means empty).  Every number has a
    range (``low``..``high``, inclusive); a string may have a ``pattern`` (full match)
    and a ``max_length`` in characters.
    """

    name: str
    default: Any
    kind: type
    description: str
    low: float | None = None
    high: float | None = None
    read_only: bool = False
    choices: tuple[str, ...] = ()
    pattern: str = ''
    max_length: int | None = None
    #: a string a params file may write as a number (``mains_hz: 50``, as the simulator's
    #: integer of the same name): the number is taken as its text ('50')
    numbers_as_text: bool = False


_M = MaterialParameters()
_SLIM = {'length_m': 0.022, 'width_m': 0.007, 'thickness_m': 0.00036}

GEOMETRY_SPECS = tuple(
    Spec(name, _SLIM[name], float, f"{text}, m (default: the paper's 'slim' sample)",
         low=GEOMETRY_LIMITS_M[name][0], high=GEOMETRY_LIMITS_M[name][1])
    for name, text in (('length_m', 'free length L of the cantilever, clamp to tip'),
                       ('width_m', 'width W of the sample'),
                       ('thickness_m', 'total thickness 2h of the sample')))

MATERIAL_SPECS = tuple(
    Spec(name, getattr(_M, name), float, text,
         low=MATERIAL_LIMITS[name][0], high=MATERIAL_LIMITS[name][1])
    for name, text in (
        ('youngs_modulus_pa', "Young's modulus Y, Pa"),
        ('surface_resistance_ohm', 'surface-electrode resistance r0 per unit length and width, '
                                   'ohm (H2 only)'),
        ('diffusivity_m2_per_s', 'ionic diffusivity d, m^2/s'),
        ('anion_concentration_mol_per_m3', 'anion concentration C-, mol/m^3'),
        ('permittivity_f_per_m', 'effective dielectric permittivity kappa_e, F/m'),
        ('charge_stress_coupling_j_per_c', 'charge-stress coupling alpha0, J/C'),
        ('temperature_k', 'absolute temperature T, K')))

MODEL_SPECS = (
    Spec('model', 'h2', str, "base model: 'h1' (eq. 31) or 'h2' (eq. 45, with surface "
         'resistance)', choices=tuple(sorted(BASES))),
    Spec('effects', [], list, "extra effects beyond the base model, each 'name' or "
         "'name(param=value, ...)' from the effects catalog, e.g. ['time_delay(delay_s=0.002)'];"
         ' unknown names and effects already in the base model are refused'),
    Spec('model_file', '', str, "saved model (ipmc-model/1 YAML written by 'ipmc-model fit|"
         "diagnose --save-model'): its base, effects with their fitted values and its material "
         "replace 'model', 'effects' and the material parameters, which must then keep their "
         "defaults ('' = none)", read_only=True, max_length=4096),
    Spec('apply_recording_effects', False, bool, 'also apply the recording effects of '
         "'model_file' (offset and its drift, channel delay: properties of the calibration "
         'records, not of the sensor; off: the estimator learns its own offset)',
         read_only=True),
    Spec('plugins', [], list, 'Python files defining more effects (Effect subclasses, see the '
         "README's plugin API): arbitrary code, loaded once at start-up (sha256 logged), "
         'never re-read; they cannot replace a built-in effect', read_only=True),
)

QOS_SPECS = (
    Spec('qos_depth', 1000, int, 'KEEP_LAST history depth of the data subscription and '
         'publishers, messages', low=1, high=100000, read_only=True),
    Spec('qos_reliability', 'reliable', str, "'reliable' or 'best_effort' for the data topics",
         read_only=True, choices=('reliable', 'best_effort')),
)

MATERIAL_NAMES = tuple(s.name for s in MATERIAL_SPECS)
GEOMETRY_NAMES = tuple(s.name for s in GEOMETRY_SPECS)


#: Allowed values of ``publish_points``.
PUBLISH_POINTS = ('per_sample', 'last_of_block', 'none')  # not "off": YAML reads off as false

#: Characters allowed in ``frame_id`` (tf2 frame names: letters, digits, _ / . -).
FRAME_ID_PATTERN = r'[A-Za-z0-9_/.\-]+'

#: Parameters of the diagnostics (declared by every node that publishes /diagnostics).
DIAGNOSTICS_SPECS = (
    Spec('hardware_id', '', str, 'hardware_id of the DiagnosticStatus messages (e.g. the DAQ '
         "channel or sensor serial); empty = the node's fully qualified name", read_only=True),
    Spec('stale_after_s', 2.0, float, 'diagnostics: ERROR when no sample arrived for this '
         'long, s', low=0.01, high=1e6),
    Spec('rate_tolerance', 0.05, float, 'diagnostics: WARN when the measured sample rate is '
         'off sample_rate_hz by more than this fraction', low=0.0, high=10.0),
    Spec('offset_warn_a', 100e-9, float, 'diagnostics: WARN when the estimated current '
         'offset (mean over offset_window_s) exceeds this, A', low=0.0, high=1.0),
    Spec('offset_window_s', 10.0, float, 'diagnostics: window of the current offset estimate, '
         's (much longer than the motion)', low=0.01, high=1e4),
    Spec('line_warn_fraction', 0.05, float, 'diagnostics: WARN when the 50/60 Hz line '
         "amplitude exceeds this fraction of the current's RMS", low=0.0, high=10.0),
)

#: Diagnostics parameters of a stream of samples the node receives (the estimator's input).
STREAM_DIAGNOSTICS_SPECS = (
    Spec('loss_warn_fraction', 0.01, float, 'diagnostics: WARN when more than this fraction '
         'of the samples of a diagnostics period (1 s) was lost before the node (gaps in the '
         'stamps, bridged ones included; messages of the followed publisher that never '
         'arrived) or refused by the stream rules', low=0.0, high=1.0),
)


ESTIMATOR_SPECS = GEOMETRY_SPECS + MATERIAL_SPECS + MODEL_SPECS + (
    Spec('reduction_order', 4, int, 'order n of the stable reduction of R(s) = H(s)/s',
         low=1, high=MAX_ORDER),
    Spec('band_low_hz', 0.1, float, 'lower edge of the reduction fit band, Hz',
         low=1e-4, high=1e5),
    Spec('band_high_hz', 50.0, float, 'upper edge of the reduction fit band, Hz',
         low=1e-4, high=1e5),
    Spec('sample_rate_hz', 1000.0, float, 'nominal sample rate of the current, Hz; the rate '
         'is measured from the stamps, a mismatch beyond rate_tolerance is reported and the '
         'filter runs at the measured rate', low=1.0, high=1e6, read_only=True),
    Spec('estimator', 'kalman', str, "'kalman': the state-space Kalman filter (sensor, motion "
         'about a working point, current offset and drift, mains lines; rest as a '
         "measurement; publishes its standard deviation); 'leaky': the leaky inverse of the "
         'reduced model, a simple baseline without uncertainty', choices=ESTIMATORS,
         read_only=True),
    Spec('leak_corner_hz', 0.0, float, "estimator 'leaky' only: leak corner f_c, Hz (time "
         'constant 1/(2 pi f_c) of the initial-condition and held-step decay); 0 = '
         f'{DEFAULT_LEAK_CORNER_HZ:g} Hz', low=0.0, high=1e4),
    Spec('offset_corner_hz', 0.0, float, "estimator 'leaky' only: corner of the current-offset "
         'tracker, Hz (0 = off)', low=0.0, high=1e4),
    Spec('mains_hz', 'auto', str, "mains hum: 'auto' measures a line near 50 or 60 Hz in the "
         "data and models it (line states at the measured frequency); '50' or '60' measures "
         "near that one; '0' = no hum model (the leaky baseline notches '50'/'60' and ignores "
         "'auto')", choices=('auto', '0', '50', '60'), numbers_as_text=True),
    Spec('frame_id', 'ipmc_clamp', str, 'frame of the deflection points: origin at the '
         'clamp, x along the beam to the tip, z in the bending direction',
         pattern=FRAME_ID_PATTERN, max_length=128),
    Spec('max_gap_s', 0.1, float, 'largest time gap between consecutive samples bridged by '
         'the filter without a reset, s; a longer gap, or a stamp further back, starts a new '
         'run (filter reset)', low=1e-6, high=1e6),
    Spec('publish_points', 'per_sample', str, "deflection PointStamped output: 'per_sample', "
         "'last_of_block' or 'none'", choices=PUBLISH_POINTS),
    Spec('smoothed_lag_s', 0.0, float, "estimator 'kalman': also publish the deflection "
         "smoothed with this lag on 'deflection/smoothed/block' (fixed-lag Rauch-Tung-Striebel "
         'on the filter; each sample goes out between the lag and twice it after it was '
         'measured), s; 0 = off', low=0.0, high=60.0, read_only=True),
    Spec('max_block_samples', 100_000, int, 'largest accepted input block, samples',
         low=1, high=MAX_BLOCK_SAMPLES, read_only=True),
) + tuple(
    # every setting of the Kalman estimator, from its one table (estimation/config.py)
    Spec(st.name, st.default, type(st.default),
         f"estimator 'kalman': {st.text}" + (f', {st.unit}' if st.unit else ''),
         low=st.low, high=st.high)
    for st in SETTINGS
) + QOS_SPECS + DIAGNOSTICS_SPECS + STREAM_DIAGNOSTICS_SPECS

#: Largest sensor array one node handles.
MAX_CHANNELS = 256

#: Sensor-array parameters of the estimator (README "Sensor arrays").
ARRAY_SPECS = (
    Spec('channels', 1, int, 'sensors in the array: input blocks carry one current column per '
         "channel ('time_s,current_ch0_A,...' when > 1), outputs one deflection column per "
         'channel', low=1, high=MAX_CHANNELS, read_only=True),
    Spec('model_files', [], list, "one saved model per channel (as 'model_file'; '' = the "
         "node's model for that channel); empty = every channel uses the node's model",
         read_only=True),
)
ESTIMATOR_SPECS = ESTIMATOR_SPECS + ARRAY_SPECS


#: Parameters whose change needs a new reduction (the sensor model changes).
MODEL_KEYS = GEOMETRY_NAMES + MATERIAL_NAMES + ('model', 'effects', 'model_file',
                                                'apply_recording_effects', 'reduction_order',
                                                'band_low_hz', 'band_high_hz')
#: Parameters whose change needs a new filter on the same reduction.
FILTER_KEYS = ('sample_rate_hz', 'leak_corner_hz', 'offset_corner_hz', 'estimator',
               'mains_hz') + CONFIG_FIELDS


def model_key(values: Mapping[str, Any]) -> tuple:
    """
    Return the values that decide the reduced model.

    Equal keys: the reduction can be reused.
    """
    return tuple((k, tuple(values[k]) if isinstance(values[k], list) else values[k])
                 for k in MODEL_KEYS)


def filter_key(values: Mapping[str, Any]) -> tuple:
    """Return the values that decide the filter on a given reduction."""
    return tuple(values[k] for k in FILTER_KEYS)


def check_choice(name: str, value: Any, choices: Iterable[str]) -> str:
    """Return ``value`` if it is one of ``choices``, else raise ParameterError naming ``name``."""
    choices = tuple(choices)
    if value not in choices:
        raise ParameterError(f"parameter '{name}' must be one of {list(choices)}, "
                             f'got {short_repr(value)}')
    return value


def check_values(values: Mapping[str, Any], specs: Iterable[Spec] | None = None) -> None:
    """
    Check every value in ``values`` that has a spec (type, range, choices, pattern, length).

    The same rules as a params file and the ROS descriptors. Raises
    :class:`ParameterError` naming the parameter.
    """
    for spec in (ESTIMATOR_SPECS if specs is None else specs):
        if spec.name in values:
            _check_value(spec, values[spec.name], '')


def describe_exception(exc: BaseException, limit: int = 300) -> str:
    """
    Return ``'Type: message'`` of ``exc`` on one line, the message cut at ``limit`` chars.

    A :class:`ParameterError` is the message alone: it names the parameter and the place.
    """
    text = ' '.join(str(exc).split())
    text = text if len(text) <= limit else text[:limit] + '...'
    if isinstance(exc, ParameterError) and text:
        return text
    return f'{type(exc).__name__}: {text}' if text else type(exc).__name__


def defaults(specs: Iterable[Spec]) -> dict[str, Any]:
    """Return the default values of ``specs`` (string arrays default to empty lists)."""
    return {s.name: (list(s.default) if s.kind is list else s.default) for s in specs}


def _check_value(spec: Spec, value: Any, where: str) -> Any:
    where = f'{where}: ' if where else ''
    shown = short_repr(value)
    if spec.kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParameterError(f"{where}parameter '{spec.name}' must be a number, got {shown}")
        try:
            value = float(value)
        except OverflowError:
            raise ParameterError(
                f"{where}parameter '{spec.name}' = {shown} is too large"
            ) from None
    elif spec.kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ParameterError(f"{where}parameter '{spec.name}' must be an integer, got {shown}")
    elif spec.kind is str:
        if spec.numbers_as_text and isinstance(value, (int, float)) \
                and not isinstance(value, bool):
            value = f'{value + 0.0:g}'       # -0.0 is '0', as 0
        if not isinstance(value, str):
            raise ParameterError(f"{where}parameter '{spec.name}' must be a string, got {shown}")
    elif spec.kind is bool:
        if not isinstance(value, bool):
            raise ParameterError(
                f"{where}parameter '{spec.name}' must be true or false, got {shown}"
            )
    elif spec.kind is list:
        if isinstance(value, str) or not isinstance(value, (list, tuple)) \
                or not all(isinstance(v, str) for v in value):
            raise ParameterError(f"{where}parameter '{spec.name}' must be a list of strings, "
                                 f'got {shown}')
        value = [v for v in value if v]
    if spec.low is not None and not (spec.low <= value <= spec.high):  # NaN fails too
        raise ParameterError(f"{where}parameter '{spec.name}' = {shown} is outside "
                             f'[{spec.low:g}, {spec.high:g}]')
    if spec.choices and value not in spec.choices:
        raise ParameterError(f"{where}unknown {spec.name} {shown}: parameter '{spec.name}' "
                             f'must be one of {list(spec.choices)}')
    if spec.max_length is not None and len(value) > spec.max_length:
        raise ParameterError(f"{where}parameter '{spec.name}' is {len(value)} characters long, "
                             f'more than {spec.max_length}: {shown}')
    if spec.pattern and not re.fullmatch(spec.pattern, value):
        raise ParameterError(f"{where}parameter '{spec.name}' = {shown} does not match "
                             f'{spec.pattern} (allowed characters, not empty)')
    return value


def load_params_file(path: str | Path, node_name: str = 'ipmc_estimator',
                     specs: Sequence[Spec] | None = None) -> dict[str, Any]:
    """
    Parameter values for ``node_name`` from a ROS 2 params file, on top of the defaults.

    Sections that apply: ``/**``, ``/**/<node_name>``, ``<node_name>`` and
    ``/<node_name>`` (later ones win), each with ``ros__parameters``.  Unknown
    keys, wrong types, out-of-range values and unit mistakes (e.g. a length in
    millimetres) raise :class:`ParameterError` naming the key and the file;
    so do unreadable files (not UTF-8, not YAML, ``!!python`` tags: one line with
    file:line).  ``use_sim_time`` is accepted and ignored here.
    """
    from .builders import build_model  # at call time: builders imports this module

    specs = ESTIMATOR_SPECS if specs is None else specs
    path = Path(path)
    try:
        doc = read_yaml(path, 'parameters file')
    except ParameterError as exc:
        raise ParameterError(str(exc)) from None
    if not isinstance(doc, dict):
        raise ParameterError(f"{path}: expected a mapping of node names to 'ros__parameters'")
    values = defaults(specs)
    by_name = {s.name: s for s in specs}
    found = False
    for key in ('/**', f'/**/{node_name}', node_name, f'/{node_name}'):
        section = doc.get(key)
        if section is None:
            continue
        if not isinstance(section, dict) or 'ros__parameters' not in section:
            raise ParameterError(f"{path}: section '{key}' has no 'ros__parameters'")
        found = True
        params = section['ros__parameters'] or {}
        if not isinstance(params, dict):
            raise ParameterError(f"{path}: 'ros__parameters' of section '{key}' must be a "
                                 f'mapping, got {short_repr(params)}')
        for name, value in params.items():
            if name == 'use_sim_time':
                continue
            if name not in by_name:
                raise ParameterError(f'{path}: unknown parameter {short_repr(name)} in section '
                                     f"'{key}'{did_you_mean([str(name)], by_name)} "
                                     f'(known: {sorted(by_name)})')
            if by_name[name].kind is float and type(value) is int:    # as the node's rcl
                raise ParameterError(f"{path}: parameter '{name}' = {value} is an integer; a "
                                     f'ROS 2 node refuses it for a double: write {value}.0')
            values[name] = _check_value(by_name[name], value, str(path))
    if not found:
        raise ParameterError(f"{path}: no section for node '{node_name}' (expected one of "
                             f"'/**', '/**/{node_name}', '{node_name}')")
    try:
        build_model(values)
    except ParameterError as exc:
        raise ParameterError(f'{path}: {exc}') from None
    except Exception as exc:  # numerics of an extreme but in-range combination
        raise ParameterError(f'{path}: these parameter values do not give a usable model: '
                             f'{describe_exception(exc)}') from None
    return values


def markdown_table(specs: Iterable[Spec]) -> str:
    """Parameter table (name, type, default, range, description) for the docs."""
    names = {float: 'double', int: 'int', str: 'string', bool: 'bool', list: 'string[]'}
    rows = ['| parameter | type | default | range | description |', '|---|---|---|---|---|']
    for s in specs:
        if s.kind is list:
            default = '[]'
        elif s.kind is str:
            default = f'"{s.default}"'
        elif s.kind is bool:
            default = str(s.default).lower()
        else:
            default = f'{s.default:g}' if s.kind is float else str(s.default)
        fmt = '{:g}' if s.kind is float else '{}'
        rng = f'{fmt.format(s.low)} .. {fmt.format(s.high)}' if s.low is not None else (
            ' \\| '.join(str(c) for c in s.choices) if s.choices else '')
        ro = ' **read-only**' if s.read_only else ''
        kind = names[s.kind] + (' (or int)' if s.numbers_as_text else '')
        rows.append(f'| `{s.name}` | {kind} | {default} | {rng} | {s.description}{ro} |')
    return '\n'.join(rows)
