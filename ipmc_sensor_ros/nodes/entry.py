# SPDX-License-Identifier: Apache-2.0
"""
Entry points of the node executables (``setup.py`` console scripts, ``ros2 run``).

Importing a node module takes about a second (numpy, scipy, rclpy).  A SIGINT or SIGTERM in
that time would end the interpreter with the signal's default action (status -15, or a
KeyboardInterrupt traceback).  These entry points take both signals before anything heavy is
imported and exit 0 at once, as :func:`~ipmc_sensor_ros.nodes.runner.run` does once it owns
the signals (it replaces these handlers for the node's life).  A ``ROS_DOMAIN_ID`` no DDS
participant can use is refused here too, in one line (Fast DDS only logs a port error and
the process would exit 1).
"""
from __future__ import annotations

import importlib
import os
import signal
import sys

__all__ = ['estimator', 'simulator', 'estimator_managed', 'simulator_managed',
           'domain_id_problem', 'MAX_DOMAIN_ID']

#: The largest ROS_DOMAIN_ID: a domain's DDS ports are 7400 + 250 x ID (+ up to 35), within
#: 65535 up to 232.
MAX_DOMAIN_ID = 232


def domain_id_problem(environ=os.environ) -> str | None:
    """Return why ``ROS_DOMAIN_ID`` cannot be used (None: unset, empty or valid)."""
    value = environ.get('ROS_DOMAIN_ID', '')
    if not value.strip():
        return None
    try:
        if 0 <= int(value) <= MAX_DOMAIN_ID:
            return None
    except ValueError:
        pass
    return (f'ROS_DOMAIN_ID={value!r} is not a ROS 2 domain: an integer 0-{MAX_DOMAIN_ID} '
            "(its DDS ports are 7400 + 250 x ID; 0-101 keep clear of Linux's ephemeral ports)")


def _exit_now(signum, frame) -> None:
    # nothing is started before run() takes the signals (no node, no DDS, no file): leave at
    # once; SystemExit raised inside a half-done import could hang the interpreter's exit
    os._exit(0)


def _start(module: str, name: str, executable: str) -> int:
    """Take the signals, then import ``module`` and run its ``name``; return the exit code."""
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, _exit_now)
    problem = domain_id_problem()
    if problem:
        print(f'{executable}: {problem}', file=sys.stderr)
        return 2
    return getattr(importlib.import_module(f'ipmc_sensor_ros.nodes.{module}'), name)()


def estimator() -> int:
    """``ipmc_estimator``."""
    return _start('estimator_node', 'main', 'ipmc_estimator')


def simulator() -> int:
    """``ipmc_simulator``."""
    return _start('simulator_node', 'main', 'ipmc_simulator')


def estimator_managed() -> int:
    """``ipmc_estimator_managed``."""
    return _start('managed', 'main_estimator', 'ipmc_estimator_managed')


def simulator_managed() -> int:
    """``ipmc_simulator_managed``."""
    return _start('managed', 'main_simulator', 'ipmc_simulator_managed')
