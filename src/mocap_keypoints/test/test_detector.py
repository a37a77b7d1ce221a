import numpy as np
import pytest

from mocap_core.skeleton import BLAZEPOSE_TO_LAYOUT, KEYPOINT_INDEX, NUM_KEYPOINTS
from mocap_keypoints.detector import (BlazePoseDetector, Detector, blazepose_to_layout,
                                      create_detector)

BODY = ('left_shoulder', 'right_shoulder', 'left_hip', 'right_hip', 'left_knee', 'right_knee',
        'left_ankle', 'right_ankle')


def _landmarks(presence=True):
    rng = np.random.default_rng(5)
    lm = np.zeros((33, 4))
    lm[:, 0] = rng.uniform(0, 1, 33)
    lm[:, 1] = rng.uniform(0, 1, 33)
    lm[:, 2] = rng.uniform(0.2, 1, 33)
    lm[:, 3] = rng.uniform(0.5, 1, 33) if presence else np.nan
    return lm


def test_mapping_to_layout_in_pixels_with_visibility_times_presence():
    lm = _landmarks()
    kp = blazepose_to_layout(lm, 640, 360)
    assert kp.shape == (NUM_KEYPOINTS, 3)
    for k, src in enumerate(BLAZEPOSE_TO_LAYOUT):
        if src < 0:
            assert np.all(kp[k] == 0)  # BlazePose has no small toe: confidence 0
        else:
            np.testing.assert_allclose(kp[k], [lm[src, 0] * 640, lm[src, 1] * 360,
                                               lm[src, 2] * lm[src, 3]])
    assert kp[KEYPOINT_INDEX['left_big_toe'], 2] > 0  # foot_index -> big toe
    assert kp[KEYPOINT_INDEX['right_heel'], 2] > 0


def test_mapping_without_presence_uses_visibility_and_sanitises():
    lm = _landmarks(presence=False)
    lm[11, 0] = np.nan     # left shoulder broken
    lm[0, 2] = 1.7         # out-of-range visibility
    kp = blazepose_to_layout(lm, 100, 100)
    np.testing.assert_allclose(kp[KEYPOINT_INDEX['left_knee'], 2], lm[25, 2])
    assert np.all(kp[KEYPOINT_INDEX['left_shoulder']] == 0)
    assert kp[KEYPOINT_INDEX['nose'], 2] == 1.0
    with pytest.raises(ValueError, match='33, 4'):
        blazepose_to_layout(np.zeros((17, 4)), 10, 10)


def test_blazepose_on_the_real_clip(clip_detections, clip, fully_visible):
    """The issue's acceptance criterion on the committed clip, on the detector alone."""
    dets, times = clip_detections
    assert all(d.shape == (1, NUM_KEYPOINTS, 3) for d in dets)
    kp = np.concatenate(dets)
    visible = fully_visible
    assert len(visible) == len(kp) == clip[1]['frames'] and visible.sum() >= 0.9 * len(kp)
    conf = kp[:, [KEYPOINT_INDEX[n] for n in BODY], 2]
    good = np.all(conf > 0.5, axis=1)[visible]
    assert good.mean() >= 0.9, f'only {good.mean():.0%} of fully visible frames confident'
    # Plausible geometry: inside the image, upright, not mirrored (he faces the camera).
    seen = kp[..., 2] > 0.5
    assert np.all(kp[..., 0][seen] > -20) and np.all(kp[..., 0][seen] < 660)
    assert np.all(kp[..., 1][seen] > -20) and np.all(kp[..., 1][seen] < 380)
    i = KEYPOINT_INDEX
    assert np.mean(kp[:, i['left_ankle'], 1] > kp[:, i['left_hip'], 1]) > 0.95
    assert np.mean(kp[:, i['left_shoulder'], 0] > kp[:, i['right_shoulder'], 0]) > 0.8
    assert np.all(kp[:, [i['left_small_toe'], i['right_small_toe']], 2] == 0)
    assert np.all((kp[..., 2] >= 0) & (kp[..., 2] <= 1))
    assert np.median(times) < 0.5  # sanity only; speed is measured by the benchmark


def test_no_person_gives_an_empty_array():
    with BlazePoseDetector(tracking=False) as det:
        assert isinstance(det, Detector)
        out = det.detect(np.full((240, 320, 3), 128, np.uint8))
        assert out.shape == (0, NUM_KEYPOINTS, 3)
        gray = det.detect(np.zeros((240, 320), np.uint8))  # grayscale is accepted
        assert gray.shape == (0, NUM_KEYPOINTS, 3)


@pytest.mark.parametrize('image, reason', [
    (None, 'empty frame'),
    (np.zeros((0, 0, 3), np.uint8), 'empty frame'),
    (np.zeros((100, 100, 3), np.float32), 'pixel type'),
    (np.zeros((8, 8, 3), np.uint8), 'too small'),
    (np.zeros((100, 100, 2), np.uint8), 'shape'),
])
def test_bad_images_raise_value_error(image, reason):
    with BlazePoseDetector() as det:
        with pytest.raises(ValueError, match=reason):
            det.detect(image)


def test_detector_choices():
    with pytest.raises(ValueError, match='only BlazePose full'):
        BlazePoseDetector(model_complexity=2)
    with pytest.raises(ValueError, match='unknown detector'):
        create_detector('openpose_gpu')
    with pytest.raises(ValueError, match='min_detection_confidence'):
        BlazePoseDetector(min_detection_confidence=1.5)
    det = create_detector('blazepose', tracking=False)
    det.close()
    with pytest.raises(RuntimeError, match='closed'):
        det.detect(np.zeros((64, 64, 3), np.uint8))
