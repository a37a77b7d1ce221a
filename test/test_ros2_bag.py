"""Integration tests of the project's ``ros2`` command: bag play/record/info, topic, run.

The central test plays a bag holding every message type of the pipeline (DESIGN section 2)
through ``ros2 bag play`` into ``ros2 bag record -a`` (two processes talking over DDS) and
checks that the recorded bag has byte-identical payloads, in order, with the same types and QoS
durability. The bag is written with :func:`mocap_core.ros_msgs.serialize`, which pads CDR to a
multiple of 4 bytes as DDS does for every sample it delivers, so live and offline bags agree.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
from pathlib import Path

import numpy as np
import pytest
from mocap_core.bag_io import BagReader, BagWriter
from mocap_core.ros_msgs import deserialize, serialize

TIMEOUT = 60  # generous: a loaded 2-core machine

JOINTS = ['pelvis', 'left_hip', 'left_knee', 'left_ankle', 'left_toe', 'right_hip',
          'right_knee', 'right_ankle', 'right_toe', 'spine', 'neck', 'head', 'left_shoulder',
          'left_elbow', 'left_wrist', 'right_shoulder', 'right_elbow', 'right_wrist']
URDF_TOPIC = '/mocap/skeleton/urdf'
FRAMES = 5
T0 = 1_700_000_000_000_000_000


def _header(frame: int, frame_id: str):
    from std_msgs.msg import Header
    from builtin_interfaces.msg import Time
    ns = T0 + frame * 33_333_333
    return Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=frame_id)


def _cloud(frame: int, names: list[str], values: np.ndarray, frame_id: str):
    from sensor_msgs.msg import PointCloud2, PointField
    values = np.ascontiguousarray(values, dtype=np.float32)
    fields = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
              for i, n in enumerate(names)]
    return PointCloud2(header=_header(frame, frame_id), height=1, width=values.shape[0],
                       fields=fields, is_bigendian=False, point_step=4 * len(names),
                       row_step=4 * len(names) * values.shape[0], data=values.tobytes(),
                       is_dense=True)


def _quat(angle: float, axis: int):
    from geometry_msgs.msg import Quaternion
    q = [0.0, 0.0, 0.0, math.cos(angle / 2)]
    q[axis] = math.sin(angle / 2)
    return Quaternion(x=q[0], y=q[1], z=q[2], w=q[3])


def _camera_info(frame: int):
    from sensor_msgs.msg import CameraInfo
    f = 600.0 + frame
    return CameraInfo(header=_header(frame, 'camera_optical'), height=480, width=640,
                      distortion_model='plumb_bob', d=[0.1, -0.05, 0.001, 0.0, 0.0],
                      k=[f, 0.0, 320.0, 0.0, f, 240.0, 0.0, 0.0, 1.0],
                      r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                      p=[f, 0.0, 320.0, 0.0, 0.0, f, 240.0, 0.0, 0.0, 0.0, 1.0, 0.0])


def build_messages(frame: int) -> dict[str, object]:
    """One message of every pipeline topic for ``frame`` (non-trivial content)."""
    from builtin_interfaces.msg import Duration
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from geometry_msgs.msg import (Point, Pose, PoseStamped, Transform, Twist, Vector3,
                                   Wrench, WrenchStamped)
    from nav_msgs.msg import Odometry, Path
    from sensor_msgs.msg import Image, JointState
    from std_msgs.msg import ColorRGBA, String
    from trajectory_msgs.msg import MultiDOFJointTrajectory, MultiDOFJointTrajectoryPoint
    from visualization_msgs.msg import Marker, MarkerArray

    rng = np.random.default_rng(frame)
    positions = rng.normal(0.0, 0.5, (len(JOINTS), 3)).astype(np.float32)
    kp = np.column_stack([rng.uniform(0, 640, 23), rng.uniform(0, 480, 23),
                          rng.uniform(0, 1, 23)]).astype(np.float32)
    kp[18, 2] = 0.0  # BlazePose has no small toe
    msgs: dict[str, object] = {}
    msgs['/camera/image_raw'] = Image(
        header=_header(frame, 'camera_optical'), height=4, width=6, encoding='rgb8',
        is_bigendian=0, step=18, data=bytes((frame * 7 + i) % 256 for i in range(72)))
    msgs['/camera/camera_info'] = _camera_info(frame)
    msgs['/mocap/camera_info'] = _camera_info(frame)
    msgs['/mocap/keypoints2d'] = _cloud(frame, ['u', 'v', 'confidence'], kp, 'camera_optical')
    if frame in (0, 3):
        msgs[URDF_TOPIC] = String(data=f'<robot name="person_{frame}"><link name="pelvis"/>'
                                       '</robot>')
    transforms = [Transform(translation=Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                            rotation=_quat(0.1 * i + 0.01 * frame, i % 3))
                  for i, p in enumerate(positions)]
    msgs['/mocap/lifter/motion'] = MultiDOFJointTrajectory(
        header=_header(frame, 'camera_optical'), joint_names=JOINTS,
        points=[MultiDOFJointTrajectoryPoint(transforms=transforms,
                                             time_from_start=Duration(sec=0, nanosec=0))])
    msgs['/mocap/lifter/joints3d'] = _cloud(frame, ['x', 'y', 'z'], positions, 'camera_optical')
    msgs['/mocap/physics/joint_states'] = JointState(
        header=_header(frame, 'world'), name=[f'{j}_rx' for j in JOINTS],
        position=[float(x) for x in positions[:, 0]], velocity=[float(x) for x in positions[:, 1]],
        effort=[float(x) * 50.0 for x in positions[:, 2]])
    msgs['/mocap/lifter/contacts'] = JointState(
        header=_header(frame, 'world'),
        name=['left_heel', 'left_toe', 'right_heel', 'right_toe'],
        position=[float(x) for x in rng.uniform(0, 1, 4)])
    for side, sign in (('left', 1.0), ('right', -1.0)):
        msgs[f'/mocap/physics/grf/{side}'] = WrenchStamped(
            header=_header(frame, f'{side}_ankle'),
            wrench=Wrench(force=Vector3(x=sign * 3.0, y=1.5, z=343.0 + frame),
                          torque=Vector3(x=0.2, y=sign * 0.1, z=0.05 * frame)))
    pose = Pose(position=Point(x=0.1 * frame, y=0.02 * frame, z=0.95),
                orientation=_quat(0.05 * frame, 2))
    odom = Odometry(header=_header(frame, 'world'), child_frame_id='pelvis')
    odom.pose.pose = pose
    odom.pose.covariance = [float(i) * 1e-3 for i in range(36)]
    odom.twist.twist = Twist(linear=Vector3(x=3.0, y=0.6, z=0.0),
                             angular=Vector3(x=0.0, y=0.0, z=1.5))
    msgs['/mocap/world/odom'] = odom
    msgs['/mocap/world/path'] = Path(
        header=_header(frame, 'world'),
        poses=[PoseStamped(header=_header(i, 'world'),
                           pose=Pose(position=Point(x=0.1 * i, y=0.02 * i, z=0.95),
                                     orientation=_quat(0.05 * i, 2)))
               for i in range(frame + 1)])
    sticks = Marker(header=_header(frame, 'world'), ns='skeleton', id=0, type=Marker.LINE_LIST,
                    action=Marker.ADD, scale=Vector3(x=0.02, y=0.0, z=0.0),
                    color=ColorRGBA(r=0.2, g=0.6, b=1.0, a=1.0),
                    lifetime=Duration(sec=0, nanosec=100_000_000),
                    points=[Point(x=float(p[0]), y=float(p[1]), z=float(p[2]))
                            for p in positions[:8]])
    msgs['/mocap/world/markers'] = MarkerArray(markers=[
        sticks, Marker(header=_header(frame, 'world'), ns='contacts', id=1, type=Marker.SPHERE,
                       action=Marker.ADD, scale=Vector3(x=0.05, y=0.05, z=0.05),
                       color=ColorRGBA(r=1.0, g=0.0, b=0.0, a=0.8), pose=pose, text='heel')])
    msgs['/diagnostics'] = DiagnosticArray(header=_header(frame, ''), status=[DiagnosticStatus(
        level=DiagnosticStatus.WARN if frame % 2 else DiagnosticStatus.OK,
        name='mocap_lifter: processing', message=f'frame {frame}', hardware_id='cpu',
        values=[KeyValue(key='processing_time_ms', value=f'{12.5 + frame:.1f}'),
                KeyValue(key='model', value='motionet')])])
    return msgs


TOPIC_TYPES = {name: f"{type(m).__module__.split('.')[0]}/msg/{type(m).__name__}"
               for name, m in build_messages(0).items()}


def write_input_bag(path: Path) -> dict[str, list[bytes]]:
    """Write the test bag; return topic -> payloads in order."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    volatile = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE)
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    payloads: dict[str, list[bytes]] = {}
    with BagWriter(path) as bag:
        for frame in range(FRAMES):
            for i, (topic, msg) in enumerate(build_messages(frame).items()):
                qos = latched if topic == URDF_TOPIC else volatile
                if topic not in bag.topics:
                    bag.add_topic(topic, TOPIC_TYPES[topic], qos)
                stamp = T0 + frame * 40_000_000 + i * 100_000
                data = serialize(msg)  # CDR as DDS delivers it (zero-padded to 4 bytes)
                bag.write(topic, stamp, data)
                payloads.setdefault(topic, []).append(data)
    return payloads


@pytest.fixture(scope='module')
def input_bag(tmp_path_factory) -> tuple[Path, dict[str, list[bytes]]]:
    path = tmp_path_factory.mktemp('bags') / 'pipeline_in'
    return path, write_input_bag(path)


def run(cmd: list[str], env: dict[str, str], timeout: float = TIMEOUT, **kwargs):
    return subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout,
                          **kwargs)


def test_bag_has_every_pipeline_type(input_bag):
    path, payloads = input_bag
    expected_types = {
        'sensor_msgs/msg/Image', 'sensor_msgs/msg/CameraInfo', 'sensor_msgs/msg/PointCloud2',
        'std_msgs/msg/String', 'trajectory_msgs/msg/MultiDOFJointTrajectory',
        'sensor_msgs/msg/JointState', 'geometry_msgs/msg/WrenchStamped', 'nav_msgs/msg/Odometry',
        'nav_msgs/msg/Path', 'visualization_msgs/msg/MarkerArray',
        'diagnostic_msgs/msg/DiagnosticArray'}
    with BagReader(path) as bag:
        assert {t.msgtype for t in bag.topics.values()} == expected_types
        assert all(t.count >= 2 for t in bag.topics.values())
        assert bag.message_count == sum(len(v) for v in payloads.values())


def test_play_record_roundtrip_is_byte_identical(input_bag, processes, ros2_cmd, ros_env,
                                                 tmp_path):
    in_path, payloads = input_bag
    out_path = tmp_path / 'recorded'
    recorder, rec_log = processes.start([*ros2_cmd, 'bag', 'record', '-a', '-o', str(out_path)],
                                        'record')
    processes.wait_for_text(rec_log, 'Recording...', TIMEOUT, recorder)

    # the recorder subscribes to each topic once it has discovered the player's publisher (tens
    # of ms, or seconds on a loaded machine): the player waits for that before the first message
    player = run([*ros2_cmd, 'bag', 'play', str(in_path), '--wait-for-subscribers',
                  '--wait-timeout', str(TIMEOUT)], ros_env, timeout=2 * TIMEOUT)
    assert player.returncode == 0, player.stderr
    assert 'Subscribers matched after' in player.stderr

    # every topic subscribed, then give the last messages a moment to arrive
    log = processes.wait_for_text(rec_log, 'Subscribed to topic', 10, recorder,
                                  count=len(payloads))
    subscribed = {line.split("'")[1] for line in log.splitlines() if 'Subscribed to topic' in line}
    assert subscribed == set(payloads)
    recorder.send_signal(signal.SIGINT)
    assert recorder.wait(timeout=TIMEOUT) == 0, rec_log.read_text()
    assert 'Traceback' not in rec_log.read_text()

    with BagReader(out_path) as out, BagReader(in_path) as src:
        assert not out.warnings
        assert set(out.topics) == set(src.topics)
        for name, info in src.topics.items():
            got = out.topics[name]
            assert got.msgtype == info.msgtype, name
            assert got.count == info.count, (name, got.count, info.count)
            durability = {q.durability.name for q in got.qos or []}
            assert durability == ({'TRANSIENT_LOCAL'} if name == URDF_TOPIC else {'VOLATILE'})
        received: dict[str, list[bytes]] = {}
        last = {}
        for msg in out.messages():
            received.setdefault(msg.topic, []).append(msg.data)
            assert msg.timestamp_ns >= last.get(msg.topic, 0)
            last[msg.topic] = msg.timestamp_ns
        for topic, sent in payloads.items():
            assert received.get(topic) == sent, f'payloads of {topic} differ'


def test_bag_info_lists_every_topic(input_bag, ros2_cmd, ros_env):
    path, payloads = input_bag
    result = run([*ros2_cmd, 'bag', 'info', str(path)], ros_env)
    assert result.returncode == 0, result.stderr
    out = result.stdout
    assert 'Storage id:        mcap' in out
    assert f'Messages:          {sum(len(v) for v in payloads.values())}' in out
    for topic, data in payloads.items():
        assert (f'Topic: {topic} | Type: {TOPIC_TYPES[topic]} | Count: {len(data)} | '
                'Serialization Format: cdr') in out
    single = run([*ros2_cmd, 'bag', 'info', str(path / 'pipeline_in.mcap')], ros_env)
    assert single.returncode == 0, single.stderr
    assert f'Topic: {URDF_TOPIC} | Type: std_msgs/msg/String | Count: 2' in single.stdout


@pytest.mark.parametrize('args, message', [
    (['bag', 'play', '{tmp}/no_such_bag'], "bag '{tmp}/no_such_bag' does not exist"),
    (['bag', 'info', '{tmp}/garbage.mcap'], 'is not an MCAP file'),
    (['bag', 'play', '{tmp}/garbage.mcap'], 'is not an MCAP file'),
    (['bag', 'play', '{bag}', '--topics', '/nope'], "'/nope' not in bag"),
    (['bag', 'play', '{bag}', '--rate', '0'], 'rate must be > 0'),
    (['bag', 'play', '{bag}', '--wait-timeout', '3'],
     '--wait-timeout needs --wait-for-subscribers'),
    (['bag', 'play', '{bag}', '--wait-for-subscribers', '--wait-timeout', '-1'],
     'wait timeout must be >= 0'),
    (['bag', 'play', '{bag}', '--qos-depth', '0'], 'qos depth must be >= 1'),
    (['bag', 'record', '-o', '{tmp}/out'], 'no topics to record'),
    (['bag', 'record', '-a', '-o', '{bag}'], 'already exists'),
    (['run', 'no_such_package_xyz', 'node'], "Package 'no_such_package_xyz' not found"),
    (['run', 'mocap_core', 'no_such_executable'], 'No executable found'),
])
def test_bad_input_gives_one_clear_line(input_bag, ros2_cmd, ros_env, tmp_path, args, message):
    (tmp_path / 'garbage.mcap').write_bytes(b'this is not a bag\n' * 10)
    fill = {'tmp': str(tmp_path), 'bag': str(input_bag[0])}
    result = run([*ros2_cmd, *[a.format(**fill) for a in args]], ros_env)
    assert result.returncode != 0
    assert message.format(**fill) in result.stderr
    assert 'Traceback' not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr


@pytest.mark.parametrize('args', [[], ['{bag}', '--wait-for-subscribers', '0'],
                                  ['--wait-for-subscribers', '{bag}']])
def test_wrong_arguments_exit_2_with_usage(input_bag, ros2_cmd, ros_env, args):
    result = run([*ros2_cmd, 'bag', 'play', *[a.format(bag=input_bag[0]) for a in args]],
                 ros_env)
    assert result.returncode == 2
    assert 'usage: ros2 bag play' in result.stderr
    assert 'Traceback' not in result.stderr
    if '--wait-for-subscribers' in args:
        assert 'argument --wait-for-subscribers:' in result.stderr


def test_play_waits_for_subscribers_then_loops(input_bag, processes, ros2_cmd, peer):
    """With --wait-for-subscribers the first message waits for a subscriber that comes late
    (volatile: without the wait it would miss the first round), and --loop goes on without
    waiting again."""
    from nav_msgs.msg import Odometry

    path, payloads = input_bag
    topic = '/mocap/world/odom'
    player, log = processes.start([*ros2_cmd, 'bag', 'play', str(path), '--topics', topic,
                                   '--loop', '--wait-for-subscribers', '--wait-timeout',
                                   str(TIMEOUT)], 'play')
    processes.wait_for_text(log, f'Waiting for 1 matched subscription on each of 1 topic: '
                                 f'{topic}', TIMEOUT, player)
    got = peer.subscribe(Odometry, topic)
    rounds = 3
    assert peer.spin(TIMEOUT, until=lambda: len(got) >= rounds * FRAMES, proc=player), \
        (len(got), log.read_text())
    sent = [deserialize(data, Odometry) for data in payloads[topic]]
    assert got[:rounds * FRAMES] == sent * rounds   # nothing lost, in order
    assert 'Subscribers matched after' in log.read_text()
    player.send_signal(signal.SIGINT)
    assert player.wait(timeout=TIMEOUT) == 0, log.read_text()


def test_play_waits_for_n_subscribers_and_times_out(input_bag, processes, ros2_cmd, peer):
    """--wait-for-subscribers N counts the matched subscriptions of each topic: one is not
    enough for N=2, nothing is played, and --wait-timeout ends the wait with exit status 1,
    naming what is missing."""
    from nav_msgs.msg import Odometry

    path, _ = input_bag
    topic = '/mocap/world/odom'
    player, log = processes.start([*ros2_cmd, 'bag', 'play', str(path), '--topics', topic,
                                   '--wait-for-subscribers', '2', '--wait-timeout', '8'], 'play')
    processes.wait_for_text(log, 'Waiting for 2 matched subscriptions on each of 1 topic',
                            TIMEOUT, player)
    got = peer.subscribe(Odometry, topic)
    assert peer.wait_for_publishers([topic], timeout=TIMEOUT, proc=player), log.read_text()
    peer.spin_until_exit(player, TIMEOUT)
    text = log.read_text()
    assert player.returncode == 1, text
    assert text.strip().splitlines()[-1] == (
        f'ros2 bag play: error: no subscribers after 8 s (--wait-timeout): {topic} (1 of 2)')
    assert got == [] and 'Traceback' not in text


def test_play_qos_depth_sets_the_publishers_history(input_bag):
    """--qos-depth N: keep-last N (at least), reliable and durability as recorded."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy

    from mocap_core.cli.ros2 import build_parser
    from mocap_core.cli.ros2.bag_play import DEFAULT_DEPTH, publisher_qos

    with BagReader(input_bag[0]) as bag:
        latched, volatile = bag.topics[URDF_TOPIC].qos, bag.topics['/mocap/world/odom'].qos
    for option, expected in (([], DEFAULT_DEPTH), (['--qos-depth', '700'], 700),
                             (['--qos-depth', '3'], 10)):     # the recorded depth is 10
        args = build_parser().parse_args(['bag', 'play', 'my_bag', *option])
        qos = publisher_qos(volatile, args.qos_depth)
        assert (qos.history, qos.depth) == (HistoryPolicy.KEEP_LAST, expected), option
        assert qos.reliability == ReliabilityPolicy.RELIABLE
        assert qos.durability == DurabilityPolicy.VOLATILE
    assert publisher_qos(latched, 700).durability == DurabilityPolicy.TRANSIENT_LOCAL


def test_run_execs_executable_with_arguments(ros2_cmd, ros_env, tmp_path):
    prefix = tmp_path / 'prefix'
    (prefix / 'share/ament_index/resource_index/packages').mkdir(parents=True)
    (prefix / 'share/ament_index/resource_index/packages/fake_pkg').write_text('')
    exe = prefix / 'lib/fake_pkg/talker'
    exe.parent.mkdir(parents=True)
    exe.write_text('#!/bin/sh\necho "pid=$$ args=$*"\n')
    exe.chmod(0o755)
    env = dict(ros_env)
    env['AMENT_PREFIX_PATH'] = os.pathsep.join([str(prefix), env.get('AMENT_PREFIX_PATH', '')])
    proc = subprocess.Popen([*ros2_cmd, 'run', 'fake_pkg', 'talker', 'a', '--ros-args', '-r',
                             'x:=y'], env=env, stdout=subprocess.PIPE, text=True)
    out, _ = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 0
    assert out.strip() == f'pid={proc.pid} args=a --ros-args -r x:=y'  # exec: same process


def test_defers_to_a_real_ros2_on_path(ros2_cmd, ros_env, tmp_path):
    fake = tmp_path / 'realbin' / 'ros2'
    fake.parent.mkdir()
    fake.write_text('#!/bin/sh\necho "real ros2: $*"\n')
    fake.chmod(0o755)
    env = dict(ros_env, PATH=f"{fake.parent}{os.pathsep}{ros_env['PATH']}")
    env.pop('MOCAP_ROS2_NO_DEFER')
    result = run([*ros2_cmd, 'topic', 'list'], env)
    assert result.stdout.strip() == 'real ros2: topic list'
    result = run([*ros2_cmd, 'bag', 'play', 'my_bag', '--wait-for-all-acked', '10'], env)
    assert result.stdout.strip() == 'real ros2: bag play my_bag --wait-for-all-acked 10'
    # an option only the built-in player has: it plays, and says why
    result = run([*ros2_cmd, 'bag', 'play', str(tmp_path / 'nothing'),
                  '--wait-for-subscribers=2'], env)
    assert 'real ros2' not in result.stdout
    assert ("--wait-for-subscribers is an option of this project's 'ros2 bag play' only"
            in result.stderr)
    assert 'does not exist' in result.stderr and result.returncode == 1
    env['MOCAP_ROS2_NO_DEFER'] = '1'
    result = run([*ros2_cmd, 'bag', 'info', str(tmp_path / 'nothing')], env)
    assert 'real ros2' not in result.stdout


def test_options_of_the_builtin_player_only_are_recognised():
    from mocap_core.cli.ros2 import own_play_option

    for option in ('--wait-for-subscribers', '--wait-timeout', '--qos-depth'):
        assert own_play_option(['bag', 'play', 'my_bag', option, '3']) == option
        assert own_play_option(['bag', 'play', 'my_bag', f'{option}=3']) == option
        assert own_play_option(['bag', 'record', option, '3']) is None
    assert own_play_option(['bag', 'play', 'my_bag', '--rate', '2', '--loop']) is None


def test_topic_echo_list_hz_while_playing(input_bag, processes, ros2_cmd, ros_env):
    path, payloads = input_bag
    player, play_log = processes.start(
        [*ros2_cmd, 'bag', 'play', str(path), '--loop', '--rate', '2'], 'play')
    processes.wait_for_text(play_log, 'Playing', TIMEOUT, player)
    hz, hz_log = processes.start([*ros2_cmd, 'topic', 'hz', '/mocap/world/odom'], 'hz')

    echo = run([*ros2_cmd, 'topic', 'echo', '--once', '/mocap/physics/grf/left'], ros_env)
    assert echo.returncode == 0, echo.stderr
    lines = echo.stdout.splitlines()
    assert lines[-1] == '---'
    assert '  frame_id: left_ankle' in lines
    assert 'wrench:' in lines and '    y: 1.5' in lines

    latched = run([*ros2_cmd, 'topic', 'echo', '--once', URDF_TOPIC, 'std_msgs/msg/String'],
                  ros_env)
    assert latched.returncode == 0, latched.stderr
    assert latched.stdout.startswith('data: <robot name="person_')

    listed = run([*ros2_cmd, 'topic', 'list', '-t'], ros_env)
    assert listed.returncode == 0, listed.stderr
    assert '/mocap/world/odom [nav_msgs/msg/Odometry]' in listed.stdout.splitlines()

    processes.wait_for_text(hz_log, 'average rate:', TIMEOUT, hz)
    hz.send_signal(signal.SIGINT)
    assert hz.wait(timeout=TIMEOUT) == 0
    assert '\tmin: ' in hz_log.read_text()

    player.send_signal(signal.SIGINT)  # Ctrl-C ends the player cleanly
    assert player.wait(timeout=TIMEOUT) == 0
    assert 'Traceback' not in play_log.read_text()
