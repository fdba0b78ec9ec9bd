# SPDX-License-Identifier: Apache-2.0
"""
Reliability from the outside (issue 18), ROS part: the estimator node runs in a second process.

This test process is the hostile peer (remote set_parameters with extreme floats).
"""
import os
import random
import subprocess
import sys
from pathlib import Path

import pytest
import rclpy
from rclpy.parameter import Parameter

ROOT = Path(__file__).resolve().parents[1]


def _env(domain):
    return {**os.environ, 'ROS_DOMAIN_ID': str(domain), 'PYTHONPATH': str(ROOT)}


def test_remote_extreme_parameter_sets_are_refused_and_the_node_lives():
    domain = random.randint(150, 200)
    node = subprocess.Popen([sys.executable, '-m', 'ipmc_sensor_ros.nodes.estimator_node'],
                            env=_env(domain), stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    try:
        peer = rclpy.create_node('hostile_peer', context=ctx)
        from rclpy.parameter_client import AsyncParameterClient
        from rclpy.executors import SingleThreadedExecutor
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(peer)
        client = AsyncParameterClient(peer, 'ipmc_estimator')
        assert client.wait_for_services(timeout_sec=30.0)
        for name, value in (
            ('youngs_modulus_pa', 1e-296),
            ('charge_stress_coupling_j_per_c', 1e304),
            ('temperature_k', 5e-324),
            ('frame_id', 'x' * 100_000),
        ):
            future = client.set_parameters([Parameter(name, value=value)])
            executor.spin_until_future_complete(future, timeout_sec=30.0)
            result = future.result().results[0]
            assert not result.successful, name
            assert len(result.reason) < 400 and '\n' not in result.reason
        assert node.poll() is None              # alive
    finally:
        node.terminate()
        node.wait(timeout=20)
        rclpy.shutdown(context=ctx)


@pytest.mark.parametrize(
    'text',
    [
        'ipmc_estimator:\n  ros__parameters:\n    youngs_modulus_pa: 1.0e-296\n',
        'ipmc_estimator:\n  ros__parameters:\n    length_m: [1, "a"]\n',
        'ipmc_estimator:\n  ros__parameters:\n    length_m: 0.02\n   x: [\n',
    ],
)
def test_bad_params_file_at_start_up_is_one_line_exit_2(tmp_path, text):
    f = tmp_path / 'p.yaml'
    f.write_text(text)
    out = subprocess.run(
        [
            sys.executable,
            '-m',
            'ipmc_sensor_ros.nodes.estimator_node',
            '--ros-args',
            '--params-file',
            str(f),
        ],
        env=_env(random.randint(150, 200)),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2, out.stderr
    assert 'Traceback' not in out.stderr
    assert 'ipmc_estimator: invalid' in out.stderr
