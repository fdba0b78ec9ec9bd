"""Time and peak memory of reading a large ipmc-timeseries/1 file (issue #18 defect 11).

Usage: ``python -m bench.bench_read [ROWS] [--write]`` writes a ROWS-row file
(default 5e6; 1 kHz, 3 columns in repr precision) to a temporary directory,
then reads it in a fresh child process and prints wall time and peak RSS
(``ru_maxrss``) of the read alone.  ``--write`` also times write_timeseries
(which reads its output back before moving it in place).  Target: peak RSS
<= 500 MB and time linear in ROWS.
"""
from __future__ import annotations

import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

CHILD = """
import resource, sys, time
from ipmc_sensor_ros.workbench.io import read_any
t0 = time.perf_counter()
ts = read_any(sys.argv[1])
dt = time.perf_counter() - t0
rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(f"read {ts.n_samples} rows in {dt:.2f} s, peak RSS {rss:.0f} MB")
"""


def main(argv: list[str]) -> None:
    rows = int(float(argv[0])) if argv and not argv[0].startswith("-") else 5_000_000
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "big.csv"
        t = np.arange(rows) / 1000.0
        rng = np.random.default_rng(0)
        w = 1e-3 * np.sin(2 * np.pi * 5 * t)
        i = 3e-7 * np.cos(2 * np.pi * 5 * t) + 6e-9 * rng.standard_normal(rows)
        if "--write" in argv:
            from ipmc_sensor_ros.physics.parameters import PAPER_SAMPLES
            from ipmc_sensor_ros.workbench.io import TimeSeries, write_timeseries

            ts = TimeSeries("", "slim", PAPER_SAMPLES["slim"], {}, 1000.0, t, i, w)
            t0 = time.perf_counter()
            write_timeseries(path, ts)
            rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
            print(f"write_timeseries {rows} rows in {time.perf_counter() - t0:.2f} s "
                  f"(incl. read-back check), peak RSS {rss:.0f} MB")
        else:
            with open(path, "w") as f:
                f.write("# format: ipmc-timeseries/1\n# length_m: 0.022\n# width_m: 0.007\n"
                        "# thickness_m: 0.00036\ntime_s,deflection_m,current_A\n")
                np.savetxt(f, np.column_stack([t, w, i]), fmt="%.17g", delimiter=",")
        print(f"file {path.stat().st_size / 1e6:.0f} MB")
        subprocess.run([sys.executable, "-c", CHILD, str(path)], check=True)


if __name__ == "__main__":
    main(sys.argv[1:])
