# SPDX-License-Identifier: Apache-2.0
"""
Node benchmarks: the estimator node against a pass-through node, and the simulator.

Sustained input rate without loss, added latency and CPU of the estimator node against a
pass-through node (raw subscription, publish of the same bytes) in the same harness
(:mod:`bench.node_harness`: driver, node under test and sink in three processes, each
trial in fresh processes), and the simulator's real-time factor.  A rate is *sustained*
when every sample sent arrives.  Run: ``python -m bench.run`` (full: ladder of rates, 10 s
each, the best loss-free one confirmed for 60 s) or ``--smoke``; the node rows alone:
``python -m bench.bench_nodes [--one-sample] [--smoke] [--two-process] [--estimator-cost]``.
"""
from __future__ import annotations

import random
import sys
import time

from bench.node_harness import node_in_process, run_trial_in_process

__all__ = ['bench_nodes', 'bench_node_cpu', 'bench_estimator_cost', 'bench_node_rate_two_process',
           'bench_simulator_rtf']


def bench_node_cpu(smoke: bool = False) -> list[dict]:
    """
    CPU per message of each node under the same driver at a fixed rate.

    Whole process: executor, DDS threads, callback; each node in a fresh process: a steadier
    comparison than the sustained rate, which three processes sharing two cores make noisy.
    """
    rows = []
    for n, rate in ((1, 4000.0), (1000, 500.0)):
        cost = _cpu_per_message(('passthrough', 'leaky'), n, rate, 1.0 if smoke else 8.0)
        rows.append({'benchmark': f'node CPU per message, {n}-sample messages at {rate:.0f} msg/s '
                                  '(process CPU / messages handled)',
                     'value': cost['leaky'], 'unit': 'us/msg',
                     'baseline': f"pass-through {cost['passthrough']:.0f} us/msg",
                     'ratio': cost['leaky'] / cost['passthrough'], 'target': '-'})
    return rows


def bench_estimator_cost(smoke: bool = False) -> list[dict]:
    """
    Node CPU per message with ``estimator: kalman`` against the bytes pass-through and ``leaky``.

    The same harness as :func:`bench_node_cpu` (driver and node, whole-process CPU per message
    handled), one fresh process per node, at a robot DAQ's 1 kHz in 1- and 100-sample
    messages, at 4000 one-sample messages/s and at 10 kHz in 1000-sample messages.  Issue 27
    asks the one-sample node to sustain 0.75 x the pass-through's rate: where the node is
    CPU-bound that is a CPU ratio to the pass-through of at most 1 / 0.75 = 1.33.
    """
    rows = []
    for n, rate in ((1, 1000.0), (1, 4000.0), (100, 10.0), (1000, 10.0)):
        cost = _cpu_per_message(('passthrough', 'leaky', 'kalman'), n, rate,
                                1.0 if smoke else 10.0)
        rows.append({'benchmark': f'estimator node CPU per message, kalman, {n}-sample messages '
                                  f'at {rate:.0f} msg/s ({n * rate:.0f} samples/s)',
                     'value': cost['kalman'], 'unit': 'us/msg',
                     'baseline': f"pass-through {cost['passthrough']:.0f} us/msg, leaky "
                                 f"{cost['leaky']:.0f} us/msg",
                     'ratio': cost['kalman'] / cost['passthrough'],
                     'target': '<= 1.33' if n == 1 else '-'})
    return rows


def _cpu_per_message(kinds, n: int, rate: float, duration: float) -> dict:
    """Whole-process CPU per handled message (us) of each kind of node, a fresh process each."""
    cost = {}
    for kind in kinds:
        r = node_in_process(kind, rate, n, duration)
        cost[kind] = r['cpu_s'] / r['handled'] * 1e6 if r['handled'] else float('nan')
    return cost


def bench_node_rate_two_process(smoke: bool = False, duration: float = 10.0) -> dict:
    """
    Sustained one-sample rate of each node with the driver alone (no sink process).

    The three-process harness shares two cores between driver, node and sink, so it bounds
    the ladder before a node does; here the node counts what it handled (the estimator: its
    ``messages_in``) and a rate passes when it handled every message the driver sent at the
    rate asked.  The node's output has no subscriber, so its publishing is cheaper than in
    use: both nodes alike.
    """
    best = {}
    for kind in ('passthrough', 'leaky'):       # the leaky, as the rows were first measured
        best[kind] = 0.0
        for rate in ([4000.0] if smoke else [4000.0, 6000.0, 8000.0, 10000.0, 12000.0,
                                             14000.0, 16000.0, 18000.0, 20000.0, 22500.0]):
            r = node_in_process(kind, rate, 1, 1.0 if smoke else duration)
            ok = r['sent'] > 0 and r['handled_all'] == r['sent'] \
                and r['achieved_msg_s'] >= 0.97 * rate
            print(f"  two-process {kind:11s} {rate:8.0f} msg/s: sent {r['sent']}, handled "
                  f"{r['handled_all']}, {r['cpu_s'] / max(r['handled'], 1) * 1e6:.0f} us/msg "
                  f"-> {'pass' if ok else 'FAIL'}", file=sys.stderr, flush=True)
            if not ok:
                break
            best[kind] = rate
    p, e = best['passthrough'], best['leaky']
    return {'benchmark': 'estimator node sustained rate, 1-sample messages, driver and node '
                         f'only ({duration:.0f} s per rung, node counts)',
            'value': e, 'unit': 'msg/s', 'baseline': f'pass-through same harness: {p:.0f} msg/s',
            'ratio': e / p if p else float('nan'), 'target': '>= 0.9; >= 22500 msg/s'}


def _ladder(n: int) -> list[float]:
    if n == 1:
        return [1000.0, 2000.0, 4000.0, 6000.0, 8000.0, 10000.0, 12000.0, 16000.0, 20000.0,
                24000.0, 28000.0, 32000.0]
    # 1000 msg/s x 1000 samples = 1 MHz, the top of the estimator's sample_rate_hz range
    # (float64 stamps cannot carry shorter periods); the pass-through is held to the same ladder
    return [20.0, 50.0, 100.0, 200.0, 500.0, 1000.0]


def _ok(r: dict) -> bool:
    """
    Tell whether a trial passes.

    It passes when nothing was lost and the driver achieved the requested rate.
    """
    print(f"  node trial {r['kind']:11s} {r['n']:5d}-sample msgs at {r['rate_msg_s']:8.0f} msg/s: "
          f"sent {r['sent']}, received {r['received']}, achieved {r.get('achieved_msg_s', 0):.0f} "
          f"msg/s, node CPU {r.get('node_cpu_fraction', float('nan')):.0%} "
          f"-> {'pass' if r['lossless'] and r.get('driver_kept_up') else 'FAIL'}",
          file=sys.stderr, flush=True)
    return bool(r['lossless'] and r.get('driver_kept_up'))


def _best_trial(kind: str, n: int, smoke: bool) -> dict | None:
    """
    Return the trial of the highest sustained rate of a node, or None when none passed.

    The ladder of rates, 10 s each, one bisection step between the last rung passed and the
    first failed, then the best confirmed for 60 s (stepping down if needed); ``smoke``:
    one 1 s trial at the lowest rung.
    """
    if smoke:
        return run_trial_in_process(kind, _ladder(n)[0], n, 1.0)
    passed, failed = [], None
    for rate in _ladder(n):
        if not _ok(run_trial_in_process(kind, rate, n, 10.0)):
            failed = rate
            break
        passed.append(rate)
    if passed and failed is not None:   # one bisection step between the rungs
        mid = round((passed[-1] + failed) / 2.0)
        if _ok(run_trial_in_process(kind, mid, n, 10.0)):
            passed.append(mid)
    for rate in reversed(passed[-3:]):   # confirm for 60 s, stepping down if needed
        r = run_trial_in_process(kind, rate, n, 60.0)
        if _ok(r):
            return r
    return None


def _size_rows(n: int, p: dict | None, e: dict | None, smoke: bool) -> list[dict]:
    """Rate, latency and CPU rows of ``n``-sample messages from the best trials of each node."""
    if p is None or e is None:
        return [
            {
                'benchmark': f'node rate, {n}-sample messages',
                'value': float('nan'),
                'unit': 'samples/s',
                'baseline': 'pass-through node',
                'ratio': float('nan'),
                'target': '>= 0.9',
            }
        ]
    rate_e = e['rate_msg_s'] * n if e['lossless'] else 0.0
    rate_p = p['rate_msg_s'] * n if p['lossless'] else 0.0
    # latency and CPU are compared at the same message rate: the estimator's
    same = (
        p
        if p['rate_msg_s'] == e['rate_msg_s']
        else run_trial_in_process('passthrough', e['rate_msg_s'], n, 1.0 if smoke else 10.0)
    )
    _ok(same)
    return [
        {'benchmark': f'estimator node sustained rate, {n}-sample messages'
                      + (' (smoke)' if smoke else ', 60 s without loss'),
         'value': rate_e, 'unit': 'samples/s',
         'baseline': f'pass-through node same harness: {rate_p:.0f} samples/s',
         'ratio': rate_e / rate_p if rate_p else float('nan'), 'target': '>= 0.9'},
        {'benchmark': f'estimator node added latency, {n}-sample messages at '
                      f"{e['rate_msg_s']:.0f} msg/s (median; ratio column: added p99)",
         'value': e['latency_median_ms'] - same['latency_median_ms'], 'unit': 'ms',
         'baseline': f"pass-through same rate {same['latency_median_ms']:.2f} / "
                     f"{same['latency_p99_ms']:.2f} ms",
         'ratio': (e['latency_p99_ms'] - same['latency_p99_ms']), 'target': '-'},
        {
            'benchmark': f'estimator node CPU, {n}-sample messages at '
            f"{e['rate_msg_s']:.0f} msg/s",
            'value': 100.0 * e.get('node_cpu_fraction', float('nan')),
            'unit': '% of a core',
            'baseline': 'pass-through same rate '
            f"{100.0 * same.get('node_cpu_fraction', float('nan')):.0f} %",
            'ratio': e.get('node_cpu_fraction', float('nan'))
            / same.get('node_cpu_fraction', float('nan')),
            'target': '-',
        },
    ]


def bench_nodes(smoke: bool = False, sizes=(1, 1000), extras: bool = True) -> list[dict]:
    """
    Sustained lossless rate, latency and CPU of the estimator node against a pass-through.

    ``sizes``: samples per message to bench; ``extras``: also the CPU-per-message rows and
    the simulator's real-time factor.
    """
    rows = []
    for n in sizes:
        results = {kind: _best_trial(kind, n, smoke) for kind in ('passthrough', 'estimator')}
        rows.extend(_size_rows(n, results['passthrough'], results['estimator'], smoke))
    if extras:
        rows.append(bench_node_rate_two_process(smoke))
        rows.extend(bench_node_cpu(smoke))
        rows.append(bench_simulator_rtf(smoke))
    return rows


def bench_simulator_rtf(smoke: bool = False) -> dict:
    """
    Return the simulated seconds per wall second of the simulator node in fast mode at 1 kHz.

    In process (the node's publish path, no subscriber).
    """
    import rclpy
    from rclpy.parameter import Parameter

    from ipmc_sensor_ros.nodes.simulator_node import SimulatorNode

    duration = 5.0 if smoke else 60.0
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=random.randint(201, 232))
    node = SimulatorNode(context=ctx, parameter_overrides=[
        Parameter('realtime_factor', value=0.0), Parameter('duration_s', value=duration),
        Parameter('block_size', value=200)])
    from rclpy.executors import SingleThreadedExecutor

    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    t0 = time.perf_counter()
    while not node.done:
        ex.spin_once(timeout_sec=0.01)
    wall = time.perf_counter() - t0
    ex.shutdown()
    node.destroy_node()
    rclpy.shutdown(context=ctx)
    return {'benchmark': 'simulator node real-time factor at 1 kHz (fast mode)',
            'value': duration / wall, 'unit': 'x real time', 'baseline': 'wall clock',
            'ratio': duration / wall, 'target': '>= 100'}


if __name__ == '__main__':   # python -m bench.bench_nodes [--one-sample]: the node rows only
    import argparse

    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument('--one-sample', action='store_true', help='only 1-sample messages')
    ap.add_argument('--smoke', action='store_true')
    ap.add_argument('--two-process', action='store_true',
                    help='only the one-sample ladder with driver and node (no sink)')
    ap.add_argument('--estimator-cost', action='store_true',
                    help='only the CPU per message of estimator kalman against leaky')
    a = ap.parse_args()
    if a.two_process:
        print(bench_node_rate_two_process(a.smoke), flush=True)
        raise SystemExit(0)
    if a.estimator_cost:
        for row in bench_estimator_cost(a.smoke):
            print(row, flush=True)
        raise SystemExit(0)
    for row in bench_nodes(a.smoke, sizes=(1,) if a.one_sample else (1, 1000),
                           extras=not a.one_sample):
        print(row, flush=True)
