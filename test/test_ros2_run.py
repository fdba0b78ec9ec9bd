# SPDX-License-Identifier: Apache-2.0
"""
The ``ros2 run`` contract: colcon builds the package and both executables run.

There is no ``ros2`` CLI here, so the test does what ``ros2 run ipmc_sensor_ros
<exe>`` does: resolve the package prefix through the ament index
(``get_package_prefix``, with AMENT_PREFIX_PATH as sourcing
``install/setup.bash`` would set it) and execute ``<prefix>/lib/<pkg>/<exe>``,
with PYTHONPATH pointing at the install's site-packages.  Each executable is
started with the installed params file plus a ``-p`` override, must come up
(its "ready" log line, which echoes the override) and must exit 0 on SIGINT.
"""
from __future__ import annotations

import os
import queue
import random
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.ros

ROOT = Path(__file__).resolve().parents[1]
PKG = 'ipmc_sensor_ros'
IGNORE = shutil.ignore_patterns('.venv', '.git', 'build', 'install', 'log', '__pycache__',
                                '*.egg-info', '.pytest_cache', '.hypothesis', '.ci')


@pytest.fixture(scope='module')
def workspace(tmp_path_factory):
    ws = tmp_path_factory.mktemp('ws')
    shutil.copytree(ROOT, ws / 'src' / PKG, ignore=IGNORE)
    proc = subprocess.run([sys.executable, '-m', 'colcon', 'build', '--base-paths', 'src'],
                          cwd=ws, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-4000:]
    return ws


def _reader(stream, lines: queue.Queue):
    for line in iter(stream.readline, ''):
        lines.put(line)
    stream.close()


def test_colcon_install_layout(workspace, monkeypatch):
    from ament_index_python.packages import get_package_prefix, get_package_share_directory

    monkeypatch.setenv('AMENT_PREFIX_PATH', str(workspace / 'install' / PKG))
    prefix = Path(get_package_prefix(PKG))
    assert prefix == workspace / 'install' / PKG
    for exe in ('ipmc_estimator', 'ipmc_simulator', 'ipmc_estimator_managed',
                'ipmc_simulator_managed'):
        path = prefix / 'lib' / PKG / exe
        assert path.is_file() and os.access(path, os.X_OK), path
    share = Path(get_package_share_directory(PKG))
    assert (share / 'config' / 'estimator.yaml').is_file()
    assert (share / 'config' / 'simulator.yaml').is_file()
    assert (share / 'package.xml').is_file()


@pytest.mark.parametrize('exe,config,override,echo', [
    ('ipmc_estimator', 'estimator.yaml', 'sample_rate_hz:=500.0', 'fs = 500.0 Hz'),
    ('ipmc_simulator', 'simulator.yaml', 'motor_frequency_hz:=5.0', 'motor_frequency_hz=5,'),
])
def test_ros2_run_starts_and_exits_zero_on_sigint(workspace, tmp_path, monkeypatch, exe, config,
                                                  override, echo):
    from ament_index_python.packages import get_package_prefix, get_package_share_directory

    install = workspace / 'install' / PKG
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(install))
    exe_path = Path(get_package_prefix(PKG)) / 'lib' / PKG / exe
    params = Path(get_package_share_directory(PKG)) / 'config' / config
    site = sorted(install.glob('lib/python3*/site-packages'))
    assert len(site) == 1, site
    env = dict(os.environ, PYTHONPATH=str(site[0]), AMENT_PREFIX_PATH=str(install),
               ROS_DOMAIN_ID=str(random.randint(150, 200)),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', ROS_LOG_DIR=str(tmp_path))
    proc = subprocess.Popen([str(exe_path), '--ros-args', '--params-file', str(params),
                             '-p', override], cwd=tmp_path, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    lines: queue.Queue = queue.Queue()
    threading.Thread(target=_reader, args=(proc.stderr, lines), daemon=True).start()
    seen = []
    try:
        end = time.monotonic() + 120.0
        while not any('ready:' in s for s in seen):
            assert proc.poll() is None, ''.join(seen)
            assert time.monotonic() < end, "no 'ready' line:\n" + ''.join(seen)
            try:
                seen.append(lines.get(timeout=0.2))
            except queue.Empty:
                pass
        ready = next(s for s in seen if 'ready:' in s)
        assert echo in ready, ready          # the params file and the override were applied
        proc.send_signal(signal.SIGINT)
        code = proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    rest = []
    while not lines.empty():
        rest.append(lines.get())
    assert code == 0, ''.join(seen + rest)
    assert 'Traceback' not in ''.join(seen + rest)
