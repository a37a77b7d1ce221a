"""Approximate intrinsics fixed once per stream (mocap_lifter.intrinsics)."""

import numpy as np
import pytest

from mocap_core.camera import CameraIntrinsics
from mocap_lifter.intrinsics import (COMMON_IMAGE_SIZES, StreamIntrinsics, common_image_size,
                                     keypoint_extent)


def _person(u_max: float, v_max: float, seen: int = 23) -> np.ndarray:
    """(23, 3) keypoints spread up to (u_max, v_max), the first ``seen`` of them seen."""
    kp = np.zeros((23, 3))
    kp[:, 0] = np.linspace(0.5 * u_max, u_max, 23)
    kp[:, 1] = np.linspace(0.2 * v_max, v_max, 23)[::-1]
    kp[:seen, 2] = 0.8
    return kp


def test_keypoint_extent_counts_seen_finite_points_only():
    kp = _person(700.0, 650.0)
    kp[3] = [5000.0, 5000.0, 0.0]           # unseen: ignored
    kp[4] = [np.nan, 100.0, 0.9]            # not finite: ignored
    assert keypoint_extent(kp) == (700.0, 650.0)
    assert keypoint_extent(np.zeros((23, 3))) is None


@pytest.mark.parametrize('u, v, size', [
    (300, 400, (640, 480)), (650, 700, (1280, 720)), (1400, 500, (1920, 1080)),
    (1000, 1500, (1080, 1920)), (1500, 1500, (3840, 2160)), (660, 470, (1280, 720)),
    (1300, 730, (1280, 720)),                # within the edge tolerance
    (5000, 3000, (7680, 4320))])
def test_common_image_size(u, v, size):
    assert common_image_size(u, v) == size
    assert size in COMMON_IMAGE_SIZES or size == (7680, 4320)


def test_keypoint_estimate_is_fixed_after_the_warmup_and_ignores_outliers():
    est = StreamIntrinsics(60.0, warmup_frames=10)
    assert est.current is None and est.source == ''
    assert est.describe() == 'estimating from keypoints (0/10 frames)'
    rng = np.random.default_rng(0)
    for _ in range(9):
        est.observe(_person(600 + 60 * rng.random(), 600 + 50 * rng.random()))
        assert est.current is None
    est.observe(_person(1700.0, 1000.0))     # one stray detection: above the 90th percentile
    intr = est.current
    assert intr is not None and (intr.width, intr.height) == (1280, 720)
    assert intr == CameraIntrinsics.from_fov(1280, 720, 60.0) and intr.approximate
    assert est.source == 'keypoints'
    assert est.describe() == 'approximate 1280x720, fov 60 deg (from keypoints)'
    # frozen: later frames, wherever the person goes, change nothing
    for _ in range(30):
        est.observe(_person(1900.0, 1070.0))
    assert est.current is intr


def test_freeze_early_uses_what_was_seen():
    est = StreamIntrinsics(50.0, warmup_frames=10)
    assert not est.freeze()                  # nothing seen: nothing to freeze
    est.observe(_person(400.0, 300.0))
    assert est.freeze() and (est.current.width, est.current.height) == (640, 480)


def test_camera_info_wins_and_a_restart_forgets_the_keypoint_estimate():
    est = StreamIntrinsics(60.0, warmup_frames=2)
    est.observe(_person(600.0, 470.0))
    est.observe(_person(600.0, 470.0))
    assert est.source == 'keypoints'
    est.restart()
    assert est.current is None
    est.set_image_size(1920, 1080)           # an uncalibrated camera_info
    assert est.source == 'image size'
    assert est.current == CameraIntrinsics.from_fov(1920, 1080, 60.0)
    assert 'approximate 1920x1080, fov 60 deg (from the camera_info image size)' == \
        est.describe()
    calibrated = CameraIntrinsics(1920, 1080, 1400.0, 1400.0, 960.0, 540.0)
    est.set_camera_info(calibrated)
    assert est.current is calibrated and est.describe() == 'camera_info'
    est.restart()
    assert est.current is calibrated         # camera info survives a stream restart


def test_invalid_arguments():
    with pytest.raises(ValueError):
        StreamIntrinsics(0.5)
    with pytest.raises(ValueError):
        StreamIntrinsics(60.0, warmup_frames=0)
    with pytest.raises(ValueError):
        StreamIntrinsics().set_image_size(0, 480)
