"""Per-person output topics of a stage node (several people; docs/design.md).

:class:`BodyPublishers` owns the publishers of every person a stage currently follows, under
REP-155's layout ``/humans/bodies/body_<id>/<stage>/<name>`` (:func:`mocap_core.topics.
body_topic`). Publishers are created on a person's first frame and destroyed when the person
is gone. A message is built only when its topic has a subscriber (the builder is a callable),
so a person nobody listens to costs a dictionary lookup per topic and frame; the URDF is
transient-local and always published (it changes rarely). :class:`CombinedPublishers` owns a
stage's combined topics (every person of a frame in one message).
"""

from __future__ import annotations

from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Odometry, Path
from sensor_msgs.msg import JointState, PointCloud2
from std_msgs.msg import String
from trajectory_msgs.msg import MultiDOFJointTrajectory
from visualization_msgs.msg import MarkerArray

from . import topics
from .qos import LATCHED_QOS, STREAM_QOS

#: Message type of each per-person output name.
BODY_TOPIC_TYPES: Dict[str, type] = {
    'motion': MultiDOFJointTrajectory,
    'joints3d': PointCloud2,
    'joint_states': JointState,
    'contacts': JointState,
    'markers': MarkerArray,
    'odom': Odometry,
    'path': Path,
    'grf/left': WrenchStamped,
    'grf/right': WrenchStamped,
}


class BodyPublishers:
    """The per-person publishers of one stage node (module docstring).

    Args:
        node: the rclpy node that owns the publishers.
        stage: ``lifter``, ``physics`` or ``world``.
        with_urdf: also keep a transient-local ``/humans/bodies/body_<id>/urdf`` per person.
    """

    def __init__(self, node, stage: str, with_urdf: bool = False) -> None:
        topics.stage_prefix(stage)        # validates the stage
        self.node = node
        self.stage = stage
        self.with_urdf = with_urdf
        self._pubs: Dict[Tuple[int, str], object] = {}
        #: messages built and published, for diagnostics
        self.published = 0

    @property
    def ids(self):
        return sorted({pid for pid, _ in self._pubs})

    def _publisher(self, pid: int, name: str):
        key = (pid, name)
        pub = self._pubs.get(key)
        if pub is None:
            if name == 'urdf':
                pub = self.node.create_publisher(String, topics.body_urdf_topic(pid),
                                                 LATCHED_QOS)
            else:
                pub = self.node.create_publisher(BODY_TOPIC_TYPES[name],
                                                 topics.body_topic(pid, self.stage, name),
                                                 STREAM_QOS)
            self._pubs[key] = pub
        return pub

    def publish(self, pid: int, name: str, build: Callable[[], object]) -> bool:
        """Publish ``build()`` on person ``pid``'s topic ``name`` if anyone subscribes;
        returns whether it was built."""
        pub = self._publisher(pid, name)
        if pub.get_subscription_count() == 0:
            return False
        pub.publish(build())
        self.published += 1
        return True

    def urdf(self, pid: int, build: Callable[[], String]) -> None:
        """Publish person ``pid``'s URDF (transient local: late subscribers get it)."""
        if self.with_urdf:
            self._publisher(pid, 'urdf').publish(build())
            self.published += 1

    def remove(self, pid: int) -> None:
        """Person ``pid`` is gone: destroy their publishers."""
        for key in [k for k in self._pubs if k[0] == pid]:
            self.node.destroy_publisher(self._pubs.pop(key))

    def remove_all(self) -> None:
        for pid in self.ids:
            self.remove(pid)


def by_stamp(released: Sequence[Tuple[int, Sequence[Any]]], main_id: Optional[int]
             ) -> List[Tuple[int, List[Tuple[int, Any]]]]:
    """The frames several people released at once, grouped for the combined messages:
    ``[(stamp_ns, [(id, frame), ...]), ...]`` in stamp order, the main person first in each
    group, then by id. ``released``: ``(id, frames)`` pairs; each frame has ``stamp_ns``."""
    groups: Dict[int, List[Tuple[int, Any]]] = {}
    for pid, frames in released:
        for frame in frames:
            groups.setdefault(int(frame.stamp_ns), []).append((pid, frame))
    return [(stamp, sorted(groups[stamp], key=lambda pf: (pf[0] != main_id, pf[0])))
            for stamp in sorted(groups)]


class CombinedPublishers:
    """One stage's combined topics, every person of a frame in one message
    (``/mocap/<stage>/bodies/{motion,joints3d,markers}``, and ``contacts`` with
    ``with_contacts``); each built only while it has a subscriber.

    Args:
        node: the rclpy node that owns the publishers.
        stage: ``lifter``, ``physics`` or ``world`` (also the markers' namespace prefix).
        with_contacts: also ``/mocap/<stage>/bodies/contacts`` (the lifter's probabilities).
    """

    def __init__(self, node, stage: str, with_contacts: bool = False) -> None:
        names = ['motion', 'joints3d', 'markers'] + (['contacts'] if with_contacts else [])
        self.stage = stage
        self.pubs = {name: node.create_publisher(BODY_TOPIC_TYPES[name],
                                                 topics.bodies_topic(stage, name), STREAM_QOS)
                     for name in names}

    def publish(self, header, bodies: Sequence[Tuple[int, Any, Optional[np.ndarray]]]) -> None:
        """``bodies``: ``(id, Pose, contacts or None)`` of every person of the frame stamped
        ``header``, the main person first; contacts are (4,) probabilities or states (the
        markers colour the contact points by them)."""
        from . import cdr
        from . import ros_conversions as rc
        from .publishing import publish_if_heard

        pubs = self.pubs
        publish_if_heard(pubs['motion'], lambda: cdr.bodies_to_motion(
            [(pid, pose) for pid, pose, _ in bodies], header))
        if 'contacts' in pubs:
            publish_if_heard(pubs['contacts'], lambda: cdr.bodies_contacts_to_msg(
                [(pid, c) for pid, _, c in bodies], header))
        publish_if_heard(pubs['joints3d'], lambda: cdr.bodies_to_cloud(
            np.stack([pose.joint_positions() for _, pose, _ in bodies]),
            [pid for pid, _, _ in bodies], header))
        publish_if_heard(pubs['markers'], lambda: cdr.marker_array(
            [spec for pid, pose, contacts in bodies for spec in rc.pose_marker_specs(
                pose, ns=f'{self.stage}/{topics.body_name(pid)}', color=rc.person_color(pid),
                contacts=contacts)], header))
