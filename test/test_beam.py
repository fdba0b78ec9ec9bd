# SPDX-License-Identifier: Apache-2.0
"""
Tests of the beam mechanics.

small-deflection beam of the paper, eqs. 18-21, and the large-deflection elastica
that goes past it.
"""
import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from ipmc_sensor_ros.physics.beam import (MAX_DEFLECTION_RATIO, ElasticaBeam, LinearBeam,
                                          elastica_solution, make_beam)
from ipmc_sensor_ros.physics.parameters import ParameterError


def _first_integral_length(tip_angle: float, load: float) -> float:
    """
    Arc length (in units of L) of the elastica with tip angle theta_L under load lambda.

    From the first integral theta'^2 = 2 lambda (sin theta_L - sin theta): an independent
    (elliptic-integral) solution, no ODE solver.
    """
    # integrable 1/sqrt singularity at the tip: quad's algebraic weight (theta_L - theta)^-1/2
    # takes it, leaving a smooth factor
    def smooth(th):
        gap = tip_angle - th
        if gap <= 0.0:
            return 1.0 / np.sqrt(2.0 * load * np.cos(tip_angle))
        return np.sqrt(gap / (2.0 * load * (np.sin(tip_angle) - np.sin(th))))
    return quad(smooth, 0.0, tip_angle, weight='alg', wvar=(0.0, -0.5), limit=200)[0]


def test_elastica_matches_classical_large_deflection_values():
    """
    Bisshopp & Drucker (1945), tip-loaded cantilever, F L^2 / (E I) = 1.

    Vertical tip deflection 0.3017 L, horizontal shortening 0.0564 L, tip angle 0.4613
    rad (values quoted to 4 digits; tolerance one unit of the last digit, as the quoted
    figures may be truncated rather than rounded).
    """
    sol = elastica_solution(1.0)
    s = np.linspace(0.0, 1.0, 4001)
    theta = sol.sol(s)[0]
    assert np.trapezoid(np.sin(theta), s) == pytest.approx(0.3017, abs=1e-4)
    assert 1.0 - np.trapezoid(np.cos(theta), s) == pytest.approx(0.0564, abs=1e-4)
    assert theta[-1] == pytest.approx(0.4613, abs=1e-4)


@pytest.mark.parametrize('load', [0.5, 2.0, 3.0])
def test_elastica_tip_angle_agrees_with_first_integral_solution(load):
    """
    The BVP's tip angle equals the root of 'arc length = L' of the first integral.

    1e-6 rad: the BVP tolerance is 1e-10, quad's ~1e-9.
    """
    tip_bvp = elastica_solution(load).sol(1.0)[0]
    # bracket below pi/2, where the singularity stops being integrable (tips here < 1.1 rad)
    tip_exact = brentq(lambda a: _first_integral_length(a, load) - 1.0, 1e-6, 1.4,
                       xtol=1e-12)
    assert tip_bvp == pytest.approx(tip_exact, abs=1e-6)


def test_elastica_tends_to_the_paper_beam_at_small_deflection():
    beam = ElasticaBeam()
    length = 22e-3
    w = np.array([1e-3, -1e-3]) * length
    q = beam.coordinates(w, length)
    # eq. 21: one linear shape with q_1 = w; the others are O(w^3)
    assert np.allclose(q[:, 0], w, rtol=1e-5)
    assert np.max(np.abs(q[:, 1:])) < 1e-5 * np.max(np.abs(w))
    assert np.allclose(beam.tip_angle_rad(w, length), 1.5 * w / length, rtol=1e-5)
    assert np.array_equal(beam.small_signal_direction(), np.eye(beam.n_shapes)[0])
    assert np.array_equal(LinearBeam().coordinates(w, length)[:, 0], w)


def test_elastica_profile_is_represented_by_its_shapes_and_odd_in_w():
    beam = ElasticaBeam()
    # 5 polynomial shapes reproduce the curvature profile to < 2e-4 of its peak up to w/L = 0.6
    assert beam.projection_residual < 2e-4
    w = np.linspace(-0.5, 0.5, 11) * 0.011
    q = beam.coordinates(w, 0.011)
    assert np.allclose(q, -q[::-1], atol=1e-15)
    # the curvature grows faster than w: tip angle above 1.5 w/L (by 1.9 % at w/L = 0.3)
    ratio = beam.tip_angle_rad(np.array([0.3]), 1.0)[0] / 0.45
    assert ratio == pytest.approx(1.019, abs=0.002)


def test_elastica_coordinate_rates_are_the_chain_rule():
    beam = ElasticaBeam()
    length, w, v, dw = 0.011, np.array([2e-3, -4e-3]), np.array([0.3, -0.1]), 1e-7
    numeric = (beam.coordinates(w + dw, length) - beam.coordinates(w - dw, length)) / (2 * dw)
    assert np.allclose(beam.coordinate_rates(w, v, length), numeric * v[:, None], rtol=1e-5,
                       atol=1e-12)


def test_beam_refuses_unknown_names_and_deflections_beyond_its_table():
    with pytest.raises(ParameterError, match='beam_model'):
        make_beam('timoshenko')
    with pytest.raises(ParameterError, match='of the length'):
        ElasticaBeam().coordinates(np.array([(MAX_DEFLECTION_RATIO + 0.05) * 0.02]), 0.02)
    with pytest.raises(ParameterError, match='n_shapes'):
        ElasticaBeam(n_shapes=9)
