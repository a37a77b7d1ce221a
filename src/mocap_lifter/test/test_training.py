"""MotioNet training checkpoints: resumed through load_checkpoint (tensors only)."""

import numpy as np
import pytest
import torch

from mocap_core.checkpoint import WeightsError
from mocap_core.rotations import axis_angle_to_quat
from mocap_core.skeleton import NUM_JOINTS, Skeleton
from mocap_core.testing import CreatesFile

SMALL = dict(channels=16, fusion_blocks=1, skeleton_channels=8, dropout=0.0)


def _walk(frames: int = 60, seed: int = 0):
    """A walk-like motion (world frame, z up): swinging hips, turning."""
    from mocap_core.data.motion import Motion
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / 30.0
    aa = np.zeros((frames, NUM_JOINTS, 3))
    aa[:, 0, 2] = 0.3 * t + rng.uniform(-1, 1)
    aa[:, 1, 1] = 0.4 * np.sin(2 * np.pi * t)
    aa[:, 5, 1] = -0.4 * np.sin(2 * np.pi * t)
    root = np.column_stack([0.8 * t, np.zeros(frames), np.full(frames, 0.92)])
    contacts = np.zeros((frames, 4), bool)
    contacts[:, :2] = np.sin(2 * np.pi * t)[:, None] > 0
    return Motion(f'walk{seed}', 30.0, Skeleton.default(), axis_angle_to_quat(aa), root,
                  contacts)


def _config(steps: int):
    from mocap_lifter.training.train import TrainConfig
    return TrainConfig.from_dict({'steps': steps, 'batch': 4, 'window': 16, 'threads': 1,
                                  'validate_every': 1000, 'checkpoint_every': 2,
                                  'w_adversarial': 0.05, 'model': SMALL})


def test_training_resumes_from_its_checkpoint_and_refuses_a_crafted_one(tmp_path):
    from mocap_lifter.training.train import train
    from mocap_lifter.weights import load_weights

    motions = [_walk(seed=i) for i in range(2)]
    run = tmp_path / 'run'
    train(motions, motions, run, _config(2), progress=False)
    state = torch.load(run / 'last.pt', weights_only=True)      # plain data and tensors
    assert state['step'] == 2 and 'disc' in state and 'optimizer_d' in state
    weights = train(motions, motions, run, _config(4), progress=False)     # resumes at 2
    assert torch.load(run / 'last.pt', weights_only=True)['step'] == 4
    assert load_weights(weights).cfg.channels == 16
    rows = (run / 'log.csv').read_text().splitlines()
    assert rows[0].startswith('step,') and sum(r.startswith('step,') for r in rows) == 1

    torch.save({'model': CreatesFile(tmp_path / 'created'), 'optimizer': {}, 'step': 1},
               run / 'last.pt')
    with pytest.raises(WeightsError, match='refused'):
        train(motions, motions, run, _config(6), progress=False)
    assert not (tmp_path / 'created').exists()


def test_reset_joints_restart_those_rotations_at_the_rest_pose():
    """``reset_joints`` puts the named joints' rotation outputs back to the identity (zero
    weights, identity bias) and leaves every other output as it was; an unknown name is
    refused; a config file's list becomes a tuple."""
    from mocap_core.skeleton import JOINT_INDEX
    from mocap_lifter.model import LifterConfig, MotioNet
    from mocap_lifter.training.train import TrainConfig, reset_rotation_outputs

    torch.manual_seed(0)
    model = MotioNet(LifterConfig()).eval()
    with torch.no_grad():
        model.e_q.shrink.weight.normal_()
        model.e_q.shrink.bias.normal_()
    before = model.e_q.shrink.weight.detach().clone()
    reset_rotation_outputs(model, ('right_knee',))
    j = JOINT_INDEX['right_knee']
    w, b = model.e_q.shrink.weight.detach(), model.e_q.shrink.bias.detach()
    assert torch.all(w[4 * j:4 * j + 4] == 0)
    assert b[4 * j:4 * j + 4].tolist() == [0.0, 0.0, 0.0, 1.0]
    keep = torch.ones(len(w), dtype=torch.bool)
    keep[4 * j:4 * j + 4] = False
    assert torch.equal(w[keep], before[keep])
    from mocap_lifter.features import NUM_FEATURES
    with torch.no_grad():
        q, _, _ = model.e_q(torch.randn(1, NUM_FEATURES, 40))
    np.testing.assert_allclose(q[0, :, j].numpy(), np.tile([0, 0, 0, 1.0], (q.shape[1], 1)),
                               atol=1e-6)
    with pytest.raises(ValueError, match='unknown joints'):
        reset_rotation_outputs(model, ('right_kneecap',))
    assert TrainConfig.from_dict({'reset_joints': ['right_knee']}).reset_joints == \
        ('right_knee',)
