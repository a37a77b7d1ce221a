"""QoS profiles of the pipeline's topics (docs/design.md §2).

* :data:`SENSOR_QOS` — keypoints and the camera stream: best effort, keep the last few; a
  slow consumer gets the newest frame instead of a queue of stale ones.
* :data:`STREAM_QOS` — per-frame outputs of the lifter, physics and global stages: reliable,
  keep last 30 (one second at 30 fps), so recorders and the next stage get every message
  through a short stall of the consumer.
* :func:`input_qos` — a stage's subscription to its per-frame input: the publisher's
  reliability with a deeper queue (``depth``), so nothing received is lost while a callback
  is momentarily slow (e.g. the first network inference).
* :data:`LATCHED_QOS` — ``/mocap/skeleton/urdf``: reliable, transient local, depth 1, so a
  late subscriber (robot_state_publisher, RViz) still receives the current skeleton.
* :data:`DIAGNOSTICS_QOS` — ``/diagnostics``: reliable, keep last 10 (what the ROS 2
  diagnostic aggregator expects).
"""

from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy,
                       qos_profile_sensor_data)

SENSOR_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5,
                        reliability=qos_profile_sensor_data.reliability,
                        durability=DurabilityPolicy.VOLATILE)
STREAM_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=30,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE)
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
DIAGNOSTICS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                             reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.VOLATILE)


def input_qos(base: QoSProfile, depth: int) -> QoSProfile:
    """``base`` (reliability, durability) with a history of ``depth`` messages."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=int(depth),
                      reliability=base.reliability, durability=base.durability)
