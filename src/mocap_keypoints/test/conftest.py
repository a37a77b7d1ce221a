"""Fixtures of the mocap_keypoints unit tests: the committed test clip and BlazePose on it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[3]
CLIP = ROOT / 'data' / 'video_example' / 'taiji_640x360.mp4'
CLIP_INFO = json.loads(CLIP.with_suffix('.json').read_text())


@pytest.fixture(scope='session')
def clip():
    """(path of the test clip, its description from taiji_640x360.json)."""
    return CLIP, CLIP_INFO


@pytest.fixture(scope='session')
def repo_root():
    return ROOT


@pytest.fixture(scope='session')
def fully_visible():
    """Boolean mask of the clip's frames in which the person is fully visible."""
    mask = np.zeros(CLIP_INFO['frames'], dtype=bool)
    for a, b in CLIP_INFO['person_fully_visible']:
        mask[a:b + 1] = True
    return mask


@pytest.fixture(scope='session')
def clip_frames():
    from mocap_keypoints.sources import VideoSource

    with VideoSource(CLIP, start_ns=0) as src:
        frames = list(src)
    assert len(frames) == CLIP_INFO['frames']
    return frames


@pytest.fixture(scope='session')
def clip_detections(clip_frames):
    """(frames, 1, 23, 3) BlazePose keypoints of every frame (tracking mode) and the
    per-frame detector times in seconds."""
    import time

    from mocap_keypoints.detector import BlazePoseDetector

    out, times = [], []
    with BlazePoseDetector() as det:
        for f in clip_frames:
            t0 = time.perf_counter()
            out.append(det.detect(f.image))
            times.append(time.perf_counter() - t0)
    return out, times
