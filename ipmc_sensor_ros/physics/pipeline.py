# SPDX-License-Identifier: Apache-2.0
"""
One compiled model pipeline per :class:`SensorModel`.

A :class:`SensorModel` taken apart once into the pieces every user needs (prediction,
fitting, simulation, reduction, estimation).

A sensor model is H1 (eq. 31) times the factors of its effects (surface resistance, eq. 45;
amplifier, delay, beam modes, ...), wrapped in the effects' transforms.  In signal order::

    w --input transforms (T(w), e.g. nonlinearity)--> H(s) --output transforms (e.g. offset)--> i
    H(s) = H_diffusive(s) * R_exact(s) * exp(-s tau)

* ``H_diffusive`` (:meth:`CompiledModel.diffusive_transfer`): H1 times every factor that has no
  exact rational form, each with its own pure delay taken out -- the diffusion-type part that
  :mod:`ipmc_sensor_ros.lti.reduction` approximates by real poles and zeros;
* ``R_exact`` (:attr:`CompiledModel.rational_factors`): factors with an exact (zeros, poles,
  gain) form (amplifier pole, beam modes), appended to the reduction unchanged;
* ``tau`` (:attr:`CompiledModel.delay_s`): the total pure delay, which no causal inverse can
  undo (the estimator re-stamps its output instead);
* a time-varying material (``material_at``, e.g. ``hydration_drift``), followed by rebuilding
  the pieces for the material at the update times (:class:`DriftSchedule`).

Every rule of how a model is assembled lives here; :class:`SensorModel` delegates to it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterator

import numpy as np

from ..errors import ParameterError
from .effects import Effect, get_effect
from .sensing import h1

__all__ = ['CompiledModel', 'DriftSchedule', 'compile_model', 'material_nodes',
           'time_varying_response']


def _overrides(effect: Effect, name: str) -> bool:
    return getattr(type(effect), name) is not getattr(Effect, name)


@dataclass(frozen=True)
class CompiledModel:
    """The pieces of a model (module docstring); build with :func:`compile_model`."""

    model: object
    effects: tuple                       # ((Effect, values), ...) in model order
    input_transforms: tuple              # effects that transform the deflection
    output_transforms: tuple             # effects that transform the current
    material_at: Callable | None         # elapsed_s -> MaterialParameters, or None
    delay_s: float
    rational_factors: tuple              # ((zeros, poles, gain), ...) rad/s
    _rational_effects: tuple             # indices of effects whose factor is rational

    # -- frequency domain ----------------------------------------------------------------
    def transfer(self, s) -> np.ndarray:
        """
        i(s)/w(s), A m^-1: H1 (eq. 31) times every effect's factor.

        non-LTI effects contribute their linear part only.
        """
        s = np.asarray(s, dtype=complex)
        out = h1(s, self.model.material, self.model.geometry)
        for eff, values in self.effects:
            fac = eff.factor(s, self.model, values)
            if fac is not None:
                out = out * fac
        return out

    def min_phase_transfer(self, s) -> np.ndarray:
        """:meth:`transfer` without its pure delay (what a causal inverse can invert)."""
        s = np.asarray(s, dtype=complex)
        return self.transfer(s) * np.exp(s * self.delay_s)

    def diffusive_transfer(self, s) -> np.ndarray:
        """
        H1 times the factors without an exact rational form, each without its delay.

        The part the reduction approximates (the rational factors are not divided out
        numerically).
        """
        s = np.asarray(s, dtype=complex)
        out = h1(s, self.model.material, self.model.geometry)
        for k, (eff, values) in enumerate(self.effects):
            if k in self._rational_effects:
                continue
            fac = eff.factor(s, self.model, values)
            if fac is not None:
                delay = eff.delay_s(values)
                out = out * (fac * np.exp(s * delay) if delay else fac)
        return out

    # -- time domain ------------------------------------------------------------------
    def apply_input_transforms(self, elapsed_s, w) -> np.ndarray:
        """T(w): the deflection the LTI part sees."""
        for eff, values in self.input_transforms:
            w = eff.input_transform(elapsed_s, w, self.model, values)
        return w

    def apply_output_transforms(self, elapsed_s, i) -> np.ndarray:
        """Return the measured current from the LTI part's current."""
        for eff, values in self.output_transforms:
            i = eff.output_transform(elapsed_s, i, self.model, values)
        return i

    def predict(self, elapsed_s, deflection_m, linear_response: Callable,
                span_response: Callable | None = None) -> np.ndarray:
        """
        Return the current for a deflection record.

        Input transforms, ``linear_response(model, w)`` of the LTI part (quasi-static over a
        drifting material, :func:`time_varying_response`), output transforms. Prediction and
        fitting share this order of operations.  ``span_response(model, w, lo, hi)``
        (optional): the same response at samples ``lo:hi`` only, used for a drifting
        material, whose node responses are needed between their neighbours only.
        """
        w = self.apply_input_transforms(elapsed_s, deflection_m)
        if self.material_at is None:
            i = linear_response(self.model, w)
        else:
            i = time_varying_response(
                elapsed_s,
                self.material_at,
                lambda mat: linear_response(self.model.with_material(mat), w),
                None if span_response is None else
                lambda mat, lo, hi: span_response(self.model.with_material(mat), w, lo, hi),
            )
        return self.apply_output_transforms(elapsed_s, i)

    def require_inverse(self) -> None:
        """Refuse a model an estimator cannot invert: a transform without its inverse."""
        for eff, _ in self.output_transforms:
            if not _overrides(eff, 'inverse_output_transform'):
                raise ParameterError(f"parameter 'effects': '{eff.name}' transforms the current "
                                     'but defines no inverse_output_transform')
        for eff, _ in self.input_transforms:
            if not _overrides(eff, 'inverse_input_transform'):
                raise ParameterError(f"parameter 'effects': '{eff.name}' transforms the "
                                     'deflection but defines no inverse_input_transform')

    @property
    def is_lti(self) -> bool:
        """
        Return True when no effect acts outside the transfer function.

        No transforms, no drift.
        """
        return not (self.input_transforms or self.output_transforms or self.material_at)

    def at_material(self, material) -> 'CompiledModel':
        """Return the pipeline of the same model with another material (a drift update)."""
        return compile_model(self.model.with_material(material))


def compile_model(model) -> CompiledModel:
    """Take ``model`` (a :class:`~ipmc_sensor_ros.physics.model.SensorModel`) apart once."""
    effects = tuple((get_effect(spec.name), spec.as_dict()) for spec in model.effects)
    material_at, rational, rational_idx = None, [], []
    for k, (eff, values) in enumerate(effects):
        drift = eff.material_at(model, values)
        if drift is not None:
            if material_at is not None:
                raise ParameterError("parameter 'effects': two time-varying materials "
                                     f"(second: '{eff.name}')")
            material_at = drift
        zpk = eff.rational(model, values)
        if zpk is not None:
            rational.append(zpk)
            rational_idx.append(k)
    return CompiledModel(
        model=model, effects=effects,
        input_transforms=tuple(e for e in effects if _overrides(e[0], 'input_transform')),
        output_transforms=tuple(e for e in effects if _overrides(e[0], 'output_transform')),
        material_at=material_at,
        delay_s=float(sum(eff.delay_s(values) for eff, values in effects)),
        rational_factors=tuple(rational), _rational_effects=tuple(rational_idx))


class DriftSchedule:
    """
    Update times of a time-varying material: every ``update_s`` seconds of elapsed time.

    :meth:`slices` cuts a block of elapsed times at the update times and calls
    ``on_update(material)`` before the samples that follow each one; the estimator and the
    simulator both follow a drifting material this way.
    """

    def __init__(self, material_at: Callable, update_s: float):
        if not update_s > 0:
            raise ParameterError(f"parameter 'update_s' must be > 0 s, got {update_s!r}")
        self.material_at = material_at
        self.update_s = float(update_s)
        self.next_update_s = self.update_s

    def reset(self) -> None:
        self.next_update_s = self.update_s

    def slices(self, elapsed_s: np.ndarray, on_update: Callable) -> Iterator[slice]:
        start, n = 0, elapsed_s.size
        while start < n:
            cut = int(np.searchsorted(elapsed_s, self.next_update_s, side='left'))
            if cut <= start:
                on_update(self.material_at(self.next_update_s))
                self.next_update_s += self.update_s
                continue
            yield slice(start, min(cut, n))
            start = min(cut, n)


def material_nodes(elapsed_s: np.ndarray, material_at, max_step: float = 0.05) -> np.ndarray:
    """
    Node times (s) at which a time-varying material is sampled.

    Start, end, and enough in between that no material parameter changes by
    more than ``max_step`` (relative, log) between neighbours (at most 64
    nodes).
    """
    t0, t1 = float(elapsed_s[0]), float(elapsed_s[-1])
    a, b = material_at(t0).to_dict(), material_at(t1).to_dict()
    span = max(abs(np.log(b[k] / a[k])) for k in a if a[k] > 0 and b[k] > 0)
    n = int(min(64, max(1, np.ceil(span / max_step))))
    return np.linspace(t0, t1, n + 1)


def time_varying_response(elapsed_s: np.ndarray, material_at, response_for,
                          span_response_for=None) -> np.ndarray:
    """
    Quasi-static response of a system whose material drifts slowly.

    The LTI responses ``response_for(material)`` at :func:`material_nodes`,
    linearly interpolated in time between neighbouring nodes (error ~
    step^2/8 of the response's curvature in the material: < 1e-3 relative
    for 5 % steps).  ``span_response_for(material, lo, hi)`` (optional): the response
    at samples ``lo:hi`` only; each node's response is needed only between its two
    neighbours, so with it the nodes together cost about two full responses.
    """
    nodes = material_nodes(elapsed_s, material_at)
    # interval k (between nodes k-1 and k) holds samples bounds[k-1]:bounds[k]; the last
    # interval includes the final sample
    bounds = np.searchsorted(elapsed_s, nodes, side='left')
    bounds[0], bounds[-1] = 0, elapsed_s.size
    last = nodes.size - 1

    def node_response(k):
        lo, hi = int(bounds[max(k - 1, 0)]), int(bounds[min(k + 1, last)])
        mat = material_at(nodes[k])
        resp = (response_for(mat)[lo:hi] if span_response_for is None
                else span_response_for(mat, lo, hi))
        return resp, lo

    out = np.zeros(elapsed_s.size)
    previous = node_response(0)
    for k in range(1, nodes.size):
        current = node_response(k)
        a, b = int(bounds[k - 1]), int(bounds[k])
        frac = (elapsed_s[a:b] - nodes[k - 1]) / (nodes[k] - nodes[k - 1])
        out[a:b] = ((1 - frac) * previous[0][a - previous[1]:b - previous[1]]
                    + frac * current[0][a - current[1]:b - current[1]])
        previous = current
    return out
