"""2D keypoint detectors behind one small interface (no ROS imports).

A :class:`Detector` takes one BGR image and returns (P, 23, 3) keypoints in the layout of
:data:`mocap_core.skeleton.KEYPOINT_NAMES`: pixel ``u, v`` (origin top-left) and a confidence
in [0, 1], 0 for a point the detector does not provide or did not see. P = 0 when nobody was
found. Add a detector by implementing the protocol and registering it in :data:`DETECTORS`.

:class:`BlazePoseDetector` wraps MediaPipe BlazePose *full* (``mediapipe==0.10.14``, legacy
``mediapipe.solutions.pose`` API, model files bundled in the wheel; only model complexity 1
is bundled, the others would be downloaded). One person per image. Its 33 landmarks map to the
layout with :data:`~mocap_core.skeleton.BLAZEPOSE_TO_LAYOUT` (``foot_index`` -> big toe; no
small toe: confidence 0); the confidence of a landmark is ``visibility x presence`` where the
model reports presence, else ``visibility`` (the legacy API reports visibility only).
"""

from __future__ import annotations

import os
import warnings
from typing import Dict, Protocol, runtime_checkable

import numpy as np

from mocap_core.skeleton import NUM_KEYPOINTS

from .blazepose import NUM_BLAZEPOSE_LANDMARKS, blazepose_to_layout  # noqa: F401 (re-export)
from .sources import check_image


@runtime_checkable
class Detector(Protocol):
    """What the node needs from a 2D keypoint detector."""

    #: Short identifier, reported on /diagnostics (e.g. ``mediapipe_blazepose_full``).
    name: str

    def detect(self, image: np.ndarray) -> np.ndarray:
        """(H, W, 3) uint8 BGR image -> (P, 23, 3) float64 (u px, v px, confidence)."""

    def reset(self) -> None:
        """Forget any tracking state (the next image is unrelated to the previous one)."""

    def close(self) -> None:
        """Release the model."""


class BlazePoseDetector:
    """MediaPipe BlazePose full (see the module docstring).

    Args:
        tracking: video mode: after the first detection, landmarks of the previous frame
            seed the next (faster, temporally smooth); False runs the person detector on every
            image (unrelated images; ~50 % slower).
        min_detection_confidence, min_tracking_confidence: MediaPipe's thresholds.
        smooth_landmarks: MediaPipe's landmark filter across frames (tracking mode only).
        model_complexity: must be 1 (BlazePose full, the model bundled in mediapipe 0.10.14).
    """

    name = 'mediapipe_blazepose_full'

    def __init__(self, tracking: bool = True, min_detection_confidence: float = 0.5,
                 min_tracking_confidence: float = 0.5, smooth_landmarks: bool = True,
                 model_complexity: int = 1) -> None:
        if model_complexity != 1:
            raise ValueError(f'model_complexity {model_complexity} is not available offline: '
                             'mediapipe 0.10.14 bundles only BlazePose full (complexity 1)')
        for label, v in (('min_detection_confidence', min_detection_confidence),
                         ('min_tracking_confidence', min_tracking_confidence)):
            if not 0.0 <= v <= 1.0:
                raise ValueError(f'{label} must be in [0, 1], got {v}')
        os.environ.setdefault('GLOG_minloglevel', '2')  # quieter MediaPipe start-up
        import cv2
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            from mediapipe.python.solutions import pose as mp_pose
        self._cv2 = cv2
        self._mp_pose = mp_pose
        self._kwargs = dict(static_image_mode=not tracking, model_complexity=1,
                            smooth_landmarks=smooth_landmarks, enable_segmentation=False,
                            min_detection_confidence=float(min_detection_confidence),
                            min_tracking_confidence=float(min_tracking_confidence))
        self.tracking = tracking
        self._pose = self._mp_pose.Pose(**self._kwargs)

    def detect(self, image: np.ndarray) -> np.ndarray:
        img = check_image(image, 'image')
        if self._pose is None:
            raise RuntimeError('detector is closed')
        rgb = self._cv2.cvtColor(img, self._cv2.COLOR_BGR2RGB)
        with warnings.catch_warnings():
            # protobuf's GetPrototype deprecation warning, raised inside MediaPipe per call
            warnings.simplefilter('ignore', UserWarning)
            result = self._pose.process(rgb)
        if result.pose_landmarks is None:
            return np.zeros((0, NUM_KEYPOINTS, 3))
        lm = np.array([[p.x, p.y, p.visibility if p.HasField('visibility') else np.nan,
                        p.presence if p.HasField('presence') else np.nan]
                       for p in result.pose_landmarks.landmark], dtype=np.float64)
        if np.all(np.isnan(lm[:, 2])):  # no visibility at all: rely on presence / detection
            lm[:, 2] = 1.0
        h, w = img.shape[:2]
        return blazepose_to_layout(lm, w, h)[None]

    def reset(self) -> None:
        if self._pose is not None:
            self._pose.reset()

    def close(self) -> None:
        if self._pose is not None:
            self._pose.close()
            self._pose = None

    def __enter__(self) -> 'BlazePoseDetector':
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _multi(**kwargs):
    from .multipose import BlazePoseMultiDetector
    return BlazePoseMultiDetector(**kwargs)


_multi.name = 'mediapipe_blazepose_full_multi'

#: Detector name (parameter ``detector``) -> class (or factory).
DETECTORS: Dict[str, object] = {'blazepose': BlazePoseDetector, 'blazepose_multi': _multi}


def create_detector(name: str = 'blazepose', **kwargs) -> Detector:
    """Instantiate a registered detector; raises ValueError for an unknown name."""
    try:
        cls = DETECTORS[name]
    except KeyError:
        raise ValueError(f'unknown detector {name!r}; available: {", ".join(DETECTORS)}') \
            from None
    return cls(**kwargs)


def detector_names() -> Dict[str, str]:
    """{parameter value: reported name} of every registered detector."""
    return {k: getattr(v, 'name', k) for k, v in DETECTORS.items()}

