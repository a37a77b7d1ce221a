"""``ros2 run mocap_keypoints keypoints``: publishes 2D keypoints and camera info per frame.

Topics (DESIGN §2):
  * ``/mocap/keypoints2d`` (sensor_msgs/PointCloud2, sensor-data QoS): height = persons,
    width = 23 keypoints, float32 ``u, v, confidence``; all confidences 0 when nobody was found.
  * ``/mocap/camera_info`` (sensor_msgs/CameraInfo): the intrinsics the keypoints belong to.
  * ``/diagnostics``.

Sources (parameter ``source``): ``openpose_json`` — a directory of OpenPose JSON files played
at ``fps``. (Camera, video, image directory and image-topic sources come with the detector.)
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import List, Optional, Tuple

import numpy as np

from mocap_core.camera import CameraIntrinsics
from mocap_core.parameters import ParamSpec, declare_parameters, describe_parameters
from mocap_core.skeleton import NUM_KEYPOINTS

from .openpose import OpenPoseError, keypoint_extent, list_openpose_files, read_openpose_file

SOURCES = ('openpose_json',)

PARAMETERS = (
    ParamSpec('source', 'openpose_json', f'Input kind, one of: {", ".join(SOURCES)}',
              read_only=True),
    ParamSpec('path', '', 'Directory of OpenPose JSON files (source openpose_json)',
              read_only=True),
    ParamSpec('fps', 30.0, 'Frame rate for file sources (frames per second); stamps advance '
              'by 1/fps', min_value=0.1, max_value=1000.0),
    ParamSpec('realtime', True, 'Play file sources at fps (true) or as fast as possible'),
    ParamSpec('loop', False, 'Restart file sources at the end instead of exiting'),
    ParamSpec('max_persons', 1, 'Persons per cloud (most confident first); the cloud height',
              min_value=1, max_value=16),
    ParamSpec('wait_for_subscribers', 0, 'Before the first frame, wait until this many '
              'subscribers listen on /mocap/keypoints2d (e.g. 1 for a recorder); 0 = start at once',
              min_value=0),
    ParamSpec('wait_timeout_s', 10.0, 'Longest wait for those subscribers, seconds',
              min_value=0.0),
    ParamSpec('frame_id', 'camera_optical_frame', 'frame_id of the keypoints and camera info'),
    ParamSpec('image_width', 0, 'Image width in pixels for approximate intrinsics; 0 = '
              'infer from the keypoints of the first frames', min_value=0),
    ParamSpec('image_height', 0, 'Image height in pixels; 0 = infer', min_value=0),
    ParamSpec('horizontal_fov_deg', 60.0, 'Horizontal field of view for approximate '
              'intrinsics when no calibration is known', min_value=1.0, max_value=179.0),
)


def select_persons(people: np.ndarray, max_persons: int) -> np.ndarray:
    """(P, 23, 3) -> (max_persons, 23, 3): the most confident persons first, padded with
    all-zero (not seen) persons."""
    out = np.zeros((max_persons, NUM_KEYPOINTS, 3))
    if len(people):
        order = np.argsort(-people[..., 2].sum(axis=-1), kind='stable')[:max_persons]
        out[:len(order)] = people[order]
    return out


def infer_image_size(frames: List[Tuple[int, Path]], sample: int = 60) -> Tuple[int, int]:
    """Smallest 'standard' image size containing the keypoints of the first frames."""
    umax = vmax = 0.0
    for _, f in frames[:sample]:
        try:
            u, v = keypoint_extent(read_openpose_file(f))
        except OpenPoseError:
            continue
        umax, vmax = max(umax, u), max(vmax, v)
    for w, h in ((640, 480), (1280, 720), (1920, 1080), (1080, 1920), (3840, 2160)):
        if umax < w and vmax < h:
            return w, h
    return int(np.ceil(umax + 1)), int(np.ceil(vmax + 1))


def main(args: Optional[List[str]] = None) -> int:
    argv = sys.argv[1:] if args is None else list(args)
    if '-h' in argv or '--help' in argv:
        print(__doc__)
        print('Parameters (--ros-args -p name:=value):')
        print(describe_parameters(PARAMETERS))
        return 0

    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.node import Node
    from sensor_msgs.msg import CameraInfo, PointCloud2

    from mocap_core.diagnostics import NodeDiagnostics
    from mocap_core.qos import SENSOR_QOS, STREAM_QOS
    from mocap_core.ros_conversions import (intrinsics_to_camera_info, keypoints_to_cloud,
                                            make_header)

    class KeypointsNode(Node):
        def __init__(self) -> None:
            super().__init__('keypoints')
            self.p = declare_parameters(self, PARAMETERS)
            if self.p['source'] not in SOURCES:
                raise ValueError(f"unknown source {self.p['source']!r}; use one of {SOURCES}")
            self.frames = list_openpose_files(self.p['path'])
            w, h = self.p['image_width'], self.p['image_height']
            if w <= 0 or h <= 0:
                w, h = infer_image_size(self.frames)
            self.intrinsics = CameraIntrinsics.from_fov(w, h, self.p['horizontal_fov_deg'])
            self.get_logger().warn(
                f'no calibration given: approximating intrinsics from image size {w}x{h} and '
                f"horizontal FOV {self.p['horizontal_fov_deg']:.0f} deg "
                f'(fx = fy = {self.intrinsics.fx:.1f} px)')
            self.pub_kp = self.create_publisher(PointCloud2, '/mocap/keypoints2d', SENSOR_QOS)
            self.pub_info = self.create_publisher(CameraInfo, '/mocap/camera_info', STREAM_QOS)
            self.diag = NodeDiagnostics(self, 'keypoints', hardware_id=str(self.p['path']))
            self.diag.set_value('source', self.p['source'])
            self.diag.set_value('intrinsics', 'approximate')
            self.index = 0
            self.frame_ns = int(round(1e9 / self.p['fps']))
            self.t0_ns = self.get_clock().now().nanoseconds
            self.published = 0
            self.no_person = 0
            self.done = False
            period = 1.0 / self.p['fps'] if self.p['realtime'] else 0.0
            self.timer = self.create_timer(period, self.step)
            self.get_logger().info(
                f"playing {len(self.frames)} OpenPose frames from {self.p['path']} at "
                f"{self.p['fps']:g} fps{' (as fast as possible)' if not self.p['realtime'] else ''}")

        def ready(self) -> bool:
            need = self.p['wait_for_subscribers']
            if need <= 0 or self.pub_kp.get_subscription_count() >= need:
                return True
            waited = (self.get_clock().now().nanoseconds - self.t0_ns) * 1e-9
            if waited > self.p['wait_timeout_s']:
                self.get_logger().warn(f'only {self.pub_kp.get_subscription_count()} of {need} '
                                       f'subscribers after {waited:.1f} s; starting anyway')
                self.p['wait_for_subscribers'] = 0
                return True
            return False

        def step(self) -> None:
            if self.published == 0 and not self.ready():
                return
            if self.published == 0 and self.index == 0:
                self.t0_ns = self.get_clock().now().nanoseconds
            if self.index >= len(self.frames):
                if self.p['loop']:
                    self.index = 0
                else:
                    self.done = True
                    return
            _, path = self.frames[self.index]
            stamp_ns = self.t0_ns + self.published * self.frame_ns
            self.index += 1
            self.diag.input.tick()
            with self.diag.processing():
                try:
                    people = read_openpose_file(path)
                except OpenPoseError as exc:
                    self.diag.errors += 1
                    self.get_logger().warn(f'skipping frame: {exc}')
                    return
                kp = select_persons(people, self.p['max_persons'])
                header = make_header(stamp_ns, self.p['frame_id'])
                cloud = keypoints_to_cloud(kp, header)
            if not np.any(kp[..., 2] > 0):
                self.no_person += 1
                self.get_logger().info('no person in frame', throttle_duration_sec=2.0)
            self.pub_info.publish(intrinsics_to_camera_info(self.intrinsics, header))
            self.pub_kp.publish(cloud)
            self.published += 1
            self.diag.output.tick()

    rclpy.init(args=args)
    node = None
    try:
        node = KeypointsNode()
        while rclpy.ok() and not node.done:
            rclpy.spin_once(node, timeout_sec=0.1)
        # Let the last messages leave before the publishers go away.
        for _ in range(5):
            rclpy.spin_once(node, timeout_sec=0.1)
        node.get_logger().info(f'finished: {node.published} frames published, '
                               f'{node.no_person} without a person, {node.diag.errors} skipped')
        return 0
    except (FileNotFoundError, ValueError) as exc:
        print(f'keypoints: error: {exc}', file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    finally:
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()


if __name__ == '__main__':
    sys.exit(main())
