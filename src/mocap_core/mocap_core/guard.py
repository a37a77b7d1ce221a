"""One policy for a callback that fails, live and offline (no ROS imports).

A subscription or timer callback that raises must not stop a node: the message (frame) it
was handling is dropped, counted in the node's diagnostics (``frames_dropped`` and
``errors``, and ``last_error``), a clear one-line message is logged at a limited rate, and the
node keeps running. Nodes wrap every callback they register with :func:`guarded`; the
in-process graph of ``mocap process`` calls the same wrapped callbacks, so a failing frame is
handled identically in both.

Usage in a node::

    self.create_subscription(PointCloud2, topics.KEYPOINTS,
                             guarded(self, self.on_keypoints, 'keypoints'), qos)
"""

from __future__ import annotations

import functools
import time
from typing import Any, Callable, Dict, Optional

#: Seconds between two logged failures of one node (the count in diagnostics is exact).
LOG_PERIOD_S = 2.0


def describe(exc: BaseException) -> str:
    """``Type: message`` on one line (at most 200 characters of message)."""
    text = ' '.join(str(exc).split())
    return f'{type(exc).__name__}: {text[:200]}' if text else type(exc).__name__


def record_failure(node: Any, what: str, exc: BaseException) -> str:
    """Count a failed callback on ``node`` (its ``diag``, when it has one: a
    :class:`mocap_core.diagnostics.NodeDiagnostics`) and log it, rate limited.

    Returns the logged text."""
    text = f'{what}: frame dropped after an error ({describe(exc)})'
    diag = getattr(node, 'diag', None)
    if diag is not None:
        diag.dropped += 1
        diag.errors += 1
        diag.set_value('last_error', text)
    node.get_logger().error(text, throttle_duration_sec=LOG_PERIOD_S)
    return text


def guarded(node: Any, callback: Callable[..., Any], what: Optional[str] = None
            ) -> Callable[..., Any]:
    """``callback`` wrapped so that an exception drops the message, is counted and logged
    (:func:`record_failure`) instead of leaving the executor.

    Args:
        node: the rclpy node the callback belongs to (for its logger and ``diag``).
        callback: a subscription or timer callback.
        what: a short name for the log (default: the callback's name).
    """
    name = what or getattr(callback, '__name__', 'callback')

    @functools.wraps(callback)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return callback(*args, **kwargs)
        except Exception as exc:  # noqa: BLE001 - the policy: drop, count, log, keep running
            record_failure(node, name, exc)
            return None

    wrapper.guarded = True  # type: ignore[attr-defined]
    return wrapper


def deserialised_unless(ignored: Callable[[], bool], msg_type: type,
                        callback: Callable[[Any], Any],
                        decode: Optional[Callable[[bytes], Any]] = None
                        ) -> Callable[[bytes], Any]:
    """The callback of a raw subscription (``create_subscription(..., raw=True)``): the
    serialised message is deserialised into ``msg_type`` (or read by ``decode``, e.g.
    :func:`mocap_core.cdr.decode_motion`) and handed to ``callback`` only while ``ignored()``
    is False. For an input a node ignores most of the time (the single-person topic while the
    combined input of several people delivers): such messages cost no deserialisation, live
    or in :class:`~mocap_core.inprocess.InProcessGraph`."""
    if decode is None:
        from rclpy.serialization import deserialize_message

        def decode(data: bytes) -> Any:
            return deserialize_message(data, msg_type)

    def on_raw(data: bytes) -> Any:
        if ignored():
            return None
        return callback(decode(data))

    on_raw.__name__ = getattr(callback, '__name__', 'on_raw')
    return on_raw


class KeyedRateLimit:
    """At most one event per ``period_s`` seconds (monotonic clock) for each key: for logs
    limited per kind of problem (rclpy's throttling is per call site, not per key).

    Usage::

        if self.limit.ready('camera_info', 5.0):
            self.get_logger().warn(text)
    """

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self._last: Dict[str, float] = {}

    def ready(self, key: str, period_s: float) -> bool:
        """True (and the key's period restarts) when ``key`` was not ready in the last
        ``period_s`` seconds."""
        now = self._clock()
        if now - self._last.get(key, -float('inf')) >= period_s:
            self._last[key] = now
            return True
        return False
