"""Read and write rosbag2 bags (MCAP storage) as raw CDR bytes.

A *bag* here is what ``ros2 bag record`` writes: a folder with ``metadata.yaml`` and one or more
``.mcap`` files; :class:`BagReader` also opens a single ``.mcap`` file and recovers what a killed
recorder left. Everything is kept as serialised bytes, so copying a bag through
:class:`BagReader` and :class:`BagWriter` is byte-identical. Deserialising is a separate step
(:func:`deserialize`, from :mod:`mocap_core.ros_msgs`).

The package, one module per concern:

- :mod:`.reader`: :class:`BagReader`, :class:`TopicInfo`, :class:`BagMessage`;
- :mod:`.writer`: :class:`BagWriter`;
- :mod:`.typestore`: message definitions and RIHS01 hashes (:func:`message_definition`);
- :mod:`.qos`: QoS between rclpy profiles and the bag's ``offered_qos_profiles``
  (:func:`adapted_qos`, :func:`qos_to_bag`, :func:`qos_to_dicts`);
- :mod:`.errors`: :class:`BagError`.

It needs only ``rosbags`` (and ``mcap`` for the recovery path); rclpy is imported lazily by the
few helpers that build rclpy objects (:meth:`BagWriter.write_msg`, :func:`adapted_qos`).
"""

from __future__ import annotations

from ..ros_msgs import (
    deserialize,
    get_message_class,
    message_to_dict,
    message_to_yaml,
    stamp_to_ns,
)
from .errors import BagError
from .qos import adapted_qos, qos_to_bag, qos_to_dicts
from .reader import BagMessage, BagReader, TopicInfo
from .typestore import message_definition
from .writer import BagWriter

__all__ = [
    'BagError',
    'BagMessage',
    'BagReader',
    'BagWriter',
    'TopicInfo',
    'adapted_qos',
    'deserialize',
    'get_message_class',
    'message_definition',
    'message_to_dict',
    'message_to_yaml',
    'qos_to_bag',
    'qos_to_dicts',
    'stamp_to_ns',
]
