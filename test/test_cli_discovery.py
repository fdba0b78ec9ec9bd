# SPDX-License-Identifier: Apache-2.0
"""
CLI of the discovery loop: diagnose saves the whole model, compare/track read it.

The verdict ends with the exact next command; fit frees effect parameters and saves the
model. Small campaign (slim + short at 2 and 10 Hz, 3 s) to keep it short.
"""
import json
import shlex

import pytest

from ipmc_sensor_ros.cli.main import main
from ipmc_sensor_ros.physics.modelfile import load_model


@pytest.fixture(scope='module')
def data(tmp_path_factory):
    out = tmp_path_factory.mktemp('disc') / 'data'
    assert (
        main(
            [
                'simulate',
                '--out',
                str(out),
                '--model',
                'h2',
                '--effects',
                'time_delay(delay_s=0.002)',
                '--samples',
                'slim,short',
                '--frequencies',
                '2,10',
                '--duration',
                '3',
                '--seed',
                '3',
            ]
        )
        == 0
    )
    return out


def test_diagnose_saves_model_and_prints_next_command(data, tmp_path, capsys):
    model_file = tmp_path / 'model.yaml'
    js = tmp_path / 'd.json'
    assert main(['diagnose', str(data), '--model', 'h2', '--save-model', str(model_file),
                 '--json', str(js), '--max-effects', '2', '--mains', 'auto']) == 0
    out = capsys.readouterr().out
    verdict = json.loads(js.read_text())['verdict']
    assert verdict['missing_effects'][0] == 'time_delay' and verdict['explained']
    saved = load_model(model_file)
    # a channel delay belongs to the recording: kept with the calibration, not the sensor
    delay = dict(next(e for e in saved.recording_effects
                      if e.name == 'time_delay').values)['delay_s']
    assert delay == pytest.approx(2e-3, rel=0.05)       # fitted, not the catalog's 1 ms
    last = out.strip().splitlines()[-1]
    assert last.startswith('next: ipmc-model compare') and '--model-file' in last
    assert last.endswith('--apply-recording-effects')   # the same records: their delay too
    argv = shlex.split(last[len('next: '):])[1:]
    js2 = tmp_path / 'c.json'
    assert main(argv + ['--json', str(js2)]) == 0       # the printed command runs as printed
    cmp = json.loads(js2.read_text())
    assert cmp['error'] <= 1.2 * cmp['noise_floor'] + 1e-3   # same 1.2x-floor rule as diagnose


def test_fit_frees_effect_parameter_and_saves_model(data, tmp_path, capsys):
    model_file = tmp_path / 'fit.yaml'
    assert (
        main(
            [
                'fit',
                str(data),
                '--model',
                'h2',
                '--effects',
                'time_delay',
                '--free',
                'd,alpha0',
                '--save-model',
                str(model_file),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert 'time_delay.delay_s' in out and 'model adequate' in out
    saved = load_model(model_file)
    assert dict(saved.recording_effects[-1].values)['delay_s'] == pytest.approx(2e-3, rel=0.05)
    # an effect parameter of an effect not in the model: a one-line error naming the fix
    assert main(['fit', str(data), '--model', 'h2', '--free', 'd,delay_s']) == 2
    assert 'add it with --effects time_delay' in capsys.readouterr().err
