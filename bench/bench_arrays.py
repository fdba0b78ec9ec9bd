# SPDX-License-Identifier: Apache-2.0
"""
Sensor-array benchmark: one estimator node, 16 channels at 1 kHz, sustained.

Harness as :mod:`bench.node_harness`: three processes on one machine, an isolated
ROS_DOMAIN_ID (201-232), DDS on loopback.  A driver publishes 16-column ``current`` blocks
(``time_s,current_ch0_A,...``) of ``n`` rows at ``1000 / n`` msg/s on a steady clock; the
estimator node (``channels: 16``, ``publish_points: none``) republishes on
``deflection/block``; this process counts the rows that arrive.  Reported: the node's process
CPU (user + system) as a fraction of one core over the run, and whether every row arrived.
Run: ``python -m bench.bench_arrays [--smoke]`` (also part of ``python -m bench.run``).
"""
from __future__ import annotations

import subprocess
import sys
import time

from bench.node_harness import DRIVER_START, process_cpu_s, stop_trial, trial_env

CHANNELS = 16
FS = 1000.0

ARRAY_DRIVER = DRIVER_START + r"""
import sys, time, rclpy, numpy as np
from std_msgs.msg import Float64MultiArray
from ipmc_sensor_ros.interface.blocks import current_columns
from ipmc_sensor_ros.nodes import params as P
from ipmc_sensor_ros.nodes import topics as T
from ipmc_sensor_ros.nodes.messages import BlockPacker
channels, n = int(sys.argv[1]), int(sys.argv[2])
duration, fs = float(sys.argv[3]), float(sys.argv[4])
rate = fs / n
node, pub = open_publisher("array_driver")
rng = np.random.default_rng(0)
total = int(rate * duration)
k_all = np.arange(total * n)
# 1 uA at 2 Hz with a phase per channel, 30 nA offset, 2 % noise (a DAQ's current)
cols = [1e-6 * np.sin(2 * np.pi * 2.0 * k_all / fs + 0.3 * c) + 3e-8
        + 2e-8 * rng.standard_normal(k_all.size) for c in range(channels)]
packer = BlockPacker(current_columns(channels))
t0 = time.monotonic()
for k in range(total):
    due = t0 + k / rate
    now = time.monotonic()
    if due > now:
        time.sleep(due - now)
    sl = slice(k * n, (k + 1) * n)
    pub.publish(packer.pack(10.0 + k_all[sl] / fs, *(c[sl] for c in cols)))
print(f"SENT {total} {total * n} {time.monotonic() - t0:.6f}", flush=True)
time.sleep(2.0)
node.destroy_node()
rclpy.shutdown()
"""


def _array_trial(n: int, duration: float) -> dict:
    """One run: rows of ``n`` samples of :data:`CHANNELS` channels at :data:`FS`."""
    import random

    import rclpy
    from std_msgs.msg import Float64MultiArray

    from ipmc_sensor_ros.interface.blocks import estimate_columns, unpack_columns
    from ipmc_sensor_ros.nodes import topics as T
    from ipmc_sensor_ros.nodes.runner import make_executor

    domain = random.randint(201, 232)
    env = trial_env(domain)
    proc = subprocess.Popen(
        [sys.executable, '-m', 'ipmc_sensor_ros.nodes.estimator_node', '--ros-args',
         '-p', f'channels:={CHANNELS}', '-p', 'publish_points:=none', '-p', 'max_gap_s:=1.0'],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    sink = rclpy.create_node('array_sink', context=ctx)
    received = [0]
    columns = estimate_columns(CHANNELS)

    def on_block(msg):
        received[0] += unpack_columns(msg, columns)[0].size

    qos = T.make_qos({'qos_depth': 1000, 'qos_reliability': 'reliable'})
    sub = sink.create_subscription(Float64MultiArray, 'deflection/block', on_block, qos)
    ex = make_executor(context=ctx)
    ex.add_node(sink)
    ready_by = time.monotonic() + 60
    while sub.get_publisher_count() == 0 and time.monotonic() < ready_by:
        ex.spin_once(timeout_sec=0.05)
    driver = subprocess.Popen(
        [sys.executable, '-c', ARRAY_DRIVER, str(CHANNELS), str(n), str(duration), str(FS)],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    cpu_start = wall_start = None
    end = time.monotonic() + duration + 60
    while driver.poll() is None and time.monotonic() < end:
        if cpu_start is None and received[0]:
            cpu_start, wall_start = process_cpu_s(proc.pid), time.monotonic()
        ex.spin_once(timeout_sec=0.01)
    cpu_end, wall_end = process_cpu_s(proc.pid), time.monotonic()
    deadline = time.monotonic() + 3
    while time.monotonic() < deadline:
        ex.spin_once(timeout_sec=0.01)
    out = driver.communicate(timeout=5)[0] if driver.poll() is not None else ''
    sent = int(out.split()[2]) if out.startswith('SENT') else -1
    stop_trial(proc, ex, sink, ctx)
    cpu = ((cpu_end - cpu_start) / (wall_end - wall_start) if cpu_start is not None
           else float('nan'))
    return {'n': n, 'sent': sent, 'received': received[0], 'cpu_fraction': cpu,
            'lossless': sent > 0 and received[0] == sent}


def bench_arrays(smoke: bool = False) -> list[dict]:
    """Measure the sensor-array rows: 16 channels at 1 kHz in one estimator node."""
    rows = []
    for n in (10,) if smoke else (10, 1):
        r = _array_trial(n, 1.0 if smoke else 20.0)
        print(f"  array trial {CHANNELS} ch, {n}-sample msgs: sent {r['sent']} rows, received "
              f"{r['received']}, node CPU {r['cpu_fraction']:.0%}", file=sys.stderr, flush=True)
        rows.append({'benchmark': f'estimator node, {CHANNELS} channels at {FS:.0f} Hz, '
                                  f'{n}-sample messages ({FS / n:.0f} msg/s), sustained '
                                  f"({'lossless' if r['lossless'] else 'LOSS'}: "
                                  f"{r['received']}/{r['sent']} rows)",
                     'value': r['cpu_fraction'], 'unit': 'node CPU fraction of one core',
                     'baseline': '1 core', 'ratio': r['cpu_fraction'], 'target': '< 1, lossless'})
    return rows


if __name__ == '__main__':   # python -m bench.bench_arrays [--smoke]
    for row in bench_arrays('--smoke' in sys.argv[1:]):
        print(row, flush=True)
