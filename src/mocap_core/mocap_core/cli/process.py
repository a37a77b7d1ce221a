"""``mocap process INPUT -o OUT``: the whole pipeline offline, in one process.

INPUT is a rosbag2 folder with MCAP storage (as ``ros2 bag record`` writes it), a single
``.mcap`` file, or a video file. The pipeline starts from what the input holds:

===========  ==================================================  ============================
start        input topic (first one found, in this order)         nodes run
===========  ==================================================  ============================
images       an Image/CompressedImage topic (``--image-topic``)  keypoints, lifter, physics,
             or a video file                                      gmr
keypoints    ``/mocap/keypoints2d`` (+ ``/mocap/camera_info``)     lifter, physics, gmr
lifter       ``/mocap/lifter/motion`` (+ ``/mocap/lifter/contacts``) physics, gmr
physics      ``/mocap/physics/motion`` (+ ``/mocap/physics/floor``,   gmr
             ``/mocap/lifter/contacts``)
===========  ==================================================  ============================

A later start is fed, besides its own topic, what the stages after it read from the bag:
the lifter's contacts (the physics stage's contact labels, the world stage's foot planting),
its unsmoothed motion (the world stage's network pose), the physics floor, the camera-motion
estimate, and every person's ``bodies`` motion with everyone's contacts (only when the bag
holds those contacts).

The nodes are the pipeline's own node classes (the ones ``ros2 run`` starts), wired with
:class:`mocap_core.inprocess.InProcessGraph`: every message is delivered synchronously, in
order, so the run is deterministic, as fast as the machine allows and drops nothing. The output
bag holds the input bag's topics (those the pipeline re-computes excepted) and every topic the
nodes publish (``/diagnostics``: one final status per node). Messages are written with their
header stamp as the bag time (messages without a header: the time of the input message that
caused them).

Node parameters: ``--param NODE.NAME=VALUE`` (NODE = keypoints, lifter, physics, gmr; VALUE in
YAML, e.g. ``--param lifter.mode=causal --param physics.gains_mode=learned``).
"""

from __future__ import annotations

import argparse
import fnmatch
import functools
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

from .. import topics as T
from ..inprocess import SerializedMessage
from ..ros_msgs import header_stamp_ns, msgtype_of
from .inputs import VIDEO_SUFFIXES, is_bag
from ..plugins import PIPELINE as NODES
from ..plugins import PluginError, load_node_class

STAGES = ('images', 'keypoints', 'lifter', 'physics')
IMAGE_TYPES = {'sensor_msgs/msg/Image', 'sensor_msgs/msg/CompressedImage'}
#: Topics each stage's node produces (an input bag's copy of them is not kept).
PRODUCED = {
    'keypoints': (T.KEYPOINTS, T.CAMERA_INFO, T.CAMERA_MOTION),
    'lifter': (T.stage_prefix('lifter'), T.SKELETON_URDF),
    'physics': (T.stage_prefix('physics'),),
    'gmr': (T.stage_prefix('world'),),
}
#: Parameters the offline run sets (overridable with --param).
OFFLINE_DEFAULTS: Dict[str, Dict[str, Any]] = {
    # the mirror check (a second detector pass per frame) where no frame budget forbids it:
    # left and right put right in back views the detector reads as front views
    # (docs/keypoints.md); live it is off, the pass does not fit in 30 fps on two cores
    'keypoints': {'synchronous': True, 'realtime': False, 'mirror_check': True},
    # several frames per network pass: the lifter's output is the same as frame by frame,
    # GMR's earlier frames of a chunk see more future frames than the look-ahead
    'lifter': {'chunk': 16},
    'gmr': {'chunk': 16},
    # a motion frame waits for its contacts by message order, not by wall-clock time
    'physics': {'contacts_wait_s': 5.0},
}


class ProcessError(Exception):
    """A problem with the input or the options: one line for the user."""


@dataclass
class Plan:
    """What to run on an input."""

    start: str                       # one of STAGES
    nodes: List[str]                 # node names, upstream first
    feed_topics: List[str]           # input topics delivered to the nodes
    video: Optional[Path] = None
    image_topic: str = ''
    dropped_topics: List[str] = field(default_factory=list)


def is_video(path: Path) -> bool:
    return path.is_file() and path.suffix.lower() in VIDEO_SUFFIXES


def plan_for(topics: Dict[str, str], start: str = 'auto', image_topic: str = '',
             video: Optional[Path] = None) -> Plan:
    """Choose the first stage from the input's topics (name -> type) or a video file.

    Raises ProcessError when the input holds nothing the pipeline can start from."""
    if video is not None:
        if start not in ('auto', 'images'):
            raise ProcessError(f'a video input starts at images, not {start}')
        return Plan('images', list(NODES), [], video=video)
    images = [t for t, ty in sorted(topics.items()) if ty in IMAGE_TYPES]
    if image_topic:
        if image_topic not in topics:
            raise ProcessError(f'--image-topic {image_topic} is not in the input')
        images = [image_topic]
    elif T.IMAGE in images:
        images = [T.IMAGE]
    available = {
        'images': bool(images),
        'keypoints': T.KEYPOINTS in topics,
        'lifter': T.LIFTER_MOTION in topics,
        'physics': T.PHYSICS_MOTION in topics,
    }
    if start == 'auto':
        start = next((s for s in STAGES if available[s]), '')
        if not start:
            raise ProcessError(
                'nothing to start from: the input has no image topic, /mocap/keypoints2d, '
                f"/mocap/lifter/motion or /mocap/physics/motion (topics: "
                f"{', '.join(sorted(topics)) or 'none'})")
    elif start not in STAGES:
        raise ProcessError(f'unknown start stage {start!r} (use auto or {", ".join(STAGES)})')
    elif not available[start]:
        raise ProcessError(f'--start {start}: the input lacks its topic')
    if start == 'images' and len(images) > 1:
        raise ProcessError(f"several image topics ({', '.join(images)}): choose one with "
                           '--image-topic')
    nodes = list(NODES[STAGES.index(start):])
    # what the stages after the start read besides the start's own topic: the lifter's
    # contacts (the physics stage's contact labels, the world stage's foot planting), its
    # unsmoothed motion (the world stage's network), the floor, and the same per person
    lifter_contacts = (T.LIFTER_CONTACTS, T.bodies_topic('lifter', 'contacts'))
    feed = [images[:1] + [T.IMAGE_CAMERA_INFO],
            [T.KEYPOINTS, T.CAMERA_INFO],
            [T.LIFTER_MOTION, T.bodies_topic('lifter', 'motion'), *lifter_contacts,
             T.LIFTER_UNSMOOTHED_MOTION, T.bodies_topic('lifter', 'unsmoothed_motion')],
            [T.PHYSICS_MOTION, T.bodies_topic('physics', 'motion'), T.PHYSICS_FLOOR,
             *lifter_contacts, T.LIFTER_UNSMOOTHED_MOTION,   # (the world stage's network
             T.bodies_topic('lifter', 'unsmoothed_motion')]][STAGES.index(start)]   # pose)
    feed = feed[:1] + [t for t in feed[1:] if t in topics]
    if T.bodies_topic('lifter', 'contacts') not in topics:
        # everyone's motion without everyone's contacts (a bag recorded with --topics): the
        # one person's motion and contacts, which the stages read together
        feed = [t for t in feed if t not in (T.bodies_topic('lifter', 'motion'),
                                             T.bodies_topic('physics', 'motion'),
                                             T.bodies_topic('lifter', 'unsmoothed_motion'))]
    if start != 'images' and T.CAMERA_MOTION in topics:    # for the world stage
        feed.append(T.CAMERA_MOTION)
    produced = [p for n in nodes for p in PRODUCED[n]]
    dropped = [t for t in sorted(topics) if t not in feed and any(
        t == p or (p.endswith('/') and t.startswith(p)) for p in produced)]
    return Plan(start, nodes, feed, image_topic=images[0] if start == 'images' else '',
                dropped_topics=dropped)


def parse_params(items: List[str]) -> Dict[str, Dict[str, Any]]:
    """``NODE.NAME=VALUE`` strings -> {node: {name: value}} (VALUE parsed as YAML)."""
    import yaml

    out: Dict[str, Dict[str, Any]] = {n: {} for n in NODES}
    for item in items:
        key, sep, value = item.partition('=')
        node, dot, name = key.partition('.')
        if not sep or not dot or node not in NODES or not name:
            raise ProcessError(f'--param {item!r}: expected NODE.NAME=VALUE with NODE one of '
                               f'{", ".join(NODES)}')
        try:
            out[node][name] = yaml.safe_load(value) if value != '' else ''
        except yaml.YAMLError as exc:
            raise ProcessError(f'--param {item!r}: bad value ({exc})') from None
    return out


def _overrides(values: Dict[str, Any]) -> List[Any]:
    from rclpy.parameter import Parameter

    return [Parameter(k, value=v) for k, v in values.items()]


def unknown_params(node: Any, name: str, values: Dict[str, Any]) -> Optional[str]:
    """The message for ``--param`` names that ``node`` (the ``name`` stage) does not declare,
    or None when it declares all of them. rclpy drops an override of an undeclared
    parameter without a word, so a misspelt ``--param`` would silently run the defaults."""
    import difflib

    missing = [k for k in values if not node.has_parameter(k)]
    if not missing:
        return None
    declared = sorted(node._parameters)  # noqa: SLF001 - rclpy keeps no public list of names
    hints = []
    for k in missing:
        close = difflib.get_close_matches(k, declared, n=3)
        hints.append(f'{name}.{k}' + (f' (did you mean {", ".join(close)}?)' if close else ''))
    return (f'unknown parameter{"s" if len(missing) > 1 else ""} of the {name} node: '
            f'{"; ".join(hints)} (`ros2 param list` on the running node, or the node\'s '
            'README, lists them)')


class Recorder:
    """Writes every message the graph sees to the output bag (see the module doc)."""

    def __init__(self, writer, exclude: Tuple[str, ...] = (),
                 only: Optional[Sequence[str]] = None) -> None:
        self.writer = writer
        self.now_ns = 0
        self.counts: Dict[str, int] = {}
        self.exclude = set(exclude)
        #: glob patterns of the topics to write (None: all)
        self.only = None if only is None else list(only)
        self._selected: Dict[str, bool] = {}

    def selected(self, topic: str) -> bool:
        """Whether ``topic`` is among those to write (``only``)."""
        chosen = self._selected.get(topic)
        if chosen is None:
            chosen = self.only is None or any(fnmatch.fnmatchcase(topic, p) for p in self.only)
            self._selected[topic] = chosen
        return chosen

    def wants(self, topic: str) -> bool:
        """Whether this recorder writes ``topic`` (the input topics that the driver copies
        are excluded). The graph counts the recorder as a subscriber of these topics only,
        so the nodes build no other optional output."""
        return topic not in self.exclude and self.selected(topic)

    def unmatched(self) -> List[str]:
        """The ``only`` patterns that matched no topic seen so far."""
        seen = list(self._selected)
        return [p for p in (self.only or []) if not any(fnmatch.fnmatchcase(t, p)
                                                          for t in seen)]

    def __call__(self, topic: str, msg: Any, qos: Any) -> None:
        """``msg``: a message, or a SerializedMessage (the graph hands them on raw)."""
        if not self.wants(topic):
            return
        if isinstance(msg, SerializedMessage):
            if topic not in self.writer.topics:
                self.writer.add_topic(topic, msgtype_of(msg.msg_type), qos)
            data = msg.data + bytes(-len(msg.data) % 4)     # as serialize() pads
            stamp_ns = header_stamp_ns(msg.data, msg.msg_type)
            if stamp_ns is None and _header_field(msg.msg_type) is not None:
                stamp_ns = _stamp_ns(msg.message())
        else:
            data = None
            stamp_ns = _stamp_ns(msg)
        ts = self.now_ns
        if stamp_ns is not None and topic != T.DIAGNOSTICS:
            ts = stamp_ns or self.now_ns
        if data is None:
            self.writer.write_msg(topic, ts, msg, qos)
        else:
            self.writer.write(topic, ts, data)
        self.counts[topic] = self.counts.get(topic, 0) + 1


@functools.lru_cache(maxsize=None)
def _header_field(msg_type: type) -> Any:
    return msg_type.get_fields_and_field_types().get('header')


def _stamp_ns(msg: Any) -> Optional[int]:
    """The header stamp of a message (ns), None for a message without a header."""
    stamp = getattr(getattr(msg, 'header', None), 'stamp', None)
    return None if stamp is None else int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def process(input_path: Path, output: Path, *, start: str = 'auto', image_topic: str = '',
            params: Optional[Dict[str, Dict[str, Any]]] = None, overwrite: bool = False,
            record_images: bool = False, progress: bool = True, log=print,
            log_level: str = 'info', topics_out: Optional[Sequence[str]] = None
            ) -> Dict[str, Any]:
    """Run the pipeline on ``input_path`` and write ``output``; returns a summary dict
    (plan, frames, seconds, per-topic counts of the output, problems).

    ``topics_out``: glob patterns (``fnmatch``, e.g. ``/mocap/world/*``) of the topics to
    write, None = every topic. The nodes then build only the optional outputs that are
    written (or that another node reads)."""
    import rclpy
    from rclpy.context import Context

    from ..bag_io import BagError, BagReader, BagWriter
    from ..inprocess import InProcessGraph
    from ..ros_msgs import deserialize, get_message_class

    params = params or {n: {} for n in NODES}
    video = input_path if is_video(input_path) else None
    reader = None
    topics: Dict[str, str] = {}
    infos = {}
    if video is None:
        if not input_path.exists():
            raise ProcessError(f'input {input_path} does not exist')
        try:
            reader = BagReader(input_path)
        except BagError as exc:
            raise ProcessError(f'cannot read the input bag: {exc}') from None
        infos = reader.topics
        topics = {t: i.msgtype for t, i in infos.items()}
    problems: List[str] = []
    for warning in (reader.warnings if reader is not None else []):
        problems.append(warning)
        log(f'  warning: {warning}')
    plan = plan_for(topics, start, image_topic, video)
    for node_params in params.values():         # a known camera pose for the stages
        pose_topic = str(node_params.get('camera_pose_topic', '') or '')
        if pose_topic and pose_topic in topics and pose_topic not in plan.feed_topics:
            plan.feed_topics.append(pose_topic)
    log(f'mocap process: {input_path} -> {output}; start: {plan.start}; nodes: '
        f"{', '.join(plan.nodes)}" + (f"; feeding {', '.join(plan.feed_topics)}"
                                     if plan.feed_topics else ''))
    for t in plan.dropped_topics:
        log(f'  input topic {t} is re-computed by the pipeline: its input copy is not kept')

    # A private context: the nodes' DDS participant is local to this process.
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    context = Context()
    rclpy.init(args=['--ros-args', '--log-level', log_level], context=context)
    nodes: Dict[str, Any] = {}
    summary: Dict[str, Any] = {'input': str(input_path), 'output': str(output),
                               'start': plan.start, 'nodes': plan.nodes}
    try:
        writer = BagWriter(output, overwrite=overwrite)
    except BagError as exc:
        context.try_shutdown()
        raise ProcessError(str(exc)) from None
    try:
        recorder = Recorder(writer, exclude=tuple(plan.feed_topics), only=topics_out)

        def on_error(node: str, topic: str, exc: BaseException) -> None:
            text = f'{node} failed on a {topic} message: {type(exc).__name__}: {exc}'
            problems.append(text)
            log(f'  warning: {text}')

        graph = InProcessGraph(record=recorder, on_error=on_error, record_raw=True,
                              record_filter=recorder.wants)
        driver = rclpy.create_node('mocap_process', context=context)
        feeders = {}
        for t in plan.feed_topics:
            feeders[t] = driver.create_publisher(get_message_class(topics[t]), t, 10)
        graph.add(driver)
        for name in plan.nodes:
            values = dict(OFFLINE_DEFAULTS.get(name, {}))
            if name == 'keypoints':
                if video is not None:
                    values.update(source='video', path=str(video))
                else:
                    values.update(source='topic', image_topic=plan.image_topic)
            values.update(params.get(name, {}))
            try:
                cls = load_node_class(name)
            except PluginError as exc:
                raise ProcessError(str(exc)) from None
            try:
                nodes[name] = graph.add(cls(context=context,
                                            parameter_overrides=_overrides(values)))
            except Exception as exc:  # noqa: BLE001 - e.g. a bad parameter value
                raise ProcessError(f'cannot start the {name} node: {type(exc).__name__}: '
                                   f'{exc}') from None
            bad = unknown_params(nodes[name], name, params.get(name, {}))
            if bad:
                raise ProcessError(bad)
        t0 = time.perf_counter()
        frames = 0
        if video is not None:
            frames = _run_video(nodes['keypoints'], graph, recorder, writer, record_images,
                                progress)
        else:
            frames = _run_bag(reader, infos, plan, feeders, graph, recorder, writer, problems,
                              progress, log, deserialize)
        graph.flush()
        for node in nodes.values():
            diag = getattr(node, 'diag', None)
            if diag is not None:
                diag.publish()
        seconds = time.perf_counter() - t0
        for pattern in recorder.unmatched():
            problems.append(f'--topics {pattern}: no such topic')
            log(f'  warning: --topics {pattern} matched no topic of this run')
        summary.update(frames=frames, seconds=seconds,
                       fps=frames / seconds if seconds > 0 else float('nan'),
                       topics=dict(sorted(recorder.counts.items())), problems=problems)
    finally:
        writer.close()
        if reader is not None:
            reader.close()
        for node in nodes.values():
            shutdown = getattr(node, 'shutdown', None)
            if shutdown is not None:
                shutdown()
            node.destroy_node()
        context.try_shutdown()
    return summary


def _run_bag(reader, infos, plan: Plan, feeders, graph, recorder, writer, problems,
             progress: bool, log, deserialize) -> int:
    from tqdm import tqdm

    from ..bag_io import BagError

    written = [t for t in infos if t not in plan.dropped_topics and recorder.selected(t)]
    for t in written:
        i = infos[t]
        writer.add_topic(t, i.msgtype, i.qos, msgdef=i.msgdef, type_hash=i.type_hash)
    keep = [t for t in infos if t in written or t in feeders]
    written = set(written)
    first = plan.feed_topics[0]
    total = infos[first].count
    frames = 0
    bad = 0
    bar = tqdm(total=total, desc='mocap process', unit='frame', disable=not progress)
    try:
        for m in reader.messages(topics=keep):
            recorder.now_ns = m.timestamp_ns
            if m.topic in written:
                writer.write(m.topic, m.timestamp_ns, m.data)
            if m.topic not in feeders:
                continue
            try:
                msg = deserialize(m.data, m.msgtype)
            except Exception as exc:  # noqa: BLE001 - a corrupt message is skipped, counted
                bad += 1
                if bad <= 5:
                    log(f'  warning: cannot decode a {m.topic} message at '
                        f'{m.timestamp_ns} ns ({type(exc).__name__}: {exc}); skipped')
                continue
            feeders[m.topic].publish(msg)
            if m.topic == first:
                frames += 1
                bar.update(1)
    except BagError as exc:
        text = f'the input bag ends early: {exc} (processed what came before)'
        problems.append(text)
        log(f'  warning: {text}')
    finally:
        bar.close()
    if bad:
        problems.append(f'{bad} input messages could not be decoded')
    return frames


def _run_video(node, graph, recorder, writer, record_images: bool, progress: bool) -> int:
    """The keypoint node's file source through the graph (``KeypointNode.run_offline``: the
    detection beside the later stages, in order); the frames also go to the bag with
    ``record_images``."""
    from tqdm import tqdm

    from ..ros_conversions import bgr_to_image, make_header

    def decode(frame) -> None:
        if record_images and frame.image is None and frame.decode is not None:
            frame.image = frame.decode()

    def before_publish(frame) -> None:
        recorder.now_ns = frame.stamp_ns
        if record_images and frame.image is not None:
            header = make_header(frame.stamp_ns, node.frame_id)
            writer.write_msg(T.IMAGE, frame.stamp_ns, bgr_to_image(frame.image, header))

    with tqdm(total=node.frame_count, desc='mocap process', unit='frame',
              disable=not progress) as bar:
        return node.run_offline(before_detect=decode, before_publish=before_publish,
                                after_publish=lambda frame: bar.update(1))


def add_parser(sub) -> None:
    p = sub.add_parser('process', help='run the whole pipeline offline on a bag or a video',
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('input', nargs='+', help='rosbag2 folder (MCAP), .mcap file or video file; '
                   'several, a folder of them or @list.txt: a batch (mocap_core.cli.batch)')
    p.add_argument('-o', '--output', required=True, help='output bag folder (a batch: the '
                   'folder of one output folder per input)')
    p.add_argument('--jobs', type=int, default=1, help='batch: inputs processed at once, each '
                   'in its own process (default 1)')
    p.add_argument('--backend', default='local', choices=('local', 'ray'),
                   help='batch: local (--jobs child processes on this machine) or ray (one '
                   'Ray task per input on a Ray cluster; docs in mocap_core.cli.batch)')
    p.add_argument('--ray-address', default=None,
                   help="backend ray: the cluster to join ('auto', host:port; default: "
                   'start one on this machine for the run)')
    p.add_argument('--start', default='auto', choices=('auto',) + STAGES,
                   help='first stage (default: from the input topics)')
    p.add_argument('--image-topic', default='', help='image topic of the input bag')
    p.add_argument('--param', action='append', default=[], metavar='NODE.NAME=VALUE',
                   help='node parameter (repeatable)')
    p.add_argument('--topics', nargs='+', metavar='TOPIC', default=None,
                   help='write only these topics (glob patterns, e.g. "/mocap/world/*" '
                   '/tf; quote them); the stages then skip building the optional outputs '
                   'that are not written. Default: every topic')
    p.add_argument('--record-images', action='store_true',
                   help='video input: also write the frames to /camera/image_raw')
    p.add_argument('--overwrite', action='store_true', help='replace an existing output')
    p.add_argument('--summary', help='also write the summary as JSON to this file')
    p.add_argument('--no-progress', action='store_true', help='no progress bar')
    p.add_argument('--log-level', default='info', choices=('debug', 'info', 'warn', 'error'),
                   help="the nodes' log level (default info)")
    p.set_defaults(func=cmd_process)


def _cmd_batch(args: argparse.Namespace) -> int:
    from .batch import expand_inputs, run_batch, summary_table, write_summary

    try:
        inputs = expand_inputs(args.input)
        parse_params(args.param)
    except (FileNotFoundError, ProcessError) as exc:
        print(f'mocap process: error: {exc}', file=sys.stderr)
        return 2
    if not inputs:
        print('mocap process: error: no bag or video among the inputs', file=sys.stderr)
        return 2
    extra = []
    if args.start != 'auto':
        extra += ['--start', args.start]
    if args.image_topic:
        extra += ['--image-topic', args.image_topic]
    if args.topics:
        extra += ['--topics', *args.topics]
    t0 = time.monotonic()
    try:
        batch = run_batch(inputs, Path(args.output), args.jobs, args.param,
                          progress=not args.no_progress, extra=extra, backend=args.backend,
                          address=args.ray_address)
    except (RuntimeError, ConnectionError) as exc:      # no Ray, or no cluster there
        print(f'mocap process: error: {exc}', file=sys.stderr)
        return 2
    wall = time.monotonic() - t0
    write_summary(batch, Path(args.output), wall)
    print(summary_table(batch, wall))
    return 1 if any(j.status == 'failed' for j in batch) else 0


def cmd_process(args: argparse.Namespace) -> int:
    import json

    first = Path(args.input[0])
    if (len(args.input) > 1 or args.input[0].startswith('@') or args.jobs > 1 or
            args.backend != 'local' or (first.is_dir() and not is_bag(first))):
        return _cmd_batch(args)
    args.input = args.input[0]
    try:
        params = parse_params(args.param)
        summary = process(Path(args.input), Path(args.output), start=args.start,
                          image_topic=args.image_topic, params=params,
                          overwrite=args.overwrite, record_images=args.record_images,
                          progress=not args.no_progress, log_level=args.log_level,
                          topics_out=args.topics)
    except ProcessError as exc:
        print(f'mocap process: error: {exc}', file=sys.stderr)
        return 2
    print(f"processed {summary['frames']} frames in {summary['seconds']:.1f} s "
          f"({summary['fps']:.1f} frames/s) -> {summary['output']}")
    for topic, n in summary['topics'].items():
        print(f'  {topic}: {n}')
    if args.summary:
        Path(args.summary).write_text(json.dumps(summary, indent=1))
    if summary['problems']:
        print(f"{len(summary['problems'])} problem(s): " + '; '.join(summary['problems']),
              file=sys.stderr)
        return 1
    return 0
