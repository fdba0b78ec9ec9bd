# SPDX-License-Identifier: Apache-2.0
"""
The Kalman filter on :class:`~.statespace.StateSpaceModel`: explicit state in, state out.

One recursion per sample, the same for a block and a single sample (a block is a loop over
its samples; there is no second implementation)::

    predict   x- = F_m x,  P- = F_m P F_m' + Q_m       (m = sample periods since the last
                                                         sample: missing samples bridged)
    rest test on the window of r = i - lines(x-)        (:mod:`.rest`)
    update    nu = i - c x-,  S = c P- c' + R,  K = P- c' / S,  x = x- + K nu,
              P = P- - K S K'
    at rest   velocity = 0, motion current = 0          (pseudo-measurements, :mod:`.rest`)
              working point = w                         (its prior released first:
                                                         :attr:`~.statespace.StateSpaceModel.hold_variance`)

R, the white-noise variance per sample, is measured on r = i - lines: the third difference
r_k - 3 r_{k-1} + 3 r_{k-2} - r_{k-3} has variance 20 R for white noise and passes a motion
current at f only as (2 sin(pi f / fs))^6 (4e-6 at 20 Hz and 1 kHz), so its square / 20,
averaged over ``NOISE_AVERAGE_S`` (weights normalised, so the first differences already give
R; ``current_noise_a`` until then), is R.  Differences across a bridged gap are skipped.  The state is held in scaled units (x / scale) so that every entry of P is
O(1) whatever the sensor (deflections of mm, currents of nA).

:class:`FilterState` is the whole state (what save/restore keeps); :meth:`KalmanFilter.run`
returns the new one and never changes the old.  Pass ``record`` to keep what the smoother
needs (:mod:`.smoother`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from .rest import RestTest
from .statespace import StateSpaceModel

__all__ = ['FilterState', 'KalmanFilter', 'ForwardRecord', 'NOISE_AVERAGE_S', 'NOISE_FLOOR_A']

#: Averaging time of the measured noise variance, s: long against one sample, short against a
#: record (the noise is known within a second of the start).
NOISE_AVERAGE_S = 1.0
#: One sample counts at most this many times the measured variance in the noise average (a
#: step in the current moves the measured noise by at most this, not by its square).
NOISE_CLIP = 25.0
#: The measured noise stays above this, A RMS (below any DAQ's noise; a noise-free record would
#: otherwise drive the gain to infinity).
NOISE_FLOOR_A = 1e-12


@dataclass(frozen=True)
class FilterState:
    """Everything the filter carries from one sample to the next (scaled units)."""

    x: np.ndarray
    P: np.ndarray
    noise_var_a2: float
    window: np.ndarray = field(repr=False)
    window_count: int = 0
    window_pos: int = 0
    still: bool = False
    samples: int = 0
    contiguous: int = 0
    noise_weight: float = 0.0
    line_sums: np.ndarray = field(default=None, repr=False)
    phase: np.ndarray = field(default=None, repr=False)
    phases: np.ndarray = field(default=None, repr=False)

    def copy(self) -> 'FilterState':
        return replace(self, x=self.x.copy(), P=self.P.copy(), window=self.window.copy(),
                       line_sums=self.line_sums.copy(), phase=self.phase.copy(),
                       phases=self.phases.copy())


@dataclass
class ForwardRecord:
    """Per-sample predictions and updates of a forward pass (what the RTS smoother needs)."""

    x_pred: np.ndarray
    P_pred: np.ndarray
    x_post: np.ndarray
    P_post: np.ndarray
    steps: np.ndarray
    still: np.ndarray

    @classmethod
    def empty(cls, n: int, nx: int) -> 'ForwardRecord':
        return cls(np.empty((n, nx)), np.empty((n, nx, nx)), np.empty((n, nx)),
                   np.empty((n, nx, nx)), np.empty(n, dtype=np.int64), np.empty(n, dtype=bool))


class KalmanFilter:
    """
    The recursion of the module docstring for ``model``.

    Parameters
    ----------
    model : StateSpaceModel
        The model (sensor, motion, offset, lines).
    rest_lines_hz : sequence of float, optional
        Lines the rest test fits in its window (default: the model's): a hum the model has no
        states for yet must not hide a rest.

    """

    def __init__(self, model: StateSpaceModel, rest_lines_hz=None):
        self.model = model
        cfg = model.config
        lines = tuple(model.lines_hz if rest_lines_hz is None or model.lines_hz
                      else rest_lines_hz)
        self.rest_lines_hz = lines
        self.rest = RestTest.design(cfg.rest_window_s, model.sample_rate_hz,
                                    cfg.rest_false_alarm, len(lines))
        # one step of each line's phasor e^{-i W_k / fs} (sliding DFT of the rest window)
        self._rot = np.exp(-2j * np.pi * np.asarray(lines) / model.sample_rate_hz)
        self._alpha = 1.0 / (NOISE_AVERAGE_S * model.sample_rate_hz)
        s = model.scale
        self._anchor = np.zeros(model.size)
        self._anchor[model.iw], self._anchor[model.ih] = s[model.iw], -s[model.ih]
        v2, m2 = model.rest_variances
        anchor_var = (cfg.rest_velocity_m_s / model.sample_rate_hz) ** 2
        accel = np.zeros(model.size)
        accel[model.ia] = model.scale[model.ia]
        self._rest_rows = ((model.c_velocity, v2), (accel, v2 * model.sample_rate_hz ** 2),
                           (model.c_motion, m2), (self._anchor, anchor_var))

    def initial_state(self) -> FilterState:
        x, P = self.model.prior()
        k = len(self.rest_lines_hz)
        return FilterState(x, P, self.model.config.current_noise_a ** 2,
                           np.zeros(self.rest.n), line_sums=np.zeros(k, complex),
                           phase=np.ones(k, complex), phases=np.ones((self.rest.n, k), complex))

    def deflection(self, state: FilterState) -> tuple[float, float]:
        """(w, its standard deviation) of a state, m."""
        m = self.model
        s = m.scale[m.iw]
        return float(state.x[m.iw] * s), math.sqrt(max(float(state.P[m.iw, m.iw]), 0.0)) * s

    def offset(self, state: FilterState) -> tuple[float, float]:
        """(current offset, its standard deviation) of a state, A."""
        m = self.model
        s = m.scale[m.ib]
        return float(state.x[m.ib] * s), math.sqrt(max(float(state.P[m.ib, m.ib]), 0.0)) * s

    # -- the recursion ---------------------------------------------------------------------------
    def run(self, state: FilterState, current_a, steps=None, record: ForwardRecord | None = None,
            offset: int = 0):
        """
        Filter ``current_a`` (A) from ``state``; return (new state, w, std, still).

        ``steps[k]``: sample periods from the sample before (None: all 1).  ``record``: filled
        at rows ``offset + k`` for the smoother.
        """
        y = np.asarray(current_a, dtype=float)
        n = y.size
        st = np.ones(n, dtype=np.int64) if steps is None else np.asarray(steps, dtype=np.int64)
        out_w, out_s = np.empty(n), np.empty(n)
        out_still = np.empty(n, dtype=bool)
        state = state.copy()
        for k in range(n):
            state = self._step(state, float(y[k]), int(st[k]), record, offset + k)
            out_w[k], out_s[k] = self.deflection(state)
            out_still[k] = state.still
        return state, out_w, out_s, out_still

    def _step(self, st: FilterState, y: float, steps: int, record, row: int) -> FilterState:
        m = self.model
        F, Q = m.discrete(steps)
        if st.samples:
            x = F @ st.x
        else:
            x = st.x
        still, window_state = self._rest_test(st, x, y, steps)
        if st.samples:
            P = F @ st.P @ F.T + Q
        else:
            P = st.P
        if still:
            P[m.ih, m.ih] += m.hold_variance
        if record is not None:
            record.x_pred[row], record.P_pred[row] = x, P
            record.steps[row], record.still[row] = steps, still
        c = m.c
        Pc = P @ c
        cpc = float(c @ Pc)
        nu = y - float(c @ x)
        S = cpc + st.noise_var_a2
        K = Pc / S
        x = x + K * nu
        P = P - np.outer(K, Pc)
        noise, noise_weight = self._noise(st, window_state[0], window_state[2], steps)
        if still:
            for row_c, var in self._rest_rows:
                Pc = P @ row_c
                K = Pc / (float(row_c @ Pc) + var)
                x = x - K * float(row_c @ x)
                P = P - np.outer(K, Pc)
        P = 0.5 * (P + P.T)
        if record is not None:
            record.x_post[row], record.P_post[row] = x, P
        return FilterState(x, P, noise, *window_state[:3], still, st.samples + 1,
                           min(st.contiguous + 1, 4) if steps == 1 else 1, noise_weight,
                           *window_state[3:])

    def _noise(self, st: FilterState, window: np.ndarray, pos: int, steps: int) -> float:
        """Update the measured noise variance with the newest third difference (docstring)."""
        if steps != 1 or st.contiguous < 3:
            return st.noise_var_a2, st.noise_weight
        n = window.size
        r0, r1, r2, r3 = (window[(pos - j) % n] for j in (1, 2, 3, 4))
        d = r0 - 3.0 * r1 + 3.0 * r2 - r3
        sample = d * d / 20.0
        if st.noise_weight:
            sample = min(sample, NOISE_CLIP * st.noise_var_a2)
        weight = (1.0 - self._alpha) * st.noise_weight
        value = (weight * st.noise_var_a2 + sample) / (weight + 1.0)
        return max(value, NOISE_FLOOR_A ** 2), weight + 1.0

    def _rest_test(self, st: FilterState, x: np.ndarray, y: float, steps: int):
        """
        Add r = y - lines(x-) to the window; return (still, window state).

        The window state is (window, count, pos, line sums, phase, phases): a sliding DFT of
        the window at each line frequency, so the test can remove the lines' least-squares fit.
        """
        m = self.model
        s = m.scale
        n = self.rest.n
        window, pos = st.window, st.window_pos
        phase = st.phase * self._rot ** steps if st.samples else st.phase
        r = y - float(x[m.il::2] @ s[m.il::2]) if m.lines_hz else y
        if self._rot.size:
            sums = st.line_sums + r * phase - window[pos] * st.phases[pos]
            st.phases[pos] = phase
        else:
            sums = st.line_sums
        window[pos] = r
        count = min(st.window_count + 1, n)
        state = (window, count, (pos + 1) % n, sums, phase, st.phases)
        if count < n:
            return False, state
        total = float(window.sum())
        energy = 2.0 / n * float(np.sum(np.abs(sums) ** 2)) if self._rot.size else 0.0
        b, pb = x[m.ib] * s[m.ib], st.P[m.ib, m.ib] * s[m.ib] ** 2
        return self.rest.still(total, float(window @ window), energy, b, pb,
                               st.noise_var_a2), state
