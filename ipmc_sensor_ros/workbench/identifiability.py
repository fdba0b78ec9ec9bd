# SPDX-License-Identifier: Apache-2.0
"""
Confidence intervals and SVD identifiability of a fit in log-parameters.

The uncertainty half of :func:`~.freqfit.fit_parameters`: from the Jacobian of
the weighted residuals at the optimum it derives the covariance, the 95 %
confidence intervals, the correlation matrix and the identifiability report.

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

from typing import Sequence

import numpy as np

from ..physics.parameters import MaterialParameters

__all__ = ['NAMED_COMBINATIONS', 'SYMBOLS', 'combination_text', 'confidence_intervals',
           'covariance', 'named_combinations', 'not_identifiable', 'svd_combinations']

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


def combination_text(vector: np.ndarray, free: Sequence[str]) -> str:
    """Power-law product ``d^0.50 * alpha0^-1.00`` of a combination, largest exponent 1."""
    v = vector / np.max(np.abs(vector))
    parts = []
    for coef, name in zip(v, free):
        if abs(coef) < 0.05:
            continue
        sym = SYMBOLS.get(name, name)
        parts.append(sym if abs(coef - 1) < 0.025 else f'{sym}^{coef:.2f}')
    return ' * '.join(parts) if parts else '(none)'


def covariance(jac: np.ndarray, r: np.ndarray, n_free: int):
    """Return chi2, dof, covariance ``s^2 (J^T J)^+``, marginal sd and correlation of theta."""
    dof = max(r.size - n_free, 1)
    chi2 = float(r @ r)
    s2 = max(chi2 / dof, 1.0) if dof > 0 else 1.0
    cov = s2 * np.linalg.pinv(jac.T @ jac, rcond=1e-15)
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(invalid='ignore', divide='ignore'):
        corr = cov / np.outer(sd, sd)
    corr = np.nan_to_num(corr)
    return chi2, dof, cov, sd, corr


def svd_combinations(jac: np.ndarray, sd_rows: np.ndarray, cov: np.ndarray, free: Sequence[str],
                     sd_threshold: float, min_sensitivity: float):
    """Return the combinations from the SVD of the unweighted sensitivity matrix, and ``V^T``."""
    # Structural sensitivity: derivative of the model's ln-response itself (not
    # divided by the uncertainty), RMS over all points, per e-fold change.
    sens_jac = jac * sd_rows[:, None]
    _, sv, vt = np.linalg.svd(sens_jac / np.sqrt(sens_jac.shape[0]), full_matrices=True)
    sv = np.concatenate([sv, np.zeros(vt.shape[0] - sv.size)])   # fewer rows: unseen ones
    combos = []
    for k in range(len(sv)):
        sd_k = float(np.sqrt(max(vt[k] @ cov @ vt[k], 0.0)))
        combos.append({'exponents': {n: float(c) for n, c in zip(free, vt[k])},
                       'expression': combination_text(vt[k], free), 'sd_log': sd_k,
                       'sensitivity': float(sv[k]),
                       'determined': bool(sd_k <= sd_threshold and sv[k] >= min_sensitivity)})
    return combos, vt


def not_identifiable(free: Sequence[str], sd: np.ndarray, vt: np.ndarray, combos: list[dict],
                     sd_threshold: float) -> list[str]:
    """Free parameters the data do not determine alone."""
    # A parameter is not identifiable alone if its marginal sd is large or it takes
    # part in a combination the data do not determine.
    not_ident = []
    for j, (n, s_j) in enumerate(zip(free, sd)):
        in_null = any(not c['determined'] and abs(vt[k, j]) > 0.1 * np.max(np.abs(vt[k]))
                      for k, c in enumerate(combos))
        if s_j > sd_threshold or in_null:
            not_ident.append(n)
    return not_ident


def named_combinations(cov: np.ndarray, free: Sequence[str], fitted: MaterialParameters,
                       sd_threshold: float) -> list[dict]:
    """Value and sd(ln) of each :data:`NAMED_COMBINATIONS` entry with two or more free terms."""
    named = []
    for cname, expo in NAMED_COMBINATIONS.items():
        vec = np.array([expo.get(n, 0.0) for n in free])
        if np.count_nonzero(vec) < 2:
            continue
        fixed = [SYMBOLS[n] for n in expo if n not in free]
        sd_c = float(np.sqrt(max(vec @ cov @ vec, 0.0)))
        value = fitted.k_rate_per_s if cname.startswith('K') else \
            float(np.exp(sum(expo[n] * np.log(getattr(fitted, n)) for n in expo)))
        named.append({'name': cname + (f" (with {', '.join(fixed)} fixed)" if fixed else ''),
                      'exponents': {n: expo[n] for n in expo if n in free}, 'value': value,
                      'sd_log': sd_c, 'determined': bool(sd_c <= sd_threshold)})
    return named


def confidence_intervals(free: Sequence[str], theta: np.ndarray, sd: np.ndarray,
                         is_log: np.ndarray) -> dict[str, tuple[float, float]]:
    """95 % intervals ``theta +/- 1.96 sd``, mapped back through exp for log-scale parameters."""
    with np.errstate(over='ignore'):
        return {n: ((float(np.exp(v - 1.96 * s)), float(np.exp(v + 1.96 * s))) if lg
                    else (float(v - 1.96 * s), float(v + 1.96 * s)))
                for n, v, s, lg in zip(free, theta, sd, is_log)}
