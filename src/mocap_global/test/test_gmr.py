"""Unit tests of GMR: accumulation (eq. 2-4), flip augmentation, features, model, metrics,
the online accumulation and the static-camera fusion (no ROS, no training)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from mocap_core.data.motion import Motion
from mocap_core.pose import Pose
from mocap_core.rotations import axis_angle_to_matrix, matrix_to_quat, quat_to_matrix
from mocap_core.skeleton import CONTACT_POINT_NAMES, NUM_JOINTS, Skeleton

from mocap_global import features as F
from mocap_global.model import GMR, GMRConfig, TTA_MODES, reverse_padded, with_tta
from mocap_global.inference import NumpyGMR
from mocap_global.online import INFERENCE_ENGINES, OnlineGMR, StaticCameraFusion, prepare_outputs
from mocap_global.se3 import (accumulate, align_yaw_translation, compose_steps, invert_motion,
                              relative_motion, time_reverse_motion, tilt_rotation, up_in_body)
from mocap_global.training import metrics as M
from mocap_global.training.samples import Augmentation, WindowSampler
from mocap_global.training.train import TrainConfig, losses, total_loss
from mocap_global.weights import default_weights, load_weights, save_weights

EZ = np.array([0.0, 0.0, 1.0])


def rz(a):
    return axis_angle_to_matrix(np.asarray(a, dtype=np.float64)[..., None] * EZ)


def circle_walk(frames=90, radius=2.0, turn=0.05, pitch_deg=4.0):
    """A body walking counter-clockwise on a circle, facing along the tangent, with a pelvis
    pitch oscillation: R_i, T_i."""
    i = np.arange(frames)
    yaw = turn * i
    pitch = np.radians(pitch_deg) * np.sin(0.3 * i)
    R = rz(yaw) @ axis_angle_to_matrix(pitch[:, None] * np.array([0.0, 1.0, 0.0]))
    T = np.stack([radius * np.sin(yaw), radius * (1 - np.cos(yaw)), 0.9 + 0.02 * np.sin(0.6 * i)],
                 axis=-1)
    return R, T


def test_accumulation_reproduces_a_known_trajectory():
    R, T = circle_walk()
    dR, dT = relative_motion(R, T)
    # body-frame motion of a uniform circle without pitch: constant, analytic
    R0, T0 = circle_walk(pitch_deg=0.0)
    T0[:, 2] = 0.9
    dR0, dT0 = relative_motion(R0, T0)
    w, r = 0.05, 2.0
    np.testing.assert_allclose(dR0, np.broadcast_to(rz(w), dR0.shape), atol=1e-12)
    np.testing.assert_allclose(dT0, np.broadcast_to([r * np.sin(w), r * (1 - np.cos(w)), 0.0],
                                                    dT0.shape), atol=1e-12)
    # eq. 3-4 from the first pose give the whole trajectory back
    Ra, Ta = accumulate(R[0], T[0], dR, dT)
    np.testing.assert_allclose(Ta, T, atol=1e-9)
    np.testing.assert_allclose(Ra, R, atol=1e-9)
    # the motion does not depend on the world frame (camera agnostic)
    C = axis_angle_to_matrix(np.array([0.3, -1.2, 0.7]))
    dR2, dT2 = relative_motion(C @ R, T @ C.T + np.array([5.0, -2.0, 1.0]))
    np.testing.assert_allclose(dR2, dR, atol=1e-12)
    np.testing.assert_allclose(dT2, dT, atol=1e-12)


def test_accumulation_by_hand():
    # 1 m forward, then turn 90 deg left while stepping 1 m forward: ends at (1, 1)
    dR = np.stack([np.eye(3), rz(np.pi / 2)])
    dT = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    R, T = accumulate(np.eye(3), np.zeros(3), dR, dT)
    dR2 = np.stack([rz(0.0)])
    R2, T2 = accumulate(R[-1], T[-1], dR2, np.array([[1.0, 0.0, 0.0]]))
    np.testing.assert_allclose(T2[-1], [1.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(R2[-1], rz(np.pi / 2), atol=1e-12)


def test_time_reversal_inverts_the_motion():
    R, T = circle_walk(40)
    dR, dT = relative_motion(R, T)
    rR, rT = relative_motion(R[::-1], T[::-1])
    fR, fT = time_reverse_motion(dR, dT)
    np.testing.assert_allclose(fR, rR, atol=1e-12)
    np.testing.assert_allclose(fT, rT, atol=1e-12)
    # dG'_i dG_{F-2-i} = I
    n = len(dR)
    for i in range(n):
        Rc = fR[i] @ dR[n - 1 - i]
        Tc = fR[i] @ dT[n - 1 - i] + fT[i]
        np.testing.assert_allclose(Rc, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(Tc, 0.0, atol=1e-12)
    iR, iT = invert_motion(dR[:1], dT[:1])
    np.testing.assert_allclose(iR[0] @ dR[0], np.eye(3), atol=1e-12)


def _motion(R, T, frames=None, seed=0) -> Motion:
    rng = np.random.default_rng(seed)
    n = len(R)
    rot = np.zeros((n, NUM_JOINTS, 4))
    rot[..., 3] = 1.0
    rot[:, 0] = matrix_to_quat(R)
    rot[:, 1:] = matrix_to_quat(axis_angle_to_matrix(
        0.2 * rng.standard_normal((n, NUM_JOINTS - 1, 3))))
    return Motion('synthetic', 30.0, Skeleton.default(), rot, T, np.zeros((n, 4), bool))


def test_sampler_flip_augmentation_targets_are_the_reversed_motion():
    R, T = circle_walk(30)
    m = _motion(R, T)
    aug = Augmentation(reverse_prob=1.0, mirror_prob=0.0, scale_range=0.0, noise_prob=0.0,
                       short_prob=0.0)
    s = WindowSampler([m], 30, 30.0, 0, aug)
    b = s.batch(1)
    dR, dT = relative_motion(R, T)
    fR, fT = time_reverse_motion(dR, dT)
    np.testing.assert_allclose(b['dR'][0], fR, atol=1e-5)
    np.testing.assert_allclose(b['dT'][0], fT, atol=1e-5)
    # accumulated from the last pose, the flipped targets retrace the trajectory backwards
    Rb, Tb = accumulate(R[-1], T[-1], b['dR'][0].astype(np.float64), b['dT'][0].astype(np.float64))
    np.testing.assert_allclose(Tb[::-1], T, atol=1e-4)
    # the input features are the local poses in reverse order
    fwd = F.gmr_features(m.rotations, m.skeleton.group_lengths())
    np.testing.assert_allclose(b['features'][0], fwd[::-1], atol=1e-6)
    s.pose_input = 'positions'
    s.rng = np.random.default_rng(0)
    b = s.batch(1)
    fwd = F.gmr_features(m.rotations, m.skeleton.group_lengths(), pose_input='positions')
    np.testing.assert_allclose(b['features'][0], fwd[::-1], atol=1e-5)


def test_mirror_augmentation_mirrors_the_motion():
    R, T = circle_walk(20)
    m = _motion(R, T)
    rot = F.mirror_rotations(m.rotations)
    Rm = quat_to_matrix(rot[:, 0])
    dR, dT = relative_motion(R, T)
    dRm, dTm = relative_motion(Rm, F.mirror_vectors(T))
    S = np.diag([1.0, -1.0, 1.0])
    np.testing.assert_allclose(dRm, S @ dR @ S, atol=1e-12)
    np.testing.assert_allclose(dTm, dT @ S, atol=1e-12)
    # mirroring twice is the identity (up to quaternion sign)
    twice = F.mirror_rotations(rot)
    np.testing.assert_allclose(quat_to_matrix(twice), quat_to_matrix(m.rotations), atol=1e-12)


def test_compose_steps_is_the_subsampled_motion():
    R, T = circle_walk(31)
    dR, dT = relative_motion(R, T)
    cR, cT = compose_steps(dR, dT, 3)
    sR, sT = relative_motion(R[::3], T[::3])
    np.testing.assert_allclose(cR, sR, atol=1e-12)
    np.testing.assert_allclose(cT, sT, atol=1e-12)


def test_features_and_noise():
    R, T = circle_walk(50)
    m = _motion(R, T)
    f = F.gmr_features(m.rotations, m.skeleton.group_lengths())
    assert f.shape == (50, F.num_features('none')) and f.dtype == np.float32
    q = f[:, :F.NUM_POSE_FEATURES].reshape(50, NUM_JOINTS - 1, 4)
    assert np.all(q[..., 3] >= 0)                    # one code per rotation
    f_up = F.gmr_features(m.rotations, m.skeleton.group_lengths(), up_in_body(R), 'up')
    assert f_up.shape == (50, F.num_features('up'))
    with pytest.raises(ValueError):
        F.gmr_features(m.rotations, m.skeleton.group_lengths(), None, 'up')
    with pytest.raises(ValueError):
        F.gmr_features(m.rotations[:, :10], m.skeleton.group_lengths())
    noisy = F.noisy_local_pose(m.rotations, np.random.default_rng(0))
    np.testing.assert_allclose(noisy[:, 0], m.rotations[:, 0])
    from mocap_core.rotations import quat_angle
    ang = np.degrees(quat_angle(noisy[:, 1:], m.rotations[:, 1:]))
    assert 5.0 < ang.mean() < 25.0
    # joints in the root frame: the root at the origin, the rest pose offsets at identity
    p = F.body_joint_positions(m.skeleton.offsets, np.tile(np.array([0, 0, 0, 1.0]),
                                                           (2, NUM_JOINTS, 1)))
    np.testing.assert_allclose(p[0], m.skeleton.rest_positions(), atol=1e-12)


def _small_model(**kw) -> GMR:
    torch.manual_seed(0)
    return GMR(GMRConfig(**{**dict(layers=1, hidden=16, projection=16, window=24), **kw})).eval()


def test_model_shapes_padding_and_weights_roundtrip(tmp_path):
    model = _small_model()
    x = torch.randn(3, 24, model.cfg.num_features)
    lengths = torch.tensor([24, 10, 5])
    with torch.no_grad():
        out = model(x, lengths)
        assert out['axis_angle'].shape == (3, 24, 3) and out['rotation'].shape == (3, 24, 3, 3)
        assert torch.allclose(out['up'].norm(dim=-1), torch.ones(3, 24))
        # a padded sequence gives the same output as the sequence alone
        alone = model(x[1:2, :10])
        assert torch.allclose(alone['translation'][0], out['translation'][1, :10], atol=1e-6)
        # the fused inference kernel gives the same result as the training path
        with torch.enable_grad():
            slow = model(x)['translation']
        assert torch.allclose(model(x)['translation'], slow, atol=1e-6)
    save_weights(model, tmp_path / 'w.pt', {'note': 'test'})
    again = load_weights(tmp_path / 'w.pt')
    with torch.no_grad():
        assert torch.allclose(again(x)['translation'], model(x)['translation'])
    assert again.info == {'note': 'test'}
    (tmp_path / 'bad.pt').write_bytes(b'not weights')
    with pytest.raises(ValueError):
        load_weights(tmp_path / 'bad.pt')


@pytest.mark.parametrize('pose_input', ['quat', 'positions'])
def test_test_time_augmentation_is_mirror_and_time_reversal_equivariant(pose_input):
    """Mirrored features are the features of the mirrored motion; with 'mirror' or 'both'
    the model's motion of a mirrored sequence is exactly the mirrored motion, with 'reverse'
    or 'both' the rotation of a reversed sequence is exactly the inverted, reordered one; the
    padding of a batch does not change the augmented output either."""
    R, T = circle_walk(20)
    m = _motion(R, T)
    gl = m.skeleton.group_lengths()
    model = _small_model(pose_input=pose_input)
    f = torch.as_tensor(F.gmr_features(m.rotations, gl, pose_input=pose_input))
    fm = torch.as_tensor(F.gmr_features(F.mirror_rotations(m.rotations), gl,
                                        pose_input=pose_input))
    assert torch.allclose(model.mirror_features(f), fm, atol=1e-5)
    assert torch.allclose(model.mirror_features(model.mirror_features(f)), f)
    axial = torch.tensor([-1.0, 1.0, -1.0])
    polar = torch.tensor([1.0, -1.0, 1.0])
    with torch.no_grad():
        for tta in TTA_MODES:
            a, b = model(f[None], tta=tta), model(fm[None], tta=tta)
            err = (b['axis_angle'] * axial - a['axis_angle'])[:, :-1].abs().max()
            if tta in ('mirror', 'both'):
                assert err < 1e-5, tta
                assert torch.allclose(b['translation'] * polar, a['translation'], atol=1e-5)
                assert torch.allclose(b['up'] * polar, a['up'], atol=1e-5)
            else:
                assert err > 1e-3, tta          # the plain network is not symmetric
            r = model(f.flip(0)[None], tta=tta)
            back = -r['axis_angle'][0, :-1].flip(0)
            err = (back - a['axis_angle'][0, :-1]).abs().max()
            assert (err < 1e-5) if tta in ('reverse', 'both') else (err > 1e-3), tta
        x = torch.stack([f, torch.cat([f[:12], torch.zeros(8, f.shape[1])])])
        batch = model(x, torch.tensor([20, 12]), tta='both')
        alone = model(f[None, :12], tta='both')
        assert torch.allclose(batch['axis_angle'][1, :11], alone['axis_angle'][0, :11],
                              atol=1e-5)
        assert torch.allclose(with_tta(model, 'both')(f[None])['translation'],
                              model(f[None], tta='both')['translation'])
    assert with_tta(model, 'none') is model
    from mocap_global.training.cli import TTA_CHOICES
    assert TTA_CHOICES == TTA_MODES                     # `mocap eval gmr --tta` offers them all
    with pytest.raises(ValueError, match='tta'):
        model(f[None], tta='sideways')
    # reverse_padded is its own inverse and keeps the padding in place
    lengths = torch.tensor([20, 12])
    assert torch.equal(reverse_padded(reverse_padded(x, lengths), lengths), x)
    assert torch.equal(reverse_padded(x, lengths)[1, 12:], x[1, 12:])


def test_paper_configuration():
    cfg = GMRConfig.paper()
    assert (cfg.layers, cfg.hidden, cfg.projection, cfg.fps) == (4, 2048, 2048, 10.0)
    small = GMR(GMRConfig(layers=1, hidden=8, projection=8, velocity_input=False,
                          skeleton_input=False, pose_input='quat'))
    assert small.cfg.num_features == F.NUM_POSE_FEATURES
    R, T = circle_walk(12)
    m = _motion(R, T)
    x = F.gmr_features(m.rotations, m.skeleton.group_lengths(), skeleton_input=False)
    with torch.no_grad():
        assert small(torch.as_tensor(x[None]))['translation'].shape == (1, 12, 3)


def test_losses_vanish_at_the_ground_truth_and_train_down():
    R, T = circle_walk(40)
    m = _motion(R, T)
    s = WindowSampler([m, _motion(R[::-1].copy(), T[::-1].copy(), seed=1)], 24, 30.0, 0,
                      Augmentation(noise_prob=0.0), pose_input='positions')
    b = {k: torch.as_tensor(v) for k, v in s.batch(4).items()}
    cfg = TrainConfig()
    perfect = {'rotation': torch.cat([b['dR'], b['dR'][:, -1:]], 1),
               'translation': torch.cat([b['dT'], b['dT'][:, -1:]], 1), 'up': b['up']}
    terms = losses(perfect, b, cfg)
    assert all(float(v) < 1e-8 for k, v in terms.items() if k != 'smooth')
    model = _small_model()
    opt = torch.optim.Adam(model.parameters(), 3e-3)
    first = None
    for _ in range(60):
        out = model(b['features'], b['lengths'])
        loss = total_loss(losses(out, b, cfg), cfg)
        first = first if first is not None else float(loss.detach())
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert float(loss.detach()) < 0.5 * first


def test_motion_metrics():
    R, T = circle_walk(91)
    dR, dT = relative_motion(R, T)
    assert M.ome_deg(dR, dR).max() < 1e-6 and M.tme_mm(dT, dT).max() == 0
    err = rz(np.radians(1.0))
    np.testing.assert_allclose(M.ome_deg(dR @ err, dR), 1.0, atol=1e-9)
    np.testing.assert_allclose(M.tme_mm(dT + [0.002, 0, 0], dT), 2.0, atol=1e-9)
    joints = np.zeros((90, 2, 3))
    np.testing.assert_allclose(M.jme_mm(dR, dT + [0, 0.003, 0], dR, dT, joints), 3.0)
    # on a straight walk a constant 1 mm/frame error drifts 30 mm per second
    Rs = np.broadcast_to(np.eye(3), (91, 3, 3)).copy()
    Ts = np.stack([0.04 * np.arange(91), np.zeros(91), np.full(91, 0.9)], axis=-1)
    sR, sT = relative_motion(Rs, Ts)
    d = M.drift_mm(sR, sT + np.array([0.001, 0.0, 0.0]), Rs, Ts, [30, 60], 30)
    assert len(d[30]) == 3 and len(d[60]) == 2
    np.testing.assert_allclose(d[30], 30.0, rtol=1e-6)
    traj = M.trajectory_errors(dR, dT, R, T)
    assert traj['rte_pct'] < 1e-9 and traj['ate_mm'] < 1e-6
    Rz, t = align_yaw_translation(T, T @ rz(0.7).T + [1.0, 2.0, 0.0])
    np.testing.assert_allclose(Rz, rz(0.7), atol=1e-12)


@pytest.mark.parametrize('cfg', [dict(layers=2, velocity_input=True),
                                 dict(layers=1, velocity_input=False, pose_input='quat')])
def test_numpy_inference_is_the_network(cfg):
    """NumpyGMR = the PyTorch pass to float32 rounding, for one window and a batch; the
    shipped weights too; an augmented model is refused."""
    model = _small_model(**cfg)
    engine = NumpyGMR(model)
    shipped = load_weights(default_weights())
    rng = np.random.default_rng(1)
    for net, eng, shape in ((model, engine, (1, 24)), (model, engine, (3, 17)),
                            (shipped, NumpyGMR(shipped), (2, shipped.cfg.window))):
        x = rng.normal(size=shape + (net.cfg.num_features,)).astype(np.float32)
        with torch.no_grad():
            ref = {k: v.double().numpy() for k, v in net(torch.as_tensor(x)).items()}
        got = eng(x)
        assert set(got) == set(ref)
        for k in ref:
            assert got[k].shape == ref[k].shape and got[k].dtype == np.float64
            np.testing.assert_allclose(got[k], ref[k], atol=2e-6, err_msg=k)
    # weights changed in place after the copy are copied again before the next pass
    x = rng.normal(size=(1, 24, model.cfg.num_features)).astype(np.float32)
    before = engine(x)['translation']
    with torch.no_grad():
        model.regression.bias.add_(0.25)
        ref = model(torch.as_tensor(x))['translation'].double().numpy()
    after = engine(x)['translation']
    assert np.abs(after - before).max() > 1e-3
    np.testing.assert_allclose(after, ref, atol=2e-6)
    with pytest.raises(TypeError):
        NumpyGMR(with_tta(model, 'mirror'))
    with pytest.raises(ValueError, match='features'):
        engine(np.zeros((1, 24, 5), np.float32))


def test_online_engines_give_the_same_frames():
    """OnlineGMR with the NumPy engine emits the PyTorch engine's frames; an augmented model
    runs on PyTorch; an unknown engine is refused."""
    model = _small_model()
    poses = _poses(50)
    runs = {}
    for engine in INFERENCE_ENGINES:
        online = OnlineGMR(model, lookahead=5, inference=engine)
        assert online.inference == engine
        frames = []
        for i, p in enumerate(poses):
            frames += online.push(i * 33_333_333, p)[0]
        runs[engine] = frames + online.flush()
    assert len(runs['numpy']) == len(runs['torch']) == 50
    for a, b in zip(runs['numpy'], runs['torch']):
        np.testing.assert_allclose(a.pose.root_position, b.pose.root_position, atol=1e-5)
        np.testing.assert_allclose(a.pose.rotations, b.pose.rotations, atol=1e-5)
    assert OnlineGMR(with_tta(model, 'mirror'), lookahead=5).inference == 'torch'
    with pytest.raises(ValueError, match='inference'):
        OnlineGMR(model, lookahead=5, inference='onnx')


def _poses(n=40, seed=0):
    R, T = circle_walk(n)
    m = _motion(R, T, seed=seed)
    return [Pose(m.skeleton, r, t) for r, t in zip(m.rotations, m.root_positions)]


def test_online_start_up_flush_gap_and_bad_input():
    model = _small_model()
    online = OnlineGMR(model, lookahead=5, max_gap_s=0.2)
    assert online.frames_needed() == 6
    poses = _poses(40)
    stamps = [int(i * 1e9 / 30) for i in range(40)]
    out = []
    for i in range(5):
        frames, event = online.push(stamps[i], poses[i])
        assert frames == [] and event == ''          # waiting for look-ahead
    frames, _ = online.push(stamps[5], poses[5])
    assert len(frames) == 1 and frames[0].first and frames[0].stamp_ns == stamps[0]
    out += frames
    first = frames[0].pose
    # gravity-aligned first pose: heading 0, the lowest contact point on the floor
    assert min(p[2] for p in first.contact_positions().values()) == pytest.approx(0, abs=1e-9)
    Rf = quat_to_matrix(first.rotations[0])
    assert abs(np.arctan2(Rf[1, 0], Rf[0, 0])) < 1e-3     # minimal tilt: no turn about z
    for i in range(6, 20):
        out += online.push(stamps[i], poses[i])[0]
    # a gap: the waiting frames come out, then the accumulation restarts
    frames, event = online.push(stamps[19] + int(0.5e9), poses[20])
    assert event == 'gap' and len(frames) == 5
    out += frames
    assert online.segments == 1 and online.pending() == 1
    out += online.flush()
    assert [f.stamp_ns for f in out] == stamps[:20] + [stamps[19] + int(0.5e9)]
    assert out[-1].first and online.segments == 2
    assert all(np.all(np.isfinite(f.pose.root_position)) for f in out)
    # the world pose keeps the input's local pose
    np.testing.assert_allclose(out[3].pose.rotations[1:], poses[3].rotations[1:], atol=1e-12)
    # bad input: another joint set, NaN
    sk = Skeleton(np.zeros((3, 3)), joint_names=('pelvis', 'a', 'b'), parents=(-1, 0, 1))
    with pytest.raises(ValueError, match='joint set does not match'):
        online.push(stamps[-1] + 10**9, Pose(sk, np.tile([0, 0, 0, 1.0], (3, 1)), np.zeros(3)))
    with pytest.raises(ValueError, match='lookahead'):
        OnlineGMR(model, lookahead=30)


def test_online_pure_accumulation_matches_the_network_motions():
    """With look-ahead = the rest of a short stream, OnlineGMR = eq. 3-4 over the outputs."""
    model = _small_model()
    poses = _poses(20)
    online = OnlineGMR(model, lookahead=19)
    frames = []
    for i, p in enumerate(poses):
        frames += online.push(i * 33_333_333, p)[0]
    frames += online.flush()
    x = torch.as_tensor(np.stack([F.features_for(model.cfg, p.rotations[None],
                                                 p.skeleton.group_lengths())[0]
                                  for p in poses])[None])
    with torch.no_grad():
        out = model(x)
    R0 = quat_to_matrix(frames[0].pose.rotations[0])
    R, T = accumulate(R0, frames[0].pose.root_position, out['rotation'][0, :-1].double().numpy(),
                      out['translation'][0, :-1].double().numpy())
    np.testing.assert_allclose(np.stack([f.pose.root_position for f in frames]), T, atol=1e-6)
    np.testing.assert_allclose(R0, tilt_rotation(out['up'][0, 0].double().numpy()), atol=1e-6)


def _between(a: Pose, b: Pose, t: float) -> Pose:
    from mocap_core.rotations import quat_slerp
    return Pose(b.skeleton, quat_slerp(a.rotations, b.rotations, t),
                (1 - t) * a.root_position + t * b.root_position)


@pytest.mark.parametrize('floor_input', [False, True])
def test_frames_missing_from_the_stream_are_filled_in_at_the_network_rate(floor_input):
    """network_rate_hz: a stream with frames dropped gives, at the frames received, exactly
    what the full stream gives when the dropped frames were the interpolation of their
    neighbours (the filled-in frames run through the network, the accumulation and the foot
    lock, and never come out); without the fill the same stream reads the motion too fast."""
    model = _small_model()
    period = 33_333_333
    poses = _poses(60)
    kept = [i for i in range(60) if i % 3 == 0 or i in (1, 2, 40, 41, 50)]   # gaps of 1-2
    full = list(poses)
    for a, b in zip(kept, kept[1:]):            # the dropped frames: between their neighbours
        for i in range(a + 1, b):
            full[i] = _between(poses[a], poses[b], (i - a) / (b - a))
    kw = dict(lookahead=5, floor_input=floor_input, foot_lock=floor_input)

    def run(items, **more):
        online = OnlineGMR(model, **kw, **more)
        out = []
        for i, p in items:
            out += online.push(i * period, p)[0]
        return out + online.flush(), online

    reference, _ = run(enumerate(full))
    filled, online = run([(i, poses[i]) for i in kept], network_rate_hz=30.0)
    assert [f.stamp_ns for f in filled] == [i * period for i in kept]   # each once, in order
    assert online.filled_frames == 60 - len(kept) - (59 - kept[-1])
    assert online.pending() == 0 and not online._filled
    ref = {f.stamp_ns: f for f in reference}

    def worst(frames):
        return max(np.linalg.norm(f.pose.root_position - ref[f.stamp_ns].pose.root_position)
                   for f in frames)
    # the same up to the look-ahead: after a fill, a frame may be emitted from a network pass
    # that already sees the frames filled in after it (more than `lookahead` future frames);
    # read without the fill, the same frames put the body 10-200 times further off
    unfilled, plain = run([(i, poses[i]) for i in kept])
    assert plain.filled_frames == 0
    assert worst(unfilled) > 0.3 and worst(filled) < worst(unfilled) / 10
    # a long gap behind a long look-ahead: no more frames filled in than the window holds
    # besides the frames waiting, and none of those lost
    online = OnlineGMR(model, lookahead=20, max_gap_s=1.0, network_rate_hz=30.0)
    got, sent = [], [i * period for i in range(30)] + [29 * period + 12 * period]
    for k, stamp in enumerate(sent):
        got += online.push(stamp, poses[k])[0]
    got += online.flush()
    assert [f.stamp_ns for f in got] == sent
    assert 0 < online.filled_frames <= 11 and online.filled_frames == 24 - 1 - 20
    # a gap longer than max_gap_s is not filled: the accumulation restarts
    online = OnlineGMR(model, lookahead=2, max_gap_s=0.2, network_rate_hz=30.0)
    for i in range(5):
        online.push(i * period, poses[i])
    frames, event = online.push(4 * period + int(0.5e9), poses[5])
    assert event == 'gap' and online.filled_frames == 0
    with pytest.raises(ValueError, match='network_rate_hz'):
        OnlineGMR(model, network_rate_hz=-1.0)


def test_filled_frames_take_the_camera_anchor_between_their_neighbours():
    from mocap_global.online import InputAnchor, _anchor_between
    a = InputAnchor(True, rz(0.0), np.zeros(3), static=False)
    b = InputAnchor(True, rz(0.4), np.array([1.0, 0.0, 0.0]), static=False)
    m = _anchor_between(a, b, 0.25)
    np.testing.assert_allclose(m.rotation, rz(0.1), atol=1e-12)
    np.testing.assert_allclose(m.translation, [0.25, 0.0, 0.0])
    assert _anchor_between(a, InputAnchor(False), 0.5) is a          # another kind: the earlier
    assert _anchor_between(InputAnchor(True, static=True), b, 0.5).static
    assert _anchor_between(None, b, 0.5) is None


def test_several_people_in_one_network_pass_give_each_ones_own_frames():
    """add / prepare_outputs / take for three people (one joins later, so windows differ in
    length) = push each on their own; one pass per window length."""
    model = _small_model()
    streams = [_poses(60, seed=s) for s in range(3)]
    starts = [0, 0, 9]
    alone = [OnlineGMR(model, lookahead=5) for _ in streams]
    together = [OnlineGMR(model, lookahead=5) for _ in streams]
    out_alone = [[] for _ in streams]
    out_together = [[] for _ in streams]
    passes = []
    for i in range(60):
        stamp = i * 33_333_333
        active = [k for k in range(3) if i >= starts[k]]
        for k in active:
            out_alone[k] += alone[k].push(stamp, streams[k][i])[0]
            out_together[k] += together[k].add(stamp, streams[k][i])[0]
        passes.append(prepare_outputs([together[k] for k in active]))
        assert prepare_outputs([together[k] for k in active]) == 0     # cached
        for k in active:
            out_together[k] += together[k].take()
    # windows of 24 frames: until person 3's window is full there are two lengths
    assert passes[:5] == [0] * 5 and passes[5] == 1 and passes[20] == 2 and passes[-1] == 1
    for a, b in zip(out_alone, out_together):
        assert [f.stamp_ns for f in a] == [f.stamp_ns for f in b] and len(a) > 40
        for fa, fb in zip(a, b):
            np.testing.assert_allclose(fa.pose.root_position, fb.pose.root_position, atol=1e-5)
            np.testing.assert_allclose(fa.pose.rotations, fb.pose.rotations, atol=1e-5)


def test_static_camera_fusion_removes_drift():
    R, T = circle_walk(150, turn=0.02)                  # 1.2 m/s for 5 s
    dR, dT = relative_motion(R, T)
    biased = dT * 1.1                                   # a GMR that overestimates the speed
    C = axis_angle_to_matrix(np.array([1.9, 0.2, -0.4]))   # the input (camera) frame
    c = np.array([0.3, 1.0, 4.0])
    R_in, T_in = C.T @ R, (T - c) @ C                   # x_world = C x_in + c
    up = up_in_body(R)
    from mocap_global.training.evaluate import fuse_sequence
    _, T_gmr = fuse_sequence(R[0], T[0], dR, biased, up, R_in, T_in, None)
    for fusion in (StaticCameraFusion(30.0), StaticCameraFusion(30.0, input_up=C.T @ EZ)):
        _, T_f = fuse_sequence(R[0], T[0], dR, biased, up, R_in, T_in, fusion)
        assert fusion.ready
        # the world frame is gravity-aligned: W maps the input frame's up to +z
        np.testing.assert_allclose(fusion.W_R @ (C.T @ EZ), EZ, atol=1e-9)
        # a first-order filter: a lag of about bias speed x time constant remains
        assert M.ate_mm(T_f, T) < 0.5 * M.ate_mm(T_gmr, T)


def test_full_tilt_correction_follows_the_estimated_up():
    model = _small_model()
    online = OnlineGMR(model, lookahead=19, tilt_correction=1.0)
    poses = _poses(20)
    frames = []
    for i, p in enumerate(poses):
        frames += online.push(i * 33_333_333, p)[0]
    frames += online.flush()
    x = torch.as_tensor(np.stack([F.features_for(model.cfg, p.rotations[None],
                                                 p.skeleton.group_lengths())[0]
                                  for p in poses])[None])
    with torch.no_grad():
        up = model(x)['up'][0].double().numpy()
    R = quat_to_matrix(np.stack([f.pose.rotations[0] for f in frames]))
    np.testing.assert_allclose(up_in_body(R), up, atol=1e-5)


def test_floor_input_keeps_the_physics_height_and_tilt():
    """An input in a floor frame (the physics output): the world output's root height and
    tilt are the input's, every contact point as high above z = 0 as in the input; GMR
    still decides the heading and the horizontal path."""
    model = _small_model()
    poses = _poses(40)
    # a floor-frame input: lift each pose so its lowest contact point is 2 cm above z = 0,
    # and give it a tilt that changes over time
    lifted = []
    for i, p in enumerate(poses):
        tilt = axis_angle_to_matrix(np.array([0.1 * np.sin(i / 5), 0.05, 0.0]))
        rot = np.array(p.rotations)
        rot[0] = matrix_to_quat(tilt @ quat_to_matrix(rot[0]))
        q = Pose(p.skeleton, rot, p.root_position)
        low = min(c[2] for c in q.contact_positions().values())
        lifted.append(Pose(p.skeleton, rot, q.root_position + [0, 0, 0.02 - low]))
    runs = {}
    for floor in (False, True):
        online = OnlineGMR(model, lookahead=5, floor_input=floor)
        frames = []
        for i, p in enumerate(lifted):
            frames += online.push(i * 33_333_333, p)[0]
        frames += online.flush()
        runs[floor] = frames
    for f, p in zip(runs[True], lifted):
        assert f.pose.root_position[2] == pytest.approx(p.root_position[2], abs=1e-12)
        lows = [c[2] for c in f.pose.contact_positions().values()]
        assert min(lows) == pytest.approx(0.02, abs=1e-9)
        # the same tilt: the body's up axis makes the same angle with +z
        up_out = quat_to_matrix(f.pose.rotations[0])[2]
        up_in = quat_to_matrix(p.rotations[0])[2]
        assert up_out[2] == pytest.approx(up_in[2], abs=1e-9)
        # the published input frame in the world: a turn about z on the floor, and it maps
        # every input joint onto the output joint
        Rw, tw = f.input_rotation, f.input_translation
        np.testing.assert_allclose(Rw[2], [0, 0, 1], atol=1e-9)
        assert tw[2] == 0.0
        np.testing.assert_allclose(p.joint_positions() @ Rw.T + tw, f.pose.joint_positions(),
                                   atol=1e-9)
    # with a camera-frame input the transform is the general one (not a turn about z)
    for f, p in zip(runs[False], lifted):
        np.testing.assert_allclose(p.joint_positions() @ f.input_rotation.T
                                   + f.input_translation, f.pose.joint_positions(), atol=1e-9)
    # heading and horizontal path are GMR's: the same with and without the floor input
    from mocap_global.se3 import yaw_of
    for a, b in zip(runs[False], runs[True]):
        np.testing.assert_allclose(a.pose.root_position[:2], b.pose.root_position[:2],
                                   atol=1e-9)
        assert yaw_of(quat_to_matrix(a.pose.rotations[0])) == pytest.approx(
            yaw_of(quat_to_matrix(b.pose.rotations[0])), abs=1e-9)
    # without it, the accumulated height drifts away from the input's
    assert any(abs(a.pose.root_position[2] - p.root_position[2]) > 1e-3
               for a, p in zip(runs[False], lifted))


def test_floor_input_heading_offset_is_averaged_over_past_and_look_ahead():
    """With a floor input the world pose is the input pose turned about z by a heading
    offset. ``heading_smoothing`` h averages that offset (circular mean) over the frames
    k - n .. k + n, n = min(h, k, frames after k): the accumulation (GMR's own heading) is
    unchanged, the yaw noise of the input stays in the body, and a frame's offset is the
    centred mean of the per-frame offsets of the unsmoothed run (up to GMR's motion over the
    look-ahead, read from the window of frame k rather than from the later windows: within
    2 mrad here, against offsets that jitter by 50 mrad)."""
    from mocap_global.se3 import yaw_of
    model = _small_model()
    rng = np.random.default_rng(4)
    noisy = []
    for p in _poses(30):
        rot = np.array(p.rotations)
        rot[0] = matrix_to_quat(rz(0.05 * rng.normal()) @ quat_to_matrix(rot[0]))
        noisy.append(Pose(p.skeleton, rot, p.root_position))

    def offsets(h):
        online = OnlineGMR(model, lookahead=5, floor_input=True, heading_smoothing=h)
        frames = []
        for i, p in enumerate(noisy):
            frames += online.push(i * 33_333_333, p)[0]
        frames += online.flush()
        assert len(frames) == len(noisy)
        return np.array([yaw_of(quat_to_matrix(f.pose.rotations[0]))
                         - yaw_of(quat_to_matrix(p.rotations[0]))
                         for f, p in zip(frames, noisy)]), frames

    raw, frames0 = offsets(0)
    smooth, frames3 = offsets(3)
    for k in range(len(noisy)):
        n = min(3, k, len(noisy) - 1 - k)
        w = raw[k - n:k + n + 1]
        expected = np.arctan2(np.sin(w).mean(), np.cos(w).mean())
        assert np.angle(np.exp(1j * (smooth[k] - expected))) == pytest.approx(0.0, abs=2e-3)
    assert np.abs(np.angle(np.exp(1j * (smooth - raw)))).mean() > 0.01   # not the raw one
    # the per-frame offset jitters with the input's yaw noise; the averaged one much less
    wrap = np.unwrap
    assert np.abs(np.diff(wrap(smooth), 2)).mean() < 0.5 * np.abs(np.diff(wrap(raw), 2)).mean()
    # heights and tilts stay the input's
    for f, p in zip(frames3, noisy):
        assert f.pose.root_position[2] == pytest.approx(p.root_position[2], abs=1e-12)
    with pytest.raises(ValueError):
        OnlineGMR(model, floor_input=True, heading_smoothing=-1)


def test_heading_offset_reads_the_motion_into_each_later_frame():
    """``_heading_offset`` with known network motions: the window holds input poses facing
    +x, GMR turns by a different yaw into each frame (0.1, 0.2, 0.3, ... rad), so the offset
    of frame pos + m is yaw(R) plus the turns into frames pos + 1 .. pos + m. Reading the
    motion of the wrong frame (one off) would give another mean."""
    online = OnlineGMR(_small_model(), lookahead=3, floor_input=True, heading_smoothing=2)
    poses = _poses(6)
    facing = []
    for p in poses:
        rot = np.array(p.rotations)
        rot[0] = matrix_to_quat(np.eye(3))
        facing.append(Pose(p.skeleton, rot, p.root_position))
    online._poses.extend(facing)
    online._offsets.extend([0.05, 0.07])              # two earlier frames' offsets
    turns = np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    out = {'axis_angle': turns[:, None] * np.array([0.0, 0.0, 1.0])}
    pos = 2                                             # frames 3 and 4 lie ahead
    got = online._heading_offset(rz(0.3), out, pos)
    values = [0.3, 0.05, 0.07, 0.3 + turns[2], 0.3 + turns[2] + turns[3]]
    expected = np.arctan2(np.mean(np.sin(values)), np.mean(np.cos(values)))
    assert got == pytest.approx(expected, abs=1e-12)
    assert list(online._offsets)[-1] == pytest.approx(0.3)   # this frame's own offset kept


def test_position_input_is_the_root_frame_joints_and_ignores_leaf_twist():
    R, T = circle_walk(10)
    m = _motion(R, T)
    gl = m.skeleton.group_lengths()
    f = F.gmr_features(m.rotations, gl, pose_input='positions')
    assert f.shape == (10, F.num_features(pose_input='positions'))
    p = F.body_joint_positions(m.skeleton.offsets, m.rotations)[:, 1:].reshape(10, -1)
    np.testing.assert_allclose(f[:, :F.NUM_POSITION_FEATURES], p, atol=1e-6)
    twisted = np.array(m.rotations)
    wrist = list(m.skeleton.joint_names).index('left_wrist')
    twisted[:, wrist] = matrix_to_quat(axis_angle_to_matrix(np.array([1.0, 0.5, 0.0])))
    f2 = F.gmr_features(twisted, gl, pose_input='positions')
    np.testing.assert_allclose(f2, f, atol=1e-6)
    assert not np.allclose(F.gmr_features(twisted, gl), F.gmr_features(m.rotations, gl))


def _camera_views(poses, C, c, turn_rate=0.0):
    """The poses (world frame) as a camera sees them that stands at ``c`` with orientation
    ``C`` (x_world = C x_cam + c) and turns about its own y axis at ``turn_rate`` rad/frame;
    returns the camera-frame poses and the camera's rotation since the first frame
    (current camera -> first camera) per frame."""
    out, R0s = [], []
    for i, p in enumerate(poses):
        R0 = axis_angle_to_matrix(np.array([0.0, turn_rate * i, 0.0]))
        Ci = C @ R0                                       # world <- current camera
        rot = np.array(p.rotations)
        rot[0] = matrix_to_quat(Ci.T @ quat_to_matrix(p.rotations[0]))
        out.append(Pose(p.skeleton, rot, Ci.T @ (p.root_position - c)))
        R0s.append(R0)
    return out, R0s


def _fused_roots(poses, anchors=None, up=None):
    online = OnlineGMR(_small_model(), lookahead=3,
                       fusion=StaticCameraFusion(30.0, init_s=0.3, input_up=up))
    frames = []
    for i, p in enumerate(poses):
        frames += online.push(i * 33_333_333, p, None if anchors is None else anchors[i])[0]
    frames += online.flush()
    return online, np.stack([f.pose.root_position for f in frames]), frames


def test_a_turning_camera_is_fused_once_its_rotation_is_taken_out():
    """The network sees only local poses, so the GMR motion is the same whether the camera
    turns or not; with the camera's rotation as anchors the fused path is the static
    camera's, and a camera said to translate is not fused at all."""
    from mocap_global.online import InputAnchor

    poses = _poses(60)
    C = axis_angle_to_matrix(np.array([-1.7, 0.1, 0.2]))
    c = np.array([4.0, -1.0, 1.5])
    static, _ = _camera_views(poses, C, c)
    turning, R0s = _camera_views(poses, C, c, turn_rate=0.01)
    _, T_static, _ = _fused_roots(static)
    _, T_turn, _ = _fused_roots(turning, [InputAnchor(True, R) for R in R0s])
    np.testing.assert_allclose(T_turn, T_static, atol=1e-6)
    # without taking the rotation out, the turning camera's path is another one
    _, T_wrong, _ = _fused_roots(turning)
    assert np.abs(T_wrong - T_static).max() > 0.05
    # a translating camera: no frame fused, the path is GMR's own
    online, T_moving, frames = _fused_roots(turning, [InputAnchor(False)] * 60)
    assert not any(f.fused for f in frames) and online.unanchored_frames == 60
    plain = OnlineGMR(_small_model(), lookahead=3)
    ref = []
    for i, p in enumerate(turning):
        ref += plain.push(i * 33_333_333, p)[0]
    ref += plain.flush()
    np.testing.assert_allclose(T_moving, np.stack([f.pose.root_position for f in ref]),
                               atol=1e-9)


def test_the_fusion_aligns_again_after_the_camera_translated():
    """Static, then 20 frames of a translating camera, then static at a new place: the
    fusion stops, aligns itself again over init_s, and fuses the last frames."""
    from mocap_global.online import InputAnchor

    poses = _poses(60)
    C = axis_angle_to_matrix(np.array([-1.7, 0.1, 0.2]))
    first, _ = _camera_views(poses[:20], C, np.array([4.0, -1.0, 1.5]))
    later, _ = _camera_views(poses[20:], C, np.array([5.0, -0.5, 1.5]))
    anchors = [InputAnchor(True)] * 20 + [InputAnchor(False)] * 20 + [InputAnchor(True)] * 20
    online, T, frames = _fused_roots(first + later, anchors)
    fused = [f.fused for f in frames]
    # an unknown input up: 0.3 s (9 frames) of alignment first, then fused
    assert not any(fused[:9]) and all(fused[9:20]) and not any(fused[20:40])
    assert not fused[40] and all(fused[50:])            # 0.3 s to align again, then fused
    assert online.unanchored_frames == 20 and online.fusion.ready


def test_foot_lock_holds_the_standing_points_without_jumps():
    """Foot lock with a floor input: the points that stand (lower than ``lock_height``) in
    two consecutive frames do not move horizontally in the world output on average (one
    standing point: not at all), whichever points land or lift in between; while none
    stands, the root takes GMR's step."""
    poses = []
    for p in _poses(60, seed=3):
        low = min(c[2] for c in p.contact_positions().values())
        poses.append(Pose(p.skeleton, p.rotations, p.root_position - [0, 0, low]))

    def run(lock_height):
        online = OnlineGMR(_small_model(), lookahead=3, floor_input=True, foot_lock=True,
                           lock_height=lock_height)
        frames = []
        for i, p in enumerate(poses):
            frames += online.push(i * 33_333_333, p)[0]
        return frames + online.flush()

    frames = run(0.05)
    pts = np.array([[f.pose.contact_positions()[n] for n in CONTACT_POINT_NAMES]
                    for f in frames])                              # (F, 4, 3) world
    stand = pts[..., 2] < 0.05
    changes = 0
    for k in range(1, len(frames)):
        both = stand[k] & stand[k - 1]
        changes += int(np.any(stand[k] != stand[k - 1]))
        if both.any():
            moved = pts[k, both, :2] - pts[k - 1, both, :2]
            np.testing.assert_allclose(moved.mean(axis=0), 0.0, atol=1e-9)
            if both.sum() == 1:
                np.testing.assert_allclose(moved[0], 0.0, atol=1e-9)
    assert changes > 10                      # points did land and lift
    # nothing ever stands: GMR's path, as without the lock
    free = run(-1.0)
    online = OnlineGMR(_small_model(), lookahead=3, floor_input=True)
    plain = []
    for i, p in enumerate(poses):
        plain += online.push(i * 33_333_333, p)[0]
    plain += online.flush()
    np.testing.assert_allclose([f.pose.root_position for f in free],
                               [f.pose.root_position for f in plain], atol=1e-9)


def test_fused_floor_frames_follow_the_input_root_not_the_foot_lock():
    """A static camera with a floor input: with an instant position gain the fused world root
    is the input root (turned into the world), the foot lock does not hold GMR's drift."""
    from mocap_global.online import InputAnchor

    poses = _poses(50)
    fusion = StaticCameraFusion(30.0, position_time_constant_s=1e-9,
                                input_up=np.array([0.0, 0.0, 1.0]))
    online = OnlineGMR(_small_model(), lookahead=3, fusion=fusion, floor_input=True,
                       foot_lock=True)
    frames = []
    for i, p in enumerate(poses):
        frames += online.push(i * 33_333_333, p, InputAnchor(True))[0]
    frames += online.flush()
    assert all(f.fused for f in frames)
    T = np.stack([f.pose.root_position for f in frames])
    T_in = np.stack([p.root_position for p in poses])
    np.testing.assert_allclose(T, T_in @ fusion.W_R.T + fusion.W_t, atol=1e-6)


def test_sampler_lifted_inputs_follow_the_window_through_mirror_and_reversal():
    """With the 'lifted' poses equal to the truth, a lifted window's input is its target pose
    exactly, whatever mirror, reversal and scale did to the window; with other lifted poses
    the input is those poses of the same frames."""
    from mocap_global.training.lifted import LiftedClip

    R, T = circle_walk(90)
    clips = [_motion(R, T, seed=s) for s in range(3)]
    same = [LiftedClip(m.rotations[None].astype(np.float32),
                       m.skeleton.group_lengths()[None].astype(np.float32)) for m in clips]
    aug = Augmentation(lifted_prob=1.0, noise_prob=1.0)
    sampler = WindowSampler(clips, 24, 30.0, seed=3, aug=aug, pose_input='positions',
                            lifted=same)
    for _ in range(20):
        s = sampler.sample()
        np.testing.assert_allclose(s['rot_in'], s['rot'], atol=1e-6)
        np.testing.assert_allclose(s['lengths_in'], sampler.group_lengths[0] *
                                   s['lengths_in'][0] / sampler.group_lengths[0][0], rtol=1e-5)
    other = [LiftedClip(np.tile([0, 0, 0, 1.0], (1, m.num_frames, NUM_JOINTS, 1)),
                        np.ones((1, 10))) for m in clips]
    sampler = WindowSampler(clips, 24, 30.0, seed=3, aug=Augmentation(lifted_prob=1.0),
                            lifted=other)
    s = sampler.sample()
    np.testing.assert_allclose(s['rot_in'][..., 3], 1.0)
    with pytest.raises(ValueError, match='frame-aligned'):
        WindowSampler(clips, 24, 30.0, lifted=[LiftedClip(c.rotations[:, :5], c.lengths)
                                               for c in other])


def test_time_scale_augmentation_plays_the_clip_slower_input_and_targets_alike():
    """At half speed (range (0.5, 0.5)) a window is the clip resampled at twice its rate
    (slerp and linear root, as ``mocap_core.data.motion.resample``): the targets step half as
    far per frame, and a lifted input equal to the truth stays the target pose frame by
    frame. At playback speed 1 nothing is interpolated."""
    from mocap_core.data.motion import resample
    from mocap_global.training.lifted import LiftedClip

    R, T = circle_walk(90)
    m = _motion(R, T, seed=2)
    aug = Augmentation(reverse_prob=0.0, mirror_prob=0.0, scale_range=0.0, noise_prob=0.0,
                       short_prob=0.0, lifted_prob=1.0, time_scale_prob=1.0,
                       time_scale_range=(0.5, 0.5))
    same = [LiftedClip(m.rotations[None].astype(np.float32),
                       m.skeleton.group_lengths()[None].astype(np.float32))]
    sampler = WindowSampler([m], 40, 30.0, seed=0, aug=aug, lifted=same)
    slow_rot, slow_root = resample(m.rotations, m.root_positions, 30.0, 60.0)
    for _ in range(5):
        w = sampler.sample()
        assert len(w['rot']) == 40
        # the window starts at some half frame of the clip: find it by the root
        k = int(np.argmin(np.linalg.norm(slow_root - w['root'][0], axis=1)))
        np.testing.assert_allclose(w['root'], slow_root[k:k + 40], atol=1e-5)
        dots = np.abs(np.sum(w['rot'] * slow_rot[k:k + 40], axis=-1))
        np.testing.assert_allclose(dots, 1.0, atol=1e-5)
        np.testing.assert_allclose(w['rot_in'], w['rot'], atol=1e-5)
    step_slow = np.linalg.norm(np.diff(w['root'], axis=0), axis=1).mean()
    step_clip = np.linalg.norm(np.diff(T, axis=0), axis=1).mean()
    assert step_slow == pytest.approx(0.5 * step_clip, rel=0.02)
    with pytest.raises(ValueError, match='time_scale_range'):
        Augmentation(time_scale_range=(1.5, 0.5))
    plain = WindowSampler([m], 40, 30.0, seed=0, aug=Augmentation.none()).sample()
    k = int(np.argmin(np.linalg.norm(T - plain['root'][0], axis=1)))
    np.testing.assert_array_equal(plain['root'], T[k:k + 40].astype(np.float32))


def test_static_camera_frames_are_the_floor_input_moved_rigidly():
    """A camera that stands still, floor input, static time constants 0: every output frame
    is the input pose moved by one rigid transform (a turn about z and a shift), so every
    contact point moves in the world exactly as the physics moved it (no skating added);
    a turning camera's frames (anchors not static) keep the slower pull towards the input."""
    from mocap_global.online import InputAnchor

    poses = []
    for p in _poses(50, seed=5):
        low = min(c[2] for c in p.contact_positions().values())
        poses.append(Pose(p.skeleton, p.rotations, p.root_position - [0, 0, low]))
    pts_in = np.array([[p.contact_positions()[n] for n in CONTACT_POINT_NAMES]
                       for p in poses])

    def run(static):
        fusion = StaticCameraFusion(30.0, input_up=EZ, static_position_time_constant_s=0.0)
        online = OnlineGMR(_small_model(), lookahead=3, fusion=fusion, floor_input=True,
                           foot_lock=True)
        frames = []
        for i, p in enumerate(poses):
            frames += online.push(i * 33_333_333, p, InputAnchor(True, static=static))[0]
        frames += online.flush()
        assert len(frames) == len(poses) and all(f.fused for f in frames)
        pts = np.array([[f.pose.contact_positions()[n] for n in CONTACT_POINT_NAMES]
                        for f in frames])
        return fusion, pts

    fusion, pts = run(True)
    np.testing.assert_allclose(fusion.W_R @ EZ, EZ, atol=1e-12)     # a turn about z
    np.testing.assert_allclose(pts, pts_in @ fusion.W_R.T + fusion.W_t, atol=1e-6)
    # the same anchors said to turn: GMR's own steps, pulled with 0.15 s, are not rigid
    fusion, pts = run(False)
    assert np.abs(pts - (pts_in @ fusion.W_R.T + fusion.W_t)).max() > 0.005


def test_a_moving_cameras_fused_frames_keep_the_foot_lock():
    """Fused frames of a camera that turns (anchors not static: a translation measured over
    the floor, noisy frame to frame) follow that noise with their feet unless
    ``moving_lock_time_constant_s`` keeps the lock: then the standing points stay put and
    the root still follows the anchors' slow drift. A walking camera's are not locked."""
    from mocap_global.online import InputAnchor

    poses = []
    for p in _poses(80, seed=7):
        low = min(c[2] for c in p.contact_positions().values())
        poses.append(Pose(p.skeleton, p.rotations, p.root_position - [0, 0, low]))
    rng = np.random.default_rng(3)
    drift = np.array([0.01, 0.0, 0.0])               # the camera walks 1 cm per frame
    anchors = [InputAnchor(True, np.eye(3), i * drift + rng.normal(0, 0.02, 3) * [1, 1, 0],
                           static=False) for i in range(len(poses))]

    def run(tau, walking=False):
        fusion = StaticCameraFusion(30.0, input_up=EZ)
        online = OnlineGMR(_small_model(), lookahead=3, fusion=fusion, floor_input=True,
                           foot_lock=True, moving_lock_time_constant_s=tau)
        frames = []
        for i, (p, a) in enumerate(zip(poses, anchors)):
            if walking:
                a = InputAnchor(True, a.rotation, a.translation, translating=True)
            frames += online.push(i * 33_333_333, p, a)[0]
        frames += online.flush()
        assert len(frames) == len(poses) and all(f.fused for f in frames[1:])
        pts = np.array([[f.pose.contact_positions()[n] for n in CONTACT_POINT_NAMES]
                        for f in frames])
        stand = (pts[1:, :, 2] < 0.02) & (pts[:-1, :, 2] < 0.02)
        skate = np.linalg.norm(np.diff(pts[..., :2], axis=0), axis=-1)[stand].mean()
        roots = np.array([f.pose.root_position for f in frames])
        return skate, roots

    loose, roots_loose = run(0.0)
    locked, roots_locked = run(0.5)
    assert locked < 0.3 * loose, (locked, loose)
    # a walking camera's frames (the estimate says it translates) follow the fused root
    assert run(0.5, walking=True)[0] == pytest.approx(loose)
    # both follow the anchored input's path over the clip (input root plus the anchors'
    # translation, here about 3.5 m) within a tenth of it
    want = np.linalg.norm((poses[-1].root_position + anchors[-1].translation -
                           poses[0].root_position - anchors[0].translation)[:2])
    for roots, tol in ((roots_loose, 0.1), (roots_locked, 0.1)):
        moved = np.linalg.norm(roots[-1, :2] - roots[0, :2])
        assert abs(moved - want) < tol * want, (moved, want)
    with pytest.raises(ValueError, match='moving_lock_time_constant_s'):
        OnlineGMR(_small_model(), lookahead=3, moving_lock_time_constant_s=-1.0)


def test_playback_speed_evaluation_measures_the_pace(monkeypatch):
    """``evaluate_speeds`` scores each clip retimed: a predictor that returns the retimed
    clip's true motion scores step ratio 1 and RTE 0 at every speed, one that returns half of
    it 0.5; clips that do not travel are left out."""
    from mocap_core.rotations import matrix_to_axis_angle
    from mocap_global.training import evaluate as E

    R, T = circle_walk(120)
    walk = _motion(R, T, seed=1)
    still = _motion(R[:1].repeat(120, 0), T[:1].repeat(120, 0), seed=2)
    seen = {}
    arrays = E.clip_arrays

    def keep(*a, **k):
        seen['c'] = arrays(*a, **k)
        return seen['c']

    for scale in (1.0, 0.5):
        def truth(model, feats, *a, scale=scale, **k):
            c = seen['c']
            assert len(feats) == len(c['R'])
            return {'axis_angle': matrix_to_axis_angle(c['dR']),
                    'translation': scale * c['dT'], 'up': c['up']}
        monkeypatch.setattr(E, 'clip_arrays', keep)
        monkeypatch.setattr(E, 'predict_clip', truth)
        rows = E.evaluate_speeds(_small_model(), [walk, still], ('none',), (0.5, 1.0, 1.4))
        assert [r['speed'] for r in rows] == [0.5, 1.0, 1.4]
        assert all(r['clips'] == 1 for r in rows)
        for r in rows:
            assert r['step_ratio'] == pytest.approx(scale, abs=1e-6)
            if scale == 1.0:
                assert r['rte_pct'] < 1e-3
    # the truth of a slowed clip steps half as far per frame
    E.evaluate_speeds(_small_model(), [walk], ('none',), (0.5,))
    slow = np.linalg.norm(seen['c']['dT'], axis=1).mean()
    E.evaluate_speeds(_small_model(), [walk], ('none',), (1.0,))
    assert slow == pytest.approx(0.5 * np.linalg.norm(seen['c']['dT'], axis=1).mean(),
                                 rel=0.02)


def test_foot_plant_keeps_the_feet_the_contacts_say_stand_under_a_fused_root():
    """A static camera with a floor input, the fused root following the input root: the
    input's feet slide with the root, the planted output's feet do not where the contacts
    (matched by stamp) say they stand; a foot said to be lifted follows the input, and a
    frame without contacts falls back to the heights."""
    from mocap_core.foot_plant import FootPlantConfig
    from mocap_global.online import InputAnchor

    base = _poses(1)[0]
    low = min(c[2] for c in base.contact_positions().values())
    poses = [Pose(base.skeleton, base.rotations, base.root_position + [0.005 * i, 0.0, -low])
             for i in range(40)]
    stamps = [i * 33_333_333 for i in range(40)]
    contacts = {s: np.array([1.0, 1.0, 0.0, 0.0]) for s in stamps[:-5]}   # left stands

    def run(plant):
        fusion = StaticCameraFusion(30.0, position_time_constant_s=1e-9,
                                    input_up=np.array([0.0, 0.0, 1.0]))
        online = OnlineGMR(_small_model(), lookahead=3, fusion=fusion, floor_input=True,
                           foot_lock=True, foot_plant=plant, contacts=contacts,
                           lock_height=-1.0)
        frames = []
        for s, p in zip(stamps, poses):
            frames += online.push(s, p, InputAnchor(True, static=True))[0]
        return frames + online.flush(), online

    plain, _ = run(None)
    planted, online = run(FootPlantConfig(lock_height=-1.0, max_correction=1.0, reach=2.0))

    def feet(frames):
        return np.array([[f.pose.contact_positions()[n] for n in CONTACT_POINT_NAMES]
                         for f in frames])

    fp, fq = feet(plain), feet(planted)
    n = len(stamps) - 5
    assert np.abs(fp[n - 1, :2, :2] - fp[0, :2, :2]).max() > 0.15     # the input slides
    assert np.abs(fq[n - 1, :2, :2] - fq[0, :2, :2]).max() < 2e-3      # planted
    np.testing.assert_allclose(fq[:, 2:], fp[:, 2:], atol=1e-9)        # right: as before
    np.testing.assert_allclose([f.pose.root_position for f in planted],
                               [f.pose.root_position for f in plain], atol=1e-12)
    # the last frames have no contacts: heights (lock_height -1: nothing stands) release
    assert online.planted_with_contacts == n and online.planted_by_height == 5
    assert np.abs(fq[-1, :2] - fp[-1, :2]).max() < np.abs(fq[n - 1, :2] - fp[n - 1, :2]).max()


def test_treatment_changes_do_not_make_the_root_jump():
    """Blocks of frames fused towards the input root (a static camera, instant position gain)
    alternate with blocks the estimate cannot anchor (foot lock, here under a GMR that
    predicts no motion, so the lock alone moves the body). The locked root drifts away from
    the input root, so every switch back to the fusion made the emitted root jump; with
    ``transition_time_constant_s`` the root goes on at its velocity and the difference
    decays: no jump, and by a block's end the root is the treatment's own again."""
    from mocap_global.online import InputAnchor

    n, block = 300, 60
    R, T = circle_walk(n, turn=0.0)                     # standing, the legs swinging
    swing = np.zeros((n, NUM_JOINTS - 1, 3))
    swing[..., 1] = 0.3 * np.sin(0.13 * np.arange(n)[:, None]
                                 + np.linspace(0, np.pi, NUM_JOINTS - 1)[None])
    rot = np.zeros((n, NUM_JOINTS, 4))
    rot[:, 0] = matrix_to_quat(R)
    rot[:, 1:] = matrix_to_quat(axis_angle_to_matrix(swing))
    poses = []
    for r, t in zip(rot, T):
        p = Pose(Skeleton.default(), r, t)
        low = min(c[2] for c in p.contact_positions().values())
        poses.append(Pose(p.skeleton, r, t - [0, 0, low]))
    anchors = [InputAnchor(True, static=True) if (i // block) % 2 == 0 else InputAnchor(False)
               for i in range(n)]
    model = _small_model()
    with torch.no_grad():
        model.regression.weight.zero_()                 # no motion, up = +z

    def run(tau):
        fusion = StaticCameraFusion(30.0, input_up=EZ, static_position_time_constant_s=0.0)
        online = OnlineGMR(model, lookahead=3, fusion=fusion, floor_input=True,
                           foot_lock=True, lock_height=10.0,     # every point stands
                           transition_time_constant_s=tau)
        frames = []
        for i, (p, a) in enumerate(zip(poses, anchors)):
            frames += online.push(i * 33_333_333, p, a)[0]
        frames += online.flush()
        assert len(frames) == n
        return online, np.array([f.pose.root_position for f in frames]), frames

    raw_online, raw, _ = run(0.0)
    online, smooth, frames = run(0.3)
    # fused -> lock at 60 and 180, lock -> fused one frame after 120 and 240 (the fusion
    # aligns itself on the first anchored frame)
    assert raw_online.treatment_changes == online.treatment_changes == 4
    acc_raw = np.linalg.norm(np.diff(raw[:, :2], 2, axis=0), axis=-1)
    acc = np.linalg.norm(np.diff(smooth[:, :2], 2, axis=0), axis=-1)
    jumps = [acc_raw[s - 3:s + 3].max() for s in (2 * block, 4 * block)]
    assert min(jumps) > 0.1                            # the scenario does jump (m / frame^2)
    for s, jump in zip((2 * block, 4 * block), jumps):
        assert acc[s - 3:s + 3].max() < 0.15 * jump, (acc[s - 3:s + 3], jump)
    assert acc.max() < 0.15 * min(jumps)
    # heights are the input's, untouched
    np.testing.assert_allclose(smooth[:, 2], raw[:, 2], atol=1e-12)
    # the offset decays: by the end of each block (2 s, 6.7 time constants) the root is the
    # treatment's own within 2 % of the jump it took up
    for end in range(2 * block - 1, n, block):
        start = end - block + 2
        jump = np.linalg.norm(smooth[start, :2] - raw[start, :2])
        assert np.linalg.norm(smooth[end, :2] - raw[end, :2]) < 0.02 * jump + 1e-9
    # the treatments' own state is not changed by it, and what is published agrees with
    # itself: the input transform maps the input root onto the emitted root, the velocity
    # is the emitted root's
    for f, p in zip(frames, poses):
        np.testing.assert_allclose(f.input_rotation @ p.root_position + f.input_translation,
                                   f.pose.root_position, atol=1e-9)
    k = 2 * block + 2
    v = quat_to_matrix(frames[k].pose.rotations[0]).T @ (smooth[k] - smooth[k - 1]) * 30.0
    np.testing.assert_allclose(frames[k].linear_velocity, v, rtol=1e-6, atol=1e-9)
    with pytest.raises(ValueError, match='transition_time_constant_s'):
        OnlineGMR(_small_model(), lookahead=3, transition_time_constant_s=-0.1)


def test_the_network_can_read_another_pose_than_the_one_emitted():
    """``network_pose``: the world path is the one GMR gives for the network's pose (here
    another random local pose per frame), the body emitted is the input's own; the network
    pose given with the frame or set later (the pass runs again) are the same; a stamp not in
    the window changes nothing; a network pose with other joints is refused."""
    model = _small_model()
    body, net = _poses(40, seed=0), _poses(40, seed=1)
    stamps = [i * 33_333_333 for i in range(40)]

    def run(mode):
        online = OnlineGMR(model, lookahead=5)
        out = []
        for s, p, q in zip(stamps, body, net):
            if mode == 'body':
                out += online.add(s, p)[0]
            elif mode == 'net':
                out += online.add(s, q)[0]
            elif mode == 'given':
                out += online.add(s, p, network_pose=q)[0]
            else:          # 'set': the network pose comes after the network's pass
                out += online.add(s, p)[0]
                prepare_outputs([online])
                assert online.set_network_pose(s, q)
            out += online.take()
        return online, out + online.flush()

    _, plain = run('body')
    _, as_net = run('net')
    given_state, given = run('given')
    _, later = run('set')
    assert given_state.network_pose_frames == 40
    def path(frames):      # from the first frame (placed by the body's own lowest foot)
        T = np.stack([f.pose.root_position for f in frames])
        return T - T[0]

    # the path is the network pose's, and it differs from the body's own
    np.testing.assert_allclose(path(given), path(as_net), atol=1e-6)
    assert np.abs(path(given) - path(plain)).max() > 1e-3
    np.testing.assert_allclose(path(later), path(given), atol=1e-6)
    # the emitted body is the input's local pose (not the network's)
    for f, p in zip(given, body):
        np.testing.assert_allclose(f.pose.rotations[1:], p.rotations[1:], atol=1e-12)
    # a stamp the window does not hold: nothing changes, and a pose with other joints fails
    assert not given_state.set_network_pose(stamps[-1] + 10**9, net[0])
    assert given_state.network_pose_frames == 40
    sk = Skeleton(np.zeros((3, 3)), joint_names=('pelvis', 'a', 'b'), parents=(-1, 0, 1))
    other = Pose(sk, np.tile([0, 0, 0, 1.0], (3, 1)), np.zeros(3))
    with pytest.raises(ValueError, match='joint set does not match'):
        given_state.set_network_pose(stamps[-1], other)
    with pytest.raises(ValueError, match='joint set does not match'):
        OnlineGMR(model, lookahead=5).add(0, body[0], network_pose=other)


def _trail(fusion: StaticCameraFusion, steps: int = 150, v: float = 0.05,
           ratio: float = 0.7, noise: float = 0.0, seed: int = 0) -> np.ndarray:
    """A walker measured at (v k, 0, 0) m (known world, every frame measured) while GMR's
    steps cover ``ratio`` of the way: the fused positions (steps, 3), each frame's GMR
    step taken from the last fused position as OnlineGMR does."""
    rng = np.random.default_rng(seed)
    R = np.eye(3)
    T = np.zeros(3)
    out = []
    for k in range(steps):
        Tm = np.array([v * k, 0.0, 0.0]) + noise * rng.normal(size=3) * [1, 1, 0]
        T_gmr = T + np.array([ratio * v, 0.0, 0.0])
        _, T, _ = fusion.step(R, T_gmr, R, Tm, np.array([0.0, 0.0, 1.0]), first=k == 0,
                              measured=True)
        out.append(T)
    return np.stack(out)


def test_the_velocity_correction_takes_out_the_lag_of_short_gmr_steps():
    """A known-world fusion of a measured root with GMR's steps at 0.7 of the walk: the
    first-order pull trails the walker by about (1 - 0.7) v tau / dt; the alpha-beta filter
    learns the missing velocity and does not trail, and still filters measurement noise
    (its jitter stays well below the measurement's)."""
    v = 0.05                                             # 1.5 m/s at 30 frames/s
    truth = v * np.arange(150)
    plain = _trail(StaticCameraFusion(30.0, known_world=True,
                                      measured_position_time_constant_s=0.15), v=v)
    ab = _trail(StaticCameraFusion(30.0, known_world=True,
                                   measured_position_time_constant_s=0.15,
                                   measured_velocity_correction=True), v=v)
    lag_plain = truth[-30:] - plain[-30:, 0]
    lag_ab = truth[-30:] - ab[-30:, 0]
    a = 1.0 - np.exp(-1.0 / (30.0 * 0.15))
    assert np.mean(lag_plain) == pytest.approx(0.3 * v * (1 - a) / a, rel=0.05)   # ~5 cm
    assert np.max(np.abs(lag_ab)) < 1e-3
    # noise: both filter the measurement's frame-to-frame noise (3 cm)
    noisy = _trail(StaticCameraFusion(30.0, known_world=True,
                                      measured_position_time_constant_s=0.15,
                                      measured_velocity_correction=True), v=v, noise=0.03)
    acc = np.diff(noisy[:, :2], 2, axis=0)
    assert np.sqrt((acc ** 2).sum(-1).mean()) < 0.5 * 0.03 * np.sqrt(6 * 2)
    # not measured frames drop the correction
    fusion = StaticCameraFusion(30.0, known_world=True, measured_velocity_correction=True)
    _trail(fusion, steps=40)
    assert np.linalg.norm(fusion.velocity_correction) > 0.01
    fusion.step(np.eye(3), np.zeros(3), np.eye(3), np.zeros(3), np.array([0.0, 0.0, 1.0]))
    np.testing.assert_array_equal(fusion.velocity_correction, 0.0)
