"""``ros2 run mocap_physics physics`` in its own process, fed and observed from this process."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture
def graph(peer):
    """The test's rclpy peer: publishes lifter motion and contacts, collects physics output."""
    from geometry_msgs.msg import WrenchStamped
    from sensor_msgs.msg import JointState
    from trajectory_msgs.msg import MultiDOFJointTrajectory

    got = {'motion': peer.subscribe(MultiDOFJointTrajectory, '/mocap/physics/motion'),
           'left': peer.subscribe(WrenchStamped, '/mocap/physics/grf/left'),
           'right': peer.subscribe(WrenchStamped, '/mocap/physics/grf/right'),
           'states': peer.subscribe(JointState, '/mocap/physics/joint_states')}
    pubs = {'motion': peer.publisher(MultiDOFJointTrajectory, '/mocap/lifter/motion'),
            'contacts': peer.publisher(JointState, '/mocap/lifter/contacts')}
    return peer, pubs, got


def test_physics_node_standing(processes, ros2_cmd, graph):
    from mocap_core.pose import Pose
    from mocap_core.ros_conversions import (contacts_to_msg, make_header, motion_to_pose,
                                            msg_to_wrench, pose_to_motion, stamp_to_ns)
    from mocap_core.skeleton import Skeleton

    peer, pubs, got = graph
    proc, log = processes.start(ros2_cmd + ['run', 'mocap_physics', 'physics', '--ros-args',
                                            '-p', 'body_mass:=80.0',
                                            '-p', 'floor_source:=input'], 'physics')
    # the node's inputs have matched the test's publishers, and the test's subscriptions every
    # node output: nothing sent from now on is lost
    ready = peer.wait_for_subscribers(pubs.values(), timeout=60, proc=proc) and \
        peer.wait_for_publishers(timeout=60, proc=proc)
    assert ready, (peer.unmatched_subscriptions(), log.read_text())
    sk = Skeleton.default()
    rest = Pose.rest(sk)
    t0 = 1_000_000_000
    n = 30
    for i in range(n):
        header = make_header(t0 + i * 33_333_333, 'world')
        pubs['contacts'].publish(contacts_to_msg([1, 1, 1, 1], header))
        if i == 10:  # a malformed frame is dropped, not a crash
            bad = pose_to_motion(rest, header)
            bad.points = []
            pubs['motion'].publish(bad)
            continue
        pubs['motion'].publish(pose_to_motion(rest, header))
        peer.spin(1 / 30, step=0.005)     # a live lifter publishes at the frame rate
    ok = peer.spin(30, until=lambda: all(len(v) >= n - 1 for v in got.values()))
    assert ok, (len(got["motion"]), len(got["right"]), len(got["states"]), log.read_text())
    assert len(got['motion']) == n - 1 and len(got['states']) == n - 1
    stamps = [stamp_to_ns(m.header.stamp) for m in got['motion']]
    assert stamps == [t0 + i * 33_333_333 for i in range(n) if i != 10]
    assert got['motion'][-1].header.frame_id == 'world'
    weight = 80.0 * 9.81
    fz = [msg_to_wrench(lw)[0][2] + msg_to_wrench(rw)[0][2]
          for lw, rw in zip(got['left'][1:], got['right'][1:])]
    np.testing.assert_allclose(fz, weight, rtol=0.03)
    out = motion_to_pose(got['motion'][-1])
    np.testing.assert_allclose(out.joint_positions(), rest.joint_positions(), atol=5e-3)
    assert len(got['states'][-1].effort) == 3 * (sk.num_joints - 1)
    assert np.all(np.isfinite(got['states'][-1].effort))
    proc.send_signal(2)
    proc.wait(timeout=20)
    assert proc.returncode == 0, log.read_text()
    assert 'dropping a motion message' in log.read_text()
