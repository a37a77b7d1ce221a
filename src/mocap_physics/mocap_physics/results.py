"""What the dynamic cycle returns (no ROS imports, no simulation).

:class:`FrameResult` is the output of :meth:`mocap_physics.cycle.PhysicsCycle.step` for one
frame, :class:`FootWrench` the ground reaction wrench of one foot, :class:`CycleStats` the
counters of a cycle since it was created. Everything is in the **floor frame** (z up, floor
z = 0, gravity (0, 0, -9.81)); forces in N, moments and torques in N m, lengths in m,
quaternions x, y, z, w. ``C`` = 4 contact points in
:data:`mocap_core.skeleton.CONTACT_POINT_NAMES` order (left heel, left toe, right heel,
right toe); ``nq`` / ``nv`` = the Pinocchio configuration / velocity sizes
(:mod:`mocap_physics.model`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional

import numpy as np

from mocap_core.pose import Pose


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

    stamp: float                    # s
    pose: Pose                      # physics-corrected pose
    q: np.ndarray                   # (nq,) configuration
    v: np.ndarray                   # (nv,) generalised velocity (root: in the root frame)
    torques: np.ndarray             # (nv,) tau* = tau - J^T lambda: [root residual (6), joints]
    contact_forces: np.ndarray      # (C, 3) lambda per contact point, N
    contact_active: np.ndarray      # (C,) bool: had a contact force in some sub-step
    feet: Dict[str, FootWrench]     # 'left', 'right'
    center_of_mass: np.ndarray      # (3,) m
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
    contact_sliding: Optional[np.ndarray] = None  # (C,) bool: a stance point slid (whole body)
    residual_saturated: int = 0     # sub-steps whose root residual reached its bound

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
    frame_changes: int = 0          # re-expressions of the state in a new floor frame (every
                                    # step of a blended re-fit: FloorTracker.changes counts fits)
    stick_failures: int = 0
    residual_saturations: int = 0   # whole-body sub-steps whose root residual hit its bound
    sliding_substeps: int = 0       # whole-body sub-steps with a stance point sliding
    sunk_targets: int = 0           # targets raised: a foot deeper than
                                    # target_floor_tolerance below the floor
    reached_targets: int = 0        # targets moved back within root_reach of the stance feet
    last_event: str = ''


__all__ = ['FootWrench', 'FrameResult', 'CycleStats']
