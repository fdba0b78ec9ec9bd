# SPDX-License-Identifier: Apache-2.0
"""End-to-end tests of the ipmc-model workbench verbs on files written by `simulate`."""
import json

import pytest
import yaml

from ipmc_sensor_ros.cli.main import main
from ipmc_sensor_ros.workbench.io import read_frf, read_timeseries


@pytest.fixture(scope='module')
def sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp('sweep')
    assert main(['simulate', '--out', str(out), '--model', 'h2', '--frequencies', '1:20:6',
                 '--duration', '4', '--seed', '3']) == 0
    return out


def test_simulate_writes_valid_timeseries(sweep):
    files = sorted(sweep.glob('*.csv'))
    assert len(files) == 12   # 2 samples x 6 frequencies
    ts = read_timeseries(files[0])
    assert ts.geometry.length_m in (0.022, 0.011) and ts.deflection_m is not None


def test_compare_json_and_report(sweep, tmp_path):
    js, rep = tmp_path / 'c.json', tmp_path / 'rep'
    assert (
        main(['compare', str(sweep), '--model', 'h2', '--json', str(js), '--report', str(rep)])
        == 0
    )
    right = json.loads(js.read_text())
    assert {'error', 'fit_percent'} <= set(right)
    assert right['fit_percent'] > 97.0   # 1 % noise
    assert (rep / 'index.html').exists()
    assert {p.name for p in rep.glob('*.png')} == {'bode.png', 'time_worst.png', 'residuals.png',
                                                   'residual_spectrum.png', 'failure_map.png'}
    assert main(['compare', str(sweep), '--model', 'h1', '--json', str(js)]) == 0
    wrong = json.loads(js.read_text())
    assert wrong['error'] > 3 * right['error']


def test_fit_saves_params_usable_by_nodes(sweep, tmp_path, capsys):
    saved = tmp_path / 'fitted.yaml'
    assert main(['fit', str(sweep), '--model', 'h2', '--free', 'alpha0,d', '--set', 'd=5e-11',
                 '--save', str(saved), '--report', str(tmp_path / 'r')]) == 0
    # the frequencies it read are said, per sample (a point missing would show here)
    assert '12 frequency point(s) of 2 sample(s): ' in capsys.readouterr().err
    # two samples (slim, short) -> one file per sample geometry, under the namespace-proof key
    saved_short = tmp_path / 'fitted_short.yaml'
    doc = yaml.safe_load(saved_short.read_text())
    p = doc['/**/ipmc_estimator']['ros__parameters']
    assert p['model'] == 'h2'
    assert (p['length_m'], p['width_m'], p['thickness_m']) == (
        0.011,
        0.007,
        0.00036,
    )  # short sample
    assert p['sample_rate_hz'] == 1000.0
    assert p['diffusivity_m2_per_s'] == pytest.approx(3.32e-11, rel=0.05)
    assert doc['/**/ipmc_simulator']['ros__parameters'] == p
    assert 'ipmc-model fit' in saved_short.read_text().splitlines()[0]    # provenance comment
    assert (tmp_path / 'r' / 'index.html').exists()
    # the saved file is accepted back as --params, and by the node's own loader
    from ipmc_sensor_ros.interface.specs import load_params_file
    assert load_params_file(saved_short)['length_m'] == 0.011
    assert main(['compare', str(sweep), '--params', str(saved_short),
                 '--json', str(tmp_path / 'c.json')]) == 0
    assert json.loads((tmp_path / 'c.json').read_text())['fit_percent'] > 97.0


def test_fit_reports_degeneracy(sweep, capsys):
    assert main(['fit', str(sweep), '--free', 'd,C-,kappa_e,alpha0']) == 0
    out = capsys.readouterr().out
    assert 'do not determine' in out and 'sqrt(d)/alpha0' in out
    assert out.count('identifiability:') == 1          # said once


def test_frf_format_round_trip_through_fit(tmp_path):
    out = tmp_path / 'frf'
    assert main(['simulate', '--out', str(out), '--format', 'frf', '--frequencies', '1:20:5',
                 '--duration', '3']) == 0
    files = sorted(out.glob('*.frf.csv'))
    assert len(files) == 2 and read_frf(files[0]).gain_std_a_per_m is not None
    js = tmp_path / 'fit.json'
    assert main(['fit', *map(str, files), '--free', 'alpha0', '--set', 'alpha0=150',
                 '--json', str(js)]) == 0
    est = json.loads(js.read_text())['estimates']['charge_stress_coupling_j_per_c']
    assert est == pytest.approx(104.0, rel=0.01)


def test_track_long_record(tmp_path, capsys):
    out = tmp_path / 'long'
    assert main(['simulate', '--out', str(out), '--samples', 'slim', '--frequencies', '6',
                 '--duration', '130', '--sample-rate', '500',
                 '--effects', 'hydration_drift(diffusivity_rate_per_s=-0.002)']) == 0
    js = tmp_path / 't.json'
    assert main(['track', str(next(out.glob('*.csv'))), '--window', '60', '--json', str(js)]) == 0
    track = json.loads(js.read_text())[0]['track']
    d = [p['estimates']['diffusivity_m2_per_s'] for p in track]
    # d falls by exp(-0.002 * 60) = 0.887 per minute; allow 2 % for window-averaging
    assert d[1] / d[0] == pytest.approx(0.887, abs=0.02)


def test_figures_numbers_match_paper_claims(tmp_path):
    js = tmp_path / 'f.json'
    assert main(['figures', '--report', str(tmp_path / 'figs'), '--json', str(js)]) == 0
    n = json.loads(js.read_text())
    assert n['fig5 big - slim magnitude, mean (dB)'] == pytest.approx(6.02, abs=0.02)  # 20 log10 2
    assert n['fig5 big - slim phase, max |diff| (deg)'] < 0.2  # same phase
    assert n['fig6 slim slope 1-20 Hz, H2 endpoints (dB/decade)'] == pytest.approx(14.9, abs=0.1)
    assert n['fig6 short slope 1-20 Hz, H2 endpoints (dB/decade)'] == pytest.approx(17.3, abs=0.1)
    assert (
        n['fig6 short slope 1-20 Hz, data (dB/decade)']
        > n['fig6 slim slope 1-20 Hz, data (dB/decade)'] + 1.5
    )
    # Fig. 4: H2 fits the phase, H1 does not
    assert n['fig4 h1 fit: rms phase error (deg)'] > 10 * n['fig4 h2 fit: rms phase error (deg)']
    assert (tmp_path / 'figs' / 'fig6.png').exists()


def test_effects_verb_and_bad_inputs(capsys, tmp_path):
    assert main(['effects']) == 0
    out = capsys.readouterr().out
    for name in ('surface_resistance', 'amplifier_bandwidth', 'time_delay', 'current_offset',
                 'hydration_drift', 'effective_length', 'beam_inertia', 'nonlinearity'):
        assert name in out
    assert main(['compare', str(tmp_path / 'missing.csv')]) == 2
    assert 'missing.csv' in capsys.readouterr().err
    assert main(['compare', str(tmp_path), '--effects', 'warp_drive']) == 2
    assert 'warp_drive' in capsys.readouterr().err
