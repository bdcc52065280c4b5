# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""Install the wctls_lab ament_python package (colcon build runs this)."""

from setuptools import find_packages, setup

package_name = 'wctls_lab'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={'wctls_lab.simulation': ['plans/*.yaml']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='wctls_ros maintainers',
    maintainer_email='maintainers@wctls-ros.dev',
    description='The wctls_ros lab: simulation, evaluation, benchmarks and the demo.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'calibrate = wctls_lab.evaluation.calibrate_cli:main',
            'demo = wctls_lab.demo:main',
            'evaluate = wctls_lab.evaluation.evaluate_cli:main',
            'score = wctls_lab.evaluation.score_cli:main',
            'simulate = wctls_lab.evaluation.simulate_cli:main',
            'simulated_rplidar = wctls_lab.simulated_rplidar:main',
        ],
    },
)
