# SPDX-License-Identifier: Apache-2.0
"""
Design of the leaky inverse (the ``leaky`` baseline estimator): current (A) -> deflection (m).

Continuous inverse
------------------
The paper inverts its reduced model directly (eqs. 47-48).  With
``H_n(s) = s R_n(s)`` from :func:`ipmc_sensor_ros.lti.reduction.reduce_model` the
exact inverse ``1/(s R_n(s))`` contains a pure integrator: the sensor measures
the *rate* of charge, so any current offset i0 would ramp the estimate without
bound.  We therefore use

    H_inv(s) = 1 / ((s + w_c) R_n(s))                      [leaky integration]

optionally followed on the input by the offset tracker ``s / (s + w_o)``
(``offset_corner_hz``), which removes a constant current offset entirely.
Both corners are in Hz (``w = 2 pi f``).  ``R_n`` is minimum phase, so H_inv
is stable for every w_c > 0.

Trade-off (see :func:`leak_tradeoff`): the leak makes a held deflection step
w0 decay as ``w0 exp(-w_c t)`` (relative error ``1 - exp(-w_c t)`` after t s),
while a constant current offset i0 gives a bounded steady error
``i0 / (w_c R_n(0))`` instead of a ramp.  With offset tracking the steady error
under a constant offset is zero and its transient peak is
``i0/R_n(0) * max_t (e^{-w_c t} - e^{-w_o t})/(w_o - w_c)``, at the price of a
second high-pass on held deflections.  Sinusoids at f >> f_c see a phase lead
of about ``atan(f_c/f)`` (0.57 deg at 1 Hz for the default f_c = 0.01 Hz).

:func:`design` checks the parameters, discretises the inverse (Tustin with prewarping,
:mod:`ipmc_sensor_ros.lti.discretize`) and checks that the result is stable;
:class:`~ipmc_sensor_ros.estimation.inverse.InverseEstimator` runs it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.signal as sig

from ..errors import ParameterError
from ..lti.discretize import default_prewarp_hz, tustin_sos
from ..lti.reduction import ReducedModel

__all__ = ['DEFAULT_LEAK_CORNER_HZ', 'Design', 'design', 'inverse_zpk', 'leak_tradeoff',
           'positive']

#: Default leaky-integration corner, Hz: time constant 16 s; a 2 mm step held
#: 3 s loses 17 %, a 1 Hz sinusoid sees a 0.57 deg phase lead.
DEFAULT_LEAK_CORNER_HZ = 0.01


def positive(name: str, value, allow_none: bool = False):
    """Return ``value`` as a float, finite and > 0 (or None with ``allow_none``)."""
    if value is None and allow_none:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterError(f"parameter '{name}' must be a number, got {value!r}") from None
    if not (math.isfinite(v) and v > 0.0):
        raise ParameterError(f"parameter '{name}' must be finite and > 0, got {value!r}")
    return v


def inverse_zpk(reduced: ReducedModel, leak_corner_hz: float = DEFAULT_LEAK_CORNER_HZ,
                offset_corner_hz: float | None = None):
    """Continuous inverse (zeros, poles, gain) in rad/s: 1/((s+w_c) R_n(s)) [* s/(s+w_o)]."""
    wc = 2.0 * np.pi * positive('leak_corner_hz', leak_corner_hz)
    zeros = np.asarray(reduced.poles_rad_s)
    poles = np.concatenate([np.asarray(reduced.zeros_rad_s), [-wc]])
    if offset_corner_hz is not None:
        wo = 2.0 * np.pi * positive('offset_corner_hz', offset_corner_hz)
        zeros = np.concatenate([zeros, [0.0]])
        poles = np.concatenate([poles, [-wo]])
    return zeros, poles, 1.0 / reduced.gain


def leak_tradeoff(reduced: ReducedModel, leak_corner_hz: float, hold_time_s: float,
                  current_offset_a: float, offset_corner_hz: float | None = None) -> dict:
    """
    Quantify the leak trade-off (see the module docstring).

    Returns ``held_step_relative_error`` after ``hold_time_s`` and the
    deflection error (m) caused by ``current_offset_a``: its steady value and
    its peak.
    """
    wc = 2.0 * np.pi * positive('leak_corner_hz', leak_corner_hz)
    r0 = float(np.real(reduced.charge_response(np.array([0.0]))[0]))
    step_err = 1.0 - math.exp(-wc * hold_time_s)
    if offset_corner_hz is None:
        steady = current_offset_a / (wc * r0)
        peak = steady
    else:
        wo = 2.0 * np.pi * positive('offset_corner_hz', offset_corner_hz)
        step_err = 1.0 - (wc * math.exp(-wc * hold_time_s) - wo * math.exp(-wo * hold_time_s)) \
            / (wc - wo) if wc != wo else 1.0 - (1 - wc * hold_time_s) * math.exp(-wc * hold_time_s)
        t_peak = math.log(wo / wc) / (wo - wc) if wo != wc else 1.0 / wc
        peak = (
            current_offset_a / r0 * (math.exp(-wc * t_peak) - math.exp(-wo * t_peak)) / (wo - wc)
            if wo != wc
            else current_offset_a / r0 * t_peak * math.exp(-wc * t_peak)
        )
        steady = 0.0
    return {'held_step_relative_error': step_err, 'offset_steady_error_m': steady,
            'offset_peak_error_m': peak}


@dataclass(frozen=True)
class Design:
    """A discretised inverse: second-order sections at a sample rate and prewarp frequency."""

    sos: np.ndarray
    sample_rate_hz: float
    prewarp_hz: float


def design(reduced: ReducedModel, sample_rate_hz: float, leak_corner_hz: float,
           offset_corner_hz: float | None, prewarp_hz: float | None) -> Design:
    """Check the parameters, discretise :func:`inverse_zpk` and check its stability."""
    fs = positive('sample_rate_hz', sample_rate_hz)
    if prewarp_hz is None:
        prewarp_hz = default_prewarp_hz(fs, reduced.band_hz[1])
    prewarp_hz = positive('prewarp_hz', prewarp_hz)
    if prewarp_hz >= fs / 2.0:
        raise ParameterError(f"parameter 'prewarp_hz' = {prewarp_hz} must be below the Nyquist "
                             f'frequency {fs / 2.0} Hz')
    for name, corner in (
        ('leak_corner_hz', leak_corner_hz),
        ('offset_corner_hz', offset_corner_hz),
    ):
        if corner is not None and corner >= fs / 2.0:
            raise ParameterError(f"parameter '{name}' = {corner} must be below the "
                                 f'Nyquist frequency {fs / 2.0} Hz')
    sos = tustin_sos(*inverse_zpk(reduced, leak_corner_hz, offset_corner_hz), fs, prewarp_hz)
    radius = np.abs(sig.sos2zpk(sos)[1])
    if not np.all(radius < 1.0):
        raise ParameterError(f'discrete inverse is unstable: pole radius {radius.max():.12f} >= 1 '
                             f'(sample_rate_hz={fs}, leak_corner_hz={leak_corner_hz})')
    if not np.all(np.isfinite(sos)):
        raise ParameterError('discrete inverse has non-finite coefficients')
    return Design(sos=sos, sample_rate_hz=fs, prewarp_hz=prewarp_hz)
