# SPDX-License-Identifier: Apache-2.0
"""The drawn-record sweep (bench/bench_drawn.py): reproducible records, one judged line each."""
import json
import math

import numpy as np
import pytest

from bench.bench_drawn import describe, main
from bench.scenarios.drawn import draw


def test_a_drawn_record_is_the_same_for_its_index_and_fresh_for_another():
    a, info_a = draw(5, 3.0)
    b, info_b = draw(5, 3.0)
    c, _ = draw(6, 3.0)
    assert np.array_equal(a.current_a, b.current_a) and info_a == info_b
    assert not (a.current_a.size == c.current_a.size and np.array_equal(a.current_a, c.current_a))
    assert a.sample_rate_hz == info_a['sample_rate_hz']
    assert info_a['motion'] in describe(info_a) and info_a['sample'] in describe(info_a)


def test_drawn_records_cover_the_habits_they_claim():
    infos = [draw(i, 2.0)[1] for i in range(24)]
    # 24 draws: each habit (chance 0.25-0.5 per record) is missing from all of them with
    # probability <= 0.75^24 = 1e-3; the indexes are fixed, so this is deterministic
    for key in ('mains_hz', 'stamp_jitter', 'drop_fraction', 'offset_step', 'noise_a',
                'noise_fraction', 'offset_drift_a_per_s'):
        assert any(key in info for info in infos), key
    assert {info['kind'] for info in infos} == {'pick', 'crank', 'sines-hold', 'vibration'}


def test_the_sweep_prints_a_judged_line_per_record_and_the_count(tmp_path, capsys):
    out = tmp_path / 'drawn.json'
    assert main(['--first', '2', '--count', '1', '--duration-s', '3', '--json', str(out)]) == 0
    text = capsys.readouterr().out
    assert text.splitlines()[0].split()[0] == '2'
    assert 'of 1 drawn records within max(2 x causal bound, 1 %)' in text
    row = json.loads(out.read_text())['rows'][0]
    narrow = 'on 1 (2)' if row['coverage'] < 0.9 else 'on 0 ('
    assert f'+-2 sigma coverage below 90 % {narrow}' in text
    assert row['index'] == 2 and row['drawn'] in text
    assert math.isfinite(row['nrmse']) and row['rows_given'] > 0
    assert row['ok'] == (row['nrmse'] <= max(2 * row['causal_bound'], 0.01)
                         and row['rows_estimated'] == row['rows_given'])


def test_a_sweep_too_short_to_judge_is_refused(capsys):
    with pytest.raises(SystemExit) as exc:
        main(['--duration-s', '1'])
    assert exc.value.code == 2
    assert '--duration-s >= 2' in capsys.readouterr().err


def test_a_fault_inside_the_estimator_is_named_on_its_line(tmp_path, capsys, monkeypatch):
    """
    A sweep does not hide a fault inside the estimator.

    The stream drops a call's samples when the estimator raises (the node goes on); the
    record then fails (rows missing) and its line names the exception.
    """
    from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator

    real, calls = DeflectionEstimator.process, []

    def faulty(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == 2:             # the live run's second 1000-row block
            raise ValueError('operands could not be broadcast together')
        return real(self, *args, **kwargs)
    monkeypatch.setattr(DeflectionEstimator, 'process', faulty)
    out = tmp_path / 'drawn.json'
    assert main(['--first', '2', '--count', '1', '--duration-s', '3', '--json', str(out)]) == 0
    line = capsys.readouterr().out.splitlines()[0]
    row = json.loads(out.read_text())['rows'][0]
    assert 'FAULT: estimator fault (ValueError: operands could not' in line
    assert row['fault'].startswith('estimator fault (ValueError') and not row['ok']
    assert row['rows_estimated'] < row['rows_given']
