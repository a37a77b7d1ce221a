"""The lifter's virtual camera (``virtual_camera``): a person seen away from the image centre
is lifted as a camera turned to look at them would see them, and the pose turned back."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest

from mocap_core.camera import CameraIntrinsics
from mocap_core.rotations import axis_angle_to_quat, matrix_to_quat, quat_to_matrix
from mocap_core.skeleton import KEYPOINT_INDEX
from mocap_lifter.features import (lifter_features, ray_rotations, to_virtual_camera,
                                   virtual_camera_window)
from mocap_lifter.online import OnlineLifter
from mocap_lifter.weights import default_weights, load_weights

INTR = CameraIntrinsics(640, 480, 450.0, 450.0, 320.0, 240.0)
_LHIP, _RHIP = KEYPOINT_INDEX['left_hip'], KEYPOINT_INDEX['right_hip']


def _body(hips=(1.0, 0.0), n=50, seed=0):
    """(n, 23, 3) points of a person-sized cloud, camera optical frame, mid-hip at the origin
    and still (the root keypoint does not move), the other points swinging; the hips 0.2 m
    apart along the image direction ``hips``."""
    rng = np.random.default_rng(seed)
    base = rng.uniform([-0.25, -0.9, -0.15], [0.25, 0.8, 0.15], (23, 3))
    h = np.array([hips[0], hips[1], 0.0]) / np.hypot(*hips)
    base[_LHIP], base[_RHIP] = 0.1 * h, -0.1 * h
    t = np.arange(n)[:, None, None]
    pts = base[None] + 0.05 * np.sin(0.2 * t + rng.uniform(0, 6, (23, 1)))
    pts[:, [_LHIP, _RHIP]] = base[[_LHIP, _RHIP]]
    return pts


def _pixels(points):
    """(n, 23, 3) camera-frame points -> (n, 23, 3) pixels and confidence 1."""
    uv = points[..., :2] / points[..., 2:3] * [INTR.fx, INTR.fy] + [INTR.cx, INTR.cy]
    return np.concatenate([uv, np.ones(points.shape[:-1] + (1,))], axis=-1)


def _scene(ray_xy, hips_on_axis=False):
    """The body on the optical axis 4 m away, and the same body turned about the camera's
    centre so that its root lies on the canonical ray ``ray_xy``; and that turn.
    ``hips_on_axis``: the hips lie along the turn's axis, so that the mid-point of their
    images is exactly the image of the mid-hip in both scenes."""
    hips = (-ray_xy[1], ray_xy[0]) if hips_on_axis else (1.0, 0.0)
    on_axis = _body(hips) + [0.0, 0.0, 4.0]
    R = ray_rotations(np.asarray([ray_xy], dtype=float))[0]
    return on_axis, on_axis @ R.T, R


def test_ray_rotations_are_rotations_onto_the_ray_without_roll():
    r = np.random.default_rng(1).normal(size=(64, 2)) * 0.5
    R = ray_rotations(r)
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape),
                               atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    d = np.concatenate([r, np.ones((64, 1))], axis=1)
    np.testing.assert_allclose(R[:, :, 2], d / np.linalg.norm(d, axis=1, keepdims=True),
                               atol=1e-12)
    # the smallest turn: its axis is perpendicular to the optical axis (no roll)
    axis_z = R[:, 1, 0] - R[:, 0, 1]               # 2 sin(a) k_z of the axis-angle form
    np.testing.assert_allclose(axis_z, 0.0, atol=1e-12)
    np.testing.assert_allclose(ray_rotations(np.zeros((1, 2)))[0], np.eye(3), atol=1e-15)


@pytest.mark.parametrize('ray_xy', [(0.35, 0.0), (0.0, -0.3), (-0.25, 0.2)])
def test_the_virtual_cameras_features_do_not_depend_on_where_the_person_is(ray_xy):
    """Exactly, where the mid-point of the hips' images is the image of the mid-hip; else
    up to that difference, still 20x closer than the real camera's features."""
    on_axis, off_axis, _ = _scene(ray_xy, hips_on_axis=True)
    f_on, r_on, s_on, _ = lifter_features(_pixels(on_axis), INTR, virtual_camera=True)
    f_off, r_off, s_off, _ = lifter_features(_pixels(off_axis), INTR, virtual_camera=True)
    np.testing.assert_allclose(f_off, f_on, atol=2e-5)
    np.testing.assert_allclose(s_off, s_on, rtol=1e-6)
    on_axis, off_axis, _ = _scene(ray_xy)
    f_on = lifter_features(_pixels(on_axis), INTR, virtual_camera=True)[0]
    f_off, r_off, _, _ = lifter_features(_pixels(off_axis), INTR, virtual_camera=True)
    np.testing.assert_allclose(f_off, f_on, atol=2.5e-3)
    np.testing.assert_allclose(r_off, 0.0)
    # the real camera's features of the two differ (the oblique view's distortion)
    plain_on = lifter_features(_pixels(on_axis), INTR)[0]
    plain_off = lifter_features(_pixels(off_axis), INTR)[0]
    assert np.abs(plain_off - plain_on).max() > 0.04


def test_unseen_points_stay_unseen_in_the_virtual_camera():
    kc = np.array([[[0.3, 0.1, 0.9], [0.5, -0.2, 0.0]]])
    out = to_virtual_camera(kc, ray_rotations(np.array([[0.3, 0.1]])))
    np.testing.assert_allclose(out[0, 0], [0.0, 0.0, 0.9], atol=1e-12)
    np.testing.assert_allclose(out[0, 1], 0.0)


@pytest.mark.parametrize('chunk', [1, 8])
def test_the_lifted_pose_turns_with_the_person(chunk):
    """Lifting the turned scene gives the on-axis scene's pose turned by the same rotation:
    root position and root orientation (window pass and streaming encoder alike)."""
    path = default_weights('windowed', 'motionet')
    if not path.exists():
        pytest.skip('no shipped weights')
    model = load_weights(path, 'cpu', causal=False)
    on_axis, off_axis, R = _scene((0.3, -0.2), hips_on_axis=True)

    # the same network lifting in the real camera (weights trained in the virtual camera
    # always use it, so the plain pass needs a copy that is not marked so)
    plain_model = copy.deepcopy(model)
    plain_model.cfg = dataclasses.replace(model.cfg, virtual_camera=False)

    def lift(points, virtual):
        lifter = OnlineLifter(model if virtual else plain_model, 'windowed', chunk=chunk,
                              flip=True, virtual_camera=virtual)
        frames = []
        for i, k in enumerate(_pixels(points)):
            frames += lifter.push(i * 33_333_333, k, INTR)[0]
        return frames + lifter.flush(), lifter.streaming

    on, _ = lift(on_axis, True)
    off, streamed = lift(off_axis, True)
    assert streamed == (chunk == 1)
    assert len(on) == len(off) == len(on_axis)
    for a, b in zip(on, off):
        np.testing.assert_allclose(b.pose.root_position, R @ a.pose.root_position, atol=1e-4)
        np.testing.assert_allclose(np.asarray(quat_to_matrix(b.pose.rotations[0])),
                                   R @ np.asarray(quat_to_matrix(a.pose.rotations[0])),
                                   atol=1e-4)
        np.testing.assert_allclose(b.pose.rotations[1:], a.pose.rotations[1:], atol=1e-4)
    # the plain network does not turn its pose with the person
    plain, _ = lift(off_axis, False)
    err = max(np.abs(np.asarray(quat_to_matrix(p.pose.rotations[0]))
                     - np.asarray(quat_to_matrix(b.pose.rotations[0]))).max()
              for p, b in zip(plain, off))
    assert err > 0.02


def test_vtm_refuses_the_virtual_camera():
    from mocap_lifter.vtm import VTM, VTMConfig
    with pytest.raises(ValueError, match='virtual_camera'):
        OnlineLifter(VTM(VTMConfig()), 'windowed', virtual_camera=True)


def test_training_windows_match_the_nodes_virtual_camera():
    """A training window turned into the virtual camera has the features the node computes
    there, and targets turned with it: the off-axis scene's targets become the on-axis
    scene's (the network learns one pose for both)."""
    on_axis, off_axis, R = _scene((0.3, -0.2), hips_on_axis=True)
    feats, root_2d, scale, _ = lifter_features(_pixels(off_axis), INTR)
    rng = np.random.default_rng(3)
    q_on = np.asarray(axis_angle_to_quat(rng.normal(size=(len(on_axis), 18, 3))))
    R_q = np.asarray(quat_to_matrix(q_on[:, 0]))
    q_off = q_on.copy()
    q_off[:, 0] = matrix_to_quat(R @ R_q)
    window = {'features': feats, 'root_2d': root_2d.astype(np.float32),
              'scale': scale.astype(np.float32), 'positions': off_axis.astype(np.float32),
              'root': off_axis[:, 0].astype(np.float32), 'rotations': q_off.astype(np.float32),
              'contacts': np.zeros((len(on_axis), 4), np.float32)}
    v = virtual_camera_window(window)
    f_node, r_node, s_node, _ = lifter_features(_pixels(off_axis), INTR, virtual_camera=True)
    np.testing.assert_allclose(v['features'], f_node, atol=1e-4)
    np.testing.assert_allclose(v['scale'], s_node, rtol=1e-5)
    np.testing.assert_allclose(v['root_2d'], 0.0)
    np.testing.assert_allclose(v['positions'], on_axis, atol=1e-5)
    np.testing.assert_allclose(v['root'], on_axis[:, 0], atol=1e-5)
    np.testing.assert_allclose(np.asarray(quat_to_matrix(v['rotations'][:, 0])), R_q,
                               atol=1e-5)
    np.testing.assert_allclose(v['rotations'][:, 1:], q_off[:, 1:], atol=1e-6)
    assert v['contacts'] is window['contacts']
    # a batch axis in front gives the same
    b = virtual_camera_window({k: np.stack([w, w]) for k, w in window.items()})
    np.testing.assert_allclose(b['features'][1], v['features'], atol=1e-6)
    np.testing.assert_allclose(b['positions'][0], v['positions'], atol=1e-6)
