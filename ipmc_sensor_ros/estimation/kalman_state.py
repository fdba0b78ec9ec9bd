# SPDX-License-Identifier: Apache-2.0
"""
The Kalman estimator's state in and out: save, restore, rebuild, continue, report.

What :class:`~.kalman.KalmanEstimator` is at any sample is its
:class:`~.filter.FilterState`, the model's lines and periodic motion, the mains line
measured so far, the last window of current on the sample grid, the stretches a model change
would filter again (:class:`~.periodic.StretchLog`), the first rest's sample and the jumps
counted, the motion since the last rest (:class:`~.jump_time.MotionLog`);
:meth:`KalmanState.get_state` returns them as values and
:meth:`KalmanState.set_state` takes them back (scipy.signal's ``zi`` / ``zf``: state in,
state out), so a restored estimator continues to the bit. A new design (reduced model, rate,
settings) continues from the old one's state (:func:`~.carry.carry_state`).
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import ParameterError
from ..lti.reduction import ReducedModel
from .carry import carry_state
from .filter import FilterState, KalmanFilter
from .instants import at_stamp
from .jump_time import MotionLog
from .lines import Line
from .periodic import StretchLog, design
from .ring import SampleRing
from .phasors import harmonics_below
from .statespace import StateSpaceModel

__all__ = ['KalmanState']


class KalmanState:
    """Save, restore and carry the state of :class:`~.kalman.KalmanEstimator` (a mixin)."""

    def get_state(self) -> dict:
        return {'filter': self._state.copy(), 'line_hz': self.model.fundamentals_hz,
                'motion_hz': self.model.motion_fundamentals_hz,
                'remainder_m': self.model.config.periodic_remainder_rms_m,
                'bandwidth_hz': self.model.config.motion_bandwidth_hz,
                'recent': self._recent.buffer.copy(), 'grid': self._recent.count,
                'first_rest_n': self._first_rest_n, 'stretches': self._log.saved(),
                'offset_jumps': self.offset_jumps, 'moving': self._moving.saved(),
                'line': tuple(float(v) for v in self._line)}

    def set_state(self, state: dict) -> None:
        try:
            fs: FilterState = state['filter']
            line = tuple(float(f) for f in state['line_hz'])
            motion = tuple(float(f) for f in np.atleast_1d(state['motion_hz']) if f)
            remainder = float(state['remainder_m'])
            band = float(state['bandwidth_hz'])
            recent = np.asarray(state['recent'], dtype=float)
            filt = self._model_filter(line, motion, remainder, band)
            log = StretchLog.restored(state['stretches'], self._model_filter)
            moving = MotionLog.restored(self._moving.limit, state.get('moving'),
                                        self._model_filter)
            window_slots = fs.window.offset_var.shape
            line = Line(*(float(v) for v in state.get('line', ())))
        except (KeyError, TypeError, ValueError, AttributeError):
            raise ParameterError('not a state of this Kalman estimator') from None
        if (fs.x.shape != (filt.model.size,) or recent.shape != self._recent.buffer.shape
                or window_slots != fs.window.samples.shape):
            raise ParameterError('state was saved from a different estimator design')
        if self._lag is not None:
            self._lag.flush()
        self._filter, self._log, self._moving = filt, log, moving
        self._state = fs.copy()
        self._recent = SampleRing(recent.size, recent, int(state.get('grid', fs.samples)))
        self._first_rest_n = state.get('first_rest_n')
        self.offset_jumps = int(state.get('offset_jumps', 0))
        self._line = line

    def _design_after(self, old: 'KalmanState') -> tuple:
        """(lines, motion, remainder, corner) of ``old``'s design under these settings."""
        was, now, chosen = old.config, self.config, old.model.config
        lines = (old.model.fundamentals_hz if old.mains_hz == self.mains_hz
                 else self.model.fundamentals_hz)
        remainder = (chosen.periodic_remainder_rms_m if was.periodic_remainder_rms_m
                     == now.periodic_remainder_rms_m else now.periodic_remainder_rms_m)
        band = (chosen.motion_bandwidth_hz if was.motion_bandwidth_hz == now.motion_bandwidth_hz
                else now.motion_bandwidth_hz)
        motion = tuple(f for f in old.model.motion_fundamentals_hz
                       if harmonics_below(f, band, now.motion_harmonics))
        return lines, motion, remainder, band

    def _model_filter(self, line_hz, motion_hz, remainder_m, band_hz) -> KalmanFilter:
        """Return this filter when its model is of this design (:func:`.periodic.design`)."""
        if design(self.model) == (tuple(line_hz), motion_hz, remainder_m, band_hz):
            return self._filter
        config = self.config.replace(periodic_remainder_rms_m=remainder_m,
                                     motion_bandwidth_hz=band_hz)
        return self._new_filter(StateSpaceModel(self.reduced, config, self.sample_rate_hz,
                                                tuple(line_hz), motion_hz))

    def rebuilt(self, reduced: ReducedModel | None = None, recent_input=None,
                **changes) -> 'KalmanState':
        """
        Return an estimator for a new design (reduced model, sample rate, settings).

        Its state continues from this one's: deflection, velocity, working point, offset and
        lines carried over; the sensor's charge states restarted from the velocity.
        """
        fs = float(changes.pop('sample_rate_hz', self.sample_rate_hz))
        config = changes.pop('config', self.config)
        mains = changes.pop('mains_hz', self.mains_hz)
        lag_s = changes.pop('smoothed_lag_s', self.smoothed_lag_s)
        if changes:
            raise ParameterError(f'cannot rebuild the Kalman estimator with {sorted(changes)}')
        new = type(self)(reduced or self.reduced, fs, config, mains, lag_s)
        new.continue_from(self)
        return new

    def continue_from(self, old: 'KalmanState', recent_input=None) -> None:
        """
        Take over ``old``'s stream state (deflection, offset, lines, ...) and its design.

        The mains lines measured (under the same ``mains_hz``) and the periodic motion carry
        over, and so do the remainder and upper corner the data chose while the settings they
        were chosen from are the same: a new sensor model or setting is not a new motion.
        """
        self._filter = self._model_filter(*self._design_after(old))
        self._state = carry_state(old._filter, self._filter, old._state)
        self._log = StretchLog(self._filter, self._state)
        self._first_rest_n, self.offset_jumps = old._first_rest_n, old.offset_jumps
        self._line = old._line
        if old._window_n == self._window_n:
            self._recent = old._recent.copy()

    def status(self) -> dict:
        """Return the state in numbers (:meth:`~.core.EstimatorCore.status`)."""
        m, x = self.model, self._state.x
        w, w_std = self._filter.deflection(self._state)
        b, b_std = self._filter.offset(self._state)
        level = float(math.hypot(x[m.il] * m.scale[m.il], x[m.il + 1] * m.scale[m.il + 1])
                      if m.lines_hz else 0.0)
        return {'estimator': self.name, 'offset_a': b, 'offset_std_a': b_std,
                'at_rest': bool(self._state.still), 'deflection_std_m': w_std,
                'noise_a': math.sqrt(self._state.noise.var_a2),
                'mains_line_hz': self.model.line_hz, 'mains_line_a': level,
                'motion_hz': self.model.motion_hz,
                'motion_fundamentals_hz': list(m.motion_fundamentals_hz),
                'motion_remainder_m': m.motion_hz and m.config.periodic_remainder_rms_m or None,
                'motion_bandwidth_hz': self.model.config.motion_bandwidth_hz,
                'offset_jumps': self.offset_jumps,
                'sampled_at_stamp': at_stamp(self._state.innovations.stamps,
                                             self.config.sampled_at_stamp_prior)}
