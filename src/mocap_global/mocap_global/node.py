"""``ros2 run mocap_global gmr``: world-frame pose independent of camera motion (GMR).

Subscribes ``motion_topic`` (default ``/mocap/physics/motion``; the lifter's
``/mocap/lifter/motion`` works too, by the parameter or a remap), a
trajectory_msgs/MultiDOFJointTrajectory per frame. Only the local joint rotations and the
bone lengths are used (the paper's camera-agnostic input): the GRU runs over a sliding window
of ``window`` frames and frame k is emitted when frame k + ``lookahead`` has arrived (latency
``lookahead`` / fps seconds; ``lookahead:=0`` is the causal option). The world pose is
accumulated from a gravity-aligned first pose (z up, heading +x, feet on z = 0), see
:mod:`mocap_global.online`.

Publishes, stamped with the input's stamps, in ``frame_id`` (default ``world``):
``/mocap/world/motion`` (MultiDOFJointTrajectory), ``/mocap/world/joints3d`` (PointCloud2),
``/mocap/world/joint_states`` (JointState), ``/mocap/world/odom`` (nav_msgs/Odometry: root
pose, twist in the root frame), ``/mocap/world/path`` (nav_msgs/Path), ``/mocap/world/markers``
(MarkerArray), ``/mocap/world/floor`` (geometry_msgs/TransformStamped: the pose of the input
frame, e.g. the physics floor frame, in ``frame_id``; with a floor input a turn about z and a
shift along the floor, so that the physics floor and the world floor are one plane) and
``/diagnostics``.

Several people (docs/multi_person.md): ``bodies_motion_topic`` (default
``/mocap/physics/bodies/motion``, names prefixed ``body_<id>/``) carries every person; once it
delivers, each person gets their own world pose (ended ``person_timeout_s`` after last seen)
and ``motion_topic`` is ignored. Each person's output goes to ``/humans/bodies/body_<id>/world/
{motion,joints3d,joint_states,odom,path}``, every person to ``/mocap/world/bodies/{motion,
joints3d,markers}``, the main person (the smallest id present) to the single-person topics
above, and, with ``publish_tf``, every person's skeleton to ``/tf`` (frames ``body_<id>`` in
``frame_id`` and ``body_<id>/<joint>``). Every output but the motion and ``/diagnostics`` is
built only while it has a subscriber.

One floor for all outputs: when the input is in a floor frame (the physics output, z up,
floor z = 0; ``vertical`` 'auto' decides by the input's frame_id), the root's
height and tilt are the input's and GMR gives the heading and the horizontal path, so the
world output's feet are never below z = 0 and stand where the physics put them vertically.

Camera motion (beyond the paper; ``camera_mode``): the input's root trajectory does not drift
when the camera does not move, so the GMR motion is fused with it
(:class:`~mocap_global.online.StaticCameraFusion`). ``auto`` (default) reads the keypoint
node's estimate from the image background (``camera_motion_topic``, nav_msgs/Odometry,
matched by stamp): a static camera is fused; a camera whose translation the keypoint node
measured over the floor (``fuse_translating``, default on) has its rotation and position taken
out of the input root first (in the floor frame, with ``floor_topic``, when the input is a
floor frame) and is fused too; so, with ``fuse_rotating``, is a camera that only turns; a
translating camera without a measurement (or, by default, a turning one), an unknown motion or
a missing estimate leaves GMR alone for that frame, and the fusion aligns itself again once
the camera's pose is known again. With a floor input, the horizontal position of a fixed frame
is the lifter's root of the same stamp moved by the estimated camera motion
(``fused_root`` 'lifter', the default; the physics root trails a walker), the height the
input's. ``static`` fuses every frame, ``moving``
never does. ``/diagnostics`` says which mode each frame took.

Bad input never stops the node: a malformed or NaN message is dropped with a warning, a
joint set that does not match the model is reported with the joints it needs, a stamp that
does not advance is dropped, a gap longer than ``max_gap_s`` restarts the accumulation (logged
and counted), and nothing is published until ``lookahead + 1`` frames have arrived (said
once). A non-finite network output never enters the accumulated world pose: the last finite
motion is held for that frame (:mod:`mocap_global.online`; counted as ``nonfinite_outputs``
on ``/diagnostics``). A callback that raises drops its frame (:func:`mocap_core.guard.guarded`).
Weights that are missing, damaged or not plain tensors (a crafted pickle is never executed)
end the start with one line ``gmr: error: ...`` and exit status 2.
"""

from __future__ import annotations

import collections
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Deque, Dict, List, Optional, Sequence, Tuple

import numpy as np
import torch
from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import Odometry, Path as PathMsg
from rclpy.node import Node
from sensor_msgs.msg import JointState, PointCloud2
from trajectory_msgs.msg import MultiDOFJointTrajectory
from visualization_msgs.msg import MarkerArray

from mocap_core import ros_conversions as rc
from mocap_core import topics
from mocap_core.bodies import BodyPublishers, CombinedPublishers, by_stamp
from mocap_core.camera_pose import known_camera_poses
from mocap_core import cdr
from mocap_core.publishing import publish_if_heard
from mocap_core.tf import TfBroadcaster
from mocap_core.diagnostics import NodeDiagnostics
from mocap_core.guard import deserialised_unless, guarded
from mocap_core.pose import Pose
from mocap_core.parameters import (ParamSpec, camera_pose_params, declare_parameters,
                                   help_requested, spin_node)
from mocap_core.qos import STREAM_QOS, input_qos
from mocap_core.rotations import closest_yaw, quat_to_matrix

from .model import TTA_MODES, with_tta
from mocap_core.foot_plant import FootPlantConfig

from .online import (INFERENCE_ENGINES, MEASURED_ROOT_AVERAGES, InputAnchor, OnlineGMR,
                     StaticCameraFusion, WorldFrame, prepare_outputs)
from .se3 import heading_rotation
from .weights import default_weights, load_weights

@dataclass
class _Person:
    """The world stage's state of one person (or of the single-person input)."""

    online: Optional[OnlineGMR] = None        # built at the person's first frame (frame_id)
    last_stamp: int = -1
    path: cdr.PathTrail = field(default_factory=cdr.PathTrail)   # their /path
    said_waiting: bool = False
    seen_ns: int = 0                          # stamp of their last input frame


PARAMETERS = (
    ParamSpec('bodies_motion_topic', topics.bodies_topic('physics', 'motion'), 'Input '
              'motion of every person (names prefixed body_<id>/); once it delivers, each '
              'person gets their own world pose and motion_topic is ignored; empty = one '
              'person only', read_only=True),
    ParamSpec('network_pose_topic', topics.LIFTER_UNSMOOTHED_MOTION, 'The local pose the '
              'network reads, matched by stamp (MultiDOFJointTrajectory, the model\'s joints), '
              'instead of the input\'s own: the lifter\'s frames before its output smoothing, '
              'whose legs swing more than the physics output\'s, so GMR steps farther '
              '(rendered travel set, moving cameras: world RTE 8.0 -> 4.7 %); the body placed '
              'is still the input\'s. A frame without one uses the input\'s pose; empty = '
              'always the input\'s (docs/global.md, "What the network reads")',
              read_only=True),
    ParamSpec('bodies_network_pose_topic', topics.bodies_topic('lifter', 'unsmoothed_motion'),
              'The same for every person (names prefixed body_<id>/), with '
              'bodies_motion_topic; empty = the input\'s', read_only=True),
    ParamSpec('person_timeout_s', 1.0, 'A person absent from the input for longer than this '
              '(stamps) is dropped: their last frames are emitted, their state and topics '
              'removed', min_value=0.0, read_only=True),
    ParamSpec('publish_tf', True, 'Publish every person\'s skeleton on /tf: frames '
              'body_<id> (the pelvis, in frame_id) and body_<id>/<joint> (mocap_core.tf); '
              'built only while /tf has subscribers', read_only=True),
    ParamSpec('motion_topic', topics.PHYSICS_MOTION, 'Input motion '
              '(MultiDOFJointTrajectory): the physics or the lifter stage', read_only=True),
    ParamSpec('weights', '', 'GMR weights file; empty = the shipped weights '
              '(share/mocap_global/weights/gmr.pt)', read_only=True),
    ParamSpec('lookahead', 15, 'Future frames each output waits for: latency = lookahead / '
              'fps (0 = causal; the bidirectional GRU is more accurate with more)',
              read_only=True, min_value=0),
    ParamSpec('window', 48, 'Frames the GRU sees per update (0 = the training window, 64); '
              'the time per frame grows with it', read_only=True, min_value=0),
    ParamSpec('test_time_augmentation', 'none', "Average the motion read off the mirrored "
              "('mirror'), time-reversed ('reverse') or both ('both') window as well: "
              'slightly more accurate, 2 or 4 windows per update', read_only=True,
              additional_constraints="one of: none, mirror, reverse, both"),
    ParamSpec('max_gap_s', 0.25, 'A larger gap between input stamps restarts the '
              'accumulation from a new gravity-aligned pose', min_value=0.0),
    ParamSpec('fill_missing_frames', False, 'Frames missing from the stream (dropped by a '
              'busy keypoint node, a slower camera) are filled in by interpolation at the rate '
              'the weights were trained at (the shipped ones: 30 frames/s; gaps of 1.5 periods '
              'or more), run through the network and the '
              'accumulation, and never published. Off by default: on rendered walks played '
              'live at 41 % of their frames it cut the world skating (28.4 -> 24.8 mm/frame) '
              'but not the path error (world RTE 9.7 -> 11.0 %; docs/global.md). false: every '
              'frame is read as the next one', read_only=True),
    ParamSpec('tilt_correction', 0.05, 'Fraction per frame by which the accumulated '
              'orientation\'s pitch and roll are pulled towards the network\'s tilt estimate '
              '(removes the tilt drift; 0 = the paper\'s pure accumulation)', min_value=0.0,
              max_value=1.0),
    ParamSpec('queue_depth', 100, 'Input messages queued while a frame is processed (older '
              'ones are lost when the queue is full)', min_value=1, read_only=True),
    ParamSpec('output_queue_depth', 30, 'History of the per-frame output topics (reliable): a '
              'subscriber that falls further behind than this (e.g. a recorder on a loaded '
              'machine) loses the oldest messages; raise it to keep every one', min_value=1,
              read_only=True),
    ParamSpec('chunk', 1, 'Frames emitted per network pass: 1 for live use; more (offline, '
              'e.g. mocap process) is faster per frame and adds chunk - 1 frames of delay',
              min_value=1, max_value=64, read_only=True),
    ParamSpec('camera_mode', 'auto', "How the camera moves: 'auto' (from the keypoint "
              "node's camera-motion estimate on camera_motion_topic: a static camera is fused "
              "with the input root, a turning camera's rotation is taken out of the input root "
              "first, a translating camera leaves GMR alone), 'static' (fuse every frame), "
              "'moving' (GMR alone, the paper)", read_only=True,
              additional_constraints='auto, static or moving'),
    ParamSpec('fuse_rotating', False, "camera_mode auto: also fuse the frames of a camera "
              "that only turns, with its rotation taken out (off by default: on the rendered "
              "test a camera that orbits is often taken for one that turns, docs/global.md)",
              read_only=True),
    ParamSpec('fuse_translating', True, "camera_mode auto: fuse the frames whose camera "
              "translation the keypoint node measured over the floor (its floor_topic), with "
              "the camera's rotation and position taken out of the input root first: a "
              "moving camera then fixes the person in the world as a static one does",
              read_only=True),
    *camera_pose_params(
        'the world pose is that pose composed with the input pose, GMR fills gaps and '
        'smooths, and the outputs are in the pose\'s frame; empty = unknown',
        'GMR fills the frame'),
    ParamSpec('static_camera', False, "Same as camera_mode:=static (kept for older launch "
              "files)", read_only=True),
    ParamSpec('camera_motion_topic', topics.CAMERA_MOTION, 'The camera-motion estimate '
              '(nav_msgs/Odometry of the keypoint node) for camera_mode auto; empty = none',
              read_only=True),
    ParamSpec('floor_topic', topics.PHYSICS_FLOOR, 'The physics floor (TransformStamped): '
              'turns the camera rotation into the floor frame when the input is a floor '
              'frame', read_only=True),
    ParamSpec('input_up', 'auto', "Up direction of the input frame for the fusion: 'auto' "
              "(z up, unless the input frame_id is an optical frame: then estimated), "
              "'estimate', or three numbers 'x y z'", read_only=True),
    ParamSpec('fusion_init_s', 1.0, 'Static camera with an estimated up: seconds of GMR '
              'alone while the input frame\'s tilt and heading are estimated', min_value=0.0),
    ParamSpec('fusion_position_time_constant_s', 0.15, 'Time constant of the position '
              'correction towards the input root', min_value=0.0),
    ParamSpec('fusion_orientation_time_constant_s', 1.0, 'Time constant of the orientation '
              'correction towards the input root', min_value=0.0),
    ParamSpec('fusion_static_position_time_constant_s', 0.05, 'The same for the frames of a '
              'camera that stands still (measured static, or camera_mode static) with a floor '
              'input (the physics output): 0 = the output root is the input root moved '
              'rigidly into the world, so the feet stay where the input put them (less '
              'skating, a little more jitter: docs/global.md)', min_value=0.0),
    ParamSpec('fusion_static_orientation_time_constant_s', 0.0, 'The orientation correction '
              'of those frames (0 = the input root orientation, turned into the world)',
              min_value=0.0),
    ParamSpec('camera_pose_root', 'lifter', "With a known camera pose (camera_pose_topic), "
              "where the person's horizontal position comes from: 'lifter' = the lifter's "
              "camera-frame root of the same stamp (network_pose_topic) moved by the pose, "
              "the height and the body staying the input's (the physics root lags the "
              "lifter's and is moved to put the feet on its floor: docs/global.md); "
              "'input' = the input's root", read_only=True,
              additional_constraints='lifter or input'),
    ParamSpec('camera_pose_height', 'lifter', "With a known camera pose and a floor input "
              "(the physics output): where the person's height comes from. 'lifter' = the "
              "whole body is raised by the height of the lifter's root in the pose's world "
              "above the input root (camera_pose_root lifter), its median over "
              "camera_pose_height_window_s and the look-ahead: the heights are then the pose "
              "frame's (the feet on the floor the lifter was sized by, its "
              "camera_pose_floor_z); 'input' = the input's height above its floor (the physics "
              "floor, fitted to the feet, is the world's z = 0; docs/global.md)",
              read_only=True,
              additional_constraints='input or lifter'),
    ParamSpec('camera_pose_root_half_window', 15, "With a known camera pose "
              "(camera_pose_root lifter): the measured root averaged over this many frames "
              "before and after its own, at most the look-ahead (the known-pose counterpart of "
              "fusion_measured_root_half_window: a pose carries no estimate noise, so a wider "
              "average places the person better; docs/global.md)", read_only=True,
              min_value=0),
    ParamSpec('camera_pose_position_time_constant_s', 0.05, "With a known camera pose "
              "(camera_pose_root lifter): time constant of the pull towards the measured root "
              "(the known-pose counterpart of fusion_measured_position_time_constant_s; longer "
              "trails a walker, GMR's steps being short)", read_only=True, min_value=0.0),
    ParamSpec('camera_pose_height_window_s', 2.0, "camera_pose_height lifter: the raise "
              "follows the median over this many seconds before the frame and the look-ahead "
              "frames after it, s (0 = the frame's own, at once)",
              read_only=True, min_value=0.0),
    ParamSpec('camera_pose_height_follow_s', 0.2, "camera_pose_height lifter: time constant "
              "with which the raise follows that median, s (the median steps as frames enter "
              "and leave the window: without it the body bobs)", read_only=True,
              min_value=0.0),
    ParamSpec('fused_root', 'lifter', "Camera mode auto with a floor input (the physics "
              "output), a frame the camera-motion estimate fixes in the world (a static "
              "camera, one whose translation was measured over the floor, or with "
              "fuse_rotating one that turns): where the person's horizontal position comes "
              "from. 'lifter' = the lifter's camera-frame root of the same stamp "
              "(network_pose_topic) moved by the camera's estimated motion, fused as "
              "camera_pose_root lifter fuses it (the height and the body stay the input's); "
              "'input' = the input's root (docs/global.md). Not used for an optical-frame "
              "input or one the physics derotated (floor_start)", read_only=True,
              additional_constraints='lifter or input'),
    ParamSpec('fusion_measured_root_half_window', 8, "A root measured apart from the input "
              "(fused_root lifter; a known pose's: camera_pose_root_half_window) averaged over "
              "this many frames before and after its own, at most the look-ahead (no delay "
              "added)", read_only=True,
              min_value=0),
    ParamSpec('fusion_measured_root_average', 'root', "What that average is taken of: "
              "'root' = the measured roots; 'offset' = their horizontal offsets from the "
              "input roots moved into the world the same way, added to the frame's own input "
              "root (the measured root's slow part, the input's motion from frame to frame: "
              "docs/global.md)", read_only=True,
              additional_constraints=' or '.join(MEASURED_ROOT_AVERAGES)),
    ParamSpec('fusion_measured_position_time_constant_s', 0.15, "Time constant of the "
              "position correction towards a root measured apart from the input (fused_root "
              "lifter; a known pose's: camera_pose_position_time_constant_s): GMR's steps "
              "between, the lifter's noise filtered",
              min_value=0.0),
    ParamSpec('fusion_measured_velocity_correction', False, "With a root measured apart "
              "from the input (camera_pose_root or fused_root lifter): fuse it with an "
              "alpha-beta filter that also learns the velocity GMR's steps miss, so that a "
              "walker is not trailed by the position time constant (docs/global.md)",
              read_only=True),
    ParamSpec('vertical', 'auto', "Where the root's height and tilt come from: 'input' (an "
              "input in a floor frame, z up, floor z = 0, e.g. the physics output: one floor "
              "for all outputs; GMR gives heading and horizontal path), 'gmr' (accumulated "
              "like the rest) or 'auto' ('input' unless the input frame is an optical "
              "frame)"),
    ParamSpec('foot_lock', False, "With the vertical from the input: the root is moved so "
              "that contact points standing on the floor (below lock_height) stay where they "
              "touched down in the world; GMR's translation moves the body only while no foot "
              "stands. Off by default since session 53: foot_plant keeps the standing feet by "
              "bending the legs, and the locked root was the world output's noisiest "
              "(docs/global.md, 'The foot lock, off')"),
    ParamSpec('fusion_moving_lock_time_constant_s', 0.5, 'With foot_lock: fused frames of a '
              'camera that turns without walking (estimate rotating, its position measured '
              'over the floor, or fuse_rotating) keep the foot lock, and the locked root is '
              'pulled towards the fused one with this time constant, s; 0 = they follow the '
              'fused root. Not for a walking camera (estimate moving: its path is the '
              'person\'s) nor a known camera pose (camera_pose_topic), followed as they are',
              min_value=0.0, read_only=True),
    ParamSpec('transition_time_constant_s', 0.3, 'When the treatment of the root changes '
              'between frames (GMR alone, foot lock, fusion, lock pulled towards the fusion: '
              'the camera-motion estimate decides), the output root goes on from the last '
              'one at its velocity and the difference to the new treatment\'s root decays '
              'with this time constant, s; 0 = the new root at once (it jumps)',
              min_value=0.0, read_only=True),
    ParamSpec('heading_smoothing', 7, 'With the vertical from the input: frames on each '
              'side over which the heading offset between the world and the input frame is '
              'averaged (the later ones from the look-ahead; 0 = GMR\'s heading per frame)',
              min_value=0, read_only=True),
    ParamSpec('lock_height', 0.02, 'Height above the floor below which a contact point '
              'stands (foot_lock), m', min_value=0.0),
    ParamSpec('foot_plant', True, 'With the vertical from the input: bend each leg (two-bone '
              'inverse kinematics from the hip) so that the foot points the lifter says stand '
              '(contacts_topic) stay where they landed; the root path stays GMR\'s and the '
              'fusion\'s, what the leg cannot reach slides (or moves the root: '
              'foot_plant_root_follow_s; mocap_core.foot_plant, docs/global.md "Feet planted '
              'by the legs")', read_only=True),
    ParamSpec('contacts_topic', topics.LIFTER_CONTACTS, 'Foot contact probabilities '
              '(JointState: left_heel, left_toe, right_heel, right_toe) matched by stamp, for '
              'foot_plant; a frame without them uses lock_height; empty = heights only',
              read_only=True),
    ParamSpec('bodies_contacts_topic', topics.bodies_topic('lifter', 'contacts'), 'The same '
              'for every person (names prefixed body_<id>/), with bodies_motion_topic',
              read_only=True),
    ParamSpec('contact_threshold', 0.5, 'foot_plant: a contact probability at least this '
              'high makes the point stand', min_value=0.0, max_value=1.0, read_only=True),
    ParamSpec('foot_plant_max_correction', 0.35, 'foot_plant: largest horizontal '
              'correction of a foot, m', min_value=0.0, read_only=True),
    ParamSpec('foot_plant_reach', 1.05, 'foot_plant: the correction stops where the hip-'
              'ankle distance would exceed this fraction of thigh plus shin (above 1 the leg '
              'straightens and the rest slides)', min_value=0.0, read_only=True),
    ParamSpec('foot_plant_release_s', 0.1, 'foot_plant: time constant with which a lifted '
              'foot returns to the input\'s, s', min_value=0.0, read_only=True),
    ParamSpec('foot_plant_double_stance_s', 0.2, 'foot_plant: while both feet stand, the '
              'corrections leak away with this time constant, s (a root drifting under a '
              'person who stands still is not followed by ever longer legs; 0 = never)',
              min_value=0.0, read_only=True),
    ParamSpec('foot_plant_root_follow_s', 0.0, 'foot_plant: > 0: what a standing leg cannot '
              'reach moves the root instead (the foot stays), an offset that returns to the '
              'world root with this time constant, s; 0: the foot slides. Not with a known '
              'camera pose (the root is measured there). Off: it zigzags a real walk\'s path '
              '(docs/global.md)', min_value=0.0, read_only=True),
    ParamSpec('frame_id', 'world', 'frame_id of the outputs'),
    ParamSpec('path_length', 3000, 'Poses kept in /mocap/world/path (0 = all)', min_value=0),
    ParamSpec('flush_after_s', 0.3, 'When no input arrives for this long, emit the frames '
              'still waiting for look-ahead', min_value=0.0),
    ParamSpec('threads', 1, 'Torch CPU threads', read_only=True, min_value=1),
    ParamSpec('device', 'cpu', "Torch device ('cpu' or 'cuda')", read_only=True),
    ParamSpec('inference', 'numpy', "The network's engine: 'numpy' (the same network in "
              'NumPy, to float32 rounding; about 1.7x as fast for one window on a CPU: '
              "mocap_global.inference; used on the CPU without test-time augmentation, else "
              "PyTorch) or 'torch'", read_only=True,
              additional_constraints='one of: numpy, torch'),
)


#: Camera-motion estimates and camera poses kept for matching by stamp (10 s at 30 fps).
MAX_CAMERA_FRAMES = 300


def parse_up(text: str) -> Optional[np.ndarray]:
    """'x y z' (or 'x,y,z') -> unit vector; raises ValueError."""
    try:
        v = np.array([float(t) for t in text.replace(',', ' ').split()], dtype=np.float64)
    except ValueError:
        raise ValueError(f"input_up must be 'auto', 'estimate' or 'x y z', got {text!r}") \
            from None
    if v.shape != (3,) or not np.all(np.isfinite(v)) or np.linalg.norm(v) < 1e-9:
        raise ValueError(f"input_up must be 'auto', 'estimate' or 'x y z', got {text!r}")
    return v / np.linalg.norm(v)



def _measured_root_text(frames: int, missing: int, kind: str) -> str:
    """The diagnostics value of a root measured apart from the input (``camera_pose_root``,
    ``fused_root``): how many frames the main person's took the lifter's root, and how many
    ``kind`` frames of all persons had no lifter pose of their stamp."""
    return (f"the lifter's root in {frames} frames; {missing} {kind}frames of all persons had "
            "none of their stamp (filled from their neighbours', else the input's)")


class GMRNode(Node):
    """The ``gmr`` node (module docstring). Keyword arguments go to ``rclpy.node.Node``
    (``context``, ``parameter_overrides``, ...).

    Raises (at construction): FileNotFoundError for missing weights, ValueError (also
    :class:`~mocap_core.checkpoint.WeightsError`) for unusable weights or a bad parameter.
    """

    def __init__(self, **kwargs) -> None:
        super().__init__('gmr', **kwargs)
        self.p = p = declare_parameters(self, PARAMETERS)
        torch.set_num_threads(int(p['threads']))
        path = Path(p['weights']) if p['weights'] else default_weights()
        if not path.exists():
            raise FileNotFoundError(f'weights not found: {path} (train them with '
                                    '`mocap train gmr --install`)')
        if p['test_time_augmentation'] not in TTA_MODES:
            raise ValueError(f"test_time_augmentation must be one of {TTA_MODES}, got "
                             f"{p['test_time_augmentation']!r}")
        if p['inference'] not in INFERENCE_ENGINES:
            raise ValueError(f'inference must be one of {INFERENCE_ENGINES}, got '
                             f"{p['inference']!r}")
        self.model = with_tta(load_weights(path, p['device']), p['test_time_augmentation'])
        cfg = self.model.cfg
        self.fps = cfg.fps
        if p['vertical'] not in ('auto', 'input', 'gmr'):
            raise ValueError(f"vertical must be 'auto', 'input' or 'gmr', got "
                             f"{p['vertical']!r}")
        if p['input_up'] not in ('auto', 'estimate'):
            parse_up(p['input_up'])              # fail early on a malformed vector
        window = p['window'] or cfg.window
        if p['lookahead'] + p['chunk'] > window - 1:
            raise ValueError(f"lookahead + chunk ({p['lookahead']} + {p['chunk']}) must be "
                             f'at most window - 1 ({window - 1})')
        self.single = _Person()                   # the single-person input
        self.persons: Dict[int, _Person] = {}     # several people (the combined input)
        self.bodies_mode = False
        self.main_id: Optional[int] = None
        self.main_last_ns = -1
        self.bodies = BodyPublishers(self, 'world')
        self.tf = TfBroadcaster(self) if p['publish_tf'] else None
        self.last_input = time.monotonic()
        self.restarts = 0
        self.restart_time: Optional[float] = None
        self.intervals: List[float] = []
        self.rate_checked = False
        self.nonfinite_reported = 0
        out_qos = input_qos(STREAM_QOS, p['output_queue_depth'])
        self.pub = {
            'motion': self.create_publisher(MultiDOFJointTrajectory, topics.WORLD_MOTION,
                                            out_qos),
            'joints3d': self.create_publisher(PointCloud2, topics.WORLD_JOINTS3D, out_qos),
            'joint_states': self.create_publisher(JointState, topics.WORLD_JOINT_STATES,
                                                  out_qos),
            'odom': self.create_publisher(Odometry, topics.WORLD_ODOM, out_qos),
            'path': self.create_publisher(PathMsg, topics.WORLD_PATH, out_qos),
            'markers': self.create_publisher(MarkerArray, topics.WORLD_MARKERS, out_qos),
            'floor': self.create_publisher(TransformStamped, topics.WORLD_FLOOR, out_qos),
        }
        self.combined = CombinedPublishers(self, 'world')
        self.input_frame = ''
        if p['camera_mode'] not in ('auto', 'static', 'moving'):
            raise ValueError(f"camera_mode must be auto, static or moving, got "
                             f"{p['camera_mode']!r}")
        self.camera_mode = 'static' if p['static_camera'] else p['camera_mode']
        self.output_frame = p['frame_id']
        self.camera_pose_missing = 0
        #: frames with a known pose but no lifter root of their stamp (camera_pose_root)
        self.camera_pose_root_missing = 0
        for name in ('camera_pose_root', 'fused_root', 'camera_pose_height'):
            if p[name] not in ('lifter', 'input'):
                raise ValueError(f'{name} must be lifter or input, got {p[name]!r}')
        if p['fusion_measured_root_average'] not in MEASURED_ROOT_AVERAGES:
            raise ValueError('fusion_measured_root_average must be root or offset, got '
                             f"{p['fusion_measured_root_average']!r}")
        #: fixed frames without a lifter root of their stamp (fused_root lifter; all persons)
        self.fused_root_missing = 0
        # (its message type checked only where a pose topic is given, as in the other nodes)
        self.camera_poses = known_camera_poses(
            p if p['camera_pose_topic'] else dict(p, camera_pose_type='odometry'),
            MAX_CAMERA_FRAMES)
        if p['camera_pose_topic']:
            self.camera_mode = 'known'
        #: stamp -> (state, R0 (3, 3), camera position (3,) m in the first camera frame or
        #: None where not measured)
        self.camera_motion: Dict[int, Tuple[str, np.ndarray, Optional[np.ndarray]]] = {}
        self.camera_stamps: Deque[int] = collections.deque()
        self.floor: Optional[Tuple[int, np.ndarray, np.ndarray]] = None  # stamp, A, b
        #: person id (None: the single-person input) -> stamp -> (4,) contact probabilities
        self.contacts: Dict[Optional[int], Dict[int, np.ndarray]] = {}
        #: person id (None: the single-person input) -> stamp -> the network's pose
        #: (``network_pose_topic``), the last ``MAX_CAMERA_FRAMES``
        self.network_poses: Dict[Optional[int], Dict[int, Pose]] = {}
        self.camera_frames: Dict[str, int] = {}
        self.diag = NodeDiagnostics(self, 'gmr', hardware_id=path.name)
        self.diag.set_value('model', f'GMR {cfg.layers}x{cfg.hidden} bi-GRU, '
                            f'{cfg.fps:g} fps, window {window}, '
                            f"test-time augmentation {p['test_time_augmentation']}")
        self.diag.set_value('lookahead_frames', p['lookahead'])
        self.diag.set_value('latency_s', f"{p['lookahead'] / cfg.fps:.3f}")
        self.diag.set_value('camera_mode', self.camera_mode)
        self.diag.set_value('nonfinite_outputs', 0)
        self.diag.watch('input', self.create_subscription(
            MultiDOFJointTrajectory, p['motion_topic'], guarded(self, deserialised_unless(
                lambda: self.bodies_mode, MultiDOFJointTrajectory, self.on_motion,
                decode=cdr.decode_motion), 'motion'),
            input_qos(STREAM_QOS, p['queue_depth']), raw=True))
        if p['bodies_motion_topic']:
            self.diag.watch('bodies', self.create_subscription(
                MultiDOFJointTrajectory, p['bodies_motion_topic'],
                guarded(self, deserialised_unless(
                    lambda: False, MultiDOFJointTrajectory, self.on_bodies_motion,
                    decode=cdr.decode_motion), 'bodies motion'),
                input_qos(STREAM_QOS, p['queue_depth']), raw=True))
        if self.camera_mode == 'known':
            self.diag.watch('camera_pose', self.create_subscription(
                rc.camera_pose_message_type(p['camera_pose_type']), p['camera_pose_topic'],
                guarded(self, self.on_camera_pose, 'camera pose'),
                input_qos(STREAM_QOS, p['queue_depth'])))
        if self.camera_mode in ('auto', 'known') and p['floor_topic']:
            self.create_subscription(TransformStamped, p['floor_topic'],
                                     guarded(self, self.on_floor, 'floor'),
                                     input_qos(STREAM_QOS, p['queue_depth']))
        if p['network_pose_topic']:     # (ignored, not even decoded, once everyone's come)
            self.create_subscription(
                MultiDOFJointTrajectory, p['network_pose_topic'],
                guarded(self, deserialised_unless(
                    lambda: self.bodies_mode, MultiDOFJointTrajectory, self.on_network_pose,
                    decode=cdr.decode_motion), 'network pose'),
                input_qos(STREAM_QOS, p['queue_depth']), raw=True)
        if p['bodies_network_pose_topic'] and p['bodies_motion_topic']:
            self.create_subscription(
                MultiDOFJointTrajectory, p['bodies_network_pose_topic'],
                guarded(self, deserialised_unless(
                    lambda: False, MultiDOFJointTrajectory, self.on_bodies_network_pose,
                    decode=cdr.decode_motion), 'bodies network pose'),
                input_qos(STREAM_QOS, p['queue_depth']), raw=True)
        if p['foot_plant'] and p['contacts_topic']:
            self.create_subscription(JointState, p['contacts_topic'],
                                     guarded(self, self.on_contacts, 'contacts'),
                                     input_qos(STREAM_QOS, p['queue_depth']))
        if p['foot_plant'] and p['bodies_contacts_topic']:
            self.create_subscription(JointState, p['bodies_contacts_topic'],
                                     guarded(self, self.on_bodies_contacts, 'bodies contacts'),
                                     input_qos(STREAM_QOS, p['queue_depth']))
        if self.camera_mode == 'auto' and p['camera_motion_topic']:
            self.diag.watch('camera_motion', self.create_subscription(
                Odometry, p['camera_motion_topic'],
                guarded(self, self.on_camera_motion, 'camera motion'),
                input_qos(STREAM_QOS, p['queue_depth'])))
        self.diag.watch('motion', self.pub['motion'])
        self.create_timer(0.1, guarded(self, self.on_idle, 'idle'))
        self.get_logger().info(
            f"gmr ready: {path} ({cfg.layers}x{cfg.hidden} GRU at {cfg.fps:g} fps), input "
            f"{p['motion_topic']}, look-ahead {p['lookahead']} frames "
            f"({p['lookahead'] / cfg.fps:.2f} s), camera mode {self.camera_mode}")

    def _make_online(self, frame_id: str, pid: Optional[int] = None) -> OnlineGMR:
        p = self.p
        self.input_frame = frame_id
        fusion = None
        up = None
        if p['input_up'] == 'auto':
            up = None if 'optical' in frame_id else np.array([0.0, 0.0, 1.0])
        elif p['input_up'] != 'estimate':
            up = parse_up(p['input_up'])
        if self.camera_mode != 'moving':
            fusion = StaticCameraFusion(
                self.fps, p['fusion_init_s'], p['fusion_position_time_constant_s'],
                p['fusion_orientation_time_constant_s'], input_up=up,
                known_world=self.camera_mode == 'known',
                static_position_time_constant_s=p['fusion_static_position_time_constant_s'],
                static_orientation_time_constant_s=p[
                    'fusion_static_orientation_time_constant_s'],
                measured_position_time_constant_s=p[
                    'camera_pose_position_time_constant_s' if self.camera_mode == 'known'
                    else 'fusion_measured_position_time_constant_s'],
                measured_velocity_correction=p['fusion_measured_velocity_correction'])
            self.get_logger().info(
                ('static camera: fusing' if self.camera_mode == 'static' else
                 'camera mode auto: fusing the frames of a static or turning camera')
                + ' with the input root trajectory ('
                + ('input frame up = ' + np.array2string(up, precision=3)
                   if up is not None else
                   f"up of '{frame_id}' estimated over {p['fusion_init_s']:g} s") + ')')
        model_up = None
        if self.model.cfg.root_input == 'up':
            model_up = up if up is not None else np.array([0.0, -1.0, 0.0])
        mode = p['vertical']
        on_floor = ('optical' not in frame_id) if mode == 'auto' else mode == 'input'
        # a known pose's height from the lifter's root (camera_pose_height)
        known_height = on_floor and self.camera_mode == 'known' \
            and p['camera_pose_height'] == 'lifter' and p['camera_pose_root'] == 'lifter'
        self.diag.set_value('vertical', 'input' if on_floor else 'gmr')
        if on_floor:
            self.get_logger().info(f"the input '{frame_id}' is a floor frame: height and tilt "
                                   'from the input, heading and horizontal path from GMR' + (
                                       "; with the known camera pose, the height from the "
                                       "lifter's root (camera_pose_height)"
                                       if known_height else ''))
        state = OnlineGMR(self.model, p['lookahead'], p['window'] or None, p['max_gap_s'],
                          p['tilt_correction'], fusion, model_up, p['device'],
                          chunk=p['chunk'], floor_input=on_floor,
                          foot_lock=p['foot_lock'], lock_height=p['lock_height'],
                          heading_smoothing=p['heading_smoothing'],
                          # a known camera pose carries no estimate noise: followed as it is
                          moving_lock_time_constant_s=(
                              0.0 if self.camera_mode == 'known'
                              else p['fusion_moving_lock_time_constant_s']),
                          network_rate_hz=self.fps if p['fill_missing_frames'] else 0.0,
                          inference=p['inference'],
                          foot_plant=FootPlantConfig(
                              lock_height=p['lock_height'],
                              release_time_constant_s=p['foot_plant_release_s'],
                              max_correction=p['foot_plant_max_correction'],
                              reach=p['foot_plant_reach'],
                              double_stance_time_constant_s=p['foot_plant_double_stance_s'],
                              # a known camera pose measures the root: it is not moved
                              root_follow_time_constant_s=(
                                  0.0 if self.camera_mode == 'known'
                                  else p['foot_plant_root_follow_s']))
                          if p['foot_plant'] else None,
                          contacts=self.contacts.setdefault(pid, {}),
                          contact_threshold=p['contact_threshold'],
                          transition_time_constant_s=p['transition_time_constant_s'],
                          measured_root_half_window=min(p[
                              'camera_pose_root_half_window' if self.camera_mode == 'known'
                              else 'fusion_measured_root_half_window'], p['lookahead']),
                          measured_root_average=p['fusion_measured_root_average'],
                          measured_height_window_s=(
                              p['camera_pose_height_window_s'] if known_height else None),
                          measured_height_follow_s=p['camera_pose_height_follow_s'])
        self.diag.set_value('inference', state.inference)
        return state

    def _keep_contacts(self, pid: Optional[int], stamp: int, probs: np.ndarray) -> None:
        """Keep one person's contact probabilities of a stamp (the last
        ``MAX_CAMERA_FRAMES``; dicts keep their insertion order)."""
        kept = self.contacts.setdefault(pid, {})
        kept[stamp] = probs
        while len(kept) > MAX_CAMERA_FRAMES:
            del kept[next(iter(kept))]

    def on_contacts(self, msg: JointState) -> None:
        """The single-person input's foot contact probabilities (``contacts_topic``)."""
        self._read_contacts(msg, lambda m: [(None, rc.msg_to_contacts(m))])

    def on_bodies_contacts(self, msg: JointState) -> None:
        """Every person's foot contact probabilities (``bodies_contacts_topic``)."""
        self._read_contacts(msg, rc.msg_to_bodies_contacts)

    def _parsed(self, msg, parse, what: str) -> Optional[list]:
        """``parse(msg)``: the ``(person id or None, value)`` pairs of a message, or None for
        a malformed one (counted and logged at a limited rate)."""
        try:
            return parse(msg)
        except rc.MessageError as exc:
            self.diag.errors += 1
            self.get_logger().warn(f'ignoring {what}: {exc}', throttle_duration_sec=5.0)
            return None

    def _read_contacts(self, msg: JointState, parse) -> None:
        """Keep the ``(person id, (4,) probabilities)`` pairs ``parse(msg)`` gives; a
        malformed message is counted and dropped."""
        bodies = self._parsed(msg, parse, 'contacts')
        stamp = rc.stamp_to_ns(msg.header.stamp)
        for pid, probs in bodies or ():
            self._keep_contacts(None if pid is None else int(pid), stamp,
                                np.asarray(probs, dtype=float))

    def on_network_pose(self, msg: MultiDOFJointTrajectory) -> None:
        """The single-person input's network pose (``network_pose_topic``)."""
        names = self.model.cfg.joint_names
        self._read_network_poses(msg, lambda m: [(None, rc.motion_to_pose(m, names))])

    def on_bodies_network_pose(self, msg: MultiDOFJointTrajectory) -> None:
        """Every person's network pose (``bodies_network_pose_topic``)."""
        names = list(self.model.cfg.joint_names)

        def parse(m):
            return [(pid, pose if list(pose.joint_names) == names else rc.motion_to_pose(
                rc.pose_to_motion(pose, m.header), names)) for pid, pose in
                rc.motion_to_bodies(m)]
        self._read_network_poses(msg, parse)

    def _read_network_poses(self, msg: MultiDOFJointTrajectory, parse) -> None:
        """Keep the ``(person id or None, Pose)`` pairs ``parse(msg)`` gives for the input
        frames of the same stamp; a malformed message is counted and dropped."""
        stamp = rc.stamp_to_ns(msg.header.stamp)
        for pid, pose in self._parsed(msg, parse, 'network pose') or ():
            key = None if pid is None else int(pid)
            self._keep_network_pose(key, self.single if key is None else self.persons.get(key),
                                    stamp, pose)

    def _keep_network_pose(self, pid: Optional[int], person: Optional['_Person'], stamp: int,
                           pose: Pose) -> None:
        """Keep a network pose for the input frame of the same stamp; a frame already
        added reads it from now on."""
        kept = self.network_poses.setdefault(pid, {})
        kept[stamp] = pose
        while len(kept) > MAX_CAMERA_FRAMES:
            del kept[next(iter(kept))]
        if person is not None and person.online is not None:
            try:
                person.online.set_network_pose(stamp, pose)
            except ValueError as exc:
                self.diag.errors += 1
                kept.pop(stamp, None)
                self.get_logger().warn(f'ignoring network pose: {exc}',
                                       throttle_duration_sec=5.0)

    def on_camera_motion(self, msg: Odometry) -> None:
        """Keep the camera-motion estimate of each stamp (the last ``MAX_CAMERA_FRAMES``)."""
        try:
            state, q, _ = rc.odometry_to_camera_motion(msg)
        except rc.MessageError as exc:
            self.diag.errors += 1
            self.get_logger().warn(f'ignoring camera motion: {exc}', throttle_duration_sec=5.0)
            return
        stamp = rc.stamp_to_ns(msg.header.stamp)
        if stamp not in self.camera_motion:
            self.camera_stamps.append(stamp)
        self.camera_motion[stamp] = (state, quat_to_matrix(q),
                                     rc.odometry_to_camera_position(msg))
        while len(self.camera_stamps) > MAX_CAMERA_FRAMES:
            self.camera_motion.pop(self.camera_stamps.popleft(), None)

    def on_camera_pose(self, msg) -> None:
        """Keep the camera's optical-frame pose in the world (``camera_pose_topic``)."""
        stamp, t, q = rc.camera_pose_from_msg(msg)
        status = self.camera_poses.add(stamp, t, q)
        if status == 'invalid':
            self.diag.errors += 1
            self.get_logger().warn('ignoring camera pose: not finite', throttle_duration_sec=5.0)
            return
        if status != 'old' and msg.header.frame_id and \
                self.output_frame != msg.header.frame_id:
            self.output_frame = msg.header.frame_id
            self.get_logger().info(f"known camera pose: outputs in '{self.output_frame}'")

    def camera_pose_at(self, stamp: int) -> Optional[Tuple[np.ndarray, np.ndarray]]:
        """The camera's optical frame in the world at ``stamp`` (rotation, position)
        (:class:`mocap_core.camera_pose.KnownCameraPoses`); None when there is none."""
        return self.camera_poses.at(stamp)

    def _known_anchor(self, stamp: int, on_floor: bool,
                      network_pose: Optional[Pose] = None) -> InputAnchor:
        """The input frame in the world from the known camera pose (and the physics floor
        for a floor input); not fixed (GMR fills) without a pose near ``stamp``. With
        ``camera_pose_root`` lifter, the lifter's camera-frame root of this stamp
        (``network_pose``) moved by the pose is the measured root (``InputAnchor.root``)."""
        pose = self.camera_pose_at(stamp)
        if pose is None or (on_floor and self.floor is None):
            self.camera_pose_missing += 1
            self.diag.set_value('camera_pose', 'missing for this frame: GMR fills')
            return InputAnchor(False)
        self.diag.set_value('camera_pose', 'ok')
        R_wc, t_wc = pose
        root = None
        if self.p['camera_pose_root'] == 'lifter':
            if network_pose is not None:
                root = R_wc @ np.asarray(network_pose.root_position, float) + t_wc
            if root is None or not np.all(np.isfinite(root)):
                root = None
                self.camera_pose_root_missing += 1
        if not on_floor:
            return InputAnchor(True, R_wc, t_wc, known=True, root=root)
        # one floor for all outputs: the physics floor is the world's z = 0 (the world frame
        # of the pose has z up, REP-103), so the known pose gives the floor frame's heading
        # and its position along the floor; the vertical and tilt stay the physics' (an
        # estimated floor a few degrees off would otherwise tilt the world output and lift
        # its feet off z = 0)
        _, A, b = self.floor
        M = R_wc @ A
        origin = R_wc @ b + t_wc
        return InputAnchor(True, heading_rotation(closest_yaw(M)),
                           np.array([origin[0], origin[1], 0.0]), known=True, root=root)

    def on_floor(self, msg: TransformStamped) -> None:
        """The physics floor in the camera frame: ``p_camera = A p_floor + b``."""
        q, b = rc.transform_stamped_to_arrays(msg)
        n = float(np.linalg.norm(q))
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(b)) and n > 0.5):
            self.get_logger().warn('ignoring floor: not a finite transform',
                                   throttle_duration_sec=5.0)
            return
        self.floor = (rc.stamp_to_ns(msg.header.stamp), quat_to_matrix(q / n), b)

    def _anchor(self, stamp: int, on_floor: bool,
                network_pose: Optional[Pose] = None) -> Optional[InputAnchor]:
        """The camera motion of this frame as an :class:`InputAnchor` (camera_mode auto;
        None otherwise): fixed for a static or turning camera, with the camera's rotation
        since the first image (in the floor frame for a floor input: ``on_floor``, an input
        frame that is not an optical frame, as the physics floor), else not fixed; with a
        known camera pose, the input frame in the world."""
        if self.camera_mode == 'known':
            return self._known_anchor(stamp, on_floor, network_pose)
        if self.camera_mode != 'auto':
            return None
        cm = self.camera_motion.get(stamp)
        state = 'no estimate' if cm is None else cm[0]
        position = None
        if cm is not None and cm[2] is not None and self.p['fuse_translating']:
            position = cm[2]                # a static camera may have moved before it stood
            if state != 'static':
                state += ' (translation measured)'
        self.camera_frames[state] = self.camera_frames.get(state, 0) + 1
        self.diag.set_value('camera_motion', state)
        if on_floor and self.input_frame.endswith(topics.START_FRAME_SUFFIX):
            return self._derotated_anchor(cm, state, position)
        fusable = ('static', 'rotating') if self.p['fuse_rotating'] else ('static',)
        if cm is None or (state not in fusable and position is None):
            return InputAnchor(False)
        R0 = cm[1]
        C = np.zeros(3) if position is None else position
        walking = state.startswith('moving')
        if not on_floor:
            return InputAnchor(True, R0, C, static=state == 'static', translating=walking)
        if self.floor is None:
            # no floor yet: the camera's motion cannot be put into the floor frame
            return InputAnchor(state == 'static', static=state == 'static')
        # p_first_camera = R0 p_camera + C and p_camera = A p_floor + b, for the floor frame
        # of the first image as for this one; the lifter's root of this stamp goes the same
        # way (fused_root lifter)
        _, A, b = self.floor
        root = self._fused_root(network_pose, R0, C)
        return InputAnchor(True, A.T @ R0 @ A, A.T @ (R0 @ b + C - b),
                           static=state == 'static', translating=walking,
                           root=None if root is None else A.T @ (root - b))

    def _fused_root(self, network_pose: Optional[Pose], R0: np.ndarray,
                    C: np.ndarray) -> Optional[np.ndarray]:
        """With ``fused_root`` lifter, the lifter's camera-frame root of the frame's stamp
        (``network_pose``) in the first camera frame, ``R0 root + C`` (m; R0 (3, 3), C (3,):
        the camera's estimated orientation and position there); None with ``input``, or when
        the stamp has no finite lifter root (counted: the input's root is fused)."""
        if self.p['fused_root'] != 'lifter':
            return None
        if network_pose is not None:
            root = R0 @ np.asarray(network_pose.root_position, float) + C
            if np.all(np.isfinite(root)):
                return root
        self.fused_root_missing += 1
        return None

    def _derotated_anchor(self, cm, state: str, position: Optional[np.ndarray]
                          ) -> InputAnchor:
        """The anchor of a floor input from which the physics stage took the camera's
        rotation out (``derotate_camera``; frame ``floor_start``, the floor frame of the first
        image): a camera that does not translate leaves that frame where the world is, so
        static and turning frames are fixed with the identity, the physics output moved
        rigidly (the static time constants); a translation measured over the floor moves
        it by ``A^T C`` (A the floor's axes in the first camera frame, C the camera's
        position there); other frames are GMR's."""
        standing = cm is not None and state in ('static', 'rotating')
        if position is None or self.floor is None:
            return InputAnchor(standing, static=standing)
        f_stamp, A, _ = self.floor
        # the floor message is in the current camera frame of its stamp: turn it into the
        # first image's frame with the camera's rotation then
        at = self.camera_motion.get(f_stamp)
        A_start = (at[1] if at is not None else cm[1]) @ A
        return InputAnchor(True, np.eye(3), A_start.T @ position,
                           static=standing and state == 'static',
                           translating=state.startswith('moving'))

    @property
    def online(self) -> Optional[OnlineGMR]:
        """The main person's :class:`OnlineGMR` (the single-person input's without several
        people), or None before the first frame."""
        if self.bodies_mode:
            person = self.persons.get(self.main_id)
            return None if person is None else person.online
        return self.single.online

    def _pose(self, msg: MultiDOFJointTrajectory, pose=None):
        """The message's pose in the model's joint order, or None (reported)."""
        names = self.model.cfg.joint_names
        try:
            return rc.motion_to_pose(msg, names) if pose is None else pose
        except rc.MessageError as exc:
            self.diag.errors += 1
            if 'lacks joint' in str(exc):
                self.diag.error('joint set does not match the model')
                self.get_logger().error(
                    f'dropping motion: joint set does not match the GMR model ({exc}); '
                    f'the model needs {len(names)} joints: {", ".join(names)}',
                    throttle_duration_sec=2.0)
            else:
                self.get_logger().error(f'dropping motion: {exc}', throttle_duration_sec=2.0)
            return None

    def on_motion(self, msg: MultiDOFJointTrajectory) -> None:
        """One input frame of the single-person input (ignored once the combined input of
        several people delivers)."""
        if self.bodies_mode:
            return
        self.diag.input.tick()
        pose = self._pose(msg)
        if pose is not None:
            self._push(None, self.single, rc.stamp_to_ns(msg.header.stamp), pose,
                       msg.header.frame_id)

    def on_bodies_motion(self, msg: MultiDOFJointTrajectory) -> None:
        """One input frame of every person (names prefixed ``body_<id>/``, the main person
        first)."""
        self.diag.input.tick()
        if not self.bodies_mode:
            self.bodies_mode = True
            # the main person comes again with the combined input: what the single-person
            # input left waiting is dropped (not published twice)
            self.single = _Person()
            self.get_logger().info(f"following every person on {self.p['bodies_motion_topic']}"
                                   f" ({self.p['motion_topic']} is ignored from now on)")
        try:
            bodies = rc.motion_to_bodies(msg)
        except rc.MessageError as exc:
            self.diag.errors += 1
            self.get_logger().error(f'dropping motion: {exc}', throttle_duration_sec=2.0)
            return
        stamp = rc.stamp_to_ns(msg.header.stamp)
        if stamp < self.main_last_ns - int(self.p['max_gap_s'] * 1e9):
            self.main_last_ns = -1                # a new stream (a bag played again)
        with self.diag.processing():     # every person's frame, timed as one message
            batch = self._add_everyone(bodies, stamp, msg.header)
            # one network pass for everybody whose frame is ready, then each one's frames
            prepare_outputs([person.online for _, person, _ in batch])
            ready = [(pid, person, frames + person.online.take(), event, gap)
                     for pid, person, (frames, event, gap) in batch]
        self._publish_combined([(pid, self._finish(pid, person, frames, event, gap))
                                for pid, person, frames, event, gap in ready])
        timeout = int(self.p['person_timeout_s'] * 1e9)
        for pid in [q for q, pr in self.persons.items()
                    if stamp - pr.seen_ns > timeout or pr.seen_ns - stamp > max(timeout, 10**9)]:
            person = self.persons.pop(pid)
            if person.online is not None and person.online.pending():
                self._publish_combined([(pid, self._publish(pid, person,
                                                            person.online.flush()))])
            self.contacts.pop(pid, None)
            self.network_poses.pop(pid, None)
            self.main_id = min(self.persons) if self.persons else None
            self.bodies.remove(pid)
            self.get_logger().info(f'person {pid} gone: their topics are removed')

    def _add_everyone(self, bodies, stamp: int, header) -> list:
        """:meth:`_add` each person's pose (new people get a state); returns
        ``(id, state, what _add returned)`` of the frames taken."""
        names = list(self.model.cfg.joint_names)
        batch = []
        for pid, pose in bodies:
            if list(pose.joint_names) != names:
                pose = self._pose(rc.pose_to_motion(pose, header))
                if pose is None:
                    continue
            person = self.persons.get(pid)
            if person is None:
                person = self.persons[pid] = _Person()
                self.get_logger().info(f'person {pid}: new')
                self.main_id = min(self.persons)
            person.seen_ns = stamp
            added = self._add(pid, person, stamp, pose, header.frame_id)
            if added is not None:
                batch.append((pid, person, added))
        return batch

    def _push(self, pid: Optional[int], person: _Person, stamp: int, pose,
              frame_id: str) -> None:
        """Check the stamp, push to the person's :class:`OnlineGMR`, publish the frames
        that became ready."""
        with self.diag.processing():
            added = self._add(pid, person, stamp, pose, frame_id)
            if added is not None:
                frames, event, gap = added
                frames = frames + person.online.take()
        if added is not None:
            self._finish(pid, person, frames, event, gap)

    def _add(self, pid: Optional[int], person: _Person, stamp: int, pose, frame_id: str):
        """Check the stamp and add the frame to the person's :class:`OnlineGMR` (without
        emitting). Returns (frames a restart ended, event, gap s) or None if dropped."""
        if person.last_stamp - stamp > self.p['max_gap_s'] * 1e9:
            # a new stream (e.g. a bag played again): the accumulation restarts below
            self.get_logger().warn(
                f'motion stamps jumped back by {(person.last_stamp - stamp) * 1e-9:.1f} s '
                '(a bag restarted?): starting a new stream')
            person.last_stamp = -1
        if stamp <= person.last_stamp:
            self.diag.dropped += 1
            self.get_logger().warn('motion stamp did not advance; frame dropped',
                                   throttle_duration_sec=2.0)
            return None
        if person.online is None:
            person.online = self._make_online(frame_id, pid)
        gap = (stamp - person.last_stamp) * 1e-9 if person.last_stamp >= 0 else 0.0
        person.last_stamp = stamp
        if pid is None or pid == self.main_id:
            self._check_rate(gap)
        network_pose = self.network_poses.get(pid, {}).pop(stamp, None)
        try:
            frames, event = person.online.add(
                stamp, pose, self._anchor(stamp, 'optical' not in self.input_frame,
                                          network_pose), network_pose)
        except ValueError as exc:
            self.diag.errors += 1
            self.get_logger().error(f'dropping motion: {exc}', throttle_duration_sec=2.0)
            return None
        return frames, event, gap

    def _finish(self, pid: Optional[int], person: _Person, frames, event: str,
                gap: float) -> List[WorldFrame]:
        """After :meth:`_add` and the emission: restarts, the first-frame log, publish
        (:meth:`_publish`; returns the frames published)."""
        self.diag.error(None)
        self.last_input = time.monotonic()
        if event:
            self.restart_time = time.monotonic()
            self.restarts += 1
            self.diag.set_value('restarts', self.restarts)
            self.diag.warn(f'accumulation restarted ({event})')
            self.get_logger().warn(f'time gap of {gap:.3f} s (> max_gap_s): world pose '
                                   'accumulation restarted from a new gravity-aligned pose')
        if not frames and person.online.pending() and not person.said_waiting:
            person.said_waiting = True
            self.get_logger().info(
                f'waiting for {person.online.frames_needed()} frames (look-ahead) before the '
                'first world pose')
        return self._publish(pid, person, frames)

    def _check_rate(self, dt: float) -> None:
        """Warn once when the input rate is not the model's (the motions per frame would be
        wrong by the ratio)."""
        if self.rate_checked or not 0 < dt <= self.p['max_gap_s']:
            return
        self.intervals.append(dt)
        if len(self.intervals) >= 30:
            self.rate_checked = True
            rate = 1.0 / float(np.median(self.intervals))
            self.diag.set_value('input_stamp_rate_hz', f'{rate:.1f}')
            filled = self.p['fill_missing_frames'] and 2 * self.fps >= 3 * rate
            if abs(rate / self.fps - 1.0) > 0.2 and filled:
                self.get_logger().info(
                    f'input rate {rate:.1f} Hz, below the model rate {self.fps:g} fps: the '
                    'missing frames are filled in for the network (fill_missing_frames)')
            elif abs(rate / self.fps - 1.0) > 0.2:
                msg = (f'input rate {rate:.1f} Hz differs from the model rate {self.fps:g} '
                       f'fps: the network sees the motion at {self.fps / rate:.1f}x its pace '
                       '(trained for 0.5-1.5x; measured with 41 % of the frames: world RTE 9.7 '
                       'against 7.0 % with all; fill_missing_frames fills the gaps instead; '
                       'docs/global.md)')
                self.diag.warn(msg)
                self.get_logger().warn(msg)

    def _everyone(self):
        """``(id or None, state)`` of every person followed now."""
        if self.bodies_mode:
            return list(self.persons.items())
        return [(None, self.single)]

    def on_idle(self) -> None:
        """Emit the frames waiting for look-ahead when the input pauses; clear the restart
        warning on /diagnostics after 5 s."""
        if self.restart_time is not None and time.monotonic() - self.restart_time > 5.0:
            self.restart_time = None
            self.diag.warn(None)
        if time.monotonic() - self.last_input > self.p['flush_after_s']:
            self.flush()

    def flush(self) -> None:
        """End of the input (offline processing): emit the frames waiting for look-ahead."""
        self._publish_combined([
            (pid, self._publish(pid, person, person.online.flush()))
            for pid, person in self._everyone()
            if person.online is not None and person.online.pending()])

    def _publish(self, pid: Optional[int], person: _Person,
                 frames: Sequence[WorldFrame]) -> List[WorldFrame]:
        """A person's ready frames: on their own topics, and on the single-person topics
        for the main person (or the single-person input). Returns the frames published (the
        finite ones), for the caller's combined messages (:meth:`_publish_combined`)."""
        good = []
        for f in frames:
            pose = f.pose
            if not (np.all(np.isfinite(pose.rotations))
                    and np.all(np.isfinite(pose.root_position))):
                self.diag.errors += 1
                self.get_logger().error('world pose not finite; frame dropped',
                                        throttle_duration_sec=2.0)
                continue
            good.append(f)
            header = rc.make_header(f.stamp_ns, self.output_frame)
            if self.tf is not None and self.tf.subscribers() > 0:
                self.tf.send_pose(pose, header, 1 if pid is None else pid)
            odom = cdr.root_to_odometry(pose.root_position, pose.rotations[0], header,
                                        linear_velocity=f.linear_velocity,
                                        angular_velocity=f.angular_velocity)
            if f.first:
                person.path.clear()              # a new segment: a new path
            person.path.max_length = self.p['path_length']
            person.path.append(header, pose.root_position, pose.rotations[0])
            if pid is not None:
                self._publish_body(pid, pose, header, odom, person.path)
            if pid is None or (pid == self.main_id and f.stamp_ns > self.main_last_ns):
                if pid is not None:
                    self.main_last_ns = f.stamp_ns
                self._publish_main(f, pose, header, odom, person.path)
            self.diag.output.tick()
        online = self.online
        if online is not None:
            self._report_nonfinite(online.nonfinite_outputs)
            fusion = online.fusion
            self.diag.set_value('segments', online.segments)
            self.diag.set_value('filled_frames', online.filled_frames)
            self.diag.set_value('treatment_changes', online.treatment_changes)
            if self.p['network_pose_topic'] or self.p['bodies_network_pose_topic']:
                self.diag.set_value('network_pose_frames', online.network_pose_frames)
            planter = online.planter
            if planter is not None:
                self.diag.set_value('foot_plant', (
                    f"correction left {planter.last_correction['left']:.3f} m, right "
                    f"{planter.last_correction['right']:.3f} m; contacts from the lifter in "
                    f'{online.planted_with_contacts} frames, from heights in '
                    f'{online.planted_by_height}; cut by the reach {planter.limited_frames}; '
                    f'root held back by {float(np.hypot(*planter.root_offset)):.3f} m'))
            if fusion is not None:
                self.diag.set_value('fusion', 'on' if fusion.ready else 'initialising')
            if self.camera_mode == 'known':
                self.diag.set_value('camera_pose_missing_frames', self.camera_pose_missing)
                if self.p['camera_pose_root'] == 'lifter':
                    self.diag.set_value('camera_pose_root', _measured_root_text(
                        online.measured_root_frames, self.camera_pose_root_missing, ''))
                if online.measured_height_window_s is not None:
                    self.diag.set_value('camera_pose_height', (
                        "the lifter's root: the body raised by "
                        f'{100 * online.measured_height:.1f} cm (median over '
                        f'{online.measured_height_window_s:g} s and the look-ahead)')
                        if online.measured_height is not None
                        else "the lifter's root: not measured yet")
            if self.camera_mode == 'auto':
                self.diag.set_value('camera_motion_frames', ', '.join(
                    f'{k} {v}' for k, v in sorted(self.camera_frames.items())))
                self.diag.set_value('unfused_frames', online.unanchored_frames)
                if self.p['fused_root'] == 'lifter' and 'optical' not in self.input_frame \
                        and not self.input_frame.endswith(topics.START_FRAME_SUFFIX):
                    self.diag.set_value('fused_root', _measured_root_text(
                        online.measured_root_frames, self.fused_root_missing, 'fixed '))
        self.diag.set_value('persons', len(self.persons) if self.bodies_mode else 1)
        return good

    def _publish_main(self, f: WorldFrame, pose, header, odom: bytes,
                      path: cdr.PathTrail) -> None:
        """The main person's world frame on the single-person topics: the motion always, the
        others only while someone listens (mocap_core.publishing)."""
        pub = self.pub
        pub['motion'].publish(cdr.pose_to_motion(pose, header))
        publish_if_heard(pub['joints3d'],
                         lambda: cdr.positions_to_cloud(pose.joint_positions(), header))
        publish_if_heard(pub['joint_states'], lambda: cdr.pose_to_joint_state(pose, header))
        publish_if_heard(pub['odom'], lambda: odom)
        publish_if_heard(pub['path'], path.message)
        publish_if_heard(pub['markers'], lambda: cdr.pose_to_markers(pose, header, ns='world'))
        publish_if_heard(pub['floor'], lambda: cdr.transform_stamped(
            header, self.input_frame or 'input', f.input_rotation, f.input_translation))

    def _publish_body(self, pid: int, pose, header, odom: bytes, path: cdr.PathTrail) -> None:
        """One person's world frame on their own topics (built only for subscribers)."""
        b = self.bodies
        b.publish(pid, 'motion', lambda: cdr.pose_to_motion(pose, header))
        b.publish(pid, 'joints3d',
                  lambda: cdr.positions_to_cloud(pose.joint_positions(), header))
        b.publish(pid, 'joint_states', lambda: cdr.pose_to_joint_state(pose, header))
        b.publish(pid, 'odom', lambda: odom)
        b.publish(pid, 'path', path.message)

    def _publish_combined(self, released: Sequence[Tuple[Optional[int], Sequence[WorldFrame]]]
                          ) -> None:
        """Combined world messages of the frames several people released at once: one per
        stamp with everybody's frame of it, the main person first (``(None, frames)`` of the
        single-person input are not combined)."""
        for stamp, group in by_stamp([r for r in released if r[0] is not None], self.main_id):
            self.combined.publish(rc.make_header(stamp, self.output_frame),
                                  [(pid, f.pose, None) for pid, f in group])

    def _report_nonfinite(self, count: int) -> None:
        """Diagnostics and a rate-limited warning for frames whose network output was not
        finite (held: :mod:`mocap_global.online`)."""
        if count == self.nonfinite_reported:
            return
        self.nonfinite_reported = count
        self.diag.set_value('nonfinite_outputs', count)
        self.get_logger().warn(f'network output not finite ({count} frames so far): the last '
                               'finite motion was held for those frames',
                               throttle_duration_sec=2.0)


def main(args: Optional[List[str]] = None) -> int:
    if help_requested(sys.argv[1:] if args is None else list(args), __doc__, PARAMETERS):
        return 0
    return spin_node(GMRNode, args, 'gmr')


if __name__ == '__main__':
    sys.exit(main())
