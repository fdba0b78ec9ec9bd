# SPDX-License-Identifier: Apache-2.0
"""
Realistic DAQ current for a deflection trajectory, for evaluating estimators.

The sensing current comes from the exact model (H1/H2 with effects,
:func:`~ipmc_sensor_ros.simulation.sensor.predict_current`: FFT convolution, no
reduction), independent of any estimator's reduced model.  The DAQ adds

* an offset: constant ``offset_a`` plus a linear drift ``drift_a_per_min``;
* white Gaussian noise of RMS ``noise_fraction`` times the clean signal's RMS
  (``noise_a`` adds an absolute floor);
* mains hum at ``mains_hz`` (50/60) and harmonics 2..4 (amplitudes 1, 0.5, 0.3,
  0.2 relative, random phases), total RMS ``hum_fraction`` times the signal RMS.

Motions: :func:`robot_motion` (slow sines plus step-and-hold moves with
raised-cosine transitions) and :func:`started` (any deflection record that
starts from rest after ``rest_s`` with a smooth onset).
"""
from __future__ import annotations

import numpy as np

from ..physics.model import SensorModel
from .convolution import predict_current
from .stimuli import RobotMotion

__all__ = ['daq_current', 'robot_motion', 'started', 'intermittent_motion']


def _ramp(u):
    u = np.clip(u, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * u)


def started(time_s, deflection_m, rest_s: float = 2.0, onset_s: float = 0.5) -> np.ndarray:
    """Return the record held at zero for ``rest_s``, then faded in over ``onset_s``."""
    t = np.asarray(time_s, float)
    return np.asarray(deflection_m, float) * _ramp((t - rest_s) / onset_s)


def robot_motion(time_s, seed: int = 0, amplitude_m: float = 1.5e-3) -> np.ndarray:
    """Robot-like deflection, m: :class:`~.stimuli.RobotMotion` (holds, moves, slow sines)."""
    return RobotMotion(amplitude_m=amplitude_m, seed=seed).deflection(time_s)


def intermittent_motion(time_s, seed: int = 0, amplitude_m: float = 1.5e-3,
                        move_every_s: float = 60.0) -> np.ndarray:
    """
    Long holds with a 10 s robot-like burst every ``move_every_s`` seconds.

    Each burst is :func:`robot_motion` with a new seed each time; it blends in from the held
    level over 0.5 s and its last value is held, so levels stay within +-``amplitude_m``.
    """
    t = np.asarray(time_s, float)
    dt = t[1] - t[0]
    tb = np.arange(0, 10.0, dt)
    w = np.zeros_like(t)
    level = 0.0
    for k, start in enumerate(np.arange(move_every_s / 2, t[-1] - 10.0, move_every_s)):
        i0 = int(round((start - t[0]) / dt))
        burst = robot_motion(tb, seed * 1000 + k, amplitude_m)
        seg = burst + level * (1 - _ramp(tb / 0.5))
        w[i0:i0 + tb.size] = seg[:max(0, min(tb.size, t.size - i0))]
        level = float(seg[-1])
        w[i0 + tb.size:] = level
    return w


def daq_current(model: SensorModel, time_s, deflection_m, *, offset_a: float = 0.0,
                drift_a_per_min: float = 0.0, noise_fraction: float = 0.0, noise_a: float = 0.0,
                mains_hz: float = 0.0, hum_fraction: float = 0.0, seed: int = 0) -> np.ndarray:
    """Measured current, A (see the module docstring)."""
    rng = np.random.default_rng(seed)
    t = np.asarray(time_s, float)
    clean = predict_current(model, t, deflection_m)
    rms = float(np.sqrt(np.mean(clean ** 2)))
    i = clean + offset_a + drift_a_per_min * (t - t[0]) / 60.0
    sigma = np.hypot(noise_fraction * rms, noise_a)
    i = i + sigma * rng.standard_normal(t.size)
    if mains_hz and hum_fraction:
        rel = np.array([1.0, 0.5, 0.3, 0.2])
        amps = hum_fraction * rms * rel / np.sqrt(np.sum(rel ** 2) / 2)
        for k, a in enumerate(amps, start=1):
            i = i + a * np.sin(2 * np.pi * k * mains_hz * t + rng.uniform(0, 2 * np.pi))
    return i
