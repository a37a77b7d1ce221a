"""A TF tree per body (REP-155 style): ``body_<id>`` and ``body_<id>/<joint>`` on ``/tf``.

Frames of one person ``<id>`` (docs/design.md, "Several people"):

* ``body_<id>``: the root joint (pelvis), child of the stage's output frame (``world`` for the
  world stage): the root pose.
* ``body_<id>/<joint>`` for every other joint, child of its parent joint's frame
  (``body_<id>`` for the joints on the pelvis): translation = the joint's offset from its
  parent (m, the skeleton's bone), rotation = the joint's rotation relative to its parent,
  exactly the transforms of the motion message. So ``tf2`` gives any joint of any person in
  any frame, and RViz's TF display draws each skeleton.

:func:`pose_to_transforms` builds the ``geometry_msgs/TransformStamped`` list (no ROS node
needed), :func:`pose_frames` the same as arrays. :class:`TfBroadcaster` publishes them as
``tf2_msgs/TFMessage``; ``tf2_msgs`` has no wheel, the workspace builds it
(``src/tf2_msgs``), and where it is missing the broadcaster says so once and stays silent.
"""

from __future__ import annotations

from typing import List, Optional, Sequence, Tuple

import numpy as np
from geometry_msgs.msg import TransformStamped
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Header

from . import cdr
from .pose import Pose
from .ros_conversions import transform_stamped
from .topics import body_name

#: ``/tf`` as tf2_ros's TransformBroadcaster publishes it.
TF_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                    reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE)
TF_TOPIC = '/tf'


def joint_frame(person_id: int, joint: str, root: str = 'pelvis') -> str:
    """The TF frame of ``joint`` of person ``person_id``: ``body_<id>`` for the root,
    ``body_<id>/<joint>`` otherwise."""
    return body_name(person_id) if joint == root else f'{body_name(person_id)}/{joint}'


def pose_frames(pose: Pose, header: Header, person_id: int
                ) -> Tuple[List[str], List[str], np.ndarray]:
    """The TF frames of one person's pose (module docstring) as arrays: the parent and child
    frame ids (J,) and the (J, 7) transforms, translation x, y, z (m) and rotation x, y, z, w,
    root first; ``header.frame_id`` is the frame the root pose is in."""
    names = list(pose.joint_names)
    parents = pose.skeleton.parents
    children = [joint_frame(person_id, n, names[0]) for n in names]
    frames = [header.frame_id] + [children[parents[j]] for j in range(1, len(names))]
    return frames, children, cdr.pose_transforms(pose)


def pose_to_transforms(pose: Pose, header: Header, person_id: int) -> List[TransformStamped]:
    """The TF frames of one person's pose (module docstring); ``header.frame_id`` is the
    frame the root pose is in. Returns one transform per joint, root first."""
    parents, children, transforms = pose_frames(pose, header, person_id)
    return [transform_stamped(Header(stamp=header.stamp, frame_id=parent), child, tr[3:],
                              tr[:3])
            for parent, child, tr in zip(parents, children, transforms)]


class TfBroadcaster:
    """Publishes transforms on ``/tf`` from ``node`` (``tf2_msgs/TFMessage``, tf2_ros's QoS).

    ``available`` is False when ``tf2_msgs`` cannot be imported (the workspace was built
    without a compiler): :meth:`send` then does nothing, and the node is told once why.
    """

    def __init__(self, node) -> None:
        self.node = node
        self.sent = 0
        try:
            from tf2_msgs.msg import TFMessage
        except ImportError:
            self._msg = None
            self._pub = None
            node.get_logger().warn(
                'publish_tf: tf2_msgs is not available (the workspace builds it from its '
                'message definition; that needs cmake and a C/C++ compiler, see '
                'src/tf2_msgs/README.md): no /tf')
            return
        self._msg = TFMessage
        self._pub = node.create_publisher(TFMessage, TF_TOPIC, TF_QOS)

    @property
    def available(self) -> bool:
        return self._pub is not None

    def send(self, transforms: Sequence[TransformStamped]) -> None:
        if self._pub is None or not transforms:
            return
        self._pub.publish(self._msg(transforms=list(transforms)))
        self.sent += 1

    def send_pose(self, pose: Pose, header: Header, person_id: int) -> None:
        """The frames of one person's pose (:func:`pose_frames`), serialised straight from
        the arrays (:func:`mocap_core.cdr.tf_message`)."""
        if self._pub is None:
            return
        self._pub.publish(cdr.tf_message(header.stamp, *pose_frames(pose, header, person_id)))
        self.sent += 1

    def subscribers(self) -> int:
        return 0 if self._pub is None else self._pub.get_subscription_count()


def body_transforms(bodies: Sequence[tuple], header: Header,
                    only: Optional[Sequence[int]] = None) -> List[TransformStamped]:
    """Transforms of several ``(id, Pose)`` in one list (those in ``only``, if given)."""
    out: List[TransformStamped] = []
    for pid, pose in bodies:
        if only is None or pid in only:
            out.extend(pose_to_transforms(pose, header, pid))
    return out
