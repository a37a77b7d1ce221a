"""Foot planting (mocap_core.foot_plant): the two-bone inverse kinematics and the per-leg
correction that keeps standing feet where they landed under a root that moves on."""

from __future__ import annotations

import numpy as np
import pytest

from mocap_core.foot_plant import (LEGS, FootPlantConfig, FootPlanter, bounded_correction,
                                   two_bone_ik)
from mocap_core.pose import Pose
from mocap_core.rotations import axis_angle_to_quat
from mocap_core.skeleton import CONTACT_POINT_NAMES, JOINT_INDEX, Skeleton

DT = 1.0 / 30.0


def _standing_pose(root_xy=(0.0, 0.0), knee_deg=40.0) -> Pose:
    """A pose with both knees bent by ``knee_deg`` (hips flexed to match), the feet flat
    on the floor z = 0 below the hips."""
    sk = Skeleton.default()
    rot = np.zeros((sk.num_joints, 4))
    rot[:, 3] = 1.0
    a = np.radians(knee_deg)
    for side in ('left', 'right'):
        # hip flexes forward by a/2, knee back by a, ankle forward by a/2: shin and thigh
        # tilt equally, the foot stays flat
        rot[JOINT_INDEX[f'{side}_hip']] = axis_angle_to_quat(np.array([0.0, -a / 2, 0.0]))
        rot[JOINT_INDEX[f'{side}_knee']] = axis_angle_to_quat(np.array([0.0, a, 0.0]))
        rot[JOINT_INDEX[f'{side}_ankle']] = axis_angle_to_quat(np.array([0.0, -a / 2, 0.0]))
    probe = Pose(sk, rot, np.zeros(3))
    low = min(p[2] for p in probe.contact_positions().values())
    return Pose(sk, rot, np.array([root_xy[0], root_xy[1], -low]))


def _feet(pose: Pose) -> np.ndarray:
    c = pose.contact_positions()
    return np.array([c[n] for n in CONTACT_POINT_NAMES])


def _bones(pose: Pose) -> np.ndarray:
    J = pose.joint_positions()
    par = pose.skeleton.parents
    return np.array([np.linalg.norm(J[j] - J[par[j]]) for j in range(1, len(J))])


def test_two_bone_ik_reaches_the_target_keeps_the_bones_and_the_bending_side():
    hip = np.array([0.0, 0.1, 0.9])
    knee = np.array([0.08, 0.1, 0.48])                 # bent forward
    ankle = np.array([0.0, 0.1, 0.07])
    l1, l2 = np.linalg.norm(knee - hip), np.linalg.norm(ankle - knee)
    hinge = np.array([0.0, 1.0, 0.0])
    for target in ([0.15, 0.1, 0.07], [-0.2, 0.1, 0.1], [0.05, 0.2, 0.07]):
        target = np.array(target)
        k, a = two_bone_ik(hip, knee, ankle, target, hinge)
        np.testing.assert_allclose(a, target, atol=1e-9)
        assert np.linalg.norm(k - hip) == pytest.approx(l1)
        assert np.linalg.norm(a - k) == pytest.approx(l2)
        # the knee stays in front of the hip-ankle line, as it was
        u = (a - hip) / np.linalg.norm(a - hip)
        off = (k - hip) - ((k - hip) @ u) * u
        assert off[0] > 0.0
    # out of reach: the leg straightens towards the target, the bones keep their lengths
    k, a = two_bone_ik(hip, knee, ankle, np.array([0.9, 0.1, 0.07]), hinge)
    assert np.linalg.norm(a - hip) == pytest.approx(l1 + l2, rel=1e-6)
    assert np.linalg.norm(a - k) == pytest.approx(l2)


def test_bounded_correction_keeps_the_ankle_within_reach():
    hip = np.array([0.0, 0.0, 0.9])
    ankle = np.array([0.0, 0.0, 0.1])
    c = bounded_correction(ankle, hip, np.array([0.9, 0.0]), 0.85)
    assert np.linalg.norm(ankle + [c[0], c[1], 0.0] - hip) == pytest.approx(0.85)
    np.testing.assert_allclose(bounded_correction(ankle, hip, np.array([0.1, 0.0]), 0.85),
                               [0.1, 0.0])
    # already out of reach: it may come nearer, never go further
    far = np.array([0.5, 0.0, 0.1])
    np.testing.assert_allclose(bounded_correction(far, hip, np.array([-0.2, 0.0]), 0.85),
                               [-0.2, 0.0])
    assert np.linalg.norm(bounded_correction(far, hip, np.array([0.2, 0.0]), 0.85)) < 1e-9


def test_standing_feet_stay_where_they_landed_while_the_root_moves_on():
    """The input's feet slide with the root (1 cm per frame); the planted output's standing
    feet do not move, the root and the upper body are the input's, the bones keep their
    lengths, and once the feet lift they return to the input's within a few time constants."""
    planter = FootPlanter(FootPlantConfig(release_time_constant_s=0.1,
                                          double_stance_time_constant_s=0.0))
    inputs = [_standing_pose((0.01 * k, 0.0)) for k in range(16)]
    out = [planter.apply(p, DT if k else 0.0) for k, p in enumerate(inputs)]
    moved_in = np.abs(_feet(inputs[-1])[:, :2] - _feet(inputs[0])[:, :2]).max()
    moved_out = np.abs(_feet(out[-1])[:, :2] - _feet(out[0])[:, :2]).max()
    assert moved_in == pytest.approx(0.15)
    assert moved_out < 1e-3
    upper = [JOINT_INDEX[n] for n in ('pelvis', 'spine', 'neck', 'head', 'left_wrist')]
    for p, q in zip(inputs, out):
        np.testing.assert_allclose(q.root_position, p.root_position)
        np.testing.assert_allclose(q.joint_positions()[upper], p.joint_positions()[upper],
                                   atol=1e-9)
        np.testing.assert_allclose(_bones(q), _bones(p), atol=1e-9)
        np.testing.assert_allclose(_feet(q)[:, 2], _feet(p)[:, 2], atol=1e-6)  # heights kept
    assert planter.last_correction['left'] == pytest.approx(0.15, abs=1e-3)
    # lifted: every point says it does not stand; the correction decays with 0.1 s
    lifted = {n: False for n in CONTACT_POINT_NAMES}
    last = inputs[-1]
    for _ in range(30):                                    # 1 s = 10 time constants
        q = planter.apply(last, DT, lifted)
    assert np.abs(_feet(q) - _feet(last)).max() < 1e-4
    assert planter.last_correction['right'] < 0.15 * np.exp(-9.0)


def test_nothing_standing_leaves_the_pose_as_it_is():
    planter = FootPlanter()
    pose = _standing_pose()
    lifted = {n: False for n in CONTACT_POINT_NAMES}
    assert planter.apply(pose, 0.0, lifted) is pose
    raised = Pose(pose.skeleton, pose.rotations, pose.root_position + [0.0, 0.0, 0.3])
    assert planter.apply(raised, DT) is raised          # by height: 30 cm up, nothing stands


def test_a_foot_out_of_reach_slides_and_the_leg_is_not_stretched():
    """A root that runs away from a planted foot, the root not following: the correction
    stops at the leg's reach, the rest slides, and the frames are counted."""
    planter = FootPlanter(FootPlantConfig(reach=1.0, max_correction=2.0,
                                          double_stance_time_constant_s=0.0,
                                          root_follow_time_constant_s=0.0))
    out = [planter.apply(_standing_pose((0.05 * k, 0.0)), DT if k else 0.0)
           for k in range(30)]                              # 1.45 m
    J = out[-1].joint_positions()
    for (h, k, a), _ in LEGS.values():
        leg = np.linalg.norm(J[k] - J[h]) + np.linalg.norm(J[a] - J[k])
        assert np.linalg.norm(J[a] - J[h]) <= leg + 1e-9
    assert planter.limited_frames > 0
    step = np.linalg.norm(_feet(out[-1])[:, :2] - _feet(out[-2])[:, :2], axis=1)
    assert np.all(step > 0.01)                              # sliding with the root


def test_given_contacts_decide_which_points_stand():
    """Contact flags from elsewhere (the lifter's) override the height rule: a foot said to
    stand is planted, the other follows the input."""
    planter = FootPlanter()
    left_only = {'left_heel': True, 'left_toe': True, 'right_heel': False, 'right_toe': False}
    inputs = [_standing_pose((0.01 * k, 0.0)) for k in range(10)]
    out = [planter.apply(p, DT if k else 0.0, left_only) for k, p in enumerate(inputs)]
    f0, f1 = _feet(out[0]), _feet(out[-1])
    assert np.abs(f1[:2, :2] - f0[:2, :2]).max() < 1e-3               # left planted
    np.testing.assert_allclose(f1[2:], _feet(inputs[-1])[2:], atol=1e-9)  # right: the input


def test_a_root_drifting_over_two_planted_feet_is_not_followed_by_the_legs():
    """Both feet stand while the root drifts 1 cm a frame (a world path's drift under a
    person who stands still): with the double-stance leak the corrections settle near
    drift x time constant, instead of growing to the cap; one planted foot keeps all of its
    correction."""
    tau = 0.2
    planter = FootPlanter(FootPlantConfig(double_stance_time_constant_s=tau,
                                          max_correction=1.0, reach=2.0))
    for k in range(60):
        planter.apply(_standing_pose((0.01 * k, 0.0)), DT if k else 0.0)
    rate = 0.01 / DT                                          # m/s
    settled = rate * DT / (1.0 - np.exp(-DT / tau)) * np.exp(-DT / tau)
    assert planter.last_correction['left'] == pytest.approx(settled, rel=0.05)
    assert settled < 0.25                                    # 60 frames: 0.59 m of drift
    one = FootPlanter(FootPlantConfig(double_stance_time_constant_s=tau, max_correction=1.0,
                                      reach=2.0))
    left_only = {'left_heel': True, 'left_toe': True, 'right_heel': False, 'right_toe': False}
    for k in range(20):
        one.apply(_standing_pose((0.01 * k, 0.0)), DT if k else 0.0, left_only)
    assert one.last_correction['left'] == pytest.approx(0.19, abs=1e-3)


def test_a_root_that_runs_away_from_a_planted_foot_is_held_back_and_returns():
    """With ``root_follow_time_constant_s``, what the standing leg cannot reach moves the root
    instead: the planted foot does not move at all, the root stays within the leg's reach of
    it, the bones keep their lengths; once the foot lifts the root returns to the input's."""
    tau = 0.5
    planter = FootPlanter(FootPlantConfig(reach=1.0, max_correction=2.0,
                                          double_stance_time_constant_s=0.0,
                                          root_follow_time_constant_s=tau))
    left_only = {'left_heel': True, 'left_toe': True, 'right_heel': False, 'right_toe': False}
    inputs = [_standing_pose((0.05 * k, 0.0)) for k in range(30)]      # 1.45 m
    out = [planter.apply(p, DT if k else 0.0, left_only) for k, p in enumerate(inputs)]
    heel = np.array([_feet(q)[0] for q in out])
    assert np.abs(heel[1:, :2] - heel[1, :2]).max() < 1e-6               # planted throughout
    J = out[-1].joint_positions()
    (h, k, a), _ = LEGS['left']
    assert np.linalg.norm(J[a] - J[h]) <= np.linalg.norm(J[k] - J[h]) \
        + np.linalg.norm(J[a] - J[k]) + 1e-9
    behind = inputs[-1].root_position[0] - out[-1].root_position[0]
    assert behind > 1.0                                   # held back by the foot
    for q, p in zip(out, inputs):
        np.testing.assert_allclose(_bones(q), _bones(p), atol=1e-9)
        assert q.root_position[2] == pytest.approx(p.root_position[2])
    lifted = {n: False for n in CONTACT_POINT_NAMES}
    for _ in range(60):                                   # 2 s = 4 time constants
        q = planter.apply(inputs[-1], DT, lifted)
    assert inputs[-1].root_position[0] - q.root_position[0] < behind * np.exp(-3.5)
    # without it the same foot slides (the test above) and the root is the input's
    plain = FootPlanter(FootPlantConfig(reach=1.0, max_correction=2.0,
                                        double_stance_time_constant_s=0.0,
                                        root_follow_time_constant_s=0.0))
    q = [plain.apply(p, DT if k else 0.0, left_only) for k, p in enumerate(inputs)][-1]
    np.testing.assert_allclose(q.root_position, inputs[-1].root_position)
