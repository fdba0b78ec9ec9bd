# SPDX-License-Identifier: Apache-2.0
"""
What :func:`~ipmc_sensor_ros.workbench.diagnose.diagnose` returns: candidates, steps, verdict.

:class:`Candidate` (one fitted model and its held-out error), :class:`Step` (one move of the
stepwise search: added, dropped, swapped or kept, with the fitted values and the ties) and
:class:`Diagnosis` (the verdict with its JSON form; its text form is :mod:`.summary`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..timefit import FitSpec, ModelFit
from ..timepredict import PreparedRecord

__all__ = ['Candidate', 'Step', 'Diagnosis']


@dataclass
class Candidate:
    """One fitted model: its error (held-out when ``held_out``), fit, parameters and flags."""

    effect: str | None
    error: float
    fold_errors: list[float]
    fit: ModelFit
    params: dict
    flags: list[str] = field(default_factory=list)
    shape: tuple[str, ...] = ()          # the effect's free parameters
    x: np.ndarray | None = None          # fit vector (for warm starts)
    spec: FitSpec | None = None
    held_out: bool = True                # False: ``error`` is the in-sample error (not scored)
    in_sample_error: float | None = None

    @property
    def plausible(self) -> bool:
        return not self.flags

    def to_json(self, baseline: 'Candidate | None' = None) -> dict:
        d = {'effect': self.effect, 'error': self.error, 'fold_errors': self.fold_errors,
             'params': self.params, 'bic': self.fit.bic, 'aic': self.fit.aic,
             'chi2': self.fit.chi2, 'n_params': self.fit.n_params, 'flags': self.flags,
             'fitted_parameters': list(self.shape), 'held_out': self.held_out}
        if baseline is not None:
            d['delta_bic'] = self.fit.bic - baseline.fit.bic
            d['improvement'] = baseline.error / self.error if self.error > 0 else float('inf')
        return d


@dataclass
class Step:
    """
    One accepted change of the model.

    ``action``: added, dropped, swapped, or kept (an effect of the first search that the
    search beside C(s) names again: refitted beside C(s), not added a second time).
    """

    effect: str
    action: str
    error: float
    bic: float
    values: dict                          # effect -> fitted values, plus 'material'
    reason: str
    ties: list[dict] = field(default_factory=list)
    alternatives: list[str] = field(default_factory=list)   # plausible scored runners-up

    def to_json(self) -> dict:
        return {'effect': self.effect, 'action': self.action, 'error': self.error, 'bic': self.bic,
                'values': self.values, 'reason': self.reason, 'ties': self.ties}


@dataclass
class Diagnosis:
    """The verdict: the named effects, what keeps each, the lines, the correction C(s)."""

    baseline: Candidate
    candidates: list[Candidate]          # first step's ranking
    noise_floor: float
    missing_effect: str | None
    explained: bool
    reason: str
    ties: list[str]
    prepared: list[PreparedRecord]
    cv: str
    steps: list[Step] = field(default_factory=list)
    missing_effects: list[str] = field(default_factory=list)
    final: Candidate | None = None
    interference: list[dict] = field(default_factory=list)
    offset_test: dict = field(default_factory=dict)
    line_test: dict = field(default_factory=dict)
    kept_by: dict = field(default_factory=dict)
    correction: object | None = None      # :class:`~.correction.Correction` or None
    unranked: str = ''                    # why ``candidates`` is empty (the search stopped)

    @property
    def final_model(self):
        """Fitted model of the first record after the last step."""
        return (self.final or self.baseline).fit.models[0]

    def to_json(self) -> dict:
        final = self.final or self.baseline
        return {
            'baseline': {
                **self.baseline.to_json(),
                'model': self.baseline.fit.models[0].describe(),
            },
            'candidates': [c.to_json(self.baseline) for c in self.candidates],
            'unranked': self.unranked,
            'steps': [s.to_json() for s in self.steps],
            'final': {**final.to_json(), 'model': final.fit.models[0].describe()},
            'noise_floor': self.noise_floor,
            'cross_validation': self.cv,
            'interference': self.interference,
            'line_test': self.line_test,
            'offset_test': self.offset_test,
            'correction': self.correction.to_json() if self.correction is not None else None,
            'verdict': {
                'missing_effects': self.missing_effects,
                'missing_effect': self.missing_effect,
                'explained': self.explained,
                'reason': self.reason,
                'ties': self.ties,
                'kept_by': self.kept_by,
                'error': final.error,
            },
        }

    def summary(self) -> str:
        """Return the verdict as text (:func:`~.summary.summary_text`)."""
        from .summary import summary_text

        return summary_text(self)
