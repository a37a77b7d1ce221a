"""Parameters of the dynamic cycle (no ROS imports, no simulation).

:class:`PhysicsParams` holds every setting of :class:`~mocap_physics.cycle.PhysicsCycle`; the
node exposes most of them as ROS parameters. Units: SI (kg, m, s, N). Gains are per-DoF
*accelerations* per unit error, multiplied by the joint-space inertia M(q) in the cycle::

    tau = M(q) (kp o d(q_hat, q) - kd o qdot) + alpha + h(q, qdot)

so ``kp`` is in s^-2 and ``kd`` in s^-1 for every DoF (root translation, root rotation and
ball joints alike). The choice of the defaults is explained in ``docs/physics.md``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import List, Tuple

import numpy as np

#: Values of ``penetration_metric``: the metric of the velocity QP (eq. 15).
PENETRATION_METRICS = ('diagonal', 'identity', 'mass')
#: Values of ``gains_mode``.
GAINS_MODES = ('fixed', 'learned')
#: Values of ``dynamics``: the whole-body inverse-dynamics QP, or eq. 13 of the paper.
DYNAMICS_MODES = ('whole_body', 'paper')


@dataclass
class PhysicsParams:
    """Parameters of the dynamic cycle (the node exposes each as a ROS parameter).

    Gains are accelerations per unit error (module docstring): kp in s^-2, kd in s^-1.
    """

    body_mass: float = 70.0               # kg
    dynamics: str = 'whole_body'          # 'whole_body' (mocap_physics.wbid) or 'paper' (eq. 13)
    residual_weight: float = 300.0        # w_r of the whole-body QP: vertical force, moments
    residual_horizontal_weight: float = 3000.0  # w_r of the horizontal residual force rows
    #: whole body: factor on the QP's tracking weights of the joints that carry no stance
    #: point (arms, trunk, head, a swinging leg): the root and the stance legs, not light
    #: limbs, take up what the forces cannot explain (docs/physics.md, "Limbs without
    #: stance"; 1: the inertia-scaled weights alone, before session 58)
    free_limb_weight: float = 100.0
    #: whole body: the same factor for the joints of a leg with a point in stance (above 1
    #: the residual grows: docs/physics.md)
    stance_leg_weight: float = 1.0
    residual_bound: float = 1.0           # body weights: bound of each residual force row
    residual_moment_bound: float = 0.5    # body weight x m: bound of each residual moment row
    stance_gain: float = 20.0             # 1/s: stance points return to their anchor (whole body)
    stance_release: float = 0.08          # m: whole body: a stance anchor follows the target
    #                                       point when it is farther (at most stick_speed)
    root_follow_gain: float = 0.0         # whole body: per frame, the target root moves this
    #                                       share of the way to where the stance feet's targets
    #                                       lie on their anchors (0: off; cycle.py, root follow)
    root_follow_relax_s: float = 1.0      # s: without stance, that root offset fades with
    #                                       this time constant
    root_follow_stance_relax_s: float = 0.0   # s: > 0: it also fades in stance, the stance
    #                                       anchors moving with it (0: it does not)
    stance_drift_s: float = 0.25          # s: > 0: the floor frame follows the slow drift of
    #                                       the target's stance feet (a moving camera; time
    #                                       constant of its low-pass; cycle.py, stance drift)
    stance_drift_deadband: float = 0.2   # m/s: that drift is followed only where faster, by
    #                                       what it exceeds this (lifter noise of a near-still
    #                                       camera)
    slide_threshold: float = 0.15         # body weights: horizontal residual that lets a foot
    #                                       with saturated friction slide (whole body)
    slide_time: float = 0.1               # s: whole body: that residual is averaged over this
    stance_height: float = 0.08           # m: whole body: a point the contact probability puts
    #                                       down becomes a stance point this close to the floor
    #                                       (and is pulled onto it)
    #: m: a target whose foot (any guard point: heels, toes, ankles, soles) lies deeper
    #: than this below the floor is raised to this depth before the PD follows it (the
    #: lifter's depth noise and a camera that moves can put the target's feet far below the
    #: floor frame; followed, the root pulls the body down onto its held feet and it falls
    #: over: docs/physics.md, "A target below the floor"); negative: off
    target_floor_tolerance: float = 0.05
    #: m, > 0: whole body: the target's root is moved horizontally, by what exceeds this, so
    #: that the targets of the anchored stance points lie within this of their anchors (a
    #: target carried sideways away from the held feet by depth jumps pulls the body over
    #: them; cycle.py, ``_keep_within_reach``; the default since session 58, docs/physics.md);
    #: 0: off
    root_reach: float = 0.15
    force_smoothness: float = 0.01        # w_s of the whole-body QP (forces between sub-steps)
    wbid_solver: str = 'osqp'             # 'osqp' (deterministic) or 'proxqp' (mocap_physics.wbid)
    wbid_condensed: bool = True           # the QP over forces and residual, qdd in closed form
    substeps: int = 6                     # k of the paper (4: measured, docs/physics.md)
    frame_period: float = 1.0 / 30.0      # s, used when frames carry no stamps
    max_substep: float = 1.0 / 120.0      # s; longer frames get more sub-steps
    kp_root: float = 400.0                # root translation and orientation, s^-2
    kd_root: float = 40.0                 # s^-1
    kp_joint: float = 3600.0              # ball joints, s^-2
    kd_joint: float = 120.0               # s^-1
    #: the ball joints' PD in frames whose camera may move and is not carried (the floor
    #: frame then rides with the camera: the target's apparent motion includes the camera's,
    #: which the PD would trail): 90 rad/s, critically damped (docs/physics.md, session 63);
    #: 0 = kp_joint / kd_joint
    kp_joint_moving: float = 8100.0       # s^-2
    kd_joint_moving: float = 180.0        # s^-1
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
    flat_foot_pitch_deg: float = 30.0     # deg: ankle-to-toe pitch of a flat foot (heel point,
    #                                       mocap_physics.foot); 30: template; -1: estimated
    #                                       from the input's flat feet (FlatFootEstimator)

    def validate(self) -> None:
        """Raise ValueError naming every bad value."""
        bad: List[str] = []
        if not (self.flat_foot_pitch_deg == -1.0 or (np.isfinite(self.flat_foot_pitch_deg)
                                                     and 0.0 <= self.flat_foot_pitch_deg <= 60.0)):
            bad.append(f'flat_foot_pitch_deg={self.flat_foot_pitch_deg} (0 to 60, or -1: auto)')
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
        for name in ('kp_root', 'kd_root', 'kp_joint', 'kd_joint', 'kp_joint_moving',
                     'kd_joint_moving', 'grf_smoothness'):
            val = getattr(self, name)
            if not (np.isfinite(val) and val >= 0):
                bad.append(f'{name}={val} (must be >= 0)')
        if not 0.0 <= self.contact_probability_threshold <= 1.0:
            bad.append(f'contact_probability_threshold={self.contact_probability_threshold}')
        if not 0.0 <= self.root_residual <= 1.0:
            bad.append(f'root_residual={self.root_residual} (in [0, 1])')
        if self.gains_mode not in GAINS_MODES:
            bad.append(f"gains_mode={self.gains_mode!r} ('fixed' or 'learned')")
        elif self.gains_mode == 'learned' and not self.dynet_weights:
            bad.append('gains_mode learned needs dynet_weights (a file from mocap train '
                       'physics)')
        if self.dynamics not in DYNAMICS_MODES:
            bad.append(f"dynamics={self.dynamics!r} ('whole_body' or 'paper')")
        for name in ('residual_weight', 'residual_horizontal_weight', 'free_limb_weight',
                     'stance_leg_weight', 'stance_gain', 'root_follow_relax_s'):
            val = getattr(self, name)
            if not (np.isfinite(val) and val > 0):
                bad.append(f'{name}={val} (must be > 0)')
        for name in ('residual_bound', 'residual_moment_bound', 'force_smoothness',
                     'stance_release', 'slide_threshold', 'slide_time', 'stance_height',
                     'root_follow_gain', 'root_follow_stance_relax_s', 'stance_drift_s',
                     'stance_drift_deadband', 'root_reach'):
            val = getattr(self, name)
            if not (np.isfinite(val) and val >= 0):
                bad.append(f'{name}={val} (must be >= 0)')
        if self.wbid_solver not in ('osqp', 'proxqp'):
            bad.append(f"wbid_solver={self.wbid_solver!r} ('osqp' or 'proxqp')")
        if self.penetration_metric not in PENETRATION_METRICS:
            bad.append(f'penetration_metric={self.penetration_metric!r} '
                       '(mass | diagonal | identity)')
        if bad:
            raise ValueError('bad physics parameters: ' + '; '.join(bad))

    def gains(self, nv: int, moving: bool = False) -> Tuple[np.ndarray, np.ndarray]:
        """Per-DoF (kp, kd) vectors of length nv (root first: 3 translation, 3 rotation);
        ``moving``: those of a frame whose camera moves (``kp_joint_moving``,
        ``kd_joint_moving`` where set)."""
        kp_j = self.kp_joint_moving if moving and self.kp_joint_moving > 0 else self.kp_joint
        kd_j = self.kd_joint_moving if moving and self.kd_joint_moving > 0 else self.kd_joint
        kp = np.full(nv, float(kp_j))
        kd = np.full(nv, float(kd_j))
        kp[:6] = self.kp_root
        kd[:6] = self.kd_root
        return kp, kd


__all__ = ['PhysicsParams', 'PENETRATION_METRICS', 'GAINS_MODES', 'DYNAMICS_MODES']
