# SPDX-License-Identifier: Apache-2.0
"""
The time rules of a sample stream: which sample-clock slot each stamp takes.

A DAQ samples on its own clock; the host stamps each sample with some jitter.  The model of a
stream (one *run*) is

    t_j = a + P (k_j - k_a) + e_j,     |e_j| <= JITTER_FRACTION P                       (1)

with ``P`` the sample period, ``k_j`` the integer slot of sample j on the sample clock and
``(a, k_a)`` an anchor (the stamp of slot ``k_a``).  :class:`Timebase` keeps ``P`` and the
anchor (the *grid*) and takes each stamp at the nearest grid slot (:func:`grid_slot`):

    k = floor((t - a) / P + 1/2) + k_a                                                  (2)

so ``steps = k - k_prev`` is the number of sample periods since the previous accepted sample
(1: contiguous; m > 1: m - 1 samples missing, bridged by the filter), and
``(t - a) / P - (k - k_a)``, in [-1/2, 1/2), the stamp's offset from its slot in periods
(``slot_offset``: where a DAQ that samples when it stamps took the sample, :mod:`.instants`).
Jitter up to ``JITTER_FRACTION`` = 25 % of the period rounds to the right slot as long as the
grid is within the remaining 25 % of the stamps' slots, which the grid's updates keep it:

* **phase and period** are refitted at the end of each *window* of accepted samples: a
  least-squares line of the stamps against their slots (outliers beyond half a period
  dropped, :func:`fit_line`).  The anchor becomes the line's value at the window's last slot
  (the phase follows the stamps with a lag of at most one window); the period takes the
  fitted slope only where it differs from the current one by more than ``SIGNIFICANCE``
  standard errors (a DAQ clock some ppm off the host's is followed; stamp noise is not; the
  standard error is estimated from the fit's residuals, so the threshold is the Student-t
  quantile of as many degrees of freedom at the same probability).
  A window ends before the period's remaining uncertainty (``SIGNIFICANCE`` standard errors)
  could move the grid by ``DRIFT_MARGIN`` of a period, and never before
  ``FIRST_WINDOW_SAMPLES``; until the run has ``RATE_WINDOW_S`` of data each fit takes every
  sample of the run, then windows of ``RATE_WINDOW_S``.  So the first windows of a run are a
  few samples long and a stream some % off the nominal rate is followed before its phase
  drifts off the grid;
* **re-lock**: a grid whose period is off by more than the jitter margin cannot see it
  (every stamp still has a nearest slot: a 700 Hz stream on a 1 kHz grid looks like a 1 kHz
  stream missing 3 samples in 10, a 2 kHz one like a 1 kHz one with a stamp between slots).
  The median spacing of the stamps can: in a window of at least ``RELOCK_MIN_SAMPLES`` that
  has gaps or stamps between slots, a median spacing more than ``JITTER_FRACTION`` away from
  ``P`` that explains the stamps with at most every other slot empty re-locks the grid (slots
  re-counted from the spacings, then fitted); so does one less far off that differs from
  ``P`` by more than ``SIGNIFICANCE`` standard errors of the median (a grid a few % off whose
  phase walked past half a period reads the stamps as a stream missing samples).  A stream
  losing more than half its samples cannot be told from a slower one;
* **the measured rate** ``1/P`` is reported (``measured``) after every window of
  ``RATE_WINDOW_S`` of data (or ``MAX_WINDOW_SAMPLES``); the stream decides what it implies
  (:class:`~ipmc_sensor_ros.estimation.stream.StreamEstimator`).

Refused stamps (:meth:`Timebase.admit` codes): non-finite, outside ``[0, MAX_STAMP_S]``,
equal to the previous accepted one (``DUPLICATE``), behind it by at most ``max_gap_s``
(``BEHIND``: a late or repeated sample) or on the previous sample's slot (``TOO_CLOSE``).
A run ends (``START`` of a new one) at a gap longer than ``max_gap_s`` or a jump back by more
than ``max_gap_s`` (a bag loop, a restarted driver): the missing current is unknown.

The one rule for one stamp is :meth:`Timebase.admit`; :meth:`Timebase.admit_plain` is the
same rule for the leading samples of a block that it accepts without a refusal or a new run,
in numpy: the same expression (2) in the same operations, so the decisions are identical
whatever the cut of the stream into messages.
"""
from __future__ import annotations

import functools
import math

import numpy as np
from scipy.stats import norm, t as student_t

from ..errors import DataError

__all__ = ['Timebase', 'grid_slot', 'slots_of', 'fit_line', 'MAX_STAMP_S', 'JITTER_FRACTION',
           'RATE_WINDOW_S', 'FIRST_WINDOW_SAMPLES', 'RELOCK_MIN_SAMPLES', 'SIGNIFICANCE',
           'DRIFT_MARGIN', 'MAX_WINDOW_SAMPLES',
           'START', 'DUPLICATE', 'BEHIND', 'TOO_CLOSE', 'NON_FINITE', 'OUT_OF_RANGE',
           'REFUSAL_NAMES']

#: Largest representable stamp (``builtin_interfaces/Time.sec`` is int32), s.
MAX_STAMP_S = 2.0 ** 31 - 1.0

#: Stamp jitter accepted, as a fraction of the period (eq. 1): half of the half-period that
#: separates two slots, the other half left for the grid's own error.
JITTER_FRACTION = 0.25

#: The rate is measured from windows of this much data, s (0.5 s at 1 kHz: a slope known to
#: ~1e-4 with 25 % jitter, far below the 0.2 % at which the filter follows the rate).
RATE_WINDOW_S = 0.5

#: Longest window, samples: bounds the memory at high rates (a window is ``RATE_WINDOW_S`` of
#: data or this many samples, whichever is fewer); 8192 stamps with 25 % jitter give the
#: slope to ~1e-6, far inside what the rate rules need.
MAX_WINDOW_SAMPLES = 8192

#: First window of a run, samples: a stream 2 % off the nominal rate drifts 0.16 periods in
#: it, inside the jitter margin, and is then followed.
FIRST_WINDOW_SAMPLES = 8

#: Share of a period the grid may drift within one window for an uncertain period: of the
#: half period between slots, ``JITTER_FRACTION`` is the stamps' and the rest is shared
#: equally by the drift and the anchor's own error (0.125).
DRIFT_MARGIN = 0.5 * (0.5 - JITTER_FRACTION)

#: Fewest samples whose median spacing may re-lock the grid: the median of 31 spacings of a
#: stream with 25 % jitter exceeds 1.25 periods with a probability below 1e-5.
RELOCK_MIN_SAMPLES = 32

#: A fitted period replaces the grid's when they differ by more than this many standard
#: errors of the fit (stamp noise alone does so with a probability of 0.3 %).
SIGNIFICANCE = 3.0

#: :meth:`Timebase.admit` codes other than steps >= 1.
START, DUPLICATE, BEHIND, TOO_CLOSE, NON_FINITE, OUT_OF_RANGE = 0, -1, -2, -3, -4, -5

#: Refusal reason of each negative code (the stream's counter suffixes).
REFUSAL_NAMES = {DUPLICATE: 'duplicate_stamp', BEHIND: 'stamp_behind',
                 TOO_CLOSE: 'stamp_too_close', NON_FINITE: 'non_finite',
                 OUT_OF_RANGE: 'out_of_range'}


def slots_of(steps):
    """
    Return the slots of ``steps``: sample periods from the slot of the sample before.

    What the stream hands the filter is the slots plus the stamp's offset from its slot
    (``slot_offset``, in [-1/2, 1/2)), so the slots are the nearest integer (eq. 2's rule).
    """
    if isinstance(steps, (int, float)):
        return math.floor(steps + 0.5)
    return np.floor(np.asarray(steps, dtype=float) + 0.5).astype(np.int64)


def grid_slot(time_s, anchor_s: float, period_s: float, anchor_slot: int, floor=math.floor):
    """
    Return the grid slot of stamp(s) ``time_s``: eq. (2) of the module docstring.

    ``floor`` is :func:`math.floor` for a float, :func:`numpy.floor` for an array: the same
    operations in the same order, so both give the same slots.
    """
    return floor((time_s - anchor_s) / period_s + 0.5) + anchor_slot


def fit_line(slots: np.ndarray, times: np.ndarray, period_s: float):
    """
    Least-squares line ``t = t_c + slope (k - k_c)`` of stamps against slots.

    Points more than half a period off the first fit are dropped and the line refitted (a
    stamp on a wrong slot is a period off).  Returns ``(slope, slope_std, k_c, t_c, dof)``:
    the slope (s per slot), its standard error (inf with fewer than 3 points), the centroid of
    the points kept and the degrees of freedom the standard error is estimated from.
    """
    k = slots - slots[-1]
    t = times - times[-1]
    keep = np.ones(k.size, dtype=bool)
    for _ in range(2):
        kk, tt = k[keep], t[keep]
        kc, tc = kk.mean(), tt.mean()
        sxx = float(np.dot(kk - kc, kk - kc))
        slope = float(np.dot(kk - kc, tt - tc)) / sxx if sxx > 0.0 else period_s
        resid = t - (tc + slope * (k - kc))
        inliers = np.abs(resid) <= 0.5 * period_s
        if inliers.sum() < 3 or np.array_equal(inliers, keep):
            break
        keep = inliers
    m = int(keep.sum())
    r = resid[keep]
    std = math.sqrt(float(np.dot(r, r)) / (m - 2) / sxx) if m > 2 and sxx > 0.0 else math.inf
    return slope, std, float(kc) + float(slots[-1]), float(tc) + float(times[-1]), max(m - 2, 1)


@functools.lru_cache(maxsize=256)
def _quantile(dof: int) -> float:
    """
    Return the two-sided Student-t quantile of ``SIGNIFICANCE`` normal standard errors.

    The slope's standard error is estimated from the fit's own ``dof`` residuals: with the 6
    of a first window of 8 stamps, 3 estimated standard errors are exceeded 2.4 % of the
    time (a +-25 % jitter then took a period 5 % off and held it), not 0.3 %.
    """
    return float(student_t.isf(norm.sf(SIGNIFICANCE), dof))


def _refuted(spacing: float, period: float, stamps: np.ndarray) -> bool:
    """
    Tell whether the stamps' median ``spacing`` refutes a grid ``period`` within the jitter.

    A grid a few % off whose phase walked past half a period reads the stamps as a stream
    missing samples on a grid of its own (a first window's slope 5 % off under +-25 %
    jitter did so, for ever); the median spacing is the stream's period whatever is missing.
    Refuted when they differ by more than ``SIGNIFICANCE`` standard errors of the median
    (1.2533 sigma / sqrt(n) for n spacings of spread sigma, from their MAD).
    """
    d = np.diff(stamps)
    sigma = 1.4826 * float(np.median(np.abs(d - spacing)))
    return abs(spacing - period) > SIGNIFICANCE * 1.2533 * sigma / math.sqrt(d.size)


class Timebase:
    """
    Grid of one stream: slots, steps and the measured rate (module docstring).

    Parameters
    ----------
    period_s : float
        Nominal sample period, s (the grid's period until one is measured).
    max_gap_s : float
        Longest gap (or jump back) within one run, s.

    """

    def __init__(self, period_s: float, max_gap_s: float):
        self.period_s = float(period_s)
        self.max_gap_s = float(max_gap_s)
        self.last_s: float | None = None       # stamp of the last accepted sample
        self.last_slot = 0
        #: the last accepted stamp's offset from its slot, periods (eq. 2: in [-1/2, 1/2));
        #: of the samples :meth:`admit_plain` accepted, ``plain_offsets``
        self.slot_offset = 0.0
        self.plain_offsets = np.zeros(0)
        self.anchor_s = 0.0
        self.anchor_slot = 0
        self.measured: float | None = None     # period of the last full rate window, s
        self.fresh = False                     # a rate window just completed
        self.relocks = 0
        #: slots and gaps counted under a grid a re-lock found wrong (the stream takes them
        #: off its counts: a 500 Hz stream read on a 1 kHz grid lost no samples)
        self.recounted = (0, 0)
        self.break_kind = ''                   # why the last run started: '', 'gap', 'back'
        self.break_s = 0.0                     # and the size of that gap or jump, s
        self._win_t: list[float] = []
        self._win_k: list[int] = []
        self._close: list[float] = []
        self._due = 0

    def forget(self) -> None:
        """Start afresh at the next stamp (the period found so far is kept)."""
        self.last_s = None

    # -- the rule for one stamp -----------------------------------------------------
    def block_times(self, times, n: int, now_s) -> np.ndarray:
        """Return a block's sample times (None: continued on the grid, or from ``now_s()``)."""
        if times is None:
            start = now_s() if self.last_s is None else self.last_s + self.period_s
            return start + np.arange(n) * self.period_s
        t = np.asarray(times, dtype=float)
        if t.shape != (n,):
            raise DataError(f'{t.size} sample times for {n} samples')
        return t

    def admit(self, t: float) -> int:
        """
        Decide stamp ``t`` (s): steps >= 1 (accepted), ``START`` (accepted, first of a run).

        or a negative refusal code (:data:`REFUSAL_NAMES`); the grid follows accepted stamps.
        """
        last = self.last_s
        if last is not None and 0.0 < t - last <= self.max_gap_s and t <= MAX_STAMP_S:
            slot = grid_slot(t, self.anchor_s, self.period_s, self.anchor_slot)
            steps = slot - self.last_slot
            if steps < 1:
                if len(self._close) <= len(self._win_t) + self._due:   # bounded by the window
                    self._close.append(t)
                return TOO_CLOSE
            self.last_s = t
            self.last_slot = slot
            self.slot_offset = (t - self.anchor_s) / self.period_s - (slot - self.anchor_slot)
            self._win_t.append(t)
            self._win_k.append(slot)
            self._due -= 1
            if not self._due:
                self._measure()
            return steps
        if not 0.0 <= t <= MAX_STAMP_S:
            return NON_FINITE if not math.isfinite(t) else OUT_OF_RANGE
        if last is None:
            return self._start(t, '', 0.0)
        if t == last:
            return DUPLICATE
        if t < last:
            return BEHIND if last - t <= self.max_gap_s else self._start(t, 'back', last - t)
        return self._start(t, 'gap', t - last)

    def admit_plain(self, times: np.ndarray, start: int, stop: int) -> np.ndarray:
        """
        :meth:`admit` for ``times[start:stop]`` as long as it accepts without a new run.

        Returns the steps of the leading samples that :meth:`admit` would accept one by one
        with steps >= 1 (possibly none; at most up to the end of the current window), with the
        grid advanced as it would be.
        """
        m = min(stop - start, self._due)
        if self.last_s is None or m <= 0:
            return np.zeros(0, dtype=np.int64)
        t = times[start:start + m]
        d = np.diff(t, prepend=self.last_s)
        slots = grid_slot(t, self.anchor_s, self.period_s, self.anchor_slot, np.floor)
        steps = np.diff(slots, prepend=self.last_slot)
        ok = (t >= 0.0) & (t <= MAX_STAMP_S) & (d > 0.0) & (d <= self.max_gap_s) & (steps >= 1)
        j = m if ok.all() else int(np.argmin(ok))
        if j == 0:
            return np.zeros(0, dtype=np.int64)
        self.plain_offsets = ((t[:j] - self.anchor_s) / self.period_s
                              - (slots[:j] - self.anchor_slot))
        self.last_s = float(t[j - 1])
        self.last_slot = int(slots[j - 1])
        self._win_t.extend(t[:j].tolist())
        self._win_k.extend(slots[:j].astype(np.int64).tolist())
        self._due -= j
        if not self._due:
            self._measure()
        return steps[:j].astype(np.int64)

    # -- grid updates -----------------------------------------------------------------
    def _start(self, t: float, kind: str, size_s: float) -> int:
        """Begin a run at stamp ``t``: slot 0, the grid anchored there."""
        self.last_s = self.anchor_s = t
        self.last_slot = self.anchor_slot = 0
        self.slot_offset = 0.0
        self.break_kind, self.break_s = kind, size_s
        self._win_t, self._win_k, self._close = [t], [0], []
        self._due = FIRST_WINDOW_SAMPLES - 1       # accepted samples until the window ends
        return START

    def _measure(self) -> None:
        """Refit phase and period at the end of a window (module docstring)."""
        t = np.array(self._win_t)
        k = np.array(self._win_k, dtype=float)
        period = self.period_s
        relock = False
        # a grid off by more than the jitter margin shows as gaps (a slower stream) or as
        # stamps between slots (a faster one); without either there is nothing to re-lock
        suspect = self._close or k[-1] - k[0] > t.size - 1
        if suspect and t.size >= RELOCK_MIN_SAMPLES:
            stamps = np.sort(np.concatenate([t, self._close])) if self._close else t
            spacing = float(np.median(np.diff(stamps)))
            # a grid at the median spacing must explain the stamps with at most every other
            # slot empty (a burst of stamps within one slot is no faster stream)
            regular = 0.0 < stamps[-1] - stamps[0] <= 2.0 * spacing * (stamps.size - 1)
            if regular and (abs(spacing / period - 1.0) > JITTER_FRACTION
                            or _refuted(spacing, period, stamps)):
                relock, period = True, spacing
                k = np.concatenate([[0.0], np.cumsum(np.maximum(
                    np.floor(np.diff(t) / spacing + 0.5), 1.0))])
                k += self.last_slot - k[-1]
                was, now = np.diff(self._win_k), np.diff(k)
                # the slots the old grid counted lost; a faster stream's new empty slots are
                # its refused samples' (counted as refused): nothing is added
                lost = max(int(np.sum(was - now)), 0)
                gaps = max(int(np.sum(was > 1) - np.sum(now > 1)), 0)
                self.recounted = (self.recounted[0] + lost, self.recounted[1] + gaps)
                self._win_k = k.astype(np.int64).tolist()
                self.relocks += 1
        slope, std, kc, tc, dof = fit_line(k, t, period)
        if relock or abs(slope - period) > _quantile(dof) * std:
            period = slope
        self.period_s = period
        self.anchor_s = tc + slope * (k[-1] - kc)       # the fitted line at the last slot
        self.anchor_slot = self.last_slot
        n = t.size
        full = min(math.ceil(RATE_WINDOW_S / period - 1e-9), MAX_WINDOW_SAMPLES)
        if n >= full:                                   # a rate window: measured, restarted
            self.measured = period
            self.fresh = True
            self._win_t, self._win_k, self._close, n = [], [], [], 0
        # the next window ends before the period's uncertainty can move the grid by
        # DRIFT_MARGIN; until a full window, the fit takes every sample of the run
        room = DRIFT_MARGIN * period / (_quantile(dof) * std) if std > 0.0 else math.inf
        self._due = int(min(max(room, FIRST_WINDOW_SAMPLES), full - n))
