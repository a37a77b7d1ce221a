"""Running several rclpy nodes in one process with synchronous, lossless message delivery.

``mocap process`` uses this to drive the pipeline's own node classes over a recorded bag as
fast as the machine allows, deterministically and without dropping a message: instead of
going through DDS (where best-effort topics drop under load and the order between topics
depends on timing), every ``publish`` of a wired node is put on one FIFO queue and handed,
in order, to the subscription callbacks of the wired nodes on that topic, in the calling
thread. Timers are not run (nothing is spun): the driver calls the nodes' ``flush`` methods at
the end of the input instead of relying on idle timers.

The publishers and subscriptions stay real rclpy entities (the ROS graph sees them, e.g.
``count_publishers``); only delivery is short-circuited. Every published message can also be
handed to a ``record`` callback (e.g. to write the output bag).

A node may publish serialised bytes (``Publisher.publish`` accepts them; the stages do for
their per-frame outputs, :mod:`mocap_core.cdr`): the graph carries them as a
:class:`SerializedMessage`, deserialised once, and only when a wired subscriber or a
``record`` callback that does not take them raw (``record_raw=False``) needs the message.

Usage::

    graph = InProcessGraph(record=lambda topic, msg, qos: ...)
    graph.add(lifter_node)
    graph.add(physics_node)
    graph.publish('/mocap/keypoints2d', cloud)   # delivered to the lifter, then onwards
"""

from __future__ import annotations

import collections
from typing import Any, Callable, DefaultDict, Deque, Dict, List, Optional, Tuple

#: Topics of rclpy's own machinery: never wired.
SYSTEM_TOPICS = frozenset({'/rosout', '/parameter_events'})

RecordFn = Callable[[str, Any, Any], None]


def _ignore(*_args: Any) -> None:
    """The DDS callback of a wired subscription in a live graph (see InProcessGraph.seal)."""


class SerializedMessage:
    """CDR bytes published on a topic, with the publisher's message class; :meth:`message`
    deserialises them (once)."""

    __slots__ = ('data', 'msg_type', '_message')

    def __init__(self, data: bytes, msg_type: type) -> None:
        self.data = bytes(data)
        self.msg_type = msg_type
        self._message = None

    def message(self) -> Any:
        if self._message is None:
            from rclpy.serialization import deserialize_message
            self._message = deserialize_message(self.data, self.msg_type)
        return self._message


def _message(msg: Any) -> Any:
    return msg.message() if isinstance(msg, SerializedMessage) else msg


def _raw(msg: Any) -> bytes:
    """What a raw subscription (``raw=True``) receives: the CDR bytes."""
    if isinstance(msg, SerializedMessage):
        return msg.data
    from rclpy.serialization import serialize_message
    return serialize_message(msg)


class DeliveryError(RuntimeError):
    """A subscription callback raised: which node and topic, and the original error."""


class InProcessGraph:
    """Synchronous message delivery between the nodes added to it (see the module doc).

    Args:
        record: called as ``record(topic, msg, qos)`` for every message published by a wired
            node (``qos`` = the publisher's rclpy QoSProfile), before it is delivered.
        on_error: called as ``on_error(node_name, topic, exception)`` when a callback raises;
            the message still reaches the other subscribers. Default: raise DeliveryError.
        record_raw: ``record`` takes what was published as it is: a message, or a
            :class:`SerializedMessage` where a node published bytes. Otherwise it always
            gets a message.
        record_filter: ``record_filter(topic)`` says whether ``record`` wants the topic
            (default: every topic); only then does it count as a subscriber of the topic.
    """

    def __init__(self, record: Optional[RecordFn] = None,
                 on_error: Optional[Callable[[str, str, BaseException], None]] = None,
                 live: bool = False, record_raw: bool = False,
                 record_filter: Optional[Callable[[str], bool]] = None) -> None:
        self.record = record
        self.record_raw = record_raw
        self.record_filter = record_filter
        self.on_error = on_error
        #: live (``mocap run``): every message also leaves through DDS while a subscriber
        #: outside the graph listens, and the wired subscriptions ignore what DDS delivers
        #: from a wired publisher (they get it from the graph); see :meth:`seal`
        self.live = live
        self._pub_topics: set = set()
        self._dds_callbacks: List[Tuple[Any, Callable[[Any], None]]] = []
        self.nodes: List[Any] = []
        self._subscribers: DefaultDict[str, List[Tuple[str, Callable[[Any], None]]]] = \
            collections.defaultdict(list)
        self._queue: Deque[Tuple[str, Any]] = collections.deque()
        self._delivering = False
        self.published: Dict[str, int] = collections.Counter()

    def add(self, node: Any) -> Any:
        """Wire a node: its publishers publish into the graph, its subscriptions receive from
        it. Returns the node."""
        name = node.get_name()
        for pub in node.publishers:
            self._wire(pub)
        # publishers the node creates later (one per person, as people come) are wired too
        create = node.create_publisher

        def create_publisher(*args, **kwargs):
            pub = create(*args, **kwargs)
            self._wire(pub)
            return pub

        node.create_publisher = create_publisher
        for sub in node.subscriptions:
            if sub.topic_name not in SYSTEM_TOPICS:
                self._subscribers[sub.topic_name].append(
                    (name, sub.callback, bool(getattr(sub, 'raw', False))))
                self._dds_callbacks.append((sub, sub.callback))
        self.nodes.append(node)
        return node

    def seal(self) -> None:
        """Live graphs, after every node is added: a wired subscription on a topic that a
        wired node publishes ignores DDS deliveries (the graph already delivered the message);
        on other topics (a camera, a bag played beside) it receives from DDS as usual."""
        for sub, callback in self._dds_callbacks:
            if sub.topic_name in self._pub_topics:
                sub.callback = _ignore
            else:
                sub.callback = callback

    def subscribers(self, topic: str) -> List[str]:
        """Names of the wired nodes subscribed to ``topic``."""
        return [name for name, *_ in self._subscribers.get(topic, [])]

    def _wire(self, pub: Any) -> None:
        """Publish into the graph; the subscription count is that of the graph (the wired
        subscribers, plus one for ``record``), so that a node that builds a message only
        for a topic with subscribers (``get_subscription_count``) does so here too."""
        topic = pub.topic_name
        if topic in SYSTEM_TOPICS:
            return
        self._pub_topics.add(topic)
        inner = self._publisher(topic, pub.qos_profile, pub.msg_type)
        if not self.live:
            pub.publish = inner
            pub.get_subscription_count = lambda: len(self._subscribers.get(topic, ())) + \
                self._recorded(topic)
            return
        dds_publish, dds_count = pub.publish, pub.get_subscription_count

        def outside() -> int:
            # DDS matches the wired subscriptions of this process too: they are not outside
            return max(0, dds_count() - len(self._subscribers.get(topic, ())))

        def publish(msg: Any) -> None:
            inner(msg)
            if outside() > 0:
                dds_publish(msg)

        pub.publish = publish
        pub.get_subscription_count = lambda: len(self._subscribers.get(topic, ())) + \
            self._recorded(topic) + outside()

    def _recorded(self, topic: str) -> int:
        """1 if ``record`` takes ``topic``, else 0."""
        if self.record is None:
            return 0
        return 1 if self.record_filter is None or self.record_filter(topic) else 0

    def _publisher(self, topic: str, qos: Any, msg_type: type) -> Callable[[Any], None]:
        def publish(msg: Any) -> None:
            if isinstance(msg, (bytes, bytearray, memoryview)):
                msg = SerializedMessage(msg, msg_type)
            self.publish(topic, msg, qos)
        return publish

    def publish(self, topic: str, msg: Any, qos: Any = None) -> None:
        """Record ``msg`` (a message or a :class:`SerializedMessage`) and deliver it (and
        everything published in response) before returning; re-entrant calls from callbacks
        only enqueue."""
        if self._recorded(topic):
            self.record(topic, msg if self.record_raw else _message(msg), qos)
        self.published[topic] += 1
        self._queue.append((topic, msg))
        if self._delivering:
            return
        self._delivering = True
        try:
            while self._queue:
                t, m = self._queue.popleft()
                for name, callback, raw in self._subscribers.get(t, ()):
                    try:
                        callback(_raw(m) if raw else _message(m))
                    except Exception as exc:  # noqa: BLE001 - reported with its context
                        if self.on_error is None:
                            raise DeliveryError(f'{name} failed on {t}: '
                                                f'{type(exc).__name__}: {exc}') from exc
                        self.on_error(name, t, exc)
        finally:
            self._delivering = False
            self._queue.clear()

    def flush(self) -> None:
        """End of input: call every wired node's ``flush()`` (if it has one), upstream first,
        so that frames held back for look-ahead flow through the rest of the graph."""
        for node in self.nodes:
            flush = getattr(node, 'flush', None)
            if flush is not None:
                flush()
