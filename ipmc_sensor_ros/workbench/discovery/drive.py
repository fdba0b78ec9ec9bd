# SPDX-License-Identifier: Apache-2.0
"""
The drive of a record: its fundamental and the harmonics that carry deflection content.

Found once per record and diagnosis (:func:`drive_of`) and used by the line test (which
regresses out the drive harmonics and asks whether a line sits on one) and by the periodic
history (whose period it gives).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...lti.discretize import USABLE_BAND_FRACTION
from ..freqresp import fundamental_response, harmonic_fit

__all__ = ['Drive', 'drive_of', 'CONTENT_FRACTION']

#: a harmonic carries deflection content when its amplitude is at least this fraction of the
#: fundamental's (a crank-slider's 2nd harmonic is ~r/4l = 3 %, its 4th ~1e-3, the rest less)
CONTENT_FRACTION = 1e-4


@dataclass(frozen=True)
class Drive:
    """``frequency_hz``: the fundamental (None: not periodic); ``harmonics_hz``: with content."""

    frequency_hz: float | None = None
    harmonics_hz: tuple = ()


def drive_of(rec, max_harmonics: int = 20) -> Drive:
    """
    Return the drive of ``rec`` (``time_s``, ``deflection_m``), from its deflection alone.

    The fundamental from :func:`~ipmc_sensor_ros.workbench.freqresp.fundamental_response`
    (refined by a harmonic fit); the harmonics up to ``max_harmonics`` below 0.45 of the rate
    with at least :data:`CONTENT_FRACTION` of the fundamental's amplitude.  Not periodic (no
    fundamental) when the harmonics leave more than a tenth of the deflection's variance.
    """
    w = getattr(rec, 'deflection_m', None)
    if w is None:
        return Drive()
    t = np.asarray(rec.time_s, float) - rec.time_s[0]
    w = np.asarray(w, float)
    try:
        f0 = fundamental_response(t, w, w).frequency_hz
    except ValueError:
        return Drive()
    fs = (t.size - 1) / t[-1]
    k_max = min(int(USABLE_BAND_FRACTION * fs / f0), max_harmonics)
    if k_max < 1 or f0 * t[-1] < 2:
        return Drive()
    phasors, resid, _ = harmonic_fit(t, w, f0, k_max)
    if np.var(resid) > 0.1 * np.var(w):
        return Drive()
    amps = np.abs(phasors)
    return Drive(float(f0), tuple(float((k + 1) * f0)
                                  for k in np.flatnonzero(amps >= CONTENT_FRACTION * amps[0])))
