# SPDX-License-Identifier: Apache-2.0
"""
The rest test's jump run: a still sensor whose offset jumped (:mod:`.rest`, module docstring).

:class:`JumpRun` holds the methods of :class:`~.rest.RestWindow` that follow the run: where
it starts, what each of its samples is tested as, and when it is taken.  Its fields
(``jump_quiet``, ``jump_track``, ``jump_sums``, ``jump_moving``) are the window's.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ['JumpRun', 'JumpLag', 'jump_covariance']


class JumpRun:
    """Mixin of :class:`~.rest.RestWindow`: the run of an offset's jump."""

    __slots__ = ()

    def _follow_jump(self, test, r: float, fit: tuple, offset_a: float,
                     offset_var_a2: float, noise_var_a2: float, still_before: bool,
                     lines, shifted: bool = False) -> None:
        """
        Test sample ``r`` against a still sensor whose offset jumped (module docstring).

        A run starts at a sample beyond the per-sample limit from the filter's offset on its
        own, or at one the rest test refused at rest by its CUSUM or by its window's mean,
        the spread flat (``shifted``: a step smaller than one sample's noise; a motion that
        starts gently, or a drift, starts one there too, and its current, not flat, ends it
        before it holds a window); out of a still
        stretch (``still_before``: at rest, or the sample before agreed with rest) it must
        hold a window, out of a motion ``RestTest.moving_jump_n`` samples (a smooth move's
        current can be flat within the noise for a window about its peak).  It starts from
        the filter's offset with the jump's variance added (``jump_quiet`` 1: a run starts
        here) and learns it from each sample that agrees (:meth:`_run_residual`).  ``fit``:
        (the sample's current, and the window's (A'A)^-1, fit and A'i; None without lines);
        ``lines()``: the filter's mains lines at this sample and their variance, (A, A^2)
        (asked for only out of a motion, whose samples are tested within the noise and that
        variance: the filter's own account of how well it knows the hum).
        """
        current = fit[0]
        if self.jump_track is not None:
            if self._steps():
                total, phasors = self.jump_sums
                self.jump_sums = (total + current, phasors + self.phase)
            residual, line_var = self._run_residual(r, fit, lines)
            ok, self.jump_track = test.sample_ok(residual, self.jump_track, offset_a,
                                                 offset_var_a2, noise_var_a2 + line_var)
            if ok:
                self.jump_quiet += 1
                return
        self.jump_quiet, self.jump_track, self.jump_sums = 0, None, None
        self.jump_moving = moving = not still_before
        value, line_var = lines() if moving else (0.0, 0.0)
        d = (current - value if moving else r) - offset_a
        if shifted or d * d > test.level_limit * (noise_var_a2 + line_var + offset_var_a2):
            self.jump_sums = None if moving else (current, self.phase.copy())
            residual, line_var = ((current - value, line_var) if moving   # lines asked once
                                  else self._run_residual(r, fit, lines))
            ok, self.jump_track = test.sample_ok(residual, None, offset_a,
                                                 offset_var_a2 + test.jump_var_a2,
                                                 noise_var_a2 + line_var)
            if ok:
                self.jump_quiet = 1
            else:
                self.jump_sums = None

    def run_phasors(self, phases: np.ndarray) -> np.ndarray:
        """
        Return the sum of the run's samples' phasors under the per-slot ``phases``.

        What ``jump_sums`` holds for the run's newest samples (:meth:`_follow_jump` adds one
        per sample while ``jump_quiet + 1`` is below the window's size), asked when the
        window's lines change (:func:`~.carry.carry_state`): a run in progress goes on under
        the new lines as if they had been tested from its start.
        """
        n = self.samples.size
        length = min(self.jump_quiet, n - 1)
        return phases[(self.pos - 1 - np.arange(length)) % n].sum(axis=0)

    def _steps(self) -> bool:
        """Tell whether the run's samples are fitted with its step (:meth:`_run_residual`)."""
        return (self.jump_sums is not None and not self.jump_moving
                and self.jump_quiet + 1 < self.samples.size)

    def _run_residual(self, r: float, fit: tuple, lines) -> tuple[float, float]:
        """
        Return the newest sample less the lines the jump's run assumes, and their variance.

        Out of a still stretch, the lines of the window's fit with the jump's step
        (:meth:`_step_residual`; ``r``, the fit without it, once the run holds the window).
        Out of a motion, the filter's own lines ``lines()``: the window's older samples are
        the motion's, whose current a fit of lines would take in (a move's end leaked ~8 nA
        into them, and the run began only when the move had left the window).
        """
        current, gram, theta, b = fit
        if self.jump_moving:
            value, variance = lines()
            return current - value, variance
        if gram is None or not self._steps():
            return r, 0.0
        return self._step_residual(current, gram, theta, b), 0.0

    def _step_residual(self, current_a: float, gram: np.ndarray, theta: np.ndarray,
                       b: np.ndarray) -> float:
        """
        Return the newest sample less the lines of the window's fit with the jump's step.

        The jump's hypothesis is its own least squares: the window's basis A (a constant and
        the lines) and a step e, 1 on the run's samples, 0 before.  With G = A'A, u = A'e,
        L = e'e and the fit theta = G^-1 A'i: the step beta = (e'i - u' theta) / (L - u' G^-1
        u) and the lines' fit theta - G^-1 u beta (the block inverse).  Fitted without e, a
        window that holds the step leaks it into the lines (~1 nA of a 14 nA step over the
        nominal 50 and 60 Hz lines with harmonics: 5 sigma at 0.2 nA of noise).
        """
        total, phasors = self.jump_sums
        length = self.jump_quiet + 1
        u = np.concatenate(((float(length),), (phasors * self.phase.conj()).view(float)))
        v = gram @ u
        schur = length - float(u @ v)
        if not schur > 1e-9 * length:   # the window's basis already holds the step
            return current_a - float(theta[1::2].sum())
        beta = (total - float(u @ theta)) / schur
        return current_a - float((theta[1::2] - v[1::2] * beta).sum())

    def jumped(self, test, noise_var_a2: float) -> bool:
        """
        Tell whether the window is still at an offset that jumped; if so, rest on that run.

        True when the jump test's run has held the whole window (``RestTest.moving_jump_n``
        samples out of a motion; each sample agreed with the run's offset, learned from the
        samples before it) and the window passes the spread test; the rest test's run then
        becomes that one.  The window's mean is not tested
        again: each of its samples agreed with the run's offset, within the per-sample test
        and the CUSUM.
        """
        need = max(self.samples.size, test.moving_jump_n if self.jump_moving else 0)
        if self.jump_quiet < need or self.jump_track is None:
            return False
        fit = self.fit(test.gram_inv) if self.phase.size else (None, None)
        if not test.flat(self._level(*fit)[1], noise_var_a2):
            return False
        self.quiet, self.track = self.jump_quiet, self.jump_track
        return True


class JumpLag(NamedTuple):
    """How long before its run a jump found out of a motion happened (:mod:`.jump_time`)."""

    #: the lag's mean and variance, s and s^2
    mean_s: float
    var_s2: float
    #: the jump as its run measured it, A
    jump_a: float


def jump_covariance(jump_var_a2: float, lag: JumpLag | None, charge_gain: float) -> np.ndarray:
    """
    Return the covariance a jump of the offset adds to (offset A, deflection m).

    A jump J that happened L seconds before its run, while the sensor moved, was read as
    motion: the current's steady part is R_n(0) times the tip's velocity (H_n(s) = s R_n(s),
    eq. 45 reduced as in :mod:`~ipmc_sensor_ros.lti.reduction`, so H(0) = 0; R_n(0) is
    ``charge_gain``, A s/m), so from then the filter's tip ramped by J / R_n(0) a second (drawn
    record 187: 9.25 nA, 29 um/s, until a hold).  The deflection's error is then
    -J L / R_n(0): with the jump's variance ``jump_var_a2`` and the lag's mean and
    variance, the cross term is -var_J E[L] / R_n(0), and the deflection's own
    (var_J E[L]^2 + J^2 var_L) / R_n(0)^2: the offset measured again moves the deflection
    by -E[L] / R_n(0) a unit of its change and leaves the spread of the jump's time, with
    the jump's measured size.  ``lag`` None: the offset's variance alone (a jump at rest,
    or one placed on its sample by :mod:`.step_glr`).
    """
    cov = np.zeros((2, 2))
    cov[0, 0] = jump_var_a2
    if lag is not None:
        k = -lag.mean_s / charge_gain
        cov[0, 1] = cov[1, 0] = jump_var_a2 * k
        cov[1, 1] = jump_var_a2 * k * k + (lag.jump_a / charge_gain) ** 2 * lag.var_s2
    return cov
