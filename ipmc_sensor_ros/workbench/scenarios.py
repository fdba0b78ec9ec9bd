# SPDX-License-Identifier: Apache-2.0
"""
Synthetic measurement campaigns.

crank-slider sweeps and long records, with any model (base + effects),
realistic noise, seeded.

Used by ``ipmc-model simulate``, the hidden-effect tests and the worked
example.  The current is the exact prediction of the model
(:func:`~ipmc_sensor_ros.simulation.sensor.predict_current`) after a pre-roll
of ``preroll_s`` seconds (so no start-up transient), plus white Gaussian noise
of RMS ``noise_rel`` times the clean current's RMS.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..physics.beam import check_fidelity
from ..physics.effects import get_effect
from ..physics.model import SensorModel
from ..physics.parameters import PAPER_PARAMETERS, PAPER_SAMPLES, Geometry, MaterialParameters
from ..simulation.convolution import predict_current
from ..simulation.stimuli import CrankSlider
from .timepredict import Record

__all__ = [
    'crank_slider_campaign',
    'DETECTABLE_RANGES',
    'random_effect_values',
    'hidden_effects_campaign',
]

#: Parameter ranges, inside each effect's plausible range, where the effect is
#: large enough to be seen against 1 % noise in a 1-20 Hz sweep (used to draw
#: hidden effects for tests; smaller effects are, correctly, not detected).
DETECTABLE_RANGES = {
    'amplifier_bandwidth': {'corner_hz': (30.0, 300.0)},
    'time_delay': {'delay_s': (5e-4, 5e-3)},
    'current_offset': {'offset_a': (1e-7, 5e-7), 'drift_a_per_s': (-2e-8, 2e-8)},
    # the plain exponential (no equilibrium) unless a test asks for a relaxation
    'hydration_drift': {'diffusivity_rate_per_s': (-2e-3, -5e-4), 'equilibrium_ratio': (0.0, 0.0)},
    'effective_length': {'tip_offset_m': (1.5e-3, 4e-3)},
    'beam_inertia': {'natural_frequency_hz': (22.0, 50.0), 'damping_ratio': (0.01, 0.1)},
    'nonlinearity': {'quadratic': (0.5, 2.0), 'cubic': (5.0, 20.0)},
}


def random_effect_values(name: str, rng: np.random.Generator) -> dict[str, float]:
    """Draw parameters of ``name`` within its detectable (else plausible) range."""
    eff = get_effect(name)
    out = {}
    for par in eff.parameters:
        lo, hi = DETECTABLE_RANGES.get(name, {}).get(par.name, par.typical)
        if par.log_scale and lo > 0:
            out[par.name] = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
        else:
            out[par.name] = float(rng.uniform(lo, hi))
    return out


def crank_slider_campaign(true_effects: Sequence = ('surface_resistance',), *,
                          samples: Sequence[str | Geometry] = ('slim', 'short'),
                          frequencies_hz: Sequence[float] = tuple(np.geomspace(1.0, 20.0, 8)),
                          duration_s: float = 6.0, sample_rate_hz: float = 1000.0,
                          crank_radius_m: float = 2e-3, rod_length_m: float = 15e-3,
                          material: MaterialParameters = PAPER_PARAMETERS, noise_rel: float = 0.01,
                          seed: int = 0, model_effects: Sequence = ('surface_resistance',),
                          preroll_s: float = 1.0, fidelity: str = 'model',
                          beam_model: str = 'linear', hum_rel: float = 0.0,
                          hum_hz: float = 50.0) -> list[Record]:
    """
    One record per (sample, frequency).

    ``true_effects`` make the data, ``model_effects`` go into each record's (to be tested) model.
    ``fidelity``: ``model`` (FFT prediction of the closed form with its effects) or ``field`` (the
    independent field solution, :class:`~ipmc_sensor_ros.simulation.sensor.FieldSensorSimulator`),
    whose ``beam_model`` may be ``elastica`` (large-deflection stress profile). ``hum_rel``: mains
    interference of RMS ``hum_rel`` x the clean current's RMS at ``hum_hz`` (80 % of its power)
    and its third harmonic (20 %), random phases per record.
    """
    check_fidelity(fidelity, beam_model)
    rng = np.random.default_rng(seed)
    out = []
    for sample in samples:
        geometry = PAPER_SAMPLES[sample] if isinstance(sample, str) else sample
        truth = SensorModel(geometry, material, tuple(true_effects))
        for f in frequencies_hz:
            k = np.arange(int(round((duration_s + preroll_s) * sample_rate_hz)))
            t = k / sample_rate_hz
            stim = CrankSlider(float(f), crank_radius_m, rod_length_m)
            w = stim.deflection(t)
            if fidelity == 'field':
                from ..simulation.sensor import FieldSensorSimulator

                i = FieldSensorSimulator(truth, sample_rate_hz, beam_model=beam_model).run(
                    stim, t
                )[1]
            else:
                i = predict_current(truth, t, w)
            keep = t >= preroll_s
            # the record's clock from its first sample, by sample count (t - preroll_s carries
            # rounding noise into the written times: 0.0009999999999998899)
            k = k[keep]
            t, w, i = (k - k[0]) / sample_rate_hz, w[keep], i[keep]
            scale = np.std(i)
            i = i + rng.normal(0.0, noise_rel * scale, i.size)
            if hum_rel > 0:
                for m, share in ((1, 0.8), (3, 0.2)):
                    i = i + hum_rel * scale * np.sqrt(2 * share) * np.cos(
                        2 * np.pi * m * hum_hz * t + rng.uniform(0, 2 * np.pi))
            out.append(Record(f"{geometry.name or 'sample'}_{f:.3g}Hz", geometry.name or 'sample',
                              SensorModel(geometry, material, tuple(model_effects)), t, w, i))
    return out


def hidden_effects_campaign(
    hidden: Sequence[str], seed: int, **kwargs
) -> tuple[list[Record], dict]:
    """
    Return the records with the ``hidden`` effects and the truth.

    Effect values are drawn by :func:`random_effect_values` from a generator seeded with
    ``seed``, for a diagnosis that starts from H2, or from H1 when ``surface_resistance``
    is among the hidden effects.  Returns ``(records, truth)``, ``truth`` = {effect: values}.
    """
    rng = np.random.default_rng(10_000 + seed)
    truth = {name: random_effect_values(name, rng) for name in hidden}
    true_effects = ['surface_resistance'] + [
        (n, v) for n, v in truth.items() if n != 'surface_resistance'
    ]
    model_effects = () if 'surface_resistance' in truth else ('surface_resistance',)
    recs = crank_slider_campaign(
        tuple(true_effects), seed=seed, model_effects=model_effects, **kwargs
    )
    return recs, truth
