# SPDX-License-Identifier: Apache-2.0
"""
Hidden-effect tests of the missing-physics discovery (issue: discovery).

Each test simulates a crank-slider sweep (slim and short samples, 8 frequencies
1-20 Hz, 6 s each, 1 % noise) or long records from H2 plus one hidden effect with
seeded random parameters drawn in the effect's detectable range, then diagnoses
it starting from plain H2.  Two hidden effects rest on physics rather than on the
effect's own formula: hydration_drift (field solution with a drifting diffusivity)
and nonlinearity (field solution with the large-deflection elastica beam).
"""
from pathlib import Path

import numpy as np
import pytest

from ipmc_sensor_ros.physics.effects import EFFECTS, load_plugin
from ipmc_sensor_ros.workbench.diagnose import diagnose
from ipmc_sensor_ros.workbench.scenarios import crank_slider_campaign, random_effect_values

PLUGIN = Path(__file__).resolve().parents[1] / 'examples' / 'polymer_leakage.py'
CATALOG = [n for n in ('amplifier_bandwidth', 'time_delay', 'current_offset', 'hydration_drift',
                       'effective_length', 'beam_inertia', 'nonlinearity')]

#: Crank radius of the large-deflection campaign: 4 mm, i.e. w/L up to 0.18 (slim, 22 mm)
#: and 0.36 (short, 11 mm); the paper's 2 mm gives too little distortion to see in 1 % noise.
LARGE_CRANK_RADIUS_M = 4e-3


def campaign(hidden, seed):
    kwargs = {}
    if hidden and hidden[0] == 'hydration_drift':
        # the drift needs long records: 4 records of 120 s (2 samples x 2 frequencies), and
        # the data come from the independent field solution with d(t) drifting (physics
        # ground truth, not the effect's own quasi-static formula)
        kwargs = dict(frequencies_hz=(3.0, 7.0), duration_s=120.0, fidelity='field')
    if hidden and hidden[0] == 'nonlinearity':
        # physics ground truth: the data come from the field solution with the
        # large-deflection (elastica) stress profile, and contain no 'nonlinearity'
        # effect (nor its parameters) at all; the catalog's polynomial must stand in for it
        return crank_slider_campaign(('surface_resistance',), seed=seed, fidelity='field',
                                     beam_model='elastica', crank_radius_m=LARGE_CRANK_RADIUS_M)
    effects = ('surface_resistance',) + ((hidden,) if hidden else ())
    return crank_slider_campaign(effects, seed=seed, **kwargs)


@pytest.mark.parametrize('name', CATALOG)
def test_hidden_effect_ranks_first_and_error_falls(name):
    rng = np.random.default_rng(1000 + CATALOG.index(name))
    values = random_effect_values(name, rng)
    diag = diagnose(campaign((name, values), seed=CATALOG.index(name)))
    # stepwise: exactly the hidden effect is named (a mean current is named by the direct
    # offset test before any ranking, so the first ranking need not contain it)
    assert diag.missing_effects == [name], diag.summary()
    assert diag.missing_effect == name, diag.summary()
    if name != 'current_offset':
        assert diag.candidates[0].effect == name, diag.summary()
    # one row per effect: an effect tried in two shapes (hydration_drift) is ranked once, the
    # shapes that were not cross-validated too
    names = [c.effect for c in diag.candidates]
    assert len(names) == len(set(names)), diag.summary()
    best = diag.final
    # "falls at least 3x or to the noise floor": noise floor within 20 % (finite-sample scatter
    # of a 1 % noise estimate over ~90k samples is far below that)
    assert (diag.baseline.error / best.error >= 3.0) or (
        best.error <= 1.2 * diag.noise_floor
    ), diag.summary()
    assert diag.explained
    if name == 'nonlinearity':
        # the polynomial stand-in takes the elastica's physical values: no even term (the
        # beam bends alike both ways) and a_3 ~ 0.2 -- the tip angle's 1 + 0.21 (w/L)^2
        # (test_beam: +1.9 % at w/L = 0.3); bounds allow the fit's scatter and the
        # surface-resistance weighting of the curvature profile
        assert abs(best.params['quadratic']) < 0.05, diag.summary()
        assert 0.15 < best.params['cubic'] < 0.3, diag.summary()


def test_surface_resistance_is_found_missing_from_h1():
    """The paper's own step (section 5.3.1): data from H2, model H1."""
    records = crank_slider_campaign(('surface_resistance',), seed=11, model_effects=())
    diag = diagnose(records)
    assert diag.missing_effect == 'surface_resistance' and diag.explained, diag.summary()
    assert diag.baseline.error / diag.candidates[0].error >= 3.0


def test_no_false_alarm_on_data_the_model_explains():
    diag = diagnose(campaign(None, seed=42))
    assert diag.missing_effect is None and diag.explained, diag.summary()
    assert diag.baseline.error <= 1.2 * diag.noise_floor


@pytest.fixture
def plugin_unloaded():
    yield
    EFFECTS.pop('polymer_leakage', None)


def test_effect_outside_catalog_is_unexplained_until_given_as_plugin(plugin_unloaded):
    load_plugin(PLUGIN)
    records = campaign(('polymer_leakage', {'time_constant_s': 0.05}), seed=7)
    EFFECTS.pop('polymer_leakage')
    without = diagnose(records)
    assert without.explained is False, without.summary()
    load_plugin(PLUGIN)
    with_plugin = diagnose(records)
    assert with_plugin.missing_effect == 'polymer_leakage', with_plugin.summary()
    assert with_plugin.explained
    assert with_plugin.candidates[0].params['time_constant_s'] == pytest.approx(0.05, rel=0.05)


def test_diagnosis_json_contract():
    diag = diagnose(campaign(('time_delay', {'delay_s': 2e-3}), seed=3),
                    candidates=['time_delay', 'amplifier_bandwidth'])
    js = diag.to_json()
    assert js['baseline']['error'] > 0
    assert [c['effect'] for c in js['candidates']][0] == 'time_delay'
    for c in js['candidates']:
        assert {'effect', 'error', 'params'} <= set(c)
    assert js['verdict']['missing_effect'] == 'time_delay'
    assert js['verdict']['explained'] is True
