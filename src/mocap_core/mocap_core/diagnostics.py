"""Per-node ``/diagnostics`` publishing (docs/design.md §2): processing time, input and output
rates, frames dropped, model in use, plus any key/values and warnings the node adds.

Usage in a node::

    self.diag = NodeDiagnostics(self, 'keypoints', hardware_id='webcam0')
    self.diag.input.tick()                 # a frame arrived
    with self.diag.processing():           # timed work
        ...
    self.diag.output.tick()                # a result was published
    self.diag.dropped += 1                 # a frame was skipped
    self.diag.set_value('model', 'blazepose_full')
    self.diag.warn('no camera_info yet')   # level WARN until cleared
    self.diag.watch('motion', publisher)   # its matched subscriptions are reported

Connections: for each watched publisher the status carries ``subscribers_<label>`` (the
subscriptions this node's publisher has matched), for each watched subscription
``publishers_<label>`` (the publishers it has matched). Both sides of a connection must have
matched before a reliable message reaches its subscriber: a stage that discovers its peer late
misses the messages sent before (volatile durability), and these values tell.
"""

from __future__ import annotations

import contextlib
import math
from typing import Callable, Dict, Iterator, List, Optional

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from .metrics import LatencyStats, RateMeter, Stopwatch
from .qos import DIAGNOSTICS_QOS


class NodeDiagnostics:
    """Collects a node's statistics and publishes a DiagnosticArray every ``period_s``."""

    def __init__(self, node, name: str, hardware_id: str = '', period_s: float = 1.0,
                 topic: str = '/diagnostics') -> None:
        self.node = node
        self.name = f'{node.get_name()}: {name}'
        self.hardware_id = hardware_id
        self.input = RateMeter()
        self.output = RateMeter()
        self.latency = LatencyStats()
        self.dropped = 0
        self.errors = 0
        self._values: Dict[str, str] = {}
        self._warning: Optional[str] = None
        self._error: Optional[str] = None
        self._watched: Dict[str, object] = {}
        self._refresh: List[Callable[[], None]] = []
        self._pub = node.create_publisher(DiagnosticArray, topic, DIAGNOSTICS_QOS)
        self._timer = node.create_timer(period_s, self.publish)

    @contextlib.contextmanager
    def processing(self) -> Iterator[Stopwatch]:
        """Time the enclosed block into the processing-time statistics."""
        with Stopwatch(self.latency) as sw:
            yield sw

    def set_value(self, key: str, value) -> None:
        self._values[str(key)] = str(value)

    def watch(self, label: str, endpoint) -> None:
        """Report the matched count of ``endpoint`` (an rclpy Publisher or Subscription) as
        ``subscribers_<label>`` or ``publishers_<label>``."""
        self._watched[str(label)] = endpoint

    def connections(self) -> Dict[str, str]:
        """``{'subscribers_<label>' | 'publishers_<label>': count}`` of the watched
        endpoints (an endpoint already destroyed is left out)."""
        out: Dict[str, str] = {}
        for label, ep in self._watched.items():
            try:
                if hasattr(ep, 'get_subscription_count'):
                    out[f'subscribers_{label}'] = str(ep.get_subscription_count())
                else:
                    out[f'publishers_{label}'] = str(ep.get_publisher_count())
            except Exception:  # noqa: BLE001 - destroyed during shutdown
                continue
        return out

    def on_publish(self, refresh: Callable[[], None]) -> None:
        """Call ``refresh`` (which sets values) before each status is built and published,
        by the timer live and by the final ``publish()`` of ``mocap process``, where timers do
        not run."""
        self._refresh.append(refresh)

    def warn(self, message: Optional[str]) -> None:
        """Set (or clear with None) the current warning."""
        self._warning = message

    def error(self, message: Optional[str]) -> None:
        """Set (or clear with None) the current error."""
        self._error = message

    def status(self) -> DiagnosticStatus:
        lat = self.latency.summary()
        values = {
            'input_rate_hz': f'{self.input.rate():.2f}',
            'output_rate_hz': f'{self.output.rate():.2f}',
            'processing_ms_median': _ms(lat['median']),
            'processing_ms_mean': _ms(lat['mean']),
            'processing_ms_p95': _ms(lat['p95']),
            'frames_in': str(self.input.total),
            'frames_out': str(self.output.total),
            'frames_dropped': str(self.dropped),
            'errors': str(self.errors),
            **self.connections(),
            **self._values,
        }
        if self._error:
            level, message = DiagnosticStatus.ERROR, self._error
        elif self._warning:
            level, message = DiagnosticStatus.WARN, self._warning
        else:
            level, message = DiagnosticStatus.OK, 'ok'
        return DiagnosticStatus(level=level, name=self.name, message=message,
                                hardware_id=self.hardware_id,
                                values=[KeyValue(key=k, value=v) for k, v in values.items()])

    def publish(self) -> None:
        for refresh in self._refresh:
            refresh()
        msg = DiagnosticArray()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.status = [self.status()]
        self._pub.publish(msg)


def _ms(seconds: float) -> str:
    return 'nan' if math.isnan(seconds) else f'{seconds * 1e3:.2f}'
