"""``ros2 run mocap_keypoints keypoints`` in its own process, observed from this process."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / 'data' / 'openpose_example' / 'seq1'


def _collect(peer, msg_type, topic: str, sensor: bool = True) -> list:
    """Subscribe (best effort for sensor topics) with a deep reader queue, so that this
    process, sharing two cores with the node, cannot lose messages while it is busy."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    qos = QoSProfile(depth=500, reliability=ReliabilityPolicy.BEST_EFFORT if sensor
                     else ReliabilityPolicy.RELIABLE)
    return peer.subscribe(msg_type, topic, qos)


@pytest.fixture
def listener(peer):
    """The test's rclpy peer collecting keypoints and camera_info (deep reader queues: a
    sensor-data depth of 5 lost 14 of 81 messages at 60 fps on a loaded machine)."""
    from sensor_msgs.msg import CameraInfo, PointCloud2
    return peer, {'kp': _collect(peer, PointCloud2, '/mocap/keypoints2d'),
                  'info': _collect(peer, CameraInfo, '/mocap/camera_info', sensor=False)}


def _run_node(processes, ros2_cmd, path: Path, *extra: str):
    return processes.start(
        ros2_cmd + ['run', 'mocap_keypoints', 'keypoints', '--ros-args',
                    '-p', f'path:={path}', '-p', 'fps:=60.0', '-p', 'wait_for_subscribers:=1',
                    '-p', 'wait_timeout_s:=30.0', *extra], 'keypoints')


def test_node_publishes_every_frame_in_order(processes, ros2_cmd, listener):
    from mocap_core.ros_conversions import (camera_info_to_intrinsics, cloud_to_ids,
                                            cloud_to_keypoints, stamp_to_ns)
    from mocap_core.data.openpose import list_openpose_files, read_openpose_file

    peer, got = listener
    # as fast as possible, no drops: at its frame rate (the default) a loaded machine makes
    # the node drop frames it cannot keep up with, as designed for live use
    proc, log = _run_node(processes, ros2_cmd, EXAMPLE, '-p', 'realtime:=false')
    peer.spin_until_exit(proc, timeout=90)
    assert proc.returncode == 0, log.read_text()
    # what the node sent just before it exited may still be on its way (a loaded machine)
    peer.spin(10.0, until=lambda: len(got['kp']) >= 81 and len(got['info']) >= 81)
    assert len(got['kp']) == 81, log.read_text()
    assert len(got['info']) == 81
    stamps = [stamp_to_ns(m.header.stamp) for m in got['kp']]
    assert np.all(np.diff(stamps) > 0)
    np.testing.assert_allclose(np.diff(stamps), 1e9 / 60.0, atol=2)
    # a new person gets an id (and is published) on the third consecutive frame seen
    # (id_after_frames 3): the first two clouds are the all-zero row of nobody, id 0
    assert [cloud_to_ids(m).tolist() for m in got['kp'][:4]] == [[0], [0], [1], [1]]
    assert not np.any(cloud_to_keypoints(got['kp'][1])[..., 2])
    expected = read_openpose_file(list_openpose_files(EXAMPLE)[2][1])
    np.testing.assert_allclose(cloud_to_keypoints(got['kp'][2]), expected, rtol=1e-6)
    assert {tuple(cloud_to_ids(m)) for m in got['kp'][2:]} == {(1,)}   # one id throughout
    intr = camera_info_to_intrinsics(got['info'][0])
    assert intr.width >= 738 and intr.height >= 985
    assert got['info'][0].header.stamp == got['kp'][0].header.stamp
    assert 'approximating intrinsics' in log.read_text()


def test_malformed_json_is_skipped_with_the_file_named(processes, ros2_cmd, listener, tmp_path):
    peer, got = listener
    data = tmp_path / 'seq'
    shutil.copytree(EXAMPLE, data)
    files = sorted(data.glob('*.json'))
    for f in files[10:]:
        f.unlink()
    files[3].write_text('{"people": [{"pose_keypoints_2d": [1, 2, 3')
    files[5].write_text(json.dumps({'people': []}))  # nobody: all confidences 0
    proc, log = _run_node(processes, ros2_cmd, data, '-p', 'realtime:=false')
    peer.spin_until_exit(proc, timeout=60)
    text = log.read_text()
    assert proc.returncode == 0, text
    assert files[3].name in text and 'skipping frame' in text
    assert len(got['kp']) == 9
    from mocap_core.ros_conversions import cloud_to_keypoints
    empty = [i for i, m in enumerate(got['kp']) if not np.any(cloud_to_keypoints(m)[..., 2])]
    # the two frames before the person gets an id, and the file with nobody (the 5th cloud)
    assert empty == [0, 1, 4]
    assert all(cloud_to_keypoints(got['kp'][i]).shape == (1, 23, 3) for i in empty)


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


# --- camera, video, image and topic sources with MediaPipe BlazePose ---------------------------
CLIP = ROOT / 'data' / 'video_example' / 'taiji_640x360.mp4'
CLIP_INFO = json.loads(CLIP.with_suffix('.json').read_text())
BODY = ('left_shoulder', 'right_shoulder', 'left_hip', 'right_hip', 'left_knee', 'right_knee',
        'left_ankle', 'right_ankle')


def _keypoints_node(processes, ros2_cmd, name: str, *params: str, remap: tuple = ()):
    args = []
    for p in params:
        args += ['-p', p]
    for r in remap:
        args += ['-r', r]
    return processes.start(ros2_cmd + ['run', 'mocap_keypoints', 'keypoints', '--ros-args',
                                       *args], name)


def _confident_body(kp: np.ndarray) -> np.ndarray:
    from mocap_core.skeleton import KEYPOINT_INDEX
    return np.all(kp[:, 0, [KEYPOINT_INDEX[n] for n in BODY], 2] > 0.5, axis=1)


def test_video_source_one_message_per_frame_with_image_stamps(processes, ros2_cmd, peer,
                                                              tmp_path):
    """The issue's acceptance test: the committed clip through ``ros2 run``."""
    from sensor_msgs.msg import CameraInfo, Image, PointCloud2

    from mocap_core.camera import CameraCalibration, CameraIntrinsics, write_camera_info_yaml
    from mocap_core.ros_conversions import (camera_info_to_intrinsics, cloud_to_keypoints,
                                            image_to_bgr, stamp_to_ns)

    calib = tmp_path / 'camera.yaml'  # calibrated at 1280x720: scaled to the 640x360 clip
    write_camera_info_yaml(CameraCalibration(
        CameraIntrinsics(1280, 720, 1100.0, 1100.0, 639.5, 359.5)), calib)
    from diagnostic_msgs.msg import DiagnosticArray

    info_msgs = _collect(peer, CameraInfo, '/mocap/camera_info', sensor=False)
    annotated = _collect(peer, Image, '/mocap/keypoints2d/annotated', sensor=False)
    diagnostics = _collect(peer, DiagnosticArray, '/diagnostics', sensor=False)
    proc, log = _keypoints_node(
        processes, ros2_cmd, 'keypoints_video', 'source:=video', f'path:={CLIP}',
        'realtime:=false', 'publish_annotated:=true', f'calibration_file:={calib}',
        'wait_for_subscribers:=1', 'wait_timeout_s:=30.0', 'frame_id:=taiji_camera',
        'facing_check:=true', 'mirror_check:=true')
    # The node starts when it sees the keypoint subscriber; subscribe to the keypoints only
    # once the debug-image publisher (its own participant) has been discovered too.
    assert peer.spin(60, until=lambda: peer.node.count_publishers(
        '/mocap/keypoints2d/annotated') > 0, proc=proc), log.read_text()
    peer.spin(0.5)
    kp_msgs = _collect(peer, PointCloud2, '/mocap/keypoints2d')
    peer.spin_until_exit(proc, timeout=90)
    text = log.read_text()
    assert proc.returncode == 0, text
    n = CLIP_INFO['frames']
    assert len(kp_msgs) == n and len(info_msgs) == n, text
    stamps = np.array([stamp_to_ns(m.header.stamp) for m in kp_msgs])
    expected = stamps[0] + np.round(np.arange(n) * 1e9 / CLIP_INFO['fps'])
    np.testing.assert_allclose(stamps, expected, atol=1)  # start + index / video fps
    assert [stamp_to_ns(m.header.stamp) for m in info_msgs] == list(stamps)
    assert all(m.header.frame_id == 'taiji_camera' for m in kp_msgs)
    # Debug images: reliable, keep-last 2, so this busy process may miss a few.
    assert len(annotated) >= n * 3 // 4, len(annotated)
    assert {stamp_to_ns(m.header.stamp) for m in annotated} <= set(stamps.tolist())
    assert image_to_bgr(annotated[0]).shape == (360, 640, 3)
    intr = camera_info_to_intrinsics(info_msgs[0])
    assert (intr.width, intr.height) == (640, 360)
    assert (intr.fx, intr.cx, intr.cy) == pytest.approx((550.0, 319.5, 179.5))
    kp = np.stack([cloud_to_keypoints(m) for m in kp_msgs])
    visible = np.zeros(n, bool)
    for a, b in CLIP_INFO['person_fully_visible']:
        visible[a:b + 1] = True
    assert _confident_body(kp)[visible].mean() >= 0.9
    assert 'video ended after 96 frames' in text and 'scaled to the 640x360 image' in text
    assert 'Traceback' not in text
    # /diagnostics: detector time, input and output rates, drops, source, detector.
    values = {kv.key: kv.value for kv in diagnostics[-1].status[0].values}
    assert 'keypoints' in diagnostics[-1].status[0].name
    assert float(values['detector_ms_median']) > 0 and float(values['output_rate_hz']) > 0
    assert float(values['input_rate_hz']) > 0 and values['frames_dropped'] == '0'
    assert 'taiji_640x360.mp4' in values['source']
    assert values['detector'] == 'mediapipe_blazepose_full_multi'     # max_persons 4
    assert values['camera_motion_rotation'] == 'plane'
    assert values['finish_thread'] == 'on'      # the camera motion beside the detector
    assert values['person_ids'] == '1' and values['ids_given'] == '1'
    # the person is found in the first searches and followed; the finer squares are
    # searched in turn, and where the picture changed
    assert re.fullmatch(r'[1-9]\d* \(\d+ in the finer squares, \d+ people found there; '
                        r'\d+ where the picture changed, \d+ found there\), '
                        r'\d+ skipped in a still picture', values['searches']), values
    assert 'calibration file' in values['intrinsics']
    # the facing check ran on the frames with a person (what it decides there is
    # test_facing.py's and docs/keypoints.md's)
    assert values['facing_check'] == 'on (facing.pt)', values
    assert re.fullmatch(r'\d+ of \d+ persons scored.*', values['facing_exchanged']), values
    assert int(values['facing_exchanged'].split()[2]) >= 0.8 * n
    assert values['facing_failures'] == '0' and float(values['facing_ms_median']) > 0
    # the mirror check read every frame mirrored and found the performer there
    assert values['mirror_check'] == 'on' and values['mirror_failures'] == '0', values
    m = re.fullmatch(r'(\d+) of (\d+) persons labelled as facing the camera \((\d+) found in '
                     r'the mirrored frame\)', values['mirror_exchanged'])
    assert m and int(m.group(2)) >= 0.8 * n and int(m.group(3)) >= 0.8 * int(m.group(2)), values
    assert float(values['mirror_detector_ms_median']) > 0
    read, frames = (int(x) for x in values['mirror_frames_read'].split(' of '))
    assert 0 < read <= frames, values


def test_facing_check_with_unusable_weights_is_off_and_the_node_runs(processes, ros2_cmd, peer,
                                                                     tmp_path):
    from sensor_msgs.msg import PointCloud2

    bad = tmp_path / 'facing.pt'
    bad.write_bytes(b'no weights here')
    kp_msgs = _collect(peer, PointCloud2, '/mocap/keypoints2d')
    proc, log = _keypoints_node(
        processes, ros2_cmd, 'keypoints_facing', 'source:=video', f'path:={CLIP}',
        'realtime:=false', 'max_persons:=1', 'camera_motion:=false', 'facing_check:=true',
        f'facing_weights:={bad}', 'wait_for_subscribers:=1', 'wait_timeout_s:=30.0')
    peer.spin_until_exit(proc, timeout=90)
    text = log.read_text()
    assert proc.returncode == 0, text
    peer.spin(10.0, until=lambda: len(kp_msgs) >= CLIP_INFO['frames'])
    assert len(kp_msgs) == CLIP_INFO['frames'], text
    assert 'facing_check is off' in text and str(bad) in text and 'Traceback' not in text


def _image_msg(img, stamp_ns, encoding='bgr8', frame_id='cam_optical'):
    from mocap_core.ros_conversions import bgr_to_image, make_header
    return bgr_to_image(img, make_header(stamp_ns, frame_id), encoding)


def test_topic_source_image_stamps_and_bad_images(processes, ros2_cmd, peer):
    """Image and CompressedImage topics: one cloud per good image with its stamp; unsupported
    encodings, wrong sizes, empty and corrupt images, stamps going back and bad CameraInfo are
    logged and skipped while the node keeps running."""
    import signal

    from sensor_msgs.msg import CameraInfo, CompressedImage, Image, PointCloud2

    from mocap_core.camera import CameraIntrinsics
    from mocap_core.executors import SHUTDOWN_HANG
    from mocap_core.ros_conversions import (bgr_to_compressed_image, camera_info_to_intrinsics,
                                            cloud_to_keypoints, intrinsics_to_camera_info,
                                            make_header, stamp_to_ns)
    from mocap_keypoints.sources import VideoSource

    with VideoSource(CLIP) as src:
        frames = [f.image for f, _ in zip(src, range(14))]
    raw, raw_log = _keypoints_node(processes, ros2_cmd, 'keypoints_raw', 'source:=topic')
    comp, comp_log = _keypoints_node(
        processes, ros2_cmd, 'keypoints_compressed', 'source:=topic',
        'image_topic:=/camera/image_raw/compressed',
        remap=('__node:=keypoints_compressed', '/mocap/keypoints2d:=/c/keypoints2d',
               '/mocap/camera_info:=/c/camera_info'))
    kp_raw = _collect(peer, PointCloud2, '/mocap/keypoints2d')
    info_raw = _collect(peer, CameraInfo, '/mocap/camera_info', sensor=False)
    kp_comp = _collect(peer, PointCloud2, '/c/keypoints2d')
    pub_img = peer.node.create_publisher(Image, '/camera/image_raw', 10)
    pub_comp = peer.node.create_publisher(CompressedImage, '/camera/image_raw/compressed', 10)
    pub_info = peer.node.create_publisher(CameraInfo, '/camera/camera_info', 10)
    n = peer.node
    assert peer.spin(60, until=lambda: pub_img.get_subscription_count() > 0
                     and pub_comp.get_subscription_count() > 0
                     and pub_info.get_subscription_count() > 1
                     and n.count_publishers('/mocap/keypoints2d') > 0
                     and n.count_publishers('/c/keypoints2d') > 0), \
        raw_log.read_text() + comp_log.read_text()

    t0 = 1_700_000_000_000_000_000

    def real(got):
        """The messages of the test proper: warm-up clouds, stamped before ``t0``, may still
        arrive late on a busy machine and are left out."""
        return [m for m in got if stamp_to_ns(m.header.stamp) >= t0]

    def warm_up(pub, got, make, proc):
        """Publish until a cloud with the person comes back (discovery has matched both ways
        and the person has an id, which takes three frames)."""
        def person():
            return bool(got) and bool(np.any(cloud_to_keypoints(got[-1])[..., 2]))
        for k in range(60):
            pub.publish(make(t0 - 5 * 10**8 + k * 10**6))
            if peer.spin(0.5, until=person, proc=proc):
                break
        assert person(), 'no cloud with the person came back'

    # image_qos auto: each node subscribes reliably once it has seen this test's reliable
    # publishers (re-checked every second); a large raw image sent to the first, best-effort
    # subscription may be lost on a loaded machine
    processes.wait_for_text(raw_log, 'subscribed to /camera/image_raw (Image, reliable)', 30,
                            raw)
    processes.wait_for_text(comp_log, '/compressed (CompressedImage, reliable)', 30, comp)
    warm_up(pub_img, kp_raw, lambda st: _image_msg(frames[0], st), raw)
    warm_up(pub_comp, kp_comp,
            lambda st: bgr_to_compressed_image(frames[0], make_header(st, 'c')), comp)
    info = intrinsics_to_camera_info(CameraIntrinsics(1280, 720, 1000.0, 1000.0, 639.5, 359.5),
                                     make_header(t0, 'cam_optical'))
    pub_info.publish(info)
    processes.wait_for_text(raw_log, 'camera_info: 1280x720', 20, raw)

    def send(pub, msg, got, expect_cloud=True, log=None, text=None):
        count = len(real(got))
        pub.publish(msg)
        if expect_cloud:
            assert peer.spin(20, until=lambda: len(real(got)) > count, proc=raw), log.read_text()
            assert stamp_to_ns(real(got)[-1].header.stamp) == stamp_to_ns(msg.header.stamp)
        else:
            deadline = time.monotonic() + 20
            while text not in log.read_text() and time.monotonic() < deadline:
                peer.executor.spin_once(timeout_sec=0.02)
            assert text in log.read_text(), log.read_text()

    good_stamps = []
    for i in range(10):
        stamp = t0 + i * 40_000_000
        enc = 'rgb8' if i % 3 == 2 else 'bgr8'
        img = frames[i] if enc == 'bgr8' else frames[i][:, :, ::-1]
        send(pub_img, _image_msg(img, stamp, enc), kp_raw, log=raw_log)
        good_stamps.append(stamp)
    stamp = t0 + 10 * 40_000_000  # nobody in the image: a cloud with all confidences 0
    send(pub_img, _image_msg(np.full((360, 640, 3), 90, np.uint8), stamp), kp_raw, log=raw_log)
    good_stamps.append(stamp)
    assert not np.any(cloud_to_keypoints(kp_raw[-1])[..., 2])
    processes.wait_for_text(raw_log, 'no person found', 10, raw)
    bad = []
    m = _image_msg(frames[10], t0 + 11 * 40_000_000)
    m.encoding = '32FC1'
    bad.append((m, 'unsupported image encoding'))
    m = _image_msg(frames[10], t0 + 12 * 40_000_000)
    m.data = m.data[:1000]
    bad.append((m, 'image data has 1000 bytes'))
    m = _image_msg(np.zeros((480, 640, 3), np.uint8), t0 + 13 * 40_000_000)
    m.width = 1280  # header says a wider image than the rows hold
    bad.append((m, 'image step 1920 is shorter than a row of 1280 x bgr8'))
    m = _image_msg(frames[10], t0 + 14 * 40_000_000)
    m.width = m.height = m.step = 0
    m.data = []
    bad.append((m, 'empty image'))
    bad.append((_image_msg(np.zeros((8, 8, 3), np.uint8), t0 + 15 * 40_000_000),
                'image too small'))
    bad.append((_image_msg(frames[11], t0 + 5 * 40_000_000), 'is not after the previous'))
    for msg, text in bad:
        send(pub_img, msg, kp_raw, expect_cloud=False, log=raw_log, text=text)
    broken = intrinsics_to_camera_info(CameraIntrinsics(64, 48, 1.0, 1.0, 1.0, 1.0),
                                       make_header(t0, 'cam_optical'))
    broken.k = [0.0] * 9  # an uncalibrated camera
    send(pub_info, broken, kp_raw, expect_cloud=False, log=raw_log,
         text='ignoring /camera/camera_info')
    stamp = t0 + 20 * 40_000_000
    send(pub_img, _image_msg(frames[12], stamp), kp_raw, log=raw_log)  # still running
    good_stamps.append(stamp)
    square = intrinsics_to_camera_info(CameraIntrinsics(640, 640, 500.0, 500.0, 319.5, 319.5),
                                       make_header(t0, 'cam_optical'))
    pub_info.publish(square)
    processes.wait_for_text(raw_log, 'camera_info: 640x640', 20, raw)
    stamp = t0 + 21 * 40_000_000
    send(pub_img, _image_msg(frames[13], stamp), kp_raw, log=raw_log)
    good_stamps.append(stamp)
    processes.wait_for_text(raw_log, 'another aspect ratio', 10, raw)

    kp_raw = real(kp_raw)
    got = [stamp_to_ns(m.header.stamp) for m in kp_raw]
    assert got == good_stamps                    # one cloud per good image, with its stamp
    peer.spin(10, until=lambda: len(real(info_raw)) >= len(good_stamps))
    info_raw = real(info_raw)
    assert [stamp_to_ns(m.header.stamp) for m in info_raw] == good_stamps
    assert all(m.header.frame_id == 'cam_optical' for m in kp_raw)
    intr = camera_info_to_intrinsics(info_raw[0])  # 1280x720 calibration scaled to 640x360
    assert (intr.width, intr.fx, intr.cx) == pytest.approx((640, 500.0, 319.5))
    last = camera_info_to_intrinsics(info_raw[-1])  # 640x640 does not fit: approximated
    assert last.fx == pytest.approx(CameraIntrinsics.from_fov(640, 360, 60.0).fx)
    kp = np.stack([cloud_to_keypoints(m) for i, m in enumerate(kp_raw) if i != 10])
    assert _confident_body(kp).mean() >= 0.9

    # CompressedImage: JPEG frames, a corrupt JPEG and a depth format.
    for i in range(3):
        msg = bgr_to_compressed_image(frames[i], make_header(t0 + i * 40_000_000, 'c'))
        send(pub_comp, msg, kp_comp, log=comp_log)
    corrupt = bgr_to_compressed_image(frames[3], make_header(t0 + 4 * 40_000_000, 'c'))
    corrupt.data = corrupt.data[:20]
    send(pub_comp, corrupt, kp_comp, expect_cloud=False, log=comp_log,
         text='cannot decode compressed image')
    depth = bgr_to_compressed_image(frames[3], make_header(t0 + 5 * 40_000_000, 'c'))
    depth.format = '16UC1; compressedDepth'
    send(pub_comp, depth, kp_comp, expect_cloud=False, log=comp_log,
         text='unsupported compressed format')
    kp_comp = real(kp_comp)
    assert len(kp_comp) == 3
    assert _confident_body(np.stack([cloud_to_keypoints(m) for m in kp_comp])).all()

    for proc in (raw, comp):
        proc.send_signal(signal.SIGINT)
    for proc, log in ((raw, raw_log), (comp, comp_log)):
        try:
            code = proc.wait(timeout=60)   # two detectors closing on two shared cores
        except subprocess.TimeoutExpired:
            raise AssertionError(f'{log.name}: still running 60 s after SIGINT:\n'
                                 f'{log.read_text()}') from None
        assert code == 0, f'{log.name}: exit code {code} after SIGINT:\n{log.read_text()}'
        assert 'Traceback' not in log.read_text()
        assert SHUTDOWN_HANG not in log.read_text(), log.read_text()   # ended by itself


def test_image_directory_with_corrupt_empty_and_odd_sized_files(processes, ros2_cmd, peer,
                                                                 tmp_path):
    import cv2
    from sensor_msgs.msg import CameraInfo, PointCloud2

    from mocap_core.ros_conversions import camera_info_to_intrinsics, stamp_to_ns
    from mocap_keypoints.sources import VideoSource

    d = tmp_path / 'frames'
    d.mkdir()
    with VideoSource(CLIP) as src:
        for f, _ in zip(src, range(6)):
            cv2.imwrite(str(d / f'frame_{f.index:03d}.jpg'), f.image)
            last = f.image
    cv2.imwrite(str(d / 'frame_006.jpg'), cv2.resize(last, (320, 180)))  # another size
    (d / 'frame_007.jpg').write_bytes(b'\xff\xd8\xff\xe0' + bytes(300))     # corrupt
    (d / 'frame_008.png').write_bytes(b'')                                 # empty
    cv2.imwrite(str(d / 'frame_009.png'), np.zeros((5, 5, 3), np.uint8))    # tiny
    kp_msgs = _collect(peer, PointCloud2, '/mocap/keypoints2d')
    info_msgs = _collect(peer, CameraInfo, '/mocap/camera_info', sensor=False)
    proc, log = _keypoints_node(processes, ros2_cmd, 'keypoints_images', f'path:={d}',
                                'realtime:=false', 'fps:=10.0', 'wait_for_subscribers:=1',
                                'wait_timeout_s:=30.0')
    peer.spin_until_exit(proc, timeout=60)
    text = log.read_text()
    assert proc.returncode == 0, text
    assert len(kp_msgs) == 7, text
    stamps = [stamp_to_ns(m.header.stamp) for m in kp_msgs]
    np.testing.assert_allclose(np.diff(stamps), 1e8, atol=1)
    for name, reason in (('frame_007.jpg', 'not a readable image'),
                         ('frame_008.png', 'empty file'), ('frame_009.png', 'image too small')):
        assert f'{name}: {reason}' in text and 'skipping frame' in text
    assert 'image size changed from 640x360 to 320x180' in text
    assert 'approximating intrinsics from image size 640x360' in text
    assert camera_info_to_intrinsics(info_msgs[-1]).width == 320
    assert '7 frames published, 0 dropped, 3 skipped' in text and 'Traceback' not in text


def test_sources_that_cannot_be_opened_exit_with_clear_errors(processes, ros2_cmd, tmp_path):
    text_file = tmp_path / 'notes.mp4'
    text_file.write_text('not a video\n' * 100)
    empty_dir = tmp_path / 'empty'
    empty_dir.mkdir()
    bad_yaml = tmp_path / 'bad.yaml'
    bad_yaml.write_text('image_width: [')
    cases = {
        'camera_index': (['source:=camera', 'device:=57'],
                         "camera not found or cannot be opened: device '57'"),
        'camera_path': (['source:=camera', 'device:=/dev/video_missing'],
                        'camera device not found: /dev/video_missing'),
        'video_missing': (['source:=video', f'path:={tmp_path / "none.mp4"}'],
                          'video file not found'),
        'video_unreadable': ([f'path:={text_file}'], 'cannot open video file'),
        'images_empty': (['source:=images', f'path:={empty_dir}'], 'no image files'),
        'calibration_missing': ([f'path:={CLIP}', f'calibration_file:={tmp_path / "c.yaml"}'],
                                'calibration file not found'),
        'calibration_bad': ([f'path:={CLIP}', f'calibration_file:={bad_yaml}'],
                            'cannot read calibration YAML'),
    }
    started = {name: _keypoints_node(processes, ros2_cmd, name, *params)
               for name, (params, _) in cases.items()}
    for name, (proc, log) in started.items():
        rc = proc.wait(timeout=60)
        text = log.read_text()
        assert rc == 2, f'{name}: exit code {rc}\n{text}'
        assert 'keypoints: error:' in text and cases[name][1] in text, f'{name}:\n{text}'
        assert 'Traceback' not in text, f'{name}:\n{text}'
