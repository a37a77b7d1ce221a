"""The lifter node built in this process (private rclpy Context, messages delivered through
InProcessGraph): a stream without camera_info where the person leaves the picture; bad
weight files at start; what starting the node imports."""

from __future__ import annotations

import copy
import json
import os
import random
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mocap_core.testing import CreatesFile

ROOT = Path(__file__).resolve().parents[3]
BAG = ROOT / 'bags' / 'gt_cmu_walk_12_02'
SHIPPED = ROOT / 'src' / 'mocap_lifter' / 'weights' / 'motionet_windowed.pt'
DT = 33_333_333
T0 = 1_700_000_000_000_000_000


@pytest.fixture(scope='module')
def clouds():
    """The bag's first 20 keypoint clouds (one person) and its first camera_info."""
    from mocap_core import topics
    from mocap_core.bag_io import BagReader, deserialize

    kp, info = [], None
    with BagReader(BAG) as reader:
        for m in reader.messages(topics=[topics.KEYPOINTS, topics.CAMERA_INFO]):
            if m.topic == topics.KEYPOINTS and len(kp) < 20:
                kp.append(deserialize(m.data, m.msgtype))
            elif m.topic == topics.CAMERA_INFO and info is None:
                info = deserialize(m.data, m.msgtype)
            if len(kp) == 20 and info is not None:
                break
    return kp, info


@pytest.fixture
def lifter():
    """A LifterNode in an InProcessGraph; yields (graph, node, recorded (topic, msg))."""
    import rclpy

    from mocap_core.inprocess import InProcessGraph
    from mocap_lifter.node import LifterNode

    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    recorded = []
    graph = InProcessGraph(record=lambda topic, msg, qos: recorded.append((topic, msg)))
    node = graph.add(LifterNode(context=context))
    yield graph, node, recorded
    node.destroy_node()
    context.try_shutdown()


def _stamped(msg, k: int):
    m = copy.deepcopy(msg)
    m.header.stamp.sec, m.header.stamp.nanosec = divmod(T0 + k * DT, 1_000_000_000)
    return m


def _empty_cloud(like):
    from mocap_core.ros_conversions import array_to_cloud
    return array_to_cloud(np.zeros((1, 23, 3)), ('u', 'v', 'confidence'),
                          copy.deepcopy(like.header))


def _values(node) -> dict:
    return {kv.key: kv.value for kv in node.diag.status().values}


def test_frames_missing_from_the_stream_are_filled_and_not_published(lifter, clouds):
    """Every second keypoint frame of a 30 fps stream (a busy keypoint node): the node lifts
    the gaps filled (network_rate_hz 30, the default) and publishes exactly the frames it
    received; diagnostics count the filled ones."""
    from mocap_core import topics

    graph, node, recorded = lifter
    kp, _ = clouds
    for k in range(0, 20, 2):
        graph.publish(topics.KEYPOINTS, _stamped(kp[k], k))
    graph.flush()
    node.flush()
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
              for topic, m in recorded if topic == topics.LIFTER_MOTION]
    assert stamps == [T0 + k * DT for k in range(0, 20, 2)]
    values = _values(node)
    assert values['filled_frames'] == '9' and values['thinned_frames'] == '0'


def test_person_leaving_without_camera_info_keeps_frames_flowing(lifter, clouds, capfd):
    """Regression: 20 frames with a person, then 40 with every confidence 0, and no
    camera_info. The node used to reset at every frame (intrinsics from each frame's extent)
    and to fail on the first empty frame ('zero-size array to reduction operation maximum
    which has no identity'). Frames keep flowing while the person is away, until they have
    been away for person_timeout_s (1 s = 30 frames): then they are gone, their last frames
    are emitted and nothing more is published for them."""
    from mocap_core import topics

    graph, node, recorded = lifter
    kp, _ = clouds
    for k in range(60):
        msg = kp[k] if k < 20 else _empty_cloud(kp[0])
        graph.publish(topics.KEYPOINTS, _stamped(msg, k))
    graph.flush()
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
              for topic, m in recorded if topic == topics.LIFTER_MOTION]
    # last seen at frame 19; frame 50 is the first more than 1 s later
    assert stamps == [T0 + k * DT for k in range(50)]
    values = _values(node)
    assert values['persons'] == '0' and values['person_ids'] == 'none'
    assert values['inference'].startswith('streaming'), values    # live defaults
    # windowed defaults: output smoothing sigma 1.5 (rotations) and 3 (root), the root's 6
    # frames on top of the look-ahead
    assert values['output_smoothing'] == 'sigma 1.5 frames (rotations), 3 (root)', values
    assert values['latency_frames'] == str(14 + 6), values
    # the main person's stature from the published skeleton
    size = values['body_size']
    assert size.startswith('estimated from the keypoints: stature ') and size.endswith(' m')
    assert 1.3 < float(size.split()[-2]) < 2.2, size
    assert values['errors'] == '0' and values['frames_dropped'] == '0'
    assert 'last_error' not in values
    assert values['intrinsics'].startswith('approximate ') and \
        values['intrinsics'].endswith('(from keypoints)')
    assert capfd.readouterr().err.count('buffer and skeleton reset') <= 1


def test_uncalibrated_camera_info_gives_the_image_size(lifter, clouds):
    """A camera_info with K all zero (uncalibrated) still fixes the image size: frames are
    lifted at once, with approximate intrinsics of that size, and it is no error."""
    from mocap_core import topics

    graph, node, recorded = lifter
    kp, info = clouds
    uncalibrated = copy.deepcopy(info)
    uncalibrated.k = [0.0] * 9
    graph.publish(topics.CAMERA_INFO, uncalibrated)
    graph.publish(topics.KEYPOINTS, _stamped(kp[0], 0))
    assert node.people.streams[1].lifter.frames_seen == 1   # in the network's buffer
    graph.flush()
    assert sum(1 for topic, _ in recorded if topic == topics.LIFTER_MOTION) == 1
    values = _values(node)
    assert values['errors'] == '0'
    assert values['intrinsics'] == (f'approximate {info.width}x{info.height}, fov 60 deg '
                                    '(from the camera_info image size)')
    graph.publish(topics.CAMERA_INFO, info)
    assert _values(node)['intrinsics'] == 'camera_info'


def _ros_env() -> dict:
    env = dict(os.environ)
    env.update(ROS_DOMAIN_ID=str(random.SystemRandom().randint(1, 200)),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', PYTHONUNBUFFERED='1')
    env.pop('ROS_LOCALHOST_ONLY', None)
    return env


def _bad_weights(kind: str, tmp_path: Path) -> Path:
    import torch

    path = tmp_path / f'{kind}.pt'
    if kind == 'truncated':
        data = SHIPPED.read_bytes()
        path.write_bytes(data[:len(data) // 2])
    elif kind == 'random bytes':
        path.write_bytes(np.random.default_rng(0).bytes(4096))
    else:
        torch.save({'model': CreatesFile(tmp_path / 'created'), 'config': {}}, path)
    return path


@pytest.mark.parametrize('kind', ['truncated', 'random bytes', 'crafted pickle'])
def test_bad_weights_end_the_start_with_one_line(kind, tmp_path):
    """`ros2 run mocap_lifter lifter -p weights:=bad.pt` and `mocap eval lifter --weights
    bad.pt`: exit status 2, one line `... error: ...` on stderr, no traceback; a crafted
    pickle is never executed."""
    bad = _bad_weights(kind, tmp_path)
    commands = {
        'lifter': [sys.executable, '-m', 'mocap_core.cli.ros2', 'run', 'mocap_lifter', 'lifter',
                   '--ros-args', '-p', f'weights:={bad}'],
        'mocap eval lifter': [sys.executable, '-m', 'mocap_lifter.training.cli', 'eval',
                              'lifter', '--weights', str(bad)],
    }
    for name, cmd in commands.items():
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=_ros_env(),
                             cwd=tmp_path)
        lines = out.stderr.strip().splitlines()
        assert out.returncode == 2, out.stderr
        assert len(lines) == 1 and lines[0].startswith(f'{name}: error: '), out.stderr
        assert str(bad) in lines[0]
        assert not (tmp_path / 'created').exists()


def test_load_weights_raises_weights_error_for_wrong_contents(tmp_path):
    """Plain data that is not lifter weights: a one-line WeightsError, not a KeyError or a
    TypeError from deep inside."""
    import torch

    from mocap_core.checkpoint import WeightsError
    from mocap_lifter.weights import load_weights

    cases = {'no config': {'model': {}},
             'unknown field': {'model': {}, 'config': {'channels': 8, 'wings': 2}},
             'wrong tensors': {'model': {'e_q.shrink.weight': torch.zeros(3)},
                               'config': {'channels': 16, 'fusion_blocks': 1}},
             'unknown arch': {'arch': 'resnet', 'model': {}, 'config': {}}}
    for name, state in cases.items():
        path = tmp_path / f'{name}.pt'
        torch.save(state, path)
        with pytest.raises(WeightsError) as info:
            load_weights(path)
        assert str(path) in str(info.value) and '\n' not in str(info.value), name


START = '''
import json, sys
import rclpy, torch
before = set(sys.modules)
import mocap_lifter.node
context = rclpy.Context()
rclpy.init(args=[], context=context)
node = mocap_lifter.node.LifterNode(context=context)
print(json.dumps([sorted(before), sorted(sys.modules)]))
node.destroy_node()
context.try_shutdown()
'''

#: Modules of training, evaluation and dataset building, never needed by a running node.
TRAINING = ('mocap_lifter.training', 'mocap_core.data.dataset', 'mocap_core.data.splits',
            'mocap_core.data.retarget', 'mocap_core.data.synth2d', 'mocap_core.data.bvh')
#: Libraries of training only (torch itself imports tqdm when it is installed: checked
#: against what ``import torch`` alone loads).
TRAINING_LIBRARIES = ('tqdm', 'matplotlib')


def test_starting_the_node_imports_no_training_code():
    out = subprocess.run([sys.executable, '-c', START], capture_output=True, text=True,
                         timeout=120, env=_ros_env())
    assert out.returncode == 0, out.stderr
    before, loaded = json.loads(out.stdout.strip().splitlines()[-1])
    assert 'mocap_lifter.online' in loaded and 'mocap_lifter.weights' in loaded

    def matches(m: str, names) -> bool:
        return any(m == n or m.startswith(n + '.') for n in names)

    assert [m for m in loaded if matches(m, TRAINING)] == []
    assert [m for m in set(loaded) - set(before) if matches(m, TRAINING_LIBRARIES)] == []


def test_subject_height_is_reported_and_a_bad_one_refused():
    """``subject_height``: in the diagnostics when given; a value no person has stops the
    node at construction with what is allowed."""
    import rclpy
    from rclpy.parameter import Parameter

    from mocap_lifter.node import LifterNode

    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    try:
        node = LifterNode(context=context,
                          parameter_overrides=[Parameter('subject_height', value=1.62)])
        assert _values(node)['body_size'] == 'given: stature 1.62 m'
        node.destroy_node()
        with pytest.raises(ValueError, match='stature of 0.5-3 m'):
            LifterNode(context=context,
                       parameter_overrides=[Parameter('subject_height', value=0.2)])
    finally:
        context.try_shutdown()
