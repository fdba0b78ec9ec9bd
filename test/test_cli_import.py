# SPDX-License-Identifier: Apache-2.0
"""
The eight-step import of a lab export (issue #16) is one command, and every verb reads the result.

Four dialects of the same recording import to the same SI record.
"""
from pathlib import Path

import numpy as np
import pytest

from ipmc_sensor_ros.cli import main
from ipmc_sensor_ros.workbench.io import read_any

LAB = Path(__file__).resolve().parent / 'data' / 'lab'
DIALECTS = {'labview_slim_5Hz.csv': [], 'daq_slim_5Hz.tsv': [], 'tabelle_slim_5Hz.txt': [],
            'tia_slim_5Hz.csv': ['--current-gain', '1e6']}


@pytest.fixture(scope='module')
def imported(tmp_path_factory):
    out = tmp_path_factory.mktemp('imported')
    for name, extra in DIALECTS.items():
        assert main(['import', str(LAB / name), '--meta', str(LAB / 'run.json'),
                     '--out', str(out), *extra]) == 0
    return out


def test_every_dialect_imports_to_the_same_si_record(imported):
    records = [read_any(imported / (Path(n).stem + '.csv')) for n in DIALECTS]
    ref = records[0]
    assert ref.geometry.length_m == pytest.approx(
        0.022
    ) and ref.geometry.thickness_m == pytest.approx(360e-6)
    # the recording: 0.8 mm peak at 5 Hz, ~0.3 uA current with a 40 nA offset
    assert np.max(np.abs(ref.deflection_m)) == pytest.approx(0.8e-3, rel=0.01)
    assert 2e-7 < np.max(np.abs(ref.current_a)) < 5e-7
    for r in records[1:]:
        assert r.time_s.size == ref.time_s.size
        # dialects round differently (0.01 um, 1e-5 uA of the exports): compare to that
        assert np.allclose(r.deflection_m, ref.deflection_m, atol=2e-8)
        assert np.allclose(r.current_a, ref.current_a, atol=2e-11)


def test_verbs_read_the_imported_directory_and_skip_current_only_files(imported, capsys):
    assert main(['import', str(LAB / 'field_current_only.csv'), '--meta', str(LAB / 'run.json'),
                 '--out', str(imported)]) == 0
    capsys.readouterr()
    assert main(['compare', str(imported), '--model', 'h2']) == 0
    captured = capsys.readouterr()
    assert 'field_current_only' in captured.err and 'skip' in captured.err.lower()
