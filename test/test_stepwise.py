# SPDX-License-Identifier: Apache-2.0
"""
Stepwise discovery (issue 15): several missing effects at once, the offset, mains hum.

Effect parameters in ``fit``, the model file and implausible magnitudes.

The campaigns are smaller than the bench's (slim + short, 5 frequencies 1-20 Hz, 4 s each,
1 % noise) to keep CI short; each multi-effect combination is run for ONE seed here
(``bench/bench_discovery.py`` runs 10 seeds per combination).  Hidden values are drawn
by ``random_effect_values`` (seeded), never chosen to suit the tool.
"""
import numpy as np
import pytest

from ipmc_sensor_ros.physics.modelfile import load_model, save_model
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import PAPER_SAMPLES, ParameterError
from ipmc_sensor_ros.workbench.adequacy import magnitude_flags
from ipmc_sensor_ros.workbench.diagnose import diagnose
from ipmc_sensor_ros.workbench.discovery.residual import mains_lines
from ipmc_sensor_ros.workbench.freqfit import FitGroup, fit_parameters
from ipmc_sensor_ros.workbench.freqresp import fundamental_response
from ipmc_sensor_ros.workbench.scenarios import crank_slider_campaign, hidden_effects_campaign

SMALL = dict(frequencies_hz=tuple(np.geomspace(1.0, 20.0, 5)), duration_s=4.0)
#: "within 1.2x the noise floor" (issue target); the floor itself is estimated from
#: ~60k samples, its scatter is well below 1 %
FLOOR_FACTOR = 1.2


@pytest.mark.parametrize('hidden,seed', [
    (('surface_resistance', 'amplifier_bandwidth'), 1),
    (('surface_resistance', 'time_delay', 'current_offset'), 2),
])
def test_several_hidden_effects_are_all_named(hidden, seed):
    recs, truth = hidden_effects_campaign(hidden, seed, **SMALL)
    diag = diagnose(recs)
    assert set(diag.missing_effects) == set(hidden), diag.summary()
    assert diag.explained, diag.summary()
    assert diag.final.error <= FLOOR_FACTOR * diag.noise_floor, diag.summary()
    js = diag.to_json()
    assert js['verdict']['missing_effects'] == diag.missing_effects
    assert js['verdict']['missing_effect'] == diag.missing_effects[0]
    # the held-out error falls at every step the search added (the offset is added and kept by
    # its own test: the held-out error cannot see a mean current beside the dynamics)
    errs = [diag.baseline.error] + [s.error for s in diag.steps
                                    if s.action == 'added' and s.effect != 'current_offset']
    assert all(b < a for a, b in zip(errs, errs[1:])), diag.summary()
    # fitted values of the effects carry their truth (10 %: 1 % noise over ~60k samples
    # determines them far better; the bound allows for the correlation with the material)
    final_values = diag.steps[-1].values
    for name, values in truth.items():
        for par, v in values.items():
            if name == 'current_offset' and par == 'drift_a_per_s':
                continue    # a drift of +-2e-8 A/s over 4 s is below the noise
            assert final_values[name][par] == pytest.approx(v, rel=0.1), (
                name,
                par,
                diag.summary(),
            )


def test_exchange_pass_replaces_an_early_stand_in_when_the_budget_is_spent():
    """
    From H1 with an offset, a 50 Hz amplifier pole and surface resistance missing.

    The first search step takes a 5 ms delay (it mimics the pole's and the diffusion's phase
    together), the offset and surface resistance fill the budget of 3, and the error stays 4.6x
    the floor.  The exchange pass then tries each chosen effect against every one not in the
    model and puts the pole in the delay's place: the right set, at the floor.
    """
    hidden = ('surface_resistance', 'amplifier_bandwidth', 'current_offset')
    recs, _ = hidden_effects_campaign(hidden, 6, **SMALL)
    diag = diagnose(recs)
    assert set(diag.missing_effects) == set(hidden), diag.summary()
    assert diag.final.error <= FLOOR_FACTOR * diag.noise_floor, diag.summary()
    swaps = [s for s in diag.steps if s.action == 'swapped' and 'exchange pass' in s.reason]
    assert [s.effect for s in swaps] == ['amplifier_bandwidth'], diag.summary()
    assert 'replaces time_delay' in swaps[0].reason


def test_an_amplifier_pole_beside_a_delay_is_named_near_the_floor():
    """
    A ~200 Hz amplifier pole and a 1 ms delay (full campaign, seed 4 of the seed study).

    The delay absorbs the pole's phase: with the delay alone the held-out error is 2.2 % over
    the floor, so the old rule (stop within 5 %, a step must gain 3 %) named the delay alone.
    A step now needs only half the excess over the floor when that is less than 3 %, and the
    search stops within 1 %: the pole is named, by a gain under 3 % that the BIC (>= 20)
    backs.
    """
    hidden = ('amplifier_bandwidth', 'time_delay')
    recs, _ = hidden_effects_campaign(hidden, 4)
    diag = diagnose(recs)
    assert set(diag.missing_effects) == set(hidden), diag.summary()
    assert diag.final.error <= FLOOR_FACTOR * diag.noise_floor, diag.summary()
    added = [s for s in diag.steps if s.action == 'added']
    errors = [diag.baseline.error] + [s.error for s in added]
    gains = [1 - b / a for a, b in zip(errors, errors[1:])]
    assert min(gains) < 0.03, diag.summary()      # the step the old 3 % rule refused


def test_exchange_pass_runs_above_the_floor_even_when_explained():
    """
    A 3.3 ms delay and beam inertia at 23 Hz (full campaign, seed 7 of the seed study).

    The first step takes a 44 Hz amplifier pole (it mimics the delay's phase and the beam's
    droop), the second a 0.3 ms delay: 1.14x the floor, under the 'explained' threshold
    (1.15x), where the exchange pass used not to run.  It now runs above the stop band and
    puts beam inertia in the pole's place; both values land on their truth.
    """
    hidden = ('time_delay', 'beam_inertia')
    recs, truth = hidden_effects_campaign(hidden, 7)
    diag = diagnose(recs)
    assert set(diag.missing_effects) == set(hidden), diag.summary()
    assert diag.final.error <= FLOOR_FACTOR * diag.noise_floor, diag.summary()
    swaps = [s for s in diag.steps if s.action == 'swapped' and 'exchange pass' in s.reason]
    assert [s.effect for s in swaps] == ['beam_inertia'], diag.summary()
    values = diag.steps[-1].values
    # 5 %: 1 % noise over 16 records pins them far better (fitted 3.344 ms, 22.94 Hz)
    assert values['time_delay']['delay_s'] == pytest.approx(
        truth['time_delay']['delay_s'], rel=0.05)
    assert values['beam_inertia']['natural_frequency_hz'] == pytest.approx(
        truth['beam_inertia']['natural_frequency_hz'], rel=0.05)


def test_lab_like_data_offset_named_amplifier_not_delay_hum_reported():
    """H2 x 200 Hz amplifier, 15 nA offset, 3 % hum at 50 Hz, 2 % noise (the issue's lab case)."""
    recs = crank_slider_campaign(
        (
            'surface_resistance',
            ('amplifier_bandwidth', {'corner_hz': 200.0}),
            ('current_offset', {'offset_a': 15e-9}),
        ),
        noise_rel=0.02,
        hum_rel=0.03,
        seed=5,
        **SMALL,
    )
    diag = diagnose(recs)
    assert diag.missing_effects[0] == 'current_offset', diag.summary()
    assert 'amplifier_bandwidth' in diag.missing_effects, diag.summary()
    # the look-alike may be reported as a tie, but never named instead of the amplifier
    assert 'time_delay' not in diag.missing_effects, diag.summary()
    lines = {round(d['frequency_hz']): d for d in diag.to_json()['interference']}
    assert 50 in lines, diag.summary()
    # level: 80 % of the 3 % hum power at 50 Hz -> RMS 0.027 of the clean current's RMS
    # (relative to the noisy current, a little less); 25 % tolerance for the estimate
    assert lines[50]['level'] == pytest.approx(0.03 * np.sqrt(0.8), rel=0.25)
    assert diag.explained and diag.final.error <= FLOOR_FACTOR * diag.noise_floor, diag.summary()


def test_nothing_missing_names_nothing_and_finds_no_hum():
    recs = crank_slider_campaign(('surface_resistance',), seed=21, **SMALL)
    diag = diagnose(recs)
    assert diag.missing_effects == [] and diag.explained, diag.summary()
    assert diag.to_json()['interference'] == []


def test_mains_lines_are_found_at_their_level_and_only_when_present():
    clean = crank_slider_campaign(('surface_resistance',), seed=3, **SMALL)
    hum = crank_slider_campaign(
        ('surface_resistance',), seed=3, hum_rel=0.05, hum_hz=60.0, **SMALL
    )
    assert mains_lines(clean, 'auto')[0] == []
    lines = mains_lines(hum, 'auto')[0]
    freqs = {ln.nominal_hz for ln in lines}
    assert {60.0, 180.0} <= freqs and not freqs & {50.0, 150.0}
    f60 = [ln.level for ln in lines if ln.nominal_hz == 60.0]
    assert np.median(f60) == pytest.approx(0.05 * np.sqrt(0.8), rel=0.2)


def test_mains_lines_off_the_nominal_frequency_are_measured_and_removed():
    # The grid runs at 50 +- 0.2 Hz; on 20 s records a 50.2 Hz hum is 4 resolution cells
    # from 50 Hz, where a fixed regressor sees only its beat.  The fundamental is measured
    # per record on a grid of 1/8 cell (0.004 Hz here), so to half a step; harmonic m to m
    # times that (a tenth of a cell, 0.005 Hz, per harmonic allowed).  The lines are removed:
    # what the cleaned records still show is under a tenth of the hum's level (the residual
    # frequency error, ~1e-3 Hz after interpolation, leaves a few % of a line at 150 Hz; the
    # 1 % noise is 10x larger).
    kw = dict(frequencies_hz=(2.0, 7.0), duration_s=20.0)
    hum = crank_slider_campaign(('surface_resistance',), seed=3, hum_rel=0.05, hum_hz=50.2, **kw)
    lines, cleaned, _ = mains_lines(hum, 'auto')
    assert {ln.nominal_hz for ln in lines} >= {50.0, 150.0}
    for ln in lines:
        m = round(ln.nominal_hz / 50.0)
        assert ln.frequency_hz == pytest.approx(m * 50.2, abs=m * 0.005)
    f50 = [ln.level for ln in lines if ln.nominal_hz == 50.0]
    assert np.median(f50) == pytest.approx(0.05 * np.sqrt(0.8), rel=0.2)
    left = [ln.level for ln in mains_lines(cleaned, 'auto')[0]]
    assert max(left, default=0.0) < 0.1 * min(f50)


def _groups(recs):
    groups = {}
    for r in recs:
        g = groups.setdefault(r.sample, FitGroup(r.model.geometry, [], {}, r.sample))
        g.points.append(fundamental_response(r.time_s, r.deflection_m, r.current_a))
    return list(groups.values())


def test_fit_frees_effect_parameters_and_judges_adequacy():
    recs = crank_slider_campaign(
        ('surface_resistance', ('time_delay', {'delay_s': 2e-3})), seed=4, **SMALL
    )
    groups = _groups(recs)
    res = fit_parameters(
        groups,
        ('charge_stress_coupling_j_per_c', 'diffusivity_m2_per_s', 'delay_s'),
        effects=('surface_resistance', 'time_delay'),
    )
    lo, hi = res.ci95['time_delay.delay_s']
    assert lo <= 2e-3 <= hi and hi - lo < 2e-4
    assert res.adequate and 'model adequate' in res.summary()
    without = fit_parameters(groups, ('charge_stress_coupling_j_per_c', 'diffusivity_m2_per_s'))
    assert not without.adequate and 'model inadequate' in without.summary()
    assert 'run diagnose' in without.summary()
    with pytest.raises(ParameterError, match='add it with --effects time_delay'):
        fit_parameters(groups, ('delay_s',))


def test_model_file_round_trip_and_errors(tmp_path):
    geom = PAPER_SAMPLES['slim']
    model = SensorModel(
        geom, effects=('surface_resistance', ('amplifier_bandwidth', {'corner_hz': 123.0}))
    )
    path = save_model(tmp_path / 'm.yaml', model, tool='test', data_files=['a.csv'],
                      error={'held_out': 0.01}, ci95={'d': (1.0, 2.0)})
    back = load_model(path)
    assert back.sensor_model(geom) == model
    assert back.provenance['data_files'] == ['a.csv'] and back.provenance['ci95']['d'] == [
        1.0,
        2.0,
    ]
    bad = tmp_path / 'bad.yaml'
    bad.write_text(path.read_text().replace('corner_hz', 'corner_khz'))
    with pytest.raises(ParameterError, match=r"bad\.yaml:9: effects: .*'corner_khz'.*did you mean "
                                             r"'corner_hz'"):
        load_model(bad)


def test_unit_errors_are_flagged_with_their_factor():
    recs = crank_slider_campaign(
        ('surface_resistance',), seed=6, frequencies_hz=(5.0,), duration_s=3.0
    )
    r = recs[0]
    mm = [type(r)(r.path, r.sample, r.model, r.time_s, r.deflection_m * 1e3, r.current_a)]
    ua = [type(r)(r.path, r.sample, r.model, r.time_s, r.deflection_m, r.current_a * 1e6)]
    assert magnitude_flags(recs) == []
    assert 'multiply by 0.001' in magnitude_flags(mm)[0]
    flag = magnitude_flags(ua)[0]
    assert 'current' in flag and ('1e-06' in flag or '0.001' in flag)


def test_hydration_relaxation_shape_limits():
    from ipmc_sensor_ros.physics.catalog import diffusivity_ratio_function

    t = np.array([0.0, 1.0, 600.0, 1e6])
    plain = diffusivity_ratio_function({'diffusivity_rate_per_s': -1e-3, 'equilibrium_ratio': 0.0})
    assert plain(t) == pytest.approx(np.exp(-1e-3 * t))           # q = 0: the old exponential
    relax = diffusivity_ratio_function({'diffusivity_rate_per_s': -1e-3, 'equilibrium_ratio': 0.6})
    assert relax(0.0) == 1.0 and relax(1e6) == pytest.approx(
        0.6
    )  # starts at d0, levels off at q d0
    # initial relative rate r_d (forward difference over 10 ms: curvature error ~1e-5 relative)
    assert (relax(0.01) - 1.0) / 0.01 == pytest.approx(-1e-3, rel=1e-4)


def test_priors_from_headers_and_their_errors():
    from types import SimpleNamespace

    from ipmc_sensor_ros.workbench.diagnose import priors_from_headers

    ts = [SimpleNamespace(path='a.csv', extra={'amplifier_bandwidth_hz': '200', 'operator': 'x'}),
          SimpleNamespace(path='b.csv', extra={'time_delay.delay_s': '0.001'})]
    assert priors_from_headers(ts) == {('amplifier_bandwidth', 'corner_hz'): 200.0,
                                       ('time_delay', 'delay_s'): 0.001}
    with pytest.raises(ValueError, match="c.csv: header key 'amplifier_bandwidth_hz'"):
        priors_from_headers(
            [SimpleNamespace(path='c.csv', extra={'amplifier_bandwidth_hz': 'fast'})]
        )


def test_effect_given_without_values_is_fitted_in_the_baseline():
    """The issue's trap: '--effects amplifier_bandwidth' must fit corner_hz, not use 200 Hz."""
    recs = crank_slider_campaign(
        ('surface_resistance', ('amplifier_bandwidth', {'corner_hz': 25.0})),
        model_effects=('surface_resistance', 'amplifier_bandwidth'),
        seed=8,
        **SMALL,
    )
    diag = diagnose(recs, fit_effects=['amplifier_bandwidth'])
    assert diag.missing_effects == [] and diag.explained, diag.summary()
    # 1 % noise pins a 25 Hz corner to well under 5 % (its phase lag at 20 Hz is 0.7 rad)
    assert diag.baseline.params['amplifier_bandwidth.corner_hz'] == pytest.approx(25.0, rel=0.05)


def _study_cases():
    from bench.seed_study import LOOKALIKE, PAIRS, TRIPLES

    return ([('null', (), 20)] + [('pairs', h, 10) for h in PAIRS]
            + [('triples', h, 10) for h in TRIPLES] + [('lookalike', h, 10) for h in LOOKALIKE])


@pytest.mark.slow
@pytest.mark.parametrize('group,hidden,n_seeds', _study_cases())
def test_seed_study_hit_rate(group, hidden, n_seeds):
    """
    Issue 15 targets on the full campaign (16 records, 1 % noise), 10 seeds per combination.

    Nothing missing: nothing named in 20/20; otherwise the target (right set within 1.2x the
    floor, or for look-alikes the true one or a tie) in >= 9 of 10 seeds.  Minutes per
    combination: run with ``-m slow`` (``bench/seed_study.py`` writes the same as a table).
    """
    from bench.seed_study import campaign_kwargs, judge

    ok = []
    for seed in range(n_seeds):
        recs, _ = hidden_effects_campaign(hidden, seed, **campaign_kwargs(hidden))
        ok.append(judge(group, hidden, diagnose(recs)))
    need = n_seeds if group == 'null' else n_seeds - 1
    assert sum(ok) >= need, (group, hidden, ok)
