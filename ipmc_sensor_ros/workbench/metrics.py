# SPDX-License-Identifier: Apache-2.0
"""
Figures of merit, defined once for every verb, report and test.

* :func:`fit_percent` -- MATLAB ``compare``: 100 (1 - ||y - y_hat|| / ||y - mean y||);
* :func:`nrmse` -- RMS(estimate - truth) / RMS(truth) (deflection estimates);
* :func:`noise_rms` -- the measurement-noise RMS of a current record, the noise floor every
  error is compared with (``compare``, ``fit``, ``diagnose``).
"""
from __future__ import annotations

import numpy as np

__all__ = ['fit_percent', 'nrmse', 'noise_rms']


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
    while start + span <= t[-1] + 1e-9:
        sel = (t >= start) & (t < start + span)
        _, resid, _ = harmonic_fit(t[sel] - start, y[sel], f0, k)
        ss += float(resid @ resid)
        dof += max(int(sel.sum()) - (2 * k + 1), 1)
        start += span
    if dof == 0:
        sel = (t >= p.window[0]) & (t <= p.window[1])
        _, resid, _ = harmonic_fit(t[sel] - t[sel][0], y[sel], f0, k)
        return float(np.sqrt(np.mean(resid ** 2)))
    return float(np.sqrt(ss / dof))
