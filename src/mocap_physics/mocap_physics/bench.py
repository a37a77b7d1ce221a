"""Quick measurement of the physics time per frame (not a test).

    python -m mocap_physics.bench [--frames 600] [--substeps 6] [--root-residual 1.0]

Runs a synthetic standing motion with smooth random joint motion, root sway and frame jitter
(feet on the floor, contact probabilities flickering; the input is in the floor frame) through
the node's streaming logic (:class:`~mocap_physics.online.OnlinePhysics`) at 30 fps and prints
the median and 95th percentile of the cycle's time per frame (ms), with the time spent in the
two QP solvers, for the whole-body dynamics (OSQP and ProxQP) and the paper's cycle side by
side (``--configs``). Pin it to one core for comparable figures: ``taskset -c 0 python -m ...``.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Iterator, List, Optional, Tuple

import numpy as np

from mocap_core.pose import Pose
from mocap_core.rotations import axis_angle_to_quat
from mocap_core.skeleton import JOINT_INDEX, Skeleton

from .cycle_params import PhysicsParams
from .online import OnlinePhysics


def synthetic_motion(skeleton: Skeleton, n: int, fps: float, seed: int = 0
                     ) -> Iterator[Tuple[float, Pose, np.ndarray]]:
    """Standing motion with smooth random joint rotations and jitter, feet near the floor
    (floor frame): yields (time s, pose, contact probabilities (4,))."""
    rng = np.random.default_rng(seed)
    rest = Pose.rest(skeleton)
    t = np.arange(n) / fps
    freqs = rng.uniform(0.3, 2.0, size=(skeleton.num_joints, 3))
    phases = rng.uniform(0, 2 * np.pi, size=(skeleton.num_joints, 3))
    amp = np.full((skeleton.num_joints, 3), 0.25)
    amp[0] = 0.05
    for name in ('left_ankle', 'right_ankle', 'left_toe', 'right_toe'):
        amp[JOINT_INDEX[name]] = 0.05
    for k in range(n):
        aa = amp * np.sin(2 * np.pi * freqs * t[k] + phases) + 0.02 * rng.normal(size=amp.shape)
        root = (rest.root_position + 0.05 * np.sin(2 * np.pi * 0.7 * t[k] + np.arange(3))
                + 0.01 * rng.normal(size=3))
        probs = np.clip(0.9 + 0.2 * rng.normal(size=4), 0, 1)
        yield t[k], Pose(skeleton, axis_angle_to_quat(aa), root), probs


#: The configurations compared side by side (the same frames, interleaved frame by frame).
CONFIGS = {
    'whole_body': dict(dynamics='whole_body'),
    'whole_body_k4': dict(dynamics='whole_body', substeps=4),
    'whole_body_full_qp': dict(dynamics='whole_body', wbid_condensed=False),
    'whole_body_proxqp': dict(dynamics='whole_body', wbid_solver='proxqp'),
    'paper': dict(dynamics='paper'),
}


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(prog='mocap bench physics', description=__doc__.split('\n')[0])
    ap.add_argument('--frames', type=int, default=600)
    ap.add_argument('--fps', type=float, default=30.0)
    ap.add_argument('--substeps', type=int, default=None,
                    help="sub-steps of every configuration (default: each one's own, else the "
                         "node's default)")
    ap.add_argument('--root-residual', type=float, default=1.0)
    ap.add_argument('--configs', nargs='+', default=list(CONFIGS), choices=list(CONFIGS),
                    help='configurations, run side by side on the same frames (default all)')
    ap.add_argument('--json', action='store_true', help='print the figures as JSON')
    args = ap.parse_args(argv)
    sk = Skeleton.default()
    onlines = {}
    for name in args.configs:
        try:
            cfg = dict(CONFIGS[name])
            if args.substeps is not None:
                cfg['substeps'] = args.substeps
            onlines[name] = OnlinePhysics(PhysicsParams(root_residual=args.root_residual,
                                                        **cfg), skeleton=sk)
        except Exception as exc:  # noqa: BLE001 - e.g. proxsuite missing: skip that one
            print(f'{name}: skipped ({exc})', file=sys.stderr)
    times = {name: ([], [], []) for name in onlines}
    for t, pose, probs in synthetic_motion(sk, args.frames, args.fps):
        for name, online in onlines.items():
            out = online.step(int(round(t * 1e9)), pose, probabilities=probs, time_s=t)
            if out is None:
                continue
            r = out.result
            for lst, v in zip(times[name], (r.time_total, r.time_grf_qp,
                                            r.time_penetration_qp)):
                lst.append(v)
    results = {}
    for name, online in onlines.items():
        cyc = online.cycle
        total, grf, pen = (np.array(x[10:]) * 1e3 for x in times[name])  # skip warm-up
        results[name] = {
            'frames': int(total.size), 'substeps': online.cycle.params.substeps,
            'ms_per_frame_median': float(np.median(total)),
            'ms_per_frame_p95': float(np.percentile(total, 95)),
            'ms_per_frame_max': float(total.max()),
            'qp_ms_median': float(np.median(grf)),
            'penetration_qp_ms_median': float(np.median(pen)),
            'fallbacks': cyc.stats.fallbacks, 'qp_failures': cyc.stats.grf_failures,
            'penetration_solves': cyc.stats.penetration_solves,
        }
    base = results.get('whole_body')
    if args.json:
        print(json.dumps(results, indent=2))
        return 0
    print(f'physics per frame, {args.frames} frames, configurations interleaved frame by '
          'frame:')
    for name, o in results.items():
        ratio = (f", {o['ms_per_frame_median'] / base['ms_per_frame_median']:.2f}x whole_body"
                 if base and name != 'whole_body' else '')
        print(f"  {name:22s} k = {o['substeps']}: median {o['ms_per_frame_median']:.2f} ms, p95 "
              f"{o['ms_per_frame_p95']:.2f} ms, max {o['ms_per_frame_max']:.2f} ms{ratio}; "
              f"dynamics QP median {o['qp_ms_median']:.2f} ms, penetration QP median "
              f"{o['penetration_qp_ms_median']:.2f} ms; fallbacks {o['fallbacks']}, QP "
              f"failures {o['qp_failures']}")
    return 0


if __name__ == '__main__':
    sys.exit(main())
