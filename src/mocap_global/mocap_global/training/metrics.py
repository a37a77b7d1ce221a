"""Metrics of global motion and world trajectories (no ROS). Positions in metres in, the
functions return millimetres / degrees / percent where the name says so.

Per-step motion errors (supplementary S4):

* OME, eq. 15: ``|log(dR*_i dR_i^T)|`` (deg), mean over steps;
* TME, eq. 16: ``|dT_i - dT*_i|`` (mm);
* joint motion error (JME), eq. 17 with the skeleton's joints in place of SMPL vertices:
  ``mean_j |dM_i[j] - dM*_i[j]|`` (mm) with ``dM_i[j] = dR_i p_{i+1}[j] + dT_i`` the joints of
  frame i + 1 in the body frame of frame i (ground-truth local pose on both sides).

Accumulated (world trajectory) errors, the predicted motions accumulated by eq. 3-4 from the
ground-truth pose at a start frame (so only the motion errors count):

* drift after h seconds: root position error h seconds after the start, averaged over starts
  every second of every clip long enough;
* RTE: mean root position error over a whole clip accumulated from its first frame, as a
  percentage of the distance the root travelled (clips that travel at least 1 m);
* ATE: mean root position error after the best rotation about the vertical and translation
  (4 DOF) of the whole predicted trajectory onto the ground truth.
"""

from __future__ import annotations

from typing import Dict, Sequence

import numpy as np

from mocap_core.rotations import matrix_to_axis_angle

from ..se3 import accumulate, align_yaw_translation

#: Clips travelling less than this (m) are left out of RTE.
RTE_MIN_DISTANCE_M = 1.0


def ome_deg(dR: np.ndarray, dR_gt: np.ndarray) -> np.ndarray:
    """Per-step orientation motion error (deg), (N, 3, 3) x2 -> (N,)."""
    err = dR_gt @ np.swapaxes(dR, -1, -2)
    return np.degrees(np.linalg.norm(matrix_to_axis_angle(err), axis=-1))


def tme_mm(dT: np.ndarray, dT_gt: np.ndarray) -> np.ndarray:
    """Per-step translation motion error (mm), (N, 3) x2 -> (N,)."""
    return 1000.0 * np.linalg.norm(dT - dT_gt, axis=-1)


def jme_mm(dR: np.ndarray, dT: np.ndarray, dR_gt: np.ndarray, dT_gt: np.ndarray,
           joints_next: np.ndarray) -> np.ndarray:
    """Per-step joint motion error (mm): ``joints_next`` (N, J, 3) are the joints of frame
    i + 1 in its own root frame. -> (N,)."""
    pred = np.einsum('nik,njk->nji', dR, joints_next) + dT[:, None]
    true = np.einsum('nik,njk->nji', dR_gt, joints_next) + dT_gt[:, None]
    return 1000.0 * np.linalg.norm(pred - true, axis=-1).mean(axis=-1)


def drift_mm(dR: np.ndarray, dT: np.ndarray, R_gt: np.ndarray, T_gt: np.ndarray,
             horizons: Sequence[int], start_every: int) -> Dict[int, np.ndarray]:
    """Root position errors (mm) ``h`` steps after starts every ``start_every`` frames,
    accumulating predicted motions (N = F-1) from the ground-truth poses (F frames) at each
    start. Returns {h: errors (starts,)} (empty arrays where the clip is too short)."""
    n = len(dR)
    out: Dict[int, np.ndarray] = {}
    hmax = max(horizons)
    starts = np.arange(0, max(n - min(horizons) + 1, 0), start_every)
    if len(starts) == 0:
        return {h: np.zeros(0) for h in horizons}
    R = R_gt[starts].copy()
    T = T_gt[starts].copy()
    for step in range(1, hmax + 1):
        ok = starts + step - 1 < n
        if not ok.any():
            break
        i = np.minimum(starts + step - 1, n - 1)
        T = T + np.einsum('nij,nj->ni', R, dT[i])
        R = R @ dR[i]
        if step in horizons:
            valid = starts + step <= n
            out[step] = 1000.0 * np.linalg.norm(T[valid] - T_gt[starts[valid] + step], axis=-1)
    return {h: out.get(h, np.zeros(0)) for h in horizons}


def trajectory_errors(dR: np.ndarray, dT: np.ndarray, R_gt: np.ndarray,
                      T_gt: np.ndarray) -> Dict[str, float]:
    """RTE (%), ATE (mm), final error (mm) and distance (m) of one clip accumulated from its
    first ground-truth pose."""
    _, T = accumulate(R_gt[0], T_gt[0], dR, dT)
    err = np.linalg.norm(T - T_gt, axis=-1)
    dist = float(np.sum(np.linalg.norm(np.diff(T_gt, axis=0), axis=-1)))
    Rz, t = align_yaw_translation(T, T_gt)
    ate = np.linalg.norm(T @ Rz.T + t - T_gt, axis=-1)
    return {'rte_pct': 100.0 * float(err.mean()) / dist if dist >= RTE_MIN_DISTANCE_M
            else float('nan'),
            'ate_mm': 1000.0 * float(ate.mean()), 'final_mm': 1000.0 * float(err[-1]),
            'distance_m': dist}


def ate_mm(T: np.ndarray, T_gt: np.ndarray) -> float:
    """Mean root error (mm) of a world trajectory after the best 4-DOF alignment."""
    Rz, t = align_yaw_translation(T, T_gt)
    return 1000.0 * float(np.linalg.norm(T @ Rz.T + t - T_gt, axis=-1).mean())
