"""The camera intrinsics a keypoint stream is lifted with, fixed once per stream (no ROS
imports).

Pixel coordinates: origin top-left, u right, v down (:mod:`mocap_core.camera`); keypoints
(23, 3): u, v, confidence (0 = unseen).

Sources, in order of preference (:attr:`StreamIntrinsics.source`):

1. ``camera_info``: a calibrated camera (valid K);
2. ``image size``: a camera_info without calibration (K all zero, the CameraInfo convention)
   still gives the image size W x H: ``CameraIntrinsics.from_fov(W, H, fov)`` (square pixels,
   principal point ((W - 1) / 2, (H - 1) / 2), ``fx = W / (2 tan(fov / 2))``);
3. ``keypoints``: an estimate from the keypoint extent. Per frame with a person the extent is
   (max u, max v) over its seen keypoints; over the first ``warmup_frames`` such frames the
   ``percentile`` of each is taken and the image is the first of
   :data:`COMMON_IMAGE_SIZES` that contains it (up to :data:`EDGE_TOLERANCE`), with the field of
   view ``fov`` as in 2.

The keypoint estimate is frozen at the end of the warm-up (or at :meth:`StreamIntrinsics.freeze`,
e.g. the end of the input) and kept until the stream restarts
(:meth:`StreamIntrinsics.restart`); camera info replaces it whenever it arrives.
"""

from __future__ import annotations

import math
from typing import List, Optional, Tuple

import numpy as np

from mocap_core.camera import CameraIntrinsics

#: Image sizes (width, height) the keypoint estimate rounds up to, in the order tried (those
#: of :func:`mocap_core.data.openpose.infer_image_size`; portrait 1080 x 1920 only when the
#: keypoints reach below 1080 px but not right of 1080 px).
COMMON_IMAGE_SIZES: Tuple[Tuple[int, int], ...] = (
    (640, 480), (1280, 720), (1920, 1080), (1080, 1920), (3840, 2160))

#: Keypoints this far beyond the image border (relative) still count as inside it.
EDGE_TOLERANCE = 1.02


def keypoint_extent(keypoints: np.ndarray) -> Optional[Tuple[float, float]]:
    """(max u, max v) in pixels of the seen (confidence > 0, finite) keypoints of one frame
    ((23, 3)), or None when none is seen."""
    kp = np.asarray(keypoints, dtype=np.float64)
    seen = (kp[:, 2] > 0) & np.isfinite(kp[:, 0]) & np.isfinite(kp[:, 1])
    if not seen.any():
        return None
    return float(kp[seen, 0].max()), float(kp[seen, 1].max())


def common_image_size(max_u: float, max_v: float) -> Tuple[int, int]:
    """The first of :data:`COMMON_IMAGE_SIZES` whose width and height (times
    :data:`EDGE_TOLERANCE`) reach ``max_u`` and ``max_v`` pixels; beyond the last, the
    smallest integer multiple of it that does."""
    for w, h in COMMON_IMAGE_SIZES:
        if max_u <= w * EDGE_TOLERANCE and max_v <= h * EDGE_TOLERANCE:
            return w, h
    w, h = COMMON_IMAGE_SIZES[-1]
    k = math.ceil(max(max_u / (w * EDGE_TOLERANCE), max_v / (h * EDGE_TOLERANCE)))
    return w * k, h * k


class StreamIntrinsics:
    """The intrinsics in use for one keypoint stream (module docstring).

    Args:
        horizontal_fov_deg: field of view of the approximate intrinsics, degrees.
        warmup_frames: frames with a person the keypoint estimate is taken over.
        percentile: percentile of the per-frame extents used (robust to a few stray
            keypoints).
    """

    def __init__(self, horizontal_fov_deg: float = 60.0, warmup_frames: int = 10,
                 percentile: float = 90.0) -> None:
        if not 1.0 < horizontal_fov_deg < 179.0:
            raise ValueError('horizontal field of view must be in (1, 179) degrees, '
                             f'got {horizontal_fov_deg}')
        if warmup_frames < 1:
            raise ValueError(f'warmup_frames must be >= 1, got {warmup_frames}')
        self.fov = float(horizontal_fov_deg)
        self.warmup_frames = int(warmup_frames)
        self.percentile = float(percentile)
        self.calibrated: Optional[CameraIntrinsics] = None
        self._from_size: Optional[CameraIntrinsics] = None
        self._estimate: Optional[CameraIntrinsics] = None
        self._extents: List[Tuple[float, float]] = []

    def set_camera_info(self, intrinsics: CameraIntrinsics) -> None:
        """A calibrated camera_info: its intrinsics are used from now on."""
        self.calibrated = intrinsics

    def set_image_size(self, width: int, height: int) -> None:
        """The image size from a camera_info without calibration (used while no calibrated
        one has arrived)."""
        if width <= 0 or height <= 0:
            raise ValueError(f'image size must be positive, got {width}x{height}')
        if self._from_size is None or (self._from_size.width, self._from_size.height) != \
                (width, height):
            self._from_size = CameraIntrinsics.from_fov(int(width), int(height), self.fov)

    def observe(self, keypoints: np.ndarray) -> None:
        """A frame with a person ((23, 3) pixels + confidence): its extent counts towards the
        keypoint estimate until that is frozen (at ``warmup_frames`` frames)."""
        if self._estimate is not None or self.calibrated is not None or \
                self._from_size is not None:
            return
        extent = keypoint_extent(keypoints)
        if extent is None:
            return
        self._extents.append(extent)
        if len(self._extents) >= self.warmup_frames:
            self.freeze()

    def freeze(self) -> bool:
        """Fix the keypoint estimate from the frames observed so far (if any); returns
        whether intrinsics are known now."""
        if self._estimate is None and self._extents:
            ext = np.asarray(self._extents)
            u, v = np.percentile(ext, self.percentile, axis=0)
            w, h = common_image_size(float(u), float(v))
            self._estimate = CameraIntrinsics.from_fov(w, h, self.fov)
        return self.current is not None

    def restart(self) -> None:
        """A new stream: forget the keypoint estimate (camera info is kept)."""
        self._estimate = None
        self._extents = []

    @property
    def current(self) -> Optional[CameraIntrinsics]:
        """The intrinsics in use, or None while the keypoint estimate is still collecting."""
        return self.calibrated or self._from_size or self._estimate

    @property
    def source(self) -> str:
        """'camera_info', 'image size', 'keypoints', or '' (none yet)."""
        if self.calibrated is not None:
            return 'camera_info'
        if self._from_size is not None:
            return 'image size'
        return 'keypoints' if self._estimate is not None else ''

    def describe(self) -> str:
        """One line for diagnostics: which intrinsics are in use."""
        intr, source = self.current, self.source
        if intr is None:
            return (f'estimating from keypoints ({len(self._extents)}/{self.warmup_frames} '
                    'frames)')
        if source == 'camera_info':
            return 'camera_info'
        origin = 'from the camera_info image size' if source == 'image size' else \
            'from keypoints'
        return f'approximate {intr.width}x{intr.height}, fov {self.fov:.0f} deg ({origin})'
