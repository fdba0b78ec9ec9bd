# SPDX-License-Identifier: Apache-2.0
"""Line measurements of the estimator (estimation/lines.py): their edge cases."""
import numpy as np
import pytest

from bench.bench_estimators import _causal, estimate_scores
from bench.scenarios import build
from bench.scenarios.drawn import draw
from ipmc_sensor_ros.estimation.config import EstimatorConfig
from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator
from ipmc_sensor_ros.estimation.lines import Line, measure_line, vertex
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import Geometry

#: the default settings: line walk 1 nA/sqrt(s), false alarm 1e-6 (new line beyond 4.9 sigma)
CFG = EstimatorConfig()
FA = CFG.false_alarm


def test_the_vertex_stays_within_half_a_bin_on_a_flank():
    """
    The largest bin inside a range whose outer neighbour is larger still (a flank).

    The parabola through (1, 4, 6.9) peaks 29.5 bins away; the vertex is clipped to half a
    bin (a quantised DAQ at rest gave such a flank, and the peak index fell off the array).
    """
    summed = np.array([0.0, 1.0, 4.0, 6.9])
    assert vertex(np.arange(4), summed, 2) == 2.5
    assert vertex(np.arange(4), np.array([0.0, 3.0, 4.0, 3.0]), 2) == 2.0


def test_a_quantised_still_record_has_no_line():
    """A 16-bit DAQ reading a still sensor: a few codes of noise, no hum, no line."""
    lsb = 20e-6 / 2 ** 16
    rng = np.random.default_rng(0)
    codes = np.round(0.4 * rng.standard_normal(4000))
    assert measure_line(codes * lsb, 1000.0) == Line()


def test_the_flank_of_a_motion_line_beside_the_search_range_is_no_line():
    """
    A 24.3 Hz crank's second harmonic, 1.4 Hz below the 50 Hz search range, is no mains line.

    In one second its main lobe (+-2 Hz) rises across the range; its largest bin inside was
    taken for a 1.2 uA line at 49.515 Hz, known to 1 mHz, with or without a weak line at
    50.28 Hz that a 1 s window cannot tell from it.  Only a peak within a resolution bin is a
    line.
    """
    t = np.arange(500) / 500.0
    rng = np.random.default_rng(1)
    for weak_a in (0.0, 20e-9):
        x = (2e-6 * np.sin(2 * np.pi * 48.64 * t) + weak_a * np.sin(2 * np.pi * 50.28 * t + 1)
             + rng.normal(0, 2e-9, t.size))
        assert measure_line(x, 500.0) == Line()


def test_a_line_beside_a_crank_harmonic_is_modelled_only_where_it_is_likelier():
    """
    A measured line frequency is a candidate: its states take over if the stretch is likelier.

    Drawn record 101: a 24.3 Hz crank from rest at 500 Hz, its second harmonic 1.6 Hz
    below a 0.7 % hum at 50.28 Hz.  The first second's window (the spin-up) measured
    49.85 Hz; taken over unasked, that line's model refiltered the rest at the start without
    finding it, and the level stayed 17 um off (1.15 % NRMSE against a bound of 0.015 %;
    now 0.56 %, limit the issue's 1 %).
    """
    rec, _ = draw(101)
    model = SensorModel.named(rec.model, Geometry(*rec.geometry_m, rec.sample),
                              extra_effects=rec.effects)
    est = DeflectionEstimator(model, rec.sample_rate_hz)
    assert estimate_scores(rec, _causal(rec, est, 1000))['nrmse'] < 0.01
    assert est.core.status()['mains_line_hz'] == pytest.approx(rec.mains_hz, abs=0.1)


def test_measurements_of_one_line_are_joined_by_their_variances():
    """
    The joined frequency is the inverse-variance mean.

    A window that shares half its samples with the last counts half; a measurement far
    outside both is a new line.
    """
    first = Line(50.10, 1e-6, 1e-4, 1.0)            # 10 mHz each: 1.4 sigma apart
    second = Line(50.12, 1e-6, 1e-4, 1.0)
    assert first.joined(second, 0.0, FA).hz == pytest.approx(50.11)
    assert first.joined(second, 0.0, FA).hz_var == pytest.approx(5e-5)
    half = first.joined(second, 0.5, FA)         # the second counts as variance 2e-4
    assert half.hz == pytest.approx((50.10 / 1 + 50.12 / 2) / (1 / 1 + 1 / 2))
    assert first.joined(Line(), 0.0, FA) == first
    assert first.joined(Line(50.2, 1e-6, 1e-4, 1.0), 0.0, FA).hz == 50.2     # 7 sigma: a new line


def test_line_states_are_retuned_when_the_walk_cannot_follow_and_the_model_is_unlikely():
    """
    A 3 uA line 0.004 Hz off its model is retuned once the joined measurement tells it.

    Its phasors turn by 75 nA/s (walk 1 nA/sqrt(s)) and it is known to 0.2 mHz; a weak
    line, or an error within the measurements' spread, keeps the model.
    """
    strong = Line(50.1143, 3.2e-6, (2e-4) ** 2, 2 * np.pi * 3.2e-6)
    assert not strong.follows(50.1180, CFG)
    assert strong.follows(50.1145, CFG)             # within 4.9 sigma: noise
    weak = strong._replace(amplitude_a=1e-12, drift_a_per_hz=2 * np.pi * 1e-12)
    assert weak.follows(50.1180, CFG)


def test_a_strong_hum_is_modelled_at_the_frequency_its_later_windows_tell():
    """
    A strong hum is modelled at the frequency its later windows tell (slim-strong-hum, 1).

    A 3.2 uA hum at 50.1143 Hz, 0.12 uA noise, a 5 Hz crank: the first 0.5 s measured
    50.1180 Hz and the model kept it (it was within a fixed 0.02 Hz), the innovations'
    variance grew to 38 times the model's and the estimate read 0.84 %. Now the joined
    measurements retune it: within 1 mHz (the 2 s windows read it to 0.2 mHz each), and the
    estimate 0.52 % (0.49 % at the true frequency; limit 0.65 %, between the two).
    """
    rec = build('slim-strong-hum', 1)
    model = SensorModel.named(rec.model, Geometry(*rec.geometry_m, rec.sample),
                              extra_effects=rec.effects)
    est = DeflectionEstimator(model, rec.sample_rate_hz)
    assert estimate_scores(rec, _causal(rec, est, 1000))['nrmse'] < 0.0065
    assert est.core.status()['mains_line_hz'] == pytest.approx(rec.mains_hz, abs=1e-3)


def test_the_joined_line_is_saved_and_restored_with_the_state():
    """A restored estimator goes on joining the line it had, to the bit."""
    rec = build('slim-strong-hum', 1)
    model = SensorModel.named(rec.model, Geometry(*rec.geometry_m, rec.sample),
                              extra_effects=rec.effects)
    y, cut = rec.current_a[:8000], 3500
    whole = DeflectionEstimator(model, rec.sample_rate_hz).core
    expected = whole.estimate(y).deflection_m
    first = DeflectionEstimator(model, rec.sample_rate_hz).core
    head = first.estimate(y[:cut]).deflection_m
    saved = first.get_state()
    assert saved['line'][0] == pytest.approx(rec.mains_hz, abs=2e-3)     # one joined
    restored = DeflectionEstimator(model, rec.sample_rate_hz).core
    restored.set_state(saved)
    assert restored.get_state()['line'] == saved['line']
    tail = restored.estimate(y[cut:]).deflection_m
    assert np.array_equal(np.concatenate([head, tail]), expected)


def test_a_noise_free_line_has_a_small_finite_variance():
    """
    A synthetic line with no noise: the local level is the window's leakage, maybe zero.

    The frequency within 0.1 mHz of the truth (the vertex's error on 2 s), its variance
    positive and finite, plain floats (a saved state holds them).
    """
    t = np.arange(2000) / 1000.0
    line = measure_line(1e-6 * np.sin(2 * np.pi * 50.1 * t), 1000.0)
    assert line.hz == pytest.approx(50.1, abs=1e-4)
    assert 0.0 < line.hz_var < 1e-6
    assert all(type(v) is float for v in line)
