"""The whole pipeline live, for machines with a full ROS 2 install (``ros2 launch``):

    ros2 launch mocap_core pipeline.launch.py                       # camera 0
    ros2 launch mocap_core pipeline.launch.py source:=video path:=clip.mp4
    ros2 launch mocap_core pipeline.launch.py source:=topic image_topic:=/camera/image_raw
    ros2 launch mocap_core pipeline.launch.py source:=none          # keypoints from a bag:
    ros2 bag play my_keypoints_bag                                  #   /mocap/keypoints2d

Starts keypoints (unless ``source:=none``), lifter, physics and gmr, each in its own process;
``record:=true`` also records every pipeline topic with ``ros2 bag record`` into ``bag``;
``executor:=single_threaded`` spins the nodes with rclpy's default executor instead of the events
executor (``MOCAP_EXECUTOR``, :mod:`mocap_core.executors`).
``scripts/live.sh`` does the same with ``ros2 run`` where ``ros2 launch`` is not installed.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess, SetEnvironmentVariable
from launch.conditions import IfCondition, UnlessCondition
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node

from mocap_core import topics

#: Every topic of the pipeline (docs/design.md §2), for ``record:=true``.
TOPICS = topics.ALL


def generate_launch_description() -> LaunchDescription:
    arg = LaunchConfiguration
    args = [
        DeclareLaunchArgument('source', default_value='camera', description='keypoint source: '
                              'camera, video, images, topic, openpose_json, or none (no '
                              'keypoint node: play keypoints from a bag)'),
        DeclareLaunchArgument('path', default_value='', description='video file or folder'),
        DeclareLaunchArgument('device', default_value='0', description='camera index or URL'),
        DeclareLaunchArgument('image_topic', default_value='/camera/image_raw'),
        DeclareLaunchArgument('calibration_file', default_value='',
                              description='camera_info YAML (else approximate intrinsics)'),
        DeclareLaunchArgument('lifter_model', default_value='motionet',
                              description="lifter network: 'motionet' or 'vtm' (windowed only)"),
        DeclareLaunchArgument('lifter_mode', default_value='windowed',
                              description='windowed (accurate; latency 14 frames, 16 for '
                                          'VTM) or causal (MotioNet only)'),
        DeclareLaunchArgument('gains_mode', default_value='fixed',
                              description='physics PD gains: fixed or learned'),
        DeclareLaunchArgument('lookahead', default_value='15',
                              description='GMR look-ahead frames (latency)'),
        DeclareLaunchArgument('static_camera', default_value='false',
                              description='GMR: fuse with the camera-frame root (static camera)'),
        DeclareLaunchArgument('record', default_value='false',
                              description='record every pipeline topic'),
        DeclareLaunchArgument('bag', default_value='mocap_live', description='recording folder'),
        DeclareLaunchArgument('executor', default_value='events',
                              description="the node processes' rclpy executor: events or "
                              'single_threaded (MOCAP_EXECUTOR; mocap_core.executors)'),
    ]
    executor = SetEnvironmentVariable('MOCAP_EXECUTOR', arg('executor'))
    keypoints = Node(
        package='mocap_keypoints', executable='keypoints', name='keypoints', output='screen',
        condition=UnlessCondition(PythonExpression(["'", arg('source'), "' == 'none'"])),
        parameters=[{'source': arg('source'), 'path': arg('path'), 'device': arg('device'),
                     'image_topic': arg('image_topic'),
                     'calibration_file': arg('calibration_file')}])
    lifter = Node(package='mocap_lifter', executable='lifter', name='lifter', output='screen',
                  parameters=[{'mode': arg('lifter_mode'), 'model': arg('lifter_model')}])
    physics = Node(package='mocap_physics', executable='physics', name='physics',
                   output='screen', parameters=[{'gains_mode': arg('gains_mode')}])
    gmr = Node(package='mocap_global', executable='gmr', name='gmr', output='screen',
               parameters=[{'lookahead': arg('lookahead'),
                            'static_camera': arg('static_camera')}])
    record = ExecuteProcess(cmd=['ros2', 'bag', 'record', '-o', arg('bag')] + TOPICS,
                            output='screen', condition=IfCondition(arg('record')))
    return LaunchDescription(args + [executor, record, lifter, physics, gmr, keypoints])
