"""Lifter benchmark (``python -m mocap_lifter.bench``): per-frame latency of the online lifter
(ring buffer + network, as the node runs it) and offline throughput of one pass over a whole
clip, for MotioNet (windowed, causal) and VTM (windowed), on the shipped weights, with real
keypoints from a committed bag. Prints the figures and writes a Markdown report (default
``docs/benchmarks/lifter.md``)."""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np
import torch

from .features import lifter_features
from .online import OnlineLifter
from .weights import default_weights, load_weights

ROOT = Path(__file__).resolve().parents[3]


def _keypoints(bag: Path):
    from mocap_core import topics
    from mocap_core.bag_io import BagReader, deserialize
    from mocap_core.ros_conversions import camera_info_to_intrinsics, cloud_to_keypoints
    kp, intr = [], None
    with BagReader(bag) as reader:
        for m in reader.messages(topics=[topics.KEYPOINTS, topics.CAMERA_INFO]):
            msg = deserialize(m.data, m.msgtype)
            if m.topic == topics.CAMERA_INFO:
                intr = camera_info_to_intrinsics(msg)
            else:
                kp.append(cloud_to_keypoints(msg)[0])
    return np.stack(kp), intr


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog='mocap bench lifter', description=__doc__)
    ap.add_argument('--bag', default=str(ROOT / 'bags' / 'gt_bandai_walk_exhausted'))
    ap.add_argument('--threads', type=int, default=1)
    ap.add_argument('--repeat', type=int, default=3, help='passes over the clip')
    ap.add_argument('--output', default=str(ROOT / 'docs' / 'benchmarks' / 'lifter.md'))
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    kp, intr = _keypoints(Path(args.bag))
    rows = []
    for arch, mode in (('motionet', 'windowed'), ('motionet', 'causal'), ('vtm', 'windowed')):
        path = default_weights(mode, arch)
        if not path.exists():
            print(f'{arch} {mode}: no weights ({path}), skipped')
            continue
        model = load_weights(path)
        lat = []
        for _ in range(args.repeat):
            online = OnlineLifter(model, mode)
            for i, k in enumerate(kp):
                t = time.perf_counter()
                online.push(1 + i * 33_333_333, k, intr)
                lat.append(time.perf_counter() - t)
        feats, root, scale, _ = lifter_features(kp, intr)
        x = torch.as_tensor(feats[None])
        r = torch.as_tensor(root[None]).float()
        s = torch.as_tensor(scale[None]).float()
        with torch.no_grad():
            model(x, r, s)
            t = time.perf_counter()
            for _ in range(args.repeat):
                model(x, r, s)
            offline = args.repeat * len(kp) / (time.perf_counter() - t)
        lat_ms = 1000 * np.asarray(lat[len(kp):] if args.repeat > 1 else lat)
        rows.append((f'{arch} {mode}', float(np.median(lat_ms)),
                     float(np.percentile(lat_ms, 95)), offline, online.latency))
        print(f'{arch:8s} {mode:9s} online per frame: median {rows[-1][1]:.2f} ms, '
              f'p95 {rows[-1][2]:.2f}'
              f' ms; offline {offline:.0f} frames/s; look-ahead {online.latency} frames')
    lines = ['# Lifter benchmark', '',
             f'`python -m mocap_lifter.bench --threads {args.threads}` on {platform.machine()}, '
             f'{torch.get_num_threads()} torch thread(s), {len(kp)} real keypoint frames of '
             f'`{Path(args.bag).name}`, {args.repeat} passes (the first pass is warm-up for the '
             'online figures). Medians and 95th percentiles; the machine is shared.', '',
             '| model, mode | online per frame (ring buffer + network), median | p95 | '
             'offline: network + FK, one pass per clip | '
             'look-ahead |', '|---|---|---|---|---|']
    lines += [f'| {m} | {a:.2f} ms | {b:.2f} ms | {c:.0f} frames/s | {d} frames |'
              for m, a, b, c, d in rows]
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text('\n'.join(lines) + '\n')
    print(f'report: {out}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
