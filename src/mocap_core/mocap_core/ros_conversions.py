"""Thin conversion layer between the core types and standard ROS 2 messages (docs/design.md §2).

Every ``*_to_*`` function has its inverse and a round-trip test. Parsing functions validate the
message and raise :class:`MessageError` (a ``ValueError``) with a one-line reason, so a node
can log it and drop the message instead of crashing.

Topic contracts implemented here:

* keypoints: ``sensor_msgs/PointCloud2``, organised: height = persons, width = 23 keypoints
  (:data:`~mocap_core.skeleton.KEYPOINT_NAMES`), float32 fields ``u``, ``v`` (pixels),
  ``confidence`` in [0, 1] (0 = not seen); frame = camera optical frame;
* joint positions: ``sensor_msgs/PointCloud2``, height 1, width J, float32 ``x, y, z`` (m);
* motion: ``trajectory_msgs/MultiDOFJointTrajectory`` with one point whose ``transforms[i]``
  is joint i's rotation relative to its parent (x, y, z, w) and translation = its rest offset
  from the parent; the root transform is the root pose in ``header.frame_id``;
* joint states: ``sensor_msgs/JointState`` with the URDF's revolute joints (3 per ball joint,
  see :mod:`mocap_core.urdf`); ``effort`` optionally carries joint torques (N m);
* foot contacts: ``sensor_msgs/JointState`` whose ``name`` lists the contact points
  (``left_heel, left_toe, right_heel, right_toe``) and whose ``position`` holds the contact
  probabilities in [0, 1] (stamped and self-describing; velocity/effort empty);
* ground reaction force: ``geometry_msgs/WrenchStamped`` (N, N m);
* root trajectory: ``nav_msgs/Odometry`` and ``nav_msgs/Path``;
* stick figure: ``visualization_msgs/MarkerArray``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

import numpy as np
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import (Point, PointStamped, Pose as PoseMsg, PoseStamped, Quaternion,
                               Transform, TransformStamped, Vector3, Wrench, WrenchStamped)
from nav_msgs.msg import Odometry, Path
from sensor_msgs.msg import CameraInfo, JointState, PointCloud2, PointField
from std_msgs.msg import ColorRGBA, Header, String
from trajectory_msgs.msg import MultiDOFJointTrajectory, MultiDOFJointTrajectoryPoint
from visualization_msgs.msg import Marker, MarkerArray

from .camera import CameraIntrinsics
from .pose import Pose
from .rotations import matrix_to_quat
from .skeleton import CONTACT_POINT_NAMES, JOINT_NAMES, NUM_KEYPOINTS, Skeleton
from .urdf import revolute_joint_names

KEYPOINT_FIELDS: Tuple[str, ...] = ('u', 'v', 'confidence')
#: The optional per-person id field of the keypoint cloud (float32, the same at every point
#: of a row; docs/design.md).
KEYPOINT_ID_FIELD = 'id'
POSITION_FIELDS: Tuple[str, ...] = ('x', 'y', 'z')


class MessageError(ValueError):
    """A message that cannot be converted: missing fields, wrong sizes, NaN, unknown names."""


# ---------------------------------------------------------------------------------------------
# Stamps and headers
# ---------------------------------------------------------------------------------------------
def ns_to_stamp(ns: int) -> Time:
    """Nanoseconds since the epoch -> builtin_interfaces/Time."""
    ns = int(ns)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def stamp_to_ns(stamp: Time) -> int:
    """builtin_interfaces/Time -> integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def make_header(stamp_ns: int, frame_id: str) -> Header:
    """A std_msgs/Header from integer nanoseconds and a frame id."""
    return Header(stamp=ns_to_stamp(stamp_ns), frame_id=str(frame_id))


# ---------------------------------------------------------------------------------------------
# PointCloud2 (float32 fields only)
# ---------------------------------------------------------------------------------------------
def array_to_cloud(values: np.ndarray, fields: Sequence[str], header: Header) -> PointCloud2:
    """(H, W, F) values -> organised PointCloud2 with float32 fields ``fields`` (packed, LE)."""
    values = cloud_values(values, fields)
    height, width, nf = values.shape
    msg = PointCloud2()
    msg.header = header
    msg.height = int(height)
    msg.width = int(width)
    msg.fields = [PointField(name=f, offset=4 * i, datatype=PointField.FLOAT32, count=1)
                  for i, f in enumerate(fields)]
    msg.is_bigendian = False
    msg.point_step = 4 * nf
    msg.row_step = 4 * nf * width
    msg.data = values.astype('<f4').tobytes()
    msg.is_dense = bool(np.all(np.isfinite(values)))
    return msg


def cloud_values(values: np.ndarray, fields: Sequence[str]) -> np.ndarray:
    """``values`` as float64 (H, W, F) for the ``fields``; MessageError for another shape."""
    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 3 or values.shape[-1] != len(fields):
        raise MessageError(f'expected values of shape (H, W, {len(fields)}), got {values.shape}')
    return values


def cloud_to_array(msg: PointCloud2, fields: Sequence[str],
                   width: Optional[int] = None) -> np.ndarray:
    """PointCloud2 -> (H, W, F) float32 array of the named float32 fields.

    Raises:
        MessageError: a field is missing or not one float32, the width differs from
            ``width``, or the data size does not match height, width and steps.
    """
    by_name = {f.name: f for f in msg.fields}
    missing = [f for f in fields if f not in by_name]
    if missing:
        raise MessageError(f'PointCloud2 lacks field(s) {missing}; has {sorted(by_name)}')
    for f in fields:
        pf = by_name[f]
        if pf.datatype != PointField.FLOAT32 or pf.count != 1:
            raise MessageError(f'PointCloud2 field {f!r} must be one FLOAT32 '
                               f'(datatype {PointField.FLOAT32}), got datatype {pf.datatype} '
                               f'count {pf.count}')
        if pf.offset + 4 > msg.point_step:
            raise MessageError(f'PointCloud2 field {f!r} at offset {pf.offset} exceeds '
                               f'point_step {msg.point_step}')
    if width is not None and msg.width != width:
        raise MessageError(f'PointCloud2 width is {msg.width}, expected {width}')
    height, w = int(msg.height), int(msg.width)
    if msg.row_step < msg.point_step * w:
        raise MessageError(f'PointCloud2 row_step {msg.row_step} < point_step {msg.point_step}'
                           f' x width {w}')
    data = bytes(msg.data) if not isinstance(msg.data, (bytes, bytearray)) else msg.data
    if len(data) != msg.row_step * height:
        raise MessageError(f'PointCloud2 data has {len(data)} bytes, expected row_step '
                           f'{msg.row_step} x height {height} = {msg.row_step * height}')
    order = '>' if msg.is_bigendian else '<'
    dtype = np.dtype({'names': list(fields), 'formats': [order + 'f4'] * len(fields),
                      'offsets': [by_name[f].offset for f in fields],
                      'itemsize': msg.point_step})
    out = np.empty((height, w, len(fields)), dtype=np.float32)
    for r in range(height):
        row = np.frombuffer(data, dtype=dtype, count=w, offset=r * msg.row_step)
        for i, f in enumerate(fields):
            out[r, :, i] = row[f]
    return out


def keypoints_to_cloud(keypoints: np.ndarray, header: Header,
                       ids: Optional[Sequence[int]] = None) -> PointCloud2:
    """Keypoints (P, 23, 3) or (23, 3) of (u px, v px, confidence) -> PointCloud2, one row per
    person.

    ``ids`` (P,): the person id of each row (positive integers, 0 = nobody, a padding row);
    when given, the cloud has a fourth float32 field ``id`` holding the row's id at every
    point (exact for ids below 2**24). Confidences are clipped to [0, 1]; a keypoint with a
    non-finite coordinate or confidence is written as (0, 0, 0) (not seen), so consumers never
    receive NaN.
    """
    kp = np.array(keypoints, dtype=np.float64)
    if kp.ndim == 2:
        kp = kp[None]
    if kp.ndim != 3 or kp.shape[1:] != (NUM_KEYPOINTS, 3):
        raise MessageError(f'keypoints must have shape (P, {NUM_KEYPOINTS}, 3), got {kp.shape}')
    kp = sanitize_keypoints(kp)
    if ids is None:
        return array_to_cloud(kp, KEYPOINT_FIELDS, header)
    idv = np.asarray(ids, dtype=np.float64).reshape(-1)
    if len(idv) != len(kp) or not np.all(np.isfinite(idv)) or np.any(idv < 0) or \
            np.any(idv >= 2 ** 24) or np.any(idv != np.round(idv)):
        raise MessageError(f'ids must be {len(kp)} integers in [0, 2**24), got {ids!r}')
    vals = np.concatenate([kp, np.broadcast_to(idv[:, None, None], kp.shape[:2] + (1,))],
                          axis=-1)
    return array_to_cloud(vals, KEYPOINT_FIELDS + (KEYPOINT_ID_FIELD,), header)


def cloud_to_keypoints(msg: PointCloud2) -> np.ndarray:
    """PointCloud2 -> (P, 23, 3) float64 keypoints (u, v, confidence), sanitised like
    :func:`keypoints_to_cloud`. Raises MessageError for a malformed cloud."""
    return sanitize_keypoints(cloud_to_array(msg, KEYPOINT_FIELDS, width=NUM_KEYPOINTS))


def cloud_to_ids(msg: PointCloud2) -> Optional[np.ndarray]:
    """The (P,) int64 person id of each row of a keypoint cloud, or None when the cloud has no
    ``id`` field (an older bag: one person, row 0). A row whose points disagree, or whose id
    is not a non-negative integer, gets 0 (nobody). Raises MessageError for a malformed
    cloud."""
    if not any(f.name == KEYPOINT_ID_FIELD for f in msg.fields):
        return None
    arr = cloud_to_array(msg, (KEYPOINT_ID_FIELD,), width=NUM_KEYPOINTS)[..., 0]
    first = arr[:, 0].astype(np.float64)
    with np.errstate(invalid='ignore'):
        ok = np.all(arr == arr[:, :1], axis=1) & np.isfinite(first) & (first >= 0) & \
            (first == np.round(first))
    return np.where(ok, first, 0.0).astype(np.int64)


def bodies_to_cloud(positions: np.ndarray, ids: Sequence[int], header: Header) -> PointCloud2:
    """(B, J, 3) joint positions (m) of B persons and their (B,) ids -> PointCloud2 with one
    row per person, float32 fields ``x, y, z, id`` (the combined ``/mocap/<stage>/bodies/
    joints3d``). B may be 0 (a cloud of height 0)."""
    return array_to_cloud(bodies_cloud_values(positions, ids),
                          POSITION_FIELDS + (KEYPOINT_ID_FIELD,), header)


def bodies_cloud_values(positions: np.ndarray, ids: Sequence[int]) -> np.ndarray:
    """(B, J, 4) x, y, z, id of :func:`bodies_to_cloud`; MessageError for bad shapes or
    ids."""
    pos = np.asarray(positions, dtype=np.float64)
    if pos.ndim != 3 or pos.shape[-1] != 3:
        raise MessageError(f'positions must have shape (B, J, 3), got {pos.shape}')
    idv = np.asarray(ids, dtype=np.float64).reshape(-1)
    if len(idv) != len(pos) or np.any(idv <= 0) or np.any(idv != np.round(idv)):
        raise MessageError(f'ids must be {len(pos)} positive integers, got {ids!r}')
    return np.concatenate([pos, np.broadcast_to(idv[:, None, None], pos.shape[:2] + (1,))],
                          axis=-1)


def cloud_to_bodies(msg: PointCloud2) -> Tuple[np.ndarray, np.ndarray]:
    """The inverse of :func:`bodies_to_cloud`: (B, J, 3) float64 positions and (B,) int64
    ids. Raises MessageError for a malformed cloud."""
    arr = cloud_to_array(msg, POSITION_FIELDS + (KEYPOINT_ID_FIELD,))
    return arr[..., :3].astype(np.float64), arr[:, 0, 3].astype(np.int64) if arr.shape[1] \
        else np.zeros(len(arr), np.int64)


def person_color(person_id: int, alpha: float = 1.0) -> Tuple[float, float, float, float]:
    """A distinct RGBA colour per person id (golden-angle hues), for markers and plots."""
    import colorsys
    hue = (0.58 + 0.618034 * (int(person_id) - 1)) % 1.0
    r, g, b = colorsys.hsv_to_rgb(hue, 0.75, 1.0)
    return (r, g, b, float(alpha))


#: Positions (m) beyond this magnitude are not a person's pose: the message is rejected.
MAX_POSITION = 1e4

#: Pixel coordinates beyond this magnitude are not from any camera: the keypoint is unseen.
MAX_PIXEL_COORDINATE = 1e5


def sanitize_keypoints(kp: np.ndarray) -> np.ndarray:
    """Copy of (..., 3) keypoints with confidence clipped to [0, 1] and every keypoint that has
    a non-finite value or a coordinate beyond +-:data:`MAX_PIXEL_COORDINATE` px set to
    (0, 0, 0) (not seen)."""
    kp = np.array(kp, dtype=np.float64)
    with np.errstate(invalid='ignore'):
        bad = ~np.all(np.isfinite(kp), axis=-1) | np.any(
            np.abs(kp[..., :2]) > MAX_PIXEL_COORDINATE, axis=-1)
    kp[bad] = 0.0
    kp[..., 2] = np.clip(kp[..., 2], 0.0, 1.0)
    return kp


def positions_to_cloud(positions: np.ndarray, header: Header) -> PointCloud2:
    """(J, 3) joint positions (m) -> PointCloud2 (height 1, width J, fields x, y, z)."""
    return array_to_cloud(positions_cloud_values(positions), POSITION_FIELDS, header)


def positions_cloud_values(positions: np.ndarray) -> np.ndarray:
    """(1, J, 3) float64 values of :func:`positions_to_cloud`; MessageError for a shape that
    is not (J, 3)."""
    pos = np.asarray(positions, dtype=np.float64)
    if pos.ndim != 2 or pos.shape[1] != 3:
        raise MessageError(f'positions must have shape (J, 3), got {pos.shape}')
    return pos[None]


def cloud_to_positions(msg: PointCloud2, num_points: Optional[int] = None) -> np.ndarray:
    """PointCloud2 with x, y, z -> (N, 3) float64 positions (all rows concatenated)."""
    arr = cloud_to_array(msg, POSITION_FIELDS, width=num_points)
    return arr.reshape(-1, 3).astype(np.float64)


# ---------------------------------------------------------------------------------------------
# Motion: MultiDOFJointTrajectory
# ---------------------------------------------------------------------------------------------
def _quat_msg(q: np.ndarray) -> Quaternion:
    return Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))


def _vec_msg(v: np.ndarray) -> Vector3:
    return Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def pose_to_motion(pose: Pose, header: Header) -> MultiDOFJointTrajectory:
    """Pose -> MultiDOFJointTrajectory (one point; lossless, see module docstring)."""
    msg = MultiDOFJointTrajectory()
    msg.header = header
    msg.joint_names = list(pose.joint_names)
    translations = np.array(pose.skeleton.offsets)
    translations[0] = pose.root_position
    point = MultiDOFJointTrajectoryPoint()
    point.transforms = [Transform(translation=_vec_msg(t), rotation=_quat_msg(q))
                        for t, q in zip(translations, pose.rotations)]
    point.time_from_start = Duration(sec=0, nanosec=0)
    msg.points = [point]
    return msg


def _point_transforms(msg: MultiDOFJointTrajectory) -> list:
    """The transforms of the message's first point; MessageError for no point or a count
    that is not the number of joint names."""
    if len(msg.points) == 0:
        raise MessageError('MultiDOFJointTrajectory has no point')
    transforms = msg.points[0].transforms
    if len(transforms) != len(msg.joint_names):
        raise MessageError(f'MultiDOFJointTrajectory has {len(msg.joint_names)} joint names '
                           f'but {len(transforms)} transforms')
    return transforms


class DecodedMotion:
    """A ``trajectory_msgs/MultiDOFJointTrajectory`` read by
    :func:`mocap_core.cdr.decode_motion`: what the stages use of it, as arrays.

    Attributes:
        header: ``std_msgs/Header`` (a message object: stamp and frame id).
        joint_names: the joint names, in the message's order.
        transforms: ``(len(joint_names), 7)`` float64 of the first point: translation x, y, z
            (m) and rotation x, y, z, w of each joint, in the message's order.
        problem: why the transforms cannot be read (no point, a count unlike the names'),
            or None; the conversions (:func:`mocap_core.ros_conversions.motion_to_pose`)
            raise it as MessageError, as they do for the deserialised message.
    """

    __slots__ = ('header', 'joint_names', 'transforms', 'problem')

    def __init__(self, header, joint_names: list, transforms: np.ndarray,
                 problem: Optional[str] = None) -> None:
        self.header = header
        self.joint_names = joint_names
        self.transforms = transforms
        self.problem = problem


def _motion_arrays(msg) -> Tuple[List[str], np.ndarray]:
    """(joint names, (N, 7) translation x, y, z and rotation x, y, z, w of the first point)
    of a MultiDOFJointTrajectory, or of a :class:`DecodedMotion` (the same, read straight
    from the CDR bytes); MessageError as :func:`_point_transforms`."""
    if isinstance(msg, DecodedMotion):
        if msg.problem:
            raise MessageError(msg.problem)
        return msg.joint_names, msg.transforms
    transforms = _point_transforms(msg)
    table = np.array([[t.translation.x, t.translation.y, t.translation.z,
                       t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w]
                      for t in transforms], dtype=np.float64).reshape(-1, 7)
    return list(msg.joint_names), table


def motion_to_pose(msg: MultiDOFJointTrajectory,
                   joint_names: Sequence[str] = JOINT_NAMES) -> Pose:
    """MultiDOFJointTrajectory (or a :class:`DecodedMotion`) -> Pose with
    joints in the order of ``joint_names``.

    The message may list the joints in any order; extra joints are ignored. Raises
    MessageError for no point, a size mismatch, a missing joint, NaN or a zero quaternion.
    """
    return _arrays_to_pose(*_motion_arrays(msg), joint_names)


def _arrays_to_pose(names: Sequence[str], table: np.ndarray,
                    joint_names: Sequence[str] = JOINT_NAMES) -> Pose:
    """:func:`motion_to_pose` of the joint names and (N, 7) table of :func:`_motion_arrays`."""
    index = {n: i for i, n in enumerate(names)}
    missing = [n for n in joint_names if n not in index]
    if missing:
        raise MessageError(f'MultiDOFJointTrajectory lacks joint(s) {missing}')
    if names[0] != joint_names[0]:
        raise MessageError(f'first joint must be the root {joint_names[0]!r}, '
                           f'got {names[0]!r}')
    rows = table[[index[n] for n in joint_names]]
    trans = rows[:, :3].copy()
    quats = rows[:, 3:].copy()
    offsets = trans.copy()
    offsets[0] = 0.0
    with np.errstate(invalid='ignore'):
        far = np.abs(trans) > MAX_POSITION
    if np.any(far):
        raise MessageError(f'invalid motion message: a translation beyond +-{MAX_POSITION:g} m')
    try:
        return Pose(Skeleton(offsets=offsets), quats, trans[0])
    except ValueError as exc:
        raise MessageError(f'invalid motion message: {exc}') from None


# ---------------------------------------------------------------------------------------------
# JointState (revolute angles, optional torques) and contacts
# ---------------------------------------------------------------------------------------------
def pose_to_joint_state(pose: Pose, header: Header,
                        efforts: Optional[np.ndarray] = None) -> JointState:
    """Pose -> JointState of the URDF's revolute joints (rad); ``efforts`` (J-1, 3) N m in the
    same z, y, x order fills ``effort`` (the physics stage's joint torques)."""
    msg = JointState()
    msg.header = header
    msg.name = revolute_joint_names(pose.skeleton)
    msg.position = [float(a) for a in pose.revolute_angles().reshape(-1)]
    if efforts is not None:
        msg.effort = [float(e) for e in effort_values(efforts, len(msg.name))]
    return msg


def effort_values(efforts: np.ndarray, count: int) -> np.ndarray:
    """(count,) float64 joint torques of :func:`pose_to_joint_state`; MessageError for
    another count."""
    eff = np.asarray(efforts, dtype=np.float64).reshape(-1)
    if eff.size != count:
        raise MessageError(f'expected {count} efforts, got {eff.size}')
    return eff


def joint_state_to_angles(msg: JointState, skeleton: Skeleton) -> np.ndarray:
    """JointState -> (J-1, 3) z, y, x revolute angles (rad) for ``skeleton``'s joints.

    Names may come in any order. Raises MessageError for missing names, a length mismatch or
    non-finite angles."""
    if len(msg.position) != len(msg.name):
        raise MessageError(f'JointState has {len(msg.name)} names but {len(msg.position)} '
                           'positions')
    index = {n: i for i, n in enumerate(msg.name)}
    wanted = revolute_joint_names(skeleton)
    missing = [n for n in wanted if n not in index]
    if missing:
        raise MessageError(f'JointState lacks {len(missing)} joint(s), e.g. {missing[:3]}')
    angles = np.array([msg.position[index[n]] for n in wanted], dtype=np.float64)
    if not np.all(np.isfinite(angles)):
        raise MessageError('JointState has non-finite positions')
    return angles.reshape(-1, 3)


def contacts_to_msg(probabilities: Mapping[str, float] | Sequence[float] | np.ndarray,
                    header: Header) -> JointState:
    """Foot contact probabilities -> JointState (name = contact points, position = p)."""
    msg = JointState()
    msg.header = header
    msg.name = list(CONTACT_POINT_NAMES)
    msg.position = [float(v) for v in contact_values(probabilities)]
    return msg


def contact_values(probabilities: Mapping[str, float] | Sequence[float] | np.ndarray
                   ) -> np.ndarray:
    """(4,) contact probabilities in :data:`CONTACT_POINT_NAMES` order, clipped to [0, 1],
    from a mapping by name or a sequence; MessageError for another count."""
    if isinstance(probabilities, Mapping):
        values = np.array([probabilities[n] for n in CONTACT_POINT_NAMES], dtype=np.float64)
    else:
        values = np.asarray(probabilities, dtype=np.float64).reshape(-1)
    if len(values) != len(CONTACT_POINT_NAMES):
        raise MessageError(f'expected {len(CONTACT_POINT_NAMES)} contact probabilities, '
                           f'got {len(values)}')
    return np.clip(values, 0.0, 1.0)


def msg_to_contacts(msg: JointState) -> np.ndarray:
    """Contacts JointState -> (4,) probabilities in :data:`CONTACT_POINT_NAMES` order."""
    if len(msg.position) != len(msg.name):
        raise MessageError(f'contacts message has {len(msg.name)} names but '
                           f'{len(msg.position)} values')
    index = {n: i for i, n in enumerate(msg.name)}
    missing = [n for n in CONTACT_POINT_NAMES if n not in index]
    if missing:
        raise MessageError(f'contacts message lacks {missing}')
    p = np.array([msg.position[index[n]] for n in CONTACT_POINT_NAMES], dtype=np.float64)
    if not np.all(np.isfinite(p)):
        raise MessageError('contacts message has non-finite probabilities')
    return np.clip(p, 0.0, 1.0)


# ---------------------------------------------------------------------------------------------
# Several people in one message (docs/design.md, "Several people")
# ---------------------------------------------------------------------------------------------
def _body_prefix(person_id: int) -> str:
    from .topics import body_name
    return body_name(person_id) + '/'


def _split_bodies(names: Sequence[str]) -> Dict[int, List[int]]:
    """Indices of the names of each ``body_<id>/`` prefix, in order of first appearance."""
    out: Dict[int, List[int]] = {}
    for i, n in enumerate(names):
        head, sep, _ = n.partition('/')
        if not sep or not head.startswith('body_') or not head[5:].isdigit() or \
                int(head[5:]) <= 0:
            raise MessageError(f'joint name {n!r} has no body_<id>/ prefix')
        out.setdefault(int(head[5:]), []).append(i)
    return out


def bodies_to_motion(bodies: Sequence[Tuple[int, Pose]], header: Header
                     ) -> MultiDOFJointTrajectory:
    """Several persons' poses of one frame -> one MultiDOFJointTrajectory: each person's
    joints (as :func:`pose_to_motion`) with names prefixed ``body_<id>/``, in the given order
    (the main person first). Lossless; :func:`motion_to_bodies` is the inverse."""
    msg = MultiDOFJointTrajectory()
    msg.header = header
    point = MultiDOFJointTrajectoryPoint()
    point.time_from_start = Duration(sec=0, nanosec=0)
    for pid, pose in bodies:
        one = pose_to_motion(pose, header)
        prefix = _body_prefix(pid)
        msg.joint_names.extend(prefix + n for n in one.joint_names)
        point.transforms.extend(one.points[0].transforms)
    msg.points = [point]
    return msg


def motion_to_bodies(msg: MultiDOFJointTrajectory) -> List[Tuple[int, Pose]]:
    """The inverse of :func:`bodies_to_motion`: ``[(id, Pose)]`` in the message's order (also
    of a :class:`DecodedMotion`).
    Raises MessageError for a name without a ``body_<id>/`` prefix or a malformed body."""
    names, table = _motion_arrays(msg)
    return [(pid, _arrays_to_pose([names[i].partition('/')[2] for i in idx], table[idx]))
            for pid, idx in _split_bodies(names).items()]


def bodies_contacts_to_msg(bodies: Sequence[Tuple[int, np.ndarray]], header: Header
                           ) -> JointState:
    """Several persons' (4,) contact probabilities -> one JointState, names prefixed
    ``body_<id>/`` (as :func:`contacts_to_msg` per person)."""
    msg = JointState()
    msg.header = header
    for pid, probs in bodies:
        one = contacts_to_msg(probs, header)
        msg.name.extend(_body_prefix(pid) + n for n in one.name)
        msg.position.extend(one.position)
    return msg


def msg_to_bodies_contacts(msg: JointState) -> List[Tuple[int, np.ndarray]]:
    """The inverse of :func:`bodies_contacts_to_msg`: ``[(id, (4,) probabilities)]``."""
    if len(msg.position) != len(msg.name):
        raise MessageError(f'contacts message has {len(msg.name)} names but '
                           f'{len(msg.position)} values')
    out = []
    for pid, idx in _split_bodies(msg.name).items():
        one = JointState()
        one.name = [msg.name[i].partition('/')[2] for i in idx]
        one.position = [msg.position[i] for i in idx]
        out.append((pid, msg_to_contacts(one)))
    return out


def bodies_bone_lengths_to_msg(bodies: Sequence[Tuple[int, np.ndarray]], header: Header
                               ) -> JointState:
    """Several persons' (G,) bone-group lengths (m, :data:`skeleton.BONE_GROUP_NAMES` order)
    -> one JointState: names ``body_<id>/<group>``, ``position`` the lengths. The lifter's
    held skeletons, the signature by which the keypoint node's tracker names a returning
    person (:data:`topics.BODIES_BONE_LENGTHS`)."""
    names, values = bone_lengths_values(bodies)
    msg = JointState()
    msg.header = header
    msg.name = names
    msg.position = [float(x) for x in values]
    return msg


def bone_lengths_values(bodies: Sequence[Tuple[int, np.ndarray]]
                        ) -> Tuple[List[str], np.ndarray]:
    """The names ``body_<id>/<group>`` and (N,) lengths (m) of
    :func:`bodies_bone_lengths_to_msg`; ValueError for a wrong number of lengths."""
    from .skeleton import BONE_GROUP_NAMES
    names: List[str] = []
    values = []
    for pid, lengths in bodies:
        lengths = np.asarray(lengths, dtype=np.float64).ravel()
        if len(lengths) != len(BONE_GROUP_NAMES):
            raise ValueError(f'expected {len(BONE_GROUP_NAMES)} bone-group lengths, got '
                             f'{len(lengths)}')
        names += [_body_prefix(pid) + n for n in BONE_GROUP_NAMES]
        values.append(lengths)
    return names, (np.concatenate(values) if values else np.zeros(0))


def msg_to_bodies_bone_lengths(msg: JointState) -> List[Tuple[int, np.ndarray]]:
    """The inverse of :func:`bodies_bone_lengths_to_msg`: ``[(id, (G,) lengths)]``. Raises
    MessageError for mismatched sizes, unknown or missing groups, or lengths that are not
    finite and positive."""
    from .skeleton import BONE_GROUP_NAMES
    if len(msg.position) != len(msg.name):
        raise MessageError(f'bone-length message has {len(msg.name)} names but '
                           f'{len(msg.position)} values')
    out = []
    for pid, idx in _split_bodies(msg.name).items():
        got = {msg.name[i].partition('/')[2]: float(msg.position[i]) for i in idx}
        if sorted(got) != sorted(BONE_GROUP_NAMES):
            raise MessageError(f'body_{pid}: bone groups {sorted(got)} are not '
                               f'{sorted(BONE_GROUP_NAMES)}')
        lengths = np.array([got[n] for n in BONE_GROUP_NAMES])
        if not np.all(np.isfinite(lengths)) or not np.all(lengths > 0):
            raise MessageError(f'body_{pid}: bone lengths must be finite and positive')
        out.append((pid, lengths))
    return out


def is_bodies_message(names: Sequence[str]) -> bool:
    """Whether joint or contact names are prefixed ``body_<id>/`` (a several-people
    message) rather than plain (one person)."""
    return bool(names) and str(names[0]).startswith('body_') and '/' in str(names[0])


# ---------------------------------------------------------------------------------------------
# Wrench, odometry, path, URDF
# ---------------------------------------------------------------------------------------------
def wrench_to_msg(force: np.ndarray, torque: np.ndarray, header: Header) -> WrenchStamped:
    """Force (3,) N and moment (3,) N m -> WrenchStamped."""
    return WrenchStamped(header=header, wrench=Wrench(force=_vec_msg(np.asarray(force)),
                                                      torque=_vec_msg(np.asarray(torque))))


def point_to_msg(point: np.ndarray, header: Header) -> PointStamped:
    """A point (3,) m -> PointStamped (e.g. the centre of mass)."""
    return PointStamped(header=header, point=Point(x=float(point[0]), y=float(point[1]),
                                                   z=float(point[2])))


def transform_stamped(header: Header, child_frame_id: str, rotation: np.ndarray,
                      translation: np.ndarray) -> TransformStamped:
    """geometry_msgs/TransformStamped of the frame ``child_frame_id`` in ``header.frame_id``
    (as tf2 stores it: ``p_parent = rotation @ p_child + translation``). ``rotation``: (3, 3)
    matrix or (4,) quaternion x, y, z, w; ``translation``: (3,) m."""
    r = np.asarray(rotation, dtype=float)
    q = matrix_to_quat(r) if r.shape == (3, 3) else r.reshape(4)
    return TransformStamped(header=header, child_frame_id=child_frame_id,
                            transform=Transform(translation=_vec_msg(np.asarray(translation)),
                                                rotation=_quat_msg(q)))


def transform_stamped_to_arrays(msg: TransformStamped) -> Tuple[np.ndarray, np.ndarray]:
    """TransformStamped -> (quaternion (4,) x, y, z, w, translation (3,) m)."""
    r, t = msg.transform.rotation, msg.transform.translation
    return np.array([r.x, r.y, r.z, r.w]), np.array([t.x, t.y, t.z])


def msg_to_wrench(msg: WrenchStamped) -> Tuple[np.ndarray, np.ndarray]:
    """WrenchStamped -> (force (3,), torque (3,))."""
    f, t = msg.wrench.force, msg.wrench.torque
    return np.array([f.x, f.y, f.z]), np.array([t.x, t.y, t.z])


def root_to_odometry(position: np.ndarray, orientation: np.ndarray, header: Header,
                     child_frame_id: str = 'pelvis',
                     linear_velocity: Optional[np.ndarray] = None,
                     angular_velocity: Optional[np.ndarray] = None) -> Odometry:
    """Root pose (position (3,) m, quaternion x,y,z,w) and optional twist (m/s, rad/s, in the
    child frame as REP-105 specifies) -> nav_msgs/Odometry."""
    msg = Odometry()
    msg.header = header
    msg.child_frame_id = child_frame_id
    msg.pose.pose = PoseMsg(position=Point(x=float(position[0]), y=float(position[1]),
                                           z=float(position[2])),
                            orientation=_quat_msg(np.asarray(orientation)))
    if linear_velocity is not None:
        msg.twist.twist.linear = _vec_msg(np.asarray(linear_velocity))
    if angular_velocity is not None:
        msg.twist.twist.angular = _vec_msg(np.asarray(angular_velocity))
    return msg


def odometry_to_root(msg: Odometry) -> Tuple[np.ndarray, np.ndarray]:
    """nav_msgs/Odometry -> (position (3,), quaternion (4,) x,y,z,w)."""
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    return np.array([p.x, p.y, p.z]), np.array([q.x, q.y, q.z, q.w])


#: Camera motion states (``mocap_core.camera_motion``) and their encoding in Odometry.
CAMERA_MOTION_STATES = ('static', 'rotating', 'moving', 'unknown')
_KNOWN_VAR = 1e-6       # covariance of a quantity the background determines
_UNKNOWN_VAR = 1e6      # covariance of a quantity it does not (ROS practice: large = ignore)


_MEASURED_VAR = 1e-2     # covariance of a translation measured over the floor (m^2, m^2/s^2)


def camera_motion_to_odometry(state: str, orientation: np.ndarray,
                              angular_velocity: np.ndarray, header: Header,
                              child_frame_id: str, position: Optional[np.ndarray] = None,
                              linear_velocity: Optional[np.ndarray] = None) -> Odometry:
    """A camera-motion estimate -> nav_msgs/Odometry.

    ``header.frame_id`` names the camera frame at the first image (fixed), ``child_frame_id``
    the camera's optical frame now. pose.orientation (x, y, z, w): the current camera frame in
    the first one. twist.angular: rad/s in the current camera frame. The state is in the twist
    covariance, as what the background determines:

    * ``static``: angular velocity exactly 0; linear and angular covariance 1e-6 (the camera
      is known not to move);
    * ``rotating``: linear covariance 1e-6 (known not to translate), angular 1e-6;
    * ``moving``: linear covariance 1e6 (translation unknown), or 1e-2 when the translation
      was measured over the floor (``position`` given); angular 1e-6;
    * ``unknown``: every covariance 1e6 (nothing could be tracked; the orientation is the
      last one).

    ``position`` (3,) m: the camera's position in the first camera frame, measured over the
    floor (``mocap_core.camera_motion``), with ``linear_velocity`` (3,) m/s in the current
    camera frame; pose position covariance 1e-2. None: position 0 with covariance 1e6
    (unknown).
    """
    if state not in CAMERA_MOTION_STATES:
        raise ValueError(f'unknown camera motion state {state!r}')
    w = np.zeros(3) if state == 'static' else np.asarray(angular_velocity, dtype=float)
    known = position is not None and state != 'unknown'
    v = np.zeros(3)
    if known and state == 'moving' and linear_velocity is not None:
        v = np.asarray(linear_velocity, dtype=float)
    msg = root_to_odometry(np.asarray(position, dtype=float) if known else np.zeros(3),
                           orientation, header, child_frame_id, v, w)
    if state in ('static', 'rotating'):
        lin = _KNOWN_VAR
    else:
        lin = _MEASURED_VAR if known else _UNKNOWN_VAR
    ang = _UNKNOWN_VAR if state == 'unknown' else _KNOWN_VAR
    cov = np.zeros((6, 6))
    cov[:3, :3] = np.eye(3) * lin
    cov[3:, 3:] = np.eye(3) * ang
    msg.twist.covariance = cov.ravel().tolist()
    pcov = np.zeros((6, 6))
    pcov[:3, :3] = np.eye(3) * (_MEASURED_VAR if known else _UNKNOWN_VAR)
    pcov[3:, 3:] = np.eye(3) * ang
    msg.pose.covariance = pcov.ravel().tolist()
    return msg


def odometry_to_camera_motion(msg: Odometry) -> Tuple[str, np.ndarray, np.ndarray]:
    """nav_msgs/Odometry of :func:`camera_motion_to_odometry` -> (state, orientation (4,)
    x, y, z, w, angular velocity (3,) rad/s). Raises MessageError when the message is not
    finite."""
    _, q = odometry_to_root(msg)
    a = msg.twist.twist.angular
    w = np.array([a.x, a.y, a.z])
    cov = np.asarray(msg.twist.covariance, dtype=float).reshape(6, 6)
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(w)) and np.all(np.isfinite(cov))
            and np.linalg.norm(q) > 0.5):
        raise MessageError('camera motion: non-finite orientation, angular velocity or '
                           'covariance')
    if cov[3, 3] >= 1.0:
        state = 'unknown'
    elif cov[0, 0] > 1e-4:
        state = 'moving'
    elif not np.any(w):
        state = 'static'
    else:
        state = 'rotating'
    return state, q / np.linalg.norm(q), w


def camera_pose_message_type(kind: str) -> type:
    """The message class of a known camera pose of ``camera_pose_type`` ``kind``: 'odometry'
    (nav_msgs/Odometry) or 'pose' (geometry_msgs/PoseStamped)."""
    return Odometry if kind == 'odometry' else PoseStamped


def camera_pose_from_msg(msg) -> Tuple[int, np.ndarray, np.ndarray]:
    """A known camera pose (nav_msgs/Odometry or geometry_msgs/PoseStamped) -> (stamp ns,
    position (3,) m, orientation (4,) x, y, z, w), unchecked
    (:class:`mocap_core.camera_pose.KnownCameraPoses` checks them)."""
    if isinstance(msg, Odometry):
        p, o = msg.pose.pose.position, msg.pose.pose.orientation
    else:
        p, o = msg.pose.position, msg.pose.orientation
    return (stamp_to_ns(msg.header.stamp), np.array([p.x, p.y, p.z], dtype=float),
            np.array([o.x, o.y, o.z, o.w], dtype=float))


def odometry_to_camera_position(msg: Odometry) -> Optional[np.ndarray]:
    """The camera's position (3,) m in the first camera frame from a message of
    :func:`camera_motion_to_odometry`, or None where it was not measured (pose position
    covariance >= 1, or not finite)."""
    p = msg.pose.pose.position
    pos = np.array([p.x, p.y, p.z], dtype=float)
    var = float(msg.pose.covariance[0])
    if not (np.isfinite(var) and var < 1.0 and np.all(np.isfinite(pos))):
        return None
    return pos


def append_to_path(path: Path, odom: Odometry, max_length: int = 0) -> Path:
    """Append an Odometry's pose to ``path`` (in place; keeps the last ``max_length`` poses
    when > 0) and set its header to the odometry's."""
    path.header = odom.header
    path.poses.append(PoseStamped(header=odom.header, pose=odom.pose.pose))
    if max_length > 0 and len(path.poses) > max_length:
        del path.poses[:len(path.poses) - max_length]
    return path


def urdf_to_msg(urdf: str) -> String:
    """URDF XML -> std_msgs/String (publish transient-local)."""
    return String(data=urdf)


# ---------------------------------------------------------------------------------------------
# Markers
# ---------------------------------------------------------------------------------------------
def _color(rgba: Sequence[float]) -> ColorRGBA:
    return ColorRGBA(r=float(rgba[0]), g=float(rgba[1]), b=float(rgba[2]), a=float(rgba[3]))


def _points(xyz: Iterable[np.ndarray]) -> list:
    return [Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in xyz]


@dataclass
class MarkerSpec:
    """What a visualization_msgs/Marker of the pipeline holds (pose: identity; every other
    field its default): built as a message by :func:`marker_array`, serialised directly by
    :func:`mocap_core.cdr.marker_array`.

    Attributes:
        ns, id, type, action: as in visualization_msgs/Marker.
        scale: (3,) as Marker.scale (m).
        color: (4,) RGBA in [0, 1].
        points: (n, 3) points (m) in the header's frame.
        colors: (n, 4) per-point RGBA, or (0, 4).
    """

    ns: str
    id: int
    type: int
    action: int = Marker.ADD
    scale: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    color: Tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    colors: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))


def marker_array(specs: Sequence[MarkerSpec], header: Header) -> MarkerArray:
    """MarkerArray of the markers ``specs``, all stamped ``header``."""
    markers = []
    for s in specs:
        m = Marker(header=header, ns=s.ns, id=int(s.id), type=int(s.type),
                   action=int(s.action))
        m.pose.orientation.w = 1.0
        m.scale.x, m.scale.y, m.scale.z = (float(v) for v in s.scale)
        m.color = _color(s.color)
        m.points = _points(np.asarray(s.points, dtype=np.float64).reshape(-1, 3))
        m.colors = [_color(c) for c in np.asarray(s.colors, dtype=np.float64).reshape(-1, 4)]
        markers.append(m)
    return MarkerArray(markers=markers)


def pose_marker_specs(pose: Pose, ns: str = 'mocap',
                      color: Sequence[float] = (0.2, 0.6, 1.0, 1.0),
                      contacts: Optional[Sequence[float]] = None,
                      forces: Optional[Dict[str, np.ndarray]] = None,
                      newtons_per_metre: float = 1000.0) -> List[MarkerSpec]:
    """The markers of :func:`pose_to_markers` (which see)."""
    positions = pose.joint_positions()
    color = tuple(float(c) for c in color)
    bones = np.stack([positions[np.asarray(pose.skeleton.parents[1:])], positions[1:]], axis=1)
    specs = [MarkerSpec(ns, 0, Marker.LINE_LIST, scale=(0.02, 0.0, 0.0), color=color,
                        points=bones.reshape(-1, 3)),
             MarkerSpec(ns, 1, Marker.SPHERE_LIST, scale=(0.04, 0.04, 0.04), color=color,
                        points=positions)]
    contact_pos = pose.contact_positions()
    if contacts is not None:
        probs = np.clip(np.asarray(contacts, dtype=np.float64).reshape(-1), 0.0, 1.0)
        specs.append(MarkerSpec(
            ns, 2, Marker.SPHERE_LIST, scale=(0.05, 0.05, 0.05),
            points=np.array([contact_pos[n] for n in CONTACT_POINT_NAMES]),
            colors=np.stack([probs, 1.0 - probs, np.zeros_like(probs),
                             np.ones_like(probs)], axis=1)))
    for k, (name, force) in enumerate(sorted((forces or {}).items())):
        start = contact_pos[name]
        specs.append(MarkerSpec(
            ns, 10 + k, Marker.ARROW, scale=(0.02, 0.04, 0.06), color=(1.0, 0.3, 0.0, 1.0),
            points=np.array([start, start + np.asarray(force) / newtons_per_metre])))
    return specs


def pose_to_markers(pose: Pose, header: Header, ns: str = 'mocap',
                    color: Sequence[float] = (0.2, 0.6, 1.0, 1.0),
                    contacts: Optional[Sequence[float]] = None,
                    forces: Optional[Dict[str, np.ndarray]] = None,
                    newtons_per_metre: float = 1000.0) -> MarkerArray:
    """Stick figure for RViz/Foxglove.

    Markers (namespace ``ns``): id 0 LINE_LIST bones, id 1 SPHERE_LIST joints, id 2 SPHERE_LIST
    contact points coloured from green (free) to red (contact) when ``contacts`` (4,) is
    given, ids 10+ ARROW per foot force when ``forces`` maps a contact point name to a force
    (3,) N (arrow length = force / ``newtons_per_metre``).
    """
    return marker_array(pose_marker_specs(pose, ns, color, contacts, forces,
                                          newtons_per_metre), header)


# ---------------------------------------------------------------------------------------------
# Camera info
# ---------------------------------------------------------------------------------------------
def intrinsics_to_camera_info(intr: CameraIntrinsics, header: Header) -> CameraInfo:
    """CameraIntrinsics -> sensor_msgs/CameraInfo (plumb_bob, zero distortion)."""
    msg = CameraInfo(header=header, width=int(intr.width), height=int(intr.height))
    msg.distortion_model = 'plumb_bob'
    msg.d = [0.0] * 5
    msg.k = [float(v) for v in intr.K.reshape(-1)]
    msg.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    msg.p = [float(intr.fx), 0.0, float(intr.cx), 0.0, 0.0, float(intr.fy), float(intr.cy),
             0.0, 0.0, 0.0, 1.0, 0.0]
    return msg


def camera_info_to_intrinsics(msg: CameraInfo) -> CameraIntrinsics:
    """sensor_msgs/CameraInfo -> CameraIntrinsics (from K). Raises MessageError if invalid."""
    k = list(msg.k)
    try:
        return CameraIntrinsics(int(msg.width), int(msg.height), float(k[0]), float(k[4]),
                                float(k[2]), float(k[5]))
    except (ValueError, IndexError) as exc:
        raise MessageError(f'invalid CameraInfo: {exc}') from None


# ---------------------------------------------------------------------------------------------
# Images: sensor_msgs/Image and CompressedImage <-> NumPy BGR (OpenCV's channel order)
# ---------------------------------------------------------------------------------------------
import array as _array  # noqa: E402  (kept with the image section it serves)

from sensor_msgs.msg import CompressedImage, Image  # noqa: E402

#: Encodings :func:`image_to_bgr` reads: encoding -> (channels, bytes per channel, order).
#: ``order`` names the channels (``'bgr'``, ``'rgb'``, ``'bgra'``, ``'rgba'``, ``'mono'``).
IMAGE_ENCODINGS: Dict[str, Tuple[int, int, str]] = {
    'bgr8': (3, 1, 'bgr'), 'rgb8': (3, 1, 'rgb'), 'bgra8': (4, 1, 'bgra'),
    'rgba8': (4, 1, 'rgba'), 'mono8': (1, 1, 'mono'), 'mono16': (1, 2, 'mono'),
    '8UC1': (1, 1, 'mono'), '8UC3': (3, 1, 'bgr'), '8UC4': (4, 1, 'bgra'),
    '16UC1': (1, 2, 'mono'), 'bgr16': (3, 2, 'bgr'), 'rgb16': (3, 2, 'rgb'),
}
#: Formats :func:`compressed_image_to_bgr` decodes (the codec part of ``format``).
COMPRESSED_FORMATS: Tuple[str, ...] = ('jpeg', 'jpg', 'png')


def image_to_bgr(msg: Image) -> np.ndarray:
    """sensor_msgs/Image -> (H, W, 3) uint8 BGR array (a copy, C-contiguous).

    Reads the 8-bit encodings of :data:`IMAGE_ENCODINGS` as they are and the 16-bit ones
    scaled to 8 bits (value / 257). Raises MessageError for an empty image, an unsupported
    encoding, a ``step`` shorter than a row, or ``data`` whose size is not ``step x height``.
    """
    enc = str(msg.encoding)
    if enc not in IMAGE_ENCODINGS:
        raise MessageError(f'unsupported image encoding {enc!r}; supported: '
                           f'{", ".join(IMAGE_ENCODINGS)}')
    channels, depth, order = IMAGE_ENCODINGS[enc]
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    if height <= 0 or width <= 0:
        raise MessageError(f'empty image ({width}x{height})')
    row = width * channels * depth
    if step < row:
        raise MessageError(f'image step {step} is shorter than a row of {width} x {enc} '
                           f'({row} bytes)')
    data = msg.data
    size = len(data)
    if size != step * height:
        raise MessageError(f'image data has {size} bytes, expected step {step} x height '
                           f'{height} = {step * height} for {width}x{height} {enc}')
    buf = np.frombuffer(data, dtype=np.uint8).reshape(height, step)[:, :row]
    if depth == 2:
        dt = np.dtype('>u2' if msg.is_bigendian else '<u2')
        img16 = np.ascontiguousarray(buf).view(dt).reshape(height, width, channels)
        img = (img16.astype(np.uint32) * 255 // 65535).astype(np.uint8)
    else:
        img = buf.reshape(height, width, channels)
    if order == 'mono':
        return np.ascontiguousarray(np.repeat(img, 3, axis=2))
    if order == 'bgr':
        return np.array(img, copy=True, order='C')
    if order == 'rgb':
        return np.ascontiguousarray(img[:, :, ::-1])
    if order == 'bgra':
        return np.ascontiguousarray(img[:, :, :3])
    return np.ascontiguousarray(img[:, :, 2::-1])  # rgba


def bgr_to_image(image: np.ndarray, header: Header, encoding: str = 'bgr8') -> Image:
    """(H, W, 3) uint8 BGR (or (H, W) gray with ``mono8``) -> sensor_msgs/Image.

    ``encoding`` is ``bgr8``, ``rgb8`` or ``mono8`` (a BGR input is converted to gray with the
    ITU-R BT.601 weights)."""
    img = np.asarray(image)
    if img.dtype != np.uint8:
        raise MessageError(f'image must be uint8, got {img.dtype}')
    if encoding == 'mono8':
        if img.ndim == 3:
            img = np.round(img[..., 0] * 0.114 + img[..., 1] * 0.587
                           + img[..., 2] * 0.299).astype(np.uint8)
        if img.ndim != 2:
            raise MessageError(f'mono8 image must have shape (H, W), got {img.shape}')
        channels = 1
    elif encoding in ('bgr8', 'rgb8'):
        if img.ndim != 3 or img.shape[2] != 3:
            raise MessageError(f'{encoding} image must have shape (H, W, 3), got {img.shape}')
        if encoding == 'rgb8':
            img = img[:, :, ::-1]
        channels = 3
    else:
        raise MessageError(f'cannot write encoding {encoding!r}; use bgr8, rgb8 or mono8')
    img = np.ascontiguousarray(img)
    msg = Image(header=header, height=int(img.shape[0]), width=int(img.shape[1]),
                encoding=encoding, is_bigendian=0, step=int(img.shape[1] * channels))
    msg.data = _array.array('B', img.tobytes())  # array.array: fast, unlike bytes
    return msg


def compressed_image_to_bgr(msg: CompressedImage) -> np.ndarray:
    """sensor_msgs/CompressedImage (JPEG or PNG) -> (H, W, 3) uint8 BGR.

    ``format`` may be the bare codec (``jpeg``) or image_transport's ``"<encoding>; <codec>
    compressed <encoding>"``. Raises MessageError for an empty message, an unsupported format
    (e.g. ``compressedDepth``) or data the codec cannot decode."""
    import cv2

    fmt = str(msg.format).strip().lower()
    if 'compresseddepth' in fmt.replace(' ', ''):
        raise MessageError(f'unsupported compressed format {msg.format!r} (depth images)')
    codec = fmt.split(';')[-1].strip().split(' ')[0] if fmt else ''
    if codec and codec not in COMPRESSED_FORMATS:
        raise MessageError(f'unsupported compressed format {msg.format!r}; supported: '
                           f'{", ".join(COMPRESSED_FORMATS)}')
    if len(msg.data) == 0:
        raise MessageError('empty compressed image')
    img = cv2.imdecode(np.frombuffer(msg.data, dtype=np.uint8), cv2.IMREAD_COLOR)
    if img is None or img.size == 0:
        raise MessageError(f'cannot decode compressed image ({len(msg.data)} bytes, '
                           f'format {msg.format!r})')
    return img


def bgr_to_compressed_image(image: np.ndarray, header: Header, fmt: str = 'jpeg',
                            quality: int = 90) -> CompressedImage:
    """(H, W, 3) uint8 BGR -> sensor_msgs/CompressedImage (``fmt`` ``jpeg`` or ``png``;
    ``quality`` 0-100 for JPEG)."""
    import cv2

    if fmt not in ('jpeg', 'png'):
        raise MessageError(f'cannot write compressed format {fmt!r}; use jpeg or png')
    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
        raise MessageError(f'expected a (H, W, 3) uint8 image, got {img.shape} {img.dtype}')
    params = [cv2.IMWRITE_JPEG_QUALITY, int(quality)] if fmt == 'jpeg' else []
    ok, buf = cv2.imencode('.jpg' if fmt == 'jpeg' else '.png', img, params)
    if not ok:
        raise MessageError(f'OpenCV could not encode the image as {fmt}')
    msg = CompressedImage(header=header, format=fmt)
    msg.data = _array.array('B', buf.tobytes())
    return msg
