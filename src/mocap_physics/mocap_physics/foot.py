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

from typing import Dict, List, Optional, Sequence, Tuple

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


#: Samples (feet in double contact) before :class:`FlatFootEstimator` gives an estimate.
FLAT_FOOT_MIN_SAMPLES = 60
#: An estimate further than this (degrees) from the pitch in use replaces it.
FLAT_FOOT_UPDATE_DEG = 2.0


class FlatFootEstimator:
    """The flat-foot pitch of a motion stream (``flat_foot_pitch_deg`` -1: auto).

    :meth:`add` takes each target pose in the floor frame (z up, floor z = 0) with its contact
    probabilities (heel, toe; left, right); a foot whose heel and toe are both above
    ``threshold`` and whose toe joint is within ``max_height`` m of the floor gives one sample:
    the angle (degrees) of its ankle-to-toe bone below the floor. :meth:`estimate` is the
    median of the samples once there are ``min_samples``, clipped to 0-60, else None (the
    caller decides once and stops feeding it).
    """

    def __init__(self, threshold: float = 0.5, max_height: float = 0.08,
                 min_samples: int = FLAT_FOOT_MIN_SAMPLES) -> None:
        self.threshold = float(threshold)
        self.max_height = float(max_height)
        self.min_samples = int(min_samples)
        self._samples: List[float] = []

    def add(self, pose: Pose, probabilities: Optional[Sequence[float]]) -> int:
        """Record the feet of ``pose`` that stand flat; returns the samples added (0-2)."""
        if probabilities is None:
            return 0
        prob = np.asarray(probabilities, dtype=float).reshape(-1)
        if prob.shape != (len(CONTACT_POINT_NAMES),) or not np.all(np.isfinite(prob)):
            return 0
        names = pose.skeleton.joint_names
        pos = pose.joint_positions()
        added = 0
        for side in ('left', 'right'):
            heel = prob[CONTACT_POINT_NAMES.index(f'{side}_heel')]
            toe_p = prob[CONTACT_POINT_NAMES.index(f'{side}_toe')]
            ankle, toe = pos[names.index(f'{side}_ankle')], pos[names.index(f'{side}_toe')]
            v = toe - ankle
            length = float(np.linalg.norm(v))
            if heel > self.threshold and toe_p > self.threshold and length > 1e-6 \
                    and np.all(np.isfinite(v)) and toe[2] < self.max_height:
                self._samples.append(float(np.degrees(np.arcsin(np.clip(-v[2] / length,
                                                                        -1.0, 1.0)))))
                added += 1
        return added

    @property
    def samples(self) -> int:
        return len(self._samples)

    def estimate(self) -> Optional[float]:
        if len(self._samples) < self.min_samples:
            return None
        return float(np.clip(np.median(np.asarray(self._samples)), 0.0, 60.0))
