# SPDX-License-Identifier: Apache-2.0
"""
Time and peak memory of reading (and writing) a large ipmc-timeseries/1 file.

Issue #18 (defect 11): a 5e6-row file took 65 s and 3.1 GB.  Usage:
``python -m bench.bench_read [ROWS] [--write]`` (default 5e6 rows: 1 kHz, three
columns).  Each step runs in its own process and reports its wall time and its
peak resident memory (``VmHWM``, which unlike ``ru_maxrss`` is not inherited
from the parent).  Without ``--write`` the file is made with ``numpy.savetxt``
(``%.17g``); with it, by :func:`write_timeseries` (shortest repr, read back
before it is moved in place).

``python -m bench.bench_read --verbs [ROWS,ROWS,...]`` runs the whole ``ipmc-model estimate``
and ``ipmc-model compare`` on files of 1e6, 2e6 and 5e6 rows (or the rows given), one process
at a time, and prints each one's seconds and peak RSS (MiB) with the time per row relative to
the smallest file (1.00 = linear).  Target (issue 18): peak <= 500 MB at 5e6 rows, time
linear in the rows.  Measured figures: README, "Memory of ``estimate`` / ``compare``".
"""
from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

PEAK = ("def peak():\n    for line in open('/proc/self/status'):\n"
        "        if line.startswith('VmHWM'):\n            return int(line.split()[1]) / 1024\n")
MAKE = PEAK + """
import sys, time
import numpy as np
rows, path, write = int(sys.argv[1]), sys.argv[2], sys.argv[3] == '1'
t = np.arange(rows) / 1000.0
w = 1e-3 * np.sin(2 * np.pi * 5 * t)
i = 3e-7 * np.cos(2 * np.pi * 5 * t) + 6e-9 * np.random.default_rng(0).standard_normal(rows)
if write:
    from ipmc_sensor_ros.physics.parameters import PAPER_SAMPLES
    from ipmc_sensor_ros.workbench.io import TimeSeries, write_timeseries
    ts = TimeSeries('', 'slim', PAPER_SAMPLES['slim'], {}, 1000.0, t, i, w)
    del t, w, i
    before = peak()
    t0 = time.perf_counter()
    write_timeseries(path, ts)
    print(f'write_timeseries {rows} rows: {time.perf_counter() - t0:.1f} s (incl. read-back '
          f'check), peak RSS {peak():.0f} MB ({before:.0f} MB before: the series itself)')
else:
    with open(path, 'w') as f:
        f.write('# format: ipmc-timeseries/1\\n# length_m: 0.022\\n# width_m: 0.007\\n'
                '# thickness_m: 0.00036\\ntime_s,deflection_m,current_A\\n')
        np.savetxt(f, np.column_stack([t, w, i]), fmt='%.17g', delimiter=',')
"""
READ = PEAK + """
import sys, time
from ipmc_sensor_ros.workbench.io import read_any
base = peak()
t0 = time.perf_counter()
ts = read_any(sys.argv[1])
print(f'read {ts.n_samples} rows: {time.perf_counter() - t0:.1f} s, peak RSS {peak():.0f} MB '
      f'(after imports {base:.0f} MB)')
"""

VERB = PEAK + """
import contextlib, io, sys, time
from ipmc_sensor_ros.cli.main import main
base = peak()
t0 = time.perf_counter()
with contextlib.redirect_stdout(io.StringIO()):
    code = main(sys.argv[1:])
print(f'RESULT {code} {time.perf_counter() - t0:.3f} {peak():.1f} {base:.1f}')
"""


def _make(rows: int, path: Path, write: bool = False) -> None:
    subprocess.run([sys.executable, '-c', MAKE, str(rows), str(path), '1' if write else '0'],
                   check=True)


def _verb(verb: str, path: Path, tmp: str) -> tuple[float, float, float]:
    """Return (seconds, peak RSS MiB, RSS after imports MiB) of one ``ipmc-model`` run."""
    extra = ['--out', tmp] if verb == 'estimate' else []
    res = subprocess.run([sys.executable, '-c', VERB, verb, str(path), *extra],
                         check=True, capture_output=True, text=True)
    line = next(x for x in res.stdout.splitlines() if x.startswith('RESULT '))
    code, seconds, peak, base = line.split()[1:]
    if code != '0':
        raise SystemExit(f'ipmc-model {verb} {path}: exit {code}\n{res.stderr}')
    return float(seconds), float(peak), float(base)


def verbs(rows_list: list[int]) -> None:
    """Print seconds and peak RSS of ``estimate`` and ``compare`` for each file length."""
    results = {}
    for rows in rows_list:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / 'big.csv'
            _make(rows, path)
            for verb in ('estimate', 'compare'):
                results[verb, rows] = _verb(verb, path, tmp)
                seconds, peak, base = results[verb, rows]
                print(f'{verb:8s} {rows:>9d} rows: {seconds:7.1f} s, peak RSS {peak:5.0f} MiB '
                      f'(after imports {base:.0f} MiB)', flush=True)
    first = rows_list[0]
    for verb in ('estimate', 'compare'):
        per_row = [results[verb, r][0] / r for r in rows_list]
        ratios = ', '.join(f'{r:g}: {p / per_row[0]:.2f}' for r, p in zip(rows_list, per_row))
        print(f'{verb}: time per row relative to {first:g} rows (1.00 = linear): {ratios}')


def main(argv: list[str]) -> None:
    if '--verbs' in argv:
        given = [a for a in argv if not a.startswith('-')]
        verbs([int(float(r)) for r in given[0].split(',')] if given
              else [1_000_000, 2_000_000, 5_000_000])
        return
    rows = int(float(argv[0])) if argv and not argv[0].startswith('-') else 5_000_000
    write = '--write' in argv
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / 'big.csv'
        _make(rows, path, write)
        print(f'file {path.stat().st_size / 1e6:.0f} MB')
        subprocess.run([sys.executable, '-c', READ, str(path)], check=True)


if __name__ == '__main__':
    main(sys.argv[1:])
