"""A small ``ros2`` command for machines without the ROS 2 command line (pip-installed ROS).

It implements the verbs this project's users need, with the options and output of the real
``ros2`` where they overlap::

    ros2 run <package> <executable> [args ...]
    ros2 bag play <bag> [-r RATE] [-l] [--topics T ...] [--start-offset S] [-d DELAY]
                        [-m FROM:=TO ...] [--wait-for-all-acked MS]
    ros2 bag record [-o OUT] (-a | -e REGEX | TOPIC ...)
    ros2 bag info <bag>
    ros2 topic list [-t] [-c]
    ros2 topic echo <topic> [type] [--once] [--qos-* ...] [--no-arr] [--no-str]
    ros2 topic hz <topic> [-w WINDOW]

When a real ``ros2`` is on the PATH (a ROS 2 install), this command hands over to it at once
(``os.execv``), so it never shadows the real tools; set ``MOCAP_ROS2_NO_DEFER=1`` to use this
one anyway.

Bags are rosbag2 folders with MCAP storage (what ``ros2 bag record`` writes); ``bag play`` and
``bag info`` also take a single ``.mcap`` file. Messages are copied as raw CDR bytes, so a
play -> record round trip is byte-identical.
"""

from __future__ import annotations

import argparse
import datetime
import math
import os
import re
import shlex
import signal
import sys
import time
from collections import deque
from typing import Any, Callable, Sequence

NO_DEFER_ENV = 'MOCAP_ROS2_NO_DEFER'
DEBUG_ENV = 'MOCAP_ROS2_DEBUG'


class CliError(Exception):
    """A user error: printed as one line, exit status 1."""


# --- handing over to a real ros2 -----------------------------------------------------------------

def _is_this_tool(path: str) -> bool:
    """True if ``path`` is this command (a console-script wrapper of mocap_core)."""
    try:
        with open(path, 'rb') as stream:
            head = stream.read(4096)
    except OSError:
        return True  # unreadable: do not hand over to it
    return b'mocap_core' in head or b'mocap-core' in head


def find_real_ros2() -> str | None:
    """The first ``ros2`` on the PATH that is not this tool, or None."""
    mine = {os.path.realpath(p) for p in (sys.argv[0], __file__) if p}
    for entry in os.environ.get('PATH', '').split(os.pathsep):
        candidate = os.path.join(entry or '.', 'ros2')
        if not (os.path.isfile(candidate) and os.access(candidate, os.X_OK)):
            continue
        real = os.path.realpath(candidate)
        if real in mine or _is_this_tool(real):
            continue
        return candidate
    return None


# --- rclpy session ------------------------------------------------------------------------------

class _Ros:
    """An rclpy context whose SIGINT/SIGTERM only set ``stop`` (the loops then end cleanly)."""

    def __init__(self, ros_args: Sequence[str] = ()) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        self.rclpy = rclpy
        self.stop = False
        self.signals = 0
        self.context = Context()
        args = ['ros2', '--ros-args', *ros_args] if ros_args else ['ros2']
        try:
            rclpy.init(args=args, context=self.context,
                       signal_handler_options=SignalHandlerOptions.NO)
        except Exception as exc:
            raise CliError(f'cannot start ROS: {exc}') from None
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes: list[Any] = []
        self._old = {s: signal.signal(s, self._on_signal) for s in (signal.SIGINT, signal.SIGTERM)}

    def _on_signal(self, signum: int, frame: Any) -> None:
        self.signals += 1
        self.stop = True
        if self.signals >= 3:  # third Ctrl-C: give up waiting for a clean end
            raise KeyboardInterrupt

    def node(self, name: str) -> Any:
        node = self.rclpy.create_node(name, context=self.context, start_parameter_services=False)
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def spin(self, seconds: float) -> None:
        """Process callbacks for ``seconds`` (or until stopped)."""
        end = time.monotonic() + seconds
        while not self.stop:
            left = end - time.monotonic()
            if left <= 0:
                break
            self.executor.spin_once(timeout_sec=min(left, 0.05))

    def sleep_until(self, deadline: float) -> None:
        """Wall-clock sleep until ``time.monotonic() >= deadline`` (or until stopped)."""
        while not self.stop:
            left = deadline - time.monotonic()
            if left <= 0:
                return
            time.sleep(min(left, 0.05))

    def close(self) -> None:
        for node in self.nodes:
            try:
                self.executor.remove_node(node)
                node.destroy_node()
            except Exception:
                pass
        try:
            self.executor.shutdown(timeout_sec=1.0)
        except Exception:
            pass
        try:
            self.rclpy.try_shutdown(context=self.context)
        except Exception:
            pass
        for sig, old in self._old.items():
            signal.signal(sig, old)


def _logger(node: Any) -> Any:
    return node.get_logger()


def _absolute(topic: str) -> str:
    topic = topic.strip()
    if not topic:
        raise CliError('empty topic name')
    return topic if topic.startswith('/') else '/' + topic


def _wait_for_topic(ros: _Ros, node: Any, topic: str, msgtype: str | None,
                    timeout: float | None = None) -> tuple[str, list[Any]] | None:
    """Wait until ``topic`` has a publisher; return its type and the publishers' QoS."""
    from ..ros_msgs import normalize_msgtype

    start = time.monotonic()
    told = False
    while not ros.stop:
        types = dict(node.get_topic_names_and_types()).get(topic, [])
        infos = node.get_publishers_info_by_topic(topic) if types else []
        if infos:
            if msgtype is None:
                if len(types) > 1:
                    raise CliError(f"topic '{topic}' has several types ({', '.join(types)}); "
                                   'pass the type to use')
                msgtype = types[0]
            return normalize_msgtype(msgtype), [i.qos_profile for i in infos]
        if not told and time.monotonic() - start > 3.5:
            print(f"WARNING: topic [{topic}] does not appear to be published yet; waiting "
                  '(Ctrl-C to stop)', file=sys.stderr, flush=True)
            told = True
        if timeout is not None and time.monotonic() - start > timeout:
            return None
        ros.spin(0.1)
    return None


# --- ros2 run ------------------------------------------------------------------------------------

def cmd_run(args: argparse.Namespace) -> int:
    from ament_index_python.packages import PackageNotFoundError, get_package_prefix

    try:
        prefix = get_package_prefix(args.package_name)
    except (PackageNotFoundError, ValueError):
        print(f"Package '{args.package_name}' not found", file=sys.stderr)
        return 1
    base = os.path.join(prefix, 'lib', args.package_name)
    found = []
    for dirpath, _, filenames in os.walk(base):
        for filename in filenames:
            path = os.path.join(dirpath, filename)
            if filename == args.executable_name and os.access(path, os.X_OK):
                found.append(path)
    if not found:
        print('No executable found', file=sys.stderr)
        return 1
    if len(found) > 1:
        print('Multiple executables found:', file=sys.stderr)
        for path in sorted(found):
            print(f'- {path}', file=sys.stderr)
        return 1
    cmd = [found[0], *args.argv]
    if args.prefix:
        cmd = [*shlex.split(args.prefix), *cmd]
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        os.execvp(cmd[0], cmd)  # replaces this process: signals go straight to the node
    except OSError as exc:
        print(f"cannot run '{cmd[0]}': {exc.strerror or exc}", file=sys.stderr)
        return 1
    return 1  # not reached


# --- ros2 bag info -------------------------------------------------------------------------------

def _format_size(size: float) -> str:
    units = ['B', 'KiB', 'MiB', 'GiB', 'TiB']
    index = 0
    while size >= 1024 and index < len(units) - 1:
        size /= 1024
        index += 1
    return f'{size:.{0 if index == 0 else 1}f} {units[index]}'


def _format_time(ns: int) -> str:
    sec, nsec = divmod(ns, 1_000_000_000)
    local = datetime.datetime.fromtimestamp(sec)
    return f"{local.strftime('%b %e %Y %H:%M:%S')}.{nsec:09d} ({sec}.{nsec:09d})"


def _warn(lines: Sequence[str]) -> None:
    for line in lines:
        print(f'[WARN] {line}', file=sys.stderr)


def cmd_bag_info(args: argparse.Namespace) -> int:
    from ..bag_io import BagReader

    with BagReader(args.bag_path) as bag:
        _warn(bag.warnings)
        topics = bag.topics
        if args.topic_name:
            for name in topics:
                print(name)
            return 0
        indent = ' ' * 19
        files = [str(f) for f in bag.files] or ['']
        out = ['', f'Files:             {files[0]}']
        out += [f'{indent}{f}' for f in files[1:]]
        duration = bag.duration_ns
        out += [
            f'Bag size:          {_format_size(bag.size_bytes)}',
            f'Storage id:        {bag.storage_id}',
            f'ROS Distro:        {bag.ros_distro or "unknown"}',
            f'Duration:          {duration // 1_000_000_000}.{duration % 1_000_000_000:09d}s',
            f'Start:             {_format_time(bag.start_ns)}',
            f'End:               {_format_time(bag.end_ns)}',
            f'Messages:          {bag.message_count}',
        ]
        lines = [f'Topic: {t.name} | Type: {t.msgtype} | Count: {t.count} | '
                 f'Serialization Format: {t.serialization_format}' for t in topics.values()]
        out.append('Topic information: ' + (lines[0] if lines else ''))
        out += [f'{indent}{line}' for line in lines[1:]]
        out += ['Service:           0', 'Service information: ']
        print('\n'.join(out))
    return 0


# --- ros2 bag play -------------------------------------------------------------------------------

def cmd_bag_play(args: argparse.Namespace) -> int:
    from ..bag_io import BagReader, adapted_qos
    from ..ros_msgs import MessageTypeError, get_message_class

    if not args.rate > 0 or not math.isfinite(args.rate):
        raise CliError(f'rate must be > 0, got {args.rate}')
    if args.delay < 0:
        raise CliError(f'delay must be >= 0, got {args.delay}')
    if args.start_offset < 0:
        raise CliError(f'start offset must be >= 0, got {args.start_offset}')
    remaps: list[str] = []
    for rule in args.remap or []:
        if ':=' not in rule:
            raise CliError(f"invalid remap rule '{rule}' (expected FROM:=TO)")
        remaps += ['-r', rule]

    with BagReader(args.bag_path) as bag:
        _warn(bag.warnings)
        wanted = bag.check_topics(args.topics) if args.topics else set(bag.topics)
        classes = {}
        for name in sorted(wanted):
            info = bag.topics[name]
            try:
                classes[name] = get_message_class(info.msgtype)
            except MessageTypeError as exc:
                print(f"[WARN] Ignoring topic '{name}': {exc}", file=sys.stderr)
        if not classes:
            print('[WARN] nothing to play: no topic of a known message type', file=sys.stderr)
            return 0 if not wanted else 1

        ros = _Ros(remaps)
        try:
            node = ros.node('rosbag2_player')
            log = _logger(node)
            pubs = {}
            for name, cls in classes.items():
                qos = adapted_qos(bag.topics[name].qos, depth=100)
                pubs[name] = node.create_publisher(cls, name, qos)
            start_ns = bag.start_ns + int(round(args.start_offset * 1e9))
            total = sum(bag.topics[n].count for n in classes)
            log.info(f"Playing '{args.bag_path}': {total} messages on {len(classes)} topics "
                     f'at rate {args.rate:g}{" (looping)" if args.loop else ""}')
            played = 0
            while not ros.stop:
                if args.delay > 0:
                    ros.sleep_until(time.monotonic() + args.delay)
                wall0 = time.monotonic()
                this_round = 0
                for msg in bag.messages(list(classes), start_ns=start_ns):
                    ros.sleep_until(wall0 + (msg.timestamp_ns - start_ns) / 1e9 / args.rate)
                    if ros.stop:
                        break
                    pubs[msg.topic].publish(msg.data)
                    this_round += 1
                played += this_round
                if not args.loop or this_round == 0:
                    break
            if args.wait_for_all_acked >= 0 and not ros.signals:
                from rclpy.duration import Duration
                timeout = Duration(nanoseconds=int(args.wait_for_all_acked * 1e6)) \
                    if args.wait_for_all_acked > 0 else Duration(nanoseconds=-1)
                for pub in pubs.values():
                    pub.wait_for_all_acked(timeout)
            log.info(f'Played {played} messages')
        finally:
            ros.close()
    return 0


# --- ros2 bag record -----------------------------------------------------------------------------

_SYSTEM_TOPICS = ('/rosout', '/parameter_events')


def cmd_bag_record(args: argparse.Namespace) -> int:
    from rclpy.topic_or_service_is_hidden import topic_or_service_is_hidden

    from ..bag_io import BagError, BagWriter, adapted_qos
    from ..ros_msgs import MessageTypeError, get_message_class

    named = {_absolute(t) for t in [*(args.topics or []), *(args.topics_opt or [])]}
    try:
        regex = re.compile(args.regex) if args.regex else None
        exclude_re = re.compile(args.exclude_regex) if args.exclude_regex else None
    except re.error as exc:
        raise CliError(f'invalid regular expression: {exc}') from None
    exclude = {_absolute(t) for t in args.exclude_topics or []}
    if not (args.all or named or regex):
        raise CliError('no topics to record: name topics, or use -a/--all or -e/--regex')
    if args.polling_interval <= 0:
        raise CliError('polling interval must be > 0')
    output = args.output or datetime.datetime.now().strftime('rosbag2_%Y_%m_%d-%H_%M_%S')

    def selected(name: str) -> bool:
        if name in exclude or (exclude_re and exclude_re.search(name)):
            return False
        if name in named:
            return True
        if not (args.all or (regex and regex.search(name))):
            return False
        if name in _SYSTEM_TOPICS:
            return False
        return args.include_hidden_topics or not topic_or_service_is_hidden(name)

    writer = BagWriter(output, storage=args.storage)
    ros = None
    counts: dict[str, int] = {}
    try:
        ros = _Ros()
        node = ros.node('rosbag2_recorder')
        log = _logger(node)
        clock = node.get_clock()
        subscriptions: dict[str, Any] = {}
        ignored: set[str] = set()
        own = (node.get_name(), node.get_namespace())

        def callback_for(topic: str) -> Callable[[bytes], None]:
            def callback(data: bytes) -> None:
                writer.write(topic, clock.now().nanoseconds, data)
                counts[topic] += 1
            return callback

        def discover() -> None:
            for name, types in node.get_topic_names_and_types():
                if name in subscriptions or name in ignored or not selected(name):
                    continue
                if len(types) != 1:
                    log.warning(f"Topic '{name}' has several types ({', '.join(types)}); "
                                'not recording it')
                    ignored.add(name)
                    continue
                infos = [i for i in node.get_publishers_info_by_topic(name)
                         if (i.node_name, i.node_namespace) != own]
                if not infos:
                    continue  # no publisher yet: wait to learn its QoS
                try:
                    cls = get_message_class(types[0])
                    offered = [i.qos_profile for i in infos]
                    writer.add_topic(name, types[0], qos=offered)
                except (MessageTypeError, BagError) as exc:
                    log.warning(f"Not recording topic '{name}': {exc}")
                    ignored.add(name)
                    continue
                counts[name] = 0
                subscriptions[name] = node.create_subscription(
                    cls, name, callback_for(name), adapted_qos(offered, depth=1000), raw=True)
                log.info(f"Subscribed to topic '{name}'")

        log.info('Listening for topics...')
        discover()
        log.info('Recording...')
        interval = args.polling_interval / 1000.0
        next_poll = time.monotonic() + interval
        while not ros.stop:
            ros.executor.spin_once(timeout_sec=0.05)
            if not args.no_discovery and time.monotonic() >= next_poll:
                if args.all or regex or not named.issubset(subscriptions):
                    discover()
                next_poll = time.monotonic() + interval
    finally:
        if ros is not None:
            for node in ros.nodes:  # no more callbacks into the writer
                for sub in list(node.subscriptions):
                    node.destroy_subscription(sub)
        try:
            writer.close()
        finally:
            if ros is not None:
                ros.close()
    total = sum(counts.values())
    print(f"[INFO] [rosbag2_recorder]: Recording stopped: {total} messages on {len(counts)} "
          f"topics written to '{output}'", file=sys.stderr)
    return 0


# --- ros2 topic ----------------------------------------------------------------------------------

def _cli_node_name() -> str:
    return f'_ros2cli_{os.getpid()}'


def _discover_topics(ros: _Ros, node: Any, max_wait: float,
                     settle: float = 0.5) -> list[tuple[str, list[str]]]:
    """The graph's topics once discovery has settled (there is no daemon to ask).

    DDS discovery of other processes takes from a few ms to a few s (when the first
    announcements are missed, the next periodic one comes ~3 s later). Returns when other nodes
    have been seen and the topic list has not changed for ``settle`` s, else after ``max_wait``.
    """
    start = time.monotonic()
    topics = sorted(node.get_topic_names_and_types())
    changed = start
    while not ros.stop and time.monotonic() - start < max_wait:
        ros.spin(0.05)
        now_topics = sorted(node.get_topic_names_and_types())
        if now_topics != topics:
            topics, changed = now_topics, time.monotonic()
        others = len(node.get_node_names_and_namespaces()) > 1 or \
            node.count_publishers('/rosout') > 1
        if others and time.monotonic() - changed >= settle:
            break
    return topics


def cmd_topic_list(args: argparse.Namespace) -> int:
    from rclpy.topic_or_service_is_hidden import topic_or_service_is_hidden

    ros = _Ros()
    try:
        node = ros.node(_cli_node_name())
        topics = _discover_topics(ros, node, args.spin_time)
    finally:
        ros.close()
    if not args.include_hidden_topics:
        topics = [(n, t) for n, t in topics if not topic_or_service_is_hidden(n)]
    if args.count_topics:
        print(len(topics))
        return 0
    for name, types in topics:
        print(f"{name} [{', '.join(types)}]" if args.show_types else name)
    return 0


_QOS_PRESETS = {
    'system_default': 'SYSTEM_DEFAULT', 'sensor_data': 'SENSOR_DATA',
    'services_default': 'SERVICES_DEFAULT', 'parameters': 'PARAMETERS',
    'parameter_events': 'PARAMETER_EVENTS', 'action_status_default': 'ACTION_STATUS_DEFAULT',
    'best_available': 'BEST_AVAILABLE', 'default': 'DEFAULT',
}


def _subscription_qos(args: argparse.Namespace, offered: list[Any]) -> Any:
    import copy

    from rclpy import qos as rq

    from ..bag_io import adapted_qos

    if args.qos_profile:
        name = _QOS_PRESETS[args.qos_profile]
        base = getattr(rq, f'qos_profile_{name.lower()}', None)
        profile = copy.copy(base) if base is not None else rq.QoSPresetProfiles[name].value
        profile = rq.QoSProfile(history=profile.history, depth=profile.depth,
                                reliability=profile.reliability, durability=profile.durability)
    else:
        profile = adapted_qos(offered, depth=10)
    if args.qos_depth is not None:
        profile.depth = args.qos_depth
    if args.qos_history:
        profile.history = rq.HistoryPolicy[args.qos_history.upper()]
    if args.qos_reliability:
        profile.reliability = rq.ReliabilityPolicy[args.qos_reliability.upper()]
    if args.qos_durability:
        profile.durability = rq.DurabilityPolicy[args.qos_durability.upper()]
    return profile


def _get_field(msg: Any, path: str) -> Any:
    value = msg
    for part in path.split('.'):
        if not hasattr(value, 'get_fields_and_field_types') or \
                part not in value.get_fields_and_field_types():
            raise CliError(f"invalid field '{path}': no '{part}' in {type(value).__name__}")
        value = getattr(value, part)
    return value


def cmd_topic_echo(args: argparse.Namespace) -> int:
    from ..ros_msgs import _convert, get_message_class, message_to_yaml, value_to_yaml

    topic = _absolute(args.topic_name)
    if args.field is not None:
        args.field = args.field.strip('.')
    truncate = None if args.full_length else args.truncate_length
    ros = _Ros()
    try:
        node = ros.node(_cli_node_name())
        found = _wait_for_topic(ros, node, topic, args.message_type)
        if found is None:
            return 0  # interrupted while waiting
        msgtype, offered = found
        cls = get_message_class(msgtype)
        qos = _subscription_qos(args, offered)
        received = [0]

        def callback(msg: Any) -> None:
            if ros.stop:
                return
            if args.field:
                value = _convert(_get_field(msg, args.field), None, truncate, args.no_arr,
                                 args.no_str)
                text = value_to_yaml(value, flow_style=args.flow_style)
            else:
                text = message_to_yaml(msg, truncate_length=truncate, no_arr=args.no_arr,
                                       no_str=args.no_str, flow_style=args.flow_style)
            sys.stdout.write(text)
            if not text.endswith('\n'):
                sys.stdout.write('\n')
            sys.stdout.write('---\n')
            sys.stdout.flush()
            received[0] += 1
            if args.once:
                ros.stop = True

        node.create_subscription(cls, topic, callback, qos)
        while not ros.stop:
            ros.executor.spin_once(timeout_sec=0.1)
    finally:
        ros.close()
    return 0


def cmd_topic_hz(args: argparse.Namespace) -> int:
    from ..ros_msgs import get_message_class

    topic = _absolute(args.topic_name)
    if args.window < 1:
        raise CliError('window must be >= 1')
    ros = _Ros()
    try:
        node = ros.node(_cli_node_name())
        found = _wait_for_topic(ros, node, topic, None)
        if found is None:
            return 0
        msgtype, offered = found
        cls = get_message_class(msgtype)
        from ..bag_io import adapted_qos

        stamps: deque[float] = deque(maxlen=args.window + 1)
        fresh = [0]

        def callback(_: bytes) -> None:
            stamps.append(time.monotonic())
            fresh[0] += 1

        node.create_subscription(cls, topic, callback, adapted_qos(offered, depth=100),
                                 raw=True)
        next_print = time.monotonic() + 1.0
        while not ros.stop:
            ros.executor.spin_once(timeout_sec=0.05)
            if time.monotonic() < next_print:
                continue
            next_print += 1.0
            if not fresh[0] or len(stamps) < 2:
                continue
            fresh[0] = 0
            times = list(stamps)
            deltas = [b - a for a, b in zip(times, times[1:])]
            mean = sum(deltas) / len(deltas)
            rate = 1.0 / mean if mean > 0 else 0.0
            std = math.sqrt(sum((d - mean) ** 2 for d in deltas) / len(deltas))
            print(f'average rate: {rate:.3f}\n\tmin: {min(deltas):.3f}s max: {max(deltas):.3f}s '
                  f'std dev: {std:.5f}s window: {len(times)}', flush=True)
    finally:
        ros.close()
    return 0


# --- argument parsing ---------------------------------------------------------------------------

class _Parser(argparse.ArgumentParser):
    """argparse that prints the usage line and one error line (exit status 2)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.print_usage(sys.stderr)
        self.exit(2, f'{self.prog}: error: {message}\n')


def _nonneg_int(text: str) -> int:
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f'must be >= 0, got {value}')
    return value


def _add_qos_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--qos-profile', choices=sorted(_QOS_PRESETS),
                        help='QoS preset to start from (default: adapted to the publishers: '
                             'reliable if all are, transient-local if all are)')
    parser.add_argument('--qos-depth', type=_nonneg_int, metavar='N',
                        help='queue size of the subscription')
    parser.add_argument('--qos-history', choices=['system_default', 'keep_last', 'keep_all'])
    parser.add_argument('--qos-reliability',
                        choices=['system_default', 'reliable', 'best_effort', 'best_available'])
    parser.add_argument('--qos-durability',
                        choices=['system_default', 'volatile', 'transient_local',
                                 'best_available'])


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog='ros2',
        description='ros2 is an extensible command-line tool for ROS 2. This is the small '
                    'built-in version of the mocap project (run, bag play|record|info, '
                    'topic list|echo|hz); a real ros2 on the PATH takes precedence '
                    f'(set {NO_DEFER_ENV}=1 to use this one).',
        formatter_class=argparse.RawDescriptionHelpFormatter)
    verbs = parser.add_subparsers(title='Commands', dest='verb', metavar='<command>')

    # run
    run = verbs.add_parser('run', help='Run a package specific executable',
                           description='Run a package specific executable: '
                                       '<prefix>/lib/<package>/<executable> of the first '
                                       'AMENT_PREFIX_PATH entry that has the package.')
    run.add_argument('--prefix', metavar='PREFIX',
                     help="Prefix command, which should go before the executable. Command must "
                          "be wrapped in quotes if it contain spaces (e.g. --prefix 'gdb -ex run "
                          "--args').")
    run.add_argument('package_name', help='Name of the ROS package')
    run.add_argument('executable_name', help='Name of the executable')
    run.add_argument('argv', nargs=argparse.REMAINDER,
                     help='Pass arbitrary arguments to the executable (e.g. --ros-args ...)')
    run.set_defaults(func=cmd_run)

    # bag
    bag = verbs.add_parser('bag', help='Various rosbag related sub-commands',
                           description='Play, record and inspect rosbag2 bags (MCAP storage).')
    bag_verbs = bag.add_subparsers(title='Commands', dest='bag_verb', metavar='<command>')
    bag.set_defaults(func=None, _help=bag.print_help)

    info = bag_verbs.add_parser('info', help='Print information about a bag to the screen')
    info.add_argument('bag_path', help='Bag to open (a folder, or a single .mcap file)')
    info.add_argument('-s', '--storage', choices=['mcap', 'sqlite3'],
                      help='Storage implementation of bag (detected automatically)')
    info.add_argument('-t', '--topic-name', action='store_true',
                      help='Only display topic names.')
    info.set_defaults(func=cmd_bag_info)

    play = bag_verbs.add_parser(
        'play', help='Play back ROS data from a bag',
        description='Publish the messages of a bag with their recorded timing and the '
                    "publishers' recorded QoS (transient-local kept), as raw bytes.")
    play.add_argument('bag_path', help='Bag to open (a folder, or a single .mcap file)')
    play.add_argument('-s', '--storage', choices=['mcap', 'sqlite3'],
                      help='Storage implementation of bag (detected automatically)')
    play.add_argument('-r', '--rate', type=float, default=1.0,
                      help='rate at which to play back messages. Valid range > 0.0.')
    play.add_argument('-l', '--loop', action='store_true',
                      help='enables loop playback when playing a bagfile: it starts back at the '
                           'beginning on reaching the end and plays indefinitely.')
    play.add_argument('--topics', nargs='+', metavar='TOPIC',
                      help='topics to replay, separated by space. If none specified, all topics '
                           'will be replayed.')
    play.add_argument('--start-offset', type=float, default=0.0, metavar='SECONDS',
                      help='Start the playback player this many seconds into the bag file.')
    play.add_argument('-d', '--delay', type=float, default=0.0, metavar='SECONDS',
                      help='Sleep duration before play (each loop), in seconds; gives '
                           'subscribers time to discover the publishers. Negative durations '
                           'invalid.')
    play.add_argument('-m', '--remap', '--remap-topics', nargs='+', metavar='FROM:=TO',
                      help='list of topics to be remapped: in the form '
                           '"old_topic1:=new_topic1 old_topic2:=new_topic2 etc."')
    play.add_argument('--wait-for-all-acked', type=int, default=1000, metavar='TIMEOUT_MS',
                      help='After the last message, wait until all published messages are '
                           'acknowledged by all reliable subscribers or until the timeout (ms) '
                           'elapses; 0 waits forever, negative does not wait (default: 1000).')
    play.set_defaults(func=cmd_bag_play)

    record = bag_verbs.add_parser(
        'record', help='Record ROS data to a bag',
        description='Record topics into a rosbag2 bag (MCAP) with each message as received '
                    '(raw bytes, receive time) and the publishers\' offered QoS. Stops '
                    'cleanly on Ctrl-C or SIGTERM.')
    record.add_argument('topics', nargs='*', metavar='TOPIC',
                        help='List of topics to record.')
    record.add_argument('--topics', dest='topics_opt', nargs='+', metavar='TOPIC',
                        help='List of topics to record (same as the positional form).')
    record.add_argument('-a', '--all', '--all-topics', action='store_true',
                        help='Record all topics (hidden topics, /rosout and /parameter_events '
                             'only when named or with --include-hidden-topics).')
    record.add_argument('-e', '--regex', metavar='REGEX',
                        help='Record only topics matching the regular expression.')
    record.add_argument('--exclude-regex', metavar='REGEX',
                        help='Exclude topics matching the regular expression.')
    record.add_argument('--exclude-topics', nargs='+', metavar='TOPIC',
                        help='List of topics not to record.')
    record.add_argument('--include-hidden-topics', action='store_true',
                        help='Also record hidden topics (a name part starting with _).')
    record.add_argument('-o', '--output', metavar='URI',
                        help='Destination of the bag (default: rosbag2_<date>-<time>); must '
                             'not exist.')
    record.add_argument('-s', '--storage', choices=['mcap', 'sqlite3'], default='mcap',
                        help='Storage identifier to be used (default: mcap).')
    record.add_argument('--polling-interval', type=int, default=100, metavar='MS',
                        help='Time in ms to wait between querying for new topics (default 100).')
    record.add_argument('--no-discovery', action='store_true',
                        help='Disables topic auto discovery during recording: only topics '
                             'present at startup will be recorded.')
    record.set_defaults(func=cmd_bag_record)

    # topic
    topic = verbs.add_parser('topic', help='Various topic related sub-commands',
                             description='Inspect the topics of the running ROS graph.')
    topic_verbs = topic.add_subparsers(title='Commands', dest='topic_verb', metavar='<command>')
    topic.set_defaults(func=None, _help=topic.print_help)

    tlist = topic_verbs.add_parser('list', help='Output a list of available topics')
    tlist.add_argument('-t', '--show-types', action='store_true',
                       help='Additionally show the topic type')
    tlist.add_argument('-c', '--count-topics', action='store_true',
                       help='Only display the number of topics discovered')
    tlist.add_argument('--include-hidden-topics', action='store_true',
                       help='Consider hidden topics as well')
    tlist.add_argument('--spin-time', type=float, default=3.5, metavar='SECONDS',
                       help='Longest time in seconds to wait for discovery; returns earlier '
                            'once other nodes are found and the list is stable for 0.5 s '
                            '(default 3.5)')
    tlist.set_defaults(func=cmd_topic_list)

    echo = topic_verbs.add_parser('echo', help='Output messages from a topic')
    echo.add_argument('topic_name', help="Name of the ROS topic to listen to (e.g. '/chatter')")
    echo.add_argument('message_type', nargs='?',
                      help="Type of the ROS message (e.g. 'std_msgs/msg/String'); default: "
                           'learned from the graph (waits for a publisher)')
    _add_qos_args(echo)
    echo.add_argument('--once', action='store_true', help='Print the first message received '
                                                           'and then exit.')
    echo.add_argument('--field', metavar='FIELD',
                      help="Echo a selected field of a message, e.g. 'header.stamp'.")
    echo.add_argument('-f', '--full-length', action='store_true',
                      help='Output all elements for arrays, bytes, and string with a length > '
                           "'--truncate-length', by default they are truncated after "
                           "'--truncate-length' elements with '...'")
    echo.add_argument('-l', '--truncate-length', type=_nonneg_int, default=128, metavar='N',
                      help='The length to truncate arrays, bytes, and string to (default: 128)')
    echo.add_argument('--no-arr', action='store_true', help="Don't print array fields of messages")
    echo.add_argument('--no-str', action='store_true',
                      help="Don't print string fields of messages")
    echo.add_argument('--flow-style', action='store_true',
                      help='Print collections in flow style ([a, b], {k: v})')
    echo.set_defaults(func=cmd_topic_echo)

    hz = topic_verbs.add_parser('hz', help='Print the average publishing rate to screen')
    hz.add_argument('topic_name', help="Name of the ROS topic to listen to (e.g. '/chatter')")
    hz.add_argument('-w', '--window', type=int, default=10000, metavar='WINDOW',
                    help='window size, in # of messages, for calculating rate (default: 10000)')
    hz.set_defaults(func=cmd_topic_hz)

    parser.set_defaults(func=None, _help=parser.print_help)
    return parser


def _error_prefix(args: argparse.Namespace | None) -> str:
    parts = ['ros2']
    for key in ('verb', 'bag_verb', 'topic_verb'):
        value = getattr(args, key, None) if args is not None else None
        if value:
            parts.append(value)
    return ' '.join(parts)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``ros2`` console script. Returns the exit status."""
    if argv is None:
        if not os.environ.get(NO_DEFER_ENV):
            real = find_real_ros2()
            if real is not None:
                try:
                    os.execv(real, [real, *sys.argv[1:]])
                except OSError as exc:
                    print(f"[WARN] cannot run the real ros2 at '{real}' ({exc}); using the "
                          'built-in one', file=sys.stderr)
        argv = sys.argv[1:]
    parser = build_parser()
    args = None
    try:
        args = parser.parse_args(list(argv))
        if args.func is None:
            args._help()
            return 0
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        try:
            sys.stdout = open(os.devnull, 'w')  # noqa: SIM115 - silence the final flush
        except OSError:
            pass
        return 0
    except Exception as exc:  # one clear line, never a bare traceback
        if os.environ.get(DEBUG_ENV):
            raise
        from ..bag_io import BagError
        from ..ros_msgs import MessageTypeError
        if isinstance(exc, (CliError, BagError, MessageTypeError)):
            message = str(exc)
        else:
            message = f'{exc.__class__.__name__}: {exc} (set {DEBUG_ENV}=1 for a traceback)'
        print(f"{_error_prefix(args)}: error: {' '.join(message.split())}", file=sys.stderr)
        return 1


if __name__ == '__main__':
    sys.exit(main())
