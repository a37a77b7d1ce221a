"""``mocap data ...``: the motion-capture data pipeline on the command line.

    mocap data build [--fps 30] [--workers 2] [--sources DIR ...] [--report docs/data_report.md]
    mocap data report [--json]
    mocap data split [--check] [--sources DIR ...] [-o splits.json]
    mocap data to-bag <clip | train | validation | file.bvh> -o BAG [--frames N] [--start S]
                      [--seed S] [--distance MIN [MAX]] [--height MIN [MAX]] [--fov MIN [MAX]]
                      [--azimuth MIN [MAX]] [--image-size WxH] [--clean] [--no-world-motion]
    mocap data from-openpose <dir> -o BAG [--fps 30] [--fov 60] [--camera-info YAML]
    mocap data fit-confidence <openpose dirs ...> -o model.json
    mocap data fit-placement [--renders DIR] [--split train] [-o detector_placement.json]
    mocap data render [--split validation|train|all] [--bvh FILE ...] [-o DIR] [--jobs 2]
                      [--limit N] [--max-seconds 8] [--seed 0] [--camera KIND] [--hours H]

The data default to ``$MOCAP_SHARED_DATA`` (else ``<repo>/../shared/data``): its ``cmu_bvh``
and ``bandai_namco_bvh`` folders. Errors are one line on stderr, exit status 1.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import List, Optional, Sequence, Tuple

import numpy as np

_PROG = 'mocap data'


class CommandError(Exception):
    """A user error: printed as one line."""


def _fail(msg: str) -> int:
    print(f'{_PROG}: error: {" ".join(str(msg).split())}', file=sys.stderr)
    return 1


def _guard(fn):
    """Run a command; turn the expected failures into a one-line error."""
    def run(args: argparse.Namespace) -> int:
        from ..bag_io import BagError
        from ..data.dataset import DatasetError
        from ..data.splits import SplitsError
        try:
            return int(fn(args) or 0)
        except (CommandError, BagError, DatasetError, SplitsError, FileNotFoundError,
                NotADirectoryError, ValueError, OSError) as exc:
            return _fail(str(exc))
        except KeyError as exc:  # unknown clip (message already one line)
            return _fail(exc.args[0] if exc.args else str(exc))
    run.__doc__ = fn.__doc__
    return run


def _human(n: int) -> str:
    return f'{n / 1e6:.2f} MB' if n >= 1e6 else f'{n / 1e3:.0f} kB'


def _range(values: Optional[Sequence[float]], name: str) -> Optional[Tuple[float, float]]:
    if values is None:
        return None
    if len(values) == 1:
        return float(values[0]), float(values[0])
    if len(values) == 2:
        lo, hi = float(values[0]), float(values[1])
        if lo > hi:
            raise CommandError(f'--{name}: MIN {lo} is larger than MAX {hi}')
        return lo, hi
    raise CommandError(f'--{name} takes one value or MIN MAX')


def _image_size(text: Optional[str]) -> Optional[Tuple[int, int]]:
    if text is None:
        return None
    try:
        w, h = (int(v) for v in text.lower().split('x'))
        if w <= 0 or h <= 0:
            raise ValueError
        return w, h
    except ValueError:
        raise CommandError(f'--image-size must be WIDTHxHEIGHT, e.g. 1280x720, got {text!r}') \
            from None


def _sources(args) -> Optional[List[Path]]:
    return [Path(s) for s in args.sources] if getattr(args, 'sources', None) else None


def _check_data(sources) -> None:
    """One clear line when the default data are absent."""
    from ..data.splits import default_sources, shared_data_dir
    if sources is None and not any(p.exists() for p in default_sources()):
        raise CommandError(f'motion-capture data not found in {shared_data_dir()} (set '
                           'MOCAP_SHARED_DATA to the folder holding cmu_bvh/ and '
                           'bandai_namco_bvh/, or pass --sources)')


# ---------------------------------------------------------------------------------------------
# build / report
# ---------------------------------------------------------------------------------------------
def _write_report(report: dict, path: Path) -> Tuple[Path, Path]:
    from ..data.dataset import report_markdown
    path.parent.mkdir(parents=True, exist_ok=True)
    md = path if path.suffix == '.md' else path.with_suffix('.md')
    md.write_text(report_markdown(report))
    js = md.with_suffix('.json')
    js.write_text(json.dumps(report, indent=1) + '\n')
    return md, js


@_guard
def cmd_build(args: argparse.Namespace) -> int:
    """Retarget and process every clip; cache it; print and write the report."""
    from ..data.dataset import build_dataset, report_markdown

    sources = _sources(args)
    _check_data(sources)
    t0 = time.perf_counter()
    info = build_dataset(sources, cache_root=args.cache_dir, fps=args.fps,
                         workers=args.workers, splits=args.splits,
                         progress=not args.no_progress, force=args.force)
    report = info.report()
    if not args.quiet:
        print(report_markdown(report))
    state = 'built' if info.rebuilt else 'up to date (cached; --force rebuilds)'
    print(f'dataset {state}: {info.path} ({time.perf_counter() - t0:.1f} s)')
    if args.report:
        md, js = _write_report(report, Path(args.report))
        print(f'wrote {md} and {js}')
    return 0


@_guard
def cmd_report(args: argparse.Namespace) -> int:
    """Print the report of the dataset built for these settings."""
    from ..data.dataset import find_dataset, report_markdown

    sources = _sources(args)
    _check_data(sources)
    info = find_dataset(sources, args.fps, args.splits, args.cache_dir)
    if info is None:
        raise CommandError('no dataset built for these sources and settings (run '
                           '`mocap data build` first)')
    report = info.report()
    print(json.dumps(report, indent=1) if args.json else report_markdown(report))
    if args.output:
        md, js = _write_report(report, Path(args.output))
        print(f'wrote {md} and {js}', file=sys.stderr)
    return 0


# ---------------------------------------------------------------------------------------------
# split
# ---------------------------------------------------------------------------------------------
@_guard
def cmd_split(args: argparse.Namespace) -> int:
    """Regenerate the split file from the data, or check the committed one."""
    from ..data.splits import SPLITS_PATH, load_splits, make_splits, scan_sources

    sources = _sources(args)
    _check_data(sources)
    t0 = time.perf_counter()
    new = make_splits(scan_sources(sources, workers=args.workers), fraction=args.fraction)
    path = Path(args.output) if args.output else SPLITS_PATH
    c = new.counts
    figures = (f"train {c['train']['clips']} clips / {c['train']['hours']:.2f} h, "
               f"validation {c['validation']['clips']} clips / "
               f"{c['validation']['hours']:.2f} h, excluded {c['excluded']['clips']}")
    if args.check:
        old = load_splits(path)
        if old.to_json() == new.to_json():
            print(f'{path}: up to date ({figures}; scanned in '
                  f'{time.perf_counter() - t0:.1f} s)')
            return 0
        added = sorted(set(new.clips) - set(old.clips))
        gone = sorted(set(old.clips) - set(new.clips))
        moved = sorted(i for i in set(new.clips) & set(old.clips)
                       if new.clips[i][0] != old.clips[i][0])
        raise CommandError(f'{path} does not match the data: {len(added)} new clip(s), '
                           f'{len(gone)} missing, {len(moved)} in another split'
                           + (f' (e.g. {(added + gone + moved)[0]})' if added + gone + moved
                              else ' (rule or counts differ)')
                           + '; run `mocap data split` to regenerate it')
    new.write(path)
    print(f'wrote {path}: {figures}')
    for stratum, row in new.counts['strata'].items():
        print(f"  {stratum:18s} validation {row['validation']['clips']:4d} clips "
              f"({100 * row['validation_share']:.1f} % of the duration): "
              f"{', '.join(row['validation_groups'][:8])}"
              + (' ...' if len(row['validation_groups']) > 8 else ''))
    return 0


# ---------------------------------------------------------------------------------------------
# to-bag
# ---------------------------------------------------------------------------------------------
def load_source_clip(clip_id: str, root: Path):
    """Read one clip of the split file from the data root (a file or an archive member)."""
    from ..data.bvh import parse_bvh, read_bvh
    from ..data.splits import archive_member_ids, iter_source_members

    path, sep, member = clip_id.partition(':')
    src = root / path
    if not src.exists():
        raise CommandError(f'clip {clip_id} needs {src}, which does not exist (set '
                           'MOCAP_SHARED_DATA to the motion-capture data folder)')
    if not sep:
        return read_bvh(src, name=clip_id)
    for name, data in iter_source_members(src):
        if name == member or name.endswith('/' + member) or \
                archive_member_ids([name])[0] == member:
            return parse_bvh(data.decode('utf-8', errors='replace'), clip_id)
    raise CommandError(f'{src} has no member {member}')


def _short_name(clip_id: str) -> str:
    tail = clip_id.split(':')[-1]
    tail = tail[:-4] if tail.lower().endswith('.bvh') else tail
    return tail.replace('/', '_')


def _camera_sampling(args):
    from dataclasses import replace

    from ..data.synth2d import CameraSampling
    cfg = CameraSampling()
    kw = {}
    for name in ('distance', 'height', 'azimuth'):
        r = _range(getattr(args, name), name)
        if r is not None:
            kw[name] = r
    fov = _range(args.fov, 'fov')
    if fov is not None:
        if not (1.0 < fov[0] and fov[1] < 179.0):
            raise CommandError(f'--fov must be in (1, 179) degrees, got {args.fov}')
        kw['horizontal_fov'] = fov
    if kw.get('distance') and kw['distance'][0] <= 0:
        raise CommandError('--distance must be positive')
    size = _image_size(args.image_size)
    if size is not None:
        kw['image_sizes'] = (size,)
    return replace(cfg, **kw)


def _write_one(motion, out: Path, args, split: str, seed: int) -> None:
    from ..data.gt_bag import crop_motion, write_groundtruth_bag
    from ..data.synth2d import Corruption

    motion = crop_motion(motion, args.start, args.frames)
    summary = write_groundtruth_bag(
        motion, out, camera=_camera_sampling(args),
        corruption=None if args.clean else Corruption(), seed=seed,
        world_motion=not args.no_world_motion, overwrite=args.overwrite)
    cam = summary.camera
    dist = float(np.linalg.norm((cam.position - motion.root_positions.mean(axis=0))[:2]))
    fov = float(np.degrees(2 * np.arctan(0.5 * cam.intrinsics.width / cam.intrinsics.fx)))
    print(f'wrote {out}: {motion.name} ({split}), {summary.frames} frames at '
          f'{summary.fps:g} fps, {"clean" if summary.clean else "corrupted"} keypoints, '
          f'camera {cam.intrinsics.width}x{cam.intrinsics.height} fov {fov:.0f} deg at '
          f'{dist:.1f} m, height {cam.position[2]:.2f} m, {_human(summary.size_bytes)}')


@_guard
def cmd_to_bag(args: argparse.Namespace) -> int:
    """Ground-truth bag(s) of a clip, a split or a BVH file."""
    from ..data.dataset import load_split, process_clip
    from ..data.splits import SPLITS, load_splits, resolve_clip, shared_data_dir

    if args.frames is not None and args.frames <= 0:
        raise CommandError(f'--frames must be positive, got {args.frames}')
    if args.start < 0:
        raise CommandError(f'--start must be >= 0, got {args.start}')
    _camera_sampling(args)  # validate the options before any work
    out = Path(args.output)
    target = args.clip
    if target in SPLITS:
        _check_data(None)
        data = load_split(target, fps=args.fps, workers=args.workers,
                          progress=not args.no_progress)
        n = len(data) if args.limit is None else min(args.limit, len(data))
        out.mkdir(parents=True, exist_ok=True)
        for i in range(n):
            m = data.motion(i)
            _write_one(m, out / _short_name(m.name), args, target, args.seed + i)
        print(f'{n} bag(s) of the {target} split in {out}')
        return 0
    p = Path(target)
    if p.suffix.lower() == '.bvh' and p.is_file():
        from ..data.bvh import read_bvh
        motion, _ = process_clip(read_bvh(p), p.stem, args.fps)
        _write_one(motion, out, args, 'file', args.seed)
        return 0
    splits = load_splits(args.splits)
    clip_id = resolve_clip(target, [i for i, c in splits.clips.items() if c[0] != 'excluded'])
    bvh = load_source_clip(clip_id, shared_data_dir())
    motion, _ = process_clip(bvh, clip_id, args.fps)
    _write_one(motion, out, args, splits.split_of(clip_id), args.seed)
    return 0


# ---------------------------------------------------------------------------------------------
# OpenPose
# ---------------------------------------------------------------------------------------------
@_guard
def cmd_from_openpose(args: argparse.Namespace) -> int:
    """Keypoint bag from an OpenPose JSON folder."""
    from ..camera import CameraIntrinsics, read_camera_info_yaml
    from ..data.gt_bag import write_openpose_bag

    if not args.fps > 0:
        raise CommandError(f'--fps must be positive, got {args.fps}')
    intr = None
    if args.camera_info:
        intr = read_camera_info_yaml(args.camera_info).intrinsics
    elif args.image_size:
        w, h = _image_size(args.image_size)
        intr = CameraIntrinsics.from_fov(w, h, args.fov)
    s = write_openpose_bag(args.directory, args.output, fps=args.fps, intrinsics=intr,
                           fov=args.fov, overwrite=args.overwrite)
    i = s.intrinsics
    print(f'wrote {s.path}: {s.frames} frames at {s.fps:g} fps, camera {i.width}x{i.height} '
          f'fx {i.fx:.1f}{" (approximate: from --fov)" if i.approximate else ""}, '
          f'{_human(s.size_bytes)}'
          + (f'; skipped {len(s.skipped)} unreadable file(s): {s.skipped[0]}'
             if s.skipped else ''))
    return 0


def most_confident_people(directories: Sequence[str]) -> Tuple[np.ndarray, List[str]]:
    """(N, 23) confidences of the most confident person (largest summed confidence) of every
    frame with at least one person, over OpenPose JSON folders; and the folder names."""
    from mocap_core.data.openpose import list_openpose_files, read_openpose_file

    rows, names = [], []
    for d in directories:
        d = Path(d)
        if not d.is_dir():
            raise CommandError(f'not an OpenPose folder: {d}')
        for _, f in list_openpose_files(d):
            kp = read_openpose_file(f)
            if len(kp):
                rows.append(kp[int(np.argmax(kp[..., 2].sum(axis=-1))), :, 2])
        names.append(d.name)
    if not rows:
        raise CommandError('no person in any frame of the given folders')
    return np.stack(rows), names


@_guard
def cmd_fit_confidence(args: argparse.Namespace) -> int:
    """Fit the keypoint confidence model (MotioNet §4) on real OpenPose detections."""
    from ..data.synth2d import fit_confidence_model

    conf, names = most_confident_people(args.directories)
    source = args.source or (f'OpenPose detections of {len(names)} sequence(s) '
                             f'({", ".join(names)}), most confident person per frame; '
                             'fitted by `mocap data fit-confidence`')
    model = fit_confidence_model(conf, source)
    out = Path(args.output)
    model.to_json(out)
    print(f'wrote {out}: {model.frames} frames; zero probability '
          f'{model.zero_prob.min():.3f}-{model.zero_prob.max():.3f}, mean confidence '
          f'{model.mean.min():.2f}-{model.mean.max():.2f}')
    return 0


# ---------------------------------------------------------------------------------------------
# parser
# ---------------------------------------------------------------------------------------------
# ---------------------------------------------------------------------------------------------
# render
# ---------------------------------------------------------------------------------------------
def cmd_render(args: argparse.Namespace) -> int:
    """Render people driven by motion capture, run the detector, write ground truth."""
    import logging

    from ..render import RendererUnavailable
    from ..render.batch import DEFAULT_OUT, plan, run
    from ..render.cameras import CAMERA_KINDS
    from ..render.scene import check_renderer

    if args.camera and args.camera not in CAMERA_KINDS:
        raise CommandError(f'--camera must be one of {", ".join(CAMERA_KINDS)}')
    if args.jobs < 1 or args.max_seconds <= 0:
        raise CommandError('--jobs must be >= 1 and --max-seconds > 0')
    if not args.min_travel >= 0:
        raise CommandError('--min-travel must be >= 0 (metres)')
    if not args.speed > 0:
        raise CommandError('--speed must be > 0 (1: the captured pace, 0.5: slow motion)')
    for f in args.bvh:
        if not Path(f).is_file():
            raise CommandError(f'{f}: no such BVH file')
    problem = check_renderer()
    if problem:
        raise CommandError(f'cannot render: {problem}')
    splits = {'all': ['validation', 'train'], 'none': []}.get(args.split, [args.split])
    if args.bvh and args.split == 'validation' and not args.split_given:
        splits = []
    logging.basicConfig(level=logging.INFO, format='%(message)s')
    out = Path(args.out) if args.out else DEFAULT_OUT
    jobs = plan(splits, args.seed, args.limit, args.bvh, min_travel=args.min_travel,
                max_seconds=args.max_seconds, speed=args.speed)
    print(f'{_PROG} render: {len(jobs)} clips ({", ".join(splits) or "user BVH"}) -> {out}; '
          f'{args.jobs} worker(s), at most {args.max_seconds:g} s per clip', file=sys.stderr)
    try:
        summary = run(jobs, out, seed=args.seed, workers=args.jobs,
                      max_frames=int(round(args.max_seconds * 30.0)), camera=args.camera,
                      write_bag=not args.no_bag, progress=not args.quiet, hours=args.hours,
                      speed=args.speed, head_details=not args.plain_heads)
    except RendererUnavailable as exc:
        raise CommandError(str(exc)) from None
    r = summary['this_run']
    print(f'rendered {r["clips_rendered"]} clips ({r["frames"]} frames) in {r["seconds"]:.0f} s;'
          f' {r["clips_failed"]} failed (see {out / "failures.jsonl"}); {r["clips_left"]} left')
    for split, s in summary['splits'].items():
        print(f'  {split}: {s["clips"]} clips, {s["frames"]} frames, person detected in '
              f'{100 * s["detected_fraction"]:.1f} % of frames; cameras {s["cameras"]}; '
              f'views {s["views"]}')
    return 1 if r['clips_failed'] else 0


def cmd_fit_placement(args: argparse.Namespace) -> int:
    """Fit where the detector puts the keypoints, on rendered clips."""
    from ..data.detector_placement import PLACEMENT_PATH, fit_detector_placement
    from ..render.batch import DEFAULT_OUT
    from ..render.clip import iter_done, load_clip
    from ..skeleton import KEYPOINT_NAMES

    renders = Path(args.renders) if args.renders else DEFAULT_OUT
    clips = list(iter_done(renders, args.split))
    if len(clips) < args.min_clips:
        raise CommandError(f'{len(clips)} rendered {args.split} clips under {renders}; at least '
                           f'{args.min_clips} needed (mocap data render --split {args.split})')
    placement = fit_detector_placement(
        (load_clip(d)[0] for d in clips),
        info={'renders': args.split, 'command': 'mocap data fit-placement '
              + ' '.join(sys.argv[3:]), 'date': time.strftime('%Y-%m-%d')})
    out = Path(args.output) if args.output else PLACEMENT_PATH
    placement.save(out)
    before = placement.info['median_residual_before_rel_height']
    after = placement.info['median_residual_after_rel_height']
    print(f'{len(clips)} clips; median 2D residual (fraction of the person\'s height) of the '
          'detector against the synthesizer: joints -> placed')
    for k, name in enumerate(KEYPOINT_NAMES):
        if np.isfinite(before[k]):
            print(f'  {name:16s} {before[k]:.4f} -> {after[k]:.4f}   offset (leg lengths) '
                  f'{np.round(placement.offsets[k], 3).tolist()}')
    print(f'wrote {out}')
    return 0


def cmd_fit_stature(args: argparse.Namespace) -> int:
    """Fit stature against Skeleton.height() on rendered clips; check on the validation ones."""
    from ..render.batch import DEFAULT_OUT
    from ..render.clip import iter_done
    from ..render.stature import fit_stature, stature_errors, stature_pairs
    from ..skeleton import STATURE_OFFSET, STATURE_SLOPE

    renders = Path(args.renders) if args.renders else DEFAULT_OUT
    train = stature_pairs(iter_done(renders, 'train'))
    if len(train) < args.min_clips:
        raise CommandError(f'{len(train)} rendered train clips under {renders}; at least '
                           f'{args.min_clips} needed (mocap data render --split train)')
    slope, offset = fit_stature(train)
    print(f'{len(train)} training bodies: stature = {slope:.4f} * height() + {offset:.4f} m '
          f'(shipped: {STATURE_SLOPE:.4f} * height() + {STATURE_OFFSET:.4f})')
    sets = [('train', train)] + [(name, stature_pairs(iter_done(Path(r), 'validation')))
                                 for name, r in [('validation', renders)]
                                 + [(str(x), x) for x in args.check]]
    for name, pairs in sets:
        if not len(pairs):
            continue
        for label, (a, b) in (('fitted', (slope, offset)),
                              ('shipped', (STATURE_SLOPE, STATURE_OFFSET)),
                              ('height() alone', (1.0, 0.0))):
            e = 100 * np.abs(stature_errors(pairs, a, b))
            print(f'  {name} ({len(pairs)} bodies), {label}: |error| median {np.median(e):.2f} '
                  f'cm, p95 {np.percentile(e, 95):.2f} cm')
    return 0


class _SplitAction(argparse.Action):
    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)
        namespace.split_given = True


def add_data_parser(sub) -> None:
    """Add ``data`` and its sub-commands to the ``mocap`` sub-parsers."""
    from ..data.dataset import DEFAULT_FPS

    p = sub.add_parser('data', help='motion-capture data: build the dataset, splits, bags',
                       description='Motion-capture data pipeline (BVH -> training data, '
                       'ground-truth bags, OpenPose bags).')
    dsub = p.add_subparsers(dest='data_command', metavar='DATA_COMMAND')

    def data_opts(q, fps=True):
        q.add_argument('--sources', nargs='+', metavar='PATH',
                       help='BVH files, tar archives or folders (default: cmu_bvh and '
                       'bandai_namco_bvh of $MOCAP_SHARED_DATA)')
        if fps:
            q.add_argument('--fps', type=float, default=DEFAULT_FPS,
                           help=f'output frame rate (default {DEFAULT_FPS:g})')
        q.add_argument('--splits', metavar='JSON', help='split file (default: the committed '
                       'mocap_core/data/splits.json)')
        q.add_argument('--cache-dir', metavar='DIR', help='dataset cache root (default '
                       '~/.cache/mocap/dataset)')

    q = dsub.add_parser('build', help='retarget + process all clips into the cache; report')
    data_opts(q)
    q.add_argument('--workers', type=int, default=2, help='processes (default 2)')
    q.add_argument('--force', action='store_true', help='rebuild even if cached')
    q.add_argument('--report', metavar='MD', help='also write the report here (Markdown, '
                   'and JSON next to it), e.g. docs/data_report.md')
    q.add_argument('--no-progress', action='store_true', help='no progress bar')
    q.add_argument('-q', '--quiet', action='store_true', help='do not print the report')
    q.set_defaults(func=cmd_build)

    q = dsub.add_parser('report', help='print the report of the built dataset')
    data_opts(q)
    q.add_argument('--json', action='store_true', help='JSON instead of Markdown')
    q.add_argument('-o', '--output', metavar='MD', help='also write Markdown + JSON here')
    q.set_defaults(func=cmd_report)

    q = dsub.add_parser('split', help='regenerate the train/validation split file '
                        '(--check: verify the committed one)')
    q.add_argument('--sources', nargs='+', metavar='PATH', help='as for build')
    q.add_argument('-o', '--output', metavar='JSON', help='split file (default: the '
                   'committed mocap_core/data/splits.json)')
    q.add_argument('--check', action='store_true', help='compare instead of writing; exit 1 '
                   'if the file does not match the data')
    q.add_argument('--fraction', type=float, default=0.10, help='validation share (0.10)')
    q.add_argument('--workers', type=int, default=2, help='processes (default 2)')
    q.set_defaults(func=cmd_split)

    q = dsub.add_parser('to-bag', help='ground-truth bag of a clip (or one bag per clip of '
                        'a split) filmed by a random virtual camera')
    q.add_argument('clip', help="clip id or name from the split file (e.g. "
                   "'dataset-1_walk_normal_001', '08_01'), a .bvh file, or 'train' / "
                   "'validation' (then -o is a folder, one bag per clip)")
    q.add_argument('-o', '--output', required=True, help='output bag (folder)')
    q.add_argument('--frames', type=int, help='at most this many frames (default: all)')
    q.add_argument('--start', type=int, default=0, help='first frame (at --fps)')
    q.add_argument('--fps', type=float, default=DEFAULT_FPS, help='frame rate (default 30)')
    q.add_argument('--seed', type=int, default=0, help='camera and corruption seed (split '
                   'target: seed + clip index)')
    q.add_argument('--distance', type=float, nargs='+', metavar='M',
                   help='horizontal camera distance, m: value or MIN MAX (default 3 8)')
    q.add_argument('--height', type=float, nargs='+', metavar='M',
                   help='camera height, m: value or MIN MAX (default 0.4 2.2)')
    q.add_argument('--azimuth', type=float, nargs='+', metavar='DEG',
                   help='camera direction from the subject\'s front, deg (default -180 180)')
    q.add_argument('--fov', type=float, nargs='+', metavar='DEG',
                   help='horizontal field of view, deg: value or MIN MAX (default 45 75)')
    q.add_argument('--image-size', metavar='WxH', help='image size (default: one of '
                   '1920x1080, 1280x720, 1080x1920, 640x480, 720x1280)')
    q.add_argument('--clean', action='store_true',
                   help='exact projections with confidence 1 (default: detector-like '
                   'corruption from the confidence model fitted on real OpenPose output)')
    q.add_argument('--no-world-motion', action='store_true',
                   help='leave out /mocap/groundtruth/world_motion (half the size; it is '
                   '/mocap/groundtruth/camera_pose composed with the camera-frame motion)')
    q.add_argument('--splits', metavar='JSON', help='split file (default: the committed one)')
    q.add_argument('--limit', type=int, help='split target: at most this many clips')
    q.add_argument('--workers', type=int, default=2, help='split target: build processes')
    q.add_argument('--no-progress', action='store_true', help='no progress bar')
    q.add_argument('--overwrite', action='store_true', help='replace an existing bag')
    q.set_defaults(func=cmd_to_bag)

    q = dsub.add_parser('from-openpose', help='keypoint bag from an OpenPose JSON folder')
    q.add_argument('directory', help='folder of <name>_<frame>_keypoints.json files')
    q.add_argument('-o', '--output', required=True, help='output bag (folder)')
    q.add_argument('--fps', type=float, default=30.0, help='frame rate (default 30)')
    q.add_argument('--fov', type=float, default=60.0,
                   help='horizontal field of view for the approximate intrinsics (default 60)')
    q.add_argument('--image-size', metavar='WxH',
                   help='image size (default: smallest standard size holding the keypoints)')
    q.add_argument('--camera-info', metavar='YAML', help='calibration (camera_info YAML) '
                   'instead of --fov')
    q.add_argument('--overwrite', action='store_true', help='replace an existing bag')
    q.set_defaults(func=cmd_from_openpose)

    q = dsub.add_parser('fit-confidence', help='fit the keypoint confidence model on '
                        'OpenPose JSON folders (most confident person per frame)')
    q.add_argument('directories', nargs='+', help='OpenPose JSON folders')
    q.add_argument('-o', '--output', required=True, help='output JSON (the shipped model is '
                   'mocap_core/data/confidence_model.json)')
    q.add_argument('--source', help='description stored in the model (default: generated)')
    q.set_defaults(func=cmd_fit_confidence)

    q = dsub.add_parser('fit-placement', help='fit where the keypoint detector puts each point '
                        'relative to the synthesizer, on rendered clips (cross-synthesizer '
                        'keypoints)')
    q.add_argument('--renders', help='rendered clips (default ~/.cache/mocap/render)')
    q.add_argument('--split', default='train', help='rendered split to fit on (default train)')
    q.add_argument('--min-clips', type=int, default=20, help='refuse fewer clips (default 20)')
    q.add_argument('-o', '--output', help='output JSON (default: the shipped '
                   'mocap_core/data/detector_placement.json)')
    q.set_defaults(func=_guard(cmd_fit_placement))

    q = dsub.add_parser('fit-stature', help='fit a person\'s stature against the skeleton\'s '
                        'rest height on rendered clips of known body height (the constants of '
                        'Skeleton.stature); checked on the validation renders')
    q.add_argument('--renders', help='rendered clips (default ~/.cache/mocap/render)')
    q.add_argument('--check', nargs='*', default=[], help='more render folders whose '
                   'validation split to check on (e.g. ~/.cache/mocap/render_travel)')
    q.add_argument('--min-clips', type=int, default=20, help='refuse fewer clips (default 20)')
    q.set_defaults(func=_guard(cmd_fit_stature))

    q = dsub.add_parser(
        'render', help='render people (Anny + pyrender) driven by motion capture, run the '
        'keypoint detector on the video, write exact ground truth (resumable cache)',
        description='Render clips of the split (validation first, then train) or user BVH '
        'files with random bodies, clothes, scenes and cameras; run BlazePose on the frames '
        'as the keypoint node does; write video, keypoints, ground truth and a bag per clip '
        'under OUT/<split>/<clip>/. Clips already done are skipped, so the command resumes.')
    q.add_argument('--split', choices=('validation', 'train', 'all', 'none'),
                   default='validation', action=_SplitAction,
                   help='clips of the committed split to render (default validation; with '
                   '--bvh and no --split, only the BVH files)')
    q.set_defaults(split_given=False)
    q.add_argument('--bvh', nargs='+', default=[], metavar='FILE',
                   help='also render these BVH files (any format the data pipeline reads)')
    q.add_argument('-o', '--out', help='output folder (default ~/.cache/mocap/render)')
    q.add_argument('--jobs', type=int, default=2, help='worker processes (default 2)')
    q.add_argument('--limit', type=int, help='at most this many clips per split')
    q.add_argument('--max-seconds', type=float, default=8.0,
                   help='longest rendered stretch of a clip, seconds (default 8)')
    q.add_argument('--seed', type=int, default=0, help='seed of bodies, scenes and cameras')
    q.add_argument('--camera', default='', help='force one camera kind (static, pan, orbit, '
                   'handheld, follow); default: drawn per clip')
    q.add_argument('--min-travel', type=float, default=0.0, metavar='M',
                   help='only clips of the split whose pelvis travels at least M metres '
                   'over a --max-seconds stretch (at the clip\'s mean speed), before '
                   '--limit: a world-frame benchmark of people who go somewhere '
                   '(e.g. --min-travel 1.5 -o ~/.cache/mocap/render_travel)')
    q.add_argument('--speed', type=float, default=1.0,
                   help='play every motion at this pace (default 1; 0.5: slow motion, as a '
                   'slow-motion video or a slow walker shows it; the ground truth is the '
                   'slowed motion). Use another -o: clips are cached by name')
    q.add_argument('--hours', type=float, help='stop starting new clips after this long')
    q.add_argument('--no-bag', action='store_true', help='skip the per-clip MCAP bag')
    q.add_argument('--plain-heads', action='store_true',
                   help='heads without hair or a face, one skin colour, as rendered before '
                   'session 42 (to compare with those renders; docs/rendering.md). Use '
                   'another -o: clips are cached by name')
    q.add_argument('--quiet', action='store_true', help='no progress bar')
    q.set_defaults(func=_guard(cmd_render))

    p.set_defaults(func=lambda a: (p.print_help(), 0)[1])
