# SPDX-License-Identifier: Apache-2.0
"""
The rest test: whether the sensor is still over the last ``rest_window_s``.

A still sensor's current is its offset, the mains lines and white noise (H(0) = 0: a held
deflection gives no current).  Over the window's N samples of the current i, fitted by
least squares with a constant c and the K modelled mains lines, two chi-square tests at the
level ``false_alarm`` decide:

* **spread**: sum (i - c - lines)^2 / R < chi2_{N-1-2K}: no motion current beyond the
  noise R, which the filter measures (:mod:`.filter`), once the window's own least-squares
  fit of a constant and the K modelled mains lines is removed (a hum the filter has not
  learned yet does not hide a rest; at rest the filter then learns it within a window).  The
  fit is the exact least-squares one, (A'A)^-1 A'i over the window's basis
  A = [1, cos W_k t, -sin W_k t] (t from the newest sample): a window is not a whole number of
  the line's periods (0.2 s holds 10.04 of a 50.22 Hz line), and a sliding DFT left enough of
  a 2 % hum at 0.5 nA of noise to end a rest 1,564 times in 20 s.  A'i is the sliding DFT
  turned to the newest sample; A'A is fixed for a window without a gap
  (:attr:`RestTest.gram_inv`) and formed from the slots' phases otherwise;
* **level**: (c - b)^2 / (R/N + P_b) < chi2_1: the window's mean less its lines agrees with
  the filter's offset b within its own uncertainty P_b (so an offset not yet learned does not
  hide a rest, and a slow deflection ramp, a steady current the spread cannot see, is
  motion).

and every sample of the window must agree with rest on its own (a motion that starts ends the
rest at its first telling sample, before the pseudo-measurements below could push its current
into the offset; ``RestTest.sample_ok``): its innovation z_k = (r_k - b_k) / sqrt(R + P_k),
r_k the sample less the window's fit of the lines, against the offset b_k (variance P_k) a
still sensor would have, from the filter's own b and P_b and then learned from each sample
that agreed (a scalar Kalman filter of the offset), is within chi2_1, its two-sided CUSUM
within the level for the same false-alarm rate, and so is their likelihood ratio of a mean
shifted at any age (:mod:`.mean_shift`: a shift too small for the CUSUM, designed for one
sigma, is told once old enough).  Under rest these innovations are independent
N(0, 1), so an offset not learned yet is one offset, not evidence summed sample by sample; at
rest the filter itself is that still sensor's filter, and its b and P_b are used.  The
window's first samples are tested once the window is full, against its fit of the lines
(before it a hum would fail every sample).

**An offset that jumps** (``offset_jump_a``: an amplifier re-zeroed, a range switched): a
sample beyond the per-sample limit from the filter's offset on its own may be a step, and so
may a sample at which the CUSUM of a sensor at rest tells its mean shifted (a step smaller
than the noise of one sample: 12.5 nA under 14.7 nA of noise at 2 kHz, which no single
sample shows while the window's mean knows it to 0.7 nA; the run then begins at the CUSUM's
alarm, its delay after the step; or at the shift statistic's, for a quarter sigma ~500
samples after it), or one at which the window's mean leaves the offset while
its spread stays flat, whichever tells first (a 3.5 nA step under 2.1 nA of noise, drawn
record 80, ended the rest by the level test 0.2 % beyond its limit, before the CUSUM spoke,
and the hold read as a ramp).  From it a second run of the per-sample tests starts,
against a still sensor whose offset is the filter's with the jump's variance added
(``jump_track``, ``jump_quiet``).  Out of a still stretch (at rest, or after a sample that
agreed with rest on its own: a hold whose rest the window has not confirmed yet; a motion
that starts gently, or a drift, starts a run there too, and its current, not flat, ends the
run before it holds a window) its samples are taken less the lines of the jump's own fit,
the window's basis with a step at the run's first sample (a line fit without it leaks the
step into the lines), and it must hold the window.  Out of a motion (a step inside a move,
or in a hold after it before the rest is confirmed) its samples are taken less the filter's
own lines (the window's older samples are the motion's) and it must hold ``jump_hold_s``
(:attr:`RestTest.moving_jump_n`: a smooth move's current can be flat within the noise for a
window about its peak).  When the window fails against the filter's offset but its run has
held that long and the window passes the spread test (:meth:`RestWindow.jumped`; each of its
samples agreed with the run's offset), the offset jumped where the run began: the filter
takes the run's samples again from there as still, the offset's variance grown by the jump's
(:func:`.onset.restart`), and the rest test goes on with the run's offset.

When all pass, the filter applies the zero-velocity pseudo-measurements (as zero-velocity
updates in foot-mounted inertial navigation): the tip velocity and the motion's current are
zero within ``rest_velocity_m_s``.  The test runs on every sample; a window that fails ends
the rest at once.  Motion whose current stays within the noise over a whole window is taken
for rest; its deflection is then below ``R0^-1 sqrt(R/N)`` per second (R0 = R_n(0)).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.stats import chi2

from .innovations import CUSUM_CHANGE_SIGMAS
from .mean_shift import ShiftTest
from .rest_jump import JumpRun

__all__ = ['RestTest', 'RestWindow', 'CUSUM_DRIFT', 'rest_change']

#: CUSUM drift, in noise sigmas: half the smallest shift it must see quickly
#: (:data:`~.innovations.CUSUM_CHANGE_SIGMAS`).
CUSUM_DRIFT = 0.5 * CUSUM_CHANGE_SIGMAS


@dataclass(frozen=True)
class RestTest:
    """Thresholds of the two tests for a window of ``n`` samples at ``false_alarm``."""

    n: int
    spread_limit: float
    level_limit: float
    cusum_limit: float = math.inf
    #: variance of an offset jump (``offset_jump_a`` squared), A^2; 0: no jump test
    jump_var_a2: float = 0.0
    #: samples a jump's run must hold when it did not start out of a still stretch
    #: (``jump_hold_s``; out of one, a window's)
    moving_jump_n: int = 0
    #: (A'A)^-1 of the window's fit when it holds no gap (module docstring; None: formed
    #: from the window's phases each time)
    gram_inv: np.ndarray | None = field(default=None, compare=False)
    #: a shift of any size, told once old enough (:mod:`.mean_shift`; None: the CUSUM's only)
    shift: ShiftTest | None = field(default=None, compare=False)

    def sample_ok(self, r: float, track: tuple | None, offset_a: float, offset_var_a2: float,
                  noise_var_a2: float, at_rest: bool = False) -> tuple[bool, tuple | None]:
        """
        Test one sample r against a still sensor (offset + noise); return (ok, new track).

        ``track``: (CUSUM up, CUSUM down, the still sensor's offset, its variance) after the
        samples that agreed so far, or None to start from the filter's ``offset_a`` and
        ``offset_var_a2`` (used as they are ``at_rest``).  A sample that fails returns None.
        """
        if track is None:
            track = (0.0, 0.0, offset_a, offset_var_a2, None)
        elif at_rest:
            track = (track[0], track[1], offset_a, offset_var_a2, track[4])
        up, down, b, pb, sums = track
        s = noise_var_a2 + pb
        z = (r - b) / math.sqrt(s)
        up = max(0.0, up + z - CUSUM_DRIFT)
        down = max(0.0, down - z - CUSUM_DRIFT)
        sums, shifted = (self.shift.step(sums, z, s / pb if pb > 0.0 else math.inf)
                         if self.shift is not None else (None, False))
        if (z * z > self.level_limit or up > self.cusum_limit or down > self.cusum_limit
                or shifted):
            return False, None
        return True, (up, down, b + pb / s * (r - b), pb * noise_var_a2 / s, sums)

    def first_window(self, residuals, offset_a: float, offset_var_a2: float,
                     noise_var_a2: float) -> tuple[int, tuple | None]:
        """
        Test a full window's samples, oldest first; return (quiet, track) after the newest.

        ``quiet``: how many of the newest samples agreed in a row; ``track`` as
        :meth:`sample_ok` returns it.  The offset (and variance) is the filter's before the
        window's first sample; a sample that fails restarts from it.
        """
        quiet, track = 0, None
        for r in residuals:
            ok, track = self.sample_ok(float(r), track, offset_a, offset_var_a2, noise_var_a2)
            quiet = quiet + 1 if ok else 0
        return quiet, track

    @classmethod
    def design(cls, window_s: float, sample_rate_hz: float, false_alarm: float,
               lines_hz=(), jump_a: float = 0.0, jump_hold_s: float = 0.0) -> 'RestTest':
        """
        Thresholds for a window of ``window_s`` with the mains lines ``lines_hz`` fitted.

        ``jump_a``: RMS of an offset jump, A (0: no jump test); ``jump_hold_s``: how long a
        jump's run that did not start out of a still stretch must hold, s.
        """
        lines = len(lines_hz)
        n = max(8 + 2 * lines, int(round(window_s * sample_rate_hz)))
        turns = np.exp(2j * np.pi * np.outer(np.arange(n), lines_hz) / sample_rate_hz)
        # Siegmund: mean run length to a false alarm ~ exp(2 k (h + 1.166)) / (2 k^2) samples,
        # one-sided; two sides halve it, so each side's is 2 / false_alarm
        k = CUSUM_DRIFT
        cusum = math.log(4 * k * k / false_alarm) / (2 * k) - 1.166
        return cls(n, float(chi2.isf(false_alarm, n - 1 - 2 * lines)),
                   float(chi2.isf(false_alarm, 1)), max(cusum, 1.0), jump_a * jump_a,
                   max(n, int(round(jump_hold_s * sample_rate_hz))), _gram_inv(turns),
                   ShiftTest.design(false_alarm))

    def flat(self, spread: float, noise_var_a2: float) -> bool:
        """Tell whether the window's residual ``spread`` (A^2) is white noise (the spread test)."""
        return spread <= self.spread_limit * noise_var_a2

    def still(self, mean: float, spread: float, offset_a: float, offset_var_a2: float,
              noise_var_a2: float) -> bool:
        """
        Return True if a full window is consistent with a still sensor.

        ``mean``: the constant of the window's least-squares fit (its mean without lines), A;
        ``spread``: the sum of the fit's squared residuals, A^2; ``offset_a``,
        ``offset_var_a2``: the filter's offset and its variance; ``noise_var_a2``: the
        measured white-noise variance per sample, A^2.
        """
        return (self.flat(spread, noise_var_a2)
                and self.level(mean, offset_a, offset_var_a2, noise_var_a2))

    def level(self, mean: float, offset_a: float, offset_var_a2: float,
              noise_var_a2: float) -> bool:
        """Tell whether a window's mean is the filter's offset (:meth:`still`'s level test)."""
        d = mean - offset_a
        return d * d <= self.level_limit * (noise_var_a2 / self.n + offset_var_a2)


def _gram_inv(turns: np.ndarray) -> np.ndarray:
    """
    (A'A)^-1 of the window's line fit; ``turns[j, k]`` = e^{-i W_k t_j}, t_j from the newest.

    A = [1, Re, Im of each line's turn] = [1, cos W_k t_j, -sin W_k t_j].
    """
    A = np.empty((turns.shape[0], 1 + 2 * turns.shape[1]))
    A[:, 0] = 1.0
    A[:, 1::2], A[:, 2::2] = turns.real, turns.imag
    return np.linalg.pinv(A.T @ A)


@dataclass(slots=True)
class RestWindow(JumpRun):
    """
    The window the rest test judges: the last N samples of the current, and its progress.

    ``samples`` is a ring (``pos``: the slot the next sample takes, ``count``: how many it
    holds, ``contiguous``: how many of the newest are one period apart); ``line_sums`` is the
    sliding DFT of the tested lines over it (the phasor of each slot's sample in ``phases``,
    of the newest in ``phase``); ``total`` and ``total_sq`` are
    running sums, recomputed exactly once per turn of the ring (no drift); ``offset_var`` the
    filter's offset variance (A^2) before each slot's sample; ``quiet`` how many of the newest
    samples agreed with rest in a row, and ``track`` the CUSUM and still-sensor offset after
    them (:meth:`RestTest.sample_ok`; before the window is full, the filter's offset before
    its first sample).
    """

    samples: np.ndarray
    line_sums: np.ndarray
    phase: np.ndarray
    phases: np.ndarray
    offset_var: np.ndarray
    count: int = 0
    pos: int = 0
    contiguous: int = 0
    total: float = 0.0
    total_sq: float = 0.0
    quiet: int = 0
    track: tuple | None = None
    #: the same for a still sensor whose offset jumped (``RestTest.jump_var_a2``)
    jump_quiet: int = 0
    jump_track: tuple | None = None
    #: the run's own sums over its samples: (sum of the currents, sum of their phasors)
    #: (:meth:`_step_residual`)
    jump_sums: tuple | None = None
    #: the run did not start out of a still stretch (it must hold ``moving_jump_n`` samples)
    jump_moving: bool = False

    @classmethod
    def empty(cls, n: int, lines: int, offset_var_a2: float) -> 'RestWindow':
        """Return a window of ``n`` samples testing ``lines`` lines, before its first sample."""
        return cls(np.zeros(n), np.zeros(lines, complex), np.ones(lines, complex),
                   np.ones((n, lines), complex), np.full(n, offset_var_a2))

    def copy(self) -> 'RestWindow':
        return replace(self, samples=self.samples.copy(), line_sums=self.line_sums.copy(),
                       phase=self.phase.copy(), phases=self.phases.copy(),
                       offset_var=self.offset_var.copy())

    def push(self, current_a: float, turn, steps: int = 1) -> None:
        """
        Take the newest sample, ``steps`` periods after the one before.

        ``turn``: its lines' phasor turn since the one before (None: the first sample).
        """
        pos, n = self.pos, self.samples.size
        self.contiguous = self.contiguous + 1 if steps == 1 else 1
        old = self.samples[pos]
        if self.phase.size:
            if turn is not None:
                self.phase = self.phase * turn
            self.line_sums += current_a * self.phase - old * self.phases[pos]
            self.phases[pos] = self.phase
        self.samples[pos] = current_a
        self.total += current_a - old
        self.total_sq += current_a * current_a - old * old
        self.pos = pos + 1
        if self.pos == n:           # exact sums once per turn
            self.pos = 0
            w = self.samples
            self.total, self.total_sq = float(w.sum()), float(w @ w)

    def fit(self, gram_inv: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """
        Return (theta, A'i): the least-squares fit of a constant and the lines (module docstring).

        theta = [mean, (cos, -sin) of each line], the times from the newest sample (A'i is the
        sliding DFT turned to the newest sample, as reals); ``gram_inv``: (A'A)^-1 for a window
        without a gap (None: formed from the phases).
        """
        return self.solve(self.gram(gram_inv))

    def solve(self, gram: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return (theta, A'i) of :meth:`fit` given the window's (A'A)^-1 ``gram``."""
        b = np.concatenate(((self.total,), (self.line_sums * self.phase.conj()).view(float)))
        return gram @ b, b

    def gram(self, gram_inv: np.ndarray | None = None) -> np.ndarray:
        """Return (A'A)^-1 of the window's fit (``gram_inv`` if the window holds no gap)."""
        if gram_inv is None or self.contiguous < self.samples.size:
            return _gram_inv(self.phases * self.phase.conj())
        return gram_inv

    def residuals(self, start: int) -> np.ndarray:
        """Return the window's samples less its fit of the lines, from slot ``start`` on."""
        n = self.samples.size
        order = (start + np.arange(n)) % n
        if not self.phase.size:
            return self.samples[order]
        theta, _ = self.fit()
        turns = self.phases[order] * self.phase.conj()
        return self.samples[order] - (turns.real @ theta[1::2] + turns.imag @ theta[2::2])

    def judge(self, test: RestTest, current_a: float, offset_a: float, offset_var_a2: float,
              noise_var_a2: float, at_rest: bool, lines=lambda: (0.0, 0.0)) -> bool | None:
        """
        Test the newest sample (after :meth:`push`); return the window's verdict.

        None while the window fills; then True when every sample agreed with rest on its own
        (the window's first ones once it is full, against its fit of the lines) and the
        whole window passes :meth:`RestTest.still`.  ``offset_a``, ``offset_var_a2``: the
        filter's offset and its variance before this sample; ``lines()``: the filter's mains
        lines at it and their variance, (A, A^2) (the jump test's run out of a motion asks).
        """
        n = self.samples.size
        filled = self.count == n - 1
        self.count = min(self.count + 1, n)
        self.offset_var[self.pos - 1] = offset_var_a2
        if self.count < n:
            self.track = self.track or (0.0, 0.0, offset_a, offset_var_a2, None)
            return None
        gram = self.gram(test.gram_inv) if self.phase.size else None
        theta, b = self.solve(gram) if gram is not None else (None, None)
        if filled:                  # from the offset before the window's first sample
            first = self.track or (0.0, 0.0, offset_a, offset_var_a2, None)
            self.quiet, self.track = test.first_window(self.residuals(self.pos), *first[2:4],
                                                       noise_var_a2)
        else:                       # this sample less the window's lines (t = 0: the cosines)
            r = current_a - float(theta[1::2].sum()) if theta is not None else current_a
            ok, self.track = test.sample_ok(r, self.track, offset_a, offset_var_a2,
                                            noise_var_a2, at_rest)
            still_before = at_rest or self.quiet > 0
            self.quiet = self.quiet + 1 if ok else 0
        if self.quiet < n:          # a sample of the window disagreed: no window test
            flat = level = False
        else:
            mean, spread = self._level(theta, b)
            flat = test.flat(spread, noise_var_a2)
            level = flat and test.level(mean, offset_a, offset_var_a2, noise_var_a2)
        if not filled and test.jump_var_a2:     # at rest, a sample or a flat window off the
            self._follow_jump(test, r, (current_a, gram, theta, b), offset_a,   # offset
                              offset_var_a2, noise_var_a2, still_before, lines,
                              shifted=at_rest and not (ok and (level or not flat)))
        return level

    def _level(self, theta, b) -> tuple[float, float]:
        """Return the window's (mean, spread) less the lines' fit ``theta`` (None: none)."""
        n = self.samples.size
        if theta is None:
            mean, explained = self.total / n, self.total * self.total / n
        else:
            mean, explained = float(theta[0]), float(b @ theta)
        return mean, max(self.total_sq - explained, 0.0)


def rest_change(verdict: bool | None, still: bool, moved: bool):
    """
    Return (still, release, begins, moved) after the rest window's ``verdict``.

    The working point is released when the tip leaves a rest (the centre of the coming
    motion is unknown) and when a new hold begins (it is where the tip is held); a record
    that starts at rest keeps its rest position until it moves.  None: the window is not
    full, no rest.
    """
    if verdict is None:
        return False, False, False, moved
    release = still != verdict and (not verdict or moved)
    moved = (moved or not verdict) and not (release and verdict)
    return verdict, release, verdict and not still, moved
