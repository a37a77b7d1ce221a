"""``ros2 run mocap_global gmr`` fed by ``ros2 bag play`` of a committed validation bag, bad
input, and the shipped weights against zero-motion and constant-velocity baselines."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / 'bags' / 'gt_cmu_walk_12_02'
WEIGHTS = ROOT / 'src' / 'mocap_global' / 'weights' / 'gmr.pt'
OUTPUTS = ('motion', 'joints3d', 'joint_states', 'odom', 'path', 'markers')


def _weights(tmp_path: Path) -> Path:
    """The shipped weights, or (before they are trained) a randomly initialised network of the
    shipped size: the node tests check the plumbing, not the accuracy."""
    if WEIGHTS.exists():
        return WEIGHTS
    import torch

    from mocap_global.model import GMR, GMRConfig
    from mocap_global.weights import save_weights
    torch.manual_seed(0)
    path = tmp_path / 'gmr_untrained.pt'
    save_weights(GMR(GMRConfig()), path, {'note': 'untrained, for the node tests'})
    return path


def _world_groundtruth():
    from mocap_core.rotations import quat_to_matrix

    from mocap_core.data.gt_bag import read_groundtruth_bag
    b = read_groundtruth_bag(BAG)
    Rc, tc = b['camera']
    rot = np.stack([p.rotations for p in b['poses']])
    root = np.stack([p.root_position for p in b['poses']])
    return b, Rc @ quat_to_matrix(rot[:, 0]), root @ Rc.T + tc


@pytest.mark.parametrize('name, step', [('gmr.pt', 1), ('gmr_10fps.pt', 3)])
def test_shipped_weights_beat_zero_motion_and_constant_velocity(name, step):
    """The 30 fps node model on the 30 fps bag, the 10 fps model (the paper's rate) on every
    third frame of it."""
    from mocap_core.rotations import axis_angle_to_matrix, matrix_to_axis_angle

    from mocap_global.features import body_joint_positions, features_for
    from mocap_global.se3 import relative_motion
    from mocap_global.training import metrics as M
    from mocap_global.training.evaluate import predict_clip
    from mocap_global.weights import load_weights

    weights = WEIGHTS.parent / name
    if not weights.exists():
        pytest.skip(f'{weights} does not exist yet: train it with `mocap train gmr --install`')
    b, Rw, Tw = _world_groundtruth()
    Rw, Tw = Rw[::step], Tw[::step]
    model = load_weights(weights)
    assert model.cfg.fps == 30.0 / step
    sk = b['poses'][0].skeleton
    rot = np.stack([p.rotations for p in b['poses']])[::step]
    feats = features_for(model.cfg, rot, sk.group_lengths())
    pred = predict_clip(model, feats, lookahead=15 // step)
    dR_gt, dT_gt = relative_motion(Rw, Tw)
    joints = body_joint_positions(sk.offsets, rot)[1:]
    n = len(dR_gt)
    candidates = {
        'gmr': (axis_angle_to_matrix(pred['axis_angle']), pred['translation']),
        'zero': (np.broadcast_to(np.eye(3), (n, 3, 3)), np.zeros((n, 3))),
        # the clip's true mean motion: an oracle constant velocity and turn rate
        'constant_velocity': (np.broadcast_to(axis_angle_to_matrix(
            matrix_to_axis_angle(dR_gt).mean(0)), (n, 3, 3)),
            np.broadcast_to(dT_gt.mean(0), (n, 3))),
    }
    err = {}
    for name, (dR, dT) in candidates.items():
        err[name] = {'ome': M.ome_deg(dR, dR_gt).mean(), 'tme': M.tme_mm(dT, dT_gt).mean(),
                     'jme': M.jme_mm(dR, dT, dR_gt, dT_gt, joints).mean()}
    print({k: {m: round(float(v), 3) for m, v in e.items()} for k, e in err.items()})
    g, z, c = err['gmr'], err['zero'], err['constant_velocity']
    for metric in ('tme', 'jme'):
        assert g[metric] < 0.5 * z[metric], metric
        assert g[metric] < 0.75 * c[metric], metric
    assert g['ome'] < 0.75 * z['ome']


@pytest.mark.parametrize('bag', ['gt_cmu_walk_12_02', 'gt_bandai_walk_exhausted'])
def test_shipped_weights_keep_the_path_of_a_stream_with_three_frames_in_four_dropped(bag):
    """A walk delivered at a quarter of its rate (a busy machine's keypoint node): with the
    missing frames filled in (the node's fill_missing_frames) GMR's path is nearer the one it
    gives with every frame than without (measured: CMU walk 4.22 / 4.96 m against 4.40 with
    every frame, Bandai Namco walk 6.42 / 7.80 against 6.82; docs/global.md)."""
    from mocap_core.data.gt_bag import read_groundtruth_bag
    from mocap_global.online import OnlineGMR
    from mocap_global.weights import load_weights

    if not WEIGHTS.exists():
        pytest.skip(f'{WEIGHTS} does not exist yet')
    model = load_weights(WEIGHTS)
    b = read_groundtruth_bag(ROOT / 'bags' / bag)
    up = np.array([0.0, -1.0, 0.0]) if model.cfg.root_input == 'up' else None

    def path(step: int, rate: float) -> float:
        online = OnlineGMR(model, lookahead=15, window=48, network_rate_hz=rate, input_up=up)
        out = []
        for i in range(0, len(b['poses']), step):
            out += online.push(b['stamps'][i], b['poses'][i])[0]
        out += online.flush()
        assert len(out) == len(range(0, len(b['poses']), step))
        T = np.array([f.pose.root_position[:2] for f in out])
        return float(np.linalg.norm(np.diff(T, axis=0), axis=1).sum())

    full = path(1, 30.0)
    assert path(1, 0.0) == pytest.approx(full, abs=1e-9)        # nothing to fill at 30 fps
    filled, unfilled = path(4, 30.0), path(4, 0.0)
    print(bag, full, filled, unfilled)
    assert abs(filled - full) < 0.6 * abs(unfilled - full)
    assert abs(filled - full) < 0.08 * full


@pytest.fixture
def listener(peer):
    """The test's rclpy peer subscribed to every world output."""
    from nav_msgs.msg import Odometry, Path as PathMsg
    from sensor_msgs.msg import JointState, PointCloud2
    from trajectory_msgs.msg import MultiDOFJointTrajectory
    from visualization_msgs.msg import MarkerArray

    types = {'motion': MultiDOFJointTrajectory, 'joints3d': PointCloud2,
             'joint_states': JointState, 'odom': Odometry, 'path': PathMsg,
             'markers': MarkerArray}
    from mocap_core.qos import STREAM_QOS, input_qos

    deep = input_qos(STREAM_QOS, 1000)     # the node's outputs are as deep (output_queue_depth)
    return peer, {name: peer.subscribe(cls, f'/mocap/world/{name}', deep)
                  for name, cls in types.items()}


def _stamp(m):
    from mocap_core.ros_conversions import stamp_to_ns
    return stamp_to_ns(m.header.stamp if hasattr(m, 'header') else m.markers[0].header.stamp)


def test_node_publishes_the_world_motion_of_a_played_bag(processes, ros2_cmd, listener,
                                                         tmp_path):
    from mocap_core.ros_conversions import cloud_to_positions, motion_to_pose, odometry_to_root

    peer, got = listener
    b, Rw, Tw = _world_groundtruth()
    stamps = b['stamps']
    # deep queues (the node's input and outputs, the player's publishers): every frame even
    # when a loaded machine slows the node, or this listener, below the bag's rate (the live
    # defaults favour latency)
    node, log = processes.start(ros2_cmd + [
        'run', 'mocap_global', 'gmr', '--ros-args', '-p',
        'motion_topic:=/mocap/groundtruth/motion', '-p', f'weights:={_weights(tmp_path)}',
        '-p', 'lookahead:=10', '-p', 'queue_depth:=1000', '-p', 'output_queue_depth:=1000'],
        'gmr')
    processes.wait_for_text(log, 'gmr ready', 90, node)
    # no fixed delays: every subscription of the test has matched the node's publisher, and the
    # player waits until the node's input has matched before its first message
    assert peer.wait_for_publishers(timeout=60, proc=node), \
        (peer.unmatched_subscriptions(), log.read_text())
    player, plog = processes.start(ros2_cmd + ['bag', 'play', str(BAG), '--wait-for-subscribers',
                                               '--wait-timeout', '60', '--qos-depth', '1000',
                                               '--topics', '/mocap/groundtruth/motion'], 'play')
    peer.spin(120, until=lambda: player.poll() is not None)
    assert player.returncode == 0, plog.read_text()
    # a node slowed down by a loaded machine may still be working through its input queue
    peer.spin(120, until=lambda: all(len(got[k]) >= len(stamps) for k in OUTPUTS))
    text = log.read_text()
    assert 'Traceback' not in text, text
    assert 'waiting for 11 frames' in text
    for name in OUTPUTS:
        assert len(got[name]) == len(stamps), (name, len(got[name]), text[-2000:])
        assert [_stamp(m) for m in got[name]] == stamps, name
    assert all(m.header.frame_id == 'world' for m in got['motion'])
    assert len(got['path'][-1].poses) == len(stamps)
    for m in got['joints3d']:
        assert np.all(np.isfinite(cloud_to_positions(m, 18)))
    poses = [motion_to_pose(m) for m in got['motion']]
    # the local pose is passed through; the world root starts gravity-aligned on the floor
    np.testing.assert_allclose(poses[5].rotations[1:], b['poses'][5].rotations[1:], atol=1e-6)
    first = poses[0]
    assert min(p[2] for p in first.contact_positions().values()) == pytest.approx(0, abs=1e-6)
    T = np.stack([odometry_to_root(m)[0] for m in got['odom']])
    assert np.all(np.isfinite(T))
    if WEIGHTS.exists():   # trained: the trajectory follows the walk (4-DOF aligned)
        from mocap_global.training.metrics import ate_mm
        travelled = np.linalg.norm(Tw[-1] - Tw[0])
        assert ate_mm(T, Tw) < 0.25 * 1000 * travelled


def test_node_survives_bad_input(processes, ros2_cmd, listener, tmp_path):
    from trajectory_msgs.msg import MultiDOFJointTrajectory

    from mocap_core.qos import STREAM_QOS
    from mocap_core.ros_conversions import make_header, pose_to_motion

    peer, got = listener
    b, _, _ = _world_groundtruth()
    pub = peer.publisher(MultiDOFJointTrajectory, '/mocap/physics/motion', STREAM_QOS)
    proc, log = processes.start(ros2_cmd + [
        'run', 'mocap_global', 'gmr', '--ros-args', '-p', f'weights:={_weights(tmp_path)}',
        '-p', 'lookahead:=3', '-p', 'static_camera:=true', '-p', 'max_gap_s:=0.2'],
        'gmr_bad')
    processes.wait_for_text(log, 'gmr ready', 90, proc)
    assert peer.wait_for_subscribers([pub], timeout=60, proc=proc) and \
        peer.wait_for_publishers(timeout=60, proc=proc), log.read_text()
    t0 = 1_000_000_000
    dt = 33_333_333

    def send(i, pose, stamp):
        pub.publish(pose_to_motion(pose, make_header(stamp, 'floor')))
        peer.spin(0.03)

    poses = b['poses']
    # a joint set that does not match the model
    wrong = pose_to_motion(poses[0], make_header(t0, 'floor'))
    wrong.joint_names = wrong.joint_names[:10]
    wrong.points[0].transforms = wrong.points[0].transforms[:10]
    pub.publish(wrong)
    # NaN
    nan = pose_to_motion(poses[0], make_header(t0, 'floor'))
    nan.points[0].transforms[3].rotation.x = float('nan')
    pub.publish(nan)
    peer.spin(0.2)
    for i in range(10):                       # start-up: outputs wait for 3 future frames
        send(i, poses[i], t0 + i * dt)
    send(0, poses[9], t0 + 9 * dt)            # a stamp that does not advance
    for i in range(10, 20):                   # after a gap of 1 s: accumulation restarts
        send(i, poses[i], t0 + int(1e9) + i * dt)
    peer.spin(5, until=lambda: all(len(got[k]) >= 20 for k in OUTPUTS))
    text = log.read_text()
    assert proc.poll() is None, text            # still running
    assert 'Traceback' not in text
    assert 'joint set does not match the GMR model' in text
    assert 'dropping motion' in text and 'NaN' in text
    assert 'did not advance' in text
    assert 'waiting for 4 frames' in text
    assert 'accumulation restarted' in text
    assert 'static camera' in text
    assert len(got['motion']) == 20, text[-2000:]
    stamps = [_stamp(m) for m in got['motion']]
    assert stamps == sorted(stamps)
    from mocap_core.ros_conversions import cloud_to_positions
    assert all(np.all(np.isfinite(cloud_to_positions(m, 18))) for m in got['joints3d'])
    # the restart begins a new path
    assert len(got['path'][-1].poses) == 10


def test_node_test_time_augmentation_parameter():
    """test_time_augmentation wraps the model (the published motion is the augmented one and
    stays finite); an unknown value is refused with the valid ones named."""
    import rclpy
    from rclpy.parameter import Parameter

    from mocap_core.bag_io import BagReader, deserialize
    from mocap_core.inprocess import InProcessGraph
    from mocap_core.ros_conversions import motion_to_pose

    from mocap_global.model import Augmented
    from mocap_global.node import GMRNode

    with BagReader(BAG) as reader:
        motions = [deserialize(m.data, m.msgtype)
                   for m in reader.messages(topics=['/mocap/groundtruth/motion'])][:40]
    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    cls = GMRNode
    try:
        with pytest.raises(ValueError, match='mirror'):
            cls(context=context, parameter_overrides=[
                Parameter('test_time_augmentation', value='sideways')]).destroy_node()
        roots = {}
        for tta in ('none', 'both'):
            out = []
            graph = InProcessGraph(record=lambda t, m, q, out=out: out.append((t, m)))
            node = graph.add(cls(context=context, parameter_overrides=[
                Parameter('test_time_augmentation', value=tta),
                Parameter('motion_topic', value='/in/motion')]))
            assert isinstance(node.model, Augmented) == (tta != 'none')
            for m in motions:
                graph.publish('/in/motion', m)
            graph.flush()
            world = [motion_to_pose(m) for t, m in out if t == '/mocap/world/motion']
            assert len(world) == len(motions)
            roots[tta] = np.stack([p.root_position for p in world])
            assert np.all(np.isfinite(roots[tta]))
            node.destroy_node()
        assert not np.allclose(roots['none'], roots['both'])
        # both are the same walk: apart by a small part of the distance walked in 40 frames
        # (0.86 m; 11 cm with the weights fine-tuned on the lifter's output, under 10 before)
        walked = np.linalg.norm(np.diff(roots['none'][:, :2], axis=0), axis=-1).sum()
        assert walked > 0.5
        assert np.linalg.norm(roots['none'] - roots['both'], axis=-1).max() < 0.15 * walked
    finally:
        context.try_shutdown()


def test_node_network_reads_the_lifters_pose_matched_by_stamp():
    """network_pose_topic: the lifter's motion of a stamp reaches GMR's network for the input
    frame of the same stamp, whether it comes before or after that frame (diagnostics
    network_pose_frames); the world path is then the network pose's while the body placed
    is the input's; a network pose with other joints is dropped and counted, never fatal."""
    import copy

    import rclpy
    from rclpy.parameter import Parameter

    from mocap_core import topics
    from mocap_core.bag_io import BagReader, deserialize
    from mocap_core.inprocess import InProcessGraph
    from mocap_core.ros_conversions import motion_to_pose

    from mocap_global.node import GMRNode

    with BagReader(BAG) as reader:
        motions = [deserialize(m.data, m.msgtype)
                   for m in reader.messages(topics=['/mocap/groundtruth/motion'])][:40]
    # the "input": the same frames with the legs frozen at the first frame's (a body that
    # does not step); the network pose: the walk itself
    still = []
    for m in motions:
        s = copy.deepcopy(m)
        for i, name in enumerate(s.joint_names):
            if name != s.joint_names[0]:
                s.points[0].transforms[i].rotation = motions[0].points[0].transforms[i].rotation
        still.append(s)
    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    try:
        roots = {}
        for case in ('still', 'still + walk', 'walk'):
            out = []
            graph = InProcessGraph(record=lambda t, m, q, out=out: out.append((t, m)))
            node = graph.add(GMRNode(context=context, parameter_overrides=[
                Parameter('motion_topic', value='/in/motion'),
                Parameter('network_pose_topic', value='/in/lifter')]))
            for k, (m, s) in enumerate(zip(motions, still)):
                body = m if case == 'walk' else s
                if case == 'still + walk' and k % 2 == 0:     # the lifter's pose first
                    graph.publish('/in/lifter', m)
                graph.publish('/in/motion', body)
                if case == 'still + walk' and k % 2 == 1:     # the lifter's pose after
                    graph.publish('/in/lifter', m)
                if case == 'still + walk' and k == 20:        # another skeleton: dropped
                    bad = copy.deepcopy(m)
                    bad.joint_names = bad.joint_names[:5]
                    bad.points[0].transforms = bad.points[0].transforms[:5]
                    graph.publish('/in/lifter', bad)
            graph.flush()
            world = [motion_to_pose(m) for t, m in out if t == topics.WORLD_MOTION]
            assert len(world) == len(motions), case
            roots[case] = np.stack([p.root_position[:2] for p in world])
            if case == 'still + walk':
                assert node.online.network_pose_frames == len(motions)
                values = {kv.key: kv.value for kv in node.diag.status().values}
                assert values['network_pose_frames'] == str(len(motions))
                assert node.diag.errors == 1
                # the body placed is the input's (the frozen legs), not the network's
                first_leg = motion_to_pose(still[0]).rotations[1:]
                np.testing.assert_allclose(world[-1].rotations[1:], first_leg, atol=1e-9)
            node.destroy_node()
        # the path follows the network's pose: the frozen body alone walks a different path
        walked = np.linalg.norm(np.diff(roots['walk'], axis=0), axis=-1).sum()
        assert walked > 0.5
        fed = np.abs(roots['still + walk'] - roots['walk']).max()
        alone = np.abs(roots['still'] - roots['walk']).max()
        assert fed < 0.2 * alone, (fed, alone)      # (3 cm against 80 cm here)
    finally:
        context.try_shutdown()
