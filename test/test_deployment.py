# SPDX-License-Identifier: Apache-2.0
"""
Deployment suite: what a robot stack or a lab meets, tried black-box where it can be.

The nodes run as their real executables in child processes (domains 150-200, as
``conftest`` reserves), driven over DDS and the lifecycle services; the command line runs
through :func:`ipmc_sensor_ros.cli.main.main` on files written here.  Each test reproduces
one failure as a user meets it and asserts the guarantee of docs/reliability.md.
"""
from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import rclpy
from lifecycle_msgs.msg import Transition
from std_msgs.msg import String

from ipmc_sensor_ros.nodes import params as P
from ipmc_sensor_ros.nodes.messages import pack_block
from test_managed import Client

ROOT = Path(__file__).resolve().parents[1]
FS = 1000.0


# ---------------------------------------------------------------------------
# Nodes in child processes
# ---------------------------------------------------------------------------
class ChildNode:
    """A node executable in a child process on its own domain, its log in a file."""

    def __init__(self, tmp_path: Path, entry: str, *ros_args: str):
        self.domain = random.randint(150, 200)
        self.log = tmp_path / f'{entry}.log'
        env = dict(os.environ, PYTHONPATH=str(ROOT), ROS_DOMAIN_ID=str(self.domain),
                   ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', ROS_LOG_DIR=str(tmp_path),
                   RCUTILS_LOGGING_BUFFERED_STREAM='0')
        module, func = entry.rsplit('.', 1)
        self.proc = subprocess.Popen(
            [sys.executable, '-c', f'import sys; from {module} import {func}; '
             f'sys.exit({func}())', '--ros-args', *ros_args],
            env=env, stdout=self.log.open('w'), stderr=subprocess.STDOUT)

    def text(self) -> str:
        return self.log.read_text(errors='replace')

    def alive(self) -> None:
        assert self.proc.poll() is None, f'the node exited early:\n{self.text()}'

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        return self.proc.wait(timeout=30)


def one_sample_messages(n: int, t0: float, seed: int = 0) -> list:
    """``n`` one-sample current messages at 1 kHz from ``t0`` (white noise of 10 nA)."""
    i = np.random.default_rng(seed).normal(0.0, 1e-8, n)
    return [pack_block([t0 + k / FS], [i[k]]) for k in range(n)]


@pytest.fixture
def managed_child(tmp_path, monkeypatch):
    """A managed estimator (autostart) in a child process and a tester :class:`Client`."""
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    child = ChildNode(tmp_path, 'ipmc_sensor_ros.nodes.managed.main_estimator',
                      '-p', 'autostart:=true', '-p', 'publish_points:=none')
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=child.domain)
    client = Client(ctx, None, '/ipmc_estimator')
    counters: list = []
    client.node.create_subscription(String, 'estimator/counters',
                                    lambda m: counters.append(json.loads(m.data)),
                                    P.COUNTERS_QOS)
    client.counters = counters
    try:
        client.spin_until(lambda: client.change.service_is_ready(), 'the lifecycle services',
                          check=child.alive)
        client.spin_until(lambda: client.state() == 'active', 'autostart', check=child.alive)
        yield child, client
    finally:
        client.close()
        rclpy.shutdown(context=ctx)
        child.stop()


# ---------------------------------------------------------------------------
# Lifecycle
# ---------------------------------------------------------------------------
class Streamer:
    """One-sample current messages at about 1 kHz from a thread of its own (its own node)."""

    def __init__(self, ctx, t0: float = 1000.0):
        import threading

        from std_msgs.msg import Float64MultiArray

        from test_managed import QOS

        self.node = rclpy.create_node('streamer', context=ctx)
        self.pub = self.node.create_publisher(Float64MultiArray, 'current', QOS)
        self.sent = 0
        self._t0 = t0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        rng = np.random.default_rng(1)
        start = time.monotonic()
        while not self._stop.is_set():
            due = int((time.monotonic() - start) * FS)
            while self.sent < due:
                self.pub.publish(pack_block([self._t0 + self.sent / FS],
                                            [rng.normal(0.0, 1e-8)]))
                self.sent += 1
            time.sleep(0.0005)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()
        self.node.destroy_node()


@pytest.mark.ros
def test_deactivate_while_data_streams_never_meets_a_torn_node(managed_child):
    """
    40 deactivate/activate cycles while one-sample messages stream at 1 kHz.

    No data callback meets a half-torn node (no error processing), every transition
    succeeds, and ``samples_out`` counts exactly the estimates that reached a reliable
    subscriber.
    """
    child, client = managed_child
    streamer = Streamer(client.node.context)
    try:
        for _ in range(40):
            client.spin_until(lambda: client.pub.get_subscription_count() == 1,
                              'the subscription', check=child.alive)
            client.spin_for(0.05)
            assert client.transition(Transition.TRANSITION_DEACTIVATE), child.text()[-2000:]
            assert client.transition(Transition.TRANSITION_ACTIVATE), child.text()[-2000:]
    finally:
        streamer.stop()
    text = child.text()
    assert 'error processing' not in text and 'Traceback' not in text, text[-3000:]
    assert client.transition(Transition.TRANSITION_DEACTIVATE)
    client.spin_for(0.5)     # the last estimates on their way
    client.counters.clear()
    assert client.transition(Transition.TRANSITION_ACTIVATE)
    client.spin_until(lambda: client.counters, 'a counters message', check=child.alive)
    published = int(client.estimates().size)
    assert published > 1000
    assert client.counters[-1]['samples_out'] == published


@pytest.mark.ros
def test_shutdown_logs_once_and_the_process_ends(managed_child):
    child, client = managed_child
    assert client.transition(Transition.TRANSITION_ACTIVE_SHUTDOWN)
    code = child.proc.wait(timeout=10)     # the executable ends by itself (no signal)
    text = child.text()
    assert code == 0, text
    assert text.count('shut down (finalized)') == 1, text
    assert 'cleaned up' not in text and 'Traceback' not in text, text
