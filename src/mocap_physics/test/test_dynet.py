"""DyNet: untrained = fixed gains, the differentiable rollout matches the cycle, it learns."""

from pathlib import Path

import numpy as np
import pytest
import torch

from mocap_core.rotations import axis_angle_to_quat, quat_multiply, quat_to_axis_angle
from mocap_physics.cycle import PhysicsCycle
from mocap_physics.cycle_params import PhysicsParams
from mocap_physics.dynet import DyNet, make_dynet
from mocap_physics.model import PhysicsModel
from mocap_physics.training.evaluate import load_gt_bag
from mocap_physics.training.train_dynet import Rollout, rollout_loss, t_difference, t_integrate

BAG = Path(__file__).resolve().parents[3] / 'bags' / 'gt_bandai_walk_exhausted'


@pytest.fixture(scope='module')
def walk():
    clip = load_gt_bag(BAG)
    model = PhysicsModel(clip.skeleton)
    q = np.array([model.normalize(model.pose_to_q(clip.to_world.transform_pose(clip.pose(i))))
                  for i in range(20)])
    return clip, model, q


def test_lie_helpers_match_pinocchio(walk):
    import pinocchio as pin
    _, model, q = walk
    a, b = torch.from_numpy(q[0]), torch.from_numpy(q[5])
    d = t_difference(a, b).numpy()
    ref = pin.difference(model.model, q[0], q[5])
    np.testing.assert_allclose(d[6:], ref[6:], atol=1e-9)          # ball joints
    back = t_integrate(a, torch.from_numpy(d)).numpy()
    np.testing.assert_allclose(model.joint_positions(back), model.joint_positions(q[5]),
                               atol=2e-3)
    r = torch.tensor([0.3, -0.2, 0.1], dtype=torch.float64)
    np.testing.assert_allclose(quat_to_axis_angle(axis_angle_to_quat(r)).numpy(), r.numpy(),
                               atol=1e-12)
    np.testing.assert_allclose(quat_multiply(axis_angle_to_quat(r),
                                             axis_angle_to_quat(-r)).numpy(), [0, 0, 0, 1],
                               atol=1e-12)


def test_untrained_dynet_is_the_fixed_cycle(walk, tmp_path):
    clip, model, q = walk
    net = make_dynet(model, PhysicsParams())
    path = tmp_path / 'dynet.pt'
    net.save(path)
    assert DyNet.load(path).config == net.config
    fixed = PhysicsCycle(clip.skeleton, PhysicsParams(dynamics='paper'))
    learned = PhysicsCycle(clip.skeleton, PhysicsParams(dynamics='paper', gains_mode='learned',
                                                        dynet_weights=str(path)))
    for i in range(10):
        a = fixed.step(model.q_to_pose(q[i]), i / 30, clip.contacts[i])
        b = learned.step(model.q_to_pose(q[i]), i / 30, clip.contacts[i])
    np.testing.assert_allclose(a.q, b.q, atol=1e-9)
    with pytest.raises(ValueError):
        PhysicsParams(gains_mode='learned').validate()


def test_rollout_matches_the_cycle_and_has_gradients(walk):
    clip, model, q = walk
    params = PhysicsParams(dynamics='paper')
    cyc = PhysicsCycle(clip.skeleton, params)
    for i in range(12):
        r = cyc.step(model.q_to_pose(q[i]), i / 30, clip.contacts[i])
    ro = Rollout(model, params)
    qt = torch.from_numpy(q[0].copy())
    v = torch.zeros(model.nv, dtype=torch.float64)
    with torch.no_grad():
        for i in range(1, 12):
            qt, v, _ = ro.frame(None, qt, v, q[i], clip.contacts[i], 1 / 30)
    diff = np.abs(model.joint_positions(qt.numpy()) - model.joint_positions(r.q)).max()
    assert diff < 2e-3, diff
    net = make_dynet(model, params, hidden=32)
    loss, err = rollout_loss(Rollout(model, params), net, q[:8], q[:8], clip.contacts[:8],
                             30.0, burn_in=3)
    loss.backward()
    grads = [p.grad for p in net.parameters() if p.grad is not None]
    assert grads and all(torch.isfinite(g).all() for g in grads)
    assert any(g.abs().max() > 0 for g in grads)


def test_a_few_steps_reduce_the_tracking_loss(walk):
    """Overfit one short window: the learned gains track it better than the fixed ones."""
    clip, model, q = walk
    params = PhysicsParams(dynamics='paper')
    torch.manual_seed(0)
    net = make_dynet(model, params, hidden=32)
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    args = (q[:7], q[:7], clip.contacts[:7], 30.0, 2)
    first = None
    for _ in range(12):
        loss, _ = rollout_loss(Rollout(model, params), net, *args)
        first = float(loss.detach()) if first is None else first
        opt.zero_grad()
        loss.backward()
        opt.step()
    with torch.no_grad():
        last, _ = rollout_loss(Rollout(model, params), net, *args)
    assert float(last) < 0.9 * first, (float(last), first)
