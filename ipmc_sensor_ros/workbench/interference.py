# SPDX-License-Identifier: Apache-2.0
"""
Mains interference: line components at 50/60 Hz and harmonics that the stimulus does not explain.

Procedure (:func:`find_mains_lines`)
------------------------------------
For every record the current is regressed, by linear least squares, on

* a mean and the harmonics ``k f0`` (k <= 20) of the stimulus fundamental that
  carry deflection content (at least ``1e-4`` of the fundamental's amplitude in a
  least-squares harmonic fit of the deflection; these are the components the
  sensor's response to the deflection can produce),
* cosine/sine pairs at the mains lines ``m f_mains`` (``m = 1 .. n_harmonics``,
  below 0.45 of the sampling rate).

A mains line that coincides (within one frequency resolution, 1/T) with any
harmonic of the stimulus fundamental is *not separable* (a nonlinear sensor
responds there even where the deflection has no content): it is reported as
such and left in the data.  Records without a periodic stimulus use
only the mean and the lines (the response to a broadband deflection is smooth
in frequency, a line is not).  A line is detected when its amplitude exceeds
``z_threshold`` (6) standard errors of the regression (false-alarm probability
per line ~1e-8 for Gaussian noise; the noise is the residual's spectral level near the
line, not its whole variance); its ``level`` is its RMS over the RMS of the
record's current (after removing the mean), and removing it subtracts the
fitted sinusoid (:func:`remove_mains`).  With ``mains="auto"`` both 50 and
60 Hz are tested and the family with the larger detected power is used.

The grid does not run at exactly 50 or 60 Hz (+-0.2 Hz is common, and a DAQ clock
error shifts the apparent line), while a line is 1/T wide: on a 40 s record a
50.15 Hz hum is 6 resolution cells from 50 Hz, and a regressor at 50 Hz sees only its
beat.  So each record's fundamental is measured first: the current less its mean and
stimulus harmonics is transformed (zero-padded 8x), and the summed power at ``m f``,
m = 1..3, is maximised over ``f`` within ``MAINS_SEARCH_HZ`` of the nominal frequency.
Lines are reported at the measured ``m f`` with their nominal ``m f_mains``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from .freqresp import _coarse_frequency, harmonic_fit

__all__ = ['MainsLine', 'find_mains_lines', 'remove_mains', 'parse_mains']

#: Search half-width around the nominal mains frequency, Hz (grid tolerance: European and
#: North American grids stay within +-0.2 Hz in normal operation; 1 % of 50 Hz covers
#: islanded supplies and DAQ clock errors).
MAINS_SEARCH_HZ = 0.5


@dataclass(frozen=True)
class MainsLine:
    record: str
    frequency_hz: float
    amplitude_a: float           # peak amplitude of the fitted sinusoid
    level: float                 # RMS of the line / RMS of the record's current
    z: float                     # amplitude / its standard error
    separable: bool              # False: coincides with a stimulus harmonic
    nominal_hz: float = float('nan')   # m * 50 or m * 60 (frequency_hz is the measured one)

    def to_json(self) -> dict:
        return {
            'record': self.record,
            'frequency_hz': self.frequency_hz,
            'amplitude_a': self.amplitude_a,
            'level': self.level,
            'z': self.z,
            'separable': self.separable,
            'nominal_hz': self.nominal_hz,
        }


def parse_mains(value) -> float | str | None:
    """
    Parse a mains setting: ``'off'``/None -> None, ``'auto'`` -> 'auto', ``50``/``60`` -> Hz.

    Anything else is refused.
    """
    if value is None or str(value).strip().lower() in ('off', 'none', '0', ''):
        return None
    text = str(value).strip().lower()
    if text == 'auto':
        return 'auto'
    try:
        f = float(text)
    except ValueError:
        f = None
    if f not in (50.0, 60.0):
        raise ValueError(f'mains must be 50, 60, auto or off, got {value!r}')
    return f


def _stimulus_harmonics(t, w, max_harmonics: int = 20):
    """
    Fundamental and the harmonics (at most ``max_harmonics``) carrying deflection content.

    From a least-squares harmonic fit of the deflection; ``(None, [])`` for a non-periodic
    stimulus.
    """
    fs = (t.size - 1) / (t[-1] - t[0])
    f0 = _coarse_frequency(t, w, fs)
    if not f0 > 0 or f0 * (t[-1] - t[0]) < 2:
        return None, []
    k_max = min(int(0.45 * fs / f0), max_harmonics)
    if k_max < 1:
        return f0, []
    phasors, resid, _ = harmonic_fit(t, w, f0, k_max)
    if np.var(resid) > 0.1 * np.var(w):
        return None, []              # not periodic: the harmonics do not explain the deflection
    amps = np.abs(phasors)
    return f0, [k + 1 for k in np.flatnonzero(amps >= 1e-4 * amps[0])]


def _sinusoids(t, freqs):
    """Return a column of ones, then cosine/sine pairs at ``freqs``."""
    cols = [np.ones_like(t)]
    for f in freqs:
        cols += [np.cos(2 * np.pi * f * t), np.sin(2 * np.pi * f * t)]
    return np.column_stack(cols)


def _measured_mains(t, y, stim, f_mains, fs):
    """Return the record's mains fundamental, Hz, near ``f_mains`` (see module docstring)."""
    a = _sinusoids(t, stim)
    r = y - a @ np.linalg.lstsq(a, y, rcond=None)[0]
    nfft = 1 << int(np.ceil(np.log2(8 * r.size)))
    power = np.abs(np.fft.rfft(r, nfft)) ** 2
    df = fs / nfft
    cand = f_mains + np.arange(-MAINS_SEARCH_HZ, MAINS_SEARCH_HZ + df / 2, df)
    total = np.zeros(cand.size)
    for m in (1, 2, 3):
        ok = m * cand < 0.45 * fs
        total[ok] += power[np.rint(m * cand[ok] / df).astype(int)]
    k = int(np.argmax(total))
    if 0 < k < cand.size - 1 and np.all(total[k - 1:k + 2] > 0):
        # vertex of the parabola through the log power of the peak and its neighbours: the
        # grid step alone leaves up to half a step, 2.5 % of a 5 % line after removal
        lo, mid, hi = np.log(total[k - 1:k + 2])
        den = lo - 2 * mid + hi
        if den < 0:
            return float(cand[k] + 0.5 * df * (lo - hi) / den)
    return float(cand[k])


def _record_lines(name, t, stimulus, y, f_mains, n_harmonics):
    t = np.asarray(t, float) - t[0]
    duration = t[-1] - t[0]
    fs = (t.size - 1) / duration
    res = 1.0 / duration
    f0, ks = stimulus
    stim = [k * f0 for k in ks] if f0 else []
    nominal = [m * f_mains for m in range(1, n_harmonics + 1) if m * f_mains < 0.45 * fs]
    if not nominal:
        return [], np.zeros_like(y)
    f_line = _measured_mains(t, y, stim, f_mains, fs)
    lines = [m * f_line for m in range(1, len(nominal) + 1) if m * f_line < 0.45 * fs]
    nominal = dict(zip(lines, nominal))
    # a line on any stimulus harmonic may be the sensor's own (e.g. nonlinear) response
    sep = [f for f in lines if not f0 or abs(f - round(f / f0) * f0) > res]
    a = _sinusoids(t, stim + sep)
    try:  # normal equations: the columns are nearly orthogonal sinusoids (fast, well conditioned)
        coef = np.linalg.solve(a.T @ a, a.T @ y)
    except np.linalg.LinAlgError:
        coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    resid = y - a @ coef
    # standard error of a sinusoid's amplitude, sigma sqrt(2 / n), with sigma^2 the residual's
    # *local* spectral level: the median periodogram (mean = n sigma^2, median ln 2 of that)
    # 3 cells to 2 Hz from the line.  A broadband motion current unexplained by a periodic
    # stimulus (robot moves) sits below 10 Hz; taken as white it hid a 3 % hum at 50 Hz.
    n = t.size
    spec = np.abs(np.fft.rfft(resid)) ** 2
    freq = np.fft.rfftfreq(n, 1.0 / fs)
    rms_y = float(np.std(y)) or 1.0

    def standard_error(f):
        near = (np.abs(freq - f) > 3 * res) & (np.abs(freq - f) < 2.0)
        level = np.median(spec[near]) / np.log(2) if np.any(near) else resid @ resid
        return float(np.sqrt(2.0 * level / n) / np.sqrt(n))

    out, fitted = [], np.zeros_like(y)
    base = 1 + 2 * len(stim)
    for j, f in enumerate(sep):
        ca, cb = coef[base + 2 * j], coef[base + 2 * j + 1]
        amp = float(np.hypot(ca, cb))
        se = standard_error(f)
        z = amp / se if se > 0 else np.inf
        if z >= 6.0:
            out.append(MainsLine(name, float(f), amp, amp / np.sqrt(2) / rms_y, float(z), True,
                                 nominal[f]))
            fitted += ca * np.cos(2 * np.pi * f * t) + cb * np.sin(2 * np.pi * f * t)
    for f in lines:
        if f not in sep:
            out.append(MainsLine(name, float(f), float('nan'), float('nan'), float('nan'), False,
                                 nominal[f]))
    return out, fitted


def find_mains_lines(records: Sequence, mains='auto', n_harmonics: int = 10):
    """
    Detect mains lines in every record (see module docstring).

    ``records``: objects with ``path``, ``time_s``, ``current_a`` and ``deflection_m``
    (:class:`~.timefit.Record`).  Returns ``(lines, fitted)``: the detected (and the
    non-separable) lines, and per record the fitted line sum to subtract.  ``mains``:
    50, 60, 'auto' or None (nothing done).
    """
    mains = parse_mains(mains)
    if mains is None:
        return [], [np.zeros(np.asarray(r.current_a).size) for r in records]
    families = (50.0, 60.0) if mains == 'auto' else (mains,)
    best = None
    stimuli = [
        (
            _stimulus_harmonics(
                np.asarray(r.time_s, float) - r.time_s[0], np.asarray(r.deflection_m, float)
            )
            if r.deflection_m is not None
            else (None, [])
        )
        for r in records
    ]
    for f_mains in families:
        lines, fitted = [], []
        for r, stim in zip(records, stimuli):
            lr, fr = _record_lines(r.path, r.time_s, stim, np.asarray(r.current_a, float),
                                   f_mains, n_harmonics)
            lines += lr
            fitted.append(fr)
        power = sum(float(np.sum(f ** 2)) for f in fitted)
        if best is None or power > best[0]:
            best = (power, lines, fitted)
    _, lines, fitted = best
    if mains == 'auto' and not any(ln.separable for ln in lines):
        lines = []        # nothing found: do not report the untested family's blind spots
    return lines, fitted


def remove_mains(records: Sequence, mains='auto', n_harmonics: int = 10):
    """
    Return ``(cleaned records, lines)``.

    Cleaned records: each record's current minus its detected mains lines.
    """
    lines, fitted = find_mains_lines(records, mains, n_harmonics)
    cleaned = [replace(r, current_a=np.asarray(r.current_a, float) - f) if np.any(f) else r
               for r, f in zip(records, fitted)]
    return cleaned, lines


def summarize_lines(lines: Sequence[MainsLine]) -> list[dict]:
    """
    One entry per nominal line: the largest level over records and how many records show it.

    ``frequency_hz`` is the nominal m * 50 or m * 60 Hz; ``measured_hz`` the range of the
    frequencies measured in the records (the grid's frequency varies).
    """
    by_f: dict[float, list[MainsLine]] = {}
    for ln in lines:
        by_f.setdefault(ln.nominal_hz, []).append(ln)
    out = []
    for f in sorted(by_f):
        det = [ln for ln in by_f[f] if ln.separable]
        if det:
            measured = [ln.frequency_hz for ln in det]
            out.append({'frequency_hz': f, 'measured_hz': [min(measured), max(measured)],
                        'level': max(ln.level for ln in det),
                        'records': len(det), 'removable': True})
        else:
            out.append({'frequency_hz': f, 'level': None, 'records': 0, 'removable': False,
                        'note': 'coincides with a stimulus harmonic: not separable, not removed'})
    return out
