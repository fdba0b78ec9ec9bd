# SPDX-License-Identifier: Apache-2.0
"""Glue between loaded measurements and the analyses: per-record models and FRF groups."""
from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np
from scipy.interpolate import CubicSpline

from ..errors import DataError
from ..estimation.instants import ON_SLOT
from ..interface.specs import defaults, ESTIMATOR_SPECS
from ..physics.model import SensorModel
from ..physics.parameters import MaterialParameters
from .freqfit import FitGroup
from .freqresp import FrequencyPoint
from .measurements import FrequencyResponseData, TimeSeries, sample_label
from .stamps import stamp_steps
from .tones import tone_responses
from .timepredict import Record

__all__ = ['material_for', 'records_from', 'on_sample_grid', 'OnGrid', 'taken_at_stamps',
           'groups_from', 'frf_points']

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
        t, (w, y), filled, at_stamps = grid or (ts.time_s, (ts.deflection_m, ts.current_a),
                                                None, False)
        if filled is not None and not filled.any():
            filled = None
        out.append(Record(ts.path, sample_label(ts), model, t, w, y, filled, at_stamps))
    return out


class OnGrid(NamedTuple):
    """A record put on its sample clock (:func:`on_sample_grid`)."""

    time_s: np.ndarray
    columns: tuple
    filled: np.ndarray
    #: the rows were taken at their stamps (a DAQ the host times), not on the clock's slots
    at_stamps: bool


def on_sample_grid(path: str, time_s, *columns, max_gap_s: float = MAX_GAP_S):
    """
    Return a record on its sample clock (:class:`OnGrid`), or None when it is on it already.

    The model predicts the current from the deflection on the sample clock (an FFT over the
    samples).  Each stamp takes its slot by the stream's rule
    (:class:`~ipmc_sensor_ros.estimation.timebase.Timebase`: jitter up to a quarter of the
    period, the clock's period and phase followed).  A dropped row would join the motion
    before and after it (a spurious charge in the prediction): each column is interpolated
    (cubic spline) at the slots no row holds, which ``filled`` marks: the model's input
    there, never fitted or scored.  Rows taken at their stamps (:func:`taken_at_stamps`) are
    interpolated onto the slots, every one (read as if on them, a 13 Hz crank's +-20 % jitter
    was a 5 % error no model explains).  None: no slot is missing and the rows are on their
    slots, or a stamp has no slot of its own.  A gap longer than ``max_gap_s`` (the stream's)
    is refused: the motion in it is unknown.  The first column decides where rows were taken.
    """
    t = np.asarray(time_s, float)
    if t.size < 8 or not np.all(np.diff(t) > 0):
        return None
    steps = stamp_steps(path, t, max_gap_s)
    if steps is None:
        return None
    slots = np.concatenate([[0], np.cumsum(steps)])
    at_stamps = taken_at_stamps(t, slots, np.asarray(columns[0], float))
    if np.all(steps == 1) and not at_stamps:
        return None
    filled = np.ones(slots[-1] + 1, bool)
    filled[slots] = False
    slope, intercept = np.polyfit(slots, t, 1)
    clock = intercept + slope * np.arange(filled.size)
    knots = t if at_stamps else clock[slots]        # where each row's value was taken
    out = [None if c is None else CubicSpline(knots, np.asarray(c, float))(clock)
           for c in columns]
    if not at_stamps:                   # rows on their slots keep their values and stamps
        for c, column in zip(columns, out):
            if c is not None:
                column[slots] = c
        clock[slots] = t
    return OnGrid(clock, tuple(out), filled, at_stamps)


def taken_at_stamps(time_s, slots, values) -> bool:
    """
    Return True when ``values`` were taken at their stamps rather than on their slots.

    A DAQ on its own clock samples on the slots and the host stamps late by a varying delay;
    a DAQ the host times samples when it stamps (the estimator weighs both:
    :mod:`~ipmc_sensor_ros.estimation.instants`).  A smooth signal (the deflection) is
    smooth against the instants it was taken at: each interior value is predicted by the
    cubic through its two neighbours either side, placed at their slots or at their stamps,
    and the smaller RMS of what is left says where (stamps all within
    :data:`~ipmc_sensor_ros.estimation.instants.ON_SLOT` of the clock are on their slots).
    """
    t, k, v = (np.asarray(a, float) for a in (time_s, slots, values))
    if t.size < 5:
        return False
    slope, intercept = np.polyfit(k, t, 1)
    if np.max(np.abs(t - (intercept + slope * k))) <= ON_SLOT * slope:
        return False                    # the estimator's rule: within ON_SLOT, on the slot
    on_slots, at_stamps = (_cubic_miss(x, v) for x in (k, t))    # (weights: affine-free)
    return bool(at_stamps < on_slots)


def _cubic_miss(x: np.ndarray, v: np.ndarray) -> float:
    """RMS of each interior value less the cubic through its two neighbours either side."""
    centre = x[2:-2]
    near = [x[:-4], x[1:-3], x[3:-1], x[4:]]
    vals = [v[:-4], v[1:-3], v[3:-1], v[4:]]
    guess = np.zeros(centre.size)
    for j, (xj, vj) in enumerate(zip(near, vals)):
        weight = np.ones(centre.size)
        for m, xm in enumerate(near):
            if m != j:
                weight *= (centre - xm) / (xj - xm)
        guess += weight * vj
    return float(np.sqrt(np.mean((v[2:-2] - guess) ** 2)))


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
