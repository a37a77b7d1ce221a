"""Physics in the first image's frame (``derotate_camera``): the camera's rotation taken out
of the input, so that a turning camera does not move the feet."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocap_core.pose import Pose
from mocap_core.rotations import axis_angle_to_matrix, matrix_to_quat
from mocap_core.skeleton import Skeleton
from mocap_physics.camera_rotation import CameraRotations, floor_in_camera, rotate_pose
from mocap_physics.floor import FloorFrame

BAG = Path(__file__).resolve().parents[3] / 'bags' / 'gt_bandai_walk_exhausted'


def _rot(axis, angle):
    return axis_angle_to_matrix(np.asarray(axis, float) / np.linalg.norm(axis) * angle)


def test_rotations_by_stamp_held_and_restarted():
    rots = CameraRotations()
    assert np.allclose(rots.at(5)[0], np.eye(3)) and not rots.at(5)[1]
    A, B = _rot([0, 1, 0], 0.2), _rot([0, 1, 0], 0.3)
    assert rots.add(10, 'rotating', A) and rots.add(20, 'moving', B)
    assert not rots.add(30, 'unknown', np.eye(3))               # the estimator lost track
    assert not rots.add(40, 'rotating', np.full((3, 3), np.nan))
    R, own = rots.at(20)
    assert own and np.allclose(R, B)
    R, own = rots.at(30)                                        # held from 20
    assert not own and np.allclose(R, B)
    R, own = rots.at(15)
    assert not own and np.allclose(R, A)
    # a bag played again: its estimate starts again
    assert rots.add(5, 'static', np.eye(3)) and len(rots) == 3   # 5 ns back: not a restart
    assert rots.add(20 - 2_000_000_000, 'static', np.eye(3)) and len(rots) == 1


def test_a_rotated_pose_and_the_floor_seen_from_the_current_camera():
    skel = Skeleton.default()
    rng = np.random.default_rng(0)
    q = rng.normal(size=(skel.num_joints, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    pose = Pose(skel, q, np.array([0.3, 0.2, 4.0]))
    R = _rot([0.2, 1.0, 0.1], 0.4)
    turned = rotate_pose(pose, R)
    assert np.allclose(turned.joint_positions(), pose.joint_positions() @ R.T)
    floor = FloorFrame.from_camera_height_pitch(1.5, 0.2)      # in the first image's frame
    seen = floor_in_camera(floor, R)
    p = rng.normal(size=(5, 3))                                 # points in the current camera
    assert np.allclose(seen.transform_points(p), floor.transform_points(p @ R.T))
    assert floor_in_camera(floor, None) is floor


def test_translation_measured_coasted_and_held():
    """The camera's position: measured steps are summed, a frame without a measurement
    coasts on the last velocity for coast_s and then holds, a measurement after a gap
    continues from the coasted position (no jump), a static frame stops the coasting."""
    dt = 100_000_000                                       # 10 frames/s
    cams = CameraRotations(translation=True, coast_s=0.25)
    eye = np.eye(3)
    # the estimator's own position: 0.1 m per frame along x while measured
    assert cams.add(0, 'static', eye, np.zeros(3))
    assert cams.add(dt, 'moving', eye, np.array([0.1, 0, 0]))
    assert cams.add(2 * dt, 'moving', eye, np.array([0.2, 0, 0]))
    assert np.allclose(cams.pose_at(2 * dt)[1], [0.2, 0, 0])
    # three frames without a step: two coast (0.25 s), the third holds
    assert cams.add(3 * dt, 'moving', eye, None)
    assert not cams.add(4 * dt, 'unknown', np.full((3, 3), np.nan), None)  # stored, not own
    assert cams.add(5 * dt, 'moving', eye, None)
    C = [cams.pose_at(k * dt)[1][0] for k in (3, 4, 5)]
    assert np.allclose(C, [0.3, 0.4, 0.4])
    R, _, own = cams.pose_at(4 * dt)
    assert not own and np.allclose(R, eye)                   # the unknown frame's rotation held
    # measured again: the estimator's position advanced only by this step (0.2 -> 0.3)
    assert cams.add(6 * dt, 'moving', eye, np.array([0.3, 0, 0]))
    assert np.allclose(cams.pose_at(6 * dt)[1], [0.5, 0, 0])
    assert cams.add(7 * dt, 'static', eye, np.array([0.3, 0, 0]))
    assert cams.add(8 * dt, 'moving', eye, None)             # no velocity after a static frame
    assert np.allclose(cams.pose_at(8 * dt)[1], [0.5, 0, 0])
    assert (cams.measured_frames, cams.coasted_frames, cams.held_frames) == (5, 2, 2)
    # out of order: ignored; a bag played again: starts afresh
    assert not cams.add(7 * dt, 'moving', eye, np.array([9.0, 0, 0]))
    assert cams.add(8 * dt - 2_000_000_000, 'static', eye, np.zeros(3)) and len(cams) == 1
    assert np.allclose(cams.pose_at(8 * dt - 2_000_000_000)[1], 0)


def _run(node_kwargs, poses, contacts, rotations, frame='camera_optical_frame',
         positions=None, known=None, state=None):
    """Drive a physics node in process (as ``mocap process`` does) with camera-frame poses,
    their contacts and the camera-motion estimate (rotations since the first image, None =
    no estimate published; ``positions``: the camera's measured positions in the first
    camera frame, None entries unmeasured; ``known``: (R, t) known camera poses published
    as PoseStamped on /robot/camera, None entries not published; ``state``: the estimate's
    state, default ``rotating`` or ``moving`` with positions); returns the output frames and
    the published floors."""
    import rclpy
    from rclpy.parameter import Parameter

    from mocap_core import topics
    from mocap_core.inprocess import InProcessGraph
    from mocap_core.ros_conversions import (camera_motion_to_odometry, contacts_to_msg,
                                            make_header, pose_to_motion)
    from mocap_physics.node import PhysicsNode

    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    floors = []
    graph = InProcessGraph(record=lambda topic, msg, qos: floors.append(msg)
                           if topic == topics.PHYSICS_FLOOR else None)
    node = PhysicsNode(context=context, parameter_overrides=[
        Parameter(k, value=v) for k, v in node_kwargs.items()])
    frames = []
    publish_frame = node._publish_frame
    node._publish_frame = lambda f: (frames.append(f), publish_frame(f))
    graph.add(node)
    try:
        for i, (pose, c) in enumerate(zip(poses, contacts)):
            stamp = 1_000_000_000 + i * 33_333_333
            if rotations is not None:
                pos = None if positions is None else positions[i]
                graph.publish(topics.CAMERA_MOTION, camera_motion_to_odometry(
                    state or ('rotating' if positions is None else 'moving'),
                    matrix_to_quat(rotations[i]), np.array([0.0, 0.3, 0.0]),
                    make_header(stamp, frame + '_start'), frame, position=pos))
            if known is not None and known[i] is not None:
                from geometry_msgs.msg import PoseStamped
                msg = PoseStamped(header=make_header(stamp, 'odom'))
                R, t = known[i]
                msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = map(float, t)
                o = matrix_to_quat(R)
                (msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z,
                 msg.pose.orientation.w) = map(float, o)
                graph.publish('/robot/camera', msg)
            graph.publish(topics.LIFTER_CONTACTS, contacts_to_msg(c, make_header(stamp, frame)))
            graph.publish(topics.LIFTER_MOTION, pose_to_motion(pose, make_header(stamp, frame)))
            graph.flush()
        node.flush()
        graph.flush()
        return frames, floors, node
    finally:
        node.destroy_node()
        context.try_shutdown()


@pytest.fixture(scope='module')
def panning():
    """A recorded walk seen by a static camera, and by the same camera panning about the
    world's vertical (0.4 rad/s, the camera centre fixed): camera-frame poses and the
    rotation of each frame's camera into the first one."""
    from mocap_physics.training.evaluate import load_gt_bag
    clip = load_gt_bag(BAG)
    n = 60
    up = clip.to_world.rotation.T @ np.array([0.0, 0.0, 1.0])  # world up in the camera frame
    static = [Pose(clip.skeleton, clip.gt_rotations[i], clip.gt_root_positions[i])
              for i in range(n)]
    turns = [_rot(up, 0.4 * i / clip.fps) for i in range(n)]
    # the current camera sees p_current = Q^T p_first
    panned = [rotate_pose(p, Q.T) for p, Q in zip(static, turns)]
    return static, panned, turns, clip.labels[:n].astype(float), up


def _feet(frames):
    from mocap_core.skeleton import JOINT_INDEX
    idx = [JOINT_INDEX[j] for j in ('left_ankle', 'left_toe', 'right_ankle', 'right_toe')]
    return np.array([f.result.pose.joint_positions()[idx] for f in frames])


def test_a_panning_camera_taken_out_gives_the_static_cameras_physics(panning):
    """Derotated, the panned input is simulated exactly as the static camera's (frame
    ``floor_start``); the floor published per frame is the floor seen from that frame's
    camera; without the estimate the same input gives feet that move with the pan."""
    static, panned, turns, contacts, up = panning
    ref, ref_floors, _ = _run({}, static, contacts, None)
    der, der_floors, node = _run({'derotate_camera': True}, panned, contacts, turns)
    raw, _, _ = _run({}, panned, contacts, None)
    assert len(ref) == len(der) == len(raw) == len(static)
    assert {f.frame_id for f in der} == {'floor_start'} and {f.frame_id for f in ref} == {'floor'}
    assert np.abs(_feet(der) - _feet(ref)).max() < 1e-6
    assert np.abs(_feet(raw) - _feet(ref)).max() > 0.1
    assert node.rotation_own_frames == len(static) and node.rotation_held_frames == 0

    def normals(msgs):
        from mocap_core.rotations import quat_to_matrix
        q = np.array([[m.transform.rotation.x, m.transform.rotation.y, m.transform.rotation.z,
                       m.transform.rotation.w] for m in msgs])
        return quat_to_matrix(q)[:, :, 2]              # the floor's z axis in the camera
    n_ref, n_der = normals(ref_floors), normals(der_floors)
    assert len(n_der) == len(turns)
    # the static camera's floor normal, seen from each panned camera
    expect = np.einsum('fji,fj->fi', np.array(turns), n_ref)
    assert np.abs(n_der - expect).max() < 1e-6
    assert np.degrees(np.arccos(np.clip(n_ref[-1] @ up, -1, 1))) < 10.0


def test_without_an_estimate_the_first_image_is_held(panning):
    """No camera-motion estimate at all: the frames are taken as seen from the first image
    (identity, counted as held) and the output is in floor_start."""
    static, _, _, contacts, _ = panning
    der, _, node = _run({'derotate_camera': True}, static[:20], contacts[:20], None)
    ref, _, _ = _run({}, static[:20], contacts[:20], None)
    assert np.abs(_feet(der) - _feet(ref)).max() < 1e-6
    assert node.rotation_held_frames == 20 and node.rotation_own_frames == 0


@pytest.mark.parametrize('motion', ['pan', 'walk'])
def test_carried_with_a_moving_camera_the_feet_stand_as_for_a_static_one(panning, motion):
    """OnlinePhysics with the camera's pose per frame: the state is carried by the camera's
    turn (a pan about the vertical through the camera) or its step along the floor (a
    camera walking sideways at 1 m/s), so the moved camera's input gives the static
    camera's physics seen from each moved camera (the true floor, the same in every moved
    camera); without the camera's pose the stance feet are held where the moving floor
    frame had them."""
    from mocap_physics.cycle_params import PhysicsParams
    from mocap_physics.online import OnlinePhysics
    from mocap_physics.training.evaluate import load_gt_bag
    static, panned, turns, contacts, up = panning
    floor = load_gt_bag(BAG).to_world                     # camera -> floor, z up
    A, t = floor.rotation, floor.translation
    n = len(static)
    if motion == 'pan':
        moved, cameras = panned, [(Q, np.zeros(3)) for Q in turns]
    else:
        side = np.cross(up, [0.0, 0.0, 1.0])
        side /= np.linalg.norm(side)
        cameras = [(np.eye(3), side * (i / 30.0)) for i in range(n)]
        moved = [Pose(p.skeleton, p.rotations, p.root_position - c)
                 for p, (_, c) in zip(static, cameras)]

    def run(poses, cams):
        online = OnlinePhysics(PhysicsParams(), floor)
        out = [online.step(1_000_000_000 + i * 33_333_333, p, 'camera', c, camera=cam)
               for i, (p, c, cam) in enumerate(zip(poses, contacts, cams))]
        return [f for f in out if f is not None], online
    ref, _ = run(static, [None] * n)
    car, online = run(moved, cameras)
    raw, _ = run(moved, [None] * n)
    assert len(ref) == len(car) == len(raw) == n
    assert online.camera_steps == n - 1

    def back(frames):                                     # each camera's floor -> the first's
        return np.array([(f - t) @ (A @ Q @ A.T).T + t + A @ c
                         for f, (Q, c) in zip(_feet(frames), cameras)])
    ref_feet = _feet(ref)
    # not exact for a pan: the four-sided friction pyramid is fixed to the floor frame's
    # axes, so a turned frame bounds the forces a little differently (3 mm at most at this
    # 0.4 rad/s, 0.9 mm at 0.1 rad/s)
    assert np.abs(back(car) - ref_feet).max() < (0.005 if motion == 'pan' else 1e-6)
    assert np.abs(back(raw) - ref_feet).max() > 0.05


def test_carried_with_a_known_camera_pose(panning):
    """camera_pose_topic (carry_with_camera not needed): the node carries every frame that has a
    known pose near it by that pose (output frame ``floor``; the estimate is not needed),
    counts the frames without one and does not carry them; the output differs from the
    same input without carrying."""
    static, panned, turns, contacts, _ = panning
    n = len(static)
    world = [(Q, np.array([0.5, 0.0, 1.4])) for Q in turns]    # a pan on a tripod
    kwargs = {'camera_pose_topic': '/robot/camera', 'camera_pose_type': 'pose'}
    car, _, node = _run(kwargs, panned, contacts, None, known=world)
    assert len(car) == n and {f.frame_id for f in car} == {'floor'}
    assert node.online.camera_steps == n - 1 and node.camera_pose_missing == 0
    part, _, node = _run(kwargs, panned, contacts, None,
                         known=world[:30] + [None] * (n - 30))
    assert len(part) == n and node.camera_pose_missing == n - 30 - 3   # 0.1 s still served
    assert node.online.camera_steps == 30 + 3 - 1
    raw, _, _ = _run({}, panned, contacts, None)
    assert np.abs(_feet(car) - _feet(raw)).max() > 0.05


def _world_skating(feet, contacts):
    """Mean horizontal speed (mm/frame) of the feet joints (N, 4, 3) between consecutive
    frames where the foot's contacts (N, 4: heel, toe per foot) hold in both."""
    steps = np.linalg.norm(np.diff(feet[:, :, :2], axis=0), axis=-1)     # (N-1, 4)
    down = contacts > 0.5
    both = down[1:] & down[:-1]
    return 1000.0 * steps[both].mean()


def test_stance_drift_keeps_the_feet_standing_for_a_camera_walking_sideways(panning):
    """``stance_drift_s``: no camera pose at all; a camera walking sideways at 1 m/s. The
    stance points of the target drift through the floor frame at the camera's speed; the
    physics follows that drift, so mapped into the world (by the true camera positions, for
    scoring only) its stance feet slide far less than without it, where the stance anchors
    hold the feet still in the moving frame. For the static camera the output is the same
    (the recorded target's stance feet drift, if at all, slower than the dead band)."""
    from mocap_physics.cycle_params import PhysicsParams
    from mocap_physics.online import OnlinePhysics
    from mocap_physics.training.evaluate import load_gt_bag
    static, _, _, contacts, up = panning
    floor = load_gt_bag(BAG).to_world
    n = len(static)
    side = np.cross(up, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    centres = [side * (i / 30.0) for i in range(n)]
    moved = [Pose(p.skeleton, p.rotations, p.root_position - c)
             for p, c in zip(static, centres)]

    def run(poses, drift):
        online = OnlinePhysics(PhysicsParams(stance_drift_s=drift), floor)
        out = [online.step(1_000_000_000 + i * 33_333_333, p, 'camera', c, camera_moving=True)
               for i, (p, c) in enumerate(zip(poses, contacts))]
        assert all(f is not None for f in out)
        return out, online

    def world_feet(frames):                       # floor of each moved camera -> the first's
        return np.array([f + floor.rotation @ c for f, c in zip(_feet(frames), centres)])
    # _feet: left ankle, left toe, right ankle, right toe; contacts: left heel, left toe,
    # right heel, right toe (the ankle stands with its heel)
    late = slice(15, None)                         # after the drift's filter has settled
    drift, online = run(moved, 0.3)
    held, _ = run(moved, 0.0)
    s_drift = _world_skating(world_feet(drift)[late], contacts[late])
    s_held = _world_skating(world_feet(held)[late], contacts[late])
    assert online.cycle.drift_frames > 0
    assert s_held > 20.0                           # the camera's 33 mm per frame, partly held
    assert s_drift < 0.4 * s_held
    # the drift it settled on is the camera's motion seen in the floor frame
    v = online.cycle.drift_velocity
    expect = -(floor.rotation @ side)[:2]
    assert np.linalg.norm(v - expect) < 0.3
    still, online = run(static, 0.3)
    ref, _ = run(static, 0.0)
    assert 0.0 < np.linalg.norm(online.cycle.drift_velocity) < 0.2     # the dead band
    assert np.abs(_feet(still) - _feet(ref)).max() < 1e-9


def _drifting_cycle(speed=np.array([0.6, -0.3])):
    """A whole-body cycle fed a standing target that slides along the floor at ``speed``
    (m/s, floor x, y) with both feet in contact, as a camera moving the other way would
    show it; returns (cycle, the target of frame k, contacts)."""
    from mocap_physics.cycle import PhysicsCycle
    from mocap_physics.cycle_params import PhysicsParams
    from mocap_physics.training.evaluate import load_gt_bag
    clip = load_gt_bag(BAG)
    cyc = PhysicsCycle(clip.skeleton, PhysicsParams(stance_drift_s=0.3))
    stand = cyc.model.pose_to_q(clip.to_world.transform_pose(
        Pose(clip.skeleton, clip.gt_rotations[0], clip.gt_root_positions[0])))

    def target(k):
        q = stand.copy()
        q[:2] += speed * k / 30.0
        return q
    return cyc, target, np.ones(4)


def _moved(q, R, t):
    import pinocchio as pin
    q = q.copy()
    q[:7] = pin.SE3ToXYZQUAT(pin.SE3(R, t) * pin.XYZQUATToSE3(q[:7]))
    return q


def test_stance_drift_is_carried_through_a_change_of_floor_frame():
    """A floor re-estimate (``change_frame``) between two frames turns the drift velocity
    and moves the remembered stance points with it: the sliding target seen in the new frame
    keeps exactly the drift it had, turned by the change."""
    speed = np.array([0.6, -0.3])
    cyc, target, probs = _drifting_cycle(speed)
    for k in range(8):
        cyc.step(target(k), k / 30.0, probs, camera_moving=True)
    np.testing.assert_allclose(cyc.drift_velocity, speed, atol=1e-9)
    assert cyc.drift_frames > 0
    R = axis_angle_to_matrix(np.array([0.0, 0.0, 0.3]))
    t = np.array([0.4, -0.2, 0.0])
    frames = cyc.stats.frame_changes
    cyc.change_frame(R, t)
    assert cyc.stats.frame_changes == frames + 1
    np.testing.assert_allclose(cyc.drift_velocity, R[:2, :2] @ speed, atol=1e-9)
    cyc.step(_moved(target(8), R, t), 8 / 30.0, probs, camera_moving=True)
    np.testing.assert_allclose(cyc.drift_velocity, R[:2, :2] @ speed, atol=1e-9)
    # the drift's own shifts are not floor changes
    assert cyc.stats.frame_changes == frames + 1


def test_stance_drift_across_a_held_target_a_model_change_and_a_reset():
    """An invalid target (held) keeps the drift and does not double the next sample; a new
    flat-foot pitch (heel points elsewhere) is no drift; a static frame, ``reset`` and
    ``set_state`` forget it."""
    speed = np.array([0.5, 0.0])
    cyc, target, probs = _drifting_cycle(speed)
    for k in range(6):
        cyc.step(target(k), k / 30.0, probs, camera_moving=True)
    bad = target(6)
    bad[3:7] = 0.0                                   # a zero quaternion: held
    res = cyc.step(bad, 6 / 30.0, probs, camera_moving=True)
    assert 'invalid_input' in cyc.stats.last_event and res is not None
    np.testing.assert_allclose(cyc.drift_velocity, speed, atol=1e-9)
    cyc.step(target(7), 7 / 30.0, probs, camera_moving=True)
    np.testing.assert_allclose(cyc.drift_velocity, speed, atol=1e-9)
    assert cyc.set_flat_foot_pitch(45.0)
    cyc.step(target(8), 8 / 30.0, probs, camera_moving=True)
    np.testing.assert_allclose(cyc.drift_velocity, speed, atol=1e-9)
    cyc.step(target(9), 9 / 30.0, probs, camera_moving=False)
    assert not cyc.drift_velocity.any()
    cyc.step(target(10), 10 / 30.0, probs, camera_moving=True)
    cyc.step(target(11), 11 / 30.0, probs, camera_moving=True)
    assert cyc.drift_velocity.any()
    state = cyc.state
    cyc.set_state(*state, stamp=11 / 30.0)
    assert not cyc.drift_velocity.any()
    cyc.step(target(12), 12 / 30.0, probs, camera_moving=True)
    cyc.step(target(13), 13 / 30.0, probs, camera_moving=True)
    cyc.reset()
    assert not cyc.drift_velocity.any()


def test_the_node_follows_the_stance_drift_unless_the_camera_is_static(panning):
    """The node with ``stance_drift_s``: the estimate says the camera moves (a camera walking
    sideways at 1 m/s whose steps were not measured), and the drift is followed; the same
    input with the estimate saying ``static``, or without an estimate, gives exactly the
    output without the drift; carried with the camera's pose instead, the drift is off (the
    camera's motion is known there)."""
    static, _, _, contacts, up = panning
    n = 40
    side = np.cross(up, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    moved = [Pose(p.skeleton, p.rotations, p.root_position - side * (i / 30.0))
             for i, p in enumerate(static[:n])]
    ident = [np.eye(3)] * n
    # (the joints' moving gains off: this is the drift alone)
    fixed = {'kp_joint_moving': 0.0, 'kd_joint_moving': 0.0}
    drift = dict(fixed, stance_drift_s=0.3)
    off, _, _ = _run(dict(fixed, stance_drift_s=0.0), moved, contacts[:n], ident)
    follows, _, node = _run(drift, moved, contacts[:n], ident, state='moving')
    assert node.drift and node.online.cycle.drift_frames > 0
    node.refresh_diagnostics()
    assert int(node.diag._values['stance_drift_frames']) == node.online.cycle.drift_frames
    vx, vy = map(float, node.diag._values['stance_drift_m_s'].split())
    assert np.hypot(vx, vy) > 0.5                  # the camera's 1 m/s, seen in the floor
    held, _, node = _run(drift, moved, contacts[:n], ident, state='static')
    assert node.online.cycle.drift_frames == 0
    assert np.abs(_feet(held) - _feet(off)).max() < 1e-9
    alone, _, node = _run(drift, moved, contacts[:n], None)
    assert node.drift and node.online.cycle.drift_frames == 0
    assert np.abs(_feet(alone) - _feet(off)).max() < 1e-9
    assert np.abs(_feet(follows) - _feet(off)).max() > 0.05
    _, _, node = _run(dict(drift, camera_pose_topic='/robot/camera', camera_pose_type='pose'),
                      moved, contacts[:n], None,
                      known=[(np.eye(3), side * (i / 30.0)) for i in range(n)])
    assert node.carry and not node.drift and node.online.cycle.drift_frames == 0


@pytest.mark.parametrize('dynamics', ['whole_body', 'paper'])
def test_the_node_gives_a_moving_cameras_frames_the_moving_gains(panning, dynamics):
    """``kp_joint_moving`` / ``kd_joint_moving`` reach the frames the estimate says move, in
    either dynamics and without the stance drift: the same input simulated differently with
    the estimate ``moving`` than ``static``, and alike with the moving gains at 0 (then
    reported off in the diagnostics)."""
    _, panned, turns, contacts, _ = panning
    n = 30
    base = {'stance_drift_s': 0.0, 'dynamics': dynamics}
    plain = dict(base, kp_joint_moving=0.0, kd_joint_moving=0.0)
    still, _, _ = _run(base, panned[:n], contacts[:n], turns[:n], state='static')
    moving, _, node = _run(base, panned[:n], contacts[:n], turns[:n], state='moving')
    assert node.diag._values['moving_gains'].startswith('joints kp 8100, kd 180')
    assert np.abs(_feet(moving) - _feet(still)).max() > 1e-4
    alike, _, node = _run(plain, panned[:n], contacts[:n], turns[:n], state='moving')
    assert node.diag._values['moving_gains'] == 'off'
    assert np.abs(_feet(alike) - _feet(still)).max() < 1e-9


@pytest.mark.parametrize('gravity', [True, False])
def test_a_known_camera_pose_can_give_the_floor_its_normal(panning, gravity):
    """floor_from_camera_pose: the recorded walk's static camera with its true pose in the
    clip's z-up world. With it every published floor's normal is that world's up seen from
    the camera (the feet give only the height); without it the normal is fitted to the feet
    and differs."""
    from mocap_physics.training.evaluate import load_gt_bag
    static, _, _, contacts, _ = panning
    A, t = load_gt_bag(BAG).to_world.rotation, load_gt_bag(BAG).to_world.translation
    kwargs = {'camera_pose_topic': '/robot/camera', 'camera_pose_type': 'pose',
              'floor_from_camera_pose': gravity}
    out, floors, node = _run(kwargs, static, contacts, None, known=[(A, t)] * len(static))
    assert len(out) == len(static) and len(floors) >= len(static) - 1
    from mocap_core.rotations import quat_to_matrix
    q = np.array([[m.transform.rotation.x, m.transform.rotation.y, m.transform.rotation.z,
                   m.transform.rotation.w] for m in floors])
    err = np.abs(quat_to_matrix(q)[:, :, 2] - A[2]).max()
    assert node.online.floor_gravity == gravity
    if gravity:
        assert err < 1e-6
    else:
        assert err > 1e-3
