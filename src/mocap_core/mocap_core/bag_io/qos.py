"""QoS profiles between rclpy and the ``offered_qos_profiles`` of rosbag2 metadata.

A bag stores, per topic, the QoS its publishers offered (rosbags :class:`~rosbags.interfaces.Qos`,
rosbag2 metadata version 9 dicts in ``metadata.yaml`` and the MCAP channel metadata). The
functions here convert rclpy ``QoSProfile`` objects (e.g. from
``node.get_publishers_info_by_topic``), metadata dicts and YAML text to that form, and choose an
rclpy profile compatible with a set of offers (for a player's publishers or a recorder's
subscriptions). Durations are kept in integer nanoseconds (``QosTime(sec, nsec)``).

rclpy is imported only by :func:`adapted_qos`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import ReaderError
from rosbags.rosbag2.metadata import dump_qos_v9, parse_qos

from .errors import BagError

if TYPE_CHECKING:
    from collections.abc import Sequence

__all__ = ['adapted_qos', 'parse_qos_text', 'qos_list', 'qos_to_bag', 'qos_to_dicts']

_NS = 1_000_000_000


def _enum(enum_cls: Any, value: Any, unknown: Any) -> Any:
    """``value`` (an enum of rclpy or rosbags, its name or its int) as a member of ``enum_cls``;
    ``unknown`` when it has no counterpart."""
    if isinstance(value, enum_cls):
        return value
    raw = getattr(value, 'value', value)
    if isinstance(raw, str):
        return enum_cls.__members__.get(raw.upper(), unknown)
    try:
        return enum_cls(int(raw))
    except (TypeError, ValueError):
        return unknown


def _qtime(value: Any) -> QosTime:
    """A duration (rosbags ``QosTime``, ``{'sec', 'nsec'}`` dict, rclpy ``Duration`` or int ns)
    as ``QosTime``."""
    if isinstance(value, QosTime):
        return value
    if isinstance(value, dict):
        return QosTime(int(value['sec']), int(value['nsec']))
    ns = getattr(value, 'nanoseconds', value)  # rclpy Duration or int ns
    sec, nsec = divmod(int(ns), _NS)
    return QosTime(sec, nsec)


def qos_to_bag(qos: Any) -> Qos:
    """Convert one QoS profile to the rosbags ``Qos`` stored in bag metadata.

    Accepts a rosbags ``Qos``, an rclpy ``QoSProfile`` (e.g. from
    ``node.get_publishers_info_by_topic``) or a dict in rosbag2 metadata form.
    """
    if isinstance(qos, Qos):
        return qos
    if isinstance(qos, dict):
        parsed = parse_qos([qos])  # type: ignore[list-item]
        return parsed[0]
    try:
        return Qos(
            _enum(QosHistory, qos.history, QosHistory.UNKNOWN),
            int(qos.depth),
            _enum(QosReliability, qos.reliability, QosReliability.UNKNOWN),
            _enum(QosDurability, qos.durability, QosDurability.UNKNOWN),
            _qtime(qos.deadline),
            _qtime(qos.lifespan),
            _enum(QosLiveliness, qos.liveliness, QosLiveliness.UNKNOWN),
            _qtime(qos.liveliness_lease_duration),
            bool(qos.avoid_ros_namespace_conventions),
        )
    except AttributeError as exc:
        raise BagError(f'cannot use {type(qos).__name__} as a QoS profile: {exc}') from None


def parse_qos_text(text: str) -> list[Qos]:
    """The profiles of an ``offered_qos_profiles`` YAML text (MCAP channel metadata); an empty
    list when the text cannot be parsed (such metadata is advisory)."""
    try:
        return parse_qos(text)
    except (ReaderError, KeyError, TypeError):
        return []


def qos_list(qos: Any) -> list[Qos]:
    """Offered QoS in any accepted form as a list of rosbags ``Qos``.

    ``qos`` may be None (no profiles), YAML text as stored by rosbag2, one profile in a form
    :func:`qos_to_bag` accepts, or a list of those. Raises :class:`BagError` for invalid text.
    """
    if qos is None:
        return []
    if isinstance(qos, str):
        try:
            return parse_qos(qos)
        except (ReaderError, KeyError, TypeError) as exc:
            raise BagError(f'invalid offered QoS profiles text: {exc}') from None
    if isinstance(qos, (list, tuple)) and not isinstance(qos, Qos):
        return [qos_to_bag(x) for x in qos]
    return [qos_to_bag(qos)]


def qos_to_dicts(qos: Sequence[Qos] | None) -> list[dict]:
    """QoS profiles in the dict form of rosbag2 (version 9) metadata."""
    return [dict(x) for x in dump_qos_v9(list(qos or []))]


def adapted_qos(offers: Sequence[Any] | None, *, depth: int = 100) -> Any:
    """An rclpy ``QoSProfile`` compatible with all ``offers`` (publishers' offered QoS).

    Like rosbag2: reliable unless some offer is best effort, transient-local only when every
    offer is transient-local, keep-last with at least ``depth`` (or the largest offered depth).
    ``offers`` may be rosbags ``Qos`` (from a bag) or rclpy profiles (from the graph).
    """
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    bag_offers = [qos_to_bag(x) for x in (offers or [])]
    reliability = ReliabilityPolicy.RELIABLE
    durability = DurabilityPolicy.VOLATILE
    if bag_offers:
        if any(x.reliability == QosReliability.BEST_EFFORT for x in bag_offers):
            reliability = ReliabilityPolicy.BEST_EFFORT
        if all(x.durability == QosDurability.TRANSIENT_LOCAL for x in bag_offers):
            durability = DurabilityPolicy.TRANSIENT_LOCAL
        depth = max([depth] + [x.depth for x in bag_offers if x.history == QosHistory.KEEP_LAST])
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(1, int(depth)),
                      reliability=reliability, durability=durability)
