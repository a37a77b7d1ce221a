from glob import glob

from setuptools import find_packages, setup

package_name = 'mocap_physics'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/weights', glob('weights/*.pt') + glob('weights/*.json')),
    ],
    install_requires=['setuptools'],
    zip_safe=False,
    maintainer='Mocap pipeline maintainers',
    maintainer_email='maintainers@mocap-pipeline.dev',
    description=('Physics cycle of neural PhysCap on Pinocchio: PD control, ground reaction forces'
                 ' in friction cones, forward dynamics, no-penetration QP.'),
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'physics = mocap_physics.node:main',
        ],
        # the core finds the pipeline's parts through these groups (mocap_core.plugins)
        'mocap.nodes': ['physics = mocap_physics.node:PhysicsNode'],
        'mocap.benches': ['physics = mocap_physics.bench:main'],
        'mocap.commands': ['physics = mocap_physics.training.cli'],
    },
)
