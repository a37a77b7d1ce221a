"""Reading the committed ground-truth bags for the benchmark and the evaluation (no ROS node;
the bag is read with :mod:`mocap_core.bag_io`).

A ground-truth bag (``bags/gt_*``, written by ``mocap data``) holds per frame the motion in
the camera's optical frame (``/mocap/groundtruth/motion``), the static camera's pose in the
world (``/mocap/groundtruth/camera_pose``: ``x_world = R_c x_camera + t_c``), the 2D keypoints
and the camera intrinsics.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Dict, Union

import numpy as np

from mocap_core import topics
from mocap_core.rotations import quat_to_matrix


def read_groundtruth_bag(path: Union[str, Path]) -> Dict[str, Any]:
    """Read a ground-truth bag.

    Returns:
        ``stamps`` (list of int ns), ``poses`` (list of :class:`~mocap_core.pose.Pose`, root in
        the camera frame, m), ``camera`` ((R_c (3, 3), t_c (3,)) the camera pose in the z-up
        world), ``keypoints`` ((F, K, 3) u, v, confidence, or None) and ``intrinsics`` (the
        last camera info, or None).

    Raises:
        ValueError: the bag has no camera pose or no ground-truth motion.
    """
    from mocap_core.bag_io import BagReader, deserialize
    from mocap_core.ros_conversions import (camera_info_to_intrinsics, cloud_to_keypoints,
                                            motion_to_pose, stamp_to_ns)

    stamps, poses, cam, keypoints, intr = [], [], None, [], None
    with BagReader(path) as bag:
        for msg in bag.messages(topics=[topics.GROUNDTRUTH_MOTION,
                                        topics.GROUNDTRUTH_CAMERA_POSE,
                                        topics.KEYPOINTS, topics.CAMERA_INFO]):
            d = deserialize(msg.data, msg.msgtype)
            if msg.topic == topics.KEYPOINTS:
                keypoints.append(cloud_to_keypoints(d)[0])
            elif msg.topic == topics.CAMERA_INFO:
                intr = camera_info_to_intrinsics(d)
            elif msg.topic == topics.GROUNDTRUTH_CAMERA_POSE:
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
