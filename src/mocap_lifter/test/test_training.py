"""MotioNet training checkpoints: resumed through load_checkpoint (tensors only)."""

from pathlib import Path

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


def test_train_reset_only_changes_nothing_but_those_rows():
    """With ``reset_only_parameters`` an optimiser step on any loss moves the reset joints'
    output rows and nothing else: not the other rows, not the trunk."""
    from mocap_core.skeleton import JOINT_INDEX
    from mocap_lifter.features import NUM_FEATURES
    from mocap_lifter.model import LifterConfig, MotioNet
    from mocap_lifter.training.train import reset_only_parameters, reset_rotation_outputs

    torch.manual_seed(1)
    model = MotioNet(LifterConfig())
    reset_rotation_outputs(model, ('right_knee',))
    before = {k: v.clone() for k, v in model.state_dict().items()}
    params = reset_only_parameters(model, ('right_knee',))
    opt = torch.optim.Adam(params, lr=0.1)
    model.eval()
    q, depth, contacts = model.e_q(torch.randn(2, NUM_FEATURES, 30))
    (q * torch.randn_like(q)).sum().add(depth.sum() + contacts.sum()).backward()
    opt.step()
    after = model.state_dict()
    j = JOINT_INDEX['right_knee']
    rows = torch.zeros(len(before['e_q.shrink.bias']), dtype=torch.bool)
    rows[4 * j:4 * j + 4] = True
    assert not torch.equal(after['e_q.shrink.weight'][rows], before['e_q.shrink.weight'][rows])
    assert torch.equal(after['e_q.shrink.weight'][~rows], before['e_q.shrink.weight'][~rows])
    assert torch.equal(after['e_q.shrink.bias'][~rows], before['e_q.shrink.bias'][~rows])
    changed = [k for k in before if k not in ('e_q.shrink.weight', 'e_q.shrink.bias')
               and not torch.equal(before[k], after[k])]
    assert changed == []
    with pytest.raises(ValueError, match='needs reset_joints'):
        reset_only_parameters(MotioNet(LifterConfig()), ())


def test_freeze_keeps_the_named_modules_as_they_were():
    """``freeze_modules``: the named modules' parameters stop requiring gradients (and so stay
    as they are through training) while the rest still learns; an unknown name is refused."""
    from mocap_lifter.model import LifterConfig, MotioNet
    from mocap_lifter.training.train import freeze_modules

    model = MotioNet(LifterConfig())
    frozen = freeze_modules(model, ('e_q.expand', 'e_q.blocks.0', 'e_s'))
    names = {n for n, p in model.named_parameters() if not p.requires_grad}
    assert names and all(n.startswith(('e_q.expand.', 'e_q.blocks.0.', 'e_s.')) for n in names)
    assert all(p.requires_grad for n, p in model.named_parameters()
               if n.startswith(('e_q.blocks.1.', 'e_q.blocks.2.', 'e_q.shrink.')))
    assert any(isinstance(m, torch.nn.BatchNorm1d) for m in frozen)
    with pytest.raises(ValueError, match='no module'):
        freeze_modules(model, ('e_q.blocks.9',))


def test_eval_scores_the_weights_the_node_loads():
    """`mocap eval lifter` without --weights scores the node's default (DEFAULT_FILES), not
    the older `motionet_windowed.pt`."""
    from mocap_lifter.training.cli import eval_weights
    from mocap_lifter.weights import DEFAULT_FILES, default_weights
    got = eval_weights('motionet', 'windowed', None)
    assert got == default_weights('windowed')
    assert got.name == DEFAULT_FILES[('motionet', 'windowed')]
    assert eval_weights('vtm', 'windowed', None).name == 'vtm_windowed.pt'
    assert eval_weights('motionet', 'windowed', '/x/y.pt') == Path('/x/y.pt')
