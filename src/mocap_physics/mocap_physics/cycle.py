"""The dynamic cycle of neural PhysCap (Shimada et al. 2021, §3.4) with fixed gains.

No ROS imports. One :class:`PhysicsCycle` keeps the simulated state (q, qdot) of one person
between frames; :meth:`PhysicsCycle.step` takes the frame's kinematic target pose q_hat (in the
floor frame: z up, floor z = 0, see :mod:`mocap_physics.floor`) with the foot-contact
probabilities and runs ``k`` sub-steps (paper: 6) of ``dt = frame period / k``:

1. **PD force vector**, eq. 7, inertia-scaled (see below)::

       tau = M(q) (kp o d(q_hat, q) - kd o qdot) + alpha + h(q, qdot)

   ``d`` is the tangent-space difference: ``pinocchio.difference`` for the ball joints (the
   rotation vector of q^-1 q_hat in the joint frame); for the free-flyer root, the translation
   error R^T (p_hat - p) and the rotation vector log(R^T R_hat), both in the root frame (the
   frame of the root velocity). alpha = 0 with fixed gains; with learned gains
   (``gains_mode='learned'``, :mod:`mocap_physics.dynet`) DyNet gives kp, kd and alpha per
   sub-step from (q_hat, q, qdot, diag M, e).
2. **Ground reaction forces** (eq. 8, 9, 11): contact points whose probability exceeds
   ``contact_probability_threshold`` *and* that lie within ``contact_height`` of the floor in
   the simulated state get a force lambda_c from :class:`~mocap_physics.qp.GrfQP`, which
   explains the root part tau_root of tau by contact forces inside the friction pyramid as well
   as it can. A solver failure gives lambda = 0 for the sub-step (counted, reported).
3. **Forward dynamics**, eq. 13: ``qddot = M^-1 (tau* + J^T lambda - h)`` with
   ``tau* = tau - J^T lambda`` (paper): the joint torques are compensated for the contact
   forces, and the root keeps the *residual* direct actuation ``tau_root - J_1^T lambda``,
   minimised by step 2. ``root_residual`` scales that residual: 1 (default) is the paper;
   0 drops it, so the root is moved only by the contact forces and gravity (a body with no
   contact then falls freely; the joint torques absorb the changed root acceleration so the
   joints still follow the PD). Computed with ``pinocchio.aba``. With 0 the body has only
   its four foot points to balance on: a target that is not balanced over its feet (e.g.
   standing on one leg with the pelvis centred, or lifter noise) makes it fall over, so 1 is
   the default for motion capture.
4. **Pose update** (eq. 14-16): ``qdot += dt qddot``; the penetration QP
   (:class:`~mocap_physics.qp.PenetrationQP`; metric diag(M) by default, the plain norm of
   eq. 15 or the kinetic-energy metric M on request) makes
   contact points at or below the floor move up or stay, and keeps points above it from
   crossing it within the step; then ``q = pinocchio.integrate(q, dt qdot)`` (semi-implicit).
   **Foot stick** (``foot_stick``, on by default; not in the paper): the same QP also holds
   the contact points that take a force (probability above the threshold, near the floor)
   at an anchor on the floor: equality rows ``J_c,xy qdot* = k_s (anchor_c - p_c,xy)``
   (capped at ``stick_speed``), the no-slip counterpart of eq. 15-16 at velocity level. The
   anchor is where the point touched down; when the kinematic target's point moves more
   than ``stick_release`` m away from it (a sliding foot, a wrong contact), the anchor is
   dragged along so that it stays within that distance. The stick is kinematic like eq. 15:
   the GRF QP still keeps the forces in the friction cone.
   Metric: the plain norm of eq. 15 treats a root velocity change (a whole body of 70 kg)
   like a toe's; with the stick rows active in every sub-step that feeds a correction into
   the root that the PD then fights (on the ground-truth bags: residual root force 3-25
   times body weight, and with ``root_residual = 0`` a standing body tips over), while
   diag(M) puts the correction where the inertia is small (residual 0.6 / 2.4 body weights
   clean / with lifter noise, lower jitter, see docs/benchmarks/physics_eval.md).
   The stick acts only with ``root_residual = 1``: on a passive root (0) these velocity
   projections are not momentum-consistent (diag M) or whip the light links (M: toe speeds
   of 50-100 rad/s), and a body dropped onto the floor bounces instead of landing.
   A stuck point's vertical velocity is an equality too (the one the dynamics gave it, or
   the no-penetration bound): otherwise the horizontal correction lifts the foot.

Gains (``PhysicsParams``). Eq. 7 multiplies per-DoF gains with the error (Hadamard). Here the
gains are per-DoF *accelerations* multiplied by the joint-space inertia M(q) (a
computed-torque law; DyNet takes M as an input for the same reason): every DoF follows the same
second-order error dynamics ``e'' = -kp e - kd e'`` (without contact forces), independent of
its inertia. Plain torque gains cannot be both stiff enough to track 30 fps motion on the
heavy DoF (root, hips) and stable at dt = 5.6 ms on the light ones (hands, toes): the
eigenvalues of M^-1 diag(M) of this body span 0.2 to 210. Defaults for the ball joints:
kp = 3600 s^-2, kd = 120 s^-1, i.e. natural frequency 60 rad/s (9.5 Hz), critically damped:
the delay of a critically damped tracker is about 2/omega = 33 ms (one 30 fps frame), motion up
to ~3 Hz keeps over 90 % of its amplitude, frame-rate jitter (10-15 Hz) is attenuated 2-3.5
times, and omega dt = 0.33 at 180 Hz keeps the semi-implicit Euler integration accurate and
stable. The root is softer: kp = 400 s^-2, kd = 40 s^-1 (20 rad/s, critically damped). With
the joints' 60 rad/s on the root too, a root error of 1 cm asks for 3.7 g, the GRF QP can only
push (lambda_n >= 0), so it rectifies that fluctuating demand: on the ground-truth walks the
mean vertical GRF was 2.5-2.8 body weights and the residual root force 0.6 (clean) to 2.4
(lifter noise) body weights; with 20 rad/s they are 1.06-1.11 and 0.06 / 0.96, with less
jitter, at the price of a root lag of about 2/omega = 100 ms (global position error on clean
walking 48 mm instead of 15 mm; docs/benchmarks/physics_eval.md). ``kp_ini`` of DyNet
(appendix A) are these values.

Robustness: the first frame and a time jump (a gap over ``max_frame_gap`` or stamps going
backwards) re-initialise q from the target (lifted so that no contact point is below the
floor) with qdot = 0. A skeleton change (bones off by more than ``skeleton_tolerance``)
rebuilds the model and keeps the state (lifted out of the floor). A non-finite or malformed
target holds the last valid one. A failed or inaccurate penetration QP or a non-finite /
exploding state falls back to the (lifted) kinematic target for that frame and continues from
it with the target's velocity. Every event is counted in :attr:`PhysicsCycle.stats` and named
in the frame's ``status``. No NaN is ever returned.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import pinocchio as pin
from scipy.linalg import cho_factor, cho_solve

from mocap_core.pose import Pose
from mocap_core.skeleton import Skeleton

from .model import PhysicsModel, SkeletonError
from .qp import GrfQP, PenetrationQP

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


class InvalidInput(ValueError):
    """The cycle cannot run on this input (no skeleton yet, malformed target, ...)."""


@dataclass
class PhysicsParams:
    """Parameters of the dynamic cycle (the node exposes each as a ROS parameter).

    Gains are accelerations per unit error (see the module docstring): kp in s^-2, kd in s^-1.
    """

    body_mass: float = 70.0               # kg
    substeps: int = 6                     # k of the paper
    frame_period: float = 1.0 / 30.0      # s, used when frames carry no stamps
    max_substep: float = 1.0 / 120.0      # s; longer frames get more sub-steps
    kp_root: float = 400.0                # root translation and orientation, s^-2
    kd_root: float = 40.0                 # s^-1
    kp_joint: float = 3600.0              # ball joints, s^-2
    kd_joint: float = 120.0               # s^-1
    velocity_feedforward: bool = False    # kd o (qdot_hat - qdot) instead of -kd o qdot
    friction: float = 0.8                 # mu (eq. 9)
    contact_probability_threshold: float = 0.5
    contact_height: float = 0.03          # m: a contact point must be this close to the floor
    grf_smoothness: float = 0.1           # w_s of eq. 11 relative to eq. 8
    grf_moment_weight: float = 1.0        # w_m: root moment rows of eq. 8 vs force rows
    root_residual: float = 1.0            # 1: paper (residual root actuation kept), 0: none
    penetration_metric: str = 'diagonal'  # 'diagonal' (diag M), 'identity' (paper), 'mass' (M)
    recovery_speed: float = 0.5           # m/s: max upward speed that undoes a penetration
    max_frame_gap: float = 0.25           # s: a longer gap (or stamps going back) re-initialises
    max_speed: float = 200.0              # any |qdot| entry above it counts as a blow-up
    skeleton_tolerance: float = 0.005     # m: bone offsets changing less keep the model
    gains_mode: str = 'fixed'             # 'fixed' or 'learned' (DyNet, dynet_weights)
    dynet_weights: str = ''               # DyNet weights file (mocap train physics)
    foot_stick: bool = True               # hold contact points in contact at their anchor
    stick_gain: float = 10.0              # 1/s: horizontal velocity = gain * (anchor - p)
    stick_speed: float = 0.2              # m/s: cap of that velocity
    stick_release: float = 0.05           # m: the anchor stays this close to the target

    def validate(self) -> None:
        """Raise ValueError naming every bad value."""
        bad: List[str] = []
        if not (np.isfinite(self.body_mass) and self.body_mass > 0):
            bad.append(f'body_mass={self.body_mass} (must be > 0)')
        if int(self.substeps) != self.substeps or self.substeps < 1:
            bad.append(f'substeps={self.substeps} (integer >= 1)')
        for name in ('frame_period', 'max_substep', 'max_frame_gap', 'friction',
                     'contact_height', 'recovery_speed', 'max_speed', 'skeleton_tolerance',
                     'stick_gain', 'stick_speed', 'stick_release'):
            val = getattr(self, name)
            if not (np.isfinite(val) and val > 0):
                bad.append(f'{name}={val} (must be > 0)')
        for name in ('kp_root', 'kd_root', 'kp_joint', 'kd_joint', 'grf_smoothness'):
            val = getattr(self, name)
            if not (np.isfinite(val) and val >= 0):
                bad.append(f'{name}={val} (must be >= 0)')
        if not 0.0 <= self.contact_probability_threshold <= 1.0:
            bad.append(f'contact_probability_threshold={self.contact_probability_threshold}')
        if not 0.0 <= self.root_residual <= 1.0:
            bad.append(f'root_residual={self.root_residual} (in [0, 1])')
        if self.gains_mode not in ('fixed', 'learned'):
            bad.append(f"gains_mode={self.gains_mode!r} ('fixed' or 'learned')")
        elif self.gains_mode == 'learned' and not self.dynet_weights:
            bad.append('gains_mode learned needs dynet_weights (a file from mocap train '
                       'physics)')
        if self.penetration_metric not in ('mass', 'diagonal', 'identity'):
            bad.append(f'penetration_metric={self.penetration_metric!r} '
                       '(mass | diagonal | identity)')
        if bad:
            raise ValueError('bad physics parameters: ' + '; '.join(bad))

    def gains(self, nv: int) -> Tuple[np.ndarray, np.ndarray]:
        """Per-DoF (kp, kd) vectors of length nv (root first)."""
        kp = np.full(nv, float(self.kp_joint))
        kd = np.full(nv, float(self.kd_joint))
        kp[:6] = self.kp_root
        kd[:6] = self.kd_root
        return kp, kd


@dataclass
class FootWrench:
    """Ground reaction wrench of one foot in the floor frame.

    force: (3,) N (sum over the foot's contact points); moment: (3,) N m about ``point``;
    point: (3,) the foot's reference point (midpoint of heel and toe contact points);
    cop: (3,) centre of pressure on the floor (NaN-free: equals ``point`` with no load).
    """

    force: np.ndarray
    moment: np.ndarray
    point: np.ndarray
    cop: np.ndarray
    in_contact: bool


@dataclass
class FrameResult:
    """Output of :meth:`PhysicsCycle.step` for one frame (all in the floor frame).

    Forces and torques are averages over the frame's sub-steps (the impulse over the frame
    divided by its duration).
    """

    stamp: float
    pose: Pose                      # physics-corrected pose
    q: np.ndarray                   # (nq,) configuration
    v: np.ndarray                   # (nv,) generalised velocity
    torques: np.ndarray             # (nv,) tau* = tau - J^T lambda: [root residual (6), joints]
    contact_forces: np.ndarray      # (C, 3) lambda per contact point, N
    contact_active: np.ndarray      # (C,) bool: had a contact force in some sub-step
    feet: Dict[str, FootWrench]     # 'left', 'right'
    center_of_mass: np.ndarray      # (3,)
    residual_root: np.ndarray       # (6,) tau_root - J_1^T lambda (force N, moment N m)
    residual_ratio: float           # |residual root force| / body weight
    contact_heights: np.ndarray     # (C,) height of each contact point after the frame, m
    status: str                     # 'ok' or the events of this frame (comma separated)
    messages: List[str] = field(default_factory=list)
    contact_stuck: Optional[np.ndarray] = None  # (C,) bool: held by the foot stick (last
    #                                             sub-step)
    cone_violations: int = 0        # sub-step forces outside the true friction cone
    grf_failures: int = 0
    penetration_solves: int = 0
    substeps: int = 0
    time_total: float = 0.0         # s, the whole step
    time_grf_qp: float = 0.0        # s, in the GRF solver
    time_penetration_qp: float = 0.0

    @property
    def joint_torques(self) -> np.ndarray:
        """(nv - 6,) torques of the ball joints (3 per joint, joint frames), N m."""
        return self.torques[6:]


@dataclass
class CycleStats:
    """Counters since the cycle was created."""

    frames: int = 0
    reinitialisations: int = 0
    time_jumps: int = 0
    fallbacks: int = 0
    invalid_inputs: int = 0
    grf_failures: int = 0
    penetration_failures: int = 0
    penetration_solves: int = 0
    model_builds: int = 0
    cone_violations: int = 0
    frame_changes: int = 0
    stick_failures: int = 0
    last_event: str = ''


class PhysicsCycle:
    """Physics-based correction of a kinematic motion, one person (module docstring).

    Args:
        skeleton: the skeleton (a model is built now); None: built from the first target.
        params: :class:`PhysicsParams`.
    """

    def __init__(self, skeleton: Optional[Skeleton] = None,
                 params: Optional[PhysicsParams] = None) -> None:
        self.params = params if params is not None else PhysicsParams()
        self.params.validate()
        self.stats = CycleStats()
        self.model: Optional[PhysicsModel] = None
        self.grf = GrfQP(4, self.params.friction, self.params.grf_smoothness,
                         moment_weight=self.params.grf_moment_weight)
        self.pen = PenetrationQP(metric=self.params.penetration_metric)
        self._q: Optional[np.ndarray] = None
        self._v: Optional[np.ndarray] = None
        self._stamp: Optional[float] = None
        self._target_prev: Optional[np.ndarray] = None
        self._period = self.params.frame_period
        self._anchor = np.zeros((4, 2))
        self._anchored = np.zeros(4, dtype=bool)
        self._stick_vertical = True
        #: the stick needs the residual root actuation (module docstring)
        self._stick_on = bool(self.params.foot_stick and self.params.root_residual >= 1.0)
        if skeleton is not None:
            self.set_skeleton(skeleton)

    # -- state -------------------------------------------------------------------------------
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
        self.grf.reset()
        self._anchored[:] = False

    def reset(self) -> None:
        """Forget the state: the next frame re-initialises from its target."""
        self._q = self._v = self._stamp = self._target_prev = None
        self.grf.reset()
        self._anchored[:] = False

    def change_frame(self, rotation: np.ndarray, translation: np.ndarray) -> None:
        """Re-express the state in a new floor frame: ``p_new = rotation p_old +
        translation`` (e.g. a refined floor estimate). Only the root placement in q changes
        (Pinocchio's free-flyer velocity is in the root's own frame); the pose is lifted out
        of the new floor if needed, and the foot-stick anchors are dropped."""
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
        self._anchored[:] = False
        self.grf.reset()
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
        old = self.model
        model = PhysicsModel(skeleton, self.params.body_mass)
        self.model = model
        self.stats.model_builds += 1
        self._kp, self._kd = self.params.gains(model.nv)
        self.dynet = None
        if self.params.gains_mode == 'learned':
            from .dynet import LearnedGains      # torch only when learned gains are used
            self.dynet = LearnedGains(self.params.dynet_weights, model)
        if old is None or old.nq != model.nq or old.skeleton.parents != skeleton.parents:
            self.reset()
        elif self._q is not None:
            self._q = self._lift(self._q)   # longer legs must not start in the floor
        return True

    # -- helpers -----------------------------------------------------------------------------
    def _difference(self, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
        """Tangent vector from q0 to q1 (root decoupled: R0^T dp, log(R0^T R1))."""
        model = self.model.model
        d = pin.difference(model, q0, q1)
        R0 = pin.XYZQUATToSE3(q0[:7]).rotation
        R1 = pin.XYZQUATToSE3(q1[:7]).rotation
        d[0:3] = R0.T @ (q1[0:3] - q0[0:3])
        d[3:6] = pin.log3(R0.T @ R1)
        return d

    def _lift(self, q: np.ndarray) -> np.ndarray:
        """``q`` raised so that no contact point is below the floor."""
        q = q.copy()
        low = float(self.model.contact_positions(q)[:, 2].min())
        if low < 0.0:
            q[2] -= low
        return q

    def _stick_rows(self, Jc, xy, target, stick, zdot, vertical: bool = True):
        return stick_rows(self.model.contact_feet, Jc, xy, target, stick, zdot, vertical)

    def _valid_q(self, q: np.ndarray) -> bool:
        if q.shape != (self.model.nq,) or not np.all(np.isfinite(q)):
            return False
        for j, iq in enumerate(self.model.idx_q):
            off = 3 if j == 0 else 0
            if np.linalg.norm(q[iq + off:iq + off + 4]) < 1e-6:
                return False
        return True

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
             alpha: Optional[np.ndarray] = None) -> FrameResult:
        """Advance the simulation by one frame towards ``target``.

        Args:
            target: the kinematic target in the floor frame, a :class:`Pose` (its skeleton
                may change: the model is rebuilt) or a configuration vector (nq,).
            stamp: the frame time, s (None: one ``frame_period`` after the previous frame).
            contact_probabilities: (4,) in ``CONTACT_POINT_NAMES`` order, or None
                (kinematic contact detection only). NaN entries count as unknown.
            alpha: optional (nv,) offset force of eq. 7 (0 with fixed gains).

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
        if self._valid_q(q_hat):
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
        v_hat = None
        if self._target_prev is not None and reinit is None:
            v_hat = self._difference(self._target_prev, q_hat) / frame_dt
        if reinit is not None:
            events.append(reinit)
            self.stats.reinitialisations += 1
            self._q = self._lift(q_hat)
            self._v = np.zeros(self.model.nv)
            self.grf.reset()
        self._target_prev = q_hat.copy()
        self._stamp = stamp

        n_sub = max(int(p.substeps), int(np.ceil(frame_dt / p.max_substep - 1e-9)))
        dt = frame_dt / n_sub
        v_ff = v_hat if (p.velocity_feedforward and v_hat is not None) else None
        if self._stick_on:
            # drag the anchors along with a target that moves away from them; the points
            # then follow at up to stick_speed (a faster drag, following the target's
            # velocity, lets a noisy target's jitter through: lifter-noise skating 32 instead
            # of 19 mm/frame on the ground-truth bags)
            tgt = self.model.contact_positions(q_hat)[:, :2]
            d = tgt - self._anchor
            dist = np.linalg.norm(d, axis=1)
            far = self._anchored & (dist > p.stick_release)
            if np.any(far):
                self._anchor[far] += d[far] * (1.0 - p.stick_release / dist[far])[:, None]
        try:
            acc = self._simulate(q_hat, v_ff, mask, alpha, dt, n_sub)
        except _Fallback as exc:
            acc = None
            messages.append(f'fallback to the kinematic target: {exc}')
            events.append('fallback')
            self.stats.fallbacks += 1
            self._q = self._lift(q_hat)
            v0 = np.zeros(self.model.nv) if v_hat is None else v_hat
            self._v = np.clip(np.nan_to_num(v0), -p.max_speed, p.max_speed)
            self.grf.reset()
            self._anchored[:] = False
        result = self._result(stamp, acc, events, messages)
        result.time_total = time.perf_counter() - t_start
        self.stats.frames += 1
        if events:
            self.stats.last_event = ', '.join(events)
        return result

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
            if np.any(rows) or A_eq is not None:
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
            if not (np.all(np.isfinite(v_new)) and np.abs(v_new).max() <= p.max_speed):
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
            moment = sum(np.cross(pos[c] - point, forces[c]) for c in idx)
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
            time_grf_qp=acc['t_grf'], time_penetration_qp=acc['t_pen'])
        return result


def stick_rows(contact_feet: Sequence[str], Jc: np.ndarray, xy: np.ndarray,
               target: np.ndarray, stick: np.ndarray, zdot: np.ndarray, vertical: bool = True
               ) -> Tuple[np.ndarray, np.ndarray]:
    """Equality rows holding the stuck contact points' horizontal velocity at ``target``
    (C, 2) and their vertical velocity at ``zdot`` (C,). A foot's heel and toe points lie on
    one rigid body, so their velocities along the line joining them are (nearly) dependent:
    with both stuck, the horizontal rows are the heel's x, y and the toe's velocity across
    that line (planar position and yaw of the foot), otherwise x, y of the one point."""
    rows = [Jc[c, 2] for c in np.flatnonzero(stick)] if vertical else []
    vals = [zdot[c] for c in np.flatnonzero(stick)] if vertical else []
    feet = contact_feet
    done = np.zeros(len(stick), dtype=bool)
    for c in np.flatnonzero(stick):
        if done[c]:
            continue
        mates = [k for k in np.flatnonzero(stick) if k != c and feet[k] == feet[c]
                 and not done[k]]
        rows += [Jc[c, 0], Jc[c, 1]]
        vals += [target[c, 0], target[c, 1]]
        done[c] = True
        for k in mates:
            line = xy[k] - xy[c]
            length = np.linalg.norm(line)
            if length < 1e-3:
                continue
            perp = np.array([-line[1], line[0]]) / length
            rows.append(perp @ Jc[k, :2])
            vals.append(perp @ target[k])
            done[k] = True
    return np.array(rows), np.array(vals)


class _Fallback(RuntimeError):
    """Internal: abandon the frame and fall back to the kinematic target."""


__all__ = ['PhysicsCycle', 'PhysicsParams', 'FrameResult', 'FootWrench', 'CycleStats',
           'InvalidInput', 'SkeletonError', 'stick_rows']
