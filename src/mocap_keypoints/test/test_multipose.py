"""The multi-person BlazePose detector (mocap_keypoints.multipose) on the committed clip: the
bundle builds offline from the wheel, one person comes out as the single-person detector
sees it, and two people side by side are both found, each where the single-person detector
finds them alone."""

import numpy as np
import pytest

from mocap_core.skeleton import KEYPOINT_INDEX, NUM_KEYPOINTS
from mocap_keypoints.multipose import BlazePoseMultiDetector, pose_bundle

BODY = [KEYPOINT_INDEX[n] for n in ('left_shoulder', 'right_shoulder', 'left_hip', 'right_hip',
                                    'left_knee', 'right_knee', 'left_ankle', 'right_ankle')]

SWAPPED = [BODY[i ^ 1] for i in range(len(BODY))]     # BODY is in (left, right) pairs


def test_bundle_is_built_from_the_wheel(tmp_path):
    import zipfile
    path = pose_bundle(tmp_path)
    assert path.parent == tmp_path and path.stat().st_size > 1_000_000
    with zipfile.ZipFile(path) as z:
        assert sorted(z.namelist()) == ['pose_detector.tflite', 'pose_landmarks_detector.tflite']
    assert pose_bundle(tmp_path) == path                  # cached


def _error_px(a, b):
    both = (a[:, BODY, 2] > 0.5) & (b[:, BODY, 2] > 0.5)
    d = np.linalg.norm(a[:, BODY, :2] - b[:, BODY, :2], axis=-1)
    return np.median(d[both]), both.mean()


def test_one_person_as_the_single_person_detector(clip_frames, clip_detections, fully_visible):
    single = np.concatenate(clip_detections[0])
    multi = []
    with BlazePoseMultiDetector(max_persons=4) as det:
        for f in clip_frames:
            got = det.detect(f.image)
            assert got.shape[1:] == (NUM_KEYPOINTS, 3) and len(got) <= 1
            multi.append(got[0] if len(got) else np.zeros((NUM_KEYPOINTS, 3)))
    multi = np.array(multi)
    err, shared = _error_px(multi[fully_visible], single[fully_visible])
    assert shared > 0.85 and err < 6.0, (err, shared)


@pytest.mark.parametrize('threads', [1, 2])
def test_two_people_side_by_side(clip_frames, clip_detections, threads):
    """The clip next to its mirror image: two people, each found where the single-person
    detector finds the person of its half (mirrored for the right half); the two windows'
    landmarkers one after the other or at once in two threads."""
    frames = clip_frames[::3][:30]
    single = np.concatenate(clip_detections[0])[::3][:30]
    w = frames[0].image.shape[1]
    found = []
    scan = len(BlazePoseMultiDetector.regions(2 * w, frames[0].image.shape[0]))
    with BlazePoseMultiDetector(max_persons=4, detection_interval=1, threads=threads) as det:
        for f, s in zip(frames, single):
            img = np.concatenate([f.image, f.image[:, ::-1]], axis=1)
            got = det.detect(img)
            found.append(len(got))
            if len(got) != 2 or s[BODY, 2].min() < 0.5:
                continue
            left = got[np.argmin(got[:, BODY, 0].mean(axis=1))]
            right = got[np.argmax(got[:, BODY, 0].mean(axis=1))]
            assert np.median(np.abs(left[BODY, :2] - s[BODY, :2])) < 10.0
            # the mirror image swaps left and right: its left shoulder is the mirrored right
            mirrored = 2 * w - 1 - s[SWAPPED, 0]
            assert np.median(np.abs(right[BODY, 0] - mirrored)) < 10.0
    # every region has been scanned once after ``scan`` frames
    assert np.mean(np.array(found[scan:]) == 2) >= 0.8, found


def test_bad_parameters_and_closing():
    with pytest.raises(ValueError):
        BlazePoseMultiDetector(max_persons=0)
    with pytest.raises(ValueError):
        BlazePoseMultiDetector(detection_interval=0)
    with pytest.raises(ValueError):
        BlazePoseMultiDetector(threads=0)
    det = BlazePoseMultiDetector()
    det.close()
    det.close()
    with pytest.raises(RuntimeError):
        det.detect(np.zeros((64, 64, 3), np.uint8))
