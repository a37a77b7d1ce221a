"""Several-people benchmark (``mocap bench people``): identities, per-person accuracy and
time per frame by number of people, on the synthetic multi-person scenes
(:mod:`mocap_core.data.multi_person`: recorded mocap clips projected into one camera, paths
that cross, one person hiding another, people entering and leaving, one-frame false
detections, rows shuffled every frame).

* **Identities**: the tracker (:class:`mocap_core.tracking.PersonTracker`, the keypoint node's
  defaults) over every scene and seed: identity switches per 1000 person-frames, fragments,
  coverage, ids per actor, ids given to false detections.
* **Per-person accuracy**: each actor's keypoints lifted with the shipped MotioNet through
  :class:`~mocap_lifter.online.PeopleStreams` with the tracker's ids, in the three-person
  scene, against the same actor's clip alone in the same camera (no one else: no occlusion,
  no tracking). MPJPE in mm, pelvis-aligned, camera frame, against the clips' ground truth.
* **Time per frame**: tracker and lifter (one network state per person), medians by the number
  of people in the frame, measured side by side in one run.

Prints the figures and writes a Markdown report (default ``docs/benchmarks/people.md``) with
a JSON copy beside it.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from collections import Counter, defaultdict
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np

from .online import DEFAULT_HOLD_UNSEEN_S as HOLD_S     # the node's default hold

ROOT = Path(__file__).resolve().parents[3]
BAGS = ('gt_cmu_walk_12_02', 'gt_bandai_walk_exhausted', 'gt_bandai_wave_normal')


def _motions():
    from mocap_core.testing import groundtruth_motion
    return [groundtruth_motion(ROOT / 'bags' / b) for b in BAGS]


def identity_figures(seeds: int) -> Dict[str, object]:
    """Tracker identity metrics over every standard scene and ``seeds`` seeds."""
    from mocap_core.data.multi_person import crossing_scenes, identity_metrics
    from mocap_core.tracking import PersonTracker

    motions = _motions()
    rows, totals, times = [], Counter(), []
    for seed in range(seeds):
        for name, scene in crossing_scenes(*motions, np.random.default_rng(seed)).items():
            tr = PersonTracker()
            ids = []
            for kp, st in zip(scene.keypoints, scene.stamps_s()):
                t0 = time.perf_counter()
                out = tr.update(kp, st)
                times.append(time.perf_counter() - t0)
                ids.append({p.row: p.id for p in out})
            m = identity_metrics(scene.truth, ids)
            rows.append({'scene': name, 'seed': seed, **m})
            for k in ('person_frames', 'switches', 'fragments', 'false_ids'):
                totals[k] += m[k]
    pf = max(totals['person_frames'], 1.0)
    return {
        'rows': rows,
        'person_frames': int(totals['person_frames']),
        'switches': int(totals['switches']),
        'switches_per_1000': 1000.0 * totals['switches'] / pf,
        'fragments': int(totals['fragments']),
        'false_ids': int(totals['false_ids']),
        'covered': float(np.mean([r['covered'] for r in rows])),
        'ids_per_actor': float(np.mean([r['ids_per_actor'] for r in rows])),
        'tracker_ms_median': 1e3 * float(np.median(times)),
    }


def _lift(scene, tracked: bool, model, intr, hold_unseen_s: float = 0.0):
    """Lift a scene's persons: ``{actor: {frame: (J, 3) camera-frame joints}}`` and the time
    per frame by people in the frame. ``tracked``: ids from the tracker (actor = the majority
    truth of the rows an id took); else the truth's actor index is the id."""
    from mocap_core.tracking import PersonTracker
    from mocap_lifter.intrinsics import StreamIntrinsics
    from mocap_lifter.online import OnlineLifter, PeopleStreams

    si = StreamIntrinsics()
    si.set_camera_info(intr)
    streams = PeopleStreams(lambda: OnlineLifter(model, 'windowed'), si,
                            hold_unseen_s=hold_unseen_s)
    tracker = PersonTracker()
    votes: Dict[int, Counter] = defaultdict(Counter)
    out: Dict[int, Dict[int, np.ndarray]] = defaultdict(dict)
    per_count: Dict[int, List[float]] = defaultdict(list)
    index = {}
    dt_ns = int(round(1e9 / scene.fps))

    def collect(step):
        for pid, st in step.steps.items():
            for f in st.frames:
                out[pid][index[f.stamp_ns]] = f.pose.joint_positions()

    for k, (kp, truth) in enumerate(zip(scene.keypoints, scene.truth)):
        stamp = k * dt_ns
        index[stamp] = k
        t0 = time.perf_counter()
        if tracked:
            people = tracker.update(kp, k / scene.fps)
            rows = np.array([p.keypoints for p in people]).reshape(-1, kp.shape[1], 3)
            ids = np.array([p.id for p in people], dtype=np.int64)
            for p in people:
                votes[p.id][int(truth[p.row])] += 1
        else:
            keep = truth >= 0
            rows, ids = kp[keep], truth[keep] + 1
        step = streams.push(stamp, rows, ids)
        per_count[len(ids)].append(time.perf_counter() - t0)
        collect(step)
    collect(streams.flush())
    actor_of = ({pid: v.most_common(1)[0][0] for pid, v in votes.items()} if tracked else
                {pid: pid - 1 for pid in out})
    by_actor: Dict[int, Dict[int, np.ndarray]] = defaultdict(dict)
    for pid, frames in out.items():
        a = actor_of.get(pid, -1)
        if a >= 0:
            by_actor[a].update(frames)
    return by_actor, per_count


def _mpjpe(pred: Dict[int, np.ndarray], truth: np.ndarray, frames) -> float:
    """Pelvis-aligned MPJPE (mm) over ``frames`` where both exist."""
    errs = []
    for f in frames:
        if f in pred and np.all(np.isfinite(truth[f])):
            p = pred[f] - pred[f][0]
            g = truth[f] - truth[f][0]
            errs.append(np.linalg.norm(p - g, axis=-1).mean())
    return 1e3 * float(np.mean(errs)) if errs else float('nan')


def accuracy_figures(seeds: int, hold_unseen_s: float = 0.0) -> Dict[str, object]:
    """Per-person MPJPE in the three-person scene against each clip alone
    (``hold_unseen_s``: the lifter's hold of unseen keypoints, :class:`LifterStream`)."""
    from mocap_core.data.multi_person import Actor, crossing_camera, make_scene
    from mocap_lifter.weights import default_weights, load_weights

    walk_a, walk_b, stand = _motions()
    model = load_weights(default_weights('windowed'), 'cpu', causal=False)
    cam = crossing_camera()
    actors = [Actor(walk_a, 0.0, (0.0, 0.0)), Actor(walk_b, np.pi, (0.0, 1.0)),
              Actor(stand, 0.0, (0.2, 2.2))]
    frames = min(walk_a.num_frames, walk_b.num_frames)
    rows = []
    timing: Dict[int, List[float]] = defaultdict(list)
    for seed in range(seeds):
        scene = make_scene(actors, frames, cam, np.random.default_rng(seed))
        together, per_count = _lift(scene, True, model, cam.intrinsics, hold_unseen_s)
        for n, ts in per_count.items():
            timing[n] += ts
        for a, actor in enumerate(actors):
            alone_scene = make_scene([actor], frames, cam, np.random.default_rng(100 + seed))
            alone, per_count = _lift(alone_scene, False, model, cam.intrinsics, hold_unseen_s)
            for n, ts in per_count.items():
                timing[n] += ts
            present = [f for f in range(frames) if np.all(np.isfinite(scene.joints[f, a]))]
            m_alone = _mpjpe(alone.get(0, {}), alone_scene.joints[:, 0], present)
            m_three = _mpjpe(together.get(a, {}), scene.joints[:, a], present)
            covered = sum(1 for f in present if f in together.get(a, {})) / max(len(present), 1)
            rows.append({'seed': seed, 'actor': a, 'clip': BAGS[a], 'alone_mm': m_alone,
                         'three_mm': m_three, 'delta_mm': m_three - m_alone,
                         'covered': covered})
    return {
        'rows': rows,
        'alone_mm': float(np.nanmean([r['alone_mm'] for r in rows])),
        'three_mm': float(np.nanmean([r['three_mm'] for r in rows])),
        'delta_mm': float(np.nanmean([r['delta_mm'] for r in rows])),
        'ms_per_frame_by_people': {int(n): 1e3 * float(np.median(ts))
                                   for n, ts in sorted(timing.items()) if len(ts) >= 10},
    }


def write_report(path: Path, ident: dict, acc: dict, seeds: int,
                 acc_hold: Optional[dict] = None) -> None:
    import os
    machine = f'{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs'
    lines = [
        '# Several people: identities, per-person accuracy, time per frame',
        '',
        f'`mocap bench people --seeds {seeds}` on {platform.node()} ({machine}), '
        f'{time.strftime("%Y-%m-%d")}. Synthetic scenes of `mocap_core.data.multi_person` '
        '(three recorded clips, crossing paths, occlusion, entries and exits, one-frame false '
        'detections, rows shuffled every frame).',
        '',
        '## Identities (tracker, keypoint node defaults)',
        '',
        '| measure | value | goal |',
        '|---|---|---|',
        f"| identity switches per 1000 person-frames | {ident['switches_per_1000']:.2f} "
        f"({ident['switches']} in {ident['person_frames']}) | <= 1 |",
        f"| fragments (coverage resumes after a gap) | {ident['fragments']} | |",
        f"| person-frames with an id | {100 * ident['covered']:.1f} % | |",
        f"| ids per actor | {ident['ids_per_actor']:.2f} | 1 |",
        f"| ids given to false detections | {ident['false_ids']} | 0 |",
        f"| tracker time per frame (median) | {ident['tracker_ms_median']:.2f} ms | |",
        '',
        '| scene | seed | person-frames | switches | fragments | covered | ids/actor |',
        '|---|---|---|---|---|---|---|',
    ]
    for r in ident['rows']:
        lines.append(f"| {r['scene']} | {r['seed']} | {int(r['person_frames'])} | "
                     f"{int(r['switches'])} | {int(r['fragments'])} | "
                     f"{100 * r['covered']:.1f} % | {r['ids_per_actor']:.0f} |")
    lines += [
        '',
        '## Per-person lifter accuracy: three people against each clip alone',
        '',
        'MPJPE (mm, pelvis-aligned, camera frame) of the shipped MotioNet (windowed) on each '
        'actor of the three-person scene (tracker ids, occlusion by the others) and on the '
        'same clip alone in the same camera (no one else). Goal: within +5 mm.',
        '',
        '| seed | clip | alone | three people | difference | frames with the person |',
        '|---|---|---|---|---|---|',
    ]
    for r in acc['rows']:
        lines.append(f"| {r['seed']} | {r['clip']} | {r['alone_mm']:.1f} | "
                     f"{r['three_mm']:.1f} | {r['delta_mm']:+.1f} | "
                     f"{100 * r['covered']:.0f} % |")
    lines += [
        f"| **mean** | | **{acc['alone_mm']:.1f}** | **{acc['three_mm']:.1f}** | "
        f"**{acc['delta_mm']:+.1f}** | |",
        '',
    ]
    if acc_hold is not None:
        lines += [
            'Without the lifter\'s hold of hidden keypoints (`hold_unseen_s:=0`; the default '
            f'{HOLD_S:g} s: a keypoint hidden behind someone takes its last seen position), '
            'the same scenes and seeds: alone '
            f"{acc_hold['alone_mm']:.1f} mm, three people {acc_hold['three_mm']:.1f} mm, "
            f"difference **{acc_hold['delta_mm']:+.1f} mm** (per clip: " + ', '.join(
                f"{r['clip']} seed {r['seed']} {r['delta_mm']:+.1f}"
                for r in acc_hold['rows']) + ').',
            '',
        ]
    lines += [
        '## Time per frame by people in the frame (tracker + lifter, median)',
        '',
        '| people | ms per frame |',
        '|---|---|',
    ]
    for n, ms in acc['ms_per_frame_by_people'].items():
        lines.append(f'| {n} | {ms:.2f} |')
    lines += ['', 'Regenerate: `mocap bench people` (about a minute on 2 cores).', '']
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text('\n'.join(lines))
    path.with_suffix('.json').write_text(json.dumps({'identities': ident, 'accuracy': acc,
                                                     'accuracy_without_hold': acc_hold},
                                                    indent=1))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog='mocap bench people', description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--seeds', type=int, default=3, help='noise seeds per scene (default 3)')
    ap.add_argument('--output', default=str(ROOT / 'docs' / 'benchmarks' / 'people.md'))
    args = ap.parse_args(argv)
    import torch
    torch.set_num_threads(1)
    ident = identity_figures(args.seeds)
    print(f"identities: {ident['switches_per_1000']:.2f} switches per 1000 person-frames "
          f"({ident['switches']} in {ident['person_frames']}), {ident['fragments']} fragments,"
          f" {100 * ident['covered']:.1f} % covered, {ident['false_ids']} false ids, tracker "
          f"{ident['tracker_ms_median']:.2f} ms/frame")
    acc = accuracy_figures(args.seeds, HOLD_S)
    print(f"per-person MPJPE: alone {acc['alone_mm']:.1f} mm, three people "
          f"{acc['three_mm']:.1f} mm ({acc['delta_mm']:+.1f} mm)")
    for n, ms in acc['ms_per_frame_by_people'].items():
        print(f'  {n} people: {ms:.2f} ms per frame (tracker + lifter)')
    acc_hold = accuracy_figures(args.seeds, 0.0)
    print(f"  without the hold (hold_unseen_s 0): alone {acc_hold['alone_mm']:.1f} mm, three "
          f"people {acc_hold['three_mm']:.1f} mm ({acc_hold['delta_mm']:+.1f} mm)")
    write_report(Path(args.output), ident, acc, args.seeds, acc_hold)
    print(f'report: {args.output}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
