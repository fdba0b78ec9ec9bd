# SPDX-License-Identifier: Apache-2.0
"""
Benchmarks of the core: estimator throughput and per-sample overhead, model evaluation.

Every figure is a ratio against a baseline measured in the same process, so the
numbers are comparable across machines.  No assertions: README "Benchmarks" lists the
measured figures.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.signal as sig

from ipmc_sensor_ros.estimation.inverse import InverseEstimator
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import PAPER_SAMPLES
from ipmc_sensor_ros.lti.reduction import reduce_model


def _best_of(fn, repeats: int) -> float:
    best = float('inf')
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def bench_estimator(smoke: bool = False) -> list[dict]:
    model = SensorModel(PAPER_SAMPLES['slim'])
    est = InverseEstimator(reduce_model(model, 4), 1000.0)
    n = 10_000 if smoke else 1_000_000
    repeats = 2 if smoke else 5
    x = np.random.default_rng(0).normal(0, 1e-6, n)
    zi = np.zeros((est.sos.shape[0], 2))
    t_ref = _best_of(lambda: sig.sosfilt(est.sos, x, zi=zi), repeats)
    t_est = _best_of(lambda: est.process(x), repeats)
    rows = [
        {
            'benchmark': 'estimator block (1 ch)',
            'value': n / t_est / 1e6,
            'unit': 'Msample/s',
            'baseline': 'scipy.signal.sosfilt same SOS',
            'ratio': t_ref / t_est,
            'target': '>= 0.8',
        }
    ]
    m = 1000 if smoke else 50_000
    t_per = _best_of(lambda: [est.process_sample(v) for v in x[:m]], 2) / m
    t_ref1 = _best_of(lambda: [sig.sosfilt(est.sos, x[i:i + 1], zi=zi) for i in range(m)], 2) / m
    rows.append(
        {
            'benchmark': 'estimator per-sample call',
            'value': t_per * 1e6,
            'unit': 'us/sample',
            'baseline': 'sosfilt on 1-sample arrays',
            'ratio': t_ref1 / t_per,
            'target': '-',
        }
    )
    ch = 8
    xc = np.random.default_rng(1).normal(0, 1e-6, (n // ch * ch // ch, ch))
    est8 = InverseEstimator(est.reduced, 1000.0, channels=ch)
    t8 = _best_of(lambda: est8.process(xc), repeats)
    t1 = _best_of(lambda: est.process(xc[:, 0]), repeats)
    rows.append({'benchmark': f'estimator {ch} channels', 'value': xc.size / t8 / 1e6,
                 'unit': 'Msample/s', 'baseline': f'{ch} x 1-channel time', 'ratio': ch * t1 / t8,
                 'target': '>= 1 (linear or better)'})
    return rows


def bench_model(smoke: bool = False) -> list[dict]:
    model = SensorModel(PAPER_SAMPLES['slim'])
    f = np.logspace(-2, 3, 10_000 if smoke else 100_000)
    t = _best_of(lambda: model.frequency_response(f), 3)
    t_exp = _best_of(lambda: np.exp(2j * np.pi * f), 3)
    return [{'benchmark': f'H2 on {f.size} frequencies', 'value': t * 1e3, 'unit': 'ms',
             'baseline': 'np.exp on same complex array', 'ratio': t / t_exp,
             'target': '< 20 ms at 1e5'}]


def bench_field(smoke: bool = False) -> list[dict]:
    """
    Return the simulated seconds per wall-clock second of the field solvers at 1 kHz.

    Sample slim, 5 Hz.
    """
    from ipmc_sensor_ros.physics.beam import ElasticaBeam
    from ipmc_sensor_ros.physics.field import FieldSolver
    from ipmc_sensor_ros.physics.field_nonlinear import NonlinearFieldSolver

    duration = 1.0 if smoke else 10.0
    t = np.arange(int(duration * 1000)) / 1000.0
    w = 2e-3 * np.sin(2 * np.pi * 5 * t)
    slim = SensorModel(PAPER_SAMPLES['slim'])
    linear = FieldSolver(slim)
    elastica = FieldSolver(slim, beam=ElasticaBeam())
    nonlinear = NonlinearFieldSolver(SensorModel(PAPER_SAMPLES['slim'], effects=()))
    rows = []
    for label, solver in (
        (f'linear (H2, {linear.n_states} states)', linear),
        (f'elastica beam (H2, 5 shapes, {elastica.n_states} states)', elastica),
        (
            f'nonlinear eq. 9 (H1, {nonlinear.z.size} z-points x {nonlinear.x.size} ' 'nodes)',
            nonlinear,
        ),
    ):
        t0 = time.perf_counter()
        solver.simulate(t, w)
        wall = time.perf_counter() - t0
        rows.append({'benchmark': f'field solver {label}, 1 kHz', 'value': duration / wall,
                     'unit': 'x real time', 'baseline': 'wall clock', 'ratio': duration / wall,
                     'target': '-'})
    return rows
