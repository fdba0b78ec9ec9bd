# SPDX-License-Identifier: Apache-2.0
"""
What a forward pass of the filter keeps per sample for the smoothers.

:mod:`.smoother` and :mod:`.fixed_lag` need the predictions, the updates, the transition's
steps, the rest flag and the row of the published deflection of each sample;
:mod:`.step_glr` the current's update: its row and normalised innovation.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

__all__ = ['ForwardRecord', 'astuple_shallow']


@dataclass
class ForwardRecord:
    """Per-sample predictions and updates of a forward pass (what the RTS smoother needs)."""

    x_pred: np.ndarray
    P_pred: np.ndarray
    x_post: np.ndarray
    P_post: np.ndarray
    steps: np.ndarray
    still: np.ndarray
    #: the row of the published deflection (m per scaled state): the tip where the sample
    #: was taken (:attr:`~.statespace.StateSpaceModel.off_slot_rows`)
    w_row: np.ndarray
    #: the row the current was measured with (the slot's, or the stamp's: :mod:`.instants`)
    c_row: np.ndarray
    #: the current's innovation over sqrt(S), and sqrt(S) (A)
    z: np.ndarray
    s: np.ndarray

    @classmethod
    def empty(cls, n: int, nx: int) -> 'ForwardRecord':
        return cls(np.empty((n, nx)), np.empty((n, nx, nx)), np.empty((n, nx)),
                   np.empty((n, nx, nx)), np.empty(n, dtype=np.int64), np.empty(n, dtype=bool),
                   np.empty((n, nx)), np.empty((n, nx)), np.empty(n), np.empty(n))

    def rows(self, start: int, stop: int) -> 'ForwardRecord':
        """Return the record of samples ``start`` to ``stop`` (views, not copies)."""
        return ForwardRecord(*(a[start:stop] for a in astuple_shallow(self)))


def astuple_shallow(rec: ForwardRecord) -> tuple:
    """Return a record's arrays in field order (not copied)."""
    return tuple(getattr(rec, f.name) for f in fields(rec))
