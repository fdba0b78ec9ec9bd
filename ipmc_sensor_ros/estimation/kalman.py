# SPDX-License-Identifier: Apache-2.0
"""
The Kalman deflection estimator.

It joins the model (:mod:`.statespace`), filter (:mod:`.filter`), smoother
(:mod:`.smoother`) and the mains line measured from the data (:mod:`.lines`).

:class:`KalmanEstimator` implements :class:`~.core.EstimatorCore`.  It owns one
:class:`~.filter.FilterState` and advances it sample by sample; a block and single samples
run the same recursion.  The mains line (``mains_hz``: ``'auto'``, 50, 60 or 0 = none) is
measured every ``LINE_CHECK_S`` of data on the last ``LINE_CHECK_S`` of current, at fixed
sample counts (so the result does not depend on how the stream is cut into blocks); when it
appears, or moves by more than ``LINE_RETUNE_HZ``, the model is rebuilt with line states at
the measured frequency and the filter state carried over.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..errors import ParameterError
from ..lti.reduction import ReducedModel
from .config import EstimatorConfig
from .core import Estimate
from .filter import FilterState, KalmanFilter
from .lines import NOMINAL_LINES_HZ, measure_line
from .smoother import smooth
from .statespace import StateSpaceModel

__all__ = ['KalmanEstimator', 'MAINS_CHOICES', 'parse_mains', 'LINE_CHECK_S']

#: Data between two measurements of the mains line, s (also the stretch measured): 2 s
#: resolves 0.5 Hz and, zero-padded, finds the line to ~0.01 Hz at 3 % hum.  The first
#: measurement is made after ``LINE_FIRST_S`` (0.5 s: to ~0.05 Hz), so hum is modelled early.
LINE_CHECK_S = 2.0
LINE_FIRST_S = 0.5
#: A measured line this far from the modelled one retunes the model, Hz: the line states'
#: random walk follows a smaller error (the phasor turns by 2 pi 0.02 rad/s).
LINE_RETUNE_HZ = 0.02

#: Values of ``mains_hz``.
MAINS_CHOICES = ('auto', 0, 50, 60)


def parse_mains(value) -> str | float:
    """Return ``'auto'`` or the line frequency 0, 50.0, 60.0 (``mains_hz``)."""
    if isinstance(value, str) and value.strip().lower() == 'auto':
        return 'auto'
    try:
        f = float(value)
    except (TypeError, ValueError):
        f = math.nan
    if f not in (0.0, 50.0, 60.0):
        raise ParameterError(f"parameter 'mains_hz' must be 'auto', 0, 50 or 60, got {value!r}")
    return f


class KalmanEstimator:
    """
    Streaming Kalman estimate of tip deflection (m) from sensing current (A).

    Parameters
    ----------
    reduced : ReducedModel
        The sensor's reduced model.
    sample_rate_hz : float
        Sample rate of the current, Hz.
    config : EstimatorConfig, optional
        Priors and rest test (defaults documented there).
    mains_hz : 'auto', 0, 50 or 60
        Mains line handling (module docstring).

    """

    name = 'kalman'

    def __init__(self, reduced: ReducedModel, sample_rate_hz: float,
                 config: EstimatorConfig | None = None, mains_hz='auto'):
        self.reduced = reduced
        self.config = config or EstimatorConfig()
        self.mains_hz = parse_mains(mains_hz)
        fs = float(sample_rate_hz)
        # until measured: a line at each nominal frequency (hum at the start must not be
        # taken for an offset), then the measured one
        nominal_line = () if self.mains_hz == 0.0 else self._nominal()
        self._check_n = max(64, int(round(LINE_CHECK_S * fs)))
        self._first_n = max(64, int(round(LINE_FIRST_S * fs)))
        self._filter = self._new_filter(StateSpaceModel(reduced, self.config, fs, nominal_line))
        self.reset()

    def _new_filter(self, model: StateSpaceModel) -> KalmanFilter:
        """Build the filter; its rest test fits the nominal lines until one is modelled."""
        from .statespace import line_frequencies_hz

        nominal = () if self.mains_hz == 0.0 else self._nominal()
        rest_lines = tuple(f for f0 in nominal for f in line_frequencies_hz(
            f0, model.sample_rate_hz, self.config.line_harmonics))
        return KalmanFilter(model, rest_lines)

    def _nominal(self) -> tuple:
        return NOMINAL_LINES_HZ if self.mains_hz == 'auto' else (self.mains_hz,)

    def _next_check(self, samples: int) -> int:
        """Return the sample count of the next line measurement after ``samples``."""
        if samples < self._first_n:
            return self._first_n
        return self._first_n + ((samples - self._first_n) // self._check_n + 1) * self._check_n

    # -- properties ---------------------------------------------------------------------
    @property
    def sample_rate_hz(self) -> float:
        return self._filter.model.sample_rate_hz

    @property
    def model(self) -> StateSpaceModel:
        return self._filter.model

    @property
    def line_hz(self) -> float:
        """Mains fundamental in the model now, Hz (0: none)."""
        return self._filter.model.line_hz

    def reset(self) -> None:
        """Start afresh: the nominal lines (the measured ones are measured again) and the prior."""
        nominal = () if self.mains_hz == 0.0 else self._nominal()
        if self.model.fundamentals_hz != tuple(nominal):
            self._filter = self._new_filter(StateSpaceModel(self.reduced, self.config,
                                                            self.sample_rate_hz, nominal))
        self._state = self._filter.initial_state()
        self._recent = np.zeros(self._check_n)
        self._grid = 0           # sample periods since the start (bridged ones included)
        self._first_rest_n = None

    # -- streaming ------------------------------------------------------------------------
    def estimate(self, current_a, steps=None) -> Estimate:
        y = np.asarray(current_a, dtype=float)
        st = np.ones(y.size, dtype=np.int64) if steps is None else np.asarray(steps, np.int64)
        parts = []
        a = 0
        while a < y.size:
            # cut where the line check falls due (a fixed sample count, however cut)
            due = self._next_check(self._state.samples)
            b = min(y.size, a + due - self._state.samples)
            self._state, w, s, still = self._filter.run(self._state, y[a:b], st[a:b],
                                                        copy=False)
            self._remember(y[a:b], st[a:b], still)
            parts.append((w, s, still))
            a = b
            if self._state.samples == due:
                self._check_line()
        if not parts:
            return Estimate(np.zeros(0), np.zeros(0), np.zeros(0, dtype=bool))
        return Estimate(*(np.concatenate(p) for p in zip(*parts)))

    def estimate_one(self, current_a: float, steps: int = 1) -> tuple[float, float]:
        """One sample through the same recursion (:meth:`estimate` without its arrays)."""
        n = self._state.samples
        if n + 1 == self._next_check(n):
            est = self.estimate(np.array([current_a], dtype=float),
                                None if steps == 1 else np.array([steps]))
            return float(est.deflection_m[0]), float(est.std_m[0])
        self._state, w, s, still = self._filter.run(self._state, [float(current_a)],
                                                    [int(steps)], copy=False)
        for _ in range(int(steps)):     # a bridged slot holds the next value (line check)
            self._recent[self._grid % self._check_n] = current_a
            self._grid += 1
        if self._first_rest_n is None and still[0]:
            self._first_rest_n = n
        return float(w[0]), float(s[0])

    def _remember(self, y: np.ndarray, steps: np.ndarray, still: np.ndarray) -> None:
        """
        Keep the last check window of current on the sample grid; note the first rest.

        A bridged slot holds the value of the sample after it, so the line check sees the
        hum's phase where it was (a dropped burst does not shift the rest of the window).
        """
        n = self._check_n
        end = self._state.samples
        if self._first_rest_n is None and still.any():
            self._first_rest_n = end - y.size + int(np.argmax(still))
        dense = np.repeat(y, steps)[-n:]
        idx = np.arange(self._grid + int(steps.sum()) - dense.size,
                        self._grid + int(steps.sum())) % n
        self._recent[idx] = dense
        self._grid += int(steps.sum())

    def _check_line(self) -> None:
        if self.mains_hz == 0.0:
            return
        seen = min(self._grid, self._check_n)
        recent = np.roll(self._recent, -(self._grid % self._check_n))[-seen:]
        f_line, _ = measure_line(recent, self.sample_rate_hz, self._nominal(),
                                 self.config.line_harmonics)
        old = self.model.fundamentals_hz
        if f_line and len(old) == 1 and abs(f_line - old[0]) <= LINE_RETUNE_HZ:
            return
        if not f_line and (len(old) < 2 or self._state.samples > self._first_n):
            return        # no line: keep what is modelled (the nominal pair only at the start)
        f_line = f_line or ()
        model = StateSpaceModel(self.reduced, self.config, self.sample_rate_hz, f_line)
        filt = self._new_filter(model)
        self._state = carry_state(self._filter, filt, self._state)
        self._filter = filt

    # -- offline --------------------------------------------------------------------------
    def smooth(self, current_a, steps=None) -> Estimate:
        """
        Smoothed estimate of a whole record from a fresh start (fixed-interval RTS).

        The mains line is measured on the whole record first (offline, it can be).  Leaves
        this estimator's stream state untouched.
        """
        y = np.asarray(current_a, dtype=float)
        line = self.model.line_hz
        if self.mains_hz != 0.0:
            line = measure_line(y, self.sample_rate_hz, self._nominal(),
                                self.config.line_harmonics)[0]
        filt = self._new_filter(StateSpaceModel(self.reduced, self.config, self.sample_rate_hz,
                                                line))
        w, s, _ = smooth(filt, filt.initial_state(), y, steps)
        return Estimate(w, s, np.zeros(y.size, dtype=bool))

    # -- state ------------------------------------------------------------------------------
    def get_state(self) -> dict:
        return {'filter': self._state.copy(), 'line_hz': self.model.fundamentals_hz,
                'recent': self._recent.copy(), 'grid': self._grid,
                'first_rest_n': self._first_rest_n}

    def set_state(self, state: dict) -> None:
        try:
            fs: FilterState = state['filter']
            line = tuple(float(f) for f in state['line_hz'])
            recent = np.asarray(state['recent'], dtype=float)
        except (KeyError, TypeError, ValueError):
            raise ParameterError('not a state of this Kalman estimator') from None
        if line != self.model.fundamentals_hz:
            self._filter = self._new_filter(StateSpaceModel(self.reduced, self.config,
                                                            self.sample_rate_hz, line))
        if fs.x.shape != (self.model.size,) or recent.shape != self._recent.shape:
            raise ParameterError('state was saved from a different estimator design')
        self._state = fs.copy()
        self._recent = recent.copy()
        self._grid = int(state.get('grid', fs.samples))
        self._first_rest_n = state.get('first_rest_n')

    def rebuilt(self, reduced: ReducedModel | None = None, recent_input=None,
                **changes) -> 'KalmanEstimator':
        """
        Return an estimator for a new design (reduced model, sample rate, settings).

        Its state continues from this one's: deflection, velocity, working point, offset and
        lines carried over; the sensor's charge states restarted from the velocity.
        """
        fs = float(changes.pop('sample_rate_hz', self.sample_rate_hz))
        config = changes.pop('config', self.config)
        mains = changes.pop('mains_hz', self.mains_hz)
        if changes:
            raise ParameterError(f'cannot rebuild the Kalman estimator with {sorted(changes)}')
        new = KalmanEstimator(reduced or self.reduced, fs, config, mains)
        if new.mains_hz == self.mains_hz:
            new._filter = new._new_filter(StateSpaceModel(new.reduced, config, fs,
                                                          self.model.fundamentals_hz))
        new._state = carry_state(self._filter, new._filter, self._state)
        new._first_rest_n = self._first_rest_n
        if new._check_n == self._check_n:
            new._recent, new._grid = self._recent.copy(), self._grid
        return new

    def continue_from(self, old: 'KalmanEstimator', recent_input=None) -> None:
        """Take over ``old``'s stream state (deflection, offset, lines, ...)."""
        self._state = carry_state(old._filter, self._filter, old._state)
        self._first_rest_n = old._first_rest_n
        if old._check_n == self._check_n:
            self._recent, self._grid = old._recent.copy(), old._grid

    # -- reporting -----------------------------------------------------------------------
    def status(self) -> dict:
        m = self.model
        w, w_std = self._filter.deflection(self._state)
        b, b_std = self._filter.offset(self._state)
        level = 0.0
        if m.lines_hz:
            s = m.scale
            level = float(math.hypot(self._state.x[m.il] * s[m.il],
                                     self._state.x[m.il + 1] * s[m.il + 1]))
        return {'estimator': self.name, 'offset_a': b, 'offset_std_a': b_std,
                'at_rest': bool(self._state.still), 'deflection_std_m': w_std,
                'noise_a': math.sqrt(self._state.noise_var_a2),
                'mains_line_hz': self.line_hz, 'mains_line_a': level}

    def settling(self) -> tuple[float, str]:
        if self._first_rest_n is not None:
            return self._first_rest_n / self.sample_rate_hz, 'level learned at the first rest'
        return (5.0 / (2 * math.pi * self.config.motion_corner_hz),
                'no rest yet: five time constants of motion_corner_hz')


def carry_state(old: KalmanFilter, new: KalmanFilter, state: FilterState) -> FilterState:
    """
    Map a filter state onto another model of the same sensor family.

    States with a physical meaning in both (deflection, velocity, acceleration, working
    point, offset, drift, each line state whose frequency is within 1 Hz of one of the old
    model, and the charge states when the sensor is the same) are carried with their
    covariance; a different sensor's charge states are set to their steady value for the
    current velocity (x_R = -u / p_i) with their prior covariance; new line states start from
    their prior.
    """
    mo, mn = old.model, new.model
    x_old = state.x * mo.scale
    init = new.initial_state()
    x, P = init.x * mn.scale, init.P * np.outer(mn.scale, mn.scale)
    P_old = state.P * np.outer(mo.scale, mo.scale)
    src = list(range(mo.iw, mo.il))
    dst = list(range(mn.iw, mn.il))
    for k, f in enumerate(mn.lines_hz):
        near = [j for j, g in enumerate(mo.lines_hz) if abs(g - f) < 1.0]
        if near:
            src += [mo.il + 2 * near[0], mo.il + 2 * near[0] + 1]
            dst += [mn.il + 2 * k, mn.il + 2 * k + 1]
    same_sensor = np.array_equal(np.diag(mo.sensor[0]), np.diag(mn.sensor[0]))
    if same_sensor:                   # only the lines changed: the charge states carry too
        src = list(range(mo.n_sensor)) + src
        dst = list(range(mn.n_sensor)) + dst
    x[dst] = x_old[src]
    P[np.ix_(dst, dst)] = P_old[np.ix_(src, src)]
    if not same_sensor:
        x[:mn.n_sensor] = -x[mn.iu] / np.diag(mn.sensor[0])
        P[:mn.n_sensor, dst] = 0.0
        P[dst, :mn.n_sensor] = 0.0
    out = replace(init, x=x / mn.scale, P=P / np.outer(mn.scale, mn.scale),
                  noise_var_a2=state.noise_var_a2, samples=state.samples,
                  contiguous=state.contiguous, noise_weight=state.noise_weight,
                  still=state.still, moved=state.moved, quiet=state.quiet, cusum=state.cusum)
    if state.window.size != new.rest.n:
        return replace(out, still=False, moved=True)    # the rest test's window restarts
    # the window carries over; its sliding DFT is recomputed for the new model's rest lines
    # (the window's samples taken as consecutive, the newest with phase 1)
    n = state.window.size
    age = (state.window_pos - 1 - np.arange(n)) % n       # slot of the sample j periods ago
    phases = np.ones((n, len(new.rest_lines_hz)), complex)
    phases[age] = new.rotation[None, :] ** -np.arange(n)[:, None]
    sums = state.window @ phases
    return replace(out, window=state.window.copy(), window_count=state.window_count,
                   window_pos=state.window_pos, total=state.total, total_sq=state.total_sq,
                   line_sums=sums, phase=np.ones(len(new.rest_lines_hz), complex),
                   phases=phases)
