"""Foot stick, floor-frame changes and friction-cone markers of the cycle."""

import numpy as np
import pytest

from mocap_core.pose import Pose
from mocap_core.rotations import axis_angle_to_quat
from mocap_core.skeleton import Skeleton
from mocap_physics.cycle import PhysicsCycle
from mocap_physics.cycle_params import PhysicsParams
from mocap_physics.floor import FloorFrame
from mocap_physics.markers import friction_cone_lines

FPS = 30.0


@pytest.fixture(scope='module')
def skeleton():
    return Skeleton.default()


def _jittered_standing(skeleton, n=90, seed=0):
    """Standing target whose root jitters 1.5 cm horizontally (lifter-like)."""
    rng = np.random.default_rng(seed)
    rest = Pose.rest(skeleton)
    out = []
    for _ in range(n):
        root = rest.root_position + np.array([0.015, 0.015, 0.0]) * rng.normal(size=3)
        rot = np.array(rest.rotations)
        rot[0] = axis_angle_to_quat(np.radians(2.0) * rng.normal(size=3))
        out.append(Pose(skeleton, rot, root))
    return out


def _skating(cyc, targets):
    prev, slide = None, []
    for i, t in enumerate(targets):
        r = cyc.step(t, i / FPS, [1, 1, 1, 1])
        assert np.all(np.isfinite(r.q)) and r.status in ('ok', 'first_frame')
        pts = np.array(list(r.pose.contact_positions().values()))
        if prev is not None and i > 10:
            slide.append(np.linalg.norm(pts[:, :2] - prev[:, :2], axis=1).mean())
        prev = pts
    return np.mean(slide), r


def test_stick_cuts_skating_of_jittered_standing(skeleton):
    targets = _jittered_standing(skeleton)
    off, _ = _skating(PhysicsCycle(skeleton, PhysicsParams(dynamics='paper',
                                                           foot_stick=False)), targets)
    cyc = PhysicsCycle(skeleton, PhysicsParams(dynamics='paper', foot_stick=True))
    on, r = _skating(cyc, targets)
    assert on < 0.5 * off, (on, off)
    # the target's feet jitter by up to ~5 cm: with a longer release the feet stay put
    held, _ = _skating(PhysicsCycle(skeleton, PhysicsParams(dynamics='paper',
                                                            stick_release=0.2)), targets)
    assert held < 1e-3                                  # under a millimetre per frame
    assert r.contact_stuck.all() and cyc.stats.stick_failures == 0
    assert r.contact_heights.min() > -1e-3
    # the GRF still holds the body, inside the friction cone
    assert cyc.stats.cone_violations == 0
    assert r.contact_forces[:, 2].sum() == pytest.approx(cyc.model.weight, rel=0.3)


def test_stick_releases_a_sliding_foot(skeleton):
    """A target whose feet slide 1 m at 0.5 m/s while 'in contact' (a wrong contact): the
    anchors are dragged along and the simulated feet follow at stick_speed (0.2 m/s)."""
    cyc = PhysicsCycle(skeleton, PhysicsParams(dynamics='paper', stick_release=0.05))
    rest = Pose.rest(skeleton)
    feet0 = None
    for i in range(60):
        root = rest.root_position + np.array([i / 60.0, 0.0, 0.0])
        r = cyc.step(Pose(skeleton, rest.rotations, root), i / FPS, [1, 1, 1, 1])
        feet = np.array(list(r.pose.contact_positions().values()))
        feet0 = feet if feet0 is None else feet0
    assert r.q[0] > 0.7                                  # target: 0.98 m
    moved = feet[:, 0] - feet0[:, 0]
    assert np.all(moved > 0.3) and np.all(moved < 0.45)  # ~stick_speed x 2 s
    assert r.contact_stuck.all() and np.all(np.isfinite(r.q))


def test_no_stick_without_contact_or_with_passive_root(skeleton):
    targets = _jittered_standing(skeleton, n=20)
    cyc = PhysicsCycle(skeleton, PhysicsParams(dynamics='paper'))
    for i, t in enumerate(targets):
        r = cyc.step(t, i / FPS, [0, 0, 0, 0])
    assert not r.contact_stuck.any()
    cyc = PhysicsCycle(skeleton, PhysicsParams(dynamics='paper', root_residual=0.0))
    for i, t in enumerate(targets):
        r = cyc.step(t, i / FPS, [1, 1, 1, 1])
    assert not r.contact_stuck.any()


def test_change_frame_keeps_the_pose(skeleton):
    """Re-expressing the state in a new floor frame changes only the root placement."""
    cyc = PhysicsCycle(skeleton, PhysicsParams(dynamics='paper'))
    targets = _jittered_standing(skeleton, n=10)
    for i, t in enumerate(targets):
        r = cyc.step(t, i / FPS, [1, 1, 1, 1])
    before = r.pose.joint_positions()
    delta = FloorFrame(np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]), np.array([0.3, -0.2, 0]))
    cyc.change_frame(delta.rotation, delta.translation)
    q, v = cyc.state
    after = cyc.model.q_to_pose(q).joint_positions()
    np.testing.assert_allclose(after, delta.transform_points(before), atol=1e-9)
    assert cyc.stats.frame_changes == 1
    r = cyc.step(delta.transform_pose(targets[-1]), 10 / FPS, [1, 1, 1, 1])
    assert r.status == 'ok'
    # one more frame towards the (jittering) target: the pose continues, no jump
    np.testing.assert_allclose(r.pose.joint_positions(), delta.transform_points(before),
                               atol=0.05)


def test_a_small_frame_change_carries_the_anchors_a_large_one_drops_them(skeleton):
    """A step of a floor being blended in (1 deg, 2 cm) moves the foot-stick anchors with the
    frame, so the stuck feet stay where they are in the world; a large change (the 90 deg
    turn above) drops them."""
    from mocap_core.rotations import axis_angle_to_matrix

    def standing(cyc):
        targets = _jittered_standing(skeleton, n=20, seed=3)
        for i, t in enumerate(targets):
            r = cyc.step(t, i / FPS, [1, 1, 1, 1])
        assert r.contact_stuck.all()
        return targets

    cyc = PhysicsCycle(skeleton, PhysicsParams(stick_release=0.2))
    standing(cyc)
    anchors = cyc._anchor.copy()
    # the old and new floor frames of a camera, as OnlinePhysics re-expresses the state: a
    # tilt of 1 deg and a floor 2 cm lower, delta = new o old^-1
    old = FloorFrame.from_camera_height_pitch(1.5, np.radians(20.0))
    new = FloorFrame(axis_angle_to_matrix(np.radians([0.6, -0.8, 0.3])) @ old.rotation,
                     old.translation + np.array([0.01, -0.02, 0.02]))
    delta = new.compose(old.inverse())
    cyc.change_frame(delta.rotation, delta.translation)
    assert cyc._anchored.all()
    # each anchor is the same point of the camera's world, seen in the new floor frame
    # (to within the height a 1-deg tilt gives a floor point: the anchors are 2D)
    points = np.c_[anchors, np.zeros(len(anchors))]
    same = new.transform_points(old.inverse().transform_points(points))
    np.testing.assert_allclose(cyc._anchor, same[:, :2], atol=1e-3)
    assert np.abs(cyc._anchor - anchors).max() > 0.01     # they did move
    big = PhysicsCycle(skeleton, PhysicsParams(stick_release=0.2))
    standing(big)
    big.change_frame(np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]), np.array([0.3, -0.2, 0]))
    assert not big._anchored.any()


def test_friction_cone_lines_lie_on_the_cone():
    apex = np.array([[0.1, 0.2, 0.0], [0.5, -0.1, 0.0]])
    pts = friction_cone_lines(apex, 0.8, height=0.1, segments=8)
    assert pts.shape == (2 * 2 * 2 * 8, 3)
    rim = pts[1::2]                       # segment ends: the rim of each cone
    for k, a in enumerate(apex):
        d = rim[k * 16:(k + 1) * 16] - a
        np.testing.assert_allclose(d[:, 2], 0.1)
        np.testing.assert_allclose(np.linalg.norm(d[:, :2], axis=1), 0.08)
