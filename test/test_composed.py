"""``mocap run``: the four nodes in one process, observed from outside through DDS (issue 20,
the composed live mode)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CLIP = ROOT / 'data' / 'video_example' / 'taiji_640x360.mp4'


def test_composed_run_publishes_to_outside_subscribers(processes, peer):
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import PointCloud2
    from trajectory_msgs.msg import MultiDOFJointTrajectory

    from mocap_core.ros_conversions import stamp_to_ns

    reliable = QoSProfile(depth=500, reliability=ReliabilityPolicy.RELIABLE)
    world = peer.subscribe(MultiDOFJointTrajectory, '/mocap/world/motion', reliable)
    joints = peer.subscribe(PointCloud2, '/mocap/world/joints3d', reliable)
    keypoints = peer.subscribe(PointCloud2, '/mocap/keypoints2d',
                               QoSProfile(depth=500,
                                          reliability=ReliabilityPolicy.BEST_EFFORT))
    # the keypoint node starts once it has 2 subscribers: the lifter in its own process and
    # this test
    proc, log = processes.start(
        [sys.executable, '-m', 'mocap_core.cli.mocap', 'run', '--video', str(CLIP),
         '--param', 'keypoints.realtime=false', '--param', 'keypoints.wait_for_subscribers=2',
         '--param', 'keypoints.wait_timeout_s=60.0'], 'mocap_run')
    peer.spin_until_exit(proc, timeout=180)
    text = log.read_text()
    assert proc.returncode == 0, text
    assert 'finished: 96 frames published' in text and 'Traceback' not in text, text
    kp_stamps = [stamp_to_ns(m.header.stamp) for m in keypoints]
    stamps = [stamp_to_ns(m.header.stamp) for m in world]
    # every world frame is a keypoint frame, in order; the first two frames have no id yet and
    # the last look-ahead frames leave at the end: most of the 96 reach this listener
    assert len(stamps) >= 60, (len(stamps), len(kp_stamps), text[-2000:])
    assert np.all(np.diff(stamps) > 0)
    assert set(stamps) <= set(kp_stamps) or len(kp_stamps) < 96
    assert len(joints) >= 60                     # built because this test subscribes


def test_composed_run_takes_remappings_and_node_parameters(processes, peer):
    """`-- --ros-args -r ...` remaps for every node of the process (the stages still find each
    other), and a node's parameter set with --ros-args -p NODE:NAME:=VALUE reaches it."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import PointCloud2
    from trajectory_msgs.msg import MultiDOFJointTrajectory

    reliable = QoSProfile(depth=500, reliability=ReliabilityPolicy.RELIABLE)
    world = peer.subscribe(MultiDOFJointTrajectory, '/person/world', reliable)
    lifted = peer.subscribe(MultiDOFJointTrajectory, '/person/lifted', reliable)
    peer.subscribe(PointCloud2, '/mocap/keypoints2d',
                   QoSProfile(depth=500, reliability=ReliabilityPolicy.BEST_EFFORT))
    proc, log = processes.start(
        [sys.executable, '-m', 'mocap_core.cli.mocap', 'run', '--video', str(CLIP),
         '--param', 'keypoints.realtime=false', '--param', 'keypoints.wait_for_subscribers=2',
         '--param', 'keypoints.wait_timeout_s=60.0', '--',
         '--ros-args', '-r', '/mocap/world/motion:=/person/world',
         '-r', '/mocap/lifter/motion:=/person/lifted', '-p', 'lifter:mode:=causal'],
        'mocap_run_remapped')
    peer.spin_until_exit(proc, timeout=180)
    text = log.read_text()
    assert proc.returncode == 0, text
    assert len(world) >= 60 and len(lifted) >= 60, (len(world), len(lifted), text[-2000:])
    assert '(causal' in text                     # the lifter's start line names its mode


def test_composed_run_records_the_topics_asked_for(tmp_path, processes):
    """`mocap run --record OUT --topics ...`: the messages published in the process are written
    to an MCAP bag, nothing lost (no DDS in between), only the topics asked for; a second run
    onto the same bag needs --overwrite."""
    from mocap_core.bag_io import BagReader, deserialize
    from mocap_core.ros_conversions import stamp_to_ns

    out = tmp_path / 'live_bag'
    cmd = [sys.executable, '-m', 'mocap_core.cli.mocap', 'run', '--video', str(CLIP),
           '--param', 'keypoints.realtime=false', '--record', str(out),
           '--topics', '/mocap/keypoints2d', '/mocap/world/*']
    proc, log = processes.start(cmd, 'mocap_run_record')
    proc.wait(timeout=300)
    text = log.read_text()
    assert proc.returncode == 0, text
    stamps = {}
    with BagReader(out) as reader:
        topics = set(reader.topics)
        assert all(t == '/mocap/keypoints2d' or t.startswith('/mocap/world/') for t in topics)
        for m in reader.messages(topics=['/mocap/keypoints2d', '/mocap/world/motion']):
            msg = deserialize(m.data, m.msgtype)
            assert m.timestamp_ns == stamp_to_ns(msg.header.stamp)   # stamped by the header
            stamps.setdefault(m.topic, []).append(m.timestamp_ns)
    kp, world = stamps['/mocap/keypoints2d'], stamps.get('/mocap/world/motion', [])
    assert len(kp) == 96 and all(b > a for a, b in zip(kp, kp[1:]))   # every frame, in order
    # every keypoint frame but the first two (no person id yet) reaches the world output
    assert len(world) == 94 and set(world) == set(kp[2:]), (len(world), text[-2000:])
    assert '/mocap/lifter/motion' not in topics and '/mocap/world/joints3d' in topics
    proc, log = processes.start(cmd, 'mocap_run_record_again')
    proc.wait(timeout=120)
    assert proc.returncode == 2 and 'exists' in log.read_text(), log.read_text()
