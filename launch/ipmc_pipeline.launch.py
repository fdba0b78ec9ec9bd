# SPDX-License-Identifier: Apache-2.0
"""
Simulator -> estimator pipeline in one namespace.

ros2 launch ipmc_sensor_ros ipmc_pipeline.launch.py namespace:=left \
    estimator_params:=/path/estimator.yaml simulator_params:=/path/simulator.yaml
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


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
        Node(package='ipmc_sensor_ros', executable='ipmc_simulator', name='ipmc_simulator',
             namespace=ns, parameters=[LaunchConfiguration('simulator_params')],
             remappings=[('current', LaunchConfiguration('current_topic'))], output='screen'),
        Node(package='ipmc_sensor_ros', executable='ipmc_estimator', name='ipmc_estimator',
             namespace=ns, parameters=[LaunchConfiguration('estimator_params')],
             remappings=[('current', LaunchConfiguration('current_topic'))], output='screen'),
    ])
