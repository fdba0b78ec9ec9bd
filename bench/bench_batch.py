# SPDX-License-Identifier: Apache-2.0
"""
``ipmc-model estimate`` on a directory of many small files: the cost per file.

Usage: ``python -m bench.bench_batch [FILES] [ROWS]`` (default 500 files of 100 rows at
1 kHz).  The whole command runs in a child process, as a user runs it; the baseline, in the
same harness, is the same command on one file of the same size (start-up, imports and one
estimator build), so the ratio says what each further file costs.  Target (issue 30): 500
files of 100 rows in <= 30 s on the two-core machine.  Measured figures: docs/reliability.md.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
HEADER = ('# format: ipmc-timeseries/1\n# sample: slim\n# length_m: 0.022\n# width_m: 0.007\n'
          '# thickness_m: 0.00036\n# sample_rate_hz: 1000.0\ntime_s,current_A\n')


def make_files(folder: Path, files: int, rows: int) -> None:
    """Write ``files`` records of ``rows`` rows of 10 nA white current."""
    folder.mkdir(parents=True)
    rng = np.random.default_rng(0)
    t = np.arange(rows) / 1000.0
    for k in range(files):
        i = rng.normal(0, 1e-8, rows)
        body = ''.join(f'{a!r},{b!r}\n' for a, b in zip(t.tolist(), i.tolist()))
        (folder / f'r{k}.csv').write_text(HEADER + body)


def run_estimate(data: Path, out: Path) -> float:
    """Wall time of ``ipmc-model estimate DATA --out OUT`` in a child process, s."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    start = time.perf_counter()
    subprocess.run([sys.executable, '-m', 'ipmc_sensor_ros.cli', 'estimate', str(data),
                    '--out', str(out)], env=env, check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    return time.perf_counter() - start


def bench_batch(smoke: bool = False, files: int = 500, rows: int = 100) -> list[dict]:
    """Rows of the benchmark table (``bench.run``)."""
    files = 5 if smoke else files
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        make_files(tmp / 'many', files, rows)
        make_files(tmp / 'one', 1, rows)
        one = run_estimate(tmp / 'one', tmp / 'o1')
        many = run_estimate(tmp / 'many', tmp / 'on')
    return [{'benchmark': f'estimate: {files} files of {rows} rows', 'value': many,
             'unit': 's', 'ratio': many / one, 'baseline': f'one file: {one:.2f} s',
             'target': '<= 30 s for 500 files'}]


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    files = int(argv[0]) if argv else 500
    rows = int(argv[1]) if len(argv) > 1 else 100
    for r in bench_batch(files=files, rows=rows):
        print(f"{r['benchmark']}: {r['value']:.1f} s ({r['ratio']:.1f}x one file: "
              f"{r['baseline']}; target {r['target']})")
    return 0


if __name__ == '__main__':
    sys.exit(main())
