"""Feet planted where they stand: a per-leg correction by two-bone inverse kinematics
(no ROS imports).

A pose whose root comes from one source (GMR's path, a fused camera-frame root) and whose
legs come from another (the lifter, the physics) slides its feet over the floor whenever the
two disagree: a lifter whose stride is short under a root that travels a full stride leaves
the stance foot to skate. :class:`FootPlanter` keeps the root and moves the legs instead:

- A contact point (heel or toe, :meth:`~mocap_core.skeleton.Skeleton.contact_points`) stands
  while it is lower than ``lock_height`` above the floor (z-up frame, floor z = 0).
- Per leg, a horizontal correction ``c`` (2,) m is added to where the input puts the foot.
  While points of the leg stand in this frame and stood in the previous one, ``c`` takes up
  their mean horizontal motion in the input (``c -= mean(p_k - p_{k-1})``), so that the
  planted points do not move in the output; a point that lands or lifts changes nothing at
  once (differential, as the world stage's root lock). While no point of the leg stands, ``c``
  decays to zero with ``release_time_constant_s``: the swing foot returns smoothly to where
  the input has it.
- While both legs stand, both corrections leak towards zero with
  ``double_stance_time_constant_s``: a body on two planted feet cannot travel, so a root that
  moves away from both (the drift of a world path under a person who stands still) is not
  followed by ever longer legs; the feet slide slowly back under it instead. A walker's
  double support is short (about 0.1 s a step) and loses little of its correction.
- ``c`` is bounded by ``max_correction`` and by the leg's reach: the hip-ankle distance may
  not exceed ``reach`` times thigh plus shin (nor grow beyond it where it already does; above
  1 the leg straightens and the rest slides). What cannot be reached slides, as little as the
  leg allows, unless the root follows:
- With ``root_follow_time_constant_s`` > 0, what a standing leg cannot take up moves the whole
  body instead (the mean over the standing legs that were cut), so that the foot stays: the
  root is held back by a foot it cannot leave. That offset of the root returns to the input's
  root with the time constant (the legs take the return up while they can). A root that
  runs away from a planted foot by more than a leg can reach is more likely wrong than the
  foot contact (measured in docs/global.md, "Feet planted by the legs").
- The ankle is moved to ``ankle + (c, 0)`` by rotating the hip and the knee (analytic
  two-bone inverse kinematics, the knee kept in its bending plane turned with the leg); the
  foot keeps its orientation, so heel and toe move with the ankle. The ankle's height is the
  input's: the vertical (floor contact, no penetration) is left as it was.

Only the hip, knee and ankle rotations of a corrected leg change, and with the root following,
the root's horizontal position; the trunk's and arms' joint rotations and the skeleton are
the input's. State is per person; :meth:`FootPlanter.reset` starts
afresh (a new segment, a time jump).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, Optional, Tuple

import numpy as np

from .pose import Pose
from .rotations import matrix_to_quat
from .skeleton import JOINT_INDEX, PARENTS

#: leg -> (hip, knee, ankle) joint indices, and its contact point names
LEGS: Dict[str, Tuple[Tuple[int, int, int], Tuple[str, str]]] = {
    side: ((JOINT_INDEX[f'{side}_hip'], JOINT_INDEX[f'{side}_knee'],
            JOINT_INDEX[f'{side}_ankle']), (f'{side}_heel', f'{side}_toe'))
    for side in ('left', 'right')}


@dataclass(frozen=True)
class FootPlantConfig:
    """Settings of :class:`FootPlanter` (module docstring)."""

    lock_height: float = 0.02              # m above the floor under which a point stands
    release_time_constant_s: float = 0.1   # decay of a lifted leg's correction, s
    max_correction: float = 0.35           # m, horizontal
    reach: float = 1.05                    # of thigh + shin, the hip-ankle distance allowed
    double_stance_time_constant_s: float = 0.2   # leak of the corrections while both stand, s
    root_follow_time_constant_s: float = 0.0   # > 0: the root moves by what legs cannot reach, s


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b of two (3,) vectors (np.cross costs ten times more on one pair)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def _norm(v: np.ndarray) -> float:
    return math.sqrt(float(v @ v))


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(3, 3) the smallest rotation taking direction ``a`` (3,) to direction ``b`` (3,)
    (Rodrigues: ``I + [v]x + [v]x^2 / (1 + c)``, ``v = a x b``, ``c = a . b`` of the unit
    vectors; about an axis normal to ``a`` for opposite directions)."""
    a = a / _norm(a)
    b = b / _norm(b)
    c = float(a @ b)
    if c < -1.0 + 1e-12:
        axis = _cross(a, np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9
                      else np.array([0.0, 1.0, 0.0]))
        axis /= _norm(axis)
        return 2.0 * np.outer(axis, axis) - np.eye(3)
    v = _cross(a, b)
    K = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + K + (K @ K) / (1.0 + c)


def bounded_correction(ankle: np.ndarray, hip: np.ndarray, c: np.ndarray, reach: float
                       ) -> np.ndarray:
    """The largest part ``s c`` (s in [0, 1]) of the horizontal correction ``c`` (2,) m that
    keeps the ankle (3,) within ``reach`` m of the hip (3,), or no further from it than it
    already is when it is out of reach before the correction."""
    c3 = np.array([c[0], c[1], 0.0])
    d0 = ankle - hip
    limit = max(reach, _norm(d0))
    if _norm(d0 + c3) <= limit:
        return np.asarray(c, dtype=float)
    # |d0 + s c3|^2 = limit^2, the root in [0, 1]
    a = float(c3 @ c3)
    if a < 1e-18:
        return np.zeros(2)
    b = 2.0 * float(d0 @ c3)
    q = float(d0 @ d0) - limit * limit          # <= 0: the ankle starts within the limit
    s = (-b + math.sqrt(max(b * b - 4 * a * q, 0.0))) / (2 * a)
    return float(np.clip(s, 0.0, 1.0)) * np.asarray(c, dtype=float)


def two_bone_ik(hip: np.ndarray, knee: np.ndarray, ankle: np.ndarray, target: np.ndarray,
                hinge: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """New knee and ankle positions (3,) that put the ankle at ``target`` (or as near as the
    bone lengths allow), with the hip fixed and the bone lengths kept. The knee stays in its
    bending plane, turned with the leg: its side of the hip-ankle line is the one it had.
    ``hinge`` (3,): the bending axis used when the leg is straight (no plane to keep)."""
    l1 = _norm(knee - hip)
    l2 = _norm(ankle - knee)
    to = target - hip
    d = _norm(to)
    if d < 1e-9 or l1 < 1e-9 or l2 < 1e-9:
        return knee.copy(), ankle.copy()
    u = to / d
    d = float(np.clip(d, abs(l1 - l2) + 1e-9, l1 + l2 - 1e-9))
    old = ankle - hip
    n = _cross(old, knee - hip)                 # the bending plane's normal
    if _norm(n) < 1e-6 * l1 * l1:               # straight leg: the given hinge
        n = hinge
    v = _cross(n, u)
    nv = _norm(v)
    if nv < 1e-12:
        return knee.copy(), ankle.copy()
    v /= nv
    cos_a = float(np.clip((l1 * l1 + d * d - l2 * l2) / (2 * l1 * d), -1.0, 1.0))
    new_knee = hip + l1 * (cos_a * u + math.sqrt(1.0 - cos_a * cos_a) * v)
    return new_knee, hip + d * u


class FootPlanter:
    """Online foot planting for one person (module docstring). Feed every frame in order to
    :meth:`apply`; poses are in a z-up frame with the floor at z = 0."""

    def __init__(self, config: FootPlantConfig = FootPlantConfig()):
        self.config = config
        self.reset()

    def reset(self) -> None:
        """Forget the standing points and the corrections (a new segment)."""
        self._correction = {leg: np.zeros(2) for leg in LEGS}
        self._standing: Dict[str, Dict[str, np.ndarray]] = {leg: {} for leg in LEGS}
        #: per leg, the last frame's applied correction, m (diagnostics)
        self.last_correction = {leg: 0.0 for leg in LEGS}
        #: frames in which a leg's correction was cut by its reach or max_correction
        self.limited_frames = 0
        #: the horizontal offset of the root (root_follow_time_constant_s > 0), m
        self.root_offset = np.zeros(2)

    def apply(self, pose: Pose, dt: float, standing: Optional[Dict[str, bool]] = None) -> Pose:
        """The pose with each leg's correction applied. ``dt``: seconds since the previous
        frame (0 for the first). ``standing``: contact point name -> whether it stands, where
        known from elsewhere (default: its height, ``lock_height``). Returns ``pose`` itself
        when nothing is corrected."""
        cfg = self.config
        follow = cfg.root_follow_time_constant_s > 0
        if follow:                  # the root offset returns to the input's root
            self.root_offset = self.root_offset * math.exp(
                -max(dt, 0.0) / cfg.root_follow_time_constant_s)
            if _norm(self.root_offset) < 1e-9:
                self.root_offset = np.zeros(2)
            else:
                pose = Pose(pose.skeleton, pose.rotations,
                            pose.root_position + np.array([*self.root_offset, 0.0]))
        contacts = pose.contact_positions()
        decay = math.exp(-max(dt, 0.0) / cfg.release_time_constant_s) \
            if cfg.release_time_constant_s > 0 else 0.0
        downs = {leg: {n: contacts[n][:2].copy() for n in names
                       if (standing[n] if standing is not None and n in standing
                           else contacts[n][2] < cfg.lock_height)}
                 for leg, (_, names) in LEGS.items()}
        helds = {leg: [n for n in downs[leg] if n in self._standing[leg]] for leg in LEGS}
        tau = cfg.double_stance_time_constant_s
        leak = math.exp(-max(dt, 0.0) / tau) if tau > 0 and all(helds.values()) else 1.0
        positions: Optional[np.ndarray] = None
        G = None
        changed: Dict[int, np.ndarray] = {}       # joint -> its new local rotation (3, 3)
        unreached = []                            # standing legs: the correction not made
        for leg, ((h, k, a), _) in LEGS.items():
            down, held, prev = downs[leg], helds[leg], self._standing[leg]
            c = self._correction[leg]
            if held:
                c = (c - np.mean([down[n] - prev[n] for n in held], axis=0)) * leak
            elif not down:
                c = c * decay
            self._standing[leg] = down
            if positions is None:
                positions = pose.joint_positions()
            wanted = c
            limited = False
            norm = _norm(c)
            if norm > cfg.max_correction:
                c = c * (cfg.max_correction / norm)
                limited = True
            hip, knee, ankle = positions[h], positions[k], positions[a]
            reach = cfg.reach * (_norm(knee - hip) + _norm(ankle - knee))
            bounded = bounded_correction(ankle, hip, c, reach)
            limited = limited or _norm(bounded - c) > 1e-12
            c = bounded
            self._correction[leg] = c
            self.last_correction[leg] = _norm(c)
            self.limited_frames += int(limited)
            if limited and held:
                unreached.append(wanted - c)
            if self.last_correction[leg] < 1e-6:
                continue
            if G is None:
                G = pose.global_rotations()
            target = ankle + np.array([c[0], c[1], 0.0])
            new_knee, new_ankle = two_bone_ik(hip, knee, ankle, target, G[h][:, 1])
            Q1 = _rotation_between(knee - hip, new_knee - hip)
            R_hip = Q1 @ G[h]
            Q2 = _rotation_between(Q1 @ (ankle - knee), new_ankle - new_knee)
            R_knee = Q2 @ Q1 @ G[k]
            changed[h] = G[PARENTS[h]].T @ R_hip
            changed[k] = R_hip.T @ R_knee
            changed[a] = R_knee.T @ G[a]                    # the foot keeps its orientation
        root = pose.root_position
        if follow and unreached:
            # the whole body moves by what the standing legs could not take up, so their feet
            # stay; the stored standing points move with it (they are where the feet are)
            shift = np.mean(unreached, axis=0)
            self.root_offset = self.root_offset + shift
            root = root + np.array([shift[0], shift[1], 0.0])
            for leg in LEGS:
                self._standing[leg] = {n: p + shift for n, p in self._standing[leg].items()}
        if not changed:
            return pose if root is pose.root_position else Pose(pose.skeleton, pose.rotations,
                                                                root)
        rot = np.array(pose.rotations)
        joints = list(changed)
        rot[joints] = matrix_to_quat(np.stack([changed[j] for j in joints]))
        return Pose(pose.skeleton, rot, root)
