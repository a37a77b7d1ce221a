"""The resumable, cached batch behind ``mocap data render`` (no ROS imports).

Jobs are the clips of the committed split (``data/splits.json``; the dataset cache of
``mocap data build``) or user BVH files. Order: the validation clips first (the rendered
benchmark), then the training clips; within a split, clips are ordered by their seeded hash,
so any prefix of a run is a random sample and a later run extends it. Clip folders are
``<out>/<split>/<clip_key>/``; a clip with a ``done`` file is skipped (resume), a half-written
one (``*.partial``) is redone. Workers are separate processes (spawned, one body model and one
detector each, one torch thread); a clip that fails is logged with its reason in
``<out>/failures.jsonl`` and the rest go on. ``<out>/summary.json`` counts what is there.
"""

from __future__ import annotations

import json
import logging
import os
import time
import traceback
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path
from typing import Dict, Iterable, List, Optional, Sequence

import numpy as np

from .clip import clip_key, clip_seed, is_done, iter_done

log = logging.getLogger('mocap.render')

#: Default cache of rendered clips.
DEFAULT_OUT = Path.home() / '.cache' / 'mocap' / 'render'


@dataclass(frozen=True)
class Job:
    """One clip to render: ``split`` (train / validation / user), the clip id, and where the
    motion comes from (``dataset_index`` into the split of the dataset cache, or ``bvh``)."""

    split: str
    clip: str
    dataset_index: int = -1
    bvh: str = ''


def travel_per_stretch(root_positions: np.ndarray, fps: float, seconds: float) -> float:
    """Horizontal path length (m) of the pelvis over a stretch of ``seconds`` at the clip's
    mean speed: ``root_positions`` (F, 3) in a z-up world, metres."""
    xy = np.asarray(root_positions, dtype=float)[:, :2]
    if len(xy) < 2:
        return 0.0
    path = float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum())
    duration = (len(xy) - 1) / float(fps)
    return path * min(1.0, seconds / duration)


def plan(splits: Sequence[str], seed: int, limit: Optional[int] = None,
         bvh_files: Sequence[str] = (), min_travel: float = 0.0,
         max_seconds: float = 8.0, speed: float = 1.0) -> List[Job]:
    """The jobs, in rendering order (module docstring). ``limit`` caps the clips per split;
    ``min_travel`` > 0 (m) keeps only the split's clips whose pelvis travels at least that far
    over a ``max_seconds`` stretch of the video (:func:`travel_per_stretch`, at playback
    ``speed``; a benchmark of the world frame needs people who go somewhere), before the
    limit."""
    jobs: List[Job] = []
    for path in bvh_files:
        jobs.append(Job('user', str(Path(path).resolve()), bvh=str(Path(path).resolve())))
    if splits:
        from ..data.dataset import load_split
        for split in splits:
            ds = load_split(split)
            names = [str(n) for n in ds.ids]
            order = sorted(range(len(names)), key=lambda i: clip_seed(seed, names[i]))
            if min_travel > 0:
                motions = (ds.motion(i) for i in order)
                order = [i for i, m in zip(order, motions) if travel_per_stretch(
                    m.root_positions, m.fps, max_seconds * speed) >= min_travel]
            if limit is not None:
                order = order[:limit]
            jobs += [Job(split, names[i], dataset_index=i) for i in order]
    return jobs


# ------------------------------------------------------------------------------------------
# worker side
# ------------------------------------------------------------------------------------------
_WORKER: Dict[str, object] = {}


def _init_worker(detector: str, head_details: bool = True) -> None:
    os.environ.setdefault('OMP_NUM_THREADS', '1')
    import torch
    torch.set_num_threads(1)
    from ..plugins import detector_class
    from .clip import ClipRenderer
    cls = detector_class(detector)
    _WORKER['renderer'] = ClipRenderer(lambda: cls(tracking=True), head_details=head_details)
    _WORKER['splits'] = {}


def _motion(job: Job):
    if job.bvh:
        from ..data.bvh import read_bvh
        from ..data.dataset import process_clip
        motion, _ = process_clip(read_bvh(job.bvh, name=job.clip), job.clip)
        return motion
    splits = _WORKER['splits']
    if job.split not in splits:
        from ..data.dataset import load_split
        splits[job.split] = load_split(job.split)
    return splits[job.split].motion(job.dataset_index)


def _run_job(job: Job, out: str, seed: int, max_frames: Optional[int], camera: str,
             write_bag: bool, speed: float = 1.0) -> dict:
    try:
        from ..data.motion import retime
        motion = retime(_motion(job), speed)
        res = _WORKER['renderer'].render(
            motion, job.clip, job.split, Path(out) / job.split / clip_key(job.clip), seed,
            max_frames=max_frames, camera_kind=camera, write_bag=write_bag)
        return {'clip': job.clip, 'ok': True, 'frames': res.frames,
                'detected': res.detected, 'seconds': res.seconds}
    except Exception as exc:  # noqa: BLE001 - one bad clip must not stop the batch
        return {'clip': job.clip, 'split': job.split, 'ok': False,
                'error': f'{type(exc).__name__}: {exc}',
                'trace': traceback.format_exc(limit=4)}


# ------------------------------------------------------------------------------------------
# driver
# ------------------------------------------------------------------------------------------
def _other_heads(out: Path, jobs: Sequence[Job], head_details: bool) -> int:
    """How many finished clips of ``jobs`` under ``out`` were rendered with the other kind of
    head (``meta.json`` ``head_details``; missing: the plain heads of before session 42)."""
    n = 0
    for j in jobs:
        d = out / j.split / clip_key(j.clip)
        if is_done(d):
            try:
                meta = json.loads((d / 'meta.json').read_text())
            except (OSError, ValueError):
                continue
            n += bool(meta.get('head_details', False)) != bool(head_details)
    return n


def summarize(out: Path) -> dict:
    """Counts over the finished clips under ``out`` (written to ``summary.json``)."""
    out = Path(out)
    by: Dict[str, dict] = {}
    for d in iter_done(out):
        try:
            meta = json.loads((d / 'meta.json').read_text())
        except (OSError, ValueError):
            continue
        s = by.setdefault(meta['split'], {'clips': 0, 'frames': 0, 'detected_frames': 0.0,
                                          'cameras': {}, 'views': {},
                                          'heads': {'face_and_hair': 0, 'plain': 0}})
        s['clips'] += 1
        s['heads']['face_and_hair' if meta.get('head_details') else 'plain'] += 1
        s['frames'] += meta['frames']
        s['detected_frames'] += meta['detected_fraction'] * meta['frames']
        kind = meta['camera']['kind']
        s['cameras'][kind] = s['cameras'].get(kind, 0) + 1
        for v, n in meta['views'].items():
            s['views'][v] = s['views'].get(v, 0) + n
    for s in by.values():
        s['detected_fraction'] = s.pop('detected_frames') / max(s['frames'], 1)
    return by


def run(jobs: Iterable[Job], out: Path, seed: int = 0, workers: int = 2,
        max_frames: Optional[int] = 240, camera: str = '', write_bag: bool = True,
        detector: str = 'blazepose', progress: bool = True, hours: Optional[float] = None,
        speed: float = 1.0, head_details: bool = True) -> dict:
    """Render ``jobs`` into ``out`` with ``workers`` processes; returns the summary.

    ``head_details``: heads with hair and a face (False: the plain heads of the renders
    before session 42; see ``docs/rendering.md``).

    ``speed`` plays every motion at that pace (:func:`mocap_core.data.motion.retime`; 0.5:
    slow motion, the ground truth written is the slowed motion). Clips already done are
    skipped. ``hours`` stops submitting new clips after that long
    (the clips in flight finish), for runs spread over several sessions.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    jobs = list(jobs)
    todo = [j for j in jobs if not is_done(out / j.split / clip_key(j.clip))]
    other = _other_heads(out, jobs, head_details)
    if other:
        log.warning('%d finished clip(s) of these splits in %s have %s heads; they are kept '
                    '(clips are cached by name), so the set mixes both kinds. Use another -o '
                    'for a set of one kind (docs/rendering.md).', other, out,
                    'plain' if head_details else 'detailed')
    skipped = 0
    from .body import load_anny
    load_anny()  # builds Anny's cache once (about a minute), before the workers read it
    try:
        from tqdm import tqdm
        bar = tqdm(total=len(todo), unit='clip', disable=not progress, dynamic_ncols=True)
    except ImportError:  # pragma: no cover - tqdm is a project dependency
        bar = None
    t0 = time.monotonic()
    frames = 0
    rendered = 0
    failures = out / 'failures.jsonl'
    ctx = get_context('spawn')
    pending = list(reversed(todo))
    with ProcessPoolExecutor(max_workers=max(1, workers), mp_context=ctx,
                             initializer=_init_worker, initargs=(detector, head_details)) as pool:
        running = set()

        def submit() -> None:
            while pending and len(running) < 2 * max(1, workers):
                if hours is not None and time.monotonic() - t0 > hours * 3600:
                    pending.clear()
                    return
                running.add(pool.submit(_run_job, pending.pop(), str(out), seed, max_frames,
                                        camera, write_bag, speed))

        submit()
        while running:
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for fut in done:
                running.discard(fut)
                r = fut.result()
                if r['ok']:
                    frames += r['frames']
                    rendered += 1
                else:
                    skipped += 1
                    log.warning('clip %s failed: %s', r['clip'], r['error'])
                    with failures.open('a') as f:
                        f.write(json.dumps(r) + '\n')
                if bar is not None:
                    bar.update(1)
                    bar.set_postfix(fps=f'{frames / max(time.monotonic() - t0, 1e-9):.1f}',
                                    failed=skipped)
            submit()
    if bar is not None:
        bar.close()
    summary = {'splits': summarize(out), 'this_run': {
        'clips_rendered': rendered, 'clips_failed': skipped,
        'clips_left': len(todo) - rendered - skipped,
        'frames': frames, 'seconds': time.monotonic() - t0}}
    (out / 'summary.json').write_text(json.dumps(summary, indent=1))
    return summary
