from glob import glob

from setuptools import find_packages, setup

package_name = 'mocap_lifter'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/weights', glob('weights/*.pt') + glob('weights/*.md')
         + glob('weights/*.json')),
    ],
    install_requires=['setuptools'],
    zip_safe=False,
    maintainer='Mocap pipeline maintainers',
    maintainer_email='maintainers@mocap-pipeline.dev',
    description=('MotioNet (and VTM) lifter: one symmetric skeleton, joint rotations, root '
                 'position and foot contacts from 2D keypoints.'),
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'lifter = mocap_lifter.node:main',
        ],
        # the core finds the pipeline's parts through these groups (mocap_core.plugins)
        'mocap.nodes': ['lifter = mocap_lifter.node:LifterNode'],
        'mocap.benches': ['lifter = mocap_lifter.bench:main',
                          'people = mocap_lifter.people_bench:main'],
        'mocap.commands': ['lifter = mocap_lifter.training.cli'],
    },
)
