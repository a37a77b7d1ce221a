"""Several people per image with the BlazePose models bundled in MediaPipe (no ROS imports).

MediaPipe 0.10.14 ships the BlazePose person detector (``pose_detection.tflite``) and the full
landmark model (``pose_landmark_full.tflite``) inside its wheel, but its multi-person API (the
Tasks ``PoseLandmarker``) wants a ``.task`` bundle, which is a download. :func:`pose_bundle`
builds that bundle from the two wheel files with MediaPipe's own metadata writer (image
normalisation of each model) and caches it under ``~/.cache/mocap/models``; nothing is
downloaded.

Measured on this project's clips (docs/multi_person.md): a Tasks landmarker asked for several
poses on the whole frame drops its tracking (it re-detects every frame), misses people in
~10-35 % of frames and returns partial duplicates. So :class:`BlazePoseMultiDetector` works
the BlazePose way, per person:

* **Detection** every ``detection_interval`` frames (and whenever nobody is followed): the
  Tasks landmarker in IMAGE mode with ``num_poses = max_persons`` on one region of the image.
  The regions take turns: the whole image, squares of the image's short side along its long
  side, and in larger images the whole image again and squares of two thirds of the short
  side on a grid (overlapping by at least a third). The detector sees its input at
  224 x 224, so in a wide image a person a third of the image high is ~50 px to it and often
  missed; in the smaller squares the same person is three times that. Then these regions
  take turns with finer squares (:meth:`~BlazePoseMultiDetector.fine_regions`) sized for
  people down to ``min_person_px`` high, or ``search_min_person_fraction`` of the image's
  short side if more (:meth:`~BlazePoseMultiDetector.search_regions`: a round of the coarse
  regions alone, then a coarse region and a finer square in turn, until every finer square
  had its turn; then again). A person far from the camera, 50 px high in a 360 x 640 video,
  is hardly ever found in the coarse regions and is followed in most frames once a 128-px
  square finds them. A person that a square cuts is not taken from it (a larger region finds
  them whole). A search is made every ``detection_interval`` frames (every frame while
  nobody is followed), so a coarse region comes every ``detection_interval`` x (twice their
  number) frames and the finer squares, many more, are all scanned only every
  ``detection_interval`` x (their number + twice that of the coarse regions) frames: about
  5 s on a 640 x 360 video while nobody is followed, over a minute at the longest interval
  while somebody is. While whole rounds of the coarse regions find nobody new (the looks where
  the picture changed, below, are not searches of such a round) the interval doubles, up to
  ``max_detection_interval``, and it drops back as soon as someone new is found or a window
  ends. Once a whole round of regions at the longest interval has
  found nobody new, a due search is skipped while nothing has changed outside the people
  followed since the last search (:func:`changed_outside`: a grey copy of the image about
  160 px wide, the people's boxes then and now left out), but one is made at least every
  ``still_detection_interval`` frames. Nobody can come into a still picture without changing
  it, and a moving camera changes everything, so searches go on as before there. A change
  starts a full round of regions again. On a static camera this takes most of the search's
  cost off (one search costs about half a landmark pass). The same comparison says where to
  look (``search_where_changed``): while somebody is followed, a due search goes to the
  largest patch of the picture that changed since the last search outside the people
  followed, in the smallest region of the cycle that holds it and shows it at most
  :data:`SMALL_PERSON_SIDE_FRACTION` of its side (:func:`changed_patch`,
  :meth:`~BlazePoseMultiDetector.region_for`), every other search at most, so that the cycle
  goes on beside it. Somebody walking into a static picture is then looked for where they
  are; a moving camera changes more than :data:`MAX_CHANGED_SHARE` of the picture and the
  cycle alone goes on.
* **A window per person**: every person found that no window already follows gets a square
  window on the image (``window_scale`` x the person's box, at least ``min_window_px``) and
  its own VIDEO-mode landmarker for one pose. The window stays put while the person stays in
  its central part, so the landmarker tracks inside it as it does on a whole video (landmarks
  of one frame seed the next; no detection); when the person nears the window's edge, the
  window is moved onto the person and its landmarker restarted.
* **One person alone, large in the image**: while only one person is followed and their box
  is at least ``whole_frame_min_height`` of the image's long side, their landmarker sees the
  whole image instead of a window, as the single-person detector does (the landmarker crops
  its own region from the last frame's landmarks; no copy of a window, no restart when the
  person crosses the image). It goes back to a window when a second person is found, when
  the person becomes smaller than ``whole_frame_leave_height``, or when its landmarker jumps
  to somebody else. Measured on the committed one-person clip: per frame as fast as the
  single-person detector (docs/multi_person.md).
* **Windows end** when their landmarker loses the person for ``max_missed`` frames (in the
  meantime it looks for them again in its window, as MediaPipe does after losing track), or
  when two windows follow the same person (the less confident one ends). When the landmarker
  jumps to somebody else in its window (:func:`jumped`: the torso moves by more than its own
  length in one frame; a person passing in front or behind), that frame counts as missed and
  the window's landmarker starts afresh. A new window's first landmarks are compared with
  the search's coarser keypoints more leniently (:data:`FRESH_MAX_RATIO`).

Identities are not this module's job: :class:`mocap_core.tracking.PersonTracker` gives them
downstream, and also merges the duplicates that remain.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import List, Optional, Sequence, Tuple

import numpy as np

from mocap_core.skeleton import KEYPOINT_INDEX, NUM_KEYPOINTS
from mocap_core.tracking import box_iou, keypoint_box, oks

from .blazepose import blazepose_to_layout
from .sources import check_image

#: Where the built ``.task`` bundle is cached.
MODEL_CACHE = Path(os.environ.get('MOCAP_CACHE', Path.home() / '.cache' / 'mocap')) / 'models'
BUNDLE_NAME = 'pose_landmarker_full_mp0.10.14.task'


def pose_bundle(cache_dir: Optional[Path] = None) -> Path:
    """Path of the pose landmarker ``.task`` bundle, built from the model files in the
    installed mediapipe wheel on first use (with metadata: the detector's input normalised
    to [-1, 1], the landmark model's to [0, 1]). Raises RuntimeError when the wheel lacks the
    models."""
    cache_dir = Path(cache_dir or MODEL_CACHE)
    out = cache_dir / BUNDLE_NAME
    if out.is_file() and out.stat().st_size > 0:
        return out
    import mediapipe
    from mediapipe.tasks.python.metadata.metadata_writers import (metadata_writer,
                                                                  model_asset_bundle_utils)
    root = Path(mediapipe.__file__).parent / 'modules'
    det = root / 'pose_detection' / 'pose_detection.tflite'
    lmk = root / 'pose_landmark' / 'pose_landmark_full.tflite'
    for f in (det, lmk):
        if not f.is_file():
            raise RuntimeError(f'{f} is missing from the mediapipe wheel: cannot build the '
                               'multi-person pose model')

    def with_metadata(path: Path, name: str, mean: float, std: float) -> bytes:
        w = metadata_writer.MetadataWriter.create(bytearray(path.read_bytes()))
        w.add_general_info(name, 'BlazePose model from the mediapipe wheel')
        w.add_image_input([mean], [std])
        model, _ = w.populate()
        return bytes(model)

    cache_dir.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(f'.{os.getpid()}.tmp')
    model_asset_bundle_utils.create_model_asset_bundle(
        {'pose_detector.tflite': with_metadata(det, 'pose_detector', 127.5, 127.5),
         'pose_landmarks_detector.tflite': with_metadata(lmk, 'pose_landmarks', 0.0, 255.0)},
        str(tmp))
    os.replace(tmp, out)
    return out


def mask_box(kp: np.ndarray, margin: float = 0.1) -> Optional[tuple]:
    """``(x0, y0, x1, y1)`` integer pixels covering a person's seen keypoints (confidence
    >= 0.3), grown by ``margin`` x the person's height on every side (hair, clothes and
    hands beyond the keypoints); None when fewer than two are seen."""
    box = keypoint_box(kp, 0.3)
    if box is None:
        return None
    cx, cy, bh, bw = box
    pad = margin * bh
    return (int(np.floor(cx - bw / 2 - pad)), int(np.floor(cy - bh / 2 - pad)),
            int(np.ceil(cx + bw / 2 + pad)), int(np.ceil(cy + bh / 2 + pad)))


def cut_by(kp: np.ndarray, region: tuple, width: int, height: int,
           margin: float = 0.02) -> bool:
    """Whether a person found in ``region`` ``(x0, y0, x1, y1)`` of a ``width`` x
    ``height`` image reaches one of the region's edges that lie inside the image (within
    ``margin`` of the region's side): a person the square cuts, whose keypoints beyond the
    edge are guesses. The whole image, or a larger square, finds them whole."""
    box = mask_box(kp, margin=0.0)
    if box is None:
        return False
    x0, y0, x1, y1 = region
    m = margin * max(x1 - x0, y1 - y0)
    return bool((x0 > 0 and box[0] <= x0 + m) or (y0 > 0 and box[1] <= y0 + m) or
                (x1 < width and box[2] >= x1 - m) or (y1 < height and box[3] >= y1 - m))


#: Width (px) of the grey copy of the image compared between searches (:func:`changed_outside`),
#: at least: the image is reduced by the integer factor that comes nearest (160-319 px).
CHANGE_WIDTH = 160
#: The search where the picture changed (:meth:`BlazePoseMultiDetector.region_for`) first
#: sizes its region for a person as large as the patch that changed, and after each look that
#: found nobody new for one this many times larger, in turn: only the edges of a person's
#: clothes change when they move (measured on rendered walkers 180 px high in a 1280 x 720
#: video, five frames apart: patches 50-90 px high).
GUIDED_GROWTH = (1.0, 2.0, 3.0)
#: After this many such looks that found nobody new (with no search finding anyone in between),
#: the search keeps to its cycle for a round of the coarse regions (twice their number where
#: finer squares take turns) and one search more, so that something moving that is nobody
#: (leaves, a screen) takes at most this many of every ``2 x this + round + 1`` searches while
#: nobody new comes.
GUIDED_MAX_MISSES = 2 * len(GUIDED_GROWTH)
#: A change over more than this share of that whole grey copy (counted outside the people
#: followed) has no one place to look at (:func:`changed_patch`): the camera moved or the
#: light changed.
MAX_CHANGED_SHARE = 0.2
#: The people followed are left out of that comparison in their box grown by this x their
#: height on every side (:func:`mask_box`): their shadows and reflections on the floor move
#: with them (measured on the committed clip: a reflection beyond 0.1 triggered searches).
CHANGE_MARGIN = 0.25


def picture_range(ref: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """(H, W) uint8 grey image -> the lowest and highest value in each pixel's 3 x 3
    neighbourhood, int16 (for :func:`changed_outside`)."""
    import cv2
    kernel = np.ones((3, 3), np.uint8)
    return cv2.erode(ref, kernel).astype(np.int16), cv2.dilate(ref, kernel).astype(np.int16)


def changed_mask(ref_range: Tuple[np.ndarray, np.ndarray], now: np.ndarray,
                 boxes: Sequence[tuple], level: float = 20.0) -> Optional[np.ndarray]:
    """(H, W) bool: the pixels of the small grey image ``now`` (uint8) more than ``level``
    grey levels outside the range of the reference in their 3 x 3 neighbourhood
    (``ref_range``, from :func:`picture_range`), none inside ``boxes`` (``(x0, y0, x1, y1)``
    pixels of these images); None when the sizes differ (see :func:`changed_outside`)."""
    lo, hi = ref_range
    if lo.shape != now.shape:
        return None
    cur = now.astype(np.int16)
    diff = (cur < lo - level) | (cur > hi + level)
    for x0, y0, x1, y1 in boxes:
        diff[max(y0, 0):max(y1, 0), max(x0, 0):max(x1, 0)] = False
    return diff


def changed_outside(ref_range: Tuple[np.ndarray, np.ndarray], now: np.ndarray,
                    boxes: Sequence[tuple], level: float = 20.0, min_pixels: int = 6) -> bool:
    """Whether a small grey image ``now`` (uint8) differs from a reference outside ``boxes``
    (``(x0, y0, x1, y1)`` pixels of these images, e.g. the people followed in either): at
    least ``min_pixels`` pixels of ``now`` lie more than ``level`` grey levels outside the
    range of the reference in their 3 x 3 neighbourhood (``ref_range``, from
    :func:`picture_range`). The neighbourhood forgives a shake of the camera by up to a pixel
    of the small image (4 px of a 640-px-wide frame), which otherwise lights up every edge; a
    person coming into the picture changes a whole patch. At :data:`CHANGE_WIDTH` px wide a
    person 48 px high in a 1280 x 720 image covers about 15 pixels. Another image size is a
    change."""
    diff = changed_mask(ref_range, now, boxes, level)
    return diff is None or int(np.count_nonzero(diff)) >= min_pixels


def changed_patch(diff: np.ndarray, min_pixels: int = 6,
                  max_share: float = MAX_CHANGED_SHARE) -> Optional[tuple]:
    """Where something moved in a :func:`changed_mask`: ``(x0, y0, x1, y1)`` (pixels of that
    mask, end exclusive) of its largest patch of changed pixels (8-connected after a 3 x 3
    dilation, so that the scattered pixels of one moving person join), or None when fewer
    than ``min_pixels`` changed (nothing came) or more than ``max_share`` of the image (the
    camera moved or the light changed: no one place to look)."""
    import cv2
    n = int(np.count_nonzero(diff))
    if n < min_pixels or n > max_share * diff.size:
        return None
    grown = cv2.dilate(diff.astype(np.uint8), np.ones((3, 3), np.uint8))
    count, labels = cv2.connectedComponents(grown, connectivity=8)
    if count < 2:
        return None
    # the patch with the most changed pixels, boxed by those pixels (not by the dilation's)
    sizes = np.bincount(labels[diff], minlength=count)
    sizes[0] = 0
    ys, xs = np.nonzero(diff & (labels == int(np.argmax(sizes))))
    return int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1


def _fill(crop: np.ndarray, box: tuple, x0: int, y0: int) -> None:
    """Paint the image box ``(x0, y0, x1, y1)`` grey in ``crop``, whose top-left corner is
    at image pixel (``x0``, ``y0``)."""
    bx0, by0, bx1, by1 = box
    crop[max(by0 - y0, 0):max(by1 - y0, 0), max(bx0 - x0, 0):max(bx1 - x0, 0)] = 127


#: Side of the smaller search squares (:meth:`BlazePoseMultiDetector.regions`) as a fraction
#: of the image's short side. The detector sees its input at 224 x 224; measured on rendered
#: people 28 % of a 720p frame high (``mocap eval people``), squares of the short side found
#: them in about half of the scans, squares of two thirds of it in every scan, and a third of
#: it gave partial bodies. A person such a square cuts is left to the larger regions
#: (:func:`cut_by`).
TILE_FRACTION = 2.0 / 3.0
#: The squares of :data:`TILE_FRACTION` are scanned only in images whose short side is at
#: least this (px); in smaller images the finer squares of
#: :meth:`BlazePoseMultiDetector.fine_regions` look for the small people.
SMALL_TILE_MIN_SIDE = 480

#: The finest search squares (:meth:`BlazePoseMultiDetector.fine_regions`) are sized so that the
#: smallest person searched is this fraction of a square's side high (the detector sees the
#: square at 224 x 224). Measured on rendered walkers far from a static camera (a 360 x 640
#: video, squares placed at random around the person, 20 frames each): a person 51 px high was
#: found in 18 of 20 squares of 128 px (0.40 of the side), 12-14 of 20 of 180-240 px (0.21-0.28),
#: 2 of 20 of 360 px and never in the whole image; people 33 px high in 5-9 of 20 squares of
#: 128 px. Found, their landmarks were off by 3 % of their height (docs/multi_person.md).
SMALL_PERSON_SIDE_FRACTION = 0.375
#: Each level of finer squares is this much larger than the one below it, as long as a level's
#: squares stay smaller than the smallest of the regions of
#: :meth:`BlazePoseMultiDetector.regions` by more than the square root of this; the squares of
#: a level overlap by half their side, so that a person up to half a square high lies wholly
#: in one of them.
FINE_LEVEL_STEP = 1.5
#: The smallest person the finer squares are made for (px), whatever the settings: people
#: 33 px high were found in at most 9 of 20 squares sized for them, and the number of squares
#: grows with the inverse square of the size (``min_person_height_px`` may be 0).
SMALLEST_SEARCHED_PX = 32.0

#: :func:`jumped`'s largest torso-length ratio between a window's first landmarks and the
#: search's keypoints that opened it. The search sees the whole region at 224 x 224, so a
#: small person's torso comes out short: on the pexels walk the search gave 45 px and the
#: window 62 px (1.38x), and the default 1.3 threw the window's first seven frames away as
#: "somebody else" against that coarse reference, until the window ended.
FRESH_MAX_RATIO = 2.0

#: Keypoints of the torso (shoulders and hips), for :func:`jumped`.
_TORSO = tuple(KEYPOINT_INDEX[n] for n in ('left_shoulder', 'right_shoulder', 'left_hip',
                                           'right_hip'))


def jumped(last: np.ndarray, kp: np.ndarray, max_shift: float = 1.0,
           max_ratio: float = 1.3) -> bool:
    """Whether (23, 3) keypoints ``kp`` of one frame cannot be the same person as ``last`` of
    the frame before: the torso (shoulders and hips) moved by more than ``max_shift`` torso
    lengths (mid-shoulder to mid-hip), or its length changed by more than ``max_ratio``. A
    person walking or running moves a fraction of a torso length per frame at 30 fps; the
    landmarker of a window that takes the person passing in front is off by more. False when
    a torso is not seen in both."""
    def torso(k):
        t = k[list(_TORSO)]
        if np.any(t[:, 2] < 0.3):
            return None
        shoulders, hips = t[:2, :2].mean(axis=0), t[2:, :2].mean(axis=0)
        return (shoulders + hips) / 2.0, float(np.linalg.norm(shoulders - hips))
    a, b = torso(last), torso(kp)
    if a is None or b is None or min(a[1], b[1]) < 1.0:
        return False
    size = max(a[1], b[1])
    return bool(np.linalg.norm(a[0] - b[0]) > max_shift * size
                or max(a[1], b[1]) / min(a[1], b[1]) > max_ratio)


def interleave(coarse: Sequence[tuple], fine: Sequence[tuple]) -> List[tuple]:
    """One cycle of the search's regions: every ``coarse`` region once, then a coarse region
    (in order, again and again) and a ``fine`` square in turn until each fine square had its
    turn. Without fine squares: the coarse regions."""
    return list(coarse) + [r for k, f in enumerate(fine)
                           for r in (coarse[k % len(coarse)], f)]


def _starts(length: int, side: int, step: float) -> List[int]:
    """Starts of squares of ``side`` px spread evenly over ``length`` px, from one end to the
    other, at most ``step`` px apart (one square when it covers the length)."""
    if length <= side:
        return [0]
    n = int(np.ceil((length - side) / step)) + 1
    return [int(round(k * (length - side) / (n - 1))) for k in range(n)]


def _where(win: '_Window') -> List[np.ndarray]:
    """Where the person of ``win`` may be in this frame, before its landmarker has run: the
    last frame's keypoints and, after two frames in a row, those moved on as much again."""
    if win.last is None:
        return []
    if win.prev is None:
        return [win.last]
    ahead = win.last.copy()
    both = (win.last[:, 2] >= 0.3) & (win.prev[:, 2] >= 0.3)
    ahead[both, :2] = 2.0 * win.last[both, :2] - win.prev[both, :2]
    ahead[~both, 2] = 0.0          # only what was seen in both frames moves on
    return [win.last, ahead]


@dataclass
class _Window:
    x0: int                 # top-left corner in the image (px), may lie outside it
    y0: int
    side: int               # square side (px)
    landmarker: object      # a VIDEO-mode PoseLandmarker (one pose)
    missed: int = 0
    last: Optional[np.ndarray] = None   # (23, 3) image keypoints of the last frame
    prev: Optional[np.ndarray] = None   # those of the frame before (None after a miss)
    whole: bool = False     # the landmarker sees the whole image (x0, y0, side unused)
    fresh: bool = True      # ``last`` is still the search's keypoints (coarser; see detect)


class BlazePoseMultiDetector:
    """Several people per image (see the module docstring).

    Args:
        max_persons: the most people followed at once.
        detection_interval: look for new people every this many frames (1: every frame);
            also whenever no window follows anybody; never while ``max_persons`` are followed.
        max_detection_interval: while whole rounds of regions find nobody new, the interval
            doubles up to this.
        still_detection_interval: after a whole round at ``max_detection_interval`` found
            nobody new, a search is skipped while nothing changed outside the people followed
            since the last one, but made at least every this many frames (0: never skipped).
        min_person_px: people whose box of seen keypoints is lower than this are ignored.
        window_scale: window side / the person's box side (height or width, the larger).
        min_window_px: the smallest window side.
        max_missed: a window ends after its landmarker misses this many frames in a row.
        min_detection_confidence, min_tracking_confidence: MediaPipe's thresholds.
        threads: the windows' landmarkers run in up to this many threads at once (two people
            on two cores: 13 against 23 ms per frame for both windows, docs/multi_person.md).
        whole_frame_min_height: a person followed alone whose box is at least this fraction
            of the image's long side is tracked on the whole image (the detector then sees
            them at least this x 224 px high); 0 disables it.
        whole_frame_leave_height: ... and goes back to a window below this fraction
            (hysteresis; at most ``whole_frame_min_height``).
        search_min_person_fraction: the search also scans finer squares
            (:meth:`fine_regions`), taking turns with the regions of :meth:`regions` after a
            round of those alone (:meth:`search_regions`), for people down to
            ``max(min_person_px, this x the image's short side)`` high, at least
            :data:`SMALLEST_SEARCHED_PX` (a smaller fraction: more squares, so each is
            scanned less often); 1 scans only :meth:`regions`.
        search_where_changed: while somebody is followed, a due search looks where the
            picture changed since the last search, outside the people followed
            (:meth:`_changed_region`: the region of the cycle sized for the largest patch of
            change that holds it), every other search at most; the others keep to the cycle
            of :meth:`search_regions`. Somebody who walks into a static camera's picture is
            then looked for where they are within a search or two, instead of when the cycle
            comes to their region (up to a minute for a small person while somebody else is
            followed). A camera that moves changes too
            much of the picture (:data:`MAX_CHANGED_SHARE`) to say where: the cycle goes on.
    """

    name = 'mediapipe_blazepose_full_multi'

    def __init__(self, max_persons: int = 4, detection_interval: int = 5,
                 max_detection_interval: int = 15, still_detection_interval: int = 60,
                 min_person_px: float = 48.0, window_scale: float = 2.0,
                 min_window_px: int = 128, max_missed: int = 8,
                 min_detection_confidence: float = 0.5,
                 min_tracking_confidence: float = 0.5, threads: int = 2,
                 whole_frame_min_height: float = 0.4,
                 whole_frame_leave_height: float = 0.3,
                 search_min_person_fraction: float = 0.1,
                 search_where_changed: bool = True) -> None:
        if max_persons < 1:
            raise ValueError(f'max_persons must be >= 1, got {max_persons}')
        if detection_interval < 1:
            raise ValueError(f'detection_interval must be >= 1, got {detection_interval}')
        if threads < 1:
            raise ValueError(f'threads must be >= 1, got {threads}')
        if not 0.0 <= whole_frame_min_height <= 1.0:
            raise ValueError(f'whole_frame_min_height must be in [0, 1] (0: off), got '
                             f'{whole_frame_min_height}')
        if whole_frame_min_height > 0 and not 0.0 <= whole_frame_leave_height \
                <= whole_frame_min_height:
            raise ValueError(f'whole_frame_leave_height must be in [0, whole_frame_min_height '
                             f'= {whole_frame_min_height}], got {whole_frame_leave_height}')
        if not 0.0 <= search_min_person_fraction <= 1.0:
            raise ValueError(f'search_min_person_fraction must be in [0, 1], got '
                             f'{search_min_person_fraction}')
        self.search_min_person_fraction = float(search_min_person_fraction)
        self.search_where_changed = bool(search_where_changed)
        #: the last search looked where the picture changed (the next keeps to the cycle)
        self._guided_last = False
        #: the next such search's region, as a multiple of the size the change asks for
        #: (:data:`GUIDED_GROWTH`: grown after each look that found nobody new; back to the
        #: first when any search finds someone new or the last window ends)
        self._growth = 0
        #: such looks that found nobody new since any search last found someone (or the last
        #: window ended), and the searches left that keep to the cycle after
        #: :data:`GUIDED_MAX_MISSES` of them (something that moves is no person)
        self._misses = 0
        self._guided_pause = 0
        #: this frame's small grey image and its scale (:meth:`_small`; cleared each frame)
        self._small_of: Optional[Tuple[np.ndarray, float]] = None
        #: the search's regions in turn per image size (see :meth:`search_regions`), and
        #: the number of searches in a round of them
        self._scan: dict = {}
        self._fine_turn = False
        #: the next turn in the cycle of :meth:`search_regions`, and the image size it is of
        self._turn = 0
        self._turn_size: Optional[Tuple[int, int]] = None
        self.whole_frame_min_height = float(whole_frame_min_height)
        self.whole_frame_leave_height = float(whole_frame_leave_height)
        self.threads = int(threads)
        self._pool = None
        os.environ.setdefault('GLOG_minloglevel', '2')
        import cv2
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            import mediapipe as mp
            from mediapipe.tasks.python import vision
            from mediapipe.tasks.python.core.base_options import BaseOptions
        self._cv2, self._mp, self._vision = cv2, mp, vision
        self._base = BaseOptions(model_asset_path=str(pose_bundle()))
        self.max_persons = int(max_persons)
        self.detection_interval = int(detection_interval)
        self.min_person_px = float(min_person_px)
        self.window_scale = float(window_scale)
        self.min_window_px = int(min_window_px)
        self.max_missed = int(max_missed)
        #: a window moves when the person comes within this fraction of its side of an edge,
        #: and is remade when the person's size changes by more than ``resize_ratio``
        self.recentre_margin = 0.05
        self.resize_ratio = 1.6
        self.recentred = 0
        self._det_conf = float(min_detection_confidence)
        self._trk_conf = float(min_tracking_confidence)
        self._finder = vision.PoseLandmarker.create_from_options(vision.PoseLandmarkerOptions(
            base_options=self._base, running_mode=vision.RunningMode.IMAGE,
            num_poses=self.max_persons, min_pose_detection_confidence=self._det_conf,
            min_pose_presence_confidence=self._det_conf))
        self._windows: List[_Window] = []
        self.max_detection_interval = max(int(max_detection_interval), self.detection_interval)
        self.still_detection_interval = int(still_detection_interval)
        #: the last search's small grey image (its 3 x 3 ranges) and the people's boxes in it
        self._ref: Optional[Tuple[np.ndarray, np.ndarray]] = None
        self._ref_boxes: List[tuple] = []
        #: a whole round of regions at the longest interval found nobody new (searches may
        #: then be skipped while the picture is still)
        self._settled = False
        self._since_search = 0
        #: no lone person on the whole image until the next search (after a jump there)
        self._whole_blocked = False
        #: searches skipped because nothing changed outside the people followed
        self.searches_skipped = 0
        #: searches of the finer squares (:meth:`fine_regions`), and the people they found
        #: that nobody followed yet
        self.fine_searches = 0
        self.found_in_fine = 0
        #: searches where the picture changed (:meth:`_changed_region`), and the people they
        #: found that nobody followed yet
        self.guided_searches = 0
        self.found_guided = 0
        self._frame = 0
        self._since_find = 0
        self._interval = self.detection_interval
        self._quiet = 0
        self._ts_ms = 0
        self._closed = False
        #: counters for diagnostics
        self.detections = 0
        self.windows_opened = 0
        #: windows ended because their landmarker jumped to somebody else
        self.jumps = 0
        #: switches of a lone person's landmarker to the whole image and back to a window
        self.whole_switches = 0

    # ------------------------------------------------------------------ protocol
    def detect(self, image: np.ndarray) -> np.ndarray:
        img = check_image(image, 'image')
        if self._closed:
            raise RuntimeError('detector is closed')
        h, w = img.shape[:2]
        self._small_of = None      # this frame's small copy is made when first needed
        rgb = self._cv2.cvtColor(img, self._cv2.COLOR_BGR2RGB)
        self._ts_ms += 33          # VIDEO mode wants increasing stamps; only order matters
        people: List[np.ndarray] = []
        for win, kp in self._track_windows(rgb):
            if kp is not None and win.last is not None and \
                    jumped(win.last, kp, max_ratio=FRESH_MAX_RATIO if win.fresh else 1.3):
                # the landmarker took somebody else in its window (a person passing in
                # front or behind), or lost its person: this frame has nobody from this
                # window, and a fresh landmarker looks for the person again (the others
                # masked) from the next frame on
                self.jumps += 1
                if win.whole:
                    # somebody else is in the picture: back to a window around the person,
                    # and search soon (no whole image until then)
                    self._to_window(win, win.last, w, h)
                    self._whole_blocked = True
                    self._search_soon()
                else:
                    self._restart(win)
                kp = None
            if kp is None:
                win.missed += 1
                win.prev = None
                if win.missed >= self.max_missed:
                    self._end(win)
                continue
            win.prev = win.last if win.missed == 0 else None
            win.missed = 0
            win.last = kp
            win.fresh = False
            people.append(kp)
            self._recentre(win, kp, w, h)
        self._drop_duplicate_windows(people)
        self._since_find += 1
        self._since_search += 1
        due = not self._windows or (self._since_find >= self._interval and
                                    len(self._windows) < self.max_persons)
        if due and self._windows and self._still(rgb):
            self._since_find = 0        # the picture is checked again an interval later
            due = False
        if due:
            self._since_find = self._since_search = 0
            region = None
            # (only while somebody is followed: searches are then sparse; while nobody is,
            # one comes every frame and the cycle's first regions find most people soonest)
            if self.search_where_changed and not self._guided_last and self._windows:
                if self._guided_pause > 0:
                    self._guided_pause -= 1
                else:
                    region = self._changed_region(rgb)
            self._guided_last = region is not None
            new: List[np.ndarray] = []
            for kp in self._find(rgb, [wn.last for wn in self._windows if wn.last is not None],
                                 region):
                box = keypoint_box(kp, 0.3)
                if box is None or box[2] < self.min_person_px:
                    continue
                if any(self._same(kp, q) for q in people + new):
                    continue
                if len(self._windows) + len(new) >= self.max_persons:
                    break
                new.append(kp)
            if new:
                # whoever found them, the next change is another person's: its looks start
                # at the patch's own size and with no misses counted (a pause under way goes
                # on: what moved and was nobody is still there)
                self._growth = self._misses = 0
            if region is not None:
                self.guided_searches += 1
                self.found_guided += len(new)
                if not new:
                    self._growth = (self._growth + 1) % len(GUIDED_GROWTH)
                    self._misses += 1
                if self._misses >= GUIDED_MAX_MISSES:
                    # a change that is nobody (leaves, a screen, a reflection): a round of
                    # the cycle's regions before the next such look
                    self._misses = 0
                    self._guided_pause = self.search_regions(w, h)[1]
            elif self._fine_turn:
                self.fine_searches += 1
                self.found_in_fine += len(new)
            alone = not self._windows and len(new) == 1
            for kp in new:
                self._open(kp, w, h, whole=alone and self._large(kp, w, h))
            people += new
            self._back_off(len(new), self.search_regions(w, h)[1], guided=region is not None)
            self._searched(rgb)
        self._settle_whole(w, h)
        self._frame += 1
        people = [p for p in people if (b := keypoint_box(p, 0.3)) is not None and
                  b[2] >= self.min_person_px]
        if not people:
            return np.zeros((0, NUM_KEYPOINTS, 3))
        return np.stack(people)

    def reset(self) -> None:
        for win in list(self._windows):
            self._end(win)
        self._frame = 0
        self._since_find = 0
        self._interval = self.detection_interval
        self._quiet = 0
        self._ref, self._ref_boxes = None, []
        self._small_of = None
        self._turn = 0
        self._settled = self._whole_blocked = self._guided_last = False
        self._growth = self._misses = self._guided_pause = 0
        self._since_search = 0

    def _small(self, rgb: np.ndarray) -> Tuple[np.ndarray, float]:
        """The image grey, reduced by an integer factor to :data:`CHANGE_WIDTH` - 319 px wide
        (the last rows and columns that do not fill a block are left out), and its scale
        (made once per frame: ``rgb`` is this frame's image)."""
        if self._small_of is None:
            self._small_of = self._make_small(rgb)
        return self._small_of

    def _make_small(self, rgb: np.ndarray) -> Tuple[np.ndarray, float]:
        h, w = rgb.shape[:2]
        f = max(1, w // CHANGE_WIDTH)
        cut = rgb[:max(f, h - h % f), :w - w % f]
        small = self._cv2.resize(cut, (cut.shape[1] // f, cut.shape[0] // f),
                                 interpolation=self._cv2.INTER_AREA)
        return self._cv2.cvtColor(small, self._cv2.COLOR_RGB2GRAY), 1.0 / f

    def _followed_boxes(self, scale: float) -> List[tuple]:
        """The people followed, each in their box grown by :data:`CHANGE_MARGIN`, in the
        pixels of :meth:`_small` (rounded outwards)."""
        out = []
        for win in self._windows:
            box = mask_box(win.last, CHANGE_MARGIN) if win.last is not None else None
            if box is not None:
                out.append(tuple(int(round(v * scale)) + (1 if k >= 2 else -1)
                                 for k, v in enumerate(box)))
        return out

    def _still(self, rgb: np.ndarray) -> bool:
        """Whether this due search can be skipped: searches have settled (a whole round at
        the longest interval found nobody new), the last search is fewer than
        ``still_detection_interval`` frames ago, and nothing changed outside the people
        followed (then or now) since then. A change unsettles the searches: a full round of
        regions comes first again."""
        if (self.still_detection_interval <= 0 or not self._settled or self._ref is None or
                self._since_search >= self.still_detection_interval):
            return False
        small, scale = self._small(rgb)
        if changed_outside(self._ref, small, self._ref_boxes + self._followed_boxes(scale)):
            self._settled, self._quiet = False, 0
            return False
        self.searches_skipped += 1
        return True

    def _searched(self, rgb: np.ndarray) -> None:
        """After a search: its picture is the reference of the next :meth:`_still` and
        :meth:`_changed_region`."""
        self._whole_blocked = False
        if self.still_detection_interval > 0 or self.search_where_changed:
            small, scale = self._small(rgb)
            self._ref = picture_range(small)
            self._ref_boxes = self._followed_boxes(scale)

    def _changed_region(self, rgb: np.ndarray) -> Optional[tuple]:
        """Where this due search looks (``search_where_changed``): the region of the cycle
        (:meth:`region_for`) for the largest patch of the picture that changed since the last
        search outside the people followed then and now (:func:`changed_mask`,
        :func:`changed_patch`), or None (no last search, nothing changed, or too much)."""
        if self._ref is None:
            return None
        small, scale = self._small(rgb)
        diff = changed_mask(self._ref, small, self._ref_boxes + self._followed_boxes(scale))
        patch = changed_patch(diff) if diff is not None else None
        if patch is None:
            return None
        h, w = rgb.shape[:2]
        return self.region_for(w, h, tuple(v / scale for v in patch),
                               GUIDED_GROWTH[self._growth])

    def region_for(self, width: int, height: int, box: tuple, growth: float = 1.0) -> tuple:
        """The region of the search's cycle (:meth:`search_regions`) to look for a person in
        whose moving part is the image box ``(x0, y0, x1, y1)`` (px): the smallest that holds
        the box and shows it at most :data:`SMALL_PERSON_SIDE_FRACTION` / ``growth`` of its
        side (with ``growth`` 1 as the finer squares show the smallest person; more where the
        person may be larger than the part of them that moved, and then holding as well
        (``growth`` - 1) / 2 x the box's larger side above and below it), the one whose
        centre is nearest the box's among equals; the whole image (always a region of the
        cycle, and exempt from the size) when none does."""
        regions, _ = self.search_regions(width, height)
        x0, y0, x1, y1 = box
        side = max(x1 - x0, y1 - y0)
        need = growth * side / SMALL_PERSON_SIDE_FRACTION
        cx, cy = (x0 + x1) / 2.0, (y0 + y1) / 2.0
        # the person the patch is part of may reach above and below it (a moving chest
        # above still legs): a grown look holds that much more of the image's height too
        reach = 0.5 * (growth - 1.0) * side
        y0, y1 = max(0.0, y0 - reach), min(float(height), y1 + reach)
        best, key = None, None
        for r in set(regions):
            rx0, ry0, rx1, ry1 = r
            whole = r == (0, 0, width, height)
            if not whole and min(rx1 - rx0, ry1 - ry0) < need:
                continue
            if not (rx0 <= x0 and ry0 <= y0 and x1 <= rx1 and y1 <= ry1):
                continue
            k = ((rx1 - rx0) * (ry1 - ry0),
                 np.hypot((rx0 + rx1) / 2.0 - cx, (ry0 + ry1) / 2.0 - cy), r)
            if key is None or k < key:
                best, key = r, k
        return best

    def _back_off(self, opened: int, regions: int, guided: bool = False) -> None:
        """After a detection: someone new resets the interval to ``detection_interval``; a
        whole round of the coarse regions (``regions`` searches of the cycle, twice their
        number where finer squares take turns: :meth:`search_regions`) with nobody new doubles
        it, up to ``max_detection_interval`` (a scene that stays the same costs little; a
        window that ends resets it too). A look where the picture changed (``guided``) that
        found nobody is not one of the round's searches: the round covers every coarse
        region however many such looks come between them."""
        if opened:
            self._search_soon()
            return
        if guided:
            return
        self._quiet += 1
        if self._quiet >= regions:
            self._quiet = 0
            if self._interval >= self.max_detection_interval:
                self._settled = True
            self._interval = min(2 * self._interval, self.max_detection_interval)

    def close(self) -> None:
        if self._closed:
            return
        self.reset()
        self._finder.close()
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None
        self._closed = True

    def __enter__(self) -> 'BlazePoseMultiDetector':
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def num_windows(self) -> int:
        return len(self._windows)

    # ------------------------------------------------------------------ helpers
    @staticmethod
    def _landmarks(pose) -> np.ndarray:
        return np.array([[p.x, p.y,
                          np.nan if p.visibility is None else p.visibility,
                          np.nan if p.presence is None else p.presence] for p in pose],
                        dtype=np.float64)

    @staticmethod
    def regions(width: int, height: int) -> List[tuple]:
        """``(x0, y0, x1, y1)`` regions scanned in turn: the whole image, squares of the
        image's short side along its long side; then, in an image whose short side is at
        least :data:`SMALL_TILE_MIN_SIDE`, the whole image again and squares of
        :data:`TILE_FRACTION` of the short side on a grid over the image (row by row).
        Neighbouring squares overlap by at least a third of a square."""
        short = min(width, height)

        def grid(side: int, both: bool) -> List[tuple]:
            step = side * 2.0 / 3.0
            ys = _starts(height, side, step) if both or height > width else [0]
            xs = _starts(width, side, step) if both or width >= height else [0]
            return [(x, y, x + side, y + side) for y in ys for x in xs]

        out = [(0, 0, width, height)]
        if max(width, height) > 1.2 * short:
            out += grid(short, both=False)
        if short >= SMALL_TILE_MIN_SIDE:
            out += [(0, 0, width, height)] + grid(int(round(TILE_FRACTION * short)), both=True)
        return out

    @staticmethod
    def fine_regions(width: int, height: int, smallest_px: float) -> List[tuple]:
        """``(x0, y0, x1, y1)`` squares for people down to ``smallest_px`` high, which the
        regions of :meth:`regions` show the detector too small: levels of squares from
        ``smallest_px`` / :data:`SMALL_PERSON_SIDE_FRACTION` up by :data:`FINE_LEVEL_STEP`
        while smaller than the smallest of those regions by more than the square root of
        that step, each level a grid over the image whose neighbouring squares overlap by half
        a square (finest level first, row by row). Empty when the coarse regions are fine
        enough. ``smallest_px`` must be at least 1."""
        if not smallest_px >= 1.0:
            raise ValueError(f'smallest_px must be >= 1, got {smallest_px}')
        coarse = min(min(x1 - x0, y1 - y0) for x0, y0, x1, y1 in
                     BlazePoseMultiDetector.regions(width, height))
        out: List[tuple] = []
        side = smallest_px / SMALL_PERSON_SIDE_FRACTION
        while side < coarse / np.sqrt(FINE_LEVEL_STEP):
            s = int(round(side))
            out += [(x, y, x + s, y + s) for y in _starts(height, s, s / 2.0)
                    for x in _starts(width, s, s / 2.0)]
            side *= FINE_LEVEL_STEP
        return out

    def search_regions(self, width: int, height: int) -> Tuple[List[tuple], int]:
        """The regions searched in turn in a ``width`` x ``height`` image (one cycle,
        :func:`interleave` of :meth:`regions` and the :meth:`fine_regions` for people down to
        ``max(min_person_px, search_min_person_fraction`` x the short side,
        :data:`SMALLEST_SEARCHED_PX`) high), and the searches that the interval's back-off
        counts as a round of the coarse regions (twice their number where they take turns
        with finer squares). The settings are read once per image size."""
        key = (width, height)
        if key not in self._scan:
            coarse = self.regions(width, height)
            smallest = max(self.min_person_px, SMALLEST_SEARCHED_PX,
                           self.search_min_person_fraction * min(width, height))
            fine = self.fine_regions(width, height, smallest)
            self._scan[key] = (interleave(coarse, fine),
                               2 * len(coarse) if fine else len(coarse))
        return self._scan[key]

    def _find(self, rgb: np.ndarray, followed: Sequence[np.ndarray] = (),
              region: Optional[tuple] = None) -> List[np.ndarray]:
        """Detection on ``region`` ``(x0, y0, x1, y1)``, by default this turn's region of the
        cycle (which a given region leaves where it is): (23, 3) image keypoints of every
        person found. The people already ``followed`` (their last (23, 3) keypoints) are
        masked grey (:func:`mask_box`): the detector's strongest detections are often the
        people it already follows, and it then reports nobody else."""
        h, w = rgb.shape[:2]
        regions, _ = self.search_regions(w, h)
        if (w, h) != self._turn_size:      # a new image size starts a cycle
            self._turn, self._turn_size = 0, (w, h)
        if region is None:
            turn = self._turn % len(regions)
            self._turn = turn + 1
            x0, y0, x1, y1 = regions[turn]
            # after the round of coarse regions alone, every other turn is a finer square
            coarse = len(self.regions(w, h))
            self._fine_turn = turn >= coarse and (turn - coarse) % 2 == 1
        else:
            x0, y0, x1, y1 = region
            self._fine_turn = False
        self.detections += 1
        boxes = [b for b in map(mask_box, followed) if b is not None]
        crop = (np.array if boxes else np.ascontiguousarray)(rgb[y0:y1, x0:x1])
        for box in boxes:
            _fill(crop, box, x0, y0)
        with warnings.catch_warnings():
            warnings.simplefilter('ignore', UserWarning)
            res = self._finder.detect(self._mp.Image(image_format=self._mp.ImageFormat.SRGB,
                                                     data=crop))
        out = []
        for pose in res.pose_landmarks:
            kp = blazepose_to_layout(self._landmarks(pose), x1 - x0, y1 - y0)
            seen = kp[:, 2] > 0
            kp[seen, 0] += x0
            kp[seen, 1] += y0
            if not cut_by(kp, (x0, y0, x1, y1), w, h):
                out.append(kp)
        out.sort(key=lambda k: -float(np.sum(k[:, 2])))
        return out

    def _new_landmarker(self):
        v = self._vision
        return v.PoseLandmarker.create_from_options(v.PoseLandmarkerOptions(
            base_options=self._base, running_mode=v.RunningMode.VIDEO, num_poses=1,
            min_pose_detection_confidence=self._det_conf,
            min_pose_presence_confidence=self._det_conf,
            min_tracking_confidence=self._trk_conf))

    def _window_for(self, kp: np.ndarray, w: int, h: int) -> tuple:
        box = keypoint_box(kp, 0.3)
        side = int(max(self.min_window_px, self.window_scale * max(box[2], box[3])))
        return int(round(box[0] - side / 2)), int(round(box[1] - side / 2)), side

    def _open(self, kp: np.ndarray, w: int, h: int, whole: bool = False) -> None:
        x0, y0, side = self._window_for(kp, w, h)
        self._windows.append(_Window(x0, y0, side, self._new_landmarker(), last=kp,
                                     whole=whole))
        self.windows_opened += 1

    def _large(self, kp: np.ndarray, w: int, h: int) -> bool:
        """Whether a person is large enough to be followed alone on the whole image."""
        box = keypoint_box(kp, 0.3)
        return (self.whole_frame_min_height > 0.0 and not self._whole_blocked and
                box is not None and box[2] >= self.whole_frame_min_height * max(w, h))

    def _settle_whole(self, w: int, h: int) -> None:
        """A lone, large person's landmarker goes to the whole image; with several windows
        none sees the whole image (the others must be masked)."""
        if len(self._windows) > 1:
            for win in self._windows:
                if win.whole:
                    self._to_window(win, win.last, w, h)
            return
        if len(self._windows) != 1:
            return
        win = self._windows[0]
        if win.whole or win.missed or win.last is None or not self._large(win.last, w, h):
            return
        win.whole = True
        self.whole_switches += 1
        self._restart(win)

    def _to_window(self, win: _Window, kp: Optional[np.ndarray], w: int, h: int) -> None:
        """Back from the whole image to a window on ``kp`` (the landmarker restarts); a
        square over the whole image when ``kp`` has too few points seen for a box."""
        if kp is not None and keypoint_box(kp, 0.3) is not None:
            win.x0, win.y0, win.side = self._window_for(kp, w, h)
        else:
            side = max(w, h)
            win.x0, win.y0, win.side = (w - side) // 2, (h - side) // 2, side
        win.whole = False
        self.whole_switches += 1
        self._restart(win)

    def _restart(self, win: _Window) -> None:
        """A fresh landmarker for the window (it detects the person again on its next
        frame)."""
        win.landmarker.close()
        win.landmarker = self._new_landmarker()

    def _end(self, win: _Window) -> None:
        win.landmarker.close()
        self._windows.remove(win)
        self._search_soon()
        if not self._windows:
            # nobody followed: the looks where the picture changed start afresh with the
            # next person (their sizes, misses and pause were about the scene before)
            self._growth = self._misses = self._guided_pause = 0

    def _search_soon(self) -> None:
        """Back to the shortest search interval, and a full round of regions before any
        search is skipped (someone new came, a window ended, or a lone person's landmarker
        saw somebody else)."""
        self._interval, self._quiet, self._settled = self.detection_interval, 0, False

    def _track_windows(self, rgb: np.ndarray):
        """Yield ``(window, keypoints or None)`` of every window on this frame. With
        ``threads`` > 1 and several windows, the landmarkers run at once (MediaPipe lets go of
        the GIL while it infers), each masking the others' people where they were in the
        last frame and where they would be now at the same speed (:func:`_where`); with one
        thread, in turn, a later window masking the earlier ones where they are in this
        frame."""
        wins = list(self._windows)
        if self.threads > 1 and len(wins) > 1:
            if self._pool is None:
                from concurrent.futures import ThreadPoolExecutor
                self._pool = ThreadPoolExecutor(self.threads, thread_name_prefix='landmarks')
            jobs = [(win, [k for o in wins if o is not win for k in _where(o)])
                    for win in wins]
            with warnings.catch_warnings():    # here: the filters are global, not per thread
                warnings.simplefilter('ignore', UserWarning)
                found = list(self._pool.map(lambda j: self._track(j[0], rgb, j[1]), jobs))
            yield from zip(wins, found)
            return
        for win in wins:
            others = [o.last for o in self._windows if o is not win and o.last is not None]
            with warnings.catch_warnings():
                warnings.simplefilter('ignore', UserWarning)
                kp = self._track(win, rgb, others)
            yield win, kp

    def _track(self, win: _Window, rgb: np.ndarray, others: Sequence[np.ndarray] = ()
               ) -> Optional[np.ndarray]:
        """Run the window's landmarker on its crop (borders outside the image are black);
        return image keypoints or None. The other people followed (``others``: their last
        (23, 3) keypoints) are masked grey in the crop, except where they overlap the window's
        own person: the landmarker then keeps to its person instead of taking a more salient
        one next to them. A window on the whole image (a lone person) takes the image as it
        is."""
        if win.whole:
            return self._landmarks_in(win, rgb, 0, 0)
        M = np.array([[1.0, 0.0, -win.x0], [0.0, 1.0, -win.y0]])
        crop = self._cv2.warpAffine(rgb, M, (win.side, win.side),
                                    flags=self._cv2.INTER_LINEAR,
                                    borderMode=self._cv2.BORDER_CONSTANT)
        own = mask_box(win.last) if win.last is not None else None
        if others and own is not None:
            ox0, oy0 = max(own[0] - win.x0, 0), max(own[1] - win.y0, 0)
            ox1, oy1 = max(own[2] - win.x0, 0), max(own[3] - win.y0, 0)
            keep = crop[oy0:oy1, ox0:ox1].copy()
            for kp in others:
                box = mask_box(kp)
                if box is not None:
                    _fill(crop, box, win.x0, win.y0)
            crop[oy0:oy1, ox0:ox1] = keep
        return self._landmarks_in(win, crop, win.x0, win.y0)

    def _landmarks_in(self, win: _Window, image: np.ndarray, x0: int, y0: int
                      ) -> Optional[np.ndarray]:
        """The window's landmarker on ``image`` (RGB), whose top-left corner is image pixel
        (``x0``, ``y0``): (23, 3) image keypoints, or None when it found nobody."""
        res = win.landmarker.detect_for_video(
            self._mp.Image(image_format=self._mp.ImageFormat.SRGB, data=image), self._ts_ms)
        if not res.pose_landmarks:
            return None
        kp = blazepose_to_layout(self._landmarks(res.pose_landmarks[0]), image.shape[1],
                                 image.shape[0])
        seen = kp[:, 2] > 0
        kp[seen, 0] += x0
        kp[seen, 1] += y0
        return kp

    def _recentre(self, win: _Window, kp: np.ndarray, w: int, h: int) -> None:
        """Move the window onto the person (and restart its landmarker) when the person's box
        leaves the window's central part or no longer fits its size."""
        box = keypoint_box(kp, 0.3)
        if box is None:
            return
        if win.whole:
            if box[2] < self.whole_frame_leave_height * max(w, h):
                self._to_window(win, kp, w, h)
            return
        x0, y0, side = self._window_for(kp, w, h)
        margin = self.recentre_margin * win.side
        inside = (box[0] - box[3] / 2 >= win.x0 + margin and
                  box[0] + box[3] / 2 <= win.x0 + win.side - margin and
                  box[1] - box[2] / 2 >= win.y0 + margin and
                  box[1] + box[2] / 2 <= win.y0 + win.side - margin)
        if inside and 1.0 / self.resize_ratio <= side / win.side <= self.resize_ratio:
            return
        self.recentred += 1
        self._restart(win)
        win.x0, win.y0, win.side = x0, y0, side

    def _same(self, a: np.ndarray, b: np.ndarray) -> bool:
        ba, bb = keypoint_box(a, 0.3), keypoint_box(b, 0.3)
        if ba is None or bb is None:
            return False
        return oks(a, b, max(ba[2], bb[2]), 0.3, 2.0) > 0.5 or box_iou(ba, bb) > 0.5

    def _drop_duplicate_windows(self, people: List[np.ndarray]) -> None:
        """End windows that follow the same person as a more confident one (in place on
        ``people``, which holds one entry per window that found someone, in window order)."""
        live = [wn for wn in self._windows if wn.missed == 0 and wn.last is not None]
        if len(live) != len(people):
            return
        drop = set()
        for i in range(len(people)):
            for j in range(i + 1, len(people)):
                if i in drop or j in drop or not self._same(people[i], people[j]):
                    continue
                worse = i if np.sum(people[i][:, 2]) < np.sum(people[j][:, 2]) else j
                drop.add(worse)
        for k in sorted(drop, reverse=True):
            self._end(live[k])
            del people[k]
