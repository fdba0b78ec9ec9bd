# SPDX-License-Identifier: Apache-2.0
"""Params-file rules and QoS override parameters (params.py helpers) on a real node."""
import os

import pytest

rclpy = pytest.importorskip('rclpy')
from rclpy.node import Node  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from ipmc_sensor_ros.nodes import params as P  # noqa: E402
from ipmc_sensor_ros.nodes import topics as T  # noqa: E402
from ipmc_sensor_ros.interface.specs import Spec  # noqa: E402

SPECS = (Spec('gain', 1.0, float, 'test gain'),)


@pytest.fixture
def context():
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=150 + os.getpid() % 50)
    yield ctx
    rclpy.try_shutdown(context=ctx)


def _node(context, tmp_path, text, extra=()):
    path = tmp_path / 'p.yaml'
    path.write_text(text)
    args = ['--ros-args', '--params-file', str(path), *extra]
    node = Node('ipmc_estimator', context=context, cli_args=args)
    return node, args


def test_renamed_node_takes_its_default_name_section(context, tmp_path):
    node, args = _node(context, tmp_path, '/**/ipmc_estimator:\n  ros__parameters:\n'
                       '    gain: 2.5\n', ['-r', '__node:=left_ipmc'])
    assert node.get_name() == 'left_ipmc'
    P.check_unknown_overrides(node, SPECS, args, default_name='ipmc_estimator')
    P.declare(node, SPECS)
    assert node.get_parameter('gain').value == 2.5
    node.destroy_node()


def test_other_nodes_keys_in_wildcard_section_warn_but_typo_for_this_node_fails(context,
                                                                                tmp_path):
    node, args = _node(context, tmp_path, '/**:\n  ros__parameters:\n    block_size: 10\n')
    P.check_unknown_overrides(node, SPECS, args, default_name='ipmc_estimator')  # no raise
    P.declare(node, SPECS)
    assert not node.has_parameter('block_size')          # warned about, never declared
    node.destroy_node()
    node, args = _node(context, tmp_path, 'ipmc_estimator:\n  ros__parameters:\n    gian: 1.0\n')
    with pytest.raises(P.ParameterError, match="did you mean 'gain' for 'gian'"):
        P.check_unknown_overrides(node, SPECS, args, default_name='ipmc_estimator')
    node.destroy_node()


def test_standard_qos_override_applies_and_a_stray_one_is_refused(context, tmp_path):
    node, args = _node(context, tmp_path, '/**:\n  ros__parameters:\n    gain: 1.0\n',
                       ['-p', 'qos_overrides./out.publisher.reliability:=best_effort'])
    P.check_unknown_overrides(node, SPECS, args)
    pub = T.create_publisher(node, String, 'out', T.COUNTERS_QOS)
    T.check_qos_overrides(node)
    assert pub.qos_profile.reliability == rclpy.qos.ReliabilityPolicy.BEST_EFFORT
    node.destroy_node()
    node, args = _node(context, tmp_path, '/**:\n  ros__parameters:\n    gain: 1.0\n',
                       ['-p', 'qos_overrides./uot.publisher.reliability:=best_effort'])
    P.check_unknown_overrides(node, SPECS, args)
    T.create_publisher(node, String, 'out', T.COUNTERS_QOS)
    with pytest.raises(P.ParameterError, match='uot'):
        T.check_qos_overrides(node)
    node.destroy_node()


@pytest.mark.parametrize('override, shown', [
    ('qos_overrides./out.publisher.reliability:=bestefort', "'bestefort'"),
    ('qos_overrides./out.publisher.depth:=-5', '-5')])
def test_a_qos_override_value_rclpy_refuses_names_the_parameter(context, tmp_path, override,
                                                                shown):
    """A misspelt policy or a negative depth: a ParameterError naming it (no traceback)."""
    node, args = _node(context, tmp_path, '/**:\n  ros__parameters:\n    gain: 1.0\n',
                       ['-p', override])
    with pytest.raises(P.ParameterError) as refused:
        T.create_publisher(node, String, 'out', T.COUNTERS_QOS)
    name = override.split(':=')[0]
    assert f"'{name}': {shown}" in str(refused.value) and 'best_effort' in str(refused.value)
    # rclpy applies overrides to the profile it is given: the shared one stays as it was
    assert T.COUNTERS_QOS.depth == 1
    assert T.COUNTERS_QOS.reliability == rclpy.qos.ReliabilityPolicy.RELIABLE
    node.destroy_node()


def test_mains_hz_written_as_a_number_is_accepted_as_the_simulator_writes_it(
        context, tmp_path):
    """A shared ``/**`` file with ``mains_hz: 50`` (the simulator's integer) starts both."""
    from ipmc_sensor_ros.estimation.config import parse_mains
    from ipmc_sensor_ros.interface.specs import ESTIMATOR_SPECS, check_values

    mains = [s for s in ESTIMATOR_SPECS if s.name == 'mains_hz']
    node, args = _node(context, tmp_path, '/**:\n  ros__parameters:\n    mains_hz: 50\n')
    P.declare(node, mains)
    value = P.read(node, mains)['mains_hz']
    check_values({'mains_hz': value}, mains)              # no raise
    assert parse_mains(value) == 50.0
    node.destroy_node()
    check_values({'mains_hz': -0.0}, mains)               # '0', as 0: no raise
    with pytest.raises(P.ParameterError, match='must be one of'):
        check_values({'mains_hz': 55}, mains)


def test_a_params_file_with_no_section_for_the_node_is_said(context, tmp_path, capfd):
    """A misspelt section key (``/**/ipmc_estimatr``) leaves the node on its defaults: said."""
    node, args = _node(context, tmp_path, '/**/ipmc_estimatr:\n  ros__parameters:\n'
                       '    gain: 2.5\n')
    P.check_unknown_overrides(node, SPECS, args, default_name='ipmc_estimator')
    err = capfd.readouterr().err
    assert 'p.yaml: no section applies to /ipmc_estimator' in err
    assert "did you mean '/**/ipmc_estimator'?" in err
    node.destroy_node()
    node, args = _node(context, tmp_path, '/**:\n  ros__parameters:\n    gain: 2.5\n')
    P.check_unknown_overrides(node, SPECS, args, default_name='ipmc_estimator')
    assert 'no section applies' not in capfd.readouterr().err
    node.destroy_node()


@pytest.mark.parametrize('text, value', [('22e-3', 0.022), ('1', None)])
def test_the_workbench_reads_a_params_file_as_the_node_does(context, tmp_path, text, value):
    """
    A params file means the same to ``--params`` as to the node.

    ``22e-3`` is a number to the node (YAML 1.2) and to ``--params``; ``1`` is an integer,
    which the node refuses for a double parameter, and so does ``--params``.
    """
    from ipmc_sensor_ros.interface.specs import ESTIMATOR_SPECS, load_params_file

    spec = [s for s in ESTIMATOR_SPECS if s.name == 'length_m']
    node, args = _node(context, tmp_path, f'ipmc_estimator:\n  ros__parameters:\n'
                       f'    length_m: {text}\n')
    if value is None:
        with pytest.raises(Exception, match='INTEGER'):
            P.declare(node, spec)
        with pytest.raises(P.ParameterError, match=r"'length_m' = 1 is an integer.*1\.0"):
            load_params_file(tmp_path / 'p.yaml')
    else:
        P.declare(node, spec)
        assert P.read(node, spec)['length_m'] == value
        assert load_params_file(tmp_path / 'p.yaml')['length_m'] == value
    node.destroy_node()
