# SPDX-License-Identifier: Apache-2.0
"""
Black-box soak of the estimator node against hostile peers (issue 18, "done when").

The node runs as its own process (``python -m ipmc_sensor_ros.nodes.estimator_node``).  A
second process publishes one-sample current messages paced at 1 kHz; this test process holds
a RELIABLE KEEP_ALL subscriber on ``deflection`` that is never spun (a stalled reader), a
monitor on ``deflection/block`` and ``estimator/counters``, and a parameter peer that sets
random model parameters (mostly extreme or invalid, from half-time on also valid ones).  At
the end the node must be alive, its counters exact, its output equal to the ROS-free core on
every sample before the first accepted change, finite afterwards, and its resident memory
bounded.  The duration is ``IPMC_SOAK_S`` (default 25 s for CI); the slow test runs 600 s.

The deployment soak (issue 30) runs the same harness without the hostile peers, with mains
hum at 3 % of the signal amplitude and the node's default hum handling (``mains_hz`` as the
node defaults it; ``IPMC_SOAK_MAINS_HZ`` overrides it): no sample lost without a count, none
refused, the node's CPU below half a core, its resident memory flat after the first minute.
"""
import json
import math
import os
import random
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import rclpy
from geometry_msgs.msg import PointStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64MultiArray, String

from ipmc_sensor_ros.estimation.stream import StreamEstimator
from ipmc_sensor_ros.interface import builders as B
from ipmc_sensor_ros.interface import specs as C
from ipmc_sensor_ros.nodes.messages import ESTIMATE_COLUMNS

ROOT = Path(__file__).resolve().parents[1]
FS = 1000.0
T0_S = 100.0
#: Input and output history of the node, messages: 10 s at 1 kHz.  The default (1000, 1 s)
#: overflows on a shared 2-core machine (load 8: 17 % of the input lost in transport); the
#: soak is about the node's own behaviour, so scheduling hiccups are buffered.
QOS_DEPTH = 10000

#: Mains hum of the deployment soak: amplitude / signal amplitude (4 uA), frequency Hz.
HUM_FRACTION, HUM_HZ = 0.03, 50.0

#: The paced one-sample publisher (own process, own GIL).  Sample k: time T0 + k/FS,
#: current 4 uA sin(2 pi 3 Hz t) + 1 % noise (seed 18) + hum, the same as :func:`_samples`.
PUBLISHER = r"""
import json, sys, time
import numpy as np
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
n, fs, t0 = int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3])
t = t0 + np.arange(n) / fs
i = 4e-6 * np.sin(2 * np.pi * 3.0 * t) + np.random.default_rng(18).normal(0, 4e-8, n)
i += float(sys.argv[5]) * 4e-6 * np.sin(2 * np.pi * float(sys.argv[6]) * t + 0.3)
rclpy.init()
node = rclpy.create_node('paced_current')
pub = node.create_publisher(Float64MultiArray, 'current',
                            QoSProfile(depth=int(sys.argv[4]),
                                       reliability=ReliabilityPolicy.RELIABLE))
end = time.monotonic() + 60
while pub.get_subscription_count() < 1 and time.monotonic() < end:
    time.sleep(0.05)
time.sleep(1.0)
msg = Float64MultiArray()
msg.layout.dim = [MultiArrayDimension(label='sample', size=1, stride=2),
                  MultiArrayDimension(label='time_s,current_A', size=2, stride=2)]
tl, il = t.tolist(), i.tolist()
late = failed = 0
start = time.monotonic()
for k in range(n):
    target = start + k / fs
    now = time.monotonic()
    if target - now > 2e-4:
        time.sleep(target - now)
    elif now - target > 5e-3:
        late += 1
    msg.data = [tl[k], il[k]]
    try:
        pub.publish(msg)
    except Exception:      # the node's reader is full: this sample never leaves the peer
        failed += 1
elapsed = time.monotonic() - start
print(json.dumps({'sent': n, 'elapsed_s': elapsed, 'late_5ms': late, 'failed': failed}),
      flush=True)
time.sleep(2.0)
node.destroy_node()
rclpy.shutdown()
"""


def _samples(n, hum=0.0):
    t = T0_S + np.arange(n) / FS
    i = 4e-6 * np.sin(2 * np.pi * 3.0 * t) + np.random.default_rng(18).normal(0, 4e-8, n)
    i += hum * 4e-6 * np.sin(2 * np.pi * HUM_HZ * t + 0.3)
    return t, i


def _rss_bytes(pid):
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) * 1024
    return 0


def _cpu_s(pid):
    """CPU time (user + system) of process ``pid`` so far, s."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


MODEL_SPECS = [s for s in C.ESTIMATOR_SPECS
               if s.name in C.GEOMETRY_NAMES + C.MATERIAL_NAMES and s.kind is float]


def _hostile_value(spec, rng):
    """Draw an extreme or invalid value for a float model parameter (must be refused)."""
    choices = [math.nan, math.inf, -math.inf, -1.0, 0.0, 5e-324, 1e-296, 1e304, -1e304]
    if spec.low is not None:
        choices += [spec.low * 0.5 if spec.low > 0 else spec.low - 1.0, spec.high * 2.0]
    value = rng.choice(choices)
    if spec.low is not None and spec.low <= value <= spec.high:   # e.g. 0.0 when low is 0
        value = spec.high * 2.0
    return value


def _valid_value(spec, rng):
    """Draw the default perturbed by up to +-10 %, inside the range."""
    value = spec.default * (1.0 + rng.uniform(-0.1, 0.1))
    if spec.low is not None:
        value = min(max(value, spec.low), spec.high)
    return value


def _soak(tmp_path, duration_s, hum=0.0, hostile=True, node_args=()):
    n = int(duration_s * FS)
    domain = random.randint(150, 200)
    env = dict(os.environ, PYTHONPATH=str(ROOT), ROS_DOMAIN_ID=str(domain),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', ROS_LOG_DIR=str(tmp_path))
    node_log = open(tmp_path / 'estimator.log', 'w')
    node = subprocess.Popen(
        [sys.executable, '-m', 'ipmc_sensor_ros.nodes.estimator_node', '--ros-args',
         '-p', 'publish_points:=per_sample', '-p', f'qos_depth:={QOS_DEPTH}', *node_args],
        env=env, stdout=node_log, stderr=subprocess.STDOUT)
    publisher = None
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    rng = random.Random(18)
    results = []            # (phase, name, value, successful, reason)
    blocks = []
    counters = {}
    spinner = None
    try:
        stall = None
        if hostile:
            stalled = rclpy.create_node('stalled_reader', context=ctx)   # never spun
            stall = stalled.create_subscription(
                PointStamped, 'deflection', lambda m: None,
                QoSProfile(history=HistoryPolicy.KEEP_ALL,
                           reliability=ReliabilityPolicy.RELIABLE))
        peer = rclpy.create_node('hostile_peer', context=ctx)
        peer.create_subscription(
            Float64MultiArray, 'deflection/block', lambda m: blocks.append(m.data),
            QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE))
        peer.create_subscription(String, 'estimator/counters',
                                 lambda m: counters.update(json.loads(m.data)), 10)
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(peer)
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()      # the monitor keeps up with 1 kHz; this thread only paces
        client = AsyncParameterClient(peer, 'ipmc_estimator')
        assert client.wait_for_services(timeout_sec=60.0), 'node did not come up'
        publisher = subprocess.Popen(
            [sys.executable, '-c', PUBLISHER, str(n), str(FS), str(T0_S), str(QOS_DEPTH),
             str(hum), str(HUM_HZ)], env=env,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        start = time.monotonic()
        cpu = [(start, _cpu_s(node.pid))]      # (wall, node CPU) at start, then when data ends
        rss = []                               # (s since start, bytes) every ~5 s
        deadline = start + 120.0 + 3.0 * duration_s
        next_set = start + 2.0
        pending = None
        rss_early = None
        first_valid_at = None
        while publisher.poll() is None:
            assert node.poll() is None, (tmp_path / 'estimator.log').read_text()[-3000:]
            assert time.monotonic() < deadline, 'publisher did not finish'
            time.sleep(0.02)
            now = time.monotonic()
            if rss_early is None and now - start > max(0.3 * duration_s, 15.0):
                rss_early = _rss_bytes(node.pid)
            if not rss or now - start >= rss[-1][0] + 5.0:
                rss.append((now - start, _rss_bytes(node.pid)))
            if not hostile:
                continue
            if pending is not None and pending[-1].done():
                phase, spec, value, future = pending
                r = future.result().results[0]
                results.append((phase, spec.name, value, r.successful, r.reason, now))
                pending = None
            if pending is None and now >= next_set:
                spec = rng.choice(MODEL_SPECS)
                phase = 'hostile' if now - start < 0.5 * duration_s else 'mixed'
                valid = phase == 'mixed' and rng.random() < 0.3
                value = _valid_value(spec, rng) if valid else _hostile_value(spec, rng)
                if valid and first_valid_at is None:
                    # samples counted in a counters message received before this request
                    # were processed before the node could see it
                    first_valid_at = counters.get('samples_in', 0)
                pending = (phase if not valid else 'valid', spec, value,
                           client.set_parameters([Parameter(spec.name, value=value)]))
                next_set = now + 0.25
        cpu.append((time.monotonic(), _cpu_s(node.pid)))
        stalled_matched = stall.get_publisher_count() if stall is not None else None
        pub_out, pub_err = publisher.communicate(timeout=30)
        assert publisher.returncode == 0, pub_err[-3000:]
        stats = json.loads(pub_out.strip().splitlines()[-1])
        # the node drains its input; counters are published at 1 Hz
        settle = time.monotonic() + 60.0
        while time.monotonic() < settle:
            time.sleep(0.1)
            c = dict(counters)
            received = sum(len(b) for b in blocks) // len(ESTIMATE_COLUMNS.split(','))
            if c and c['samples_in'] == n and received == c['samples_out'] and \
                    time.monotonic() > start + duration_s + 3.0:
                break
        time.sleep(2.2)     # two more counters messages
        alive = node.poll() is None
        rss_end = _rss_bytes(node.pid) if alive else 0
    finally:
        if publisher is not None and publisher.poll() is None:
            publisher.kill()
            publisher.wait()
        if node.poll() is None:
            node.send_signal(signal.SIGINT)
        try:
            code = node.wait(timeout=30)
        except subprocess.TimeoutExpired:
            node.kill()
            code = node.wait()
        node_log.close()
        if spinner is not None:     # stop the monitor's thread before its context goes
            executor.shutdown(timeout_sec=5.0)
            spinner.join(timeout=10)
        rclpy.shutdown(context=ctx)
    return dict(n=n, stats=stats, stalled_matched=stalled_matched,
                first_valid_at=first_valid_at, counters=dict(counters),
                blocks=blocks, results=results, alive=alive, exit_code=code,
                rss_early=rss_early, rss_end=rss_end, rss=rss, hum=hum,
                cpu_fraction=(cpu[1][1] - cpu[0][1]) / (cpu[1][0] - cpu[0][0]),
                log=(tmp_path / 'estimator.log').read_text())


def _check(run):
    n, c, blocks = run['n'], run['counters'], run['blocks']
    stats = run['stats']
    accepted = [r for r in run['results'] if r[3]]
    summary = (f"sent {stats['sent']} one-sample messages in {stats['elapsed_s']:.1f} s "
               f"({stats['sent'] / stats['elapsed_s']:.0f} /s, {stats['late_5ms']} > 5 ms late); "
               f"{stats['failed']} publish failures at the peer; "
               f"lost in transport {n - c['samples_in'] - stats['failed']}; "
               f"parameter sets {len(run['results'])} ({len(accepted)} accepted); counters {c}; "
               f"RSS {run['rss_early'] / 1e6:.1f} -> {run['rss_end'] / 1e6:.1f} MB")
    print(summary)
    assert run['alive'], run['log'][-3000:]
    assert run['exit_code'] == 0, run['log'][-3000:]
    assert 'Traceback' not in run['log']
    # exact accounting, end to end: every sample is in exactly one term of the node's
    # invariant, or was lost in transport before the node (its KEEP_LAST input history
    # overflows when the node is starved of CPU); a lost sample is absent from the output
    # by its stamp, so the missing stamps are exactly what the node did not deliver
    assert c['messages_in'] == c['samples_in'] and 0 < c['samples_in'] <= n, summary
    assert c['samples_in'] == (c['samples_out'] + c['samples_rejected'] + c['samples_dropped']
                               + c['samples_unpublished']), summary
    assert c['samples_rejected'] == 0 and c['samples_dropped'] == 0, summary
    # every hostile value refused with one line
    for phase, name, value, ok, reason, _ in run['results']:
        if phase != 'valid':
            assert not ok, (name, value)
            assert reason and '\n' not in reason and len(reason) < 400, (name, reason)
    # the peer waits for each reply, and a reply waits behind the node's input backlog
    # (up to QOS_DEPTH messages): on a starved machine a set took ~13 s
    assert len(run['results']) >= 10, 'the parameter peer hardly ran'
    # resident memory from 30 % of the run (at least 15 s: the histories are full ~10 s after
    # the data starts) to its end: the stalled reader makes the point writer keep at most
    # QOS_DEPTH unacknowledged points (measured: +12 MB while filling), so growth beyond
    # 20 MB once full is a leak (one 100-byte object kept per sample: +42 MB over 70 % of
    # 10 minutes)
    assert run['rss_early'] is not None, summary
    assert run['rss_end'] - run['rss_early'] <= 20e6, summary
    # what the monitor received: checked last, since a monitor starved longer than its
    # history loses rows (not the node's doing) and then nothing is left to compare against
    rows = np.concatenate([np.frombuffer(b, dtype=np.float64) for b in blocks]).reshape(
        -1, len(ESTIMATE_COLUMNS.split(',')))     # one-sample blocks: time_s, deflection_m, std
    times, received = rows[:, 0], rows[:, 1]
    # the monitor's own RELIABLE reader (history QOS_DEPTH) must see every published row; when
    # this process is starved for longer than that history, rows are lost between the node
    # and the monitor, which is not the node's doing but leaves nothing to compare against
    assert received.size == c['samples_out'], (
        f'monitor received {received.size} of {c["samples_out"]} published rows '
        f'(load {os.getloadavg()[0]:.1f}): {summary}')
    assert np.all(np.isfinite(received)), summary
    assert np.all(np.diff(times) > 0), 'output stamps not strictly increasing'
    lost = n - c['samples_in']
    assert n - times.size == lost + c['samples_unpublished'], summary
    # clean reference: the ROS-free stream core with the default parameters, fed the samples
    # the node delivered (same gaps, same resets), equals the node's output on every sample
    # before the first accepted change (1e-12 m: the same float64 code, rounding only)
    t, i = _samples(n)
    k_seen = np.searchsorted(t, times)
    assert np.allclose(t[k_seen], times, rtol=0, atol=1e-9)
    values = {s.name: s.default for s in C.ESTIMATOR_SPECS}
    values['effects'], values['plugins'] = [], []
    ref = StreamEstimator(B.build_estimator(values))
    out = ref.feed(t[k_seen], i[k_seen])
    assert out is not None and out[1].size == times.size
    ref_w = out[1]
    if c['samples_unpublished']:
        ref_w = received      # the node filtered samples the monitor never saw: no reference
    differs = np.abs(received - ref_w) > 1e-12
    first_change = int(np.argmax(differs)) if np.any(differs) else times.size
    if run['first_valid_at'] is None:
        assert first_change == times.size, summary
    else:
        # the samples the node had counted before the peer's first valid set are exact
        assert accepted and 'filter rebuilt' in run['log'], summary
        seen = int(np.searchsorted(times, t[run['first_valid_at'] - 1], 'right'))
        assert first_change >= seen > 0, (first_change, seen, summary)
    # after valid +-10 % changes the output stays within twice the reference amplitude
    # (the gain is a product of a few material and geometry factors, each +-10 %)
    assert np.max(np.abs(received)) <= 2.0 * np.max(np.abs(ref_w)), summary
    return summary


def test_soak_short_stalled_reader_and_random_parameters(tmp_path):
    _check(_soak(tmp_path, float(os.environ.get('IPMC_SOAK_S', '25'))))


@pytest.mark.slow
def test_soak_ten_minutes_stalled_reader_and_random_parameters(tmp_path):
    _check(_soak(tmp_path, 600.0))


#: Node CPU limit of the deployment soak: a fraction of one core (two-core machine).
CPU_LIMIT = 0.5
#: Resident memory growth allowed after the first minute of the deployment soak, bytes.
RSS_FLAT_BYTES = 5e6


def _check_deployment(run, duration_s):
    """
    Check the deployment soak's guarantees (module docstring); return the summary line.

    A sample lost before the node must be counted by it (``samples_lost``, when the node
    counts losses), none refused; CPU and memory are judged on runs of a minute or more.
    """
    n, c, stats = run['n'], run['counters'], run['stats']
    after = [b for t, b in run['rss'] if t >= 60.0]
    lost = n - c.get('samples_in', 0)
    unaccounted = lost - c.get('samples_lost', 0)
    hum_pct = 100 * run['hum']
    summary = (f'{duration_s:g} s at 1 kHz, hum {hum_pct:g} %: sent {stats["sent"]} '
               f"({stats['late_5ms']} > 5 ms late, {stats['failed']} failed at the peer); "
               f'lost before the node {lost}, unaccounted {unaccounted}; counters {c}; node CPU '
               f"{100 * run['cpu_fraction']:.1f} % of a core; RSS after the first minute "
               + (f'{min(after) / 1e6:.1f}..{max(after) / 1e6:.1f} MB' if after else 'n/a'))
    print(summary)
    assert run['alive'] and run['exit_code'] == 0, run['log'][-3000:]
    assert 'Traceback' not in run['log']
    assert c['samples_in'] == (c['samples_out'] + c['samples_rejected'] + c['samples_dropped']
                               + c['samples_unpublished']), summary
    assert unaccounted == 0, summary
    assert c['samples_rejected'] == 0 and c['messages_rejected'] == 0, summary
    if duration_s >= 120.0:
        assert run['cpu_fraction'] < CPU_LIMIT, summary
        assert max(after) - min(after) <= RSS_FLAT_BYTES, summary
    return summary


def _mains_args():
    wanted = os.environ.get('IPMC_SOAK_MAINS_HZ')
    return ('-p', f'mains_hz:={wanted}') if wanted else ()


def test_deployment_soak_short_hum_default_handling(tmp_path):
    duration_s = float(os.environ.get('IPMC_SOAK_S', '20'))
    _check_deployment(_soak(tmp_path, duration_s, hum=HUM_FRACTION, hostile=False,
                            node_args=_mains_args()), duration_s)


@pytest.mark.slow
def test_deployment_soak_ten_minutes_hum_default_handling(tmp_path):
    _check_deployment(_soak(tmp_path, 600.0, hum=HUM_FRACTION, hostile=False,
                            node_args=_mains_args()), 600.0)
