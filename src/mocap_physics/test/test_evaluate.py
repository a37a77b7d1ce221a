"""Evaluation helpers and ``mocap eval physics`` on a committed ground-truth bag."""

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mocap_physics.cycle_params import PhysicsParams
from mocap_physics.training.evaluate import (evaluate_clip, lifter_noise, load_gt_bag,
                                             motion_metrics, procrustes, summarize)

BAGS = Path(__file__).resolve().parents[3] / 'bags'


@pytest.fixture(scope='module')
def clip():
    c = load_gt_bag(BAGS / 'gt_bandai_walk_exhausted')
    n = 75
    return replace(c, stamps=c.stamps[:n], rotations=c.rotations[:n],
                   root_positions=c.root_positions[:n], contacts=c.contacts[:n],
                   labels=c.labels[:n], gt_rotations=c.gt_rotations[:n],
                   gt_root_positions=c.gt_root_positions[:n])


def test_procrustes_removes_similarity():
    rng = np.random.default_rng(0)
    gt = rng.normal(size=(5, 18, 3))
    a = 0.4
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    pred = 1.3 * gt @ R.T + np.array([1.0, -2.0, 0.5])
    np.testing.assert_allclose(procrustes(pred, gt), gt, atol=1e-9)


def test_groundtruth_bag_and_noise(clip):
    assert clip.source_frame == 'camera' and clip.fps == pytest.approx(30.0)
    # the camera pose puts the ground-truth feet on the world floor (z = 0, 5 mm)
    in_world = clip.to_world.transform_pose(clip.pose(0))
    assert min(p[2] for p in in_world.contact_positions().values()) > -0.005
    a, b = lifter_noise(clip, 3), lifter_noise(clip, 3)
    np.testing.assert_array_equal(a.rotations, b.rotations)
    assert not np.allclose(a.root_positions, clip.root_positions)
    np.testing.assert_array_equal(a.gt_root_positions, clip.gt_root_positions)
    assert np.all((a.contacts >= 0) & (a.contacts <= 1))


def test_metrics_of_ground_truth_are_zero_errors(clip):
    from mocap_physics.training.evaluate import _world
    from mocap_core.kinematics import forward_kinematics
    rot, root = _world(clip, clip.rotations, clip.root_positions)
    joints = forward_kinematics(clip.skeleton.parents, clip.skeleton.offsets, rot,
                                root).positions
    m = motion_metrics(clip.skeleton, rot, root, joints, clip.labels, clip.fps)
    assert m['pa_mpjpe_mm'] < 1e-6 and m['accel_error'] < 1e-9 and m['e_smooth_mm'] < 1e-9


def test_evaluate_clip_clean_and_noisy(clip):
    rows = [evaluate_clip(clip, PhysicsParams(), 'gt'),
            evaluate_clip(lifter_noise(clip, 1), PhysicsParams(), 'estimate')]
    for r in rows:
        o, p = r['output'], r['physics']
        assert p['cone_violations'] == 0 and p['fallbacks'] == 0
        assert p['penetration_own_floor_max_mm'] < 1.0
        assert all(np.isfinite(v) for v in o.values())
    clean, noisy = rows
    assert clean['output']['penetration_max_mm'] < 1.0           # the true floor
    assert clean['output']['pa_mpjpe_mm'] < 15.0
    # lifter noise: the physics smooths it
    assert noisy['output']['jitter'] < noisy['input']['jitter']
    assert noisy['output']['accel_error'] < noisy['input']['accel_error']
    assert noisy['output']['skating_mean_mm'] < noisy['input']['skating_mean_mm']
    assert np.isfinite(noisy['physics']['floor_error_deg'])
    s = summarize(rows[:1])
    assert s['goals']['no_cone_violation'] and s['frames'] == clip.num_frames


def test_mocap_eval_physics_cli(tmp_path):
    out = tmp_path / 'report'
    res = subprocess.run([sys.executable, '-m', 'mocap_physics.training.cli', 'eval',
                          'physics',
                          '--bags', str(BAGS / 'gt_cmu_walk_12_02'), '--dataset-clips', '0',
                          '--family-clips', '0',
                          '--noise', 'none', '--quick', '--out', str(out)],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    data = json.loads(out.with_suffix('.json').read_text())
    assert {r['config'] for r in data['results']} == {'physics, true floor',
                                                       'physics, est. floor',
                                                       'paper (eq. 13), true floor'}
    md = out.with_suffix('.md').read_text()
    assert 'friction-cone violations' in md and 'PA-MPJPE' in md
