"""The pose error measures of ``mocap_core.pose_metrics`` on poses with a known error."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from mocap_core.pose_metrics import (alignment_angle_deg, procrustes_align, rotate_about_root,
                                     twist_angle_deg)


def _poses(n=5, joints=18, seed=0):
    return np.random.default_rng(seed).normal(scale=0.3, size=(n, joints, 3))


def test_a_rotated_scaled_shifted_pose_is_aligned_exactly_with_scale_and_not_without():
    g = _poses()
    R = Rotation.from_rotvec([0.0, 0.4, 0.1]).as_matrix()
    p = 0.8 * g @ R.T + np.array([0.1, -0.2, 3.0])
    assert np.abs(procrustes_align(p, g) - g).max() < 1e-9
    rigid = procrustes_align(p, g, scale=False)
    # the rotation and translation are removed, the scale error is left: the aligned pose
    # is the truth shrunk by 0.8 about its centroid
    c = g.mean(axis=1, keepdims=True)
    assert np.abs(rigid - (c + 0.8 * (g - c))).max() < 1e-9


def test_the_orientation_error_is_the_angle_of_the_rotation_between_the_poses():
    g = _poses(n=4)
    angles = np.array([0.0, 5.0, 30.0, 120.0])
    axes = np.array([[0, 1, 0], [1, 0, 0], [0.6, 0.8, 0], [0, 0, 1]], float)
    p = np.stack([gi @ Rotation.from_rotvec(np.radians(a) * ax).as_matrix().T
                  for gi, a, ax in zip(g, angles, axes)]) * 1.1 + 0.5
    assert np.allclose(alignment_angle_deg(p, g), angles, atol=1e-4)   # arccos near 1: ~1e-6 deg
    # noise on the joints gives a small angle, not zero
    noisy = g + np.random.default_rng(1).normal(scale=0.02, size=g.shape)
    got = alignment_angle_deg(noisy, g)
    assert np.all(got > 0.01) and np.all(got < 10.0), got


def test_the_twist_about_an_axis_is_the_tilt_alone():
    """A pose tilted about the camera's x axis by known angles, then turned about y: the
    twist about x gives back the tilt with the sign of the correcting rotation, the twist
    about z stays small, and rotating about the root by the median tilt undoes it."""
    g = _poses(n=5)
    tilt = np.array([-7.0, 3.0, 10.0, 0.0, -30.0])
    p = rotate_about_root(g, (1, 0, 0), -tilt)
    np.testing.assert_allclose(twist_angle_deg(p, g, (1, 0, 0)), tilt, atol=1e-6)
    np.testing.assert_allclose(twist_angle_deg(p, g, (0, 0, 1)), 0.0, atol=1e-6)
    # a turn about y on top (a yaw error) leaves the x twist close to the tilt
    turned = rotate_about_root(p, (0, 1, 0), 8.0)
    assert np.abs(twist_angle_deg(turned, g, (1, 0, 0)) - tilt).max() < 1.5
    np.testing.assert_allclose(rotate_about_root(p, (1, 0, 0), tilt), g, atol=1e-9)
    # the root stays where it was
    np.testing.assert_allclose(rotate_about_root(g, (0, 1, 0), 40.0)[:, 0], g[:, 0])
