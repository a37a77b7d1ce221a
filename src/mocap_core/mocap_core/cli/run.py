"""``mocap run``: the four nodes live in one process (the composed mode).

The keypoint, lifter, physics and GMR node classes (the ones ``ros2 run`` starts, found through
the ``mocap.nodes`` entry points) run in one process, spun by one executor, and hand their
messages to each other through :class:`mocap_core.inprocess.InProcessGraph` in live mode:
in order, without serialising them and without DDS between the stages. Every topic still
leaves through DDS while a subscriber outside the process listens (RViz, ``ros2 topic echo``,
``ros2 bag record``), and a node builds a message only while someone listens
(:mod:`mocap_core.publishing`).

Usage::

    mocap run --video clip.mp4                     # a video file, played at its rate
    mocap run --camera 0                           # a camera
    mocap run --image-topic /camera/image_raw      # images from a topic
    mocap run --video clip.mp4 --param lifter.mode=causal --param gmr.lookahead=0
    mocap run --camera 0 -- --ros-args -r /mocap/world/motion:=/person/motion
    mocap run --video clip.mp4 --record out_bag --topics '/mocap/world/*'

``--record OUT`` writes what the nodes publish to an MCAP bag, as ``mocap process`` does
(``--topics``: glob patterns of the topics to write, default every topic; the nodes build
only the optional outputs that are written or that someone else listens to), from inside the
process: no DDS subscriber, nothing lost to a best-effort topic. Messages are stamped with
their header stamp (live: the frame's capture time), others with the time they were
published.

Node parameters: ``--param NODE.NAME=VALUE`` (NODE = keypoints, lifter, physics, gmr), or the
usual ``--ros-args -p NODE:NAME:=VALUE`` after ``--``; ``--ros-args`` remappings apply to every
node. The executor is the one ``$MOCAP_EXECUTOR`` names (:mod:`mocap_core.executors`; default
rclpy's events executor). A file source ends the run when it ends (the frames waiting for
look-ahead are emitted first); Ctrl-C ends any run. Exit status: 0, 2 for a bad argument or
a node that cannot start.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence

from .. import plugins


class RunError(RuntimeError):
    """A bad argument or a node that cannot start (one line)."""


def run(params: Dict[str, Dict[str, Any]], ros_args: Optional[List[str]] = None,
        max_seconds: float = 0.0, record: Optional[Path] = None,
        topics_out: Optional[Sequence[str]] = None, overwrite: bool = False,
        log_level: str = '', info: Optional[Dict[str, Any]] = None) -> int:
    """Run the composed pipeline until the source ends, Ctrl-C or ``max_seconds`` (0: no
    limit). With ``record``, every message the wired nodes publish (``topics_out``: glob
    patterns of the topics to write, None = all; the annotated image, published by a side
    node, is not among them) is written to that MCAP bag (``overwrite`` an existing one).
    ``log_level`` (debug, info, warn, error; '' = ROS's default) applies to every node.
    ``info``, a dict, receives how the run ended: ``end`` (the source's reason, or
    'interrupted', 'time limit'), ``failed`` (the source failed), ``published`` and
    ``dropped`` (the keypoint node's counts) and ``source_start_ns`` (the stamp of a file
    source's first frame: frame ``i`` is stamped ``source_start_ns + i / fps``).
    Returns the exit status: 0, 1 when the source failed, 2 for a node that cannot start."""
    import time

    from rclpy.context import Context
    from rclpy.executors import ExternalShutdownException

    from ..executors import close_nodes, init_rclpy, make_executor, spin_until
    from ..guard import record_failure
    from ..inprocess import InProcessGraph
    from .process import _overrides, unknown_params

    writer = recorder = None
    if record is not None:
        from ..bag_io import BagError, BagWriter
        from .process import Recorder
        try:
            writer = BagWriter(record, overwrite=overwrite)
        except BagError as exc:
            raise RunError(str(exc)) from None
        recorder = Recorder(writer, only=topics_out)
    args = list(ros_args or [])
    if log_level:
        args += ['--log-level', log_level]
    context = Context()
    signals = None
    try:
        signals = init_rclpy(['--ros-args', *args] if args else None, context=context)
        executor = make_executor(context=context)
    except BaseException:
        if signals is not None:
            signals.restore()
        context.try_shutdown()
        if writer is not None:
            writer.close()
        raise
    nodes: Dict[str, Any] = {}

    def on_error(node: str, topic: str, exc: BaseException) -> None:
        target = nodes.get(node)
        if target is not None:
            record_failure(target, f'{topic} message', exc)

    def write(topic: str, msg: Any, qos: Any) -> None:
        recorder.now_ns = time.time_ns()        # for messages without a header stamp
        recorder(topic, msg, qos)

    graph = InProcessGraph(on_error=on_error, live=True,
                           record=write if recorder is not None else None, record_raw=True,
                           record_filter=recorder.wants if recorder is not None else None)
    try:
        for name in plugins.PIPELINE:
            try:
                cls = plugins.load_node_class(name)
                nodes[name] = graph.add(cls(context=context,
                                            parameter_overrides=_overrides(params.get(name,
                                                                                      {}))))
            except Exception as exc:  # noqa: BLE001 - a bad parameter, missing weights, ...
                raise RunError(f'cannot start the {name} node: {type(exc).__name__}: '
                               f'{exc}') from None
            bad = unknown_params(nodes[name], name, params.get(name, {}))
            if bad:
                raise RunError(bad)
        graph.seal()
        for node in nodes.values():
            executor.add_node(node)
        source = nodes['keypoints']
        t0 = time.monotonic()
        spin_until(executor,
                   lambda: (context.ok() and not signals.requested
                            and not getattr(source, 'done', False)
                            and not (max_seconds and time.monotonic() - t0 > max_seconds)),
                   lambda exc: record_failure(source, 'callback', exc))
        if signals.requested:
            _fill_info(info, source, 'interrupted', False)
            return 0
        drain = getattr(source, '_drain', None)
        if drain is not None:
            drain()
        graph.flush()               # the frames still waiting for look-ahead
        for _ in range(5):          # let the last messages leave
            executor.spin_once(timeout_sec=0.05)
        reason, error = getattr(source, 'source_end', None) or (
            'time limit' if max_seconds and time.monotonic() - t0 > max_seconds
            else 'stopped', None)
        _fill_info(info, source, reason, error is not None)
        summary = getattr(source, 'summary', None)
        text = summary() if summary is not None else ''
        if error is not None:
            source.get_logger().error(f'source failed: {reason} ({text})')
            return 1
        if text:
            source.get_logger().info(f'finished: {text}')
        return 0
    except (KeyboardInterrupt, ExternalShutdownException):
        _fill_info(info, nodes.get('keypoints'), 'interrupted', False)
        return 0
    finally:
        def close_writer() -> None:
            if writer is not None:
                writer.close()
                for pattern in recorder.unmatched():
                    print(f'mocap run: warning: no topic matched --topics {pattern}',
                          file=sys.stderr)

        stops = [node.shutdown for node in nodes.values()
                 if callable(getattr(node, 'shutdown', None))]
        try:
            # (a library call: a hang is reported, the caller's process is never ended)
            close_nodes(executor, list(nodes.values()), context=context,
                        before=[*stops, close_writer], label='mocap run', hard_exit=False)
        finally:
            signals.restore()


def _fill_info(info: Optional[Dict[str, Any]], source: Any, end: str, failed: bool) -> None:
    """How the run ended, for :func:`run`'s ``info``."""
    if info is None:
        return
    info.update(end=end, failed=failed)
    if source is not None:
        info['published'] = int(getattr(source, 'published', 0))
        diag = getattr(source, 'diag', None)
        info['dropped'] = int(getattr(diag, 'dropped', 0)) if diag is not None else 0
        start = getattr(getattr(source, 'source', None), 'start_ns', None)
        info['source_start_ns'] = int(start) if start is not None else None


def add_parser(sub) -> None:
    p = sub.add_parser('run', help='the four nodes live in one process (composed mode)',
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    src = p.add_mutually_exclusive_group()
    src.add_argument('--video', help='a video file (played at its frame rate)')
    src.add_argument('--camera', help='an OpenCV camera index, /dev/videoN or a stream URL')
    src.add_argument('--image-topic', help='sensor_msgs/Image (or .../compressed) topic')
    p.add_argument('--loop', action='store_true', help='video: play it again at the end')
    p.add_argument('--param', action='append', default=[], metavar='NODE.NAME=VALUE',
                   help='node parameter (repeatable)')
    p.add_argument('--seconds', type=float, default=0.0, help='stop after this long (0: no '
                   'limit)')
    p.add_argument('--record', metavar='OUT', help='write the published messages to this '
                   'MCAP bag (from inside the process; see above)')
    p.add_argument('--topics', nargs='+', metavar='TOPIC', help='with --record: glob patterns '
                   'of the topics to write (default every topic)')
    p.add_argument('--overwrite', action='store_true', help='with --record: replace OUT')
    p.add_argument('ros_args', nargs=argparse.REMAINDER,
                   help='after --: --ros-args ... for every node (remappings, parameters)')
    p.set_defaults(func=cmd_run)


def cmd_run(args: argparse.Namespace) -> int:
    from .process import ProcessError, parse_params

    try:
        params = parse_params(args.param)
    except ProcessError as exc:
        print(f'mocap run: error: {exc}', file=sys.stderr)
        return 2
    kp = params.setdefault('keypoints', {})
    if args.video:
        kp.setdefault('source', 'video')
        kp.setdefault('path', args.video)
        kp.setdefault('loop', bool(args.loop))
    elif args.camera:
        kp.setdefault('source', 'camera')
        kp.setdefault('device', args.camera)
    elif args.image_topic:
        kp.setdefault('source', 'topic')
        kp.setdefault('image_topic', args.image_topic)
    extra = [a for a in args.ros_args if a != '--']
    if extra and extra[0] == '--ros-args':
        extra = extra[1:]
    if args.topics and not args.record:
        print('mocap run: error: --topics needs --record', file=sys.stderr)
        return 2
    try:
        return run(params, extra, args.seconds,
                   record=Path(args.record) if args.record else None, topics_out=args.topics,
                   overwrite=args.overwrite)
    except RunError as exc:
        print(f'mocap run: error: {exc}', file=sys.stderr)
        return 2
