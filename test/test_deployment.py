# SPDX-License-Identifier: Apache-2.0
"""
Deployment suite: what a robot stack or a lab meets, tried black-box where it can be.

The nodes run as their real executables in child processes (domains 150-200, as
``conftest`` reserves), driven over DDS and the lifecycle services; the command line runs
through :func:`ipmc_sensor_ros.cli.main.main` on files written here.  Each test reproduces
one failure as a user meets it and asserts the guarantee of docs/reliability.md.
"""
from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import rclpy
from lifecycle_msgs.msg import Transition
from std_msgs.msg import String

from ipmc_sensor_ros.nodes import topics as T
from ipmc_sensor_ros.nodes.messages import pack_block
from test_managed import Client

ROOT = Path(__file__).resolve().parents[1]
FS = 1000.0


# ---------------------------------------------------------------------------
# Nodes in child processes
# ---------------------------------------------------------------------------
class ChildNode:
    """A node executable in a child process on its own domain, its log in a file."""

    def __init__(self, tmp_path: Path, entry: str, *ros_args: str):
        self.domain = random.randint(150, 200)
        self.log = tmp_path / f'{entry}.log'
        env = dict(os.environ, PYTHONPATH=str(ROOT), ROS_DOMAIN_ID=str(self.domain),
                   ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', ROS_LOG_DIR=str(tmp_path),
                   RCUTILS_LOGGING_BUFFERED_STREAM='0')
        module, func = entry.rsplit('.', 1)
        self.proc = subprocess.Popen(
            [sys.executable, '-c', f'import sys; from {module} import {func}; '
             f'sys.exit({func}())', '--ros-args', *ros_args],
            env=env, stdout=self.log.open('w'), stderr=subprocess.STDOUT)

    def text(self) -> str:
        return self.log.read_text(errors='replace')

    def alive(self) -> None:
        assert self.proc.poll() is None, f'the node exited early:\n{self.text()}'

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        return self.proc.wait(timeout=30)


def one_sample_messages(n: int, t0: float, seed: int = 0) -> list:
    """``n`` one-sample current messages at 1 kHz from ``t0`` (white noise of 10 nA)."""
    i = np.random.default_rng(seed).normal(0.0, 1e-8, n)
    return [pack_block([t0 + k / FS], [i[k]]) for k in range(n)]


@pytest.fixture
def managed_child(tmp_path, monkeypatch):
    """Start a managed estimator (autostart) in a child process; yield it and a tester."""
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    child = ChildNode(tmp_path, 'ipmc_sensor_ros.nodes.managed.main_estimator',
                      '-p', 'autostart:=true', '-p', 'publish_points:=none')
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=child.domain)
    client = Client(ctx, None, '/ipmc_estimator')
    counters: list = []
    client.node.create_subscription(String, 'estimator/counters',
                                    lambda m: counters.append(json.loads(m.data)),
                                    T.COUNTERS_QOS)
    client.counters = counters
    try:
        client.spin_until(lambda: client.change.service_is_ready(), 'the lifecycle services',
                          check=child.alive)
        client.spin_until(lambda: client.state() == 'active', 'autostart', check=child.alive)
        yield child, client
    finally:
        client.close()
        rclpy.shutdown(context=ctx)
        child.stop()


# ---------------------------------------------------------------------------
# Lifecycle
# ---------------------------------------------------------------------------
class Streamer:
    """One-sample current messages at about 1 kHz from a thread of its own (its own node)."""

    def __init__(self, ctx, t0: float = 1000.0):
        import threading

        from std_msgs.msg import Float64MultiArray

        from test_managed import QOS

        self.node = rclpy.create_node('streamer', context=ctx)
        self.pub = self.node.create_publisher(Float64MultiArray, 'current', QOS)
        self.sent = 0
        self._t0 = t0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        rng = np.random.default_rng(1)
        start = time.monotonic()
        while not self._stop.is_set():
            due = int((time.monotonic() - start) * FS)
            while self.sent < due:
                self.pub.publish(pack_block([self._t0 + self.sent / FS],
                                            [rng.normal(0.0, 1e-8)]))
                self.sent += 1
            time.sleep(0.0005)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()
        self.node.destroy_node()


@pytest.mark.ros
def test_deactivate_while_data_streams_never_meets_a_torn_node(managed_child):
    """
    40 deactivate/activate cycles while one-sample messages stream at 1 kHz.

    No data callback meets a half-torn node (no error processing), every transition
    succeeds, and ``samples_out`` counts exactly the estimates that reached a reliable
    subscriber.
    """
    child, client = managed_child
    streamer = Streamer(client.node.context)
    try:
        for _ in range(40):
            client.spin_until(lambda: client.pub.get_subscription_count() == 1,
                              'the subscription', check=child.alive)
            client.spin_for(0.05)
            assert client.transition(Transition.TRANSITION_DEACTIVATE), child.text()[-2000:]
            assert client.transition(Transition.TRANSITION_ACTIVATE), child.text()[-2000:]
    finally:
        streamer.stop()
    text = child.text()
    assert 'error processing' not in text and 'Traceback' not in text, text[-3000:]
    assert client.transition(Transition.TRANSITION_DEACTIVATE)
    client.spin_for(0.5)     # the last estimates on their way
    client.counters.clear()
    assert client.transition(Transition.TRANSITION_ACTIVATE)
    client.spin_until(lambda: client.counters, 'a counters message', check=child.alive)
    published = int(client.estimates().size)
    assert published > 1000
    assert client.counters[-1]['samples_out'] == published


@pytest.mark.ros
def test_shutdown_logs_once_and_the_process_ends(managed_child):
    child, client = managed_child
    assert client.transition(Transition.TRANSITION_ACTIVE_SHUTDOWN)
    code = child.proc.wait(timeout=10)     # the executable ends by itself (no signal)
    text = child.text()
    assert code == 0, text
    assert text.count('shut down (finalized)') == 1, text
    assert 'cleaned up' not in text and 'Traceback' not in text, text


# ---------------------------------------------------------------------------
# Command line: errors that name the place, batches, names, outputs, cost per file
# ---------------------------------------------------------------------------
def _record(path: Path, rows: int = 3000, seed: int = 0) -> list[str]:
    """Write an ``ipmc-timeseries/1`` record of white current (10 nA) and return its lines."""
    rng = np.random.default_rng(seed)
    t = np.arange(rows) / FS
    lines = ['# format: ipmc-timeseries/1', '# sample: slim', '# length_m: 0.022',
             '# width_m: 0.007', '# thickness_m: 0.00036', '# sample_rate_hz: 1000.0',
             'time_s,current_A']
    lines += [f'{a!r},{b!r}' for a, b in zip(t.tolist(), rng.normal(0, 1e-8, rows).tolist())]
    Path(path).write_bytes(('\n'.join(lines) + '\n').encode())
    return lines


def _estimate(*argv) -> int:
    from ipmc_sensor_ros.cli.main import main

    return main(['estimate', *map(str, argv)])


def test_a_bad_row_is_named_by_file_and_line_and_the_batch_goes_on(tmp_path, capsys):
    src = tmp_path / 'in'
    src.mkdir()
    for name in ('a', 'b', 'c'):
        lines = _record(src / f'{name}.csv')
    row = 2992
    lines[7 + row] = lines[7 + row].split(',')[0] + ',2.0'     # one row of 2 A in b.csv
    (src / 'b.csv').write_text('\n'.join(lines) + '\n')
    code = _estimate(src, '--out', tmp_path / 'o')
    out, err = capsys.readouterr()
    assert code == 1                                      # some inputs failed
    assert f'b.csv:{8 + row}: current block has |i| > 1.0 A (2.0 A)' in err
    assert sorted(p.name for p in (tmp_path / 'o').iterdir()) == ['a.estimate.csv',
                                                                  'c.estimate.csv']
    assert '2 of 3 input(s) written' in out and '1 failed' in out and 'b.csv' in out


def test_an_incomplete_last_line_is_named_and_not_read(tmp_path, capsys):
    lines = _record(tmp_path / 'live.csv')
    # a recorder still writing: the last row cut inside its number
    with open(tmp_path / 'live.csv', 'a') as f:
        f.write('3.0,-6.937703375')
    assert _estimate(tmp_path / 'live.csv', '--out', tmp_path / 'o') == 0
    err = capsys.readouterr().err
    assert f'live.csv:{len(lines) + 1}: last line has no line end' in err
    from ipmc_sensor_ros.cli.data_verbs import read_estimate

    est = read_estimate(tmp_path / 'o' / 'live.estimate.csv')
    assert est['time_s'].size == 3000 and np.all(np.abs(est['current_A']) < 1e-6)


def test_a_file_name_that_is_not_utf8_is_estimated_and_shown_escaped(tmp_path, capsys):
    src = os.fsencode(tmp_path) + b'/caf\xe9.csv'     # Latin-1 e-acute
    _record(os.fsdecode(src))
    out_dir = tmp_path / 'o'
    assert _estimate(os.fsdecode(src), '--out', out_dir) == 0
    out = capsys.readouterr().out
    assert 'caf\\xe9.csv: 3000 rows, 3000 estimated' in out
    written = os.listdir(os.fsencode(out_dir))
    assert written == [b'caf\xe9.estimate.csv']
    head = (out_dir / os.fsdecode(written[0])).read_bytes()[:200].decode()
    assert 'caf\\xe9.csv' in head


def test_nothing_empty_is_left_behind_on_an_error(tmp_path, monkeypatch):
    from ipmc_sensor_ros.cli import estimate_verb

    _record(tmp_path / 'x.csv')

    def broken(path, *args):
        Path(path).write_text('# format: ipmc-estimate/1\n')
        raise OSError(28, 'No space left on device')

    monkeypatch.setattr(estimate_verb, '_write_estimate', broken)
    assert _estimate(tmp_path / 'x.csv', '--out', tmp_path / 'o') == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ['x.csv']   # no output, no folder


def test_two_runs_with_the_same_out_never_lose_rows_silently(tmp_path, capsys):
    for name, seed in (('a', 1), ('b', 2)):
        (tmp_path / name).mkdir()
        _record(tmp_path / name / 'run.csv', seed=seed)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    cmd = [sys.executable, '-m', 'ipmc_sensor_ros.cli', 'estimate']
    runs = [subprocess.Popen(cmd + [str(tmp_path / name / 'run.csv'), '--out',
                                    str(tmp_path / 'same')], env=env, text=True,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE)
            for name in ('a', 'b')]
    results = [(r.wait(timeout=120), *r.communicate()) for r in runs]
    codes = sorted(code for code, _, _ in results)
    assert codes == [0, 2], results                      # one writes, the other refuses
    refusal = next(err for code, _, err in results if code)
    written = (tmp_path / 'same' / 'run.estimate.csv').read_text()
    first = 'a/run.csv' if 'a/run.csv' in written else 'b/run.csv'
    assert 'run.estimate.csv: exists, written from' in refusal and first in refusal
    from ipmc_sensor_ros.cli.estimate_verb import read_estimate

    assert read_estimate(tmp_path / 'same' / 'run.estimate.csv')['time_s'].size == 3000
    # --overwrite replaces, and says what it replaced
    assert _estimate(tmp_path / 'a' / 'run.csv', '--out', tmp_path / 'same', '--overwrite') == 0
    assert 'replaced' in capsys.readouterr().out


def test_the_estimator_is_built_once_for_a_directory_of_one_model(tmp_path, monkeypatch):
    from ipmc_sensor_ros.interface import builders

    src = tmp_path / 'in'
    src.mkdir()
    for k in range(5):
        _record(src / f'r{k}.csv', rows=100, seed=k)
    built = []
    real = builders.build_estimator
    monkeypatch.setattr(builders, 'build_estimator', lambda *a, **kw: built.append(1) or
                        real(*a, **kw))
    assert _estimate(src, '--out', tmp_path / 'o') == 0
    assert len(built) == 1
    # each file gets the estimator in its start state: the same input gives the same output
    from ipmc_sensor_ros.cli.data_verbs import read_estimate

    last = read_estimate(tmp_path / 'o' / 'r4.estimate.csv')['deflection_estimate_m']
    _record(src / 'r9.csv', rows=100, seed=4)
    assert _estimate(src / 'r9.csv', '--out', tmp_path / 'o2') == 0
    again = read_estimate(tmp_path / 'o2' / 'r9.estimate.csv')['deflection_estimate_m']
    np.testing.assert_array_equal(last, again)


# ---------------------------------------------------------------------------
# Physically possible or flagged
# ---------------------------------------------------------------------------
@pytest.mark.ros
def test_an_estimate_beyond_the_geometry_is_flagged_and_diagnostics_go_error(
        tmp_path, monkeypatch):
    """
    A current that means 15 mm of tip motion on a 22 mm beam (L/2 = 11 mm).

    The block carries each estimate with ``deflection_beyond_limit`` set exactly where
    |w| > L/2, the points (last of each block) are +-inf there (REP 117), and /diagnostics
    turn ERROR.
    """
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from geometry_msgs.msg import PointStamped
    from std_msgs.msg import Float64MultiArray

    from ipmc_sensor_ros.interface.blocks import ESTIMATE_COLUMNS
    from ipmc_sensor_ros.nodes.messages import unpack_block
    from ipmc_sensor_ros.physics.model import SensorModel
    from ipmc_sensor_ros.physics.parameters import Geometry
    from ipmc_sensor_ros.simulation.sensor import SensorSimulator
    from ipmc_sensor_ros.simulation.stimuli import CrankSlider
    from test_managed import QOS

    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    model = SensorModel.named('h2', Geometry(0.022, 0.007, 0.00036))
    k = np.arange(3000)
    _, current = SensorSimulator(model, FS).run(
        CrankSlider(5.0, crank_radius_m=15e-3, rod_length_m=60e-3), k / FS)
    child = ChildNode(tmp_path, 'ipmc_sensor_ros.nodes.estimator_node.main',
                      '-p', 'publish_points:=last_of_block')
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=child.domain)
    node = rclpy.create_node('robot_stack', context=ctx)
    blocks, points, diagnostics = [], [], []
    node.create_subscription(Float64MultiArray, 'deflection/block',
                             lambda m: blocks.append(unpack_block(m, ESTIMATE_COLUMNS)), QOS)
    node.create_subscription(PointStamped, 'deflection', lambda m: points.append(m.point.z), QOS)
    node.create_subscription(DiagnosticArray, '/diagnostics',
                             lambda m: diagnostics.extend(m.status), 10)
    pub = node.create_publisher(Float64MultiArray, 'current', QOS)
    client = Client(ctx, None, '/ipmc_estimator')
    client.ex.add_node(node)
    try:
        client.spin_until(lambda: pub.get_subscription_count() == 1
                          and node.count_publishers('/deflection') == 1
                          and node.count_publishers('/deflection/block') == 1, 'the node',
                          check=child.alive)
        client.spin_for(0.5)       # the node's writers matched with our readers
        # 70-sample blocks: their last samples walk through the crank's 0.2 s cycle
        for a in range(0, k.size, 70):
            pub.publish(pack_block(1000.0 + k[a:a + 70] / FS, current[a:a + 70]))
        client.spin_until(lambda: sum(len(b) for b in blocks) == k.size
                          and len(points) == len(blocks), 'the estimates', check=child.alive)
        client.spin_until(lambda: any(s.level == DiagnosticStatus.ERROR for s in diagnostics),
                          'an ERROR status', check=child.alive)
    finally:
        node.destroy_node()
        client.close()
        rclpy.shutdown(context=ctx)
        child.stop()
    w = np.concatenate([b.values for b in blocks])
    flags = np.concatenate([b.extra[:, 1] for b in blocks])
    beyond = np.abs(w) > 0.011
    assert 0.05 < beyond.mean() < 0.95             # some estimates beyond, some within
    np.testing.assert_array_equal(flags, beyond.astype(float))
    z, last = np.array(points), np.array([b.values[-1] for b in blocks])
    far = np.abs(last) > 0.011
    assert far.any() and not far.all()
    np.testing.assert_array_equal(np.isinf(z), far)
    np.testing.assert_array_equal(np.sign(z), np.sign(last))
    np.testing.assert_array_equal(z[~far], last[~far])
    error = next(s for s in diagnostics if s.level == DiagnosticStatus.ERROR)
    assert 'beyond the geometric limit |w| > 0.011 m' in error.message


def test_estimate_files_flag_the_same_way(tmp_path, capsys):
    from ipmc_sensor_ros.cli.data_verbs import read_estimate
    from ipmc_sensor_ros.physics.model import SensorModel
    from ipmc_sensor_ros.physics.parameters import Geometry
    from ipmc_sensor_ros.simulation.sensor import SensorSimulator
    from ipmc_sensor_ros.simulation.stimuli import CrankSlider

    model = SensorModel.named('h2', Geometry(0.022, 0.007, 0.00036))
    t = np.arange(3000) / FS
    _, i = SensorSimulator(model, FS).run(
        CrankSlider(5.0, crank_radius_m=15e-3, rod_length_m=60e-3), t)
    lines = _record(tmp_path / 'far.csv')[:7]
    lines += [f'{a!r},{b!r}' for a, b in zip(t.tolist(), i.tolist())]
    (tmp_path / 'far.csv').write_text('\n'.join(lines) + '\n')
    assert _estimate(tmp_path / 'far.csv', '--out', tmp_path / 'o') == 0
    est = read_estimate(tmp_path / 'o' / 'far.estimate.csv')
    beyond = np.abs(est['deflection_estimate_m']) > 0.011
    assert beyond.any() and not beyond.all()
    np.testing.assert_array_equal(est['deflection_beyond_limit'], beyond.astype(float))
    assert (f'{beyond.sum()} estimate(s) beyond the geometric limit |w| > L/2 = 0.011 m'
            in capsys.readouterr().out)


# ---------------------------------------------------------------------------
# Output stamps across a parameter change
# ---------------------------------------------------------------------------
@pytest.mark.ros
@pytest.mark.parametrize('delays', [('', 'time_delay(delay_s=0.002)'),
                                    ('time_delay(delay_s=0.002)', '')])
def test_output_stamps_stay_strictly_increasing_when_time_delay_changes(delays):
    """Adding (or removing) ``time_delay`` while running: stamps never repeat or go back."""
    from rclpy.parameter import Parameter

    from conftest import DirectNode

    before, after = ([d] if d else [] for d in delays)
    direct = DirectNode(publish_points='per_sample', **({'effects': before} if before else {}))
    try:
        msgs = one_sample_messages(600, 1000.0)
        for msg in msgs[:300]:
            direct.send(msg)
        result = direct.node.set_parameters(
            [Parameter('effects', Parameter.Type.STRING_ARRAY, after)])
        assert result[0].successful, result[0].reason
        direct.node.settle()
        for msg in msgs[300:]:
            direct.send(msg)
        assert direct.node.rebuilds == 1
        stamps = np.concatenate([b.times_s for b in direct.published])
        points = np.array([sec + 1e-9 * nsec for sec, nsec, *_ in direct.points])
        counters = direct.node.counters()
    finally:
        direct.close()
    assert np.all(np.diff(stamps) > 0), stamps[np.flatnonzero(np.diff(stamps) <= 0)[0]:][:5]
    assert np.all(np.diff(points) > 0)
    # each estimate not published is counted; the invariant holds
    assert counters['samples_out'] == stamps.size
    assert counters['samples_in'] == counters['samples_out'] + counters['samples_dropped']
    assert counters['samples_dropped'] == (2 if before == [] else 0)
