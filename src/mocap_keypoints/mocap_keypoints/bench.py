"""Benchmark of the keypoint node (not a test): ``python -m mocap_keypoints.bench``.

Measures on this machine, on a 640x480 stream made from the committed clip
(``data/video_example/taiji_640x360.mp4`` letterboxed to 640x480):

1. **Detector time per frame** (BlazePose full, MediaPipe 0.10.14): median, p95 and max
   over the frames, in video (tracking) mode and in static mode, with the process pinned to
   one CPU core and with all cores.
2. **Sustained node throughput**: ``ros2 run mocap_keypoints keypoints`` (source ``topic``)
   in its own process, fed 640x480 ``sensor_msgs/Image`` frames at a fixed rate by this
   process for ``--seconds``; reports the output rate, the frames the node dropped (its
   ``/diagnostics``), frames lost in transport, and the latency from the image stamp to the
   arrival of its keypoints (which includes one detector run plus any queueing). Also the
   video source played as fast as possible (no drops): the most frames per second the node
   sustains.

Writes a Markdown report (default ``docs/benchmarks/keypoints.md``) and prints it.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np

from mocap_core import topics

ROOT = Path(__file__).resolve().parents[3]
CLIP = ROOT / 'data' / 'video_example' / 'taiji_640x360.mp4'
WIDTH, HEIGHT = 640, 480


def _frames_640x480(n: int) -> List[np.ndarray]:
    """``n`` frames of the clip (played forward and back), letterboxed to 640x480."""
    import cv2

    from .sources import VideoSource

    with VideoSource(CLIP) as src:
        clip = [f.image for f in src]
    seq = clip + clip[::-1]
    out = []
    for i in range(n):
        img = seq[i % len(seq)]
        pad = (HEIGHT - img.shape[0]) // 2
        out.append(cv2.copyMakeBorder(img, pad, HEIGHT - img.shape[0] - pad, 0, 0,
                                      cv2.BORDER_CONSTANT, value=(0, 0, 0)))
    return out


def _stats(seconds: List[float]) -> Dict[str, float]:
    v = np.asarray(seconds, dtype=np.float64) * 1e3
    return {'median_ms': float(np.median(v)), 'p95_ms': float(np.percentile(v, 95)),
            'max_ms': float(v.max()), 'mean_ms': float(v.mean()), 'n': int(v.size)}


def _pin(cores: Optional[List[int]]):
    if not cores:
        return None
    return lambda: os.sched_setaffinity(0, set(cores))


# --- 1. detector alone (run in a child process so the affinity covers MediaPipe's threads) ---
def detector_child(frames: int, tracking: bool) -> Dict[str, float]:
    from .detector import BlazePoseDetector

    imgs = _frames_640x480(frames + 10)
    times = []
    with BlazePoseDetector(tracking=tracking) as det:
        for k, img in enumerate(imgs):
            t0 = time.perf_counter()
            det.detect(img)
            if k >= 10:  # warm-up excluded
                times.append(time.perf_counter() - t0)
    return _stats(times)


def run_detector(frames: int, tracking: bool, cores: Optional[List[int]]) -> Dict[str, float]:
    cmd = [sys.executable, '-m', 'mocap_keypoints.bench', '--_detector-child', str(frames),
           '--tracking' if tracking else '--static']
    out = subprocess.run(cmd, capture_output=True, text=True, preexec_fn=_pin(cores),
                         check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


# --- 2. the node in its own process ---------------------------------------------------------
class _Observer:
    """rclpy node of the benchmark: publishes images, collects keypoints and diagnostics."""

    def __init__(self) -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import Image, PointCloud2

        self.rclpy = rclpy
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('keypoints_bench', context=self.context)
        self.executor = rclpy.executors.SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.arrivals: List[tuple] = []
        self.diag: Dict[str, str] = {}
        self.node.create_subscription(
            PointCloud2, topics.KEYPOINTS,
            lambda m: self.arrivals.append((time.time_ns(), m.header.stamp.sec * 10**9
                                            + m.header.stamp.nanosec)),
            QoSProfile(depth=500, reliability=ReliabilityPolicy.BEST_EFFORT))
        self.node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, self._on_diag, 10)
        self.pub = self.node.create_publisher(Image, topics.IMAGE, 2)

    def _on_diag(self, msg) -> None:
        for st in msg.status:
            if 'keypoints' in st.name:
                self.diag = {kv.key: kv.value for kv in st.values}

    def spin(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=min(0.01, max(0.0, end - time.monotonic())))

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.rclpy.shutdown(context=self.context)


def _node_cmd(*params: str) -> List[str]:
    cmd = [sys.executable, '-m', 'mocap_core.cli.ros2', 'run', 'mocap_keypoints', 'keypoints',
           '--ros-args']
    for p in params:
        cmd += ['-p', p]
    return cmd


def _env() -> Dict[str, str]:
    """Environment of the node: this process's (same domain; see main)."""
    env = dict(os.environ)
    env['MOCAP_ROS2_NO_DEFER'] = '1'
    return env


def run_topic_stream(obs: _Observer, rate: float, seconds: float,
                     node_cores: Optional[List[int]], log_dir: Path, label: str) -> Dict:
    """The node on /camera/image_raw fed at ``rate`` Hz for ``seconds``."""
    import array

    from mocap_core.ros_conversions import bgr_to_image, make_header

    frames = _frames_640x480(int(rate * 2))
    msgs = [bgr_to_image(f, make_header(0, 'camera_optical_frame')) for f in frames]
    for m in msgs:  # keep the bytes, only the stamp changes per frame
        m.data = array.array('B', bytes(m.data))
    log = (log_dir / f'{label}.log').open('wb')
    proc = subprocess.Popen(_node_cmd('source:=topic'), stdout=log, stderr=subprocess.STDOUT,
                            env=_env(), preexec_fn=_pin(node_cores))
    try:
        deadline = time.monotonic() + 60
        while obs.pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            obs.spin(0.05)
        if obs.pub.get_subscription_count() == 0:
            raise RuntimeError(f'the node did not subscribe; see {log.name}')
        # Warm up (MediaPipe graph start, QoS choice, discovery both ways) for 2 s.
        period = 1.0 / rate
        k = 0
        t_next = time.monotonic()
        warm_end = t_next + 2.0
        while time.monotonic() < warm_end:
            m = msgs[k % len(msgs)]
            m.header.stamp.sec, m.header.stamp.nanosec = divmod(time.time_ns(), 10**9)
            obs.pub.publish(m)
            k += 1
            t_next += period
            obs.spin(max(0.0, t_next - time.monotonic()))
        obs.spin(0.5)
        obs.arrivals.clear()
        sent: List[int] = []
        t_start = time.monotonic()
        t_next = t_start
        while time.monotonic() < t_start + seconds:
            m = msgs[k % len(msgs)]
            stamp = time.time_ns()
            m.header.stamp.sec, m.header.stamp.nanosec = divmod(stamp, 10**9)
            obs.pub.publish(m)
            sent.append(stamp)
            k += 1
            t_next += period
            obs.spin(max(0.0, t_next - time.monotonic()))
        obs.diag = {}
        obs.spin(1.5)  # last results and a /diagnostics message from after the stream
        diag1 = dict(obs.diag)
        total_sent = k
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
        log.close()
    sent_set = set(sent)
    got = [(t, s) for t, s in obs.arrivals if s in sent_set]
    latency = [(t - s) * 1e-9 for t, s in got]
    span = (sent[-1] - sent[0]) * 1e-9
    out_rate = (len(got) - 1) / ((got[-1][1] - got[0][1]) * 1e-9) if len(got) > 1 else 0.0

    def _int(d, key):
        try:
            return int(d.get(key, 0))
        except ValueError:
            return 0

    return {
        'label': label, 'rate_hz': rate, 'seconds': span, 'sent': len(sent),
        'published': len(got), 'output_hz': out_rate, 'missing': len(sent) - len(got),
        'run_sent': total_sent, 'run_received_by_node': _int(diag1, 'frames_in'),
        'run_dropped_by_node': _int(diag1, 'frames_dropped'),
        'latency': _stats(latency) if latency else {},
        'node_detector_ms_median': diag1.get('detector_ms_median', 'nan'),
        'node_detector_ms_p95': diag1.get('detector_ms_p95', 'nan'),
        'node_cores': '1' if node_cores else 'all',
    }


def run_video_max(obs: _Observer, frames: int, node_cores: Optional[List[int]],
                  log_dir: Path, label: str) -> Dict:
    """The node on a 640x480 video file, as fast as possible (no drops)."""
    import cv2

    path = log_dir / 'stream_640x480.avi'
    if not path.exists():
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*'MJPG'), 30.0,
                                 (WIDTH, HEIGHT))
        for f in _frames_640x480(frames):
            writer.write(f)
        writer.release()
    obs.arrivals.clear()
    log = (log_dir / f'{label}.log').open('wb')
    proc = subprocess.Popen(_node_cmd('source:=video', f'path:={path}', 'realtime:=false',
                                      'wait_for_subscribers:=1', 'wait_timeout_s:=60.0'),
                            stdout=log, stderr=subprocess.STDOUT, env=_env(),
                            preexec_fn=_pin(node_cores))
    try:
        deadline = time.monotonic() + 120
        while proc.poll() is None and time.monotonic() < deadline:
            obs.spin(0.05)
        obs.spin(0.5)
    finally:
        if proc.poll() is None:
            proc.kill()
        log.close()
    t = np.array([a for a, _ in obs.arrivals], dtype=np.float64) * 1e-9
    # Steady state: skip the first 10 frames (graph start-up).
    steady = t[10:]
    rate = (len(steady) - 1) / (steady[-1] - steady[0]) if len(steady) > 1 else 0.0
    return {'label': label, 'frames': frames, 'published': len(obs.arrivals),
            'fps': rate, 'node_cores': '1' if node_cores else 'all'}


# --- report ---------------------------------------------------------------------------------
def _cpu_model() -> str:
    try:
        for line in Path('/proc/cpuinfo').read_text().splitlines():
            if line.startswith('model name'):
                return line.split(':', 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or 'unknown'


def render(results: Dict) -> str:
    import mediapipe

    lines = ['# Keypoint node benchmark', '',
             f"Generated by `python -m mocap_keypoints.bench` on {results['date']}.", '',
             f"Machine: {_cpu_model()}, {os.cpu_count()} logical cores visible; Python "
             f"{platform.python_version()}, MediaPipe {mediapipe.__version__} (BlazePose full), "
             f"input 640x480 BGR frames from `data/video_example/taiji_640x360.mp4` "
             f"(letterboxed). Times are wall-clock; the machine may be shared, so expect "
             f"noise of 10-20 %. Load average (1 min) before / after the run: "
             f"{results['load'][0]:.2f} / {results['load'][1]:.2f}.", '',
             '## Detector time per frame', '',
             '| mode | cores | median ms | p95 ms | max ms | frames |',
             '|---|---|---|---|---|---|']
    for d in results['detector']:
        s = d['stats']
        lines.append(f"| {d['mode']} | {d['cores']} | {s['median_ms']:.1f} | {s['p95_ms']:.1f} "
                     f"| {s['max_ms']:.1f} | {s['n']} |")
    lines += ['', 'tracking = MediaPipe video mode (the node\'s default); static = person '
              'detector on every frame (`tracking:=false`).', '',
              '## Sustained node throughput: 640x480 `sensor_msgs/Image` stream', '',
              'The node (`source:=topic`) runs in its own process; this benchmark publishes '
              'the frames (reliable, stamped with the wall clock) and measures the keypoint '
              'messages coming back, after a 2 s warm-up. Latency = arrival of the keypoints '
              '- image stamp (transport both ways + waiting + one detector run). "Without '
              'keypoints" = frames of the measured window that never came back. The node\'s '
              'own counters (from its `/diagnostics`, whole run including the warm-up): '
              'frames it received, and frames it dropped because a newer one replaced them '
              'in its one-frame slot.', '',
              '| node cores | input Hz | seconds | frames sent | keypoint msgs | without '
              'keypoints | output Hz | latency median ms | latency p95 ms | latency max ms | '
              'node detector median / p95 ms | whole run: sent / received by node / dropped '
              'by node |', '|---|---|---|---|---|---|---|---|---|---|---|---|']
    for r in results['topic']:
        lat = r['latency']
        lines.append(
            f"| {r['node_cores']} | {r['rate_hz']:g} | {r['seconds']:.1f} | {r['sent']} | "
            f"{r['published']} | {r['missing']} | {r['output_hz']:.1f} | "
            f"{lat.get('median_ms', float('nan')):.1f} | {lat.get('p95_ms', float('nan')):.1f} "
            f"| {lat.get('max_ms', float('nan')):.1f} | {r['node_detector_ms_median']} / "
            f"{r['node_detector_ms_p95']} | {r['run_sent']} / {r['run_received_by_node']} / "
            f"{r['run_dropped_by_node']} |")
    lines += ['', '## Most frames per second: video file as fast as possible (no drops)', '',
              '| node cores | frames | keypoint msgs | sustained fps |', '|---|---|---|---|']
    for r in results['video']:
        lines.append(f"| {r['node_cores']} | {r['frames']} | {r['published']} | "
                     f"{r['fps']:.1f} |")
    lines += ['', '## Reading', '', results['summary'], '']
    return '\n'.join(lines)


def summarise(results: Dict) -> str:
    det1 = next(d for d in results['detector'] if d['mode'] == 'tracking' and d['cores'] == '1')
    t30 = [r for r in results['topic'] if r['rate_hz'] == 30.0 and r['node_cores'] == '1']
    parts = [f"On one core BlazePose full takes {det1['stats']['median_ms']:.1f} ms per "
             f"640x480 frame (median; p95 {det1['stats']['p95_ms']:.1f} ms), i.e. up to "
             f"{1000.0 / det1['stats']['median_ms']:.0f} frames per second of detector time."]
    if t30:
        r = t30[0]
        period = 1000.0 / r['rate_hz']
        try:  # the node's own detector p95 during this run, else the standalone one
            det_p95 = float(r['node_detector_ms_p95'])
        except ValueError:
            det_p95 = det1['stats']['p95_ms']
        q = r['latency'].get('p95_ms', float('nan')) - det_p95
        parts.append(
            f"Pinned to one core and fed 30 fps, the node published {r['output_hz']:.1f} "
            f"keypoint messages per second ({r['missing']} of {r['sent']} frames without "
            f"keypoints), with latency p95 "
            f"{r['latency'].get('p95_ms', float('nan')):.1f} ms: "
            f"{q:.1f} ms above the node's detector p95 ({det_p95:.1f} ms), "
            f"{'within' if q <= period else 'more than'} one frame period ({period:.1f} ms).")
    fast = [r for r in results['topic'] if r['rate_hz'] > 30.0 and r['node_cores'] == '1']
    if fast:
        r = fast[0]
        parts.append(
            f"Fed {r['rate_hz']:g} fps on one core, it published {r['output_hz']:.1f} per "
            f"second and dropped the rest ({r['run_dropped_by_node']} in its one-frame slot "
            f"over the run), with latency p95 {r['latency'].get('p95_ms', float('nan')):.1f} "
            f"ms: no queue builds up.")
    vid = [r for r in results['video'] if r['node_cores'] == '1']
    if vid:
        parts.append(f"Its ceiling on one core (video file, no drops) is "
                     f"{vid[0]['fps']:.1f} fps.")
    return ' '.join(parts)


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(prog='mocap bench keypoints',
                                 description=__doc__.split('\n\n')[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--frames', type=int, default=200, help='frames per detector run')
    ap.add_argument('--seconds', type=float, default=10.0, help='length of each stream')
    ap.add_argument('--rates', type=float, nargs='+', default=[30.0, 60.0],
                    help='input rates of the image stream (Hz)')
    ap.add_argument('--output', type=Path, default=ROOT / 'docs' / 'benchmarks' / 'keypoints.md')
    ap.add_argument('--json', type=Path, default=None, help='also write the raw figures')
    ap.add_argument('--skip-node', action='store_true', help='detector timings only')
    ap.add_argument('--_detector-child', type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument('--tracking', action='store_true', help=argparse.SUPPRESS)
    ap.add_argument('--static', action='store_true', help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args._detector_child is not None:
        print(json.dumps(detector_child(args._detector_child, tracking=not args.static)))
        return 0

    # The node and this process meet on one domain, kept on this machine.
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    os.environ.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))
    ncores = len(os.sched_getaffinity(0))
    one = [sorted(os.sched_getaffinity(0))[0]]
    other = [c for c in sorted(os.sched_getaffinity(0)) if c not in one]
    results: Dict = {'date': datetime.datetime.now().strftime('%Y-%m-%d %H:%M'),
                     'detector': [], 'topic': [], 'video': [], 'load': [os.getloadavg()[0]]}
    for tracking in (True, False):
        for cores in (one, None):
            label = 'tracking' if tracking else 'static'
            print(f'[bench] detector {label}, cores {cores or "all"} ...', flush=True)
            st = run_detector(args.frames, tracking, cores)
            results['detector'].append({'mode': label, 'cores': '1' if cores else str(ncores),
                                        'stats': st})
    if not args.skip_node:
        if other:  # the benchmark's own publisher stays off the node's core
            os.sched_setaffinity(0, set(other))
        obs = _Observer()
        try:
            with tempfile.TemporaryDirectory(prefix='kp_bench_') as tmp:
                log_dir = Path(tmp)
                for rate in args.rates:
                    for cores in ((one, None) if rate == args.rates[0] else (one,)):
                        label = f'topic_{rate:g}hz_{"1core" if cores else "all"}'
                        print(f'[bench] node, {label} ...', flush=True)
                        results['topic'].append(run_topic_stream(
                            obs, rate, args.seconds, cores, log_dir, label))
                for cores in (one, None):
                    label = f'video_max_{"1core" if cores else "all"}'
                    print(f'[bench] node, {label} ...', flush=True)
                    results['video'].append(run_video_max(obs, 300, cores, log_dir, label))
        finally:
            obs.close()
    results['load'].append(os.getloadavg()[0])
    results['summary'] = summarise(results) if results['topic'] else ''
    text = render(results)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(text)
    if args.json:
        args.json.write_text(json.dumps(results, indent=1, default=str))
    print(text)
    print(f'[bench] report written to {args.output}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
