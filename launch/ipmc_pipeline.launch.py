# SPDX-License-Identifier: Apache-2.0
"""
Simulator -> estimator pipeline in one namespace.

ros2 launch ipmc_sensor_ros ipmc_pipeline.launch.py namespace:=left \
    estimator_params:=/path/estimator.yaml simulator_params:=/path/simulator.yaml

managed:=true starts the managed (lifecycle) executables ipmc_simulator_managed and
ipmc_estimator_managed with autostart:=true: they configure and activate themselves, and the
lifecycle services stay available (README "Managed nodes").
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition, UnlessCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def _nodes(ns, managed):
    """Return the simulator and estimator actions, plain or managed (``managed`` true)."""
    suffix = '_managed' if managed else ''
    condition = IfCondition if managed else UnlessCondition
    extra = [{'autostart': True}] if managed else []
    return [
        Node(package='ipmc_sensor_ros', executable='ipmc_simulator' + suffix,
             name='ipmc_simulator', namespace=ns,
             parameters=[LaunchConfiguration('simulator_params')] + extra,
             remappings=[('current', LaunchConfiguration('current_topic'))], output='screen',
             condition=condition(LaunchConfiguration('managed'))),
        Node(package='ipmc_sensor_ros', executable='ipmc_estimator' + suffix,
             name='ipmc_estimator', namespace=ns,
             parameters=[LaunchConfiguration('estimator_params')] + extra,
             remappings=[('current', LaunchConfiguration('current_topic'))], output='screen',
             condition=condition(LaunchConfiguration('managed'))),
    ]


def generate_launch_description():
    share = get_package_share_directory('ipmc_sensor_ros')
    ns = LaunchConfiguration('namespace')
    return LaunchDescription([
        DeclareLaunchArgument('namespace', default_value='ipmc',
                              description='namespace of both nodes and their topics'),
        DeclareLaunchArgument('simulator_params',
                              default_value=os.path.join(share, 'config', 'simulator.yaml'),
                              description='params file of the simulator'),
        DeclareLaunchArgument('estimator_params',
                              default_value=os.path.join(share, 'config', 'estimator.yaml'),
                              description='params file of the estimator'),
        DeclareLaunchArgument('current_topic', default_value='current',
                              description='topic of the sensing current (relative to namespace)'),
        DeclareLaunchArgument('managed', default_value='false', choices=['true', 'false'],
                              description='start the managed (lifecycle) executables, '
                                          'self-activating (autostart)'),
    ] + _nodes(ns, managed=False) + _nodes(ns, managed=True))
