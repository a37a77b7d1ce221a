"""The person's size from a known camera pose (:mod:`mocap_lifter.known_floor`)."""

from __future__ import annotations

import numpy as np
import pytest

from mocap_core.pose import Pose
from mocap_core.rotations import axis_angle_to_matrix, matrix_to_quat, quat_multiply
from mocap_core.skeleton import CONTACT_POINT_NAMES, Skeleton
from mocap_lifter.known_floor import SizeFromKnownFloor, scale_pose

HEIGHTS = (0.02,) * 4


def _camera(height: float = 1.6, pitch_deg: float = 20.0, yaw_deg: float = 30.0):
    """A camera ``height`` m above the floor looking ``pitch_deg`` down: its optical frame's
    pose (R, t) in the z-up world (x_world = R x_optical + t)."""
    body_to_optical = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    R = (axis_angle_to_matrix(np.array([0.0, 0.0, np.radians(yaw_deg)]))
         @ axis_angle_to_matrix(np.array([0.0, np.radians(pitch_deg), 0.0])) @ body_to_optical)
    return R, np.array([-3.0, 0.5, height])


def _standing(skeleton: Skeleton, camera, lean_deg: float = 0.0) -> Pose:
    """The rest pose standing in the world with its contact points at ``HEIGHTS``, 3-4 m in
    front of ``camera``, expressed in the camera's optical frame."""
    R, t = camera
    rest = Pose.rest(skeleton, np.zeros(3))
    rot = rest.rotations.copy()
    rot[0] = matrix_to_quat(axis_angle_to_matrix(np.array([np.radians(lean_deg), 0.0, 0.0])))
    world = Pose(skeleton, rot, np.zeros(3))
    lowest = min(p[2] for p in world.contact_positions().values())
    world = Pose(skeleton, rot, np.array([0.4, 0.8, HEIGHTS[0] - lowest]))
    # into the camera frame: x_c = R^T (x_w - t)
    q_cw = matrix_to_quat(R.T)
    rot_c = rot.copy()
    rot_c[0] = quat_multiply(q_cw, rot[0])
    return Pose(skeleton, rot_c, R.T @ (world.root_position - t))


def _world_heights(pose: Pose, camera) -> np.ndarray:
    R, t = camera
    cps = pose.contact_positions()
    return np.array([(R @ cps[n] + t)[2] for n in CONTACT_POINT_NAMES])


@pytest.mark.parametrize('pitch', [5.0, 20.0, 45.0])
def test_the_stance_feet_on_the_known_floor_give_the_size(pitch):
    """A body the network made 15 % too large (every joint along its camera ray: the same
    image) is taken back to its size: its feet stand on the known floor again."""
    camera = _camera(pitch_deg=pitch)
    truth = _standing(Skeleton.default(), camera)
    np.testing.assert_allclose(_world_heights(truth, camera), HEIGHTS, atol=1e-9)
    lifted = scale_pose(truth, 1.15)
    np.testing.assert_allclose(lifted.joint_positions()[:, :2] / lifted.joint_positions()[:, 2:],
                               truth.joint_positions()[:, :2] / truth.joint_positions()[:, 2:],
                               atol=1e-12)
    assert np.all(_world_heights(lifted, camera) < -0.05)        # sunk into the floor
    sizer = SizeFromKnownFloor(contact_heights=HEIGHTS, min_samples=8, rate=0.0)
    contacts = np.ones(4)
    sizer.observe(0, lifted, contacts, camera)          # 4 samples of the 8 needed
    assert sizer.applied_height is None and sizer.factor(lifted.skeleton) == 1.0
    for k in range(2, 10):
        sizer.observe(k * 33_000_000, lifted, contacts, camera)
    factor = sizer.factor(lifted.skeleton)
    assert factor == pytest.approx(1 / 1.15, rel=1e-9)
    assert sizer.stature() == pytest.approx(truth.skeleton.stature(), rel=1e-9)
    np.testing.assert_allclose(_world_heights(scale_pose(lifted, factor), camera), HEIGHTS,
                               atol=1e-9)


def test_only_stance_points_below_the_camera_count():
    """Points in the air (probability 0.5 or less), points without a height (the default's
    heels), frames without a camera pose, a camera at the feet's height and sizes no adult
    has give no sample."""
    camera = _camera()
    pose = scale_pose(_standing(Skeleton.default(), camera), 1.1)
    sizer = SizeFromKnownFloor(contact_heights=HEIGHTS, min_samples=1)
    assert sizer.observe(0, pose, np.array([0.9, 0.2, 0.5, 0.6]), camera) == 2
    assert sizer.observe(1, pose, np.ones(4), None) == 0
    low = _camera(height=0.2, pitch_deg=0.0)
    assert sizer.observe(2, _standing(Skeleton.default(), low), np.ones(4), low) == 0
    giant = _standing(Skeleton.default().scaled(1.5), camera)       # 2.5 m
    assert sizer.observe(3, giant, np.ones(4), camera) == 0 and sizer.refused == 4
    assert sizer.samples == 2
    toes = SizeFromKnownFloor(min_samples=1)
    assert toes.observe(0, pose, np.ones(4), camera) == 2


def test_the_size_follows_the_median_and_changes_in_steps():
    """The median of the window: a few frames with the feet off (a jump the contact
    probabilities missed) do not move it; a change below ``update`` is not applied, the
    window forgets old samples."""
    camera = _camera()
    truth = _standing(Skeleton.default(), camera)
    sizer = SizeFromKnownFloor(contact_heights=HEIGHTS, min_samples=4, window_s=2.0,
                               update=0.02, rate=0.0)
    ns = 33_333_333
    for k in range(30):
        sizer.observe(k * ns, truth, np.ones(4), camera)
    height = truth.skeleton.height()
    assert sizer.applied_height == pytest.approx(height)
    # the body 20 cm up for 10 frames (its points give a size 10-15 % small)
    air = _standing(Skeleton.default(), camera)
    air = Pose(air.skeleton, air.rotations, air.root_position + camera[0].T @ [0, 0, 0.2])
    for k in range(30, 40):
        sizer.observe(k * ns, air, np.ones(4), camera)
    assert sizer.applied_height == pytest.approx(height)
    # the network's own size does not matter (the same image, the same feet)
    sizer.observe(40 * ns, scale_pose(truth, 0.9), np.ones(4), camera)
    assert sizer.applied_height == pytest.approx(height)
    # a person 1 % larger for long: not applied (update 2 %); 5 %: applied once the window
    # turned
    start = 41
    for scale, applied in ((1.01, height), (1.05, 1.05 * height)):
        other = _standing(Skeleton.default().scaled(scale), camera)
        for k in range(start, start + 70):
            sizer.observe(k * ns, other, np.ones(4), camera)
        start += 70
        assert sizer.applied_height == pytest.approx(applied, rel=1e-9)


def test_the_size_applied_follows_the_estimate_at_its_rate():
    """From the network's own size when the first estimate comes, at most ``rate`` of itself
    per second (30 frames/s: 0.33 % a frame), then held; a gap in the frames counts as
    ``MAX_RAMP_STEP_S``: the size never jumps."""
    from mocap_lifter.known_floor import MAX_RAMP_STEP_S

    camera = _camera()
    truth = _standing(Skeleton.default(), camera)
    lifted = scale_pose(truth, 1.12)
    sizer = SizeFromKnownFloor(contact_heights=HEIGHTS, min_samples=8, rate=0.1)
    ns = 33_333_333
    factors = []
    for k in range(90):
        sizer.observe(k * ns, lifted, np.ones(4), camera)
        factors.append(sizer.factor(lifted.skeleton))
    factors = np.array(factors)
    assert factors[0] == 1.0                    # 4 samples; with 8 the target, one step
    assert factors[1] == pytest.approx(1 - 0.1 / 30)
    steps = np.abs(np.diff(factors))
    assert steps.max() <= 0.1 / 30 * 1.0001
    reached = int(np.argmax(np.abs(factors - 1 / 1.12) < 1e-9))
    assert 30 < reached < 45                              # 10.7 % at 10 %/s (of the size)
    assert np.all(factors[reached:] == factors[reached])
    gap = SizeFromKnownFloor(contact_heights=HEIGHTS, min_samples=4, rate=0.1)
    gap.observe(0, lifted, np.ones(4), camera)
    start = gap.applied_height
    gap.observe(10**10, lifted, np.ones(4), camera)                 # 10 s later
    assert gap.applied_height == pytest.approx(start * (1 - 0.1 * MAX_RAMP_STEP_S))


def test_bad_settings_are_refused():
    with pytest.raises(ValueError):
        SizeFromKnownFloor(contact_heights=(0.0, 0.0))
    with pytest.raises(ValueError):
        SizeFromKnownFloor(contact_heights=(float('nan'),) * 4)
    with pytest.raises(ValueError):
        SizeFromKnownFloor(floor_z=float('nan'))
    with pytest.raises(ValueError):
        SizeFromKnownFloor(statures=(2.0, 1.0))
