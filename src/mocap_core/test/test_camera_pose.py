"""Known camera poses by stamp (mocap_core.camera_pose): interpolation, age limit, restarts,
conventions and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from mocap_core.camera_pose import BODY_TO_OPTICAL, KnownCameraPoses, known_camera_poses
from mocap_core.rotations import axis_angle_to_matrix, matrix_to_quat

MS = 1_000_000


def _q(axis_angle):
    return matrix_to_quat(axis_angle_to_matrix(np.asarray(axis_angle, dtype=float)))


def test_interpolated_between_poses_and_nearest_within_the_age_limit():
    poses = KnownCameraPoses(max_age_s=0.1)
    assert poses.at(0) is None
    assert poses.add(1000 * MS, [0.0, 0.0, 0.0], _q([0, 0, 0.0])) == 'ok'
    assert poses.add(1100 * MS, [1.0, 0.0, 0.0], _q([0, 0, 0.2])) == 'ok'
    R, t = poses.at(1050 * MS)                       # half way: position and angle halved
    np.testing.assert_allclose(t, [0.5, 0.0, 0.0])
    np.testing.assert_allclose(R, axis_angle_to_matrix(np.array([0, 0, 0.1])), atol=1e-12)
    R, t = poses.at(1180 * MS)                       # after the newest, within 0.1 s
    np.testing.assert_allclose(t, [1.0, 0.0, 0.0])
    assert poses.at(1250 * MS) is None               # too far from any pose
    # poses further apart than twice the age limit are not interpolated across
    assert poses.add(1400 * MS, [5.0, 0.0, 0.0], _q([0, 0, 0.0])) == 'ok'
    assert poses.at(1250 * MS) is None
    np.testing.assert_allclose(poses.at(1320 * MS)[1], [5.0, 0.0, 0.0])


def test_old_invalid_and_restarted_poses():
    poses = KnownCameraPoses()
    assert poses.add(5000 * MS, [0.0, 0.0, 1.0], _q([0, 0, 0.0])) == 'ok'
    assert poses.add(6000 * MS, [0.0, 0.0, 2.0], _q([0, 0, 0.0])) == 'ok'
    assert poses.add(5500 * MS, [9.0, 9.0, 9.0], _q([0, 0, 0.0])) == 'old'   # within 1 s
    assert poses.add(6100 * MS, [np.nan, 0, 0], _q([0, 0, 0.0])) == 'invalid'
    assert poses.add(6100 * MS, [0, 0, 0], [0.0, 0.0, 0.0, 0.0]) == 'invalid'
    assert len(poses) == 2
    assert poses.add(1000 * MS, [0.0, 0.0, 3.0], _q([0, 0, 0.0])) == 'restart'  # a bag again
    assert len(poses) == 1
    np.testing.assert_allclose(poses.at(1000 * MS)[1], [0.0, 0.0, 3.0])


def test_a_body_frame_pose_gives_the_optical_frame():
    body = KnownCameraPoses(convention='body')
    R_wb = axis_angle_to_matrix(np.array([0.0, 0.0, 0.7]))
    body.add(0, [1.0, 2.0, 1.5], matrix_to_quat(R_wb))
    R, _ = body.at(0)
    np.testing.assert_allclose(R, R_wb @ BODY_TO_OPTICAL, atol=1e-12)
    # the optical axis (z) looks along the body's x (forward), y (down) along -z
    np.testing.assert_allclose(R[:, 2], R_wb[:, 0], atol=1e-12)
    np.testing.assert_allclose(R[:, 1], [0.0, 0.0, -1.0], atol=1e-12)
    with pytest.raises(ValueError, match='optical or body'):
        KnownCameraPoses(convention='link')


def test_the_store_from_a_nodes_parameters():
    """known_camera_poses: the nodes' camera_pose_* parameters give the store (its age limit
    and convention); a message type or convention no node knows is refused."""
    p = {'camera_pose_type': 'pose', 'camera_pose_convention': 'body',
         'camera_pose_max_age_s': 0.05}
    store = known_camera_poses(p, max_frames=7)
    assert store.convention == 'body' and store.max_age_ns == 0.05e9
    assert store.poses.maxlen == 7
    with pytest.raises(ValueError, match='camera_pose_type'):
        known_camera_poses({**p, 'camera_pose_type': 'tf'})
    with pytest.raises(ValueError, match='convention'):
        known_camera_poses({**p, 'camera_pose_convention': 'camera'})
