"""``mocap eval signatures`` (registered with the lifter's commands): can the lifter's held
bone lengths tell people apart?

The keypoint node gives a person who left and came back under a new id their old id when the
lifter's held skeletons of the two agree within ``id_bone_length_tolerance``
(docs/multi_person.md). This measures, on the rendered validation clips of ``mocap data
render`` (a random body per clip, the real detector's keypoints, calibrated intrinsics), how
far apart two estimates of one person are (the two halves of a clip, each lifted as its own
stream) against two different people (two clips), for the shipped windowed MotioNet with the
node's defaults (:mod:`mocap_lifter.signatures`).

    mocap eval signatures [--renders ~/.cache/mocap/render] [--split validation]
                          [--limit N] [-o docs/benchmarks/bone_length_signatures.md]
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path
from typing import Dict

DEFAULT_RENDERS = Path.home() / '.cache' / 'mocap' / 'render'


def add_signatures_parser(sub) -> None:
    p = sub.add_parser('signatures', help="how well the lifter's held bone lengths tell "
                       'people apart (rendered clips)', description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--renders', default=str(DEFAULT_RENDERS), help='rendered clips')
    p.add_argument('--split', default='validation')
    p.add_argument('--limit', type=int, default=0, help='at most this many clips (0: all)')
    p.add_argument('--half-frames', type=int, default=90, help='a clip is cut in two halves '
                   'when each has at least this many frames (default 90: the skeleton is '
                   'held after 90 frames)')
    p.add_argument('-o', '--output', default='docs/benchmarks/bone_length_signatures.md')
    p.add_argument('--quiet', action='store_true', help='no progress bar')
    p.set_defaults(func=cmd_eval_signatures)


def cmd_eval_signatures(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from .online import DEFAULT_VIRTUAL_CAMERA, OnlineLifter
    from .output_smoothing import DEFAULT_OUTPUT_ROOT_SIGMA, DEFAULT_OUTPUT_SIGMA
    from .signatures import clip_signatures, summarise
    from .weights import default_weights, load_weights

    root = Path(args.renders).expanduser() / args.split
    clips = sorted(d for d in root.glob('*') if (d / 'done').exists()) if root.is_dir() else []
    if args.limit:
        clips = clips[:args.limit]
    if len(clips) < 3:
        print(f'mocap eval signatures: error: fewer than 3 rendered clips in {root} (make them '
              f'with: mocap data render --split {args.split} --limit 60)', file=sys.stderr)
        return 1
    weights = default_weights('windowed')
    model = load_weights(weights, 'cpu', causal=False)

    def make_lifter() -> OnlineLifter:      # the node's defaults (mocap_lifter.node)
        return OnlineLifter(model, 'windowed', None, 90, 1.0, 'cpu', flip=True,
                            output_sigma=DEFAULT_OUTPUT_SIGMA,
                            output_root_sigma=DEFAULT_OUTPUT_ROOT_SIGMA,
                            virtual_camera=DEFAULT_VIRTUAL_CAMERA)

    got = []
    for clip in tqdm(clips, desc='mocap eval signatures', unit='clip', disable=args.quiet):
        sig = clip_signatures(make_lifter, clip, args.half_frames)
        if sig is not None:
            got.append(sig)
    res = summarise(got)
    res['weights'] = weights.name
    command = f'mocap eval signatures --split {args.split}' + (
        f' --limit {args.limit}' if args.limit else '')
    write_report(res, Path(args.output), command)
    print(Path(args.output).read_text())
    return 0


def _q(d: Dict) -> str:
    if not d.get('n'):
        return '–'
    return (f"{100 * d['median']:.1f} % (p10 {100 * d['p10']:.1f}, p90 {100 * d['p90']:.1f}; "
            f"{d['n']} pairs)")


def write_report(res: Dict, out: Path, command: str) -> None:
    lines = [
        "# Bone lengths as a signature: the lifter's held skeletons, one person twice against "
        'two people', '',
        f'`{command}` on {platform.node()} ({platform.machine()}), '
        f"{time.strftime('%Y-%m-%d')}, weights `{res['weights']}` with the lifter node's "
        'defaults. Rendered validation clips (one random Anny body each, BlazePose '
        'keypoints, true intrinsics). Distance: the median over the bone groups of the '
        "relative difference (`mocap_core.tracking.signature_distance`, the tracker's own).",
        '',
        f"Clips: {res['clips']} with the person found ({res['lifted']} lifted, "
        f"{res['held']} long enough for the skeleton to be held).", '',
        '| pairs | distance: median (p10, p90) |', '|---|---|',
        f"| one person twice (two halves of a clip, each its own stream) | "
        f"{_q(res['same_person'])} |",
        f"| two different people (whole-clip estimates of two clips) | "
        f"{_q(res['different_people'])} |",
        f"| two different people, true bone lengths | {_q(res['different_people_truth'])} |",
        f"| estimate against the body's true bone lengths | {_q(res['estimate_vs_truth'])} |",
        '',
        f"Correlation of the estimated and the true summed bone lengths over the clips: "
        f"{res['size_correlation']:.2f}. Spread of a bone group over the clips (std / mean, "
        f"median over the groups): estimates {100 * res['spread']['estimate']:.1f} %, "
        f"truth {100 * res['spread']['truth']:.1f} %.", '',
        'The same with the scale taken out (each set of lengths divided by its sum: the '
        "body's proportions):", '',
        '| pairs | distance: median (p10, p90) |', '|---|---|',
        f"| one person twice | {_q(res['proportions']['same_person'])} |",
        f"| two different people | {_q(res['proportions']['different_people'])} |",
        f"| two different people, truth | "
        f"{_q(res['proportions']['different_people_truth'])} |", '',
        '| tolerance | one person twice: renamed | two people: renamed (wrongly) |',
        '|---|---|---|']
    lines += [f"| {100 * t['tolerance']:.0f} % | {t['same_accepted']:.0%} | "
              f"{t['different_accepted']:.0%} |" for t in res['tolerances']]
    lines += ['', 'A wrong rename needs more than a close skeleton: the tracker also requires '
              'that exactly one remembered person qualifies, that the two were never seen '
              'at the same time and, with the image, that their clothes agree '
              '(docs/multi_person.md); those filters are not part of these figures.', '',
              'Regenerate: `mocap data render --split validation --limit 60`, then `'
              + command + '`.', '']
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text('\n'.join(lines))
    out.with_suffix('.json').write_text(json.dumps(res, indent=1, default=float))
