import numpy as np
import pytest

from mocap_core.camera import CameraIntrinsics
from mocap_core.data.motion import (contact_labels, contact_point_positions, floor_height,
                                    floor_plane, process_motion, resample,
                                    retime)
from mocap_core.data.synth2d import (CameraSampling, ConfidenceModel, Corruption, VirtualCamera,
                                     canonicalize, corrupt_keypoints, in_view, keypoints_3d,
                                     look_at, mirror_keypoints, mirror_motion, motion_to_camera,
                                     project, sample_camera)
from mocap_core.kinematics import forward_kinematics
from mocap_core.render.evaluate import camera_pitch_deg
from mocap_core.rotations import axis_angle_to_quat, quat_angle, quat_normalize
from mocap_core.skeleton import (JOINT_INDEX, KEYPOINT_INDEX, NUM_JOINTS, NUM_KEYPOINTS,
                                 Skeleton)


def _walk(frames=120, fps=30.0):
    """A synthetic motion: the rest pose moving forward with swinging legs."""
    sk = Skeleton.default()
    t = np.arange(frames) / fps
    rot = np.zeros((frames, NUM_JOINTS, 4))
    rot[..., 3] = 1.0
    swing = 0.4 * np.sin(2 * np.pi * 1.0 * t)
    rot[:, JOINT_INDEX['left_hip']] = axis_angle_to_quat(np.outer(swing, [0, 1, 0]))
    rot[:, JOINT_INDEX['right_hip']] = axis_angle_to_quat(np.outer(-swing, [0, 1, 0]))
    root = np.stack([0.8 * t, 0 * t, np.full_like(t, sk.rest_root_height() + 0.3)], axis=1)
    return sk, rot, root


def test_resample_keeps_endpoints_and_interpolates():
    sk, rot, root = _walk(61, 60.0)
    r2, p2 = resample(rot, root, 60.0, 30.0)
    assert len(r2) == 31
    np.testing.assert_allclose(p2[-1], root[-1])
    assert np.max(quat_angle(r2, rot[::2])) < 1e-9
    r3, p3 = resample(rot, root, 60.0, 120.0)
    assert len(r3) == 121
    np.testing.assert_allclose(p3[1], 0.5 * (root[0] + root[1]))
    mid = quat_angle(r3[1], rot[0]) - quat_angle(r3[1], rot[1])
    assert np.max(np.abs(mid)) < 1e-9  # slerp midpoint is equidistant
    with pytest.raises(ValueError):
        resample(rot, root, 0.0, 30.0)


def test_retime_plays_the_motion_slower_at_the_same_frame_rate():
    sk, rot, root = _walk(61)
    m = process_motion('walk', sk, rot, root, 30.0, 30.0)
    slow = retime(m, 0.5)
    assert slow.fps == 30.0 and slow.num_frames == 121 and slow.contacts.shape == (121, 4)
    # the same path, twice the frames: every second frame is an input frame
    np.testing.assert_allclose(slow.root_positions[::2], m.root_positions, atol=1e-12)
    assert np.max(quat_angle(slow.rotations[::2], m.rotations)) < 1e-9
    np.testing.assert_array_equal(slow.contacts[::2], m.contacts)
    step = np.linalg.norm(np.diff(m.root_positions[:, :2], axis=0), axis=1).mean()
    step_slow = np.linalg.norm(np.diff(slow.root_positions[:, :2], axis=0), axis=1).mean()
    assert step_slow == pytest.approx(0.5 * step, rel=1e-6)
    fast = retime(m, 2.0)
    assert fast.num_frames == 31
    np.testing.assert_allclose(fast.root_positions, m.root_positions[::2], atol=1e-12)
    assert retime(m, 1.0) is m
    with pytest.raises(ValueError, match='speed'):
        retime(m, 0.0)


def test_process_motion_puts_floor_at_zero_and_labels_contacts():
    sk, rot, root = _walk()
    m = process_motion('walk', sk, rot, root, 30.0, 30.0)
    pts = contact_point_positions(sk, m.rotations, m.root_positions)
    np.testing.assert_allclose(floor_plane(pts, 30.0), 0.0, atol=1e-3)
    assert abs(floor_height(pts)) < 1e-3
    assert m.contacts.shape == (120, 4) and m.contacts.dtype == bool
    # a point high above the floor or moving fast is never in contact
    high = pts[..., 2] > 0.05
    assert not np.any(m.contacts & high)


def test_sloped_capture_floor_is_levelled():
    """A walk on a floor rising 2 cm per metre ends up on the level floor z = 0."""
    sk, rot, root = _walk(150)
    root = root.copy()
    root[:, 2] += 0.02 * root[:, 0]
    pts = contact_point_positions(sk, rot, root)
    plane = floor_plane(pts, 30.0)
    assert plane[1] == pytest.approx(0.02, abs=2e-3) and abs(plane[2]) < 2e-3
    m = process_motion('slope', sk, rot, root, 30.0, 30.0)
    levelled = contact_point_positions(sk, m.rotations, m.root_positions)
    low = levelled[..., 2].min(axis=1)
    assert np.ptp(np.percentile(low.reshape(5, -1), 10, axis=1)) < 0.01  # no drift along x


def test_contact_labels_thresholds():
    p = np.zeros((5, 4, 3))
    p[:, 1, 2] = 0.2                           # toe 20 cm up: no contact
    p[:, 2, 0] = np.arange(5) * 0.1            # heel sliding at 3 m/s: no contact
    c = contact_labels(p, 30.0, 0.0)
    assert c[:, 0].all() and not c[:, 1].any() and not c[:, 2].any() and c[:, 3].all()


def test_keypoints_3d_match_joints_and_face_geometry():
    sk = Skeleton.default()
    rot = np.zeros((1, NUM_JOINTS, 4))
    rot[..., 3] = 1
    kp = keypoints_3d(sk, rot, np.array([[0, 0, 1.0]]))[0]
    pos = forward_kinematics(sk.parents, sk.offsets, rot, np.array([[0, 0, 1.0]])).positions[0]
    np.testing.assert_allclose(kp[KEYPOINT_INDEX['left_knee']], pos[JOINT_INDEX['left_knee']])
    assert kp[KEYPOINT_INDEX['nose'], 0] > pos[JOINT_INDEX['head'], 0] + 0.05   # nose in front
    assert kp[KEYPOINT_INDEX['left_ear'], 1] > 0 > kp[KEYPOINT_INDEX['right_ear'], 1]
    assert kp[KEYPOINT_INDEX['left_big_toe'], 0] > kp[KEYPOINT_INDEX['left_heel'], 0]
    assert abs(kp[KEYPOINT_INDEX['left_heel'], 2] - kp[KEYPOINT_INDEX['left_big_toe'], 2]) < 1e-9


def test_projection_of_a_known_point():
    intr = CameraIntrinsics(640, 480, 500.0, 500.0, 320.0, 240.0)
    cam = VirtualCamera(intr, look_at(np.array([-5.0, 0, 1]), np.array([0.0, 0, 1])),
                        np.array([-5.0, 0, 1]))
    # camera looks along +x: a point 1 m to the right (-y) and 0.5 m up, 5 m ahead
    uv = project(cam, np.array([[0.0, -1.0, 1.5]]))[0]
    np.testing.assert_allclose(uv[:2], [320 + 500 * 1 / 5, 240 - 500 * 0.5 / 5])
    kc = canonicalize(uv[None], intr)[0]
    np.testing.assert_allclose(kc[:2], [0.2, -0.1])


def test_sampled_cameras_keep_subject_in_view():
    sk, rot, root = _walk()
    pts = keypoints_3d(sk, rot, root)
    rng = np.random.default_rng(0)
    for _ in range(20):
        cam = sample_camera(pts, rng, CameraSampling())
        assert in_view(cam, pts, margin=0.0)
        kp = project(cam, pts)
        assert kp.shape == (120, NUM_KEYPOINTS, 3)


def test_steep_cameras_look_down_from_their_elevation_and_see_the_subject():
    sk, rot, root = _walk(60)
    pts = keypoints_3d(sk, rot, root)
    # without steep cameras the camera and the generator's next draw are those the sampler
    # gave before steep cameras existed (figures of the code of commit 7839b36): existing
    # training configurations draw the same data
    rng = np.random.default_rng(5)
    a = sample_camera(pts, rng, CameraSampling())
    np.testing.assert_allclose(a.position, [5.231332495193085, 0.4258250839789884,
                                            0.4970752642869816], rtol=1e-12)
    assert rng.random() == pytest.approx(0.9991761150650714, rel=1e-12)
    cfg = CameraSampling(steep_fraction=1.0, steep_elevation=(40.0, 60.0))
    rng = np.random.default_rng(6)
    for _ in range(20):
        cam = sample_camera(pts, rng, cfg)
        assert in_view(cam, pts, margin=0.0)
        # aimed within the aim jitter of the subject's centre: its axis looks down at about
        # the drawn elevation (the jitter moves it a few degrees)
        assert 30.0 < float(camera_pitch_deg(cam.rotation)) < 70.0
    # the usual ranges hardly ever look down that far
    rng = np.random.default_rng(7)
    usual = [float(camera_pitch_deg(sample_camera(pts, rng, CameraSampling()).rotation))
             for _ in range(50)]
    assert max(usual) < 30.0


def test_motion_to_camera_matches_projection_of_fk():
    sk, rot, root = _walk(10)
    cam = sample_camera(keypoints_3d(sk, rot, root), np.random.default_rng(1))
    crot, croot = motion_to_camera(rot, root, cam)
    pos_cam = forward_kinematics(sk.parents, sk.offsets, crot, croot).positions
    pos_world = forward_kinematics(sk.parents, sk.offsets, rot, root).positions
    np.testing.assert_allclose(pos_cam, cam.world_to_camera(pos_world), atol=1e-9)


def test_mirror_motion_is_a_reflection():
    sk, rot, root = _walk(10)
    rng = np.random.default_rng(2)
    rot = quat_normalize(rot + 0.3 * rng.normal(size=rot.shape))
    mrot, mroot = mirror_motion(rot, root)
    p = forward_kinematics(sk.parents, sk.offsets, rot, root).positions
    mp = forward_kinematics(sk.parents, sk.offsets, mrot, mroot).positions
    from mocap_core.skeleton import JOINT_MIRROR
    expected = p[:, list(JOINT_MIRROR)] * np.array([1, -1, 1])
    np.testing.assert_allclose(mp, expected, atol=1e-9)
    r2, p2 = mirror_motion(mrot, mroot)
    assert np.max(quat_angle(r2, rot)) < 1e-9


def test_mirror_keypoints_swaps_sides():
    kp = np.zeros((NUM_KEYPOINTS, 3))
    kp[KEYPOINT_INDEX['left_wrist']] = [100, 50, 0.9]
    m = mirror_keypoints(kp, 640)
    np.testing.assert_allclose(m[KEYPOINT_INDEX['right_wrist']], [539, 50, 0.9])
    assert np.all(m[KEYPOINT_INDEX['left_wrist']] == 0)


def test_corruption_follows_the_confidence_model():
    model = ConfidenceModel.default()
    assert model.frames > 1000 and 'OpenPose' in model.source
    zero = model.zero_prob
    assert zero[KEYPOINT_INDEX['left_ear']] > zero[KEYPOINT_INDEX['left_hip']]
    rng = np.random.default_rng(3)
    clean = np.zeros((4000, NUM_KEYPOINTS, 3))
    clean[..., 0] = 300
    clean[..., 1] = np.linspace(100, 700, NUM_KEYPOINTS)
    clean[..., 2] = 1
    cfg = Corruption(extra_drop_prob=0.0, drop_frame_prob=0.0)
    out = corrupt_keypoints(clean, rng, model, cfg)
    zero = out[..., 2] == 0
    np.testing.assert_allclose(zero.mean(axis=0), model.zero_prob, atol=0.02)
    assert np.all(out[zero] == 0)
    seen = ~zero
    # displacement bounded by beta * (1 - c) * person height (600 px)
    d = np.linalg.norm(out[..., :2] - clean[..., :2], axis=-1)
    bound = cfg.beta * 600 * (1 - out[..., 2]) + 1e-6
    assert np.all(d[seen] <= bound[seen])
    k = KEYPOINT_INDEX['left_knee']
    assert abs(out[seen[:, k], k, 2].mean() - model.mean[k]) < 0.02
    dropped = corrupt_keypoints(clean, rng, model, Corruption(drop_frame_prob=1.0))
    assert np.all(dropped == 0)
