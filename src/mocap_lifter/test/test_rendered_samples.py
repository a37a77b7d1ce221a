"""Rendered windows (real detector on rendered people) mixed into the lifter's batches."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mocap_core.data.synth2d import look_at
from mocap_core.skeleton import NUM_KEYPOINTS
from mocap_lifter.training.samples import MixedSampler, RenderedWindowSampler, WindowSampler

REPO = Path(__file__).resolve().parents[3]


@pytest.fixture(scope='module')
def walk():
    from mocap_core.testing import groundtruth_motion
    return groundtruth_motion(REPO / 'bags' / 'gt_bandai_walk_exhausted')


def test_rendered_and_projected_windows_mix_into_one_batch(walk, tmp_path):
    """The lifter's mixed sampler: rendered windows have the projected windows' keys,
    shapes and dtypes."""
    F = 80
    d = tmp_path / 'clip'
    d.mkdir()
    fk = walk.fk()
    R = np.tile(look_at(np.array([4.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0])), (F, 1, 1))
    kp = np.zeros((F, NUM_KEYPOINTS, 3))
    kp[..., :2] = np.random.default_rng(0).uniform(200, 400, (F, NUM_KEYPOINTS, 2))
    kp[..., 2] = 0.9
    np.savez(d / 'data.npz', keypoints=kp, K=np.array([[600.0, 0, 320], [0, 600, 240],
                                                        [0, 0, 1]]),
             image_size=np.array([640, 480]), rotations=walk.rotations[:F],
             camera_R=R, joints_camera=fk.positions[:F], bone_lengths=walk.skeleton.
             group_lengths(), contacts=walk.contacts[:F])
    (d / 'meta.json').write_text(json.dumps({'clip': 'x'}))
    rendered = RenderedWindowSampler([d], window=32, seed=0)
    projected = WindowSampler([walk], window=32, seed=0)
    mixed = MixedSampler(projected, rendered, 0.5)
    b = mixed.batch(8)
    p = projected.batch(2)
    assert set(b) == set(p)
    for k in p:
        assert b[k].shape[1:] == p[k].shape[1:], k
    with pytest.raises(ValueError):
        RenderedWindowSampler([d], window=200)


def test_a_mirrored_rendered_window_is_the_mirrored_body_seen_in_the_mirrored_image(walk,
                                                                                  tmp_path):
    """Flip augmentation of rendered windows: the mirrored targets are one body (the
    mirrored rotations' FK with the same bone lengths reaches the mirrored joints), the
    left foot's contacts become the right foot's, and the features are those of the
    mirrored keypoints seen by a camera whose principal point is mirrored too."""
    from mocap_core.camera import CameraIntrinsics
    from mocap_core.kinematics import forward_kinematics
    from mocap_core.skeleton import Skeleton
    from mocap_lifter.features import lifter_features
    from mocap_lifter.training.samples import mirror_rendered_window

    F, W = 40, 640
    fk = walk.fk()
    cam_pos = np.array([3.0, -2.0, 1.4])
    R = look_at(cam_pos, np.array([0.0, 0.0, 1.0]))
    cam = np.einsum('ij,fkj->fki', R, fk.positions[:F] - cam_pos)
    K = np.array([[600.0, 0, 300], [0, 600, 250], [0, 0, 1]])
    kp = np.zeros((F, NUM_KEYPOINTS, 3))
    rng = np.random.default_rng(1)
    kp[..., :2] = rng.uniform(100, 500, (F, NUM_KEYPOINTS, 2))
    kp[..., 2] = rng.uniform(0.3, 1.0, (F, NUM_KEYPOINTS))
    d = tmp_path / 'clip'
    d.mkdir()
    contacts = np.zeros((F, 4), np.float32)
    contacts[:, 0] = 1.0                                   # left heel only
    np.savez(d / 'data.npz', keypoints=kp, K=K, image_size=np.array([W, 480]),
             rotations=walk.rotations[:F], camera_R=np.tile(R, (F, 1, 1)),
             joints_camera=cam, bone_lengths=walk.skeleton.group_lengths(), contacts=contacts)
    (d / 'meta.json').write_text(json.dumps({'clip': 'x'}))
    sampler = RenderedWindowSampler([d], window=F, seed=0)
    w = sampler.sample()
    m = mirror_rendered_window({k: v for k, v in w.items() if k != "tpose"}, W)

    skel = Skeleton.from_group_lengths(w['lengths'])

    def reach(s):
        return forward_kinematics(skel.parents, skel.offsets, s['rotations'].astype(float),
                                  s['root'].astype(float)).positions

    # the fixture is one body in the camera frame, and so is its mirror image
    assert np.abs(reach(w) - w['positions']).max() < 1e-3
    assert np.abs(reach(m) - m['positions']).max() < 1e-3
    # ... and the mirror is not the original (x reflected)
    assert np.abs(m['positions'] - w['positions']).max() > 0.1
    assert m['contacts'][:, 2].all() and not m['contacts'][:, [0, 1, 3]].any()
    mirrored_intr = CameraIntrinsics(W, 480, 600.0, 600.0, (W - 1) - 300.0, 250.0,
                                     approximate=False)
    expect, root_2d, _, _ = lifter_features(m['keypoints'].astype(float), mirrored_intr)
    assert np.allclose(m['features'], expect, atol=1e-4)
    assert np.allclose(m['root_2d'], root_2d, atol=1e-5)
    # the sampler applies it with the probability asked for
    flipping = RenderedWindowSampler([d], window=F, seed=0, flip=1.0)
    assert np.allclose(flipping.sample()['positions'], m['positions'])
