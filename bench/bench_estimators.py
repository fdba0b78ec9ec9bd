# SPDX-License-Identifier: Apache-2.0
"""
The deflection estimator judged on the scenario library, beside the physical limits.

Per scenario and seed (records from :mod:`bench.scenarios`, generated without package code),
the estimator runs on the rows the DAQ delivered, in blocks as ``ipmc-model estimate`` feeds
them, with its default configuration and the sensor model the user would have; reported:

* raw NRMSE after the first second (RMS(estimate - truth) / RMS(truth) over the estimated
  rows sampled at t >= 1 s; no level or scale fitted) of the causal estimate, and its ratio
  to the causal Wiener bound (:mod:`bench.bounds`), and on stationary records to the causal
  bound that learns the offset from the record as the estimator must;
* the same for the offline smoothed estimate against the non-causal Wiener bound (a true
  lower bound on stationary records, marked ``*``), where the estimator has a smoother;
* +-2 sigma coverage: the fraction of those rows whose error is within twice the estimator's
  published standard deviation;
* rows estimated / rows given, and CPU time per given row (``time.process_time`` around the
  estimator only);
* ``ok``: raw NRMSE <= max(2 x causal bound, 1 %) and every row estimated (issue 27); the
  bound that learns the offset where there is one (stationary records).

The estimator is reached through ONE adapter, :func:`run_estimator`; nothing else here knows
its API.  Usage::

    python -m bench.bench_estimators [--quick] [--seeds 0-2] [--scenarios crank*,slim-field-lab]
        [--estimators kalman,leaky] [--block-samples 1000] [--json out.json]

``--seeds``: ``N`` (seeds 0..N-1), ``a-b`` or ``a,b,c`` (any integer is a fresh seed).
``--quick``: a few short scenarios, seed 0 (a test runs it; < 60 s).
"""
from __future__ import annotations

import argparse
import fnmatch
import json
import math
import platform
import sys
import time
from dataclasses import dataclass

import numpy as np

from bench.bounds import record_bounds
from bench.scenarios import build, names, QUICK, Record

__all__ = ['Estimate', 'run_estimator', 'estimate_scores', 'judge', 'parse_seeds', 'main']

#: Rows sampled before this are not judged (start-up), s.
AFTER_S = 1.0


@dataclass
class Estimate:
    """
    What an estimator made of a record.

    ``row_index``: the record rows that have an estimate (into ``record.time_s``), with their
    output ``time_s``, ``deflection_m`` and published ``std_m`` (NaN: none); ``cpu_s``:
    process time spent in the estimator; ``fault``: the last exception inside the estimator
    the stream said (its samples dropped, the filter reset), or the first of the smoother
    (its run's live estimate kept): a defect to report, or ''.
    """

    row_index: np.ndarray
    time_s: np.ndarray
    deflection_m: np.ndarray
    std_m: np.ndarray
    rows_given: int
    rows_estimated: int
    cpu_s: float
    fault: str = ''


def run_estimator(record: Record, causal: bool = True, estimator: str = 'kalman',
                  block_samples: int = 1000) -> Estimate | None:
    """
    Run the package's estimator on ``record``'s rows: the one adapter to its API.

    Today's public API: ``DeflectionEstimator(SensorModel.named(...), sample_rate_hz)`` with
    its defaults, behind the stream rules of ``ipmc-model estimate``
    (:class:`~ipmc_sensor_ros.estimation.stream.StreamEstimator`, fed block by block as
    :func:`~ipmc_sensor_ros.estimation.records.estimate_record` does, so the published std of
    each block can be read; ``block_samples`` 1: the node's one-sample path, ``feed_one``).
    ``causal=False``: the offline smoothed estimate, as ``ipmc-model estimate`` makes it.
    """
    from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator
    from ipmc_sensor_ros.physics.model import SensorModel
    from ipmc_sensor_ros.physics.parameters import Geometry

    model = SensorModel.named(record.model, Geometry(*record.geometry_m, record.sample),
                              extra_effects=record.effects)
    est = DeflectionEstimator(model, record.sample_rate_hz, estimator=estimator)
    if not causal:
        return _smoothed(record, est, block_samples)
    return _causal(record, est, block_samples)


def _causal(record: Record, est, block_samples: int) -> Estimate:
    """Return the live estimate: the stream rules, block by block (1: the one-sample path)."""
    from ipmc_sensor_ros.estimation.stream import StreamEstimator

    stream = StreamEstimator(est, max_gap_s=0.1, source=record.name)
    t, i = record.time_s, record.current_a
    index, t_out, w_out, std_out = [], [], [], []
    cpu0 = time.process_time()
    for k in range(0, t.size, block_samples):
        end = min(k + block_samples, t.size)
        if end - k == 1:
            res = stream.feed_one(float(t[k]), float(i[k]))
            if res is not None:
                index.append(np.array([k]))
                t_out.append(np.array([res[0]]))
                w_out.append(np.array([res[1]]))
                std_out.append(np.array([est.std_m]))
            continue
        res = stream.feed(t[k:end], i[k:end])
        if res is None:
            continue
        index.append(k + np.flatnonzero(stream.accepted))      # rows refused one by one
        t_out.append(res[0])
        w_out.append(res[1])
        std_out.append(stream.last_std_m)
    cpu = time.process_time() - cpu0
    cat = (lambda parts, dtype=float: np.concatenate(parts) if parts
           else np.zeros(0, dtype=dtype))
    rows = cat(index, np.int64)
    return Estimate(rows, cat(t_out), cat(w_out), cat(std_out), int(t.size), int(rows.size), cpu,
                    stream.last_fault)


def _smoothed(record: Record, est, block_samples: int) -> Estimate:
    """Return the offline smoothed estimate of the kept rows (as ``ipmc-model estimate``)."""
    from ipmc_sensor_ros.estimation.records import estimate_record, smooth_record

    fresh = est.rebuilt()
    cpu0 = time.process_time()
    _, _, stream = estimate_record(est, record.time_s, record.current_a, max_gap_s=0.1,
                                   block_samples=block_samples, source=record.name)
    rows = np.flatnonzero(stream.kept)
    faults = []
    t_out, w, std = smooth_record(fresh, stream, record.time_s, record.current_a,
                                  warn=faults.append)
    cpu = time.process_time() - cpu0
    return Estimate(rows, t_out, w, std, int(record.time_s.size), int(rows.size), cpu,
                    stream.last_fault or (faults[0] if faults else ''))


def estimate_scores(record: Record, estimate: Estimate | None) -> dict:
    """NRMSE after AFTER_S and +-2 sigma coverage of ``estimate`` (None: NaN)."""
    if estimate is None or estimate.rows_estimated == 0:
        return {'nrmse': math.nan, 'coverage': math.nan}
    truth = record.deflection_m[estimate.row_index]
    judged = record.sample_time_s[estimate.row_index] >= AFTER_S
    err = estimate.deflection_m[judged] - truth[judged]
    nrmse = float(np.sqrt(np.mean(err ** 2)) / np.sqrt(np.mean(truth[judged] ** 2)))
    std = estimate.std_m[judged]
    coverage = float(np.mean(np.abs(err) <= 2 * std)) if np.all(np.isfinite(std)) else math.nan
    return {'nrmse': nrmse, 'coverage': coverage}


def judge(record: Record, estimators=('kalman',), block_samples: int = 1000) -> list[dict]:
    """One result row per estimator for ``record`` (bounds computed once)."""
    bounds = record_bounds(record, after_s=AFTER_S)
    learned = bounds.causal_offset_unknown_nrmse
    judged_by = learned if record.stationary else bounds.causal_nrmse
    rows = []
    for name in estimators:
        live = run_estimator(record, True, name, block_samples)
        smooth = run_estimator(record, False, name, block_samples)
        s_live, s_smooth = estimate_scores(record, live), estimate_scores(record, smooth)
        rows.append({
            'scenario': record.name, 'seed': record.seed, 'class': record.tags[0],
            'estimator': name, 'stationary': record.stationary,
            'nrmse': s_live['nrmse'], 'causal_bound': bounds.causal_nrmse,
            'ratio': s_live['nrmse'] / bounds.causal_nrmse,
            'causal_bound_offset_unknown': learned,
            'ratio_offset_unknown': s_live['nrmse'] / learned,
            'smoothed_nrmse': s_smooth['nrmse'], 'noncausal_bound': bounds.noncausal_nrmse,
            'smoothed_ratio': s_smooth['nrmse'] / bounds.noncausal_nrmse,
            'coverage': s_live['coverage'], 'rows_given': live.rows_given,
            'rows_estimated': live.rows_estimated,
            'cpu_us_per_row': 1e6 * live.cpu_s / max(live.rows_given, 1),
            'fault': live.fault or smooth.fault,
            'ok': bool(s_live['nrmse'] <= max(2 * judged_by, 0.01)
                       and live.rows_estimated == live.rows_given),
        })
    return rows


def parse_seeds(text: str) -> list[int]:
    """'3' -> [0, 1, 2]; '4-6' -> [4, 5, 6]; '0,7,1000' -> [0, 7, 1000]; none is an error."""
    text = text.strip()
    try:
        if ',' in text:
            seeds = [int(s) for s in text.split(',') if s.strip()]
        elif '-' in text:
            first, last = text.split('-', 1)
            seeds = list(range(int(first), int(last) + 1))
        else:
            seeds = list(range(int(text)))
    except ValueError:
        raise SystemExit('--seeds: expected N, a-b or a,b,c (non-negative integers), got '
                         f'{text!r}') from None
    if not seeds:
        raise SystemExit(f'--seeds {text!r} names no seed (N is seeds 0..N-1: seed 0 alone is '
                         '0-0)')
    return seeds


def select_scenarios(patterns: str | None, quick: bool) -> list[str]:
    """Scenario names matching the comma-separated glob ``patterns`` (default: all, or QUICK)."""
    if not patterns:
        return list(QUICK) if quick else names()
    chosen = []
    for pattern in patterns.split(','):
        hits = [n for n in names() if fnmatch.fnmatch(n, pattern.strip())]
        if not hits:
            raise SystemExit(f'--scenarios: no scenario matches {pattern!r}; known: '
                             + ', '.join(names()))
        chosen += [h for h in hits if h not in chosen]
    return chosen


def _pct(values, how=np.mean) -> str:
    v = np.asarray(values, dtype=float)
    return '-' if np.all(np.isnan(v)) else f'{100 * how(v):.3g}'


def _worst(values) -> str:
    v = np.asarray(values, dtype=float)
    return '-' if np.all(np.isnan(v)) else f'{np.nanmax(v):.3g}'


COLUMNS = ('scenario', 'class', 'estimator', 'seeds', 'raw NRMSE % mean / max',
           'causal bound %', 'ratio max', 'offset unknown: bound %', 'ratio max',
           'smoothed %', 'non-causal bound %', 'ratio max',
           '±2σ coverage %', 'rows est/given', 'CPU µs/row', 'ok')


def summary_table(results: list[dict]) -> str:
    """Markdown table, one line per scenario and estimator (mean / worst over seeds)."""
    lines = ['| ' + ' | '.join(COLUMNS) + ' |', '|' + '---|' * len(COLUMNS)]
    groups: dict = {}
    for r in results:
        groups.setdefault((r['scenario'], r['estimator']), []).append(r)
    for (scenario, est), rs in groups.items():
        col = {k: [r[k] for r in rs] for k in rs[0]}
        star = '*' if rs[0]['stationary'] else ''
        cells = (scenario, rs[0]['class'], est, len(rs),
                 f"{_pct(col['nrmse'])} / {_pct(col['nrmse'], np.max)}",
                 _pct(col['causal_bound']), _worst(col['ratio']),
                 _pct(col['causal_bound_offset_unknown']), _worst(col['ratio_offset_unknown']),
                 _pct(col['smoothed_nrmse']),
                 _pct(col['noncausal_bound']) + star, _worst(col['smoothed_ratio']),
                 _pct(col['coverage']), f"{sum(col['rows_estimated'])}/{sum(col['rows_given'])}",
                 f"{np.mean(col['cpu_us_per_row']):.3g}", f"{sum(col['ok'])}/{len(rs)}")
        lines.append('| ' + ' | '.join(str(c) for c in cells) + ' |')
    return '\n'.join(lines)


def _json_safe(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return _json_safe(value.item())
    return value


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog='python -m bench.bench_estimators',
                                 description=__doc__.split('\n\n')[0])
    ap.add_argument('--seeds', default=None, help='N, a-b or a,b,c (default 3; --quick: 1)')
    ap.add_argument('--scenarios', default=None, help='comma-separated names or globs')
    ap.add_argument('--quick', action='store_true', help='a few short scenarios, seed 0')
    ap.add_argument('--estimators', default='kalman', help='comma-separated: kalman, leaky')
    ap.add_argument('--block-samples', type=int, default=1000,
                    help='rows per block fed to the estimator (1: one-sample path)')
    ap.add_argument('--json', default=None, help='write every result row to this file')
    args = ap.parse_args(argv)
    seeds = parse_seeds(args.seeds or ('1' if args.quick else '3'))
    scenarios = select_scenarios(args.scenarios, args.quick)
    estimators = tuple(e.strip() for e in args.estimators.split(',') if e.strip())
    wall0 = time.perf_counter()
    results = []
    for name in scenarios:
        for seed in seeds:
            results += judge(build(name, seed), estimators, args.block_samples)
            print(f'{name} seed {seed}: done ({time.perf_counter() - wall0:.0f} s)',
                  file=sys.stderr, flush=True)
    print(f'machine: {platform.machine()} python {platform.python_version()}; seeds {seeds}; '
          f'{time.perf_counter() - wall0:.0f} s; * = stationary record (the non-causal bound '
          'is a true lower bound)')
    print(summary_table(results))
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump({'seeds': seeds, 'after_s': AFTER_S,
                       'rows': [{k: _json_safe(v) for k, v in r.items()} for r in results]},
                      f, indent=1)
    return 0


def bench_scenarios(smoke: bool = False) -> list[dict]:
    """Rows for ``bench/run.py``: the worst ratio to the causal bound over the quick set."""
    chosen = QUICK[:2] if smoke else QUICK
    results = [r for name in chosen for r in judge(build(name, 0))]
    worst = max(results, key=lambda r: r['ratio'])
    label = f"{len(chosen)} scenarios, worst: {worst['scenario']}"
    return [{'benchmark': f'estimator raw NRMSE / causal Wiener bound ({label})',
             'value': 100 * worst['nrmse'], 'unit': '% NRMSE', 'ratio': worst['ratio'],
             'baseline': 'causal Wiener bound, same record', 'target': '<= 2 (or <= 1 %)'}]


if __name__ == '__main__':
    sys.exit(main())
