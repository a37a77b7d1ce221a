"""An rclpy participant inside this process, for the tests and benchmarks that drive node
processes: subscribe (collecting messages in lists), publish, spin in the caller's thread or
in a background thread (:meth:`RosPeer.spin_in_background`).

It has its own ``rclpy.Context`` (so several can coexist, and rclpy's global context is left
alone) on a given DDS domain, with discovery kept on this machine.

    with RosPeer('test_listener', domain_id=42) as peer:
        got = peer.subscribe(PointCloud2, '/mocap/lifter/joints3d')
        ... start the node process ...
        assert peer.wait_for_publishers(['/mocap/lifter/joints3d'])   # matched: nothing lost
        ... feed the node ...
        peer.spin(30.0, until=lambda: len(got) >= 100)
"""

from __future__ import annotations

import os
import threading
import time
from typing import Any, Callable, Dict, Iterable, List, Optional


class RosPeer:
    """One rclpy node with its executor (module docstring).

    Args:
        name: node name.
        domain_id: DDS domain (default: ``ROS_DOMAIN_ID`` of the environment, else 0).
    """

    def __init__(self, name: str = 'mocap_peer', domain_id: Optional[int] = None) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
        if domain_id is None:
            domain_id = int(os.environ.get('ROS_DOMAIN_ID', '0'))
        self.context = rclpy.Context()
        rclpy.init(args=[], context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None

    def spin_in_background(self) -> None:
        """From now on, process callbacks in a daemon thread (the lists filled by
        :meth:`subscribe` grow on their own; :meth:`spin` is then an error)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._spin_forever, daemon=True)
            self._thread.start()

    def subscribe(self, msg_type, topic: str, qos: Any = None,
                  transform: Optional[Callable[[Any], Any]] = None) -> List:
        """Subscribe and return the list the messages (or ``transform(msg)``) are appended to.
        Default QoS: the pipeline's stream QoS (reliable, depth 30)."""
        if qos is None:
            from mocap_core.qos import STREAM_QOS
            qos = STREAM_QOS
        got: List = []
        if transform is None:
            self.node.create_subscription(msg_type, topic, got.append, qos)
        else:
            self.node.create_subscription(msg_type, topic, lambda m: got.append(transform(m)),
                                          qos)
        return got

    def unmatched_subscriptions(self, topics: Optional[Iterable[str]] = None,
                                count: int = 1) -> Dict[str, int]:
        """Topic -> matched publishers, for this peer's subscriptions (on ``topics``; all when
        None) that have matched fewer than ``count`` publishers. Matching is DDS's: a
        publisher the subscription will receive from, not only one seen in the graph."""
        wanted = None if topics is None else {self._resolve(t) for t in topics}
        if wanted is not None:
            missing = wanted - {sub.topic_name for sub in self.node.subscriptions}
            if missing:
                raise ValueError(f"this peer has no subscription on {', '.join(sorted(missing))}")
        unmatched: Dict[str, int] = {}
        for sub in self.node.subscriptions:
            if wanted is not None and sub.topic_name not in wanted:
                continue
            matched = sub.get_publisher_count()
            if matched < count:
                unmatched[sub.topic_name] = min(matched, unmatched.get(sub.topic_name, matched))
        return unmatched

    def wait_for_publishers(self, topics: Optional[Iterable[str]] = None, count: int = 1,
                            timeout: float = 60.0, proc=None) -> bool:
        """Wait until each of this peer's subscriptions (on ``topics``; all when None) has
        matched at least ``count`` publishers, for up to ``timeout`` seconds or until the
        subprocess ``proc`` (if given) exits. Returns whether they have (see
        :meth:`unmatched_subscriptions` for what is missing)."""
        topics = None if topics is None else list(topics)
        return self.wait_until(lambda: not self.unmatched_subscriptions(topics, count),
                               timeout, proc)

    def wait_for_subscribers(self, publishers: Iterable[Any], count: int = 1,
                             timeout: float = 60.0, proc=None) -> bool:
        """Wait until each of ``publishers`` (made by :meth:`publisher`) has matched at least
        ``count`` subscriptions, for up to ``timeout`` seconds or until ``proc`` exits."""
        pubs = list(publishers)
        return self.wait_until(lambda: all(p.get_subscription_count() >= count for p in pubs),
                               timeout, proc)

    def _resolve(self, topic: str) -> str:
        return self.node.resolve_topic_name(topic)

    def wait_until(self, condition: Callable[[], bool], timeout: float, proc=None) -> bool:
        """Wait up to ``timeout`` seconds for ``condition()``, or until the subprocess ``proc``
        (if given) exits; callbacks are processed meanwhile (in this thread, or by the
        background thread of :meth:`spin_in_background`). Returns ``condition()``."""
        if self._thread is None:
            return self.spin(timeout, until=condition, proc=proc)
        deadline = time.monotonic() + timeout
        while not condition():
            if time.monotonic() >= deadline or (proc is not None and proc.poll() is not None):
                return condition()
            self._stop.wait(0.02)
        return True

    def publisher(self, msg_type, topic: str, qos: Any = None):
        """A publisher on this node (default QoS: the pipeline's stream QoS)."""
        if qos is None:
            from mocap_core.qos import STREAM_QOS
            qos = STREAM_QOS
        return self.node.create_publisher(msg_type, topic, qos)

    def spin(self, seconds: float, until: Optional[Callable[[], bool]] = None,
             step: float = 0.05, proc=None) -> bool:
        """Process callbacks in this thread for up to ``seconds``, returning early once
        ``until()`` holds or the subprocess ``proc`` (if given) has exited. Returns
        ``until()`` (True without a condition)."""
        if self._thread is not None:
            raise RuntimeError('this peer spins in a background thread')
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            if until is not None and until():
                return True
            if proc is not None and proc.poll() is not None:
                break
            self.executor.spin_once(timeout_sec=step)
        return True if until is None else bool(until())

    def spin_until_exit(self, proc, timeout: float) -> None:
        """Spin until the subprocess ``proc`` exits (then drain what is in flight); fails
        with AssertionError when it is still running after ``timeout`` seconds."""
        self.spin(timeout, until=lambda: proc.poll() is not None, step=0.02)
        for _ in range(20):
            self.executor.spin_once(timeout_sec=0.02)
        assert proc.poll() is not None, 'node did not exit in time'

    def _spin_forever(self) -> None:
        while not self._stop.is_set():
            self.executor.spin_once(timeout_sec=0.05)

    def close(self) -> None:
        """Stop the background thread (if any), destroy the node, shut the context down."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()

    def __enter__(self) -> 'RosPeer':
        return self

    def __exit__(self, *exc) -> None:
        self.close()
