"""The physics node on a committed ground-truth bag played with ``ros2 bag play``.

``bags/gt_cmu_walk_12_02`` (168 frames of walking, camera optical frame) is played with its
``/mocap/groundtruth/motion`` and ``/contacts`` remapped to the node's inputs; the node
estimates the floor from the feet (``floor_source: estimate``, the default). Every frame must
come out, finite, with plausible ground reaction forces inside the friction cone, friction
cones among the markers, and a floor transform close to the bag's true camera pose.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

BAG = Path(__file__).resolve().parents[1] / 'bags' / 'gt_cmu_walk_12_02'
MU = 0.8


@pytest.fixture
def graph(peer):
    """The test's rclpy peer collecting every physics output in deep reliable queues (the
    test must see every frame even when this process is slow)."""
    from geometry_msgs.msg import TransformStamped, WrenchStamped
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import MultiDOFJointTrajectory
    from visualization_msgs.msg import MarkerArray

    deep = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                      reliability=ReliabilityPolicy.RELIABLE)
    got = {key: peer.subscribe(typ, topic, deep) for key, typ, topic in (
        ('motion', MultiDOFJointTrajectory, '/mocap/physics/motion'),
        ('left', WrenchStamped, '/mocap/physics/grf/left'),
        ('right', WrenchStamped, '/mocap/physics/grf/right'),
        ('states', JointState, '/mocap/physics/joint_states'),
        ('markers', MarkerArray, '/mocap/physics/markers'),
        ('floor', TransformStamped, '/mocap/physics/floor'))}
    return peer, got


def test_physics_node_on_groundtruth_bag(processes, ros2_cmd, graph):
    from mocap_core.ros_conversions import (motion_to_pose, msg_to_wrench, stamp_to_ns)
    from mocap_core.rotations import quat_to_matrix
    from mocap_physics.training.evaluate import load_gt_bag
    from mocap_physics.markers import CONE_NS
    from sensor_msgs.msg import JointState

    clip = load_gt_bag(BAG)
    n = clip.num_frames
    peer, got = graph
    # every frame with its contacts even when a loaded machine slows the node below the bag's
    # rate: deep queues (the node's input, the player's publishers: --qos-depth below) and a
    # long wait for the contacts of a frame (the live defaults favour latency: 100, 0.05 s).
    # A contacts publisher stays up, as a live lifter would: once the player has sent all and
    # exited, a node still working through its queue would otherwise expect no more contacts
    # and give its frames the previous frame's
    peer.publisher(JointState, '/mocap/lifter/contacts')      # never publishes
    proc, log = processes.start(ros2_cmd + ['run', 'mocap_physics', 'physics', '--ros-args',
                                            '-p', 'queue_depth:=1000',
                                            '-p', 'contacts_wait_s:=2.0'], 'physics')
    # no fixed delays: the test's subscriptions have matched every node output, and the player
    # waits until the node's two inputs have matched before its first message
    ready = peer.wait_for_publishers(timeout=60, proc=proc)
    assert ready, (peer.unmatched_subscriptions(), log.read_text())
    player, play_log = processes.start(
        ros2_cmd + ['bag', 'play', str(BAG), '--wait-for-subscribers', '--wait-timeout', '60',
                    '--qos-depth', '1000',
                    '--topics', '/mocap/groundtruth/motion', '/mocap/groundtruth/contacts',
                    '--remap', '/mocap/groundtruth/motion:=/mocap/lifter/motion',
                    '/mocap/groundtruth/contacts:=/mocap/lifter/contacts'], 'play')
    ok = peer.spin(90, until=lambda: all(len(v) >= n for v in got.values()))
    assert ok, ({k: len(v) for k, v in got.items()}, log.read_text(), play_log.read_text())
    assert player.wait(timeout=30) == 0, play_log.read_text()
    peer.spin(0.5)   # nothing more should come

    # every frame, in order, with the bag's stamps, in the floor frame
    t0 = 1_700_000_000 * 10 ** 9
    stamps = [stamp_to_ns(m.header.stamp) for m in got['motion']]
    expected = [t0 + int(round(t * 1e9)) for t in clip.stamps]
    assert len(stamps) == n
    assert np.allclose(stamps, expected, atol=2)
    assert {m.header.frame_id for m in got['motion']} == {'floor'}
    poses = [motion_to_pose(m) for m in got['motion']]
    joints = np.array([p.joint_positions() for p in poses])
    assert np.all(np.isfinite(joints))
    assert all(np.all(np.isfinite(s.effort)) and len(s.effort) == 51 for s in got['states'])

    # no penetration of the node's own floor, beyond a mm
    lowest = np.array([min(c[2] for c in p.contact_positions().values()) for p in poses])
    assert lowest.min() > -1e-3

    # GRF: finite, inside the friction cone, plausible for walking
    weight = 70.0 * 9.81
    fz = []
    for lw, rw in zip(got['left'], got['right']):
        total = 0.0
        for msg in (lw, rw):
            f, m = msg_to_wrench(msg)
            assert np.all(np.isfinite(f)) and np.all(np.isfinite(m))
            assert f[2] >= -1e-6
            assert np.hypot(f[0], f[1]) <= MU * f[2] + 1e-6
            total += f[2]
        fz.append(total / weight)
    fz = np.array(fz)
    assert 0.8 < fz.mean() < 1.6, fz.mean()      # walking: about one body weight on average
    assert fz.max() < 4.0
    assert np.mean(fz > 0.05) > 0.9                # walking: a foot on the floor nearly always

    # friction cones among the markers whenever a force acts
    with_cones = [any(mk.ns == CONE_NS and mk.action == mk.ADD and len(mk.points) > 0
                      for mk in ma.markers) for ma in got['markers']]
    assert len(got['markers']) == n and np.mean(with_cones) > 0.9

    # the floor transform: camera -> floor frame, close to the true floor of the bag
    tf = got['floor'][-1]
    assert tf.header.frame_id == 'camera_optical_frame' and tf.child_frame_id == 'floor'
    q = tf.transform.rotation
    R = quat_to_matrix(np.array([q.x, q.y, q.z, q.w]))     # floor axes in the camera frame
    normal_cam = R[:, 2]
    true_normal_cam = clip.to_world.rotation[2]           # world z in camera axes
    angle = np.degrees(np.arccos(np.clip(normal_cam @ true_normal_cam, -1, 1)))
    assert angle < 2.0, angle
    height = np.array([tf.transform.translation.x, tf.transform.translation.y,
                       tf.transform.translation.z]) @ -normal_cam
    true_height = clip.to_world.translation[2]
    # the published floor is the blended one (floor_blend_frames 15): up to 15 frames behind
    # the latest fit, whose camera height on this 6-s clip still moves by 2-4 cm from one
    # re-fit to the next (here 58 mm off at the end, the latest fit 36 mm; docs/physics.md)
    assert abs(height - true_height) < 0.07, (height, true_height)

    proc.send_signal(2)
    proc.wait(timeout=20)
    assert proc.returncode == 0, log.read_text()
    assert 'Traceback' not in log.read_text()
