# SPDX-License-Identifier: Apache-2.0
"""Glue between loaded measurements and the analyses: per-record models and FRF groups."""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..physics.model import SensorModel
from ..physics.parameters import MaterialParameters
from .freqfit import FitGroup
from .freqresp import FrequencyPoint, fundamental_response
from .measurements import FrequencyResponseData, TimeSeries, sample_label
from .timepredict import Record

__all__ = ['material_for', 'records_from', 'groups_from', 'frf_points']

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
            raise ValueError(f"{getattr(ts, 'path', ts)}: a time series is needed here "
                             '(this is a frequency-response file)')
        if ts.deflection_m is None:
            raise ValueError(f'{ts.path}: no deflection column: cannot compare or fit')
        model = SensorModel(ts.geometry, material_for(ts, material), effects)
        out.append(Record(ts.path, sample_label(ts), model,
                          ts.time_s, ts.deflection_m, ts.current_a))
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

    Time series through the fundamental-response extraction (paper
    section 5.2).
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
                raise ValueError(f'{d.path}: no deflection column: cannot measure the response')
            try:
                g.points.append(fundamental_response(d.time_s, d.deflection_m, d.current_a,
                                                     source=d.path, min_periods=min_periods))
            except ValueError as exc:
                raise ValueError(f'{exc}; fit reads periodic (crank-slider) records: '
                                 f'`ipmc-model diagnose DATA --save-model FILE` fits the '
                                 f'material in the time domain on any record') from None
    return list(groups.values())
