"""Splits, the dataset build / cache / loader, and contact labels on real walks.

The split tests read only the committed ``splits.json`` (it stores the inventory it was made
from), the build tests use a synthetic BVH clip; the tests on real motion capture skip without
``../shared/data`` (``MOCAP_SHARED_DATA``).
"""

from __future__ import annotations

import os
import random
import re
from pathlib import Path

import numpy as np
import pytest

from mocap_core.data.bvh import BVH, iter_bvh_archive, parse_bvh, read_bvh
from mocap_core.data.bvh_synth import synthetic_walk_bvh
from mocap_core.data.dataset import (build_dataset, compute_report, find_dataset, load_dataset,
                                     TELEPORT_SPEED_MPS, load_split, process_clip,
                                     report_markdown)
from mocap_core.data.splits import (SPLITS_PATH, ClipInfo, Splits, SplitsError,
                                    archive_member_ids, clip_labels, hashed_split, load_splits,
                                    make_splits, nominal_fps, resolve_clip)
from mocap_core.skeleton import NUM_BONE_GROUPS, NUM_JOINTS

REPO = Path(__file__).resolve().parents[3]
DATA = Path(os.environ.get('MOCAP_SHARED_DATA', REPO.parent / 'shared' / 'data'))
NEEDS_DATA = 'needs ../shared/data (not shipped with the repository)'


def data_path(*parts: str) -> Path:
    p = DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(NEEDS_DATA)
    return p


@pytest.fixture(scope='module')
def committed() -> Splits:
    return load_splits()


# ---------------------------------------------------------------------------------------------
# splits
# ---------------------------------------------------------------------------------------------
def test_committed_split_is_deterministic(committed):
    """Regenerating from the inventory stored in the file gives the file, byte for byte,
    whatever the order the clips come in."""
    inv = committed.inventory()
    random.Random(3).shuffle(inv)
    again = make_splits(inv, committed.fraction, committed.salt)
    assert again.to_json() == SPLITS_PATH.read_text()
    assert again.clips == committed.clips


def test_committed_split_is_disjoint_and_groups_do_not_cross(committed):
    train, val = set(committed.ids('train')), set(committed.ids('validation'))
    excluded = set(committed.ids('excluded'))
    assert train and val and not (train & val) and not (train & excluded)
    assert train | val | excluded == set(committed.clips)
    assert set(committed.excluded) == excluded
    split_of_group = {}
    for i, (split, group, *_rest) in committed.clips.items():
        assert group == clip_labels(i, committed.clips[i][4])['group']
        if split == 'excluded':
            continue
        assert split_of_group.setdefault(group, split) == split, f'{group} crosses the split'
        assert committed.groups[group] == split
    # about 10 % of every stratum's duration, each stratum on both sides
    for stratum, row in committed.counts['strata'].items():
        assert 0.07 <= row['validation_share'] <= 0.14, stratum
        assert row['train']['clips'] > 0 and row['validation']['clips'] > 0
    assert committed.counts['train']['clips'] == len(train)
    assert committed.counts['validation']['clips'] == len(val)


def test_cmu_trials_count_once_and_conversions_share_a_group(committed):
    trials = {}
    for i, (split, group, _, _, fmt) in committed.clips.items():
        lab = clip_labels(i, fmt)
        if lab['dataset'] == 'cmu' and lab['trial']:
            trials.setdefault(lab['trial'], []).append((i, split, group))
    for trial, rows in trials.items():
        kept = [r for r in rows if r[1] != 'excluded']
        assert len(kept) == 1, f'trial {trial} counted {len(kept)} times'
        assert len({r[2] for r in rows}) == 1, f'conversions of {trial} in different groups'
    dup = [i for i, why in committed.excluded.items() if why.startswith('duplicate')]
    for i in dup:
        assert committed.clips[i][4] == 'cmu_daz'  # mb2 / ASF preferred


def _inv(*rows):
    return [ClipInfo(i, frames, fps, fmt) for i, frames, fps, fmt in rows]


def test_split_rules_on_a_synthetic_inventory():
    rows = []
    for s in range(1, 13):                                   # 12 CMU subjects
        for t in range(1, 4):
            rows.append((f'cmu_bvh/daz/{s:02d}_{t:02d}.bvh', 1200, 120.0, 'cmu_daz'))
    rows.append(('cmu_bvh/mb2/03_02.bvh', 1190, 120.0, 'cmu_mb2'))   # same trial as DAZ 03_02
    rows.append(('cmu_bvh/acrnn.tar.xz:salsa/01.bvh', 3000, 120.0, 'cmu_daz'))
    rows.append(('cmu_bvh/acrnn.tar.xz:salsa/16.bvh', 3000, 120.0, 'cmu_daz'))
    rows.append(('cmu_bvh/acrnn.tar.xz:standard.bvh', 3, 30.0, 'cmu_daz'))
    for c in ('walk', 'run', 'wave', 'bow'):
        for st in ('normal', 'happy', 'sad', 'proud', 'tired'):
            for k in (1, 2, 3):
                rows.append((f'bandai/ds2.tar.xz:dataset-2_{c}_{st}_{k:03d}.bvh', 300, 30.0,
                             'bandai_namco'))
    rows.append(('mine/jump_01.bvh', 100, 30.0, 'cmu_mb2'))
    rows.append(('mine/broken.bvh', 0, 0.0, ''))
    inv = [ClipInfo(i, f, fps, fmt, 'unreadable: no MOTION' if not fmt else '')
           for i, f, fps, fmt in rows]
    sp = make_splits(inv)
    # the DAZ copy of trial 03_02 goes, the mb2 one stays, in subject 03's group
    assert sp.split_of('cmu_bvh/daz/03_02.bvh') == 'excluded'
    assert 'duplicate of CMU trial 03_02' in sp.excluded['cmu_bvh/daz/03_02.bvh']
    assert sp.clips['cmu_bvh/mb2/03_02.bvh'][1] == 'cmu/subject-03'
    assert sp.split_of('cmu_bvh/acrnn.tar.xz:standard.bvh') == 'excluded'
    assert sp.split_of('mine/broken.bvh') == 'excluded'
    # couple dances stay together; Bandai groups are content x style
    assert sp.group_of('cmu_bvh/acrnn.tar.xz:salsa/01.bvh') == 'cmu/salsa'
    assert sp.split_of('cmu_bvh/acrnn.tar.xz:salsa/01.bvh') == \
        sp.split_of('cmu_bvh/acrnn.tar.xz:salsa/16.bvh')
    assert sp.group_of('bandai/ds2.tar.xz:dataset-2_wave_happy_002.bvh') == \
        'bandai/dataset-2/wave/happy'
    for g, s in sp.groups.items():
        splits = {sp.clips[i][0] for i in sp.clips if sp.clips[i][1] == g} - {'excluded'}
        assert splits == {s}
    # Bandai: validation combinations have distinct contents and styles (first pass)
    val = [g.split('/')[2:] for g, s in sp.groups.items()
           if s == 'validation' and g.startswith('bandai')]
    assert val and len({c for c, _ in val}) == len(val) and len({s for _, s in val}) == len(val)
    for stratum, row in sp.counts['strata'].items():
        if stratum != 'other':
            assert 0.07 <= row['validation_share'] <= 0.14, stratum
    # deterministic, order independent; another salt gives another valid split
    assert make_splits(list(reversed(inv))).to_json() == sp.to_json()
    other = make_splits(inv, salt='another')
    assert other.to_json() != sp.to_json()
    assert Splits.from_json(sp.to_json()).clips == sp.clips
    assert hashed_split('other/x') in ('train', 'validation')


def test_ids_names_and_rates():
    assert archive_member_ids(['A/data/x.bvh', 'A/data/y.bvh']) == ['x.bvh', 'y.bvh']
    assert archive_member_ids(['standard.bvh', 'salsa/01.bvh']) == ['standard.bvh',
                                                                    'salsa/01.bvh']
    assert nominal_fps(0.0083333) == 120.0 and nominal_fps(0.033333) == 30.0
    assert nominal_fps(0.04) == 25.0 and abs(nominal_fps(0.0425) - 23.53) < 0.01
    lab = clip_labels('bandai_namco_bvh/a.tar.xz:dataset-1_walk-back_not-confident_002.bvh',
                      'bandai_namco')
    assert (lab['content'], lab['style'], lab['stratum']) == ('walk-back', 'not-confident',
                                                              'bandai/dataset-1')
    ids = ['cmu_bvh/mb2_120fps/02_01.bvh', 'x.tar.xz:salsa/01.bvh', 'x.tar.xz:indian/01.bvh']
    assert resolve_clip('02_01', ids) == ids[0]
    assert resolve_clip('salsa/01', ids) == ids[1]
    with pytest.raises(KeyError, match='ambiguous'):
        resolve_clip('01', ids)
    with pytest.raises(KeyError, match='unknown clip'):
        resolve_clip('99_99', ids)


def test_split_file_errors(tmp_path):
    with pytest.raises(SplitsError, match='not found'):
        load_splits(tmp_path / 'nope.json')
    bad = tmp_path / 'bad.json'
    bad.write_text('{"format": "something else"}')
    with pytest.raises(SplitsError, match='not a mocap-splits'):
        load_splits(bad)
    bad.write_text('{not json')
    with pytest.raises(SplitsError, match='not valid JSON'):
        load_splits(bad)


# ---------------------------------------------------------------------------------------------
# build, cache, loader, report (synthetic clips)
# ---------------------------------------------------------------------------------------------
@pytest.fixture()
def synth_sources(tmp_path):
    src = tmp_path / 'mine'
    src.mkdir()
    (src / 'walk_01.bvh').write_text(synthetic_walk_bvh(240, 120.0))
    (src / 'walk_02.bvh').write_text(synthetic_walk_bvh(150, 60.0, speed_m_s=0.8, crlf=True))
    (src / 'jog_01.bvh').write_text(synthetic_walk_bvh(90, 30.0, speed_m_s=2.5, step_hz=1.4))
    (src / 'broken.bvh').write_text('HIERARCHY\nROOT x\n{\n')
    inv = [ClipInfo('mine/walk_01.bvh', 240, 120.0, 'cmu_mb2'),
           ClipInfo('mine/walk_02.bvh', 150, 60.0, 'cmu_mb2'),
           ClipInfo('mine/jog_01.bvh', 90, 30.0, 'cmu_mb2')]
    sp = make_splits(inv, fraction=0.4)
    split_file = sp.write(tmp_path / 'splits.json')
    return src, split_file, sp


def test_build_caches_loads_and_rebuilds_on_change(tmp_path, synth_sources):
    src, split_file, sp = synth_sources
    cache = tmp_path / 'cache'
    kw = dict(cache_root=cache, splits=split_file, workers=1, progress=False, root=tmp_path)
    info = build_dataset([src], **kw)   # broken.bvh does not parse: reported, not fatal
    assert info.rebuilt and info.path.parent == cache
    assert [e['id'] for e in info.manifest['errors']] == ['mine/broken.bvh']
    again = build_dataset([src], **kw)
    assert not again.rebuilt and again.path == info.path
    assert find_dataset([src], splits=split_file, cache_root=cache, root=tmp_path).path == \
        info.path

    parts = {s: load_split(s, info) for s in ('train', 'validation')}
    ids = {s: set(p.ids.tolist()) for s, p in parts.items()}
    for s in ('train', 'validation'):
        assert ids[s] == set(sp.ids(s))
    tr = parts['train']
    assert tr.rotations.dtype == np.float32 and tr.rotations.shape[1:] == (NUM_JOINTS, 4)
    assert tr.contacts.dtype == bool and tr.contacts.shape == (tr.num_frames, 4)
    assert tr.group_lengths.shape == (len(tr), NUM_BONE_GROUPS)
    assert tr.offsets[-1] == len(tr.root_positions) == tr.num_frames
    # 240 frames at 120 fps -> 60 frames at 30 fps (the last sample at t = 239/120 s)
    motions = {m.name: m for s in parts for m in load_dataset(s, info)}
    assert motions['mine/walk_01.bvh'].num_frames == 60
    assert motions['mine/walk_02.bvh'].num_frames == 75
    for m in motions.values():
        assert m.fps == 30.0
        q = np.linalg.norm(m.rotations, axis=-1)
        assert np.allclose(q, 1.0, atol=1e-5)
        assert m.skeleton.is_symmetric()
    i = tr.index('walk_01') if 'mine/walk_01.bvh' in ids['train'] else None
    if i is not None:
        assert tr.ids[i] == 'mine/walk_01.bvh'

    report = info.report()
    assert report['total']['clips'] == 3
    assert report['total']['frames'] == sum(m.num_frames for m in motions.values())
    assert report['fk_error_mm']['cmu_mb2']['max'] < 1e-3   # exact skeleton
    assert set(report['bone_lengths_m']['thigh']) == {'min', 'median', 'max'}
    assert 0.4 < report['bone_lengths_m']['thigh']['median'] < 0.44
    assert '## Foot contact ratio' in info.report_md.read_text()
    assert compute_report(info.path)['total'] == report['total']
    assert 'mocap data build' in report_markdown(report)

    # a touched source or another rate give another dataset
    f = src / 'jog_01.bvh'
    st = f.stat()
    os.utime(f, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    touched = build_dataset([src], **kw)
    assert touched.rebuilt and touched.path != info.path
    slow = build_dataset([src], fps=15.0, **kw)
    assert slow.path != touched.path
    assert load_split('train', slow).fps == 15.0


def test_build_errors(tmp_path, synth_sources):
    src, split_file, _ = synth_sources
    with pytest.raises(FileNotFoundError, match='not found'):
        build_dataset([tmp_path / 'missing'], cache_root=tmp_path, splits=split_file,
                      progress=False)
    with pytest.raises(ValueError, match='frame rate'):
        build_dataset([src], cache_root=tmp_path, splits=split_file, fps=0, progress=False)
    with pytest.raises(ValueError, match="unknown split"):
        load_split('test', tmp_path)


def test_process_clip_drops_a_rest_pose_lead_in():
    """A clip that starts with a T-pose frame and blends into the motion (the cgspeed CMU
    conversions) loses those frames; a clip that does not is kept whole."""
    text = synthetic_walk_bvh(240, 120.0)
    bvh = parse_bvh(text, 'walk')
    _, info = process_clip(bvh, 'walk')
    assert info['trimmed_frames'] == 0
    motion = bvh.motion.copy()
    motion[0, 3:] = 0.0                                 # frame 0: all rotations zero
    motion[0, :3] += np.array([0.0, 0.0, -6.0])         # and 34 cm off the motion
    lead = BVH(bvh.joint_names, bvh.parents, bvh.offsets, bvh.channels, bvh.end_sites,
               bvh.frame_time, motion, 'lead')
    m, info = process_clip(lead, 'lead')
    assert info['trimmed_frames'] == 1
    assert m.num_frames == 60          # 239 frames at 120 fps -> t = 0 ... 238/120 s
    _, info = process_clip(lead, 'lead', trim_lead_in=False)
    assert info['trimmed_frames'] == 0


def test_process_clip_drops_frames_before_a_capture_jump():
    """A pelvis jump faster than any human (DAZ 09_10: 2.1 m in one 120 fps frame) within the
    lead-in window drops the frames before it, with or without a rest pose at frame 0; a clip
    whose first frames move normally keeps them."""
    bvh = parse_bvh(synthetic_walk_bvh(240, 120.0), 'walk')
    motion = bvh.motion.copy()
    motion[:4, :3] += np.array([40.0, 0.0, 0.0])        # 4 frames far off, then a jump

    def clip(m):
        return BVH(bvh.joint_names, bvh.parents, bvh.offsets, bvh.channels, bvh.end_sites,
                   bvh.frame_time, m, 'jump')
    m, info = process_clip(clip(motion), 'jump')
    assert info['trimmed_frames'] == 4
    speed = np.linalg.norm(np.diff(m.root_positions, axis=0), axis=-1) * m.fps
    assert speed.max() < TELEPORT_SPEED_MPS
    late = bvh.motion.copy()
    late[100:, :3] += np.array([40.0, 0.0, 0.0])        # after the lead-in window: kept
    assert process_clip(clip(late), 'late')[1]['trimmed_frames'] == 0


# ---------------------------------------------------------------------------------------------
# real motion capture
# ---------------------------------------------------------------------------------------------
def _phases(flags: np.ndarray, min_len: int = 3, max_gap: int = 3):
    """[(start, end)] runs of True, gaps of up to max_gap frames closed, short runs dropped."""
    f = flags.copy()
    idx = np.flatnonzero(f)
    for a, b in zip(idx[:-1], idx[1:]):
        if 1 < b - a <= max_gap + 1:
            f[a:b] = True
    runs, start = [], None
    for i, v in enumerate(np.append(f, False)):
        if v and start is None:
            start = i
        elif not v and start is not None:
            if i - start >= min_len:
                runs.append((start, i))
            start = None
    return runs


def _assert_walk_contacts(motion):
    c = motion.contacts
    left, right = c[:, 0] | c[:, 1], c[:, 2] | c[:, 3]
    for foot in (left, right):
        assert 0.4 <= foot.mean() <= 0.8, f'foot in contact {foot.mean():.2f} of the frames'
    for heel in (c[:, 0], c[:, 2]):
        assert 0.25 <= heel.mean() <= 0.8
    # heel-strike phases alternate left / right
    events = sorted([(s, 'L') for s, _ in _phases(c[:, 0])] +
                    [(s, 'R') for s, _ in _phases(c[:, 2])])
    sides = [side for _, side in events]
    assert sides.count('L') >= 2 and sides.count('R') >= 2, sides
    assert all(a != b for a, b in zip(sides[:-1], sides[1:])), sides
    # walking: (nearly) always a foot on the ground
    assert (left | right).mean() > 0.9


def test_contacts_alternate_on_a_real_bandai_walk():
    arc = data_path('bandai_namco_bvh', 'dataset-1_all.tar.xz')
    bvh = next(b for _, b in iter_bvh_archive(arc, pattern=re.escape(
        'dataset-1_walk_normal_001.bvh')))
    motion, info = process_clip(bvh, 'dataset-1_walk_normal_001')
    assert info['format'] == 'bandai_namco' and motion.num_frames == 195
    _assert_walk_contacts(motion)


def test_contacts_alternate_on_a_real_cmu_walk():
    bvh = read_bvh(data_path('cmu_bvh', 'daz_friendly_120fps', '12_02.bvh'))
    motion, info = process_clip(bvh, '12_02')
    assert info['trimmed_frames'] >= 1            # the cgspeed rest-pose lead-in
    _assert_walk_contacts(motion)
