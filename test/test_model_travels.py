# SPDX-License-Identifier: Apache-2.0
"""
From calibration to the field: one model file that travels (issue 28, "done when").

A slim sample with a 300 Hz amplifier pole is calibrated on crank-slider sweeps recorded with
a 10 nA offset drifting -0.5 nA/s; the same sensor is then recorded in the field for 90 s of
robot-like motion with a 25 nA offset.  The field record comes from the exact model (FFT
prediction, :func:`~ipmc_sensor_ros.simulation.daq.daq_current`), not from the estimator's
reduction.  Checked:

* ``fit --save node.yaml``: rcl parses the file, and the node started on
  ``--params-file node.yaml`` carries the fitted corner (read back over the parameter
  services, tests/test_ros_params.py style);
* ``fit --save-model m.yaml`` -> ``estimate field.csv --model-file m.yaml``: raw NRMSE
  within 1.2x of the same estimate with the true model;
* a model file holding the calibration's offset and drift (as ``diagnose --save-model``
  writes it) gives the same estimate unless ``--apply-recording-effects`` is asked for; then
  the estimate changes, and the Kalman estimator's offset state (issue 27) takes up the
  wrong offset instead of carrying it for the whole record.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from ipmc_sensor_ros.cli.main import main
from ipmc_sensor_ros.physics.model import SensorModel
from ipmc_sensor_ros.physics.modelfile import ModelFile, load_model, save_model
from ipmc_sensor_ros.physics.parameters import PAPER_SAMPLES
from ipmc_sensor_ros.simulation.daq import daq_current, robot_motion
from ipmc_sensor_ros.workbench.formats import write_timeseries
from ipmc_sensor_ros.workbench.measurements import TimeSeries

ROOT = Path(__file__).resolve().parents[1]
CORNER_HZ = 300.0
TRUE_EFFECTS = ('surface_resistance', ('amplifier_bandwidth', {'corner_hz': CORNER_HZ}))
CAL_OFFSET = 'current_offset(offset_a=1e-8,drift_a_per_s=-5e-10)'


@pytest.fixture(scope='module')
def calibrated(tmp_path_factory):
    tmp = tmp_path_factory.mktemp('travel')
    cal = tmp / 'cal'
    assert main(['simulate', '--out', str(cal), '--samples', 'slim', '--frequencies', '1:20:6',
                 '--duration', '4', '--seed', '11', '--effects',
                 f'amplifier_bandwidth(corner_hz={CORNER_HZ:g}),{CAL_OFFSET}']) == 0
    assert main(['fit', str(cal), '--model', 'h2', '--effects', 'amplifier_bandwidth',
                 '--save', str(tmp / 'node.yaml'), '--save-model', str(tmp / 'm.yaml'),
                 '--json', str(tmp / 'fit.json')]) == 0
    return tmp


@pytest.fixture(scope='module')
def field(calibrated):
    """90 s of robot motion at 1 kHz, offset 25 nA, 1 % noise (seeded)."""
    geometry = PAPER_SAMPLES['slim']
    t = np.arange(90_000) / 1000.0
    w = robot_motion(t, seed=5)
    truth = SensorModel(geometry, effects=TRUE_EFFECTS)
    i = daq_current(truth, t, w, offset_a=25e-9, noise_fraction=0.01, seed=7)
    path = calibrated / 'field.csv'
    write_timeseries(path, TimeSeries(path='', sample='slim', geometry=geometry, known={},
                                      sample_rate_hz=1000.0, time_s=t, current_a=i,
                                      deflection_m=w))
    save_model(calibrated / 'true.yaml', truth, tool='test: the true sensor')
    return path


def _raw_nrmse(tmp: Path, data: Path, *flags: str) -> float:
    out = tmp / f'est{len(list(tmp.glob("est*")))}'
    js = out.with_suffix('.json')
    assert main(['estimate', str(data), '--out', str(out), '--json', str(js), *flags]) == 0
    return json.loads(js.read_text())[0]['nrmse_raw']


def test_fitted_model_estimates_the_field_record_as_well_as_the_true_one(calibrated, field):
    fitted = load_model(calibrated / 'm.yaml')
    corner = dict(fitted.effects[-1].values)['corner_hz']
    ci = json.loads((calibrated / 'fit.json').read_text())['ci95']['amplifier_bandwidth.corner_hz']
    assert ci[0] <= corner <= ci[1] and abs(corner / CORNER_HZ - 1) < 0.1
    true_err = _raw_nrmse(calibrated, field, '--model-file', str(calibrated / 'true.yaml'))
    fit_err = _raw_nrmse(calibrated, field, '--model-file', str(calibrated / 'm.yaml'))
    last = max(calibrated.glob('est*/field.estimate.csv'), key=lambda p: p.stat().st_mtime_ns)
    written = last.read_text().splitlines()[:12]
    assert ('# params: defaults of the estimator node, material and effects of '
            f"--model-file {calibrated / 'm.yaml'}") in written      # which model made it, said
    print(f'raw NRMSE: fitted model {fit_err:.5f}, true model {true_err:.5f}, '
          f'ratio {fit_err / true_err:.3f}')
    assert fit_err <= 1.2 * true_err          # the criterion


def test_calibration_offset_is_not_carried_to_the_field(calibrated, field, capsys):
    fitted = load_model(calibrated / 'm.yaml')
    # what diagnose --save-model writes on these sweeps: the sensor plus the recording's offset
    # and drift (the drift, extrapolated over 90 s, is 45 nA)
    with_offset = ModelFile(fitted.effects, fitted.material,
                            ModelFile.from_model(effects=(CAL_OFFSET,),
                                                 material=fitted.material).recording_effects,
                            {'tool': 'test'})
    path = with_offset.save(calibrated / 'with_offset.yaml')
    plain = _raw_nrmse(calibrated, field, '--model-file', str(calibrated / 'm.yaml'))
    kept = _raw_nrmse(calibrated, field, '--model-file', str(path))
    err = capsys.readouterr().err
    assert 'recording effects of the calibration not applied: current_offset' in err
    assert kept == pytest.approx(plain, rel=1e-9)     # not applied: the same estimate
    applied = _raw_nrmse(calibrated, field, '--model-file', str(path),
                         '--apply-recording-effects')
    assert 'WARNING' in capsys.readouterr().err
    print(f'raw NRMSE with the calibration offset applied {applied:.5f}, without {plain:.5f}')
    assert applied != pytest.approx(plain, rel=1e-6)  # applied: the estimate changed
    # the offset and its drift are filter states: a wrong calibration offset is learned away in
    # the first seconds, so it costs little on 90 s: measured 0.27 % of the RMS (0.68 against
    # 0.40 %; 0.9 % with the periodic model's innovations test off, 4.4 against 3.5 %); the
    # 45 nA drift carried through the record would cost several percent
    assert applied - plain < 0.005


def _start_node(params: Path, domain: int):
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONPATH=str(ROOT))
    return subprocess.Popen([sys.executable, '-m', 'ipmc_sensor_ros.nodes.estimator_node',
                             '--ros-args', '--params-file', str(params)],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _remote_parameters(node_name: str, names: list[str], domain: int, timeout_s: float = 30.0):
    import rclpy
    from rclpy.parameter_client import AsyncParameterClient

    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=domain)
    try:
        me = rclpy.create_node('travel_probe', context=ctx)
        client = AsyncParameterClient(me, node_name)
        assert client.wait_for_services(timeout_sec=timeout_s), 'node did not come up'
        future = client.get_parameters(names)
        end = time.monotonic() + timeout_s
        executor = rclpy.executors.SingleThreadedExecutor(context=ctx)
        executor.add_node(me)
        while not future.done() and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.1)
        values = future.result().values
        me.destroy_node()
        return {n: v for n, v in zip(names, values)}
    finally:
        rclpy.try_shutdown(context=ctx)


@pytest.mark.ros
def test_node_starts_on_the_saved_params_with_the_fitted_corner(calibrated):
    pytest.importorskip('rclpy')
    from rclpy.parameter import parameter_value_to_python

    domain = int(os.environ.get('ROS_DOMAIN_ID', '0') or 0)
    proc = _start_node(calibrated / 'node.yaml', domain)
    try:
        got = _remote_parameters('ipmc_estimator', ['effects', 'diffusivity_m2_per_s'], domain)
    finally:
        proc.terminate()
        out, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0 and 'Traceback' not in out, out
    fitted = load_model(calibrated / 'm.yaml')
    effects = parameter_value_to_python(got['effects'])
    corner = dict(fitted.effects[-1].values)['corner_hz']
    assert effects == [f'amplifier_bandwidth(corner_hz={corner!r})']
    assert parameter_value_to_python(got['diffusivity_m2_per_s']) == \
        fitted.material.diffusivity_m2_per_s


def _rcl_parse(path: Path, node_name: str) -> dict:
    """Return the parameters rcl's own params-file parser gives ``node_name`` from ``path``."""
    import rclpy

    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, args=[], domain_id=int(os.environ.get('ROS_DOMAIN_ID', '0') or 0))
    try:
        node = rclpy.create_node(node_name, context=ctx, use_global_arguments=False,
                                 cli_args=['--ros-args', '--params-file', str(path)],
                                 start_parameter_services=False, enable_rosout=False,
                                 automatically_declare_parameters_from_overrides=True)
        values = {n: p.value for n, p in node.get_parameters_by_prefix('').items()}
        node.destroy_node()
        return values
    finally:
        rclpy.try_shutdown(context=ctx)


@pytest.mark.ros
def test_rcl_parses_the_saved_params_for_both_nodes(calibrated, tmp_path):
    pytest.importorskip('rclpy')
    from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

    fitted = load_model(calibrated / 'm.yaml')
    corner = dict(fitted.effects[-1].values)['corner_hz']
    for node in ('ipmc_estimator', 'ipmc_simulator'):
        got = _rcl_parse(calibrated / 'node.yaml', node)
        assert got['effects'] == [f'amplifier_bandwidth(corner_hz={corner!r})'], node
        assert got['model'] == 'h2' and got['sample_rate_hz'] == 1000.0
    # the control: the same content with a YAML alias, as PyYAML writes shared lists, is refused
    text = (calibrated / 'node.yaml').read_text()
    aliased = tmp_path / 'aliased.yaml'
    aliased.write_text(text.replace('    effects:\n', '    effects: &id001\n', 1)
                       .rsplit('    effects:', 1)[0] + '    effects: *id001\n')
    with pytest.raises(_rclpy.RCLInvalidROSArgsError, match='aliasing'):
        _rcl_parse(aliased, 'ipmc_simulator')
