"""Accuracy and plausibility metrics of 3D motion (no ROS). Positions in metres; the
functions return millimetres where the name says ``_mm``.

* MPJPE: mean per-joint position error after aligning the roots (pelvis);
* N-MPJPE: MPJPE after the least-squares scale of the root-aligned prediction;
* PA-MPJPE: MPJPE after a per-frame similarity Procrustes alignment;
* MRPE: mean root position error in the camera frame;
* MBLE: mean bone-length error;
* acceleration error: mean |second difference| error of joint positions (mm/frame^2);
* foot skating: mean horizontal speed of contact points during labelled contact.
"""

from __future__ import annotations

import numpy as np

from .skeleton import PARENTS


def _root_aligned(p: np.ndarray) -> np.ndarray:
    return p - p[..., :1, :]


def mpjpe_mm(pred: np.ndarray, gt: np.ndarray) -> float:
    """(..., J, 3) positions -> root-aligned MPJPE (mm)."""
    return float(1000 * np.linalg.norm(_root_aligned(pred) - _root_aligned(gt), axis=-1).mean())


def n_mpjpe_mm(pred: np.ndarray, gt: np.ndarray) -> float:
    """Scale-aligned MPJPE (mm): per frame, the scale minimising the error is applied."""
    p, g = _root_aligned(pred), _root_aligned(gt)
    scale = (p * g).sum(axis=(-1, -2), keepdims=True) / \
        np.maximum((p * p).sum(axis=(-1, -2), keepdims=True), 1e-12)
    return float(1000 * np.linalg.norm(scale * p - g, axis=-1).mean())


def _umeyama(pred: np.ndarray, gt: np.ndarray):
    """Per-frame least-squares similarity of (N, J, 3) ``pred`` onto ``gt``: (rotation
    (N, 3, 3) ``r`` with ``p @ r`` onto ``g``, scale (N,), centroids (N, 1, 3) of pred and
    gt)."""
    mp, mg = pred.mean(axis=1, keepdims=True), gt.mean(axis=1, keepdims=True)
    p, g = pred - mp, gt - mg
    h = np.einsum('nji,njk->nik', p, g)
    u, s, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.einsum('nij,njk->nik', u, vt)))
    fix = np.ones_like(s)
    fix[:, -1] = d
    r = np.einsum('nij,nj,njk->nik', u, fix, vt)  # p @ r maps onto g
    scale = (s * fix).sum(axis=1) / np.maximum((p ** 2).sum(axis=(1, 2)), 1e-12)
    return r, scale, mp, mg


def procrustes_align(pred: np.ndarray, gt: np.ndarray, scale: bool = True) -> np.ndarray:
    """Per-frame similarity transform of (N, J, 3) ``pred`` onto ``gt`` (Umeyama); with
    ``scale`` False a rigid one (rotation and translation only)."""
    r, s, mp, mg = _umeyama(pred, gt)
    if not scale:
        s = np.ones_like(s)
    return s[:, None, None] * np.einsum('nji,nik->njk', pred - mp, r) + mg


def alignment_angle_deg(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """(N,) angle (degrees) of the rotation that best aligns each frame of (N, J, 3)
    ``pred`` with ``gt``: the error of the body's global orientation."""
    r = _umeyama(pred, gt)[0]
    cos = (np.trace(r, axis1=1, axis2=2) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def twist_angle_deg(pred: np.ndarray, gt: np.ndarray, axis) -> np.ndarray:
    """(N,) signed angle (degrees, right-handed about ``axis``) of the twist about the unit
    (3,) ``axis`` of the rotation that best aligns each frame of (N, J, 3) ``pred`` with
    ``gt`` (the swing-twist split of :func:`alignment_angle_deg`'s rotation). With camera-frame
    poses and the optical x axis this is the body's tilt toward or away from the camera: the
    part of the orientation a camera's pitch hides from the 2D keypoints."""
    from .rotations import matrix_to_quat
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    q = matrix_to_quat(np.transpose(_umeyama(pred, gt)[0], (0, 2, 1)))   # x, y, z, w; g ~ r p
    # the vector part's projection on the axis and w give the twist (near 180 deg the twist
    # is ill-defined; those frames give about +-180)
    return np.degrees(2.0 * np.arctan2(q[:, :3] @ a, q[:, 3]))


def rotate_about_root(points: np.ndarray, axis, angle_deg) -> np.ndarray:
    """(N, J, 3) ``points`` rotated about their root joint by (N,) or scalar ``angle_deg``
    (right-handed) about the (3,) ``axis``."""
    from .rotations import axis_angle_to_matrix
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    ang = np.broadcast_to(np.radians(np.asarray(angle_deg, dtype=np.float64)), (len(points),))
    rot = axis_angle_to_matrix(ang[:, None] * a)
    root = points[:, :1]
    return np.einsum('nij,nkj->nki', rot, points - root) + root


def pa_mpjpe_mm(pred: np.ndarray, gt: np.ndarray) -> float:
    """Procrustes-aligned MPJPE (mm)."""
    p = pred.reshape(-1, *pred.shape[-2:])
    g = gt.reshape(-1, *gt.shape[-2:])
    return float(1000 * np.linalg.norm(procrustes_align(p, g) - g, axis=-1).mean())


def mrpe_mm(pred_root: np.ndarray, gt_root: np.ndarray) -> float:
    """Mean root position error (mm) of (..., 3) roots."""
    return float(1000 * np.linalg.norm(pred_root - gt_root, axis=-1).mean())


def bone_lengths(p: np.ndarray) -> np.ndarray:
    """(..., J, 3) -> (..., J-1) bone lengths from the positions."""
    return np.linalg.norm(p[..., 1:, :] - p[..., list(PARENTS[1:]), :], axis=-1)


def mble_mm(pred: np.ndarray, gt: np.ndarray) -> float:
    """Mean bone-length error (mm)."""
    return float(1000 * np.abs(bone_lengths(pred) - bone_lengths(gt)).mean())


def bone_length_spread_mm(p: np.ndarray) -> float:
    """Largest standard deviation over time of any bone length (mm); 0 for one skeleton."""
    return float(1000 * bone_lengths(p).std(axis=0).max())


def accel_error_mm(pred: np.ndarray, gt: np.ndarray) -> float:
    """Mean error of joint accelerations (second differences along axis 0), mm/frame^2."""
    if len(pred) < 3:
        return float('nan')
    a = np.diff(pred, 2, axis=0) - np.diff(gt, 2, axis=0)
    return float(1000 * np.linalg.norm(a, axis=-1).mean())


def jitter_mm(p: np.ndarray) -> float:
    """Mean magnitude of joint accelerations (mm/frame^2): smoothness without ground truth."""
    if len(p) < 3:
        return float('nan')
    return float(1000 * np.linalg.norm(np.diff(p, 2, axis=0), axis=-1).mean())


def foot_skating_mm(points: np.ndarray, contacts: np.ndarray, up_axis: int) -> float:
    """Mean displacement per frame (mm) of contact points (T, 4, 3) along the two axes other
    than ``up_axis`` while ``contacts`` (T, 4) holds in both frames."""
    if len(points) < 2:
        return float('nan')
    horiz = [a for a in range(3) if a != up_axis]
    step = np.linalg.norm(np.diff(points[..., horiz], axis=0), axis=-1)
    both = contacts[1:].astype(bool) & contacts[:-1].astype(bool)
    return float(1000 * step[both].mean()) if both.any() else float('nan')


def contact_accuracy(pred_prob: np.ndarray, labels: np.ndarray) -> float:
    """Share of (frame, point) contact states predicted right at threshold 0.5."""
    return float(((pred_prob >= 0.5) == labels.astype(bool)).mean())
