# SPDX-License-Identifier: Apache-2.0
"""
Where the offset stepped in a span: the generalised likelihood ratio of one jump, at every sample.

Willsky and Jones (1976): a span filtered again under a model gives normalised innovations
z_k = nu_k / sqrt(S_k), N(0, 1) under the model.  A jump of the offset by ``a`` before
sample t adds a rho_k(t) to z_k for k >= t, the jump's signature through this filter::

    rho_k(t) = c_k e_k / sqrt(S_k),   e_t = e_b (the offset's unit vector),
    e_{k+1} = Phi_k e_k,              Phi_k = F_{k+1} (I - K_k c_k),  K_k = P_k c_k' / S_k

(F_{k+1} the transition to the next sample, c_k the row the current was measured with: the
slot's or the stamp's, :mod:`.instants`).  A sample the rest test found still has the rest's
pseudo-measurements too (zero velocity, ...); its map is then the product of every update's
I - K h, which for the filter's own gains is P+_k (P-_k)^-1 (posterior times inverse prior:
each factor is P_i P_(i-1)^-1); without them a jump's error at rest would run through the
motion's dynamics unchecked.  What the best jump at t explains is
(sum_k rho_k z_k)^2 / sum_k rho_k^2.  Both sums are linear and quadratic forms in e_b of
quantities that run *backwards* (the adjoint of the signature's recursion)::

    sum_{k>=t} w_k rho_k(t) = e_b' lambda_t,  lambda_t = Phi_t' lambda_{t+1} + c_t' w_t / sqrt(S_t)
    sum_{k>=t} rho_k(t)^2   = e_b' M_t e_b,   M_t = Phi_t' M_{t+1} Phi_t + c_t' c_t / S_t

so one backward pass gives the ratio at *every* sample, not at a grid of candidates: a
step of several times the one-sample prediction's spread must be placed on its sample (one
sample early or late, the filter reads the step's first sample as motion, and the model
with the jump fails its test as surely as the model without).

Over a periodic model's blocks (one period each: the statistic of :mod:`.innovations`, in
which a model's residual at the motion's harmonics sums to nearly nothing over a period,
while sample by sample it would pull the jump's time to where it happens to match), the
signature's and innovations' block sums B_j(t), Z_j give sum_j B_j Z_j / n_j (the weights
w_k = Z_j(k) / n_j(k)) and sum_j B_j^2 / n_j (the block being summed, v, and the blocks
after it, M_>, run back the same way).  The block ratio finds the jump's period, the
sample ratio within a period of it its sample; over the span's last period, which no
whole block follows, the sample ratio alone.
"""
from __future__ import annotations

import numpy as np

from .filter import ForwardRecord, KalmanFilter
from .innovations import block_samples
from .timebase import slots_of

__all__ = ['jump_signatures', 'offset_step_at']


def offset_step_at(span, filt: KalmanFilter, chunk: int = 512) -> int | None:
    """
    Return the sample of ``span`` before which the offset most likely jumped, or None.

    ``span``: a :class:`~.periodic.Stretch` (its start state, samples and sample periods),
    filtered again under ``filt``'s periodic model.  Candidates: the samples within a period
    of the block the block ratio picks (of the samples that leave a period after them, the
    span's first included: a jump just before its start, which the last check's test could
    not see yet), and every sample of the span's last period (a jump a block closed early
    on, a few samples old: :mod:`.innovations`); None: fewer than two samples.
    """
    m = filt.model
    n, period = len(span.y), block_samples(m.motion_fundamentals_hz, m.sample_rate_hz)
    if n < 2:
        return None
    fit, power = _ratios(filt, span.steps, _innovations(span, filt, chunk), period)
    near = np.arange(0, n)              # the sample stage: the last period's samples too
    judged = near > n - period - 1
    if n >= period + 2:                 # the block stage: the period of an older jump
        at = np.arange(0, n - period + 1)
        coarse = at[int(np.argmax(fit[0, at] ** 2 / np.maximum(power[0, at], 1e-300)))]
        judged |= np.abs(near - coarse) <= period
    sample = fit[1, near] ** 2 / np.maximum(power[1, near], 1e-300)
    return int(near[int(np.argmax(np.where(judged, sample, -1.0)))])


def jump_signatures(span, filt: KalmanFilter, chunk: int = 512) -> tuple:
    """
    Return (fit, power) per sample of ``span``: sum_k rho_k z_k and sum_k rho_k^2, 1 A jump.

    The sample stage of the module docstring: twice the log-likelihood ratio of a jump of
    ``a`` amperes before sample t is 2 a fit[t] - a^2 power[t].
    """
    fit, power = _ratios(filt, span.steps, _innovations(span, filt, chunk), 1, blocks=False)
    return fit[1], power[1]


def _ratios(filt: KalmanFilter, steps, forward, period: int, blocks: bool = True):
    """
    Return (fit, power), each (block, sample) x sample: the sums of the module docstring.

    ``forward``: what :func:`_innovations` returns.  One backward pass: lambda (blocks,
    samples), v and M_> (blocks), M (samples); without ``blocks`` the block stage is not run
    (its rows stay 0).
    """
    m = filt.model
    z, s, rows, gains, maps = forward
    n, size = z.size, m.size
    unit = np.zeros(size)
    unit[m.ib] = 1.0 / m.scale[m.ib]
    starts = np.arange(0, n, period)
    sizes = np.minimum(period, n - starts)
    block_mean = np.repeat(np.add.reduceat(z, starts) / sizes, sizes)     # Z_j / n_j
    fit, power = np.zeros((2, n)), np.zeros((2, n))
    lam_b, lam_s, v, later, M = (np.zeros(size), np.zeros(size), np.zeros(size),
                                 np.zeros((size, size)), np.zeros((size, size)))
    for t in range(n - 1, -1, -1):
        if t + 1 < n:
            F = m.discrete(slots_of(steps[t + 1]))[0]      # the model caches it
            # the sample's map P+ (P-)^-1: stored whole where the rest's updates followed
            # the current's, else the current's alone, I - K c_k (rank one: kept as K)
            phi = (F @ maps[t] if t in maps
                   else F - np.outer(F @ gains[t], rows[t]) / s[t] ** 2)
            lam_s, M = phi.T @ lam_s, phi.T @ M @ phi
            if blocks:
                lam_b, v, later = phi.T @ lam_b, phi.T @ v, phi.T @ later @ phi
        row = rows[t] / s[t]
        lam_s += row * z[t]
        M += np.outer(row, row)
        fit[1, t], power[1, t] = unit @ lam_s, unit @ M @ unit
        if not blocks:
            continue
        lam_b += row * block_mean[t]
        v += row
        n_block = min(period, n - (t - t % period))
        fit[0, t] = unit @ lam_b
        power[0, t] = (unit @ v) ** 2 / n_block + unit @ later @ unit
        if t % period == 0:             # the block's first sample: it joins the later ones
            later += np.outer(v, v) / n_block
            v = np.zeros(size)
    return fit, power


def _innovations(span, filt: KalmanFilter, chunk: int):
    """
    Return (z, sqrt(S), c_k, P c_k', maps) for each sample of ``span`` filtered again.

    The filter's own normalised innovations, their sqrt(S) and measurement rows; ``maps``:
    P+ (P-)^-1 of each sample found still (the module docstring), by sample.  In pieces of
    ``chunk`` samples, so the covariances held for them stay small.
    """
    m, state = filt.model, span.start_under(filt)
    n = len(span.y)
    z, s, maps = np.empty(n), np.empty(n), {}
    rows, gains = np.empty((n, m.size)), np.empty((n, m.size))
    for a in range(0, n, chunk):
        b = min(n, a + chunk)
        rec = ForwardRecord.empty(b - a, m.size)
        state = filt.run(state, span.y[a:b], span.steps[a:b], record=rec)[0]
        z[a:b], s[a:b], rows[a:b] = rec.z, rec.s, rec.c_row
        gains[a:b] = np.einsum('kij,kj->ki', rec.P_pred, rec.c_row)
        for k in np.flatnonzero(rec.still):
            maps[a + k] = np.linalg.solve(rec.P_pred[k], rec.P_post[k]).T
    return z, s, rows, gains, maps
