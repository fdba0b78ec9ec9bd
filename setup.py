# SPDX-License-Identifier: Apache-2.0
from glob import glob

from setuptools import find_packages, setup

package_name = 'ipmc_sensor_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(include=['ipmc_sensor_ros', 'ipmc_sensor_ros.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/launch',
         glob('launch/*.launch.py') + glob('launch/*.launch.xml')),
    ],
    install_requires=['setuptools', 'numpy', 'scipy', 'control', 'pyyaml'],
    extras_require={
        'test': ['pytest', 'hypothesis'],
        'workbench': ['matplotlib', 'rosbags'],
    },
    zip_safe=True,
    maintainer='ipmc_sensor_ros maintainers',
    maintainer_email='ipmc-sensor-ros@example.org',
    description='Physics-based IPMC sensing: deflection estimation, simulation, model workbench',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'ipmc_estimator = ipmc_sensor_ros.nodes.entry:estimator',
            'ipmc_simulator = ipmc_sensor_ros.nodes.entry:simulator',
            'ipmc_estimator_managed = ipmc_sensor_ros.nodes.entry:estimator_managed',
            'ipmc_simulator_managed = ipmc_sensor_ros.nodes.entry:simulator_managed',
            'ipmc-model = ipmc_sensor_ros.cli.main:main',
        ],
    },
)
