# SPDX-License-Identifier: Apache-2.0
"""
Independent numerical solution of the paper's field equations (no closed-form H1/H2).

What is solved
--------------
* Charge transport across the thickness, eq. 12 (linear):
  d rho/dt = d d^2 rho/dx^2 - K rho on -h < x < h, with the stress boundary
  condition rho(+-h, z, t) = +-sigma(h, z, t)/alpha0 = +-c(z) w(t),
  c(z) = 3 Y h (L - z) / (alpha0 L^3) (eqs. 16-22).  The solution is odd in x
  and separable, rho = c(z) u(x, t) with u(h) = w(t), u(0) = 0, so one
  thickness problem serves every z.
* Field and potential, eqs. 1-2 and 24-25: E even in x, E(x) = E(0) +
  (1/kappa_e) int_0^x rho, and phi(h) - phi(-h) = 2 phi_s(z) fixes E(0).  The
  surface charge per area is then q(z) = D(h) = m(t) c(z) - (kappa_e/h) phi_s(z),
  with m = (1/h) int_0^h x u dx.
* The distributed surface resistance, eqs. 32-36 and 39: d phi_s/dz =
  (r0/W) i_s, d i_s/dz = -W dq/dt, phi_s(0) = 0, i_s(L) = 0, which is the
  RC-line diffusion r0 (kappa_e/h) d phi_s/dt = d^2 phi_s/dz^2 + r0 c(z) dm/dt.
  The sensing current is i = i_s(0) = W int_0^L dq/dt dz.  With r0 = 0,
  phi_s = 0 and i = W dm/dt int c dz (the paper's H1 case).
* The stress profile sigma(h, z) comes from a beam model
  (:mod:`ipmc_sensor_ros.physics.beam`): the paper's small-deflection beam (eq. 21,
  the default) or the large-deflection elastica, a sum of P shapes with one copy of
  the thickness problem each (the problem is linear in its boundary value).

Discretisation (method of lines)
--------------------------------
* Thickness: nodes on [0, h] graded geometrically towards the surface x = h,
  where the Debye-like boundary layer 1/beta ~ sqrt(d/K) (0.7 um for the paper's
  values, against h = 180 um) lives: the first cell is ``surface_cell`` x the
  boundary-layer thickness, growing by ``growth`` inland; second derivative by
  the three-point formula on non-uniform nodes, m by the trapezoidal rule.
* Length: ``n_length`` uniform cells on [0, L]; second derivative with the
  Dirichlet (clamp) and Neumann (open tip) conditions; integrals by the
  trapezoidal rule.
* The line is written for psi = phi_s - (c(z) h / kappa_e) m, which removes the
  input derivative, giving a standard LTI system x' = A x + B w, charge Q = C x;
  the current is i = dQ/dt = C (A x + B w).
* Frequency response: H(j w) = j w C (j w I - A)^-1 B, solved per frequency
  (sparse LU).  Time domain: Crank-Nicolson (A-stable, second order), one
  sparse LU per step size; i = C (A x + B w) + C_w dw/dt (C_w: the surface
  node's share of m, a direct term).

:func:`ipmc_sensor_ros.workbench.studies.convergence_table` shows the error against the
closed forms falling with refinement; the tests require 0.1 dB / 0.5 deg over 0.1-100 Hz.
The term the paper drops from eq. 9 is kept by :mod:`.field_nonlinear`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .model import SensorModel

__all__ = ['FieldSolver', 'FieldStream']


def _graded_nodes(h: float, first: float, growth: float) -> np.ndarray:
    """Nodes 0 = x_0 < ... < x_N = h, cell sizes growing by ``growth`` from ``first`` at x = h."""
    sizes = [first]
    while sum(sizes) < h:
        sizes.append(sizes[-1] * growth)
    sizes = np.array(sizes)
    sizes *= h / sizes.sum()            # rescale so they fill [0, h] exactly
    return h - np.concatenate([[0.0], np.cumsum(sizes)])[::-1]


def _second_derivative(x: np.ndarray) -> sp.csr_matrix:
    """
    Three-point second derivative on nodes x.

    Rows for interior nodes 1..N-1, columns for all nodes 0..N.
    """
    n = x.size
    rows, cols, vals = [], [], []
    for i in range(1, n - 1):
        hm, hp = x[i] - x[i - 1], x[i + 1] - x[i]
        for j, v in (
            (i - 1, 2 / (hm * (hm + hp))),
            (i, -2 / (hm * hp)),
            (i + 1, 2 / (hp * (hm + hp))),
        ):
            rows.append(i - 1)
            cols.append(j)
            vals.append(v)
    return sp.csr_matrix((vals, (rows, cols)), shape=(n - 2, n))


def _trapezoid_weights(x: np.ndarray) -> np.ndarray:
    w = np.zeros(x.size)
    dx = np.diff(x)
    w[:-1] += dx / 2
    w[1:] += dx / 2
    return w


@dataclass
class FieldSolver:
    """
    Method-of-lines solver of the field equations for ``model`` (h1 or h2 base).

    ``surface_cell``: first thickness cell at x = h in units of the boundary-layer
    thickness sqrt(d/K); ``growth``: cell growth ratio inland; ``n_length``:
    cells along the length (RC line); ``beam``: the mechanics that turn the tip
    deflection into the surface stress (:mod:`ipmc_sensor_ros.physics.beam`; default
    the paper's small-deflection beam, eq. 21).

    With a beam of P stress shapes, rho(h, z, t) = c0 L sum_k q_k(t) phi_k(z/L)
    (c0 = 3 Y h / (alpha0 L^3); the paper: P = 1, phi_1 = 1 - z/L, q_1 = w).  Eq. 12
    is linear, so each shape has its own copy of the thickness problem (the same
    operator) driven by q_k, and the RC line sums their charges; the system is
    x' = A x + B q with P inputs.
    """

    model: SensorModel
    surface_cell: float = 0.05
    growth: float = 1.08
    n_length: int = 40
    beam: object = None

    def __post_init__(self):
        from .beam import LinearBeam

        if self.beam is None:
            self.beam = LinearBeam()
        m, g = self.model.material, self.model.geometry
        self.h = g.half_thickness_m
        self.L = g.length_m
        self.W = g.width_m
        d, K = m.diffusivity_m2_per_s, m.k_rate_per_s
        debye = np.sqrt(d / K)
        self.x = _graded_nodes(self.h, self.surface_cell * debye, self.growth)
        nx = self.x.size
        d2x = _second_derivative(self.x)
        # thickness states (one copy per shape): interior u_1..u_{N-1}; u_0 = 0, u_N = q_k
        a_u = d * d2x[:, 1:-1] - K * sp.identity(nx - 2, format='csr')
        b_u = d * d2x[:, -1].toarray().ravel()
        wx = _trapezoid_weights(self.x) * self.x / self.h     # m = sum wx u
        p_u, p_w = wx[1:-1], wx[-1]
        a0 = m.charge_stress_coupling_j_per_c
        self.c0 = 3 * m.youngs_modulus_pa * self.h / (a0 * self.L ** 3)   # c(z) = c0 (L - z)
        n_shapes = self.beam.n_shapes
        eye_p = sp.identity(n_shapes, format='csr')
        a_uu = sp.kron(eye_p, a_u, format='csr')
        b_uu = sp.kron(eye_p, sp.csr_matrix(b_u[:, None]), format='csr').toarray()   # (P n_u, P)
        self.resistive = self.model.has_effect('surface_resistance') and \
            m.surface_resistance_ohm > 0
        kap = m.permittivity_f_per_m
        if not self.resistive:
            # Q = W int rho-shape m dz = W c0 L sum_k (int phi_k dz) m_k
            zg, wg = np.polynomial.legendre.leggauss(8)     # exact for shapes up to degree 15
            gains = (
                self.W * self.c0 * self.L * (0.5 * self.L * wg) @ self.beam.shapes(0.5 * (zg + 1))
            )
            self.A = a_uu.tocsc()
            self.B = b_uu
            self.C = np.concatenate([gk * p_u for gk in gains])
            self.Cw = gains * p_w           # Q also has a direct term in q
            return
        r0 = m.surface_resistance_ohm
        nz = self.n_length
        z = np.linspace(0, self.L, nz + 1)
        dz = z[1] - z[0]
        # phi_1..phi_nz (phi_0 = 0), Neumann at z = L via ghost node phi_{nz+1} = phi_{nz-1}
        main = -2 * np.ones(nz)
        lap = sp.diags([np.ones(nz - 1), main, np.ones(nz - 1)], [-1, 0, 1], format='lil')
        lap[nz - 1, nz - 2] = 2.0
        lap = (lap / dz ** 2).tocsr()
        tau = r0 * kap / self.h                 # r0 c per unit length^2 (time constant factor)
        # phi = psi + sum_k g_k m_k, g_k(z) = c0 L phi_k(z/L) h / kappa
        g_all = self.c0 * self.L * self.beam.shapes(z / self.L) * self.h / kap   # (nz+1, P)
        # psi' = (1/tau) lap (psi + sum_k g_k m_k),  m_k = p_u u_k + p_w q_k
        lap_g = lap @ g_all[1:]                                                  # (nz, P)
        a_pp = lap / tau
        a_pu = sp.hstack(
            [sp.csr_matrix(np.outer(lap_g[:, k] / tau, p_u)) for k in range(n_shapes)]
        )
        b_p = lap_g / tau * p_w
        self.A = sp.bmat([[a_uu, None], [a_pu, a_pp]], format='csc')
        self.B = np.vstack([b_uu, b_p])
        # Q = W int q dz, q = rho-shape m - (kappa/h) phi = -(kappa/h) psi: trapezoid over z
        # (psi_0 at z = 0 equals -sum_k g_k(0) m_k because phi_0 = 0)
        wz = _trapezoid_weights(z)
        c_psi = -self.W * kap / self.h * wz[1:]
        c_m = self.W * kap / self.h * wz[0] * g_all[0]                           # (P,)
        self.C = np.concatenate([np.concatenate([ck * p_u for ck in c_m]), c_psi])
        self.Cw = c_m * p_w

    @property
    def n_states(self) -> int:
        return self.A.shape[0]

    def frequency_response(self, frequency_hz) -> np.ndarray:
        """
        i/w (A/m) at ``frequency_hz`` from the discretised equations.

        For a nonlinear beam: its small-signal linearisation at w = 0.
        """
        f = np.atleast_1d(np.asarray(frequency_hz, float))
        out = np.empty(f.size, dtype=complex)
        eye = sp.identity(self.n_states, format='csc')
        direction = self.beam.small_signal_direction()
        b = (self.B @ direction).astype(complex)
        cw = float(self.Cw @ direction)
        for k, fk in enumerate(f):
            s = 2j * np.pi * fk
            x = spla.spsolve((s * eye - self.A).tocsc(), b)
            out[k] = s * (self.C @ x + cw)
        return out

    def simulate(
        self, time_s, deflection_m, diffusivity_at=None, update_s: float = 0.5
    ) -> np.ndarray:
        """
        Sensing current (A) for a deflection record (uniform time steps, starting from rest).

        By Crank-Nicolson; i = C (A x + B q) + C_w dq/dt with q = beam(w).

        ``diffusivity_at(elapsed_s) -> d`` (m^2/s) makes the diffusivity change during the
        run (hydration, paper section 5.4): the system is re-assembled every ``update_s``
        with d at that time, keeping the state.  The thickness mesh does not depend on d
        (its scale sqrt(d/K) = sqrt(kappa_e R T / (F^2 C-)) is independent of d), so the
        state carries over exactly.
        """
        t = np.asarray(time_s, float)
        w = np.asarray(deflection_m, float)
        dt = float(t[1] - t[0])
        stream = self.stream(1.0 / dt, diffusivity_at, update_s)
        return stream.step(w, np.gradient(w, dt))

    def stream(
        self, sample_rate_hz: float, diffusivity_at=None, update_s: float = 0.5
    ) -> 'FieldStream':
        """Return a streaming (block by block) Crank-Nicolson integrator of this system."""
        return FieldStream(self, sample_rate_hz, diffusivity_at, update_s)

    def _with_diffusivity(self, d: float) -> 'FieldSolver':
        model = self.model.with_material(
            self.model.material.replace(diffusivity_m2_per_s=float(d))
        )
        return FieldSolver(model, self.surface_cell, self.growth, self.n_length, self.beam)


class FieldStream:
    """
    Streaming Crank-Nicolson integration of a :class:`FieldSolver` (state kept between blocks).

    ``step(w_block, w_rate_block) -> current_block``. Used by
    :meth:`FieldSolver.simulate` and the simulator's ``fidelity = field``.
    """

    def __init__(self, solver: FieldSolver, sample_rate_hz: float, diffusivity_at=None,
                 update_s: float = 0.5):
        self.base = solver
        self.dt = 1.0 / float(sample_rate_hz)
        self.diffusivity_at = diffusivity_at
        self.update_s = float(update_s)
        self.x = np.zeros(solver.n_states)
        self.q_prev = np.zeros(solver.beam.n_shapes)
        self.elapsed = 0.0
        self._next_update = 0.0 if diffusivity_at else float('inf')
        self._factor(solver)

    def _factor(self, sol: FieldSolver) -> None:
        eye = sp.identity(sol.n_states, format='csc')
        self.sol = sol
        self.lhs = spla.splu((eye - 0.5 * self.dt * sol.A).tocsc())
        self.rhs = (eye + 0.5 * self.dt * sol.A).tocsr()
        self.a = sol.A.tocsr()

    def step(self, w, w_rate) -> np.ndarray:
        w = np.asarray(w, float)
        beam, length = self.base.beam, self.base.L
        q_all = beam.coordinates(w, length)
        q_rate = beam.coordinate_rates(w, w_rate, length)
        out = np.empty(w.size)
        for k in range(w.size):
            if self.elapsed >= self._next_update:
                self._factor(self.base._with_diffusivity(self.diffusivity_at(self.elapsed)))
                self._next_update += self.update_s
            qk = q_all[k]
            bq = self.sol.B @ qk
            self.x = self.lhs.solve(
                self.rhs @ self.x + 0.5 * self.dt * (self.sol.B @ self.q_prev + bq)
            )
            out[k] = self.sol.C @ (self.a @ self.x + bq) + self.sol.Cw @ q_rate[k]
            self.q_prev = qk
            self.elapsed += self.dt
        return out
