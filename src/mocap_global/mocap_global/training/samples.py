"""Training windows for GMR with their targets and augmentations (no ROS imports).

A window is up to ``window`` consecutive frames of one clip at the model's frame rate (30 fps
clips are subsampled with a random phase for a 10 fps model, as the paper trains at 10 fps,
§4.1). Clips shorter than the window, and a share of deliberately shortened windows (the node
starts with short windows), are padded; the padding is masked in the losses.

Augmentations (:class:`Augmentation`):

* flip augmentation (§3.5): the sequence is reversed in time; the targets follow, the motions
  of the reversed sequence being the inverted motions in reverse order;
* beyond the paper: left/right mirroring (the skeleton is symmetric), a global body scale
  (bone lengths and trajectory together), and lifter-like noise on the input local pose and
  bone lengths (:func:`mocap_global.features.noisy_local_pose`) for robustness to estimated
  poses;
* time scale: a share of the windows (``time_scale_prob``) plays the clip slower or faster,
  at a playback speed drawn log-uniformly from ``time_scale_range`` (0.5 = half speed, as a
  slow-motion video or a slow walker shows it). The frames are interpolated (slerp for the
  rotations, linear for the root) at the fractional clip positions, the input's as well as
  the targets', so every step of the root moves with the legs that make it. Without it a
  slow gait reads as standing (``docs/global.md``, the real walk).

Targets: ``dR`` (T-1, 3, 3), ``dT`` (T-1, 3) global motions (:mod:`mocap_global.se3`),
``up`` (T, 3) the world's up direction in the root frame, ``joints`` (T, J, 3) joint positions
in the root frame (for the joint-motion loss).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from mocap_core.data.motion import Motion, frames_at
from mocap_core.rotations import quat_to_matrix
from mocap_core.skeleton import NUM_JOINTS

from .. import features as F
from ..se3 import relative_motion, up_in_body


@dataclass
class Augmentation:
    """Probabilities and ranges of the augmentations (module docstring)."""

    reverse_prob: float = 0.5
    mirror_prob: float = 0.5
    scale_range: float = 0.1
    noise_prob: float = 0.5
    noise_level: float = 1.0      # maximum, in units of the lifter-like noise defaults
    short_prob: float = 0.15
    min_length: int = 8
    #: share of windows whose input is the shipped lifter's output of the clip (given to the
    #: sampler as ``lifted``, :mod:`mocap_global.training.lifted`) instead of the ground truth
    lifted_prob: float = 0.0
    #: share of windows played at another speed, and the (slowest, fastest) playback speed
    time_scale_prob: float = 0.0
    time_scale_range: Tuple[float, float] = (0.5, 1.5)

    def __post_init__(self) -> None:
        lo, hi = (float(v) for v in self.time_scale_range)
        if not 0.0 < lo <= hi:
            raise ValueError(f'time_scale_range must be 0 < slowest <= fastest, got '
                             f'{self.time_scale_range}')
        self.time_scale_range = (lo, hi)

    @classmethod
    def none(cls) -> 'Augmentation':
        return cls(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, lifted_prob=0.0)


def frame_step(source_fps: float, fps: float) -> int:
    """Subsampling step from the data rate to the model rate (an integer)."""
    step = source_fps / fps
    if abs(step - round(step)) > 1e-6 or round(step) < 1:
        raise ValueError(f'model rate {fps} fps must divide the data rate {source_fps} fps')
    return int(round(step))


class WindowSampler:
    """Random windows of a set of clips (module docstring)."""

    def __init__(self, motions: Sequence[Motion], window: int, fps: float = 30.0,
                 seed: int = 0, aug: Augmentation = Augmentation(),
                 root_input: str = 'none', skeleton_input: bool = True,
                 pose_input: str = 'quat', lifted: Optional[Sequence] = None) -> None:
        """``lifted``: per clip of ``motions`` a :class:`~.lifted.LiftedClip` (the lifter's
        local poses, frame-aligned), used for ``aug.lifted_prob`` of the windows."""
        if not motions:
            raise ValueError('no clips to sample from')
        self.window = int(window)
        self.fps = float(fps)
        self.step = frame_step(motions[0].fps, fps)
        self.aug = aug
        self.root_input = root_input
        self.skeleton_input = skeleton_input
        self.pose_input = pose_input
        self.rng = np.random.default_rng(seed)
        ok = [(m.num_frames - 1) // self.step + 1 >= 3 for m in motions]
        keep = [m for m, k in zip(motions, ok) if k]
        if not keep:
            raise ValueError('every clip is too short')
        self.lifted_rot: Optional[np.ndarray] = None
        if lifted is not None:
            if len(lifted) != len(motions):
                raise ValueError('lifted: one entry per clip')
            lk = [c for c, k in zip(lifted, ok) if k]
            if any(c.rotations.shape[1] != m.num_frames for c, m in zip(lk, keep)):
                raise ValueError('lifted poses are not frame-aligned with their clips')
            self.lifted_rot = np.concatenate([c.rotations for c in lk], axis=1)  # (C, N, J, 4)
            self.lifted_lengths = np.stack([c.lengths for c in lk])              # (clips, C, G)
        self.lengths = np.array([m.num_frames for m in keep])
        self.offsets = np.concatenate([[0], np.cumsum(self.lengths)])
        self.rotations = np.concatenate([m.rotations for m in keep]).astype(np.float32)
        self.roots = np.concatenate([m.root_positions for m in keep]).astype(np.float32)
        self.group_lengths = np.stack([m.skeleton.group_lengths() for m in keep])
        self.bone_offsets = np.stack([m.skeleton.offsets for m in keep])
        self.prob = self.lengths / self.lengths.sum()

    def sample(self) -> Dict[str, np.ndarray]:
        """One augmented window (unpadded)."""
        rng, aug = self.rng, self.aug
        c = int(rng.choice(len(self.lengths), p=self.prob))
        speed = 1.0
        if aug.time_scale_prob > 0 and rng.random() < aug.time_scale_prob:
            lo, hi = np.log(aug.time_scale_range)
            speed = float(np.exp(rng.uniform(lo, hi)))
        stride = self.step * speed                  # clip frames per model frame
        phase = int(rng.integers(0, self.step)) if self.lengths[c] > 2 * self.step else 0
        avail = int(np.floor((self.lengths[c] - 1 - phase) / stride + 1e-9)) + 1
        t = min(self.window, avail)
        if rng.random() < aug.short_prob and t > aug.min_length:
            t = int(rng.integers(aug.min_length, t + 1))
        s = int(rng.integers(0, avail - t + 1))
        at = phase + stride * (s + np.arange(t))    # fractional frame of the clip
        first, last = self.offsets[c], self.offsets[c + 1]
        gl = self.group_lengths[c].copy()
        off = self.bone_offsets[c].copy()
        use_lifted = (self.lifted_rot is not None and aug.lifted_prob > 0
                      and rng.random() < aug.lifted_prob)
        cam = int(rng.integers(self.lifted_rot.shape[0])) if use_lifted else 0
        if speed == 1.0:
            idx = first + np.round(at).astype(np.int64)
            rot = self.rotations[idx].astype(np.float64)
            root = self.roots[idx].astype(np.float64)
            rot_l = self.lifted_rot[cam, idx].astype(np.float64) if use_lifted else None
        else:
            rot, root = frames_at(self.rotations[first:last],
                                           self.roots[first:last], at)
            rot_l = (frames_at(self.lifted_rot[cam, first:last], None, at)[0]
                     if use_lifted else None)
        lifted = None
        if use_lifted:
            lifted = (rot_l, self.lifted_lengths[c, cam].astype(np.float64))
        sc = 1.0
        if aug.scale_range > 0:
            sc = 1.0 + aug.scale_range * (2.0 * rng.random() - 1.0)
            gl, off, root = gl * sc, off * sc, root * sc
        mirror = rng.random() < aug.mirror_prob
        if mirror:
            rot, root = F.mirror_rotations(rot), F.mirror_vectors(root)
        reverse = rng.random() < aug.reverse_prob
        if reverse:
            rot, root = rot[::-1].copy(), root[::-1].copy()
        rot_in, gl_in = rot, gl
        if lifted is not None:
            # the lifter's view of the same frames, through the same mirror and time reversal
            rot_in, gl_in = lifted[0], lifted[1] * sc
            if mirror:
                rot_in = F.mirror_rotations(rot_in)
            if reverse:
                rot_in = rot_in[::-1].copy()
        elif aug.noise_prob > 0 and rng.random() < aug.noise_prob:
            level = aug.noise_level * rng.random()
            rot_in = F.noisy_local_pose(rot, rng, self.fps, F.NOISE_SMOOTH_DEG * level,
                                        F.NOISE_JITTER_DEG * level,
                                        F.NOISE_CORRELATION_S)
            gl_in = F.noisy_lengths(gl, rng, F.NOISE_LENGTH_REL * level)
        return {'rot': rot, 'rot_in': rot_in, 'root': root, 'lengths_in': gl_in,
                'offsets': off}

    def batch(self, size: int) -> Dict[str, np.ndarray]:
        """``size`` windows padded to the longest: see :func:`collate`."""
        return collate([self.sample() for _ in range(size)], self.root_input,
                       self.skeleton_input, self.pose_input)


def collate(samples: List[Dict[str, np.ndarray]], root_input: str = 'none',
            skeleton_input: bool = True, pose_input: str = 'quat') -> Dict[str, np.ndarray]:
    """Pad samples and compute inputs and targets for the whole batch at once.

    Returns float32 arrays: ``features`` (B, T, C), ``dR`` (B, T-1, 3, 3), ``dT`` (B, T-1, 3),
    ``up`` (B, T, 3), ``joints`` (B, T, J, 3); ``lengths`` (B,) int64; ``motion_mask``
    (B, T-1) and ``frame_mask`` (B, T) bool."""
    b = len(samples)
    t = max(len(s['rot']) for s in samples)
    rot = np.zeros((b, t, NUM_JOINTS, 4))
    rot[..., 3] = 1.0
    rot_in = rot.copy()
    root = np.zeros((b, t, 3))
    lengths = np.array([len(s['rot']) for s in samples], dtype=np.int64)
    for i, s in enumerate(samples):
        n = lengths[i]
        rot[i, :n], rot_in[i, :n], root[i, :n] = s['rot'], s['rot_in'], s['root']
        rot[i, n:], rot_in[i, n:], root[i, n:] = s['rot'][-1], s['rot_in'][-1], s['root'][-1]
    R = quat_to_matrix(rot[:, :, 0])
    dR, dT = relative_motion(R, root)
    up = up_in_body(R)
    gl_in = np.stack([s['lengths_in'] for s in samples])
    offsets = np.stack([s['offsets'] for s in samples])
    joints = F.body_joint_positions(offsets, rot)
    feats = F.gmr_features(rot_in, gl_in, up if root_input == 'up' else None, root_input,
                           skeleton_input, pose_input)
    frame_mask = np.arange(t)[None] < lengths[:, None]
    return {'features': feats, 'dR': dR.astype(np.float32), 'dT': dT.astype(np.float32),
            'up': up.astype(np.float32), 'joints': joints.astype(np.float32),
            'lengths': lengths, 'frame_mask': frame_mask,
            'motion_mask': frame_mask[:, 1:]}
