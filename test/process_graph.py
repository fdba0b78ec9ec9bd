# SPDX-License-Identifier: Apache-2.0
"""
Launch-free process graphs for the DDS tests.

Node executables run as child processes on a ROS domain of their own (150-200, see
``conftest.TEST_DOMAIN``) with discovery kept on loopback; this test process watches them with
a monitor node.  One place for the rules every such test follows: each child's output goes to a
log under ``tmp_path``, a child that exits early fails the wait with its log, and every child
gets SIGINT (then SIGKILL after 30 s) when the graph closes, whatever happened.
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


class ProcessGraph:
    """
    Node processes plus an in-test monitor node, shut down together.

    Parameters
    ----------
    tmp_path : pathlib.Path
        Where the children's logs (``<name>.log``) and ROS logs go.
    monkeypatch : pytest.MonkeyPatch
        Keeps this process's own discovery on loopback, like its children's.

    Attributes
    ----------
    node : rclpy.node.Node
        The monitor node (``monitor``) on which a test creates its subscriptions.
    codes : dict
        Exit code of each child by name, filled by :meth:`close`.

    """

    def __init__(self, tmp_path: Path, monkeypatch):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.domain = random.randint(150, 200)
        self.env = dict(os.environ, PYTHONPATH=str(ROOT), ROS_DOMAIN_ID=str(self.domain),
                        ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', ROS_LOG_DIR=str(tmp_path))
        monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
        self._tmp_path = tmp_path
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=self.domain)
        self.node = rclpy.create_node('monitor', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.procs: dict[str, subprocess.Popen] = {}
        self.logs: dict[str, Path] = {}
        self.codes: dict[str, int] = {}

    def start(self, name: str, module: str, params: dict, namespace: str) -> None:
        """Start ``ipmc_sensor_ros.nodes.<module>`` as child ``name`` with ``-p`` parameters."""
        cmd = [sys.executable, '-m', f'ipmc_sensor_ros.nodes.{module}',
               '--ros-args', '-r', f'__ns:={namespace}']
        for key, value in params.items():
            cmd += ['-p', f'{key}:={value}']
        self.logs[name] = self._tmp_path / f'{name}.log'
        self.procs[name] = subprocess.Popen(cmd, env=self.env, stdout=self.logs[name].open('w'),
                                            stderr=subprocess.STDOUT)

    def spin_until(self, predicate, what: str, timeout_s: float) -> None:
        """Spin the monitor until ``predicate()``; fail on timeout or on a child's early exit."""
        end = time.monotonic() + timeout_s
        while not predicate():
            for name, proc in self.procs.items():
                assert proc.poll() is None, f'{name} exited early:\n{self.logs[name].read_text()}'
            assert time.monotonic() < end, f'timed out waiting for {what}'
            self.executor.spin_once(timeout_sec=0.05)

    def close(self) -> dict[str, int]:
        """SIGINT every child still running, collect exit codes, shut the monitor down."""
        import rclpy

        for proc in self.procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        for name, proc in self.procs.items():
            try:
                self.codes[name] = proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                self.codes[name] = proc.wait()
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)
        return self.codes

    def log_texts(self) -> dict[str, str]:
        """Return every child's log, for assertion messages."""
        return {name: log.read_text() for name, log in self.logs.items()}
