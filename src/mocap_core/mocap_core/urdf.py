"""Skeleton -> URDF with anthropometric masses and inertias.

The URDF is what `/mocap/skeleton/urdf` carries (docs/design.md §2): robot_state_publisher,
RViz and Pinocchio load it. Its structure:

* the root link is ``pelvis``; a consumer that needs the floating base adds it (Pinocchio:
  ``buildModelFromXML(urdf, JointModelFreeFlyer())``);
* every other joint ``j`` of :mod:`mocap_core.skeleton` is a ball joint written as three
  revolute joints ``j_rz``, ``j_ry``, ``j_rx`` (axes z, y, x, in this order from the parent)
  joined by massless links ``j_rz_link``, ``j_ry_link``; the composite rotation is
  ``Rz(a) Ry(b) Rx(c)`` = intrinsic Euler 'ZYX' (:func:`ball_joint_names`). The joint origin
  is the bone offset from :class:`~mocap_core.skeleton.Skeleton` (rest pose = all zero);
* link ``j`` carries the body segment that starts at joint ``j``;
* fixed joints add the foot contact frames ``left_heel_contact``, ``left_toe_contact``,
  ``right_heel_contact``, ``right_toe_contact``.

Segment parameters: de Leva, P. (1996). "Adjustments to Zatsiorsky-Seluyanov's segment inertia
parameters." Journal of Biomechanics 29(9), 1223-1230, Table 4 (male): mass fraction of the
whole body, centre-of-mass position along the segment (fraction of its length from the
proximal end) and radii of gyration (fraction of the segment length; we model each segment as
axisymmetric about its long axis, using the mean of the sagittal and transverse radii).
The lower and middle trunk form the pelvis link, the upper trunk the spine link, head+neck the
head link; the neck link is massless (its mass is in head+neck). Foot mass is split 80/20
between the foot (ankle link) and the toes (toe link) — our assumption, the table has one
foot segment. The fractions sum to 1, so the model's total mass equals ``body_mass``.
Segment lengths are this skeleton's bone lengths (end segments: see ``_END_SEGMENT``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, List, Tuple
from xml.sax.saxutils import escape

import numpy as np

from .skeleton import CONTACT_POINT_NAMES, JOINT_INDEX, REST_DIRECTIONS, Skeleton

#: Euler order of the three revolute joints that stand for one ball joint (intrinsic).
BALL_EULER_ORDER = 'ZYX'
_AXIS_SUFFIXES = ('rz', 'ry', 'rx')
_AXES = {'rz': '0 0 1', 'ry': '0 1 0', 'rx': '1 0 0'}


@dataclass(frozen=True)
class SegmentParameters:
    """Inertial parameters of one body segment, relative to body mass and segment length."""

    mass_fraction: float     # of total body mass
    com_fraction: float      # CoM distance from the proximal joint / segment length
    radius_transverse: float  # radius of gyration about axes across the segment / length
    radius_longitudinal: float  # radius of gyration about the long axis / length


def _seg(mass_pct: float, com_pct: float, r_sag: float, r_trans: float, r_long: float,
         ) -> SegmentParameters:
    return SegmentParameters(mass_pct / 100.0, com_pct / 100.0,
                             0.5 * (r_sag + r_trans) / 100.0, r_long / 100.0)


# de Leva (1996), Table 4, male. Trunk parts are combined where one link of ours spans them.
_DE_LEVA = {
    'head_neck': _seg(6.94, 59.76, 36.2, 37.6, 31.2),
    'upper_trunk': _seg(15.96, 29.99, 71.6, 45.4, 65.9),
    'middle_plus_lower_trunk': _seg(16.33 + 11.17, 50.0, 48.2, 38.3, 46.8),
    'upper_arm': _seg(2.71, 57.72, 28.5, 26.9, 15.8),
    'forearm': _seg(1.62, 45.74, 27.6, 26.5, 12.1),
    'hand': _seg(0.61, 79.00, 62.8, 51.3, 40.1),
    'thigh': _seg(14.16, 40.95, 32.9, 32.9, 14.9),
    'shank': _seg(4.33, 44.59, 25.5, 24.9, 10.3),
    'foot': _seg(1.37 * 0.8, 44.15, 25.7, 24.5, 12.4),
    'toes': _seg(1.37 * 0.2, 50.0, 25.7, 24.5, 12.4),
}

#: Segment carried by each joint's link (None: massless link).
LINK_SEGMENTS: Dict[str, str | None] = {
    'pelvis': 'middle_plus_lower_trunk', 'spine': 'upper_trunk', 'neck': None,
    'head': 'head_neck',
    'left_hip': 'thigh', 'left_knee': 'shank', 'left_ankle': 'foot', 'left_toe': 'toes',
    'right_hip': 'thigh', 'right_knee': 'shank', 'right_ankle': 'foot', 'right_toe': 'toes',
    'left_shoulder': 'upper_arm', 'left_elbow': 'forearm', 'left_wrist': 'hand',
    'right_shoulder': 'upper_arm', 'right_elbow': 'forearm', 'right_wrist': 'hand',
}

#: The segment of link j runs from joint j to this child joint ...
_SEGMENT_CHILD = {
    'pelvis': 'spine', 'spine': 'neck', 'neck': 'head',
    'left_hip': 'left_knee', 'left_knee': 'left_ankle', 'left_ankle': 'left_toe',
    'right_hip': 'right_knee', 'right_knee': 'right_ankle', 'right_ankle': 'right_toe',
    'left_shoulder': 'left_elbow', 'left_elbow': 'left_wrist',
    'right_shoulder': 'right_elbow', 'right_elbow': 'right_wrist',
}
#: ... or, for end joints, continues along the joint's own bone direction for this fraction of
#: a reference bone: hand ~ 0.7 forearm, toes ~ 0.35 foot, head (ears to vertex and the face)
#: ~ 1.0 neck-to-head bone.
_END_SEGMENT = {
    'head': ('head', 1.0), 'left_wrist': ('left_wrist', 0.7),
    'right_wrist': ('right_wrist', 0.7), 'left_toe': ('left_toe', 0.35),
    'right_toe': ('right_toe', 0.35),
}


def ball_joint_names(joint: str) -> Tuple[str, str, str]:
    """Names of the three revolute joints (z, y, x) that stand for ball joint ``joint``."""
    return tuple(f'{joint}_{s}' for s in _AXIS_SUFFIXES)  # type: ignore[return-value]


def revolute_joint_names(skeleton: Skeleton) -> List[str]:
    """All revolute joint names of the URDF, in JointState order (3 per non-root joint)."""
    return [n for j in skeleton.joint_names[1:] for n in ball_joint_names(j)]


def segment_geometry(skeleton: Skeleton, joint: str) -> Tuple[np.ndarray, float]:
    """Unit direction (3,) in the link frame and length (m) of the segment of ``joint``."""
    if joint in _SEGMENT_CHILD:
        vec = skeleton.offsets[JOINT_INDEX[_SEGMENT_CHILD[joint]]]
        length = float(np.linalg.norm(vec))
        return vec / max(length, 1e-9), length
    ref, fraction = _END_SEGMENT[joint]
    length = fraction * float(skeleton.bone_lengths()[JOINT_INDEX[ref]])
    return REST_DIRECTIONS[JOINT_INDEX[joint]].copy(), length


def link_inertials(skeleton: Skeleton, body_mass: float = 70.0,
                   ) -> Dict[str, Tuple[float, np.ndarray, np.ndarray]]:
    """Mass (kg), CoM (3,) and inertia about the CoM (3, 3) of every link, in link frames.

    Massless links are omitted. Raises ValueError for a non-positive body mass.
    """
    if not np.isfinite(body_mass) or body_mass <= 0:
        raise ValueError(f'body_mass must be positive, got {body_mass}')
    out: Dict[str, Tuple[float, np.ndarray, np.ndarray]] = {}
    for joint in skeleton.joint_names:
        seg_name = LINK_SEGMENTS[joint]
        if seg_name is None:
            continue
        seg = _DE_LEVA[seg_name]
        direction, length = segment_geometry(skeleton, joint)
        mass = seg.mass_fraction * body_mass
        com = direction * seg.com_fraction * length
        dd = np.outer(direction, direction)
        inertia = mass * length ** 2 * (seg.radius_transverse ** 2 * (np.eye(3) - dd)
                                        + seg.radius_longitudinal ** 2 * dd)
        out[joint] = (mass, com, inertia)
    return out


def _fmt(v: np.ndarray | List[float]) -> str:
    return ' '.join(f'{float(x):.9g}' for x in v)


def skeleton_to_urdf(skeleton: Skeleton, body_mass: float = 70.0,
                     name: str = 'mocap_skeleton', joint_limit: float = np.pi,
                     ) -> str:
    """URDF (XML string) of ``skeleton`` with de Leva segment inertias (module docstring).

    Args:
        skeleton: the skeleton (offsets in metres).
        body_mass: total body mass, kg.
        name: robot name.
        joint_limit: +- limit of every revolute joint, rad (robot_state_publisher and
            Pinocchio need limits; pi leaves the ball joint free).
    """
    inertials = link_inertials(skeleton, body_mass)
    lines = ['<?xml version="1.0"?>', f'<robot name="{escape(name)}">']

    def link(link_name: str) -> None:
        if link_name in inertials:
            mass, com, inertia = inertials[link_name]
            lines.append(f'  <link name="{link_name}">')
            lines.append('    <inertial>')
            lines.append(f'      <origin xyz="{_fmt(com)}" rpy="0 0 0"/>')
            lines.append(f'      <mass value="{mass:.9g}"/>')
            lines.append(
                f'      <inertia ixx="{inertia[0, 0]:.9g}" ixy="{inertia[0, 1]:.9g}" '
                f'ixz="{inertia[0, 2]:.9g}" iyy="{inertia[1, 1]:.9g}" '
                f'iyz="{inertia[1, 2]:.9g}" izz="{inertia[2, 2]:.9g}"/>')
            lines.append('    </inertial>')
            lines.append('  </link>')
        else:
            lines.append(f'  <link name="{link_name}"/>')

    def joint(joint_name: str, kind: str, parent: str, child: str, xyz: np.ndarray,
              axis: str | None = None) -> None:
        lines.append(f'  <joint name="{joint_name}" type="{kind}">')
        lines.append(f'    <parent link="{parent}"/>')
        lines.append(f'    <child link="{child}"/>')
        lines.append(f'    <origin xyz="{_fmt(xyz)}" rpy="0 0 0"/>')
        if axis is not None:
            lines.append(f'    <axis xyz="{axis}"/>')
            lines.append(f'    <limit lower="{-joint_limit:.9g}" upper="{joint_limit:.9g}" '
                         'effort="1000" velocity="100"/>')
        lines.append('  </joint>')

    link(skeleton.joint_names[0])
    for j in range(1, skeleton.num_joints):
        child_name = skeleton.joint_names[j]
        parent_link = skeleton.joint_names[skeleton.parents[j]]
        names = ball_joint_names(child_name)
        frames = [f'{names[0]}_link', f'{names[1]}_link', child_name]
        origin = skeleton.offsets[j]
        for k, (jn, suffix) in enumerate(zip(names, _AXIS_SUFFIXES)):
            link(frames[k])
            joint(jn, 'revolute', parent_link if k == 0 else frames[k - 1], frames[k],
                  origin if k == 0 else np.zeros(3), axis=_AXES[suffix])
    for contact, (ji, point) in skeleton.contact_points().items():
        assert contact in CONTACT_POINT_NAMES
        frame = f'{contact}_contact'
        link(frame)
        joint(f'{frame}_joint', 'fixed', skeleton.joint_names[ji], frame, point)
    lines.append('</robot>')
    return '\n'.join(lines) + '\n'
