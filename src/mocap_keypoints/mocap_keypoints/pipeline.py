"""One frame in, keypoints and intrinsics out (no ROS imports): the work the node's detector
thread does for every frame.

:class:`FrameProcessor` turns a :class:`~mocap_keypoints.sources.Frame` into a
:class:`FrameResult`: decode the image if needed, run the detector (or take the OpenPose
detections), give the persons their identities with a
:class:`~mocap_core.tracking.PersonTracker` (rows ordered longest tracked first, at most
``max_persons``; a frame without anybody gives one all-zero row with id 0, so its cloud's
confidences are all 0) or, without a tracker, keep the ``max_persons`` most confident
persons (padding with all-zero persons), check the persons' left and right labels against a
second detector's reading of the mirrored frame (``mirror``, :mod:`mocap_keypoints.mirror_check`)
and against which way they face (``facing``, :mod:`mocap_keypoints.facing`; both off unless
given), pick the intrinsics for the image size, undistort the keypoints when the calibration
has lens distortion, estimate the camera's motion from the image background (``camera_motion``,
:mod:`mocap_core.camera_motion`) and draw the annotated debug image if asked.
"""

from __future__ import annotations

import collections
import time
from dataclasses import dataclass, field
from typing import Deque, List, Optional, Sequence, Tuple

import numpy as np

from mocap_core.skeleton import KEYPOINT_EDGES, KEYPOINT_NAMES, NUM_KEYPOINTS
from mocap_core.camera_motion import (CameraMotionEstimate, CameraMotionEstimator,
                                      CameraMotionParams)
from mocap_core.streams import StampOrder
from mocap_core.tracking import PersonTracker

from .detector import Detector
from .facing import FacingCheck
from .mirror_check import MirrorCheck
from .intrinsics import FrameIntrinsics, IntrinsicsProvider, distortion_supported, \
    undistort_keypoints
from .sources import Frame, check_image


def select_persons(people: np.ndarray, max_persons: int) -> np.ndarray:
    """(P, 23, 3) -> (max_persons, 23, 3): the most confident persons first, padded with
    all-zero (not seen) persons."""
    out = np.zeros((max_persons, NUM_KEYPOINTS, 3))
    if len(people):
        order = np.argsort(-people[..., 2].sum(axis=-1), kind='stable')[:max_persons]
        out[:len(order)] = people[order]
    return out


_LEFT = (255, 160, 0)    # BGR: left side blue-ish
_RIGHT = (0, 140, 255)   # right side orange
_CENTRE = (0, 220, 0)


def _side_colour(a: int, b: int) -> Tuple[int, int, int]:
    na, nb = KEYPOINT_NAMES[a], KEYPOINT_NAMES[b]
    if na.startswith('left_') and nb.startswith('left_'):
        return _LEFT
    if na.startswith('right_') and nb.startswith('right_'):
        return _RIGHT
    return _CENTRE


def draw_keypoints(image: np.ndarray, keypoints: np.ndarray, threshold: float = 0.5,
                   text: str = '', ids: Optional[np.ndarray] = None) -> np.ndarray:
    """A copy of ``image`` with the skeletons of (P, 23, 3) ``keypoints`` drawn over it: bones
    between points with confidence >= ``threshold`` (left blue, right orange), points as
    dots whose size grows with confidence, ``text`` in the top-left corner and, with ``ids``
    (P,), each person's id above its highest point (id 0 rows are not labelled)."""
    import cv2

    out = np.array(image, copy=True)
    scale = max(1.0, max(out.shape[:2]) / 640.0)
    thick = max(1, int(round(2 * scale)))
    people = np.asarray(keypoints).reshape(-1, NUM_KEYPOINTS, 3)
    for r, person in enumerate(people):
        ok = person[:, 2] >= threshold
        if ids is not None and ids[r] > 0 and np.any(ok):
            top = int(np.argmin(np.where(ok, person[:, 1], np.inf)))
            cv2.putText(out, f'id {int(ids[r])}', (int(person[top, 0]) - int(15 * scale),
                                                   int(person[top, 1] - 12 * scale)),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.6 * scale, (0, 255, 255), thick,
                        cv2.LINE_AA)
        for a, b in KEYPOINT_EDGES:
            if ok[a] and ok[b]:
                cv2.line(out, (int(round(person[a, 0])), int(round(person[a, 1]))),
                         (int(round(person[b, 0])), int(round(person[b, 1]))),
                         _side_colour(a, b), thick, cv2.LINE_AA)
        for k in np.flatnonzero(ok):
            cv2.circle(out, (int(round(person[k, 0])), int(round(person[k, 1]))),
                       int(round((2 + 2 * person[k, 2]) * scale)), (255, 255, 255), -1,
                       cv2.LINE_AA)
    if text:
        cv2.putText(out, text, (int(8 * scale), int(20 * scale)), cv2.FONT_HERSHEY_SIMPLEX,
                    0.5 * scale, (255, 255, 255), thick, cv2.LINE_AA)
    return out


@dataclass
class FrameResult:
    """What the node publishes for one frame (``error`` set: nothing to publish)."""

    stamp_ns: int
    index: int
    name: str
    frame_id: str = ''
    keypoints: Optional[np.ndarray] = None          # (P, 23, 3), P <= max_persons
    ids: Optional[np.ndarray] = None                # (P,) person ids (with a tracker)
    intrinsics: Optional[FrameIntrinsics] = None
    image_size: Tuple[int, int] = (0, 0)            # width, height
    detector_s: float = 0.0
    annotated: Optional[np.ndarray] = None
    camera_motion: Optional[CameraMotionEstimate] = None   # image frames, when enabled
    camera_motion_s: float = 0.0
    error: Optional[str] = None
    notes: List[str] = field(default_factory=list)  # to log (intrinsics changes, ...)
    #: (new id, old id): persons who took an old id back by their bone lengths this frame
    renamed: List[Tuple[int, int]] = field(default_factory=list)
    #: (P,) rows whose left and right the facing check exchanged (None: not checked)
    exchanged: Optional[np.ndarray] = None

    @property
    def person_found(self) -> bool:
        return self.keypoints is not None and bool(np.any(self.keypoints[..., 2] > 0))


@dataclass
class Detected:
    """A frame between :meth:`FrameProcessor.detect` and :meth:`FrameProcessor.finish`: the
    result so far, the decoded image (None: no image, or the frame failed), the persons as
    detected and labelled, before undistortion ((P, 23, 3), pixels) and whether the frame
    started a new stream."""

    result: FrameResult
    image: Optional[np.ndarray] = None
    raw: Optional[np.ndarray] = None
    restart: bool = False


class FrameProcessor:
    """See the module docstring. ``detector`` may be None for sources that bring their own
    keypoints (OpenPose); ``fixed_size`` is then the image size for the intrinsics."""

    def __init__(self, detector: Optional[Detector], intrinsics: IntrinsicsProvider,
                 max_persons: int = 1, undistort: bool = True, annotate: bool = False,
                 fixed_size: Optional[Tuple[int, int]] = None,
                 restart_after_s: float = 1.0,
                 camera_motion: Optional[CameraMotionParams] = None,
                 tracker: Optional[PersonTracker] = None, appearance: bool = True,
                 facing: Optional[FacingCheck] = None,
                 mirror: Optional[MirrorCheck] = None) -> None:
        self.detector = detector
        #: the left/right label check by a second detector on the mirrored frames
        self.mirror = mirror
        #: frames whose mirror check failed (an exception; the frame goes on unchecked)
        self.mirror_failures = 0
        #: the left/right label check by the person's facing (mocap_keypoints.facing)
        self.facing = facing
        #: frames whose facing check failed (an exception; the frame goes on unchecked)
        self.facing_failures = 0
        self.tracker = tracker
        #: the tracker also sees the image (people's clothes; mocap_core.tracking)
        self.appearance = appearance
        # stamps jumping back start a new stream: the detector forgets the person it tracked
        self.order = StampOrder(restart_after_s)
        self.intrinsics = intrinsics
        self.max_persons = int(max_persons)
        self.undistort = undistort
        self.annotate = annotate
        self.fixed_size = fixed_size
        self._warned_models: set = set()
        self._last_size: Optional[Tuple[int, int]] = None
        self.camera_motion_params = camera_motion
        self._motion: Optional[CameraMotionEstimator] = None
        self._motion_K: Optional[np.ndarray] = None
        #: frames whose camera-motion estimate failed (an exception; the frame is published)
        self.camera_motion_failures = 0
        self._floor: Optional[Tuple[np.ndarray, float, float]] = None
        self._floor_pending = False
        self._signatures: Deque[List[Tuple[int, np.ndarray]]] = collections.deque()

    def set_signatures(self, bodies: Sequence[Tuple[int, np.ndarray]]) -> None:
        """The 3D stages' signatures of the persons followed (``(id, (G,) bone-group
        lengths, m)``, the lifter's held skeletons), for the tracker to name a person who
        came back (:meth:`PersonTracker.set_signature`). Safe to call from another thread:
        applied before the next frame."""
        self._signatures.append([(int(i), np.asarray(x, dtype=np.float64)) for i, x in bodies])

    def _apply_signatures(self, res: FrameResult) -> None:
        while self._signatures:
            for pid, lengths in self._signatures.popleft():
                old = self.tracker.set_signature(pid, lengths)
                if old is not None:
                    res.renamed.append((pid, old))

    def set_floor(self, normal: np.ndarray, height: float, stamp_s: float) -> None:
        """The floor in the camera frame of the image stamped ``stamp_s`` (its up normal
        (3,) and the camera's height above it, m), e.g. from the physics stage: the camera's
        translation is then measured over it (:meth:`CameraMotionEstimator.set_floor`).
        Safe to call from another thread: it is applied before the next frame."""
        self._floor = (np.array(normal, dtype=np.float64), float(height), float(stamp_s))
        self._floor_pending = True

    def _estimate_camera_motion(self, res: FrameResult, image: np.ndarray,
                                keypoints: np.ndarray, restart: bool) -> None:
        """The camera's motion into this frame (:mod:`mocap_core.camera_motion`); a new
        estimator when the intrinsics change or the stream restarts. A failure is noted and
        counted, and the frame goes on without an estimate."""
        i = res.intrinsics.intrinsics
        K = np.array([[i.fx, 0.0, i.cx], [0.0, i.fy, i.cy], [0.0, 0.0, 1.0]])
        new = self._motion is None or restart or not np.array_equal(K, self._motion_K)
        if new:
            self._motion = CameraMotionEstimator(K, self.camera_motion_params)
            self._motion_K = K
        floor = self._floor
        if floor is not None and (new or self._floor_pending):
            self._floor_pending = False
            if not self._motion.set_floor(*floor):
                res.notes.append(f'ignoring a floor that is not plausible (camera height '
                                 f'{floor[1]:.2f} m)')
        t0 = time.perf_counter()
        try:
            res.camera_motion = self._motion.update(image, res.stamp_ns * 1e-9, keypoints)
        except Exception as exc:  # noqa: BLE001 - an estimate is optional; the frame is not
            self.camera_motion_failures += 1
            self._motion = None
            res.notes.append(f'camera motion estimate failed ({type(exc).__name__}: {exc}); '
                             'starting it again')
        res.camera_motion_s = time.perf_counter() - t0

    def process(self, frame: Frame) -> FrameResult:
        """The whole frame in the calling thread: :meth:`finish` of :meth:`detect`."""
        return self.finish(self.detect(frame))

    def detect(self, frame: Frame) -> Detected:
        """The first part of a frame's work: decode, detect, track, check the labels, pick
        the intrinsics and undistort. Calls must come in the frames' order, and each result
        must go through :meth:`finish`, in the same order (possibly in another thread, while
        the next frame is detected: the two parts share no state)."""
        res = FrameResult(frame.stamp_ns, frame.index, frame.name, frame.frame_id)
        restart = self.order.check(frame.stamp_ns) == 'restart'
        if restart and self.detector is not None:
            self.detector.reset()
        if restart and self.tracker is not None:
            self.tracker.reset()
        if frame.error is not None:
            res.error = frame.error
            return Detected(res)
        image = None
        if frame.keypoints is not None:
            people = np.asarray(frame.keypoints, dtype=np.float64).reshape(-1, NUM_KEYPOINTS, 3)
            if self.fixed_size is None:
                res.error = f'{frame.name}: no image size known for OpenPose keypoints'
                return Detected(res)
            width, height = self.fixed_size
        else:
            try:
                image = frame.decode() if frame.image is None and frame.decode else frame.image
                image = check_image(image, frame.name or f'frame {frame.index}')
            except ValueError as exc:
                res.error = str(exc)
                return Detected(res)
            height, width = image.shape[:2]
            if self.detector is None:
                res.error = 'no detector configured for image frames'
                return Detected(res)
            t0 = time.perf_counter()
            people = self.detector.detect(image)
            res.detector_s = time.perf_counter() - t0
        size = (int(width), int(height))
        if self._last_size is not None and size != self._last_size:
            res.notes.append(f'{frame.name}: image size changed from '
                             f'{self._last_size[0]}x{self._last_size[1]} to {width}x{height}')
        self._last_size = size
        res.image_size = size
        fi, note = self.intrinsics.for_image(*size)
        if note:
            res.notes.append(f'intrinsics: {note}')
        res.intrinsics = fi
        if self.tracker is not None:
            self._apply_signatures(res)
            tracked = self.tracker.update(
                people, frame.stamp_ns * 1e-9,
                image=image if self.appearance else None)[:self.max_persons]
            if tracked:
                raw = np.stack([t.keypoints for t in tracked])
                res.ids = np.array([t.id for t in tracked], dtype=np.int64)
            else:
                raw = np.zeros((1, NUM_KEYPOINTS, 3))
                res.ids = np.zeros(1, dtype=np.int64)
        else:
            raw = select_persons(people, self.max_persons)
        if self.mirror is not None and image is not None:
            if restart:
                self.mirror.reset()
            try:
                raw, ex = self.mirror.apply(image, raw)
                res.exchanged = ex if res.exchanged is None else res.exchanged | ex
            except Exception as exc:  # noqa: BLE001 - the check is optional; the frame is not
                self.mirror_failures += 1
                res.notes.append(f'mirror check failed ({type(exc).__name__}: {exc}); the '
                                 'frame goes on unchecked')
        if self.facing is not None and image is not None:
            if restart:
                self.facing.reset()
            try:
                raw, ex = self.facing.apply(image, raw, res.ids, frame.stamp_ns * 1e-9)
                res.exchanged = ex if res.exchanged is None else res.exchanged | ex
            except Exception as exc:  # noqa: BLE001 - the check is optional; the frame is not
                self.facing_failures += 1
                res.notes.append(f'facing check failed ({type(exc).__name__}: {exc}); the '
                                 'frame goes on unchecked')
        kp = raw
        if self.undistort and fi.distortion and any(d != 0 for d in fi.distortion):
            if distortion_supported(fi.distortion_model):
                kp = undistort_keypoints(raw, fi)
            elif fi.distortion_model not in self._warned_models:
                self._warned_models.add(fi.distortion_model)
                res.notes.append(f'distortion model {fi.distortion_model!r} is not supported: '
                                 'keypoints are published without undistortion')
        res.keypoints = kp
        return Detected(res, image, raw, restart)

    @property
    def has_finish_work(self) -> bool:
        """Whether :meth:`finish` does anything worth a thread of its own (the camera-motion
        estimate or the annotated image)."""
        return self.camera_motion_params is not None or self.annotate

    def finish(self, detected: Detected) -> FrameResult:
        """The second part: the camera's motion from the image background (it needs the
        frame's persons, to leave them out) and the annotated image. Returns the result."""
        res, image, raw = detected.result, detected.image, detected.raw
        if res.error is not None or image is None or raw is None:
            return res
        if self.camera_motion_params is not None:
            self._estimate_camera_motion(res, image, raw, detected.restart)
        if self.annotate:
            seen = int(np.sum(raw[0, :, 2] > 0.5)) if len(raw) else 0
            res.annotated = draw_keypoints(
                image, raw, text=f'{res.name}  {seen}/{NUM_KEYPOINTS} points > 0.5  '
                                 f'{res.detector_s * 1e3:.0f} ms', ids=res.ids)
        return res
