"""The single skeleton definition of the pipeline (docs/design.md §2, §3).

Everything that names a joint or a keypoint imports it from here:

* the fixed **23-point 2D keypoint layout** (COCO-WholeBody body + feet) and the maps from
  detector layouts (OpenPose BODY_25, MediaPipe BlazePose 33) onto it;
* the fixed **3D joint names**, their parents (a tree in topological order, root = pelvis),
  the **bone groups** (one length per symmetric pair, so a skeleton built from group lengths
  is left/right symmetric by construction), and the left/right mirror permutations;
* the **rest pose**: a T-pose whose local rotations are all identity. Each bone points along a
  fixed unit direction in the body frame; the skeleton of a person is the rest pose scaled by
  their bone lengths;
* the foot **contact points** (heel and toe, left and right), as points in joint frames.

Frames and units. The body (rest) frame is x forward, y left, z up (REP-103 body frame),
metres. Local rotations of a pose are expressed relative to this rest pose: joint ``j``'s
rotation maps its frame to its parent's frame, and with all rotations identity FK gives the
T-pose below (arms along +-y, legs along -z, feet flat, the toes forward).

This module has no ROS imports and depends on NumPy only.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Dict, Mapping, Optional, Sequence, Tuple

import numpy as np

# ---------------------------------------------------------------------------------------------
# 2D keypoint layout (docs/design.md §2): COCO-WholeBody body + feet, 23 points.
# ---------------------------------------------------------------------------------------------
KEYPOINT_NAMES: Tuple[str, ...] = (
    'nose', 'left_eye', 'right_eye', 'left_ear', 'right_ear',
    'left_shoulder', 'right_shoulder', 'left_elbow', 'right_elbow',
    'left_wrist', 'right_wrist', 'left_hip', 'right_hip',
    'left_knee', 'right_knee', 'left_ankle', 'right_ankle',
    'left_big_toe', 'left_small_toe', 'left_heel',
    'right_big_toe', 'right_small_toe', 'right_heel',
)
NUM_KEYPOINTS = len(KEYPOINT_NAMES)
KEYPOINT_INDEX: Dict[str, int] = {n: i for i, n in enumerate(KEYPOINT_NAMES)}

#: Lines drawn between keypoints in overlays (pairs of keypoint indices).
KEYPOINT_EDGES: Tuple[Tuple[int, int], ...] = tuple(
    (KEYPOINT_INDEX[a], KEYPOINT_INDEX[b]) for a, b in (
        ('left_ear', 'left_eye'), ('left_eye', 'nose'), ('nose', 'right_eye'),
        ('right_eye', 'right_ear'),
        ('left_shoulder', 'right_shoulder'), ('left_shoulder', 'left_elbow'),
        ('left_elbow', 'left_wrist'), ('right_shoulder', 'right_elbow'),
        ('right_elbow', 'right_wrist'), ('left_shoulder', 'left_hip'),
        ('right_shoulder', 'right_hip'), ('left_hip', 'right_hip'),
        ('left_hip', 'left_knee'), ('left_knee', 'left_ankle'),
        ('right_hip', 'right_knee'), ('right_knee', 'right_ankle'),
        ('left_ankle', 'left_heel'), ('left_ankle', 'left_big_toe'),
        ('left_big_toe', 'left_small_toe'), ('right_ankle', 'right_heel'),
        ('right_ankle', 'right_big_toe'), ('right_big_toe', 'right_small_toe'),
    ))


def _mirror_permutation(names: Sequence[str]) -> Tuple[int, ...]:
    """Index permutation that swaps every ``left_*`` name with its ``right_*`` twin."""
    index = {n: i for i, n in enumerate(names)}

    def twin(n: str) -> str:
        if n.startswith('left_'):
            return 'right_' + n[5:]
        if n.startswith('right_'):
            return 'left_' + n[6:]
        return n

    return tuple(index[twin(n)] for n in names)


#: ``keypoints[..., KEYPOINT_MIRROR, :]`` swaps left and right (for flip augmentation; the
#: u coordinate must be mirrored separately).
KEYPOINT_MIRROR: Tuple[int, ...] = _mirror_permutation(KEYPOINT_NAMES)

#: OpenPose BODY_25 index for each layout keypoint (BODY_25 order: 0 Nose, 1 Neck,
#: 2 RShoulder, 3 RElbow, 4 RWrist, 5 LShoulder, 6 LElbow, 7 LWrist, 8 MidHip, 9 RHip,
#: 10 RKnee, 11 RAnkle, 12 LHip, 13 LKnee, 14 LAnkle, 15 REye, 16 LEye, 17 REar, 18 LEar,
#: 19 LBigToe, 20 LSmallToe, 21 LHeel, 22 RBigToe, 23 RSmallToe, 24 RHeel).
BODY25_TO_LAYOUT: Tuple[int, ...] = (
    0, 16, 15, 18, 17, 5, 2, 6, 3, 7, 4, 12, 9, 13, 10, 14, 11, 19, 20, 21, 22, 23, 24)

#: MediaPipe BlazePose (33 landmarks) index for each layout keypoint; -1 = not provided
#: (BlazePose has no small toe; its "foot index" landmark is used as the big toe).
BLAZEPOSE_TO_LAYOUT: Tuple[int, ...] = (
    0, 2, 5, 7, 8, 11, 12, 13, 14, 15, 16, 23, 24, 25, 26, 27, 28, 31, -1, 29, 32, -1, 30)

# ---------------------------------------------------------------------------------------------
# 3D skeleton (docs/design.md §2): fixed joint names, root = pelvis.
# ---------------------------------------------------------------------------------------------
JOINT_NAMES: Tuple[str, ...] = (
    'pelvis',
    'left_hip', 'left_knee', 'left_ankle', 'left_toe',
    'right_hip', 'right_knee', 'right_ankle', 'right_toe',
    'spine', 'neck', 'head',
    'left_shoulder', 'left_elbow', 'left_wrist',
    'right_shoulder', 'right_elbow', 'right_wrist',
)
NUM_JOINTS = len(JOINT_NAMES)
JOINT_INDEX: Dict[str, int] = {n: i for i, n in enumerate(JOINT_NAMES)}

_PARENT_NAMES: Dict[str, Optional[str]] = {
    'pelvis': None,
    'left_hip': 'pelvis', 'left_knee': 'left_hip', 'left_ankle': 'left_knee',
    'left_toe': 'left_ankle',
    'right_hip': 'pelvis', 'right_knee': 'right_hip', 'right_ankle': 'right_knee',
    'right_toe': 'right_ankle',
    'spine': 'pelvis', 'neck': 'spine', 'head': 'neck',
    'left_shoulder': 'neck', 'left_elbow': 'left_shoulder', 'left_wrist': 'left_elbow',
    'right_shoulder': 'neck', 'right_elbow': 'right_shoulder', 'right_wrist': 'right_elbow',
}
#: Parent index of each joint (-1 for the root); parents[j] < j (topological order, each limb
#: finished before the next: the order Pinocchio needs when building a model in code).
PARENTS: Tuple[int, ...] = tuple(
    -1 if _PARENT_NAMES[n] is None else JOINT_INDEX[_PARENT_NAMES[n]] for n in JOINT_NAMES)

#: ``rotations[..., JOINT_MIRROR, :]`` swaps left and right joints.
JOINT_MIRROR: Tuple[int, ...] = _mirror_permutation(JOINT_NAMES)

#: End effectors (weighted more in position losses, MotioNet eq. 7).
END_EFFECTORS: Tuple[int, ...] = tuple(
    JOINT_INDEX[n] for n in ('left_toe', 'right_toe', 'head', 'left_wrist', 'right_wrist'))

# Bones are named by their child joint: bone j goes from PARENTS[j] to j. A bone group is one
# length shared by a symmetric pair (or a single central bone). MotioNet's E_S predicts one
# value per group (symmetry by construction).
BONE_GROUPS: Tuple[Tuple[str, Tuple[str, ...]], ...] = (
    ('hip', ('left_hip', 'right_hip')),               # pelvis centre -> hip joint
    ('thigh', ('left_knee', 'right_knee')),
    ('shin', ('left_ankle', 'right_ankle')),
    ('foot', ('left_toe', 'right_toe')),              # ankle -> toe (ball of the foot)
    ('spine', ('spine',)),                            # pelvis -> chest
    ('neck', ('neck',)),                              # chest -> base of the neck (shoulder level)
    ('head', ('head',)),                              # base of the neck -> head centre (ears)
    ('clavicle', ('left_shoulder', 'right_shoulder')),
    ('upper_arm', ('left_elbow', 'right_elbow')),
    ('forearm', ('left_wrist', 'right_wrist')),
)
BONE_GROUP_NAMES: Tuple[str, ...] = tuple(g for g, _ in BONE_GROUPS)
NUM_BONE_GROUPS = len(BONE_GROUPS)
#: Bone group index of each joint's incoming bone (-1 for the root).
JOINT_BONE_GROUP: Tuple[int, ...] = tuple(
    next((gi for gi, (_, js) in enumerate(BONE_GROUPS) if n in js), -1) for n in JOINT_NAMES)

_SIN30 = 0.5
_COS30 = float(np.sqrt(3.0) / 2.0)
_REST_DIRECTION_BY_NAME: Dict[str, Tuple[float, float, float]] = {
    'pelvis': (0.0, 0.0, 0.0),
    'left_hip': (0.0, 1.0, 0.0), 'right_hip': (0.0, -1.0, 0.0),
    'left_knee': (0.0, 0.0, -1.0), 'right_knee': (0.0, 0.0, -1.0),
    'left_ankle': (0.0, 0.0, -1.0), 'right_ankle': (0.0, 0.0, -1.0),
    # The foot bone runs forward and down at 30 degrees so that heel and toe touch the floor.
    'left_toe': (_COS30, 0.0, -_SIN30), 'right_toe': (_COS30, 0.0, -_SIN30),
    'spine': (0.0, 0.0, 1.0), 'neck': (0.0, 0.0, 1.0), 'head': (0.0, 0.0, 1.0),
    'left_shoulder': (0.0, 1.0, 0.0), 'right_shoulder': (0.0, -1.0, 0.0),
    'left_elbow': (0.0, 1.0, 0.0), 'right_elbow': (0.0, -1.0, 0.0),
    'left_wrist': (0.0, 1.0, 0.0), 'right_wrist': (0.0, -1.0, 0.0),
}
#: (J, 3) unit direction of each joint's incoming bone in the rest pose (body frame); zero for
#: the root.
REST_DIRECTIONS: np.ndarray = np.array(
    [_REST_DIRECTION_BY_NAME[n] for n in JOINT_NAMES], dtype=np.float64)
REST_DIRECTIONS.setflags(write=False)

#: Default bone-group lengths in metres: an adult of about 1.75 m (pelvis 0.93 m above the
#: floor in the rest pose).
DEFAULT_BONE_GROUP_LENGTHS: Dict[str, float] = {
    'hip': 0.10, 'thigh': 0.43, 'shin': 0.42, 'foot': 0.15,
    'spine': 0.26, 'neck': 0.26, 'head': 0.18,
    'clavicle': 0.18, 'upper_arm': 0.29, 'forearm': 0.26,
}

#: Contact points: name -> (joint whose frame holds the point, position of the point in that
#: frame in units of the foot bone length). The toe point is the toe joint itself; the heel
#: lies behind the ankle at the height of the toe, so in the rest pose both touch the floor.
CONTACT_POINT_NAMES: Tuple[str, ...] = ('left_heel', 'left_toe', 'right_heel', 'right_toe')
#: ``contacts[..., CONTACT_MIRROR]`` swaps the left and right contact points.
CONTACT_MIRROR: Tuple[int, ...] = _mirror_permutation(CONTACT_POINT_NAMES)
_CONTACT_POINTS_FOOT_UNITS: Dict[str, Tuple[str, Tuple[float, float, float]]] = {
    'left_heel': ('left_ankle', (-0.25, 0.0, -_SIN30)),
    'left_toe': ('left_toe', (0.0, 0.0, 0.0)),
    'right_heel': ('right_ankle', (-0.25, 0.0, -_SIN30)),
    'right_toe': ('right_toe', (0.0, 0.0, 0.0)),
}

#: 3D joint -> 2D layout keypoints whose mean is the joint's image (used to project motion
#: capture to synthetic 2D input and to compare 2D and 3D). Joints with no 2D counterpart
#: (``spine``) map to an empty tuple.
JOINT_TO_KEYPOINTS: Dict[str, Tuple[int, ...]] = {
    'pelvis': (KEYPOINT_INDEX['left_hip'], KEYPOINT_INDEX['right_hip']),
    'left_hip': (KEYPOINT_INDEX['left_hip'],), 'right_hip': (KEYPOINT_INDEX['right_hip'],),
    'left_knee': (KEYPOINT_INDEX['left_knee'],), 'right_knee': (KEYPOINT_INDEX['right_knee'],),
    'left_ankle': (KEYPOINT_INDEX['left_ankle'],),
    'right_ankle': (KEYPOINT_INDEX['right_ankle'],),
    'left_toe': (KEYPOINT_INDEX['left_big_toe'],),
    'right_toe': (KEYPOINT_INDEX['right_big_toe'],),
    'spine': (),
    'neck': (KEYPOINT_INDEX['left_shoulder'], KEYPOINT_INDEX['right_shoulder']),
    'head': (KEYPOINT_INDEX['left_ear'], KEYPOINT_INDEX['right_ear']),
    'left_shoulder': (KEYPOINT_INDEX['left_shoulder'],),
    'right_shoulder': (KEYPOINT_INDEX['right_shoulder'],),
    'left_elbow': (KEYPOINT_INDEX['left_elbow'],), 'right_elbow': (KEYPOINT_INDEX['right_elbow'],),
    'left_wrist': (KEYPOINT_INDEX['left_wrist'],), 'right_wrist': (KEYPOINT_INDEX['right_wrist'],),
}


def group_lengths_to_bone_lengths(group_lengths: np.ndarray) -> np.ndarray:
    """Expand bone-group lengths to per-joint bone lengths.

    Args:
        group_lengths: (..., G) lengths in metres, in the order of :data:`BONE_GROUP_NAMES`.
    Returns:
        (..., J) length of each joint's incoming bone (0 for the root).
    """
    group_lengths = np.asarray(group_lengths, dtype=np.float64)
    if group_lengths.shape[-1] != NUM_BONE_GROUPS:
        raise ValueError(
            f'expected {NUM_BONE_GROUPS} bone-group lengths, got shape {group_lengths.shape}')
    index = np.array([max(g, 0) for g in JOINT_BONE_GROUP])
    out = group_lengths[..., index]
    out[..., 0] = 0.0
    return out


def bone_lengths_to_group_lengths(bone_lengths: np.ndarray) -> np.ndarray:
    """Average per-joint bone lengths (..., J) over each symmetric group -> (..., G)."""
    bone_lengths = np.asarray(bone_lengths, dtype=np.float64)
    if bone_lengths.shape[-1] != NUM_JOINTS:
        raise ValueError(f'expected {NUM_JOINTS} bone lengths, got shape {bone_lengths.shape}')
    return np.stack(
        [bone_lengths[..., [JOINT_INDEX[j] for j in js]].mean(axis=-1) for _, js in BONE_GROUPS],
        axis=-1)


#: ``stature = STATURE_SLOPE * Skeleton.height() + STATURE_OFFSET`` (m): fitted by
#: ``mocap data fit-stature`` on 320 rendered training bodies (:meth:`Skeleton.stature`).
STATURE_SLOPE = 0.9719
STATURE_OFFSET = 0.2144


@dataclass(frozen=True, eq=False)
class Skeleton:
    """A person's skeleton: the fixed joint tree with per-bone rest offsets.

    Attributes:
        offsets: (J, 3) float64, metres. Rest-pose translation of each joint from its parent,
            in the parent's frame (body frame at rest: x forward, y left, z up). Row 0 (root)
            is zero.
        joint_names: joint names, default :data:`JOINT_NAMES`.
        parents: parent indices, default :data:`PARENTS`.
    """

    offsets: np.ndarray
    joint_names: Tuple[str, ...] = JOINT_NAMES
    parents: Tuple[int, ...] = PARENTS

    def __post_init__(self) -> None:
        offsets = np.array(self.offsets, dtype=np.float64)
        if offsets.shape != (len(self.joint_names), 3):
            raise ValueError(
                f'offsets must have shape ({len(self.joint_names)}, 3), got {offsets.shape}')
        if not np.all(np.isfinite(offsets)):
            raise ValueError('skeleton offsets contain NaN or inf')
        offsets[0] = 0.0
        offsets.setflags(write=False)
        object.__setattr__(self, 'offsets', offsets)

    # -- construction ------------------------------------------------------------------------
    @classmethod
    def from_group_lengths(cls, group_lengths: Sequence[float] | np.ndarray) -> 'Skeleton':
        """Symmetric skeleton from one length per bone group (:data:`BONE_GROUP_NAMES`), m."""
        lengths = group_lengths_to_bone_lengths(np.asarray(group_lengths, dtype=np.float64))
        if np.any(lengths[1:] <= 0):
            raise ValueError('bone lengths must be positive')
        return cls(offsets=REST_DIRECTIONS * lengths[:, None])

    @classmethod
    def from_lengths_dict(cls, lengths: Mapping[str, float]) -> 'Skeleton':
        """Symmetric skeleton from ``{group name: length}``; missing groups take defaults."""
        unknown = set(lengths) - set(BONE_GROUP_NAMES)
        if unknown:
            raise ValueError(f'unknown bone groups: {sorted(unknown)}; known: {BONE_GROUP_NAMES}')
        merged = {**DEFAULT_BONE_GROUP_LENGTHS, **lengths}
        return cls.from_group_lengths([merged[g] for g in BONE_GROUP_NAMES])

    @classmethod
    def default(cls) -> 'Skeleton':
        """The default adult skeleton (:data:`DEFAULT_BONE_GROUP_LENGTHS`)."""
        return cls.from_lengths_dict({})

    # -- derived quantities ------------------------------------------------------------------
    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    def bone_lengths(self) -> np.ndarray:
        """(J,) length of each joint's incoming bone, metres (0 for the root)."""
        return np.linalg.norm(self.offsets, axis=-1)

    def group_lengths(self) -> np.ndarray:
        """(G,) bone-group lengths (mean over each symmetric pair), metres."""
        return bone_lengths_to_group_lengths(self.bone_lengths())

    def foot_length(self) -> float:
        """Mean ankle-to-toe length, metres."""
        bl = self.bone_lengths()
        return float(0.5 * (bl[JOINT_INDEX['left_toe']] + bl[JOINT_INDEX['right_toe']]))

    def rest_positions(self) -> np.ndarray:
        """(J, 3) joint positions of the rest pose with the root at the origin (body frame)."""
        pos = np.zeros((self.num_joints, 3))
        for j in range(1, self.num_joints):
            pos[j] = pos[self.parents[j]] + self.offsets[j]
        return pos

    def rest_root_height(self) -> float:
        """Height of the root above the lowest contact point in the rest pose, metres."""
        pos = self.rest_positions()
        lowest = min(pos[j, 2] + off[2] for j, off in self.contact_points().values())
        return float(-lowest)

    def contact_points(self) -> Dict[str, Tuple[int, np.ndarray]]:
        """Foot contact points: name -> (joint index, (3,) position in that joint's frame, m).

        The heel point is scaled by this skeleton's foot length, so it follows the person's
        size; the toe point is the toe joint itself.
        """
        foot = self.foot_length()
        return {name: (JOINT_INDEX[joint], foot * np.asarray(p, dtype=np.float64))
                for name, (joint, p) in _CONTACT_POINTS_FOOT_UNITS.items()}

    def is_symmetric(self, atol: float = 1e-9) -> bool:
        """True when mirrored joints have mirrored offsets (y negated)."""
        mirrored = self.offsets[list(JOINT_MIRROR)] * np.array([1.0, -1.0, 1.0])
        return bool(np.allclose(mirrored, self.offsets, atol=atol))

    def height(self) -> float:
        """Approximate standing height (floor to top of the head), metres: the rest pose plus
        a head-top allowance of 0.55 times the neck-to-head bone."""
        pos = self.rest_positions()
        head_bone = self.bone_lengths()[JOINT_INDEX['head']]
        return float(pos[JOINT_INDEX['head'], 2] + 0.55 * head_bone + self.rest_root_height())

    def stature(self) -> float:
        """The person's stature (floor to the top of the head, as a tape measure gives it),
        metres, from :meth:`height`: ``STATURE_SLOPE * height() + STATURE_OFFSET``.

        :meth:`height` reads about 10 % short of a real stature (its head-top allowance is
        small and the soles sit below the contact points); the affine map was fitted on the
        rigs of 320 rendered training bodies of known mesh height (``scripts/fit_stature.py``)
        and is within 0.9 cm (median; 1.9 cm at the 95th percentile) on the 60 validation bodies,
        0.6 cm (2.2 cm) on the 40 of the travel set.
        """
        return float(STATURE_SLOPE * self.height() + STATURE_OFFSET)

    def size_for_stature(self, stature: float) -> float:
        """The factor :meth:`scaled` needs for a skeleton of this ``stature`` (m, > 0)."""
        if not np.isfinite(stature) or stature <= STATURE_OFFSET:
            raise ValueError(f'stature must be finite and > {STATURE_OFFSET} m, got {stature}')
        return float((stature - STATURE_OFFSET) / (STATURE_SLOPE * self.height()))

    def scaled(self, factor: float) -> 'Skeleton':
        """This skeleton with every bone ``factor`` times as long (same joint directions)."""
        if not np.isfinite(factor) or factor <= 0:
            raise ValueError(f'scale factor must be finite and > 0, got {factor}')
        return replace(self, offsets=self.offsets * float(factor))


def keypoint_index(name: str) -> int:
    """Index of a 2D keypoint name; raises KeyError naming the valid names."""
    try:
        return KEYPOINT_INDEX[name]
    except KeyError:
        raise KeyError(f'unknown keypoint {name!r}; known: {", ".join(KEYPOINT_NAMES)}') from None


def joint_index(name: str) -> int:
    """Index of a 3D joint name; raises KeyError naming the valid names."""
    try:
        return JOINT_INDEX[name]
    except KeyError:
        raise KeyError(f'unknown joint {name!r}; known: {", ".join(JOINT_NAMES)}') from None
