# SPDX-License-Identifier: Apache-2.0
"""Line measurements of the estimator (estimation/lines.py): their edge cases."""
import numpy as np

from ipmc_sensor_ros.estimation.lines import measure_line, vertex


def test_the_vertex_stays_within_half_a_bin_on_a_flank():
    """
    The largest bin inside a range whose outer neighbour is larger still (a flank).

    The parabola through (1, 4, 6.9) peaks 29.5 bins away; the vertex is clipped to half a
    bin (a quantised DAQ at rest gave such a flank, and the peak index fell off the array).
    """
    summed = np.array([0.0, 1.0, 4.0, 6.9])
    assert vertex(np.arange(4), summed, 2) == 2.5
    assert vertex(np.arange(4), np.array([0.0, 3.0, 4.0, 3.0]), 2) == 2.0


def test_a_quantised_still_record_has_no_line():
    """A 16-bit DAQ reading a still sensor: a few codes of noise, no hum, no line."""
    lsb = 20e-6 / 2 ** 16
    rng = np.random.default_rng(0)
    codes = np.round(0.4 * rng.standard_normal(4000))
    assert measure_line(codes * lsb, 1000.0) == (0.0, 0.0)
