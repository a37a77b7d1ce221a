"""``ros2 bag record``: record topics of the live graph into a rosbag2 bag (MCAP).

Each topic is subscribed once a publisher of it is seen (its offered QoS is then stored in the
bag, and the subscription adapts to it); messages are written as received, raw bytes stamped
with the receive time (ns).
"""

from __future__ import annotations

import datetime
import re
import sys
import time
from typing import TYPE_CHECKING, Any, Callable

from .common import CliError, RosSession, absolute_topic

if TYPE_CHECKING:
    import argparse

_SYSTEM_TOPICS = ('/rosout', '/parameter_events')
_DRAIN_MAX_CALLBACKS = 100_000


def _drain(ros: RosSession, counts: dict[str, int]) -> None:
    """Write the messages DDS had already delivered when the stop came (a Ctrl-C just after
    the last message must not lose it): take callbacks until two in a row bring nothing."""
    idle = 0
    for _ in range(_DRAIN_MAX_CALLBACKS):
        before = sum(counts.values())
        ros.executor.spin_once(timeout_sec=0.0)
        idle = idle + 1 if sum(counts.values()) == before else 0
        if idle >= 2:
            return


def cmd_bag_record(args: argparse.Namespace) -> int:
    """Record until Ctrl-C / SIGTERM; the bag is finished (summary, metadata) on the way out."""
    from rclpy.topic_or_service_is_hidden import topic_or_service_is_hidden

    from ...bag_io import BagError, BagWriter, adapted_qos
    from ...ros_msgs import MessageTypeError, get_message_class

    named = {absolute_topic(t) for t in [*(args.topics or []), *(args.topics_opt or [])]}
    try:
        regex = re.compile(args.regex) if args.regex else None
        exclude_re = re.compile(args.exclude_regex) if args.exclude_regex else None
    except re.error as exc:
        raise CliError(f'invalid regular expression: {exc}') from None
    exclude = {absolute_topic(t) for t in args.exclude_topics or []}
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
        ros = RosSession()
        node = ros.node('rosbag2_recorder')
        log = node.get_logger()
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
        if ros.signals < 2:
            _drain(ros, counts)
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


def add_parser(bag_verbs: Any) -> None:
    """Register ``bag record`` on the ``bag`` subparsers."""
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
