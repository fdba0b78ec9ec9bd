# SPDX-License-Identifier: Apache-2.0
"""
The deflection estimator on drawn records: cases nobody wrote down, judged as the library is.

Each record of :mod:`bench.scenarios.drawn` (its motion, sample and DAQ habits all drawn at
random, generated without package code) is judged by :func:`bench.bench_estimators.judge`:
the live estimate's raw NRMSE after the first second beside the causal Wiener bound, the
smoothed one, +-2 sigma coverage, rows estimated; ``ok`` as there (raw NRMSE <= max(2 x
bound, 1 %) and every row estimated).  One line per record says what was drawn, so a failure
can be rebuilt (``bench.scenarios.drawn.draw(index)``); the summary names the records whose
coverage is below 90 %.  Usage::

    python -m bench.bench_drawn [--first 0] [--count 40] [--duration-s 20] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import sys
import time

from .bench_estimators import _json_safe, judge
from .scenarios.drawn import DRAWN_DURATION_S, draw

__all__ = ['describe', 'main']

NA = 1e-9
#: The +-2 sigma coverage issue 27 asks for is 90-98 %: below, the published std understates
#: the error (a record's failure as much as its NRMSE); above is the priors' floor
#: (docs/benchmarks.md).
COVERAGE_LOW = 0.90


def describe(info: dict) -> str:
    """Return one line saying what a drawn record holds (``draw``'s ``info``)."""
    parts = [info['motion'], info['sample'], f"{info['sample_rate_hz']:g} Hz",
             f"offset {info['offset_a'] / NA:.1f} nA"]
    if 'noise_a' in info:
        parts.append(f"noise {info['noise_a'] / NA:.2f} nA")
    else:
        parts.append(f"noise {100 * info['noise_fraction']:.2g} %")
    if 'offset_drift_a_per_s' in info:
        parts.append(f"drift {60 * info['offset_drift_a_per_s'] / NA:.2f} nA/min")
    if 'mains_hz' in info:
        parts.append(f"hum {info['mains_hz']:.2f} Hz {100 * info['hum_fraction']:.2g} %")
    if info['adc_bits']:
        parts.append(f"{info['adc_bits']} bits")
    if 'stamp_jitter' in info:
        parts.append(f"jitter +-{100 * info['stamp_jitter']:.0f} % ({info['jitter_kind']})")
    if 'drop_fraction' in info:
        parts.append(f"drops {100 * info['drop_fraction']:.2f} % + "
                     f"{info['drop_bursts']} bursts")
    if 'offset_step' in info:
        at, step = info['offset_step']
        parts.append(f'offset step {step / NA:+.1f} nA at {at:.1f} s')
    if info['amplifier_corner_hz']:
        parts.append(f"amplifier {info['amplifier_corner_hz']:.0f} Hz")
    return ', '.join(parts)


def _line(index: int, row: dict, info: dict) -> str:
    rows = f"{row['rows_estimated']}/{row['rows_given']}"
    return (f"{index:5d} {'ok  ' if row['ok'] else 'FAIL'} live {100 * row['nrmse']:8.3f} % "
            f"bound {100 * row['causal_bound']:7.3f} % smoothed "
            f"{100 * row['smoothed_nrmse']:8.3f} % coverage {100 * row['coverage']:5.1f} % "
            f"rows {rows}  {describe(info)}{'  FAULT: ' + row['fault'] if row['fault'] else ''}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog='python -m bench.bench_drawn',
                                 description=__doc__.split('\n\n')[0])
    ap.add_argument('--first', type=int, default=0, help='first record index (any integer)')
    ap.add_argument('--count', type=int, default=40, help='how many records')
    ap.add_argument('--duration-s', type=float, default=DRAWN_DURATION_S,
                    help='length of each record, s')
    ap.add_argument('--json', default=None, help='write every result row to this file')
    args = ap.parse_args(argv)
    if args.count < 1 or not args.duration_s >= 2.0:
        ap.error('--count must be >= 1 and --duration-s >= 2 (the first second is not judged)')
    wall0, results = time.perf_counter(), []
    for index in range(args.first, args.first + args.count):
        record, info = draw(index, args.duration_s)
        row = dict(judge(record)[0], index=index, drawn=describe(info))
        results.append(row)
        print(_line(index, row, info), flush=True)
    passed = sum(bool(r['ok']) for r in results)
    narrow = [r['index'] for r in results if not r['coverage'] >= COVERAGE_LOW]   # NaN too
    which = f" ({', '.join(map(str, narrow))})" if narrow else ''
    print(f'{passed} of {len(results)} drawn records within max(2 x causal bound, 1 %) with '
          f'every row estimated; +-2 sigma coverage below {100 * COVERAGE_LOW:.0f} % on '
          f'{len(narrow)}{which} ({time.perf_counter() - wall0:.0f} s)')
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump({'rows': [{k: _json_safe(v) for k, v in r.items()} for r in results]},
                      f, indent=1)
    return 0


if __name__ == '__main__':
    sys.exit(main())
