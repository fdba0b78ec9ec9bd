# SPDX-License-Identifier: Apache-2.0
"""Tests of the model-aware DeflectionEstimator (effects around the inverse filter)."""
from dataclasses import replace

import numpy as np
import pytest

from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator
from ipmc_sensor_ros.estimation.ring import SampleRing
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import PAPER_SAMPLES
from ipmc_sensor_ros.simulation.sensor import predict_current
from ipmc_sensor_ros.simulation.stimuli import CrankSlider

FS = 1000.0
SLIM = PAPER_SAMPLES['slim']


def track(model_true, model_est, f=5.0, duration=120.0, block=250, estimator='leaky'):
    """NRMSE over the last 20 s of an estimate from blocks of exact current."""
    t = np.arange(int(duration * FS)) / FS
    w = CrankSlider(f, 2e-3, 15e-3).deflection(t)
    i = predict_current(model_true, t, w)
    est = DeflectionEstimator(model_est, FS, estimator=estimator)
    outs = [est.process(t[k:k + block], i[k:k + block]) for k in range(0, t.size, block)]
    t_out = np.concatenate([o[0] for o in outs])
    y = np.concatenate([o[1] for o in outs])
    truth = CrankSlider(f, 2e-3, 15e-3).deflection(t_out)
    sel = t_out >= t_out[-1] - 20
    return float(np.sqrt(np.mean((y[sel] - truth[sel]) ** 2)) / np.sqrt(np.mean(truth[sel] ** 2)))


@pytest.mark.parametrize('effect', [
    'time_delay(delay_s=0.003)', 'current_offset(offset_a=3e-7,drift_a_per_s=1e-9)',
    'nonlinearity(quadratic=2,cubic=30)', 'amplifier_bandwidth(corner_hz=20)',
    'hydration_drift(diffusivity_rate_per_s=-0.003)',
])
def test_estimate_improves_when_the_model_gains_the_hidden_effect(effect):
    true = SensorModel.named('h2', SLIM, extra_effects=effect)
    plain = track(true, SensorModel.named('h2', SLIM))
    aware = track(true, true)
    # The aware estimator is back to the plain-data accuracy (~1 %, leak phase lead);
    # every hidden effect here costs the plain one at least twice that.
    assert aware < 0.03, (plain, aware)
    assert plain > 2 * aware, (plain, aware)


def test_delay_restamps_output_times():
    model = SensorModel.named('h2', SLIM, extra_effects='time_delay(delay_s=0.002)')
    est = DeflectionEstimator(model, FS)
    t = np.arange(100) / FS
    t_out, _ = est.process(t, np.zeros(100))
    assert np.allclose(t_out, t - 0.002)


def test_rebuilt_continues_without_jump():
    model = SensorModel.named('h2', SLIM)
    t = np.arange(int(31 * FS)) / FS
    i = predict_current(model, t, CrankSlider(2.0, 2e-3, 15e-3).deflection(t))
    n = int(30 * FS)
    est = DeflectionEstimator(model, FS)
    _, before = est.process(t[:n], i[:n])
    changed = est.rebuilt(config=est.config.replace(motion_corner_hz=2.0))
    _, after = changed.process(t[n:], i[n:])
    # one sample of a 2 Hz, 2 mm motion moves the tip by at most 25 um; the carried state
    # (deflection, velocity, acceleration, offset) keeps the switch far below that
    assert abs(after[0] - before[-1]) < 10e-6


def test_a_new_sensor_model_under_a_periodic_motion_reads_the_current_as_a_fresh_one():
    """
    A sensor model changed while a crank runs keeps its periodic model, read through it.

    The phasors were learned through the old sensor; the new one reads the same current as
    them times H_old / H_new per harmonic.  Without that (the periodic model dropped, or
    kept unscaled), a 10 % narrower sample read the level 50-80 um off a fresh estimator
    of the new model for 4 s, until the motion was measured again.
    """
    narrow = SensorModel.named('h2', replace(SLIM, width_m=0.9 * SLIM.width_m))
    t = np.arange(int(16 * FS)) / FS
    i = predict_current(SensorModel.named('h2', SLIM), t, CrankSlider(3.0, 1e-3, 15e-3)
                        .deflection(t)) + np.random.default_rng(5).normal(0, 4e-8, t.size)
    n = int(12.5 * FS)
    est = DeflectionEstimator(SensorModel.named('h2', SLIM), FS)
    est.process(t[:n], i[:n])
    assert est.core.model.motion_hz > 0             # the crank is modelled before the change
    changed = DeflectionEstimator(narrow, FS)
    changed.continue_from(est)
    _, after = changed.process(t[n:], i[n:])
    _, fresh = DeflectionEstimator(narrow, FS).process(t, i)
    # the new model's estimate of a 1 mm crank; 10 um, a tenth of the unscaled carry's
    # error (measured 2.8 um in the first period after the change, 0.1 um after it)
    assert np.max(np.abs(after - fresh[n:])) < 10e-6


def test_recent_input_is_the_last_inputs_in_order_for_any_block_sizes():
    """
    The replay history (a ring buffer) holds exactly the last history_s of input, oldest first.

    Whatever the block sizes (1 sample up to more than the buffer).
    """
    est = DeflectionEstimator(SensorModel(PAPER_SAMPLES['slim']), 1000.0, history_s=0.05)
    size = est._history.size
    rng = np.random.default_rng(3)
    x = rng.normal(0, 1e-6, 2000)
    k = 0
    for n in rng.choice([1, 3, size - 1, size, size + 7], size=60):
        n = int(min(n, x.size - k))
        if n == 0:
            break
        est.process(np.arange(k, k + n) / 1000.0, x[k:k + n])
        k += n
        expected = x[max(0, k - size):k]
        assert np.array_equal(est.recent_input, expected)


def test_sample_ring_keeps_the_last_values_however_fed():
    """Blocks and single values, a restore from (buffer, count) and a clear: the last values."""
    ring = SampleRing(7)
    fed = []
    rng = np.random.default_rng(5)
    for n in rng.choice([0, 1, 2, 7, 9, 16], size=40):
        x = rng.normal(size=int(n))
        if n == 1:
            ring.push(float(x[0]))
        else:
            ring.extend(x)
        fed.extend(x.tolist())
        assert np.array_equal(ring.values(), np.array(fed[-7:]))
    again = SampleRing(7, ring.buffer, ring.count)
    copied = ring.copy()
    ring.push(1.0)
    assert np.array_equal(again.values(), np.array(fed[-7:]))
    assert np.array_equal(copied.values(), np.array(fed[-7:]))
    ring.clear()
    assert ring.values().size == 0


def test_kalman_with_a_nonlinearity_holds_a_step_and_tracks_a_crank():
    # The mean of T(w) - w is restored by a running average.  For the Kalman it follows the
    # corner in use while moving and is frozen at rest.  At the floor corner for all samples,
    # a held 2 mm step (a_2 = 2, a_3 = 30: T(w) - w = 0.36 mm) crept by 34 um in 16 s towards
    # 2.36 mm, and a crank from t = 0 was 6.6 % off (the centring is immediate; the average
    # took 160 s).  Measured now: the step constant to 1e-9 m, 0.4 % low (the 0.2 s move);
    # the crank 0.34 % (leaky 1.1 %).  Bounds: 1 um of creep, 1 % level, 3 % crank.
    from ipmc_sensor_ros.simulation.daq import daq_current
    effect = 'nonlinearity(quadratic=2,cubic=30)'
    true = SensorModel.named('h2', SLIM, extra_effects=effect)
    t = np.arange(int(20 * FS)) / FS
    w = np.convolve(np.where(t > 3, 2e-3, 0.0), np.ones(200) / 200, 'same')
    w[-200:] = 2e-3
    i = daq_current(true, t, w, noise_a=1e-12, seed=0)
    est = DeflectionEstimator(true, FS, estimator='kalman')
    y = np.concatenate([est.process(t[k:k + 500], i[k:k + 500])[1]
                        for k in range(0, t.size, 500)])
    assert abs(y[int(19 * FS)] - y[int(5 * FS)]) < 1e-6
    assert abs(y[int(19 * FS)] - 2e-3) < 0.01 * 2e-3
    true_est = SensorModel.named('h2', SLIM, extra_effects=effect)
    plain = track(true, SensorModel.named('h2', SLIM), estimator='kalman')
    aware = track(true, true_est, estimator='kalman')
    assert aware < 0.03, (plain, aware)
    assert plain > 2 * aware, (plain, aware)
