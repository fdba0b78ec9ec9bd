# SPDX-License-Identifier: Apache-2.0
"""
Parameter identification from measured frequency response (paper section 5.2, done better).

The paper tunes d, C-, kappa_e and alpha0 with ``fminsearch`` on one sample.
Here:

* any subset of the material parameters is fitted, the rest fixed (or taken
  per file from its header: temperature, Young's modulus, r0);
* bounded nonlinear least squares (:func:`scipy.optimize.least_squares`,
  trust-region reflective) in **log-parameters**, on log-magnitude and phase,
  each residual divided by its measured standard uncertainty;
* many files and sample geometries are fitted jointly (geometric scalability);
* the result carries 95 % confidence intervals, the correlation matrix and an
  **identifiability report** from the SVD of the scaled Jacobian
  (:mod:`.identifiability` derives them and explains when a combination of
  parameters counts as determined).
"""
from __future__ import annotations

import math

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy.optimize import least_squares

from scipy.stats import chi2 as chi2_dist

from ..physics.model import SensorModel, parse_effects
from ..physics.parameters import PAPER_PARAMETERS, Geometry, MaterialParameters, ParameterError
from .fitmap import (FITTABLE, ParameterMap, effect_parameter_names, resolve_effect_parameter,
                     resolve_free, start_and_bounds)
from .freqresp import FrequencyPoint
from .identifiability import (confidence_intervals, covariance, named_combinations,
                              not_identifiable, svd_combinations, SYMBOLS)

__all__ = ['FitGroup', 'FitResult', 'fit_parameters', 'misfit', 'FITTABLE', 'SYMBOLS',
           'model_for_group', 'resolve_effect_parameter', 'effect_parameter_names',
           'ADEQUACY_P']

#: chi^2 p-value below which the model is declared inadequate for the data
ADEQUACY_P = 1e-3


@dataclass
class FitGroup:
    """Frequency points measured on one sample (one geometry, one header)."""

    geometry: Geometry
    points: list[FrequencyPoint]
    known: dict[str, float] = field(default_factory=dict)
    name: str = ''


@dataclass
class FitResult:
    """
    Result of :func:`fit_parameters`: estimates, intervals and identifiability.

    Parameter names are the material's (``diffusivity_m2_per_s``) or ``effect.parameter``;
    values are in the material's SI units or the effect parameter's declared ``unit``.

    Attributes
    ----------
    material : the fitted material parameters.
    effects : the effect specifications with the fitted effect parameters.
    free : names of the fitted parameters, in fit order.
    estimates : name -> fitted value.
    ci95 : name -> 95 % confidence interval (lower, upper).
    sd_log : name -> standard deviation of the fit coordinate: of ln(value) for log-scale
        parameters (all material ones), of the value for linear effect parameters.
    correlation : correlation matrix of the fit coordinates (order of ``free``).
    chi2 : sum of squared residuals (ln-magnitude and phase, each over its uncertainty).
    dof : degrees of freedom: residuals minus free parameters (at least 1).
    identifiability : combinations from the SVD of the scaled Jacobian (``expression``,
        ``sd_log``, ``sensitivity``, ``determined``), :mod:`.identifiability`.
    named_combinations : the named combinations of free parameters (``name``, ``value``,
        ``sd_log``, ``determined``).
    not_identifiable : free parameters the data do not determine alone.
    success, message : the optimiser's convergence flag and message.
    at_bound : free parameters that ended at a bound.
    residuals : the weighted residuals at the optimum.

    """

    material: MaterialParameters
    effects: tuple
    free: tuple[str, ...]
    estimates: dict[str, float]
    ci95: dict[str, tuple[float, float]]
    sd_log: dict[str, float]
    correlation: np.ndarray
    chi2: float
    dof: int
    identifiability: list[dict]
    named_combinations: list[dict]
    not_identifiable: list[str]
    success: bool
    message: str
    at_bound: list[str]
    residuals: np.ndarray

    @property
    def reduced_chi2(self) -> float:
        return self.chi2 / max(self.dof, 1)

    @property
    def p_value(self) -> float:
        """
        Probability of a chi^2 at least this large if the model were right.

        Residuals in units of their measured uncertainty.
        """
        return float(chi2_dist.sf(self.chi2, max(self.dof, 1)))

    @property
    def adequate(self) -> bool:
        return self.p_value >= ADEQUACY_P

    def adequacy_text(self) -> str:
        if self.adequate:
            return (f'model adequate: chi2/dof = {self.reduced_chi2:.3g}, p = {self.p_value:.3g} '
                    f'(>= {ADEQUACY_P:g})')
        return (
            f'model inadequate: chi2/dof = {self.reduced_chi2:.3g}, p = {self.p_value:.2g} '
            f'(< {ADEQUACY_P:g}): the misfit is far above the measurement noise; run diagnose '
            'to find the missing effect (the intervals above include the misfit, not just noise)'
        )

    def summary(self) -> str:
        lines = [
            f"fit of {', '.join(SYMBOLS.get(n, n) for n in self.free)} "
            f"({'+'.join(('h1',) + tuple(getattr(e, 'name', e) for e in self.effects))}): "
            f'chi2/dof = {self.chi2:.4g}/{self.dof} '
            f'= {self.reduced_chi2:.3g}, p = {self.p_value:.3g}'
        ]
        lines.append(f"{'parameter':<32} {'estimate':>12} {'95% CI':>27}  note")
        for name in self.free:
            lo, hi = self.ci95[name]
            note = 'at bound' if name in self.at_bound else ''
            d = interval_digits(self.estimates[name], lo, hi)
            lines.append(f'{name:<32} {self.estimates[name]:>12.{d}g} [{lo:>11.{d}g}, '
                         f'{hi:>11.{d}g}]  {note}')
        if len(self.free) > 1:
            lines.append('correlation:')
            width = max(8, *(len(SYMBOLS.get(n, n)) for n in self.free))
            for k, name in enumerate(self.free):
                row = ' '.join(f'{c:+.3f}' for c in self.correlation[k])
                lines.append(f'  {SYMBOLS.get(name, name):>{width}} {row}')
        lines.append('identifiability (SVD of the scaled Jacobian; combinations of the free '
                     'parameters; sensitivity = change of the ln-response per e-fold change):')
        for comb in self.identifiability:
            lines.append(
                f"  {comb['expression']:<44} sd(ln) = {comb['sd_log']:.3g}, sensitivity "
                f"{comb['sensitivity']:.3g}  {'determined' if comb['determined'] else 'NOT'}"
            )
        for comb in self.named_combinations:
            lines.append(
                f"  {comb['name']:<44} = {comb['value']:.5g}, sd(ln) = {comb['sd_log']:.3g}  "
                f"{'determined' if comb['determined'] else 'NOT'}"
            )
        lines.append(self.identifiability_text())
        lines.append(self.adequacy_text())
        return '\n'.join(lines)

    def identifiability_text(self) -> str:
        """One verdict: which parameters the data determine, and which only in combination."""
        names = [SYMBOLS.get(n, n) for n in self.free]
        if not self.not_identifiable:
            return ('identifiability: every free parameter is determined by these data '
                    '(each CI above stands on its own)')
        alone = [SYMBOLS.get(n, n) for n in self.free if n not in self.not_identifiable]
        shared = [SYMBOLS.get(n, n) for n in self.not_identifiable]
        n_det = sum(c['determined'] for c in self.identifiability)
        return (f'identifiability: these data determine {n_det} of {len(names)} combinations '
                f"(marked determined above){'; ' + ', '.join(alone) + ' alone' if alone else ''};"
                f" {', '.join(shared)} take part in a combination they do not determine (NOT: "
                'too weak an effect on the response, or too uncertain), so their CIs hold only '
                'if the model is exact: quote the determined combinations, or fix one of them '
                'from an independent measurement')


def model_for_group(material: MaterialParameters, group: FitGroup, free: Sequence[str],
                    effects: tuple) -> SensorModel:
    """Model of one group: header-known values override fixed parameters."""
    overrides = {k: v for k, v in group.known.items() if k not in free and k in FITTABLE}
    mat = material.replace(**overrides) if overrides else material
    return SensorModel(group.geometry, mat, effects)


def misfit(h_model, h_measured, sd_log_mag, sd_phase_rad) -> np.ndarray:
    """
    Return the weighted misfit of a modelled response: ln|H|, then the phase (wrapped).

    ``ln(h_model / h_measured)``: its real part over ``sd_log_mag``, its imaginary part (the
    phase difference in (-pi, pi]) over ``sd_phase_rad``; 1e6 where undefined.
    """
    with np.errstate(divide='ignore', invalid='ignore'):
        r = np.log(np.asarray(h_model, complex) / np.asarray(h_measured, complex))
    out = np.concatenate([r.real / sd_log_mag, r.imag / sd_phase_rad])
    return np.where(np.isfinite(out), out, 1e6)


def _weighted_data(groups: Sequence[FitGroup], sd_floor: float):
    """Per group (group, f, H, sd_ln, sd_phase), and all sds in residual order."""
    data = []
    for g in groups:
        f = np.array([p.frequency_hz for p in g.points])
        h = np.array([p.response for p in g.points])
        sdm = np.maximum([p.sd_log_mag for p in g.points], sd_floor)
        sdp = np.maximum([p.sd_phase_rad for p in g.points], sd_floor)
        data.append((g, f, h, sdm, sdp))
    sd_rows = np.concatenate([np.concatenate([d[3], d[4]]) for d in data])
    return data, sd_rows


def _residual_function(pmap: ParameterMap, data: list):
    """Weighted residuals of ln|H| and phase as a function of theta (1e6 where undefined)."""
    def residual(theta):
        try:
            mat = pmap.material_at(theta)
            effs = pmap.effects_at(theta)
        except ParameterError:
            return np.full(2 * sum(d[1].size for d in data), 1e6)
        return np.concatenate([
            misfit(model_for_group(mat, g, pmap.free, effs).frequency_response(f), h, sdm, sdp)
            for g, f, h, sdm, sdp in data])
    return residual


def _optimise(residual, theta0: np.ndarray, lower: np.ndarray, upper: np.ndarray,
              is_log: np.ndarray):
    """Bounded trust-region-reflective least squares from theta0 moved just inside the bounds."""
    theta0 = np.clip(theta0, lower + 1e-9 * (upper - lower), upper - 1e-9 * (upper - lower))
    return least_squares(
        residual,
        theta0,
        bounds=(lower, upper),
        method='trf',
        x_scale=np.where(is_log, 1.0, np.maximum(np.abs(upper - lower) * 1e-3, 1e-30)),
        diff_step=1e-6,
        max_nfev=200 * (len(theta0) + 1),
    )


def interval_digits(value: float, lo: float, hi: float) -> int:
    """Return the significant digits (4 to 10) that print ``lo``, ``value`` and ``hi`` apart."""
    gap = min(abs(value - lo), abs(hi - value))
    if not (math.isfinite(gap) and gap > 0 and value):
        return 4
    return int(min(10, max(4, math.ceil(math.log10(abs(value) / gap)) + 2)))


def _at_bound(free: Sequence[str], theta, lower, upper) -> list[str]:
    """Names of the parameters within 0.1 % of the bound span (at least 1e-3) of a bound."""
    return [n for n, v, lo, hi in zip(free, theta, lower, upper)
            if v - lo < 1e-3 * max(1.0, hi - lo) or hi - v < 1e-3 * max(1.0, hi - lo)]


def _result(sol, pmap: ParameterMap, sd_rows: np.ndarray, lower: np.ndarray, upper: np.ndarray,
            sd_threshold: float, min_sensitivity: float) -> FitResult:
    """Estimates, intervals, correlation and identifiability at the optimum ``sol``."""
    theta, free = sol.x, pmap.free
    chi2, dof, cov, sd, corr = covariance(sol.jac, sol.fun, len(free))
    combos, vt = svd_combinations(sol.jac, sd_rows, cov, free, sd_threshold, min_sensitivity)
    fitted = pmap.material_at(theta)
    return FitResult(
        material=fitted,
        effects=pmap.effects_at(theta),
        free=free,
        estimates=pmap.values_at(theta),
        ci95=confidence_intervals(free, theta, sd, pmap.is_log),
        sd_log={n: float(s) for n, s in zip(free, sd)},
        correlation=corr,
        chi2=chi2,
        dof=dof,
        identifiability=combos,
        named_combinations=named_combinations(cov, free, fitted, sd_threshold),
        not_identifiable=not_identifiable(free, sd, vt, combos, sd_threshold),
        success=bool(sol.success),
        message=str(sol.message),
        at_bound=_at_bound(free, theta, lower, upper),
        residuals=sol.fun,
    )


def fit_parameters(groups: Sequence[FitGroup], free: Sequence[str],
                   material: MaterialParameters = PAPER_PARAMETERS,
                   effects: tuple = ('surface_resistance',), *,
                   bounds_factor: float = 1e3, sd_floor: float = 1e-6,
                   sd_threshold: float = 0.3, min_sensitivity: float = 0.01) -> FitResult:
    """
    Fit ``free`` parameters to the frequency points of ``groups`` (see module doc).

    ``material`` supplies the initial values and the fixed parameters;
    ``bounds_factor`` bounds each free parameter to [p0/b, p0*b].
    ``sd_floor`` floors the per-point uncertainties (ln units and radians).
    A combination counts as determined when its sd(ln) <= ``sd_threshold`` and
    an e-fold change of it moves the modelled response by at least
    ``min_sensitivity`` (RMS of ln-magnitude and phase, i.e. 1 % by default):
    a combination the response hardly depends on is only "determined" through
    effects smaller than any model's accuracy, so we do not trust it
    (see :mod:`.identifiability`).
    """
    free = tuple(free)
    if not free:
        raise ParameterError('no parameter to fit: give at least one of ' + ', '.join(FITTABLE))
    effects = parse_effects(effects)
    keys, free = resolve_free(free, effects)
    if not groups or not any(g.points for g in groups):
        raise ParameterError('no frequency points to fit')
    theta0, lower, upper, is_log = start_and_bounds(keys, material, effects, bounds_factor)
    pmap = ParameterMap(free, keys, is_log, material, effects)
    data, sd_rows = _weighted_data(groups, sd_floor)
    if sd_rows.size <= len(free):
        points = sum(len(g.points) for g in groups)
        raise ParameterError(f'{len(free)} free parameter(s) ({", ".join(free)}) but only '
                             f'{sd_rows.size} data values ({points} frequency point(s): gain and '
                             'phase each): nothing is left to judge the fit; add records at '
                             'other frequencies or free fewer parameters')
    sol = _optimise(_residual_function(pmap, data), theta0, lower, upper, is_log)
    return _result(sol, pmap, sd_rows, lower, upper, sd_threshold, min_sensitivity)
