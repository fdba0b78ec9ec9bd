# SPDX-License-Identifier: Apache-2.0
"""
The whole fitted model in one YAML file (``ipmc-model/1``).

Written by ``ipmc-model fit --save-model`` and ``diagnose --save-model``; read by
``estimate``, ``compare``, ``simulate`` (``--model-file``) and the nodes (``model_file``).
The file holds everything the model needs except the sample geometry, which comes with
each data file or node configuration.  It keeps the sensor apart from the recording it
was calibrated on (:attr:`~ipmc_sensor_ros.physics.effects.Effect.scope`)::

    format: ipmc-model/1
    base: h1                          # the paper's H1 (eq. 31); H2 = h1 + surface_resistance
    effects:                          # the sensor, in order, with fitted values (SI units)
      - name: surface_resistance
      - name: amplifier_bandwidth
        values: {corner_hz: 212.4}
    material: {charge_stress_coupling_j_per_c: 104.1, ...}   # every MaterialParameters field
    provenance:                       # the calibration: how the model was obtained
      tool: ipmc-model diagnose
      created_utc: '2026-11-22T23:59:00Z'
      data_files: [a.csv, b.csv]
      error: {held_out: 0.0102, noise_floor: 0.0100}
      adequate: true                  # fit: the misfit within the noise (chi2 test); false is
                                      # said wherever the file is loaded
      ci95: {diffusivity_m2_per_s: [3.1e-11, 3.4e-11]}
      recording_effects:              # properties of those recordings, not of the sensor
        - name: current_offset
          values: {offset_a: 1.1e-08, drift_a_per_s: -4.8e-10}
      mains_lines: [{frequency_hz: 50.0, level: 0.03}]

Recording effects (an offset and its drift, a channel delay) are shown to the user and
applied only when asked for (``--apply-recording-effects``, node parameter
``apply_recording_effects``): the estimator learns its own offset, and a calibration's
offset extrapolated over another record is wrong.  A file whose ``effects:`` list holds a
recording effect (written before the split) is read with that effect moved to the
recording part and a notice (:attr:`ModelFile.notices`).

Files larger than :data:`~ipmc_sensor_ros.physics.parameters.MAX_YAML_BYTES` are refused
before parsing; every error names the file (and the key).
"""
from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

from ..errors import did_you_mean
from .effects import get_effect, split_by_scope
from .model import EffectSpec, SensorModel, format_effect, parse_effects
from .parameters import Geometry, MaterialParameters, ParameterError, read_yaml

__all__ = ['MODEL_FORMAT', 'RECORDING_FLAG', 'RECORDING_PARAMETER', 'ModelFile', 'save_model',
           'load_model']

MODEL_FORMAT = 'ipmc-model/1'
#: The one command-line flag and node parameter that apply a file's recording effects.
RECORDING_FLAG = '--apply-recording-effects'
RECORDING_PARAMETER = 'apply_recording_effects'

_HEADER = (f'# {MODEL_FORMAT}: the sensor (base, effects, material) and, under provenance, the\n'
           '# calibration it came from. provenance.recording_effects belong to those recordings\n'
           f'# and are applied to other data only when asked ({RECORDING_FLAG},\n'
           f'# node parameter {RECORDING_PARAMETER}: true).\n')
_KEYS = ('format', 'base', 'effects', 'material', 'provenance')


def _text(specs) -> str:
    return ', '.join(format_effect(e) for e in specs)


@dataclass(frozen=True)
class ModelFile:
    """
    A saved model: the sensor, the recording effects of its calibration, provenance.

    ``effects`` are the sensor's (base included: ``surface_resistance`` for H2),
    ``recording_effects`` those of the calibration recordings, ``notices`` what was
    changed while reading (to be shown to the user).
    """

    effects: tuple[EffectSpec, ...]
    material: MaterialParameters
    recording_effects: tuple[EffectSpec, ...] = ()
    provenance: Mapping[str, Any] = field(default_factory=dict)
    path: str = ''
    notices: tuple[str, ...] = ()

    @classmethod
    def from_model(cls, model: SensorModel | None = None, *, effects: Sequence = (),
                   material: MaterialParameters | None = None,
                   provenance: Mapping[str, Any] | None = None) -> 'ModelFile':
        """Split a fitted model (or ``effects`` and ``material``) into sensor and recording."""
        if model is not None:
            effects, material = model.effects, model.material
        if material is None:
            raise ParameterError('ModelFile.from_model: no material given')
        sensor, recording = split_by_scope(parse_effects(effects))
        return cls(sensor, material, recording, dict(provenance or {}))

    def effects_for(self, recording: bool = False) -> tuple[EffectSpec, ...]:
        """Return the sensor effects, followed by the recording effects when ``recording``."""
        return self.effects + (self.recording_effects if recording else ())

    def sensor_model(self, geometry: Geometry, known: Mapping[str, float] | None = None,
                     recording: bool = False) -> SensorModel:
        """
        Return the model for a sample of ``geometry``.

        ``known``: header values that override the saved material, e.g. a measured
        temperature.  ``recording``: also apply the calibration's recording effects.
        """
        mat = self.material.replace(**dict(known)) if known else self.material
        return SensorModel(geometry, mat, self.effects_for(recording))

    @property
    def name(self) -> str:
        """Text form of the sensor model (``h2,amplifier_bandwidth(corner_hz=299)``)."""
        return SensorModel(Geometry(0.02, 0.005, 2e-4), self.material, self.effects).describe()

    def recording_note(self, applied: bool) -> str:
        """Return the line to show about the recording effects ('' when there are none)."""
        if not self.recording_effects:
            return ''
        where = self.path or 'the model file'
        if applied:
            return (f'{where}: recording effects of the calibration APPLIED: '
                    f'{_text(self.recording_effects)}; the estimator learns its own offset, and '
                    "a calibration's offset, drift or delay carried to another record can make "
                    'the estimate worse')
        return (f'{where}: recording effects of the calibration not applied: '
                f'{_text(self.recording_effects)} (properties of the calibration records; '
                f'{RECORDING_FLAG} / {RECORDING_PARAMETER}: true applies them)')

    def summary(self, recording: bool = False) -> str:
        """One line for logs: the model applied, where it came from, the recording effects."""
        prov = self.provenance
        files = prov.get('data_files') or []
        origin = ', '.join(filter(None, (
            str(prov.get('tool') or ''), str(prov.get('created_utc') or ''),
            f'{len(files)} data file(s)' if files else '',
            'which found it INADEQUATE' if prov.get('adequate') is False else '')))
        line = (f"model_file {self.path or '(unsaved)'}: {self.name}"
                + (f' (calibration: {origin})' if origin else ''))
        note = self.recording_note(recording)
        return f'{line}; {note}' if note else line

    def describe(self) -> str:
        """Several lines for ``ipmc-model info``-like output."""
        prov = self.provenance
        lines = [f'model file {self.path or "(unsaved)"} ({MODEL_FORMAT})',
                 f'  sensor: {self.name}',
                 '  material: ' + ', '.join(f'{k}={v:.6g}'
                                            for k, v in self.material.to_dict().items())]
        lines.append('  recording effects of the calibration (not applied unless '
                     f"{RECORDING_FLAG}): {_text(self.recording_effects) or 'none'}")
        for key in ('tool', 'created_utc', 'data_files', 'error', 'adequate', 'mains_lines'):
            if prov.get(key) or prov.get(key) is False:
                lines.append(f'  {key}: {prov[key]}')
        lines.extend(f'  notice: {n}' for n in self.notices)
        return '\n'.join(lines)

    def to_doc(self) -> dict:
        """Return the YAML document (plain types)."""
        def items(specs):
            return [({'name': e.name, 'values': dict(e.values)} if e.values else
                     {'name': e.name}) for e in specs]

        prov = {k: v for k, v in self.provenance.items() if k != 'recording_effects'}
        prov['recording_effects'] = items(self.recording_effects)
        return _plain({'format': MODEL_FORMAT, 'base': 'h1', 'effects': items(self.effects),
                       'material': self.material.to_dict(), 'provenance': prov})

    def save(self, path) -> Path:
        """Write the file (and read it back: what is written must load); return the path."""
        import yaml

        path = Path(path)
        text = yaml.safe_dump(self.to_doc(), sort_keys=False)
        try:
            path.write_text(_HEADER + text, encoding='utf-8')
        except OSError as exc:
            raise ParameterError(f'{path}: cannot write the model file: '
                                 f'{exc.strerror or exc}') from None
        load_model(path)
        return path


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
    Write a model file (see module docstring); return the path.

    ``model`` gives effects and material, or give ``effects`` and ``material`` directly;
    recording effects go under ``provenance`` (:func:`~.effects.split_by_scope`).
    """
    provenance = {
        'tool': tool,
        'created_utc': _dt.datetime.now(_dt.timezone.utc).strftime('%Y-%m-%dT%H:%M:%SZ'),
        'data_files': [str(f) for f in data_files],
        'error': dict(error or {}),
        'ci95': dict(ci95 or {}),
        **dict(extra or {}),
    }
    saved = ModelFile.from_model(model, effects=effects, material=material,
                                 provenance=provenance)
    return saved.save(path)


def _at(path: Path, key: str, *more) -> str:
    """
    Return ``file:line`` of a key of the document (``a.b``: b under a; then list indices).

    Read again only for an error message: ``file`` alone when the key is not found.
    """
    import yaml

    try:
        node = yaml.compose(path.read_text(encoding='utf-8-sig'), Loader=yaml.SafeLoader)
        mark = None
        for step in (*key.split('.'), *more):
            if isinstance(node, yaml.MappingNode):
                mark, node = next((k.start_mark, v) for k, v in node.value if k.value == step)
            else:
                node = node.value[step]
                mark = node.start_mark
        return f'{path}:{mark.line + 1}'
    except Exception:                   # noqa: BLE001 (a message's place: never a new error)
        return str(path)


def _effect_items(path: Path, items: Any, key: str) -> list[tuple[str, dict]]:
    """``(name, values)`` of a list of ``{name, values}`` items; errors name file and key."""
    if items is None:
        return []
    if not isinstance(items, list):
        raise ParameterError(f'{_at(path, key)}: {key}: must be a list of {{name, values}}')
    out = []
    for k, item in enumerate(items):
        if not isinstance(item, dict) or 'name' not in item or set(item) - {'name', 'values'}:
            raise ParameterError(f'{_at(path, key, k)}: {key}[{k}]: expected '
                                 f'{{name: ..., values: {{...}}}}, got {item!r}')
        values = item.get('values') or {}
        if not isinstance(values, dict):
            raise ParameterError(f'{_at(path, key, k)}: {key}[{k}].values: must be a mapping')
        out.append((str(item['name']), values))
    return out


def _parse(path: Path, items, key: str, listed_from: int = 0) -> tuple[EffectSpec, ...]:
    """Parse effect items; an error names the line of the first item refused alone."""
    try:
        return parse_effects(items)
    except ParameterError as exc:
        alone = [k for k, item in enumerate(items[listed_from:]) if not _parses(item)]
        where = _at(path, key, *alone[:1])
        raise ParameterError(f'{where}: {key}: {exc}') from None


def _parses(item) -> bool:
    try:
        parse_effects([item])
    except ParameterError:
        return False
    return True


def _split_effects(path: Path, doc: dict, prov: dict):
    """(sensor effects, recording effects, notices) of a model document."""
    base = str(doc.get('base', 'h1')).lower()
    if base not in ('h1', 'h2'):
        raise ParameterError(f"{_at(path, 'base')}: base: must be h1 or h2, got "
                             f"{doc.get('base')!r}")
    items = _effect_items(path, doc.get('effects'), 'effects')
    if base == 'h2':
        items.insert(0, ('surface_resistance', {}))
    sensor, moved = split_by_scope(_parse(path, items, 'effects', int(base == 'h2')))
    recording = _parse(path, _effect_items(path, prov.get('recording_effects'),
                                           'provenance.recording_effects'),
                       'provenance.recording_effects')
    for e in recording:
        if get_effect(e.name).scope != 'recording':
            raise ParameterError(f"{path}: provenance.recording_effects: '{e.name}' is a "
                                 "property of the sensor: list it under 'effects'")
    notices = ()
    if moved:
        clash = {e.name for e in moved} & {e.name for e in recording}
        if clash:
            raise ParameterError(f'{path}: {sorted(clash)} listed both in effects and in '
                                 'provenance.recording_effects')
        notices = (f'{path}: {_text(moved)} in effects: belongs to the calibration recording, '
                   'not to the sensor; read as provenance.recording_effects (not applied to '
                   f'other data unless {RECORDING_FLAG} / {RECORDING_PARAMETER}: true); '
                   'save the model again to write it there',)
    return sensor, tuple(moved) + recording, notices


def load_model(path) -> ModelFile:
    """Read a model file; a one-line :class:`ParameterError` naming the file and key otherwise."""
    path = Path(path)
    doc = read_yaml(path, 'model file')
    if not isinstance(doc, dict) or doc.get('format') != MODEL_FORMAT:
        raise ParameterError(f"{path}: not a model file (expected 'format: {MODEL_FORMAT}')")
    unknown = sorted(str(k) for k in set(doc) - set(_KEYS))
    if unknown:
        raise ParameterError(f'{_at(path, unknown[0])}: unknown key(s) {unknown} '
                             f'(known: {", ".join(_KEYS)})'
                             + did_you_mean(unknown, _KEYS))
    prov = doc.get('provenance') or {}
    if not isinstance(prov, dict):
        raise ParameterError(f"{_at(path, 'provenance')}: provenance: must be a mapping")
    sensor, recording, notices = _split_effects(path, doc, prov)
    mat = doc.get('material')
    if not isinstance(mat, dict):
        raise ParameterError(f"{_at(path, 'material')}: material: missing or not a mapping")
    material = MaterialParameters.from_dict(mat, where=f"{_at(path, 'material')}: material")
    prov = {k: v for k, v in prov.items() if k != 'recording_effects'}
    return ModelFile(sensor, material, recording, prov, str(path), notices)
