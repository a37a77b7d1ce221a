"""The dynamic cycle of neural PhysCap (Shimada et al. 2021, §3.4) on Pinocchio (no ROS imports).

One :class:`PhysicsCycle` keeps the simulated state (q, qdot) of one person between frames;
:meth:`PhysicsCycle.step` takes the frame's kinematic target pose q_hat (in the floor frame:
z up, floor z = 0, gravity (0, 0, -9.81), see :mod:`mocap_physics.floor`) with the
foot-contact probabilities (4,) and runs ``n = max(k, ceil(frame_dt / max_substep))``
sub-steps (k = ``substeps``, paper: 6) of ``dt = frame_dt / n``. Layout of q (nq) and
qdot (nv): :mod:`mocap_physics.model`; parameters: :class:`~.cycle_params.PhysicsParams`;
outputs: :class:`~.results.FrameResult`. Why the defaults are what they are, with the
measurements behind them: ``docs/physics.md``.

1. **PD force vector**, eq. 7, inertia-scaled::

       tau = M(q) (kp o d(q_hat, q) - kd o qdot) + alpha + h(q, qdot)

   kp (s^-2), kd (s^-1) per DoF; ``d`` is the tangent-space difference: ``pinocchio.difference``
   for the ball joints (the rotation vector of q^-1 q_hat in the joint frame); for the
   free-flyer root, the translation error R^T (p_hat - p) and the rotation vector
   log(R^T R_hat), both in the root frame (the frame of the root velocity). alpha (nv,) = 0
   with fixed gains; with learned gains (``gains_mode='learned'``, :mod:`mocap_physics.dynet`)
   DyNet gives kp, kd and alpha per sub-step from (q_hat, q, qdot, diag M, e). Every DoF then
   follows ``e'' = -kp e - kd e'`` without contact forces.
2. **Ground reaction forces** (eq. 8, 9, 11): contact points whose probability exceeds
   ``contact_probability_threshold`` *and* that lie within ``contact_height`` (m) of the
   floor get a force lambda_c (3,) N from :class:`~mocap_physics.qp.GrfQP`: the root part
   tau_root (6,) of tau is explained by contact forces inside the friction pyramid
   (mu = ``friction``) as well as possible. A solver failure gives lambda = 0 for the
   sub-step (counted, reported).
3. **Forward dynamics**, eq. 13::

       qddot = M^-1 (tau* + J^T lambda - h),     tau* = tau - J^T lambda

   J (3C, nv): the contact Jacobians (LOCAL_WORLD_ALIGNED). The root keeps the residual
   direct actuation ``tau_root - J_1^T lambda`` scaled by ``root_residual`` (1 = paper;
   0 = root moved by the contact forces and gravity only, the joint torques absorbing the
   changed root acceleration so that the joints still follow the PD). Computed with
   ``pinocchio.aba``.
4. **Pose update** (eq. 14-16): ``qdot += dt qddot``; the velocity QP
   (:class:`~mocap_physics.qp.PenetrationQP`) finds the qdot* closest to qdot in the metric
   W (``penetration_metric``: diag(M), identity = eq. 15, or M) with, per contact point c
   at height z_c::

       J_c,z qdot* >= min(-z_c / dt, recovery_speed)

   for the points within ``contact_height`` of the floor now or after the step (a point at
   or below the floor moves up or stays; one above it does not cross it within the step).

   **Foot stick** (``foot_stick``, not in the paper; only with ``root_residual = 1``): the
   points that take a force are held at an anchor a_c on the floor (where they touched
   down) by equality rows ``J_c,xy qdot* = k_s (a_c - p_c,xy)`` (k_s = ``stick_gain``
   1/s, capped at ``stick_speed`` m/s) and keep their vertical velocity; the anchor is
   dragged along to stay within ``stick_release`` m of the target's point. Then
   ``q = pinocchio.integrate(q, dt qdot*)`` (semi-implicit Euler).

The steps above are the paper's cycle (``dynamics='paper'``). The default
(``dynamics='whole_body'``) replaces steps 2-3 by the whole-body inverse-dynamics QP of
:mod:`mocap_physics.wbid` per sub-step. Its stance points are the points the probabilities
put down that lie within ``contact_height`` of the floor, or within ``stance_height`` while
they come down slower than :data:`LANDING_SPEED` (they are then pulled onto the floor). A
foot slides when its friction is saturated and holding it needs ``slide_threshold`` body
weights of horizontal residual, averaged over ``slide_time``. Step 4's velocity QP stays as
the last guard.

Robustness: the first frame and a time jump (a gap over ``max_frame_gap`` s or stamps going
backwards) re-initialise q from the target (lifted so that no contact point is below the
floor) with qdot = 0, and drop the stance anchors. A skeleton change (bones off by more
than ``skeleton_tolerance`` m) rebuilds the model and keeps the state (lifted out of the
floor). A non-finite or malformed target holds the last valid one. A failed penetration QP
or a non-finite / exploding state (|qdot| above ``max_speed``) falls back to the (lifted)
kinematic target for that frame and continues from it with the target's velocity. Every
event is counted in :attr:`PhysicsCycle.stats` and named in the frame's ``status``. No NaN
is ever returned.
"""

from __future__ import annotations

import time
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import pinocchio as pin
from scipy.linalg import cho_factor, cho_solve

from mocap_core.pose import Pose
from mocap_core.skeleton import JOINT_NAMES, Skeleton

from .cycle_params import PhysicsParams
from .foot import TEMPLATE_FLAT_FOOT_PITCH_DEG
from .model import GRAVITY, PhysicsModel
from .qp import GrfQP, PenetrationQP
from .results import CycleStats, FootWrench, FrameResult
from .wbid import WholeBodyID, across_line

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

#: m/s: whole body: a point between ``contact_height`` and ``stance_height`` above the floor
#: becomes a stance point only while it comes down slower than this (a dropped foot lands)
LANDING_SPEED = 0.5



#: :meth:`PhysicsCycle.change_frame`: the largest change (rotation angle, deg; translation, m)
#: that keeps the foot-stick anchors and the solvers' memory.
SMALL_FRAME_CHANGE_DEG = 2.0
SMALL_FRAME_CHANGE_M = 0.05

class InvalidInput(ValueError):
    """The cycle cannot run on this input (no skeleton yet, malformed target, ...)."""


class PhysicsCycle:
    """Physics-based correction of a kinematic motion, one person (module docstring).

    Args:
        skeleton: the skeleton (a model is built now); None: built from the first target.
        params: :class:`PhysicsParams`.

    Raises:
        ValueError: a bad parameter; with ``gains_mode='learned'``,
            :class:`mocap_core.checkpoint.WeightsError` (a ValueError with a one-line
            message) for a missing, corrupt or crafted ``dynet_weights`` file or one that
            does not fit the skeleton's joint tree: the weights are loaded here, not at the
            first frame.
    """

    def __init__(self, skeleton: Optional[Skeleton] = None,
                 params: Optional[PhysicsParams] = None) -> None:
        self.params = params if params is not None else PhysicsParams()
        self.params.validate()
        #: the flat-foot pitch the model's heel points are placed for (degrees; the template's
        #: until an estimate replaces it when ``flat_foot_pitch_deg`` is -1)
        self.flat_foot_pitch = self.params.flat_foot_pitch_deg \
            if self.params.flat_foot_pitch_deg >= 0 else TEMPLATE_FLAT_FOOT_PITCH_DEG
        self._dynet_net = None
        self.dynet = None
        if self.params.gains_mode == 'learned':
            from .dynet import DyNet      # torch only when learned gains are used
            self._dynet_net = DyNet.load(self.params.dynet_weights)
            self._dynet_net.check_fits(len(skeleton.joint_names) if skeleton is not None
                                       else len(JOINT_NAMES), self.params.dynet_weights)
        self.stats = CycleStats()
        self.model: Optional[PhysicsModel] = None
        self.grf = GrfQP(4, self.params.friction, self.params.grf_smoothness,
                         moment_weight=self.params.grf_moment_weight)
        self.pen = PenetrationQP(metric=self.params.penetration_metric)
        self.wbid: Optional[WholeBodyID] = None
        self._whole_body = self.params.dynamics == 'whole_body'
        self._q: Optional[np.ndarray] = None
        self._v: Optional[np.ndarray] = None
        self._stamp: Optional[float] = None
        self._target_prev: Optional[np.ndarray] = None
        self._period = self.params.frame_period
        self._anchor = np.zeros((4, 2))
        self._anchored = np.zeros(4, dtype=bool)
        self._root_offset = np.zeros(2)       # m, floor x, y (_follow_feet)
        #: stance drift (_follow_drift): the last valid target's contact points (4, 3) m in
        #: the floor frame, their stance mask (4,) and their time (s); the low-passed drift
        #: velocity of the stance points (2,) m/s, floor x, y; the samples it has taken
        self._drift_prev: Optional[Tuple[np.ndarray, np.ndarray, float]] = None
        self._drift_velocity = np.zeros(2)
        self._drift_samples = 0
        #: frames the stance drift carried the state
        self.drift_frames = 0
        self._stick_vertical = True
        #: the stick needs the residual root actuation (module docstring); the whole-body
        #: dynamics holds stance points by its own acceleration rows instead
        self._stick_on = bool(self.params.foot_stick and self.params.root_residual >= 1.0
                              and not self._whole_body)
        self._stance_on = self._whole_body
        if skeleton is not None:
            self.set_skeleton(skeleton)

    # -- state -------------------------------------------------------------------------------
    @property
    def drift_velocity(self) -> np.ndarray:
        """(2,) the stance drift's low-passed velocity, m/s, floor x, y (before the dead
        band; zero where it is not followed)."""
        return self._drift_velocity.copy()

    @property
    def state(self) -> Optional[Tuple[np.ndarray, np.ndarray]]:
        """(q, qdot) copies, or None before the first frame."""
        if self._q is None:
            return None
        return self._q.copy(), self._v.copy()

    def set_state(self, q: np.ndarray, v: np.ndarray, stamp: Optional[float] = None) -> None:
        """Set the simulated state (tests, or a user resuming a run)."""
        if self.model is None:
            raise InvalidInput('no skeleton yet')
        q = np.array(q, dtype=float)
        v = np.array(v, dtype=float)
        if q.shape != (self.model.nq,) or v.shape != (self.model.nv,):
            raise ValueError('state has the wrong size')
        self._q = self.model.normalize(q)
        self._v = v
        self._stamp = stamp
        self._reset_solvers()
        self._anchored[:] = False
        self._root_offset = np.zeros(2)
        self._reset_drift()

    def reset(self) -> None:
        """Forget the state: the next frame re-initialises from its target."""
        self._q = self._v = self._stamp = self._target_prev = None
        self._reset_solvers()
        self._anchored[:] = False
        self._reset_drift()

    def _reset_drift(self) -> None:
        self._drift_prev, self._drift_velocity, self._drift_samples = None, np.zeros(2), 0

    def _reset_solvers(self) -> None:
        self.grf.reset()
        if self.wbid is not None:
            self.wbid.reset()

    def change_frame(self, rotation: np.ndarray, translation: np.ndarray,
                     carry: Optional[bool] = None, drift: bool = False) -> None:
        """Re-express the state in a new floor frame: ``p_new = rotation p_old +
        translation`` (e.g. a refined floor estimate, or the camera's motion between two
        frames). Only the root placement in q changes (Pinocchio's free-flyer velocity is
        in the root's own frame); the pose is lifted out of the new floor if needed. A small
        change (at most :data:`SMALL_FRAME_CHANGE_DEG` and :data:`SMALL_FRAME_CHANGE_M`: a
        step of a floor being blended in) carries the foot-stick anchors over (their floor
        points moved by the change) and keeps the solvers' memory of the last forces; a
        larger one drops both. ``carry`` True / False decides that whatever the size (a
        turn about z and a shift along the floor that the world made, such as a camera's
        motion, keeps the feet where they stand). ``drift`` True: the stance drift's own
        shift (:meth:`_follow_drift`): the target's remembered stance points stay where they
        are (they are the lifter's, in the camera's floor frame) and the change is not
        counted in ``stats.frame_changes``; otherwise they and the drift velocity are
        re-expressed in the new frame too."""
        R = np.asarray(rotation, dtype=float)
        t = np.asarray(translation, dtype=float).reshape(3)
        M = pin.SE3(R, t)

        def moved(q):
            q = q.copy()
            q[:7] = pin.SE3ToXYZQUAT(M * pin.XYZQUATToSE3(q[:7]))
            return q
        if self._q is not None:
            self._q = self._lift(moved(self._q))
        if self._target_prev is not None:
            self._target_prev = moved(self._target_prev)
        angle = np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))
        if carry is None:
            carry = angle <= SMALL_FRAME_CHANGE_DEG and np.linalg.norm(t) <= SMALL_FRAME_CHANGE_M
        if not drift:
            if self._drift_prev is not None:
                pts, stance, when = self._drift_prev
                self._drift_prev = (pts @ R.T + t, stance, when)
            self._drift_velocity = R[:2, :2] @ self._drift_velocity
        if carry:
            self._anchor = self._anchor @ R[:2, :2].T + t[:2]
            self._root_offset = R[:2, :2] @ self._root_offset     # a horizontal vector
        else:
            self._anchored[:] = False
            self._root_offset = np.zeros(2)
            self._reset_solvers()
        if not drift:
            self.stats.frame_changes += 1

    def set_skeleton(self, skeleton: Skeleton) -> bool:
        """Use ``skeleton``: builds a new model if a bone offset changed by more than
        ``skeleton_tolerance`` (smaller changes, e.g. a lifter refining its estimate, keep
        the model). The state (joint angles, velocities) carries over to the new model when
        the joint tree is the same; otherwise the next frame re-initialises.

        Returns True when a model was built. Raises :class:`~mocap_physics.model.SkeletonError`
        for a skeleton that cannot be simulated (the previous model is kept).
        """
        if self.model is not None and self.model.matches(
                skeleton, self.params.body_mass, atol=self.params.skeleton_tolerance):
            return False
        self._build(skeleton)
        return True

    def set_flat_foot_pitch(self, degrees: float) -> bool:
        """Place the heel points for a flat foot whose ankle-to-toe bone is ``degrees`` below
        the floor (:func:`mocap_physics.foot.contact_points`): a model with the new heel
        frames for the same skeleton; the state and the solvers carry over. Returns True when
        the model changed."""
        degrees = float(degrees)
        if not (np.isfinite(degrees) and 0.0 <= degrees <= 60.0):
            raise ValueError(f'flat-foot pitch must be 0 to 60 degrees, got {degrees}')
        if degrees == self.flat_foot_pitch:
            return False
        if self.model is None:
            self.flat_foot_pitch = degrees
            return False
        # only the heel frames move: the joint tree, the solvers and the state stay as they
        # are (rebuilding the solvers and lifting the state out of the floor at the switch
        # made the output jump); the heels' stance anchors were where the old heel points
        # stood, so they are taken again
        model = PhysicsModel(self.model.skeleton, self.params.body_mass, degrees)
        self.model, self.flat_foot_pitch = model, degrees
        self.stats.model_builds += 1
        heels = [i for i, name in enumerate(model.contact_names) if name.endswith('_heel')]
        self._anchored[heels] = False
        self._drift_prev = None           # the old heel points: not a drift of the new ones
        if self._dynet_net is not None:
            from .dynet import LearnedGains
            self.dynet = LearnedGains(self._dynet_net, self.model, self.params.dynet_weights)
        return True

    def _weight_scale(self, stance: np.ndarray) -> Optional[np.ndarray]:
        """(nv,) factors on the whole-body QP's tracking weights: ``free_limb_weight`` on
        every actuated joint but those of a leg with a point in stance (``stance``: (C,)
        bool), 1 on the root and the stance legs; None when the factor is 1."""
        k, k_s = self.params.free_limb_weight, self.params.stance_leg_weight
        if k == 1.0 and k_s == 1.0:
            return None
        key = (k, k_s, stance.tobytes())
        scale = self._scale_cache.get(key)
        if scale is None:              # (a few stance sets; the callers only read it)
            scale = np.full(self.model.nv, k)
            scale[:6] = 1.0
            for points, dofs in self._leg_dofs:
                if stance[points].any():
                    scale[dofs] = k_s
            self._scale_cache[key] = scale
        return scale

    def _build(self, skeleton: Skeleton) -> None:
        old = self.model
        model = PhysicsModel(skeleton, self.params.body_mass, self.flat_foot_pitch)
        self.model = model
        self.stats.model_builds += 1
        self._drift_prev = None           # the old bones' points: not a drift of the new ones
        if self._whole_body:
            p = self.params
            self.wbid = WholeBodyID(model.nv, len(model.contact_frame_ids), p.friction,
                                    residual_weight=p.residual_weight,
                                    residual_horizontal_weight=p.residual_horizontal_weight,
                                    residual_bound=p.residual_bound,
                                    residual_moment_bound=p.residual_moment_bound,
                                    smoothness=p.force_smoothness,
                                    slide_threshold=p.slide_threshold,
                                    slide_time=p.slide_time, solver=p.wbid_solver,
                                    condensed=p.wbid_condensed)
            # per leg: its contact points (mask) and its joints' velocity indices (hip to
            # toe), for free_limb_weight
            names, feet = skeleton.joint_names, np.array(model.contact_feet)
            self._scale_cache: Dict[tuple, np.ndarray] = {}
            self._leg_dofs = [
                (feet == side,
                 np.concatenate([np.arange(3) + model.idx_v[names.index(f'{side}_{j}')]
                                 for j in ('hip', 'knee', 'ankle', 'toe')]))
                for side in ('left', 'right')]
        #: (kp, kd) per DoF of a frame whose camera stands still or moves (step's
        #: moving_gains)
        self._gains = {False: self.params.gains(model.nv),
                       True: self.params.gains(model.nv, moving=True)}
        self._kp, self._kd = self._gains[False]
        self.dynet = None
        if self._dynet_net is not None:
            from .dynet import LearnedGains
            self.dynet = LearnedGains(self._dynet_net, model, self.params.dynet_weights)
        if old is None or old.nq != model.nq or old.skeleton.parents != skeleton.parents:
            self.reset()
        elif self._q is not None:
            self._q = self._lift(self._q)   # longer legs must not start in the floor

    # -- helpers -----------------------------------------------------------------------------
    def _difference(self, q0: np.ndarray, q1: np.ndarray,
                    R1: Optional[np.ndarray] = None) -> np.ndarray:
        """Tangent vector from q0 to q1 (root decoupled: R0^T dp, log(R0^T R1)); ``R1``: q1's
        root rotation (3, 3) when the caller has it."""
        model = self.model.model
        d = pin.difference(model, q0, q1)
        R0 = pin.XYZQUATToSE3(q0[:7]).rotation
        if R1 is None:
            R1 = pin.XYZQUATToSE3(q1[:7]).rotation
        d[0:3] = R0.T @ (q1[0:3] - q0[0:3])
        d[3:6] = pin.log3(R0.T @ R1)
        return d

    def _lift(self, q: np.ndarray, depth: float = 0.0) -> np.ndarray:
        """``q`` raised so that no foot guard point (contacts, ankles, soles) lies deeper
        than ``depth`` (m) below the floor (a copy)."""
        q = q.copy()
        low = float(self.model.guard_positions(q)[:, 2].min())
        if low < -depth:
            q[2] += -depth - low
        return q

    def _stance_offset(self, q_hat: np.ndarray) -> Optional[np.ndarray]:
        """(2,) m: the mean horizontal offset from the target's anchored stance points to
        their anchors (None: nothing anchored)."""
        held = self._anchored
        if not np.any(held):
            return None
        tgt = self.model.contact_positions(q_hat)[:, :2]
        return np.mean(self._anchor[held] - tgt[held], axis=0)

    def _keep_within_reach(self, q_hat: np.ndarray) -> np.ndarray:
        """``root_reach`` > 0 (whole body): the target moved horizontally so that the mean
        offset of its anchored stance points from their anchors is at most ``root_reach``
        (m; only the excess is taken out, so the target's own stepping within that reach is
        left to the stance release). Counted in ``stats.reached_targets``."""
        reach = self.params.root_reach
        if reach <= 0.0 or not self._stance_on or self._q is None:
            return q_hat
        wanted = self._stance_offset(q_hat)
        if wanted is None:
            return q_hat
        dist = float(np.linalg.norm(wanted))
        if dist <= reach:
            return q_hat
        self.stats.reached_targets += 1
        out = q_hat.copy()
        out[:2] += wanted * (1.0 - reach / dist)
        return out

    def _raise_sunk_target(self, q_hat: np.ndarray) -> np.ndarray:
        """The target raised so that no foot guard point lies deeper than
        ``target_floor_tolerance`` below the floor (counted in
        ``stats.sunk_targets``); unchanged when the tolerance is negative. A raise moves
        the whole body up: no joint angle changes, so the pose the PD tracks keeps its
        shape; only its height stops asking the held feet's legs to fold."""
        tol = self.params.target_floor_tolerance
        if tol < 0.0:
            return q_hat
        out = self._lift(q_hat, tol)
        if out[2] != q_hat[2]:
            self.stats.sunk_targets += 1
        return out

    def _stick_rows(self, Jc, xy, target, stick, zdot, vertical: bool = True):
        return stick_rows(self.model.contact_feet, Jc, xy, target, stick, zdot, vertical)

    def _valid_q(self, q: np.ndarray) -> bool:
        if q.shape != (self.model.nq,) or not np.all(np.isfinite(q)):
            return False
        quats = q[self.model.quaternion_q_index]
        return bool(np.all(np.einsum('ij,ij->i', quats, quats) >= 1e-12))

    def _contact_mask(self, probs: Optional[Sequence[float]]) -> Tuple[np.ndarray, str]:
        n = len(self.model.contact_names)
        if probs is None:
            return np.ones(n, dtype=bool), ''
        p = np.asarray(probs, dtype=float).reshape(-1)
        if p.shape != (n,):
            return np.ones(n, dtype=bool), f'contact probabilities: expected {n}, got {p.size}'
        mask = np.where(np.isfinite(p), p > self.params.contact_probability_threshold, True)
        msg = '' if np.all(np.isfinite(p)) else 'NaN contact probability (kinematics only)'
        return mask, msg

    # -- the cycle ---------------------------------------------------------------------------
    def step(self, target, stamp: Optional[float] = None,
             contact_probabilities: Optional[Sequence[float]] = None,
             alpha: Optional[np.ndarray] = None, camera_moving: bool = False,
             moving_gains: bool = False) -> FrameResult:
        """Advance the simulation by one frame towards ``target``.

        Args:
            target: the kinematic target in the floor frame, a :class:`Pose` (its skeleton
                may change: the model is rebuilt) or a configuration vector (nq,).
            stamp: the frame time, s (None: one ``frame_period`` after the previous frame).
            contact_probabilities: (4,) in ``CONTACT_POINT_NAMES`` order, or None
                (kinematic contact detection only). NaN entries count as unknown.
            alpha: optional (nv,) offset force of eq. 7 (0 with fixed gains).
            camera_moving: the camera may move in this frame (a camera-motion estimate
                that is not ``static``): only then is the stance drift followed
                (``stance_drift_s``).
            moving_gains: the joints' PD of this frame is ``kp_joint_moving`` /
                ``kd_joint_moving`` where set (a camera that may move and whose motion is not
                carried: the floor frame rides with it).

        Raises:
            InvalidInput: no skeleton/model yet and the target cannot provide one, or the
                first target is invalid (nothing to hold).
            SkeletonError: the target's skeleton cannot be simulated.
        """
        t_start = time.perf_counter()
        events: List[str] = []
        messages: List[str] = []
        if isinstance(target, Pose):
            had_model = self.model is not None
            if self.set_skeleton(target.skeleton) and had_model:
                events.append('skeleton_changed')
            q_hat = self.model.pose_to_q(target)
        else:
            if self.model is None:
                raise InvalidInput('no skeleton yet: pass a Pose or call set_skeleton first')
            q_hat = np.array(target, dtype=float).reshape(-1)
        valid = self._valid_q(q_hat)
        if valid:
            q_hat = self.model.normalize(q_hat)
        else:
            self.stats.invalid_inputs += 1
            if self._target_prev is None:
                raise InvalidInput('invalid target (NaN, inf, zero quaternion or wrong size) '
                                   'and no previous target to hold')
            events.append('invalid_input')
            messages.append('invalid target (NaN/inf or malformed): holding the last one')
            q_hat = self._target_prev.copy()
        mask, msg = self._contact_mask(contact_probabilities)
        if msg:
            messages.append(msg)
        if alpha is not None:
            alpha = np.asarray(alpha, dtype=float)
            if alpha.shape != (self.model.nv,) or not np.all(np.isfinite(alpha)):
                messages.append('ignored malformed alpha')
                alpha = None

        # -- time -----------------------------------------------------------------------------
        p = self.params
        if stamp is None:
            stamp = (self._stamp + self._period) if self._stamp is not None else 0.0
        stamp = float(stamp)
        reinit = None
        frame_dt = self._period
        if self._q is None:
            reinit = 'first_frame'
        elif not np.isfinite(stamp) or self._stamp is None:
            reinit = 'time_jump'
        else:
            gap = stamp - self._stamp
            if gap <= 0.0 or gap > p.max_frame_gap:
                reinit = 'time_jump'
                self.stats.time_jumps += 1
                messages.append(f'time jump of {gap:.3f} s: re-initialised from the target')
            else:
                frame_dt = gap
                # follow the actual frame rate smoothly (it sets the period after a reinit)
                self._period = 0.9 * self._period + 0.1 * gap
        if not np.isfinite(stamp):
            stamp = (self._stamp or 0.0) + self._period
        if p.stance_drift_s > 0.0 and self._stance_on:
            self._follow_drift(q_hat if valid else None, mask, frame_dt, stamp,
                               reinit is not None, camera_moving)
        if valid:          # a held target (the last one) carries its offset already
            q_hat = self._follow_feet(q_hat, frame_dt, reinit is not None)
            if reinit is None:
                q_hat = self._keep_within_reach(q_hat)
            q_hat = self._raise_sunk_target(q_hat)
        v_hat = None
        if self._target_prev is not None and reinit is None:
            v_hat = self._difference(self._target_prev, q_hat) / frame_dt
        if reinit is not None:
            events.append(reinit)
            self.stats.reinitialisations += 1
            self._q = self._lift(q_hat)
            self._v = np.zeros(self.model.nv)
            self._reset_solvers()
            self._anchored[:] = False       # anchors of the old state would pull the feet
        self._target_prev = q_hat.copy()
        self._stamp = stamp

        n_sub = max(int(p.substeps), int(np.ceil(frame_dt / p.max_substep - 1e-9)))
        dt = frame_dt / n_sub
        v_ff = v_hat if (p.velocity_feedforward and v_hat is not None) else None
        if self._stick_on or self._stance_on:
            # drag the anchors along with a target that moves away from them; the points
            # then follow at up to stick_speed (why not faster: docs/physics.md)
            tgt = self.model.contact_positions(q_hat)[:, :2]
            d = tgt - self._anchor
            dist = np.linalg.norm(d, axis=1)
            release = p.stance_release if self._stance_on else p.stick_release
            far = self._anchored & (dist > release)
            if np.any(far):
                step = d[far] * (1.0 - release / dist[far])[:, None]
                if self._stance_on:
                    # at most stick_speed: the stance rows pull the point to its anchor
                    n = np.linalg.norm(step, axis=1, keepdims=True)
                    step *= np.minimum(1.0, p.stick_speed * frame_dt / np.maximum(n, 1e-12))
                self._anchor[far] += step
        self._kp, self._kd = self._gains[bool(moving_gains)]
        try:
            simulate = self._simulate_whole_body if self._whole_body else self._simulate
            acc = simulate(q_hat, v_ff, mask, alpha, dt, n_sub)
        except _Fallback as exc:
            acc = None
            messages.append(f'fallback to the kinematic target: {exc}')
            events.append('fallback')
            self.stats.fallbacks += 1
            self._q = self._lift(q_hat)
            v0 = np.zeros(self.model.nv) if v_hat is None else v_hat
            self._v = np.clip(np.nan_to_num(v0), -p.max_speed, p.max_speed)
            self._reset_solvers()
            self._anchored[:] = False
        result = self._result(stamp, acc, events, messages)
        result.time_total = time.perf_counter() - t_start
        self.stats.frames += 1
        if events:
            self.stats.last_event = ', '.join(events)
        return result

    def _follow_drift(self, q_hat: Optional[np.ndarray], mask: np.ndarray, frame_dt: float,
                      stamp: float, reinit: bool, camera_moving: bool = False) -> None:
        """Stance drift (``stance_drift_s`` > 0, whole body): the floor frame rides with the
        camera, so with a moving camera a foot that stands in the world moves in it, and the
        target's stance points move with it. Their mean horizontal motion between two frames
        (points in stance in both, near the floor), low-passed with the time constant
        ``stance_drift_s``, is taken as the world's motion in the floor frame: the state and
        the stance anchors are carried by it (``change_frame(..., carry=True)``), as a known
        camera motion carries them, by what its speed exceeds ``stance_drift_deadband``. The
        lifter's quick foot noise is filtered out; its slow slides are followed. Until the
        filter has as many samples as its time constant spans, the drift is their mean (no
        start from zero); without stance points (a run's flight) or with an invalid (held)
        target, the last drift is held, as the camera keeps moving. Only frames whose camera
        may move (``camera_moving``: the node passes the camera-motion estimate's states
        other than ``static``) drift; in the others the velocity is reset and the stance
        anchors hold (a static camera's lifter feet drift too, and holding them is right
        there: docs/physics.md, "Stance drift").

        Args:
            q_hat: (nq,) the target in the floor frame, or None (invalid, held).
            mask: (4,) bool, the contact probabilities' stance mask of this frame.
            frame_dt: this frame's step, s. stamp: its time, s.
            reinit: the cycle re-initialises at this frame (the drift starts again).
            camera_moving: the camera may move in this frame.
        """
        p = self.params
        sample_points = None
        if q_hat is not None:
            pts = self.model.contact_positions(q_hat)
            sample_points = (pts, mask & (pts[:, 2] < p.stance_height), float(stamp))
        if reinit or self._q is None or not camera_moving:
            self._reset_drift()
            self._drift_prev = sample_points
            return
        if sample_points is not None:
            pts, stance, now = sample_points
            prev = self._drift_prev
            if prev is not None and now > prev[2]:
                both = stance & prev[1]
                if np.any(both):
                    sample = np.mean(pts[both, :2] - prev[0][both, :2], axis=0) / (now - prev[2])
                    self._drift_samples += 1
                    # the mean of the samples so far until the filter's memory is that long
                    a = max(1.0 - np.exp(-frame_dt / p.stance_drift_s), 1.0 / self._drift_samples)
                    self._drift_velocity = self._drift_velocity + a * (
                        sample - self._drift_velocity)
            self._drift_prev = sample_points
        speed = float(np.linalg.norm(self._drift_velocity))
        followed = max(0.0, 1.0 - p.stance_drift_deadband / speed) if speed > 0.0 else 0.0
        shift = followed * self._drift_velocity * frame_dt
        if np.any(shift != 0.0):
            self.change_frame(np.eye(3), np.array([shift[0], shift[1], 0.0]), carry=True,
                              drift=True)
            self.drift_frames += 1

    def _follow_feet(self, q_hat: np.ndarray, frame_dt: float, reinit: bool) -> np.ndarray:
        """Root follow (``root_follow_gain`` > 0, whole body): the target's root moved
        horizontally so that the targets of the points anchored in stance lie on their
        anchors. The lifter's root and legs often disagree about how far a step goes; the
        stance anchors then follow the target (``stance_release``) and the feet slide. This
        takes the disagreement out of the root instead: a translation, which changes no
        joint angle. The offset (m, floor x, y) moves ``root_follow_gain`` of the way to its
        new value per frame and fades with ``root_follow_relax_s`` while nothing stands.
        With ``root_follow_stance_relax_s`` > 0 it also fades in stance, with that time
        constant, and the stance anchors move with it: the feet slide slowly back under the
        lifter's root (a complementary filter: the root's motion within that time from the
        legs, the slower motion from the lifter's root)."""
        p = self.params
        if p.root_follow_gain <= 0.0 or not self._stance_on:
            return q_hat
        if reinit or self._q is None:
            self._root_offset = np.zeros(2)
            return q_hat
        held = self._anchored
        wanted = self._stance_offset(q_hat)
        if wanted is not None:
            self._root_offset = self._root_offset + p.root_follow_gain * (
                wanted - self._root_offset)
            if p.root_follow_stance_relax_s > 0.0:
                fade = self._root_offset * (1.0 - np.exp(
                    -frame_dt / p.root_follow_stance_relax_s))
                self._root_offset = self._root_offset - fade
                self._anchor[held] -= fade
        else:
            self._root_offset = self._root_offset * np.exp(
                -frame_dt / max(p.root_follow_relax_s, 1e-6))
        out = q_hat.copy()
        out[:2] += self._root_offset
        return out

    def _simulate(self, q_hat, v_ff, mask, alpha, dt, n_sub) -> dict:
        """Run n_sub sub-steps from the current state; raises _Fallback."""
        m = self.model
        model, data = m.model, m.data
        p = self.params
        weight = m.weight
        kp, kd = self._kp, self._kd
        n_c = len(m.contact_frame_ids)
        q, v = self._q, self._v
        acc = dict(torques=np.zeros(m.nv), forces=np.zeros((n_c, 3)),
                   active=np.zeros(n_c, dtype=bool), residual=np.zeros(6), grf_failures=0,
                   pen_solves=0, t_grf=0.0, t_pen=0.0, n=n_sub, cone=0,
                   stuck=np.zeros(n_c, dtype=bool))
        Jc = np.empty((n_c, 3, m.nv))
        z = np.empty(n_c)
        xy = np.empty((n_c, 2))
        anchor, anchored = self._anchor.copy(), self._anchored.copy()
        for _ in range(n_sub):
            # -- dynamics quantities at (q, v) ------------------------------------------------
            pin.computeAllTerms(model, data, q, v)   # M (upper), nle, joint Jacobians, FK
            pin.updateFramePlacements(model, data)
            M = np.triu(data.M)
            M = M + np.triu(M, 1).T
            h = data.nle.copy()
            for c, fid in enumerate(m.contact_frame_ids):
                Jc[c] = pin.getFrameJacobian(model, data, fid, _LWA)[:3]
                z[c] = data.oMf[fid].translation[2]
                xy[c] = data.oMf[fid].translation[:2]
            # -- 1. PD force vector (eq. 7, inertia-scaled) ------------------------------------
            e = self._difference(q, q_hat)
            vel_err = v if v_ff is None else v - v_ff
            alpha_k = alpha
            if self.dynet is not None:      # DyNet (eq. 7 with learned kp and alpha)
                kp, kd, alpha_net = self.dynet(q_hat, q, v, np.diag(M).copy(), e)
                alpha_k = alpha_net if alpha is None else alpha_net + alpha
            a_des = kp * e - kd * vel_err
            tau = M @ a_des + h
            if alpha_k is not None:
                tau += alpha_k
                a_des = a_des + cho_solve(cho_factor(M), alpha_k)
            # -- 2. ground reaction forces (eq. 8, 9, 11) --------------------------------------
            active = mask & (z < p.contact_height)
            grf = self.grf.solve(tau[:6], Jc[:, :, :6], active, weight)
            acc['t_grf'] += grf.solve_time
            if not grf.ok:
                acc['grf_failures'] += 1
                self.stats.grf_failures += 1
            lam = grf.forces
            tangential = np.linalg.norm(lam[:, :2], axis=1)
            cone_bad = int(np.sum((lam[:, 2] < -1e-9)
                                  | (tangential > p.friction * lam[:, 2] + 1e-9)))
            if cone_bad:
                acc['cone'] += cone_bad
                self.stats.cone_violations += cone_bad
            JtL = np.einsum('cin,ci->n', Jc, lam)
            # -- 3. forward dynamics (eq. 13): qddot = M^-1 (tau* + J^T lambda - h) -------------
            # tau* = tau - J^T lambda: joint torques compensated for the contact forces, root
            # = residual tau_root - J_1^T lambda (scaled by root_residual).
            applied = tau.copy()
            if p.root_residual < 1.0:
                # The root gets J_1^T lambda + s * residual; the joint torques absorb the
                # changed root acceleration so that the joints still follow a_des
                # (floating-base inverse dynamics of the joint rows).
                f_root = tau[:6] - (1.0 - p.root_residual) * grf.residual
                a_root = np.linalg.solve(M[:6, :6], f_root - h[:6] - M[:6, 6:] @ a_des[6:])
                applied[:6] = f_root
                applied[6:] += M[6:, :6] @ (a_root - a_des[:6])
            tau_star = applied - JtL
            a = pin.aba(model, data, q, v, tau_star + JtL)
            # -- 4. velocity update + penetration QP (eq. 14-16) ------------------------------
            v_new = v + dt * a
            zdot = Jc[:, 2, :] @ v_new
            rows = (z < p.contact_height) | (z + dt * zdot < p.contact_height)
            stick = active if self._stick_on else np.zeros(n_c, dtype=bool)
            new = stick & ~anchored
            anchor[new] = xy[new]
            anchored = stick.copy()
            A_eq = b_eq = None
            acc['stuck'] = stick.copy()
            b_all = np.minimum(-z / dt, p.recovery_speed)
            if np.any(stick):
                target = p.stick_gain * (anchor - xy)
                speed = np.linalg.norm(target, axis=1, keepdims=True)
                target *= np.minimum(1.0, p.stick_speed / np.maximum(speed, 1e-12))
                # a stuck point keeps the vertical velocity of the dynamics (or the
                # no-penetration bound): the stick must not lift or push it
                zdot_keep = np.where(rows, np.maximum(zdot, b_all), zdot)
                A_eq, b_eq = self._stick_rows(Jc, xy, target, stick, zdot_keep,
                                              vertical=self._stick_vertical)
                if self._stick_vertical:
                    rows = rows & ~stick
            if rows.any() or A_eq is not None:
                A = Jc[rows, 2, :]
                b = b_all[rows]
                solve_metric, scale = None, 1.0
                if p.penetration_metric == 'mass':
                    chol = None

                    def solve_metric(X, _M=M):
                        nonlocal chol
                        if chol is None:
                            chol = cho_factor(_M)
                        return cho_solve(chol, X)
                    scale = m.body_mass
                elif p.penetration_metric == 'diagonal':
                    d = np.maximum(np.diag(M), 1e-6)

                    def solve_metric(X, _d=d):
                        return X / _d[:, None]
                    scale = m.body_mass
                res = self.pen.solve(v_new, A, b, solve_metric=solve_metric, scale=scale,
                                     A_eq=A_eq, b_eq=b_eq)
                if not res.ok and A_eq is not None:
                    # the stick rows made it fail: keep the no-penetration rows only
                    self.stats.stick_failures += 1
                    acc['t_pen'] += res.solve_time
                    acc['stuck'][:] = False
                    anchored[:] = False
                    res = self.pen.solve(v_new, A, b, solve_metric=solve_metric, scale=scale)
                acc['t_pen'] += res.solve_time
                if res.solved:
                    acc['pen_solves'] += 1
                    self.stats.penetration_solves += 1
                if not res.ok:
                    self.stats.penetration_failures += 1
                    raise _Fallback(f'penetration QP failed ({res.status})')
                v_new = res.velocity
            if not (np.isfinite(v_new).all() and np.abs(v_new).max() <= p.max_speed):
                raise _Fallback('the simulated state diverged')
            q = pin.integrate(model, q, v_new * dt)
            v = v_new
            acc['torques'] += tau_star
            acc['forces'] += lam
            acc['active'] |= active
            acc['residual'] += grf.residual
        if not np.all(np.isfinite(q)):
            raise _Fallback('the simulated pose is not finite')
        self._q, self._v = q, v
        self._anchor, self._anchored = anchor, anchored
        return acc

    def _simulate_whole_body(self, q_hat, v_ff, mask, alpha, dt, n_sub) -> dict:
        """Run n_sub sub-steps of the whole-body dynamics (:mod:`mocap_physics.wbid`).

        Per sub-step: the PD's desired accelerations, the inverse-dynamics QP (joint torques,
        stance forces in the friction pyramid, bounded root residual), forward dynamics of
        those torques and forces (``pinocchio.aba``), the velocity update, the penetration QP
        over the foot guard points as the last guard, and the integration. Raises _Fallback.
        """
        m = self.model
        model, data = m.model, m.data
        p = self.params
        kp, kd = self._kp, self._kd
        n_c = len(m.contact_frame_ids)
        guards = m.guard_frame_ids
        q, v = self._q, self._v
        zeros = np.zeros(m.nv)
        acc = dict(torques=np.zeros(m.nv), forces=np.zeros((n_c, 3)),
                   active=np.zeros(n_c, dtype=bool), residual=np.zeros(6), grf_failures=0,
                   pen_solves=0, t_grf=0.0, t_pen=0.0, n=n_sub, cone=0,
                   stuck=np.zeros(n_c, dtype=bool), sliding=np.zeros(n_c, dtype=bool),
                   saturated=0)
        Jc = np.empty((n_c, 3, m.nv))
        Jg = np.empty((len(guards), m.nv))
        pos = np.empty((n_c, 3))
        vel = np.empty((n_c, 3))
        zg = np.empty(len(guards))
        anchor, anchored = self._anchor.copy(), self._anchored.copy()
        w_s = p.stance_gain
        feet = m.contact_feet
        lower, upper = m.lower_flat, m.upper_flat
        # the guard points start with the contact points (PhysicsModel): their rows are the
        # contacts' own
        shared = n_c if guards[:n_c] == m.contact_frame_ids else 0
        drift = np.empty((n_c, 3))
        R_hat = pin.XYZQUATToSE3(q_hat[:7]).rotation
        for _ in range(n_sub):
            pin.computeAllTerms(model, data, q, v)
            M = data.M.copy()                   # Pinocchio fills the upper triangle
            M_flat = M.reshape(-1)              # (a view: the copy is C-contiguous)
            M_flat[lower] = M_flat[upper]
            h = data.nle.copy()
            pin.forwardKinematics(model, data, q, v, zeros)   # data.a: drift terms
            pin.updateFramePlacements(model, data)
            for c, fid in enumerate(m.contact_frame_ids):
                Jc[c] = pin.getFrameJacobian(model, data, fid, _LWA)[:3]
                pos[c] = data.oMf[fid].translation
                vel[c] = pin.getFrameVelocity(model, data, fid, _LWA).linear
                drift[c] = pin.getFrameClassicalAcceleration(model, data, fid, _LWA).linear
            if shared:
                Jg[:shared] = Jc[:shared, 2]
                zg[:shared] = pos[:shared, 2]
            for g in range(shared, len(guards)):
                fid = guards[g]
                Jg[g] = pin.getFrameJacobian(model, data, fid, _LWA)[2]
                zg[g] = data.oMf[fid].translation[2]
            # -- desired accelerations (PD, eq. 7 without the inertia factor) ----------------
            e = self._difference(q, q_hat, R_hat)
            vel_err = v if v_ff is None else v - v_ff
            if self.dynet is not None:
                kp, kd, alpha_net = self.dynet(q_hat, q, v, np.diag(M).copy(), e)
                alpha = alpha_net if alpha is None else alpha_net + alpha
            a_des = kp * e - kd * vel_err
            if alpha is not None:
                a_des = a_des + cho_solve(cho_factor(M), alpha)
            # -- stance points and their stabilising reference -------------------------------
            # a point the probabilities put down is in stance near the floor, or up to
            # stance_height above it when it enters stance not coming down fast (a foot
            # falling onto the floor lands first: it is not braked in the air); once in
            # stance the speed of its own pull onto the floor does not release it
            stance = mask & ((pos[:, 2] < p.contact_height)
                             | ((pos[:, 2] < p.stance_height)
                                & (anchored | (vel[:, 2] > -LANDING_SPEED))))
            new = stance & ~anchored
            anchor[new] = pos[new, :2]
            anchored = stance.copy()
            target = np.zeros((n_c, 3))
            target[:, :2] = anchor
            a_ref = -2.0 * w_s * vel - w_s * w_s * (pos - target)
            # -- whole-body inverse dynamics -------------------------------------------------
            res = self.wbid.solve(M, h, a_des, Jc, drift, stance, a_ref, pos[:, :2], vel,
                                  feet, m.body_mass, GRAVITY,
                                  root_rotation=data.oMi[1].rotation, dt=dt,
                                  weight_scale=self._weight_scale(stance))
            acc['t_grf'] += res.solve_time
            if not res.ok:
                # no consistent solution: the PD alone drives the body for this sub-step
                acc['grf_failures'] += 1
                self.stats.grf_failures += 1
                tau_full = M @ a_des + h
                lam = np.zeros((n_c, 3))
            else:
                tau_full = np.concatenate([res.residual, res.tau])
                lam = res.forces
                if res.saturated:
                    acc['saturated'] += 1
                    self.stats.residual_saturations += 1
                if res.sliding.any():
                    anchor[res.sliding] = pos[res.sliding, :2]   # re-anchor where it slid to
                    acc['sliding'] |= res.sliding
                    self.stats.sliding_substeps += 1
            tangential = np.sqrt(lam[:, 0] * lam[:, 0] + lam[:, 1] * lam[:, 1])
            cone_bad = int(((lam[:, 2] < -1e-9)
                            | (tangential > p.friction * lam[:, 2] * (1 + 1e-6) + 1e-6)).sum())
            if cone_bad:
                acc['cone'] += cone_bad
                self.stats.cone_violations += cone_bad
            JtL = np.einsum('cin,ci->n', Jc, lam)
            # -- forward dynamics of the torques, residual and contact forces ----------------
            a = pin.aba(model, data, q, v, tau_full + JtL)
            v_new = v + dt * a
            # -- last guard: no foot point goes through the floor; a stance point that
            # arrives with a velocity is stopped at once (the plastic impact of touchdown:
            # the velocity rows of the foot stick, which leave a point already held by the
            # dynamics unchanged) -------------------------------------------------------------
            zdot = Jg @ v_new
            rows = (zg < p.contact_height) | (zg + dt * zdot < p.contact_height)
            hold = stance & ~(res.sliding if res.ok else np.zeros(n_c, dtype=bool)) \
                if self.params.foot_stick else np.zeros(n_c, dtype=bool)
            A_eq = b_eq = None
            if hold.any():
                target = p.stick_gain * (anchor - pos[:, :2])
                speed = np.linalg.norm(target, axis=1, keepdims=True)
                target *= np.minimum(1.0, p.stick_speed / np.maximum(speed, 1e-12))
                zc = Jc[:, 2, :] @ v_new
                zc_keep = np.maximum(zc, np.minimum(-pos[:, 2] / dt, p.recovery_speed))
                A_eq, b_eq = self._stick_rows(Jc, pos[:, :2], target, hold, zc_keep)
            if rows.any() or A_eq is not None:
                b_all = np.minimum(-zg / dt, p.recovery_speed)
                d = np.maximum(np.diag(M), 1e-6)

                def metric(X, _d=d):
                    return X / _d[:, None]
                res_pen = self.pen.solve(v_new, Jg[rows], b_all[rows], solve_metric=metric,
                                         scale=m.body_mass, A_eq=A_eq, b_eq=b_eq)
                if not res_pen.ok and A_eq is not None:
                    self.stats.stick_failures += 1
                    acc['t_pen'] += res_pen.solve_time
                    res_pen = self.pen.solve(v_new, Jg[rows], b_all[rows],
                                             solve_metric=metric, scale=m.body_mass)
                acc['t_pen'] += res_pen.solve_time
                if res_pen.solved:
                    acc['pen_solves'] += 1
                    self.stats.penetration_solves += 1
                if not res_pen.ok:
                    self.stats.penetration_failures += 1
                    raise _Fallback(f'penetration QP failed ({res_pen.status})')
                v_new = res_pen.velocity
            if not (np.isfinite(v_new).all() and np.abs(v_new).max() <= p.max_speed):
                raise _Fallback('the simulated state diverged')
            q = pin.integrate(model, q, v_new * dt)
            v = v_new
            acc['torques'] += tau_full
            acc['forces'] += lam
            acc['active'] |= stance
            acc['residual'] += tau_full[:6]
            acc['stuck'] = stance & ~(res.sliding if res.ok else False)
        if not np.all(np.isfinite(q)):
            raise _Fallback('the simulated pose is not finite')
        self._q, self._v = q, v
        self._anchor, self._anchored = anchor, anchored
        return acc

    def _result(self, stamp: float, acc: Optional[dict], events: List[str],
                messages: List[str]) -> FrameResult:
        m = self.model
        q, v = self._q.copy(), self._v.copy()
        n_c = len(m.contact_frame_ids)
        if acc is None:
            acc = dict(torques=np.zeros(m.nv), forces=np.zeros((n_c, 3)),
                       active=np.zeros(n_c, dtype=bool), residual=np.zeros(6), grf_failures=0,
                       pen_solves=0, t_grf=0.0, t_pen=0.0, n=0, cone=0,
                       stuck=np.zeros(n_c, dtype=bool))
            scale = 1.0
        else:
            scale = 1.0 / acc['n']
        torques = acc['torques'] * scale
        forces = acc['forces'] * scale
        residual = acc['residual'] * scale
        pos = m.contact_positions(q)
        feet: Dict[str, FootWrench] = {}
        for foot in ('left', 'right'):
            idx = [c for c, f in enumerate(m.contact_feet) if f == foot]
            point = pos[idx].mean(axis=0)
            f = forces[idx].sum(axis=0)
            moment = np.cross(pos[idx] - point, forces[idx]).sum(axis=0)
            fz = forces[idx, 2].sum()
            if fz > 1e-9:
                cop = (pos[idx] * forces[idx, 2:3]).sum(axis=0) / fz
                cop[2] = 0.0
            else:
                cop = np.array([point[0], point[1], 0.0])
            feet[foot] = FootWrench(f, np.asarray(moment, dtype=float), point, cop,
                                    bool(acc['active'][idx].any()))
        result = FrameResult(
            stamp=stamp, pose=m.q_to_pose(q), q=q, v=v, torques=torques,
            contact_forces=forces, contact_active=acc['active'].copy(), feet=feet,
            center_of_mass=m.center_of_mass(q), residual_root=residual,
            residual_ratio=float(np.linalg.norm(residual[:3]) / m.weight),
            contact_heights=pos[:, 2].copy(), contact_stuck=acc['stuck'].copy(),
            cone_violations=acc['cone'], status=', '.join(events) if events else 'ok',
            messages=messages, grf_failures=acc['grf_failures'],
            penetration_solves=acc['pen_solves'], substeps=acc['n'],
            time_grf_qp=acc['t_grf'], time_penetration_qp=acc['t_pen'],
            contact_sliding=acc.get('sliding', np.zeros(n_c, dtype=bool)).copy(),
            residual_saturated=int(acc.get('saturated', 0)))
        return result


def stick_rows(contact_feet: Sequence[str], Jc: np.ndarray, xy: np.ndarray,
               target: np.ndarray, stick: np.ndarray, zdot: np.ndarray, vertical: bool = True
               ) -> Tuple[np.ndarray, np.ndarray]:
    """Equality rows holding the stuck contact points' horizontal velocity at ``target``
    (C, 2) and their vertical velocity at ``zdot`` (C,). A foot's heel and toe points lie on
    one rigid body, so their velocities along the line joining them are (nearly) dependent:
    with both stuck, the horizontal rows are the heel's x, y and the toe's velocity across
    that line (planar position and yaw of the foot), otherwise x, y of the one point."""
    held = np.flatnonzero(stick).tolist()
    rows = [Jc[c, 2] for c in held] if vertical else []
    vals = [zdot[c] for c in held] if vertical else []
    feet = contact_feet
    done = set()
    for c in held:
        if c in done:
            continue
        rows += [Jc[c, 0], Jc[c, 1]]
        vals += [target[c, 0], target[c, 1]]
        done.add(c)
        for k in held:
            if k == c or feet[k] != feet[c] or k in done:
                continue
            n = across_line(xy, c, k)
            if n is None:
                continue
            px, py = n
            rows.append(px * Jc[k, 0] + py * Jc[k, 1])
            vals.append(px * target[k, 0] + py * target[k, 1])
            done.add(k)
    return np.array(rows), np.array(vals)


class _Fallback(RuntimeError):
    """Internal: abandon the frame and fall back to the kinematic target."""


__all__ = ['PhysicsCycle', 'InvalidInput', 'stick_rows']
