"""Retargeting BVH clips to the pipeline skeleton (mocap_core.data.retarget).

Most tests need the real motion capture in ``../shared/data`` (``MOCAP_SHARED_DATA``) and skip
without it; one clip per format, a few hundred frames each.
"""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from mocap_core.data.bvh import BVH, CMU_ASF_UNIT, iter_bvh_archive, parse_bvh, read_bvh
from mocap_core.data.retarget import (CMU_ARM_TWIST_DEG, FORMATS, detect_format,
                                      resolve_unit_scale, retarget, retarget_report)
from mocap_core.kinematics import forward_kinematics
from mocap_core.rotations import (euler_to_matrix, matrix_to_euler, quat_angle,
                                  quat_multiply, quat_rotate, quat_to_axis_angle)
from mocap_core.skeleton import (BONE_GROUP_NAMES, JOINT_INDEX, NUM_JOINTS, PARENTS,
                                 REST_DIRECTIONS)

REPO = Path(__file__).resolve().parents[3]
DATA = Path(os.environ.get('MOCAP_SHARED_DATA', REPO.parent / 'shared' / 'data'))
NEEDS_DATA = 'needs ../shared/data (not shipped with the repository)'

FILES = {
    'cmu_mb2': ('cmu_bvh', 'mb2_120fps', '02_01.bvh'),            # walk, 343 frames
    'cmu_asf': ('cmu_bvh', 'asf_names_30fps', '16_01.bvh'),       # jumps, 322 frames
    'cmu_daz': ('cmu_bvh', 'daz_friendly_120fps', '08_01.bvh'),   # walk, 278 frames
}
BANDAI_CLIP = 'dataset-1_walk_normal_001.bvh'                     # walk, 195 frames


def data_path(*parts: str) -> Path:
    p = DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(NEEDS_DATA)
    return p


@pytest.fixture(scope='module')
def sources() -> dict:
    out = {fmt: read_bvh(data_path(*rel)) for fmt, rel in FILES.items()}
    arc = data_path('bandai_namco_bvh', 'dataset-1_all.tar.xz')
    for _, bvh in iter_bvh_archive(arc, pattern=re.escape(BANDAI_CLIP)):
        out['bandai_namco'] = bvh
    assert 'bandai_namco' in out, f'{BANDAI_CLIP} missing from {arc}'
    return out


@pytest.fixture(scope='module')
def clips(sources) -> dict:
    return {fmt: retarget(bvh) for fmt, bvh in sources.items()}


FORMAT_NAMES = sorted(FORMATS)

# FK error bounds (mm), from the measured errors of these clips (mean / max): mb2 4.4 / 16,
# asf 2.9 / 15, daz 0.2 / 4.8, bandai 0.4 / 5.2. What remains is the source's own deviation
# from the pipeline's rigid symmetric skeleton: the CMU skeletons are left/right asymmetric
# (02_01: thighs 15 mm, upper arms 15 mm apart, so the symmetric mean is ~7.5 mm off at knees
# and elbows), the CMU lumbar pivot lies above the pipeline's pelvis, the clavicles move the
# shoulders (neck = their midpoint), and the head is not exactly on the neck's axis.
MEAN_MM = {'cmu_mb2': 5.0, 'cmu_asf': 4.0, 'cmu_daz': 1.0, 'bandai_namco': 1.0}
MAX_MM = {'cmu_mb2': 25.0, 'cmu_asf': 25.0, 'cmu_daz': 10.0, 'bandai_namco': 10.0}


@pytest.mark.parametrize('fmt', FORMAT_NAMES)
def test_format_detection_and_unit(fmt, sources):
    bvh = sources[fmt]
    assert detect_format(bvh).name == fmt
    expected = CMU_ASF_UNIT if fmt in ('cmu_mb2', 'cmu_asf') else 0.01
    assert resolve_unit_scale(bvh, FORMATS[fmt]) == pytest.approx(expected)


@pytest.mark.parametrize('fmt', FORMAT_NAMES)
def test_fk_reproduces_source_positions(fmt, clips, sources):
    clip = clips[fmt]
    F = sources[fmt].num_frames
    assert clip.rotations.shape == (F, NUM_JOINTS, 4)
    assert clip.root_positions.shape == (F, 3) and clip.source_positions.shape == (F, 18, 3)
    assert clip.fps == pytest.approx(sources[fmt].fps)
    np.testing.assert_allclose(np.linalg.norm(clip.rotations, axis=-1), 1.0, atol=1e-9)
    # quaternions are continuous in time (no sign flips)
    assert np.all(np.sum(clip.rotations[1:] * clip.rotations[:-1], axis=-1) > 0)
    err = clip.fk_error_mm()
    assert err.mean < MEAN_MM[fmt], f'{fmt}: mean FK error {err.mean:.2f} mm'
    assert err.max < MAX_MM[fmt], f'{fmt}: max FK error {err.max:.1f} mm'
    # the hips are exact (the pelvis frame is built on the hip axis), and so is the root
    hips = [JOINT_INDEX['pelvis'], JOINT_INDEX['left_hip'], JOINT_INDEX['right_hip']]
    assert err.per_joint_mean[hips].max() < 1.0
    # the legs are exact where the source legs are symmetric (DAZ, Bandai Namco)
    if fmt in ('cmu_daz', 'bandai_namco'):
        legs = [JOINT_INDEX[f'{s}_{j}'] for s in ('left', 'right')
                for j in ('knee', 'ankle', 'toe')]
        assert err.per_joint_mean[legs].max() < 0.01
    # the same numbers through the public FK and through Pose
    fk = forward_kinematics(clip.skeleton.parents, clip.skeleton.offsets, clip.rotations,
                            clip.root_positions)
    np.testing.assert_allclose(fk.positions, clip.joint_positions(), atol=1e-12)
    np.testing.assert_allclose(clip.pose(7).joint_positions(), fk.positions[7], atol=1e-12)


HUMAN_RANGES_M = {
    'hip': (0.04, 0.12), 'thigh': (0.35, 0.50), 'shin': (0.35, 0.50), 'foot': (0.08, 0.18),
    'spine': (0.12, 0.30), 'neck': (0.10, 0.35), 'head': (0.06, 0.20),
    'clavicle': (0.08, 0.22), 'upper_arm': (0.22, 0.35), 'forearm': (0.18, 0.30),
}


@pytest.mark.parametrize('fmt', FORMAT_NAMES)
def test_bone_lengths_in_human_ranges(fmt, clips):
    skel = clips[fmt].skeleton
    assert skel.is_symmetric()
    for name, length in zip(BONE_GROUP_NAMES, skel.group_lengths()):
        lo, hi = HUMAN_RANGES_M[name]
        assert lo <= length <= hi, f'{fmt}: {name} = {length:.3f} m'
    assert 1.35 <= skel.height() <= 2.0


def _median_axis(clip, joint: str, min_deg: float = 30.0) -> np.ndarray:
    rv = quat_to_axis_angle(clip.rotations[:, JOINT_INDEX[joint]])
    ang = np.linalg.norm(rv, axis=-1)
    big = ang > np.radians(min_deg)
    assert big.sum() >= 5, f'{joint}: too few bent frames'
    ax = np.mean(rv[big] / ang[big, None], axis=0)
    return ax / np.linalg.norm(ax)


@pytest.mark.parametrize('fmt', FORMAT_NAMES)
def test_knee_and_elbow_are_hinges_in_every_format(fmt, clips):
    """The twist conventions line up across formats: knees bend about +y (flexion positive),
    elbows about -z (left) / +z (right) of their parent's frame. The component along the bone
    (the forearm's pronation, free in the Bandai data) is left out; what is checked is the
    twist of the parent segment, which would show as a tilt of the hinge (30 deg for the CMU
    arms without CMU_ARM_TWIST_DEG)."""
    clip = clips[fmt]
    for joint, hinge, bone in (('left_knee', 1, 2), ('right_knee', 1, 2),
                               ('left_elbow', 2, 1), ('right_elbow', 2, 1)):
        try:
            ax = _median_axis(clip, joint)
        except AssertionError:
            if 'elbow' in joint:      # a clip may keep one arm straight
                continue
            raise
        sign = -1.0 if joint == 'left_elbow' else 1.0
        other = 3 - hinge - bone
        tilt = np.degrees(np.arctan2(abs(ax[other]), sign * ax[hinge]))
        assert tilt < 10.0, f'{fmt} {joint}: hinge axis {ax} tilted {tilt:.1f} deg'


def test_walking_knees_agree_between_cmu_and_bandai(clips):
    """Same motion, different datasets and skeletons: the mean knee flexion of a walk is alike
    (measured: CMU mb2 02_01 30 deg, Bandai Namco walk_normal_001 31 deg)."""
    def mean_knee_deg(clip):
        q = clip.rotations[:, [JOINT_INDEX['left_knee'], JOINT_INDEX['right_knee']]]
        return float(np.degrees(quat_angle(q, np.array([0.0, 0.0, 0.0, 1.0]))).mean())

    cmu, bn = mean_knee_deg(clips['cmu_mb2']), mean_knee_deg(clips['bandai_namco'])
    assert 15.0 < cmu < 45.0 and 15.0 < bn < 45.0
    assert abs(cmu - bn) < 10.0


def _swing_deg(q: np.ndarray) -> np.ndarray:
    """(J,) angle between each joint's child bone in the pose and in the rest pose, for joints
    with one child (the bone direction, whatever the twist about it); NaN otherwise."""
    out = np.full(NUM_JOINTS, np.nan)
    for j in range(1, NUM_JOINTS):
        kids = [k for k, p in enumerate(PARENTS) if p == j]
        if len(kids) == 1:
            r = REST_DIRECTIONS[kids[0]]
            out[j] = np.degrees(np.arccos(np.clip(quat_rotate(q[j], r) @ r, -1.0, 1.0)))
    return out


def test_t_pose_frames_are_near_identity_in_two_formats():
    """Frame 0 of CMU mb2 01_01 (cgspeed's T-pose) and of every DAZ file (the DAZ rest pose)
    are T-poses: every bone is near its rest direction, and the two formats agree. The residue
    is the sources' rest geometry (CMU legs splayed 20 deg, DAZ knees, feet and forearms bent).
    The arms' twist is CMU_ARM_TWIST_DEG: the CMU rest has the upper arms rotated 30 deg about
    their axis relative to the pipeline's rest (elbow hinge vertical)."""
    mb2 = retarget(read_bvh(data_path('cmu_bvh', 'mb2_120fps', '01_01.bvh')), frames=[0])
    daz = retarget(read_bvh(data_path('cmu_bvh', 'daz_friendly_120fps', '02_01.bvh')),
                   frames=[0])
    swings, twists = [], []
    for clip in (mb2, daz):
        sw = _swing_deg(clip.rotations[0])
        assert np.nanmax(sw) < 25.0, sw
        swings.append(sw)
        for side in ('left', 'right'):
            q = clip.rotations[0, JOINT_INDEX[f'{side}_shoulder']]
            # twist about the arm axis (y): the 30 deg arm convention plus the neck frame's
            # pitch (the CMU head is ~10 deg in front of the shoulder line); measured -40
            twists.append(np.degrees(2 * np.arctan2(q[1], q[3])))
    assert np.nanmax(np.abs(swings[0] - swings[1])) < 20.0
    assert all(abs(t - (CMU_ARM_TWIST_DEG - 10.0)) < 8.0 for t in twists), twists
    # by contrast a walking frame is far from the T-pose (arms down)
    walk = retarget(read_bvh(data_path('cmu_bvh', 'daz_friendly_120fps', '02_01.bvh')),
                    frames=[100])
    assert _swing_deg(walk.rotations[0])[JOINT_INDEX['left_shoulder']] > 60


def _rotated_about_up(bvh: BVH, theta_deg: float) -> BVH:
    """Copy of a clip turned by theta about the vertical (BVH y) through the origin, by
    rewriting the root's channels (which must include 3 positions and 3 rotations)."""
    motion = bvh.motion.copy()
    chans = bvh.channels[0]
    s = bvh.channel_start[0]
    pos = [s + chans.index(a + 'position') for a in 'XYZ']
    rot_cols = [s + k for k, c in enumerate(chans) if c.endswith('rotation')]
    order = bvh.rotation_order(0)
    Ry = euler_to_matrix(np.array([np.radians(theta_deg), 0.0, 0.0]), 'YXZ')
    L0 = euler_to_matrix(np.radians(motion[:, rot_cols]), order)
    motion[:, rot_cols] = np.degrees(matrix_to_euler(Ry @ L0, order))
    motion[:, pos] = motion[:, pos] @ Ry.T
    return BVH(bvh.joint_names, bvh.parents, bvh.offsets, bvh.channels, bvh.end_sites,
               bvh.frame_time, motion, bvh.name + ' (rotated)')


@pytest.mark.parametrize('fmt', ['cmu_mb2', 'bandai_namco'])
def test_invariant_to_a_turn_about_the_vertical(fmt, sources, clips):
    theta = 73.0
    clip = clips[fmt]
    turned = retarget(_rotated_about_up(sources[fmt], theta))
    # non-root rotations and the skeleton are unchanged
    np.testing.assert_allclose(turned.skeleton.offsets, clip.skeleton.offsets, atol=1e-9)
    ang = quat_angle(turned.rotations[:, 1:], clip.rotations[:, 1:])
    assert ang.max() < 1e-6
    # the root turns by theta about world z, positions rotate with it
    half = np.radians(theta) / 2
    qz = np.array([0.0, 0.0, np.sin(half), np.cos(half)])
    ang0 = quat_angle(turned.rotations[:, 0], quat_multiply(qz, clip.rotations[:, 0]))
    assert ang0.max() < 1e-6
    Rz = euler_to_matrix(np.array([np.radians(theta), 0.0, 0.0]), 'ZYX')
    np.testing.assert_allclose(turned.root_positions, clip.root_positions @ Rz.T, atol=1e-9)
    np.testing.assert_allclose(turned.source_positions, clip.source_positions @ Rz.T,
                               atol=1e-9)


def test_unit_check_falls_back_to_guess_for_a_file_in_metres(sources):
    bvh = sources['cmu_daz'].slice_frames(slice(0, 40))
    motion = bvh.motion.copy()
    for j, chans in enumerate(bvh.channels):
        for k, c in enumerate(chans):
            if c.endswith('position'):
                motion[:, bvh.channel_start[j] + k] *= 0.01
    metres = BVH(bvh.joint_names, bvh.parents, bvh.offsets * 0.01, bvh.channels,
                 tuple(type(e)(e.parent, e.offset * 0.01) for e in bvh.end_sites),
                 bvh.frame_time, motion, 'daz in metres')
    with pytest.warns(UserWarning, match='guessed'):
        assert resolve_unit_scale(metres, FORMATS['cmu_daz']) == pytest.approx(1.0)
    with pytest.warns(UserWarning, match='guessed'):
        b = retarget(metres)
    a = retarget(bvh)
    np.testing.assert_allclose(a.source_positions, b.source_positions, atol=1e-9)
    np.testing.assert_allclose(a.rotations, b.rotations, atol=1e-9)


def test_unknown_skeleton_is_refused():
    text = ('HIERARCHY\nROOT body\n{\nOFFSET 0 0 0\nCHANNELS 3 Xrotation Yrotation Zrotation\n'
            'End Site\n{\nOFFSET 0 1 0\n}\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n0 0 0\n')
    with pytest.raises(ValueError, match='unknown BVH skeleton'):
        retarget(parse_bvh(text))


def test_retarget_report_on_a_directory(tmp_path, clips):
    shutil.copy(data_path(*FILES['cmu_mb2']), tmp_path / 'a.bvh')
    (tmp_path / 'broken.bvh').write_text('HIERARCHY\nROOT x\n{\n}\n')
    with pytest.warns(UserWarning, match='broken.bvh'):
        rep = retarget_report(tmp_path)
    fmt = rep['formats']['cmu_mb2']
    assert fmt['clips'] == 1 and fmt['frames'] == 343
    assert fmt['mean_mm'] == pytest.approx(clips['cmu_mb2'].fk_error_mm().mean)
    assert rep['clips'][0]['name'].endswith('a.bvh') and not rep['failed']
