"""``ros2 run mocap_keypoints keypoints`` in its own process, observed from this process."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / 'data' / 'openpose_example' / 'seq1'


@pytest.fixture
def listener(ros_env):
    """An rclpy node in this process, on the test session's domain, collecting messages."""
    import rclpy
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import CameraInfo, PointCloud2

    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=int(ros_env['ROS_DOMAIN_ID']))
    node = rclpy.create_node('test_listener', context=context)
    got = {'kp': [], 'info': []}
    node.create_subscription(PointCloud2, '/mocap/keypoints2d', got['kp'].append,
                             qos_profile_sensor_data)
    node.create_subscription(CameraInfo, '/mocap/camera_info', got['info'].append, 10)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    yield executor, got
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown(context=context)


def _spin_until_exit(executor, proc: subprocess.Popen, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while proc.poll() is None and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    for _ in range(20):  # drain what is still in flight
        executor.spin_once(timeout_sec=0.02)
    assert proc.poll() is not None, 'node did not exit in time'


def _run_node(processes, ros2_cmd, path: Path, *extra: str):
    return processes.start(
        ros2_cmd + ['run', 'mocap_keypoints', 'keypoints', '--ros-args',
                    '-p', f'path:={path}', '-p', 'fps:=60.0', '-p', 'wait_for_subscribers:=1',
                    '-p', 'wait_timeout_s:=30.0', *extra], 'keypoints')


def test_node_publishes_every_frame_in_order(processes, ros2_cmd, listener):
    from mocap_core.ros_conversions import (camera_info_to_intrinsics, cloud_to_keypoints,
                                            stamp_to_ns)
    from mocap_keypoints.openpose import list_openpose_files, read_openpose_file

    executor, got = listener
    proc, log = _run_node(processes, ros2_cmd, EXAMPLE)
    _spin_until_exit(executor, proc, timeout=90)
    assert proc.returncode == 0, log.read_text()
    assert len(got['kp']) == 81, log.read_text()
    assert len(got['info']) == 81
    stamps = [stamp_to_ns(m.header.stamp) for m in got['kp']]
    assert np.all(np.diff(stamps) > 0)
    np.testing.assert_allclose(np.diff(stamps), 1e9 / 60.0, atol=2)
    expected = read_openpose_file(list_openpose_files(EXAMPLE)[0][1])
    np.testing.assert_allclose(cloud_to_keypoints(got['kp'][0]), expected, rtol=1e-6)
    intr = camera_info_to_intrinsics(got['info'][0])
    assert intr.width >= 738 and intr.height >= 985
    assert got['info'][0].header.stamp == got['kp'][0].header.stamp
    assert 'approximating intrinsics' in log.read_text()


def test_malformed_json_is_skipped_with_the_file_named(processes, ros2_cmd, listener, tmp_path):
    executor, got = listener
    data = tmp_path / 'seq'
    shutil.copytree(EXAMPLE, data)
    files = sorted(data.glob('*.json'))
    for f in files[10:]:
        f.unlink()
    files[3].write_text('{"people": [{"pose_keypoints_2d": [1, 2, 3')
    files[5].write_text(json.dumps({'people': []}))  # nobody: all confidences 0
    proc, log = _run_node(processes, ros2_cmd, data)
    _spin_until_exit(executor, proc, timeout=60)
    text = log.read_text()
    assert proc.returncode == 0, text
    assert files[3].name in text and 'skipping frame' in text
    assert len(got['kp']) == 9
    from mocap_core.ros_conversions import cloud_to_keypoints
    empty = [cloud_to_keypoints(m) for m in got['kp'] if not np.any(cloud_to_keypoints(m)[..., 2])]
    assert len(empty) == 1 and empty[0].shape == (1, 23, 3)


def test_missing_directory_exits_with_clear_error(processes, ros2_cmd, tmp_path):
    proc, log = processes.start(
        ros2_cmd + ['run', 'mocap_keypoints', 'keypoints', '--ros-args',
                    '-p', f'path:={tmp_path / "nope"}'], 'keypoints_missing')
    assert proc.wait(timeout=60) != 0
    text = log.read_text()
    assert 'not found' in text and 'Traceback' not in text


def test_every_node_executable_starts_with_ros2_run(processes, ros2_cmd, ros_env):
    """Each executable installed under lib/<pkg>/ of the node packages starts as a process
    (the packages' nodes land issue by issue; each new one is covered here automatically)."""
    from ament_index_python.packages import get_package_prefix

    found = []
    for pkg in ('mocap_keypoints', 'mocap_lifter', 'mocap_physics', 'mocap_global'):
        lib = Path(get_package_prefix(pkg)) / 'lib' / pkg
        found += [(pkg, exe.name) for exe in sorted(lib.glob('*')) if os.access(exe, os.X_OK)]
    assert ('mocap_keypoints', 'keypoints') in found
    for pkg, exe in found:
        proc, log = processes.start(ros2_cmd + ['run', pkg, exe, '--help'], f'{pkg}_{exe}')
        rc = proc.wait(timeout=60)
        text = log.read_text()
        assert rc == 0 and 'Traceback' not in text, text
        assert '| parameter |' in text, f'{pkg}/{exe} --help does not list its parameters'
