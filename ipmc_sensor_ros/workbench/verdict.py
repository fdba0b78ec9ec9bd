# SPDX-License-Identifier: Apache-2.0
"""
What :func:`~ipmc_sensor_ros.workbench.diagnose.diagnose` returns: candidates, steps, verdict.

:class:`Candidate` (one fitted model and its held-out error), :class:`Step` (one move of the
stepwise search: added, dropped or swapped, with the fitted values and the ties) and
:class:`Diagnosis` (the verdict with its JSON and text forms).  The search itself lives in
:mod:`~ipmc_sensor_ros.workbench.diagnose`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .timefit import FitSpec, ModelFit, PreparedRecord

__all__ = ['Candidate', 'Step', 'Diagnosis']


@dataclass
class Candidate:
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
    """One accepted change of the model (``action``: added / dropped)."""

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
            'steps': [s.to_json() for s in self.steps],
            'final': {**final.to_json(), 'model': final.fit.models[0].describe()},
            'noise_floor': self.noise_floor,
            'cross_validation': self.cv,
            'interference': [d for d in self.interference if d.get('removable')],
            'interference_not_separable': [d for d in self.interference if not d.get('removable')],
            'offset_test': self.offset_test,
            'verdict': {
                'missing_effects': self.missing_effects,
                'missing_effect': self.missing_effect,
                'explained': self.explained,
                'reason': self.reason,
                'ties': self.ties,
                'error': final.error,
            },
        }

    def summary(self) -> str:
        lines = [f'baseline {self.baseline.fit.models[0].describe()}: held-out error '
                 f'{self.baseline.error:.4f} (noise floor {self.noise_floor:.4f}; {self.cv})']
        for d in self.interference:
            if d.get('removable'):
                lines.append(
                    f"interference: {d['frequency_hz']:g} Hz line (measured "
                    f"{d['measured_hz'][0]:.3f}-{d['measured_hz'][1]:.3f} Hz), level "
                    f"{d['level']:.3g} of the signal RMS in {d['records']} record(s): removed "
                    'before fitting'
                )
        if self.offset_test:
            ot = self.offset_test
            lines.append(f"offset test: mean residual current {ot['mean_a'] * 1e9:.3g} nA, chi2 "
                         f"{ot['chi2']:.1f}/{ot['dof']} (p = {ot['p_value']:.2g})")
        lines.append(
            f"first step: {'rank':>4} {'effect':<24} {'error':>8} {'x better':>8} {'dBIC':>10}  "
            'params / flags'
        )
        for k, c in enumerate(self.candidates, 1):
            ratio = self.baseline.error / c.error if c.error > 0 else float('inf')
            params = ', '.join(f'{n}={v:.4g}' for n, v in c.params.items())
            flags = ('  [' + '; '.join(c.flags) + ']') if c.flags else ''
            mark = ' ' if c.held_out else '*'
            lines.append(f'            {k:>4} {c.effect:<24} {c.error:8.4f}{mark}{ratio:7.2f} '
                         f'{c.fit.bic - self.baseline.fit.bic:10.1f}  {params}{flags}')
        if any(not c.held_out for c in self.candidates):
            lines.append(
                '            (* in-sample error: the BIC rule already rejects it, '
                'not cross-validated)'
            )
        for k, s in enumerate(self.steps, 1):
            vals = '; '.join(f'{e}: ' + ', '.join(f'{n}={v:.4g}' for n, v in vs.items())
                             for e, vs in s.values.items() if e != 'material')
            lines.append(
                f'step {k}: {s.action} {s.effect}: held-out error {s.error:.4f}  ({vals})'
            )
            for t in s.ties:
                lines.append(
                    f"        tie: {t['effect']} (error {t['error']:.4f}, "
                    f"dBIC {t['delta_bic']:+.0f}"
                    f"{', implausible' if t['flags'] else ''}): "
                    + ', '.join(f'{n}={v:.4g}' for n, v in t['params'].items())
                )
        lines.append(f"verdict: missing effects = {self.missing_effects or 'none'}; explained = "
                     f'{self.explained} ({self.reason})')
        if self.ties:
            lines.append('ties (indistinguishable on these data): ' + ', '.join(self.ties))
        return '\n'.join(lines)
