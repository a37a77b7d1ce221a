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
