"""``mocap eval video``: the whole pipeline from rendered videos, scored against exact ground
truth (``mocap_core.render.evaluate``).

    mocap eval video [--renders DIR] [--split validation] [--limit N] [-o OUT_DIR]
                     [--param NODE.NAME=VALUE ...] [--intrinsics true|approx]
                     [--start video|keypoints] [--tag NAME]

Per rendered clip (``mocap data render``), ``mocap process`` runs on ``video.mp4`` (start
``video``: the keypoint node with BlazePose at its defaults, the multi-person detector (until
session 64 ``max_persons`` 1 was set here, the single-person detector of the recorded
detections; ``--param keypoints.max_persons=1`` asks for it), then lifter, physics, GMR;
the camera's true intrinsics are given to the keypoint node as a calibration file unless
``--intrinsics approx``) or on the clip's bag from the keypoints it recorded (start
``keypoints``: the single-person detector's output at render time, faster). The output
bags are kept under ``~/.cache/mocap/eval_video/<tag>_<start>_<intrinsics>/``
(``--work``) and reused by a rerun with the same tag. Writes ``OUT_DIR/report.md``,
``report.json`` and plots.

``--live`` (with start ``video``): each clip is played at its frame rate through the composed
live pipeline (``mocap run``: the four nodes in one process, every stage at live settings),
recorded from inside the process and scored as above. The keypoint node drops the frames
its detector cannot keep up with, as with a camera, so the figures are what a live user of
this machine gets; the report adds the share of the frames that reached each stage. Run it
on an otherwise idle machine: the share depends on the CPU left to the pipeline.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import numpy as np

from .. import topics as _T


T_GT_CAMERA_POSE = '/mocap/groundtruth/camera_pose'


class EvalError(Exception):
    pass


class NoOutput(Exception):
    """The pipeline published no 3D output for a clip (nobody detected in any frame)."""


def _read_output(bag: Path) -> Dict[str, Tuple[np.ndarray, np.ndarray]]:
    """``{topic: (stamps ns (N,), joints (N, 18, 3))}`` of the three joints topics, and the
    keypoint stamps (every frame) under ``'keypoints'``."""
    from ..bag_io import BagReader, deserialize
    from ..ros_conversions import cloud_to_positions, stamp_to_ns
    from ..skeleton import NUM_JOINTS
    from .. import topics as T
    want = [T.KEYPOINTS, T.LIFTER_JOINTS3D, T.PHYSICS_JOINTS3D, T.WORLD_JOINTS3D,
            T.PHYSICS_FLOOR]
    acc: Dict[str, Tuple[list, list]] = {t: ([], []) for t in want}
    with BagReader(bag) as reader:
        present = [t for t in want if t in reader.topics]
        for m in reader.messages(topics=present):
            msg = deserialize(m.data, m.msgtype)
            stamp = stamp_to_ns(msg.header.stamp)
            if m.topic == T.KEYPOINTS:
                acc[m.topic][0].append(stamp)
                continue
            if m.topic == T.PHYSICS_FLOOR:       # (x y z w, tx ty tz) of the floor frame
                r, t = msg.transform.rotation, msg.transform.translation
                acc[m.topic][0].append(stamp)
                acc[m.topic][1].append([r.x, r.y, r.z, r.w, t.x, t.y, t.z])
                continue
            try:
                joints = cloud_to_positions(msg, NUM_JOINTS)[:NUM_JOINTS]
            except ValueError:  # a malformed output frame is not scored
                continue
            if joints.shape == (NUM_JOINTS, 3):
                acc[m.topic][1].append(joints)
                acc[m.topic][0].append(stamp)
    return {t: (np.asarray(s, dtype=np.int64), np.asarray(v)) for t, (s, v) in acc.items()}


def _camera_state_groups(bag: Path, first: int, fps: float, n: int) -> Optional[List[str]]:
    """(n,) :func:`~mocap_core.render.evaluate.camera_state_group` of each rendered frame
    from the camera-motion estimate the input bag carried (``unknown`` where it has none), or
    None without any."""
    from ..bag_io import BagReader, deserialize
    from ..render.evaluate import camera_state_group
    from ..ros_conversions import (odometry_to_camera_motion, odometry_to_camera_position,
                                   stamp_to_ns)
    from .. import topics as T
    stamps, found = [], []
    with BagReader(bag) as reader:
        if T.CAMERA_MOTION not in reader.topics:
            return None
        for m in reader.messages(topics=[T.CAMERA_MOTION]):
            msg = deserialize(m.data, m.msgtype)
            stamps.append(stamp_to_ns(msg.header.stamp))
            found.append(camera_state_group(odometry_to_camera_motion(msg)[0],
                                            odometry_to_camera_position(msg) is not None))
    groups = ['unknown'] * n
    seen = False
    for i, g in zip(_index(np.asarray(stamps, dtype=np.int64), first, fps), found):
        if 0 <= i < n:
            groups[i] = g
            seen = True
    return groups if seen else None


def _index(stamps: np.ndarray, first: int, fps: float) -> np.ndarray:
    return np.round((stamps - first) * fps / 1e9).astype(int)


#: frames between an image and the physics floor of its stamp reaching the keypoint node in
#: ``mocap process`` (lifter latency 14 + physics and GMR hand-over; measured on the real walk:
#: the first floor arrives at frame 30), used to hand the floor over as late as live
FLOOR_LAG_FRAMES = 30


def _lagged_floors(floor_bag: Optional[Path], n: int, fps: float) -> Optional[list]:
    """Per frame the physics floor the keypoint node would hold by then (the one of the
    stamp ``FLOOR_LAG_FRAMES`` earlier) from a first run's output bag: (normal, height,
    stamp_s) or None."""
    if floor_bag is None:
        return None
    from .. import topics as T
    from ..data.gt_bag import DEFAULT_START_NS
    data = _read_output(floor_bag)
    fs, fv = data[T.PHYSICS_FLOOR]
    if not len(fv):
        return None
    from ..rotations import quat_to_matrix
    idx = _index(fs, DEFAULT_START_NS, fps)
    by_frame = {int(i): v for i, v in zip(idx, fv)}
    out: list = []
    for i in range(n):
        v = by_frame.get(i - FLOOR_LAG_FRAMES)
        if v is None:
            out.append(None)
            continue
        A = quat_to_matrix(v[:4] / np.linalg.norm(v[:4]))
        nrm = A[:, 2]
        out.append((nrm, float(-nrm @ v[4:7]), (i - FLOOR_LAG_FRAMES) / fps))
    return out


def _true_floors(gt: Dict[str, np.ndarray]) -> list:
    """Per frame the render's true floor, handed over ``FLOOR_LAG_FRAMES`` late like the
    physics floor (:func:`_lagged_floors`): the oracle that separates the floor's error from
    the tracking's (``--camera-floor true``)."""
    R, C = gt['camera_R'], gt['camera_position']       # world -> camera; camera in world
    fps = float(gt['fps'])
    ez = np.array([0.0, 0.0, 1.0])
    return [None if i < FLOOR_LAG_FRAMES else
            (R[i - FLOOR_LAG_FRAMES] @ ez, float(C[i - FLOOR_LAG_FRAMES, 2]),
             (i - FLOOR_LAG_FRAMES) / fps) for i in range(len(R))]


def _camera_motion_bag(clip_dir: Path, gt: Dict[str, np.ndarray], out: Path,
                       floor_bag: Optional[Path] = None, true_floor: bool = False) -> dict:
    """The clip's bag with the camera-motion estimate from its video added (what the keypoint
    node publishes when it reads the video), and the estimate's accuracy against the true
    camera: ``{'rotation_error_deg_s': median error of the frame-to-frame rotation,
    'drift_deg': orientation error at the end, 'state_<state>': fraction of frames}``
    (scored as ``camera_<key>``). With ``floor_bag`` (a first run's output), the camera's
    translation is measured over the physics floor as the keypoint node does, the floor
    handed over ``FLOOR_LAG_FRAMES`` late, and scored too: ``translation_frames`` (share of
    moving frames measured), ``position_error_pct`` (the camera's position at the end
    against the truth, % of the distance it travelled). ``true_floor``: the render's true
    floor instead (an oracle)."""
    from mocap_core.camera_motion import estimate_video, rotation_accuracy

    from ..render.bag import write_rendered_bag
    from ..rotations import quat_to_matrix

    fps = float(gt['fps'])
    floors = _true_floors(gt) if true_floor else \
        _lagged_floors(floor_bag, len(gt['keypoints']), fps)
    est = estimate_video(clip_dir / 'video.mp4', gt['K'], fps, gt['keypoints'], floors=floors)
    write_rendered_bag(clip_dir, out, overwrite=True, camera_motion=[
        (e.state, e.orientation, e.angular_velocity,
         e.position if e.translation_known else None, e.linear_velocity) for e in est])
    R = gt['camera_R']                   # world -> camera
    n = min(len(est), len(R))
    error, drift = rotation_accuracy(est, R, fps)
    acc = {'rotation_error_deg_s': error, 'drift_deg': drift}
    for state in ('static', 'rotating', 'moving', 'unknown'):
        acc[f'state_{state}'] = float(np.mean([e.state == state for e in est[:n]]))
    if floors is not None:
        moving = [e for e in est[:n] if e.state == 'moving']
        acc['translation_frames'] = float(np.mean([e.translation_known for e in moving])) \
            if moving else float('nan')
        # the camera's path in its first frame: truth vs the estimate, over the frames from
        # the first measured one (before it the floor was not known)
        C = gt['camera_position']
        first = next((i for i in range(1, n) if est[i].translation_known and
                      not est[i - 1].translation_known and est[i].state != 'static'), 0)
        true = R[first] @ (C[n - 1] - C[first])
        mine = quat_to_matrix(est[first].orientation).T @ (est[n - 1].position -
                                                           est[first].position)
        travelled = float(np.linalg.norm(np.diff(C[first:n], axis=0), axis=1).sum())
        acc['position_error_pct'] = float(100 * np.linalg.norm(mine - true) / travelled) \
            if travelled > 0.2 and est[n - 1].translation_known else float('nan')
    return acc


#: the topics a live run records (what :func:`_read_output` and the skating split read, and
#: the camera info: the recorded bag can be processed again from its keypoints)
LIVE_TOPICS = (_T.KEYPOINTS, _T.CAMERA_INFO, _T.CAMERA_MOTION, _T.LIFTER_JOINTS3D,
               _T.PHYSICS_JOINTS3D, _T.WORLD_JOINTS3D, _T.PHYSICS_FLOOR)


def _live_summary(out: Path) -> Dict:
    """What a live run of this clip recorded about itself (:func:`~.run.run`'s ``info``), from
    its own folder or, for a replay, the copy of the live run's."""
    for name in ('summary.json', 'live_summary.json'):
        path = out / name
        if path.exists():
            data = json.loads(path.read_text())
            if 'source_start_ns' in data:
                return data
    return {}


def run_clip(clip_dir: Path, work: Path, start: str, intrinsics: str,
             params: Dict[str, Dict], progress: bool = False, camera_motion: bool = True,
             camera_floor: str = 'physics', known_height: bool = False, live: bool = False,
             replay: Optional[Path] = None):
    """Process one rendered clip (reusing a finished output) and score it. With
    ``camera_motion`` and start ``keypoints``, the input bag carries the camera-motion
    estimate from the clip's video (start ``video``: the keypoint node makes it), its
    translation measured over ``camera_floor`` ('physics': the physics floor of a first run;
    'true': the render's floor, an oracle). With ``known_height`` the lifter is given the
    rendered body's stature (``lifter.subject_height``). ``live`` (start ``video``): played
    at its rate through the composed live pipeline (module docstring). ``replay`` (start
    ``keypoints``): the work folder of a live run, whose recorded keypoint stream (the frames
    that live run kept, its camera-motion estimate) is processed instead of the render's."""
    from .. import topics as T
    from ..camera import CameraCalibration, CameraIntrinsics, write_camera_info_yaml
    from ..render.clip import load_clip
    from ..render.evaluate import score_clip
    from .process import process

    gt, meta = load_clip(clip_dir)
    out = work / clip_dir.name
    bag = out / 'bag'
    if not (out / 'done').exists():
        out.mkdir(parents=True, exist_ok=True)
        p = {k: dict(v) for k, v in params.items()}
        if known_height:
            p.setdefault('lifter', {})['subject_height'] = float(meta['body_height_m'])
        if start == 'video':
            src = clip_dir / 'video.mp4'
            if intrinsics == 'true':
                K = gt['K']
                w, h = (int(x) for x in gt['image_size'])
                yaml = out / 'camera.yaml'
                write_camera_info_yaml(CameraCalibration(CameraIntrinsics(
                    w, h, float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]),
                    approximate=False)), yaml)
                p.setdefault('keypoints', {})['calibration_file'] = str(yaml)
            kw = {}
        elif replay is not None:
            src = replay / clip_dir.name / 'bag'
            if not (replay / clip_dir.name / 'done').exists():
                raise EvalError(f'the live run {replay} has no finished recording of this clip')
            kw = {'start': 'keypoints'}
            (out / 'live_summary.json').write_text(
                (replay / clip_dir.name / 'summary.json').read_text())
        else:
            src = clip_dir / 'gt_bag'
            kw = {'start': 'keypoints'}
            if intrinsics != 'true':
                raise EvalError('--start keypoints uses the bag\'s true camera_info; '
                                'use --start video for --intrinsics approx')
            if camera_motion:
                # two passes, as the keypoint node measures the camera's translation over
                # the physics floor: the physics does not depend on the camera motion, so
                # the first pass gives the floor the second one hands over (late, as live)
                src = out / 'input_bag'
                if camera_floor == 'true':
                    acc = _camera_motion_bag(clip_dir, gt, src, true_floor=True)
                else:
                    _camera_motion_bag(clip_dir, gt, src)
                    process(src, out / 'floor_bag', params=p, overwrite=True, progress=False,
                            log=lambda *a: None, log_level='error', **kw)
                    acc = _camera_motion_bag(clip_dir, gt, src, out / 'floor_bag')
                (out / 'camera_motion.json').write_text(json.dumps(acc, indent=1))
        if live:
            from .run import RunError, run
            kp = p.setdefault('keypoints', {})
            kp.update(source='video', path=str(src), loop=False)
            kp.setdefault('realtime', True)    # (false: no frame dropped, for tests)
            info: Dict = {}
            try:
                status = run(p, record=bag, topics_out=LIVE_TOPICS, overwrite=True,
                             log_level='error', info=info)
            except RunError as exc:
                raise EvalError(str(exc)) from None
            if status != 0 or info.get('end') == 'interrupted' \
                    or info.get('source_start_ns') is None:
                # not marked done: a rerun plays the clip again
                raise EvalError(f"the live run did not finish ({info.get('end', 'status')} "
                                f'{status})')
            summary = {'live': True, **info}
        else:
            summary = process(src, bag, params=p, overwrite=True, progress=progress,
                              log=lambda *a: None, log_level='error', **kw)
        (out / 'summary.json').write_text(json.dumps(summary, indent=1, default=str))
        (out / 'done').write_text('1')
    data = _read_output(bag)
    fps = float(gt['fps'])
    kp_stamps = data[T.KEYPOINTS][0]
    streamed = live or replay is not None       # a live run's frames, live or replayed
    live_info = _live_summary(out) if streamed else {}
    if live_info.get('source_start_ns') is not None:
        first = int(live_info['source_start_ns'])   # frame 0, kept or dropped
    elif start == 'video' or streamed:
        # (a live run recorded before its source's first stamp was kept: its first frame)
        first = int(kp_stamps.min()) if len(kp_stamps) else 0
    else:
        from ..data.gt_bag import DEFAULT_START_NS
        first = DEFAULT_START_NS
    ls, lj = data[T.LIFTER_JOINTS3D]
    if not len(lj):
        raise NoOutput(f"{meta['clip']}: no lifter output (person detected in "
                       f"{100 * meta.get('detected_fraction', 0):.0f} % of frames)")
    roots = {}
    for stage, topic in (('physics', T.PHYSICS_JOINTS3D), ('world', T.WORLD_JOINTS3D)):
        s, j = data[topic]
        if len(j):
            roots[stage] = (j, _index(s, first, fps))   # all joints: the feet are scored
    score = score_clip(meta['clip'], meta, gt, lj if len(lj) else None,
                       _index(ls, first, fps), roots)
    if streamed:
        # the share of the rendered frames that reached each stage (the rest were dropped
        # by the keypoint node, as a camera's frames are when the detector falls behind)
        n = max(int(meta.get('frames') or len(gt['joints_world'])), 1)
        score.root['live'] = {'keypoint_share': len(kp_stamps) / n,
                              'world_share': len(data[T.WORLD_JOINTS3D][0]) / n}
    cm = out / 'camera_motion.json'
    if cm.exists():
        score.root.setdefault('camera', {}).update(json.loads(cm.read_text()))
    # live (and its replays): the live keypoint node's estimate
    motion_bag = bag if streamed else out / 'input_bag'
    if motion_bag.exists() and 'world' in roots and 'contacts' in gt:
        from ..render.evaluate import skating_by_camera_state
        groups = _camera_state_groups(motion_bag, first, fps, len(gt['contacts']))
        if groups is not None:
            score.world_skating_by_state = skating_by_camera_state(
                *roots['world'], gt['contacts'], groups)
    fs, fv = data[T.PHYSICS_FLOOR]
    if len(fv) and 'camera_R' in gt and 'physics' in score.root:
        from ..render.evaluate import floor_errors
        score.root['physics'].update(floor_errors(fv[:, :4], fv[:, 4:], _index(fs, first, fps),
                                                  gt))
        if 'physics' in roots and 'contacts' in gt:
            from ..render.evaluate import skating_in_world
            score.root['physics'].update(skating_in_world(
                *roots['physics'], fv[:, :4], fv[:, 4:], _index(fs, first, fps), gt))
    return score


def _plots(scores, agg: dict, out: Path) -> List[Path]:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    paths = []
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    per = np.array([s.summary()['mpjpe'] for s in scores])
    ax[0].hist(per, bins=30, color='tab:blue')
    ax[0].axvline(np.median(per), color='k', ls='--', label=f'median {np.median(per):.0f} mm')
    ax[0].set_xlabel('lifter MPJPE per clip (mm)')
    ax[0].set_ylabel('clips')
    ax[0].legend()
    views = list(agg['by_view'])
    ax[1].bar(views, [agg['by_view'][v]['mpjpe'] for v in views], color='tab:orange',
              label='MPJPE')
    ax[1].bar(views, [agg['by_view'][v]['pa_mpjpe'] for v in views], color='tab:green',
              width=0.5, label='PA-MPJPE')
    ax[1].set_ylabel('mm (pooled over frames)')
    ax[1].legend()
    fig.tight_layout()
    p = out / 'video_eval.png'
    fig.savefig(p, dpi=110)
    plt.close(fig)
    paths.append(p)
    return paths


def cmd_compare(args: argparse.Namespace) -> int:
    """``--compare NAME=REPORT.json ...``: one side-by-side table of earlier runs."""
    from ..render.evaluate import comparison_markdown
    reports = []
    for item in args.compare:
        name, sep, path = item.partition('=')
        if not sep or not name or not path:
            print(f'mocap eval video: error: --compare takes NAME=REPORT.json, got {item!r}',
                  file=sys.stderr)
            return 2
        try:
            reports.append((name, json.loads(Path(path).read_text())))
        except (OSError, ValueError) as exc:
            print(f'mocap eval video: error: cannot read {path}: {exc}', file=sys.stderr)
            return 2
    setup = ['Made by `mocap eval video --compare ' + ' '.join(args.compare) + '` from the '
             'reports of runs over the same rendered clips.']
    md = comparison_markdown(reports, args.title, setup)
    out = Path(args.output)
    if out.suffix != '.md':
        out.mkdir(parents=True, exist_ok=True)
        out = out / 'comparison.md'
    else:
        out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(md)
    print(md)
    print(f'report: {out}', file=sys.stderr)
    return 0


def cmd_eval_video(args: argparse.Namespace) -> int:
    if args.compare:
        return cmd_compare(args)
    from ..render.batch import DEFAULT_OUT
    from ..render.clip import iter_done
    from ..render.evaluate import aggregate, report_markdown
    from .process import ProcessError, parse_params

    if args.known_camera_pose and args.start != 'keypoints':
        print('mocap eval video: error: --known-camera-pose needs --start keypoints (the '
              "camera's pose is in the rendered clip's bag)", file=sys.stderr)
        return 2
    if args.replay_live and (args.start != 'keypoints' or args.live):
        print('mocap eval video: error: --replay-live needs --start keypoints (and no --live)',
              file=sys.stderr)
        return 2
    if args.live and args.start != 'video':
        print('mocap eval video: error: --live needs --start video (the keypoint node reads '
              'the video live)', file=sys.stderr)
        return 2
    renders = Path(args.renders) if args.renders else DEFAULT_OUT
    clips = list(iter_done(renders, args.split))
    if not clips:
        print(f'mocap eval video: error: no rendered {args.split} clips under {renders} '
              f'(make them with: mocap data render --split {args.split})', file=sys.stderr)
        return 2
    if args.limit:
        clips = clips[:args.limit]
    out = Path(args.output)
    tag = args.tag or ('_'.join(f'{k}' for k in sorted(args.param)) or 'default')
    if args.no_camera_motion:
        tag += '_nocm'
    if args.camera_floor == 'true':
        tag += '_truefloor'
    if args.known_height:
        tag += '_height'
    if args.known_camera_pose:
        tag += '_pose'
        args.param = list(args.param) + [
            f'{node}.{k}' for node in ('lifter', 'physics', 'gmr') for k in (
                f'camera_pose_topic={T_GT_CAMERA_POSE}', 'camera_pose_type=pose')]
    tag = ''.join(c if c.isalnum() or c in '-_.=' else '_' for c in tag)
    work_root = Path(args.work) if args.work else Path.home() / '.cache' / 'mocap' / 'eval_video'
    replayed = Path(args.replay_live).expanduser() if args.replay_live else None
    work = work_root / (f'{tag}_{args.start}_{args.intrinsics}' + ('_live' if args.live else '')
                        + (f'_replay_{replayed.resolve().name}' if replayed else ''))
    try:
        params = parse_params(args.param)
    except ProcessError as exc:
        print(f'mocap eval video: error: {exc}', file=sys.stderr)
        return 2
    from tqdm import tqdm
    scores, failed, no_output = [], [], []
    for d in tqdm(clips, desc='mocap eval video', unit='clip', disable=args.quiet):
        try:
            scores.append(run_clip(d, work, args.start, args.intrinsics, params,
                                   camera_motion=not args.no_camera_motion,
                                   camera_floor=args.camera_floor,
                                   known_height=args.known_height, live=args.live,
                                   replay=replayed))
        except NoOutput as exc:
            no_output.append(str(exc))
        except (EvalError, ProcessError, ValueError, OSError) as exc:
            failed.append(f'{d.name}: {exc}')
            print(f'mocap eval video: skipping {d.name}: {exc}', file=sys.stderr)
    if not scores:
        print('mocap eval video: error: no clip could be scored', file=sys.stderr)
        return 2
    agg = aggregate(scores)
    agg['failed'] = failed
    agg['no_output'] = no_output
    try:
        shown = f'~/{Path(renders).resolve().relative_to(Path.home().resolve())}'
    except ValueError:
        shown = str(renders)
    setup = ['`mocap eval video' + (f' --renders {shown}' if args.renders else '')
             + f' --split {args.split} --start {args.start} --intrinsics '
             f'{args.intrinsics}' + (' --live' if args.live else '')
             + (f' --replay-live {args.replay_live}' if args.replay_live else '')
             + ''.join(f' --param {p}' for p in args.param)
             + (' --known-height' if args.known_height else '') + '`'
             + (f' (first {args.limit} clips)' if args.limit else ''),
             f'Rendered clips: `{shown}` ({args.split} split: subjects, contents and styles '
             'never trained on).',
             f'{len(no_output)} clip(s) without any lifter output (the detector found nobody '
             'in any frame) are not in the figures.' if no_output else '']
    out.mkdir(parents=True, exist_ok=True)
    md = report_markdown(agg, args.title, setup)
    (out / 'report.md').write_text(md)
    (out / 'report.json').write_text(json.dumps(
        {'aggregate': agg, 'clips': [{'clip': s.clip, **s.summary()} for s in scores]},
        indent=1, default=float))
    _plots(scores, agg, out)
    print(md)
    print(f'report: {out / "report.md"}', file=sys.stderr)
    return 1 if failed else 0


def add_eval_parser(sub) -> None:
    p = sub.add_parser('video', help='the whole pipeline from rendered test videos, scored '
                       'against exact ground truth', description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--renders', help='rendered clips (default ~/.cache/mocap/render)')
    p.add_argument('--split', default='validation', help='split to score (default validation)')
    p.add_argument('--limit', type=int, help='score only the first N clips')
    p.add_argument('-o', '--output', default='out/eval_video',
                   help='report folder (default out/eval_video)')
    p.add_argument('--param', action='append', default=[], metavar='NODE.NAME=VALUE',
                   help='node parameter for mocap process (repeatable)')
    p.add_argument('--intrinsics', choices=('true', 'approx'), default='true',
                   help="true: the render camera's calibration; approx: the keypoint node's "
                   'field-of-view approximation')
    p.add_argument('--start', choices=('video', 'keypoints'), default='video',
                   help="video: run the keypoint node on the video (its default, "
                   "multi-person detector); keypoints: reuse the render's detections (the "
                   "single-person detector, faster)")
    p.add_argument('--known-camera-pose', action='store_true',
                   help="give the lifter, physics and world stages the render camera's true "
                   'pose (/mocap/groundtruth/camera_pose; --start keypoints), as a robot that '
                   "knows its camera's pose would: the lifter sizes the person by their stance "
                   'feet on the floor (--param lifter.size_from_camera_pose=false: not), the '
                   'physics stage carries the body with it, the world output is in the true '
                   'world frame, scored without alignment')
    p.add_argument('--known-height', action='store_true',
                   help="give the lifter each rendered body's stature "
                   '(lifter.subject_height), as a user who knows the performer\'s height would')
    p.add_argument('--no-camera-motion', action='store_true',
                   help='--start keypoints: leave the camera-motion estimate from the video '
                   'out of the input (the world stage then runs without it)')
    p.add_argument('--camera-floor', choices=('physics', 'true'), default='physics',
                   help="--start keypoints: the floor over which the camera's translation is "
                   'measured: physics (as the keypoint node does: the physics floor of a first '
                   "run, 30 frames late) or true (the render's floor, same lag: an oracle that "
                   'separates the floor error from the tracking error)')
    p.add_argument('--live', action='store_true',
                   help='--start video: play each clip at its frame rate through the composed '
                   'live pipeline (mocap run), frames dropped as live; run it on an idle '
                   'machine')
    p.add_argument('--replay-live', metavar='WORK', help='--start keypoints: process the '
                   'keypoint streams a --live run recorded (its work folder, e.g. '
                   '~/.cache/mocap/eval_video/<tag>_video_true_live) instead of the render\'s: '
                   'the same dropped frames and camera-motion estimate, other settings, '
                   'deterministically')
    p.add_argument('--tag', help='name of this run (output bags reused by the same tag)')
    p.add_argument('--work', help='where the output bags are kept (default '
                   '~/.cache/mocap/eval_video/<tag>_<start>_<intrinsics>)')
    p.add_argument('--title', default='Rendered test videos: the pipeline against exact '
                   'ground truth', help='report title')
    p.add_argument('--quiet', action='store_true', help='no progress bar')
    p.add_argument('--compare', nargs='+', metavar='NAME=REPORT.json',
                   help='run nothing: write one side-by-side table of earlier runs '
                        '(report.json of each) to -o (a folder, or a .md file)')
    p.set_defaults(func=cmd_eval_video)


def main(argv: Optional[List[str]] = None) -> int:  # pragma: no cover - via mocap
    parser = argparse.ArgumentParser(prog='mocap eval')
    add_eval_parser(parser.add_subparsers(dest='model'))
    args = parser.parse_args(argv)
    return args.func(args)
