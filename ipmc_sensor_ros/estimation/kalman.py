# SPDX-License-Identifier: Apache-2.0
"""
Offset-aware steady-state Kalman estimator of tip deflection from sensing current.

Model (continuous time, designed from the same :class:`ReducedModel` that
:class:`~ipmc_sensor_ros.estimation.inverse.InverseEstimator` inverts)
------------------------------------------------------------------------------
``H_n(s) = s R_n(s)`` (eqs. 45, 47): the current is ``R_n`` driven by the tip
*velocity* v.  State x = [x_R (n states of R_n), w, v, b]:

    x_R' = A_R x_R + B_R v                (R_n, diagonal realisation)
    w'   = v - w_l w                      (deflection; w_l = 2 pi leak_corner_hz)
    v'   = -a v + xi_v                    (velocity: Ornstein-Uhlenbeck,
                                           a = 2 pi motion_bandwidth_hz)
    b'   = xi_b                           (current offset: constant + random-walk drift)
    i    = C_R x_R + D_R v + b + n        (measured current, A)

with white noises of intensities ``q_v = 2 a sigma_v^2`` (velocity RMS sigma_v =
``motion_velocity_m_s``, flat up to ``motion_bandwidth_hz``), ``q_b =
offset_drift_a_per_s^2 * 60 s`` (moves by ``offset_drift_a_per_s * 60 s`` RMS per
minute), measurement noise RMS ``current_noise_a`` per sample.  The leak ``w_l``
makes w detectable (an unmeasured integrator has no steady-state gain) and caps what
noise and offset error integrate into it; its corner follows the motion
(:mod:`~ipmc_sensor_ros.estimation.leak_schedule`: the corner of a ladder that minimises
the predicted leak + noise + offset error, about 0.02 f_motion under 1 % noise), never
below 0.02 Hz (``START_LEAK_CORNER_HZ``) until the first rest and while the offset is
not trusted, else never below 0.001 Hz (``KALMAN_LEAK_CORNER_HZ``), towards the last
held level.  Exact
discretisation (Van Loan, expm), gain from :func:`scipy.linalg.solve_discrete_are`.

Defaults (from the DAQ and the motion)
--------------------------------------
``current_noise_a`` = 20 nA RMS per sample (a 16-bit DAQ on a +-1 uA-scale
transimpedance range; 1 % of a slim sample's current at 1 Hz);
``motion_velocity_m_s`` = 0.1 m/s (a 2 mm crank at 8 Hz; a smaller value biases the
estimate low: 2 % at 20 mm/s, as the filter then expects most current to be noise or offset),
``motion_bandwidth_hz`` = 50 Hz (above the paper's 1-20 Hz band and the 30 Hz
free vibration); ``offset_drift_a_per_s`` = 1 nA/min.

Observability, and how slow is too slow
---------------------------------------
``H(0) = 0``: a constant offset b is exactly a constant velocity b / R_n(0); only
spectra separate them.  The motion current's low-frequency PSD ``R0^2 q_v / a^2``
(flat) and the offset's ``q_b / w^2`` cross at

    w_c = sqrt(q_b a^2 / (R0^2 q_v)) = sqrt(q_b a / (2 R0^2 sigma_v^2)),

(:func:`offset_corner_hz`).  Below ``f_c = w_c / 2 pi`` a deflection change is
taken for offset drift and vice versa: a deflection that creeps by dw over a
time longer than ``1/w_c`` is invisible.  With the defaults and the slim sample
(R0 = 3.2e-4 A s/m) f_c is about 1e-6 Hz: while the sensor moves, the offset is
essentially *not* learned (any faster offset learning during motion would
also erase slow deflection ramps).  It is learned when the sensor rests:

Rest detector and gain scheduling
---------------------------------
The current is band-passed (``REST_BAND_LOW_HZ`` = 1 Hz to min(50 Hz, fs/4)), each
sample's energy capped at ``ENERGY_CLIP`` times the noise's (a pulse then delays
rest by < 0.5 s) and averaged over ``rest_window_s``.  The noise energy is the
larger of ``current_noise_a`` and the white noise measured above the motion band
(fs/4 .. Nyquist, averaged over ``NOISE_WINDOW_S``, from zero with the bias corrected, so
it is known within tens of samples of the start).  The sensor is *at rest* when
the band energy falls below ``rest_enter`` times the noise's; it is *moving* again
as soon as the energy exceeds ``rest_leave`` times it (hysteresis), one sample
exceeds 6 sigma, or the low-passed current departs from the offset estimate by
more than 4 sigma of their difference (a slow deflection ramp is a steady current
R0 dw/dt the band-pass cannot see).
At rest the deflection is held (frozen, as a gyro's angle while its bias is
learned at standstill) at its *smoothed* value where the detector last saw motion:
the quiet samples the detector needed are dropped, the leak's losses over the move are
restored and the ramp of the offset's error (the offset learned at this rest against
the one the move ran with, an RTS-smoothed random walk) is removed
(:meth:`KalmanEstimator._enter_rest`).  The charge and velocity states are zeroed and the offset
is the running mean of the current, started with the weight sigma^2/P_b of its
previous estimate (P_b grows by q_b per second of motion) and, once it has
``fs * rest_offset_time_s`` samples, a level-and-trend average that follows a drift
without lag (an exponential average would trail 1 nA/min by 0.17 nA with the default
10 s); sigma is the *measured* noise.
Leaving rest, the last ``REST_REWIND_WINDOWS`` rest windows are re-run in the moving
mode from the offset learned before them (the detector's lag), and the leak pulls
towards the held level (not zero), starting from ``leak_corner_hz`` while the offset is
known to ``OFFSET_TRUSTED_A``, else from ``START_LEAK_CORNER_HZ``, then at the corner the
schedule picks (re-chosen every ``leak_schedule.STEP_S`` on a fixed sample grid; one
gain set per ladder corner, built when first used).  The moving mode is an
LTI filter run over each run of moving samples in modal coordinates (one first-order
:func:`scipy.signal.lfilter` per eigenvalue of the closed-loop matrix, conjugate
pairs once), so blocks are vectorised and the state passes exactly between modes.

Periodic motion: once a second while moving, the offset is also learned from whole periods
of the motion when it is periodic (:mod:`~.periodic_offset`; mean current over k periods =
b, since the charge returns), fused with the offset known when the motion began; w is
corrected for the ramp the old value caused and, before the first rest, centred
(:meth:`KalmanEstimator._periodic_update`).

Limits: an offset while the sensor never rests nor moves periodically is learned only at
``f_c`` (as the leaky inverse's offset error); motion slower than the detector's band with R0 dw/dt
within 4 sigma of the offset is taken for rest (its current for offset); an
offset *step* while moving is integrated until the next rest.

Uncertainty: ``last_std`` is the standard deviation of w from the moving mode's
steady-state posterior covariance (held at rest); it excludes reduction error.
"""

from __future__ import annotations

import math
from collections import deque
from operator import mul

import numpy as np
from scipy.linalg import solve_discrete_are, solve_discrete_lyapunov
import scipy.signal as sig

from .inverse import ParameterError, _positive
from .leak_schedule import LeakSchedule
from .periodic_offset import PeriodicOffset
from ..lti.discretize import van_loan
from ..lti.reduction import ReducedModel

__all__ = ['KalmanEstimator', 'offset_corner_hz', 'DEFAULT_CURRENT_NOISE_A']

#: Defaults (see the module docstring): DAQ noise A RMS per sample, motion, drift.
DEFAULT_CURRENT_NOISE_A = 20e-9
DEFAULT_MOTION_VELOCITY_M_S = 0.1
DEFAULT_MOTION_BANDWIDTH_HZ = 50.0
DEFAULT_OFFSET_DRIFT_A_PER_S = 1e-9 / 60.0
#: Default deflection leak while moving after a rest, Hz (time constant 160 s): each move
#: loses 0.6 %/s of its excursion from the held level; an offset error db adds db t / R0.
KALMAN_LEAK_CORNER_HZ = 0.001
#: Deflection leak before the first rest (level unknown, offset not yet learned), Hz: twice the
#: leaky inverse's corner.  An unlearned offset b then costs b / (2 pi f R0) (half the leaky's);
#: a sinusoid at f sees a phase lead of about f / f_motion (2 % at 1 Hz).  Measured (bench, 1 %
#: noise + 10 nA, moving from t=0): 0.01 Hz 23 / 12 %, 0.02 Hz 15-17 / 8-11 %, 0.05 Hz 6-8 %
#: (slim / short) but 5 % on a clean 1 Hz crank (leaky 2.1 %), so 0.02 Hz.
START_LEAK_CORNER_HZ = 0.02
#: Offset uncertainty (RMS, A) below which the slow leak is used after a rest: 1 nA ramps the
#: slim sample's deflection by 3 um/s (R0 = 3.2e-4 A s/m), 50 um in a 16 s move.  A 2 s rest
#: with noise sigma learns the offset to sigma / sqrt(2000): 1 nA for sigma = 45 nA.
OFFSET_TRUSTED_A = 1e-9
#: Leaving rest, the last REST_REWIND_WINDOWS * rest_window_s of 'rest' samples are re-run in
#: the moving mode from the offset learned before them: the detector notices a gentle start
#: only after its averaging window, and those first motion samples must neither feed the
#: offset (0.26 nA on a clean 5 Hz crank, a 0.8 um/s ramp on slim) nor be lost from w.
REST_REWIND_WINDOWS = 2.0
#: Entering rest, the held deflection is the estimate at the last sample the detector saw
#: motion (or the record's start), when that is at most this long ago, s: the quiet samples
#: the detector needed to confirm rest integrate noise and offset error only (see _enter_rest).
QUIET_REWIND_MAX_S = 2.0
#: Prior RMS of the current offset before any rest, A (DAQ offsets: tens of nA).
OFFSET_PRIOR_A = 100e-9
#: Cap on one sample's band-passed energy in the rest detector, in units of the noise's.
ENERGY_CLIP = 20.0
#: Low edge of the rest detector's band, Hz (slower motion is seen only by the offset test).
REST_BAND_LOW_HZ = 1.0
NOISE_WINDOW_S = 0.5   # averaging time of the measured white-noise floor, s
#: Largest measured noise RMS accepted, in units of current_noise_a (each sample's high-passed
#: energy is capped there, so one glitch moves the floor little).  1 % noise on a 2 mm, 20 Hz
#: crank of the short sample is 735 nA (37 x 20 nA); at 20 the floor stayed below the true
#: noise and the detector flickered between rest and motion (NRMSE 3.4 % vs 2.2 % at 60).
NOISE_CLIP = 60.0


def offset_corner_hz(
    reduced: ReducedModel,
    motion_velocity_m_s: float = DEFAULT_MOTION_VELOCITY_M_S,
    motion_bandwidth_hz: float = DEFAULT_MOTION_BANDWIDTH_HZ,
    offset_drift_a_per_s: float = DEFAULT_OFFSET_DRIFT_A_PER_S,
) -> float:
    """Frequency below which offset drift and deflection cannot be told apart while moving, Hz."""
    r0 = abs(float(np.real(reduced.charge_response(np.array([0.0]))[0])))
    a = 2 * math.pi * motion_bandwidth_hz
    q_b = offset_drift_a_per_s ** 2 * 60.0
    return math.sqrt(q_b * a / (2 * r0 ** 2 * motion_velocity_m_s ** 2)) / (2 * math.pi)


def _modal_realisation(reduced: ReducedModel):
    """
    R_n(s) = d + sum_i r_i / (s - p_i) (distinct real poles) as (A, B, C, D).

    a diagonal, well-scaled realisation (each state is a first-order lag of v).
    """
    z = np.real(np.asarray(reduced.zeros_rad_s))
    p = np.real(np.asarray(reduced.poles_rad_s))
    k = float(reduced.gain)
    if np.min(np.abs(np.subtract.outer(p, p)) + np.eye(p.size) * 1e300) < 1e-9 * np.max(np.abs(p)):
        raise ParameterError(
            'reduced model has repeated poles; the Kalman estimator needs distinct poles'
        )
    if z.size > p.size:
        raise ParameterError(
            f'reduced model has more zeros ({z.size}) than poles ({p.size}); the Kalman '
            'estimator needs a proper R_n(s)'
        )
    r = np.array([k * np.prod(pi - z) / np.prod([pi - pj for pj in p if pj != pi]) for pi in p])
    # feedthrough k only when R_n is biproper (an amplifier pole makes it strictly proper)
    d = k if z.size == p.size else 0.0
    return np.diag(p), np.ones((p.size, 1)), r[None, :], np.array([[d]])


class _Mode:
    """One LTI predictor s_{k+1} = F s_k + G y_k with outputs in modal form."""

    def __init__(
        self, ad: np.ndarray, k: np.ndarray, c: np.ndarray, iw: int, ib: int, scale: np.ndarray
    ):
        n = ad.shape[0]
        ikc = np.eye(n) - np.outer(k, c)
        f = ad @ ikc
        g = ad @ k
        lam, vs = np.linalg.eig(f / scale[:, None] * scale[None, :])   # in O(1) state units
        if not np.all(np.abs(lam) <= 1.0 + 1e-12):
            raise ParameterError(
                f'Kalman predictor is unstable (pole radius {np.abs(lam).max():.12f})'
            )
        cond = np.linalg.cond(vs)
        if not np.isfinite(cond) or cond > 1e12:
            raise ParameterError(f'Kalman predictor is not diagonalisable (condition {cond:.3g})')
        v = scale[:, None] * vs
        vinv = np.linalg.inv(vs) / scale[None, :]
        # keep one of each conjugate pair (weight 2) and the real modes (weight 1)
        keep = lam.imag >= -1e-14 * np.abs(lam)
        pair = np.where(lam.imag > 1e-14 * np.abs(lam), 2.0, 1.0)
        self.v = v
        self.vinv = vinv
        self.keep = np.flatnonzero(keep)
        self.lam = lam[self.keep]
        self.g = (vinv @ g)[self.keep]
        self.hw = (ikc[iw] @ v)[self.keep] * pair[self.keep]
        self.dw = float(k[iw])
        self.hb = (ikc[ib] @ v)[self.keep] * pair[self.keep]
        self.db = float(k[ib])
        self.f, self.gvec, self.k = f, g, k
        self.k_w, self.k_b = float(k[iw]), float(k[ib])
        self.f_rows = [list(map(float, row)) for row in f]     # plain floats for process_one
        self.g_list = list(map(float, g))
        self.dropped = np.flatnonzero(~keep)
        self.partner = np.array(
            [int(np.argmin(np.abs(self.lam - np.conj(lam[j])))) for j in self.dropped], dtype=int
        )
        self.a_list = [np.array([1.0, -pole]) for pole in self.lam]
        self.b_list = [np.array([0.0, gg]) for gg in self.g]

    def run(self, y: np.ndarray, s0: np.ndarray):
        """Filter y from predicted state s0; returns (w_hat, b_hat_last, s_end)."""
        z0 = (self.vinv @ s0)[self.keep]
        w = self.dw * y
        z_end = np.empty_like(z0)
        zlast = np.empty_like(z0)
        for j in range(self.lam.size):
            zj, zf = sig.lfilter(self.b_list[j], self.a_list[j], y, zi=z0[j:j + 1])
            w = w + (self.hw[j] * zj).real
            zlast[j] = zj[-1]
            z_end[j] = zf[0]
        b_last = float((self.hb @ zlast).real + self.db * y[-1])
        return w, b_last, self._to_state(z_end)

    def _to_state(self, z_kept: np.ndarray) -> np.ndarray:
        """Physical state from the kept modal values (dropped modes are conjugates)."""
        full = np.empty(self.v.shape[0], complex)
        full[self.keep] = z_kept
        full[self.dropped] = np.conj(z_kept[self.partner])
        return (self.v @ full).real


class KalmanEstimator:
    """
    Streaming offset-aware Kalman estimate of tip deflection (m) from current (A).

    Parameters
    ----------
    reduced : reduced model of the sensor.
    sample_rate_hz : sample rate of the current, Hz.
    current_noise_a : white measurement noise, A RMS per sample.
    motion_velocity_m_s : RMS tip velocity of typical motion, m/s.
    motion_bandwidth_hz : corner of the velocity spectrum, Hz.
    leak_corner_hz : deflection leak while moving (detectability), Hz.
    offset_drift_a_per_s : RMS offset drift rate (random walk), A/s.
    rest_offset_time_s : time constant of offset learning at rest, s.
    rest_window_s : averaging time of the rest detector, s.
    rest_enter, rest_leave : rest-detector thresholds (multiples of the noise energy in band).
    rest_detection : switch the rest detector (and gain scheduling) on or off.

    """

    def __init__(self, reduced: ReducedModel, sample_rate_hz: float, *,
                 current_noise_a: float = DEFAULT_CURRENT_NOISE_A,
                 motion_velocity_m_s: float = DEFAULT_MOTION_VELOCITY_M_S,
                 motion_bandwidth_hz: float = DEFAULT_MOTION_BANDWIDTH_HZ,
                 leak_corner_hz: float = KALMAN_LEAK_CORNER_HZ,
                 offset_drift_a_per_s: float = DEFAULT_OFFSET_DRIFT_A_PER_S,
                 rest_offset_time_s: float = 10.0, rest_window_s: float = 0.15,
                 rest_enter: float = 2.0, rest_leave: float = 4.0, rest_detection: bool = True,
                 channels: int = 1):
        if channels != 1:
            raise ParameterError(
                f"parameter 'channels' must be 1 for the Kalman estimator, got {channels!r}"
            )
        self.channels = 1
        self.reduced = reduced
        fs = _positive('sample_rate_hz', sample_rate_hz)
        self._fs = fs
        self.current_noise_a = _positive('current_noise_a', current_noise_a)
        self.motion_velocity_m_s = _positive('motion_velocity_m_s', motion_velocity_m_s)
        self.motion_bandwidth_hz = _positive('motion_bandwidth_hz', motion_bandwidth_hz)
        self.leak_corner_hz = _positive('leak_corner_hz', leak_corner_hz)
        self.offset_corner_hz = None      # interface parity with InverseEstimator (no tracker)
        self.offset_drift_a_per_s = _positive('offset_drift_a_per_s', offset_drift_a_per_s)
        self.rest_offset_time_s = _positive('rest_offset_time_s', rest_offset_time_s)
        self.rest_window_s = _positive('rest_window_s', rest_window_s)
        self.rest_enter = _positive('rest_enter', rest_enter)
        self.rest_leave = _positive('rest_leave', rest_leave)
        if self.rest_leave <= self.rest_enter:
            raise ParameterError(
                f"parameter 'rest_leave' ({rest_leave}) must exceed 'rest_enter' ({rest_enter})"
            )
        for name, f in (
            ('motion_bandwidth_hz', self.motion_bandwidth_hz),
            ('leak_corner_hz', self.leak_corner_hz),
        ):
            if f >= fs / 2:
                raise ParameterError(
                    f"parameter '{name}' = {f} must be below the Nyquist frequency {fs / 2} Hz"
                )
        self.rest_detection = bool(rest_detection)
        self._build()
        self.reset()

    # -- design -------------------------------------------------------------
    def _build(self) -> None:
        fs, dt = self._fs, 1.0 / self._fs
        ar, br, cr, dr = _modal_realisation(self.reduced)
        n = ar.shape[0]
        iw, iv, ib = n, n + 1, n + 2
        N = n + 3
        a = 2 * math.pi * self.motion_bandwidth_hz
        sv = self.motion_velocity_m_s
        ac = np.zeros((N, N))
        ac[:n, :n] = ar
        ac[:n, iv] = br[:, 0]
        ac[iw, iv] = 1.0
        ac[iv, iv] = -a
        c = np.zeros(N)
        c[:n] = cr[0]
        c[iv] = dr[0, 0]
        c[ib] = 1.0
        qc = np.zeros((N, N))
        qc[iv, iv] = 2 * a * sv ** 2
        qc[ib, ib] = self.offset_drift_a_per_s ** 2 * 60.0
        # state scaling x = S x~ (all O(1), current in units of the noise) for the Riccati solve
        scale = np.ones(N)
        scale[:n] = sv / np.abs(np.diag(ar))
        scale[iw] = 1e-3
        scale[iv] = sv
        scale[ib] = self.current_noise_a
        self._c, self._iw, self._ib, self._n = c, iw, ib, N
        self._motion_idx = np.r_[np.arange(n), iv]
        self._c_list = c.tolist()
        # moving-mode gain sets for a ladder of leak corners, built when first used; the
        # corner follows the motion (leak_schedule.py): floor leak_corner_hz once the offset
        # is trusted, START_LEAK_CORNER_HZ before the first rest (level unknown, offset not
        # learned) and while it is not
        self._design = (ac, qc, c, scale, dt)
        self._modes = {}
        self._gain = None
        self._r0 = abs(float(np.real(self.reduced.charge_response(np.array([0.0]))[0])))
        self._sched = LeakSchedule(fs, self._r0, self.leak_corner_hz, START_LEAK_CORNER_HZ)
        self._periodic = PeriodicOffset(fs)
        self._moving = self._ladder_mode(self._sched.floor_index)
        self._moving_start = self._ladder_mode(self._sched.start_index)
        self.std_moving_m = self._moving.std_m
        self._n_max = fs * self.rest_offset_time_s
        self._rewind_n = max(1, int(round(REST_REWIND_WINDOWS * self.rest_window_s * fs)))
        self._quiet_max_n = int(round(QUIET_REWIND_MAX_S * fs))
        self._rest_min_n = int(round(self.rest_window_s * fs))
        self._ramp_step = 1.0 / (fs * self._r0)   # w per sample per ampere of offset error
        self._q_b_step = self.offset_drift_a_per_s ** 2 * 60.0 * dt
        # detector: band-pass and one-pole energy average
        hi = min(50.0, fs / 4)
        self._bp = sig.butter(1, [REST_BAND_LOW_HZ, hi], btype='bandpass', fs=fs, output='sos')
        self._bp_list = self._bp[0].tolist()
        imp1 = np.zeros(4096)
        imp1[0] = 1.0
        self._bp_unit = float(np.sum(sig.sosfilt(self._bp, imp1) ** 2))
        enbw = math.pi / 2 * (hi - REST_BAND_LOW_HZ)
        self.noise_energy_a2 = self.current_noise_a ** 2 * 2 * enbw / fs
        self._alpha = math.exp(-1.0 / (fs * self.rest_window_s))
        # the noise floor is averaged over NOISE_WINDOW_S and each sample's energy capped at
        # ENERGY_CLIP^2 times the configured noise's, so a jump in the current cannot raise it
        self._alpha_hf = math.exp(-1.0 / (fs * NOISE_WINDOW_S))
        self._log_ah = -1.0 / (fs * NOISE_WINDOW_S)
        self._settled_n = int(40 * fs * NOISE_WINDOW_S)      # alpha^n < 1e-17: factor 1
        # the filters start in the steady state of the first sample (see _start_filters)
        self._bp_zi1 = sig.sosfilt_zi(self._bp)
        # white-noise level seen above the motion band (fs/4 .. Nyquist): energy ratio to the band
        self._hp = (
            sig.butter(2, fs / 4, btype='highpass', fs=fs, output='sos')
            if fs / 4 > 2 * hi
            else None
        )
        if self._hp is not None:
            imp = np.zeros(4096)
            imp[0] = 1.0
            self._hp_list = self._hp[0].tolist()
            self._hp_unit = float(np.sum(sig.sosfilt(self._hp, imp) ** 2))
            self._hf_clip = NOISE_CLIP ** 2 * self.current_noise_a ** 2 * self._hp_unit
            # the leak schedule's white-noise level: fourth order at 0.3 fs.  The detector's
            # second-order high-pass at fs/4 lets 0.6 % of a 20 Hz motion current through (148
            # nA of 'noise' on a clean 2 mm crank, slim), which the schedule would integrate as
            # white noise; this one passes 2e-5 of it.
            self._nz = sig.butter(4, 0.3 * fs, btype='highpass', fs=fs, output='sos')
            self._nz_list = [section.tolist() for section in self._nz]
            self._hp_zi1 = sig.sosfilt_zi(self._hp)
            self._nz_zi1 = sig.sosfilt_zi(self._nz)
            self._nz_unit = float(np.sum(sig.sosfilt(self._nz, imp) ** 2))
            self._nz_clip = NOISE_CLIP ** 2 * self.current_noise_a ** 2 * self._nz_unit
            self._hp_ratio = float(
                np.sum(sig.sosfilt(self._bp, imp) ** 2) / np.sum(sig.sosfilt(self._hp, imp) ** 2)
            )
            self.noise_energy_a2 = self.current_noise_a**2 * float(
                np.sum(sig.sosfilt(self._bp, imp) ** 2)
            )

    def _ladder_mode(self, index: int) -> '_Mode':
        """
        Moving-mode predictor for the ladder's corner ``index`` (built once, kept).

        Every corner uses one gain (:meth:`_moving_gain`); only the leak changes along the
        ladder.  The optimal gains of the corners differ in K_w alone (by under 4 % from
        0.001 to 0.5 Hz), and changing K_w in motion moves w by dK_w times the running sum
        of the innovation, which a periodic model mismatch turns into a step (15 um on a
        clean 2 mm, 5 Hz crank, slim, when the corner rose from 0.001 to 0.016 Hz) that the
        slow leak then keeps for 1 / (2 pi f) seconds.  With one gain the switch is
        bumpless.  The reported standard deviation is that of the gain in use.
        """
        mode = self._modes.get(index)
        if mode is None:
            if self._gain is None:
                self._gain = self._moving_gain()
            wl = 2 * math.pi * float(self._sched.corners_hz[index])
            mode = self._modes[index] = self._moving_mode(wl, self._gain)
        return mode

    def _moving_model(self, wl):
        """Discrete moving model with leak wl (rad/s): (ad, ad_s, qd_s, c_s), _s = scaled."""
        ac, qc, c, scale, dt = self._design
        moving = ac.copy()
        moving[self._iw, self._iw] = -wl
        ad, qd = van_loan(moving, qc, dt)
        s_inv = 1.0 / scale
        ad_s = ad * s_inv[:, None] * scale[None, :]
        qd_s = qd * s_inv[:, None] * s_inv[None, :]
        return ad, ad_s, qd_s, c * scale / self.current_noise_a

    def _moving_gain(self) -> np.ndarray:
        """
        Moving-mode gain (A -> state): Kalman at the floor, K_w for unit in-band gain.

        The steady-state Kalman gain at the floor corner, but for K_w.  With the offset a
        random walk, the optimal K_w (35.8 m/A for the slim sample at the
        defaults; 37.2 m/A without drift) scales every motion by 0.992, flat from 0.2 to
        50 Hz: the posterior w = w_pred + K_w (y - y_pred) inverts the reduced model at
        unit gain for one K_w only, and the in-band gain moves by about 0.6 % per m/A of
        K_w.  That 0.8 % was the Kalman's whole error on a clean crank (the leaky's: 0.2 %
        at 20 Hz).  The offset gain K_b (1e-6 of the others) is kept: it alone separates a
        drifting offset from motion.  K_w is solved (secant) so that the real part of the
        predictor's response times H(j 2 pi f_ref) is 1 at f_ref = motion_bandwidth_hz / 10
        (5 Hz); at 20-50 kHz the optimal K_w is 1.6-2.4 times too small.
        """
        ad, ad_s, qd_s, c_s = self._moving_model(
            2 * math.pi * float(self._sched.corners_hz[self._sched.floor_index]))
        n = ad.shape[0]
        scale = self._design[3]
        try:
            p_s = solve_discrete_are(
                ad_s.T, c_s[:, None], qd_s + 1e-30 * np.eye(n), np.array([[1.0]]))
        except (np.linalg.LinAlgError, ValueError) as exc:
            raise ParameterError(
                f'Kalman design failed at sample_rate_hz = {self._fs:g} ({exc}); '
                'use estimator: leaky or a lower sample rate'
            ) from None
        k = p_s @ c_s / (c_s @ p_s @ c_s + 1.0) * scale / self.current_noise_a
        f_ref = min(self.motion_bandwidth_hz, self._fs / 20) / 10
        h = complex(self.reduced.transfer(np.array([2j * math.pi * f_ref]))[0])
        z = complex(np.exp(2j * math.pi * f_ref / self._fs))
        c, iw = self._c, self._iw

        def in_band_gain(k_w):
            kk = k.copy()
            kk[iw] = k_w
            ikc = np.eye(n) - np.outer(kk, c)
            resp = ikc[iw] @ np.linalg.solve(z * np.eye(n) - ad @ ikc, ad @ kk) + k_w
            return (resp * h).real - 1.0

        # the gain is affine in K_w (measured): secant steps converge in one or two
        k0, k1 = k[iw], 1.1 * k[iw]
        g0, g1 = in_band_gain(k0), in_band_gain(k1)
        for _ in range(6):
            if g1 == g0 or abs(g1) < 1e-9:
                break
            k0, g0, k1 = k1, g1, k1 - g1 * (k1 - k0) / (g1 - g0)
            g1 = in_band_gain(k1)
        if not (abs(g1) < 1e-6 and k1 > 0):
            raise ParameterError(
                f'Kalman design: no deflection gain gives unit gain at {f_ref:g} Hz '
                f'(sample_rate_hz = {self._fs:g}; left {g1:.3g}); use estimator: leaky'
            )
        k[iw] = k1
        return k

    def _moving_mode(self, wl, gain) -> '_Mode':
        """Predictor of the moving model with leak wl (rad/s) and ``gain``, its w std."""
        ad, ad_s, qd_s, c_s = self._moving_model(wl)
        n, scale = ad.shape[0], self._design[3]
        # error covariance of a fixed gain: P = F P F' + A K K' A' + Q, F = A (I - K C)
        k_s = np.asarray(gain, float) * self.current_noise_a / scale
        ikc = np.eye(n) - np.outer(k_s, c_s)
        ak = ad_s @ k_s
        p_s = solve_discrete_lyapunov(ad_s @ ikc, qd_s + np.outer(ak, ak), method='bilinear')
        post = ikc @ p_s @ ikc.T + np.outer(k_s, k_s)
        mode = _Mode(ad, np.asarray(gain, float), self._c, self._iw, self._ib, scale)
        mode.leak_a = math.exp(-wl / self._fs)      # w's decay per sample (see _enter_rest)
        mode.std_m = float(math.sqrt(max(post[self._iw, self._iw], 0.0)) * scale[self._iw])
        return mode

    # -- properties -----------------------------------------------------------
    @property
    def sample_rate_hz(self) -> float:
        return self._fs

    @property
    def offset_a(self) -> float:
        """Return the current offset estimate, A."""
        return self._b_last

    @property
    def offset_corner_while_moving_hz(self) -> float:   # see offset_corner_hz
        return offset_corner_hz(
            self.reduced,
            self.motion_velocity_m_s,
            self.motion_bandwidth_hz,
            self.offset_drift_a_per_s,
        )

    # -- streaming ------------------------------------------------------------
    def reset(self) -> None:
        """Zero deflection, zero offset, moving mode."""
        self._s = np.zeros(self._n)
        self._bp_zi = np.zeros((self._bp.shape[0], 2))
        # start as if just moving: rest is entered only after ~rest_window_s of quiet current
        self._w_ref = 0.0
        self._seen_rest = False
        self._offset_learned = False      # learned from whole periods of motion (no rest)
        # sample (since the reset) at which the offset, hence the level, was first known
        self.level_known_n: int | None = None
        self._lp = 0.0
        # the detector starts undecided (at the leave threshold): motion crosses it at once;
        # rest needs rest_window_s of quiet current (the first samples' energy is no average)
        self._energy = self.rest_leave * self.noise_energy_a2
        # the motion segment since the last rest (or the start): [leak loss L (m), samples,
        # offset b_ref the filter used, its variance P0]; None once a periodic update
        # corrected it.  See _enter_rest.
        self._seg: list | None = [0.0, 0, 0.0, OFFSET_PRIOR_A ** 2]
        # (absolute w, L, segment samples, samples since) at the last sample the detector saw
        # motion: the record's start counts as one (w = 0)
        self._quiet = (0.0, 0.0, 0, 0)
        # through a rest: (level, C, b_ref) of the held-level correction, the rest's samples
        self._held_fix = None
        self._rest_own_n = 0
        self._offset_var = OFFSET_PRIOR_A ** 2
        # at rest the offset's weight is a sample count (its variance = sigma^2 / count with the
        # noise measured at each sample, so blocks and single samples agree); None while moving
        self._offset_n: float | None = None
        self._sigma2 = self.current_noise_a ** 2
        self._sig2_seq = None
        self._hp_zi = np.zeros((2 if self._hp is None else self._hp.shape[0], 2))
        self._nz_zi = np.zeros((2, 2))
        # white-noise energies: averages from zero over the samples measured so far (see
        # _unbias), so the level is known within tens of samples of the start
        self._nz_energy = self._hf_energy = 0.0
        self._noise_n = 0
        self.at_rest = False
        self._b_last = 0.0
        self.last_std = self._moving_start.std_m
        self.last_rest = np.zeros(0, bool)
        self._sched.reset()
        self._periodic.reset()
        self._motion_prior = (0.0, self._offset_var)    # offset and variance as motion began
        self._hf_seq = None
        self._trend = None                # (S1, S2) of the rest's level-and-trend average
        # the last rest samples and the offset before each (see _rewind)
        self._rest_y = deque(maxlen=self._rewind_n)
        self._rest_b = deque(maxlen=self._rewind_n)

    def _clip_a2(self) -> float:
        """
        Cap on one sample's band energy (ENERGY_CLIP times the noise's).

        a large pulse then delays rest by at most rest_window_s * ln(ENERGY_CLIP /
        rest_enter) (0.35 s).
        """
        return ENERGY_CLIP * self._sigma2 * self._bp_unit

    def _start_filters(self, y0: float) -> None:
        """
        Detector filters in the steady state of a constant ``y0`` (the first sample).

        A DAQ offset is then no step at t = 0: a 1 uA offset would otherwise ring the
        band-pass and noise filters at hundreds of nA as the record starts.
        """
        self._bp_zi = self._bp_zi1 * y0
        if self._hp is not None:
            self._hp_zi = self._hp_zi1 * y0
            self._nz_zi = self._nz_zi1 * y0

    def _unbias(self, n):
        """
        Factor that turns the noise averages after n samples into means (n: int or array).

        The averages start from zero with weight (1 - alpha) per sample; after n samples
        the weights sum to 1 - alpha^n (the bias correction of zero-started moving averages).
        The noise level is then measured from the first samples on, not pulled from
        ``current_noise_a`` over ``NOISE_WINDOW_S``: a record whose noise is 12 times the
        configured one was taken for motion for its first 0.3 s, in rest/motion flickers
        that walked w by 20-40 um before the first rest.
        """
        if isinstance(n, int):          # one sample (process_one): no numpy on the hot path
            return 1.0 if n >= self._settled_n else 1.0 / -math.expm1(n * self._log_ah)
        if n[0] >= self._settled_n:
            return 1.0
        return 1.0 / -np.expm1(np.asarray(n, float) * self._log_ah)

    def _dc_limit_a2(self) -> float:
        """
        Largest squared departure of the low-passed current that still counts as rest.

        The departure is from the offset estimate; the limit is (4 sigma)^2 of that
        difference, sigma^2 = the mean's noise sigma^2/(2 fs rest_window_s) + the offset's
        variance P_b (+ 2 nA for the reduction/drift).  A deflection ramp of v m/s gives
        R0 v of steady current.
        """
        return 16.0 * (
            self._sigma2 / (2 * self._fs * self.rest_window_s) + self._offset_var + 4e-18
        )

    def _rest_flags(self, y: np.ndarray):
        """(at rest per sample, detector verdict per sample: 0 motion, 1 quiet, -1 between)."""
        if self._sched.count == 0:
            self._start_filters(float(y[0]))
        # single-section filters run by lfilter (same DF-II-T state as sosfilt, less overhead)
        band, zf = sig.lfilter(self._bp[0, :3], self._bp[0, 3:], y, zi=self._bp_zi[0])
        self._bp_zi[0] = zf
        a = self._alpha
        floor = self.noise_energy_a2
        if self._hp is not None and self.rest_detection:
            # measured white-noise floor (never below the configured DAQ noise)
            high, zf = sig.lfilter(self._hp[0, :3], self._hp[0, 3:], y, zi=self._hp_zi[0])
            self._hp_zi[0] = zf
            ah = self._alpha_hf
            hf, zf = sig.lfilter(
                [1 - ah],
                [1, -ah],
                np.minimum(high * high, self._hf_clip),
                zi=[ah * self._hf_energy],
            )
            unbias = self._unbias(self._noise_n + np.arange(1, y.size + 1))
            self._noise_n += y.size
            hf_raw_end = float(zf[0] / ah)
            hf = hf * unbias
            # the noise level each sample sees is the one measured up to the sample before
            sigma2 = np.maximum(
                self.current_noise_a**2, np.concatenate([[self._sigma2], hf[:-1] / self._hp_unit])
            )
            self._hf_energy = hf_raw_end
            sq = np.minimum(band * band, ENERGY_CLIP * self._bp_unit * sigma2)
            e, zf = sig.lfilter([1 - a], [1, -a], sq, zi=[a * self._energy])
            self._energy = float(zf[0] / a)
            floor = np.maximum(floor, hf * self._hp_ratio)
            self._sigma2 = max(self.current_noise_a ** 2, float(hf[-1]) / self._hp_unit)
            # the measured noise after each sample, as process_one sees it (see _run_rest)
            self._sig2_seq = np.maximum(self.current_noise_a ** 2, hf / self._hp_unit)
            # the leak schedule's noise level after each sample (see _sigma2_at)
            high, self._nz_zi = sig.sosfilt(self._nz, y, zi=self._nz_zi)
            nz2 = np.minimum(high * high, self._nz_clip)
            hf_seq, zf = sig.lfilter([1 - ah], [1, -ah], nz2, zi=[ah * self._nz_energy])
            self._hf_seq = hf_seq * unbias
            self._nz_energy = float(zf[0] / ah)
        else:
            self._hf_seq = self._sig2_seq = None
            e, zf = sig.lfilter([1 - a], [1, -a], np.minimum(band * band, self._clip_a2()),
                                zi=[a * self._energy])
            self._energy = float(zf[0] / a)
        # low-passed current against the offset estimate (a slow ramp is a steady current
        # the band-pass does not see, H(0) = 0): see _dc_limit_a2
        lp, zf = sig.lfilter([1 - a], [1, -a], y, zi=[a * self._lp])
        self._lp = float(zf[0] / a)
        if not self.rest_detection:
            return np.zeros(y.size, bool), np.zeros(y.size, np.int8)
        # leave rest on the averaged energy, or at once on one sample beyond 6 sigma of the
        # in-band noise (false alarm 2e-9 per sample), so a sudden move never feeds the offset
        dc = lp - self._b_last
        moving = (
            (e > self.rest_leave * floor)
            | (band * band > 36.0 * floor)
            | (dc * dc > self._dc_limit_a2())
        )
        quiet = e < self.rest_enter * floor
        first = self._rest_min_n - self._sched.count
        if first > 0:                    # no rest before the average has formed (see reset)
            quiet[:first] = False
        code = np.where(moving, 0, np.where(quiet, 1, -1))
        idx = np.where(code >= 0, np.arange(y.size), -1)
        np.maximum.accumulate(idx, out=idx)
        flags = np.where(idx >= 0, code[np.maximum(idx, 0)] == 1, self.at_rest)
        return flags, code

    def process_with_std(self, current_a):
        """(deflection m, its standard deviation m) for a block of current samples."""
        y = np.asarray(current_a, dtype=float)
        if y.ndim == 2 and y.shape[1] == 1:
            y = y[:, 0]
        if y.ndim != 1:
            raise ParameterError(f'expected shape (n,) or (n, 1), got {y.shape}')
        if y.size == 0:
            return np.empty(0), np.empty(0)
        was_rest = self.at_rest
        flags, code = self._rest_flags(y)
        self.last_rest = flags
        cuts = np.flatnonzero(np.diff(flags.astype(np.int8))) + 1
        bounds = [0, *cuts.tolist(), y.size]
        out = np.empty(y.size)
        count0 = self._sched.count
        for lo, hi in zip(bounds[:-1], bounds[1:]):
            if flags[lo]:
                if not was_rest:
                    self._enter_rest()
                self._level_known_at(count0 + lo)
                out[lo:hi] = self._run_rest(y[lo:hi], lo)
            else:
                if was_rest:                              # leaving rest: leak towards this level
                    self._leave_rest()
                self._run_moving(y, lo, hi, out, count0, code)
            was_rest = bool(flags[lo])
        self._sched.count = count0 + y.size
        self.at_rest = bool(flags[-1])
        self.last_std = self._mode().std_m
        return out, np.full(y.size, self.last_std)

    def _enter_rest(self) -> None:
        """
        Hold the deflection at its smoothed estimate where the detector last saw motion.

        The detector confirms rest only after ``rest_window_s`` (times ln(rest_leave /
        rest_enter)) of quiet current; over those samples the moving filter integrated only
        noise and the offset's error (a random walk and a ramp: the record's first 0.6 s
        ramped w by 47 um for a 25 nA offset, slim, and a rest held it).  The estimate at the
        last sample with motion (the record's start: 0) is kept instead, when at most
        ``QUIET_REWIND_MAX_S`` ago.

        The rest then smooths the motion segment that ended (a fixed-interval smoother run
        once, at the rest), for two errors the causal filter had to accept while moving:

        - *the leak*: w only feeds the output (C has no w term), so the leak-free estimate is
          w + L, L the sum of what the leak removed, (1 - a) w per sample (a = exp(-w_l /
          fs)).  The 0.001 Hz leak took 38 um of an 8 s move to +1 mm; before the first
          rest the 0.02 Hz leak took 21 % of a 3 s move to 1 mm (both slim, tested).
        - *the offset*: the segment ran with offset b_ref (variance P0); the rest learns b.
          With a random-walk offset (intensity q) the smoothed offset error averaged over
          the segment's T seconds is (b - b_ref) (1 + P0 / (P0 + q T)) / 2 (RTS smoother:
          the error at the start is (b - b_ref) P0 / (P0 + q T), at the end b - b_ref,
          linear between): 1 before the first rest (P0 = OFFSET_PRIOR_A^2, a constant
          unknown offset), 1/2 for a pure drift.  As a velocity it ramped w by that times T
          / R0 (H(0) = 0): C = (1 + P0 / (P0 + q T)) T / (2 R0).

        The held level is w + L - (b - b_ref) C with the offset learned so far (see
        :meth:`_run_rest`).  What remains is the noise walk of the leak-free integral
        (measured 10 um after an 8 s move at 20 nA, slim).  A segment corrected
        by a periodic update (:meth:`_periodic_update`) is not smoothed again.
        """
        w_q, l_q, n_seg, since = self._quiet
        seg = self._seg
        iw = self._iw
        if since > self._quiet_max_n:
            w_q = float(self._s[iw]) + self._w_ref
            l_q, n_seg = (seg[0], seg[1]) if seg is not None else (0.0, 0)
        level = w_q + l_q
        self._s[iw] = level                               # rest holds the absolute deflection
        self._w_ref = 0.0
        self._held_fix = None
        if seg is not None and n_seg:
            p0 = seg[3]
            c = 0.5 * (1.0 + p0 / (p0 + self._q_b_step * n_seg)) * n_seg * self._ramp_step
            self._held_fix = (level, c, seg[2])
        self._seg = None
        self._rest_own_n = 0
        self._seen_rest = True

    def _leave_rest(self) -> None:
        """Re-reference w to the held level, slowest allowed corner, rewind (see _rewind)."""
        self._w_ref = float(self._s[self._iw])
        self._s[self._iw] = 0.0
        self._held_fix = None
        self._trend = None
        self._offset_n = None
        sch = self._sched
        sch.moving_n = 0          # J at t = 0 is the leak term alone: the slowest corner
        self._periodic.reset()    # a new motion segment
        self._motion_prior = (float(self._s[self._ib]), self._offset_var)
        sch.index = int(self._floor_index(self._offset_var))
        self._rewind()
        sch.u_prev = float(self._s[self._iw])
        # a new segment, relative to the offset the moving filter starts from (see _enter_rest)
        self._seg = [0.0, 0, float(self._s[self._ib]), self._offset_var]

    def _floor_index(self, offset_var):
        """
        Slowest allowed ladder index (per value of ``offset_var``, scalar or array).

        leak_corner_hz only while the offset is known to OFFSET_TRUSTED_A RMS (learned at
        rest or from whole periods, its variance growing by the drift during motion); else
        START_LEAK_CORNER_HZ (an offset error db ramps w by db / R0 per second).
        """
        trusted = self._offset_known & (np.asarray(offset_var) < OFFSET_TRUSTED_A ** 2)
        return np.where(trusted, self._sched.floor_index, self._sched.start_index)

    def _choose(self, stats, sigma2, offset_var, moving_n) -> np.ndarray:
        """Leak corner indices for the motion so far (LeakSchedule.choose, vectorised)."""
        # before the first rest the offset is not observable: its term is left out
        p_b = offset_var if self._offset_known else 0.0
        return self._sched.choose(stats, sigma2, p_b, self._floor_index(offset_var), moving_n)

    def _sigma2_at(self, k):
        """Measured noise variance after sample(s) k of the present block (as process_one)."""
        if self._hf_seq is None:
            return self._noise_var()
        return np.maximum(self.current_noise_a ** 2, self._hf_seq[k] / self._nz_unit)

    def _sigma2_one(self) -> float:
        """Measured noise variance after the present sample (process_one)."""
        if self._hp is None or not self.rest_detection:
            return self._noise_var()
        return max(self.current_noise_a ** 2,
                   self._nz_energy * self._unbias(self._noise_n) / self._nz_unit)

    def _run_moving(
        self, y: np.ndarray, lo: int, hi: int, out: np.ndarray, count0: int, code: np.ndarray
    ):
        """
        Moving-mode filter over y[lo:hi], cut at the decision grid.

        ``code``: the detector's verdict per sample (0 motion); the estimate at the last
        motion sample is kept for :meth:`_enter_rest`.

        At each grid point (every ``leak_schedule.STEP_S`` of samples) the offset is updated
        from whole periods of the motion when it is periodic (:meth:`_periodic_update`) and
        the leak corner re-chosen, as :meth:`process_one` does at the same samples.
        """
        sch = self._sched
        q = self._q_b_step
        pos = lo
        while pos < hi:
            phase = (count0 + pos) % sch.step
            if phase == 0:
                sigma2 = float(self._sigma2_at(pos))
                self._periodic_update(sigma2, count0 + pos)
                sch.index = int(self._choose(
                    sch.stats, sigma2, self._offset_var, sch.moving_n)[0])
            cut = min(hi, pos + sch.step - phase)
            n = cut - pos
            mode = self._mode()
            w, b_last, s_end = mode.run(y[pos:cut], self._s)
            seq = sch.stats_sequence(w)
            out[pos:cut] = w + self._w_ref
            self._track_segment(w, out[pos:cut], code[pos:cut], mode.leak_a)
            self._b_last, self._s = b_last, s_end
            sch.stats = seq[:, n - 1].copy()
            sch.u_prev = float(w[-1])
            sch.moving_n += n
            self._offset_var += q * n
            self._periodic.extend(y[pos:cut], w)
            pos = cut

    def _track_segment(self, w, out, code, a) -> None:
        """Leak loss, segment length and the last motion sample (see _enter_rest)."""
        seg = self._seg
        motion = np.flatnonzero(code == 0)
        n = w.size
        if seg is not None:
            csum = np.cumsum(w)
            if motion.size:
                j = int(motion[-1])
                self._quiet = (float(out[j]), seg[0] + (1.0 - a) * float(csum[j] - w[j]),
                               seg[1] + j + 1, n - 1 - j)
            seg[0] += (1.0 - a) * float(csum[-1])
            seg[1] += n
        elif motion.size:
            j = int(motion[-1])
            self._quiet = (float(out[j]), 0.0, 0, n - 1 - j)
        if not motion.size:
            w_q, l_q, n_seg, since = self._quiet
            self._quiet = (w_q, l_q, n_seg, since + n)

    @property
    def _offset_known(self) -> bool:
        """Whether the offset has been observed: at rest or from whole periods of motion."""
        return self._seen_rest or self._offset_learned

    def _level_known_at(self, n: int) -> None:
        """Note sample n as the first where the level is known (if it is the first)."""
        if self.level_known_n is None:
            self.level_known_n = n

    def _periodic_update(self, sigma2: float, n: int) -> None:
        """
        Offset from whole periods of the motion since it began, if it is periodic.

        :mod:`~.periodic_offset` gives b_p with variance R_p from the last window; it is
        fused with the offset known when the motion began (b_0, variance P_0 grown by the
        drift since): b = (b_0 R_p + b_p P_0) / (P_0 + R_p), as a Kalman update (the
        windows of successive updates overlap, so each update starts from b_0).  w is
        corrected as if the new offset had been used over the whole periods the estimate
        spans (t = min(time moving, k P)): an offset error db ramped it by db / R0 per
        second through the leak w_l, i.e. by db (1 - exp(-w_l t)) / (w_l R0).  (Over the
        whole motion, the noise of successive estimates would be multiplied by its length.)
        Before the first rest the level is unknown and the leak pulls w towards w_ref; a
        periodic motion is then taken to oscillate about w_ref at once (its mean over the
        same whole periods, corrected alike, is removed).  ``n``: the sample counter now.
        """
        found = self._periodic.estimate(math.sqrt(sigma2))
        if found is None:
            return
        b_p, r_p, _, mean_u, span_s = found
        sch = self._sched
        # fused with the offset known when the motion began (its variance grown by the
        # drift), not with the last update: successive windows overlap
        b0, p0 = self._motion_prior
        p0 += self._q_b_step * sch.moving_n
        iw, ib = self._iw, self._ib
        db = (b0 * r_p + b_p * p0) / (p0 + r_p) - float(self._s[ib])
        wl = 2 * math.pi * sch.corner_hz
        t = min(sch.moving_n / self._fs, span_s)
        ramp = db * -math.expm1(-wl * t) / (wl * self._r0)
        shift = ramp
        if not self._seen_rest:
            # mean over tau in [t - span, t] of the ramp at tau (clipped at the motion's start)
            t0 = max(t - span_s, 0.0)
            mean_ramp = db / (wl * self._r0) * (
                1.0 - (math.exp(-wl * t0) - math.exp(-wl * t)) / (wl * max(t - t0, 1e-12)))
            shift += mean_u - mean_ramp
        self._s[ib] += db
        self._s[iw] -= shift
        self._b_last = float(self._s[ib])
        self._offset_var = p0 * r_p / (p0 + r_p)
        self._offset_learned = True
        self._level_known_at(n)
        # the segment's ramp is corrected here, not smoothed again at the rest
        w_q, _, _, since = self._quiet
        self._quiet = (w_q - shift, 0.0, 0, since)
        self._seg = None
        # the leak schedule's statistics of u follow the shift
        wgt, m, s2, v2 = sch.stats.tolist()
        sch.stats = np.array([wgt, m - shift * wgt, s2 - 2 * shift * m + shift * shift * wgt, v2])
        sch.u_prev -= shift
        self._periodic.shift_u(shift)

    def _noise_var(self) -> float:
        """White-noise variance per sample: the measured one, never below current_noise_a^2."""
        return max(self.current_noise_a ** 2, self._sigma2)

    def _mode(self) -> '_Mode':
        """Moving-mode predictor for the leak corner in use (see _choose)."""
        return self._ladder_mode(self._sched.index)

    @property
    def leak_corner_in_use_hz(self) -> float:
        """Return the deflection leak corner chosen for the motion so far, Hz."""
        return self._sched.corner_hz

    def _rest_sigma2(self, k: int) -> float:
        """Measured noise variance after sample k of the present block (as process_one)."""
        return self._noise_var() if self._sig2_seq is None else float(self._sig2_seq[k])

    def _run_rest(self, y: np.ndarray, lo: int) -> np.ndarray:
        """
        Rest: deflection held, velocity and charge states zero.

        Through a rest the held level is corrected for the ramp the offset's error caused
        in the motion before it (see :meth:`_enter_rest`), with the offset learned so far,
        until the rest's own samples know it to ``OFFSET_TRUSTED_A`` or the running mean is
        full; then held.

        The detector has seen quiet current for ~rest_window_s, many times the sensor's
        memory.  Offset = running mean of the current, weighted by its prior variance
        (n0 = sigma^2 / P_b equivalent samples), then, past ``rest_offset_time_s`` worth of
        samples, a level-and-trend average (Brown's double exponential smoothing, time
        constant ``rest_offset_time_s``): level 2 S1 - S2 of S1 = EMA(i), S2 = EMA(S1).  A
        plain EMA trails a drifting offset by tau * rate (0.17 nA at 1 nA/min with 10 s),
        a steady +0.2 nA that ramps w by 0.6 um per second of the next motion (the 1-hour
        row's error grew by that); the level follows a linear drift without lag, at about
        2.5 times the EMA's variance (0.2 nA RMS for 20 nA noise and 10 s).
        """
        s_end = self._s.copy()
        s_end[self._motion_idx] = 0.0       # at rest nothing moves: no predicted motion current
        w = np.full(y.size, s_end[self._iw])
        u = y
        b0 = self._s[self._ib]
        # weight of the offset so far: carried as a count through a rest (see reset), converted
        # from its variance with the noise at the rest's first sample
        n0 = (self._rest_sigma2(lo) / self._offset_var if self._offset_n is None
              else self._offset_n)
        counts = n0 + np.arange(1, y.size + 1)
        first = self._held_fix
        b_seq = None
        if counts[-1] <= self._n_max:
            if first is None:
                b = (n0 * b0 + float(np.sum(u))) / counts[-1]
            else:
                b_seq = (n0 * b0 + np.cumsum(u)) / counts
                b = float(b_seq[-1])
            n_end = counts[-1]
        else:
            k = max(0, int(math.floor(self._n_max - n0)))
            b = (n0 * b0 + float(np.sum(u[:k]))) / (n0 + k) if k > 0 else b0
            g = 1.0 / (self._n_max + 1.0)
            s1, s2 = (b, b) if self._trend is None else self._trend
            s1_seq, _ = sig.lfilter([g], [1.0, -(1.0 - g)], u[k:], zi=[(1.0 - g) * s1])
            s2_seq, _ = sig.lfilter([g], [1.0, -(1.0 - g)], s1_seq, zi=[(1.0 - g) * s2])
            self._trend = (float(s1_seq[-1]), float(s2_seq[-1]))
            b = 2.0 * self._trend[0] - self._trend[1]
            n_end = self._n_max
            if first is not None:
                b_seq = np.concatenate([(n0 * b0 + np.cumsum(u[:k])) / counts[:k],
                                        2.0 * s1_seq - s2_seq])
        if first is not None:
            # the level less the ramp of the offset learned so far (see _enter_rest), until
            # this rest alone knows the offset to OFFSET_TRUSTED_A or its average is full
            level, c, b_ref = first
            w = level - (b_seq - b_ref) * c
            sig2 = (np.full(y.size, self._noise_var()) if self._sig2_seq is None
                    else self._sig2_seq[lo:lo + y.size])
            own = self._rest_own_n + np.arange(1, y.size + 1)
            done = np.flatnonzero(
                (counts >= self._n_max) | (sig2 < OFFSET_TRUSTED_A ** 2 * own))
            if done.size:
                w[done[0]:] = w[done[0]]
                self._held_fix = None
            s_end[self._iw] = w[-1]
        self._rest_own_n += y.size
        s_end[self._ib] = b
        self._remember_rest(y, b0, n0)
        self._s = s_end
        self._b_last = b
        self._offset_n = n_end
        self._offset_var = self._rest_sigma2(lo + y.size - 1) / n_end
        return w

    def _remember_rest(self, y: np.ndarray, b0: float, n0: float) -> None:
        """Keep the last rest samples and the offset estimate before each of them."""
        m = min(y.size, self._rewind_n)
        lo = y.size - m
        # offset before sample k: the running mean of the samples before k (weight n0 on b0);
        # past n_max samples the rest offset is a level-and-trend average: no rewind then
        counts = np.minimum(n0 + np.arange(lo, y.size), self._n_max)
        csum = np.concatenate([[0.0], np.cumsum(y)])[lo:y.size]
        b_before = np.where(
            n0 + np.arange(lo, y.size) <= self._n_max,
            (n0 * b0 + csum) / np.maximum(counts, 1e-300),
            np.nan,
        )
        if np.any(np.isnan(b_before)):
            b_before = np.full(m, np.nan)         # long rest: rewind to the start value below
        self._rest_y.extend(y[lo:].tolist())
        self._rest_b.extend(b_before.tolist())

    def _rewind(self) -> None:
        """
        Re-run the last rest samples in the moving mode on leaving rest.

        The state is already re-referenced; the offset is restored to its value before
        the remembered samples.
        """
        if not self._rest_y:
            return
        b_start = self._rest_b[0]
        ys = np.array(self._rest_y)
        self._rest_y.clear()
        self._rest_b.clear()
        if not math.isfinite(b_start):
            return
        self._s[self._ib] = b_start
        _, _, self._s = self._mode().run(ys, self._s)

    def process(self, current_a) -> np.ndarray:
        """Deflection, m, for a block of current samples (A); see :meth:`process_with_std`."""
        w, _ = self.process_with_std(current_a)
        return w

    def process_one(self, current_a: float) -> float:
        """
        One sample, as a float.

        The same recursion as :meth:`process` written for a single sample (no per-call
        lfilter costs); equal to it to rounding (tested).
        """
        y = float(current_a)
        x = y
        if self._sched.count == 0:
            self._start_filters(y)
        b0, b1, b2, _, a1, a2 = self._bp_list
        zi = self._bp_zi
        z0, z1 = zi.item(0), zi.item(1)
        band = b0 * x + z0
        zi[0] = (b1 * x - a1 * band + z1, b2 * x - a2 * band)
        a = self._alpha
        e = a * self._energy + (1 - a) * min(band * band, self._clip_a2())
        self._energy = e
        floor = self.noise_energy_a2
        if self._hp is not None and self.rest_detection:
            h0, h1, h2, _, g1, g2 = self._hp_list
            hz = self._hp_zi
            y0, y1 = hz.item(0), hz.item(1)
            high = h0 * x + y0
            hz[0] = (h1 * x - g1 * high + y1, h2 * x - g2 * high)
            ah = self._alpha_hf
            self._hf_energy = ah * self._hf_energy + (1 - ah) * min(high * high, self._hf_clip)
            self._noise_n += 1
            hf = self._hf_energy * self._unbias(self._noise_n)
            floor = max(floor, hf * self._hp_ratio)
            self._sigma2 = max(self.current_noise_a ** 2, hf / self._hp_unit)
            nz = x
            for hz, (h0, h1, h2, _, g1, g2) in zip(self._nz_zi, self._nz_list):
                y0, y1 = hz.item(0), hz.item(1)
                inp, nz = nz, h0 * nz + y0
                hz[0], hz[1] = h1 * inp - g1 * nz + y1, h2 * inp - g2 * nz
            self._nz_energy = ah * self._nz_energy + (1 - ah) * min(nz * nz, self._nz_clip)
        was_rest = self.at_rest
        sch = self._sched
        self._lp = lp = a * self._lp + (1 - a) * x
        motion = True
        if self.rest_detection:
            dc = lp - self._b_last
            if (
                e > self.rest_leave * floor
                or band * band > 36.0 * floor
                or dc * dc > self._dc_limit_a2()
            ):
                self.at_rest = False
            else:
                motion = False
                if e < self.rest_enter * floor and sch.count >= self._rest_min_n:
                    self.at_rest = True
        iw, ib = self._iw, self._ib
        if self.at_rest and not was_rest:
            self._enter_rest()
        elif was_rest and not self.at_rest:
            self._leave_rest()
        st = self._s.tolist()
        if self.at_rest:
            self._level_known_at(sch.count)
            for j in self._motion_idx.tolist():
                st[j] = 0.0
            n0 = (self._noise_var() / self._offset_var if self._offset_n is None
                  else self._offset_n)
            self._rest_y.append(y)
            self._rest_b.append(st[ib] if n0 + 1.0 <= self._n_max else math.nan)
            n1 = min(n0 + 1.0, self._n_max)
            if n0 + 1.0 <= self._n_max:
                b = st[ib] + (y - st[ib]) / n1
            else:                               # level-and-trend average (see _run_rest)
                g = 1.0 / (self._n_max + 1.0)
                s1, s2 = (st[ib], st[ib]) if self._trend is None else self._trend
                s1 += g * (y - s1)
                s2 += g * (s1 - s2)
                self._trend = (s1, s2)
                b = 2.0 * s1 - s2
            new = st
            fix = self._held_fix
            self._rest_own_n += 1
            if fix is None:
                w = st[iw]
            else:                               # see _run_rest
                w = new[iw] = fix[0] - (b - fix[2]) * fix[1]
                if (n0 + 1.0 >= self._n_max
                        or self._noise_var() < OFFSET_TRUSTED_A ** 2 * self._rest_own_n):
                    self._held_fix = None
            new[ib] = b
            self._b_last = b
            self._offset_n = n1
            self._offset_var = self._noise_var() / n1
        else:
            if sch.count % sch.step == 0:
                sigma2 = self._sigma2_one()
                self._periodic_update(sigma2, sch.count)
                st = self._s.tolist()
                sch.index = int(self._choose(sch.stats, sigma2, self._offset_var,
                                             sch.moving_n)[0])
            mode = self._mode()
            innov = y - sum(map(mul, self._c_list, st))
            u = st[iw] + mode.k_w * innov
            w = u + self._w_ref
            seg = self._seg                     # see _track_segment
            if seg is not None:
                seg[1] += 1
                if motion:
                    self._quiet = (w, seg[0], seg[1], 0)
                seg[0] += (1.0 - mode.leak_a) * u
            elif motion:
                self._quiet = (w, 0.0, 0, 0)
            if not motion:
                w_q, l_q, n_seg, since = self._quiet
                self._quiet = (w_q, l_q, n_seg, since + 1)
            self._b_last = st[ib] + mode.k_b * innov
            new = [sum(map(mul, row, st)) + g * y for row, g in zip(mode.f_rows, mode.g_list)]
            self._offset_var += self._q_b_step
            sch.update_one(u)
            self._periodic.add_one(y, u)
        sch.count += 1
        self._s[:] = new
        return w

    def get_state(self) -> dict:
        return {
            's': self._s.copy(),
            'bp_zi': self._bp_zi.copy(),
            'energy': self._energy,
            'at_rest': self.at_rest,
            'offset_a': self._b_last,
            'w_ref': self._w_ref,
            'hp_zi': self._hp_zi.copy(),
            'hf_energy': self._hf_energy,
            'nz_zi': self._nz_zi.copy(),
            'nz_energy': self._nz_energy,
            'noise_n': self._noise_n,
            'offset_var': self._offset_var,
            'offset_n': self._offset_n,
            'sigma2': self._sigma2,
            'lp': self._lp,
            'seen_rest': self._seen_rest,
            'offset_learned': self._offset_learned,
            'level_known_n': self.level_known_n,
            'periodic': self._periodic.get_state(),
            'motion_prior': self._motion_prior,
            'leak': self._sched.get_state(),
            'trend': self._trend,
            'quiet': self._quiet,
            'segment': None if self._seg is None else list(self._seg),
            'held_fix': self._held_fix,
            'rest_own_n': self._rest_own_n,
            'rest_tail': (list(self._rest_y), list(self._rest_b)),
        }

    def set_state(self, state: dict) -> None:
        s = np.asarray(state.get('s'), float)
        if s.shape != self._s.shape or not np.all(np.isfinite(s)):
            raise ParameterError(
                f'state shape {s.shape} does not match {self._s.shape} or is not finite'
            )
        self._s = s.copy()
        self._bp_zi = np.asarray(state['bp_zi'], float).copy()
        self._energy = float(state['energy'])
        self.at_rest = bool(state['at_rest'])
        self._b_last = float(state['offset_a'])
        self._w_ref = float(state['w_ref'])
        self._hp_zi = np.asarray(state['hp_zi'], float).copy()
        self._hf_energy = float(state['hf_energy'])
        if 'nz_zi' in state:
            self._nz_zi = np.asarray(state['nz_zi'], float).copy()
            self._nz_energy = float(state['nz_energy'])
        self._noise_n = int(state.get('noise_n', 10 ** 9))
        self._offset_var = float(state['offset_var'])
        n = state.get('offset_n')
        self._offset_n = None if n is None else float(n)
        self._sigma2 = float(state['sigma2'])
        self._lp = float(state['lp'])
        self._seen_rest = bool(state['seen_rest'])
        self._offset_learned = bool(state.get('offset_learned', False))
        known = state.get('level_known_n')
        self.level_known_n = None if known is None else int(known)
        if 'periodic' in state:
            self._periodic.set_state(state['periodic'])
            self._motion_prior = tuple(float(v) for v in state['motion_prior'])
        if 'leak' in state:
            self._sched.set_state(state['leak'])
        trend = state.get('trend')
        self._trend = None if trend is None else (float(trend[0]), float(trend[1]))
        if 'quiet' in state:
            w_q, l_q, n_seg, since = state['quiet']
            self._quiet = (float(w_q), float(l_q), int(n_seg), int(since))
            seg = state['segment']
            self._seg = None if seg is None else [float(seg[0]), int(seg[1]), float(seg[2]),
                                                  float(seg[3])]
            fix = state['held_fix']
            self._held_fix = None if fix is None else tuple(float(v) for v in fix)
            self._rest_own_n = int(state['rest_own_n'])
        if 'rest_tail' in state:          # the rest samples a move would rewind (see _rewind)
            ys, bs = state['rest_tail']
            self._rest_y.clear()
            self._rest_b.clear()
            self._rest_y.extend(float(v) for v in ys)
            self._rest_b.extend(float(v) for v in bs)

    def current_output(self) -> np.ndarray:
        """Deflection held in the predicted state (per channel), m."""
        return np.array([self._s[self._iw] + self._w_ref])

    def continue_from(self, old, recent_input=None) -> None:
        """
        Take over ``old``'s deflection and offset (bumpless).

        The fast states are rebuilt by replaying ``recent_input`` (then deflection
        and offset are reset to ``old``'s).
        """
        self.reset()
        if recent_input is not None and np.size(recent_input):
            self.process(np.asarray(recent_input, float).reshape(-1))
        if isinstance(old, KalmanEstimator):
            self._s[self._iw] = old._s[old._iw]
            self._w_ref = old._w_ref
            self._seen_rest = old._seen_rest
            self._offset_learned = old._offset_learned
            if old.level_known_n is not None:
                self.level_known_n = 0         # known from this estimator's first sample
            if old._fs == self._fs:
                self._periodic.set_state(old._periodic.get_state())
            self._motion_prior = old._motion_prior
            self._offset_var = old._offset_var
            self._offset_n = old._offset_n
            self._s[self._ib] = old._s[old._ib]
            self._b_last = old._b_last
            self.at_rest = old.at_rest
            self._energy = old._energy
            # the motion statistics and the corner in use (the nearest of this ladder)
            self._sched.set_state(old._sched.get_state())
            self._trend = old._trend
            self._quiet, self._held_fix = old._quiet, old._held_fix
            self._seg = None if old._seg is None else list(old._seg)
            self._rest_own_n = old._rest_own_n
            ladder = self._sched.corners_hz
            self._sched.index = int(np.argmin(np.abs(np.log(ladder / old.leak_corner_in_use_hz))))
        else:
            self._s[self._iw] = float(old.current_output()[0])

    def rebuilt(
        self, reduced: ReducedModel | None = None, recent_input=None, **changes
    ) -> 'KalmanEstimator':
        kwargs = {
            k: getattr(self, k)
            for k in (
                'current_noise_a',
                'motion_velocity_m_s',
                'motion_bandwidth_hz',
                'leak_corner_hz',
                'offset_drift_a_per_s',
                'rest_offset_time_s',
                'rest_window_s',
                'rest_enter',
                'rest_leave',
                'rest_detection',
            )
        }
        kwargs['sample_rate_hz'] = self._fs
        kwargs.update(changes)
        fs = kwargs.pop('sample_rate_hz')
        new = KalmanEstimator(reduced or self.reduced, fs, **kwargs)
        new.continue_from(self, recent_input)
        return new
