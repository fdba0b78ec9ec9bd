# SPDX-License-Identifier: Apache-2.0
"""A defect raised in a node's timer callback is logged on one line; the node goes on."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip('rclpy')
ROOT = Path(__file__).resolve().parents[1]

# The plain estimator node whose 1 s status timer raises (a stand-in for any defect in a
# callback outside the stream's own barrier: the smoother's drain, the counters' JSON).
_FAULTY = """
import sys
from ipmc_sensor_ros.nodes import estimator_node as m

def _status(self):
    raise ZeroDivisionError('injected by the test')

m.EstimatorNode._status = _status
sys.exit(m.main())
"""


@pytest.mark.ros
@pytest.mark.parametrize('executor', ['events', 'single'])
def test_a_timer_callback_defect_is_said_and_the_node_goes_on(executor):
    env = dict(os.environ, PYTHONPATH=str(ROOT), IPMC_EXECUTOR=executor,
               ROS_DOMAIN_ID=str(100 + os.getpid() % 50))
    proc = subprocess.Popen([sys.executable, '-c', _FAULTY], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, env=env, text=True)
    lines = []
    deadline = time.monotonic() + 60.0
    for line in proc.stdout:
        lines.append(line)
        if 'ready' in line or time.monotonic() > deadline:
            break
    time.sleep(3.5)                 # three ticks of the 1 s timer, each one raising
    alive = proc.poll() is None
    proc.send_signal(signal.SIGTERM)
    try:
        out, _ = proc.communicate(timeout=20.0)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
    text = ''.join(lines) + out
    assert alive, text              # before the barrier the first tick ended the process
    assert proc.returncode == 0, text
    assert 'Traceback' not in text, text
    said = [ln for ln in text.splitlines() if 'internal error (ZeroDivisionError' in ln]
    # one line per DEFECT_LOG_PERIOD_S (10 s): the first tick's, naming the package line
    assert len(said) == 1, text
    assert 'the node goes on (1 callback defect(s) so far)' in said[0]
    assert 'a defect of ipmc_sensor_ros' in said[0]
