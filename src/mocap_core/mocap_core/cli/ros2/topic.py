"""``ros2 topic list | echo | hz``: inspect the topics of the running ROS graph.

There is no ros2 daemon here: each command starts its own node and waits for DDS discovery.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections import deque
from typing import Any

from .common import (
    CliError,
    RosSession,
    absolute_topic,
    cli_node_name,
    nonneg_int,
    wait_for_topic,
)


def _discover_topics(ros: RosSession, node: Any, max_wait: float,
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

    ros = RosSession()
    try:
        node = ros.node(cli_node_name())
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

    from ...bag_io import adapted_qos

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
    from ...ros_msgs import _convert, get_message_class, message_to_yaml, value_to_yaml

    topic = absolute_topic(args.topic_name)
    if args.field is not None:
        args.field = args.field.strip('.')
    truncate = None if args.full_length else args.truncate_length
    ros = RosSession()
    try:
        node = ros.node(cli_node_name())
        found = wait_for_topic(ros, node, topic, args.message_type)
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
    from ...ros_msgs import get_message_class

    topic = absolute_topic(args.topic_name)
    if args.window < 1:
        raise CliError('window must be >= 1')
    ros = RosSession()
    try:
        node = ros.node(cli_node_name())
        found = wait_for_topic(ros, node, topic, None)
        if found is None:
            return 0
        msgtype, offered = found
        cls = get_message_class(msgtype)
        from ...bag_io import adapted_qos

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


def _add_qos_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--qos-profile', choices=sorted(_QOS_PRESETS),
                        help='QoS preset to start from (default: adapted to the publishers: '
                             'reliable if all are, transient-local if all are)')
    parser.add_argument('--qos-depth', type=nonneg_int, metavar='N',
                        help='queue size of the subscription')
    parser.add_argument('--qos-history', choices=['system_default', 'keep_last', 'keep_all'])
    parser.add_argument('--qos-reliability',
                        choices=['system_default', 'reliable', 'best_effort', 'best_available'])
    parser.add_argument('--qos-durability',
                        choices=['system_default', 'volatile', 'transient_local',
                                 'best_available'])


def add_parser(verbs: Any) -> None:
    """Register ``topic`` and its verbs on the top-level subparsers."""
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
    echo.add_argument('-l', '--truncate-length', type=nonneg_int, default=128, metavar='N',
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
