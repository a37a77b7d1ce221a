"""mocap_core.cdr writes, from arrays, the messages that mocap_core.ros_conversions builds:
deserialised, every encoded message equals the built one (sizes, names, values, the default
fields), on varied inputs; and the bytes are deterministic (rclpy's own serialiser leaves
whatever was in memory in the padding)."""

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message

from mocap_core import cdr
from mocap_core import ros_conversions as rc
from mocap_core.pose import Pose
from mocap_core.rotations import quat_normalize, quat_to_matrix
from mocap_core.skeleton import CONTACT_POINT_NAMES, NUM_JOINTS, Skeleton
from mocap_core.tf import pose_frames, pose_to_transforms
from trajectory_msgs.msg import MultiDOFJointTrajectory


def _pose(seed):
    rng = np.random.default_rng(seed)
    return Pose(Skeleton.from_group_lengths(rng.uniform(0.1, 0.4, 10)),
                quat_normalize(rng.normal(size=(NUM_JOINTS, 4))), rng.normal(size=3) * 3)


HEADERS = [rc.make_header(0, ''), rc.make_header(1_700_000_000_123_456_789, 'camera'),
           rc.make_header(5, 'abc'), rc.make_header(2**31 * 10**9 - 1, 'floor_frame')]


def _same(data, built):
    """The encoded bytes deserialise to the built message as rclpy serialises it (float32
    fields such as colours rounded)."""
    assert isinstance(data, bytes)
    got = deserialize_message(data, type(built))
    assert got == deserialize_message(serialize_message(built), type(built))


@pytest.mark.parametrize('seed', range(4))
def test_motion_joint_states_and_clouds(seed):
    pose, header = _pose(seed), HEADERS[seed]
    _same(cdr.pose_to_motion(pose, header), rc.pose_to_motion(pose, header))
    _same(cdr.pose_to_joint_state(pose, header), rc.pose_to_joint_state(pose, header))
    efforts = np.random.default_rng(seed).normal(size=(NUM_JOINTS - 1, 3))
    _same(cdr.pose_to_joint_state(pose, header, efforts),
          rc.pose_to_joint_state(pose, header, efforts))
    _same(cdr.positions_to_cloud(pose.joint_positions(), header),
          rc.positions_to_cloud(pose.joint_positions(), header))
    bodies = [(3, pose), (1, _pose(seed + 10))]
    _same(cdr.bodies_to_motion(bodies, header), rc.bodies_to_motion(bodies, header))
    _same(cdr.bodies_to_motion([], header), rc.bodies_to_motion([], header))
    positions = np.stack([p.joint_positions() for _, p in bodies])
    _same(cdr.bodies_to_cloud(positions, [3, 1], header),
          rc.bodies_to_cloud(positions, [3, 1], header))
    _same(cdr.bodies_to_cloud(np.zeros((0, NUM_JOINTS, 3)), [], header),
          rc.bodies_to_cloud(np.zeros((0, NUM_JOINTS, 3)), [], header))


def test_cloud_with_nan_is_not_dense():
    header = HEADERS[1]
    pos = _pose(1).joint_positions()
    pos[3] = np.nan
    data = cdr.positions_to_cloud(pos, header)
    _same(data, rc.positions_to_cloud(pos, header))
    assert not deserialize_message(data, type(rc.positions_to_cloud(pos, header))).is_dense


def test_contacts():
    header = HEADERS[2]
    probs = np.array([0.2, 1.5, -0.1, 0.7])
    _same(cdr.contacts_to_msg(probs, header), rc.contacts_to_msg(probs, header))
    mapping = dict(zip(CONTACT_POINT_NAMES, probs))
    _same(cdr.contacts_to_msg(mapping, header), rc.contacts_to_msg(mapping, header))
    bodies = [(2, probs), (5, probs[::-1].copy())]
    _same(cdr.bodies_contacts_to_msg(bodies, header), rc.bodies_contacts_to_msg(bodies, header))


@pytest.mark.parametrize('seed', range(3))
def test_markers(seed):
    pose, header = _pose(seed), HEADERS[seed + 1]
    _same(cdr.pose_to_markers(pose, header), rc.pose_to_markers(pose, header))
    forces = {n: np.random.default_rng(seed).normal(size=3) * 300 for n in CONTACT_POINT_NAMES}
    kwargs = dict(ns=f'physics/body_{seed}', color=rc.person_color(seed + 1),
                  contacts=[0.0, 0.3, 1.0, 0.5], forces=forces, newtons_per_metre=800.0)
    _same(cdr.pose_to_markers(pose, header, **kwargs), rc.pose_to_markers(pose, header,
                                                                          **kwargs))
    # a marker with no points and defaults (as the friction cones' DELETE marker)
    specs = [rc.MarkerSpec('cones', 0, 4, action=2)] + rc.pose_marker_specs(pose, 'x')
    _same(cdr.marker_array(specs, header), rc.marker_array(specs, header))
    _same(cdr.marker_array([], header), rc.marker_array([], header))


def test_tf_message():
    tf2_msgs = pytest.importorskip('tf2_msgs.msg', reason='tf2_msgs is built in the workspace')
    pose, header = _pose(5), HEADERS[1]
    data = cdr.tf_message(header.stamp, *pose_frames(pose, header, 4))
    _same(data, tf2_msgs.TFMessage(transforms=pose_to_transforms(pose, header, 4)))


def test_bytes_are_deterministic_and_zero_padded():
    pose = _pose(0)
    a = cdr.pose_to_motion(pose, rc.make_header(7, 'ab'))
    assert a == cdr.pose_to_motion(pose, rc.make_header(7, 'ab'))
    assert a[:4] == b'\x00\x01\x00\x00'
    # the frame id 'ab' + NUL is padded with one zero byte before the joint-name count
    assert a[16:20] == b'ab\x00\x00'


def test_bad_input_raises_message_error_as_the_builders():
    header = HEADERS[0]
    with pytest.raises(rc.MessageError):
        cdr.positions_to_cloud(np.zeros((3, 2)), header)
    with pytest.raises(rc.MessageError):
        cdr.contacts_to_msg([0.1, 0.2], header)
    with pytest.raises(rc.MessageError):
        cdr.bodies_to_cloud(np.zeros((1, 3, 3)), [0], header)
    with pytest.raises(rc.MessageError):
        cdr.pose_to_joint_state(_pose(0), header, np.zeros(5))


def test_odometry():
    rng = np.random.default_rng(3)
    for header in HEADERS:
        pos, quat = rng.normal(size=3), quat_normalize(rng.normal(size=4))
        _same(cdr.root_to_odometry(pos, quat, header), rc.root_to_odometry(pos, quat, header))
        lin, ang = rng.normal(size=3), rng.normal(size=3)
        _same(cdr.root_to_odometry(pos, quat, header, 'body_2', lin, ang),
              rc.root_to_odometry(pos, quat, header, 'body_2', lin, ang))


def test_wrench_transform_and_point():
    """The physics' forces, centre of mass and floor and the world's floor: every header
    length (the padding before the float64 fields changes with it), a matrix or a
    quaternion for the rotation."""
    rng = np.random.default_rng(4)
    for header in HEADERS:
        f, t, p = rng.normal(size=3) * 500, rng.normal(size=3) * 50, rng.normal(size=3)
        _same(cdr.wrench_to_msg(f, t, header), rc.wrench_to_msg(f, t, header))
        _same(cdr.point_to_msg(p, header), rc.point_to_msg(p, header))
        q = quat_normalize(rng.normal(size=4))
        for child in ('', 'floor', 'body_12/pelvis'):
            _same(cdr.transform_stamped(header, child, q, p),
                  rc.transform_stamped(header, child, q, p))
        R = quat_to_matrix(q)
        _same(cdr.transform_stamped(header, 'floor', R, p),
              rc.transform_stamped(header, 'floor', R, p))


def test_bone_lengths():
    rng = np.random.default_rng(6)
    for header in HEADERS:
        for bodies in ([], [(1, rng.uniform(0.1, 0.5, 10))],
                       [(3, rng.uniform(0.1, 0.5, 10)), (12, rng.uniform(0.1, 0.5, 10))]):
            _same(cdr.bodies_bone_lengths_to_msg(bodies, header),
                  rc.bodies_bone_lengths_to_msg(bodies, header))
    with pytest.raises(ValueError):
        cdr.bodies_bone_lengths_to_msg([(1, np.ones(4))], HEADERS[0])


@pytest.mark.parametrize('frame_id', ['', 'w', 'world', 'odom_frame', 'map_12345'])
def test_path_trail_is_the_appended_path(frame_id):
    """Every frame id length (the layout of the structured poses changes with it), the
    first pose, trimming to max_length, and clearing at a new segment."""
    from nav_msgs.msg import Path
    rng = np.random.default_rng(len(frame_id))
    trail, path = cdr.PathTrail(max_length=5), Path()
    _same(trail.message(), Path())
    for k in range(8):
        header = rc.make_header(10**9 * k + 7 * k, frame_id)
        pos, quat = rng.normal(size=3), quat_normalize(rng.normal(size=4))
        trail.append(header, pos, quat)
        rc.append_to_path(path, rc.root_to_odometry(pos, quat, header), 5)
        _same(trail.message(), path)
        if k == 5:                                   # a new segment
            trail.clear()
            path.poses = []
    assert len(trail) == 2


def _poses_equal(a, b):
    assert a.joint_names == b.joint_names
    np.testing.assert_array_equal(a.rotations, b.rotations)
    np.testing.assert_array_equal(a.root_position, b.root_position)
    np.testing.assert_array_equal(a.skeleton.offsets, b.skeleton.offsets)


@pytest.mark.parametrize('seed', range(4))
def test_decoded_motion_reads_as_the_deserialised_message(seed):
    """What the stages' raw subscriptions read from the bytes (decode_motion) converts to the
    same poses as the rclpy message, for the single-person and the combined motion, written by
    this module or by rclpy (whose padding is not zero)."""
    header = HEADERS[seed]
    pose = _pose(seed)
    bodies = [(4, pose), (2, _pose(seed + 20))]
    for data in (cdr.pose_to_motion(pose, header),
                 serialize_message(rc.pose_to_motion(pose, header))):
        decoded = cdr.decode_motion(data)
        assert isinstance(decoded, cdr.DecodedMotion)
        assert decoded.header == header
        _poses_equal(rc.motion_to_pose(decoded),
                     rc.motion_to_pose(deserialize_message(data, MultiDOFJointTrajectory)))
    for data in (cdr.bodies_to_motion(bodies, header),
                 serialize_message(rc.bodies_to_motion(bodies, header))):
        decoded = cdr.decode_motion(data)
        got = rc.motion_to_bodies(decoded)
        want = rc.motion_to_bodies(deserialize_message(data, MultiDOFJointTrajectory))
        assert [pid for pid, _ in got] == [4, 2] == [pid for pid, _ in want]
        for (_, a), (_, b) in zip(got, want):
            _poses_equal(a, b)
    assert rc.motion_to_bodies(cdr.decode_motion(cdr.bodies_to_motion([], header))) == []


def test_decoded_motion_refuses_what_the_message_path_refuses():
    """Truncated bytes, no point, a transform count unlike the names: MessageError (the
    node's guard drops and counts it); the conversions' own checks (a missing joint, NaN)
    apply to the decoded message as to the deserialised one."""
    from geometry_msgs.msg import Twist
    from trajectory_msgs.msg import MultiDOFJointTrajectoryPoint
    header = HEADERS[1]
    data = cdr.pose_to_motion(_pose(0), header)
    for cut in (0, 3, 10, len(data) // 2, len(data) - 9):
        with pytest.raises(rc.MessageError):
            cdr.decode_motion(data[:cut])
    msg = rc.pose_to_motion(_pose(0), header)
    msg.points = []
    decoded = cdr.decode_motion(serialize_message(msg))
    assert decoded.header == header              # the stamp is read (the stage admits it)
    for convert in (rc.motion_to_pose, rc.motion_to_bodies):
        with pytest.raises(rc.MessageError, match='no point'):
            convert(decoded)
    msg = rc.pose_to_motion(_pose(0), header)
    msg.points[0].transforms = msg.points[0].transforms[:-1]
    with pytest.raises(rc.MessageError, match='transforms'):
        rc.motion_to_pose(cdr.decode_motion(serialize_message(msg)))
    msg = rc.pose_to_motion(_pose(0), header)
    msg.joint_names = msg.joint_names[:-1]
    msg.points[0].transforms = msg.points[0].transforms[:-1]
    with pytest.raises(rc.MessageError, match='lacks joint'):
        rc.motion_to_pose(cdr.decode_motion(serialize_message(msg)))
    msg = rc.pose_to_motion(_pose(0), header)
    msg.points[0].transforms[3].rotation.x = float('nan')
    with pytest.raises(rc.MessageError):
        rc.motion_to_pose(cdr.decode_motion(serialize_message(msg)))
    msg = rc.pose_to_motion(_pose(0), header)
    second = MultiDOFJointTrajectoryPoint()
    second.transforms = msg.points[0].transforms[:3]
    second.velocities = [Twist()] * 2
    msg.points.append(second)                             # a second point is read past
    data = serialize_message(msg)
    _poses_equal(rc.motion_to_pose(cdr.decode_motion(data)),
                 rc.motion_to_pose(rc.pose_to_motion(_pose(0), header)))
    for cut in (len(data) - 9, len(data) - 60, len(data) - 100):   # cut in the second point
        with pytest.raises(rc.MessageError):
            cdr.decode_motion(data[:cut])


def test_decoded_motion_of_another_encapsulation_goes_through_rclpy():
    """Another encapsulation than little-endian CDR is handed to rclpy's deserialiser: these
    little-endian bytes marked big-endian fail there as on the message path."""
    from rclpy._rclpy_pybind11 import RMWError
    data = bytearray(cdr.pose_to_motion(_pose(1), HEADERS[1]))
    data[1] = 0x00
    with pytest.raises(RMWError):
        deserialize_message(bytes(data), MultiDOFJointTrajectory)
    with pytest.raises(RMWError):
        cdr.decode_motion(bytes(data))
