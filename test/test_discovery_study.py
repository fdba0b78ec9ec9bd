# SPDX-License-Identifier: Apache-2.0
"""
The discovery targets on records made apart from the code, many seeds each (slow).

Records: :func:`bench.discovery_records.scenario` (exact H2 by FFT with a pre-roll, written
from the paper; a sample off the paper's values; hum off 50/60 Hz, offsets, a 16-bit ADC).
Each seed is judged by :func:`bench.seed_study.judge_scenario`, the same rule as the seed
study's table in docs/discovery.md.  Minutes per row: run with ``-m slow``.
"""
import pytest

from bench.discovery_records import scenario
from bench.seed_study import catalog_names, judge_scenario
from ipmc_sensor_ros.workbench.diagnose import diagnose

#: (group, scenario kind, seeds, successes needed): the issue's targets
ROWS = [
    ('hum', 'hum', 10, 9),              # right set named and explained
    ('null_daq', 'null', 20, 20),       # no line, nothing named
    ('offset', 'offset', 10, 9),        # current_offset named
    ('outside', 'high_pass', 10, 9),    # no wrong effect, corner in its interval, plugin
    ('outside', 'lag', 10, 9),          # brings the error to 1.2x the floor
    ('outside', 'resonance', 10, 9),
]


@pytest.mark.slow
@pytest.mark.parametrize('group,kind,n_seeds,need', ROWS)
def test_independent_records_meet_the_targets(group, kind, n_seeds, need, tmp_path):
    results = []
    for seed in range(n_seeds):
        recs, truth, expected = scenario(kind, seed)
        diag = diagnose(recs, candidates=catalog_names())     # not earlier seeds' plugins
        results.append(judge_scenario(kind, recs, truth, expected, diag, tmp_path, seed))
    assert sum(ok for ok, _ in results) >= need, results
