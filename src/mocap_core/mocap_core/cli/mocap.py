"""``mocap``: the project's user-facing command (later issues add data, train, eval, process,
export and bench sub-commands).

    mocap --help
    mocap doctor                      # versions and what this machine can run
    mocap bag check <bag>             # per-topic counts, rates and message validation
    mocap plot keypoints <bag> -o F   # 2D skeletons and confidences of a keypoint topic
    mocap skeleton [--urdf FILE]      # the default skeleton, its bone lengths and URDF
    mocap data build|report|split|to-bag|from-openpose|fit-confidence
                                      # motion-capture data (see mocap_core.cli.mocap_data)
    mocap export bvh <bag> -o out.bvh # a motion topic as BVH for animation tools
    mocap train|eval MODEL            # models: commands registered by the node packages
                                      # (entry points mocap.commands, mocap_core.plugins)
    mocap process | report | bench    # the pipeline offline, its report, benchmarks
"""

from __future__ import annotations

import argparse
import importlib
import os
import platform
from pathlib import Path
import sys
from typing import Callable, Dict, List, Optional

import numpy as np

from .. import topics

def validator_for(topic: str, msgtype: str) -> Optional[Callable]:
    """The converter that parses a message of a pipeline topic (raises on a bad message), or
    None for topics this project does not define."""
    from .. import ros_conversions as rc
    from ..skeleton import NUM_JOINTS

    kind = msgtype.replace('/msg/', '/')
    leaf = topic.rsplit('/', 1)[-1]
    if kind == 'sensor_msgs/PointCloud2' and topic.endswith('keypoints2d'):
        return rc.cloud_to_keypoints
    if kind == 'sensor_msgs/PointCloud2' and topic.endswith('joints3d'):
        return lambda m: rc.cloud_to_positions(m, NUM_JOINTS)
    # /mocap/<stage>/motion, and /mocap/groundtruth/world_motion of the ground-truth bags
    if kind == 'trajectory_msgs/MultiDOFJointTrajectory' and \
            (leaf == 'motion' or leaf.endswith('_motion')):
        return rc.motion_to_pose
    if kind == 'sensor_msgs/JointState' and topic.endswith('contacts'):
        return rc.msg_to_contacts
    if kind == 'sensor_msgs/CameraInfo':
        return rc.camera_info_to_intrinsics
    return None


def cmd_bag_check(args: argparse.Namespace) -> int:
    """Counts, rates and validation of every message of the pipeline's topics in a bag."""
    from ..bag_io import BagError, BagReader, deserialize

    try:
        with BagReader(args.bag) as reader:
            topics = reader.topics
            stamps: Dict[str, List[int]] = {t: [] for t in topics}
            errors: Dict[str, List[str]] = {t: [] for t in topics}
            for m in reader.messages():
                stamps[m.topic].append(m.timestamp_ns)
                fn = validator_for(m.topic, m.msgtype)
                if fn is None:
                    continue
                try:
                    fn(deserialize(m.data, m.msgtype))
                except Exception as exc:  # noqa: BLE001 - report any decoding problem
                    errors[m.topic].append(f'{type(exc).__name__}: {exc}')
    except BagError as exc:
        print(f'mocap bag check: error: {exc}', file=sys.stderr)
        return 1
    bad = 0
    print(f'{"topic":40s} {"type":42s} {"count":>6s} {"rate Hz":>8s}  status')
    for name, info in sorted(topics.items()):
        ts = np.asarray(stamps[name], dtype=np.int64)
        rate = (1e9 / np.median(np.diff(ts))) if len(ts) > 2 and np.median(np.diff(ts)) > 0 \
            else float('nan')
        checked = validator_for(name, info.msgtype) is not None
        errs = errors[name]
        bad += len(errs)
        status = (f'{len(errs)} invalid: {errs[0]}' if errs
                  else ('valid' if checked else 'not checked'))
        print(f'{name:40s} {info.msgtype:42s} {len(ts):6d} {rate:8.2f}  {status}')
    return 1 if bad else 0


def cmd_doctor(args: argparse.Namespace) -> int:
    """Print versions of the stack and whether each part imports."""
    print(f'python      {platform.python_version()} ({sys.executable})')
    print(f'machine     {platform.machine()}, {os.cpu_count()} CPU cores')
    ok = True
    for mod, attr in (('numpy', '__version__'), ('scipy', '__version__'),
                      ('torch', '__version__'), ('pinocchio', '__version__'),
                      ('cv2', '__version__'), ('mediapipe', '__version__'),
                      ('rosbags', None), ('osqp', None), ('clarabel', None), ('rclpy', None)):
        try:
            m = importlib.import_module(mod)
            version = getattr(m, attr, '') if attr else ''
            if not version:
                from importlib.metadata import PackageNotFoundError, version as dist_version
                try:
                    version = dist_version({'rclpy': 'ros-rclpy'}.get(mod, mod))
                except PackageNotFoundError:
                    version = 'installed'
            extra = ''
            if mod == 'torch':
                extra = f' (cuda available: {m.cuda.is_available()})'
            print(f'{mod:11s} {version}{extra}')
        except Exception as exc:  # noqa: BLE001
            ok = False
            print(f'{mod:11s} MISSING ({type(exc).__name__}: {exc})')
    print(f"AMENT_PREFIX_PATH {'set' if os.environ.get('AMENT_PREFIX_PATH') else 'NOT SET'}")
    from .. import plugins
    found = plugins.nodes()
    for stage in plugins.PIPELINE:
        if stage in found:
            n = found[stage]
            print(f'node {stage:9s} ros2 run {n.package} {n.executable} '
                  f'({n.entry_point.value})')
        else:
            ok = False
            print(f'node {stage:9s} MISSING (no package registers it under {plugins.NODE_GROUP})')
    for name, ep in plugins.benches().items():
        print(f'bench {name:8s} {ep.value}')
    return 0 if ok else 1


def cmd_skeleton(args: argparse.Namespace) -> int:
    """Show the default skeleton; optionally write its URDF."""
    from ..skeleton import BONE_GROUP_NAMES, JOINT_NAMES, PARENTS, Skeleton
    from ..urdf import skeleton_to_urdf

    sk = Skeleton.default()
    if args.urdf:
        text = skeleton_to_urdf(sk, body_mass=args.body_mass)
        if args.urdf == '-':
            sys.stdout.write(text)
            return 0
        with open(args.urdf, 'w') as f:
            f.write(text)
        print(f'wrote {args.urdf} (body mass {args.body_mass:g} kg)')
        return 0
    print('joints (parent):')
    for name, parent in zip(JOINT_NAMES, PARENTS):
        print(f'  {name:16s} {JOINT_NAMES[parent] if parent >= 0 else "-"}')
    print('bone groups (m):')
    for name, length in zip(BONE_GROUP_NAMES, sk.group_lengths()):
        print(f'  {name:16s} {length:.3f}')
    print(f'height ~ {sk.height():.2f} m, rest root height {sk.rest_root_height():.3f} m')
    return 0


class CommandError(Exception):
    """A one-line error of a sub-command (printed as ``mocap <command>: error: ...``)."""


def read_topic(bag: str, topic: str, convert: Callable, what: str):
    """Stamps (ns) and converted messages of one topic of a bag, in time order.

    Messages the converter rejects are skipped with a note on stderr. Raises CommandError for
    an unreadable bag or when nothing on the topic converts."""
    from ..bag_io import BagError, BagReader, deserialize
    from ..ros_conversions import MessageError, stamp_to_ns

    stamps, values = [], []
    try:
        with BagReader(bag) as reader:
            for m in reader.messages(topics=[topic]):
                try:
                    msg = deserialize(m.data, m.msgtype)
                    values.append(convert(msg))
                except MessageError as exc:
                    print(f'skipping a message: {exc}', file=sys.stderr)
                    continue
                stamps.append(stamp_to_ns(msg.header.stamp))
    except BagError as exc:
        raise CommandError(str(exc)) from None
    if not values:
        raise CommandError(f'no {what} on {topic}')
    return stamps, values


def cmd_plot_keypoints(args: argparse.Namespace) -> int:
    """Plot the first person's keypoints of a bag's keypoint topic."""
    from ..plots import plot_keypoint_frames
    from ..ros_conversions import cloud_to_keypoints

    stamps, clouds = read_topic(args.bag, args.topic, cloud_to_keypoints, 'keypoints')
    keep = [i for i, kp in enumerate(clouds) if len(kp)]
    if not keep:
        raise CommandError(f'no person rows on {args.topic}')
    out = plot_keypoint_frames([stamps[i] * 1e-9 for i in keep],
                               np.stack([clouds[i][0] for i in keep]), args.output,
                               title=f'{args.topic} ({len(keep)} frames)')
    print(f'wrote {out}')
    return 0


def _bodies_topic(topic: str) -> str:
    """The combined several-people topic beside a stage's motion topic
    (``/mocap/<stage>/motion`` -> ``/mocap/<stage>/bodies/motion``)."""
    head, _, leaf = topic.rstrip('/').rpartition('/')
    return f'{head}/bodies/{leaf}'


def cmd_export_bvh(args: argparse.Namespace) -> int:
    """Write the motion topic of a bag as a BVH file (``--per-person``: one file per person
    of the stage's combined topic)."""
    from ..data.bvh_writer import write_bvh
    from ..ros_conversions import motion_to_bodies, motion_to_pose

    if args.per_person:
        topic = args.bodies_topic or _bodies_topic(args.topic)
        stamps, frames = read_topic(args.bag, topic, motion_to_bodies, 'several-people motion')
        by_id = {}
        for stamp, bodies in zip(stamps, frames):
            for pid, pose in bodies:
                by_id.setdefault(pid, {})[stamp] = pose
        out = Path(args.output)
        for pid, series in sorted(by_id.items()):
            ts = sorted(series)
            poses = [series[t] for t in ts]
            fps = args.fps or (1e9 / float(np.median(np.diff(ts))) if len(ts) > 1 else 30.0)
            path = out.with_name(f'{out.stem}_body_{pid}{out.suffix or ".bvh"}')
            write_bvh(path, poses[-1].skeleton, np.stack([p.rotations for p in poses]),
                      np.stack([p.root_position for p in poses]), fps, frame=args.frame)
            print(f'wrote {path}: person {pid}, {len(poses)} frames at {fps:.2f} fps')
        return 0
    stamps, poses = read_topic(args.bag, args.topic, motion_to_pose, 'motion')
    fps = args.fps or (1e9 / float(np.median(np.diff(stamps))) if len(stamps) > 1 else 30.0)
    # one skeleton for the file: the last estimate (the lifter holds it after a while)
    skeleton = poses[-1].skeleton
    out = write_bvh(args.output, skeleton, np.stack([p.rotations for p in poses]),
                    np.stack([p.root_position for p in poses]), fps, frame=args.frame)
    print(f'wrote {out}: {len(poses)} frames at {fps:.2f} fps')
    return 0


def cmd_plot_motion(args: argparse.Namespace) -> int:
    """Plot the skeleton of a motion topic (MultiDOFJointTrajectory) at a few frames."""
    from ..plots import plot_motion_frames
    from ..ros_conversions import motion_to_pose

    stamps, poses = read_topic(args.bag, args.topic, motion_to_pose, 'motion')
    out = plot_motion_frames([t * 1e-9 for t in stamps],
                             np.stack([p.joint_positions() for p in poses]),
                             poses[-1].skeleton.parents, args.output, frame=args.frame,
                             title=f'{args.topic} ({len(poses)} frames)')
    print(f'wrote {out}')
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    """Figures, plots, the side-by-side video and a Markdown report of a pipeline run."""
    import json

    from ..bag_io import BagError
    from ..demo_render import plot_run, render_video, report_markdown
    from ..run_report import accuracy, load_run, plausibility

    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    try:
        run = load_run(args.bag)
    except BagError as exc:
        raise CommandError(str(exc)) from None
    if not run.stages:
        raise CommandError(f'{args.bag} has no /mocap/<stage>/motion topic: not a pipeline run')
    plaus, acc = plausibility(run), accuracy(run)
    (out / 'report.json').write_text(json.dumps({'plausibility': plaus, 'accuracy': acc,
                                                 'diagnostics': run.diagnostics}, indent=1))
    written = {k: str(v) for k, v in plot_run(run, out).items()}
    notes = list(args.note)
    if args.video:
        if 'world' not in run.stages:
            raise CommandError('--video needs the world stage (/mocap/world/motion)')
        n = render_video(run, Path(args.video), out / 'pipeline.mp4', out / 'pipeline_frames.png')
        written.update(video=str(out / 'pipeline.mp4'), frames=str(out / 'pipeline_frames.png'))
        notes.append(f'video: `pipeline.mp4` ({n} frames), a few of them in '
                     '`pipeline_frames.png`')
    (out / 'report.md').write_text(report_markdown(run, plaus, acc, args.title, notes,
                                                   args.wall_seconds))
    for _key, path in sorted(written.items()):
        print(f'wrote {path}')
    print(f"wrote {out / 'report.md'}")
    return 0


def run_model_cli(commands, prog: str, argv: Optional[List[str]] = None) -> int:
    """``python -m <package>.cli train|eval ...`` for one model package: the same commands as
    ``mocap train|eval`` built from its ``add_train_parser`` / ``add_eval_parser``."""
    parser = argparse.ArgumentParser(prog=prog)
    sub = parser.add_subparsers(dest='command', required=True)
    commands.add_train_parser(sub.add_parser('train').add_subparsers(dest='what', required=True))
    commands.add_eval_parser(sub.add_parser('eval').add_subparsers(dest='what', required=True))
    args = parser.parse_args(argv)
    return args.func(args)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='mocap', description='Monocular motion capture pipeline: tools.')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND')

    p = sub.add_parser('doctor', help='check the installation')
    p.set_defaults(func=cmd_doctor)

    p = sub.add_parser('bag', help='bag tools')
    bag_sub = p.add_subparsers(dest='bag_command', metavar='BAG_COMMAND')
    pc = bag_sub.add_parser('check', help='per-topic counts and rates; validate every '
                            'message of the pipeline topics')
    pc.add_argument('bag', help='rosbag2 folder (MCAP) or .mcap file')
    pc.set_defaults(func=cmd_bag_check)

    p = sub.add_parser('plot', help='figures from bags')
    plot_sub = p.add_subparsers(dest='plot_command', metavar='PLOT_COMMAND')
    pk = plot_sub.add_parser('keypoints', help='2D skeletons at a few frames and the '
                             'confidence over time')
    pk.add_argument('bag', help='rosbag2 folder (MCAP) or .mcap file')
    pk.add_argument('-o', '--output', default='keypoints.png', help='output PNG')
    pk.add_argument('--topic', default=topics.KEYPOINTS, help='keypoint topic')
    pk.set_defaults(func=cmd_plot_keypoints)
    pm = plot_sub.add_parser('motion', help='3D skeleton of a motion topic, front and side '
                             'views at a few frames')
    pm.add_argument('bag', help='rosbag2 folder (MCAP) or .mcap file')
    pm.add_argument('-o', '--output', default='motion.png', help='output PNG')
    pm.add_argument('--topic', default=topics.LIFTER_MOTION, help='motion topic')
    pm.add_argument('--frame', choices=('camera', 'world'), default='camera',
                    help="the topic's frame: camera optical frame or z-up world")
    pm.set_defaults(func=cmd_plot_motion)

    p = sub.add_parser('skeleton', help='the default skeleton and its URDF')
    p.add_argument('--urdf', metavar='FILE', help="write the URDF to FILE ('-' = stdout)")
    p.add_argument('--body-mass', type=float, default=70.0, help='body mass, kg (default 70)')
    p.set_defaults(func=cmd_skeleton)

    from .mocap_data import add_data_parser
    add_data_parser(sub)

    from .process import add_parser as add_process_parser
    add_process_parser(sub)
    from .run import add_parser as add_run_parser
    add_run_parser(sub)

    from .bench import add_parser as add_bench_parser
    add_bench_parser(sub)

    p = sub.add_parser('report', help='report, plots and video of a pipeline run (output bag)')
    p.add_argument('bag', help='output bag of mocap process or a recording of the nodes')
    p.add_argument('-o', '--output', default='report', help='output folder')
    p.add_argument('--video', help='the input video: also write pipeline.mp4 (frames with '
                   'keypoints beside the world skeleton) and pipeline_frames.png')
    p.add_argument('--title', default='Pipeline run', help='report title')
    p.add_argument('--note', action='append', default=[], help='a line for the report')
    p.add_argument('--wall-seconds', type=float, help='wall time of the run, for the rate')
    p.set_defaults(func=cmd_report)

    p = sub.add_parser('export', help='export motion to other formats')
    export_sub = p.add_subparsers(dest='export_command', metavar='FORMAT')
    pb = export_sub.add_parser('bvh', help='a motion topic of a bag as a BVH file (y up, cm)')
    pb.add_argument('bag', help='rosbag2 folder (MCAP) or .mcap file')
    pb.add_argument('-o', '--output', default='motion.bvh', help='output BVH file')
    pb.add_argument('--topic', default=topics.LIFTER_MOTION, help='motion topic')
    pb.add_argument('--frame', choices=('camera', 'world'), default='camera',
                    help="the topic's frame: camera optical frame or z-up world")
    pb.add_argument('--fps', type=float, help='frame rate (default: from the stamps)')
    pb.add_argument('--per-person', action='store_true',
                    help='one BVH per person (<output>_body_<id>.bvh) from the stage\'s '
                    'combined topic (/mocap/<stage>/bodies/motion)')
    pb.add_argument('--bodies-topic', help='the combined topic (default: beside --topic)')
    pb.set_defaults(func=cmd_export_bvh)

    # Training and evaluation commands live with their models, in the node packages, which
    # register them as entry points (mocap_core.plugins).
    train_sub = sub.add_parser('train', help='train a model').add_subparsers(
        dest='model', metavar='MODEL')
    eval_sub = sub.add_parser('eval', help='evaluate a model').add_subparsers(
        dest='model', metavar='MODEL')
    from .. import plugins
    from . import eval_people, eval_video
    eval_video.add_eval_parser(eval_sub)  # the whole pipeline, from the core
    eval_people.add_eval_parser(eval_sub)  # several people: detector and tracker
    for commands in plugins.command_modules():
        commands.add_train_parser(train_sub)
        commands.add_eval_parser(eval_sub)
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    from .. import plugins
    if len(argv) >= 2 and argv[0] == 'bench' and argv[1] in plugins.benches():
        # the per-node benchmarks parse their own options (--help included)
        return plugins.run_bench(argv[1], argv[2:])
    parser = build_parser()
    args = parser.parse_args(argv)
    if not hasattr(args, 'func'):
        parser.print_help()
        return 0 if args.command is None else 2
    try:
        return int(args.func(args) or 0)
    except CommandError as exc:
        print(f"mocap {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    except (OSError, ValueError) as exc:
        print(f'mocap: error: {exc}', file=sys.stderr)
        return 1


if __name__ == '__main__':
    sys.exit(main())
