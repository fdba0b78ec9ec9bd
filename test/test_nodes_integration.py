# SPDX-License-Identifier: Apache-2.0
"""
Simulator -> estimator end to end: tracking accuracy and exact sample accounting.

1. One process, one executor: three simulator/estimator pairs (crank-slider at
   1, 5 and 20 Hz) in namespaces /f1, /f5, /f20.
2. Two OS processes over DDS (loopback, random ROS_DOMAIN_ID in 100..200): the
   simulator and the estimator as subprocesses, this test process monitors.

Accounting is checked three ways: the simulator's ``samples_published``, the
estimator's counters (``samples_in``/``samples_out``, from the node in case 1
and from its ``estimator/counters`` topic in case 2) and the samples the
monitor received on ``deflection/block``.  They must agree exactly.

Accuracy: each run simulates 120 s in fast mode and scores the last 20 s.  The
estimator starts from zero deflection while the crank starts at +2 mm; that
initial-condition error decays with the leak time constant 1/(2 pi 0.01 Hz) =
16 s, i.e. to 2 mm * exp(-100/16) = 4 um (0.3 % of the RMS) by the scored
window.  What remains is the leak's phase lead (atan(0.01/f): 0.6 deg at 1 Hz)
and the order-4 reduction (< 0.01 dB): measured NRMSE 1.3 %, 0.9 %, 0.7 % at
1, 5, 20 Hz, against the required 5 %.
"""
from __future__ import annotations

import time
from pathlib import Path

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter

from ipmc_sensor_ros.nodes.estimator_node import EstimatorNode
from ipmc_sensor_ros.nodes.monitor import TrackingMonitor
from ipmc_sensor_ros.nodes.simulator_node import SimulatorNode
from conftest import TEST_DOMAIN
from process_graph import ProcessGraph

pytestmark = pytest.mark.ros

DURATION_S = 120.0
FS = 1000.0
N_SAMPLES = int(DURATION_S * FS)
NRMSE_LIMIT = 0.05
TIMEOUT_S = 120.0


def _sim_params(f_hz: float, duration_s: float = DURATION_S, realtime_factor: float = 0.0) -> dict:
    # 120 s in blocks of 200 = 600 messages per topic, fewer than the QoS depth of
    # 1000: even a stalled subscriber cannot lose one, so exact accounting does not
    # depend on scheduling (fast mode: one block per ms, real-time factor ~200).
    return {'motor_frequency_hz': f_hz, 'realtime_factor': realtime_factor, 'block_size': 200,
            'duration_s': duration_s, 'wait_for_subscribers': 1}


def _context_with_monitor(monkeypatch):
    """Return a fresh context on a random loopback domain, its executor and a monitor node."""
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=TEST_DOMAIN)
    ex = SingleThreadedExecutor(context=ctx)
    monitor_node = rclpy.create_node('monitor', context=ctx)
    ex.add_node(monitor_node)
    return ctx, ex, monitor_node


def test_in_process_pairs_track_truth_and_account_exactly(monkeypatch):
    ctx, ex, monitor_node = _context_with_monitor(monkeypatch)
    pairs = []
    try:
        for f in (1.0, 5.0, 20.0):
            ns = f'/f{int(f)}'
            monitor = TrackingMonitor(monitor_node, ns)
            est = EstimatorNode(context=ctx, namespace=ns, parameter_overrides=[
                Parameter('publish_points', value='last_of_block')])
            sim = SimulatorNode(context=ctx, namespace=ns, parameter_overrides=[
                Parameter(k, value=v) for k, v in _sim_params(f).items()])
            ex.add_node(est)
            ex.add_node(sim)
            pairs.append((f, sim, est, monitor))

        def finished():
            return all(sim.done and m.estimate_samples == N_SAMPLES for _, sim, _, m in pairs)

        end = time.monotonic() + TIMEOUT_S
        while not finished() and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
        for f, sim, est, monitor in pairs:
            c = est.counters()
            assert sim.counters()['samples_published'] == N_SAMPLES, f
            assert c['samples_in'] == c['samples_out'] == N_SAMPLES, (f, c)
            assert c['samples_rejected'] == c['samples_dropped'] == c['resets'] == 0, (f, c)
            assert monitor.estimate_samples == monitor.truth_samples == N_SAMPLES, f
            error, compared = monitor.score(last_s=20.0)
            # Every sample of the last 20 s is aligned (20000 or 20001 depending on how
            # the window edge rounds at the run's absolute start time).
            assert compared >= 20000, f
            print(f'in-process {f:g} Hz: NRMSE {error:.4f} over {compared} samples')
            assert error < NRMSE_LIMIT, (f, error)
    finally:
        ex.shutdown()
        for _, sim, est, _ in pairs:
            sim.destroy_node()
            est.destroy_node()
        monitor_node.destroy_node()
        rclpy.shutdown(context=ctx)


def test_estimator_improves_when_its_model_gains_the_hidden_effect(monkeypatch):
    """
    Issue 'discovery': the simulator hides a 40 Hz current-amplifier pole.

    An estimator with the plain H2 model misses its 14 deg phase lag at 10 Hz, one whose
    ``effects`` parameter names it tracks the truth. Two identical (seeded, deterministic)
    simulators feed the two estimators in namespaces /plain and /aware of one executor.
    """
    ctx, ex, monitor_node = _context_with_monitor(monkeypatch)
    hidden = ['amplifier_bandwidth(corner_hz=40)']
    nodes, monitors = [], {}
    try:
        for ns, est_effects in (('/plain', None), ('/aware', hidden)):
            monitors[ns] = TrackingMonitor(monitor_node, ns)
            est_params = [Parameter('publish_points', value='none')]
            if est_effects:
                est_params.append(Parameter('effects', value=est_effects))
            est = EstimatorNode(context=ctx, namespace=ns, parameter_overrides=est_params)
            sim = SimulatorNode(context=ctx, namespace=ns, parameter_overrides=[
                Parameter(k, value=v) for k, v in _sim_params(10.0).items()]
                + [Parameter('effects', value=hidden)])
            nodes += [est, sim]
            ex.add_node(est)
            ex.add_node(sim)
        end = time.monotonic() + TIMEOUT_S
        while (any(m.estimate_samples < N_SAMPLES for m in monitors.values())
               and time.monotonic() < end):
            ex.spin_once(timeout_sec=0.05)
        errors = {ns: m.score(last_s=20.0)[0] for ns, m in monitors.items()}
        print(
            f"hidden amplifier pole: NRMSE plain {errors['/plain']:.4f}, "
            f"aware {errors['/aware']:.4f}"
        )
        # A 14 deg phase error alone is a 25 % NRMSE; knowing the pole leaves the ~1 %
        # of the leak and the reduction.  "Measurably better": at least 5x, and < 5 %.
        assert errors['/aware'] < NRMSE_LIMIT
        assert errors['/plain'] > 5 * errors['/aware']
    finally:
        ex.shutdown()
        for n in nodes:
            n.destroy_node()
        monitor_node.destroy_node()
        rclpy.shutdown(context=ctx)


def test_two_processes_over_dds_track_truth_and_account_exactly(tmp_path, monkeypatch):
    _two_process_run(tmp_path, monkeypatch, DURATION_S, 0.0)


@pytest.mark.slow
def test_ten_minute_live_run_accounts_exactly(tmp_path, monkeypatch):
    """
    The reliability soak: 10 minutes paced in real time, two processes over DDS, exact accounting.

    Resident memory of each node flat (growth from 10 % of the run to its end within 5
    %).
    """
    rss = _two_process_run(tmp_path, monkeypatch, 600.0, 1.0)
    for name, (early, end) in rss.items():
        assert end <= 1.05 * early, (name, early, end)


def _rss_bytes(pid: int) -> int:
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) * 1024
    return 0


def _two_process_run(tmp_path, monkeypatch, duration_s: float, realtime_factor: float):
    """
    Run the simulator and estimator as two processes.

    Returns {name: (rss early, rss at end)}.
    """
    n_samples = int(duration_s * FS)
    timeout_s = TIMEOUT_S + 1.2 * duration_s * (realtime_factor > 0)
    graph = ProcessGraph(tmp_path, monkeypatch)
    monitor = TrackingMonitor(graph.node, '/rig')
    try:
        graph.start('estimator', 'estimator_node', {'publish_points': 'last_of_block'}, '/rig')
        # Start the simulator only once the monitor is matched with the estimator's
        # output; the simulator itself waits for its subscribers (wait_for_subscribers).
        graph.spin_until(lambda: monitor.subscriptions[0].get_publisher_count() > 0,
                         "the estimator's deflection/block publisher", timeout_s)
        graph.start('simulator', 'simulator_node', _sim_params(5.0, duration_s, realtime_factor),
                    '/rig')
        graph.spin_until(lambda: monitor.estimate_samples >= n_samples // 10, '10 % of the run',
                         timeout_s)
        rss_early = {name: _rss_bytes(p.pid) for name, p in graph.procs.items()}
        graph.spin_until(lambda: monitor.simulator_counters.get('done')
                         and monitor.estimator_counters.get('samples_out') == n_samples
                         and monitor.estimate_samples == n_samples
                         and monitor.truth_samples == n_samples, 'the run to complete',
                         timeout_s)
        error, compared = monitor.score(last_s=20.0)
        rss = {name: (rss_early[name], _rss_bytes(p.pid)) for name, p in graph.procs.items()}
    finally:
        codes = graph.close()

    sim_c, est_c = monitor.simulator_counters, monitor.estimator_counters
    print(f'two processes 5 Hz, {duration_s:g} s: NRMSE {error:.4f}; simulator {sim_c}; '
          f'estimator {est_c}; monitor received {monitor.estimate_samples} estimated / '
          f'{monitor.truth_samples} truth')
    assert sim_c['samples_published'] == n_samples
    assert est_c['samples_in'] == est_c['samples_out'] == n_samples
    assert est_c['messages_in'] == sim_c['blocks_published']
    assert est_c['samples_rejected'] == est_c['samples_dropped'] == est_c['resets'] == 0
    assert monitor.estimate_samples == monitor.truth_samples == n_samples
    assert compared >= 20000
    assert error < NRMSE_LIMIT
    assert codes == {'estimator': 0, 'simulator': 0}, graph.log_texts()
    print('resident memory (early, end) in MB: '
          + ', '.join(f'{k} {a / 2**20:.1f} -> {b / 2**20:.1f}' for k, (a, b) in rss.items()))
    return rss
