"""The pipeline's output messages serialised straight from arrays (issue 20, item 3).

Building an rclpy message means one Python object per point, transform and colour (a
``MultiDOFJointTrajectory`` of 20 joints is 61 objects), and rclpy converts them all again to
serialise. For the topics the stages publish every frame, this module writes the CDR bytes
directly from the numpy arrays with :class:`CdrWriter`; ``Publisher.publish`` accepts them as
they are (rclpy publishes serialised bytes), :class:`~mocap_core.inprocess.InProcessGraph`
records them without serialising and deserialises only for an in-process subscriber.

Every function here has the name and the arguments of the :mod:`mocap_core.ros_conversions`
function that builds the same message, and returns what ``serialize(<that message>)`` would
return, in content: deserialised, the two are equal (``test_cdr.py`` compares every function,
and ``test_process.py`` compares a whole ``mocap process`` output bag with the one written
from rclpy messages). Unlike rclpy's serialiser, the bytes are deterministic: padding is zero
and nothing trails the message.

Encoding: plain little-endian CDR as ROS 2's rmw writes it (the ``00 01 00 00`` encapsulation
header, then every primitive aligned to its own size counted from the end of that header;
strings as uint32 length with the NUL, then the bytes and the NUL; sequences as a uint32 count
then the elements; a struct has no alignment of its own).
"""

from __future__ import annotations

import contextlib
import struct
import sys
from typing import Dict, Iterator, Optional, Sequence, Tuple

import numpy as np
from std_msgs.msg import Header

from .pose import Pose
from .rotations import matrix_to_quat
from .ros_conversions import (KEYPOINT_ID_FIELD, POSITION_FIELDS, DecodedMotion, MessageError,
                              bodies_cloud_values, bone_lengths_values, cloud_values,
                              contact_values, effort_values, pose_marker_specs,
                              positions_cloud_values)
from .skeleton import CONTACT_POINT_NAMES
from .topics import body_name
from .urdf import revolute_joint_names

__all__ = ['CdrWriter', 'DecodedMotion', 'PathTrail', 'bodies_bone_lengths_to_msg',
           'bodies_contacts_to_msg',
           'bodies_to_cloud', 'bodies_to_motion', 'built_messages', 'contacts_to_msg',
           'decode_motion', 'marker_array', 'pose_to_joint_state', 'pose_to_markers',
           'point_to_msg', 'pose_to_motion', 'pose_transforms', 'positions_to_cloud',
           'root_to_odometry', 'tf_message', 'transform_stamped', 'wrench_to_msg']

_ENCAPSULATION = b'\x00\x01\x00\x00'      # CDR_LE, no options
_I32 = struct.Struct('<i')
_U32 = struct.Struct('<I')
_TIME = struct.Struct('<iI')
_FLOAT32 = 7                              # sensor_msgs/PointField.FLOAT32


#: Encoded strings and string sequences (:meth:`CdrWriter.string`, :meth:`CdrWriter.strings`),
#: at most :data:`_CACHE_SIZE` of each (cleared when full: names of people who left).
_STRING_BYTES: Dict[str, bytes] = {}
_STRINGS_BYTES: Dict[Tuple[str, ...], bytes] = {}
_CACHE_SIZE = 4096


def _remember(cache: Dict, key, raw: bytes) -> bytes:
    if len(cache) >= _CACHE_SIZE:
        cache.clear()
    cache[key] = raw
    return raw


class CdrWriter:
    """Appends CDR fields to a buffer (module doc); :meth:`data` returns the message bytes."""

    __slots__ = ('buf',)

    def __init__(self) -> None:
        self.buf = bytearray(_ENCAPSULATION)

    def align(self, n: int) -> None:
        """Zero padding up to a multiple of ``n`` bytes from the start of the payload."""
        pad = -(len(self.buf) - 4) % n
        if pad:
            self.buf += bytes(pad)

    def u8(self, value: int) -> None:
        self.buf.append(int(value) & 0xFF)

    def boolean(self, value: bool) -> None:
        self.buf.append(1 if value else 0)

    def u32(self, value: int) -> None:
        self.align(4)
        self.buf += _U32.pack(value)

    def i32(self, value: int) -> None:
        self.align(4)
        self.buf += _I32.pack(value)

    def time(self, sec: int, nanosec: int) -> None:
        """builtin_interfaces/Time or Duration."""
        self.align(4)
        self.buf += _TIME.pack(sec, nanosec)

    def string(self, text: str) -> None:
        self.align(4)
        raw = _STRING_BYTES.get(text)
        if raw is None:
            encoded = text.encode()
            raw = _remember(_STRING_BYTES, text, _U32.pack(len(encoded) + 1) + encoded + b'\0')
        self.buf += raw

    def strings(self, texts: Sequence[str]) -> None:
        """sequence<string>. The encoding of a name list (joint and frame names: the same
        every frame) is kept: after the first uint32's alignment it does not depend on where
        the sequence starts."""
        self.align(4)
        key = tuple(texts)
        raw = _STRINGS_BYTES.get(key)
        if raw is None:
            w = CdrWriter()
            w.u32(len(key))
            for t in key:
                w.string(t)
            raw = _remember(_STRINGS_BYTES, key, bytes(w.buf[len(_ENCAPSULATION):]))
        self.buf += raw

    def header(self, header) -> None:
        """std_msgs/Header from a Header message (its stamp and frame id)."""
        self.time(header.stamp.sec, header.stamp.nanosec)
        self.string(header.frame_id)

    def float64s(self, values: np.ndarray) -> None:
        """float64 values in C order, no count (a fixed array, or the fields of structs made
        only of float64, e.g. geometry_msgs/Transform = 7 float64)."""
        values = np.ascontiguousarray(values, dtype='<f8')
        if values.size:
            self.align(8)
            self.buf += values.tobytes()

    def float32s(self, values: np.ndarray) -> None:
        """float32 values in C order, no count (e.g. std_msgs/ColorRGBA = 4 float32)."""
        values = np.ascontiguousarray(values, dtype='<f4')
        if values.size:
            self.align(4)
            self.buf += values.tobytes()

    def float64_sequence(self, values: np.ndarray) -> None:
        """sequence<double>."""
        values = np.asarray(values, dtype=np.float64).reshape(-1)
        self.u32(len(values))
        self.float64s(values)

    def octets(self, raw: bytes) -> None:
        """sequence<uint8>."""
        self.u32(len(raw))
        self.buf += raw

    def data(self) -> bytes:
        return bytes(self.buf)


# ---------------------------------------------------------------------------------------------
# Motion: trajectory_msgs/MultiDOFJointTrajectory (mocap_core.ros_conversions.pose_to_motion)
# ---------------------------------------------------------------------------------------------
def pose_transforms(pose: Pose) -> np.ndarray:
    """(J, 7) translation x, y, z (m) and rotation x, y, z, w of each joint's transform, as
    the motion message and the TF frames carry them: the root pose, then each joint's
    offset from its parent and rotation relative to it."""
    out = np.empty((len(pose.rotations), 7))
    out[:, :3] = pose.skeleton.offsets
    out[0, :3] = pose.root_position
    out[:, 3:] = pose.rotations
    return out


def _motion(header, names: Sequence[str], transforms: np.ndarray) -> bytes:
    w = CdrWriter()
    w.header(header)
    w.strings(names)
    w.u32(1)                                # one point
    w.u32(len(transforms))
    w.float64s(transforms)
    w.u32(0)                                # velocities
    w.u32(0)                                # accelerations
    w.time(0, 0)                            # time_from_start
    return w.data()


def pose_to_motion(pose: Pose, header) -> bytes:
    """As :func:`mocap_core.ros_conversions.pose_to_motion`, serialised."""
    return _motion(header, pose.joint_names, pose_transforms(pose))


def bodies_to_motion(bodies: Sequence[Tuple[int, Pose]], header) -> bytes:
    """As :func:`mocap_core.ros_conversions.bodies_to_motion`, serialised."""
    names = [f'{body_name(pid)}/{n}' for pid, pose in bodies for n in pose.joint_names]
    transforms = (np.concatenate([pose_transforms(pose) for _, pose in bodies])
                  if bodies else np.zeros((0, 7)))
    return _motion(header, names, transforms)


class _Reader:
    """Reads little-endian CDR fields (the module doc's encoding); MessageError past the
    end."""

    __slots__ = ('data', 'pos')

    def __init__(self, data: bytes) -> None:
        self.data = data
        self.pos = 4                                  # after the encapsulation header

    def _take(self, n: int, align: int) -> int:
        start = self.pos + (-(self.pos - 4) % align)
        end = start + n
        if end > len(self.data):
            raise MessageError(f'truncated message ({len(self.data)} bytes)')
        self.pos = end
        return start

    def u32(self) -> int:
        return _U32.unpack_from(self.data, self._take(4, 4))[0]

    def time(self) -> Tuple[int, int]:
        return _TIME.unpack_from(self.data, self._take(8, 4))

    def string(self) -> str:
        n = self.u32()
        start = self._take(n, 1)
        return self.data[start:start + max(n - 1, 0)].decode(errors='replace')

    def float64s(self, count: int) -> np.ndarray:
        if count == 0:
            return np.zeros(0)
        start = self._take(8 * count, 8)
        return np.frombuffer(self.data, dtype='<f8', count=count, offset=start).astype(float)


#: Sequences longer than this in a motion message are malformed (a person has 18 joints).
_MAX_JOINTS = 100_000


def decode_motion(data: bytes):
    """The CDR bytes of a ``trajectory_msgs/MultiDOFJointTrajectory`` (as
    :func:`pose_to_motion` / :func:`bodies_to_motion` or any ROS 2 publisher write it) as a
    :class:`DecodedMotion`, without building a Python object per transform (what a raw
    subscription of the motion topics receives). Another encapsulation than little-endian CDR
    is deserialised with rclpy and returned as the message. Only the first point's transforms
    are kept; every point is read past, so that a truncated message raises MessageError
    (where rclpy's deserialiser raises). No point, or a first point whose transforms are not
    one per joint name, is the decoded message's ``problem``."""
    data = bytes(data)
    if data[:2] != _ENCAPSULATION[:2]:
        if len(data) < 4:
            raise MessageError(f'truncated message ({len(data)} bytes)')
        from rclpy.serialization import deserialize_message
        from trajectory_msgs.msg import MultiDOFJointTrajectory
        return deserialize_message(data, MultiDOFJointTrajectory)
    r = _Reader(data)
    header = Header()
    header.stamp.sec, header.stamp.nanosec = r.time()
    header.frame_id = r.string()
    n = r.u32()
    if n > _MAX_JOINTS:
        raise MessageError(f'MultiDOFJointTrajectory with {n} joint names')
    names = [r.string() for _ in range(n)]
    points = r.u32()
    if points == 0:
        return DecodedMotion(header, names, np.zeros((0, 7)),
                             'MultiDOFJointTrajectory has no point')
    if points > _MAX_JOINTS:
        raise MessageError(f'MultiDOFJointTrajectory with {points} points')
    m = r.u32()
    if m > _MAX_JOINTS:
        raise MessageError(f'MultiDOFJointTrajectory with {m} transforms')
    transforms = r.float64s(7 * m).reshape(m, 7)
    for p in range(points):                 # the rest of every point is read past (checked)
        if p > 0:
            k = r.u32()
            if k > _MAX_JOINTS:
                raise MessageError(f'MultiDOFJointTrajectory with {k} transforms')
            if k:
                r._take(56 * k, 8)                  # geometry_msgs/Transform: 7 float64
        for _ in range(2):                          # velocities, accelerations
            k = r.u32()
            if k > _MAX_JOINTS:
                raise MessageError(f'MultiDOFJointTrajectory with {k} velocities')
            if k:
                r._take(48 * k, 8)                  # geometry_msgs/Twist: 6 float64
        r.time()                                    # time_from_start
    if m != n:
        return DecodedMotion(header, names, transforms, f'MultiDOFJointTrajectory has {n} '
                             f'joint names but {m} transforms')
    return DecodedMotion(header, names, transforms)


# ---------------------------------------------------------------------------------------------
# sensor_msgs/JointState: joint angles, contacts
# ---------------------------------------------------------------------------------------------
def _joint_state(header, names: Sequence[str], position: np.ndarray,
                 effort: Optional[np.ndarray] = None) -> bytes:
    w = CdrWriter()
    w.header(header)
    w.strings(names)
    w.float64_sequence(position)
    w.u32(0)                                # velocity
    w.float64_sequence(np.zeros(0) if effort is None else effort)
    return w.data()


def pose_to_joint_state(pose: Pose, header, efforts: Optional[np.ndarray] = None) -> bytes:
    """As :func:`mocap_core.ros_conversions.pose_to_joint_state`, serialised."""
    names = revolute_joint_names(pose.skeleton)
    eff = None if efforts is None else effort_values(efforts, len(names))
    return _joint_state(header, names, pose.revolute_angles().reshape(-1), eff)


def bodies_bone_lengths_to_msg(bodies: Sequence[Tuple[int, np.ndarray]], header) -> bytes:
    """As :func:`mocap_core.ros_conversions.bodies_bone_lengths_to_msg`, serialised (the
    same ValueError for a wrong number of lengths)."""
    names, values = bone_lengths_values(bodies)
    return _joint_state(header, names, values)


def contacts_to_msg(probabilities, header) -> bytes:
    """As :func:`mocap_core.ros_conversions.contacts_to_msg`, serialised."""
    return _joint_state(header, CONTACT_POINT_NAMES, contact_values(probabilities))


def bodies_contacts_to_msg(bodies: Sequence[Tuple[int, np.ndarray]], header) -> bytes:
    """As :func:`mocap_core.ros_conversions.bodies_contacts_to_msg`, serialised."""
    names = [f'{body_name(pid)}/{n}' for pid, _ in bodies for n in CONTACT_POINT_NAMES]
    values = (np.concatenate([contact_values(p) for _, p in bodies]) if bodies
              else np.zeros(0))
    return _joint_state(header, names, values)


# ---------------------------------------------------------------------------------------------
# sensor_msgs/PointCloud2 of float32 fields
# ---------------------------------------------------------------------------------------------
def array_to_cloud(values: np.ndarray, fields: Sequence[str], header) -> bytes:
    """As :func:`mocap_core.ros_conversions.array_to_cloud`, serialised."""
    values = cloud_values(values, fields)
    height, width, nf = values.shape
    w = CdrWriter()
    w.header(header)
    w.u32(height)
    w.u32(width)
    w.u32(nf)
    for i, name in enumerate(fields):
        w.string(name)
        w.u32(4 * i)
        w.u8(_FLOAT32)
        w.u32(1)
    w.boolean(False)                        # is_bigendian
    w.u32(4 * nf)
    w.u32(4 * nf * width)
    w.octets(values.astype('<f4').tobytes())
    w.boolean(bool(np.all(np.isfinite(values))))
    return w.data()


def positions_to_cloud(positions: np.ndarray, header) -> bytes:
    """As :func:`mocap_core.ros_conversions.positions_to_cloud`, serialised."""
    return array_to_cloud(positions_cloud_values(positions), POSITION_FIELDS, header)


def bodies_to_cloud(positions: np.ndarray, ids: Sequence[int], header) -> bytes:
    """As :func:`mocap_core.ros_conversions.bodies_to_cloud`, serialised."""
    return array_to_cloud(bodies_cloud_values(positions, ids),
                          POSITION_FIELDS + (KEYPOINT_ID_FIELD,), header)


# ---------------------------------------------------------------------------------------------
# visualization_msgs/MarkerArray
# ---------------------------------------------------------------------------------------------
def _marker(w: CdrWriter, header, spec) -> None:
    """One visualization_msgs/Marker from a :class:`~mocap_core.ros_conversions.MarkerSpec`
    (every field the spec does not set has its default)."""
    w.header(header)
    w.string(spec.ns)
    w.i32(spec.id)
    w.i32(spec.type)
    w.i32(spec.action)
    w.float64s(np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]))     # pose: identity
    w.float64s(np.asarray(spec.scale, dtype=np.float64))
    w.float32s(np.asarray(spec.color, dtype=np.float64))
    w.time(0, 0)                            # lifetime
    w.boolean(False)                        # frame_locked
    points = np.asarray(spec.points, dtype=np.float64).reshape(-1, 3)
    w.u32(len(points))
    w.float64s(points)
    colors = np.asarray(spec.colors, dtype=np.float64).reshape(-1, 4)
    w.u32(len(colors))
    w.float32s(colors)
    w.string('')                            # texture_resource
    w.time(0, 0)                            # texture: sensor_msgs/CompressedImage, empty
    w.string('')
    w.string('')
    w.u32(0)
    w.u32(0)                                # uv_coordinates
    w.string('')                            # text
    w.string('')                            # mesh_resource
    w.string('')                            # mesh_file: filename, data
    w.u32(0)
    w.boolean(False)                        # mesh_use_embedded_materials


def marker_array(specs: Sequence, header) -> bytes:
    """As :func:`mocap_core.ros_conversions.marker_array`, serialised."""
    w = CdrWriter()
    w.u32(len(specs))
    for spec in specs:
        _marker(w, header, spec)
    return w.data()


def pose_to_markers(pose: Pose, header, ns: str = 'mocap',
                    color: Sequence[float] = (0.2, 0.6, 1.0, 1.0),
                    contacts: Optional[Sequence[float]] = None,
                    forces: Optional[Dict[str, np.ndarray]] = None,
                    newtons_per_metre: float = 1000.0) -> bytes:
    """As :func:`mocap_core.ros_conversions.pose_to_markers`, serialised."""
    return marker_array(pose_marker_specs(pose, ns, color, contacts, forces,
                                          newtons_per_metre), header)


# ---------------------------------------------------------------------------------------------
# tf2_msgs/TFMessage
# ---------------------------------------------------------------------------------------------
def tf_message(stamp, parents: Sequence[str], children: Sequence[str],
               transforms: np.ndarray) -> bytes:
    """A TFMessage of n transforms with one stamp (builtin_interfaces/Time): ``parents`` and
    ``children`` (n,) frame ids, ``transforms`` (n, 7) translation x, y, z (m) and rotation
    quaternion x, y, z, w (see :func:`mocap_core.tf.frames_of_bodies`)."""
    w = CdrWriter()
    w.u32(len(children))
    sec, nanosec = stamp.sec, stamp.nanosec
    for parent, child, tr in zip(parents, children, np.asarray(transforms, dtype=np.float64)):
        w.time(sec, nanosec)
        w.string(parent)
        w.string(child)
        w.float64s(tr)
    return w.data()


# ---------------------------------------------------------------------------------------------
# nav_msgs/Odometry and nav_msgs/Path
# ---------------------------------------------------------------------------------------------
def root_to_odometry(position: np.ndarray, orientation: np.ndarray, header,
                     child_frame_id: str = 'pelvis',
                     linear_velocity: Optional[np.ndarray] = None,
                     angular_velocity: Optional[np.ndarray] = None) -> bytes:
    """As :func:`mocap_core.ros_conversions.root_to_odometry`, serialised (covariances
    zero)."""
    values = np.zeros(85)            # pose 7, pose covariance 36, twist 6, twist covariance 36
    values[:3] = position
    values[3:7] = orientation
    if linear_velocity is not None:
        values[43:46] = linear_velocity
    if angular_velocity is not None:
        values[46:49] = angular_velocity
    w = CdrWriter()
    w.header(header)
    w.string(child_frame_id)
    w.float64s(values)
    return w.data()


# ---------------------------------------------------------------------------------------------
# geometry_msgs: WrenchStamped, TransformStamped, PointStamped
# ---------------------------------------------------------------------------------------------
def wrench_to_msg(force: np.ndarray, torque: np.ndarray, header) -> bytes:
    """As :func:`mocap_core.ros_conversions.wrench_to_msg`, serialised: force (3,) N and
    moment (3,) N m."""
    w = CdrWriter()
    w.header(header)
    w.float64s(np.concatenate([np.asarray(force, dtype=float).reshape(3),
                               np.asarray(torque, dtype=float).reshape(3)]))
    return w.data()


def transform_stamped(header, child_frame_id: str, rotation: np.ndarray,
                      translation: np.ndarray) -> bytes:
    """As :func:`mocap_core.ros_conversions.transform_stamped`, serialised: ``rotation`` (3, 3)
    or a quaternion (4,) x, y, z, w; ``translation`` (3,) m."""
    r = np.asarray(rotation, dtype=float)
    q = matrix_to_quat(r) if r.shape == (3, 3) else r.reshape(4)
    w = CdrWriter()
    w.header(header)
    w.string(child_frame_id)
    w.float64s(np.concatenate([np.asarray(translation, dtype=float).reshape(3), q]))
    return w.data()


def point_to_msg(point: np.ndarray, header) -> bytes:
    """As :func:`mocap_core.ros_conversions.point_to_msg`, serialised: a point (3,) m."""
    w = CdrWriter()
    w.header(header)
    w.float64s(np.asarray(point, dtype=float).reshape(3))
    return w.data()


class PathTrail:
    """The poses of a nav_msgs/Path kept as arrays, newest last, at most ``max_length`` (0:
    no limit); :meth:`message` serialises the Path in one pass over the arrays.

    It is what :func:`mocap_core.ros_conversions.append_to_path` builds: every pose stamped
    with the header it was appended with, the path's header the last one's. All poses share
    one frame id (the stage's output frame); appending a pose in another frame clears the
    trail first.
    """

    def __init__(self, max_length: int = 0) -> None:
        self.max_length = int(max_length)
        self.frame_id = ''
        self.stamps = np.zeros((0, 2), dtype=np.int64)     # sec, nanosec
        self.poses = np.zeros((0, 7))                       # x, y, z, qx, qy, qz, qw

    def __len__(self) -> int:
        return len(self.poses)

    def clear(self) -> None:
        self.stamps, self.poses = self.stamps[:0], self.poses[:0]

    def append(self, header, position: np.ndarray, orientation: np.ndarray) -> None:
        """Append a pose (position (3,) m, quaternion x, y, z, w) stamped ``header``."""
        if header.frame_id != self.frame_id:
            self.clear()
            self.frame_id = header.frame_id
        keep = len(self.poses) + 1 - self.max_length if self.max_length > 0 else 0
        keep = max(keep, 0)
        self.stamps = np.concatenate([self.stamps[keep:],
                                      [[header.stamp.sec, header.stamp.nanosec]]])
        self.poses = np.concatenate([self.poses[keep:],
                                     np.concatenate([position, orientation])[None]])

    def message(self) -> bytes:
        """The serialised nav_msgs/Path (the header of the newest pose)."""
        w = CdrWriter()
        n = len(self.poses)
        sec, nanosec = (int(v) for v in self.stamps[-1]) if n else (0, 0)
        w.time(sec, nanosec)
        w.string(self.frame_id)
        w.u32(n)
        if n == 0:
            return w.data()
        # the first PoseStamped as it falls; it ends 8-aligned, so every later one has the
        # same layout and is written as one structured array
        w.time(sec=int(self.stamps[0, 0]), nanosec=int(self.stamps[0, 1]))
        w.string(self.frame_id)
        w.float64s(self.poses[0])
        if n > 1:
            raw = self.frame_id.encode() + b'\x00'
            pose_at = -(-(12 + len(raw)) // 8) * 8
            rest = np.zeros(n - 1, dtype=np.dtype({
                'names': ['sec', 'nanosec', 'length', 'frame_id', 'pose'],
                'formats': ['<i4', '<u4', '<u4', f'S{len(raw)}', ('<f8', 7)],
                'offsets': [0, 4, 8, 12, pose_at], 'itemsize': pose_at + 56}))
            rest['sec'], rest['nanosec'] = self.stamps[1:, 0], self.stamps[1:, 1]
            rest['length'] = len(raw)
            rest['frame_id'] = raw
            rest['pose'] = self.poses[1:]
            w.buf += rest.tobytes()
        return w.data()


# ---------------------------------------------------------------------------------------------
# The reference: the same messages built as rclpy objects
# ---------------------------------------------------------------------------------------------
_ENCODERS = ('pose_to_motion', 'bodies_to_motion', 'pose_to_joint_state', 'contacts_to_msg',
             'bodies_contacts_to_msg', 'positions_to_cloud', 'bodies_to_cloud',
             'pose_to_markers', 'marker_array', 'root_to_odometry', 'wrench_to_msg',
             'transform_stamped', 'point_to_msg', 'bodies_bone_lengths_to_msg')


@contextlib.contextmanager
def built_messages() -> Iterator[None]:
    """Within the block, every encoder of this module (and the path trail's message) builds
    the rclpy message with :mod:`mocap_core.ros_conversions` and serialises it with rclpy:
    the stages' outputs as they were made before this module. For the equivalence test
    (``test/test_process.py``) and the baseline of ``mocap bench pipeline``. Not
    thread-safe: it swaps module attributes."""
    from nav_msgs.msg import Path

    from . import ros_conversions as rc
    from .ros_msgs import serialize

    def built(fn):
        return lambda *a, **k: serialize(fn(*a, **k))

    def path_message(trail: PathTrail) -> bytes:
        # a Path message kept beside the trail and appended to, as the stage did before
        path = trail.__dict__.setdefault('_reference', Path())
        stamps = [(int(a), int(b)) for a, b in trail.stamps]
        last = ((path.poses[-1].header.stamp.sec, path.poses[-1].header.stamp.nanosec)
                if path.poses else None)
        if last is None or last not in stamps:
            path.poses = []
            start = 0
        else:
            start = stamps.index(last) + 1
        for (sec, nanosec), p in zip(stamps[start:], trail.poses[start:]):
            header = rc.make_header(sec * 1_000_000_000 + nanosec, trail.frame_id)
            rc.append_to_path(path, rc.root_to_odometry(p[:3], p[3:], header), len(trail))
        if not stamps:
            path.poses = []
        return serialize(path)

    def tf_built(stamp, parents, children, transforms) -> bytes:
        from tf2_msgs.msg import TFMessage
        return serialize(TFMessage(transforms=[
            rc.transform_stamped(Header(stamp=stamp, frame_id=p), c, t[3:], t[:3])
            for p, c, t in zip(parents, children, transforms)]))

    module = sys.modules[__name__]
    saved = {name: getattr(module, name) for name in _ENCODERS + ('tf_message',)}
    saved_path = PathTrail.message
    try:
        for name in _ENCODERS:
            setattr(module, name, built(getattr(rc, name)))
        module.tf_message = tf_built
        PathTrail.message = path_message
        yield
    finally:
        for name, fn in saved.items():
            setattr(module, name, fn)
        PathTrail.message = saved_path
