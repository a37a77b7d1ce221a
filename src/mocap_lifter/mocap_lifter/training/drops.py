"""``mocap eval drops``: the node's lifter when keypoint frames are missing (no ROS imports).

A keypoint node on a busy machine publishes fewer frames than its camera gives (13 of 30
frames/s on a slow 2-core VM, ``docs/speed.md``), and some cameras run slower than the 30
frames/s the networks were trained at; others run faster. The lifter reads the frames it gets
as consecutive, so the motion it sees is two or three times too fast, or at half its pace.
:class:`~mocap_lifter.online.OnlineLifter` feeds the network at its own rate
(``network_rate_hz``: gaps filled in, faster input thinned); this evaluation measures what
that gives.

For every ground-truth bag (keypoints, intrinsics and the true camera-frame pose per frame,
``mocap data to-bag`` or the committed ``bags/``), frames are dropped by a pattern (every
second, every third, a random 45 % kept: the slow VM's rate), the rest are lifted frame by
frame with the node's defaults (windowed MotioNet, test-time flip, output smoothing), once as
they come (``network_rate_hz`` 0) and once with the gaps filled (30), and MPJPE / PA-MPJPE are
scored on the frames kept. The all-frames run is the reference. A 60 frames/s camera is
simulated by adding the midpoint between consecutive frames (keypoints and truth alike).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Dict, List, Sequence, Tuple

import numpy as np

REPO = Path(__file__).resolve().parents[4]
#: the committed ground-truth bags (bags/README.md): three from the keypoint synthesizer, one
#: rendered and detected by BlazePose
COMMITTED = ('rendered_cmu_05_01', 'gt_cmu_walk_12_02', 'gt_bandai_walk_exhausted',
             'gt_bandai_wave_normal')
#: where ``mocap data to-bag validation -o ... --limit 16`` puts more bags (the command in
#: docs/lifter.md); used when present
CACHE_BAGS = Path.home() / '.cache' / 'mocap' / 'drops_bags'
PERIOD_NS = 33_333_333
PATTERNS = ('every 2nd frame (15 Hz)', 'every 3rd frame (10 Hz)', 'random 45 % (13.5 Hz)')
#: a faster camera, simulated: each frame and the midpoint to the next, 16.7 ms apart (the
#: truth at the midpoints interpolated too)
FAST = '60 frames/s (midpoints added)'


def read_bag(path: Path) -> Tuple[np.ndarray, object, np.ndarray]:
    """(T, 23, 3) keypoints of the first person, the camera intrinsics and (T, 18, 3) true
    joint positions (camera optical frame, m) of a ground-truth bag."""
    from mocap_core.data.gt_bag import read_groundtruth_bag
    b = read_groundtruth_bag(path)
    if b['keypoints'] is None or b['intrinsics'] is None:
        raise ValueError(f'{path}: no keypoints or no camera info')
    n = min(len(b['keypoints']), len(b['poses']))
    return b['keypoints'][:n], b['intrinsics'], np.stack([p.joint_positions()
                                                          for p in b['poses'][:n]])


def kept_frames(pattern: str, frames: int, seed: int) -> np.ndarray:
    """Indices of the frames a pattern of :data:`PATTERNS` keeps (or 'all')."""
    if pattern == 'all':
        return np.arange(frames)
    if pattern.startswith('every 2nd'):
        return np.arange(0, frames, 2)
    if pattern.startswith('every 3rd'):
        return np.arange(0, frames, 3)
    keep = np.random.default_rng(seed).random(frames) < 0.45
    keep[0] = True
    return np.flatnonzero(keep)


def lift_stamped(model, kp: np.ndarray, intr, stamps: Sequence[int], network_rate_hz: float
                 ) -> Tuple[np.ndarray, object]:
    """The node's lifter (windowed defaults) frame by frame on keypoints (K, 23, 3) stamped
    ``stamps`` (ns): ((K, 18, 3) joints of those frames, the lifter)."""
    from ..online import DEFAULT_VIRTUAL_CAMERA, OnlineLifter
    from ..output_smoothing import DEFAULT_OUTPUT_ROOT_SIGMA, DEFAULT_OUTPUT_SIGMA

    lifter = OnlineLifter(model, 'windowed', flip=True, output_sigma=DEFAULT_OUTPUT_SIGMA,
                          output_root_sigma=DEFAULT_OUTPUT_ROOT_SIGMA,
                          network_rate_hz=network_rate_hz,
                          virtual_camera=DEFAULT_VIRTUAL_CAMERA)
    frames = []
    for stamp, k in zip(stamps, kp):
        frames += lifter.push(int(stamp), k, intr)[0]
    frames += lifter.flush()
    if [f.stamp_ns for f in frames] != [int(s) for s in stamps]:
        raise RuntimeError('the lifter did not return exactly the frames it was given')
    return np.stack([f.pose.joint_positions() for f in frames]), lifter


def lift_kept(model, kp: np.ndarray, intr, kept: np.ndarray, network_rate_hz: float
              ) -> Tuple[np.ndarray, int]:
    """The kept frames of a 30 frames/s sequence, stamped as the camera gave them: ((K, 18,
    3) joints of the kept frames, frames filled in)."""
    joints, lifter = lift_stamped(model, kp[kept], intr, [PERIOD_NS * int(i) for i in kept],
                                  network_rate_hz)
    return joints, lifter.filled_frames


def with_midpoints(x: np.ndarray, confidence: bool = False) -> np.ndarray:
    """(T, ...) -> (2T - 1, ...): each frame and the midpoint to the next (a keypoint's
    confidence at a midpoint the smaller of its two)."""
    out = np.empty((2 * len(x) - 1,) + x.shape[1:])
    out[0::2] = x
    mid = 0.5 * (x[:-1] + x[1:])
    if confidence:
        mid[..., 2] = np.minimum(x[:-1, ..., 2], x[1:, ..., 2])
    out[1::2] = mid
    return out


def evaluate(bags: Sequence[Path], progress: bool = True) -> Dict:
    """Per bag and pattern: MPJPE / PA-MPJPE (mm) of the kept frames, as they come and
    filled; the all-frames reference."""
    import torch
    from tqdm import tqdm

    from ..weights import default_weights, load_weights
    from .metrics import mpjpe_mm, pa_mpjpe_mm

    torch.set_num_threads(1)
    model = load_weights(default_weights('windowed')).eval()
    rows: List[Dict] = []
    for b, path in enumerate(tqdm(bags, desc='mocap eval drops', unit='bag',
                                  disable=not progress)):
        kp, intr, gt = read_bag(path)
        for pattern in ('all',) + PATTERNS:
            kept = kept_frames(pattern, len(kp), seed=b)
            row = {'bag': path.name, 'pattern': pattern, 'frames': len(kp),
                   'kept': int(len(kept))}
            for key, rate in (('as_is', 0.0), ('filled', 30.0)):
                if pattern == 'all' and key == 'filled':
                    continue
                pred, filled = lift_kept(model, kp, intr, kept, rate)
                row[key] = {'mpjpe_mm': mpjpe_mm(pred, gt[kept]),
                            'pa_mpjpe_mm': pa_mpjpe_mm(pred, gt[kept]),
                            'filled_frames': filled}
            rows.append(row)
        kp60, gt60 = with_midpoints(kp, confidence=True), with_midpoints(gt)
        stamps = [PERIOD_NS * i // 2 for i in range(len(kp60))]
        row = {'bag': path.name, 'pattern': FAST, 'frames': len(kp60), 'kept': len(kp60)}
        for key, rate in (('as_is', 0.0), ('filled', 30.0)):
            pred, lifter = lift_stamped(model, kp60, intr, stamps, rate)
            row[key] = {'mpjpe_mm': mpjpe_mm(pred, gt60),
                        'pa_mpjpe_mm': pa_mpjpe_mm(pred, gt60),
                        'thinned_frames': lifter.thinned_frames}
        rows.append(row)
    summary = {}
    for pattern in PATTERNS + (FAST,):
        sel = [r for r in rows if r['pattern'] == pattern]
        summary[pattern] = {
            'bags': len(sel),
            **{f'{key}_{m}': float(np.median([r[key][m] for r in sel]))
               for key in ('as_is', 'filled') for m in ('mpjpe_mm', 'pa_mpjpe_mm')},
            'filled_better_pa': int(sum(r['filled']['pa_mpjpe_mm'] < r['as_is']['pa_mpjpe_mm']
                                        for r in sel)),
            'filled_better_mpjpe': int(sum(r['filled']['mpjpe_mm'] < r['as_is']['mpjpe_mm']
                                           for r in sel))}
    ref = [r for r in rows if r['pattern'] == 'all']
    summary['all'] = {'bags': len(ref),
                      'mpjpe_mm': float(np.median([r['as_is']['mpjpe_mm'] for r in ref])),
                      'pa_mpjpe_mm': float(np.median([r['as_is']['pa_mpjpe_mm'] for r in ref]))}
    return {'summary': summary, 'rows': rows}


def write_report(res: Dict, out: Path, command: str) -> None:
    """``out``.md and ``out``.json."""
    s = res['summary']
    lines = ['# The lifter with keypoint frames missing (`mocap eval drops`)', '',
             f'Command: `{command}`. The node\'s lifter (windowed MotioNet, default weights, '
             'test-time flip, output smoothing) on ground-truth bags with frames dropped; '
             'scored on the frames kept (`mocap_lifter/training/drops.py`). "as is": every '
             'frame received given to the network as the next one (`network_rate_hz:=0`); '
             '"filled": the network fed at 30 frames/s (`network_rate_hz:=30`, the default: '
             'gaps filled in, the 60 frames/s input thinned and the frames between '
             'interpolated). The 60 frames/s row is scored on every frame, the truth at the '
             'midpoints interpolated as well.', '',
             f"All frames (reference): MPJPE {s['all']['mpjpe_mm']:.1f} mm, PA-MPJPE "
             f"{s['all']['pa_mpjpe_mm']:.1f} mm (median over {s['all']['bags']} bags).", '',
             '| frames kept | bags | MPJPE as is | MPJPE filled | PA-MPJPE as is | '
             'PA-MPJPE filled | bags better filled (PA / MPJPE) |',
             '|---|---|---|---|---|---|---|']
    for pattern in PATTERNS + (FAST,):
        v = s[pattern]
        lines.append(f"| {pattern} | {v['bags']} | {v['as_is_mpjpe_mm']:.1f} | "
                     f"**{v['filled_mpjpe_mm']:.1f}** | {v['as_is_pa_mpjpe_mm']:.1f} | "
                     f"**{v['filled_pa_mpjpe_mm']:.1f}** | {v['filled_better_pa']} / "
                     f"{v['filled_better_mpjpe']} |")
    lines += ['', 'Medians over bags (mm). Per bag:', '',
              '| bag | frames kept | PA-MPJPE: all frames | as is | filled |',
              '|---|---|---|---|---|']
    ref = {r['bag']: r['as_is']['pa_mpjpe_mm'] for r in res['rows'] if r['pattern'] == 'all'}
    for r in res['rows']:
        if r['pattern'] == 'all':
            continue
        lines.append(f"| {r['bag']} | {r['pattern']} | {ref[r['bag']]:.1f} | "
                     f"{r['as_is']['pa_mpjpe_mm']:.1f} | {r['filled']['pa_mpjpe_mm']:.1f} |")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix('.md').write_text('\n'.join(lines) + '\n')
    out.with_suffix('.json').write_text(json.dumps(res, indent=1))


def default_bags() -> List[Path]:
    bags = [REPO / 'bags' / name for name in COMMITTED]
    if CACHE_BAGS.is_dir():
        bags += sorted(p for p in CACHE_BAGS.iterdir() if p.is_dir())
    return bags


def add_parser(sub) -> None:
    p = sub.add_parser('drops', help='the lifter with keypoint frames missing, gaps filled '
                       'or not (docs/lifter.md)')
    p.add_argument('--bags', nargs='*', type=Path, default=None,
                   help='ground-truth bags (default: the committed ones and those in '
                   f'{CACHE_BAGS}, made by `mocap data to-bag validation -o {CACHE_BAGS} '
                   '--limit 16 --frames 240 --seed 11 --image-size 1280x720 '
                   '--no-world-motion`)')
    p.add_argument('--out', type=Path, default=REPO / 'docs' / 'benchmarks' / 'lifter_drops',
                   help='report path without suffix (.md and .json are written)')
    p.add_argument('--no-progress', action='store_true')
    p.set_defaults(func=cmd_drops)


def cmd_drops(args: argparse.Namespace) -> int:
    import sys

    bags = args.bags or default_bags()
    missing = [b for b in bags if not b.is_dir()]
    if missing:
        print(f'mocap eval drops: error: no such bag: {missing[0]}', file=sys.stderr)
        return 2
    res = evaluate(bags, progress=not args.no_progress)
    command = 'mocap eval drops' + ('' if args.bags is None else ' --bags ...')
    write_report(res, args.out, command)
    print(args.out.with_suffix('.md').read_text())
    return 0
