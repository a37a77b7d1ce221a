"""Default topic names of the pipeline, in one place (the design contract, ``docs/design.md``).

Nodes create their publishers and subscriptions with these names; users remap them with
``--ros-args -r /mocap/keypoints2d:=/other`` as usual. Tools (``mocap process``, the recorder,
the benchmarks, the tests) use the same constants.
"""

from __future__ import annotations

# inputs of the keypoint node
IMAGE = '/camera/image_raw'
IMAGE_CAMERA_INFO = '/camera/camera_info'

# keypoint node
KEYPOINTS = '/mocap/keypoints2d'
CAMERA_INFO = '/mocap/camera_info'
ANNOTATED = '/mocap/keypoints2d/annotated'
#: nav_msgs/Odometry: the camera's rotation and motion state estimated from the image
#: background (``ros_conversions.camera_motion_to_odometry`` documents the encoding)
CAMERA_MOTION = '/mocap/camera/motion'
#: suffix of the first image's camera frame (``<optical frame>_start``, the camera-motion
#: estimate's header.frame_id)
START_FRAME_SUFFIX = '_start'
#: frame of the physics outputs with ``derotate_camera``: the floor frame of the first image,
#: which does not turn with the camera (``floor`` turns with it)
FLOOR_START_FRAME = 'floor' + START_FRAME_SUFFIX

# every node
DIAGNOSTICS = '/diagnostics'

# lifter
SKELETON_URDF = '/mocap/skeleton/urdf'
LIFTER_CONTACTS = '/mocap/lifter/contacts'

# physics
PHYSICS_GRF_LEFT = '/mocap/physics/grf/left'
PHYSICS_GRF_RIGHT = '/mocap/physics/grf/right'
PHYSICS_FLOOR = '/mocap/physics/floor'
PHYSICS_COM = '/mocap/physics/com'

# world stage
WORLD_ODOM = '/mocap/world/odom'
WORLD_PATH = '/mocap/world/path'
#: geometry_msgs/TransformStamped: the pose of the world stage's input frame (the physics
#: floor frame, or the camera frame) in ``world``; with a floor input a turn about z and a
#: shift along the floor
WORLD_FLOOR = '/mocap/world/floor'

# ground truth written by the data tools (bags for tests and evaluation)
GROUNDTRUTH_MOTION = '/mocap/groundtruth/motion'
GROUNDTRUTH_JOINTS3D = '/mocap/groundtruth/joints3d'
GROUNDTRUTH_CONTACTS = '/mocap/groundtruth/contacts'
GROUNDTRUTH_CAMERA_POSE = '/mocap/groundtruth/camera_pose'
GROUNDTRUTH_WORLD_MOTION = '/mocap/groundtruth/world_motion'

#: The three 3D stages, in pipeline order.
STAGES = ('lifter', 'physics', 'world')


def stage_prefix(stage: str) -> str:
    """``/mocap/<stage>/``: the namespace of one stage's outputs."""
    if stage not in STAGES:
        raise ValueError(f'unknown stage {stage!r} (one of {", ".join(STAGES)})')
    return f'/mocap/{stage}/'


def stage_topic(stage: str, name: str) -> str:
    """``/mocap/<stage>/<name>``, e.g. ``stage_topic('physics', 'motion')``; ``name`` is one of
    ``motion``, ``joints3d``, ``joint_states``, ``markers`` (common to the three stages) or a
    stage's own output."""
    return stage_prefix(stage) + name


LIFTER_MOTION = stage_topic('lifter', 'motion')
LIFTER_JOINTS3D = stage_topic('lifter', 'joints3d')
LIFTER_JOINT_STATES = stage_topic('lifter', 'joint_states')
LIFTER_MARKERS = stage_topic('lifter', 'markers')
#: trajectory_msgs/MultiDOFJointTrajectory as ``motion``: the lifter's frames before its output
#: smoothing, published as soon as its network releases them (up to the smoothing's radius
#: before ``motion``), while someone listens; the world stage's network reads them
#: (docs/global.md, "What the network reads")
LIFTER_UNSMOOTHED_MOTION = stage_topic('lifter', 'unsmoothed_motion')
PHYSICS_MOTION = stage_topic('physics', 'motion')
PHYSICS_JOINTS3D = stage_topic('physics', 'joints3d')
PHYSICS_JOINT_STATES = stage_topic('physics', 'joint_states')
PHYSICS_MARKERS = stage_topic('physics', 'markers')
WORLD_MOTION = stage_topic('world', 'motion')
WORLD_JOINTS3D = stage_topic('world', 'joints3d')
WORLD_JOINT_STATES = stage_topic('world', 'joint_states')
WORLD_MARKERS = stage_topic('world', 'markers')

# several people (docs/design.md, "Several people"): REP-155's /humans/bodies/<body>/ layout
#: std_msgs/UInt32MultiArray: the ids of the persons tracked in the latest keypoint frame
#: (published by the keypoint node with every frame; empty when nobody is tracked)
BODIES_TRACKED = '/humans/bodies/tracked'


def body_name(person_id: int) -> str:
    """``body_<id>``: the name of a person's body, used both as its TF frame (REP-155's
    ``body_<body_id>``) and as its namespace token (a ROS name token may not start with a
    digit, so the bare id cannot be one)."""
    pid = int(person_id)
    if pid <= 0:
        raise ValueError(f'person ids are positive integers, got {person_id}')
    return f'body_{pid}'


def body_topic(person_id: int, stage: str, name: str) -> str:
    """``/humans/bodies/body_<id>/<stage>/<name>``: one person's output of one stage, e.g.
    ``body_topic(2, 'world', 'motion')``; ``name`` as in :func:`stage_topic`."""
    return f'/humans/bodies/{body_name(person_id)}/{stage_prefix(stage)[len("/mocap/"):]}{name}'


def body_urdf_topic(person_id: int) -> str:
    """``/humans/bodies/body_<id>/urdf``: std_msgs/String (transient local), the person's
    skeleton as URDF (as :data:`SKELETON_URDF` for the main person)."""
    return f'/humans/bodies/{body_name(person_id)}/urdf'


def bodies_topic(stage: str, name: str) -> str:
    """``/mocap/<stage>/bodies/<name>``: one combined message per frame with every person of a
    stage: ``joints3d`` (PointCloud2, one row per person, fields x, y, z, id) or ``markers``
    (MarkerArray, one namespace per person)."""
    return stage_prefix(stage) + 'bodies/' + name


#: sensor_msgs/JointState, transient local: the lifter's held skeleton of every person
#: followed, names ``body_<id>/<bone group>``, positions the lengths (m); re-published when
#: a held skeleton changes. The keypoint node's tracker uses it as a signature to give a
#: person who left and came back their old id (docs/multi_person.md).
BODIES_BONE_LENGTHS = bodies_topic('lifter', 'bone_lengths')

#: Every output topic of the pipeline (what ``record:=true`` of the launch file records).
ALL = [KEYPOINTS, CAMERA_INFO, CAMERA_MOTION, SKELETON_URDF, DIAGNOSTICS, LIFTER_CONTACTS,
       PHYSICS_GRF_LEFT, PHYSICS_GRF_RIGHT, PHYSICS_COM, PHYSICS_FLOOR, WORLD_ODOM, WORLD_PATH,
       WORLD_FLOOR] + [
    stage_topic(stage, leaf) for stage in STAGES
    for leaf in ('motion', 'joints3d', 'joint_states', 'markers')] + [
    BODIES_TRACKED, BODIES_BONE_LENGTHS, '/tf', bodies_topic('lifter', 'contacts'),
    LIFTER_UNSMOOTHED_MOTION, bodies_topic('lifter', 'unsmoothed_motion')] + [
    bodies_topic(stage, leaf) for stage in STAGES for leaf in ('motion', 'joints3d', 'markers')]
#: (The per-person topics /humans/bodies/body_<id>/... come and go with the people: record them
#: with ``ros2 bag record -a`` or by regular expression, ``-e '/humans/bodies/.*'``.)
