"""Parameter identification from measured frequency response (paper section 5.2, done better).

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

from ..physics.model import SensorModel
from ..physics.parameters import PAPER_PARAMETERS, Geometry, MaterialParameters, ParameterError
from .freqresp import FrequencyPoint

__all__ = ["FitGroup", "FitResult", "fit_parameters", "FITTABLE", "SYMBOLS", "model_for_group"]

#: Parameters that may be fitted (F and R are constants).
FITTABLE = ("temperature_k", "youngs_modulus_pa", "surface_resistance_ohm", "diffusivity_m2_per_s",
            "anion_concentration_mol_per_m3", "permittivity_f_per_m",
            "charge_stress_coupling_j_per_c")
#: Physical combinations worth reporting (exponents of ln-parameters).  Y and
#: alpha0 enter H only as Y/alpha0 (eq. 31); sqrt(d)/alpha0 and K set H1 when
#: |beta h| >> 1 (eq. 51); kappa_e r0 sets the surface-resistance line (eq. 42).
NAMED_COMBINATIONS = {
    "sqrt(d)/alpha0": {"diffusivity_m2_per_s": 0.5, "charge_stress_coupling_j_per_c": -1.0},
    "K = F^2 d C-/(kappa_e R T) [1/s]": {"diffusivity_m2_per_s": 1.0, "anion_concentration_mol_per_m3": 1.0,
                             "permittivity_f_per_m": -1.0, "temperature_k": -1.0},
    "Y/alpha0": {"youngs_modulus_pa": 1.0, "charge_stress_coupling_j_per_c": -1.0},
    "kappa_e r0": {"permittivity_f_per_m": 1.0, "surface_resistance_ohm": 1.0},
}

#: Short physics symbols for reports.
SYMBOLS = {"temperature_k": "T", "youngs_modulus_pa": "Y", "surface_resistance_ohm": "r0",
           "diffusivity_m2_per_s": "d", "anion_concentration_mol_per_m3": "C-",
           "permittivity_f_per_m": "kappa_e", "charge_stress_coupling_j_per_c": "alpha0",
           "one_minus_anion_volume_fraction": "(1-C-dV)"}


@dataclass
class FitGroup:
    """Frequency points measured on one sample (one geometry, one header)."""

    geometry: Geometry
    points: list[FrequencyPoint]
    known: dict[str, float] = field(default_factory=dict)
    name: str = ""


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

    def summary(self) -> str:
        lines = [f"fit of {', '.join(SYMBOLS.get(n, n) for n in self.free)} "
                 f"({'+'.join(('h1',) + tuple(getattr(e, 'name', e) for e in self.effects))}): chi2/dof = {self.chi2:.4g}/{self.dof} "
                 f"= {self.reduced_chi2:.3g}"]
        lines.append(f"{'parameter':<32} {'estimate':>12} {'95% CI':>27}  note")
        for name in self.free:
            lo, hi = self.ci95[name]
            note = []
            if name in self.not_identifiable:
                note.append("NOT IDENTIFIABLE alone")
            if name in self.at_bound:
                note.append("at bound")
            lines.append(f"{name:<32} {self.estimates[name]:>12.4g} [{lo:>11.4g}, {hi:>11.4g}]  "
                         f"{'; '.join(note)}")
        if len(self.free) > 1:
            lines.append("correlation:")
            for k, name in enumerate(self.free):
                row = " ".join(f"{c:+.3f}" for c in self.correlation[k])
                lines.append(f"  {SYMBOLS.get(name, name):>8} {row}")
        lines.append("identifiability (SVD of the scaled Jacobian; combinations of the free parameters):")
        for comb in self.identifiability:
            lines.append(f"  {comb['expression']:<44} sd(ln) = {comb['sd_log']:.3g}, sensitivity "
                         f"{comb['sensitivity']:.3g}  "
                         f"{'determined' if comb['determined'] else 'NOT determined by these data'}")
        for comb in self.named_combinations:
            lines.append(f"  {comb['name']:<44} = {comb['value']:.5g}, sd(ln) = {comb['sd_log']:.3g}  "
                         f"{'determined' if comb['determined'] else 'NOT determined'}")
        if self.not_identifiable:
            lines.append("WARNING: " + ", ".join(SYMBOLS.get(n, n) for n in self.not_identifiable)
                         + " cannot be estimated separately from these data; report the determined "
                         "combinations above, or fix some of them from independent measurements.")
        return "\n".join(lines)


def model_for_group(material: MaterialParameters, group: FitGroup, free: Sequence[str],
                    effects: tuple) -> SensorModel:
    """Model of one group: header-known values override fixed parameters."""
    overrides = {k: v for k, v in group.known.items() if k not in free and k in FITTABLE}
    mat = material.replace(**overrides) if overrides else material
    return SensorModel(group.geometry, mat, effects)


def _wrap(angle):
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


def _combination_text(vector: np.ndarray, free: Sequence[str]) -> str:
    v = vector / np.max(np.abs(vector))
    parts = []
    for coef, name in zip(v, free):
        if abs(coef) < 0.05:
            continue
        sym = SYMBOLS.get(name, name)
        parts.append(sym if abs(coef - 1) < 0.025 else f"{sym}^{coef:.2f}")
    return " * ".join(parts) if parts else "(none)"


def fit_parameters(groups: Sequence[FitGroup], free: Sequence[str],
                   material: MaterialParameters = PAPER_PARAMETERS,
                   effects: tuple = ("surface_resistance",), *,
                   bounds_factor: float = 1e3, sd_floor: float = 1e-6,
                   sd_threshold: float = 0.3, min_sensitivity: float = 0.01) -> FitResult:
    """Fit ``free`` parameters to the frequency points of ``groups`` (see module doc).

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
        raise ParameterError("no parameter to fit: give at least one of " + ", ".join(FITTABLE))
    for name in free:
        if name not in FITTABLE:
            raise ParameterError(f"cannot fit '{name}'; fittable parameters: {', '.join(FITTABLE)}")
    if len(set(free)) != len(free):
        raise ParameterError(f"parameter listed twice in {list(free)}")
    if not groups or not any(g.points for g in groups):
        raise ParameterError("no frequency points to fit")
    theta0 = np.log([getattr(material, n) if getattr(material, n) > 0 else 1e-6 for n in free])
    lower, upper = theta0 - np.log(bounds_factor), theta0 + np.log(bounds_factor)
    if "surface_resistance_ohm" in free and material.surface_resistance_ohm == 0:
        lower[free.index("surface_resistance_ohm")] = np.log(1e-6)
    data = []
    for g in groups:
        f = np.array([p.frequency_hz for p in g.points])
        h = np.array([p.response for p in g.points])
        sdm = np.maximum([p.sd_log_mag for p in g.points], sd_floor)
        sdp = np.maximum([p.sd_phase_rad for p in g.points], sd_floor)
        data.append((g, f, np.log(np.abs(h)), np.angle(h), sdm, sdp))
    sd_rows = np.concatenate([np.concatenate([d[4], d[5]]) for d in data])

    def material_at(theta):
        return material.replace(**{n: float(np.exp(v)) for n, v in zip(free, theta)})

    def residual(theta):
        try:
            mat = material_at(theta)
        except ParameterError:
            return np.full(2 * sum(d[1].size for d in data), 1e6)
        out = []
        for g, f, lm, ph, sdm, sdp in data:
            hm = model_for_group(mat, g, free, effects).frequency_response(f)
            out.append((np.log(np.abs(hm)) - lm) / sdm)
            out.append(_wrap(np.angle(hm) - ph) / sdp)
        r = np.concatenate(out)
        return np.where(np.isfinite(r), r, 1e6)

    sol = least_squares(residual, theta0, bounds=(lower, upper), method="trf", x_scale=1.0,
                        diff_step=1e-6, max_nfev=200 * (len(free) + 1))
    theta = sol.x
    jac = sol.jac
    r = sol.fun
    n_res = r.size
    dof = max(n_res - len(free), 1)
    chi2 = float(r @ r)
    s2 = max(chi2 / dof, 1.0) if dof > 0 else 1.0
    cov = s2 * np.linalg.pinv(jac.T @ jac, rcond=1e-15)
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sd, sd)
    corr = np.nan_to_num(corr)
    # Structural sensitivity: derivative of the model's ln-response itself (not
    # divided by the uncertainty), RMS over all points, per e-fold change.
    sens_jac = jac * sd_rows[:, None]
    _, sv, vt = np.linalg.svd(sens_jac / np.sqrt(sens_jac.shape[0]), full_matrices=False)
    combos = []
    for k in range(len(sv)):
        sd_k = float(np.sqrt(max(vt[k] @ cov @ vt[k], 0.0)))
        combos.append({"exponents": {n: float(c) for n, c in zip(free, vt[k])},
                       "expression": _combination_text(vt[k], free), "sd_log": sd_k,
                       "sensitivity": float(sv[k]),
                       "determined": bool(sd_k <= sd_threshold and sv[k] >= min_sensitivity)})
    # A parameter is not identifiable alone if its marginal sd is large or it takes
    # part in a combination the data do not determine.
    not_ident = []
    for j, (n, s_j) in enumerate(zip(free, sd)):
        in_null = any(not c["determined"] and abs(vt[k, j]) > 0.1 * np.max(np.abs(vt[k]))
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
        value = fitted.k_rate_per_s if cname.startswith("K") else \
            float(np.exp(sum(expo[n] * np.log(getattr(fitted, n)) for n in expo)))
        named.append({"name": cname + (f" (with {', '.join(fixed)} fixed)" if fixed else ""),
                      "exponents": {n: expo[n] for n in expo if n in free}, "value": value,
                      "sd_log": sd_c, "determined": bool(sd_c <= sd_threshold)})
    at_bound = [n for n, v, lo, hi in zip(free, theta, lower, upper)
                if v - lo < 1e-3 or hi - v < 1e-3]
    est = {n: float(np.exp(v)) for n, v in zip(free, theta)}
    with np.errstate(over="ignore"):
        ci = {n: (float(np.exp(v - 1.96 * s)), float(np.exp(v + 1.96 * s)))
              for n, v, s in zip(free, theta, sd)}
    return FitResult(material=material_at(theta), effects=tuple(effects), free=free, estimates=est,
                     ci95=ci, sd_log={n: float(s) for n, s in zip(free, sd)}, correlation=corr,
                     chi2=chi2, dof=dof, identifiability=combos, named_combinations=named,
                     not_identifiable=not_ident,
                     success=bool(sol.success), message=str(sol.message), at_bound=at_bound,
                     residuals=r)
