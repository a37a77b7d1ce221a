"""``mocap bench``: benchmarks that print figures and write a report (never timed tests).

    mocap bench pipeline [--seconds 20] [--output docs/benchmarks/pipeline.md]
    mocap bench soak [--minutes 10] [--output docs/benchmarks/soak.md]
    mocap bench keypoints|lifter|physics|gmr [ARGS...]   (the per-node benchmarks)

``pipeline`` measures:

* **offline** (``mocap process`` in this process, keypoints -> world motion, on a committed
  ground-truth bag, ``--repeat`` passes): frames/s, median of the passes, and each node's
  processing time per frame (median, p95) from its final /diagnostics; each pass runs, in
  turn, the outputs built as rclpy messages (the baseline), serialised from arrays (the
  default) and the world motion alone (``--topics``), reported side by side as ratios;
* **live** (the four nodes as separate ``ros2 run`` processes, the keypoint node reading the
  shipped video in a loop, paced at 30 fps; a listener in this process): per stage the latency
  from the image stamp (the frame's capture time on this machine's clock) to the arrival of
  that frame's output, median and p95; the latency beyond the configured look-ahead (lifter
  window and output smoothing + GMR look-ahead frames); whether a queue grows (median
  latency of the last quarter minus the first, after a warm-up); output rate; CPU use
  (% of one core) and peak memory (VmHWM) of each node process. Two configurations: the
  defaults (windowed lifter, GMR look-ahead 15 frames) and the low-latency one (causal
  lifter, GMR look-ahead 0).

``soak`` feeds the lifter, physics and GMR processes a bag played in a loop (the stamps jump
back at every repetition: each node starts a new stream) for ``--minutes`` and fits the trend
of each node's resident memory after a warm-up (flat = no leak).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np

from .. import plugins, topics

ROOT = Path(__file__).resolve().parents[4]
STAGE_TOPICS = {'keypoints': topics.KEYPOINTS, 'lifter': topics.LIFTER_MOTION,
                'physics': topics.PHYSICS_MOTION, 'world': topics.WORLD_MOTION}



def _default_sigint() -> None:
    """Let the node processes the benchmark starts stop on SIGINT also when the benchmark
    itself runs where SIGINT is ignored (a background job of a script, nohup): an ignored
    signal stays ignored across ``exec``, a handled one is reset to the default there. Call
    once, before any child is started."""
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def _proc_stats(pid: int) -> Optional[Dict[str, float]]:
    """CPU seconds (user + system) and peak resident memory (MiB) of a live process."""
    try:
        stat = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
        ticks = os.sysconf('SC_CLK_TCK')
        cpu = (int(stat[11]) + int(stat[12])) / ticks
        hwm = next(int(line.split()[1]) for line in
                   Path(f'/proc/{pid}/status').read_text().splitlines()
                   if line.startswith('VmHWM'))
        return {'cpu_s': cpu, 'peak_mib': hwm / 1024}
    except (OSError, StopIteration, IndexError, ValueError):
        return None


def _rss_mib(pid: int) -> Optional[float]:
    """Current resident memory (MiB) of a live process."""
    try:
        return next(int(line.split()[1]) for line in
                    Path(f'/proc/{pid}/status').read_text().splitlines()
                    if line.startswith('VmRSS')) / 1024
    except (OSError, StopIteration, ValueError):
        return None


def _stop(procs) -> None:
    """SIGINT every process still running, wait up to 15 s each, then kill."""
    procs = list(procs)
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
    for p in procs:
        try:
            p.wait(15)
        except subprocess.TimeoutExpired:
            p.kill()


def _summary(values: List[float]) -> Dict[str, float]:
    if not values:
        return {'median': float('nan'), 'p95': float('nan'), 'n': 0}
    a = np.asarray(values)
    return {'median': float(np.median(a)), 'p95': float(np.percentile(a, 95)), 'n': len(a)}


def repeated_bag(bag: Path, out: Path, times: int, gap_s: float = 2.0) -> Path:
    """``bag``'s keypoints and camera info ``times`` times in a row, each repetition
    ``gap_s`` after the previous (a new take for every stage), as one bag."""
    from ..bag_io import BagReader, BagWriter
    from ..ros_msgs import deserialize, serialize

    names = [topics.KEYPOINTS, topics.CAMERA_INFO]
    with BagReader(bag) as reader:
        infos = {t: reader.topics[t] for t in names}
        msgs = list(reader.messages(topics=names))
    span = msgs[-1].timestamp_ns - msgs[0].timestamp_ns + int(gap_s * 1e9)
    with BagWriter(out, overwrite=True) as writer:
        for t, i in infos.items():
            writer.add_topic(t, i.msgtype, i.qos, msgdef=i.msgdef, type_hash=i.type_hash)
        for k in range(times):
            for m in msgs:
                msg = deserialize(m.data, m.msgtype)
                ns = m.timestamp_ns + k * span
                msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, 1_000_000_000)
                writer.write(m.topic, ns, serialize(msg))
    return out


#: Offline variants, run in turn in every pass: (key, description, --topics, messages built
#: as rclpy objects).
OFFLINE_VARIANTS = (
    ('built', 'every topic, messages built as rclpy objects and serialised by rclpy (as '
              'before the outputs were serialised from arrays)', None, True),
    ('arrays', 'every topic, serialised from arrays (`mocap_core.cdr`; the default)', None,
     False),
    ('world', '`--topics /mocap/world/motion`: the world motion only', ['/mocap/world/motion'],
     False),
)


def bench_offline(bag: Path, repeat: int, work: Path, times: int = 5) -> Dict:
    """``repeat`` passes; each pass runs every :data:`OFFLINE_VARIANTS` entry once, in turn,
    so that the variants see the same machine load."""
    import contextlib

    from .. import cdr
    from .process import process
    from ..run_report import load_run

    fps: Dict[str, List[float]] = {key: [] for key, *_ in OFFLINE_VARIANTS}
    per_node: Dict[str, list] = {}
    long_bag = repeated_bag(bag, work / 'offline_input', times)
    for k in range(repeat):
        for key, _, wanted, built in OFFLINE_VARIANTS:
            out = work / f'offline_{key}_{k}'
            with cdr.built_messages() if built else contextlib.nullcontext():
                s = process(long_bag, out, overwrite=True, progress=False,
                            log=lambda *a: None, log_level='error', topics_out=wanted)
            fps[key].append(s['fps'])
            if key == 'arrays':
                run = load_run(out)
                for name, d in run.diagnostics.items():
                    per_node.setdefault(name.split(':')[0], []).append(
                        (float(d['processing_ms_mean']), float(d['processing_ms_p95'])))
            print(f"  offline pass {k + 1}, {key}: {s['frames']} frames in "
                  f"{s['seconds']:.2f} s ({s['fps']:.1f} frames/s)", flush=True)
    return {'bag': str(bag.relative_to(ROOT) if bag.is_relative_to(ROOT) else bag),
            'times': times, 'frames': s['frames'], 'fps_passes': fps['arrays'],
            'fps_median': float(np.median(fps['arrays'])),
            'variants': {key: {'description': desc, 'fps_passes': fps[key],
                               'fps_median': float(np.median(fps[key]))}
                         for key, desc, *_ in OFFLINE_VARIANTS},
            'node_ms': {n: {'mean': float(np.median([v[0] for v in vals])),
                            'p95': float(np.median([v[1] for v in vals]))}
                        for n, vals in per_node.items()}}


def bench_video_offline(video: Path, repeat: int, work: Path) -> Dict:
    """``mocap process`` on ``video`` (keypoints from the detector -> world), ``repeat`` pairs:
    the detection beside the later stages (keypoint ``finish_thread``, the default) and one
    frame after the other, in turn (the first of a pair alternates)."""
    from .process import NODES, process

    fps: Dict[str, List[float]] = {'split': [], 'one': []}
    frames = 0
    for k in range(repeat):
        for key in (('split', 'one') if k % 2 == 0 else ('one', 'split')):
            params: Dict[str, Dict] = {n: {} for n in NODES}
            params['keypoints'] = {'finish_thread': key == 'split'}
            s = process(video, work / f'video_{key}_{k}', overwrite=True, progress=False,
                        log=lambda *a: None, log_level='error', params=params)
            fps[key].append(s['fps'])
            frames = s['frames']
            print(f"  video pass {k + 1}, {key}: {s['frames']} frames in {s['seconds']:.2f} s "
                  f"({s['fps']:.1f} frames/s)", flush=True)
    ratios = [a / b for a, b in zip(fps['split'], fps['one'])]
    return {'video': str(video.relative_to(ROOT) if video.is_relative_to(ROOT) else video),
            'frames': frames, 'fps': fps,
            'fps_median': {k: float(np.median(v)) for k, v in fps.items()},
            'ratio_passes': ratios, 'ratio_median': float(np.median(ratios))}


class _Listener:
    """Receive times of every stage's output, keyed by header stamp: ``samples[stage]`` is a
    list of (header stamp ns, arrival time ns), filled by a background thread."""

    def __init__(self, domain_id: int) -> None:
        from sensor_msgs.msg import PointCloud2
        from trajectory_msgs.msg import MultiDOFJointTrajectory

        from ..qos import SENSOR_QOS, STREAM_QOS
        from ..ros_peer import RosPeer

        def arrival(msg) -> tuple:
            return (msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec,
                    time.time_ns())

        self.peer = RosPeer('bench_listener', domain_id)
        self.samples: Dict[str, List[tuple]] = {
            stage: self.peer.subscribe(
                PointCloud2 if stage == 'keypoints' else MultiDOFJointTrajectory, topic,
                SENSOR_QOS if stage == 'keypoints' else STREAM_QOS, transform=arrival)
            for stage, topic in STAGE_TOPICS.items()}
        self.peer.spin_in_background()

    def close(self) -> None:
        self.peer.close()


def bench_live(config: Dict, seconds: float, video: Path, work: Path, env: Dict) -> Dict:
    ros2 = [sys.executable, '-m', 'mocap_core.cli.ros2', 'run']
    procs: Dict[str, subprocess.Popen] = {}
    logs: Dict[str, Path] = {}

    installed = plugins.nodes()

    def start(name: str, params: Dict[str, object]) -> None:
        plugin = installed[name]
        cmd = ros2 + [plugin.package, plugin.executable, '--ros-args']
        for k, v in params.items():
            cmd += ['-p', f'{k}:={v}']
        logs[name] = work / f"{config['name']}_{name}.log"
        with logs[name].open('wb') as f:
            procs[name] = subprocess.Popen(cmd, env=env, stdout=f, stderr=subprocess.STDOUT,
                                           stdin=subprocess.DEVNULL)

    def wait_for(name: str, text: str, timeout: float = 120) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if text in logs[name].read_text(errors='replace'):
                return
            if procs[name].poll() is not None:
                break
            time.sleep(0.1)
        raise RuntimeError(f'{name} did not start:\n{logs[name].read_text(errors="replace")}')

    listener = _Listener(int(env['ROS_DOMAIN_ID']))
    stats: Dict[str, Dict[str, float]] = {}
    cpu0: Dict[str, float] = {}
    try:
        if config.get('composed'):
            # the four nodes in one process (mocap run); the listener is the subscriber the
            # keypoint node waits for beside the lifter
            kp = {'realtime': True, 'fps': 30.0, 'wait_for_subscribers': 2,
                  **config.get('keypoints', {})}
            cmd = [sys.executable, '-m', 'mocap_core.cli.mocap', 'run', '--video', str(video),
                   '--loop', '--param', f"lifter.mode={config['lifter_mode']}",
                   '--param', f"gmr.lookahead={config['lookahead']}"]
            for k, v in kp.items():
                cmd += ['--param', f'keypoints.{k}={v}']
            for node in ('lifter', 'physics', 'gmr'):
                for k, v in config.get(node, {}).items():
                    cmd += ['--param', f'{node}.{k}={v}']
            logs['composed'] = work / f"{config['name']}_composed.log"
            with logs['composed'].open('wb') as f:
                procs['composed'] = subprocess.Popen(cmd, env=env, stdout=f,
                                                     stderr=subprocess.STDOUT,
                                                     stdin=subprocess.DEVNULL)
            wait_for('composed', 'detector')
        else:
            start('lifter', {'mode': config['lifter_mode'], **config.get('lifter', {})})
            start('physics', dict(config.get('physics', {})))
            start('gmr', {'lookahead': config['lookahead'], **config.get('gmr', {})})
            for name, text in (('lifter', 'lifter ready'), ('physics', 'physics on'),
                               ('gmr', 'gmr ready')):
                wait_for(name, text)
            time.sleep(3.0)                               # discovery between the processes
            start('keypoints', {'path': str(video), 'realtime': True,
                                'loop': True, 'fps': 30.0,
                                'wait_for_subscribers': 2, **config.get('keypoints', {})})
            wait_for('keypoints', 'detector')
        for name, p in procs.items():
            s = _proc_stats(p.pid)
            cpu0[name] = s['cpu_s'] if s else 0.0
        t0 = time.monotonic()
        while time.monotonic() - t0 < seconds:
            time.sleep(0.5)
            for name, p in procs.items():
                s = _proc_stats(p.pid)
                if s:
                    stats[name] = s
        elapsed = time.monotonic() - t0
        first = 'composed' if 'composed' in procs else 'keypoints'
        procs[first].send_signal(signal.SIGINT)
        try:
            procs[first].wait(15)
            stopped = True
        except subprocess.TimeoutExpired:     # reported, then killed by _stop
            stopped = False
            print(f'  warning: {first} did not stop within 15 s of SIGINT (killed; log '
                  f'{logs[first]})', flush=True)
        time.sleep(2.0)
    finally:
        _stop(procs.values())
        listener.close()
    # windowed: half the receptive field of the default weights (14) plus the radius of the
    # default output smoothing (ceil(2 sigma), sigma 2: mocap_lifter.output_smoothing)
    lifter_latency = 0 if config['lifter_mode'] == 'causal' else 14 + 4
    result = {'config': config, 'seconds': elapsed, 'stages': {}, 'nodes': {},
              'stopped_on_sigint': stopped,
              'lookahead_frames': lifter_latency + config['lookahead']}
    warm = 2.0
    for stage, samples in listener.samples.items():
        if not samples:
            result['stages'][stage] = {'frames': 0}
            continue
        stamps = np.array([s for s, _ in samples], dtype=np.int64)
        lat = (np.array([r for _, r in samples], dtype=np.int64) - stamps) * 1e-6
        keep = (stamps - stamps[0]) * 1e-9 > warm
        lat_k = lat[keep] if keep.sum() > 8 else lat
        q = max(len(lat_k) // 4, 1)
        span = (stamps[-1] - stamps[0]) * 1e-9
        result['stages'][stage] = {
            'frames': len(samples), 'rate_hz': (len(samples) - 1) / span if span > 0 else 0.0,
            'latency_ms': _summary(lat_k.tolist()),
            'latency_growth_ms': float(np.median(lat_k[-q:]) - np.median(lat_k[:q])),
        }
    # Look-ahead is counted in frames: at the rate the frames actually arrive (the keypoint
    # node drops frames its detector cannot keep up with) it lasts frames / rate.
    world = result['stages'].get('world', {})
    rate = result['stages'].get('keypoints', {}).get('rate_hz') or 30.0
    budget_s = result['lookahead_frames'] / rate
    result['lookahead_budget_ms'] = 1000 * budget_s
    if world.get('frames'):
        world['beyond_lookahead_ms'] = {k: world['latency_ms'][k] - 1000 * budget_s
                                        for k in ('median', 'p95')}
    for name, s in stats.items():
        result['nodes'][name] = {'cpu_percent': 100 * (s['cpu_s'] - cpu0.get(name, 0.0)) /
                                 max(elapsed, 1e-9), 'peak_mib': s['peak_mib']}
    return result


def cmd_soak(args: argparse.Namespace) -> int:
    """Lifter, physics and GMR (``ros2 run``) fed a bag played in a loop for ``--minutes``;
    resident memory of each node sampled every 2 s; the trend after a warm-up is fitted."""
    import random
    import tempfile

    _default_sigint()
    work = Path(tempfile.mkdtemp(prefix='mocap_soak_'))
    env = dict(os.environ)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env['ROS_DOMAIN_ID'] = env.get('ROS_DOMAIN_ID') or str(random.randint(1, 200))
    os.environ.update({k: env[k] for k in ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_DOMAIN_ID')})
    ros2 = [sys.executable, '-m', 'mocap_core.cli.ros2']
    procs: Dict[str, subprocess.Popen] = {}
    installed = plugins.nodes()
    for stage in ('lifter', 'physics', 'gmr'):
        pkg, exe = installed[stage].package, installed[stage].executable
        with (work / f'{exe}.log').open('wb') as f:
            procs[exe] = subprocess.Popen(ros2 + ['run', pkg, exe], env=env, stdout=f,
                                          stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    listener = _Listener(int(env['ROS_DOMAIN_ID']))
    samples: Dict[str, List[tuple]] = {n: [] for n in procs}
    try:
        time.sleep(15.0)
        with (work / 'play.log').open('wb') as f:
            player = subprocess.Popen(ros2 + ['bag', 'play', str(args.bag), '--loop',
                                              '--topics', topics.CAMERA_INFO,
                                              topics.KEYPOINTS], env=env, stdout=f,
                                      stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        t0 = time.monotonic()
        while time.monotonic() - t0 < args.minutes * 60:
            time.sleep(2.0)
            for n, p in procs.items():
                rss = _rss_mib(p.pid)
                if rss is not None:
                    samples[n].append((time.monotonic() - t0, rss))
        player.send_signal(signal.SIGINT)
        player.wait(15)
    finally:
        _stop(procs.values())
        listener.close()
    frames = len(listener.samples['world'])
    lines = ['# Soak run', '', f"{datetime.date.today().isoformat()}, commit `{_git_commit()}`: "
             f"`mocap bench soak --minutes {args.minutes:g}`; bag `{Path(args.bag).name}` "
             f'played in a loop into lifter, physics and GMR (`ros2 run`); {frames} world '
             'frames came out.', '',
             '| node | alive at the end | RSS after warm-up (MiB) | RSS at the end (MiB) | '
             'trend after warm-up (MiB/min) |', '|---|---|---|---|---|']
    result = {'minutes': args.minutes, 'world_frames': frames, 'nodes': {}}
    for n, vals in samples.items():
        t = np.array([v[0] for v in vals])
        m = np.array([v[1] for v in vals])
        keep = t > 0.2 * t.max() if len(t) else t.astype(bool)
        slope = float(np.polyfit(t[keep] / 60, m[keep], 1)[0]) if keep.sum() > 3 else \
            float('nan')
        alive = procs[n].returncode in (0, -2) or procs[n].returncode is None
        result['nodes'][n] = {'rss_start_mib': float(m[keep][0]) if keep.any() else None,
                              'rss_end_mib': float(m[-1]) if len(m) else None,
                              'trend_mib_per_min': slope}
        lines.append(f"| {n} | {'yes' if alive else 'no'} | "
                     f"{m[keep][0] if keep.any() else float('nan'):.0f} | "
                     f"{m[-1] if len(m) else float('nan'):.0f} | {slope:+.2f} |")
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text('\n'.join(lines) + '\n')
    out.with_suffix('.json').write_text(json.dumps(result, indent=1))
    print(out.read_text())
    return 0


def _git_commit() -> str:
    try:
        return subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], cwd=ROOT, text=True,
                              capture_output=True, timeout=10).stdout.strip() or 'unknown'
    except OSError:
        return 'unknown'


def write_report(res: Dict, out: Path) -> None:
    off = res.get('offline')
    lines = [
        '# Pipeline benchmark', '',
        f"Video of the live runs: `{res.get('video', '')}`.", '',
        f"{res['date']}, commit `{res['commit']}`, {res['machine']}. Command: "
        f"`{res.get('command', 'mocap bench pipeline')}` (see `mocap_core/cli/bench.py`).", '',
    ]
    if off is not None:
        lines += [
            '## Offline: `mocap process`, keypoints -> world motion', '',
            f"Bag `{off['bag']}` {off['times']} times in a row (a 2 s gap between the takes; "
            f"{off['frames']} frames), {len(off['fps_passes'])} passes: "
            f"**{off['fps_median']:.1f} frames/s** (median; passes: "
            + ', '.join(f'{v:.1f}' for v in off['fps_passes']) + '). Goal: >= 300 frames/s. '
            'Lifter and GMR run 16 frames per network pass offline (`chunk`).', '']
        variants = off.get('variants')
        if variants:
            base = variants['built']['fps_median']
            lines += ['Variants, run in turn in every pass (same machine load):', '',
                      '| variant | frames/s, median | passes | vs. built messages |',
                      '|---|---|---|---|']
            for v in variants.values():
                lines.append(f"| {v['description']} | {v['fps_median']:.1f} | "
                             + ', '.join(f'{x:.1f}' for x in v['fps_passes'])
                             + f" | {v['fps_median'] / base:.2f}x |")
            lines.append('')
        lines += ['Each node\'s processing time per input message (every topic, from arrays; '
                  'from its final /diagnostics; includes building and publishing its '
                  'outputs):', '',
                  '| node | mean (ms) | p95 (ms) |', '|---|---|---|']
        for n, v in sorted(off['node_ms'].items()):
            lines.append(f"| {n} | {v['mean']:.2f} | {v['p95']:.2f} |")
    vid = res.get('video_offline')
    if vid is not None:
        lines += [
            '', '## Offline from a video: `mocap process`, detector -> world motion', '',
            f"`{vid['video']}` ({vid['frames']} frames), {len(vid['ratio_passes'])} pairs of "
            'runs, in turn: the next frame detected while the last one is finished (camera '
            'motion) and published through the later stages in a second thread (keypoint '
            '`finish_thread`, the default), and one frame after the other.', '',
            '| run | frames/s, median | passes |', '|---|---|---|',
            f"| detection beside the later stages (default) | {vid['fps_median']['split']:.1f} "
            '| ' + ', '.join(f'{x:.1f}' for x in vid['fps']['split']) + ' |',
            f"| one frame after the other | {vid['fps_median']['one']:.1f} | "
            + ', '.join(f'{x:.1f}' for x in vid['fps']['one']) + ' |', '',
            f"Ratio, median of the pairs: **{vid['ratio_median']:.2f}x** ("
            + ', '.join(f'{x:.2f}' for x in vid['ratio_passes']) + ').']
    for live in res['live']:
        c = live['config']
        lines += ['', f"## Live, {c['name']}: lifter {c['lifter_mode']}, GMR look-ahead "
                  f"{c['lookahead']} frames", '',
                  ('The four nodes in one process (`mocap run`)' if c.get('composed') else
                   'Four `ros2 run` processes') + ', the video looped at 30 fps for '
                  f"{live['seconds']:.0f} s; latency = arrival time - image stamp, after a "
                  f"2 s warm-up. Look-ahead: {live['lookahead_frames']} frames = "
                  f"{live['lookahead_budget_ms']:.0f} ms at the rate the keypoints arrived. "
                  'rclpy executor: ' + c.get('env', {}).get('MOCAP_EXECUTOR', 'events') + '.',
                  '',
                  '| stage topic | frames | rate (Hz) | latency median (ms) | p95 (ms) | '
                  'growth last-first quarter (ms) |', '|---|---|---|---|---|---|']
        for stage, s in live['stages'].items():
            if not s.get('frames'):
                lines.append(f'| {STAGE_TOPICS[stage]} | 0 | | | | |')
                continue
            lines.append(f"| {STAGE_TOPICS[stage]} | {s['frames']} | {s['rate_hz']:.1f} | "
                         f"{s['latency_ms']['median']:.0f} | {s['latency_ms']['p95']:.0f} | "
                         f"{s['latency_growth_ms']:+.0f} |")
        w = live['stages'].get('world', {})
        if 'beyond_lookahead_ms' in w:
            lines += ['', f"End to end beyond the look-ahead: median "
                      f"**{w['beyond_lookahead_ms']['median']:.0f} ms**, p95 "
                      f"{w['beyond_lookahead_ms']['p95']:.0f} ms (goal <= 100 ms)."]
        lines += ['', '| node process | CPU (% of one core) | peak memory (MiB) |',
                  '|---|---|---|']
        for n, v in live['nodes'].items():
            lines.append(f"| {n} | {v['cpu_percent']:.0f} | {v['peak_mib']:.0f} |")
        stages3 = [live['nodes'][n]['cpu_percent'] for n in ('lifter', 'physics', 'gmr')
                   if n in live['nodes']]
        if len(stages3) == 3:
            lines.append(f'| lifter + physics + gmr (goal <= 60) | **{sum(stages3):.0f}** | |')
        if not live.get('stopped_on_sigint', True):
            lines += ['', '**The first process did not stop within 15 s of SIGINT** (it was '
                      'killed).']
    lines.append('')
    out.write_text('\n'.join(lines))


#: the module of each node's PARAMETERS (``--variant`` names are checked against them: rclpy
#: drops an override of an undeclared parameter without a word)
_NODE_MODULES = {'keypoints': 'mocap_keypoints.node', 'lifter': 'mocap_lifter.node',
                 'physics': 'mocap_physics.node', 'gmr': 'mocap_global.node'}


def cmd_pipeline(args: argparse.Namespace) -> int:
    import platform
    import random
    import shlex
    import tempfile

    variants = []        # {node: {name: value}} per variant
    for option, item in ([('--keypoints-variant', i) for i in args.keypoints_variant]
                         + [('--variant', i) for i in args.variant]):
        pairs = dict(kv.split('=', 1) for kv in item.split(',') if '=' in kv)
        if not pairs or len(pairs) != len(item.split(',')):
            print(f'mocap bench pipeline: error: {option} {item!r}: expected '
                  f"{'NODE.' if option == '--variant' else ''}NAME=VALUE[,...]",
                  file=sys.stderr)
            return 2
        if option == '--keypoints-variant':
            variants.append({'keypoints': pairs})
            continue
        nodes: Dict[str, Dict[str, str]] = {}
        for key, value in pairs.items():
            node, _, name = key.partition('.')
            if node not in _NODE_MODULES or not name:
                print(f'mocap bench pipeline: error: --variant {item!r}: expected '
                      'NODE.NAME=VALUE (NODE: keypoints, lifter, physics, gmr)',
                      file=sys.stderr)
                return 2
            nodes.setdefault(node, {})[name] = value
        for node, pairs in nodes.items():
            import difflib
            import importlib

            declared = [spec.name for spec in importlib.import_module(
                _NODE_MODULES[node]).PARAMETERS]
            for name in pairs:
                if name not in declared:
                    close = difflib.get_close_matches(name, declared, n=3)
                    print(f'mocap bench pipeline: error: --variant {item!r}: the {node} node '
                          f'has no parameter {name!r}'
                          + (f' (did you mean {", ".join(close)}?)' if close else ''),
                          file=sys.stderr)
                    return 2
        variants.append(nodes)
    _default_sigint()
    work = Path(tempfile.mkdtemp(prefix='mocap_bench_'))
    env = dict(os.environ)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env['ROS_DOMAIN_ID'] = env.get('ROS_DOMAIN_ID') or str(random.randint(1, 200))
    env['PYTHONUNBUFFERED'] = '1'
    os.environ.update({k: env[k] for k in ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_DOMAIN_ID')})
    res = {'date': datetime.date.today().isoformat(), 'commit': _git_commit(),
           'machine': f'{platform.machine()}, {os.cpu_count()} CPU cores (shared)'}
    res['video'] = str(args.video)
    if 'pipeline' in sys.argv:      # the options as given (reports say how they were made)
        res['command'] = ' '.join(['mocap bench pipeline'] + [
            shlex.quote(a) for a in sys.argv[sys.argv.index('pipeline') + 1:]])
    if args.repeat > 0:
        print('offline (mocap process) ...', flush=True)
        res['offline'] = bench_offline(Path(args.bag), args.repeat, work)
    if args.video_offline > 0:
        print('offline from the video (mocap process) ...', flush=True)
        res['video_offline'] = bench_video_offline(Path(args.video), args.video_offline, work)
    res['live'] = []
    configs = [{'name': 'defaults', 'lifter_mode': 'windowed', 'lookahead': 15},
               {'name': 'low latency', 'lifter_mode': 'causal', 'lookahead': 0}]
    configs = configs[:args.configs]
    if args.composed:
        # the same configurations with the four nodes in one process (mocap run)
        configs += [dict(c, name=c['name'] + ', composed (mocap run)', composed=True)
                    for c in configs]
    if args.single_person_baseline:
        # today's one-person keypoint stage beside the several-people default, same run
        configs.insert(0, {'name': 'defaults, max_persons 1 (single-person detector)',
                           'lifter_mode': 'windowed', 'lookahead': 15,
                           'keypoints': {'max_persons': 1}})
    for nodes in variants:
        # the live defaults with node parameters changed (e.g. keypoints mirror_check=true,
        # gmr inference=torch), after the others, same run
        configs.append({'name': 'defaults, ' + ', '.join(
            f'{node} ' + ', '.join(f'{k}={v}' for k, v in pairs.items())
            for node, pairs in nodes.items()), 'lifter_mode': 'windowed',
            'lookahead': 15, **nodes})
    if args.executor_baseline:
        # every node process with rclpy's SingleThreadedExecutor beside the default (the
        # events executor: mocap_core.executors), same run
        configs.insert(0, {'name': 'defaults, single-threaded executor (MOCAP_EXECUTOR='
                                   'single_threaded)', 'lifter_mode': 'windowed',
                           'lookahead': 15, 'env': {'MOCAP_EXECUTOR': 'single_threaded'}})
    for c in configs:
        print(f"live, {c['name']} ({args.seconds:.0f} s) ...", flush=True)
        res['live'].append(bench_live(c, args.seconds, Path(args.video), work,
                                      {**env, **c.get('env', {})}))
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_report(res, out)
    out.with_suffix('.json').write_text(json.dumps(res, indent=1, default=str))
    print(out.read_text())
    print(f'wrote {out} and {out.with_suffix(".json")}')
    return 0


def add_parser(sub) -> None:
    p = sub.add_parser('bench', help='benchmarks (print figures, write a report)')
    bench_sub = p.add_subparsers(dest='bench_command', metavar='BENCH')
    pp = bench_sub.add_parser('pipeline', help='offline throughput, live latency, CPU and '
                              'memory of the whole pipeline')
    pp.add_argument('--bag', default=str(ROOT / 'bags' / 'gt_cmu_walk_12_02'))
    pp.add_argument('--video', default=str(ROOT / 'data' / 'video_example' /
                                           'taiji_640x360.mp4'))
    pp.add_argument('--repeat', type=int, default=3, help='offline passes (0: none)')
    pp.add_argument('--video-offline', type=int, default=0, metavar='PAIRS',
                    help='also run mocap process on the video, PAIRS pairs of runs: the '
                    'detection beside the later stages (the default) and one frame after the '
                    'other, in turn (0: none)')
    pp.add_argument('--composed', action='store_true',
                    help='also run each live configuration as one process (mocap run), '
                    'after the separate processes, in the same run')
    pp.add_argument('--single-person-baseline', action='store_true',
                    help='also run the live defaults with the single-person keypoint stage '
                    '(max_persons 1), first, for a side-by-side comparison')
    pp.add_argument('--executor-baseline', action='store_true',
                    help='also run the live defaults with the single-threaded rclpy executor '
                    '(MOCAP_EXECUTOR=single_threaded), first, for a side-by-side comparison')
    pp.add_argument('--keypoints-variant', action='append', default=[],
                    metavar='NAME=VALUE[,NAME=VALUE]',
                    help='also run the live defaults with these keypoint-node parameters '
                    '(e.g. mirror_check=true), last, in the same run (repeatable)')
    pp.add_argument('--variant', action='append', default=[],
                    metavar='NODE.NAME=VALUE[,NODE.NAME=VALUE]',
                    help='also run the live defaults with these node parameters (NODE: '
                    'keypoints, lifter, physics, gmr; e.g. gmr.inference=torch), last, in '
                    'the same run (repeatable)')
    pp.add_argument('--seconds', type=float, default=20.0, help='live run per configuration')
    pp.add_argument('--configs', type=int, default=2, choices=(0, 1, 2),
                    help='live configurations to run (defaults, then low latency)')
    pp.add_argument('--output', default=str(ROOT / 'docs' / 'benchmarks' / 'pipeline.md'))
    pp.set_defaults(func=cmd_pipeline)
    from .bench_camera import add_parser as add_camera_motion
    add_camera_motion(bench_sub, ROOT)
    ps = bench_sub.add_parser('soak', help='nodes fed a looped bag for a while: memory trend')
    ps.add_argument('--bag', default=str(ROOT / 'bags' / 'gt_cmu_walk_12_02'))
    ps.add_argument('--minutes', type=float, default=10.0)
    ps.add_argument('--output', default=str(ROOT / 'docs' / 'benchmarks' / 'soak.md'))
    ps.set_defaults(func=cmd_soak)
    for name, ep in plugins.benches().items():
        pn = bench_sub.add_parser(name, help=f'the {name} benchmark ({ep.value})',
                                  add_help=False)
        pn.add_argument('rest', nargs=argparse.REMAINDER)
        pn.set_defaults(func=lambda a, n=name: plugins.run_bench(n, a.rest))
