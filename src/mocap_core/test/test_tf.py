"""The TF tree of a body (mocap_core.tf): chaining the frames from the root gives the pose's
joint positions and orientations (forward kinematics), with REP-155 frame names."""

import numpy as np

from mocap_core.pose import Pose
from mocap_core.ros_conversions import make_header
from mocap_core.rotations import quat_normalize, quat_to_matrix
from mocap_core.skeleton import NUM_JOINTS, Skeleton
from mocap_core.tf import joint_frame, pose_to_transforms


def _matrix(t):
    q = t.transform.rotation
    p = t.transform.translation
    m = np.eye(4)
    m[:3, :3] = quat_to_matrix(np.array([q.x, q.y, q.z, q.w]))
    m[:3, 3] = [p.x, p.y, p.z]
    return m


def test_tf_frames_compose_to_forward_kinematics():
    rng = np.random.default_rng(2)
    pose = Pose(Skeleton.from_group_lengths(rng.uniform(0.1, 0.4, 10)),
                quat_normalize(rng.normal(size=(NUM_JOINTS, 4))), rng.normal(size=3))
    tfs = pose_to_transforms(pose, make_header(123, 'world'), 7)
    assert len(tfs) == NUM_JOINTS
    assert (tfs[0].header.frame_id, tfs[0].child_frame_id) == ('world', 'body_7')
    names = list(pose.joint_names)
    assert tfs[names.index('left_knee')].child_frame_id == 'body_7/left_knee'
    assert tfs[names.index('left_knee')].header.frame_id == 'body_7/left_hip'
    assert tfs[names.index('left_hip')].header.frame_id == 'body_7'
    assert all(t.header.stamp.nanosec == 123 for t in tfs)
    # chain every frame up to `world`
    by_child = {t.child_frame_id: t for t in tfs}
    positions = pose.joint_positions()
    orientations = pose.global_rotations()
    for j, name in enumerate(names):
        frame, m = joint_frame(7, name), np.eye(4)
        while frame != 'world':
            t = by_child[frame]
            m = _matrix(t) @ m
            frame = t.header.frame_id
        np.testing.assert_allclose(m[:3, 3], positions[j], atol=1e-9)
        np.testing.assert_allclose(m[:3, :3], orientations[j], atol=1e-9)
