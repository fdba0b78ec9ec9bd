# SPDX-License-Identifier: Apache-2.0
"""Tests of the discrete inverse estimator (current -> deflection)."""
import numpy as np
import pytest

from ipmc_sensor_ros.estimation.inverse import (
    DEFAULT_LEAK_CORNER_HZ,
    ParameterError,
    InverseEstimator,
    leak_tradeoff,
)
from ipmc_sensor_ros.errors import DataError
from ipmc_sensor_ros.estimation.stream import validate_block
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import PAPER_SAMPLES
from ipmc_sensor_ros.lti.reduction import reduce_model
from ipmc_sensor_ros.simulation.sensor import SensorSimulator, periodic_response
from ipmc_sensor_ros.workbench.metrics import nrmse
from ipmc_sensor_ros.simulation.stimuli import CrankSlider, FreeVibration, Step

SLIM = SensorModel(PAPER_SAMPLES['slim'])
BIG = SensorModel(PAPER_SAMPLES['big'])
FS = 1000.0


@pytest.fixture(scope='module')
def reduced_slim():
    return reduce_model(SLIM, 4)


@pytest.mark.parametrize('fs', [200.0, 1000.0, 10000.0])
def test_discrete_matches_continuous_up_to_fs_over_10(reduced_slim, fs):
    est = InverseEstimator(reduced_slim, fs)
    f = np.logspace(-1, np.log10(fs / 10), 80)
    ratio = est.frequency_response(f) / est.continuous_frequency_response(f)
    assert np.max(np.abs(20 * np.log10(np.abs(ratio)))) < 0.5
    assert np.max(np.abs(np.degrees(np.angle(ratio)))) < 2.0


def test_all_poles_strictly_inside_unit_circle(reduced_slim):
    est = InverseEstimator(reduced_slim, FS, offset_corner_hz=0.002)
    assert np.all(np.abs(est.poles()) < 1.0)


@pytest.mark.parametrize('kw,name', [
    (dict(leak_corner_hz=0.0), 'leak_corner_hz'), (dict(leak_corner_hz=-1.0), 'leak_corner_hz'),
    (dict(sample_rate_hz=float('nan')), 'sample_rate_hz'), (dict(prewarp_hz=600.0), 'prewarp_hz'),
    (dict(leak_corner_hz=600.0), 'leak_corner_hz'), (dict(channels=0), 'channels'),
])
def test_invalid_configuration_is_refused(reduced_slim, kw, name):
    args = dict(sample_rate_hz=FS)
    args.update(kw)
    with pytest.raises(ParameterError, match=name):
        InverseEstimator(reduced_slim, **args)


@pytest.mark.parametrize('drive_hz', [1.0, 5.0, 20.0])
def test_crank_slider_tracking_from_exact_h2(reduced_slim, drive_hz):
    # Current from the exact H2 steady-state periodic response (frequency domain), 2 mm
    # crank radius; the record is repeated so that the leak transient (tau = 16 s) is gone.
    t = np.arange(int(20 * FS)) / FS
    w = CrankSlider(drive_hz, 2e-3, 20e-3).deflection(t)
    i = periodic_response(SLIM, w, FS)
    est = InverseEstimator(reduced_slim, FS)
    for _ in range(6):  # 120 s: transient decays to exp(-100/16) ~ 0.2 % of its start
        y = est.process(i)
    assert nrmse(y, w) < 0.05


def test_step_held_3s_stays_within_documented_leak_tradeoff():
    red = reduce_model(BIG, 4)
    est = InverseEstimator(red, FS)
    sim = SensorSimulator(BIG, FS)
    stim = Step(2e-3, start_s=0.5, rise_time_s=0.02)
    t = np.arange(int(3.52 * FS)) / FS
    w, i = sim.run(stim, t)
    y = est.process(i)
    held = t >= 0.52
    rel_err_end = abs(y[-1] - w[-1]) / 2e-3
    predicted = leak_tradeoff(red, DEFAULT_LEAK_CORNER_HZ, 3.0, 0.0)['held_step_relative_error']
    # The leak predicts exp(-w_c t) decay; the end error must match it within 2 % of the
    # step (sensor dynamics add a few ms of lag and a small static gain error).
    assert rel_err_end == pytest.approx(predicted, abs=0.02)
    assert np.all(np.abs(y[held] - w[held]) <= (predicted + 0.02) * 2e-3)


def test_damped_free_vibration_30hz(reduced_slim):
    sim = SensorSimulator(SLIM, FS)
    est = InverseEstimator(reduced_slim, FS)
    t = np.arange(int(2.0 * FS)) / FS
    w, i = sim.run(FreeVibration(2e-3, 30.0, 0.05, release_s=0.5, ramp_s=0.3), t)
    y = est.process(i)
    assert nrmse(y, w) < 0.05


def test_offset_ramps_without_leak_tradeoff_and_is_bounded(reduced_slim):
    offset = 1e-7  # A
    est = InverseEstimator(reduced_slim, 100.0)
    y = est.process(np.full(int(200 * 100), offset))
    bound = leak_tradeoff(reduced_slim, DEFAULT_LEAK_CORNER_HZ, 1.0, offset)[
        'offset_steady_error_m'
    ]
    assert y[-1] == pytest.approx(bound, rel=0.02)   # 200 s = 12.5 leak time constants
    est2 = InverseEstimator(reduced_slim, 100.0, offset_corner_hz=0.002)
    y2 = est2.process(np.full(int(2000 * 100), offset))
    peak = leak_tradeoff(reduced_slim, DEFAULT_LEAK_CORNER_HZ, 1.0, offset, 0.002)[
        'offset_peak_error_m'
    ]
    assert np.max(np.abs(y2)) <= peak * 1.02 and abs(y2[-1]) < 0.01 * peak


def test_blocks_and_single_samples_identical_and_state_restore(reduced_slim):
    rng = np.random.default_rng(1)
    x = rng.normal(0, 1e-6, 500)
    a = InverseEstimator(reduced_slim, FS)
    ya = a.process(x)
    b = InverseEstimator(reduced_slim, FS)
    yb = np.array([b.process_sample(v) for v in x])
    assert np.array_equal(ya, yb)
    c = InverseEstimator(reduced_slim, FS)
    c.process(x[:200])
    state = c.get_state()
    tail = c.process(x[200:])
    c.set_state(state)
    assert np.array_equal(c.process(x[200:]), tail)
    assert np.array_equal(tail, ya[200:])
    c.reset()
    assert np.array_equal(c.process(x), ya)


@pytest.mark.parametrize('offset_corner_hz', [None, 0.05])
def test_small_block_path_equals_sosfilt_bit_for_bit(reduced_slim, offset_corner_hz):
    """
    Blocks up to SMALL_BLOCK_SAMPLES run a plain-Python recursion equal to sosfilt.

    The recursion is the one-sample fast path of the node; it must give exactly sosfilt's
    numbers, whatever the mix of block sizes around the threshold.
    """
    from ipmc_sensor_ros.estimation.inverse import SMALL_BLOCK_SAMPLES
    rng = np.random.default_rng(7)
    x = rng.normal(0, 1e-6, 3000)
    whole = InverseEstimator(reduced_slim, FS, offset_corner_hz=offset_corner_hz)
    y_whole = whole.process(x)
    mixed = InverseEstimator(reduced_slim, FS, offset_corner_hz=offset_corner_hz)
    sizes = rng.choice([1, 2, SMALL_BLOCK_SAMPLES, SMALL_BLOCK_SAMPLES + 1, 100], size=200)
    bounds = np.minimum(np.concatenate([[0], np.cumsum(sizes)]), x.size)
    y_mixed = np.concatenate([mixed.process(x[a:b]) for a, b in zip(bounds[:-1], bounds[1:])]
                             + [mixed.process(x[bounds[-1]:])])
    assert np.array_equal(y_whole, y_mixed)
    assert np.array_equal(whole.get_state()['zi'], mixed.get_state()['zi'])


def test_multichannel_equals_independent_channels(reduced_slim):
    rng = np.random.default_rng(2)
    x = rng.normal(0, 1e-6, (300, 3))
    multi = InverseEstimator(reduced_slim, FS, channels=3).process(x)
    for ch in range(3):
        single = InverseEstimator(reduced_slim, FS).process(x[:, ch])
        assert np.allclose(multi[:, ch], single, rtol=0, atol=1e-18)


def test_rebuild_continues_without_jump(reduced_slim):
    t = np.arange(int(30 * FS)) / FS
    w = CrankSlider(2.0, 2e-3, 20e-3).deflection(t)
    i = periodic_response(SLIM, w, FS)
    est = InverseEstimator(reduced_slim, FS)
    y = est.process(i)
    new = est.rebuilt(leak_corner_hz=0.02)
    y_next = new.process(i[:1])[0]
    # One sample at 2 Hz, 2 mm moves the tip by at most 2*pi*2*2e-3/1000 = 25 um; allow 50 um.
    assert abs(y_next - y[-1]) < 50e-6


@pytest.mark.parametrize('bad,msg', [
    ([], 'empty'), ([1e-6, float('nan')], 'non-finite'), ([float('inf')], 'non-finite'),
    ([[1.0]], '1-D'), ([5.0], r'\|i\|'), (['x'], 'numeric'),
])
def test_validate_block_rejects_bad_input(bad, msg):
    with pytest.raises(DataError, match=msg):
        validate_block(bad)


def test_validate_block_rejects_oversized():
    with pytest.raises(DataError, match='limit'):
        validate_block(np.zeros(11), max_samples=10)
