"""Input features of the lifter networks from 2D keypoints (no ROS imports).

Per frame (MotioNet §3.3 and §4 with neural PhysCap's canonicalisation, §3.2):

* keypoints are canonicalised with the camera intrinsics, ``((u - cx) / fx, (v - cy) / fy)``
  (:func:`mocap_core.keypoint_geometry.canonicalize`);
* the root keypoint is the midpoint of the two hips (the pelvis of the pipeline skeleton is
  the midpoint of the hip joints); every keypoint is expressed relative to it;
* unseen keypoints (confidence 0) are zeros; the confidences themselves are input channels;
* the root-relative keypoints are divided by the person's 2D scale ``s`` (the RMS distance of
  the seen keypoints from the root, canonical units); ``log s`` is a channel of its own;
* the global 2D velocity of the root keypoint, also divided by ``s``, is appended.

Layout of the (T, C) feature matrix, C = 23*2 + 23 + 2 + 1 = 72: scaled root-relative x, y of
each keypoint (interleaved), the 23 confidences, root velocity x, y, log s. The root keypoint
(canonical, (T, 2)) and the scale (T,) are returned separately: the network predicts the
depth as ``Z = exp(d) / s`` (m), and the root position is ``Z * (root_x, root_y, 1)`` in the
camera optical frame (m).

A frame where a hip is unseen takes the root of the nearest frame where both are seen (the
root keypoint is held, then back-filled), so the root stays defined through short gaps.
"""

from __future__ import annotations

from typing import Dict, Optional, Tuple

import numpy as np

from mocap_core.camera import CameraIntrinsics
from mocap_core.keypoint_geometry import canonicalize
from mocap_core.skeleton import KEYPOINT_INDEX, KEYPOINT_MIRROR, NUM_KEYPOINTS

NUM_FEATURES = NUM_KEYPOINTS * 3 + 3
_LHIP, _RHIP = KEYPOINT_INDEX['left_hip'], KEYPOINT_INDEX['right_hip']


def root_keypoint(canonical: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Root (mid-hip) keypoint per frame from (T, 23, 3) canonical keypoints.

    Returns (T, 2) root and (T,) bool validity (both hips seen in that frame). Invalid frames
    hold the previous valid root (back-filled at the start); all-invalid gives zeros.
    """
    kc = np.asarray(canonical)
    valid = (kc[:, _LHIP, 2] > 0) & (kc[:, _RHIP, 2] > 0)
    root = 0.5 * (kc[:, _LHIP, :2] + kc[:, _RHIP, :2])
    if not valid.any():
        return np.zeros_like(root), valid
    idx = np.where(valid, np.arange(len(kc)), -1)
    idx = np.maximum.accumulate(idx)
    first = int(np.argmax(valid))
    idx[idx < 0] = first
    return root[idx], valid


def person_scale(relative: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """(T,) RMS distance of the seen keypoints from the root ((T, 23, 2) root-relative,
    (T, 23) bool); frames with fewer than 3 seen points hold the previous value (back-filled
    at the start; 0.1 when no frame has enough)."""
    n = seen.sum(axis=-1)
    sq = np.where(seen[..., None], relative ** 2, 0.0).sum(axis=(-1, -2))
    ok = n >= 3
    scale = np.sqrt(sq / np.maximum(n, 1))
    ok &= scale > 1e-6
    if not ok.any():
        return np.full(len(relative), 0.1)
    idx = np.where(ok, np.arange(len(relative)), -1)
    idx = np.maximum.accumulate(idx)
    idx[idx < 0] = int(np.argmax(ok))
    return scale[idx]


def ray_rotations(root_2d: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotations of virtual cameras looking at the person, from the (T, 2)
    canonical root keypoint (camera optical frame: x right, y down, z forward).

    Each is the smallest rotation taking the optical axis (0, 0, 1) onto the root's ray
    ``(x, y, 1) / |(x, y, 1)|`` (no roll about the ray): its third column is that ray and a
    point ``p`` of the virtual camera's frame is ``R @ p`` in the real camera's."""
    r = np.asarray(root_2d, dtype=np.float64)
    d = np.concatenate([r, np.ones(r.shape[:-1] + (1,))], axis=-1)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    # Rodrigues with axis z x d: for a unit axis k and angle a, cos a = d_z, sin a = |z x d|
    c = d[..., 2]
    kx, ky = -d[..., 1], d[..., 0]                      # z x d = (-d_y, d_x, 0)
    one_c = 1.0 / (1.0 + c)                             # (1 - cos a) / sin^2 a, c > -1
    R = np.empty(r.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1.0 - one_c * ky * ky
    R[..., 0, 1] = one_c * kx * ky
    R[..., 0, 2] = d[..., 0]
    R[..., 1, 0] = one_c * kx * ky
    R[..., 1, 1] = 1.0 - one_c * kx * kx
    R[..., 1, 2] = d[..., 1]
    R[..., 2, 0] = -d[..., 0]
    R[..., 2, 1] = -d[..., 1]
    R[..., 2, 2] = c
    return R


def turn_root_orientation(rotations: np.ndarray, rays: np.ndarray,
                          inverse: bool = False) -> np.ndarray:
    """(..., J, 4) rotations (x, y, z, w; row 0 the root's orientation in a camera frame, the
    other rows local) with row 0 turned from the virtual cameras' frames into the real
    camera's by the (..., 3, 3) ``rays`` of :func:`ray_rotations` (``inverse``: from the real
    camera's into the virtual ones). A new array; the local rows are copied unchanged."""
    from mocap_core.rotations import quat_multiply
    d = np.asarray(rays, dtype=np.float64)[..., :, 2]       # the ray: the turn from (0, 0, 1)
    turn = np.stack([-d[..., 1], d[..., 0], np.zeros_like(d[..., 0]), 1.0 + d[..., 2]], -1)
    turn /= np.linalg.norm(turn, axis=-1, keepdims=True)
    if inverse:
        turn[..., :3] *= -1.0
    out = np.array(rotations, dtype=np.float64, copy=True)
    out[..., 0, :] = quat_multiply(turn, out[..., 0, :])
    return out


def to_virtual_camera(canonical: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    """(..., T, K, 3) canonical keypoints (x, y, confidence) seen by the virtual cameras
    ``rotations`` (..., T, 3, 3) of :func:`ray_rotations`: each point's ray ``(x, y, 1)`` is
    expressed in the virtual camera's frame, ``R^T (x, y, 1)``, and projected again.
    Confidences are kept, unseen points (confidence 0) stay (0, 0, 0)."""
    kc = np.asarray(canonical, dtype=np.float64)
    R = np.asarray(rotations, dtype=np.float64)[..., None, :, :]   # per point of the frame
    x, y = kc[..., 0], kc[..., 1]
    # R^T (x, y, 1), written out (a batched 3x3 product is slower in NumPy)
    vx = x * R[..., 0, 0] + y * R[..., 1, 0] + R[..., 2, 0]
    vy = x * R[..., 0, 1] + y * R[..., 1, 1] + R[..., 2, 1]
    vz = np.maximum(x * R[..., 0, 2] + y * R[..., 1, 2] + R[..., 2, 2], 1e-6)
    seen = kc[..., 2] > 0
    out = np.empty_like(kc)
    out[..., 0] = np.where(seen, vx / vz, 0.0)
    out[..., 1] = np.where(seen, vy / vz, 0.0)
    out[..., 2] = kc[..., 2]
    return out


def lifter_features(keypoints: np.ndarray, intr: CameraIntrinsics,
                    virtual_camera: bool = False,
                    ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Features of a keypoint window.

    Args:
        keypoints: (T, 23, 3) pixel u, v and confidence of one person.
        intr: the camera intrinsics of those pixels.
        virtual_camera: take the keypoints as a camera looking at the person would see
            them (:func:`ray_rotations`, :func:`to_virtual_camera`: the person's root is then
            on the optical axis, at (0, 0), and the returned root keypoint is zero); the
            root velocity stays the real camera's. The network's pose is then in that
            virtual camera's frame, which :func:`lifter_features_and_rays` returns.
    Returns:
        features (T, 72) float32, root keypoint (T, 2) canonical, person scale (T,)
        canonical, root validity (T,) bool.
    """
    return lifter_features_and_rays(keypoints, intr, virtual_camera)[:4]


def lifter_features_and_rays(keypoints: np.ndarray, intr: CameraIntrinsics,
                             virtual_camera: bool = False,
                             ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                        Optional[np.ndarray]]:
    """:func:`lifter_features` and, with ``virtual_camera``, the (T, 3, 3) rotations of the
    virtual cameras (:func:`ray_rotations`; a point of a virtual camera's frame is ``R @ p``
    in the real camera's), else None."""
    kp = np.asarray(keypoints, dtype=np.float64)
    if kp.ndim != 3 or kp.shape[1:] != (NUM_KEYPOINTS, 3):
        raise ValueError(f'keypoints must have shape (T, {NUM_KEYPOINTS}, 3), got {kp.shape}')
    kc = canonicalize(kp, intr)
    root, valid = root_keypoint(kc)
    vel = np.zeros_like(root)
    vel[1:] = root[1:] - root[:-1]
    rays = None
    if virtual_camera:
        rays = ray_rotations(root)
        kc = to_virtual_camera(kc, rays)
        root = np.zeros_like(root)
    seen = kc[..., 2] > 0
    rel = np.where(seen[..., None], kc[..., :2] - root[:, None, :], 0.0)
    scale = person_scale(rel, seen)
    feats = np.concatenate([(rel / scale[:, None, None]).reshape(len(kp), -1), kc[..., 2],
                            vel / scale[:, None], np.log(scale)[:, None]], axis=1)
    return feats.astype(np.float32), root, scale, valid, rays


def virtual_camera_window(window: Dict[str, np.ndarray]) -> Dict[str, np.ndarray]:
    """A training window (features in the real camera, :func:`lifter_features`) as the
    virtual cameras looking at the person see it: the features of
    ``lifter_features(..., virtual_camera=True)`` and the targets turned into those cameras'
    frames.

    ``window`` holds ``features`` (..., T, 72), ``root_2d`` (..., T, 2) and ``scale``
    (..., T) and, when present, the camera-frame targets ``positions`` (..., T, J, 3),
    ``root`` (..., T, 3) and ``rotations`` (..., T, J, 4) (x, y, z, w; row 0 the root's
    orientation in the camera frame; the other rows are local and stay). Other entries are
    copied. Returns a new dict; ``root_2d`` becomes zero, as the network sees it then."""
    n = NUM_KEYPOINTS
    f = np.asarray(window['features'], dtype=np.float64)
    root = np.asarray(window['root_2d'], dtype=np.float64)
    scale = np.asarray(window['scale'], dtype=np.float64)
    rel = f[..., :2 * n].reshape(f.shape[:-1] + (n, 2)) * scale[..., None, None]
    conf = f[..., 2 * n:3 * n]
    seen = conf > 0
    kc = np.concatenate([np.where(seen[..., None], rel + root[..., None, :], 0.0),
                         conf[..., None]], axis=-1)
    R = ray_rotations(root)
    kv = to_virtual_camera(kc, R)
    lead = f.shape[:-2]
    rel_v = kv[..., :2].reshape((-1,) + kv.shape[-3:-1] + (2,))
    s_v = np.stack([person_scale(r, m) for r, m in
                    zip(rel_v, seen.reshape((-1,) + seen.shape[-2:]))]).reshape(scale.shape)
    out = dict(window)
    dtype = np.asarray(window['features']).dtype
    feats = f.copy()
    feats[..., :2 * n] = (kv[..., :2] / s_v[..., None, None]).reshape(lead + (-1, 2 * n))
    feats[..., 3 * n + 2] = np.log(s_v)
    out['features'] = feats.astype(dtype)
    out['root_2d'] = np.zeros_like(np.asarray(window['root_2d']))
    out['scale'] = s_v.astype(np.asarray(window['scale']).dtype)
    Rt = np.swapaxes(R, -1, -2)
    if 'positions' in window:
        pos = np.asarray(window['positions'], dtype=np.float64)
        out['positions'] = np.einsum('...ij,...kj->...ki', Rt, pos).astype(
            np.asarray(window['positions']).dtype)
    if 'root' in window:
        out['root'] = np.einsum('...ij,...j->...i', Rt, np.asarray(
            window['root'], dtype=np.float64)).astype(np.asarray(window['root']).dtype)
    if 'rotations' in window:
        out['rotations'] = turn_root_orientation(window['rotations'], R, inverse=True).astype(
            np.asarray(window['rotations']).dtype)
    return out


def mirror_features(features: np.ndarray, root_2d: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """The features (..., T, 72) and canonical root keypoint (..., T, 2) of the left-right
    mirrored image (canonical x -> -x about the principal point, left and right keypoints
    exchanged), in the layout of :func:`lifter_features`. For test-time flip augmentation."""
    f = np.array(features, copy=True)
    n = NUM_KEYPOINTS
    mirror = list(KEYPOINT_MIRROR)
    rel = f[..., :2 * n].reshape(f.shape[:-1] + (n, 2))[..., mirror, :]
    rel[..., 0] *= -1
    f[..., :2 * n] = rel.reshape(f.shape[:-1] + (2 * n,))
    f[..., 2 * n:3 * n] = f[..., 2 * n:3 * n][..., mirror]
    f[..., 3 * n] *= -1                                   # root velocity, x
    r = np.array(root_2d, copy=True)
    r[..., 0] *= -1
    return f, r


def unmirror_rotations(rotations: np.ndarray) -> np.ndarray:
    """Local rotations (..., J, 4) x, y, z, w lifted from a mirrored image (root row in the
    camera optical frame) -> the rotations of the unmirrored pose: joints exchanged left and
    right, the camera frame reflected in x and the body frame in y (its left axis)."""
    from mocap_core.rotations import matrix_to_quat, quat_to_matrix
    from mocap_core.skeleton import JOINT_MIRROR
    R = np.asarray(quat_to_matrix(np.asarray(rotations, dtype=np.float64)))
    R = R[..., list(JOINT_MIRROR), :, :]
    cam = np.diag([-1.0, 1.0, 1.0])
    body = np.diag([1.0, -1.0, 1.0])
    out = body @ R @ body
    out[..., 0, :, :] = cam @ R[..., 0, :, :] @ body
    return np.asarray(matrix_to_quat(out))


def average_quaternions(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Half-way rotation of two arrays of unit quaternions (same hemisphere first)."""
    sign = np.where(np.sum(a * b, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    q = a + sign * b
    return q / np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), 1e-12)


def smooth_keypoints(keypoints: np.ndarray, sigma: float) -> np.ndarray:
    """Zero-phase Gaussian smoothing of (T, 23, 3) keypoints along time (``sigma`` in frames;
    0 returns them unchanged). Each point's u, v are confidence-weighted averages over the
    frames where it was seen; confidences are kept; unseen points stay (0, 0, 0). The window
    is truncated at the ends of the sequence (one-sided there)."""
    kp = np.asarray(keypoints, dtype=np.float64)
    if sigma <= 0 or len(kp) < 2:
        return kp.copy()
    r = int(np.ceil(3 * sigma))
    t = np.arange(-r, r + 1)
    w = np.exp(-0.5 * (t / sigma) ** 2)
    c = kp[..., 2]
    T = len(kp)
    num = np.zeros(kp.shape[:-1] + (2,))
    den = np.zeros(kp.shape[:-1])
    for k, wk in zip(t, w):
        lo, hi = max(0, -k), min(T, T - k)            # frames i with i + k inside
        cw = wk * c[lo + k:hi + k]
        num[lo:hi] += cw[..., None] * kp[lo + k:hi + k, :, :2]
        den[lo:hi] += cw
    out = kp.copy()
    seen = (c > 0) & (den > 0)
    out[..., :2] = np.where(seen[..., None], num / np.maximum(den, 1e-12)[..., None],
                            kp[..., :2])
    return out
