"""Several people through the pipeline's nodes in one process (InProcessGraph, lossless and
deterministic): each person is followed by every stage on their own, and a person's output
does not depend on who else is in the picture."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
BAGS = [ROOT / 'bags' / 'gt_cmu_walk_12_02', ROOT / 'bags' / 'gt_bandai_wave_normal']
DT = 33_333_333
T0 = 1_700_000_000_000_000_000
FRAMES = 60


@pytest.fixture(scope='module')
def two_people():
    """(F, 23, 3) keypoints of two recorded persons (the second shifted 300 px right) and
    the first bag's camera_info."""
    from mocap_core import topics
    from mocap_core.bag_io import BagReader, deserialize
    from mocap_core.ros_conversions import cloud_to_keypoints

    out, info = [], None
    for bag in BAGS:
        kp = []
        with BagReader(bag) as reader:
            for m in reader.messages(topics=[topics.KEYPOINTS, topics.CAMERA_INFO]):
                msg = deserialize(m.data, m.msgtype)
                if m.topic == topics.KEYPOINTS and len(kp) < FRAMES:
                    kp.append(cloud_to_keypoints(msg)[0])
                elif m.topic == topics.CAMERA_INFO and info is None:
                    info = msg
        out.append(np.array(kp))
    out[1][..., 0] += 300.0 * (out[1][..., 2] > 0)
    return out[0], out[1], info


def _run(frames, info, with_gmr=False):
    """Feed keypoint frames ``[(rows, ids)]`` through lifter -> physics (-> GMR); return
    ``{topic: [msg]}``."""
    import rclpy

    from mocap_core import topics
    from mocap_core.inprocess import InProcessGraph
    from mocap_core.ros_conversions import keypoints_to_cloud, make_header
    from mocap_lifter.node import LifterNode
    from mocap_physics.node import PhysicsNode

    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    by_topic = {}
    graph = InProcessGraph(record=lambda t, m, q: (by_topic.setdefault(t, []).append(m),
                                                   by_topic.setdefault('order', []).append(t)))
    nodes = [graph.add(LifterNode(context=context)),
             graph.add(PhysicsNode(context=context))]
    if with_gmr:
        from mocap_global.node import GMRNode
        nodes.append(graph.add(GMRNode(context=context)))
    try:
        for k, (rows, ids) in enumerate(frames):
            info.header.stamp.sec, info.header.stamp.nanosec = divmod(T0 + k * DT, 10**9)
            graph.publish(topics.CAMERA_INFO, info)
            graph.publish(topics.KEYPOINTS, keypoints_to_cloud(
                rows, make_header(T0 + k * DT, info.header.frame_id), ids=ids))
        graph.flush()
        return by_topic, nodes
    finally:
        for n in nodes:
            n.destroy_node()
        context.try_shutdown()


def test_two_people_through_every_stage(two_people):
    from mocap_core import topics
    from mocap_core.ros_conversions import motion_to_bodies, motion_to_pose

    a, b, info = two_people
    both, nodes = _run([(np.stack([a[k], b[k]]), [1, 2]) for k in range(FRAMES)], info, True)
    alone, _ = _run([(a[k][None], [1]) for k in range(FRAMES)], info, True)
    for pid in (1, 2):
        for name in ('motion', 'joints3d', 'joint_states', 'grf/left', 'grf/right'):
            assert len(both[topics.body_topic(pid, 'physics', name)]) == FRAMES, (pid, name)
    combined = both[topics.bodies_topic('physics', 'motion')]
    assert sorted({pid for m in combined for pid, _ in motion_to_bodies(m)}) == [1, 2]
    # one combined message per stamp with everybody in it (the world stage then runs its
    # network once for both)
    assert len(combined) == FRAMES
    assert all(len(motion_to_bodies(m)) == 2 for m in combined)
    # the main person (row 0, id 1) on the single-person topic: exactly as when alone
    main = both[topics.PHYSICS_MOTION]
    ref = alone[topics.PHYSICS_MOTION]
    assert len(main) == len(ref) == FRAMES
    for m, r in zip(main, ref):
        pm, pr = motion_to_pose(m), motion_to_pose(r)
        np.testing.assert_allclose(pm.root_position, pr.root_position, atol=1e-9)
        np.testing.assert_allclose(pm.rotations, pr.rotations, atol=1e-9)
    # person 2 is simulated separately (another body, somewhere else)
    p1 = motion_to_pose(both[topics.body_topic(1, 'physics', 'motion')][-1])
    p2 = motion_to_pose(both[topics.body_topic(2, 'physics', 'motion')][-1])
    assert np.linalg.norm(p1.root_position - p2.root_position) > 0.3
    # the world stage: each person's own world pose; the main person's as when alone
    for pid in (1, 2):
        for name in ('motion', 'joints3d', 'joint_states', 'odom', 'path'):
            assert len(both[topics.body_topic(pid, 'world', name)]) == FRAMES, (pid, name)
    main = both[topics.WORLD_MOTION]
    ref = alone[topics.WORLD_MOTION]
    assert len(main) == len(ref) == FRAMES
    for m, r in zip(main, ref):
        np.testing.assert_allclose(motion_to_pose(m).root_position,
                                   motion_to_pose(r).root_position, atol=1e-6)
    w1 = motion_to_pose(both[topics.body_topic(1, 'world', 'motion')][-1])
    w2 = motion_to_pose(both[topics.body_topic(2, 'world', 'motion')][-1])
    assert np.abs(w1.rotations - w2.rotations).max() > 0.1     # a walker and a waver
    # GMR's network read each person's own lifter pose in every frame (network_pose_topic)
    gmr = nodes[2]
    assert [gmr.persons[pid].online.network_pose_frames for pid in (1, 2)] == [FRAMES] * 2
    worlds = both[topics.bodies_topic('world', 'motion')]
    assert sorted({pid for m in worlds for pid, _ in motion_to_bodies(m)}) == [1, 2]
    assert len(worlds) == FRAMES
    # each frame's physics floor goes out before the combined motion that the world stage
    # follows (it places the frame on that floor: a frame without one is GMR's alone)
    order = [t for t in both['order']
             if t in (topics.PHYSICS_FLOOR, topics.bodies_topic('physics', 'motion'))]
    assert len(order) == 2 * FRAMES
    assert order[::2] == [topics.PHYSICS_FLOOR] * FRAMES


def test_mocap_process_and_bvh_export_of_two_people(two_people, tmp_path):
    """`mocap process` on a keypoint bag with two people: every stage's per-person and
    combined topics land in the output bag; `mocap export bvh --per-person` writes one file
    per person."""
    import subprocess
    import sys

    from mocap_core import topics
    from mocap_core.bag_io import BagReader, BagWriter
    from mocap_core.ros_conversions import keypoints_to_cloud, make_header

    a, b, info = two_people
    bag = tmp_path / 'two'
    with BagWriter(bag) as w:
        for k in range(FRAMES):
            stamp = T0 + k * DT
            info.header.stamp.sec, info.header.stamp.nanosec = divmod(stamp, 10**9)
            w.write_msg(topics.CAMERA_INFO, stamp, info)
            w.write_msg(topics.KEYPOINTS, stamp, keypoints_to_cloud(
                np.stack([b[k], a[k]]), make_header(stamp, info.header.frame_id), ids=[2, 1]))

    def mocap(*args):
        res = subprocess.run([sys.executable, '-m', 'mocap_core.cli.mocap', *map(str, args)],
                             capture_output=True, text=True, timeout=600)
        assert res.returncode == 0, res.stdout + res.stderr
        return res.stdout

    out = tmp_path / 'out'
    mocap('process', bag, '-o', out, '--no-progress')
    with BagReader(out) as r:
        counts = {t: i.count for t, i in r.topics.items()}
    for pid in (1, 2):
        for stage in ('lifter', 'physics', 'world'):
            assert counts[topics.body_topic(pid, stage, 'motion')] == FRAMES, (pid, stage)
    for stage in ('lifter', 'physics', 'world'):
        assert counts[topics.bodies_topic(stage, 'motion')] >= FRAMES
        assert counts[topics.stage_topic(stage, 'motion')] == FRAMES     # the main person
    text = mocap('export', 'bvh', out, '-o', tmp_path / 'walk.bvh', '--per-person',
                 '--topic', topics.WORLD_MOTION, '--frame', 'world')
    for pid in (1, 2):
        bvh = (tmp_path / f'walk_body_{pid}.bvh').read_text()
        assert f'Frames: {FRAMES}' in bvh, text
    # the report: a table of the persons, their paths in one colour each
    mocap('report', out, '-o', tmp_path / 'report')
    text = (tmp_path / 'report' / 'report.md').read_text()
    assert '## Persons' in text
    rows = [line for line in text.splitlines() if line.startswith('| 1 |')
            or line.startswith('| 2 |')]
    assert len(rows) == 2 and all(f'| {FRAMES} |' in r for r in rows), rows
    assert (tmp_path / 'report' / 'root_trajectory.png').stat().st_size > 1000


def _tf2_msgs() -> bool:
    try:
        import tf2_msgs.msg  # noqa: F401
    except ImportError:
        return False
    return True


@pytest.mark.skipif(not _tf2_msgs(), reason='tf2_msgs not built (scripts/setup.sh needs cmake '
                    'and a C/C++ compiler; see src/tf2_msgs/README.md)')
def test_tf_tree_of_two_people(two_people):
    """/tf from the world stage: every person's skeleton, frames body_<id> (in world) and
    body_<id>/<joint>, one TFMessage per person and frame."""
    a, b, info = two_people
    both, nodes = _run([(np.stack([a[k], b[k]]), [1, 2]) for k in range(FRAMES)], info, True)
    tf = both['/tf']
    children = {t.child_frame_id: t.header.frame_id for m in tf for t in m.transforms}
    assert children['body_1'] == children['body_2'] == 'world'
    assert children['body_2/left_knee'] == 'body_2/left_hip'
    assert children['body_1/left_hip'] == 'body_1'
    assert len(tf) == 2 * FRAMES
