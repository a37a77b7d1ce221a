#!/usr/bin/env python3
"""Offline speed of the working tree against another commit, side by side.

    scripts/bench_commits.py REV [--pairs 5] [--topics all|/mocap/world/motion]

``mocap process`` on the benchmark's input of ``mocap bench pipeline`` (the CMU walk bag five
times in a row, 840 frames), once with the code of commit ``REV`` and once with the working
tree, in turn, ``--pairs`` times (each run in a fresh process, after a warm-up pass of the
same process). The code of ``REV`` is a git worktree under ``~/.cache/mocap/bench_commits/``
put first on ``PYTHONPATH`` (the packages are pure Python; the built workspace's message
packages and the package data, e.g. the shipped weights, are the working tree's). Prints
frames/s, process CPU per frame and each node's mean time per message for every run, then the
median of the per-pair ratios: on a shared machine whose speed changes from minute to minute,
a ratio within a pair is what can be compared.
Run from the repository root after ``source env.sh``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ('mocap_core', 'mocap_lifter', 'mocap_physics', 'mocap_global', 'mocap_keypoints')

#: one measured run (after a warm-up run): prints a JSON line
RUN = r'''
import json, sys, time
from pathlib import Path
from mocap_core.cli.bench import repeated_bag
from mocap_core.cli.process import process
from mocap_core.run_report import load_run
work = Path(sys.argv[1]); work.mkdir(parents=True, exist_ok=True)
bag = repeated_bag(Path(sys.argv[2]), work / 'input', 5)
topics = None if sys.argv[3] == 'all' else [sys.argv[3]]
kw = dict(overwrite=True, progress=False, log=lambda *a: None, log_level='error',
          topics_out=topics)
process(bag, work / 'warm', **kw)
c0 = time.process_time()
s = process(bag, work / 'out', **kw)
cpu = time.process_time() - c0
nodes = {n.split(':')[0]: float(d['processing_ms_mean'])
         for n, d in load_run(work / 'out').diagnostics.items()}
print(json.dumps({'fps': s['fps'], 'cpu_ms': 1e3 * cpu / s['frames'], 'nodes': nodes}))
'''


def worktree(rev: str) -> Path:
    sha = subprocess.run(['git', 'rev-parse', rev], cwd=ROOT, check=True, text=True,
                         capture_output=True).stdout.strip()
    path = Path.home() / '.cache' / 'mocap' / 'bench_commits' / sha[:12]
    if not path.exists():
        subprocess.run(['git', 'worktree', 'prune'], cwd=ROOT, check=True)
        subprocess.run(['git', 'worktree', 'add', '--detach', str(path), sha], cwd=ROOT,
                       check=True)
    return path


def run(src_root: Path, topics: str, work: Path) -> dict:
    env = dict(os.environ)
    paths = [str(src_root / 'ros2_ws' / 'src' / p) for p in PACKAGES]
    env['PYTHONPATH'] = os.pathsep.join(paths + [env.get('PYTHONPATH', '')])
    out = subprocess.run([sys.executable, '-c', RUN, str(work),
                          str(ROOT / 'bags' / 'gt_cmu_walk_12_02'), topics],
                         env=env, text=True, capture_output=True)
    if out.returncode != 0:
        raise SystemExit(f'the run with the code of {src_root} failed:\n{out.stderr}')
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('rev', help='the commit to compare the working tree with')
    ap.add_argument('--pairs', type=int, default=5)
    ap.add_argument('--topics', default='all',
                    help="'all' (every output, the default) or one topic")
    args = ap.parse_args()
    other = worktree(args.rev)
    work = Path.home() / '.cache' / 'mocap' / 'bench_commits' / 'work'
    ratios, cpu_ratios = [], []
    for k in range(args.pairs):
        a = run(other, args.topics, work / 'a')
        b = run(ROOT, args.topics, work / 'b')
        ratios.append(b['fps'] / a['fps'])
        cpu_ratios.append(b['cpu_ms'] / a['cpu_ms'])
        for name, r in ((args.rev, a), ('working tree', b)):
            nodes = ', '.join(f'{n} {v:.2f}' for n, v in sorted(r['nodes'].items()))
            print(f"pair {k + 1} {name:>14s}: {r['fps']:6.1f} frames/s, CPU "
                  f"{r['cpu_ms']:5.2f} ms/frame" + (f'; ms per message: {nodes}' if nodes
                                                    else ''), flush=True)
    print(f'working tree / {args.rev}: frames/s x{statistics.median(ratios):.2f} '
          f"(pairs {', '.join(f'{r:.2f}' for r in ratios)}); CPU per frame "
          f'x{statistics.median(cpu_ratios):.2f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
