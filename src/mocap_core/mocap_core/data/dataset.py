"""The processed motion dataset: build, cache, load and report (no ROS imports).

:func:`build_dataset` retargets every clip of the sources (:mod:`.retarget`), resamples it to
one rate, puts its floor at z = 0 and labels its foot contacts (:func:`.motion.process_motion`),
and stores the result as one compressed NumPy file per split (``train.npz``,
``validation.npz``) with a ``manifest.json`` and a report, in a cache directory outside the
repository::

    ~/.cache/mocap/dataset/<key>/      ($MOCAP_CACHE_DIR or $XDG_CACHE_HOME/mocap instead of
                                         ~/.cache/mocap)

``<key>`` hashes everything the content depends on: the source files (path, size, mtime), the
output rate, the split file and the code of the processing chain (:func:`code_version`). So a
changed source, setting, split or algorithm gives another key and the dataset is rebuilt
automatically; an unchanged one is reused (a build takes about a minute on 2 cores). The 3
most recent datasets are kept, older ones removed.

Training code reads it with :func:`load_dataset` (``list[Motion]``) or :func:`load_split`
(concatenated arrays + per-clip offsets, the form to sample windows from). The split of every
clip comes from the committed ``splits.json`` (:mod:`.splits`); validation clips are stored in
``validation.npz`` only, so training code that reads ``train`` never sees them.

Stored per clip (arrays of ``<split>.npz``; C clips, N frames in all):

==================  =============  ===========================================================
key                 shape / type   meaning
==================  =============  ===========================================================
ids                 (C,) str       clip id (:mod:`.splits`)
formats             (C,) str       source format (``cmu_mb2``, ``cmu_daz``, ``bandai_namco``...)
groups              (C,) str       split group (subject / content-style)
offsets             (C+1,) int64   clip c is frames ``offsets[c]:offsets[c+1]``
group_lengths       (C, 10) f64    bone-group lengths, m (``skeleton.BONE_GROUP_NAMES``)
source_fps          (C,) f64       rate of the source file
source_frames       (C,) int64     frames of the source file
trimmed_frames      (C,) int64     leading source frames dropped (:func:`lead_in_frames`)
fk_error_mean_mm    (C,) f64       retargeting FK error (mean over frames and joints)
fk_error_max_mm     (C,) f64       ... maximum
unit_scale          (C,) f64       metres per source unit used
rotations           (N, 18, 4) f32 local quaternions x, y, z, w (row 0: root in the world)
root_positions      (N, 3) f32     pelvis position, m, world frame (z up, floor at z = 0)
contacts            (N, 4) bool    left_heel, left_toe, right_heel, right_toe in contact
fps                 () f64         frame rate of all clips
==================  =============  ===========================================================
"""

from __future__ import annotations

import hashlib
import json
import lzma
import os
import platform
import shutil
import tarfile
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from ..skeleton import BONE_GROUP_NAMES, CONTACT_POINT_NAMES, Skeleton
from .bvh import BVH, BVHError, is_bvh_archive, parse_bvh, read_bvh
from .motion import Motion, process_motion
from .splits import (RULE, SPLITS, Splits, _rel, archive_member_ids, clip_labels,
                     expand_sources, hashed_split, iter_source_members, load_splits,
                     nominal_fps, shared_data_dir)

__all__ = [
    'CACHE_FORMAT', 'DatasetError', 'DatasetInfo', 'DatasetSplit', 'default_cache_root',
    'code_version', 'dataset_key', 'process_clip', 'build_dataset', 'load_split',
    'load_dataset', 'compute_report', 'report_markdown', 'find_dataset', 'DEFAULT_FPS',
]

#: Version of the cache layout (part of the key).
CACHE_FORMAT = 1
DEFAULT_FPS = 30.0
#: Datasets kept under the cache root (newest first); older ones are removed after a build.
KEEP_DATASETS = 3
_CODE_FILES = ('data/bvh.py', 'data/retarget.py', 'data/motion.py', 'data/splits.py',
               'data/dataset.py', 'skeleton.py', 'kinematics.py', 'rotations.py')


class DatasetError(RuntimeError):
    """The dataset cannot be built or loaded (one-line message)."""


def default_cache_root() -> Path:
    """``$MOCAP_CACHE_DIR/dataset``, else ``$XDG_CACHE_HOME/mocap/dataset``, else
    ``~/.cache/mocap/dataset``."""
    env = os.environ.get('MOCAP_CACHE_DIR')
    if env:
        return Path(env) / 'dataset'
    xdg = os.environ.get('XDG_CACHE_HOME')
    base = Path(xdg) if xdg else Path.home() / '.cache'
    return base / 'mocap' / 'dataset'


def code_version() -> str:
    """Hash of the source code of the processing chain (BVH, retargeting, motion processing,
    clip ids, this module, skeleton, FK, rotations) and :data:`CACHE_FORMAT`."""
    h = hashlib.sha256(f'cache-format-{CACHE_FORMAT}'.encode())
    pkg = Path(__file__).resolve().parents[1]
    for rel in _CODE_FILES:
        h.update(rel.encode())
        h.update((pkg / rel).read_bytes())
    return h.hexdigest()[:16]


def _splits_of(splits: Union[None, str, os.PathLike, Splits]) -> Splits:
    if isinstance(splits, Splits):
        return splits
    return load_splits(splits)


def dataset_key(sources=None, fps: float = DEFAULT_FPS,
                splits: Union[None, str, os.PathLike, Splits] = None,
                root: Optional[Path] = None) -> Tuple[str, dict]:
    """``(key, settings)``: the cache key and what it hashes (module docstring)."""
    files = expand_sources(sources, root)
    sp = _splits_of(splits)
    entries = []
    for f, base in files:
        st = f.stat()
        entries.append({'path': str(f.resolve()), 'id_base': str(base), 'size': st.st_size,
                        'mtime_ns': st.st_mtime_ns})
    settings = {
        'cache_format': CACHE_FORMAT, 'fps': float(fps), 'code': code_version(),
        'splits_sha256': hashlib.sha256(sp.to_json().encode()).hexdigest()[:16],
        'sources': sorted(entries, key=lambda e: e['path']),
    }
    key = hashlib.sha256(json.dumps(settings, sort_keys=True).encode()).hexdigest()[:16]
    return key, settings


# ---------------------------------------------------------------------------------------------
# processing
# ---------------------------------------------------------------------------------------------
#: Lead-in trimming: at most this many seconds are dropped at the start of a clip.
LEAD_IN_MAX_SECONDS = 0.25
#: ... while the fastest mapped joint moves more than this times the 90th percentile of its
#: per-frame displacement over the clip (and at least LEAD_IN_MIN_STEP_M per source frame).
LEAD_IN_FACTOR = 2.0
LEAD_IN_MIN_STEP_M = 0.01
#: Frame 0 is a rest pose when all its non-root rotation channels are within this (deg).
LEAD_IN_REST_DEG = 20.0
#: Within the lead-in window, a pelvis displacement faster than this (m/s) is a jump of the
#: capture, not human motion: the frames up to it are dropped too.
TELEPORT_SPEED_MPS = 15.0


def lead_in_frames(bvh: BVH, source_positions: np.ndarray) -> int:
    """Number of leading source frames that are not motion capture.

    The cgspeed CMU conversions start with a rest (T-) pose frame (mb2 ``01_01``, every DAZ
    file: all non-root rotation channels within a few degrees of 0, or the ASF rest's +-17 deg
    at the hips), and the DAZ ones then blend into the motion over about 4 frames at 120 fps,
    with joints jumping 12-23 cm per frame (2-30 times the clip's median, also in running
    clips). When frame 0 is such a rest pose (every non-root rotation channel within
    :data:`LEAD_IN_REST_DEG`), frame 0 is dropped, and so are the next frames while the largest
    joint displacement to the following frame exceeds :data:`LEAD_IN_FACTOR` x the 90th
    percentile of that displacement over the clip (and :data:`LEAD_IN_MIN_STEP_M`), up to
    :data:`LEAD_IN_MAX_SECONDS`. In any clip, a pelvis jump faster than
    :data:`TELEPORT_SPEED_MPS` within that window also drops the frames before it (DAZ
    ``09_10`` holds a rest pose for 5 frames, then its pelvis moves 2.1 m in one 120 fps
    frame). Any other clip is not trimmed (Bandai Namco, CMU ASF-named files, the TMoCo mb2
    files).
    """
    if bvh.num_frames < 3:
        return 0
    max_frames = min(bvh.num_frames - 2, int(round(LEAD_IN_MAX_SECONDS * bvh.fps)))
    speed = np.linalg.norm(np.diff(source_positions[:max_frames + 1, 0], axis=0),
                           axis=-1) * bvh.fps
    jumps = np.nonzero(speed > TELEPORT_SPEED_MPS)[0]
    after_jump = int(jumps[-1]) + 1 if len(jumps) else 0
    rot_cols = [bvh.channel_start[j] + k for j in range(1, bvh.num_joints)
                for k, c in enumerate(bvh.channels[j]) if c.endswith('rotation')]
    if not rot_cols or np.max(np.abs(bvh.motion[0, rot_cols])) > LEAD_IN_REST_DEG:
        return after_jump
    step = np.linalg.norm(np.diff(source_positions, axis=0), axis=-1).max(axis=-1)
    limit = max(LEAD_IN_FACTOR * float(np.percentile(step, 90)), LEAD_IN_MIN_STEP_M)
    start = 1
    while start < max_frames and step[start] > limit:
        start += 1
    return max(start, after_jump)


def process_clip(bvh: BVH, clip_id: str, fps: float = DEFAULT_FPS,
                 trim_lead_in: bool = True) -> Tuple[Motion, dict]:
    """Retarget, drop the lead-in (:func:`lead_in_frames`), resample to ``fps``, floor to
    z = 0 and label contacts: ``(Motion, info)`` with info keys ``format, source_fps,
    source_frames, trimmed_frames, fk_error_mean_mm, fk_error_max_mm, unit_scale`` (FK error
    over the kept frames). Raises ValueError (BVHError) for a clip that cannot be processed."""
    from .retarget import retarget

    clip = retarget(bvh, name=clip_id or None)
    start = lead_in_frames(bvh, clip.source_positions) if trim_lead_in else 0
    err = 1000.0 * np.linalg.norm(clip.joint_positions()[start:]
                                  - clip.source_positions[start:], axis=-1)
    fps_in = nominal_fps(bvh.frame_time)
    motion = process_motion(clip_id, clip.skeleton, clip.rotations[start:],
                            clip.root_positions[start:], fps_in, fps)
    info = {'format': clip.source_format, 'source_fps': fps_in,
            'source_frames': clip.num_frames, 'trimmed_frames': int(start),
            'fk_error_mean_mm': float(err.mean()), 'fk_error_max_mm': float(err.max()),
            'unit_scale': clip.unit_scale}
    return motion, info


def _record(motion: Motion, info: dict) -> dict:
    return {**info, 'group_lengths': motion.skeleton.group_lengths(),
            'rotations': motion.rotations.astype(np.float32),
            'root_positions': motion.root_positions.astype(np.float32),
            'contacts': motion.contacts.astype(bool)}


def _build_one(job: Tuple[str, str, float]) -> Tuple[List[dict], List[Tuple[str, str]]]:
    """Process one file or archive: (records with 'id', [(id, error)])."""
    path, base, fps = Path(job[0]), Path(job[1]), float(job[2])
    rel = _rel(path, base)
    records: List[Tuple[int, dict]] = []
    errors: List[Tuple[int, str]] = []
    names: List[str] = []
    if is_bvh_archive(path):
        items = iter_source_members(path)
    else:
        items = iter([('', None)])
    try:
        for k, (name, data) in enumerate(items):
            names.append(name)
            try:
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter('always')
                    bvh = read_bvh(path) if data is None else parse_bvh(
                        data.decode('utf-8', errors='replace'), f'{path}:{name}')
                    motion, info = process_clip(bvh, '', fps)
                rec = _record(motion, info)
                rec['warnings'] = [str(w.message) for w in caught]
                records.append((k, rec))
            except (BVHError, ValueError, KeyError) as exc:
                errors.append((k, f'{type(exc).__name__}: {exc}'))
        damaged = ''
    except (tarfile.TarError, EOFError, OSError, lzma.LZMAError) as exc:
        damaged = f'{type(exc).__name__}: {exc}'    # a damaged archive: keep what was read
    ids = [f'{rel}:{m}' for m in archive_member_ids(names)] if is_bvh_archive(path) else [rel]
    out = []
    for k, rec in records:
        rec['id'] = ids[k]
        out.append(rec)
    errs = [(ids[k], e) for k, e in errors]
    if damaged:
        errs.append((rel, f'unreadable after {len(names)} member(s): {damaged}'))
    return out, errs


@dataclass
class DatasetInfo:
    """A built dataset: its directory, manifest and whether this call built it."""

    path: Path
    manifest: dict
    rebuilt: bool

    @property
    def report_json(self) -> Path:
        return self.path / 'report.json'

    @property
    def report_md(self) -> Path:
        return self.path / 'report.md'

    def report(self) -> dict:
        return json.loads(self.report_json.read_text())


def _expected_clips(splits: Splits, rels: Sequence[str]) -> Optional[int]:
    rs = set(rels)
    n = 0
    for i in splits.clips:
        if i in rs or i.partition(':')[0] in rs:
            n += 1
    return n or None


def _valid(path: Path, key: str) -> Optional[dict]:
    man = path / 'manifest.json'
    if not man.is_file():
        return None
    try:
        manifest = json.loads(man.read_text())
    except (OSError, json.JSONDecodeError):
        return None
    if manifest.get('key') != key:
        return None
    if not all((path / f'{s}.npz').is_file() for s in SPLITS):
        return None
    return manifest


def find_dataset(sources=None, fps: float = DEFAULT_FPS, splits=None,
                 cache_root: Union[None, str, os.PathLike] = None,
                 root: Optional[Path] = None) -> Optional[DatasetInfo]:
    """The cached dataset for these settings, or None when it is not built (or stale)."""
    key, _ = dataset_key(sources, fps, splits, root)
    path = Path(cache_root or default_cache_root()) / key
    manifest = _valid(path, key)
    return DatasetInfo(path, manifest, False) if manifest else None


def build_dataset(sources=None, cache_root: Union[None, str, os.PathLike] = None,
                  fps: float = DEFAULT_FPS, workers: int = 2,
                  splits: Union[None, str, os.PathLike, Splits] = None,
                  progress: bool = True, force: bool = False,
                  root: Optional[Path] = None) -> DatasetInfo:
    """Build (or reuse) the processed dataset; see the module docstring.

    Args:
        sources: BVH files, tar archives or directories (default: the shared CMU and Bandai
            Namco folders, :func:`~.splits.default_sources`).
        cache_root: where dataset directories live (default :func:`default_cache_root`).
        fps: output frame rate.
        workers: processes (one source file or archive each at a time).
        splits: split file or :class:`~.splits.Splits` (default: the committed one). Clips it
            does not list get :func:`~.splits.hashed_split` of their group (and are counted
            in the manifest as ``unlisted``).
        progress: show a tqdm progress bar (stderr).
        force: rebuild even when a valid cache exists.
        root: data root for clip ids (default :func:`~.splits.shared_data_dir`).
    """
    if not fps > 0:
        raise ValueError(f'frame rate must be positive, got {fps}')
    sp = _splits_of(splits)
    root = shared_data_dir() if root is None else Path(root)
    key, settings = dataset_key(sources, fps, sp, root)
    cache_root = Path(cache_root or default_cache_root())
    path = cache_root / key
    manifest = None if force else _valid(path, key)
    if manifest is not None:
        return DatasetInfo(path, manifest, False)

    t0 = time.perf_counter()
    files = expand_sources(sources, root)
    jobs = sorted(((str(f), str(b), float(fps)) for f, b in files),
                  key=lambda j: -os.path.getsize(j[0]))
    rels = [_rel(Path(j[0]), Path(j[1])) for j in jobs]
    from tqdm import tqdm

    bar = tqdm(total=_expected_clips(sp, rels), unit='clip', desc='mocap data build',
               disable=not progress, dynamic_ncols=True)
    records: List[dict] = []
    errors: List[Tuple[str, str]] = []
    try:
        if workers > 1 and len(jobs) > 1:
            import multiprocessing as mp
            method = 'fork' if 'fork' in mp.get_all_start_methods() else 'spawn'
            with mp.get_context(method).Pool(min(workers, len(jobs))) as pool:
                for recs, errs in pool.imap_unordered(_build_one, jobs, chunksize=1):
                    records.extend(recs)
                    errors.extend(errs)
                    bar.update(len(recs) + len(errs))
        else:
            for job in jobs:
                recs, errs = _build_one(job)
                records.extend(recs)
                errors.extend(errs)
                bar.update(len(recs) + len(errs))
    finally:
        bar.close()
    process_seconds = time.perf_counter() - t0

    by_split: Dict[str, List[dict]] = {s: [] for s in SPLITS}
    unlisted, excluded = [], []
    for rec in sorted(records, key=lambda r: r['id']):
        lab = clip_labels(rec['id'], rec['format'])
        rec['group'] = lab['group']
        if rec['id'] in sp.clips:
            split = sp.clips[rec['id']][0]
        else:
            split = hashed_split(lab['group'], sp.fraction, sp.salt)
            unlisted.append(rec['id'])
        if split == 'excluded':
            excluded.append(rec['id'])
            continue
        by_split[split].append(rec)
    if not any(by_split.values()):
        raise DatasetError('no clip could be processed'
                           + (f' (first error: {errors[0][0]}: {errors[0][1]})' if errors else ''))

    tmp = cache_root / f'.{key}.tmp-{os.getpid()}'
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir(parents=True)
    try:
        for split, recs in by_split.items():
            _save_split(tmp / f'{split}.npz', recs, fps)
        build_seconds = time.perf_counter() - t0
        manifest = {
            'key': key, 'settings': settings, 'fps': float(fps),
            'splits_file': str(sp.path) if sp.path else '',
            'split_rule': list(RULE), 'split_strata': sp.counts.get('strata', {}),
            'created': time.strftime('%Y-%m-%dT%H:%M:%S%z'),
            'build_seconds': round(build_seconds, 2),
            'process_seconds': round(process_seconds, 2), 'workers': int(workers),
            'machine': f'{platform.machine()}, {os.cpu_count()} CPU cores, '
                       f'Python {platform.python_version()}',
            'counts': {s: {'clips': len(r), 'frames': int(sum(len(x['rotations']) for x in r))}
                       for s, r in by_split.items()},
            'errors': [{'id': i, 'error': e} for i, e in sorted(errors)],
            'excluded': excluded, 'unlisted': unlisted,
            'warnings': {r['id']: r['warnings'] for r in records if r.get('warnings')},
        }
        (tmp / 'manifest.json').write_text(json.dumps(manifest, indent=1) + '\n')
        report = compute_report(tmp, manifest)
        report['dataset_dir'] = str(path)
        (tmp / 'report.json').write_text(json.dumps(report, indent=1) + '\n')
        (tmp / 'report.md').write_text(report_markdown(report))
        if path.exists():
            shutil.rmtree(path)
        tmp.rename(path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    _prune(cache_root, keep=path)
    return DatasetInfo(path, manifest, True)


def _save_split(path: Path, recs: List[dict], fps: float) -> None:
    lengths = [len(r['rotations']) for r in recs]
    offsets = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)

    def cat(k, shape, dtype):
        if not recs:
            return np.zeros((0,) + shape, dtype)
        return np.concatenate([r[k] for r in recs]).astype(dtype)

    np.savez_compressed(
        path,
        ids=np.array([r['id'] for r in recs], dtype=str),
        formats=np.array([r['format'] for r in recs], dtype=str),
        groups=np.array([r['group'] for r in recs], dtype=str),
        offsets=offsets,
        group_lengths=np.array([r['group_lengths'] for r in recs],
                               dtype=np.float64).reshape(-1, len(BONE_GROUP_NAMES)),
        source_fps=np.array([r['source_fps'] for r in recs], dtype=np.float64),
        source_frames=np.array([r['source_frames'] for r in recs], dtype=np.int64),
        trimmed_frames=np.array([r['trimmed_frames'] for r in recs], dtype=np.int64),
        fk_error_mean_mm=np.array([r['fk_error_mean_mm'] for r in recs], dtype=np.float64),
        fk_error_max_mm=np.array([r['fk_error_max_mm'] for r in recs], dtype=np.float64),
        unit_scale=np.array([r['unit_scale'] for r in recs], dtype=np.float64),
        rotations=cat('rotations', (18, 4), np.float32),
        root_positions=cat('root_positions', (3,), np.float32),
        contacts=cat('contacts', (4,), bool),
        fps=np.float64(fps),
    )


def _prune(cache_root: Path, keep: Path, n: int = KEEP_DATASETS) -> None:
    """Remove all but the ``n`` newest dataset directories (those with a manifest)."""
    try:
        dirs = [d for d in cache_root.iterdir()
                if d.is_dir() and not d.name.startswith('.') and (d / 'manifest.json').is_file()]
    except OSError:
        return
    dirs.sort(key=lambda d: (d == keep, (d / 'manifest.json').stat().st_mtime), reverse=True)
    for d in dirs[n:]:
        shutil.rmtree(d, ignore_errors=True)


# ---------------------------------------------------------------------------------------------
# loading
# ---------------------------------------------------------------------------------------------
@dataclass(eq=False)
class DatasetSplit:
    """One split of a built dataset as concatenated arrays (module docstring table)."""

    split: str
    fps: float
    ids: np.ndarray
    formats: np.ndarray
    groups: np.ndarray
    offsets: np.ndarray
    group_lengths: np.ndarray
    source_fps: np.ndarray
    source_frames: np.ndarray
    trimmed_frames: np.ndarray
    fk_error_mean_mm: np.ndarray
    fk_error_max_mm: np.ndarray
    unit_scale: np.ndarray
    rotations: np.ndarray
    root_positions: np.ndarray
    contacts: np.ndarray

    def __len__(self) -> int:
        return len(self.ids)

    @property
    def num_frames(self) -> int:
        return int(self.offsets[-1])

    def lengths(self) -> np.ndarray:
        return np.diff(self.offsets)

    def index(self, clip: str) -> int:
        """Index of a clip by id or short name (:func:`~.splits.resolve_clip`)."""
        from .splits import resolve_clip
        return int(np.flatnonzero(self.ids == resolve_clip(clip, self.ids.tolist()))[0])

    def motion(self, i: int) -> Motion:
        """Clip ``i`` as a :class:`~.motion.Motion` (float64 arrays)."""
        a, b = int(self.offsets[i]), int(self.offsets[i + 1])
        return Motion(str(self.ids[i]), float(self.fps),
                      Skeleton.from_group_lengths(self.group_lengths[i]),
                      self.rotations[a:b].astype(np.float64),
                      self.root_positions[a:b].astype(np.float64),
                      self.contacts[a:b].copy())

    def motions(self) -> List[Motion]:
        return [self.motion(i) for i in range(len(self))]

    @classmethod
    def load(cls, path: Union[str, os.PathLike], split: str) -> 'DatasetSplit':
        try:
            with np.load(path, allow_pickle=False) as z:
                return cls(split=split, fps=float(z['fps']),
                           **{k: z[k] for k in ('ids', 'formats', 'groups', 'offsets',
                                                'group_lengths', 'source_fps',
                                                'source_frames', 'trimmed_frames',
                                                'fk_error_mean_mm',
                                                'fk_error_max_mm', 'unit_scale', 'rotations',
                                                'root_positions', 'contacts')})
        except (OSError, KeyError, ValueError) as exc:
            raise DatasetError(f'cannot read dataset file {path}: {exc}') from None


def load_split(split: str, dataset: Union[None, str, os.PathLike, DatasetInfo] = None,
               **build_kwargs) -> DatasetSplit:
    """Arrays of one split (``'train'`` or ``'validation'``).

    ``dataset``: a built dataset directory or :class:`DatasetInfo`; default: build or reuse
    the cache with ``build_kwargs`` (those of :func:`build_dataset`)."""
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r} (use 'train' or 'validation')")
    if dataset is None:
        dataset = build_dataset(**build_kwargs)
    path = dataset.path if isinstance(dataset, DatasetInfo) else Path(dataset)
    f = path / f'{split}.npz'
    if not f.is_file():
        raise DatasetError(f'no {split} data in {path} (run `mocap data build`)')
    return DatasetSplit.load(f, split)


def load_dataset(split: str, dataset=None, **build_kwargs) -> List[Motion]:
    """The clips of one split as :class:`~.motion.Motion` objects (see :func:`load_split`)."""
    return load_split(split, dataset, **build_kwargs).motions()


# ---------------------------------------------------------------------------------------------
# report
# ---------------------------------------------------------------------------------------------
def _stats(x: np.ndarray) -> Dict[str, float]:
    x = np.asarray(x, dtype=np.float64)
    if x.size == 0:
        return {'min': float('nan'), 'median': float('nan'), 'max': float('nan')}
    return {'min': round(float(x.min()), 4), 'median': round(float(np.median(x)), 4),
            'max': round(float(x.max()), 4)}


def _source_of(clip_id: str) -> str:
    """Folder or archive a clip comes from (its id up to ':' or the last '/')."""
    if ':' in clip_id:
        return clip_id.partition(':')[0]
    return clip_id.rpartition('/')[0] or '.'


def compute_report(path: Union[str, os.PathLike], manifest: Optional[dict] = None) -> dict:
    """Figures of a built dataset directory (clips, frames, hours per split / format / source,
    bone-length ranges, contact ratios, FK error, build time)."""
    path = Path(path)
    if manifest is None:
        manifest = json.loads((path / 'manifest.json').read_text())
    parts = [DatasetSplit.load(path / f'{s}.npz', s) for s in SPLITS]
    fps = float(manifest['fps'])
    ids = np.concatenate([p.ids for p in parts])
    fmts = np.concatenate([p.formats for p in parts])
    splits = np.concatenate([np.full(len(p), p.split) for p in parts])
    lengths = np.concatenate([p.lengths() for p in parts]).astype(np.int64)
    gl = np.concatenate([p.group_lengths for p in parts])
    fk_mean = np.concatenate([p.fk_error_mean_mm for p in parts])
    fk_max = np.concatenate([p.fk_error_max_mm for p in parts])
    contacts = np.concatenate([p.contacts for p in parts])
    clip_of_frame = np.repeat(np.arange(len(ids)), lengths)
    src_frames = np.concatenate([p.source_frames for p in parts])
    trimmed = np.concatenate([p.trimmed_frames for p in parts])

    def block(mask) -> dict:
        fr = int(lengths[mask].sum())
        return {'clips': int(mask.sum()), 'frames': fr, 'hours': round(fr / fps / 3600.0, 4)}

    sources = np.array([_source_of(i) for i in ids])
    report = {
        'dataset_dir': str(path), 'fps': fps,
        'created': manifest.get('created', ''),
        'build_seconds': manifest.get('build_seconds'),
        'process_seconds': manifest.get('process_seconds'),
        'workers': manifest.get('workers'), 'machine': manifest.get('machine', ''),
        'source_frames': int(src_frames.sum()),
        'lead_in_trimmed': {'clips': int((trimmed > 0).sum()),
                            'source_frames': int(trimmed.sum())},
        'total': block(np.ones(len(ids), bool)),
        'per_split': {s: block(splits == s) for s in SPLITS},
        'per_format': {f: {**block(fmts == f),
                           **{f'{s}_clips': int(((fmts == f) & (splits == s)).sum())
                              for s in SPLITS}}
                       for f in sorted(set(fmts.tolist()))},
        'per_source': {s: {**block(sources == s),
                           'validation_clips': int(((sources == s)
                                                    & (splits == 'validation')).sum())}
                       for s in sorted(set(sources.tolist()))},
        'bone_lengths_m': {g: _stats(gl[:, k]) for k, g in enumerate(BONE_GROUP_NAMES)},
        'bone_lengths_m_per_format': {
            f: {g: _stats(gl[fmts == f, k]) for k, g in enumerate(BONE_GROUP_NAMES)}
            for f in sorted(set(fmts.tolist()))},
        'contact_ratio': {n: round(float(contacts[:, k].mean()), 4) if len(contacts) else 0.0
                          for k, n in enumerate(CONTACT_POINT_NAMES)},
        'contact_ratio_per_format': {
            f: {n: round(float(contacts[np.isin(clip_of_frame, np.flatnonzero(fmts == f)), k]
                               .mean()), 4) for k, n in enumerate(CONTACT_POINT_NAMES)}
            for f in sorted(set(fmts.tolist()))},
        'no_contact_ratio': round(float((~contacts.any(axis=1)).mean()), 4)
        if len(contacts) else 0.0,
        'fk_error_mm': {},
        'split_rule': manifest.get('split_rule', []),
        'split_strata': manifest.get('split_strata', {}),
        'errors': manifest.get('errors', []),
        'excluded_by_split_file': manifest.get('excluded', []),
        'unlisted': manifest.get('unlisted', []),
    }
    for f in sorted(set(fmts.tolist())) + ['all']:
        m = np.ones(len(ids), bool) if f == 'all' else fmts == f
        w = lengths[m].astype(np.float64)
        worst = int(np.flatnonzero(m)[np.argmax(fk_max[m])])
        report['fk_error_mm'][f] = {
            'clips': int(m.sum()),
            'mean': round(float((fk_mean[m] * w).sum() / max(w.sum(), 1.0)), 3),
            'median_clip_mean': round(float(np.median(fk_mean[m])), 3),
            'worst_clip_mean': round(float(fk_mean[m].max()), 3),
            'max': round(float(fk_max[worst]), 2), 'worst_clip': str(ids[worst]),
        }
    return report


def report_markdown(r: dict) -> str:
    """The report as Markdown."""
    def row(*cells):
        return '| ' + ' | '.join(str(c) for c in cells) + ' |'

    t = r['total']
    out = [
        '# Motion dataset report',
        '',
        f"Written by `mocap data build` ({r.get('created', '')}). Every clip of the sources "
        f"retargeted to the pipeline skeleton, resampled to {r['fps']:g} fps, floor at z = 0, "
        'heel/toe contact labels; split from the committed `splits.json`.',
        '',
        f"- **{t['clips']} clips, {t['frames']:,} frames at {r['fps']:g} fps, "
        f"{t['hours']:.2f} hours** ({r['source_frames']:,} source frames; the rest-pose "
        f"lead-in of {r['lead_in_trimmed']['clips']} clips, "
        f"{r['lead_in_trimmed']['source_frames']} source frames, dropped)",
        f"- build time: **{r['build_seconds']} s** ({r['process_seconds']} s retargeting and "
        f"processing) with {r['workers']} worker(s) on {r['machine']}",
        f"- cache: `{r['dataset_dir']}`",
        '',
        '## Splits',
        '',
        row('split', 'clips', 'frames', 'hours'), row('---', '---:', '---:', '---:'),
    ]
    for s, b in r['per_split'].items():
        out.append(row(s, b['clips'], f"{b['frames']:,}", f"{b['hours']:.3f}"))
    if r.get('split_rule'):
        out += ['', 'Rule (`mocap_core/data/splits.py`):', '']
        out += [f'- {line}' for line in r['split_rule']]
    if r.get('split_strata'):
        out += ['', row('stratum', 'validation share (duration)', 'validation groups'),
                row('---', '---:', '---')]
        for st, b in r['split_strata'].items():
            out.append(row(st, f"{100 * b['validation_share']:.1f} %",
                           ', '.join(f'`{g}`' for g in b['validation_groups'])))
    out += ['', '## Per source format', '',
            row('format', 'clips', 'train', 'validation', 'frames', 'hours'),
            row('---', '---:', '---:', '---:', '---:', '---:')]
    for f, b in r['per_format'].items():
        out.append(row(f, b['clips'], b['train_clips'], b['validation_clips'],
                       f"{b['frames']:,}", f"{b['hours']:.3f}"))
    out += ['', '## Per source (folder or archive)', '',
            row('source', 'clips', 'validation clips', 'frames', 'hours'),
            row('---', '---:', '---:', '---:', '---:')]
    for s, b in r['per_source'].items():
        out.append(row(f'`{s}`', b['clips'], b['validation_clips'], f"{b['frames']:,}",
                       f"{b['hours']:.3f}"))
    out += ['', '## Bone lengths (m, per clip: min / median / max)', '',
            row('group', 'all', *r['bone_lengths_m_per_format'].keys()),
            row('---', *(['---'] * (1 + len(r['bone_lengths_m_per_format']))))]
    for g, st in r['bone_lengths_m'].items():
        cells = [f"{st['min']:.3f} / {st['median']:.3f} / {st['max']:.3f}"]
        for per in r['bone_lengths_m_per_format'].values():
            s2 = per[g]
            cells.append(f"{s2['min']:.3f} / {s2['median']:.3f} / {s2['max']:.3f}")
        out.append(row(g, *cells))
    names = list(r['contact_ratio'].keys())
    out += ['', '## Foot contact ratio (fraction of frames in contact)', '',
            row('format', *names), row('---', *(['---:'] * len(names)))]
    out.append(row('all', *(f"{r['contact_ratio'][n]:.3f}" for n in names)))
    for f, per in r['contact_ratio_per_format'].items():
        out.append(row(f, *(f'{per[n]:.3f}' for n in names)))
    out += ['', f"Frames with no foot point in contact: {r['no_contact_ratio']:.3f}.",
            '', '## Retargeting FK error (mm)', '',
            row('format', 'clips', 'mean (frame-weighted)', 'median clip', 'worst clip mean',
                'max', 'worst clip'),
            row('---', '---:', '---:', '---:', '---:', '---:', '---')]
    for f, e in r['fk_error_mm'].items():
        out.append(row(f, e['clips'], e['mean'], e['median_clip_mean'], e['worst_clip_mean'],
                       e['max'], f"`{e['worst_clip']}`"))
    if r.get('errors'):
        out += ['', '## Clips that could not be processed', '']
        out += [f"- `{e['id']}`: {e['error']}" for e in r['errors']]
    if r.get('excluded_by_split_file'):
        out += ['', '## Excluded by the split file', '']
        out += [f'- `{i}`' for i in r['excluded_by_split_file']]
    if r.get('unlisted'):
        out += ['', f"{len(r['unlisted'])} clip(s) not in the split file were assigned by "
                'the group hash.']
    return '\n'.join(out) + '\n'
