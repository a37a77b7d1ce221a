import json
from pathlib import Path

import numpy as np
import pytest

from mocap_core.skeleton import KEYPOINT_INDEX, NUM_KEYPOINTS
from mocap_keypoints.node import infer_image_size, select_persons
from mocap_core.data.openpose import (OpenPoseError, list_openpose_files, parse_people,
                                      read_openpose_file)

EXAMPLE = Path(__file__).resolve().parents[3] / 'data' / 'openpose_example' / 'seq1'


def test_real_file_maps_body25_to_layout():
    frames = list_openpose_files(EXAMPLE)
    assert len(frames) == 81 and [i for i, _ in frames] == list(range(81))
    kp = read_openpose_file(frames[0][1])
    assert kp.shape == (1, NUM_KEYPOINTS, 3)
    raw = np.array(json.loads(frames[0][1].read_text())['people'][0]['pose_keypoints_2d'])
    raw = raw.reshape(25, 3)
    # BODY_25: 0 nose, 5 LShoulder, 9 RHip, 24 RHeel
    np.testing.assert_allclose(kp[0, KEYPOINT_INDEX['nose']], raw[0])
    np.testing.assert_allclose(kp[0, KEYPOINT_INDEX['left_shoulder']], raw[5])
    np.testing.assert_allclose(kp[0, KEYPOINT_INDEX['right_hip']], raw[9])
    np.testing.assert_allclose(kp[0, KEYPOINT_INDEX['right_heel']], raw[24])
    # the person stands upright: head above hips above ankles (image v grows downwards)
    v = kp[0, :, 1]
    assert v[KEYPOINT_INDEX['nose']] < v[KEYPOINT_INDEX['left_hip']] < \
        v[KEYPOINT_INDEX['left_ankle']]


def test_undetected_and_nan_points_are_unseen():
    flat = [10.0, 20.0, 0.9] * 25
    flat[3:6] = [0.0, 0.0, 0.0]          # neck not detected (not in the layout anyway)
    flat[15 * 3:15 * 3 + 3] = [5, 5, 0]  # REye confidence 0
    flat[0] = float('nan')               # nose x NaN
    kp = parse_people({'people': [{'pose_keypoints_2d': flat}]})
    assert np.all(kp[0, KEYPOINT_INDEX['right_eye']] == 0)
    assert np.all(kp[0, KEYPOINT_INDEX['nose']] == 0)
    assert kp[0, KEYPOINT_INDEX['left_eye'], 2] == pytest.approx(0.9)


def test_coco18_accepted_without_feet():
    kp = parse_people({'people': [{'pose_keypoints_2d': [1.0, 2.0, 0.5] * 18}]})
    assert kp[0, KEYPOINT_INDEX['left_heel'], 2] == 0 and kp[0, KEYPOINT_INDEX['nose'], 2] == 0.5


@pytest.mark.parametrize('content,match', [
    ('{not json', 'cannot read JSON'),
    ('{"version": 1.2}', 'people'),
    ('{"people": [{"pose_keypoints_2d": [1, 2]}]}', 'expected 25 x 3'),
    ('{"people": [{"pose_keypoints_2d": "abc"}]}', 'numeric'),
])
def test_malformed_files_name_the_file(tmp_path, content, match):
    f = tmp_path / 'x_000000000007_keypoints.json'
    f.write_text(content)
    with pytest.raises(OpenPoseError, match=match) as info:
        read_openpose_file(f)
    assert str(f) in str(info.value)


def test_listing_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        list_openpose_files(tmp_path / 'missing')
    with pytest.raises(FileNotFoundError, match='no'):
        list_openpose_files(tmp_path)


def test_select_persons_orders_by_confidence_and_pads():
    people = np.zeros((2, NUM_KEYPOINTS, 3))
    people[0, :, 2] = 0.2
    people[1, :, 2] = 0.8
    out = select_persons(people, 3)
    assert out.shape == (3, NUM_KEYPOINTS, 3)
    assert out[0, 0, 2] == 0.8 and out[1, 0, 2] == 0.2 and np.all(out[2] == 0)
    assert np.all(select_persons(people[:0], 1) == 0)


def test_image_size_inferred_from_keypoints():
    w, h = infer_image_size(list_openpose_files(EXAMPLE))
    assert (w, h) == (1080, 1920) or (w >= 738 and h >= 985)
