"""``ros2 bag play <bag>``: publish a bag's messages with their recorded timing and QoS.

Besides the options of rosbag2's player, this one can wait for subscribers before the first
message (``--wait-for-subscribers [N]``, ``--wait-timeout S``) and set the history depth of its
publishers (``--qos-depth N``, messages a reliable subscriber may lag behind).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from typing import Any

from .common import CliError, RosSession, print_warnings

#: The options only this player has; with them, ``ros2`` does not hand over to a real ros2.
OWN_OPTIONS = ('--wait-for-subscribers', '--wait-timeout', '--qos-depth')

#: History depth of the publishers when --qos-depth is not given (or a recorded depth is larger).
DEFAULT_DEPTH = 100

_NOTE_EVERY_S = 10.0


def _matched_count(text: str) -> int:
    """argparse type of ``--wait-for-subscribers``: an integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a number of subscriptions, got '{text}' (write the bag path before "
            '--wait-for-subscribers, or --wait-for-subscribers=N)') from None
    if value < 1:
        raise argparse.ArgumentTypeError(f'must be >= 1, got {value}')
    return value


def _unmatched(pubs: dict[str, Any], count: int) -> dict[str, int]:
    """Topic (as published, remapped) -> matched subscriptions, for those with fewer than
    ``count``."""
    matched = {pub.topic_name: pub.get_subscription_count() for pub in pubs.values()}
    return {topic: n for topic, n in sorted(matched.items()) if n < count}


def _describe(unmatched: dict[str, int], count: int) -> str:
    return ', '.join(f'{topic} ({n} of {count})' for topic, n in unmatched.items())


def wait_for_subscribers(ros: RosSession, log: Any, pubs: dict[str, Any], count: int,
                         timeout: float) -> bool:
    """Wait until every publisher in ``pubs`` has matched ``count`` subscriptions.

    Returns True once they have, False when stopped (Ctrl-C); raises CliError after
    ``timeout`` seconds (0: no limit). Logs what it waits for, then every 10 s what is missing.
    """
    plural = 's' if count > 1 else ''
    topics = sorted(pub.topic_name for pub in pubs.values())
    log.info(f'Waiting for {count} matched subscription{plural} on each of {len(topics)} '
             f"topic{'s' if len(topics) > 1 else ''}: {', '.join(topics)}")
    start = time.monotonic()
    next_note = start + _NOTE_EVERY_S
    while not ros.stop:
        unmatched = _unmatched(pubs, count)
        now = time.monotonic()
        if not unmatched:
            log.info(f'Subscribers matched after {now - start:.1f} s')
            return True
        if timeout > 0 and now - start >= timeout:
            raise CliError(f'no subscribers after {timeout:g} s (--wait-timeout): '
                           f'{_describe(unmatched, count)}')
        if now >= next_note:
            log.info(f'Still waiting for subscribers: {_describe(unmatched, count)}')
            next_note += _NOTE_EVERY_S
        ros.sleep_until(now + 0.02)
    return False


def publisher_qos(recorded: Any, depth: int | None = None) -> Any:
    """The rclpy QoS of the publisher of a topic whose recorded offers are ``recorded``:
    compatible with them (:func:`mocap_core.bag_io.adapted_qos`), keep-last with a history of
    ``depth`` messages (None: :data:`DEFAULT_DEPTH`) or the largest recorded depth."""
    from ...bag_io import adapted_qos

    return adapted_qos(recorded, depth=depth or DEFAULT_DEPTH)


def cmd_bag_play(args: argparse.Namespace) -> int:
    """Publish the bag (raw bytes, recorded QoS), paced by the bag's time stamps / rate."""
    from ...bag_io import BagReader
    from ...ros_msgs import MessageTypeError, get_message_class

    if not args.rate > 0 or not math.isfinite(args.rate):
        raise CliError(f'rate must be > 0, got {args.rate}')
    if args.delay < 0:
        raise CliError(f'delay must be >= 0, got {args.delay}')
    if args.start_offset < 0:
        raise CliError(f'start offset must be >= 0, got {args.start_offset}')
    if args.qos_depth is not None and args.qos_depth < 1:
        raise CliError(f'qos depth must be >= 1, got {args.qos_depth}')
    if args.wait_timeout is not None:
        if args.wait_for_subscribers is None:
            raise CliError('--wait-timeout needs --wait-for-subscribers')
        if not args.wait_timeout >= 0 or not math.isfinite(args.wait_timeout):
            raise CliError(f'wait timeout must be >= 0, got {args.wait_timeout}')
    remaps: list[str] = []
    for rule in args.remap or []:
        if ':=' not in rule:
            raise CliError(f"invalid remap rule '{rule}' (expected FROM:=TO)")
        remaps += ['-r', rule]

    with BagReader(args.bag_path) as bag:
        print_warnings(bag.warnings)
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

        ros = RosSession(remaps)
        try:
            node = ros.node('rosbag2_player')
            log = node.get_logger()
            pubs = {}
            for name, cls in classes.items():
                pubs[name] = node.create_publisher(
                    cls, name, publisher_qos(bag.topics[name].qos, args.qos_depth))
            start_ns = bag.start_ns + int(round(args.start_offset * 1e9))
            total = sum(bag.topics[n].count for n in classes)
            log.info(f"Playing '{args.bag_path}': {total} messages on {len(classes)} topics "
                     f'at rate {args.rate:g}{" (looping)" if args.loop else ""}')
            if args.wait_for_subscribers is not None:
                wait_for_subscribers(ros, log, pubs, args.wait_for_subscribers,
                                     args.wait_timeout or 0.0)
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


def add_parser(bag_verbs: Any) -> None:
    """Register ``bag play`` on the ``bag`` subparsers."""
    play = bag_verbs.add_parser(
        'play', help='Play back ROS data from a bag',
        description='Publish the messages of a bag with their recorded timing and the '
                    "publishers' recorded QoS (transient-local kept), as raw bytes. "
                    '--wait-for-subscribers, --wait-timeout and --qos-depth are options of '
                    'this built-in player only (a real ros2 does not know them): with one of '
                    'them, this command plays the bag itself even when a real ros2 is on the '
                    'PATH.')
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
    play.add_argument('--wait-for-subscribers', type=_matched_count, nargs='?', const=1,
                      metavar='N',
                      help='Before the first message, wait until the publisher of every played '
                           'topic (after remapping) has matched at least N subscriptions '
                           '(default N: 1), so that nodes started just before get every '
                           'message; logs what it waits for. Only before the first message, '
                           'not again at each loop; --delay, if given, comes after. Put it '
                           'after the bag path (or write --wait-for-subscribers=N). Built-in '
                           'player only.')
    play.add_argument('--wait-timeout', type=float, metavar='SECONDS',
                      help='With --wait-for-subscribers: give up after this many seconds, '
                           'naming the topics still without subscribers, with exit status 1 '
                           '(default: 0, no limit: Ctrl-C stops the wait). Built-in player '
                           'only.')
    play.add_argument('--qos-depth', type=int, metavar='N',
                      help='History depth of the publishers: how many messages a reliable '
                           'subscriber may fall behind (a node slower than the bag) before the '
                           'oldest it has not acknowledged are dropped; larger costs memory only '
                           f'while a subscriber lags (default: {DEFAULT_DEPTH}, or the largest '
                           'recorded depth). Built-in player only.')
    play.set_defaults(func=cmd_bag_play)
