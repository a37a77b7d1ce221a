"""The person's size from a known camera pose: the stance feet stand on the floor (no ROS
imports).

2D keypoints of one person fix their pose up to one scale: a tall person far away and a short
one nearby project alike, and the network's guess of the size carries little information
(docs/lifter.md, "What the keypoints cannot tell"). A robot that knows its camera's pose in a
world frame whose floor is known (REP-105's ``odom`` or ``map`` of a ground robot: the floor is
``z = floor_z``, z up) knows more: a foot that stands on the floor is on that plane. Scaling the
lifted body by ``k`` about the camera centre (every bone and the root position, along the
camera rays: the projection is unchanged) moves a contact point ``X`` (camera optical frame, m)
to ``k X``, at world height ``k (u . X) + t_z`` with ``u`` the world's up in camera axes (the
third row of ``R_world_camera``) and ``t_z`` the camera's height. A stance point sits
``contact_height`` above the floor (:data:`CONTACT_HEIGHTS`), so each one gives::

    k = (floor_z + contact_height - t_z) / (u . X)

:class:`SizeFromKnownFloor` turns every such sample into the height (:meth:`Skeleton.height`)
the person's skeleton would need, keeps the samples of the last ``window_s`` seconds, and
gives each frame the factor that takes its skeleton to the median height. Samples whose
point is less than ``min_drop`` below the camera (a camera near the floor: the ratio is
ill-conditioned) or whose factor is outside the plausible statures are not taken. The
target changes only when the median moves by more than ``update`` (a fraction), and the
size applied follows it at ``rate`` (a fraction per second) from the network's own size: a
size that jumped would move the whole body along the camera rays in one frame (0.5 m for a
10 % change 5 m away), and the skeleton the later stages build their models from would
change every frame.

Conventions: poses in the camera's optical frame (x right, y down, z forward), m; the camera
pose ``(R, t)`` with ``p_world = R p_optical + t``
(:class:`mocap_core.camera_pose.KnownCameraPoses`); contact probabilities in
:data:`~mocap_core.skeleton.CONTACT_POINT_NAMES` order.
"""

from __future__ import annotations

import collections
from typing import Deque, Optional, Tuple

import numpy as np

from mocap_core.pose import Pose
from mocap_core.skeleton import CONTACT_POINT_NAMES, STATURE_OFFSET, STATURE_SLOPE, Skeleton

#: Height above the floor of each contact point (:meth:`Skeleton.contact_points`, in
#: :data:`CONTACT_POINT_NAMES` order) of a foot that stands, m; NaN: the point gives no sample.
#: The toe joint of the rendered bodies' ground truth, in the frames where it stands still
#: (below 0.15 m/s): median 4.5 cm on the 37 travel clips, 3.5 cm on the committed CMU clip.
#: The heel point is left out: where it sits depends on the motion data's foot pitch (0.0 on
#: the CMU clip, 7 cm median on the travel clips; docs/lifter.md, "The size from a known
#: floor").
CONTACT_HEIGHTS = (float('nan'), 0.04, float('nan'), 0.04)

#: The longest time between two frames the applied height follows the target for, s (a gap
#: in the frames does not let the size jump).
MAX_RAMP_STEP_S = 0.1


class SizeFromKnownFloor:
    """One person's size from their stance feet on a known floor (module docstring).

    Args:
        floor_z: the floor's height in the camera pose's world frame, m.
        contact_heights: (4,) height of each stance contact point above the floor, m (NaN:
            the point gives no sample).
        window_s: samples older than this (by stamp, behind the newest) are forgotten.
        min_samples: samples needed before a factor other than 1 is given (each stance
            point of a frame gives one: the toes of a person standing give 20 in 0.33 s).
        min_drop: a point less than this far below the camera (m, along the world's up) gives
            no sample.
        threshold: contact probability from which a point is in stance.
        update: the target height changes only when the median moves by more than this
            fraction of it.
        rate: the applied height follows the target at most this fraction of itself per
            second (from the network's own size when the first estimate comes), so that the
            body does not jump along the camera rays; 0: at once.
        statures: (min, max) plausible statures, m; samples outside are not taken.
    """

    def __init__(self, floor_z: float = 0.0,
                 contact_heights: Tuple[float, ...] = CONTACT_HEIGHTS,
                 window_s: float = 20.0, min_samples: int = 20, min_drop: float = 0.3,
                 threshold: float = 0.5, update: float = 0.01, rate: float = 0.1,
                 statures: Tuple[float, float] = (1.0, 2.2)) -> None:
        heights = np.asarray(contact_heights, dtype=float)
        if not (np.isfinite(floor_z) and heights.shape == (len(CONTACT_POINT_NAMES),)
                and np.all(np.isfinite(heights) | np.isnan(heights))
                and np.any(np.isfinite(heights))):
            raise ValueError('floor_z must be finite, contact_heights (4,) finite or NaN, '
                             'one at least finite')
        if window_s <= 0 or min_samples < 1 or min_drop <= 0 or update < 0 or rate < 0:
            raise ValueError('window_s, min_samples and min_drop must be > 0, update and rate '
                             '>= 0')
        lo, hi = statures
        if not STATURE_OFFSET < lo < hi:
            raise ValueError(f'statures must satisfy {STATURE_OFFSET} < min < max')
        self.floor_z = float(floor_z)
        self.contact_heights = heights
        self.window_ns = int(window_s * 1e9)
        self.min_samples = int(min_samples)
        self.min_drop = float(min_drop)
        self.threshold = float(threshold)
        self.update = float(update)
        self.rate = float(rate)
        # heights (Skeleton.height) of the plausible statures
        self.heights = tuple((s - STATURE_OFFSET) / STATURE_SLOPE for s in statures)
        self._samples: Deque[Tuple[int, float]] = collections.deque()
        #: the skeleton height the median gives (None: too few samples yet) and the one the
        #: factors take the body to, which follows it at ``rate``
        self.target_height: Optional[float] = None
        self.applied_height: Optional[float] = None
        self._last_stamp: Optional[int] = None
        #: samples taken and refused (out of the plausible statures) so far
        self.taken = 0
        self.refused = 0

    def observe(self, stamp_ns: int, pose: Pose, contacts: np.ndarray,
                camera: Optional[Tuple[np.ndarray, np.ndarray]]) -> int:
        """Take the samples of one lifted frame (``pose`` in the camera's optical frame as the
        network gave it, before any factor of this class; ``contacts`` (4,) probabilities;
        ``camera`` the pose (R (3, 3), t (3,)) of the frame's stamp, or None), and move the
        applied height towards the estimate by the frame's time. Frames come in stamp
        order. Returns the samples taken."""
        taken = 0 if camera is None else self._sample(stamp_ns, pose, contacts, camera)
        self.taken += taken
        newest = self._samples[-1][0] if self._samples else None
        while self._samples and self._samples[0][0] < newest - self.window_ns:
            self._samples.popleft()
        if len(self._samples) >= self.min_samples:
            median = float(np.median([h for _, h in self._samples]))
            if self.target_height is None or \
                    abs(median / self.target_height - 1.0) > self.update:
                self.target_height = median
        self._ramp(int(stamp_ns), pose.skeleton.height())
        return taken

    def _sample(self, stamp_ns: int, pose: Pose, contacts: np.ndarray,
                camera: Tuple[np.ndarray, np.ndarray]) -> int:
        """Keep the heights the frame's stance points give; returns how many."""
        R, t = camera
        up = np.asarray(R, dtype=float)[2]             # the world's up in camera axes
        cps = pose.contact_positions()
        height = pose.skeleton.height()
        probs = np.asarray(contacts, dtype=float).reshape(-1)
        taken = 0
        for name, p, above in zip(CONTACT_POINT_NAMES, probs, self.contact_heights):
            if not (p > self.threshold and np.isfinite(above)):
                continue
            drop = float(up @ cps[name])                # < 0: below the camera
            if not drop < -self.min_drop:
                continue
            h = (self.floor_z + above - float(t[2])) / drop * height
            if not (np.isfinite(h) and self.heights[0] <= h <= self.heights[1]):
                self.refused += 1
                continue
            self._samples.append((int(stamp_ns), h))
            taken += 1
        return taken

    def _ramp(self, stamp_ns: int, network_height: float) -> None:
        """Move the applied height towards the target at ``rate`` (from the network's own
        size, ``network_height``, when the first target comes)."""
        last, self._last_stamp = self._last_stamp, stamp_ns
        target = self.target_height
        if target is None:
            return
        if self.applied_height is None:
            self.applied_height = target if self.rate <= 0 else float(network_height)
        if self.rate <= 0:
            self.applied_height = target
            return
        dt = 0.0 if last is None else min(max((stamp_ns - last) * 1e-9, 0.0), MAX_RAMP_STEP_S)
        step = self.rate * dt * self.applied_height
        self.applied_height += float(np.clip(target - self.applied_height, -step, step))

    @property
    def samples(self) -> int:
        """Samples in the window."""
        return len(self._samples)

    def factor(self, skeleton: Skeleton) -> float:
        """The factor that takes ``skeleton`` (and the root position) to the estimated size;
        1 without an estimate."""
        if self.applied_height is None:
            return 1.0
        return float(self.applied_height / skeleton.height())

    def stature(self) -> Optional[float]:
        """The estimated stature (floor to the top of the head, m), None without one."""
        if self.applied_height is None:
            return None
        return float(STATURE_SLOPE * self.applied_height + STATURE_OFFSET)


def scale_pose(pose: Pose, factor: float) -> Pose:
    """``pose`` with every bone and the root position ``factor`` times as long: the body
    scaled about the frame's origin (for a camera-frame pose, along the camera rays)."""
    if factor == 1.0:
        return pose
    return Pose(pose.skeleton.scaled(factor), pose.rotations, pose.root_position * factor)
