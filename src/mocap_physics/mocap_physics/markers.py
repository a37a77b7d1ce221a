"""Markers and transform messages of the physics node (ROS message types, no rclpy).

:func:`friction_cone_lines` gives the geometry (plain numpy, tested on its own);
:func:`friction_cone_spec` and :func:`friction_cone_marker` wrap it in a marker and
:func:`floor_transform_msg` writes the floor frame as a serialised geometry_msgs/TransformStamped.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

#: Namespace of the friction-cone marker in /mocap/physics/markers.
CONE_NS = 'physics_friction_cones'


def friction_cone_lines(apexes: np.ndarray, friction: float, height: float = 0.12,
                        segments: int = 12) -> np.ndarray:
    """Line segments drawing the friction cones ``|f_t| <= mu f_n`` (normal = +z) at each
    apex: ``segments`` generators from the apex to a circle of radius ``mu height`` at
    ``height`` above it, and the circle.

    Returns:
        (2 * 2 * segments * N, 3) points, consecutive pairs are segments (LINE_LIST order).
    """
    apexes = np.asarray(apexes, dtype=float).reshape(-1, 3)
    ang = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([friction * height * np.cos(ang), friction * height * np.sin(ang),
                     np.full(segments, height)], axis=1)
    out = []
    for a in apexes:
        top = a + ring
        for k in range(segments):
            out += [a, top[k], top[k], top[(k + 1) % segments]]
    return np.array(out).reshape(-1, 3)


def friction_cone_spec(apexes: np.ndarray, friction: float,
                       color: Sequence[float] = (0.1, 0.8, 0.9, 0.8)):
    """The LINE_LIST marker (ns :data:`CONE_NS`, id 0) of the friction cones at the contact
    points that carry a force, as a :class:`mocap_core.ros_conversions.MarkerSpec`; a DELETE
    marker when there is none."""
    from visualization_msgs.msg import Marker

    from mocap_core.ros_conversions import MarkerSpec

    apexes = np.asarray(apexes, dtype=float).reshape(-1, 3)
    if len(apexes) == 0:
        return MarkerSpec(CONE_NS, 0, Marker.LINE_LIST, action=Marker.DELETE)
    return MarkerSpec(CONE_NS, 0, Marker.LINE_LIST, action=Marker.ADD, scale=(0.005, 0.0, 0.0),
                      color=tuple(float(c) for c in color),
                      points=friction_cone_lines(apexes, friction))


def friction_cone_marker(header, apexes: np.ndarray, friction: float,
                         color: Sequence[float] = (0.1, 0.8, 0.9, 0.8)):
    """:func:`friction_cone_spec` as a visualization_msgs/Marker stamped ``header``."""
    from mocap_core.ros_conversions import marker_array

    return marker_array([friction_cone_spec(apexes, friction, color)], header).markers[0]


#: The last floor converted by :func:`floor_transform_msg` and its inverse's rotation (x, y,
#: z, w) and translation.
_FLOOR_CACHE: dict = {}


def floor_transform_msg(header, floor, child_frame_id: str):
    """geometry_msgs/TransformStamped (serialised, bytes) of the floor frame in the source
    (camera) frame: ``header.frame_id`` = source frame, ``child_frame_id`` = the floor frame,
    transform = ``T_floor_camera^-1`` (a point p_floor in the floor frame is ``rotation *
    p_floor + translation`` in the camera frame), as tf2 would store it."""
    from mocap_core import cdr

    if _FLOOR_CACHE.get("floor") is not floor:   # the same floor until a fit is blended in
        inv = floor.inverse()
        _FLOOR_CACHE.update(floor=floor, q=inv.quaternion(), t=inv.translation)
    return cdr.transform_stamped(header, child_frame_id, _FLOOR_CACHE['q'], _FLOOR_CACHE['t'])
