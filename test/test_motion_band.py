# SPDX-License-Identifier: Apache-2.0
"""
The broad motion prior's upper corner chosen by likelihood (estimation/motion_band.py).

Records drawn by the bench's own generator (exact H2 by FFT, DAQ habits; no package code).
"""
import numpy as np
import pytest

from bench.bench_estimators import _causal, estimate_scores
from bench.scenarios.drawn import draw
from ipmc_sensor_ros.estimation.config import EstimatorConfig
from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator
from ipmc_sensor_ros.estimation.motion_band import band_choices_hz
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import Geometry


def _estimator(rec):
    model = SensorModel.named(rec.model, Geometry(*rec.geometry_m, rec.sample),
                              extra_effects=rec.effects)
    return DeflectionEstimator(model, rec.sample_rate_hz)


def test_the_corners_tried_are_the_setting_and_its_fractions_above_the_lower_corner():
    """A half and a quarter of the setting, none at or below ``motion_corner_hz``."""
    assert band_choices_hz(EstimatorConfig()) == [50.0, 25.0, 12.5]
    assert band_choices_hz(EstimatorConfig(motion_corner_hz=20.0)) == [50.0, 25.0]


def test_two_slow_sines_and_a_hold_take_a_narrow_prior():
    """
    Drawn record 5 (two sines at 1.7-10.5 s, then a hold; 0.37 nA of noise, host jitter).

    With the 50 Hz upper corner the prior expects jerks the sines never have, the filter
    follows the noise and the hold's level is 5.4 um off: 1.06 % NRMSE (limit 1 %).  The
    likelihood takes a quarter of it (12.5 Hz) at the first check with the noise measured:
    0.11 % (limit 0.5 %, between the two).
    """
    rec, _ = draw(5, 20.0)
    est = _estimator(rec)
    assert estimate_scores(rec, _causal(rec, est, 1000))['nrmse'] < 0.005
    assert est.core.status()['motion_bandwidth_hz'] == 12.5


def test_a_crank_under_a_narrow_prior_is_still_found_and_modelled():
    """
    Drawn record 13 (a 6.95 Hz crank from rest, 12 bits): 1.43 % with the 50 Hz corner.

    The likelihood prefers 12.5 Hz on its first second of motion (its harmonics are
    small); a periodic motion searched up to half that corner (6.25 Hz) was never found
    and the record read 6.5 %.  The search runs to half the setting (limit 2 %, between
    the two; 1.08 % before the periodic phasors' rates were states: the ADC's step, not
    the search, keeps it above 1 %).
    """
    rec, _ = draw(13, 20.0)
    est = _estimator(rec)
    assert estimate_scores(rec, _causal(rec, est, 1000))['nrmse'] < 0.02
    assert est.core.status()['motion_hz'] == pytest.approx(6.95, abs=0.05)


def test_a_chosen_corner_is_saved_and_restored_with_the_state():
    """A restored estimator runs the corner it had chosen, to the bit."""
    rec, _ = draw(5, 20.0)
    y, cut = rec.current_a[:6000], 3000
    whole = _estimator(rec).core
    expected = whole.estimate(y).deflection_m
    first = _estimator(rec).core
    head = first.estimate(y[:cut]).deflection_m
    saved = first.get_state()
    assert saved['bandwidth_hz'] == 12.5            # chosen at the check at 2 s
    restored = _estimator(rec).core
    restored.set_state(saved)
    assert restored.model.config.motion_bandwidth_hz == pytest.approx(12.5)
    tail = restored.estimate(y[cut:]).deflection_m
    assert np.array_equal(np.concatenate([head, tail]), expected)


def test_a_stretch_spent_still_is_not_filtered_again(monkeypatch):
    """
    Record 5's hold (from 10.5 s): the rest measurement holds the tip, so no corner is tried.

    Every check in the sines tries the two other corners (two runs each); those in the
    hold, from 12 s (a stretch wholly still), try none: on the hold's eight checks the
    choice had cost sixteen runs of a second each.
    """
    import ipmc_sensor_ros.estimation.motion_band as motion_band
    rec, _ = draw(5, 20.0)
    n = int(12.0 * rec.sample_rate_hz)
    runs = []
    refilter = motion_band.refilter
    monkeypatch.setattr(motion_band, 'refilter',
                        lambda span, filt: runs.append(len(span.y)) or refilter(span, filt))
    core = _estimator(rec).core
    core.estimate(rec.current_a[:n])
    assert len(runs) >= 2                           # the sines' checks tried the corners
    del runs[:]
    core.estimate(rec.current_a[n:])
    assert runs == []
    assert core.status()['at_rest']
