# SPDX-License-Identifier: Apache-2.0
"""SIGINT/SIGTERM right after "ready" end the node process with 0 and no traceback."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip('rclpy')
ROOT = Path(__file__).resolve().parents[1]


def _start_and_signal(sig, domain):
    env = dict(os.environ, PYTHONPATH=str(ROOT), ROS_DOMAIN_ID=str(domain))
    proc = subprocess.Popen([sys.executable, '-m', 'ipmc_sensor_ros.nodes.simulator_node'],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env, text=True)
    lines = []
    deadline = time.monotonic() + 60.0
    for line in proc.stdout:
        lines.append(line)
        if 'ready' in line or time.monotonic() > deadline:
            break
    proc.send_signal(sig)                     # on the "ready" line: the racy moment
    try:
        out, _ = proc.communicate(timeout=20.0)   # the guard timer acts within 0.1 s
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
        pytest.fail('node did not exit within 20 s of the signal:\n' + ''.join(lines) + out)
    return proc.returncode, ''.join(lines) + out


@pytest.mark.ros
@pytest.mark.parametrize('sig', [signal.SIGTERM, signal.SIGTERM, signal.SIGTERM, signal.SIGINT])
def test_signal_after_ready_exits_zero_without_traceback(sig):
    code, text = _start_and_signal(sig, 150 + os.getpid() % 50)
    assert 'ready' in text
    assert code == 0, text
    assert 'Traceback' not in text and 'Error' not in text, text
