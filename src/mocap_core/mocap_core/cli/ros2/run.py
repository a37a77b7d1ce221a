"""``ros2 run <package> <executable> [args ...]``: exec ``<prefix>/lib/<package>/<executable>``."""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from typing import Any


def cmd_run(args: argparse.Namespace) -> int:
    """Replace this process with the executable (signals then go straight to it)."""
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


def add_parser(verbs: Any) -> None:
    """Register ``run`` on the top-level subparsers."""
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
