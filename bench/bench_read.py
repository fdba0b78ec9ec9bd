# SPDX-License-Identifier: Apache-2.0
"""
Time and peak memory of reading (and writing) a large ipmc-timeseries/1 file.

Issue #18 (defect 11): a 5e6-row file took 65 s and 3.1 GB.  Usage:
``python -m bench.bench_read [ROWS] [--write]`` (default 5e6 rows: 1 kHz, three
columns).  Each step runs in its own process and reports its wall time and its
peak resident memory (``VmHWM``, which unlike ``ru_maxrss`` is not inherited
from the parent).  Without ``--write`` the file is made with ``numpy.savetxt``
(``%.17g``); with it, by :func:`write_timeseries` (shortest repr, read back
before it is moved in place).  Target: read peak <= 500 MB, time linear in ROWS.
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


def main(argv: list[str]) -> None:
    rows = int(float(argv[0])) if argv and not argv[0].startswith('-') else 5_000_000
    write = '--write' in argv
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / 'big.csv'
        subprocess.run([sys.executable, '-c', MAKE, str(rows), str(path), '1' if write else '0'],
                       check=True)
        print(f'file {path.stat().st_size / 1e6:.0f} MB')
        subprocess.run([sys.executable, '-c', READ, str(path)], check=True)


if __name__ == '__main__':
    main(sys.argv[1:])
