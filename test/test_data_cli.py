"""``mocap data``: ground-truth bags, OpenPose bags, the committed bags, splits, errors.

Tests that need the real motion capture or OpenPose detections of ``../shared/data``
(``MOCAP_SHARED_DATA``) skip without them; the others use the repository's files and a
synthetic BVH clip.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mocap_core.bag_io import BagReader, deserialize
from mocap_core.data.bvh_synth import synthetic_walk_bvh
from mocap_core.data.bvh import parse_bvh
from mocap_core.data.dataset import process_clip
from mocap_core.data.gt_bag import (DEFAULT_START_NS, GT_TOPICS, OPTICAL_FRAME, WORLD_FRAME,
                                    read_groundtruth_bag, write_groundtruth_bag)
from mocap_core.data.synth2d import CameraSampling, Corruption
from mocap_core.kinematics import forward_kinematics
from mocap_core.ros_conversions import (camera_info_to_intrinsics, cloud_to_keypoints,
                                        cloud_to_positions, motion_to_pose, msg_to_contacts,
                                        stamp_to_ns)
from mocap_core.rotations import quat_multiply, quat_rotate
from mocap_core.skeleton import JOINT_INDEX, KEYPOINT_INDEX, NUM_JOINTS

ROOT = Path(__file__).resolve().parents[1]
BAGS = ROOT / 'bags'
EXAMPLE = ROOT / 'data' / 'openpose_example' / 'seq1'
DATA = Path(os.environ.get('MOCAP_SHARED_DATA', ROOT.parent / 'shared' / 'data'))
NEEDS_DATA = 'needs ../shared/data (not shipped with the repository)'
MOCAP = [sys.executable, '-m', 'mocap_core.cli.mocap']
JOINT_KEYPOINTS = ('left_shoulder', 'right_shoulder', 'left_elbow', 'right_elbow',
                   'left_wrist', 'right_wrist', 'left_hip', 'right_hip', 'left_knee',
                   'right_knee', 'left_ankle', 'right_ankle')


def run(args, env=None, timeout=180):
    return subprocess.run(MOCAP + [str(a) for a in args], env=env, capture_output=True,
                          text=True, timeout=timeout)


def one_line_error(r) -> str:
    assert r.returncode != 0, r.stdout
    assert 'Traceback' not in r.stderr, r.stderr
    lines = [ln for ln in r.stderr.strip().splitlines() if ln.strip()]
    assert len(lines) == 1, r.stderr
    assert 'error' in lines[0]
    return lines[0]


def read_bag(path):
    """{topic: [(bag stamp, msgtype, message), ...]}"""
    out = {}
    with BagReader(path) as reader:
        for m in reader.messages():
            out.setdefault(m.topic, []).append((m.timestamp_ns, m.msgtype,
                                                deserialize(m.data, m.msgtype)))
    return out


@pytest.fixture(scope='module')
def synth_motion():
    bvh = parse_bvh(synthetic_walk_bvh(360, 120.0), 'synthetic_walk')
    motion, _ = process_clip(bvh, 'synthetic_walk')
    return motion


def check_groundtruth_bag(path, frames, fps, clean, world_motion=True):
    """Types, counts, stamps, frames; FK of the motion = joints3d; joints3d projects onto the
    keypoints (clean: within 1 px); the world motion is the camera pose x the camera motion."""
    bag = read_bag(path)
    expected = {GT_TOPICS[k] for k in ('camera_info', 'keypoints', 'motion', 'joints3d',
                                       'contacts', 'camera_pose')}
    if world_motion:
        expected.add(GT_TOPICS['world_motion'])
    assert set(bag) == expected
    types = {t: rows[0][1] for t, rows in bag.items()}
    assert types[GT_TOPICS['keypoints']] == 'sensor_msgs/msg/PointCloud2'
    assert types[GT_TOPICS['joints3d']] == 'sensor_msgs/msg/PointCloud2'
    assert types[GT_TOPICS['camera_info']] == 'sensor_msgs/msg/CameraInfo'
    assert types[GT_TOPICS['motion']] == 'trajectory_msgs/msg/MultiDOFJointTrajectory'
    assert types[GT_TOPICS['contacts']] == 'sensor_msgs/msg/JointState'
    assert types[GT_TOPICS['camera_pose']] == 'geometry_msgs/msg/PoseStamped'
    assert len(bag[GT_TOPICS['camera_pose']]) == 1
    for t in expected - {GT_TOPICS['camera_pose']}:
        rows = bag[t]
        assert len(rows) == frames, t
        stamps = np.array([stamp_to_ns(m.header.stamp) for _, _, m in rows])
        assert np.array_equal(stamps, [s for s, _, _ in rows])  # header stamp = bag time
        assert stamps[0] == DEFAULT_START_NS
        assert np.abs(np.diff(stamps) - 1e9 / fps).max() <= 1.0   # 1/fps, rounded to 1 ns
        frame = WORLD_FRAME if t == GT_TOPICS['world_motion'] else OPTICAL_FRAME
        assert all(m.header.frame_id == frame for _, _, m in rows)
    intr = camera_info_to_intrinsics(bag[GT_TOPICS['camera_info']][0][2])
    pose_msg = bag[GT_TOPICS['camera_pose']][0][2].pose
    cam_q = np.array([pose_msg.orientation.x, pose_msg.orientation.y, pose_msg.orientation.z,
                      pose_msg.orientation.w])
    cam_p = np.array([pose_msg.position.x, pose_msg.position.y, pose_msg.position.z])
    worst_px = 0.0
    for i in range(frames):
        kp = cloud_to_keypoints(bag[GT_TOPICS['keypoints']][i][2])
        assert kp.shape == (1, 23, 3)
        joints = cloud_to_positions(bag[GT_TOPICS['joints3d']][i][2], NUM_JOINTS)
        pose = motion_to_pose(bag[GT_TOPICS['motion']][i][2])
        fk = forward_kinematics(pose.skeleton.parents, pose.skeleton.offsets, pose.rotations,
                                pose.root_position).positions
        assert np.abs(fk - joints).max() < 1e-4          # float32 cloud
        assert np.all(joints[:, 2] > 0)                  # in front of the camera
        c = msg_to_contacts(bag[GT_TOPICS['contacts']][i][2])
        assert set(np.unique(c)) <= {0.0, 1.0}
        uv = intr.project(joints)
        for name in JOINT_KEYPOINTS:
            k, j = KEYPOINT_INDEX[name], JOINT_INDEX[name]
            if kp[0, k, 2] > 0:
                worst_px = max(worst_px, float(np.linalg.norm(kp[0, k, :2] - uv[j])))
        if clean:
            assert np.all(kp[0, :, 2] == 1.0)
            assert np.all((kp[0, :, 0] >= 0) & (kp[0, :, 0] < intr.width))
            assert np.all((kp[0, :, 1] >= 0) & (kp[0, :, 1] < intr.height))
        if world_motion:
            world = motion_to_pose(bag[GT_TOPICS['world_motion']][i][2])
            np.testing.assert_allclose(world.skeleton.offsets, pose.skeleton.offsets)
            np.testing.assert_allclose(world.rotations[1:], pose.rotations[1:], atol=1e-9)
            np.testing.assert_allclose(quat_rotate(cam_q, pose.root_position) + cam_p,
                                       world.root_position, atol=1e-6)
            q = quat_multiply(cam_q, pose.rotations[0])
            assert abs(abs(float(np.dot(q, world.rotations[0]))) - 1.0) < 1e-9
            assert world.joint_positions()[:, 2].min() > -0.15   # floor at z = 0
    if clean:
        assert worst_px < 1.0, worst_px
    return bag, worst_px


# ---------------------------------------------------------------------------------------------
# library: ground-truth bags from a synthetic clip (no shared data needed)
# ---------------------------------------------------------------------------------------------
def test_groundtruth_bag_clean_reprojects_within_a_pixel(tmp_path, synth_motion):
    out = tmp_path / 'clean'
    s = write_groundtruth_bag(synth_motion, out, CameraSampling(), corruption=None, seed=4)
    assert s.frames == synth_motion.num_frames == 90 and s.clean
    check_groundtruth_bag(out, 90, 30.0, clean=True)
    # read back as a lifter's evaluation reads it: the camera's keypoints and camera-frame poses
    b = read_groundtruth_bag(out)
    kp, intr, poses = b['keypoints'], b['intrinsics'], b['poses']
    raw = read_bag(out)
    assert kp.shape == (90, 23, 3) and len(poses) == 90 and len(b['stamps']) == 90
    assert np.array_equal(kp[37], cloud_to_keypoints(raw[GT_TOPICS['keypoints']][37][2])[0])
    assert (intr.width, intr.height) == (s.intrinsics.width, s.intrinsics.height)
    assert np.allclose(poses[37].joint_positions(),
                       cloud_to_positions(raw[GT_TOPICS['joints3d']][37][2], NUM_JOINTS))


def test_groundtruth_bag_corrupted_and_reproducible(tmp_path, synth_motion):
    a = write_groundtruth_bag(synth_motion, tmp_path / 'a', seed=7, corruption=Corruption(),
                              world_motion=False)
    b = write_groundtruth_bag(synth_motion, tmp_path / 'b', seed=7, corruption=Corruption(),
                              world_motion=False)
    bag, worst = check_groundtruth_bag(tmp_path / 'a', 90, 30.0, clean=False,
                                       world_motion=False)
    kp = np.stack([cloud_to_keypoints(m)[0] for _, _, m in bag[GT_TOPICS['keypoints']]])
    conf = kp[..., 2]
    assert 0.5 < conf.mean() < 0.95 and (conf < 1.0).mean() > 0.9   # detector-like
    assert worst > 0.5                                               # displaced
    assert np.array_equal(a.camera.rotation, b.camera.rotation)
    other = read_bag(tmp_path / 'b')      # same seed, same messages (CDR padding aside)
    assert set(other) == set(bag)
    for (ta, _, ma), (tb, _, mb) in zip(bag[GT_TOPICS['keypoints']],
                                        other[GT_TOPICS['keypoints']]):
        assert ta == tb and np.array_equal(cloud_to_keypoints(ma), cloud_to_keypoints(mb))
    assert np.array_equal(a.camera.position, b.camera.position)


# ---------------------------------------------------------------------------------------------
# command line
# ---------------------------------------------------------------------------------------------
def test_data_help_lists_commands(ros_env):
    r = run(['data', '--help'], ros_env)
    assert r.returncode == 0
    for cmd in ('build', 'report', 'split', 'to-bag', 'from-openpose', 'fit-confidence'):
        assert cmd in r.stdout


def test_to_bag_from_a_bvh_file(tmp_path, ros_env):
    bvh = tmp_path / 'synthetic_walk.bvh'
    bvh.write_text(synthetic_walk_bvh(360, 120.0))
    out = tmp_path / 'bag'
    r = run(['data', 'to-bag', bvh, '-o', out, '--clean', '--frames', 40, '--start', 10,
             '--fov', 60, '--image-size', '1280x720', '--distance', 4, '--seed', 3], ros_env)
    assert r.returncode == 0, r.stderr
    assert '40 frames at 30 fps' in r.stdout
    check_groundtruth_bag(out, 40, 30.0, clean=True)
    intr = camera_info_to_intrinsics(read_bag(out)[GT_TOPICS['camera_info']][0][2])
    assert (intr.width, intr.height) == (1280, 720)
    assert abs(np.degrees(2 * np.arctan(640 / intr.fx)) - 60.0) < 1e-6
    # the same bag again needs --overwrite
    line = one_line_error(run(['data', 'to-bag', bvh, '-o', out], ros_env))
    assert 'already exists' in line
    r = run(['data', 'to-bag', bvh, '-o', out, '--overwrite', '--fps', 25], ros_env)
    assert r.returncode == 0, r.stderr
    assert len(read_bag(out)[GT_TOPICS['keypoints']]) == 75    # 3 s at 25 fps


def test_to_bag_real_validation_clip(tmp_path, ros_env):
    if not (DATA / 'cmu_bvh' / 'daz_friendly_120fps' / '12_02.bvh').exists():
        pytest.skip(NEEDS_DATA)
    out = tmp_path / 'walk'
    r = run(['data', 'to-bag', '12_02', '-o', out, '--clean', '--frames', 60, '--seed', 5],
            ros_env)
    assert r.returncode == 0, r.stderr
    assert 'daz_friendly_120fps/12_02.bvh (validation), 60 frames at 30 fps' in r.stdout
    bag, _ = check_groundtruth_bag(out, 60, 30.0, clean=True)
    contacts = np.stack([msg_to_contacts(m) for _, _, m in bag[GT_TOPICS['contacts']]])
    assert 0.2 < contacts[:, [0, 2]].mean() < 0.8              # heels on the floor at times


def test_from_openpose_reproduces_the_json(tmp_path, ros_env):
    from mocap_core.data.openpose import list_openpose_files, read_openpose_file

    out = tmp_path / 'op'
    r = run(['data', 'from-openpose', EXAMPLE, '-o', out, '--fps', 25, '--fov', 50], ros_env)
    assert r.returncode == 0, r.stderr
    bag = read_bag(out)
    assert set(bag) == {'/mocap/keypoints2d', '/mocap/camera_info'}
    files = list_openpose_files(EXAMPLE)
    rows = bag['/mocap/keypoints2d']
    assert len(rows) == len(files) == 81
    for (k, f), (stamp, _, msg) in zip(files, rows):
        assert stamp == DEFAULT_START_NS + round((k - files[0][0]) * 1e9 / 25)
        assert stamp_to_ns(msg.header.stamp) == stamp
        expected = read_openpose_file(f)
        got = cloud_to_keypoints(msg)
        assert got.shape == expected.shape
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-3)  # float32 pixels
    intr = camera_info_to_intrinsics(bag['/mocap/camera_info'][0][2])
    assert abs(np.degrees(2 * np.arctan(0.5 * intr.width / intr.fx)) - 50.0) < 1e-6
    assert intr.width >= 739 and intr.height >= 986        # holds every keypoint


def test_committed_bags_pass_bag_check(ros_env):
    bags = sorted(p.parent for p in BAGS.glob('*/metadata.yaml'))
    names = {p.name for p in bags}
    assert 'openpose_seq1' in names and sum(n.startswith('gt_') for n in names) >= 2, names
    for bag in bags:
        size = sum(f.stat().st_size for f in bag.iterdir())
        assert size < 1_000_000, f'{bag.name}: {size} bytes'
        r = run(['bag', 'check', bag], ros_env)
        assert r.returncode == 0, r.stdout + r.stderr
        for line in r.stdout.splitlines()[1:]:
            topic = line.split()[0]
            if topic != GT_TOPICS['camera_pose']:
                assert line.rstrip().endswith('valid') and '30.00' in line, line
    readme = (BAGS / 'README.md').read_text()
    for name in names:
        assert name in readme, f'{name} is not described in bags/README.md'


def test_committed_groundtruth_bags_are_consistent():
    for bag in sorted(BAGS.glob('gt_*/metadata.yaml')):
        with BagReader(bag.parent) as r:
            n = r.topics[GT_TOPICS['keypoints']].count
            world = GT_TOPICS['world_motion'] in r.topics
        check_groundtruth_bag(bag.parent, n, 30.0, clean=False, world_motion=world)


def test_split_check_matches_the_data(ros_env):
    if not (DATA / 'cmu_bvh').exists() or not (DATA / 'bandai_namco_bvh').exists():
        pytest.skip(NEEDS_DATA)
    r = run(['data', 'split', '--check'], ros_env)
    assert r.returncode == 0, r.stdout + r.stderr
    assert 'up to date' in r.stdout


def test_fit_confidence_reproduces_the_shipped_model(tmp_path, ros_env):
    real = DATA / 'keypoints_real' / 'motionet_openpose'
    if not real.is_dir():
        pytest.skip(NEEDS_DATA)
    from mocap_core.data.synth2d import ConfidenceModel

    shipped = ROOT / 'src' / 'mocap_core' / 'mocap_core' / 'data' / 'confidence_model.json'
    out = tmp_path / 'model.json'
    source = json.loads(shipped.read_text())['source']
    r = run(['data', 'fit-confidence', *sorted(real.iterdir()), '-o', out, '--source', source],
            ros_env)
    assert r.returncode == 0, r.stderr
    assert out.read_text() == shipped.read_text()
    assert ConfidenceModel.from_json(out).frames == 2640


def test_fit_confidence_on_the_repository_example(tmp_path, ros_env):
    from mocap_core.data.synth2d import ConfidenceModel

    out = tmp_path / 'model.json'
    r = run(['data', 'fit-confidence', EXAMPLE, '-o', out], ros_env)
    assert r.returncode == 0, r.stderr
    m = ConfidenceModel.from_json(out)
    assert m.frames == 81 and np.all((m.mean > 0) & (m.mean <= 1)) and 'seq1' in m.source


@pytest.mark.parametrize('case', ['unknown_clip', 'ambiguous_clip', 'no_openpose_dir',
                                  'empty_openpose_dir', 'bad_image_size', 'bad_frames',
                                  'no_data_build', 'no_data_split', 'no_data_report',
                                  'bad_fov', 'fit_not_a_dir', 'bad_split_file'])
def test_bad_inputs_give_one_line_errors(case, tmp_path, ros_env):
    env = dict(ros_env)
    bvh = tmp_path / 'w.bvh'
    bvh.write_text(synthetic_walk_bvh(120, 120.0))
    empty = tmp_path / 'empty'
    empty.mkdir()
    args, want = {
        'unknown_clip': (['data', 'to-bag', 'no_such_clip', '-o', tmp_path / 'x'],
                         'unknown clip'),
        'ambiguous_clip': (['data', 'to-bag', '04', '-o', tmp_path / 'x'], 'ambiguous'),
        'no_openpose_dir': (['data', 'from-openpose', tmp_path / 'nope', '-o', tmp_path / 'x'],
                            'not found'),
        'empty_openpose_dir': (['data', 'from-openpose', empty, '-o', tmp_path / 'x'],
                               'no *.json'),
        'bad_image_size': (['data', 'to-bag', bvh, '-o', tmp_path / 'x', '--image-size',
                            '640by480'], 'WIDTHxHEIGHT'),
        'bad_frames': (['data', 'to-bag', bvh, '-o', tmp_path / 'x', '--frames', 0],
                       '--frames'),
        'no_data_build': (['data', 'build'], 'not found'),
        'no_data_split': (['data', 'split', '--check'], 'not found'),
        'no_data_report': (['data', 'report'], 'not found'),
        'bad_fov': (['data', 'to-bag', bvh, '-o', tmp_path / 'x', '--fov', 200], '--fov'),
        'fit_not_a_dir': (['data', 'fit-confidence', bvh, '-o', tmp_path / 'm.json'],
                          'not an OpenPose folder'),
        'bad_split_file': (['data', 'to-bag', 'x', '-o', tmp_path / 'x', '--splits', bvh],
                           'not valid JSON'),
    }[case]
    if case.startswith('no_data'):
        env['MOCAP_SHARED_DATA'] = str(tmp_path / 'no_shared_data')
    line = one_line_error(run(args, env))
    assert want in line, line
    assert not (tmp_path / 'x').exists()
