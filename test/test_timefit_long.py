# SPDX-License-Identifier: Apache-2.0
"""
Long records in the time-domain fit: the row-matrix path gives the per-bin path's results.

The 30-minute drying record of ``bench/bench_discovery.py --drying-only`` is fitted through
``timepredict._row_matrix`` (issue 15 speed target); here a 400 s record (32,768 FFT bins, above
``ROW_MATRIX_ABOVE``) with a drifting diffusivity is fitted both ways.
"""
import numpy as np
import pytest

from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import PAPER_SAMPLES
from ipmc_sensor_ros.simulation.sensor import predict_current
from ipmc_sensor_ros.simulation.stimuli import CrankSlider
from ipmc_sensor_ros.workbench.timefit import FitSpec, fit_model
from ipmc_sensor_ros.workbench.timepredict import Record, predict, prepare


def _drifting_record():
    fs = 100.0
    truth = SensorModel.named('h2', PAPER_SAMPLES['slim'],
                              extra_effects='hydration_drift(diffusivity_rate_per_s=-0.002)')
    t = np.arange(int(400 * fs)) / fs
    w = CrankSlider(3.0, 2e-3, 15e-3).deflection(t)
    clean = predict_current(truth, t, w)
    y = clean + 0.01 * np.std(clean) * np.random.default_rng(3).standard_normal(t.size)
    start = truth.with_effect('hydration_drift', diffusivity_rate_per_s=-0.001)
    return Record('drift.csv', 'slim', start, t, w, y), truth


def test_row_matrix_fit_equals_per_bin_fit():
    """
    Fit d, alpha0 and the drift rate through the row matrix and through every FFT bin.

    The two predictions differ by < 1e-5 of the signal RMS (test_workbench_analysis), i.e.
    1e-3 of the 1 % noise, so the fitted values may differ by ~1e-3 of their standard errors
    (here >= 1e-3 relative): 1e-4 relative bounds that with margin, and would catch a row
    matrix that is wrong by a fraction of the noise.
    """
    rec, truth = _drifting_record()
    fast = prepare([rec])
    slow = prepare([rec], row_matrix_above=10 ** 9)
    assert fast[0].row_matrix is not None and slow[0].row_matrix is None
    spec = FitSpec(('diffusivity_m2_per_s', 'charge_stress_coupling_j_per_c'),
                   (('hydration_drift', 'diffusivity_rate_per_s'),))
    a, b = fit_model(fast, spec), fit_model(slow, spec)
    for name in spec.material:
        assert getattr(a.material, name) == pytest.approx(getattr(b.material, name), rel=1e-4)
    rate_a = a.effect_values['hydration_drift']['diffusivity_rate_per_s']
    rate_b = b.effect_values['hydration_drift']['diffusivity_rate_per_s']
    assert rate_a == pytest.approx(rate_b, rel=1e-4)
    assert a.chi2 == pytest.approx(b.chi2, rel=1e-4)
    # and both found the truth (1 % noise on 40,000 samples: d within 2 %)
    assert rate_a == pytest.approx(-0.002, rel=0.05)
    assert a.material.diffusivity_m2_per_s == pytest.approx(
        truth.material.diffusivity_m2_per_s, rel=0.02)


def test_lightly_damped_mode_in_band_keeps_per_bin_path():
    """
    A lightly damped beam mode inside the band breaks the cubic interpolation in log f.

    Its poles (22 Hz, damping 0.01) sit 0.01 from the real log-frequency axis, under one grid
    step: ``_smooth_on_grid`` refuses, and the per-bin path (log-magnitude and phase) is the
    more accurate one there (measured 6e-4 against 1.1e-3 of the signal RMS for the row
    matrix).  Bound 1e-3: a tenth of 1 % noise.
    """
    from ipmc_sensor_ros.workbench.timepredict import _smooth_on_grid, _transfer_on_grid

    rec, _ = _drifting_record()
    model = SensorModel.named(
        'h2', PAPER_SAMPLES['slim'],
        extra_effects='beam_inertia(natural_frequency_hz=5, damping_ratio=0.01)')
    p = prepare([Record('r', 'slim', model, rec.time_s, rec.deflection_m, rec.current_a)])[0]
    assert not _smooth_on_grid(p, model)
    exact = predict_current(model, p.t, p.w, pad_s=1.0)[p.rows]

    def error(got):
        return np.sqrt(np.mean((got - exact) ** 2)) / np.std(exact)

    per_bin = error(predict(p, model, rows=p.rows))
    matrix = error((p.row_matrix @ _transfer_on_grid(p, model, None)).real)
    assert per_bin < 1e-3
    assert per_bin < matrix
