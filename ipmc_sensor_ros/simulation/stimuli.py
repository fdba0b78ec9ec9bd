# SPDX-License-Identifier: Apache-2.0
"""
Tip-deflection stimuli w(t) (m) with their exact velocities dw/dt (m/s).

The sensor responds to the *rate* of deformation (H(s) = s R(s), eq. 31), so
every stimulus provides its analytic velocity; the simulator feeds the
velocity to the proper charge model R(s) and never differentiates samples.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..physics.parameters import ParameterError

__all__ = ['Stimulus', 'CrankSlider', 'Sweep', 'FreeVibration', 'Step', 'RobotMotion', 'Sampled',
           'make_stimulus', 'STIMULUS_KINDS']


def _pos(name, value, allow_zero=False):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterError(
            f"stimulus parameter '{name}' must be a number, got {value!r}"
        ) from None
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise ParameterError(
            f"stimulus parameter '{name}' must be {'>= 0' if allow_zero else '> 0'}, "
            f'got {value!r}'
        )
    return v


class Stimulus:
    """Base class: ``deflection(t)`` in m and ``velocity(t)`` in m/s, vectorised."""

    def deflection(self, t) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError

    def velocity(self, t) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError


@dataclass(frozen=True)
class CrankSlider(Stimulus):
    """
    The paper's set-up (section 5.1, Fig. 3).

    a motor-driven crank of radius r and a connecting rod of length l push
    the slider that holds the IPMC tip.

    Slider position x(theta) = r cos(theta) + sqrt(l^2 - r^2 sin^2 theta),
    theta = 2 pi f t + phase.  The IPMC is mounted with its rest position at the
    mean slider position, so the tip deflection is x - <x>, with
    <x> = (2/pi) l E((r/l)^2) (complete elliptic integral of the second kind):
    zero-mean, peak-to-peak 2 r, with even harmonics of relative size ~ r/(4 l).
    """

    motor_frequency_hz: float = 1.0
    crank_radius_m: float = 2e-3
    rod_length_m: float = 20e-3
    phase_rad: float = 0.0

    def __post_init__(self):
        _pos('motor_frequency_hz', self.motor_frequency_hz)
        _pos('crank_radius_m', self.crank_radius_m)
        _pos('rod_length_m', self.rod_length_m)
        if self.rod_length_m <= self.crank_radius_m:
            raise ParameterError(
                f"stimulus parameter 'rod_length_m' ({self.rod_length_m}) must exceed "
                f"'crank_radius_m' ({self.crank_radius_m})"
            )

    def _theta(self, t):
        return 2 * np.pi * self.motor_frequency_hz * np.asarray(t, dtype=float) + self.phase_rad

    def deflection(self, t):
        th = self._theta(t)
        r, rod = self.crank_radius_m, self.rod_length_m
        return r * np.cos(th) + np.sqrt(rod * rod - (r * np.sin(th)) ** 2) - self.mean_position_m

    @property
    def mean_position_m(self) -> float:
        """Cycle average of the slider position sqrt(l^2 - r^2 sin^2) term, m."""
        from scipy.special import ellipe

        r, rod = self.crank_radius_m, self.rod_length_m
        return 2.0 / np.pi * rod * float(ellipe((r / rod) ** 2))

    def velocity(self, t):
        th = self._theta(t)
        r, rod = self.crank_radius_m, self.rod_length_m
        root = np.sqrt(rod * rod - (r * np.sin(th)) ** 2)
        omega = 2 * np.pi * self.motor_frequency_hz
        return omega * (-r * np.sin(th) - r * r * np.sin(th) * np.cos(th) / root)


@dataclass(frozen=True)
class Sweep(Stimulus):
    """
    Logarithmic sine sweep of amplitude A from f0 to f1 over ``duration_s``.

    Then repeated (period = duration).
    """

    amplitude_m: float = 1e-3
    start_frequency_hz: float = 0.5
    stop_frequency_hz: float = 50.0
    duration_s: float = 20.0

    def __post_init__(self):
        for k in ('amplitude_m', 'start_frequency_hz', 'stop_frequency_hz', 'duration_s'):
            _pos(k, getattr(self, k))

    def _phase(self, t):
        tt = np.mod(np.asarray(t, dtype=float), self.duration_s)
        f0, f1, T = self.start_frequency_hz, self.stop_frequency_hz, self.duration_s
        if f1 == f0:
            return 2 * np.pi * f0 * tt, 2 * np.pi * f0 * np.ones_like(tt)
        k = math.log(f1 / f0) / T
        return 2 * np.pi * f0 * np.expm1(k * tt) / k, 2 * np.pi * f0 * np.exp(k * tt)

    def deflection(self, t):
        return self.amplitude_m * np.sin(self._phase(t)[0])

    def velocity(self, t):
        ph, dph = self._phase(t)
        return self.amplitude_m * np.cos(ph) * dph


def _smoothstep(u):
    """Raised-cosine ramp 0 -> 1 on u in [0, 1] and its derivative d/du."""
    u = np.clip(u, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * u), 0.5 * np.pi * np.sin(np.pi * u)


@dataclass(frozen=True)
class Step(Stimulus):
    """
    Tip pushed to ``amplitude_m`` at ``start_s``, then held (paper Fig. 8).

    The rise is a raised cosine of ``rise_time_s`` (a real actuator has finite speed).
    """

    amplitude_m: float = 2e-3
    start_s: float = 0.5
    rise_time_s: float = 0.02

    def __post_init__(self):
        _pos('start_s', self.start_s, allow_zero=True)
        _pos('rise_time_s', self.rise_time_s)

    def deflection(self, t):
        return (
            self.amplitude_m
            * _smoothstep((np.asarray(t, float) - self.start_s) / self.rise_time_s)[0]
        )

    def velocity(self, t):
        u = (np.asarray(t, float) - self.start_s) / self.rise_time_s
        inside = (u > 0) & (u < 1)
        return np.where(inside, self.amplitude_m * _smoothstep(u)[1] / self.rise_time_s, 0.0)


@dataclass(frozen=True)
class FreeVibration(Stimulus):
    """
    Tip pulled to ``amplitude_m`` and released (paper Fig. 7, natural frequency about 30 Hz).

    The pull is a raised-cosine ramp of ``ramp_s`` ending at ``release_s``; after it
    w = A e^{-zeta wn tau} (cos wd tau + zeta wn/wd sin wd tau), tau = t - release_s.
    """

    amplitude_m: float = 2e-3
    natural_frequency_hz: float = 30.0
    damping_ratio: float = 0.05
    release_s: float = 0.5
    ramp_s: float = 0.3

    def __post_init__(self):
        _pos('natural_frequency_hz', self.natural_frequency_hz)
        _pos('release_s', self.release_s)
        _pos('ramp_s', self.ramp_s)
        if not 0.0 <= float(self.damping_ratio) < 1.0:
            raise ParameterError(f"stimulus parameter 'damping_ratio' must be in [0, 1), "
                                 f'got {self.damping_ratio!r}')

    def _parts(self, t):
        t = np.asarray(t, float)
        wn = 2 * np.pi * self.natural_frequency_hz
        z = self.damping_ratio
        wd = wn * math.sqrt(1 - z * z)
        tau = np.maximum(t - self.release_s, 0.0)
        env = np.exp(-z * wn * tau)
        c, s = np.cos(wd * tau), np.sin(wd * tau)
        return t, wn, z, wd, tau, env, c, s

    def deflection(self, t):
        t, wn, z, wd, tau, env, c, s = self._parts(t)
        ramp = _smoothstep((t - (self.release_s - self.ramp_s)) / self.ramp_s)[0]
        free = env * (c + z * wn / wd * s)
        return self.amplitude_m * np.where(t < self.release_s, ramp, free)

    def velocity(self, t):
        t, wn, z, wd, tau, env, c, s = self._parts(t)
        u = (t - (self.release_s - self.ramp_s)) / self.ramp_s
        ramp_v = np.where((u > 0) & (u < 1), _smoothstep(u)[1] / self.ramp_s, 0.0)
        free_v = -env * s * wn / math.sqrt(1 - z * z)
        return self.amplitude_m * np.where(t < self.release_s, ramp_v, free_v)


class Sampled(Stimulus):
    """
    User-supplied deflection samples (t_s, w_m), interpolated by a cubic spline.

    The velocity is the spline's derivative. Outside the record the
    deflection is held at its end values.
    """

    def __init__(self, time_s, deflection_m):
        from scipy.interpolate import CubicSpline

        t = np.asarray(time_s, float)
        w = np.asarray(deflection_m, float)
        if t.ndim != 1 or t.shape != w.shape or t.size < 4:
            raise ParameterError(
                'sampled stimulus needs at least 4 (time, deflection) pairs of equal length'
            )
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(w))):
            raise ParameterError('sampled stimulus contains non-finite values')
        if np.any(np.diff(t) <= 0):
            raise ParameterError('sampled stimulus time must increase strictly')
        self._t0, self._t1 = float(t[0]), float(t[-1])    # the record's first and last time, s
        self._spline = CubicSpline(t, w)
        self._d = self._spline.derivative()

    @property
    def start_s(self) -> float:
        """Time of the first sample of the record, s."""
        return self._t0

    def deflection(self, t):
        return self._spline(np.clip(np.asarray(t, float), self._t0, self._t1))

    def velocity(self, t):
        t = np.asarray(t, float)
        return np.where(
            (t >= self._t0) & (t <= self._t1), self._d(np.clip(t, self._t0, self._t1)), 0.0
        )


@dataclass(frozen=True)
class RobotMotion(Stimulus):
    """
    Robot-like motion: from ``first_move_s`` on, segments of 2-6 s, each one of three.

    A hold; a move to a new level in +-``amplitude_m`` (a raised cosine of 0.2-0.6 s, then
    held); or slow sines (0.2-2 Hz, 0.2-0.6 ``amplitude_m``, faded in and out over 0.3 s)
    around the current level.  The segments are drawn from ``seed`` in order, as far as the
    latest time asked for, so any cut of time into blocks gives the same motion; the velocity
    is the analytic derivative of each piece.
    """

    amplitude_m: float = 1.5e-3
    seed: int = 0
    first_move_s: float = 1.0

    def __post_init__(self):
        _pos('amplitude_m', self.amplitude_m)
        _pos('first_move_s', self.first_move_s, allow_zero=True)
        object.__setattr__(self, '_rng', np.random.default_rng(self.seed))
        object.__setattr__(self, '_segments', [])      # (start, dur, kind, level, a, b)
        object.__setattr__(self, '_level', 0.0)

    def _until(self, t_max: float) -> list:
        segments = self._segments
        start = segments[-1][0] + segments[-1][1] if segments else self.first_move_s
        rng, level = self._rng, self._level
        while start < t_max:
            dur = rng.uniform(2.0, 6.0)
            kind = int(rng.integers(3))
            if kind == 1:
                new = rng.uniform(-self.amplitude_m, self.amplitude_m)
                segments.append((start, dur, 1, level, new, rng.uniform(0.2, 0.6)))
                level = new
            elif kind == 2:
                f = rng.uniform(0.2, 2.0)
                segments.append((start, dur, 2, level, f,
                                 rng.uniform(0.2, 0.6) * self.amplitude_m))
            else:
                segments.append((start, dur, 0, level, 0.0, 0.0))
            start += dur
        object.__setattr__(self, '_level', level)
        return segments

    def _pieces(self, t):
        t = np.asarray(t, float)
        for start, dur, kind, level, a, b in self._until(float(np.max(t, initial=0.0))):
            sel = (t >= start) & (t < start + dur)
            if np.any(sel):
                yield sel, t[sel] - start, dur, kind, level, a, b

    def deflection(self, t):
        w = np.zeros(np.shape(t))
        for sel, tau, dur, kind, level, a, b in self._pieces(t):
            if kind == 0:
                w[sel] = level
            elif kind == 1:
                w[sel] = level + (a - level) * _smoothstep(tau / b)[0]
            else:
                w[sel] = level + b * np.sin(2 * np.pi * a * tau) * _smoothstep(tau / 0.3)[0] \
                    * _smoothstep((dur - tau) / 0.3)[0]
        return w

    def velocity(self, t):
        v = np.zeros(np.shape(t))
        for sel, tau, dur, kind, level, a, b in self._pieces(t):
            if kind == 1:
                v[sel] = (a - level) * _smoothstep(tau / b)[1] / b
            elif kind == 2:
                (r1, d1), (r2, d2) = _smoothstep(tau / 0.3), _smoothstep((dur - tau) / 0.3)
                phase = 2 * np.pi * a * tau
                v[sel] = b * (2 * np.pi * a * np.cos(phase) * r1 * r2
                              + np.sin(phase) * (d1 * r2 - r1 * d2) / 0.3)
        return v


STIMULUS_KINDS = {'crank_slider': CrankSlider, 'sweep': Sweep, 'free_vibration': FreeVibration,
                  'step': Step, 'robot_motion': RobotMotion}


def make_stimulus(kind: str, **params) -> Stimulus:
    """Build a stimulus by name (a key of :data:`STIMULUS_KINDS`)."""
    if kind not in STIMULUS_KINDS:
        raise ParameterError(f"unknown stimulus '{kind}'; choose one of {sorted(STIMULUS_KINDS)} "
                             '(or a file via Sampled)')
    try:
        return STIMULUS_KINDS[kind](**params)
    except TypeError as exc:
        raise ParameterError(f"stimulus '{kind}': {exc}") from None
