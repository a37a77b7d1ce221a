"""Where the foot touches the floor: the heel point of a foot that is flat (no ROS imports).

The skeleton template's foot bone runs forward and down at 30 degrees, and
:meth:`mocap_core.skeleton.Skeleton.contact_points` puts the heel point at the toe's height in
that pose, so heel and toe are on the floor together when the ankle-to-toe bone is 30 degrees
below the floor. The motion data do not agree on where the toe joint sits: with heel and toe
on the floor that bone is about 40 degrees below the floor in the Bandai Namco clips and about
15 in the CMU ones (medians over the training clips' frames labelled with both contacts), and
the lifter reproduces the convention of what it sees (the rendered validation clips, mostly
Bandai Namco motion: 41 degrees). Holding heel and toe on the floor turns the foot to the
pitch the heel point implies, so the physics can place the heel for another flat-foot pitch
(``flat_foot_pitch_deg``; docs/physics.md).
"""

from __future__ import annotations

from typing import Dict, Tuple

import numpy as np

from mocap_core.pose import Pose
from mocap_core.skeleton import CONTACT_POINT_NAMES, Skeleton

#: The ankle-to-toe pitch (degrees below the floor) of a flat foot in the skeleton template:
#: the rest pose's foot bone runs forward and down at 30 degrees, and
#: :meth:`Skeleton.contact_points` puts the heel point at the toe's height in that pose.
TEMPLATE_FLAT_FOOT_PITCH_DEG = 30.0


def contact_points(skeleton: Skeleton, flat_foot_pitch_deg: float = TEMPLATE_FLAT_FOOT_PITCH_DEG
                   ) -> Dict[str, Tuple[int, np.ndarray]]:
    """The skeleton's contact points (:meth:`Skeleton.contact_points`: name -> (joint index,
    (3,) point in that joint's frame, m)) with the heel placed for a foot that is flat when its
    ankle-to-toe bone points ``flat_foot_pitch_deg`` below the floor (module docstring): a
    quarter of a foot length behind the ankle, at the toe's height, when the ankle joint is
    turned toe-down by ``pitch - 30`` degrees about its lateral (y) axis; 30 gives the
    template's point."""
    out = dict(skeleton.contact_points())
    alpha = np.radians(float(flat_foot_pitch_deg) - TEMPLATE_FLAT_FOOT_PITCH_DEG)
    if alpha == 0.0:
        return out
    foot = skeleton.foot_length()
    theta = np.radians(float(flat_foot_pitch_deg))
    c, s = np.cos(alpha), np.sin(alpha)
    # heel in the flat foot's frame, then into the ankle frame: R_y(-alpha) (R_y(a) maps x to
    # (cos a, 0, -sin a), a toe-down turn)
    x, z = -0.25 * foot, -np.sin(theta) * foot
    point = np.array([c * x - s * z, 0.0, s * x + c * z])
    for side in ('left', 'right'):
        j, _ = out[f'{side}_heel']
        out[f'{side}_heel'] = (j, point.copy())
    return out


def contact_positions(pose: Pose, flat_foot_pitch_deg: float = TEMPLATE_FLAT_FOOT_PITCH_DEG
                      ) -> np.ndarray:
    """(4, 3) positions of the contact points (:data:`CONTACT_POINT_NAMES` order) of ``pose`` in
    its frame, the heel placed by :func:`contact_points` (the template's: the pose's own
    ``contact_positions``)."""
    if float(flat_foot_pitch_deg) == TEMPLATE_FLAT_FOOT_PITCH_DEG:
        cps = pose.contact_positions()
        return np.array([cps[n] for n in CONTACT_POINT_NAMES])
    pos, rot = pose.joint_positions(), pose.global_rotations()
    points = contact_points(pose.skeleton, flat_foot_pitch_deg)
    return np.array([pos[j] + rot[j] @ p for j, p in (points[n] for n in CONTACT_POINT_NAMES)])
