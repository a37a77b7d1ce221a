"""``mocap train lifter`` and ``mocap eval lifter`` (also ``python -m mocap_lifter.training.cli``).

    mocap train lifter [--config cfg.json] [--mode windowed|causal] [--steps N]
                       [--run-dir runs/lifter_windowed] [--device cpu|cuda] [--no-resume]
    mocap train vtm [--stage tpmae|tpve|both] [--steps N [N]] [--run-dir runs/vtm] [--install]
    mocap eval lifter [--model motionet|vtm] [--weights FILE] [--noise none|motionet|both]
                      [--out DIR]

Training reads the train split of the processed dataset (``mocap data build``; built on
first use), evaluation the validation split.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import List, Optional

WEIGHTS_DIR = Path(__file__).resolve().parents[2] / 'weights'


def add_train_parser(sub) -> None:
    p = sub.add_parser('lifter', help='train the MotioNet lifter')
    p.add_argument('--config', help='JSON file with TrainConfig fields (model: LifterConfig)')
    p.add_argument('--mode', choices=('windowed', 'causal'), default='windowed',
                   help='centred window (default) or causal convolutions')
    p.add_argument('--steps', type=int, help='override the number of steps')
    p.add_argument('--run-dir', help='checkpoints, log.csv, loss.png (default runs/lifter_<mode>)')
    p.add_argument('--device', default='cpu', help="'cpu' or 'cuda'")
    p.add_argument('--threads', type=int, help='torch CPU threads (default 2; 1 is faster on '
                   'a machine busy with other work)')
    p.add_argument('--no-resume', action='store_true', help='start over even if a checkpoint '
                   'exists')
    p.add_argument('--init', help='start from these weights (fine-tuning; same network '
                   'configuration) instead of a random initialisation')
    p.add_argument('--clean-fraction', type=float, help='share of training windows with clean '
                   'keypoints (confidence 1, no displacement); default 0.25')
    p.add_argument('--split', choices=('committed', 'strict'),
                   help='training clips: the committed split (default) or the strict one '
                   '(whole motion families held out; mocap_core.data.strict_split)')
    p.add_argument('--placement-fraction', type=float,
                   help='share of projected windows with detector-placed keypoints')
    p.add_argument('--rendered-fraction', type=float,
                   help='share of windows from rendered clips (mocap data render)')
    p.add_argument('--renders', help='rendered clips folder (default ~/.cache/mocap/render)')
    p.add_argument('--cameras', choices=('default', 'wide', 'steep'),
                   help='projected-keypoint camera ranges (wide: those of the renders; steep: '
                   'wide, a quarter of the cameras looking down from 25-65 degrees)')
    p.add_argument('--install', action='store_true', help='copy the final weights to the '
                   'package (weights/motionet_<mode>.pt)')
    p.set_defaults(func=cmd_train)
    _add_vtm_train_parser(sub)


def _add_vtm_train_parser(sub) -> None:
    p = sub.add_parser('vtm', help='train the VTM lifter (two stages: TPMAE, then TPVE)')
    p.add_argument('--stage', choices=('tpmae', 'tpve', 'both'), default='both',
                   help='stage 1 (motion auto-encoder), stage 2 (visual encoder, joint '
                   'training from the stage-1 weights) or both in turn (default)')
    p.add_argument('--config', help='JSON file with VTMTrainConfig fields applied to both '
                   'stages (model: VTMConfig)')
    p.add_argument('--steps', type=int, nargs='+', metavar='N',
                   help='steps of the stage(s): one value, or two for --stage both '
                   '(default 4000 and 5000)')
    p.add_argument('--run-dir', default='runs/vtm', help='stage directories <run-dir>/tpmae, '
                   '<run-dir>/tpve: checkpoints, log.csv, loss.png')
    p.add_argument('--init', help='stage tpve: the stage-1 weights (default '
                   '<run-dir>/tpmae/vtm_tpmae.pt)')
    p.add_argument('--device', default='cpu', help="'cpu' or 'cuda'")
    p.add_argument('--threads', type=int, help='torch CPU threads (default 1)')
    p.add_argument('--no-resume', action='store_true', help='start over even if a checkpoint '
                   'exists')
    p.add_argument('--install', action='store_true', help='copy the final weights to the '
                   'package (weights/vtm_windowed.pt, with the logs)')
    p.set_defaults(func=cmd_train_vtm)


def cmd_train_vtm(args: argparse.Namespace) -> int:
    import shutil

    from mocap_core.checkpoint import WeightsError
    from mocap_core.data.dataset import load_dataset

    from .vtm_train import VTMTrainConfig, train_stage

    stages = ('tpmae', 'tpve') if args.stage == 'both' else (args.stage,)
    steps = {'tpmae': 4000, 'tpve': 5000}
    if args.steps:
        if len(args.steps) != len(stages):
            print(f'mocap train vtm: error: --steps needs {len(stages)} value(s)',
                  file=sys.stderr)
            return 2
        steps.update(zip(stages, args.steps))
    base = json.loads(Path(args.config).read_text()) if args.config else {}
    run_dir = Path(args.run_dir)
    print('loading the dataset (train and validation splits) ...', flush=True)
    train_motions = load_dataset('train')
    val_motions = load_dataset('validation')
    print(f'{len(train_motions)} training clips, {len(val_motions)} validation clips',
          flush=True)
    weights = None
    for stage in stages:
        cfg = VTMTrainConfig.from_dict({**base, 'stage': stage})
        cfg.steps = steps[stage]
        if args.threads:
            cfg.threads = args.threads
        if stage == 'tpve':
            init = Path(args.init) if args.init else run_dir / 'tpmae' / 'vtm_tpmae.pt'
            if not init.exists():
                print(f'mocap train vtm: error: stage-1 weights not found: {init} (run '
                      '--stage tpmae first)', file=sys.stderr)
                return 1
            cfg.init = str(init.resolve())
        try:
            weights = train_stage(train_motions, val_motions, run_dir / stage, cfg,
                                  device=args.device, resume=not args.no_resume)
        except WeightsError as exc:   # a damaged checkpoint or --init file
            print(f'mocap train vtm: error: {exc}', file=sys.stderr)
            return 2
        print(f'{stage} weights: {weights}', flush=True)
    if args.install and weights is not None:
        WEIGHTS_DIR.mkdir(exist_ok=True)
        shutil.copy(weights, WEIGHTS_DIR / 'vtm_windowed.pt')
        for stage in stages:
            shutil.copy(run_dir / stage / 'log.csv', WEIGHTS_DIR / f'vtm_{stage}_log.csv')
            shutil.copy(run_dir / stage / 'loss.png', WEIGHTS_DIR / f'vtm_{stage}_loss.png')
        print(f"installed {WEIGHTS_DIR / 'vtm_windowed.pt'}")
    return 0


def add_eval_parser(sub) -> None:
    from ..signatures_cli import add_signatures_parser
    add_signatures_parser(sub)      # mocap eval signatures: bone lengths as a signature
    from .drops import add_parser as add_drops_parser
    add_drops_parser(sub)           # mocap eval drops: keypoint frames missing
    p = sub.add_parser('lifter', help='evaluate the lifter on the validation split')
    p.add_argument('--model', choices=('motionet', 'vtm'), default='motionet',
                   help='which shipped lifter to evaluate (default motionet); VTM adds its '
                   'motion auto-encoder alone (the paper\'s Table 2 row)')
    p.add_argument('--weights', help='weights file (default: what the node loads for --model and '
                   '--mode, mocap_lifter.weights.default_weights)')
    p.add_argument('--vtm-root', choices=('decoder', 'reprojection'),
                   help="VTM: where the root comes from (default: the weights' setting): the "
                   "root decoder's depth (the paper) or the reprojection fit of the lifted "
                   'joints to the keypoints')
    p.add_argument('--mode', choices=('windowed', 'causal'), default='windowed')
    p.add_argument('--noise', choices=('none', 'motionet', 'both'), default='both')
    p.add_argument('--split', choices=('validation', 'strict'), default='validation',
                   help='validation: the committed split; strict: held-out subjects and whole '
                   'motion families (mocap_core.data.strict_split)')
    p.add_argument('--placement', choices=('joints', 'detector', 'both'), default='joints',
                   help='keypoints on the joints (the training synthesizer) or where the real '
                   'detector puts them (cross-synthesizer check, '
                   'mocap_core/data/detector_placement.json)')
    p.add_argument('--flip', action='store_true',
                   help='test-time flip augmentation (mirrored input lifted too, averaged)')
    p.add_argument('--smooth', type=float, default=0.0, metavar='SIGMA',
                   help='Gaussian smoothing of the keypoints along time before lifting '
                   '(frames; the node parameter smooth_sigma)')
    p.add_argument('--output-sigma', type=float, default=0.0, metavar='SIGMA',
                   help='Gaussian smoothing of the lifted output along time (frames; the node '
                   'parameter output_sigma, 1.5 in windowed mode by default; applied here to the '
                   'positions, and to the root unless --output-root-sigma is given)')
    p.add_argument('--output-root-sigma', type=float, default=None, metavar='SIGMA',
                   help='Gaussian smoothing of the lifted root along time (frames; the node '
                   'parameter output_root_sigma, 3 in windowed mode by default; default: '
                   '--output-sigma)')
    p.add_argument('--virtual-camera', action='store_true',
                   help='lift as a camera turned to look at the person sees them and turn '
                   'the pose back (the node parameter virtual_camera, on by default there; '
                   'weights trained in the virtual camera use it always)')
    p.add_argument('--rendered', nargs='?', const='', default=None, metavar='DIR',
                   help='also lift the rendered validation clips (mocap data render; default '
                   'folder ~/.cache/mocap/render) from the detector, from clean projections '
                   'of the same frames and from detector-placed projections')
    p.add_argument('--out', help='report directory (default: next to the weights)')
    p.add_argument('--device', default='cpu')
    p.add_argument('--real', nargs='*', default=None, metavar='DIR',
                   help='OpenPose JSON folders lifted without ground truth (jitter, skating); '
                   'default: the sequences of ../shared/data/keypoints_real/motionet_openpose '
                   'if present, else data/openpose_example/seq1')
    p.set_defaults(func=cmd_eval)


def split_motions(split: str):
    """``(train motions, validation motions, validation families or None)`` of the committed
    split (``'committed'`` / ``'validation'``) or the strict one (``'strict'``)."""
    if split == 'strict':
        from mocap_core.data.strict_split import load_strict
        train, _ = load_strict('strict_train')
        val, families = load_strict('strict_validation')
        return train, val, families
    from mocap_core.data.dataset import load_dataset
    return load_dataset('train'), load_dataset('validation'), None


def cmd_train(args: argparse.Namespace) -> int:
    import shutil

    from mocap_core.checkpoint import WeightsError

    from .train import TrainConfig, train

    cfg = TrainConfig()
    if args.config:
        cfg = TrainConfig.from_dict(json.loads(Path(args.config).read_text()))
    cfg.model.causal = args.mode == 'causal'
    if args.steps:
        cfg.steps = args.steps
    if args.threads:
        cfg.threads = args.threads
    if args.init:
        cfg.init = str(Path(args.init).resolve())
    if args.clean_fraction is not None:
        cfg.clean_fraction = args.clean_fraction
    for name in ('split', 'placement_fraction', 'rendered_fraction', 'renders', 'cameras'):
        if getattr(args, name) is not None:
            setattr(cfg, name, getattr(args, name))
    run_dir = Path(args.run_dir or f'runs/lifter_{args.mode}')
    print(f'loading the dataset ({cfg.split} train and validation splits) ...', flush=True)
    t0 = time.time()
    train_motions, val_motions, _ = split_motions(cfg.split)
    print(f'{len(train_motions)} training clips, {len(val_motions)} validation clips '
          f'({time.time() - t0:.0f} s)', flush=True)
    try:
        weights = train(train_motions, val_motions, run_dir, cfg, device=args.device,
                        resume=not args.no_resume)
    except WeightsError as exc:   # a damaged checkpoint or --init file
        print(f'mocap train lifter: error: {exc}', file=sys.stderr)
        return 2
    print(f'weights: {weights}')
    if args.install:
        WEIGHTS_DIR.mkdir(exist_ok=True)
        dest = WEIGHTS_DIR / f'motionet_{args.mode}.pt'
        shutil.copy(weights, dest)
        shutil.copy(run_dir / 'loss.png', WEIGHTS_DIR / f'motionet_{args.mode}_loss.png')
        (WEIGHTS_DIR / f'motionet_{args.mode}_train.json').write_text(json.dumps(
            {'config': asdict(cfg), 'command': ' '.join(['mocap', 'train', 'lifter'] +
                                                       sys.argv[3:])}, indent=1))
        print(f'installed {dest}')
    return 0


def default_real_sequences() -> List[str]:
    """The real OpenPose sequences of the shared data, or the committed example."""
    repo = Path(__file__).resolve().parents[4]
    shared = repo.parent / 'shared' / 'data' / 'keypoints_real' / 'motionet_openpose'
    if shared.is_dir():
        return [str(d) for d in sorted(shared.iterdir()) if d.is_dir()]
    example = repo / 'data' / 'openpose_example' / 'seq1'
    return [str(example)] if example.is_dir() else []


def eval_weights(model: str, mode: str, given: Optional[str]) -> Path:
    """The weights ``mocap eval lifter`` scores: ``given``, else what the node loads for
    ``model`` and ``mode`` (:func:`mocap_lifter.weights.default_weights`; for the windowed
    MotioNet that is not ``motionet_windowed.pt``, an older stage)."""
    from ..weights import default_weights
    return Path(given) if given else default_weights(mode, model)


def cmd_eval(args: argparse.Namespace) -> int:
    from mocap_core.checkpoint import WeightsError

    from ..weights import architecture, load_weights
    from .evaluate import (baseline_mean_pose, evaluate, evaluate_real,
                           groundtruth_plausibility, write_report)

    if args.model == 'vtm' and args.mode == 'causal':
        print('mocap eval lifter: error: VTM is windowed only', file=sys.stderr)
        return 2
    weights = eval_weights(args.model, args.mode, args.weights)
    if not weights.exists():
        print(f'mocap eval lifter: error: weights not found: {weights}', file=sys.stderr)
        return 1
    try:
        model = load_weights(weights, args.device)
    except WeightsError as exc:
        print(f'mocap eval lifter: error: {exc}', file=sys.stderr)
        return 2
    is_vtm = architecture(model) == 'vtm'
    if is_vtm and args.vtm_root:
        model.cfg.root_from = args.vtm_root
    if is_vtm != (args.model == 'vtm'):
        print(f"mocap eval lifter: error: {weights} holds {'VTM' if is_vtm else 'MotioNet'} "
              f'weights but --model {args.model}', file=sys.stderr)
        return 2
    train_for_baseline, val, families = split_motions(args.split)
    placements = {'joints': [None], 'detector': ['detector'],
                  'both': [None, 'detector']}[args.placement]
    if 'detector' in placements:
        from mocap_core.data.detector_placement import PLACEMENT_PATH, DetectorPlacement
        try:
            placed = DetectorPlacement.load(PLACEMENT_PATH)
        except (OSError, ValueError) as exc:
            print(f'mocap eval lifter: error: no detector placement ({exc}); make it with '
                  '`mocap data fit-placement`', file=sys.stderr)
            return 2
        placements = [placed if p else None for p in placements]
    noises = ('none', 'motionet') if args.noise == 'both' else (args.noise,)
    t0 = time.time()
    results = [evaluate(model, val, n, args.device, placement=pl, families=families,
                        flip=args.flip, smooth=args.smooth, output_sigma=args.output_sigma,
                        output_root_sigma=args.output_root_sigma,
                        virtual_camera=args.virtual_camera)
               for pl in placements for n in noises]
    seconds = time.time() - t0
    baseline = {n: baseline_mean_pose(train_for_baseline, val, n) for n in noises}
    suffix = '' if args.split == 'validation' else f'_{args.split}'
    out = Path(args.out) if args.out else weights.parent / f'{weights.stem}_eval{suffix}'
    real_dirs = args.real if args.real is not None else default_real_sequences()
    real = None
    if real_dirs:
        real = evaluate_real(model, [Path(d) for d in real_dirs], device=args.device,
                             flip=args.flip, smooth=args.smooth,
                             output_sigma=args.output_sigma,
                             output_root_sigma=args.output_root_sigma,
                             virtual_camera=args.virtual_camera)
        real['groundtruth'] = groundtruth_plausibility(val)
        s = real['summary']
        print(f"real OpenPose ({real['sequences']} sequences, {real['frames']} frames): jitter "
              f"{s['jitter_mm_s2'] / 1000:.2f} m/s^2 (ground truth "
              f"{real['groundtruth']['jitter_mm_s2'] / 1000:.2f}), skating "
              f"{s['skating_mm']:.1f} mm/frame (ground truth "
              f"{real['groundtruth']['skating_mm']:.1f})")
    extra = {'baseline_mean_pose': baseline, 'weights': str(weights),
             'eval_seconds': round(seconds, 1), 'flip': args.flip, 'smooth': args.smooth,
             'virtual_camera': args.virtual_camera,
             'output_sigma': args.output_sigma, 'output_root_sigma': args.output_root_sigma}
    if args.rendered is not None:
        from mocap_core.render.batch import DEFAULT_OUT
        from mocap_core.render.clip import iter_done

        from .evaluate import evaluate_rendered
        root = Path(args.rendered) if args.rendered else DEFAULT_OUT
        dirs = list(iter_done(root, 'validation'))
        if not dirs:
            print(f'mocap eval lifter: error: no rendered validation clip under {root}',
                  file=sys.stderr)
            return 2
        placed = None
        try:
            from mocap_core.data.detector_placement import PLACEMENT_PATH, DetectorPlacement
            placed = DetectorPlacement.load(PLACEMENT_PATH)
        except (OSError, ValueError):
            pass
        rendered = {}
        for inputs in ('detector', 'projected') + (('placed',) if placed else ()):
            r = evaluate_rendered(model, dirs, inputs, args.device, flip=args.flip,
                                  smooth=args.smooth, placement=placed,
                                  output_sigma=args.output_sigma,
                                  output_root_sigma=args.output_root_sigma,
                                  virtual_camera=args.virtual_camera)
            rendered[inputs] = {k: r[k] for k in ('clips', 'frames', 'summary')}
            s = r['summary']
            print(f"rendered ({inputs:9s}, {r['clips']} clips): MPJPE {s['mpjpe_mm']:.1f} mm "
                  f"(median {s['median_mpjpe_mm']:.1f})  PA-MPJPE {s['pa_mpjpe_mm']:.1f} mm "
                  f"(median {s['median_pa_mpjpe_mm']:.1f})  MRPE {s['mrpe_mm']:.0f} mm  "
                  f"MBLE {s['mble_mm']:.1f} mm")
        extra['rendered_lifter_only'] = rendered
    if is_vtm:
        from .evaluate import evaluate_tpmae
        extra['tpmae'] = evaluate_tpmae(model, val, args.device)['summary']
        extra['root_from'] = model.cfg.root_from
        t = extra['tpmae']
        print(f"TPMAE alone (true motion encoded and decoded): MPJPE {t['mpjpe_mm']:.1f} mm  "
              f"PA-MPJPE {t['pa_mpjpe_mm']:.1f} mm  MRPE {t['mrpe_mm']:.1f} mm")
    name = 'VTM' if is_vtm else 'MotioNet'
    split_name = 'the validation split' if args.split == 'validation' else \
        'the strict split (held-out subjects and whole motion families)'
    path = write_report(results, out, f'{name} lifter ({weights.name}) on {split_name}', extra,
                        real=real)
    for r in results:
        s = r['summary']
        print(f"{r['noise']:9s} {r['placement']:8s} MPJPE {s['mpjpe_mm']:.1f} mm  "
              f"PA-MPJPE {s['pa_mpjpe_mm']:.1f} mm  MRPE {s['mrpe_mm']:.1f} mm  "
              f"MBLE {s['mble_mm']:.1f} mm  contacts "
              f"{s['contact_accuracy']:.3f}")
    print(f'baseline (mean pose): {baseline}')
    print(f'report: {path}')
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    from mocap_core.cli.mocap import run_model_cli
    return run_model_cli(sys.modules[__name__], 'python -m mocap_lifter.training.cli', argv)


if __name__ == '__main__':
    sys.exit(main())
