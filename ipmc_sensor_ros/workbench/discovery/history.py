# SPDX-License-Identifier: Apache-2.0
"""
The motion before a record: the periodic continuation of a periodic stimulus.

The model predicts each record from rest (the deflection held at its first value before the
first sample), and the ``settle_s`` left out at the start covers the sensor's own memory (its
poles lie at K ~ 72 1/s and beyond, eq. 31).  A correction C(s) can remember much longer: an
AC coupling at 0.2 Hz has a time constant of 0.8 s, and from rest its prediction is off by a
transient of ~ f_c/f of the signal for seconds -- which a fit of C(s) would bend its corner to
absorb.  For a periodic stimulus in steady state (a crank running before the recording
started) the motion before the record is its periodic continuation, ``w(t) = w(t mod P)`` for
``t < 0``: :func:`with_history` prepends it (cubic-spline samples of the first period), so the
prediction enters the record in steady state.  The samples used are the record's own: the
prepended ones are never fitted or scored.

:func:`prepare_with_history` gives every periodic record the history its FFT holds without
growing (the prediction's length is the next power of two above the record and its 1 s
return to zero; a 6 s record at 1 kHz has 1.19 s of room, a 4 s one 3.19 s): the diagnosis
runs on these records, so every model, plugins included, starts each record nearer its
steady state at no cost.  The correction stage (:mod:`.outside`) asks for more.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.interpolate import CubicSpline

from ..timepredict import prepare
from .drive import drive_of

#: the prediction's return to zero after a record (:func:`~ipmc_sensor_ros.workbench.timepredict.
#: prepare`'s ``pad_s``), s
PAD_S = 1.0

__all__ = ['PERIODIC_TOLERANCE', 'with_history', 'free_history_s', 'prepare_with_history',
           'history_samples']

#: the stimulus counts as periodic when w(t + P) differs from w(t) by at most this fraction
#: of its RMS (a crank in steady state repeats to the deflection sensor's noise, well under
#: 1 %; a motion that speeds up or stops does not)
PERIODIC_TOLERANCE = 0.02


def with_history(rec, history_s: float, drive=None):
    """
    Return ``rec`` with ``history_s`` seconds of periodic continuation before it, or None.

    ``drive``: the record's :class:`~.drive.Drive` (found here when not given).
    """
    drive = drive or drive_of(rec)
    if drive.frequency_hz is None:
        return None
    period = 1.0 / drive.frequency_hz
    t = np.asarray(rec.time_s, float)
    w = np.asarray(rec.deflection_m, float)
    y = np.asarray(rec.current_a, float)
    tt = t - t[0]
    if period >= tt[-1] or history_s <= 0:
        return None
    spline = CubicSpline(tt, w)
    inside = tt + period <= tt[-1]
    scale = float(np.std(w)) or 1.0
    if np.sqrt(np.mean((spline(tt[inside] + period) - w[inside]) ** 2)) > \
            PERIODIC_TOLERANCE * scale:
        return None
    dt = tt[-1] / (t.size - 1)
    th = np.arange(-int(np.ceil(history_s / dt)), 0) * dt
    phase = np.mod(th, period)
    filled = None if rec.filled is None else np.concatenate([np.zeros(th.size, bool),
                                                             rec.filled])
    return replace(rec, time_s=np.concatenate([t[0] + th, t]),
                   deflection_m=np.concatenate([spline(phase), w]),
                   current_a=np.concatenate([CubicSpline(tt, y)(phase), y]), filled=filled)


def free_history_s(rec) -> float:
    """Seconds of history the record's FFT holds without growing (module docstring)."""
    t = np.asarray(rec.time_s, float)
    fs = (t.size - 1) / (t[-1] - t[0])
    used = t.size + int(np.ceil(PAD_S * fs))
    return max(0, (1 << int(np.ceil(np.log2(used)))) - used - 1) / fs


def prepare_with_history(records, settle_s: float, drives=None) -> list:
    """
    Prepare each record for fitting, periodic ones with the history their FFT holds.

    :func:`free_history_s` of periodic continuation (``drives``: the records'
    :class:`~.drive.Drive`, found here when not given).  The samples kept for fitting and
    scoring are those of the record after ``settle_s``, whatever the history.
    """
    out = []
    for k, rec in enumerate(records):
        h = free_history_s(rec)
        longer = with_history(rec, h, drives[k] if drives else None) if h > 0 else None
        start = float(rec.time_s[0]) + settle_s
        use = longer or rec
        out.append(prepare([use], settle_s=start - float(use.time_s[0]))[0])
    return out


def history_samples(p, rec) -> int:
    """Return the samples of history in front of ``rec`` in its prepared record ``p``."""
    return p.t.size - np.asarray(rec.time_s).size
