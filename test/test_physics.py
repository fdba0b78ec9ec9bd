# SPDX-License-Identifier: Apache-2.0
"""Tests of the physical parameter set and of H1 (eq. 31) / H2 (eq. 45)."""
import math

import numpy as np
import pytest

from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import (PAPER_PARAMETERS, PAPER_SAMPLES, Geometry,
                                                MaterialParameters, ParameterError, load_yaml,
                                                save_yaml)
from ipmc_sensor_ros.physics.sensing import beta, h1, h2, surface_resistance_factor

M = PAPER_PARAMETERS
SLIM, BIG, SHORT = PAPER_SAMPLES['slim'], PAPER_SAMPLES['big'], PAPER_SAMPLES['short']


def test_core_imports_without_rclpy():
    import subprocess
    import sys
    code = ("import sys; sys.modules['rclpy'] = None\n"
            'import ipmc_sensor_ros.physics.model, ipmc_sensor_ros.lti.reduction, '
            'ipmc_sensor_ros.estimation.inverse, ipmc_sensor_ros.simulation.sensor\n'
            "assert 'rclpy' not in [m for m in sys.modules if sys.modules[m] is not None]")
    subprocess.run([sys.executable, '-c', code], check=True)


def test_k_over_d_and_beta_h_match_paper_section_4():
    # Paper section 4: K/d is "of the order of 1e12"; with Tables 1-2 it is 2.166e12.
    assert M.k_rate_per_s / M.diffusivity_m2_per_s == pytest.approx(2.17e12, rel=5e-3)
    f = np.logspace(-1, 2, 50)
    bh = np.abs(beta(2j * np.pi * f, M)) * SLIM.half_thickness_m
    assert np.all(bh > 10)


@pytest.mark.parametrize('name,value', [
    ('youngs_modulus_pa', -1.0), ('diffusivity_m2_per_s', 0.0), ('temperature_k', float('nan')),
    ('surface_resistance_ohm', -0.1), ('permittivity_f_per_m', 'abc'),
])
def test_non_physical_material_values_are_refused_with_name_and_value(name, value):
    with pytest.raises(ParameterError) as exc:
        MaterialParameters(**{name: value})
    assert name in str(exc.value) and repr(value) in str(exc.value)


@pytest.mark.parametrize('kwargs,key', [
    (dict(length_m=0.0, width_m=7e-3, thickness_m=3.6e-4), 'length_m'),
    (dict(length_m=22e-3, width_m=-7e-3, thickness_m=3.6e-4), 'width_m'),
    (dict(length_m=22.0, width_m=7e-3, thickness_m=3.6e-4), 'length_m'),  # mm given as m
])
def test_non_physical_geometry_is_refused(kwargs, key):
    with pytest.raises(ParameterError, match=key):
        Geometry(**kwargs)


def test_zero_surface_resistance_is_allowed_and_parameters_are_immutable():
    m = MaterialParameters(surface_resistance_ohm=0.0)
    with pytest.raises(Exception):
        m.temperature_k = 10.0  # frozen dataclass


def test_yaml_round_trip(tmp_path):
    m = M.replace(diffusivity_m2_per_s=4e-11)
    save_yaml(tmp_path / 'p.yaml', m, SLIM)
    m2, g2 = load_yaml(tmp_path / 'p.yaml')
    assert m2 == m and g2 == SLIM


def test_yaml_errors_name_file_and_key(tmp_path):
    p = tmp_path / 'bad.yaml'
    p.write_text('material:\n  diffusivity: 3e-11\n')
    with pytest.raises(ParameterError, match=r'bad\.yaml.*diffusivity'):
        load_yaml(p)
    p.write_text('material:\n  youngs_modulus_pa: -5\n')
    with pytest.raises(ParameterError, match=r'bad\.yaml.*youngs_modulus_pa'):
        load_yaml(p)


@pytest.mark.parametrize('geometry', list(PAPER_SAMPLES.values()), ids=list(PAPER_SAMPLES))
def test_h1_h2_finite_over_1e_minus4_to_1e5_hz(geometry):
    f = np.logspace(-4, 5, 400)
    for fn in (h1, h2):
        H = fn(2j * np.pi * f, M, geometry)
        assert np.all(np.isfinite(H)) and np.all(np.abs(H) > 0)


def test_h1_matches_printed_eq31_where_printed_form_is_safe():
    # Printed eq. 31 with numpy cosh/sinh is fine at moderate |beta h|; thin sample keeps
    # beta h small enough not to overflow.  Agreement to 1e-10 is float round-off.
    g = Geometry(22e-3, 7e-3, 2e-6)
    s = 2j * np.pi * np.logspace(-2, 3, 30)
    b = np.sqrt((s + M.k_rate_per_s) / M.diffusivity_m2_per_s)
    hh = g.half_thickness_m
    printed = (3 * s * M.youngs_modulus_pa * g.width_m * (b * hh / np.tanh(b * hh) - 1)
               / (2 * M.charge_stress_coupling_j_per_c * g.length_m * b ** 2))
    assert np.allclose(h1(s, M, g), printed, rtol=1e-10, atol=0)


def test_h2_matches_printed_eq45():
    s = 2j * np.pi * np.logspace(-2, 3, 30)
    Bs = s * M.permittivity_f_per_m * M.surface_resistance_ohm / SLIM.half_thickness_m
    a = np.sqrt(Bs) * SLIM.length_m
    b = beta(s, M)
    hh = SLIM.half_thickness_m
    printed = (3 * s * M.youngs_modulus_pa * SLIM.width_m * (b * hh / np.tanh(b * hh) - 1)
               / (M.charge_stress_coupling_j_per_c * SLIM.length_m ** 3 * b ** 2)
               * (1 - np.cosh(a) + a * np.sinh(a)) / (Bs * np.cosh(a)))
    # 1e-9: the printed form loses digits in 1 - cosh(a) + a sinh(a) at small a.
    assert np.allclose(h2(s, M, SLIM), printed, rtol=1e-9, atol=0)


def test_h2_tends_to_h1_as_r0_tends_to_zero():
    f = np.logspace(-1, 3, 100)
    s = 2j * np.pi * f
    m = M.replace(surface_resistance_ohm=1e-9)
    rel = np.abs(h2(s, m, SLIM) / h1(s, m, SLIM) - 1)
    assert rel.max() < 1e-6
    # r0 = 0 exactly: the limit of eq. 46 is taken, no 0/0.
    m0 = M.replace(surface_resistance_ohm=0.0)
    assert np.array_equal(surface_resistance_factor(s, m0, SLIM), np.ones_like(s))


def test_big_and_slim_differ_by_6_db_with_equal_phase():
    f = np.logspace(-1, 2, 60)
    Hb = SensorModel(BIG).frequency_response(f)
    Hs = SensorModel(SLIM).frequency_response(f)
    assert np.allclose(20 * np.log10(np.abs(Hb / Hs)), 20 * np.log10(2), atol=1e-9)
    assert np.allclose(np.angle(Hb / Hs), 0, atol=1e-12)


def _slope_db_per_decade(model, f1=1.0, f2=20.0):
    H = model.frequency_response(np.array([f1, f2]))
    return 20 * np.log10(abs(H[1]) / abs(H[0])) / math.log10(f2 / f1)


def test_magnitude_slopes_slim_vs_short_section_5_3_2():
    # Slope between 1 and 20 Hz; the paper measured about 14 (slim) and 18 (short) dB/dec.
    slim, short = SensorModel(SLIM), SensorModel(SHORT)
    assert _slope_db_per_decade(slim) == pytest.approx(14.9, abs=0.1)
    assert _slope_db_per_decade(short) == pytest.approx(17.3, abs=0.1)
    # H1 has no length-dependent dynamics: equal slopes for slim and short.
    h1_slim, h1_short = SensorModel(SLIM, effects=()), SensorModel(SHORT, effects=())
    assert _slope_db_per_decade(h1_slim) == pytest.approx(_slope_db_per_decade(h1_short), abs=1e-9)


def test_h1_over_s_is_a_sum_of_real_pole_lags():
    # z coth z - 1 = 2 sum z^2/(z^2 + n^2 pi^2): H1/s = C sum_n 1/(s + K + n^2 pi^2 d/h^2).
    # This modal form justifies the real-pole reduction; check it numerically.
    s = 2j * np.pi * np.array([0.3, 3.0, 30.0])
    h = SLIM.half_thickness_m
    n = np.arange(1, 2_000_001)[:, None]
    lags = np.sum(1.0 / (s + M.k_rate_per_s + n**2 * np.pi**2 * M.diffusivity_m2_per_s / h**2), 0)
    c = 3 * M.youngs_modulus_pa * SLIM.width_m * M.diffusivity_m2_per_s / (
        M.charge_stress_coupling_j_per_c * SLIM.length_m)
    # tail of the series beyond n = 2e6 is ~ h/(pi sqrt(d) ... ) 1/n: 1e-3 relative is enough
    assert np.allclose(c * lags, h1(s, M, SLIM) / s, rtol=2e-3)
