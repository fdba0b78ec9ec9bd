# SPDX-License-Identifier: Apache-2.0
"""
The estimator node in deployment (issue 30): one source per stream, nothing lost uncounted.

And /diagnostics saying so.  Two harnesses: the node driven through its subscription callback
with the message info a middleware delivers (``DirectNode``: deterministic), and the node with
real publishers over DDS in one process (the black-box reproduction of two publishers on
``current`` and of messages that never reach the node).
"""
from __future__ import annotations

import time

import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64MultiArray

from conftest import TEST_DOMAIN, DirectNode
from ipmc_sensor_ros.nodes.estimator_node import EstimatorNode
from ipmc_sensor_ros.nodes.messages import pack_block

FS = 1000.0
T0 = 100.0


def _info(gid: bytes, seq: int) -> dict:
    """Return the message info rclpy hands a subscription callback."""
    return {'source_timestamp': 0, 'received_timestamp': 0, 'publication_sequence_number': seq,
            'reception_sequence_number': None,
            'publisher_gid': {'implementation_identifier': 'rmw_fastrtps_cpp', 'data': gid}}


GID_A, GID_B = bytes(range(16)), bytes(range(1, 17))


def _send(node: DirectNode, t: float, i: float, gid: bytes, seq: int, pair=False) -> None:
    raw = serialize_message(pack_block(np.array([t]), np.array([i])))
    if pair:        # as rclpy 9.1.2's EventsExecutor calls it: (message, info) in one argument
        node.node._on_current_message((raw, _info(gid, seq)))
    else:
        node.node._on_current_message(raw, _info(gid, seq))


def _recorded(node) -> list:
    """Record the health of every /diagnostics evaluation (the node's timer runs too)."""
    seen = []
    update = node._diagnostics.update

    def recording(status):
        msg = update(status)
        seen.append(next(iter(node._diagnostics.last.values())))
        return msg
    node._diagnostics.update = recording
    return seen


def _diagnose(node) -> tuple[int, str]:
    """Evaluate /diagnostics now: (level, message) of the node's input channel."""
    node._diagnostics.update(node._status())
    health = next(iter(node._diagnostics.last.values()))
    return health.level, health.message


# -- DirectNode: the message info as the middleware delivers it ---------------------------
def test_a_second_publisher_is_ignored_counted_and_named():
    """Issue 30 item 2: a second publisher 0.3 ms later refused 9,999 of 10,000 samples."""
    d = DirectNode()
    try:
        _diagnose(d.node)
        rng = np.random.default_rng(0)
        i = 1e-6 * np.sin(2 * np.pi * 2 * np.arange(10_000) / FS) + rng.normal(0, 1e-8, 10_000)
        for k in range(10_000):
            t = T0 + k / FS
            _send(d, t, i[k], GID_A, k + 1, pair=k % 2 == 0)
            _send(d, t + 0.3e-3, i[k], GID_B, k + 1)
        c = d.node.counters()
        assert c['samples_out'] == 10_000 and c['samples_rejected'] == 0
        assert c['messages_ignored'] == 10_000 and c['resets'] == 0
        level, text = _diagnose(d.node)
        assert level == 1 and '10000 message(s) of other publishers ignored' in text
        assert f"gid {GID_B.hex('.')}: 10000" in text
        assert d.node.last_warning.startswith(f"ignoring messages of gid {GID_B.hex('.')}")
    finally:
        d.close()


def test_the_other_publisher_is_followed_once_the_first_is_silent(capfd):
    d = DirectNode(stale_after_s=0.2)
    try:
        for k in range(100):
            _send(d, T0 + k / FS, 1e-7, GID_A, k + 1)
            _send(d, T0 + 5.0 + k / FS, 1e-7, GID_B, k + 1)     # another run, ignored
        time.sleep(0.3)                                          # A silent > stale_after_s
        for k in range(100, 200):
            _send(d, T0 + 5.0 + k / FS, 1e-7, GID_B, k + 1)
        c = d.node.counters()
        assert c['source_switches'] == 1 and c['messages_ignored'] == 100
        assert c['samples_out'] == 200 and c['resets'] == 1      # B's stamps: a new run
        err = capfd.readouterr().err
        gid_b = GID_B.hex('.')
        assert f'silent on /current for more than stale_after_s = 0.2 s: now following gid ' \
            f'{gid_b}' in err
    finally:
        d.close()


def test_messages_that_never_arrived_are_counted_from_sequence_numbers():
    d = DirectNode(max_gap_s=1.0)
    try:
        _diagnose(d.node)
        seq = 0
        for k in range(2000):
            seq += 1
            if 1000 <= k < 1100:
                continue                       # 100 messages lost between publisher and node
            _send(d, T0 + k / FS, 1e-7, GID_A, seq)
        c = d.node.counters()
        assert c['messages_lost'] == 100 and c['samples_lost'] == 100
        assert c['gaps_bridged'] == 1 and c['resets'] == 0
        level, text = _diagnose(d.node)
        assert level == 1 and '5 % of the data lost before the node' in text
        assert '100 message(s) that never arrived' in text
    finally:
        d.close()


def test_diagnostics_warn_on_refused_and_lost_fractions_and_rate():
    d = DirectNode(loss_warn_fraction=0.01)
    try:
        _diagnose(d.node)
        rng = np.random.default_rng(2)
        t = T0 + np.arange(3000) / FS + rng.uniform(-0.2e-3, 0.2e-3, 3000)
        i = np.array([3e-8])            # a still sensor's 30 nA offset, under offset_warn_a
        for k in range(1000):                                   # clean: OK
            d.send(pack_block(t[k:k + 1], i))
        level, text = _diagnose(d.node)
        assert level == 0, text
        dup = set(range(1001, 1991, 33))                         # 30, none adjacent
        for k in range(1000, 2000):                             # 3 % duplicated stamps
            d.send(pack_block(t[k - 1:k] if k in dup else t[k:k + 1], i))
        level, text = _diagnose(d.node)
        assert level == 1 and '3 % of the samples refused (duplicate_stamp 30' in text
        kept = [k for k in range(2000, 3000) if k % 40]           # 2.5 % lost before the node
        for k in kept:
            d.send(pack_block(t[k:k + 1], i))
        level, text = _diagnose(d.node)
        assert level == 1 and '% of the data lost before the node (25 sample slot(s)' in text
    finally:
        d.close()


def test_a_rate_mismatch_is_reported_once_and_on_diagnostics(capfd):
    d = DirectNode()
    try:
        for k in range(2100):                                    # a 700 Hz DAQ, 3 s
            d.send(pack_block(np.array([T0 + k / 700.0]), np.array([1e-7])))
        level, text = _diagnose(d.node)
        assert level == 1 and 'sample rate 700 Hz (measured from the stamps)' in text
        err = capfd.readouterr().err
        assert err.count('measured sample rate 700') == 1
        assert d.node.counters()['rate_rebuilds'] == 1
        # the offset and mains-line estimates take the current at its measured rate
        d.node._on_timer()
        stats = next(iter(d.node._diagnostics._stats.values()))
        assert abs(stats.sample_rate_hz - 700.0) < 0.1
    finally:
        d.close()


# -- over DDS, in one process --------------------------------------------------------------
@pytest.fixture
def dds(monkeypatch):
    """Yield (context, executor, make_node) on the run's domain; all destroyed after."""
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=TEST_DOMAIN)
    ex = SingleThreadedExecutor(context=ctx)
    nodes = []

    def make(factory, *args, **kwargs):
        nodes.append(factory(*args, context=ctx, **kwargs))
        ex.add_node(nodes[-1])
        return nodes[-1]
    try:
        yield ctx, ex, make
    finally:
        ex.shutdown()
        for n in nodes:
            n.destroy_node()
        rclpy.shutdown(context=ctx)


def _spin_until(ex, done, timeout_s=20.0) -> None:
    end = time.monotonic() + timeout_s
    while not done() and time.monotonic() < end:
        ex.spin_once(timeout_sec=0.01)


def _estimator(make, **params):
    return make(EstimatorNode, parameter_overrides=[
        Parameter(k, value=v) for k, v in {'publish_points': 'none', **params}.items()])


@pytest.mark.ros
def test_two_publishers_on_current_over_dds(dds):
    ctx, ex, make = dds
    node = _estimator(make)
    seen = _recorded(node)
    pubs = [make(rclpy.node.Node, name) for name in ('daq_driver', 'stray_replayer')]
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    writers = [p.create_publisher(Float64MultiArray, 'current', qos) for p in pubs]
    _spin_until(ex, lambda: all(w.get_subscription_count() for w in writers))
    n = 2000
    for k in range(n):
        t = T0 + k / FS
        writers[0].publish(pack_block(np.array([t]), np.array([1e-7])))
        writers[1].publish(pack_block(np.array([t + 0.3e-3]), np.array([1e-7])))
        if k % 50 == 49:
            _spin_until(ex, lambda: node.counters()['messages_in']
                        + node.counters()['messages_ignored'] >= 2 * (k + 1) - 2, 5.0)
    _spin_until(ex, lambda: node.counters()['messages_in']
                + node.counters()['messages_ignored'] >= 2 * n)
    c = node.counters()
    # main: 9,999 of 10,000 refused, 'faster than sample_rate_hz'
    assert c['samples_out'] == n and c['samples_rejected'] == 0, c
    assert c['messages_ignored'] == n and c['messages_lost'] == 0
    _diagnose(node)
    warned = [h.message for h in seen if 'of other publishers ignored' in h.message]
    assert warned and all(h.level == 1 for h in seen if h.message in warned)
    assert '(/stray_replayer (gid' in warned[0] and 'following /daq_driver (gid' in warned[0]


@pytest.mark.ros
def test_messages_lost_before_the_node_over_dds_are_counted(dds):
    """Messages a full reader queue dropped: counted from sequence numbers, WARN."""
    ctx, ex, make = dds
    node = _estimator(make, qos_depth=20, max_gap_s=2.0)
    seen = _recorded(node)
    driver = make(rclpy.node.Node, 'daq_driver')
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    writer = driver.create_publisher(Float64MultiArray, 'current', qos)
    _spin_until(ex, lambda: writer.get_subscription_count() > 0)
    _diagnose(node)
    for k in range(100):
        writer.publish(pack_block(np.array([T0 + k / FS]), np.array([1e-7])))
        _spin_until(ex, lambda: node.counters()['samples_in'] > k, 5.0)
    for k in range(100, 1100):          # a burst while the node is not taking: its queue of
        writer.publish(pack_block(np.array([T0 + k / FS]), np.array([1e-7])))   # 20 overflows
    _spin_until(ex, lambda: node.counters()['samples_in'] >= 120, 10.0)
    time.sleep(0.2)
    _spin_until(ex, lambda: False, 0.5)
    c = node.counters()
    lost = 1000 - (c['samples_in'] - 100)
    assert lost > 900, c                         # at most a queue's worth arrived
    assert c['messages_lost'] == lost and c['samples_lost'] == lost, c
    assert c['resets'] == 0 and c['gaps_bridged'] == 1
    _diagnose(node)
    assert any(h.level == 1 and f'{lost} message(s) that never arrived' in h.message
               for h in seen), [h.message for h in seen]
