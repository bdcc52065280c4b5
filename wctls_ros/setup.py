# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Install the wctls_ros ament_python package (colcon build runs this)."""

from glob import glob

from setuptools import find_packages, setup

package_name = 'wctls_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/config/sensors', glob('config/sensors/*.yaml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='wctls_ros maintainers',
    maintainer_email='maintainers@wctls-ros.dev',
    description='Line segments and corners with calibrated covariances from 2D LiDAR scans.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'bag_replay = wctls_ros.bags.replay_node:main',
            'feature_node = wctls_ros.feature_node:main',
            'odometry_node = wctls_ros.odometry_node:main',
            'process_bag = wctls_ros.bags.process_bag:main',
        ],
    },
)
