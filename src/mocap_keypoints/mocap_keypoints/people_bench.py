"""Several-people detector benchmark (``mocap bench multipose``): the single-person BlazePose
(the legacy API, ``max_persons 1``) and the multi-person detector
(:class:`~mocap_keypoints.multipose.BlazePoseMultiDetector`, ``max_persons 4``) with the
tracker, side by side on the same decoded frames of real clips: time per frame (median and
mean, all measured in one run, taking turns frame by frame, the order rotating), people found
per frame, the ids the tracker gave and for how many frames each. The mean includes the
multi-person detector's periodic search for new people, so it is the one that says what a
live keypoint node spends. A third column runs the multi-person detector with its windows
only (``whole_frame_min_height`` 0: no whole-image tracking of a lone person), the design
before it; a fourth without the finer search squares for people far from the camera
(``search_min_person_fraction`` 1), a fifth keeping the search to its cycle of regions
instead of looking where the picture changed (``search_where_changed`` false). A clip shorter
than ``--frames`` is played forwards and backwards (no cut).

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
    """Up to ``limit`` decoded BGR frames; a shorter clip is played forwards, backwards,
    forwards ... (:func:`ping_pong`)."""
    import cv2
    cap = cv2.VideoCapture(str(path))
    out = []
    while len(out) < limit:
        ok, img = cap.read()
        if not ok:
            break
        out.append(img)
    cap.release()
    return ping_pong(out, limit)


def ping_pong(frames: List, limit: int) -> List:
    """``frames`` forwards, then backwards without repeating the turning frame, and so on,
    until ``limit`` items: a short clip made longer with no cut in the motion."""
    if len(frames) < 2:
        return list(frames[:limit])
    out = list(frames)
    back = True
    while len(out) < limit:
        seq = frames[-2::-1] if back else frames[1:]
        out.extend(seq[:limit - len(out)])
        back = not back
    return out[:limit]


#: the detectors compared: label -> (factory keyword arguments of the multi-person detector,
#: or None for the single-person one)
DETECTORS = {'single': None, 'multi': {}, 'windows': {'whole_frame_min_height': 0.0},
             'coarse': {'search_min_person_fraction': 1.0},
             'cycle': {'search_where_changed': False}}


def measure(path: Path, limit: int) -> Dict[str, object]:
    """Both detectors on the clip's frames, alternating frame by frame."""
    from mocap_core.tracking import PersonTracker, TrackerParams

    from .detector import BlazePoseDetector
    from .multipose import BlazePoseMultiDetector

    frames = _frames(path, limit)
    dets = {k: BlazePoseDetector() if kw is None else BlazePoseMultiDetector(max_persons=4, **kw)
            for k, kw in DETECTORS.items()}
    names = list(dets)
    multi = dets['multi']
    tracker = PersonTracker(TrackerParams(max_persons=4))
    times = {k: [] for k in names}
    found = {k: Counter() for k in names}
    id_frames: Counter = Counter()
    try:
        for k, img in enumerate(frames):
            got = {}
            for j in range(len(names)):          # the order rotates frame by frame
                name = names[(k + j) % len(names)]
                t0 = time.perf_counter()
                got[name] = dets[name].detect(img)
                times[name].append(time.perf_counter() - t0)
                found[name][len(got[name])] += 1
            for p in tracker.update(got['multi'], k / 30.0):
                id_frames[p.id] += 1
    finally:
        for d in dets.values():
            d.close()
    h, w = frames[0].shape[:2] if frames else (0, 0)

    def ms(v, f):
        return 1e3 * float(f(v)) if v else float('nan')
    out = {'frames': len(frames), 'size': f'{w}x{h}'}
    for name in names:
        out[f'{name}_ms'] = ms(times[name], np.median)
        out[f'{name}_mean_ms'] = ms(times[name], np.mean)
        out[f'{name}_found'] = dict(sorted(found[name].items()))
    out.update({
        'ids': dict(sorted(id_frames.items())),
        'detections': multi.detections, 'windows_opened': multi.windows_opened,
        'whole_frame_switches': multi.whole_switches,
        'tracker': {'births': tracker.stats.births, 'reidentified': tracker.stats.reidentified,
                    'false_detections_ignored': tracker.stats.blips},
    })
    return out


def render(results: Dict[str, dict], limit: int) -> str:
    machine = f'{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs'
    lines = [
        '# Several people: the multi-person detector on real clips',
        '',
        f'`mocap bench multipose --frames {limit}` on {platform.node()} ({machine}), '
        f'{time.strftime("%Y-%m-%d")}. The detectors see the same decoded frames, '
        'taking turns frame by frame (the order rotating), one thread each. "single": '
        'BlazePose, one person (`max_persons 1`); "multi": the multi-person detector '
        '(`max_persons 4`, defaults); "windows": the same with windows only '
        '(`whole_frame_min_height 0`, no whole-image tracking of a lone person); "coarse": '
        'the defaults without the finer search squares for people far from the camera '
        '(`search_min_person_fraction 1`); "cycle": the defaults with the search keeping to '
        'its cycle of regions, not looking where the picture changed '
        '(`search_where_changed false`). Short clips are played forwards and backwards up '
        'to the frame count.',
        '',
        '## Time per frame',
        '',
        'Median and mean (ms); the mean includes the periodic search for new people and is what '
        'a live node spends. Ratios: multi / single.',
        '',
        '| clip | frames | size | ' + ' | '.join(f'{d} median' for d in DETECTORS) + ' | '
        + ' | '.join(f'{d} mean' for d in DETECTORS) + ' | ratio of medians | ratio of means |',
        '|---|---|---|' + '---|' * (2 * len(DETECTORS) + 2),
    ]

    def ratio(a, b):
        return a / b if b > 0 else float('nan')
    for name, r in results.items():
        lines.append(
            f"| {name} | {r['frames']} | {r['size']} | "
            + ' | '.join(f"{r[f'{d}_ms']:.1f}" for d in DETECTORS) + ' | '
            + ' | '.join(f"{r[f'{d}_mean_ms']:.1f}" for d in DETECTORS) + ' | '
            f"{ratio(r['multi_ms'], r['single_ms']):.2f} | "
            f"{ratio(r['multi_mean_ms'], r['single_mean_ms']):.2f} |")
    lines += ['', '## People found', '',
              '| clip | ' + ' | '.join(DETECTORS) + ' | ids of multi (frames each) | '
              'whole-image switches |', '|---|' + '---|' * (len(DETECTORS) + 2)]
    for name, r in results.items():
        cells = [', '.join(f'{k}: {v}' for k, v in r[f'{d}_found'].items())
                 for d in DETECTORS]
        ids = ', '.join(f'{k}: {v}' for k, v in r['ids'].items()) or 'none'
        lines.append(f"| {name} | {' | '.join(cells)} | {ids} | "
                     f"{r['whole_frame_switches']} |")
    lines += ['', ', '.join(f'"{d}"' for d in DETECTORS) + ': frames by number of people the '
              'detector returned. "ids": the tracker\'s ids over the multi-person detections '
              '(keypoint node defaults) and the frames each was published. "whole-image '
              'switches": times the multi-person detector took a lone person onto the whole '
              'image or back to a window.', '']
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
        times = ', '.join(f"{d} {r[f'{d}_ms']:.1f} / {r[f'{d}_mean_ms']:.1f} ms"
                          for d in DETECTORS)
        print(f"{name}: per frame median / mean: {times}; people (multi) "
              f"{r['multi_found']}; ids {r['ids']}")
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(render(results, args.frames))
    args.output.with_suffix('.json').write_text(json.dumps(results, indent=1))
    print(f'report: {args.output}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
