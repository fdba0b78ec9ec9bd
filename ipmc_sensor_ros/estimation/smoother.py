# SPDX-License-Identifier: Apache-2.0
"""
Fixed-interval Rauch-Tung-Striebel smoother on the filter of :mod:`.filter`.

Backward over a forward pass (Rauch, Tung & Striebel 1965)::

    J_k   = P+_k F_{k+1}' (P-_{k+1})^-1
    x^s_k = x+_k + J_k (x^s_{k+1} - x-_{k+1})
    P^s_k = P+_k + J_k (P^s_{k+1} - P-_{k+1}) J_k'

``F_{k+1}`` is the transition into sample k+1 (``steps`` periods); a rest sample's release of
the working point is part of its P- (:mod:`.filter`), so the rests need nothing special.

Memory stays bounded for records of any length: the forward pass keeps its state every
``chunk`` samples only, and the backward pass re-runs the filter one chunk at a time (the
filter is deterministic, so the re-run is the same pass) to get that chunk's P+ and P-.
The smoothed estimate is never worse than the filtered one in the model's own terms
(P^s <= P+); a fixed-lag smoother is the same backward pass over the last samples.
"""
from __future__ import annotations

import numpy as np

from .filter import FilterState, ForwardRecord, KalmanFilter

__all__ = ['smooth', 'smooth_segments', 'rts_backward', 'across', 'first_of',
           'CHUNK_SAMPLES']

#: Samples re-run and smoothed at a time (2 x 4096 covariances of a 15-state model: ~15 MB).
CHUNK_SAMPLES = 4096


def rts_backward(filt: KalmanFilter, rec: ForwardRecord, end=None):
    """
    Smooth one forward record; return (w^s, its variance, (x^s, P^s) of the first sample).

    The deflection is the record's published one (``w_row``: where each sample was taken),
    m and m^2.

    ``end``: (x^s, P^s, x-, P-, steps) of the sample after the record, or (x^s, P^s) of the
    record's last sample (smoothed across a model change: :func:`across`), or None (the
    record ends the data).
    """
    n = rec.x_post.shape[0]
    w, pw, rows = np.empty(n), np.empty(n), rec.w_row
    if end is None or len(end) == 2:
        x_next, P_next = (rec.x_post[-1], rec.P_post[-1]) if end is None else end
        w[-1], pw[-1] = rows[-1] @ x_next, rows[-1] @ P_next @ rows[-1]
        last = n - 2
        xp_next, Pp_next, step_next = rec.x_pred[-1], rec.P_pred[-1], int(rec.steps[-1])
    else:
        x_next, P_next, xp_next, Pp_next, step_next = end
        last = n - 1
    for k in range(last, -1, -1):
        if k < n - 1:
            xp_next, Pp_next = rec.x_pred[k + 1], rec.P_pred[k + 1]
            step_next = int(rec.steps[k + 1])
        F, _ = filt.model.discrete(step_next)
        J = np.linalg.solve(Pp_next, F @ rec.P_post[k]).T
        x_next = rec.x_post[k] + J @ (x_next - xp_next)
        P_next = rec.P_post[k] + J @ (P_next - Pp_next) @ J.T
        w[k], pw[k] = rows[k] @ x_next, rows[k] @ P_next @ rows[k]
    return w, pw, (x_next, P_next)


def smooth(filt: KalmanFilter, state: FilterState, current_a, steps=None,
           chunk: int = CHUNK_SAMPLES, last=None):
    """
    Smooth a whole record from ``state``; return (w, std, first).

    ``w`` and ``std`` are the smoothed deflection and its standard deviation, m; ``first``:
    (x^s, P^s, x-, P-, steps) of the first sample, scaled (:func:`across` goes back from
    there).  ``last``: the smoothed (x^s, P^s) of the last sample, where a later model's
    smoother passed back (None: the record ends the data).
    """
    y = np.asarray(current_a, dtype=float)
    n = y.size
    st = np.ones(n) if steps is None else np.asarray(steps, dtype=float)
    starts = list(range(0, n, chunk))
    checkpoints = []
    s = state
    for a in starts:                      # forward: keep the state at each chunk's start
        checkpoints.append(s)
        s, _, _, _ = filt.run(s, y[a:a + chunk], st[a:a + chunk])
    w = np.empty(n)
    pw = np.empty(n)
    end = last
    for a, s0 in zip(reversed(starts), reversed(checkpoints)):
        b = min(a + chunk, n)
        rec = ForwardRecord.empty(b - a, filt.model.size)
        filt.run(s0, y[a:b], st[a:b], record=rec)
        w[a:b], pw[a:b], (x_first, P_first) = rts_backward(filt, rec, end)
        end = first_of(rec, x_first, P_first)
    return w, np.sqrt(np.maximum(pw, 0.0)), end


def first_of(rec: ForwardRecord, x_first, P_first) -> tuple:
    """(x^s, P^s, x-, P-, steps) of a record's first sample: what the pass before needs."""
    return x_first, P_first, rec.x_pred[0], rec.P_pred[0], int(rec.steps[0])


def across(filt: KalmanFilter, start: FilterState, first, back):
    """
    Return the smoothed (x^s, P^s) of the old model's last sample before a model change.

    ``filt`` ran from ``start`` (carried from the old model's last state:
    :func:`~.carry.carry_state`); ``first``: :func:`smooth`'s ``first`` of that run;
    ``back``: :func:`~.carry.carry_back` of the change.  One RTS step back to the carried
    state, then through the carry: J = C P_new^-1.
    """
    xs, Ps, xp, Pp, step = first
    F, _ = filt.model.discrete(int(step))
    J = np.linalg.solve(Pp, F @ start.P).T
    x_new = start.x + J @ (xs - xp)
    P_new = start.P + J @ (Ps - Pp) @ J.T
    x_o, P_o, C = back
    Jc = np.linalg.lstsq(start.P, C.T, rcond=None)[0].T      # P_new may be singular
    return x_o + Jc @ (x_new - start.x), P_o + Jc @ (P_new - start.P) @ Jc.T


def smooth_segments(segments, current_a, steps) -> tuple[np.ndarray, np.ndarray]:
    """
    Smooth a record the filter ran under several models; return (w, std), m.

    ``segments``: (first sample, filter, the state it started from, :func:`~.carry.
    carry_back` of the change or None) of each model, in order.  Each part is smoothed from
    its state (:func:`smooth`), the last first, and the backward pass goes on into the part
    before through the change (:func:`across`).
    """
    y = np.asarray(current_a, dtype=float)
    w, std = np.empty(y.size), np.empty(y.size)
    ends = [seg[0] for seg in segments[1:]] + [y.size]
    last = None
    for (a, filt, state, back), b in reversed(list(zip(segments, ends))):
        if b > a:
            w[a:b], std[a:b], first = smooth(filt, state, y[a:b], steps[a:b], last=last)
            last = None if back is None else across(filt, state, first, back)
    return w, std
