"""The floor-frame boundary (camera frame -> floor frame)."""

import numpy as np
import pytest

from mocap_core.pose import Pose
from mocap_core.skeleton import Skeleton
from mocap_physics.floor import FloorFrame


def test_camera_height_pitch():
    h, pitch = 1.5, np.deg2rad(20)
    ff = FloorFrame.from_camera_height_pitch(h, pitch)
    # the camera centre is h above the floor origin
    np.testing.assert_allclose(ff.transform_points(np.zeros(3)), [0, 0, h])
    # the optical axis points forward and down by the pitch
    d = ff.rotation @ np.array([0, 0, 1.0])
    assert np.degrees(np.arctan2(-d[2], d[0])) == pytest.approx(20)
    # image "down" (optical +y) has a downward floor component, image right is floor -y
    assert (ff.rotation @ [0, 1.0, 0])[2] < 0
    np.testing.assert_allclose(ff.rotation @ [1.0, 0, 0], [0, -1, 0], atol=1e-12)
    # a point on the optical axis at the distance where it meets the floor lies on it
    dist = h / np.sin(pitch)
    assert ff.transform_points([0, 0, dist])[2] == pytest.approx(0.0, abs=1e-9)


def test_pose_round_trip():
    sk = Skeleton.default()
    ff = FloorFrame.from_camera_height_pitch(1.2, 0.3)
    pose = Pose.rest(sk, np.array([0.2, 0.1, 3.0]))
    floor_pose = ff.transform_pose(pose)
    np.testing.assert_allclose(floor_pose.joint_positions(),
                               ff.transform_points(pose.joint_positions()), atol=1e-12)
    back = ff.inverse().transform_pose(floor_pose)
    np.testing.assert_allclose(back.joint_positions(), pose.joint_positions(), atol=1e-12)


def test_bad_rotation_rejected():
    with pytest.raises(ValueError):
        FloorFrame(np.diag([1.0, 1.0, -1.0]))
