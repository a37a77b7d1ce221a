"""Benchmark of the GMR window update (not a test): ``python -m mocap_global.bench``.

Feeds the ground-truth motion of a committed validation bag (default
``bags/gt_cmu_walk_12_02``, replayed ``--repeat`` times as one stream) frame by frame to
:class:`~mocap_global.online.OnlineGMR`, the node's algorithm, with the process pinned to one
CPU core and torch on one thread, and reports the time of each ``push`` (features, one GRU
pass over the window, accumulation; the ROS conversions are not included): median, p95 and
max, for the shipped weights (or, when they do not exist yet, a randomly initialised network
of the shipped size: the time does not depend on the weights) at several look-aheads and
window lengths, with and without the static-camera fusion and with test-time augmentation
(2 or 4 windows per pass), on both network engines (``inference``: NumPy, the default, and
PyTorch; each configuration's two engines run in turn, twice, in alternating order, and the
median of the runs' medians is reported with the ratio of the two). The goal and past
figures: ``docs/global.md``.

Writes a Markdown report (default ``docs/benchmarks/gmr.md``) and a JSON file next to it.
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
from typing import Dict, List, Optional

import numpy as np

ROOT = Path(__file__).resolve().parents[3]
BAG = ROOT / 'bags' / 'gt_cmu_walk_12_02'


def run(model, poses, stamps, lookahead: int, window: Optional[int], fusion: bool,
        warmup: int = 20, inference: str = 'numpy') -> Dict[str, float]:
    """Time per push (ms) over a stream."""
    from .online import OnlineGMR, StaticCameraFusion

    fu = StaticCameraFusion(model.cfg.fps) if fusion else None
    online = OnlineGMR(model, lookahead, window, max_gap_s=1e9, fusion=fu,
                       inference=inference)
    times = []
    for i, (s, p) in enumerate(zip(stamps, poses)):
        t = time.perf_counter()
        online.push(s, p)
        if i >= warmup:
            times.append(time.perf_counter() - t)
    ms = 1000 * np.asarray(times)
    return {'median_ms': float(np.median(ms)), 'p95_ms': float(np.percentile(ms, 95)),
            'max_ms': float(ms.max()), 'frames': len(ms)}


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(prog='mocap bench gmr', description=__doc__.split('\n\n')[0])
    ap.add_argument('--weights', type=Path, help='weights (default: the shipped gmr.pt)')
    ap.add_argument('--bag', type=Path, default=BAG)
    ap.add_argument('--repeat', type=int, default=3, help='times the bag is replayed')
    ap.add_argument('--output', type=Path, default=ROOT / 'docs' / 'benchmarks' / 'gmr.md')
    args = ap.parse_args(argv)

    import torch

    from mocap_core.data.gt_bag import read_groundtruth_bag
    from .model import GMR, GMRConfig, with_tta
    from .weights import default_weights, load_weights

    try:
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    except (AttributeError, OSError):
        pass
    torch.set_num_threads(1)
    path = args.weights or default_weights()
    if path.exists():
        model, source = load_weights(path), str(path)
    else:
        model = GMR(GMRConfig()).eval()
        source = f'randomly initialised (no weights at {path}), shipped size'
    b = read_groundtruth_bag(args.bag)
    n = len(b['poses'])
    dt = int(round(1e9 / model.cfg.fps))
    stamps = [b['stamps'][0] + i * dt for i in range(n * args.repeat)]
    poses = b['poses'] * args.repeat
    cfg = model.cfg
    rows = []
    for lookahead, window, fusion, tta in (
            (15, 48, False, 'none'), (0, 48, False, 'none'), (15, 48, True, 'none'),
            (15, 64, False, 'none'), (31, 64, False, 'none'), (15, 32, False, 'none'),
            (15, 48, False, 'mirror'), (15, 48, False, 'both')):
        net = with_tta(model, tta)
        # NumPy runs a plain network only (an augmented one falls back to PyTorch)
        engines = ('numpy', 'torch') if tta == 'none' else ('torch',)
        runs: Dict[str, list] = {e: [] for e in engines}
        for k in range(2):
            for engine in (engines if k % 2 == 0 else engines[::-1]):
                runs[engine].append(run(net, poses, stamps, lookahead, window, fusion,
                                        inference=engine))
        for engine in engines:
            r = {key: float(np.median([x[key] for x in runs[engine]]))
                 for key in ('median_ms', 'p95_ms', 'max_ms')}
            r.update({'frames': runs[engine][0]['frames'], 'lookahead': lookahead,
                      'window': window or cfg.window, 'fusion': fusion, 'tta': tta,
                      'inference': engine})
            if engine != 'torch':
                torch_median = float(np.median([x['median_ms'] for x in runs['torch']]))
                r['vs_torch'] = r['median_ms'] / torch_median
            rows.append(r)
            print(f"look-ahead {lookahead:2d}, window {r['window']:3d}, fusion {fusion!s:5s}, "
                  f"test-time augmentation {tta:6s}, {engine:5s}: median "
                  f"{r['median_ms']:.2f} ms, p95 {r['p95_ms']:.2f} ms, max "
                  f"{r['max_ms']:.2f} ms ({r['frames']} frames)", flush=True)
    res = {'date': datetime.datetime.now().strftime('%Y-%m-%d %H:%M'), 'weights': source,
           'model': f'{cfg.layers} x {cfg.hidden} bi-GRU, projection {cfg.projection}',
           'machine': f'{platform.machine()}, {os.cpu_count()} CPU cores, '
                      f'Python {platform.python_version()}, torch {torch.__version__}',
           'load_average': os.getloadavg()[0], 'bag': str(args.bag.name), 'rows': rows}
    lines = ['# GMR window update benchmark', '',
             f"`python -m mocap_global.bench` on {res['date']}: {res['machine']}, pinned to "
             f"one core, torch 1 thread, load average {res['load_average']:.2f}.", '',
             f"Model: {res['model']} ({source}); input: `{res['bag']}` ground-truth motion, "
             f'{args.repeat}x replayed as one stream. Time per frame of OnlineGMR.push (one '
             'GRU pass over the window + accumulation). The node\'s default: look-ahead 15, '
             'window 48, engine numpy. Each configuration\'s engines ran in turn, twice, in '
             'alternating order: medians of the two runs. Goal: <= 5 ms.', '',
             '| look-ahead | window | fusion | test-time augmentation | engine | median ms | '
             'vs. torch | p95 ms | max ms | frames |',
             '|---|---|---|---|---|---|---|---|---|---|']
    for r in rows:
        ratio = f"{r['vs_torch']:.2f}x" if 'vs_torch' in r else ''
        lines.append(f"| {r['lookahead']} | {r['window']} | {r['fusion']} | {r['tta']} | "
                     f"{r['inference']} | {r['median_ms']:.2f} | {ratio} | "
                     f"{r['p95_ms']:.2f} | {r['max_ms']:.2f} | {r['frames']} |")
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text('\n'.join(lines) + '\n')
    args.output.with_suffix('.json').write_text(json.dumps(res, indent=1))
    print('\n'.join(lines))
    print(f'report: {args.output}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
