# SPDX-License-Identifier: Apache-2.0
"""Glue between loaded measurements and the analyses: per-record models and FRF groups."""
from __future__ import annotations

from typing import Sequence

import numpy as np
from scipy.interpolate import CubicSpline

from ..errors import DataError
from ..estimation.timebase import JITTER_FRACTION
from ..interface.specs import defaults, ESTIMATOR_SPECS
from ..physics.model import SensorModel
from ..physics.parameters import MaterialParameters
from .freqfit import FitGroup
from .freqresp import FrequencyPoint
from .measurements import FrequencyResponseData, TimeSeries, sample_label
from .stamps import stamp_steps
from .tones import tone_responses
from .timepredict import Record

__all__ = ['material_for', 'records_from', 'on_sample_grid', 'groups_from', 'frf_points']

#: the stream's ``max_gap_s`` default: the longest gap of dropped rows bridged, s
MAX_GAP_S = float(defaults(ESTIMATOR_SPECS)['max_gap_s'])

#: relative gain / phase uncertainty assumed for FRF files without std columns
#: or coherence (1 % and 0.01 rad, typical of a careful crank-slider sweep)
DEFAULT_FRF_SD = 0.01


def material_for(data, material: MaterialParameters) -> MaterialParameters:
    """``material`` with the values the file header says are known."""
    known = {k: v for k, v in getattr(data, 'known', {}).items()
             if k in MaterialParameters.__dataclass_fields__}
    return material.replace(**known) if known else material


def records_from(series: Sequence[TimeSeries], material: MaterialParameters,
                 effects: tuple) -> list[Record]:
    out = []
    for ts in series:
        if not isinstance(ts, TimeSeries):
            raise DataError(f"{getattr(ts, 'path', ts)}: a time series is needed here "
                            '(this is a frequency-response file)')
        if ts.deflection_m is None:
            raise DataError(f'{ts.path}: no deflection column: cannot compare or fit')
        model = SensorModel(ts.geometry, material_for(ts, material), effects)
        grid = on_sample_grid(ts.path, ts.time_s, ts.deflection_m, ts.current_a)
        t, (w, y), filled = grid or (ts.time_s, (ts.deflection_m, ts.current_a), None)
        out.append(Record(ts.path, sample_label(ts), model, t, w, y, filled))
    return out


def on_sample_grid(path: str, time_s, *columns, max_gap_s: float = MAX_GAP_S):
    """
    Return ``(grid times, columns on the grid, filled)`` of a record with dropped rows, or None.

    The model predicts the current from the deflection on the sample clock (an FFT over the
    samples): a dropped row would join the motion before and after it, a jump that puts a
    spurious charge into the prediction.  Each stamp takes its sample-clock slot by the
    stream's rule (:class:`~ipmc_sensor_ros.estimation.timebase.Timebase`: jitter up to a
    quarter of the period, the clock's period and phase followed); each column is interpolated
    (cubic spline) at the slots no row holds, which ``filled`` marks: the model's input there,
    never fitted or scored.  None: no slot is missing, or a stamp has no slot of its own
    (left as they are).  A gap longer than ``max_gap_s`` (the stream's) is refused: the
    motion in it is unknown.
    """
    t = np.asarray(time_s, float)
    dt = np.diff(t)
    if t.size < 8 or not np.all(dt > 0):
        return None
    if np.max(dt) < (1 + 2 * JITTER_FRACTION) * np.median(dt):
        return None                         # no spacing holds a missing slot: nothing to fill
    steps = stamp_steps(path, t, max_gap_s)
    if steps is None or np.all(steps == 1):
        return None
    slots = np.concatenate([[0], np.cumsum(steps)])
    filled = np.ones(slots[-1] + 1, bool)
    filled[slots] = False
    slope, intercept = np.polyfit(slots, t, 1)
    t_grid = intercept + slope * np.arange(filled.size)
    t_grid[slots] = t
    return t_grid, tuple(None if c is None else _filled(t, np.asarray(c, float), t_grid, slots)
                         for c in columns), filled


def _filled(t, values, t_grid, slots) -> np.ndarray:
    """Return ``values`` at their slots of ``t_grid``, a cubic spline through them between."""
    out = CubicSpline(t, values)(t_grid)
    out[slots] = values
    return out


def frf_points(frf: FrequencyResponseData) -> list[FrequencyPoint]:
    """
    Points of an ``ipmc-frf/1`` file with standard uncertainties.

    Std columns, else the coherence formula with 16 averages, else 1 %.
    """
    pts = []
    for k, f in enumerate(frf.frequency_hz):
        if frf.gain_std_a_per_m is not None:
            sdm = float(frf.gain_std_a_per_m[k] / frf.gain_a_per_m[k])
            sdp = float(np.radians(frf.phase_std_deg[k]))
        elif frf.coherence is not None and frf.coherence[k] > 0:
            g = float(frf.coherence[k])
            sdm = sdp = float(np.sqrt(max(1 - g, 1e-12) / (2 * 16 * g)))
        else:
            sdm = sdp = DEFAULT_FRF_SD
        pts.append(FrequencyPoint(frequency_hz=float(f), response=complex(frf.response[k]),
                                  sd_log_mag=sdm, sd_phase_rad=sdp, source=frf.path,
                                  coherence=float(frf.coherence[k]) if frf.coherence is not None
                                  else float('nan')))
    return pts


def groups_from(data: Sequence, min_periods: int = 2) -> list[FitGroup]:
    """
    One FitGroup per sample: FRF files as they are.

    Time series through the fundamental-response extraction (paper section 5.2), or at
    each tone of a multi-sine drive (:mod:`.tones`).
    """
    groups: dict[tuple, FitGroup] = {}
    for d in data:
        key = (sample_label(d), d.geometry.length_m, d.geometry.width_m,
               d.geometry.thickness_m, tuple(sorted(d.known.items())))
        g = groups.setdefault(key, FitGroup(d.geometry, [], dict(d.known), name=key[0]))
        if isinstance(d, FrequencyResponseData):
            g.points.extend(frf_points(d))
        else:
            if d.deflection_m is None:
                raise DataError(f'{d.path}: no deflection column: cannot measure the response')
            try:
                g.points.extend(tone_responses(d.time_s, d.deflection_m, d.current_a,
                                               source=d.path, min_periods=min_periods))
            except ValueError as exc:
                raise DataError(f'{exc}; fit reads periodic records (a crank-slider, tones '
                                f'of a common fundamental): `ipmc-model diagnose DATA '
                                f'--save-model FILE` fits the material in the time domain '
                                f'on any record') from None
    return list(groups.values())
