from glob import glob

from setuptools import find_packages, setup

package_name = 'mocap_global'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/weights', glob('weights/*.pt') + glob('weights/*.md')
         + glob('weights/*.json')),
        ('share/' + package_name + '/config', glob('config/*.json')),
    ],
    install_requires=['setuptools'],
    zip_safe=False,
    maintainer='Mocap pipeline maintainers',
    maintainer_email='maintainers@mocap-pipeline.dev',
    description=('GMR: world-frame global motion from the local pose sequence with a bidirectional'
                 ' GRU.'),
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'gmr = mocap_global.node:main',
        ],
        # the core finds the pipeline's parts through these groups (mocap_core.plugins)
        'mocap.nodes': ['gmr = mocap_global.node:GMRNode'],
        'mocap.benches': ['gmr = mocap_global.bench:main'],
        'mocap.commands': ['gmr = mocap_global.training.cli'],
    },
)
