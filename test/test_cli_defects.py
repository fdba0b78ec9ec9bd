# SPDX-License-Identifier: Apache-2.0
"""
Small defects of the command line, each at its rule (issue 28).

* ``fit --effects time_delay --free ...,delay_s``: one parameter, not "listed twice";
* unnamed samples are labelled by their geometry, named bags by their sidecar's name;
* a measured sample rate is kept to 9 significant digits (no 999.9999999999991);
* file lists in natural order (1Hz before 13Hz) in saved files and printed lists;
* compare's amplitude bins never read ``2-2 mm``;
* ``--geometry 360um`` is 0.00036 m exactly.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from ipmc_sensor_ros.cli.args import parse_geometry
from ipmc_sensor_ros.cli.main import main
from ipmc_sensor_ros.physics.modelfile import load_model
from ipmc_sensor_ros.workbench.compare import amplitude_bins
from ipmc_sensor_ros.workbench.io import read_any
from ipmc_sensor_ros.workbench.measurements import TimeSeries, round_rate_hz

LAB = Path(__file__).resolve().parent / 'data' / 'lab'


@pytest.fixture(scope='module')
def sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp('sweep')
    assert main(['simulate', '--out', str(out), '--samples', 'slim', '--frequencies', '1,13,2',
                 '--duration', '3', '--effects', 'time_delay(delay_s=0.002)']) == 0
    return out


def test_fit_frees_an_effect_parameter_named_alone_once(sweep, tmp_path, capsys):
    js = tmp_path / 'f.json'
    assert main(['fit', str(sweep), '--effects', 'time_delay', '--free', 'alpha0,d,delay_s',
                 '--json', str(js)]) == 0
    assert json.loads(js.read_text())['free'] == [
        'charge_stress_coupling_j_per_c', 'diffusivity_m2_per_s', 'time_delay.delay_s']


def test_saved_params_list_the_data_in_natural_order(sweep, tmp_path):
    saved = tmp_path / 'node.yaml'
    assert main(['fit', str(sweep), '--free', 'alpha0', '--save', str(saved)]) == 0
    data_line = next(ln for ln in saved.read_text().splitlines() if ln.startswith('# data:'))
    assert data_line == '# data: slim_1Hz.csv, slim_2Hz.csv, slim_13Hz.csv'


def test_a_model_the_fit_found_inadequate_is_saved_with_that_said(sweep, tmp_path, capsys):
    """
    A model the chi-square test refuses is saved with that said, on the line and in the file.

    The sweep has a 2 ms delay the fitted model lacks (10 degrees at 13 Hz, far above the
    noise); the file says so wherever it is loaded (the node's and estimate's model_file line).
    """
    saved = tmp_path / 'm.yaml'
    assert main(['fit', str(sweep), '--free', 'alpha0', '--save-model', str(saved)]) == 0
    out = capsys.readouterr().out
    assert 'model inadequate' in out and 'saved although the fit found it inadequate' in out
    assert 'which found it INADEQUATE' in load_model(saved).summary()
    assert main(['fit', str(sweep), '--effects', 'time_delay', '--free', 'alpha0,delay_s',
                 '--save-model', str(saved), '--overwrite']) == 0
    assert 'saved although' not in capsys.readouterr().out
    assert 'INADEQUATE' not in load_model(saved).summary()


def test_import_prints_files_in_natural_order(tmp_path, capsys):
    src = (LAB / 'labview_slim_5Hz.csv').read_text(encoding='utf-8')
    for f in ('13', '1', '2'):
        (tmp_path / f'run_{f}Hz.csv').write_text(src, encoding='utf-8')
    files = sorted(str(p) for p in tmp_path.glob('run_*.csv'))     # as a shell glob lists them
    assert main(['import', *files, '--geometry', '22mm,7mm,360um', '--out',
                 str(tmp_path / 'out')]) == 0
    wrote = [ln.rsplit('/', 1)[-1] for ln in capsys.readouterr().out.splitlines()
             if ln.startswith('wrote ')]
    assert wrote == ['run_1Hz.csv', 'run_2Hz.csv', 'run_13Hz.csv']


def test_unnamed_sample_is_labelled_by_its_geometry(tmp_path):
    assert main(['import', str(LAB / 'labview_slim_5Hz.csv'), '--geometry', '22mm,7mm,360um',
                 '--out', str(tmp_path)]) == 0
    js = tmp_path / 'c.json'
    assert main(['compare', str(tmp_path / 'labview_slim_5Hz.csv'), '--json', str(js)]) == 0
    assert json.loads(js.read_text())['records'][0]['sample'] == '22x7x0.36mm'
    assert main(['estimate', str(tmp_path / 'labview_slim_5Hz.csv'), '--out',
                 str(tmp_path / 'est')]) == 0                # the same label, not '# sample: '
    est = (tmp_path / 'est' / 'labview_slim_5Hz.estimate.csv').read_text().splitlines()
    assert '# sample: 22x7x0.36mm' in est


def test_bag_sample_named_by_its_sidecar_also_with_geometry_flag(tmp_path):
    assert main(['simulate', '--out', str(tmp_path), '--samples', 'slim', '--frequencies', '5',
                 '--duration', '2', '--format', 'bag']) == 0
    js = tmp_path / 'c.json'
    assert main(['compare', str(tmp_path / 'slim_5Hz'), '--geometry', '22mm,7mm,360um',
                 '--json', str(js)]) == 0
    assert json.loads(js.read_text())['records'][0]['sample'] == 'slim'


def test_measured_sample_rate_is_rounded_to_nine_digits(tmp_path):
    rate = 1.0 / float(np.median(np.diff(np.arange(6000) / 1000.0)))
    assert rate != 1000.0 and round_rate_hz(rate) == 1000.0
    assert round_rate_hz(1234.56789012345) == 1234.56789      # real digits are kept
    assert main(['import', str(LAB / 'labview_slim_5Hz.csv'), '--geometry', '22mm,7mm,360um',
                 '--out', str(tmp_path)]) == 0
    text = (tmp_path / 'labview_slim_5Hz.csv').read_text()
    assert '# sample_rate_hz: 1000.0\n' in text and '# thickness_m: 0.00036\n' in text
    ts = read_any(tmp_path / 'labview_slim_5Hz.csv')
    assert TimeSeries(ts.path, '', ts.geometry, {}, rate, ts.time_s,
                      ts.current_a).sample_rate_hz == 1000.0


def test_amplitude_bins_never_repeat_an_edge():
    same = [(2e-3, 0.1), (2.0000001e-3, 0.1), (2e-3, 0.2)]
    assert [label for label, _ in amplitude_bins(same)] == ['2 mm']
    spread = [(a * 1e-3, 0.1) for a in (0.5, 0.6, 1.0, 1.1, 2.0, 2.0)]
    bins = amplitude_bins(spread)
    assert sum(len(sel) for _, sel in bins) == len(spread)      # each window in one bin
    assert all(lo != hi for lo, hi in (label[:-3].split('-') for label, _ in bins))


def test_geometry_in_micrometres_is_exact():
    g = parse_geometry('22mm,7mm,360um')
    assert (g.length_m, g.width_m, g.thickness_m) == (0.022, 0.007, 0.00036)


def test_geometry_flag_that_disagrees_with_a_file_is_refused(sweep, tmp_path, capsys):
    """A header's or a sidecar's geometry and --geometry: equal is fine, different refused."""
    csv = str(sweep / 'slim_1Hz.csv')
    assert main(['compare', csv, '--geometry', '22mm,7mm,360um']) == 0
    assert main(['compare', csv, '--geometry', '11mm,7mm,360um']) == 2
    err = capsys.readouterr().err
    assert 'slim_1Hz.csv: the geometry given (--geometry: length_m 0.011' in err
    assert "disagrees with the file's (length_m 0.022" in err
    assert main(['simulate', '--out', str(tmp_path), '--samples', 'slim', '--frequencies', '5',
                 '--duration', '2', '--format', 'bag']) == 0
    assert main(['compare', str(tmp_path / 'slim_5Hz'), '--geometry', '11mm,7mm,360um']) == 2
    assert 'ipmc.yaml: the geometry given' in capsys.readouterr().err


@pytest.mark.parametrize('flags, message', [
    (['--duration', '-1'], 'argument --duration: must be > 0'),
    (['--sample-rate', '0'], 'argument --sample-rate: must be > 0'),
    (['--noise-rel', '-0.1'], 'argument --noise-rel: must be >= 0'),
    (['--frequencies', '600'], "--frequencies: '600': each must be above 0 and below half the "
                               '--sample-rate (500 Hz)'),
    (['--set', 'd=abc'], "--set d=abc: 'abc' is not a number"),
])
def test_simulate_names_the_bad_flag_and_writes_nothing(tmp_path, capsys, flags, message):
    out = tmp_path / 'out'
    try:                                  # argparse's own errors exit; ours return 2
        code = main(['simulate', '--out', str(out), '--samples', 'slim', *flags])
    except SystemExit as exc:
        code = exc.code
    assert code == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_fit_with_no_more_data_values_than_free_parameters_is_refused(sweep, capsys):
    """One record is one frequency point (gain, phase): two values cannot judge three."""
    assert main(['fit', str(sweep / 'slim_1Hz.csv')]) == 2
    assert ('3 free parameter(s) (charge_stress_coupling_j_per_c, diffusivity_m2_per_s, '
            'permittivity_f_per_m) but only 2 data values' in capsys.readouterr().err)
    assert main(['fit', str(sweep / 'slim_1Hz.csv'), '--free', 'd']) == 0


def test_a_misspelt_header_key_is_refused_and_a_note_kept(tmp_path):
    """'temperatur_k' would leave the model at 300 K without a word; 'operator' is a note."""
    rows = '\n'.join(f'{k * 1e-3},{1e-3 * np.sin(k / 30)},{1e-9 * np.cos(k / 30)}'
                     for k in range(200))
    head = ('# format: ipmc-timeseries/1\n# sample: slim\n# length_m: 0.022\n'
            '# width_m: 0.007\n# thickness_m: 0.00036\n{}\ntime_s,deflection_m,current_A\n')
    typo, note = tmp_path / 'typo.csv', tmp_path / 'note.csv'
    typo.write_text(head.format('# temperatur_k: 350') + rows)
    note.write_text(head.format('# operator: lab 2') + rows)
    with pytest.raises(ValueError, match=r"typo.csv:6: header key 'temperatur_k' is not one of "
                                         r"the format; did you mean 'temperature_k'\?"):
        read_any(typo)
    assert read_any(note).extra == {'operator': 'lab 2'}


def test_estimate_refuses_an_existing_output_before_the_work(sweep, tmp_path, capsys):
    csv = str(sweep / 'slim_1Hz.csv')
    assert main(['estimate', csv, '--out', str(tmp_path)]) == 0
    capsys.readouterr()
    assert main(['estimate', csv, '--out', str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert 'slim_1Hz.estimate.csv: exists, written from' in err
    assert 'estimating' not in err                # refused before the estimator ran


@pytest.mark.parametrize('verb, flag', [
    ('diagnose', '--save-model'), ('diagnose', '--save-plugin'), ('fit', '--save'),
    ('fit', '--save-model'), ('fit', '--save-material')])
def test_an_existing_output_file_is_refused_before_the_data_is_read(
        verb, flag, tmp_path, capsys):
    calibrated = tmp_path / 'm.yaml'
    calibrated.write_text('kept\n')
    assert main([verb, 'no-such-data', flag, str(calibrated)]) == 2
    err = capsys.readouterr().err
    assert 'm.yaml: exists, written at' in err and f'choose another {flag}' in err
    assert 'no-such-data' not in err              # refused before the data was looked for
    assert calibrated.read_text() == 'kept\n'     # nothing lost


@pytest.mark.parametrize('flag', ['--save-model', '--json'])
def test_an_output_in_no_directory_is_refused_before_the_work(sweep, tmp_path, capsys, flag):
    """--save-model nodir/x.yaml failed only when the diagnosis was over."""
    target = tmp_path / 'nodir' / 'x.yaml'
    assert main(['diagnose', str(sweep), flag, str(target)]) == 2
    err = capsys.readouterr().err
    assert f'{flag} {target}: no directory {target.parent} to write it in' in err
    assert 'diagnosing' not in err


def test_two_flags_naming_one_file_are_refused(tmp_path, capsys):
    out = tmp_path / 'm.yaml'
    assert main(['diagnose', 'no-such-data', '--save-model', str(out), '--json', str(out)]) == 2
    assert 'the same file as --json' in capsys.readouterr().err
    assert not out.exists()


def test_simulate_refuses_existing_records_and_overwrite_replaces_them(tmp_path, capsys):
    flags = ['simulate', '--out', str(tmp_path), '--samples', 'slim', '--frequencies', '5',
             '--duration', '1']
    assert main(flags) == 0
    record = tmp_path / 'slim_5Hz.csv'
    record.write_text('a record kept\n')
    capsys.readouterr()
    assert main(flags + ['--seed', '1']) == 2
    assert 'slim_5Hz.csv: exists' in capsys.readouterr().err
    assert record.read_text() == 'a record kept\n'
    assert main(flags + ['--seed', '1', '--overwrite']) == 0
    assert read_any(record).current_a.size == 1000      # 1 s at 1 kHz, written anew


def test_import_refuses_an_existing_output_and_overwrite_replaces_it(tmp_path, capsys):
    src = tmp_path / 'run_5Hz.csv'
    src.write_text((LAB / 'labview_slim_5Hz.csv').read_text(encoding='utf-8'), encoding='utf-8')
    out = tmp_path / 'out'
    flags = ['import', str(src), '--geometry', '22mm,7mm,360um', '--out', str(out)]
    assert main(flags) == 0
    capsys.readouterr()
    assert main(flags) == 2
    assert '--overwrite' in capsys.readouterr().err
    assert main(flags + ['--overwrite']) == 0


def test_an_interval_prints_with_the_digits_that_tell_its_ends_apart():
    from ipmc_sensor_ros.workbench.freqfit import interval_digits

    for value, lo, hi in ((104.00022, 103.99994, 104.0005), (3.3e-11, 3.2e-11, 3.4e-11),
                          (2.0, 1.0, 3.0), (5.0, 5.0 - 1e-12, 5.0 + 1e-12)):
        d = interval_digits(value, lo, hi)
        texts = [f'{x:.{d}g}' for x in (lo, value, hi)]
        assert 4 <= d <= 10
        assert len(set(texts)) == 3 or d == 10        # a gap below 1e-10 relative: capped


def test_an_unknown_flag_is_named_with_the_verbs_usage_and_a_near_flag(tmp_path, capsys):
    """``estimate ... --casual``: the verb's usage, the flag, and ``--causal`` suggested."""
    with pytest.raises(SystemExit) as exc:
        main(['estimate', str(tmp_path / 'x.csv'), '--out', str(tmp_path / 'o'), '--casual'])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert 'usage: ipmc-model estimate' in err
    assert 'unrecognized arguments: --casual (did you mean --causal?)' in err
    assert not (tmp_path / 'o').exists()
