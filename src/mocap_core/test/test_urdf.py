import numpy as np
import pinocchio as pin
import pytest

from mocap_core.pose import Pose
from mocap_core.rotations import quat_normalize
from mocap_core.skeleton import CONTACT_POINT_NAMES, JOINT_NAMES, NUM_JOINTS, Skeleton
from mocap_core.urdf import link_inertials, revolute_joint_names, skeleton_to_urdf


@pytest.fixture(scope='module')
def model():
    urdf = skeleton_to_urdf(Skeleton.default(), body_mass=70.0)
    return pin.buildModelFromXML(urdf, pin.JointModelFreeFlyer())


def test_pinocchio_loads_with_expected_mass_and_joints(model):
    assert sum(i.mass for i in model.inertias) == pytest.approx(70.0, rel=1e-9)
    # free flyer + 3 revolute joints per non-root joint
    assert model.nq == 7 + 3 * (NUM_JOINTS - 1)
    assert model.nv == 6 + 3 * (NUM_JOINTS - 1)
    names = list(model.names)
    for n in revolute_joint_names(Skeleton.default()):
        assert n in names
    for c in CONTACT_POINT_NAMES:
        assert model.existFrame(f'{c}_contact')


def test_body_mass_scales_linearly():
    sk = Skeleton.default()
    m1 = sum(m for m, _, _ in link_inertials(sk, 50.0).values())
    m2 = sum(m for m, _, _ in link_inertials(sk, 100.0).values())
    assert m1 == pytest.approx(50.0) and m2 == pytest.approx(100.0)
    with pytest.raises(ValueError):
        link_inertials(sk, -1.0)


def test_inertias_are_physical():
    for mass, _com, inertia in link_inertials(Skeleton.default()).values():
        assert mass > 0
        ev = np.linalg.eigvalsh(inertia)
        assert np.all(ev > 0)
        # triangle inequality of principal moments
        assert ev[0] + ev[1] >= ev[2] - 1e-12


def test_dynamics_consistent(model):
    data = model.createData()
    rng = np.random.default_rng(1)
    q = pin.neutral(model)
    q[7:] = rng.uniform(-1.0, 1.0, model.nq - 7)
    v = rng.normal(size=model.nv)
    tau = rng.normal(size=model.nv)
    a = pin.aba(model, data, q, v, tau)
    M = pin.crba(model, data, q)
    M = np.triu(M) + np.triu(M, 1).T
    b = pin.nonLinearEffects(model, data, q, v)
    np.testing.assert_allclose(M @ a + b, tau, atol=1e-8)


def test_urdf_kinematics_match_pose_fk(model):
    """Revolute angles of a random pose put into the URDF give the same joint positions."""
    sk = Skeleton.default()
    rng = np.random.default_rng(2)
    rot = quat_normalize(rng.normal(size=(NUM_JOINTS, 4)))
    pose = Pose(sk, rot, np.array([0.3, -0.2, 0.9]))
    q = pin.neutral(model)
    q[:3] = pose.root_position
    q[3:7] = pose.rotations[0]  # pinocchio free flyer: x, y, z, qx, qy, qz, qw
    q[7:] = pose.revolute_angles().reshape(-1)
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    expected = pose.joint_positions()
    for j, name in enumerate(JOINT_NAMES):
        got = data.oMf[model.getFrameId(name)].translation
        np.testing.assert_allclose(got, expected[j], atol=1e-9, err_msg=name)
    for name, p in pose.contact_positions().items():
        got = data.oMf[model.getFrameId(f'{name}_contact')].translation
        np.testing.assert_allclose(got, p, atol=1e-9, err_msg=name)
