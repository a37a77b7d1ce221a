"""The two QPs solved with OSQP's own API against the same problems stated in cvxpy."""

import cvxpy as cp
import numpy as np
import pinocchio as pin
import pytest
from scipy.linalg import cho_factor, cho_solve

from mocap_core.pose import Pose
from mocap_core.rotations import quat_normalize
from mocap_core.skeleton import Skeleton
from mocap_physics.model import PhysicsModel
from mocap_physics.qp import GrfQP, PenetrationQP

MU = 0.8


@pytest.fixture(scope='module')
def model():
    return PhysicsModel(Skeleton.default(), 70.0)


def _contact_jacobians(model, q):
    data = model.data
    pin.computeJointJacobians(model.model, data, q)
    pin.updateFramePlacements(model.model, data)
    return np.array([pin.getFrameJacobian(model.model, data, f,
                                          pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[:3]
                     for f in model.contact_frame_ids])


def _perturbed_rest(model, rng, scale=0.15):
    pose = Pose.rest(model.skeleton)
    rot = quat_normalize(np.array(pose.rotations) + scale * rng.normal(size=pose.rotations.shape)
                         * np.array([1, 1, 1, 0]))
    return model.pose_to_q(Pose(model.skeleton, rot, pose.root_position))


def grf_cvxpy(tau_root, Jroot, active, lam_prev, smoothness, regularization, mu=MU):
    """Eq. 8 + 11 with the friction pyramid (eq. 9 inscribed), stated in newtons."""
    idx = np.flatnonzero(active)
    lam = cp.Variable((len(idx), 3))
    A = np.concatenate([Jroot[c].T for c in idx], axis=1)           # (6, 3n) = J_1^T
    m = mu / np.sqrt(2.0)
    objective = (cp.sum_squares(tau_root - A @ cp.reshape(lam, (3 * len(idx),), order='C'))
                 + smoothness * cp.sum_squares(lam - lam_prev[idx])
                 + regularization * cp.sum_squares(lam))
    cons = [lam[:, 2] >= 0, cp.abs(lam[:, 0]) <= m * lam[:, 2], cp.abs(lam[:, 1]) <= m * lam[:, 2]]
    cp.Problem(cp.Minimize(objective), cons).solve(solver=cp.CLARABEL)
    out = np.zeros((len(active), 3))
    out[idx] = lam.value
    return out


def _in_pyramid(forces, mu=MU, tol=1e-9):
    m = mu / np.sqrt(2.0)
    fz = forces[:, 2]
    return bool(np.all(fz >= -tol) and np.all(np.abs(forces[:, 0]) <= m * fz + tol)
                and np.all(np.abs(forces[:, 1]) <= m * fz + tol)
                and np.all(np.linalg.norm(forces[:, :2], axis=1) <= mu * fz + tol))


@pytest.mark.parametrize('case', range(6))
def test_grf_matches_cvxpy(model, case):
    rng = np.random.default_rng(10 + case)
    q = _perturbed_rest(model, rng)
    J = _contact_jacobians(model, q)[:, :, :6]
    W = model.weight
    # root force: mostly weight support plus a random push (large pushes hit the pyramid)
    tau_root = np.concatenate([[0, 0, W], np.zeros(3)]) + W * rng.normal(size=6) * [0.6, 0.6, 0.3,
                                                                                    0.1, 0.1, 0.1]
    active = rng.random(4) < 0.8
    active[case % 4] = True
    qp = GrfQP(4, MU, smoothness=0.1, regularization=1e-4)
    prev = np.abs(rng.normal(size=(4, 3))) * [0.1, 0.1, 0.3]        # units of body weight
    qp.prev[:] = prev
    res = qp.solve(tau_root, J, active, W)
    assert res.ok, res.status
    # the cvxpy problem in newtons: weights scale with W^2 exactly like the scaled problem
    ref = grf_cvxpy(tau_root, J, active, prev * W, 0.1, 1e-4)
    np.testing.assert_allclose(res.forces, ref, atol=1e-5 * W)   # 7 mN
    assert np.all(res.forces[~active] == 0)
    assert _in_pyramid(res.forces)
    A = np.concatenate([J[c].T for c in np.flatnonzero(active)], axis=1)
    np.testing.assert_allclose(res.residual, tau_root - A @ res.forces[active].reshape(-1),
                               atol=1e-9)


def test_grf_pyramid_is_binding_for_a_sideways_push(model):
    """A large horizontal demand is limited by friction: the solution sits on the pyramid."""
    q = model.pose_to_q(Pose.rest(model.skeleton))
    J = _contact_jacobians(model, q)[:, :, :6]
    W = model.weight
    tau_root = np.array([2.0 * W, 0.0, W, 0.0, 0.0, 0.0])     # 2 g sideways: beyond mu = 0.8
    res = GrfQP(4, MU).solve(tau_root, J, np.ones(4, bool), W)
    assert res.ok
    assert _in_pyramid(res.forces)
    total = res.forces.sum(axis=0)
    assert total[0] == pytest.approx(MU / np.sqrt(2) * total[2], rel=1e-3)
    assert np.linalg.norm(res.residual[:3]) > 0.5 * W        # the rest is residual root force


def test_grf_no_contact(model):
    res = GrfQP().solve(np.ones(6), np.zeros((4, 3, 6)), np.zeros(4, bool), 700.0)
    assert res.ok and np.all(res.forces == 0) and np.all(res.residual == 1.0)


def penetration_cvxpy(v, A, b, W):
    x = cp.Variable(len(v))
    L = np.linalg.cholesky(W)
    cp.Problem(cp.Minimize(0.5 * cp.sum_squares(L.T @ (x - v))), [A @ x >= b]).solve(
        solver=cp.CLARABEL)
    return x.value


@pytest.mark.parametrize('metric', ['mass', 'diagonal', 'identity'])
def test_penetration_matches_cvxpy(model, metric):
    rng = np.random.default_rng(3)
    dt = 1.0 / 180
    for _ in range(4):
        q = _perturbed_rest(model, rng, scale=0.03)
        q[2] -= model.contact_positions(q)[:, 2].min() + 0.005  # lowest point 5 mm under
        J = _contact_jacobians(model, q)
        z = model.contact_positions(q)[:, 2]
        v = rng.normal(size=model.nv) * 0.5
        v[2] = -1.5                                       # moving down fast
        A, b = J[:, 2, :], np.minimum(-z / dt, 0.5)
        M = model.mass_matrix(q)
        chol = cho_factor(M)
        d = np.diag(M).copy()
        W, solve_metric, scale = {
            'mass': (M, lambda X, _c=chol: cho_solve(_c, X), 70.0),
            'diagonal': (np.diag(d), lambda X, _d=d: X / _d[:, None], 70.0),
            'identity': (np.eye(model.nv), None, 1.0)}[metric]
        qp = PenetrationQP(metric=metric)
        res = qp.solve(v, A, b, solve_metric=solve_metric, scale=scale)
        assert res.ok and res.solved, res.status
        assert np.all(A @ res.velocity >= b - 1e-6)
        ref = penetration_cvxpy(v, A, b, W)
        np.testing.assert_allclose(res.velocity, ref, atol=1e-4)
        assert np.all(res.impulses >= 0)


def test_penetration_feasible_velocity_unchanged(model):
    q = model.pose_to_q(Pose.rest(model.skeleton))
    J = _contact_jacobians(model, q)
    v = np.zeros(model.nv)
    v[2] = 0.3                                             # moving up: nothing to correct
    res = PenetrationQP().solve(v, J[:, 2, :], np.zeros(4))
    assert res.ok and not res.solved
    np.testing.assert_array_equal(res.velocity, v)


@pytest.mark.parametrize('metric', ['diagonal', 'identity'])
def test_penetration_with_stick_rows_matches_cvxpy(model, metric):
    """Inequality rows (no penetration) plus equality rows (foot stick: the heel's x, y and
    z, the toe's z and across-foot velocity) against cvxpy."""
    rng = np.random.default_rng(5)
    dt = 1.0 / 180
    for _ in range(3):
        q = _perturbed_rest(model, rng, scale=0.03)
        q[2] -= model.contact_positions(q)[:, 2].min() + 0.003
        J = _contact_jacobians(model, q)
        z = model.contact_positions(q)[:, 2]
        v = rng.normal(size=model.nv) * 0.5
        A, b = J[2:, 2, :], np.minimum(-z[2:] / dt, 0.5)              # right foot: inequality
        E = np.stack([J[0, 0], J[0, 1], J[0, 2], J[1, 2], J[1, 1]])    # left foot stuck
        e = np.array([0.01, -0.02, 0.0, 0.0, 0.005])
        M = model.mass_matrix(q)
        d = np.diag(M).copy()
        W, solve_metric, scale = {
            'diagonal': (np.diag(d), lambda X, _d=d: X / _d[:, None], 70.0),
            'identity': (np.eye(model.nv), None, 1.0)}[metric]
        res = PenetrationQP(metric=metric).solve(v, A, b, solve_metric=solve_metric,
                                                 scale=scale, A_eq=E, b_eq=e)
        assert res.ok and res.solved, res.status
        np.testing.assert_allclose(E @ res.velocity, e, atol=1e-6)
        assert np.all(A @ res.velocity >= b - 1e-6)
        x = cp.Variable(model.nv)
        L = np.linalg.cholesky(W)
        cp.Problem(cp.Minimize(0.5 * cp.sum_squares(L.T @ (x - v))),
                   [A @ x >= b, E @ x == e]).solve(solver=cp.CLARABEL)
        np.testing.assert_allclose(res.velocity, x.value, atol=1e-4)
        assert len(res.impulses) == len(b) + len(e) and np.all(res.impulses[:len(b)] >= 0)


def _sinking_feet(model):
    """The rest pose 4 mm below the floor, falling at 1 m/s: (contact Jacobians (4, 3, nv),
    velocity (nv,))."""
    q = model.pose_to_q(Pose.rest(model.skeleton))
    q[2] -= 0.004
    v = np.zeros(model.nv)
    v[2] = -1.0
    return _contact_jacobians(model, q), v


def test_penetration_clarabel_second_chance(model, monkeypatch):
    """DAQP missing and OSQP not converging: Clarabel solves the same dual, to the same
    velocity as DAQP (the first solver)."""
    import mocap_physics.qp as qp_module
    J, v = _sinking_feet(model)
    first = PenetrationQP().solve(v, J[:, 2, :], np.full(4, 0.1))
    assert first.ok and first.status == 'daqp solved', first.status
    monkeypatch.setattr(qp_module, 'daqp', None)
    qp = PenetrationQP(max_iter=1)
    res = qp.solve(v, J[:, 2, :], np.full(4, 0.1))
    assert res.ok, res.status
    assert qp.second_chances == 1 and 'clarabel' in res.status
    assert np.all(J[:, 2, :] @ res.velocity >= 0.1 - 1e-6)
    np.testing.assert_allclose(res.velocity, first.velocity, atol=1e-5)


def test_penetration_daqp_off_the_constraints_falls_back(model, monkeypatch):
    """A DAQP answer that leaves a constraint violated is not taken: OSQP solves the dual
    (with the exact refinement on its support) and the rows hold."""
    import osqp

    J, v = _sinking_feet(model)
    good = PenetrationQP().solve(v, J[:, 2, :], np.full(4, 0.1))
    monkeypatch.setattr(PenetrationQP, '_daqp', staticmethod(
        lambda P, q, m_eq: (np.zeros(len(q)), osqp.SolverStatus.OSQP_SOLVED, 'daqp solved')))
    res = PenetrationQP().solve(v, J[:, 2, :], np.full(4, 0.1))
    assert res.ok and 'off the constraints' in res.status, res.status
    assert np.all(J[:, 2, :] @ res.velocity >= 0.1 - 1e-6)
    np.testing.assert_allclose(res.velocity, good.velocity, atol=1e-5)


def test_grf_moment_weight(model):
    """w_m = 1 is eq. 8; a smaller w_m lets the root moment go unexplained first."""
    q = model.pose_to_q(Pose.rest(model.skeleton))
    J = _contact_jacobians(model, q)[:, :, :6]
    W = model.weight
    tau_root = np.array([0.0, 0.0, W, 0.0, 80.0, 0.0])    # weight + a pitch moment
    full = GrfQP(4, MU).solve(tau_root, J, np.ones(4, bool), W)
    light = GrfQP(4, MU, moment_weight=0.01).solve(tau_root, J, np.ones(4, bool), W)
    assert full.ok and light.ok
    assert abs(light.residual[2]) <= abs(full.residual[2]) + 1e-6
    assert np.linalg.norm(light.residual[3:]) >= np.linalg.norm(full.residual[3:]) - 1e-6
    with pytest.raises(ValueError):
        GrfQP(moment_weight=0.0)
