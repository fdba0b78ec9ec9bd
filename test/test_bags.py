# SPDX-License-Identifier: Apache-2.0
"""
rosbag2 workflows: written bags are what rclpy expects.

Offline estimation equals a live replay into the node (as `ros2 bag play --clock` does), and
a looping replay resets cleanly.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
import rclpy
import yaml
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray

from ipmc_sensor_ros.cli.data_verbs import read_estimate
from ipmc_sensor_ros.cli.main import main
from ipmc_sensor_ros.nodes.estimator_node import EstimatorNode
from ipmc_sensor_ros.nodes.messages import ESTIMATE_COLUMNS, unpack_block
from conftest import TEST_DOMAIN

pytestmark = pytest.mark.ros
ROOT = Path(__file__).resolve().parents[1]
TYPES = {'std_msgs/msg/Float64MultiArray': Float64MultiArray}


def _simulate_bag(tmp_path, storage: str, duration: float = 30.0) -> Path:
    out = tmp_path / f'sim_{storage}'
    assert main(['simulate', '--out', str(out), '--samples', 'slim', '--frequencies', '5',
                 '--duration', str(duration), '--format', 'bag', '--storage', storage]) == 0
    return next(p for p in out.iterdir() if p.is_dir())


def _raw_messages(bag: Path):
    from rosbags.rosbag2 import Reader

    with Reader(bag) as reader:
        for conn, stamp, raw in reader.messages():
            yield conn.topic, conn.msgtype, stamp, bytes(raw)


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_written_bags_match_rclpy_types_and_deserialise(tmp_path, storage):
    bag = _simulate_bag(tmp_path, storage, duration=3.0)
    meta = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert meta['storage_identifier'] == storage
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=TEST_DOMAIN)
    try:
        node = rclpy.create_node('hash_probe', context=ctx)
        for entry in meta['topics_with_message_count']:
            tm = entry['topic_metadata']
            node.create_publisher(TYPES[tm['type']], tm['name'], 10)
            info = node.get_publishers_info_by_topic(tm['name'])
            assert info and str(info[0].topic_type_hash) == tm['type_description_hash'], tm['name']
        node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)
    samples = {}
    for topic, msgtype, _, raw in _raw_messages(bag):
        msg = deserialize_message(raw, TYPES[msgtype])
        samples[topic] = samples.get(topic, 0) + len(msg.data) // 2
    assert samples == {'/current': 3000, '/deflection_truth': 3000}


def test_replay_into_live_node_equals_offline_and_loop_resets(tmp_path):
    bag = _simulate_bag(tmp_path, 'sqlite3')
    params = ROOT / 'config' / 'estimator.yaml'
    assert (
        main(['estimate', str(bag), '--out', str(tmp_path / 'est'), '--params', str(params),
              '--causal']) == 0
    )
    offline = read_estimate(tmp_path / 'est' / f'{bag.name}.estimate.csv')

    current = [(stamp, raw) for topic, _, stamp, raw in _raw_messages(bag) if topic == '/current']
    current.sort(key=lambda x: x[0])
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=TEST_DOMAIN)
    ex = SingleThreadedExecutor(context=ctx)
    try:
        est = EstimatorNode(context=ctx, parameter_overrides=[
            Parameter('use_sim_time', value=True), Parameter('publish_points', value='none')],
            cli_args=['--ros-args', '--params-file', str(params)])
        player = rclpy.create_node('player', context=ctx)
        qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        pub_clock = player.create_publisher(Clock, '/clock', 10)
        pub_current = player.create_publisher(Float64MultiArray, '/current', qos)
        blocks = []
        player.create_subscription(Float64MultiArray, '/deflection/block',
                                   lambda m: blocks.append(unpack_block(m, ESTIMATE_COLUMNS)), qos)
        ex.add_node(est)
        ex.add_node(player)
        end = time.monotonic() + 10
        while pub_current.get_subscription_count() == 0 and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)

        def play():
            for stamp, raw in current:
                clock = Clock()
                clock.clock.sec, clock.clock.nanosec = divmod(int(stamp), 1_000_000_000)
                pub_clock.publish(clock)
                pub_current.publish(raw)          # serialized bytes, as rosbag2 plays them
                ex.spin_once(timeout_sec=0)

        n = offline['time_s'].size
        for loop in (1, 2):                        # the second pass jumps back (bag --loop)
            play()
            end = time.monotonic() + 30
            while sum(len(b) for b in blocks) < loop * n and time.monotonic() < end:
                ex.spin_once(timeout_sec=0.05)
        c = est.counters()
        assert c['samples_in'] == c['samples_out'] == 2 * n and c['samples_rejected'] == 0
        assert c['resets'] == 1 and 'time jumped back' in est.last_warning
        t = np.concatenate([b.times_s for b in blocks])
        w = np.concatenate([b.values for b in blocks])
        # Pass 1 equals the offline estimate from the same params file (same code path).
        assert np.array_equal(t[:n], offline['time_s'])
        assert np.max(np.abs(w[:n] - offline['deflection_estimate_m'])) <= 1e-12
        # Pass 2 restarts from a clean filter: identical to pass 1, so no spike at the jump.
        assert np.max(np.abs(w[n:] - w[:n])) <= 1e-12
        est.destroy_node()
        player.destroy_node()
    finally:
        ex.shutdown()
        rclpy.shutdown(context=ctx)


def test_workbench_reads_bags_directly(tmp_path, capsys):
    """compare/fit take bags: topics by name, geometry from the ipmc.yaml sidecar or --geometry."""
    out = tmp_path / 'bags'
    assert main(['simulate', '--out', str(out), '--format', 'bag', '--samples', 'slim',
                 '--frequencies', '2,8', '--duration', '4', '--storage', 'mcap']) == 0
    bags = sorted(p for p in out.iterdir() if p.is_dir())
    js = tmp_path / 'c.json'
    assert main(['compare', *map(str, bags), '--json', str(js)]) == 0
    import json
    assert json.loads(js.read_text())['fit_percent'] > 97.0
    for b in bags:
        (b / 'ipmc.yaml').unlink()
    assert main(['compare', str(bags[0])]) == 2
    assert 'geometry' in capsys.readouterr().err
    assert main(['compare', str(bags[0]), '--geometry', '0.022,0.007,0.00036',
                 '--json', str(js)]) == 0
    assert main(['compare', str(bags[0]), '--current-topic', 'nope']) == 2
    assert 'nope' in capsys.readouterr().err
