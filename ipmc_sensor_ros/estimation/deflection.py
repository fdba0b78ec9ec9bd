# SPDX-License-Identifier: Apache-2.0
"""
Model-aware streaming deflection estimator: a :class:`SensorModel` in, deflection out.

:class:`DeflectionEstimator` is what the estimator node and ``ipmc-model estimate`` run (one
code path).  It reduces the model (:func:`~ipmc_sensor_ros.lti.reduction.reduce_model_parts`:
the minimum-phase LTI part, exact rational factors appended), hands it to an estimator core
(:class:`~.core.EstimatorCore`: ``kalman``, the default, or the ``leaky`` baseline) and
handles the model's other effects around the core, per block:

* a pure delay (``time_delay``; ``SensorModel.delay_s``) cannot be inverted causally: the
  deflection at time t is known once the current of t + delay has arrived, so output samples
  are re-stamped ``t_out = t_in - delay``;
* effects with an ``output_transform`` (e.g. ``current_offset``, when asked for explicitly)
  are undone on the current before the core (``inverse_output_transform``);
* effects with an ``input_transform`` T (e.g. ``nonlinearity``) are undone on the core's
  output (``inverse_input_transform``).  The sensor cannot see the mean of T(w) (H(0) = 0)
  and the core centres its moving estimate on its working point, so the estimator adds back
  m = <T(w) - w>, averaged while moving (the core's ``mean_corner_hz``: the setting
  ``nonlinear_mean_corner_hz``; the leaky core: its leak corner) and frozen at rest, where
  the core holds an absolute level;
* a time-varying material (``hydration_drift``) is followed by rebuilding the core every
  ``update_s`` seconds of data time for the material at that time, each reduction
  warm-started from the previous one; the new core continues from the old one's state.

``smoothed_lag_s`` > 0 (Kalman core): :meth:`DeflectionEstimator.pop_smoothed` returns the
output smoothed with that lag (:mod:`.fixed_lag`), with the output times of its samples.

Time in the effect hooks runs from the first sample after construction or the last
:meth:`reset`.  An effect that transforms without defining the inverse is refused with
:class:`~ipmc_sensor_ros.physics.parameters.ParameterError`.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..errors import ParameterError
from ..lti.reduction import ReducedModel, reduce_model_parts
from ..physics.model import SensorModel
from ..physics.pipeline import DriftSchedule
from .around import InputInverse, LagOutput
from .config import EstimatorConfig, parse_mains
from .core import ESTIMATORS, Estimate, EstimatorCore
from .inverse import DEFAULT_LEAK_CORNER_HZ, InverseEstimator
from .kalman import KalmanEstimator
from .mains import MainsFilter, detect_lines
from .ring import SampleRing

__all__ = ['DeflectionEstimator', 'ESTIMATORS']


class DeflectionEstimator:
    """
    Streaming estimate of tip deflection (m) from sensing current (A) for ``model``.

    Parameters
    ----------
    model : SensorModel
        The sensor model (base and sensor effects).
    sample_rate_hz : float
        Sample rate of the current, Hz.
    reduction_order : int
        Fitted poles of the reduction, 1..8.
    band_hz : (float, float)
        Band of the reduction, Hz.
    estimator : str
        ``'kalman'`` (:class:`~.kalman.KalmanEstimator`) or ``'leaky'``
        (:class:`~.inverse.InverseEstimator`).
    config : EstimatorConfig, optional
        Settings of the Kalman core.
    mains_hz : 'auto', 0, 50 or 60
        Mains line: the Kalman core models it (``auto`` measures it); the leaky baseline
        notches 50/60 Hz and ignores ``auto``.
    leak_corner_hz, offset_corner_hz, prewarp_hz : float, optional
        Settings of the leaky core (refused for the Kalman core).
    update_s : float
        Rebuild interval for time-varying effects, s.
    reduced : ReducedModel, optional
        A reduction to use instead of computing one.

    """

    def __init__(self, model: SensorModel, sample_rate_hz: float, *, reduction_order: int = 4,
                 band_hz: Sequence[float] = (0.1, 50.0), estimator: str = 'kalman',
                 config: EstimatorConfig | None = None, mains_hz='auto',
                 leak_corner_hz: float | None = None, offset_corner_hz: float | None = None,
                 prewarp_hz: float | None = None, update_s: float = 5.0,
                 reduced: ReducedModel | None = None, history_s: float = 0.5,
                 smoothed_lag_s: float = 0.0):
        if estimator not in ESTIMATORS:
            raise ParameterError(f"parameter 'estimator' must be one of {ESTIMATORS}, got "
                                 f'{estimator!r}')
        self.estimator = estimator
        self.mains_hz = parse_mains(mains_hz)
        self.config = config or EstimatorConfig()
        self.model = model
        self.reduction_order = int(reduction_order)
        self.band_hz = (float(band_hz[0]), float(band_hz[1]))
        self.update_s = float(update_s)
        self.smoothed_lag_s = float(smoothed_lag_s)
        self._lag = LagOutput() if self.smoothed_lag_s else None
        self.delay_s = float(model.delay_s())
        compiled = model.compiled
        compiled.require_inverse()
        self._current_inv = compiled.output_transforms
        self._deflection_inv = InputInverse(compiled.input_transforms, model)
        self._material_at = compiled.material_at
        self._drift = (DriftSchedule(compiled.material_at, self.update_s)
                       if compiled.material_at is not None else None)
        self._diffusive = None
        self.reduced = reduced if reduced is not None else self._reduce(model)
        self._leaky_args = {'leak_corner_hz': leak_corner_hz, 'offset_corner_hz': offset_corner_hz,
                            'prewarp_hz': prewarp_hz}
        self.core: EstimatorCore = self._new_core(self.reduced, float(sample_rate_hz))
        numeric_mains = 0.0 if self.mains_hz == 'auto' else self.mains_hz
        self.mains = MainsFilter(numeric_mains if estimator == 'leaky' else 0.0,
                                 self.core.sample_rate_hz)
        self._history = SampleRing(max(1, int(round(history_s * self.core.sample_rate_hz))))
        self.reset_outputs()

    def _new_core(self, reduced: ReducedModel, sample_rate_hz: float) -> EstimatorCore:
        if self.estimator == 'kalman':
            given = [k for k, v in self._leaky_args.items() if v is not None]
            if given:
                raise ParameterError(f'parameter(s) {given} apply to estimator "leaky" only '
                                     '(the Kalman estimator learns the offset and holds levels '
                                     'itself)')
            return KalmanEstimator(reduced, sample_rate_hz, self.config, self.mains_hz,
                                   self.smoothed_lag_s)
        if self.smoothed_lag_s:
            raise ParameterError("parameter 'smoothed_lag_s' applies to estimator 'kalman' only "
                                 '(the leaky inverse has no smoother)')
        args = dict(self._leaky_args)
        if args['leak_corner_hz'] is None:
            args['leak_corner_hz'] = DEFAULT_LEAK_CORNER_HZ
        return InverseEstimator(reduced, sample_rate_hz, **args)

    def _reduce(self, model: SensorModel) -> ReducedModel:
        reduced, self._diffusive = reduce_model_parts(model, self.reduction_order, self.band_hz,
                                                      initial=self._diffusive)
        return reduced

    # -- properties -------------------------------------------------------------------------
    @property
    def sample_rate_hz(self) -> float:
        return self.core.sample_rate_hz

    @property
    def std_m(self) -> float:
        """Return the standard deviation of the latest estimate, m (NaN: none, leaky)."""
        return float(self.last_std_m[-1]) if self.last_std_m.size else float('nan')

    @property
    def plain(self) -> bool:
        """Tell whether no effect acts around the core (:meth:`process_one` calls it directly)."""
        return not (self._current_inv or self._deflection_inv or self._material_at is not None
                    or self.mains.sos.shape[0])

    @property
    def recent_input(self) -> np.ndarray:
        """Return the last inputs fed to the core (effect-corrected current), oldest first."""
        return self._history.values()

    def settling(self) -> tuple[float, str]:
        """Return (seconds since the reset, why) before the estimate is comparable."""
        return self.core.settling()

    def status(self) -> dict:
        """
        Return the estimator's state for counters and diagnostics (JSON-able).

        The core's (``estimator``, ``offset_a``, ``at_rest``, ``deflection_std_m``,
        ``noise_a``, ``mains_line_hz`` ...); for the leaky core the mains line found in the
        recent input (``mains_line_hz`` 0/50/60, ``mains_line_level`` relative to its RMS).
        """
        out = dict(self.core.status())
        if 'mains_line_hz' not in out:
            line = detect_lines(self.recent_input, self.sample_rate_hz)
            out.update(mains_line_hz=line['mains_hz'], mains_line_level=line['level'])
        return out

    # -- streaming --------------------------------------------------------------------------
    def reset_outputs(self) -> None:
        self.last_std_m = np.zeros(0)
        self.last_still = np.zeros(0, dtype=bool)
        self._t0: float | None = None
        self._deflection_inv.reset()

    def reset(self) -> None:
        """Zero the core and restart the effects' time origin."""
        self._collect_smoothed(flush=True)
        if self._material_at is not None:
            self._diffusive = None
            self.core = self._new_core(self._reduce(self.model), self.core.sample_rate_hz)
        else:
            self.core.reset()
        if self._drift is not None:
            self._drift.reset()
        self._history.clear()
        self.mains.reset()
        self.reset_outputs()

    def process_with_std(self, time_s, current_a, steps=None):
        """(output times, deflection, its standard deviation) for one block, m."""
        t_out, w = self.process(time_s, current_a, steps)
        return t_out, w, self.last_std_m

    def process(self, time_s, current_a, steps=None) -> tuple[np.ndarray, np.ndarray]:
        """
        Filter one block; returns (output times, deflection).

        Pass validated values (:func:`~ipmc_sensor_ros.estimation.stream.validate_block`).
        ``steps[k]`` is the number of sample periods from the sample fed before sample k (1:
        contiguous; m > 1: m - 1 samples missing, bridged by the core); None: all 1.  The
        stream decides it (:class:`~ipmc_sensor_ros.estimation.stream.StreamEstimator`).
        """
        t = np.asarray(time_s, float)
        i = np.asarray(current_a, float)
        if t.size == 0:
            return t, i
        if self._t0 is None:
            self._t0 = float(t[0])
        elapsed = t - self._t0 if (self._current_inv or self._material_at is not None) else None
        t_out = t - self.delay_s if self.delay_s else t
        if self._lag is not None:
            self._lag.times.extend(t_out.tolist())
        i = self.mains.process(i)
        for eff, values in reversed(self._current_inv):
            i = eff.inverse_output_transform(elapsed, i, self.model, values)
        est = self._run_core(elapsed, i, steps)
        w = self._undo_input_transforms(est)
        self.last_std_m, self.last_still = est.std_m, est.still
        return t_out, w

    def _run_core(self, elapsed, i: np.ndarray, steps) -> Estimate:
        if self._material_at is None:
            est = self.core.estimate(i, steps)
            self._history.extend(i)
            return est
        parts = []
        for sl in self._drift.slices(elapsed, self._follow_drift):
            parts.append(self.core.estimate(i[sl], None if steps is None else steps[sl]))
            self._history.extend(i[sl])
        return Estimate(*(np.concatenate(p) for p in zip(*parts)))

    def _undo_input_transforms(self, est: Estimate) -> np.ndarray:
        return self._deflection_inv.undo(est, self.core.mean_corner_hz, self.sample_rate_hz)

    def pop_smoothed(self, flush: bool = False):
        """
        Return (output times, deflection, std) smoothed with ``smoothed_lag_s``, since last asked.

        None when nothing is ready.  ``flush``: also the samples held for their lag, smoothed
        with the data there is (this estimator is being replaced).
        """
        self._collect_smoothed(flush)
        return None if self._lag is None else self._lag.pop()

    def _collect_smoothed(self, flush: bool) -> None:
        if self._lag is not None:
            self._lag.collect(self.core.pop_smoothed(flush), self._deflection_inv)

    def process_one(self, time_s: float, current_a: float, steps: int = 1) -> tuple[float, float]:
        """
        One sample, as floats (output time, deflection).

        The core's one-sample recursion (the same as for a block); the general path when
        effects act around the core.
        """
        if not self.plain:
            t_out, w = self.process(np.array([time_s], float), np.array([current_a], float),
                                    None if steps == 1 else np.array([steps]))
            return float(t_out[0]), float(w[0])
        if self._t0 is None:
            self._t0 = float(time_s)
        t_out = time_s - self.delay_s if self.delay_s else float(time_s)
        if self._lag is not None:
            self._lag.times.append(t_out)
        w, std = self.core.estimate_one(current_a, steps)
        self.last_std_m = np.array([std])
        self._history.push(current_a)
        return t_out, w

    def smooth(self, time_s, current_a, steps=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """
        Offline: (output times, smoothed deflection, its std) of a whole record.

        The core's smoother from a fresh start (the leaky core: its causal estimate); effects
        around the core as in :meth:`process`.  Time-varying materials are not smoothed (the
        causal estimate is returned).  Leaves the stream state untouched.
        """
        fresh = self.rebuilt()
        fresh.reset()
        if self._material_at is not None:
            t_out, w = fresh.process(time_s, current_a, steps)
            return t_out, w, fresh.last_std_m
        t = np.asarray(time_s, float)
        i = fresh.mains.process(np.asarray(current_a, float))
        elapsed = t - t[0] if t.size else t
        for eff, values in reversed(fresh._current_inv):
            i = eff.inverse_output_transform(elapsed, i, fresh.model, values)
        est = fresh.core.smooth(i, steps)
        w = fresh._undo_input_transforms(est)
        return (t - self.delay_s if self.delay_s else t), w, est.std_m

    def _follow_drift(self, material) -> None:
        """Rebuild the core for the drifted ``material`` (its state carried over)."""
        drifted = self.model.with_material(material)
        self._collect_smoothed(flush=True)
        self.core = self.core.rebuilt(self._reduce(drifted), self.recent_input)

    def rebuilt(self, model: SensorModel | None = None, reduced: ReducedModel | None = None,
                **changes) -> 'DeflectionEstimator':
        """
        Return a new estimator (new model and/or settings) continuing from this one.

        ``changes``: ``sample_rate_hz``, ``config``, ``mains_hz`` and the leaky core's
        settings.  ``self`` is untouched if the new design is invalid.
        """
        kwargs = dict(self._leaky_args)
        kwargs.update(config=self.config, mains_hz=self.mains_hz,
                      smoothed_lag_s=self.smoothed_lag_s)
        kwargs.update(changes)
        fs = kwargs.pop('sample_rate_hz', self.sample_rate_hz)
        new = DeflectionEstimator(
            model or self.model, fs, reduction_order=self.reduction_order, band_hz=self.band_hz,
            estimator=self.estimator, update_s=self.update_s,
            reduced=reduced if (reduced is not None or model is not None) else self.reduced,
            **kwargs)
        new.continue_from(self)
        return new

    def continue_from(self, old: 'DeflectionEstimator') -> None:
        """Take over ``old``'s stream: its recent input, core state and time origin."""
        if old._history.size == self._history.size:
            self._history = old._history.copy()
        if old.core.name == self.core.name:
            self.core.continue_from(old.core, self.recent_input)
        self._t0 = old._t0
