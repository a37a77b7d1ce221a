"""Helpers of ``mocap bench recall`` (mocap_keypoints.recall_bench): the settings parsed, a
detection matched to the true person, the pooled figures and the report."""

import numpy as np
import pytest

from mocap_core.skeleton import JOINT_INDEX, KEYPOINT_INDEX, NUM_JOINTS, NUM_KEYPOINTS
from mocap_keypoints.recall_bench import (_finite, clip_dirs, match, parse_variant, render,
                                          summarise)


def test_variants_are_parsed():
    assert parse_variant('coarse:search_min_person_fraction=1') == \
        ('coarse', {'search_min_person_fraction': 1.0})
    assert parse_variant('base') == ('base', {})
    assert parse_variant('x:a=1,b=0.5') == ('x', {'a': 1.0, 'b': 0.5})
    with pytest.raises(ValueError):
        parse_variant('x:a')


def _person(uv):
    kp = np.zeros((NUM_KEYPOINTS, 3))
    for name, j in JOINT_INDEX.items():
        if name in KEYPOINT_INDEX:
            kp[KEYPOINT_INDEX[name], :2] = uv[j]
            kp[KEYPOINT_INDEX[name], 2] = 0.9
    return kp


def test_a_detection_is_the_person_only_near_the_true_joints():
    rng = np.random.default_rng(0)
    uv = rng.uniform(100, 200, (NUM_JOINTS, 2))
    near = _person(uv + 3.0)                  # 3 px off a person 100 px high: 4 %
    far = _person(uv + 60.0)                  # somebody else
    err, others = match(np.stack([far, near]), uv, 100.0)
    assert err == pytest.approx(np.hypot(3, 3) / 100) and others == 1
    err, others = match(far[None], uv, 100.0)
    assert err is None and others == 1
    # keypoints the detector is not sure of are not compared: a guess far off does not
    # make the person a miss, and a detection with too few sure keypoints is not the person
    guess = near.copy()
    guess[KEYPOINT_INDEX['left_ankle']] = [900.0, 900.0, 0.1]
    assert match(guess[None], uv, 100.0)[0] == pytest.approx(np.hypot(3, 3) / 100)
    unsure = near.copy()
    unsure[:, 2] = 0.1
    assert match(unsure[None], uv, 100.0) == (None, 1)
    assert match(np.zeros((0, NUM_KEYPOINTS, 3)), uv, 100.0) == (None, 0)


def test_summary_counts_only_the_frames_where_the_person_can_be_found():
    clip = {'clip': 'a', 'frames': 4, 'size': '64x48', 'height': [40.0, 50.0, 70.0, 200.0],
            'counted': [False, True, True, True],
            'one': {'found': [True, True, False, True], 'error': [0.01, 0.02, np.nan, 0.04],
                    'false': [3, 1, 1, 0], 'ms': [1.0, 2.0, 3.0, 4.0]},
            'two': {'found': [False, False, False, False], 'error': [np.nan] * 4,
                    'false': [0] * 4, 'ms': [1.0] * 4}}
    s = summarise([clip], ['one', 'two'])
    assert s['one']['frames'] == 3 and s['one']['recall'] == pytest.approx(2 / 3)
    assert s['one']['by_height']['48-64']['recall'] == 1.0
    assert s['one']['by_height']['64-96']['recall'] == 0.0
    # the frame not counted (the person 40 px high) is left out of the error and the others
    assert s['one']['error_median'] == pytest.approx(0.03)
    assert s['one']['false_per_1000'] == pytest.approx(2000 / 3) and s['one']['never_found'] == []
    assert s['one']['ms_median'] == 2.5
    assert s['two']['never_found'] == ['a'] and s['two']['recall'] == 0.0
    text = render(s, [clip], {'one': {}, 'two': {'search_min_person_fraction': 1.0}}, [])
    assert '| **recall** | **66.7 %** | **0.0 %** |' in text
    assert '| a | 64x48 | 60 | 67 % | 0 % |' in text


def test_no_clip_measured_is_an_error_and_the_json_is_strict():
    with pytest.raises(ValueError):
        summarise([], ['one'])
    assert _finite({'a': [1.0, float('nan')], 'b': {'c': float('inf')}, 'd': 2}) == \
        {'a': [1.0, None], 'b': {'c': None}, 'd': 2}


def test_clip_folders_are_found_once(tmp_path):
    for split in ('u', 't'):
        for name in ('c1', 'c2'):
            d = tmp_path / split / name
            d.mkdir(parents=True)
            (d / 'data.npz').write_bytes(b'')
            (d / 'video.mp4').write_bytes(b'')
    (tmp_path / 'u' / 'empty').mkdir()
    got = clip_dirs([tmp_path / 'u', tmp_path / 't'])
    assert [p.parent.name + '/' + p.name for p in got] == ['u/c1', 'u/c2']
    assert clip_dirs([tmp_path / 't' / 'c2']) == [tmp_path / 't' / 'c2']
