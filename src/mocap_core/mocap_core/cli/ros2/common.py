"""What the verbs of the built-in ``ros2`` share: the one-line user error, the argument parser
class, an rclpy session whose Ctrl-C ends loops cleanly, and topic-name helpers."""

from __future__ import annotations

import argparse
import os
import sys
import time
from typing import Any, Sequence

__all__ = ['CliError', 'Parser', 'RosSession', 'absolute_topic', 'cli_node_name',
           'nonneg_int', 'print_warnings', 'wait_for_topic']


class CliError(Exception):
    """A user error: printed as one line, exit status 1."""


class Parser(argparse.ArgumentParser):
    """argparse that prints the usage line and one error line (exit status 2)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.print_usage(sys.stderr)
        self.exit(2, f'{self.prog}: error: {message}\n')


def nonneg_int(text: str) -> int:
    """argparse type: an integer >= 0."""
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f'must be >= 0, got {value}')
    return value


class RosSession:
    """An rclpy context whose SIGINT/SIGTERM only set ``stop`` (the loops then end cleanly).

    A third signal raises KeyboardInterrupt (give up waiting for a clean end). ``ros_args`` are
    passed as ``--ros-args ...`` (e.g. ``['-r', 'from:=to']`` remaps every node's topics).
    """

    def __init__(self, ros_args: Sequence[str] = ()) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor

        from ...executors import init_rclpy

        self.rclpy = rclpy
        self._stopped = False
        self.context = Context()
        args = ['ros2', '--ros-args', *ros_args] if ros_args else ['ros2']
        try:
            self._signals = init_rclpy(args, context=self.context)
        except Exception as exc:
            raise CliError(f'cannot start ROS: {exc}') from None
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes: list[Any] = []

    @property
    def stop(self) -> bool:
        """Whether to end: a stop signal arrived, or a loop set it."""
        return self._stopped or self._signals.requested

    @stop.setter
    def stop(self, value: bool) -> None:
        self._stopped = bool(value)

    @property
    def signals(self) -> int:
        """Stop signals received so far."""
        return self._signals.count

    def node(self, name: str) -> Any:
        """A new node (no parameter services) spun by this session's executor."""
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
        """Destroy the nodes, shut the context down, restore the signal handlers."""
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
        self._signals.restore()


def print_warnings(lines: Sequence[str]) -> None:
    """Print each line on stderr as ``[WARN] line`` (e.g. a bag reader's warnings)."""
    for line in lines:
        print(f'[WARN] {line}', file=sys.stderr)


def absolute_topic(topic: str) -> str:
    """``topic`` with a leading ``/``; CliError for an empty name."""
    topic = topic.strip()
    if not topic:
        raise CliError('empty topic name')
    return topic if topic.startswith('/') else '/' + topic


def cli_node_name() -> str:
    """A hidden node name unique to this process (like ros2cli's)."""
    return f'_ros2cli_{os.getpid()}'


def wait_for_topic(ros: RosSession, node: Any, topic: str, msgtype: str | None,
                   timeout: float | None = None) -> tuple[str, list[Any]] | None:
    """Wait until ``topic`` has a publisher; return its type and the publishers' QoS.

    Returns None when stopped (Ctrl-C) or after ``timeout`` seconds; CliError when the topic
    has several types and ``msgtype`` does not choose one.
    """
    from ...ros_msgs import normalize_msgtype

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
