"""Reading recorded OpenPose JSON detections into the 23-point layout (no ROS imports).

OpenPose writes one file per frame, ``<prefix>_<12-digit frame>_keypoints.json``::

    {"version": 1.2, "people": [{"pose_keypoints_2d": [x0, y0, c0, ..., x24, y24, c24], ...}]}

with BODY_25 keypoints in pixels (origin top-left) and ``0, 0, 0`` for a joint that was not
detected. :func:`read_openpose_file` maps them onto :data:`mocap_core.skeleton.KEYPOINT_NAMES`
(:data:`~mocap_core.skeleton.BODY25_TO_LAYOUT`); COCO-18 files (18 keypoints, no feet) are
accepted too, with the foot points at confidence 0.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import List, Tuple

import numpy as np

from ..skeleton import BODY25_TO_LAYOUT, NUM_KEYPOINTS

# COCO-18 (OpenPose's older body model) index for each layout keypoint, -1 = missing.
_COCO18_TO_LAYOUT = (0, 15, 14, 17, 16, 5, 2, 6, 3, 7, 4, 11, 8, 12, 9, 13, 10,
                     -1, -1, -1, -1, -1, -1)
_FRAME_RE = re.compile(r'(\d+)(?:_keypoints)?\.json$')


class OpenPoseError(ValueError):
    """A malformed OpenPose JSON file; the message names the file."""


def parse_people(data: dict, source: str = '<json>') -> np.ndarray:
    """OpenPose JSON object -> (P, 23, 3) keypoints (u px, v px, confidence), P >= 0.

    Raises:
        OpenPoseError: no ``people`` list, or a person whose ``pose_keypoints_2d`` is not a
            list of 25*3 (BODY_25) or 18*3 (COCO) numbers.
    """
    people = data.get('people') if isinstance(data, dict) else None
    if not isinstance(people, list):
        raise OpenPoseError(f'{source}: no "people" list')
    out = np.zeros((len(people), NUM_KEYPOINTS, 3))
    for p, person in enumerate(people):
        flat = person.get('pose_keypoints_2d') if isinstance(person, dict) else None
        try:
            values = np.asarray(flat, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            raise OpenPoseError(f'{source}: person {p} has no numeric pose_keypoints_2d') from None
        if values.size == 25 * 3:
            mapping = BODY25_TO_LAYOUT
        elif values.size == 18 * 3:
            mapping = _COCO18_TO_LAYOUT
        else:
            raise OpenPoseError(f'{source}: person {p} has {values.size} values in '
                                'pose_keypoints_2d, expected 25 x 3 (BODY_25) or 18 x 3 (COCO)')
        arr = values.reshape(-1, 3)
        for k, src in enumerate(mapping):
            if src >= 0:
                out[p, k] = arr[src]
    # (0, 0, 0) means "not detected"; non-finite values too.
    bad = ~np.all(np.isfinite(out), axis=-1) | (out[..., 2] <= 0)
    out[bad] = 0.0
    out[..., 2] = np.clip(out[..., 2], 0.0, 1.0)
    return out


def read_openpose_file(path: str | Path) -> np.ndarray:
    """Read one OpenPose JSON file -> (P, 23, 3); raises OpenPoseError naming the file."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise OpenPoseError(f'{path}: cannot read JSON ({exc})') from None
    return parse_people(data, str(path))


def list_openpose_files(directory: str | Path) -> List[Tuple[int, Path]]:
    """(frame index, path) of every ``*.json`` in ``directory``, ordered by frame index.

    The frame index is the last run of digits in the name (``..._000000000042_keypoints.json``
    -> 42); files without one are ordered after, by name. Raises FileNotFoundError when the
    directory does not exist or holds no JSON file.
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise FileNotFoundError(f'OpenPose directory not found: {directory}')
    files = sorted(directory.glob('*.json'))
    if not files:
        raise FileNotFoundError(f'no *.json files in {directory}')
    indexed = []
    for n, f in enumerate(files):
        m = _FRAME_RE.search(f.name)
        indexed.append((int(m.group(1)) if m else 10**12 + n, f))
    indexed.sort(key=lambda t: (t[0], t[1].name))
    return indexed


def keypoint_extent(keypoints: np.ndarray) -> Tuple[float, float]:
    """Largest u and v over detected keypoints of a (..., 23, 3) array (0 if none)."""
    seen = keypoints[..., 2] > 0
    if not np.any(seen):
        return 0.0, 0.0
    return float(keypoints[..., 0][seen].max()), float(keypoints[..., 1][seen].max())


def infer_image_size(frames: List[Tuple[int, Path]], sample: int = 60) -> Tuple[int, int]:
    """Smallest 'standard' image size containing the keypoints of the first ``sample`` frames
    (OpenPose JSON does not record the image size)."""
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
