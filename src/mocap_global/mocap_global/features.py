"""GMR input features, body-frame joint positions, mirroring and input noise (no ROS imports).

Input of the network per frame (§3.1; C = :func:`num_features` values, float32):

* the local pose, either (``pose_input='quat'``, the paper's, §4.4 Table 1) the local
  rotations of the 17 non-root joints relative to their parents as unit quaternions
  (x, y, z, w) in the ``w >= 0`` hemisphere (one code per rotation), 68 values, or
  (``'positions'``, the shipped configuration) the 17 non-root joint positions in the root's
  own frame (root at the origin, identity orientation; m) by forward kinematics of those
  rotations with the skeleton, 51 values. The root's global orientation is never an input
  (§4.1): it is expressed in the camera frame, which moves;
* with ``skeleton_input``: the skeleton's 10 bone-group lengths (m);
* with ``root_input='up'`` (not shipped): the world's up direction in the root's frame,
  ``R^T e_z`` (3 values), which needs the up direction of the input's frame at run time.
  With ``'none'`` (the paper's input) the model estimates this vector as an extra output.

Also here: :func:`body_joint_positions` (the root-frame joints used by the features, the
joint-motion loss and metric), left/right mirroring of motions (y -> -y) and the lifter-like
noise model of the training augmentation and the evaluation. The reasons for the choices
beyond the paper: ``docs/global.md``.
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from mocap_core.kinematics import forward_kinematics
from mocap_core.rotations import axis_angle_to_quat, quat_canonical, quat_multiply
from mocap_core.skeleton import (JOINT_MIRROR, NUM_BONE_GROUPS, NUM_JOINTS, PARENTS,
                                 REST_DIRECTIONS, group_lengths_to_bone_lengths)

ROOT_INPUTS = ('none', 'up')
POSE_INPUTS = ('quat', 'positions')
NUM_POSE_FEATURES = 4 * (NUM_JOINTS - 1)
NUM_POSITION_FEATURES = 3 * (NUM_JOINTS - 1)


def pose_dims(pose_input: str = 'quat') -> int:
    """Channels of the local-pose part of the input."""
    if pose_input not in POSE_INPUTS:
        raise ValueError(f'pose_input must be one of {POSE_INPUTS}, got {pose_input!r}')
    return NUM_POSE_FEATURES if pose_input == 'quat' else NUM_POSITION_FEATURES


def num_features(root_input: str = 'none', skeleton_input: bool = True,
                 pose_input: str = 'quat') -> int:
    """Input channels for the input options (module docstring)."""
    if root_input not in ROOT_INPUTS:
        raise ValueError(f'root_input must be one of {ROOT_INPUTS}, got {root_input!r}')
    return (pose_dims(pose_input) + (NUM_BONE_GROUPS if skeleton_input else 0)
            + (3 if root_input == 'up' else 0))


def features_for(cfg, rotations: np.ndarray, group_lengths: np.ndarray,
                 up: Optional[np.ndarray] = None) -> np.ndarray:
    """:func:`gmr_features` with the input options of a :class:`~.model.GMRConfig`."""
    return gmr_features(rotations, group_lengths, up, cfg.root_input, cfg.skeleton_input,
                        cfg.pose_input)


def gmr_features(rotations: np.ndarray, group_lengths: np.ndarray,
                 up: Optional[np.ndarray] = None, root_input: str = 'none',
                 skeleton_input: bool = True, pose_input: str = 'quat') -> np.ndarray:
    """Per-frame network input (module docstring).

    Args:
        rotations: (..., F, J, 4) local quaternions (row 0, the root, is ignored).
        group_lengths: (..., 10) or (..., F, 10) bone-group lengths, m.
        up: (..., F, 3) up direction in the root frame (only for ``root_input='up'``).
        skeleton_input: include the bone-group lengths (False: the paper's input).
        pose_input: 'quat' (the paper's) or 'positions' (the joints in the root frame).
    Returns:
        (..., F, C) float32.
    """
    rot = np.asarray(rotations, dtype=np.float64)
    if rot.shape[-2:] != (NUM_JOINTS, 4):
        raise ValueError(f'rotations must have shape (..., F, {NUM_JOINTS}, 4), '
                         f'got {rot.shape}')
    gl = np.asarray(group_lengths, dtype=np.float64)
    if gl.shape[-1] != NUM_BONE_GROUPS:
        raise ValueError(f'expected {NUM_BONE_GROUPS} bone-group lengths, got {gl.shape}')
    if pose_input == 'quat':
        q = quat_canonical(rot[..., 1:, :])
        q = q.reshape(q.shape[:-2] + (NUM_POSE_FEATURES,))
    elif pose_input == 'positions':
        offsets = REST_DIRECTIONS * group_lengths_to_bone_lengths(gl)[..., None]
        if gl.ndim == rot.ndim - 2:          # one skeleton per sequence
            offsets = offsets[..., None, :, :]
        q = body_joint_positions(offsets, rot, per_frame_offsets=True)[..., 1:, :]
        q = q.reshape(q.shape[:-2] + (NUM_POSITION_FEATURES,))
    else:
        raise ValueError(f'pose_input must be one of {POSE_INPUTS}, got {pose_input!r}')
    if gl.ndim == q.ndim - 1:
        gl = gl[..., None, :]
    gl = np.broadcast_to(gl, q.shape[:-1] + (NUM_BONE_GROUPS,))
    parts = [q, gl] if skeleton_input else [q]
    if root_input == 'up':
        if up is None:
            raise ValueError("root_input='up' needs the up direction in the root frame")
        parts.append(np.broadcast_to(np.asarray(up, dtype=np.float64),
                                     q.shape[:-1] + (3,)))
    elif root_input != 'none':
        raise ValueError(f'root_input must be one of {ROOT_INPUTS}, got {root_input!r}')
    return np.concatenate(parts, axis=-1).astype(np.float32)


def body_joint_positions(offsets: np.ndarray, rotations: np.ndarray,
                         per_frame_offsets: bool = False) -> np.ndarray:
    """Joint positions (..., F, J, 3) in the root's own frame (root at the origin, identity
    root orientation) from local rotations (..., F, J, 4) and bone offsets (J, 3) or
    (..., J, 3) (broadcast over frames). The joint-motion loss and metric use them in place
    of the SMPL mesh of the paper (S3 eq. 13, S4 eq. 17). ``per_frame_offsets``: the offsets
    already broadcast against the frames (..., F or 1, J, 3)."""
    rot = np.array(rotations, dtype=np.float64)
    rot[..., 0, :] = (0.0, 0.0, 0.0, 1.0)
    off = np.asarray(offsets, dtype=np.float64)
    if off.ndim > 2 and not per_frame_offsets:
        off = off[..., None, :, :]
    zero = np.zeros(rot.shape[:-2] + (3,))
    return forward_kinematics(PARENTS, off, rot, zero).positions


# ---------------------------------------------------------------------------------------------
# mirroring (left <-> right), for augmentation
# ---------------------------------------------------------------------------------------------
_S = np.diag([1.0, -1.0, 1.0])


def mirror_rotations(rotations: np.ndarray) -> np.ndarray:
    """Reflect a motion through the body's sagittal plane (y -> -y): every rotation R becomes
    S R S (quaternion (-x, y, -z, w)) and left and right joints swap. Valid for the pipeline
    skeleton, whose rest pose is left/right symmetric. (..., J, 4) -> (..., J, 4)."""
    q = np.asarray(rotations, dtype=np.float64)[..., list(JOINT_MIRROR), :]
    return q * np.array([-1.0, 1.0, -1.0, 1.0])


def mirror_vectors(v: np.ndarray) -> np.ndarray:
    """Reflect (..., 3) vectors (positions, translations, up vectors): y -> -y."""
    return np.asarray(v, dtype=np.float64) * np.array([1.0, -1.0, 1.0])


# ---------------------------------------------------------------------------------------------
# lifter-like noise on the local pose
# ---------------------------------------------------------------------------------------------
#: Default noise of the "lifter-like" evaluation condition (an assumption, not fitted to a
#: lifter): per joint and axis a slowly varying error (Gaussian-filtered white noise with a
#: correlation of 5 frames at 30 fps, std 8 deg) plus frame-to-frame jitter (std 2 deg), and a
#: per-clip bone-length error of 3 % per bone group.
NOISE_SMOOTH_DEG = 8.0
NOISE_JITTER_DEG = 2.0
NOISE_CORRELATION_S = 5.0 / 30.0
NOISE_LENGTH_REL = 0.03


def _smooth_noise(rng: np.random.Generator, shape, sigma_frames: float) -> np.ndarray:
    """White noise along axis 0 filtered by a Gaussian of ``sigma_frames``, unit std."""
    n = shape[0]
    if sigma_frames < 0.5:
        return rng.standard_normal(shape)
    r = int(np.ceil(3 * sigma_frames))
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma_frames) ** 2)
    k /= np.sqrt(np.sum(k ** 2))          # keeps unit variance
    w = rng.standard_normal((n + 2 * r,) + tuple(shape[1:]))
    out = np.zeros(shape)
    for i, kv in enumerate(k):
        out += kv * w[i:i + n]
    return out


def noisy_local_pose(rotations: np.ndarray, rng: np.random.Generator, fps: float = 30.0,
                     smooth_deg: float = NOISE_SMOOTH_DEG, jitter_deg: float = NOISE_JITTER_DEG,
                     correlation_s: float = NOISE_CORRELATION_S) -> np.ndarray:
    """Lifter-like errors on the non-root local rotations of (F, J, 4) quaternions: each joint
    is rotated by a random rotation vector (slow part + jitter, see the constants above).
    The root row is unchanged."""
    rot = np.array(rotations, dtype=np.float64)
    f, j = rot.shape[:2]
    v = (np.radians(smooth_deg) * _smooth_noise(rng, (f, j - 1, 3), correlation_s * fps)
         + np.radians(jitter_deg) * rng.standard_normal((f, j - 1, 3)))
    rot[:, 1:] = quat_multiply(rot[:, 1:], axis_angle_to_quat(v))
    return rot


def noisy_lengths(group_lengths: np.ndarray, rng: np.random.Generator,
                  rel: float = NOISE_LENGTH_REL) -> np.ndarray:
    """Bone-group lengths with a relative error of std ``rel`` each."""
    gl = np.asarray(group_lengths, dtype=np.float64)
    return gl * (1.0 + rel * rng.standard_normal(gl.shape))
