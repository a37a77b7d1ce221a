"""Which way a detected person faces, from the image, and a left/right label check built on it
(no ROS imports).

Pose detectors label a person seen from behind as if seen from the front in a good share of
frames: the legs and arms come out mirrored (left called right), and no 2D geometry can tell,
since a mirrored body seen from the front and the true body seen from behind project to the
same points. The picture can tell: a face, hair, the toes' direction. :class:`FacingNet` is a
small convolutional network that reads a 48 x 96 crop of the person (:func:`person_crop`, the
box of the detected keypoints) and gives the probability that the person's front faces the
camera. It is trained by :mod:`mocap_keypoints.training.facing` on rendered people whose
facing is known (``mocap train facing``).

:class:`FacingCheck` uses it as a label check: when the detector's labels say the person faces
the camera clearly (the left shoulder and hip right of the right ones in the image, by more
than ``min_width`` torso lengths) and the network, as the median of the person's last
``window`` frames, is sure of the opposite (probability below ``max_probability``), the
person's left and right keypoints are exchanged. The state is kept per person id.

Conventions: keypoints (23, 3) rows of (u, v, confidence) in pixels of the image given (the
23-point layout of :mod:`mocap_core.skeleton`); images H x W x 3 uint8, BGR as OpenCV reads
them (the network is trained with colour channels permuted, so RGB works as well).
"""

from __future__ import annotations

import collections
from dataclasses import dataclass, field
from pathlib import Path
from typing import Deque, Dict, Optional, Sequence, Tuple, Union

import numpy as np

from mocap_core.metrics import LatencyStats
from mocap_core.skeleton import KEYPOINT_INDEX, KEYPOINT_MIRROR, NUM_KEYPOINTS

#: Crop size the network reads: width, height (pixels).
CROP_SIZE: Tuple[int, int] = (48, 96)
#: Keypoints at or above this confidence make the person's box.
CROP_MIN_CONFIDENCE = 0.3
#: A person with fewer such keypoints gets no crop.
CROP_MIN_POINTS = 10
#: The box's height (and twice its width), times the keypoints' extent.
CROP_MARGIN = 1.2
#: Persons smaller than this (crop height, pixels) get no crop.
CROP_MIN_HEIGHT = 24.0

_LS, _RS = KEYPOINT_INDEX['left_shoulder'], KEYPOINT_INDEX['right_shoulder']
_LH, _RH = KEYPOINT_INDEX['left_hip'], KEYPOINT_INDEX['right_hip']


def person_crop(image: np.ndarray, keypoints: np.ndarray) -> Optional[np.ndarray]:
    """The person's crop for :class:`FacingNet`: (96, 48, 3) uint8, or None when too few
    keypoints are seen or the person is too small.

    The box is centred on the keypoints with confidence >= :data:`CROP_MIN_CONFIDENCE`; its
    height is :data:`CROP_MARGIN` times the larger of their vertical extent and twice their
    horizontal extent, its width half of that (the crop is scaled uniformly); outside the
    image it is black. The box is cut out at whole pixels and resized with pixel-area
    averaging when it shrinks (no aliasing, whatever the person's size in pixels), bilinear
    when it grows.
    """
    import cv2

    kp = np.asarray(keypoints, dtype=np.float64).reshape(NUM_KEYPOINTS, 3)
    ok = np.isfinite(kp).all(axis=1) & (kp[:, 2] >= CROP_MIN_CONFIDENCE)
    if int(ok.sum()) < CROP_MIN_POINTS:
        return None
    x0, y0 = kp[ok, :2].min(axis=0)
    x1, y1 = kp[ok, :2].max(axis=0)
    h = max(y1 - y0, 2.0 * (x1 - x0)) * CROP_MARGIN
    if h < CROP_MIN_HEIGHT:
        return None
    cw, ch = CROP_SIZE
    bh = max(2, int(round(h / 2.0)) * 2)          # even, so that the width is exactly half
    bw = bh // 2
    left = int(round((x0 + x1) / 2.0 - bw / 2.0))
    top = int(round((y0 + y1) / 2.0 - bh / 2.0))
    ih, iw = image.shape[:2]
    box = np.zeros((bh, bw) + image.shape[2:], dtype=image.dtype)
    sx0, sy0 = max(left, 0), max(top, 0)
    sx1, sy1 = min(left + bw, iw), min(top + bh, ih)
    if sx1 > sx0 and sy1 > sy0:
        box[sy0 - top:sy1 - top, sx0 - left:sx1 - left] = image[sy0:sy1, sx0:sx1]
    return cv2.resize(box, (cw, ch), interpolation=cv2.INTER_AREA if bh > ch
                      else cv2.INTER_LINEAR)


def signed_width(keypoints: np.ndarray) -> float:
    """How much the detector's labels say the person faces the camera: the left shoulder's
    and left hip's image u minus the right ones', over the torso's image length. Positive:
    the labels face the camera (a person's left is on the image's right when they face it);
    NaN when a shoulder or hip is missing (confidence 0 or not finite)."""
    kp = np.asarray(keypoints, dtype=np.float64).reshape(NUM_KEYPOINTS, 3)
    pts = kp[[_LS, _RS, _LH, _RH]]
    if not (np.isfinite(pts).all() and (pts[:, 2] > 0).all()):
        return float('nan')
    width = (pts[0, 0] - pts[1, 0]) + (pts[2, 0] - pts[3, 0])
    torso = float(np.linalg.norm((pts[0, :2] + pts[1, :2]) / 2 - (pts[2, :2] + pts[3, :2]) / 2))
    return float(width / torso) if torso > 1e-6 else float('nan')


def _net_class():
    import torch
    from torch import nn

    class FacingNet(nn.Module):
        """(B, 3, 96, 48) float images in [0, 1] -> (B,) logits of "the front faces the
        camera": four stride-2 convolutions (16, 32, 48, 64 channels) with batch norm, one
        more convolution, the spatial mean and a linear read-out (about 84 thousand
        weights)."""

        def __init__(self) -> None:
            super().__init__()

            def block(i: int, o: int) -> nn.Sequential:
                return nn.Sequential(nn.Conv2d(i, o, 3, 2, 1), nn.BatchNorm2d(o), nn.ReLU())

            self.features = nn.Sequential(block(3, 16), block(16, 32), block(32, 48),
                                          block(48, 64), nn.Conv2d(64, 64, 3, 1, 1),
                                          nn.ReLU())
            self.head = nn.Linear(64, 1)

        def forward(self, x: 'torch.Tensor') -> 'torch.Tensor':
            return self.head(self.features(x).mean(dim=(2, 3))).squeeze(1)

    return FacingNet


def FacingNet():  # noqa: N802 - a class made on first use (torch is imported lazily)
    """A new :class:`FacingNet` (see :func:`_net_class`); torch is imported on first use."""
    return _net_class()()


def crops_to_tensor(crops: Union[np.ndarray, Sequence[np.ndarray]]):
    """(B, 96, 48, 3) uint8 crops -> (B, 3, 96, 48) float tensor in [0, 1]."""
    import torch

    x = torch.from_numpy(np.ascontiguousarray(np.asarray(crops, dtype=np.uint8)))
    return x.permute(0, 3, 1, 2).float() / 255.0


def default_weights() -> Path:
    """The shipped weights, ``weights/facing.pt`` of the package share directory (or of the
    source tree when the package is not installed through ament)."""
    from mocap_core.checkpoint import shipped_weights

    return shipped_weights('mocap_keypoints', 'facing.pt',
                           Path(__file__).resolve().parents[1] / 'weights')


class FacingClassifier:
    """The trained network, ready to score crops (float32 on the CPU, with torch's thread
    settings of the process).

    Args:
        weights: a file written by :func:`save_weights` (default :func:`default_weights`).

    Raises:
        mocap_core.checkpoint.WeightsError: the file is missing, damaged or of another model.
    """

    def __init__(self, weights: Union[str, Path, None] = None) -> None:
        from mocap_core.checkpoint import WeightsError, load_checkpoint

        self.path = Path(weights) if weights else default_weights()
        state = load_checkpoint(self.path, required=('model', 'arch'))
        if state['arch'] != 'facing':
            raise WeightsError(f"{self.path}: weights of {state['arch']!r}, not of the facing "
                               'classifier')
        info = state.get('info', {})
        if not isinstance(info, dict):
            raise WeightsError(f'{self.path}: its info is not a mapping')
        self.info: Dict = dict(info)
        self.net = FacingNet()
        try:
            self.net.load_state_dict({k: v.float() if v.is_floating_point() else v
                                      for k, v in state['model'].items()})
        except (RuntimeError, AttributeError) as exc:
            raise WeightsError(f'{self.path}: not the facing network\'s weights '
                               f'({str(exc).splitlines()[0]})') from None
        self.net.eval()

    def probabilities(self, crops: Union[np.ndarray, Sequence[np.ndarray]]) -> np.ndarray:
        """(B, 96, 48, 3) uint8 crops -> (B,) probabilities that the person faces the
        camera."""
        import torch

        if len(crops) == 0:
            return np.zeros(0)
        with torch.no_grad():
            return torch.sigmoid(self.net(crops_to_tensor(crops))).numpy().astype(np.float64)


def save_weights(net, path: Union[str, Path], info: Optional[Dict] = None) -> None:
    """Write ``net``'s weights (floating tensors as float16) with ``arch='facing'`` and
    ``info`` (plain data: how they were trained and what they reached)."""
    import torch

    state = {k: (v.half() if v.is_floating_point() else v) for k, v in net.state_dict().items()}
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    torch.save({'arch': 'facing', 'model': state, 'info': dict(info or {})}, str(path))


@dataclass
class FacingCheckParams:
    """When :class:`FacingCheck` exchanges a person's left and right."""

    #: the detector's labels must face the camera by more than this (:func:`signed_width`)
    min_width: float = 0.25
    #: ... and the network's median probability of facing the camera be below this
    max_probability: float = 0.02
    #: frames in that median (the person's last ones, this one included)
    window: int = 9
    #: forget a person not seen for this long (s)
    forget_after_s: float = 2.0


@dataclass
class FacingStats:
    """Counts since the check started, and the time of its recent frames (diagnostics)."""

    persons: int = 0        # persons checked (frames where the check ran to the end)
    scored: int = 0         # ... with a crop the network scored
    exchanged: int = 0      # ... whose left and right were exchanged
    #: the check's time per frame with someone to score (crops and network), s
    times: LatencyStats = field(default_factory=lambda: LatencyStats(100))


class FacingCheck:
    """The left/right label check of the module docstring, over a stream of frames.

    Args:
        classifier: the network (:class:`FacingClassifier`) or any object with its
            ``probabilities`` method.
        params: thresholds and window.
    """

    def __init__(self, classifier: FacingClassifier,
                 params: Optional[FacingCheckParams] = None) -> None:
        self.classifier = classifier
        self.params = params or FacingCheckParams()
        self.stats = FacingStats()
        self._history: Dict[int, Deque[float]] = {}
        self._last_seen: Dict[int, float] = {}

    def reset(self) -> None:
        """Forget every person (a new stream)."""
        self._history.clear()
        self._last_seen.clear()

    def apply(self, image: np.ndarray, people: np.ndarray, ids: Optional[np.ndarray],
              stamp_s: float) -> Tuple[np.ndarray, np.ndarray]:
        """Check one frame.

        Args:
            image: the frame the keypoints were detected in (H, W, 3) uint8.
            people: (P, 23, 3) keypoints in that image's pixels (rows of all-zero confidence
                are nobody).
            ids: (P,) person ids (rows of the same id across frames are the same person;
                id 0 or None: by row).
            stamp_s: the frame's time, s.

        Returns:
            ``(people, exchanged)``: the keypoints, a copy with the rows found mirrored
            exchanged left for right (the input when none), and (P,) bool, which rows.
        """
        import time

        people = np.asarray(people)
        n = len(people)
        exchanged = np.zeros(n, dtype=bool)
        keys = [int(ids[r]) if ids is not None and int(ids[r]) > 0 else -1 - r
                for r in range(n)]
        t0 = time.perf_counter()
        crops, rows = [], []
        present = 0
        for r in range(n):
            if not np.any(people[r, :, 2] > 0):
                continue
            present += 1
            crop = person_crop(image, people[r])
            if crop is not None:
                crops.append(crop)
                rows.append(r)
        probs = self.classifier.probabilities(np.stack(crops)) if crops else np.zeros(0)
        if crops:
            self.stats.times.add(time.perf_counter() - t0)
        self.stats.persons += present
        self.stats.scored += len(rows)
        p = self.params
        for key in [k for k, t in self._last_seen.items()
                    if not 0.0 <= stamp_s - t <= p.forget_after_s]:
            del self._last_seen[key]
            self._history.pop(key, None)
        for r, prob in zip(rows, probs):
            key = keys[r]
            hist = self._history.get(key)
            if hist is None:
                hist = self._history[key] = collections.deque(maxlen=max(1, int(p.window)))
            hist.append(float(prob))
            self._last_seen[key] = stamp_s
            if (signed_width(people[r]) > p.min_width
                    and float(np.median(hist)) < p.max_probability):
                exchanged[r] = True
        if not exchanged.any():
            return people, exchanged
        out = people.copy()
        out[exchanged] = people[exchanged][:, list(KEYPOINT_MIRROR)]
        self.stats.exchanged += int(exchanged.sum())
        return out, exchanged


__all__ = ['CROP_SIZE', 'FacingCheck', 'FacingCheckParams', 'FacingClassifier', 'FacingNet',
           'FacingStats', 'crops_to_tensor', 'default_weights', 'person_crop', 'save_weights',
           'signed_width']
