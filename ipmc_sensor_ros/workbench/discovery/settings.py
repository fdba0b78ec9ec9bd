# SPDX-License-Identifier: Apache-2.0
"""
The tuning numbers of the diagnosis: few, named, with units and the reason for each value.

Every keyword argument of :func:`~ipmc_sensor_ros.workbench.diagnose.diagnose` except the
priors and the progress callback is a field of :class:`Settings`.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, fields

from ...physics.parameters import ParameterError

__all__ = ['Settings', 'DEFAULT_FREE_MATERIAL']

DEFAULT_FREE_MATERIAL = (
    'charge_stress_coupling_j_per_c',
    'diffusivity_m2_per_s',
    'permittivity_f_per_m',
)


@dataclass(frozen=True)
class Settings:
    """
    What the search may change and how much evidence each move needs.

    Attributes
    ----------
    free_material : material parameters refitted with every model (alpha0, d, kappa_e: the
        ones the paper identifies by curve fitting, Table 2).
    candidates : effects offered (None: every registered effect, plugins included).
    fit_effects : effects of the given model whose parameters are fitted too.
    max_effects : most effects the stepwise search adds.
    n_folds : folds of the held-out error (records, or time blocks with fewer records).
    explained_factor : ``explained`` when the final held-out error is at most this times the
        noise floor plus 0.001 (1.15: a model that explains the data ends 0.3-0.6 % over it).
    min_gain : relative drop of the held-out error a step must make (3 %), or half its excess
        over the floor when that is less (near the floor).
    min_delta_bic : BIC drop a step must make, and the BIC rise that makes an effect's own
        test significant (20: "very strong" on the Kass-Raftery scale).
    tie_tol : candidates within this fraction of the best held-out error are ties (5 %).
    offset_p : p-value below which the offset test names ``current_offset`` and keeps it
        (1e-6: a chi-square over the records; mean currents this unlikely are not noise).
    mains : 50, 60, 'auto' or None: the mains family whose lines are looked for.
    line_false_alarm : probability that one record without hum shows a line (1e-4: with 16
        records, one diagnosis in 600 reports a line that is not there).
    stop_factor : the search stops at this times the noise floor (1.01).
    settle_s : seconds left out at each record start, s (the model starts from rest).
    fold_nfev : function evaluations of each fold's refit (warm start at the full fit).
    max_cv : candidates per step scored by their held-out error (the lowest BIC ones).
    n_jobs : worker processes (None: up to 2).
    correction : fit a low-order correction C(s) when the catalog leaves the search above
        the floor (:mod:`.outside`).
    max_correction_order : most parameters of C(s) (3).

    """

    free_material: tuple = DEFAULT_FREE_MATERIAL
    candidates: tuple | None = None
    fit_effects: tuple = ()
    max_effects: int = 3
    n_folds: int = 4
    explained_factor: float = 1.15
    min_gain: float = 0.03
    min_delta_bic: float = 20.0
    tie_tol: float = 0.05
    offset_p: float = 1e-6
    mains: object = 'auto'
    line_false_alarm: float = 1e-4
    stop_factor: float = 1.01
    settle_s: float = 0.5
    fold_nfev: int = 15
    max_cv: int = 4
    n_jobs: int | None = None
    correction: bool = True
    max_correction_order: int = 3

    def __post_init__(self):
        object.__setattr__(self, 'free_material', tuple(self.free_material))
        object.__setattr__(self, 'fit_effects', tuple(self.fit_effects))
        if self.candidates is not None:
            object.__setattr__(self, 'candidates', tuple(self.candidates))
        if self.max_effects < 0:
            raise ParameterError(f'diagnose: max_effects must be >= 0, got {self.max_effects}')
        if not 0 < self.line_false_alarm < 1:
            raise ParameterError('diagnose: line_false_alarm must lie in (0, 1), got '
                                 f'{self.line_false_alarm}')
        if not 0 < self.offset_p < 1:
            raise ParameterError(f'diagnose: offset_p must lie in (0, 1), got {self.offset_p}')

    @classmethod
    def from_kwargs(cls, kwargs: dict) -> 'Settings':
        """Build from keyword arguments; an unknown name is an error naming the known ones."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(kwargs) - known)
        if unknown:
            raise TypeError(f'diagnose: unknown argument(s) {unknown}; known: {sorted(known)}')
        return cls(**kwargs)

    @property
    def workers(self) -> int:
        """Worker processes to use (``n_jobs``, default up to 2)."""
        return min(2, os.cpu_count() or 1) if self.n_jobs is None else int(self.n_jobs)
