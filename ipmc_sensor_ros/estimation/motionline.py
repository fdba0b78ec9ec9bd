# SPDX-License-Identifier: Apache-2.0
"""
Measure a periodic motion in a stretch of current, and whether the periodic model fits it.

The estimator models a periodic motion by states at k f_motion with a small remainder
(:mod:`.statespace`); :func:`measure_motion` gives the fundamentals to model, or ():

* the strongest family of lines k f (k = 1..``motion_harmonics``) in the periodogram (Hann,
  zero-padded as in :mod:`.lines`) between :data:`MOTION_PERIODS` periods of the stretch
  and half ``motion_bandwidth_hz``, whose first line passes the chi-square test of
  :func:`~.lines.measure_line`;
* at a rate of at least :data:`MOTION_RATE_HZ` (block means);
* refined by least squares: a mean, the modelled lines k f and the mains lines, the
  phasors held over pieces of :data:`MOTION_PIECE_S` (a motor's speed wobbles);
* accepted when the periodic model explains the stretch: the residual of one fit of the
  offset (a mean), the harmonics up to the band's edge and the mains lines has the
  periodogram the model expects: the white noise (measured by the third difference, as the
  filter does), the current of a remainder motion of
  ``periodic_remainder_rms_m`` (its spectrum through the sensor, H(f)) and, beside each
  harmonic, at most the sidebands of a speed wobble (:func:`_wobble_power`).  Each bin's
  ratio to that is exponential with mean 1 (every other bin of the Hann periodogram, nearly
  independent, from the second); the stretch is refused when their sum exceeds its gamma
  quantile, or one bin its exponential quantile, at ``false_alarm``: a second motion, a step
  or a slow sweep is not a periodic motion;
* while the stretch is not explained, another motion (a sum of sines, a crank on a
  vibrating base), up to ``motion_fundamentals``: the strongest family in the residual
  whose first line is none of the others' lines, each fundamental then refined again beside
  the others from its periodogram peak (on pieces of two periods, a motion not yet
  accounted for pulls the fit: 1.7 Hz beside an unmodelled 1 Hz sine was read 1.82 Hz).

:func:`measure_recent` judges the end of a live stream: the last 1, 2, ..., 8 s
(:data:`MOTION_LONGEST_S`), the shortest that holds a periodic motion first, so a fast crank
is taken from a short stretch and a slow one (down to ``MOTION_PERIODS / MOTION_LONGEST_S``)
from a long one.  Every whole second: on 1, 2, 4 and 8 s, a 1.49 Hz crank from rest had
2.7 s of its four periods at 4 s on the 2 s stretch, too short, while the 4 s one still held
the spin-up; it was modelled at 6 s, after a burst of dropped rows the broad prior could not
bridge (drawn record 82, 1.45 % NRMSE, now 0.52 %).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy.linalg import lstsq
from scipy.ndimage import maximum_filter1d
from scipy.optimize import minimize_scalar
from scipy.special import jv
from scipy.stats import gamma

from ..lti.discretize import USABLE_BAND_FRACTION
from .lines import FIND_FALSE_ALARM, PAD, local_levels, vertex
from .ring import hold_next
from .phasors import harmonics_below, motion_lines
from .statespace import MOTION_WOBBLE, MOTION_WOBBLE_HZ, motion_intensity

__all__ = ['measure_motion', 'measure_recent', 'MOTION_PERIODS', 'MOTION_LONGEST_S',
           'MOTION_SHORTEST_S', 'MOTION_PIECE_S', 'MOTION_RATE_HZ', 'MOTION_WOBBLE',
           'MOTION_WOBBLE_HZ']

#: A stretch is searched for fundamentals of at least this many periods: with fewer, the
#: Hann window's main lobes about adjacent harmonics (+-2 / T) cover the whole axis and
#: another motion has nowhere to show apart from a wobble.
MOTION_PERIODS = 4.0
#: The longest stretch judged live, s: periodic motions down to MOTION_PERIODS / this
#: (0.5 Hz, below the paper's 1 Hz crank) are modelled, and no slower.
MOTION_LONGEST_S = 8.0
#: A stretch shorter than this, s, is not judged (None): the longest over 8, a check's
#: data (:data:`~.kalman.CHECK_S`); a live stream is judged on the stretches since each of
#: the last eight checks (:func:`measure_recent`).
MOTION_SHORTEST_S = MOTION_LONGEST_S / 8.0
#: The stretch is measured at this rate or the lowest above it (block means of the samples,
#: whose nulls fall on the aliases of the band), Hz: above the motion band and 3 mains
#: harmonics, and it bounds the cost of a measurement at high sample rates.
MOTION_RATE_HZ = 1000.0
#: The fit holds its phasors over pieces of at least this, s (and two periods): short
#: against a motor's speed wobble (a quarter of the fastest one's period), long against a
#: period.
MOTION_PIECE_S = 0.25 / MOTION_WOBBLE_HZ
#: Bessel orders and rates counted in the wobble bound: the index reaches ~8 on a live
#: stretch (8 s, 25 Hz), whose sidebands above the 12th are negligible; more than
#: 4 MOTION_WOBBLE_HZ beyond the frequency excursion every order is near 1e-6 of the line or
#: below, and no bound is added.
_SIDEBANDS = 24
#: (the rates from the stretch's resolution to MOTION_WOBBLE_HZ, geometric)
_RATES = 24


def measure_recent(current_a, sample_rate_hz: float, model, settings=None) -> tuple | None:
    """
    Return the fundamentals of the periodic motions at the end of a live stream, Hz.

    (Module doc.)  ``current_a``: the last samples (up to :data:`MOTION_LONGEST_S`); ():
    none; None: less than :data:`MOTION_SHORTEST_S` of current.  ``settings``: the
    :class:`~.config.EstimatorConfig` whose remainder (what the residual may hold) and upper
    corner (how high the search goes) the measurement takes (None: ``model``'s own; the
    estimator gives its settings, the largest a model may leave and the widest band,
    whatever the model in use chose).
    """
    x = np.asarray(current_a, dtype=float)
    fs = float(sample_rate_hz)
    available = x.size / fs
    if available < MOTION_SHORTEST_S - 1e-9:
        return None
    checks = round(MOTION_LONGEST_S / MOTION_SHORTEST_S)
    spans = sorted({min(available, MOTION_SHORTEST_S * m) for m in range(1, checks + 1)})
    for span in spans:
        found = measure_motion(x[-int(round(span * fs)):], fs, model, settings=settings)
        if found:
            return found
    return ()


def measure_motion(current_a, sample_rate_hz: float, model,
                   false_alarm: float = FIND_FALSE_ALARM, settings=None) -> tuple | None:
    """
    Return the fundamentals of the periodic motions in a stretch of current, Hz.

    (): none; None: a stretch shorter than :data:`MOTION_SHORTEST_S` cannot be judged.
    ``model``: the estimator's :class:`~.statespace.StateSpaceModel` (sensor, settings and
    mains lines); ``settings``: as :func:`measure_recent`'s.  Module docstring.
    """
    x = np.asarray(current_a, dtype=float)
    fs = float(sample_rate_hz)
    cfg = settings or model.config
    span = x.size / fs
    if span < MOTION_SHORTEST_S - 1e-9:
        return None
    lo = MOTION_PERIODS / min(span, MOTION_LONGEST_S)
    hi = 0.5 * cfg.motion_bandwidth_hz
    d = np.diff(x, 3)
    d = d[np.isfinite(d)]             # NaN: a slot the DAQ did not deliver (left out)
    if x.size < 64 or lo >= hi or d.size < 64 or np.isinf(x).any():
        return ()
    noise_a2 = float(np.mean(d * d)) / 20.0       # third difference of white noise: 20 var
    step = max(1, int(fs // MOTION_RATE_HZ))       # block means: the variance of a mean of
    if step > 1:                                   # `step` white samples is noise / step
        x = _block_means(x[:x.size // step * step].reshape(-1, step))
        fs, noise_a2 = fs / step, noise_a2 / step
    kept = ~np.isnan(x)
    stretch = _Stretch(x, np.arange(x.size) / fs, fs, None if kept.all() else kept,
                       tuple(model.lines_hz))
    peaks, found, searched = (), (), hold_next(x)
    for _ in range(cfg.motion_fundamentals):
        f0 = _strongest_family(searched, fs, lo, hi, cfg.motion_harmonics, false_alarm,
                               _lines_of(found, hi, fs, cfg.motion_harmonics))
        if not f0:
            return ()
        peaks, found = peaks + (f0,), found + (f0,)
        for j, peak in enumerate(peaks):     # each refined beside the others (one pass)
            found = (*found[:j], _refined(stretch, found[:j] + found[j + 1:], peak,
                                          cfg.motion_harmonics), *found[j + 1:])
        explained, searched = _judged(stretch, found, min(peaks), hi, model, cfg, noise_a2,
                                      false_alarm)
        if explained:
            return found
    return ()


class _Stretch(NamedTuple):
    """A stretch measured (block means): samples, times, rate, kept slots, mains lines."""

    x: np.ndarray
    t: np.ndarray
    fs: float
    kept: np.ndarray | None
    mains: tuple


def _lines_of(fundamentals, limit_hz: float, fs: float, count: int) -> tuple:
    """Return the harmonics k f (k <= ``count``) of each fundamental below ``limit_hz``."""
    return motion_lines(fundamentals, min(limit_hz, USABLE_BAND_FRACTION * fs), count, 0.0)[0]


def _refined(s: _Stretch, found: tuple, f0: float, harmonics: int) -> float:
    """Return ``f0`` refined by least squares beside the motions ``found`` (module doc)."""
    span = s.x.size / s.fs
    df = s.fs / s.x.size
    piece, top_hz = min(span, max(MOTION_PIECE_S, 2.0 / f0)), USABLE_BAND_FRACTION * s.fs
    known = _lines_of(found, top_hz, s.fs, harmonics)
    best = minimize_scalar(lambda f: float(np.var(_piecewise(
        s.x, s.t, known + harmonics_below(f, top_hz, harmonics), s.mains, piece, s.kept)[0])),
                           bounds=(f0 - df, f0 + df), method='bounded',
                           options={'xatol': 1e-4 * df})
    return float(best.x)


def _judged(s: _Stretch, found: tuple, slowest: float, hi: float, model, cfg,
            noise_a2: float, false_alarm: float) -> tuple[bool, np.ndarray]:
    """
    Tell whether the motions ``found`` explain the stretch; return it and the residual.

    The residual of one fit over the stretch (a mean: a slope would take up a wobbling
    line's leakage, and the ramp it took away would fill the lowest bins); the lines' power,
    wobble included, from pieces of two periods of the ``slowest`` peak (one fit sees only
    the carrier).
    """
    span = s.x.size / s.fs
    edge = hi * (1 + MOTION_WOBBLE) + 4 * MOTION_WOBBLE_HZ + 2.0 / span   # lines reaching it
    every = _lines_of(found, edge, s.fs, s.x.size)
    piece = min(span, max(MOTION_PIECE_S, 2.0 / slowest))
    residual = _piecewise(s.x, s.t, every, s.mains, span, s.kept)[0]
    amplitude2 = _piecewise(s.x, s.t, every, s.mains, piece, s.kept)[1]
    explained = _explained(residual, s.fs, hi, (np.array(every), amplitude2, span), s.mains,
                           _remainder_psd(model, cfg), noise_a2, false_alarm)
    return explained, residual


def _block_means(blocks: np.ndarray) -> np.ndarray:
    """Return each row's mean over its delivered (finite) samples; NaN where none was."""
    ok = np.isfinite(blocks)
    count = ok.sum(axis=1)
    sums = np.where(ok, blocks, 0.0).sum(axis=1)
    return np.where(count > 0, sums / np.maximum(count, 1), np.nan)


def _strongest_family(x, fs, lo, hi, harmonics, false_alarm, taken=()) -> float:
    """
    Return the fundamental of the strongest line family in [lo, hi] (0.0: none).

    The family is chosen among the fundamentals whose first line is a line: a peak of the
    periodogram within one resolution bin (not the flank of a stronger line) above the
    chi-square level.  (The strongest family of all can be a subharmonic's: on a record with
    little noise, 2.5 Hz, 5 Hz and 7.5 Hz hold a 5 Hz line and its leakage, more than 5, 10
    and 15 Hz do; its first line is no line.)  Nor one whose first line is within 2 bins of
    one of ``taken`` (Hz: the lines other motions found hold).
    """
    w = (x - x.mean()) * np.hanning(x.size)
    n_fft = 1 << int(math.ceil(math.log2(PAD * x.size)))
    power = np.abs(np.fft.rfft(w, n_fft)) ** 2
    df = fs / n_fft
    cand = np.arange(int(lo / df), int(hi / df) + 1)
    ks = [k for k in range(1, harmonics + 1) if k * hi < USABLE_BAND_FRACTION * fs] or [1]
    summed = sum(power[np.minimum(k * cand, power.size - 1)] for k in ks)
    near = maximum_filter1d(power, 2 * PAD + 1, mode='nearest')[cand]
    level = math.log(cand.size / false_alarm)
    peaks = np.flatnonzero(power[cand[1:-1]] >= near[1:-1]) + 1
    lines = peaks[power[cand[peaks]] > level * local_levels(power, cand[peaks], df)]
    if taken:                 # a motion's line already modelled is not another's first line
        lines = lines[np.all(np.abs(cand[lines, None] * df - np.asarray(taken)[None, :])
                             > 2.0 * fs / x.size, axis=1)]
    lines = lines.tolist()
    if not lines:
        return 0.0
    best = max(lines, key=lambda j: summed[j])
    return vertex(cand, summed, best) * df


def _piecewise(x, t, lines_hz, mains_hz, piece_s, kept=None) -> tuple[np.ndarray, np.ndarray]:
    """
    Fit a mean and the lines on pieces of about ``piece_s`` (one piece: ``piece_s`` >= span).

    Return (residual, each of ``lines_hz``'s squared amplitude averaged over the pieces:
    its power, wobble included, where one fit over the stretch sees only the carrier).
    ``kept``: the samples delivered (None: all); the others are left out of the fit, their
    residual 0.  ``t``: uniform.
    """
    dt = t[1] - t[0] if t.size > 1 else 1.0
    pieces = max(1, int(x.size * dt / piece_s))
    edges = np.linspace(0, x.size, pieces + 1).astype(int)
    omega = 2 * np.pi * np.array((*lines_hz, *mains_hz), dtype=float)
    residual = np.empty_like(x)
    n = len(lines_hz)
    power = np.zeros(n)
    for a, b in zip(edges[:-1], edges[1:]):
        cols = np.ones((b - a, 1 + 2 * omega.size))
        turns = _turns(t[a], dt, b - a, omega)
        cols[:, 1::2], cols[:, 2::2] = turns.real, turns.imag
        gram, y = _gram(t[a], dt, b - a, omega), x[a:b]
        if kept is not None:            # the slots not delivered taken out of the sums
            missed = ~kept[a:b]
            gram -= cols[missed].T @ cols[missed]
            y = np.where(missed, 0.0, y)
        # least squares by the normal equations (pivoted QR of the small system keeps a
        # mains harmonic on a motion harmonic from making it singular)
        coef = lstsq(gram, y @ cols, lapack_driver='gelsy')[0]
        residual[a:b] = y - cols @ coef
        if kept is not None:
            residual[a:b][missed] = 0.0
        power += (coef[1:1 + 2 * n:2] ** 2 + coef[2:2 + 2 * n:2] ** 2) * (b - a) / x.size
    return residual, power


def _turns(t0: float, dt: float, count: int, omega: np.ndarray) -> np.ndarray:
    """
    Return e^{i w t} on ``count`` samples t0 + m dt (rows) for each w of ``omega`` (columns).

    One turn e^{i w dt} a sample, multiplied on (a cumulative product: its rounding grows
    as count x 1e-16, ~1e-12 on a stretch; a tenth of the cost of cos and sin).
    """
    z = np.empty((count, omega.size), dtype=complex)
    z[0] = np.exp(1j * omega * t0)
    z[1:] = np.exp(1j * omega * dt)
    return np.cumprod(z, axis=0, out=z)


def _gram(t0: float, dt: float, count: int, omega: np.ndarray) -> np.ndarray:
    """
    Return C'C of the columns [1, cos w_1 t, sin w_1 t, ...] on ``count`` samples t0 + m dt.

    In closed form: products of cosines and sines are sums of e^{i a t} at a = w_j +- w_k,
    and sum_m e^{i a (t0 + m dt)} = e^{i a t0} (e^{i a count dt} - 1) / (e^{i a dt} - 1)
    (count at a = 0), so the Gram costs no pass over the samples.
    """
    def sums(a):
        den = np.expm1(1j * a * dt)
        safe = np.where(a == 0, 1.0, den)
        geo = np.where(a == 0, float(count), np.expm1(1j * a * count * dt) / safe)
        return np.exp(1j * a * t0) * geo

    diff = sums(omega[:, None] - omega[None, :])
    both = sums(omega[:, None] + omega[None, :])
    single = sums(omega)
    k = omega.size
    g = np.empty((1 + 2 * k, 1 + 2 * k))
    g[0, 0] = count
    g[0, 1::2] = g[1::2, 0] = single.real
    g[0, 2::2] = g[2::2, 0] = single.imag
    g[1::2, 1::2] = 0.5 * (diff.real + both.real)         # cos cos
    g[2::2, 2::2] = 0.5 * (diff.real - both.real)         # sin sin
    g[1::2, 2::2] = 0.5 * (both.imag - diff.imag)         # cos_j sin_k
    g[2::2, 1::2] = g[1::2, 2::2].T
    return g


def _remainder_psd(model, cfg):
    """Return f (Hz) -> two-sided PSD of the remainder motion's current, A^2/Hz (``cfg``'s)."""
    a, c = 2 * np.pi * cfg.motion_bandwidth_hz, 2 * np.pi * cfg.motion_corner_hz
    q = motion_intensity(a, c, cfg.periodic_remainder_rms_m)

    def psd(f):
        w2 = (2 * np.pi * np.asarray(f)) ** 2
        h2 = np.abs(model.reduced.frequency_response(f)) ** 2
        return h2 * q / ((w2 + c * c) * (w2 + a * a) ** 2)
    return psd


def _hann_response(bins) -> np.ndarray:
    """Power response of the Hann window ``bins`` from a line (1 at 0, zeros at 2, 3, ...)."""
    x = np.abs(np.asarray(bins, dtype=float))
    near_one = np.abs(x - 1.0) < 1e-9                 # sinc(x) / (1 - x^2) -> 1/2 there
    x = np.where(near_one, 0.0, x)
    amplitude = np.where(near_one, 0.5, np.sinc(x) / (1.0 - x * x))
    return amplitude * amplitude


def _wobble_power(f, centres, power, span) -> np.ndarray:
    """
    Upper bound of the periodogram power a speed wobble puts at ``f`` (Hz).

    ``centres``, ``power``: the harmonics, Hz, and their peak powers in the periodogram;
    ``span``: the stretch, s.  A motor turning at f0 whose speed wobbles by
    :data:`MOTION_WOBBLE` at rate r phase-modulates harmonic k with index
    beta = k f0 MOTION_WOBBLE / r: sideband n, at k f0 +- n r, holds J_n(beta)^2 of the line's
    power (the Bessel expansion of exp(i beta sin)); each reaches a bin through the Hann
    window's response.  The bound is the largest sum over rates from 1 / (2 span) (a slower
    wobble is, within the stretch, a change of speed) to :data:`MOTION_WOBBLE_HZ`.  A line
    that is not a wobble (a second motion beside a harmonic) exceeds it.
    """
    out = np.zeros(f.size)
    n = np.arange(1, _SIDEBANDS + 1)
    rates = np.geomspace(min(0.5 / span, MOTION_WOBBLE_HZ), MOTION_WOBBLE_HZ, _RATES)
    for c, p in zip(centres, power):
        reach = c * MOTION_WOBBLE + 4 * MOTION_WOBBLE_HZ + 2.0 / span
        j = np.flatnonzero(np.abs(f - c) < reach)
        if j.size == 0:
            continue
        share = jv(n[None, :], c * MOTION_WOBBLE / rates[:, None]) ** 2    # (rate, n)
        off = (f[j] - c)[:, None, None]
        at = n[None, None, :] * rates[None, :, None]
        seen = _hann_response((off - at) * span) + _hann_response((off + at) * span)
        out[j] += p * np.max(np.sum(share[None] * seen, axis=2), axis=1)
    return out


def _explained(r, fs, hi, lines, mains, psd, noise_a2, false_alarm) -> bool:
    """
    Tell whether the residual holds no more than noise, remainder and wobble (module doc).

    ``lines``: (harmonics Hz, their squared amplitudes A^2, the stretch s); ``mains``: mains
    lines, Hz (their neighbourhood, 1 Hz, is not judged).
    """
    centres, amplitude2, span = lines
    n = r.size
    window = np.hanning(n)
    power = np.abs(np.fft.rfft(r * window)) ** 2
    f = np.arange(power.size) * fs / n
    k = np.arange(2, power.size, 2)       # every other bin: Hann bins two apart ~independent
    k = k[f[k] <= hi]
    if mains:
        k = k[np.all(np.abs(f[k, None] - np.asarray(mains)[None, :]) > 1.0, axis=1)]
    if k.size == 0:
        return False
    line_power = amplitude2 * (window.sum() / 2) ** 2      # a line's periodogram peak
    expected = (float(window @ window) * (noise_a2 + fs * psd(f[k]))
                + _wobble_power(f[k], centres, line_power, span))
    ratio = power[k] / expected
    size = ratio.size
    return not bool(ratio.sum() > gamma.ppf(1.0 - false_alarm, size)
                    or ratio.max() > math.log(size / false_alarm))
