"""mocap_lifter.signatures: the figures of ``mocap eval signatures`` from clip signatures."""

import numpy as np
import pytest

from mocap_core.tracking import signature_distance
from mocap_lifter.signatures import ClipSignatures, summarise


def test_signature_distance_is_the_median_relative_difference():
    ref = np.array([0.4, 0.4, 0.2])
    assert signature_distance(ref * [1.01, 1.02, 1.10], ref) == pytest.approx(0.02)
    assert signature_distance(ref, ref) == 0.0
    assert signature_distance(ref[:2], ref) == float('inf')


def test_summary_separates_one_person_twice_from_two_people():
    rng = np.random.default_rng(0)
    clips = []
    for k in range(6):
        truth = np.full(10, 0.3) * (1.0 + 0.05 * k)          # 5 % apart from clip to clip
        est = truth * (1.0 + rng.normal(0, 0.002, 10))
        clips.append(ClipSignatures(f'c{k}', truth, est, held=True, frames=200,
                                    halves=[est * 1.004, est * 0.998]))
    res = summarise(clips, tolerances=(0.01, 0.03))
    assert res['same_person']['n'] == 6 and res['different_people']['n'] == 15
    assert res['same_person']['median'] == pytest.approx(0.006, abs=0.001)
    assert res['different_people']['median'] > 0.04
    assert res['size_correlation'] > 0.99
    one, three = res['tolerances']
    assert one['same_accepted'] == 1.0 and one['different_accepted'] == 0.0
    assert three['different_accepted'] < 0.5
    # proportions: every clip the same shape, so two people are as close as one
    assert res['proportions']['different_people']['median'] < 0.01
