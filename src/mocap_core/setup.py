from glob import glob

from setuptools import find_packages, setup

package_name = 'mocap_core'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
    ],
    package_data={'mocap_core.data': ['*.json']},
    install_requires=['setuptools'],
    zip_safe=False,
    maintainer='Mocap pipeline maintainers',
    maintainer_email='maintainers@mocap-pipeline.dev',
    description=('Core library of the monocular motion-capture pipeline: skeleton, rotations, '
                 'forward kinematics, URDF, ROS message conversions, QoS, diagnostics, bag I/O and'
                 ' the ros2/mocap command-line tools. No node.'),
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'ros2 = mocap_core.cli.ros2:main',
            'mocap = mocap_core.cli.mocap:main',
        ],
    },
)
