"""``ros2 run mocap_lifter lifter``: lifting of 2D keypoints to a 3D skeleton with MotioNet
(default) or VTM (``model:=vtm``).

Subscribes ``/mocap/keypoints2d`` (PointCloud2: one row per person, fields u, v, confidence)
and ``/mocap/camera_info``; per keypoint frame publishes, stamped with that frame's stamp and
in its camera optical frame: ``/mocap/lifter/motion`` (MultiDOFJointTrajectory),
``/mocap/lifter/joints3d`` (PointCloud2), ``/mocap/lifter/joint_states`` (JointState),
``/mocap/lifter/contacts`` (JointState: left_heel, left_toe, right_heel, right_toe
probabilities), ``/mocap/lifter/markers`` (MarkerArray), ``/mocap/skeleton/urdf`` (String,
transient local; re-published when the skeleton estimate changes by more than
``skeleton_tolerance``) and ``/diagnostics``.

With a known camera pose (``camera_pose_topic``, nav_msgs/Odometry or geometry_msgs/PoseStamped
of the camera in a world frame whose floor is ``z = camera_pose_floor_z``) each person is
scaled, bones and root along the camera rays, so that their stance toes stand on that floor
(:mod:`mocap_lifter.known_floor`; ``size_from_camera_pose``, on when a pose topic is given);
the diagnostics value ``body_size`` says where the main person's size comes from.

Several people (docs/multi_person.md): the cloud's rows are persons with an ``id`` field (a
cloud without it: persons 1, 2, ... in row order). Each id gets its own lifting state
(:class:`mocap_lifter.online.PeopleStreams`), ended ``person_timeout_s`` after the person was
last seen. Each person's frames go to ``/humans/bodies/body_<id>/lifter/{motion,joints3d,
joint_states,contacts}`` and ``/humans/bodies/body_<id>/urdf``; every person of a frame to
``/mocap/lifter/bodies/{motion,contacts,joints3d,markers}`` (names prefixed ``body_<id>/``, the
main person first); the single-person topics above carry the person of row ``person`` (row 0:
the one tracked longest). ``/mocap/lifter/bodies/bone_lengths`` (JointState, transient local)
holds every person's held skeleton (names ``body_<id>/<bone group>``), re-published when one
changes: the keypoint node's tracker gives a person who comes back their old id by it.
Every output but the motion and ``/diagnostics`` is built only while it has a subscriber.

Without a calibrated ``/mocap/camera_info`` the keypoints are lifted with approximate
intrinsics fixed once per stream (:mod:`mocap_lifter.intrinsics`: the image size of an
uncalibrated camera_info, else an estimate from the keypoints of the first frames); the
diagnostics value ``intrinsics`` says which are in use. Frames where the tracked person is
missing go through the network once the person was seen
(:class:`mocap_lifter.online.LifterStream`).
A callback that raises drops its frame (:func:`mocap_core.guard.guarded`); weights that are
missing, damaged or more than plain tensors end the start with one line
``lifter: error: ...`` and exit status 2.
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import numpy as np
import torch
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, JointState, PointCloud2
from std_msgs.msg import String
from trajectory_msgs.msg import MultiDOFJointTrajectory
from visualization_msgs.msg import MarkerArray

from mocap_core import ros_conversions as rc
from mocap_core import topics
from mocap_core.diagnostics import NodeDiagnostics
from mocap_core.bodies import BodyPublishers, CombinedPublishers, by_stamp
from mocap_core import cdr
from mocap_core.publishing import publish_if_heard
from mocap_core.guard import guarded
from mocap_core.camera_pose import KnownCameraPoses, known_camera_poses
from mocap_core.parameters import (ParamSpec, camera_pose_params, declare_parameters,
                                  help_requested, spin_node)
from mocap_core.qos import LATCHED_QOS, SENSOR_QOS, STREAM_QOS, input_qos
from mocap_core.urdf import skeleton_to_urdf

from .intrinsics import StreamIntrinsics
from .known_floor import SizeFromKnownFloor, scale_pose
from .online import (DEFAULT_HOLD_UNSEEN_S, DEFAULT_VIRTUAL_CAMERA, LiftedFrame,
                     OnlineLifter, PeopleStep, PeopleStreams)
from .output_smoothing import DEFAULT_OUTPUT_ROOT_SIGMA, DEFAULT_OUTPUT_SIGMA
from .weights import MODELS, architecture, default_weights, load_weights

PARAMETERS = (
    ParamSpec('model', 'motionet', "Lifter network: 'motionet' (MotioNet, windowed or causal) "
              "or 'vtm' (VTM, keypoints only; windowed only, window 32 frames)",
              read_only=True),
    ParamSpec('mode', 'windowed', "'windowed' (centred window: delay of `latency` frames) or "
              "'causal' (only past frames; needs causal weights)", read_only=True),
    ParamSpec('weights', '', 'Weights file; empty = the shipped weights of the model and '
              'mode (share/mocap_lifter/weights/<model>_<mode>.pt)', read_only=True),
    ParamSpec('latency', -1, 'Look-ahead frames in windowed mode (-1 = half the receptive '
              'field: 14 frames for MotioNet, 16 for VTM)', read_only=True),
    ParamSpec('skeleton_frames', 90, 'Frames used to estimate the skeleton before it is '
              'held for the person', min_value=1),
    ParamSpec('skeleton_tolerance', 0.01, 'Re-publish the URDF when a bone changes by more '
              'than this (m)', min_value=0.0),
    ParamSpec('max_gap_s', 1.0, 'A larger gap between keypoint stamps resets the buffer and '
              'the skeleton; stamps jumping back by as much start a new stream',
              min_value=0.0),
    ParamSpec('flush_after_s', 0.3, 'Windowed mode: when no keypoints arrive for this long, '
              'emit the frames still waiting for look-ahead', min_value=0.0),
    ParamSpec('chunk', 1, 'Frames lifted per network pass: 1 for live use; more (offline, '
              'e.g. mocap process) is faster per frame and adds chunk - 1 frames of delay',
              min_value=1, max_value=256, read_only=True),
    ParamSpec('test_time_flip', True, 'MotioNet: also lift the mirrored keypoints and '
              'average the mirrored-back pose in (test-time flip augmentation, one pass of '
              'two rows; validation MPJPE 42.8 -> 39.9 mm, docs/lifter.md; false: the plain '
              'network)', read_only=True),
    ParamSpec('smooth_sigma', 0.0, 'Gaussian smoothing of the keypoints along time before '
              'lifting, sigma in frames (0: off; 3 cuts the jitter on real detections 2.7x for '
              '1.6 mm of validation MPJPE, docs/lifter.md); the frames beyond the look-ahead '
              'are not yet there, so with chunk > 1 the output differs from frame-by-frame '
              'lifting (by up to ~1 cm); one-sided (a lag) in causal mode', min_value=0.0,
              max_value=10.0, read_only=True),
    ParamSpec('output_sigma', -1.0, 'Gaussian smoothing of the lifted joint rotations along '
              'time, sigma in frames, delaying the output by ceil(2 sigma) frames (-1: 1.5 '
              'frames in windowed mode, off in causal mode; 0: off). More flattens a walk\'s '
              'knee and hip swings (docs/lifter.md, "Output smoothing"); frame by frame and in '
              'chunks the output is the same', min_value=-1.0, max_value=10.0, read_only=True),
    ParamSpec('output_root_sigma', -1.0, 'Gaussian smoothing of the lifted root position '
              'along time, sigma in frames (-1: 3 frames in windowed mode, off in causal '
              'mode; 0: off). Most of the output\'s jitter on real detections is the root\'s '
              'depth; the output is delayed by ceil(2 sigma) frames of the larger sigma',
              min_value=-1.0, max_value=10.0, read_only=True),
    ParamSpec('subject_height', 0.0, 'The person\'s stature in metres (floor to the top of '
              'the head), when it is known: the skeleton is scaled to it and the root moved '
              'along its camera ray by the same factor (0: estimated from the keypoints; on '
              'rendered video a known stature takes the median MPJPE from 75 to 64 mm, '
              'docs/lifter.md). One value for every person in the picture', min_value=0.0,
              max_value=3.0, read_only=True),
    ParamSpec('virtual_camera', DEFAULT_VIRTUAL_CAMERA, 'MotioNet: lift the keypoints as a '
              'camera turned to look at the person would see them, then turn the pose back: '
              'a person away from the image centre is seen along an oblique ray, which the '
              'network\'s root-relative input does not show (rendered videos: MPJPE 72.2 -> '
              '69.4 mm, travelling people 77.0 -> 69.7; docs/lifter.md, "The person\'s '
              'ray"). Weights trained in the virtual camera use it whatever this says; VTM '
              'ignores it',
              read_only=True),
    ParamSpec('network_rate_hz', 30.0, 'The frame rate the network reads its input at (the '
              'shipped weights: 30): keypoint frames missing from the stream (dropped by a '
              'busy keypoint node, a slower camera) are filled in by interpolation before '
              'lifting, frames coming faster (a 60 frames/s camera) are thinned and their '
              'outputs interpolated; every frame received is published, once. With 55 % of '
              'the frames dropped, PA-MPJPE 49.9 -> 41.7 mm on 20 ground-truth bags (all '
              'frames: 38.1; people gesturing on the spot lose 2-6 mm; docs/lifter.md). 0: '
              'off, every frame is given to the network as the next one',
              min_value=0.0, max_value=240.0, read_only=True),
    ParamSpec('queue_depth', 30, 'Keypoint messages queued while a frame is processed (best '
              'effort: older ones are lost when the queue is full)', min_value=1,
              read_only=True),
    ParamSpec('person', 0, 'Row of the keypoint cloud whose person the single-person '
              'topics (/mocap/lifter/...) carry (row 0: the person tracked longest)',
              min_value=0),
    ParamSpec('max_persons', 8, 'Most persons lifted at once (one network state each); '
              'further ids are ignored and counted', min_value=1, max_value=64,
              read_only=True),
    ParamSpec('person_timeout_s', 1.0, 'A person absent from the keypoints for longer than '
              'this (message stamps) is dropped: their last frames are emitted and their '
              'per-person topics removed', min_value=0.0, read_only=True),
    ParamSpec('hold_unseen_s', DEFAULT_HOLD_UNSEEN_S, 'A keypoint unseen (confidence 0) '
              'while its person is seen, whose last sighting lies in another person\'s box '
              '(hidden behind them), takes its last seen position and confidence if seen at '
              'most this long ago, s; 0 = off (zeros to the network, as for a keypoint the '
              'detector dropped with nobody in front of it). Three people on the synthetic '
              'crossing scenes: +7.7 -> +2.9 mm MPJPE over alone (docs/multi_person.md)',
              min_value=0.0, max_value=10.0, read_only=True),
    ParamSpec('body_mass', 70.0, 'Body mass for the URDF inertias (kg)', min_value=1.0),
    ParamSpec('horizontal_fov_deg', 60.0, 'Field of view of the approximate intrinsics used '
              'without a calibrated camera_info (image size from an uncalibrated camera_info, '
              'else estimated from the keypoints of the first frames, then fixed)',
              min_value=1.0, max_value=179.0),
    ParamSpec('device', 'cpu', "Torch device ('cpu' or 'cuda')", read_only=True),
    ParamSpec('threads', 1, 'Torch CPU threads (1 is fastest for per-frame inference of this '
              'small network, see docs/lifter.md)', min_value=1, read_only=True),
) + camera_pose_params(
    'each person\'s size is then measured from their stance feet on the floor of that frame '
    '(size_from_camera_pose)', 'it gives no size sample') + (
    ParamSpec('size_from_camera_pose', True, 'With a known camera pose (camera_pose_topic): '
              'scale each person (bones and root, along the camera rays) so that their stance '
              'feet stand on the floor z = camera_pose_floor_z of the pose\'s frame, the median '
              'over the last 20 s of stance points (docs/lifter.md, "The size from a known '
              'floor"); a given subject_height wins', read_only=True),
    ParamSpec('camera_pose_floor_z', 0.0, 'The floor\'s height in the camera pose\'s world '
              'frame (z up), m: 0 for the odom or map frame of a ground robot',
              read_only=True),
    ParamSpec('size_rate', 0.1, 'size_from_camera_pose: the size applied follows the '
              'estimate at most this fraction of itself per second, from the network\'s own '
              'size (0: at once, a jump of the whole body along the camera rays)',
              min_value=0.0, max_value=10.0, read_only=True),
)


class LifterNode(Node):
    """The ``lifter`` node (module docstring). Keyword arguments go to ``rclpy.node.Node``
    (``context``, ``parameter_overrides``, ...).

    Raises (at construction): FileNotFoundError for missing weights, ValueError (also
    :class:`~mocap_core.checkpoint.WeightsError`) for unusable weights or a bad parameter.
    """

    def __init__(self, **kwargs) -> None:
        super().__init__('lifter', **kwargs)
        self.p = p = declare_parameters(self, PARAMETERS)
        mode, arch = p['mode'], p['model']
        if mode not in ('causal', 'windowed'):
            raise ValueError(f"mode must be 'causal' or 'windowed', got {mode!r}")
        if arch not in MODELS:
            raise ValueError(f'model must be one of {MODELS}, got {arch!r}')
        if arch == 'vtm' and mode == 'causal':
            raise ValueError('VTM is windowed only (bounded look-ahead, `latency`): use '
                             'mode:=windowed, or model:=motionet for causal lifting')
        torch.set_num_threads(p['threads'])
        path = Path(p['weights']) if p['weights'] else default_weights(mode, arch)
        if not path.exists():
            raise FileNotFoundError(f'weights not found: {path}')
        model = load_weights(path, p['device'], causal=(mode == 'causal'))
        if architecture(model) != arch:
            raise ValueError(f'{path} holds {architecture(model)} weights but model:={arch}')
        output_sigma = p['output_sigma'] if p['output_sigma'] >= 0 else (
            DEFAULT_OUTPUT_SIGMA if mode == 'windowed' else 0.0)
        root_sigma = p['output_root_sigma'] if p['output_root_sigma'] >= 0 else (
            DEFAULT_OUTPUT_ROOT_SIGMA if mode == 'windowed' else 0.0)

        def make_lifter() -> OnlineLifter:
            return OnlineLifter(model, mode, None if p['latency'] < 0 else p['latency'],
                                p['skeleton_frames'], p['max_gap_s'], p['device'],
                                chunk=p['chunk'], flip=p['test_time_flip'],
                                smooth=p['smooth_sigma'], output_sigma=output_sigma,
                                output_root_sigma=root_sigma,
                                subject_height=p['subject_height'],
                                network_rate_hz=p['network_rate_hz'],
                                virtual_camera=p['virtual_camera'] and arch == 'motionet')

        lifter = make_lifter()
        self.people = PeopleStreams(make_lifter, StreamIntrinsics(p['horizontal_fov_deg']),
                                    p['person'], p['max_gap_s'], p['person_timeout_s'],
                                    p['max_persons'], p['hold_unseen_s'])
        self.bodies = BodyPublishers(self, 'lifter', with_urdf=True)
        self.published_lengths: Optional[np.ndarray] = None
        self.body_lengths: Dict[int, np.ndarray] = {}
        #: each person's held skeleton (bone-group lengths, m) as last published on
        #: BODIES_BONE_LENGTHS, and whether that table changed since
        self.signatures: Dict[int, np.ndarray] = {}
        self.signatures_changed = False
        self.main_id: Optional[int] = None
        self.main_last_ns = -1
        self.main_unsmoothed_ns = -1
        self.intrinsics_said = ''
        self.pub = {
            'motion': self.create_publisher(MultiDOFJointTrajectory, topics.LIFTER_MOTION,
                                            STREAM_QOS),
            'joints3d': self.create_publisher(PointCloud2, topics.LIFTER_JOINTS3D, STREAM_QOS),
            'joint_states': self.create_publisher(JointState, topics.LIFTER_JOINT_STATES,
                                                  STREAM_QOS),
            'contacts': self.create_publisher(JointState, topics.LIFTER_CONTACTS, STREAM_QOS),
            'markers': self.create_publisher(MarkerArray, topics.LIFTER_MARKERS, STREAM_QOS),
            # the frames before the output smoothing (the world stage's network reads them)
            'unsmoothed_motion': self.create_publisher(
                MultiDOFJointTrajectory, topics.LIFTER_UNSMOOTHED_MOTION, STREAM_QOS),
            'bodies_unsmoothed_motion': self.create_publisher(
                MultiDOFJointTrajectory, topics.bodies_topic('lifter', 'unsmoothed_motion'),
                STREAM_QOS),
            'urdf': self.create_publisher(String, topics.SKELETON_URDF, LATCHED_QOS),
            'bone_lengths': self.create_publisher(JointState, topics.BODIES_BONE_LENGTHS,
                                                  LATCHED_QOS),
        }
        self.combined = CombinedPublishers(self, 'lifter', with_contacts=True)
        self.diag = NodeDiagnostics(self, 'lifter', hardware_id=str(path.name))
        self.diag.set_value('model', f'{arch} ({mode})')
        self.diag.set_value('latency_frames', lifter.delay)
        self.diag.set_value('output_smoothing',
                            f'sigma {output_sigma:g} frames (rotations), {root_sigma:g} (root)'
                            if max(output_sigma, root_sigma) > 0 else 'off')
        # the main person's size; with their stature once a skeleton is published
        self.diag.set_value('body_size', f"given: stature {p['subject_height']:.2f} m"
                            if p['subject_height'] > 0 else 'estimated from the keypoints')
        # frame by frame through the streaming encoder where exact (default look-ahead, no
        # smoothing, chunk 1), otherwise a network pass over the context window per frame
        self.diag.set_value('inference', 'streaming (one new column per layer and frame)'
                            if lifter.streaming else f'window pass ({lifter.context} frames)')
        self._report_intrinsics()
        self.frame_id = 'camera_optical_frame'
        self.last_input = time.monotonic()
        #: the known camera pose and each person's size from it (size_from_camera_pose)
        self.known_poses: Optional[KnownCameraPoses] = None
        self.sizers: Dict[int, SizeFromKnownFloor] = {}
        #: person -> stamp -> the skeleton height applied to that stamp (None: none yet), so
        #: that a stamp's unsmoothed and smoothed frames take the same size
        self.size_at: Dict[int, Dict[int, Optional[float]]] = {}
        self.camera_pose_missing = 0
        if p['camera_pose_topic'] and p['size_from_camera_pose']:
            poses = known_camera_poses(p)
            if p['subject_height'] > 0:
                self.get_logger().info('subject_height given: the size is not measured from '
                                       'the camera pose')
            else:
                self.known_poses = poses
                self.diag.set_value('body_size', 'from the known floor: no stance yet')
                self.diag.watch('camera_pose', self.create_subscription(
                    rc.camera_pose_message_type(p['camera_pose_type']),
                    p['camera_pose_topic'], guarded(self, self.on_camera_pose, 'camera pose'),
                    STREAM_QOS))
        self.create_timer(0.1, guarded(self, self.on_idle, 'idle flush'))
        self.create_subscription(CameraInfo, topics.CAMERA_INFO,
                                 guarded(self, self.on_info, 'camera_info'), STREAM_QOS)
        sub = self.create_subscription(PointCloud2, topics.KEYPOINTS,
                                       guarded(self, self.on_keypoints, 'keypoints'),
                                       input_qos(SENSOR_QOS, p['queue_depth']))
        self.diag.watch('keypoints', sub)
        self.diag.watch('motion', self.pub['motion'])
        self.diag.watch('contacts', self.pub['contacts'])
        self.get_logger().info(f'lifter ready: {arch} {path} ({mode}, receptive field '
                               f'{model.cfg.receptive_field()} frames, latency '
                               f'{lifter.delay} frames)')

    def on_info(self, msg: CameraInfo) -> None:
        try:
            self.people.intrinsics.set_camera_info(rc.camera_info_to_intrinsics(msg))
        except rc.MessageError as exc:
            if msg.width > 0 and msg.height > 0 and not any(msg.k):
                # an uncalibrated camera (K all zero): its image size is still good
                self.people.intrinsics.set_image_size(int(msg.width), int(msg.height))
            else:
                self.diag.errors += 1
                self.get_logger().warn(f'ignoring camera_info: {exc}',
                                       throttle_duration_sec=5.0)
        self._report_intrinsics()

    def on_camera_pose(self, msg) -> None:
        """Keep the camera's known pose (camera_pose_topic)."""
        if self.known_poses.add(*rc.camera_pose_from_msg(msg)) == 'invalid':
            self.diag.errors += 1
            self.get_logger().warn('ignoring camera pose: not finite',
                                   throttle_duration_sec=5.0)

    def _sized(self, pid: int, frame: LiftedFrame) -> LiftedFrame:
        """``frame`` at the size its person's stance feet on the known floor give
        (:mod:`mocap_lifter.known_floor`); unchanged without a known camera pose. A stamp's
        first frame (the unsmoothed one) is measured; later frames of the stamp take its
        size."""
        if self.known_poses is None:
            return frame
        sizer = self.sizers.get(pid)
        if sizer is None:
            sizer = self.sizers[pid] = SizeFromKnownFloor(self.p['camera_pose_floor_z'],
                                                          rate=self.p['size_rate'])
        memo = self.size_at.setdefault(pid, {})
        stamp = int(frame.stamp_ns)
        if stamp in memo:
            height = memo[stamp]
        else:
            camera = self.known_poses.at(stamp)
            if camera is None:
                self.camera_pose_missing += 1
                self.get_logger().warn('no camera pose near a lifted frame: no size sample',
                                       throttle_duration_sec=5.0)
            sizer.observe(stamp, frame.pose, frame.contacts, camera)
            height = memo[stamp] = sizer.applied_height
            while len(memo) > 512:
                del memo[next(iter(memo))]
        if height is None:
            return frame
        factor = height / frame.pose.skeleton.height()
        return replace(frame, pose=scale_pose(frame.pose, factor), depth=frame.depth * factor)

    def on_keypoints(self, msg: PointCloud2) -> None:
        self.diag.input.tick()
        try:
            people = rc.cloud_to_keypoints(msg)
            ids = rc.cloud_to_ids(msg)
        except rc.MessageError as exc:
            self.diag.errors += 1
            self.get_logger().warn(f'dropping keypoints: {exc}', throttle_duration_sec=2.0)
            return
        self.people.person = int(self.p['person'])
        with self.diag.processing():
            step = self.people.push(rc.stamp_to_ns(msg.header.stamp), people, ids)
        if step.restarted > 0:
            self.get_logger().warn(f'keypoint stamps jumped back by {step.restarted:.1f} s (a '
                                   'bag restarted?): starting a new stream')
            self._emit(PeopleStep(steps=step.flushed, ended=step.ended))
            step.ended = []
            self.main_last_ns = -1
        if step.main is not None:
            self.main_id = step.main
        if not step.steps:
            self.get_logger().info('nobody seen yet', throttle_duration_sec=2.0)
        used = False
        for pid, st in step.steps.items():
            if st.jumped_back_s > 0:
                self.get_logger().warn(f'keypoint stamps jumped back by {st.jumped_back_s:.1f}'
                                       ' s (a bag restarted?): starting a new stream')
            if st.dropped and not st.nobody:
                self.diag.dropped += 1
                self.get_logger().warn(f'frame of person {pid} dropped: {st.dropped}',
                                       throttle_duration_sec=2.0)
            used = used or not st.dropped
        if used:
            self.frame_id = msg.header.frame_id
            self.last_input = time.monotonic()
        self._emit(step)

    def on_idle(self) -> None:
        """When the input pauses (end of a bag, a stalled camera), emit the frames still
        waiting for look-ahead or for the intrinsics, with the frames that exist."""
        idle = time.monotonic() - self.last_input
        if self.people.pending() and idle > self.p['flush_after_s']:
            self._emit(self.people.flush())

    def flush(self) -> None:
        """End of the input (offline processing): emit every frame still waiting."""
        self._emit(self.people.flush())

    def _emit(self, step: PeopleStep) -> None:
        """Log what a step did and publish its frames: each person's on their own topics,
        the main person's on the single-person topics, all of a stamp in one combined
        message."""
        released: List[Tuple[int, List[LiftedFrame]]] = []
        for pid, st in step.steps.items():
            for reason in st.resets:
                self.get_logger().info(f'person {pid}: buffer and skeleton reset ({reason})')
            for error in st.errors:
                self.diag.errors += 1
                self.get_logger().error(f'frame dropped: {error}', throttle_duration_sec=2.0)
            released.append((pid, [f for f in st.frames if self._finite(f)]))
        self._report_intrinsics()
        # the unsmoothed frames first: a stamp's first frame is the one measured for its size
        unsmoothed = [(pid, [self._sized(pid, f) for f in st.unsmoothed
                             if self._finite(f, quiet=True)])
                      for pid, st in step.steps.items()]
        released = [(pid, [self._sized(pid, f) for f in frames]) for pid, frames in released]
        self.publish_unsmoothed(unsmoothed)
        for stamp, frames in by_stamp(released, self.main_id):   # the main person first
            # combined first: the next stage, which follows everybody from the combined
            # motion, hears it before the single-person topics
            self.publish_combined(stamp, frames)
            for pid, frame in frames:
                self.publish_body(pid, frame)
                if pid == self.main_id and stamp > self.main_last_ns:
                    self.main_last_ns = stamp
                    self.publish(frame)
        for pid in step.ended:
            self.bodies.remove(pid)
            self.sizers.pop(pid, None)
            self.size_at.pop(pid, None)
            self.body_lengths.pop(pid, None)
            self.signatures_changed |= self.signatures.pop(pid, None) is not None
            self.get_logger().info(f'person {pid} gone: their topics are removed')
        stamps = [int(f.stamp_ns) for _, frames in released for f in frames]
        if self.signatures_changed and stamps:
            self.signatures_changed = False
            self.pub['bone_lengths'].publish(cdr.bodies_bone_lengths_to_msg(
                sorted(self.signatures.items()), rc.make_header(max(stamps), self.frame_id)))
        self.diag.set_value('persons', len(self.people.streams))
        self.diag.set_value('person_ids', ' '.join(map(str, sorted(self.people.streams)))
                            or 'none')
        self.diag.set_value('persons_ignored', self.people.ignored)
        if self.people.hold_unseen_s > 0:
            self.diag.set_value('held_unseen_keypoints', self.people.held_ended + sum(
                s.held_keypoints for s in self.people.streams.values()))
        filled, thinned = self.people.rate_counts()
        self.diag.set_value('filled_frames', filled)
        self.diag.set_value('thinned_frames', thinned)

    def _finite(self, frame: LiftedFrame, quiet: bool = False) -> bool:
        """Whether the frame is finite; if not it is counted and logged (``quiet``: only
        dropped, for a frame that also comes out smoothed and is counted then)."""
        pose = frame.pose
        if np.all(np.isfinite(pose.rotations)) and np.all(np.isfinite(pose.root_position)) \
                and np.all(np.isfinite(frame.contacts)):
            return True
        if quiet:
            return False
        self.diag.errors += 1
        self.get_logger().error('network output not finite; frame dropped',
                                throttle_duration_sec=2.0)
        return False

    def publish_body(self, pid: int, frame: LiftedFrame) -> None:
        """One person's frame on their own topics (built only for topics with
        subscribers; the URDF whenever their skeleton changes)."""
        header = rc.make_header(frame.stamp_ns, self.frame_id)
        pose = frame.pose
        lengths = pose.skeleton.group_lengths()
        old = self.body_lengths.get(pid)
        if old is None or np.max(np.abs(lengths - old)) > self.p['skeleton_tolerance']:
            self.body_lengths[pid] = lengths
            self.bodies.urdf(pid, lambda: rc.urdf_to_msg(
                skeleton_to_urdf(pose.skeleton, self.p['body_mass'])))
        held = self.signatures.get(pid)
        if frame.skeleton_fixed and (held is None or np.max(np.abs(lengths - held)) >
                                     self.p['skeleton_tolerance']):
            # the person's signature for the keypoint node's tracker (topics.py)
            self.signatures[pid] = lengths
            self.signatures_changed = True
        self.bodies.publish(pid, 'motion', lambda: cdr.pose_to_motion(pose, header))
        self.bodies.publish(pid, 'joints3d',
                            lambda: cdr.positions_to_cloud(pose.joint_positions(), header))
        self.bodies.publish(pid, 'joint_states', lambda: cdr.pose_to_joint_state(pose, header))
        self.bodies.publish(pid, 'contacts', lambda: cdr.contacts_to_msg(frame.contacts, header))

    def publish_unsmoothed(self, released: List[Tuple[int, List[LiftedFrame]]]) -> None:
        """The network's frames before the output smoothing, while someone listens: every
        person's of a stamp in one message, and the main person's alone."""
        combined, single = self.pub['bodies_unsmoothed_motion'], self.pub['unsmoothed_motion']
        to_combined = combined.get_subscription_count() > 0
        to_single = single.get_subscription_count() > 0
        if not (to_combined or to_single):
            return
        for stamp, frames in by_stamp(released, self.main_id):
            header = rc.make_header(stamp, self.frame_id)
            if to_combined:
                combined.publish(cdr.bodies_to_motion([(pid, f.pose) for pid, f in frames],
                                                      header))
            main = [f for pid, f in frames if pid == self.main_id]
            if main and stamp > self.main_unsmoothed_ns:
                self.main_unsmoothed_ns = stamp
                if to_single:
                    single.publish(cdr.pose_to_motion(main[0].pose, header))

    def publish_combined(self, stamp: int, frames: List[Tuple[int, LiftedFrame]]) -> None:
        """All persons of one stamp (main person first): the lossless motion and contacts
        (the physics stage's input), a joints cloud with an id field and the markers, one
        namespace and colour per person."""
        self.combined.publish(rc.make_header(stamp, self.frame_id),
                              [(pid, f.pose, f.contacts) for pid, f in frames])

    def _report_intrinsics(self) -> None:
        """Diagnostics (and one log line per change) of the intrinsics in use."""
        intr = self.people.intrinsics
        text = intr.describe()
        self.diag.set_value('intrinsics', text)
        self.diag.warn(None if intr.source == 'camera_info' else
                       'no camera_info: approximate intrinsics')
        if text != self.intrinsics_said and intr.current is not None:
            self.intrinsics_said = text
            if intr.source == 'camera_info':
                self.get_logger().info('intrinsics from camera_info')
            else:
                self.get_logger().warn(f'no camera_info: using {text}')

    def publish(self, frame: LiftedFrame) -> None:
        """The main person's frame on the single-person topics."""
        pose = frame.pose
        header = rc.make_header(frame.stamp_ns, self.frame_id)
        lengths = pose.skeleton.group_lengths()
        if (self.published_lengths is None or np.max(np.abs(
                lengths - self.published_lengths)) > self.p['skeleton_tolerance']):
            self.pub['urdf'].publish(rc.urdf_to_msg(
                skeleton_to_urdf(pose.skeleton, self.p['body_mass'])))
            self.published_lengths = lengths
            self.diag.set_value('body_size', f'{self._size_source()}: stature '
                                f'{pose.skeleton.stature():.2f} m')
        self.pub['motion'].publish(cdr.pose_to_motion(pose, header))
        # the others only while someone listens (mocap_core.publishing)
        publish_if_heard(self.pub['joints3d'],
                         lambda: cdr.positions_to_cloud(pose.joint_positions(), header))
        publish_if_heard(self.pub['joint_states'], lambda: cdr.pose_to_joint_state(pose, header))
        publish_if_heard(self.pub['contacts'], lambda: cdr.contacts_to_msg(frame.contacts, header))
        publish_if_heard(self.pub['markers'], lambda: cdr.pose_to_markers(
            pose, header, ns='lifter', contacts=frame.contacts))
        self.diag.output.tick()
        self.diag.set_value('skeleton', 'held' if frame.skeleton_fixed else 'estimating')
        self.diag.set_value('root_depth_m', f'{frame.depth:.2f}')
        if self.known_poses is not None:
            self.diag.set_value('camera_pose_missing', self.camera_pose_missing)

    def _size_source(self) -> str:
        """Where the main person's size comes from, for the diagnostics."""
        if self.p['subject_height'] > 0:
            return 'given'
        sizer = self.sizers.get(self.main_id) if self.known_poses is not None else None
        if sizer is None:
            return 'estimated from the keypoints'
        if sizer.applied_height is None:
            return (f'estimated from the keypoints (known floor: {sizer.samples} of '
                    f'{sizer.min_samples} stance samples)')
        return f'from the known floor ({sizer.samples} stance samples)'


def main(args: Optional[List[str]] = None) -> int:
    if help_requested(sys.argv[1:] if args is None else list(args), __doc__, PARAMETERS):
        return 0
    return spin_node(LifterNode, args, 'lifter')


if __name__ == '__main__':
    sys.exit(main())
