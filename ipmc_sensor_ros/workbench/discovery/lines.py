# SPDX-License-Identifier: Apache-2.0
"""
Mains lines: the current at 50/60 Hz and harmonics that the deflection does not explain.

Procedure (:func:`find_mains_lines`)
------------------------------------
1. **What the deflection explains.**  The caller predicts each record's current from its
   measured deflection with the model fitted to the records; the residual ``r = y - y_hat``
   (after the settle time) holds the lines, the noise and what the model misses.  On a drive
   harmonic this separates hum from signal: a crank-slider's 50th harmonic is ~0, its 5th
   (odd) is 0, so whatever is at 50 Hz in a 1, 2, 5 or 10 Hz record is hum.
2. **The grid's frequency, per record.**  The grid does not run at exactly 50 or 60 Hz
   (+-0.2 Hz is common, a DAQ clock error shifts it too) and a line is 1/T wide, so the
   fundamental is measured first: the summed power of the zero-padded (8x) residual spectrum
   at ``m f``, m = 1..3, is maximised over ``f`` within :data:`MAINS_SEARCH_HZ` of nominal
   (parabolic vertex).  Lines are reported at the measured ``m f`` with their nominal ``m
   f_mains``.
3. **Amplitudes.**  The residual is regressed on a mean, a cosine/sine pair at every ``m f``
   (m = 1 .. ``n_harmonics``, below 0.45 of the sampling rate) and at the harmonics of the
   drive that carry deflection content (at least 1e-4 of the fundamental's; where the model
   errs, it errs there, and a rectangular window would leak it everywhere).  A drive harmonic
   within 1/T of a line is left to the line.
4. **The test, at a stated false-alarm rate.**  A line's squared amplitude is compared with the
   residual's spectral level around it: the mean periodogram of the regression residual over
   the ``nu`` bins from 3 bins to :data:`LEVEL_BAND_HZ` away from the line.  For Gaussian noise
   that is white near the line, ``z^2 = A^2 / (2 sigma_hat^2 / n)`` is ``2 F(2, 2 nu)``:
   ``P(z^2 >= u^2) = (1 + u^2 / (2 nu))^-nu`` at one frequency.  Lines m = 1..3 are tested at
   the frequency the search chose for them, the maximum of a random process over ``2
   MAINS_SEARCH_HZ m T`` resolution cells; by Rice's formula it exceeds ``u`` about ``1 + sqrt(pi
   / 6) u cells`` times as often (:func:`line_threshold`).  The threshold ``u`` makes the
   probability that a record **without** hum shows any line of either family at most
   ``false_alarm`` (summed over the lines).  What the model misses near a line raises the level
   and makes the test conservative.
5. **Hum or the sensor's own response?**  A line that its measured frequency cannot tell from
   a harmonic of the drive (:func:`on_drive_harmonic`) may be what the model misses there (a
   nonlinear sensor responds at the odd harmonics of a crank, whose deflection has none); it
   counts as hum only when the same line shows off every drive harmonic in another record of
   the campaign (mains couples into all of them alike).  Otherwise it stays in the residual
   and is reported as such (``left``): one record, or a sweep whose every drive puts a
   harmonic on the line, cannot tell hum from the sensor's response; a record at a drive
   frequency whose harmonics miss the line can.
6. With ``mains='auto'`` both families are tested and the one with the larger detected power is
   kept.  Removing a line subtracts its fitted sinusoid from the whole record.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ...estimation.config import parse_mains as parse_mains_hz
from ...estimation.lines import SEARCH_HZ
from ...lti.discretize import USABLE_BAND_FRACTION
from .drive import drive_of

__all__ = ['MainsLine', 'MAINS_SEARCH_HZ', 'LEVEL_BAND_HZ', 'parse_mains', 'find_mains_lines',
           'line_threshold', 'summarize_lines']

#: Search half-width around the nominal mains frequency, Hz: the estimator's
#: (:data:`~ipmc_sensor_ros.estimation.lines.SEARCH_HZ`), one rule for both.
MAINS_SEARCH_HZ = SEARCH_HZ
#: Half-width of the band whose residual spectrum gives a line's noise level, Hz (wide enough
#: for ~50 bins on a 6 s record, narrow enough that the level is local).
LEVEL_BAND_HZ = 5.0
#: Rice's factor for the periodogram of a rectangular window over frequency: the expected
#: upcrossings of level u per resolution cell are sqrt(pi / 6) u exp(-u^2 / 2) (second
#: spectral moment (pi T)^2 / 3 of the window's |sinc|^2 correlation)
RICE = float(np.sqrt(np.pi / 6))


@dataclass(frozen=True)
class MainsLine:
    """One detected line of one record (``frequency_hz`` measured, ``nominal_hz`` m x 50/60)."""

    record: str
    frequency_hz: float
    amplitude_a: float           # peak amplitude of the fitted sinusoid
    level: float                 # RMS of the line / RMS of the record's current
    z: float                     # amplitude / its standard error
    nominal_hz: float
    z_threshold: float           # the test's threshold for this record
    cos_a: float = 0.0           # the fitted sinusoid: cos_a cos(2 pi f t) + sin_a sin(2 pi f t)
    sin_a: float = 0.0

    def to_json(self) -> dict:
        return dict(self.__dict__)


def parse_mains(value) -> float | str | None:
    """
    Return the mains family to look for: 'auto', 50.0, 60.0, or None (none).

    The estimator's ``mains_hz`` values ('auto', 0, 50, 60; others are refused by its
    parser, :func:`~ipmc_sensor_ros.estimation.config.parse_mains`), 0 and None meaning none.
    """
    if value is None:
        return None
    return parse_mains_hz(value) or None


def line_threshold(nu: int, span_s: float, orders, false_alarm: float) -> float:
    """
    Return the z threshold of a record's lines (module docstring, 4).

    ``nu``: bins of the level estimate; ``span_s``: record length T; ``orders``: the harmonic
    numbers m of every line tested in the record (both families).  Solves
    ``sum_m n_m(u) (1 + u^2/(2 nu))^-nu = false_alarm`` for u, with ``n_m(u) = 1 + sqrt(pi/6) u
    2 MAINS_SEARCH_HZ m T`` for m <= 3 and 1 above.
    """
    def rate(u):
        looks = sum(1.0 + (RICE * u * 2 * MAINS_SEARCH_HZ * m * span_s if m <= 3 else 0.0)
                    for m in orders)
        return looks * (1 + u * u / (2 * nu)) ** (-nu)

    lo, hi = 1.0, 50.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if rate(mid) > false_alarm else (lo, mid)
    return hi


def _sinusoids(t, freqs):
    """Return a column of ones, then cosine/sine pairs at ``freqs``."""
    cols = [np.ones_like(t)]
    for f in freqs:
        cols += [np.cos(2 * np.pi * f * t), np.sin(2 * np.pi * f * t)]
    return np.column_stack(cols)


def _measured_mains(r, f_mains, fs):
    """Return the record's mains fundamental near ``f_mains``, Hz (module docstring, 2)."""
    r = r - r.mean()
    nfft = 1 << int(np.ceil(np.log2(8 * r.size)))
    power = np.abs(np.fft.rfft(r, nfft)) ** 2
    df = fs / nfft
    cand = f_mains + np.arange(-MAINS_SEARCH_HZ, MAINS_SEARCH_HZ + df / 2, df)
    total = np.zeros(cand.size)
    for m in (1, 2, 3):
        ok = m * cand < USABLE_BAND_FRACTION * fs
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


def on_drive_harmonic(f, z, f0, span_s) -> bool:
    """
    Return True when a line at ``f`` cannot be told from a harmonic of the drive by its frequency.

    Within 3 standard errors of its measured frequency, ``sqrt(6) / (2 pi z T)`` (the
    Cramer-Rao bound of a sinusoid whose amplitude is z standard errors), or a tenth of a
    resolution cell, of some k f0.
    """
    if f0 is None:
        return False
    k = max(1, round(f / f0))
    return abs(f - k * f0) <= max(3 * np.sqrt(6) / (2 * np.pi * z * span_s), 0.1 / span_s)


def _orders(fs, families, n_harmonics):
    """Harmonic numbers m of every line tested in a record, over the families."""
    top_hz = USABLE_BAND_FRACTION * fs
    return [m for fm in families for m in range(1, min(n_harmonics, int(top_hz / fm)) + 1)]


def _family(t, r, drive, f_mains, n_harmonics, orders, false_alarm):
    """Lines of one family in one residual: [(f, nominal, a, b, z, u), ...] for every line."""
    n = t.size
    fs = (n - 1) / (t[-1] - t[0])
    res = 1.0 / (t[-1] - t[0])
    top_hz = USABLE_BAND_FRACTION * fs
    m_max = min(n_harmonics, int(top_hz / f_mains))
    if m_max < 1:
        return []
    f_line = _measured_mains(r, f_mains, fs)
    freqs = [m * f_line for m in range(1, m_max + 1) if m * f_line < top_hz]
    stim = [f for f in drive if min(abs(f - g) for g in freqs) > res]
    a = _sinusoids(t, freqs + stim)
    coef = np.linalg.lstsq(a, r, rcond=None)[0]
    spec = np.abs(np.fft.rfft(r - a @ coef)) ** 2 / n
    fk = np.fft.rfftfreq(n, 1.0 / fs)
    out = []
    for j, f in enumerate(freqs):
        near = (np.abs(fk - f) > 3 * res) & (np.abs(fk - f) < LEVEL_BAND_HZ) & (fk > 0)
        nu = int(near.sum())
        if nu < 4:
            continue
        ca, cb = coef[1 + 2 * j], coef[2 + 2 * j]
        z = float(np.hypot(ca, cb) / np.sqrt(2 * float(np.mean(spec[near])) / n))
        out.append((f, (j + 1) * f_mains, ca, cb, z,
                    line_threshold(nu, t[-1] - t[0], orders, false_alarm)))
    return out


def _record_rows(rec, pred, keep, drive, f_mains, families, n_harmonics, false_alarm):
    """
    Return the lines that pass the test: ``[(row, ambiguous), ...]`` (:func:`_family` rows).

    On every sample from the first kept one: the spectra are of the sample clock, so the
    slots a dropped row left (``rec.filled``: the current interpolated there) stay in (taken
    out, each joined the samples around it: 1 % of rows dropped read 50 Hz hum at
    49.85-50.05 Hz and missed its harmonics in 3 of 5 records).
    """
    span = slice(int(np.argmax(keep)), None)
    t = (np.asarray(rec.time_s, float) - rec.time_s[0])[span]
    r = (np.asarray(rec.current_a, float) - pred)[span]
    orders = _orders((t.size - 1) / (t[-1] - t[0]), families, n_harmonics)
    rows = _family(t, r, list(drive.harmonics_hz), f_mains, n_harmonics, orders, false_alarm)
    return [(row, on_drive_harmonic(row[0], row[4], drive.frequency_hz, t[-1] - t[0]))
            for row in rows if row[4] >= row[5]]


def _line_sum(rec, keep, rows):
    """Return the MainsLine of accepted rows and their sum over the whole record."""
    t_all = np.asarray(rec.time_s, float) - rec.time_s[0]
    y = np.asarray(rec.current_a, float)
    rms_y = float(np.std(y[keep])) or 1.0
    total, lines = np.zeros_like(y), []
    for f, nominal, ca, cb, z, u in rows:
        total += ca * np.cos(2 * np.pi * f * t_all) + cb * np.sin(2 * np.pi * f * t_all)
        amp = float(np.hypot(ca, cb))
        lines.append(MainsLine(rec.path, float(f), amp, amp / np.sqrt(2) / rms_y, z,
                               float(nominal), u, float(ca), float(cb)))
    return lines, total


def find_mains_lines(records: Sequence, predictions: Sequence[np.ndarray],
                     keeps: Sequence[np.ndarray], mains='auto', n_harmonics: int = 10,
                     false_alarm: float = 1e-4, drives=None):
    """
    Detect mains lines in every record from the model residual (module docstring).

    ``records``: objects with ``path``, ``time_s``, ``current_a`` and ``deflection_m``;
    ``predictions``: the current the model predicts from each record's deflection; ``keeps``:
    the samples to use (after the settle time); ``drives``: their :class:`~.drive.Drive`
    (found here when not given).  Returns ``(lines, fitted, left)``: the detected lines, per
    record, the fitted line sum to subtract from the whole record; ``left``: (line, the drive
    harmonic it sits on) for each line that passed the test there and stays in the residual
    (step 5).
    """
    mains = parse_mains(mains)
    zeros = [np.zeros(np.asarray(r.current_a).size) for r in records]
    if mains is None:
        return [], zeros, []
    families = (50.0, 60.0) if mains == 'auto' else (mains,)
    drives = drives or [drive_of(rec) for rec in records]
    best, left = ([], zeros, 0.0), []
    for f_mains in families:
        per_record = [_record_rows(rec, pred, keep, drive, f_mains, families, n_harmonics,
                                   false_alarm)
                      for rec, pred, keep, drive in zip(records, predictions, keeps, drives)]
        # a line on a drive harmonic may be the sensor's own response there; it is hum when
        # the same line shows, off every drive harmonic, in another record (mains couples
        # into every record of a campaign alike)
        clear = {row[1] for rows in per_record for row, ambiguous in rows if not ambiguous}
        found = [_line_sum(rec, keep, [row for row, ambiguous in rows
                                       if not ambiguous or row[1] in clear])
                 for rec, keep, rows in zip(records, keeps, per_record)]
        left += [(ln, round(ln.frequency_hz / drive.frequency_hz))
                 for rec, keep, rows, drive in zip(records, keeps, per_record, drives)
                 for ln in _line_sum(rec, keep, [row for row, ambiguous in rows
                                                 if ambiguous and row[1] not in clear])[0]]
        power = sum(float(np.sum(f ** 2)) for _, f in found)
        if power > best[2]:
            best = ([ln for lines, _ in found for ln in lines], [f for _, f in found], power)
    return best[0], best[1], left


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
        measured = [ln.frequency_hz for ln in by_f[f]]
        out.append({'frequency_hz': f, 'measured_hz': [min(measured), max(measured)],
                    'level': max(ln.level for ln in by_f[f]), 'records': len(by_f[f]),
                    'min_z': min(ln.z for ln in by_f[f])})
    return out
