# SPDX-License-Identifier: Apache-2.0
"""
Discrete, stable inverse of a reduced sensing model: current (A) -> deflection (m).

The leaky inverse ``1/((s + w_c) R_n(s))`` [* ``s/(s + w_o)``] is designed in
:mod:`.leaky_design` (derivation and the leak trade-off there).

Discretisation
--------------
Tustin (bilinear) transform with frequency prewarping at ``prewarp_hz``
(default fs/20, capped at the upper edge of the reduction band; see
:mod:`ipmc_sensor_ros.lti.discretize`), applied pole by pole in zpk form and
realised as second-order sections.  Tustin maps the open
left half plane into the unit disc, so stability is preserved for every sample
rate; it is nevertheless checked at construction (every pole strictly inside
the unit circle) and :class:`ParameterError` is raised otherwise.  The
frequency warping error up to fs/10 is below 0.3 dB / 1 deg for these
diffusion-type responses (tested).

Streaming
---------
:class:`InverseEstimator` keeps explicit state (one DF-II-transposed state per
section and channel, as :func:`scipy.signal.sosfilt` uses), so blocks of any
size -- including single samples -- give identical results.  Several channels
are filtered at once (input shape ``(n_samples, n_channels)``).
"""
from __future__ import annotations

import math

import numpy as np
import scipy.signal as sig
from scipy.linalg import schur, solve_sylvester

from ..errors import ParameterError
from ..lti.reduction import ReducedModel
from .core import Estimate, forgets_s
from .leaky_design import DEFAULT_LEAK_CORNER_HZ, design, inverse_zpk, leak_tradeoff, positive

__all__ = ['ParameterError', 'InverseEstimator', 'inverse_zpk', 'leak_tradeoff',
           'DEFAULT_LEAK_CORNER_HZ']

#: Blocks up to this many samples (single channel) are filtered by a plain-Python
#: recursion instead of :func:`scipy.signal.sosfilt` (identical output, lower fixed
#: cost); above it sosfilt's vectorised loop wins (measured crossover ~40 samples).
SMALL_BLOCK_SAMPLES = 16


class InverseEstimator:
    """
    Streaming causal estimator of tip deflection (m) from sensing current (A).

    Parameters
    ----------
    reduced : reduced model of the sensor (:func:`~ipmc_sensor_ros.lti.reduction.reduce_model`).
    sample_rate_hz : sample rate of the current, Hz.
    leak_corner_hz : leaky-integration corner f_c, Hz (> 0).
    offset_corner_hz : corner of the optional current-offset tracker, Hz, or None.
    prewarp_hz : Tustin prewarping frequency, Hz (default min(band high, fs/20)).
    channels : number of independent channels filtered together.

    """

    def __init__(self, reduced: ReducedModel, sample_rate_hz: float,
                 leak_corner_hz: float = DEFAULT_LEAK_CORNER_HZ,
                 offset_corner_hz: float | None = None, prewarp_hz: float | None = None,
                 channels: int = 1):
        if (
            isinstance(channels, bool)
            or not isinstance(channels, (int, np.integer))
            or channels < 1
        ):
            raise ParameterError(
                f"parameter 'channels' must be a positive integer, got {channels!r}"
            )
        self.reduced = reduced
        self.leak_corner_hz = positive('leak_corner_hz', leak_corner_hz)
        self.offset_corner_hz = positive('offset_corner_hz', offset_corner_hz, allow_none=True)
        self.channels = int(channels)
        self._slow_cache = None
        self._design = design(reduced, sample_rate_hz, self.leak_corner_hz,
                              self.offset_corner_hz, prewarp_hz)
        self._zi = np.zeros((self.sos.shape[0], 2, self.channels))
        # (b0, b1, b2, a1, a2) per section as Python floats (a0 = 1 from tustin_sos)
        self._coefficients = [tuple(row) for row in (self.sos[:, [0, 1, 2, 4, 5]]
                                                     / self.sos[:, 3:4]).tolist()]

    # -- properties ---------------------------------------------------------
    @property
    def sos(self) -> np.ndarray:
        """Second-order sections (b0 b1 b2 a0 a1 a2 per row) of the discrete inverse."""
        return self._design.sos

    @property
    def sample_rate_hz(self) -> float:
        return self._design.sample_rate_hz

    @property
    def prewarp_hz(self) -> float:
        return self._design.prewarp_hz

    @property
    def mean_corner_hz(self) -> float:
        """Corner of a nonlinear sensor's mean restored while moving: the leak's, Hz."""
        return self.leak_corner_hz

    def poles(self) -> np.ndarray:
        """Discrete poles, all strictly inside the unit circle."""
        return sig.sos2zpk(self.sos)[1]

    def dc_gain_m_per_a(self) -> float:
        """Return the static gain of the discrete inverse (finite thanks to the leak), m A^-1."""
        return float(np.real(self.frequency_response(np.array([0.0]))[0]))

    def frequency_response(self, frequency_hz) -> np.ndarray:
        """Discrete inverse response at ``frequency_hz``, m A^-1."""
        f = np.atleast_1d(np.asarray(frequency_hz, dtype=float))
        _, h = sig.sosfreqz(self.sos, worN=f, fs=self.sample_rate_hz)
        return h

    def continuous_frequency_response(self, frequency_hz) -> np.ndarray:
        """Return the continuous inverse 1/((s+w_c) R_n) [* s/(s+w_o)] it discretises, m A^-1."""
        z, p, k = inverse_zpk(self.reduced, self.leak_corner_hz, self.offset_corner_hz)
        s = 2j * np.pi * np.atleast_1d(np.asarray(frequency_hz, dtype=float))[:, None]
        return k * np.prod(s - z, axis=1) / np.prod(s - p, axis=1)

    # -- streaming ----------------------------------------------------------
    def process(self, current_a) -> np.ndarray:
        """
        Filter a block of current samples, A -> deflection, m.

        ``current_a``: shape ``(n,)`` (one channel only) or ``(n, channels)``.
        Pass values through :func:`~ipmc_sensor_ros.estimation.stream.validate_block` first:
        the filter trusts its input.
        """
        x = np.asarray(current_a, dtype=float)
        squeeze = x.ndim == 1
        if squeeze:
            if self.channels != 1:
                raise ParameterError(f'expected shape (n, {self.channels}), got {x.shape}')
            x = x[:, None]
        if x.ndim != 2 or x.shape[1] != self.channels:
            raise ParameterError(f'expected shape (n, {self.channels}), got {x.shape}')
        if x.shape[0] == 0:
            return np.empty(0) if squeeze else np.empty((0, self.channels))
        if squeeze and x.shape[0] <= SMALL_BLOCK_SAMPLES:
            return np.array(self._process_small(x[:, 0].tolist()))
        y, zi = sig.sosfilt(self.sos, x, axis=0, zi=self._zi)
        self._zi = zi
        return y[:, 0] if squeeze else y

    def process_one(self, current_a: float) -> float:
        """
        One sample of a single-channel estimator, as a float.

        Identical to :meth:`process` on a one-sample block, without numpy's
        per-call costs.
        """
        if self.channels != 1:
            raise ParameterError(
                f'process_one needs a single-channel estimator (channels = {self.channels})'
            )
        return self._process_small([float(current_a)])[0]

    def _process_small(self, values: list) -> list:
        """
        Run the single-channel DF-II-transposed recursion in plain Python floats.

        For blocks of at most :data:`SMALL_BLOCK_SAMPLES` samples.  Same operations in
        the same order as :func:`scipy.signal.sosfilt`, so the output is identical
        (tested); it avoids sosfilt's fixed per-call cost (~40 us of argument
        handling), which dominates one-sample messages.
        """
        state = self._zi_list
        if state is None:   # the numpy state changed since the last small block
            state = self._zi_list = self._zi_array[:, :, 0].tolist()
        out = []
        for x_cur in values:
            for (b0, b1, b2, a1, a2), zs in zip(self._coefficients, state):
                x_new = b0 * x_cur + zs[0]
                zs[0] = b1 * x_cur - a1 * x_new + zs[1]
                zs[1] = b2 * x_cur - a2 * x_new
                x_cur = x_new
            out.append(x_cur)
        return out   # the state stays in the list until a numpy path reads _zi

    @property
    def _zi(self) -> np.ndarray:
        """
        Filter state, shape (sections, 2, channels): the numpy view of it.

        The one-sample path keeps channel 0's state as a list of floats between calls
        (copying it to and from numpy cost 8 us per sample); reading ``_zi`` writes the
        list back first, and setting it drops the list.
        """
        if self._zi_list is not None:
            self._zi_array[:, :, 0] = self._zi_list
            self._zi_list = None
        return self._zi_array

    @_zi.setter
    def _zi(self, value: np.ndarray) -> None:
        self._zi_list = None
        self._zi_array = value

    # -- the estimator-core interface (:class:`~.core.EstimatorCore`) ------------------------
    name = 'leaky'

    def estimate(self, current_a, steps=None):
        """
        Filter a block; return an :class:`~.core.Estimate` (std NaN, never at rest).

        A sample ``steps[k] > 1`` slots after the one before is preceded by ``steps[k] - 1``
        zero-current samples (the leaky inverse has no prediction model: a missing sample is
        taken as no charge flowing); a stamp's offset from its slot is not used (on a slot).
        """
        from .timebase import slots_of

        x = np.asarray(current_a, dtype=float)
        st = None if steps is None else slots_of(steps)
        if st is not None and np.any(st > 1):
            idx = np.cumsum(st) - st[0]
            padded = np.zeros(int(idx[-1]) + 1)
            padded[idx] = x
            w = self.process(padded)[idx]
        else:
            w = self.process(x)
        return Estimate(w, np.full(w.size, np.nan), np.zeros(w.size, dtype=bool))

    def estimate_one(self, current_a: float, steps: float = 1) -> tuple[float, float]:
        """One sample: (deflection, NaN); :meth:`process_one` after ``steps - 1`` zeros."""
        from .timebase import slots_of

        if slots_of(steps) > 1:
            self._process_small([0.0] * (slots_of(steps) - 1))
        return self.process_one(current_a), math.nan

    def pop_smoothed(self, flush: bool = False) -> None:
        """Return None: the leaky inverse has no fixed-lag smoother."""
        return None

    def smooth(self, current_a, steps=None):
        """Return the causal estimate from a fresh start (the leaky inverse has no smoother)."""
        fresh = InverseEstimator(self.reduced, self.sample_rate_hz,
                                 leak_corner_hz=self.leak_corner_hz,
                                 offset_corner_hz=self.offset_corner_hz,
                                 prewarp_hz=self.prewarp_hz, channels=self.channels)
        return fresh.estimate(current_a, steps)

    def status(self) -> dict:
        return {'estimator': self.name, 'offset_a': None, 'offset_std_a': None,
                'at_rest': False, 'deflection_std_m': None, 'noise_a': None, 'motion_hz': None,
                'motion_fundamentals_hz': None}

    def settling(self) -> tuple[float, str]:
        """Five time constants of the leak: it has forgotten the unknown starting level."""
        return forgets_s(self.leak_corner_hz), 'five time constants of the leak'

    def process_sample(self, current_a: float) -> float:
        """One sample of a single-channel estimator (alias of :meth:`process_one`)."""
        return self.process_one(current_a)

    def reset(self) -> None:
        """Zero the state: the estimate restarts from zero deflection."""
        self._zi = np.zeros_like(self._zi)

    def get_state(self) -> dict:
        """Return a copy of the filter state, restorable with :meth:`set_state`."""
        return {'zi': self._zi.copy(), 'sos': self.sos.copy()}

    def set_state(self, state: dict) -> None:
        zi = np.asarray(state.get('zi'), dtype=float)
        if zi.shape != self._zi.shape:
            raise ParameterError(f'state shape {zi.shape} does not match {self._zi.shape}')
        if 'sos' in state and not np.array_equal(np.asarray(state['sos']), self.sos):
            raise ParameterError('state was saved from a different filter design')
        if not np.all(np.isfinite(zi)):
            raise ParameterError('state contains non-finite values')
        self._zi = zi.copy()

    def continue_from(self, old: 'InverseEstimator', recent_input=None) -> None:
        """
        Set this filter's state so its output continues ``old``'s without a jump.

        With ``recent_input`` (the last samples fed to ``old``, shape (n,) or
        (n, channels); a few tenths of a second is many times the fast modes'
        memory) the state is the new filter's response to that history, which
        restores its fast modes, plus a correction in the slow modes (leak and
        offset tracker) that makes the next output equal ``old``'s and keeps
        ``old``'s current-offset estimate (these modes carry the deflection and
        the offset, which the history alone does not determine).  Without it,
        only the slow modes are set (a short transient of the fast modes).
        """
        self.reset()
        if recent_input is not None and np.size(recent_input):
            x = np.asarray(recent_input, dtype=float).reshape(-1, self.channels)
            _, self._zi = sig.sosfilt(self.sos, x, axis=0, zi=self._zi)
        # Hand-over in the slow modes (leak, and offset tracker when on), which the short
        # history cannot restore: the next output equals the old one, and with the tracker
        # the current-offset estimate carries over.  In continuous form the slow free
        # response obeys dx/dt = -w_c x - q (q: offset estimate / R_n(0), 0 without
        # tracker), so q = -(rate + w_c x) is kept; discretely w_c -> 1 - leak pole.
        # (Not the DC steady state: with the tracker the DC gain is exactly 0.)
        level, rate = old._slow_level_and_rate()
        own_level, own_rate = self._slow_level_and_rate()
        basis, t11, c1, _ = self._slow_part()
        d_level = old.current_output() - self.current_output()
        rows, rhs = [c1], [d_level]
        if t11.shape[0] == 2:
            offset_term = rate - (old._leak_pole() - 1.0) * level
            rate_want = offset_term + (self._leak_pole() - 1.0) * (own_level + d_level)
            rows.append(c1 @ (t11 - np.eye(2)))
            rhs.append(rate_want - own_rate)
        coef = np.linalg.solve(np.array(rows), np.array(rhs))      # (m, channels)
        self._zi = self._zi + (basis @ coef).reshape(-1, 2, self.channels)

    def _leak_pole(self) -> float:
        """
        Return the discrete pole of the leak.

        Prewarped Tustin image of -w_c (as
        :func:`~ipmc_sensor_ros.lti.discretize.tustin_sos` maps it); computed, not picked
        among the eigenvalues, which are ambiguous when the two corners nearly coincide.
        """
        w0 = 2.0 * math.pi * self.prewarp_hz
        k = w0 / math.tan(w0 / (2.0 * self.sample_rate_hz))      # 2 fs_warped
        wc = 2.0 * math.pi * self.leak_corner_hz
        return (k - wc) / (k + wc)

    def _slow_level_and_rate(self) -> tuple[np.ndarray, np.ndarray]:
        """Slow part of the free response now: level s(0) and rate s(1) - s(0), per channel."""
        _, t11, c1, proj = self._slow_part()
        a = proj @ self._zi.reshape(-1, self.channels)            # slow coordinates (m, ch)
        level = c1 @ a
        rate = c1 @ (t11 @ a) - level
        return level, rate

    def _slow_part(self) -> tuple:
        """
        Slow invariant subspace of the zero-input dynamics.

        Basis Q1 (n, m), dynamics T11 (m, m), output row c1 (m,), and the spectral
        projector onto slow coordinates (m, n) along the fast modes.
        """
        if self._slow_cache is not None:
            return self._slow_cache
        sections = self.sos.shape[0]
        n = 2 * sections
        step = np.empty((n, n))
        out = np.empty(n)
        for k in range(n):
            z = np.zeros((sections, 2))
            z.flat[k] = 1.0
            x = 0.0
            for (b0, b1, b2, a1, a2), zs in zip(self._coefficients, z):
                y = b0 * x + zs[0]
                zs[0], zs[1] = b1 * x - a1 * y + zs[1], b2 * x - a2 * y
                x = y
            out[k] = x
            step[:, k] = z.ravel()
        m = 1 if self.offset_corner_hz is None else 2
        radius = np.sort(np.abs(np.linalg.eigvals(step)))[::-1]
        cut = 0.5 * (radius[m - 1] + radius[m]) if radius.size > m else 0.0
        t, q, dim = schur(step, output='real', sort=lambda re, im: np.hypot(re, im) > cut)
        t11, t12, t22 = t[:dim, :dim], t[:dim, dim:], t[dim:, dim:]
        x_syl = solve_sylvester(t11, -t22, -t12)
        proj = q[:, :dim].T - x_syl @ q[:, dim:].T
        self._slow_cache = (q[:, :dim], t11, out @ q[:, :dim], proj)
        return self._slow_cache

    def rebuilt(self, reduced: ReducedModel | None = None, recent_input=None,
                **changes) -> 'InverseEstimator':
        """
        Return a new estimator with changed design whose output continues from this one's.

        :meth:`continue_from`, with ``recent_input`` if given.

        ``changes`` may set sample_rate_hz, leak_corner_hz, offset_corner_hz,
        prewarp_hz.  Raises :class:`ParameterError` (and leaves ``self`` intact)
        if the new design is invalid.
        """
        kwargs = {'sample_rate_hz': self.sample_rate_hz, 'leak_corner_hz': self.leak_corner_hz,
                  'offset_corner_hz': self.offset_corner_hz, 'channels': self.channels}
        if 'prewarp_hz' not in changes and 'sample_rate_hz' not in changes:
            kwargs['prewarp_hz'] = self.prewarp_hz
        kwargs.update(changes)
        new = InverseEstimator(reduced or self.reduced, **kwargs)
        new.continue_from(self, recent_input)
        return new

    def current_output(self) -> np.ndarray:
        """Return the output the filter would produce for a zero input now (per channel), m."""
        y, _ = sig.sosfilt(self.sos, np.zeros((1, self.channels)), axis=0, zi=self._zi)
        return y[0]
