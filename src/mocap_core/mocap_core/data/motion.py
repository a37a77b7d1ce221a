"""Clip-level motion processing: resampling, floor height and foot contact labels (no ROS).

A motion here is a sequence on the pipeline skeleton: ``rotations`` (F, J, 4) local unit
quaternions (x, y, z, w) relative to the rest pose (row 0 = root orientation in the world),
``root_positions`` (F, 3) metres in the world frame (z up), and a :class:`Skeleton`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np

from ..kinematics import forward_kinematics
from ..rotations import quat_normalize, quat_slerp
from ..skeleton import CONTACT_POINT_NAMES, Skeleton

#: Foot contact thresholds (MotioNet §3.3 labels contacts from the height of the foot joints
#: above the ground and their velocity). A heel or toe point is in contact when it is at most
#: CONTACT_HEIGHT_M above the clip's floor AND moves slower than CONTACT_SPEED_M_S (3D speed,
#: central differences).
CONTACT_HEIGHT_M = 0.05
CONTACT_SPEED_M_S = 0.45

#: The floor of a clip is this percentile of the per-frame lowest contact point height: robust
#: to a few frames of marker glitches below the floor while following the feet otherwise.
FLOOR_PERCENTILE = 5.0
#: Capture floors are not always level (CMU walks rise 5-8 cm over 3-4 m): the floor is fitted
#: as a plane z = a + b x + c y through the stance feet when the clip travels at least
#: FLOOR_PLANE_MIN_EXTENT_M and the fitted slope stays below FLOOR_PLANE_MAX_SLOPE; otherwise
#: it is flat at the percentile height.
FLOOR_PLANE_MIN_EXTENT_M = 1.0
FLOOR_PLANE_MAX_SLOPE = 0.05


def make_continuous(q: np.ndarray) -> np.ndarray:
    """Flip quaternion signs along axis 0 so consecutive frames lie in the same hemisphere.

    Args:
        q: (F, ..., 4) quaternions. Returns a copy; the rotations are unchanged.
    """
    q = np.array(q, dtype=np.float64)
    for f in range(1, len(q)):
        dot = np.sum(q[f] * q[f - 1], axis=-1, keepdims=True)
        q[f] = np.where(dot < 0, -q[f], q[f])
    return q


def resample(rotations: np.ndarray, root_positions: np.ndarray, fps_in: float,
             fps_out: float) -> Tuple[np.ndarray, np.ndarray]:
    """Resample a motion to ``fps_out`` (slerp for rotations, linear for the root).

    Output frame k is at time k / fps_out, for every such time within the input's span
    [0, (F-1) / fps_in].

    Args:
        rotations: (F, J, 4) quaternions x, y, z, w.
        root_positions: (F, 3) metres.
    Returns:
        (F', J, 4) rotations and (F', 3) root positions.
    """
    rotations = np.asarray(rotations, dtype=np.float64)
    root_positions = np.asarray(root_positions, dtype=np.float64)
    if fps_in <= 0 or fps_out <= 0:
        raise ValueError(f'frame rates must be positive, got {fps_in} -> {fps_out}')
    n = len(rotations)
    if n != len(root_positions) or n == 0:
        raise ValueError('rotations and root positions must have the same, non-zero length')
    duration = (n - 1) / fps_in
    count = int(np.floor(duration * fps_out + 1e-9)) + 1
    t = np.arange(count) * (fps_in / fps_out)  # in input frames
    return frames_at(make_continuous(rotations), root_positions, t)


def frames_at(rotations: np.ndarray, positions: Optional[np.ndarray], at: np.ndarray
              ) -> Tuple[np.ndarray, Optional[np.ndarray]]:
    """Frames at fractional indices: slerp between the two neighbouring rotations (along the
    shortest path) and linear interpolation of the positions.

    Args:
        rotations: (N, J, 4) quaternions x, y, z, w.
        positions: (N, 3) or None.
        at: (T,) fractional frame indices in [0, N - 1].
    Returns:
        (T, J, 4) unit quaternions and (T, 3) positions (None if ``positions`` is None).
    """
    rotations = np.asarray(rotations, dtype=np.float64)
    at = np.asarray(at, dtype=np.float64)
    n = len(rotations)
    i0 = np.clip(np.floor(at).astype(np.int64), 0, n - 1)
    i1 = np.minimum(i0 + 1, n - 1)
    w = (at - i0)[:, None]
    rot = quat_normalize(quat_slerp(rotations[i0], rotations[i1], w))
    if positions is None:
        return rot, None
    positions = np.asarray(positions, dtype=np.float64)
    return rot, (1.0 - w) * positions[i0] + w * positions[i1]


def retime(motion: 'Motion', speed: float) -> 'Motion':
    """The motion played at ``speed`` times its pace, at its own frame rate: 0.5 is slow
    motion (twice the frames, each step half as far), 2 is fast forward. Rotations are
    slerped and the root interpolated linearly (:func:`resample`); each output frame takes
    the contact labels of the nearest input frame. ``speed`` 1 returns the motion itself."""
    if not speed > 0:
        raise ValueError(f'speed must be > 0, got {speed}')
    if speed == 1.0:
        return motion
    rot, root = resample(motion.rotations, motion.root_positions, motion.fps,
                         motion.fps / speed)
    near = np.minimum(np.round(np.arange(len(rot)) * speed).astype(np.int64),
                      motion.num_frames - 1)
    return Motion(motion.name, motion.fps, motion.skeleton, rot, root,
                  np.asarray(motion.contacts)[near])


def contact_point_positions(skeleton: Skeleton, rotations: np.ndarray,
                            root_positions: np.ndarray) -> np.ndarray:
    """(F, 4, 3) world positions of the heel and toe points (:data:`CONTACT_POINT_NAMES`)."""
    fk = forward_kinematics(skeleton.parents, skeleton.offsets, rotations, root_positions)
    pts = []
    for name in CONTACT_POINT_NAMES:
        j, local = skeleton.contact_points()[name]
        pts.append(fk.positions[:, j] + fk.global_rotations[:, j] @ local)
    return np.stack(pts, axis=1)


def floor_height(contact_positions: np.ndarray) -> float:
    """Floor height (m, world z) of a clip from its (F, 4, 3) contact point positions."""
    lowest = np.min(contact_positions[..., 2], axis=1)
    return float(np.percentile(lowest, FLOOR_PERCENTILE))


def floor_plane(contact_positions: np.ndarray, fps: float) -> np.ndarray:
    """Floor plane (a, b, c) with z = a + b x + c y (m, world frame) of a clip.

    Fitted by least squares through the lowest contact point of every frame in which that
    point is slow (stance), refitted once without residuals above 2 cm; flat at
    :func:`floor_height` when the clip covers less than FLOOR_PLANE_MIN_EXTENT_M, has fewer
    than 10 stance frames, or the slope exceeds FLOOR_PLANE_MAX_SLOPE.
    """
    p = np.asarray(contact_positions, dtype=np.float64)
    flat = np.array([floor_height(p), 0.0, 0.0])
    low = p[np.arange(len(p)), np.argmin(p[..., 2], axis=1)]  # (F, 3)
    if len(p) < 10 or np.ptp(low[:, 0]) + np.ptp(low[:, 1]) < FLOOR_PLANE_MIN_EXTENT_M:
        return flat
    speed = np.linalg.norm(np.gradient(low, 1.0 / fps, axis=0), axis=-1)
    stance = low[speed <= CONTACT_SPEED_M_S]
    if len(stance) < 10:
        return flat
    design = np.column_stack([np.ones(len(stance)), stance[:, 0], stance[:, 1]])
    coef = np.linalg.lstsq(design, stance[:, 2], rcond=None)[0]
    keep = np.abs(design @ coef - stance[:, 2]) <= 0.02
    if keep.sum() >= 10:
        coef = np.linalg.lstsq(design[keep], stance[keep, 2], rcond=None)[0]
    if np.hypot(coef[1], coef[2]) > FLOOR_PLANE_MAX_SLOPE:
        return flat
    # keep the same robust offset as the flat floor, measured against the plane
    resid = np.min(p[..., 2] - (coef[0] + coef[1] * p[..., 0] + coef[2] * p[..., 1]), axis=1)
    coef[0] += np.percentile(resid, FLOOR_PERCENTILE)
    return coef


def height_above_floor(points: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """Height (m) of (..., 3) points above the floor plane (a, b, c)."""
    return points[..., 2] - (plane[0] + plane[1] * points[..., 0] + plane[2] * points[..., 1])


def contact_labels(contact_positions: np.ndarray, fps: float, floor_z: float,
                   height_m: float = CONTACT_HEIGHT_M,
                   speed_m_s: float = CONTACT_SPEED_M_S) -> np.ndarray:
    """(F, 4) boolean contact labels of the heel/toe points (module docstring thresholds)."""
    p = np.asarray(contact_positions, dtype=np.float64)
    if len(p) < 2:
        speed = np.zeros(p.shape[:2])
    else:
        vel = np.gradient(p, 1.0 / fps, axis=0)
        speed = np.linalg.norm(vel, axis=-1)
    return (p[..., 2] - floor_z <= height_m) & (speed <= speed_m_s)


@dataclass(eq=False)
class Motion:
    """A processed clip: motion on the pipeline skeleton at a fixed rate, floor at z = 0.

    Attributes:
        name: clip identifier (source file or archive member).
        fps: frame rate, Hz.
        skeleton: per-clip bone lengths.
        rotations: (F, J, 4) local quaternions x, y, z, w (row 0: root in the world).
        root_positions: (F, 3) metres, world frame with the floor at z = 0.
        contacts: (F, 4) bool heel/toe contact labels (left_heel, left_toe, right_heel,
            right_toe).
    """

    name: str
    fps: float
    skeleton: Skeleton
    rotations: np.ndarray
    root_positions: np.ndarray
    contacts: np.ndarray

    @property
    def num_frames(self) -> int:
        return len(self.rotations)

    def fk(self):
        """Forward kinematics of the whole clip (positions (F, J, 3), global rotations)."""
        return forward_kinematics(self.skeleton.parents, self.skeleton.offsets, self.rotations,
                                  self.root_positions)


def process_motion(name: str, skeleton: Skeleton, rotations: np.ndarray,
                   root_positions: np.ndarray, fps_in: float, fps_out: float = 30.0) -> Motion:
    """Resample to ``fps_out``, level the floor to z = 0 and label foot contacts.

    The floor plane (:func:`floor_plane`) is removed under the subject: each frame is shifted
    vertically by the plane height at the root's xy, so a sloping capture floor becomes the
    level floor z = 0 of the world frame (docs/design.md §3).
    """
    rot, root = resample(rotations, root_positions, fps_in, fps_out)
    pts = contact_point_positions(skeleton, rot, root)
    plane = floor_plane(pts, fps_out)
    shift = plane[0] + plane[1] * root[:, 0] + plane[2] * root[:, 1]
    root = root - np.stack([np.zeros_like(shift), np.zeros_like(shift), shift], axis=1)
    pts = pts - shift[:, None, None] * np.array([0.0, 0.0, 1.0])
    return Motion(name, float(fps_out), skeleton, rot, root,
                  contact_labels(pts, fps_out, 0.0))
