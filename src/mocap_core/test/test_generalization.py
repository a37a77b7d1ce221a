"""The strict split, the detector placement fit and the rendered-clip scores (no renderer)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocap_core.data.detector_placement import (DetectorPlacement, fit_detector_placement,
                                                leg_length)
from mocap_core.data.strict_split import family_of, strict_assignment
from mocap_core.data.synth2d import keypoints_3d, look_at
from mocap_core.render.evaluate import (aggregate, detector_swaps, foot_scores, motion_group,
                                         score_clip, skating_in_world)
from mocap_core.skeleton import JOINT_INDEX, JOINT_MIRROR, KEYPOINT_NAMES, NUM_KEYPOINTS

REPO = Path(__file__).resolve().parents[3]


@pytest.fixture(scope='module')
def walk():
    from mocap_core.testing import groundtruth_motion
    return groundtruth_motion(REPO / 'bags' / 'gt_bandai_walk_exhausted')


# ------------------------------------------------------------------------------------------
def test_strict_split_holds_out_whole_families_and_keeps_committed_validation():
    bn = 'bandai_namco_bvh/dataset-1_all.tar.xz:'
    cases = {
        bn + 'dataset-1_kick_normal_001.bvh': 'martial arts',
        bn + 'dataset-1_dance-short_normal_001.bvh': 'dance',
        bn + 'dataset-1_walk_old_002.bvh': 'style: old',
        'bandai_namco_bvh/dataset-2_run.tar.xz:dataset-2_run_exhausted_004.bvh':
            'style: exhausted',
        'cmu_bvh/daz_friendly_acrnn_salsa_indian.tar.xz:salsa/03.bvh': 'dance',
        bn + 'dataset-1_walk_happy_001.bvh': None,
        'cmu_bvh/mb2_120fps/02_01.bvh': None,
    }
    for clip, fam in cases.items():
        assert family_of(clip) == fam, clip
    ids = list(cases)
    got = strict_assignment(ids, ['train'] * (len(ids) - 1) + ['validation'])
    assert got[0] == ('strict_validation', 'martial arts')
    assert got[5] == ('strict_train', '')
    assert got[-1] == ('strict_validation', 'validation')  # committed validation stays


# ------------------------------------------------------------------------------------------
def _fake_renders(walk, placement, n_clips=6, noise_px=1.0, seed=0):
    """Arrays like ``render.clip`` writes, whose 'detections' are the placed keypoints
    projected by random static cameras around the walk, plus pixel noise."""
    rng = np.random.default_rng(seed)
    sk = walk.skeleton
    pts = keypoints_3d(sk, walk.rotations, walk.root_positions, placement=placement)
    centre = walk.root_positions.mean(axis=0)
    out = []
    for c in range(n_clips):
        az = 2 * np.pi * c / n_clips + rng.uniform(-0.3, 0.3)
        pos = centre + np.array([4 * np.cos(az), 4 * np.sin(az), 0.5])
        R = look_at(pos, centre)
        K = np.array([[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]])
        pc = (pts - pos) @ R.T
        uv = pc[..., :2] / pc[..., 2:] * 600.0 + [320, 240]
        det = np.concatenate([uv + rng.normal(0, noise_px, uv.shape),
                              np.ones(uv.shape[:-1] + (1,))], axis=-1)
        det[:, [KEYPOINT_NAMES.index('left_small_toe'),
                KEYPOINT_NAMES.index('right_small_toe')]] = 0.0  # like BlazePose
        F = len(pts)
        out.append({'bone_lengths': sk.group_lengths(), 'rotations': walk.rotations,
                    'root_positions': walk.root_positions, 'camera_R': np.tile(R, (F, 1, 1)),
                    'camera_position': np.tile(pos, (F, 1)), 'K': K, 'keypoints': det})
    return out


def test_placement_fit_recovers_known_offsets(walk):
    rng = np.random.default_rng(1)
    truth = rng.uniform(-0.05, 0.05, (NUM_KEYPOINTS, 3))
    for k, name in enumerate(KEYPOINT_NAMES):   # a symmetric detector
        if name.startswith('right_'):
            truth[k] = truth[KEYPOINT_NAMES.index('left_' + name[6:])] * [1, -1, 1]
    truth[[KEYPOINT_NAMES.index('left_small_toe'), KEYPOINT_NAMES.index('right_small_toe')]] = 0
    placed = DetectorPlacement(truth, np.zeros(NUM_KEYPOINTS), {})
    fit = fit_detector_placement(_fake_renders(walk, placed))
    err_mm = 1000 * leg_length(walk.skeleton) * np.linalg.norm(fit.offsets - truth, axis=1)
    assert err_mm.max() < 6.0, dict(zip(KEYPOINT_NAMES, err_mm.round(1)))
    before = np.array(fit.info['median_residual_before_rel_height'], dtype=float)
    after = np.array(fit.info['median_residual_after_rel_height'], dtype=float)
    ok = np.isfinite(before)
    assert np.all(after[ok] < before[ok])
    assert fit.info['detections_per_keypoint'][KEYPOINT_NAMES.index('left_small_toe')] == 0
    # no offset in the data: the fit stays near zero
    zero = fit_detector_placement(_fake_renders(walk, None, seed=2))
    assert 1000 * leg_length(walk.skeleton) * np.abs(zero.offsets).max() < 6.0


def test_placement_moves_points_with_their_segment(walk, tmp_path):
    offsets = np.zeros((NUM_KEYPOINTS, 3))
    k = KEYPOINT_NAMES.index('left_knee')
    offsets[k] = [0.1, 0.0, 0.0]                       # forward of the thigh's end
    placed = DetectorPlacement(offsets, np.zeros(NUM_KEYPOINTS), {'x': 1})
    a = keypoints_3d(walk.skeleton, walk.rotations, walk.root_positions)
    b = keypoints_3d(walk.skeleton, walk.rotations, walk.root_positions, placement=placed)
    moved = np.linalg.norm(b - a, axis=-1)
    assert np.allclose(moved[:, k], 0.1 * leg_length(walk.skeleton))
    assert np.allclose(np.delete(moved, k, axis=1), 0.0)
    placed.save(tmp_path / 'p.json')
    again = DetectorPlacement.load(tmp_path / 'p.json')
    np.testing.assert_allclose(again.offsets, offsets)


# ------------------------------------------------------------------------------------------
def _gt(walk, F=40):
    fk = walk.fk()
    J = fk.positions[:F] - [0, 0, 0] + np.array([0.0, 0.0, 3.0])  # a 'camera' frame
    meta = {'clip': 'bandai_namco_bvh/x.tar.xz:dataset-2_walk_exhausted_001.bvh',
            'camera': {'kind': 'static'}, 'body_height_m': 1.8, 'detected_fraction': 1.0}
    K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
    kp = np.zeros((F, NUM_KEYPOINTS, 3))   # a detector that puts knees and ankles exactly
    for side in ('left', 'right'):
        for n in ('knee', 'ankle'):
            p = J[:, JOINT_INDEX[f'{side}_{n}']] @ K.T
            kp[:, KEYPOINT_NAMES.index(f'{side}_{n}')] = np.c_[p[:, :2] / p[:, 2:], np.ones(F)]
    gt = {'fps': np.array(30.0), 'joints_camera': J, 'joints_world': fk.positions[:F],
          'view': np.array(['front'] * F), 'K': K, 'keypoints': kp}
    return gt, meta, J


def test_scores_of_a_perfect_and_of_a_leg_swapped_lifter(walk):
    gt, meta, J = _gt(walk)
    idx = np.arange(len(J))
    perfect = score_clip(meta['clip'], meta, gt, J, idx,
                         {'world': (gt['joints_world'][:, 0], idx)})
    s = perfect.summary()
    assert s['mpjpe'] < 1e-6 and s['pa_mpjpe'] < 1e-6 and s['mble'] < 1e-6
    assert s['world_root_error'] < 1e-6 and abs(s['jitter_ratio'] - 1) < 1e-9
    legs = [JOINT_INDEX[f'{sd}_{n}'] for sd in ('left', 'right')
            for n in ('hip', 'knee', 'ankle', 'toe')]
    swapped = J.copy()
    swapped[:, legs] = J[:, [JOINT_MIRROR[j] for j in legs]]
    sw = score_clip(meta['clip'], meta, gt, swapped, idx).summary()
    scored = score_clip(meta['clip'], meta, gt, swapped, idx).swaps
    assert sw['swap_rate'] == 1.0 and (scored >= 0).sum() > len(J) // 2
    assert s['swap_rate'] == 0.0
    # a translated, rotated world path has no trajectory error after rigid alignment
    c, si = np.cos(0.7), np.sin(0.7)
    Rz = np.array([[c, -si, 0], [si, c, 0], [0, 0, 1]])
    moved = gt['joints_world'][:, 0] @ Rz.T + [5.0, -2.0, 0.3]
    r = score_clip(meta['clip'], meta, gt, J, idx, {'physics': (moved, idx)}).summary()
    assert r['physics_root_error'] < 1e-6
    # without alignment the error is split along the floor and up
    off = gt['joints_world'][:, 0] + [0.3, -0.4, 0.12]
    u = score_clip(meta['clip'], meta, gt, J, idx, {'physics': (off, idx)}).summary()
    assert u['physics_root_error_unaligned'] == pytest.approx(np.hypot(500, 120))
    assert u['physics_root_error_unaligned_horizontal'] == pytest.approx(500.0)
    assert u['physics_root_error_unaligned_vertical'] == pytest.approx(120.0)
    # and with the camera's pose, the lifter's own root moved into the world is split so
    # too (here the camera frame is the world moved 3 m along z)
    posed = dict(gt, camera_R=np.tile(np.eye(3), (len(J), 1, 1)),
                 camera_position=np.tile([0.0, 0.0, -3.0], (len(J), 1)))
    w = score_clip(meta['clip'], meta, posed, J + [0.2, 0.0, 0.05], idx,
                   {'world': (np.repeat(gt['joints_world'][:, None, 0], 18, 1), idx)}).summary()
    assert w['world_lifter_root_error_horizontal'] == pytest.approx(200.0)
    assert w['world_lifter_root_error_vertical'] == pytest.approx(50.0)
    # a lifter whose body is turned by 20 deg about its pelvis: all of its MPJPE is the
    # global orientation's (RA-MPJPE 0, orientation error 20 deg); one also 10 % too large
    # keeps only the scale's share after the rigid alignment
    Ry = Rotation.from_rotvec([0.0, np.radians(20.0), 0.0]).as_matrix()
    turned = (J - J[:, :1]) @ Ry.T + J[:, :1]
    t = score_clip(meta['clip'], meta, gt, turned, idx).summary()
    assert t['mpjpe'] > 50 and t['ra_mpjpe'] < 1e-6 and t['pa_mpjpe'] < 1e-6
    assert abs(t['orientation_deg'] - 20.0) < 1e-3
    big = score_clip(meta['clip'], meta, gt, 1.1 * (turned - J[:, :1]) + J[:, :1], idx)
    b = big.summary()
    assert b['mpjpe'] > t['mpjpe'] and 5 < b['ra_mpjpe'] < b['mpjpe'] and b['pa_mpjpe'] < 1e-6
    assert aggregate([big])['by_view']['front']['ra_mpjpe'] == pytest.approx(b['ra_mpjpe'])
    agg = aggregate([perfect, score_clip(meta['clip'], meta, gt, swapped, idx)])
    assert agg['clips'] == 2 and agg['by_view']['front']['frames'] == 2 * len(J)
    # moving cameras by the rendered floor's texture (static cameras left out)
    import dataclasses
    from mocap_core.render.evaluate import report_markdown
    pan = dataclasses.replace(perfect, camera='pan', floor='stripes')
    floors = aggregate([pan, dataclasses.replace(perfect, camera='static', floor='checker')])
    assert list(floors['moving_by_floor']) == ['stripes']
    assert floors['moving_by_floor']['stripes']['clips'] == 1
    assert "## Moving cameras by the floor's texture" in report_markdown(floors, 't', [])
    # by how far the camera looks down: the clip's median pitch, from its camera pose
    from mocap_core.render.evaluate import camera_pitch_deg, pitch_class
    down = look_at(np.array([0.0, -2.0, 3.0]), np.array([0.0, 0.0, 1.0]))   # 45 deg down
    level = look_at(np.array([0.0, -4.0, 1.0]), np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(camera_pitch_deg(np.stack([down, level])), [45.0, 0.0],
                               atol=1e-9)
    steep = score_clip(meta['clip'], meta, dict(gt, camera_R=np.tile(down, (len(J), 1, 1))),
                       J, idx)
    assert steep.pitch == 'looking down >= 35 deg'
    assert pitch_class(-20.0) == 'looking up (> 15 deg)'
    assert pitch_class(20.0) == 'looking down 15-35 deg'
    assert pitch_class(-10.0) == pitch_class(10.0) == 'level (within 15 deg)'
    pitches = aggregate([steep, dataclasses.replace(perfect, pitch='level (within 15 deg)')])
    assert {g: r['clips'] for g, r in pitches['by_pitch'].items()} == {
        'level (within 15 deg)': 1, 'looking down >= 35 deg': 1}
    text = report_markdown(pitches, 't', [])
    assert '## By how far the camera looks up or down' in text
    assert '| looking down >= 35 deg | 1 |' in text
    # the detector's own swaps: none as placed; every scored frame with its legs exchanged
    det = detector_swaps(gt)
    assert (det >= 0).sum() > len(J) // 2 and det.max() == 0
    assert agg['pooled']['detector_swap_rate'] == 0.0
    swap = {n: n.replace('left', 'right') if 'left' in n else n.replace('right', 'left')
            for n in KEYPOINT_NAMES}
    mirrored = dict(gt, keypoints=gt['keypoints'][:, [KEYPOINT_NAMES.index(swap[n])
                                                      for n in KEYPOINT_NAMES]])
    det = detector_swaps(mirrored)
    assert np.array_equal(det >= 0, detector_swaps(gt) >= 0) and det[det >= 0].min() == 1
    assert motion_group(meta['clip']) == 'walk'


def test_foot_scores_against_the_stage_floor(walk):
    """Feet on the floor score 0; feet sunk 2 cm after the first second, or sliding while
    in contact, are measured."""
    fk = walk.fk()
    W = fk.positions[:60].copy()
    feet = [JOINT_INDEX[n] for n in ('left_ankle', 'left_toe', 'right_ankle', 'right_toe')]
    W[..., 2] -= W[:, feet, 2].min()                  # lowest foot joint of the clip on z = 0
    idx = np.arange(len(W))
    contacts = np.zeros((len(W), 4), dtype=bool)
    contacts[:, :2] = True                            # left foot in contact throughout
    s = foot_scores(W, idx, contacts, 30.0)
    assert s['penetration_after_1s_mm'] == pytest.approx(
        max(0.0, -1000 * W[30:, feet, 2].min()), abs=1e-9)
    sunk = W.copy()
    sunk[35, :, 2] -= 0.02 + sunk[35, feet, 2].min()   # one late frame 2 cm under the floor
    sunk[10, :, 2] -= 0.5                              # an early one does not count
    s2 = foot_scores(sunk, idx, contacts, 30.0)
    assert s2['penetration_after_1s_mm'] == pytest.approx(20.0, abs=1e-6)
    assert s2['frames_below_5mm'] == pytest.approx(1 / 30)
    # a left foot that slides 1 cm per frame while in contact
    slid = W.copy()
    slid[:, [feet[0], feet[1]], 0] = 0.01 * idx[:, None]
    slid[:, [feet[0], feet[1]], 1] = 0.0
    s3 = foot_scores(slid, idx, contacts, 30.0)
    assert s3['skating_mm'] == pytest.approx(10.0, abs=1e-6)
    # per rendered frame also when the output has every third frame only (a live run)
    kept = idx[::3]
    assert foot_scores(slid[kept], kept, contacts, 30.0)['skating_mm'] == \
        pytest.approx(10.0, abs=1e-6)
    assert np.isnan(foot_scores(W, idx, np.zeros_like(contacts), 30.0)['skating_mm'])


def test_skating_in_the_world_with_a_floor_frame_riding_with_the_camera(walk):
    """A camera that walks 2 cm per frame along x: a left foot that stands in the world
    moves 2 cm per frame in the camera's floor frame (its own-frame skating says 20 mm) and
    scores 0 in the world; a foot held still in the floor frame scores 20 mm in the world."""
    from mocap_core.rotations import matrix_to_quat
    fk = walk.fk()
    n = 60
    feet = [JOINT_INDEX[k] for k in ('left_ankle', 'left_toe')]
    W = fk.positions[:n].copy()
    W[:, feet] = W[0, feet]                            # the left foot stands in the world
    idx = np.arange(n)
    C = np.stack([0.02 * idx, np.full(n, -3.0), np.full(n, 1.5)], axis=1)   # camera centre
    R = look_at(C[0], C[0] + np.array([0.0, 1.0, -0.3]))   # p_camera = R (p_world - c)
    shift = C * np.array([1.0, 1.0, 0.0])              # the floor frame rides with the camera
    in_floor = W - shift[:, None]
    quats = np.repeat(matrix_to_quat(R)[None], n, axis=0)
    trans = np.repeat((R @ np.array([0.0, 0.0, -1.5]))[None], n, axis=0)
    gt = {'camera_R': np.repeat(R[None], n, axis=0), 'camera_position': C, 'fps': 30.0,
          'contacts': np.zeros((n, 4), dtype=bool)}
    gt['contacts'][:, :2] = True                       # left heel and toe in contact
    assert foot_scores(in_floor, idx, gt['contacts'], 30.0)['skating_mm'] == \
        pytest.approx(20.0, abs=1e-6)
    assert skating_in_world(in_floor, idx, quats, trans, idx, gt)['skating_world_mm'] == \
        pytest.approx(0.0, abs=1e-6)
    held = W.copy()
    held[:, feet] = in_floor[0, feet]                  # still in the floor frame
    assert skating_in_world(held, idx, quats, trans, idx, gt)['skating_world_mm'] == \
        pytest.approx(20.0, abs=1e-6)
    # frames without a floor message are left out: none left to score
    assert np.isnan(skating_in_world(in_floor, idx, quats[:1], trans[:1], idx[:1],
                                     gt)['skating_world_mm'])


def test_stage_change_from_the_lifter_is_paired_by_frame():
    """A stage is compared with the lifter on the frames both have: the lifter itself gives
    a change of 0 and a jitter ratio of 1 whatever frames it drops; a smoothed copy of the
    lifter (moving average) gives a ratio below 1; a noisier one a positive change."""
    from mocap_core.render.evaluate import _paired_with_lifter
    rng = np.random.default_rng(0)
    F = 60
    t = np.arange(F)[:, None, None] / 30.0
    G = np.sin(t + np.arange(18)[None, :, None] * 0.1 + np.arange(3) * 0.5)
    lifter = G + rng.normal(0, 0.01, G.shape)
    idx = np.arange(F)
    keep = np.r_[5:F]                             # the stage starts 5 frames later
    same = _paired_with_lifter(lifter[keep], idx[keep], lifter, idx, G, 30.0)
    assert same['pa_mpjpe_change'] == pytest.approx(0.0, abs=1e-9)
    assert same['jitter_vs_lifter'] == pytest.approx(1.0)
    kernel = np.ones(5) / 5
    smooth = np.apply_along_axis(lambda x: np.convolve(x, kernel, mode='same'), 0, lifter)
    sm = _paired_with_lifter(smooth[keep], idx[keep], lifter, idx, G, 30.0)
    assert sm['jitter_vs_lifter'] < 0.3
    noisy = _paired_with_lifter(lifter + rng.normal(0, 0.02, G.shape), idx, lifter, idx, G,
                                30.0)
    assert noisy['pa_mpjpe_change'] > 5.0 and noisy['jitter_vs_lifter'] > 1.5
    # against the truth: the truth itself gives 1, the noisy lifter far more, the moving
    # average less than the lifter
    truth = _paired_with_lifter(G[keep], idx[keep], lifter, idx, G, 30.0)
    assert truth['jitter_vs_truth'] == pytest.approx(1.0) and truth['jitter'] > 0
    assert same['jitter_vs_truth'] > 3.0
    assert sm['jitter_vs_truth'] < 0.3 * same['jitter_vs_truth']


def test_world_jitter_is_compared_in_an_inertial_frame():
    """With a moving camera the lifter's joints (optical frame) accelerate with the camera.
    A perfect world output (the true world joints) against a perfect lifter (the true
    camera-frame joints) must give a jitter ratio of 1: the lifter is carried into the
    world by the true camera pose first. Against the camera-frame lifter the same output
    would look several times smoother or rougher, whichever way the camera shakes."""
    from mocap_core.render.evaluate import _paired_with_lifter, camera_to_world
    from mocap_core.rotations import axis_angle_to_matrix
    rng = np.random.default_rng(1)
    F = 90
    t = np.arange(F) / 30.0
    W = np.stack([np.c_[0.3 * np.sin(t + j), 0.1 * np.cos(2 * t + j), 1.0 + 0.02 * j
                        + 0.0 * t] for j in range(18)], axis=1)      # (F, 18, 3) world
    # a hand-held camera: it orbits and shakes
    yaw = 0.8 * t + 0.03 * rng.normal(size=F)
    R = np.stack([axis_angle_to_matrix(np.array([0.0, 0.0, a])) for a in yaw])
    position = np.c_[3 * np.cos(yaw), 3 * np.sin(yaw), 1.5 + 0.01 * rng.normal(size=F)]
    C = np.einsum('fij,fkj->fki', R, W - position[:, None])
    gt = {'camera_R': R, 'camera_position': position}
    idx = np.arange(F)
    np.testing.assert_allclose(camera_to_world(C, idx, gt), W, atol=1e-12)
    r = _paired_with_lifter(W, idx, C, idx, C, 30.0, camera_to_world(C, idx, gt), W)
    assert r['jitter_vs_lifter'] == pytest.approx(1.0)
    assert r['jitter_vs_lifter_camera_frame'] < 0.5
    assert r['jitter_vs_truth'] == pytest.approx(1.0)     # the truth in the world, too


def test_video_runs_compared_side_by_side(tmp_path):
    """``mocap eval video --compare``: each run's medians land in its own column; a bad
    argument or an unreadable report is an error, not a traceback."""
    import argparse
    import json

    from mocap_core.cli.eval_video import add_eval_parser
    reports = {}
    for name, change in (('a', 2.0), ('b', -1.5)):
        path = tmp_path / f'{name}.json'
        path.write_text(json.dumps({'aggregate': {'clips': 3, 'median': {
            'pa_mpjpe': 70.0, 'physics_pa_mpjpe_change': change,
            'world_frames_below_5mm': 0.25, 'world_root_error_unaligned': 128.96}}}))
        reports[name] = path
    parser = argparse.ArgumentParser()
    add_eval_parser(parser.add_subparsers(dest='model'))
    out = tmp_path / 'cmp.md'
    args = parser.parse_args(['video', '--compare', f"a={reports['a']}", f"b={reports['b']}",
                              '-o', str(out), '--title', 'T'])
    assert args.func(args) == 0
    md = out.read_text()
    assert '| physics PA-MPJPE change from the lifter, same frames (mm) | +2.0 | -1.5 |' in md
    assert '| world frames with a foot joint > 5 mm below the floor (%) | 25.0 | 25.0 |' in md
    assert '| physics skating in contact (mm/frame) | – | – |' in md
    assert ('| world root error, no alignment (meaningful with a known camera pose, mm) | 129 '
            '| 129 |') in md
    bad = parser.parse_args(['video', '--compare', 'nameonly', '-o', str(out)])
    assert bad.func(bad) == 2
    missing = parser.parse_args(['video', '--compare', f'x={tmp_path / "none.json"}',
                                 '-o', str(out)])
    assert missing.func(missing) == 2


def test_world_segment_errors_align_pieces_whole_or_by_their_start():
    from mocap_core.render.evaluate import world_segment_errors
    from mocap_core.rotations import axis_angle_to_matrix

    rng = np.random.default_rng(0)
    F = 250
    gt = rng.normal(size=(F, 18, 3)) * 0.3 + np.linspace(0, 5, F)[:, None, None] * [1, 0, 0]
    # the same motion in another frame: both errors vanish
    R = axis_angle_to_matrix(np.array([0.0, 0.0, 0.7]))
    moved = gt @ R.T + [3.0, -1.0, 0.2]
    e = world_segment_errors(moved, np.arange(F), gt)
    assert e['wa_mpjpe100'] < 1e-6 and e['w_mpjpe100'] < 1e-6
    # a drift of 1 mm per frame along y: the whole-piece alignment removes most of it, the
    # alignment by the first two frames keeps it (mean over a 100-frame piece ~ 50 mm)
    drift = gt + np.arange(F)[:, None, None] * [0.0, 0.001, 0.0]
    e = world_segment_errors(drift, np.arange(F), gt)
    assert 40 < e['w_mpjpe100'] < 60 and e['wa_mpjpe100'] < 0.6 * e['w_mpjpe100']
    # the 50-frame tail counts; a 30-frame clip is one piece; no frames: nothing
    assert world_segment_errors(gt[:30], np.arange(30), gt[:30])['wa_mpjpe100'] < 1e-6
    assert world_segment_errors(gt[:1], np.arange(1), gt[:30]) == {}


def test_a_fallen_body_is_counted_only_where_the_truth_stands(walk):
    """``fallen_share``: a stage body turned 60 deg about a horizontal axis has fallen in
    every frame where the true body stands; an upright one in none; a true body that lies
    down itself is not a stage's fall. The report counts the clips."""
    from mocap_core.render.evaluate import aggregate, fallen_share
    J = walk.fk().positions[:30]
    turn = Rotation.from_rotvec([np.radians(60.0), 0.0, 0.0]).as_matrix()
    down = (J - J[:, :1]) @ turn.T + J[:, :1]
    assert fallen_share(J, J) == 0.0
    assert fallen_share(down, J) == 1.0
    assert fallen_share(down, down) == 0.0            # the truth lies too: not a fall
    gt, meta, Jc = _gt(walk, F=30)
    idx = np.arange(30)
    clips = [score_clip(meta['clip'], meta, gt, Jc, idx, {'physics': (s, idx)})
             for s in (J, down)]
    pooled = aggregate(clips)['pooled']
    assert pooled['physics_fallen_clips'] == 1 and pooled['physics_fallen'] == 0.5
