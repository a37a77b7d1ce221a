"""QoS profiles of the pipeline's topics (DESIGN §2).

* :data:`SENSOR_QOS` — keypoints and the camera stream: best effort, keep the last few; a
  slow consumer gets the newest frame instead of a queue of stale ones.
* :data:`STREAM_QOS` — per-frame outputs of the lifter, physics and global stages: reliable,
  keep last 10, so recorders and offline tools get every message.
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
STREAM_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE)
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
DIAGNOSTICS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                             reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.VOLATILE)
