# SPDX-License-Identifier: Apache-2.0
"""
The periodic-motion states of the Kalman estimator: model, measurement, policy, estimate.

Code: estimation/statespace.py, motionline.py, periodic.py, kalman.py.

Records come from ``bench.scenarios`` (exact H2 by FFT with a pre-roll, a crank-slider with
speed wobble, DAQ offset and noise): generated independently of the estimator's code.
"""
import math

import numpy as np
import pytest

from bench.bench_estimators import estimate_scores, run_estimator
from bench.scenarios import build
from ipmc_sensor_ros.estimation.config import EstimatorConfig
from ipmc_sensor_ros.estimation.kalman import KalmanEstimator
from ipmc_sensor_ros.estimation.motionline import measure_motion, measure_recent
from ipmc_sensor_ros.estimation.motionline import MOTION_WOBBLE, MOTION_WOBBLE_HZ
from ipmc_sensor_ros.estimation.periodic import StretchLog
from ipmc_sensor_ros.estimation.statespace import StateSpaceModel
from ipmc_sensor_ros.lti.reduction import reduce_model_parts
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import PAPER_SAMPLES

FS = 1000.0


@pytest.fixture(scope='module')
def reduced():
    model = SensorModel.named('h2', PAPER_SAMPLES['short'])
    return reduce_model_parts(model, 4, (0.1, 50.0))[0]


def test_forced_response_solves_its_sylvester_equation(reduced):
    """X V = A_mm X + A_mp: the motion states' steady response to the periodic states."""
    ssm = StateSpaceModel(reduced, EstimatorConfig(), FS, motion_hz=5.0)
    assert ssm.motion_lines_hz == (5.0, 10.0, 15.0)
    A, _ = ssm.continuous
    s = ssm.scale
    As = A * s[None, :] / s[:, None]
    m, p = ssm.motion_states, np.arange(ssm.im, ssm.size)
    X = ssm.forced_response
    lhs = X @ As[np.ix_(p, p)]
    rhs = As[np.ix_(m, m)] @ X + As[np.ix_(m, p)]
    assert np.max(np.abs(lhs - rhs)) < 1e-9 * np.max(np.abs(As[np.ix_(m, p)]))


def test_moving_start_prior_is_invariant_under_the_model(reduced):
    """
    Moving since before the start: one step of the model leaves the prior unchanged.

    With no walk of the periodic states and their rates known zero (the fundamental exact)
    their covariance is kept by the rotation, and the motion states' part (forced response
    + stationary remainder) is then stationary too.
    """
    cfg = EstimatorConfig(motion_speed_walk=0.0, working_point_walk_m=0.0,
                          offset_walk_a=0.0, offset_drift_walk_a_per_s=0.0)
    ssm = StateSpaceModel(reduced, cfg, FS, motion_hz=5.0)
    F, Q = ssm.discrete(1)
    _, P0 = ssm.prior()
    T = np.eye(ssm.size)        # the prior is T P T' (forced response); rates known zero in P
    T[np.ix_(ssm.motion_states, np.arange(ssm.im, ssm.size))] = ssm.forced_response
    P = np.linalg.solve(T, np.linalg.solve(T, P0).T)
    P[ssm.ir:, :] = P[:, ssm.ir:] = 0.0
    P0 = T @ P @ T.T
    m = np.r_[ssm.motion_states, np.arange(ssm.im, ssm.size)]
    # the offset drift turns into offset: leave those two out; 1e-8: discrete vs continuous
    # Lyapunov solutions and the Sylvester solve, each near 1e-10 of the largest entry
    step = (F @ P0 @ F.T + Q)[np.ix_(m, m)]
    assert np.max(np.abs(step - P0[np.ix_(m, m)])) < 1e-8 * np.max(np.abs(P0[np.ix_(m, m)]))


def test_measure_motion_finds_a_crank_two_sines_and_no_motion(reduced):
    """
    A crank's fundamental to 1 %; two unrelated sines: none, or each; no motion: none.

    With one motion modelled (the default ``motion_fundamentals``) two sines are refused: one
    family of harmonics cannot explain them.  With three, the second is searched in what the
    first leaves, and each refined beside the other: a 2 s stretch resolves 5 and 7.3 Hz to
    1e-3 (its resolution is 0.5 Hz; the least-squares fit of two clean sines in 1 nA of noise
    is far finer).
    """
    ssm = StateSpaceModel(reduced, EstimatorConfig(), FS)
    crank = build('crank-5hz-short-0.2na-poweron', 0)
    found = measure_motion(crank.current_a[:2000], crank.sample_rate_hz, ssm)
    assert found == pytest.approx((5.0,), rel=1e-2)  # a 2 s mean of a speed wobbling by <= 1 %
    two = _two_sines(reduced, 2000, (5.0, 0.8e-3), (7.3, 0.3e-3), 1e-9, seed=0)
    assert measure_motion(two, FS, ssm) == ()
    assert measure_motion(two, FS, _several(reduced)) == pytest.approx((5.0, 7.3), rel=1e-3)
    rng = np.random.default_rng(0)
    assert measure_motion(1e-9 * rng.standard_normal(2000), FS, _several(reduced)) == ()


def test_slots_the_daq_did_not_deliver_are_left_out_of_the_motion_s_measurement(reduced):
    """
    A burst of dropped rows inside the stretch: the crank is still found, and its fit holds.

    The Kalman estimator's grid keeps NaN where the DAQ delivered nothing (ring.on_grid).
    Before, a bridged slot held the next sample's value: a 39-row burst (drawn record 82, a
    1.49 Hz crank) put a flat stretch in every window that held it, the periodic model was
    refused there and dropped for seconds, and an offset step under the crank then came to
    the broad prior, which read it as a ramp (26 % NRMSE; the same record without the burst
    0.51 %).  Here 60 ms of a 5 Hz crank missing from 2 s: held, the fit's residual is
    refused; left out, 5 Hz to 1 % as without the burst; with no sample at all, none.
    """
    ssm = StateSpaceModel(reduced, EstimatorConfig(), FS)
    y = build('crank-5hz-short-0.2na-poweron', 0).current_a[:2000].copy()
    gap = slice(900, 960)
    held = y.copy()
    held[gap] = y[960]
    assert measure_motion(held, FS, ssm) == ()
    y[gap] = np.nan
    assert measure_motion(y, FS, ssm) == pytest.approx((5.0,), rel=1e-2)
    assert measure_motion(np.full(2000, np.nan), FS, ssm) == ()


def test_drawn_record_82_keeps_its_crank_through_a_burst_and_finds_the_offset_step():
    """
    Drawn record 82 (1.49 Hz crank, a 39-row burst at 5.5 s, -37 nA offset step at 9.9 s).

    26 % NRMSE while the burst's held slots refused the periodic model (previous test);
    then 1.45 %: judged on the last 1, 2, 4 and 8 s, the crank (from rest at ~1 s) was
    modelled at 6 s, after the burst, which the broad prior bridged 100 um off.  On every
    whole second's stretch it is modelled before the burst: 0.52 % (bound 0.026 %: the
    step's period is left).  Allowed: the issue's 1 %.
    """
    from bench.scenarios.drawn import draw
    rec = draw(82)[0]
    assert estimate_scores(rec, run_estimator(rec))['nrmse'] < 0.01


def _several(reduced):
    """Return the model of an estimator that models up to three periodic motions."""
    return StateSpaceModel(reduced, EstimatorConfig(motion_fundamentals=3), FS)


def _gain(reduced, f):
    """|H(f)|, A/m: the current of a 1 m sine at f."""
    return abs(reduced.frequency_response(np.array([f]))[0])


def _two_sines(reduced, n, first, second, noise_a, seed):
    """Return the current of two sines (Hz, m), the second 1 rad ahead, and white noise (A)."""
    t = np.arange(n) / FS
    rng = np.random.default_rng(seed)
    (f1, a1), (f2, a2) = first, second
    return (a1 * _gain(reduced, f1) * np.sin(2 * np.pi * f1 * t)
            + a2 * _gain(reduced, f2) * np.sin(2 * np.pi * f2 * t + 1.0)
            + noise_a * rng.standard_normal(n))


def test_a_slow_crank_is_judged_on_a_long_stretch(reduced):
    """
    A 1 Hz crank: not periodic on 2 s, 1 Hz on 8 s; two slow sines on 8 s: both, modelled.

    2 s hold too few of its periods to search it (MOTION_PERIODS), and a family of its
    harmonics leaves the fundamental in the residual; measure_recent tries 1, 2, ..., 8 s.
    The sines' fundamentals to 1 % (each refined beside the other on pieces of two of its
    periods, where the other's is not resolved).
    """
    ssm = StateSpaceModel(reduced, EstimatorConfig(), FS)
    y = build('crank-1hz-short-0.2na-poweron', 0).grid_current_a
    assert measure_recent(y[:2000], FS, ssm) == ()
    assert measure_recent(y[:8000], FS, ssm) == pytest.approx((1.0,), rel=1e-2)
    two = _two_sines(reduced, 8000, (1.0, 0.5e-3), (1.7, 0.3e-3), 0.2e-9, seed=1)
    assert measure_recent(two, FS, ssm) == ()
    assert sorted(measure_recent(two, FS, _several(reduced))) == pytest.approx([1.0, 1.7],
                                                                               rel=1e-2)


@pytest.mark.parametrize('noise_a', [0.0, 1e-10, 1e-9])
def test_a_sine_with_little_noise_keeps_its_fundamental(reduced, noise_a):
    """
    A 5 Hz sine of 0.5 mm with 0-1 nA of noise is 5 Hz periodic on 2, 4 and 8 s.

    With little noise the family at half the fundamental (2.5, 5, 7.5 Hz: the line and its
    leakage) outweighs the line's own (5, 10, 15 Hz); its first line is no line, and the
    stretch was judged not periodic, so a clean record lost its periodic model at the second
    check.  Tolerance: the refined fundamental of a clean sine, to 1e-4.
    """
    ssm = StateSpaceModel(reduced, EstimatorConfig(), FS)
    y = _two_sines(reduced, 8000, (5.0, 0.5e-3), (7.3, 0.0), noise_a, seed=3)   # one sine
    for seconds in (2, 3, 5, 8):
        assert measure_recent(y[:int(seconds * FS)], FS, ssm) == pytest.approx((5.0,),
                                                                               rel=1e-4)


def test_a_speed_wobble_is_allowed_and_a_line_beyond_its_reach_is_not(reduced):
    """
    A 20 Hz crank whose speed wobbles by MOTION_WOBBLE at MOTION_WOBBLE_HZ is periodic.

    The same with a line of 1 % of the crank's at 24 Hz (4 Hz off: beyond the wobble's
    excursion and four sidebands) is not: it is a second motion, found when several are.
    """
    ssm = StateSpaceModel(reduced, EstimatorConfig(), FS)
    t = np.arange(2000) / FS
    f, rate = 20.0, MOTION_WOBBLE_HZ
    phase = 2 * np.pi * f * t + f * MOTION_WOBBLE / rate * np.sin(2 * np.pi * rate * t)
    rng = np.random.default_rng(2)
    crank = (1e-3 * _gain(reduced, f) * np.sin(phase)
             + 0.05e-3 * _gain(reduced, 2 * f) * np.sin(2 * phase)
             + 0.2e-9 * rng.standard_normal(t.size))
    assert measure_motion(crank, FS, ssm) == pytest.approx((f,), rel=MOTION_WOBBLE)
    line = 0.01e-3 * _gain(reduced, 24.0) * np.sin(2 * np.pi * 24.0 * t)
    # the line to 1 % (a quarter of the stretch's resolution): 1 % of the crank, beside
    # the wobble's sidebands 0.5 Hz apart, refined on pieces of 0.5 s
    assert measure_motion(crank + line, FS, _several(reduced)) == pytest.approx((f, 24.0),
                                                                                rel=1e-2)
    assert measure_motion(crank + line, FS, ssm) == ()


def test_power_on_crank_level_is_learned_within_one_percent():
    """
    A 5 Hz crank moving since before power-on, with an unknown offset: within 1 % NRMSE.

    The periodic model is adopted and the estimate stays within 1 % NRMSE after the first
    second (the bench's pass mark); the bounded-motion prior alone gave 2.1 % on this record.
    """
    record = build('crank-5hz-short-pct-poweron', 0)
    est = run_estimator(record)
    assert est.rows_estimated == est.rows_given
    assert estimate_scores(record, est)['nrmse'] < 0.01


def test_blocks_singles_and_restore_agree_through_a_change_of_motion_model(reduced):
    """The refiltered stretch at a model change is the same for any cut and after a restore."""
    record = build('crank-20hz-short-0.2na-poweron', 1)
    y = record.grid_current_a[:int(5.0 * FS)] + 5e-9
    whole = KalmanEstimator(reduced, FS)
    w_block = whole.estimate(y).deflection_m
    assert whole.status()['motion_hz'] == pytest.approx(20.0, rel=0.01)
    one = KalmanEstimator(reduced, FS)
    w_one = np.array([one.estimate_one(v)[0] for v in y])
    assert np.array_equal(w_block, w_one)
    cut = KalmanEstimator(reduced, FS)
    cut.estimate(y[:2300])      # past the first check: the next one refilters from there
    saved = cut.get_state()
    tail = cut.estimate(y[2300:]).deflection_m
    cut.set_state(saved)
    assert np.array_equal(tail, cut.estimate(y[2300:]).deflection_m)
    assert np.array_equal(tail, w_block[2300:])
    assert math.isfinite(cut.status()['offset_a'])


class _State:
    """Stand-in for a FilterState (the log only copies it)."""

    def copy(self):
        return self


def _log_after(stretches):
    """
    Return a StretchLog after stretches of (samples, rest, fundamentals Hz or None) each.

    An optional fourth item is the lowest fundamental the measurement could see, Hz.
    """
    log = StretchLog('filter', _State())
    for i, (n, rest, measured, *floor) in enumerate(stretches):
        log.add([0.0] * n, [1] * n, np.full(n, rest))
        if i < len(stretches) - 1:
            log.span_for(measured, False, *floor)
            log.mark('filter', _State())
    return log


def test_a_periodic_model_needs_two_stretches_in_a_row_or_a_start_in_motion():
    """The policy of estimation/periodic.py, stretch by stretch."""
    # moving since the start: the first stretch judged decides, from the very start (a
    # stretch not judged, None, runs on into the next)
    log = _log_after([(500, False, None), (500, False, None)])
    span = log.span_for((5.0,), never_rested=True)
    assert span is not None and len(span.y) == 1000
    # after a rest the first judgement alone is not enough ...
    log = _log_after([(500, True, None), (500, False, None)])
    assert log.span_for((5.0,), never_rested=False) is None
    # ... two agreeing stretches are, from the start of the last one
    log = _log_after([(500, True, None), (500, False, (5.0,)), (2000, False, None)])
    span = log.span_for((5.05,), never_rested=False)
    assert span is not None and len(span.y) == 2000
    # ... and of the one before when it had no rest either: both are that periodic motion
    log = _log_after([(500, True, ()), (1000, False, (5.0,)), (1000, False, None)])
    span = log.span_for((5.0,), never_rested=False)
    assert span is not None and len(span.y) == 2000
    # a rest in the last stretch, or a fundamental that moved by more than MOTION_WOBBLE: no
    log = _log_after([(500, True, None), (500, False, (5.0,)), (2000, True, None)])
    assert log.span_for((5.0,), never_rested=False) is None
    log = _log_after([(500, True, None), (500, False, (5.0,)), (2000, False, None)])
    assert log.span_for((5.0 * (1 + 2 * MOTION_WOBBLE),), never_rested=False) is None
    # a check that found none on 1 s of current (4 periods: 4 Hz and up) does not speak of a
    # 2 Hz crank: moving since the start, the 2 Hz of the next check decides alone ...
    log = _log_after([(1000, False, (), 4.0), (2000, False, None)])
    span = log.span_for((2.0,), never_rested=True, floor_hz=4 / 3)
    assert span is not None and len(span.y) == 3000
    log = _log_after([(500, True, None), (500, False, (), 4.0), (2000, False, None)])
    assert log.span_for((2.0,), never_rested=False, floor_hz=4 / 3) is None
    # ... while one that could have seen it (down to 1 Hz) and found none contradicts it
    log = _log_after([(4000, False, (), 1.0), (2000, False, None)])
    assert log.span_for((2.0,), never_rested=True, floor_hz=4 / 6) is None
    # the motion gone twice in a row (none) is a change too, rest or not
    log = _log_after([(500, True, None), (500, False, ()), (2000, True, None)])
    assert log.span_for((), never_rested=False) is not None
    log = _log_after([(500, True, None), (500, False, (), 4.0), (2000, True, None)])
    assert log.span_for((), never_rested=False, floor_hz=2.0) is not None
    # several motions: the same set in any order is the same; one more or less is not
    log = _log_after([(500, True, None), (500, False, (5.0, 7.3)), (2000, False, None)])
    assert len(log.span_for((7.3, 5.0), never_rested=False).y) == 2000
    log = _log_after([(500, True, None), (500, False, (5.0, 7.3)), (2000, False, None)])
    assert log.span_for((5.0,), never_rested=False) is None


def _core(record):
    """Return the Kalman core the package builds for ``record``'s sensor and rate."""
    from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator
    from ipmc_sensor_ros.physics.parameters import Geometry

    model = SensorModel.named(record.model, Geometry(*record.geometry_m, record.sample))
    return DeflectionEstimator(model, record.sample_rate_hz).core


def _stop_record(seed):
    """Return a 2-5 Hz crank that stops and holds (bench), its estimator and its Crank."""
    import zlib

    from bench.scenarios import SCENARIOS

    name = 'slim-crank-stop'
    record = build(name, seed)
    crank = SCENARIOS[name].make(np.random.default_rng([seed, zlib.crc32(name.encode())]))[1]
    return record, _core(record), crank


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_crank_that_stops_is_dropped_within_a_period_and_its_hold_is_read(seed):
    """
    A periodic model that no longer explains the current goes as its next block closes.

    Before, it went at the next check (up to 1 s later), the stop read meanwhile as offset
    (50-90 nA of it) and a false jump of the offset could follow: the hold read 0.35-1.4 mm
    off on 2 Hz cranks.  Now, two periods after the crank stood still (a block closes within
    one and its test fails), the model has no periodic states, and from 1 s on the hold
    reads within 0.1 mm (5 % of the crank's 2 mm swing; measured 5-60 um at 1-2 % noise).
    """
    record, core, crank = _stop_record(seed)
    t, y, fs, truth = record.sample_time_s, record.current_a, record.sample_rate_hz, \
        record.deflection_m
    stop = int(np.searchsorted(t, crank.stop_s))
    still = int(np.searchsorted(t, crank.stop_s + crank.stop_duration_s))
    assert np.ptp(truth[still:]) == 0.0 < np.ptp(truth[:stop])
    w = [core.estimate(y[:stop]).deflection_m]
    assert core.model.motion_hz == pytest.approx(crank.frequency_hz, rel=0.02)
    two_periods = still + int(2 * fs / crank.frequency_hz)
    w.append(core.estimate(y[stop:two_periods]).deflection_m)
    assert core.model.motion_hz == 0.0
    w = np.concatenate(w + [core.estimate(y[two_periods:]).deflection_m])
    held = t > t[still] + 1.0
    assert np.max(np.abs(w[held] - truth[held])) < 1e-4
    # the whole record after 1 s: measured 0.71 / 1.34 / 0.68 % (the wrong estimates before
    # the model goes are most of it; 0.91 / 3.2 / 0.69 % when the test waited for the
    # block's end, the likeliest remainder, 1.25 um here, following the stop less); a jump
    # taken 0.13 s into seed 1's stop, on too few samples to tell it from the stop, read 5.6 %
    judged = t >= 1.0
    assert np.sqrt(np.mean((w - truth)[judged] ** 2) / np.mean(truth[judged] ** 2)) < 0.02


def test_a_crank_braked_in_50_ms_is_not_read_as_a_jump_of_the_offset():
    """
    A stop leaves a residual at the crank's harmonics that the block test cannot see.

    So a jump of the offset placed in it passes that test; it is taken only if the current
    is also more likely so than without the periodic model.  A 2 Hz crank braked in 50 ms
    (a motor braked, an end stop): with the test alone a jump was taken and the hold read
    0.96 mm off (25.8 % NRMSE); with the likelihood 32 um (2.5 %).
    """
    from bench.scenarios.daq import acquire, Daq
    from bench.scenarios.motions import Crank
    from bench.scenarios.sensor import Sensor

    rng = np.random.default_rng([6, 777])
    crank = Crank(2.0, rng.uniform(1.8, 2.2) * 1e-3, rng.uniform(15, 25) * 1e-3,
                  phase_rad=rng.uniform(0, 2 * math.pi), start_s=0.3,
                  wobble=rng.uniform(0, 0.01), wobble_hz=rng.uniform(0.1, 0.5),
                  stop_s=rng.uniform(5.5, 6.5), stop_duration_s=0.05)
    daq = Daq(offset_a=rng.uniform(0, 20) * 1e-9, noise_fraction=rng.uniform(0.01, 0.02))
    record = acquire('braked-crank', 6, Sensor('slim'), crank, 12.0, daq, rng,
                     stationary=False, description='', tags=('crank',), post_record_s=12.0)
    core = _core(record)
    w = core.estimate(record.current_a).deflection_m
    held = record.sample_time_s > crank.stop_s + crank.stop_duration_s + 1.0
    assert core.model.motion_hz == 0.0
    assert np.max(np.abs(w[held] - record.deflection_m[held])) < 1e-4


def test_blocks_and_single_samples_agree_where_a_stopped_crank_is_dropped():
    """The test at each block's close runs at the same sample whichever way the data come."""
    record, whole, _ = _stop_record(0)
    one = _stop_record(0)[1]
    y = record.current_a
    w_block = whole.estimate(y).deflection_m
    w_one = np.array([one.estimate_one(v)[0] for v in y])
    assert np.array_equal(w_block, w_one)
    assert whole.model.motion_hz == one.model.motion_hz == 0.0


def test_two_sines_on_a_shaker_are_modelled_as_two_periodic_motions(monkeypatch):
    """
    Two sines (2.0 and 3.1 Hz, 0.6 and 0.4 mm) since 0.5 s on the short sample, 20 nA offset.

    With one periodic motion modelled (the default) the stretch is never periodic and the
    broad prior confuses the slow part with offset: 2.1 % NRMSE.  With three (the setting
    ``motion_fundamentals``) both are modelled, with the fundamentals to 1 %, and the
    offset is the current's mean within a few periods: 0.79 %.  Asserted: half the error
    of one motion and the issue's 1 %.  The record is the bench's (exact H2 by FFT).
    """
    from bench.scenarios.daq import Daq
    from bench.scenarios.library import MM, NA, Scenario
    from bench.scenarios.motions import Sines, Windowed
    from bench.scenarios.sensor import Sensor
    from ipmc_sensor_ros.estimation import deflection

    def make(rng):
        sines = Sines((2.0, 3.1), (0.6 * MM, 0.4 * MM), (0.0, 1.0))
        return (Sensor('short'), Windowed(sines, 0.5, 30.0, 0.5),
                Daq(sample_rate_hz=500.0, offset_a=20 * NA, noise_fraction=0.01))

    rec = Scenario('two-sines', 'sines', 12.0, make, 'two sines on a shaker').build(0)
    one = estimate_scores(rec, run_estimator(rec))['nrmse']
    monkeypatch.setattr(deflection, 'EstimatorConfig',
                        lambda: EstimatorConfig(motion_fundamentals=3))
    made, init = [], deflection.DeflectionEstimator.__init__
    monkeypatch.setattr(deflection.DeflectionEstimator, '__init__',
                        lambda self, *a, **k: made.append(self) or init(self, *a, **k))
    several = estimate_scores(rec, run_estimator(rec))['nrmse']
    assert several < min(0.5 * one, 0.01)
    fundamentals = made[0].core.status()['motion_fundamentals_hz']
    assert sorted(fundamentals) == pytest.approx([2.0, 3.1], rel=0.01)


def test_blocks_singles_and_restore_agree_with_two_periodic_motions(reduced):
    """Two sines modelled together: blocks, single samples and a restore give the same values."""
    config = EstimatorConfig(motion_fundamentals=3)
    y = _two_sines(reduced, int(6.0 * FS), (5.0, 0.5e-3), (7.3, 0.4e-3), 1e-9, seed=4) + 5e-9
    whole = KalmanEstimator(reduced, FS, config=config)
    w_block = whole.estimate(y).deflection_m
    assert sorted(whole.status()['motion_fundamentals_hz']) == pytest.approx([5.0, 7.3],
                                                                             rel=0.01)
    one = KalmanEstimator(reduced, FS, config=config)
    assert np.array_equal(w_block, [one.estimate_one(v)[0] for v in y])
    cut = KalmanEstimator(reduced, FS, config=config)
    cut.estimate(y[:4300])
    assert len(cut.status()['motion_fundamentals_hz']) == 2      # the state holds both
    saved = cut.get_state()
    tail = cut.estimate(y[4300:]).deflection_m
    cut.set_state(saved)
    assert np.array_equal(tail, cut.estimate(y[4300:]).deflection_m)
    assert np.array_equal(tail, w_block[4300:])
