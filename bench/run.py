# SPDX-License-Identifier: Apache-2.0
"""
Run every benchmark and print one table: ``python -m bench.run [--smoke]``.

``--smoke`` runs each benchmark on tiny inputs (what CI does): it checks that
they run, not how fast.
"""
from __future__ import annotations

import argparse
import platform
import sys

from bench import (bench_arrays, bench_batch, bench_core, bench_estimators, bench_nodes,
                   bench_workbench)

SUITES = [bench_core.bench_estimator, bench_core.bench_model, bench_core.bench_field,
          bench_workbench.bench_workbench, bench_batch.bench_batch,
          bench_nodes.bench_nodes, bench_arrays.bench_arrays, bench_estimators.bench_scenarios]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument('--smoke', action='store_true')
    args = ap.parse_args(argv)
    print(
        f"machine: {platform.machine()} {platform.processor() or ''} "
        f'python {platform.python_version()}'
        f" cores={__import__('os').cpu_count()}"
    )
    print('| benchmark | value | unit | ratio | baseline | target |')
    print('|---|---|---|---|---|---|', flush=True)
    for suite in SUITES:          # rows are printed as each suite finishes
        for r in suite(smoke=args.smoke):
            print(f"| {r['benchmark']} | {r['value']:.3g} | {r['unit']} | {r['ratio']:.3g} | "
                  f"{r['baseline']} | {r['target']} |", flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
