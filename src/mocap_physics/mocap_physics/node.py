"""``ros2 run mocap_physics physics``: physics-based correction of the lifter's motion, live.

The dynamic cycle of neural PhysCap (§3.4; :mod:`mocap_physics.cycle`, fixed PD gains) on a
Pinocchio model of the incoming skeleton: PD control towards the kinematic pose, ground
reaction forces in friction pyramids, forward dynamics and a QP that forbids foot-floor
penetration.

Subscribes:
  * ``motion_topic`` (default ``/mocap/lifter/motion``, trajectory_msgs/MultiDOFJointTrajectory):
    the kinematic target; it carries the skeleton (bone offsets), so the Pinocchio model is
    built from it and rebuilt when a bone changes by more than ``skeleton_tolerance``;
  * ``contacts_topic`` (default ``/mocap/lifter/contacts``, sensor_msgs/JointState: names =
    ``left_heel, left_toe, right_heel, right_toe``, position = probabilities): matched to the
    motion by stamp; a motion frame waits up to ``contacts_wait_s`` for its contacts, then
    uses the newest older ones (at most ``contacts_max_age_s`` old) or none (contact from
    the kinematics only).

Publishes, stamped with the input's stamp, in the floor frame (z up, floor z = 0):
  * ``/mocap/physics/motion``, ``/joints3d``, ``/joint_states`` (``effort`` = joint torques of
    the URDF's z, y, x revolute joints, N m);
  * ``/mocap/physics/grf/left``, ``/right`` (geometry_msgs/WrenchStamped): the foot's ground
    reaction force (N, floor axes) and its moment (N m) about the foot's reference point, the
    midpoint of its heel and toe contact points (not about the frame origin);
  * ``/mocap/physics/com`` (geometry_msgs/PointStamped): the centre of mass;
  * ``/mocap/physics/markers``: stick figure, contact states (red = force), force arrows;
  * ``/diagnostics``: processing time, rates, solver status and time, residual root force
    over body weight, counters of fallbacks, solver failures, re-initialisations, time jumps.

Floor frame (``floor_source``): ``input`` - the input already is in a floor frame (e.g. the
ground-truth motion in ``world``), outputs use the input's frame_id; ``camera_params`` - the
input is in the camera optical frame, the floor frame is below the camera at
``camera_height`` m with the camera pitched down by ``camera_pitch_deg`` (no roll), outputs use
``frame_id`` (default ``floor``): p_floor = R p_camera + (0, 0, camera_height), see
:mod:`mocap_physics.floor`. Estimating the floor from the feet is a later step.

Bad input never stops the node: malformed or NaN motion is logged and dropped (or held by the
cycle), a non-increasing stamp is dropped, a degenerate skeleton is reported and skipped, a
solver failure falls back to the kinematic target for that frame, a time jump re-initialises
the simulation; all are counted on /diagnostics.
"""

from __future__ import annotations

import collections
import sys
import time
from typing import Deque, List, Optional, Tuple

import numpy as np

from mocap_core.parameters import ParamSpec, declare_parameters, help_requested

from .cycle import PhysicsParams

_D = PhysicsParams()

PARAMETERS = (
    ParamSpec('motion_topic', '/mocap/lifter/motion', 'Input motion (kinematic target), '
              'MultiDOFJointTrajectory', read_only=True),
    ParamSpec('contacts_topic', '/mocap/lifter/contacts', 'Input foot contact probabilities '
              '(JointState: heel/toe, left/right); empty = none', read_only=True),
    ParamSpec('contacts_wait_s', 0.05, 'Longest wait (wall clock) of a motion frame for the '
              'contacts with its stamp', min_value=0.0, max_value=5.0),
    ParamSpec('contacts_max_age_s', 0.1, 'Otherwise use the newest older contacts if at most '
              'this old (stamp time), else none', min_value=0.0),
    ParamSpec('body_mass', _D.body_mass, 'Body mass, kg (segment masses: de Leva 1996)',
              min_value=1.0, max_value=500.0, read_only=True),
    ParamSpec('gains_mode', 'fixed', 'PD gains: fixed (kp/kd below); learned (DyNet) is not '
              'available yet', read_only=True),
    ParamSpec('kp_root', _D.kp_root, 'PD stiffness of the root, s^-2 (acceleration per unit '
              'error, multiplied by M(q))', min_value=0.0, read_only=True),
    ParamSpec('kd_root', _D.kd_root, 'PD damping of the root, s^-1', min_value=0.0,
              read_only=True),
    ParamSpec('kp_joint', _D.kp_joint, 'PD stiffness of the ball joints, s^-2 (default: '
              '60 rad/s natural frequency, critically damped with kd 120)', min_value=0.0,
              read_only=True),
    ParamSpec('kd_joint', _D.kd_joint, 'PD damping of the ball joints, s^-1', min_value=0.0,
              read_only=True),
    ParamSpec('substeps', _D.substeps, 'Simulation sub-steps per frame (k, paper: 6)',
              min_value=1, max_value=100, read_only=True),
    ParamSpec('friction', _D.friction, 'Friction coefficient mu (friction cone as its '
              'inscribed pyramid)', min_value=0.01, max_value=5.0, read_only=True),
    ParamSpec('contact_threshold', _D.contact_probability_threshold, 'Contact probability '
              'above which a foot point may take a force', min_value=0.0, max_value=1.0,
              read_only=True),
    ParamSpec('contact_height', _D.contact_height, 'A contact point takes a force only when '
              'within this height of the floor, m', min_value=0.0, read_only=True),
    ParamSpec('grf_smoothness', _D.grf_smoothness, 'Weight of the temporal smoothness of the '
              'ground reaction forces (eq. 11) relative to the root residual (eq. 8)',
              min_value=0.0, read_only=True),
    ParamSpec('root_residual', _D.root_residual, 'Share of the residual direct root actuation '
              'that is applied: 1 = paper; 0 = root driven by contact forces and gravity only',
              min_value=0.0, max_value=1.0, read_only=True),
    ParamSpec('penetration_metric', _D.penetration_metric, 'Metric of the penetration QP: '
              'identity (paper), mass (M) or diagonal (diag M)', read_only=True),
    ParamSpec('max_frame_gap_s', _D.max_frame_gap, 'A longer gap between frames (stamp time) '
              're-initialises the simulation from the target', min_value=0.001, read_only=True),
    ParamSpec('skeleton_tolerance', _D.skeleton_tolerance, 'Bone offset change (m) that '
              'rebuilds the model', min_value=0.0, read_only=True),
    ParamSpec('floor_source', 'input', 'Floor frame: input (input is already in a floor '
              'frame, z up, floor z = 0) or camera_params (input in the camera optical frame; '
              'camera_height, camera_pitch_deg)', read_only=True),
    ParamSpec('camera_height', 1.5, 'floor_source camera_params: camera height above the '
              'floor, m', min_value=0.0, read_only=True),
    ParamSpec('camera_pitch_deg', 0.0, 'floor_source camera_params: camera pitch down from '
              'horizontal, degrees', min_value=-90.0, max_value=90.0, read_only=True),
    ParamSpec('frame_id', '', 'frame_id of the outputs; empty = the input\'s (floor_source '
              'input) or "floor" (camera_params)', read_only=True),
    ParamSpec('publish_markers', True, 'Publish /mocap/physics/markers', read_only=True),
)

OUT = '/mocap/physics'


def main(args: Optional[List[str]] = None) -> int:
    if help_requested(sys.argv[1:] if args is None else list(args), __doc__, PARAMETERS):
        return 0

    import rclpy
    from geometry_msgs.msg import PointStamped, WrenchStamped
    from rclpy.executors import ExternalShutdownException
    from rclpy.node import Node
    from sensor_msgs.msg import JointState, PointCloud2
    from trajectory_msgs.msg import MultiDOFJointTrajectory
    from visualization_msgs.msg import MarkerArray

    from mocap_core.diagnostics import NodeDiagnostics
    from mocap_core.qos import STREAM_QOS
    from mocap_core.ros_conversions import (MessageError, make_header, motion_to_pose,
                                            msg_to_contacts, pose_to_joint_state,
                                            pose_to_markers, pose_to_motion,
                                            positions_to_cloud, stamp_to_ns, wrench_to_msg)

    from .cycle import InvalidInput, PhysicsCycle
    from .floor import FloorFrame
    from .model import SkeletonError, revolute_efforts

    class PhysicsNode(Node):
        def __init__(self) -> None:
            super().__init__('physics')
            self.p = p = declare_parameters(self, PARAMETERS)
            if p['gains_mode'] != 'fixed':
                raise ValueError(f"gains_mode {p['gains_mode']!r}: only 'fixed' is available")
            self.params = PhysicsParams(
                body_mass=p['body_mass'], substeps=p['substeps'], kp_root=p['kp_root'],
                kd_root=p['kd_root'], kp_joint=p['kp_joint'], kd_joint=p['kd_joint'],
                friction=p['friction'], contact_probability_threshold=p['contact_threshold'],
                contact_height=p['contact_height'], grf_smoothness=p['grf_smoothness'],
                root_residual=p['root_residual'], penetration_metric=p['penetration_metric'],
                max_frame_gap=p['max_frame_gap_s'], skeleton_tolerance=p['skeleton_tolerance'])
            self.cycle = PhysicsCycle(params=self.params)      # validates the parameters
            if p['floor_source'] == 'input':
                self.floor: Optional[FloorFrame] = None
            elif p['floor_source'] == 'camera_params':
                self.floor = FloorFrame.from_camera_height_pitch(
                    p['camera_height'], np.deg2rad(p['camera_pitch_deg']))
            else:
                raise ValueError(f"floor_source {p['floor_source']!r}: use input or "
                                 'camera_params')
            self.pub_motion = self.create_publisher(MultiDOFJointTrajectory, OUT + '/motion',
                                                    STREAM_QOS)
            self.pub_joints = self.create_publisher(PointCloud2, OUT + '/joints3d', STREAM_QOS)
            self.pub_states = self.create_publisher(JointState, OUT + '/joint_states',
                                                    STREAM_QOS)
            self.pub_grf = {f: self.create_publisher(WrenchStamped, f'{OUT}/grf/{f}', STREAM_QOS)
                            for f in ('left', 'right')}
            self.pub_com = self.create_publisher(PointStamped, OUT + '/com', STREAM_QOS)
            self.pub_markers = (self.create_publisher(MarkerArray, OUT + '/markers', STREAM_QOS)
                                if p['publish_markers'] else None)
            self.diag = NodeDiagnostics(self, 'physics', hardware_id='cpu')
            self.diag.set_value('gains', 'fixed')
            self.diag.set_value('model', 'none yet (waiting for the first motion)')
            self.pending: Deque[Tuple[int, object, str, float]] = collections.deque()
            self.contacts: 'collections.OrderedDict[int, np.ndarray]' = collections.OrderedDict()
            self.last_stamp = -1
            self.last_result = None
            self._limited = {}
            self.create_subscription(MultiDOFJointTrajectory, p['motion_topic'], self._on_motion,
                                     STREAM_QOS)
            self.contacts_sub = None
            if p['contacts_topic']:
                self.contacts_sub = self.create_subscription(
                    JointState, p['contacts_topic'], self._on_contacts, STREAM_QOS)
            self.create_timer(0.01, self._process)
            self.create_timer(1.0, self._refresh_diagnostics)
            self.get_logger().info(
                f"physics on {p['motion_topic']} (contacts: {p['contacts_topic'] or 'none'}); "
                f"k={p['substeps']}, kp={p['kp_joint']:g}, kd={p['kd_joint']:g}, "
                f"mu={p['friction']:g}, floor: {p['floor_source']}")

        # -- helpers -------------------------------------------------------------------------
        def _warn_limited(self, key: str, text: str, period_s: float = 5.0) -> None:
            now = time.monotonic()
            if now - self._limited.get(key, -1e9) >= period_s:
                self._limited[key] = now
                self.get_logger().warn(text)

        def _problem(self, key: str, text: str) -> None:
            self.diag.errors += 1
            self.diag.warn(text)
            self._warn_limited(key, text)

        # -- input ---------------------------------------------------------------------------
        def _on_contacts(self, msg: JointState) -> None:
            try:
                probs = msg_to_contacts(msg)
            except MessageError as exc:
                self._problem('contacts', f"ignoring {self.p['contacts_topic']}: {exc}")
                return
            self.contacts[stamp_to_ns(msg.header.stamp)] = probs
            while len(self.contacts) > 256:
                self.contacts.popitem(last=False)
            self._process()

        def _on_motion(self, msg: MultiDOFJointTrajectory) -> None:
            self.diag.input.tick()
            stamp = stamp_to_ns(msg.header.stamp)
            if stamp <= self.last_stamp or (self.pending and stamp <= self.pending[-1][0]):
                self.diag.dropped += 1
                self._problem('order', f'motion stamp {stamp} ns is not after the previous '
                              'one (time went backwards or a duplicate): dropped')
                return
            try:
                pose = motion_to_pose(msg)
            except MessageError as exc:
                self.diag.dropped += 1
                self._problem('motion', f'dropping a motion message: {exc}')
                return
            self.pending.append((stamp, pose, msg.header.frame_id, time.monotonic()))
            self._process()

        def _contacts_for(self, stamp: int, waited: float) -> Tuple[bool, Optional[np.ndarray]]:
            """(ready, probabilities) for a motion frame."""
            if stamp in self.contacts:
                return True, self.contacts[stamp]
            expecting = (self.contacts_sub is not None
                         and self.count_publishers(self.p['contacts_topic']) > 0)
            if expecting and waited < self.p['contacts_wait_s'] and \
                    not any(s > stamp for s in self.contacts):
                return False, None
            older = [s for s in self.contacts if s < stamp]
            if older and stamp - max(older) <= self.p['contacts_max_age_s'] * 1e9:
                return True, self.contacts[max(older)]
            return True, None

        def _process(self) -> None:
            while self.pending:
                stamp, pose, frame_id, t_in = self.pending[0]
                ready, probs = self._contacts_for(stamp, time.monotonic() - t_in)
                if not ready:
                    return
                self.pending.popleft()
                self._step(stamp, pose, frame_id, probs)

        # -- the cycle -----------------------------------------------------------------------
        def _step(self, stamp: int, pose, frame_id: str, probs) -> None:
            if probs is None and self.contacts_sub is not None:
                self._warn_limited('nocontacts', 'no contact probabilities for this frame: '
                                   'contacts from the kinematics only', 10.0)
            if self.floor is not None:
                pose = self.floor.transform_pose(pose)
                frame_id = self.p['frame_id'] or 'floor'
            else:
                frame_id = self.p['frame_id'] or frame_id or 'world'
            try:
                with self.diag.processing():
                    res = self.cycle.step(pose, stamp * 1e-9, probs)
            except (InvalidInput, SkeletonError) as exc:
                self.diag.dropped += 1
                self._problem('skeleton', f'skipping a frame: {exc}')
                return
            except Exception as exc:  # never die on one frame
                self.diag.dropped += 1
                self._problem('step', f'physics step failed ({type(exc).__name__}: {exc}); '
                              'frame skipped')
                return
            for m in res.messages:
                self._warn_limited(m.split(':')[0], m)
            if res.status not in ('ok', 'first_frame'):
                self.diag.warn(f'{res.status}: {"; ".join(res.messages)}'
                               if res.messages else res.status)
            self.last_stamp = stamp
            self.last_result = res
            self._publish(stamp, frame_id, res)
            self.diag.output.tick()

        def _publish(self, stamp: int, frame_id: str, res) -> None:
            header = make_header(stamp, frame_id)
            pose = res.pose
            self.pub_motion.publish(pose_to_motion(pose, header))
            self.pub_joints.publish(positions_to_cloud(pose.joint_positions(), header))
            efforts = revolute_efforts(pose.revolute_angles(), res.joint_torques.reshape(-1, 3))
            self.pub_states.publish(pose_to_joint_state(pose, header, efforts))
            for foot, pub in self.pub_grf.items():
                w = res.feet[foot]
                pub.publish(wrench_to_msg(w.force, w.moment, header))
            com = PointStamped(header=header)
            com.point.x, com.point.y, com.point.z = (float(c) for c in res.center_of_mass)
            self.pub_com.publish(com)
            if self.pub_markers is not None:
                names = self.cycle.model.contact_names
                forces = {n: res.contact_forces[i] for i, n in enumerate(names)
                          if res.contact_active[i]}
                self.pub_markers.publish(pose_to_markers(
                    pose, header, ns='physics', color=(1.0, 0.6, 0.1, 1.0),
                    contacts=res.contact_active.astype(float), forces=forces))

        def _refresh_diagnostics(self) -> None:
            st = self.cycle.stats
            d = self.diag
            if self.cycle.model is not None:
                d.set_value('model', f'{self.cycle.model.nv} DoF, '
                            f'{self.cycle.model.body_mass:g} kg')
            d.set_value('fallbacks', st.fallbacks)
            d.set_value('grf_solver_failures', st.grf_failures)
            d.set_value('penetration_solver_failures', st.penetration_failures)
            d.set_value('penetration_qp_solves', st.penetration_solves)
            d.set_value('reinitialisations', st.reinitialisations)
            d.set_value('time_jumps', st.time_jumps)
            d.set_value('invalid_inputs', st.invalid_inputs)
            d.set_value('model_builds', st.model_builds)
            r = self.last_result
            if r is not None:
                d.set_value('last_status', r.status)
                d.set_value('residual_root_force_over_weight', f'{r.residual_ratio:.4f}')
                d.set_value('grf_qp_ms', f'{r.time_grf_qp * 1e3:.3f}')
                d.set_value('penetration_qp_ms', f'{r.time_penetration_qp * 1e3:.3f}')
                d.set_value('substeps', r.substeps)
            if r is not None and r.status == 'ok' and not self.pending:
                d.warn(None)

    rclpy.init(args=args)
    node = None
    try:
        node = PhysicsNode()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ValueError as exc:   # bad parameters
        print(f'physics: {exc}', file=sys.stderr)
        return 2
    finally:
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
