# SPDX-License-Identifier: Apache-2.0
"""
The paper's charge transport with the term it drops from eq. 9: how far the linear model holds.

The same thickness mesh and second derivative as :mod:`.field` (its linear solver), on the
full thickness, since the nonlinear term breaks the odd symmetry of the linear problem.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .field import _graded_nodes, _second_derivative
from .model import SensorModel

__all__ = ['NonlinearFieldSolver']


class NonlinearFieldSolver:
    """
    Eq. 12 *with* the term the paper drops from eq. 9, on the full thickness.

    d rho/dt = d rho_xx - K rho - d (F (1 - C- dV) / (R T)) d(E rho)/dx,   -h < x < h,

    E_x = rho / kappa_e with zero potential difference between the electrodes (r0 = 0,
    the H1 set-up, where the nonlinearity is cleanest to isolate), rho(+-h) = +-c(z) w(t).
    The nonlinear term breaks the odd symmetry in x and the separability in z, so the
    thickness problem is solved on the whole of [-h, h] (mesh graded towards both
    surfaces) at Gauss-Legendre points along the length (the charge per area is a
    low-degree polynomial in the boundary amplitude c(z) w, so ``n_gauss`` = 6 points
    integrate it exactly to high degree).  Time stepping: IMEX -- Crank-Nicolson for the
    linear part, second-order Adams-Bashforth for the (small) nonlinear term.
    ``linear=True`` drops the term (the paper's model), for comparisons.
    Output: the short-circuit current i = W int_0^L dq/dt dz, q = kappa_e E(h).
    """

    def __init__(self, model: SensorModel, surface_cell: float = 0.05, growth: float = 1.08,
                 n_gauss: int = 6, linear: bool = False):
        m, g = model.material, model.geometry
        self.h, self.L, self.W = g.half_thickness_m, g.length_m, g.width_m
        self.d, self.K, self.kappa = m.diffusivity_m2_per_s, m.k_rate_per_s, m.permittivity_f_per_m
        self.nl_coef = 0.0 if linear else self.d * m.faraday_constant_c_per_mol * \
            m.one_minus_anion_volume_fraction / (m.gas_constant_j_per_mol_k * m.temperature_k)
        half = _graded_nodes(self.h, surface_cell * np.sqrt(self.d / self.K), growth)
        self.x = np.concatenate([-half[::-1], half[1:]])
        d2 = _second_derivative(self.x)
        n = self.x.size
        self.A = (self.d * d2[:, 1:-1] - self.K * sp.identity(n - 2, format='csr')).tocsc()
        self.b_left = self.d * d2[:, 0].toarray().ravel()
        self.b_right = self.d * d2[:, -1].toarray().ravel()
        # derivative on interior nodes (non-uniform central differences)
        xm, x0, xp = self.x[:-2], self.x[1:-1], self.x[2:]
        hm, hp = x0 - xm, xp - x0
        self._dm, self._d0, self._dp = (
            -hp / (hm * (hm + hp)),
            (hp - hm) / (hm * hp),
            hm / (hp * (hm + hp)),
        )
        zg, wg = np.polynomial.legendre.leggauss(n_gauss)
        self.z = 0.5 * self.L * (zg + 1)
        self.wz = 0.5 * self.L * wg
        self.c = (
            3
            * m.youngs_modulus_pa
            * self.h
            / (m.charge_stress_coupling_j_per_c * self.L**3)
            * (self.L - self.z)
        )
        self.dx = np.diff(self.x)

    def _field(self, rho: np.ndarray) -> np.ndarray:
        """
        E at all nodes (columns of rho: one per z point) with zero electrode potential difference.

        int_{-h}^{h} E dx = 0.
        """
        cum = (
            np.vstack(
                [
                    np.zeros((1, rho.shape[1])),
                    np.cumsum(0.5 * (rho[1:] + rho[:-1]) * self.dx[:, None], axis=0),
                ]
            )
            / self.kappa
        )
        integral = np.sum(0.5 * (cum[1:] + cum[:-1]) * self.dx[:, None], axis=0)
        e_left = -integral / (2 * self.h)
        return e_left[None, :] + cum

    def _nonlinear(self, rho: np.ndarray) -> np.ndarray:
        if self.nl_coef == 0.0:
            return np.zeros((rho.shape[0] - 2, rho.shape[1]))
        flux = self._field(rho) * rho
        return -self.nl_coef * (self._dm[:, None] * flux[:-2] + self._d0[:, None] * flux[1:-1]
                                + self._dp[:, None] * flux[2:])

    def simulate(self, time_s, deflection_m) -> np.ndarray:
        t = np.asarray(time_s, float)
        w = np.asarray(deflection_m, float)
        dt = float(t[1] - t[0])
        n_in = self.x.size - 2
        eye = sp.identity(n_in, format='csc')
        lhs = spla.splu((eye - 0.5 * dt * self.A).tocsc())
        rhs_m = (eye + 0.5 * dt * self.A).tocsr()
        u = np.zeros((n_in, self.z.size))
        charge = np.empty(t.size)

        def full(u_in, wk):
            bc = self.c * wk
            return np.vstack([-bc[None, :], u_in, bc[None, :]])

        def surface_charge(u_in, wk):
            return self.W * np.sum(self.wz * self.kappa * self._field(full(u_in, wk))[-1])

        charge[0] = surface_charge(u, w[0])
        n_prev = self._nonlinear(full(u, w[0]))
        for k in range(1, t.size):
            bc_sum = self.c * (w[k - 1] + w[k])
            forcing = 0.5 * dt * (np.outer(self.b_right, bc_sum) - np.outer(self.b_left, bc_sum))
            n_now = self._nonlinear(full(u, w[k - 1]))
            explicit = dt * (1.5 * n_now - 0.5 * n_prev) if k > 1 else dt * n_now
            u = lhs.solve(rhs_m @ u + forcing + explicit)
            n_prev = n_now
            charge[k] = surface_charge(u, w[k])
        return np.gradient(charge, dt)
