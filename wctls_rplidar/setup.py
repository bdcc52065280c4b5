# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Install the wctls_rplidar ament_python package (colcon build runs this)."""

from glob import glob

from setuptools import find_packages, setup

package_name = 'wctls_rplidar'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='wctls_ros maintainers',
    maintainer_email='maintainers@wctls-ros.dev',
    description='A ROS 2 lifecycle driver and an emulator for the SLAMTEC RPLIDARs.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'rplidar_node = wctls_rplidar.rplidar_node:main',
            'rplidar_emulator = wctls_rplidar.emulator.cli:main',
        ],
    },
)
