# SPDX-License-Identifier: Apache-2.0
"""The reduce/eq55 verbs and a smoke run of every benchmark (no timing assertions)."""
import json
import subprocess
import sys
from pathlib import Path

from ipmc_sensor_ros.cli.main import main

ROOT = Path(__file__).resolve().parents[1]


def test_reduce_table_json(tmp_path, capsys):
    out = tmp_path / 't.json'
    assert main(['reduce', '--orders', '3-4', '--samples', 'short', '--json', str(out)]) == 0
    rows = json.loads(out.read_text())['rows']
    assert [r['order'] for r in rows] == [3, 4]
    assert rows[1]['max_mag_error_db'] < 0.1
    assert 'short' in capsys.readouterr().out


def test_eq55_verb_reports_unstable_inverse(capsys):
    assert main(['eq55', '--samples', 'slim']) == 0
    assert 'UNSTABLE' in capsys.readouterr().out


def test_bad_sample_is_a_clear_error(capsys):
    assert main(['reduce', '--samples', 'nope']) == 2
    assert 'nope' in capsys.readouterr().err


def test_benchmarks_smoke():
    res = subprocess.run([sys.executable, '-m', 'bench.run', '--smoke'], cwd=ROOT,
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    assert 'estimator block' in res.stdout and '| benchmark |' in res.stdout


def test_effect_catalog_doc_is_in_sync():
    """docs/effects.md is the catalog's one place of documentation: it must match the code."""
    from ipmc_sensor_ros.physics.effects import catalog_markdown

    doc = (ROOT / 'docs' / 'effects.md').read_text()
    assert catalog_markdown().strip() in doc


def test_bench_sink_reads_rows_and_last_time_from_the_serialised_block():
    """The node benchmark's raw sink must count what a deserialising subscriber would."""
    import numpy as np
    from rclpy.serialization import serialize_message

    from bench.node_harness import block_rows_and_last_time
    from ipmc_sensor_ros.interface.blocks import estimate_columns
    from ipmc_sensor_ros.nodes.messages import BlockPacker, pack_block

    t = 1234.5 + np.arange(7) / 1000.0
    assert block_rows_and_last_time(serialize_message(pack_block(t, np.sin(t)))) == (7, t[-1])
    for rows in (1, 3):        # the estimator's 4 columns (odd labels and padding)
        msg = BlockPacker(estimate_columns(1)).pack(t[:rows], t[:rows] * 2, t[:rows] * 3,
                                                    0.0 * t[:rows])
        assert block_rows_and_last_time(serialize_message(msg)) == (rows, t[rows - 1])
