"""The ``mocap`` command: help, bag check (validation of pipeline topics), plots, skeleton."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mocap_core.bag_io import BagWriter
from mocap_core.ros_conversions import keypoints_to_cloud, make_header

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / 'data' / 'openpose_example' / 'seq1'
MOCAP = [sys.executable, '-m', 'mocap_core.cli.mocap']


def run(args, env, timeout=120):
    return subprocess.run(MOCAP + [str(a) for a in args], env=env, capture_output=True,
                          text=True, timeout=timeout)


@pytest.fixture(scope='module')
def keypoint_bag(tmp_path_factory):
    """A bag of the real OpenPose example as keypoint clouds, plus one malformed cloud."""
    from mocap_core.data.openpose import list_openpose_files, read_openpose_file

    path = tmp_path_factory.mktemp('bags') / 'kp'
    with BagWriter(path) as bag:
        for i, (_, f) in enumerate(list_openpose_files(EXAMPLE)[:30]):
            stamp = 1_000_000_000 + i * 33_333_333
            bag.write_msg('/mocap/keypoints2d', stamp,
                          keypoints_to_cloud(read_openpose_file(f), make_header(stamp, 'cam')))
    return path


def test_help_lists_commands(ros_env):
    r = run(['--help'], ros_env)
    assert r.returncode == 0
    for cmd in ('doctor', 'bag', 'plot', 'skeleton'):
        assert cmd in r.stdout


def test_bag_check_valid_bag(keypoint_bag, ros_env):
    r = run(['bag', 'check', keypoint_bag], ros_env)
    assert r.returncode == 0, r.stdout + r.stderr
    line = next(ln for ln in r.stdout.splitlines() if ln.startswith('/mocap/keypoints2d'))
    assert ' 30 ' in line and 'valid' in line and '30.00' in line


def test_bag_check_reports_malformed_messages(tmp_path, ros_env):
    from sensor_msgs.msg import PointCloud2
    path = tmp_path / 'bad'
    with BagWriter(path) as bag:
        good = keypoints_to_cloud(np.zeros((1, 23, 3)), make_header(1, 'cam'))
        bag.write_msg('/mocap/keypoints2d', 1, good)
        bad = keypoints_to_cloud(np.zeros((1, 23, 3)), make_header(2, 'cam'))
        bad.width = 17  # wrong number of keypoints
        bag.write_msg('/mocap/keypoints2d', 2, bad)
        bag.write_msg('/other', 3, PointCloud2())
    r = run(['bag', 'check', path], ros_env)
    assert r.returncode == 1
    line = next(ln for ln in r.stdout.splitlines() if ln.startswith('/mocap/keypoints2d'))
    assert '1 invalid' in line and 'width' in line
    assert 'not checked' in next(ln for ln in r.stdout.splitlines() if ln.startswith('/other'))


@pytest.mark.parametrize('make', ['missing', 'garbage'])
def test_bag_check_bad_path_is_one_clear_line(tmp_path, ros_env, make):
    path = tmp_path / 'nope'
    if make == 'garbage':
        path = tmp_path / 'garbage.mcap'
        path.write_bytes(b'not an mcap file at all')
    r = run(['bag', 'check', path], ros_env)
    assert r.returncode != 0
    assert 'Traceback' not in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert 'error' in r.stderr


def test_plot_keypoints_writes_png(keypoint_bag, tmp_path, ros_env):
    out = tmp_path / 'kp.png'
    r = run(['plot', 'keypoints', keypoint_bag, '-o', out], ros_env)
    assert r.returncode == 0, r.stderr
    assert out.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n' and out.stat().st_size > 10_000
    r = run(['plot', 'keypoints', keypoint_bag, '-o', out, '--topic', '/none'], ros_env)
    assert r.returncode == 1 and 'Traceback' not in r.stderr


def test_skeleton_urdf_loads_in_pinocchio(tmp_path, ros_env):
    import pinocchio as pin
    out = tmp_path / 'sk.urdf'
    r = run(['skeleton', '--urdf', out, '--body-mass', '80'], ros_env)
    assert r.returncode == 0, r.stderr
    model = pin.buildModelFromUrdf(str(out), pin.JointModelFreeFlyer())
    assert sum(i.mass for i in model.inertias) == pytest.approx(80.0)



def test_export_bvh_reproduces_ground_truth_joints(tmp_path, ros_env):
    """`mocap export bvh` of a committed bag's motion re-reads to the bag's joint positions."""
    from mocap_core.bag_io import BagReader, deserialize
    from mocap_core.data.bvh import BVH_TO_WORLD, bvh_fk, read_bvh
    from mocap_core.data.bvh_writer import FRAME_TO_BVH
    from mocap_core.ros_conversions import cloud_to_positions

    bag = ROOT / 'bags' / 'gt_cmu_walk_12_02'
    out = tmp_path / 'gt.bvh'
    r = run(['export', 'bvh', bag, '--topic', '/mocap/groundtruth/motion', '-o', out], ros_env)
    assert r.returncode == 0, r.stderr
    with BagReader(bag) as reader:
        joints = np.stack([cloud_to_positions(deserialize(m.data, m.msgtype)) for m in
                           reader.messages(topics=['/mocap/groundtruth/joints3d'])])
    got = bvh_fk(read_bvh(out), unit_scale=0.01).positions[:, :18]
    want = joints @ (np.asarray(BVH_TO_WORLD) @ FRAME_TO_BVH['camera']).T
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, atol=1e-3)   # float32 joints in the bag
    r = run(['export', 'bvh', bag, '--topic', '/none', '-o', out], ros_env)
    assert r.returncode == 1 and 'Traceback' not in r.stderr


def test_bench_commands_are_listed_and_node_benches_take_their_own_options(ros_env):
    res = run(['bench', '--help'], ros_env)
    assert res.returncode == 0 and all(n in res.stdout for n in
                                       ('pipeline', 'soak', 'keypoints', 'lifter', 'physics',
                                        'gmr'))
    res = run(['bench', 'lifter', '--help'], ros_env)
    assert res.returncode == 0 and '--repeat' in res.stdout, res.stderr
