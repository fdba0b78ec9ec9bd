# SPDX-License-Identifier: Apache-2.0
"""
Saved models on the command line: ``--model-file``, ``--apply-recording-effects``, ``--save``.

A model file (:mod:`~ipmc_sensor_ros.physics.modelfile`) is read once per command, its notices
and the fate of its recording effects printed; ``estimate`` turns it into node parameter
values; ``fit --save`` writes the fitted model as a ROS 2 params file (a view of the same
model, as rcl reads it); ``fit``/``diagnose`` say what they saved and which command comes next.
"""
from __future__ import annotations

import datetime
from pathlib import Path

from ..physics.modelfile import RECORDING_FLAG, ModelFile, load_model
from ..physics.parameters import MaterialParameters, ParameterError
from ..workbench.io import natural_key
from ..workbench.measurements import round_rate_hz
from .args import say

__all__ = ['add_model_file_args', 'saved_model', 'recording_effects_wanted', 'estimate_values',
           'params_file_doc', 'params_file_text', 'params_file_paths', 'write_params_files',
           'data_files', 'print_saved', 'with_recording_flag']

#: physical constants of MaterialParameters that are not node parameters
_NOT_NODE_PARAMS = ('faraday_constant_c_per_mol', 'gas_constant_j_per_mol_k',
                    'one_minus_anion_volume_fraction')


def add_model_file_args(g, replaces: str = '--model and --params') -> None:
    """``--model-file`` and ``--apply-recording-effects`` (every verb that takes a model)."""
    g.add_argument('--model-file', metavar='FILE',
                   help='a saved model (ipmc-model/1 YAML from --save-model): its sensor effects '
                        f'with their values and its material replace {replaces}')
    g.add_argument('--apply-recording-effects', action='store_true',
                   help="also apply the model file's recording effects (offset, drift, channel "
                        'delay of the calibration records); for those records only: the '
                        'estimator learns its own offset')


def saved_model(args):
    """
    Return the saved model of ``--model-file`` (None without it); with ``--params`` it is refused.

    Two sources of the material, nothing chosen silently.  The file is read once per
    command; its notices and what happens to its recording effects are printed then.
    """
    path = getattr(args, 'model_file', None)
    if not path:
        return None
    if getattr(args, 'params', None):
        raise ParameterError(f'--model-file {path} and --params {args.params} both give the '
                             'material: use one')
    saved = getattr(args, '_saved_model', None)
    if saved is None:
        saved = args._saved_model = _announced(load_model(path), args)
    return saved


def _announced(saved: ModelFile, args) -> ModelFile:
    """Print what reading ``saved`` changed, and whether its recording effects apply."""
    for notice in saved.notices:
        say(f'notice: {notice}')
    note = saved.recording_note(recording_effects_wanted(args))
    if note:
        say(('WARNING: ' if recording_effects_wanted(args) else '') + note)
    return saved


def recording_effects_wanted(args) -> bool:
    """Return True if ``--apply-recording-effects`` was given."""
    return bool(getattr(args, 'apply_recording_effects', False))


def estimate_values(values: dict, explicit: set[str], args) -> tuple[dict, set[str]]:
    """
    Node parameter values for ``estimate`` with ``--model-file`` (unchanged without it).

    The model file gives the model and the material (``--params`` may still give the filter
    settings, but no model or material value: two sources are refused, naming both); a data
    header whose material disagrees with the file is then a conflict ``--prefer`` decides.
    Returns (values, names given explicitly).
    """
    from ..interface.specs import MATERIAL_NAMES
    from ..physics.modelfile import RECORDING_PARAMETER

    path = getattr(args, 'model_file', None)
    if not path:
        if recording_effects_wanted(args):
            raise ParameterError('--apply-recording-effects applies the recording effects of '
                                 'a --model-file; no --model-file given')
        return values, explicit
    given = sorted(explicit & (set(MATERIAL_NAMES) | {'model', 'effects', 'model_file'}))
    if given:
        raise ParameterError(f'--model-file {path} and --params {args.params} both define the '
                             f'model ({", ".join(given)}): use one')
    saved = _announced(load_model(path), args)
    out = dict(values, model_file=str(path))
    out[RECORDING_PARAMETER] = recording_effects_wanted(args)
    out.update({k: v for k, v in saved.material.to_dict().items() if k in MATERIAL_NAMES})
    return out, explicit | set(MATERIAL_NAMES)


def _effect_text(spec) -> str:
    """``name(p=v, ...)`` with every digit of the fitted values (not the 6 of format_effect)."""
    if not spec.values:
        return spec.name
    return f"{spec.name}({', '.join(f'{k}={v!r}' for k, v in spec.values)})"


def params_file_doc(model, geometry, sample_rate_hz: float | None = None) -> dict:
    """
    ROS 2 params for both nodes, under ``/**/<node>`` (any namespace): a view of ``model``.

    ``model`` is a :class:`~ipmc_sensor_ros.physics.modelfile.ModelFile`: its sensor effects
    and material, with ``geometry`` and the measured sample rate.  Its recording effects are
    not node parameters (the node learns its own offset); nothing else is added.
    """
    material = model.material.to_dict()
    constants = {k: v for k, v in material.items() if k in _NOT_NODE_PARAMS}
    if constants != {k: getattr(MaterialParameters(), k) for k in constants}:
        raise ParameterError(f'the model changes physical constants {sorted(constants)}, which '
                             'are not node parameters: use --save-model and model_file')
    params = {'length_m': geometry.length_m, 'width_m': geometry.width_m,
              'thickness_m': geometry.thickness_m}
    params.update({k: v for k, v in material.items() if k not in _NOT_NODE_PARAMS})
    if sample_rate_hz:
        params['sample_rate_hz'] = round_rate_hz(sample_rate_hz)
    names = [e.name for e in model.effects]
    params['model'] = 'h2' if 'surface_resistance' in names else 'h1'
    extra = [_effect_text(e) for e in model.effects if e.name != 'surface_resistance']
    if extra:
        params['effects'] = extra
    return {'/**/ipmc_estimator': {'ros__parameters': params},
            '/**/ipmc_simulator': {'ros__parameters': dict(params)}}


def params_file_text(doc: dict) -> str:
    """YAML text of a params file as rcl reads it: plain, no anchors or aliases."""
    import yaml

    class _Plain(yaml.SafeDumper):
        def ignore_aliases(self, data) -> bool:
            return True

    return yaml.dump(doc, Dumper=_Plain, sort_keys=False)


def params_file_paths(path: Path, groups) -> list[Path]:
    """Return the params file of each sample geometry: ``path``, or ``NAME_<sample>.yaml``."""
    if len(groups) == 1:
        return [path]
    return [path.with_name(f'{path.stem}_{g.name}{path.suffix}') for g in groups]


def write_params_files(path: Path, groups, data, res) -> list[Path]:
    """
    One params file per sample geometry (``NAME_<sample>.yaml`` when several).

    The fitted model (:func:`params_file_doc`), with each sample's known header values.
    """
    from ..workbench.io import TimeSeries

    fitted = ModelFile.from_model(effects=res.effects, material=res.material)
    written = []
    for g, out in zip(groups, params_file_paths(path, groups)):
        known = {k: v for k, v in g.known.items()
                 if k not in res.free and k in MaterialParameters.__dataclass_fields__}
        view = ModelFile(fitted.effects, fitted.material.replace(**known),
                         fitted.recording_effects)
        rates = {d.sample_rate_hz for d in data
                 if isinstance(d, TimeSeries) and d.geometry == g.geometry}
        doc = params_file_doc(view, g.geometry, rates.pop() if len(rates) == 1 else None)
        sources = sorted({Path(p.source).name for p in g.points if getattr(p, 'source', '')},
                         key=natural_key)
        head = [
            '# Written by ipmc-model fit on '
            f'{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC',
            f'# sample {g.name}: geometry from the data; fitted model {view.name}',
            f"# fitted: {', '.join(res.free)}; chi2/dof {res.chi2:.4g}/{res.dof}",
            f"# data: {', '.join(sources[:12])}{' ...' if len(sources) > 12 else ''}",
        ]
        if view.recording_effects:
            head.append('# not node parameters (recording effects of the calibration): '
                        + ', '.join(_effect_text(e) for e in view.recording_effects))
        head.append('# use: ros2 run ipmc_sensor_ros ipmc_estimator --ros-args --params-file '
                    'THIS_FILE')
        try:
            out.write_text('\n'.join(head) + '\n' + params_file_text(doc), encoding='utf-8')
        except OSError as exc:
            raise ParameterError(f'{out}: cannot write: {exc.strerror or exc}') from None
        written.append(out)
    return written


def data_files(data) -> list[str]:
    """Return the files (and bags) a model was fitted on, in natural order (provenance)."""
    return sorted({str(d.path) for d in data}, key=natural_key)


def print_saved(path) -> None:
    """Say what a saved model holds: the sensor, and what stays with the calibration records."""
    saved = load_model(path)
    print(f'saved the whole model to {path}: {saved.name}')
    if saved.recording_effects:
        print('  ' + saved.recording_note(False))


def with_recording_flag(line: str, model_path) -> str:
    """
    Return the printed next command, with ``--apply-recording-effects`` if it needs it.

    The next command compares the saved model with the records it was fitted on, whose
    recording effects (offset, channel delay) it must then include.
    """
    if model_path and '--model-file' in line and load_model(model_path).recording_effects:
        return f'{line} {RECORDING_FLAG}'
    return line
