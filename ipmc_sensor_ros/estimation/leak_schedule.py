# SPDX-License-Identifier: Apache-2.0
"""
Motion-adaptive deflection leak corner for :class:`~.kalman.KalmanEstimator`.

While the sensor moves, the Kalman estimate w leaks towards the last held level
w_ref at a corner f (``w' = v - 2 pi f (w - w_ref)``).  Three errors depend on f
(R0 = R_n(0), A s/m; current noise sigma A RMS per sample at fs; offset error of
variance P_b, A^2; t = time since the motion began, s):

* the leak itself: a high-pass at f on u = w - w_ref.  On motion of mean square S and
  velocity mean square V about w_ref it loses ``(f / f_eff)^2 S`` with
  ``f_eff = sqrt(V / S) / 2 pi`` (a sinusoid at f_m: f_eff = f_m, error f / f_m); and
  a level M held away from w_ref (a robot that moved there and keeps moving about it)
  decays as ``M (1 - exp(-w_f t))``, w_f = 2 pi f.  M^2 is the square of the running
  mean of u less what an oscillation leaves in a running mean of time constant tau,
  ``2 S / (1 + (2 pi f_eff tau)^2)``, and less ``WANDER_SIGMAS^2`` times the mean-square
  noise and offset wander predicted at the slowest allowed corner (the two terms below):
  the estimate's own drift must not read as a held level, or it would keep the corner
  that lets it drift (judged at the floor, not at the corner in use, so that the choice
  cannot flip back and forth with it);
* white current noise: it is a white velocity of two-sided PSD sigma^2 / (fs R0^2)
  integrated by 1 / (s + w_f), w_f = 2 pi f: variance
  ``sigma^2 / (fs R0^2) * (1 - exp(-2 w_f t)) / (2 w_f)``;
* the offset error: a constant velocity error db / R0 ramping w through the same
  integrator: ``P_b / R0^2 * ((1 - exp(-w_f t)) / w_f)^2``.

:meth:`LeakSchedule.choose` picks, from a ladder of corners (``LADDER_RATIO`` apart),
the one minimising the sum J(f) of these mean squares, from quantities the filter
measures causally: mean(u), S and V as running means (``STATS_WINDOW_S`` = tau) of the
estimate's u, u^2 and squared sample-to-sample velocity, sigma^2 the white noise
measured above 0.3 fs (the estimator's fourth-order noise meter), P_b the offset
variance (learned at rest, growing by the drift while moving), t the samples since
leaving rest.  Under 1 % noise sigma and S^(1/2) f_m both scale
with the motion, so the optimum scales with f_m (measured on the slim sample after a
2 s rest: 0.016 Hz at 1 Hz, 0.064 Hz at 5 Hz, 0.256 Hz at 20 Hz, i.e. 0.013-0.016
f_m); a short move after a hold keeps the slowest corner (all three terms are small at
small t), a long one raises it as its noise and offset ramps grow.  Before the first
rest the offset is not observable (any value of it fits the current, ``H(0) = 0``): the
offset term is left out and the floor is ``START_LEAK_CORNER_HZ`` (the clean 1 Hz crank
then keeps its 2 % leak error).
Decisions are taken every ``STEP_S`` on a fixed sample grid (so blocks of any size
and single samples decide identically) and only when J drops by ``HYSTERESIS``;
the corner never exceeds ``CEILING_FRACTION * f_eff`` nor ``CEILING_HZ``.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.signal as sig

__all__ = ['LeakSchedule', 'leak_error_terms']

#: Ratio between neighbouring corners of the ladder (J is flat within a factor 2 of its
#: minimum: the leak term grows as f^2, the noise term falls as 1/f).
LADDER_RATIO = 2.0
#: Highest corner, Hz: 1 Hz keeps the leak's phase lead below 3 deg down to 20 Hz motion.
CEILING_HZ = 1.0
#: Highest corner relative to the motion's f_eff: a 5 % amplitude / 3 deg phase error on it.
CEILING_FRACTION = 0.05
#: Time constant of the running means M, S, V: two periods of 1 Hz motion (a 0.2 Hz motion
#: is then averaged over less than a cycle, so S and V fluctuate; the leak term keeps the
#: corner low there).
STATS_WINDOW_S = 2.0
#: Decision interval, s: half the stats window (S and V change little in between); one per
#: 1000-sample block at 1 kHz, which keeps the decisions cheap.
STEP_S = 1.0
#: A running mean of u counts as a held level only beyond this many standard deviations of
#: the wander predicted at the slowest allowed corner (3: a 0.3 % chance per decision of reading an
#: offset or noise drift as a level).
WANDER_SIGMAS = 3.0
#: Switch only when the predicted mean-square error falls by this fraction (hysteresis): the
#: statistics describe the last ~2 s, and a robot's next move can take u far from w_ref, which a
#: higher corner then leaks at 2 pi f |u| per second.  Halving (the RMS error falls by 29 %)
#: keeps the slow corner on robot-like motion (at 0.2 a move after a hold raised it and lost
#: 0.1 mm, seed 1 of the bench's robot row); on cranks the optimum is several times better.
HYSTERESIS = 0.5


def leak_error_terms(f_hz, m_m, s_m2, v_m2_s2, sigma2_a2, p_b_a2, t_s, r0, fs,
                     wander_m2=0.0):
    """
    Predicted mean-square errors (m^2) of a leak at ``f_hz``: (leak, noise, offset).

    Parameters
    ----------
    f_hz : array_like
        Leak corner(s), Hz.
    m_m : float
        Running mean of u = w - w_ref, m.
    s_m2 : float
        Mean square of u, m^2.
    v_m2_s2 : float
        Mean square of the velocity of u, m^2/s^2.
    sigma2_a2 : float
        White current noise variance per sample, A^2.
    p_b_a2 : float
        Offset error variance, A^2 (0: left out).
    t_s : float
        Time since the motion began, s.
    r0 : float
        R_n(0), A s/m.
    fs : float
        Sample rate, Hz.
    wander_m2 : float
        What the estimate's own drift puts into m_m^2 (not a held level), m^2.

    """
    f = np.asarray(f_hz, float)
    wf = 2 * math.pi * f
    if v_m2_s2 > 0:
        leak = (wf * s_m2) ** 2 / v_m2_s2
        residual = 2 * s_m2 / (1 + v_m2_s2 / s_m2 * STATS_WINDOW_S ** 2)
    else:
        leak, residual = np.zeros_like(f), 0.0
    leak = leak + max(m_m * m_m - residual - wander_m2, 0.0) * np.expm1(-wf * t_s) ** 2
    noise = sigma2_a2 / (fs * r0 * r0) * -np.expm1(-2 * wf * t_s) / (2 * wf)
    offset = p_b_a2 / (r0 * r0) * (np.expm1(-wf * t_s) / wf) ** 2
    return leak, noise, offset


class LeakSchedule:
    """
    Running motion statistics and the chosen leak-corner index (see the module docstring).

    Parameters
    ----------
    fs : sample rate, Hz.
    r0 : R_n(0), A s/m.
    floor_hz : slowest corner (the estimator's ``leak_corner_hz``), Hz.
    start_hz : floor before the first rest and while the offset is not trusted, Hz.

    """

    def __init__(self, fs: float, r0: float, floor_hz: float, start_hz: float):
        self.fs, self.r0 = float(fs), float(r0)
        top = max(min(CEILING_HZ, fs / 20.0), floor_hz, start_hz)
        n = int(math.floor(math.log(top / floor_hz) / math.log(LADDER_RATIO) + 1e-9)) + 1
        corners = {floor_hz * LADDER_RATIO ** k for k in range(n)} | {max(start_hz, floor_hz)}
        self.corners_hz = np.array(sorted(corners))
        self._wf = (2 * math.pi * self.corners_hz).tolist()
        self.floor_index = 0
        self.start_index = int(np.flatnonzero(self.corners_hz == max(start_hz, floor_hz))[0])
        self.step = max(1, int(round(STEP_S * fs)))
        self.alpha = math.exp(-1.0 / (fs * STATS_WINDOW_S))
        self.reset()

    def reset(self) -> None:
        self.index = self.start_index
        self.stats = np.zeros(4)        # running means of [1, u, u^2, v^2] (weight, M, S, V)
        self.u_prev = 0.0
        self.moving_n = 0               # samples since the motion began
        self.count = 0                  # absolute sample counter (decision grid)

    def get_state(self) -> dict:
        return {'index': self.index, 'stats': self.stats.copy(), 'u_prev': self.u_prev,
                'moving_n': self.moving_n, 'count': self.count}

    def set_state(self, state: dict) -> None:
        self.index = int(state['index'])
        self.stats = np.asarray(state['stats'], float).copy()
        self.u_prev = float(state['u_prev'])
        self.moving_n = int(state['moving_n'])
        self.count = int(state['count'])

    @property
    def corner_hz(self) -> float:
        """Return the leak corner in use, Hz."""
        return float(self.corners_hz[self.index])

    def f_eff_hz(self, stats=None) -> float:
        """Return the motion's effective frequency sqrt(V / S) / 2 pi, Hz (0 if unknown)."""
        w, _, s, v = self.stats if stats is None else stats
        return math.sqrt(v / s) / (2 * math.pi) if s > 0 and v > 0 and w > 0 else 0.0

    def choose(self, stats, sigma2_a2, p_b_a2, floor_index, moving_n) -> np.ndarray:
        """
        Corner index minimising J with hysteresis, within [floor, ceiling].

        For each decision point (columns of ``stats``, shape (4, G); the other arguments
        scalars or length G), judged against the index in use, up to the first point that
        changes it (the caller cuts the run there; later entries repeat that choice).
        """
        st = np.asarray(stats, float).reshape(4, -1)
        g = st.shape[1]
        cols = [np.broadcast_to(np.asarray(x, float), (g,)).tolist()
                for x in (sigma2_a2, p_b_a2, floor_index, moving_n)]
        out = np.full(g, self.index)
        for c, (wgt, m, s, v) in enumerate(st.T.tolist()):
            k = self._choose_one(wgt, m, s, v, *(col[c] for col in cols))
            if k != self.index:
                out[c:] = k
                break
        return out

    def _choose_one(self, wgt, m, s, v, sigma2_a2, p_b_a2, floor, moving_n) -> int:
        """One decision: J = the sum of :func:`leak_error_terms` over the allowed corners."""
        floor = int(floor)
        if not (wgt > 0 and s > 0 and v > 0):
            return floor
        s, v, m = s / wgt, v / wgt, m / wgt
        corners = self.corners_hz
        f_eff = math.sqrt(v / s) / (2 * math.pi)
        top = max(corners[floor], min(CEILING_HZ, CEILING_FRACTION * f_eff))
        hi = int(np.searchsorted(corners, top * (1 + 1e-9), side='right'))
        if hi <= floor + 1:
            return floor
        args = (sigma2_a2, p_b_a2, moving_n / self.fs, self.r0, self.fs)
        # the estimate's own wander, judged at the slowest allowed corner (module docstring)
        _, noise, offset = leak_error_terms(corners[floor], m, s, v, *args)
        wander = WANDER_SIGMAS ** 2 * float(noise + offset)
        j = sum(leak_error_terms(corners[floor:hi], m, s, v, *args, wander_m2=wander))
        best = floor + int(np.argmin(j))
        cur = self.index
        if not floor <= cur < hi or j[best - floor] < (1.0 - HYSTERESIS) * j[cur - floor]:
            return best
        return cur

    def stats_sequence(self, u: np.ndarray) -> np.ndarray:
        """Return the running means after each sample of u (shape (4, n)); state unchanged."""
        v = np.diff(u, prepend=self.u_prev) * self.fs
        x = np.vstack([np.ones(u.size), u, u * u, v * v])
        a = self.alpha
        out, _ = sig.lfilter([1 - a], [1, -a], x, axis=1, zi=(a * self.stats)[:, None])
        return out

    def update_one(self, u: float) -> None:
        """Take one moving sample u = w - w_ref into the running means."""
        v = (u - self.u_prev) * self.fs
        a, b = self.alpha, 1.0 - self.alpha
        st = self.stats
        st[0] = a * st[0] + b
        st[1] = a * st[1] + b * u
        st[2] = a * st[2] + b * u * u
        st[3] = a * st[3] + b * v * v
        self.u_prev = u
        self.moving_n += 1
