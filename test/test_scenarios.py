# SPDX-License-Identifier: Apache-2.0
"""
The scenario library (bench/scenarios).

Its H2 against the package, its current against a direct convolution, its DAQ habits, its
seeds, and its independence from the package.
"""
import math
import subprocess
import sys
from pathlib import Path
import zlib

import numpy as np
import pytest

from bench.scenarios import build, GEOMETRIES, MATERIAL, names, SCENARIOS, Sensor
from bench.scenarios.motions import Crank, FreeVibration, MinJerkPath, Sines, Sum
from bench.scenarios.sensor import frequency_response, sensor_current

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize('sample', sorted(GEOMETRIES))
@pytest.mark.parametrize('corner_hz', [None, 200.0])
def test_h2_matches_the_package_model(sample, corner_hz):
    """Typed in from the paper, evaluated by other algebra: equal to rounding (1e-9)."""
    from ipmc_sensor_ros.physics.model import SensorModel
    from ipmc_sensor_ros.physics.parameters import Geometry

    sensor = Sensor(sample, corner_hz)
    model = SensorModel.named('h2', Geometry(*sensor.geometry, sample),
                              extra_effects=sensor.model_effects)
    f = np.logspace(-3, 4, 300)
    mine, theirs = frequency_response(sensor, f), model.frequency_response(f)
    assert np.max(np.abs(mine - theirs) / np.abs(theirs)) < 1e-9


def test_material_and_paper_samples_match_the_package_parameters():
    from ipmc_sensor_ros.physics.parameters import PAPER_PARAMETERS, PAPER_SAMPLES

    for key, value in MATERIAL.items():
        assert getattr(PAPER_PARAMETERS, key) == value, key
    assert PAPER_PARAMETERS.one_minus_anion_volume_fraction == 1.0   # section 5.2
    for name, g in PAPER_SAMPLES.items():
        assert GEOMETRIES[name] == (g.length_m, g.width_m, g.thickness_m), name


def _direct_current(sensor, motion, t, fs_fine=64000.0, span_s=1.0):
    """
    Sum the impulse response times the motion, at any instants.

    A check independent of the generator's FFT (another grid, another length, the motion
    evaluated at t - tau for the whole past, no padding).  The impulse response is the inverse
    FFT of H on a 64 kHz grid over +-0.5 s (12 slowest time constants of the narrow sample:
    the tail is 6e-6).
    """
    n = int(span_s * fs_fine)
    dt = 1.0 / fs_fine
    h = np.fft.irfft(frequency_response(sensor, np.fft.rfftfreq(n, dt)), n)
    lags = np.arange(-n // 2, n // 2)
    taps = h[lags % n]
    return np.array([taps @ motion(tk - lags * dt) for tk in t])


DIRECT_CASES = {
    'crank since power-on, short': (Sensor('short'), Crank(20.0, 2e-3, 20e-3, 0.3, wobble=0.01)),
    'sines + step, slim, 200 Hz amplifier': (
        Sensor('slim', 200.0), Sum((Sines((0.3, 2.0), (5e-4, 3e-4), (0.1, 1.0)),
                                    MinJerkPath((1.2,), (0.3,), (0.0, 5e-4))))),
    'free vibration from rest, narrow': (
        Sensor('narrow'), FreeVibration(2e-3, 30.0, 0.03, 0.2, 0.5, 1.3)),
    'crank from rest, big': (Sensor('big'), Crank(5.0, 2e-3, 20e-3, 1.0, start_s=0.3)),
}


@pytest.mark.parametrize('case', sorted(DIRECT_CASES))
@pytest.mark.parametrize('jitter', [0.0, 0.25])
def test_current_matches_direct_convolution(case, jitter):
    """FFT with pre-roll and padding = the convolution over the whole past (1e-3 relative)."""
    sensor, motion = DIRECT_CASES[case]
    fs = 1000.0
    t = np.arange(2000) / fs
    t = t + np.random.default_rng(1).uniform(-jitter, jitter, t.size) / fs
    current = sensor_current(sensor, motion, t, fs)
    pick = np.arange(5, t.size, 97)
    direct = _direct_current(sensor, motion, t[pick])
    # measured 1e-10 .. 4e-6 (free vibration: a kink in the acceleration at release)
    assert np.max(np.abs(current[pick] - direct)) < 1e-3 * np.max(np.abs(direct))


def test_generator_and_bounds_do_not_import_the_package():
    code = ('import sys, bench.scenarios, bench.bounds\n'
            "bad = sorted(m for m in sys.modules if m.startswith('ipmc_sensor_ros'))\n"
            'assert not bad, bad\n'
            "r = bench.scenarios.build('crank-5hz-slim-pct-rest', 0)\n"
            'bench.bounds.record_bounds(r)\n'
            "bad = sorted(m for m in sys.modules if m.startswith('ipmc_sensor_ros'))\n"
            'assert not bad, bad\n')
    res = subprocess.run([sys.executable, '-c', code], cwd=ROOT, capture_output=True,
                         text=True, timeout=120)
    assert res.returncode == 0, res.stderr


def test_issue_table_and_crank_grid_are_in_the_library():
    for name in ('slim-motion-hold-0.2na', 'short-2khz-jitter-hum', 'big-pick-place-10min',
                 'slim-field-lab', 'slim-crank-poweron-20na', 'big-step-held',
                 'big-step-held-10na', 'slim-free-vibration-30hz', 'slim-hour-drift'):
        assert name in SCENARIOS
    for f in (1, 5, 20):
        for sample in ('slim', 'short'):
            for noise in ('0.2na', 'pct'):
                for start in ('rest', 'poweron'):
                    assert f'crank-{f}hz-{sample}-{noise}-{start}' in SCENARIOS
    assert {SCENARIOS[n].make(np.random.default_rng(0))[0].sample for n in names()} == \
        set(GEOMETRIES)


@pytest.mark.parametrize('name', [n for n in names() if SCENARIOS[n].duration_s <= 60])
def test_every_short_scenario_builds_a_consistent_record(name):
    r = build(name, 0)
    n = r.time_s.size
    for a in (r.current_a, r.deflection_m, r.sample_time_s, r.offset_a, r.hum_a):
        assert a.shape == (n,) and np.all(np.isfinite(a))
    assert np.all(np.diff(r.time_s) > 0)
    assert r.grid_deflection_m.size == r.grid_current_a.size == \
        int(round(SCENARIOS[name].duration_s * r.sample_rate_hz))
    assert 0.2e-3 < np.sqrt(np.mean(r.deflection_m ** 2)) and np.max(np.abs(r.deflection_m)) < 5e-3
    if r.stationary or SCENARIOS[name].moving_at_start:
        assert r.grid_pre_current_a.size >= r.grid_current_a.size
    else:
        assert abs(r.grid_deflection_m[0]) < 1e-12          # starts from rest at zero
        assert r.grid_pre_current_a.size == 0


def test_seed_draws_everything_and_fresh_seeds_work():
    a, b, c = (build('short-2khz-jitter-hum', s) for s in (3, 3, 4))
    assert np.array_equal(a.current_a, b.current_a) and np.array_equal(a.time_s, b.time_s)
    assert a.mains_hz != c.mains_hz and a.offset_a[0] != c.offset_a[0]
    assert not np.array_equal(a.deflection_m[:1000], c.deflection_m[:1000])   # crank phase
    assert build('crank-5hz-slim-pct-rest', 987654).current_a.size == 20000
    rng = np.random.default_rng([3, zlib.crc32(b'short-2khz-jitter-hum')])
    assert SCENARIOS['short-2khz-jitter-hum'].make(rng)[2].mains_hz == a.mains_hz


def test_daq_habits_of_the_jittered_hum_record():
    r = build('short-2khz-jitter-hum', 1)
    period = 1.0 / r.sample_rate_hz
    rows = np.round(r.sample_time_s / period).astype(int)
    stamp_error = (r.time_s - r.time_origin_s) - rows * period
    assert np.max(np.abs(stamp_error)) <= 0.04 * period * (1 + 1e-6) + 1e-6   # + epoch rounding
    assert np.std(stamp_error) > 0.02 * period                  # uniform +-4 %: std 2.3 %
    lost = 1 - r.time_s.size / r.grid_current_a.size
    assert 0.005 < lost < 0.02                                  # 0.5 % + 3 bursts of 5-50
    assert np.max(np.diff(rows)) >= 6                           # a burst
    assert r.time_origin_s > 1.6e9 and 59.7 <= r.mains_hz <= 60.3
    assert np.allclose(r.current_a, r.grid_current_a[rows] + r.offset_a + r.hum_a,
                       rtol=0, atol=1e-20)                     # no hidden term, to rounding
    hum = np.fft.rfft(r.hum_a[:2000] * np.hanning(2000))
    f = np.fft.rfftfreq(2000, period)
    for m in (1, 2, 3):                                         # fundamental and harmonics
        band = np.abs(f - m * r.mains_hz) < 3
        assert np.max(np.abs(hum[band])) > 0.05 * np.max(np.abs(hum))


def test_quantisation_noise_and_model_text():
    from ipmc_sensor_ros.physics.model import SensorModel
    from ipmc_sensor_ros.physics.parameters import Geometry

    r = build('slim-field-lab', 2)
    assert r.lsb_a > 0 and np.allclose(r.current_a / r.lsb_a, np.round(r.current_a / r.lsb_a),
                                       atol=1e-6)
    model = SensorModel.named(r.model, Geometry(*r.geometry_m, r.sample),
                              extra_effects=r.effects)
    assert model.has_effect('amplifier_bandwidth')
    assert math.isclose(model.effect_values('amplifier_bandwidth')['corner_hz'], 200.0)
    clean = sensor_current(r.sensor, SCENARIOS['slim-field-lab'].make(
        np.random.default_rng([2, zlib.crc32(b'slim-field-lab')]))[1],
        np.arange(r.grid_current_a.size) / r.sample_rate_hz, r.sample_rate_hz)
    residual = r.grid_current_a - clean              # white noise + quantisation error
    expected = math.sqrt(r.noise_std_a ** 2 + r.lsb_a ** 2 / 12)
    assert abs(np.std(residual) / expected - 1) < 0.02          # 60,000 samples: 0.3 % std


def test_the_offset_steps_once_where_the_amplifier_is_re_zeroed():
    """``slim-offset-step``: one step of 2-60 nA at 10-20 s, in the record's offset column."""
    r = build('slim-offset-step', 0)
    t = r.time_s - r.time_s[0]
    jumps = np.flatnonzero(np.abs(np.diff(r.offset_a)) > 1e-12)
    assert jumps.size == 1
    k = int(jumps[0])
    assert 10.0 <= t[k + 1] <= 20.0
    assert 2e-9 <= abs(r.offset_a[k + 1] - r.offset_a[k]) <= 60e-9


def test_a_crank_that_stops_holds_where_it_stopped():
    crank = Crank(3.0, 2e-3, 20e-3, phase_rad=0.7, start_s=0.3, wobble=0.01, wobble_hz=0.3,
                  stop_s=5.0, stop_duration_s=0.3)
    turning = Crank(3.0, 2e-3, 20e-3, phase_rad=0.7, start_s=0.3, wobble=0.01, wobble_hz=0.3)
    t = np.arange(0.0, 8.0, 1e-4)
    w, free = crank(t), turning(t)
    assert np.array_equal(w[t <= 5.0], free[t <= 5.0])          # the same motion until the stop
    held = w[t >= 5.3]
    assert np.ptp(held) == 0.0 and np.ptp(free[t >= 5.3]) > 3e-3  # held, where it would turn
    # it slows down, never faster than it turned (2 pi f r = 38 mm/s, 1 % wobble)
    assert np.max(np.abs(np.diff(w))) < 38e-3 * 1e-4 * 1.05
    rec = build('slim-crank-stop', 0)
    late = rec.sample_time_s > 7.6      # stops by 7.5 s at the latest
    assert np.ptp(rec.deflection_m[late]) == 0.0 and np.ptp(rec.deflection_m) > 3e-3
