# SPDX-License-Identifier: Apache-2.0
"""
Time-domain output-error fit of a model (material parameters + effect parameters).

Used by the diagnosis: every effect, built-in or plugin, acts on the predicted
current through :func:`~ipmc_sensor_ros.simulation.sensor.predict_current`,
so fitting in the time domain treats them all alike (LTI factors, input and
output transforms, time-varying material).

Residuals are ``(y - y_hat) / sigma_r`` on a decimated subset of each record's
samples (at most ``max_rows_per_record``, after ``settle_s``), sigma_r the
record's noise RMS; free material parameters are fitted in log space, effect
parameters in log or linear space as their :class:`EffectParameter` says,
within their bounds (:func:`scipy.optimize.least_squares`, ``trf``).

The records, their preparation and the fast prediction of the current
(:func:`~ipmc_sensor_ros.workbench.timepredict.prepare`,
:func:`~ipmc_sensor_ros.workbench.timepredict.predict`) live in
:mod:`~ipmc_sensor_ros.workbench.timepredict`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy.optimize import least_squares

from ..physics.effects import effect_parameter
from ..physics.model import EffectSpec, SensorModel
from ..physics.parameters import MATERIAL_LIMITS, MaterialParameters, ParameterError
from .timepredict import PreparedRecord, predict

__all__ = ['FitSpec', 'ModelFit', 'fit_model']


@dataclass(frozen=True)
class FitSpec:
    """What is free: material parameter names and (effect, parameter) pairs."""

    material: tuple[str, ...] = ()
    effect_params: tuple[tuple[str, str], ...] = ()


@dataclass
class ModelFit:
    """
    Result of :func:`fit_model`: the fitted models and the fit's statistics.

    Attributes
    ----------
    models : the fitted model of each record (in the order of the prepared records).
    material : the fitted material parameters (SI units, as :class:`MaterialParameters`).
    effect_values : effect name -> parameter name -> fitted value, in the parameter's unit.
    chi2 : sum of the squared residuals, each in units of its record's noise RMS.
    n_rows : residuals (decimated samples) fitted.
    n_params : free parameters fitted.
    success : whether the optimiser reported convergence.
    flags : warnings: parameters at a bound, effect values outside their plausible range.
    covariance : covariance of the fit-space parameters (logs of log-scale ones) from the
        Jacobian at the optimum, (J^T J)^-1 scaled by chi^2/dof when that exceeds 1; None
        without free parameters.

    """

    models: list[SensorModel]            # fitted model per record
    material: MaterialParameters
    effect_values: dict[str, dict[str, float]]
    chi2: float
    n_rows: int
    n_params: int
    success: bool
    flags: list[str] = field(default_factory=list)
    covariance: np.ndarray | None = None

    @property
    def bic(self) -> float:
        return float(self.chi2 + self.n_params * np.log(max(self.n_rows, 1)))

    @property
    def aic(self) -> float:
        return float(self.chi2 + 2 * self.n_params)


def _apply(models: Sequence[SensorModel], material_names, effect_keys, x, base_material):
    mat_changes = {n: float(np.exp(v)) for n, v in zip(material_names, x[:len(material_names)])}
    ev: dict[str, dict[str, float]] = {}
    logs = [effect_parameter(e, p).log_scale for e, p in effect_keys]
    for (eff_name, par_name), v, log in zip(effect_keys, x[len(material_names):], logs):
        ev.setdefault(eff_name, {})[par_name] = float(np.exp(v)) if log else float(v)
    out, built = [], {}
    for m in models:
        # records of one sample share their base model: build (and compile) it once
        if m in built:
            out.append(built[m])
            continue
        mat = m.material.replace(**mat_changes) if mat_changes else m.material
        effects = []
        for spec in m.effects:
            if spec.name in ev:
                vals = spec.as_dict()
                vals.update(ev[spec.name])
                effects.append(EffectSpec(spec.name, tuple(sorted(vals.items()))))
            else:
                effects.append(spec)
        built[m] = SensorModel(m.geometry, mat, tuple(effects))
        out.append(built[m])
    return out, ev


def fit_model(
    prepared: Sequence[PreparedRecord],
    free: FitSpec,
    *,
    train: Sequence[np.ndarray] | None = None,
    starts: Sequence[np.ndarray] | None = None,
    bounds_factor: float = 100.0,
    max_nfev: int = 60,
) -> ModelFit:
    """
    Fit ``free`` to the prepared records (all rows, or ``train[r]`` row masks per record).

    Each record's model must already contain every effect named in ``free``.
    ``starts``: optional list of starting vectors (fit space); the one of lowest cost is
    refined.  A material parameter is bounded to ``bounds_factor`` either side of the span of
    the model's value and the starts' (and to its physical range).
    """
    models = [p.rec.model for p in prepared]
    base = models[0].material
    mat_names = tuple(free.material)
    eff_keys = tuple(free.effect_params)
    x0, lo, hi = [], [], []
    for k, n in enumerate(mat_names):
        v = np.log(getattr(base, n))
        x0.append(v)
        # within bounds_factor of the model's value and of every start's, and inside the
        # physical range (a bound past it let a fit end where the model cannot be built)
        span = [v] + [float(st[k]) for st in (starts or [])]
        limit = MATERIAL_LIMITS.get(n, (0.0, None))
        lo.append(max(min(span) - np.log(bounds_factor), np.log(max(limit[0], 1e-300)) + 1e-9))
        top = max(span) + np.log(bounds_factor)
        hi.append(top if limit[1] is None else min(top, np.log(limit[1]) - 1e-9))
    for eff_name, par_name in eff_keys:
        par = effect_parameter(eff_name, par_name)
        current = models[0].effect_values(eff_name)[par_name]
        if par.log_scale:
            x0.append(np.log(current))
            lo.append(np.log(par.lower))
            hi.append(np.log(par.upper))
        else:
            x0.append(current)
            lo.append(par.lower)
            hi.append(par.upper)
    x0, lo, hi = np.array(x0, float), np.array(lo, float), np.array(hi, float)
    rows = [p.rows if train is None else p.rows[train[k][p.rows]] for k, p in enumerate(prepared)]
    n_rows = int(sum(r.size for r in rows))

    def residual(x):
        try:
            ms, _ = _apply(models, mat_names, eff_keys, x, base)
            cache: dict = {}
            parts = [
                (p.y[r] - predict(p, m, cache, r)) / p.sigma for p, m, r in zip(prepared, ms, rows)
            ]
        except (ParameterError, ValueError, FloatingPointError):
            return np.full(n_rows, 1e3)
        res = np.concatenate(parts)
        return np.where(np.isfinite(res), res, 1e3)

    if x0.size == 0:
        r = residual(x0)
        ms, ev = _apply(models, mat_names, eff_keys, x0, base)
        return ModelFit(ms, ms[0].material, ev, float(r @ r), n_rows, 0, True)
    candidates = [np.clip(np.asarray(st, float), lo + 1e-9 * (hi - lo), hi - 1e-9 * (hi - lo))
                  for st in (starts or [x0])]
    if len(candidates) > 1:
        # screen the starts by their cost and refine only the best one
        costs = [float(np.sum(residual(c) ** 2)) for c in candidates]
        candidates = [candidates[int(np.argmin(costs))]]
    best = least_squares(residual, candidates[0], bounds=(lo, hi), method='trf', x_scale='jac',
                         diff_step=1e-4, max_nfev=max_nfev)
    ms, ev = _apply(models, mat_names, eff_keys, best.x, base)
    flags = []
    for k, (v, l, h) in enumerate(zip(best.x, lo, hi)):
        name = mat_names[k] if k < len(mat_names) else '/'.join(eff_keys[k - len(mat_names)])
        if (v - l) < 1e-3 * (h - l) or (h - v) < 1e-3 * (h - l):
            flags.append(f'{name} at bound')
        if k >= len(mat_names):
            par = effect_parameter(*eff_keys[k - len(mat_names)])
            val = float(np.exp(v)) if par.log_scale else float(v)
            if not par.typical[0] <= val <= par.typical[1]:
                flags.append(f'{name} = {val:.4g} {par.unit} outside plausible range '
                             f'[{par.typical[0]:g}, {par.typical[1]:g}]')
    chi2 = float(2 * best.cost)
    scale = max(1.0, chi2 / max(n_rows - best.x.size, 1))
    cov = np.linalg.pinv(best.jac.T @ best.jac) * scale
    return ModelFit(ms, ms[0].material, ev, chi2, n_rows, int(best.x.size), bool(best.success),
                    flags, cov)
