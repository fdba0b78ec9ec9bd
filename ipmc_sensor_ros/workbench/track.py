# SPDX-License-Identifier: Apache-2.0
"""
Time-varying parameter tracking over a long record (paper section 5.4, Figs. 9-10).

The paper refits d minute by minute while an IPMC dries in air.  Here the
record is cut into consecutive windows (``window_s`` long, advanced by
``step_s``); in each window the response at the excitation fundamental is
measured with its uncertainty (:func:`~.freqresp.fundamental_response`) and
the chosen parameter(s) refitted with the others fixed
(:func:`~.fit.fit_parameters`), giving a trajectory with 95 % confidence bands.

Given the model found by ``diagnose`` (``model``, e.g. from a saved model file),
every window also carries the model's own trajectory at its centre
(``model_estimates``): for ``hydration_drift`` the fitted d(t) of the relaxation
toward equilibrium (:func:`model_trajectory`), so the windowed refits and the
smooth drift can be read side by side.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..errors import DataError, ParameterError
from ..physics.effects import get_effect
from ..physics.model import SensorModel
from ..physics.parameters import Geometry, MaterialParameters
from .freqfit import FitGroup, fit_parameters
from .freqresp import fundamental_response

__all__ = ['TrackPoint', 'track_parameter', 'model_trajectory']


@dataclass(frozen=True)
class TrackPoint:
    time_s: float            # window centre
    estimates: dict          # name -> value
    ci95: dict               # name -> (low, high)
    frequency_hz: float
    gain_a_per_m: float
    phase_deg: float
    model_estimates: dict | None = None   # name -> the model's time-varying value (see module doc)


def model_trajectory(
    model: SensorModel, elapsed_s, names: Sequence[str] = ('diffusivity_m2_per_s',)
):
    """
    Values of material parameters ``names`` of ``model`` at ``elapsed_s`` seconds.

    Seconds from the record start, following its time-varying effect (e.g.
    ``hydration_drift``); None if the model has none.
    """
    for spec in model.effects:
        mat_at = get_effect(spec.name).material_at(model, spec.as_dict())
        if mat_at is not None:
            return {n: np.array([getattr(mat_at(float(t)), n) for t in np.atleast_1d(elapsed_s)])
                    for n in names}
    return None


def track_parameter(time_s, deflection_m, current_a, geometry: Geometry,
                    material: MaterialParameters, free: Sequence[str] = ('diffusivity_m2_per_s',),
                    effects: tuple = ('surface_resistance',), *, window_s: float = 60.0,
                    step_s: float | None = None, known: dict | None = None,
                    source: str = '', model: SensorModel | None = None) -> list[TrackPoint]:
    """
    Refit ``free`` in consecutive windows; returns one :class:`TrackPoint` per window.

    Each window's fit starts from the previous window's estimate.
    """
    t = np.asarray(time_s, float)
    w = np.asarray(deflection_m, float)
    i = np.asarray(current_a, float)
    step_s = step_s or window_s
    if not (window_s > 0 and step_s > 0):
        raise ParameterError('window_s and step_s must be > 0')
    if t[-1] - t[0] < window_s:
        raise DataError(f'{source}: record of {t[-1] - t[0]:.3g} s is shorter than one window '
                        f'({window_s} s)')
    out: list[TrackPoint] = []
    current = material
    start = t[0]
    dt = (t[-1] - t[0]) / max(t.size - 1, 1)
    while start + window_s <= t[-1] + dt * 1.0001:
        sel = (t >= start) & (t < start + window_s)
        point = fundamental_response(t[sel], w[sel], i[sel], source=f'{source}@{start:.1f}s')
        res = fit_parameters(
            [FitGroup(geometry, [point], dict(known or {}))], free, current, effects
        )
        current = res.material
        centre = float(start + window_s / 2)
        traj = model_trajectory(model, centre - t[0], free) if model is not None else None
        out.append(TrackPoint(time_s=centre, estimates=dict(res.estimates),
                              ci95=dict(res.ci95), frequency_hz=point.frequency_hz,
                              gain_a_per_m=point.gain_a_per_m, phase_deg=point.phase_deg,
                              model_estimates=None if traj is None else
                              {n: float(v[0]) for n, v in traj.items()}))
        start += step_s
    return out
