# SPDX-License-Identifier: Apache-2.0
"""
Infinite-dimensional sensing transfer functions H1 (eq. 31) and H2 (eq. 45).

Both map tip deflection w(s) (metres) to short-circuit sensing current i(s)
(amperes); units of H are A m^-1.  Equation numbers refer to Chen, Tan, Will,
Ziel, Smart Mater. Struct. 16 (2007) 1477 ("the paper").

Numerically robust forms
------------------------
The printed formulas overflow or cancel at the ends of the useful range, so we
evaluate algebraically identical forms:

* eq. 31: ``(beta h coth(beta h) - 1) / beta^2 = h^2 phi(beta h)`` with
  ``phi(z) = (z coth z - 1)/z^2``.  For ``|z| >= 0.5`` we use
  ``coth z = (1 + e^{-2z}) / (-expm1(-2z))`` (no overflow: ``Re z > 0`` on the
  principal branch), for ``|z| < 0.5`` the Taylor series
  ``phi = 1/3 - z^2/45 + 2 z^4/945 - z^6/4725 + 2 z^8/93555`` (truncation
  < 2e-9 relative).  The identity ``z coth z - 1 = 2 sum_n z^2/(z^2 + n^2 pi^2)``
  shows that ``H1(s)/s`` is a sum of first-order lags with real poles at
  ``-(K + n^2 pi^2 d / h^2)``, n = 1, 2, ... (the diffusion modes across the
  thickness); :mod:`ipmc_sensor_ros.lti.reduction` uses this to justify a
  real-pole, real-zero reduction.
* eq. 45 / 46: ``H2 = H1 * 2 G(a)``, ``a = L sqrt(B(s))``, ``B = s kappa_e r0 / h``
  (eq. 42) and ``G(a) = (1 - cosh a + a sinh a) / (a^2 cosh a)``, evaluated as
  ``G = tanhc(a) - (expm1(-a)/a)^2 / (1 + e^{-2a})`` with
  ``tanhc(a) = tanh(a)/a``.  This has no cancellation for small ``a`` and no
  overflow for large ``a``; at ``a = 0`` (``r0 = 0``) it equals the limit 1/2
  of eq. 46 exactly, so H2 = H1 there with no division by zero.
"""
from __future__ import annotations

import numpy as np

from .parameters import Geometry, MaterialParameters

__all__ = [
    'beta',
    'h1',
    'h2',
    'surface_resistance_factor',
    'surface_resistance_time_constant_s',
    'thickness_function',
]

_PHI_SERIES = (1.0 / 3.0, -1.0 / 45.0, 2.0 / 945.0, -1.0 / 4725.0, 2.0 / 93555.0)


def _as_complex(s) -> np.ndarray:
    return np.asarray(s, dtype=complex)


def beta(s, material: MaterialParameters) -> np.ndarray:
    """Return beta of s: sqrt((s + K)/d), m^-1 (definition after eq. 14), principal branch."""
    s = _as_complex(s)
    return np.sqrt((s + material.k_rate_per_s) / material.diffusivity_m2_per_s)


def thickness_function(z) -> np.ndarray:
    """phi(z) = (z coth z - 1) / z^2, robust for all z with Re z >= 0 (see module doc)."""
    z = _as_complex(z)
    out = np.empty_like(z)
    small = np.abs(z) < 0.5
    if np.any(small):
        z2 = z[small] ** 2
        acc = np.zeros_like(z2)
        for coef in reversed(_PHI_SERIES):
            acc = acc * z2 + coef
        out[small] = acc
    big = ~small
    if np.any(big):
        zb = z[big]
        e2 = np.exp(-2.0 * zb)
        coth = (1.0 + e2) / (-np.expm1(-2.0 * zb))
        out[big] = coth / zb - 1.0 / zb ** 2
    return out


def h1(s, material: MaterialParameters, geometry: Geometry) -> np.ndarray:
    """
    H1(s) = i(s)/w(s), perfectly conducting electrodes (eq. 31), A m^-1.

    H1(s) = 3 s Y W (beta h coth(beta h) - 1) / (2 alpha0 L beta^2)
          = 3 s Y W h^2 phi(beta h) / (2 alpha0 L).

    ``s`` is any array of complex frequencies (rad s^-1), e.g. ``2j*pi*f``.
    """
    s = _as_complex(s)
    h = geometry.half_thickness_m
    phi = thickness_function(beta(s, material) * h)
    return (3.0 * s * material.youngs_modulus_pa * geometry.width_m * h ** 2 * phi
            / (2.0 * material.charge_stress_coupling_j_per_c * geometry.length_m))


def surface_resistance_time_constant_s(material: MaterialParameters, geometry: Geometry) -> float:
    """
    tau_r = kappa_e r0 L^2 / h, s, so that a(s)^2 = B(s) L^2 = s tau_r (eq. 42).

    The distributed RC line of paper Fig. 2 has its poles at
    s = -(n - 1/2)^2 pi^2 / tau_r (zeros of cosh a in eq. 45).
    """
    return (material.permittivity_f_per_m * material.surface_resistance_ohm
            * geometry.length_m ** 2 / geometry.half_thickness_m)


def surface_resistance_factor(s, material: MaterialParameters, geometry: Geometry) -> np.ndarray:
    """
    2 G(a): the factor by which H2 (eq. 45) differs from H1 (eq. 31), dimensionless.

    G(a) = (1 - cosh a + a sinh a)/(a^2 cosh a), a = L sqrt(s kappa_e r0 / h);
    2 G -> 1 as r0 -> 0 (eq. 46).
    """
    s = _as_complex(s)
    a = np.sqrt(s * surface_resistance_time_constant_s(material, geometry))
    zero = a == 0
    a_safe = np.where(zero, 1.0, a)
    e2 = np.exp(-2.0 * a_safe)
    tanhc = -np.expm1(-2.0 * a_safe) / (a_safe * (1.0 + e2))
    em1 = np.expm1(-a_safe) / a_safe
    g = tanhc - em1 ** 2 / (1.0 + e2)
    return np.where(zero, 1.0, 2.0 * g)


def h2(s, material: MaterialParameters, geometry: Geometry) -> np.ndarray:
    """
    H2(s) = i(s)/w(s) with distributed surface resistance (eq. 45), A m^-1.

    H2 = H1 * 2 G(a) (the identity printed just before eq. 46).
    """
    return h1(s, material, geometry) * surface_resistance_factor(s, material, geometry)
