# SPDX-License-Identifier: Apache-2.0
"""
The response at each tone of a periodic record: a crank's fundamental, or a multi-sine's tones.

A crank-slider record gives one point, H at its fundamental (the paper's section 5.2:
:func:`~.freqresp.fundamental_response`).  A drive that sums several tones (a signal
generator's 3 + 7 Hz on a shaker) is periodic too, at the tones' common fundamental, which
its spectrum need not show: the strongest tone's harmonics leave the others unexplained.
The tones of a generator are commensurate, so the common fundamental is the strongest
tone's frequency over a whole number m:

* each m = 2, 3, ... that leaves at least :data:`TONE_MIN_PERIODS` periods in the record
  is scored by the share of the deflection's power its harmonics hold in one spectrum of
  the record (Hann window; the nearest bin to each harmonic and one either side: a tone
  between two bins keeps most of its power there, and the groups stay apart); the smallest
  m is kept whose harmonics leave at most :data:`LEFT_FACTOR` times what the best leave
  (a multiple of m holds as much, and a fundamental whose harmonics beside a tone take up
  part of its leakage can hold 90 %);
* its harmonics up to the last that carries a tone (an amplitude of at least
  :data:`TONE_FRACTION` of the strongest's) are regressed with a straight line (a laser's
  or a mount's drift, an offset's), deflection and current alike, on the record's last
  whole periods (orthogonal there, so one tone cannot leak into another): the fundamental
  is refined by least squares, as the crank's is, within :data:`REFINE_BINS`; the window is
  the longest that leaves no more of the deflection than the least any shorter one does
  (an F test at 1 %: a rest or start-up before the drive is dropped a period, two, four,
  ... at a time);
* the fit must pass the aperiodic test (:data:`~.freqresp.MAX_APERIODIC_FRACTION`), and
  what it leaves must hold no line from the fundamental up (a tone that is no harmonic:
  :data:`STRAY_FALSE_ALARM`).

H = I_k / W_k at each tone; uncertainties as the fundamental's, first order in the
regression's covariance (:func:`~.freqresp.phasor_sd`).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.stats import f as f_dist

from ..lti.discretize import USABLE_BAND_FRACTION
from .freqresp import (MAX_APERIODIC_FRACTION, FrequencyPoint, NotPeriodic,
                       fundamental_response, harmonic_fit, phasor_sd)

__all__ = ['tone_responses', 'TONE_FRACTION', 'TONE_MIN_PERIODS', 'REFINE_BINS', 'LEFT_FACTOR',
           'STRAY_FALSE_ALARM', 'MAX_TONE_HARMONICS']

#: A harmonic of the common fundamental is a tone of the drive when its deflection amplitude
#: is at least this fraction of the strongest tone's: below, it is the motion's distortion
#: or the noise (a crank's 2nd harmonic is 0.1-0.3 of its fundamental; that record is read
#: at its fundamental alone, as the paper does, before tones are looked for).
TONE_FRACTION = 0.1

#: Fewest periods of a common fundamental in the record: over P periods a tone that falls
#: between two of its harmonics spreads over the P bins between them, and with P = 2 or 3
#: the two harmonics beside it take up most of it (3 and 3 sqrt 2 Hz in 10 s: 0.25 Hz's
#: harmonics over 2 periods left 0.3 % of the deflection; each fundamental with 5 or more
#: periods left 18 % or more, and the aperiodic test refuses them).
TONE_MIN_PERIODS = 5

#: How far the strongest tone's frequency may move when the common fundamental is refined,
#: in bins of the record (1 / its duration): its least-squares estimate beside the other
#: tones is off by a small part of a bin (0.004 for 3 + 7 Hz in 10 s); a twentieth lets
#: that be corrected but not a tone that is no harmonic be met halfway (3 and 3 sqrt 2 Hz
#: in 10 s: allowed a tenth of a bin, 0.6 Hz's 5th and 7th harmonics met them at 3.01 and
#: 4.21 Hz and left 8 % of the deflection, within the aperiodic test).
REFINE_BINS = 0.05

#: Of the common fundamentals whose harmonics hold the deflection's power, the highest is
#: kept that leaves at most this many times the power the best leaves: a half or a third
#: of the tones' fundamental holds as much and a little more noise (3 + 7 Hz: 1 Hz and
#: 0.5 Hz both leave 0.1 %), a fundamental whose harmonics miss a tone leaves its power
#: (1.5 Hz: 6 %).
LEFT_FACTOR = 2.0

#: False alarm of the test for a line the common fit left in the deflection (a tone that is
#: no harmonic), over the whole spectrum of the window: one record in a hundred of tones and
#: white noise refused.
STRAY_FALSE_ALARM = 0.01

#: Most harmonics of a common fundamental regressed (the regression's columns: 2 x this + 1):
#: tones 0.1 Hz apart up to 6.4 Hz, or 1 Hz apart up to 64 Hz.
MAX_TONE_HARMONICS = 64


def tone_responses(time_s, deflection_m, current_a, *, source: str = '',
                   min_periods: int = 2) -> list[FrequencyPoint]:
    """
    Return H at the fundamental of a periodic record, or at each tone of a multi-sine one.

    The module docstring; a record that is periodic at no common fundamental tried raises
    the fundamental's :class:`~.freqresp.NotPeriodic` (a ``ValueError``).
    """
    try:
        return [fundamental_response(time_s, deflection_m, current_a, source=source,
                                     min_periods=min_periods)]
    except NotPeriodic as refused:
        t = np.asarray(time_s, float)
        w, i = np.asarray(deflection_m, float), np.asarray(current_a, float)
        fs = float((t.size - 1) / (t[-1] - t[0]))
        duration = t[-1] - t[0] + 1.0 / fs
        fewest = max(min_periods, TONE_MIN_PERIODS)
        common = _common_fundamental(w, fs, refused.frequency_hz, duration, fewest)
        if common is None:
            raise
        f0, top = common
        whole = int(np.floor(duration * f0 + 1e-9))
        drops = [0] + [2 ** k for k in range(int(np.log2(max(whole - fewest, 1))) + 1)]

        def windows(f: float) -> list:          # most periods first
            return [_common_fit(t, w, f, whole - d, fs, top) for d in drops
                    if whole - d >= fewest]
        sl = min(windows(f0), key=lambda f: f.left).window     # refined past a start-up
        f0 = _refined(t[sl] - t[sl][0], w[sl], f0,
                      REFINE_BINS / (duration * refused.frequency_hz), top)
        chosen = _longest(windows(f0))
        if chosen.left > MAX_APERIODIC_FRACTION:
            raise
        stray = _stray_line(chosen.resid, fs, f0, float(np.max(np.abs(chosen.pw))))
        if stray is not None:
            raise NotPeriodic(f'{source}: the deflection holds a tone near {stray:.3g} Hz that '
                              f'is no harmonic of the common {f0:.4g} Hz of the others: its '
                              'tones have no common period in the record',
                              refused.frequency_hz) from None
        return _tones(t, i, chosen, source)


class CommonFit(NamedTuple):
    """The deflection regressed on ``top`` harmonics of ``f0`` and a line, over a window."""

    #: the deflection's share it leaves, per degree of freedom left (``dof``)
    left: float
    f0: float
    periods: int
    window: slice
    top: int
    pw: np.ndarray
    cov_w: np.ndarray
    resid: np.ndarray
    dof: int


def _hann_power(x: np.ndarray) -> np.ndarray:
    """Return the periodogram of ``x`` less its mean, Hann-windowed (bin k at k fs / N)."""
    return np.abs(np.fft.rfft((x - x.mean()) * np.hanning(x.size))) ** 2


def _stray_line(resid, fs: float, f0: float, strongest_m: float) -> float | None:
    """
    Return the frequency of a tone the common fit left in the deflection, or None.

    The residual's Hann-windowed periodogram from the bin before ``f0`` up: its largest bin
    is a tone the harmonics miss when it is a tone (an amplitude of :data:`TONE_FRACTION`
    of the strongest, ``strongest_m``, or more: a sine of amplitude A peaks at (A N / 4)^2)
    and stands out of the noise (each bin's power exponential about its mean, estimated by
    the median over ln 2, which a line does not move: above ln(bins /
    :data:`STRAY_FALSE_ALARM`) times it).  Such a tone would otherwise pass the aperiodic
    test under 10 % of the deflection and pull the tones' fit (3 + 3 sqrt 2 Hz at 0.8 and
    0.3 mm read as 3.006 and 4.208 Hz).  Below ``f0`` a commensurate tone cannot be (the
    common fundamental would be lower): the power there is a drift's.
    """
    power = _hann_power(resid)
    above = power[max(int(f0 * resid.size / fs) - 1, 1):]
    mean = float(np.median(above)) / np.log(2.0)
    k = int(np.argmax(above))
    tone = (TONE_FRACTION * strongest_m * resid.size / 4.0) ** 2
    if above[k] < tone or above[k] <= mean * np.log(above.size / STRAY_FALSE_ALARM):
        return None
    return (k + power.size - above.size) * fs / resid.size


def _common_fundamental(w, fs: float, peak_hz: float, duration: float, fewest: int):
    """
    Return (common fundamental, its last harmonic with a tone), or None (module docstring).

    Scored on one Hann-windowed spectrum of the record: the share of the deflection's power
    in the bins nearest each harmonic below the usable band and one either side.
    """
    power = _hann_power(w)
    power[0] = 0.0
    total = float(power.sum())
    df = fs / w.size
    scored = []                         # (share left, f0, last harmonic with a tone)
    for m in range(2, MAX_TONE_HARMONICS + 1):
        f0 = peak_hz / m
        if np.floor(duration * f0 + 1e-9) < fewest:
            break
        k = np.arange(1, int(min(MAX_TONE_HARMONICS, USABLE_BAND_FRACTION * fs / f0)) + 1)
        bins = np.rint(k * f0 / df).astype(int)[:, None] + np.arange(-1, 2)[None, :]
        held = power[np.clip(bins, 0, power.size - 1)].sum(axis=1)
        tones = np.flatnonzero(held >= TONE_FRACTION ** 2 * held.max())
        scored.append((1.0 - float(held.sum()) / total, f0, int(k[tones[-1]])))
    least = min((s[0] for s in scored), default=1.0)
    if least > MAX_APERIODIC_FRACTION:
        return None
    return next(s[1:] for s in scored if s[0] <= LEFT_FACTOR * least)


def _common_fit(t, w, f0: float, periods: int, fs: float, top: int) -> CommonFit:
    """
    Return the :class:`CommonFit` over the last ``periods`` whole periods.

    Its share left is per degree of freedom (so a window of fewer samples is not favoured
    for fitting its noise with as many columns).
    """
    n_keep = int(round(periods / f0 * fs))
    sl = slice(t.size - n_keep, t.size)
    pw, resid_w, cov_w = harmonic_fit(t[sl] - t[sl][0], w[sl], f0, top, trend=True)
    variance_w = float(np.var(w[sl]))
    dof = max(n_keep - 2 * top - 2, 1)      # the harmonics, the mean and the line
    left = float(resid_w @ resid_w) / dof / variance_w if variance_w > 0 else np.inf
    return CommonFit(left, f0, periods, sl, top, pw, cov_w, resid_w, dof)


def _refined(t, w, f0: float, relative: float, top: int) -> float:
    """
    Return ``f0`` refined by least squares of its ``top`` harmonics over the window ``t``.

    The strongest tone's peak was refined beside the others, which pull it (1e-4 relative
    for 3 + 7 Hz: 24 mrad of phase at 7 Hz over 9 s); it may move by ``relative``.
    """
    span = relative * f0
    res = minimize_scalar(lambda f: float(np.sum(harmonic_fit(t, w, f, top, True)[1] ** 2)),
                          bounds=(f0 - span, f0 + span), method='bounded',
                          options={'xatol': 1e-7 * f0})
    return float(res.x)


def _longest(fits: list) -> CommonFit:
    """
    Return the fit of the most periods that leaves no more than the least does, at 1 %.

    ``fits``: one fundamental's, most periods first.  A window that still holds a start-up
    leaves more per degree of freedom than one past it; the F test of the two residual
    variances at a 1 % false alarm tells more from the noise's spread.
    """
    best = min(fits, key=lambda f: f.left)
    return next(f for f in fits if f.left <= best.left * f_dist.isf(0.01, f.dof, best.dof))


def _tones(t, i, fit: CommonFit, source: str) -> list[FrequencyPoint]:
    """Return the points of the tones of the common fundamental's fit (the module docstring)."""
    sl, f0, top, pw = fit.window, fit.f0, fit.top, fit.pw
    pi_, _, cov_i = harmonic_fit(t[sl] - t[sl][0], i[sl], f0, top, trend=True)
    out = []
    for k in np.flatnonzero(np.abs(pw) >= TONE_FRACTION * float(np.max(np.abs(pw)))):
        sdm_w, sdp_w = phasor_sd(fit.cov_w, pw[k], int(k) + 1)
        sdm_i, sdp_i = phasor_sd(cov_i, pi_[k], int(k) + 1)
        out.append(FrequencyPoint(
            frequency_hz=float((k + 1) * f0), response=complex(pi_[k] / pw[k]),
            sd_log_mag=float(np.hypot(sdm_w, sdm_i)), sd_phase_rad=float(np.hypot(sdp_w, sdp_i)),
            deflection_amplitude_m=float(abs(pw[k])), source=source,
            window=(float(t[sl][0]), float(t[sl][-1])),
            extra={'periods': fit.periods, 'harmonics': top, 'tone_of_hz': f0}))
    return out
