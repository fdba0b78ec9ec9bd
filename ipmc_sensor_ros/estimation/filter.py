# SPDX-License-Identifier: Apache-2.0
"""
The Kalman filter on :class:`~.statespace.StateSpaceModel`: explicit state in, state out.

One recursion per sample, the same for a block and a single sample (a block is a loop over
its samples; there is no second implementation)::

    predict   x- = F_m x,  P- = F_m P F_m' + Q_m       (m = sample periods since the last
                                                         sample: missing samples bridged)
    rest test on the window of the current, less its     (:mod:`.rest`)
              own fit of a constant and the lines
    update    nu = i - c x-,  S = c P- c' + R,  K = P- c' / S,  x = x- + K nu,
              P = P- - K S K'
    a rest    the window's mean current less its fit of the lines = offset at the window's
    begins    centre, within R/N (:meth:`KalmanFilter._window_offset`)
    at rest   velocity = 0, acceleration = 0, motion current = 0, periodic motion = 0
              (pseudo-measurements, :mod:`.rest`); working point = w (its prior released
              first when the tip moved since the working point was last set:
              :attr:`~.statespace.StateSpaceModel.hold_variance`; a record that starts at
              rest keeps the starting working point, its rest position); leaving a rest,
              the periodic motion's prior is released (a new motion's amplitude is unknown)
    a jump    a step out of a still stretch, then a window still at a new offset (:mod:`.rest`):
              the run is filtered again from its start as still, the offset's variance
              grown by ``offset_jump_a`` squared (:func:`.onset.restart`)

R, the white-noise variance per sample, is measured by :class:`~.noise.NoiseMeter`.
A sample whose stamp is d periods off its slot (:mod:`.timebase`) was taken there (a DAQ the
host times) or on the slot (a DAQ on its own clock, stamped late): with p the probability of
the first (:mod:`.instants`), its row is the mixture's mean (1 - p) c + p c e^{A
d/fs}, R grows by the mixture's spread, and the published deflection is the tip's there.
The state is held in scaled units (x / scale) so that every entry of P is O(1) whatever the
sensor (deflections of mm, currents of nA).

:class:`FilterState` is the whole state (what save/restore keeps); :meth:`KalmanFilter.run`
returns the new one and never changes the old.  Pass ``record`` to keep what the smoother
needs (:mod:`.smoother`, :mod:`.fixed_lag`).  :func:`.carry.carry_state` maps a state onto
another model of the same sensor (a line measured, a new design).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from .forward import ForwardRecord, astuple_shallow
from .innovations import Innovations, Tally, block_samples, cusum_limit
from .instants import ON_SLOT, OffSlot, StampTally
from .noise import NOISE_FLOOR_A, NoiseMeter
from .onset import Onset, Start, follow_jump, track_onset
from .rest import RestTest, RestWindow, rest_change
from .rest_jump import JumpLag, jump_covariance
from .rounding import RoundingBias, RoundingTally
from .statespace import StateSpaceModel
from .timebase import slots_of

__all__ = ['FilterState', 'KalmanFilter', 'ForwardRecord', 'astuple_shallow', 'NoiseMeter',
           'NOISE_FLOOR_A']


@dataclass(slots=True)
class FilterState:
    """Everything the filter carries from one sample to the next (scaled units)."""

    x: np.ndarray
    P: np.ndarray
    noise: NoiseMeter
    window: RestWindow = field(repr=False)
    still: bool = False
    #: the tip moved since the working point was last set (a new hold releases it)
    moved: bool = False
    samples: int = 0
    #: at rest: where a motion that ends it would have begun (:mod:`.onset`)
    onset: Onset | None = None
    #: the rest ended at the last sample, or the offset jumped: where to filter again from
    #: (:class:`.onset.Start`)
    ended: Start | None = None
    #: samples still to be taken as motion (as still if ``hold_still``) whatever the rest test
    #: says (:func:`.onset.restart`)
    hold_off: int = 0
    hold_still: bool = False
    #: a run of samples the jump test finds still at one offset (:mod:`.rest`): a
    #: :class:`.onset.Start` from before its first sample
    jump: Start | None = None
    #: the normalised innovations' sums a check tests the model by (:mod:`.innovations`)
    innovations: Innovations = Innovations()
    #: the estimate's sensitivity to the rounding a rest keeps (:mod:`.rounding`)
    rounding: RoundingBias | None = None

    def copy(self) -> 'FilterState':
        return replace(self, x=self.x.copy(), P=self.P.copy(), noise=replace(self.noise),
                       window=self.window.copy(),
                       rounding=None if self.rounding is None else self.rounding.copy(),
                       onset=None if self.onset is None else self.onset.copy(),
                       jump=None if self.jump is None else self.jump.copy())


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
        self.rest = RestTest.design(cfg.rest_window_s, model.sample_rate_hz, cfg.false_alarm,
                                    lines, cfg.offset_jump_a, cfg.jump_hold_s)
        # one step of each line's phasor e^{-i W_k / fs} (sliding DFT of the rest window)
        self._rot = np.exp(-2j * np.pi * np.asarray(lines) / model.sample_rate_hz)
        self._c_lines = np.zeros(model.size)        # the mains lines' current
        self._c_lines[model.il:model.im] = model.c[model.il:model.im]
        self._alpha = 1.0 / (cfg.noise_average_s * model.sample_rate_hz)
        #: the first sample the test counts (R measured: noise_average_s); the CUSUM's limit
        self._settled, self._limit = math.ceil(1.0 / self._alpha), cusum_limit(cfg.false_alarm)
        self._block = block_samples(model.motion_fundamentals_hz, model.sample_rate_hz)
        s = model.scale
        self._sb = float(s[model.ib])              # the offset's scale, A
        self._w_row = np.zeros(model.size)          # the published deflection, m
        self._w_row[model.iw] = s[model.iw]
        self.off_slot = OffSlot(model, self._w_row)     # a sample off its slot (.instants)
        self._anchor = np.zeros(model.size)
        self._anchor[model.iw], self._anchor[model.ih] = s[model.iw], -s[model.ih]
        v2, m2 = model.rest_variances
        anchor_var = (cfg.rest_velocity_m_s / model.sample_rate_hz) ** 2
        accel = np.zeros(model.size)
        accel[model.ia] = model.scale[model.ia]
        rows = [(model.c_velocity, v2), (accel, v2 * model.sample_rate_hz ** 2),
                (model.c_motion, m2), (self._anchor, anchor_var)]
        for j, f in zip(range(model.im, model.ir), np.repeat(model.motion_lines_hz, 2)):
            for i, var in ((j, v2 / (2 * np.pi * f) ** 2), (j + model.ir - model.im, v2)):
                row = np.zeros(model.size)      # at rest a periodic amplitude is the velocity's
                row[i] = s[i]                   # noise / W, its rate the velocity's noise
                rows.append((row, var))
        self._rest_rows = tuple(rows)
        # the lines' third difference i_{k+4} - 3 i_{k+3} + 3 i_{k+2} - i_{k+1} from the state
        # at sample k (module docstring): a phasor turned on by tau is (cos W tau) l_I -
        # (sin W tau) l_Q (A = [[0, -W], [W, 0]], statespace._phasors)
        ahead = np.arange(4, 0, -1) / model.sample_rate_hz
        weights = np.array([1.0, -3.0, 3.0, -1.0])
        self.line_difference = np.zeros(model.size) if model.lines_hz else None
        for k, f in enumerate(model.lines_hz):
            j = model.il + 2 * k
            self.line_difference[j] = weights @ np.cos(2 * np.pi * f * ahead) * s[j]
            self.line_difference[j + 1] = -weights @ np.sin(2 * np.pi * f * ahead) * s[j + 1]

    @property
    def rotation(self) -> np.ndarray:
        """One sample's turn e^{-i W_k / fs} of each rest-test line."""
        return self._rot

    def _window_offset(self, x, P, window: RestWindow, noise,
                       bias: RoundingTally | None = None):
        """
        Update (x, P) with the window's fitted constant as a measurement of the offset.

        Applied when a rest begins: the rest test has just found the window's N samples to be
        offset + lines + white noise, so the constant of its least-squares fit (:mod:`.rest`)
        is the offset at the window's centre, b - d (N - 1) / (2 fs), within R / N (the
        fit's lines add 1e-4 of it for three lines of 50.22 Hz in 0.2 s).  The filter has
        used these samples already, under its motion model, which takes little of b from
        them (a steady current is also a slow motion: a still start leaves P_b at its prior);
        the information on b it took, 1/P_b now less 1/P_b before the window's first sample
        (kept in the window's slot), is taken off the measurement's: no sample counts twice.
        """
        m, n = self.model, window.samples.size
        sb = self._sb
        first_var = window.offset_var[window.pos]
        info = n / noise - (1.0 / (float(P[m.ib, m.ib]) * sb * sb) - 1.0 / first_var)
        if info <= 0.0:
            return x, P
        row = np.zeros(m.size)
        row[m.ib] = sb
        row[m.ib + 1] = -float(m.scale[m.ib + 1]) * (n - 1) / (2.0 * m.sample_rate_hz)
        mean = float(window.residuals(0).mean())
        x, P, _, r, g = scalar_update(x, P, row, mean, 1.0 / info)
        if bias is not None:                    # the mean of a still reading: its rounding
            bias.update(g / r, row, 1.0)
        return x, P

    def initial_state(self) -> FilterState:
        x, P = self.model.prior()
        pb = P[self.model.ib, self.model.ib] * self._sb ** 2
        return FilterState(x, P, NoiseMeter(self.model.config.current_noise_a ** 2),
                           RestWindow.empty(self.rest.n, len(self.rest_lines_hz), pb))

    def deflection(self, state: FilterState) -> tuple[float, float]:
        """(w, its standard deviation) of a state, m."""
        w, bias = self._w_row, RoundingTally(state.rounding, self.model.size)
        return float(w @ state.x), math.sqrt(max(float(w @ state.P @ w), 0.0)
                                             + bias.variance(w, state.noise))

    def to_block_end(self, state: FilterState) -> int:
        """
        Return the samples after which the filter closes its next innovation block.

        A block is one period of the periodic motion (:mod:`.innovations`), counted from
        the first sample after ``noise_average_s``; without a periodic model, 0 (none).
        """
        if self._block == 1:
            return 0
        before = max(0, self._settled - state.samples)
        return before + self._block - state.innovations.open_n

    def offset(self, state: FilterState) -> tuple[float, float]:
        """Return (current offset, its standard deviation) of a state, A."""
        ib, s = self.model.ib, self._sb
        return float(state.x[ib]) * s, math.sqrt(max(float(state.P[ib, ib]), 0.0)) * s

    # -- the recursion ---------------------------------------------------------------------------
    def run(self, state: FilterState, current_a, steps=None, record: ForwardRecord | None = None,
            offset: int = 0, copy: bool = True, until_motion: bool = False):
        """
        Filter ``current_a`` (A) from ``state``; return (new state, w, std, still).

        ``steps[k]``: sample periods from the slot of the sample before (None: all 1); a
        fraction is the stamp's offset from its slot (:mod:`.instants`).  ``record``: filled
        at rows ``offset + k`` for the smoother.  The loop keeps the state's arrays in local
        variables and builds the returned :class:`FilterState` once; a block and single
        samples run the same statements.  ``copy=False``: the new state reuses ``state``'s
        buffers (for an owner that drops the old state; ``state`` is then no longer valid).
        ``until_motion``: stop after a sample that ends a rest (the outputs are then shorter;
        the state's ``ended`` says where the motion began: :mod:`.onset`).
        """
        y, st = _as_lists(current_a, steps)
        n, m = len(y), self.model
        x, P, meter, win, onset, jump = _unpacked(state, copy)
        bias = RoundingTally(state.rounding, m.size)
        still, moved, samples = state.still, state.moved, state.samples
        hold, hold_still = state.hold_off, state.hold_still
        sums = Tally(state.innovations, self._block, self._limit)
        stamps = StampTally(state.innovations.stamps, self.off_slot,
                            m.config.sampled_at_stamp_prior)

        def snapshot():             # the sums as they stand (a snapshot's, or the result's)
            return sums.value(stamps.value())
        out_w, out_s, out_still = np.empty(n), np.empty(n), np.empty(n, dtype=bool)
        F, Q = m.discrete(1)
        last_steps, ended, alarm = 1, None, False
        for k in range(n):
            yk, tk = y[k], st[k]
            sk = slots_of(tk)           # the slots, and the stamp's offset from its slot
            dk = tk - sk
            if -ON_SLOT < dk < ON_SLOT:     # within the table's half row: on the slot
                dk = 0.0
            if sk != last_steps:
                F, Q = m.discrete(sk)
                last_steps = sk
            x0, P0, accepted = x, P, None
            if samples:
                x = F @ x
                bias.predict(F, meter)
            held = hold > 0             # a motion's start again (.onset.restart): motion, the
            if held:                    # window and meter left as the test left them, past it
                verdict, hold = hold_still, hold - 1
            else:
                verdict, jump, accepted = self._judge(
                    win, meter.var_a2, yk, tk, sk, x, P, still, jump, samples,
                    lambda: (x0, P0, moved, samples, snapshot()))
            was = still
            still, release, begins, moved = rest_change(verdict, still, moved)
            if samples:
                P = F @ P @ F.T
                P = 0.5 * (P + P.T) + Q     # symmetric to the bit (the updates keep it so)
            if release:
                P = self._released(P, still)
            row, wk, var, g = ((m.c, self._w_row, meter.var_a2, 0.0) if not dk
                               else stamps.row(dk, x, meter.var_a2))   # at the stamp or slot?
            if record is not None:
                j = offset + k
                record.x_pred[j], record.P_pred[j] = x, P
                record.steps[j], record.still[j], record.w_row[j] = sk, still, wk
            x, P, z, r, gain = scalar_update(x, P, row, yk, var)
            bias.update(gain / r, row, 1.0 if still else 0.0, meter)
            alarm = sums.add(z, r, samples >= self._settled)    # R measured: the test counts
            stamps.add(dk, z, r, g)
            x, P = self._rest_updates(x, P, yk, sk, win, meter, held, begins, still, bias)
            if record is not None:      # j: this sample's row, set before the update
                record.x_post[j], record.P_post[j] = x, P
                record.c_row[j], record.z[j], record.s[j] = row, z, r
            samples += 1
            out_w[k] = float(wk @ x)    # the tip where the sample was taken (on its slot:
            out_s[k] = math.sqrt(max(float(wk @ P @ wk), 0.0)      # wk = e_w s_w, w itself)
                                 + bias.variance(wk, meter))
            out_still[k] = still
            onset, ended = track_onset(accepted, still, was, onset, ended, win, yk, tk,
                                       lambda: (x, P, moved, samples, snapshot()))
            if until_motion and (ended is not None or alarm):
                n = k + 1
                break
        return (FilterState(x, P, meter, win, still, moved, samples, onset, ended, hold,
                            hold_still, jump, snapshot(), bias.value()),
                out_w[:n], out_s[:n], out_still[:n])

    def _judge(self, win: RestWindow, noise_a2: float, y: float, t: float, steps: int, x, P,
               still: bool, jump, samples: int, snapshot):
        """
        Push a sample into the rest window; return (verdict, jump's run, jump accepted).

        ``x``: the state predicted to the sample, ``P`` the covariance before it; the jump
        test follows a run still at one offset (:func:`.onset.follow_jump`) and accepts it
        when the window says the offset jumped (:meth:`.rest.RestWindow.jumped`).
        """
        rot, ib, sb, cl = self._rot, self.model.ib, self._sb, self._c_lines
        win.push(y, None if not (samples and rot.size) else rot if steps == 1 else rot ** steps,
                 steps)
        verdict = win.judge(self.rest, y, float(x[ib]) * sb, float(P[ib, ib]) * sb * sb,
                            noise_a2, still, lambda: (float(cl @ x), float(cl @ P @ cl)))
        jump = follow_jump(jump, win.jump_quiet, verdict, y, t, snapshot, still)
        if jump is not None and verdict is False and win.jumped(self.rest, noise_a2):
            return verdict, None, jump
        return verdict, jump, None

    def _rest_updates(self, x, P, y: float, steps: int, win: RestWindow, meter: NoiseMeter,
                      held: bool, begins: bool, still: bool, bias: RoundingTally):
        """
        Return (x, P) after a sample's rest measurements.

        The noise meter takes the sample (not while a motion's start is held); a rest that
        begins measures the offset (:meth:`_window_offset`); at rest, the pseudo-measurements
        (velocity, acceleration, motion current, periodic motion = 0; the working point).
        """
        if not held:
            d3 = self.line_difference
            meter.add(y, steps, win, self._alpha, None if d3 is None else float(d3 @ x))
            if begins:              # a new level, its own rounding (.rounding)
                bias.fold(self._w_row, meter)
                x, P = self._window_offset(x, P, win, meter.var_a2, bias)
        if still:
            for row, var in self._rest_rows:
                x, P, _, r, gain = scalar_update(x, P, row, 0.0, var)
                bias.update(gain / r, row, 0.0)
        return x, P

    def with_jump(self, P: np.ndarray, lag: JumpLag | None = None) -> np.ndarray:
        """Return a copy of ``P`` with a jump's covariance (:func:`.rest_jump.jump_covariance`)."""
        m, at = self.model, np.array([self.model.ib, self.model.iw])
        P = P.copy()
        P[np.ix_(at, at)] += (jump_covariance(self.rest.jump_var_a2, lag, m.charge_gain)
                              / np.outer(m.scale[at], m.scale[at]))
        return P

    def _released(self, P: np.ndarray, still: bool) -> np.ndarray:
        """
        Release the working point's prior as the rest changes (and the periodic motion's).

        Leaving a rest, the periodic motion's prior is released too: a new motion's amplitude
        is unknown.
        """
        m = self.model
        P[m.ih, m.ih] += m.hold_variance
        if m.size > m.im and not still:
            P[m.im:, m.im:] += np.eye(m.size - m.im)
        return P


def _as_lists(current_a, steps) -> tuple[list, list]:
    """Return the samples and their steps as lists of floats (the loop's fastest form)."""
    y = current_a if isinstance(current_a, list) else np.asarray(current_a, float).tolist()
    return y, ([1] * len(y) if steps is None else steps if isinstance(steps, list)
               else np.asarray(steps, dtype=float).tolist())


def _unpacked(state: FilterState, copy: bool) -> tuple:
    """Return the state's (x, P, meter, window, onset, jump), copies if ``copy``."""
    x, P, meter, win, onset, jump = (state.x, state.P, state.noise, state.window, state.onset,
                                     state.jump)
    if not copy:
        return x, P, meter, win, onset, jump
    return (x.copy(), P.copy(), replace(meter), win.copy(),
            None if onset is None else onset.copy(), None if jump is None else jump.copy())


def scalar_update(x: np.ndarray, P: np.ndarray, row: np.ndarray, value: float, var: float):
    """
    Update (x, P) with the scalar measurement ``row @ x = value`` of variance ``var``.

    Returns (x, P, z, sqrt(S), g).

    P - g g' with g = P row / sqrt(S): symmetric exactly (the gain is g / sqrt(S)); z = nu /
    sqrt(S), the normalised innovation, S its variance.
    """
    Pc = P @ row
    S = float(row @ Pc) + var
    nu = value - float(row @ x)
    x = x + Pc * (nu / S)
    r = math.sqrt(S)
    g = Pc / r
    return x, P - g[:, None] * g, nu / r, r, g
