# SPDX-License-Identifier: Apache-2.0
"""
A jump of the offset in a motion, found at the hold after it, moves the level by its lag.

estimation/jump_time.py: the rest test finds the jump only at the hold; while the sensor
moved, the jump was read as a ramp of the tip (J / R_n(0) a second).  The motion's own
current says when it happened (the likelihood of a jump at every sample of it, with the
size the hold measured), and the level the hold starts from moves by the jump times its
expected lag, its std keeping the lag's spread.  Records from ``bench.scenarios`` (exact H2
by FFT with a pre-roll, a DAQ offset step, noise, 16-bit quantisation): generated
independently of the estimator's code.
"""
from __future__ import annotations

import numpy as np
import pytest

from bench.bench_estimators import _causal
from bench.scenarios.daq import Daq
from bench.scenarios.library import MM, NA, Scenario
from bench.scenarios.motions import MinJerkPath, Sines, Sum, Windowed
from bench.scenarios.sensor import Sensor
from ipmc_sensor_ros.estimation.config import EstimatorConfig
from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import Geometry

MOTION_S = (1.0, 8.0)           # two slow sines, then a move to a hold at 0.4 mm
JUMP_S = 3.5


def _record(step_a: float):
    """slim, two slow sines 1-8 s then a hold; the offset steps by ``step_a`` at 3.5 s."""
    def make(rng):
        sines = Windowed(Sines((0.7, 1.9), (0.5 * MM, 0.3 * MM), (0.3, 1.1)), *MOTION_S, 0.5)
        motion = Sum((sines, MinJerkPath((MOTION_S[1] - 1.0,), (1.5,), (0.0, 0.4 * MM))))
        daq = Daq(offset_a=6 * NA, noise_a=0.3 * NA, adc_bits=16,
                  offset_steps=((JUMP_S, step_a),))
        return Sensor('slim'), motion, daq
    return Scenario('motion-jump', 'daq', 14.0, make, '').build(0)


def _hold_errors(step_a: float, **config):
    """Return (median error, median std) over the hold's last 3 s, m, and the status."""
    rec = _record(step_a)
    model = SensorModel.named(rec.model, Geometry(*rec.geometry_m, rec.sample),
                              extra_effects=rec.effects)
    est = DeflectionEstimator(model, rec.sample_rate_hz, config=EstimatorConfig(**config))
    out = _causal(rec, est, 1000)
    keep = rec.sample_time_s[out.row_index] > 11.0
    err = out.deflection_m[keep] - rec.deflection_m[out.row_index[keep]]
    return float(np.median(err)), float(np.median(out.std_m[keep])), est.core.status()


@pytest.mark.parametrize('step_a', [15 * NA, -25 * NA])
def test_a_jump_in_a_motion_moves_the_level_the_hold_starts_from(step_a):
    """
    The level after the hold is the jump's ramp less its expected lag, within its std.

    Without the lag (``jump_search_s`` 0: no motion kept) the level is off by the ramp the
    filter read from the jump, J / R_n(0) a second from 3.5 s until the hold's rest (measured
    423 um at 15 nA, 148 um at 9.25 nA on drawn record 187) at a std of ~12 um.  At 15-25 nA
    over 0.3 nA of noise the motion's current places the jump within a fraction of the
    motion (drawn record 247, 23 nA: lag 5.88 +- 0.70 s against 6.1 s true): measured here
    31 and 113 um left of 423 and 392 um (0.07 and 0.29 of it; the -25 nA jump's lag is
    the less certain), so at most a third is allowed; the published std covers what is
    left (2 sigma: the lag's spread is in it; 94 and 169 um here).
    """
    level, std, status = _hold_errors(step_a)
    assert status['offset_jumps'] >= 1
    ramp, ramp_std, _ = _hold_errors(step_a, jump_search_s=0.0)
    assert abs(ramp) > 3 * ramp_std                 # the ramp alone: off, and not covered
    assert abs(level) < abs(ramp) / 3
    assert abs(level) < 2 * std


def test_the_motion_kept_is_saved_and_restored_with_the_state():
    """Saved mid-motion and restored, an estimator continues to the bit through the jump."""
    rec = _record(15 * NA)
    model = SensorModel.named(rec.model, Geometry(*rec.geometry_m, rec.sample),
                              extra_effects=rec.effects)
    first, second = (DeflectionEstimator(model, rec.sample_rate_hz).core for _ in range(2))
    cut = int(6.0 * rec.sample_rate_hz)             # moving, the jump in the motion kept
    first.estimate(rec.current_a[:cut])
    assert first.get_state()['moving'] is not None
    second.set_state(first.get_state())
    a, b = (est.estimate(rec.current_a[cut:]) for est in (first, second))
    assert first.status()['offset_jumps'] >= 1
    np.testing.assert_array_equal(a.deflection_m, b.deflection_m)
    np.testing.assert_array_equal(a.std_m, b.std_m)
