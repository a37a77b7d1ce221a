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

Stopping a process (:class:`StopSignals`, :func:`close_nodes`): rclpy's own signal handler
shuts the context down and raises KeyboardInterrupt wherever the main thread is, which may be
inside the C++ events executor dispatching a callback; the executor was then never shut down
and the nodes were destroyed under it. Once in a while (a CI run on a busy machine) a node
process did not end within 60 s of SIGINT. Node processes therefore take SIGINT / SIGTERM as a
request (the spin loop ends at its next step), then tear down in order: the node's own threads,
``remove_node``, ``executor.shutdown``, ``destroy_node``, the context. If that rclpy part
still hangs, every thread's stack goes to stderr after ``limit_s`` (so the hang can be found;
the node tests fail on it), and a node process exits with status 0: everything received was
processed and published by then. A library caller (``mocap run`` inside ``mocap eval``) is
only told, never ended.
"""
from __future__ import annotations

import faulthandler
import os
import signal
import sys
import threading
from typing import Any, Callable, Iterable, Optional

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


class StopSignals:
    """SIGINT and SIGTERM of a node process as a request to stop.

    :meth:`install` (main thread only; elsewhere it does nothing) replaces the handlers; the
    first signal sets :attr:`requested`, the spin loop's condition reads it and the process
    ends cleanly; a third signal raises KeyboardInterrupt (give up waiting). Use with
    ``rclpy.init(..., signal_handler_options=SignalHandlerOptions.NO)`` so that rclpy does not
    shut the context down under a running callback (module docstring)."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.count = 0
        self._old: dict = {}

    @property
    def requested(self) -> bool:
        """Whether a stop signal arrived."""
        return self.count > 0

    def install(self) -> 'StopSignals':
        if threading.current_thread() is threading.main_thread():
            self._old = {s: signal.signal(s, self._on_signal) for s in self.SIGNALS}
        return self

    def restore(self) -> None:
        """Put the previous handlers back."""
        for sig, old in self._old.items():
            signal.signal(sig, old)
        self._old = {}

    def _on_signal(self, signum: int, frame: Any) -> None:
        self.count += 1
        if self.count >= 3:
            raise KeyboardInterrupt


def init_rclpy(args: Any = None, context: Any = None) -> StopSignals:
    """``rclpy.init`` without rclpy's signal handlers, and :class:`StopSignals` installed."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    rclpy.init(args=args, context=context, signal_handler_options=SignalHandlerOptions.NO)
    return StopSignals().install()


SHUTDOWN_HANG = 'shutting down took more than'


def close_nodes(executor: Any, nodes: Iterable[Any], context: Any = None,
                before: Iterable[Callable[[], None]] = (), limit_s: float = 20.0,
                label: str = 'node', hard_exit: bool = True) -> bool:
    """Tear a node process down in order: ``before`` (e.g. the nodes' own threads and
    writers, each bounded by its own waits), then per node ``executor.remove_node`` and,
    after ``executor.shutdown``, ``destroy_node``, then the context (None: the default one).
    Each step's exception is printed and the next goes on.

    If the rclpy part takes more than ``limit_s`` s, a line with :data:`SHUTDOWN_HANG` and
    every thread's stack are printed on stderr, and with ``hard_exit`` (a node process that
    owns its interpreter) the process exits with status 0 (module docstring); without it (a
    library call, e.g. :func:`mocap_core.cli.run.run` inside ``mocap eval``) the teardown just
    goes on waiting. Returns True when it finished in time."""
    import rclpy

    nodes = [n for n in nodes if n is not None]

    def step(what: str, fn: Callable[[], Any]) -> None:
        try:
            fn()
        except Exception as exc:  # noqa: BLE001 - a failing step never stops the teardown
            print(f'[{label}] {what} failed during shutdown: {type(exc).__name__}: {exc}',
                  file=sys.stderr)

    for fn in before:
        step('stopping', fn)
    done = threading.Event()
    late = threading.Event()

    def watchdog() -> None:
        if done.wait(limit_s):
            return
        late.set()
        err = sys.__stderr__ if sys.__stderr__ is not None else sys.stderr
        try:
            for stream in (sys.stdout, sys.stderr):
                stream.flush()
            print(f'[{label}] {SHUTDOWN_HANG} {limit_s:.0f} s: the threads are', file=err,
                  flush=True)
            faulthandler.dump_traceback(file=err, all_threads=True)
            if hard_exit:
                print(f'[{label}] exiting without finishing the shutdown', file=err,
                      flush=True)
        except Exception:  # noqa: BLE001 - a stream without a file descriptor
            pass
        if hard_exit:
            os._exit(0)

    threading.Thread(target=watchdog, name='shutdown-watchdog', daemon=True).start()
    try:
        if executor is not None:
            for node in nodes:
                step('remove_node', lambda node=node: executor.remove_node(node))
            step('executor.shutdown', lambda: executor.shutdown(timeout_sec=5.0))
        for node in nodes:
            step('destroy_node', node.destroy_node)
        step('context shutdown', lambda: rclpy.try_shutdown(context=context))
    finally:
        done.set()
    return not late.is_set()
