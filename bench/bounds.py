# SPDX-License-Identifier: Apache-2.0
"""
Physical-limit bounds for the deflection estimate of a record (no estimator code).

What the best linear time-invariant filter that knows the true deflection spectrum could do
on the same record: on its nominal sample grid (no dropped rows, no jitter), with the offset
and the hum removed (clean current + the record's white noise and quantisation error); the
noise is white, S_n = sigma^2 + lsb^2/12 per sample; H_k = H(j 2 pi f_k) is the exact sensor
response (w band-limited: the DAQ samples the continuous current).

**Two models of the motion.**  A *stationary* record (zero-mean motion going on since before
power-on: cranks, sines) uses the spectrum S_x of x = w and R = H.  A record *from rest*
(steps, holds, pick-and-place, motion started in the record) uses the spectrum of its
increments x = w_n - w_(n-1) and R = H / D, D = 1 - e^(-j Omega): holds are then levels an
integrator keeps (S_w = S_x / |D|^2, unbounded at f = 0), and H(0) = 0 (a one-bin notch
that no finite FFT grid resolves) never appears, since R(0) = lim H / D != 0.  The estimate
of w is then the running sum of the estimated increments from the true w_0 (0 for a record
from rest; the field record's level at power-on, which the bound is given).

**Oracle spectrum.**  The periodogram of x over the record, zero-padded to ``pad`` x its
length (the transform of its biased autocorrelation: a valid spectrum), smoothed by a
triangle of half-width ``smooth_hz``.  Window: a Kaiser window (beta = KAISER_BETA, side
lobes ~ -100 dB) over a stationary record, so the truncation of an oscillation leaks no
power to f ~ 0 (the filter would otherwise integrate it); a ``taper_s`` cosine taper at the
end only of a record from rest (it has no edge at its start).

**Causal Wiener bound.**  Phi_y = |R|^2 S_x + S_n = s_e^2 |G|^2, G monic and minimum-phase,
by the cepstral method on the dense FFT grid (log Phi_y -> real cepstrum c; log s_e^2 = c_0;
log G = the transform of c_n, n > 0).  Wiener-Kolmogorov: W = [S_x R* / G*]_+ / (s_e^2 G)
([.]_+: lags n >= 0); for increments [U / D]_+ = (U_+ + U_-(1)) / D (U_-(1): the sum of U's
negative lags), the 1/D being the running sum.  Its impulse response is cut to lags
0 .. M/2 (exactly causal) and it runs from a zero state: at the record start for a record
from rest (zero current before it), at the start of ``grid_pre_current_a`` (the current of
the motion before power-on, which the estimator does not see) when the tip moves at power-on,
so the bound carries no cold-start transient: a lower bound there.  Reported: the raw NRMSE,
RMS(error)/RMS(w) over t >= ``after_s``.

**Non-causal Wiener bound.**  W = S_x R* / Phi_y, error spectrum S_e = S_x S_n / Phi_y.  On a
stationary record it is the expectation sqrt(sum S_e / sum S_x) (the zero bin left out:
H(0) = 0): a true lower bound.  On a record from rest it is the filter run on the record
(with ``grid_post_current_a``, the current after it, as its future), measured like the causal
one, and at most the causal bound (a smoother may ignore the future): not a lower bound,
since the best estimator of a record from rest is not time-invariant (a filter that knows
when the motion stopped stops integrating noise; the LTI filter integrates it all along).

**Offset-unknown causal bound.**  The bounds above are given the offset; an estimator must
learn it from the record.  With y = s + b u (s: the offset-free current, Gaussian with the
spectrum Phi_y; u: 1 on the record's samples, 0 on the pre-roll, which the estimator does
not see; b: a constant with a flat prior), Woodbury's identity splits the best estimate
from y_0..y_t exactly: E[w_t | y] = W (y - u b_t), where W is the offset-known filter and
b_t the generalised least-squares offset from y_0..y_t.  That estimate is the whitened
regression b_t = sum a_k e_k / sum a_k^2 over k <= t (e = y / G, a = u / G, both from a
zero state like the filter).  So the offset-unknown causal estimate is the causal one minus
(b_t - b) times the filter's response to u; its error does not depend on b (nor on the
offset's drift or the hum, which stay removed by oracle).  The same infinite-past
approximation as the causal bound; a lower bound where the estimator has no prior on the
offset.  Stationary records only: in the increments model of a record from rest a constant
current is a steady ramp of w as likely as the spectrum of its increments makes it, while
the record's rests (which show the offset) are a time-varying fact no LTI model holds, so
there it would be far above what an estimator that sees the rests reaches.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bench.scenarios import frequency_response, Record

__all__ = ['Bounds', 'wiener_bounds', 'record_bounds', 'nrmse', 'evaluation_mask']

#: Relative floor of the noise spectrum (to the current's mean square): keeps log Phi_y finite
#: on a noise-free record, far below any DAQ (1e-12 in power = 1e-6 in amplitude).
NOISE_FLOOR = 1e-12

#: Kaiser window parameter of a stationary record's periodogram (side lobes ~ -100 dB).
KAISER_BETA = 14.0


@dataclass
class Bounds:
    """Bounds of one record; NRMSE are fractions (0.01 = 1 %)."""

    causal_nrmse: float
    causal_offset_unknown_nrmse: float   # learning the offset (stationary records; else NaN)
    noncausal_nrmse: float        # stationary: expected; else min(realised, causal)
    noncausal_expected: float     # sqrt(sum S_e / sum S_w) (stationary records; else NaN)
    noncausal_realised: float     # the non-causal filter run on the record, after after_s
    causal_estimate_m: np.ndarray
    noncausal_estimate_m: np.ndarray
    causal_offset_unknown_estimate_m: np.ndarray


def evaluation_mask(time_s: np.ndarray, after_s: float) -> np.ndarray:
    """Return the samples evaluated: from ``after_s`` seconds after the record start on."""
    return np.asarray(time_s) >= after_s


def nrmse(estimate, truth, mask) -> float:
    """Raw NRMSE: RMS(estimate - truth) / RMS(truth) over ``mask`` (no level or scale fit)."""
    e = np.asarray(estimate)[mask] - np.asarray(truth)[mask]
    return float(np.sqrt(np.mean(e ** 2)) / np.sqrt(np.mean(np.asarray(truth)[mask] ** 2)))


def _even_length(n: float) -> int:
    from scipy.fft import next_fast_len
    return 2 * next_fast_len(int(math.ceil(n / 2)), real=True)


def _smooth(spectrum: np.ndarray, half_width: int) -> np.ndarray:
    """Triangular smoothing of a one-sided even spectrum (reflected at 0 and Nyquist)."""
    if half_width < 1:
        return spectrum
    kernel = np.bartlett(2 * half_width + 3)[1:-1]
    kernel /= kernel.sum()
    ext = np.concatenate([spectrum[half_width:0:-1], spectrum, spectrum[-2:-2 - half_width:-1]])
    return np.convolve(ext, kernel, mode='valid')


def _periodogram(x: np.ndarray, m: int, taper_n: int | None) -> np.ndarray:
    """
    |DFT_m(x * window)|^2 / sum(window^2).

    ``taper_n`` None: a Kaiser window over the whole record (a stationary record: no edge
    leakage down to f = 0 to mistake for slow motion); else a ``taper_n``-sample cosine
    taper at the end only (a record from rest has no edge at its start).
    """
    if taper_n is None:
        win = np.kaiser(x.size, KAISER_BETA)
    else:
        win = np.ones(x.size)
        k = min(taper_n, x.size // 2)
        win[x.size - k:] = 0.5 + 0.5 * np.cos(np.pi * (np.arange(k) + 0.5) / k)
    return np.abs(np.fft.rfft(x * win, m)) ** 2 / float(np.sum(win ** 2))


def _minimum_phase(phi: np.ndarray, m: int) -> tuple[float, np.ndarray]:
    """(s_e^2, G) with phi = s_e^2 |G|^2, G monic minimum-phase (cepstral method)."""
    c = np.fft.irfft(np.log(phi), m)
    c_plus = np.zeros(m)
    c_plus[1:m // 2] = c[1:m // 2]
    c_plus[m // 2] = 0.5 * c[m // 2]
    return float(np.exp(c[0])), np.exp(np.fft.rfft(c_plus))


def _filters(s_x: np.ndarray, r: np.ndarray, s_n: float, m: int, integrate: bool):
    """
    Causal and non-causal Wiener filters (DFT on the m-grid) of x from y = R x + noise.

    ``integrate``: the estimated x is then summed (x = increments of w, R = H / D): the causal
    part of U / D is (U_+ + U_-(1)) / D (U_-(1): the sum of U's negative lags), so the causal
    filter of w is that numerator over s_e^2 G, followed by the running sum.
    """
    phi = np.abs(r) ** 2 * s_x + s_n
    var_e, g = _minimum_phase(phi, m)
    u = np.fft.irfft(s_x * np.conj(r) / np.conj(g), m)
    anticausal_sum = float(np.sum(u[m // 2:])) if integrate else 0.0
    u[m // 2:] = 0.0
    k = np.fft.irfft((np.fft.rfft(u) + anticausal_sum) / (var_e * g), m)
    k[m // 2:] = 0.0                     # exactly causal (lags 0 .. m/2 - 1 >= record length)
    return np.fft.rfft(k), s_x * np.conj(r) / phi, phi, g


def _offset_error(y_f, u_f, g, m: int, span: slice) -> np.ndarray:
    """
    b_t - b of the whitened regression (module docstring) at every sample of ``span``.

    ``y_f``, ``u_f``: transforms on the m-grid of the offset-free current and of the offset's
    regressor u; ``g``: the monic minimum-phase factor of Phi_y.  The flat prior: the sums
    start where u does.
    """
    e = np.fft.irfft(y_f / g, m)[span]
    a = np.fft.irfft(u_f / g, m)[span]
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.cumsum(a * e) / np.cumsum(a * a)


def _motion_model(w, h, f, sample_rate_hz, response, stationary):
    """(x, R): (w, H) for a stationary record, (increments of w, H / D) for one from rest."""
    if stationary:
        x, r = w, h.copy()
        r[0] = 0.0
    else:
        x = np.diff(w, prepend=w[0])
        d = -np.expm1(-2j * np.pi * f / sample_rate_hz)
        d[0] = 1.0
        r = h / d
        f0 = 1e-6 * sample_rate_hz           # R(0) = lim H / D (H ~ j omega R0, D ~ j Omega)
        r[0] = (response(np.array([f0]))[0] / -np.expm1(-2j * np.pi * f0 / sample_rate_hz)).real
    r[-1] = abs(r[-1])                       # the Nyquist bin of a real filter is real
    return x, r


def wiener_bounds(current_a, deflection_m, sample_rate_hz: float, response, noise_var_a2: float,
                  *, stationary: bool, pre_current_a=None, post_current_a=None,
                  after_s: float = 1.0, pad: int = 4,
                  smooth_hz: float = 0.25, taper_s: float = 1.0) -> Bounds:
    """
    Causal and non-causal Wiener bounds (module docstring) of one uniformly sampled record.

    ``current_a``: the current the filters see (offset and hum removed), A; ``deflection_m``:
    the truth at the same samples; ``response(f_hz)``: H(j 2 pi f), A/m; ``noise_var_a2``:
    the white-noise variance per sample, A^2; ``stationary``: zero-mean motion going on since
    before the record (spectrum of w) or motion after rest (spectrum of its increments);
    ``pre_current_a``: the current before the record (motion going on at power-on), where the
    filters start (zero state there), or None: they start at the record (rest before it);
    ``post_current_a``: the current after it (the non-causal filter's future at the end).
    """
    w = np.asarray(deflection_m, dtype=float)
    n = w.size
    pre = np.zeros(0) if pre_current_a is None else np.asarray(pre_current_a, dtype=float)
    post = np.zeros(0) if post_current_a is None else np.asarray(post_current_a, dtype=float)
    n_pre = pre.size
    y = np.concatenate([pre, np.asarray(current_a, dtype=float), post])
    m = _even_length(pad * y.size)
    f = np.fft.rfftfreq(m, 1.0 / sample_rate_hz)
    h = np.asarray(response(f), dtype=complex)
    s_n = max(float(noise_var_a2), NOISE_FLOOR * float(np.mean(y ** 2)))
    x, r = _motion_model(w, h, f, sample_rate_hz, response, stationary)
    taper_n = None if stationary else int(round(taper_s * sample_rate_hz))
    s_x = _smooth(_periodogram(x, m, taper_n), int(round(smooth_hz * m / sample_rate_hz)))
    causal, noncausal, phi, g = _filters(s_x, r, s_n, m, integrate=not stationary)
    y_f = np.fft.rfft(y, m)
    span = slice(n_pre, n_pre + n)
    w_c = np.fft.irfft(causal * y_f, m)[span]
    w_nc = np.fft.irfft(noncausal * y_f, m)[span]
    if stationary:                                     # minus (b_t - b) x the response to u
        u_f = np.fft.rfft(np.concatenate([np.zeros(n_pre), np.ones(n)]), m)
        w_cu = w_c - _offset_error(y_f, u_f, g, m, span) * np.fft.irfft(causal * u_f, m)[span]
    else:
        w_c = w[0] + np.cumsum(w_c)
        w_nc = w[0] + np.cumsum(w_nc)
        w_cu = np.full(n, np.nan)
    t = np.arange(n) / sample_rate_hz
    mask = evaluation_mask(t, after_s)
    expected = float('nan')
    if stationary:
        s_e = s_x * s_n / phi
        weights = np.full(f.size, 2.0)
        weights[[0, -1]] = 0.0, 1.0          # the zero bin: H(0) = 0 (module docstring)
        expected = math.sqrt(float(np.sum(weights * s_e) / np.sum(weights * s_x)))
    realised, causal_nrmse = nrmse(w_nc, w, mask), nrmse(w_c, w, mask)
    bound = expected if stationary else min(realised, causal_nrmse)
    unknown = nrmse(w_cu, w, mask) if stationary else float('nan')
    return Bounds(causal_nrmse, unknown, bound, expected, realised, w_c, w_nc,
                  w_cu)


def record_bounds(record: Record, *, after_s: float = 1.0, **kwargs) -> Bounds:
    """:func:`wiener_bounds` of a :class:`~bench.scenarios.Record` (its nominal grid)."""
    var = record.noise_std_a ** 2 + record.lsb_a ** 2 / 12.0
    return wiener_bounds(record.grid_current_a, record.grid_deflection_m, record.sample_rate_hz,
                         lambda f: frequency_response(record.sensor, f), var,
                         stationary=record.stationary,
                         pre_current_a=record.grid_pre_current_a,
                         post_current_a=record.grid_post_current_a,
                         after_s=after_s, **kwargs)
