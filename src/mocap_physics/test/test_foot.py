"""The flat-foot pitch: the heel point placed for the motion's own flat foot, and its estimate
from the input (``flat_foot_pitch_deg`` -1)."""

import numpy as np
import pytest

from mocap_core.pose import Pose
from mocap_core.rotations import axis_angle_to_quat
from mocap_core.skeleton import Skeleton
from mocap_physics.cycle_params import PhysicsParams
from mocap_physics.floor import FloorFrame
from mocap_physics.foot import FLAT_FOOT_MIN_SAMPLES, FlatFootEstimator, contact_positions
from mocap_physics.online import OnlinePhysics


def _standing(pitch_deg: float, lift: float = 0.0) -> Pose:
    """The rest pose with both ankles turned toe-down so that the ankle-to-toe bone is
    ``pitch_deg`` below the floor, raised so that the toes stand on z = 0 (+ ``lift``)."""
    sk = Skeleton.default()
    rest = Pose.rest(sk)
    rot = rest.rotations.copy()
    for side in ('left', 'right'):
        rot[sk.joint_names.index(f'{side}_ankle')] = axis_angle_to_quat(
            np.array([0.0, np.radians(pitch_deg - 30.0), 0.0]))
    pose = Pose(sk, rot, rest.root_position)
    toe = pose.joint_positions()[sk.joint_names.index('left_toe')]
    return Pose(sk, rot, rest.root_position + np.array([0.0, 0.0, lift - toe[2]]))


def _foot_pitch(pose: Pose, side: str = 'left') -> float:
    names = pose.skeleton.joint_names
    pos = pose.joint_positions()
    v = pos[names.index(f'{side}_toe')] - pos[names.index(f'{side}_ankle')]
    return float(np.degrees(np.arcsin(-v[2] / np.linalg.norm(v))))


def test_the_estimator_takes_feet_that_stand_flat_and_nothing_else():
    est = FlatFootEstimator()
    flat, lifted = _standing(40.0), _standing(40.0, lift=0.2)
    both = np.full(4, 0.9)
    assert est.add(flat, None) == 0                              # no contacts: no sample
    assert est.add(flat, np.array([0.9, 0.2, 0.9, 0.9])) == 1    # left toe not in contact
    assert est.add(lifted, both) == 0                            # labelled, but 20 cm up
    assert est.add(flat, np.array([np.nan, 0.9, 0.9, 0.9])) == 0
    assert est.estimate() is None
    for _ in range(FLAT_FOOT_MIN_SAMPLES // 2):
        est.add(flat, both)
    assert est.estimate() == pytest.approx(40.0, abs=1e-6)
    # the median: a few wrong samples do not move it
    for _ in range(5):
        est.add(_standing(10.0), both)
    assert est.estimate() == pytest.approx(40.0, abs=1e-6)


@pytest.mark.parametrize('pitch', [30.0, -1.0])
def test_a_flat_foot_of_40_degrees_keeps_its_pitch_with_the_estimate(pitch):
    """A person standing still with flat feet whose ankle-to-toe bone is 40 degrees below the
    floor (the Bandai Namco convention). With the template's heel points (30) the physics
    holds heel and toe on the floor by turning the foot toe-up to about 30 degrees; with the
    pitch estimated from the input (-1) the heel points move and the foot keeps its 40."""
    target = _standing(40.0)
    online = OnlinePhysics(PhysicsParams(flat_foot_pitch_deg=pitch), FloorFrame.identity())
    probs = np.full(4, 0.95)
    out = None
    for k in range(60):
        frame = online.step(int(k * 1e9 / 30), target, probabilities=probs)
        out = frame.result.pose if frame is not None else out
    got = _foot_pitch(out)
    if pitch < 0:
        assert online.cycle.flat_foot_pitch == pytest.approx(40.0, abs=0.5)
        # decided once: the estimator stopped, the model was rebuilt once
        assert online.flat_foot is None and online.flat_foot_estimate == pytest.approx(40.0,
                                                                                       abs=0.5)
        assert online.cycle.stats.model_builds == 2
        assert got == pytest.approx(40.0, abs=2.0), got
        # heel and toe of the output on the floor together
        cp = contact_positions(out, online.cycle.flat_foot_pitch)
        assert np.abs(cp[:, 2]).max() < 0.01, cp[:, 2]
    else:
        assert online.cycle.flat_foot_pitch == 30.0
        assert got < 35.0, got
