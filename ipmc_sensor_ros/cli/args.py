# SPDX-License-Identifier: Apache-2.0
"""
Shared pieces of the ``ipmc-model`` verbs.

One flag vocabulary, argument parsing helpers, data loading, progress
lines and JSON output.

Flag vocabulary (the same name means the same thing in every verb)
    ``--model``      base model, h1 (eq. 31) or h2 (eq. 45)
    ``--effects``    extra effects added to the base model
    ``--plugin``     Python file defining more effects
    ``--params``     material YAML or a ROS 2 params file of the nodes
    ``--model-file`` a saved model (:mod:`.saved_models`); ``--apply-recording-effects``
                     also applies its calibration's offset and channel delay
    ``--set``        override one material parameter
    ``--free``       parameters estimated from the data (fit, track, diagnose)
    ``--geometry``   sample geometry 'L,W,T' (metres, or with units mm/um)
    ``--samples``    paper samples (big, slim, short)
    ``--out``        output DIRECTORY (always a directory)
    ``--json``       output FILE with the verb's numbers as JSON
    ``--report``     output DIRECTORY for index.html and PNG plots
    ``--save``       output FILE: ROS 2 params file for the nodes
    ``--save-model`` output FILE: the whole fitted model (ipmc-model/1)
"""
from __future__ import annotations

import argparse
import json
import math
import re
import sys
import threading
import time
from pathlib import Path

import numpy as np

from ..physics.effects import load_plugin
from ..physics.model import model_effects, parse_effects
from ..workbench.discovery import SYMBOL_TO_NAME
from ..workbench.io import natural_key
from ..physics.parameters import (PAPER_PARAMETERS, PAPER_SAMPLES, Geometry, MaterialParameters,
                                  ParameterError, load_yaml)

__all__ = ['HelpFormatter', 'Progress', 'say', 'positive', 'nonnegative', 'nonnegative_int',
           'natural_key', 'fmt_time_s', 'param_names', 'parse_geometry', 'material_from_args',
           'load_material', 'effects_from_args', 'expand_inputs', 'load_data', 'add_model_args',
           'add_data_args', 'add_output_args', 'write_json', 'report_dir', 'parse_samples',
           'renamed_flag', 'SYMBOL_TO_NAME']

MATERIAL_KEYS = tuple(MaterialParameters.__dataclass_fields__)
#: Length units and how many of each make a metre (dividing keeps 360 um exactly 0.00036 m).
PER_METRE = {'m': 1.0, 'mm': 1e3, 'um': 1e6, 'µm': 1e6, 'μm': 1e6}


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows ``(default: X)`` for every flag that has a real default (not None/False)."""

    def _get_help_string(self, action):
        text = action.help or ''
        if action.default in (None, False, '', argparse.SUPPRESS) or '%(default)' in text:
            return text
        if action.option_strings or action.nargs in (argparse.OPTIONAL, argparse.ZERO_OR_MORE):
            return text + ' (default: %(default)s)'
        return text


def positive(text: str) -> float:
    """Argparse type: a finite number > 0 (argparse names the flag in its error)."""
    return _number(text, lambda v: v > 0, '> 0')


def nonnegative(text: str) -> float:
    """Argparse type: a finite number >= 0."""
    return _number(text, lambda v: v >= 0, '>= 0')


def nonnegative_int(text: str) -> int:
    """Argparse type: an integer >= 0."""
    value = int(text) if re.fullmatch(r'\s*\d+\s*', text) else -1
    if value < 0:
        raise argparse.ArgumentTypeError(f'expected an integer >= 0, got {text!r}')
    return value


def _number(text: str, ok, rule: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected a number {rule}, got {text!r}') from None
    if not (math.isfinite(value) and ok(value)):
        raise argparse.ArgumentTypeError(f'must be {rule}, got {text!r}')
    return value


def say(msg: str) -> None:
    """Return a progress/status line on stderr (stdout keeps the results)."""
    print(f'... {msg}', file=sys.stderr, flush=True)


class Progress:
    """
    Progress lines for anything that may take over 5 s.

    ``step(msg)`` prints at most one line every ``interval_s`` seconds (the
    first and, via ``done``, the last always); inside ``with Progress(...)``
    a heartbeat line with the elapsed time is printed every ``heartbeat_s``
    once the work has run ``quiet_s`` seconds, so opaque library calls are
    not silent either.
    """

    def __init__(self, what: str, *, interval_s: float = 2.0, quiet_s: float = 5.0,
                 heartbeat_s: float = 5.0, out=None):
        self.what, self.interval_s, self.quiet_s = what, interval_s, quiet_s
        self.heartbeat_s = max(heartbeat_s, interval_s)
        self.out = out or sys.stderr
        self.t0 = time.monotonic()
        self._last = -np.inf
        self._last_msg = ''
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()

    def _print(self, msg: str) -> None:
        with self._lock:
            self._last = time.monotonic()
            print(
                f'... {self.what}: {msg} [{self._last - self.t0:.0f} s]', file=self.out, flush=True
            )

    def step(self, msg: str) -> None:
        self._last_msg = msg
        if time.monotonic() - self._last >= self.interval_s:
            self._print(msg)

    __call__ = step

    def _beat(self) -> None:
        while not self._stop.wait(self.interval_s / 4):
            now = time.monotonic()
            if now - self.t0 >= self.quiet_s and now - self._last >= self.heartbeat_s:
                self._print(f"still working ({self._last_msg or 'running'})")

    def __enter__(self) -> 'Progress':
        self._thread = threading.Thread(target=self._beat, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        if time.monotonic() - self.t0 >= self.quiet_s and exc[0] is None:
            self._print('done')


def fmt_time_s(t: float) -> str:
    """Return a time with sensible precision: 4 significant digits, no float noise."""
    return f'{float(t):.4g}'


def param_names(text: str, flag: str = '--free') -> tuple[str, ...]:
    """Full material names from a comma list of symbols (d, alpha0, ...) or full names."""
    out = []
    for item in filter(None, (x.strip() for x in text.split(','))):
        name = SYMBOL_TO_NAME.get(item, item)
        if name not in MATERIAL_KEYS:
            raise ParameterError(
                f"{flag}: unknown parameter '{item}'; use {sorted(SYMBOL_TO_NAME)} "
                f'or full names {list(MATERIAL_KEYS)}'
            )
        out.append(name)
    if not out:
        raise ParameterError(f'{flag}: no parameter given')
    return tuple(out)


def parse_geometry(text: str, name: str = '', flag: str = '--geometry') -> Geometry:
    """'L,W,T' in metres, or each value with a unit: '22mm,7mm,360um'."""
    parts = [p.strip() for p in text.split(',')]
    if len(parts) != 3:
        raise ParameterError(f"{flag}: expected 'L,W,T' (length, width, thickness), got {text!r}")
    values = []
    for part in parts:
        m = re.fullmatch(r'([-+0-9.eE]+)\s*([a-zµμ]*)', part)
        if not m or m.group(2) not in ('', *PER_METRE):
            raise ParameterError(f'{flag}: cannot read {part!r}; use metres or a unit '
                                 f'{sorted(PER_METRE)}, e.g. 22mm,7mm,360um')
        values.append(float(m.group(1)) / PER_METRE[m.group(2) or 'm'])
    return Geometry(*values, name=name)


def parse_samples(text: str, flag: str = '--samples') -> list[str]:
    names = [s.strip() for s in text.split(',') if s.strip()]
    unknown = [n for n in names if n not in PAPER_SAMPLES]
    if unknown or not names:
        raise ParameterError(f'{flag}: unknown sample(s) {unknown}; paper samples are '
                             f'{sorted(PAPER_SAMPLES)}')
    return names


def load_material(path) -> MaterialParameters:
    """
    Material from a workbench YAML (``material:``) or a ROS 2 params file.

    ROS 2 params files are read with the nodes' own loader
    (:func:`~ipmc_sensor_ros.interface.specs.load_params_file`), so section
    precedence is the same as in the node.
    """
    from ..physics.parameters import read_yaml

    data = read_yaml(path, 'parameters file') or {}
    if isinstance(data, dict) and any(isinstance(v, dict) and 'ros__parameters' in v
                                      for v in data.values()):
        from ..interface.specs import load_params_file

        values = load_params_file(path)
        return MaterialParameters.from_dict(
            {k: v for k, v in values.items() if k in MATERIAL_KEYS}, where=str(path)
        )
    return load_yaml(path)[0]


def material_from_args(args) -> MaterialParameters:
    material = PAPER_PARAMETERS
    from .saved_models import saved_model

    saved = saved_model(args)
    if saved is not None:
        material = saved.material
    elif getattr(args, 'params', None):
        material = load_material(args.params)
    for item in getattr(args, 'set', None) or []:
        if '=' not in item:
            raise ParameterError(f'--set expects name=value, got {item!r}')
        k, v = item.split('=', 1)
        try:
            value = float(v)
        except ValueError:
            raise ParameterError(f'--set {item}: {v!r} is not a number') from None
        material = material.replace(**{param_names(k, '--set')[0]: value})
    return material


def effects_from_args(args) -> tuple:
    for plugin in getattr(args, 'plugin', None) or []:
        names = load_plugin(plugin)
        say(f"plugin {plugin}: effects {', '.join(names)}")
    from .saved_models import recording_effects_wanted, saved_model

    extra = getattr(args, 'effects', '') or ''
    saved = saved_model(args)
    if saved is None:
        if recording_effects_wanted(args):
            raise ParameterError('--apply-recording-effects applies the recording effects of '
                                 'a --model-file; no --model-file given')
        return model_effects(args.model, extra)
    base = saved.effects_for(recording_effects_wanted(args))
    added = parse_effects(extra)
    for e in added:
        if e.name in {b.name for b in base}:
            raise ParameterError(f"--effects: '{e.name}' is already in --model-file "
                                 f'{args.model_file} (with its fitted values)')
    return tuple(base) + tuple(added)


def expand_inputs(paths) -> list[Path]:
    """
    Return the files and bags named by ``paths``.

    A directory that is not a bag gives its .csv/.txt/.tsv files and bags (natural order).
    """
    out: list[Path] = []
    for path in paths:
        p = Path(path)
        if p.is_dir() and not (p / 'metadata.yaml').exists():
            inner = [x for x in p.iterdir() if x.suffix in ('.csv', '.txt', '.tsv')
                     or (x.is_dir() and (x / 'metadata.yaml').exists())]
            if not inner:
                raise ParameterError(f'{p}: directory holds no .csv/.txt files and no bags')
            out.extend(sorted(inner, key=natural_key))
        else:
            out.append(p)
    return out


def load_data(args, *, need_deflection: bool = True) -> list:
    """
    Read every input named by ``args.data`` in natural order.

    Time series without a deflection column are skipped (with a line saying
    so) when ``need_deflection``; an error if nothing is left.
    """
    from ..workbench.bags import same_geometry
    from ..workbench.io import TimeSeries, read_any, read_bag

    geometry = parse_geometry(args.geometry, getattr(args, 'sample', '') or '') \
        if getattr(args, 'geometry', None) else None
    out = []
    for p in sorted(expand_inputs(args.data), key=natural_key):
        if p.is_dir() or p.suffix in ('.mcap', '.db3'):
            item = read_bag(p, args.current_topic, args.deflection_topic, geometry)
        else:
            item = read_any(p)
            if geometry is not None and getattr(item, 'geometry', None) is not None:
                same_geometry(str(p), item.geometry, geometry)     # the header holds one
        if need_deflection and isinstance(item, TimeSeries) and item.deflection_m is None:
            say(f'skipped {p}: current only (no deflection column)')
            continue
        out.append(item)
    if not out:
        raise ParameterError('no usable data: ' + ('every input lacks a deflection column'
                                                   if need_deflection else 'no input given'))
    return out


def renamed_flag(parser: argparse.ArgumentParser, old: str, new: str) -> None:
    """Return a hidden flag kept only to say it was renamed (exit 2 with a hint)."""

    class _Renamed(argparse.Action):
        def __call__(self, parser, namespace, values, option_string=None):
            parser.error(f'{old} was renamed {new} (same meaning)')

    parser.add_argument(old, action=_Renamed, help=argparse.SUPPRESS)


def add_model_args(p: argparse.ArgumentParser, *, effects: bool = True) -> None:
    g = p.add_argument_group('model')
    g.add_argument('--model', default='h2', metavar='h1|h2',
                   help='base model: h1 (eq. 31) or h2 = h1 + surface_resistance (eq. 45)')
    if effects:
        g.add_argument('--effects', default='', metavar='LIST',
                       help="extra effects, e.g. 'time_delay' or "
                            "'time_delay(delay_s=0.002),nonlinearity' (see: ipmc-model effects)")
        g.add_argument('--plugin', action='append', metavar='FILE',
                       help='Python file defining more effects (repeatable)')
    from .saved_models import add_model_file_args

    add_model_file_args(g)
    g.add_argument('--params', metavar='FILE',
                   help="material YAML ('material:') or a ROS 2 params file of the nodes "
                        "(default: the paper's Tables 1-2)")
    g.add_argument('--set', action='append', metavar='NAME=VALUE',
                   help='override a material parameter, e.g. --set d=3e-11 (repeatable)')


def add_data_args(p: argparse.ArgumentParser, frf: bool = True) -> None:
    kinds = 'ipmc-timeseries/1 or ipmc-frf/1 files' if frf else 'ipmc-timeseries/1 files'
    p.add_argument('data', nargs='+',
                   help=f'{kinds}, directories of them, or rosbag2 bags (see: ipmc-model import '
                        'for lab files)')
    g = p.add_argument_group('data')
    g.add_argument('--current-topic', default='current', metavar='TOPIC',
                   help='bags: topic of the current blocks')
    g.add_argument('--deflection-topic', default='deflection_truth', metavar='TOPIC',
                   help='bags: topic of the measured deflection')
    g.add_argument('--geometry', metavar='L,W,T',
                   help='bags without ipmc.yaml sidecar: length, width, thickness in metres or '
                        'with units (22mm,7mm,360um); refused where it disagrees with a '
                        "file's own")


def add_output_args(p: argparse.ArgumentParser, *, report: bool = True) -> None:
    g = p.add_argument_group('output')
    g.add_argument('--json', metavar='FILE', help='write the numbers as JSON to this file')
    if report:
        g.add_argument('--report', metavar='DIR',
                       help='write index.html and PNG plots into this directory')
    g.add_argument('--overwrite', action='store_true',
                   help='replace saved models, parameter files and records that exist '
                        '(default: refuse before any work, naming what wrote them; --json and '
                        '--report are replaced)')


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, complex):
        return [o.real, o.imag]
    return str(o)


def write_json(path, obj) -> None:
    if path:
        Path(path).write_text(json.dumps(obj, indent=2, default=_json_default))


def report_dir(path) -> Path | None:
    if not path:
        return None
    d = Path(path)
    d.mkdir(parents=True, exist_ok=True)
    return d
