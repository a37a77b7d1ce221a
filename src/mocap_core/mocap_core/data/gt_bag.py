"""Ground-truth bags from motion capture, and keypoint bags from OpenPose JSON folders.

:func:`write_groundtruth_bag` films a processed clip (:class:`~.motion.Motion`, world frame,
floor at z = 0) with a virtual static camera (:func:`~.synth2d.sample_camera`) and writes, one
message per frame on each topic, stamped ``start_ns + round(i * 1e9 / fps)``:

=================================  ===================================  =======================
topic                              type                                 frame (``frame_id``)
=================================  ===================================  =======================
``/mocap/camera_info``             sensor_msgs/CameraInfo               camera optical frame
``/mocap/keypoints2d``             sensor_msgs/PointCloud2 (1 x 23:     camera optical frame
                                   u, v, confidence)
``/mocap/groundtruth/motion``      trajectory_msgs/                     camera optical frame
                                   MultiDOFJointTrajectory (docs/design.md §2)
``/mocap/groundtruth/joints3d``    sensor_msgs/PointCloud2 (1 x 18:     camera optical frame
                                   x, y, z, metres)
``/mocap/groundtruth/contacts``    sensor_msgs/JointState (name =       camera optical frame
                                   left_heel, left_toe, right_heel,
                                   right_toe; position = 0 or 1)
``/mocap/groundtruth/world_motion``  MultiDOFJointTrajectory            ``world`` (z up, floor
                                                                        z = 0)
``/mocap/groundtruth/camera_pose``   geometry_msgs/PoseStamped, once,   ``world``
                                     transient local: the optical
                                     frame's pose in the world
=================================  ===================================  =======================

The last two are for the physics and global stages. The world motion is redundant (it is the
camera pose composed with the camera-frame motion) and can be left out (``world_motion=False``)
to halve the size of a bag; the camera pose is always written. The
keypoints are the projection of the clip's 23 layout points (:func:`~.synth2d.keypoints_3d`),
clean (confidence 1) or corrupted like a real detector (:func:`~.synth2d.corrupt_keypoints`
with the confidence model fitted on real OpenPose output); a frame whose keypoints are all
dropped is published as one person with all confidences 0, as the keypoint node does when it
finds nobody. The camera-frame motion is :func:`~.synth2d.motion_to_camera` of the world
motion: only the root changes, so the joint rotations, bone offsets and contacts are the
same in both frames, and the FK of ``/mocap/groundtruth/motion`` is
``/mocap/groundtruth/joints3d``, whose projection is the clean keypoints.

QoS recorded in the bag (what a player offers): keypoints best effort like the keypoint node
(:data:`~mocap_core.qos.SENSOR_QOS`), the rest reliable (``STREAM_QOS``), the camera pose
transient local (``LATCHED_QOS``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Union

import numpy as np

from ..camera import CameraIntrinsics
from ..kinematics import forward_kinematics
from ..rotations import matrix_to_quat, quat_rotate
from .. import topics as T
from .motion import Motion
from .synth2d import (CameraSampling, ConfidenceModel, Corruption, VirtualCamera,
                      corrupt_keypoints, keypoints_3d, motion_to_camera, project,
                      sample_camera)

__all__ = [
    'OPTICAL_FRAME', 'WORLD_FRAME', 'DEFAULT_START_NS', 'GT_TOPICS', 'BagSummary',
    'crop_motion', 'facing_direction', 'read_groundtruth_bag', 'write_groundtruth_bag',
    'write_openpose_bag',
]

#: frame_id of the camera topics (the keypoint node's default ``frame_id`` parameter).
OPTICAL_FRAME = 'camera_optical_frame'
WORLD_FRAME = 'world'
#: Stamp of the first frame: 2023-11-14 22:13:20 UTC (fixed, so bags are reproducible).
DEFAULT_START_NS = 1_700_000_000 * 1_000_000_000

GT_TOPICS: Dict[str, str] = {
    'camera_info': T.CAMERA_INFO,
    'keypoints': T.KEYPOINTS,
    'motion': T.GROUNDTRUTH_MOTION,
    'joints3d': T.GROUNDTRUTH_JOINTS3D,
    'contacts': T.GROUNDTRUTH_CONTACTS,
    'world_motion': T.GROUNDTRUTH_WORLD_MOTION,
    'camera_pose': T.GROUNDTRUTH_CAMERA_POSE,
}


@dataclass
class BagSummary:
    """What a bag writer wrote."""

    path: Path
    frames: int
    fps: float
    start_ns: int
    topics: List[str]
    intrinsics: CameraIntrinsics
    camera: Optional[VirtualCamera] = None
    clean: bool = True
    skipped: List[str] = field(default_factory=list)

    @property
    def size_bytes(self) -> int:
        p = Path(self.path)
        if p.is_file():
            return p.stat().st_size
        return sum(f.stat().st_size for f in p.rglob('*') if f.is_file())


def stamps_ns(frames: int, fps: float, start_ns: int = DEFAULT_START_NS) -> np.ndarray:
    """(frames,) int64 stamps ``start_ns + round(i * 1e9 / fps)``."""
    return start_ns + np.round(np.arange(frames) * (1e9 / fps)).astype(np.int64)


def read_groundtruth_bag(path: Union[str, os.PathLike]) -> Dict[str, Any]:
    """Read a ground-truth bag (:func:`write_groundtruth_bag`, or a rendered clip's
    ``gt_bag``).

    Returns:
        ``stamps`` (list of int ns), ``poses`` (list of :class:`~mocap_core.pose.Pose` of
        ``/mocap/groundtruth/motion``, root in the camera's optical frame, m), ``camera``
        ((R_c (3, 3), t_c (3,)) the camera pose in the z-up world, ``x_world = R_c x_camera +
        t_c``; the static camera of :func:`write_groundtruth_bag`; a rendered clip's bag has
        one per frame, and this is the last), ``keypoints`` ((F, 23, 3) u, v in pixels and
        confidence of the cloud's first person, or None) and ``intrinsics`` (the last camera
        info, or None).

    Raises:
        ValueError: the bag has no camera pose or no ground-truth motion.
    """
    from ..bag_io import BagReader, deserialize
    from ..ros_conversions import (camera_info_to_intrinsics, cloud_to_keypoints,
                                   motion_to_pose, stamp_to_ns)
    from ..rotations import quat_to_matrix

    stamps, poses, cam, keypoints, intr = [], [], None, [], None
    with BagReader(path) as bag:
        for msg in bag.messages(topics=[T.GROUNDTRUTH_MOTION, T.GROUNDTRUTH_CAMERA_POSE,
                                        T.KEYPOINTS, T.CAMERA_INFO]):
            d = deserialize(msg.data, msg.msgtype)
            if msg.topic == T.KEYPOINTS:
                keypoints.append(cloud_to_keypoints(d)[0])
            elif msg.topic == T.CAMERA_INFO:
                intr = camera_info_to_intrinsics(d)
            elif msg.topic == T.GROUNDTRUTH_CAMERA_POSE:
                q = d.pose.orientation
                p = d.pose.position
                cam = (quat_to_matrix(np.array([q.x, q.y, q.z, q.w])),
                       np.array([p.x, p.y, p.z]))
            else:
                stamps.append(stamp_to_ns(d.header.stamp))
                poses.append(motion_to_pose(d))
    if cam is None or not poses:
        raise ValueError(f'{path}: no camera pose or no ground-truth motion')
    return {'stamps': stamps, 'poses': poses, 'camera': cam,
            'keypoints': np.stack(keypoints) if keypoints else None, 'intrinsics': intr}


def crop_motion(motion: Motion, start: int = 0, frames: Optional[int] = None) -> Motion:
    """Frames ``start : start + frames`` of a motion (all after ``start`` when None)."""
    n = motion.num_frames
    if not 0 <= start < n:
        raise ValueError(f'{motion.name}: start frame {start} outside the clip ({n} frames)')
    end = n if frames is None else start + int(frames)
    if frames is not None and frames <= 0:
        raise ValueError(f'frame count must be positive, got {frames}')
    end = min(end, n)
    return Motion(motion.name, motion.fps, motion.skeleton, motion.rotations[start:end],
                  motion.root_positions[start:end], motion.contacts[start:end])


def facing_direction(motion: Motion) -> np.ndarray:
    """(2,) mean horizontal forward direction of the pelvis over the clip (world xy)."""
    fwd = quat_rotate(np.asarray(motion.rotations[:, 0], dtype=np.float64),
                      np.array([1.0, 0.0, 0.0]))
    v = fwd[:, :2].mean(axis=0)
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-6 else np.array([1.0, 0.0])


def _qos():
    from ..qos import LATCHED_QOS, SENSOR_QOS, STREAM_QOS
    return SENSOR_QOS, STREAM_QOS, LATCHED_QOS


def write_groundtruth_bag(motion: Motion, out: Union[str, os.PathLike],
                          camera: Union[None, CameraSampling, VirtualCamera] = None,
                          corruption: Optional[Corruption] = None, seed: int = 0, *,
                          confidence_model: Optional[ConfidenceModel] = None,
                          world_motion: bool = True, start_ns: int = DEFAULT_START_NS,
                          frame_id: str = OPTICAL_FRAME, overwrite: bool = False
                          ) -> BagSummary:
    """Write a ground-truth bag of ``motion`` (module docstring).

    Args:
        motion: processed clip (world frame, floor at z = 0), e.g. from
            :func:`~.dataset.load_dataset` or :func:`~.dataset.process_clip`.
        out: bag folder to create.
        camera: a fixed :class:`~.synth2d.VirtualCamera`, or the ranges to draw one from
            (default :class:`~.synth2d.CameraSampling()`); the draw keeps every keypoint of
            the clip in view.
        corruption: detector-like corruption of the keypoints (None = clean, confidence 1).
        seed: seeds the camera draw and the corruption (same seed, same bag).
        confidence_model: for the corruption (default: the shipped model fitted on real
            OpenPose detections).
        world_motion: also write the world-frame motion (the camera pose is always
            written).
        start_ns: stamp of the first frame.
        frame_id: optical frame id of the camera topics.
        overwrite: replace an existing bag at ``out``.
    """
    from geometry_msgs.msg import Point, Pose as PoseMsg, PoseStamped, Quaternion

    from ..bag_io import BagWriter
    from ..pose import Pose
    from ..ros_conversions import (contacts_to_msg, intrinsics_to_camera_info,
                                   keypoints_to_cloud, make_header, pose_to_motion,
                                   positions_to_cloud)

    if motion.num_frames == 0:
        raise ValueError(f'{motion.name}: no frames to write')
    if not motion.fps > 0:
        raise ValueError(f'{motion.name}: frame rate must be positive, got {motion.fps}')
    rng = np.random.default_rng(seed)
    sk = motion.skeleton
    rot = np.asarray(motion.rotations, dtype=np.float64)
    root = np.asarray(motion.root_positions, dtype=np.float64)
    kp3d = keypoints_3d(sk, rot, root)
    if isinstance(camera, VirtualCamera):
        cam = camera
    else:
        cam = sample_camera(kp3d, rng, camera if camera is not None else CameraSampling(),
                            facing=facing_direction(motion))
    keypoints = project(cam, kp3d)
    clean = corruption is None
    if not clean:
        keypoints = corrupt_keypoints(keypoints, rng, confidence_model
                                      or ConfidenceModel.default(), corruption)
    rot_c, root_c = motion_to_camera(rot, root, cam)
    joints_c = cam.world_to_camera(
        forward_kinematics(sk.parents, sk.offsets, rot, root).positions)
    stamps = stamps_ns(motion.num_frames, motion.fps, start_ns)
    sensor_qos, stream_qos, latched_qos = _qos()
    T = GT_TOPICS
    with BagWriter(out, overwrite=overwrite) as bag:
        # the optical frame's pose in the world: camera -> world = transpose of world -> camera
        q = matrix_to_quat(np.asarray(cam.rotation).T)
        p = np.asarray(cam.position, dtype=np.float64)
        msg = PoseStamped(header=make_header(int(stamps[0]), WORLD_FRAME),
                          pose=PoseMsg(position=Point(x=float(p[0]), y=float(p[1]),
                                                      z=float(p[2])),
                                       orientation=Quaternion(x=float(q[0]), y=float(q[1]),
                                                              z=float(q[2]), w=float(q[3]))))
        bag.write_msg(T['camera_pose'], int(stamps[0]), msg, qos=latched_qos)
        for i, stamp in enumerate(stamps.tolist()):
            h = make_header(stamp, frame_id)
            bag.write_msg(T['camera_info'], stamp, intrinsics_to_camera_info(cam.intrinsics, h),
                          qos=stream_qos)
            bag.write_msg(T['keypoints'], stamp, keypoints_to_cloud(keypoints[i], h),
                          qos=sensor_qos)
            bag.write_msg(T['motion'], stamp, pose_to_motion(Pose(sk, rot_c[i], root_c[i]), h),
                          qos=stream_qos)
            bag.write_msg(T['joints3d'], stamp, positions_to_cloud(joints_c[i], h),
                          qos=stream_qos)
            bag.write_msg(T['contacts'], stamp,
                          contacts_to_msg(motion.contacts[i].astype(np.float64), h),
                          qos=stream_qos)
            if world_motion:
                hw = make_header(stamp, WORLD_FRAME)
                bag.write_msg(T['world_motion'], stamp,
                              pose_to_motion(Pose(sk, rot[i], root[i]), hw), qos=stream_qos)
        topics = sorted(bag.topics)
    return BagSummary(Path(out), motion.num_frames, float(motion.fps), int(start_ns), topics,
                      cam.intrinsics, cam, clean)


def write_openpose_bag(directory: Union[str, os.PathLike], out: Union[str, os.PathLike],
                       fps: float = 30.0, intrinsics: Optional[CameraIntrinsics] = None,
                       fov: float = 60.0, *, start_ns: int = DEFAULT_START_NS,
                       frame_id: str = OPTICAL_FRAME, overwrite: bool = False) -> BagSummary:
    """Write an OpenPose BODY_25 (or COCO-18) JSON folder as ``/mocap/keypoints2d`` (every
    detected person, mapped to the 23-point layout) and ``/mocap/camera_info``.

    Frame ``k`` (the number in the file name) is stamped ``start_ns + (k - k0) / fps``, so
    gaps in the numbering stay gaps in time. A frame with nobody detected is one person with
    all confidences 0 (as the keypoint node publishes it); an unreadable file is skipped and
    named in :attr:`BagSummary.skipped`. ``intrinsics`` default: the horizontal field of view
    ``fov`` (degrees) over the smallest standard image size that contains the keypoints
    (OpenPose JSON does not record it).
    """
    from mocap_core.data.openpose import (OpenPoseError, infer_image_size,
                                          list_openpose_files, read_openpose_file)

    from ..bag_io import BagWriter
    from ..ros_conversions import intrinsics_to_camera_info, keypoints_to_cloud, make_header

    if not fps > 0:
        raise ValueError(f'frame rate must be positive, got {fps}')
    files = list_openpose_files(directory)
    if intrinsics is None:
        w, h = infer_image_size(files)
        intrinsics = CameraIntrinsics.from_fov(w, h, fov)
    sensor_qos, stream_qos, _ = _qos()
    k0 = files[0][0]
    skipped: List[str] = []
    frames = []
    for k, path in files:
        try:
            kp = read_openpose_file(path)
        except OpenPoseError as exc:
            skipped.append(str(exc))
            continue
        if len(kp) == 0:
            kp = np.zeros((1,) + kp.shape[1:])
        frames.append((start_ns + int(round((k - k0) * 1e9 / fps)), kp))
    if not frames:
        raise ValueError(f'{directory}: no readable OpenPose file ({skipped[0]})')
    with BagWriter(out, overwrite=overwrite) as bag:
        for stamp, kp in frames:
            hdr = make_header(stamp, frame_id)
            bag.write_msg(GT_TOPICS['camera_info'], stamp,
                          intrinsics_to_camera_info(intrinsics, hdr), qos=stream_qos)
            bag.write_msg(GT_TOPICS['keypoints'], stamp, keypoints_to_cloud(kp, hdr),
                          qos=sensor_qos)
        topics = sorted(bag.topics)
    return BagSummary(Path(out), len(frames), float(fps), int(start_ns), topics, intrinsics,
                      None, True, skipped)
