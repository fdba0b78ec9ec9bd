# SPDX-License-Identifier: Apache-2.0
"""
The scenarios: a name, a class (tag), and a builder that draws everything from the seed.

Every random quantity of a record (phases, amplitudes, levels, offsets, hum level and
frequency, jitter, dropped rows, noise) comes from ``numpy.random.default_rng([seed,
crc32(name)])``: seed k of two scenarios are independent, and any integer is a fresh seed.
Deflections are of the paper's size (the crank rig moves the tip +-2 mm, section 5.1).
"""
from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from .daq import acquire, Daq, Record
from .motions import Crank, FreeVibration, MinJerkPath, Sines, Sum, Windowed
from .sensor import Sensor

__all__ = ['Scenario', 'SCENARIOS', 'QUICK', 'build', 'names']

MM = 1e-3
NA = 1e-9
#: Host clock at a record start: seconds since 1970 (a ROS stamp), drawn within a year.
EPOCH_S = 1.7e9


@dataclass(frozen=True)
class Scenario:
    """
    A named scenario: ``build(seed)`` returns its :class:`~.daq.Record`.

    ``stationary``: zero-mean motion going on since before power-on; ``moving_at_start``: the
    tip moves when the record starts (implied by ``stationary``).  Either way the record keeps
    the current before it for the bounds (``grid_pre_current_a``).
    """

    name: str
    tag: str
    duration_s: float
    make: Callable
    description: str
    stationary: bool = False
    moving_at_start: bool = False

    def build(self, seed: int) -> Record:
        rng = np.random.default_rng([int(seed), zlib.crc32(self.name.encode())])
        sensor, motion, daq = self.make(rng)
        return acquire(self.name, int(seed), sensor, motion, self.duration_s, daq, rng,
                       stationary=self.stationary, description=self.description,
                       tags=(self.tag,),
                       pre_record_s=(max(3 * self.duration_s, 60.0)
                                     if self.stationary or self.moving_at_start else 0.0),
                       post_record_s=min(self.duration_s, 60.0))


def _hum(rng, nominal_hz: float, fraction: float, of: str = 'rms') -> dict:
    """Mains hum within 0.3 Hz of ``nominal_hz``, harmonics 2 and 3 at 0.1-0.5 of it."""
    return dict(mains_hz=nominal_hz + rng.uniform(-0.3, 0.3), hum_fraction=fraction, hum_of=of,
                hum_harmonics=tuple(rng.uniform(0.1, 0.5, 2)),
                hum_phases_rad=tuple(rng.uniform(0, 2 * math.pi, 3)))


def _crank(rng, frequency_hz: float, from_rest: bool) -> Crank:
    """Draw the paper's rig: crank radius 1.8-2.2 mm (2 mm amplitude), rod 15-25 mm."""
    return Crank(frequency_hz, rng.uniform(1.8, 2.2) * MM, rng.uniform(15, 25) * MM,
                 phase_rad=rng.uniform(0, 2 * math.pi),
                 start_s=rng.uniform(0.2, 0.5) if from_rest else None,
                 wobble=rng.uniform(0.0, 0.01), wobble_hz=rng.uniform(0.1, 0.5))


def _noise(rng, kind: str) -> dict:
    """'0.2na': 0.2 nA RMS; 'pct': 1-2 % of the current RMS."""
    if kind == '0.2na':
        return dict(noise_a=0.2 * NA)
    return dict(noise_fraction=rng.uniform(0.01, 0.02))


def _crank_maker(frequency_hz: float, sample: str, noise: str, from_rest: bool):
    def make(rng):
        motion = _crank(rng, frequency_hz, from_rest)
        daq = Daq(offset_a=rng.uniform(0, 20) * NA, **_noise(rng, noise))
        return Sensor(sample), motion, daq
    return make


def _crank_stop(rng):
    """Draw a 2-5 Hz crank from rest that stops at 5-7 s (in 0.1-0.5 s) and holds there."""
    crank = replace(_crank(rng, rng.uniform(2.0, 5.0), True), stop_s=rng.uniform(5.0, 7.0),
                    stop_duration_s=rng.uniform(0.1, 0.5))
    return Sensor('slim'), crank, Daq(offset_a=rng.uniform(0, 20) * NA, **_noise(rng, 'pct'))


def _sines(rng, n: int, lo_hz: float, hi_hz: float, lo_m: float, hi_m: float) -> Sines:
    return Sines(tuple(np.exp(rng.uniform(math.log(lo_hz), math.log(hi_hz), n))),
                 tuple(rng.uniform(lo_m, hi_m, n)), tuple(rng.uniform(0, 2 * math.pi, n)))


def _path(rng, first_s: float, stop_s: float, gap_s: tuple, move_s: float,
          level_m: float) -> MinJerkPath:
    """Draw holds of ``gap_s`` = (min, max) s joined by ``move_s`` moves to levels +-level_m."""
    starts, t = [], first_s
    while t + move_s < stop_s:
        starts.append(t)
        t += move_s + rng.uniform(*gap_s)
    levels = (0.0, *rng.uniform(-level_m, level_m, len(starts)))
    return MinJerkPath(tuple(starts), (move_s,) * len(starts), levels)


def _motion_hold(rng):
    sines = Windowed(_sines(rng, 2, 0.5, 3.0, 0.3 * MM, 0.8 * MM), 0.3, 8.0, 0.5)
    final = rng.choice([-1, 1]) * rng.uniform(0.3, 1.0) * MM
    motion = Sum((sines, MinJerkPath((5.0,), (2.5,), (0.0, final))))
    return Sensor('slim'), motion, Daq(offset_a=5 * NA, noise_a=0.2 * NA)


def _jitter_hum(rng):
    daq = Daq(sample_rate_hz=2000.0, offset_a=rng.uniform(5, 15) * NA,
              noise_fraction=rng.uniform(0.005, 0.01), **_hum(rng, 60.0, 0.02),
              stamp_jitter=0.04, drop_fraction=0.005, drop_bursts=3, burst_rows=(5, 50),
              time_origin_s=EPOCH_S + rng.uniform(0, 3e7))
    return Sensor('short'), _crank(rng, 5.0, True), daq


def _jitter25(sample: str, frequency_hz: float, kind: str):
    def make(rng):
        daq = Daq(offset_a=rng.uniform(0, 20) * NA, noise_fraction=rng.uniform(0.005, 0.01),
                  stamp_jitter=0.25, jitter_kind=kind, drop_fraction=0.002,
                  time_origin_s=EPOCH_S + rng.uniform(0, 3e7))
        return Sensor(sample), _crank(rng, frequency_hz, True), daq
    return make


def _pick_place(sample: str, minutes: float, hum: bool):
    def make(rng):
        motion = _path(rng, 1.0, 60 * minutes - 0.5, (4.0, 4.0), 0.4, 1.0 * MM)
        start, end = rng.uniform(3, 7) * NA, rng.uniform(20, 30) * NA
        daq = Daq(offset_a=start, offset_drift_a_per_s=(end - start) / (60 * minutes),
                  noise_a=0.5 * NA, adc_bits=16,
                  **(_hum(rng, 50.0, 0.02, 'peak') if hum else {}))
        return Sensor(sample), motion, daq
    return make


def _field_lab(rng):
    sines = _sines(rng, 3, 0.2, 3.0, 0.2 * MM, 0.6 * MM)
    steps = _path(rng, rng.uniform(1.5, 3.0), 59.0, (3.0, 8.0), 0.3, 0.5 * MM)
    daq = Daq(offset_a=15 * NA, noise_fraction=0.02, **_hum(rng, 50.0, 0.03), adc_bits=16)
    return Sensor('slim', amplifier_corner_hz=200.0), Sum((sines, steps)), daq


def _sines_poweron(rng):
    daq = Daq(offset_a=rng.uniform(5, 20) * NA, noise_fraction=rng.uniform(0.01, 0.02))
    return Sensor('slim'), _sines(rng, 3, 0.2, 3.0, 0.3 * MM, 0.8 * MM), daq


def _crank_poweron_20na(rng):
    return Sensor('slim'), _crank(rng, 2.0, False), Daq(offset_a=20 * NA, noise_fraction=0.01)


def _step(offset_a: float):
    def make(rng):
        motion = MinJerkPath((rng.uniform(2.0, 3.0),), (0.05,), (0.0, 2 * MM))
        return Sensor('big'), motion, Daq(offset_a=offset_a, noise_fraction=0.01)
    return make


def _free_vibration(rng):
    motion = FreeVibration(rng.uniform(1.5, 2.5) * MM, 30.0, rng.uniform(0.02, 0.05),
                           push_start_s=1.0, push_s=1.0, release_s=rng.uniform(5.5, 6.0))
    return Sensor('slim'), motion, Daq(offset_a=10 * NA, noise_fraction=0.01)


def _strong_hum(rng):
    daq = Daq(offset_a=rng.uniform(5, 15) * NA, noise_fraction=rng.uniform(0.005, 0.01),
              **_hum(rng, 50.0, rng.uniform(0.2, 0.4)))
    return Sensor('slim'), _crank(rng, 5.0, True), daq


def _offset_step(rng):
    motion = _path(rng, 1.0, 29.5, (2.0, 4.0), 0.4, 1.0 * MM)
    size = math.exp(rng.uniform(math.log(2.0), math.log(60.0)))      # log-uniform 2-60 nA
    step = (rng.uniform(10, 20), rng.choice([-1, 1]) * size * NA)
    daq = Daq(offset_a=rng.uniform(3, 10) * NA, noise_a=rng.choice([0.2, 2.0]) * NA,
              adc_bits=16, offset_steps=(step,))
    return Sensor('slim'), motion, daq


def _coarse_adc(rng):
    """Draw a 2-5 Hz crank after a 1-2 s rest, a 12-bit ADC whose step is ~100 x the noise."""
    crank = replace(_crank(rng, rng.uniform(2.0, 5.0), True), start_s=rng.uniform(1.0, 2.0))
    daq = Daq(offset_a=rng.uniform(5, 20) * NA, noise_a=0.2 * NA, adc_bits=12)
    return Sensor('slim'), crank, daq


def _hour_drift(rng):
    bursts, steps, t = [], [], rng.uniform(20, 60)
    while t < 3540:
        length = rng.uniform(10, 60)
        bursts.append(Windowed(_sines(rng, 2, 0.5, 5.0, 0.3 * MM, 1.0 * MM), t, t + length, 1.0))
        steps.append(t + length - 0.5)
        t += length + rng.uniform(60, 240)
    path = MinJerkPath(tuple(steps), (0.4,) * len(steps),
                       (0.0, *rng.uniform(-1, 1, len(steps)) * MM))
    daq = Daq(offset_a=rng.uniform(5, 15) * NA,
              offset_drift_a_per_s=rng.uniform(-1, 1) * NA / 60,
              offset_walk_a_per_sqrt_s=0.02 * NA, noise_a=0.5 * NA, adc_bits=16,
              **_hum(rng, 50.0, 0.005, 'peak'))
    return Sensor('slim'), Sum((*bursts, path)), daq


def _scenarios() -> list[Scenario]:
    out = [
        Scenario('slim-motion-hold-0.2na', 'hold', 12.0, _motion_hold,
                 'slim, 8 s of motion from rest, unlearned 5 nA offset, then a 4 s perfect hold; '
                 'DAQ noise 0.2 nA'),
        Scenario('short-2khz-jitter-hum', 'jitter', 20.0, _jitter_hum,
                 'short, 5 Hz crank from rest, 2 kHz host-stamped DAQ: +-4 % stamp jitter, '
                 '0.5 % dropped rows + 3 bursts, 60 Hz hum 2 % of RMS'),
        Scenario('big-pick-place-10min', 'pick-place', 600.0, _pick_place('big', 10, True),
                 'big, 10 min pick-and-place (0.4 s moves, 4 s holds, +-1 mm), offset drifting '
                 '5 -> 25 nA, 50 Hz hum 2 % of the peak current, 0.5 nA, 16 bit'),
        Scenario('slim-field-lab', 'field', 60.0, _field_lab,
                 'slim, 0.2-3 Hz sines since power-on with step-and-holds on top (never still), '
                 '200 Hz amplifier, 15 nA offset, 50 Hz hum 3 %, noise 2 %, 16 bit',
                 moving_at_start=True),
        Scenario('slim-crank-poweron-20na', 'crank', 30.0, _crank_poweron_20na,
                 'slim, 2 Hz crank moving since before power-on, 20 nA offset, noise 1 %',
                 stationary=True),
        Scenario('big-step-held', 'hold', 15.0, _step(0.0),
                 'big, 2 mm step (50 ms) held 12 s, noise 1 %, no offset'),
        Scenario('big-step-held-10na', 'hold', 15.0, _step(10 * NA),
                 'big, 2 mm step (50 ms) held 12 s, noise 1 %, 10 nA offset'),
        Scenario('slim-free-vibration-30hz', 'vibration', 10.0, _free_vibration,
                 'slim, pushed from rest to 1.5-2.5 mm, held, released: 30 Hz decay; 1 %, 10 nA'),
        Scenario('slim-sines-poweron', 'sines', 60.0, _sines_poweron,
                 'slim, 0.2-3 Hz sines since before power-on (never still), 1-2 %',
                 stationary=True),
        Scenario('slim-hour-drift', 'drift', 3600.0, _hour_drift,
                 'slim, 1 h: bursts of motion every 1-5 min ending at new holds (+-1 mm), '
                 'offset 5-15 nA drifting +-1 nA/min + random walk, 0.5 nA, 0.5 % hum, 16 bit'),
        Scenario('short-jitter25-sampled', 'jitter', 20.0, _jitter25('short', 2.0, 'sampled'),
                 'short, 2 Hz crank from rest, software-timed DAQ sampling at +-25 % jittered '
                 'instants, 0.2 % dropped rows'),
        Scenario('slim-jitter25-host', 'jitter', 20.0, _jitter25('slim', 5.0, 'host'),
                 'slim, 5 Hz crank from rest, host stamps +-25 % of the period off the DAQ '
                 'clock, 0.2 % dropped rows'),
        Scenario('slim-strong-hum', 'daq', 20.0, _strong_hum,
                 'slim, 5 Hz crank from rest, an unshielded lead: hum 20-40 % of the current '
                 'RMS, 50 Hz +-0.3 Hz with harmonics; noise 0.5-1 %'),
        Scenario('slim-offset-step', 'daq', 30.0, _offset_step,
                 'slim, 30 s pick-and-place (0.4 s moves, 2-4 s holds, +-1 mm); the amplifier '
                 're-zeroed or its range switched once (offset steps by 2-60 nA, '
                 'log-uniform, at 10-20 s); noise 0.2 or 2 nA, 16 bit'),
        Scenario('slim-coarse-adc', 'daq', 20.0, _coarse_adc,
                 'slim, 2-5 Hz crank after a 1-2 s rest, 12-bit ADC (its step 10-25 nA, '
                 '50-120 times the 0.2 nA noise: a still reading sits on one code), '
                 'offset 5-20 nA'),
        Scenario('narrow-pick-place-2min', 'pick-place', 120.0, _pick_place('narrow', 2, False),
                 'narrow (30 x 5 x 0.2 mm), 2 min pick-and-place, offset drifting 5 -> 25 nA, '
                 '0.5 nA, 16 bit'),
        Scenario('slim-crank-stop', 'crank', 12.0, _crank_stop,
                 'slim, 2-5 Hz crank from rest that stops at 5-7 s (in 0.1-0.5 s) and holds '
                 'where it stopped, noise 1-2 %, offset 0-20 nA'),
        Scenario('crank-5hz-narrow-pct-rest', 'crank', 20.0,
                 _crank_maker(5.0, 'narrow', 'pct', True),
                 'narrow (30 x 5 x 0.2 mm), 5 Hz crank from rest, noise 1-2 %'),
    ]
    for f in (1, 5, 20):
        for sample in ('slim', 'short'):
            for noise in ('0.2na', 'pct'):
                for rest in (True, False):
                    start = 'rest' if rest else 'poweron'
                    out.append(Scenario(
                        f'crank-{f}hz-{sample}-{noise}-{start}', 'crank', 20.0,
                        _crank_maker(float(f), sample, noise, rest),
                        f'{sample}, {f} Hz crank '
                        f"{'from rest' if rest else 'since before power-on'}, noise "
                        f"{'0.2 nA' if noise == '0.2na' else '1-2 %'}, offset 0-20 nA",
                        stationary=not rest))
    return out


#: Every scenario by name.
SCENARIOS: dict[str, Scenario] = {s.name: s for s in _scenarios()}

#: A few short scenarios of different classes (a smoke run of the bench).
QUICK = ('crank-5hz-slim-pct-rest', 'crank-20hz-short-0.2na-poweron', 'slim-motion-hold-0.2na',
         'big-step-held-10na', 'slim-free-vibration-30hz', 'short-2khz-jitter-hum')


def names() -> list[str]:
    return list(SCENARIOS)


def build(name: str, seed: int = 0) -> Record:
    """Return the record of scenario ``name`` for ``seed``."""
    try:
        scenario = SCENARIOS[name]
    except KeyError:
        raise KeyError(f'unknown scenario {name!r}; known: {", ".join(SCENARIOS)}') from None
    return scenario.build(seed)
