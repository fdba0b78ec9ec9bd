# SPDX-License-Identifier: Apache-2.0
"""
Model-aware streaming deflection estimator: a :class:`SensorModel` in, deflection out.

:class:`DeflectionEstimator` is what the estimator node and ``ipmc-model
estimate`` run (one code path).  It reduces the model
(:func:`~ipmc_sensor_ros.lti.reduction.reduce_model`: the minimum-phase LTI part,
exact rational factors appended), inverts it causally
(:class:`~ipmc_sensor_ros.estimation.inverse.InverseEstimator`) and handles the rest of
the model's effects around the filter, per block:

* a pure delay (``time_delay``; ``SensorModel.delay_s``) cannot be inverted
  causally: the deflection at time t is known once the current of t + delay
  has arrived, so output samples are re-stamped ``t_out = t_in - delay``;
* effects with an ``output_transform`` (e.g. ``current_offset``) are undone
  on the current before the filter (``inverse_output_transform``);
* effects with an ``input_transform`` T (e.g. ``nonlinearity``) are undone on
  the filter output (``inverse_input_transform``).  The sensor cannot see the
  mean of T(w) (H(0) = 0) and the leak removes it from the filter output, so
  the estimator adds back m = <T(w) - w>, the mean an even nonlinearity gives a
  zero-mean deflection, tracked by a first-order average of the estimates with
  the leak's time constant and applied per block (with one block of lag).  The
  Kalman estimator leaks only while moving, at the corner in use, and holds an
  absolute level at rest: its average follows the corner in use and is frozen
  at rest (else a held 2 mm step with a_2 = 2 crept towards 2.36 mm);
* a time-varying material (``hydration_drift``) is followed by rebuilding the
  filter every ``update_s`` seconds of data time for the material at that time,
  each reduction warm-started from the previous one.

Rebuilds (drift updates, parameter changes through :meth:`rebuilt`) are
bumpless: the new filter replays the last ``history_s`` (0.5 s) of input to
restore its fast modes and takes over the old output
(:meth:`InverseEstimator.continue_from`).

Time in the effect hooks runs from the first sample after construction or the
last :meth:`reset`.  An effect that transforms without defining the inverse is
refused with :class:`~ipmc_sensor_ros.physics.parameters.ParameterError`.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
from scipy.signal import lfilter

from .inverse import DEFAULT_LEAK_CORNER_HZ, ParameterError, InverseEstimator
from .kalman import (
    DEFAULT_CURRENT_NOISE_A, KALMAN_LEAK_CORNER_HZ, START_LEAK_CORNER_HZ, KalmanEstimator,
)
from .mains import MainsFilter, detect_lines
from ..physics.model import SensorModel
from ..physics.pipeline import DriftSchedule
from ..lti.reduction import ReducedModel, reduce_model_parts

__all__ = ['DeflectionEstimator', 'ESTIMATORS', 'leak_transient_s']

#: The estimator cores: the leaky inverse and the offset-aware Kalman filter.
ESTIMATORS = ('leaky', 'kalman')


def leak_transient_s(corner_hz: float) -> float:
    """Return the time a leak at ``corner_hz`` takes to forget a level, s: 5 time constants."""
    return 5.0 / (2 * np.pi * corner_hz)


class DeflectionEstimator:
    """
    Streaming estimate of tip deflection (m) from sensing current (A) for ``model``.

    Parameters: ``model``; ``sample_rate_hz``; ``reduction_order`` (fitted
    poles, 1..8); ``band_hz`` of the reduction; ``leak_corner_hz`` (default 0.01 Hz leaky,
    0.001 Hz kalman),
    ``offset_corner_hz``, ``prewarp_hz`` as in :class:`InverseEstimator`;
    ``update_s``: rebuild interval for time-varying effects, s;
    ``estimator``: ``"leaky"`` (:class:`InverseEstimator`) or ``"kalman"``
    (:class:`~ipmc_sensor_ros.estimation.kalman.KalmanEstimator`: offset-aware, rest
    detector, per-sample standard deviation in :attr:`last_std_m`);
    ``mains_hz``: 0, 50 or 60, notch the line and its harmonics before the filter
    (:class:`~ipmc_sensor_ros.estimation.mains.MainsFilter`; ``mains.line_present``);
    ``current_noise_a``: DAQ white-noise RMS per sample for the Kalman design, A.
    """

    def __init__(self, model: SensorModel, sample_rate_hz: float, *, reduction_order: int = 4,
                 band_hz: Sequence[float] = (0.1, 50.0),
                 leak_corner_hz: float | None = None,
                 offset_corner_hz: float | None = None, prewarp_hz: float | None = None,
                 update_s: float = 5.0, reduced: ReducedModel | None = None,
                 history_s: float = 0.5, estimator: str = 'kalman', mains_hz: float = 0,
                 current_noise_a: float = DEFAULT_CURRENT_NOISE_A):
        if estimator not in ESTIMATORS:
            raise ParameterError(
                f"parameter 'estimator' must be 'leaky' or 'kalman', got {estimator!r}"
            )
        self.estimator = estimator
        self.mains_hz = mains_hz
        self.current_noise_a = float(current_noise_a)
        self.mains = MainsFilter(mains_hz, sample_rate_hz)
        if leak_corner_hz is None:
            leak_corner_hz = (
                KALMAN_LEAK_CORNER_HZ if estimator == 'kalman' else DEFAULT_LEAK_CORNER_HZ
            )
        self.model = model
        self.reduction_order = int(reduction_order)
        self.band_hz = (float(band_hz[0]), float(band_hz[1]))
        self.update_s = float(update_s)
        self.delay_s = float(model.delay_s())
        compiled = model.compiled
        compiled.require_inverse()
        self._current_inv = compiled.output_transforms
        self._deflection_inv = compiled.input_transforms
        self._material_at = compiled.material_at
        self._drift = (DriftSchedule(compiled.material_at, self.update_s)
                       if compiled.material_at is not None else None)
        self._diffusive = None
        if reduced is None:
            reduced = self._reduce(model)
        self.reduced = reduced
        if estimator == 'kalman':
            if offset_corner_hz is not None:
                raise ParameterError(
                    "parameter 'offset_corner_hz' applies to estimator 'leaky' only "
                    '(the Kalman estimator tracks the offset itself)'
                )
            self.inverse = KalmanEstimator(reduced, sample_rate_hz, leak_corner_hz=leak_corner_hz,
                                           current_noise_a=current_noise_a)
        else:
            self.inverse = InverseEstimator(
                reduced,
                sample_rate_hz,
                leak_corner_hz=leak_corner_hz,
                offset_corner_hz=offset_corner_hz,
                prewarp_hz=prewarp_hz,
            )
        self.last_std_m = np.zeros(0)
        self._t0: float | None = None
        self._history = np.zeros(max(1, int(round(history_s * self.inverse.sample_rate_hz))))
        self._history_n = 0
        self._history_end = 0
        self._bias_m = 0.0          # m = <T(w) - w>, see the module docstring
        self._bias_zi = np.zeros(1)

    def _remember(self, x: np.ndarray) -> None:
        """
        Append ``x`` to the ring buffer of recent input.

        ``_history_end`` is the index after the newest sample.
        """
        n = self._history.size
        m = x.size
        if m >= n:
            self._history[:] = x[-n:]
            self._history_end = 0
        else:
            end = self._history_end
            first = min(m, n - end)
            self._history[end:end + first] = x[:first]
            self._history[:m - first] = x[first:]
            self._history_end = (end + m) % n
        self._history_n = min(n, self._history_n + m)

    @property
    def recent_input(self) -> np.ndarray:
        """Return the last inputs fed to the filter (effect-corrected current), oldest first."""
        ordered = np.roll(self._history, -self._history_end)
        return ordered[ordered.size - self._history_n:]

    def _reduce(self, model: SensorModel) -> ReducedModel:
        reduced, self._diffusive = reduce_model_parts(model, self.reduction_order, self.band_hz,
                                                      initial=self._diffusive)
        return reduced

    # -- properties -------------------------------------------------------------
    @property
    def sample_rate_hz(self) -> float:
        return self.inverse.sample_rate_hz

    @property
    def filter_kwargs(self) -> dict:
        return {'sample_rate_hz': self.inverse.sample_rate_hz,
                'leak_corner_hz': self.inverse.leak_corner_hz,
                'offset_corner_hz': self.inverse.offset_corner_hz}

    def settling(self) -> tuple[float, str]:
        """
        Return (seconds since the reset, why) before the estimate is comparable with a measurement.

        A current sensor cannot see a constant deflection (H(0) = 0): the level before the
        record is unknown until the estimator learns it.  Leaky: never; its leak forgets the
        initial level within :func:`leak_transient_s`.  Kalman: at the first rest or the first
        offset from whole periods (``level_known_n``); if neither happened yet, the leak
        while the level is unknown (``START_LEAK_CORNER_HZ``) sets it alike.
        """
        if self.estimator == 'kalman':
            known = self.inverse.level_known_n
            if known is not None:
                return (known / self.inverse.sample_rate_hz,
                        'level learned then (first rest or whole periods)')
            return (leak_transient_s(START_LEAK_CORNER_HZ),
                    'leak transient; level never learned (no rest, no whole periods)')
        return leak_transient_s(self.inverse.leak_corner_hz), 'leak transient'

    # -- streaming --------------------------------------------------------------
    def reset(self) -> None:
        """Zero the filter and restart the effects' time origin."""
        self.inverse.reset()
        self._t0 = None
        if self._drift is not None:
            self._drift.reset()
        self._history_n = 0
        self._bias_m = 0.0
        self._bias_zi = np.zeros(1)
        self.mains.reset()
        if self._material_at is not None:
            self._diffusive = None
            self.inverse = self._new_filter(self._reduce(self.model))

    def _new_filter(self, reduced: ReducedModel):
        if self.estimator == 'kalman':
            return KalmanEstimator(
                reduced,
                self.inverse.sample_rate_hz,
                leak_corner_hz=self.inverse.leak_corner_hz,
                current_noise_a=self.current_noise_a,
            )
        return InverseEstimator(reduced, **self._filter_args())

    def process_with_std(self, time_s, current_a) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """
        (output times, deflection, its standard deviation) for one block, m.

        The leaky estimator has no uncertainty model (NaN).
        """
        t_out, w = self.process(time_s, current_a)
        return t_out, w, self.last_std_m

    def process(self, time_s, current_a, steps=None) -> tuple[np.ndarray, np.ndarray]:
        """
        Filter one block; returns (output times, deflection).

        Pass validated values
        (:func:`~ipmc_sensor_ros.estimation.stream.validate_block`).  ``steps[k]`` is the
        number of sample periods from the sample fed before sample k (1: contiguous; m > 1:
        m - 1 samples missing, bridged by the filter); None: all 1.  The stream decides it
        (:class:`~ipmc_sensor_ros.estimation.stream.StreamEstimator`).
        """
        t = np.asarray(time_s, float)
        i = np.asarray(current_a, float)
        if t.size == 0:
            return t, i
        if self._t0 is None:
            self._t0 = float(t[0])
        elapsed = t - self._t0 if (self._current_inv or self._material_at is not None) else None
        i = self.mains.process(i)
        for eff, values in reversed(self._current_inv):
            i = eff.inverse_output_transform(elapsed, i, self.model, values)
        if self._material_at is None:
            w = self.inverse.process(i)
            self._remember(i)
        else:
            parts = []
            for sl in self._drift.slices(elapsed, self._follow_drift):
                parts.append(self.inverse.process(i[sl]))
                self._remember(i[sl])
            w = np.concatenate(parts)
        if self._deflection_inv:
            w_prime = w + self._bias_m
            w = w_prime
            for eff, values in reversed(self._deflection_inv):
                w = np.asarray(eff.inverse_input_transform(w, self.model, values), dtype=float)
            gap = w_prime - w
            if self.estimator == 'kalman':
                # the Kalman removes the mean only while moving, at the corner in use (and
                # centres periodic motion before the first rest); at rest it holds an
                # absolute level, whose T(w) - w it did not remove: the average is frozen
                gap = gap[~self.inverse.last_rest]
                corner = self.inverse.leak_corner_in_use_hz
            else:
                corner = self.inverse.leak_corner_hz
            a = float(np.exp(-2 * np.pi * corner / self.inverse.sample_rate_hz))
            if gap.size:
                avg, self._bias_zi = lfilter([1 - a], [1, -a], gap, zi=self._bias_zi)
                self._bias_m = float(avg[-1])
        self.last_std_m = np.full(w.size, getattr(self.inverse, 'last_std', np.nan))
        return (t - self.delay_s if self.delay_s else t), w

    def _follow_drift(self, material) -> None:
        """Rebuild the filter for the drifted ``material`` (bumpless: recent input replayed)."""
        drifted = self.model.with_material(material)
        self.inverse = self.inverse.rebuilt(self._reduce(drifted), self.recent_input)

    @property
    def std_m(self) -> float:
        """
        Return the standard deviation of the latest estimate.

        m (Kalman: from the filter covariance of the current mode; leaky: NaN, the
        leaky inverse has no uncertainty model).
        """
        std = getattr(self.inverse, 'last_std', None)
        return float('nan') if std is None else float(std)

    def status(self) -> dict:
        """
        Return the estimator's state for counters and diagnostics.

        JSON-able; None = not available.

        ``estimator``, ``offset_a`` (the current offset the Kalman filter has learned),
        ``at_rest``, ``deflection_std_m`` (standard deviation of the estimate; the leaky
        inverse has none), and the mains line found in the last ``history_s`` of input
        (``mains_line_hz`` 0/50/60, ``mains_line_level`` relative to the current's RMS; after
        the notch when ``mains_hz`` is set).
        """
        inv = self.inverse
        std = getattr(inv, 'last_std', None)
        offset = getattr(inv, 'offset_a', None)
        line = detect_lines(self.recent_input, self.sample_rate_hz)
        return {'estimator': self.estimator,
                'offset_a': None if offset is None else float(offset),
                'at_rest': bool(getattr(inv, 'at_rest', False)),
                'deflection_std_m': None if std is None or not np.isfinite(std) else float(std),
                'mains_line_hz': line['mains_hz'], 'mains_line_level': line['level']}

    @property
    def plain(self) -> bool:
        """
        Return True when no effect acts around the filter (no transforms, no drift).

        Then :meth:`process_one` takes its lean path.
        """
        return not (self._current_inv or self._deflection_inv or self._material_at is not None
                    or self.mains.sos.shape[0])

    def process_one(self, time_s: float, current_a: float, steps: int = 1) -> tuple[float, float]:
        """
        One sample, as floats (output time, deflection).

        Identical to :meth:`process` on a one-sample block (tested), without
        numpy's per-call costs when :attr:`plain` (the node's
        one-sample-message path).
        """
        if not self.plain:
            t_out, w = self.process(np.array([time_s], float), np.array([current_a], float))
            return float(t_out[0]), float(w[0])
        if self._t0 is None:
            self._t0 = float(time_s)
        w = self.inverse.process_one(current_a)
        end = self._history_end
        self._history[end] = current_a
        self._history_end = (end + 1) % self._history.size
        if self._history_n < self._history.size:
            self._history_n += 1
        return (time_s - self.delay_s if self.delay_s else float(time_s)), w

    def rebuilt(self, model: SensorModel | None = None, reduced: ReducedModel | None = None,
                **filter_changes) -> 'DeflectionEstimator':
        """
        Return a new estimator (new model and/or filter settings).

        Its output continues from this one's without a jump; ``self`` is untouched if the new
        design is invalid.
        """
        kwargs = dict(self.filter_kwargs)
        kwargs.update(filter_changes)
        fs = kwargs.pop('sample_rate_hz')
        new = DeflectionEstimator(
            model or self.model,
            fs,
            reduction_order=self.reduction_order,
            band_hz=self.band_hz,
            update_s=self.update_s,
            reduced=reduced if (reduced is not None or model is not None) else self.reduced,
            estimator=self.estimator,
            mains_hz=self.mains_hz,
            current_noise_a=self.current_noise_a,
            **kwargs,
        )
        new.continue_from(self)
        return new

    def continue_from(self, old: 'DeflectionEstimator') -> None:
        """Take over ``old``'s stream: its recent input, output level and time origin."""
        if old._history.size == self._history.size:
            self._history = old._history.copy()
            self._history_n, self._history_end = old._history_n, old._history_end
        else:
            self._history_n = self._history_end = 0
        self.inverse.continue_from(old.inverse, self.recent_input)
        self._t0 = old._t0

    def _filter_args(self) -> dict:
        return {'sample_rate_hz': self.inverse.sample_rate_hz,
                'leak_corner_hz': self.inverse.leak_corner_hz,
                'offset_corner_hz': self.inverse.offset_corner_hz}
