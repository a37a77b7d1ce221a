"""``ros2 run mocap_physics physics``: physics-based correction of the lifter's motion, live.

The dynamic cycle of neural PhysCap (§3.4; :mod:`mocap_physics.cycle`; fixed PD gains, or
DyNet's learned ones with ``gains_mode: learned``) on a Pinocchio model of the incoming
skeleton: PD control towards the kinematic pose, ground reaction forces in friction
pyramids, forward dynamics and a QP that forbids foot-floor penetration and holds the feet
in contact in place (``foot_stick``).

Subscribes:
  * ``motion_topic`` (default ``/mocap/lifter/motion``, trajectory_msgs/MultiDOFJointTrajectory):
    the kinematic target; it carries the skeleton (bone offsets), so the Pinocchio model is
    built from it and rebuilt when a bone changes by more than ``skeleton_tolerance``;
  * ``contacts_topic`` (default ``/mocap/lifter/contacts``, sensor_msgs/JointState: names =
    ``left_heel, left_toe, right_heel, right_toe``, position = probabilities): matched to the
    motion by stamp; a motion frame waits up to ``contacts_wait_s`` for its contacts, then
    uses the newest older ones (at most ``contacts_max_age_s`` old) or none (contact from
    the kinematics only);
  * ``camera_motion_topic`` (default ``/mocap/camera/motion``, nav_msgs/Odometry, the keypoint
    node's estimate): its state by stamp decides where the stance drift is followed
    (``stance_drift_s``: only where the camera is not ``static``; the floor frame then
    follows the drift of the target's stance feet, so that with a moving camera the feet
    stand in the world; docs/physics.md, "Stance drift"). With ``derotate_camera``: the
    camera's rotation since the first image by stamp. Each input pose is turned by its
    frame's rotation into the first image's camera frame before the floor estimate and the
    simulation
    (:mod:`mocap_physics.camera_rotation`), so that a turning camera does not move the feet;
    the outputs are then in ``floor_start``, the floor frame of the first image, and the
    floor message stays the floor seen from each frame's camera. A frame without its own
    estimate holds the newest one before it (counted). With ``carry_with_camera`` instead,
    the outputs stay in the camera's floor frame and the simulated state is carried with
    the camera's motion from frame to frame: its turn about the floor's normal and its step
    along the floor where the keypoint node measured it (frames without a measured step
    coast on the last velocity for ``camera_translation_coast_s``), or a known camera pose
    (``camera_pose_topic``).

Publishes, stamped with the input's stamp, in the floor frame (z up, floor z = 0):
  * ``/mocap/physics/motion``, ``/joints3d``, ``/joint_states`` (``effort`` = joint torques of
    the URDF's z, y, x revolute joints, N m);
  * ``/mocap/physics/grf/left``, ``/right`` (geometry_msgs/WrenchStamped): the foot's ground
    reaction force (N, floor axes) and its moment (N m) about the foot's reference point, the
    midpoint of its heel and toe contact points (not about the frame origin);
  * ``/mocap/physics/com`` (geometry_msgs/PointStamped): the centre of mass;
  * ``/mocap/physics/markers``: stick figure, contact states (red = force), force arrows
    (ids 10-13, one per contact point, zero length without force) and the friction cones
    (namespace ``physics_friction_cones``: LINE_LIST of the cone mu at each contact point
    that takes a force);
  * ``/mocap/physics/floor`` (geometry_msgs/TransformStamped, every frame; not with
    ``floor_source: input``): the floor frame in the input's frame, header.frame_id = the
    input's frame (e.g. ``camera_optical_frame``), child_frame_id = the outputs' frame
    (``floor``): ``p_camera = R p_floor + t``, as tf2 stores a transform;
  * ``/diagnostics``: processing time, rates, solver status and time, residual root force
    over body weight, counters of fallbacks, solver failures, re-initialisations, time jumps.

Several people (docs/multi_person.md): ``bodies_motion_topic`` and ``bodies_contacts_topic``
(default ``/mocap/lifter/bodies/...``, names prefixed ``body_<id>/``) carry every person; once
they deliver, each person is simulated on their own (own contacts matching, floor estimate and
state, ended ``person_timeout_s`` after last seen) and ``motion_topic`` is ignored. Each
person's output goes to ``/humans/bodies/body_<id>/physics/{motion,joints3d,joint_states,
grf/left,grf/right}``, every person to ``/mocap/physics/bodies/{motion,joints3d,markers}``,
and the main person (the smallest id present: the one tracked longest) to the single-person
topics above. Every output but the motion and ``/diagnostics`` is built only while it has a
subscriber.

Floor frame (``floor_source``, :mod:`mocap_physics.floor`): the dynamics and the outputs are
in a floor frame (z up, floor z = 0, x = the camera's viewing direction on the floor, origin
below the camera): p_floor = R p_camera + (0, 0, camera height).

  * ``estimate`` (default): the input is in the camera optical frame; the floor plane is
    fitted to the heel and toe points of the incoming motion while their contact
    probability is above ``floor_contact_threshold``, over the last ``floor_window`` frames,
    re-fitted every ``floor_update_every`` frames (RANSAC + least squares regularised towards
    the body's mean up direction). It starts provisional (the body's up direction through
    the lowest foot point) and is replaced when a fit moves it by more than 0.5 deg or
    1 cm, blended in over ``floor_blend_frames`` frames; the simulation state is carried
    over into each new frame. ``floor_freeze_after`` > 0 fixes it after that many frames.
  * ``camera_params``: a level floor ``camera_height`` m below a camera pitched down by
    ``camera_pitch_deg`` (no roll).
  * ``input``: the input already is in a floor frame (e.g. ground-truth motion in
    ``world``); outputs use the input's frame_id.

Bad input never stops the node: malformed or NaN motion is logged and dropped (or held by the
cycle), a non-increasing stamp is dropped, a degenerate skeleton is reported and skipped, a
solver failure falls back to the kinematic target for that frame, a time jump re-initialises
the simulation; all are counted on /diagnostics. A callback that raises drops its frame
(:func:`mocap_core.guard.guarded`). The streaming logic (contacts matched by stamp, floor,
cycle) is :class:`mocap_physics.online.OnlinePhysics`; this module only converts messages.
Unusable ``gains_mode: learned`` weights (missing, corrupt, crafted, wrong size) end the node
at start with exit status 2 and one line ``physics: error: ...``.
"""


from __future__ import annotations

import collections
import os
import sys
from typing import Dict, List, Optional, Tuple

import numpy as np
from geometry_msgs.msg import PointStamped, TransformStamped, WrenchStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from sensor_msgs.msg import JointState, PointCloud2
from trajectory_msgs.msg import MultiDOFJointTrajectory
from visualization_msgs.msg import MarkerArray

from mocap_core import topics
from mocap_core.bodies import BodyPublishers, CombinedPublishers, by_stamp
from mocap_core import cdr
from mocap_core.camera_pose import KnownCameraPoses, known_camera_poses
from mocap_core.publishing import publish_if_heard
from mocap_core.diagnostics import NodeDiagnostics
from mocap_core.guard import KeyedRateLimit, deserialised_unless, guarded
from mocap_core.parameters import (ParamSpec, camera_pose_params, declare_parameters,
                                   help_requested, spin_node)
from mocap_core.qos import STREAM_QOS, input_qos
from mocap_core.ros_conversions import (MessageError, make_header, motion_to_bodies,
                                        motion_to_pose, msg_to_bodies_contacts,
                                        msg_to_contacts, odometry_to_camera_motion,
                                        odometry_to_camera_position, pose_marker_specs,
                                        camera_pose_from_msg, camera_pose_message_type,
                                        stamp_to_ns)
from mocap_core.rotations import quat_to_matrix

from .cycle_params import PhysicsParams
from .floor import FloorFrame, FloorTracker, FloorTrackerParams, UprightPrior
from .foot import TEMPLATE_FLAT_FOOT_PITCH_DEG, contact_positions
from .markers import floor_transform_msg, friction_cone_spec
from .model import revolute_efforts
from .camera_rotation import START_FLOOR_FRAME, CameraRotations, floor_in_camera, rotate_pose
from .online import FloorSource, Notice, OnlinePhysics, PhysicsFrame

_D = PhysicsParams()
#: the stance drift takes the newest camera-motion state at most this much older than a
#: frame without its own
CAMERA_STATE_MAX_AGE_NS = 500_000_000
_F = FloorTrackerParams()
#: frames over which upright_from_camera_pose averages the body's up (2 s at 30 fps)
UPRIGHT_WINDOW_FRAMES = 60

PARAMETERS = (
    ParamSpec('motion_topic', topics.LIFTER_MOTION, 'Input motion (kinematic target), '
              'MultiDOFJointTrajectory', read_only=True),
    ParamSpec('contacts_topic', topics.LIFTER_CONTACTS, 'Input foot contact probabilities '
              '(JointState: heel/toe, left/right); empty = none', read_only=True),
    ParamSpec('camera_motion_topic', topics.CAMERA_MOTION, 'The keypoint node\'s camera-motion '
              'estimate (nav_msgs/Odometry: the camera\'s orientation since the first image); '
              'used with derotate_camera; empty = none', read_only=True),
    ParamSpec('derotate_camera', False, 'Take the camera\'s rotation since the first image '
              '(camera_motion_topic) out of each input pose before the floor estimate and the '
              'simulation, so that a turning camera does not move the feet: outputs in the '
              'floor frame of the first image (frame_id floor_start); the floor message stays '
              'the floor in the current camera frame. Only with floor_source estimate or '
              'camera_params', read_only=True),
    ParamSpec('carry_with_camera', False, 'Carry the simulated body, its stance feet and its '
              'last target with the camera\'s motion between frames as the keypoint node '
              'estimates it (camera_motion_topic: the turn about the floor\'s normal and, where '
              'measured over the floor, the step along it), so that a foot that stands in the '
              'world keeps standing while the camera turns or walks; the outputs stay in the '
              'camera\'s floor frame (frame_id floor). Not with derotate_camera. Off by '
              'default: the estimate\'s steps are too rough (docs/physics.md)', read_only=True),
    *camera_pose_params(
        'the simulated body is carried with it as with carry_with_camera, whatever that '
        'says (not with derotate_camera); empty = none',
        'the frame is not carried'),
    ParamSpec('floor_from_camera_pose', False, 'With a known camera pose (camera_pose_topic) '
              'and floor_source estimate: the floor\'s normal is the pose frame\'s z (gravity, '
              'REP-103) seen from each frame\'s camera, and only its height is fitted to the '
              'stance feet, each frame\'s moved into that frame by its pose; false: the floor '
              'is fitted to the feet in the camera frame as without a pose (docs/physics.md)',
              read_only=True),
    ParamSpec('upright_from_camera_pose', False, 'With a known camera pose '
              '(camera_pose_topic): turn each target about its root so that its body is '
              'upright on average over the last 60 frames in the pose frame\'s gravity (z up), at '
              'most 10 deg: the lean toward the camera that its pitch hides '
              '(docs/physics.md; measured, off by default)', read_only=True),
    ParamSpec('camera_translation_coast_s', 0.5, 'carry_with_camera: a frame whose camera step '
              'was not measured moves the camera by its last measured velocity for this long '
              'after the last measurement, then not at all', min_value=0.0, max_value=10.0,
              read_only=True),
    ParamSpec('contacts_wait_s', 0.05, 'Longest wait (wall clock) of a motion frame for the '
              'contacts with its stamp', min_value=0.0, max_value=5.0),
    ParamSpec('contacts_max_age_s', 0.1, 'Otherwise use the newest older contacts if at most '
              'this old (stamp time), else none', min_value=0.0),
    ParamSpec('bodies_motion_topic', topics.bodies_topic('lifter', 'motion'), 'Input motion '
              'of every person (names prefixed body_<id>/); once it delivers, each person is '
              'simulated on their own and motion_topic is ignored; empty = one person only',
              read_only=True),
    ParamSpec('bodies_contacts_topic', topics.bodies_topic('lifter', 'contacts'), 'Input '
              'foot contacts of every person (names prefixed body_<id>/)', read_only=True),
    ParamSpec('person_timeout_s', 1.0, 'A person absent from the input for longer than this '
              '(stamps) is dropped: their state and per-person topics are removed',
              min_value=0.0, read_only=True),
    ParamSpec('queue_depth', 100, 'Input messages queued while a frame is processed (older '
              'ones are lost when the queue is full)', min_value=1, read_only=True),
    ParamSpec('body_mass', _D.body_mass, 'Body mass, kg (segment masses: de Leva 1996)',
              min_value=1.0, max_value=500.0, read_only=True),
    ParamSpec('gains_mode', 'fixed', 'PD gains: fixed (kp/kd below) or learned (DyNet, '
              'dynet_weights; kp/kd below are its kp_ini)', read_only=True),
    ParamSpec('dynet_weights', '', 'gains_mode learned: DyNet weights (mocap train physics); '
              'empty = the package\'s weights/dynet.pt', read_only=True),
    ParamSpec('kp_root', _D.kp_root, 'PD stiffness of the root, s^-2 (acceleration per unit '
              'error, multiplied by M(q))', min_value=0.0, read_only=True),
    ParamSpec('kd_root', _D.kd_root, 'PD damping of the root, s^-1 (default: 20 rad/s, '
              'critically damped with kp 400)', min_value=0.0, read_only=True),
    ParamSpec('kp_joint', _D.kp_joint, 'PD stiffness of the ball joints, s^-2 (default: '
              '60 rad/s natural frequency, critically damped with kd 120); frames of a moving '
              'camera take kp_joint_moving', min_value=0.0,
              read_only=True),
    ParamSpec('kd_joint', _D.kd_joint, 'PD damping of the ball joints, s^-1 (frames of a '
              'moving camera: kd_joint_moving)', min_value=0.0,
              read_only=True),
    ParamSpec('kp_joint_moving', _D.kp_joint_moving, 'PD stiffness of the ball joints in '
              'frames whose camera the camera-motion estimate does not call static and whose '
              'motion is not carried (the floor frame rides with the camera, so the target '
              'moves by the camera\'s motion too and the PD would trail it), s^-2 (default: 90 '
              'rad/s, critically damped with kd 180; travel set PA-MPJPE cost +4.5 -> +3.0 '
              'mm); 0 = kp_joint. Unused with derotate_camera, a carried body, floor_source '
              'input or learned gains (docs/physics.md)', min_value=0.0, read_only=True),
    ParamSpec('kd_joint_moving', _D.kd_joint_moving, 'PD damping of the ball joints in those '
              'frames, s^-1; 0 = kd_joint', min_value=0.0, read_only=True),
    ParamSpec('velocity_feedforward', _D.velocity_feedforward, 'PD damping against the '
              "target's velocity (kd o (qdot_hat - qdot), qdot_hat differenced from the last "
              'two targets) instead of against zero velocity (-kd o qdot)', read_only=True),
    ParamSpec('substeps', _D.substeps, 'Simulation sub-steps per frame (k; the paper: 6; '
              'at least one per 1/120 s of frame period)',
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
    ParamSpec('dynamics', _D.dynamics, 'whole_body: one inverse-dynamics QP per sub-step '
              '(torques, stance forces in friction cones, bounded root residual) drives the '
              'forward dynamics; paper: eq. 13 of neural PhysCap (residual root actuation, '
              'PD filter, foot stick)', read_only=True),
    ParamSpec('residual_weight', _D.residual_weight, 'whole_body: weight of the root '
              'residual (vertical force, moments; body-weight units)', min_value=1e-6,
              read_only=True),
    ParamSpec('residual_horizontal_weight', _D.residual_horizontal_weight, 'whole_body: '
              'weight of the horizontal root residual force (body-weight units)',
              min_value=1e-6, read_only=True),
    ParamSpec('free_limb_weight', _D.free_limb_weight, 'whole_body: factor on the QP\'s '
              'tracking weights of the joints that carry no stance point (arms, trunk, head, '
              'a swinging leg): above 1 these follow the PD more closely, and the root and the '
              'stance legs take up what the forces cannot explain (docs/physics.md)',
              min_value=1e-6, read_only=True),
    ParamSpec('stance_leg_weight', _D.stance_leg_weight, 'whole_body: the same factor for '
              'the joints of a leg with a point in stance (docs/physics.md)', min_value=1e-6,
              read_only=True),
    ParamSpec('residual_bound', _D.residual_bound, 'whole_body: bound of each residual root '
              'force component, body weights (reaching it is counted in diagnostics)',
              min_value=0.0, read_only=True),
    ParamSpec('residual_moment_bound', _D.residual_moment_bound, 'whole_body: bound of each '
              'residual root moment component, body weight x m', min_value=0.0,
              read_only=True),
    ParamSpec('stance_release', _D.stance_release, 'whole_body: a stance point\'s anchor '
              'follows the target point when it is farther than this, at most stick_speed, m',
              min_value=0.0, read_only=True),
    ParamSpec('stick_speed', _D.stick_speed, 'Fastest a dragged stance / stick anchor moves '
              'after its target point (stance_release, stick_release), m/s', min_value=0.0,
              read_only=True),
    ParamSpec('root_follow_gain', _D.root_follow_gain, 'whole_body: per frame the target '
              'root moves this share of the way to where the stance feet\'s targets lie on '
              'their anchors (0: off): the lifter\'s disagreement between root and legs is '
              'taken out of the root instead of sliding the feet', min_value=0.0,
              max_value=1.0, read_only=True),
    ParamSpec('root_follow_stance_relax_s', _D.root_follow_stance_relax_s, 'whole_body: '
              '> 0: the root follow offset also fades in stance with this time constant, s, '
              'the stance feet sliding slowly with it back under the lifter\'s root (0: it '
              'does not fade in stance)', min_value=0.0, read_only=True),
    ParamSpec('stance_drift_s', _D.stance_drift_s, 'whole_body: > 0: in frames where the '
              'camera-motion estimate (camera_motion_topic) says the camera may move (any '
              'state but static, unknown included), the floor '
              'frame (it rides with the camera) follows the drift of the target\'s stance '
              'feet, low-passed with this time constant, s: the feet then stand in the world, '
              'not in the moving camera\'s frame. 0: off; also off without an estimate, with '
              'a static one, with floor_source input or derotate_camera, and while the body '
              'is carried with the camera', min_value=0.0,
              read_only=True),
    ParamSpec('stance_drift_deadband', _D.stance_drift_deadband, 'stance_drift_s: the drift '
              'is followed only by what its speed exceeds this, m/s (the lifter\'s foot noise '
              'under a camera that hardly moves)', min_value=0.0, read_only=True),
    ParamSpec('root_follow_relax_s', _D.root_follow_relax_s, 'whole_body: without stance, '
              'the root follow offset fades with this time constant, s', min_value=0.01,
              read_only=True),
    ParamSpec('slide_threshold', _D.slide_threshold, 'whole_body: a foot whose friction is '
              'saturated slides when holding it needs a horizontal residual root force above '
              'this, body weights', min_value=0.0, read_only=True),
    ParamSpec('slide_time', _D.slide_time, 'whole_body: the horizontal residual that lets a '
              'foot slide is averaged over this time while its friction is saturated, s (0: '
              'decided per sub-step)', min_value=0.0, read_only=True),
    ParamSpec('stance_height', _D.stance_height, 'whole_body: a contact point whose contact '
              'probability is above contact_threshold becomes a stance point (held, carrying '
              'a force, pulled onto the floor) within this height of the floor, m',
              min_value=0.0, read_only=True),
    ParamSpec('target_floor_tolerance', _D.target_floor_tolerance, 'A target whose foot '
              'lies deeper than this below the floor is raised to this depth before it is '
              'followed (the lifter\'s depth noise or a moving camera can sink it; followed, '
              'the body falls over onto its held feet), m; negative: off', read_only=True),
    ParamSpec('root_reach', _D.root_reach, 'whole_body, > 0: the target\'s root is moved '
              'horizontally, by what exceeds this, so that its anchored stance points lie '
              'within this of their anchors (a target carried sideways from the held feet '
              'pulls the body over them), m; 0: off', min_value=0.0, read_only=True),
    ParamSpec('wbid_solver', _D.wbid_solver, 'whole_body: QP solvers, osqp (the condensed QP '
              'on DAQP, the full one on OSQP; deterministic) or proxqp (ProxQP for both; last '
              'bits vary between runs)', read_only=True),
    ParamSpec('wbid_condensed', _D.wbid_condensed, 'whole_body: solve the QP over the contact '
              'forces and the residual alone, the accelerations in closed form (the same '
              'optimum, faster); false: the QP over all variables', read_only=True),
    ParamSpec('root_residual', _D.root_residual, 'paper: share of the residual direct root '
              'actuation that is applied: 1 = paper; 0 = root driven by contact forces and '
              'gravity only', min_value=0.0, max_value=1.0, read_only=True),
    ParamSpec('penetration_metric', _D.penetration_metric, 'Metric of the penetration QP: '
              'diagonal (diag M), identity (paper) or mass (M)', read_only=True),
    ParamSpec('foot_stick', _D.foot_stick, 'paper: hold contact points in contact at their '
              'anchor on the floor (no foot skating; needs root_residual 1); whole_body holds '
              'stance points by its own acceleration rows', read_only=True),
    ParamSpec('stick_release', _D.stick_release, 'The stick anchor follows the target when '
              'the target foot moves farther than this from it, m', min_value=0.0,
              read_only=True),
    ParamSpec('flat_foot_pitch_deg', _D.flat_foot_pitch_deg, 'Ankle-to-toe pitch below the '
              'floor of a flat foot, degrees: places the heel contact point (30: the skeleton '
              'template; the Bandai Namco motion data put it near 40, CMU near 15); -1: '
              'estimated from the input\'s feet in double contact (docs/physics.md)',
              min_value=-1.0, max_value=60.0, read_only=True),
    ParamSpec('max_frame_gap_s', _D.max_frame_gap, 'A longer gap between frames (stamp time) '
              're-initialises the simulation from the target', min_value=0.001, read_only=True),
    ParamSpec('skeleton_tolerance', _D.skeleton_tolerance, 'Bone offset change (m) that '
              'rebuilds the model', min_value=0.0, read_only=True),
    ParamSpec('floor_source', 'estimate', 'Floor frame: estimate (fitted to the feet in '
              'contact, input in the camera optical frame), camera_params (camera_height, '
              'camera_pitch_deg) or input (input already in a floor frame, z up, floor z = 0)',
              read_only=True),
    ParamSpec('floor_window', _F.window, 'floor_source estimate: frames of foot contacts '
              'kept for the fit', min_value=10, read_only=True),
    ParamSpec('floor_update_every', _F.update_every, 'floor_source estimate: frames between '
              're-fits', min_value=1, read_only=True),
    ParamSpec('floor_contact_threshold', _F.contact_threshold, 'floor_source estimate: '
              'contact probability above which a heel/toe point is used', min_value=0.0,
              max_value=1.0, read_only=True),
    ParamSpec('floor_prior', _F.prior, 'floor_source estimate: up direction for what the '
              'feet cannot determine: body (mean ankles-to-neck direction) or camera (-y)',
              read_only=True),
    ParamSpec('floor_freeze_after', _F.freeze_after, 'floor_source estimate: frames after '
              'which no new fit is taken (0 = keep refining; a blend in progress completes)',
              min_value=0, read_only=True),
    ParamSpec('floor_blend_frames', _F.blend_frames, 'floor_source estimate: frames over '
              'which a re-fitted floor replaces the last one (smoothstep; 0 = at once: the '
              'outputs, in the floor frame, then jump at every re-fit; at most '
              'floor_update_every)', min_value=0, read_only=True),
    ParamSpec('floor_restart_share', _F.restart_share, 'floor_source estimate: when the '
              'window\'s plane explains less than this share of the points of the last '
              'floor_restart_frames contact frames and their own plane at least twice as '
              'many, the older points are forgotten (a camera re-aimed while its motion was '
              'unknown; never while the camera-motion estimate says static; 0 = never)',
              min_value=0.0, max_value=1.0, read_only=True),
    ParamSpec('floor_restart_frames', _F.restart_frames, 'floor_source estimate: contact '
              'frames kept when the window restarts (floor_restart_share)', min_value=1,
              read_only=True),
    ParamSpec('camera_height', 1.5, 'floor_source camera_params: camera height above the '
              'floor, m', min_value=0.0, read_only=True),
    ParamSpec('camera_pitch_deg', 0.0, 'floor_source camera_params: camera pitch down from '
              'horizontal, degrees', min_value=-90.0, max_value=90.0, read_only=True),
    ParamSpec('frame_id', '', 'frame_id of the outputs; empty = the input\'s (floor_source '
              'input) or "floor" (camera_params)', read_only=True),
    ParamSpec('publish_markers', True, 'Publish /mocap/physics/markers', read_only=True),
)

FLOOR_SOURCES = ('estimate', 'camera_params', 'input')


def default_dynet_weights() -> str:
    """The package's DyNet weights (``weights/dynet.pt``, installed by ``mocap train physics
    --install``)."""
    from .dynet import WEIGHTS_DIR
    return str(WEIGHTS_DIR / 'dynet.pt')


class PhysicsNode(Node):
    """The physics node (module docstring). Keyword arguments go to ``rclpy.node.Node``
    (``context``, ``parameter_overrides``, ...).

    Raises:
        ValueError: a bad parameter, or unusable learned-gain weights
            (``mocap_core.checkpoint.WeightsError``, one line).
    """

    def __init__(self, **kwargs) -> None:
        super().__init__('physics', **kwargs)
        self.p = p = declare_parameters(self, PARAMETERS)
        learned = p['gains_mode'] == 'learned'
        weights = p['dynet_weights'] or (default_dynet_weights() if learned else '')
        if learned and not os.path.isfile(weights):
            raise ValueError(f'gains_mode learned: no DyNet weights at {weights} (train '
                             'them with `mocap train physics --install`)')
        # a derotated or carried input, or one in its own floor frame, has no camera motion
        # to trail; learned gains replace the PD's gains
        no_moving = self._no_moving_gains(p)
        self.params = PhysicsParams(
            body_mass=p['body_mass'], substeps=p['substeps'], kp_root=p['kp_root'],
            kd_root=p['kd_root'], kp_joint=p['kp_joint'], kd_joint=p['kd_joint'],
            kp_joint_moving=0.0 if no_moving else p['kp_joint_moving'],
            kd_joint_moving=0.0 if no_moving else p['kd_joint_moving'],
            friction=p['friction'], contact_probability_threshold=p['contact_threshold'],
            contact_height=p['contact_height'], grf_smoothness=p['grf_smoothness'],
            root_residual=p['root_residual'], penetration_metric=p['penetration_metric'],
            max_frame_gap=p['max_frame_gap_s'], skeleton_tolerance=p['skeleton_tolerance'],
            foot_stick=p['foot_stick'], stick_release=p['stick_release'],
            stick_speed=p['stick_speed'],
            flat_foot_pitch_deg=p['flat_foot_pitch_deg'],
            gains_mode=p['gains_mode'], dynet_weights=weights if learned else '',
            dynamics=p['dynamics'], residual_weight=p['residual_weight'],
            residual_horizontal_weight=p['residual_horizontal_weight'],
            free_limb_weight=p['free_limb_weight'],
            stance_leg_weight=p['stance_leg_weight'], residual_bound=p['residual_bound'],
            residual_moment_bound=p['residual_moment_bound'], wbid_solver=p['wbid_solver'],
            wbid_condensed=p['wbid_condensed'],
            stance_release=p['stance_release'], slide_threshold=p['slide_threshold'],
            stance_drift_s=0.0 if self._carried(p) or self._derotating(p) or
            p['floor_source'] == 'input' else p['stance_drift_s'],
            stance_drift_deadband=p['stance_drift_deadband'],
            root_follow_gain=p['root_follow_gain'],
            root_follow_relax_s=p['root_follow_relax_s'],
            root_follow_stance_relax_s=p['root_follow_stance_relax_s'],
            stance_height=p['stance_height'], slide_time=p['slide_time'],
            target_floor_tolerance=p['target_floor_tolerance'],
            root_reach=p['root_reach'],
            velocity_feedforward=p['velocity_feedforward'])
        self._limited = KeyedRateLimit()
        self.diag = NodeDiagnostics(self, 'physics', hardware_id='cpu')
        # the camera's rotation taken out of the input (derotate_camera)
        self.derotate = self._derotating(p)
        self.carry = self._carried(p)
        #: the stance drift (stance_drift_s; off while the body is carried with the camera)
        #: is followed only in frames the camera-motion estimate says are not static: its
        #: state by stamp
        self.drift = self.params.stance_drift_s > 0.0 and self.params.dynamics == 'whole_body'
        #: frames of a moving camera take the joints' moving gains (kp_joint_moving)
        self.moving_gains = self.params.kp_joint_moving > 0 or self.params.kd_joint_moving > 0
        self.camera_states: 'collections.OrderedDict[int, str]' = collections.OrderedDict()
        #: the known camera pose (camera_pose_topic), for carry_with_camera
        self.known_poses: Optional[KnownCameraPoses] = None
        self.camera_pose_missing = 0
        if self.carry and p['camera_pose_topic']:
            self.known_poses = known_camera_poses(p)
        #: the keypoint node's camera-motion estimate (none where a known pose is followed)
        self.rotations: Optional[CameraRotations] = None if self.known_poses is not None \
            else CameraRotations(translation=self.carry,
                                 coast_s=p['camera_translation_coast_s'])
        #: the rotation and camera position each input stamp was moved by (for the floor
        #: message), newest last
        self.used_rotations: Dict[int, Tuple[np.ndarray, np.ndarray]] = {}
        self.rotation_held_frames = 0
        self.rotation_own_frames = 0
        #: the stamp whose floor was published last (:meth:`_publish_floor`)
        self._floor_stamp = -1
        contacts_topic = p['contacts_topic']
        self.online = self._make_online(contacts_topic)
        # several people (the combined input): one OnlinePhysics per id
        self.persons: Dict[int, OnlinePhysics] = {}
        self.person_seen_ns: Dict[int, int] = {}
        self.bodies_mode = False
        self.main_id: Optional[int] = None
        self.main_last_ns = -1
        self.bodies = BodyPublishers(self, 'physics')
        self.pub_motion = self.create_publisher(MultiDOFJointTrajectory, topics.PHYSICS_MOTION,
                                                STREAM_QOS)
        self.pub_joints = self.create_publisher(PointCloud2, topics.PHYSICS_JOINTS3D,
                                                STREAM_QOS)
        self.pub_states = self.create_publisher(JointState, topics.PHYSICS_JOINT_STATES,
                                                STREAM_QOS)
        self.pub_grf = {'left': self.create_publisher(WrenchStamped, topics.PHYSICS_GRF_LEFT,
                                                      STREAM_QOS),
                        'right': self.create_publisher(WrenchStamped, topics.PHYSICS_GRF_RIGHT,
                                                       STREAM_QOS)}
        self.pub_com = self.create_publisher(PointStamped, topics.PHYSICS_COM, STREAM_QOS)
        self.pub_floor = (self.create_publisher(TransformStamped, topics.PHYSICS_FLOOR,
                                                STREAM_QOS)
                          if p['floor_source'] != 'input' else None)
        self.pub_markers = (self.create_publisher(MarkerArray, topics.PHYSICS_MARKERS,
                                                  STREAM_QOS)
                            if p['publish_markers'] else None)
        self.combined = CombinedPublishers(self, 'physics')
        self.diag.set_value('gains', 'fixed' if not learned else f'learned ({weights})')
        self.diag.set_value('model', 'none yet (waiting for the first motion)')
        qos = input_qos(STREAM_QOS, p['queue_depth'])
        self.diag.watch('input', self.create_subscription(
            MultiDOFJointTrajectory, p['motion_topic'], guarded(self, deserialised_unless(
                lambda: self.bodies_mode, MultiDOFJointTrajectory, self.on_motion,
                decode=cdr.decode_motion), 'motion'),
            qos, raw=True))
        self.contacts_sub = None
        if contacts_topic:
            self.contacts_sub = self.create_subscription(
                JointState, contacts_topic, guarded(self, deserialised_unless(
                    lambda: self.bodies_mode, JointState, self.on_contacts), 'contacts'),
                qos, raw=True)
            self.diag.watch('contacts', self.contacts_sub)
        if p['bodies_motion_topic']:
            self.diag.watch('bodies', self.create_subscription(
                MultiDOFJointTrajectory, p['bodies_motion_topic'],
                guarded(self, deserialised_unless(
                    lambda: False, MultiDOFJointTrajectory, self.on_bodies_motion,
                    decode=cdr.decode_motion), 'bodies motion'), qos, raw=True))
        if p['bodies_contacts_topic']:
            self.create_subscription(
                JointState, p['bodies_contacts_topic'],
                guarded(self, self.on_bodies_contacts, 'bodies contacts'), qos)
        if self.known_poses is not None:
            self.diag.watch('camera_pose', self.create_subscription(
                camera_pose_message_type(p['camera_pose_type']),
                p['camera_pose_topic'], guarded(self, self.on_camera_pose, 'camera pose'),
                qos))
        elif self.derotate or self.carry or ((self.drift or self.moving_gains)
                                             and p['camera_motion_topic']):
            self.diag.watch('camera_motion', self.create_subscription(
                Odometry, p['camera_motion_topic'],
                guarded(self, self.on_camera_motion, 'camera motion'), qos))
        elif p['derotate_camera']:
            self.get_logger().warn('derotate_camera needs floor_source estimate or '
                                   'camera_params and a camera_motion_topic: off')
        if (p['carry_with_camera'] or p['camera_pose_topic']) and not self.carry:
            self.get_logger().warn('carrying the body with the camera needs floor_source '
                                   'estimate or camera_params, a camera_motion_topic or '
                                   'camera_pose_topic, and derotate_camera off: off')
        self.diag.set_value('floor_normal', 'gravity of the known camera pose, height from '
                            'the feet' if self.online.floor_gravity else 'from the feet')
        self.diag.set_value('carry_with_camera', 'off' if not self.carry else
                            'with the known camera pose' if self.known_poses is not None
                            else 'with the camera-motion estimate')
        if p['stance_drift_s'] > 0.0 and (self.carry or self.derotate):
            self.get_logger().info('stance_drift_s: off while the camera\'s motion is taken '
                                   'out or the body is carried with it')
        elif p['stance_drift_s'] > 0.0 and p['floor_source'] == 'input':
            self.get_logger().info('stance_drift_s: off with floor_source input (the input\'s '
                                   'floor frame is not the camera\'s)')
        self.diag.set_value('stance_drift', 'off' if not self.drift else
                            f"followed ({self.params.stance_drift_s:g} s) in frames the "
                            "camera-motion estimate says the camera moves" if
                            p['camera_motion_topic'] else 'off (no camera_motion_topic)')
        self.diag.set_value('camera_rotation', 'taken out (outputs in the first image\'s '
                            'floor frame)' if self.derotate else 'off')
        self.diag.set_value('moving_gains', 'off' if not self.moving_gains else (
            f'joints kp {self.params.kp_joint_moving or self.params.kp_joint:g}, kd '
            f'{self.params.kd_joint_moving or self.params.kd_joint:g} in frames the '
            'camera-motion estimate does not call static (not carried)'
            + ('' if p['camera_motion_topic'] else ': no camera_motion_topic, never')))
        self.diag.watch('motion', self.pub_motion)
        # frames whose contacts are late go after at most contacts_wait_s plus half of it
        # (each tick of a timer is a turn of the executor, which costs CPU even when idle)
        self.create_timer(min(max(0.5 * p['contacts_wait_s'], 0.01), 0.05),
                          guarded(self, self.on_timer, 'process'))
        self.diag.on_publish(guarded(self, self.refresh_diagnostics, 'diagnostics'))
        self.get_logger().info(
            f"physics on {p['motion_topic']} (contacts: {contacts_topic or 'none'}); "
            f"k={p['substeps']}, kp={p['kp_joint']:g}, kd={p['kd_joint']:g} "
            f"(moving camera: {self.params.kp_joint_moving or p['kp_joint']:g}, "
            f"{self.params.kd_joint_moving or p['kd_joint']:g}), "
            f"mu={p['friction']:g}, floor: {p['floor_source']}")

    def _make_online(self, contacts_topic: str) -> OnlinePhysics:
        """A new per-person streaming state (its own floor estimate)."""
        p = self.p
        online = OnlinePhysics(
            self.params, self._floor_source(),
            frame_id=p['frame_id'] or (START_FLOOR_FRAME if self.derotate else ''),
            contacts_wait_s=p['contacts_wait_s'], contacts_max_age_s=p['contacts_max_age_s'],
            contacts_expected=((lambda: self.count_publishers(contacts_topic) > 0)
                               if contacts_topic else None),
            report=self._report, record_time=self.diag.latency.add)
        if self.known_poses is not None:
            online.floor_gravity = bool(p['floor_from_camera_pose'])
            if p['upright_from_camera_pose']:
                online.upright = UprightPrior(UPRIGHT_WINDOW_FRAMES)
        return online

    def _floor_source(self) -> FloorSource:
        """The floor of ``floor_source`` (module docstring); raises ValueError."""
        p = self.p
        if p['floor_source'] == 'input':
            return None
        if p['floor_source'] == 'camera_params':
            return FloorFrame.from_camera_height_pitch(p['camera_height'],
                                                       np.deg2rad(p['camera_pitch_deg']))
        if p['floor_source'] == 'estimate':
            return FloorTracker(FloorTrackerParams(
                window=p['floor_window'], update_every=p['floor_update_every'],
                contact_threshold=p['floor_contact_threshold'], prior=p['floor_prior'],
                freeze_after=p['floor_freeze_after'],
                blend_frames=p['floor_blend_frames'],
                restart_share=p['floor_restart_share'],
                restart_frames=p['floor_restart_frames'],
                # auto (-1): the template's until the physics has estimated it
                flat_foot_pitch_deg=p['flat_foot_pitch_deg'] if p['flat_foot_pitch_deg'] >= 0
                else TEMPLATE_FLAT_FOOT_PITCH_DEG))     # validates them
        raise ValueError(f"floor_source {p['floor_source']!r}: use "
                         f"{', '.join(FLOOR_SOURCES[:-1])} or {FLOOR_SOURCES[-1]}")

    # -- logging and counting -----------------------------------------------------------------
    def _warn_limited(self, key: str, text: str, period_s: float = 5.0) -> None:
        """Warn, at most once per ``period_s`` for the same ``key``."""
        if self._limited.ready(key, period_s):
            self.get_logger().warn(text)

    def _problem(self, key: str, text: str) -> None:
        self.diag.errors += 1
        self.diag.warn(text)
        self._warn_limited(key, text)

    def _report(self, notice: Notice) -> None:
        """Log and count a :class:`~mocap_physics.online.Notice` of the streaming logic."""
        if notice.dropped:
            self.diag.dropped += 1
        if notice.level == 'problem':
            self._problem(notice.key, notice.text)
        elif notice.level == 'status':
            self.diag.warn(notice.text)
        elif notice.level == 'info':
            self.get_logger().info(notice.text, throttle_duration_sec=notice.period_s)
        else:
            self._warn_limited(notice.key, notice.text, notice.period_s)

    # -- input ---------------------------------------------------------------------------------
    def on_contacts(self, msg: JointState) -> None:
        if self.bodies_mode:
            return                       # the main person's come with the combined input
        try:
            probs = msg_to_contacts(msg)
        except MessageError as exc:
            self._problem('contacts', f"ignoring {self.p['contacts_topic']}: {exc}")
            return
        self._publish(self.online.add_contacts(stamp_to_ns(msg.header.stamp), probs))

    def on_bodies_contacts(self, msg: JointState) -> None:
        try:
            bodies = msg_to_bodies_contacts(msg)
        except MessageError as exc:
            self._problem('contacts', f"ignoring {self.p['bodies_contacts_topic']}: {exc}")
            return
        stamp = stamp_to_ns(msg.header.stamp)
        released = []
        for pid, probs in bodies:
            online = self.persons.get(pid)
            if online is not None:
                released.append((pid, online.add_contacts(stamp, probs)))
            else:                                  # contacts before the person's first motion
                self._person(pid).add_contacts(stamp, probs)
        self._publish_people(released)

    @property
    def _main_online(self) -> OnlinePhysics:
        """The main person's streaming state (the single-person input's without several
        people)."""
        return self.persons.get(self.main_id, self.online) if self.bodies_mode else self.online

    def _person(self, pid: int) -> OnlinePhysics:
        online = self.persons.get(pid)
        if online is None:
            online = self.persons[pid] = self._make_online(self.p['bodies_contacts_topic'])
            self.get_logger().info(f'person {pid}: new')
            self.main_id = min(self.persons)
        return online

    def on_bodies_motion(self, msg: MultiDOFJointTrajectory) -> None:
        self.diag.input.tick()
        stamp = stamp_to_ns(msg.header.stamp)
        if stamp < self.main_last_ns - 10**9:
            self.main_last_ns = -1                # a new stream (a bag played again)
        if not self.bodies_mode:
            self.bodies_mode = True
            # the main person comes again with the combined input: what the single-person
            # input left waiting is dropped (not published twice)
            self.online = self._make_online(self.p['contacts_topic'])
            self.get_logger().info(f"following every person on {self.p['bodies_motion_topic']}"
                                   f" ({self.p['motion_topic']} is ignored from now on)")
        try:
            bodies = motion_to_bodies(msg)
        except MessageError as exc:
            self.diag.dropped += 1
            self._problem('motion', f'dropping a motion message: {exc}')
            return
        released = []
        for pid, pose in bodies:
            online = self._person(pid)
            self.person_seen_ns[pid] = stamp
            accepted, frames = online.admit(stamp)
            if accepted:
                frames = frames + online.add_motion(stamp, self._derotated(stamp, pose),
                                                    msg.header.frame_id,
                                                    camera=self._camera(stamp),
                                                    camera_moving=self._camera_moving(stamp),
                                                    camera_static=self._camera_static(stamp))
            released.append((pid, frames))
        self._publish_people(released)
        timeout = int(self.p['person_timeout_s'] * 1e9)
        for pid in [q for q, t in self.person_seen_ns.items() if stamp - t > timeout or
                    t - stamp > max(timeout, 10**9)]:
            self._end_person(pid)

    def _end_person(self, pid: int) -> None:
        """Person ``pid`` is gone: their waiting frames, then their state and topics go."""
        online = self.persons.pop(pid)
        self.person_seen_ns.pop(pid, None)
        self.main_id = min(self.persons) if self.persons else None
        self._publish_people([(pid, online.flush())])
        self.bodies.remove(pid)
        self.get_logger().info(f'person {pid} gone: their topics are removed')

    def on_motion(self, msg: MultiDOFJointTrajectory) -> None:
        if self.bodies_mode:
            return                       # the main person comes with the combined input
        self.diag.input.tick()
        stamp = stamp_to_ns(msg.header.stamp)
        accepted, frames = self.online.admit(stamp)     # before decoding, as documented
        self._publish(frames)
        if not accepted:
            return
        try:
            pose = motion_to_pose(msg)
        except MessageError as exc:
            self.diag.dropped += 1
            self._problem('motion', f'dropping a motion message: {exc}')
            return
        self._publish(self.online.add_motion(stamp, self._derotated(stamp, pose),
                                             msg.header.frame_id, camera=self._camera(stamp),
                                             camera_moving=self._camera_moving(stamp),
                                             camera_static=self._camera_static(stamp)))

    @staticmethod
    def _derotating(p) -> bool:
        """Whether the camera's rotation is taken out of the input (derotate_camera)."""
        return bool(p['derotate_camera']) and p['floor_source'] != 'input' \
            and bool(p['camera_motion_topic'])

    @staticmethod
    def _no_moving_gains(p) -> bool:
        """Whether kp_joint_moving / kd_joint_moving are unused: the camera's motion is taken
        out (derotate_camera) or carried, the input is in its own floor frame, or the gains
        are learned."""
        return PhysicsNode._derotating(p) or PhysicsNode._carried(p) or \
            p['floor_source'] == 'input' or p['gains_mode'] == 'learned'

    @staticmethod
    def _carried(p) -> bool:
        """Whether the simulated body is carried with the camera's motion (a known camera
        pose, or carry_with_camera with the estimate; not while derotating)."""
        return not PhysicsNode._derotating(p) and p['floor_source'] != 'input' and (
            bool(p['camera_pose_topic']) or
            (bool(p['carry_with_camera']) and bool(p['camera_motion_topic'])))

    def on_camera_motion(self, msg: Odometry) -> None:
        """Keep the camera's rotation since the first image of each stamp, and its state
        (static or not) for the stance drift."""
        if self.rotations is None:           # a known camera pose is followed instead
            return
        try:
            state, q, _ = odometry_to_camera_motion(msg)
        except MessageError as exc:
            self._problem('camera_motion', f'ignoring camera motion: {exc}')
            return
        if self.drift or self.moving_gains:
            self.camera_states[stamp_to_ns(msg.header.stamp)] = state
            while len(self.camera_states) > 600:
                self.camera_states.popitem(last=False)
        if not (self.derotate or self.carry):
            return
        position = odometry_to_camera_position(msg) if self.rotations.translation else None
        self.rotations.add(stamp_to_ns(msg.header.stamp), state, quat_to_matrix(q), position)

    def _derotated(self, stamp: int, pose):
        """The input pose in the first image's camera frame (derotate_camera; else as
        is)."""
        if not self.derotate:
            return pose
        return rotate_pose(pose, self._camera_at(stamp)[0])

    def on_camera_pose(self, msg) -> None:
        """Keep the camera's known pose (camera_pose_topic)."""
        if self.known_poses.add(*camera_pose_from_msg(msg)) == 'invalid':
            self._problem('camera_pose', 'ignoring camera pose: not finite')

    def _camera_state(self, stamp: int) -> Optional[str]:
        """The camera-motion estimate's state of ``stamp`` (else of the newest one at most
        0.5 s before it), None without one."""
        state = self.camera_states.get(stamp)
        if state is None:
            before = next((s for s in reversed(self.camera_states) if s < stamp), None)
            if before is not None and stamp - before <= CAMERA_STATE_MAX_AGE_NS:
                state = self.camera_states[before]
        return state

    def _camera_moving(self, stamp: int) -> bool:
        """Whether the camera may move at ``stamp`` for the stance drift: its estimate
        (:meth:`_camera_state`) exists and is not ``static``."""
        state = self._camera_state(stamp)
        return state is not None and state != 'static'

    def _camera_static(self, stamp: int) -> bool:
        """Whether the estimate says the camera stands still at ``stamp`` (the floor window
        then does not restart)."""
        return self._camera_state(stamp) == 'static'

    def _camera(self, stamp: int):
        """The camera's pose (R, C) of ``stamp`` for carry_with_camera, else None (also
        where the known pose has none near ``stamp``: the frame is not carried, counted)."""
        if not self.carry:
            return None
        if self.known_poses is None:
            return self._camera_at(stamp)
        pose = self.known_poses.at(stamp)
        if pose is None:
            self.camera_pose_missing += 1
            self._warn_limited('camera_pose_missing', 'no known camera pose near this frame: '
                               'the frame is not carried', 10.0)
        return pose

    def _camera_at(self, stamp: int):
        """(R (3, 3), C (3,)): the camera's pose of ``stamp``, the same for every person of
        a frame. A stamp without its own camera estimate holds the newest one before it
        (counted)."""
        if stamp in self.used_rotations:       # another person of the same frame
            R, C = self.used_rotations[stamp]
        else:
            R, C, own = self.rotations.pose_at(stamp)
            if own:
                self.rotation_own_frames += 1
            else:
                self.rotation_held_frames += 1
                self._warn_limited('rotation_held', 'no camera-motion estimate for this '
                                   'frame: the last rotation is held', 10.0)
            self.used_rotations[stamp] = (R, C)
            while len(self.used_rotations) > 600:
                del self.used_rotations[next(iter(self.used_rotations))]
        return R, C

    def on_timer(self) -> None:
        """Frames whose contacts did not come in time go now."""
        self._publish(self.online.process())
        self._publish_people([(pid, online.process())
                              for pid, online in list(self.persons.items())])

    def flush(self) -> None:
        """End of the input (offline processing): step every waiting frame now, with the
        contacts that arrived (no more waiting for late ones)."""
        self._publish(self.online.flush())
        self._publish_people([(pid, online.flush())
                              for pid, online in list(self.persons.items())])

    # -- output --------------------------------------------------------------------------------
    def _publish(self, frames: List[PhysicsFrame], pid: Optional[int] = None) -> None:
        """Publish frames of the single-person input (``pid`` None) or of person ``pid`` on
        their own topics and, for the main person, on the single-person topics (the combined
        messages of several people: :meth:`_publish_people`)."""
        for frame in frames:
            if pid is None:
                self._publish_frame(frame)
            else:
                self._publish_body(pid, frame)
                if pid == self.main_id and frame.stamp_ns > self.main_last_ns:
                    self.main_last_ns = frame.stamp_ns
                    self._publish_frame(frame)
            self.diag.output.tick()

    def _publish_people(self, released: List[Tuple[int, List[PhysicsFrame]]]) -> None:
        """Publish the frames several people released in one callback: everybody's frames
        of a stamp in one combined message (the world stage then runs its network once for
        all of them), then each person's own topics and the main person's."""
        for stamp, group in by_stamp(released, self.main_id):
            # the main person's floor first (the world stage places every frame on it, so
            # it must have the floor of a frame before its motion), then the combined
            # message: the next stage follows everybody from it, and hears it before the
            # single-person topics
            main = next((f for pid, f in group if pid == self.main_id), None)
            if main is not None and main.stamp_ns > self.main_last_ns:
                self._publish_floor(main)
            self.combined.publish(make_header(stamp, group[0][1].frame_id), [
                (pid, f.result.pose, f.result.contact_active.astype(float))
                for pid, f in group])
            for pid, frame in group:
                self._publish([frame], pid)

    def _publish_body(self, pid: int, frame: PhysicsFrame) -> None:
        res = frame.result
        header = make_header(frame.stamp_ns, frame.frame_id)
        pose = res.pose
        b = self.bodies
        b.publish(pid, 'motion', lambda: cdr.pose_to_motion(pose, header))
        b.publish(pid, 'joints3d',
                  lambda: cdr.positions_to_cloud(pose.joint_positions(), header))
        b.publish(pid, 'joint_states', lambda: cdr.pose_to_joint_state(
            pose, header, revolute_efforts(pose.revolute_angles(),
                                           res.joint_torques.reshape(-1, 3))))
        for foot in ('left', 'right'):
            w = res.feet[foot]
            b.publish(pid, f'grf/{foot}',
                      lambda w=w: cdr.wrench_to_msg(w.force, w.moment, header))

    def _publish_floor(self, frame: PhysicsFrame) -> None:
        """The floor of the main person's frame (once per stamp), before its motion: the
        floor in the current camera frame (derotate_camera: the first image's floor turned
        back by the rotation this frame was turned by)."""
        if self.pub_floor is None or frame.floor is None \
                or frame.stamp_ns == self._floor_stamp:
            return
        self._floor_stamp = frame.stamp_ns
        used = self.used_rotations.get(frame.stamp_ns) if self.derotate else None
        publish_if_heard(self.pub_floor, lambda: floor_transform_msg(
            make_header(frame.stamp_ns, frame.input_frame),
            floor_in_camera(frame.floor, None if used is None else used[0]),
            frame.frame_id))

    def _publish_frame(self, frame: PhysicsFrame) -> None:
        """The main person's (or the single input's) frame on the single-person topics: the
        motion always, the others only while someone listens (mocap_core.publishing)."""
        res = frame.result
        header = make_header(frame.stamp_ns, frame.frame_id)
        pose = res.pose
        self._publish_floor(frame)
        self.pub_motion.publish(cdr.pose_to_motion(pose, header))
        publish_if_heard(self.pub_joints,
                         lambda: cdr.positions_to_cloud(pose.joint_positions(), header))
        publish_if_heard(self.pub_states, lambda: cdr.pose_to_joint_state(
            pose, header, revolute_efforts(pose.revolute_angles(),
                                           res.joint_torques.reshape(-1, 3))))
        for foot, pub in self.pub_grf.items():
            w = res.feet[foot]
            publish_if_heard(pub, lambda w=w: cdr.wrench_to_msg(w.force, w.moment, header))

        publish_if_heard(self.pub_com, lambda: cdr.point_to_msg(res.center_of_mass, header))
        if self.pub_markers is not None:
            publish_if_heard(self.pub_markers, lambda: self._markers(frame, header))

    def _markers(self, frame: PhysicsFrame, header) -> bytes:
        """The stick figure with contacts and force arrows, and the friction cones
        (serialised MarkerArray)."""
        res = frame.result
        pose = res.pose
        names = self._main_online.cycle.model.contact_names
        # every contact point always has its arrow (ids 10-13 stay the same; zero length
        # without force)
        forces = {n: res.contact_forces[i] for i, n in enumerate(names)}
        specs = pose_marker_specs(pose, ns='physics', color=(1.0, 0.6, 0.1, 1.0),
                                  contacts=res.contact_active.astype(float), forces=forces)
        cps = contact_positions(pose, self._main_online.cycle.flat_foot_pitch)
        loaded = [cps[i] for i in range(len(names)) if res.contact_forces[i, 2] > 1e-6]
        specs.append(friction_cone_spec(np.array(loaded), self.params.friction))
        return cdr.marker_array(specs, header)

    def refresh_diagnostics(self) -> None:
        online = self._main_online       # several people: the counters below are theirs
        self.diag.set_value('persons', len(self.persons) if self.bodies_mode else 1)
        self.diag.set_value('person_ids', ' '.join(map(str, sorted(self.persons))) or 'none')
        st = online.cycle.stats
        d = self.diag
        model = online.cycle.model
        if model is not None:
            d.set_value('model', f'{model.nv} DoF, {model.body_mass:g} kg')
        d.set_value('fallbacks', st.fallbacks)
        d.set_value('grf_solver_failures', st.grf_failures)
        d.set_value('penetration_solver_failures', st.penetration_failures)
        d.set_value('penetration_qp_solves', st.penetration_solves)
        d.set_value('reinitialisations', st.reinitialisations)
        d.set_value('time_jumps', st.time_jumps)
        d.set_value('invalid_inputs', st.invalid_inputs)
        d.set_value('model_builds', st.model_builds)
        d.set_value('flat_foot_pitch_deg', f'{online.cycle.flat_foot_pitch:.1f}')
        d.set_value('friction_cone_violations', st.cone_violations)
        d.set_value('stick_failures', st.stick_failures)
        d.set_value('sunk_targets_raised', st.sunk_targets)
        d.set_value('targets_kept_within_reach', st.reached_targets)
        d.set_value('dynamics', self.params.dynamics)
        if self.rotations is not None and (self.derotate or self.carry):
            d.set_value('camera_rotation_frames', f'{self.rotation_own_frames} with their own '
                        f'estimate, {self.rotation_held_frames} held')
        if self.carry:
            d.set_value('carried_frames', online.camera_steps)
        if self.drift:
            v = online.cycle.drift_velocity
            d.set_value('stance_drift_frames', online.cycle.drift_frames)
            d.set_value('stance_drift_m_s', f'{v[0]:.2f} {v[1]:.2f}')
        if self.known_poses is not None:
            d.set_value('camera_pose_missing_frames', self.camera_pose_missing)
        if self.rotations is not None and self.rotations.translation:
            r = self.rotations
            d.set_value('camera_translation_frames', f'{r.measured_frames} measured, '
                        f'{r.coasted_frames} coasted, {r.held_frames} held')
        d.set_value('residual_bound_reached_substeps', st.residual_saturations)
        d.set_value('sliding_substeps', st.sliding_substeps)
        floor = online.floor
        if online.tracker is not None:
            tr = online.tracker
            d.set_value('floor', 'ready' if tr.ready else
                        f'provisional ({tr.contact_frames}/{tr.params.min_frames} contact '
                        'frames)')
            if floor is not None:
                d.set_value('floor_camera_height_m', f'{floor.height:.3f}')
                d.set_value('floor_normal_in_camera', ' '.join(f'{x:.4f}' for x in floor.normal))
            if tr.fit is not None:
                d.set_value('floor_fit', f'{tr.fit.inliers}/{tr.fit.points} inliers, rms '
                            f'{tr.fit.rms * 1e3:.1f} mm, {tr.fit.source}')
            d.set_value('floor_changes', tr.changes)
            d.set_value('floor_window_restarts', tr.restarts)
        elif floor is not None:
            d.set_value('floor_camera_height_m', f'{floor.height:.3f}')
        r = online.last_result
        if r is not None:
            d.set_value('last_status', r.status)
            d.set_value('residual_root_force_over_weight', f'{r.residual_ratio:.4f}')
            d.set_value('grf_qp_ms', f'{r.time_grf_qp * 1e3:.3f}')
            d.set_value('penetration_qp_ms', f'{r.time_penetration_qp * 1e3:.3f}')
            d.set_value('substeps', r.substeps)
        if r is not None and r.status == 'ok' and not online.pending:
            d.warn(None)


def main(args: Optional[List[str]] = None) -> int:
    if help_requested(sys.argv[1:] if args is None else list(args), __doc__, PARAMETERS):
        return 0
    return spin_node(PhysicsNode, args, 'physics')


if __name__ == '__main__':
    sys.exit(main())
