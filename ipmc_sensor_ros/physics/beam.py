# SPDX-License-Identifier: Apache-2.0
"""
Beam mechanics that turn a tip deflection into the surface-stress profile sigma(h, z).

The paper uses small-deflection Euler-Bernoulli theory (eqs. 18-21):
M(z) = F (L - z), w = L^3 F / (3 Y I), hence sigma(h, z) = 3 Y h (L - z) w / L^3
(eq. 21) and the boundary charge rho(h, z) = sigma / alpha0 (eqs. 16, 22).  It says
so itself (section 2): "only small deflections ... are considered, where one can
ignore the nonlinearity of stress profile".  This module supplies that stress
profile for both cases, in a form the field solver
(:class:`~ipmc_sensor_ros.physics.field.FieldSolver`) takes as its input:

    sigma(h, z, t) = (3 Y h / L^2) sum_k q_k(t) phi_k(z / L),   phi_k(zeta) = (1 - zeta)^k,

i.e. a few shape functions phi_k with time-varying coordinates q_k (m).

* :class:`LinearBeam` -- the paper: one shape, q_1 = w.
* :class:`ElasticaBeam` -- the inextensible elastica of a cantilever under a tip
  force that stays vertical (the crank-slider pushes the tip along its stroke):
  with the slope theta(s) along the arc length s, EI theta'' = -F cos theta,
  theta(0) = 0, theta'(L) = 0, and the vertical tip deflection
  w = int_0^L sin theta ds.  The surface strain is h kappa(s) = h theta'(s), so
  sigma(h, s) = Y h theta'(s): in dimensionless form theta'' = -lambda cos theta
  (lambda = F L^2 / (Y I)) depends on w / L only, not on the material.  The
  curvature profile is no longer the straight line (1 - zeta) and its size grows
  faster than w: the tip angle is 1.5 w/L at small w and 0.46 rad (not 0.45)
  at w/L = 0.30.  The profile is projected on ``n_shapes`` polynomial shapes by
  least squares (5 shapes: residual < 2e-4 of the peak up to w/L = 0.6, tested) and
  tabulated against w/L (cubic splines, odd in w).  The arc length s is the
  coordinate of the electrode line (the surface resistance follows the material).

Quasi-static: the beam is massless (its inertia is the ``beam_inertia`` effect).
The elastica is solved with :func:`scipy.integrate.solve_bvp` (continuation in
lambda); the tests check it against the independent first-integral (elliptic)
solution theta'^2 = 2 lambda (sin theta_L - sin theta) and against the classical
large-deflection values of Bisshopp & Drucker (1945).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.integrate import solve_bvp
from scipy.interpolate import CubicSpline

from .parameters import ParameterError

__all__ = ['LinearBeam', 'ElasticaBeam', 'BEAM_MODELS', 'make_beam', 'elastica_solution',
           'require_field_fidelity']

#: Largest |w| / L the elastica tables cover (lambda ~ 3.1; the tip is then at 1.1 rad,
#: well past IPMC sensing use).
MAX_DEFLECTION_RATIO = 0.6


class LinearBeam:
    """Small-deflection beam of the paper (eqs. 18-21): one shape, q_1 = w."""

    name = 'linear'
    n_shapes = 1

    def shapes(self, zeta) -> np.ndarray:
        """Shape functions phi_k(zeta) at zeta = z / L, shape (n_zeta, n_shapes)."""
        return (1.0 - np.asarray(zeta, float))[:, None]

    def coordinates(self, deflection_m, length_m: float) -> np.ndarray:
        """q_k (m) for tip deflections w (m), shape (n, n_shapes)."""
        return np.asarray(deflection_m, float).reshape(-1, 1)

    def coordinate_rates(self, deflection_m, rate_m_s, length_m: float) -> np.ndarray:
        """dq_k/dt (m/s) for w and dw/dt, shape (n, n_shapes)."""
        return np.asarray(rate_m_s, float).reshape(-1, 1)

    def small_signal_direction(self) -> np.ndarray:
        """dq/dw at w = 0 (the linearisation's input direction)."""
        return np.ones(1)


def elastica_solution(tip_load: float, n_nodes: int = 201, guess=None):
    """
    Dimensionless elastica theta'' = -lambda cos theta, theta(0) = 0, theta'(1) = 0.

    For lambda = ``tip_load`` = F L^2 / (Y I) >= 0.

    Returns the :func:`scipy.integrate.solve_bvp` solution (y = [theta, theta'], over
    s/L in [0, 1]); w/L = int sin theta, kappa L = theta'.  ``guess``: a previous
    solution (continuation).
    """
    lam = float(tip_load)
    s = np.linspace(0.0, 1.0, n_nodes)
    if guess is None:   # small-deflection solution: theta = lambda (s - s^2/2)
        y0 = np.vstack([lam * (s - s ** 2 / 2), lam * (1 - s)])
    else:
        y0 = guess.sol(s)
    sol = solve_bvp(lambda x, y: np.vstack([y[1], -lam * np.cos(y[0])]),
                    lambda ya, yb: np.array([ya[0], yb[1]]), s, y0, tol=1e-10, max_nodes=20000)
    if not sol.success:
        raise RuntimeError(f'elastica did not converge for lambda = {lam}: {sol.message}')
    return sol


@lru_cache(maxsize=8)
def _elastica_table(n_shapes: int, n_loads: int = 161) -> tuple:
    """(w/L, coefficients c_k(w/L), tip angle, max projection residual) on a load grid."""
    loads = np.linspace(0.0, 4.0, n_loads)        # w/L up to 0.67
    zeta = np.linspace(0.0, 1.0, 401)
    basis = (1.0 - zeta)[:, None] ** np.arange(1, n_shapes + 1)[None, :]
    ratio, coeffs, tip, resid = [0.0], [np.zeros(n_shapes)], [0.0], 0.0
    sol = None
    for lam in loads[1:]:
        sol = elastica_solution(lam, guess=sol)
        theta, dtheta = sol.sol(zeta)
        w_over_l = float(np.trapezoid(np.sin(theta), zeta))
        # kappa L^2 / 3 = sum_k (q_k / L) phi_k  ->  theta'/3 on the basis, per unit w
        c, *_ = np.linalg.lstsq(basis, dtheta / 3.0, rcond=None)
        if w_over_l <= MAX_DEFLECTION_RATIO:
            resid = max(resid, float(np.max(np.abs(basis @ c - dtheta / 3.0))
                                     / np.max(np.abs(dtheta / 3.0))))
        ratio.append(w_over_l)
        coeffs.append(c)
        tip.append(float(theta[-1]))
    return np.array(ratio), np.array(coeffs), np.array(tip), resid


class ElasticaBeam:
    """
    Large-deflection (elastica) cantilever under a vertical tip force; see the module docstring.

    ``n_shapes`` polynomial shapes (1..6).
    """

    name = 'elastica'

    def __init__(self, n_shapes: int = 5):
        if not 1 <= int(n_shapes) <= 6:
            raise ParameterError(f"parameter 'n_shapes' must be 1..6, got {n_shapes!r}")
        self.n_shapes = int(n_shapes)
        ratio, coeffs, tip, self.projection_residual = _elastica_table(self.n_shapes)
        # odd in w: mirror the table so splines are smooth through w = 0
        r = np.concatenate([-ratio[:0:-1], ratio])
        c = np.concatenate([-coeffs[:0:-1], coeffs])
        self._coeff = CubicSpline(r, c, axis=0)
        self._coeff_slope = self._coeff.derivative()
        self._tip = CubicSpline(r, np.concatenate([-tip[:0:-1], tip]))
        self.max_ratio = float(min(ratio[-1], MAX_DEFLECTION_RATIO))

    def shapes(self, zeta) -> np.ndarray:
        z = np.asarray(zeta, float)
        return (1.0 - z)[:, None] ** np.arange(1, self.n_shapes + 1)[None, :]

    def _ratio(self, deflection_m, length_m: float) -> np.ndarray:
        r = np.asarray(deflection_m, float).ravel() / float(length_m)
        if r.size and np.max(np.abs(r)) > self.max_ratio:
            raise ParameterError(f'tip deflection {np.max(np.abs(r)) * length_m:.4g} m is '
                                 f'{np.max(np.abs(r)):.2f} of the length: beyond the elastica '
                                 f'table (|w|/L <= {self.max_ratio:.2f})')
        return r

    def coordinates(self, deflection_m, length_m: float) -> np.ndarray:
        return float(length_m) * self._coeff(self._ratio(deflection_m, length_m))

    def coordinate_rates(self, deflection_m, rate_m_s, length_m: float) -> np.ndarray:
        slope = self._coeff_slope(self._ratio(deflection_m, length_m))
        return slope * np.asarray(rate_m_s, float).reshape(-1, 1)

    def small_signal_direction(self) -> np.ndarray:
        # exact: at first order in the load the elastica is the linear beam
        return np.eye(self.n_shapes)[0]

    def tip_angle_rad(self, deflection_m, length_m: float) -> np.ndarray:
        """Slope at the tip for tip deflections w (small-deflection theory: 1.5 w / L)."""
        return self._tip(self._ratio(deflection_m, length_m))


BEAM_MODELS = ('linear', 'elastica')

#: How a simulator computes the current: ``model`` -- the closed-form model with its effects
#: (offline by exact FFT prediction, in the node by an order-8 reduction); ``field`` -- the
#: independent solution of the field equations (:mod:`ipmc_sensor_ros.physics.field`).
FIDELITIES = ('model', 'field')


def check_fidelity(fidelity: str, beam_model: str = 'linear') -> bool:
    """
    Validate ``fidelity`` and ``beam_model`` together; True for the field solution.

    A large-deflection beam needs the field solution (the closed form assumes the
    small-deflection beam, eq. 21).  Raises ParameterError naming the parameter.
    """
    if fidelity not in FIDELITIES:
        hint = (
            " ('reduced' and 'exact' are now 'model')" if fidelity in ('reduced', 'exact') else ''
        )
        raise ParameterError(f"parameter 'fidelity' must be one of {list(FIDELITIES)}, "
                             f'got {fidelity!r}{hint}')
    require_field_fidelity(beam_model, fidelity == 'field')
    return fidelity == 'field'


def require_field_fidelity(beam_model: str, field: bool) -> None:
    """
    Refuse a large-deflection beam where the closed form is used instead of the field solution.

    The closed form: small-deflection beam, eq. 21.  Raises ParameterError naming the parameter.
    """
    if beam_model != 'linear' and not field:
        raise ParameterError(f"parameter 'beam_model' = {beam_model!r} needs fidelity 'field' "
                             '(the closed form assumes the small-deflection beam, eq. 21)')


def make_beam(name: str):
    """``linear`` (the paper, eq. 21) or ``elastica`` (large deflection)."""
    if name == 'linear':
        return LinearBeam()
    if name == 'elastica':
        return ElasticaBeam()
    raise ParameterError(
        f"parameter 'beam_model' must be one of {list(BEAM_MODELS)}, got {name!r}"
    )
