from glob import glob

from setuptools import find_packages, setup

package_name = 'mocap_keypoints'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/weights', glob('weights/*.pt') + glob('weights/*.md')),
    ],
    install_requires=['setuptools'],
    zip_safe=False,
    maintainer='Mocap pipeline maintainers',
    maintainer_email='maintainers@mocap-pipeline.dev',
    description=('2D body keypoints with confidences (23-point layout) from a camera, a video '
                 'file, an image topic or OpenPose JSON.'),
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'keypoints = mocap_keypoints.node:main',
        ],
        # the core finds the pipeline's parts through these groups (mocap_core.plugins)
        'mocap.nodes': ['keypoints = mocap_keypoints.node:KeypointsNode'],
        'mocap.commands': ['keypoints = mocap_keypoints.training.cli'],
        'mocap.benches': ['keypoints = mocap_keypoints.bench:main',
                          'multipose = mocap_keypoints.people_bench:main',
                          'recall = mocap_keypoints.recall_bench:main'],
        # the node's detectors, for data generation (mocap data render)
        'mocap.detectors': ['blazepose = mocap_keypoints.detector:BlazePoseDetector'],
    },
)
