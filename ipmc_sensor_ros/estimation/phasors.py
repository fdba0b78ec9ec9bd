# SPDX-License-Identifier: Apache-2.0
"""
The lines the estimator's model turns: mains and periodic-motion frequencies, and their blocks.

A line is a phasor pair (in phase, quadrature) turning at 2 pi f (:mod:`.statespace`): the
mains line and its harmonics below 0.45 fs, each periodic motion's harmonics below the
motion band.
"""
from __future__ import annotations

import math

import numpy as np

from ..lti.discretize import USABLE_BAND_FRACTION

__all__ = ['harmonics_below', 'line_frequencies_hz', 'motion_lines', 'write_phasors']


def harmonics_below(fundamental_hz: float, limit_hz: float, count: int) -> tuple:
    """Return k f, k = 1..count, below ``limit_hz`` (none for a fundamental of 0), Hz."""
    if not fundamental_hz:
        return ()
    return tuple(k * fundamental_hz for k in range(1, count + 1)
                 if k * fundamental_hz < limit_hz)


def line_frequencies_hz(line_hz: float, sample_rate_hz: float, harmonics: int) -> tuple:
    """Return the mains line and its harmonics below 0.45 fs (none for ``line_hz`` 0), Hz."""
    return harmonics_below(line_hz, USABLE_BAND_FRACTION * sample_rate_hz, harmonics)


def write_phasors(A: np.ndarray, Q: np.ndarray, first: int, frequencies_hz, walk) -> None:
    """Write phasor pairs from state ``first``: turning at 2 pi f, walking by ``walk`` (each)."""
    walks = np.broadcast_to(np.asarray(walk, dtype=float), (len(frequencies_hz),))
    for k, f in enumerate(frequencies_hz):
        j = first + 2 * k
        A[j, j + 1], A[j + 1, j] = -2 * math.pi * f, 2 * math.pi * f
        Q[j, j] = Q[j + 1, j + 1] = walks[k] ** 2


def motion_lines(fundamentals_hz: tuple, limit_hz: float, count: int,
                 apart: float) -> tuple[tuple, tuple]:
    """
    Return the periodic motions' lines, Hz, and the fundamental each belongs to.

    Each motion's harmonics k f (k = 1..``count``) below ``limit_hz``; a line within
    ``apart`` (relative) of one already listed (another motion's harmonic) is that one.
    """
    lines, of = [], []
    for f0 in fundamentals_hz:
        for f in harmonics_below(f0, limit_hz, count):
            if all(abs(f - g) > apart * max(f, g) for g in lines):
                lines.append(f)
                of.append(f0)
    return tuple(lines), tuple(of)
