"""A left/right label check by the detector itself on the mirrored image (no ROS imports).

BlazePose labels a person seen from behind as if seen from the front in a share of frames
(left called right; ``docs/keypoints.md``). Run on the image mirrored left to right, the same
detector often reads the same person the other way: a second opinion from a network trained
on real people (unlike :mod:`mocap_keypoints.facing`, trained on rendered ones). The detector
errs almost only one way, calling a back view a front view (0.6 % of front views mirrored
against 26 % of back views on the rendered clips), so where the two readings disagree clearly
the one that faces away is taken:

1. a second detector of the same kind follows the mirrored frames (its own tracking state);
2. its persons are mapped back into the image (u -> W - 1 - u, and left and right exchanged,
   since the mirrored image's left is the image's right);
3. each person of the main detector whose labels face the camera by more than
   ``min_width`` (:func:`~mocap_keypoints.facing.signed_width`) is matched to the mirrored
   reading of the same person (the same points up to labels, mean distance under
   ``match_fraction`` of the person's height);
4. if that reading faces away by more than ``min_width``, the person's left and right
   keypoints are exchanged.

A person whose labels face away, or side on, is never changed, so a frame where nobody's
labels face the camera needs no second reading: with ``only_when_needed`` the second detector
runs only on the other frames, and starts afresh (forgets whom it tracked) after a frame it
skipped. By default it reads every frame (its tracking then never has gaps; measured a little
better). The cost is a second detector run per frame read.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Optional, Tuple

import numpy as np

from mocap_core.metrics import LatencyStats
from mocap_core.skeleton import KEYPOINT_MIRROR, NUM_KEYPOINTS

from .facing import signed_width

_MIRROR = list(KEYPOINT_MIRROR)


def mirrored_back(people: np.ndarray, width: int) -> np.ndarray:
    """(P, 23, 3) keypoints detected on an image mirrored left to right -> the same persons in
    the pixels and the labels of the original image of ``width`` pixels: u -> width - 1 - u
    and left and right exchanged."""
    out = np.array(people, dtype=np.float64, copy=True).reshape(-1, NUM_KEYPOINTS, 3)
    out[..., 0] = (width - 1) - out[..., 0]
    return out[:, _MIRROR]


def same_person_distance(a: np.ndarray, b: np.ndarray, min_confidence: float = 0.3) -> float:
    """How far apart two readings of (maybe) one person are, whatever their labels: the mean
    image distance of the points both see (confidence >= ``min_confidence``), with the labels
    as they are or exchanged, whichever is nearer, over the person's height in ``a``
    (pixels / pixels). Infinite when fewer than 5 points are seen by both."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    best = np.inf
    for bb in (b, b[_MIRROR]):
        seen = (a[:, 2] >= min_confidence) & (bb[:, 2] >= min_confidence)
        seen &= np.isfinite(a[:, :2]).all(axis=1) & np.isfinite(bb[:, :2]).all(axis=1)
        if seen.sum() < 5:
            continue
        height = float(np.ptp(a[seen, 1])) or 1.0
        best = min(best, float(np.linalg.norm(a[seen, :2] - bb[seen, :2], axis=1).mean())
                   / height)
    return best


@dataclass
class MirrorCheckParams:
    """When :class:`MirrorCheck` exchanges a person's left and right."""

    #: both readings must face opposite ways by more than this (torso lengths)
    min_width: float = 0.25
    #: the two readings are one person when their points lie this close (share of height)
    match_fraction: float = 0.1
    #: read the mirrored frame only when someone's labels face the camera (else every frame:
    #: measured better, docs/keypoints.md)
    only_when_needed: bool = False


@dataclass
class MirrorCheckStats:
    """Counts since the check started, and its recent times (diagnostics)."""

    frames: int = 0          # frames checked
    read: int = 0            # ... on which the mirrored frame was read
    candidates: int = 0      # persons whose labels faced the camera
    matched: int = 0         # ... found in the mirrored reading
    exchanged: int = 0       # ... whose left and right were exchanged
    #: the mirrored detector's time per frame, s
    times: LatencyStats = field(default_factory=lambda: LatencyStats(100))


class MirrorCheck:
    """The check of the module docstring over a stream of frames.

    Args:
        make_detector: makes the second detector (the same kind and settings as the main one;
            it sees only mirrored frames).
        params: thresholds.
    """

    def __init__(self, make_detector: Callable[[], object],
                 params: Optional[MirrorCheckParams] = None) -> None:
        self.detector = make_detector()
        self.params = params or MirrorCheckParams()
        self.stats = MirrorCheckStats()
        self._skipped = False

    def reset(self) -> None:
        """A new stream: the mirrored detector forgets whom it tracked."""
        self.detector.reset()
        self._skipped = False

    def close(self) -> None:
        self.detector.close()

    def apply(self, image: np.ndarray, people: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Check one frame.

        Args:
            image: the frame (H, W, 3) uint8 BGR the keypoints were detected in.
            people: (P, 23, 3) the main detector's persons in that image's pixels (all-zero
                rows are nobody).

        Returns:
            ``(people, exchanged)``: the keypoints (a copy with the rows found mirrored
            exchanged; the input when none) and (P,) bool, which rows.
        """
        import cv2

        people = np.asarray(people)
        exchanged = np.zeros(len(people), dtype=bool)
        p = self.params
        self.stats.frames += 1
        candidates = [r for r in range(len(people))
                      if np.any(people[r, :, 2] > 0) and signed_width(people[r]) > p.min_width]
        self.stats.candidates += len(candidates)
        if not candidates and p.only_when_needed:
            self._skipped = True
            return people, exchanged
        if self._skipped:       # frames were skipped: what it tracked is stale
            self.detector.reset()
            self._skipped = False
        t0 = time.perf_counter()
        found = self.detector.detect(cv2.flip(image, 1))
        self.stats.times.add(time.perf_counter() - t0)
        self.stats.read += 1
        other = mirrored_back(found, image.shape[1]) if len(found) else np.zeros(
            (0, NUM_KEYPOINTS, 3))
        for r in candidates:
            if not len(other):
                continue
            d = [same_person_distance(people[r], o) for o in other]
            best = int(np.argmin(d))
            if not d[best] < p.match_fraction:
                continue
            self.stats.matched += 1
            if signed_width(other[best]) < -p.min_width:
                exchanged[r] = True
        if not exchanged.any():
            return people, exchanged
        out = people.copy()
        out[exchanged] = people[exchanged][:, _MIRROR]
        self.stats.exchanged += int(exchanged.sum())
        return out, exchanged


__all__ = ['MirrorCheck', 'MirrorCheckParams', 'MirrorCheckStats', 'mirrored_back',
           'same_person_distance']
