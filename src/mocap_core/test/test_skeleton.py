import numpy as np
import pytest

from mocap_core import skeleton as sk


def test_layout_sizes_and_names():
    assert sk.NUM_KEYPOINTS == 23
    assert sk.KEYPOINT_NAMES[0] == 'nose' and sk.KEYPOINT_NAMES[22] == 'right_heel'
    assert sk.JOINT_NAMES[0] == 'pelvis' and sk.NUM_JOINTS == 18
    assert len(set(sk.JOINT_NAMES)) == sk.NUM_JOINTS


def test_parents_topological_and_limbs_contiguous():
    assert sk.PARENTS[0] == -1
    assert all(0 <= p < j for j, p in enumerate(sk.PARENTS) if j > 0)
    # every joint's subtree is a contiguous index range (depth-first order, Pinocchio needs it)
    for j in range(sk.NUM_JOINTS):
        sub = {j}
        for k in range(j + 1, sk.NUM_JOINTS):
            if sk.PARENTS[k] in sub:
                sub.add(k)
        assert sorted(sub) == list(range(j, j + len(sub)))


@pytest.mark.parametrize('perm,names', [(sk.JOINT_MIRROR, sk.JOINT_NAMES),
                                        (sk.KEYPOINT_MIRROR, sk.KEYPOINT_NAMES)])
def test_mirror_is_involution_swapping_sides(perm, names):
    perm = np.asarray(perm)
    assert np.array_equal(perm[perm], np.arange(len(names)))
    for i, j in enumerate(perm):
        a, b = names[i], names[j]
        if a.startswith('left_'):
            assert b == 'right_' + a[5:]
        elif not a.startswith('right_'):
            assert i == j


def test_detector_maps_point_at_matching_names():
    body25 = ['nose', 'neck', 'right_shoulder', 'right_elbow', 'right_wrist', 'left_shoulder',
              'left_elbow', 'left_wrist', 'mid_hip', 'right_hip', 'right_knee', 'right_ankle',
              'left_hip', 'left_knee', 'left_ankle', 'right_eye', 'left_eye', 'right_ear',
              'left_ear', 'left_big_toe', 'left_small_toe', 'left_heel', 'right_big_toe',
              'right_small_toe', 'right_heel']
    assert [body25[i] for i in sk.BODY25_TO_LAYOUT] == list(sk.KEYPOINT_NAMES)
    blaze = {0: 'nose', 2: 'left_eye', 5: 'right_eye', 7: 'left_ear', 8: 'right_ear',
             11: 'left_shoulder', 12: 'right_shoulder', 13: 'left_elbow', 14: 'right_elbow',
             15: 'left_wrist', 16: 'right_wrist', 23: 'left_hip', 24: 'right_hip',
             25: 'left_knee', 26: 'right_knee', 27: 'left_ankle', 28: 'right_ankle',
             29: 'left_heel', 30: 'right_heel', 31: 'left_big_toe', 32: 'right_big_toe'}
    for k, src in enumerate(sk.BLAZEPOSE_TO_LAYOUT):
        if src < 0:
            assert 'small_toe' in sk.KEYPOINT_NAMES[k]
        else:
            assert blaze[src] == sk.KEYPOINT_NAMES[k]


def test_bone_groups_cover_every_bone_once_and_pairs_are_mirrors():
    covered = [j for _, js in sk.BONE_GROUPS for j in js]
    assert sorted(covered) == sorted(sk.JOINT_NAMES[1:])
    for _, js in sk.BONE_GROUPS:
        if len(js) == 2:
            a, b = (sk.JOINT_INDEX[n] for n in js)
            assert sk.JOINT_MIRROR[a] == b


def test_skeleton_from_group_lengths_is_symmetric_and_roundtrips():
    rng = np.random.default_rng(0)
    lengths = rng.uniform(0.05, 0.5, sk.NUM_BONE_GROUPS)
    s = sk.Skeleton.from_group_lengths(lengths)
    assert s.is_symmetric()
    np.testing.assert_allclose(s.group_lengths(), lengths)
    np.testing.assert_allclose(np.linalg.norm(sk.REST_DIRECTIONS[1:], axis=-1), 1.0)


def test_rest_pose_feet_flat_on_floor():
    s = sk.Skeleton.default()
    pos = s.rest_positions()
    h = s.rest_root_height()
    contacts = {n: pos[j] + p for n, (j, p) in s.contact_points().items()}
    for p in contacts.values():
        assert p[2] == pytest.approx(-h)
    assert contacts['left_toe'][0] > contacts['left_heel'][0]  # toes point forward (+x)
    assert pos[sk.JOINT_INDEX['left_wrist'], 1] > 0.5          # T-pose, left arm along +y
    assert 1.6 < s.height() < 1.9


def test_invalid_skeletons_raise():
    with pytest.raises(ValueError):
        sk.Skeleton(offsets=np.zeros((5, 3)))
    with pytest.raises(ValueError):
        sk.Skeleton.from_group_lengths(np.ones(sk.NUM_BONE_GROUPS - 1))
    with pytest.raises(ValueError):
        sk.Skeleton.from_lengths_dict({'tail': 1.0})
    with pytest.raises(ValueError):
        sk.Skeleton.from_group_lengths(-np.ones(sk.NUM_BONE_GROUPS))
    bad = np.zeros((sk.NUM_JOINTS, 3))
    bad[3, 1] = np.nan
    with pytest.raises(ValueError):
        sk.Skeleton(offsets=bad)
    with pytest.raises(KeyError, match='known'):
        sk.joint_index('tail')


def test_scaled_skeleton_and_its_stature():
    skel = sk.Skeleton.default()
    big = skel.scaled(1.1)
    np.testing.assert_allclose(big.bone_lengths(), 1.1 * skel.bone_lengths())
    np.testing.assert_allclose(big.height(), 1.1 * skel.height())
    # the stature map is affine: scaling by k moves the stature by slope * (k - 1) * height
    assert abs(big.stature() - skel.stature() - sk.STATURE_SLOPE * 0.1 * skel.height()) < 1e-9
    assert 1.4 < skel.stature() < 2.1
    for bad in (0.0, -1.0, float('nan')):
        with pytest.raises(ValueError):
            skel.scaled(bad)
