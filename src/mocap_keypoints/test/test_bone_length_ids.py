"""A person who leaves the picture and comes back gets their old id back from the bone lengths
the lifter holds for them (keypoint node and lifter node wired in one process, the keypoint
node reading OpenPose JSON files, so its tracker gives the ids as it does live)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[3]
BAGS = ROOT / 'bags'
GAP = 150                   # frames (5 s) person A is out of the picture


def _keypoints(bag: str):
    from mocap_core import topics
    from mocap_core.bag_io import BagReader, deserialize
    from mocap_core.ros_conversions import camera_info_to_intrinsics, cloud_to_keypoints

    kp, intr = [], None
    with BagReader(BAGS / bag) as reader:
        for m in reader.messages(topics=[topics.KEYPOINTS, topics.CAMERA_INFO]):
            msg = deserialize(m.data, m.msgtype)
            if m.topic == topics.KEYPOINTS:
                kp.append(cloud_to_keypoints(msg)[0])
            elif intr is None:
                intr = camera_info_to_intrinsics(msg)
    return np.array(kp), intr


def _body25(kp: np.ndarray) -> list:
    from mocap_core.skeleton import BODY25_TO_LAYOUT

    out = np.zeros((25, 3))
    for layout, b in enumerate(BODY25_TO_LAYOUT):
        out[b] = kp[layout]
    out[out[:, 2] <= 0] = 0.0
    return out.ravel().tolist()


@pytest.fixture(scope='module')
def scene(tmp_path_factory):
    """OpenPose JSON frames: person A (a CMU walk) for 90 frames, gone for GAP frames, back
    for the whole walk (168 frames, from its start); person B (a Bandai Namco subject waving,
    played back and forth) 350 px to the right throughout."""
    a, intr = _keypoints('gt_cmu_walk_12_02')
    b, _ = _keypoints('gt_bandai_wave_normal')
    b[..., 0] += 350.0 * (b[..., 2] > 0)
    rows_a = [a[k] for k in range(90)] + [None] * GAP + [a[k] for k in range(len(a))]
    pingpong = np.concatenate([b, b[::-1]])
    folder = tmp_path_factory.mktemp('openpose')
    for f, ka in enumerate(rows_a):
        people = [{'pose_keypoints_2d': _body25(pingpong[f % len(pingpong)])}]
        if ka is not None:
            people.insert(f % 2, {'pose_keypoints_2d': _body25(ka)})    # rows in any order
        (folder / f'scene_{f:012d}_keypoints.json').write_text(json.dumps({'people': people}))
    return folder, intr, len(rows_a), pingpong


def test_returning_person_takes_their_id_back(scene):
    import rclpy
    from rclpy.parameter import Parameter

    from mocap_core import topics
    from mocap_core.inprocess import InProcessGraph
    from mocap_core.ros_conversions import cloud_to_ids, cloud_to_keypoints, \
        msg_to_bodies_bone_lengths
    from mocap_keypoints.node import KeypointsNode
    from mocap_lifter.node import LifterNode

    folder, intr, frames, rows_b = scene
    fov = float(np.degrees(2.0 * np.arctan(intr.width / (2.0 * intr.fx))))
    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    recorded = []
    graph = InProcessGraph(record=lambda topic, msg, qos: recorded.append((topic, msg)))
    kp_node = graph.add(KeypointsNode(context=context, parameter_overrides=[
        Parameter('source', value='openpose_json'), Parameter('path', value=str(folder)),
        Parameter('fps', value=30.0), Parameter('realtime', value=False),
        Parameter('image_width', value=int(intr.width)),
        Parameter('image_height', value=int(intr.height)),
        Parameter('horizontal_fov_deg', value=fov),
        Parameter('id_by_bone_lengths', value=True)]))
    lifter = graph.add(LifterNode(context=context, parameter_overrides=[
        Parameter('skeleton_frames', value=45)]))
    try:
        # the lifter's bone lengths feed back into the tracker: mocap process's run stays one
        # frame after the other (the ids would otherwise depend on the threads' timing)
        assert not kp_node.offline_split
        assert kp_node.run_offline() == len(list(folder.glob('*.json')))
        graph.flush()
        lifter.flush()
        # who is who in each published frame: B's rows are B's keypoints of that frame
        ids_a, ids_b = [], []
        clouds = [msg for topic, msg in recorded if topic == topics.KEYPOINTS]
        for f, msg in enumerate(clouds):
            b = rows_b[f % len(rows_b)]
            for row, pid in zip(cloud_to_keypoints(msg), cloud_to_ids(msg)):
                if pid > 0:
                    seen = (row[:, 2] > 0) & (b[:, 2] > 0)
                    is_b = np.allclose(row[seen, :2], b[seen, :2], atol=1.0)
                    (ids_b if is_b else ids_a).append(int(pid))
        assert len(clouds) == frames
        first_a = ids_a[0]
        assert set(ids_b) == {ids_b[0]} and ids_b[0] != first_a     # B keeps one id
        # A came back under a new id, then took the old one back, and kept it to the end
        back = ids_a[90:]
        assert back[-1] == first_a
        new = [i for i in back if i != first_a]
        assert new and len(set(new)) == 1 and new[0] not in ids_b
        switch = len(back) - back[::-1].index(new[0])
        assert all(i == first_a for i in back[switch:])
        # the signature came from the lifter's held skeletons of both people
        tables = [msg_to_bodies_bone_lengths(m) for t, m in recorded
                  if t == topics.BODIES_BONE_LENGTHS]
        assert tables and {pid for table in tables for pid, _ in table} >= {first_a, new[0]}
        assert kp_node.tracker.stats.renamed == 1
        # A's rows of the return, before and after the renaming
        print(f'A: id {first_a}, back as {new[0]} for {switch} frames, then {first_a} for '
              f'{len(back) - switch}')
    finally:
        kp_node.shutdown()
        for n in (kp_node, lifter):
            n.destroy_node()
        context.try_shutdown()
