"""Clip inventory and the train / validation split of the motion-capture data (no ROS imports).

Training and evaluation read one committed file, ``splits.json`` next to this module
(:data:`SPLITS_PATH`, :func:`load_splits`), which says for every clip of ``../shared/data``
whether it is ``train``, ``validation`` or ``excluded``. ``mocap data split`` regenerates it
from the data (:func:`scan_sources` + :func:`make_splits`); ``mocap data split --check``
verifies that the committed file is what the rule gives for the data on disk.

Clip ids
--------
A clip id is the path of its file relative to the data root (``MOCAP_SHARED_DATA``, default
``<repo>/../shared/data``), e.g. ``cmu_bvh/mb2_120fps/02_01.bvh``; an archive member is
``<archive path>:<member path>`` with the directories that all ``.bvh`` members of that archive
share removed, e.g. ``bandai_namco_bvh/dataset-2_walk.tar.xz:dataset-2_walk_active_001.bvh`` or
``cmu_bvh/daz_friendly_acrnn_salsa_indian.tar.xz:salsa/01.bvh``. Sources outside the data
root are named relative to the parent of the path given on the command line.

The rule (:data:`RULE`, also written into ``splits.json``)
---------------------------------------------------------
1. **Groups** -- clips that must stay together (:func:`clip_labels`):

   * CMU (any of the three BVH conversions): the *subject* (file ``SS_TT.bvh`` -> subject SS),
     so whole subjects are held out; the acRNN archive, whose files lost their CMU trial ids,
     is grouped by its folder (``salsa`` = subjects 60/61 dancing as couples, where files 16-30
     are the partners of 01-15; ``indian`` = one subject), so a dance and its partner never
     straddle the split.
   * Bandai Namco (``dataset-N_<content>_<style>_<take>.bvh``): the *(dataset, content, style)*
     combination: all takes of one content in one style. The actor id is not published, so an
     actor-disjoint split is impossible (dataset README); a validation group is a
     content-style combination never seen in training (each content and each style on its own
     is seen in training).
   * Anything else (and CMU files not named ``SS_TT``): the file stem without a trailing take
     number. A clip is CMU when its path contains ``cmu``, Bandai Namco when its name has the
     Bandai pattern.

2. **Exclusions** (``excluded``, with the reason): clips shorter than :data:`MIN_CLIP_SECONDS`
   (acRNN's ``standard.bvh``, a 3-frame reference pose), files that do not parse or whose
   skeleton is not a known format, and **duplicate CMU trials**: a trial (``SS_TT``) present in
   several conversions counts once; the copy kept is, in this order of preference, mb2, ASF
   names, DAZ (mb2/ASF keep the subject's own bone lengths and a straight-limbed rest pose; the
   DAZ conversion maps everybody onto one standard skeleton). So ``daz_friendly_120fps/02_01``
   is excluded in favour of ``mb2_120fps/02_01`` -- same subject, same group, never split.

3. **Strata** -- the validation share is met separately in ``cmu``, ``bandai/dataset-1``,
   ``bandai/dataset-2`` (and ``other``): in each, the groups are ordered by
   ``sha256(salt + ':' + group)`` and taken in that order while the validation duration is
   below :data:`VALIDATION_FRACTION` of the stratum's duration, skipping a group that would
   bring it above 1.25 x that target. A first pass takes only groups whose content and whose
   style are not yet in validation (so dataset-2's validation holds every style once, each
   with a different content); a second pass, without that condition, fills the rest.
   Durations are source frames / source frame rate.

Everything depends only on the clip ids, frame counts, rates and formats, so the split is
deterministic; adding clips can move groups only within their own stratum.
"""

from __future__ import annotations

import hashlib
import json
import lzma
import os
import re
import tarfile
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Dict, Iterable, Iterator, List, Optional, Sequence, Tuple, Union

from .bvh import BVHError, is_bvh_archive, list_bvh_sources, parse_bvh

__all__ = [
    'SPLITS_PATH', 'VALIDATION_FRACTION', 'SPLIT_SALT', 'MIN_CLIP_SECONDS', 'RULE', 'SPLITS',
    'ClipInfo', 'Splits', 'SplitsError', 'repo_root', 'shared_data_dir', 'default_sources',
    'nominal_fps', 'clip_labels', 'scan_sources', 'make_splits', 'load_splits',
    'iter_source_members', 'archive_member_ids', 'clip_id_base', 'resolve_clip',
]

#: The committed split file that training and evaluation read.
SPLITS_PATH = Path(__file__).resolve().with_name('splits.json')
#: Target share of each stratum's duration held out for validation.
VALIDATION_FRACTION = 0.10
#: Salt of the group hash (changing it gives another, equally valid split).
SPLIT_SALT = 'mocap-split-v1'
#: Clips shorter than this (seconds) are excluded: not motions (reference poses).
MIN_CLIP_SECONDS = 0.5
#: A group is skipped when it would bring the validation duration above this times the target.
OVERSHOOT = 1.25
SPLITS = ('train', 'validation')
_FORMAT_VERSION = 'mocap-splits/1'
#: Preference among the conversions of one CMU trial (lower = kept).
_CONVERSION_RANK = {'cmu_mb2': 0, 'cmu_asf': 1, 'cmu_daz': 2}

RULE: Tuple[str, ...] = (
    'Split by clip; clips of one group are always in the same split.',
    'Groups: CMU = subject (SS of SS_TT.bvh; the acRNN archive, which lost the trial ids, by '
    'folder: salsa = subjects 60/61 couples, indian = one subject); Bandai Namco = (dataset, '
    'content, style), all takes of one content in one style (no actor id is published); '
    'other = file stem without a trailing take number.',
    f'Excluded: clips shorter than {MIN_CLIP_SECONDS:g} s, unreadable files, unknown '
    'skeletons, and duplicate CMU trials (a trial SS_TT in several conversions is kept once, '
    'preferring mb2, then ASF names, then DAZ).',
    f'Strata cmu, bandai/dataset-1, bandai/dataset-2, other: groups ordered by '
    f'sha256("{SPLIT_SALT}:" + group) are moved to validation while the validation duration '
    f'is below {VALIDATION_FRACTION:g} of the stratum duration, skipping a group that would '
    f'exceed {OVERSHOOT:g} x that target; a first pass takes only groups whose content and '
    'style are not yet in validation, a second pass fills the rest. Duration = source frames '
    '/ source frame rate.',
)


class SplitsError(ValueError):
    """The split file is missing, malformed or does not match the data (one-line message)."""


# ---------------------------------------------------------------------------------------------
# locations
# ---------------------------------------------------------------------------------------------
def repo_root() -> Path:
    """The repository root: ``MOCAP_ROOT`` (set by env.sh) or four levels above this file."""
    env = os.environ.get('MOCAP_ROOT')
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[4]


def shared_data_dir() -> Path:
    """``MOCAP_SHARED_DATA`` or ``<repo>/../shared/data`` (it may not exist: users lack it)."""
    env = os.environ.get('MOCAP_SHARED_DATA')
    if env:
        return Path(env)
    return repo_root().parent / 'shared' / 'data'


def default_sources() -> List[Path]:
    """The motion capture of the shared data: CMU BVH and Bandai Namco folders."""
    root = shared_data_dir()
    return [root / 'cmu_bvh', root / 'bandai_namco_bvh']


def nominal_fps(frame_time: float) -> float:
    """Frame rate of a BVH ``Frame Time``, snapped to the nearest integer when within 0.1 %
    (files write 1/30 s as 0.033333 or 0.0333333, 1/120 s as .0083333)."""
    fps = 1.0 / float(frame_time)
    r = round(fps)
    if r > 0 and abs(fps - r) <= 1e-3 * fps:
        return float(r)
    return float(fps)


# ---------------------------------------------------------------------------------------------
# clip ids and sources
# ---------------------------------------------------------------------------------------------
def clip_id_base(path: Path, root: Optional[Path]) -> Path:
    """Directory clip ids under the source ``path`` are relative to: ``root`` when ``path``
    lies inside it, else ``path``'s parent."""
    p = Path(path).resolve()
    if root is not None:
        r = Path(root).resolve()
        if p == r or r in p.parents:
            return r
    return p.parent


def _rel(path: Path, base: Path) -> str:
    return Path(path).resolve().relative_to(base).as_posix()


def archive_member_ids(names: Sequence[str]) -> List[str]:
    """Member names without the directories that all of them share."""
    parts = [PurePosixPath(n).parts for n in names]
    if not parts:
        return []
    common = 0
    shortest = min(len(p) for p in parts)
    while common < shortest - 1 and len({p[common] for p in parts}) == 1:
        common += 1
    return ['/'.join(p[common:]) for p in parts]


def iter_source_members(path: Path, max_bytes: Optional[int] = None
                        ) -> Iterator[Tuple[str, bytes]]:
    """Yield ``(member name, bytes)`` of every ``.bvh`` member of a tar archive (streamed once,
    nothing unpacked). With ``max_bytes`` only the first bytes of each member are read (more
    if its header is longer)."""
    with tarfile.open(path, 'r|*') as tar:
        for member in tar:
            if not member.isfile() or not member.name.lower().endswith('.bvh'):
                continue
            f = tar.extractfile(member)
            if f is None:
                continue
            if max_bytes is None:
                data = f.read()
            else:
                data = f.read(max_bytes)
                if b'Frame Time' not in data and b'frame time' not in data.lower():
                    data += f.read()
            yield member.name, data


# ---------------------------------------------------------------------------------------------
# inventory
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ClipInfo:
    """One clip of the inventory.

    Attributes:
        id: clip id (module docstring).
        frames: frame count announced by the file.
        fps: nominal source frame rate (:func:`nominal_fps`).
        format: source format (:data:`mocap_core.data.retarget.FORMATS` key), '' if unknown.
        error: why the file cannot be used ('' if it can).
        source: path of the file or archive on this machine ('' when rebuilt from the json).
        member: archive member name ('' for a plain file).
    """

    id: str
    frames: int
    fps: float
    format: str = ''
    error: str = ''
    source: str = ''
    member: str = ''

    @property
    def seconds(self) -> float:
        return self.frames / self.fps if self.fps > 0 else 0.0


_MOTION_RE = re.compile(rb'^[ \t]*MOTION[ \t]*\r?$', re.IGNORECASE | re.MULTILINE)
_FRAMES_RE = re.compile(rb'Frames\s*:\s*(\d+)', re.IGNORECASE)
_FRAME_TIME_RE = re.compile(rb'Frame\s*Time\s*:\s*([-+0-9.eE]+)', re.IGNORECASE)


def _scan_bytes(clip_id: str, data: bytes, source: str, member: str) -> ClipInfo:
    """Frames, rate and format of a BVH from its header (the motion is not parsed)."""
    from .retarget import detect_format

    m = _MOTION_RE.search(data)
    fm = _FRAMES_RE.search(data, m.end()) if m else None
    tm = _FRAME_TIME_RE.search(data, m.end()) if m else None
    if m is None or fm is None or tm is None:
        return ClipInfo(clip_id, 0, 0.0, '', 'unreadable: no MOTION / Frames / Frame Time',
                        source, member)
    try:
        frame_time = float(tm.group(1))
        if not frame_time > 0:
            raise ValueError(f'Frame Time {frame_time}')
        header = data[:m.start()].decode('utf-8', errors='replace')
        bvh = parse_bvh(header + '\nMOTION\nFrames: 0\nFrame Time: 1\n', clip_id)
    except (BVHError, ValueError) as exc:
        return ClipInfo(clip_id, 0, 0.0, '', f'unreadable: {exc}', source, member)
    frames, fps = int(fm.group(1)), nominal_fps(frame_time)
    try:
        fmt = detect_format(bvh).name
    except ValueError:
        return ClipInfo(clip_id, frames, fps, '', 'unknown skeleton (not a known BVH format)',
                        source, member)
    return ClipInfo(clip_id, frames, fps, fmt, '', source, member)


def _scan_one(args: Tuple[str, str]) -> List[ClipInfo]:
    path, base = Path(args[0]), Path(args[1])
    rel = _rel(path, base)
    if is_bvh_archive(path):
        names, infos = [], []
        damaged = ''
        try:
            for name, data in iter_source_members(path, max_bytes=1 << 16):
                names.append(name)
                infos.append(_scan_bytes('', data, str(path), name))
        except (tarfile.TarError, EOFError, OSError, lzma.LZMAError) as exc:
            damaged = f'unreadable archive ({type(exc).__name__}: {exc})'
        ids = archive_member_ids(names)
        out = [ClipInfo(f'{rel}:{i}', c.frames, c.fps, c.format, c.error, c.source, c.member)
               for i, c in zip(ids, infos)]
        if damaged:
            out.append(ClipInfo(rel, 0, 0.0, '', damaged, str(path)))
        return out
    try:
        with open(path, 'rb') as f:
            data = f.read()
    except OSError as exc:
        return [ClipInfo(rel, 0, 0.0, '', f'unreadable: {exc}', str(path))]
    return [_scan_bytes(rel, data, str(path), '')]


def expand_sources(sources: Union[None, str, os.PathLike, Sequence[Union[str, os.PathLike]]],
                   root: Optional[Path] = None) -> List[Tuple[Path, Path]]:
    """``(file or archive, id base)`` for every BVH file and archive under ``sources``
    (default :func:`default_sources`); raises FileNotFoundError naming a missing path."""
    if sources is None:
        sources = default_sources()
    if isinstance(sources, (str, os.PathLike)):
        sources = [sources]
    root = shared_data_dir() if root is None else Path(root)
    out: List[Tuple[Path, Path]] = []
    seen = set()
    for s in sources:
        s = Path(s)
        if not s.exists():
            raise FileNotFoundError(f'motion-capture source not found: {s} (set '
                                    'MOCAP_SHARED_DATA or pass --sources)')
        base = clip_id_base(s, root)
        for f in list_bvh_sources([s]):
            key = f.resolve()
            if key not in seen:
                seen.add(key)
                out.append((f, base))
    if not out:
        raise FileNotFoundError(f'no .bvh files or archives under {", ".join(map(str, sources))}')
    return out


def scan_sources(sources=None, root: Optional[Path] = None, workers: int = 2
                 ) -> List[ClipInfo]:
    """Inventory of every clip under ``sources`` (files, archives, directories), sorted by id.

    Reads only the BVH headers (the archives are still decompressed: ~7 s for all the shared
    data on one core)."""
    files = expand_sources(sources, root)
    jobs = sorted(((str(f), str(b)) for f, b in files), key=lambda j: -os.path.getsize(j[0]))
    if workers > 1 and len(jobs) > 1:
        import multiprocessing as mp
        method = 'fork' if 'fork' in mp.get_all_start_methods() else 'spawn'
        with mp.get_context(method).Pool(min(workers, len(jobs))) as pool:
            chunks = pool.map(_scan_one, jobs, chunksize=1)
    else:
        chunks = [_scan_one(j) for j in jobs]
    clips = [c for ch in chunks for c in ch]
    ids = [c.id for c in clips]
    dup = {i for i in ids if ids.count(i) > 1} if len(set(ids)) != len(ids) else set()
    if dup:
        raise SplitsError(f'two sources give the same clip id(s) {sorted(dup)[:3]}')
    return sorted(clips, key=lambda c: c.id)


# ---------------------------------------------------------------------------------------------
# groups
# ---------------------------------------------------------------------------------------------
_CMU_TRIAL_RE = re.compile(r'^(\d{1,3})_(\d{1,3})$')
_BANDAI_RE = re.compile(r'^(dataset-\d+)_([^_]+)_([^_]+)_(\d+)$')
_TAKE_RE = re.compile(r'[_\- ]*\d+$')


def clip_labels(clip_id: str, fmt: str = '') -> Dict[str, str]:
    """Group, stratum and the labels the names carry: ``{'group', 'stratum', 'dataset',
    'subject', 'trial', 'content', 'style'}`` (missing labels are '')."""
    path, _, member = clip_id.partition(':')
    inner = PurePosixPath(member or path)
    stem = inner.stem
    out = dict(group='', stratum='', dataset='', subject='', trial='', content='', style='')
    m = _BANDAI_RE.match(stem)
    if m and (fmt in ('', 'bandai_namco')):
        ds, content, style, _ = m.groups()
        out.update(dataset=f'bandai/{ds}', content=content, style=style,
                   group=f'bandai/{ds}/{content}/{style}', stratum=f'bandai/{ds}')
        return out
    if 'cmu' in path.lower():
        out.update(dataset='cmu', stratum='cmu')
        m = _CMU_TRIAL_RE.match(stem)
        if m:
            s, t = int(m.group(1)), int(m.group(2))
            out.update(subject=f'{s:02d}', trial=f'{s:02d}_{t:02d}', group=f'cmu/subject-{s:02d}')
        elif member and inner.parent.name:
            out.update(group=f'cmu/{inner.parent.name}', content=inner.parent.name)
        else:
            out.update(group=f'cmu/{_TAKE_RE.sub("", stem) or stem}')
        return out
    base = _TAKE_RE.sub('', stem) or stem
    out.update(dataset='other', stratum='other', group=f'other/{base}')
    return out


def _hash(group: str, salt: str) -> str:
    return hashlib.sha256(f'{salt}:{group}'.encode()).hexdigest()


# ---------------------------------------------------------------------------------------------
# the split
# ---------------------------------------------------------------------------------------------
@dataclass
class Splits:
    """The split of an inventory (see the module docstring).

    Attributes:
        clips: id -> ``(split, group, frames, fps, format)``; split is ``train``,
            ``validation`` or ``excluded``.
        excluded: id -> reason, for the excluded clips.
        groups: group -> split (groups of excluded-only clips are absent).
        counts: summary figures (per split and per stratum).
        fraction, salt: the rule's parameters.
    """

    clips: Dict[str, Tuple[str, str, int, float, str]]
    excluded: Dict[str, str]
    groups: Dict[str, str]
    counts: dict
    fraction: float = VALIDATION_FRACTION
    salt: str = SPLIT_SALT
    path: Optional[Path] = field(default=None, compare=False)

    def split_of(self, clip_id: str) -> str:
        """'train', 'validation' or 'excluded'; KeyError (one line) for an unknown id."""
        try:
            return self.clips[clip_id][0]
        except KeyError:
            raise KeyError(f'clip {clip_id!r} is not in the split file '
                           f'{self.path or ""}'.rstrip()) from None

    def ids(self, split: str) -> List[str]:
        """Sorted ids of a split."""
        if split not in SPLITS + ('excluded',):
            raise ValueError(f"unknown split {split!r} (use 'train' or 'validation')")
        return sorted(i for i, c in self.clips.items() if c[0] == split)

    def group_of(self, clip_id: str) -> str:
        return self.clips[clip_id][1]

    def inventory(self) -> List[ClipInfo]:
        """The inventory this split was made from (to regenerate it)."""
        out = []
        for i, (_, _, frames, fps, fmt) in sorted(self.clips.items()):
            err = self.excluded.get(i, '') if not fmt else ''
            out.append(ClipInfo(i, int(frames), float(fps), fmt, err))
        return out

    # -- json ------------------------------------------------------------------------------
    def to_json(self) -> str:
        """Deterministic text: fixed key order; clips listed per source folder / archive
        (``"<folder>/"`` or ``"<archive>:"`` + name = clip id), one clip per line as
        ``[split, frames, fps, format]`` (the group follows from id and format)."""
        head = {
            'format': _FORMAT_VERSION,
            'rule': list(RULE),
            'validation_fraction': self.fraction,
            'salt': self.salt,
            'counts': self.counts,
            'excluded': dict(sorted(self.excluded.items())),
            'groups': dict(sorted(self.groups.items())),
            'clip_fields': ['split', 'frames', 'fps', 'format'],
        }
        text = json.dumps(head, indent=1)
        assert text.endswith('\n}')
        by_prefix: Dict[str, List[str]] = {}
        for i, (split, _, frames, fps, fmt) in sorted(self.clips.items()):
            prefix, name = _split_id(i)
            by_prefix.setdefault(prefix, []).append(
                f'   {json.dumps(name)}: {json.dumps([split, frames, fps, fmt])}')
        blocks = [f'  {json.dumps(p)}: {{\n' + ',\n'.join(lines) + '\n  }'
                  for p, lines in sorted(by_prefix.items())]
        return text[:-2] + ',\n "clips": {\n' + ',\n'.join(blocks) + '\n }\n}\n'

    def write(self, path: Union[str, os.PathLike] = SPLITS_PATH) -> Path:
        path = Path(path)
        path.write_text(self.to_json())
        self.path = path
        return path

    @classmethod
    def from_json(cls, text: str, path: Optional[Path] = None) -> 'Splits':
        where = str(path or '<json>')
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise SplitsError(f'{where}: not valid JSON ({exc})') from None
        if not isinstance(d, dict) or d.get('format') != _FORMAT_VERSION:
            raise SplitsError(f'{where}: not a {_FORMAT_VERSION} split file')
        try:
            clips = {}
            for prefix, block in d['clips'].items():
                for name, v in block.items():
                    i = str(prefix) + str(name)
                    clips[i] = (str(v[0]), clip_labels(i, str(v[3]))['group'], int(v[1]),
                                float(v[2]), str(v[3]))
            return cls(clips, dict(d['excluded']), dict(d['groups']), dict(d['counts']),
                       float(d['validation_fraction']), str(d['salt']), path)
        except (KeyError, IndexError, TypeError, ValueError) as exc:
            raise SplitsError(f'{where}: malformed split file ({exc!r})') from None


def _split_id(clip_id: str) -> Tuple[str, str]:
    """``('<archive>:', member)`` or ``('<folder>/', file name)``."""
    if ':' in clip_id:
        a, _, m = clip_id.partition(':')
        return a + ':', m
    head, sep, tail = clip_id.rpartition('/')
    return head + sep, tail


def _exclusions(inventory: Sequence[ClipInfo]) -> Dict[str, str]:
    out: Dict[str, str] = {}
    trials: Dict[str, List[ClipInfo]] = {}
    for c in inventory:
        if c.error:
            out[c.id] = c.error
        elif c.seconds < MIN_CLIP_SECONDS:
            out[c.id] = (f'too short ({c.frames} frames, {c.seconds:.2f} s < '
                         f'{MIN_CLIP_SECONDS:g} s): not a motion')
        else:
            lab = clip_labels(c.id, c.format)
            if lab['dataset'] == 'cmu' and lab['trial']:
                trials.setdefault(lab['trial'], []).append(c)
    for trial, cs in sorted(trials.items()):
        if len(cs) < 2:
            continue
        cs = sorted(cs, key=lambda c: (_CONVERSION_RANK.get(c.format, 9), c.id))
        for c in cs[1:]:
            out[c.id] = (f'duplicate of CMU trial {trial} ({c.format}); kept {cs[0].id} '
                         f'({cs[0].format})')
    return out


def make_splits(inventory: Iterable[ClipInfo], fraction: float = VALIDATION_FRACTION,
                salt: str = SPLIT_SALT) -> Splits:
    """Apply the rule of the module docstring to an inventory."""
    if not 0.0 <= fraction < 1.0:
        raise ValueError(f'validation fraction must be in [0, 1), got {fraction}')
    inventory = sorted(inventory, key=lambda c: c.id)
    excluded = _exclusions(inventory)
    labels = {c.id: clip_labels(c.id, c.format) for c in inventory}
    kept = [c for c in inventory if c.id not in excluded]

    group_seconds: Dict[str, float] = {}
    group_info: Dict[str, Dict[str, str]] = {}
    for c in kept:
        lab = labels[c.id]
        group_seconds[lab['group']] = group_seconds.get(lab['group'], 0.0) + c.seconds
        group_info[lab['group']] = lab
    validation: set = set()
    for stratum in sorted({lab['stratum'] for lab in group_info.values()}):
        groups = sorted((g for g, lab in group_info.items() if lab['stratum'] == stratum),
                        key=lambda g: (_hash(g, salt), g))
        target = fraction * sum(group_seconds[g] for g in groups)
        acc = 0.0
        contents: set = set()
        styles: set = set()
        for first_pass in (True, False):
            for g in groups:
                if acc >= target:
                    break
                lab = group_info[g]
                if g in validation or acc + group_seconds[g] > OVERSHOOT * target:
                    continue
                if first_pass and ((lab['content'] and lab['content'] in contents)
                                   or (lab['style'] and lab['style'] in styles)):
                    continue
                validation.add(g)
                acc += group_seconds[g]
                contents.add(lab['content'])
                styles.add(lab['style'])
    groups = {g: ('validation' if g in validation else 'train') for g in group_info}
    clips = {}
    for c in inventory:
        lab = labels[c.id]
        split = 'excluded' if c.id in excluded else groups[lab['group']]
        clips[c.id] = (split, lab['group'], int(c.frames), round(float(c.fps), 6), c.format)
    counts = _counts(clips, labels, groups)
    return Splits(clips, excluded, groups, counts, fraction, salt)


def _counts(clips, labels, groups) -> dict:
    def summary(ids):
        secs = sum(clips[i][2] / clips[i][3] for i in ids if clips[i][3] > 0)
        return {'clips': len(ids), 'groups': len({clips[i][1] for i in ids}),
                'frames': int(sum(clips[i][2] for i in ids)), 'hours': round(secs / 3600.0, 4)}

    out = {s: summary([i for i in clips if clips[i][0] == s]) for s in SPLITS}
    out['excluded'] = {'clips': sum(1 for c in clips.values() if c[0] == 'excluded')}
    per = {}
    for stratum in sorted({labels[i]['stratum'] for i in clips if clips[i][0] != 'excluded'}):
        row = {s: summary([i for i in clips if clips[i][0] == s
                           and labels[i]['stratum'] == stratum]) for s in SPLITS}
        tot = row['train']['hours'] + row['validation']['hours']
        row['validation_share'] = round(row['validation']['hours'] / tot, 4) if tot else 0.0
        row['validation_groups'] = sorted(g for g, s in groups.items()
                                          if s == 'validation' and g in
                                          {labels[i]['group'] for i in clips
                                           if labels[i]['stratum'] == stratum})
        per[stratum] = row
    out['strata'] = per
    return out


def load_splits(path: Union[None, str, os.PathLike] = None) -> Splits:
    """Read a split file (default: the committed :data:`SPLITS_PATH`)."""
    path = Path(path) if path is not None else SPLITS_PATH
    if not path.is_file():
        raise SplitsError(f'split file not found: {path} (run `mocap data split`)')
    return Splits.from_json(path.read_text(), path)


def hashed_split(group: str, fraction: float = VALIDATION_FRACTION,
                 salt: str = SPLIT_SALT) -> str:
    """Split of a clip that is not in the split file (e.g. a user's own data added later):
    validation when its group's hash, read as a number in [0, 1), is below ``fraction``."""
    return 'validation' if int(_hash(group, salt)[:12], 16) / 16 ** 12 < fraction else 'train'


def resolve_clip(name: str, ids: Iterable[str]) -> str:
    """The clip id that ``name`` designates: an exact id, or the unique id whose file name,
    stem or ``/``/``:``-separated tail equals it (``02_01``, ``dataset-2_walk_active_001``,
    ``salsa/01``). Raises KeyError with a one-line reason."""
    ids = list(ids)
    if name in ids:
        return name
    want = name[:-4] if name.lower().endswith('.bvh') else name
    hits = []
    for i in ids:
        tail = i[:-4] if i.lower().endswith('.bvh') else i
        if tail == want or tail.endswith('/' + want) or tail.endswith(':' + want):
            hits.append(i)
    if len(hits) == 1:
        return hits[0]
    if not hits:
        raise KeyError(f'unknown clip {name!r} (give a clip id or name from the split file, '
                       "e.g. 'dataset-1_walk_normal_001' or '02_01')")
    raise KeyError(f'clip name {name!r} is ambiguous: {", ".join(hits[:4])}'
                   + (' ...' if len(hits) > 4 else ''))


def describe_rule() -> str:
    """The rule as one paragraph (for reports)."""
    return ' '.join(RULE)


def strata_table(splits: Splits) -> List[Tuple[str, int, int, float, float]]:
    """(stratum, train clips, validation clips, validation hours, validation share) rows."""
    rows = []
    for s, row in splits.counts.get('strata', {}).items():
        rows.append((s, row['train']['clips'], row['validation']['clips'],
                     row['validation']['hours'], row['validation_share']))
    return rows

