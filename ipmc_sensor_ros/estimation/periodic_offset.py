# SPDX-License-Identifier: Apache-2.0
"""
Current offset learned from whole periods of periodic motion.

Why it works
------------
``H(0) = 0`` (eq. 45: ``H_n(s) = s R_n(s)``): the sensing current integrates to the
sensor's charge ``q = R_n w``, so the integral of the measured current ``i = s R_n w + b
+ n`` over any time T is ``q(t) - q(t - T) + b T`` (+ noise).  While the sensor moves,
q(t) - q(t - T) is unknown and a constant offset b is exactly a constant velocity b / R0:
without a rest (:mod:`~.kalman`) or a model of the motion the two cannot be told apart.
Periodic motion (a crank-slider, a gait, a vibrating test rig) is such a model: over a
whole number k of periods P the charge returns, ``q(t) - q(t - kP) = 0``, whatever the
level the motion oscillates about, so the mean current over k periods is b.

An estimated period is never exact, and ``q(t) - q(t - k P')`` with ``P' = P + d`` leaves
``R0 v(t) d / P`` (0.1 mm/s ... 0.25 m/s tip velocities: tens of nA for d / P = 1e-3).
:func:`periodic_offset` therefore compares one-period *means* of the charge,
``Qbar(t) = mean of Q over [t - P', t]`` with ``Q = integral of i``: the mean of a periodic
q over any interval of one true period is the same, so the velocity term cancels and only
``(d / P) * max|q| / (k P)`` is left (0.1 nA for a 2 mm crank on the slim sample with
d / P = 1e-3 and k P = 8 s):

    b_k = (Qbar(t) - Qbar(t - k P')) / (k P').

The period comes from the autocorrelation of the current over the last ``window_s``
(first peak above ``MIN_CORRELATION``, refined on the peak nearest the longest multiple
of it that still overlaps a quarter of the window).  A motion is accepted as periodic only
if ``b_k`` agrees with ``b_h`` (h = ceil(k / 2), the same end, half the periods) within
``AGREE_SIGMAS`` times the white-noise standard deviation of ``b_h``: a start, a stop, a
decaying vibration or a drifting level all change q between the two windows differently
and are refused; and only if each one-period difference ``Qbar(t - jP) - Qbar(t - (j+1)P)``
lies within ``PERIOD_SIGMAS`` of its own white noise from ``b_k P`` (a motion fading in
changes its one-period mean while it grows, in both windows alike: 24 nA taken for offset
1 s into a 5 Hz crank fading in over 0.5 s).  The largest k that passes is used.  White
current noise sigma (per sample at fs) leaves ``sigma / sqrt(fs k P)`` in b_k (0.22 nA for
20 nA over 8 s at 1 kHz).

Where it cannot help: non-periodic motion (robot moves, steps, sweeps), periods longer than
``window_s / (MIN_PERIODS + 1)`` (2.7 s by default), and periodic motion whose mean level
changes with time (indistinguishable from an offset, see :mod:`~.kalman`).

The buffer keeps the running sums of the current and of the deflection estimate on a grid
of at most ``BUFFER_RATE_HZ`` (integer decimation of fs), so its cost does not grow with fs.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ['PeriodicOffset', 'periodic_offset', 'motion_period']

#: Length of the history searched for periods, s.
WINDOW_S = 8.0
#: Rate of the stored running sums, Hz (the decimation keeps 1 ms resolution or better).
BUFFER_RATE_HZ = 2000.0
#: Smallest peak of the normalised autocorrelation that counts as a period (1 % white noise
#: gives 0.9999 on a crank; a random robot motion stays below 0.5 at its own time scales).
MIN_CORRELATION = 0.9
#: Fewest whole periods in an offset estimate (k >= 2, compared against h = 1).
MIN_PERIODS = 2
#: b_k and b_h must agree within this many standard deviations of b_h's white noise.
AGREE_SIGMAS = 3.0
#: Each one-period difference of Qbar must lie within this many standard deviations of its
#: white noise from b_k P (4: a 6e-5 chance per period, under 1 % over the 160 periods of a
#: 20 Hz motion in 8 s, of refusing periodic motion; a refusal only delays the estimate).
PERIOD_SIGMAS = 4.0


def motion_period(x: np.ndarray, min_lag: int = 2) -> tuple[float, float] | None:
    """
    Return (period in samples, autocorrelation at it) of a record, or None.

    The peak of the first stretch of the normalised autocorrelation above
    ``MIN_CORRELATION`` after its first zero crossing (a period's multiples correlate as
    well, so the largest value is not the period); refined to a fraction of a sample on the
    peak near its largest multiple that overlaps at least a quarter of the record and still
    correlates (parabolic interpolation).  Each lag is normalised by the energies of its two
    overlapping parts, so a motion fading in or out keeps its correlation.
    """
    x = np.asarray(x, float)
    n = x.size
    if n < 8:
        return None
    x = x - x.mean()
    nfft = 1 << int(math.ceil(math.log2(2 * n)))
    spec = np.fft.rfft(x, nfft)
    r = np.fft.irfft(spec.real ** 2 + spec.imag ** 2, nfft)[:n]
    if not r[0] > 0:
        return None
    cs = np.concatenate([[0.0], np.cumsum(x * x)])
    lags = np.arange(n)
    r = r / np.sqrt(np.maximum(cs[n - lags] * (cs[n] - cs[lags]), 1e-300))
    half = n // 2
    neg = np.flatnonzero(r[:half] < 0)
    if neg.size == 0:
        return None
    lo = max(int(neg[0]), min_lag)
    if lo >= half - 1:
        return None
    # the first stretch above MIN_CORRELATION holds the period (later ones its multiples)
    above = np.flatnonzero(r[lo:half] >= MIN_CORRELATION)
    if above.size == 0:
        return None
    start = lo + int(above[0])
    below = np.flatnonzero(r[start:half] < MIN_CORRELATION)
    stop = start + (int(below[0]) if below.size else half - start)
    p1 = start + int(np.argmax(r[start:stop]))
    if p1 >= half - 1:
        return None
    for m in range(max(1, int(0.75 * n / p1)), 0, -1):
        k0 = max(1, int(round(m * p1 - p1 / 4)))
        k1 = min(n - 2, int(round(m * p1 + p1 / 4)))
        pk = k0 + int(np.argmax(r[k0:k1 + 1]))
        if r[pk] >= MIN_CORRELATION and 1 <= pk <= n - 2:
            break
    else:
        return None
    y0, y1, y2 = r[pk - 1], r[pk], r[pk + 1]
    den = y0 - 2 * y1 + y2
    frac = 0.5 * (y0 - y2) / den if den < 0 else 0.0
    return (pk + float(np.clip(frac, -0.5, 0.5))) / m, float(r[pk])


def periodic_offset(q_sum, dt: float, period_s: float, sigma_a: float, fs: float):
    """
    Offset b (A) and its variance from whole periods, or None if not periodic.

    Parameters
    ----------
    q_sum : array_like
        Running integral of the current, A s, on a uniform grid of step ``dt`` ending now.
    dt : float
        Grid step, s.
    period_s : float
        Motion period, s.
    sigma_a : float
        White current noise, A RMS per sample at ``fs``.
    fs : float
        Sample rate of the current, Hz.

    Returns
    -------
    (b_a, variance_a2, periods) or None.
        ``variance_a2`` = white-noise variance of b_k + (b_k - b_h)^2.

    """
    q = np.asarray(q_sum, float)
    t = np.arange(q.size) * dt
    span = t[-1]
    k_max = int(span / period_s + 1e-9) - 1
    if k_max < MIN_PERIODS:
        return None
    # running integral of Q (trapezoid), so that Qbar = mean of Q over one period
    qq = np.concatenate([[0.0], np.cumsum(0.5 * (q[1:] + q[:-1]) * dt)])

    def qbar(end):
        return (np.interp(end, t, qq) - np.interp(end - period_s, t, qq)) / period_s

    # one-period differences D_j = Qbar(now - j P) - Qbar(now - (j + 1) P), j = 0 .. k_max - 1
    d = -np.diff(qbar(span - period_s * np.arange(k_max + 1)))
    # white noise: D_j weights the current by a triangle of base 2P, variance (2P/3) s^2/fs
    sd_d = sigma_a * math.sqrt(2.0 * period_s / (3.0 * fs))
    b_sum = np.cumsum(d)                       # b_k = b_sum[k - 1] / (k P)
    for k in range(k_max, MIN_PERIODS - 1, -1):
        h = (k + 1) // 2
        bk, bh = b_sum[k - 1] / (k * period_s), b_sum[h - 1] / (h * period_s)
        sd_h = sigma_a / math.sqrt(fs * h * period_s)
        if (abs(bk - bh) <= AGREE_SIGMAS * sd_h
                and np.max(np.abs(d[:k] - bk * period_s)) <= PERIOD_SIGMAS * sd_d):
            return bk, sigma_a ** 2 / (fs * k * period_s) + (bk - bh) ** 2, k
    return None


class PeriodicOffset:
    """
    Running sums of the current and the estimate, and the offset they give (module docstring).

    Parameters
    ----------
    fs : sample rate, Hz.
    window_s : history kept, s.

    """

    def __init__(self, fs: float, window_s: float = WINDOW_S):
        self.fs = float(fs)
        self.decim = max(1, int(self.fs // BUFFER_RATE_HZ))
        self.size = max(8, int(round(window_s * self.fs / self.decim)) + 1)
        self.reset()

    def reset(self) -> None:
        """Forget the history (a new motion segment)."""
        self.q_total = 0.0            # running sum of the current, A (x 1/fs: A s)
        self.u_total = 0.0            # running sum of the estimate u, m
        self.n = 0                    # samples taken since the reset
        self.grid_q: list[float] = [0.0]
        self.grid_u: list[float] = [0.0]

    def get_state(self) -> dict:
        return {'q_total': self.q_total, 'u_total': self.u_total, 'n': self.n,
                'grid_q': list(self.grid_q), 'grid_u': list(self.grid_u)}

    def set_state(self, state: dict) -> None:
        self.q_total = float(state['q_total'])
        self.u_total = float(state['u_total'])
        self.n = int(state['n'])
        self.grid_q = [float(v) for v in state['grid_q']]
        self.grid_u = [float(v) for v in state['grid_u']]

    def _trim(self) -> None:
        extra = len(self.grid_q) - self.size
        if extra > 0:
            del self.grid_q[:extra]
            del self.grid_u[:extra]

    def extend(self, y: np.ndarray, u: np.ndarray) -> None:
        """Take a run of moving samples: current y (A) and estimate u (m)."""
        if y.size == 0:
            return
        d = self.decim
        cq = np.cumsum(np.concatenate([[self.q_total], y]))[1:]
        cu = np.cumsum(np.concatenate([[self.u_total], u]))[1:]
        first = (-self.n - 1) % d                 # index of the first sample ending a cell
        self.grid_q.extend(cq[first::d].tolist())
        self.grid_u.extend(cu[first::d].tolist())
        self.q_total, self.u_total = float(cq[-1]), float(cu[-1])
        self.n += y.size
        self._trim()

    def add_one(self, y: float, u: float) -> None:
        """Take one moving sample (the same sums as :meth:`extend`)."""
        self.q_total += y
        self.u_total += u
        self.n += 1
        if self.n % self.decim == 0:
            self.grid_q.append(self.q_total)
            self.grid_u.append(self.u_total)
            if len(self.grid_q) > self.size:
                del self.grid_q[0]
                del self.grid_u[0]

    def shift_u(self, delta_m: float) -> None:
        """Rewrite the kept history as if the estimate u had been ``delta_m`` lower throughout."""
        d = self.decim
        n_last = self.n - self.n % d
        counts = n_last - d * np.arange(len(self.grid_u) - 1, -1, -1)
        self.grid_u = (np.asarray(self.grid_u) - delta_m * counts).tolist()
        self.u_total -= delta_m * self.n

    def estimate(self, sigma_a: float):
        """
        (b_a, variance_a2, period_s, mean_u_m, span_s) from the history, or None.

        None when the motion is not periodic; ``span_s`` = k P, the whole periods used, and
        ``mean_u_m`` the mean of the estimate u over them.
        """
        g = np.asarray(self.grid_q)
        if g.size < 8:
            return None
        dt = self.decim / self.fs
        current = np.diff(g) / self.decim            # cell means of the current, A
        found = motion_period(current)
        if found is None:
            return None
        period_s = found[0] * dt
        res = periodic_offset(g / self.fs, dt, period_s, sigma_a, self.fs)
        if res is None:
            return None
        b, var, k = res
        gu = np.asarray(self.grid_u)
        t = np.arange(gu.size) * dt
        span = t[-1]
        mean_u = (gu[-1] - np.interp(span - k * period_s, t, gu)) / (k * period_s * self.fs)
        return b, var, period_s, float(mean_u), k * period_s
