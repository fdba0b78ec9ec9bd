# SPDX-License-Identifier: Apache-2.0
"""
Entry points of the node executables (``setup.py`` console scripts, ``ros2 run``).

Importing a node module takes about a second (numpy, scipy, rclpy).  A SIGINT or SIGTERM in
that time would end the interpreter with the signal's default action (status -15, or a
KeyboardInterrupt traceback).  These entry points take both signals before anything heavy is
imported and exit 0 at once, as :func:`~ipmc_sensor_ros.nodes.runner.run` does once it owns
the signals (it replaces these handlers for the node's life).
"""
from __future__ import annotations

import importlib
import os
import signal

__all__ = ['estimator', 'simulator', 'estimator_managed', 'simulator_managed']


def _exit_now(signum, frame) -> None:
    # nothing is started before run() takes the signals (no node, no DDS, no file): leave at
    # once; SystemExit raised inside a half-done import could hang the interpreter's exit
    os._exit(0)


def _start(module: str, name: str) -> int:
    """Take the signals, then import ``module`` and run its ``name``; return the exit code."""
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, _exit_now)
    return getattr(importlib.import_module(f'ipmc_sensor_ros.nodes.{module}'), name)()


def estimator() -> int:
    """``ipmc_estimator``."""
    return _start('estimator_node', 'main')


def simulator() -> int:
    """``ipmc_simulator``."""
    return _start('simulator_node', 'main')


def estimator_managed() -> int:
    """``ipmc_estimator_managed``."""
    return _start('managed', 'main_estimator')


def simulator_managed() -> int:
    """``ipmc_simulator_managed``."""
    return _start('managed', 'main_simulator')
