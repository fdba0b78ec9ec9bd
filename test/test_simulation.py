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
