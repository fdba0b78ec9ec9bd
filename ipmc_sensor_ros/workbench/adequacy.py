# SPDX-License-Identifier: Apache-2.0
"""
Implausible magnitudes in measured records, with the likely unit factor.

A tip deflection beyond L/2 cannot be bent by the crank-slider on these
cantilevers (the small-deflection model fails far earlier), a short-circuit
current above 1 mA is three orders above any IPMC of these geometries (tens of
nA to a few uA, paper Fig. 5), and a measured gain at the stimulus fundamental
60 dB (a factor 1000) away from the model is not a model error but a scale
error.  Each flag names the record, the quantity and the power-of-1000 factor
that would bring it into range (mm or um stored under m, uA or nA under A).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ['magnitude_flags', 'MAX_CURRENT_A', 'MAX_GAIN_DB']

MAX_CURRENT_A = 1e-3
MAX_GAIN_DB = 60.0
_UNIT = {1e-3: 'milli', 1e-6: 'micro', 1e-9: 'nano', 1e3: 'kilo'}


def _factor(ratio: float) -> float:
    """Power of 1000 nearest to 1/ratio (the factor to multiply the data by)."""
    return float(10.0 ** (-3 * round(np.log10(ratio) / 3)))


def magnitude_flags(records: Sequence, model_for=None) -> list[str]:
    """
    Return flags for records whose magnitudes are implausible.

    Records: objects with ``path``, ``time_s``, ``deflection_m``, ``current_a`` and
    ``model``, :class:`~.timepredict.Record`, or give ``model_for(record)``.
    """
    from .freqresp import fundamental_response

    out = []
    for r in records:
        model = model_for(r) if model_for is not None else r.model
        L = model.geometry.length_m
        w = None if r.deflection_m is None else np.asarray(r.deflection_m, float)
        i = np.asarray(r.current_a, float)
        if w is not None and np.max(np.abs(w)) > L / 2:
            wmax = float(np.max(np.abs(w)))
            f = _factor(wmax / (0.05 * L))
            out.append(f'{r.path}: deflection up to {wmax:.4g} m on a {L:.4g} m beam (> L/2): '
                       f"likely stored in {_UNIT.get(f, f'x{f:g}')}metres; multiply by {f:g}")
            continue
        if np.max(np.abs(i)) > MAX_CURRENT_A:
            imax = float(np.max(np.abs(i)))
            f = _factor(imax / 1e-7)
            out.append(
                f'{r.path}: current up to {imax:.4g} A (> {MAX_CURRENT_A:g} A for these '
                f"geometries): likely stored in {_UNIT.get(f, f'x{f:g}')}amperes; "
                f'multiply by {f:g}'
            )
            continue
        if w is None:
            continue
        try:
            p = fundamental_response(r.time_s, w, i)
        except ValueError:
            continue
        model_gain = float(np.abs(model.frequency_response(np.array([p.frequency_hz]))[0]))
        ratio = p.gain_a_per_m / model_gain if model_gain > 0 else np.inf
        if np.isfinite(ratio) and ratio > 0 and abs(20 * np.log10(ratio)) > MAX_GAIN_DB:
            f = _factor(ratio)
            out.append(
                f'{r.path}: gain at {p.frequency_hz:.3g} Hz is '
                f'{20 * np.log10(ratio):+.0f} dB off the '
                f'model (> {MAX_GAIN_DB:g} dB): a unit error of current or deflection; the '
                f'current x {f:g} (or the deflection / {f:g}) would fit'
            )
    return out
