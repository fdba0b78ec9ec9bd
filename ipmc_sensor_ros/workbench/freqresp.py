# SPDX-License-Identifier: Apache-2.0
"""
Empirical frequency response from time records, with uncertainty.

Two estimators:

* :func:`fundamental_response` -- the paper's section 5.2 procedure, done with
  error bars.  The excitation frequency f0 is found from the deflection
  spectrum (peak, then refined by least squares), the record is cut to the
  largest integer number of periods (the last ones, so start-up transients are
  dropped first), and deflection and current are each regressed on
  ``1, cos(k w0 t), sin(k w0 t)``, k = 1..K (K harmonics up to 0.45 fs, at
  most 12).  On an integer number of periods these regressors are orthogonal,
  so crank-slider harmonics cannot leak into the fundamental.  H(f0) is the
  ratio of the two fundamental phasors; its standard uncertainty follows from
  the regression residual variance, propagated to log-magnitude and phase
  (first order: var ln|H| = var|I|/|I|^2 + var|W|/|W|^2, likewise for phase).
* :func:`cross_spectral_response` -- for broadband records (sweeps, free
  vibration, step trains): Welch cross-spectral H1 estimate
  ``H = P_wi / P_ww`` with magnitude-squared coherence and the standard
  random-error formula ``sd(ln|H|) = sd(phase) = sqrt((1 - g2) / (2 n_d g2))``
  (Bendat & Piersol, Random Data, eq. 9.90), n_d the number of averages.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.fft
import scipy.signal as sig
from scipy.optimize import minimize_scalar

from ..errors import DataError
from ..lti.discretize import USABLE_BAND_FRACTION

__all__ = ['FrequencyPoint', 'fundamental_response', 'cross_spectral_response', 'harmonic_fit',
           'phasor_sd', 'NotPeriodic']

#: A record is periodic at f0 only if its harmonics explain the deflection: at most this fraction
#: of the deflection's variance may be left by the K-harmonic fit.  A crank-slider record leaves
#: its laser noise (1 % of the amplitude: 1e-4 of the variance) and a slow laser drift of 10 % of
#: the amplitude about 1e-2; robot-like motion, steps and free vibration leave most of it, and
#: their "fundamental" would be a peak of a broadband spectrum, not a response.
MAX_APERIODIC_FRACTION = 0.1


class NotPeriodic(DataError):
    """The deflection is not explained by harmonics of ``frequency_hz`` (its spectrum's peak)."""

    def __init__(self, text: str, frequency_hz: float):
        super().__init__(text)
        self.frequency_hz = frequency_hz


@dataclass(frozen=True)
class FrequencyPoint:
    """
    Measured H(j 2 pi f) = i/w at one frequency, with standard uncertainties.

    ``sd_log_mag`` is the standard uncertainty of ln|H| (so the relative
    uncertainty of the gain); ``sd_phase_rad`` that of the phase.
    """

    frequency_hz: float
    response: complex            # A m^-1
    sd_log_mag: float
    sd_phase_rad: float
    deflection_amplitude_m: float = float('nan')
    coherence: float = float('nan')
    source: str = ''
    window: tuple[float, float] | None = None
    extra: dict = field(default_factory=dict)

    @property
    def gain_a_per_m(self) -> float:
        return float(abs(self.response))

    @property
    def phase_deg(self) -> float:
        return float(np.degrees(np.angle(self.response)))


#: Records longer than this get an FFT length without Bluestein's algorithm (:func:`_fft_length`).
BLUESTEIN_FREE_ABOVE = 65_536


def _largest_prime_factor(n: int) -> int:
    largest, d = 1, 2
    while d * d <= n:
        while n % d == 0:
            largest, n = d, n // d
        d += 1 if d == 2 else 2
    return max(largest, n)


def _fft_length(n: int) -> int:
    """
    Return ``n``, or for long records the nearest shorter length FFT'd without Bluestein.

    A length whose largest prime factor exceeds its square root can make pocketfft use
    Bluestein's algorithm, with ~145 B of working memory per sample (725 MiB for a prime
    length near 5e6, measured); a length without that property never does.  Records up to
    ``BLUESTEIN_FREE_ABOVE`` samples keep their length (a few MB at most).
    """
    m = n
    while m > BLUESTEIN_FREE_ABOVE and _largest_prime_factor(m) ** 2 > m:
        m -= 1
    return m


def _coarse_frequency(t: np.ndarray, x: np.ndarray, fs: float) -> float:
    """
    Peak of the windowed deflection spectrum, Hz (the start of the least-squares refinement).

    Over the whole record, or over its last samples when a length a few samples shorter
    avoids Bluestein's algorithm (:func:`_fft_length`; bounded memory for any length).
    """
    x = x[x.size - _fft_length(x.size):]
    n = x.size
    windowed = x - x.mean()
    windowed *= np.hanning(n)    # in place: one record-length copy, not three
    spec = np.abs(np.fft.rfft(windowed))
    del windowed
    spec[0] = 0.0
    k = int(np.argmax(spec))
    if 1 <= k < spec.size - 1:
        a, b, c = np.log(spec[k - 1:k + 2] + 1e-300)
        k = k + 0.5 * (a - c) / (a - 2 * b + c) if (a - 2 * b + c) != 0 else k
    return float(k * fs / n)


#: Rows of the regression matrix of :func:`harmonic_fit` built at a time: the fit holds a
#: few MB whatever the record length (the whole matrix with its complex powers took ~400 B
#: per row, 2 GB for 5e6 rows).
FIT_CHUNK_ROWS = 32_768


def _harmonic_columns(t: np.ndarray, w0: float, n_harmonics: int) -> np.ndarray:
    """Regressors [1, cos(w0 t), sin(w0 t), cos(2 w0 t), ...] of the times ``t``."""
    # cos(k w0 t), sin(k w0 t) from powers of exp(j w0 t) (one exp instead of 2K trig)
    powers = np.cumprod(np.broadcast_to(np.exp(1j * w0 * t), (n_harmonics, t.size)), axis=0)
    a = np.empty((t.size, 2 * n_harmonics + 1))
    a[:, 0] = 1.0
    a[:, 1::2] = powers.real.T
    a[:, 2::2] = powers.imag.T
    return a


def harmonic_fit(t: np.ndarray, x: np.ndarray, f0: float, n_harmonics: int,
                 trend: bool = False):
    """
    Least-squares fit of x(t) by a mean and ``n_harmonics`` harmonics of f0.

    Returns (phasors (complex, amplitude and phase of cos), residual, covariance
    of the real coefficients [mean, a1, b1, a2, b2, ...]).  Phasor convention:
    x = Re(X_k exp(j k w0 t)), i.e. X_k = a_k - j b_k for a_k cos + b_k sin.
    ``trend``: a straight line is fitted with them (a laser's or a mount's drift; not
    orthogonal to the harmonics, so fitted jointly), its row and column left out of the
    covariance (the others' marginal).  The normal equations are accumulated over
    ``FIT_CHUNK_ROWS`` rows at a time (memory independent of the record length; a record
    of one chunk gives the same numbers as the whole matrix at once).
    """
    w0 = 2 * np.pi * f0
    t = np.asarray(t, float)
    x = np.asarray(x, float)
    mid, half = 0.5 * (t[0] + t[-1]), max(0.5 * (t[-1] - t[0]), 1e-300)

    def columns(tk):
        a = _harmonic_columns(tk, w0, n_harmonics)
        return np.column_stack([a, (tk - mid) / half]) if trend else a
    m = 2 * n_harmonics + 1 + int(trend)
    gram = np.zeros((m, m))
    atx = np.zeros(m)
    chunks = [slice(k, k + FIT_CHUNK_ROWS) for k in range(0, t.size, FIT_CHUNK_ROWS)]
    for sl in chunks:
        a = columns(t[sl])
        gram += a.T @ a
        atx += a.T @ x[sl]
    gram_inv = np.linalg.pinv(gram)
    coef = gram_inv @ atx
    resid = np.empty(t.size)
    for sl in chunks:
        resid[sl] = x[sl] - columns(t[sl]) @ coef
    dof = max(t.size - m, 1)
    band = _band_variance(resid, (t.size - 1) / max(t[-1] - t[0], 1e-300), f0, n_harmonics)
    sigma2 = float(resid @ resid) / dof if band is None else band
    keep = slice(0, 2 * n_harmonics + 1)
    cov = sigma2 * gram_inv[keep, keep]
    phasors = coef[1:2 * n_harmonics + 1:2] - 1j * coef[2:2 * n_harmonics + 1:2]
    return phasors, resid, cov


#: Fewest periodogram bins the harmonics' noise level is read from (else the residual's
#: variance): a median of 32 exponential bins is within ~25 % of the level.
MIN_NOISE_BINS = 32


def _band_variance(resid: np.ndarray, fs: float, f0: float, n_harmonics: int) -> float | None:
    """
    Return the residual's white-equivalent variance about the harmonics, or None.

    The coefficients' uncertainty is the noise at their frequencies: mains hum or a far
    vibration in the residual is power the harmonics' regressors do not see (5 % hum made a
    wrong model's chi2/dof 27 read 0.9).  Hann periodogram over 0.5 f0 .. (n + 0.5) f0, the
    fitted lines' own bins left out, its median over ln 2 (the mean of exponential bins,
    robust to a line in the band): sigma^2 for white noise.
    """
    n, df = resid.size, fs / resid.size
    band = np.arange(int(np.ceil(0.5 * f0 / df)), int((n_harmonics + 0.5) * f0 / df) + 1)
    band = band[band <= n // 2]
    nearest = f0 * np.clip(np.rint(band * df / f0), 1, n_harmonics)
    band = band[np.abs(band * df - nearest) > 2.5 * df]
    if band.size < MIN_NOISE_BINS:
        return None
    # a noise level needs no double precision: the Hann-windowed residual and its spectrum
    # in single (4 B per sample each; compare's memory per sample is bounded)
    x = np.arange(n, dtype=np.float32)
    x *= np.float32(2 * np.pi / max(n - 1, 1))
    np.cos(x, out=x)
    x *= np.float32(-0.5)
    x += np.float32(0.5)
    norm = float(np.sum(np.square(x), dtype=np.float64))
    x *= resid
    spectrum = scipy.fft.rfft(x)
    del x
    power = np.abs(spectrum[band].astype(complex)) ** 2 / norm
    return float(np.median(power) / np.log(2.0))


def phasor_sd(cov: np.ndarray, phasor: complex, k: int = 1) -> tuple[float, float]:
    """Return the sd of ln|X| and arg X for harmonic k from the coefficient covariance."""
    ia, ib = 2 * k - 1, 2 * k
    a, b = phasor.real, -phasor.imag
    mag2 = a * a + b * b
    # gradient of ln|X| = 0.5 ln(a^2+b^2) and of arg X = atan2(-b, a)
    g_mag = np.array([a / mag2, b / mag2])
    g_ph = np.array([b / mag2, -a / mag2])
    c = cov[np.ix_([ia, ib], [ia, ib])]
    return float(np.sqrt(g_mag @ c @ g_mag)), float(np.sqrt(g_ph @ c @ g_ph))


def fundamental_response(time_s, deflection_m, current_a, *, frequency_hz: float | None = None,
                         n_harmonics: int | None = None, source: str = '',
                         min_periods: int = 2) -> FrequencyPoint:
    """H at the excitation fundamental of a periodic record (see module doc)."""
    t = np.asarray(time_s, float)
    w = np.asarray(deflection_m, float)
    i = np.asarray(current_a, float)
    if not (t.size == w.size == i.size) or t.size < 16:
        raise DataError(f'{source}: need at least 16 samples of time, deflection and current')
    fs = float((t.size - 1) / (t[-1] - t[0]))
    f0 = float(frequency_hz) if frequency_hz else _coarse_frequency(t, w, fs)
    if not f0 > 0:
        raise DataError(f'{source}: no excitation found in the deflection')
    duration = t[-1] - t[0] + 1.0 / fs
    if frequency_hz is None:
        # refine f0: minimise the residual of a 3-harmonic fit of the deflection
        def cost(f):
            return float(np.sum(harmonic_fit(t, w, f, 3)[1] ** 2))
        span = 1.0 / duration
        res = minimize_scalar(cost, bounds=(max(f0 - span, 0.5 * f0), f0 + span), method='bounded',
                              options={'xatol': 1e-6 * f0})
        f0 = float(res.x)
    periods = int(np.floor(duration * f0 + 1e-9))
    if periods < min_periods:
        raise DataError(f'{source}: record holds {duration * f0:.2f} periods of {f0:.4g} Hz; '
                        f'need at least {min_periods}')
    n_keep = int(round(periods / f0 * fs))
    sl = slice(t.size - n_keep, t.size)
    tt, ww, ii = t[sl] - t[sl][0], w[sl], i[sl]
    k_max = n_harmonics or int(max(1, min(12, np.floor(USABLE_BAND_FRACTION * fs / f0))))
    pw, resid_w, cov_w = harmonic_fit(tt, ww, f0, k_max)
    variance_w = float(np.var(ww))
    if variance_w > 0 and float(np.mean(resid_w ** 2)) > MAX_APERIODIC_FRACTION * variance_w:
        raise NotPeriodic(
            f'{source}: the deflection is not periodic: mean + {k_max} harmonics of {f0:.4g} Hz '
            f'explain {100 * (1 - float(np.mean(resid_w ** 2)) / variance_w):.0f} % of it (need '
            f'{100 * (1 - MAX_APERIODIC_FRACTION):.0f} %)', f0)
    pi_, _, cov_i = harmonic_fit(tt, ii, f0, k_max)
    h = pi_[0] / pw[0]
    sdm_w, sdp_w = phasor_sd(cov_w, pw[0])
    sdm_i, sdp_i = phasor_sd(cov_i, pi_[0])
    return FrequencyPoint(
        frequency_hz=f0,
        response=complex(h),
        sd_log_mag=float(np.hypot(sdm_w, sdm_i)),
        sd_phase_rad=float(np.hypot(sdp_w, sdp_i)),
        deflection_amplitude_m=float(abs(pw[0])),
        source=source,
        window=(float(t[sl][0]), float(t[sl][-1])),
        extra={
            'periods': periods,
            'harmonics': k_max,
            'harmonic_ratio_deflection': [float(abs(p / pw[0])) for p in pw[1:4]],
            'harmonic_ratio_current': [float(abs(p / pi_[0])) for p in pi_[1:4]],
        },
    )


def cross_spectral_response(time_s, deflection_m, current_a, *, nperseg: int | None = None,
                            band_hz: tuple[float, float] | None = None, min_coherence: float = 0.5,
                            source: str = '') -> list[FrequencyPoint]:
    """
    Welch H1 estimate with coherence for broadband records (see module doc).

    Returns points in ``band_hz`` whose coherence is at least ``min_coherence``.
    """
    t = np.asarray(time_s, float)
    w = np.asarray(deflection_m, float)
    i = np.asarray(current_a, float)
    fs = float((t.size - 1) / (t[-1] - t[0]))
    nperseg = int(nperseg or min(t.size, 2 ** int(np.floor(np.log2(max(t.size / 8, 16))))))
    f, pww = sig.welch(w, fs, nperseg=nperseg)
    _, pwi = sig.csd(w, i, fs, nperseg=nperseg)
    _, coh = sig.coherence(w, i, fs, nperseg=nperseg)
    n_avg = max(1, int(2 * t.size / nperseg - 1))   # 50 % overlap Hann segments
    h = pwi / np.where(pww > 0, pww, np.inf)
    lo, hi = band_hz or (f[1], USABLE_BAND_FRACTION * fs)
    out = []
    for fk, hk, gk in zip(f, h, coh):
        if fk < lo or fk > hi or gk < min_coherence or hk == 0:
            continue
        sd = float(np.sqrt((1 - gk) / (2 * n_avg * gk)))
        out.append(
            FrequencyPoint(
                frequency_hz=float(fk),
                response=complex(hk),
                sd_log_mag=sd,
                sd_phase_rad=sd,
                coherence=float(gk),
                source=source,
            )
        )
    return out
