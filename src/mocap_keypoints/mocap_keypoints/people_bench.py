"""Several-people detector benchmark (``mocap bench multipose``): the single-person BlazePose
(the legacy API, ``max_persons 1``) and the multi-person detector
(:class:`~mocap_keypoints.multipose.BlazePoseMultiDetector`, ``max_persons 4``) with the
tracker, side by side on the same decoded frames of real clips: time per frame (median, both
measured in one run, alternating frame by frame), people found per frame, the ids the
tracker gave and for how many frames each.

Clips: the committed test clip, and where ``../shared/data/videos`` exists the real videos
(two basketball players, a walk filmed by a moving camera, a two-person demo, a street).
Prints the figures and writes a Markdown report (default ``docs/benchmarks/multipose.md``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from collections import Counter
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np

ROOT = Path(__file__).resolve().parents[3]


def clips() -> Dict[str, Path]:
    from mocap_core.data.splits import shared_data_dir
    out = {'taiji_640x360 (committed)': ROOT / 'data' / 'video_example' / 'taiji_640x360.mp4'}
    videos = shared_data_dir() / 'videos'
    for name, rel in (('basketball (2 people)', 'glamr/basketball.mp4'),
                      ('pexels walk (moving camera)', 'glamr/pexels-walking-dynamic-5738706.mp4'),
                      ('multi_person_demo (2 people)', 'mmhuman3d/multi_person_demo.mp4'),
                      ('street (many people)', 'openpose_examples/video.avi')):
        if (videos / rel).is_file():
            out[name] = videos / rel
    return out


def _frames(path: Path, limit: int) -> List[np.ndarray]:
    import cv2
    cap = cv2.VideoCapture(str(path))
    out = []
    while len(out) < limit:
        ok, img = cap.read()
        if not ok:
            break
        out.append(img)
    cap.release()
    return out


def measure(path: Path, limit: int) -> Dict[str, object]:
    """Both detectors on the clip's frames, alternating frame by frame."""
    from mocap_core.tracking import PersonTracker, TrackerParams

    from .detector import BlazePoseDetector
    from .multipose import BlazePoseMultiDetector

    frames = _frames(path, limit)
    single, multi = BlazePoseDetector(), BlazePoseMultiDetector(max_persons=4)
    tracker = PersonTracker(TrackerParams(max_persons=4))
    t_single, t_multi, found_single, found_multi = [], [], Counter(), Counter()
    id_frames: Counter = Counter()
    try:
        for k, img in enumerate(frames):
            t0 = time.perf_counter()
            a = single.detect(img)
            t1 = time.perf_counter()
            b = multi.detect(img)
            t2 = time.perf_counter()
            t_single.append(t1 - t0)
            t_multi.append(t2 - t1)
            found_single[len(a)] += 1
            found_multi[len(b)] += 1
            for p in tracker.update(b, k / 30.0):
                id_frames[p.id] += 1
    finally:
        single.close()
        multi.close()
    h, w = frames[0].shape[:2] if frames else (0, 0)
    return {
        'frames': len(frames), 'size': f'{w}x{h}',
        'single_ms': 1e3 * float(np.median(t_single)) if t_single else float('nan'),
        'multi_ms': 1e3 * float(np.median(t_multi)) if t_multi else float('nan'),
        'single_found': dict(sorted(found_single.items())),
        'multi_found': dict(sorted(found_multi.items())),
        'ids': dict(sorted(id_frames.items())),
        'detections': multi.detections, 'windows_opened': multi.windows_opened,
        'tracker': {'births': tracker.stats.births, 'reidentified': tracker.stats.reidentified,
                    'false_detections_ignored': tracker.stats.blips},
    }


def render(results: Dict[str, dict], limit: int) -> str:
    machine = f'{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs'
    lines = [
        '# Several people: the multi-person detector on real clips',
        '',
        f'`mocap bench multipose --frames {limit}` on {platform.node()} ({machine}), '
        f'{time.strftime("%Y-%m-%d")}. Both detectors see the same decoded frames, '
        'alternating frame by frame, one thread each; medians per frame.',
        '',
        '| clip | frames | size | single-person ms | multi-person ms | ratio | people found '
        '(single) | people found (multi) | ids (frames each) |',
        '|---|---|---|---|---|---|---|---|---|',
    ]
    for name, r in results.items():
        ratio = r['multi_ms'] / r['single_ms'] if r['single_ms'] > 0 else float('nan')
        fs = ', '.join(f'{k}: {v}' for k, v in r['single_found'].items())
        fm = ', '.join(f'{k}: {v}' for k, v in r['multi_found'].items())
        ids = ', '.join(f'{k}: {v}' for k, v in r['ids'].items()) or 'none'
        lines.append(f"| {name} | {r['frames']} | {r['size']} | {r['single_ms']:.1f} | "
                     f"{r['multi_ms']:.1f} | {ratio:.2f} | {fs} | {fm} | {ids} |")
    lines += ['', '"people found": frames by number of people the detector returned. "ids": '
              'the tracker\'s ids over the multi-person detections (keypoint node defaults) '
              'and the frames each was published.', '']
    return '\n'.join(lines)


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(prog='mocap bench multipose', description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--frames', type=int, default=300, help='frames per clip (default 300)')
    ap.add_argument('--output', type=Path,
                    default=ROOT / 'docs' / 'benchmarks' / 'multipose.md')
    args = ap.parse_args(argv)
    os.environ.setdefault('GLOG_minloglevel', '2')
    results = {}
    for name, path in clips().items():
        r = measure(path, args.frames)
        results[name] = r
        print(f"{name}: single {r['single_ms']:.1f} ms, multi {r['multi_ms']:.1f} ms per "
              f"frame; people (multi) {r['multi_found']}; ids {r['ids']}")
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(render(results, args.frames))
    args.output.with_suffix('.json').write_text(json.dumps(results, indent=1))
    print(f'report: {args.output}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
