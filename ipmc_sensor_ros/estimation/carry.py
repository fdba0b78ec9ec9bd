# SPDX-License-Identifier: Apache-2.0
"""
A filter state carried onto another model of the same sensor (:func:`carry_state`).

Used when the model changes under a running filter: a mains line measured, a periodic motion
adopted or dropped (:mod:`.periodic`), a new design (:mod:`.kalman`).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .filter import FilterState, KalmanFilter

__all__ = ['carry_state', 'carry_back', 'Changes']


def carry_state(old: KalmanFilter, new: KalmanFilter, state: FilterState) -> FilterState:
    """
    Map a filter state onto another model of the same sensor family.

    States with a physical meaning in both (deflection, velocity, acceleration, working
    point, offset, drift, each line state whose frequency is within 1 Hz of one of the old
    model, and the charge states when the sensor is the same) are carried with their
    covariance; a different sensor's charge states are set to their steady value for the
    current velocity (x_R = -u / p_i) with their prior covariance; new line states start from
    their prior.  The map is linear in the state (the priors' means are 0), so the state's
    sensitivity to a rest's rounding (:mod:`.rounding`) is carried by it too.
    """
    x, P, _ = _carried(old.model, new.model, state.x, state.P, joint=False)
    bias = state.rounding           # a linear map of the state: its sensitivity maps alike
    if bias is not None:            # (d = 0 too: it takes the new model's size)
        bias = bias._replace(sensitivity=_carried(old.model, new.model, bias.sensitivity,
                                                  state.P, joint=False)[0]
                             if bias.sensitivity.any() else np.zeros(new.model.size))
    init = new.initial_state()
    out = replace(init, x=x, P=P, noise=replace(state.noise), samples=state.samples,
                  still=state.still, moved=state.moved,
                  innovations=state.innovations.closed(), rounding=bias)
    win = state.window
    if win.samples.size != new.rest.n:          # the rest test's window restarts
        return replace(out, still=False, moved=True)
    # the window carries over; its sliding DFT is recomputed for the new model's rest lines
    # (the window's samples taken as consecutive, the newest with phase 1)
    n = win.samples.size
    age = (win.pos - 1 - np.arange(n)) % n      # slot of the sample j periods ago
    phases = np.ones((n, len(new.rest_lines_hz)), complex)
    phases[age] = new.rotation[None, :] ** -np.arange(n)[:, None]
    window = replace(win.copy(), line_sums=win.samples @ phases,
                     phase=np.ones(len(new.rest_lines_hz), complex), phases=phases, contiguous=n)
    if window.jump_sums is not None:            # a jump's run goes on under the new lines
        window.jump_sums = (window.jump_sums[0], window.run_phasors(phases))
    return replace(out, window=window)


def carry_back(old: KalmanFilter, new: KalmanFilter, state: FilterState):
    """
    Return what the smoother needs to pass back across :func:`carry_state` (same sensor).

    (x_o, P_o, C): the old state's mean and covariance once the new model's structure is
    known (the periodic restart's relation is a measurement of it too) and its covariance
    with the carried state, Cov(x_old, x_new).  Back from the carried state's smoothed value
    x^s (P^s), with J = C P_new^-1: x_o + J (x^s - x_new), P_o + J (P^s - P_new) J'.
    """
    return _carried(old.model, new.model, state.x, state.P, joint=True)[2]


class Changes:
    """
    The live filter's model changes, as the offline smoother needs them.

    ``segments``: (first sample, filter, the state it started from, :func:`carry_back` or
    None) of each model the filter ran, kept only for the offline smoother's own run (None:
    not kept).  Every change takes over from a state the filter had before any change there
    (the start of a stretch, where a motion began), and filters every sample since again: so
    a change drops the segments from its first sample on, an earlier change at that sample
    included.
    """

    def __init__(self, segments: list | None = None):
        self.segments = segments

    def begin(self, filt, state: FilterState, old, old_state: FilterState) -> tuple:
        """Note that ``filt`` runs on from ``state``, carried from ``old``'s ``old_state``."""
        link = (state.copy(), carry_back(old, filt, old_state))
        if self.segments is not None:
            n = state.samples
            self.segments = [seg for seg in self.segments if seg[0] < n]
            self.segments.append((n, filt, *link))
        return link


def _carried(mo, mn, x_scaled, P_scaled, joint: bool):
    """(x, P) of the new model, scaled, and (x_o, P_o, C) when ``joint`` (:func:`carry_back`)."""
    x_old = x_scaled * mo.scale
    init_x, init_P = mn.prior()
    x, P = init_x * mn.scale, init_P * np.outer(mn.scale, mn.scale)
    P_old = P_scaled * np.outer(mo.scale, mo.scale)
    src = list(range(mo.iw, mo.il))
    dst = list(range(mn.iw, mn.il))
    for k, f in enumerate(mn.lines_hz):
        near = [j for j, g in enumerate(mo.lines_hz) if abs(g - f) < 1.0]
        if near:
            src += [mo.il + 2 * near[0], mo.il + 2 * near[0] + 1]
            dst += [mn.il + 2 * k, mn.il + 2 * k + 1]
    # periodic states carry when the fundamental is the same (each harmonic both models
    # have: another corner or count of harmonics keeps the rest); else they start afresh
    fresh = bool(mn.motion_lines_hz) and mo.motion_fundamentals_hz != mn.motion_fundamentals_hz
    if mn.motion_lines_hz and not fresh:
        for k in range(min(len(mo.motion_lines_hz), len(mn.motion_lines_hz))):
            src += [mo.im + 2 * k, mo.im + 2 * k + 1, mo.ir + 2 * k, mo.ir + 2 * k + 1]
            dst += [mn.im + 2 * k, mn.im + 2 * k + 1, mn.ir + 2 * k, mn.ir + 2 * k + 1]
    same_sensor = np.array_equal(np.diag(mo.sensor[0]), np.diag(mn.sensor[0]))
    if same_sensor:                   # only the lines changed: the charge states carry too
        src = list(range(mo.n_sensor)) + src
        dst = list(range(mn.n_sensor)) + dst
    elif joint:
        raise RuntimeError('the smoother passes back only across a model of the same sensor')
    x[dst] = x_old[src]
    P[np.ix_(dst, dst)] = P_old[np.ix_(src, src)]
    if not same_sensor:
        x, P = _another_sensor(mo, mn, x, P, periodic=bool(mn.motion_lines_hz) and not fresh)
    x, P = x / mn.scale, P / np.outer(mn.scale, mn.scale)
    back = None
    if joint:                         # x_new[dst] = x_old[src]: Cov(x_old, x_new) = P_old T'
        C = np.zeros((mo.size, mn.size))
        C[:, dst] = P_scaled[:, src] * (mo.scale[src] / mn.scale[dst])[None, :]
        back = (np.array(x_scaled, float), np.array(P_scaled, float), C)
    if fresh:
        x, P, back = _restart_motion(mn, x, P, back)
    return x, P, back


def _another_sensor(mo, mn, x: np.ndarray, P: np.ndarray, periodic: bool):
    """
    (x, P), SI units, carried onto another sensor: the current the old state explained kept.

    The deflection states are the sensor's input and carry as they are, but what the old
    state knew of a periodic motion came from its current through the old sensor: the new
    sensor reads the same current as the phasors p_j (and their rates r_j) times
    H_old(i V_j) / H_new(i V_j) (a complex gain: a turn and a scale of each phasor; eq. 45
    through the reduced model), and the motion states follow them by their forced response
    (:attr:`~.statespace.StateSpaceModel.forced_response`).  The charge states are the new
    sensor's response to that motion: forced by the periodic states, steady for the rest of
    the velocity (x_R = -u / p_i), with their prior covariance.
    """
    n = mn.n_sensor
    poles = np.diag(mn.sensor[0])
    if periodic:
        p = np.arange(mn.im, mn.size)
        X = mn.forced_response * mn.scale[mn.motion_states][:, None] / mn.scale[p][None, :]
        turn = np.eye(p.size)
        for k, f in enumerate(mn.motion_lines_hz):
            s = 2j * np.pi * f            # R_n = H_n / s of each sensor (eq. 45 reduced)
            g = complex(mo.reduced.charge_response(s) / mn.reduced.charge_response(s))
            block = np.array([[g.real, -g.imag], [g.imag, g.real]])
            for first in (2 * k, mn.ir - mn.im + 2 * k):
                turn[first:first + 2, first:first + 2] = block
        T = np.eye(mn.size)
        T[np.ix_(p, p)] = turn
        T[np.ix_(mn.motion_states[n:], p)] = X[n:] @ (turn - np.eye(p.size))
        x, P = T @ x, T @ P @ T.T
        x[:n] = X[:n] @ x[p] - (x[mn.iu] - X[n + 1] @ x[p]) / poles
    else:
        x[:n] = -x[mn.iu] / poles
    P[:n, n:] = 0.0
    P[n:, :n] = 0.0
    return x, P


def _restart_motion(mn, x: np.ndarray, P: np.ndarray, back=None):
    """
    Join the carried state and new periodic states under the new model's structure.

    The carried states keep their mean and covariance, the new periodic states p start from
    their prior (independent of them); the new model says the motion states m are the
    working point plus the periodic states' forced response plus a remainder,
    m = L h + X p + e with e ~ its stationary covariance (:meth:`~.statespace.
    StateSpaceModel.prior`).  That relation is applied as a measurement (value 0, noise the
    remainder's covariance), so what the old estimate held of a periodic motion goes to p,
    with the correlations of motion, offset and working point kept.  ``back``: (x_o, P_o, C)
    of :func:`carry_back`, conditioned on the same relation.
    """
    motion = mn.motion_states
    fresh = np.arange(mn.im, mn.size)
    P = P.copy()
    P[np.ix_(fresh, fresh)] = np.eye(fresh.size)
    others = np.setdiff1d(np.arange(mn.size), fresh)
    P[np.ix_(others, fresh)] = 0.0
    P[np.ix_(fresh, others)] = 0.0
    x = x.copy()
    x[fresh] = 0.0
    H = np.zeros((motion.size, mn.size))
    H[np.arange(motion.size), motion] = 1.0
    H[list(motion).index(mn.iw), mn.ih] = -mn.scale[mn.ih] / mn.scale[mn.iw]
    H[:, fresh] = -mn.forced_response
    PH = P @ H.T
    S = H @ PH + mn.stationary_motion
    K = np.linalg.solve(S, PH.T).T
    z = H @ x
    if back is not None:
        x_o, P_o, C = back
        C = C.copy()
        C[:, fresh] = 0.0           # the new periodic states: independent of the old state
        CH = C @ H.T
        K_o = np.linalg.solve(S, CH.T).T
        back = (x_o - K_o @ z, P_o - K_o @ CH.T, C - K_o @ PH.T)
    x = x - K @ z
    P = P - K @ PH.T
    return x, 0.5 * (P + P.T), back
