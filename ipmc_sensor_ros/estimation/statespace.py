# SPDX-License-Identifier: Apache-2.0
"""
The estimator's state-space model: sensor, motion, offset and mains lines in one state.

Continuous time; the sensor from :class:`~ipmc_sensor_ros.lti.reduction.ReducedModel`,
H_n(s) = s R_n(s) (eq. 45 reduced as in :mod:`~ipmc_sensor_ros.lti.reduction`; eq. 31 for
H1)::

    x_R' = A_R x_R + B_R u             R_n = C_R (s - A_R)^-1 B_R + D_R, driven by the tip
                                       velocity u: the sensor measures the rate of charge,
                                       so H(0) = 0 and a constant deflection gives no current
    w'   = u,  u' = g                  tip deflection w (m), velocity u, acceleration g
    g'   = -a^2 f (w - h - sum_j p_j[0]) - (a^2 + 2af) u - (2a + f) g + xi_g
                                       motion about the working point h: a third-order
                                       process, deflection spectrum q / ((W^2 + f^2)
                                       (W^2 + a^2)^2), f = 2 pi motion_corner_hz, a = 2 pi
                                       motion_bandwidth_hz, q from motion_rms_m
                                       (:func:`motion_intensity`); smooth (continuous
                                       acceleration), so a sample's current is predicted
                                       from the last ones and a mains line, persistent,
                                       is told from motion within a few cycles
    h'   = xi_h                        working point (random walk, working_point_walk_m)
    p_j' = V_j [[0, -1], [1, 0]] p_j + r_j
    r_j' = V_j [[0, -1], [1, 0]] r_j + xi_r
                                       periodic motion j (in phase, quadrature), m: the
                                       target the tip follows turns at V_j = 2 pi j f_motion,
                                       j = 1..motion_harmonics below motion_bandwidth_hz,
                                       f_motion measured from the data (:mod:`.motionline`;
                                       several motions: each its own f_motion and lines);
                                       with these states xi_g drives only what the periodic
                                       part leaves (periodic_remainder_rms_m).  A motor's
                                       speed wobbles: its relative error e walks
                                       (e' = motion_speed_walk xi), and p_j turns at
                                       V_j (1 + e), so p_j' - V_j J p_j = V_j e J p_j =: r_j
                                       is continuous (a speed has inertia) and walks by
                                       motion_rms_m 2 pi f_motion motion_speed_walk (r_j,
                                       m/s: the phasor's rate in its turning frame)
    b'   = d + xi_b                    current offset, A (random walk, offset_walk_a)
    d'   = xi_d                        its drift, A/s (offset_drift_walk_a_per_s)
    l_k' = W_k [[0, -1], [1, 0]] l_k + xi_l
                                       mains line k (in phase, quadrature), W_k = 2 pi k
                                       f_line, k = 1..line_harmonics below 0.45 fs
    i    = C_R x_R + D_R u + b + sum_k l_k[0] + n          measured current, n white

The motion is *bounded* about the working point: a bounded deflection carries no mean
current, so the offset is the long-run mean of the current even while the sensor moves
(slower excursions than ``motion_corner_hz`` are told from an offset change by the priors
only, which is slow unless the motion is periodic: a periodic motion, once its frequency is
measured, is modelled by the states p_j and leaves a small remainder, so the offset is the
current's mean within a few periods).  Moving since before the start, the sensor and motion
states hold the periodic states' forced response X p (X V = A X + A_p: a Sylvester
equation) on top of their own stationary spread (:meth:`StateSpaceModel.prior`).

At rest (:mod:`.rest`) the velocity and the motion's current are measured to be zero
(pseudo-measurements), which tells offset from motion exactly, and the working point is
where the tip is held: its prior is released (:attr:`StateSpaceModel.hold_variance`) and it
is measured equal to w.

Exact discretisation (Van Loan; :func:`~ipmc_sensor_ros.lti.discretize.van_loan`) for one
sample period, chained by doubling for ``m`` periods (bridged samples; a single ``expm``
over a long gap overflows); states are scaled to O(1) for the filter's
arithmetic (:attr:`StateSpaceModel.scale`).
"""
from __future__ import annotations

import functools
import math

import numpy as np
from scipy.linalg import expm, solve_discrete_lyapunov, solve_sylvester

from ..errors import ParameterError
from ..lti.discretize import chain, van_loan
from ..lti.modal import modal_realisation
from ..lti.reduction import ReducedModel
from .config import EstimatorConfig
from .phasors import line_frequencies_hz, motion_lines, write_phasors

__all__ = ['StateSpaceModel', 'modal_realisation']


#: At a rest sample the working point's prior is widened to this many ``motion_rms_m`` before it
#: is measured equal to the held deflection: wide enough that the held level, not the old
#: working point, decides (a 1e-4 relative pull), narrow enough for well-conditioned algebra.
HOLD_RELEASE = 100.0

#: A motor's speed wobbles by up to this, relative, at rates up to MOTION_WOBBLE_HZ (a DC
#: motor under a crank's varying load): the sidebands it puts beside each harmonic are
#: allowed in a periodic model's residual (:mod:`.motionline`), and a periodic phasor's rate
#: is known to this of its turning before the data tell it (the rate states' prior).
MOTION_WOBBLE = 0.02
#: The fastest such wobble, Hz: a crank's load cycle seen through the motor's inertia.
MOTION_WOBBLE_HZ = 0.5

#: Rows tabulated per period for a sample taken off its slot (:attr:`StateSpaceModel.
#: off_slot_rows`; the nearest is used): a sample's instant to 1/2048 of a period, 0.5 us at
#: 1 kHz, about the resolution of a float stamp of today's epoch time (0.24 us).
OFF_SLOT_STEPS = 1024


def motion_intensity(a: float, f: float, rms_m: float) -> float:
    """
    White-noise intensity q that gives w the variance rms_m^2 through 1/((s + f)(s + a)^2).

    Var w = q / (2 pi) int dW / ((W^2 + f^2)(W^2 + a^2)^2) = q (2a + f) / (4 a^3 f (a + f)^2)
    (partial fractions; f, a in rad/s).
    """
    return rms_m ** 2 * 4 * a ** 3 * f * (a + f) ** 2 / (2 * a + f)


class StateSpaceModel:
    """
    The model of the module docstring for one sensor, sample rate and mains line.

    Parameters
    ----------
    reduced : ReducedModel
        The sensor's reduced model R_n.
    config : EstimatorConfig
        Motion, offset and line priors.
    sample_rate_hz : float
        Nominal sample rate, Hz.
    line_hz : float or tuple of float
        Mains fundamental(s) in the model, Hz (0 or (): no line states; several while the line
        is not yet measured, e.g. (50, 60)).
    motion_hz : float or tuple of float
        Fundamental(s) of the periodic motions in the model, Hz (0 or (): none), the
        strongest first.

    """

    def __init__(self, reduced: ReducedModel, config: EstimatorConfig, sample_rate_hz: float,
                 line_hz=0.0, motion_hz=0.0):
        fs = float(sample_rate_hz)
        if not (math.isfinite(fs) and fs > 0):
            raise ParameterError(f"parameter 'sample_rate_hz' must be > 0 Hz, got "
                                 f'{sample_rate_hz!r}')
        if config.motion_bandwidth_hz >= fs / 2:
            raise ParameterError(
                f"parameter 'motion_bandwidth_hz' = {config.motion_bandwidth_hz:g} Hz must be "
                f'below the Nyquist frequency {fs / 2:g} Hz')
        self.reduced, self.config, self.sample_rate_hz = reduced, config, fs
        self.fundamentals_hz = tuple(float(f) for f in np.atleast_1d(line_hz) if f)
        self.line_hz = self.fundamentals_hz[0] if len(self.fundamentals_hz) == 1 else 0.0
        self.lines_hz = tuple(f for f0 in self.fundamentals_hz
                              for f in line_frequencies_hz(f0, fs, config.line_harmonics))
        self.motion_fundamentals_hz = tuple(float(f) for f in np.atleast_1d(motion_hz or 0.0)
                                            if f)
        self.motion_hz = (self.motion_fundamentals_hz or (0.0,))[0]
        self.motion_lines_hz, self.motion_line_fundamentals_hz = motion_lines(
            self.motion_fundamentals_hz, config.motion_bandwidth_hz, config.motion_harmonics,
            MOTION_WOBBLE)
        self.sensor = modal_realisation(reduced)
        n = self.n_sensor = reduced.order
        self.iw, self.iu, self.ia, self.ih, self.ib = n, n + 1, n + 2, n + 3, n + 4
        self.il = n + 6
        self.im = self.il + 2 * len(self.lines_hz)
        self.ir = self.im + 2 * len(self.motion_lines_hz)        # the phasors' rates
        self.size = self.ir + 2 * len(self.motion_lines_hz)
        #: R_n(0), A s/m: a steady current is this times the tip's velocity (H(0) = 0)
        self.charge_gain = float(np.real(reduced.charge_response(np.array([0.0]))[0]))
        self.r0 = abs(self.charge_gain)

    # -- continuous model ---------------------------------------------------------------
    @functools.cached_property
    def continuous(self) -> tuple[np.ndarray, np.ndarray]:
        """Continuous (A, Q): x' = A x + xi with E[xi xi'] = Q delta (intensities)."""
        cfg = self.config
        ar, br, _, _ = self.sensor
        n, nx = self.n_sensor, self.size
        a_m = 2 * math.pi * cfg.motion_bandwidth_hz
        f_m = 2 * math.pi * cfg.motion_corner_hz
        A = np.zeros((nx, nx))
        Q = np.zeros((nx, nx))
        A[:n, :n] = ar
        A[:n, self.iu] = br
        A[self.iw, self.iu] = 1.0
        A[self.iu, self.ia] = 1.0
        # (s + f)(s + a)^2 = s^3 + (2a + f) s^2 + (a^2 + 2af) s + a^2 f, acting on w - h
        A[self.ia, self.iw] = -a_m * a_m * f_m
        A[self.ia, self.ih] = a_m * a_m * f_m
        A[self.ia, self.iu] = -(a_m * a_m + 2 * a_m * f_m)
        A[self.ia, self.ia] = -(2 * a_m + f_m)
        rms = cfg.periodic_remainder_rms_m if self.motion_lines_hz else cfg.motion_rms_m
        Q[self.ia, self.ia] = motion_intensity(a_m, f_m, rms)
        Q[self.ih, self.ih] = cfg.working_point_walk_m ** 2
        A[self.ib, self.ib + 1] = 1.0
        Q[self.ib, self.ib] = cfg.offset_walk_a ** 2
        Q[self.ib + 1, self.ib + 1] = cfg.offset_drift_walk_a_per_s ** 2
        write_phasors(A, Q, self.il, self.lines_hz, cfg.line_walk_a)
        write_phasors(A, Q, self.im, self.motion_lines_hz, 0.0)
        write_phasors(A, Q, self.ir, self.motion_lines_hz, self.motion_line_walk_m)
        A[np.arange(self.im, self.ir), np.arange(self.ir, self.size)] = 1.0
        A[self.ia, self.im:self.ir:2] = a_m * a_m * f_m      # the target the tip follows
        return A, Q

    @functools.cached_property
    def scale(self) -> np.ndarray:
        """Typical size of each state (the filter works in x / scale), SI units."""
        cfg = self.config
        s = np.empty(self.size)
        s[:self.n_sensor] = cfg.motion_rms_m * 2 * math.pi * cfg.motion_bandwidth_hz / np.abs(
            np.diag(self.sensor[0]))
        s[self.iw] = s[self.ih] = cfg.motion_rms_m
        s[self.iu] = cfg.motion_rms_m * 2 * math.pi * cfg.motion_bandwidth_hz
        s[self.ia] = s[self.iu] * 2 * math.pi * cfg.motion_bandwidth_hz
        s[self.ib] = cfg.offset_prior_a
        s[self.ib + 1] = cfg.offset_drift_a_per_s
        s[self.il:self.im] = cfg.line_prior_a
        s[self.im:self.ir] = cfg.motion_rms_m
        s[self.ir:] = np.repeat(cfg.motion_rms_m * 2 * math.pi * MOTION_WOBBLE
                                * np.asarray(self.motion_line_fundamentals_hz), 2)
        return s

    # -- measurement rows (scaled states) ----------------------------------------------------
    @functools.cached_property
    def c(self) -> np.ndarray:
        """Row of the measured current (A per unit scaled state)."""
        _, _, cr, dr = self.sensor
        c = np.zeros(self.size)
        c[:self.n_sensor] = cr
        c[self.iu] = dr
        c[self.ib] = 1.0
        c[self.il:self.im:2] = 1.0
        return c * self.scale

    @functools.cached_property
    def off_slot_rows(self) -> tuple[np.ndarray, np.ndarray]:
        """
        Rows of the current (A) and the deflection (m) of a sample off its slot (scaled).

        The state is on the sample clock's slots; a sample taken d periods from its slot
        (|d| <= 1/2: a DAQ that samples when it stamps, :mod:`.timebase`) measures
        i(t + d/fs) = c e^{A d/fs} x(t) + n, and the tip is then at e_w e^{A d/fs} x(t) (the
        process noise over |d|/fs left out).  Row j is for d = j / OFF_SLOT_STEPS - 1/2, by
        powers of e^{+-A / (OFF_SLOT_STEPS fs)} from the slot's rows.
        """
        A, _ = self.continuous
        s = self.scale
        As = A * s[None, :] / s[:, None] / (OFF_SLOT_STEPS * self.sample_rate_hz)
        half = OFF_SLOT_STEPS // 2
        rows = np.zeros((2, OFF_SLOT_STEPS + 1, self.size))
        rows[0, half], rows[1, half, self.iw] = self.c, s[self.iw]
        for sign, turn in ((1, expm(As)), (-1, expm(-As))):
            for j in range(1, half + 1):
                rows[:, half + sign * j] = rows[:, half + sign * (j - 1)] @ turn
        return rows[0], rows[1]

    @functools.cached_property
    def c_motion(self) -> np.ndarray:
        """Row of the motion's current (the current less offset and lines)."""
        c = self.c.copy()
        c[self.ib:] = 0.0
        return c

    @functools.cached_property
    def c_velocity(self) -> np.ndarray:
        """Row of the tip velocity."""
        c = np.zeros(self.size)
        c[self.iu] = self.scale[self.iu]
        return c

    @functools.cached_property
    def rest_variances(self) -> tuple[float, float]:
        """Variances of the rest pseudo-measurements: velocity (m/s)^2, motion current A^2."""
        v2 = self.config.rest_velocity_m_s ** 2
        return v2, v2 * self.r0 ** 2

    @property
    def motion_line_walk_m(self) -> np.ndarray:
        """Random walk of each periodic phasor's rate, m/s/sqrt(s) (a relative speed walk)."""
        cfg = self.config
        return (cfg.motion_rms_m * 2 * math.pi * cfg.motion_speed_walk
                * np.asarray(self.motion_line_fundamentals_hz))

    @functools.cached_property
    def motion_states(self) -> np.ndarray:
        """Return the indices of the charge states and w, u, g (the motion, its current)."""
        return np.r_[np.arange(self.n_sensor), self.iw, self.iu, self.ia]

    @functools.cached_property
    def forced_response(self) -> np.ndarray:
        """
        X (scaled): the motion states' steady response x = X p to the periodic states p.

        X V = A_mm X + A_mp with V the periodic states' rotation (Sylvester; the motion
        states are stable and V is a pure rotation, so X is unique).
        """
        A, _ = self.continuous
        s = self.scale
        As = A * s[None, :] / s[:, None]
        m, p = self.motion_states, np.arange(self.im, self.size)
        return solve_sylvester(As[np.ix_(m, m)], -As[np.ix_(p, p)], -As[np.ix_(m, p)])

    def with_forced_response(self, P: np.ndarray) -> np.ndarray:
        """Return P with the periodic states driving the motion states: T P T', T = I + X."""
        if not self.motion_lines_hz:
            return P
        T = np.eye(self.size)
        T[np.ix_(self.motion_states, np.arange(self.im, self.size))] = self.forced_response
        return T @ P @ T.T

    @property
    def hold_variance(self) -> float:
        """Scaled variance added to the working point at a rest sample (releases its prior)."""
        return HOLD_RELEASE ** 2

    # -- discretisation and priors -------------------------------------------------------------
    def discrete(self, steps: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """
        (F, Qd) over ``steps`` sample periods, in scaled states.

        One period by Van Loan; longer spans chained from powers of two of it
        (:func:`~ipmc_sensor_ros.lti.discretize.chain`, exact) so a long bridged gap
        cannot overflow.
        """
        cache = self.__dict__.setdefault('_discrete', {})
        if steps not in cache:
            if len(cache) >= 64:        # bridged gaps of many lengths: keep the cache small
                cache.pop(next(iter(cache)))
            cache[steps] = self._chained(steps)
        return cache[steps]

    def _chained(self, steps: int) -> tuple[np.ndarray, np.ndarray]:
        """(F, Qd) over ``steps`` >= 1 periods from the doubled one-period transition."""
        powers = self.__dict__.get('_powers')
        if powers is None:
            A, Q = self.continuous
            F, Qd = van_loan(A, Q, 1.0 / self.sample_rate_hz)
            s = self.scale
            powers = self.__dict__['_powers'] = [(F * s[None, :] / s[:, None],
                                                  Qd / np.outer(s, s))]
        out = None
        for bit in range(steps.bit_length()):
            if bit == len(powers):
                powers.append(chain(powers[-1], powers[-1]))
            if steps >> bit & 1:
                out = powers[bit] if out is None else chain(out, powers[bit])
        return out

    @functools.cached_property
    def stationary_motion(self) -> np.ndarray:
        """Stationary covariance of the motion states about the working point (scaled)."""
        F, Q = self.discrete(1)
        m = self.motion_states
        return solve_discrete_lyapunov(F[np.ix_(m, m)], Q[np.ix_(m, m)])

    def prior(self) -> tuple[np.ndarray, np.ndarray]:
        """
        (x0, P0), scaled: the motion stationary about a working point known to start_level_m.

        Offset and lines unknown to ``offset_prior_a``.
        """
        cfg = self.config
        nx = self.size
        P0 = np.zeros((nx, nx))
        motion = self.motion_states
        P0[np.ix_(motion, motion)] = self.stationary_motion
        h = (cfg.start_level_m / self.scale[self.ih]) ** 2
        P0[self.ih, self.ih] = h
        P0[self.iw, self.iw] += h
        P0[self.iw, self.ih] = P0[self.ih, self.iw] = h
        P0[self.ib, self.ib] = 1.0
        P0[self.ib + 1, self.ib + 1] = 1.0
        P0[self.il:, self.il:] = np.eye(nx - self.il)
        return np.zeros(nx), self.with_forced_response(P0)
