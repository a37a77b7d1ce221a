"""A small ``ros2`` command for machines without the ROS 2 command line (pip-installed ROS).

It implements the verbs this project's users need, with the options and output of the real
``ros2`` where they overlap::

    ros2 run <package> <executable> [args ...]
    ros2 bag play <bag> [-r RATE] [-l] [--topics T ...] [--start-offset S] [-d DELAY]
                        [-m FROM:=TO ...] [--wait-for-all-acked MS]
                        [--wait-for-subscribers [N]] [--wait-timeout S] [--qos-depth N]
    ros2 bag record [-o OUT] (-a | -e REGEX | TOPIC ...)
    ros2 bag info <bag>
    ros2 topic list [-t] [-c]
    ros2 topic echo <topic> [type] [--once] [--qos-* ...] [--no-arr] [--no-str]
    ros2 topic hz <topic> [-w WINDOW]

When a real ``ros2`` is on the PATH (a ROS 2 install), this command hands over to it at once
(``os.execv``), so it never shadows the real tools; set ``MOCAP_ROS2_NO_DEFER=1`` to use this
one anyway. ``bag play`` with an option only this player has (``--wait-for-subscribers``,
``--wait-timeout``, ``--qos-depth``) is not handed over: the built-in player runs, and says so.

Bags are rosbag2 folders with MCAP storage (what ``ros2 bag record`` writes); ``bag play`` and
``bag info`` also take a single ``.mcap`` file. Messages are copied as raw CDR bytes, so a
play -> record round trip is byte-identical.

One module per verb (:mod:`.run`, :mod:`.bag_info`, :mod:`.bag_play`, :mod:`.bag_record`,
:mod:`.topic`), each with its ``cmd_*`` function and an ``add_parser``; :mod:`.common` holds
what they share. This module builds the parser, hands over to a real ros2, and runs a verb.
"""

from __future__ import annotations

import argparse
import os
import sys
from typing import Sequence

from . import bag_info, bag_play, bag_record, run, topic
from .common import CliError, Parser

__all__ = ['CliError', 'build_parser', 'find_real_ros2', 'main']

NO_DEFER_ENV = 'MOCAP_ROS2_NO_DEFER'
DEBUG_ENV = 'MOCAP_ROS2_DEBUG'


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


def own_play_option(argv: Sequence[str]) -> str | None:
    """The first option of ``argv`` that only this ``bag play`` knows, if ``argv`` is a
    ``bag play`` command line; else None."""
    args = list(argv)
    if args[:2] != ['bag', 'play']:
        return None
    for arg in args[2:]:
        if arg == '--':
            break
        name = arg.split('=', 1)[0]
        if name in bag_play.OWN_OPTIONS:
            return name
    return None


def _hand_over(argv: Sequence[str]) -> None:
    """exec a real ros2 on the PATH with ``argv``, unless told not to or unless ``argv`` needs
    this one; returns only when this command goes on."""
    if os.environ.get(NO_DEFER_ENV):
        return
    real = find_real_ros2()
    if real is None:
        return
    own = own_play_option(argv)
    if own is not None:
        print(f"[INFO] {own} is an option of this project's 'ros2 bag play' only: playing with "
              f"it instead of the ros2 at '{real}'", file=sys.stderr, flush=True)
        return
    try:
        os.execv(real, [real, *argv])
    except OSError as exc:
        print(f"[WARN] cannot run the real ros2 at '{real}' ({exc}); using the "
              'built-in one', file=sys.stderr)


# --- argument parsing ---------------------------------------------------------------------------

def build_parser() -> argparse.ArgumentParser:
    """The ``ros2`` parser: each verb's ``args.func`` runs it (None: print ``args._help``)."""
    parser = Parser(
        prog='ros2',
        description='ros2 is an extensible command-line tool for ROS 2. This is the small '
                    'built-in version of the mocap project (run, bag play|record|info, '
                    'topic list|echo|hz); a real ros2 on the PATH takes precedence '
                    f'(set {NO_DEFER_ENV}=1 to use this one).',
        formatter_class=argparse.RawDescriptionHelpFormatter)
    verbs = parser.add_subparsers(title='Commands', dest='verb', metavar='<command>')

    run.add_parser(verbs)

    bag = verbs.add_parser('bag', help='Various rosbag related sub-commands',
                           description='Play, record and inspect rosbag2 bags (MCAP storage).')
    bag_verbs = bag.add_subparsers(title='Commands', dest='bag_verb', metavar='<command>')
    bag.set_defaults(func=None, _help=bag.print_help)
    bag_info.add_parser(bag_verbs)
    bag_play.add_parser(bag_verbs)
    bag_record.add_parser(bag_verbs)

    topic.add_parser(verbs)

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
    """Entry point of the ``ros2`` console script. Returns the exit status.

    With ``argv`` None (the console script), the command line is ``sys.argv[1:]`` and a real
    ros2 on the PATH takes over (see the module docstring).
    """
    if argv is None:
        argv = sys.argv[1:]
        _hand_over(argv)
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
        from ...bag_io import BagError
        from ...ros_msgs import MessageTypeError
        if isinstance(exc, (CliError, BagError, MessageTypeError)):
            message = str(exc)
        else:
            message = f'{exc.__class__.__name__}: {exc} (set {DEBUG_ENV}=1 for a traceback)'
        print(f"{_error_prefix(args)}: error: {' '.join(message.split())}", file=sys.stderr)
        return 1
