"""``mocap bench camera-motion``: the camera-motion estimate's cost and accuracy on rendered clips,
for several Lucas-Kanade settings side by side (a benchmark: prints figures, writes a report).

Each rendered clip (``mocap data render``: a video, its people's keypoints and the true camera
path) is decoded once; every setting then runs :class:`~mocap_core.camera_motion.
CameraMotionEstimator` over the same frames, in turn, on one OpenCV thread (as the keypoint node
runs it), and is scored against the true camera:

- the rotation error, deg/s: median over the frames with a known state of the angle between the
  estimated and the true frame-to-frame rotation, times the frame rate (the median over clips is
  reported, as ``mocap eval video`` does);
- the drift, deg: the accumulated orientation's error at the last frame;
- static correct: the share of frames whose ``static`` / not ``static`` verdict matches the
  truth (the camera's centre moved more than 2 mm or it turned more than 0.05 deg since the last
  frame: not static), which decides the world stage's fusion;
- the share of frames in each state, and the CPU time of the estimate per frame (decoding
  excluded; the median over clips).

The first setting is the reference of the paired counts (clips better or worse).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Dict, List, Sequence, Tuple

import numpy as np

#: a camera centre that moved more than this (m), or turned more than ``STILL_DEG``, since the
#: last frame is not static
STILL_M = 0.002
STILL_DEG = 0.05


def true_states(R: np.ndarray, C: np.ndarray) -> List[str]:
    """Per frame 'static' or 'moving' / 'rotating' from the true camera: (F, 3, 3) world ->
    camera rotations ``R`` and (F, 3) centres ``C`` in the world."""
    from ..rotations import matrix_to_axis_angle

    out = ['static']
    for i in range(1, len(R)):
        turn = float(np.degrees(np.linalg.norm(matrix_to_axis_angle(R[i - 1] @ R[i].T))))
        moved = float(np.linalg.norm(C[i] - C[i - 1]))
        out.append('moving' if moved > STILL_M else 'rotating' if turn > STILL_DEG
                   else 'static')
    return out


def score_clip(clip: Path, settings: Sequence[Tuple[int, int]]) -> Dict:
    """One clip, every (window, levels) setting: ``{'clip', 'frames', 'true': state shares,
    'WxL': {rotation_error_deg_s, drift_deg, static_correct, states, cpu_ms}}``."""
    import cv2

    from ..camera_motion import CameraMotionEstimator, CameraMotionParams, rotation_accuracy

    z = np.load(clip / 'data.npz')
    fps, R, C = float(z['fps']), z['camera_R'], z['camera_position']
    cap = cv2.VideoCapture(str(clip / 'video.mp4'))
    frames = []
    try:
        while True:
            ok, image = cap.read()
            if not ok:
                break
            frames.append(image)
    finally:
        cap.release()
    n = min(len(frames), len(R))
    if n < 2:
        raise ValueError(f'{clip}: {n} frame(s) decoded, at least 2 needed')
    truth = true_states(R[:n], C[:n])
    row: Dict = {'clip': clip.name, 'frames': n,
                 'true': {s: truth.count(s) / n for s in ('static', 'rotating', 'moving')}}
    keypoints = z['keypoints']
    for window, levels in settings:
        est = CameraMotionEstimator(z['K'], CameraMotionParams(track_window=window,
                                                               track_levels=levels))
        t0 = time.process_time()
        res = [est.update(frames[i], i / fps, keypoints[i] if i < len(keypoints) else None)
               for i in range(n)]
        cpu = (time.process_time() - t0) / n * 1e3
        error, drift = rotation_accuracy(res, R, fps)
        states = [e.state for e in res]
        row[f'{window}x{levels}'] = {
            'rotation_error_deg_s': error if np.isfinite(error) else None,
            'drift_deg': drift,
            'static_correct': float(np.mean([(s == 'static') == (t == 'static')
                                             for s, t in zip(states, truth)])),
            'states': {s: states.count(s) / n for s in ('static', 'rotating', 'moving',
                                                        'unknown')},
            'cpu_ms': cpu}
    return row


def summarise(rows: List[Dict], keys: Sequence[str]) -> Dict[str, Dict]:
    """Per setting: medians and means over ``rows``, and paired counts against ``keys[0]``."""
    out: Dict[str, Dict] = {}
    for k in keys:
        errs = [r[k]['rotation_error_deg_s'] for r in rows
                if r[k]['rotation_error_deg_s'] is not None]
        s = {'rotation_error_deg_s': float(np.median(errs)) if errs else float('nan'),
             'drift_deg_median': float(np.median([r[k]['drift_deg'] for r in rows])),
             'drift_deg_mean': float(np.mean([r[k]['drift_deg'] for r in rows])),
             'static_correct': float(np.mean([r[k]['static_correct'] for r in rows])),
             'states': {st: float(np.mean([r[k]['states'][st] for r in rows]))
                        for st in ('static', 'rotating', 'moving', 'unknown')},
             'cpu_ms': float(np.median([r[k]['cpu_ms'] for r in rows]))}
        if k != keys[0]:
            ref = keys[0]
            s['cpu_vs_reference'] = float(np.median([r[k]['cpu_ms'] / r[ref]['cpu_ms']
                                                     for r in rows]))
            d = [r[k]['drift_deg'] - r[ref]['drift_deg'] for r in rows]
            s['drift_worse_better'] = (sum(x > 0.5 for x in d), sum(x < -0.5 for x in d))
            e = [r[k]['rotation_error_deg_s'] - r[ref]['rotation_error_deg_s'] for r in rows
                 if r[k]['rotation_error_deg_s'] is not None
                 and r[ref]['rotation_error_deg_s'] is not None]
            s['error_worse_better'] = (sum(x > 0.05 for x in e), sum(x < -0.05 for x in e))
        out[k] = s
    return out


def report(sets: Dict[str, Dict], keys: Sequence[str], meta: Dict) -> str:
    lines = ['# Camera-motion estimate: Lucas-Kanade settings side by side', '',
             f"`{meta['command']}` on {meta['date']}: {meta['machine']}, one OpenCV thread. "
             'Each clip is decoded once and every setting runs over the same frames; scores '
             'against the render\'s true camera (`mocap_core/cli/bench_camera.py`). '
             f'Reference of the paired counts and ratios: {keys[0]} (window x pyramid '
             'levels).', '']
    for name, d in sets.items():
        s = d['summary']
        lines += [f"## {name}: {d['clips']} clips (true camera: moving "
                  f"{d['true_moving']:.0%} of the frames, rotating "
                  f"{d['true_rotating']:.0%})", '',
                  '| setting | rotation error (deg/s, median over clips) | drift (deg, '
                  'median / mean) | static correct | unknown | CPU per frame (ms, median) | '
                  'CPU vs. reference | drift worse / better (clips) | rotation error '
                  'worse / better |', '|---|---|---|---|---|---|---|---|---|']
        for k in keys:
            r = s[k]
            ratio = f"{r['cpu_vs_reference']:.2f}x" if 'cpu_vs_reference' in r else ''
            lines.append(
                f"| {k} | {r['rotation_error_deg_s']:.3f} | {r['drift_deg_median']:.2f} / "
                f"{r['drift_deg_mean']:.2f} | {r['static_correct']:.4f} | "
                f"{r['states']['unknown']:.3f} | {r['cpu_ms']:.2f} | {ratio} | "
                f"{_pair(r.get('drift_worse_better'))} | "
                f"{_pair(r.get('error_worse_better'))} |")
        lines.append('')
    return '\n'.join(lines)


def _pair(counts) -> str:
    return f'{counts[0]} / {counts[1]}' if counts else ''


def parse_setting(text: str) -> Tuple[int, int]:
    """'15x2' -> (15, 2)."""
    try:
        w, lv = text.lower().split('x')
        out = (int(w), int(lv))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f'expected WINDOWxLEVELS (e.g. 15x2), got {text!r}') from None
    if out[0] < 3 or out[1] < 0:
        raise argparse.ArgumentTypeError(f'window must be >= 3 and levels >= 0: {text!r}')
    return out


def cmd_camera_motion(args: argparse.Namespace) -> int:
    import cv2

    from ..render.batch import DEFAULT_OUT
    from ..render.clip import iter_done

    cv2.setNumThreads(1)
    settings = args.lk or [(21, 3), (15, 2)]
    if len(set(settings)) != len(settings) or args.limit < 0 or args.every < 1:
        print('mocap bench camera-motion: error: each --lk once, --limit >= 0, --every >= 1',
              file=sys.stderr)
        return 2
    keys = [f'{w}x{lv}' for w, lv in settings]
    sets: Dict[str, Dict] = {}
    for renders in args.renders or [str(DEFAULT_OUT)]:
        clips = [Path(c) for c in iter_done(Path(renders), args.split)]
        clips = clips[::max(1, args.every)][:args.limit or None]
        if not clips:
            print(f'mocap bench camera-motion: error: no rendered {args.split} clips under '
                  f'{renders}', file=sys.stderr)
            return 2
        rows = []
        for i, clip in enumerate(clips):
            try:
                rows.append(score_clip(clip, settings))
            except (OSError, ValueError, KeyError) as exc:       # one bad clip: skipped
                print(f'{renders} {i + 1}/{len(clips)}: skipped ({exc})', flush=True)
                continue
            print(f'{renders} {i + 1}/{len(clips)} {clip.name[-50:]}: ' + ', '.join(
                f"{k} {rows[-1][k]['cpu_ms']:.1f} ms" for k in keys), flush=True)
        if not rows:
            print(f'mocap bench camera-motion: error: no clip under {renders} could be read',
                  file=sys.stderr)
            return 1
        sets[renders] = {'clips': len(rows), 'rows': rows, 'summary': summarise(rows, keys),
                         'true_moving': float(np.mean([r['true']['moving'] for r in rows])),
                         'true_rotating': float(np.mean([r['true']['rotating']
                                                         for r in rows]))}
    meta = {'date': datetime.datetime.now().strftime('%Y-%m-%d %H:%M'),
            'machine': f'{platform.machine()}, {os.cpu_count()} CPU cores',
            'command': ' '.join(['mocap bench camera-motion'] + (
                sys.argv[sys.argv.index('camera-motion') + 1:] if 'camera-motion' in sys.argv
                else []))}
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    text = report(sets, keys, meta)
    out.write_text(text + '\n')
    out.with_suffix('.json').write_text(json.dumps({'meta': meta, 'sets': sets}, indent=1))
    print(text)
    print(f'wrote {out}')
    return 0


def add_parser(bench_sub, root: Path) -> None:
    p = bench_sub.add_parser('camera-motion', help="the camera-motion estimate's cost and "
                             'accuracy on rendered clips, Lucas-Kanade settings side by side')
    p.add_argument('--renders', action='append',
                   help='rendered clips (repeatable; default ~/.cache/mocap/render)')
    p.add_argument('--split', default='validation')
    p.add_argument('--every', type=int, default=1, help='every k-th clip')
    p.add_argument('--limit', type=int, default=0, help='at most this many clips per set')
    p.add_argument('--lk', action='append', type=parse_setting, metavar='WINDOWxLEVELS',
                   help='a Lucas-Kanade setting (repeatable; the first is the reference; '
                   'default: 21x3, the default, and 15x2)')
    p.add_argument('--output', default=str(root / 'docs' / 'benchmarks' / 'camera_motion.md'))
    p.set_defaults(func=cmd_camera_motion)
