import numpy as np
import pytest

from mocap_core.data.bvh import read_bvh, bvh_fk
from mocap_core.data.bvh_writer import write_bvh
from mocap_core.kinematics import forward_kinematics
from mocap_core.rotations import quat_normalize
from mocap_core.skeleton import JOINT_NAMES, NUM_JOINTS, Skeleton


@pytest.mark.parametrize('frame', ['world', 'camera'])
def test_written_bvh_reproduces_joint_positions(tmp_path, frame):
    rng = np.random.default_rng(0)
    sk = Skeleton.from_group_lengths(rng.uniform(0.08, 0.45, 10))
    rot = quat_normalize(rng.normal(size=(7, NUM_JOINTS, 4)))
    root = rng.normal(size=(7, 3))
    path = write_bvh(tmp_path / 'm.bvh', sk, rot, root, fps=30.0, frame=frame)
    bvh = read_bvh(path)
    assert list(bvh.joint_names[:NUM_JOINTS]) == list(JOINT_NAMES)
    assert bvh.frame_time == pytest.approx(1 / 30.0)
    got = bvh_fk(bvh, unit_scale=0.01).positions          # pipeline world frame, metres
    want = forward_kinematics(sk.parents, sk.offsets, rot, root).positions
    if frame == 'camera':   # the reader's world frame = the writer's frame seen from BVH
        from mocap_core.data.bvh import BVH_TO_WORLD
        from mocap_core.data.bvh_writer import FRAME_TO_BVH
        want = want @ (np.asarray(BVH_TO_WORLD) @ FRAME_TO_BVH['camera']).T
    np.testing.assert_allclose(got[:, :NUM_JOINTS], want, atol=1e-5)


def test_bad_arguments():
    sk = Skeleton.default()
    with pytest.raises(ValueError):
        write_bvh('/tmp/x.bvh', sk, np.zeros((2, 5, 4)), np.zeros((2, 3)), 30.0)
    with pytest.raises(ValueError):
        write_bvh('/tmp/x.bvh', sk, np.zeros((2, NUM_JOINTS, 4)), np.zeros((2, 3)), 30.0,
                  frame='image')
