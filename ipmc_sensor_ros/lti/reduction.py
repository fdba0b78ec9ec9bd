# SPDX-License-Identifier: Apache-2.0
"""
Finite-order models of the IPMC sensing dynamics.

Two things live here:

1. :func:`paper_eq55` -- the paper's fourth-order model (eq. 55) exactly as
   printed.  It is **not** fit for inversion with the Table 1-2 parameters: the
   second-order Taylor expansion of sqrt(s + K) in eq. 52,
   ``h sqrt(K) (1 + s/(2K) - s^2/(8K^2)) - sqrt(d)``, has roots
   ``s = K (2 +/- sqrt(12 - 8 sqrt(d)/(h sqrt(K))))``, one of them in the
   right half plane (about +393 rad/s for the paper's values).  That zero of
   H-hat becomes an unstable pole of its inverse (eq. 48), so a literal
   implementation of the paper's section 5.3.3 diverges.  The series of
   sqrt(s+K) about s = 0 also only converges for |s| < K (about 11 Hz), below
   the paper's own 1-20 Hz band.  :func:`eq55_poles_zeros` reports this.

2. :func:`reduce_model` -- a stable, minimum-phase reduction of any order 1..8,
   used by the estimator and the simulator.

Method of :func:`reduce_model`
------------------------------
Write ``H(s) = s R(s)``: the factor ``s`` is exact (the sensor measures the rate
of charge, eq. 31) and ``R`` has a finite, non-zero DC value.  ``R`` is a
diffusion-type function: the identity ``z coth z - 1 = 2 sum z^2/(z^2+n^2 pi^2)``
turns H1/s into a sum of first-order lags with positive residues and real
poles ``-(K + n^2 pi^2 d/h^2)`` (a Stieltjes function), and the surface-
resistance line of eq. 45 has real poles ``-(n-1/2)^2 pi^2 / tau_r``.  Rational
approximants of Stieltjes functions have real, negative, interlacing poles and
zeros, so we fit

    R_n(s) = k prod_i (s + exp(psi_i)) / prod_i (s + exp(theta_i)),

``n`` real poles and ``n`` real zeros, by weighted nonlinear least squares
(:func:`scipy.optimize.least_squares`, analytic Jacobian) on the complex
logarithm (log-magnitude and unwrapped phase, weighted 1/0.1 dB and 1/1 deg)
over a log-spaced grid that extends the requested band by a factor
``extension`` on both sides.  Because poles and zeros are parametrised as
``-exp(.)``, **every** reduced model is stable and minimum phase by
construction, for any parameters and geometry, and its inverse is stable too.
Orders are fitted in sequence; order n is started both from interlaced
log-spaced corners and from the order n-1 solution plus a near-cancelling
pole-zero pair where the error was largest, and the better fit is kept.
Models are kept in zpk form (never as high-order polynomials).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from scipy.optimize import least_squares

from ..errors import ParameterError
from ..physics.model import SensorModel

__all__ = [
    'ReducedModel',
    'ParameterError',
    'paper_eq55',
    'eq55_poles_zeros',
    'reduce_model',
    'reduce_response',
    'append_rational',
    'reduce_model_parts',
    'reduction_error',
    'reduction_error_table',
    'MAX_ORDER',
]

MAX_ORDER = 8
_DB_SCALE = 0.1 * np.log(10.0) / 20.0   # 0.1 dB expressed as a natural-log magnitude
_DEG_SCALE = np.pi / 180.0               # 1 degree in radians


@dataclass(frozen=True)
class ReducedModel:
    """
    H_n(s) = s * k * prod(s - z_i) / prod(s - p_i), A m^-1.

    ``zeros_rad_s`` and ``poles_rad_s`` are those of R_n = H_n / s (all real and
    negative, rad s^-1); ``gain`` is k (A s m^-1 at high frequency).
    ``band_hz`` is the band the fit was made for.
    """

    zeros_rad_s: np.ndarray
    poles_rad_s: np.ndarray
    gain: float
    band_hz: tuple[float, float]

    @property
    def order(self) -> int:
        return len(self.poles_rad_s)

    def charge_response(self, s) -> np.ndarray:
        """R_n(s) = H_n(s)/s, A s m^-1."""
        s = np.asarray(s, dtype=complex)[..., None]
        # numerator and denominator apart: an effect may add poles (amplifier_bandwidth)
        return (self.gain * np.prod(s - self.zeros_rad_s, axis=-1)
                / np.prod(s - self.poles_rad_s, axis=-1))

    def transfer(self, s) -> np.ndarray:
        s = np.asarray(s, dtype=complex)
        return s * self.charge_response(s)

    def frequency_response(self, frequency_hz) -> np.ndarray:
        return self.transfer(2j * np.pi * np.asarray(frequency_hz, dtype=float))

    def zpk(self) -> tuple[np.ndarray, np.ndarray, float]:
        """(zeros, poles, gain) of H_n (including the zero at s = 0)."""
        return (np.concatenate([[0.0], self.zeros_rad_s]), self.poles_rad_s.copy(), self.gain)

    def to_control(self):
        """
        H_n as a python-control ``StateSpace``.

        Improper models are not allowed there, so this returns the proper
        charge model R_n; multiply by ``s``.
        """
        import control
        import scipy.signal as sig

        a, b, c, d = sig.zpk2ss(self.zeros_rad_s, self.poles_rad_s, self.gain)
        return control.ss(a, b, c, d)


def _grid(band_hz: tuple[float, float], extension: float, n_points: int) -> np.ndarray:
    lo, hi = band_hz
    return 2.0 * np.pi * np.logspace(np.log10(lo / extension), np.log10(hi * extension), n_points)


def _check_band(band_hz: Sequence[float]) -> tuple[float, float]:
    try:
        lo, hi = (float(band_hz[0]), float(band_hz[1]))
    except (TypeError, IndexError, ValueError):
        raise ParameterError(f'band_hz must be (low, high) in Hz, got {band_hz!r}') from None
    if not (np.isfinite(lo) and np.isfinite(hi) and 0.0 < lo < hi):
        raise ParameterError(f'band_hz must satisfy 0 < low < high, got {band_hz!r}')
    return lo, hi


def reduce_response(response: Callable[[np.ndarray], np.ndarray], order: int,
                    band_hz: Sequence[float] = (0.1, 50.0), *, extension: float = 10.0,
                    n_points: int = 160, initial: ReducedModel | None = None) -> ReducedModel:
    """
    Stable, minimum-phase order-``order`` fit of ``response(s) = H(s)``.

    ``response`` must behave like ``s R(s)`` with ``R(0)`` finite and non-zero
    (a charge sensor).  See the module docstring for the method.  ``initial``
    (a reduction of the same order of a nearby response) skips the order
    continuation and starts the fit from its poles and zeros (fast updates of
    slowly varying models).
    """
    return reduce_response_all(response, order, band_hz, extension=extension,
                               n_points=n_points, initial=initial)[-1]


def reduce_response_all(
    response: Callable[[np.ndarray], np.ndarray],
    max_order: int,
    band_hz: Sequence[float] = (0.1, 50.0),
    *,
    extension: float = 10.0,
    n_points: int = 160,
    initial: ReducedModel | None = None,
) -> list[ReducedModel]:
    """Fits of orders 1..``max_order`` (each one continues from the previous)."""
    if isinstance(max_order, bool) or not isinstance(max_order, (int, np.integer)) \
            or not 1 <= max_order <= MAX_ORDER:
        raise ParameterError(f'order must be an integer in 1..{MAX_ORDER}, got {max_order!r}')
    band = _check_band(band_hz)
    if not extension >= 1.0:
        raise ParameterError(f'extension must be >= 1, got {extension!r}')
    w = _grid(band, extension, n_points)
    s = 1j * w
    r = np.asarray(response(s), dtype=complex) / s
    if not np.all(np.isfinite(r)) or np.any(r == 0):
        raise ParameterError('response is not finite and non-zero on the fit grid')
    target = np.log(np.abs(r)) + 1j * np.unwrap(np.angle(r))
    in_band = (w >= 2 * np.pi * band[0] * (1 - 1e-9)) & (w <= 2 * np.pi * band[1] * (1 + 1e-9))
    weight = np.where(in_band, 1.0, 0.3)
    log_lo, log_hi = np.log(w[0] / 100.0), np.log(w[-1] * 100.0)
    sc = s[:, None]

    def model(x, n):
        p, z = np.exp(x[:n]), np.exp(x[n:2 * n])
        return np.sum(np.log(sc + z), axis=1) - np.sum(np.log(sc + p), axis=1) + x[2 * n]

    def residual(x, n):
        e = model(x, n) - target
        return np.concatenate([weight * e.real / _DB_SCALE, weight * e.imag / _DEG_SCALE])

    def jacobian(x, n):
        p, z = np.exp(x[:n]), np.exp(x[n:2 * n])
        jac = np.concatenate([-p / (sc + p), z / (sc + z), np.ones((len(w), 1))], axis=1)
        return np.concatenate([weight[:, None] * jac.real / _DB_SCALE,
                               weight[:, None] * jac.imag / _DEG_SCALE])

    fits: list[ReducedModel] = []
    previous = None
    use_initial = initial is not None and initial.order == int(max_order)
    for n in range(int(max_order) if use_initial else 1, int(max_order) + 1):
        corners = np.logspace(np.log10(w[0]), np.log10(w[-1]), 2 * n + 2)[1:-1]
        x0 = np.concatenate([np.log(corners[0::2]), np.log(corners[1::2]), [0.0]])
        x0[-1] = np.mean(target.real - model(x0, n).real)
        starts = [x0]
        if use_initial:
            starts = [np.concatenate([np.log(-initial.poles_rad_s), np.log(-initial.zeros_rad_s),
                                      [np.log(initial.gain)]])]
        if previous is not None:
            err = np.abs(model(previous, n - 1) - target) * weight
            at = np.log(w[int(np.argmax(err))])
            starts.append(np.concatenate([np.append(previous[:n - 1], at),
                                          np.append(previous[n - 1:2 * n - 2], at + 0.05),
                                          [previous[-1]]]))
        lower = np.r_[np.full(2 * n, log_lo), -np.inf]
        upper = np.r_[np.full(2 * n, log_hi), np.inf]
        best = None
        for start in starts:
            start = np.clip(start, lower + 1e-9, upper - 1e-9)
            sol = least_squares(residual, start, jac=jacobian, args=(n,), bounds=(lower, upper),
                                method='trf', x_scale='jac', max_nfev=400)
            if best is None or sol.cost < best.cost:
                best = sol
        previous = best.x
        order_idx = np.argsort(best.x[:n])
        poles = -np.exp(best.x[:n])[order_idx]
        zeros = -np.exp(np.sort(best.x[n:2 * n]))
        fits.append(ReducedModel(zeros_rad_s=zeros, poles_rad_s=poles,
                                 gain=float(np.exp(best.x[2 * n])), band_hz=band))
    return fits


def reduce_model(model: SensorModel, order: int = 4, band_hz: Sequence[float] = (0.1, 50.0),
                 **kwargs) -> ReducedModel:
    """
    Stable minimum-phase reduction of ``model`` (see module docstring).

    A pure delay in the model (``time_delay`` effect) is not part of the
    reduction: no causal inverse can undo it; see ``SensorModel.delay_s``.
    Effects with an exact rational form (``Effect.rational``: amplifier
    bandwidth, beam resonances) are appended exactly to the real-pole fit of
    the remaining diffusion-type part, so ``order`` counts the fitted poles
    only.
    """
    return reduce_model_parts(model, order, band_hz, **kwargs)[0]


def reduce_model_parts(model: SensorModel, order: int = 4, band_hz: Sequence[float] = (0.1, 50.0),
                       **kwargs) -> tuple[ReducedModel, ReducedModel]:
    """
    (full reduction, fit of the diffusive part alone).

    The one place where the diffusive part
    (:meth:`~ipmc_sensor_ros.physics.pipeline.CompiledModel.diffusive_transfer`) is reduced and
    the exact rational factors are appended. The diffusive fit warm-starts the next reduction
    of a drifting material (``initial=``).
    """
    diffusive = reduce_response(model.diffusive_transfer, order, band_hz, **kwargs)
    return append_rational(diffusive, model.rational_factors()), diffusive


def append_rational(reduced: ReducedModel, factors) -> ReducedModel:
    """``reduced`` times exact rational factors [(zeros, poles, gain), ...] (rad/s)."""
    if not factors:
        return reduced
    zeros = np.concatenate([reduced.zeros_rad_s] + [np.asarray(z, complex) for z, _, _ in factors])
    poles = np.concatenate([reduced.poles_rad_s] + [np.asarray(p, complex) for _, p, _ in factors])
    gain = reduced.gain * float(np.prod([k for _, _, k in factors]))
    return ReducedModel(zeros_rad_s=zeros, poles_rad_s=poles, gain=gain, band_hz=reduced.band_hz)


def reduction_error(reduced, model: SensorModel, band_hz: Sequence[float] = (0.1, 50.0),
                    n_points: int = 400) -> tuple[float, float]:
    """
    Worst |magnitude error| (dB) and |phase error| (deg) of ``reduced`` against ``model``.

    Over ``band_hz``.  ``reduced`` is anything with ``frequency_response``.
    """
    lo, hi = _check_band(band_hz)
    f = np.logspace(np.log10(lo), np.log10(hi), n_points)
    ratio = reduced.frequency_response(f) / model.min_phase_transfer(2j * np.pi * f)
    mag_db = 20.0 * np.log10(np.abs(ratio))
    phase_deg = np.degrees(np.angle(ratio))
    return float(np.max(np.abs(mag_db))), float(np.max(np.abs(phase_deg)))


def reduction_error_table(models: dict[str, SensorModel], orders: Sequence[int] = range(1, 9),
                          band_hz: Sequence[float] = (0.1, 50.0)) -> list[dict]:
    """Rows ``{sample, order, max_mag_error_db, max_phase_error_deg}``."""
    rows = []
    for name, model in models.items():
        fits = reduce_response_all(model.diffusive_transfer, max(orders), band_hz)
        for order in orders:
            mag, phase = reduction_error(
                append_rational(fits[order - 1], model.rational_factors()), model, band_hz
            )
            rows.append({'sample': name, 'order': int(order), 'max_mag_error_db': mag,
                         'max_phase_error_deg': phase})
    return rows


# ---------------------------------------------------------------------------
# The paper's eq. 55
# ---------------------------------------------------------------------------
def _eq55_polynomials(model: SensorModel) -> tuple[np.ndarray, np.ndarray]:
    """
    Numerator and denominator of eq. 55 (highest power first).

    The factor B(s) = s kappa_e r0 / h that multiplies both the numerator and the
    denominator of the g-part (eqs. 53-54) is cancelled exactly; leaving it would
    only add a cancelling pole-zero pair at s = 0.
    """
    m, g = model.material, model.geometry
    y, w, l, h = m.youngs_modulus_pa, g.width_m, g.length_m, g.half_thickness_m
    d, k, a0 = m.diffusivity_m2_per_s, m.k_rate_per_s, m.charge_stress_coupling_j_per_c
    b = (m.permittivity_f_per_m * m.surface_resistance_ohm / h
         if model.has_effect('surface_resistance') else 0.0)  # B(s) = b s, eq. 42
    # f-part, eq. 52: 3 s Y W sqrt(d) (h sqrt(K)(1 + s/2K - s^2/8K^2) - sqrt(d)) / (a0 L^3 (s+K))
    quad = np.array([-h * np.sqrt(k) / (8 * k ** 2), h * np.sqrt(k) / (2 * k),
                     h * np.sqrt(k) - np.sqrt(d)])
    num_f = np.polymul([3 * y * w * np.sqrt(d), 0.0], quad)
    den_f = np.array([a0 * l ** 3, a0 * l ** 3 * k])
    # g-part, eq. 54 with B = b s, divided through by B:
    # [(1/2) L^2 + (1/8) B L^4 + (1/144) B^2 L^6] / [1 + B L^2/2 + B^2 L^4/24]
    num_g = np.array([b ** 2 * l ** 6 / 144.0, b * l ** 4 / 8.0, l ** 2 / 2.0])
    den_g = np.array([b ** 2 * l ** 4 / 24.0, b * l ** 2 / 2.0, 1.0])
    return np.trim_zeros(np.polymul(num_f, num_g), 'f'), np.trim_zeros(
        np.polymul(den_f, den_g), 'f'
    )


def paper_eq55(model: SensorModel):
    """
    Return the paper's reduced model H-hat(s) (eq. 55) as a ``control.TransferFunction``.

    Exactly as printed (second-order Taylor series of sqrt(s+K), three terms of
    each series in eq. 54).  It is improper (numerator degree 5, denominator 3)
    and, with the Table 1-2 parameters, has a right-half-plane zero near
    +393 rad/s, so ``1/paper_eq55(...)`` is unstable.  Use :func:`reduce_model`.
    """
    import control

    num, den = _eq55_polynomials(model)
    return control.tf(num, den)


def eq55_poles_zeros(model: SensorModel) -> dict:
    """
    Poles and zeros of eq. 55 and whether its inverse (eq. 48) is stable.

    Returns ``{"poles", "zeros", "rhp_zeros", "inverse_stable"}`` (rad s^-1).
    """
    num, den = _eq55_polynomials(model)
    zeros, poles = np.roots(num), np.roots(den)
    rhp = zeros[zeros.real > 0]
    return {'poles': poles, 'zeros': zeros, 'rhp_zeros': rhp, 'inverse_stable': rhp.size == 0}
