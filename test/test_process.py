"""``mocap process``: the whole pipeline offline in one process (the node classes wired by
InProcessGraph) on the committed bags and the shipped video; accuracy against ground truth,
plausibility, determinism and bad input."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
GT_BAG = ROOT / 'bags' / 'gt_cmu_walk_12_02'
OPENPOSE_BAG = ROOT / 'bags' / 'openpose_seq1'
VIDEO = ROOT / 'data' / 'video_example' / 'taiji_640x360.mp4'

#: Per-frame outputs of docs/design.md §2 (one message per input frame, same stamp).
PER_FRAME = [f'/mocap/{stage}/{leaf}' for stage in ('lifter', 'physics', 'world')
             for leaf in ('motion', 'joints3d', 'joint_states', 'markers')] + [
    '/mocap/lifter/contacts', '/mocap/physics/grf/left', '/mocap/physics/grf/right',
    '/mocap/world/odom', '/mocap/world/path']


def _mocap(*args: str, env=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'mocap_core.cli.mocap', *map(str, args)],
                          capture_output=True, text=True, timeout=600, env=env)


def _stamps(bag: Path, topic: str) -> list:
    from mocap_core.bag_io import BagReader, deserialize
    from mocap_core.ros_conversions import stamp_to_ns

    out = []
    with BagReader(bag) as reader:
        for m in reader.messages(topics=[topic]):
            msg = deserialize(m.data, m.msgtype)
            if hasattr(msg, 'markers'):
                out.append(stamp_to_ns(msg.markers[0].header.stamp))
            else:
                out.append(stamp_to_ns(msg.header.stamp))
    return out


# --- planning and options (no ROS) ---------------------------------------------------------

def test_plan_starts_from_the_earliest_stage_in_the_input():
    from mocap_core.cli.process import ProcessError, plan_for

    kp = {'/mocap/keypoints2d': 'sensor_msgs/msg/PointCloud2',
          '/mocap/camera_info': 'sensor_msgs/msg/CameraInfo',
          '/mocap/lifter/motion': 'trajectory_msgs/msg/MultiDOFJointTrajectory',
          '/mocap/lifter/contacts': 'sensor_msgs/msg/JointState',
          '/mocap/groundtruth/motion': 'trajectory_msgs/msg/MultiDOFJointTrajectory'}
    plan = plan_for(kp)
    assert plan.start == 'keypoints' and plan.nodes == ['lifter', 'physics', 'gmr']
    assert plan.feed_topics == ['/mocap/keypoints2d', '/mocap/camera_info']
    # the bag's lifter output is re-computed, so its copy is dropped; ground truth is kept
    assert plan.dropped_topics == ['/mocap/lifter/contacts', '/mocap/lifter/motion']
    plan = plan_for(kp, start='lifter')
    assert plan.nodes == ['physics', 'gmr'] and plan.dropped_topics == []
    assert plan.feed_topics == ['/mocap/lifter/motion', '/mocap/lifter/contacts']
    images = {'/cam/a': 'sensor_msgs/msg/Image', '/cam/b': 'sensor_msgs/msg/CompressedImage'}
    with pytest.raises(ProcessError, match='several image topics'):
        plan_for(images)
    plan = plan_for(images, image_topic='/cam/b')
    assert plan.start == 'images' and plan.image_topic == '/cam/b' and len(plan.nodes) == 4
    with pytest.raises(ProcessError, match='nothing to start from'):
        plan_for({'/mocap/camera_info': 'sensor_msgs/msg/CameraInfo'})
    with pytest.raises(ProcessError, match='lacks its topic'):
        plan_for(kp, start='physics')
    # from the physics output: the world stage also reads the floor, the lifter's contacts
    # (its foot planting) and unsmoothed motion (its network's pose), one person's and
    # everyone's
    phys = dict(kp, **{'/mocap/physics/motion': 'trajectory_msgs/msg/MultiDOFJointTrajectory',
                       '/mocap/physics/floor': 'geometry_msgs/msg/TransformStamped',
                       '/mocap/physics/bodies/motion':
                           'trajectory_msgs/msg/MultiDOFJointTrajectory',
                       '/mocap/lifter/bodies/contacts': 'sensor_msgs/msg/JointState',
                       '/mocap/lifter/unsmoothed_motion':
                           'trajectory_msgs/msg/MultiDOFJointTrajectory',
                       '/mocap/camera/motion': 'nav_msgs/msg/Odometry'})
    plan = plan_for(phys, start='physics')
    assert plan.nodes == ['gmr']
    assert plan.feed_topics == ['/mocap/physics/motion', '/mocap/physics/bodies/motion',
                                '/mocap/physics/floor', '/mocap/lifter/contacts',
                                '/mocap/lifter/bodies/contacts',
                                '/mocap/lifter/unsmoothed_motion', '/mocap/camera/motion']
    assert plan_for(phys, start='lifter').feed_topics == [
        '/mocap/lifter/motion', '/mocap/lifter/contacts', '/mocap/lifter/bodies/contacts',
        '/mocap/lifter/unsmoothed_motion', '/mocap/camera/motion']
    # everyone's motion without everyone's contacts: one person's, with their contacts
    partial = dict(phys)
    del partial['/mocap/lifter/bodies/contacts']
    assert plan_for(partial, start='physics').feed_topics == [
        '/mocap/physics/motion', '/mocap/physics/floor', '/mocap/lifter/contacts',
        '/mocap/lifter/unsmoothed_motion', '/mocap/camera/motion']


def test_params_parse_node_name_value():
    from mocap_core.cli.process import ProcessError, parse_params

    p = parse_params(['lifter.mode=causal', 'physics.substeps=4', 'gmr.static_camera=true'])
    assert p['lifter'] == {'mode': 'causal'} and p['physics'] == {'substeps': 4}
    assert p['gmr'] == {'static_camera': True}
    for bad in ('mode=causal', 'nosuch.x=1', 'lifter.mode'):
        with pytest.raises(ProcessError):
            parse_params([bad])


def test_graph_delivers_in_order_records_and_survives_a_failing_callback():
    import rclpy
    from std_msgs.msg import String

    from mocap_core.inprocess import DeliveryError, InProcessGraph

    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    try:
        a = rclpy.create_node('a', context=context)
        b = rclpy.create_node('b', context=context)
        pub_a = a.create_publisher(String, '/x', 10)
        seen = []
        pub_b = b.create_publisher(String, '/y', 10)

        def on_x(msg):
            seen.append(('b/x', msg.data))
            pub_b.publish(String(data=msg.data + '!'))      # re-entrant: queued
            seen.append(('b/x done', msg.data))

        b.create_subscription(String, '/x', on_x, 10)
        a.create_subscription(String, '/y', lambda m: seen.append(('a/y', m.data)), 10)
        recorded = []
        errors = []
        graph = InProcessGraph(record=lambda t, m, q: recorded.append((t, m.data)),
                               on_error=lambda n, t, e: errors.append((n, t, str(e))))
        graph.add(a)
        graph.add(b)
        pub_a.publish(String(data='1'))
        assert seen == [('b/x', '1'), ('b/x done', '1'), ('a/y', '1!')]
        assert recorded == [('/x', '1'), ('/y', '1!')]
        assert graph.subscribers('/x') == ['b']

        def boom(msg):
            raise RuntimeError('broken')

        b.create_subscription(String, '/z', boom, 10)
        graph2 = InProcessGraph()
        graph2.add(b)
        with pytest.raises(DeliveryError, match='b failed on /z'):
            graph2.publish('/z', String(data='x'))
        graph3 = InProcessGraph(on_error=lambda n, t, e: errors.append((n, t, str(e))))
        graph3.add(b)
        graph3.publish('/z', String(data='x'))
        assert errors == [('b', '/z', 'broken')]
    finally:
        context.try_shutdown()


def test_graph_hands_raw_subscriptions_the_bytes():
    """A raw subscription (``raw=True``) receives the CDR bytes, of a message published
    serialised (not deserialised on the way) or as an object; the others the message."""
    import rclpy
    from rclpy.serialization import deserialize_message, serialize_message
    from std_msgs.msg import String

    from mocap_core.inprocess import InProcessGraph, SerializedMessage

    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    try:
        node = rclpy.create_node('n', context=context)
        raw_seen, seen = [], []
        node.create_subscription(String, '/x', raw_seen.append, 10, raw=True)
        node.create_subscription(String, '/x', lambda m: seen.append(m.data), 10)
        graph = InProcessGraph()
        graph.add(node)
        ser = SerializedMessage(serialize_message(String(data='a')), String)
        graph.publish('/x', ser)
        assert raw_seen == [ser.data] and seen == ['a']
        graph2 = InProcessGraph()
        node2 = rclpy.create_node('m', context=context)
        node2.create_subscription(String, '/y', raw_seen.append, 10, raw=True)
        graph2.add(node2)
        graph2.publish('/y', String(data='b'))
        assert deserialize_message(raw_seen[-1], String).data == 'b'
        only_raw = InProcessGraph()
        only_raw.add(node2)
        ser2 = SerializedMessage(serialize_message(String(data='c')), String)
        only_raw.publish('/y', ser2)
        assert ser2._message is None               # nobody needed it decoded
    finally:
        context.try_shutdown()


# --- whole runs ----------------------------------------------------------------------------

@pytest.fixture(scope='module')
def gt_run(tmp_path_factory):
    out = tmp_path_factory.mktemp('process') / 'gt_out'
    res = _mocap('process', GT_BAG, '-o', out, '--no-progress')
    assert res.returncode == 0, res.stdout + res.stderr
    return out, res


def test_process_ground_truth_bag_every_topic_same_stamps_accurate(gt_run):
    from mocap_core.bag_io import BagReader
    from mocap_core.run_report import accuracy, load_run, plausibility

    out, res = gt_run
    kp_stamps = _stamps(GT_BAG, '/mocap/keypoints2d')
    with BagReader(out) as reader:
        topics = reader.topics
    # the input topics are kept, every output topic of docs/design.md §2 is there
    for t in ['/mocap/keypoints2d', '/mocap/camera_info', '/mocap/groundtruth/motion',
              '/mocap/skeleton/urdf', '/diagnostics', '/mocap/physics/com'] + PER_FRAME:
        assert t in topics, (t, sorted(topics))
    urdf_qos = topics['/mocap/skeleton/urdf'].qos
    assert urdf_qos and 'transient' in str(urdf_qos[0].durability).lower()
    for t in PER_FRAME:
        assert _stamps(out, t) == kp_stamps, t       # one output per input frame, same stamp
    run = load_run(out)
    for stage in ('lifter', 'physics', 'world'):
        assert np.all(np.isfinite(run.stages[stage].joints)), stage
    acc = accuracy(run)
    # the default windowed MotioNet (stage 3, chosen on rendered people through the real
    # detector: test/test_lifter_rendered.py) on this bag's synthetic keypoints: 61.3 / 35.6
    # mm, physics 70.7 / 36.0 mm (2026-11-26). The previous default, trained on this bag's
    # own keypoint synthesizer, reached about 45 mm here with a bound of 60; the bounds follow
    # the new default's figures with 10 % to spare
    assert acc['lifter']['mpjpe_mm'] < 68 and acc['lifter']['pa_mpjpe_mm'] < 40, acc
    assert acc['lifter']['contact_accuracy'] > 0.85, acc
    assert acc['physics']['mpjpe_mm'] < 78 and acc['physics']['pa_mpjpe_mm'] < 40, acc
    pl = plausibility(run)
    assert pl['physics']['penetration_mm'] < 5.0, pl
    assert pl['physics']['skating_mm'] < pl['lifter']['skating_mm'], pl
    for stage in ('lifter', 'physics', 'world'):
        assert pl[stage]['bone_spread_final_mm'] < 1e-3, (stage, pl)
    assert pl['world']['root_path_m'] > 2.0, pl           # a 5.6 s walk goes somewhere
    # the person's stature from the lifted skeleton: a person's, and the same in every stage
    assert 1.4 < pl['lifter']['stature_m'] < 2.1, pl
    assert pl['physics']['stature_m'] == pytest.approx(pl['lifter']['stature_m'], abs=1e-3)
    assert set(run.diagnostics) >= {'lifter: lifter', 'physics: physics', 'gmr: gmr'}
    # the final status is refreshed although timers do not run offline
    assert 'DoF' in run.diagnostics['physics: physics']['model'], run.diagnostics
    assert run.diagnostics['physics: physics']['dynamics'] == 'whole_body', run.diagnostics
    # a camera that stands still: the floor window never restarts (docs/physics.md)
    assert run.diagnostics['physics: physics']['floor_window_restarts'] == '0', \
        run.diagnostics['physics: physics']
    # offline: 16 frames per pass over the context window (live: the streaming encoder)
    assert run.diagnostics['lifter: lifter']['inference'].startswith('window pass'), \
        run.diagnostics
    assert 'processed 168 frames' in res.stdout


def test_process_is_deterministic(gt_run, tmp_path):
    """Two runs give the same bag, byte for byte (/diagnostics aside: it holds timings):
    every output is serialised by mocap_core.cdr, whose padding is zero (rclpy's serialiser
    leaves whatever was in memory there)."""
    from mocap_core.bag_io import BagReader
    from mocap_core.run_report import load_run

    out, _ = gt_run
    again = tmp_path / 'again'
    res = _mocap('process', GT_BAG, '-o', again, '--no-progress')
    assert res.returncode == 0, res.stderr
    a, b = load_run(out), load_run(again)
    for stage in ('lifter', 'physics', 'world'):
        np.testing.assert_array_equal(a.stages[stage].joints, b.stages[stage].joints)
    np.testing.assert_array_equal(a.grf, b.grf)

    def messages(bag):
        with BagReader(bag) as reader:
            return [(m.topic, m.timestamp_ns, bytes(m.data)) for m in reader.messages()
                    if m.topic != '/diagnostics']
    ma, mb = messages(out), messages(again)
    assert len(ma) == len(mb) and len(ma) > 1000
    differ = sorted({x[0] for x, y in zip(ma, mb) if x != y})
    assert not differ, differ


def test_process_output_from_arrays_equals_the_built_messages(gt_run, tmp_path):
    """The stages serialise their per-frame outputs straight from arrays (mocap_core.cdr).
    The same run with every encoder replaced by the rclpy message it stands for (built,
    then serialised, as before issue 20) gives the same bag: every topic, stamp and message
    content (/diagnostics aside: it holds timings)."""
    from mocap_core import cdr
    from mocap_core.bag_io import BagReader, deserialize
    from mocap_core.cli.process import process

    built = tmp_path / 'built'
    encoder = cdr.pose_to_motion
    with cdr.built_messages():
        assert cdr.pose_to_motion is not encoder
        process(GT_BAG, built, progress=False, log=lambda *a: None, log_level='error')

    def messages(bag):
        out = {}
        with BagReader(bag) as reader:
            for m in reader.messages():
                if m.topic != '/diagnostics':
                    out.setdefault(m.topic, []).append((m.timestamp_ns, m.msgtype, m.data))
        return out
    a, b = messages(gt_run[0]), messages(built)
    assert sorted(a) == sorted(b)
    for topic in ('/tf', '/mocap/physics/markers', '/mocap/lifter/bodies/motion',
                  '/mocap/world/path', '/humans/bodies/body_1/world/odom'):
        assert topic in a, topic
    for topic in a:
        assert len(a[topic]) == len(b[topic]), topic
        for (ta, msgtype, da), (tb, _, db) in zip(a[topic], b[topic]):
            assert ta == tb, topic
            assert deserialize(da, msgtype) == deserialize(db, msgtype), topic


def test_process_writes_only_the_topics_asked_for(gt_run, tmp_path):
    """--topics: the bag holds the matching topics only, their messages the same as in a
    full run (what is not asked for is not built, but the stages' results do not change);
    a pattern that matches nothing is reported as a problem (exit status 1)."""
    from mocap_core.bag_io import BagReader

    out = tmp_path / 'world_only'
    res = _mocap('process', GT_BAG, '-o', out, '--no-progress', '--topics', '/mocap/world/*',
                 '/tf', '/no/such*')
    assert res.returncode == 1, res.stdout + res.stderr
    assert '--topics /no/such* matched no topic' in res.stdout, res.stdout

    def messages(bag):
        with BagReader(bag) as reader:
            return {t: [(m.timestamp_ns, m.data) for m in reader.messages(topics=[t])]
                    for t in reader.topics}
    got, full = messages(out), messages(gt_run[0])
    assert set(got) == {t for t in full if t.startswith('/mocap/world/') or t == '/tf'}, \
        sorted(got)
    assert '/mocap/world/motion' in got and '/mocap/world/bodies/markers' in got
    for topic in ('/mocap/world/motion', '/mocap/world/joints3d', '/tf'):
        assert got[topic] == full[topic], topic       # serialised from arrays: same bytes


def test_process_starts_from_lifter_motion(gt_run, tmp_path):
    """A bag holding the lifter's output (e.g. a recording) runs physics and GMR only."""
    from mocap_core.bag_io import BagReader
    from mocap_core.run_report import load_run

    out, _ = gt_run
    res = _mocap('process', out, '-o', tmp_path / 'from_lifter', '--start', 'lifter',
                 '--no-progress')
    assert res.returncode == 0, res.stderr
    assert 'start: lifter' in res.stdout and 'nodes: physics, gmr' in res.stdout
    first, second = load_run(out), load_run(tmp_path / 'from_lifter')
    # the lifter output is the input copy; physics recomputed from it gives the same result
    np.testing.assert_array_equal(first.stages['lifter'].joints, second.stages['lifter'].joints)
    np.testing.assert_allclose(first.stages['physics'].joints, second.stages['physics'].joints,
                               atol=1e-9)
    with BagReader(tmp_path / 'from_lifter') as reader:
        assert reader.topics['/mocap/physics/motion'].count == 168


def test_process_real_openpose_bag_is_plausible(tmp_path):
    from mocap_core.run_report import load_run, plausibility

    out = tmp_path / 'op'
    # 81 frames: the skeleton is estimated over the first 30 (default 90) and then held
    res = _mocap('process', OPENPOSE_BAG, '-o', out, '--no-progress', '--param',
                 'lifter.skeleton_frames=30')
    assert res.returncode == 0, res.stderr
    run = load_run(out)
    pl = plausibility(run)
    for stage in ('lifter', 'physics', 'world'):
        assert pl[stage]['frames'] == 81
        assert np.all(np.isfinite(run.stages[stage].joints))
        assert pl[stage]['skeleton_final_from_frame'] <= 30, pl
        assert pl[stage]['bone_spread_final_mm'] < 1e-3, pl
    assert pl['physics']['penetration_mm'] < 5.0, pl


def test_process_video_file(tmp_path):
    import cv2

    from mocap_core.run_report import load_run

    cap = cv2.VideoCapture(str(VIDEO))
    frames = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    cap.release()
    out = tmp_path / 'video_out'
    res = _mocap('process', VIDEO, '-o', out, '--no-progress')
    assert res.returncode == 0, res.stdout + res.stderr
    run = load_run(out)
    assert len(run.keypoint_stamps) == frames             # no frame dropped
    # a person in every frame from the third on: a new person gets an id (and is published)
    # when seen in 3 consecutive frames (id_after_frames with max_persons 4)
    seen = (run.keypoints[:, :, 2] > 0.5).sum(axis=1)
    assert seen[:2].max() == 0 and seen[2:].min() > 8
    for stage in ('lifter', 'physics', 'world'):
        np.testing.assert_array_equal(run.stages[stage].stamps, run.keypoint_stamps[2:])
    # offline the mirror check reads every frame (process.OFFLINE_DEFAULTS); this person
    # faces the camera and is left as the detector labelled her
    diag = next(v for k, v in run.diagnostics.items() if k.startswith('keypoints'))
    assert diag['mirror_check'] == 'on', diag
    assert diag['mirror_frames_read'] == f'{frames} of {frames}', diag
    assert diag['mirror_exchanged'].startswith('0 of '), diag

    # the demo's rendering of the run: report, plots, side-by-side video of every frame
    report = tmp_path / 'report'
    res = _mocap('report', out, '-o', report, '--video', VIDEO, '--title', 'test run')
    assert res.returncode == 0, res.stdout + res.stderr
    for name in ('report.md', 'report.json', 'pipeline.mp4', 'pipeline_frames.png',
                 'root_trajectory.png', 'grf.png', 'torques.png'):
        assert (report / name).stat().st_size > 1000, name
    cap = cv2.VideoCapture(str(report / 'pipeline.mp4'))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == frames
    ok, img = cap.read()
    cap.release()
    assert ok and img.shape[1] > img.shape[0] * 2          # video frame + two skeleton views
    text = (report / 'report.md').read_text()
    assert '# test run' in text and '| physics |' in text and 'keypoints: keypoints' in text


def test_process_video_detects_beside_the_later_stages_with_the_same_output(tmp_path):
    """By default (keypoint parameter ``finish_thread``) a video's next frame is detected
    while the last one is finished and published through the later stages in a second
    thread. The output is that of one frame after the other: the same keypoints, camera
    motion and frames, in the same order, every stage's joints equal to rounding (two runs
    one frame after the other differ by 1e-6 m too: the video's stamps start at the wall
    clock). The frames recorded with ``--record-images`` are there, with their keypoints'
    stamps."""
    from mocap_core.bag_io import BagReader, deserialize
    from mocap_core.run_report import load_run

    def camera_motion(bag):
        out = []
        with BagReader(bag) as reader:
            for m in reader.messages(topics=['/mocap/camera/motion']):
                o = deserialize(m.data, m.msgtype).pose.pose.orientation
                out.append((o.x, o.y, o.z, o.w))
        return np.array(out)

    split, one = tmp_path / 'split', tmp_path / 'one'
    res = _mocap('process', VIDEO, '-o', split, '--no-progress', '--record-images')
    assert res.returncode == 0, res.stdout + res.stderr
    res = _mocap('process', VIDEO, '-o', one, '--no-progress',
                 '--param', 'keypoints.finish_thread=false')
    assert res.returncode == 0, res.stdout + res.stderr
    a, b = load_run(split), load_run(one)
    # the offline mirror check can be turned off like any default
    off = tmp_path / 'no_mirror'
    res = _mocap('process', VIDEO, '-o', off, '--no-progress', '--topics', '/diagnostics',
                 '--param', 'keypoints.mirror_check=false')
    assert res.returncode == 0, res.stdout + res.stderr
    diag = next(v for k, v in load_run(off).diagnostics.items() if k.startswith('keypoints'))
    assert diag['mirror_check'].startswith('off'), diag
    assert len(a.keypoint_stamps) == len(b.keypoint_stamps) > 90
    np.testing.assert_array_equal(np.diff(a.keypoint_stamps), np.diff(b.keypoint_stamps))
    np.testing.assert_array_equal(a.keypoints, b.keypoints)
    np.testing.assert_array_equal(camera_motion(split), camera_motion(one))
    assert len(camera_motion(split)) == len(a.keypoint_stamps)
    for stage in ('lifter', 'physics', 'world'):
        assert len(a.stages[stage].joints) == len(b.stages[stage].joints) > 90
        np.testing.assert_allclose(a.stages[stage].joints, b.stages[stage].joints, atol=1e-5)
    assert _stamps(split, '/camera/image_raw') == list(a.keypoint_stamps)


# --- bad input -----------------------------------------------------------------------------

def test_process_bad_inputs_give_one_clear_line(tmp_path):
    res = _mocap('process', tmp_path / 'missing', '-o', tmp_path / 'o1')
    assert res.returncode == 2 and 'does not exist' in res.stderr
    junk = tmp_path / 'junk.mcap'
    junk.write_bytes(b'not a bag at all' * 10)
    res = _mocap('process', junk, '-o', tmp_path / 'o2')
    assert res.returncode == 2 and 'cannot read the input bag' in res.stderr, res.stderr
    assert 'Traceback' not in res.stderr
    res = _mocap('process', GT_BAG, '-o', tmp_path / 'o3', '--param', 'lifter.mode=sideways')
    assert res.returncode == 2 and 'cannot start the lifter node' in res.stderr, res.stderr
    res = _mocap('process', VIDEO, '-o', tmp_path / 'o5', '--param',
                 'keypoints.camera_motion_rotation=sideways')
    assert res.returncode == 2 and 'cannot start the keypoints node' in res.stderr and \
        'camera_motion_rotation must be plane or homography' in res.stderr, res.stderr
    res = _mocap('process', GT_BAG, '-o', tmp_path / 'o4', '--start', 'physics')
    assert res.returncode == 2 and 'lacks its topic' in res.stderr
    # a misspelt parameter is refused (rclpy would drop it and run the default)
    res = _mocap('process', GT_BAG, '-o', tmp_path / 'o6', '--param',
                 'physics.stance_relase=0.1', '--param', 'gmr.lookahead=4')
    assert res.returncode == 2 and 'unknown parameter of the physics node' in res.stderr \
        and 'did you mean stance_release' in res.stderr, res.stderr


def test_process_truncated_bag_keeps_what_came_before(tmp_path):
    """A recording cut short (a recorder killed: no summary, the last chunk incomplete): the
    complete chunks are processed, the output is written, exit code 1 with one warning."""
    from mcap.writer import CompressionType, Writer

    from mocap_core.bag_io import BagReader

    full = tmp_path / 'chunked.mcap'
    with BagReader(GT_BAG) as reader, full.open('wb') as f:
        w = Writer(f, chunk_size=16_384, compression=CompressionType.NONE)
        w.start(profile='ros2', library='test')
        channels = {}
        for name, info in reader.topics.items():
            schema = w.register_schema(info.msgtype, 'ros2msg', (info.msgdef or '').encode())
            channels[name] = w.register_channel(name, 'cdr', schema)
        for m in reader.messages():
            w.add_message(channels[m.topic], m.timestamp_ns, m.data, m.timestamp_ns)
        w.finish()
    data = full.read_bytes()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(data[:len(data) // 2])
    out = tmp_path / 'cut_out'
    res = _mocap('process', cut, '-o', out, '--no-progress', '--log-level', 'warn')
    assert 'Traceback' not in res.stderr, res.stderr
    assert res.returncode == 1, res.stdout + res.stderr
    assert 'damaged or incomplete' in res.stdout + res.stderr
    with BagReader(out) as reader:
        n = reader.topics['/mocap/world/motion'].count
    assert 30 < n < 168, n                    # about half of the frames, all processed
    assert 'processed' in res.stdout


def test_process_a_bag_played_twice_restarts_each_stage(tmp_path):
    """The same stream twice in one bag (stamps jump back by 5.6 s, as when a bag is played
    again): every stage starts a new stream instead of dropping the second pass."""
    from mocap_core.bag_io import BagReader, BagWriter
    from mocap_core.run_report import load_run

    twice = tmp_path / 'twice'
    with BagReader(GT_BAG) as reader, BagWriter(twice) as writer:
        infos = reader.topics
        for t, i in infos.items():
            writer.add_topic(t, i.msgtype, i.qos, msgdef=i.msgdef, type_hash=i.type_hash)
        msgs = list(reader.messages(topics=['/mocap/keypoints2d', '/mocap/camera_info']))
        shift = msgs[-1].timestamp_ns - msgs[0].timestamp_ns + 100_000_000
        for k in range(2):
            for m in msgs:
                writer.write(m.topic, m.timestamp_ns + k * shift, m.data)
    out = tmp_path / 'twice_out'
    res = _mocap('process', twice, '-o', out, '--no-progress')
    assert res.returncode == 0, res.stdout + res.stderr
    assert 'jumped back' in res.stderr
    run = load_run(out)   # sorted by stamp: both passes, frame by frame
    for stage in ('lifter', 'physics', 'world'):
        assert len(run.stages[stage].stamps) == 2 * 168, stage
        assert np.all(np.isfinite(run.stages[stage].joints))


def test_process_person_leaving_without_camera_info(tmp_path):
    """A keypoint stream without /mocap/camera_info (another detector, an older bag): the
    person is seen for 20 frames, then every confidence is 0 for 40 frames. Frames keep coming
    out of every stage while the person is away, until they have been away for
    person_timeout_s (1 s: 30 frames): 50 frames, and no problem is reported (it used to be 20
    of 60 frames, 40 errors 'zero-size array to reduction operation maximum', and a reset at
    every frame)."""
    from mocap_core.bag_io import BagReader, BagWriter, deserialize
    from mocap_core.ros_conversions import cloud_to_keypoints, keypoints_to_cloud
    from mocap_core.run_report import load_run

    leaving = tmp_path / 'leaving'
    with BagReader(GT_BAG) as reader, BagWriter(leaving) as writer:
        i = reader.topics['/mocap/keypoints2d']
        writer.add_topic('/mocap/keypoints2d', i.msgtype, i.qos, msgdef=i.msgdef,
                         type_hash=i.type_hash)
        for k, m in enumerate(reader.messages(topics=['/mocap/keypoints2d'])):
            if k == 60:
                break
            msg = deserialize(m.data, m.msgtype)
            if k >= 20:
                people = cloud_to_keypoints(msg)
                people[..., 2] = 0.0
                msg = keypoints_to_cloud(people, msg.header)
            writer.write_msg('/mocap/keypoints2d', m.timestamp_ns, msg)
    out = tmp_path / 'leaving_out'
    res = _mocap('process', leaving, '-o', out, '--no-progress', '--summary',
                 tmp_path / 'summary.json')
    assert res.returncode == 0, res.stdout + res.stderr
    assert res.stderr.count('buffer and skeleton reset') <= 1, res.stderr
    run = load_run(out)
    for stage in ('lifter', 'physics', 'world'):
        assert len(run.stages[stage].stamps) == 50, stage
        assert np.all(np.isfinite(run.stages[stage].joints)), stage


def test_process_batch_jobs_isolation_and_resume(tmp_path):
    """Several inputs with --jobs 2: a bad input is reported and skipped, the others finish,
    a summary table is written; a rerun skips what is done."""
    import json

    junk = tmp_path / 'junk.mcap'
    junk.write_bytes(b'not a bag at all' * 10)
    listing = tmp_path / 'inputs.txt'
    listing.write_text(f'{GT_BAG}\n# a comment\n{ROOT / "bags" / "gt_bandai_wave_normal"}\n')
    out = tmp_path / 'batch'
    res = _mocap('process', f'@{listing}', junk, '-o', out, '--jobs', '2', '--no-progress')
    assert res.returncode == 1, res.stdout + res.stderr          # one input failed
    summary = json.loads((out / 'summary.json').read_text())
    status = {Path(j['input']).name: j['status'] for j in summary['inputs']}
    assert status == {'gt_cmu_walk_12_02': 'done', 'gt_bandai_wave_normal': 'done',
                      'junk.mcap': 'failed'}, summary
    failed = next(j for j in summary['inputs'] if j['status'] == 'failed')
    assert failed['error'], failed
    assert _stamps(out / 'gt_cmu_walk_12_02' / 'bag', '/mocap/world/motion')
    table = (out / 'summary.md').read_text()
    assert 'junk.mcap | failed |' in table and '2 processed, 0 skipped, 1 failed' in table
    res = _mocap('process', f'@{listing}', '-o', out, '--no-progress')
    assert res.returncode == 0, res.stdout + res.stderr
    again = json.loads((out / 'summary.json').read_text())
    assert {j['status'] for j in again['inputs']} == {'skipped (done before)'}


def test_process_batch_on_a_ray_cluster(tmp_path):
    """The same batch as Ray tasks on a local cluster started here (as a second machine
    would join it): the bad input fails alone, the others finish and hold the pipeline's
    output; a task whose Ray worker dies fails its job alone. The cluster is this test's
    own (``ray start --block``, stopped with SIGTERM): ``ray stop`` would stop every
    cluster on the machine, another test run's too."""
    import json
    import shutil
    import signal
    import socket
    import tempfile
    import time

    pytest.importorskip('ray')
    from mocap_core.cli import batch as batch_mod

    ray_cmd = shutil.which('ray', path=str(Path(sys.executable).parent)) or shutil.which('ray')
    assert ray_cmd, 'ray is installed but its command is not on the PATH'
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        port = s.getsockname()[1]
    env = dict(os.environ, RAY_USAGE_STATS_ENABLED='0')
    # a short temp dir: Ray's socket paths must fit in 107 characters
    temp = tempfile.mkdtemp(prefix='ray', dir='/tmp')
    log = tmp_path / 'ray_start.log'
    with log.open('w') as out_file:
        head = subprocess.Popen([ray_cmd, 'start', '--head', '--block', f'--port={port}',
                                 '--num-cpus=2', '--node-ip-address=127.0.0.1',
                                 '--include-dashboard=false', '--disable-usage-stats',
                                 '--object-store-memory=100000000', f'--temp-dir={temp}'],
                                stdout=out_file, stderr=subprocess.STDOUT, env=env,
                                start_new_session=True)
    try:
        deadline = time.monotonic() + 180
        while 'Ray runtime started' not in log.read_text():
            assert head.poll() is None, log.read_text()
            assert time.monotonic() < deadline, log.read_text()
            time.sleep(0.2)
        junk = tmp_path / 'junk.mcap'
        junk.write_bytes(b'not a bag at all' * 10)
        out = tmp_path / 'batch'
        res = _mocap('process', GT_BAG, junk, '-o', out, '--backend', 'ray',
                     '--ray-address', f'127.0.0.1:{port}', '--no-progress', env=env)
        assert res.returncode == 1, res.stdout + res.stderr        # one input failed
        assert 'as Ray tasks on a cluster of 1 node(s), 2 CPUs' in res.stderr, res.stderr
        summary = json.loads((out / 'summary.json').read_text())
        status = {Path(j['input']).name: j['status'] for j in summary['inputs']}
        assert status == {'gt_cmu_walk_12_02': 'done', 'junk.mcap': 'failed'}, summary
        assert len(_stamps(out / 'gt_cmu_walk_12_02' / 'bag', '/mocap/world/motion')) == 168

        def dies(job, params, extra, one_thread):      # the worker process is killed
            os._exit(3)

        def works(job, params, extra, one_thread):
            job.status = 'done'
            return job

        jobs = [batch_mod.Job('a', str(tmp_path / 'a')), batch_mod.Job('b', str(tmp_path / 'b'))]
        got = list(batch_mod._on_ray(jobs[:1], (), (), f'127.0.0.1:{port}', task_fn=dies))
        assert [j.status for j in got] == ['failed'], got
        assert 'Ray task failed: WorkerCrashedError' in got[0].error, got[0].error
        got = list(batch_mod._on_ray(jobs[1:], (), (), f'127.0.0.1:{port}', task_fn=works))
        assert [j.status for j in got] == ['done'], got              # the cluster goes on
    finally:
        head.send_signal(signal.SIGTERM)
        try:
            head.wait(timeout=120)
        except subprocess.TimeoutExpired:
            os.killpg(head.pid, signal.SIGKILL)
            head.wait()
        shutil.rmtree(temp, ignore_errors=True)


def test_process_batch_ray_backend_errors(tmp_path):
    """No cluster at the address: a clear error, exit status 2."""
    pytest.importorskip('ray')
    res = _mocap('process', GT_BAG, '-o', tmp_path / 'b', '--backend', 'ray',
                 '--ray-address', '127.0.0.1:9', '--no-progress')
    assert res.returncode == 2, res.stdout + res.stderr
    assert 'mocap process: error: no Ray cluster at 127.0.0.1:9' in res.stderr, res.stderr

