# SPDX-License-Identifier: Apache-2.0
"""Tests of the stimuli and the time-domain sensor simulator."""
import numpy as np
import pytest

from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import PAPER_SAMPLES, ParameterError
from ipmc_sensor_ros.simulation.sensor import SensorSimulator, periodic_response
from ipmc_sensor_ros.simulation.stimuli import (CrankSlider, FreeVibration, Sampled, Step, Sweep,
                                                make_stimulus)


@pytest.mark.parametrize('name', list(PAPER_SAMPLES))
def test_simulator_accuracy_against_full_model(name):
    sim = SensorSimulator(SensorModel(PAPER_SAMPLES[name]), 1000.0)
    mag_db, phase_deg = sim.accuracy((0.5, 50.0))
    assert mag_db <= 0.2 and phase_deg <= 1.0


def test_time_domain_simulation_matches_exact_periodic_response():
    model = SensorModel(PAPER_SAMPLES['short'])
    fs = 1000.0
    t = np.arange(int(10 * fs)) / fs
    stim = CrankSlider(5.0, 2e-3, 20e-3)
    exact = periodic_response(model, stim.deflection(t), fs)
    sim = SensorSimulator(model, fs)
    sim.run(stim, t)               # first pass: transient
    _, i = sim.run(stim, t + t[-1] + 1 / fs)
    # 0.2 dB / 1 deg response accuracy bounds the waveform error at ~3 %.
    assert np.sqrt(np.mean((i - exact) ** 2)) / np.sqrt(np.mean(exact ** 2)) < 0.03


@pytest.mark.parametrize(
    'stim',
    [
        CrankSlider(3.0, 2e-3, 15e-3),
        Sweep(1e-3, 0.5, 20.0, 5.0),
        Step(2e-3, 0.1, 0.02),
        FreeVibration(2e-3, 30.0, 0.05, 0.5, 0.3),
    ],
)
def test_velocity_is_derivative_of_deflection(stim):
    t = np.linspace(0.05, 1.5, 200_001)
    dw = np.gradient(stim.deflection(t), t)
    v = stim.velocity(t)
    # central differences on a 7 us grid are accurate to ~1e-6 relative away from kinks
    assert np.max(np.abs(dw - v)) < 1e-3 * np.max(np.abs(v))


def test_crank_slider_has_harmonics_and_full_stroke():
    fs, f0 = 1000.0, 2.0
    t = np.arange(int(fs / f0) * 4) / fs
    w = CrankSlider(f0, 2e-3, 10e-3).deflection(t)
    assert np.ptp(w) == pytest.approx(4e-3, rel=1e-3)
    spec = np.abs(np.fft.rfft(w))
    k = int(4)  # 4 periods -> fundamental in bin 4
    # second harmonic relative amplitude ~ r/(4 l) = 5 %
    assert spec[2 * k] / spec[k] == pytest.approx(0.05, rel=0.15)
    assert abs(np.mean(w)) < 1e-9


def test_measurement_chain_is_seeded_and_applies_gain_offset():
    model = SensorModel(PAPER_SAMPLES['slim'])
    t = np.arange(1000) / 1000.0
    stim = CrankSlider(1.0)
    a = SensorSimulator(model, 1000.0, noise_rms_a=1e-8, seed=3).run(stim, t)[1]
    b = SensorSimulator(model, 1000.0, noise_rms_a=1e-8, seed=3).run(stim, t)[1]
    c = SensorSimulator(model, 1000.0, current_gain=2.0, current_offset_a=1e-7).run(stim, t)[1]
    clean = SensorSimulator(model, 1000.0).run(stim, t)[1]
    assert np.array_equal(a, b)
    assert np.allclose(c, 2 * clean + 1e-7, rtol=1e-12, atol=1e-20)
    assert np.std(a - clean) == pytest.approx(1e-8, rel=0.1)


def test_sampled_stimulus_and_errors():
    t = np.linspace(0, 1, 101)
    s = Sampled(t, np.sin(2 * np.pi * t))
    assert s.deflection(np.array([0.25]))[0] == pytest.approx(1.0, abs=1e-4)
    with pytest.raises(ParameterError, match='increase'):
        Sampled(t[::-1], t)
    with pytest.raises(ParameterError, match='unknown stimulus'):
        make_stimulus('wobble')
    with pytest.raises(ParameterError, match='rod_length_m'):
        CrankSlider(1.0, 2e-3, 1e-3)


@pytest.mark.parametrize(
    'effects',
    [
        'time_delay(delay_s=0.0023)',
        'nonlinearity(quadratic=1,cubic=10)',
        'current_offset(offset_a=1e-7,drift_a_per_s=1e-9)',
        'amplifier_bandwidth(corner_hz=50)',
        'beam_inertia(natural_frequency_hz=30,damping_ratio=0.03)',
        'effective_length(tip_offset_m=0.002)',
        'hydration_drift(diffusivity_rate_per_s=-0.005)',
    ],
)
def test_streaming_simulator_with_effects_matches_exact_prediction(effects):
    """
    The streaming simulator (blocks of 100 samples) against the exact FFT prediction.

    Same model; 1 % bounds the simulator's 0.05 dB / 0.2 deg discretisation error plus the
    delay line's interpolation and the piecewise-constant drift.
    """
    fs = 1000.0
    model = SensorModel.named('h2', PAPER_SAMPLES['slim'], extra_effects=effects)
    t = np.arange(int(20 * fs)) / fs
    stim = CrankSlider(3.0, 2e-3, 15e-3)
    assert _streaming_error(SensorSimulator(model, fs, update_s=1.0), model, stim, t, 100) < 0.01


def _streaming_error(sim, model, stim, t, block: int) -> float:
    """
    Relative RMS error of a streaming simulator against the exact FFT prediction.

    Blocks of ``block`` samples; the prediction of ``model``; after a 1 s settle.
    """
    from ipmc_sensor_ros.simulation.sensor import predict_current

    i = np.concatenate([sim.run(stim, t[k:k + block])[1] for k in range(0, t.size, block)])
    exact = predict_current(model, t, stim.deflection(t))
    k = t > 1.0
    return float(np.sqrt(np.mean((i[k] - exact[k]) ** 2)) / np.std(exact[k]))


def test_field_fidelity_simulator_matches_exact_prediction_and_refuses_other_effects():
    from ipmc_sensor_ros.simulation.sensor import FieldSensorSimulator

    fs = 1000.0
    model = SensorModel.named('h2', PAPER_SAMPLES['short'],
                              extra_effects='hydration_drift(diffusivity_rate_per_s=-0.003)')
    t = np.arange(int(10 * fs)) / fs
    stim = CrankSlider(4.0, 2e-3, 15e-3)
    # field mesh (0.2 deg) + Crank-Nicolson + the effect's quasi-static approximation: < 1 %
    assert (
        _streaming_error(FieldSensorSimulator(model, fs, noise_rms_a=0.0), model, stim, t, 250)
        < 0.01
    )
    with pytest.raises(ParameterError, match='time_delay'):
        FieldSensorSimulator(SensorModel.named('h2', PAPER_SAMPLES['short'],
                                               extra_effects='time_delay'), fs)


def test_robot_motion_is_the_same_in_any_blocks_and_its_velocity_is_its_derivative():
    """
    The live simulator's robot_motion: blocks of any size give one motion; v = dw/dt.

    Velocity against the central difference of w at 1 kHz: the pieces are raised cosines and
    sines of at most 2 Hz over >= 0.2 s, whose central-difference error is (2 pi f dt)^2 / 6
    relative, i.e. below 1e-3 of the peak velocity away from the segment joins (the joins are
    C1, so the difference there is O(dt) of the velocity's jump in slope: 1 % is allowed).
    """
    from ipmc_sensor_ros.simulation.daq import robot_motion
    from ipmc_sensor_ros.simulation.stimuli import RobotMotion

    t = np.arange(0, 60, 1e-3)
    for seed in (0, 7):
        whole = RobotMotion(seed=seed).deflection(t)
        blocks = RobotMotion(seed=seed)
        np.testing.assert_array_equal(
            np.concatenate([blocks.deflection(t[k:k + 333]) for k in range(0, t.size, 333)]),
            whole)
        np.testing.assert_array_equal(robot_motion(t, seed), whole)   # the offline generator
        assert np.ptp(whole) > 1e-3 and np.max(np.abs(whole)) <= 1.5e-3 * 1.6
        v = RobotMotion(seed=seed).velocity(t)
        fd = np.gradient(whole, t)
        assert np.max(np.abs(v - fd)) <= 0.01 * np.max(np.abs(v))


def test_measurement_chain_adds_drift_and_mains_hum_without_changing_the_noise():
    from ipmc_sensor_ros.simulation.chain import MeasurementChain

    model = SensorModel(PAPER_SAMPLES['slim'])
    t = np.arange(0, 10, 1e-3)
    stim = CrankSlider(2.0, 2e-3, 20e-3)
    base = dict(noise_rms_a=20e-9, current_offset_a=10e-9, seed=4)
    _, plain = SensorSimulator(model, 1000.0, **base).run(stim, t)
    _, drifting = SensorSimulator(model, 1000.0, current_offset_drift_a_per_s=1e-9 / 60,
                                  **base).run(stim, t)
    _, humming = SensorSimulator(model, 1000.0, mains_hz=50, mains_rms_a=30e-9, **base).run(
        stim, t)
    # the noise sequence is the same, so the differences are the drift and the hum alone
    np.testing.assert_allclose(drifting - plain, 1e-9 / 60 * t, rtol=0, atol=1e-20)
    hum = humming - plain
    assert np.std(hum) == pytest.approx(30e-9, rel=1e-3)    # 500 whole periods of 50 Hz
    spectrum = np.abs(np.fft.rfft(hum))
    freqs = np.fft.rfftfreq(t.size, 1e-3)
    peaks = sorted(freqs[np.argsort(spectrum)[-4:]])
    assert peaks == pytest.approx([50.0, 100.0, 150.0, 200.0])
    with pytest.raises(ParameterError, match="'mains_hz' must be 0, 50 or 60"):
        MeasurementChain(mains_hz=55)
    with pytest.raises(ParameterError, match="'mains_rms_a' must be >= 0"):
        MeasurementChain(mains_rms_a=-1e-9)
