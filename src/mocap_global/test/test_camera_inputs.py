"""The world node with camera inputs (in-process, as ``mocap process`` wires it): a known
camera pose puts the output in the robot's frame; the camera-motion estimate switches the
static-camera fusion on and off; bad or missing camera messages are counted, never fatal."""

import numpy as np
import pytest

from mocap_core.pose import Pose
from mocap_core.rotations import axis_angle_to_matrix, matrix_to_quat, quat_to_matrix
from mocap_core.testing import random_walk_poses

DT_NS = 33_333_333


def _poses(n, seed=0):
    """A person walking along world x (z up) with random limb poses."""
    return random_walk_poses(n, seed, start=(0.0, 0.5, 0.95), step=(0.04, 0.0, 0.0))


@pytest.fixture
def graph_node():
    import rclpy
    from rclpy.parameter import Parameter

    from mocap_core.inprocess import InProcessGraph
    from mocap_global.node import GMRNode

    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    made = []

    def make(**params):
        out = []
        graph = InProcessGraph(record=lambda t, m, q: out.append((t, m)))
        node = graph.add(GMRNode(context=context, parameter_overrides=[
            Parameter(k, value=v) for k, v in {'motion_topic': '/in/motion', 'lookahead': 3,
                                                **params}.items()]))
        made.append(node)
        return graph, node, out

    yield make
    for n in made:
        n.destroy_node()
    context.try_shutdown()


def _in_camera(poses, R_wc, t_wc):
    """World poses -> the camera-frame poses a camera at (R_wc, t_wc) sees."""
    out = []
    for p in poses:
        rot = np.array(p.rotations)
        rot[0] = matrix_to_quat(R_wc.T @ quat_to_matrix(p.rotations[0]))
        out.append(Pose(p.skeleton, rot, R_wc.T @ (p.root_position - t_wc)))
    return out


def _camera_and_its_floor():
    """A camera 1.4 m up looking down at the walk (optical -> world ``R_wc``, ``t_wc``) and
    its floor frame: z up, origin on the floor below the camera, x along the optical axis
    projected on the floor (floor -> world ``R_wf``, ``t_wf``; ``p_camera = A p_floor + b``)."""
    from mocap_core.data.synth2d import look_at
    t_wc = np.array([-2.0, 3.0, 1.4])
    R_wc = look_at(t_wc, np.array([1.0, 0.5, 0.9])).T
    f = R_wc[:, 2] * np.array([1.0, 1.0, 0.0])
    x = f / np.linalg.norm(f)
    R_wf = np.stack([x, np.cross([0.0, 0.0, 1.0], x), [0.0, 0.0, 1.0]], axis=1)
    t_wf = np.array([t_wc[0], t_wc[1], 0.0])
    return t_wc, R_wc, t_wf, R_wf, R_wc.T @ R_wf, R_wc.T @ (t_wf - t_wc)


def _values(node):
    return {kv.key: kv.value for kv in node.diag.status().values}


def test_a_known_camera_pose_gives_the_pose_in_the_robot_frame(graph_node):
    from geometry_msgs.msg import Point, Pose as PoseMsg, PoseStamped, Quaternion
    from mocap_core import ros_conversions as rc
    from mocap_core import topics

    graph, node, out = graph_node(camera_pose_topic='/robot/camera_pose',
                                  camera_pose_type='pose',
                                  fusion_position_time_constant_s=1e-6,
                                  fusion_orientation_time_constant_s=1e-6)
    world = _poses(40)
    # a camera that moves (a robot driving) and turns, optical frame in 'odom'
    cams = [(axis_angle_to_matrix(np.array([-1.6, 0.0, 0.02 * i])),
             np.array([0.05 * i, -3.0, 1.2])) for i in range(40)]
    seen = [_in_camera([p], R, t)[0] for p, (R, t) in zip(world, cams)]
    for i, (p, (R, t)) in enumerate(zip(seen, cams)):
        if i == 20:
            # a malformed pose is counted and ignored; frame 20 then has its neighbours'
            q = np.full(4, np.nan)
        else:
            q = matrix_to_quat(R)
        header = rc.make_header(i * DT_NS, 'odom')
        graph.publish('/robot/camera_pose', PoseStamped(header=header, pose=PoseMsg(
            position=Point(x=float(t[0]), y=float(t[1]), z=float(t[2])),
            orientation=Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]),
                                   w=float(q[3])))))
        graph.publish('/in/motion', rc.pose_to_motion(
            p, rc.make_header(i * DT_NS, 'camera_optical_frame')))
    graph.flush()
    odom = [m for t, m in out if t == topics.WORLD_ODOM]
    assert len(odom) == 40 and all(m.header.frame_id == 'odom' for m in odom)
    T = np.stack([rc.odometry_to_root(m)[0] for m in odom])
    T_true = np.stack([p.root_position for p in world])
    # the world root is the camera pose composed with the camera-frame root (frame 20:
    # interpolated between its neighbours' poses)
    np.testing.assert_allclose(T, T_true, atol=0.02)
    v = _values(node)
    assert v['camera_mode'] == 'known' and v['errors'] == '1'
    assert v['camera_pose_missing_frames'] == '0'


def test_without_a_camera_pose_gmr_fills_and_the_frames_are_counted(graph_node):
    from mocap_core import ros_conversions as rc
    from mocap_core import topics

    graph, node, out = graph_node(camera_pose_topic='/robot/camera_pose')
    for i, p in enumerate(_poses(20)):
        graph.publish('/in/motion', rc.pose_to_motion(
            p, rc.make_header(i * DT_NS, 'camera_optical_frame')))
    graph.flush()
    assert len([m for t, m in out if t == topics.WORLD_ODOM]) == 20
    assert _values(node)['camera_pose_missing_frames'] == '20'


def test_camera_motion_switches_the_fusion(graph_node):
    """camera_mode auto: frames the estimate calls static are fused, moving ones are not;
    an estimate with NaN is counted and the frame goes unfused."""
    from mocap_core import ros_conversions as rc
    from mocap_core import topics

    graph, node, out = graph_node()
    world = _poses(60)
    R_wc = axis_angle_to_matrix(np.array([-1.6, 0.0, 0.3]))
    seen = _in_camera(world, R_wc, np.array([0.0, -4.0, 1.0]))
    for i, p in enumerate(seen):
        state = 'static' if i < 30 else 'moving'
        w = np.full(3, np.nan) if i == 10 else np.zeros(3)
        msg = rc.camera_motion_to_odometry(state, np.array([0, 0, 0, 1.0]), np.zeros(3),
                                           rc.make_header(i * DT_NS, 'cam_start'), 'cam')
        msg.twist.twist.angular.x = float(w[0])
        graph.publish(topics.CAMERA_MOTION, msg)
        graph.publish('/in/motion', rc.pose_to_motion(
            p, rc.make_header(i * DT_NS, 'camera_optical_frame')))
    graph.flush()
    v = _values(node)
    assert v['camera_mode'] == 'auto' and v['errors'] == '1'
    assert v['camera_motion_frames'] == 'moving 30, no estimate 1, static 29'
    assert v['unfused_frames'] == '31'


def test_camera_motion_round_trip():
    from mocap_core import ros_conversions as rc

    for state in ('static', 'rotating', 'moving', 'unknown'):
        q = matrix_to_quat(axis_angle_to_matrix(np.array([0.1, 0.2, 0.3])))
        msg = rc.camera_motion_to_odometry(state, q, np.array([0.1, 0.0, -0.2]),
                                           rc.make_header(5, 'a'), 'b')
        s, q2, w = rc.odometry_to_camera_motion(msg)
        assert s == state
        np.testing.assert_allclose(q2, q, atol=1e-12)
        np.testing.assert_allclose(w, np.zeros(3) if state == 'static' else [0.1, 0, -0.2])
    with pytest.raises(ValueError, match='unknown camera motion state'):
        rc.camera_motion_to_odometry('flying', q, np.zeros(3), rc.make_header(5, 'a'), 'b')
    # a translation measured over the floor: the position comes back, the state stays
    for state in ('static', 'rotating', 'moving'):
        msg = rc.camera_motion_to_odometry(state, q, np.array([0.0, 0.1, 0.0]),
                                           rc.make_header(5, 'a'), 'b',
                                           position=np.array([0.5, -0.1, 2.0]),
                                           linear_velocity=np.array([0.0, 0.0, 1.2]))
        assert rc.odometry_to_camera_motion(msg)[0] == state
        np.testing.assert_allclose(rc.odometry_to_camera_position(msg), [0.5, -0.1, 2.0])
        assert msg.twist.twist.linear.z == (1.2 if state == 'moving' else 0.0)
    for state in ('moving', 'unknown'):
        msg = rc.camera_motion_to_odometry(state, q, np.zeros(3), rc.make_header(5, 'a'), 'b')
        assert rc.odometry_to_camera_position(msg) is None
    msg = rc.camera_motion_to_odometry('unknown', q, np.zeros(3), rc.make_header(5, 'a'), 'b',
                                       position=np.ones(3))
    assert rc.odometry_to_camera_position(msg) is None       # nothing tracked: not known


@pytest.mark.parametrize('measured', [True, False])
def test_a_walking_camera_with_a_measured_translation_is_fused(graph_node, measured):
    """A camera that walks beside the person and turns (state moving): with its position
    measured over the floor the world path is the true one (up to the heading and origin the
    fusion chooses); without it, no frame is fused."""
    from mocap_core import ros_conversions as rc
    from mocap_core import topics

    # the fusion's pulls and the change from GMR alone to the fused frames (at 1 s) taken at
    # once: the measured path itself, without the time constants that smooth it
    graph, node, out = graph_node(fusion_position_time_constant_s=1e-6,
                                  fusion_orientation_time_constant_s=1e-6,
                                  fusion_moving_lock_time_constant_s=0.0,
                                  transition_time_constant_s=0.0)
    n = 70
    world = _poses(n)
    cams = [(axis_angle_to_matrix(np.array([0.0, 0.0, 0.01 * i])) @
             axis_angle_to_matrix(np.array([-1.6, 0.0, 0.0])),
             np.array([0.035 * i, -3.0, 1.2])) for i in range(n)]
    seen = [_in_camera([p], R, t)[0] for p, (R, t) in zip(world, cams)]
    R_0, t_0 = cams[0]
    for i, (p, (R, t)) in enumerate(zip(seen, cams)):
        msg = rc.camera_motion_to_odometry(
            'moving', matrix_to_quat(R_0.T @ R), np.zeros(3),
            rc.make_header(i * DT_NS, 'cam_start'), 'cam',
            position=R_0.T @ (t - t_0) if measured else None)
        graph.publish(topics.CAMERA_MOTION, msg)
        graph.publish('/in/motion', rc.pose_to_motion(
            p, rc.make_header(i * DT_NS, 'camera_optical_frame')))
    graph.flush()
    odom = [m for t, m in out if t == topics.WORLD_ODOM]
    assert len(odom) == n
    T = np.stack([rc.odometry_to_root(m)[0] for m in odom])
    T_true = np.stack([p.root_position for p in world])
    v = _values(node)
    if not measured:
        assert v['unfused_frames'] == str(n)
        return
    assert v['camera_motion_frames'] == f'moving (translation measured) {n}'
    assert v['unfused_frames'] == '0'
    # after the fusion's first second (an optical-frame input of unknown tilt aligns itself
    # over init_s), distances along the path are the true ones
    k0 = 35
    d = np.linalg.norm(T[k0:] - T[k0], axis=1)
    d_true = np.linalg.norm(T_true[k0:] - T_true[k0], axis=1)
    assert d_true[-1] > 1.3
    np.testing.assert_allclose(d, d_true, atol=0.03)


def test_a_known_camera_pose_with_the_physics_floor_input(graph_node):
    """A floor-frame input (the physics output) goes through the floor transform and then
    the camera pose: with a true floor the world output is the true world pose."""
    from mocap_core import ros_conversions as rc
    from mocap_core import topics

    graph, node, out = graph_node(camera_pose_topic='/robot/camera', floor_topic='/floor',
                                  fusion_static_position_time_constant_s=1e-6)
    world = _poses(40)
    t_wc, R_wc, t_wf, R_wf, A, b = _camera_and_its_floor()
    for i, p in enumerate(world):
        header = rc.make_header(i * DT_NS, 'odom')
        graph.publish('/robot/camera', rc.root_to_odometry(t_wc, matrix_to_quat(R_wc), header,
                                                           'camera_optical_frame'))
        rot = np.array(p.rotations)
        rot[0] = matrix_to_quat(R_wf.T @ quat_to_matrix(p.rotations[0]))
        in_floor = Pose(p.skeleton, rot, R_wf.T @ (p.root_position - t_wf))
        graph.publish('/in/motion', rc.pose_to_motion(in_floor, rc.make_header(i * DT_NS,
                                                                               'floor')))
        graph.publish('/floor', rc.transform_stamped(
            rc.make_header(i * DT_NS, 'camera_optical_frame'), 'floor', A, b))
    graph.flush()
    odom = [m for t, m in out if t == topics.WORLD_ODOM]
    assert len(odom) == 40 and odom[-1].header.frame_id == 'odom'
    T = np.stack([rc.odometry_to_root(m)[0] for m in odom])
    # the first frame comes before any floor message: GMR's own start
    np.testing.assert_allclose(T[1:], np.stack([p.root_position for p in world])[1:],
                               atol=0.02)
    assert _values(node)['camera_pose_missing_frames'] == '1'


def _publish_known_frame(graph, i, person, lifter, offset):
    """Frame ``i`` of a person seen by :func:`_camera_and_its_floor`'s camera, whose pose is
    known (``/robot/camera``): the camera pose, the physics floor (``/floor``), the lifter's
    camera-frame pose of ``lifter`` (a world pose; None: none this frame) and the physics
    input (``/in/motion``): ``person`` with its root moved by ``offset`` (3,) m in the world,
    in the floor frame."""
    from mocap_core import ros_conversions as rc
    from mocap_core import topics

    t_wc, R_wc, t_wf, R_wf, A, b = _camera_and_its_floor()
    graph.publish('/robot/camera', rc.root_to_odometry(
        t_wc, matrix_to_quat(R_wc), rc.make_header(i * DT_NS, 'odom'), 'camera_optical_frame'))
    graph.publish('/floor', rc.transform_stamped(
        rc.make_header(i * DT_NS, 'camera_optical_frame'), 'floor', A, b))
    if lifter is not None:
        graph.publish(topics.LIFTER_UNSMOOTHED_MOTION, rc.pose_to_motion(
            _in_camera([lifter], R_wc, t_wc)[0],
            rc.make_header(i * DT_NS, 'camera_optical_frame')))
    rot = np.array(person.rotations)
    rot[0] = matrix_to_quat(R_wf.T @ quat_to_matrix(person.rotations[0]))
    in_floor = Pose(person.skeleton, rot, R_wf.T @ (person.root_position + offset - t_wf))
    graph.publish('/in/motion', rc.pose_to_motion(in_floor, rc.make_header(i * DT_NS, 'floor')))


@pytest.mark.parametrize('root,noise', [('lifter', 0.0), ('input', 0.0), ('lifter', 0.05)])
def test_a_known_camera_pose_places_the_lifters_root(graph_node, root, noise):
    """camera_pose_root lifter: with a known pose the horizontal position is the lifter's
    camera-frame root of each stamp moved by the pose, the height the physics input's
    (``camera_pose_height`` input: the lifter's height is tested below); the
    physics root here lags 30 cm behind along the walk and stands 5 cm lower. With
    ``input`` the physics root is taken. A stamp without a lifter pose is counted and takes
    its neighbours' mean. A lifter
    root that jumps 5 cm back and forth along the walk every frame is averaged over 8 frames
    on each side (without a delay: the walk is followed) and moves the output by less than
    1.5 cm; with no averaging it would move it by the noise."""
    from mocap_core import ros_conversions as rc
    from mocap_core import topics

    graph, node, out = graph_node(camera_pose_topic='/robot/camera', floor_topic='/floor',
                                  camera_pose_root=root, camera_pose_height='input',
                                  camera_pose_root_half_window=8,
                                  lookahead=10,
                                  fusion_static_position_time_constant_s=1e-6,
                                  camera_pose_position_time_constant_s=1e-6)
    world = _poses(40)
    lag = np.array([-0.3, 0.0, -0.05])
    for i, p in enumerate(world):
        # the lifter's frame of stamp 25 is missing
        shaky = None if i == 25 else Pose(p.skeleton, p.rotations,
                                          p.root_position + [noise * (-1) ** i, 0.0, 0.0])
        _publish_known_frame(graph, i, p, shaky, lag)
    graph.flush()
    odom = [m for t, m in out if t == topics.WORLD_ODOM]
    assert len(odom) == 40
    T = np.stack([rc.odometry_to_root(m)[0] for m in odom])[1:]
    T_true = np.stack([p.root_position for p in world])[1:]
    np.testing.assert_allclose(T[:, 2], T_true[:, 2] + lag[2], atol=0.01)
    if root == 'lifter' and noise:
        # the middle of the walk (8 frames on each side in the buffer; 25 filled)
        mid = (np.arange(1, 40) >= 11) & (np.arange(1, 40) <= 28)
        assert np.abs(T[mid, :2] - T_true[mid, :2]).max() < 0.015
    elif root == 'lifter':
        np.testing.assert_allclose(T[:, :2], T_true[:, :2], atol=0.02)
        assert _values(node)['camera_pose_root'].startswith(
            "the lifter's root in 40 frames; 1 frames of all persons had none ")
    else:
        np.testing.assert_allclose(T[:, :2], T_true[:, :2] + lag[:2], atol=0.02)
        assert 'camera_pose_root' not in _values(node)


@pytest.mark.parametrize('height,window,average', [
    ('input', 1.0, 'root'), ('lifter', 0.0, 'root'), ('lifter', 1.0, 'root'),
    ('lifter', 0.0, 'offset')])
def test_a_known_camera_pose_can_give_the_lifters_height(graph_node, height, window, average):
    """camera_pose_height lifter: the physics floor here is 5 cm too high under the person
    (its root 5 cm low in the world; the feet rest on that floor), and from frame 20 on it
    is 4 cm higher still. With ``input`` the output's height is the physics', its floor the
    world's z = 0. With ``lifter`` the whole body is raised by the lifter's root height
    above the physics root: with a window of 0 s to the lifter's height in every frame, the
    published floor (the input frame in the world) 5 cm, then 9 cm up (also with the offsets
    averaged instead of the roots, which smears the step over the +-10 frames); with the
    median over the second before and the 10 look-ahead frames, the step of frame 20 enters
    the median once it fills half of those (frame 29) and the raise follows it smoothly, the
    offset before it at once (the first frame's median is of its look-ahead too)."""
    from mocap_core import ros_conversions as rc
    from mocap_core import topics

    graph, node, out = graph_node(camera_pose_topic='/robot/camera', floor_topic='/floor',
                                  camera_pose_height=height,
                                  camera_pose_height_window_s=window, lookahead=10,
                                  camera_pose_height_follow_s=0.5,
                                  fusion_measured_root_average=average,
                                  fusion_static_position_time_constant_s=1e-6,
                                  camera_pose_position_time_constant_s=1e-6)
    world = _poses(40)
    for i, p in enumerate(world):
        _publish_known_frame(graph, i, p, p, [0.0, 0.0, -0.05 if i < 20 else -0.09])
    graph.flush()
    odom = [m for t, m in out if t == topics.WORLD_ODOM]
    floors = [m for t, m in out if t == topics.WORLD_FLOOR]
    assert len(odom) == 40 and len(floors) == 40
    z = np.stack([rc.odometry_to_root(m)[0] for m in odom])[:, 2]
    z_true = np.stack([p.root_position for p in world])[:, 2]
    lift = np.array([rc.transform_stamped_to_arrays(m)[1][2] for m in floors])
    before, after = slice(3, 10), slice(30, 40)     # the +-10 frame averages off the step
    if height == 'input':
        assert 'camera_pose_height' not in _values(node)
        np.testing.assert_allclose(z[before], z_true[before] - 0.05, atol=0.005)
        np.testing.assert_allclose(z[after], z_true[after] - 0.09, atol=0.005)
        np.testing.assert_allclose(lift, 0.0, atol=1e-9)
        return
    np.testing.assert_allclose(z[before], z_true[before], atol=0.005)
    np.testing.assert_allclose(lift[before], 0.05, atol=0.005)
    assert _values(node)['camera_pose_height'].startswith(
        f"the lifter's root: the body raised by {100 * lift[-1]:.1f} cm")
    if window == 0.0:
        np.testing.assert_allclose(z[after], z_true[after], atol=0.005)
        np.testing.assert_allclose(lift[after], 0.09, atol=0.005)
    else:
        # the median is 0.05 up to frame 28 (the first frames' look-ahead included), half
        # and half at 29-30, 0.09 from 31 on; the raise follows it with 0.5 s
        np.testing.assert_allclose(lift[:29], 0.05, atol=1e-6)
        assert np.all(np.diff(lift[28:]) > 0)
        assert 0.06 < lift[-1] < 0.08, lift[-1]
        np.testing.assert_allclose(z - lift, z_true - np.where(np.arange(40) < 20, 0.05, 0.09),
                                   atol=0.005)


@pytest.mark.parametrize('known', [True, False])
def test_a_known_pose_takes_its_own_average_and_pull(graph_node, known):
    """A known camera pose's measured roots are averaged over camera_pose_root_half_window
    frames on each side (at most the look-ahead) and pulled in with
    camera_pose_position_time_constant_s; the camera-motion estimate's (fused_root) over
    fusion_measured_root_half_window frames with fusion_measured_position_time_constant_s."""
    import math

    graph, node, out = graph_node(camera_pose_topic='/robot/camera' if known else '',
                                  floor_topic='/floor', lookahead=12,
                                  camera_pose_root_half_window=20,
                                  camera_pose_position_time_constant_s=0.05,
                                  fusion_measured_root_half_window=5,
                                  fusion_measured_position_time_constant_s=0.4)
    online = node._make_online('floor')
    tau = 0.05 if known else 0.4
    assert online.measured_root_half_window == (12 if known else 5)
    assert online.fusion.alpha_p_measured == pytest.approx(
        1.0 - math.exp(-1.0 / (node.fps * tau)))


def _floor_of(R_wc, t_wc):
    """The floor frame of a camera (optical -> world ``R_wc``, ``t_wc``) as the physics
    stage's: z up, origin on the floor below the camera, x along the optical axis projected
    on the floor (floor -> world ``R_wf``, ``t_wf``; ``p_camera = A p_floor + b``)."""
    f = R_wc[:, 2] * np.array([1.0, 1.0, 0.0])
    x = f / np.linalg.norm(f)
    R_wf = np.stack([x, np.cross([0.0, 0.0, 1.0], x), [0.0, 0.0, 1.0]], axis=1)
    t_wf = np.array([t_wc[0], t_wc[1], 0.0])
    return R_wf, t_wf, R_wc.T @ R_wf, R_wc.T @ (t_wf - t_wc)


@pytest.mark.parametrize('camera', ['static', 'turning', 'walking'])
@pytest.mark.parametrize('root', ['lifter', 'input'])
def test_the_frames_the_estimate_fixes_fuse_the_lifters_root(graph_node, root, camera):
    """fused_root lifter: the frames the camera-motion estimate fixes (a static camera, a
    turning one with fuse_rotating, one whose translation was measured) take their horizontal
    position from the lifter's camera-frame root of the same stamp moved by the estimated
    camera motion, the height from the physics input. The physics root here walks at 0.8 of
    the person's speed and 5 cm low: with ``input`` the world path is 0.8 of the walk, with
    ``lifter`` the whole walk. A stamp without a lifter pose is counted and takes its
    neighbours' root (no step there)."""
    from mocap_core import ros_conversions as rc
    from mocap_core import topics
    from mocap_core.rotations import axis_angle_to_matrix as aa

    graph, node, out = graph_node(floor_topic='/floor', fused_root=root, lookahead=10,
                                  fuse_rotating=True,
                                  fusion_static_position_time_constant_s=1e-6,
                                  fusion_position_time_constant_s=1e-6,
                                  fusion_measured_position_time_constant_s=1e-6)
    world = _poses(60)
    t0, R_wc0, *_ = _camera_and_its_floor()
    start = world[0].root_position
    for i, p in enumerate(world):
        # the camera turns about the vertical by 0.4 deg per frame, and walks 1 cm per frame
        turn = 0.0 if camera == 'static' else np.radians(0.4) * i
        R_wc = aa(np.array([0.0, 0.0, turn])) @ R_wc0
        t_wc = t0 + (np.array([0.0, 0.01 * i, 0.0]) if camera == 'walking' else 0.0)
        R_wf, t_wf, A, b = _floor_of(R_wc, t_wc)
        header = rc.make_header(i * DT_NS, 'camera_optical_frame')
        state = {'static': 'static', 'turning': 'rotating', 'walking': 'moving'}[camera]
        graph.publish(topics.CAMERA_MOTION, rc.camera_motion_to_odometry(
            state, matrix_to_quat(R_wc0.T @ R_wc), np.zeros(3),
            rc.make_header(i * DT_NS, 'cam_start'), 'camera_optical_frame',
            position=R_wc0.T @ (t_wc - t0) if camera == 'walking' else None))
        graph.publish('/floor', rc.transform_stamped(header, 'floor', A, b))
        if i != 30:     # the lifter's frame of stamp 30 is missing
            graph.publish(topics.LIFTER_UNSMOOTHED_MOTION, rc.pose_to_motion(
                _in_camera([p], R_wc, t_wc)[0], header))
        rot = np.array(p.rotations)
        rot[0] = matrix_to_quat(R_wf.T @ quat_to_matrix(p.rotations[0]))
        slow = start + 0.8 * (p.root_position - start) + [0.0, 0.0, -0.05]
        in_floor = Pose(p.skeleton, rot, R_wf.T @ (slow - t_wf))
        graph.publish('/in/motion', rc.pose_to_motion(in_floor, rc.make_header(i * DT_NS,
                                                                               'floor')))
    graph.flush()
    v = _values(node)
    assert v['unfused_frames'] == '0', v
    odom = [m for t, m in out if t == topics.WORLD_ODOM]
    assert len(odom) == 60
    T = np.stack([rc.odometry_to_root(m)[0] for m in odom])
    T_true = np.stack([p.root_position for p in world])
    # after the fusion's first frames (its alignment), the path along the walk
    walked = np.linalg.norm(T[-10, :2] - T[20, :2])
    true = np.linalg.norm(T_true[-10, :2] - T_true[20, :2])
    steps = np.linalg.norm(np.diff(T[:, :2], axis=0), axis=1)
    if root == 'lifter':
        assert walked == pytest.approx(true, rel=0.03)
        assert v['fused_root'].startswith(
            "the lifter's root in 60 frames; 1 fixed frames of all persons had none ")
        # every step is the person's (4 cm), stamp 30 without a lifter pose included
        np.testing.assert_allclose(steps[20:50], 0.04, atol=0.005)
    else:
        assert walked == pytest.approx(0.8 * true, rel=0.03)
        assert 'fused_root' not in v
    np.testing.assert_allclose(T[20:, 2], T_true[20:, 2] - 0.05, atol=0.01)


@pytest.mark.parametrize('average', ['root', 'offset'])
def test_the_measured_roots_offset_keeps_the_inputs_steps(graph_node, average):
    """fusion_measured_root_average: a static camera, the physics root walks at 0.8 of the
    person's speed and sways 2 cm sideways at 2 Hz (its body's own motion, which its feet
    follow); the lifter's root is the true one with 1 cm of noise. Both averages give the
    whole walk; 'root' takes the position from the lifter's roots alone (the physics root's
    sway is not used; the noise averaged over 17 frames), 'offset' keeps the physics root's
    sway (its steps from frame to frame) and takes only the slow part from the lifter."""
    from mocap_core import ros_conversions as rc
    from mocap_core import topics

    graph, node, out = graph_node(floor_topic='/floor', fused_root='lifter', lookahead=10,
                                  foot_plant=False,
                                  fusion_measured_root_average=average,
                                  fusion_static_position_time_constant_s=1e-6,
                                  fusion_position_time_constant_s=1e-6,
                                  fusion_measured_position_time_constant_s=1e-6)
    n = 80
    world = _poses(n)
    t_wc, R_wc, *_ = _camera_and_its_floor()
    R_wf, t_wf, A, b = _floor_of(R_wc, t_wc)
    start = world[0].root_position
    sway = 0.02 * np.sin(2 * np.pi * np.arange(n) / 15.0)
    noise = np.random.default_rng(4).normal(0.0, 0.01, (n, 2))
    for i, p in enumerate(world):
        header = rc.make_header(i * DT_NS, 'camera_optical_frame')
        graph.publish(topics.CAMERA_MOTION, rc.camera_motion_to_odometry(
            'static', np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3),
            rc.make_header(i * DT_NS, 'cam_start'), 'camera_optical_frame'))
        graph.publish('/floor', rc.transform_stamped(header, 'floor', A, b))
        seen = Pose(p.skeleton, p.rotations,
                    p.root_position + np.array([noise[i, 0], noise[i, 1], 0.0]))
        graph.publish(topics.LIFTER_UNSMOOTHED_MOTION, rc.pose_to_motion(
            _in_camera([seen], R_wc, t_wc)[0], header))
        rot = np.array(p.rotations)
        rot[0] = matrix_to_quat(R_wf.T @ quat_to_matrix(p.rotations[0]))
        slow = start + 0.8 * (p.root_position - start) + [0.0, sway[i], -0.05]
        graph.publish('/in/motion', rc.pose_to_motion(
            Pose(p.skeleton, rot, R_wf.T @ (slow - t_wf)), rc.make_header(i * DT_NS, 'floor')))
    graph.flush()
    odom = [m for t, m in out if t == topics.WORLD_ODOM]
    assert len(odom) == n
    T = np.stack([rc.odometry_to_root(m)[0] for m in odom])[20:70, :2]
    T_true = np.stack([p.root_position for p in world])[20:70, :2]
    walked = np.linalg.norm(T[-1] - T[0])
    assert walked == pytest.approx(np.linalg.norm(T_true[-1] - T_true[0]), rel=0.05)
    # sideways: the output's distance from its own straight line, against the sway
    c = T - T.mean(axis=0)
    direction = np.linalg.svd(c, full_matrices=False)[2][0]
    side = c @ np.array([-direction[1], direction[0]])
    corr = abs(np.corrcoef(side, sway[20:70])[0, 1])
    if average == 'offset':
        assert corr > 0.9
        assert np.std(side) == pytest.approx(np.std(sway[20:70]), rel=0.25)
    else:
        assert np.std(side) < 0.4 * np.std(sway[20:70])


@pytest.mark.parametrize('frame', ['floor_start', 'floor'])
def test_a_turning_camera_taken_out_by_physics_is_fused_as_a_static_one(graph_node, frame):
    """The physics stage took the camera's rotation out (``derotate_camera``: input frame
    ``floor_start``): frames of a turning camera are fixed like a static camera's, and with
    the static time constants 0 every output is the input moved by one rigid transform. The
    same frames in ``floor`` (a floor frame that turns with the camera) are GMR's."""
    from mocap_core import ros_conversions as rc
    from mocap_core import topics

    graph, node, out = graph_node(fusion_static_position_time_constant_s=0.0)
    n = 50
    poses = [Pose(p.skeleton, p.rotations, p.root_position - [0, 0, 0.1])
             for p in _poses(n, seed=3)]
    for i, p in enumerate(poses):
        turn = matrix_to_quat(axis_angle_to_matrix(np.array([0.0, 0.01 * i, 0.0])))
        graph.publish(topics.CAMERA_MOTION, rc.camera_motion_to_odometry(
            'rotating', turn, np.array([0.0, 0.3, 0.0]), rc.make_header(i * DT_NS, 'cam_start'),
            'cam'))
        graph.publish('/in/motion', rc.pose_to_motion(p, rc.make_header(i * DT_NS, frame)))
    graph.flush()
    v = _values(node)
    odom = [m for t, m in out if t == topics.WORLD_ODOM]
    assert len(odom) == n
    if frame == 'floor':
        assert v['unfused_frames'] == str(n)
        return
    assert v['unfused_frames'] == '0'
    T = np.stack([rc.odometry_to_root(m)[0] for m in odom])
    T_in = np.stack([p.root_position for p in poses])
    # one rigid transform (a turn about z and a shift) maps the input roots onto the output
    d, d_in = np.diff(T, axis=0), np.diff(T_in, axis=0)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), np.linalg.norm(d_in, axis=1),
                               atol=1e-6)
    np.testing.assert_allclose(T[:, 2], T_in[:, 2], atol=1e-6)



def test_a_known_camera_pose_keeps_the_physics_floor_level(graph_node):
    """With a physics floor 5 degrees off the truth, a known camera pose gives the floor
    frame's heading and position along the floor, not its tilt: the world output's root
    orientation is the input's turned about z (one floor for all outputs), and the root
    height is the input's."""
    from mocap_core import ros_conversions as rc
    from mocap_core import topics

    graph, node, out = graph_node(camera_pose_topic='/robot/camera', floor_topic='/floor')
    world = _poses(30)
    t_wc, R_wc, t_wf, R_wf, _, _ = _camera_and_its_floor()
    # the estimated floor frame: the true one tilted by 5 degrees about its x axis
    R_wf = R_wf @ axis_angle_to_matrix(np.array([np.radians(5.0), 0.0, 0.0]))
    A, b = R_wc.T @ R_wf, R_wc.T @ (t_wf - t_wc)
    inputs = []
    for i, p in enumerate(world):
        graph.publish('/robot/camera', rc.root_to_odometry(
            t_wc, matrix_to_quat(R_wc), rc.make_header(i * DT_NS, 'odom'),
            'camera_optical_frame'))
        rot = np.array(p.rotations)
        rot[0] = matrix_to_quat(R_wf.T @ quat_to_matrix(p.rotations[0]))
        inputs.append(Pose(p.skeleton, rot, R_wf.T @ (p.root_position - t_wf)))
        graph.publish('/floor', rc.transform_stamped(
            rc.make_header(i * DT_NS, 'camera_optical_frame'), 'floor', A, b))
        graph.publish('/in/motion', rc.pose_to_motion(inputs[-1],
                                                      rc.make_header(i * DT_NS, 'floor')))
    graph.flush()
    odom = [m for t, m in out if t == topics.WORLD_ODOM]
    assert len(odom) == 30
    for m, p in list(zip(odom, inputs))[1:]:
        T, q = rc.odometry_to_root(m)
        turn = quat_to_matrix(q) @ quat_to_matrix(p.rotations[0]).T
        assert turn[2, 2] > 1 - 1e-6                  # a turn about z only
        assert T[2] == pytest.approx(p.root_position[2], abs=1e-6)


def test_the_first_frame_with_a_known_pose_is_placed_not_pulled(graph_node):
    """Frames before the first known camera pose are GMR's, from its own origin; the first
    frame with a pose is placed where the pose puts it (not pulled there over the next
    frames, which the default time constants would make a 2-3 m slide of the feet)."""
    from mocap_core import ros_conversions as rc
    from mocap_core import topics
    from mocap_core.data.synth2d import look_at

    graph, node, out = graph_node(camera_pose_topic='/robot/camera')
    world = [Pose(p.skeleton, p.rotations, p.root_position + [4.0, -2.0, 0.0])
             for p in _poses(20)]
    t_wc = np.array([-2.0, 3.0, 1.4])
    R_wc = look_at(t_wc, np.array([1.0, 0.5, 0.9])).T
    seen = _in_camera(world, R_wc, t_wc)
    for i, p in enumerate(seen):
        if i >= 3:
            graph.publish('/robot/camera', rc.root_to_odometry(
                t_wc, matrix_to_quat(R_wc), rc.make_header(i * DT_NS, 'odom'),
                'camera_optical_frame'))
        graph.publish('/in/motion', rc.pose_to_motion(
            p, rc.make_header(i * DT_NS, 'camera_optical_frame')))
    graph.flush()
    odom = [m for t, m in out if t == topics.WORLD_ODOM]
    assert len(odom) == 20
    T = np.stack([rc.odometry_to_root(m)[0] for m in odom])
    np.testing.assert_allclose(T[3], world[3].root_position, atol=1e-6)
    assert np.linalg.norm(T[2] - world[2].root_position) > 1.0     # GMR's own origin before
    assert np.linalg.norm(np.diff(T[3:], axis=0), axis=1).max() < 0.1
