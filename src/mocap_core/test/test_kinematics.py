"""Tests for mocap_core.kinematics."""

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from mocap_core import kinematics as kin
from mocap_core import rotations as rot

# a small branching tree: pelvis -> spine -> head, spine -> l/r arm, pelvis -> leg -> foot
PARENTS = [-1, 0, 1, 2, 1, 4, 0, 6, 7]
J = len(PARENTS)


def random_pose(batch=(), seed=0):
    rng = np.random.default_rng(seed)
    n = int(np.prod(batch)) * J
    quats = Rotation.random(n, random_state=seed).as_quat().reshape(batch + (J, 4))
    offsets = rng.normal(size=batch + (J, 3))
    root = rng.normal(size=batch + (3,))
    return offsets, quats, root


def reference_fk(parents, offsets, quats, root):
    """Slow, unbatched reference using scipy Rotation objects."""
    G, P = [], []
    for j, p in enumerate(parents):
        local = Rotation.from_quat(quats[j])
        if p < 0:
            G.append(local)
            P.append(np.asarray(root, dtype=float))
        else:
            G.append(G[p] * local)
            P.append(P[p] + G[p].apply(offsets[j]))
    return np.stack(P), np.stack([g.as_matrix() for g in G])


def test_closed_form_chain():
    parents = [-1, 0, 1, 2]
    # offsets[0] is ignored by FK
    offsets = np.array([[5.0, 5.0, 5.0], [1.0, 0, 0], [1.0, 0, 0], [0, 2.0, 0]])
    rz90 = Rotation.from_euler('z', 90, degrees=True).as_quat()
    rx90 = Rotation.from_euler('x', 90, degrees=True).as_quat()
    ident = np.array([0, 0, 0, 1.0])
    quats = np.stack([rz90, rz90, rx90, ident])
    root = np.array([1.0, 2.0, 3.0])
    res = kin.forward_kinematics(parents, offsets, quats, root)
    # G0 = Rz90, G1 = Rz180, G2 = Rz180 Rx90
    expected_pos = np.array([
        [1.0, 2.0, 3.0],
        [1.0, 3.0, 3.0],   # + Rz90 (1,0,0) = (0,1,0)
        [0.0, 3.0, 3.0],   # + Rz180 (1,0,0) = (-1,0,0)
        [0.0, 3.0, 5.0],   # + Rz180 Rx90 (0,2,0) = Rz180 (0,0,2) = (0,0,2)
    ])
    np.testing.assert_allclose(res.positions, expected_pos, atol=1e-12)
    rz180 = np.diag([-1.0, -1.0, 1.0])
    rx90m = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    np.testing.assert_allclose(res.global_rotations[1], rz180, atol=1e-12)
    np.testing.assert_allclose(res.global_rotations[3], rz180 @ rx90m, atol=1e-12)
    assert isinstance(res, kin.FKResult)
    pos, grot = res  # unpackable
    assert pos.shape == (4, 3) and grot.shape == (4, 3, 3)


def test_matches_reference_loop_batched():
    offsets, quats, root = random_pose(batch=(3, 2), seed=1)
    res = kin.forward_kinematics(PARENTS, offsets, quats, root)
    assert res.positions.shape == (3, 2, J, 3)
    assert res.global_rotations.shape == (3, 2, J, 3, 3)
    for a in range(3):
        for b in range(2):
            P, G = reference_fk(PARENTS, offsets[a, b], quats[a, b], root[a, b])
            np.testing.assert_allclose(res.positions[a, b], P, atol=1e-12)
            np.testing.assert_allclose(res.global_rotations[a, b], G, atol=1e-12)


@pytest.mark.parametrize('fmt', ['quat', 'matrix'])
def test_one_numpy_pose_matches_the_reference_and_the_batched_path(fmt):
    """One float64 NumPy pose takes the by-depth path (the nodes' per-frame case): the same
    as the reference loop and as the generic path of a batch of one, in both formats."""
    offsets, quats, root = random_pose(seed=4)
    rotations = quats if fmt == 'quat' else rot.quat_to_matrix(quats)
    res = kin.forward_kinematics(PARENTS, offsets, rotations, root, rotation_format=fmt)
    P, G = reference_fk(PARENTS, offsets, quats, root)
    np.testing.assert_allclose(res.positions, P, atol=1e-12)
    np.testing.assert_allclose(res.global_rotations, G, atol=1e-12)
    batched = kin.forward_kinematics(PARENTS, offsets[None], rotations[None], root[None],
                                     rotation_format=fmt)
    np.testing.assert_allclose(res.positions, batched.positions[0], atol=1e-13)
    np.testing.assert_allclose(res.global_rotations, batched.global_rotations[0], atol=1e-13)
    # a chain deeper than the tree above, joints listed out of depth order
    chain = [-1, 0, 0, 1, 2, 3, 4, 5]
    off = np.random.default_rng(5).normal(size=(len(chain), 3))
    q = Rotation.random(len(chain), random_state=5).as_quat()
    res = kin.forward_kinematics(chain, off, q, root)
    P, G = reference_fk(chain, off, q, root)
    np.testing.assert_allclose(res.positions, P, atol=1e-12)
    np.testing.assert_allclose(res.global_rotations, G, atol=1e-12)


def test_matrix_format_and_offset_root_ignored():
    offsets, quats, root = random_pose(batch=(4,), seed=2)
    res_q = kin.forward_kinematics(PARENTS, offsets, quats, root)
    res_m = kin.forward_kinematics(PARENTS, offsets, rot.quat_to_matrix(quats), root,
                                   rotation_format='matrix')
    np.testing.assert_allclose(res_m.positions, res_q.positions, atol=1e-12)
    np.testing.assert_allclose(res_m.global_rotations, res_q.global_rotations, atol=1e-12)
    shifted = offsets.copy()
    shifted[:, 0] += 100.0
    res_s = kin.forward_kinematics(PARENTS, shifted, quats, root)
    np.testing.assert_array_equal(res_s.positions, res_q.positions)
    # non-unit quaternions give the same pose
    res_n = kin.forward_kinematics(PARENTS, offsets, 3.0 * quats, root)
    np.testing.assert_allclose(res_n.positions, res_q.positions, atol=1e-12)


def test_unbatched_offsets_and_root_broadcast():
    offsets, quats, root = random_pose(batch=(5,), seed=3)
    off0 = offsets[0]
    res = kin.forward_kinematics(PARENTS, off0, quats, root[0])
    assert res.positions.shape == (5, J, 3)
    for b in range(5):
        P, G = reference_fk(PARENTS, off0, quats[b], root[0])
        np.testing.assert_allclose(res.positions[b], P, atol=1e-12)
        np.testing.assert_allclose(res.global_rotations[b], G, atol=1e-12)
    # batched offsets with a single pose
    res2 = kin.forward_kinematics(PARENTS, offsets, quats[0], root[0])
    assert res2.positions.shape == (5, J, 3)
    ref = reference_fk(PARENTS, offsets[2], quats[0], root[0])[0]
    np.testing.assert_allclose(res2.positions[2], ref, atol=1e-12)


def test_torch_matches_numpy_and_inputs_untouched():
    offsets, quats, root = random_pose(batch=(2, 3), seed=4)
    copies = [offsets.copy(), quats.copy(), root.copy()]
    res_np = kin.forward_kinematics(PARENTS, offsets, quats, root)
    for a, c in zip([offsets, quats, root], copies):
        np.testing.assert_array_equal(a, c)
    assert isinstance(res_np.positions, np.ndarray)
    t_args = [torch.tensor(a) for a in (offsets, quats, root)]
    t_copies = [a.clone() for a in t_args]
    res_t = kin.forward_kinematics(PARENTS, *t_args)
    assert isinstance(res_t.positions, torch.Tensor) and res_t.positions.dtype == torch.float64
    np.testing.assert_allclose(res_t.positions.numpy(), res_np.positions, atol=1e-12)
    np.testing.assert_allclose(res_t.global_rotations.numpy(), res_np.global_rotations, atol=1e-12)
    for a, c in zip(t_args, t_copies):
        assert torch.equal(a, c)
    # float32 stays float32
    res_32 = kin.forward_kinematics(PARENTS, *[a.float() for a in t_args])
    assert res_32.positions.dtype == torch.float32
    np.testing.assert_allclose(res_32.positions.numpy(), res_np.positions, atol=1e-4)


def test_gradcheck_through_fk():
    offsets, quats, root = random_pose(batch=(2,), seed=5)
    q = torch.tensor(quats, requires_grad=True)
    o = torch.tensor(offsets, requires_grad=True)
    r = torch.tensor(root, requires_grad=True)

    def f(q, o, r):
        res = kin.forward_kinematics(PARENTS, o, q, r)
        return res.positions, res.global_rotations

    assert torch.autograd.gradcheck(f, (q, o, r))
    R = torch.tensor(rot.quat_to_matrix(quats), requires_grad=True)
    assert torch.autograd.gradcheck(
        lambda R: kin.forward_kinematics(PARENTS, o, R, r, rotation_format='matrix').positions,
        (R,))
    # a non-trivial loss back-propagates to every joint rotation except the leaves' (no children)
    q2 = torch.tensor(quats, requires_grad=True)
    kin.forward_kinematics(PARENTS, o, q2, r).positions.pow(2).sum().backward()
    leaves = [j for j in range(J) if j not in PARENTS]
    non_leaves = [j for j in range(J) if j in PARENTS]
    assert torch.all(q2.grad[:, leaves] == 0)
    assert torch.all(q2.grad[:, non_leaves].abs().sum(-1) > 0)


@pytest.mark.parametrize('parents', [
    [0, 0, 1],          # root is not -1
    [-1, 1, 2],         # self-parent
    [-1, 0, 3, 1],      # parent after child
    [-1, -1, 0],        # second root
    [],                 # empty
    [-1, 0, 'a'],       # not ints
    [-1, 0, 1.5],       # not ints
])
def test_invalid_parents_raise(parents):
    n = max(len(parents), 1)
    with pytest.raises(ValueError):
        kin.forward_kinematics(parents, np.zeros((n, 3)), rot.quat_identity((n,)), np.zeros(3))
    with pytest.raises(ValueError):
        kin.local_from_global_rotations(parents, np.broadcast_to(np.eye(3), (n, 3, 3)))
    with pytest.raises(ValueError):
        kin.bone_lengths(parents, np.zeros((n, 3)))


def test_invalid_shapes_and_format_raise():
    offsets, quats, root = random_pose(seed=6)
    with pytest.raises(ValueError):
        kin.forward_kinematics(PARENTS[:-1], offsets, quats, root)  # J mismatch
    with pytest.raises(ValueError):
        kin.forward_kinematics(PARENTS, offsets, quats, root, rotation_format='euler')
    with pytest.raises(ValueError):
        kin.forward_kinematics(PARENTS, offsets, quats, root, rotation_format='matrix')
    with pytest.raises(ValueError):
        kin.forward_kinematics(PARENTS, offsets, quats, root[:2])


@pytest.mark.parametrize('backend', ['numpy', 'torch'])
def test_local_from_global_inverts_fk(backend):
    offsets, quats, root = random_pose(batch=(3,), seed=7)
    if backend == 'torch':
        offsets, quats, root = (torch.tensor(a) for a in (offsets, quats, root))
    res = kin.forward_kinematics(PARENTS, offsets, quats, root)
    local = kin.local_from_global_rotations(PARENTS, res.global_rotations)
    assert tuple(local.shape) == (3, J, 3, 3)
    expected = rot.quat_to_matrix(quats)
    if backend == 'torch':
        assert isinstance(local, torch.Tensor)
        local, expected = local.numpy(), expected.numpy()
    np.testing.assert_allclose(local, expected, atol=1e-12)
    local_in = local if backend == 'numpy' else torch.tensor(local)
    res2 = kin.forward_kinematics(PARENTS, offsets, local_in, root, rotation_format='matrix')
    np.testing.assert_allclose(np.asarray(res2.global_rotations), np.asarray(res.global_rotations),
                               atol=1e-12)


def test_bone_lengths():
    offsets, _, _ = random_pose(batch=(2,), seed=8)
    bl = kin.bone_lengths(PARENTS, offsets)
    assert bl.shape == (2, J)
    np.testing.assert_array_equal(bl[:, 0], 0.0)
    np.testing.assert_allclose(bl[:, 1:], np.linalg.norm(offsets[:, 1:], axis=-1), atol=1e-15)
    # lengths are preserved by FK: distance between joint and parent
    _, quats, root = random_pose(batch=(2,), seed=9)
    P = kin.forward_kinematics(PARENTS, offsets, quats, root).positions
    for j in range(1, J):
        np.testing.assert_allclose(np.linalg.norm(P[:, j] - P[:, PARENTS[j]], axis=-1), bl[:, j],
                                   atol=1e-12)
    bt = kin.bone_lengths(PARENTS, torch.tensor(offsets))
    assert isinstance(bt, torch.Tensor)
    np.testing.assert_allclose(bt.numpy(), bl, atol=1e-15)


def test_transform_points():
    offsets, quats, root = random_pose(batch=(4,), seed=10)
    res = kin.forward_kinematics(PARENTS, offsets, quats, root)
    foot = 8
    heel = np.array([[0.0, -0.05, -0.1], [0.1, 0.0, 0.2]])  # (P, 3) shared by the batch
    world = kin.transform_points(res.global_rotations[:, foot], res.positions[:, foot], heel)
    assert world.shape == (4, 2, 3)
    for b in range(4):
        expected = (Rotation.from_matrix(res.global_rotations[b, foot]).apply(heel)
                    + res.positions[b, foot])
        np.testing.assert_allclose(world[b], expected, atol=1e-12)
    # a point at a child's offset lands on the child joint
    child_pts = offsets[:, 8:9]
    np.testing.assert_allclose(
        kin.transform_points(res.global_rotations[:, 7], res.positions[:, 7], child_pts)[:, 0],
        res.positions[:, 8], atol=1e-12)
    # torch parity + gradient
    Rt = torch.tensor(res.global_rotations[:, foot], requires_grad=True)
    pt = torch.tensor(res.positions[:, foot], requires_grad=True)
    ht = torch.tensor(heel, requires_grad=True)
    wt = kin.transform_points(Rt, pt, ht)
    np.testing.assert_allclose(wt.detach().numpy(), world, atol=1e-12)
    assert torch.autograd.gradcheck(kin.transform_points, (Rt, pt, ht))
