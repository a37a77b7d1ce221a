"""PhysicsModel: dimensions, masses, kinematics and dynamics consistency."""

import numpy as np
import pinocchio as pin
import pytest

from mocap_core.pose import Pose
from mocap_core.rotations import quat_normalize
from mocap_core.skeleton import CONTACT_POINT_NAMES, Skeleton
from mocap_core.urdf import link_inertials
from mocap_physics.model import PhysicsModel, SkeletonError


@pytest.fixture(scope='module')
def model():
    return PhysicsModel(Skeleton.default(), 70.0)


def _random_pose(skeleton, rng, scale=1.0):
    rot = quat_normalize(np.array([0, 0, 0, 1.0])
                         + scale * rng.normal(size=(skeleton.num_joints, 4)))
    return Pose(skeleton, rot, rng.normal(size=3) + np.array([0, 0, 1.0]))


def test_dimensions_and_mass(model):
    sk = model.skeleton
    assert model.nq == 7 + 4 * (sk.num_joints - 1) == 75
    assert model.nv == 6 + 3 * (sk.num_joints - 1) == 57
    assert model.model.njoints == sk.num_joints + 1          # + universe
    assert pin.computeTotalMass(model.model) == pytest.approx(70.0, rel=1e-9)
    # every link carries the de Leva mass of its segment
    inert = link_inertials(sk, 70.0)
    for j, name in enumerate(sk.joint_names):
        mass = model.model.inertias[model.joint_ids[j]].mass
        assert mass == pytest.approx(inert[name][0] if name in inert else 0.0, abs=1e-12)
    assert tuple(model.model.names[i] for i in model.joint_ids) == sk.joint_names
    assert ([model.model.frames[f].name for f in model.contact_frame_ids]
            == list(CONTACT_POINT_NAMES))


def test_other_body_mass_and_skeleton():
    sk = Skeleton.from_lengths_dict({'thigh': 0.5, 'shin': 0.48, 'upper_arm': 0.33})
    m = PhysicsModel(sk, 95.0)
    assert pin.computeTotalMass(m.model) == pytest.approx(95.0, rel=1e-9)
    assert m.weight == pytest.approx(95.0 * 9.81)
    assert not m.matches(Skeleton.default())
    assert m.matches(Skeleton.from_lengths_dict({'thigh': 0.5, 'shin': 0.48, 'upper_arm': 0.33}))


def test_pose_conversion_and_kinematics(model):
    rng = np.random.default_rng(1)
    for _ in range(5):
        pose = _random_pose(model.skeleton, rng)
        q = model.pose_to_q(pose)
        back = model.q_to_pose(q)
        np.testing.assert_allclose(back.rotations, pose.rotations, atol=1e-12)
        np.testing.assert_allclose(back.root_position, pose.root_position, atol=1e-12)
        np.testing.assert_allclose(model.joint_positions(q), pose.joint_positions(), atol=1e-10)
        cp = pose.contact_positions()
        np.testing.assert_allclose(model.contact_positions(q),
                                   np.array([cp[n] for n in model.contact_names]), atol=1e-10)


def test_rest_pose_feet_on_floor(model):
    q = model.pose_to_q(Pose.rest(model.skeleton))
    np.testing.assert_allclose(model.contact_positions(q)[:, 2], 0.0, atol=1e-12)
    com = model.center_of_mass(q)
    feet = model.contact_positions(q)
    assert feet[:, 0].min() < com[0] < feet[:, 0].max()       # CoM above the support polygon


@pytest.mark.parametrize('pitch', [15.0, 30.0, 40.0])
def test_the_heel_point_makes_a_foot_flat_at_the_given_pitch(pitch):
    """With ``flat_foot_pitch_deg``, heel and toe are at one height exactly when the ankle is
    turned toe-down by ``pitch - 30`` degrees, the heel behind the ankle, and the template
    (30) is the skeleton's own point."""
    from mocap_core.rotations import axis_angle_to_quat
    sk = Skeleton.default()
    m = PhysicsModel(sk, 70.0, flat_foot_pitch_deg=pitch)
    rest = Pose.rest(sk)
    rot = rest.rotations.copy()
    for side in ('left', 'right'):
        rot[sk.joint_names.index(f'{side}_ankle')] = axis_angle_to_quat(
            np.array([0.0, np.radians(pitch - 30.0), 0.0]))
    q = m.pose_to_q(Pose(sk, rot, rest.root_position))
    cp = dict(zip(m.contact_names, m.contact_positions(q)))
    pos = m.joint_positions(q)
    for side in ('left', 'right'):
        heel, toe = cp[f'{side}_heel'], cp[f'{side}_toe']
        ankle = pos[sk.joint_names.index(f'{side}_ankle')]
        assert heel[2] == pytest.approx(toe[2], abs=1e-9)
        v = toe - ankle
        assert np.degrees(np.arcsin(-v[2] / np.linalg.norm(v))) == pytest.approx(pitch)
        assert heel[0] < ankle[0] < toe[0]
        # the heel lies a quarter of a foot behind the ankle along the floor
        assert ankle[0] - heel[0] == pytest.approx(0.25 * sk.foot_length())
    if pitch == 30.0:
        template = sk.contact_points()
        np.testing.assert_allclose(
            m.model.frames[m.contact_frame_ids[0]].placement.translation,
            template['left_heel'][1], atol=1e-12)
    else:   # in the rest pose the heel is then off the floor: below it for a steeper foot
        q0 = m.pose_to_q(rest)
        heel0 = m.contact_positions(q0)[0, 2]
        assert (heel0 < -1e-3) if pitch > 30 else (heel0 > 1e-3)


def test_mass_matrix_and_aba_consistent(model):
    """M * aba(q, v, tau) + h == tau (catches a wrongly ordered model, ENVIRONMENT.md)."""
    rng = np.random.default_rng(2)
    for _ in range(5):
        q = model.pose_to_q(_random_pose(model.skeleton, rng))
        v = rng.normal(size=model.nv)
        tau = 10 * rng.normal(size=model.nv)
        M = model.mass_matrix(q)
        np.testing.assert_allclose(M, M.T, atol=1e-12)
        assert np.linalg.eigvalsh(M).min() > 0
        a = pin.aba(model.model, model.data, q.copy(), v, tau)
        h = pin.nonLinearEffects(model.model, model.data, q, v)
        np.testing.assert_allclose(M @ a + h, tau, atol=1e-8 * max(1.0, np.abs(tau).max()))
        # and the same against rnea (inverse dynamics)
        np.testing.assert_allclose(pin.rnea(model.model, model.data, q, v, a), tau, atol=1e-8)


def test_degenerate_skeletons_rejected():
    with pytest.raises(SkeletonError, match='degenerate'):
        PhysicsModel(Skeleton.from_lengths_dict({'shin': 1e-5}))
    with pytest.raises(SkeletonError, match='body mass'):
        PhysicsModel(Skeleton.default(), 0.0)
    with pytest.raises(SkeletonError, match='body mass'):
        PhysicsModel(Skeleton.default(), float('nan'))


def test_revolute_efforts_preserve_power():
    """S^T tau has the same power as tau with the angular velocity of the Euler rates."""
    from mocap_core.rotations import euler_to_matrix
    from mocap_physics.model import revolute_efforts
    rng = np.random.default_rng(4)
    angles = rng.uniform(-1.2, 1.2, size=(10, 3))
    rates = rng.normal(size=(10, 3))
    tau = rng.normal(size=(10, 3))
    eps = 1e-6
    R0 = euler_to_matrix(angles, 'ZYX')
    R1 = euler_to_matrix(angles + eps * rates, 'ZYX')
    dR = (R1 - R0) / eps
    W = np.einsum('nji,njk->nik', R0, dR)                   # R^T dR = [w]x, child frame
    w = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=-1)
    eff = revolute_efforts(angles, tau)
    np.testing.assert_allclose((eff * rates).sum(-1), (tau * w).sum(-1), atol=1e-5)
