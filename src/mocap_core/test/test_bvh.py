"""BVH parsing and FK (mocap_core.data.bvh).

Synthetic files cover the syntax variants; the real-data tests (skipped without
``../shared/data``) check each format's sizes, FK against an independent SciPy reference and
bone lengths in metres.
"""

from __future__ import annotations

import io
import os
import re
import tarfile
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocap_core.data.bvh import (BVH_TO_WORLD, CMU_ASF_UNIT, BVHError, bvh_fk, guess_unit_scale,
                                 iter_bvh_archive, iter_bvh_sources, parse_bvh, read_bvh)

REPO = Path(__file__).resolve().parents[3]
DATA = Path(os.environ.get('MOCAP_SHARED_DATA', REPO.parent / 'shared' / 'data'))
NEEDS_DATA = 'needs ../shared/data (not shipped with the repository)'


def data_path(*parts: str) -> Path:
    p = DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(NEEDS_DATA)
    return p


# A small skeleton with every syntax variant seen in the data (and a few more): CRLF, tabs and
# spaces, 'Joint'/'End site' capitalisation, 6 channels on a non-root joint, a different Euler
# order per joint, a joint with a single rotation channel and one with position channels only.
SYNTH = """HIERARCHY
ROOT Hips
{
\tOFFSET 0.0 0.0 0.0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
\tJoint Chest
\t{
  \t  OFFSET 0 10 1
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\tJOINT Head
\t\t{
\t\t\tOFFSET 0 8 0
\t\t\tCHANNELS 6 Xposition Yposition Zposition Yrotation Zrotation Xrotation
\t\t\tEnd site
\t\t\t{
\t\t\t\tOFFSET 0 5 0
\t\t\t}
\t\t}
\t\tJOINT Arm
\t\t{
\t\t\tOFFSET 4 7 0
\t\t\tCHANNELS 1 Zrotation
\t\t\tEnd Site
\t\t\t{
\t\t\t\tOFFSET 6 0 0
\t\t\t}
\t\t}
\t}
\tJOINT Leg
\t{
\t\tOFFSET 2 -1 0
\t\tCHANNELS 2 Xposition Zposition
\t\tJOINT Foot
\t\t{
\t\t\tOFFSET 0 -9 1
\t\t\tCHANNELS 3 Xrotation Yrotation Zrotation
\t\t\tEnd Site
\t\t\t{
\t\t\t\tOFFSET 0 -1 3
\t\t\t}
\t\t}
\t}
}
MOTION
Frames:\t3
Frame Time: 0.0333333
"""


def _synth_motion(F: int = 3, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    # channels: Hips 6, Chest 3, Head 6, Arm 1, Leg 2, Foot 3
    m = rng.uniform(-90, 90, size=(F, 21))
    m[:, 0:3] = rng.uniform(-50, 50, size=(F, 3))
    m[:, 9:12] = [0.5, 8.0, -0.2]       # Head position channels (near the offset)
    m[:, 16:18] = rng.uniform(1, 3, size=(F, 2))
    return m


def synth_text(F: int = 3, crlf: bool = True) -> str:
    text = SYNTH.replace('Frames:\t3', f'Frames:\t{F}')
    text += '\n'.join(' '.join(f'{v:.6f}' for v in row) for row in _synth_motion(F)) + '\n'
    return text.replace('\n', '\r\n') if crlf else text


def reference_fk(bvh, frame: int):
    """Slow, independent FK of one frame in BVH coordinates (SciPy rotations)."""
    J = bvh.num_joints
    R = [None] * J
    P = [None] * J
    for j in range(J):
        vals = bvh.motion[frame, bvh.channel_start[j]:bvh.channel_start[j] + len(bvh.channels[j])]
        t = np.array(bvh.offsets[j], dtype=float)
        rot = Rotation.identity()
        for ch, v in zip(bvh.channels[j], vals):
            axis = 'XYZ'.index(ch[0])
            if ch.endswith('position'):
                t[axis] = v
            else:  # intrinsic: compose on the right
                rot = rot * Rotation.from_euler(ch[0].lower(), v, degrees=True)
        p = bvh.parents[j]
        if p < 0:
            R[j], P[j] = rot, t
        else:
            R[j], P[j] = R[p] * rot, P[p] + R[p].apply(t)
    ends = [P[e.parent] + R[e.parent].apply(e.offset) for e in bvh.end_sites]
    return np.array(P), np.stack([r.as_matrix() for r in R]), np.array(ends)


def test_parse_synthetic_variants():
    bvh = read_bvh(synth_text())
    assert bvh.joint_names == ('Hips', 'Chest', 'Head', 'Arm', 'Leg', 'Foot')
    assert bvh.parents == (-1, 0, 1, 1, 0, 4)
    assert bvh.num_frames == 3 and bvh.frame_time == pytest.approx(0.0333333)
    assert bvh.num_channels == 21
    assert bvh.channels[2] == ('Xposition', 'Yposition', 'Zposition',
                               'Yrotation', 'Zrotation', 'Xrotation')
    assert [bvh.rotation_order(j) for j in range(6)] == ['ZYX', 'ZXY', 'YZX', 'Z', '', 'XYZ']
    assert [e.parent for e in bvh.end_sites] == [2, 3, 5]
    np.testing.assert_allclose(bvh.end_sites[2].offset, [0, -1, 3])
    np.testing.assert_allclose(bvh.offsets[1], [0, 10, 1])
    np.testing.assert_allclose(bvh.motion, np.round(_synth_motion(3), 6))
    # LF, CRLF, a path and a binary file object all give the same
    lf = read_bvh(synth_text(crlf=False))
    np.testing.assert_array_equal(lf.motion, bvh.motion)
    fobj = read_bvh(io.BytesIO(synth_text().encode()))
    np.testing.assert_array_equal(fobj.motion, bvh.motion)


def test_read_from_path_and_archive(tmp_path):
    p = tmp_path / 'a.bvh'
    p.write_bytes(synth_text().encode())
    assert read_bvh(p).num_frames == 3
    arc = tmp_path / 'clips.tar.xz'
    with tarfile.open(arc, 'w:xz') as tar:
        for name, F in (('x/one.bvh', 2), ('x/two.bvh', 4)):
            data = synth_text(F).encode()
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
        info = tarfile.TarInfo('x/bad.bvh')
        info.size = 5
        tar.addfile(info, io.BytesIO(b'hello'))
        info = tarfile.TarInfo('x/readme.txt')
        info.size = 2
        tar.addfile(info, io.BytesIO(b'hi'))
    with pytest.warns(UserWarning, match='bad.bvh'):
        got = [(n, b.num_frames) for n, b in iter_bvh_archive(arc)]
    assert got == [('x/one.bvh', 2), ('x/two.bvh', 4)]
    assert [n for n, _ in iter_bvh_archive(arc, pattern='two')] == ['x/two.bvh']
    with pytest.raises(BVHError):
        list(iter_bvh_archive(arc, on_error='raise'))
    with pytest.warns(UserWarning):
        names = [n for n, _ in iter_bvh_sources(tmp_path)]
    assert names == [str(p), f'{arc}:x/one.bvh', f'{arc}:x/two.bvh']


@pytest.mark.parametrize('bad,match', [
    ('HIERARCHY\nROOT a\n{\nOFFSET 0 0\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n0\n', 'numbers'),
    ('HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 1 Wrotation\n}\nMOTION\nFrames: 1\n'
     'Frame Time: 0.1\n0\n', 'unknown channel'),
    ('HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\n\nMOTION\nFrames: 1\nFrame Time: 0.1\n\n', 'missing'),
    ('HIERARCHY\nROOT a\n{\n}\n', 'MOTION'),
    ('HIERARCHY\nROOT a\n{\nCHANNELS 1 Xrotation\n}\nMOTION\nFrames: 1\nFrame Time: 0\n1\n',
     'Frame Time'),
    ('HIERARCHY\nROOT a\n{\nCHANNELS 1 Xrotation\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\nnan\n',
     'NaN'),
])
def test_malformed_files_raise_clear_errors(bad, match):
    with pytest.raises(BVHError, match=match):
        parse_bvh(bad)


def test_truncated_motion_keeps_complete_frames():
    text = synth_text(5, crlf=False)
    lines = text.rstrip('\n').split('\n')
    lines[-1] = ' '.join(lines[-1].split()[:7])    # last frame cut in the middle
    with pytest.warns(UserWarning, match='read 4 complete frames'):
        bvh = parse_bvh('\n'.join(lines))
    assert bvh.num_frames == 4


def test_fk_matches_independent_reference_synthetic():
    bvh = read_bvh(synth_text(3))
    fk = bvh_fk(bvh, unit_scale=0.01)
    M = BVH_TO_WORLD
    for f in range(3):
        P, R, E = reference_fk(bvh, f)
        np.testing.assert_allclose(fk.positions[f], 0.01 * P @ M.T, atol=1e-12)
        np.testing.assert_allclose(fk.end_site_positions[f], 0.01 * E @ M.T, atol=1e-12)
        np.testing.assert_allclose(fk.rotations[f], M @ R @ M.T, atol=1e-12)


def test_axis_conversion_is_a_rotation_to_z_up():
    M = BVH_TO_WORLD
    assert np.linalg.det(M) == pytest.approx(1.0)
    np.testing.assert_array_equal(M @ [0, 1, 0], [0, 0, 1])   # y up -> z up
    np.testing.assert_array_equal(M @ [0, 0, 1], [1, 0, 0])   # facing +z -> facing +x
    np.testing.assert_array_equal(M @ [1, 0, 0], [0, 1, 0])   # left +x -> left +y


def test_guess_unit_scale_synthetic_human():
    # a 1.75 m stick figure, written in metres, centimetres, inches and CMU ASF units
    def human(scale):
        o = lambda *v: ' '.join(str(x / scale) for x in v)  # noqa: E731
        return (f'HIERARCHY\nROOT hip\n{{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition '
                f'Zposition Zrotation Yrotation Xrotation\n'
                f'JOINT chest\n{{\nOFFSET {o(0, 0.5, 0)}\nCHANNELS 3 Zrotation Yrotation '
                f'Xrotation\nJOINT hand\n{{\nOFFSET {o(0.8, 0, 0)}\nCHANNELS 3 Zrotation '
                f'Yrotation Xrotation\nEnd Site\n{{\nOFFSET {o(0.1, 0, 0)}\n}}\n}}\n}}\n'
                f'JOINT knee\n{{\nOFFSET {o(0.1, -0.45, 0)}\nCHANNELS 3 Zrotation Yrotation '
                f'Xrotation\nEnd Site\n{{\nOFFSET {o(0, -0.45, 0.1)}\n}}\n}}\n}}\n'
                f'MOTION\nFrames: 1\nFrame Time: 0.01\n' + ' '.join(['0'] * 15) + '\n')
    for scale in (1.0, 0.01, 0.0254, CMU_ASF_UNIT):
        assert guess_unit_scale(parse_bvh(human(scale))) == pytest.approx(scale)


# ---------------------------------------------------------------------------------------------
# real data
# ---------------------------------------------------------------------------------------------
BANDAI_CLIP = 'dataset-1_walk_normal_002.bvh'   # one of the 4 clips with joint_Root translation


@pytest.fixture(scope='module')
def bandai_bvh():
    arc = data_path('bandai_namco_bvh', 'dataset-1_all.tar.xz')
    for _, bvh in iter_bvh_archive(arc, pattern=re.escape(BANDAI_CLIP)):
        return bvh
    pytest.fail(f'{BANDAI_CLIP} not found in {arc}')


def real(fmt, bandai_bvh):
    if fmt == 'bandai':
        return bandai_bvh, 0.01
    rel = {'mb2': ('cmu_bvh', 'mb2_120fps', '02_01.bvh'),
           'daz': ('cmu_bvh', 'daz_friendly_120fps', '02_01.bvh'),
           'asf': ('cmu_bvh', 'asf_names_30fps', '16_01.bvh')}[fmt]
    return read_bvh(data_path(*rel)), (0.01 if fmt == 'daz' else CMU_ASF_UNIT)


# joints, end sites, frames, frame time, first and last joint name (from the READMEs / headers)
EXPECTED = {
    'mb2': (31, 7, 343, 0.008333, 'Hips', 'RThumb'),
    'daz': (43, 14, 344, 0.00833333, 'hip', 'lFoot'),
    'asf': (31, 7, 322, 0.033333, 'hip', 'rthumb'),
    'bandai': (22, 5, 31, 0.0333333, 'joint_Root', 'Toes_R'),
}


@pytest.mark.parametrize('fmt', sorted(EXPECTED))
def test_real_file_sizes(fmt, bandai_bvh):
    bvh, scale = real(fmt, bandai_bvh)
    J, E, F, dt, first, last = EXPECTED[fmt]
    assert bvh.num_joints == J and len(bvh.end_sites) == E
    assert bvh.num_frames == F
    assert bvh.frame_time == pytest.approx(dt, rel=1e-6)
    assert bvh.joint_names[0] == first and bvh.joint_names[-1] == last
    assert guess_unit_scale(bvh) == pytest.approx(scale)
    if fmt == 'bandai':
        assert all(len(c) == 6 for c in bvh.channels)
        assert bvh.rotation_order(5) == 'ZXY'
    elif fmt == 'daz':
        assert bvh.rotation_order(0) == 'ZYX' and bvh.rotation_order(1) == 'ZXY'
    else:
        assert {bvh.rotation_order(j) for j in range(J)} == {'ZYX'}


@pytest.mark.parametrize('fmt', sorted(EXPECTED))
def test_real_fk_matches_independent_reference(fmt, bandai_bvh):
    bvh, scale = real(fmt, bandai_bvh)
    frames = np.linspace(0, bvh.num_frames - 1, 6).astype(int)
    fk = bvh_fk(bvh, scale, frames=frames)
    M = BVH_TO_WORLD
    for k, f in enumerate(frames):
        P, R, E = reference_fk(bvh, f)
        np.testing.assert_allclose(fk.positions[k], scale * P @ M.T, atol=1e-9)
        np.testing.assert_allclose(fk.rotations[k], M @ R @ M.T, atol=1e-9)
        np.testing.assert_allclose(fk.end_site_positions[k], scale * E @ M.T, atol=1e-9)


THIGH = {'mb2': ('LeftUpLeg', 'LeftLeg'), 'daz': ('lThigh', 'lShin'),
         'asf': ('lfemur', 'ltibia'), 'bandai': ('UpperLeg_L', 'LowerLeg_L')}
SHIN = {'mb2': ('LeftLeg', 'LeftFoot'), 'daz': ('lShin', 'lFoot'),
        'asf': ('ltibia', 'lfoot'), 'bandai': ('LowerLeg_L', 'Foot_L')}


@pytest.mark.parametrize('fmt', sorted(EXPECTED))
def test_real_bone_lengths_in_metres_and_z_up(fmt, bandai_bvh):
    bvh, scale = real(fmt, bandai_bvh)
    fk = bvh_fk(bvh, scale)
    P = fk.positions

    def length(a, b):
        d = np.linalg.norm(P[:, bvh.joint_index(a)] - P[:, bvh.joint_index(b)], axis=-1)
        return float(d.mean()), float(np.ptp(d))

    thigh, thigh_var = length(*THIGH[fmt])
    shin, _ = length(*SHIN[fmt])
    assert 0.35 <= thigh <= 0.50 and thigh_var < 1e-6      # rigid bones
    assert 0.35 <= shin <= 0.50
    # z is up: the head is above the pelvis, which is above the feet, in the mean pose
    head = {'mb2': 'Head', 'daz': 'head', 'asf': 'head', 'bandai': 'Head'}[fmt]
    foot = SHIN[fmt][1]
    hz = P[:, bvh.joint_index(head), 2].mean()
    fz = P[:, bvh.joint_index(foot), 2].mean()
    assert hz - fz > 1.0


def test_bandai_root_translation_composes_joint_root_and_hips(bandai_bvh):
    # walk_normal_002 carries its forward travel on joint_Root: the hips must travel with it
    fk = bvh_fk(bandai_bvh, 0.01)
    hips = fk.positions[:, bandai_bvh.joint_index('Hips')]
    root_ch = bandai_bvh.joint_channels(0)[:, :3]
    assert np.abs(root_ch).max() > 10.0                                 # cm on joint_Root
    travel = np.linalg.norm(hips[-1, :2] - hips[0, :2])
    root_travel = 0.01 * np.linalg.norm(root_ch[-1] - root_ch[0])
    assert travel > 0.5 * root_travel > 0.05
