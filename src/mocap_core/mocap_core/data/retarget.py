"""Retargeting BVH motion capture to the pipeline skeleton (no ROS imports).

Every clip, whatever its source format, becomes a root position plus local joint rotations of
the fixed 18-joint skeleton of :mod:`mocap_core.skeleton`, *relative to that skeleton's own
rest pose* (the T-pose of ``REST_DIRECTIONS``), with per-clip bone lengths in metres. The same
physical pose therefore gives the same rotations whichever dataset it came from.

Source formats (:data:`FORMATS`, detected from the joint names by :func:`detect_format`)
-------------------------------------------------------------------------------------------
=================  ============================  ==========  ======================================
format             joints (example names)        unit        notes
=================  ============================  ==========  ======================================
``cmu_mb2``        31, Hips LeftUpLeg Spine1 ...  CMU ASF     cgspeed MotionBuilder-friendly;
                                                  unit        rest = T-pose, frames = world axes
``cmu_asf``        31, hip lfemur thorax ...      CMU ASF     ASF bone names (same skeleton as mb2)
``cmu_daz``        43, hip lThigh chest ...       cm          cgspeed DAZ-friendly; no toe joint
``bandai_namco``   22, Hips UpperLeg_L Chest ...  cm          bones along local X; rest = stick
=================  ============================  ==========  ======================================

The CMU ASF unit is (1/0.45) inch = 0.05644 m (:data:`~mocap_core.data.bvh.CMU_ASF_UNIT`). The
units come from the dataset READMEs and are checked per file: the mean thigh length must be
0.25-0.65 m, otherwise the unit guessed from the skeleton size
(:func:`~mocap_core.data.bvh.guess_unit_scale`) is tried, and the clip is refused if neither
fits (:func:`resolve_unit_scale`).

Joint map (pipeline joint <- source point; ``a+b`` = midpoint, ``x@end`` = end site of ``x``)

================  ===============  ===============  ================  ======================
pipeline          cmu_mb2          cmu_asf          cmu_daz           bandai_namco
================  ===============  ===============  ================  ======================
pelvis            LeftUpLeg+       lfemur+rfemur    lThigh+rThigh     UpperLeg_L+UpperLeg_R
                  RightUpLeg
left_hip          LeftUpLeg        lfemur           lThigh            UpperLeg_L
left_knee         LeftLeg          ltibia           lShin             LowerLeg_L
left_ankle        LeftFoot         lfoot            lFoot             Foot_L
left_toe          LeftToeBase      ltoes            lFoot@end         Toes_L
spine             Spine            upperback        abdomen           Spine
neck              LeftArm+         lhumerus+        lShldr+rShldr     UpperArm_L+UpperArm_R
                  RightArm         rhumerus
head              Head             head             head              Head
left_shoulder     LeftArm          lhumerus         lShldr            UpperArm_L
left_elbow        LeftForeArm      lradius          lForeArm          LowerArm_L
left_wrist        LeftHand         lwrist           lHand             Hand_L
================  ===============  ===============  ================  ======================

(right side likewise). Choices:

* the pelvis is the midpoint of the hip joints and the neck the midpoint of the shoulder
  (upper-arm) joints, so the pelvis->hip and neck->shoulder offsets are symmetric and lateral
  as the pipeline skeleton requires;
* ``spine`` is the source's first spine joint above the pelvis (0.18-0.23 m above the hip
  centre). The pipeline skeleton has no lumbar joint: its spine point is rigid with the pelvis,
  so it must be a source point (nearly) rigid with the source pelvis. DAZ ``abdomen`` and
  Bandai ``Spine`` are children of the root, hence exact; CMU ``Spine`` hangs from
  ``LowerBack``, whose pivot is the root, so CMU lateral lumbar bends leave an error there.
  (The chest joints -- Spine1 / thorax / chest / Chest -- were the first choice; they sit
  0.30-0.34 m up, and a lateral bend then cost 3-5x more, cascading into the arms.)
* ``head`` is the source head joint (top of the neck / skull base, near ear level);
* ``toe`` is the ball of the foot (the source toe joint, or DAZ's foot end site, 0.12-0.13 m
  from the ankle).

Rotations
---------
Global orientations ``G_j`` of the pipeline joints are built frame by frame in tree order, each
bone aimed *from the FK position of its parent joint* (not from the source joint), so a length
mismatch is not carried down the chain:

* ``pelvis``: y = hip axis (left hip - right hip), z = direction pelvis -> spine point made
  orthogonal to y, x = y x z (forward). The hips are reproduced exactly (legs exact).
* ``neck``: likewise from the shoulder axis and the head point (the shoulders exact).
* one-child joints (hips, knees, ankles, spine, shoulders, elbows): *swing* + *twist*. The
  twist about the bone comes from the source's global orientation of the segment mapped to the
  pipeline convention, ``G_ref = R_src @ C`` (``C`` below); then the minimal rotation that
  turns ``G_ref @ rest_direction(child)`` onto the observed direction (FK parent position ->
  source child point) is applied on the left: ``G_j = swing @ G_ref``. So the bone points
  exactly at the source child and the twist (thigh, shin, upper arm, forearm, upper trunk
  (from the source chest joint)) is the source's. The resulting knee and elbow rotations are
  hinges about y and z in every format (tested).
* ankles: the foot roll is not taken from the source (the CMU foot frames are rolled about 20
  deg in a flat stance, an artefact of the splayed-leg ASF rest pose) but from the
  knee-ankle-toe plane: the ankle's y axis is the plane normal (a hinge-like ankle, so a flat
  foot under a vertical shin has its heel contact point on the floor), blended smoothly back to
  the source twist where shin and foot are nearly parallel (|sin| < 0.5).
* toes (leaves): a hinge toe, x along the source toe segment's forward axis, y = the ankle's
  lateral axis; flat toes in a flat-foot stance give identity.
* wrists (leaves): the hand keeps its source rotation relative to the source forearm frame
  (``G = G_elbow @ G_ref,elbow^T @ G_ref,hand``), so a forearm whose source rest direction
  differs from the pipeline's (DAZ: 17 deg forward) does not show up as a bent wrist.
* head (leaf): ``G = G_ref`` (the source head orientation).

Local rotations are then ``L_j = G_parent^T G_j``
(:func:`~mocap_core.kinematics.local_from_global_rotations`), as quaternions (x, y, z, w) made
continuous in time (no sign flips between frames).

The constant ``C`` of each source joint says where the pipeline's rest axes (x forward, y left,
z up, i.e. the joint frame in the T-pose with the feet flat, the knee hinges lateral and the
elbow hinges vertical) lie in that source joint's frame (in the pipeline's axis labels, see
:data:`~mocap_core.data.bvh.BVH_TO_WORLD`):

* CMU (all three conversions): the zero-rotation pose is a T-pose whose joint frames are the
  world axes, so ``C = I`` (the source rest differs from the pipeline's in the bone directions
  only, e.g. CMU thighs are splayed 20 deg: the swing accounts for that) -- except the arms:
  in every CMU conversion the elbow hinge is 30 deg off the vertical of the upper-arm and
  forearm frames, so their ``C`` (and the hand's) is a 30 deg twist about the arm axis
  (:data:`CMU_ARM_TWIST_DEG`, measured over all CMU clips).
* Bandai Namco: the bones run along each joint's local X and the all-zero pose is a stick, so
  ``C`` is the signed axis permutation of each joint, read off standing frames (left leg:
  forward = +x, left = +z, up = -y in pipeline labels; see :func:`_bandai`) and checked by the
  tests (knee and elbow hinges, walking knee flexion and arm carriage consistent with CMU).

Residual differences between formats come from where each skeleton places its joints, not from
the method: e.g. CMU puts the lumbar spine 5 cm behind the hip centre (in walking trial 02_01
its pelvis frame leans back 10 deg on average in the mb2 conversion, 3.6 deg in the DAZ one;
Bandai walks: -1 to +1 deg), and the DAZ
conversion of a CMU trial has knees and elbows 10-20 deg more bent than the mb2 conversion of
the same trial (its rest pose has bent limbs), which the positions, and so the rotations,
faithfully show.

FK error
--------
Bone lengths are per-clip constants (mean over frames, symmetric pairs averaged), so the FK of
the retargeted motion does not reproduce non-rigid or asymmetric source bones exactly:
:meth:`RetargetedClip.fk_error_mm` reports it. Measured over all the motion capture in
``../shared/data`` with :func:`retarget_report` (2847 clips, 456,002 frames, 31 s on 2 cores),
mean (frame-weighted) / worst clip mean / max over all frames and joints, mm:

=============  =====  ======  ===========  =============  ===================================
format         clips  frames  mean         worst clip     max
=============  =====  ======  ===========  =============  ===================================
bandai_namco   2762   357791  0.84         3.5            47 (dance-short_normal_001)
cmu_daz        80     93443   0.54         1.2            48 (14_08)
cmu_asf        2      788     2.8          2.9            16
cmu_mb2        3      3980    5.7          10.3 (05_06)   114 (05_06, modern dance)
=============  =====  ======  ===========  =============  ===================================

Where it comes from: DAZ and Bandai legs, pelvis and spine are exact; their residue is the
clavicles moving the shoulders (the neck is their midpoint, the clavicle length a per-clip mean)
and the head off the neck's axis. The CMU mb2/ASF skeletons are left/right asymmetric (02_01:
thighs and upper arms 15 mm apart, so a symmetric skeleton is ~7.5 mm off at the knees and
elbows), and their lumbar pivot is the root, above the pipeline pelvis, so lateral lumbar bends
(05_06 bends up to 80 deg) cost up to 10 cm at the spine and head.
"""

from __future__ import annotations

import os
import time
import warnings
from dataclasses import dataclass, field
from typing import Dict, List, Mapping, NamedTuple, Optional, Sequence, Tuple, Union

import numpy as np

from ..kinematics import forward_kinematics, local_from_global_rotations
from ..pose import Pose
from ..rotations import matrix_to_quat, quat_from_two_vectors, quat_to_matrix
from ..skeleton import (BONE_GROUPS, JOINT_INDEX, JOINT_NAMES, NUM_JOINTS, PARENTS,
                        REST_DIRECTIONS, Skeleton, bone_lengths_to_group_lengths)
from .bvh import BVH, CMU_ASF_UNIT, bvh_fk, guess_unit_scale, iter_bvh_sources, list_bvh_sources

__all__ = [
    'SourceFormat', 'FORMATS', 'detect_format', 'get_format', 'resolve_unit_scale',
    'RetargetedClip', 'FKError', 'retarget', 'retarget_report',
]

_AXIS = {'x': 0, 'y': 1, 'z': 2}


def _axes_matrix(fwd: str, left: str, up: str) -> np.ndarray:
    """Matrix whose columns are the pipeline axes (forward, left, up) written in a source
    joint's frame, each given as a signed axis such as ``'+x'`` or ``'-z'``."""
    C = np.zeros((3, 3))
    for col, a in enumerate((fwd, left, up)):
        C[_AXIS[a[1]], col] = 1.0 if a[0] == '+' else -1.0
    if not np.isclose(np.linalg.det(C), 1.0):
        raise ValueError(f'axes {fwd} {left} {up} do not form a right-handed frame')
    return C


_I = _axes_matrix('+x', '+y', '+z')

#: Twist (deg, about the arm axis) between the CMU upper-arm / forearm / hand frames and the
#: pipeline's T-pose convention (elbow hinge vertical): in every CMU conversion the elbow
#: hinge lies 30 deg off the segment frame's vertical axis (an ASF skeleton constant; measured
#: over all CMU clips here: ASF-named -30.0 +- 0.1, mb2 -30.0 +- 2, DAZ -28.5 +- 1.5 deg;
#: Bandai Namco, for comparison, 0 +- 15).
#: The same value for both arms (a rotation about the lateral axis is its own mirror image).
CMU_ARM_TWIST_DEG = -30.0


def _twist_y(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


@dataclass(frozen=True, eq=False)
class SourceFormat:
    """How one BVH conversion maps onto the pipeline skeleton.

    Attributes:
        name: format id.
        description: one line for reports.
        unit_scale: documented metres per file unit.
        points: pipeline joint -> source points whose mean is that joint (``'x@end'`` is the
            first end site of joint ``x``).
        orientations: pipeline joint -> (source joint, C): the source joint whose global
            orientation gives the twist / leaf orientation, and the (3, 3) rotation ``C``
            whose columns are the pipeline's rest axes (forward, left, up) in that joint's
            frame (pipeline axis labels). Joints not listed (pelvis, neck) are fully
            determined by positions.
    """

    name: str
    description: str
    unit_scale: float
    points: Mapping[str, Tuple[str, ...]]
    orientations: Mapping[str, Tuple[str, np.ndarray]]

    def source_joint_names(self) -> List[str]:
        names = [p.split('@')[0] for pts in self.points.values() for p in pts]
        names += [o[0] for o in self.orientations.values()]
        return sorted(set(names))

    def orientation_offset(self, joint: str) -> np.ndarray:
        return np.asarray(self.orientations[joint][1], dtype=np.float64)


def _cmu_like(name: str, description: str, unit: float, j: Dict[str, str],
              right: Dict[str, str]) -> SourceFormat:
    """Format whose zero pose is a T-pose with world-aligned joint frames (``C = I``, but
    for the arms' :data:`CMU_ARM_TWIST_DEG`)."""
    pts = {
        'pelvis': (j['hip'], right['hip']),
        'left_hip': (j['hip'],), 'left_knee': (j['knee'],), 'left_ankle': (j['ankle'],),
        'left_toe': (j['toe'],), 'spine': (j['spine'],),
        'neck': (j['shoulder'], right['shoulder']), 'head': (j['head'],),
        'left_shoulder': (j['shoulder'],), 'left_elbow': (j['elbow'],),
        'left_wrist': (j['wrist'],),
    }
    for k in ('hip', 'knee', 'ankle', 'toe', 'shoulder', 'elbow', 'wrist'):
        pts['right_' + k] = (right[k],)
    ori = {}
    arm = _twist_y(CMU_ARM_TWIST_DEG)
    for k in ('hip', 'knee', 'ankle', 'toe', 'shoulder', 'elbow', 'wrist'):
        C = arm if k in ('shoulder', 'elbow', 'wrist') else _I
        ori['left_' + k] = (j[k + '_rot'], C)
        ori['right_' + k] = (right[k + '_rot'], C)
    ori['spine'] = (j['chest'], _I)
    ori['head'] = (j['head'], _I)
    return SourceFormat(name, description, unit, pts, ori)


_MB2_LEFT = dict(hip='LeftUpLeg', knee='LeftLeg', ankle='LeftFoot', toe='LeftToeBase',
                 spine='Spine', chest='Spine1', head='Head', shoulder='LeftArm',
                 elbow='LeftForeArm', wrist='LeftHand',
                 hip_rot='LeftUpLeg', knee_rot='LeftLeg', ankle_rot='LeftFoot',
                 toe_rot='LeftToeBase', shoulder_rot='LeftArm', elbow_rot='LeftForeArm',
                 wrist_rot='LeftFingerBase')   # the hand segment (LeftHand holds the wrist twist)
_ASF_LEFT = dict(hip='lfemur', knee='ltibia', ankle='lfoot', toe='ltoes', spine='upperback',
                 chest='thorax',
                 head='head', shoulder='lhumerus', elbow='lradius', wrist='lwrist',
                 hip_rot='lfemur', knee_rot='ltibia', ankle_rot='lfoot', toe_rot='ltoes',
                 shoulder_rot='lhumerus', elbow_rot='lradius', wrist_rot='lhand')
_DAZ_LEFT = dict(hip='lThigh', knee='lShin', ankle='lFoot', toe='lFoot@end', spine='abdomen',
                 chest='chest',
                 head='head', shoulder='lShldr', elbow='lForeArm', wrist='lHand',
                 hip_rot='lThigh', knee_rot='lShin', ankle_rot='lFoot', toe_rot='lFoot',
                 shoulder_rot='lShldr', elbow_rot='lForeArm', wrist_rot='lHand')


def _mb2_right(d):
    return {k: v.replace('Left', 'Right') for k, v in d.items()}


def _asf_right(d):
    return {k: (('r' + v[1:]) if v.startswith('l') else v) for k, v in d.items()}


def _daz_right(d):
    return {k: (('r' + v[1:]) if v.startswith('l') else v) for k, v in d.items()}


def _bandai() -> SourceFormat:
    pts = {
        'pelvis': ('UpperLeg_L', 'UpperLeg_R'),
        'spine': ('Spine',), 'neck': ('UpperArm_L', 'UpperArm_R'), 'head': ('Head',),
    }
    names = dict(hip='UpperLeg', knee='LowerLeg', ankle='Foot', toe='Toes',
                 shoulder='UpperArm', elbow='LowerArm', wrist='Hand')
    for k, v in names.items():
        pts['left_' + k] = (v + '_L',)
        pts['right_' + k] = (v + '_R',)
    # Where forward/left/up of the pipeline T-pose lie in each Bandai joint frame (pipeline
    # labels: x = BVH Z, y = BVH X = the bone axis, z = BVH Y). Read off standing frames.
    leg_l, leg_r = _axes_matrix('+x', '+z', '-y'), _axes_matrix('-x', '+z', '+y')
    foot_l, foot_r = _axes_matrix('+y', '+z', '+x'), _axes_matrix('-y', '+z', '-x')
    arm_l, arm_r = _axes_matrix('+x', '+y', '+z'), _axes_matrix('-x', '+y', '-z')
    trunk = _axes_matrix('+z', '+x', '+y')
    ori = {'spine': ('Chest', trunk), 'head': ('Head', trunk)}
    for side, s, leg, foot, arm in (('left', 'L', leg_l, foot_l, arm_l),
                                    ('right', 'R', leg_r, foot_r, arm_r)):
        ori[f'{side}_hip'] = (f'UpperLeg_{s}', leg)
        ori[f'{side}_knee'] = (f'LowerLeg_{s}', leg)
        ori[f'{side}_ankle'] = (f'Foot_{s}', foot)
        ori[f'{side}_toe'] = (f'Toes_{s}', foot)
        ori[f'{side}_shoulder'] = (f'UpperArm_{s}', arm)
        ori[f'{side}_elbow'] = (f'LowerArm_{s}', arm)
        ori[f'{side}_wrist'] = (f'Hand_{s}', arm)
    return SourceFormat('bandai_namco', 'Bandai Namco Research Motion Dataset (22 joints, cm)',
                        0.01, pts, ori)


#: The known source formats, by name.
FORMATS: Dict[str, SourceFormat] = {f.name: f for f in (
    _cmu_like('cmu_mb2', 'CMU, cgspeed MotionBuilder-friendly BVH (31 joints, ASF units)',
              CMU_ASF_UNIT, _MB2_LEFT, _mb2_right(_MB2_LEFT)),
    _cmu_like('cmu_asf', 'CMU, BVH with ASF bone names (31 joints, ASF units)',
              CMU_ASF_UNIT, _ASF_LEFT, _asf_right(_ASF_LEFT)),
    _cmu_like('cmu_daz', 'CMU, cgspeed DAZ-friendly BVH (43 joints, cm)',
              0.01, _DAZ_LEFT, _daz_right(_DAZ_LEFT)),
    _bandai(),
)}


def get_format(fmt: Union[str, SourceFormat]) -> SourceFormat:
    if isinstance(fmt, SourceFormat):
        return fmt
    try:
        return FORMATS[fmt]
    except KeyError:
        raise KeyError(f'unknown BVH format {fmt!r}; known: {", ".join(FORMATS)}') from None


def detect_format(bvh: BVH) -> SourceFormat:
    """The known format whose joint names the file has (case-insensitive), or ValueError."""
    have = {n.lower() for n in bvh.joint_names}
    for spec in FORMATS.values():
        if all(n.lower() in have for n in spec.source_joint_names()):
            return spec
    raise ValueError(
        f'{bvh.name}: unknown BVH skeleton (joints: {", ".join(bvh.joint_names)}); '
        f'known formats: {", ".join(FORMATS)}')


# ---------------------------------------------------------------------------------------------
# source points
# ---------------------------------------------------------------------------------------------
def _point_sources(bvh: BVH, spec: SourceFormat) -> List[List[Tuple[str, int]]]:
    """Per pipeline joint, the list of ('joint'|'end', index) whose mean is its position."""
    out = []
    for name in JOINT_NAMES:
        refs = []
        for p in spec.points[name]:
            if p.endswith('@end'):
                j = bvh.joint_index(p[:-4])
                ends = [e for e, s in enumerate(bvh.end_sites) if s.parent == j]
                if not ends:
                    raise ValueError(f'{bvh.name}: joint {p[:-4]} has no end site')
                refs.append(('end', ends[0]))
            else:
                refs.append(('joint', bvh.joint_index(p)))
        out.append(refs)
    return out


def _mapped_positions(fk, refs) -> np.ndarray:
    P = np.empty(fk.positions.shape[:1] + (NUM_JOINTS, 3))
    for j, rr in enumerate(refs):
        acc = 0.0
        for kind, k in rr:
            acc = acc + (fk.positions[:, k] if kind == 'joint' else fk.end_site_positions[:, k])
        P[:, j] = acc / len(rr)
    return P


_THIGH_RANGE_M = (0.25, 0.65)


def resolve_unit_scale(bvh: BVH, spec: SourceFormat) -> float:
    """Metres per file unit for a clip: the format's documented unit, checked on the skeleton.

    The mean thigh length (hip -> knee, first frames) must lie in 0.25-0.65 m. If the
    documented unit fails the check, the unit guessed from the skeleton size is tried (with a
    warning); if that fails too, ValueError.
    """
    refs = _point_sources(bvh, spec)
    fk = bvh_fk(bvh, 1.0, frames=slice(0, min(bvh.num_frames, 30)))
    P = _mapped_positions(fk, refs)
    thigh = 0.5 * sum(
        float(np.linalg.norm(P[:, JOINT_INDEX[f'{s}_knee']] - P[:, JOINT_INDEX[f'{s}_hip']],
                             axis=-1).mean()) for s in ('left', 'right'))
    lo, hi = _THIGH_RANGE_M
    if lo <= thigh * spec.unit_scale <= hi:
        return spec.unit_scale
    guess = guess_unit_scale(bvh)
    if lo <= thigh * guess <= hi:
        warnings.warn(
            f'{bvh.name}: with the documented unit of {spec.name} ({spec.unit_scale} m) the '
            f'thigh would be {thigh * spec.unit_scale:.3f} m; using the unit guessed from the '
            f'skeleton size instead ({guess} m, thigh {thigh * guess:.3f} m)', stacklevel=2)
        return guess
    raise ValueError(
        f'{bvh.name}: cannot determine the length unit: thigh is {thigh:.4g} file units '
        f'({thigh * spec.unit_scale:.3f} m with the documented unit of {spec.name}, '
        f'{thigh * guess:.3f} m with the guessed unit); expected {lo}-{hi} m')


# ---------------------------------------------------------------------------------------------
# retargeting
# ---------------------------------------------------------------------------------------------
class FKError(NamedTuple):
    """Position error of the retargeted FK against the mapped source points, millimetres."""

    mean: float
    """Mean over frames and joints."""
    max: float
    """Maximum over frames and joints."""
    per_joint_mean: np.ndarray
    """(J,) mean over frames of each joint."""


@dataclass(eq=False)
class RetargetedClip:
    """A motion-capture clip on the pipeline skeleton.

    Attributes:
        name: clip name (file or archive member).
        fps: frame rate of the source.
        skeleton: per-clip bone lengths (symmetric pairs averaged), metres.
        rotations: (F, J, 4) local rotations (x, y, z, w) relative to the rest (T-) pose;
            row 0 is the pelvis orientation in the world frame.
        root_positions: (F, 3) pelvis position, metres, world frame (z up).
        source_positions: (F, J, 3) the mapped source points, metres, world frame.
        source_format: :data:`FORMATS` key of the source.
        unit_scale: metres per source-file unit used.
    """

    name: str
    fps: float
    skeleton: Skeleton
    rotations: np.ndarray
    root_positions: np.ndarray
    source_positions: np.ndarray
    source_format: str = ''
    unit_scale: float = float('nan')
    _fk_cache: Optional[np.ndarray] = field(default=None, init=False, repr=False)

    @property
    def num_frames(self) -> int:
        return int(self.rotations.shape[0])

    @property
    def joint_names(self) -> Tuple[str, ...]:
        return self.skeleton.joint_names

    def joint_positions(self) -> np.ndarray:
        """(F, J, 3) FK joint positions of the retargeted motion, metres."""
        if self._fk_cache is None:
            self._fk_cache = forward_kinematics(self.skeleton.parents, self.skeleton.offsets,
                                                self.rotations, self.root_positions).positions
        return self._fk_cache

    def fk_error_mm(self) -> FKError:
        """Mean / max per-joint distance between the FK of the retargeted motion and the
        mapped source points, in millimetres."""
        err = 1000.0 * np.linalg.norm(self.joint_positions() - self.source_positions, axis=-1)
        return FKError(float(err.mean()), float(err.max()), err.mean(axis=0))

    def pose(self, i: int) -> Pose:
        """Frame ``i`` as a :class:`~mocap_core.pose.Pose` (world frame)."""
        return Pose(self.skeleton, self.rotations[i], self.root_positions[i])


def _normalize(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, 1e-12)


def _frame_from_y_and_z(y: np.ndarray, z_hint: np.ndarray) -> np.ndarray:
    """(F, 3, 3) rotation with columns (x, y, z): y exact, z = z_hint made orthogonal to y."""
    y = _normalize(y)
    z = z_hint - np.sum(z_hint * y, axis=-1, keepdims=True) * y
    bad = np.linalg.norm(z, axis=-1) < 1e-9
    if np.any(bad):   # degenerate (z_hint along y): fall back to world up / forward
        up = np.where(np.abs(y[..., 2:3]) < 0.9, np.array([0.0, 0.0, 1.0]),
                      np.array([1.0, 0.0, 0.0]))
        alt = up - np.sum(up * y, axis=-1, keepdims=True) * y
        z = np.where(bad[..., None], alt, z)
    z = _normalize(z)
    x = np.cross(y, z)
    return np.stack([x, y, z], axis=-1)


def _continuous(q: np.ndarray) -> np.ndarray:
    """Flip quaternion signs along time (axis 0) so consecutive frames have dot >= 0."""
    q = q.copy()
    if q.shape[0] < 2:
        return q
    dots = np.sum(q[1:] * q[:-1], axis=-1)
    flips = np.cumsum(dots < 0, axis=0) % 2
    q[1:] *= np.where(flips[..., None] == 1, -1.0, 1.0)
    return q


_CHILDREN = [[k for k, p in enumerate(PARENTS) if p == j] for j in range(NUM_JOINTS)]
_PELVIS, _NECK, _SPINE, _HEAD = (JOINT_INDEX[n] for n in ('pelvis', 'neck', 'spine', 'head'))


_ANKLES = (JOINT_INDEX['left_ankle'], JOINT_INDEX['right_ankle'])
_WRISTS = (JOINT_INDEX['left_wrist'], JOINT_INDEX['right_wrist'])
_TOES = (JOINT_INDEX['left_toe'], JOINT_INDEX['right_toe'])


def _frame_from_x_and_y(x: np.ndarray, y_hint: np.ndarray) -> np.ndarray:
    """(F, 3, 3) rotation with columns (x, y, z): x exact, y = y_hint made orthogonal to x."""
    x = _normalize(x)
    y = _normalize(y_hint - np.sum(y_hint * x, axis=-1, keepdims=True) * x)
    return np.stack([x, y, np.cross(x, y)], axis=-1)


def _ankle_frame(G_src: np.ndarray, up: np.ndarray, foot: np.ndarray,
                 rest_foot: np.ndarray) -> np.ndarray:
    """Ankle orientation whose lateral axis is the normal of the shin-foot plane.

    ``G_src``: (F, 3, 3) orientation from the source twist (already mapping ``rest_foot`` onto
    ``foot``); ``up``: ankle -> knee; ``foot``: ankle -> toe. The plane normal
    ``cross(up, foot)`` is the rest-pose +y (left). Where ``|sin(shin, foot)| < 0.5`` the
    source's lateral axis is blended in (fully below 0.2), so the frame stays continuous when
    the foot points along the shin.
    """
    f = _normalize(foot)
    n = np.cross(_normalize(up), f)
    s = np.linalg.norm(n, axis=-1, keepdims=True)
    w = np.clip((s - 0.2) / 0.3, 0.0, 1.0)
    w = w * w * (3.0 - 2.0 * w)                              # smoothstep
    y_src = G_src[..., :, 1]
    y = w * n / np.maximum(s, 1e-12) + (1.0 - w) * y_src
    y = y - np.sum(y * f, axis=-1, keepdims=True) * f
    ok = np.linalg.norm(y, axis=-1, keepdims=True) > 1e-6
    y = np.where(ok, _normalize(y), y_src)
    # world frame (f, y, f x y) <- body frame (r, e_y, r x e_y)
    r = rest_foot / np.linalg.norm(rest_foot)
    ey = np.array([0.0, 1.0, 0.0])
    B = np.stack([r, ey, np.cross(r, ey)], axis=-1)
    A = np.stack([f, y, np.cross(f, y)], axis=-1)
    return A @ B.T


def clip_bone_lengths(source_positions: np.ndarray) -> np.ndarray:
    """(G,) bone-group lengths (m) of a clip: per-frame source bone lengths, mean over frames,
    then over each symmetric pair."""
    P = source_positions
    bl = np.zeros(NUM_JOINTS)
    for j in range(1, NUM_JOINTS):
        bl[j] = float(np.linalg.norm(P[:, j] - P[:, PARENTS[j]], axis=-1).mean())
    return bone_lengths_to_group_lengths(bl)


def retarget(bvh: BVH, fmt: Union[None, str, SourceFormat] = None,
             unit_scale: Optional[float] = None,
             frames: Union[None, slice, Sequence[int], np.ndarray] = None,
             name: Optional[str] = None) -> RetargetedClip:
    """Retarget a BVH clip onto the pipeline skeleton (see the module docstring).

    Args:
        bvh: parsed clip.
        fmt: source format (name or :class:`SourceFormat`); default detected from the names.
        unit_scale: metres per file unit; default :func:`resolve_unit_scale`.
        frames: optional frame selection (slice or indices).
        name: clip name; default ``bvh.name``.
    """
    spec = detect_format(bvh) if fmt is None else get_format(fmt)
    if unit_scale is None:
        unit_scale = resolve_unit_scale(bvh, spec)
    refs = _point_sources(bvh, spec)
    fk = bvh_fk(bvh, unit_scale, frames=frames)
    F = fk.positions.shape[0]
    if F == 0:
        raise ValueError(f'{bvh.name}: no frames to retarget')
    P = _mapped_positions(fk, refs)

    # reference orientations (source orientation mapped to the pipeline convention)
    Gref: Dict[int, np.ndarray] = {}
    for jname, (src, _C) in spec.orientations.items():
        Gref[JOINT_INDEX[jname]] = fk.rotations[:, bvh.joint_index(src)] @ \
            spec.orientation_offset(jname)

    group = clip_bone_lengths(P)
    if np.any(~np.isfinite(group)) or np.any(group <= 0):
        raise ValueError(f'{bvh.name}: degenerate bone lengths {group}')
    skel = Skeleton.from_group_lengths(group)
    off = skel.offsets

    G = np.empty((F, NUM_JOINTS, 3, 3))
    Q = np.empty((F, NUM_JOINTS, 3))      # FK positions, built along with G
    Q[:, _PELVIS] = P[:, _PELVIS]
    li, ri = JOINT_INDEX['left_hip'], JOINT_INDEX['right_hip']
    G[:, _PELVIS] = _frame_from_y_and_z(P[:, li] - P[:, ri], P[:, _SPINE] - P[:, _PELVIS])
    ls, rs = JOINT_INDEX['left_shoulder'], JOINT_INDEX['right_shoulder']
    for j in range(1, NUM_JOINTS):
        p = PARENTS[j]
        Q[:, j] = Q[:, p] + G[:, p] @ off[j]
        kids = _CHILDREN[j]
        if j == _NECK:
            G[:, j] = _frame_from_y_and_z(P[:, ls] - P[:, rs], P[:, _HEAD] - Q[:, j])
        elif len(kids) == 1:
            c = kids[0]
            ref = Gref[j]
            rest_dir = REST_DIRECTIONS[c]
            d = P[:, c] - Q[:, j]
            swing = quat_to_matrix(quat_from_two_vectors(ref @ rest_dir, d))
            G[:, j] = swing @ ref
            if j in _ANKLES:
                # foot roll from the knee-ankle-toe plane (a hinge-like ankle), blended back to
                # the source twist where the shin and the foot are nearly parallel
                G[:, j] = _ankle_frame(G[:, j], P[:, PARENTS[j]] - Q[:, j], d, rest_dir)
        elif j in _TOES:
            # a hinge toe: x along the source toe segment's forward axis, y = the ankle's
            # lateral axis (made orthogonal); flat toes in a flat-foot stance give identity
            x = Gref[j][..., :, 0]
            G[:, j] = _frame_from_x_and_y(x, G[:, p][..., :, 1])
        elif j in _WRISTS:
            # the hand keeps its source rotation relative to the source forearm frame, so a
            # forearm whose rest direction differs from the pipeline's (DAZ: 17 deg forward,
            # corrected by the elbow's swing) does not show up as a bent wrist
            G[:, j] = G[:, p] @ np.swapaxes(Gref[p], -1, -2) @ Gref[j]
        elif not kids:
            G[:, j] = Gref[j]
        else:
            raise AssertionError(f'joint {JOINT_NAMES[j]} has {len(kids)} children')
    local = local_from_global_rotations(PARENTS, G)
    quats = _continuous(matrix_to_quat(local))
    return RetargetedClip(name=name or bvh.name, fps=bvh.fps, skeleton=skel, rotations=quats,
                          root_positions=P[:, _PELVIS].copy(), source_positions=P,
                          source_format=spec.name, unit_scale=float(unit_scale))


# ---------------------------------------------------------------------------------------------
# measurement over whole data sets
# ---------------------------------------------------------------------------------------------
def _report_one_source(path: str) -> List[dict]:
    rows = []
    for name, bvh in iter_bvh_sources([path]):
        t0 = time.perf_counter()
        try:
            clip = retarget(bvh)
        except ValueError as e:
            rows.append({'name': name, 'error': str(e)})
            continue
        err = clip.fk_error_mm()
        rows.append({'name': name, 'format': clip.source_format, 'frames': clip.num_frames,
                     'fps': clip.fps, 'mean_mm': err.mean, 'max_mm': err.max,
                     'per_joint_mean_mm': err.per_joint_mean.tolist(),
                     'group_lengths_m': clip.skeleton.group_lengths().tolist(),
                     'seconds': time.perf_counter() - t0})
    return rows


def retarget_report(paths: Union[str, os.PathLike, Sequence[Union[str, os.PathLike]]],
                    workers: int = 1) -> dict:
    """Retarget every clip under ``paths`` (files, archives, directories) and summarise the
    FK error per source format.

    Returns ``{'formats': {fmt: {'clips', 'frames', 'mean_mm' (frame-weighted), 'max_mm',
    'worst_clip', 'per_joint_mean_mm'}}, 'clips': [per-clip rows], 'failed': [...],
    'seconds': wall time, 'workers': n}``. ``workers > 1`` processes sources in parallel.
    """
    t0 = time.perf_counter()
    sources = [str(p) for p in list_bvh_sources(paths)]
    if workers > 1 and len(sources) > 1:
        import multiprocessing as mp
        # biggest sources first so the pool finishes evenly
        sources.sort(key=lambda s: -os.path.getsize(s))
        # fork where available: no re-import of the caller's __main__ (numpy-only workers)
        method = 'fork' if 'fork' in mp.get_all_start_methods() else 'spawn'
        with mp.get_context(method).Pool(workers) as pool:
            chunks = pool.map(_report_one_source, sources, chunksize=1)
    else:
        chunks = [_report_one_source(s) for s in sources]
    rows = [r for ch in chunks for r in ch]
    ok = [r for r in rows if 'error' not in r]
    formats = {}
    for fmt in sorted({r['format'] for r in ok}):
        rs = [r for r in ok if r['format'] == fmt]
        frames = np.array([r['frames'] for r in rs], dtype=np.float64)
        means = np.array([r['mean_mm'] for r in rs])
        worst = max(rs, key=lambda r: r['max_mm'])
        pj = np.array([r['per_joint_mean_mm'] for r in rs])
        gl = np.array([r['group_lengths_m'] for r in rs])
        formats[fmt] = {
            'clips': len(rs), 'frames': int(frames.sum()),
            'hours': float(sum(r['frames'] / r['fps'] for r in rs) / 3600.0),
            'mean_mm': float((means * frames).sum() / frames.sum()),
            'worst_clip_mean_mm': float(means.max()),
            'max_mm': float(worst['max_mm']), 'worst_clip': worst['name'],
            'per_joint_mean_mm': dict(zip(JOINT_NAMES, np.round(
                (pj * frames[:, None]).sum(0) / frames.sum(), 2).tolist())),
            'group_length_range_m': {g: (float(gl[:, i].min()), float(gl[:, i].max()))
                                     for i, (g, _) in enumerate(BONE_GROUPS)},
        }
    return {'formats': formats, 'clips': ok, 'failed': [r for r in rows if 'error' in r],
            'seconds': time.perf_counter() - t0, 'workers': workers}
