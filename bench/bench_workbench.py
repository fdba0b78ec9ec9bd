# SPDX-License-Identifier: Apache-2.0
"""
Benchmarks of the workbench: fit, compare and diagnose on the standard sweep.

The standard sweep: slim + short samples, 8 crank-slider frequencies 1-20 Hz,
6 s at 1 kHz each (16 files), 1 % noise.  Baseline for the ratios: one
evaluation of H2 at the 16 frequency points, in the same process.
"""
from __future__ import annotations

import time

import numpy as np

from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import PAPER_PARAMETERS, PAPER_SAMPLES
from ipmc_sensor_ros.workbench.compare import compare_records
from ipmc_sensor_ros.workbench.diagnose import diagnose
from ipmc_sensor_ros.workbench.freqfit import FitGroup, fit_parameters
from ipmc_sensor_ros.workbench.freqresp import fundamental_response
from ipmc_sensor_ros.workbench.scenarios import crank_slider_campaign


def _timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def bench_workbench(smoke: bool = False) -> list[dict]:
    freqs = (1.0, 20.0) if smoke else tuple(np.geomspace(1, 20, 8))
    recs = crank_slider_campaign(('surface_resistance', ('time_delay', {'delay_s': 2e-3})),
                                 frequencies_hz=freqs, duration_s=3.0 if smoke else 6.0)
    groups = {}
    for r in recs:
        groups.setdefault(r.sample, FitGroup(r.model.geometry, [], name=r.sample)).points.append(
            fundamental_response(r.time_s, r.deflection_m, r.current_a))
    groups = list(groups.values())
    f = np.array([p.frequency_hz for g in groups for p in g.points])
    t_base = min(_timed(lambda: SensorModel(PAPER_SAMPLES['slim']).frequency_response(f))[0]
                 for _ in range(20))
    start = PAPER_PARAMETERS.replace(
        diffusivity_m2_per_s=5e-11, charge_stress_coupling_j_per_c=150.0
    )
    free = ('diffusivity_m2_per_s', 'anion_concentration_mol_per_m3', 'permittivity_f_per_m',
            'charge_stress_coupling_j_per_c')
    t_fit, _ = _timed(lambda: fit_parameters(groups, free, start))
    t_cmp, _ = _timed(lambda: compare_records(recs, lambda r: r.model))
    rows = [
        {'benchmark': f'fit 4 parameters, {f.size} frequency points', 'value': t_fit, 'unit': 's',
         'baseline': 'H2 at those points', 'ratio': t_fit / t_base, 'target': '< 0.5 s'},
        {'benchmark': f'compare, {len(recs)} records', 'value': t_cmp, 'unit': 's',
         'baseline': 'H2 at those points', 'ratio': t_cmp / t_base, 'target': '-'},
    ]
    if not smoke:
        t_diag, _ = _timed(lambda: diagnose(recs))
        rows.append({'benchmark': f'diagnose, full catalog, {len(recs)} records', 'value': t_diag,
                     'unit': 's', 'baseline': 'H2 at those points', 'ratio': t_diag / t_base,
                     'target': '< 20 s on 2 cores'})
    return rows
