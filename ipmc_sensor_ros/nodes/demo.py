# SPDX-License-Identifier: Apache-2.0
"""
Live demo: simulator -> estimator as two ROS 2 processes over DDS, tracking error table.

``python -m ipmc_sensor_ros.nodes.demo`` (or ``bash scripts/demo.sh``).  For each
crank-slider drive frequency (default 1, 5 and 20 Hz) it starts
``ipmc_simulator`` and ``ipmc_estimator`` as separate OS processes in their own
namespace, on an isolated ROS_DOMAIN_ID (random in 50..200 unless
ROS_DOMAIN_ID is set) with discovery limited to localhost.  The simulator runs
``--duration`` simulated seconds (default 120) in fast mode; a monitor node in
this process subscribes to ``deflection/block`` and ``deflection_truth``,
aligns them by sample time and scores the last 20 s (the first 100 s let the
start-up settle: the default Kalman estimator learns the motion's level from
whole periods within seconds; the leaky's leak transient has a 16 s time
constant at its 0.01 Hz corner).

It prints drive frequency, samples sent, samples estimated, the normalised RMS
error RMS(est - truth) / RMS(truth) and PASS if it is below 5 %; the exit code
is 0 only if every case passes and all sent samples were estimated.
"""
from __future__ import annotations

import argparse
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from .entry import domain_id_problem

__all__ = ['main']

PASS_LIMIT = 0.05
SCORE_WINDOW_S = 20.0


def _ros_args(params: dict, namespace: str) -> list[str]:
    args = ['--ros-args', '-r', f'__ns:={namespace}']
    for k, v in params.items():
        args += ['-p', f'{k}:={v}']
    return args


def _child_env(domain: int) -> dict:
    package_root = str(Path(__file__).resolve().parents[1])
    path = os.environ.get('PYTHONPATH', '')
    return dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
                PYTHONPATH=package_root + (os.pathsep + path if path else ''))


def _stop(procs: dict) -> dict:
    codes = {}
    for p in procs.values():
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
    for name, p in procs.items():
        try:
            codes[name] = p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            p.kill()
            codes[name] = p.wait()
    return codes


def run_case(node, executor, f_hz: float, args, env: dict, logdir: Path) -> dict:
    """One drive frequency: start both processes, wait for the run, score it."""
    from .monitor import TrackingMonitor

    ns = '/demo_f' + f'{f_hz:g}'.replace('.', '_')
    monitor = TrackingMonitor(node, ns)
    n_expected = int(round(args.duration * 1000.0))
    sim_params = {'motor_frequency_hz': float(f_hz), 'realtime_factor': 0.0,
                  'block_size': args.block_size, 'duration_s': float(args.duration),
                  'wait_for_subscribers': 1}
    procs: dict = {}
    logs = {name: logdir / f"{ns.strip('/')}_{name}.log" for name in ('estimator', 'simulator')}
    row = {'f_hz': f_hz, 'sent': 0, 'estimated': 0, 'nrmse': float('nan'), 'ok': False,
           'note': ''}
    t0 = time.monotonic()
    try:
        procs['estimator'] = subprocess.Popen(
            [sys.executable, '-m', 'ipmc_sensor_ros.nodes.estimator_node']
            + _ros_args({'publish_points': 'last_of_block'}, ns),
            env=env, stdout=logs['estimator'].open('w'), stderr=subprocess.STDOUT)
        deadline = time.monotonic() + args.timeout
        while monitor.subscriptions[0].get_publisher_count() == 0:
            if procs['estimator'].poll() is not None or time.monotonic() > deadline:
                row['note'] = f"estimator did not come up (see {logs['estimator']})"
                return row
            executor.spin_once(timeout_sec=0.05)
        procs['simulator'] = subprocess.Popen(
            [sys.executable, '-m', 'ipmc_sensor_ros.nodes.simulator_node']
            + _ros_args(sim_params, ns),
            env=env, stdout=logs['simulator'].open('w'), stderr=subprocess.STDOUT)
        while not (monitor.simulator_counters.get('done')
                   and monitor.estimate_samples >= monitor.simulator_counters['samples_published']
                   and monitor.estimator_counters.get('samples_out')
                   == monitor.simulator_counters['samples_published']):
            dead = [k for k, p in procs.items() if p.poll() is not None]
            if dead or time.monotonic() > deadline:
                row['note'] = ('exited early: ' + ', '.join(dead)) if dead else 'timed out'
                break
            executor.spin_once(timeout_sec=0.05)
    finally:
        codes = _stop(procs)
        for sub in monitor.subscriptions:
            node.destroy_subscription(sub)
    row['sent'] = int(monitor.simulator_counters.get('samples_published', 0))
    row['estimated'] = monitor.estimate_samples
    row['nrmse'], compared = monitor.score(SCORE_WINDOW_S)
    row['wall_s'] = time.monotonic() - t0
    bad_exit = {k: c for k, c in codes.items() if c != 0}
    if bad_exit:
        row['note'] = (row['note'] + f' exit codes {bad_exit}').strip()
    row['ok'] = (row['nrmse'] < PASS_LIMIT and row['sent'] == row['estimated'] == n_expected
                 and compared > 0 and not row['note'])
    return row


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog='python -m ipmc_sensor_ros.nodes.demo',
                                     description=__doc__.split('\n\n')[0])
    parser.add_argument('--frequencies', type=float, nargs='+', default=[1.0, 5.0, 20.0],
                        help='crank-slider drive frequencies, Hz (default 1 5 20)')
    parser.add_argument('--duration', type=float, default=120.0,
                        help='simulated seconds per case (default 120; the last 20 s are scored)')
    parser.add_argument('--block-size', type=int, default=200,
                        help='samples per message (default 200: 600 messages per case, fewer '
                             'than the QoS depth of 1000, so none can be lost)')
    parser.add_argument(
        '--timeout', type=float, default=120.0, help='wall-clock limit per case, s'
    )
    args = parser.parse_args(argv)
    if args.duration <= SCORE_WINDOW_S:
        parser.error(f'--duration must exceed the {SCORE_WINDOW_S:g} s scoring window')

    problem = domain_id_problem()
    if problem:
        parser.error(problem)
    domain = int(os.environ.get('ROS_DOMAIN_ID') or random.randint(50, 200))
    env = _child_env(domain)
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'

    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    print(f'ipmc_sensor_ros demo: ROS_DOMAIN_ID={domain}, {args.duration:g} s simulated per case '
          f'in fast mode, scoring the last {SCORE_WINDOW_S:g} s', flush=True)
    rclpy.init(domain_id=domain)
    node = rclpy.create_node('ipmc_demo_monitor')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    rows = []
    logdir = Path(tempfile.mkdtemp(prefix='ipmc_demo_'))
    try:
        for f in args.frequencies:
            row = run_case(node, executor, f, args, env, logdir)
            rows.append(row)
            print(f"  {f:g} Hz done in {row.get('wall_s', 0):.1f} s wall"
                  + (f" ({row['note']})" if row['note'] else ''), flush=True)
    except KeyboardInterrupt:
        print('interrupted', file=sys.stderr)
        return 130
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()

    print()
    print('| drive (Hz) | samples sent | samples estimated | NRMSE (last 20 s) | result |')
    print('|---:|---:|---:|---:|:---|')
    for r in rows:
        print(f"| {r['f_hz']:g} | {r['sent']} | {r['estimated']} | {100 * r['nrmse']:.2f} % | "
              f"{'PASS' if r['ok'] else 'FAIL'} |")
    ok = all(r['ok'] for r in rows)
    if ok:
        shutil.rmtree(logdir, ignore_errors=True)
    print(f'\nall passed (NRMSE < {100 * PASS_LIMIT:g} %, every sample estimated once)' if ok
          else f'\nFAILED; node logs in {logdir}')
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
