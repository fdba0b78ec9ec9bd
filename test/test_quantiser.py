# SPDX-License-Identifier: Apache-2.0
"""
An ADC whose step is above the noise: its rounding is measurement noise of variance q^2/12.

estimation/noise.py: R is at least q^2 / 12, q the smallest change between two successive
samples seen.  Records come from ``bench.scenarios`` (exact H2 by FFT with a pre-roll, DAQ
offset, noise and quantisation): generated independently of the estimator's code.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import norm

from bench.bench_estimators import _causal, estimate_scores
from bench.scenarios.daq import Daq
from bench.scenarios.library import build, MM, NA, Scenario
from bench.scenarios.motions import Crank
from bench.scenarios.sensor import Sensor
from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator
from ipmc_sensor_ros.estimation.noise import NoiseMeter
from ipmc_sensor_ros.estimation.rest import RestWindow
from ipmc_sensor_ros.estimation.rounding import RoundingTally
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import Geometry


def _meter(values) -> NoiseMeter:
    meter, window = NoiseMeter(20e-9 ** 2), RestWindow.empty(64, 0, 1.0)
    for v in values:
        window.push(float(v), None)
        meter.add(float(v), 1, window, 0.001)
    return meter


def test_the_noise_is_at_least_the_quantisers_and_unchanged_without_one():
    """
    A reading on one code that steps to the next now and then has R >= q^2 / 12.

    3.05 nA steps (16 bits over +-100 uA) under 0.37 nA of noise: the third differences
    alone read 0.72 nA here (0.5 nA on drawn record 40); R is q / sqrt(12) = 0.88 nA.
    White noise of 2 nA without a quantiser reads 2 nA within the average's spread (20 %
    allowed for 4,000 samples of a 1 s average: its relative spread is ~5 %), its smallest
    change far below it.
    """
    rng = np.random.default_rng(0)
    q = 200e-6 / 2 ** 16
    codes = np.round((34.5e-9 + 0.37e-9 * rng.standard_normal(4000)) / q) * q
    meter = _meter(codes)
    assert meter.step_a == pytest.approx(q, rel=1e-9)       # float rounding of the codes
    assert meter.var_a2 == pytest.approx(q * q / 12, rel=1e-9)
    assert meter.measured_a2 < 0.8 * meter.var_a2     # the third differences: 0.72 nA RMS
    white = _meter(2e-9 * rng.standard_normal(4000))
    assert abs(np.sqrt(white.var_a2) / 2e-9 - 1) < 0.2
    assert white.step_a < 0.01 * 2e-9


def test_a_crank_from_rest_on_a_16_bit_daq_below_its_step_learns_its_offset_at_rest():
    """
    Drawn record 40's case: a 16-bit DAQ's step (3.05 nA) over 0.37 nA of noise.

    At rest the reading sits on one code and steps to the next on ~5 % of the samples.
    Measured on the third differences alone, R was 0.5 nA, each such step 5.7 sigma: it
    restarted the rest test, the start (0.4 s) was never a rest, the 34.5 nA offset was never
    learned and the spin-up left the level 1.5 mm off (71 % NRMSE).  With the quantiser's
    q^2/12 in R the start is a rest: measured 0.33 % on the drawn record; allowed 1 % (the
    issue's floor).
    """
    def make(rng):
        crank = Crank(5.3, 2.0 * MM, 20 * MM, phase_rad=1.0, start_s=0.4)
        return Sensor('big'), crank, Daq(sample_rate_hz=500.0, offset_a=34.5 * NA,
                                         noise_a=0.37 * NA, adc_bits=16,
                                         full_scale_a=100e-6)
    rec = Scenario('crank-16bit', 'daq', 10.0, make, '').build(0)
    model = SensorModel.named(rec.model, Geometry(*rec.geometry_m, rec.sample),
                              extra_effects=rec.effects)
    est = DeflectionEstimator(model, rec.sample_rate_hz)
    out = _causal(rec, est, 1000)
    assert estimate_scores(rec, out)['nrmse'] < 0.01


@pytest.mark.parametrize('sigma', [0.0, 0.1, 0.2, 0.3])
def test_the_rounding_a_still_level_keeps_has_the_variance_the_meter_says(sigma):
    """
    Var(beta) against a direct sum: the mean reading of a level u within a step, over u.

    For each of 2,000 levels u in [0, q) the mean rounding error is sum over the codes of
    (code - u) P(code | u, sigma) with Gaussian noise; its variance over u is what the
    meter's Fourier series says when its measured variance is sigma^2 + q^2 / 4 (its
    convention: the measured variance less the most a still level's rounding adds).  The
    series keeps three terms and the rest at k = 4: 1 % allowed.
    """
    q, meter = 1.0, NoiseMeter(1.0)
    meter.step_a, meter.measured_a2 = q, sigma ** 2 + q * q / 4
    u = (np.arange(2000) + 0.5) / 2000 * q
    codes = np.arange(-8, 9)[:, None] * q
    if sigma:
        edges = (codes - u - q / 2) / sigma
        p = norm.cdf(edges + q / sigma) - norm.cdf(edges)
    else:
        p = np.abs(codes - u) < q / 2
    bias = ((codes - u) * p).sum(axis=0)
    assert meter.rounding_bias_a2() == pytest.approx(np.mean(bias ** 2), rel=0.01)
    # a noise that dithers the rounding leaves none; no step seen, nothing is known of it
    meter.measured_a2 = q * q
    assert meter.rounding_bias_a2() < 1e-12 * q * q
    meter.step_a = math.inf
    assert meter.rounding_bias_a2() == 0.0


@pytest.mark.parametrize('seed', [0, 1])
def test_a_coarse_adcs_rest_rounding_is_in_the_published_std(seed):
    """
    ``slim-coarse-adc``: a 12-bit ADC's 10-25 nA step over 0.2 nA of noise, a crank after a rest.

    The rest reads one code, so the offset it measures is off by that level's rounding, and
    the level walks once the crank starts: the published std covered 5 % (seed 0) and 40 %
    (seed 1) of the errors within 2 sigma.  With the rounding's share (estimation/rounding.py)
    the issue's 90 % at least (measured 100 %).
    """
    rec = build('slim-coarse-adc', seed)
    model = SensorModel.named(rec.model, Geometry(*rec.geometry_m, rec.sample),
                              extra_effects=rec.effects)
    scores = estimate_scores(rec, _causal(rec, DeflectionEstimator(model, rec.sample_rate_hz),
                                          1000))
    assert scores['coverage'] >= 0.90


def test_without_a_quantiser_the_published_std_is_the_filters_own():
    # an unquantised record (a crank from rest): its smallest change is far below the noise,
    # so the rounding's share is 0 and the std is sqrt(P_ww) to the bit
    rec = build('crank-5hz-slim-0.2na-rest', 0)
    model = SensorModel.named(rec.model, Geometry(*rec.geometry_m, rec.sample),
                              extra_effects=rec.effects)
    est = DeflectionEstimator(model, rec.sample_rate_hz)
    _causal(rec, est, 1000)
    core = est.core
    w_row, state = core._filter._w_row, core._state
    assert state.rounding is not None and state.noise.rounding_bias_a2() == 0.0
    assert core._filter.deflection(state)[1] == np.sqrt(w_row @ state.P @ w_row)


def test_a_rest_that_begins_keeps_the_share_of_the_one_before():
    # the published variance does not jump as a new rest begins: the old rest's share (its
    # rounding through the gains since) is folded in whole, and the new rest starts from d = 0
    meter = NoiseMeter(1.0)
    meter.step_a, meter.measured_a2 = 10e-9, 0.04e-18     # 10 nA steps, 0.2 nA of noise
    tally = RoundingTally(None, 3)
    w_row = np.array([2.0, 0.0, 0.0])
    tally.update(np.array([0.5, 0.1, 0.0]), np.array([1.0, 0.0, 0.0]), 1.0, meter)
    tally.predict(np.eye(3) * 2.0, meter)
    before = tally.variance(w_row, meter)
    assert before == pytest.approx(meter.rounding_bias_a2(0.04e-18) * (2.0 * 0.5 * 2.0) ** 2)
    tally.fold(w_row, meter)
    tally.fold(w_row, meter)                    # nothing since: nothing more to fold
    assert tally.variance(w_row, meter) == before and not tally.d.any()
    tally.update(np.array([0.25, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]), 1.0, meter)
    second = tally.variance(w_row, meter)       # this rest's share beside the folded one
    assert second == pytest.approx(before + meter.rounding_bias_a2(0.04e-18) * 0.5 ** 2)
    tally.fold(w_row, meter)
    assert tally.variance(w_row, meter) == second
