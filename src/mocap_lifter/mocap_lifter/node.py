"""``ros2 run mocap_lifter lifter``: lifting of 2D keypoints to a 3D skeleton with MotioNet
(default) or VTM (``model:=vtm``).

Subscribes ``/mocap/keypoints2d`` (PointCloud2) and ``/mocap/camera_info``; per keypoint
frame publishes, stamped with that frame's stamp and in its camera optical frame:
``/mocap/lifter/motion`` (MultiDOFJointTrajectory), ``/mocap/lifter/joints3d`` (PointCloud2),
``/mocap/lifter/joint_states`` (JointState), ``/mocap/lifter/contacts`` (JointState:
left_heel, left_toe, right_heel, right_toe probabilities), ``/mocap/lifter/markers``
(MarkerArray), ``/mocap/skeleton/urdf`` (String, transient local; re-published when the
skeleton estimate changes by more than ``skeleton_tolerance``) and ``/diagnostics``.
"""

from __future__ import annotations

import functools
import sys
import time
from pathlib import Path
from typing import List, Optional

import numpy as np

from mocap_core.parameters import ParamSpec, declare_parameters, help_requested, spin_node

MODELS = ('motionet', 'vtm')

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
              'the skeleton', min_value=0.0),
    ParamSpec('flush_after_s', 0.3, 'Windowed mode: when no keypoints arrive for this long, '
              'emit the frames still waiting for look-ahead', min_value=0.0),
    ParamSpec('chunk', 1, 'Frames lifted per network pass: 1 for live use; more (offline, '
              'e.g. mocap process) is faster per frame and adds chunk - 1 frames of delay',
              min_value=1, max_value=256, read_only=True),
    ParamSpec('queue_depth', 30, 'Keypoint messages queued while a frame is processed (best '
              'effort: older ones are lost when the queue is full)', min_value=1,
              read_only=True),
    ParamSpec('person', 0, 'Row of the keypoint cloud (person) to track', min_value=0),
    ParamSpec('body_mass', 70.0, 'Body mass for the URDF inertias (kg)', min_value=1.0),
    ParamSpec('horizontal_fov_deg', 60.0, 'Field of view used when no camera_info arrived '
              '(approximate intrinsics from the keypoint extent)', min_value=1.0,
              max_value=179.0),
    ParamSpec('device', 'cpu', "Torch device ('cpu' or 'cuda')", read_only=True),
    ParamSpec('threads', 1, 'Torch CPU threads. 1 is fastest for per-frame inference of this '
              'small network: with 2 threads on a machine where another process is busy, one '
              'frame took 220 ms instead of 5 ms here', min_value=1, read_only=True),
)


def default_weights(mode: str, model: str = 'motionet') -> Path:
    """The shipped weights of a model and mode, from the package share directory (or the
    source tree)."""
    name = f'{model}_{mode}.pt'
    try:
        from ament_index_python.packages import get_package_share_directory
        path = Path(get_package_share_directory('mocap_lifter')) / 'weights' / name
        if path.exists():
            return path
    except Exception:  # noqa: BLE001 - not installed through ament: use the source tree
        pass
    return Path(__file__).resolve().parents[1] / 'weights' / name


def main(args: Optional[List[str]] = None) -> int:
    if help_requested(sys.argv[1:] if args is None else list(args), __doc__, PARAMETERS):
        return 0
    return spin_node(node_class(), args, 'lifter')


@functools.lru_cache(maxsize=None)
def node_class():
    """The node class (``LifterNode``; rclpy is imported here, not at module import, so
    ``--help`` stays fast). Keyword arguments of the constructor go to
    ``rclpy.node.Node`` (``context``, ``parameter_overrides``, ...)."""

    from rclpy.node import Node
    from sensor_msgs.msg import CameraInfo, JointState, PointCloud2
    from std_msgs.msg import String
    from trajectory_msgs.msg import MultiDOFJointTrajectory
    from visualization_msgs.msg import MarkerArray

    from mocap_core import ros_conversions as rc
    from mocap_core.camera import CameraIntrinsics
    from mocap_core.diagnostics import NodeDiagnostics
    from mocap_core.qos import LATCHED_QOS, SENSOR_QOS, STREAM_QOS, input_qos
    from mocap_core.urdf import skeleton_to_urdf

    from .online import OnlineLifter
    from .train import load_weights

    class LifterNode(Node):
        def __init__(self, **kwargs) -> None:
            super().__init__('lifter', **kwargs)
            self.p = declare_parameters(self, PARAMETERS)
            mode, arch = self.p['mode'], self.p['model']
            if mode not in ('causal', 'windowed'):
                raise ValueError(f"mode must be 'causal' or 'windowed', got {mode!r}")
            if arch not in MODELS:
                raise ValueError(f"model must be one of {MODELS}, got {arch!r}")
            if arch == 'vtm' and mode == 'causal':
                raise ValueError('VTM is windowed only (bounded look-ahead, `latency`): use '
                                 'mode:=windowed, or model:=motionet for causal lifting')
            import torch
            torch.set_num_threads(self.p['threads'])
            path = Path(self.p['weights']) if self.p['weights'] else \
                default_weights(mode, arch)
            if not path.exists():
                raise FileNotFoundError(f'weights not found: {path}')
            model = load_weights(path, self.p['device'], causal=(mode == 'causal'))
            loaded = 'vtm' if type(model).__name__ == 'VTM' else 'motionet'
            if loaded != arch:
                raise ValueError(f'{path} holds {loaded} weights but model:={arch}')
            self.lifter = OnlineLifter(
                model, mode, None if self.p['latency'] < 0 else self.p['latency'],
                self.p['skeleton_frames'], self.p['max_gap_s'], self.p['device'],
                chunk=self.p['chunk'])
            self.intrinsics: Optional[CameraIntrinsics] = None
            self.published_lengths: Optional[np.ndarray] = None
            self.last_stamp = -1
            self.pub = {
                'motion': self.create_publisher(MultiDOFJointTrajectory, '/mocap/lifter/motion',
                                                STREAM_QOS),
                'joints3d': self.create_publisher(PointCloud2, '/mocap/lifter/joints3d',
                                                  STREAM_QOS),
                'joint_states': self.create_publisher(JointState, '/mocap/lifter/joint_states',
                                                      STREAM_QOS),
                'contacts': self.create_publisher(JointState, '/mocap/lifter/contacts',
                                                  STREAM_QOS),
                'markers': self.create_publisher(MarkerArray, '/mocap/lifter/markers',
                                                 STREAM_QOS),
                'urdf': self.create_publisher(String, '/mocap/skeleton/urdf', LATCHED_QOS),
            }
            self.diag = NodeDiagnostics(self, 'lifter', hardware_id=str(path.name))
            self.diag.set_value('model', f'{arch} ({mode})')
            self.diag.set_value('latency_frames', self.lifter.latency)
            self.frame_id = 'camera_optical_frame'
            self.last_input = time.monotonic()
            self.create_timer(0.1, self.on_idle)
            self.create_subscription(CameraInfo, '/mocap/camera_info', self.on_info, STREAM_QOS)
            self.create_subscription(PointCloud2, '/mocap/keypoints2d', self.on_keypoints,
                                     input_qos(SENSOR_QOS, self.p['queue_depth']))
            self.get_logger().info(f'lifter ready: {arch} {path} ({mode}, receptive field '
                                   f'{model.cfg.receptive_field()} frames, latency '
                                   f'{self.lifter.latency} frames)')

        def on_info(self, msg: CameraInfo) -> None:
            try:
                self.intrinsics = rc.camera_info_to_intrinsics(msg)
            except rc.MessageError as exc:
                self.diag.errors += 1
                self.get_logger().warn(f'ignoring camera_info: {exc}',
                                       throttle_duration_sec=5.0)

        def on_keypoints(self, msg: PointCloud2) -> None:
            self.diag.input.tick()
            try:
                people = rc.cloud_to_keypoints(msg)
            except rc.MessageError as exc:
                self.diag.errors += 1
                self.get_logger().warn(f'dropping keypoints: {exc}', throttle_duration_sec=2.0)
                return
            stamp = rc.stamp_to_ns(msg.header.stamp)
            if self.last_stamp - stamp > self.p['max_gap_s'] * 1e9:
                # a new stream (a bag played again, a restarted camera driver): the frames of
                # the old one still waiting are emitted, then buffer and skeleton restart
                self.get_logger().warn(
                    f'keypoint stamps jumped back by {(self.last_stamp - stamp) * 1e-9:.1f} s '
                    '(a bag restarted?): starting a new stream')
                self.last_stamp = -1
            if stamp <= self.last_stamp:
                self.diag.dropped += 1
                self.get_logger().warn('keypoint stamp did not advance; frame dropped',
                                       throttle_duration_sec=2.0)
                return
            self.last_stamp = stamp
            person = self.p['person']
            if person >= len(people) or not np.any(people[person, :, 2] > 0):
                # A frame without the person still goes through the network (trained with
                # dropped frames: the pose is carried by the temporal context), unless nothing
                # has been seen yet.
                self.get_logger().info('nobody seen in this frame', throttle_duration_sec=2.0)
                if self.lifter.frames_seen == 0:
                    self.diag.dropped += 1
                    return
                people = np.zeros((person + 1, people.shape[1], 3))
            intr = self.intrinsics
            if intr is None:
                intr = self._approximate_intrinsics(people[person])
            try:
                with self.diag.processing():
                    frames, event = self.lifter.push(stamp, people[person], intr)
            except ValueError as exc:  # e.g. a non-finite network output
                self.diag.errors += 1
                self.get_logger().error(f'frame dropped: {exc}', throttle_duration_sec=2.0)
                return
            if event:
                self.get_logger().info(f'buffer and skeleton reset ({event})')
            self.frame_id = msg.header.frame_id
            self.last_input = time.monotonic()
            for frame in frames:
                self.publish(frame)

        def on_idle(self) -> None:
            """In windowed mode, frames wait for look-ahead: when the input pauses, emit them
            with the future frames that exist (end of a bag, a stalled camera)."""
            idle = time.monotonic() - self.last_input
            if self.lifter.pending() and idle > self.p['flush_after_s']:
                for frame in self.lifter.flush():
                    self.publish(frame)

        def flush(self) -> None:
            """End of the input (offline processing): emit every frame still waiting for
            look-ahead, with the future frames that exist."""
            for frame in self.lifter.flush():
                self.publish(frame)

        def _approximate_intrinsics(self, kp: np.ndarray) -> CameraIntrinsics:
            seen = kp[:, 2] > 0
            w = int(max(640, np.ceil(kp[seen, 0].max() * 1.1)))
            h = int(max(480, np.ceil(kp[seen, 1].max() * 1.1)))
            self.diag.warn('no camera_info: approximate intrinsics')
            self.get_logger().warn(f'no camera_info yet: approximating a {w}x{h} camera with '
                                   f"{self.p['horizontal_fov_deg']:.0f} deg field of view",
                                   throttle_duration_sec=10.0)
            return CameraIntrinsics.from_fov(w, h, self.p['horizontal_fov_deg'])

        def publish(self, frame) -> None:
            pose = frame.pose
            if not (np.all(np.isfinite(pose.rotations)) and np.all(np.isfinite(
                    pose.root_position)) and np.all(np.isfinite(frame.contacts))):
                self.diag.errors += 1
                self.get_logger().error('network output not finite; frame dropped')
                return
            header = rc.make_header(frame.stamp_ns, self.frame_id)
            lengths = pose.skeleton.group_lengths()
            if (self.published_lengths is None or np.max(np.abs(
                    lengths - self.published_lengths)) > self.p['skeleton_tolerance']):
                self.pub['urdf'].publish(rc.urdf_to_msg(
                    skeleton_to_urdf(pose.skeleton, self.p['body_mass'])))
                self.published_lengths = lengths
            self.pub['motion'].publish(rc.pose_to_motion(pose, header))
            self.pub['joints3d'].publish(rc.positions_to_cloud(pose.joint_positions(), header))
            self.pub['joint_states'].publish(rc.pose_to_joint_state(pose, header))
            self.pub['contacts'].publish(rc.contacts_to_msg(frame.contacts, header))
            self.pub['markers'].publish(rc.pose_to_markers(pose, header, ns='lifter',
                                                           contacts=frame.contacts))
            self.diag.output.tick()
            self.diag.set_value('skeleton', 'held' if frame.skeleton_fixed else 'estimating')
            self.diag.set_value('root_depth_m', f'{frame.depth:.2f}')

    return LifterNode


if __name__ == '__main__':
    sys.exit(main())
