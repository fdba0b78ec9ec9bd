# SPDX-License-Identifier: Apache-2.0
"""Rows a DAQ dropped and stamps it jittered: the record on its sample clock for the model."""
import json

import numpy as np
import pytest

from bench.discovery_records import make_records, Truth
from ipmc_sensor_ros.cli.main import main
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import PAPER_SAMPLES
from ipmc_sensor_ros.simulation.daq import daq_current
from ipmc_sensor_ros.workbench.data import on_sample_grid, taken_at_stamps
from ipmc_sensor_ros.workbench.formats import write_timeseries
from ipmc_sensor_ros.workbench.measurements import TimeSeries
from ipmc_sensor_ros.workbench.stamps import measured_rate_hz
from ipmc_sensor_ros.workbench.timepredict import predict, prepare, Record

DROPPED = [500, 501, 1700, 2900, 2901, 2902]


def _jittered(n=4000, seed=0):
    rng = np.random.default_rng(seed)
    return np.arange(n) * 1e-3 + 5.0 + rng.uniform(-0.2e-3, 0.2e-3, n)   # +-20 % of a period


def test_dropped_rows_are_filled_on_the_sample_clock():
    t = _jittered()
    w = np.sin(2 * np.pi * 3.0 * (5.0 + np.arange(t.size) * 1e-3))     # taken on the slots
    keep = np.setdiff1d(np.arange(t.size), DROPPED)
    t_grid, (w_grid, none), filled, at_stamps = on_sample_grid('rec.csv', t[keep], w[keep],
                                                               None)
    assert not at_stamps                                        # w is on the slots
    assert np.flatnonzero(filled).tolist() == DROPPED
    assert none is None
    assert np.array_equal(t_grid[~filled], t[keep])             # the stamps are kept
    assert np.allclose(t_grid[filled], 5.0 + np.array(DROPPED) * 1e-3, atol=0.25e-3)
    assert np.array_equal(w_grid[~filled], w[keep])             # and their values
    # the spline through the slots: 3 Hz sine, 1-3 samples missing (the clock's line through
    # 4,000 stamps at +-0.2 ms is ~2 us off: 4e-5 of the sine)
    assert np.max(np.abs(w_grid[filled] - w[DROPPED])) < 1e-4


def test_records_on_their_clock_or_off_any_clock_are_left_alone():
    t = _jittered()
    w = np.sin(2 * np.pi * 3.0 * np.arange(t.size) * 1e-3)             # on the slots
    assert on_sample_grid('rec.csv', t, w) is None                     # nothing missing
    rng = np.random.default_rng(1)
    assert on_sample_grid('rec.csv', np.sort(rng.uniform(0, 4, 4000)), t) is None


def test_rows_taken_at_their_stamps_are_put_on_the_clock():
    """
    A DAQ the host times samples when it stamps: the values belong to the jittered instants.

    The deflection is smoother against them than against the slots, so every column is
    interpolated onto the clock: a 13 Hz sine read at +-20 % jitter comes back within 1e-4
    of itself on the slots (cubic spline, 77 samples a period); host-jittered rows (values
    on the slots) are left as they are.
    """
    t = _jittered()
    on_stamps = np.sin(2 * np.pi * 13.0 * t)
    grid = on_sample_grid('rec.csv', t, on_stamps, 2 * on_stamps)
    assert grid.at_stamps and not grid.filled.any()
    assert np.allclose(np.diff(grid.time_s), 1e-3, rtol=1e-6)
    assert np.max(np.abs(grid.columns[0] - np.sin(2 * np.pi * 13.0 * grid.time_s))) < 1e-4
    assert np.array_equal(grid.columns[1], 2 * grid.columns[0])
    on_slots = np.sin(2 * np.pi * 13.0 * (5.0 + np.arange(t.size) * 1e-3))
    assert on_sample_grid('rec.csv', t, on_slots) is None
    assert not taken_at_stamps(np.arange(100) * 1e-3, np.arange(100), np.sin(np.arange(100)))


def test_a_gap_longer_than_max_gap_s_is_refused_with_the_place():
    t = np.delete(np.arange(4000) * 1e-3, np.arange(1000, 1200))       # 0.2 s missing
    with pytest.raises(ValueError, match=r'rec.csv: no sample for 0.201 s after t = 0.999 s.*'
                                         r'max_gap_s \(0.1 s\)'):
        on_sample_grid('rec.csv', t, t)


def test_dropped_rows_leave_the_residual_mean_as_it_is():
    """Six dropped rows of a 5 Hz record move its residual mean by 9 nA, unless filled."""
    rec = make_records(Truth(noise_rel=0.01), 0, samples=('slim',), frequencies_hz=(5.0,))[0]

    def mean_residual(r):
        p = prepare([r])[0]
        return float(np.mean((p.y - predict(p, r.model))[p.keep]))
    keep = np.setdiff1d(np.arange(rec.time_s.size), DROPPED)
    t, w, y = rec.time_s[keep], rec.deflection_m[keep], rec.current_a[keep]
    whole = mean_residual(rec)
    joined = mean_residual(Record(rec.path, rec.sample, rec.model, t, w, y))
    t_g, (w_g, y_g), filled, _ = on_sample_grid(rec.path, t, w, y)
    gridded = mean_residual(Record(rec.path, rec.sample, rec.model, t_g, w_g, y_g, filled))
    scale = float(np.std(rec.current_a))
    # measured (of the current's RMS): joined 7.3e-4 off, gridded 4e-7 (6 of 4000 rows fewer);
    # the mean's own standard error is 1.6e-4 (1 % noise over 4000 samples)
    assert abs(joined - whole) > 3e-4 * scale
    assert abs(gridded - whole) < 3e-5 * scale


@pytest.mark.parametrize('row_matrix_above', [0, 10 ** 9])
def test_the_fit_rows_of_a_record_with_filled_slots_are_its_prediction(row_matrix_above):
    """
    The rows a fit reads are the full prediction at those rows, filled slots between them.

    They skipped the filled slots off the progression the fast row path decimates on, and it
    read each later row's neighbour: 2.7 % of the current's RMS off, which `diagnose` took
    for a missing nonlinearity on a record with 1 % dropped rows.  Exact path: to rounding;
    the row matrix interpolates H on its grid ((h/r)^4 ~ 2e-8 relative, 1e-6 allowed).
    """
    rec = make_records(Truth(noise_rel=0.01), 0, samples=('slim',), frequencies_hz=(5.0,))[0]
    keep = np.setdiff1d(np.arange(rec.time_s.size), np.arange(3, rec.time_s.size, 97))
    t_g, (w_g, y_g), filled, _ = on_sample_grid(rec.path, rec.time_s[keep],
                                                rec.deflection_m[keep], rec.current_a[keep])
    gridded = Record(rec.path, rec.sample, rec.model, t_g, w_g, y_g, filled)
    steps = set()
    for most in range(250, 400, 10):                # row steps 14-23: even ones decimate
        p = prepare([gridded], max_rows_per_record=most, row_matrix_above=row_matrix_above)[0]
        assert not filled[p.rows].any() and np.unique(np.diff(p.rows)).size > 1
        full = predict(p, rec.model)[p.rows]
        rows = predict(p, rec.model, rows=p.rows)
        assert np.max(np.abs(rows - full)) < 1e-6 * np.sqrt(np.mean(full ** 2))
        steps.add(int(p.rows[1] - p.rows[0]))
    assert any(step % 4 == 0 for step in steps)


def test_the_rate_is_the_clock_the_stamps_follow_not_their_median_spacing():
    """
    A 1500 Hz DAQ stamped with +-15 % host jitter and 2 % of its rows dropped.

    1/median(dt) reads the jitter and the gaps (1494.8 Hz here); the line through the stamps'
    slots reads the clock: its standard error on 15,000 rows is ~3e-4 Hz (jitter RMS
    0.087 periods), so 1500 +- 0.002 Hz holds with margin.  A clock 3 ppm slow is followed,
    and float stamps k/1000 read 1000.0 exactly (rounded to the digits they support).
    """
    rng = np.random.default_rng(4)
    k = np.arange(15000)
    t = k / 1500.0 + rng.uniform(-0.15, 0.15, k.size) / 1500.0
    kept = t[rng.random(k.size) > 0.02]
    assert abs(1.0 / np.median(np.diff(kept)) - 1500.0) > 1.0       # what the median read
    assert measured_rate_hz(kept) == pytest.approx(1500.0, abs=2e-3)
    slow = 1000.0 / (1 + 3e-6)
    assert measured_rate_hz(k / slow) == pytest.approx(slow, rel=1e-9)
    assert measured_rate_hz(k / 1000.0) == 1000.0


@pytest.mark.parametrize('hum', [0.0, 0.03])
def test_diagnose_finds_nothing_missing_in_a_record_with_dropped_rows(tmp_path, hum):
    """
    One row in a hundred dropped at random from an h2 record: nothing is missing.

    The fit's rows read their neighbours across the filled slots, and the diagnosis added a
    nonlinearity (held-out error 0.0116 against a 0.0098 floor on a 10 s, 1.5 kHz record);
    with 3 % mains hum (50 Hz and its 2nd and 3rd at a third) the lines were measured on the
    kept rows joined (49.85-50.05 Hz, harmonics missed): each is found within 0.01 Hz.
    """
    t = np.arange(9000) / 1500.0
    w = 0.8e-3 * np.sin(2 * np.pi * 3 * t) + 0.3e-3 * np.sin(2 * np.pi * 3 * np.sqrt(2) * t)
    truth = SensorModel(PAPER_SAMPLES['slim'], effects=('surface_resistance',))
    i = daq_current(truth, t, w, noise_fraction=0.01, seed=4)
    i += hum * np.std(i) * sum(np.sin(2 * np.pi * 50 * k * t + k) / k for k in (1, 2, 3))
    kept = np.random.default_rng(3).random(t.size) > 0.01
    path, js = tmp_path / 'drop.csv', tmp_path / 'd.json'
    write_timeseries(path, TimeSeries(path='', sample='slim', geometry=PAPER_SAMPLES['slim'],
                                      known={}, sample_rate_hz=1500.0, time_s=t[kept],
                                      current_a=i[kept], deflection_m=w[kept]))
    assert main(['diagnose', str(path), '--json', str(js)]) == 0
    result = json.loads(js.read_text())
    verdict = result['verdict']
    assert verdict['missing_effects'] == [] and verdict['explained'], verdict['reason']
    found = sorted(line['frequency_hz'] for line in result['interference'])
    assert found == ([] if not hum else pytest.approx([50.0, 100.0, 150.0], abs=0.01))
