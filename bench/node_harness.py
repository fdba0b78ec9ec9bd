# SPDX-License-Identifier: Apache-2.0
"""
The harness of the node benchmarks (:mod:`bench.bench_nodes`, :mod:`bench.bench_arrays`).

Three processes on one machine, an isolated ROS_DOMAIN_ID, DDS on loopback.  A driver
process (:data:`DRIVER`) publishes ``current`` blocks (n samples per message, sample times =
the driver's wall clock) at a fixed message rate for a fixed time; the node under test
(the estimator, or the pass-through :data:`PASSTHROUGH`) republishes on
``deflection/block``; the calling process is the sink: it counts what arrives and the
latency ``receive time - time of the block's last sample`` (:func:`run_trial`, each trial
in a fresh process: :func:`run_trial_in_process`).  :func:`node_in_process` runs a node
under the driver alone (two processes, no sink) for its CPU per message.
"""
from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

__all__ = ['ROOT', 'PASSTHROUGH_CLASS', 'PASSTHROUGH', 'DRIVER_START', 'DRIVER', 'NODE_CPU',
           'node_in_process', 'trial_env', 'run_trial_in_process', 'process_cpu_s', 'stop_trial',
           'block_rows_and_last_time', 'run_trial']

ROOT = Path(__file__).resolve().parents[1]

# The pass-through echoes the serialised bytes (raw subscription, publish of bytes): the
# cheapest node rclpy allows, the baseline the estimator is held to (the estimator reads and
# writes one-sample blocks as bytes too; a pass-through converting messages costs ~50 us more
# per message than this one, README "Benchmarks").
PASSTHROUGH_CLASS = r"""
import sys, rclpy
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray
from ipmc_sensor_ros.nodes import params as P
from ipmc_sensor_ros.nodes import topics as T
class PassThrough(Node):
    def __init__(self):
        super().__init__("passthrough")
        qos = T.make_qos({"qos_depth": 1000, "qos_reliability": "reliable"})
        self.pub = self.create_publisher(Float64MultiArray, "deflection/block", qos)
        self.create_subscription(Float64MultiArray, "current", self.on_msg, qos, raw=True)
        self.handled = 0
    def on_msg(self, raw):
        self.handled += 1
        self.pub.publish(raw)
"""

PASSTHROUGH = PASSTHROUGH_CLASS + r"""
from ipmc_sensor_ros.nodes.runner import make_executor, spin_until_signalled
rclpy.init()
node = PassThrough()
executor = make_executor()   # the nodes' executor (EventsExecutor where rclpy has it)
executor.add_node(node)
try:
    spin_until_signalled(executor)
except KeyboardInterrupt:
    pass
"""

#: the drivers' start: a reliable publisher on ``current``, once the node under test subscribes
DRIVER_START = r"""
def open_publisher(name):
    rclpy.init()
    node = rclpy.create_node(name)
    qos = T.make_qos({"qos_depth": 1000, "qos_reliability": "reliable"})
    pub = node.create_publisher(Float64MultiArray, "current", qos)
    end = time.monotonic() + 20
    while pub.get_subscription_count() == 0 and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    time.sleep(1.0)
    return node, pub
"""
DRIVER = DRIVER_START + r"""
import sys, time, rclpy, numpy as np
from std_msgs.msg import Float64MultiArray
from ipmc_sensor_ros.nodes import params as P
from ipmc_sensor_ros.nodes import topics as T
from ipmc_sensor_ros.nodes.messages import pack_block
rate, n = float(sys.argv[1]), int(sys.argv[2])
duration, fs = float(sys.argv[3]), float(sys.argv[4])
epoch = float(sys.argv[5])   # times are seconds since this shared epoch: float64 resolution
                             # at today's epoch (0.24 us) could not carry 1 us sample periods
node, pub = open_publisher("driver")
k = 0
t0 = time.monotonic()
total = int(rate * duration)
offsets = np.arange(n) / fs
start = time.time() - epoch
back = offsets[::-1].copy()


def crank_current(end_s):      # a 5 Hz crank's current for the samples up to end_s,
    return 1e-6 * np.sin(2 * np.pi * 5.0 * (end_s - back))  # continuous across messages


from rclpy.serialization import serialize_message
# serialised once (CDR, little-endian): the rows (time, current) are the last 16 n bytes; each
# send rewrites the times and currents in place and publishes the bytes (publishing an object costs
# ~100 us of conversion and serialisation: the driver would need most of a core at 4000 msg/s)
buf = bytearray(serialize_message(pack_block(start - back, crank_current(0.0))))
rows = np.frombuffer(buf, dtype="<f8", count=2 * n, offset=len(buf) - 16 * n).reshape(n, 2)
times, currents = rows[:, 0], rows[:, 1]
while k < total:
    # a DAQ's steady sample clock: message k ends at start + k / rate (contiguous samples, no
    # jitter in the stamps); it is published when due, and after a stall the backlog goes out
    # at once, as a buffered DAQ delivers it
    # sleeps of at least 1 ms, then every message due is sent back to back: a sleep costs
    # ~30 us of CPU and overshoots by ~170 us here, more than a publish of the bytes (~5 us)
    due = t0 + k / rate
    now = time.monotonic()
    if due > now:
        time.sleep(max(due - now, 1e-3))
    times[:] = start + k / rate - back   # in place, in the serialised message
    currents[:] = crank_current(k / rate)
    pub.publish(bytes(buf))
    k += 1
print(f"SENT {k} {k * n} {time.monotonic() - t0:.6f}", flush=True)
time.sleep(2.0)
node.destroy_node()
rclpy.shutdown()
"""


NODE_CPU = r"""
import os, sys, time, random, subprocess
import rclpy
from rclpy.parameter import Parameter
from bench.node_harness import DRIVER, PASSTHROUGH_CLASS, trial_env
from ipmc_sensor_ros.nodes.runner import make_executor
kind, rate, n, duration = sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
domain = random.randint(201, 232)
rclpy.init(domain_id=domain)
if kind in ("leaky", "kalman"):
    from ipmc_sensor_ros.nodes.estimator_node import EstimatorNode
    node = EstimatorNode(parameter_overrides=[
        Parameter("sample_rate_hz", value=rate * n), Parameter("publish_points", value="none"),
        Parameter("max_gap_s", value=1.0),
        Parameter("band_high_hz", value=min(50.0, rate * n / 4))]
        + [Parameter("estimator", value=kind)])
    handled = lambda: node.counters()["messages_in"]
else:
    ns = {}
    exec(PASSTHROUGH_CLASS, ns)
    node = ns["PassThrough"]()
    handled = lambda: node.handled
ex = make_executor()
ex.add_node(node)
drv = subprocess.Popen([sys.executable, "-c", DRIVER, str(rate), str(n), str(duration),
                        str(rate * n), repr(time.time() - 100.0)], env=trial_env(domain),
                       stdout=subprocess.PIPE, text=True)
while handled() == 0 and drv.poll() is None:
    ex.spin_once(timeout_sec=0.05)
cpu0, m0 = time.process_time(), handled()
while drv.poll() is None:
    ex.spin_once(timeout_sec=0.05)
out = drv.communicate()[0].split()
sent, achieved = (int(out[1]), int(out[1]) / float(out[3])) if out[:1] == ["SENT"] else (-1, 0.0)
print("CPU", time.process_time() - cpu0, handled() - m0, handled(), sent, achieved)
"""


def node_in_process(kind: str, rate: float, n: int, duration: float) -> dict:
    """
    Run one node in a fresh process under the driver alone (two processes, no sink).

    Returns the node's whole-process CPU seconds and messages handled while data flowed,
    its messages handled in all, and what the driver sent and achieved.
    """
    res = subprocess.run([sys.executable, '-c', NODE_CPU, kind, str(rate), str(n),
                          str(duration)], cwd=str(ROOT),
                         env=dict(os.environ, PYTHONPATH=str(ROOT)), capture_output=True,
                         text=True, timeout=duration + 120)
    line = [x.split() for x in res.stdout.splitlines() if x.startswith('CPU ')]
    if not line:
        return {'cpu_s': float('nan'), 'handled': 0, 'handled_all': 0, 'sent': -1,
                'achieved_msg_s': 0.0}
    f = line[0]
    return {'cpu_s': float(f[1]), 'handled': int(f[2]), 'handled_all': int(f[3]),
            'sent': int(f[4]), 'achieved_msg_s': float(f[5])}


def trial_env(domain: int) -> dict:
    """Return the environment of a trial's processes: this checkout, ``domain``, loopback."""
    return dict(os.environ, PYTHONPATH=str(ROOT), ROS_DOMAIN_ID=str(domain),
                ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')


def run_trial_in_process(kind: str, rate: float, n: int, duration: float) -> dict:
    """
    Run :func:`run_trial` in a fresh process; its result, or ``sent = -1`` when it gave none.

    A long-lived process that creates and destroys many DDS participants was seen to lose
    messages in later trials.
    """
    import json

    code = ('import json, sys; from bench.node_harness import run_trial; '
            f"print('RESULT ' + json.dumps(run_trial({kind!r}, {rate!r}, {n!r}, {duration!r})))")
    res = subprocess.run(
        [sys.executable, '-c', code],
        cwd=str(ROOT),
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
        capture_output=True,
        text=True,
        timeout=duration + 120,
    )
    for line in res.stdout.splitlines():
        if line.startswith('RESULT '):
            return json.loads(line[7:])
    return {'kind': kind, 'rate_msg_s': rate, 'n': n, 'sent': -1, 'received': 0, 'lossless': False,
            'latency_median_ms': float('nan'), 'latency_p99_ms': float('nan')}


def process_cpu_s(pid: int) -> float:
    """User + system CPU time of a process so far, s (Linux /proc)."""
    try:
        fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')
    except (OSError, IndexError, ValueError):
        return float('nan')


def stop_trial(proc, executor, sink, context) -> None:
    """End a trial: SIGINT the node process (killed after 10 s), then the sink and its context."""
    import rclpy

    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    executor.shutdown()
    sink.destroy_node()
    rclpy.shutdown(context=context)


def block_rows_and_last_time(raw: bytes) -> tuple[int, float]:
    """
    Return (rows, time of the last row) of a serialised ``Float64MultiArray`` block.

    Reads the CDR bytes (little-endian) without deserialising: ``layout.dim[0].size`` rows,
    ``layout.dim[1].size`` columns, time in the first column of the last row.  The sink of the
    one-sample trials does this instead of building message objects (~50 us per message).
    """
    import struct

    off = 4                                     # encapsulation header
    ndim, = struct.unpack_from('<I', raw, off)
    off += 4
    sizes = []
    for _ in range(ndim):
        n_chars, = struct.unpack_from('<I', raw, off)
        off = (off + 4 + n_chars + 3) & ~3      # label string, padded to 4
        sizes.append(struct.unpack_from('<I', raw, off)[0])
        off += 8                                # size, stride
    rows, columns = sizes[0], sizes[1]
    if rows == 0:
        return 0, float('nan')
    return rows, struct.unpack_from('<d', raw, len(raw) - 8 * columns)[0]


def run_trial(kind: str, rate: float, n: int, duration: float) -> dict:
    """
    Run one three-process trial: the ``kind`` node, the driver at ``rate`` msg/s, this sink.

    ``kind`` is ``'estimator'`` or ``'passthrough'``; ``n`` samples per message for
    ``duration`` s.  Returns what was sent and received, the rate the driver achieved, the
    node's CPU fraction while data flowed and the latency (median, p99) in ms.
    """
    import numpy as np
    import rclpy
    from std_msgs.msg import Float64MultiArray

    from ipmc_sensor_ros.nodes import topics as T

    fs = rate * n
    domain = random.randint(201, 232)
    env = trial_env(domain)
    if kind == 'estimator':
        node_cmd = [sys.executable, '-m', 'ipmc_sensor_ros.nodes.estimator_node', '--ros-args',
                    '-p', f'sample_rate_hz:={fs:.1f}', '-p', 'publish_points:=none',
                    '-p', 'max_gap_s:=1.0', '-p', f'band_high_hz:={min(50.0, fs / 4):.1f}',
                    # the leaky, as when these rows were first measured: the ladder reaches
                    # 1 MHz and the Kalman cannot be designed at 500 kHz (--estimator-cost)
                    '-p', 'estimator:=leaky']
    else:
        node_cmd = [sys.executable, '-c', PASSTHROUGH]
    proc = subprocess.Popen(
        node_cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    sink = rclpy.create_node('sink', context=ctx)
    qos = T.make_qos({'qos_depth': 1000, 'qos_reliability': 'reliable'})
    received = [0]
    latencies: list[float] = []
    node_cpu: list[tuple[float, float]] = []    # (wall, CPU s of the node) while data flows

    epoch = time.time() - 100.0

    def on_block(raw: bytes):
        now = time.time() - epoch
        # the estimator sends ESTIMATE_COLUMNS, the pass-through its input's two columns
        rows, last = block_rows_and_last_time(raw)
        received[0] += rows
        latencies.append(now - last)
        if len(latencies) % 256 == 1:
            node_cpu.append((time.monotonic(), process_cpu_s(proc.pid)))

    # raw: the sink counts from the serialised bytes, so it is not the bottleneck
    sub = sink.create_subscription(Float64MultiArray, 'deflection/block', on_block, qos,
                                   raw=True)
    from ipmc_sensor_ros.nodes.runner import make_executor

    ex = make_executor(context=ctx)   # the sink must not be the bottleneck of one-sample trials
    ex.add_node(sink)
    # start the driver only once the node's output is matched: data published before the
    # match would be lost (volatile QoS) and counted against the node
    ready_by = time.monotonic() + 30
    while sub.get_publisher_count() == 0 and time.monotonic() < ready_by:
        ex.spin_once(timeout_sec=0.05)
    driver = subprocess.Popen(
        [sys.executable, '-c', DRIVER, str(rate), str(n), str(duration), str(fs), repr(epoch)],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    end = time.monotonic() + duration + 40
    while driver.poll() is None and time.monotonic() < end:
        ex.spin_once(timeout_sec=0.01)
    deadline = time.monotonic() + 3
    while time.monotonic() < deadline:
        ex.spin_once(timeout_sec=0.01)
    node_cpu.append((time.monotonic(), process_cpu_s(proc.pid)))
    # the node's CPU while data flowed (first to last block received, sampled every 256
    # blocks): not the driver's start-up, its 1 s wait and 2 s linger, nor the 3 s tail
    flow = node_cpu[:-1] if len(node_cpu) > 2 else node_cpu
    cpu_fraction = ((flow[-1][1] - flow[0][1]) / (flow[-1][0] - flow[0][0])
                    if len(flow) > 1 and flow[-1][0] > flow[0][0] else float('nan'))
    out = driver.communicate(timeout=5)[0] if driver.poll() is not None else ''
    sent = int(out.split()[2]) if out.startswith('SENT') else -1
    # the driver paces itself but cannot always keep up: a trial counts at the rate achieved
    achieved = (int(out.split()[1]) / float(out.split()[3])) if out.startswith('SENT') else 0.0
    stop_trial(proc, ex, sink, ctx)
    lat = np.array(latencies) if latencies else np.array([np.nan])
    return {'kind': kind, 'rate_msg_s': rate, 'n': n, 'sent': sent, 'received': received[0],
            'lossless': bool(sent > 0 and received[0] == sent),
            'achieved_msg_s': achieved,
            'node_cpu_fraction': cpu_fraction,
            'driver_kept_up': bool(achieved >= 0.97 * rate),
            'latency_median_ms': float(np.median(lat) * 1e3),
            'latency_p99_ms': float(np.percentile(lat, 99) * 1e3)}
