# SPDX-License-Identifier: Apache-2.0
"""
Node start-up: ``-h/--help``, a signal during a slow start, model files, the node's arguments.

* ``-h`` / ``--help`` prints the usage and parameters and exits 0; rclpy is not started.
* SIGTERM while the node is being built (a model file being parsed) ends it at once, exit 0.
* A model file that is binary, or too large, stops the node with one line naming the file.
* A node loading a model file logs what it holds and that its recording effects are not
  applied (a warning when ``apply_recording_effects`` applies them).
* The params-file rules read the node's own arguments, not ``sys.argv``, and never write
  rclpy's parameter overrides.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

rclpy = pytest.importorskip('rclpy')

from ipmc_sensor_ros.nodes import params as P  # noqa: E402
from ipmc_sensor_ros.nodes import runner  # noqa: E402
from ipmc_sensor_ros.interface.specs import Spec  # noqa: E402
from ipmc_sensor_ros.physics.model import SensorModel  # noqa: E402
from ipmc_sensor_ros.physics.modelfile import save_model  # noqa: E402
from ipmc_sensor_ros.physics.parameters import PAPER_SAMPLES  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DOMAIN = int(os.environ.get('ROS_DOMAIN_ID') or 150 + os.getpid() % 50)


def _never(**kwargs):
    raise AssertionError('the node was built')


@pytest.mark.parametrize('exe', ['ipmc_estimator', 'ipmc_simulator_managed'])
@pytest.mark.parametrize('flag', ['-h', '--help'])
def test_help_prints_usage_and_starts_nothing(exe, flag, monkeypatch, capsys):
    monkeypatch.setattr(runner.rclpy, 'init', _never)
    assert runner.run(_never, exe, [exe, flag, '--ros-args', '-p', 'x:=1']) == 0
    out = capsys.readouterr().out
    assert out.startswith(f'usage: {exe}') and 'sample_rate_hz' in out
    assert ('autostart' in out) == exe.endswith('_managed')


@pytest.mark.parametrize('value', ['233', '-1', 'abc'])
def test_a_domain_id_no_dds_participant_can_use_is_refused_in_one_line(value):
    """
    Fast DDS only logs a port error for domain 233 and the process exits 1.

    The executables (and the demo) refuse it before rclpy starts: exit 2, one line naming
    the variable and the range.
    """
    env = dict(os.environ, ROS_DOMAIN_ID=value)
    for cmd in (['-c', 'import sys; from ipmc_sensor_ros.nodes.entry import estimator; '
                       'sys.exit(estimator())'],
                ['-m', 'ipmc_sensor_ros.nodes.demo', '--duration', '25']):
        done = subprocess.run([sys.executable, *cmd], env=env, capture_output=True, text=True,
                              cwd=ROOT, timeout=60)
        assert done.returncode == 2, done.stderr
        assert f"ROS_DOMAIN_ID='{value}' is not a ROS 2 domain: an integer 0-232" in done.stderr
        assert 'Traceback' not in done.stderr and done.stdout == ''


def test_signal_while_the_node_is_built_ends_it_at_once():
    stop = threading.Event()

    def slow_node(**kwargs):               # a model file that takes long to parse
        while not stop.wait(0.01):
            pass
        raise AssertionError('not interrupted')

    threading.Timer(10.0, stop.set).start()
    threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGTERM)).start()
    t0 = time.monotonic()
    try:
        code = runner.run(slow_node, 'ipmc_estimator', ['ipmc_estimator'])
    finally:
        stop.set()
    assert code == 0 and time.monotonic() - t0 < 3.0


def test_signal_while_params_files_are_read_ends_at_once(tmp_path, monkeypatch):
    stop = threading.Event()

    def slow_read(path, what):              # a large params file being parsed
        while not stop.wait(0.01):
            pass
        raise AssertionError('not interrupted')

    params = tmp_path / 'p.yaml'
    params.write_text('/**:\n  ros__parameters: {}\n')
    monkeypatch.setattr(runner, 'read_yaml', slow_read)
    threading.Timer(10.0, stop.set).start()
    threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGTERM)).start()
    t0 = time.monotonic()
    try:
        code = runner.run(_never, 'ipmc_estimator',
                          ['ipmc_estimator', '--ros-args', '--params-file', str(params)])
    finally:
        stop.set()
    assert code == 0 and time.monotonic() - t0 < 3.0


def test_oversized_params_file_is_refused_by_name(tmp_path, capsys):
    big = tmp_path / 'big.yaml'
    with open(big, 'wb') as f:
        f.truncate(50 * 1024 ** 2)
    t0 = time.monotonic()
    assert runner.run(_never, 'ipmc_estimator',
                      ['ipmc_estimator', '--ros-args', '--params-file', str(big)]) == 2
    err = capsys.readouterr().err.strip()
    assert time.monotonic() - t0 < 2.0
    assert len(err.splitlines()) == 1 and 'big.yaml' in err and 'more than the limit' in err


def _node_process(tmp_path, model_file: Path, *extra: str):
    env = dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN), PYTHONPATH=str(ROOT))
    return subprocess.Popen(
        [sys.executable, '-m', 'ipmc_sensor_ros.nodes.estimator_node', '--ros-args',
         '-p', f'model_file:={model_file}', *extra],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=tmp_path)


@pytest.mark.ros
def test_binary_model_file_stops_the_node_with_one_line(tmp_path):
    binary = tmp_path / 'model.bin'
    binary.write_bytes(bytes(range(256)) * 4)
    proc = _node_process(tmp_path, binary)
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 2, out
    lines = [ln for ln in out.splitlines() if 'model.bin' in ln]
    assert len(lines) == 1 and 'not UTF-8' in lines[0] and 'Traceback' not in out


def _slow_model_file(path: Path) -> Path:
    """Write a valid model file under the size limit whose provenance takes seconds to parse."""
    text = save_model(path, SensorModel(PAPER_SAMPLES['slim'])).read_text()
    notes = ''.join(f'  - {{a: {k}, b: [1.5, 2.5, x{k}]}}\n' for k in range(26_000))
    path.write_text(text + '  notes:\n' + notes)
    return path


@pytest.mark.ros
def test_sigterm_while_loading_a_model_file_ends_the_node_promptly(tmp_path):
    model = _slow_model_file(tmp_path / 'slow.yaml')
    assert model.stat().st_size < 1_000_000
    proc = _node_process(tmp_path, model, '-r', '__node:=slow_model_loader')
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=DOMAIN)
    try:
        probe = rclpy.create_node('startup_probe', context=ctx)
        end = time.monotonic() + 60
        while 'slow_model_loader' not in probe.get_node_names() and time.monotonic() < end:
            time.sleep(0.05)      # the node exists: it is now reading its parameters and model
        assert proc.poll() is None, proc.communicate()[0]
        proc.send_signal(signal.SIGTERM)
        t0 = time.monotonic()
        out, _ = proc.communicate(timeout=60)
        elapsed = time.monotonic() - t0
        probe.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
    assert proc.returncode == 0 and 'Traceback' not in out, out
    assert 'ready' not in out                 # it was interrupted while loading
    assert elapsed < 2.0, f'{elapsed:.1f} s after SIGTERM'


def test_model_file_summary_is_logged(tmp_path, capfd):
    from conftest import DirectNode

    fitted = SensorModel(PAPER_SAMPLES['slim'], effects=(
        'surface_resistance', ('current_offset', {'offset_a': 1e-8})))
    path = save_model(tmp_path / 'm.yaml', fitted, tool='test')
    d = DirectNode(model_file=str(path))
    d.close()
    err = capfd.readouterr().err
    assert f'model_file {path}: h2' in err and 'not applied: current_offset' in err
    d = DirectNode(model_file=str(path), apply_recording_effects=True)
    assert d.node._stream.estimator.model.has_effect('current_offset')
    d.close()
    err = capfd.readouterr().err
    assert '[WARN]' in err and 'APPLIED: current_offset' in err


SPECS = (Spec('gain', 1.0, float, 'test gain'),)


def test_params_rules_read_the_nodes_arguments_not_sys_argv(tmp_path, monkeypatch):
    other = tmp_path / 'other.yaml'
    other.write_text('/**/ipmc_estimator:\n  ros__parameters:\n    gain: 9.0\n')
    monkeypatch.setattr(sys, 'argv', ['x', '--ros-args', '--params-file', str(other)])
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=DOMAIN)
    try:
        args = ['--ros-args', '-r', '__node:=left_ipmc']
        node = rclpy.node.Node('ipmc_estimator', context=ctx, cli_args=args)
        before = dict(P.parameter_overrides(node))
        P.check_unknown_overrides(node, SPECS, args, default_name='ipmc_estimator')
        P.declare(node, SPECS)
        assert node.get_parameter('gain').value == 1.0   # other.yaml was never given to it
        assert dict(node._parameter_overrides) == before  # rclpy's state untouched
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


def test_an_out_of_range_parameter_reads_the_same_in_the_node_and_offline(tmp_path):
    """The node checks its overrides by the params-file rules before rcl's descriptors."""
    from ipmc_sensor_ros.interface.specs import load_params_file
    f = tmp_path / 'neg.yaml'
    f.write_text('/**/ipmc_estimator:\n  ros__parameters:\n    motion_rms_m: -0.001\n')
    said = "parameter 'motion_rms_m' = -0.001 is outside [1e-07, 1]"
    with pytest.raises(P.ParameterError) as offline:
        load_params_file(f)
    assert said in str(offline.value)
    env = dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN))
    done = subprocess.run([sys.executable, '-m', 'ipmc_sensor_ros.nodes.estimator_node',
                           '--ros-args', '--params-file', str(f)], env=env, cwd=ROOT,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and said in done.stderr and 'neg.yaml' in done.stderr
    assert 'Traceback' not in done.stderr
