"""``mocap eval physics`` and ``mocap train physics`` (``python -m mocap_physics.training.cli``).

    mocap eval physics [--bags B [B ...]] [--noise none|lifter|both] [--dataset-clips N]
                       [--max-frames F] [--seed S] [--out docs/benchmarks/physics_eval]
    mocap train physics [--steps N] [--run-dir runs/physics_dynet] [--device cpu|cuda]

Evaluation runs the physics cycle on ground-truth motion (the committed ``bags/gt_*`` bags in
the camera frame, and clips of the dataset's validation split in the world frame), clean and
with lifter-like noise, and writes a JSON + Markdown report
(:mod:`mocap_physics.training.evaluate`). Training fits the DyNet gains
(:mod:`mocap_physics.dynet`, :mod:`mocap_physics.training.train_dynet`) on the train split.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, List, Optional

if TYPE_CHECKING:
    from .evaluate import EvalConfig

REPO = Path(__file__).resolve().parents[4]
DEFAULT_BAGS = ('gt_cmu_walk_12_02', 'gt_bandai_walk_exhausted', 'gt_bandai_wave_normal')


def add_train_parser(sub: argparse._SubParsersAction) -> None:
    """Add ``physics`` to the subcommands of ``mocap train``."""
    p = sub.add_parser('physics', help='train the DyNet PD gains of the physics cycle')
    p.add_argument('--steps', type=int, default=None, help='optimiser steps (default: config)')
    p.add_argument('--run-dir', default='runs/physics_dynet',
                   help='checkpoints, log.csv (default runs/physics_dynet)')
    p.add_argument('--device', default='cpu', help="'cpu' or 'cuda'")
    p.add_argument('--clips', type=int, default=None, help='use only this many training clips')
    p.add_argument('--install', action='store_true',
                   help='copy the final weights to the package (weights/dynet.pt)')
    p.set_defaults(func=cmd_train)


def add_eval_parser(sub: argparse._SubParsersAction) -> None:
    """Add ``physics`` to the subcommands of ``mocap eval``."""
    p = sub.add_parser('physics', help='evaluate the physics cycle on ground-truth motion')
    p.add_argument('--bags', nargs='*', default=None,
                   help='ground-truth bags (default: the committed bags/gt_*)')
    p.add_argument('--noise', choices=('none', 'lifter', 'both'), default='both',
                   help='input: the clean ground truth, corrupted like a lifter, or both')
    p.add_argument('--dataset-clips', type=int, default=6,
                   help='also this many clips of the validation split (0: none)')
    p.add_argument('--max-frames', type=int, default=300,
                   help='frames per validation-split clip')
    p.add_argument('--seed', type=int, default=0, help='seed of the noise')
    p.add_argument('--quick', action='store_true',
                   help='only the default configuration (no ablations)')
    p.add_argument('--dynet', default=None,
                   help='also evaluate learned gains from this DyNet weights file')
    p.add_argument('--out', default=str(REPO / 'docs' / 'benchmarks' / 'physics_eval'),
                   help='report path without suffix (.json and .md are written)')
    p.set_defaults(func=cmd_eval)


def _configs(quick: bool, dynet: Optional[str]) -> List['EvalConfig']:
    from ..cycle_params import PhysicsParams
    from .evaluate import EvalConfig

    cfgs = [EvalConfig('physics, true floor', PhysicsParams(), 'gt'),
            EvalConfig('physics, est. floor', PhysicsParams(), 'estimate'),
            EvalConfig('paper (eq. 13), true floor', PhysicsParams(dynamics='paper'), 'gt')]
    if not quick:
        cfgs += [EvalConfig('whole body, ProxQP', PhysicsParams(wbid_solver='proxqp'), 'gt'),
                 EvalConfig('paper, no stick', PhysicsParams(dynamics='paper',
                                                             foot_stick=False), 'gt'),
                 EvalConfig('paper, stiff root (kp 3600, kd 120)',
                            PhysicsParams(dynamics='paper', kp_root=3600.0, kd_root=120.0),
                            'gt')]
    if dynet:
        cfgs.append(EvalConfig('paper, DyNet gains, true floor',
                               PhysicsParams(dynamics='paper', gains_mode='learned',
                                             dynet_weights=dynet), 'gt'))
    return cfgs


def cmd_eval(args: argparse.Namespace) -> int:
    from .evaluate import dataset_clip, evaluate, load_gt_bag, write_report

    bags = args.bags if args.bags is not None else [str(REPO / 'bags' / b)
                                                    for b in DEFAULT_BAGS]
    clips = []
    for b in bags:
        try:
            clips.append(load_gt_bag(b))
        except Exception as exc:  # noqa: BLE001 - report and go on with the others
            print(f'mocap eval physics: skipping {b}: {exc}', file=sys.stderr)
    val_names: List[str] = []
    if args.dataset_clips > 0:
        from mocap_core.data.dataset import load_dataset
        print('loading the validation split ...', flush=True)
        t0 = time.time()
        motions = sorted(load_dataset('validation'), key=lambda m: m.name)
        motions = [m for m in motions if m.num_frames >= 60]
        if motions:
            step = max(1, len(motions) // args.dataset_clips)
            chosen = motions[::step][:args.dataset_clips]
            clips += [dataset_clip(m, args.max_frames) for m in chosen]
            val_names = [m.name for m in chosen]
        print(f'{len(val_names)} validation clips ({time.time() - t0:.0f} s)', flush=True)
    if not clips:
        print('mocap eval physics: error: no clip to evaluate', file=sys.stderr)
        return 1
    noises = ('none', 'lifter') if args.noise == 'both' else (args.noise,)
    t0 = time.time()
    results = evaluate(clips, _configs(args.quick, args.dynet), noises, seed=args.seed)
    seconds = time.time() - t0
    command = 'mocap eval physics ' + ' '.join(sys.argv[3:]) if len(sys.argv) > 3 and \
        sys.argv[1:3] == ['eval', 'physics'] else 'mocap eval physics'
    meta = {
        'command': command,
        'clips': ', '.join(c.name for c in clips),
        'bags (camera frame)': ', '.join(Path(b).name for b in bags),
        'validation-split clips (world frame, true floor only)': ', '.join(val_names) or 'none',
        'noise': 'lifter = evaluate.NoiseModel() (per-joint rotation noise 1 deg white + 5 deg '
                 'smooth, root jitter 5 mm / 15 mm along depth + 30 mm smooth drift, noisy '
                 f'contact probabilities), seed {args.seed}',
        'eval_seconds': round(seconds, 1),
    }
    path = write_report(results, Path(args.out), 'Physics cycle on ground-truth motion', meta)
    print(f'report: {path} (+ .json)')
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    from .train_dynet import main_train
    return main_train(args)


def main(argv: Optional[List[str]] = None) -> int:
    from mocap_core.cli.mocap import run_model_cli
    return run_model_cli(sys.modules[__name__], 'python -m mocap_physics.training.cli', argv)


if __name__ == '__main__':
    sys.exit(main())
