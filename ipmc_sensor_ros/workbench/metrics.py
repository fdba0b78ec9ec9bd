# SPDX-License-Identifier: Apache-2.0
"""
Figures of merit, defined once for every verb, report and test.

* :func:`fit_percent` -- MATLAB ``compare``: 100 (1 - ||y - y_hat|| / ||y - mean y||);
* :func:`nrmse` -- RMS(estimate - truth) / RMS(truth) (deflection estimates);
* :func:`noise_rms` -- the measurement-noise RMS of a current record, the noise floor every
  error is compared with (``compare``, ``fit``, ``diagnose``);
* :func:`detrended_nrmse` -- :func:`nrmse` after removing the mean and linear trend of each
  (``estimate``: a current sensor cannot see a constant deflection), in bounded memory;
  :func:`level_error` -- what it removes: the error of the estimate's level and its drift.
"""
from __future__ import annotations

import numpy as np

__all__ = ['fit_percent', 'nrmse', 'noise_rms', 'detrended_nrmse', 'level_error', 'CHUNK_ROWS',
           'held_at_limit', 'AT_LIMIT_FRACTION']

#: Samples per piece of the running sums of :func:`detrended_nrmse`.
CHUNK_ROWS = 65_536


def fit_percent(measured, predicted) -> float:
    """MATLAB ``compare`` fit: 100 (1 - ||y - y_hat|| / ||y - mean y||), percent."""
    y = np.asarray(measured, float)
    den = np.linalg.norm(y - y.mean())
    return float(100.0 * (1.0 - np.linalg.norm(y - predicted) / den)) if den > 0 else float('nan')


def nrmse(estimate, truth) -> float:
    """RMS(estimate - truth) / RMS(truth), dimensionless."""
    e = np.asarray(estimate, float)
    t = np.asarray(truth, float)
    return float(np.sqrt(np.mean((e - t) ** 2)) / np.sqrt(np.mean(t ** 2)))


def detrended_nrmse(estimate, truth) -> float:
    """
    RMS(e - m) / RMS(m) of ``estimate`` e and ``truth`` m, each mean and linear trend removed.

    The trend is the least-squares line over the sample index, as
    ``scipy.signal.detrend(x, type='linear')`` removes it; here from running sums over
    ``CHUNK_ROWS`` samples at a time (three passes: means; slopes about the centred index;
    the residual sums), so the memory does not grow with the record (scipy's least squares
    held ~70 B per sample).  Agrees with the detrend formulation to rounding (< 1e-12
    relative, tested).
    """
    sums = _error_sums(estimate, truth)
    return float(np.sqrt(sums['ss_err'] / sums['ss_truth']))


def level_error(estimate, truth) -> dict[str, float]:
    """
    Return what :func:`detrended_nrmse` leaves out: the error of the estimate's level, m.

    One pass of the running sums gives both: ``nrmse`` (:func:`detrended_nrmse`) and
    ``nrmse_raw``: RMS(e - m) / RMS(m) with nothing removed (meaningful when the measured
    deflection is zero at rest, as a robot stack reads it); ``mean_error_m``: mean(e - m);
    ``start_error_m`` / ``end_error_m``: the least-squares line of e - m at the first and
    last sample (a drift of the estimate against the measurement).
    """
    sums = _error_sums(estimate, truth)
    half = 0.5 * (sums['n'] - 1) / sums['n']      # centred index of the last sample
    return {'nrmse': float(np.sqrt(sums['ss_err'] / sums['ss_truth'])),
            'nrmse_raw': float(np.sqrt(sums['ss_err_raw'] / sums['ss_truth_raw'])),
            'mean_error_m': sums['mean_diff'],
            'start_error_m': sums['mean_diff'] - sums['slope_diff'] * half,
            'end_error_m': sums['mean_diff'] + sums['slope_diff'] * half}


def _error_sums(estimate, truth) -> dict:
    """Means, slopes and residual sums of squares of e and m, in bounded pieces."""
    e_all = np.asarray(estimate, float)
    m_all = np.asarray(truth, float)
    n = e_all.size
    if n != m_all.size or n < 2:
        raise ValueError(f'need two equally long records of >= 2 samples, got {n} and '
                         f'{m_all.size}')
    pieces = [slice(k, k + CHUNK_ROWS) for k in range(0, n, CHUNK_ROWS)]
    # index regressor x_k = (k + 1) / n (scipy's), centred: x_k - mean(x) = (k - (n - 1) / 2) / n
    centre = 0.5 * (n - 1)

    def x_centred(sl: slice) -> np.ndarray:
        return (np.arange(sl.start, min(sl.stop, n)) - centre) / n

    sum_e = sum_m = ss_err_raw = ss_truth_raw = 0.0
    for sl in pieces:
        sum_e += float(np.sum(e_all[sl]))
        sum_m += float(np.sum(m_all[sl]))
        ss_err_raw += float(np.sum((e_all[sl] - m_all[sl]) ** 2))
        ss_truth_raw += float(np.sum(m_all[sl] ** 2))
    mean_e, mean_m = sum_e / n, sum_m / n
    sxx = (n * n - 1.0) / (12.0 * n)     # sum of x_centred^2, exact
    sxe = sxm = 0.0
    for sl in pieces:
        x = x_centred(sl)
        sxe += float(x @ (e_all[sl] - mean_e))
        sxm += float(x @ (m_all[sl] - mean_m))
    slope_e, slope_m = sxe / sxx, sxm / sxx
    ss_err = ss_truth = 0.0
    for sl in pieces:
        x = x_centred(sl)
        e = e_all[sl] - (mean_e + slope_e * x)
        m = m_all[sl] - (mean_m + slope_m * x)
        ss_err += float(np.sum((e - m) ** 2))
        ss_truth += float(np.sum(m ** 2))
    return {'n': n, 'ss_err': ss_err, 'ss_truth': ss_truth, 'ss_err_raw': ss_err_raw,
            'ss_truth_raw': ss_truth_raw, 'mean_diff': mean_e - mean_m,
            'slope_diff': slope_e - slope_m}


def noise_rms(t: np.ndarray, w: np.ndarray, y: np.ndarray, window_s: float = 4.0) -> float:
    """
    Measurement-noise RMS of the current (A).

    Periodic records: residual of harmonic fits (mean + harmonics of the
    excitation fundamental) in consecutive windows of about ``window_s``
    (whole periods), pooled -- short windows keep slow drifts of the response
    out of the noise estimate.  Other records: scaled MAD of second differences.
    """
    from .freqresp import fundamental_response, harmonic_fit

    try:
        p = fundamental_response(t, w, y)
    except ValueError:
        d2 = np.diff(y, 2)
        return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))
    f0, k = p.frequency_hz, p.extra.get('harmonics', 10)
    periods = max(2, int(round(window_s * f0)))
    span = periods / f0
    ss, dof = 0.0, 0
    start = t[0]
    # increasing times: each window is a slice found by bisection (a mask over the whole
    # record per window made the noise floor quadratic in the record length)
    ordered = bool(np.all(t[1:] >= t[:-1]))
    while start + span <= t[-1] + 1e-9:
        if ordered:
            sel = slice(*np.searchsorted(t, [start, start + span], side='left'))
        else:
            sel = (t >= start) & (t < start + span)
        tw, yw = t[sel], y[sel]
        _, resid, _ = harmonic_fit(tw - start, yw, f0, k)
        ss += float(resid @ resid)
        dof += max(tw.size - (2 * k + 1), 1)
        start += span
    if dof == 0:
        sel = (t >= p.window[0]) & (t <= p.window[1])
        _, resid, _ = harmonic_fit(t[sel] - t[sel][0], y[sel], f0, k)
        return float(np.sqrt(np.mean(resid ** 2)))
    return float(np.sqrt(ss / dof))


#: A column holding its largest or smallest value in this fraction of its rows or more is
#: said to sit at a limit: a clean sine at full scale of a 16-bit ADC dwells on its extreme
#: codes ~0.1 % of the time at 0.05 Hz (less when faster), a clipped one far longer (a
#: +-10 V amplifier rail held 49-72 % of a trial's rows).
AT_LIMIT_FRACTION = 0.01


def held_at_limit(values) -> str:
    """
    Return how many rows hold ``values``' largest or smallest value, if a limit's share.

    '' when neither extreme holds :data:`AT_LIMIT_FRACTION` of the rows; else e.g.
    ``'4912 of 10000 rows at 10 or -10'``: an amplifier's rail or an ADC's range clips the
    signal there, which no model of the sensor predicts.
    """
    v = np.asarray(values, float)
    if v.size == 0 or v.max() == v.min():
        return ''
    ends = [(float(x), int(np.count_nonzero(v == x))) for x in (v.max(), v.min())]
    held = [(x, n) for x, n in ends if n >= AT_LIMIT_FRACTION * v.size]
    if not held:
        return ''
    return (f'{sum(n for _, n in held)} of {v.size} rows at '
            + ' or '.join(f'{x:.6g}' for x, _ in held))
