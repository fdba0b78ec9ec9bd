# SPDX-License-Identifier: Apache-2.0
"""
Measure a periodic motion in a stretch of current, and whether the periodic model fits it.

The estimator models a periodic motion by states at k f_motion with a small remainder
(:mod:`.statespace`); :func:`measure_motion` gives the fundamental to model, or 0:

* the strongest family of lines k f (k = 1..``motion_harmonics``) in the periodogram (Hann,
  zero-padded as in :mod:`.lines`) between :data:`MOTION_LOWEST_HZ` (and two periods of the
  stretch) and half ``motion_bandwidth_hz``, whose first line passes the chi-square test of
  :func:`~.lines.measure_line`;
* at a rate of at least :data:`MOTION_RATE_HZ` (block means);
* refined by least squares: a mean, the modelled lines k f and the mains lines, the
  phasors held over pieces of :data:`MOTION_PIECE_S` (a motor's speed wobbles);
* accepted when the periodic model explains the stretch: the residual of one fit of a mean,
  the harmonics up to the band's edge and the mains lines has, away from them (a speed wobble's
  sidebands: 2 :data:`MOTION_WOBBLE_HZ` + :data:`MOTION_WOBBLE` k f), the
  periodogram the model expects
  there, the white noise (measured by the third difference, as the filter does) plus the
  current of a remainder motion of ``periodic_remainder_rms_m`` (its spectrum through the
  sensor, H(f)).  Each bin's ratio to that is exponential with mean 1; the stretch is refused
  when their sum exceeds its gamma quantile, or one bin its exponential quantile, at
  ``false_alarm``: a second motion, a step or a slow sweep is not a periodic motion.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.stats import gamma

from .lines import PAD, family_peak, local_level
from .statespace import harmonics_below, motion_intensity

__all__ = ['measure_motion', 'MOTION_LOWEST_HZ', 'MOTION_EXAMINED_HZ', 'MOTION_PIECE_S',
           'MOTION_RATE_HZ',
           'MOTION_WOBBLE', 'MOTION_WOBBLE_HZ']

#: The fundamental is searched from this, Hz (and at least two periods of the stretch): a 2 s
#: stretch resolves 0.5 Hz, and a slower motion beside a periodic one is seen only above 1 Hz.
MOTION_LOWEST_HZ = 3.0
#: The fit holds its phasors over pieces of at least this, s (and two periods): short against
#: a motor's speed wobble, long against a period.
MOTION_PIECE_S = 0.5
#: The stretch is measured at this rate or the lowest above it (block means of the samples,
#: whose nulls fall on the aliases of the band), Hz: above the motion band and 3 mains
#: harmonics, and it bounds the cost of a measurement at high sample rates.
MOTION_RATE_HZ = 1000.0
#: The residual is examined at multiples of this, Hz (from the first: a slow motion beside a
#: periodic one shows there): a stretch shorter than 1 / this cannot be judged.
MOTION_EXAMINED_HZ = 1.0
#: A motor's speed wobbles by up to this, relative, at up to MOTION_WOBBLE_HZ: the residual
#: within 2 MOTION_WOBBLE_HZ + MOTION_WOBBLE k f of harmonic k belongs to it (the frequency
#: excursion plus two sidebands: at a 1e4 signal-to-noise ratio the second still shows).
MOTION_WOBBLE = 0.02
MOTION_WOBBLE_HZ = 0.5


def measure_motion(current_a, sample_rate_hz: float, model,
                   false_alarm: float = 1e-4) -> float | None:
    """
    Return the fundamental of a periodic motion in a stretch of current, Hz.

    0.0: none; None: a stretch shorter than 1 / :data:`MOTION_EXAMINED_HZ` cannot be judged.
    ``model``: the estimator's :class:`~.statespace.StateSpaceModel` (sensor, settings and
    mains lines).  Module docstring.
    """
    x = np.asarray(current_a, dtype=float)
    fs = float(sample_rate_hz)
    cfg = model.config
    span = x.size / fs
    if span * MOTION_EXAMINED_HZ < 1.0 - 1e-9:
        return None
    lo, hi = max(MOTION_LOWEST_HZ, 2.0 / span), 0.5 * cfg.motion_bandwidth_hz
    if x.size < 64 or lo >= hi or not np.all(np.isfinite(x)):
        return 0.0
    d = np.diff(x, 3)
    noise_a2 = float(np.mean(d * d)) / 20.0       # third difference of white noise: 20 var
    step = max(1, int(fs // MOTION_RATE_HZ))       # block means: the variance of a mean of
    if step > 1:                                   # `step` white samples is noise / step
        x = x[:x.size // step * step].reshape(-1, step).mean(axis=1)
        fs, noise_a2 = fs / step, noise_a2 / step
    f0 = _strongest_family(x, fs, lo, hi, cfg.motion_harmonics, false_alarm)
    if not f0:
        return 0.0
    t = np.arange(x.size) / fs
    mains = tuple(model.lines_hz)
    df = fs / x.size
    piece = min(span, max(MOTION_PIECE_S, 2.0 / f0))
    best = minimize_scalar(lambda f: float(np.var(_residual(
        x, t, harmonics_below(f, 0.45 * fs, cfg.motion_harmonics), mains, piece))),
                           bounds=(f0 - df, f0 + df), method='bounded',
                           options={'xatol': 1e-4 * df})
    f0 = float(best.x)
    every = np.array(harmonics_below(f0, hi + 2 * MOTION_WOBBLE_HZ, x.size))  # near the band
    residual = _residual(x, t, every, mains, span)
    allowed = np.r_[every, mains]
    width = np.r_[2 * MOTION_WOBBLE_HZ + MOTION_WOBBLE * every, np.full(len(mains), 1.0)]
    unexplained = _unexplained(residual, fs, hi, (allowed, width), _remainder_psd(model),
                               noise_a2, false_alarm)
    return 0.0 if unexplained else f0


def _strongest_family(x, fs, lo, hi, harmonics, false_alarm) -> float:
    """
    Return the fundamental of the strongest line family in [lo, hi] (0.0: none).

    Its first line must be a line: a peak of the periodogram within one resolution bin (not
    the flank of a stronger line outside the band) above the chi-square level.
    """
    w = (x - x.mean()) * np.hanning(x.size)
    n_fft = 1 << int(math.ceil(math.log2(PAD * x.size)))
    power = np.abs(np.fft.rfft(w, n_fft)) ** 2
    df = fs / n_fft
    cand = np.arange(int(lo / df), int(hi / df) + 1)
    ks = [k for k in range(1, harmonics + 1) if k * hi < 0.45 * fs] or [1]
    f0 = family_peak(power, cand, ks)[0] * df
    j0 = int(round(f0 / df))
    peak = power[j0] >= np.max(power[max(j0 - PAD, 0):j0 + PAD + 1])
    return f0 if peak and power[j0] > math.log(cand.size / false_alarm) * local_level(
        power, j0, df) else 0.0


def _residual(x, t, lines_hz, mains_hz, piece_s) -> np.ndarray:
    """Return ``x`` less a mean and the lines, fitted on pieces of about ``piece_s``."""
    pieces = max(1, int(x.size / (piece_s * (1.0 / (t[1] - t[0]) if t.size > 1 else 1.0))))
    edges = np.linspace(0, x.size, pieces + 1).astype(int)
    waves = [f(2 * np.pi * h * t) for h in (*lines_hz, *mains_hz) for f in (np.cos, np.sin)]
    residual = np.empty_like(x)
    for a, b in zip(edges[:-1], edges[1:]):
        cols = np.array([np.ones(b - a)] + [w[a:b] for w in waves]).T
        # least squares by the normal equations (a few dozen columns; lstsq of the small
        # system keeps a mains harmonic on a motion harmonic from making it singular)
        coef = np.linalg.lstsq(cols.T @ cols, cols.T @ x[a:b], rcond=None)[0]
        residual[a:b] = x[a:b] - cols @ coef
    return residual


def _remainder_psd(model):
    """Return f (Hz) -> two-sided PSD of the remainder motion's current, A^2/Hz."""
    cfg = model.config
    a, c = 2 * np.pi * cfg.motion_bandwidth_hz, 2 * np.pi * cfg.motion_corner_hz
    q = motion_intensity(a, c, cfg.periodic_remainder_rms_m)

    def psd(f):
        w2 = (2 * np.pi * np.asarray(f)) ** 2
        h2 = np.abs(model.reduced.frequency_response(f)) ** 2
        return h2 * q / ((w2 + c * c) * (w2 + a * a) ** 2)
    return psd


def _unexplained(r, fs, hi, allowed, psd, noise_a2, false_alarm) -> bool:
    """
    Tell whether the residual holds more than noise and remainder away from the lines.

    ``allowed``: (frequencies, half-widths), Hz.
    """
    centre, width = allowed
    n = r.size
    window = np.hanning(n)
    power = np.abs(np.fft.rfft(r * window)) ** 2
    f = np.arange(power.size) * fs / n
    # bins at multiples of MOTION_EXAMINED_HZ (apart by at least one bin)
    step = max(1, int(round(MOTION_EXAMINED_HZ * n / fs)))
    k = np.arange(step, power.size, step)
    k = k[(f[k] <= hi) & np.all(np.abs(f[k, None] - centre[None, :]) > width[None, :], axis=1)]
    if k.size == 0:
        return False
    expected = float(window @ window) * (noise_a2 + fs * psd(f[k]))
    ratio = power[k] / expected
    return bool(ratio.sum() > gamma.ppf(1.0 - false_alarm, k.size)
                or ratio.max() > math.log(k.size / false_alarm))
