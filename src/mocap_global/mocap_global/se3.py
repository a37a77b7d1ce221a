"""Global poses and global motions (GMR §3.3 eq. 2-4, §3.5, §3.6; no ROS imports).

A global pose ``G_i = (R_i, T_i)`` is the root (pelvis) orientation and position in the world
frame; the global motion ``dG_i = (dR_i, dT_i)`` is the pose of frame ``i + 1`` seen from the
body frame of frame ``i``::

    G_{i+1} = G_i dG_i          (eq. 2)
    R_{i+1} = R_i dR_i          (eq. 3)
    T_{i+1} = R_i dT_i + T_i    (eq. 4)

so ``dR_i = R_i^T R_{i+1}`` and ``dT_i = R_i^T (T_{i+1} - T_i)``. The motion is expressed in
the body's own frame, hence invariant to the choice of the world (camera) frame: any rigid
transform applied to every ``G_i`` leaves every ``dG_i`` unchanged.

Rotations are (..., 3, 3) matrices acting on column vectors; NumPy or torch (the functions use
only ``@``, ``swapaxes`` and indexing, so both work and torch keeps gradients).
"""

from __future__ import annotations

from typing import Tuple

import numpy as np

from mocap_core.rotations import (axis_angle_to_matrix, matrix_to_axis_angle, matrix_to_quat,
                                  quat_from_two_vectors, quat_to_matrix)

__all__ = [
    'relative_motion', 'accumulate', 'compose_steps', 'invert_motion', 'time_reverse_motion',
    'up_in_body', 'tilt_rotation', 'heading_rotation', 'yaw_of', 'align_yaw_translation',
]

_EZ = np.array([0.0, 0.0, 1.0])


def _t(R):
    return R.swapaxes(-1, -2) if isinstance(R, np.ndarray) else R.transpose(-1, -2)


def relative_motion(R, T) -> Tuple:
    """Global motions of a pose sequence: ``R`` (F, 3, 3), ``T`` (F, 3) -> ``dR`` (F-1, 3, 3),
    ``dT`` (F-1, 3) (module docstring). Leading batch dims before F are allowed."""
    Rt = _t(R[..., :-1, :, :])
    dR = Rt @ R[..., 1:, :, :]
    dT = (Rt @ (T[..., 1:, :] - T[..., :-1, :])[..., None])[..., 0]
    return dR, dT


def accumulate(R0: np.ndarray, T0: np.ndarray, dR: np.ndarray,
               dT: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Global poses from an initial pose and motions by eq. 3-4 (NumPy).

    Args:
        R0: (3, 3) initial orientation; T0: (3,) initial position.
        dR: (N, 3, 3), dT: (N, 3) motions.
    Returns:
        R (N+1, 3, 3), T (N+1, 3), with ``R[0] = R0``, ``T[0] = T0``.
    """
    n = len(dR)
    R = np.empty((n + 1, 3, 3))
    T = np.empty((n + 1, 3))
    R[0], T[0] = R0, T0
    for i in range(n):
        T[i + 1] = R[i] @ dT[i] + T[i]     # eq. 4
        R[i + 1] = R[i] @ dR[i]            # eq. 3
        if (i + 1) % 64 == 0:              # keep R orthonormal over long sequences
            R[i + 1] = quat_to_matrix(matrix_to_quat(R[i + 1]))
    return R, T


def compose_steps(dR: np.ndarray, dT: np.ndarray, k: int) -> Tuple[np.ndarray, np.ndarray]:
    """Motions over ``k`` frames from per-frame motions: step m of the result is
    ``dG_{km} dG_{km+1} ... dG_{km+k-1}`` (e.g. 30 fps motions -> 10 fps motions with k = 3).
    Incomplete trailing groups are dropped. (N, 3, 3), (N, 3) -> (N // k, 3, 3), (N // k, 3)."""
    n = (len(dR) // k) * k
    R = dR[0:n:k].copy()
    T = dT[0:n:k].copy()
    for j in range(1, k):
        T = T + (R @ dT[j:n:k][..., None])[..., 0]
        R = R @ dR[j:n:k]
    return R, T


def invert_motion(dR, dT) -> Tuple:
    """``dG^-1 = (dR^T, -dR^T dT)``."""
    Rt = _t(dR)
    return Rt, -(Rt @ dT[..., None])[..., 0]


def time_reverse_motion(dR, dT) -> Tuple:
    """Motions of the time-reversed sequence (flip augmentation, §3.5): reversing frames
    ``G_0..G_{F-1}`` gives ``dG'_i = (dG_{F-2-i})^-1``. Works on axis -3 / -2 (frames)."""
    Ri, Ti = invert_motion(dR, dT)
    if isinstance(dR, np.ndarray):
        return Ri[..., ::-1, :, :].copy(), Ti[..., ::-1, :].copy()
    return Ri.flip(-3), Ti.flip(-2)


def up_in_body(R):
    """The world's up direction (+z) in the body frame: ``R^T e_z`` = the third row of R.
    (..., 3, 3) -> (..., 3). It holds the root's tilt (pitch and roll), not its heading."""
    return R[..., 2, :]


def tilt_rotation(up_body: np.ndarray) -> np.ndarray:
    """The orientation with zero heading whose up vector in the body frame is ``up_body``:
    the minimal rotation taking ``up_body`` to +z. (..., 3) -> (..., 3, 3)."""
    return quat_to_matrix(quat_from_two_vectors(np.asarray(up_body, dtype=np.float64), _EZ))


def yaw_of(R: np.ndarray) -> np.ndarray:
    """Heading (rad) of an orientation: the angle of its forward (x) axis projected on the
    floor, about +z. (..., 3, 3) -> (...)."""
    return np.arctan2(R[..., 1, 0], R[..., 0, 0])


def heading_rotation(yaw) -> np.ndarray:
    """Rotation about +z by ``yaw`` rad. (...) -> (..., 3, 3)."""
    yaw = np.asarray(yaw, dtype=np.float64)
    return axis_angle_to_matrix(yaw[..., None] * _EZ)


def align_yaw_translation(P: np.ndarray, Q: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """The rotation about +z and translation (4 DOF) that best map points ``P`` onto ``Q``
    (least squares, (N, 3) each): ``(Rz (3, 3), t (3,))`` with ``Q ~ P @ Rz.T + t``. The world
    frames of GMR and of the ground truth share gravity but not heading or origin."""
    P = np.asarray(P, dtype=np.float64)
    Q = np.asarray(Q, dtype=np.float64)
    pc, qc = P.mean(axis=0), Q.mean(axis=0)
    p, q = P - pc, Q - qc
    s = np.sum(p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0])
    c = np.sum(p[:, 0] * q[:, 0] + p[:, 1] * q[:, 1])
    Rz = heading_rotation(np.arctan2(s, c))
    return Rz, qc - Rz @ pc


def rotation_angle_deg(R: np.ndarray) -> np.ndarray:
    """Angle (deg) of rotations (..., 3, 3): ``|log R|``."""
    return np.degrees(np.linalg.norm(matrix_to_axis_angle(R), axis=-1))
