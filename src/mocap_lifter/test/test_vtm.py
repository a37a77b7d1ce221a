"""VTM: body partition, motion representation, virtual skeleton and bone ratios, windowed
inference, online lifting and the two training stages (small networks, synthetic motion)."""

import numpy as np
import pytest
import torch

from mocap_core.kinematics import forward_kinematics
from mocap_core.rotations import axis_angle_to_quat, quat_angle
from mocap_core.skeleton import (KEYPOINT_INDEX, NUM_BONE_GROUPS, NUM_JOINTS, NUM_KEYPOINTS,
                                 Skeleton)
from mocap_lifter.model import offsets_from_lengths
from mocap_lifter.vtm import (LOWER_JOINTS, LOWER_KEYPOINTS, UPPER_JOINTS, UPPER_KEYPOINTS, VTM,
                              VTMConfig, keypoint_parts, motion_representation, part_channels)

SMALL = dict(width=32, latent_upper=16, latent_lower=8, keypoint_width=16, heads=2,
             dropout=0.0)


def _model(seed=0) -> VTM:
    torch.manual_seed(seed)
    cfg = VTMConfig(**SMALL, virtual_lengths=list(Skeleton.default().group_lengths()))
    return VTM(cfg).eval()


def _motion(frames=60, seed=0, name='walk'):
    """A synthetic walk-like motion (world frame, z up): swinging legs and arms, turning."""
    from mocap_core.data.motion import Motion
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / 30.0
    rot = np.zeros((frames, NUM_JOINTS, 4))
    rot[..., 3] = 1.0
    aa = np.zeros((frames, NUM_JOINTS, 3))
    aa[:, 0, 2] = 0.3 * t + rng.uniform(-1, 1)
    phase = 2 * np.pi * 1.1 * t
    for j, sign in ((1, 1), (5, -1)):           # hips
        aa[:, j, 1] = sign * 0.4 * np.sin(phase)
    for j in (2, 6):                             # knees
        aa[:, j, 1] = 0.5 + 0.4 * np.sin(phase)
    for j, sign in ((13, -1), (16, 1)):          # elbows
        aa[:, j, 2] = sign * 0.6 * (1 + np.sin(phase))
    rot = axis_angle_to_quat(aa)
    root = np.column_stack([0.8 * t, 0.1 * np.sin(phase), 0.92 + 0.02 * np.cos(2 * phase)])
    contacts = np.zeros((frames, 4), bool)
    contacts[:, :2] = np.sin(phase)[:, None] > 0
    contacts[:, 2:] = np.sin(phase)[:, None] <= 0
    return Motion(name, 30.0, Skeleton.default(), rot, root, contacts)


def test_upper_lower_partition_covers_every_joint_once_plus_root_in_both():
    assert UPPER_JOINTS[0] == LOWER_JOINTS[0] == 0
    non_root = list(UPPER_JOINTS[1:]) + list(LOWER_JOINTS[1:])
    assert sorted(non_root) == list(range(1, NUM_JOINTS))       # each once
    both = set(UPPER_KEYPOINTS) & set(LOWER_KEYPOINTS)
    assert both == {KEYPOINT_INDEX['left_hip'], KEYPOINT_INDEX['right_hip']}
    assert set(UPPER_KEYPOINTS) | set(LOWER_KEYPOINTS) == set(range(NUM_KEYPOINTS))
    up, lo = part_channels(UPPER_JOINTS), part_channels(LOWER_JOINTS)
    assert set(up) & set(lo) == set(range(12))                  # the root block
    assert len(set(up) | set(lo)) == NUM_JOINTS * 12


def test_motion_representation_channels():
    """6D rotations decode to the input rotations; positions are the virtual skeleton's
    root-relative FK; the root block holds the projection, log depth and velocities."""
    from mocap_core.rotations import rot6d_to_quat
    m = _motion(12)
    q = torch.as_tensor(m.rotations[None])
    root = torch.tensor([[0.2, -0.1, 3.0]]).repeat(12, 1)[None].double()
    root[0, :, 2] += torch.linspace(0, 0.3, 12, dtype=torch.float64)
    virtual = torch.as_tensor(Skeleton.default().group_lengths() * 1.1)
    x = motion_representation(q, root, virtual)[0].reshape(12, NUM_JOINTS, 12)
    back = rot6d_to_quat(x[..., :6]).numpy()
    assert np.degrees(quat_angle(back, m.rotations)).max() < 1e-6
    offsets = offsets_from_lengths(virtual[None])[0].numpy()
    sk = Skeleton.default()
    pos = forward_kinematics(sk.parents, offsets, m.rotations, np.zeros((12, 3))).positions
    np.testing.assert_allclose(x[:, 1:, 6:9].numpy(), pos[:, 1:], atol=1e-9)
    np.testing.assert_allclose(x[1:, 1:, 9:12].numpy(), np.diff(pos[:, 1:], axis=0), atol=1e-9)
    r = x[:, 0]
    np.testing.assert_allclose(r[:, 6].numpy(), 0.2 / root[0, :, 2].numpy(), atol=1e-12)
    np.testing.assert_allclose(r[:, 8].numpy(), np.log(root[0, :, 2].numpy()), atol=1e-12)
    np.testing.assert_allclose(r[1:, 11].numpy(), np.diff(np.log(root[0, :, 2].numpy())),
                               atol=1e-12)


def test_virtual_skeleton_is_the_mean_and_ratios_reproduce_the_training_skeletons():
    from mocap_lifter.training.vtm_train import virtual_skeleton
    rng = np.random.default_rng(1)
    base = Skeleton.default().group_lengths()
    skeletons = [Skeleton.from_group_lengths(base * rng.uniform(0.85, 1.15, NUM_BONE_GROUPS))
                 for _ in range(5)]
    motions = [_motion(10, seed=i) for i in range(5)]
    for m, sk in zip(motions, skeletons):
        m.skeleton = sk
    virtual = np.array(virtual_skeleton(motions))
    np.testing.assert_allclose(virtual, np.mean([s.group_lengths() for s in skeletons], 0))
    for sk in skeletons:
        ratios = sk.group_lengths() / virtual
        rebuilt = Skeleton.from_group_lengths(ratios * virtual)
        np.testing.assert_allclose(rebuilt.bone_lengths(), sk.bone_lengths(), atol=1e-12)
        assert rebuilt.is_symmetric(atol=1e-12)


def test_keypoint_parts_layout():
    from mocap_lifter.vtm import GLOBAL_KEYPOINT_CHANNELS, KEYPOINT_CHANNELS
    from mocap_lifter.features import NUM_FEATURES
    f = torch.randn(2, 5, NUM_FEATURES)
    f[:, :, 2 * NUM_KEYPOINTS:3 * NUM_KEYPOINTS] = 1.0
    r = torch.randn(2, 5, 2)
    up, lo = keypoint_parts(f, r)
    assert up.shape[-1] == len(UPPER_KEYPOINTS) * KEYPOINT_CHANNELS + GLOBAL_KEYPOINT_CHANNELS
    assert lo.shape[-1] == len(LOWER_KEYPOINTS) * KEYPOINT_CHANNELS + GLOBAL_KEYPOINT_CHANNELS
    k = UPPER_KEYPOINTS[3]
    np.testing.assert_allclose(up[..., 3 * 5:3 * 5 + 2].numpy(),
                               f[..., 2 * k:2 * k + 2].numpy())
    np.testing.assert_allclose(up[:, 1:, 3 * 5 + 3:3 * 5 + 5].numpy(),
                               (f[:, 1:, 2 * k:2 * k + 2] - f[:, :-1, 2 * k:2 * k + 2]).numpy(),
                               atol=1e-6)
    np.testing.assert_allclose(up[..., -2:].numpy(), r.numpy())


def test_windowed_inference_stitches_window_outputs():
    """A sequence longer than the window: every frame is the output of the window where it
    lies nearest the centre; a window-long sequence is one window; a short one is padded."""
    model = _model()
    g = torch.Generator().manual_seed(0)
    from mocap_lifter.features import NUM_FEATURES
    t = 75
    f = torch.randn(1, t, NUM_FEATURES, generator=g)
    f[..., 2 * NUM_KEYPOINTS:3 * NUM_KEYPOINTS] = 1.0
    r = 0.1 * torch.randn(1, t, 2, generator=g)
    with torch.no_grad():
        out = model(f, r, torch.ones(1, t))
        lengths = out['lengths']
        assert out['positions'].shape == (1, t, NUM_JOINTS, 3)
        # frame 40: windows start 0, 16, 32, 43 -> 32 (centre 47.5 - 40 = 7.5) vs 16 (8.5)
        w = model.window_forward(f[:, 32:64], r[:, 32:64], lengths)
        np.testing.assert_allclose(out['positions'][0, 40].numpy(),
                                   w['positions'][0, 8].numpy(), atol=1e-5)
        last = model.window_forward(f[:, 43:], r[:, 43:], lengths)
        np.testing.assert_allclose(out['positions'][0, -1].numpy(),
                                   last['positions'][0, -1].numpy(), atol=1e-5)
        one = model(f[:, :32], r[:, :32], torch.ones(1, 32))
        np.testing.assert_allclose(one['positions'].numpy(),
                                   model.window_forward(f[:, :32], r[:, :32])['positions']
                                   .numpy(), atol=1e-6)
        short = model(f[:, :10], r[:, :10], torch.ones(1, 10))
        assert short['positions'].shape == (1, 10, NUM_JOINTS, 3)
        assert torch.isfinite(short['positions']).all()
        # one symmetric skeleton from the bone ratios
        sk = Skeleton.from_group_lengths(out['lengths'][0].double().numpy())
        assert sk.is_symmetric(atol=1e-9)


def test_online_lifter_runs_vtm_windowed_only():
    from mocap_core.camera import CameraIntrinsics
    from mocap_lifter.online import OnlineLifter
    model = _model()
    with pytest.raises(ValueError):
        OnlineLifter(model, 'causal')
    online = OnlineLifter(model, 'windowed', skeleton_frames=20)
    assert online.latency == model.cfg.window // 2
    intr = CameraIntrinsics.from_fov(640, 480, 60.0)
    rng = np.random.default_rng(0)
    base = np.column_stack([rng.uniform(250, 390, NUM_KEYPOINTS),
                            rng.uniform(100, 400, NUM_KEYPOINTS), np.ones(NUM_KEYPOINTS)])
    stamps, got = [], []
    for i in range(50):
        kp = base.copy()
        kp[:, :2] += rng.normal(0, 2, (NUM_KEYPOINTS, 2))
        stamps.append(1_000 + i * 33_333_333)
        frames, event = online.push(stamps[-1], kp, intr)
        assert event == ''
        got += frames
    assert len(got) == 50 - online.latency
    got += online.flush()
    assert [f.stamp_ns for f in got] == stamps
    assert all(np.all(np.isfinite(f.pose.joint_positions())) for f in got)
    assert got[-1].skeleton_fixed and not got[0].skeleton_fixed


def test_load_weights_refuses_causal_vtm(tmp_path):
    from mocap_lifter.weights import load_vtm, load_weights, save_vtm
    model = _model()
    path = tmp_path / 'vtm.pt'
    save_vtm(model, path, {'stage': 'test'})
    with pytest.raises(ValueError, match='windowed only'):
        load_weights(path, causal=True)
    again = load_weights(path)
    assert isinstance(again, VTM)
    assert torch.equal(again.virtual_lengths, model.virtual_lengths.half().float())
    from mocap_lifter.model import LifterConfig, MotioNet
    from mocap_lifter.weights import save_weights
    save_weights(MotioNet(LifterConfig(channels=16, fusion_blocks=1, skeleton_channels=8)),
                 tmp_path / 'm.pt')
    with pytest.raises(ValueError, match='no VTM weights'):
        load_vtm(tmp_path / 'm.pt')


def test_two_training_stages_reduce_their_losses_and_resume(tmp_path):
    """Stage tpmae on motion alone, then tpve jointly from its weights: each stage's loss on
    the same validation windows goes down; a finished stage resumes without training."""
    from mocap_lifter.training.vtm_train import VTMTrainConfig, train_stage
    from mocap_lifter.weights import load_vtm
    train = [_motion(90, seed=i, name=f'walk{i}') for i in range(3)]
    val = [_motion(90, seed=10, name='val')]
    model_cfg = dict(SMALL)
    cfg = VTMTrainConfig.from_dict({'stage': 'tpmae', 'steps': 40, 'batch': 8, 'lr': 3e-3,
                                    'validate_every': 20, 'checkpoint_every': 20,
                                    'model': model_cfg})
    w1 = train_stage(train, val, tmp_path / 'tpmae', cfg, progress=False)
    rows = (tmp_path / 'tpmae' / 'log.csv').read_text().splitlines()
    val_loss = [float(r.split(',')[2]) for r in rows[1:] if ',val,' in r]
    assert len(val_loss) == 2 and val_loss[-1] < val_loss[0]
    m1 = load_vtm(w1)
    assert np.allclose(m1.virtual_lengths.numpy(),
                       Skeleton.default().group_lengths(), atol=1e-3)  # float16 storage
    cfg2 = VTMTrainConfig.from_dict({'stage': 'tpve', 'steps': 40, 'batch': 8, 'lr': 3e-3,
                                     'validate_every': 20, 'checkpoint_every': 20,
                                     'init': str(w1)})
    w2 = train_stage(train, val, tmp_path / 'tpve', cfg2, progress=False)
    rows = (tmp_path / 'tpve' / 'log.csv').read_text().splitlines()
    header = rows[0].split(',')
    vals = [dict(zip(header, r.split(','))) for r in rows[1:] if ',val,' in r]
    assert float(vals[-1]['loss']) < float(vals[0]['loss'])
    assert float(vals[-1]['ma']) > 0
    m2 = load_vtm(w2)
    # the TPMAE was trained jointly: its weights moved
    assert not torch.equal(m1.dec_u.net[0].weight, m2.dec_u.net[0].weight)
    mtime = (tmp_path / 'tpve' / 'last.pt').stat().st_mtime
    train_stage(train, val, tmp_path / 'tpve', cfg2, progress=False)   # resumes: done
    assert (tmp_path / 'tpve' / 'last.pt').stat().st_mtime == mtime


def test_reprojection_root_recovers_the_root_from_exact_keypoints():
    """Lifted joints relative to the root + their exact projections: the least-squares root
    is the true root, even from a prior 0.5 m off; unseen keypoints do not count."""
    from mocap_lifter.features import NUM_FEATURES
    from mocap_lifter.vtm import reprojection_root
    from mocap_core.skeleton import JOINT_INDEX, KEYPOINT_NAMES
    m = _motion(6)
    sk = Skeleton.default()
    rel = forward_kinematics(sk.parents, sk.offsets, m.rotations, np.zeros((6, 3))).positions
    true_root = np.array([0.3, -0.2, 4.0]) + np.linspace(0, 0.5, 6)[:, None]
    cam = rel + true_root[:, None]
    feats = np.zeros((6, NUM_FEATURES))
    root_2d = true_root[:, :2] / true_root[:, 2:]
    s = 0.07
    for k, name in enumerate(KEYPOINT_NAMES):
        if name in JOINT_INDEX:
            p = cam[:, JOINT_INDEX[name]]
            feats[:, 2 * k:2 * k + 2] = (p[:, :2] / p[:, 2:] - root_2d) / s
            feats[:, 2 * NUM_KEYPOINTS + k] = 1.0
    feats[:, 3 * NUM_KEYPOINTS + 2] = np.log(s)
    # a wrong keypoint that is marked unseen must not matter
    feats[:, 2 * KEYPOINT_INDEX['left_wrist']] += 5.0
    feats[:, 2 * NUM_KEYPOINTS + KEYPOINT_INDEX['left_wrist']] = 0.0
    prior = true_root + np.array([0.0, 0.0, 0.5])
    t = lambda x: torch.as_tensor(x[None], dtype=torch.float64)  # noqa: E731
    out = reprojection_root(t(rel), t(feats), t(root_2d), t(prior), 1e-4)[0].numpy()
    np.testing.assert_allclose(out, true_root, atol=2e-3)
    # no keypoint seen: the prior
    feats[:, 2 * NUM_KEYPOINTS:3 * NUM_KEYPOINTS] = 0.0
    out = reprojection_root(t(rel), t(feats), t(root_2d), t(prior), 1e-4)[0].numpy()
    np.testing.assert_allclose(out, prior, atol=1e-9)
