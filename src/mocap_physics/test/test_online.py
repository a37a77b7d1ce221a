"""OnlinePhysics: the node's streaming logic (contacts by stamp, order, restarts, floor, cycle),
checked against the cycle driven by hand."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mocap_core.pose import Pose
from mocap_core.skeleton import Skeleton
from mocap_physics.cycle import PhysicsCycle
from mocap_physics.cycle_params import PhysicsParams
from mocap_physics.floor import FloorFrame, FloorTracker
from mocap_physics.online import Notice, OnlinePhysics

BAG = Path(__file__).resolve().parents[3] / 'bags' / 'gt_bandai_walk_exhausted'
DT = 33_333_333
T0 = 5_000_000_000


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture(scope='module')
def clip():
    from mocap_physics.training.evaluate import load_gt_bag
    c = load_gt_bag(BAG)
    n = 45
    return replace(c, stamps=c.stamps[:n], rotations=c.rotations[:n],
                   root_positions=c.root_positions[:n], contacts=c.contacts[:n],
                   labels=c.labels[:n], gt_rotations=c.gt_rotations[:n],
                   gt_root_positions=c.gt_root_positions[:n])


def _spy(online: OnlinePhysics) -> list:
    """Record (time, probabilities) of every cycle step."""
    calls = []
    step = online.cycle.step

    def spy(target, stamp=None, contact_probabilities=None, alpha=None, **kwargs):
        calls.append((stamp, None if contact_probabilities is None
                      else np.array(contact_probabilities)))
        return step(target, stamp, contact_probabilities, alpha, **kwargs)
    online.cycle.step = spy
    return calls


def _streaming(**kwargs):
    clock = FakeClock()
    notices = []
    online = OnlinePhysics(PhysicsParams(), None, clock=clock, report=notices.append,
                           **kwargs)
    return online, clock, notices, _spy(online)


def test_fixed_floor_is_the_cycle_on_the_transformed_target(clip):
    online = OnlinePhysics(PhysicsParams(), clip.to_world, skeleton=clip.skeleton)
    cycle = PhysicsCycle(clip.skeleton, PhysicsParams())
    for i in range(clip.num_frames):
        out = online.step(T0 + i * DT, clip.pose(i), 'camera_optical_frame', clip.contacts[i])
        ref = cycle.step(clip.to_world.transform_pose(clip.pose(i)), (T0 + i * DT) * 1e-9,
                         clip.contacts[i])
        np.testing.assert_array_equal(out.result.q, ref.q)
        np.testing.assert_array_equal(out.result.contact_forces, ref.contact_forces)
    assert out.frame_id == 'floor' and out.input_frame == 'camera_optical_frame'
    assert out.floor is clip.to_world
    assert online.last_stamp == T0 + (clip.num_frames - 1) * DT


def test_estimated_floor_matches_the_hand_driven_sequence(clip):
    """The tracker's re-estimates re-express the simulated state (change_frame), exactly as
    the evaluation used to do by hand."""
    online = OnlinePhysics(PhysicsParams(), FloorTracker(), skeleton=clip.skeleton)
    tracker, cycle, frame = FloorTracker(), PhysicsCycle(clip.skeleton, PhysicsParams()), None
    for i in range(clip.num_frames):
        t = float(clip.stamps[i])
        out = online.step(int(round(t * 1e9)), clip.pose(i), probabilities=clip.contacts[i],
                          time_s=t)
        new, changed = tracker.update(clip.pose(i), clip.contacts[i])
        if changed:
            delta = new.compose(frame.inverse())
            cycle.change_frame(delta.rotation, delta.translation)
        frame = new
        ref = cycle.step(frame.transform_pose(clip.pose(i)), t, clip.contacts[i])
        np.testing.assert_array_equal(out.result.q, ref.q)
        np.testing.assert_array_equal(out.floor.rotation, frame.rotation)
    assert online.cycle.stats.frame_changes == cycle.stats.frame_changes >= 1


def test_no_floor_drops_the_frame():
    class Broken(FloorTracker):
        def update(self, pose, probabilities, *args, **kwargs):
            raise ValueError('no finite contact point')

    notices = []
    online = OnlinePhysics(PhysicsParams(), Broken(), report=notices.append)
    assert online.step(T0, Pose.rest(Skeleton.default())) is None
    assert [(n.key, n.level, n.dropped) for n in notices] == [
        ('floor', 'warn', False), ('floor', 'problem', True)]
    assert online.last_stamp == -1 and online.cycle.stats.frames == 0


def test_a_static_camera_keeps_the_floor_window_from_restarting():
    """``camera_static`` (the camera-motion estimate says the camera stands still) reaches
    the floor tracker as ``restart=False`` through the queue; other frames may restart."""
    seen = []

    class Spy(FloorTracker):
        def update(self, pose, probabilities, world=None, restart=True):
            seen.append(restart)
            return super().update(pose, probabilities, world, restart)

    online = OnlinePhysics(PhysicsParams(), Spy())
    rest = Pose.rest(Skeleton.default(), np.array([0.0, 1.0, 3.0]))
    online.add_motion(T0, rest, 'camera_optical_frame', camera_static=True)
    online.add_motion(T0 + DT, rest, 'camera_optical_frame', camera_moving=True)
    online.add_motion(T0 + 2 * DT, rest, 'camera_optical_frame')
    online.flush()
    assert seen == [False, True, True]


def test_the_moving_gains_go_to_frames_of_a_moving_camera_not_carried(clip):
    """``camera_moving`` reaches the cycle as ``moving_gains`` through the queue, except in a
    frame whose camera pose carries the body (its motion is then taken out)."""
    online = OnlinePhysics(PhysicsParams(), clip.to_world, skeleton=clip.skeleton)
    seen = []
    step = online.cycle.step

    def spy(*args, **kwargs):
        seen.append(kwargs.get('moving_gains'))
        return step(*args, **kwargs)
    online.cycle.step = spy
    camera = (np.eye(3), np.zeros(3))
    online.add_motion(T0, clip.pose(0), 'camera_optical_frame', camera_moving=True)
    online.add_motion(T0 + DT, clip.pose(1), 'camera_optical_frame', camera_static=True)
    online.add_motion(T0 + 2 * DT, clip.pose(2), 'camera_optical_frame', camera=camera,
                      camera_moving=True)
    online.flush()
    assert seen == [True, False, False]


def test_contacts_matched_by_stamp_wait_and_age():
    rest = Pose.rest(Skeleton.default())
    online, clock, notices, calls = _streaming(contacts_expected=lambda: True,
                                               contacts_wait_s=0.05, contacts_max_age_s=0.1)
    a = np.array([1.0, 1.0, 0.0, 0.0])
    b = np.array([0.0, 0.0, 1.0, 1.0])
    # the contacts come after the motion: the frame waits for them
    assert online.add_motion(T0, rest, 'world') == []
    out = online.add_contacts(T0, a)
    assert [f.stamp_ns for f in out] == [T0]
    np.testing.assert_array_equal(calls[-1][1], a)
    assert calls[-1][0] == pytest.approx(T0 * 1e-9)
    assert out[0].frame_id == 'world' and out[0].floor is None
    # the contacts came first: the frame goes at once
    online.add_contacts(T0 + DT, b)
    assert [f.stamp_ns for f in online.add_motion(T0 + DT, rest)] == [T0 + DT]
    np.testing.assert_array_equal(calls[-1][1], b)
    # none come: it waits contacts_wait_s, then takes the newest older ones (33 ms old)
    assert online.add_motion(T0 + 2 * DT, rest) == []
    clock.now += 0.04
    assert online.process() == []
    clock.now += 0.02
    assert [f.stamp_ns for f in online.process()] == [T0 + 2 * DT]
    np.testing.assert_array_equal(calls[-1][1], b)
    # newer contacts arrived (its own were lost): no wait
    online.add_contacts(T0 + 4 * DT, a)
    assert [f.stamp_ns for f in online.add_motion(T0 + 3 * DT, rest)] == [T0 + 3 * DT]
    np.testing.assert_array_equal(calls[-1][1], b)        # 67 ms old: still used
    # too old (more than contacts_max_age_s): none, the kinematics decide
    assert online.add_motion(T0 + 8 * DT, rest) == []
    assert len(online.flush()) == 1
    assert calls[-1][1] is None
    assert 'nocontacts' in [n.key for n in notices]
    assert not any(n.dropped for n in notices)


def test_contacts_still_expected_after_their_publisher_left():
    """A lagging node: the contacts publisher (a bag player at its end) is gone, but its
    messages still wait in the queue behind the motion. Once contacts have arrived, a frame
    waits for its own instead of silently taking the previous frame's."""
    rest = Pose.rest(Skeleton.default())
    publisher = {'up': True}
    online, clock, notices, calls = _streaming(contacts_expected=lambda: publisher['up'],
                                               contacts_wait_s=0.05)
    a = np.array([1.0, 1.0, 0.0, 0.0])
    b = np.array([0.0, 0.0, 1.0, 1.0])
    online.add_contacts(T0, a)
    assert [f.stamp_ns for f in online.add_motion(T0, rest)] == [T0]
    publisher['up'] = False
    assert online.add_motion(T0 + DT, rest) == []           # waits for its own contacts
    assert [f.stamp_ns for f in online.add_contacts(T0 + DT, b)] == [T0 + DT]
    np.testing.assert_array_equal(calls[-1][1], b)
    assert online.add_motion(T0 + 2 * DT, rest) == []       # none come: waits, then the
    clock.now += 0.06                                       # newest older ones
    assert [f.stamp_ns for f in online.process()] == [T0 + 2 * DT]
    np.testing.assert_array_equal(calls[-1][1], b)


def test_without_a_contacts_input_nothing_waits():
    rest = Pose.rest(Skeleton.default())
    online, clock, notices, calls = _streaming()
    assert len(online.add_motion(T0, rest)) == 1
    assert calls[-1][1] is None
    assert notices == []          # no "no contacts" warning when there is no contacts input


def test_order_and_restart():
    rest = Pose.rest(Skeleton.default())
    online, clock, notices, calls = _streaming(contacts_expected=lambda: True)
    for i in range(3):
        online.add_contacts(T0 + i * DT, np.ones(4))
        assert len(online.add_motion(T0 + i * DT, rest)) == 1
    # a duplicate and a stamp going back (less than the restart threshold): dropped
    for stamp in (T0 + 2 * DT, T0 + DT):
        accepted, frames = online.admit(stamp)
        assert not accepted and frames == []
    assert online.add_motion(T0, rest) == []
    assert [(n.key, n.level, n.dropped) for n in notices] == [('order', 'problem', True)] * 3
    assert len(calls) == 3
    # one frame waits for its contacts when the bag restarts 3 s earlier: it is finished
    # first (without waiting), then the new stream starts
    online.add_contacts(T0 + 3 * DT, np.ones(4))
    assert online.add_motion(T0 + 4 * DT, rest) == []          # waits for its contacts
    new = T0 - 3_000_000_000
    online.add_contacts(new, np.full(4, 0.9))                  # older: it still waits
    assert len(online.pending) == 1
    notices.clear()
    frames = online.add_motion(new, rest)
    assert [f.stamp_ns for f in frames] == [T0 + 4 * DT, new]
    assert (notices[0].key, notices[0].level) == ('restart', 'warn')
    assert [n.key for n in notices].count('restart') == 1
    np.testing.assert_array_equal(calls[-2][1], np.ones(4))    # the 33 ms older contacts
    np.testing.assert_array_equal(calls[-1][1], np.full(4, 0.9))
    # contacts more than 1 s after the new stamp are forgotten
    assert list(online.contacts) == [new]
    assert online.last_stamp == new and not online.pending
    assert 'time_jump' in online.last_result.status


def test_notices_of_the_cycle_and_step_times():
    rest = Pose.rest(Skeleton.default())
    times = []
    notices = []
    online = OnlinePhysics(PhysicsParams(), None, report=notices.append,
                           record_time=times.append)
    online.step(T0, rest, probabilities=np.ones(4))
    online.step(T0 + 2_000_000_000, rest, probabilities=np.ones(4))     # a time jump
    assert len(times) == 2 and all(t > 0 for t in times)
    keys = [(n.key, n.level) for n in notices]
    assert ('time jump of 2.000 s', 'warn') in keys
    assert ('status', 'status') in keys
    assert all(isinstance(n, Notice) for n in notices)
    # a malformed first target cannot be simulated: dropped, counted, no exception
    notices.clear()
    fresh = OnlinePhysics(PhysicsParams(), None, report=notices.append,
                          record_time=times.append)
    bad = Pose(Skeleton(np.zeros((18, 3))), rest.rotations, rest.root_position)
    assert fresh.step(T0, bad) is None
    assert [(n.key, n.dropped) for n in notices] == [('skeleton', True)]
    assert len(times) == 3


def test_output_frame_names():
    rest = Pose.rest(Skeleton.default())
    fixed = FloorFrame.from_camera_height_pitch(1.5, 0.1)
    assert OnlinePhysics(PhysicsParams(), fixed).step(T0, rest, '').frame_id == 'floor'
    out = OnlinePhysics(PhysicsParams(), fixed, frame_id='ground').step(T0, rest, 'cam')
    assert (out.frame_id, out.input_frame) == ('ground', 'cam')
    out = OnlinePhysics(PhysicsParams(), None).step(T0, rest, '')
    assert (out.frame_id, out.input_frame) == ('world', 'camera_optical_frame')
    assert OnlinePhysics(PhysicsParams(), None).step(T0, rest, 'map').frame_id == 'map'
