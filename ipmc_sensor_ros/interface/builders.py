# SPDX-License-Identifier: Apache-2.0
"""
Build the sensor model and the estimators from checked parameter values.

The names, units and ranges are in :mod:`.specs`.  The estimator node and the
offline ``ipmc-model estimate`` both go through :func:`build_estimator`: one
code path, one parameters file.
"""
from __future__ import annotations

from typing import Any, Mapping

from ..errors import ParameterError
from ..estimation.config import CONFIG_FIELDS, EstimatorConfig
from ..estimation.deflection import DeflectionEstimator
from ..lti.reduction import ReducedModel
from ..physics.effects import load_plugins
from ..physics.model import SensorModel
from ..physics.parameters import Geometry, MaterialParameters, short_repr
from .specs import (check_values, describe_exception, GEOMETRY_NAMES, MATERIAL_NAMES,
                    MATERIAL_SPECS, MODEL_SPECS, model_key)

__all__ = ['build_model', 'model_file_summary', 'build_estimator', 'channel_values',
           'build_channel_estimators']


def build_model(values: Mapping[str, Any]) -> SensorModel:
    """
    Build a SensorModel from geometry, material, ``model`` and ``effects`` parameter values.

    Plugins (``plugins``) are loaded on the first call only
    (:func:`~ipmc_sensor_ros.physics.effects.load_plugins`: never re-executed).
    Raises :class:`ParameterError` naming the offending parameter.
    """
    try:
        load_plugins(values.get('plugins') or ())
    except ParameterError as exc:
        raise ParameterError(f"parameter 'plugins': {exc}") from None
    geometry = Geometry(**{k: values[k] for k in GEOMETRY_NAMES})
    if values.get('model_file'):
        return _model_from_file(values, geometry)
    material = MaterialParameters(**{k: values[k] for k in MATERIAL_NAMES})
    extra = tuple(str(e) for e in values.get('effects') or ())
    try:
        return SensorModel.named(values['model'], geometry, material, extra)
    except ParameterError as exc:
        raise ParameterError(f"parameter 'effects' = {short_repr(list(extra))} with model "
                             f"{short_repr(values['model'])}: {exc}") from None


def _model_from_file(values: Mapping[str, Any], geometry: Geometry) -> SensorModel:
    """
    Return the model of ``model_file`` for ``geometry``.

    The file and the parameters are two sources of the same values: a model or effect
    parameter that differs from its default, or a material parameter that differs from its
    default and from the file's value, is refused (naming both), never silently overridden.
    The file's recording effects are applied only with ``apply_recording_effects``.
    """
    from ..physics.modelfile import load_model

    path = values['model_file']
    try:
        saved = load_model(path)
    except ParameterError as exc:       # the file's own problem, with the parameter named
        raise ParameterError(f"parameter 'model_file': {exc}") from None
    spec_default = {s.name: s.default for s in MODEL_SPECS + MATERIAL_SPECS}
    in_file = saved.material.to_dict()
    for name in ('model', 'effects') + MATERIAL_NAMES:
        if values[name] != spec_default[name] and values[name] != in_file.get(name):
            raise ParameterError(
                f"parameter '{name}' = {short_repr(values[name])} and "
                f"model_file {path} both define the model: leave '{name}' at "
                f'its default ({short_repr(spec_default[name])}) or drop model_file'
            )
    return saved.sensor_model(geometry, recording=bool(values.get('apply_recording_effects')))


def model_file_summary(values: Mapping[str, Any]) -> list[str]:
    """
    Return the lines a node logs about its model files (none without ``model_file``).

    What the file holds, where it came from, and whether its recording effects are applied
    (with the warning when they are), plus the notices of reading it.
    """
    from ..physics.modelfile import load_model

    files = [values.get('model_file') or ''] + list(values.get('model_files') or ())
    lines = []
    for path in dict.fromkeys(f for f in files if f):
        saved = load_model(path)
        lines.extend(saved.notices)
        lines.append(saved.summary(bool(values.get('apply_recording_effects'))))
    return lines


def build_estimator(
    values: Mapping[str, Any], reduced: ReducedModel | None = None
) -> DeflectionEstimator:
    """
    Return the core estimator from parameter values.

    ``reduced`` reused when the model part did not change. Raises ParameterError /
    ParameterError / ParameterError / ParameterError naming the parameter; any other
    failure of the numerics (e.g. a LinAlgError) becomes a one-line ParameterError.
    """
    check_values(values)
    try:
        model = build_model(values)
        band = (float(values['band_low_hz']), float(values['band_high_hz']))
        if not band[0] < band[1]:
            raise ParameterError(f"parameters 'band_low_hz' ({band[0]}) and 'band_high_hz' "
                                 f'({band[1]}) must satisfy low < high')
        offset = float(values['offset_corner_hz'])
        leak = float(values['leak_corner_hz'])
        config = EstimatorConfig(**{name: values[name] for name in CONFIG_FIELDS})
        return DeflectionEstimator(model, float(values['sample_rate_hz']),
                                   reduction_order=int(values['reduction_order']), band_hz=band,
                                   leak_corner_hz=leak if leak > 0.0 else None,
                                   offset_corner_hz=offset if offset > 0.0 else None,
                                   reduced=reduced, estimator=values['estimator'],
                                   mains_hz=values['mains_hz'], config=config,
                                   smoothed_lag_s=float(values['smoothed_lag_s']))
    except ParameterError:
        raise
    except Exception as exc:  # numerics of an extreme but in-range combination
        raise ParameterError(f'these parameter values do not give a usable model: '
                             f'{describe_exception(exc)}') from None


def channel_values(values: Mapping[str, Any], channel: int) -> dict[str, Any]:
    """
    Return the parameter values of one channel of a sensor array.

    The node's values, with ``model_file`` replaced by the channel's entry of ``model_files``
    when that entry is not empty.  Raises :class:`ParameterError` when ``model_files`` has
    neither zero nor ``channels`` entries.
    """
    files = list(values.get('model_files') or ())
    n = int(values.get('channels', 1))
    if files and len(files) != n:
        raise ParameterError(f"parameter 'model_files' has {len(files)} entries for channels = "
                             f"{n}: give one per channel ('' = the node's model) or none")
    out = dict(values)
    if files and files[channel]:
        out['model_file'] = files[channel]
    return out


def build_channel_estimators(values: Mapping[str, Any],
                             reduced: Mapping[tuple, ReducedModel] | None = None
                             ) -> list[DeflectionEstimator]:
    """
    One estimator per channel of a sensor array (:func:`channel_values`).

    ``reduced`` maps :func:`model_key` to a reduction to reuse; channels with equal model keys
    share one reduction.  Errors name the channel's model file.
    """
    cache = dict(reduced or {})
    out = []
    for c in range(int(values.get('channels', 1))):
        v = channel_values(values, c)
        key = model_key(v)
        try:
            est = build_estimator(v, cache.get(key))
        except ParameterError as exc:
            if v['model_file'] == values.get('model_file'):
                raise
            raise ParameterError(f"parameter 'model_files' entry {c}: {exc}") from None
        cache[key] = est.reduced
        out.append(est)
    return out
