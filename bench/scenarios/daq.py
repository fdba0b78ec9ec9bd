# SPDX-License-Identifier: Apache-2.0
"""
What a real DAQ does to the sensing current, and the :class:`Record` it produces.

The current is sampled on the DAQ's clock (or, for a software-timed DAQ, when the host gets
to it), an amplifier offset (constant, drifting, wandering) and mains hum (fundamental within
0.3 Hz of 50/60 Hz, 2nd and 3rd harmonics) add to it, white noise, then an ADC quantises it
over its range; the host stamps each row with its own clock (jitter) and loses rows (single
rows and bursts).  Every random number comes from the ``rng`` the scenario passes in.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .sensor import Sensor, sensor_current

__all__ = ['Daq', 'Record', 'acquire']


@dataclass(frozen=True)
class Daq:
    """
    One DAQ set-up; amounts are already drawn (the scenario draws them from its seed).

    noise_a / noise_fraction : white noise RMS, A, and as a fraction of the clean current's
        RMS over the record (combined in quadrature).
    offset_a, offset_drift_a_per_s, offset_walk_a_per_sqrt_s : offset at t = 0, its linear
        drift, and a random walk on top (A per square root of second).
    offset_steps : (time_s, step_a) pairs: the offset steps by step_a at time_s (an amplifier
        re-zeroed, a range switched).
    mains_hz : hum fundamental (e.g. 50.17), 0 for none; ``hum_fraction`` of the clean
        current's RMS (``hum_of='rms'``) or peak (``'peak'``); ``hum_harmonics``: amplitudes of
        the 2nd and 3rd harmonics relative to the fundamental; ``hum_phases_rad``: 3 phases.
    stamp_jitter : host stamps spread uniformly within +-``stamp_jitter`` periods;
        ``jitter_kind`` 'host': the DAQ samples on its clock, the host stamps late or early;
        'sampled': a software-timed DAQ samples when it stamps.
    drop_fraction, drop_bursts, burst_rows : rows lost one by one (fraction), and
        ``drop_bursts`` bursts of ``burst_rows`` = (min, max) consecutive rows.
    adc_bits, full_scale_a : quantisation over +-full_scale_a (0 bits: none; full scale 0:
        the smallest 1-2-5 range above 1.5 x the largest current).
    time_origin_s : the host clock at the record start (a ROS stamp is seconds since 1970).
    """

    sample_rate_hz: float = 1000.0
    noise_a: float = 0.0
    noise_fraction: float = 0.0
    offset_a: float = 0.0
    offset_drift_a_per_s: float = 0.0
    offset_walk_a_per_sqrt_s: float = 0.0
    offset_steps: tuple = ()
    mains_hz: float = 0.0
    hum_fraction: float = 0.0
    hum_of: str = 'rms'
    hum_harmonics: tuple = (0.3, 0.2)
    hum_phases_rad: tuple = (0.0, 0.0, 0.0)
    stamp_jitter: float = 0.0
    jitter_kind: str = 'host'
    drop_fraction: float = 0.0
    drop_bursts: int = 0
    burst_rows: tuple = (5, 50)
    adc_bits: int = 0
    full_scale_a: float = 0.0
    time_origin_s: float = 0.0


@dataclass
class Record:
    """
    One generated record: what the user gets, and the truth to judge an estimate by.

    Rows (what the DAQ/host delivers, dropped rows removed): ``time_s`` host stamps (s, from
    ``time_origin_s``), ``current_a``; truth per row: ``deflection_m`` at the instant the row
    was sampled (``sample_time_s``, s since the record start), ``offset_a`` and ``hum_a``
    contained in ``current_a``.  ``grid_current_a`` / ``grid_deflection_m``: every sample of
    the nominal grid n / ``sample_rate_hz`` (no drops, no jitter) with offset and hum removed
    (clean current + the same white noise + quantisation error): the bounds' input;
    ``grid_pre_current_a`` / ``grid_post_current_a`` the same for grid samples before and
    after the record (the estimator does not see them): the causal bound starts before a
    record whose motion went on before it (``stationary``), the non-causal one sees past its
    end.
    ``noise_std_a`` is the white-noise RMS, ``lsb_a`` the quantisation step (0: none).
    ``model`` / ``effects``: the sensor model the user would have, as text for
    ``SensorModel.named(model, geometry, extra_effects=effects)``.
    """

    name: str
    seed: int
    sensor: Sensor
    sample_rate_hz: float
    time_s: np.ndarray
    current_a: np.ndarray
    deflection_m: np.ndarray
    sample_time_s: np.ndarray
    offset_a: np.ndarray
    hum_a: np.ndarray
    grid_current_a: np.ndarray
    grid_deflection_m: np.ndarray
    grid_pre_current_a: np.ndarray
    grid_post_current_a: np.ndarray
    noise_std_a: float
    lsb_a: float
    mains_hz: float
    time_origin_s: float = 0.0
    stationary: bool = False
    description: str = ''
    model: str = 'h2'
    tags: tuple = field(default_factory=tuple)

    @property
    def sample(self) -> str:
        return self.sensor.sample

    @property
    def geometry_m(self) -> tuple[float, float, float]:
        """(length_m, width_m, thickness_m)."""
        return self.sensor.geometry

    @property
    def effects(self) -> str:
        return self.sensor.model_effects

    @property
    def duration_s(self) -> float:
        return self.grid_deflection_m.size / self.sample_rate_hz


def _offset(daq: Daq, t: np.ndarray, rng) -> np.ndarray:
    b = daq.offset_a + daq.offset_drift_a_per_s * t
    for time_s, step_a in daq.offset_steps:
        b = b + step_a * (t >= time_s)
    if daq.offset_walk_a_per_sqrt_s:
        dt = 1.0 / daq.sample_rate_hz
        steps = rng.normal(0.0, daq.offset_walk_a_per_sqrt_s * math.sqrt(dt), t.size)
        b = b + np.cumsum(steps) - steps[0]
    return b


def _hum(daq: Daq, t: np.ndarray, amplitude_a: float) -> np.ndarray:
    out = np.zeros(t.size)
    if not daq.mains_hz:
        return out
    amps = (1.0, *daq.hum_harmonics)
    for m, (rel, ph) in enumerate(zip(amps, daq.hum_phases_rad), start=1):
        out += amplitude_a * rel * np.sin(2.0 * math.pi * m * daq.mains_hz * t + ph)
    return out


def _lsb_a(daq: Daq, x: np.ndarray) -> float:
    """Quantisation step of ``daq`` for the signal ``x``, A (0: no quantisation)."""
    if not daq.adc_bits:
        return 0.0
    full_scale = daq.full_scale_a
    if full_scale <= 0.0:
        peak = 1.5 * float(np.max(np.abs(x)))
        decade = 10.0 ** math.floor(math.log10(peak))
        full_scale = next(m * decade for m in (1.0, 2.0, 5.0, 10.0) if m * decade >= peak)
    return 2.0 * full_scale / 2 ** daq.adc_bits


def _quantise(x: np.ndarray, daq: Daq, lsb: float) -> np.ndarray:
    if not lsb:
        return x
    half_range = lsb * 2 ** (daq.adc_bits - 1)
    return np.clip(np.round(x / lsb) * lsb, -half_range, half_range - lsb)


def _kept_rows(daq: Daq, n: int, rng) -> np.ndarray:
    keep = rng.random(n) >= daq.drop_fraction
    for _ in range(daq.drop_bursts):
        length = int(rng.integers(daq.burst_rows[0], daq.burst_rows[1] + 1))
        start = int(rng.integers(1, max(2, n - length)))
        keep[start:start + length] = False
    keep[0] = True
    return keep


def _grid_current(sensor, motion, daq: Daq, parts: dict, lsb: float) -> np.ndarray:
    """Return the bounds' input on the nominal grid: clean + noise + quantisation error."""
    if not parts['sampled']:
        return parts['measured'] - parts['offset'] - parts['hum']
    nominal = parts['nominal']
    clean = sensor_current(sensor, motion, nominal, daq.sample_rate_hz)
    hum = _hum(daq, nominal, parts['hum_amp'])
    total = clean + parts['offset'] + hum + parts['noise']
    return _quantise(total, daq, lsb) - parts['offset'] - hum


def _outside_current(sensor, motion, daq: Daq, t: np.ndarray, noise_std: float, lsb: float,
                     offset_a: float, rng) -> np.ndarray:
    """
    Return the current at grid times ``t`` outside the record (clean + noise + quantisation).

    What the bounds' filters may see before and after the record (the estimator does not get
    it).  Drawn after everything else, so the record does not depend on it.
    """
    if t.size == 0:
        return np.zeros(0)
    total = sensor_current(sensor, motion, t, daq.sample_rate_hz) + offset_a
    total = total + (rng.normal(0.0, noise_std, t.size) if noise_std > 0 else 0.0)
    return _quantise(total, daq, lsb) - offset_a


def acquire(name: str, seed: int, sensor: Sensor, motion, duration_s: float, daq: Daq, rng, *,
            stationary: bool = False, description: str = '', tags: tuple = (),
            pre_record_s: float = 0.0, post_record_s: float = 0.0) -> Record:
    """
    Sample the current of ``sensor`` under ``motion`` for ``duration_s`` through ``daq``.

    The clean current is :func:`~.sensor.sensor_current` (exact H2, FFT with pre-roll and
    padding) at the instants the DAQ samples.  ``pre_record_s`` / ``post_record_s``: lengths
    of ``grid_pre_current_a`` / ``grid_post_current_a`` kept for the bounds.
    """
    fs = daq.sample_rate_hz
    n = int(round(duration_s * fs))
    nominal = np.arange(n) / fs
    jitter = (rng.uniform(-daq.stamp_jitter, daq.stamp_jitter, n) / fs if daq.stamp_jitter
              else np.zeros(n))
    sampled = daq.jitter_kind == 'sampled' and daq.stamp_jitter > 0
    instants = nominal + jitter if sampled else nominal
    clean = sensor_current(sensor, motion, instants, fs)
    rms = float(np.sqrt(np.mean(clean ** 2)))
    noise_std = math.hypot(daq.noise_a, daq.noise_fraction * rms)
    noise = rng.normal(0.0, noise_std, n) if noise_std > 0 else np.zeros(n)
    offset = _offset(daq, nominal, rng)
    hum_amp = daq.hum_fraction * (rms if daq.hum_of == 'rms' else float(np.max(np.abs(clean))))
    hum = _hum(daq, instants, hum_amp)
    lsb = _lsb_a(daq, clean + offset + hum + noise)
    measured = _quantise(clean + offset + hum + noise, daq, lsb)
    keep = _kept_rows(daq, n, rng)
    parts = dict(sampled=sampled, nominal=nominal, measured=measured, offset=offset, hum=hum,
                 hum_amp=hum_amp, noise=noise)
    grid_current = _grid_current(sensor, motion, daq, parts, lsb)
    pre, post = (_outside_current(sensor, motion, daq, t, noise_std, lsb, float(offset[0]), rng)
                 for t in (np.arange(-int(round(pre_record_s * fs)), 0) / fs,
                           (n + np.arange(int(round(post_record_s * fs)))) / fs))
    grid_deflection = motion(nominal)
    deflection = motion(instants) if sampled else grid_deflection
    return Record(name=name, seed=seed, sensor=sensor, sample_rate_hz=fs,
                  time_s=daq.time_origin_s + (nominal + jitter)[keep], current_a=measured[keep],
                  deflection_m=deflection[keep], sample_time_s=instants[keep],
                  offset_a=offset[keep], hum_a=hum[keep], grid_current_a=grid_current,
                  grid_deflection_m=grid_deflection, grid_pre_current_a=pre,
                  grid_post_current_a=post,
                  noise_std_a=noise_std, lsb_a=lsb, mains_hz=daq.mains_hz,
                  time_origin_s=daq.time_origin_s, stationary=stationary,
                  description=description, tags=tuple(tags))
