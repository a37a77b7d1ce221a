"""``ros2 run mocap_lifter lifter`` fed by ``ros2 bag play`` of a committed validation bag, and
the shipped weights against a trivial baseline on the same bag."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / 'bags' / 'gt_cmu_walk_12_02'
WEIGHTS_DIR = ROOT / 'src' / 'mocap_lifter' / 'weights'
OUTPUTS = ('motion', 'joints3d', 'joint_states', 'contacts', 'markers')


def _bag_arrays():
    """Keypoints, intrinsics, ground-truth joints (camera frame) and stamps from the bag."""
    from mocap_core.bag_io import BagReader, deserialize
    from mocap_core.ros_conversions import (camera_info_to_intrinsics, cloud_to_keypoints,
                                            cloud_to_positions, stamp_to_ns)
    kp, gt, stamps, intr = [], [], [], None
    with BagReader(BAG) as bag:
        for m in bag.messages(topics=['/mocap/keypoints2d', '/mocap/camera_info',
                                      '/mocap/groundtruth/joints3d']):
            msg = deserialize(m.data, m.msgtype)
            if m.topic == '/mocap/keypoints2d':
                kp.append(cloud_to_keypoints(msg)[0])
                stamps.append(stamp_to_ns(msg.header.stamp))
            elif m.topic == '/mocap/camera_info':
                intr = camera_info_to_intrinsics(msg)
            else:
                gt.append(cloud_to_positions(msg))
    return np.stack(kp), intr, np.stack(gt), stamps


@pytest.mark.parametrize('weights', ['motionet_windowed.pt', 'vtm_windowed.pt'])
def test_shipped_weights_beat_mean_pose_baseline(weights):
    import torch

    from mocap_lifter.features import lifter_features
    from mocap_lifter.training.metrics import mpjpe_mm, pa_mpjpe_mm
    from mocap_lifter.weights import load_weights

    kp, intr, gt, _ = _bag_arrays()
    model = load_weights(WEIGHTS_DIR / weights)
    feats, root, scale, _ = lifter_features(kp, intr)
    with torch.no_grad():
        out = model(torch.as_tensor(feats[None]), torch.as_tensor(root[None]).float(),
                    torch.as_tensor(scale[None]).float())
    pred = out['positions'][0].double().numpy()
    rel = gt - gt[:, :1]
    baseline = np.broadcast_to(rel.mean(axis=0), rel.shape)  # this clip's own mean pose
    model_err, base_err = mpjpe_mm(pred, gt), mpjpe_mm(baseline, rel)
    print(f'{weights}: MPJPE model {model_err:.1f} mm, mean-pose baseline {base_err:.1f} mm, '
          f'PA-MPJPE {pa_mpjpe_mm(pred, gt):.1f} mm')
    assert model_err < 0.7 * base_err
    depth_err = np.abs(out['root'][0, :, 2].numpy() - gt[:, 0, 2]) / gt[:, 0, 2]
    assert np.median(depth_err) < 0.25


@pytest.fixture
def listener(peer):
    """The test's rclpy peer subscribed to every lifter output, the URDF and /diagnostics."""
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState, PointCloud2
    from std_msgs.msg import String
    from trajectory_msgs.msg import MultiDOFJointTrajectory
    from visualization_msgs.msg import MarkerArray

    from mocap_core.qos import LATCHED_QOS

    types = {'motion': MultiDOFJointTrajectory, 'joints3d': PointCloud2,
             'joint_states': JointState, 'contacts': JointState, 'markers': MarkerArray}
    got = {name: peer.subscribe(cls, f'/mocap/lifter/{name}') for name, cls in types.items()}
    got['urdf'] = peer.subscribe(String, '/mocap/skeleton/urdf', LATCHED_QOS)
    got['diagnostics'] = peer.subscribe(DiagnosticArray, '/diagnostics', 10)
    return peer, got


@pytest.mark.parametrize('model', ['motionet', 'vtm'])
def test_node_lifts_a_played_bag(processes, ros2_cmd, listener, model):
    """Every lifter topic, one message per keypoint frame with its stamp, no NaN; the
    ``model`` parameter selects the network and /diagnostics says which."""
    from mocap_core.ros_conversions import (cloud_to_positions, motion_to_pose, msg_to_contacts,
                                            stamp_to_ns)

    peer, got = listener
    _, _, _, stamps = _bag_arrays()
    # a deep input queue: every frame even when a loaded machine slows the node below the
    # bag's rate (the live default, 30, favours latency)
    node, log = processes.start(ros2_cmd + ['run', 'mocap_lifter', 'lifter', '--ros-args',
                                            '-p', 'mode:=windowed', '-p', f'model:={model}',
                                            '-p', 'queue_depth:=1000'], f'lifter_{model}')
    processes.wait_for_text(log, f'lifter ready: {model}', 90, node)
    # no fixed delays: every subscription of the test has matched the node's publisher, and the
    # player waits until the node's inputs have matched before its first message
    assert peer.wait_for_publishers(timeout=60, proc=node), \
        (peer.unmatched_subscriptions(), log.read_text())
    player, plog = processes.start(ros2_cmd + ['bag', 'play', str(BAG), '--wait-for-subscribers',
                                               '--wait-timeout', '60', '--topics',
                                               '/mocap/camera_info', '/mocap/keypoints2d'],
                                   'play')
    peer.spin(120, until=lambda: player.poll() is not None)
    assert player.returncode == 0, plog.read_text()
    # a node slowed down by a loaded machine may still be working through its input queue
    peer.spin(120, until=lambda: all(len(got[k]) >= len(stamps) for k in OUTPUTS))
    text = log.read_text()
    assert 'Traceback' not in text, text
    for name in OUTPUTS:
        assert len(got[name]) == len(stamps), (name, len(got[name]), text[-2000:])
        assert [stamp_to_ns(m.header.stamp) if hasattr(m, 'header') else
                stamp_to_ns(m.markers[0].header.stamp) for m in got[name]] == stamps, name
    assert got['urdf'] and '<robot' in got['urdf'][-1].data
    for m in got['joints3d']:
        assert np.all(np.isfinite(cloud_to_positions(m, 18)))
    pose = motion_to_pose(got['motion'][-1])
    assert pose.skeleton.is_symmetric(atol=1e-6)
    assert np.all((msg_to_contacts(got['contacts'][0]) >= 0) &
                  (msg_to_contacts(got['contacts'][0]) <= 1))
    peer.spin(3, until=lambda: any(s.name.startswith('lifter') for d in got['diagnostics']
                                         for s in d.status))
    values = {kv.key: kv.value for d in got['diagnostics'] for s in d.status
              if s.name.startswith('lifter') for kv in s.values}
    assert values.get('model') == f'{model} (windowed)', values


def test_node_refuses_causal_vtm(processes, ros2_cmd):
    """VTM is windowed only: asking for it causal is a clear error at start-up."""
    node, log = processes.start(ros2_cmd + ['run', 'mocap_lifter', 'lifter', '--ros-args',
                                            '-p', 'mode:=causal', '-p', 'model:=vtm'],
                                'lifter_vtm_causal')
    node.wait(timeout=90)
    text = log.read_text()
    assert node.returncode != 0
    assert 'VTM is windowed only' in text, text


def test_node_survives_bad_input(processes, ros2_cmd, listener):
    from sensor_msgs.msg import PointCloud2

    from mocap_core.qos import SENSOR_QOS
    from mocap_core.ros_conversions import array_to_cloud, keypoints_to_cloud, make_header

    peer, got = listener
    kp, intr, _, _ = _bag_arrays()
    pub = peer.publisher(PointCloud2, '/mocap/keypoints2d', SENSOR_QOS)
    proc, log = processes.start(ros2_cmd + ['run', 'mocap_lifter', 'lifter', '--ros-args',
                                            '-p', 'mode:=windowed'], 'lifter_bad')
    processes.wait_for_text(log, 'lifter ready', 90, proc)
    assert peer.wait_for_subscribers([pub], timeout=60, proc=proc) and \
        peer.wait_for_publishers(timeout=60, proc=proc), log.read_text()
    t0 = 1_000_000_000

    def publish_until(make, text: str, timeout: float = 20.0) -> None:
        """Publish (best effort, as the keypoint node does) until the node logs ``text``:
        under load the first samples after discovery can be lost."""
        deadline, k = time.monotonic() + timeout, 0
        while time.monotonic() < deadline:
            pub.publish(make(k))
            k += 1
            peer.spin(0.3)
            if text in log.read_text():
                return
        raise AssertionError(f'{text!r} never logged:\n{log.read_text()}')

    publish_until(lambda k: array_to_cloud(np.zeros((1, 17, 3)), ('u', 'v', 'confidence'),
                                           make_header(t0 + k, 'c')), 'dropping keypoints')

    def nobody(k):  # nobody seen, before any person: dropped and said so
        return keypoints_to_cloud(np.zeros((1, 23, 3)), make_header(t0 + 100 + k, 'c'))

    publish_until(nobody, 'nobody seen')
    nan = keypoints_to_cloud(kp[0], make_header(t0 + 1000, 'c'))
    values = np.frombuffer(bytes(nan.data), np.float32).copy()
    values[0] = np.nan                      # the nose's u
    nan.data = values.tobytes()
    pub.publish(nan)
    peer.spin(0.1)
    # valid frames without camera_info (approximate intrinsics), then one going backwards
    for i in range(10):
        pub.publish(keypoints_to_cloud(kp[i], make_header(t0 + 100_000_000 * (i + 1), 'c')))
        peer.spin(0.05)
    pub.publish(keypoints_to_cloud(kp[0], make_header(t0 + 5, 'c')))
    peer.spin(5, until=lambda: len(got['motion']) >= 11)
    text = log.read_text()
    assert proc.poll() is None, text            # still running
    assert 'Traceback' not in text
    assert 'dropping keypoints' in text and 'width' in text
    assert 'nobody seen' in text and 'no camera_info' in text
    assert 'did not advance' in text
    assert len(got['motion']) >= 8            # best effort: a sample may be lost under load
    from mocap_core.ros_conversions import cloud_to_positions
    assert all(np.all(np.isfinite(cloud_to_positions(m, 18))) for m in got['joints3d'])
