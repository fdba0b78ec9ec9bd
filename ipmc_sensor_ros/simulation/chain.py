# SPDX-License-Identifier: Apache-2.0
"""
The measurement chain between the sensor and the DAQ, as real instruments have it.

``i_meas(t) = current_gain * i(t) + current_offset_a + current_offset_drift_a_per_s * t
+ noise + hum``: a transimpedance amplifier's gain error and input offset (which creeps with
temperature), white Gaussian noise of RMS ``noise_rms_a`` and mains hum at ``mains_hz`` (50 or
60 Hz) and its harmonics 2-4 with relative amplitudes 1, 0.5, 0.3, 0.2 (a rectifier-loaded line)
and total RMS ``mains_rms_a``.  t is simulated time.  Noise and hum phases come from seeded
generators, separate so that adding hum leaves the noise sequence unchanged.
"""
from __future__ import annotations

import math

import numpy as np

from ..physics.parameters import ParameterError

__all__ = ['MeasurementChain', 'HUM_HARMONICS']

#: Relative amplitudes of the mains line's harmonics 1..4 in the hum.
HUM_HARMONICS = (1.0, 0.5, 0.3, 0.2)


class MeasurementChain:
    """
    Amplifier gain and offset (with drift), white noise and mains hum added to a current.

    Parameters
    ----------
    current_gain : dimensionless gain error of the current amplifier (1 = ideal).
    current_offset_a : constant current offset, A.
    current_offset_drift_a_per_s : linear drift of the offset with simulated time, A/s.
    noise_rms_a : white Gaussian noise RMS, A.
    mains_hz : mains line frequency, 0 (no hum), 50 or 60 Hz.
    mains_rms_a : RMS of the hum (line and harmonics together), A.
    seed : seed of the noise (and, offset by one, of the hum phases).

    """

    def __init__(self, *, current_gain: float = 1.0, current_offset_a: float = 0.0,
                 current_offset_drift_a_per_s: float = 0.0, noise_rms_a: float = 0.0,
                 mains_hz: float = 0.0, mains_rms_a: float = 0.0, seed: int = 0):
        for name, value in (('current_gain', current_gain), ('current_offset_a', current_offset_a),
                            ('current_offset_drift_a_per_s', current_offset_drift_a_per_s),
                            ('noise_rms_a', noise_rms_a), ('mains_rms_a', mains_rms_a)):
            if not math.isfinite(float(value)):
                raise ParameterError(f"parameter '{name}' must be finite, got {value!r}")
        for name, value in (('noise_rms_a', noise_rms_a), ('mains_rms_a', mains_rms_a)):
            if value < 0:
                raise ParameterError(f"parameter '{name}' must be >= 0, got {value!r}")
        if mains_hz not in (0, 50, 60):
            raise ParameterError(f"parameter 'mains_hz' must be 0, 50 or 60, got {mains_hz!r}")
        self.current_gain = float(current_gain)
        self.current_offset_a = float(current_offset_a)
        self.current_offset_drift_a_per_s = float(current_offset_drift_a_per_s)
        self.noise_rms_a = float(noise_rms_a)
        self.mains_hz = float(mains_hz)
        self.mains_rms_a = float(mains_rms_a)
        self._rng = np.random.default_rng(seed)
        rel = np.asarray(HUM_HARMONICS)
        self._hum_amplitudes = self.mains_rms_a * rel / math.sqrt(float(np.sum(rel ** 2)) / 2)
        self._hum_phases = np.random.default_rng(seed + 1).uniform(0, 2 * np.pi, rel.size)

    def apply(self, time_s, current_a) -> np.ndarray:
        """Return the measured current, A, for the sensor current at simulated times."""
        i = self.current_gain * np.asarray(current_a, float) + self.current_offset_a
        if self.current_offset_drift_a_per_s:
            i = i + self.current_offset_drift_a_per_s * np.asarray(time_s, float)
        if self.noise_rms_a > 0:
            i = i + self._rng.normal(0.0, self.noise_rms_a, i.shape)
        if self.mains_hz and self.mains_rms_a:
            t = np.asarray(time_s, float)
            for k, (a, phase) in enumerate(zip(self._hum_amplitudes, self._hum_phases), start=1):
                i = i + a * np.sin(2 * np.pi * k * self.mains_hz * t + phase)
        return i
