"""``ros2 bag info <bag>``: files, size, duration, and per-topic type and count."""

from __future__ import annotations

import argparse
import datetime
from typing import Any

from .common import print_warnings


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


def cmd_bag_info(args: argparse.Namespace) -> int:
    """Print the summary in the layout of rosbag2's ``ros2 bag info``."""
    from ...bag_io import BagReader

    with BagReader(args.bag_path) as bag:
        print_warnings(bag.warnings)
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


def add_parser(bag_verbs: Any) -> None:
    """Register ``bag info`` on the ``bag`` subparsers."""
    info = bag_verbs.add_parser('info', help='Print information about a bag to the screen')
    info.add_argument('bag_path', help='Bag to open (a folder, or a single .mcap file)')
    info.add_argument('-s', '--storage', choices=['mcap', 'sqlite3'],
                      help='Storage implementation of bag (detected automatically)')
    info.add_argument('-t', '--topic-name', action='store_true',
                      help='Only display topic names.')
    info.set_defaults(func=cmd_bag_info)
