"""Pinocchio model of the pipeline skeleton (no ROS imports).

The multibody model of neural PhysCap §3.1 (Shimada et al. 2021), built in code from a
:class:`mocap_core.skeleton.Skeleton` and a body mass:

* joint 1 ``pelvis``: a free flyer (root translation and orientation);
* every other skeleton joint: a ball joint (``pinocchio.JointModelSpherical``) at the bone
  offset from its parent, added depth first in skeleton order (``PARENTS[j] < j`` with each
  limb finished before the next; the order ``crba`` needs, see ENVIRONMENT.md);
* link ``j`` carries the de Leva segment of :func:`mocap_core.urdf.link_inertials` (the same
  masses and inertias as the URDF on ``/mocap/skeleton/urdf``), so the total mass is the body
  mass;
* four contact frames (``left_heel``, ``left_toe``, ``right_heel``, ``right_toe``) at
  :meth:`Skeleton.contact_points`;
* eight *foot guard* frames: the four contact points, each ankle joint and each sole midpoint
  (halfway between the heel point and the toe joint): the points of the whole foot that the
  cycle keeps above the floor (``guard_names``).

Configuration and velocity layout (Pinocchio's)::

    q = [root xyz (3), root quaternion x y z w (4), joint 1 quaternion xyzw (4), ...]
        nq = 7 + 4 (J - 1) = 75 for the 18-joint skeleton
    v = [root linear velocity (3), root angular velocity (3), joint 1 angular velocity (3), ...]
        nv = 6 + 3 (J - 1) = 57;  all expressed in the joint's own (local) frame

The quaternion order in ``q`` is x, y, z, w: the same as :class:`mocap_core.pose.Pose`, so
``pose_to_q`` is a copy. Joint ``j``'s quaternion is its rotation relative to its parent
(relative to the rest pose), as in the Pose.

Gravity is ``(0, 0, -9.81)``: the model lives in the floor frame (z up, floor z = 0).
"""

from __future__ import annotations

from typing import Dict, List, Tuple

import numpy as np
import pinocchio as pin

from mocap_core.pose import Pose
from mocap_core.skeleton import CONTACT_POINT_NAMES, Skeleton
from mocap_core.urdf import link_inertials

from .foot import TEMPLATE_FLAT_FOOT_PITCH_DEG, contact_points

GRAVITY = 9.81
#: Bones shorter than this (m) make a skeleton degenerate for the physics.
MIN_BONE_LENGTH = 1e-3


class SkeletonError(ValueError):
    """The skeleton cannot be simulated (degenerate bones, wrong joint tree, bad mass)."""


def check_skeleton(skeleton: Skeleton, body_mass: float) -> None:
    """Raise :class:`SkeletonError` with the reason when ``skeleton`` cannot be simulated."""
    if not np.isfinite(body_mass) or body_mass <= 0.0:
        raise SkeletonError(f'body mass must be positive and finite, got {body_mass!r}')
    parents = skeleton.parents
    if parents[0] != -1 or any(not (0 <= parents[j] < j) for j in range(1, len(parents))):
        raise SkeletonError('joint tree is not in topological order with the root first')
    lengths = skeleton.bone_lengths()
    short = [skeleton.joint_names[j] for j in range(1, skeleton.num_joints)
             if not lengths[j] >= MIN_BONE_LENGTH]
    if short:
        raise SkeletonError(f'degenerate skeleton: bones shorter than {MIN_BONE_LENGTH} m '
                            f'ending at {", ".join(short)}')
    if skeleton.foot_length() < 0.02:
        raise SkeletonError(f'degenerate skeleton: foot length {skeleton.foot_length():.4f} m')


class PhysicsModel:
    """Pinocchio model, data and contact frames of one skeleton and body mass.

    Build a new one whenever the skeleton (bone lengths) or the body mass changes
    (:meth:`matches` tells whether a skeleton is the one this model was built for).

    Attributes:
        skeleton: the skeleton the model was built from.
        body_mass: total mass, kg.
        model: ``pinocchio.Model`` (free flyer + J-1 spherical joints).
        data: a ``pinocchio.Data`` for it.
        nq, nv: configuration and velocity sizes.
        joint_ids: Pinocchio joint id of each skeleton joint (pelvis = 1).
        contact_names: ``CONTACT_POINT_NAMES`` (heel, toe; left, right).
        contact_frame_ids: Pinocchio frame id of each contact point.
        idx_q, idx_v: start of each skeleton joint's block in q and v.
        quaternion_q_index: (J, 4) int, the indices in q of each joint's quaternion (x, y, z,
            w; the root's after its position).
    """

    def __init__(self, skeleton: Skeleton, body_mass: float = 70.0,
                 flat_foot_pitch_deg: float = TEMPLATE_FLAT_FOOT_PITCH_DEG) -> None:
        check_skeleton(skeleton, body_mass)
        self.skeleton = skeleton
        self.body_mass = float(body_mass)
        self.flat_foot_pitch_deg = float(flat_foot_pitch_deg)
        model = pin.Model()
        model.name = 'mocap_skeleton'
        model.gravity = pin.Motion(np.array([0.0, 0.0, -GRAVITY]), np.zeros(3))
        inertials = link_inertials(skeleton, self.body_mass)
        joint_ids: List[int] = []
        for j, name in enumerate(skeleton.joint_names):
            if j == 0:
                jid = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), name)
            else:
                placement = pin.SE3(np.eye(3), np.asarray(skeleton.offsets[j], dtype=float))
                jid = model.addJoint(joint_ids[skeleton.parents[j]], pin.JointModelSpherical(),
                                     placement, name)
            joint_ids.append(jid)
            if name in inertials:
                mass, com, inertia = inertials[name]
                model.appendBodyToJoint(jid, pin.Inertia(mass, np.asarray(com, dtype=float),
                                                         np.asarray(inertia, dtype=float)),
                                        pin.SE3.Identity())
        contacts = contact_points(skeleton, self.flat_foot_pitch_deg)
        self.contact_names: Tuple[str, ...] = CONTACT_POINT_NAMES
        frame_ids = []
        for cname in self.contact_names:
            j, point = contacts[cname]
            frame = pin.Frame(cname, joint_ids[j], pin.SE3(np.eye(3), np.asarray(point, float)),
                              pin.FrameType.OP_FRAME)
            frame_ids.append(model.addFrame(frame))
        # whole-foot guard points: contacts, ankles, sole midpoints (ankle frame)
        guard_names = list(self.contact_names)
        guard_ids = list(frame_ids)
        index = {n: j for j, n in enumerate(skeleton.joint_names)}
        for side in ('left', 'right'):
            ankle, toe = index[f'{side}_ankle'], index[f'{side}_toe']
            heel = contacts[f'{side}_heel'][1]
            sole = 0.5 * (np.asarray(heel, float) + np.asarray(skeleton.offsets[toe], float))
            for gname, point in ((f'{side}_ankle', np.zeros(3)), (f'{side}_sole', sole)):
                frame = pin.Frame(f'{gname}_guard', joint_ids[ankle],
                                  pin.SE3(np.eye(3), point), pin.FrameType.OP_FRAME)
                guard_ids.append(model.addFrame(frame))
                guard_names.append(gname)
        self.guard_names: Tuple[str, ...] = tuple(guard_names)
        self.guard_frame_ids: Tuple[int, ...] = tuple(guard_ids)
        self.model = model
        self.data = model.createData()
        lower = np.tril_indices(model.nv, -1)
        #: flat indices of the lower triangle of an (nv, nv) matrix and of the upper triangle's
        #: entries that mirror them (Pinocchio fills only the upper triangle of the inertia)
        self.lower_flat = np.ravel_multi_index(lower, (model.nv, model.nv))
        self.upper_flat = np.ravel_multi_index(lower[::-1], (model.nv, model.nv))
        self.nq = model.nq
        self.nv = model.nv
        self.joint_ids = tuple(joint_ids)
        self.contact_frame_ids = tuple(frame_ids)
        self.idx_q = tuple(model.idx_qs[jid] for jid in joint_ids)
        self.idx_v = tuple(model.idx_vs[jid] for jid in joint_ids)
        self.quaternion_q_index = np.array([np.arange(4) + iq + (3 if j == 0 else 0)
                                            for j, iq in enumerate(self.idx_q)], dtype=int)
        #: Foot each contact belongs to ('left' / 'right').
        self.contact_feet = tuple(n.split('_')[0] for n in self.contact_names)
        total = pin.computeTotalMass(model)
        if abs(total - self.body_mass) > 1e-6 * self.body_mass:
            raise SkeletonError(f'model mass {total:.6f} kg != body mass {self.body_mass} kg')
        expected_nq = 7 + 4 * (skeleton.num_joints - 1)
        expected_nv = 6 + 3 * (skeleton.num_joints - 1)
        if (self.nq, self.nv) != (expected_nq, expected_nv):
            raise SkeletonError(f'model has nq={self.nq}, nv={self.nv}; expected '
                                f'{expected_nq}, {expected_nv}')

    # -- identity ----------------------------------------------------------------------------
    def matches(self, skeleton: Skeleton, body_mass: float | None = None,
                atol: float = 1e-6) -> bool:
        """True when ``skeleton`` (and ``body_mass``) is what this model was built for."""
        if skeleton is self.skeleton:
            same = True
        else:
            same = (skeleton.joint_names == self.skeleton.joint_names
                    and skeleton.parents == self.skeleton.parents
                    and np.allclose(skeleton.offsets, self.skeleton.offsets, atol=atol))
        return same and (body_mass is None or abs(body_mass - self.body_mass) < 1e-9)

    @property
    def weight(self) -> float:
        """Body weight m g, N."""
        return self.body_mass * GRAVITY

    # -- conversions -------------------------------------------------------------------------
    def pose_to_q(self, pose: Pose) -> np.ndarray:
        """Configuration (nq,) of ``pose`` (its skeleton must be this model's)."""
        if pose.skeleton.num_joints != self.skeleton.num_joints:
            raise ValueError('pose skeleton does not match the physics model')
        q = np.empty(self.nq)
        q[0:3] = pose.root_position
        rot = pose.rotations
        for j, iq in enumerate(self.idx_q):
            off = 3 if j == 0 else 0
            q[iq + off:iq + off + 4] = rot[j]
        return q

    def q_to_pose(self, q: np.ndarray, skeleton: Skeleton | None = None) -> Pose:
        """The :class:`Pose` of configuration ``q`` (quaternions are normalised)."""
        skeleton = self.skeleton if skeleton is None else skeleton
        q = np.asarray(q, dtype=float)
        rot = np.empty((skeleton.num_joints, 4))
        for j, iq in enumerate(self.idx_q):
            off = 3 if j == 0 else 0
            rot[j] = q[iq + off:iq + off + 4]
        return Pose(skeleton, rot, q[0:3].copy())

    def neutral(self) -> np.ndarray:
        """The rest (T-) pose at the origin."""
        return pin.neutral(self.model)

    def normalize(self, q: np.ndarray) -> np.ndarray:
        """``q`` with unit quaternions (in place and returned)."""
        q[:] = pin.normalize(self.model, q)
        return q

    # -- kinematics --------------------------------------------------------------------------
    def contact_positions(self, q: np.ndarray) -> np.ndarray:
        """(4, 3) world positions of the contact points at ``q``."""
        pin.framesForwardKinematics(self.model, self.data, q)
        return np.array([self.data.oMf[f].translation for f in self.contact_frame_ids])

    def guard_positions(self, q: np.ndarray) -> np.ndarray:
        """(G, 3) world positions of the foot guard points (``guard_names``) at ``q``."""
        pin.framesForwardKinematics(self.model, self.data, q)
        return np.array([self.data.oMf[f].translation for f in self.guard_frame_ids])

    def joint_positions(self, q: np.ndarray) -> np.ndarray:
        """(J, 3) world positions of the skeleton joints at ``q``."""
        pin.forwardKinematics(self.model, self.data, q)
        return np.array([self.data.oMi[j].translation for j in self.joint_ids])

    def center_of_mass(self, q: np.ndarray) -> np.ndarray:
        """(3,) world centre of mass at ``q``."""
        return pin.centerOfMass(self.model, self.data, q).copy()

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """Full symmetric joint-space inertia matrix M(q), (nv, nv).

        ``pinocchio.crba`` fills only the upper triangle; the lower one is mirrored here.
        """
        M = pin.crba(self.model, self.data, q)
        return np.triu(M) + np.triu(M, 1).T

    def describe(self) -> Dict[str, float]:
        """Short summary for logs and diagnostics."""
        return {'nq': self.nq, 'nv': self.nv, 'body_mass_kg': self.body_mass,
                'model_mass_kg': pin.computeTotalMass(self.model),
                'height_m': self.skeleton.height()}


def revolute_efforts(angles: np.ndarray, torques: np.ndarray) -> np.ndarray:
    """Ball-joint torques -> efforts of the URDF's z, y, x revolute joints.

    The URDF writes each ball joint as revolutes ``Rz(a) Ry(b) Rx(c)`` (intrinsic 'ZYX',
    :mod:`mocap_core.urdf`). The torque of a spherical joint in Pinocchio is a 3-vector in the
    child (joint) frame, dual to the angular velocity ``w = S(b, c) [a', b', c']`` in that
    frame; the generalised forces of the three revolutes are ``S^T tau`` (same power).

    Args:
        angles: (..., 3) a, b, c (rad), e.g. ``Pose.revolute_angles()``.
        torques: (..., 3) torques in the joint frames, N m.
    Returns:
        (..., 3) efforts of the z, y, x revolute joints, N m.
    """
    angles = np.asarray(angles, dtype=float)
    torques = np.asarray(torques, dtype=float)
    b, c = angles[..., 1], angles[..., 2]
    sb, cb, sc, cc = np.sin(b), np.cos(b), np.sin(c), np.cos(c)
    # columns of S: the z, y, x revolute axes expressed in the child frame
    col_a = np.stack([-sb, sc * cb, cc * cb], axis=-1)
    col_b = np.stack([np.zeros_like(b), cc, -sc], axis=-1)
    return np.stack([(col_a * torques).sum(-1), (col_b * torques).sum(-1), torques[..., 0]],
                    axis=-1)
