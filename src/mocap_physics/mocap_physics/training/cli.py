"""``mocap eval physics`` and ``mocap train physics`` (``python -m mocap_physics.training.cli``).

    mocap eval physics [--bags B [B ...]] [--noise none|lifter|both] [--dataset-clips N]
                       [--max-frames F] [--seed S] [--out docs/benchmarks/physics_eval]
    mocap eval gait [--bags B [B ...]] [--body-mass KG] [--out docs/benchmarks/physics_gait]
    mocap train physics [--steps N] [--run-dir runs/physics_dynet] [--device cpu|cuda]

Evaluation runs the physics cycle on ground-truth motion (the committed ``bags/gt_*`` bags in
the camera frame, and clips of the dataset's validation split in the world frame), clean and
with lifter-like noise, and writes a JSON + Markdown report
(:mod:`mocap_physics.training.evaluate`). ``mocap eval gait`` reports the forces and torques
on walking against gait biomechanics (:mod:`mocap_physics.training.gait`). Training fits the
DyNet gains
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
WALKING_BAGS = ('gt_cmu_walk_12_02', 'gt_bandai_walk_exhausted')


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
    p.add_argument('--family-clips', type=int, default=1,
                   help='also this many clips per held-out motion family of the strict split '
                        '(dance, martial arts, style old, style exhausted; 0: none)')
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
    g = sub.add_parser('gait', help='ground reaction forces and joint moments of the physics '
                       'on walking, against published gait data')
    g.add_argument('--bags', nargs='*', default=None,
                   help='ground-truth walking bags (default: the committed walking bags)')
    g.add_argument('--body-mass', type=float, default=70.0,
                   help='body mass, kg (forces in body weights and moments per kg do not '
                        'depend on it: the segment masses are fractions of it)')
    g.add_argument('--out', default=str(REPO / 'docs' / 'benchmarks' / 'physics_gait'),
                   help='report path without suffix (.json, .md and .png are written)')
    g.set_defaults(func=cmd_gait)


def _configs(quick: bool, dynet: Optional[str]) -> List['EvalConfig']:
    from ..cycle_params import PhysicsParams
    from .evaluate import EvalConfig

    cfgs = [EvalConfig('physics, true floor', PhysicsParams(), 'gt'),
            EvalConfig('physics, est. floor', PhysicsParams(), 'estimate'),
            EvalConfig('paper (eq. 13), true floor', PhysicsParams(dynamics='paper'), 'gt')]
    if not quick:
        cfgs += [EvalConfig('whole body, slide at once, stance 3 cm',
                            PhysicsParams(slide_threshold=0.05, slide_time=0.0,
                                          stance_height=0.03), 'gt'),
                 EvalConfig('whole body, joints 90 rad/s (kp 8100, kd 180)',
                            PhysicsParams(kp_joint=8100.0, kd_joint=180.0), 'gt'),
                 EvalConfig('whole body, k = 4 sub-steps',
                            PhysicsParams(substeps=4), 'gt'),
                 EvalConfig('whole body, full QP on OSQP (before)',
                            PhysicsParams(wbid_condensed=False), 'gt'),
                 EvalConfig('whole body, ProxQP', PhysicsParams(wbid_solver='proxqp'), 'gt'),
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
    fam_names: List[str] = []
    if args.family_clips > 0:
        from mocap_core.data.dataset import load_dataset
        from mocap_core.data.strict_split import HELD_OUT_FAMILIES, family_of
        print('loading the held-out families of the strict split ...', flush=True)
        t0 = time.time()
        by_family: dict = {f: [] for f in HELD_OUT_FAMILIES}
        for m in sorted(load_dataset('train'), key=lambda m: m.name):
            fam = family_of(m.name)
            if fam is not None and m.num_frames >= 60:
                by_family[fam].append(m)
        for fam, motions in by_family.items():
            if motions:
                step = max(1, len(motions) // args.family_clips)
                chosen = motions[step // 2::step][:args.family_clips]
                clips += [dataset_clip(m, args.max_frames, 'held-out families (strict split)')
                          for m in chosen]
                fam_names += [f'{m.name} ({fam})' for m in chosen]
        print(f'{len(fam_names)} held-out family clips ({time.time() - t0:.0f} s)', flush=True)
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
        'held-out family clips of the strict split (world frame, true floor only; '
        'mocap_core.data.strict_split)': ', '.join(fam_names) or 'none',
        'noise': 'lifter = evaluate.NoiseModel() (per-joint rotation noise 1 deg white + 5 deg '
                 'smooth, root jitter 5 mm / 15 mm along depth + 30 mm smooth drift, noisy '
                 f'contact probabilities), seed {args.seed}',
        'eval_seconds': round(seconds, 1),
    }
    path = write_report(results, Path(args.out), 'Physics cycle on ground-truth motion', meta)
    print(f'report: {path} (+ .json)')
    return 0


def gait_markdown(results: dict, meta: dict) -> str:
    """The gait report (``mocap eval gait``) as Markdown."""
    lines = ['# Physics on walking: forces and torques against gait biomechanics', '',
             'Made by:', '', '```', meta['command'], '```', '',
             f"- clips: {meta['clips']}", f"- body mass: {meta['body_mass']} kg (forces in "
             'body weights and moments per kg do not depend on it)',
             '- input: the ground-truth motion (clean), the true floor, ground-truth contact '
             'labels', '',
             'Published normal walking (`mocap_physics.training.gait` cites the sources): '
             'vertical GRF peaks about 1.1-1.3 BW with a mid-stance trough of about 0.7-0.8; '
             'ankle plantarflexion peak about 1.5 N m/kg; knee and hip peaks differ between '
             'laboratories (about 0.2-0.9 and 0.4-1.4 N m/kg).', '',
             '![GRF and moments over the gait cycle](physics_gait.png)', '']
    modes = list(results)
    lines += ['| measure | ' + ' | '.join(modes) + ' | published |',
              '|---|' + '---|' * (len(modes) + 1)]

    def row(name, get, fmt, ref):
        vals = []
        for m in modes:
            try:
                vals.append(fmt.format(get(results[m])))
            except (KeyError, TypeError):
                vals.append('-')
        lines.append(f'| {name} | ' + ' | '.join(vals) + f' | {ref} |')
    row('strides', lambda r: r['strides'], '{:d}', '')
    row('mean total vertical GRF (BW)', lambda r: r['mean_total_vertical_grf_bw'], '{:.3f}',
        '1.0')
    row('residual root force / weight, median', lambda r: r['residual_root_over_weight_median'],
        '{:.3f}', '0')
    row('vertical GRF, first peak (BW, % of cycle)',
        lambda r: (r['peak_1_bw'], 100 * r['peak_1_at']), '{0[0]:.2f} at {0[1]:.0f} %',
        '1.1-1.3 at ~15 %')
    row('vertical GRF, trough (BW)', lambda r: r['trough_bw'], '{:.2f}', '0.7-0.8')
    row('vertical GRF, second peak (BW, % of cycle)',
        lambda r: (r['peak_2_bw'], 100 * r['peak_2_at']), '{0[0]:.2f} at {0[1]:.0f} %',
        '1.1-1.3 at ~45-50 %')
    refs = {'ankle': '~1.5 (plantarflexion)', 'knee': '0.2-0.9', 'hip': '0.4-1.4'}
    for j in ('ankle', 'knee', 'hip'):
        row(f'{j}: peak sagittal moment (N m/kg, +max / -min)',
            lambda r, j=j: (r['moments_per_kg'][f'{j}_sagittal']['peak_positive'],
                            r['moments_per_kg'][f'{j}_sagittal']['peak_negative']),
            '+{0[0]:.2f} / {0[1]:.2f}', refs[j])
        row(f'{j}: peak moment magnitude (N m/kg)',
            lambda r, j=j: r['moments_per_kg'][f'{j}_magnitude']['peak_abs'], '{:.2f}', '')
    return '\n'.join(lines) + '\n'


def cmd_gait(args: argparse.Namespace) -> int:
    import json
    from dataclasses import replace as dc_replace

    from ..cycle_params import PhysicsParams
    from .evaluate import load_gt_bag
    from .gait import analyse, plot, run_gait

    bags = args.bags if args.bags is not None else [str(REPO / 'bags' / b)
                                                    for b in WALKING_BAGS]
    clips = []
    for b in bags:
        try:
            clips.append(load_gt_bag(b))
        except Exception as exc:  # noqa: BLE001 - report and go on with the others
            print(f'mocap eval gait: skipping {b}: {exc}', file=sys.stderr)
    if not clips:
        print('mocap eval gait: error: no clip to evaluate', file=sys.stderr)
        return 1
    base = PhysicsParams(body_mass=args.body_mass)
    modes = {'whole body (default)': base,
             'paper (eq. 13)': dc_replace(base, dynamics='paper')}
    results = {}
    for name, params in modes.items():
        runs = [run_gait(c, params) for c in clips]
        results[name] = analyse(runs)
        r = results[name]
        print(f"{name}: {r['strides']} strides, mean GRF {r['mean_total_vertical_grf_bw']:.3f} "
              f"BW, peaks {r.get('peak_1_bw', float('nan')):.2f} / "
              f"{r.get('peak_2_bw', float('nan')):.2f} BW, ankle "
              f"{r['moments_per_kg'].get('ankle_sagittal', {}).get('peak_abs', float('nan')):.2f}"
              ' N m/kg')
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = {'command': 'mocap eval gait ' + ' '.join(sys.argv[3:]) if len(sys.argv) > 3
            and sys.argv[1:3] == ['eval', 'gait'] else 'mocap eval gait',
            'clips': ', '.join(c.name for c in clips), 'body_mass': args.body_mass}
    out.with_suffix('.json').write_text(json.dumps({'meta': meta, 'results': results},
                                                   indent=1))
    plot(results['whole body (default)'], out.with_suffix('.png'))
    out.with_suffix('.md').write_text(gait_markdown(results, meta))
    print(f'report: {out.with_suffix(".md")} (+ .json, .png)')
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    from .train_dynet import main_train
    return main_train(args)


def main(argv: Optional[List[str]] = None) -> int:
    from mocap_core.cli.mocap import run_model_cli
    return run_model_cli(sys.modules[__name__], 'python -m mocap_physics.training.cli', argv)


if __name__ == '__main__':
    sys.exit(main())
