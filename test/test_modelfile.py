# SPDX-License-Identifier: Apache-2.0
"""
The model file (``ipmc-model/1``): sensor and recording apart, old files, bounded reading.

Recording effects (:attr:`Effect.scope` 'recording') are kept under the calibration's
provenance and applied only when asked for; files are refused by size before parsing, and
every error names the file.
"""
from __future__ import annotations

import time

import pytest
import yaml

from ipmc_sensor_ros.cli.main import main
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.modelfile import ModelFile, load_model, save_model
from ipmc_sensor_ros.physics.parameters import MAX_YAML_BYTES, PAPER_SAMPLES, ParameterError

SLIM = PAPER_SAMPLES['slim']
FITTED = SensorModel(SLIM, effects=('surface_resistance',
                                    ('amplifier_bandwidth', {'corner_hz': 299.0}),
                                    ('current_offset', {'offset_a': 1.1e-8,
                                                        'drift_a_per_s': -4.8e-10})))


def test_recording_effects_are_kept_apart_and_applied_only_when_asked(tmp_path):
    path = save_model(tmp_path / 'm.yaml', FITTED, tool='test', data_files=['a.csv'])
    doc = yaml.safe_load(path.read_text())
    assert [e['name'] for e in doc['effects']] == ['surface_resistance', 'amplifier_bandwidth']
    assert doc['provenance']['recording_effects'][0]['name'] == 'current_offset'
    saved = load_model(path)
    assert saved.sensor_model(SLIM).effect_names == ('surface_resistance',
                                                     'amplifier_bandwidth')
    assert saved.sensor_model(SLIM, recording=True) == FITTED
    assert 'not applied: current_offset' in saved.summary()
    assert 'APPLIED' in saved.summary(recording=True)
    assert 'recording effects of the calibration' in saved.describe()


def test_old_file_with_offset_in_effects_loads_with_a_notice(tmp_path):
    old = tmp_path / 'old.yaml'
    old.write_text(yaml.safe_dump({
        'format': 'ipmc-model/1', 'base': 'h2',
        'effects': [{'name': 'current_offset', 'values': {'offset_a': 1e-8}}],
        'material': FITTED.material.to_dict(), 'provenance': {'tool': 'ipmc-model diagnose'}}))
    saved = load_model(old)
    assert [e.name for e in saved.effects] == ['surface_resistance']
    assert [e.name for e in saved.recording_effects] == ['current_offset']
    assert len(saved.notices) == 1 and 'old.yaml' in saved.notices[0]
    assert 'current_offset' in saved.notices[0]


def test_sensor_effect_under_recording_is_refused(tmp_path):
    path = save_model(tmp_path / 'm.yaml', FITTED)
    doc = yaml.safe_load(path.read_text())
    doc['provenance']['recording_effects'].append({'name': 'beam_inertia'})
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ParameterError, match='m.yaml: provenance.recording_effects: '
                                             "'beam_inertia' is a property of the sensor"):
        load_model(path)


def test_oversized_file_is_refused_before_parsing(tmp_path):
    big = tmp_path / 'big.yaml'
    with open(big, 'wb') as f:               # sparse: 2 GB on paper, nothing on disk
        f.truncate(2 * 1024 ** 3)
    t0 = time.monotonic()
    with pytest.raises(ParameterError, match=f'big.yaml: model file is .* more than the limit '
                                             f'{MAX_YAML_BYTES}'):
        load_model(big)
    assert time.monotonic() - t0 < 1.0       # refused by its size, not after reading it


def test_binary_file_gives_one_line_naming_it(tmp_path, capsys):
    binary = tmp_path / 'model.bin'
    binary.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(ParameterError, match='model.bin: model file is not UTF-8'):
        load_model(binary)
    data = tmp_path / 'data'
    assert main(['simulate', '--out', str(data), '--samples', 'slim', '--frequencies', '5',
                 '--duration', '2']) == 0
    capsys.readouterr()
    assert main(['compare', str(data), '--model-file', str(binary)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and 'model.bin' in err and 'Decode' not in err


def test_params_view_names_the_fitted_values_without_anchors(tmp_path):
    from ipmc_sensor_ros.cli.saved_models import params_file_doc, params_file_text

    saved = ModelFile.from_model(FITTED)
    text = params_file_text(params_file_doc(saved, SLIM, 999.9999999999991))
    assert '&id' not in text and '*id' not in text
    doc = yaml.safe_load(text)
    p = doc['/**/ipmc_estimator']['ros__parameters']
    assert p['effects'] == ['amplifier_bandwidth(corner_hz=299.0)'] and p['model'] == 'h2'
    assert p['sample_rate_hz'] == 1000.0                # a measured rate, 9 digits
    assert 'current_offset' not in text                 # the recording's, not the sensor's


def test_a_misspelt_key_is_named_with_the_one_it_is_near(tmp_path):
    """A model file's 'materal:' would leave its material unread: refused, the fix named."""
    path = save_model(tmp_path / 'm.yaml', FITTED)
    doc = yaml.safe_load(path.read_text())
    doc['materal'] = doc.pop('material')
    path.write_text(yaml.safe_dump(doc))
    line = 1 + path.read_text().splitlines().index('materal:')
    with pytest.raises(ParameterError, match=rf"m\.yaml:{line}: unknown key\(s\) \['materal'\] "
                                             r"\(known: .*\); did you mean 'material' for "
                                             r"'materal'\?"):
        load_model(path)


def test_a_wrong_effect_or_material_name_is_placed_on_its_line(tmp_path):
    """The line of the item refused, and the name it is near (h2's implied first item aside)."""
    path = tmp_path / 'm.yaml'
    path.write_text('format: ipmc-model/1\nbase: h2\neffects:\n  - name: time_delay\n'
                    '  - name: amplifier_bandwith\n    values: {corner_hz: 200}\n'
                    'material: {diffusivity_m2_per_s: 3.3e-11}\n')
    with pytest.raises(ParameterError, match=r'm\.yaml:5: effects: unknown effect '
                                             r"'amplifier_bandwith'.*did you mean "
                                             r"'amplifier_bandwidth'"):
        load_model(path)
    path.write_text(path.read_text().replace('bandwith', 'bandwidth').replace(
        '{diffusivity', '{difusivity'))
    with pytest.raises(ParameterError, match=r'm\.yaml:7: material: unknown material '
                                             r"parameter.*did you mean 'diffusivity_m2_per_s'"):
        load_model(path)
