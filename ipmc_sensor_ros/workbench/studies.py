# SPDX-License-Identifier: Apache-2.0
"""
Research studies on the independent field solution (not used by the estimator or the nodes).

Mesh convergence against the closed forms, and the size of the physics the paper linearises
away (the term dropped from eq. 9; large-deflection beam mechanics instead of eq. 21).
README "Where the paper is wrong or thin" quotes their results.
"""
from __future__ import annotations

import numpy as np

from ..physics.beam import ElasticaBeam
from ..physics.field import FieldSolver
from ..physics.field_nonlinear import NonlinearFieldSolver
from ..physics.model import SensorModel
from .freqresp import harmonic_fit

__all__ = ['convergence_table', 'nonlinearity_study', 'large_deflection_study',
           'amplitude_at_error']


def convergence_table(model: SensorModel, band_hz=(0.1, 100.0), n_points: int = 25,
                      levels=((0.4, 1.3, 10), (0.2, 1.15, 20), (0.1, 1.1, 40), (0.05, 1.08, 80))):
    """
    Worst |magnitude| (dB) and |phase| (deg) error against the closed form per mesh level.

    surface_cell, growth, n_length.
    """
    f = np.logspace(np.log10(band_hz[0]), np.log10(band_hz[1]), n_points)
    exact = model.frequency_response(f)
    rows = []
    for cell, growth, nz in levels:
        solver = FieldSolver(model, surface_cell=cell, growth=growth, n_length=nz)
        ratio = solver.frequency_response(f) / exact
        rows.append({'surface_cell': cell, 'growth': growth, 'n_length': nz,
                     'states': solver.n_states,
                     'max_mag_error_db': float(np.max(np.abs(20 * np.log10(np.abs(ratio))))),
                     'max_phase_error_deg': float(np.max(np.abs(np.degrees(np.angle(ratio)))))})
    return rows


def _distortion_rows(simulate_exact, i_unit, t, shape, amplitudes_m, frequency_hz) -> list[dict]:
    """
    Relative RMS error of the linear prediction against ``simulate_exact(w)``.

    The linear prediction is amplitude x ``i_unit``; also the harmonics of the latter, over
    the last two periods.
    """
    keep = t >= t[-1] - 2 / frequency_hz
    rows = []
    for a in amplitudes_m:
        i_true = simulate_exact(a * shape)
        i_lin = a * i_unit
        err = float(
            np.sqrt(np.mean((i_true[keep] - i_lin[keep]) ** 2))
            / np.sqrt(np.mean(i_lin[keep] ** 2))
        )
        ph, _, _ = harmonic_fit(t[keep] - t[keep][0], i_true[keep], frequency_hz, 3)
        rows.append({'amplitude_m': float(a), 'linear_model_error': err,
                     'h2_over_h1': float(abs(ph[1]) / abs(ph[0])),
                     'h3_over_h1': float(abs(ph[2]) / abs(ph[0]))})
    return rows


def nonlinearity_study(model: SensorModel, amplitudes_m, frequency_hz: float = 5.0,
                       sample_rate_hz: float = 2000.0, periods: int = 6) -> list[dict]:
    """
    Relative error of the linear model and harmonic content of the current vs amplitude.

    Versus the tip-deflection amplitude (sinusoidal drive), from the nonlinear field solution
    (the eq. 9 term; r0 = 0).
    """
    t = np.arange(int(round(periods / frequency_hz * sample_rate_hz))) / sample_rate_hz
    lin = NonlinearFieldSolver(model, linear=True)
    nonlin = NonlinearFieldSolver(model)
    shape = np.sin(2 * np.pi * frequency_hz * t)
    i_unit = lin.simulate(t, shape)             # linear: scales with amplitude
    return _distortion_rows(lambda w: nonlin.simulate(t, w), i_unit, t, shape, amplitudes_m,
                            frequency_hz)


def large_deflection_study(model: SensorModel, amplitudes_m, frequency_hz: float = 5.0,
                           sample_rate_hz: float = 1000.0, periods: int = 4) -> list[dict]:
    """
    Return the same for the beam: elastica against small-deflection stress profile.

    Field solution with the elastica stress profile
    (:class:`~ipmc_sensor_ros.physics.beam.ElasticaBeam`) against the paper's
    small-deflection profile (eq. 21), sinusoidal tip deflection.  Rows also give the
    amplitude as a fraction of the length, ``amplitude_over_length``.
    """
    t = np.arange(int(round(periods / frequency_hz * sample_rate_hz))) / sample_rate_hz
    shape = np.sin(2 * np.pi * frequency_hz * t)
    i_unit = FieldSolver(model).simulate(t, shape)
    elastica = FieldSolver(model, beam=ElasticaBeam())
    rows = _distortion_rows(lambda w: elastica.simulate(t, w), i_unit, t, shape, amplitudes_m,
                            frequency_hz)
    for r in rows:
        r['amplitude_over_length'] = r['amplitude_m'] / model.geometry.length_m
    return rows


def amplitude_at_error(rows: list[dict], level: float = 0.01) -> float:
    """
    Smallest amplitude (m) at which ``linear_model_error`` reaches ``level``.

    By log-log interpolation between the study's rows (nan if never
    reached).
    """
    a = np.array([r['amplitude_m'] for r in rows])
    e = np.array([r['linear_model_error'] for r in rows])
    above = np.flatnonzero(e >= level)
    if above.size == 0:
        return float('nan')
    k = int(above[0])
    if k == 0:
        return float(a[0])
    frac = (np.log(level) - np.log(e[k - 1])) / (np.log(e[k]) - np.log(e[k - 1]))
    return float(np.exp(np.log(a[k - 1]) + frac * (np.log(a[k]) - np.log(a[k - 1]))))
