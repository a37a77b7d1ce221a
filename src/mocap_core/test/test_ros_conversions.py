import os

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import PointCloud2, PointField

from mocap_core import ros_conversions as rc
from mocap_core.camera import CameraIntrinsics
from mocap_core.pose import Pose
from mocap_core.rotations import quat_angle, quat_normalize
from mocap_core.skeleton import JOINT_NAMES, NUM_JOINTS, NUM_KEYPOINTS, Skeleton

os.environ.setdefault('ROS_PYTHON_CHECK_FIELDS', '1')


def _wire(msg):
    """Serialise and deserialise, as a bag or a topic would."""
    return deserialize_message(serialize_message(msg), type(msg))


@pytest.fixture
def header():
    return rc.make_header(1_700_000_000_123_456_789, 'camera_optical_frame')


@pytest.fixture
def pose():
    rng = np.random.default_rng(3)
    sk = Skeleton.from_group_lengths(rng.uniform(0.08, 0.45, 10))
    return Pose(sk, quat_normalize(rng.normal(size=(NUM_JOINTS, 4))), rng.normal(size=3))


def test_stamp_roundtrip():
    ns = 1_700_000_000_999_999_999
    assert rc.stamp_to_ns(rc.ns_to_stamp(ns)) == ns


def test_keypoints_roundtrip(header):
    rng = np.random.default_rng(0)
    kp = np.concatenate([rng.uniform(0, 640, (2, NUM_KEYPOINTS, 2)),
                         rng.uniform(0, 1, (2, NUM_KEYPOINTS, 1))], axis=-1)
    msg = _wire(rc.keypoints_to_cloud(kp, header))
    assert (msg.height, msg.width) == (2, NUM_KEYPOINTS)
    assert [f.name for f in msg.fields] == ['u', 'v', 'confidence']
    assert msg.header.frame_id == 'camera_optical_frame'
    np.testing.assert_allclose(rc.cloud_to_keypoints(msg), kp.astype(np.float32), rtol=1e-6)


def test_keypoint_ids_roundtrip_and_old_clouds(header):
    kp = np.random.default_rng(1).uniform(0, 1, (3, NUM_KEYPOINTS, 3))
    msg = _wire(rc.keypoints_to_cloud(kp, header, ids=[7, 2, 0]))
    assert [f.name for f in msg.fields] == ['u', 'v', 'confidence', 'id']
    assert rc.cloud_to_ids(msg).tolist() == [7, 2, 0]
    # consumers that read only the keypoints are unaffected by the extra field
    np.testing.assert_allclose(rc.cloud_to_keypoints(msg), kp.astype(np.float32), rtol=1e-6)
    # an older cloud without ids: None (one person, row 0)
    assert rc.cloud_to_ids(rc.keypoints_to_cloud(kp, header)) is None
    # a row whose points disagree, or a negative id, reads as nobody
    vals = np.concatenate([kp, np.zeros((3, NUM_KEYPOINTS, 1))], axis=-1)
    vals[0, :, 3] = 5
    vals[0, 4, 3] = 6
    vals[1, :, 3] = -3
    vals[2, :, 3] = 9
    odd = rc.array_to_cloud(vals, ('u', 'v', 'confidence', 'id'), header)
    assert rc.cloud_to_ids(odd).tolist() == [0, 0, 9]
    for bad in ([1, 2], [1, 2, -1], [1.5, 2, 3], [1, 2, np.nan]):
        with pytest.raises(rc.MessageError):
            rc.keypoints_to_cloud(kp, header, ids=bad)


def test_keypoints_nan_become_unseen(header):
    kp = np.ones((NUM_KEYPOINTS, 3)) * 0.5
    kp[3, 0] = np.nan
    kp[4, 2] = 7.0
    out = rc.cloud_to_keypoints(rc.keypoints_to_cloud(kp, header))[0]
    assert np.all(out[3] == 0) and out[4, 2] == 1.0 and np.all(np.isfinite(out))


def test_keypoints_malformed_clouds_raise(header):
    good = rc.keypoints_to_cloud(np.zeros((1, NUM_KEYPOINTS, 3)), header)
    wrong_width = rc.array_to_cloud(np.zeros((1, 17, 3)), ('u', 'v', 'confidence'), header)
    with pytest.raises(rc.MessageError, match='width'):
        rc.cloud_to_keypoints(wrong_width)
    missing = rc.array_to_cloud(np.zeros((1, NUM_KEYPOINTS, 2)), ('u', 'v'), header)
    with pytest.raises(rc.MessageError, match='confidence'):
        rc.cloud_to_keypoints(missing)
    short = _wire(good)
    short.data = bytes(short.data)[:-4]
    with pytest.raises(rc.MessageError, match='bytes'):
        rc.cloud_to_keypoints(short)
    wrong_type = _wire(good)
    wrong_type.fields[2].datatype = PointField.UINT8
    with pytest.raises(rc.MessageError, match='FLOAT32'):
        rc.cloud_to_keypoints(wrong_type)
    with pytest.raises(rc.MessageError):
        rc.keypoints_to_cloud(np.zeros((5, 3)), header)


def test_cloud_with_padding_and_big_endian(header):
    """Clouds written by other tools (padded points, big endian) are read correctly."""
    vals = np.arange(2 * NUM_KEYPOINTS * 3, dtype=np.float32).reshape(2, NUM_KEYPOINTS, 3) / 100
    msg = PointCloud2(header=header, height=2, width=NUM_KEYPOINTS, is_bigendian=True,
                      point_step=16, row_step=16 * NUM_KEYPOINTS + 8)
    msg.fields = [PointField(name=n, offset=o, datatype=PointField.FLOAT32, count=1)
                  for n, o in (('confidence', 8), ('u', 0), ('v', 4))]
    buf = bytearray(msg.row_step * 2)
    for r in range(2):
        for c in range(NUM_KEYPOINTS):
            start = r * msg.row_step + c * 16
            buf[start:start + 12] = vals[r, c].astype('>f4').tobytes()
    msg.data = bytes(buf)
    np.testing.assert_allclose(rc.cloud_to_keypoints(_wire(msg)), np.clip(vals, 0, None)
                               .clip(max=[np.inf, np.inf, 1.0]), rtol=1e-6)


def test_positions_roundtrip(header, pose):
    pos = pose.joint_positions()
    msg = _wire(rc.positions_to_cloud(pos, header))
    assert [f.name for f in msg.fields] == ['x', 'y', 'z'] and msg.width == NUM_JOINTS
    np.testing.assert_allclose(rc.cloud_to_positions(msg, NUM_JOINTS), pos, atol=1e-6)
    with pytest.raises(rc.MessageError):
        rc.cloud_to_positions(msg, NUM_JOINTS + 1)


def test_motion_roundtrip_is_lossless(header, pose):
    msg = _wire(rc.pose_to_motion(pose, header))
    assert list(msg.joint_names) == list(JOINT_NAMES) and len(msg.points) == 1
    back = rc.motion_to_pose(msg)
    np.testing.assert_array_equal(back.rotations, pose.rotations)
    np.testing.assert_array_equal(back.root_position, pose.root_position)
    np.testing.assert_array_equal(back.skeleton.offsets, pose.skeleton.offsets)
    np.testing.assert_allclose(back.joint_positions(), pose.joint_positions(), atol=1e-12)


def test_motion_any_joint_order_and_errors(header, pose):
    msg = rc.pose_to_motion(pose, header)
    perm = [0] + list(np.random.default_rng(0).permutation(np.arange(1, NUM_JOINTS)))
    msg.joint_names = [msg.joint_names[i] for i in perm]
    msg.points[0].transforms = [msg.points[0].transforms[i] for i in perm]
    np.testing.assert_allclose(rc.motion_to_pose(msg).joint_positions(),
                               pose.joint_positions(), atol=1e-12)
    bad = rc.pose_to_motion(pose, header)
    bad.points[0].transforms = bad.points[0].transforms[:-1]
    with pytest.raises(rc.MessageError, match='transforms'):
        rc.motion_to_pose(bad)
    nan = rc.pose_to_motion(pose, header)
    nan.points[0].transforms[4].rotation.x = float('nan')
    with pytest.raises(rc.MessageError, match='NaN'):
        rc.motion_to_pose(nan)
    empty = rc.pose_to_motion(pose, header)
    empty.points = []
    with pytest.raises(rc.MessageError, match='no point'):
        rc.motion_to_pose(empty)


def test_joint_state_roundtrip(header, pose):
    efforts = np.arange(3 * (NUM_JOINTS - 1), dtype=float).reshape(-1, 3)
    msg = _wire(rc.pose_to_joint_state(pose, header, efforts))
    assert len(msg.name) == 3 * (NUM_JOINTS - 1) and list(msg.effort) == list(efforts.ravel())
    angles = rc.joint_state_to_angles(msg, pose.skeleton)
    back = Pose.rest(pose.skeleton).with_revolute_angles(angles)
    assert np.max(quat_angle(back.rotations[1:], pose.rotations[1:])) < 1e-9
    msg.name = msg.name[:-1]
    with pytest.raises(rc.MessageError):
        rc.joint_state_to_angles(msg, pose.skeleton)


def test_contacts_roundtrip(header):
    p = np.array([0.1, 0.9, 0.0, 1.0])
    msg = _wire(rc.contacts_to_msg(p, header))
    assert list(msg.name) == ['left_heel', 'left_toe', 'right_heel', 'right_toe']
    np.testing.assert_allclose(rc.msg_to_contacts(msg), p)
    msg.position = [0.1, 0.2]
    with pytest.raises(rc.MessageError):
        rc.msg_to_contacts(msg)


def test_wrench_odometry_path_camera_info(header):
    f, t = np.array([1.0, -2.0, 700.0]), np.array([0.1, 0.2, -0.3])
    f2, t2 = rc.msg_to_wrench(_wire(rc.wrench_to_msg(f, t, header)))
    np.testing.assert_array_equal(f2, f) and np.testing.assert_array_equal(t2, t)
    q = quat_normalize(np.array([0.1, 0.2, 0.3, 0.9]))
    odom = _wire(rc.root_to_odometry(np.array([1.0, 2.0, 0.9]), q, header))
    p2, q2 = rc.odometry_to_root(odom)
    np.testing.assert_allclose(p2, [1.0, 2.0, 0.9]) and np.testing.assert_allclose(q2, q)
    from nav_msgs.msg import Path
    path = Path()
    for _ in range(5):
        rc.append_to_path(path, odom, max_length=3)
    assert len(path.poses) == 3
    intr = CameraIntrinsics.from_fov(640, 480, 60.0)
    back = rc.camera_info_to_intrinsics(_wire(rc.intrinsics_to_camera_info(intr, header)))
    assert (back.fx, back.cx, back.width) == pytest.approx((intr.fx, intr.cx, intr.width))


def test_markers_stick_figure(header, pose):
    arr = _wire(rc.pose_to_markers(pose, header, contacts=[1, 0, 0, 1],
                                   forces={'left_heel': np.array([0, 0, 500.0])}))
    lines = arr.markers[0]
    assert len(lines.points) == 2 * (NUM_JOINTS - 1)
    pos = pose.joint_positions()
    p = lines.points[1]
    np.testing.assert_allclose([p.x, p.y, p.z], pos[1])
    assert len(arr.markers[2].colors) == 4 and arr.markers[2].colors[0].r == 1.0
    arrow = arr.markers[3]
    assert arrow.points[1].z - arrow.points[0].z == pytest.approx(0.5)


def test_urdf_msg(pose):
    from mocap_core.urdf import skeleton_to_urdf
    msg = _wire(rc.urdf_to_msg(skeleton_to_urdf(pose.skeleton)))
    assert msg.data.startswith('<?xml') and 'left_knee_rz' in msg.data


# --- images ------------------------------------------------------------------------------------
def _test_image(h=48, w=64):
    rng = np.random.default_rng(11)
    img = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    img[: h // 2, : w // 2] = (10, 120, 240)  # a flat patch: survives JPEG almost unchanged
    return img


@pytest.mark.parametrize('encoding', ['bgr8', 'rgb8'])
def test_image_roundtrip_colour(header, encoding):
    img = _test_image()
    msg = _wire(rc.bgr_to_image(img, header, encoding))
    assert (msg.height, msg.width, msg.encoding, msg.step) == (48, 64, encoding, 64 * 3)
    assert msg.header.stamp == header.stamp
    np.testing.assert_array_equal(rc.image_to_bgr(msg), img)


def test_image_roundtrip_mono(header):
    gray = _test_image()[..., 1]
    msg = _wire(rc.bgr_to_image(gray, header, 'mono8'))
    out = rc.image_to_bgr(msg)
    assert out.shape == (48, 64, 3)
    for c in range(3):
        np.testing.assert_array_equal(out[..., c], gray)


def test_image_reads_alpha_16bit_and_padded_rows(header):
    img = _test_image(6, 5)
    rgba = np.concatenate([img[..., ::-1], np.full((6, 5, 1), 255, np.uint8)], axis=2)
    msg = rc.Image(header=header, height=6, width=5, encoding='rgba8', step=5 * 4 + 3)
    padded = np.zeros((6, 23), np.uint8)
    padded[:, :20] = rgba.reshape(6, 20)
    msg.data = padded.tobytes()
    np.testing.assert_array_equal(rc.image_to_bgr(_wire(msg)), img)

    mono16 = np.arange(30, dtype=np.uint16).reshape(6, 5) * 2000
    for big in (0, 1):
        m16 = rc.Image(header=header, height=6, width=5, encoding='mono16', step=10,
                       is_bigendian=big)
        m16.data = mono16.astype('>u2' if big else '<u2').tobytes()
        out = rc.image_to_bgr(m16)
        np.testing.assert_array_equal(out[..., 0], (mono16.astype(np.uint32) * 255 // 65535))


@pytest.mark.parametrize('change, reason', [
    (dict(encoding='32FC1'), 'unsupported image encoding'),
    (dict(encoding='yuv422'), 'unsupported image encoding'),
    (dict(width=0, height=0, step=0, data=b''), 'empty image'),
    (dict(step=10), 'shorter than a row'),
    (dict(height=49), 'expected step'),           # data of a smaller image: wrong size
    (dict(data=b'\x00' * 100), 'expected step'),  # truncated data
])
def test_image_bad_messages_raise_with_reason(header, change, reason):
    msg = rc.bgr_to_image(_test_image(), header)
    for k, v in change.items():
        setattr(msg, k, v)
    with pytest.raises(rc.MessageError, match=reason):
        rc.image_to_bgr(msg)


def test_compressed_image_roundtrip(header):
    img = _test_image()
    png = _wire(rc.bgr_to_compressed_image(img, header, 'png'))
    assert png.format == 'png' and png.header.stamp == header.stamp
    np.testing.assert_array_equal(rc.compressed_image_to_bgr(png), img)
    jpg = _wire(rc.bgr_to_compressed_image(img, header, 'jpeg', quality=95))
    out = rc.compressed_image_to_bgr(jpg)
    assert out.shape == img.shape
    patch = out[4:18, 4:26].astype(int) - np.array([10, 120, 240])
    assert np.abs(patch).mean() < 3 and np.abs(patch).max() <= 12  # lossy; colour kept
    jpg.format = 'bgr8; jpeg compressed bgr8'  # image_transport's form
    assert rc.compressed_image_to_bgr(jpg).shape == img.shape


@pytest.mark.parametrize('fmt, data, reason', [
    ('16UC1; compressedDepth', b'\x01\x02', 'unsupported compressed format'),
    ('tiff', b'\x01\x02', 'unsupported compressed format'),
    ('jpeg', b'', 'empty compressed image'),
    ('jpeg', b'\xff\xd8\xff\xe0 this is not a jpeg', 'cannot decode'),
])
def test_compressed_image_bad_messages_raise(header, fmt, data, reason):
    msg = rc.CompressedImage(header=header, format=fmt)
    msg.data = data
    with pytest.raises(rc.MessageError, match=reason):
        rc.compressed_image_to_bgr(msg)


def test_bodies_messages_roundtrip(header, pose):
    """Several people in one motion / contacts / joints message, and back."""
    rng = np.random.default_rng(8)
    other = Pose(Skeleton.from_group_lengths(rng.uniform(0.08, 0.45, 10)),
                 quat_normalize(rng.normal(size=(NUM_JOINTS, 4))), rng.normal(size=3))
    msg = _wire(rc.bodies_to_motion([(12, pose), (3, other)], header))
    assert msg.joint_names[0] == 'body_12/pelvis' and len(msg.joint_names) == 2 * NUM_JOINTS
    assert rc.is_bodies_message(msg.joint_names)
    assert not rc.is_bodies_message(rc.pose_to_motion(pose, header).joint_names)
    back = rc.motion_to_bodies(msg)
    assert [pid for pid, _ in back] == [12, 3]             # order kept: the main person first
    for (_, b), ref in zip(back, (pose, other)):
        np.testing.assert_allclose(b.rotations, ref.rotations, atol=1e-12)
        np.testing.assert_allclose(b.root_position, ref.root_position, atol=1e-12)
        np.testing.assert_allclose(b.skeleton.offsets, ref.skeleton.offsets, atol=1e-12)
    c = _wire(rc.bodies_contacts_to_msg([(3, [0.1, 0.2, 0.3, 0.4]), (12, [1, 0, 1, 0])],
                                        header))
    got = rc.msg_to_bodies_contacts(c)
    assert [pid for pid, _ in got] == [3, 12]
    np.testing.assert_allclose(got[0][1], [0.1, 0.2, 0.3, 0.4])
    cloud = _wire(rc.bodies_to_cloud(np.stack([pose.joint_positions(),
                                               other.joint_positions()]), [12, 3], header))
    pos, ids = rc.cloud_to_bodies(cloud)
    assert ids.tolist() == [12, 3]
    np.testing.assert_allclose(pos[1], other.joint_positions(), atol=1e-5)
    # malformed: a name without a body prefix, a body missing a joint
    bad = rc.bodies_to_motion([(1, pose)], header)
    bad.joint_names[4] = 'left_toe'
    with pytest.raises(rc.MessageError, match='prefix'):
        rc.motion_to_bodies(bad)
    short = rc.bodies_to_motion([(1, pose)], header)
    short.joint_names.pop()
    short.points[0].transforms.pop()
    with pytest.raises(rc.MessageError):
        rc.motion_to_bodies(short)
    with pytest.raises(rc.MessageError):
        rc.bodies_to_cloud(np.zeros((2, 18, 3)), [1, 0], header)


def test_bodies_bone_lengths_roundtrip_and_bad_messages(header):
    a = Skeleton.default().group_lengths()
    msg = rc.bodies_bone_lengths_to_msg([(3, a), (7, a * 1.1)], header)
    assert msg.name[0].startswith('body_3/')
    got = rc.msg_to_bodies_bone_lengths(deserialize_message(serialize_message(msg),
                                                            type(msg)))
    assert [pid for pid, _ in got] == [3, 7]
    np.testing.assert_allclose(got[1][1], a * 1.1)
    bad = rc.bodies_bone_lengths_to_msg([(3, a)], header)
    bad.position[2] = float('nan')
    with pytest.raises(rc.MessageError, match='finite'):
        rc.msg_to_bodies_bone_lengths(bad)
    bad = rc.bodies_bone_lengths_to_msg([(3, a)], header)
    bad.name = bad.name[:-1]
    with pytest.raises(rc.MessageError):
        rc.msg_to_bodies_bone_lengths(bad)
    bad.name = ['pelvis'] * len(bad.position)
    with pytest.raises(rc.MessageError, match='prefix'):
        rc.msg_to_bodies_bone_lengths(bad)
    with pytest.raises(ValueError):
        rc.bodies_bone_lengths_to_msg([(3, a[:-1])], header)
