# SPDX-License-Identifier: Apache-2.0
"""
An offset that jumps (an amplifier re-zeroed) is a jump of the offset state, not a ramp.

estimation/rest.py (the jump test) and filter.py: when a window is still at a level the
filter's offset does not explain but the offset after a jump of RMS ``offset_jump_a`` does,
the run of still samples is filtered again from its first sample as rest, the offset's
variance grown by the jump's.  Records come from ``bench.scenarios`` (exact H2 by FFT with a
pre-roll, DAQ offset step, noise, 16-bit quantisation): generated independently of the
estimator's code.
"""
from __future__ import annotations

import numpy as np
import pytest

from bench.bench_estimators import _causal, estimate_scores
from bench.scenarios.daq import Daq
from bench.scenarios.drawn import draw
from bench.scenarios.library import MM, NA, Scenario
from bench.scenarios.motions import MinJerkPath
from bench.scenarios.sensor import Sensor
from ipmc_sensor_ros.estimation.config import EstimatorConfig
from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator
from ipmc_sensor_ros.estimation.mean_shift import ShiftTest
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import Geometry

JUMP_S = 3.0


def _record(step_a: float, seconds: float = 12.0, jump_s: float = JUMP_S,
            noise_a: float = 0.2 * NA):
    """slim, moves at 1, 5, 9 s (0.4 s) between holds; the offset steps at 3 s; 0.2 nA."""
    def make(rng):
        path = MinJerkPath((1.0, 5.0, 9.0), (0.4,) * 3, (0.0, 0.8 * MM, -0.5 * MM, 0.3 * MM))
        daq = Daq(offset_a=6 * NA, noise_a=noise_a, adc_bits=16,
                  offset_steps=((jump_s, step_a),))
        return Sensor('slim'), path, daq
    return Scenario('offset-jump', 'daq', seconds, make, '').build(0)


def _estimator(rec, **config):
    model = SensorModel.named(rec.model, Geometry(*rec.geometry_m, rec.sample),
                              extra_effects=rec.effects)
    return DeflectionEstimator(model, rec.sample_rate_hz, config=EstimatorConfig(**config))


@pytest.mark.parametrize('step_a', [3 * NA, -5 * NA, 20 * NA])
def test_an_offset_that_jumps_in_a_hold_is_learned_not_read_as_a_ramp(step_a):
    """
    A step of the offset at rest is learned: the level holds through it.

    Without the jump in the model the hold after the step is a steady 'motion' current:
    measured 14 um/s per 3 nA for the rest of the record (6.9-20.6 % NRMSE on the bench's
    slim-offset-step).  20 nA (100 sigma of the noise) read 51 % while the jump's samples were
    taken less lines fitted without its step (rest.py: the step leaked into the nominal 50 and
    60 Hz lines).  With it the level stays; allowed 1 % (the issue's floor, the causal
    bound of a 0.2 nA record being far below it), and the offset ends within 0.1 nA of the
    DAQ's (200 samples of 0.2 nA noise know it to 0.014 nA).
    """
    rec = _record(step_a)
    est = _estimator(rec)
    out = _causal(rec, est, 1000)
    assert out.row_index.size == rec.current_a.size
    assert estimate_scores(rec, out)['nrmse'] < 0.01
    offset_a = est.core.status()['offset_a']
    assert offset_a == pytest.approx(6 * NA + step_a, abs=0.1 * NA)
    assert est.core.status()['offset_jumps'] == 1       # counted: the node warns on it
    no_jumps = _estimator(rec, offset_jump_a=0.0)
    off = _causal(rec, no_jumps, 1000)
    assert estimate_scores(rec, off)['nrmse'] > 0.05      # the model change is what does it
    assert no_jumps.core.status()['offset_jumps'] == 0


@pytest.mark.parametrize('step_a', [3 * NA, -3 * NA])
def test_a_jump_smaller_than_one_sample_s_noise_in_a_hold_is_learned(step_a):
    """
    A step of the offset below one sample's noise, at rest, is a jump too (rest.py).

    Drawn record 85 (2 kHz, 14.7 nA of noise per sample, 12 bits) stepped by -12.5 nA in a
    hold: no sample was beyond the per-sample limit, so no jump's run began; the rest test's
    CUSUM ended the rest again and again and the steady current was read as a ramp (2.85 %
    NRMSE, 73 um off at the end; 0.31 % once the CUSUM's alarm at rest starts a run).  Here
    3 nA under 4 nA of noise (0.75 sigma per sample; the 0.2 s window's mean knows it to
    0.28 nA): before, 5.7 % (+3 nA, no jump) and 7.4 % (-3 nA, a jump taken late); now
    0.15 and 0.19 %, one jump each.  Allowed: the issue's 1 % floor, one jump, and the offset
    within 0.5 nA (the 2 s hold after the step knows it to 0.09 nA; the holds after the
    later moves add theirs).
    """
    rec = _record(step_a, noise_a=4 * NA)
    est = _estimator(rec)
    out = _causal(rec, est, 1000)
    assert estimate_scores(rec, out)['nrmse'] < 0.01
    assert est.core.status()['offset_jumps'] == 1
    assert est.core.status()['offset_a'] == pytest.approx(6 * NA + step_a, abs=0.5 * NA)


def test_a_jump_the_window_s_mean_tells_before_the_cusum_is_learned():
    """
    A step at rest that the window's level test tells first starts a jump's run too.

    Drawn record 80 (500 Hz, 2.1 nA of noise, host stamps, a 60 Hz hum at 9 % of the peak
    current): a -3.5 nA step 1.5 s into the hold after a 37 Hz free vibration.  The noise
    the filter measured there was 5.5 nA (the hum sampled off its slots), so the step was
    0.6 sigma a sample and the CUSUM slow, while the window's mean left the offset by 2.752
    nA against a limit of 2.748: the rest ended with no run begun and the hold read as a
    ramp of 10 um/s (6 % NRMSE once the line's frequency was chosen by likelihood; 0.09 %
    before by a hair's breadth the other way).  Now 0.02 %, one jump.  Allowed: the issue's
    1 %, the offset within 0.5 nA of the truth at the end.
    """
    rec, _ = draw(80)
    est = _estimator(rec)
    out = _causal(rec, est, 1000)
    assert estimate_scores(rec, out)['nrmse'] < 0.01
    assert est.core.status()['offset_jumps'] >= 1
    assert est.core.status()['offset_a'] == pytest.approx(rec.offset_a[-1], abs=0.5 * NA)


def test_a_jump_of_a_quarter_sigma_at_rest_is_told_by_its_age(monkeypatch):
    """
    A step the CUSUM and the window's mean cannot see is told once old enough (mean_shift.py).

    Drawn record 291 (2 kHz, 59 nA of noise per sample, 12 bits, a 49.8 Hz hum): +14.6 nA
    1 s into an 11 s rest, 0.25 sigma of a sample.  The CUSUM's drift is 0.5 sigma, the
    window's mean showed 4.4 sigma against a limit of 4.9: no jump, the offset followed through
    its walk and the rest's zero-velocity measurement took it into the deflection (4.6 %
    NRMSE, 43 um off at the end).  The shift statistic tells it ~0.3 s after the step: 1.54 %,
    one jump.  Allowed 2 % (what is left is the deflection taken in before it is told), and
    without the statistic (its step made to tell nothing) over 3 %: it is what does it.
    """
    rec, _ = draw(291)
    est = _estimator(rec)
    assert estimate_scores(rec, _causal(rec, est, 1000))['nrmse'] < 0.02
    assert est.core.status()['offset_jumps'] == 1
    monkeypatch.setattr(ShiftTest, 'step', lambda self, sums, z, follow: (None, False))
    assert estimate_scores(rec, _causal(rec, _estimator(rec), 1000))['nrmse'] > 0.03


def test_a_jump_just_after_a_move_before_the_rest_is_confirmed_is_learned():
    """
    A step 0.3 s after a move ends, before the rest test confirms a rest (~0.5 s after it).

    The run starts at a step out of samples that agreed with rest on their own, not only out
    of a confirmed rest: before, such a step was never taken (the hold after it is never a
    rest, so no step could come out of one): 93.6 % NRMSE here, and on slim-offset-step
    seed 5 (36.6 nA, 0.31 s after a move) 156 %, now 0.19 %.  Allowed 1 %, as above.
    (Within ~0.25 s of the move's end the current's decay is still over the noise: a step
    there is not seen, 96-97 % measured at 1.45-1.5 s.)
    """
    rec = _record(-30 * NA, jump_s=1.7)
    est = _estimator(rec)
    out = _causal(rec, est, 1000)
    assert estimate_scores(rec, out)['nrmse'] < 0.01
    assert est.core.status()['offset_a'] == pytest.approx(-24 * NA, abs=0.1 * NA)


@pytest.mark.parametrize('jump_s, step_a', [(5.45, -20 * NA), (5.1, -20 * NA), (5.25, 8 * NA)])
def test_an_offset_that_jumps_in_a_move_or_its_decay_is_learned(jump_s, step_a):
    """
    A step inside a move (5.0-5.4 s) or in its decay: the hold after it is still, elsewhere.

    Before, a run of the jump test started only out of a still stretch, so a step inside a
    motion (or in a hold before its rest was confirmed) was never taken: the hold read as a
    steady creep for the rest of the record (31.7 / 34.3 / 13.3 % NRMSE here with
    ``offset_jump_a`` 0; drawn record 77, -19.7 nA as a move ended, 57 %).  Now a run may
    start out of a motion; it is taken once it has held ``jump_hold_s``, its samples less
    the filter's lines (a window that still holds the move's current fits part of it into
    lines).  The jump is placed where the run starts, once the move's decaying current is
    within the noise, so the part of the step before is the move's and stays in the level:
    measured 2.0 / 4.2 / 1.4 %.  Allowed 5 % and a fifth of the NRMSE without jumps (the
    level error is the step times the time to the run's start, not the 1 % floor); the
    offset learned within 0.1 nA (as above).
    """
    rec = _record(step_a, jump_s=jump_s)
    est = _estimator(rec)
    nrmse = estimate_scores(rec, _causal(rec, est, 1000))['nrmse']
    without = estimate_scores(rec, _causal(rec, _estimator(rec, offset_jump_a=0.0), 1000))
    assert nrmse < 0.05 and nrmse < without['nrmse'] / 5
    assert est.core.status()['offset_a'] == pytest.approx(6 * NA + step_a, abs=0.1 * NA)
    assert est.core.status()['offset_jumps'] >= 1


@pytest.mark.parametrize('jump_s, cut_s, moving', [
    (JUMP_S, JUMP_S + 0.1, False), (5.25, 6.0, True)])
def test_blocks_single_samples_and_a_state_saved_mid_jump_agree(jump_s, cut_s, moving):
    """
    One recursion through a jump: any cut, one sample at a time, and a save/restore.

    At rest (3 s) and inside a move (5.25 s: the run starts once the move's current has
    decayed, ~5.5 s, and is taken 1 s later); the state is saved while the run is open.
    """
    rec = _record(4 * NA, seconds=jump_s + 3.0, jump_s=jump_s)
    y = rec.current_a
    block = _estimator(rec).core.estimate(y).deflection_m
    one = _estimator(rec).core
    singles = np.array([one.estimate_one(v)[0] for v in y])
    np.testing.assert_allclose(singles, block, rtol=0, atol=1e-12)
    cut = int(cut_s * rec.sample_rate_hz)       # the jump's run not yet accepted
    est = _estimator(rec).core
    first = est.estimate(y[:cut]).deflection_m
    run = est._state.jump
    assert run is not None and run.held_still and run.still is not moving
    saved = est.get_state()
    tail = est.estimate(y[cut:]).deflection_m
    est.set_state(saved)
    again = est.estimate(y[cut:]).deflection_m
    assert np.array_equal(tail, again)
    np.testing.assert_allclose(np.concatenate((first, tail)), block, rtol=0, atol=1e-12)


def test_a_slow_move_from_rest_is_not_taken_for_a_jump():
    """
    A slow move out of a rest is motion, not a jump.

    A 10 s minimum-jerk move of 0.3 mm at 0.2 nA: its current leaves the rest gently and is
    flat within the noise for ~0.6 s about its peak (12 nA).  A jump test that took a run
    out of a motion after one rest window took that for a jump and lost the move (113 %
    NRMSE, 0.3 mm off; 0.4 s still did, 0.5 s did not); such a run must hold
    ``jump_hold_s`` (1 s), so through the move the estimate is the one without jumps, to the
    bit: up to 10.9 s, after which a minimum-jerk move has 10 (0.1 / 10)^3 of its 0.3 mm
    left (3 nm).  In the hold after it a jump is taken that gives back the part of the
    offset the slow move had moved (told by the shift statistic, mean_shift.py, its run
    starting 3 ms before the move's nominal end; the level moves 3.9 um at most, NRMSE
    1.65 -> 1.28 %): allowed 5 um, far from the 300 um of a lost move, and no worse an
    NRMSE.
    """
    def make(rng):
        path = MinJerkPath((1.0,), (10.0,), (0.0, 0.3 * MM))
        return Sensor('slim'), path, Daq(offset_a=6 * NA, noise_a=0.2 * NA, adc_bits=16)
    rec = Scenario('creep', 'daq', 14.0, make, '').build(0)
    with_jumps = _causal(rec, _estimator(rec), 1000)
    without = _causal(rec, _estimator(rec, offset_jump_a=0.0), 1000)
    moving = rec.sample_time_s[with_jumps.row_index] < 10.9
    a, b = with_jumps.deflection_m, without.deflection_m
    assert np.array_equal(a[moving], b[moving])
    assert np.max(np.abs(a - b)) < 5e-6
    assert estimate_scores(rec, with_jumps)['nrmse'] <= estimate_scores(rec, without)['nrmse']


def test_the_smoothers_pass_back_across_a_jump_as_a_jump():
    """
    The smoothed level holds through a jump as the live one does.

    The smoothers' link across a jump is new = old + a jump of the offset (the state before
    the jump's variance was added: onset.restart), so the offset learned after the jump is
    not carried back into the hold before it.  Linked to the state with the jump's variance,
    the offline smoothed NRMSE on slim-offset-step read 2.7-8.5 % beside a live 0.02-0.03 %;
    allowed: no worse than the live estimate.  A lag longer than the record is the offline
    smoother: equal to rounding (the same backward passes over the same forward records).
    """
    from bench.bench_estimators import _smoothed

    rec = _record(-4 * NA, seconds=8.0)
    live = _causal(rec, _estimator(rec), 1000)
    offline = _smoothed(rec, _estimator(rec), 1000)
    scores = estimate_scores(rec, live)['nrmse'], estimate_scores(rec, offline)['nrmse']
    assert scores[1] <= scores[0]
    core = _estimator(rec).core
    lagged = type(core)(core.reduced, rec.sample_rate_hz, smoothed_lag_s=10.0)
    lagged.estimate(rec.current_a)
    held = lagged.pop_smoothed(flush=True).deflection_m
    whole = core.smooth(rec.current_a).deflection_m
    assert np.max(np.abs(held - whole)) <= 1e-12


def _crank_record(step_a: float, frequency_hz: float = 5.0, jump_s: float = 7.3,
                  seconds: float = 14.0):
    """slim, a crank from rest at 0.3 s; the offset steps by ``step_a`` at ``jump_s``."""
    from bench.scenarios.motions import Crank

    def make(rng):
        crank = Crank(frequency_hz, 2.0 * MM, 20 * MM, phase_rad=0.3, start_s=0.3,
                      wobble=0.005, wobble_hz=0.3)
        steps = ((jump_s, step_a),) if step_a else ()
        return Sensor('slim'), crank, Daq(offset_a=10 * NA, noise_a=0.7 * NA, adc_bits=16,
                                          offset_steps=steps)
    return Scenario('crank-jump', 'daq', seconds, make, '').build(0)


@pytest.mark.parametrize('frequency_hz, step_a, jump_s, seconds', [
    (3.0, -10 * NA, 7.3, 14.0), (5.0, 20 * NA, 7.3, 14.0), (20.0, -30 * NA, 9.5, 14.0),
    (1.0, -18 * NA, 12.0, 20.0)])
def test_an_offset_that_jumps_while_a_crank_runs_is_taken(frequency_hz, step_a, jump_s,
                                                          seconds):
    """
    A jump of the offset under a periodic motion is taken where it happened.

    Before, the jump refuted the periodic model (its innovations' test), the model went and
    the level with it: 2.8-6.9 % NRMSE here without jumps (``offset_jump_a`` 0; drawn
    record 1, a 34 nA step under a 3.2 Hz crank, read 9.8 %, hundreds of um off to the end;
    now 0.69 %).  Now the stretches the model does not explain are filtered again with a
    jump where its likelihood ratio peaks (``periodic.offset_step_at``), and the model stays
    when it then explains them: measured 0.61-0.79 %, the level 2.7-4.8 um RMS off from 2.7 s after
    the step on.  Allowed 1 % (the issue's floor: the ~1.5 s between the step and the check
    whose stretch the model no longer explains are published as they were); the offset
    within 2 nA at the end (0.3-1.2 nA off measured: the jump's time is found to a fraction
    of a period, and the samples between are shared by the offsets before and after).
    On a 1 Hz crank a block is a second long: the block after the step may pass (the drift
    takes part of it), the next fails with the step before what it is judged on, and the
    jump found there (at its start: what the drift left) has less than two periods after
    it; its stretch then runs on past the check, so the next block judges the same jump on
    two periods (0.78 %; 6.3 % when the check ended that stretch: the jump fell out of what
    was judged, and the model went).
    """
    rec = _crank_record(step_a, frequency_hz, jump_s, seconds)
    est = _estimator(rec)
    out = _causal(rec, est, 1000)
    assert estimate_scores(rec, out)['nrmse'] < 0.01
    status = est.core.status()
    assert status['offset_jumps'] == 1 and status['motion_hz'] > 0
    assert status['offset_a'] == pytest.approx(10 * NA + step_a, abs=2 * NA)
    off = _causal(rec, _estimator(rec, offset_jump_a=0.0), 1000)
    assert estimate_scores(rec, off)['nrmse'] > 0.02      # what the jump does


def test_a_crank_without_a_jump_takes_none_and_a_jump_is_one_recursion():
    """
    No jump where the offset holds; through one, blocks and single samples agree.

    A crank whose model explains every stretch never tries a jump (the estimate equals the
    one with ``offset_jump_a`` 0 to the bit).  The jump is found and taken at a check, by
    filtering the stretches again: the same samples whatever the cut, so the one-sample path
    and a state saved before the check agree with the block path to 1e-12 m.
    """
    plain = _crank_record(0.0, seconds=10.0)
    a = _causal(plain, _estimator(plain), 1000).deflection_m
    b = _causal(plain, _estimator(plain, offset_jump_a=0.0), 1000).deflection_m
    assert np.array_equal(a, b)
    rec = _crank_record(20 * NA, seconds=10.0)
    y = rec.current_a
    block = _estimator(rec).core.estimate(y).deflection_m
    one = _estimator(rec).core
    singles = np.array([one.estimate_one(v)[0] for v in y])
    assert one.status()['offset_jumps'] == 1
    np.testing.assert_allclose(singles, block, rtol=0, atol=1e-12)
    for cut_s in (8.5, 9.5):        # before the check that finds the step, and after it
        est = _estimator(rec).core
        cut = int(cut_s * rec.sample_rate_hz)
        first = est.estimate(y[:cut]).deflection_m
        saved = est.get_state()
        tail = est.estimate(y[cut:]).deflection_m
        est.set_state(saved)
        assert np.array_equal(est.estimate(y[cut:]).deflection_m, tail)
        np.testing.assert_allclose(np.concatenate((first, tail)), block, rtol=0, atol=1e-12)


def test_the_smoothers_pass_back_across_a_jump_found_under_a_crank():
    """
    A jump found at a check joins the smoothers' parts as one found at rest does.

    The stretches filtered again with the jump are a new part of the forward record, linked
    to the state before the jump (``refilter``'s restart), so the backward pass carries the
    offset learned after it no further back than the jump: measured 0.11 % smoothed against
    0.87 % live (5 Hz crank, +20 nA at 7.3 s, 10 s).  Allowed: no worse than live.  A lag
    longer than the record is the offline smoother: equal to rounding (3.6e-14 m measured).
    """
    from bench.bench_estimators import _smoothed

    rec = _crank_record(20 * NA, seconds=10.0)
    live = _causal(rec, _estimator(rec), 1000)
    offline = _smoothed(rec, _estimator(rec), 1000)
    assert estimate_scores(rec, offline)['nrmse'] <= estimate_scores(rec, live)['nrmse']
    core = _estimator(rec).core
    lagged = type(core)(core.reduced, rec.sample_rate_hz, smoothed_lag_s=20.0)
    lagged.estimate(rec.current_a)
    assert lagged.offset_jumps == 1
    held = lagged.pop_smoothed(flush=True).deflection_m
    np.testing.assert_allclose(held, core.smooth(rec.current_a).deflection_m, rtol=0,
                               atol=1e-12)
