"""Detector recall on rendered clips (``mocap bench recall``): how often the keypoint node's
multi-person detector finds the rendered person, how well it places them, what else it
reports, and what it costs, for settings side by side on the same decoded frames.

Each clip folder of ``mocap data render`` (``video.mp4``, ``data.npz``) holds one person whose
true joints (camera frame) and camera matrix are known. Per frame, every setting's detector
(:class:`~mocap_keypoints.multipose.BlazePoseMultiDetector` with the node's defaults and the
setting's changes) sees the same image, taking turns (the order rotating frame by frame). A
detection is the person when its shoulders, hips, knees and ankles lie on average within
:data:`MATCH_FRACTION` of the person's image height of the projected true joints; any other
detection counts as false. Frames count towards recall where the true person is at least
:data:`MIN_HEIGHT_PX` high and :data:`IN_IMAGE_SHARE` of the true joints are in the image.
The figures are broken down by the person's height in the image.

    mocap bench recall ~/.cache/mocap/render/validation ~/.cache/mocap/render_travel/validation \
        [--variant coarse:search_min_person_fraction=1] [--limit N] [-o docs/benchmarks/recall.md]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

ROOT = Path(__file__).resolve().parents[3]

#: a detection is the person when its body keypoints lie within this fraction of the person's
#: image height of the true joints, on average
MATCH_FRACTION = 0.2
#: frames where the true person is lower than this (px; the node's ``min_person_height_px``)
#: are not counted
MIN_HEIGHT_PX = 48.0
#: ... or where fewer than this share of the true joints lie in the image
IN_IMAGE_SHARE = 0.8
#: only detected keypoints at least this confident are compared, and a detection needs
#: :data:`MIN_SEEN` of its body keypoints that confident to be the person
MIN_CONFIDENCE = 0.3
MIN_SEEN = 4
#: the person's image height bins of the breakdown (px)
HEIGHT_BINS = (48, 64, 96, 160, 100000)
_BODY = ('left_shoulder', 'right_shoulder', 'left_hip', 'right_hip', 'left_knee',
         'right_knee', 'left_ankle', 'right_ankle')

#: settings compared by default: name -> changes to the detector's defaults (which are the
#: keypoint node's: ``KeypointsNode._new_detector`` with its default parameters)
VARIANTS = {'default': {}, 'coarse': {'search_min_person_fraction': 1.0}}


def parse_variant(text: str) -> Tuple[str, Dict[str, float]]:
    """``name:key=value,key=value`` -> (name, {key: float value})."""
    name, _, rest = text.partition(':')
    changes = {}
    for item in filter(None, rest.split(',')):
        k, sep, v = item.partition('=')
        if not sep:
            raise ValueError(f'variant {text!r}: {item!r} is not key=value')
        changes[k.strip()] = float(v)
    return name.strip(), changes


def clip_dirs(roots: Sequence[Path], limit: Optional[int] = None) -> List[Path]:
    """Rendered clip folders under ``roots`` (a clip folder itself, or a folder of them),
    each once (the same clip in two render sets: the first), sorted by name."""
    seen, out = set(), []
    for root in roots:
        found = [root] if (root / 'data.npz').is_file() else sorted(
            p for p in root.iterdir() if (p / 'data.npz').is_file() and
            (p / 'video.mp4').is_file())
        for p in found:
            if p.name not in seen:
                seen.add(p.name)
                out.append(p)
    return out[:limit] if limit else out


def match(found: np.ndarray, truth_uv: np.ndarray, height: float) -> Tuple[Optional[float], int]:
    """(P, 23, 3) detections and the (18, 2) projected true joints of a person ``height`` px
    high -> (the best detection's mean body-keypoint error / height if it is the person,
    else None; the number of other detections). Only keypoints at least
    :data:`MIN_CONFIDENCE` confident count; a detection with fewer than :data:`MIN_SEEN`
    of them is another detection."""
    from mocap_core.skeleton import JOINT_INDEX, KEYPOINT_INDEX
    kp_idx = [KEYPOINT_INDEX[n] for n in _BODY]
    j_idx = [JOINT_INDEX[n] for n in _BODY]
    errs = []
    for k in found:
        seen = k[kp_idx, 2] >= MIN_CONFIDENCE
        d = np.linalg.norm(k[kp_idx, :2] - truth_uv[j_idx], axis=1)[seen]
        errs.append(float(d.mean()) / max(height, 1.0) if seen.sum() >= MIN_SEEN
                    else float('inf'))
    hits = [e for e in errs if e < MATCH_FRACTION]
    best = min(hits) if hits else None
    return best, len(errs) - (1 if best is not None else 0)


def measure(clip: Path, variants: Dict[str, Dict[str, float]]) -> Dict[str, object]:
    """Every variant's detector over the clip's frames; per variant the frame indices
    counted, those where the person was found, the errors, the other detections and the
    time per frame."""
    import cv2

    from mocap_core.camera import project_pinhole

    from .multipose import BlazePoseMultiDetector
    gt = np.load(clip / 'data.npz')
    uv = project_pinhole(gt['K'], gt['joints_camera'])[..., :2]
    names = list(variants)
    dets = {n: BlazePoseMultiDetector(**variants[n]) for n in names}
    res = {n: {'found': [], 'error': [], 'false': [], 'ms': []} for n in names}
    heights, counted = [], []
    cap = cv2.VideoCapture(str(clip / 'video.mp4'))
    k = 0
    try:
        while k < len(uv):
            ok, img = cap.read()
            if not ok:
                break
            h, w = img.shape[:2]
            p = uv[k]
            height = float(np.ptp(p[:, 1]))
            inside = np.mean((p[:, 0] >= 0) & (p[:, 0] < w) & (p[:, 1] >= 0) & (p[:, 1] < h))
            heights.append(height)
            counted.append(bool(height >= MIN_HEIGHT_PX and inside >= IN_IMAGE_SHARE))
            for j in range(len(names)):
                n = names[(k + j) % len(names)]
                t0 = time.perf_counter()
                got = dets[n].detect(img)
                res[n]['ms'].append(1e3 * (time.perf_counter() - t0))
                err, others = match(got, p, height)
                res[n]['found'].append(err is not None)
                res[n]['error'].append(np.nan if err is None else err)
                res[n]['false'].append(others)
            k += 1
    finally:
        cap.release()
        for d in dets.values():
            d.close()
    out = {'clip': clip.name, 'frames': k, 'size': f'{w}x{h}' if k else '',
           'height': heights, 'counted': counted}
    for n in names:
        out[n] = {'found': res[n]['found'], 'error': res[n]['error'],
                  'false': res[n]['false'], 'ms': res[n]['ms']}
    return out


def clip_recall(clip: dict, name: str) -> float:
    """The share of a measured clip's counted frames where variant ``name`` found the
    person (nan when none counts)."""
    m = np.asarray(clip['counted'], bool)
    return float(np.asarray(clip[name]['found'], bool)[m].mean()) if m.any() else float('nan')


def summarise(clips: List[dict], names: Sequence[str]) -> Dict[str, dict]:
    """Pooled figures per variant over the counted frames: recall (all, and by the person's
    height), median error of the hits, other detections per 1000 frames, clips where the
    person was never found; time per frame (median, mean) over every frame."""
    if not clips:
        raise ValueError('no clip was measured')
    out = {}
    height = np.concatenate([np.asarray(c['height']) for c in clips])
    counted = np.concatenate([np.asarray(c['counted'], bool) for c in clips])
    for n in names:
        found = np.concatenate([np.asarray(c[n]['found'], bool) for c in clips])
        err = np.concatenate([np.asarray(c[n]['error'], float) for c in clips])
        ms = np.concatenate([np.asarray(c[n]['ms'], float) for c in clips])
        other = np.concatenate([np.asarray(c[n]['false'], float) for c in clips])
        bins = {}
        for lo, hi in zip(HEIGHT_BINS[:-1], HEIGHT_BINS[1:]):
            sel = counted & (height >= lo) & (height < hi)
            bins[f'{lo}-{hi}' if hi < 100000 else f'>={lo}'] = {
                'frames': int(sel.sum()),
                'recall': float(found[sel].mean()) if sel.any() else float('nan')}
        never = [c['clip'] for c in clips
                 if np.any(c['counted']) and not np.any(np.asarray(c[n]['found'])[
                     np.asarray(c['counted'], bool)])]
        out[n] = {
            'frames': int(counted.sum()),
            'recall': float(found[counted].mean()) if counted.any() else float('nan'),
            'by_height': bins,
            'error_median': float(np.median(err[found & counted]))
            if (found & counted).any() else float('nan'),
            'false_per_1000': 1000.0 * float(other[counted].mean()) if counted.any()
            else float('nan'),
            'never_found': never,
            'ms_median': float(np.median(ms)) if len(ms) else float('nan'),
            'ms_mean': float(np.mean(ms)) if len(ms) else float('nan'),
        }
    return out


def render(summary: Dict[str, dict], clips: List[dict], variants: Dict[str, dict],
           roots: Sequence[Path]) -> str:
    names = list(variants)
    machine = f'{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs'
    shown = ', '.join(f'`{n}`' + (f" ({', '.join(f'{k} {v:g}' for k, v in ch.items())})"
                                  if ch else ' (the node\'s defaults)')
                      for n, ch in variants.items())
    where = ', '.join('`' + '/'.join(Path(r).parts[-2:]) + '`' for r in roots)
    lines = [
        '# Detector recall on rendered people',
        '',
        f'`mocap bench recall` on {platform.node()} ({machine}), {time.strftime("%Y-%m-%d")}: '
        f'{len(clips)} rendered clips ({where}), '
        f'the multi-person detector with the keypoint node\'s settings: {shown}. Every '
        'setting sees the same decoded frames, taking turns frame by frame. A detection is '
        f'the person when its shoulders, hips, knees and ankles lie within {MATCH_FRACTION:g} '
        'of the person\'s image height of the true joints on average; frames count where '
        f'the person is at least {MIN_HEIGHT_PX:g} px high and {IN_IMAGE_SHARE:.0%} of the '
        'true joints are in the image.',
        '',
        '| | ' + ' | '.join(names) + ' |',
        '|---|' + '---|' * len(names),
    ]

    def row(label: str, cell) -> None:
        lines.append(f"| {label} | {' | '.join(cell(summary[n]) for n in names)} |")
    row('frames counted', lambda s: str(s['frames']))
    row('**recall**', lambda s: f"**{100 * s['recall']:.1f} %**")
    for b, v in summary[names[0]]['by_height'].items():
        row(f"... person {b} px high ({v['frames']} frames)",
            lambda s, b=b: f"{100 * s['by_height'][b]['recall']:.1f} %")
    row('keypoint error of the hits, median (of the height)',
        lambda s: f"{100 * s['error_median']:.1f} %")
    row('other detections per 1000 frames', lambda s: f"{s['false_per_1000']:.1f}")
    row('clips where the person is never found', lambda s: str(len(s['never_found'])))
    row('time per frame: median / mean (ms)',
        lambda s: f"{s['ms_median']:.1f} / {s['ms_mean']:.1f}")
    lines += [
        '',
        '## Clips where the recalls differ most',
        '',
        '| clip | size | person height (median px) | ' + ' | '.join(names) + ' |',
        '|---|---|---|' + '---|' * len(names),
    ]

    def spread(c: dict) -> float:
        r = [clip_recall(c, n) for n in names]
        return float(np.nan_to_num(max(r) - min(r)))
    for c in sorted(clips, key=spread, reverse=True)[:12]:
        if spread(c) == 0.0:
            break
        lines.append(f"| {c['clip'][-60:]} | {c['size']} | {np.median(c['height']):.0f} | "
                     + ' | '.join(f'{100 * clip_recall(c, n):.0f} %' for n in names) + ' |')
    lines.append('')
    return '\n'.join(lines)


def _finite(x):
    """``x`` with every non-finite float (nested in dicts and lists) replaced by None, for
    strict JSON."""
    if isinstance(x, float):
        return x if np.isfinite(x) else None
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite(v) for v in x]
    return x


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(prog='mocap bench recall', description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('renders', nargs='+', type=Path,
                    help='rendered clip folders, or folders of them (mocap data render)')
    ap.add_argument('--variant', action='append', default=[],
                    help='name:key=value,... a setting compared (default: the node\'s '
                         'defaults and "coarse", search_min_person_fraction 1)')
    ap.add_argument('--limit', type=int, default=None, help='the first N clips only')
    ap.add_argument('-o', '--output', type=Path,
                    default=ROOT / 'docs' / 'benchmarks' / 'recall.md')
    args = ap.parse_args(argv)
    os.environ.setdefault('GLOG_minloglevel', '2')
    variants = dict(parse_variant(v) for v in args.variant) if args.variant else VARIANTS
    dirs = clip_dirs(args.renders, args.limit)
    if not dirs:
        ap.error('no rendered clips (folders with data.npz and video.mp4) found')
    from tqdm import tqdm
    clips = []
    for d in tqdm(dirs, desc='clips', unit='clip'):
        try:
            clips.append(measure(d, variants))
        except Exception as e:   # one unreadable clip is reported, the rest measured
            tqdm.write(f'{d.name}: skipped ({type(e).__name__}: {e})')
    if not clips:
        print('no clip could be measured', file=sys.stderr)
        return 1
    summary = summarise(clips, list(variants))
    for n, s in summary.items():
        bins = ', '.join(f"{b}: {100 * v['recall']:.0f} %" for b, v in s['by_height'].items())
        print(f"{n}: recall {100 * s['recall']:.1f} % of {s['frames']} frames ({bins}), "
              f"error {100 * s['error_median']:.1f} % of the height, "
              f"{s['false_per_1000']:.1f} other detections per 1000 frames, never found in "
              f"{len(s['never_found'])} clips, {s['ms_median']:.1f} / {s['ms_mean']:.1f} ms")
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(render(summary, clips, variants, args.renders))
    per_clip = [{'clip': c['clip'], 'frames': c['frames'], 'size': c['size'],
                 'height_median': float(np.median(c['height'])) if c['height'] else None,
                 **{n: {'recall': clip_recall(c, n),
                        'false': int(np.sum(np.asarray(c[n]['false'])[
                            np.asarray(c['counted'], bool)])),
                        'error_median': float(np.nanmedian(c[n]['error']))
                        if np.any(c[n]['found']) else None} for n in variants}}
                for c in clips]
    args.output.with_suffix('.json').write_text(json.dumps(_finite(
        {'summary': summary, 'variants': variants, 'clips': per_clip}), indent=1))
    print(f'report: {args.output}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
