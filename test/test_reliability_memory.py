# SPDX-License-Identifier: Apache-2.0
"""
Memory of writing an ipmc-estimate/1 file does not grow with the record (issue 18).

The writer formats a bounded chunk of rows at a time; before, a list of every row's text
took ~600 B per row (605 MB peak RSS for 1e6 rows in ``ipmc-model estimate``).
"""
import tracemalloc
from types import SimpleNamespace

import numpy as np

from ipmc_sensor_ros.cli.estimate_verb import WRITE_CHUNK_ROWS, _write_estimate, read_estimate


def _peak_writing(tmp_path, rows):
    t = np.arange(rows) / 1000.0
    i = 3e-7 * np.cos(t)
    w = 1e-3 * np.sin(t)
    data = SimpleNamespace(path='in.csv', sample='slim')
    values = {'length_m': 0.022, 'width_m': 0.007, 'thickness_m': 3.6e-4,
              'sample_rate_hz': 1000.0}
    path = tmp_path / f'{rows}.estimate.csv'
    flagged = (np.zeros(rows), 0.011)
    tracemalloc.start()
    _write_estimate(path, data, values, 'h2', None, 0, t, i, w, w, flagged,
                    np.full(rows, 1e-6), False)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    back = read_estimate(path)
    assert np.array_equal(back['deflection_estimate_m'], w)     # exact round trip
    return peak


def test_estimate_writer_memory_is_bounded_by_one_chunk(tmp_path):
    small = _peak_writing(tmp_path, 2 * WRITE_CHUNK_ROWS)
    large = _peak_writing(tmp_path, 8 * WRITE_CHUNK_ROWS)
    # four times the rows, the same peak: one chunk's row texts (~4 floats' repr each,
    # < 600 B per row) plus the list of rows; 10 % slack for allocator rounding
    assert large <= 1.1 * small, (small, large)
    assert small <= 600 * WRITE_CHUNK_ROWS, small
