"""``mocap train facing`` and ``mocap eval facing`` (also
``python -m mocap_keypoints.training.cli``).

    mocap train facing [--renders DIR] [--step 3] [--steps N] [--run-dir DIR] [--install]
    mocap eval facing [--weights FILE] [--renders DIR [DIR ...]] [--out DIR]

Training cuts person crops out of the rendered training clips (``mocap data render --split
train``; cached as ``<run-dir>/crops_train.npz``, remade when missing) and scores the
rendered validation clips while it trains; evaluation runs the label check over the
validation clips of one or more render folders and writes ``report.json`` and ``report.md``
(:mod:`mocap_keypoints.training.facing`).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import List, Optional

WEIGHTS_DIR = Path(__file__).resolve().parents[2] / 'weights'
CACHE = Path('~/.cache/mocap').expanduser()
DEFAULT_EVAL_RENDERS = ('~/.cache/mocap/render', '~/.cache/mocap/render_travel')
REPO = Path(__file__).resolve().parents[4]
#: Real videos of the default evaluation: path, what the person does (``away``: seen from
#: behind throughout; ``mixed``: facing the camera mostly, turning).
DEFAULT_VIDEOS = (
    (REPO.parent / 'shared/data/videos/glamr/pexels-walking-dynamic-5738706.mp4', 'away'),
    (REPO / 'data/video_example/taiji_640x360.mp4', 'mixed'),
)


def add_train_parser(sub) -> None:
    p = sub.add_parser('facing', help='train the facing classifier of the keypoint node\'s '
                       'left/right label check on rendered people')
    p.add_argument('--renders', default=str(CACHE / 'render'),
                   help='rendered clips (their train and validation splits; default '
                   '~/.cache/mocap/render)')
    p.add_argument('--step', type=int, default=3, help='every STEP-th frame of a training '
                   'clip (default 3)')
    p.add_argument('--steps', type=int, help='optimiser steps (default 4000)')
    p.add_argument('--run-dir', default=str(CACHE / 'runs' / 'facing'),
                   help='crops cache, log.csv, weights (default ~/.cache/mocap/runs/facing)')
    p.add_argument('--rebuild', action='store_true', help='cut the crops again')
    p.add_argument('--install', action='store_true',
                   help='also write the weights to the package (weights/facing.pt)')
    p.add_argument('--quiet', action='store_true', help='no progress bars')
    p.set_defaults(func=cmd_train)


def add_eval_parser(sub) -> None:
    p = sub.add_parser('facing', help='the keypoint node\'s left/right label check on '
                       'rendered validation clips: accuracy and the detector\'s leg swaps '
                       'before and after')
    p.add_argument('--weights', help='weights (default: the shipped weights/facing.pt)')
    p.add_argument('--renders', nargs='+', default=list(DEFAULT_EVAL_RENDERS),
                   help='render folders whose validation split is scored, each on its own '
                   '(default ~/.cache/mocap/render ~/.cache/mocap/render_travel)')
    p.add_argument('--split', default='validation', help='split (default validation)')
    p.add_argument('--limit', type=int, help='only the first N clips of each folder')
    p.add_argument('--window', type=int, help='frames in the median (default 9)')
    p.add_argument('--min-width', type=float, help='detector labels\' facing width (default '
                   '0.25 torso lengths)')
    p.add_argument('--max-probability', type=float, help='network median below which the '
                   'person faces away (default 0.02)')
    p.add_argument('--videos', nargs='*', default=None, metavar='VIDEO[=away|facing]',
                   help='real videos (no ground truth) the detector and the check run over; '
                   '=away marks a video whose person is seen from behind throughout, so '
                   'labels facing the camera are mirrored there (default: the shared walking-'
                   'away clip and the taiji clip, when present)')
    p.add_argument('--out', default='docs/benchmarks/facing', help='report folder')
    p.add_argument('--quiet', action='store_true', help='no progress bars')
    p.set_defaults(func=cmd_eval)


def _clips(root: Path, split: str, limit: Optional[int] = None) -> List[Path]:
    from mocap_core.render.clip import iter_done

    clips = sorted(iter_done(root, split))
    return clips[:limit] if limit is not None else clips


def cmd_train(args: argparse.Namespace) -> int:
    from ..facing import CROP_SIZE
    from .facing import TrainConfig, build_dataset, clip_crops, dataset_matches, save, train

    renders = Path(args.renders).expanduser()
    run_dir = Path(args.run_dir).expanduser()
    train_clips = _clips(renders, 'train')
    val_clips = _clips(renders, 'validation')
    if not train_clips:
        print(f'mocap train facing: no rendered training clips in {renders}/train '
              '(make them with: mocap data render --split train)', file=sys.stderr)
        return 1
    data = run_dir / 'crops_train.npz'
    if args.rebuild or not dataset_matches(data, train_clips, args.step):
        counts = build_dataset(train_clips, data, step=args.step, progress=not args.quiet)
        print(f"facing: {counts['crops']} crops from {counts['clips']} training clips -> {data}")
    val = None
    if val_clips:
        import numpy as np

        cut = [clip_crops(d, step=3) for d in val_clips]
        val = (np.concatenate([c.crops for c in cut]), np.concatenate([c.toward for c in cut]))
    if args.steps is not None and args.steps < 1:
        print('mocap train facing: --steps must be at least 1', file=sys.stderr)
        return 2
    config = TrainConfig(**({'steps': args.steps} if args.steps is not None else {}))
    t0 = time.time()
    net = train(data, run_dir, config, val=val, progress=not args.quiet)
    info = {'train_clips': len(train_clips), 'renders': str(renders),
            'crop_size': list(CROP_SIZE), 'seconds': round(time.time() - t0, 1),
            'command': f'mocap train facing --renders {renders} --step {args.step} '
                       f'--steps {config.steps}'}
    import csv
    with open(run_dir / 'log.csv') as fh:
        rows = list(csv.DictReader(fh))
    info['last'] = {k: float(v) for k, v in rows[-1].items()}
    out = run_dir / 'facing.pt'
    save(net, out, config, info)
    print(f'wrote {out}')
    if args.install:
        WEIGHTS_DIR.mkdir(parents=True, exist_ok=True)
        save(net, WEIGHTS_DIR / 'facing.pt', config, info)
        print(f"wrote {WEIGHTS_DIR / 'facing.pt'}")
    return 0


def _report_md(reports: dict, weights: str, videos: dict) -> str:
    lines = ['# Facing classifier: the left/right label check on rendered clips', '',
             f'Weights: `{weights}`. The detector\'s keypoints of each rendered validation '
             'clip (BlazePose, when the clip was rendered), checked frame by frame as the '
             'keypoint node checks them (`keypoints.facing_check`); legs scored with '
             '`detector_swaps` (knees and ankles mirrored against the true joints).', '',
             '| renders | clips | network right: front / back | leg swaps before: front / '
             'side / back / all | after | frames fixed / broken |',
             '|---|---|---|---|---|---|']
    for name, r in reports.items():
        a, b, c = r['accuracy'], r['swaps_before'], r['swaps_after']
        lines.append(
            f"| {name} | {r['clips']} | {100 * a['front']:.1f} / {100 * a['back']:.1f} % | "
            f"{b['front']:.2f} / {b['side']:.2f} / {b['back']:.2f} / **{b['all']:.2f} %** | "
            f"{c['front']:.2f} / {c['side']:.2f} / {c['back']:.2f} / **{c['all']:.2f} %** | "
            f"{r['fixed_frames']} / {r['broken_frames']} |")
    if videos:
        lines += ['', '**Real videos** (no ground truth; the detector run here, one person): '
                  'frames whose labels face the camera or turn away by more than the check\'s '
                  'width, the network\'s mean probability of facing the camera, frames the '
                  'check exchanged. For a person seen from behind throughout (`away`), every '
                  'frame labelled as facing the camera is mirrored.', '',
                  '| video | person | frames scored | labels facing / away | network: facing '
                  '(mean p) | exchanged |', '|---|---|---|---|---|---|']
        for name, v in videos.items():
            lines.append(f"| `{name}` | {v['kind']} | {v['scored']} of {v['frames']} | "
                         f"{v['labels_facing']} / {v['labels_away']} | {v['network_facing']} "
                         f"({v['mean_probability']:.2f}) | {v['exchanged']} |")
    p = next(iter(reports.values()))['params']
    lines += ['', f"Check: labels facing the camera by more than {p['min_width']} torso "
              f"lengths and the network's median over {p['window']} frames below "
              f"{p['max_probability']}. Reproduce: `mocap eval facing`.", '']
    return '\n'.join(lines)


def cmd_eval(args: argparse.Namespace) -> int:
    from ..facing import FacingCheckParams, FacingClassifier
    import numpy as np

    from .facing import evaluate_clips, video_check

    clf = FacingClassifier(args.weights)
    params = FacingCheckParams()
    for field, value in (('window', args.window), ('min_width', args.min_width),
                         ('max_probability', args.max_probability)):
        if value is not None:
            setattr(params, field, value)
    reports = {}
    for root in args.renders:
        root = Path(root).expanduser()
        clips = _clips(root, args.split, args.limit)
        if not clips:
            print(f'mocap eval facing: no rendered clips in {root}/{args.split}: skipped '
                  '(mocap data render makes them)', file=sys.stderr)
            continue
        r = evaluate_clips(clips, clf, params, progress=not args.quiet)
        reports[f'{root.name}/{args.split}'] = r
        print(f"{root.name}: {r['clips']} clips, network right front "
              f"{100 * r['accuracy']['front']:.1f} % back {100 * r['accuracy']['back']:.1f} %; "
              f"leg swaps {r['swaps_before']['all']:.2f} -> {r['swaps_after']['all']:.2f} % "
              f"(back views {r['swaps_before']['back']:.2f} -> "
              f"{r['swaps_after']['back']:.2f} %)")
    if not reports:
        print('mocap eval facing: no rendered clips in any of the folders', file=sys.stderr)
        return 1
    videos = {}
    wanted = ([(Path(v), k) for v, k in DEFAULT_VIDEOS if Path(v).exists()]
              if args.videos is None else
              [(Path(v.rsplit('=', 1)[0]), v.rsplit('=', 1)[1] if '=' in v else 'unknown')
               for v in args.videos])
    for path, kind in wanted:
        v = video_check(path, clf, params)
        v['kind'] = kind
        videos[path.name] = v
        print(f"{path.name} ({kind}): {v['scored']} frames scored, labels facing the camera "
              f"in {v['labels_facing']}, away in {v['labels_away']}; network facing in "
              f"{v['network_facing']}; exchanged {v['exchanged']}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    plain = {name: {k: v for k, v in r.items() if not isinstance(v, np.ndarray)}
             for name, r in videos.items()}
    weights = (str(clf.path.relative_to(REPO)) if clf.path.is_relative_to(REPO)
               else str(clf.path))
    (out / 'report.json').write_text(json.dumps({'weights': weights, 'info': clf.info,
                                                 'reports': reports, 'videos': plain},
                                                indent=1))
    (out / 'report.md').write_text(_report_md(reports, clf.path.name, plain))
    if videos:
        _plot_videos(videos, out / 'videos.png')
    print(f"wrote {out / 'report.md'}")
    return 0


def _plot_videos(videos: dict, path: Path) -> None:
    """Per real video: the detector labels' facing width and the network's probability over
    the frames, exchanged frames marked."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    import numpy as np

    fig, axes = plt.subplots(len(videos), 1, figsize=(9, 2.6 * len(videos)), squeeze=False)
    for ax, (name, v) in zip(axes[:, 0], videos.items()):
        f = np.arange(len(v['width']))
        ax.plot(f, np.clip(v['width'], -2, 2), lw=1, label='labels\' facing width (torso '
                'lengths, clipped to +-2)')
        ax.plot(f, v['prob'], lw=1, label='network: P(facing the camera)')
        ex = v['exchanged_frames']
        ax.scatter(f[ex], np.zeros(int(ex.sum())), s=6, c='red', label='exchanged')
        ax.axhline(0, c='grey', lw=0.5)
        ax.set_title(f"{name} ({v['kind']})", fontsize=9)
        ax.set_xlabel('frame')
    axes[0, 0].legend(fontsize=7, loc='upper right')
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: Optional[List[str]] = None) -> int:
    from mocap_core.cli.mocap import run_model_cli

    return run_model_cli(sys.modules[__name__], 'python -m mocap_keypoints.training.cli', argv)


if __name__ == '__main__':
    sys.exit(main())
