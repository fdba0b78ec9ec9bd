# SPDX-License-Identifier: Apache-2.0
"""
The exact sensor of the scenario library, typed in from the paper (no package code).

Reference: Z. Chen, X. Tan, A. Will, C. Ziel, "A dynamic model for ionic polymer-metal
composite sensors", Smart Mater. Struct. 16 (2007) 1477-1488 ("the paper").  The material is
the paper's Table 1 (constants, measured values) and Table 2 (fitted values); the samples are
its Table 3 (thickness 360 um, h = 180 um) plus one geometry of the library's own.

The transfer function is H2 (eq. 45): H1 (eq. 31) times the surface-resistance factor,

    H2(s) = 3 s Y W (beta h coth(beta h) - 1) / (alpha0 L^3 beta^2)
            * (1 - cosh a + a sinh a) / (B cosh a),

with beta^2 = (s + K)/d (after eq. 14), K = F^2 d C- / (kappa_e R T) (after eq. 12, with
1 - C- dV = 1 as in section 5.2), B = s kappa_e r0 / h (eq. 42) and a = L sqrt(B).  Written
with phi(z) = (z coth z - 1)/z^2 and F(a) = (1 - cosh a + a sinh a)/(a^2 cosh a) (so that
B = a^2/L^2):

    H2(s) = 3 s Y W h^2 phi(beta h) F(a) / (alpha0 L),     F(0) = 1/2 (eq. 46: H2 = H1).

F is evaluated as (1 - e^-a)(a (1 + e^-a) - (1 - e^-a)) / (a^2 (1 + e^-2a)) (multiply
numerator and denominator of 2 sinh(a/2)(a cosh(a/2) - sinh(a/2)) / (a^2 cosh a) by e^-a):
no overflow for large a, no cancellation for small a (1 - e^-a by ``expm1``).  phi uses
coth z = (1 + e^-2z)/(1 - e^-2z); with the paper's material |beta h| >= h sqrt(K/d), about
150-265 for these samples, where phi has no cancellation (smaller |z| is refused).

A sensor may add the first-order pole of its current amplifier, 1/(1 + s/(2 pi f_a)).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .motions import min_jerk

__all__ = ['MATERIAL', 'GEOMETRIES', 'Sensor', 'transfer', 'frequency_response',
           'slowest_time_constant_s']

#: The paper's Tables 1-2 (SI units), typed in here.
MATERIAL = {
    'faraday_constant_c_per_mol': 96487.0,       # F, Table 1
    'gas_constant_j_per_mol_k': 8.3143,          # R, Table 1
    'temperature_k': 300.0,                      # T, Table 1
    'youngs_modulus_pa': 5.71e8,                 # Y, Table 1
    'surface_resistance_ohm': 6.05,              # r0, Table 1
    'diffusivity_m2_per_s': 3.32e-11,            # d, Table 2
    'anion_concentration_mol_per_m3': 1091.0,    # C-, Table 2
    'permittivity_f_per_m': 1.88e-3,             # kappa_e, Table 2
    'charge_stress_coupling_j_per_c': 104.0,     # alpha0, Table 2
}

#: (length_m, width_m, thickness_m): Table 3 (thickness 360 um = 2h, h = 180 um of Table 1)
#: and ``narrow``, a longer, thinner strip of the same sheet chemistry (30 x 5 x 0.2 mm).
GEOMETRIES = {
    'big': (22e-3, 14e-3, 360e-6),
    'slim': (22e-3, 7e-3, 360e-6),
    'short': (11e-3, 7e-3, 360e-6),
    'narrow': (30e-3, 5e-3, 200e-6),
}


@dataclass(frozen=True)
class Sensor:
    """
    One sample of the paper's material, with an optional current-amplifier pole.

    sample : a key of :data:`GEOMETRIES`.
    amplifier_corner_hz : -3 dB corner of a first-order amplifier pole, Hz (None: none).
    """

    sample: str
    amplifier_corner_hz: float | None = None

    @property
    def geometry(self) -> tuple[float, float, float]:
        """(length_m, width_m, thickness_m)."""
        return GEOMETRIES[self.sample]

    @property
    def model_effects(self) -> str:
        """Return what the user would add to ``h2``: ``SensorModel.named('h2', g, effects)``."""
        if self.amplifier_corner_hz is None:
            return ''
        return f'amplifier_bandwidth(corner_hz={self.amplifier_corner_hz:g})'


def _k_rate_per_s() -> float:
    """K = F^2 d C- / (kappa_e R T), s^-1 (definition after eq. 12, 1 - C- dV = 1)."""
    m = MATERIAL
    return (m['faraday_constant_c_per_mol'] ** 2 * m['diffusivity_m2_per_s']
            * m['anion_concentration_mol_per_m3']
            / (m['permittivity_f_per_m'] * m['gas_constant_j_per_mol_k'] * m['temperature_k']))


def _phi(z: np.ndarray) -> np.ndarray:
    """(z coth z - 1)/z^2 for Re z > 0 and |z| >= 2 (eq. 31's thickness term over z^2)."""
    if z.size and np.min(np.abs(z)) < 2.0:
        raise ValueError(f'bench/scenarios/sensor.py: |beta h| = {np.min(np.abs(z)):.3g} < 2, '
                         'outside the range this evaluation of eq. 31 is written for')
    e2 = np.exp(-2.0 * z)
    coth = (1.0 + e2) / -np.expm1(-2.0 * z)
    return (z * coth - 1.0) / z ** 2


def _surface_factor(a: np.ndarray) -> np.ndarray:
    """F(a) = (1 - cosh a + a sinh a)/(a^2 cosh a), Re a >= 0; F(0) = 1/2 (eq. 46)."""
    out = np.full(a.shape, 0.5, dtype=complex)
    nz = a != 0
    an = a[nz]
    e1 = np.exp(-an)
    one_minus = -np.expm1(-an)
    out[nz] = one_minus * (an * (1.0 + e1) - one_minus) / (an ** 2 * (1.0 + e1 ** 2))
    return out


def transfer(sensor: Sensor, s) -> np.ndarray:
    """
    i(s)/w(s) of ``sensor``, A m^-1: H2 (eq. 45) times the amplifier pole if any.

    ``s``: complex frequencies, rad s^-1, with Re s >= 0 (the imaginary axis is what the
    library uses).
    """
    s = np.asarray(s, dtype=complex)
    m = MATERIAL
    length, width, thickness = sensor.geometry
    h = 0.5 * thickness
    z = h * np.sqrt((s + _k_rate_per_s()) / m['diffusivity_m2_per_s'])
    tau_r = m['permittivity_f_per_m'] * m['surface_resistance_ohm'] * length ** 2 / h
    a = np.sqrt(s * tau_r)                 # a = L sqrt(B), B of eq. 42
    out = (3.0 * s * m['youngs_modulus_pa'] * width * h ** 2 * _phi(z) * _surface_factor(a)
           / (m['charge_stress_coupling_j_per_c'] * length))
    if sensor.amplifier_corner_hz is not None:
        out = out / (1.0 + s / (2.0 * math.pi * sensor.amplifier_corner_hz))
    return out


def frequency_response(sensor: Sensor, frequency_hz) -> np.ndarray:
    """H(j 2 pi f), A m^-1."""
    return transfer(sensor, 2j * math.pi * np.asarray(frequency_hz, dtype=float))


def slowest_time_constant_s(sensor: Sensor) -> float:
    """
    Longest time constant of the impulse response, s.

    H2/s is meromorphic with real poles: -(K + n^2 pi^2 d / h^2) (coth, eq. 31) and
    -(n - 1/2)^2 pi^2 / tau_r (cosh a = 0, eq. 45), tau_r = kappa_e r0 L^2 / h; plus the
    amplifier pole.
    """
    m = MATERIAL
    length, _, thickness = sensor.geometry
    h = 0.5 * thickness
    rates = [_k_rate_per_s() + math.pi ** 2 * m['diffusivity_m2_per_s'] / h ** 2,
             math.pi ** 2 / 4.0 / (m['permittivity_f_per_m'] * m['surface_resistance_ohm']
                                   * length ** 2 / h)]
    if sensor.amplifier_corner_hz is not None:
        rates.append(2.0 * math.pi * sensor.amplifier_corner_hz)
    return 1.0 / min(rates)


def _lagrange_cubic(y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Value of the samples ``y`` (unit spacing) at fractional indices ``x`` (4-point cubic)."""
    k = np.clip(np.floor(x).astype(np.int64), 1, y.size - 3)
    u = x - k
    return (-u * (u - 1) * (u - 2) / 6 * y[k - 1] + (u + 1) * (u - 1) * (u - 2) / 2 * y[k]
            - (u + 1) * u * (u - 2) / 2 * y[k + 1] + (u + 1) * u * (u - 1) / 6 * y[k + 2])


def sensor_current(sensor: Sensor, motion, sample_times_s, sample_rate_hz: float, *,
                   oversample: int = 4, settle_time_constants: float = 30.0) -> np.ndarray:
    """
    Short-circuit current (A) of ``sensor`` at ``sample_times_s`` for the tip motion ``motion``.

    The convolution of the deflection with the impulse response of :func:`transfer`, by FFT on
    a grid ``oversample`` times finer than ``sample_rate_hz``, with nothing wrapping and no
    edge ringing:

    * **pre-roll**: the grid starts ``settle_time_constants`` + 10 slowest time constants tau
      (:func:`slowest_time_constant_s`) before the first sample; the motion (defined for all
      times: one going on since before the record has been going there too) is taken relative
      to its value there (H(0) = 0: a constant makes no current) and faded in by a
      minimum-jerk ramp over the first 10 tau, so its start has decayed by
      e^-settle_time_constants (1e-13) when the record begins;
    * after the last sample it is faded out over 10 tau and followed by zero padding of
      ``settle_time_constants`` tau: the circular convolution wraps nothing into the record,
      and a smooth signal has no edge for the band-limited kernel to ring on;
    * the DAQ samples the current at its instants: grid points when the instants lie on the
      grid, else 4-point cubic interpolation (error ~ (omega dt)^4 / 40 at frequency omega,
      below 1e-7 of a 20 Hz component for a 1 kHz record).
    """
    t = np.asarray(sample_times_s, dtype=float)
    dt = 1.0 / (sample_rate_hz * oversample)
    tau = slowest_time_constant_s(sensor)
    n_ramp = int(math.ceil(10.0 * tau / dt))
    n_settle = int(math.ceil(settle_time_constants * tau / dt))
    t0 = t[0] - (n_ramp + n_settle) * dt
    n_grid = int(math.ceil((t[-1] - t0) / dt)) + 4
    n_total = n_grid + n_ramp
    t_grid = t0 + dt * np.arange(n_total)
    k = np.arange(n_total)
    fade = min_jerk(k / n_ramp) * min_jerk((n_total - 1 - k) / n_ramp)
    w = (motion(t_grid) - motion(np.array([t0]))[0]) * fade
    n_fft = _fast_length(n_total + n_settle)
    f = np.fft.rfftfreq(n_fft, dt)
    i_grid = np.fft.irfft(np.fft.rfft(w, n_fft) * frequency_response(sensor, f), n_fft)[:n_grid]
    x = (t - t0) / dt
    on_grid = np.abs(x - np.round(x)) < 1e-6
    if on_grid.all():
        return i_grid[np.round(x).astype(np.int64)]
    return _lagrange_cubic(i_grid, x)


def _fast_length(n: int) -> int:
    """Smallest 2^p 3^q 5^r >= n (a fast FFT length)."""
    from scipy.fft import next_fast_len
    return next_fast_len(int(n), real=True)
