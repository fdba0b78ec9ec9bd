# SPDX-License-Identifier: Apache-2.0
"""Tests of the offset-aware Kalman estimator, the mains notch and the DAQ scenarios."""
import numpy as np
import pytest

from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator
from ipmc_sensor_ros.errors import ParameterError
from ipmc_sensor_ros.estimation.inverse import InverseEstimator
from ipmc_sensor_ros.estimation.kalman import KalmanEstimator, offset_corner_hz
from ipmc_sensor_ros.estimation.mains import LINE_WARN_RATIO, MainsFilter, line_level
from ipmc_sensor_ros.lti.reduction import reduce_model
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import PAPER_SAMPLES
from ipmc_sensor_ros.simulation.daq import daq_current, robot_motion, started
from ipmc_sensor_ros.simulation.stimuli import CrankSlider, Step
from conftest import assert_agree_and_restore, blocks_and_samples

FS = 1000.0
SLIM = SensorModel(PAPER_SAMPLES['slim'])
BIG = SensorModel(PAPER_SAMPLES['big'])


@pytest.fixture(scope='module')
def reduced_slim():
    return reduce_model(SLIM, 4)


def nrmse(est, truth):
    return float(np.sqrt(np.mean((est - truth) ** 2)) / np.sqrt(np.mean(truth ** 2)))


def in_blocks(est, t, i, n=1000):
    """Return a DeflectionEstimator's estimates of current i (A) at times t, n per call."""
    return np.concatenate([est.process(t[k:k + n], i[k:k + n])[1] for k in range(0, t.size, n)])


def blocks(est, i, n=1000):
    return np.concatenate([est.process(i[k:k + n]) for k in range(0, i.size, n)])


def test_observability_corner_is_far_below_the_motion_band(reduced_slim):
    # f_c = sqrt(q_b a / (2 R0^2 sigma_v^2)) / 2 pi: with 1 nA/min drift and 20 mm/s motion the
    # offset cannot be told from a deflection creeping slower than ~1e-5 Hz (docstring).
    f_c = offset_corner_hz(reduced_slim)
    assert 1e-7 < f_c < 1e-3
    # it scales as the square root of the drift intensity (q_b ~ drift^2 -> f_c ~ drift)
    assert offset_corner_hz(reduced_slim, offset_drift_a_per_s=4e-11) == pytest.approx(
        f_c * 4e-11 / (1e-9 / 60), rel=1e-9)


def test_offset_is_learned_at_rest_and_deflection_held(reduced_slim):
    # At rest with a 10 nA offset and 20 nA noise: after 3 s the offset estimate is a mean of
    # ~2500 samples (std 20/sqrt(2500) = 0.4 nA): within 2 nA (5 sigma).
    rng = np.random.default_rng(3)
    est = KalmanEstimator(reduced_slim, FS)
    est.process(10e-9 + 20e-9 * rng.standard_normal(3000))
    assert est.at_rest
    assert est.offset_a == pytest.approx(10e-9, abs=2e-9)
    w_before = est.process(10e-9 + 20e-9 * rng.standard_normal(10))[-1]
    # a further 5 s of rest does not move the deflection (held: frozen, no leak)
    w_after = est.process(10e-9 + 20e-9 * rng.standard_normal(5000))[-1]
    assert abs(w_after - w_before) < 1e-9


def test_blocks_single_samples_and_process_one_agree(reduced_slim):
    t = np.arange(int(6 * FS)) / FS
    w = started(t, CrankSlider(3.0, 2e-3, 20e-3).deflection(t), rest_s=1.5) * (t < 4.5)
    i = daq_current(SLIM, t, w, offset_a=8e-9, noise_a=20e-9, seed=4)
    (a, b, c), (wa, wb, wc) = blocks_and_samples(lambda: KalmanEstimator(reduced_slim, FS), i)
    # blocks of any size: the same recursion (state exact between modes, the rest offset's
    # weight a count, the noise measured at each sample) up to rounding: 1e-12 m
    assert np.max(np.abs(wa - wb)) < 1e-12
    assert np.max(np.abs(wa - wc)) < 1e-12
    assert a.at_rest == b.at_rest == c.at_rest


def test_state_save_restore_and_bumpless_continue(reduced_slim):
    rng = np.random.default_rng(5)
    t = np.arange(3000) / FS
    w = started(t, CrankSlider(2.0, 2e-3, 20e-3).deflection(t), rest_s=1.0)
    i = daq_current(SLIM, t, w, offset_a=5e-9, noise_a=20e-9, seed=5)
    est = KalmanEstimator(reduced_slim, FS)
    est.process(i[:2000])
    saved = est.get_state()
    tail = est.process(i[2000:])
    est.set_state(saved)
    assert np.array_equal(est.process(i[2000:]), tail)
    with pytest.raises(ParameterError, match='state'):
        est.set_state({'s': np.zeros(3)})
    old = KalmanEstimator(reduced_slim, FS)
    old.process(i[:2000])
    new = old.rebuilt(reduce_model(SLIM, 3), recent_input=i[1500:2000])
    assert new.current_output()[0] == pytest.approx(old.current_output()[0], abs=1e-12)
    assert new.offset_a == old.offset_a
    del rng


@pytest.mark.parametrize('kw,name', [(dict(current_noise_a=0.0), 'current_noise_a'),
                                     (dict(motion_bandwidth_hz=600.0), 'motion_bandwidth_hz'),
                                     (dict(rest_enter=5.0, rest_leave=4.0), 'rest_leave'),
                                     (dict(channels=2), 'channels')])
def test_invalid_configuration_is_refused(reduced_slim, kw, name):
    with pytest.raises(ParameterError, match=name):
        KalmanEstimator(reduced_slim, FS, **kw)


@pytest.mark.parametrize('sample', ['slim', 'short'])
@pytest.mark.parametrize('f', [1.0, 5.0, 20.0])
def test_crank_with_offset_after_rest(sample, f):
    # Issue-14 row 1 (crank, 1 % noise + 10 nA offset), starting from 2 s of rest (the offset is
    # learned there).  Kalman defaults, not the scenario's noise.  The target, 3 %, is
    # asserted: measured 1.1-2.4 % on this seed, worst 2.9 % over the bench's seeds 0-2 and 91
    # (the rest holds the level from its start and whole periods refine the offset).
    model = SensorModel(PAPER_SAMPLES[sample])
    t = np.arange(int(20 * FS)) / FS
    w = started(t, CrankSlider(f, 2e-3, 20e-3, phase_rad=0.7).deflection(t))
    i = daq_current(model, t, w, offset_a=10e-9, noise_fraction=0.01, seed=21)
    est = DeflectionEstimator(model, FS, estimator='kalman')
    w_hat = in_blocks(est, t, i)
    leaky = DeflectionEstimator(model, FS, estimator='leaky')
    w_leaky = in_blocks(leaky, t, i)
    sel = t >= 5
    assert nrmse(w_hat[sel], w[sel]) < 0.03
    assert nrmse(w_hat[sel], w[sel]) < nrmse(w_leaky[sel], w[sel])
    assert np.all(np.isfinite(est.last_std_m)) and est.last_std_m[0] > 0


def test_step_held_with_offset_big():
    # Issue-14 row 2: 2 mm step held 10 s, 10 nA offset, 1 % noise (big).  The leaky estimator
    # loses 1 - exp(-w_c t) of the step (47 % after 10 s); the Kalman estimator holds it at rest.
    t = np.arange(int(15 * FS)) / FS
    w = Step(2e-3, start_s=2.3, rise_time_s=0.05).deflection(t)
    i = daq_current(BIG, t, w, offset_a=10e-9, noise_fraction=0.01, seed=22)
    est = DeflectionEstimator(BIG, FS, estimator='kalman')
    w_hat = in_blocks(est, t, i)
    sel = t >= 5
    # target 3 %; the rest holds the leak-free level of the move (measured 0.02 %); 1 % leaves
    # room for the leak-free integral's noise walk over the 50 ms rise (a few um of 2 mm)
    assert nrmse(w_hat[sel], w[sel]) < 0.01
    assert est.inverse.at_rest


def test_mains_notch_removes_hum_and_detects_it():
    t = np.arange(int(4 * FS)) / FS
    signal = 1e-6 * np.sin(2 * np.pi * 2.0 * t)
    hum = 0.05e-6 * np.sin(2 * np.pi * 50 * t) + 0.02e-6 * np.sin(2 * np.pi * 150 * t + 1)
    mf = MainsFilter(50, FS)
    out = np.concatenate([mf.process((signal + hum)[k:k + 500]) for k in range(0, t.size, 500)])
    assert mf.line_present
    # after the notch settles (Q = 30: ~0.2 s), the hum is below 5 % of its level; the 2 Hz
    # signal passes within 1 % (notch width 1.7 Hz at 50 Hz)
    sel = t > 1.0
    assert (
        np.sqrt(np.mean((out[sel] - signal[sel]) ** 2))
        < 0.05 * np.sqrt(np.mean(hum[sel] ** 2)) + 0.01e-6
    )
    clean = MainsFilter(50, FS)
    clean.process(signal)
    assert not clean.line_present
    assert line_level(signal + hum, FS, 50) > LINE_WARN_RATIO > line_level(signal, FS, 50)
    with pytest.raises(ParameterError, match='mains_hz'):
        MainsFilter(55, FS)


def test_deflection_estimator_options():
    with pytest.raises(ParameterError, match='estimator'):
        DeflectionEstimator(SLIM, FS, estimator='magic')
    with pytest.raises(ParameterError, match='offset_corner_hz'):
        DeflectionEstimator(SLIM, FS, estimator='kalman', offset_corner_hz=0.01)
    est = DeflectionEstimator(SLIM, FS, estimator='leaky')
    t = np.arange(100) / FS
    _, w, std = est.process_with_std(t, np.zeros(100))
    assert np.all(np.isnan(std))          # the leaky inverse has no uncertainty model
    assert isinstance(est.inverse, InverseEstimator)
    # the Kalman path: std from the covariance (positive, finite), bumpless rebuild
    kal = DeflectionEstimator(SLIM, FS, estimator='kalman', mains_hz=60)
    i = daq_current(SLIM, t, 1e-3 * np.sin(2 * np.pi * 5 * t), noise_a=20e-9, seed=1)
    _, w, std = kal.process_with_std(t, i)
    assert np.all(np.isfinite(std)) and np.all(std > 0)
    new = kal.rebuilt(leak_corner_hz=0.001)
    assert new.inverse.leak_corner_hz == 0.001 and new.mains_hz == 60 and new.estimator == 'kalman'
    assert new.inverse.current_output()[0] == pytest.approx(
        kal.inverse.current_output()[0], abs=1e-12
    )


def test_robot_motion_with_hum_beats_leaky():
    # Issue-14 row 3 (shortened to 30 s): robot-like motion with holds, 10 nA offset,
    # 1 % noise + 3 % 50 Hz hum, mains_hz 50.  The target, 5 %, is asserted (measured 0.9 %).
    t = np.arange(int(30 * FS)) / FS
    w = robot_motion(t, seed=31)
    i = daq_current(
        SLIM, t, w, offset_a=10e-9, noise_fraction=0.01, mains_hz=50, hum_fraction=0.03, seed=31
    )
    est = DeflectionEstimator(SLIM, FS, estimator='kalman', mains_hz=50)
    w_hat = in_blocks(est, t, i)
    leaky = DeflectionEstimator(SLIM, FS, estimator='leaky')
    w_l = in_blocks(leaky, t, i)
    sel = t >= 5
    assert est.mains.line_present is False or est.mains.line_ratio > 0
    assert nrmse(w_hat[sel], w[sel]) < 0.05
    assert nrmse(w_hat[sel], w[sel]) < 0.5 * nrmse(w_l[sel], w[sel])


def test_drifting_offset_with_intermittent_motion_stays_bounded():
    # Issue-14 row 5, shortened to 10 min at 500 Hz (bench runs the full hour): offset 10 nA
    # drifting 1 nA/min, 1 % noise, a 10 s robot-like burst every minute.  Target: |error|
    # <= 0.2 mm at all times.  Between bursts the offset is re-learned at rest (past 10 s a
    # level-and-trend average: no lag behind the drift); each burst starts from a held level
    # and loses < 0.6 %/s of its excursion to the leak (0.001 Hz on such short moves) plus
    # ~1 % reduction error.
    fs = 500.0
    t = np.arange(int(600 * fs)) / fs
    from ipmc_sensor_ros.simulation.daq import intermittent_motion
    w = intermittent_motion(t, seed=41)
    i = daq_current(SLIM, t, w, offset_a=10e-9, drift_a_per_min=1e-9, noise_fraction=0.01, seed=41)
    est = DeflectionEstimator(SLIM, fs, estimator='kalman')
    w_hat = np.concatenate(
        [est.process(t[k:k + 5000], i[k:k + 5000])[1] for k in range(0, t.size, 5000)]
    )
    assert np.max(np.abs(w_hat - w)[t > 5]) < 0.2e-3
    assert est.inverse.offset_a == pytest.approx(20e-9, abs=2e-9)   # 10 nA + 10 min * 1 nA/min


def test_leaving_rest_keeps_motion_current_out_of_the_offset():
    # Clean current (exact H2, no offset, no noise): the rest detector notices a gentle start
    # (started(): amplitude ramps in) only after its averaging window.  Leaving rest re-runs
    # the last 2 windows in the moving mode from the offset learned before them, so the
    # offset stays at 0: without the rewind it took 0.26 nA of motion current (a ramp of
    # 0.8 um/s on slim).  Bound 0.1 nA.  (The error's mean is no ramp test any more: the
    # adaptive leak raises its corner during the motion, each rise a leak transient of
    # about (f / 5 Hz) * 2 mm.)
    t = np.arange(int(15 * FS)) / FS
    w = started(t, CrankSlider(5.0, 2e-3, 20e-3).deflection(t))
    i = daq_current(SLIM, t, w)
    est = DeflectionEstimator(SLIM, FS, estimator='kalman')
    w_hat = in_blocks(est, t, i)
    assert abs(est.inverse.offset_a) < 0.1e-9
    assert nrmse(w_hat[t >= 5], w[t >= 5]) < 0.015     # leaky: 0.7 %, reduction error ~1 %


@pytest.mark.parametrize('sample', ['slim', 'short'])
def test_moving_from_start_offset_error_below_leaky(sample):
    # Crank 5 Hz moving from t=0 (no rest), 1 % noise + 10 nA.  Without the offset from whole
    # periods the 0.02 Hz start leak halves the leaky's offset error (ratio 0.65); with it the
    # offset is learned within seconds (test_periodic_offset.py: the 3 % target).  Bound 0.8
    # keeps this comparison meaningful for any motion where periods are refused.
    model = SensorModel(PAPER_SAMPLES[sample])
    t = np.arange(int(20 * FS)) / FS
    w = CrankSlider(5.0, 2e-3, 20e-3, phase_rad=1.1).deflection(t) * np.clip(t / 0.5, 0, 1)
    i = daq_current(model, t, w, offset_a=10e-9, noise_fraction=0.01, seed=23)
    out = {}
    for name in ('leaky', 'kalman'):
        est = DeflectionEstimator(model, FS, estimator=name)
        out[name] = in_blocks(est, t, i)
    sel = t >= 5
    assert nrmse(out['kalman'][sel], w[sel]) < 0.8 * nrmse(out['leaky'][sel], w[sel])


def _crank_after_rest(model, f, seed, noise=0.01, seconds=20.0, amplitude=2e-3):
    t = np.arange(int(seconds * FS)) / FS
    w = started(t, CrankSlider(f, amplitude, 20e-3, phase_rad=0.3).deflection(t))
    i = daq_current(model, t, w, offset_a=10e-9, noise_fraction=noise, seed=seed)
    return t, w, i


def test_leak_corner_rises_with_noisy_fast_motion_and_bounds_the_error():
    # Issue-14 crank row at 20 Hz (slim, 1 % noise = ~0.6 uA per sample, 10 nA offset, 2 s rest
    # first).  The rest learns the offset only to sigma / sqrt(~1700) = 15 nA, so the old fixed
    # slow leak let noise and offset error wander (14-28 %).  The schedule must raise the
    # corner (predicted optimum ~0.02 f_m = 0.4 Hz; the noise meter's clip at 20 x 20 nA
    # under-reads sigma, so >= 0.1 Hz) and the error must stay near what leak_error_terms
    # predicts for that corner: sqrt(J) / rms(w) ~ 3 % with the true sigma; bound 4 %.
    from ipmc_sensor_ros.estimation.leak_schedule import leak_error_terms
    t, w, i = _crank_after_rest(SLIM, 20.0, seed=51)
    est = DeflectionEstimator(SLIM, FS, estimator='kalman')
    w_hat = in_blocks(est, t, i)
    kal = est.inverse
    assert kal.leak_corner_in_use_hz >= 0.1
    assert kal.leak_corner_in_use_hz <= 0.05 * 20.0 + 1e-12      # ceiling 0.05 f_eff
    sel = t >= 5
    err = nrmse(w_hat[sel], w[sel])
    s = float(np.mean(w[sel] ** 2))
    true_sigma = 0.01 * float(np.sqrt(np.mean((i - 10e-9) ** 2)))
    terms = leak_error_terms([kal.leak_corner_in_use_hz], 0.0, s, (2 * np.pi * 20.0) ** 2 * s,
                             true_sigma ** 2, true_sigma ** 2 / 1700, 15.0, kal._r0, FS)
    predicted = float(np.sqrt(sum(x[0] for x in terms) / s))
    assert 0.01 < predicted < 0.04
    assert err < 0.04
    assert err < 1.5 * predicted


def test_leak_corner_stays_low_on_slow_motion_after_rest():
    # A 0.2 Hz, 2 mm sine after 2 s of rest (slim, 1 % noise + 10 nA).  Its 1 % noise is
    # 0.2 x that of a 1 Hz crank and the offset is learned to < 1 nA (trusted): the leak
    # term (f / 0.2 Hz)^2 dominates, so the corner stays within the slowest rungs
    # (<= 0.004 Hz, a 2 % leak error), and the estimate is as good as at the fixed 0.001 Hz.
    t = np.arange(int(30 * FS)) / FS
    w = started(t, 2e-3 * np.sin(2 * np.pi * 0.2 * t))
    i = daq_current(SLIM, t, w, offset_a=10e-9, noise_fraction=0.01, seed=52)
    est = DeflectionEstimator(SLIM, FS, estimator='kalman')
    corners = []
    out = []
    for k in range(0, t.size, 1000):
        out.append(est.process(t[k:k + 1000], i[k:k + 1000])[1])
        corners.append(est.inverse.leak_corner_in_use_hz)
    assert max(corners[3:]) <= 0.004 + 1e-12
    sel = t >= 5
    assert nrmse(np.concatenate(out)[sel], w[sel]) < 0.03


def test_adaptive_corner_blocks_and_single_samples_agree(reduced_slim):
    # A noisy 20 Hz crank after rest makes the schedule switch corners; the switches fall on
    # the same sample grid whatever the block size, and every input to the decision (the rest
    # offset's weight as a count, the noise measured at each sample) is the same for blocks
    # and single samples: equal up to rounding (1e-12 m), the same final corner.
    t, w, i = _crank_after_rest(SLIM, 20.0, seed=53, seconds=10.0)
    ests, outputs = blocks_and_samples(lambda: KalmanEstimator(reduced_slim, FS), i)
    assert ests[0].leak_corner_in_use_hz > 0.02
    assert len({e.leak_corner_in_use_hz for e in ests}) == 1
    # the state (with the schedule's statistics) saves and restores exactly
    assert_agree_and_restore(ests, outputs, i[:500])


def test_noise_term_of_the_leak_schedule_matches_the_filter(reduced_slim):
    # leak_error_terms' noise term: white current noise sigma is a white velocity of two-sided
    # PSD sigma^2 / (fs R0^2) integrated by 1 / (s + 2 pi f): variance
    # sigma^2 / (fs R0^2) / (4 pi f) once t >> 1 / (2 pi f).  Checked on the moving-mode filter
    # itself at f = 0.064 Hz (tau = 2.5 s) over 360 s of pure noise: the sample variance of an
    # Ornstein-Uhlenbeck path over 144 tau is uncertain by sqrt(1 / 144) = 8 %, and the filter's
    # own high-frequency posterior noise (not in the term) adds ~5 %: bounds 0.8 - 1.35.
    from ipmc_sensor_ros.estimation.leak_schedule import leak_error_terms
    est = KalmanEstimator(reduced_slim, FS, rest_detection=False)
    k = int(np.argmin(np.abs(est._sched.corners_hz - 0.064)))
    f = float(est._sched.corners_hz[k])
    sigma = 200e-9
    y = sigma * np.random.default_rng(61).standard_normal(400000)
    w, _, _ = est._ladder_mode(k).run(y, np.zeros(est._n))
    predicted = leak_error_terms([f], 0.0, 1.0, 1.0, sigma ** 2, 0.0, 1e9, est._r0, FS)[1][0]
    assert 0.8 < np.var(w[40000:]) / predicted < 1.35


def test_rest_offset_follows_a_drift_without_lag(reduced_slim):
    # 60 s at rest, offset 10 nA drifting 10 nA/min, 20 nA noise.  Past rest_offset_time_s
    # (10 s) the offset is a level-and-trend average: no lag behind a linear drift, where an
    # exponential average over 10 s trails it by 10 s * 10 nA/min = 1.7 nA.  The level's noise
    # is ~2.5 x the EMA's variance: 0.2 nA RMS; bound 0.7 nA (3.5 sigma), well below 1.7 nA.
    t = np.arange(int(60 * FS)) / FS
    y = 10e-9 + 10e-9 * t / 60 + 20e-9 * np.random.default_rng(62).standard_normal(t.size)
    est = KalmanEstimator(reduced_slim, FS)
    blocks(est, y)
    assert est.at_rest
    assert abs(est.offset_a - (10e-9 + 10e-9 * t[-1] / 60)) < 0.7e-9


@pytest.mark.parametrize('sample,fs', [('slim', 1000.0), ('big', 1000.0), ('slim', 10000.0)])
def test_moving_predictor_inverts_the_reduced_model_at_unit_gain(sample, fs):
    # The optimal gain with a random-walk offset scaled every motion by 0.992 (flat over
    # 0.2-50 Hz); K_w is now solved for unit gain at 5 Hz.  Over 1-50 Hz the response of
    # the floor corner's predictor times H(j w) is measured within 6e-4 of 1 (the leak's
    # phase lead f_c / f is 1e-3 at 1 Hz); bound 2e-3.  Every corner shares the gain, so a
    # switch of corner cannot step w (see test_clean_crank_from_rest_beats_the_leaky).
    red = reduce_model(SensorModel(PAPER_SAMPLES[sample]), 4)
    kal = KalmanEstimator(red, fs)
    mode = kal._ladder_mode(kal._sched.floor_index)
    n, iw = mode.f.shape[0], kal._iw
    ikc = np.eye(n) - np.outer(mode.k, kal._c)
    for f in (1.0, 2.0, 5.0, 10.0, 20.0, 50.0):
        z = np.exp(2j * np.pi * f / fs)
        resp = ikc[iw] @ np.linalg.solve(z * np.eye(n) - mode.f, mode.gvec) + mode.k[iw]
        assert abs(resp * red.frequency_response(f) - 1.0) < 2e-3, f
    for index in range(len(kal._sched.corners_hz)):
        np.testing.assert_array_equal(kal._ladder_mode(index).k, mode.k)


@pytest.mark.parametrize('f', [1.0, 5.0, 20.0])
def test_clean_crank_from_rest_beats_the_leaky(f):
    # Issue-14 row "clean crank-slider as today": clean current from exact H2, 2 s of rest,
    # then a 2 mm crank.  Measured 0.16 / 0.24 / 0.19 % (leaky 1.3 / 0.7 / 0.2 %).  Before
    # this, the Kalman was worse at 5 and 20 Hz (0.9 / 0.6 %): a fade-in taken for an offset
    # (test_periodic_offset), a corner switch stepping w by 15 um, and a 0.8 % gain loss.
    # Bounds: no worse than the leaky, and 0.5 %.
    t = np.arange(int(30 * FS)) / FS
    w = started(t, CrankSlider(f, 2e-3, 20e-3).deflection(t))
    i = daq_current(SLIM, t, w)
    kal = DeflectionEstimator(SLIM, FS, estimator='kalman')
    w_hat = in_blocks(kal, t, i)
    leaky = DeflectionEstimator(SLIM, FS, estimator='leaky')
    w_leaky = in_blocks(leaky, t, i)
    sel = t >= 5
    assert nrmse(w_hat[sel], w[sel]) <= nrmse(w_leaky[sel], w[sel])
    assert nrmse(w_hat[sel], w[sel]) < 0.005
    if f == 5.0:
        # the corner rose during the run (0.001 -> 0.016 Hz at 16 s), and no one-period
        # mean of the error left 3 um (0.4 um measured; the step was 15 um)
        assert kal.inverse.leak_corner_in_use_hz > kal.inverse.leak_corner_hz
        per = int(FS / f)
        err = (w_hat - w)[5000:5000 + (t.size - 5000) // per * per].reshape(-1, per)
        assert np.max(np.abs(err.mean(axis=1))) < 3e-6


def test_kalman_with_an_amplifier_pole_in_the_model():
    # amplifier_bandwidth adds a pole: R_n(s) is then strictly proper (4 zeros, 5 poles).
    # ReducedModel.charge_response broadcast zeros against poles and failed, and the modal
    # realisation gave R_n a feedthrough it no longer has.  Now the model-aware Kalman is
    # back to clean-data accuracy (measured 0.12 % over the last 20 s of a clean 5 Hz crank;
    # bound 1 %) and the plain model, which misses the 20 Hz pole, is far worse (24 %).
    from ipmc_sensor_ros.simulation.sensor import predict_current
    true = SensorModel.named('h2', PAPER_SAMPLES['slim'],
                             extra_effects='amplifier_bandwidth(corner_hz=20)')
    t = np.arange(int(40 * FS)) / FS
    w = CrankSlider(5.0, 2e-3, 15e-3).deflection(t)
    i = predict_current(true, t, w)
    sel = t >= 20
    err = {}
    plain = SensorModel.named('h2', PAPER_SAMPLES['slim'])
    for name, model in (('aware', true), ('plain', plain)):
        est = DeflectionEstimator(model, FS, estimator='kalman')
        w_hat = np.concatenate(
            [est.process(t[k:k + 250], i[k:k + 250])[1] for k in range(0, t.size, 250)])
        err[name] = nrmse(w_hat[sel], w[sel])
    assert err['aware'] < 0.01
    assert err['plain'] > 5 * err['aware']


def test_the_sample_where_the_level_was_learned_is_the_same_in_blocks_and_samples():
    # level_known_n: the first rest (2 s rest first: the detector's ~0.2 s window) or the first
    # offset from whole periods (moving from t = 0: the first 1 s grid point with >= 2 periods
    # behind it); `ipmc-model estimate` compares the Kalman from there.
    t = np.arange(8000) / FS
    crank = CrankSlider(5.0, 2e-3, 20e-3).deflection(t)
    for w, lo, hi in ((started(t, crank), 100, 500), (crank, 1000, 1000)):
        i = daq_current(SLIM, t, w, offset_a=10e-9, noise_fraction=0.01, seed=1)
        a = DeflectionEstimator(SLIM, FS, estimator='kalman')
        b = DeflectionEstimator(SLIM, FS, estimator='kalman')
        for k in range(0, t.size, 37):
            a.process(t[k:k + 37], i[k:k + 37])
        for k in range(t.size):
            b.process_one(t[k], i[k])
        assert a.inverse.level_known_n == b.inverse.level_known_n
        assert lo <= a.inverse.level_known_n <= hi
        assert a.settling()[0] == a.inverse.level_known_n / FS


def test_a_record_that_starts_at_rest_holds_its_start_level(reduced_slim):
    # The detector confirms rest only after ~0.15-0.6 s of quiet current; over those samples
    # the moving filter integrated the unknown offset (25 nA ramps the slim sample's w by
    # 25e-9 / R0 = 78 um/s: 47 um had been held) and noise.  The level at the last sample with
    # motion (here the start: 0) is held instead.  Noise 20 nA (the configured level) and
    # 200 nA (10x: measured from the first samples, not taken for motion).  Bound 10 um: one
    # stray motion verdict at 200 nA moves w by K_w * 200 nA ~ 7 um per sample (seen: 0-9 um).
    for noise in (20e-9, 200e-9):
        for seed in range(5):
            i = 25e-9 + noise * np.random.default_rng(seed).standard_normal(3000)
            est = KalmanEstimator(reduced_slim, FS)
            w = est.process(i)
            assert est.at_rest
            assert np.max(np.abs(w[1000:])) < 10e-6, (noise, seed)


def _chirp_then_hold(t):
    """Return a 2 -> 6 Hz chirp over 3 s (not periodic) that ends 1 mm up, then held."""
    u = np.clip(t / 3.0, 0.0, 1.0)
    window = np.clip(t / 0.2, 0, 1) * np.clip((3.0 - t) / 0.3, 0, 1)
    chirp = np.sin(2 * np.pi * (2 * t + t * t * 4 / 6))
    return 1e-3 * u * u * (3 - 2 * u) + 0.5e-3 * chirp * window


def test_the_first_rest_removes_the_ramp_of_the_unknown_offset(reduced_slim):
    # Before the first rest the offset is unknown: 25 nA ramps w by 25 nA * t / R0 (215 um in
    # this 3 s move; -40 nA: -344 um).  At the rest the offset is learned and the held level is
    # corrected for that ramp: the held level is the same with either offset as with none,
    # within 5 um (measured 1-2 um: the rest detector's timing differs by a few samples).
    t = np.arange(7000) / FS
    wt = _chirp_then_hold(t)
    for noise, seed in ((0.0, 0), (20e-9, 1), (100e-9, 2)):
        held = []
        for offset in (0.0, 25e-9, -40e-9):
            i = daq_current(SLIM, t, wt, offset_a=offset, noise_a=noise, seed=seed)
            est = KalmanEstimator(reduced_slim, FS)
            held.append(est.process(i)[-1])
            assert est.at_rest
        assert abs(held[1] - held[0]) < 5e-6 and abs(held[2] - held[0]) < 5e-6, (noise, held)


def test_first_rest_correction_agrees_in_blocks_and_samples_and_restores(reduced_slim):
    # 200 nA noise: the offset needs the full 10 s average to be trusted, so the first rest's
    # correction is still running when the state is saved at the end.
    t = np.arange(7000) / FS
    i = daq_current(SLIM, t, _chirp_then_hold(t), offset_a=25e-9, noise_a=200e-9, seed=3)
    ests, outputs = blocks_and_samples(lambda: KalmanEstimator(reduced_slim, FS), i)
    assert ests[0]._held_fix is not None
    assert_agree_and_restore(ests, outputs, i[:700])


def _moves_and_holds(t):
    """Return: rest 1 s, a 3 s move to 1 mm, rest 3 s, an 8 s move to 2 mm, rest (chirps)."""
    def move(t0, dur, h0, h1):
        u = np.clip((t - t0) / dur, 0, 1)
        tt = np.clip(t - t0, 0, dur)
        window = np.clip(tt / 0.2, 0, 1) * np.clip((dur - tt) / 0.3, 0, 1)
        chirp = np.sin(2 * np.pi * (2 * tt + tt * tt * 2 / dur))
        return h0 + (h1 - h0) * u * u * (3 - 2 * u) + 0.3e-3 * chirp * window
    return np.where(t < 7, move(1.0, 3.0, 0.0, 1e-3), move(7.0, 8.0, 1e-3, 2e-3))


def test_a_rest_restores_what_the_leak_took_from_the_move_before_it(reduced_slim):
    # While moving, the leak pulls w towards the last held level (0.001 Hz after a rest: an
    # 8 s move to +1 mm lost 38 um).  w only feeds the output, so at the rest the leak-free
    # estimate w + L is exact; the held level is the true one within 2 um on clean current
    # (measured 0.2 / 0.8 um: reduction error) and 15 um with 20 nA noise (the leak-free
    # integral's noise walk, ~ K_w sigma over the move: measured 1 / 10 um).
    t = np.arange(18000) / FS
    wt = _moves_and_holds(t)
    for noise, tol in ((0.0, 2e-6), (20e-9, 15e-6)):
        i = daq_current(SLIM, t, wt, offset_a=10e-9, noise_a=noise, seed=0)
        w = KalmanEstimator(reduced_slim, FS).process(i)
        for k in (6000, 17900):                  # in the two rests after the moves
            assert abs(w[k] - wt[k]) < tol, (noise, k, w[k] - wt[k])


def test_damped_free_vibration_with_offset_and_noise():
    # Issue-14 row 4: the paper's Fig. 7 motion (2 mm, 30 Hz, damping 0.05) released after
    # 5.5 s of hold, 1 % noise + 10 nA offset, slim.  The target, 5 %, is asserted (bench,
    # seeds 0-2 and 91: 0.4-0.9 %; the hold teaches the offset, the rest after the ring-down
    # holds the smoothed level).
    from ipmc_sensor_ros.simulation.stimuli import FreeVibration
    t = np.arange(int(8 * FS)) / FS
    w = FreeVibration(2e-3, 30.0, 0.05, release_s=5.7).deflection(t)
    i = daq_current(SLIM, t, w, offset_a=10e-9, noise_fraction=0.01, seed=23)
    est = DeflectionEstimator(SLIM, FS, estimator='kalman')
    w_hat = in_blocks(est, t, i)
    sel = t >= 5
    assert nrmse(w_hat[sel], w[sel]) < 0.05
