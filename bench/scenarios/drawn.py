# SPDX-License-Identifier: Apache-2.0
"""
Drawn records: every ingredient at random, for the cases the named scenarios did not think of.

The named library (:mod:`.library`) holds the cases someone wrote down; a record here draws
its motion (pick-and-place moves, a crank from rest at 0.5-25 Hz, slow sines ending in a hold,
a free vibration at 10-40 Hz), the sample (the paper's two and two other geometries), the
DAQ (500 / 1000 / 2000 Hz, an offset within +-40 nA, white noise 0.1-3 nA or 0.3-2 % of the
current RMS) and, each with its own chance, a drifting offset, mains hum 0.5-30 % at 50/60
+-0.3 Hz, quantisation, host or sampling jitter up to +-25 % of the period, dropped rows and
bursts, an offset step of 2-60 nA (an amplifier re-zeroed) anywhere, an amplifier pole.  Record
``index`` is ``numpy.random.default_rng([index, crc32('drawn')])``'s: any integer is a fresh
record, and the same integer is the same record on every machine.
"""
from __future__ import annotations

import math

from .daq import Daq, Record
from .library import EPOCH_S, MM, NA, Scenario, _crank, _hum, _path, _sines
from .motions import FreeVibration, MinJerkPath, Sum, Windowed
from .sensor import Sensor

__all__ = ['draw', 'DRAWN_DURATION_S']

#: Length of a drawn record, s.
DRAWN_DURATION_S = 20.0


def _log_uniform(rng, lo: float, hi: float) -> float:
    return math.exp(rng.uniform(math.log(lo), math.log(hi)))


def _motion(rng, kind: str, duration_s: float, info: dict):
    """Draw the tip's motion of ``kind``; say what it is in ``info['motion']``."""
    if kind == 'pick':
        motion = _path(rng, rng.uniform(0.5, 2.0), duration_s - 0.5,
                       (rng.uniform(0.3, 1.5), rng.uniform(2.0, 5.0)),
                       rng.uniform(0.1, 1.0), rng.uniform(0.2, 2.0) * MM)
        info['motion'] = f'pick-and-place, {len(motion.starts_s)} moves'
    elif kind == 'crank':
        f = _log_uniform(rng, 0.5, 25.0)
        motion = _crank(rng, f, True)
        info['motion'] = f'crank {f:.2f} Hz from rest'
    elif kind == 'sines-hold':
        a, b = rng.uniform(0.3, 2.0), rng.uniform(0.3, 0.7) * duration_s
        sines = Windowed(_sines(rng, 2, 0.3, 5.0, 0.2 * MM, 0.8 * MM), a, b, 0.5)
        motion = Sum((sines, MinJerkPath((b - 1.0,), (1.5,), (0.0, rng.uniform(-1, 1) * MM))))
        info['motion'] = f'two sines {a:.1f}-{b:.1f} s, then a hold'
    else:
        f = rng.uniform(10.0, 40.0)
        motion = FreeVibration(rng.uniform(0.5, 2.5) * MM, f, rng.uniform(0.02, 0.08),
                               push_start_s=1.0, push_s=1.0,
                               release_s=rng.uniform(0.2, 0.4) * duration_s)
        info['motion'] = f'free vibration {f:.0f} Hz'
    return motion


def _daq(rng, duration_s: float, info: dict) -> Daq:
    """Draw the acquisition; say what it does in ``info``."""
    fs = float(rng.choice([500.0, 1000.0, 2000.0]))
    kw = dict(sample_rate_hz=fs, offset_a=rng.uniform(-40, 40) * NA,
              adc_bits=int(rng.choice([0, 12, 16])))
    info.update(sample_rate_hz=fs, offset_a=kw['offset_a'], adc_bits=kw['adc_bits'])
    if rng.random() < 0.5:
        kw['noise_a'] = info['noise_a'] = _log_uniform(rng, 0.1, 3.0) * NA
    else:
        kw['noise_fraction'] = info['noise_fraction'] = _log_uniform(rng, 0.003, 0.02)
    if rng.random() < 0.4:
        kw['offset_drift_a_per_s'] = info['offset_drift_a_per_s'] = rng.uniform(-2, 2) * NA / 60
    if rng.random() < 0.5:
        kw.update(_hum(rng, float(rng.choice([50.0, 60.0])), _log_uniform(rng, 0.005, 0.3)))
        info.update(mains_hz=kw['mains_hz'], hum_fraction=kw['hum_fraction'])
    if rng.random() < 0.3:
        kw.update(stamp_jitter=rng.uniform(0.0, 0.25), jitter_kind=str(rng.choice(['host',
                                                                                   'sampled'])),
                  time_origin_s=EPOCH_S + rng.uniform(0, 3e7))
        info.update(stamp_jitter=kw['stamp_jitter'], jitter_kind=kw['jitter_kind'])
    if rng.random() < 0.3:
        kw.update(drop_fraction=rng.uniform(0.0, 0.01), drop_bursts=int(rng.integers(0, 3)))
        info.update(drop_fraction=kw['drop_fraction'], drop_bursts=kw['drop_bursts'])
    if rng.random() < 0.25:
        step = (rng.uniform(0.15, 0.85) * duration_s,
                rng.choice([-1, 1]) * _log_uniform(rng, 2.0, 60.0) * NA)
        kw['offset_steps'] = (step,)
        info['offset_step'] = step
    return Daq(**kw)


def draw(index: int, duration_s: float = DRAWN_DURATION_S) -> tuple[Record, dict]:
    """
    Return drawn record ``index`` and what was drawn (motion, sample, DAQ habits; SI units).

    Built as seed ``index`` of a :class:`~.library.Scenario` named ``drawn``, so the bounds
    and the judge treat it as any other record.
    """
    info: dict = {}

    def make(rng):
        kind = str(rng.choice(['pick', 'crank', 'sines-hold', 'vibration']))
        motion = _motion(rng, kind, duration_s, info)
        sample = str(rng.choice(['slim', 'big', 'short', 'narrow']))
        daq = _daq(rng, duration_s, info)
        amplifier = float(rng.uniform(100, 500)) if rng.random() < 0.2 else None
        info.update(kind=kind, sample=sample, amplifier_corner_hz=amplifier)
        return Sensor(sample, amplifier_corner_hz=amplifier), motion, daq

    # any integer is a fresh record: it is the seed of one scenario, 'drawn'
    scenario = Scenario('drawn', 'drawn', float(duration_s), make,
                        'every ingredient drawn at random (bench.scenarios.drawn)')
    record = scenario.build(int(index))
    return record, info
