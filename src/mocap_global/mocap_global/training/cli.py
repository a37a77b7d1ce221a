"""``mocap train gmr`` and ``mocap eval gmr`` (also ``python -m mocap_global.training.cli``).

    mocap train gmr [--config cfg.json] [--fps 30|10] [--size cpu|paper] [--steps N]
                    [--minutes M] [--run-dir runs/gmr_30fps] [--device cpu|cuda]
                    [--threads N] [--no-resume] [--init WEIGHTS] [--install]
    mocap eval gmr [--weights FILE] [--noise none|lifter|both] [--lookahead N]
                   [--tta none|mirror|reverse|both] [--out DIR] [--device cpu|cuda]
                   [--no-bags]

Training reads the train split of the processed dataset (``mocap data build``; built on
first use), evaluation the validation split (and the committed ground-truth bags for the
static-camera fusion). A weights file that cannot be used ends ``mocap eval gmr`` with one
line ``mocap eval gmr: error: ...`` and exit status 2.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import List, Optional

_PACKAGE = Path(__file__).resolve().parents[2]
#: The package's weights directory (:data:`mocap_global.weights.WEIGHTS_DIR`; repeated here,
#: like :data:`TTA_CHOICES`, to keep ``--help`` free of torch).
WEIGHTS_DIR = _PACKAGE / 'weights'
#: The committed ground-truth bags of the repository.
BAGS_DIR = _PACKAGE.parents[1] / 'bags'
#: ``--tta`` choices (:data:`mocap_global.model.TTA_MODES`).
TTA_CHOICES = ('none', 'mirror', 'reverse', 'both')


def add_train_parser(sub) -> None:
    p = sub.add_parser('gmr', help='train GMR (world-frame global motion from local poses)')
    p.add_argument('--config', help='JSON file with TrainConfig fields (model: GMRConfig, '
                   'augmentation: Augmentation)')
    p.add_argument('--fps', type=float, help='model frame rate: 30 (default, the pipeline '
                   'rate) or 10 (as in the paper)')
    p.add_argument('--size', choices=('cpu', 'paper'), default='cpu',
                   help="'cpu': 2 x 128 GRU (default, shipped); 'paper': 4 x 2048 GRU, "
                   'batch 32, lr 5e-5 (a GPU configuration)')
    p.add_argument('--steps', type=int, help='override the number of steps')
    p.add_argument('--minutes', type=float, help='fit the run into this many minutes: the '
                   'number of steps is set from the speed of the first steps')
    p.add_argument('--run-dir', help='checkpoints, log.csv, loss.png (default '
                   'runs/gmr_<fps>fps)')
    p.add_argument('--device', default='cpu', help="'cpu' or 'cuda'")
    p.add_argument('--threads', type=int, help='torch CPU threads (default 2)')
    p.add_argument('--no-resume', action='store_true', help='start over even if a checkpoint '
                   'exists')
    p.add_argument('--init', help='start from these weights (fine-tuning; same architecture)')
    p.add_argument('--install', action='store_true', help='copy the final weights, loss curve '
                   'and training record to the package (weights/gmr.pt for 30 fps)')
    p.set_defaults(func=cmd_train)


def add_eval_parser(sub) -> None:
    p = sub.add_parser('gmr', help='evaluate GMR on the validation split')
    p.add_argument('--weights', help='weights file (default: the shipped weights/gmr.pt)')
    p.add_argument('--noise', choices=('none', 'lifter', 'lifted', 'both', 'all'),
                   default='both',
                   help='input local poses: ground truth, lifter-like noisy (an assumed '
                   "noise model), the shipped lifter's output from a random camera, 'both' "
                   "(ground truth and lifter-like) or 'all' three")
    p.add_argument('--lookahead', type=int, default=15, help='look-ahead frames of the '
                   'online (node) evaluation (default 15)')
    p.add_argument('--window', type=int, default=48, help='frames per GRU pass of the online '
                   'evaluation (default 48, the node\'s default)')
    p.add_argument('--max-clips', type=int, help='evaluate on the first N clips only')
    p.add_argument('--tta', choices=TTA_CHOICES, default='none', help='test-time '
                   'augmentation: average the motion read off the mirrored and/or '
                   'time-reversed input (2 or 4 times the compute; default none)')
    p.add_argument('--out', help='report directory (default: next to the weights)')
    p.add_argument('--device', default='cpu')
    p.add_argument('--threads', type=int, default=1, help='torch CPU threads (default 1)')
    p.add_argument('--no-bags', action='store_true', help='skip the static-camera fusion '
                   'evaluation on the committed bags')
    p.set_defaults(func=cmd_eval)


def cmd_train(args: argparse.Namespace) -> int:
    from mocap_core.data.dataset import load_dataset

    from .train import TrainConfig, train

    cfg = TrainConfig.paper() if args.size == 'paper' else TrainConfig()
    if args.config:
        cfg = TrainConfig.from_dict(json.loads(Path(args.config).read_text()))
    if args.fps:
        cfg.model.fps = float(args.fps)
    if args.steps:
        cfg.steps = args.steps
    if args.threads:
        cfg.threads = args.threads
    fps = int(round(cfg.model.fps))
    run_dir = Path(args.run_dir or f'runs/gmr_{fps}fps')
    print('loading the dataset (train and validation splits) ...', flush=True)
    t0 = time.time()
    train_motions = load_dataset('train')
    val_motions = load_dataset('validation')
    print(f'{len(train_motions)} training clips, {len(val_motions)} validation clips '
          f'({time.time() - t0:.0f} s)', flush=True)
    weights = train(train_motions, val_motions, run_dir, cfg, device=args.device,
                    resume=not args.no_resume, minutes=args.minutes,
                    init=Path(args.init) if args.init else None)
    print(f'weights: {weights}')
    if args.install:
        dest = install(run_dir, cfg, ' '.join(['mocap', 'train', 'gmr'] + sys.argv[3:]))
        print(f'installed {dest}')
    return 0


def install(run_dir: Path, cfg, command: str) -> Path:
    """Copy a finished run's weights (``run_dir/gmr.pt``), loss curve and log into the package
    (``weights/gmr.pt`` for 30 fps, ``gmr_<fps>fps.pt`` otherwise) with a training record
    (``<stem>_train.json``: configuration, command, steps, time, validation figures)."""
    from ..weights import read_info, weights_name

    weights = Path(run_dir) / 'gmr.pt'
    WEIGHTS_DIR.mkdir(exist_ok=True)
    name = weights_name(cfg.model.fps)
    dest = WEIGHTS_DIR / name
    shutil.copy(weights, dest)
    stem = Path(name).stem
    shutil.copy(Path(run_dir) / 'loss.png', WEIGHTS_DIR / f'{stem}_loss.png')
    shutil.copy(Path(run_dir) / 'log.csv', WEIGHTS_DIR / f'{stem}_log.csv')
    info = read_info(weights)
    (WEIGHTS_DIR / f'{stem}_train.json').write_text(json.dumps(
        {'config': asdict(cfg), 'command': command, 'steps': info.get('steps'),
         'train_seconds': info.get('train_seconds'),
         'validation_windows': info.get('validation_windows')}, indent=1))
    return dest


def cmd_eval(args: argparse.Namespace) -> int:
    import torch

    from mocap_core.checkpoint import WeightsError
    from mocap_core.data.dataset import load_dataset

    from ..model import with_tta
    from ..weights import load_weights
    from .evaluate import evaluate_all, write_report

    torch.set_num_threads(args.threads)
    weights = Path(args.weights) if args.weights else WEIGHTS_DIR / 'gmr.pt'
    if not weights.exists():
        print(f'mocap eval gmr: error: weights not found: {weights} (train them with '
              '`mocap train gmr --install`)', file=sys.stderr)
        return 1
    try:
        model = with_tta(load_weights(weights, args.device), args.tta)
    except WeightsError as exc:
        print(f'mocap eval gmr: error: {exc}', file=sys.stderr)
        return 2
    val = load_dataset('validation')
    if args.max_clips:
        val = val[:args.max_clips]
    noises = {'both': ('none', 'lifter'), 'all': ('none', 'lifter', 'lifted')}.get(
        args.noise, (args.noise,))
    t0 = time.time()
    bags = None if args.no_bags else sorted(BAGS_DIR.glob('gt_*'))
    report = evaluate_all(model, val, noises, args.lookahead, args.device, bags=bags,
                          progress=True, window=args.window)
    report['eval_seconds'] = round(time.time() - t0, 1)
    report['weights'] = str(weights)
    report['tta'] = args.tta
    tta = '' if args.tta == 'none' else f'_tta_{args.tta}'
    out = Path(args.out) if args.out else weights.parent / f'{weights.stem}{tta}_eval'
    title = f'GMR ({weights.name}' + (f', test-time augmentation {args.tta}'
                                      if args.tta != 'none' else '') + ') on the validation split'
    path = write_report(report, out, title)
    print(path.read_text())
    print(f'report: {path} (and eval.json)')
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    from mocap_core.cli.mocap import run_model_cli
    return run_model_cli(sys.modules[__name__], 'python -m mocap_global.training.cli',
                         argv)


if __name__ == '__main__':
    sys.exit(main())
