# SPDX-License-Identifier: Apache-2.0
"""A defect raised in a node's timer callback is logged on one line; the node goes on."""
import os
import signal
import time

import pytest
from node_process import signal_and_wait, start_until_ready

pytest.importorskip('rclpy')

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
    proc, lines = start_until_ready(['-c', _FAULTY], 100 + os.getpid() % 50,
                                    IPMC_EXECUTOR=executor)
    time.sleep(3.5)                 # three ticks of the 1 s timer, each one raising
    alive = proc.poll() is None
    code, text = signal_and_wait(proc, signal.SIGTERM, lines)
    assert alive, text              # before the barrier the first tick ended the process
    assert code == 0, text
    assert 'Traceback' not in text, text
    said = [ln for ln in text.splitlines() if 'internal error (ZeroDivisionError' in ln]
    # one line per DEFECT_LOG_PERIOD_S (10 s): the first tick's, naming the package line
    assert len(said) == 1, text
    assert 'the node goes on (1 callback defect(s) so far)' in said[0]
    assert 'a defect of ipmc_sensor_ros' in said[0]
