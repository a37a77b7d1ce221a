"""Which camera intrinsics belong to a frame (no ROS imports).

Order of preference:
  1. a calibration YAML file (parameter ``calibration_file``, the standard camera_info YAML),
     when the user gives one;
  2. the latest ``sensor_msgs/CameraInfo`` of the camera (image-topic source);
  3. an approximation from the image size and a horizontal field of view (logged as such).

A calibration made at another resolution with the same aspect ratio (within 1 %) is scaled to
the image; one with another aspect ratio does not fit the image and the approximation is used
instead, with a warning. Keypoints of a camera with lens distortion are undistorted to the
ideal pinhole image of the same ``K`` (:func:`undistort_keypoints`), so the published
CameraInfo (``K``, zero distortion) describes them exactly.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import List, Optional, Tuple

import numpy as np

from mocap_core.camera import CameraCalibration, CameraIntrinsics, scale_intrinsics

ASPECT_TOLERANCE = 0.01


@dataclass(frozen=True)
class FrameIntrinsics:
    """Intrinsics for one image size, with where they came from."""

    intrinsics: CameraIntrinsics
    source: str               # 'calibration_file', 'camera_info', 'approximate'
    detail: str               # human-readable, for logs and /diagnostics
    distortion_model: str = ''
    distortion: tuple = ()

    @property
    def approximate(self) -> bool:
        return self.source == 'approximate'


class IntrinsicsProvider:
    """Thread-safe: ``update_camera_info`` may be called from the ROS executor while the
    detector thread calls ``for_image``. ``for_image`` returns the intrinsics and, when they
    changed since the previous call, a note to log (None otherwise)."""

    def __init__(self, calibration: Optional[CameraCalibration] = None,
                 horizontal_fov_deg: float = 60.0, calibration_label: str = '') -> None:
        self._file = calibration
        self._file_label = calibration_label
        self._info: Optional[CameraCalibration] = None
        self.fov = float(horizontal_fov_deg)
        self._lock = threading.Lock()
        self._cache: dict = {}
        self._last_key: Optional[tuple] = None

    def update_camera_info(self, calibration: CameraCalibration) -> bool:
        """A new CameraInfo; returns True when it differs from the previous one."""
        with self._lock:
            changed = self._info != calibration
            self._info = calibration
            if changed:
                self._cache.clear()
            return changed

    @property
    def has_camera_info(self) -> bool:
        return self._info is not None

    def _fit(self, calib: CameraCalibration, source: str, label: str, width: int,
             height: int) -> Tuple[Optional[FrameIntrinsics], str]:
        intr = calib.intrinsics
        if (intr.width, intr.height) == (width, height):
            return FrameIntrinsics(intr, source, f'{label} ({width}x{height})',
                                   calib.distortion_model, tuple(calib.distortion)), ''
        if abs(intr.width / intr.height - width / height) <= ASPECT_TOLERANCE * width / height:
            scaled = scale_intrinsics(intr, width, height)
            return FrameIntrinsics(scaled, source,
                                   f'{label} ({intr.width}x{intr.height}) scaled to the '
                                   f'{width}x{height} image', calib.distortion_model,
                                   tuple(calib.distortion)), ''
        return None, (f'{label} is for {intr.width}x{intr.height} images but the image is '
                      f'{width}x{height} (another aspect ratio): ignoring it')

    def for_image(self, width: int, height: int) -> Tuple[FrameIntrinsics, Optional[str]]:
        with self._lock:
            key = (width, height)
            fi = self._cache.get(key)
            if fi is None:
                problems: List[str] = []
                for calib, source, label in ((self._file, 'calibration_file',
                                              f'calibration file {self._file_label}'),
                                             (self._info, 'camera_info', 'camera_info')):
                    if calib is None:
                        continue
                    fi, problem = self._fit(calib, source, label, width, height)
                    if fi is not None:
                        break
                    problems.append(problem)
                if fi is None:
                    approx = CameraIntrinsics.from_fov(width, height, self.fov)
                    why = '; '.join(problems) if problems else 'no calibration given'
                    fi = FrameIntrinsics(
                        approx, 'approximate',
                        f'{why}: approximating intrinsics from image size {width}x{height} '
                        f'and horizontal FOV {self.fov:g} deg (fx = fy = {approx.fx:.1f} px)')
                self._cache[key] = fi
            note_key = (fi.source, fi.detail)
            note = None if note_key == self._last_key else fi.detail
            self._last_key = note_key
            return fi, note


def undistort_keypoints(keypoints: np.ndarray, fi: FrameIntrinsics) -> np.ndarray:
    """(..., 23, 3) keypoints in the raw (distorted) image -> the same in the ideal pinhole
    image of ``fi.intrinsics.K`` (confidences unchanged; unseen points stay (0, 0, 0)).

    Models: ``plumb_bob`` / ``rational_polynomial`` (OpenCV's radial-tangential model) and
    ``equidistant`` (OpenCV's fisheye model). No distortion, or another model: unchanged
    (the caller logs unknown models)."""
    kp = np.array(keypoints, dtype=np.float64)
    dist = np.asarray(fi.distortion, dtype=np.float64)
    if dist.size == 0 or not np.any(dist != 0):
        return kp
    seen = kp[..., 2] > 0
    if not np.any(seen):
        return kp
    import cv2

    K = fi.intrinsics.K
    pts = kp[..., :2][seen].reshape(-1, 1, 2)
    model = fi.distortion_model
    if model in ('plumb_bob', 'rational_polynomial', ''):
        und = cv2.undistortPoints(pts, K, dist, P=K)
    elif model in ('equidistant', 'fisheye') and dist.size >= 4:
        und = cv2.fisheye.undistortPoints(pts, K, dist[:4], P=K)
    else:
        return kp
    kp[..., :2][seen] = und.reshape(-1, 2)
    return kp


def distortion_supported(model: str) -> bool:
    return model in ('plumb_bob', 'rational_polynomial', 'equidistant', 'fisheye', '')
