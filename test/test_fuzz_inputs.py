"""Malformed and fuzzed messages on every input topic of the lifter, physics and GMR nodes
(the real node classes, wired in one process by InProcessGraph, so every message is surely
delivered): wrong fields, wrong sizes, NaN/inf, empty clouds, huge values, stamps backwards,
duplicates, gaps, a wrong frame rate. No callback raises, no output holds NaN, every bad
message is counted on the node's diagnostics, and valid frames afterwards still go through."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
GT_BAG = ROOT / 'bags' / 'gt_cmu_walk_12_02'


@pytest.fixture(scope='module')
def valid():
    """The bag's first 60 keypoint clouds and camera infos, and the lifter's motion for them."""
    from mocap_core.bag_io import BagReader, deserialize

    clouds, infos = [], []
    with BagReader(GT_BAG) as reader:
        for m in reader.messages(topics=['/mocap/keypoints2d', '/mocap/camera_info']):
            (clouds if m.topic.endswith('keypoints2d') else infos).append(
                deserialize(m.data, m.msgtype))
    return clouds[:60], infos[:60]


@pytest.fixture
def pipeline():
    import rclpy

    from mocap_core.cli.process import OFFLINE_DEFAULTS, _overrides
    from mocap_core.inprocess import InProcessGraph
    from mocap_core.plugins import load_node_class

    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    outputs = []
    errors = []
    graph = InProcessGraph(record=lambda t, m, q: outputs.append((t, m)),
                           on_error=lambda n, t, e: errors.append((n, t, repr(e))))
    nodes = {}
    for name in ('lifter', 'physics', 'gmr'):
        cls = load_node_class(name)
        nodes[name] = graph.add(cls(context=context, parameter_overrides=_overrides(
            OFFLINE_DEFAULTS.get(name, {}))))
    yield graph, nodes, outputs, errors
    for node in nodes.values():
        node.destroy_node()
    context.try_shutdown()


def _stamped(msg, ns: int):
    m = copy.deepcopy(msg)
    m.header.stamp.sec, m.header.stamp.nanosec = divmod(int(ns), 1_000_000_000)
    return m


def _feed(graph, clouds, infos, t0: int, dt: int = 33_333_333) -> int:
    for k, (c, i) in enumerate(zip(clouds, infos)):
        graph.publish('/mocap/camera_info', _stamped(i, t0 + k * dt))
        graph.publish('/mocap/keypoints2d', _stamped(c, t0 + k * dt))
    return t0 + len(clouds) * dt


def _finite_outputs(outputs, injected=()) -> None:
    """Every motion and joint state a node published is finite (``injected``: the test's own
    bad messages, which the graph records too)."""
    from mocap_core.ros_conversions import motion_to_pose

    from mocap_core.ros_conversions import motion_to_bodies

    skip = {id(m) for m in injected}
    for topic, msg in outputs:
        if id(msg) in skip:
            continue
        if topic.endswith('/bodies/motion'):
            for _, pose in motion_to_bodies(msg):
                assert np.all(np.isfinite(pose.joint_positions())), topic
        elif topic.endswith('/motion'):
            pose = motion_to_pose(msg)
            assert np.all(np.isfinite(pose.joint_positions())), topic
        if topic.endswith('/joint_states'):
            assert np.all(np.isfinite(msg.position)) and np.all(np.isfinite(msg.effort)), topic


def _bad_clouds(good):
    """(name, message) pairs of malformed keypoint clouds."""
    from mocap_core.ros_conversions import array_to_cloud

    def with_values(values, fields=('u', 'v', 'confidence')):
        return array_to_cloud(np.asarray(values, float), fields, copy.deepcopy(good.header))

    kp = np.zeros((1, 23, 3))
    kp[..., :2] = 300.0
    kp[..., 2] = 1.0
    nan = kp.copy()
    nan[0, 3:9, 0] = np.nan
    inf = kp.copy()
    inf[0, :, 1] = np.inf
    huge = kp.copy()
    huge[..., :2] = 1e30
    truncated = copy.deepcopy(good)
    truncated.data = truncated.data[:len(truncated.data) // 2]
    return [
        ('wrong fields', with_values(kp, ('x', 'y', 'z'))),
        ('wrong width', with_values(np.ones((1, 10, 3)))),
        ('empty cloud', with_values(np.zeros((0, 23, 3)))),
        ('NaN keypoints', with_values(nan)),
        ('inf keypoints', with_values(inf)),
        ('huge values', with_values(huge)),
        ('truncated data', truncated),
        ('all confidences zero', with_values(np.zeros((1, 23, 3)))),
    ]


def test_lifter_survives_malformed_keypoints_and_camera_info(pipeline, valid):
    graph, nodes, outputs, errors = pipeline
    clouds, infos = valid
    t = _feed(graph, clouds[:30], infos[:30], 1_700_000_000_000_000_000)
    errors_before = nodes['lifter'].diag.errors + nodes['lifter'].diag.dropped
    for _name, bad in _bad_clouds(clouds[0]):
        t += 33_333_333
        graph.publish('/mocap/keypoints2d', _stamped(bad, t))
    bad_info = copy.deepcopy(infos[0])
    bad_info.k = [0.0] * 9                                   # an uncalibrated camera
    graph.publish('/mocap/camera_info', bad_info)
    nan_info = copy.deepcopy(infos[0])
    nan_info.k = [float('nan')] * 9
    graph.publish('/mocap/camera_info', nan_info)
    # stamps backwards and a duplicate are dropped; a 2 s gap and 100 Hz stamps go through
    graph.publish('/mocap/keypoints2d', _stamped(clouds[0], t - 100_000_000))
    graph.publish('/mocap/keypoints2d', _stamped(clouds[0], t))
    t = _feed(graph, clouds[30:45], infos[30:45], t + 2_000_000_000)
    t = _feed(graph, clouds[45:60], infos[45:60], t + 10_000_000, dt=10_000_000)
    graph.flush()
    assert errors == []
    lifter = nodes['lifter']
    assert lifter.diag.errors + lifter.diag.dropped - errors_before >= 6
    _finite_outputs(outputs)
    # the valid frames after the bad ones were all lifted, physics and GMR followed
    stamps = {t for topic, m in outputs if topic == '/mocap/world/motion'
              for t in [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec]}
    assert len(stamps) >= 55


def _as_bodies(msg, person_id: int = 1):
    """A copy of a one-person motion or contacts message as the several-people input: every
    name prefixed ``body_<id>/`` (a malformed message stays malformed)."""
    m = copy.deepcopy(msg)
    names = m.joint_names if hasattr(m, 'joint_names') else m.name
    names[:] = [f'body_{person_id}/{n}' for n in names]
    return m


def _bad_motions(good):
    from mocap_core.skeleton import JOINT_NAMES

    def edit(fn):
        m = copy.deepcopy(good)
        fn(m)
        return m

    def nan_quat(m):
        m.points[0].transforms[3].rotation.x = float('nan')

    def zero_quat(m):
        r = m.points[0].transforms[5].rotation
        r.x = r.y = r.z = r.w = 0.0

    def huge_root(m):
        m.points[0].transforms[0].translation.z = 1e12

    def fewer_joints(m):
        m.joint_names = m.joint_names[:10]
        m.points[0].transforms = m.points[0].transforms[:10]

    def size_mismatch(m):
        m.points[0].transforms = m.points[0].transforms[:-1]

    def no_points(m):
        m.points = []

    def renamed(m):
        m.joint_names = ['hip_' + n for n in JOINT_NAMES]

    def zero_bones(m):
        for tr in m.points[0].transforms[1:]:
            tr.translation.x = tr.translation.y = tr.translation.z = 0.0

    return [('NaN quaternion', edit(nan_quat)), ('zero quaternion', edit(zero_quat)),
            ('huge root', edit(huge_root)), ('10 joints', edit(fewer_joints)),
            ('size mismatch', edit(size_mismatch)), ('no point', edit(no_points)),
            ('unknown joints', edit(renamed)), ('zero-length bones', edit(zero_bones))]


def _bad_contacts(good):
    def edit(fn):
        m = copy.deepcopy(good)
        fn(m)
        return m

    return [('wrong names', edit(lambda m: setattr(m, 'name', ['a', 'b', 'c', 'd']))),
            ('NaN', edit(lambda m: setattr(m, 'position', [float('nan')] * 4))),
            ('too few', edit(lambda m: setattr(m, 'position', [0.5]))),
            ('negative', edit(lambda m: setattr(m, 'position', [-3.0] * 4)))]


@pytest.mark.parametrize('target', ['physics', 'gmr'])
def test_physics_and_gmr_survive_malformed_motion_and_contacts(pipeline, valid, target):
    graph, nodes, outputs, errors = pipeline
    clouds, infos = valid
    t = _feed(graph, clouds[:40], infos[:40], 1_700_000_000_000_000_000)
    motion = next(m for topic, m in outputs if topic == '/mocap/lifter/motion')
    contacts = next(m for topic, m in outputs if topic == '/mocap/lifter/contacts')
    # the node follows every person from the combined input (names prefixed body_<id>/)
    topic = ('/mocap/lifter/bodies/motion' if target == 'physics'
             else '/mocap/physics/bodies/motion')
    if target == 'gmr':
        motion = next(m for tp, m in outputs if tp == '/mocap/physics/motion')
    node = nodes[target]
    before = node.diag.errors + node.diag.dropped
    # bad messages straight to the node, with stamps after the valid stream
    cases = _bad_motions(motion)
    injected = []
    for k, (_name, bad) in enumerate(cases):
        injected.append(_stamped(_as_bodies(bad), t + k))
        graph.publish(topic, injected[-1])
        # both stages read the lifter's contacts (the world stage for its foot planting)
        injected.append(_stamped(_as_bodies(_bad_contacts(contacts)[k % 4][1]), t + k))
        graph.publish('/mocap/lifter/bodies/contacts', injected[-1])
        if target == 'gmr':
            injected.append(_stamped(_bad_contacts(contacts)[k % 4][1], t + k))
            graph.publish('/mocap/lifter/contacts', injected[-1])
    injected.append(_stamped(_as_bodies(motion), t - 500_000_000))    # backwards, dropped
    graph.publish(topic, injected[-1])
    unprefixed = _stamped(motion, t + len(cases))                     # no body_<id>/ prefix
    injected.append(unprefixed)
    graph.publish(topic, unprefixed)
    n_world = sum(1 for tp, _ in outputs if tp == '/mocap/world/motion')
    _feed(graph, clouds[40:60], infos[40:60], t + 1_000_000_000)  # valid again, after a gap
    graph.flush()
    assert errors == []
    assert node.diag.errors + node.diag.dropped - before >= 6, node.diag.status()
    _finite_outputs(outputs, injected)
    assert sum(1 for tp, _ in outputs if tp == '/mocap/world/motion') >= n_world + 20
