"""The dynamic cycle: standing, dropping, friction, tracking, bad input."""

import numpy as np
import pytest

from mocap_core.pose import Pose
from mocap_core.rotations import axis_angle_to_quat, quat_to_axis_angle
from mocap_core.skeleton import JOINT_INDEX, Skeleton
from mocap_physics.cycle import InvalidInput, PhysicsCycle
from mocap_physics.cycle_params import PhysicsParams
from mocap_physics.model import SkeletonError

FPS = 30.0
MU = 0.8


@pytest.fixture(scope='module')
def skeleton():
    return Skeleton.default()


def _in_pyramid(forces, mu=MU, tol=1e-9):
    m = mu / np.sqrt(2.0)
    fz = forces[:, 2]
    return bool(np.all(fz >= -tol) and np.all(np.abs(forces[:, 0]) <= m * fz + tol)
                and np.all(np.abs(forces[:, 1]) <= m * fz + tol))


def _finite(result):
    return all(np.all(np.isfinite(x)) for x in (
        result.q, result.v, result.torques, result.contact_forces, result.center_of_mass,
        result.residual_root, result.pose.rotations, result.pose.root_position))


DROP_MODES = {
    'paper': dict(dynamics='paper'),
    'paper, passive root': dict(dynamics='paper', root_residual=0.0),
    'whole body': dict(),
    'whole body, no residual': dict(residual_bound=0.0, residual_moment_bound=0.0),
}


@pytest.mark.parametrize('mode', ['whole body', 'paper', 'paper, passive root'])
def test_standing_weight_supported_and_still(skeleton, mode):
    """Rest pose on the floor, 4 contacts, 2 s: vertical GRF = body weight, no drift."""
    cyc = PhysicsCycle(skeleton, PhysicsParams(**DROP_MODES[mode]))
    rest = Pose.rest(skeleton)
    q_rest = cyc.model.pose_to_q(rest)
    fz = []
    for i in range(int(2 * FPS)):
        r = cyc.step(rest, i / FPS, [1, 1, 1, 1])
        assert _finite(r)
        assert _in_pyramid(r.contact_forces)
        fz.append(r.contact_forces[:, 2].sum())
        assert r.contact_heights.min() > -1e-3
    W = cyc.model.weight
    fz = np.array(fz[1:])
    assert np.all(np.abs(fz / W - 1.0) < 0.03), (fz / W).min()
    assert np.all(r.contact_active)
    # both feet carry about half of it; the residual root force is negligible
    assert r.feet['left'].force[2] == pytest.approx(W / 2, rel=0.03)
    assert r.feet['right'].force[2] == pytest.approx(W / 2, rel=0.03)
    assert r.residual_ratio < 0.02
    assert np.abs(r.q[:3] - q_rest[:3]).max() < 5e-3            # stays put (m)
    assert np.abs(r.pose.joint_positions() - rest.joint_positions()).max() < 5e-3
    assert np.abs(r.v[:6]).max() < 0.05
    assert cyc.stats.fallbacks == 0 and cyc.stats.grf_failures == 0
    # standing joint torques: the knees and hips hold the body (compensated for the GRF)
    assert np.all(np.isfinite(r.joint_torques))


@pytest.mark.parametrize('mode', list(DROP_MODES))
def test_drop_never_below_floor(skeleton, mode):
    """Start 0.3 m above the floor (target on the floor): the feet never go more than 5 mm
    below it. Without a root residual the body falls freely (only gravity) and lands."""
    cyc = PhysicsCycle(skeleton, PhysicsParams(**DROP_MODES[mode]))
    free_fall = mode in ('paper, passive root', 'whole body, no residual')
    rest = Pose.rest(skeleton)
    q0 = cyc.model.pose_to_q(rest)
    q0[2] += 0.3
    cyc.set_state(q0, np.zeros(cyc.model.nv), stamp=0.0)
    lowest, speeds = [], []
    for i in range(1, int(1.5 * FPS)):
        r = cyc.step(rest, i / FPS, [1, 1, 1, 1])
        assert _finite(r)
        assert r.status == 'ok'
        lowest.append(r.contact_heights.min())
        speeds.append(r.v[2])
    assert min(lowest) > -0.005
    assert abs(lowest[-1]) < 0.005                              # landed, on the floor
    if free_fall:
        # free fall: about g for the first frames, then the landing
        assert speeds[3] == pytest.approx(-9.81 * 4 / FPS, rel=0.05)
        assert min(speeds) < -2.0
        assert cyc.stats.penetration_solves > 0
        W = cyc.model.weight
        assert r.contact_forces[:, 2].sum() == pytest.approx(W, rel=0.05)


@pytest.mark.parametrize('dynamics', ['whole_body', 'paper'])
def test_penetrating_target_is_corrected(skeleton, dynamics):
    """A target whose feet are 4 cm under the floor: the output stays above -5 mm."""
    cyc = PhysicsCycle(skeleton, PhysicsParams(dynamics=dynamics))
    rest = Pose.rest(skeleton)
    sunk = Pose(skeleton, rest.rotations, rest.root_position - [0, 0, 0.04])
    for i in range(int(FPS)):
        r = cyc.step(sunk, i / FPS, [1, 1, 1, 1])
        assert r.contact_heights.min() > -0.005
        guard = cyc.model.guard_positions(r.q)[:, 2]
        assert guard.min() > -0.005, dict(zip(cyc.model.guard_names, guard))
    if dynamics == 'paper':
        assert cyc.stats.penetration_solves > 0


def _noisy_motion(skeleton, n, rng):
    """Rest pose with smooth random joint motion and frame jitter, feet on the floor."""
    rest = Pose.rest(skeleton)
    t = np.arange(n) / FPS
    freqs = rng.uniform(0.3, 2.0, size=(skeleton.num_joints, 3))
    phases = rng.uniform(0, 2 * np.pi, size=(skeleton.num_joints, 3))
    amp = np.full((skeleton.num_joints, 3), 0.25)
    amp[0] = 0.05
    for name in ('left_ankle', 'right_ankle', 'left_toe', 'right_toe'):
        amp[JOINT_INDEX[name]] = 0.05
    poses = []
    for k in range(n):
        aa = amp * np.sin(2 * np.pi * freqs * t[k] + phases) + 0.02 * rng.normal(size=amp.shape)
        root = rest.root_position + 0.05 * np.sin(2 * np.pi * 0.7 * t[k] + np.arange(3)) \
            + 0.01 * rng.normal(size=3)
        poses.append(Pose(skeleton, axis_angle_to_quat(aa), root))
    return poses


def test_grf_always_inside_friction_pyramid(skeleton):
    rng = np.random.default_rng(5)
    cyc = PhysicsCycle(skeleton)
    active_frames = 0
    for i, pose in enumerate(_noisy_motion(skeleton, 60, rng)):
        probs = (rng.random(4) < 0.8).astype(float)
        r = cyc.step(pose, i / FPS, probs)
        assert _finite(r)
        assert _in_pyramid(r.contact_forces)
        assert np.all(r.contact_forces[probs == 0] == 0)        # no force without contact
        assert r.contact_heights.min() > -0.005
        active_frames += bool(r.contact_active.any())
    assert active_frames > 30
    assert cyc.stats.grf_failures == 0 and cyc.stats.fallbacks == 0


def _fit_sine(t, x, f):
    B = np.stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t), np.ones_like(t)], 1)
    c = np.linalg.lstsq(B, x, rcond=None)[0]
    return np.hypot(c[0], c[1]), np.arctan2(c[1], c[0])


def test_fast_motion_tracked_with_bounded_delay(skeleton):
    """Left knee flexing 0-1.2 rad and right arm swinging +-0.8 rad at 2 Hz (standing on the
    right foot): amplitude kept within 10 %, delay under 30 ms (about one frame)."""
    f = 2.0
    cyc = PhysicsCycle(skeleton)
    t_all = np.arange(0, 3.0, 1 / FPS)
    sim, tgt = [], []
    for t in t_all:
        rot = np.zeros((skeleton.num_joints, 4))
        rot[:, 3] = 1.0
        knee = 0.6 * (1 - np.cos(2 * np.pi * f * t))
        arm = 0.8 * np.sin(2 * np.pi * f * t)
        rot[JOINT_INDEX['left_knee']] = axis_angle_to_quat(np.array([0.0, knee, 0.0]))
        rot[JOINT_INDEX['right_shoulder']] = axis_angle_to_quat(np.array([0.0, 0.0, arm]))
        target = Pose(skeleton, rot, [0, 0, skeleton.rest_root_height()])
        r = cyc.step(target, t, [0, 0, 1, 1])
        assert _finite(r)
        sim.append([quat_to_axis_angle(r.pose.rotations[JOINT_INDEX['left_knee']])[1],
                    quat_to_axis_angle(r.pose.rotations[JOINT_INDEX['right_shoulder']])[2]])
        tgt.append([knee, arm])
    sim, tgt = np.array(sim), np.array(tgt)
    steady = t_all >= 1.0
    for k in range(2):
        a_sim, p_sim = _fit_sine(t_all[steady], sim[steady, k], f)
        a_tgt, p_tgt = _fit_sine(t_all[steady], tgt[steady, k], f)
        delay = (p_tgt - p_sim) / (2 * np.pi * f)
        assert 0.9 < a_sim / a_tgt < 1.1, (k, a_sim / a_tgt)
        assert -0.005 < delay < 0.030, (k, delay)
        assert np.abs(sim[steady, k] - tgt[steady, k]).max() < 0.2
    assert cyc.stats.fallbacks == 0


def test_a_moving_cameras_frames_take_the_moving_gains(skeleton):
    """kp_joint_moving / kd_joint_moving: the arm swing of the test above trails its target
    by less in frames that take the stiffer PD (moving_gains, a camera whose motion is not
    carried), and with those parameters 0 the frames are simulated exactly alike."""
    f = 2.0

    def run(params, moving):
        cyc = PhysicsCycle(skeleton, params=params)
        err = []
        for t in np.arange(0, 2.0, 1 / FPS):
            rot = np.zeros((skeleton.num_joints, 4))
            rot[:, 3] = 1.0
            arm = 0.8 * np.sin(2 * np.pi * f * t)
            rot[JOINT_INDEX['right_shoulder']] = axis_angle_to_quat(np.array([0.0, 0.0, arm]))
            r = cyc.step(Pose(skeleton, rot, [0, 0, skeleton.rest_root_height()]), t,
                         [1, 1, 1, 1], moving_gains=moving)
            assert _finite(r)
            if t >= 1.0:
                err.append(abs(quat_to_axis_angle(
                    r.pose.rotations[JOINT_INDEX['right_shoulder']])[2] - arm))
        return np.array(err)

    stiff = PhysicsParams(kp_joint_moving=8100.0, kd_joint_moving=180.0)
    still, moving = run(stiff, False), run(stiff, True)
    assert moving.mean() < 0.8 * still.mean(), (moving.mean(), still.mean())
    plain = PhysicsParams(kp_joint_moving=0.0, kd_joint_moving=0.0)
    np.testing.assert_array_equal(run(plain, True), run(plain, False))
    with pytest.raises(ValueError, match='kp_joint_moving'):
        PhysicsCycle(params=PhysicsParams(kp_joint_moving=-1.0))


def test_nan_input_holds_last_target(skeleton):
    cyc = PhysicsCycle(skeleton)
    rest = Pose.rest(skeleton)
    with pytest.raises(InvalidInput):
        cyc.step(np.full(cyc.model.nq, np.nan), 0.0)           # nothing to hold yet
    r0 = cyc.step(rest, 0.0, [1, 1, 1, 1])
    assert r0.status == 'first_frame'
    bad = cyc.model.pose_to_q(rest)
    bad[10] = np.nan
    r1 = cyc.step(bad, 1 / FPS, [np.nan, 1, 1, 1])
    assert 'invalid_input' in r1.status and _finite(r1)
    np.testing.assert_allclose(r1.q[:3], r0.q[:3], atol=1e-3)
    r2 = cyc.step(np.zeros(5), 2 / FPS)                          # wrong size
    assert 'invalid_input' in r2.status and _finite(r2)
    assert cyc.stats.invalid_inputs == 3
    r3 = cyc.step(rest, 3 / FPS)
    assert r3.status == 'ok'


def test_time_jump_reinitialises(skeleton):
    cyc = PhysicsCycle(skeleton)
    rest = Pose.rest(skeleton)
    cyc.step(rest, 0.0)
    moved = Pose(skeleton, rest.rotations, rest.root_position + [1.0, 0.0, 0.0])
    r = cyc.step(moved, 5.0)                                     # 5 s gap
    assert r.status == 'time_jump'
    np.testing.assert_allclose(r.q[:3], moved.root_position, atol=1e-2)
    r = cyc.step(moved, 4.0)                                     # backwards
    assert r.status == 'time_jump'
    assert cyc.stats.time_jumps == 2


def test_solver_failure_falls_back_to_target(skeleton, monkeypatch):
    cyc = PhysicsCycle(skeleton)
    rest = Pose.rest(skeleton)
    sunk = Pose(skeleton, rest.rotations, rest.root_position - [0, 0, 0.02])
    cyc.step(rest, 0.0, [1, 1, 1, 1])
    from mocap_physics.qp import PenetrationResult

    def failing(v, A, b, **kw):
        return PenetrationResult(v.copy(), np.zeros(len(b)), ok=False, status='forced failure',
                                 solved=True)
    monkeypatch.setattr(cyc.pen, 'solve', failing)
    r = cyc.step(sunk, 1 / FPS, [1, 1, 1, 1])
    assert r.status == 'fallback' and _finite(r)
    assert 'forced failure' in ' '.join(r.messages)
    # the fallback is the target, lifted out of the floor
    assert r.contact_heights.min() == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(r.pose.rotations, sunk.rotations, atol=1e-9)
    assert cyc.stats.fallbacks == 1 and cyc.stats.penetration_failures == 1
    monkeypatch.undo()
    assert cyc.step(rest, 2 / FPS, [1, 1, 1, 1]).status == 'ok'


def test_grf_solver_failure_counted(skeleton, monkeypatch):
    cyc = PhysicsCycle(skeleton, PhysicsParams(dynamics='paper'))
    rest = Pose.rest(skeleton)
    cyc.step(rest, 0.0, [1, 1, 1, 1])
    from mocap_physics.qp import GrfResult

    def failing(tau_root, J, active, weight):
        return GrfResult(np.zeros((4, 3)), np.array(tau_root), ok=False, status='forced')
    monkeypatch.setattr(cyc.grf, 'solve', failing)
    r = cyc.step(rest, 1 / FPS, [1, 1, 1, 1])
    assert r.grf_failures == cyc.params.substeps and _finite(r)
    assert np.all(r.contact_forces == 0)


def test_whole_body_solver_failure_counted(skeleton, monkeypatch):
    """A failed inverse-dynamics QP: the PD drives that sub-step, no force, counted."""
    cyc = PhysicsCycle(skeleton)
    rest = Pose.rest(skeleton)
    cyc.step(rest, 0.0, [1, 1, 1, 1])
    from mocap_physics.wbid import WbidResult

    def failing(M, h, a_des, Jc, *args, **kwargs):
        nv = len(h)
        return WbidResult(np.zeros(nv), np.zeros(nv - 6), np.zeros((4, 3)), np.zeros(6),
                          np.zeros(4, bool), np.zeros(4, bool), ok=False, status='forced')
    monkeypatch.setattr(cyc.wbid, 'solve', failing)
    r = cyc.step(rest, 1 / FPS, [1, 1, 1, 1])
    assert r.grf_failures == cyc.params.substeps and _finite(r)
    assert np.all(r.contact_forces == 0)
    assert cyc.stats.grf_failures == cyc.params.substeps
    assert r.contact_heights.min() > -0.005
    monkeypatch.undo()
    assert cyc.step(rest, 2 / FPS, [1, 1, 1, 1]).grf_failures == 0


def test_skeleton_change_rebuilds_model(skeleton):
    cyc = PhysicsCycle()
    with pytest.raises(InvalidInput):
        cyc.step(np.zeros(75), 0.0)                              # no skeleton yet
    cyc.step(Pose.rest(skeleton), 0.0)
    # a lifter refining bone lengths by 1 mm does not rebuild the model
    nudged = Skeleton.from_lengths_dict({'thigh': 0.431})
    assert cyc.step(Pose.rest(nudged), 1 / FPS).status == 'ok'
    assert cyc.stats.model_builds == 1
    tall = Skeleton.from_lengths_dict({'thigh': 0.5, 'shin': 0.5})
    r = cyc.step(Pose.rest(tall), 2 / FPS)
    assert 'skeleton_changed' in r.status and cyc.stats.model_builds == 2
    assert cyc.model.skeleton is tall and cyc.stats.reinitialisations == 1  # state kept
    for i in range(3, 30):
        r = cyc.step(Pose.rest(tall), i / FPS, [1, 1, 1, 1])
        assert r.contact_heights.min() > -0.005
    assert r.q[2] == pytest.approx(tall.rest_root_height(), abs=2e-3)
    with pytest.raises(SkeletonError):
        cyc.step(Pose.rest(Skeleton.from_lengths_dict({'shin': 1e-5})), 31 / FPS)
    assert cyc.model.skeleton is tall                            # the old model is kept


def test_bad_parameters_rejected():
    with pytest.raises(ValueError, match='substeps'):
        PhysicsCycle(params=PhysicsParams(substeps=0))
    with pytest.raises(ValueError, match='penetration_metric'):
        PhysicsCycle(params=PhysicsParams(penetration_metric='l1'))
