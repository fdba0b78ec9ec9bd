# SPDX-License-Identifier: Apache-2.0
"""
Node benchmarks: the estimator node against a pass-through node, and the simulator.

Sustained input rate without loss and added latency of the estimator node against a
pass-through node (raw subscription, publish of the same bytes) in the same harness, and
the simulator's real-time factor.

Harness: three processes on one machine, an isolated ROS_DOMAIN_ID, DDS on
loopback.  A driver process publishes ``current`` blocks (n samples per message,
sample times = the driver's wall clock) at a fixed message rate for a fixed time;
the node under test (estimator, or the pass-through) republishes on
``deflection/block``; this process counts what arrives and the latency
``receive time - time of the block's last sample``.  A rate is *sustained* when
every sample sent arrives.  Run: ``python -m bench.run`` (full: ladder of rates, 10 s
each, the best loss-free one confirmed for 60 s) or ``--smoke``.
"""
from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

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
class PassThrough(Node):
    def __init__(self):
        super().__init__("passthrough")
        qos = P.make_qos({"qos_depth": 1000, "qos_reliability": "reliable"})
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

DRIVER = r"""
import sys, time, rclpy, numpy as np
from std_msgs.msg import Float64MultiArray
from ipmc_sensor_ros.nodes import params as P
from ipmc_sensor_ros.nodes.messages import pack_block
rate, n = float(sys.argv[1]), int(sys.argv[2])
duration, fs = float(sys.argv[3]), float(sys.argv[4])
epoch = float(sys.argv[5])   # times are seconds since this shared epoch: float64 resolution
                             # at today's epoch (0.24 us) could not carry 1 us sample periods
rclpy.init()
node = rclpy.create_node("driver")
qos = P.make_qos({"qos_depth": 1000, "qos_reliability": "reliable"})
pub = node.create_publisher(Float64MultiArray, "current", qos)
end = time.monotonic() + 20
while pub.get_subscription_count() == 0 and time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.05)
time.sleep(1.0)
k = 0
t0 = time.monotonic()
total = int(rate * duration)
offsets = np.arange(n) / fs
signal = 1e-6 * np.sin(2 * np.pi * 5.0 * offsets)
start = time.time() - epoch
back = offsets[::-1].copy()
from rclpy.serialization import serialize_message
# serialised once (CDR, little-endian): the rows (time, current) are the last 16 n bytes; each
# send rewrites the times in place and publishes the bytes (publish of a message object costs
# ~100 us of conversion and serialisation: the driver would need most of a core at 4000 msg/s)
buf = bytearray(serialize_message(pack_block(start - back, signal)))
times = np.frombuffer(buf, dtype="<f8", count=2 * n, offset=len(buf) - 16 * n).reshape(n, 2)[:, 0]
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
from bench.bench_nodes import DRIVER, PASSTHROUGH_CLASS, trial_env
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


def _node_in_process(kind: str, rate: float, n: int, duration: float) -> dict:
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
        r = _node_in_process(kind, rate, n, duration)
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
            r = _node_in_process(kind, rate, 1, 1.0 if smoke else duration)
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


def trial_env(domain: int) -> dict:
    """Return the environment of a trial's processes: this checkout, ``domain``, loopback."""
    return dict(os.environ, PYTHONPATH=str(ROOT), ROS_DOMAIN_ID=str(domain),
                ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')


def _run_once(kind: str, rate: float, n: int, duration: float) -> dict:
    """
    One trial in a fresh process.

    A long-lived process that creates and destroys many DDS participants was seen to lose
    messages in later trials.
    """
    import json

    code = ('import json, sys; from bench.bench_nodes import run_trial; '
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
    """
    End a trial: SIGINT the node process (killed after 10 s), then the sink and its context.

    Shared by the node and the sensor-array benchmarks.
    """
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

    from ipmc_sensor_ros.nodes import params as P

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
    qos = P.make_qos({'qos_depth': 1000, 'qos_reliability': 'reliable'})
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


def bench_nodes(smoke: bool = False, sizes=(1, 1000), extras: bool = True) -> list[dict]:
    """
    Sustained lossless rate, latency and CPU of the estimator node against a pass-through.

    ``sizes``: samples per message to bench; ``extras``: also the CPU-per-message rows and
    the simulator's real-time factor.
    """
    rows = []
    for n in sizes:
        results = {}
        for kind in ('passthrough', 'estimator'):
            if smoke:
                best = _run_once(kind, _ladder(n)[0], n, 1.0)
            else:
                passed, failed = [], None
                for rate in _ladder(n):
                    if not _ok(_run_once(kind, rate, n, 10.0)):
                        failed = rate
                        break
                    passed.append(rate)
                if passed and failed is not None:   # one bisection step between the rungs
                    mid = round((passed[-1] + failed) / 2.0)
                    if _ok(_run_once(kind, mid, n, 10.0)):
                        passed.append(mid)
                best = None
                for rate in reversed(passed[-3:]):   # confirm for 60 s, stepping down if needed
                    r = _run_once(kind, rate, n, 60.0)
                    if _ok(r):
                        best = r
                        break
            results[kind] = best
        p, e = results['passthrough'], results['estimator']
        if p is None or e is None:
            rows.append(
                {
                    'benchmark': f'node rate, {n}-sample messages',
                    'value': float('nan'),
                    'unit': 'samples/s',
                    'baseline': 'pass-through node',
                    'ratio': float('nan'),
                    'target': '>= 0.9',
                }
            )
            continue
        rate_e = e['rate_msg_s'] * n if e['lossless'] else 0.0
        rate_p = p['rate_msg_s'] * n if p['lossless'] else 0.0
        # latency and CPU are compared at the same message rate: the estimator's
        same = (
            p
            if p['rate_msg_s'] == e['rate_msg_s']
            else _run_once('passthrough', e['rate_msg_s'], n, 1.0 if smoke else 10.0)
        )
        _ok(same)
        rows.append({'benchmark': f'estimator node sustained rate, {n}-sample messages'
                                  + (' (smoke)' if smoke else ', 60 s without loss'),
                     'value': rate_e, 'unit': 'samples/s',
                     'baseline': f'pass-through node same harness: {rate_p:.0f} samples/s',
                     'ratio': rate_e / rate_p if rate_p else float('nan'), 'target': '>= 0.9'})
        rows.append({'benchmark': f'estimator node added latency, {n}-sample messages at '
                                  f"{e['rate_msg_s']:.0f} msg/s (median; ratio column: added p99)",
                     'value': e['latency_median_ms'] - same['latency_median_ms'], 'unit': 'ms',
                     'baseline': f"pass-through same rate {same['latency_median_ms']:.2f} / "
                                 f"{same['latency_p99_ms']:.2f} ms",
                     'ratio': (e['latency_p99_ms'] - same['latency_p99_ms']), 'target': '-'})
        rows.append(
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
            }
        )
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
