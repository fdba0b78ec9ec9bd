# SPDX-License-Identifier: Apache-2.0
"""
Unit tests of the ROS 2 layer: message layout helpers and the nodes in-process.

Every node test runs in its own rclpy Context on a random ROS_DOMAIN_ID in
100..200 with discovery limited to localhost, so parallel runs do not cross-talk.
Nothing here asserts on timing: waits poll a condition with a generous timeout.
"""
from __future__ import annotations

import json
import random
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import rclpy
import yaml
from geometry_msgs.msg import PointStamped
from rclpy.exceptions import ParameterException
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, String

from ipmc_sensor_ros.estimation.deflection import DeflectionEstimator
from ipmc_sensor_ros.estimation.kalman import KalmanEstimator
from ipmc_sensor_ros.estimation.stream import StreamEstimator
from ipmc_sensor_ros.nodes import params as P
from ipmc_sensor_ros.nodes import topics as T
from ipmc_sensor_ros.nodes.estimator_node import ESTIMATOR_SPECS, EstimatorNode
from ipmc_sensor_ros.nodes.messages import (
    CURRENT_COLUMNS,
    DEFLECTION_COLUMNS,
    ESTIMATE_COLUMNS,
    DataError,
    claimed_samples,
    pack_block,
    unpack_block,
    BlockPacker,
    OneSampleCodec,
    PointCodec,
    point_message,
)
from ipmc_sensor_ros.nodes.simulator_node import SIMULATOR_SPECS, SimulatorNode
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.parameters import Geometry
from ipmc_sensor_ros.lti.reduction import reduce_model
from ipmc_sensor_ros.simulation.sensor import SensorSimulator
from ipmc_sensor_ros.simulation.stimuli import CrankSlider
from conftest import TEST_DOMAIN

pytestmark = pytest.mark.ros

ROOT = Path(__file__).resolve().parents[1]
FS = 1000.0
SLIM = Geometry(0.022, 0.007, 0.00036)
MODEL = SensorModel.named('h2', SLIM)
T0 = 1000.0   # sample time of the first test sample, s
TIMEOUT_S = 30.0


@pytest.fixture(scope='module')
def reduced():
    return reduce_model(MODEL, 4, (0.1, 50.0))


def reference(reduced, **kw) -> KalmanEstimator:
    """Return the core estimator the node must reproduce with default parameters (kalman)."""
    return KalmanEstimator(reduced, FS, **kw)


def crank_record(seconds: float, f_hz: float = 5.0):
    """(times_s, deflection_m, current_a) of the slim sample driven by the crank-slider."""
    k = np.arange(int(round(seconds * FS)))
    w, i = SensorSimulator(MODEL, FS).run(CrankSlider(f_hz), k / FS)
    return T0 + k / FS, w, i


# ---------------------------------------------------------------------------
# messages.py
# ---------------------------------------------------------------------------
@pytest.mark.parametrize('n', [1, 7, 1000])
def test_pack_unpack_round_trip_is_exact(n):
    rng = np.random.default_rng(n)
    t = 1.7e9 + np.arange(n) * 1e-3
    v = rng.normal(size=n) * 1e-6
    msg = pack_block(t, v, CURRENT_COLUMNS)
    dims = msg.layout.dim
    assert [(d.label, d.size, d.stride) for d in dims] == [('sample', n, 2 * n),
                                                           (CURRENT_COLUMNS, 2, 2)]
    assert list(msg.data[:2]) == [t[0], v[0]]          # interleaved (t_0, i_0, ...)
    block = unpack_block(msg, CURRENT_COLUMNS)
    assert np.array_equal(block.times_s, t) and np.array_equal(block.values, v)
    assert claimed_samples(msg) == n


def test_block_packer_reuses_one_message_and_follows_length_changes():
    """
    The node's reused output message.

    Each pack is exact, including after the block length changes (1 -> 5 ->
    1), and it is the same object every time.
    """
    packer = BlockPacker(DEFLECTION_COLUMNS)
    first = None
    for n in (1, 1, 5, 1):
        t = 2.0 + np.arange(n) * 1e-3
        w = np.linspace(-1e-3, 2e-3, n)
        msg = packer.pack(t, w)
        first = first or msg
        assert msg is first
        block = unpack_block(msg, DEFLECTION_COLUMNS)
        assert np.array_equal(block.times_s, t) and np.array_equal(block.values, w)
        assert claimed_samples(msg) == n


def _same_bits(a, b) -> bool:
    bits = [np.asarray(x, float).view(np.uint64) for x in (a, b)]
    return np.array_equal(*bits)


@pytest.mark.parametrize('columns', [CURRENT_COLUMNS, ESTIMATE_COLUMNS])
def test_one_sample_codec_matches_rclpy_serialisation(columns):
    """
    The one-sample hot path reads and writes what rclpy's serialiser reads and writes.

    Written bytes deserialise to the packed message (bit for bit, incl. -0.0, inf, NaN,
    subnormals) and differ from ``serialize_message`` only in padding bytes (rclpy leaves
    buffer contents there); bytes from rclpy read back the same floats, whatever their
    padding holds; any other message reads as None.
    """
    from rclpy.serialization import deserialize_message, serialize_message

    codec = OneSampleCodec(columns)
    width = len(columns.split(','))
    rows = [(1795e6 + 0.123456789, -3.5e-7, 1e-9, 1.0)[:width],
            (0.0, -0.0, float('inf'), 0.0)[:width], (5e-324, float('nan'), -1e308, -0.0)[:width]]
    for row in rows:
        msg = BlockPacker(columns).pack_one(*row)
        raw = serialize_message(msg)
        mine = codec.encode(*row)
        back = deserialize_message(mine, Float64MultiArray)
        assert back.layout == msg.layout and _same_bits(back.data, row)
        assert len(mine) == len(raw) and mine[-8 * width:] == raw[-8 * width:]
        assert _same_bits(codec.decode(raw), row)
        in_spans = {p for a, b in codec._spans for p in range(a, b)}
        pads = [p for p in range(len(raw) - 8 * width) if p not in in_spans]
        assert pads                                     # both layouts have padded labels
        garbage = bytearray(raw)                        # any padding content reads the same
        for p in pads:
            garbage[p] = 0xA5
        assert _same_bits(codec.decode(bytes(garbage)), row)
        for p in sorted(in_spans)[::7]:                 # a changed data byte does not
            changed = bytearray(raw)
            changed[p] ^= 0x10
            assert codec.decode(bytes(changed)) is None
    other = 'time_s,deflection_m' if columns == CURRENT_COLUMNS else CURRENT_COLUMNS
    two_rows = serialize_message(BlockPacker(columns).pack(*([np.arange(2.0)] * width)))
    for raw in (serialize_message(BlockPacker(other).pack_one(*([1.0] * len(other.split(','))))),
                two_rows, serialize_message(Float64MultiArray()), b'', b'\x00\x01\x00\x00'):
        assert codec.decode(raw) is None


def test_point_codec_matches_point_message():
    """The serialised tip point deserialises to :func:`point_message` (bit for bit)."""
    from rclpy.serialization import deserialize_message

    for length, frame in ((0.022, 'ipmc_clamp'), (0.011, 'a/b_long.frame-name_xyz'),
                          (0.02, 'odd')):
        codec = PointCodec(length, frame)
        for t, w in ((1795424281.153031770, 1.25e-3), (0.0, -0.0), (12.5e-9, -2e-3)):
            assert deserialize_message(codec.encode(t, w), PointStamped) == point_message(
                t, length, w, frame)


def test_unpack_honours_data_offset_and_accepts_one_dimensional():
    msg = pack_block([1.0, 1.001], [2e-6, 3e-6])
    msg.data = [99.0] + list(msg.data)
    msg.layout.data_offset = 1
    block = unpack_block(msg)
    assert np.array_equal(block.times_s, [1.0, 1.001]) and np.array_equal(
        block.values, [2e-6, 3e-6]
    )
    plain = Float64MultiArray(data=[1e-6, 2e-6, 3e-6])
    b = unpack_block(plain)
    assert b.times_s is None and np.array_equal(b.values, [1e-6, 2e-6, 3e-6])
    one = Float64MultiArray(data=[1e-6, 2e-6])
    one.layout.dim = [MultiArrayDimension(label='current_A', size=2, stride=2)]
    assert unpack_block(one).times_s is None
    assert claimed_samples(plain) == 3


def _dims(msg, i, **kw):
    for k, v in kw.items():
        setattr(msg.layout.dim[i], k, v)
    return msg


MALFORMED = {
    'three dims': (lambda m: m.layout.dim.append(MultiArrayDimension(label='x', size=1, stride=1)),
                   'expected 2 dimensions'),
    'row label': (lambda m: _dims(m, 0, label='row'), 'dim[0].label'),
    'column label': (lambda m: _dims(m, 1, label='time_s,current_mA'), 'dim[1].label'),
    'column size': (lambda m: _dims(m, 1, size=3), 'size 2 and stride 2'),
    'row size': (lambda m: _dims(m, 0, size=5), 'dim[0] is (size 5'),
    'row stride': (lambda m: _dims(m, 0, stride=3), 'dim[0].stride'),
    'odd length': (lambda m: setattr(m, 'data', list(m.data) + [1.0]), 'odd'),
    'offset': (lambda m: setattr(m.layout, 'data_offset', 100), 'data_offset'),
    '1-D size': (lambda m: (m.layout.dim.pop(), _dims(m, 0, size=3)), '1-D layout'),
}


@pytest.mark.parametrize('case', sorted(MALFORMED))
def test_malformed_layouts_are_refused_with_a_reason(case):
    mutate, needle = MALFORMED[case]
    msg = pack_block([1.0, 1.001, 1.002, 1.003], [1e-6] * 4)
    mutate(msg)
    with pytest.raises(DataError, match=None) as err:
        unpack_block(msg, CURRENT_COLUMNS)
    assert needle in str(err.value)


# ---------------------------------------------------------------------------
# In-process harness
# ---------------------------------------------------------------------------
class Harness:
    """One context, the node under test, a tester node publishing ``current``."""

    def __init__(self, node_cls=EstimatorNode, overrides=(), use_sim_time=False):
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=TEST_DOMAIN)
        params = [Parameter(k, value=v) for k, v in dict(overrides).items()]
        if use_sim_time:
            params.append(Parameter('use_sim_time', value=True))
        self.node = node_cls(context=self.ctx, parameter_overrides=params)
        self.tester = rclpy.create_node('tester', context=self.ctx)
        qos = T.make_qos({'qos_depth': 1000, 'qos_reliability': 'reliable'})
        self.pub = self.tester.create_publisher(Float64MultiArray, 'current', qos)
        self.blocks: list = []
        self.points: list[PointStamped] = []
        self.truth: list = []
        self.counters_msgs: list[dict] = []
        self.tester.create_subscription(
            Float64MultiArray, 'deflection/block',
            lambda m: self.blocks.append(unpack_block(m, ESTIMATE_COLUMNS)), qos)
        self.tester.create_subscription(PointStamped, 'deflection', self.points.append, qos)
        self.tester.create_subscription(
            Float64MultiArray, 'deflection_truth',
            lambda m: self.truth.append(unpack_block(m, DEFLECTION_COLUMNS)), qos)
        self.currents: list = []
        self.tester.create_subscription(Float64MultiArray, 'current', self._on_current, qos)
        for topic in ('estimator/counters', 'simulator/counters'):
            self.tester.create_subscription(
                String, topic, lambda m: self.counters_msgs.append(json.loads(m.data)),
                T.COUNTERS_QOS)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.ex.add_node(self.tester)

    def _on_current(self, msg):
        try:
            self.currents.append(unpack_block(msg))
        except DataError:
            pass        # the estimator tests send malformed messages on purpose

    def spin_until(self, predicate, timeout=TIMEOUT_S):
        end = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > end:
                raise AssertionError('condition not reached within the timeout')
            self.ex.spin_once(timeout_sec=0.05)

    def send(self, msg) -> None:
        """Publish one message and spin until the node has handled it and its output arrived."""
        if self.pub.get_subscription_count() == 0:
            self.spin_until(lambda: self.pub.get_subscription_count() > 0)
        n_in = self.node.counters()['messages_in']
        self.pub.publish(msg)
        self.spin_until(lambda: self.node.counters()['messages_in'] == n_in + 1)
        self.spin_until(
            lambda: sum(len(b) for b in self.blocks) == self.node.counters()['samples_out']
        )

    def outputs(self) -> np.ndarray:
        return np.concatenate([b.values for b in self.blocks]) if self.blocks else np.empty(0)

    def close(self):
        self.ex.shutdown()
        self.node.destroy_node()
        self.tester.destroy_node()
        rclpy.shutdown(context=self.ctx)


@pytest.fixture
def harness(request):
    made = []

    def make(**kw):
        h = Harness(**kw)
        made.append(h)
        return h

    yield make
    for h in made:
        h.close()


def check_accounting(c: dict) -> None:
    assert c['samples_in'] == c['samples_out'] + c['samples_rejected'] + c['samples_dropped']


# ---------------------------------------------------------------------------
# Estimator node
# ---------------------------------------------------------------------------
def test_bad_messages_are_rejected_and_leave_the_filter_untouched(harness, reduced):
    h = harness(overrides={'publish_points': 'none', 'max_block_samples': 500})
    t, _, i = crank_record(2.0)
    valid = [(t[k:k + 100], i[k:k + 100]) for k in range(0, 2000, 100)]

    def bad_messages(tb, ib):
        """Bad variants of the *next* valid block, refused whole: any would change the output."""
        wrong_label = pack_block(tb, ib)
        wrong_label.layout.dim[1].label = 'time_s,current_mA'
        odd = pack_block(tb, ib)
        odd.data = list(odd.data)[:-1]
        big = np.full(600, 1e-6)
        return [
            (pack_block(tb, np.full(ib.size, np.nan)), 'non-finite'),
            (pack_block(tb, np.full(ib.size, np.inf)), 'non-finite'),
            (Float64MultiArray(), 'empty'),
            (pack_block(T0 + 50 + np.arange(600) / FS, big), 'limit 500'),
            (wrong_label, 'dim[1].label'),
            (odd, 'odd'),
            (pack_block(tb[:10] - 0.02, ib[:10]), 'behind the previous sample'),  # late
            (pack_block(tb, ib + 5.0), 'within +-1.0 A'),
            (pack_block(tb - 2 * T0, ib), 'must lie in'),
            (b'\x00\x01\x00\x00\x02\x00\x00\x00\xff', 'undecodable'),  # truncated CDR
        ]

    n_bad = 0
    for k, (tb, ib) in enumerate(valid):
        if k in (3, 11):                   # after a valid block: a late block is behind it
            for msg, reason in bad_messages(tb, ib):
                h.send(msg)
                n_bad += 1
                assert reason in h.node.last_rejection
        h.send(pack_block(tb, ib))

    ref = reference(reduced).estimate(i).deflection_m
    out = h.outputs()
    assert out.shape == ref.shape
    # Identical arithmetic on identical blocks: only float rounding could differ.
    assert np.max(np.abs(out - ref)) <= 1e-12
    assert np.array_equal(np.concatenate([b.times_s for b in h.blocks]), t)
    c = h.node.counters()
    assert c['messages_in'] == len(valid) + n_bad
    assert c['messages_rejected'] == n_bad
    assert c['samples_out'] == 2000
    assert c['resets'] == 0 and c['samples_dropped'] == 0
    check_accounting(c)


def test_backward_time_jump_resets_the_filter_and_warns(harness, reduced, capfd):
    h = harness(overrides={'publish_points': 'none'})
    t, _, i = crank_record(1.0)
    for k in range(0, 1000, 250):
        h.send(pack_block(t[k:k + 250], i[k:k + 250]))
    # Replay from the start (rosbag play --loop, clock reset): last sample 0.999 s -> 0 s.
    h.send(pack_block(t[:250], i[:250]))
    c = h.node.counters()
    assert c['resets'] == 1 and c['gaps'] == 0 and c['messages_rejected'] == 0
    assert 'time jumped back by 0.999 s on /current: filter reset' in h.node.last_warning
    assert 'time jumped back by' in capfd.readouterr().err
    # After the reset the output is that of a fresh filter fed the replayed block.
    replay = h.blocks[-1].values
    assert np.max(np.abs(replay - reference(reduced).estimate(i[:250]).deflection_m)) <= 1e-12
    check_accounting(c)


def test_long_gap_resets_short_gap_is_bridged(harness, reduced):
    h = harness(overrides={'publish_points': 'none', 'max_gap_s': 0.1})
    t, _, i = crank_record(1.0)
    h.send(pack_block(t[:100], i[:100]))
    h.send(pack_block(t[150:250], i[150:250]))    # 50 ms missing: bridged, no reset
    c = h.node.counters()
    assert c['gaps'] == 0 and c['resets'] == 0 and c['gaps_bridged'] == 1
    h.send(pack_block(t[500:600], i[500:600]))    # 250 ms missing > max_gap_s: reset
    c = h.node.counters()
    assert c['gaps'] == 1 and c['resets'] == 1
    assert 'gap of 0.25' in h.node.last_warning
    expected = reference(reduced).estimate(i[500:600]).deflection_m
    assert np.max(np.abs(h.blocks[-1].values - expected)) <= 1e-12


def test_one_dimensional_messages_infer_times_and_per_sample_points(harness, reduced):
    h = harness(overrides={'frame_id': 'beam', 'publish_points': 'per_sample'})
    _, _, i = crank_record(0.3)
    for k in range(0, 300, 60):
        h.send(Float64MultiArray(data=i[k:k + 60].tolist()))
    h.spin_until(lambda: len(h.points) == 300)
    times = np.concatenate([b.times_s for b in h.blocks])
    # Spacing 1/fs from the node clock at the first sample (no gap detection in this mode).
    assert np.allclose(np.diff(times), 1.0 / FS, rtol=0, atol=1e-6)
    assert np.max(np.abs(h.outputs() - reference(reduced).estimate(i).deflection_m)) <= 1e-12
    p = h.points[-1]
    assert p.header.frame_id == 'beam' and p.point.x == pytest.approx(0.022) and p.point.y == 0.0
    assert p.point.z == h.outputs()[-1]
    stamp = p.header.stamp.sec + p.header.stamp.nanosec * 1e-9
    assert stamp == pytest.approx(times[-1], abs=1e-6)   # float-seconds resolution ~0.24 us


def test_last_of_block_points_and_counters_topic_under_sim_time(harness):
    # use_sim_time without /clock: the node clock reads 0, yet stamps come from the
    # sample times and the counters (steady-clock timer) still flow.
    h = harness(overrides={'publish_points': 'last_of_block'}, use_sim_time=True)
    assert h.node.get_clock().now().nanoseconds == 0
    t, _, i = crank_record(0.5)
    for k in range(0, 500, 100):
        h.send(pack_block(t[k:k + 100], i[k:k + 100]))
    h.spin_until(lambda: len(h.points) == 5)
    assert [p.header.stamp.sec + p.header.stamp.nanosec * 1e-9 for p in h.points] == \
        pytest.approx(t[99::100], abs=1e-6)
    h.spin_until(lambda: any(m.get('samples_out') == 500 for m in h.counters_msgs))
    last = [m for m in h.counters_msgs if m.get('samples_out') == 500][-1]
    assert last['samples_in'] == 500 and last['node'] == '/ipmc_estimator'


def _record_smoothed(h) -> list:
    """Return the list the tester fills with the node's ``deflection/smoothed/block`` blocks."""
    smoothed = []
    h.tester.create_subscription(
        Float64MultiArray, 'deflection/smoothed/block',
        lambda m: smoothed.append(unpack_block(m, ESTIMATE_COLUMNS)),
        T.make_qos({'qos_depth': 1000, 'qos_reliability': 'reliable'}))
    return smoothed


def test_smoothed_output_is_the_stream_cores_with_each_sample_once(harness):
    h = harness(overrides={'publish_points': 'none', 'smoothed_lag_s': 0.05})
    smoothed = _record_smoothed(h)
    # 0.95 s: before the 1 s check, where the crank's periodic motion is modelled and the
    # lagged samples are flushed with the old model
    t, _, i = crank_record(0.95)
    core = StreamEstimator(DeflectionEstimator(MODEL, FS, smoothed_lag_s=0.05))
    expected = []
    for k in range(0, 950, 70):
        h.send(pack_block(t[k:k + 70], i[k:k + 70]))
        core.feed(t[k:k + 70], i[k:k + 70])
        out = core.pop_smoothed()
        expected += [] if out is None else [out]
    want_t = np.concatenate([e[0] for e in expected])
    h.spin_until(lambda: sum(len(b) for b in smoothed) == want_t.size)
    got = np.concatenate([b.values for b in smoothed])
    # the node is a thin shell around the stream core: the same numbers, the same samples
    assert np.array_equal(np.concatenate([b.times_s for b in smoothed]), want_t)
    assert np.max(np.abs(got - np.concatenate([e[1] for e in expected]))) <= 1e-12
    std = np.concatenate([b.extra[:, 0] for b in smoothed])
    assert np.max(np.abs(std - np.concatenate([e[2] for e in expected]))) <= 1e-12
    # 950 samples, lag 50: all but the last 50 to 99 are out, the oldest first
    assert 850 < want_t.size <= 900 and want_t[0] == t[0]


def test_node_shutdown_publishes_the_samples_the_smoother_still_holds(harness):
    """Destroying the node (SIGINT, the end of a launch) sends the held samples first."""
    h = harness(overrides={'publish_points': 'none', 'smoothed_lag_s': 0.05})
    smoothed = _record_smoothed(h)
    t, _, i = crank_record(0.3)
    for k in range(0, 300, 70):
        h.send(pack_block(t[k:k + 70], i[k:k + 70]))
    h.spin_until(lambda: len(smoothed) > 0)
    live_t = np.concatenate([b.times_s for b in h.blocks])
    assert sum(b.times_s.size for b in smoothed) < live_t.size     # some are held back
    h.ex.remove_node(h.node)
    h.node.destroy_node()
    h.node = rclpy.create_node('destroyed_already', context=h.ctx)  # for the fixture's close
    h.spin_until(lambda: sum(b.times_s.size for b in smoothed) >= live_t.size)
    # each accepted sample once, in order: the last ones smoothed with the data there was
    assert np.array_equal(np.concatenate([b.times_s for b in smoothed]), live_t)


def test_invalid_parameter_changes_are_refused_with_reason(harness, reduced):
    h = harness(overrides={'publish_points': 'none'})
    before = h.node.estimator
    cases = {
        'length_m': (-1.0, 'length_m'),
        'reduction_order': (99, 'reduction_order'),
        'sample_rate_hz': (500.0, 'read-only'),
        'qos_depth': (10, 'read-only'),
        'youngs_modulus_pa': (-5.0, 'youngs_modulus_pa'),
        'model': ('h3', 'must be one of'),
        'effects': (['bogus'], "unknown effect 'bogus'"),
        'publish_points': ('all', 'publish_points'),
        'band_low_hz': (80.0, 'band_low_hz'),
        'leak_corner_hz': (600.0, 'leak_corner_hz'),
    }
    for name, (value, needle) in cases.items():
        result = h.node.set_parameters([Parameter(name, value=value)])[0]
        assert not result.successful, name
        assert needle in result.reason, (name, result.reason)
    assert h.node.estimator is before
    assert h.node.get_parameter('length_m').value == 0.022
    # The refused changes left no trace: output equals the default core estimator.
    t, _, i = crank_record(0.5)
    for k in range(0, 500, 100):
        h.send(pack_block(t[k:k + 100], i[k:k + 100]))
    assert np.max(np.abs(h.outputs() - reference(reduced).estimate(i).deflection_m)) <= 1e-12


def test_valid_setting_change_is_applied_without_an_output_jump(harness, reduced):
    h = harness(overrides={'publish_points': 'none'})
    t, w, i = crank_record(11.0, f_hz=1.0)
    cut = 10000                      # at 10 s the 1 Hz crank is at its peak (2 mm)
    for k in range(0, cut, 1000):
        h.send(pack_block(t[k:k + 1000], i[k:k + 1000]))
    result = h.node.set_parameters([Parameter('motion_corner_hz', value=2.0)])[0]
    assert result.successful, result.reason
    assert h.node.estimator.config.motion_corner_hz == 2.0
    h.send(pack_block(t[cut:cut + 100], i[cut:cut + 100]))
    before, after = h.blocks[-2].values[-1], h.blocks[-1].values[0]
    unchanged = reference(reduced).estimate(i[:cut + 1]).deflection_m[-1]
    # The rebuilt filter carries the whole state (same sensor: the charge states too), so its
    # first sample differs from the unchanged filter's only by one step of another prior; one
    # sample of a 1 Hz, 2 mm crank moves the tip by up to 13 um, so 10 um bounds a jump.
    # A reset or a fresh filter would be off by about 1.8 mm.
    assert abs(after - unchanged) <= 10e-6
    assert abs(after - before) <= 10e-6
    # A model change is applied too (new reduction) and refused values are not stored.
    assert h.node.set_parameters([Parameter('length_m', value=0.02)])[0].successful
    assert h.node.estimator.reduced is not reduced


def test_effects_current_offset_is_removed_and_delay_restamps(harness, reduced):
    h = harness(
        overrides={
            'publish_points': 'none',
            'effects': ['current_offset(offset_a=1e-6)', 'time_delay(delay_s=0.002)'],
        }
    )
    t, _, i = crank_record(0.5)
    for k in range(0, 500, 100):
        h.send(pack_block(t[k:k + 100], i[k:k + 100] + 1e-6))
    # The offset is subtracted before the filter; the pure delay is not inverted
    # but re-stamped: output times are input times minus 2 ms.
    delayed = SensorModel.named('h2', SLIM, extra_effects='time_delay(delay_s=0.002)')
    ref = reference(reduce_model(delayed, 4, (0.1, 50.0))).estimate(i).deflection_m
    assert np.max(np.abs(h.outputs() - ref)) <= 1e-12
    assert np.allclose(np.concatenate([b.times_s for b in h.blocks]), t - 0.002, rtol=0, atol=1e-9)


def test_invalid_startup_parameters_raise_naming_the_parameter():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=TEST_DOMAIN)
    try:
        for name, value, needle in [('length_m', -1.0, 'length_m'),
                                    ('youngs_modulus_pa', -5.0, 'youngs_modulus_pa'),
                                    ('effects', ['warp_drive'], 'warp_drive'),
                                    ('publish_points', 'all', 'publish_points'),
                                    ('smoothed_lag_s', -1.0, 'smoothed_lag_s')]:
            with pytest.raises((P.ParameterError, ParameterException)) as err:
                EstimatorNode(context=ctx, parameter_overrides=[Parameter(name, value=value)])
            assert needle in str(err.value)
        # Non-LTI and time-varying effects are simulated and estimated (core SensorSimulator /
        # DeflectionEstimator), so both nodes accept them.
        for node_cls in (EstimatorNode, SimulatorNode):
            node = node_cls(context=ctx, parameter_overrides=[Parameter(
                'effects', value=['nonlinearity(quadratic=0.5)',
                                  'hydration_drift(diffusivity_rate_per_s=-0.001)'])])
            node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


def test_main_exits_nonzero_with_one_clear_line(tmp_path):
    env = {'PYTHONPATH': str(ROOT), 'ROS_DOMAIN_ID': str(random.randint(150, 200)),
           'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST', 'PATH': '/usr/bin:/bin',
           'HOME': str(tmp_path), 'ROS_LOG_DIR': str(tmp_path)}
    proc = subprocess.run([sys.executable, '-m', 'ipmc_sensor_ros.nodes.estimator_node',
                           '--ros-args', '-p', 'thickness_m:=0.36'],
                          env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert 'thickness_m' in proc.stderr and 'Traceback' not in proc.stderr


def _yaml_params(path: Path, key: str) -> dict:
    doc = yaml.safe_load(path.read_text())
    return doc[key]['ros__parameters']


@pytest.mark.parametrize(
    'file,key,specs',
    [
        ('estimator.yaml', '/**/ipmc_estimator', ESTIMATOR_SPECS),
        ('simulator.yaml', '/**/ipmc_simulator', SIMULATOR_SPECS),
    ],
)
def test_config_files_list_every_parameter_with_its_default(file, key, specs):
    values = _yaml_params(ROOT / 'config' / file, key)
    for spec in specs:
        if spec.kind is list:
            continue            # empty string arrays cannot be typed in YAML: documented
        assert spec.name in values, spec.name
        assert (
            values[spec.name] == spec.default and type(values[spec.name]) is spec.kind
        ), spec.name


def test_params_file_is_applied_in_any_namespace(tmp_path):
    text = (ROOT / 'config' / 'estimator.yaml').read_text().replace(
        'length_m: 0.022', 'length_m: 0.011')
    path = tmp_path / 'est.yaml'
    path.write_text(text)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=TEST_DOMAIN,
               args=['--ros-args', '--params-file', str(path)])
    try:
        node = EstimatorNode(context=ctx, namespace='/rig3')
        assert node.get_parameter('length_m').value == 0.011
        assert node.input_topic == '/rig3/current'
        node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


# ---------------------------------------------------------------------------
# Simulator node
# ---------------------------------------------------------------------------
def test_simulator_fast_mode_publishes_exactly_the_core_simulation(harness):
    h = harness(node_cls=SimulatorNode,
                overrides={'realtime_factor': 0.0, 'duration_s': 0.95, 'block_size': 100,
                           'motor_frequency_hz': 5.0, 'wait_for_subscribers': 1})
    h.spin_until(lambda: h.node.done)
    h.spin_until(lambda: sum(len(b) for b in h.currents) == 950 and
                 sum(len(b) for b in h.truth) == 950)
    assert h.node.counters() == {'samples_published': 950, 'blocks_published': 10, 'done': True}
    t = np.concatenate([b.times_s for b in h.currents])
    i = np.concatenate([b.values for b in h.currents])
    w = np.concatenate([b.values for b in h.truth])
    assert np.array_equal(t, np.concatenate([b.times_s for b in h.truth]))
    assert [len(b) for b in h.currents][-1] == 50            # the last block is truncated
    k = np.arange(950)
    assert np.allclose(t - t[0], k / FS, rtol=0, atol=1e-6)
    w_ref, i_ref = SensorSimulator(MODEL, FS).run(CrankSlider(5.0), k / FS)
    assert np.max(np.abs(w - w_ref)) <= 1e-15 and np.max(np.abs(i - i_ref)) <= 1e-18
    h.spin_until(lambda: any(m.get('done') for m in h.counters_msgs))


def test_simulator_file_stimulus_and_csv_errors(harness, tmp_path):
    csv = tmp_path / 'w.csv'
    tt = np.arange(0.0, 2.0, 0.01)
    ww = 1e-3 * np.sin(2 * np.pi * tt)
    csv.write_text('# recorded tip deflection\ntime_s,deflection_m\n'
                   + '\n'.join(f'{a:.17g},{b:.17g}' for a, b in zip(tt + 5.0, ww)) + '\n')
    h = harness(node_cls=SimulatorNode,
                overrides={'stimulus': 'file', 'stimulus_file': str(csv), 'realtime_factor': 0.0,
                           'duration_s': 0.5, 'block_size': 50, 'wait_for_subscribers': 1})
    h.spin_until(lambda: sum(len(b) for b in h.truth) == 500)
    w = np.concatenate([b.values for b in h.truth])
    # Cubic spline through 100 Hz samples of a 1 Hz sine: error << 1e-3 of the amplitude.
    assert np.max(np.abs(w - 1e-3 * np.sin(2 * np.pi * np.arange(500) / FS))) < 1e-7
    bad = tmp_path / 'bad.csv'
    bad.write_text('0.0,1.0\n0.1,oops\n')
    with pytest.raises(P.ParameterError, match='bad.csv:2'):
        SimulatorNode(context=h.ctx, parameter_overrides=[
            Parameter('stimulus', value='file'), Parameter('stimulus_file', value=str(bad))])


def test_sim_time_drives_the_simulator_and_stamps(harness):
    from rosgraph_msgs.msg import Clock

    h = harness(node_cls=SimulatorNode, use_sim_time=True,
                overrides={'realtime_factor': 1.0, 'block_size': 10})
    clock_pub = h.tester.create_publisher(Clock, '/clock', 10)

    def tick(t_s):
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = int(t_s), int(round((t_s % 1) * 1e9))
        clock_pub.publish(msg)
        for _ in range(20):
            h.ex.spin_once(timeout_sec=0.01)

    h.spin_until(lambda: clock_pub.get_subscription_count() > 0)
    for _ in range(5):          # no /clock yet: the node clock reads 0 and nothing is sent
        h.ex.spin_once(timeout_sec=0.02)
    assert h.node.counters()['samples_published'] == 0
    t_s = 500.0
    while h.node.counters()['samples_published'] < 100:
        tick(t_s)
        t_s += 0.01
        assert t_s < 520.0, 'simulator did not follow /clock'
    h.spin_until(lambda: len(h.currents) > 0)
    first = h.currents[0].times_s[0]
    # Stamps come from the simulated clock (~500 s), not from the wall clock (~1.7e9 s).
    assert 500.0 <= first < 501.0
    published_until = max(b.times_s[-1] for b in h.currents)
    assert published_until <= t_s + 1e-9       # never ahead of the node clock at rtf = 1


def test_docs_parameter_tables_match_the_declared_parameters():
    from ipmc_sensor_ros.interface.simulator import SIMULATOR_OWN_SPECS

    doc = (ROOT / 'docs' / 'ros_interface.md').read_text()
    # Generated from the specs: regenerate with python scripts/gen_docs.py if this fails.
    assert P.markdown_table(ESTIMATOR_SPECS) in doc
    assert P.markdown_table(SIMULATOR_OWN_SPECS) in doc


def test_plugin_effect_is_used_by_the_estimator_node():
    from ipmc_sensor_ros.physics.effects import EFFECTS

    plugin = ROOT / 'examples' / 'polymer_leakage.py'
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=TEST_DOMAIN)
    try:
        node = EstimatorNode(context=ctx, parameter_overrides=[
            Parameter('plugins', value=[str(plugin)]),
            Parameter('effects', value=['polymer_leakage(time_constant_s=0.05)'])])
        assert (
            'polymer_leakage(time_constant_s=0.05)' in node.deflection_estimator.model.describe()
        )
        # the high-pass of the leakage (zero at s = 0 in H) is in the reduced model the node
        # inverts
        assert node.deflection_estimator.reduced.order == 4
        node.destroy_node()
        with pytest.raises((P.ParameterError, ParameterException), match='plugins'):
            EstimatorNode(context=ctx, parameter_overrides=[
                Parameter('plugins', value=[str(ROOT / 'no_such_plugin.py')])])
    finally:
        EFFECTS.pop('polymer_leakage', None)
        rclpy.shutdown(context=ctx)


def test_simulator_node_field_fidelity_publishes():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=TEST_DOMAIN)
    try:
        node = SimulatorNode(context=ctx, parameter_overrides=[
            Parameter('fidelity', value='field'), Parameter('realtime_factor', value=0.0),
            Parameter('duration_s', value=0.5), Parameter('block_size', value=100)])
        from rclpy.executors import SingleThreadedExecutor
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        end = time.monotonic() + 30
        while not node.done and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.01)
        assert node.done and node.counters()['samples_published'] == 500
        ex.shutdown()
        node.destroy_node()
        with pytest.raises(P.ParameterError, match='fidelity'):
            SimulatorNode(context=ctx, parameter_overrides=[
                Parameter('fidelity', value='field'), Parameter('effects', value=['time_delay'])])
        # the large-deflection beam needs the field solution, and says so by parameter name
        with pytest.raises(P.ParameterError, match='beam_model'):
            SimulatorNode(
                context=ctx, parameter_overrides=[Parameter('beam_model', value='elastica')]
            )
        elastica = SimulatorNode(context=ctx, parameter_overrides=[
            Parameter('fidelity', value='field'), Parameter('beam_model', value='elastica')])
        assert elastica._sim._solver.beam.name == 'elastica'
        elastica.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)
