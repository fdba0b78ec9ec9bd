# SPDX-License-Identifier: Apache-2.0
"""The rest test's window and its false-alarm rates (estimation/rest.py)."""
import numpy as np
import pytest

from ipmc_sensor_ros.estimation.rest import RestTest, RestWindow

FS = 1000.0


def test_window_sums_and_line_fit_follow_the_last_samples():
    """
    Running sums and the sliding DFT equal a direct computation over the window.

    1234 samples (several turns of the ring, a bridged gap of 3 periods), a 50 Hz line: the
    sums match to rounding, and the window less its fit of the line (10 whole cycles of 50
    and 100 Hz in 0.2 s, where the DFT fit is the least-squares fit) is the noise alone.
    """
    rng = np.random.default_rng(3)
    lines = np.array([50.0, 100.0])
    rot = np.exp(-2j * np.pi * lines / FS)
    win = RestWindow.empty(200, lines.size, 1.0)
    steps = np.ones(1234, dtype=int)
    steps[700] = 3
    t = np.cumsum(steps) / FS
    noise = 1e-9 * rng.standard_normal(t.size)
    y = 5e-8 * np.cos(2 * np.pi * 50.0 * t + 0.3) + noise
    for k in range(t.size):
        win.push(float(y[k]), None if k == 0 else rot ** steps[k])
    last = y[-200:]
    assert win.total == pytest.approx(last.sum(), rel=1e-12, abs=1e-20)
    assert win.total_sq == pytest.approx(last @ last, rel=1e-12)
    phasors = np.exp(-2j * np.pi * np.outer(t[-200:] - t[0], lines))   # from the first
    assert np.allclose(win.line_sums, last @ phasors, rtol=1e-9, atol=1e-20)
    fit_free = win.residuals(win.pos)
    # the fit also takes the noise's own 50 and 100 Hz components (4 of 200 degrees of
    # freedom): what is left differs from the noise by about sqrt(4 / 200) of it
    assert np.std(fit_free - (noise[-200:] - noise[-200:].mean())) < 0.3e-9


@pytest.mark.parametrize('false_alarm', [1e-2, 1e-3])
def test_rest_tests_call_white_noise_moving_at_their_level(false_alarm):
    """
    On white noise each test calls a still sensor moving at about its stated level.

    Per sample: the innovation's chi-square and the two-sided CUSUM, each at the level, so
    2 x the level in all (Siegmund's approximation of the CUSUM's run length is within 25 %
    at these levels); per window: the spread's and the mean's chi-square, 2 x the level.
    Counts: 200,000 samples (2,000 or 400 alarms expected, Poisson +-2-5 %), 5,000 windows
    (100 or 10 expected: the band is wide for 10).
    """
    rng = np.random.default_rng(11)
    test = RestTest.design(0.2, FS, false_alarm)
    track, alarms = None, 0
    for r in rng.standard_normal(200_000).tolist():
        ok, track = test.sample_ok(r, track, 0.0, 0.0, 1.0)
        alarms += not ok
    assert 1.5 * false_alarm < alarms / 200_000 < 2.5 * false_alarm
    windows = rng.standard_normal((5000, test.n))
    fails = sum(not test.still(float(w.mean()), float(w @ w - w.sum() ** 2 / w.size), 0.0,
                               0.0, 1.0) for w in windows)
    assert 0.8 * false_alarm < fails / 5000 < 4 * false_alarm


@pytest.mark.parametrize('gap_at', [None, 1150])
def test_line_fit_is_least_squares_when_the_window_is_not_whole_periods(gap_at):
    """
    The window's fit of a constant and the lines is the least-squares fit, gap or not.

    A 2 % hum of big-pick-place-10min's kind (50.22 Hz and two harmonics, 85 nA RMS: 0.2 s
    holds 10.04 periods) over a 0.5 nA noise and a 6 nA offset, 1234 samples; with a gap of
    3 periods inside the last window or none.  The fit's residuals equal numpy's lstsq on the
    samples' times (to 1e-6 of the noise: rounding of the sliding sums), the constant is the
    offset within 5 sigma of R/N, and the still window passes.
    """
    rng = np.random.default_rng(5)
    lines = np.array([50.22, 100.44, 150.66])
    test = RestTest.design(0.2, FS, 1e-6, tuple(lines))
    rot = np.exp(-2j * np.pi * lines / FS)
    win = RestWindow.empty(test.n, lines.size, 1.0)
    steps = np.ones(1234, dtype=int)
    if gap_at is not None:
        steps[gap_at] = 3
    t = np.cumsum(steps) / FS
    noise = 0.5e-9 * rng.standard_normal(t.size)
    hum = sum(a * np.cos(2 * np.pi * f * t + p) for a, f, p in
              zip((110e-9, 40e-9, 25e-9), lines, (0.3, 1.1, 2.0)))
    y = 6e-9 + hum + noise
    for k in range(t.size):
        win.push(float(y[k]), None if k == 0 else rot ** steps[k], int(steps[k]))
        verdict = win.judge(test, float(y[k]), 6e-9, 0.0, 0.25e-18, False)
    assert verdict
    tw = t[-test.n:] - t[-1]
    A = np.column_stack([np.ones(test.n)] + [g(2 * np.pi * f * tw) for f in lines
                                             for g in (np.cos, lambda a: -np.sin(a))])
    coef = np.linalg.lstsq(A, y[-test.n:], rcond=None)[0]
    theta, _ = win.fit(test.gram_inv)
    assert np.allclose(theta, coef, rtol=0, atol=1e-15)
    lines_only = y[-test.n:] - A[:, 1:] @ coef[1:]
    assert np.allclose(win.residuals(win.pos), lines_only, rtol=0, atol=0.5e-15)
    assert abs(theta[0] - 6e-9) < 5 * 0.5e-9 / np.sqrt(test.n)


def test_a_jumps_run_is_tested_on_its_own_fit_with_the_step():
    """
    The samples of an offset's jump are taken less the lines of the fit with the step.

    The nominal 50 and 60 Hz lines with two harmonics each (what the rest test fits until a
    line is measured), a hum-free still current of 6 nA under 0.2 nA of noise whose offset
    steps by 20 nA (100 sigma) at sample 400: the run starts at the step and holds each of
    the 150 samples after it (the 200-sample window still holds the step); the newest
    sample's residual equals numpy's lstsq with a step column to 1e-15 A (rounding of the
    sliding sums).  The fit without the step column leaks 2 sigma of it into this sample
    (asserted > 1.5 sigma): a bias the CUSUM (drift 0.5 sigma) sums to its limit within
    tens of samples, which is how such steps were refused.
    """
    rng = np.random.default_rng(8)
    lines = np.array([50.0, 100.0, 150.0, 60.0, 120.0, 180.0])
    test = RestTest.design(0.2, FS, 1e-6, tuple(lines), 30e-9)
    rot = np.exp(-2j * np.pi * lines / FS)
    win = RestWindow.empty(test.n, lines.size, 1.0)
    n, step_at = 550, 400
    y = 6e-9 + 20e-9 * (np.arange(n) >= step_at) + 0.2e-9 * rng.standard_normal(n)
    for k in range(n):
        win.push(float(y[k]), None if k == 0 else rot)
        win.judge(test, float(y[k]), 6e-9, 1e-24, 0.04e-18, True)
    assert win.jump_quiet == n - step_at
    tw = (np.arange(test.n) - (test.n - 1)) / FS
    A = np.column_stack([np.ones(test.n)] + [g(2 * np.pi * f * tw) for f in lines
                                             for g in (np.cos, lambda a: -np.sin(a))])
    e = (np.arange(n - test.n, n) >= step_at).astype(float)
    coef = np.linalg.lstsq(np.column_stack([A, e]), y[-test.n:], rcond=None)[0]
    expected = y[-1] - coef[1:-1:2].sum()           # the newest sample less its lines
    gram = win.gram(test.gram_inv)
    theta, b = win.solve(gram)
    win.jump_quiet -= 1                             # the residual as judged (run before it)
    residual = win._step_residual(float(y[-1]), gram, theta, b)
    assert residual == pytest.approx(expected, abs=1e-15)
    leaked = y[-1] - theta[1::2].sum() - expected   # the fit without the step
    assert abs(leaked) > 1.5 * 0.2e-9


def test_a_jumps_run_goes_on_when_the_lines_change():
    """
    A jump's run in progress when the rest test's lines change is carried, not lost or broken.

    Drawn record 228 (2026-12-02) ended in a traceback: a mains line was measured while the
    window followed a jump's run, and the run's phasor sums (3 lines) met the new window's
    (6 lines).  Here a still current of 6 nA (0.2 nA of noise) steps by 20 nA at sample
    1400; at sample 1500 (100 samples into the run) the state of a filter that tests the
    50 Hz family is carried onto one that also tests the 60 Hz family.  The run's phasor
    sums are those of its samples under the new lines (the sum of e^(-j 2 pi f k / fs) over
    k = 0..99 samples back: the newest has phase 1 after a carry) to rounding; run on, the
    carried filter follows the run as the new filter does when it ran from the start
    (hum-free current: the lines change no verdict): the same run length, the same sums
    relative to the newest phase, the same estimates to 1e-9 of their largest.
    """
    from ipmc_sensor_ros.estimation.carry import carry_state
    from ipmc_sensor_ros.estimation.config import EstimatorConfig
    from ipmc_sensor_ros.estimation.filter import KalmanFilter
    from ipmc_sensor_ros.estimation.statespace import StateSpaceModel
    from ipmc_sensor_ros.lti.reduction import reduce_model_parts
    from ipmc_sensor_ros.physics.model import SensorModel
    from ipmc_sensor_ros.physics.parameters import PAPER_SAMPLES

    reduced = reduce_model_parts(SensorModel.named('h2', PAPER_SAMPLES['slim']), 4,
                                 (0.1, 50.0))[0]
    ssm = StateSpaceModel(reduced, EstimatorConfig(), FS)
    before, after = (50.0, 100.0, 150.0), (50.0, 100.0, 150.0, 60.0, 120.0, 180.0)
    old, new = KalmanFilter(ssm, before), KalmanFilter(ssm, after)
    rng = np.random.default_rng(5)
    n, step_at, carry_at = 1580, 1400, 1500
    y = 6e-9 + 20e-9 * (np.arange(n) >= step_at) + 0.2e-9 * rng.standard_normal(n)
    state = old.run(old.initial_state(), y[:carry_at])[0]
    assert state.window.jump_sums is not None and state.window.jump_quiet == carry_at - step_at
    carried = carry_state(old, new, state)
    back = np.arange(carry_at - step_at)[:, None]
    expected = np.exp(2j * np.pi * np.array(after) * back / FS).sum(axis=0)
    assert np.allclose(carried.window.jump_sums[1], expected, rtol=1e-9, atol=1e-9)
    end, w, _, _ = new.run(carried, y[carry_at:])
    ref, w_ref, _, _ = new.run(new.run(new.initial_state(), y[:carry_at])[0], y[carry_at:])
    assert end.window.jump_quiet == ref.window.jump_quiet == n - step_at
    relative = [s.window.jump_sums[1] * s.window.phase.conj() for s in (end, ref)]
    assert np.allclose(*relative, rtol=1e-9, atol=1e-9)
    assert np.max(np.abs(w - w_ref)) <= 1e-9 * np.max(np.abs(w_ref))


@pytest.mark.parametrize('line_std_a, holds', [(4.5e-9, True), (0.0, False)])
def test_a_jump_out_of_a_motion_is_tested_within_the_filters_hum_uncertainty(line_std_a, holds):
    """
    A jump's run out of a motion is tested within the noise and the filter's line variance.

    Drawn record 247 (2026-12-02): a 550 nA hum (25 % of the current) that the filter knew to
    4-5 nA by its own covariance, and a +23 nA step under two sines; in the hold after them
    the run's residual (the current less the filter's lines) swung +-2 nA at the line, and
    tested against 0.5 nA of noise alone every run died within a few to tens of samples: the
    jump was never taken and the level ramped 72 um/s through 11 s of hold (105 %).  Here
    the same: 1.5 s of a current 20 nA off the filter's offset, out of a motion, whose
    lines the filter reads 2 nA off (a 60 Hz swing) and knows to ``line_std_a``.  With the
    filter's 4.5 nA the run holds past ``moving_jump_n`` (1 s); with none it never does.
    """
    rng = np.random.default_rng(3)
    lines = np.array([60.0, 120.0, 180.0])
    test = RestTest.design(0.2, FS, 1e-6, tuple(lines), 30e-9, 1.0)
    rot = np.exp(-2j * np.pi * lines / FS)
    win = RestWindow.empty(test.n, lines.size, 1.0)
    n = 1500
    k = np.arange(n)
    hum = 550e-9 * np.sin(2 * np.pi * 60.0 * k / FS)
    y = 26e-9 + hum + 0.5e-9 * rng.standard_normal(n)
    read = hum - 2e-9 * np.sin(2 * np.pi * 60.0 * k / FS + 1.0)     # the filter's lines
    longest = 0
    for j in range(n):
        win.push(float(y[j]), None if j == 0 else rot)
        win.judge(test, float(y[j]), 6e-9, 1e-20, 0.25e-18, False,
                  lambda j=j: (float(read[j]), line_std_a ** 2))
        longest = max(longest, win.jump_quiet)
    assert (longest >= test.moving_jump_n) == holds
