# SPDX-License-Identifier: Apache-2.0
"""
The node's fixed-lag smoothed output (``smoothed_lag_s``) on the scenario library.

Per scenario (seed 0 unless ``--seeds``), raw NRMSE after the first second, as
:mod:`bench.bench_estimators` scores it, of: the live filter (lag 0), the fixed-lag output at
each ``--lags`` (what ``deflection/smoothed/block`` carries), and the offline fixed-interval
smoother (``ipmc-model estimate``); with the CPU time per row of each live run.  The stream
core is fed in blocks as the node is; the lagged output is collected as the node publishes it
(after each block) and what is still held at the end is flushed.  Usage::

    python -m bench.bench_fixed_lag [--scenarios crank-5hz-slim-pct-rest,...] [--lags 0.05,0.2,1]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from bench.bench_estimators import Estimate, estimate_scores, parse_seeds, run_estimator
from bench.scenarios import build, QUICK, Record

__all__ = ['run_lagged', 'main']


def run_lagged(record: Record, lag_s: float, block_samples: int = 1000) -> Estimate:
    """Return the live (lag 0) or fixed-lag output of the default Kalman estimator."""
    from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator
    from ipmc_sensor_ros.estimation.stream import StreamEstimator
    from ipmc_sensor_ros.physics.model import SensorModel
    from ipmc_sensor_ros.physics.parameters import Geometry

    model = SensorModel.named(record.model, Geometry(*record.geometry_m, record.sample),
                              extra_effects=record.effects)
    stream = StreamEstimator(DeflectionEstimator(model, record.sample_rate_hz,
                                                 smoothed_lag_s=lag_s), max_gap_s=0.1)
    t, i = record.time_s, record.current_a
    rows, outs = [], []
    cpu0 = time.process_time()
    for k in range(0, t.size, block_samples):
        res = stream.feed(t[k:k + block_samples], i[k:k + block_samples])
        if res is not None:
            rows.append(k + np.flatnonzero(stream.accepted))
            live = (res[0], res[1], stream.last_std_m)
            outs.append(stream.pop_smoothed() if lag_s else live)
    if lag_s:
        outs.append(stream.estimator.pop_smoothed(flush=True))
    cpu = time.process_time() - cpu0
    t_out, w, std = (np.concatenate(p) for p in zip(*(o for o in outs if o is not None)))
    index = np.concatenate(rows)
    return Estimate(index, t_out, w, std, int(t.size), int(index.size), cpu)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog='python -m bench.bench_fixed_lag',
                                 description=__doc__.split('\n\n')[0])
    ap.add_argument('--scenarios', default=','.join(QUICK), help='comma-separated names')
    ap.add_argument('--lags', default='0.05,0.2,1', help='smoothed_lag_s values, s')
    ap.add_argument('--seeds', default='1', help='N, a-b or a,b,c')
    args = ap.parse_args(argv)
    lags = [float(x) for x in args.lags.split(',')]
    print('| scenario | seed | live | ' + ' | '.join(f'lag {g:g} s' for g in lags)
          + ' | fixed-interval | CPU live / lagged, µs per row |')
    print('|---' * (len(lags) + 5) + '|')
    for name in args.scenarios.split(','):
        for seed in parse_seeds(args.seeds):
            rec = build(name.strip(), seed)
            runs = [run_lagged(rec, lag) for lag in [0.0] + lags]
            whole = run_estimator(rec, causal=False)
            cells = [f"{100 * estimate_scores(rec, r)['nrmse']:.2f} %" for r in runs + [whole]]
            cpu = [1e6 * r.cpu_s / r.rows_given for r in runs]
            print(f'| {name} | {seed} | ' + ' | '.join(cells)
                  + f' | {cpu[0]:.0f} / {max(cpu[1:]):.0f} |', flush=True)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
