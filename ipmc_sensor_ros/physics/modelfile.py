# SPDX-License-Identifier: Apache-2.0
"""
The whole fitted model in one YAML file (``ipmc-model/1``).

Written by ``ipmc-model diagnose --save-model`` and ``fit --save-model``; read
by ``compare``, ``estimate``, ``simulate`` and the nodes (``model_file``).  The
file holds everything the model needs except the sample geometry, which comes
with each data file or node configuration::

    format: ipmc-model/1
    base: h1                          # the paper's H1 (eq. 31); H2 = h1 + surface_resistance
    effects:                          # in order, with their fitted values (SI units)
      - name: surface_resistance
      - name: amplifier_bandwidth
        values: {corner_hz: 212.4}
    material: {charge_stress_coupling_j_per_c: 104.1, ...}   # every MaterialParameters field
    provenance:                       # how it was obtained (informative, not read back)
      tool: ipmc-model diagnose
      created_utc: '2026-11-22T23:59:00Z'
      data_files: [a.csv, b.csv]
      error: {held_out: 0.0102, noise_floor: 0.0100}
      ci95: {diffusivity_m2_per_s: [3.1e-11, 3.4e-11]}

Errors name the file and the key.
"""
from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

from .model import EffectSpec, SensorModel, parse_effects
from .parameters import Geometry, MaterialParameters, ParameterError

__all__ = ['MODEL_FORMAT', 'ModelFile', 'save_model', 'load_model']

MODEL_FORMAT = 'ipmc-model/1'


@dataclass(frozen=True)
class ModelFile:
    """A saved model: effects (with values), material and provenance."""

    effects: tuple[EffectSpec, ...]
    material: MaterialParameters
    provenance: dict = field(default_factory=dict)
    path: str = ''

    def sensor_model(
        self, geometry: Geometry, known: Mapping[str, float] | None = None
    ) -> SensorModel:
        """
        Return the model for a sample of ``geometry``.

        ``known``: header values that override the saved material, e.g. a measured
        temperature.
        """
        mat = self.material.replace(**dict(known)) if known else self.material
        return SensorModel(geometry, mat, self.effects)

    def describe(self) -> str:
        return SensorModel(Geometry(0.02, 0.005, 2e-4), self.material, self.effects).describe()


def _plain(value: Any) -> Any:
    """YAML-safe plain types (numpy scalars and tuples converted)."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, 'item') and not isinstance(value, (str, bytes)):
        try:
            return value.item()
        except (TypeError, ValueError):
            pass
    return value


def save_model(path, model: SensorModel | None = None, *, effects: Sequence = (),
               material: MaterialParameters | None = None, tool: str = '',
               data_files: Sequence[str] = (), error: Mapping[str, float] | None = None,
               ci95: Mapping[str, Sequence[float]] | None = None,
               extra: Mapping[str, Any] | None = None) -> Path:
    """
    Write a model file (see module docstring).

    ``model`` gives effects and material, or give ``effects`` and ``material`` directly.
    Returns the path.
    """
    import yaml

    if model is not None:
        effects, material = model.effects, model.material
    if material is None:
        raise ParameterError('save_model: no material given')
    specs = parse_effects(effects)
    doc = {
        'format': MODEL_FORMAT,
        'base': 'h1',
        'effects': [
            ({'name': e.name, 'values': dict(e.values)} if e.values else {'name': e.name})
            for e in specs
        ],
        'material': material.to_dict(),
        'provenance': {
            'tool': tool,
            'created_utc': _dt.datetime.now(_dt.timezone.utc).strftime('%Y-%m-%dT%H:%M:%SZ'),
            'data_files': [str(f) for f in data_files],
            'error': dict(error or {}),
            'ci95': dict(ci95 or {}),
            **dict(extra or {}),
        },
    }
    path = Path(path)
    path.write_text(yaml.safe_dump(_plain(doc), sort_keys=False))
    load_model(path)        # what we write must read back
    return path


def load_model(path) -> ModelFile:
    """Read a model file; a one-line :class:`ParameterError` naming the file and key otherwise."""
    import yaml

    path = Path(path)
    if not path.is_file():
        raise ParameterError(f'{path}: model file not found')
    try:
        doc = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ParameterError(f'{path}: not valid YAML: {str(exc).splitlines()[0]}') from None
    if not isinstance(doc, dict) or doc.get('format') != MODEL_FORMAT:
        raise ParameterError(f"{path}: not a model file (expected 'format: {MODEL_FORMAT}')")
    unknown = sorted(set(doc) - {'format', 'base', 'effects', 'material', 'provenance'})
    if unknown:
        raise ParameterError(f'{path}: unknown key(s) {unknown}')
    base = str(doc.get('base', 'h1')).lower()
    if base not in ('h1', 'h2'):
        raise ParameterError(f"{path}: base: must be h1 or h2, got {doc.get('base')!r}")
    items = doc.get('effects') or []
    if not isinstance(items, list):
        raise ParameterError(f'{path}: effects: must be a list of {{name, values}}')
    specs = []
    if base == 'h2':
        specs.append(('surface_resistance', {}))
    for k, item in enumerate(items):
        if not isinstance(item, dict) or 'name' not in item or set(item) - {'name', 'values'}:
            raise ParameterError(
                f'{path}: effects[{k}]: expected {{name: ..., values: {{...}}}}, got {item!r}'
            )
        values = item.get('values') or {}
        if not isinstance(values, dict):
            raise ParameterError(f'{path}: effects[{k}].values: must be a mapping')
        specs.append((str(item['name']), values))
    try:
        effects = parse_effects(specs)
    except ParameterError as exc:
        raise ParameterError(f'{path}: effects: {exc}') from None
    mat = doc.get('material')
    if not isinstance(mat, dict):
        raise ParameterError(f'{path}: material: missing or not a mapping')
    material = MaterialParameters.from_dict(mat, where=f'{path}: material')
    prov = doc.get('provenance') or {}
    return ModelFile(effects, material, prov if isinstance(prov, dict) else {}, str(path))
