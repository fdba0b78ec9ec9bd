# SPDX-License-Identifier: Apache-2.0
"""
Tip motions of the scenario library: callables ``w(t)`` (m) defined for every time (s).

A motion is defined before the record too (the current generator evaluates it over a
pre-roll), so "moving since power-on" is a motion that has always been going and "from rest"
one that is zero before it starts.  Everything is smooth enough for an exact FFT: moves are
minimum-jerk (continuous acceleration), speeds ramp up smoothly.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ['min_jerk', 'MinJerkPath', 'Sines', 'Windowed', 'Crank', 'FreeVibration', 'Sum']


def min_jerk(x: np.ndarray) -> np.ndarray:
    """10 x^3 - 15 x^4 + 6 x^5 on [0, 1], 0 before, 1 after (the minimum-jerk move)."""
    x = np.clip(x, 0.0, 1.0)
    return x ** 3 * (10.0 + x * (-15.0 + 6.0 * x))


@dataclass(frozen=True)
class MinJerkPath:
    """
    Holds joined by minimum-jerk moves.

    Move k goes from ``levels[k]`` to ``levels[k + 1]`` (m) between ``starts_s[k]`` and
    ``starts_s[k] + durations_s[k]``; before the first move the tip is at ``levels[0]``.
    Moves may not overlap.
    """

    starts_s: tuple
    durations_s: tuple
    levels: tuple

    def __post_init__(self):
        s, d = np.asarray(self.starts_s), np.asarray(self.durations_s)
        if len(self.levels) != s.size + 1 or d.size != s.size:
            raise ValueError('MinJerkPath: need len(levels) == len(starts_s) + 1 == '
                             'len(durations_s) + 1')
        if s.size > 1 and np.any(s[1:] < s[:-1] + d[:-1]):
            raise ValueError('MinJerkPath: moves overlap')

    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        levels = np.asarray(self.levels, dtype=float)
        starts = np.asarray(self.starts_s, dtype=float)
        if starts.size == 0:
            return np.full(t.shape, levels[0])
        k = np.searchsorted(starts, t, side='right') - 1       # last move started at t
        kk = np.maximum(k, 0)
        x = (t - starts[kk]) / np.asarray(self.durations_s, dtype=float)[kk]
        step = levels[kk + 1] - levels[kk]
        return np.where(k < 0, levels[0], levels[kk] + step * min_jerk(x))


@dataclass(frozen=True)
class Sines:
    """Sum of sines a_k sin(2 pi f_k t + phi_k), m: always moving, zero mean."""

    frequencies_hz: tuple
    amplitudes_m: tuple
    phases_rad: tuple

    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        out = np.zeros(t.shape)
        for f, a, p in zip(self.frequencies_hz, self.amplitudes_m, self.phases_rad):
            out += a * np.sin(2.0 * math.pi * f * t + p)
        return out


@dataclass(frozen=True)
class Windowed:
    """``motion`` faded in over [start_s, start_s + ramp_s], out over [stop_s - ramp_s, stop_s]."""

    motion: object
    start_s: float
    stop_s: float
    ramp_s: float

    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        out = np.zeros(t.shape)
        inside = (t > self.start_s) & (t < self.stop_s)
        ti = t[inside]
        gain = (min_jerk((ti - self.start_s) / self.ramp_s)
                * min_jerk((self.stop_s - ti) / self.ramp_s))
        out[inside] = gain * self.motion(ti)
        return out


@dataclass(frozen=True)
class Crank:
    """
    The paper's crank-slider rig (section 5.1, Fig. 3): the tip follows the slider.

    Slider position x(theta) = r cos(theta) + sqrt(l^2 - r^2 sin^2(theta)) for crank radius r
    and rod length l; the motor turns at ``frequency_hz`` with a slow speed wobble of relative
    size ``wobble`` at ``wobble_hz`` (a DC motor is not a clock).  ``start_s`` None: turning
    since before power-on, w = x - (cycle mean of x), zero mean; else at rest until
    ``start_s``, spun up smoothly (speed 3 s^2 - 2 s^3 of its final value over ``spinup_s``)
    and w = x - x(theta at rest), zero before the start.  ``stop_s``: the motor stops there,
    smoothly (speed 1 - 3 s^2 + 2 s^3 of its nominal value over ``stop_duration_s``), and the
    tip holds where the crank stopped.
    """

    frequency_hz: float
    crank_radius_m: float
    rod_length_m: float
    phase_rad: float = 0.0
    start_s: float | None = None
    spinup_s: float = 0.5
    wobble: float = 0.0
    wobble_hz: float = 0.2
    stop_s: float | None = None
    stop_duration_s: float = 0.3

    def _x(self, theta):
        r, rod = self.crank_radius_m, self.rod_length_m
        return r * np.cos(theta) + np.sqrt(rod ** 2 - (r * np.sin(theta)) ** 2)

    def _angle(self, t):
        if self.stop_s is None:
            return self._turning(t)
        s = np.clip((t - self.stop_s) / self.stop_duration_s, 0.0, 1.0)
        coast = 2.0 * math.pi * self.frequency_hz * self.stop_duration_s
        return self._turning(np.minimum(t, self.stop_s)) + coast * (s - s ** 3 + s ** 4 / 2.0)

    def _turning(self, t):
        omega = 2.0 * math.pi * self.frequency_hz
        wm = 2.0 * math.pi * self.wobble_hz
        if self.start_s is None:
            tau = t
            theta = self.phase_rad + omega * t
        else:
            s = np.clip((t - self.start_s) / self.spinup_s, 0.0, 1.0)
            tau = np.maximum(t - self.start_s - self.spinup_s, 0.0)
            theta = self.phase_rad + omega * self.spinup_s * (s ** 3 - s ** 4 / 2.0) + omega * tau
        return theta + omega * self.wobble * (1.0 - np.cos(wm * tau)) / wm

    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        if self.start_s is None:
            ref = float(np.mean(self._x(np.linspace(0.0, 2 * math.pi, 4096, endpoint=False))))
        else:
            ref = float(self._x(self.phase_rad))
        return self._x(self._angle(t)) - ref


@dataclass(frozen=True)
class FreeVibration:
    """
    Pushed from rest to ``amplitude_m``, held, released: a decaying oscillation.

    Minimum-jerk push over [push_start_s, push_start_s + push_s]; after ``release_s`` the
    free response of a damped oscillator released at rest, A e^(-zeta wn tau) (cos wd tau +
    zeta / sqrt(1 - zeta^2) sin wd tau), wd = 2 pi ``frequency_hz``.
    """

    amplitude_m: float
    frequency_hz: float
    damping_ratio: float
    push_start_s: float
    push_s: float
    release_s: float

    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        a, z = self.amplitude_m, self.damping_ratio
        wd = 2.0 * math.pi * self.frequency_hz
        wn = wd / math.sqrt(1.0 - z * z)
        tau = np.maximum(t - self.release_s, 0.0)
        free = a * np.exp(-z * wn * tau) * (np.cos(wd * tau)
                                            + z / math.sqrt(1.0 - z * z) * np.sin(wd * tau))
        held = a * min_jerk((t - self.push_start_s) / self.push_s)
        return np.where(t < self.release_s, held, free)


@dataclass(frozen=True)
class Sum:
    """Sum of motions."""

    parts: tuple

    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        out = np.zeros(t.shape)
        for p in self.parts:
            out += p(t)
        return out
