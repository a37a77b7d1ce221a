"""Several people in the lifter: one stream per person id (mocap_lifter.online.PeopleStreams)
and the node's per-person and combined topics."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[3]
SHIPPED = ROOT / 'src' / 'mocap_lifter' / 'weights' / 'motionet_windowed.pt'
BAGS = [ROOT / 'bags' / 'gt_cmu_walk_12_02', ROOT / 'bags' / 'gt_bandai_wave_normal']
DT = 33_333_333
T0 = 1_700_000_000_000_000_000


@pytest.fixture(scope='module')
def two_people():
    """Keypoints (F, 23, 3) of two recorded persons (the first 60 frames of two bags, the
    second moved 300 px right) and the first bag's intrinsics."""
    from mocap_core import topics
    from mocap_core.bag_io import BagReader, deserialize
    from mocap_core.ros_conversions import camera_info_to_intrinsics, cloud_to_keypoints

    out, intr = [], None
    for bag in BAGS:
        kp = []
        with BagReader(bag) as reader:
            for m in reader.messages(topics=[topics.KEYPOINTS, topics.CAMERA_INFO]):
                msg = deserialize(m.data, m.msgtype)
                if m.topic == topics.KEYPOINTS and len(kp) < 60:
                    kp.append(cloud_to_keypoints(msg)[0])
                elif m.topic == topics.CAMERA_INFO and intr is None:
                    intr = camera_info_to_intrinsics(msg)
        out.append(np.array(kp))
    out[1][..., 0] += 300.0 * (out[1][..., 2] > 0)
    return out[0], out[1], intr


@pytest.fixture(scope='module')
def model():
    from mocap_lifter.weights import load_weights
    return load_weights(SHIPPED, 'cpu', causal=False)


def _streams(model, intr, **kw):
    from mocap_lifter.intrinsics import StreamIntrinsics
    from mocap_lifter.online import OnlineLifter, PeopleStreams
    si = StreamIntrinsics()
    si.set_camera_info(intr)
    return PeopleStreams(lambda: OnlineLifter(model, 'windowed'), si, **kw)


def _collect(into, step):
    for pid, st in step.steps.items():
        for f in st.frames:
            into.setdefault(pid, []).append(f)


def test_each_person_is_lifted_as_if_alone(two_people, model):
    """Rows shuffled, ids from the cloud: each id's output is exactly what its keypoints
    give alone (no state shared between people, no row mixed up)."""
    a, b, intr = two_people
    rng = np.random.default_rng(0)
    together = {}
    ps = _streams(model, intr)
    for k in range(len(a)):
        rows, ids = np.stack([a[k], b[k]]), np.array([7, 3])
        if rng.random() < 0.5:
            rows, ids = rows[::-1], ids[::-1]
        _collect(together, ps.push(T0 + k * DT, rows, ids))
    _collect(together, ps.flush())
    assert sorted(together) == [3, 7]
    for pid, kp in ((7, a), (3, b)):
        alone = {}
        single = _streams(model, intr)
        for k in range(len(kp)):
            _collect(alone, single.push(T0 + k * DT, kp[k][None], np.array([pid])))
        _collect(alone, single.flush())
        got, ref = together[pid], alone[pid]
        assert [f.stamp_ns for f in got] == [f.stamp_ns for f in ref] == \
            [T0 + k * DT for k in range(len(kp))]
        for f, r in zip(got, ref):
            np.testing.assert_allclose(f.pose.rotations, r.pose.rotations, atol=1e-6)
            np.testing.assert_allclose(f.pose.root_position, r.pose.root_position, atol=1e-6)


def test_person_leaving_ends_their_stream_and_old_clouds(two_people, model):
    a, b, intr = two_people
    ps = _streams(model, intr, timeout_s=0.5)
    frames, ended, mains = {}, [], []
    for k in range(60):
        if k < 20:
            rows, ids = np.stack([a[k], b[k]]), np.array([1, 2])
        else:                                   # person 2 leaves after frame 19
            rows, ids = a[k][None], np.array([1])
        step = ps.push(T0 + k * DT, rows, ids)
        _collect(frames, step)
        ended += step.ended
        mains.append(step.main)
    assert ended == [2] and sorted(ps.streams) == [1]
    # person 2's frames: up to 0.5 s after last seen (frames 0..34), all emitted at the end
    assert [f.stamp_ns for f in frames[2]] == [T0 + k * DT for k in range(35)]
    assert set(mains) == {1}
    # an older cloud without ids: its rows are persons 1, 2, ... in order
    old = _streams(model, intr)
    step = old.push(T0, np.stack([a[0], np.zeros_like(a[0]), b[0]]), None)
    assert sorted(old.streams) == [1, 3] and step.main == 1
    # more people than max_persons: the extra ones are ignored and counted
    few = _streams(model, intr, max_persons=1)
    few.push(T0, np.stack([a[0], b[0]]), np.array([4, 5]))
    assert sorted(few.streams) == [4] and few.ignored == 1
    with pytest.raises(ValueError):
        few.push(T0 + DT, np.stack([a[1], b[1]]), np.array([4]))


def test_only_keypoints_someone_hides_are_held(two_people, model):
    """hold_unseen_s with several people: a person's keypoint that goes unseen is held from
    its last sighting only where another person's box covers that sighting (hidden behind
    them), not where nobody stands in front of it (the detector dropped it)."""
    a, b, _ = two_people

    def held(in_front: bool, hide: bool) -> int:
        streams = _streams(model, two_people[2], hold_unseen_s=0.5)
        for k in range(20):
            bk = b[k].copy()
            if hide and k >= 10:
                bk[5] = 0.0                     # person 2's keypoint 5 unseen from frame 10
            rows, ids = [a[k], bk], [1, 2]
            if in_front:                        # a third person just in front of person 2
                c = b[k].copy()
                c[:, 0] += 10.0 * (c[:, 2] > 0)
                rows, ids = rows + [c], ids + [3]
            streams.push(T0 + k * DT, np.stack(rows), np.array(ids))
        assert streams.streams[1].held_keypoints == 0      # nobody in front of person 1
        return streams.streams[2].held_keypoints

    # (the recorded keypoints have dropouts of their own: those under person 3 are held too)
    assert held(in_front=False, hide=True) == 0
    assert held(in_front=True, hide=True) - held(in_front=True, hide=False) == 10


def test_node_publishes_each_person_and_all_together(two_people):
    """The node in process: per-person topics under /humans/bodies/body_<id>/lifter/, the
    combined joints cloud with one row per person, and the main person (row 0) on the
    single-person topics."""
    import rclpy

    from mocap_core import topics
    from mocap_core.inprocess import InProcessGraph
    from mocap_core.ros_conversions import (cloud_to_bodies, intrinsics_to_camera_info,
                                            keypoints_to_cloud, make_header, motion_to_bodies,
                                            motion_to_pose, msg_to_bodies_contacts)
    from mocap_lifter.node import LifterNode

    a, b, intr = two_people
    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    recorded = []
    graph = InProcessGraph(record=lambda topic, msg, qos: recorded.append((topic, msg)))
    node = graph.add(LifterNode(context=context))
    try:
        graph.publish(topics.CAMERA_INFO, intrinsics_to_camera_info(intr, make_header(T0, 'c')))
        for k in range(40):
            rows, ids = np.stack([a[k], b[k]]), [1, 2]
            if k % 2:
                rows, ids = rows[::-1], ids[::-1]     # row 0 alternates: main stays the
            graph.publish(topics.KEYPOINTS,                # longest tracked by the node's rule
                          keypoints_to_cloud(rows, make_header(T0 + k * DT, 'c'), ids=ids))
        graph.flush()
        by_topic = {}
        for topic, msg in recorded:
            by_topic.setdefault(topic, []).append(msg)
        for pid in (1, 2):
            for name in ('motion', 'joints3d', 'joint_states', 'contacts'):
                assert len(by_topic[topics.body_topic(pid, 'lifter', name)]) == 40
            assert len(by_topic[topics.body_urdf_topic(pid)]) >= 1
        combined = by_topic[topics.bodies_topic('lifter', 'joints3d')]
        assert len(combined) == 40
        pos, ids = cloud_to_bodies(combined[-1])
        assert sorted(ids.tolist()) == [1, 2] and pos.shape == (2, 18, 3)
        # the lossless combined motion and contacts (the physics stage's input)
        motions = by_topic[topics.bodies_topic('lifter', 'motion')]
        assert len(motions) == 40
        bodies = motion_to_bodies(motions[-1])
        assert sorted(pid for pid, _ in bodies) == [1, 2]
        np.testing.assert_allclose(
            dict(bodies)[2].root_position,
            motion_to_pose(by_topic[topics.body_topic(2, 'lifter', 'motion')][-1]).root_position)
        contacts = msg_to_bodies_contacts(by_topic[topics.bodies_topic('lifter', 'contacts')][-1])
        assert sorted(pid for pid, _ in contacts) == [1, 2]
        # the frames before the output smoothing (the world stage's network reads them):
        # everyone's of each stamp in one message, and the main person's alone
        stamp = lambda m: m.header.stamp.sec * 10**9 + m.header.stamp.nanosec  # noqa: E731
        raw = by_topic[topics.bodies_topic('lifter', 'unsmoothed_motion')]
        assert sorted(map(stamp, raw)) == sorted(map(stamp, motions))
        assert all(sorted(pid for pid, _ in motion_to_bodies(m)) == [1, 2] for m in raw)
        raw_main = by_topic[topics.LIFTER_UNSMOOTHED_MOTION]
        assert list(map(stamp, raw_main)) == list(map(stamp, by_topic[topics.LIFTER_MOTION]))
        markers = by_topic[topics.bodies_topic('lifter', 'markers')][-1]
        assert {m.ns for m in markers.markers} == {'lifter/body_1', 'lifter/body_2'}
        # the single-person topics: one message per stamp, stamps increasing
        main = by_topic[topics.LIFTER_MOTION]
        stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in main]
        assert len(stamps) == 40 and np.all(np.diff(stamps) > 0)
        # person 2's own topic carries person 2 (not a copy of person 1)
        p1 = motion_to_pose(by_topic[topics.body_topic(1, 'lifter', 'motion')][-1])
        p2 = motion_to_pose(by_topic[topics.body_topic(2, 'lifter', 'motion')][-1])
        assert np.abs(p1.root_position - p2.root_position).max() > 0.1
        values = {kv.key: kv.value for kv in node.diag.status().values}
        assert values['persons'] == '2' and values['person_ids'] == '1 2'
        assert node.bodies.ids == [1, 2]
        # person 2 leaves: after person_timeout_s (1 s) their stream ends and their topics go
        before = len(by_topic[topics.body_topic(2, 'lifter', 'motion')])
        recorded.clear()
        for k in range(40, 80):
            graph.publish(topics.KEYPOINTS, keypoints_to_cloud(
                a[k % len(a)][None], make_header(T0 + k * DT, 'c'), ids=[1]))
        graph.flush()
        assert node.bodies.ids == [1]
        values = {kv.key: kv.value for kv in node.diag.status().values}
        assert values['persons'] == '1' and values['person_ids'] == '1'
        later = [m for t, m in recorded if t == topics.body_topic(2, 'lifter', 'motion')]
        # person 2's frames up to 1 s after they were last seen (frame 39), then nothing
        assert before + len(later) == 40 + 30
    finally:
        node.destroy_node()
        context.try_shutdown()
