# SPDX-License-Identifier: Apache-2.0
"""
Shared test fixtures: one ROS domain per test run, ROS contexts.

The estimator node driven synchronously, temporary workspaces.
"""
from __future__ import annotations

import contextlib
import os

import pytest

#: One DDS domain per test run (parallel runs on one machine must not hear each other);
#: ROS_DOMAIN_ID from the environment wins.  Domains are split so that nothing else a test
#: run starts can land on it: this run's in-process nodes 100-149, child processes started by
#: tests 150-200, benchmark processes 201-232.
TEST_DOMAIN = int(os.environ.get('ROS_DOMAIN_ID') or 100 + os.getpid() % 50)


def init_context(**kwargs):
    """Return a fresh, initialised :class:`rclpy.Context` on the run's domain."""
    import rclpy

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=TEST_DOMAIN, **kwargs)
    return ctx


@contextlib.contextmanager
def ros_context(**kwargs):
    """
    Yield an initialised context, shut down on exit.

    Use: ``with ros_context() as ctx:``.
    """
    import rclpy

    ctx = init_context(**kwargs)
    try:
        yield ctx
    finally:
        if ctx.ok():
            rclpy.shutdown(context=ctx)


def _typed(msg, msg_type):
    """Return ``msg`` as a message object (publishers may be handed serialised bytes)."""
    from rclpy.serialization import deserialize_message

    return deserialize_message(msg, msg_type) if isinstance(msg, bytes) else msg


def _point_row(msg) -> tuple:
    """Return (sec, nanosec, frame_id, x, z) of a published ``PointStamped`` (or its bytes)."""
    from geometry_msgs.msg import PointStamped

    p = _typed(msg, PointStamped)
    return (p.header.stamp.sec, p.header.stamp.nanosec, p.header.frame_id, p.point.x, p.point.z)


class DirectNode:
    """
    The estimator node driven synchronously through its subscription callback.

    The full message path minus DDS, capturing what it publishes.
    """

    def __init__(self, **overrides):
        from rclpy.parameter import Parameter
        from std_msgs.msg import Float64MultiArray

        from ipmc_sensor_ros.nodes.estimator_node import EstimatorNode
        from ipmc_sensor_ros.nodes.messages import ESTIMATE_COLUMNS, unpack_block

        self.ctx = init_context()
        values = {'publish_points': 'none', **overrides}
        params = [Parameter(k, value=v) for k, v in values.items()]
        self.node = EstimatorNode(context=self.ctx, parameter_overrides=params)
        self.published: list = []
        self.points: list = []
        self.node._pub_block.publish = lambda m: self.published.append(
            unpack_block(_typed(m, Float64MultiArray), ESTIMATE_COLUMNS))
        self.node._pub_point.publish = lambda m: self.points.append(_point_row(m))

    def send(self, msg) -> None:
        from rclpy.serialization import serialize_message

        # as the subscription delivers it: serialised (the node's one-sample path reads bytes)
        self.node._on_current_raw(serialize_message(msg))

    def close(self) -> None:
        import rclpy

        self.node.destroy_node()
        rclpy.shutdown(context=self.ctx)


@pytest.fixture
def direct_node():
    """Return a fresh :class:`DirectNode` with default parameters."""
    d = DirectNode()
    yield d
    d.close()


def blocks_and_samples(make, current, block: int = 1000):
    """
    Run three fresh estimators from ``make()`` over ``current``: blocks, 37-sample blocks, samples.

    Returns the estimators and their outputs; the ROS-free filter cores promise the same
    estimates up to rounding whatever the block size.
    """
    import numpy as np

    ests = [make() for _ in range(3)]
    a, b, c = ests
    wa = np.concatenate([a.process(current[k:k + block]) for k in range(0, current.size, block)])
    wb = np.concatenate([b.process(current[k:k + 37]) for k in range(0, current.size, 37)])
    wc = np.array([c.process_one(x) for x in current])
    return ests, (wa, wb, wc)


def assert_agree_and_restore(ests, outputs, current) -> None:
    """
    Assert blocks, small blocks and samples agree to rounding (1e-12 m), and state round trip.

    The first estimator's saved state, restored, reproduces exactly what it gave on ``current``.
    """
    import numpy as np

    wa, wb, wc = outputs
    assert np.max(np.abs(wa - wb)) < 1e-12
    assert np.max(np.abs(wa - wc)) < 1e-12
    saved = ests[0].get_state()
    tail = ests[0].process(current)
    ests[0].set_state(saved)
    assert np.array_equal(ests[0].process(current), tail)
