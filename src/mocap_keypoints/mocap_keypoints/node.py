"""``ros2 run mocap_keypoints keypoints``: 2D body keypoints with confidences, live.

Publishes for every processed frame, stamped with the image's stamp (docs/design.md §2):
  * ``/mocap/keypoints2d`` (sensor_msgs/PointCloud2, sensor-data QoS): one row per person
    (at most ``max_persons``, the longest tracked first), width = 23 keypoints, float32
    ``u, v, confidence, id`` (the person's id, stable from frame to frame,
    ``mocap_core.tracking``); when nobody is found the cloud is still published, one row
    with all confidences 0 and id 0;
  * ``/humans/bodies/tracked`` (std_msgs/UInt32MultiArray): the ids in the cloud;
  * ``/mocap/camera_info`` (sensor_msgs/CameraInfo): the intrinsics of the keypoints;
  * ``/mocap/camera/motion`` (nav_msgs/Odometry) with ``camera_motion`` (image sources): the
    camera's rotation since the first frame, its angular velocity and whether it is static,
    rotating or moving, from the image background (``mocap_core.camera_motion``; the
    encoding is ``mocap_core.ros_conversions.camera_motion_to_odometry``'s); once a floor
    arrives on ``floor_topic`` (the physics stage's), also the camera's position and
    velocity, measured over the floor;
  * ``/mocap/keypoints2d/annotated`` (sensor_msgs/Image, bgr8) with ``publish_annotated``:
    the skeleton drawn over the frame, for debugging (reliable, keep-last 2, published by a
    second node ``<name>_annotated`` with its own DDS participant);
  * ``/diagnostics``: detector time, input and output rates, frames dropped, errors, source,
    detector, intrinsics, ids given, lost, re-identified and renamed by bone lengths.

Subscribes (besides an image source's topics) ``floor_topic`` (above) and, with several
people and ``id_by_bone_lengths`` (off by default), ``bone_lengths_topic`` (the lifter's held
skeletons): a person who left and came back under a new id takes their old id back once the
lifter knows their bones (``mocap_core.tracking``).

Sources (parameter ``source``; ``auto`` picks from ``path``):
  * ``camera``: an OpenCV camera (``device`` index or /dev/videoN); stamps = grab time;
  * ``video``: a video file; stamps = start time + frame index / the video's fps; played at
    its own rate (``realtime``, dropping frames the detector cannot keep up with) or as fast
    as possible without drops; optionally looping;
  * ``images``: a directory of images in natural name order, stamped at ``fps``;
  * ``topic``: sensor_msgs/Image or CompressedImage on ``image_topic`` (CompressedImage when
    the name ends in ``/compressed``), with ``camera_info_topic``; stamps = the image's (an
    image whose stamp is not after the previous one is dropped with a warning; stamps jumping
    back by ``restart_after_s`` or more start a new stream, as when a bag is looped);
  * ``openpose_json``: a directory of OpenPose JSON files (BODY_25 / COCO-18), no detector.

Detector: MediaPipe BlazePose full (mediapipe 0.10.14, bundled weights), in its own thread
behind a one-frame slot: the newest frame is processed, older waiting frames are dropped and
counted. Intrinsics: ``calibration_file`` (camera_info YAML) if given, else the CameraInfo
topic (topic source), else approximated from the image size and ``horizontal_fov_deg``
(logged as an approximation). Keypoints are undistorted when the calibration has distortion.

Exit status: 0 at the end of a file source or on Ctrl-C; 2 when the source cannot be opened
(camera not found, file unreadable, bad parameter); 1 when a camera stops delivering frames.
"""

from __future__ import annotations

import collections
import re
import sys
import threading
import time
from typing import Callable, Deque, Dict, Iterator, List, Optional, Tuple

import numpy as np
import rclpy
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, JointState, PointCloud2
from std_msgs.msg import UInt32MultiArray

from mocap_core import topics
from mocap_core.camera import CameraCalibration, read_camera_info_yaml
from mocap_core.camera_motion import MOVING_ROTATIONS, CameraMotionParams
from mocap_core.checkpoint import WeightsError
from mocap_core.tracking import PersonTracker, TrackerParams
from mocap_core.data.openpose import infer_image_size
from mocap_core.diagnostics import NodeDiagnostics
from mocap_core.executors import make_executor, spin_until
from mocap_core.guard import KeyedRateLimit, guarded, record_failure
from mocap_core.metrics import LatencyStats, RateMeter
from mocap_core.parameters import ParamSpec, declare_parameters, help_requested
from mocap_core.qos import LATCHED_QOS, SENSOR_QOS, STREAM_QOS, input_qos
from mocap_core.ros_conversions import (MessageError, bgr_to_image, camera_info_to_intrinsics,
                                        camera_motion_to_odometry,
                                        compressed_image_to_bgr, image_to_bgr,
                                        intrinsics_to_camera_info, keypoints_to_cloud,
                                        make_header, msg_to_bodies_bone_lengths,
                                        stamp_to_ns, transform_stamped_to_arrays)
from mocap_core.rotations import quat_to_matrix
from mocap_core.streams import StampOrder

from .detector import create_detector
from .facing import FacingCheck, FacingCheckParams, FacingClassifier
from .mirror_check import MirrorCheck, MirrorCheckParams
from .intrinsics import IntrinsicsProvider
from .pipeline import FrameProcessor, FrameResult, select_persons  # noqa: F401 (re-exported)
from .sources import SOURCE_KINDS, Frame, SourceError, open_source, resolve_kind
from .worker import LatestWorker, SourceFeeder

PARAMETERS = (
    ParamSpec('source', 'auto', 'Input kind: auto, ' + ', '.join(SOURCE_KINDS) + '. auto: '
              'camera when path is empty, video for a file, openpose_json for a directory '
              'with *.json files, images for another directory', read_only=True),
    ParamSpec('path', '', 'Video file, image directory or OpenPose JSON directory',
              read_only=True),
    ParamSpec('device', '0', 'Camera (source camera): OpenCV index, /dev/videoN or a stream '
              'URL', read_only=True),
    ParamSpec('image_topic', topics.IMAGE, 'Image topic (source topic); '
              'sensor_msgs/CompressedImage when it ends in /compressed, else sensor_msgs/Image',
              read_only=True),
    ParamSpec('image_qos', 'auto', 'Reliability of the image subscription: auto (reliable '
              'when every publisher of the topic is reliable, else best effort; re-checked '
              'every second), reliable or best_effort. Keep-last 2 either way. '
              'Raw images are large: best effort loses many of them over Fast DDS\'s UDP '
              'transport here, reliable does not', read_only=True,
              additional_constraints='auto, reliable or best_effort'),
    ParamSpec('camera_info_topic', topics.IMAGE_CAMERA_INFO, 'CameraInfo topic (source topic)',
              read_only=True),
    ParamSpec('fps', 0.0, 'Frame rate: stamps of video/image/JSON sources advance by 1/fps '
              '(0 = the video file\'s own rate, 30 for directories); camera: rate requested '
              'from the driver (0 = its default)', min_value=0.0, max_value=1000.0,
              read_only=True),
    ParamSpec('realtime', True, 'File sources: play at their frame rate and drop frames the '
              'detector cannot keep up with (true), or as fast as possible without drops'),
    ParamSpec('loop', False, 'Restart file sources at the end instead of exiting',
              read_only=True),
    ParamSpec('detector', 'auto', 'Keypoint detector: blazepose = MediaPipe BlazePose full '
              '(bundled with mediapipe 0.10.14, one person), blazepose_multi = the same models '
              'for several people (a window per person, docs/multi_person.md), auto = '
              'blazepose_multi when max_persons > 1, else blazepose', read_only=True,
              additional_constraints='auto, blazepose or blazepose_multi'),
    ParamSpec('tracking', True, 'Video mode: follow people from frame to frame; false '
              'treats every image as unrelated (the person detector runs on every image, '
              'slower; a person gets an id at first sight)', read_only=True),
    ParamSpec('min_detection_confidence', 0.5, 'BlazePose person detection threshold',
              min_value=0.0, max_value=1.0, read_only=True),
    ParamSpec('min_tracking_confidence', 0.5, 'BlazePose tracking threshold (below it the '
              'person is detected again)', min_value=0.0, max_value=1.0, read_only=True),
    ParamSpec('max_persons', 4, 'Most persons followed and published at once (the cloud has '
              'one row per person, an id field, the longest tracked person in row 0)',
              min_value=1, max_value=16, read_only=True),
    ParamSpec('detection_interval', 5, 'blazepose_multi: look for new people every this '
              'many frames, in regions of the image taken in turn (between, each person is '
              'tracked in their own window); while nobody new appears the interval doubles, up '
              'to 3x this', min_value=1, max_value=1000, read_only=True),
    ParamSpec('still_detection_interval', 60, 'blazepose_multi: once the search for new '
              'people has found nobody in a whole round of regions at its longest interval, a '
              'search is skipped while nothing changes in the picture outside the people '
              'followed (a static camera), but made at least every this many frames; 0 = never '
              'skipped', min_value=0, max_value=100000, read_only=True),
    ParamSpec('landmark_threads', 2, 'blazepose_multi: the people\'s landmark models run in '
              'up to this many threads at once (1: one after the other)', min_value=1,
              max_value=16, read_only=True),
    ParamSpec('whole_frame_min_height', 0.4, 'blazepose_multi: a person followed alone whose '
              'keypoints span at least this fraction of the image\'s long side is tracked on '
              'the whole image, as the single-person detector does (cheaper than a window); '
              'back to a window below 0.75x this or when a second person is found; 0 = never',
              min_value=0.0, max_value=1.0, read_only=True),
    ParamSpec('min_person_height_px', 48.0, 'Persons whose seen keypoints span fewer pixels '
              'in height are ignored', min_value=0.0, read_only=True),
    ParamSpec('search_min_person_fraction', 0.1, 'blazepose_multi: the search takes turns '
              'between its regions and finer squares, for people down to '
              'max(min_person_height_px, this x the image\'s short side, 32 px) high (far from '
              'the camera); smaller: more squares, each scanned less often (all of them every '
              'few seconds while nobody is followed, over a minute while somebody is); 1 = no '
              'finer squares',
              min_value=0.0, max_value=1.0, read_only=True),
    ParamSpec('search_where_changed', True, 'blazepose_multi: the search for new people looks '
              'where the picture changed since its last look, outside the people followed '
              '(in a square sized for the change), every other search at most: somebody who '
              'walks into a static camera\'s picture is found within a search or two instead '
              'of when the turn of regions comes to them; a moving camera changes too much to '
              'say where, and the turns go on', read_only=True),
    ParamSpec('id_after_frames', 0, 'A new person gets an id (and is published) after being '
              'seen in this many consecutive frames, so that a one-frame false detection never '
              'gets one; 0 = 3 when max_persons > 1, else 1 (the single-person detector '
              'tracks one person and has no such blips)', min_value=0, max_value=100,
              read_only=True),
    ParamSpec('id_timeout_s', 1.0, 'A person unseen for longer than this loses the id; seen '
              'again sooner, near where they were expected, they keep it', min_value=0.0,
              read_only=True),
    ParamSpec('id_by_appearance', True, 'Tell people apart also by the colours of their '
              'clothes (torso, arms, legs) when they cross, and give a person hidden for up to '
              'id_appearance_timeout_s their id back when they look the same', read_only=True),
    ParamSpec('id_appearance_timeout_s', 3.0, 'With id_by_appearance: how long a person '
              'unseen keeps their id for a return recognised by their clothes (at least '
              'id_timeout_s)', min_value=0.0, read_only=True),
    ParamSpec('id_by_bone_lengths', False, 'Take the bone lengths the lifter holds for each '
              'person (bone_lengths_topic) as their signature: a person who left and came back '
              'under a new id gets their old one back once the lifter knows their skeleton '
              '(bones within id_bone_length_tolerance and, from images, clothes alike). Off by '
              'default: the shipped lifter\'s skeletons of different people are about as close '
              'as two of one person (docs/multi_person.md)', read_only=True),
    ParamSpec('bone_lengths_topic', topics.BODIES_BONE_LENGTHS, 'The lifter\'s held '
              'skeletons (sensor_msgs/JointState, names body_<id>/<bone group>)',
              read_only=True),
    ParamSpec('id_bone_length_memory_s', 60.0, 'With id_by_bone_lengths: how long a person '
              'who is gone is remembered by their bone lengths, seconds', min_value=0.0,
              read_only=True),
    ParamSpec('id_bone_length_tolerance', 0.03, 'With id_by_bone_lengths: largest relative '
              'difference of the bone lengths (median over the bone groups) for a person to '
              'be named as one who left; exactly one remembered person may qualify',
              min_value=0.0, max_value=0.5, read_only=True),
    ParamSpec('mirror_check', False, 'Check each person\'s left and right labels with a second '
              'detector on the mirrored frames (mocap_keypoints.mirror_check): a person the '
              'detector labels as facing the camera whom the mirrored reading sees facing '
              'away gets left and right exchanged. A second detector run per frame (about '
              'twice the detector\'s time); image sources only (docs/keypoints.md)',
              read_only=True),
    ParamSpec('mirror_only_when_needed', False, 'With mirror_check: read the mirrored frame only '
              'when someone\'s labels face the camera (the only frames the check can change; '
              'the second detector starts afresh after a gap): cheaper (43 % of the rendered '
              'frames), a little less accurate (docs/keypoints.md)', read_only=True),
    ParamSpec('mirror_min_width', 0.25, 'With mirror_check: both readings must face opposite '
              'ways by more than this (left minus right shoulder and hip in the image, over '
              'the torso length)', min_value=0.0, read_only=True),
    ParamSpec('facing_check', False, 'Check each person\'s left and right labels against '
              'which way they face in the image (a small network on the person\'s crop, '
              'mocap_keypoints.facing): a person the detector labels as facing the camera '
              'but the network, over the last facing_window frames, sees from behind gets left '
              'and right exchanged. Image sources only (docs/keypoints.md)', read_only=True),
    ParamSpec('facing_weights', '', 'Weights of the facing network (empty: the shipped '
              'weights/facing.pt; mocap train facing makes them)', read_only=True),
    ParamSpec('facing_window', 9, 'With facing_check: frames in the median of the network\'s '
              'probability, per person (the last ones; a longer window reacts later to a '
              'turn)', min_value=1, max_value=100, read_only=True),
    ParamSpec('facing_min_width', 0.25, 'With facing_check: the detector\'s labels must face '
              'the camera by more than this (left minus right shoulder and hip in the image, '
              'over the torso length)', min_value=0.0, read_only=True),
    ParamSpec('facing_max_probability', 0.02, 'With facing_check: exchange when the network\'s '
              'median probability of the person facing the camera is below this',
              min_value=0.0, max_value=1.0, read_only=True),
    ParamSpec('calibration_file', '', 'Camera calibration (standard camera_info YAML); takes '
              'precedence over the CameraInfo topic', read_only=True),
    ParamSpec('horizontal_fov_deg', 60.0, 'Horizontal field of view for approximate '
              'intrinsics when no calibration is known', min_value=1.0, max_value=179.0,
              read_only=True),
    ParamSpec('undistort', True, 'Undistort keypoints when the calibration has lens '
              'distortion (published CameraInfo then has zero distortion)', read_only=True),
    ParamSpec('image_width', 0, 'OpenPose source: image width for the intrinsics (0 = infer '
              'from the keypoints); camera: width requested from the driver (0 = default)',
              min_value=0, read_only=True),
    ParamSpec('image_height', 0, 'Image height, as image_width', min_value=0, read_only=True),
    ParamSpec('publish_annotated', False, 'Also publish the frame with the skeleton drawn on '
              '/mocap/keypoints2d/annotated (debugging; costs a copy per frame)',
              read_only=True),
    ParamSpec('annotated_max_fps', 0.0, 'Highest rate of the annotated images (wall '
              'clock; 0 = every frame)', min_value=0.0, read_only=True),
    ParamSpec('synchronous', False, 'Image topic: detect in the subscription callback instead '
              'of the worker thread (offline replay: no frame dropped, the callback blocks)',
              read_only=True),
    ParamSpec('wait_for_subscribers', 0, 'Before the first frame, wait until this many '
              'subscribers listen on /mocap/keypoints2d (e.g. 1 for a recorder); 0 = start at '
              'once',
              min_value=0),
    ParamSpec('wait_timeout_s', 10.0, 'Longest wait for those subscribers, seconds',
              min_value=0.0),
    ParamSpec('restart_after_s', 1.0, 'Source topic: image stamps jumping back by this much or '
              'more start a new stream (a looped bag, a restarted driver, a clock reset); a '
              'smaller step back or a repeated stamp drops the image as stale', min_value=0.001),
    ParamSpec('frame_id', 'camera_optical_frame', 'frame_id of the keypoints and camera info '
              '(source topic: the image\'s own frame_id when it has one)'),
    ParamSpec('camera_motion', True, 'Estimate the camera\'s rotation and whether it moves '
              'from the image background (tracked corners outside the people) and publish it '
              'on /mocap/camera/motion (nav_msgs/Odometry) for the world stage; image sources '
              'only', read_only=True),
    ParamSpec('floor_topic', topics.PHYSICS_FLOOR, 'The floor in the camera frame '
              '(geometry_msgs/TransformStamped p_camera = R p_floor + t, as the physics stage '
              'publishes it): with it the camera\'s translation is measured over the floor and '
              'published with the camera motion, so that a moving camera still fixes the '
              'person in the world; empty: rotation only', read_only=True),
    ParamSpec('camera_motion_max_width', 640, 'Frames wider than this are scaled down for the '
              'camera-motion estimate (speed)', min_value=64, read_only=True),
    ParamSpec('camera_motion_track_window', 21, 'Side of the camera-motion estimate\'s '
              'Lucas-Kanade window, pixels at 640 wide. 15 (with 2 pyramid levels) takes 0.73x '
              'the CPU with the same states, but made the world path of walking cameras worse '
              '(docs/benchmarks/video_eval/camera_lk_s61)', min_value=3, read_only=True),
    ParamSpec('camera_motion_track_levels', 3, 'Pyramid levels of that window above the '
              'image (OpenCV maxLevel)', min_value=0, read_only=True),
    ParamSpec('camera_motion_rotation', 'plane', "The rotation of a camera that translates, "
              "before the physics floor is known: 'plane' (the floor's homography decomposed, "
              "the solution nearest the pure turn) or 'homography' (the best pure turn, which "
              "takes a walking camera's step for a turn: 12-18 deg/s off on rendered walks; "
              'docs/global.md)', read_only=True, additional_constraints="'plane' or 'homography'"),
    ParamSpec('finish_thread', True, 'Estimate the camera motion (and draw the annotated '
              'image) in a second thread, while the next frame is detected: the frames come '
              'out in order and unchanged, the detector thread is free sooner (keypoint rate; '
              'docs/speed.md). false: both in the detector thread, one after the other',
              read_only=True),
    ParamSpec('opencv_threads', 1, "OpenCV's worker threads in this process while the node "
              'runs (cv2.setNumThreads, restored at shutdown; 0 = leave the setting as it is, '
              "OpenCV's own default being one per core). 1: the camera-motion estimate's "
              'optical flow on two threads took twice the CPU time for no wall time '
              '(docs/speed.md), and the node already runs detection and that estimate in '
              'threads of their own', read_only=True, min_value=0),
)

ANNOTATED_TOPIC = topics.ANNOTATED


class _LockedRateMeter(RateMeter):
    """RateMeter ticked from a source thread and read from the executor."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._lock = threading.Lock()

    def tick(self, now: Optional[float] = None) -> None:
        with self._lock:
            super().tick(now)

    def rate(self, now: Optional[float] = None) -> float:
        with self._lock:
            return super().rate(now)


def _within(fn, seconds: float) -> bool:
    """Run ``fn()`` in a daemon thread and wait at most ``seconds``; whether it finished (a
    shutdown never hangs on a model that does not let go)."""
    t = threading.Thread(target=fn, name='close', daemon=True)
    t.start()
    t.join(seconds)
    return not t.is_alive()


#: Detected frames waiting for the executor beyond which the oldest are dropped (counted).
MAX_WAITING_RESULTS = 2


def main(args: Optional[List[str]] = None) -> int:
    if help_requested(sys.argv[1:] if args is None else list(args), __doc__, PARAMETERS):
        return 0

    import rclpy
    from rclpy.exceptions import ParameterException
    from rclpy.executors import ExternalShutdownException

    from mocap_core.executors import close_nodes, init_rclpy

    signals = init_rclpy(args)
    node = executor = None
    try:
        try:
            node = KeypointsNode()
        except (SourceError, FileNotFoundError, ValueError, ParameterException) as exc:
            print(f'keypoints: error: {exc}', file=sys.stderr)
            return 2
        executor = make_executor()
        executor.add_node(node)
        spin_until(executor, lambda: not signals.requested and rclpy.ok() and not node.done,
                   lambda exc: record_failure(node, 'callback', exc))
        if signals.requested:
            node.get_logger().info(f'stopped: {node.summary()}')
            return 0
        node._drain()
        reason, error = node.source_end or ('stopped', None)
        # Let the last messages leave before the publishers go away.
        for _ in range(5):
            if not rclpy.ok():
                break
            executor.spin_once(timeout_sec=0.1)
        if error is not None:
            node.get_logger().error(f'source failed: {reason} ({node.summary()})')
            return 1
        node.get_logger().info(f'finished ({reason}): {node.summary()}')
        return 0
    except (KeyboardInterrupt, ExternalShutdownException):
        if node is not None:  # the context may be gone: no /rosout, plain stderr
            print(f'[keypoints] stopped: {node.summary()}', file=sys.stderr)
        return 0
    finally:
        try:
            close_nodes(executor, [node], before=[node.shutdown] if node is not None else [],
                        label='keypoints')
        finally:
            signals.restore()


def _side_node(name: str, cli_args: Optional[List[str]]) -> Node:
    """A publisher-only node in its own context (its own DDS participant). Large debug
    images sent by the keypoint node's own participant were seen to make Fast DDS lose
    best-effort keypoint messages at 40 fps on a loaded 2-core machine; from a second
    participant they do not. Topic remaps apply; node-name remaps do not."""
    from rclpy.context import Context

    raw = list(sys.argv if cli_args is None else cli_args)
    keep: List[str] = []
    i = 0
    while i < len(raw):
        if raw[i] in ('-r', '--remap') and i + 1 < len(raw) and \
                raw[i + 1].split(':=')[0].split(':')[-1] in ('__node', '__name'):
            i += 2
            continue
        keep.append(raw[i])
        i += 1
    from rclpy.signals import SignalHandlerOptions

    context = Context()  # signals are the main context's (mocap_core.executors.StopSignals)
    rclpy.init(args=keep, context=context, signal_handler_options=SignalHandlerOptions.NO)
    return rclpy.create_node(name, context=context)

class KeypointsNode(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__('keypoints', **kwargs)
        # 'device' accepts an index (an integer to ROS: device:=1) or a path/URL string.
        self.p = p = declare_parameters(self, [s for s in PARAMETERS if s.name != 'device'])
        spec = next(s for s in PARAMETERS if s.name == 'device')
        desc = spec.descriptor()
        desc.dynamic_typing = True
        p['device'] = str(self.declare_parameter('device', spec.default, desc).value)
        self.kind = resolve_kind(p['source'], p['path'])
        if p['image_qos'] not in ('auto', 'reliable', 'best_effort'):
            raise ValueError(f"image_qos must be auto, reliable or best_effort, got "
                             f"{p['image_qos']!r}")
        log = self.get_logger()
        #: OpenCV's thread setting before this node changed it (restored by ``shutdown``)
        self._opencv_threads_before: Optional[int] = None
        if p['opencv_threads'] > 0:
            import cv2
            self._opencv_threads_before = cv2.getNumThreads()
            cv2.setNumThreads(int(p['opencv_threads']))
        calibration = None
        if p['calibration_file']:
            calibration = read_camera_info_yaml(p['calibration_file'])
            log.info(f"calibration from {p['calibration_file']}: "
                     f'{calibration.intrinsics.width}x{calibration.intrinsics.height}, '
                     f'fx={calibration.intrinsics.fx:.1f} fy={calibration.intrinsics.fy:.1f}'
                     f', {calibration.distortion_model}')
        self.provider = IntrinsicsProvider(calibration, p['horizontal_fov_deg'],
                                           p['calibration_file'])
        self.source = None
        fixed_size = None
        if self.kind != 'topic':
            self.source = open_source(
                self.kind, p['path'], p['device'], fps=p['fps'], loop=p['loop'],
                width=p['image_width'], height=p['image_height'], clock_ns=self._now_ns)
        if self.kind == 'openpose_json':
            detector = None
            w, h = p['image_width'], p['image_height']
            if w <= 0 or h <= 0:
                w, h = infer_image_size(self.source.files)
            fixed_size = (w, h)
            self.detector_name = 'openpose_json (recorded detections)'
        else:
            name = p['detector']
            if name == 'auto':
                name = 'blazepose_multi' if p['max_persons'] > 1 else 'blazepose'
            self._make_detector = lambda: self._new_detector(name, p)
            detector = self._make_detector()
            self.detector_name = detector.name
        self.detector = detector
        motion = None
        if p['camera_motion'] and self.kind != 'openpose_json':
            if p['camera_motion_rotation'] not in MOVING_ROTATIONS:
                raise ValueError('camera_motion_rotation must be ' + ' or '.join(MOVING_ROTATIONS)
                                 + f", got {p['camera_motion_rotation']!r}")
            motion = CameraMotionParams(max_width=p['camera_motion_max_width'],
                                        moving_rotation=p['camera_motion_rotation'],
                                        track_window=p['camera_motion_track_window'],
                                        track_levels=p['camera_motion_track_levels'])
            motion.validate()
        # unrelated images (tracking false): a person gets an id at first sight and nobody
        # is carried from one image to the next
        self.tracker = PersonTracker(TrackerParams(
            max_persons=p['max_persons'], min_height_px=p['min_person_height_px'],
            birth_frames=(p['id_after_frames'] or (3 if p['max_persons'] > 1 else 1))
            if p['tracking'] else 1,
            max_lost_s=p['id_timeout_s'] if p['tracking'] else 0.0,
            appearance_max_lost_s=p['id_appearance_timeout_s'] if p['tracking'] else 0.0,
            signature_memory_s=(p['id_bone_length_memory_s']
                                if p['tracking'] and p['id_by_bone_lengths'] else 0.0),
            signature_rename_tolerance=p['id_bone_length_tolerance']))
        self.processor = FrameProcessor(detector, self.provider, p['max_persons'],
                                        undistort=p['undistort'],
                                        annotate=p['publish_annotated'],
                                        fixed_size=fixed_size,
                                        restart_after_s=p['restart_after_s'],
                                        camera_motion=motion, tracker=self.tracker,
                                        appearance=p['id_by_appearance'],
                                        facing=self._facing_check(p),
                                        mirror=self._mirror_check(p))
        self.pub_kp = self.create_publisher(PointCloud2, topics.KEYPOINTS, SENSOR_QOS)
        self.pub_tracked = self.create_publisher(UInt32MultiArray, topics.BODIES_TRACKED,
                                                 STREAM_QOS)
        self.pub_info = self.create_publisher(CameraInfo, topics.CAMERA_INFO, STREAM_QOS)
        self.pub_motion = (self.create_publisher(Odometry, topics.CAMERA_MOTION, STREAM_QOS)
                           if motion is not None else None)
        self.floors_received = 0
        self.translation_frames = 0
        if motion is not None and p['floor_topic']:
            self.create_subscription(TransformStamped, p['floor_topic'],
                                     guarded(self, self.on_floor, 'floor'),
                                     input_qos(STREAM_QOS, 10))
        #: the lifter's bone lengths feed back into the tracker (the detection's first part)
        self.bone_length_feedback = bool(p['tracking'] and p['id_by_bone_lengths']
                                         and p['bone_lengths_topic'] and p['max_persons'] > 1)
        if self.bone_length_feedback:
            self.create_subscription(JointState, p['bone_lengths_topic'],
                                     guarded(self, self.on_bone_lengths, 'bone_lengths'),
                                     input_qos(LATCHED_QOS, 10))
        self.motion_states: Dict[str, int] = {}
        self.implausible_turns = 0       # the estimator's refused plane / floor turns
        self.motion_stats = LatencyStats()
        self.pub_annotated = None
        self._annotated_node = None
        if p['publish_annotated']:
            self._annotated_node = _side_node(self.get_name() + '_annotated',
                                             kwargs.get('cli_args'))
            # Reliable (serves reliable and best-effort subscribers): large best-effort
            # samples are often lost over UDP; keep-last 2 never queues stale images.
            self.pub_annotated = self._annotated_node.create_publisher(
                Image, ANNOTATED_TOPIC,
                QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=2,
                           reliability=ReliabilityPolicy.RELIABLE))
        description = (self.source.description if self.source is not None
                       else f"topic {p['image_topic']}")
        self.diag = NodeDiagnostics(self, 'keypoints', hardware_id=description)
        self.diag.input = _LockedRateMeter()
        self.diag.set_value('source', description)
        self.diag.set_value('detector', self.detector_name)
        self.diag.set_value('intrinsics', 'none yet')
        self.diag.set_value('camera_motion_rotation', p['camera_motion_rotation']
                            if motion is not None else 'off')
        self.detector_stats = LatencyStats()
        self.results: Deque[tuple] = collections.deque()
        self.behind = 0       # detected frames dropped because the executor fell behind
        # paced by the world (a camera, a topic, a file played at its rate): frames may drop;
        # a file read as fast as possible (realtime false) or a synchronous topic never drops
        self._live_pace = (self.kind == 'camera' or (self.kind == 'topic' and not p['synchronous'])
                           or (self.kind not in ('camera', 'topic') and p['realtime']))
        # the worker and feeder threads hand their results to the executor's thread as tasks
        # (Executor.create_task, thread-safe): a guard condition would do the same, but the
        # events executor refuses nodes that have one (mocap_core.executors)
        self._drain_task = guarded(self, self._drain, 'results')
        split = p['finish_thread'] and self.processor.has_finish_work
        self.worker = (LatestWorker(self.processor.detect, self._on_result,
                                    finish=self.processor.finish, finish_name='camera_motion')
                       if split else
                       LatestWorker(self.processor.process, self._on_result)).start()
        self.diag.set_value('finish_thread', 'on' if split else 'off')
        self.feeder: Optional[SourceFeeder] = None
        self.source_end: Optional[Tuple[str, Optional[BaseException]]] = None
        self.published = 0
        self.no_person = 0
        self.stale = 0
        self._worker_dropped = 0
        self.input_order = StampOrder(p['restart_after_s'])    # images received (topic)
        self.output_order = StampOrder(p['restart_after_s'])   # keypoints published
        self.topic_index = 0
        self.intrinsics_detail = ''
        self.intrinsics_approx = False
        self._last_error_t = -1e9
        self._last_error = ''
        self._limited = KeyedRateLimit()
        self._next_annotated = 0.0
        self.t0_ns = self._now_ns()
        self.diag.on_publish(guarded(self, self._refresh_diagnostics, 'diagnostics'))
        if self.kind == 'topic':
            topic = p['image_topic']
            self.compressed = topic.rstrip('/').endswith('/compressed')
            self.image_type = CompressedImage if self.compressed else Image
            self.image_sub = None
            self.image_sub_old = None       # the previous subscription while switching
            # stamps that came through the new (True) and the old (False) subscription while
            # both exist: an image delivered by both is processed once
            self.switch_seen = {True: collections.deque(maxlen=32),
                                False: collections.deque(maxlen=32)}
            self.image_reliability = ''
            self._subscribe_images()
            if p['image_qos'] == 'auto':  # follow the publishers as they come and go
                self.create_timer(1.0, guarded(self, self._subscribe_images, 'image QoS'))
            self.create_subscription(CameraInfo, p['camera_info_topic'],
                                     guarded(self, self._on_camera_info, 'camera_info'),
                                     qos_profile_sensor_data)
            if calibration is not None:
                log.info(f"{p['camera_info_topic']} is ignored: the calibration file "
                         'takes precedence')
            log.info(f"listening on {topic} ({self.image_type.__name__}) and "
                     f"{p['camera_info_topic']}; detector {self.detector_name}")
        else:
            self.start_timer = self.create_timer(0.02, guarded(self, self._maybe_start, 'start'))
            mode = ('live' if self.source.live else 'at its frame rate, dropping frames '
                    'the detector cannot keep up with' if p['realtime']
                    else 'as fast as possible, no drops')
            log.info(f'{description}: {mode}; detector {self.detector_name}')

    # --- time -------------------------------------------------------------------------
    def _now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    # --- logging helpers --------------------------------------------------------------
    def _warn_limited(self, key: str, text: str, period_s: float = 5.0) -> None:
        """Warn, at most once per ``period_s`` for the same ``key``."""
        if self._limited.ready(key, period_s):
            self.get_logger().warn(text)

    def _problem(self, key: str, text: str) -> None:
        self.diag.errors += 1
        self._last_error, self._last_error_t = text, time.monotonic()
        self._warn_limited(key, text)

    # --- file and camera sources --------------------------------------------------------
    def _ready(self) -> bool:
        need = self.p['wait_for_subscribers']
        if need <= 0 or self.pub_kp.get_subscription_count() >= need:
            return True
        waited = (self._now_ns() - self.t0_ns) * 1e-9
        if waited > self.p['wait_timeout_s']:
            self.get_logger().warn(f'only {self.pub_kp.get_subscription_count()} of {need} '
                                   f'subscribers after {waited:.1f} s; starting anyway')
            return True
        return False

    def _maybe_start(self) -> None:
        if self.feeder is not None or not self._ready():
            return
        self.start_timer.cancel()
        self.feeder = SourceFeeder(self.source, self.worker, realtime=self.p['realtime'],
                                   on_frame=lambda f: self.diag.input.tick(),
                                   on_end=self._on_source_end).start()

    def _on_source_end(self, reason: str, error: Optional[BaseException]) -> None:
        self.source_end = (reason, error)  # feeder thread
        self._wake()

    # --- topic source ------------------------------------------------------------------
    def _on_image_from(self, sub, msg) -> None:
        """An image from subscription ``sub``: while an old and a new subscription overlap
        (a reliability switch), the copy the other one delivered already is skipped."""
        if self.image_sub_old is not None and sub in (self.image_sub, self.image_sub_old):
            new = sub is self.image_sub
            stamp = stamp_to_ns(msg.header.stamp)
            if stamp in self.switch_seen[not new]:
                self.switch_seen[not new].remove(stamp)
                return
            self.switch_seen[new].append(stamp)
        self._on_image(msg)

    def _on_image(self, msg) -> None:
        self.diag.input.tick()
        stamp = stamp_to_ns(msg.header.stamp)
        previous = self.input_order.last_ns
        verdict = self.input_order.check(stamp)
        if verdict == 'stale':
            self.stale += 1
            self.diag.dropped += 1
            self._problem('stamp', f'image stamp {stamp} ns is not after the previous '
                          f'{previous} ns (a duplicate or a late image): dropping the image')
            return
        if verdict == 'restart':
            self.get_logger().warn(
                f'image stamps jumped back by {(previous - stamp) * 1e-9:.1f} s (a bag played '
                'again, a restarted driver): starting a new stream')
        convert = compressed_image_to_bgr if self.compressed else image_to_bgr
        frame = Frame(stamp, None, self.topic_index,
                      f"{self.p['image_topic']} image {self.topic_index}",
                      decode=lambda m=msg: convert(m), frame_id=msg.header.frame_id)
        self.topic_index += 1
        if self.p['synchronous']:
            self.process_now(frame)
        else:
            self.worker.submit(frame)

    # --- offline processing (``mocap process``) -------------------------------------------
    def offline_frames(self) -> Iterator[Frame]:
        """The frames of the node's file source, in order, for processing in the calling
        thread with :meth:`process_offline` (the node is not spun: its own feeder thread
        never starts). Raises ValueError for the topic source."""
        if self.source is None:
            raise ValueError('offline frames need a file source (source:=video, images or '
                             'openpose_json), not an image topic')
        return iter(self.source)

    @property
    def frame_count(self) -> Optional[int]:
        """Number of frames of the file source when known (video files, directories)."""
        n = int(getattr(self.source, 'frame_count', 0) or 0)
        return n or None

    @property
    def frame_id(self) -> str:
        """The frame_id of images without their own (parameter ``frame_id``)."""
        return self.p['frame_id']

    def process_offline(self, frame: Frame) -> None:
        """Count one input frame, detect and publish it in the calling thread (nothing is
        dropped; a failure drops and counts this frame only, as live)."""
        self.diag.input.tick()
        try:
            self.process_now(frame)
        except Exception as exc:  # noqa: BLE001 - the failing-callback policy, offline
            record_failure(self, 'frame', exc)

    @property
    def offline_split(self) -> bool:
        """Whether :meth:`run_offline` uses two threads besides the caller's (``finish_thread``
        and nothing fed back into the detection from later stages: the bone-length ids
        would reach a frame one frame later or sooner, depending on timing)."""
        return bool(self.p['finish_thread'] and not self.bone_length_feedback)

    def run_offline(self, before_detect: Optional[Callable[[Frame], None]] = None,
                    before_publish: Optional[Callable[[Frame], None]] = None,
                    after_publish: Optional[Callable[[Frame], None]] = None) -> int:
        """Detect and publish every frame of the file source, in order, nothing dropped
        (``mocap process`` on a video). Returns the number of frames read.

        With :attr:`offline_split` the work runs in three threads: this one reads (decodes)
        the frames, a second one detects them, and a third one finishes (camera motion) and
        publishes them in their order, so that the later stages of an in-process graph, which
        the publishing calls, run beside the detection of the next frame: the same messages
        in the same order as one frame after the other (:meth:`process_offline`), about twice
        as fast on two cores. Otherwise every frame is processed in this thread.

        Hooks: ``before_detect(frame)`` in this thread before the frame is handed on (e.g.
        decoding it for a recorder); ``before_publish(frame)`` and ``after_publish(frame)``
        in the publishing thread around its messages (e.g. the bag time, a progress bar).
        A failing frame or hook is dropped and counted, as live; the run goes on."""
        def hook(fn, frame) -> None:
            if fn is not None:
                try:
                    fn(frame)
                except Exception as exc:  # noqa: BLE001 - the failing-callback policy
                    record_failure(self, 'frame', exc)

        count = 0
        if not self.offline_split:
            for frame in self.offline_frames():
                hook(before_detect, frame)
                hook(before_publish, frame)
                self.process_offline(frame)
                hook(after_publish, frame)
                count += 1
            return count

        def publish(frame, result, error, seconds) -> None:
            hook(before_publish, frame)
            try:
                self._handle(frame, result, error, seconds)
            except Exception as exc:  # noqa: BLE001 - the failing-callback policy, offline
                record_failure(self, 'frame', exc)
            hook(after_publish, frame)

        worker = LatestWorker(self.processor.detect, publish, name='offline_detector',
                              finish=self.processor.finish,
                              finish_name='offline_publish').start()
        try:
            for frame in self.offline_frames():
                hook(before_detect, frame)
                self.diag.input.tick()
                worker.submit(frame, block=True)
                count += 1
        finally:
            # the frames in flight are published, also when reading failed (not on Ctrl-C),
            # and no thread is left publishing once this returns
            if not isinstance(sys.exc_info()[1], KeyboardInterrupt):
                worker.wait_idle()
            worker.stop(timeout=None)
        return count

    def process_now(self, frame) -> None:
        """Detect and publish one frame in the calling thread (offline processing:
        ``synchronous`` images and ``mocap process`` on a video; nothing is dropped)."""
        t0 = time.perf_counter()
        try:
            result, error = self.processor.process(frame), None
        except Exception as exc:  # noqa: BLE001 - reported per frame, as the worker does
            result, error = None, exc
        self._handle(frame, result, error, time.perf_counter() - t0)

    def _subscribe_images(self) -> None:
        """(Re)create the image subscription with the reliability ``image_qos`` asks for
        (``auto``: what the current publishers offer; kept once images arrive)."""
        mode = self.p['image_qos']
        topic = self.p['image_topic']
        if mode == 'auto':
            infos = self.get_publishers_info_by_topic(topic)
            if not infos and self.image_sub is not None:
                return  # no publisher now: keep the subscription as it is
            mode = ('reliable' if infos and all(
                i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in infos)
                else 'best_effort')
        if self.image_sub_old is not None and \
                self.image_sub.get_publisher_count() >= self.image_sub_old.get_publisher_count():
            # the new subscription has matched what the old one had: retire the old one
            self.destroy_subscription(self.image_sub_old)
            self.image_sub_old = None
            for seen in self.switch_seen.values():
                seen.clear()
        if mode == self.image_reliability:
            return
        if self.image_sub is not None:
            # Keep the old subscription until the new one has matched the publishers (next
            # check): destroying it first would lose the images sent meanwhile. Images that
            # come through both are recognised by their stamps (_on_image).
            if self.image_sub_old is not None:
                self.destroy_subscription(self.image_sub_old)
            self.image_sub_old = self.image_sub
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=2,
                         reliability=(ReliabilityPolicy.RELIABLE if mode == 'reliable'
                                      else ReliabilityPolicy.BEST_EFFORT))
        holder: List = []   # the subscription, known to its own callback
        self.image_sub = self.create_subscription(
            self.image_type, topic,
            guarded(self, lambda msg: self._on_image_from(holder[0], msg), 'image'), qos,
            event_callbacks=SubscriptionEventCallbacks(
                incompatible_qos=self._on_incompatible_qos))
        holder.append(self.image_sub)
        self.image_reliability = mode
        self.diag.set_value('image_qos', mode)
        self.get_logger().info(f'subscribed to {topic} ({self.image_type.__name__}, '
                               f'{mode.replace("_", " ")})')

    def _on_incompatible_qos(self, event) -> None:
        self._warn_limited('qos', f"a publisher of {self.p['image_topic']} offers "
                           'incompatible QoS (a best-effort publisher cannot serve a '
                           'reliable subscription): set image_qos:=best_effort or auto')

    def _on_camera_info(self, msg: CameraInfo) -> None:
        try:
            intr = camera_info_to_intrinsics(msg)
        except MessageError as exc:
            self._problem('camera_info', f"ignoring {self.p['camera_info_topic']}: {exc} "
                          '(an uncalibrated camera has K = 0)')
            return
        calib = CameraCalibration(intr, str(msg.distortion_model),
                                  tuple(float(d) for d in msg.d))
        if self.provider.update_camera_info(calib):
            self.get_logger().info(
                f"camera_info: {intr.width}x{intr.height}, fx={intr.fx:.1f} "
                f"fy={intr.fy:.1f} cx={intr.cx:.1f} cy={intr.cy:.1f}, "
                f"{msg.distortion_model or 'no'} distortion")

    # --- results -----------------------------------------------------------------------
    def _on_result(self, frame, result, error, seconds) -> None:
        self.results.append((frame, result, error, seconds))  # worker thread
        self._wake()

    def _wake(self) -> None:
        """From the worker or feeder thread: have the executor that spins this node run
        :meth:`_drain` in its own thread. Not spun yet: the results wait for the next wake
        (or the final drain)."""
        executor = self.executor
        if executor is not None:
            executor.create_task(self._drain_task)

    def _drain(self) -> None:
        # only the results that are here now: a detector faster than the executor (in one
        # process with the other stages) must not keep this callback from returning, or
        # timers, other callbacks and Ctrl-C would wait for ever
        for _ in range(len(self.results)):
            if not self.results:
                break
            if len(self.results) > MAX_WAITING_RESULTS and self._live_pace:
                # the executor falls behind the detector (in one process with the other
                # stages, mocap run, they share it): the oldest results go, counted, as a
                # camera's frames would; never a growing queue
                self.results.popleft()
                self.diag.dropped += 1
                self.behind += 1
                self.get_logger().warn(f'falling behind: {self.behind} detected frames dropped '
                                       'before publishing so far', throttle_duration_sec=5.0)
                continue
            frame, result, error, seconds = self.results.popleft()
            self._handle(frame, result, error, seconds)
        self._count_worker_drops()

    def _count_worker_drops(self) -> None:
        """Add the frames the detector thread dropped since the last call to the dropped
        count (which also counts stale images and failed callbacks)."""
        dropped = self.worker.dropped
        self.diag.dropped += dropped - self._worker_dropped
        self._worker_dropped = dropped

    def _handle(self, frame, res: Optional[FrameResult], error, seconds: float) -> None:
        log = self.get_logger()
        if error is not None:
            self._problem(f'detector:{type(error).__name__}',
                          f'{frame.name}: detector failed ({type(error).__name__}: '
                          f'{error}); skipping the frame')
            return
        for new_id, old_id in res.renamed:
            log.info(f'person {new_id} is person {old_id} back, by the bone lengths the '
                     f'lifter holds: published as {old_id} from now on')
        for note in res.notes:
            if 'approximating' in note or 'ignoring' in note or 'not supported' in note:
                log.warn(note)
            else:
                log.info(note)
        if res.error is not None:
            # Files: one warning per file. Streams: one per kind of error and 5 s.
            key = res.error if self.kind in ('images', 'openpose_json') else \
                re.sub(r'\d+', '#', res.error)
            self._problem(key, f'skipping frame: {res.error}')
            return
        if self.output_order.check(res.stamp_ns) == 'stale':
            self.stale += 1
            self.diag.dropped += 1
            self._problem('order', f'{res.name}: stamp {res.stamp_ns} not after the last '
                          'published one; dropping it')
            return
        header = make_header(res.stamp_ns, res.frame_id or self.p['frame_id'])
        fi = res.intrinsics
        if fi.detail != self.intrinsics_detail:
            self.intrinsics_detail = fi.detail
            self.intrinsics_approx = fi.approximate
            self.diag.set_value('intrinsics', fi.detail)
        self.pub_info.publish(intrinsics_to_camera_info(fi.intrinsics, header))
        self.pub_kp.publish(keypoints_to_cloud(res.keypoints, header, ids=res.ids))
        if res.ids is not None:
            self.pub_tracked.publish(UInt32MultiArray(data=[int(i) for i in res.ids if i > 0]))
        cm = res.camera_motion
        if self.pub_motion is not None and cm is not None:
            self.pub_motion.publish(camera_motion_to_odometry(
                cm.state, cm.orientation, cm.angular_velocity,
                make_header(res.stamp_ns, header.frame_id + topics.START_FRAME_SUFFIX),
                header.frame_id,
                position=cm.position if cm.translation_known else None,
                linear_velocity=cm.linear_velocity))
            self.translation_frames += int(cm.translation_known and cm.state == 'moving')
            self.motion_states[cm.state] = self.motion_states.get(cm.state, 0) + 1
            self.implausible_turns = cm.implausible_turns
            self.motion_stats.add(res.camera_motion_s)
            self.diag.set_value('camera_motion', cm.state)
        if self.pub_annotated is not None and res.annotated is not None:
            now = time.monotonic()
            if now >= self._next_annotated:
                rate = self.p['annotated_max_fps']
                self._next_annotated = now + (1.0 / rate if rate > 0 else 0.0)
                self.pub_annotated.publish(bgr_to_image(res.annotated, header))
        self.published += 1
        self.diag.latency.add(seconds)
        if res.detector_s > 0:
            self.detector_stats.add(res.detector_s)
        self.diag.output.tick()
        if not res.person_found:
            self.no_person += 1
            log.info(f'no person found ({res.name}); publishing all confidences 0',
                     throttle_duration_sec=2.0)

    def on_bone_lengths(self, msg: JointState) -> None:
        """The lifter's held skeletons (``bone_lengths_topic``): each person's signature,
        handed to the tracker before the next frame (a returning person's old id)."""
        try:
            bodies = msg_to_bodies_bone_lengths(msg)
        except MessageError as exc:
            self._problem('bone_lengths', f'ignoring bone lengths: {exc}')
            return
        self.processor.set_signatures(bodies)

    def on_floor(self, msg: TransformStamped) -> None:
        """The physics floor in the camera frame (``floor_topic``): ``p_camera = A p_floor +
        b``, so the floor's up normal is A's third column and the camera's height ``-n . b``;
        handed to the camera-motion estimate, which measures translation over it."""
        q, b = transform_stamped_to_arrays(msg)
        nq = float(np.linalg.norm(q)) if np.all(np.isfinite(q)) else 0.0
        if nq < 0.5 or not np.all(np.isfinite(b)):
            self._problem('floor', 'ignoring floor: not a finite transform')
            return
        n = quat_to_matrix(q / nq)[:, 2]
        self.floors_received += 1
        self.processor.set_floor(n, float(-n @ b), stamp_to_ns(msg.header.stamp) * 1e-9)

    @staticmethod
    def _new_detector(name: str, p):
        """A detector ``name`` with the node's settings (the main one, and the mirror
        check's second one)."""
        if name == 'blazepose_multi':
            return create_detector(
                name, max_persons=p['max_persons'],
                detection_interval=p['detection_interval'] if p['tracking'] else 1,
                max_detection_interval=3 * p['detection_interval'] if p['tracking'] else 1,
                still_detection_interval=(p['still_detection_interval'] if p['tracking']
                                          else 0),
                min_person_px=p['min_person_height_px'],
                min_detection_confidence=p['min_detection_confidence'],
                min_tracking_confidence=p['min_tracking_confidence'],
                threads=p['landmark_threads'],
                whole_frame_min_height=p['whole_frame_min_height'],
                whole_frame_leave_height=0.75 * p['whole_frame_min_height'],
                search_min_person_fraction=p['search_min_person_fraction'],
                search_where_changed=p['search_where_changed'])
        return create_detector(name, tracking=p['tracking'],
                               min_detection_confidence=p['min_detection_confidence'],
                               min_tracking_confidence=p['min_tracking_confidence'])

    def _has_images(self, check: str) -> bool:
        """Whether the source gives images for ``check`` (a parameter name); the OpenPose
        source does not: warned once, False."""
        if self.kind != 'openpose_json':
            return True
        self.get_logger().warn(f'{check} needs images; the OpenPose source has none')
        return False

    def _mirror_check(self, p) -> Optional[MirrorCheck]:
        """The mirror check when ``mirror_check`` is on and the source has images."""
        self.mirror_status = 'off (mirror_check false)'
        if not p['mirror_check']:
            return None
        if not self._has_images('mirror_check'):
            self.mirror_status = 'off (no images: OpenPose source)'
            return None
        self.mirror_status = 'on'
        self.get_logger().info('mirror check on: a second detector reads the mirrored frames')
        return MirrorCheck(self._make_detector,
                           MirrorCheckParams(min_width=p['mirror_min_width'],
                                             only_when_needed=p['mirror_only_when_needed']))

    def _facing_check(self, p) -> Optional[FacingCheck]:
        """The facing check when ``facing_check`` is on and the weights load; otherwise
        None (an unreadable weights file is logged and the node runs without the check)."""
        self.facing_status = 'off (facing_check false)'
        if not p['facing_check']:
            return None
        if not self._has_images('facing_check'):
            self.facing_status = 'off (no images: OpenPose source)'
            return None
        try:
            clf = FacingClassifier(p['facing_weights'] or None)
        except (WeightsError, ImportError) as exc:
            self.facing_status = f'off (weights not usable: {exc})'
            self.get_logger().error(f'facing_check is off: {exc}')
            return None
        self.facing_status = f'on ({clf.path.name})'
        self.get_logger().info(f'facing check on: {clf.path}')
        return FacingCheck(clf, FacingCheckParams(
            min_width=p['facing_min_width'], max_probability=p['facing_max_probability'],
            window=p['facing_window']))

    def _refresh_diagnostics(self) -> None:
        s = self.detector_stats.summary()
        for key, v in (('detector_ms_median', s['median']), ('detector_ms_p95', s['p95'])):
            self.diag.set_value(key, 'nan' if np.isnan(v) else f'{v * 1e3:.2f}')
        self.diag.set_value('frames_without_person', self.no_person)
        ts = self.tracker.stats
        self.diag.set_value('person_ids', ' '.join(str(i) for i in self.tracker.ids) or 'none')
        self.diag.set_value('ids_given', ts.births)
        self.diag.set_value('ids_lost', ts.deaths)
        self.diag.set_value('reidentified', ts.reidentified)
        self.diag.set_value('renamed_by_bone_lengths', ts.renamed)
        self.diag.set_value('false_detections_ignored', ts.blips)
        self.diag.set_value('persons_ignored', ts.ignored)
        det = self.detector
        if det is not None and hasattr(det, 'fine_searches'):
            self.diag.set_value('searches', f'{det.detections} ({det.fine_searches} in the finer '
                                f'squares, {det.found_in_fine} people found there; '
                                f'{det.guided_searches} where the picture changed, '
                                f'{det.found_guided} found there), '
                                f'{det.searches_skipped} skipped in a still picture')
        self.diag.set_value('facing_check', self.facing_status)
        self.diag.set_value('mirror_check', self.mirror_status)
        mc = self.processor.mirror
        if mc is not None:
            ms = mc.stats
            self.diag.set_value('mirror_exchanged', f'{ms.exchanged} of {ms.candidates} persons '
                                f'labelled as facing the camera ({ms.matched} found in the '
                                'mirrored frame)')
            self.diag.set_value('mirror_frames_read', f'{ms.read} of {ms.frames}')
            m = ms.times.summary()['median'] * 1e3
            self.diag.set_value('mirror_detector_ms_median', 'nan' if np.isnan(m) else f'{m:.2f}')
            self.diag.set_value('mirror_failures', self.processor.mirror_failures)
        fc = self.processor.facing
        if fc is not None:
            fs = fc.stats
            self.diag.set_value('facing_exchanged', f'{fs.exchanged} of {fs.scored} persons '
                                'scored' + (f' ({fs.persons - fs.scored} too small or hidden)'
                                            if fs.persons > fs.scored else ''))
            m = fs.times.summary()['median'] * 1e3
            self.diag.set_value('facing_ms_median', 'nan' if np.isnan(m) else f'{m:.2f}')
            self.diag.set_value('facing_failures', self.processor.facing_failures)
        if self.pub_motion is not None:
            m = self.motion_stats.summary()['median']
            self.diag.set_value('camera_motion_ms_median', 'nan' if np.isnan(m) else
                                f'{m * 1e3:.2f}')
            self.diag.set_value('camera_motion_frames', ', '.join(
                f'{k} {v}' for k, v in sorted(self.motion_states.items())) or 'none yet')
            self.diag.set_value('camera_motion_failures', self.processor.camera_motion_failures)
            self.diag.set_value('camera_turns_refused', self.implausible_turns)
            self.diag.set_value('camera_translation', (
                f'measured over the floor in {self.translation_frames} moving frames'
                if self.floors_received else
                'rotation only (no floor received yet)' if self.p['floor_topic'] else
                'rotation only (floor_topic empty)'))
        self._count_worker_drops()
        if time.monotonic() - self._last_error_t < 5.0:
            self.diag.warn(self._last_error)
        elif self.intrinsics_approx:
            self.diag.warn('intrinsics approximated from the image size and field of view '
                           '(no calibration)')
        else:
            self.diag.warn(None)

    @property
    def done(self) -> bool:
        return (self.source_end is not None and self.worker.idle and not self.results)

    def summary(self) -> str:
        self._count_worker_drops()
        return (f'{self.published} frames published, {self.diag.dropped} '
                f'dropped, {self.diag.errors} skipped, {self.no_person} without a person')

    def shutdown(self) -> None:
        if self.feeder is not None:
            self.feeder.stop(2.0)
        self.worker.stop(5.0)
        if self.source is not None:
            self.source.close()
        if self.detector is not None:
            if self.worker.running:
                # a detection still in progress: closing the models under it could block;
                # the process ends without (the detector thread is a daemon)
                print('[keypoints] the detector did not stop within 5 s; not closing it',
                      file=sys.stderr)
            elif not _within(self.detector.close, 5.0):
                print('[keypoints] closing the detector took more than 5 s; going on',
                      file=sys.stderr)
            elif self.processor.mirror is not None and not _within(
                    self.processor.mirror.close, 5.0):
                print('[keypoints] closing the mirror check\'s detector took more than 5 s; '
                      'going on', file=sys.stderr)
        if self._annotated_node is not None:
            context = self._annotated_node.context
            self._annotated_node.destroy_node()
            context.try_shutdown()
        if self._opencv_threads_before is not None:
            import cv2
            cv2.setNumThreads(self._opencv_threads_before)
            self._opencv_threads_before = None


if __name__ == '__main__':
    sys.exit(main())
