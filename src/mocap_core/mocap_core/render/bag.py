"""A rendered clip as a ground-truth MCAP bag (the topics of ``data/gt_bag.py``).

One message per frame on ``/mocap/camera_info``, ``/mocap/keypoints2d`` (the detector's
keypoints, as the keypoint node publishes them), ``/mocap/groundtruth/joints3d`` (the rendered
body's joints, camera optical frame), ``/mocap/groundtruth/motion`` (the driving rotations on
the body's bone lengths, camera frame), ``/mocap/groundtruth/contacts``,
``/mocap/groundtruth/world_motion`` (world, z up, floor z = 0) and
``/mocap/groundtruth/camera_pose`` (the optical frame's pose in the world: per frame, since the
camera may move). Stamps: ``DEFAULT_START_NS + round(i * 1e9 / fps)``.

The motion messages carry the pipeline skeleton (straight trunk, fixed rest directions), so
their forward kinematics differs from the exact joints on the trunk by a few centimetres;
``joints3d`` is the exact ground truth.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional, Sequence, Union

import numpy as np

from ..rotations import matrix_to_quat, quat_multiply


def write_rendered_bag(clip_dir: Union[str, Path], out: Union[str, Path],
                       overwrite: bool = True,
                       camera_motion: Optional[Sequence[tuple]] = None) -> Path:
    """Write the bag of the rendered clip in ``clip_dir`` (its ``data.npz``) to ``out``.

    ``camera_motion``: per frame (state, orientation x y z w, angular velocity rad/s[,
    position (3,) m or None, linear velocity (3,) m/s]), the camera-motion estimate from the
    video, written as ``/mocap/camera/motion`` like the keypoint node publishes it."""
    from geometry_msgs.msg import Point, Pose as PoseMsg, PoseStamped, Quaternion

    from ..bag_io import BagWriter
    from ..camera import CameraIntrinsics
    from ..data.gt_bag import DEFAULT_START_NS, GT_TOPICS, OPTICAL_FRAME, WORLD_FRAME, _qos
    from ..pose import Pose
    from ..ros_conversions import (camera_motion_to_odometry, contacts_to_msg,
                                   intrinsics_to_camera_info,
                                   keypoints_to_cloud, make_header, pose_to_motion,
                                   positions_to_cloud)
    from ..skeleton import Skeleton
    from ..topics import CAMERA_MOTION

    with np.load(Path(clip_dir) / 'data.npz') as z:
        d = {k: z[k] for k in z.files}
    F = len(d['keypoints'])
    fps = float(d['fps'])
    K = d['K']
    w, h = (int(x) for x in d['image_size'])
    intr = CameraIntrinsics(w, h, float(K[0, 0]), float(K[1, 1]), float(K[0, 2]),
                            float(K[1, 2]), approximate=False)
    sk = Skeleton.from_group_lengths(d['bone_lengths'])
    R, C = d['camera_R'], d['camera_position']
    q_wc = matrix_to_quat(R)  # world -> camera
    sensor_qos, stream_qos, latched_qos = _qos()
    T = GT_TOPICS
    with BagWriter(out, overwrite=overwrite) as bag:
        for i in range(F):
            stamp = DEFAULT_START_NS + int(round(i * 1e9 / fps))
            hc = make_header(stamp, OPTICAL_FRAME)
            hw = make_header(stamp, WORLD_FRAME)
            q = matrix_to_quat(R[i].T)
            p = C[i]
            bag.write_msg(T['camera_pose'], stamp, PoseStamped(
                header=hw, pose=PoseMsg(
                    position=Point(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                    orientation=Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]),
                                           w=float(q[3])))), qos=latched_qos)
            bag.write_msg(T['camera_info'], stamp, intrinsics_to_camera_info(intr, hc),
                          qos=stream_qos)
            bag.write_msg(T['keypoints'], stamp, keypoints_to_cloud(d['keypoints'][i], hc),
                          qos=sensor_qos)
            if camera_motion is not None and i < len(camera_motion):
                state, q_cm, w_cm, *tr = camera_motion[i]
                bag.write_msg(CAMERA_MOTION, stamp, camera_motion_to_odometry(
                    state, q_cm, w_cm, make_header(stamp, OPTICAL_FRAME + '_start'),
                    OPTICAL_FRAME, *tr), qos=stream_qos)
            rot_w = d['rotations'][i]
            root_w = d['root_positions'][i]
            rot_c = rot_w.copy()
            rot_c[0] = quat_multiply(q_wc[i], rot_w[0])
            root_c = R[i] @ (root_w - p)
            bag.write_msg(T['motion'], stamp, pose_to_motion(Pose(sk, rot_c, root_c), hc),
                          qos=stream_qos)
            bag.write_msg(T['joints3d'], stamp, positions_to_cloud(d['joints_camera'][i], hc),
                          qos=stream_qos)
            bag.write_msg(T['contacts'], stamp,
                          contacts_to_msg(d['contacts'][i].astype(np.float64), hc),
                          qos=stream_qos)
            bag.write_msg(T['world_motion'], stamp, pose_to_motion(Pose(sk, rot_w, root_w), hw),
                          qos=stream_qos)
    return Path(out)
