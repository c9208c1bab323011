"""Build script for the imu_allan ament_python package."""

from glob import glob
import re

from setuptools import find_packages, setup

PACKAGE = 'imu_allan'
# The version is stated once, in package.xml (as ROS tools read it).
with open('package.xml', encoding='utf-8') as _xml:
    VERSION = re.search(r'<version>([^<]+)</version>', _xml.read()).group(1)

setup(
    name=PACKAGE,
    version=VERSION,
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        ('share/' + PACKAGE + '/config', glob('config/*.yaml')),
        ('share/' + PACKAGE + '/launch', glob('launch/*.launch.py')),
    ],
    package_data={PACKAGE: ['data/*.yaml', 'report/templates/*.html.j2',
                            'report/templates/*.css']},
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='imu_allan maintainers',
    maintainer_email='maintainers@users.noreply.h-seed-36e6b70a.example',
    description='Online and offline IMU noise monitoring with the Allan variance.',
    license='BSD-3-Clause',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'driver = imu_allan.nodes.driver:main',
            'allan = imu_allan.nodes.allan:main',
            'denoise = imu_allan.nodes.denoise:main',
            'analyze = imu_allan.cli.analyze:main',
            'discrepancy = imu_allan.cli.discrepancy:main',
            'gx3_sim = imu_allan.cli.gx3_sim:main',
            'monitor = imu_allan.cli.monitor:main',
            'fleet = imu_allan.cli.fleet:main',
        ],
    },
)
