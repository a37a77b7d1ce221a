import numpy as np
import pytest
import torch

from mocap_core.camera import CameraIntrinsics
from mocap_core.skeleton import JOINT_MIRROR, NUM_BONE_GROUPS, NUM_JOINTS, Skeleton
from mocap_lifter.features import NUM_FEATURES, lifter_features, root_keypoint
from mocap_lifter.model import LifterConfig, MotioNet, fk_layer, offsets_from_lengths
from mocap_lifter.online import OnlineLifter
from mocap_lifter.training.metrics import (bone_length_spread_mm, mpjpe_mm, n_mpjpe_mm,
                                           pa_mpjpe_mm)

SMALL = dict(channels=32, fusion_blocks=2, skeleton_channels=16, dropout=0.0)


def _inputs(b=2, t=40, seed=0):
    g = torch.Generator().manual_seed(seed)
    return (torch.randn(b, t, NUM_FEATURES, generator=g), 0.1 * torch.randn(b, t, 2, generator=g),
            0.05 + 0.1 * torch.rand(b, t, generator=g))


def test_output_shapes_units_and_one_symmetric_skeleton():
    model = MotioNet(LifterConfig(**SMALL)).eval()
    x, r, sc = _inputs()
    out = model(x, r, sc)
    assert out['rotations'].shape == (2, 40, NUM_JOINTS, 4)
    assert torch.allclose(out['rotations'].norm(dim=-1), torch.ones(2, 40, NUM_JOINTS))
    assert out['lengths'].shape == (2, NUM_BONE_GROUPS) and torch.all(out['lengths'] > 0)
    assert out['contacts'].shape == (2, 40, 4) and torch.all(out['depth'] > 0)
    # root = depth * (root_x, root_y, 1)
    torch.testing.assert_close(out['root'][..., :2], r * out['depth'][..., None])
    # a person twice as large in the image is at half the depth
    twice = model(x, r, 2 * sc)
    torch.testing.assert_close(twice['depth'], out['depth'] / 2)
    pos = out['positions'].detach().numpy()
    assert bone_length_spread_mm(pos[0]) < 1e-3        # one skeleton over time
    sk = Skeleton.from_group_lengths(out['lengths'][0].detach().double().numpy())
    assert sk.is_symmetric()
    off = offsets_from_lengths(out['lengths'])[0].detach().numpy()
    np.testing.assert_allclose(off[list(JOINT_MIRROR)] * [1, -1, 1], off, atol=1e-6)


def test_fk_layer_gradients():
    lengths = torch.full((1, NUM_BONE_GROUPS), 0.3, dtype=torch.float64, requires_grad=True)
    q = torch.randn(1, 3, NUM_JOINTS, 4, dtype=torch.float64)
    q = (q / q.norm(dim=-1, keepdim=True)).requires_grad_(True)
    root = torch.randn(1, 3, 3, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(fk_layer, (lengths, q, root), eps=1e-6, atol=1e-5)


def test_causal_mode_ignores_future_frames():
    model = MotioNet(LifterConfig(**SMALL, causal=True)).eval()
    x, r, sc = _inputs(t=50)
    x2, r2, sc2 = x.clone(), r.clone(), sc.clone()
    x2[:, 30:] += 3.0
    r2[:, 30:] += 0.5
    sc2[:, 30:] *= 2.0
    with torch.no_grad():
        lengths = model(x, r, sc)['lengths']
        a = model(x, r, sc, lengths=lengths)
        b = model(x2, r2, sc2, lengths=lengths)
    for k in ('rotations', 'depth', 'contacts', 'positions'):
        torch.testing.assert_close(a[k][:, :30], b[k][:, :30])
        assert not torch.allclose(a[k][:, 30:], b[k][:, 30:])
    # the centred model does look ahead
    centred = MotioNet(LifterConfig(**SMALL, causal=False)).eval()
    with torch.no_grad():
        c1 = centred(x, r, sc, lengths=lengths)['rotations']
        c2 = centred(x2, r2, sc2, lengths=lengths)['rotations']
    assert not torch.allclose(c1[:, 25:30], c2[:, 25:30])


def test_features_are_intrinsics_invariant_and_root_is_mid_hip():
    rng = np.random.default_rng(0)
    canon = rng.uniform(-0.3, 0.3, (5, 23, 2))
    kp_a, kp_b = np.ones((5, 23, 3)), np.ones((5, 23, 3))
    a = CameraIntrinsics(640, 480, 500.0, 500.0, 320.0, 240.0)
    b = CameraIntrinsics(1920, 1080, 1400.0, 1400.0, 960.0, 540.0)
    kp_a[..., 0] = canon[..., 0] * a.fx + a.cx
    kp_a[..., 1] = canon[..., 1] * a.fy + a.cy
    kp_b[..., 0] = canon[..., 0] * b.fx + b.cx
    kp_b[..., 1] = canon[..., 1] * b.fy + b.cy
    fa, ra, sa, _ = lifter_features(kp_a, a)
    fb, rb, sb, _ = lifter_features(kp_b, b)
    np.testing.assert_allclose(sa, sb, rtol=1e-6)
    np.testing.assert_allclose(fa, fb, atol=1e-5)
    np.testing.assert_allclose(ra, 0.5 * (canon[:, 11] + canon[:, 12]), atol=1e-9)
    assert fa.shape == (5, NUM_FEATURES)


def test_root_keypoint_holds_through_missing_hips():
    kc = np.zeros((4, 23, 3))
    kc[:, 11] = [0.1, 0.2, 1.0]
    kc[:, 12] = [0.3, 0.2, 1.0]
    kc[2, 11, 2] = 0.0                       # left hip lost in frame 2
    kc[0, 12, 2] = 0.0                       # right hip lost in frame 0
    root, valid = root_keypoint(kc)
    assert list(valid) == [False, True, False, True]
    np.testing.assert_allclose(root[0], [0.2, 0.2])   # back-filled
    np.testing.assert_allclose(root[2], root[1])      # held


def test_metrics_alignments():
    g = np.random.default_rng(1).normal(size=(4, NUM_JOINTS, 3))
    assert mpjpe_mm(g + 5.0, g) < 1e-9                  # root aligned
    assert n_mpjpe_mm(1.5 * g, g) < 1e-6 < mpjpe_mm(1.5 * g, g)
    from scipy.spatial.transform import Rotation
    r = Rotation.random(4, random_state=2).as_matrix()
    assert pa_mpjpe_mm(0.8 * np.einsum('nij,nkj->nki', r, g) - 2.0, g) < 1e-6


def test_online_lifter_causal_matches_batch_and_resets():
    model = MotioNet(LifterConfig(**SMALL, causal=True)).eval()
    intr = CameraIntrinsics(640, 480, 500.0, 500.0, 320.0, 240.0)
    rng = np.random.default_rng(3)
    kp = np.concatenate([rng.uniform(200, 400, (60, 23, 2)), np.ones((60, 23, 1))], -1)
    online = OnlineLifter(model, 'causal', skeleton_frames=10)
    frames = [f for i in range(60) for f in online.push(1_000_000 * 33 * i + 1, kp[i], intr)[0]]
    assert len(frames) == 60 and frames[-1].skeleton_fixed
    feats, root, scale, _ = lifter_features(kp, intr)
    with torch.no_grad():
        batch = model(torch.as_tensor(feats[None]), torch.as_tensor(root[None]).float(),
                      torch.as_tensor(scale[None]).float(), lengths=online.lengths)
    np.testing.assert_allclose(frames[-1].pose.rotations, batch['rotations'][0, -1].double(),
                               atol=1e-5)
    out, event = online.push(frames[-1].stamp_ns + 5_000_000_000, kp[0], intr)
    assert event == 'gap' and online.lengths is None and len(out) == 1
    _, event = online.push(1, kp[0], intr)
    assert event == 'backwards'
    with pytest.raises(ValueError):
        OnlineLifter(model, 'windowed')


def test_online_lifter_windowed_emits_every_frame_once_in_order():
    model = MotioNet(LifterConfig(**SMALL, causal=False)).eval()
    intr = CameraIntrinsics(640, 480, 500.0, 500.0, 320.0, 240.0)
    rng = np.random.default_rng(4)
    kp = np.concatenate([rng.uniform(200, 400, (40, 23, 2)), np.ones((40, 23, 1))], -1)
    online = OnlineLifter(model, 'windowed', latency=5)
    stamps = [33_000_000 * i + 7 for i in range(40)]
    got = []
    for i in range(40):
        frames, _ = online.push(stamps[i], kp[i], intr)
        got += frames
        assert len(got) == max(0, i + 1 - 5)          # five frames of look-ahead
    assert online.pending() == 5
    got += online.flush()
    assert [f.stamp_ns for f in got] == stamps and online.pending() == 0


@pytest.mark.parametrize('mode', ['windowed', 'causal', 'vtm', 'windowed_flip',
                                  'windowed_smoothed'])
def test_online_lifter_chunks_give_the_same_frames_later(mode):
    """chunk = 8 lifts eight frames per network pass: the same poses as frame by frame (the
    network is convolutional; VTM lifts each frame from its frame-by-frame window), emitted in
    groups, every frame once."""
    if mode == 'vtm':
        from mocap_lifter.vtm import VTM, VTMConfig
        torch.manual_seed(0)
        model = VTM(VTMConfig(width=32, latent_upper=16, latent_lower=8, keypoint_width=16,
                              heads=2, dropout=0.0,
                              virtual_lengths=list(Skeleton.default().group_lengths()))).eval()
        mode = 'windowed'
    else:
        model = MotioNet(LifterConfig(**SMALL, causal=mode == 'causal')).eval()
    flip = mode.endswith('_flip')     # test-time flip keeps the equivalence
    sigma = 2.0 if mode.endswith('_smoothed') else 0.0    # so does the output smoothing
    mode = mode.replace('_flip', '').replace('_smoothed', '')
    intr = CameraIntrinsics(640, 480, 500.0, 500.0, 320.0, 240.0)
    rng = np.random.default_rng(5)
    kp = np.concatenate([rng.uniform(200, 400, (50, 23, 2)), np.ones((50, 23, 1))], -1)
    stamps = [33_000_000 * i for i in range(50)]
    runs = {}
    for chunk in (1, 8):
        # the skeleton is estimated over 30 frames (changing every frame), then held
        online = OnlineLifter(model, mode, skeleton_frames=30, chunk=chunk, flip=flip,
                              output_sigma=sigma)
        got, sizes = [], []
        for i in range(50):
            frames, _ = online.push(stamps[i], kp[i], intr)
            got += frames
            sizes.append(len(frames))
        got += online.flush()
        assert [f.stamp_ns for f in got] == stamps
        # the output smoothing holds its radius back: the first chunk comes out shorter
        radius = online.delay - online.latency
        assert radius == (4 if sigma else 0)
        assert set(sizes) <= {0, chunk - radius, chunk} if chunk > 1 else set(sizes) <= {0, 1}
        assert online.delay <= 50 - sum(sizes) < online.delay + chunk
        runs[chunk] = got
    for a, b in zip(runs[1], runs[8]):
        np.testing.assert_allclose(a.pose.joint_positions(), b.pose.joint_positions(),
                                   atol=1e-5)
        assert a.skeleton_fixed == b.skeleton_fixed
    assert runs[8][-1].skeleton_fixed and not runs[8][0].skeleton_fixed
    with pytest.raises(ValueError, match='chunk'):
        OnlineLifter(model, mode, chunk=0)


def test_evaluate_real_openpose_sequence_measures_plausibility():
    """The real-detection evaluation (no ground truth) on the committed OpenPose example."""
    from pathlib import Path

    from mocap_lifter.training.evaluate import evaluate_real

    seq = Path(__file__).resolve().parents[3] / 'data' / 'openpose_example' / 'seq1'
    model = MotioNet(LifterConfig(**SMALL, causal=False)).eval()
    res = evaluate_real(model, [seq])
    assert res['sequences'] == 1 and res['frames'] == 81
    row = res['per_sequence'][0]
    assert np.isfinite(row['jitter_mm_s2']) and row['jitter_mm_s2'] > 0
    assert np.isnan(row['skating_mm']) or row['skating_mm'] >= 0   # nan: no contact predicted
    assert row['bone_spread_mm'] < 1e-3                   # one skeleton per sequence
    assert 0.3 < row['mean_confidence'] < 1.0


def test_tpose_windows_and_their_loss():
    """MotioNet's reference T-pose: a T-pose window has identity joint rotations (camera frame
    too: only the root changes), a yaw-only root, both feet in contact; the T-pose loss is
    zero for the exact rotations, positive otherwise, and only counts T-pose windows."""
    from mocap_core.data.motion import Motion
    from mocap_core.rotations import axis_angle_to_quat as quat_from_axis_angle
    from mocap_lifter.training.samples import Augmentation, make_sample
    from mocap_lifter.training.train import TrainConfig, losses

    rng = np.random.default_rng(0)
    sk = Skeleton.default()
    frames = 20
    rot = np.zeros((frames, NUM_JOINTS, 4))
    rot[..., 3] = 1.0
    rot[:, 0] = quat_from_axis_angle(np.array([0.0, 0.0, 0.7]))
    rot[:, 3] = quat_from_axis_angle(np.array([0.0, 0.5, 0.0]))           # a bent knee
    root = np.column_stack([np.linspace(0, 1, frames), np.zeros(frames),
                            np.full(frames, 0.9)])
    motion = Motion('walk', 30.0, sk, rot, root, np.zeros((frames, 4), bool))
    aug = Augmentation(flip_prob=0.0, corruption=None, tpose_prob=1.0)
    s = make_sample(motion, 0, frames, rng, aug)
    assert s['tpose'] == 1.0 and s['contacts'].min() == 1.0
    np.testing.assert_allclose(np.abs(s['rotations'][:, 1:, 3]), 1.0, atol=1e-9)
    assert np.ptp(s['positions'], axis=0).max() < 1e-9                   # standing still
    plain = make_sample(motion, 0, frames, rng, Augmentation(flip_prob=0.0, corruption=None))
    assert plain['tpose'] == 0.0

    gt = {k: torch.as_tensor(np.stack([s[k], plain[k]])) for k in s}
    out = {'positions': gt['positions'], 'rotations': gt['rotations'].clone(),
           'depth': gt['root'][..., 2], 'root': gt['root'], 'lengths': gt['lengths'],
           'contacts': torch.zeros(2, frames, 4)}
    assert float(losses(out, gt, TrainConfig())['tpose']) < 1e-7
    out['rotations'][1] = torch.roll(out['rotations'][1], 1, dims=-1)  # only the plain window
    assert float(losses(out, gt, TrainConfig())['tpose']) < 1e-7
    out['rotations'][0] = torch.roll(out['rotations'][0], 1, dims=-1)
    assert float(losses(out, gt, TrainConfig())['tpose']) > 0.1


def test_acceleration_loss_counts_jitter_not_smooth_offsets():
    """The acceleration term: zero for the true motion and for a constant-velocity drift of
    every joint, positive for frame-to-frame jitter, and in the total only with its weight."""
    from mocap_lifter.training.train import TrainConfig, losses, total_loss

    rng = np.random.default_rng(1)
    b, t = 2, 16
    pos = torch.as_tensor(np.cumsum(rng.normal(0, 0.01, (b, t, NUM_JOINTS, 3)), axis=1))
    gt = {'positions': pos, 'rotations': torch.zeros(b, t, NUM_JOINTS, 4),
          'root': torch.ones(b, t, 3), 'lengths': torch.ones(b, 10),
          'contacts': torch.zeros(b, t, 4)}
    gt['rotations'][..., 3] = 1.0
    out = {k: v.clone() for k, v in gt.items() if k != 'contacts'}
    out.update(depth=gt['root'][..., 2], contacts=torch.zeros(b, t, 4))
    assert float(losses(out, gt, TrainConfig())['acceleration']) < 1e-12
    drift = torch.arange(t, dtype=pos.dtype)[None, :, None, None] * 0.01
    out['positions'] = pos + drift * torch.as_tensor([1.0, 0.0, 0.0])
    assert float(losses(out, gt, TrainConfig())['acceleration']) < 1e-9
    out['positions'] = pos + torch.as_tensor(rng.normal(0, 0.005, pos.shape))
    terms = losses(out, gt, TrainConfig())
    assert float(terms['acceleration']) > 0.005            # ~ 0.005 * sqrt(6 * 3) per joint
    off = float(total_loss(terms, TrainConfig(w_acceleration=0.0)))
    on = float(total_loss(terms, TrainConfig(w_acceleration=2.0)))
    assert on - off == pytest.approx(2.0 * float(terms['acceleration']), rel=1e-6)
