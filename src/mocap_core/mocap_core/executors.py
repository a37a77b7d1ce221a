"""Which rclpy executor runs a node process, and the spin loop every process shares.

The executor is a property of the process, not of a node (``mocap run`` puts four nodes in
one), so it is chosen by the environment variable ``MOCAP_EXECUTOR``, read once when a
process starts spinning:

* ``events`` (default): rclpy's ``EventsExecutor`` (``rclpy.experimental``), which reacts
  to the middleware's events in C++ instead of rebuilding a wait set in Python for every
  callback. Measured side by side (``docs/benchmarks/executors.md``): the lifter, physics and
  GMR processes need about a fifth less CPU at 30 frames/s for the same output (0.82x,
  median of ten pairs of runs).
* ``single_threaded``: rclpy's ``SingleThreadedExecutor``, what ``rclpy.spin`` uses (the
  fallback where the events executor is missing or misbehaves).

A node that must wake its executor from another thread (the keypoint node's detector and
source threads) calls ``node.executor.create_task(callback)``, which both executors run in
their own thread. Guard conditions are not an option: the events executor of the pinned rclpy
refuses any node that has one (``RuntimeError: Guard conditions not supported`` at the first
``spin_once``, measured).

An unknown value, or an rclpy without the events executor, falls back to
``single_threaded`` with a warning on stderr. Whatever the executor, the loop is
:func:`spin_until`: ``spin_once`` with a timeout, so that a shutdown (Ctrl-C, SIGTERM,
``rclpy.shutdown()``) ends it within ``step_s`` (the events executor's own ``spin()`` never
sleeps in the rclpy this project pins: a core at 100 % while idle, measured), and an
exception that escapes a callback is handed to ``on_error`` instead of ending the process.
"""
from __future__ import annotations

import os
import sys
from typing import Any, Callable, Optional

ENV = 'MOCAP_EXECUTOR'
KINDS = ('events', 'single_threaded')
DEFAULT = 'events'


def executor_kind(value: Optional[str] = None) -> str:
    """The executor kind from ``value`` (None: ``$MOCAP_EXECUTOR``, unset or empty: the
    default). An unknown value gives ``single_threaded`` and a warning on stderr."""
    raw = os.environ.get(ENV, '') if value is None else value
    kind = (raw or DEFAULT).strip().lower().replace('-', '_')
    if kind not in KINDS:
        print(f'warning: {ENV}={raw!r} is not one of {", ".join(KINDS)}: using '
              'single_threaded', file=sys.stderr)
        return 'single_threaded'
    return kind


def make_executor(kind: Optional[str] = None, context: Any = None) -> Any:
    """A new executor of ``kind`` (None: :func:`executor_kind`) for ``context`` (None: the
    default context). Falls back to ``SingleThreadedExecutor`` (warning on stderr) when the
    events executor cannot be created."""
    from rclpy.executors import SingleThreadedExecutor

    if executor_kind(kind) == 'events':
        try:
            from rclpy.experimental import EventsExecutor
            return EventsExecutor(context=context)
        except Exception as exc:  # noqa: BLE001 - ImportError, or the C++ part missing
            print(f'warning: the events executor is not available ({type(exc).__name__}: '
                  f'{exc}): using single_threaded', file=sys.stderr)
    return SingleThreadedExecutor(context=context)


def spin_until(executor: Any, ok: Callable[[], bool],
               on_error: Optional[Callable[[BaseException], None]] = None,
               step_s: float = 0.1) -> None:
    """Run ``executor`` while ``ok()`` is True, ``spin_once`` at a time (each waits at most
    ``step_s`` s for work). An exception other than KeyboardInterrupt and
    ``ExternalShutdownException`` that escapes a callback goes to ``on_error`` and spinning
    goes on (without ``on_error`` it is raised)."""
    from rclpy.executors import ExternalShutdownException

    while ok():
        try:
            executor.spin_once(timeout_sec=step_s)
        except (KeyboardInterrupt, ExternalShutdownException):
            raise
        except Exception as exc:  # noqa: BLE001 - the failing-callback policy
            if on_error is None:
                raise
            on_error(exc)
