# SPDX-License-Identifier: Apache-2.0
"""
A record's sample clock read from its time stamps: the slot of each row and the rate.

A record's rows are the samples of a DAQ clock stamped by a host (jitter, dropped rows, a
clock some ppm off its nominal rate).  Each stamp takes its sample-clock slot by the stream's
rule (:class:`~ipmc_sensor_ros.estimation.timebase.Timebase`: jitter up to a quarter of the
period, the clock's period and phase followed), so the workbench and the estimator node count
the same samples; the rate is the slope of one least-squares line of the stamps against their
slots (:func:`~ipmc_sensor_ros.estimation.timebase.fit_line`), not the inverse of the median
spacing, which host jitter moves (a 1500 Hz DAQ with +-15 % jitter read 1500.15 Hz).
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import DataError
from ..estimation.timebase import START, Timebase, fit_line
from .measurements import round_rate_hz

__all__ = ['stamp_steps', 'measured_rate_hz']


def stamp_steps(path: str, time_s, max_gap_s: float) -> np.ndarray | None:
    """
    Return the slot steps of stamps ``time_s[1:]`` (sample periods since the row before).

    None: a stamp has no slot of its own (two rows closer than the jitter allows, or one
    behind the other).  A gap longer than ``max_gap_s`` raises DataError naming ``path`` and
    the gap: the motion in it is unknown.
    """
    t = np.asarray(time_s, float)
    rel = t - t[0]                      # a stream's stamps are >= 0: a record's may not be
    base = Timebase(float(np.median(np.diff(t))), max_gap_s)
    base.admit(0.0)
    out, i = [], 1
    while i < t.size:
        run = base.admit_plain(rel, i, t.size)
        out.append(run)
        i += run.size
        if i < t.size:
            step = base.admit(float(rel[i]))
            if step == START:
                raise DataError(f'{path}: no sample for {t[i] - t[i - 1]:.6g} s after t = '
                                f'{t[i - 1]:.6g} s, a gap longer than max_gap_s '
                                f'({max_gap_s:g} s): the motion in it is unknown; split the '
                                'record there')
            if step < 1:
                return None
            out.append(np.array([step]))
            i += 1
    return np.concatenate(out) if out else np.zeros(0, np.int64)


def measured_rate_hz(time_s) -> float:
    """
    Return the sample rate of stamps ``time_s`` (increasing, at least 2), Hz.

    The inverse slope of the stamps against their slots (module docstring), rounded to two
    significant digits of its standard error (the digits the stamps support; at most
    :data:`~.measurements.RATE_DIGITS` significant).  When a stamp has no slot of its own, or
    fewer than 3 stamps are given, the inverse of the median spacing.
    """
    t = np.asarray(time_s, float)
    median_rate = round_rate_hz(1.0 / float(np.median(np.diff(t))))
    steps = stamp_steps('', t, math.inf) if t.size > 2 else None
    if steps is None:
        return median_rate
    slots = np.concatenate([[0], np.cumsum(steps)])
    slope, slope_std, *_ = fit_line(slots, t, 1.0 / median_rate)
    rate = 1.0 / slope
    rate_std = rate * slope_std / slope
    if not math.isfinite(rate_std) or rate_std <= 0.0:
        return round_rate_hz(rate)
    return round_rate_hz(round(rate, max(0, 1 - math.floor(math.log10(rate_std)))))
