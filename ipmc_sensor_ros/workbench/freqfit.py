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
  **identifiability report** from the SVD of the scaled Jacobian.

Identifiability
---------------
Let J be the Jacobian of the weighted residuals with respect to
``theta = ln(parameters)``, ``J = U S V^T``.  The covariance of theta is
``s^2 V S^-2 V^T`` (s^2 = reduced chi-square, so the intervals widen when the
model does not fit within the stated uncertainty), so the combination
``v_k . theta`` -- the power-law product ``prod p_j^{v_kj}`` -- has standard
deviation ``s / S_k``.  The report lists the combinations from the SVD of the *unweighted*
sensitivity matrix (derivatives of ln|H| and phase), each with its
sensitivity (RMS response change per e-fold change) and its sd from the
covariance.  A combination is "determined" only if its sd is at most
``sd_threshold`` (0.3, about +/-35 % at 1 sigma) **and** its sensitivity is at
least ``min_sensitivity`` (1 %): with very clean data the statistics alone
would "determine" directions that act only through sub-percent terms, far
below any model's accuracy.  With the paper's model, |beta h| >> 1 makes
``H ~ (h sqrt(d)/alpha0) / sqrt(s + K) - (d/alpha0) / (s + K)``: only
``sqrt(d)/alpha0`` and ``K ~ d C- / kappa_e`` are well determined (the second
term is ~1/(beta h) ~ 0.4 % of the first), so a four-parameter fit of
d, C-, kappa_e, alpha0 is ill-posed and the report says so.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy.optimize import least_squares

from scipy.stats import chi2 as chi2_dist

from ..physics.effects import EFFECTS, get_effect
from ..physics.model import EffectSpec, SensorModel, parse_effects
from ..physics.parameters import PAPER_PARAMETERS, Geometry, MaterialParameters, ParameterError
from .freqresp import FrequencyPoint

__all__ = ['FitGroup', 'FitResult', 'fit_parameters', 'FITTABLE', 'SYMBOLS', 'model_for_group',
           'resolve_effect_parameter', 'effect_parameter_names', 'ADEQUACY_P']

#: chi^2 p-value below which the model is declared inadequate for the data
ADEQUACY_P = 1e-3

#: Parameters that may be fitted (F and R are constants).
FITTABLE = ('temperature_k', 'youngs_modulus_pa', 'surface_resistance_ohm', 'diffusivity_m2_per_s',
            'anion_concentration_mol_per_m3', 'permittivity_f_per_m',
            'charge_stress_coupling_j_per_c')
#: Physical combinations worth reporting (exponents of ln-parameters).  Y and
#: alpha0 enter H only as Y/alpha0 (eq. 31); sqrt(d)/alpha0 and K set H1 when
#: |beta h| >> 1 (eq. 51); kappa_e r0 sets the surface-resistance line (eq. 42).
NAMED_COMBINATIONS = {
    'sqrt(d)/alpha0': {'diffusivity_m2_per_s': 0.5, 'charge_stress_coupling_j_per_c': -1.0},
    'K = F^2 d C-/(kappa_e R T) [1/s]': {
        'diffusivity_m2_per_s': 1.0,
        'anion_concentration_mol_per_m3': 1.0,
        'permittivity_f_per_m': -1.0,
        'temperature_k': -1.0,
    },
    'Y/alpha0': {'youngs_modulus_pa': 1.0, 'charge_stress_coupling_j_per_c': -1.0},
    'kappa_e r0': {'permittivity_f_per_m': 1.0, 'surface_resistance_ohm': 1.0},
}

#: Short physics symbols for reports.
SYMBOLS = {'temperature_k': 'T', 'youngs_modulus_pa': 'Y', 'surface_resistance_ohm': 'r0',
           'diffusivity_m2_per_s': 'd', 'anion_concentration_mol_per_m3': 'C-',
           'permittivity_f_per_m': 'kappa_e', 'charge_stress_coupling_j_per_c': 'alpha0',
           'one_minus_anion_volume_fraction': '(1-C-dV)'}


@dataclass
class FitGroup:
    """Frequency points measured on one sample (one geometry, one header)."""

    geometry: Geometry
    points: list[FrequencyPoint]
    known: dict[str, float] = field(default_factory=dict)
    name: str = ''


@dataclass
class FitResult:
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
            lines.append(f'{name:<32} {self.estimates[name]:>12.4g} [{lo:>11.4g}, {hi:>11.4g}]  '
                         f'{note}')
        if len(self.free) > 1:
            lines.append('correlation:')
            for k, name in enumerate(self.free):
                row = ' '.join(f'{c:+.3f}' for c in self.correlation[k])
                lines.append(f'  {SYMBOLS.get(name, name):>8} {row}')
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


def effect_parameter_names(effects) -> list[str]:
    """Qualified names ``effect.parameter`` of every parameter of ``effects``."""
    return [
        f'{e.name}.{p.name}' for e in parse_effects(effects) for p in get_effect(e.name).parameters
    ]


def resolve_effect_parameter(name: str, effects) -> tuple[str, str]:
    """
    Resolve ``delay_s`` or ``time_delay.delay_s`` to ``("time_delay", "delay_s")``.

    For a model with ``effects``; a clear error when unknown, ambiguous or its effect is not
    in the model.
    """
    specs = parse_effects(effects)
    in_model = [e.name for e in specs]
    if '.' in name:
        eff, par = name.split('.', 1)
        if eff not in in_model:
            raise ParameterError(
                f"cannot fit '{name}': effect '{eff}' is not in the model "
                f"({', '.join(in_model) or 'h1 only'}); add it with --effects {eff}"
            )
        if par not in {p.name for p in get_effect(eff).parameters}:
            raise ParameterError(f"cannot fit '{name}': effect '{eff}' has parameters "
                                 f'{[p.name for p in get_effect(eff).parameters]}')
        return eff, par
    owners = [e for e in in_model if name in {p.name for p in get_effect(e).parameters}]
    if len(owners) == 1:
        return owners[0], name
    if len(owners) > 1:
        raise ParameterError(f"parameter '{name}' is ambiguous (effects {owners}); qualify it, "
                             f'e.g. {owners[0]}.{name}')
    catalog = [n for n, e in EFFECTS.items() if name in {p.name for p in e.parameters}]
    if catalog:
        raise ParameterError(
            f"cannot fit '{name}': it belongs to effect '{catalog[0]}', which is not in "
            f'the model; add it with --effects {catalog[0]}'
        )
    raise ParameterError(
        f"cannot fit '{name}'; fittable: {', '.join(FITTABLE)} or an effect parameter "
        f"of the model ({', '.join(effect_parameter_names(specs)) or 'none'})"
    )


def _wrap(angle):
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


def _combination_text(vector: np.ndarray, free: Sequence[str]) -> str:
    v = vector / np.max(np.abs(vector))
    parts = []
    for coef, name in zip(v, free):
        if abs(coef) < 0.05:
            continue
        sym = SYMBOLS.get(name, name)
        parts.append(sym if abs(coef - 1) < 0.025 else f'{sym}^{coef:.2f}')
    return ' * '.join(parts) if parts else '(none)'


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
    effects smaller than any model's accuracy, so we do not trust it.
    """
    free = tuple(free)
    if not free:
        raise ParameterError('no parameter to fit: give at least one of ' + ', '.join(FITTABLE))
    effects = parse_effects(effects)
    keys: list = []                     # material name, or (effect, parameter)
    for name in free:
        keys.append(name if name in FITTABLE else resolve_effect_parameter(name, effects))
    free = tuple(k if isinstance(k, str) else f'{k[0]}.{k[1]}' for k in keys)
    if len(set(free)) != len(free):
        raise ParameterError(f'parameter listed twice in {list(free)}')
    if not groups or not any(g.points for g in groups):
        raise ParameterError('no frequency points to fit')
    mat_free = tuple(k for k in keys if isinstance(k, str))
    is_log = []
    theta0, lower, upper = [], [], []
    for k in keys:
        if isinstance(k, str):
            v0 = np.log(getattr(material, k) if getattr(material, k) > 0 else 1e-6)
            lo, hi = v0 - np.log(bounds_factor), v0 + np.log(bounds_factor)
            if k == 'surface_resistance_ohm' and material.surface_resistance_ohm == 0:
                lo = np.log(1e-6)
            is_log.append(True)
        else:
            par = next(p for p in get_effect(k[0]).parameters if p.name == k[1])
            v = next(e for e in effects if e.name == k[0]).as_dict()[k[1]]
            if par.log_scale:
                v0, lo, hi = np.log(v), np.log(par.lower), np.log(par.upper)
            else:
                v0, lo, hi = v, par.lower, par.upper
            is_log.append(par.log_scale)
        theta0.append(v0)
        lower.append(lo)
        upper.append(hi)
    theta0, lower, upper = np.array(theta0), np.array(lower), np.array(upper)
    is_log = np.array(is_log)
    data = []
    for g in groups:
        f = np.array([p.frequency_hz for p in g.points])
        h = np.array([p.response for p in g.points])
        sdm = np.maximum([p.sd_log_mag for p in g.points], sd_floor)
        sdp = np.maximum([p.sd_phase_rad for p in g.points], sd_floor)
        data.append((g, f, np.log(np.abs(h)), np.angle(h), sdm, sdp))
    sd_rows = np.concatenate([np.concatenate([d[4], d[5]]) for d in data])

    def values_at(theta):
        return {n: float(np.exp(v)) if lg else float(v) for n, v, lg in zip(free, theta, is_log)}

    def material_at(theta):
        vals = values_at(theta)
        return material.replace(**{n: vals[n] for n in mat_free})

    def effects_at(theta):
        vals = values_at(theta)
        out = []
        for e in effects:
            d = e.as_dict()
            d.update(
                {
                    k[1]: vals[f'{k[0]}.{k[1]}']
                    for k in keys
                    if not isinstance(k, str) and k[0] == e.name
                }
            )
            out.append(EffectSpec(e.name, tuple(sorted(d.items()))))
        return tuple(out)

    def residual(theta):
        try:
            mat = material_at(theta)
            effs = effects_at(theta)
        except ParameterError:
            return np.full(2 * sum(d[1].size for d in data), 1e6)
        out = []
        for g, f, lm, ph, sdm, sdp in data:
            hm = model_for_group(mat, g, free, effs).frequency_response(f)
            out.append((np.log(np.abs(hm)) - lm) / sdm)
            out.append(_wrap(np.angle(hm) - ph) / sdp)
        r = np.concatenate(out)
        return np.where(np.isfinite(r), r, 1e6)

    theta0 = np.clip(theta0, lower + 1e-9 * (upper - lower), upper - 1e-9 * (upper - lower))
    sol = least_squares(
        residual,
        theta0,
        bounds=(lower, upper),
        method='trf',
        x_scale=np.where(is_log, 1.0, np.maximum(np.abs(upper - lower) * 1e-3, 1e-30)),
        diff_step=1e-6,
        max_nfev=200 * (len(free) + 1),
    )
    theta = sol.x
    jac = sol.jac
    r = sol.fun
    n_res = r.size
    dof = max(n_res - len(free), 1)
    chi2 = float(r @ r)
    s2 = max(chi2 / dof, 1.0) if dof > 0 else 1.0
    cov = s2 * np.linalg.pinv(jac.T @ jac, rcond=1e-15)
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(invalid='ignore', divide='ignore'):
        corr = cov / np.outer(sd, sd)
    corr = np.nan_to_num(corr)
    # Structural sensitivity: derivative of the model's ln-response itself (not
    # divided by the uncertainty), RMS over all points, per e-fold change.
    sens_jac = jac * sd_rows[:, None]
    _, sv, vt = np.linalg.svd(sens_jac / np.sqrt(sens_jac.shape[0]), full_matrices=False)
    combos = []
    for k in range(len(sv)):
        sd_k = float(np.sqrt(max(vt[k] @ cov @ vt[k], 0.0)))
        combos.append({'exponents': {n: float(c) for n, c in zip(free, vt[k])},
                       'expression': _combination_text(vt[k], free), 'sd_log': sd_k,
                       'sensitivity': float(sv[k]),
                       'determined': bool(sd_k <= sd_threshold and sv[k] >= min_sensitivity)})
    # A parameter is not identifiable alone if its marginal sd is large or it takes
    # part in a combination the data do not determine.
    not_ident = []
    for j, (n, s_j) in enumerate(zip(free, sd)):
        in_null = any(not c['determined'] and abs(vt[k, j]) > 0.1 * np.max(np.abs(vt[k]))
                      for k, c in enumerate(combos))
        if s_j > sd_threshold or in_null:
            not_ident.append(n)
    named = []
    for cname, expo in NAMED_COMBINATIONS.items():
        vec = np.array([expo.get(n, 0.0) for n in free])
        if np.count_nonzero(vec) < 2:
            continue
        fixed = [SYMBOLS[n] for n in expo if n not in free]
        sd_c = float(np.sqrt(max(vec @ cov @ vec, 0.0)))
        fitted = material_at(theta)
        value = fitted.k_rate_per_s if cname.startswith('K') else \
            float(np.exp(sum(expo[n] * np.log(getattr(fitted, n)) for n in expo)))
        named.append({'name': cname + (f" (with {', '.join(fixed)} fixed)" if fixed else ''),
                      'exponents': {n: expo[n] for n in expo if n in free}, 'value': value,
                      'sd_log': sd_c, 'determined': bool(sd_c <= sd_threshold)})
    at_bound = [n for n, v, lo, hi in zip(free, theta, lower, upper)
                if v - lo < 1e-3 * max(1.0, hi - lo) or hi - v < 1e-3 * max(1.0, hi - lo)]
    est = values_at(theta)
    with np.errstate(over='ignore'):
        ci = {n: ((float(np.exp(v - 1.96 * s)), float(np.exp(v + 1.96 * s))) if lg
                  else (float(v - 1.96 * s), float(v + 1.96 * s)))
              for n, v, s, lg in zip(free, theta, sd, is_log)}
    return FitResult(
        material=material_at(theta),
        effects=effects_at(theta),
        free=free,
        estimates=est,
        ci95=ci,
        sd_log={n: float(s) for n, s in zip(free, sd)},
        correlation=corr,
        chi2=chi2,
        dof=dof,
        identifiability=combos,
        named_combinations=named,
        not_identifiable=not_ident,
        success=bool(sol.success),
        message=str(sol.message),
        at_bound=at_bound,
        residuals=r,
    )
