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

__all__ = ['carry_state']


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
    # periodic states carry when the fundamental is the same; else they start afresh
    fresh = bool(mn.motion_lines_hz) and mo.motion_hz != mn.motion_hz
    if mn.motion_lines_hz and not fresh:
        src += list(range(mo.im, mo.size))
        dst += list(range(mn.im, mn.size))
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
    x, P = x / mn.scale, P / np.outer(mn.scale, mn.scale)
    if fresh:
        x, P = _restart_motion(mn, x, P)
    out = replace(init, x=x, P=P,
                  noise_var_a2=state.noise_var_a2, samples=state.samples,
                  contiguous=state.contiguous, noise_weight=state.noise_weight,
                  still=state.still, moved=state.moved, quiet=state.quiet,
                  rest_track=state.rest_track)
    if state.window.size != new.rest.n:
        return replace(out, still=False, moved=True, quiet=0,    # the rest test's window
                       rest_track=None)                          # restarts
    # the window carries over; its sliding DFT is recomputed for the new model's rest lines
    # (the window's samples taken as consecutive, the newest with phase 1)
    n = state.window.size
    age = (state.window_pos - 1 - np.arange(n)) % n       # slot of the sample j periods ago
    phases = np.ones((n, len(new.rest_lines_hz)), complex)
    phases[age] = new.rotation[None, :] ** -np.arange(n)[:, None]
    sums = state.window @ phases
    return replace(out, window=state.window.copy(), window_count=state.window_count,
                   window_offset_var=state.window_offset_var.copy(),
                   window_pos=state.window_pos, total=state.total, total_sq=state.total_sq,
                   line_sums=sums, phase=np.ones(len(new.rest_lines_hz), complex),
                   phases=phases)


def _restart_motion(mn, x: np.ndarray, P: np.ndarray):
    """
    Join the carried state and new periodic states under the new model's structure.

    The carried states keep their mean and covariance, the new periodic states p start from
    their prior (independent of them); the new model says the motion states m are the
    working point plus the periodic states' forced response plus a remainder,
    m = L h + X p + e with e ~ its stationary covariance (:meth:`~.statespace.
    StateSpaceModel.prior`).  That relation is applied as a measurement (value 0, noise the
    remainder's covariance), so what the old estimate held of a periodic motion goes to p,
    with the correlations of motion, offset and working point kept.
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
    x = x - K @ (H @ x)
    P = P - K @ PH.T
    return x, 0.5 * (P + P.T)
