# SPDX-License-Identifier: Apache-2.0
"""
Where the offset stepped under a periodic model: the jump's likelihood ratio at every sample.

estimation/step_glr.py computes Willsky and Jones's ratio by the adjoint of the signature's
recursion, so every sample is a candidate.  Records come from ``bench.scenarios`` (exact H2
by FFT with a pre-roll, a DAQ whose offset steps): generated independently of the
estimator's code.
"""
from __future__ import annotations

import numpy as np
import pytest

from bench.bench_estimators import _causal, estimate_scores
from bench.scenarios.daq import Daq
from bench.scenarios.drawn import draw
from bench.scenarios.library import MM, NA, Scenario
from bench.scenarios.motions import Crank
from bench.scenarios.sensor import Sensor
from ipmc_sensor_ros.estimation.config import EstimatorConfig
from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator
from ipmc_sensor_ros.estimation.filter import KalmanFilter
from ipmc_sensor_ros.estimation.forward import ForwardRecord
from ipmc_sensor_ros.estimation.innovations import block_samples
from ipmc_sensor_ros.estimation.periodic import Stretch
from ipmc_sensor_ros.estimation.statespace import StateSpaceModel
from ipmc_sensor_ros.estimation.step_glr import _innovations, _ratios
from ipmc_sensor_ros.lti.reduction import reduce_model_parts
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import Geometry, PAPER_SAMPLES

CRANK_HZ = 2.65         # drawn record 63's crank: a period of 755 samples at 2 kHz
START_S = 4.0           # the stretch judged starts here


def _record(jump_s: float, step_a: float = 6.3 * NA):
    """Return a slim crank from rest at 0.3 s, 2 kHz, 0.2 nA; the offset steps at ``jump_s``."""
    def make(rng):
        crank = Crank(CRANK_HZ, 2.0 * MM, 20 * MM, phase_rad=0.3, start_s=0.3)
        daq = Daq(sample_rate_hz=2000.0, offset_a=30 * NA, noise_a=0.2 * NA, adc_bits=16,
                  offset_steps=((jump_s, step_a),))
        return Sensor('slim'), crank, daq
    return Scenario('crank-step', 'daq', 6.0, make, '').build(0)


@pytest.fixture(scope='module')
def periodic_filter():
    reduced = reduce_model_parts(SensorModel.named('h2', PAPER_SAMPLES['slim']), 4,
                                 (0.1, 50.0))[0]
    return KalmanFilter(StateSpaceModel(reduced, EstimatorConfig(), 2000.0, (),
                                        CRANK_HZ))


def _stretch(filt, rec):
    """Return the record from START_S on, and the state the filter had there."""
    assert np.allclose(np.diff(rec.sample_time_s), 1.0 / rec.sample_rate_hz)   # no row dropped
    first = round(START_S * rec.sample_rate_hz)
    state = filt.run(filt.initial_state(), rec.current_a[:first])[0]
    rest = rec.current_a[first:].tolist()
    return Stretch(filt, state, rest, [1] * len(rest)), first


def test_the_backward_sums_are_the_signature_sums(periodic_filter):
    """
    The adjoint pass gives what the signature's forward recursion gives, at any candidate.

    The forward recursion (a unit jump's state error e through F (I - K c), its innovation
    c e / sqrt(S)) is written here once per candidate; block sums over periods as in
    :mod:`ipmc_sensor_ros.estimation.innovations`.  Agreement to 1e-9 of the largest value
    (measured 1e-14: the same products in another order).
    """
    filt = periodic_filter
    m = filt.model
    span, _ = _stretch(filt, _record(4.3))
    forward = _innovations(span, filt, 512)
    z, s, rows, gains, maps = forward
    assert not maps                     # in motion throughout: one update a sample
    period = block_samples(m.motion_hz, m.sample_rate_hz)
    fit, power = _ratios(filt, span.steps, forward, period)
    F = m.discrete(1)[0]
    for t in (1, 97, 600, 755, 1000):
        e = np.zeros(m.size)
        e[m.ib] = 1.0 / m.scale[m.ib]
        rho = np.zeros(z.size)
        for k in range(t, z.size):
            rho[k] = rows[k] @ e / s[k]
            e = F @ (e - gains[k] / s[k] ** 2 * (rows[k] @ e))
        blocks = np.arange(0, z.size, period)
        block_rho, block_z = np.add.reduceat(rho, blocks), np.add.reduceat(z, blocks)
        sizes = np.minimum(period, z.size - blocks)
        expected = np.array([[block_rho @ (block_z / sizes), rho @ z],
                             [block_rho ** 2 @ (1.0 / sizes), rho @ rho]])
        got = np.array([fit[:, t], power[:, t]])
        assert np.all(np.abs(got - expected) <= 1e-9 * np.abs(expected).max(axis=1)[:, None])


def test_the_signature_is_what_a_jump_does_to_the_filter_across_a_rest():
    """
    A jump's signature through a rest's end is the filter's own response to that jump.

    The span starts still (the crank starts 0.3 s into the record: 218 still samples, then
    motion), under the broad motion prior :mod:`.jump_time` refilters with.  Filtering the
    span again with the offset moved by 1 pA from sample t changes the normalised
    innovations by rho_k(t) per ampere: the signature by definition.  Measured agreement
    0.002-0.2 % (the noise meter follows the data, so a jump moves the gains a little, which
    the fixed-gain signature of Willsky and Jones leaves out); 1 % allowed.  Before the rest's
    pseudo-measurements were in the recursion, the sums at the still samples grew past 1e60.
    """
    reduced = reduce_model_parts(SensorModel.named('h2', PAPER_SAMPLES['slim']), 4,
                                 (0.1, 50.0))[0]
    filt = KalmanFilter(StateSpaceModel(reduced, EstimatorConfig(), 2000.0, (), ()))
    m, rec = filt.model, _record(5.0)
    state = filt.run(filt.initial_state(), rec.current_a[:400])[0]
    y = rec.current_a[400:2400].tolist()
    forward = _innovations(Stretch(filt, state, y, [1] * len(y)), filt, 512)
    z, s, rows, _, maps = forward
    fit, power = _ratios(filt, [1] * len(y), forward, 1, blocks=False)

    def predicted(values):
        record = ForwardRecord.empty(len(values), m.size)
        still = filt.run(state.copy(), values, record=record)[3]
        return record.x_pred, still
    x0, still = predicted(y)
    assert 100 < len(maps) == still.sum() < len(y) - 1000      # still, then moving
    pa = 1e-12
    for t in (5, 100, 200, 300, 800):
        x1, still1 = predicted(y[:t] + [v + pa for v in y[t:]])
        assert np.array_equal(still1, still)
        rho = (np.arange(len(y)) >= t) / s - np.einsum('ki,ki->k', x1 - x0, rows) / (pa * s)
        assert fit[1, t] == pytest.approx(rho @ z, rel=0.01)
        assert power[1, t] == pytest.approx(rho @ rho, rel=0.01)


@pytest.mark.parametrize('jump_s', [4.1218, 4.3004, 4.6661])
def test_a_step_of_the_offset_is_placed_on_its_sample(periodic_filter, jump_s):
    """
    A 6.3 nA step under a crank is most likely, sample by sample, on its own sample.

    Drawn record 63 (this crank, this step, 0.17 nA noise): the candidates were every
    len/200-th sample (13 here), the step's was not one of them, and a jump one sample off
    fails the model's test as surely as none (chi-square 100-114 for 4 blocks against a
    limit of 33; on its sample 0.0).  The step times here fall between the old candidates.
    """
    filt = periodic_filter
    rec = _record(jump_s)
    span, first = _stretch(filt, rec)
    forward = _innovations(span, filt, 512)
    period = block_samples(filt.model.motion_hz, filt.model.sample_rate_hz)
    fit, power = _ratios(filt, span.steps, forward, period)
    z = forward[0]
    at = np.arange(1, z.size - period + 1)
    stepped = int(np.argmax(rec.sample_time_s >= jump_s))
    assert at[np.argmax(fit[1, at] ** 2 / power[1, at])] == stepped - first


def test_a_step_just_after_the_crank_is_modelled_is_taken_and_the_level_holds():
    """
    Drawn record 63: the estimator takes the step under its periodic model and keeps both.

    narrow, a 2.64 Hz crank from rest, 2 kHz, 0.17 nA noise, 16 % hum at 59.71 Hz; the
    2.65 Hz model came at 4.0 s and the offset stepped by 6.3 nA at 4.12 s.  The model's
    test failed, the jump was tried 90 ms late (the nearest of every 13th sample the ratio
    was computed at) and failed the test too, the model went and was refused at every check
    after (its span's offset 6 nA off), and the level ramped 65 um/s for 10 s: 22.9 % NRMSE.
    Now 0.58 % (the issue's limit: 1 %), the model kept and the offset within 0.3 nA of the
    DAQ's at the end (measured 0.01 nA).
    """
    rec, _ = draw(63, 20.0)
    model = SensorModel.named(rec.model, Geometry(*rec.geometry_m, rec.sample),
                              extra_effects=rec.effects)
    est = DeflectionEstimator(model, rec.sample_rate_hz)
    assert estimate_scores(rec, _causal(rec, est, 1000))['nrmse'] < 0.01
    status = est.core.status()
    assert status['offset_jumps'] == 1 and status['motion_hz'] == pytest.approx(2.65, 0.01)
    assert status['offset_a'] == pytest.approx(rec.offset_a[-1], abs=0.3 * NA)
