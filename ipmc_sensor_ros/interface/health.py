# SPDX-License-Identifier: Apache-2.0
"""
Health of a node and of its channels, without ROS.

:class:`HealthMonitor` turns the counters and state a node already keeps
(``samples_in``, ``messages_rejected``, ``resets``, ``gaps``, ...) into one
:class:`Health` per evaluation: a level (``OK``, ``WARN``, ``ERROR``, the
numbering of ``diagnostic_msgs/DiagnosticStatus``), a one-line message naming
every problem, and key/value pairs for the ROS tools (rqt_robot_monitor,
diagnostic_aggregator).  The ROS publisher is
:class:`ipmc_sensor_ros.nodes.diagnostics.DiagnosticsPublisher`.

Rules (evaluated on the change of the counters since the previous evaluation; the first
evaluation's period runs from the start, so nothing counted before it goes unreported):

* ERROR: no new sample for ``stale_after_s`` (or none at all since start); an estimate
  beyond what the geometry allows (``samples_beyond_limit`` rose:
  :mod:`ipmc_sensor_ros.estimation.limits`);
* WARN: filter resets, time gaps longer than ``max_gap_s``, samples dropped, malformed or
  oversized messages, a switch of the followed publisher, messages of other publishers
  ignored (named), messages the middleware reports lost;
* WARN: more than ``loss_warn_fraction`` of the samples of the period lost before the node
  (grid slots without a sample in the stamps, bridged gaps included, and messages of the
  followed publisher that never arrived, from its sequence numbers) or refused by the stream
  rules (duplicate or late stamps, non-finite values, ...; the count per reason is named);
* WARN: measured sample rate off ``sample_rate_hz`` by more than ``rate_tolerance``
  (relative): the rate the stream measured from the stamps (``measured_rate_hz`` in the
  status) where there is one, else the samples per second of steady clock over intervals of
  >= 1 s with data;
* WARN: the estimated current offset above ``offset_warn_a``; a mains line
  (``line_frequencies_hz``) above ``line_warn_fraction`` of the current's RMS.

:class:`CurrentStatistics` estimates the offset and the mains line from the
current the node receives: the offset is the mean current over the last
``offset_window_s``.  The short-circuit current of a bent IPMC is the rate of
the charge moved through the electrodes (paper eq. 45/55: H(s) has a zero at
s = 0), the charge is bounded, so its mean over T tends to zero as Q/T: what
stays is the DAQ offset, as long as T is much longer than the motion (a hold
of T or more makes the mean the charge step over T, and is reported as an
offset: the warning names the window).  The mains line is the amplitude at
50 and 60 Hz of the last second of current (a windowed DFT bin); a
mechanical stimulus at exactly the line frequency is indistinguishable from
hum in one window and is reported as well.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from .specs import DIAGNOSTICS_SPECS

__all__ = ['OK', 'WARN', 'ERROR', 'LEVEL_NAMES', 'Health', 'HealthLimits', 'HealthMonitor',
           'CurrentStatistics', 'DIAGNOSTICS_SPECS', 'limits_from_values', 'worst']

OK, WARN, ERROR = 0, 1, 2
LEVEL_NAMES = {OK: 'OK', WARN: 'WARN', ERROR: 'ERROR'}


@dataclass(frozen=True)
class HealthLimits:
    """Thresholds of :class:`HealthMonitor` (see the module docstring; SI units)."""

    stale_after_s: float = 2.0
    rate_tolerance: float = 0.05
    offset_warn_a: float = 100e-9
    offset_window_s: float = 10.0
    line_warn_fraction: float = 0.05
    line_frequencies_hz: tuple[float, ...] = (50.0, 60.0)
    loss_warn_fraction: float = 0.01


def limits_from_values(values: Mapping[str, Any]) -> HealthLimits:
    """:class:`HealthLimits` from parameter values (names of :data:`DIAGNOSTICS_SPECS`)."""
    kw = {name: float(values[name]) for name in ('stale_after_s', 'rate_tolerance',
                                                 'offset_warn_a', 'offset_window_s',
                                                 'line_warn_fraction', 'loss_warn_fraction')
          if name in values}
    return HealthLimits(**kw)


@dataclass
class Health:
    """Result of one evaluation: level, one-line message, key/value pairs (strings)."""

    level: int
    message: str
    values: dict[str, str] = field(default_factory=dict)

    @property
    def level_name(self) -> str:
        return LEVEL_NAMES[self.level]


def worst(items: Sequence[Health], message_ok: str = 'all channels OK') -> Health:
    """Aggregate health of a node: the highest level, messages of the non-OK items."""
    if not items:
        return Health(OK, message_ok)
    level = max(h.level for h in items)
    bad = [h.message for h in items if h.level > OK]
    return Health(level, '; '.join(bad) if bad else message_ok)


class CurrentStatistics:
    """
    Running estimates of a current's offset and mains line (module docstring).

    Parameters
    ----------
    sample_rate_hz : sample rate of the current, Hz.
    offset_window_s : averaging window of the offset (a first-order mean with
        this time constant), s.
    line_frequencies_hz : mains frequencies looked at, Hz.

    """

    def __init__(self, sample_rate_hz: float, offset_window_s: float = 10.0,
                 line_frequencies_hz: Sequence[float] = (50.0, 60.0)):
        self.sample_rate_hz = float(sample_rate_hz)
        self.offset_window_s = float(offset_window_s)
        self.line_frequencies_hz = tuple(f for f in line_frequencies_hz
                                         if f < 0.5 * self.sample_rate_hz)
        n = int(min(max(round(self.sample_rate_hz), 8), 1 << 16))  # last second (capped)
        self._ring = np.zeros(n)
        self._end = 0
        self._n = 0
        self._alpha = min(1.0, 1.0 / (self.offset_window_s * self.sample_rate_hz))
        self._mean = 0.0
        self._count = 0

    def observe_one(self, current_a: float) -> None:
        """Feed one sample (A): :meth:`observe` without numpy (the one-sample message path)."""
        x = float(current_a)
        if self._count + 1 <= self.offset_window_s * self.sample_rate_hz:
            self._mean += (x - self._mean) / (self._count + 1)
        else:
            self._mean += self._alpha * (x - self._mean)
        self._count += 1
        self._ring[self._end] = x
        self._end = (self._end + 1) % self._ring.size
        if self._n < self._ring.size:
            self._n += 1

    def observe(self, current_a) -> None:
        """Feed new samples (A), oldest first."""
        x = np.asarray(current_a, dtype=float).ravel()
        m = x.size
        if m == 0:
            return
        # mean: plain average until the window is full, then exponential (time constant
        # offset_window_s); closed form of m steps of y += a (x - y).
        full = self.offset_window_s * self.sample_rate_hz
        if self._count + m <= full:
            self._mean += (x.sum() - m * self._mean) / (self._count + m)
        else:
            a = self._alpha
            weights = a * (1.0 - a) ** np.arange(m - 1, -1, -1)
            self._mean = self._mean * (1.0 - a) ** m + float(weights @ x)
        self._count += m
        n = self._ring.size
        if m >= n:
            self._ring[:] = x[-n:]
            self._end = 0
        else:
            first = min(m, n - self._end)
            self._ring[self._end:self._end + first] = x[:first]
            self._ring[:m - first] = x[first:]
            self._end = (self._end + m) % n
        self._n = min(n, self._n + m)

    @property
    def samples(self) -> int:
        return self._count

    def offset_a(self) -> float | None:
        """Mean current over the offset window (A), None before any sample."""
        return self._mean if self._count else None

    def window_filled(self) -> bool:
        """Return True once ``offset_window_s`` of current has been seen."""
        return self._count >= self.offset_window_s * self.sample_rate_hz

    def line(self) -> tuple[float, float, float, float] | None:
        """
        Return the strongest mains line in the last second.

        As (frequency Hz, amplitude A, RMS of the AC current A, local noise floor A); None
        with less than 0.2 s of data.

        Amplitudes are read off a Hann-windowed spectrum (``2 |X| / sum(w)``, exact for
        a tone on a bin); the noise floor is the median amplitude of the bins 3-10 Hz
        either side of the line (a motion harmonic or noise, not the line itself).
        """
        x = np.roll(self._ring, -self._end)[self._ring.size - self._n:]
        if x.size < 0.2 * self.sample_rate_hz or not self.line_frequencies_hz:
            return None
        x = x - x.mean()
        rms = float(np.sqrt(np.mean(x * x)))
        w = np.hanning(x.size)
        spectrum = 2.0 * np.abs(np.fft.rfft(w * x)) / w.sum()
        freqs = np.fft.rfftfreq(x.size, 1.0 / self.sample_rate_hz)
        best = None
        for f in self.line_frequencies_hz:
            near = np.abs(freqs - f)
            amp = float(spectrum[np.argmin(near)])
            side = spectrum[(near >= 3.0) & (near <= 10.0)]
            floor = float(np.median(side)) if side.size else 0.0
            if best is None or amp > best[1]:
                best = (f, amp, rms, floor)
        return best


class HealthMonitor:
    """
    Health of one channel from its counters (see the module docstring).

    Parameters
    ----------
    sample_rate_hz : expected sample rate, Hz, or None (no rate check).
    limits : thresholds.
    samples_key : counter that counts data (``samples_in`` for a consumer,
        ``samples_published`` for a source).

    """

    WARN_COUNTERS = (('resets', 'filter reset(s)'),
                     ('gaps', 'time gap(s) longer than max_gap_s'),
                     ('samples_dropped', 'sample(s) dropped'),
                     ('rejected_malformed', 'sample(s) in malformed message(s) rejected'),
                     ('rejected_too_long', 'sample(s) in message(s) over max_block_samples '
                                           'rejected'),
                     ('source_switches', 'switch(es) to another publisher'),
                     ('offset_jumps', 'jump(s) of the current offset taken (an amplifier '
                                      're-zeroed or its range switched?)'),
                     ('messages_lost_reported', 'message(s) reported lost by the middleware'))

    def __init__(self, sample_rate_hz: float | None, limits: HealthLimits = HealthLimits(),
                 samples_key: str = 'samples_in'):
        self.sample_rate_hz = None if sample_rate_hz is None else float(sample_rate_hz)
        self.limits = limits
        self.samples_key = samples_key
        self._start_s: float | None = None
        self._prev: dict[str, Any] | None = None
        self._prev_s: float | None = None
        self._last_data_s: float | None = None

    def evaluate(self, status: Mapping[str, Any], now_s: float,
                 statistics: CurrentStatistics | None = None) -> Health:
        """
        Health at steady-clock time ``now_s`` (s) from ``status``.

        Counters (ints), optionally ``done`` (bool, a finished source),
        ``estimated_offset_a`` (A) and any other scalar state, all copied to the
        key/values.
        """
        lim = self.limits
        if self._start_s is None:
            self._start_s = now_s
        prev = self._prev or {}
        delta = {k: int(v) - int(prev.get(k, 0)) for k, v in status.items()
                 if isinstance(v, (int, np.integer)) and not isinstance(v, bool)}
        dt = None if self._prev_s is None else now_s - self._prev_s
        new = delta.get(self.samples_key, 0)
        if new > 0:
            self._last_data_s = now_s
        values = {k: _text(v) for k, v in status.items()}
        errors, warnings = [], []

        done = bool(status.get('done', False))
        since = now_s - (self._last_data_s if self._last_data_s is not None else self._start_s)
        values['seconds_since_data'] = f'{since:.3f}'
        if not done and since > lim.stale_after_s:
            errors.append('no data for ' + (f'{since:.1f} s' if self._last_data_s is not None
                                            else f'{since:.1f} s since start')
                          + f' (stale_after_s {lim.stale_after_s:g})')
        beyond = delta.get('samples_beyond_limit', 0)
        if beyond > 0:
            errors.append(f'{beyond} estimate(s) beyond the geometric limit |w| > '
                          f"{_text(status.get('deflection_limit_m'))} m: not physically "
                          'possible (offset drift, wrong model or geometry?)')
        for key, text in self.WARN_COUNTERS:
            if delta.get(key, 0) > 0:
                warnings.append(f'{delta[key]} {text}')
        warnings += _fraction_warnings(delta, status, lim.loss_warn_fraction)
        warnings += self._rate_warnings(status, values, dt, new, done, prev)
        offset = status.get('estimated_offset_a')
        if statistics is not None:
            if offset is None and statistics.window_filled():
                offset = statistics.offset_a()
            line = statistics.line()
            if line is not None:
                f, amp, rms, floor = line
                values['line_frequency_hz'] = f'{f:g}'
                values['line_amplitude_a'] = f'{amp:.4g}'
                values['current_rms_a'] = f'{rms:.4g}'
                # a line stands out of its neighbourhood (4x the median of nearby bins:
                # white noise alone exceeds it with probability ~exp(-4^2 pi/4)) and is a
                # sizeable part of the current
                if amp > lim.line_warn_fraction * rms and amp > 4.0 * floor:
                    warnings.append(f'mains line at {f:g} Hz: {amp:.3g} A '
                                    f'({100.0 * amp / rms:.0f} % of the current RMS)')
        if offset is not None:
            values['estimated_offset_a'] = f'{offset:.4g}'
            if abs(offset) > lim.offset_warn_a:
                warnings.append(f'estimated current offset {offset:.3g} A over the last '
                                f'{lim.offset_window_s:g} s (offset_warn_a {lim.offset_warn_a:g})')

        self._prev = {k: v for k, v in status.items()
                      if isinstance(v, (int, np.integer)) and not isinstance(v, bool)}
        self._prev_s = now_s
        if errors:
            return Health(ERROR, '; '.join(errors + warnings), values)
        if warnings:
            return Health(WARN, '; '.join(warnings), values)
        return Health(OK, 'done' if done else 'OK', values)

    def _rate_warnings(self, status, values, dt, new, done, prev) -> list[str]:
        """Return the rate warning: the stream's measured rate, else samples per second."""
        expected, tol = self.sample_rate_hz, self.limits.rate_tolerance
        if not expected or done:
            return []
        rate = status.get('measured_rate_hz')
        if rate is not None:
            what = 'measured from the stamps'
        elif dt is not None and dt >= 0.999 and new > 0 and prev.get(self.samples_key, 0) > 0:
            rate, what = new / dt, 'received per second'
            values['measured_rate_hz'] = f'{rate:.6g}'
        else:
            return []
        if abs(rate / expected - 1.0) <= tol:
            return []
        return [f'sample rate {rate:.4g} Hz ({what}), expected {expected:g} Hz '
                f'(rate_tolerance {tol:g})']


def _fraction_warnings(delta: Mapping[str, int], status: Mapping[str, Any],
                       limit: float) -> list[str]:
    """Return the warnings of samples lost, refused or ignored over the period (module doc)."""
    out = []
    n_in, lost = delta.get('samples_in', 0), delta.get('samples_lost', 0)
    m_in, m_lost = delta.get('messages_in', 0), delta.get('messages_lost', 0)
    frac = max(lost / (n_in + lost) if lost else 0.0, m_lost / (m_in + m_lost) if m_lost else 0.0)
    if frac > limit:
        out.append(f'{100.0 * frac:.3g} % of the data lost before the node ({lost} sample '
                   f'slot(s) without a sample, {m_lost} message(s) that never arrived; '
                   f'loss_warn_fraction {limit:g})')
    refused = delta.get('samples_rejected', 0)
    if n_in and refused / n_in > limit:
        why = ', '.join(f'{k[len("rejected_"):]} {v}' for k, v in delta.items()
                        if k.startswith('rejected_') and v > 0)
        out.append(f'{100.0 * refused / n_in:.3g} % of the samples refused ({why}; '
                   f'loss_warn_fraction {limit:g})')
    ignored = delta.get('messages_ignored', 0)
    if ignored > 0:
        out.append(f'{ignored} message(s) of other publishers ignored '
                   f"({status.get('ignored_publishers') or 'unnamed'}): one source per stream, "
                   f"following {status.get('followed_publisher') or 'the first heard'}")
    return out


def _text(value: Any) -> str:
    if isinstance(value, float):
        return f'{value:.6g}'
    if isinstance(value, bool):
        return 'true' if value else 'false'
    return str(value)
