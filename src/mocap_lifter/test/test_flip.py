"""Test-time flip augmentation of the online lifter: equivariant by construction, and the
mirror helpers are exact inverses."""

from __future__ import annotations

import numpy as np
import pytest

from mocap_core.camera import CameraIntrinsics
from mocap_core.rotations import quat_to_matrix
from mocap_core.skeleton import KEYPOINT_MIRROR
from mocap_lifter.features import (average_quaternions, lifter_features, mirror_features,
                                   unmirror_rotations)
from mocap_lifter.online import OnlineLifter
from mocap_lifter.weights import default_weights, load_weights


def _keypoints(n=40, seed=0):
    rng = np.random.default_rng(seed)
    base = rng.uniform(250, 390, (23, 2))
    t = np.arange(n)[:, None, None]
    kp = np.concatenate([base[None] + 5 * np.sin(0.2 * t + rng.uniform(0, 6, (23, 1))),
                         np.full((n, 23, 1), 0.9)], axis=-1)
    return kp


def test_mirror_helpers_are_involutions():
    intr = CameraIntrinsics(640, 480, 500.0, 500.0, 320.0, 240.0)
    feats, root, _, _ = lifter_features(_keypoints(), intr)
    f2, r2 = mirror_features(*mirror_features(feats, root))
    np.testing.assert_allclose(f2, feats)
    np.testing.assert_allclose(r2, root)
    # mirroring the pixels about the principal point gives the mirrored features
    kp = _keypoints()
    mk = kp[:, list(KEYPOINT_MIRROR)].copy()
    mk[..., 0] = 2 * 320.0 - mk[..., 0]
    fm, rm, _, _ = lifter_features(mk, intr)
    f1, r1 = mirror_features(feats, root)
    np.testing.assert_allclose(f1, fm, atol=1e-5)
    np.testing.assert_allclose(r1, rm, atol=1e-9)
    q = np.random.default_rng(1).normal(size=(5, 18, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    back = unmirror_rotations(unmirror_rotations(q))
    np.testing.assert_allclose(np.asarray(quat_to_matrix(back)), np.asarray(quat_to_matrix(q)),
                               atol=1e-9)
    avg = average_quaternions(q, -q)          # the same rotation, other hemisphere
    np.testing.assert_allclose(np.abs(np.sum(avg * q, axis=-1)), 1.0, atol=1e-9)


def test_flipped_lifting_is_mirror_equivariant():
    """With flip, lifting the mirrored image gives exactly the mirrored pose."""
    path = default_weights('windowed', 'motionet')
    if not path.exists():
        pytest.skip('no shipped weights')
    model = load_weights(path, 'cpu', causal=False)
    intr = CameraIntrinsics(640, 480, 500.0, 500.0, 320.0, 240.0)
    kp = _keypoints()
    mk = kp[:, list(KEYPOINT_MIRROR)].copy()
    mk[..., 0] = 2 * 320.0 - mk[..., 0]
    outs = []
    for seq in (kp, mk):
        lifter = OnlineLifter(model, 'windowed', chunk=8, flip=True)
        frames = []
        for i, k in enumerate(seq):
            frames += lifter.push(i * 33_333_333, k, intr)[0]
        frames += lifter.flush()
        outs.append(frames)
    assert len(outs[0]) == len(outs[1]) == len(kp)
    for a, b in zip(outs[0], outs[1]):
        np.testing.assert_allclose(a.pose.root_position * [-1, 1, 1], b.pose.root_position,
                                   atol=1e-4)
        ra = unmirror_rotations(a.pose.rotations[None])[0]
        np.testing.assert_allclose(np.asarray(quat_to_matrix(ra)),
                                   np.asarray(quat_to_matrix(b.pose.rotations)), atol=1e-4)
    # without flip the two differ (the network alone is not equivariant)
    plain = OnlineLifter(model, 'windowed', chunk=8)
    p0 = []
    for i, k in enumerate(kp):
        p0 += plain.push(i * 33_333_333, k, intr)[0]
    p0 += plain.flush()
    assert max(np.abs(x.pose.root_position - y.pose.root_position).max()
               for x, y in zip(p0, outs[0])) > 1e-4


def test_unmirrored_rotations_give_the_mirrored_skeleton():
    """FK of the unmirrored rotations is the mirror image (x -> -x, left <-> right) of the
    FK of the rotations: the helper is the reflection, not just some involution."""
    from mocap_core.kinematics import forward_kinematics
    from mocap_core.skeleton import JOINT_MIRROR, Skeleton
    rng = np.random.default_rng(2)
    q = rng.normal(size=(4, 18, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    sk = Skeleton.from_lengths_dict({})
    root = rng.normal(size=(4, 3))
    P = forward_kinematics(sk.parents, sk.offsets, q, root).positions
    Q = forward_kinematics(sk.parents, sk.offsets, unmirror_rotations(q),
                           root * [-1, 1, 1]).positions
    np.testing.assert_allclose(Q, P[:, list(JOINT_MIRROR)] * [-1, 1, 1], atol=1e-9)


def test_keypoint_smoothing_keeps_a_straight_path_and_damps_noise():
    from mocap_lifter.features import smooth_keypoints
    T = 60
    t = np.arange(T, dtype=float)
    kp = np.zeros((T, 23, 3))
    kp[..., 0] = 100 + 2.0 * t[:, None]             # constant velocity: unchanged inside
    kp[..., 1] = 200.0
    kp[..., 2] = 1.0
    kp[10, 4] = 0.0                                 # an unseen point stays unseen
    sm = smooth_keypoints(kp, 2.0)
    np.testing.assert_allclose(sm[8:-8, 5:, :2], kp[8:-8, 5:, :2], atol=1e-9)
    assert np.all(sm[10, 4] == 0.0) and np.all(sm[..., 2] == kp[..., 2])
    noisy = kp.copy()
    noisy[..., :2] += np.random.default_rng(0).normal(0, 3.0, (T, 23, 2))
    acc = lambda x: np.abs(np.diff(x[..., :2], 2, axis=0)).mean()  # noqa: E731
    assert acc(smooth_keypoints(noisy, 2.0)) < 0.2 * acc(noisy)
    np.testing.assert_array_equal(smooth_keypoints(noisy, 0.0), noisy)
