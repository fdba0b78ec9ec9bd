# SPDX-License-Identifier: Apache-2.0
"""
An ADC whose step is above the noise: its rounding is measurement noise of variance q^2/12.

estimation/noise.py: R is at least q^2 / 12, q the smallest change between two successive
samples seen.  Records come from ``bench.scenarios`` (exact H2 by FFT with a pre-roll, DAQ
offset, noise and quantisation): generated independently of the estimator's code.
"""
from __future__ import annotations

import numpy as np
import pytest

from bench.bench_estimators import _causal, estimate_scores
from bench.scenarios.daq import Daq
from bench.scenarios.library import MM, NA, Scenario
from bench.scenarios.motions import Crank
from bench.scenarios.sensor import Sensor
from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator
from ipmc_sensor_ros.estimation.noise import NoiseMeter
from ipmc_sensor_ros.estimation.rest import RestWindow
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
