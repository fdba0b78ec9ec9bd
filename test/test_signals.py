# SPDX-License-Identifier: Apache-2.0
"""SIGINT/SIGTERM right after "ready" end the node process with 0 and no traceback."""
import os
import signal

import pytest
from node_process import signal_and_wait, start_until_ready

pytest.importorskip('rclpy')


def _start_and_signal(sig, domain, executor=None):
    extra = {} if executor is None else {'IPMC_EXECUTOR': executor}
    proc, lines = start_until_ready(['-m', 'ipmc_sensor_ros.nodes.simulator_node'], domain,
                                    **extra)
    code, text = signal_and_wait(proc, sig, lines)   # on the "ready" line: the racy moment
    if code is None:                                  # the spin loop sees it within 0.1 s
        pytest.fail('node did not exit within 20 s of the signal:\n' + text)
    return code, text


@pytest.mark.ros
@pytest.mark.parametrize('sig,executor', [(signal.SIGTERM, None), (signal.SIGTERM, None),
                                          (signal.SIGINT, None), (signal.SIGTERM, 'single'),
                                          (signal.SIGINT, 'single')])
def test_signal_after_ready_exits_zero_without_traceback(sig, executor):
    code, text = _start_and_signal(sig, 150 + os.getpid() % 50, executor)
    assert 'ready' in text
    assert code == 0, text
    assert 'Traceback' not in text and 'Error' not in text, text


@pytest.mark.ros
def test_events_executor_is_the_default_where_rclpy_has_it(monkeypatch):
    from ipmc_sensor_ros.nodes import runner

    monkeypatch.delenv('IPMC_EXECUTOR', raising=False)
    experimental = pytest.importorskip('rclpy.experimental')
    assert runner.executor_name() == 'events'
    # rclpy.experimental.EventsExecutor is a factory function; the class is in _rclpy_pybind11
    assert type(runner.make_executor()).__name__ == 'EventsExecutor'
    assert callable(experimental.EventsExecutor)
    monkeypatch.setenv('IPMC_EXECUTOR', 'single')
    assert runner.executor_name() == 'single'
    monkeypatch.setenv('IPMC_EXECUTOR', 'multi')
    with pytest.raises(runner.ParameterError, match='IPMC_EXECUTOR'):
        runner.executor_name()


@pytest.mark.ros
def test_the_estimator_says_its_totals_as_it_stops():
    # one line in the counters' terms (samples_in == out + refused + dropped + unpublished)
    proc, lines = start_until_ready(['-m', 'ipmc_sensor_ros.nodes.estimator_node'],
                                    150 + os.getpid() % 50)
    code, text = signal_and_wait(proc, signal.SIGINT, lines)
    assert code == 0, text
    assert ('stopping: 0 sample(s) in, 0 published, 0 refused, 0 dropped, 0 unpublished '
            '(estimator/counters has the reasons)') in text, text
