"""The floor-frame boundary (camera frame -> floor frame)."""

import numpy as np
import pytest

from mocap_core.pose import Pose
from mocap_core.skeleton import Skeleton
from mocap_physics.floor import FloorFrame


def test_camera_height_pitch():
    h, pitch = 1.5, np.deg2rad(20)
    ff = FloorFrame.from_camera_height_pitch(h, pitch)
    # the camera centre is h above the floor origin
    np.testing.assert_allclose(ff.transform_points(np.zeros(3)), [0, 0, h])
    # the optical axis points forward and down by the pitch
    d = ff.rotation @ np.array([0, 0, 1.0])
    assert np.degrees(np.arctan2(-d[2], d[0])) == pytest.approx(20)
    # image "down" (optical +y) has a downward floor component, image right is floor -y
    assert (ff.rotation @ [0, 1.0, 0])[2] < 0
    np.testing.assert_allclose(ff.rotation @ [1.0, 0, 0], [0, -1, 0], atol=1e-12)
    # a point on the optical axis at the distance where it meets the floor lies on it
    dist = h / np.sin(pitch)
    assert ff.transform_points([0, 0, dist])[2] == pytest.approx(0.0, abs=1e-9)


def test_pose_round_trip():
    sk = Skeleton.default()
    ff = FloorFrame.from_camera_height_pitch(1.2, 0.3)
    pose = Pose.rest(sk, np.array([0.2, 0.1, 3.0]))
    floor_pose = ff.transform_pose(pose)
    np.testing.assert_allclose(floor_pose.joint_positions(),
                               ff.transform_points(pose.joint_positions()), atol=1e-12)
    back = ff.inverse().transform_pose(floor_pose)
    np.testing.assert_allclose(back.joint_positions(), pose.joint_positions(), atol=1e-12)


def test_bad_rotation_rejected():
    with pytest.raises(ValueError):
        FloorFrame(np.diag([1.0, 1.0, -1.0]))


# -- floor estimation from the feet ------------------------------------------------------------
from mocap_core.data.synth2d import look_at  # noqa: E402
from mocap_core.rotations import axis_angle_to_quat, matrix_to_quat, quat_multiply  # noqa: E402
from mocap_core.skeleton import JOINT_INDEX  # noqa: E402
from mocap_physics.floor import (CAMERA_UP, FloorTracker, FloorTrackerParams,  # noqa: E402
                                 body_up, fit_floor_plane)


def _camera(pitch_deg=20.0, roll_deg=4.0, height=1.6):
    """A tilted camera 4 m behind the walk, world -> camera rotation and position."""
    pos = np.array([-4.0, 0.7, height])
    aim = pos + np.array([np.cos(np.radians(pitch_deg)), 0.0, -np.sin(np.radians(pitch_deg))])
    return look_at(pos, aim, np.radians(roll_deg)), pos


def _walk_in_camera(R, c, frames=150, seed=0, jitter=0.003):
    """A person on the floor (z = 0) walking a curved path in the world, seen from the camera
    (R world->camera, c centre): poses in the camera frame, contact probabilities (feet
    alternating), and the upper body leaning randomly (+-5 deg about a vertical mean). ``R``
    may be a list of per-frame rotations (a camera that turns)."""
    rng = np.random.default_rng(seed)
    sk = Skeleton.default()
    rest = Pose.rest(sk)
    Rs = [np.asarray(R)] * frames if np.ndim(R) == 2 else [np.asarray(r) for r in R]
    poses, probs = [], []
    for k in range(frames):
        R = Rs[k]
        qc = matrix_to_quat(R)
        t = k / 30.0
        root = np.array([0.6 * t, 0.4 * np.sin(0.8 * t), rest.root_position[2]])
        yaw = 0.3 * np.cos(0.8 * t)
        rot = np.array(rest.rotations)
        rot[0] = axis_angle_to_quat(np.array([0.0, 0.0, yaw]))
        rot[JOINT_INDEX['spine']] = axis_angle_to_quat(np.radians(5) * rng.normal(size=3))
        world = Pose(sk, rot, root + jitter * rng.normal(size=3))
        cam_rot = np.array(world.rotations)
        cam_rot[0] = quat_multiply(qc, cam_rot[0])
        poses.append(Pose(sk, cam_rot, R @ (world.root_position - c)))
        left = np.sin(2 * np.pi * 0.9 * t) > -0.3
        right = np.sin(2 * np.pi * 0.9 * t) < 0.3
        probs.append(np.array([left, left, right, right], dtype=float) * 0.9 + 0.05)
    return poses, probs


@pytest.mark.parametrize('pitch,roll', [(20.0, 4.0), (35.0, -6.0), (5.0, 0.0)])
def test_tracker_recovers_tilted_floor(pitch, roll):
    """Known tilted camera, feet on the floor: plane within 1 deg and 1 cm (camera height)."""
    R, c = _camera(pitch, roll)
    poses, probs = _walk_in_camera(R, c)
    tracker = FloorTracker()
    for pose, p in zip(poses, probs):
        frame, _ = tracker.update(pose, p)
    assert tracker.ready and tracker.fit.source == 'points'
    true_normal = R @ np.array([0.0, 0.0, 1.0])     # world up in camera axes
    angle = np.degrees(np.arccos(np.clip(frame.normal @ true_normal, -1, 1)))
    assert angle < 1.0, angle
    # the true floor under the person (mean position) is within 1 cm of the estimated one,
    # and so is the camera height (measured 4-6 m away from the person)
    mean_root_cam = np.mean([pose.root_position for pose in poses], axis=0)
    under = mean_root_cam - (true_normal @ mean_root_cam + c[2]) * true_normal
    assert abs(frame.transform_points(under)[2]) < 0.01
    assert abs(frame.height - c[2]) < 0.02, (frame.height, c[2])
    # the floor frame: feet on z = 0, z up, x along the viewing direction
    feet = np.array([[q for q in frame.transform_pose(pose).contact_positions().values()]
                     for pose in poses])
    assert np.abs(feet[..., 2]).max() < 0.015
    assert frame.rotation[0] @ np.array([0.0, 0.0, 1.0]) > 0.8


def _tilt_error_deg(frame, R):
    return np.degrees(np.arccos(np.clip(frame.normal @ (R @ np.array([0.0, 0.0, 1.0])), -1, 1)))


def test_a_camera_re_aimed_unseen_restarts_the_window():
    """A hand-held camera re-aimed from 15 to 40 degrees down after 4 s, its motion unknown
    to the physics: the floor moves in the camera frame. The old floor's points outnumber the
    new one's in the window, so without the restart (``restart_share`` 0) the fit stays on
    the old floor until they age out; with it (the default) the floor follows within a
    second and a half (the case of a rendered travel clip, docs/physics.md). A camera that
    holds still never restarts, nor does one the camera-motion estimate calls static."""
    frames = 270
    Rs = [_camera(15.0 if k < 120 else 40.0, 3.0)[0] for k in range(frames)]
    c = _camera()[1]
    poses, probs = _walk_in_camera(Rs, c, frames=frames, seed=3)
    result = {}
    for share in (FloorTrackerParams().restart_share, 0.0):
        tracker = FloorTracker(FloorTrackerParams(restart_share=share))
        err = [_tilt_error_deg(tracker.update(pose, p)[0], R)
               for pose, p, R in zip(poses, probs, Rs)]
        result[share] = (float(np.median(err[180:240])), tracker.restarts)
    on, off = result[FloorTrackerParams().restart_share], result[0.0]
    assert FloorTrackerParams().restart_share > 0
    assert on[1] == 1 and off[1] == 0, result
    assert on[0] < 1.0 and off[0] > 15.0, result
    # frames whose camera is known to stand still (restart=False) never restart the window
    tracker = FloorTracker()
    for pose, p in zip(poses, probs):
        tracker.update(pose, p, restart=False)
    assert tracker.restarts == 0
    # a steady camera: the whole window fits one plane, nothing is forgotten
    R = _camera(30.0, 3.0)[0]
    tracker = FloorTracker()
    for pose, p in zip(*_walk_in_camera(R, c, frames=frames, seed=3)):
        frame, _ = tracker.update(pose, p)
    assert tracker.restarts == 0 and _tilt_error_deg(frame, R) < 1.0


def test_fit_is_robust_to_outliers_and_uses_prior_when_degenerate():
    rng = np.random.default_rng(1)
    n_true = np.array([0.0, -np.cos(0.3), -np.sin(0.3)])       # a pitched camera's floor
    offset = 1.4
    # points on the floor spread over 2 m x 1 m, 3 mm noise, 15 % outliers 5-20 cm above
    u = np.cross(n_true, [1.0, 0, 0])
    u /= np.linalg.norm(u)
    v = np.cross(n_true, u)
    pts = (rng.uniform(-1, 1, (200, 1)) * u + rng.uniform(-0.5, 0.5, (200, 1)) * v
           - offset * n_true + 0.003 * rng.normal(size=(200, 3)))
    out = rng.random(200) < 0.15
    pts[out] += rng.uniform(0.05, 0.2, (out.sum(), 1)) * n_true
    fit = fit_floor_plane(pts, prior=CAMERA_UP, prior_weight_m=0.02)
    assert np.degrees(np.arccos(fit.normal @ n_true)) < 0.5
    assert abs(fit.offset - offset) < 0.01
    assert fit.inliers <= 200 - out.sum() + 3
    # a single foot patch (standing): the rotation comes from the prior
    patch = -offset * n_true + 0.05 * rng.normal(size=(50, 1)) * u \
        + 0.05 * rng.normal(size=(50, 1)) * v + 0.004 * rng.normal(size=(50, 3))
    fit = fit_floor_plane(patch, prior=n_true)
    assert np.degrees(np.arccos(fit.normal @ n_true)) < 1.0
    # too few points: the prior through the lowest ones
    fit = fit_floor_plane(pts[:3], prior=n_true)
    assert fit.source == 'prior' and np.allclose(fit.normal, n_true)


def test_tracker_provisional_then_refined_and_frozen():
    R, c = _camera(25.0, 3.0)
    poses, probs = _walk_in_camera(R, c, frames=120)
    tracker = FloorTracker(FloorTrackerParams(freeze_after=90))
    frame, changed = tracker.update(poses[0], probs[0])
    assert frame is not None and not changed and not tracker.ready
    assert tracker.fit.source == 'prior'
    changes = []
    for pose, p in zip(poses[1:], probs[1:]):
        f, ch = tracker.update(pose, p)
        changes.append(ch)
        if ch:
            # a change re-expresses the frame: the previous one is a different plane
            assert f is tracker.frame
    assert tracker.ready and any(changes)
    # frozen after 90 frames (a fit adopted before that is still blended in)
    assert not any(changes[90 + tracker.params.blend_frames:])
    # NaN and unknown contacts are ignored without error
    bad = Pose(Skeleton.default(), poses[0].rotations, poses[0].root_position)
    tracker.add(np.full((4, 3), np.nan), [1, 1, 1, 1])
    tracker.update(bad, None)


def test_interpolate_goes_along_the_arc_and_the_line():
    a = FloorFrame.from_camera_height_pitch(1.5, np.radians(10.0))
    b = FloorFrame.from_camera_height_pitch(1.7, np.radians(30.0))
    assert a.interpolate(b, 0.0).rotation == pytest.approx(a.rotation)
    assert a.interpolate(b, 1.0) is b
    half = a.interpolate(b, 0.5)
    assert half.height == pytest.approx(1.6)
    # the rotation half-way: 10 deg from each end
    ang = [np.degrees(np.arccos(np.clip((np.trace(half.rotation @ x.rotation.T) - 1) / 2,
                                        -1, 1))) for x in (a, b)]
    assert ang == pytest.approx([10.0, 10.0], abs=1e-6)
    # any relative turn: the same rotations as scipy's slerp; a half turn (two shortest
    # arcs): a fraction s of the half turn away from the start
    from scipy.spatial.transform import Rotation, Slerp
    c = FloorFrame(Rotation.from_rotvec([0.1, 0.3, -0.2]).as_matrix() @ a.rotation, [0, 0, 1])
    ref = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([a.rotation, c.rotation])))
    for s in (0.0, 0.3, 0.77):
        np.testing.assert_allclose(a.interpolate(c, s).rotation, ref([s]).as_matrix()[0],
                                   atol=1e-9)
    d = FloorFrame(Rotation.from_rotvec([np.pi, 0.0, 0.0]).as_matrix() @ a.rotation)
    for s in (0.3, 0.77):
        R = a.interpolate(d, s).rotation
        assert Rotation.from_matrix(R @ a.rotation.T).magnitude() == pytest.approx(s * np.pi)


def test_a_new_fit_is_blended_in_without_a_jump():
    """A re-fit that moves the floor: with blending the frame moves there over
    ``blend_frames`` updates (each step a small part of the move), without it in one step;
    both end on the same frame."""
    R, c = _camera(25.0, 3.0)
    poses, probs = _walk_in_camera(R, c, frames=120)
    runs = {}
    for blend in (0, 15):
        tracker = FloorTracker(FloorTrackerParams(blend_frames=blend))
        frames, changed, adopted = [], [], []
        for pose, p in zip(poses, probs):
            f, ch = tracker.update(pose, p)
            frames.append(f)
            changed.append(ch)
            adopted.append(tracker.adopted)
        runs[blend] = (frames, changed, adopted, tracker)
    f0, ch0, ad0, t0 = runs[0]
    f15, ch15, ad15, t15 = runs[15]
    assert t0.changes == t15.changes >= 1 and ad0 == ad15
    # the largest frame-to-frame move of a floor point under the person
    probe = np.mean([pose.root_position for pose in poses], axis=0)

    def steps(frames):
        pts = np.array([f.transform_points(probe) for f in frames[1:]])
        return np.linalg.norm(np.diff(pts, axis=0), axis=-1)

    # every adoption, the provisional floor's replacement too, is spread over 15 frames
    jump, blended = steps(f0).max(), steps(f15).max()
    assert jump > 0.01                           # a re-fit moves the floor by centimetres
    assert blended < 0.2 * jump
    for first in [i for i, a in enumerate(ad15) if a][1:]:
        assert all(ch15[first:first + 15]) and ch0[first]
        assert not any(ch0[first + 1:first + 15])
    np.testing.assert_allclose(f15[-1].rotation, f0[-1].rotation, atol=1e-9)
    np.testing.assert_allclose(f15[-1].translation, f0[-1].translation, atol=1e-9)
    with pytest.raises(ValueError, match='blend_frames'):
        FloorTracker(FloorTrackerParams(blend_frames=-1))


def test_from_plane_and_body_up():
    n = np.array([0.1, -0.95, -0.2])
    ff = FloorFrame.from_plane(n, 1.3)
    np.testing.assert_allclose(ff.normal, n / np.linalg.norm(n))
    assert ff.height == pytest.approx(1.3)
    p = -1.3 * ff.normal + 0.4 * np.cross(ff.normal, [1.0, 0, 0])   # a point on the plane
    assert ff.transform_points(p)[2] == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(ff.compose(ff.inverse()).rotation, np.eye(3), atol=1e-12)
    assert ff.difference(ff) == (pytest.approx(0.0, abs=1e-7), 0.0)
    up = body_up(Pose.rest(Skeleton.default()))
    np.testing.assert_allclose(up, [0, 0, 1], atol=1e-9)
    with pytest.raises(ValueError):
        FloorFrame.from_plane(np.zeros(3), 1.0)


def test_heel_points_placed_for_the_motion_s_flat_foot_give_the_floor_under_it():
    """Feet flat on the floor with the ankle-to-toe bone 40 degrees below it (the Bandai Namco
    convention): with ``flat_foot_pitch_deg`` 40 the tracker takes heel points on the floor with
    the toes, and the floor comes out within 1 cm and 1 degree. (The template's heel points lie
    3 cm above the floor there; the fit's lower-quartile offset follows the toes then, so the
    floor barely moves: what the pitch changes is where the physics holds the heel.)"""
    R, c = _camera(20.0, 4.0)
    poses, probs = _walk_in_camera(R, c)
    sk = poses[0].skeleton
    drop = np.sin(np.radians(40.0)) - np.sin(np.radians(30.0))   # the turn lowers the toe so much
    turned = []
    for pose in poses:
        rot = np.array(pose.rotations)
        for side in ('left', 'right'):
            rot[JOINT_INDEX[f'{side}_ankle']] = axis_angle_to_quat(np.array([0.0, np.radians(10.0),
                                                                             0.0]))
        # the whole body raised so that the turned toes stand on the floor again
        up = R @ np.array([0.0, 0.0, drop * sk.foot_length()])
        turned.append(Pose(sk, rot, pose.root_position + up))
    true_normal = R @ np.array([0.0, 0.0, 1.0])
    mean_root = np.mean([pose.root_position for pose in turned], axis=0)
    under = mean_root - (true_normal @ mean_root + c[2]) * true_normal
    errors = {}
    for pitch in (40.0,):
        tracker = FloorTracker(FloorTrackerParams(flat_foot_pitch_deg=pitch))
        for pose, p in zip(turned, probs):
            frame, _ = tracker.update(pose, p)
        angle = np.degrees(np.arccos(np.clip(frame.normal @ true_normal, -1, 1)))
        errors[pitch] = (abs(frame.transform_points(under)[2]), angle)
    assert errors[40.0][0] < 0.01 and errors[40.0][1] < 1.0, errors


def test_floor_height_along_a_known_normal_ignores_lifted_feet():
    from mocap_physics.floor import fit_floor_height
    rng = np.random.default_rng(3)
    h = np.concatenate([0.10 + 0.004 * rng.normal(size=80), 0.25 + 0.05 * rng.random(30)])
    z, inliers = fit_floor_height(h)
    assert abs(z - 0.10) < 0.006 and 70 <= inliers <= 85
    with pytest.raises(ValueError):
        fit_floor_height(np.array([np.nan]))


def test_a_known_camera_pose_gives_the_floor_normal_and_follows_the_camera():
    """A camera that tilts down and rises while a person walks: with its pose known (z up),
    every frame's floor has the world's up as its normal and the camera's height above the
    fitted floor; a point fixed in the world keeps its floor coordinates (the frame follows
    the camera, not reported as a change); a frame without a pose keeps the last floor."""
    R0, c0 = _camera(20.0, 0.0)
    poses, probs = _walk_in_camera(R0, c0, frames=90)
    tracker = FloorTracker()
    world_point = np.array([1.0, 0.5, 0.0])
    seen = []
    for k, (pose, p) in enumerate(zip(poses, probs)):
        # the same world seen by a camera pitched down a further 0.2 deg and 1 cm higher per
        # frame: the pose in this camera's frame
        R, c = _camera(20.0 + 0.2 * k, 0.0, height=1.6 + 0.01 * k)
        M = R @ R0.T
        cam_rot = np.array(pose.rotations)
        cam_rot[0] = quat_multiply(matrix_to_quat(M), cam_rot[0])
        pose_k = Pose(pose.skeleton, cam_rot, R @ (R0.T @ pose.root_position + c0 - c))
        frame, changed = tracker.update(pose_k, p, (R.T, c))
        assert not changed
        np.testing.assert_allclose(frame.normal, R @ np.array([0.0, 0.0, 1.0]), atol=1e-9)
        seen.append(frame.transform_points(R @ (world_point - c)))
    assert tracker.known and tracker.ready and tracker.fit.source == 'points'
    # the feet stand on z = 0 (lower quartile of the stance points, jitter 3 mm)
    assert abs(frame.height - (1.6 + 0.01 * 89)) < 0.01
    seen = np.array(seen)
    assert np.abs(seen[30:] - seen[30]).max() < 0.01
    held, changed = tracker.update(poses[0], probs[0])
    assert held is frame and not changed


def test_the_upright_prior_turns_a_leaning_body_up_in_the_known_gravity():
    from mocap_core.rotations import axis_angle_to_matrix
    from mocap_physics.floor import UprightPrior
    R, c = _camera(20.0, 0.0)                 # world -> camera
    poses, _ = _walk_in_camera(R, c, frames=40, jitter=0.0)
    lean = axis_angle_to_matrix(np.array([np.radians(6.0), 0.0, 0.0]))   # about camera x
    prior, capped = UprightPrior(window=40), UprightPrior(window=40, max_angle_deg=2.0)
    for pose in poses:
        rot = np.array(pose.rotations)
        rot[0] = quat_multiply(matrix_to_quat(lean), rot[0])
        leaning = Pose(pose.skeleton, rot, pose.root_position)
        out = prior.apply(leaning, R.T)
        capped.apply(leaning, R.T)
    # the walk's own mean lean (the random spine) stays: the prior undoes the added 6 deg
    ref = UprightPrior(window=40)
    for pose in poses:
        ref.apply(pose, R.T)
    assert abs(np.degrees(prior.angle) - 6.0) < 1.5 and np.degrees(ref.angle) < 1.5
    assert np.degrees(capped.angle) == pytest.approx(2.0)
    np.testing.assert_allclose(out.root_position, poses[-1].root_position)
    up_after = R.T @ body_up(out)
    assert up_after[2] > np.cos(np.radians(2.0))
