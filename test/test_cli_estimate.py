# SPDX-License-Identifier: Apache-2.0
"""
ipmc-model estimate: accuracy at any length, named output columns, geometry precedence.

The geometry precedence is explicit.
"""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from ipmc_sensor_ros.cli.data_verbs import read_estimate
from ipmc_sensor_ros.cli.main import main
from ipmc_sensor_ros.estimation.config import EstimatorConfig
from ipmc_sensor_ros.workbench.io import TimeSeries, read_timeseries, write_timeseries

ROOT = Path(__file__).resolve().parents[1]
SLIM_PARAMS = ROOT / 'config' / 'estimator.yaml'       # the shipped file: slim geometry


@pytest.fixture(scope='module')
def short_run(tmp_path_factory):
    """Return a 6 s short-sample record (L = 11 mm) at 5 Hz, 1 % current noise, and a 1.5 s one."""
    out = tmp_path_factory.mktemp('short')
    assert main(['simulate', '--out', str(out), '--samples', 'short', '--frequencies', '5',
                 '--duration', '6', '--seed', '4']) == 0
    assert (
        main(
            [
                'simulate',
                '--out',
                str(out / 'brief'),
                '--samples',
                'short',
                '--frequencies',
                '3',
                '--duration',
                '1.5',
                '--seed',
                '5',
            ]
        )
        == 0
    )
    return out


def test_conflicting_geometry_is_an_error_naming_both_values(short_run, tmp_path, capsys):
    rc = main(['estimate', str(short_run / 'short_5Hz.csv'), '--params', str(SLIM_PARAMS),
               '--out', str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 2
    assert (
        'length_m = 0.011' in err
        and '0.022' in err
        and 'estimator.yaml' in err
        and '--prefer' in err
    )
    assert not list(tmp_path.iterdir())                 # nothing written


def test_prefer_chooses_and_nrmse_shows_the_consequence(short_run, tmp_path, capsys):
    src = str(short_run / 'short_5Hz.csv')
    js = tmp_path / 'e.json'
    assert main(['estimate', src, '--params', str(SLIM_PARAMS), '--prefer', 'header',
                 '--out', str(tmp_path / 'h'), '--json', str(js)]) == 0
    right = json.loads(js.read_text())[0]['nrmse']
    assert main(['estimate', src, '--params', str(SLIM_PARAMS), '--prefer', 'params',
                 '--out', str(tmp_path / 'p'), '--json', str(js)]) == 0
    wrong = json.loads(js.read_text())[0]['nrmse']
    # 1 % current noise -> about 1 % deflection error; 3 % leaves room for the reduction error.
    assert right < 0.03
    # the slim geometry (twice the length) gives a gain error of order 1: clearly wrong
    assert wrong > 0.5
    assert 'NRMSE' in capsys.readouterr().out


def test_output_keeps_measured_and_names_the_estimate(short_run, tmp_path, capsys):
    assert main(['estimate', str(short_run), '--out', str(tmp_path)]) == 0   # a directory works
    # no --params or --model-file: the paper's material is used, and that is said
    assert "material: the paper's Tables 1-2" in capsys.readouterr().err
    est = read_estimate(tmp_path / 'short_5Hz.estimate.csv')
    measured = read_timeseries(short_run / 'short_5Hz.csv')
    assert set(est) == {'time_s', 'current_A', 'deflection_estimate_m',
                        'deflection_estimate_std_m',
                        'deflection_m', 'deflection_beyond_limit'}
    assert np.array_equal(est['deflection_m'], measured.deflection_m)
    assert np.array_equal(est['time_s'], measured.time_s)               # exact round trip
    assert not np.allclose(est['deflection_estimate_m'], est['deflection_m'])
    header = (tmp_path / 'short_5Hz.estimate.csv').read_text().splitlines()[:12]
    assert '# length_m: 0.011' in header                                 # the geometry used
    assert "# params: defaults of the estimator node (material: the paper's Tables 1-2)" in header


def test_kalman_is_compared_from_when_it_learned_the_level(short_run, tmp_path, capsys):
    """
    The record starts mid-motion (w = 2 mm at t = 0): no estimator can know that level.

    The Kalman learns it over about five time constants of motion_corner_hz (0.08 s at the
    default 10 Hz) and is compared from then on (``settling``).  1 % noise: bound 3 %.
    """
    params = tmp_path / 'kalman.yaml'
    params.write_text(yaml.safe_dump(
        {'/**/ipmc_estimator': {'ros__parameters': {'estimator': 'kalman'}}}))
    js = tmp_path / 'e.json'
    assert main(['estimate', str(short_run / 'short_5Hz.csv'), '--params', str(params),
                 '--out', str(tmp_path / 'k'), '--json', str(js)]) == 0
    out = capsys.readouterr().out
    assert 'five time constants of motion_corner_hz' in out
    row = json.loads(js.read_text())[0]
    assert row['nrmse'] < 0.03
    record_s = 6.0
    used = float(out.split(' s (after the first ')[0].rsplit('over ', 1)[1])
    corner_hz = EstimatorConfig().motion_corner_hz
    # abs 0.01 s: the span is printed to 4 significant figures and the first row is t = 0
    assert used == pytest.approx(record_s - 5 / (2 * np.pi * corner_hz), abs=0.01)


def test_short_record_still_reports_accuracy(short_run, tmp_path, capsys):
    """A 1.5 s record still gets its NRMSE, after the time the estimator needs to settle."""
    assert main(['estimate', str(short_run / 'brief'), '--out', str(tmp_path)]) == 0
    out = capsys.readouterr().out
    settle_s = 5 / (2 * np.pi * EstimatorConfig().motion_corner_hz)
    assert 'NRMSE' in out and f'after the first {settle_s:.4g} s' in out
    value = float(out.split('NRMSE ')[1].split()[0])      # printed in %, as the bench's
    assert out.split('NRMSE ')[1].split()[1] == '%'
    assert value < 5.0         # 1 % noise; a short record leaves a little more of the transient


def test_params_without_geometry_takes_the_header_and_says_so(short_run, tmp_path, capsys):
    doc = yaml.safe_load(SLIM_PARAMS.read_text())
    params = doc['/**/ipmc_estimator']['ros__parameters']
    for key in ('length_m', 'width_m', 'thickness_m'):
        del params[key]
    nogeo = tmp_path / 'nogeo.yaml'
    nogeo.write_text(yaml.safe_dump(doc))
    assert main(['estimate', str(short_run / 'short_5Hz.csv'), '--params', str(nogeo),
                 '--out', str(tmp_path / 'o')]) == 0
    err = capsys.readouterr().err
    assert 'geometry from the data header' in err
    est = (tmp_path / 'o' / 'short_5Hz.estimate.csv').read_text()
    assert '# length_m: 0.011' in est                                    # not the slim default


def test_explicit_sample_rate_mismatch_is_an_error(short_run, tmp_path, capsys):
    doc = yaml.safe_load(SLIM_PARAMS.read_text())
    doc['/**/ipmc_estimator']['ros__parameters']['sample_rate_hz'] = 500.0
    p = tmp_path / 'rate.yaml'
    p.write_text(yaml.safe_dump(doc))
    assert main(['estimate', str(short_run / 'short_5Hz.csv'), '--params', str(p), '--prefer',
                 'header', '--out', str(tmp_path / 'o')]) == 2
    assert 'sample rate 1000 Hz' in capsys.readouterr().err


def test_current_only_input(short_run, tmp_path, capsys):
    ts = read_timeseries(short_run / 'short_5Hz.csv')
    only = tmp_path / 'in' / 'current_only.csv'
    only.parent.mkdir()
    write_timeseries(only, TimeSeries(path='', sample=ts.sample, geometry=ts.geometry, known={},
                                      sample_rate_hz=ts.sample_rate_hz, time_s=ts.time_s,
                                      current_a=ts.current_a))
    assert main(['estimate', str(only), '--out', str(tmp_path / 'o')]) == 0
    assert 'accuracy not reported' in capsys.readouterr().out
    assert set(read_estimate(tmp_path / 'o' / 'current_only.estimate.csv')) == {
        'time_s', 'current_A', 'deflection_estimate_m', 'deflection_estimate_std_m',
        'deflection_beyond_limit'}
    # verbs that need a deflection skip it with a line; only current-only files -> clear error
    assert main(['compare', str(only.parent)]) == 2
    err = capsys.readouterr().err
    assert 'skipped' in err and 'current only' in err and 'no usable data' in err


def test_level_error_is_what_the_detrended_nrmse_leaves_out():
    """
    An estimate off by a level and a drift: the detrended NRMSE is blind to it, level_error not.

    e = m + 1e-4 m + 2e-5 m/s * t over 10 s: start error 1e-4 m, end 3e-4 m (to rounding:
    the line of e - m is exact), raw NRMSE = RMS(1e-4 + 2e-5 t) / RMS(m) (computed directly).
    """
    from ipmc_sensor_ros.workbench.metrics import level_error

    t = np.arange(0, 10, 1e-3)
    m = 1e-3 * np.sin(2 * np.pi * 3 * t)
    e = m + 1e-4 + 2e-5 * t
    level = level_error(e, m)
    assert level['nrmse'] < 1e-9                   # means and trends removed: nothing left
    assert level['start_error_m'] == pytest.approx(1e-4, rel=1e-6)
    assert level['end_error_m'] == pytest.approx(1e-4 + 2e-5 * t[-1], rel=1e-6)
    assert level['mean_error_m'] == pytest.approx(2e-4, rel=1e-3)
    raw = np.sqrt(np.mean((e - m) ** 2) / np.mean(m ** 2))
    assert level['nrmse_raw'] == pytest.approx(raw, rel=1e-9)


def test_estimate_reports_the_level_error_beside_the_nrmse(short_run, tmp_path, capsys):
    js = tmp_path / 'e.json'
    assert main(['estimate', str(short_run / 'short_5Hz.csv'), '--out', str(tmp_path / 'o'),
                 '--json', str(js)]) == 0
    row = json.loads(js.read_text())[0]
    assert {'nrmse', 'nrmse_raw', 'mean_error_m', 'start_error_m', 'end_error_m'} <= set(row)
    assert all(np.isfinite(row[k]) for k in ('nrmse_raw', 'start_error_m', 'end_error_m'))
    out = capsys.readouterr().out
    assert f"NRMSE {100 * row['nrmse']:.3g} % (means and linear trends removed)" in out
    assert f"as measured (nothing removed): {100 * row['nrmse_raw']:.3g} %, level error " \
        f"{row['start_error_m']:+.3g} m at the start, {row['end_error_m']:+.3g} m at the end" \
        in out


def test_a_fault_inside_the_estimator_or_smoother_is_said_and_loses_no_row(
        short_run, tmp_path, capsys, monkeypatch):
    """
    A defect inside the estimator is not a traceback, nor a row lost without a word.

    The smoother raising on a run: that run's live estimate is written (to the bit the
    ``--causal`` output) and the exception is said.  The live filter raising on a block: its
    rows are dropped with a reset (the stream's rule) and the summary says how many.
    """
    from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator

    src = str(short_run / 'short_5Hz.csv')
    assert main(['estimate', src, '--out', str(tmp_path / 'causal'), '--causal']) == 0

    def broken(self, *args, **kwargs):
        raise ValueError('operands could not be broadcast together')
    with monkeypatch.context() as m:
        m.setattr(DeflectionEstimator, 'smooth', broken)
        assert main(['estimate', src, '--out', str(tmp_path / 'smooth')]) == 0
    out = ''.join(capsys.readouterr())                  # faults on stderr, rows on stdout
    assert 'smoother fault (ValueError: operands could not be broadcast together)' in out
    assert 'their live (causal) estimate is given instead' in out
    causal = read_estimate(tmp_path / 'causal' / 'short_5Hz.estimate.csv')
    smoothed = read_estimate(tmp_path / 'smooth' / 'short_5Hz.estimate.csv')
    assert np.array_equal(smoothed['deflection_estimate_m'], causal['deflection_estimate_m'])

    real, calls = DeflectionEstimator.process, []

    def faulty(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == 2:             # the second 1000-row block
            raise ValueError('matmul: a mismatch in its core dimension')
        return real(self, *args, **kwargs)
    monkeypatch.setattr(DeflectionEstimator, 'process', faulty)
    assert main(['estimate', src, '--out', str(tmp_path / 'dropped'), '--causal',
                 '--json', str(tmp_path / 'o.json')]) == 0
    out = ''.join(capsys.readouterr())                  # faults on stderr, rows on stdout
    assert 'estimator fault (ValueError: matmul: a mismatch in its core dimension)' in out
    row = json.loads((tmp_path / 'o.json').read_text())[0]
    assert row['rows_dropped'] == 1000 and row['rows_estimated'] == row['rows_given'] - 1000
    assert '1000 dropped with a filter reset (no finite estimate)' in out


def test_a_defect_is_one_line_naming_where_and_a_batch_goes_on(
        short_run, tmp_path, capsys, monkeypatch):
    """
    An exception the package did not raise on purpose is said in one line, not a traceback.

    Not the user's input (those are the package's errors, naming the place: exit status 2)
    but a defect (a plain ValueError too, as numpy raises): its type, text and the package
    line it passed, exit status 3.  In a batch of inputs the one that meets it fails and the
    others are written (exit status 1).
    """
    import sys

    import ipmc_sensor_ros.cli.estimate_verb as verb
    cli = sys.modules['ipmc_sensor_ros.cli.main']

    def broken(args):
        raise TypeError("unsupported operand type(s) for +: 'NoneType' and 'float'")
    with monkeypatch.context() as m:
        m.setattr(cli, 'check_outputs', broken)
        assert main(['estimate', str(short_run), '--out', str(tmp_path / 'a')]) == 3
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'Traceback' not in err
    assert err.startswith('ipmc-model estimate: internal error (TypeError: unsupported operand')
    assert ' at cli/main.py:' in err                # the innermost package line it passed
    assert 'a defect of ipmc_sensor_ros, please report it' in err

    def numpy_like(args):             # a ValueError no rule of ours raised: a defect too
        raise ValueError('operands could not be broadcast together with shapes (3,) (4,)')
    with monkeypatch.context() as m:
        m.setattr(cli, 'check_outputs', numpy_like)
        assert main(['estimate', str(short_run), '--out', str(tmp_path / 'a')]) == 3
    assert 'internal error (ValueError: operands could not' in capsys.readouterr().err

    real = verb._checked_current

    def once_broken(data):
        if str(data.path).endswith('short_5Hz.csv'):
            raise IndexError('index 6000 is out of bounds for axis 0 with size 6000')
        return real(data)
    monkeypatch.setattr(verb, '_checked_current', once_broken)
    assert main(['estimate', str(short_run), str(short_run / 'brief'),
                 '--out', str(tmp_path / 'b')]) == 1
    err = capsys.readouterr().err
    assert 'short_5Hz.csv: internal error (IndexError: index 6000 is out of bounds' in err
    assert 'Traceback' not in err
    assert [p.name for p in (tmp_path / 'b').glob('*.estimate.csv')] == ['short_3Hz.estimate.csv']


def test_a_record_that_starts_before_zero_is_estimated_whole(short_run, tmp_path, capsys):
    """
    A DAQ's pre-trigger (time from -1 s) or host jitter on the first stamp (-33 us).

    The stream's stamps are >= 0 live, and the rows before 0 s were refused as out of range
    (1,000 of 8,000; 179 % raw NRMSE): fed from 0 s, published at their own times, the
    estimate is the one of the same record from 0 s to the last bit.
    """
    ts = read_timeseries(short_run / 'short_5Hz.csv')
    early = tmp_path / 'early.csv'
    write_timeseries(early, replace(ts, time_s=ts.time_s - 1.0))
    for path, out in ((short_run / 'short_5Hz.csv', 'a'), (early, 'b')):
        assert main(['estimate', str(path), '--out', str(tmp_path / out), '--causal']) == 0
    assert '0 refused' in capsys.readouterr().out.splitlines()[-1]
    a = read_estimate(tmp_path / 'a' / 'short_5Hz.estimate.csv')
    b = read_estimate(tmp_path / 'b' / 'early.estimate.csv')
    assert np.array_equal(b['time_s'], ts.time_s - 1.0)
    # the same stream from 0 s, its stamps (t - 1) + 1 within an ulp of t's
    assert np.max(np.abs(a['deflection_estimate_m'] - b['deflection_estimate_m'])) < 1e-12
