# SPDX-License-Identifier: Apache-2.0
"""
The remainder a periodic model leaves is chosen by the data (estimation/periodic.py).

The span a periodic model takes over from is filtered again with ``periodic_remainder_rms_m``
and a quarter and a sixteenth of it; the likeliest that explains it is taken.  Records come
from ``bench.scenarios`` (exact H2 by FFT with a pre-roll): a crank alone, and a crank on a
rig that vibrates at 13-42 Hz.
"""
from __future__ import annotations

import numpy as np
import pytest

from bench.bench_estimators import _causal, estimate_scores
from bench.scenarios.daq import Daq
from bench.scenarios.library import MM, NA, Scenario
from bench.scenarios.motions import Crank, Sines, Sum, Windowed
from bench.scenarios.sensor import Sensor
from ipmc_sensor_ros.estimation.config import EstimatorConfig
from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import Geometry

SETTING_M = EstimatorConfig().periodic_remainder_rms_m


def _record(vibration_m: float):
    """Return a slim 5 Hz crank from rest at 0.3 s, 1 kHz, 0.5 nA; the rig's vibration with it."""
    def make(rng):
        crank = Crank(5.0, 2.0 * MM, 20 * MM, phase_rad=0.3, start_s=0.3, wobble=0.005,
                      wobble_hz=0.3)
        shake = Windowed(Sines((13.3, 27.1, 41.7), (vibration_m,) * 3, (0.1, 1.2, 2.3)),
                         0.3, 20.0, 0.2)
        return (Sensor('slim'), Sum((crank, shake)),
                Daq(offset_a=10 * NA, noise_a=0.5 * NA, adc_bits=16))
    return Scenario('crank-rig', 'daq', 10.0, make, '').build(0)


def _estimator(rec):
    model = SensorModel.named(rec.model, Geometry(*rec.geometry_m, rec.sample),
                              extra_effects=rec.effects)
    return DeflectionEstimator(model, rec.sample_rate_hz)


@pytest.mark.parametrize('vibration_m, chosen_m', [(0.0, SETTING_M / 16),
                                                   (20e-6, SETTING_M)])
def test_the_likeliest_remainder_is_taken(vibration_m, chosen_m):
    """
    A clean crank takes the smallest remainder, a shaking rig the setting.

    Measured: 0.018 % NRMSE with 1.25 um (0.020 % with 20 um, as every model took before);
    20 um of vibration on each of three lines keeps 20 um (0.024 %).  Both below the
    issue's 1 % (the 0.5 nA causal bound is far below it).
    """
    rec = _record(vibration_m)
    est = _estimator(rec)
    assert estimate_scores(rec, _causal(rec, est, 1000))['nrmse'] < 0.01
    model = est.core.model
    assert model.motion_hz == pytest.approx(5.0, rel=0.01)
    assert model.config.periodic_remainder_rms_m == pytest.approx(chosen_m)
    assert est.core.status()['motion_remainder_m'] == model.config.periodic_remainder_rms_m


def test_a_saved_state_keeps_the_remainder_it_chose():
    """save/restore: the state carries its model's remainder, and continues to the bit."""
    rec = _record(0.0)
    core = _estimator(rec).core
    y = rec.current_a
    cut = 6000
    core.estimate(y[:cut])
    saved = core.get_state()
    assert saved['remainder_m'] == pytest.approx(SETTING_M / 16)
    tail = core.estimate(y[cut:]).deflection_m
    fresh = _estimator(rec).core             # a new estimator, at the setting's remainder
    fresh.set_state(saved)
    assert fresh.model.config.periodic_remainder_rms_m == saved['remainder_m']
    assert np.array_equal(fresh.estimate(y[cut:]).deflection_m, tail)
