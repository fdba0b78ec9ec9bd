# SPDX-License-Identifier: Apache-2.0
"""
Tustin (bilinear) discretisation with prewarping, in zpk form.

Used by the estimator (inverse model) and the simulator (forward model), so the
two share one documented mapping

    s = w_p / tan(w_p T / 2) * (z - 1) / (z + 1),       w_p = 2 pi prewarp_hz,

which is exact at DC and at ``prewarp_hz`` and maps the open left half plane
into the unit disc (stability preserved at every sample rate).  The default
prewarp frequency fs/20 keeps the frequency distortion below 0.9 % at all
f <= fs/20 and below 2.5 % up to fs/10; a prewarp near Nyquist would instead
distort the whole low-frequency band (e.g. 27 % at fs/4).
"""
from __future__ import annotations

import math

import numpy as np
import scipy.signal as sig

__all__ = ['chain', 'default_prewarp_hz', 'tustin_sos', 'van_loan', 'USABLE_BAND_FRACTION']

#: The highest frequency a sampled record is used to, as a fraction of its rate: below
#: Nyquist by an anti-alias filter's transition band (a line there is 0.1 fs from its alias).
USABLE_BAND_FRACTION = 0.45


def default_prewarp_hz(sample_rate_hz: float, band_high_hz: float | None = None) -> float:
    """fs/20, or the band's upper edge if that is lower, Hz."""
    f = sample_rate_hz / 20.0
    return min(f, band_high_hz) if band_high_hz else f


def tustin_sos(zeros, poles, gain, sample_rate_hz: float, prewarp_hz: float) -> np.ndarray:
    """Second-order sections of the prewarped Tustin image of a continuous zpk (rad/s)."""
    w0 = 2.0 * math.pi * prewarp_hz
    fs_warped = w0 / (2.0 * math.tan(w0 / (2.0 * sample_rate_hz)))
    zd, pd, kd = sig.bilinear_zpk(_maybe_real(zeros), _maybe_real(poles), gain, fs_warped)
    return sig.zpk2sos(zd, pd, kd)


def _maybe_real(values) -> np.ndarray:
    """Real array if every value is real, else complex (conjugate pairs expected)."""
    v = np.asarray(values, dtype=complex)
    return v.real.copy() if np.all(v.imag == 0) else v


def van_loan(ac: np.ndarray, qc: np.ndarray, dt: float):
    """
    Exact zero-order-hold discretisation of x' = A x + w (white, intensity Qc).

    (A_d, Q_d) over dt s (Van Loan 1978), used by the Kalman estimator.
    """
    import scipy.linalg as la

    n = ac.shape[0]
    m = np.zeros((2 * n, 2 * n))
    m[:n, :n] = -ac
    m[:n, n:] = qc
    m[n:, n:] = ac.T
    e = la.expm(m * dt)
    ad = e[n:, n:].T
    qd = ad @ e[:n, n:]
    return ad, 0.5 * (qd + qd.T)


def chain(first: tuple[np.ndarray, np.ndarray], then: tuple[np.ndarray, np.ndarray]):
    """
    (A_d, Q_d) of ``first`` followed by ``then``: A_2 A_1 and A_2 Q_1 A_2^T + Q_2.

    Exact for the same continuous model (the state transition's semigroup property), so a
    long span is built by doubling one sample period instead of one ``expm`` over the span,
    whose Van Loan block holds exp(-A T) and overflows once |A| T nears 700.
    """
    a1, q1 = first
    a2, q2 = then
    qd = a2 @ q1 @ a2.T + q2
    return a2 @ a1, 0.5 * (qd + qd.T)
