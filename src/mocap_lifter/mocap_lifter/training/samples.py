"""Training and evaluation samples for the lifter from processed motion capture (no ROS).

A sample is a window of one clip seen by a random virtual camera (MotioNet §4): the motion
is optionally mirrored (left-right flip) and given a randomly scaled symmetric skeleton (bone
length augmentation), the 23 keypoints are projected by a random camera that keeps the
subject in view (camera augmentation: distance, height, azimuth, field of view, image size),
and corrupted with the confidence model fitted on real detections. Targets are expressed in
that camera's optical frame (x right, y down, z forward), metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence

import numpy as np

from mocap_core.data.motion import Motion
from mocap_core.data.synth2d import (CameraSampling, ConfidenceModel, Corruption,
                                     corrupt_keypoints, keypoints_3d, mirror_keypoints,
                                     mirror_motion, motion_to_camera, project, sample_camera)
from mocap_core.rotations import quat_rotate
from mocap_core.kinematics import forward_kinematics
from mocap_core.skeleton import (CONTACT_MIRROR, JOINT_INDEX, JOINT_MIRROR, NUM_BONE_GROUPS,
                                 Skeleton)

from ..features import (lifter_features, mirror_features, smooth_keypoints,
                        unmirror_rotations)

_LEG = [JOINT_INDEX['left_knee'], JOINT_INDEX['left_ankle']]


@dataclass
class Augmentation:
    """Random variations applied to each training window."""

    flip_prob: float = 0.5
    bone_scale: float = 0.08       # per bone group, uniform +-
    global_scale: float = 0.10     # whole body, uniform +-
    camera: CameraSampling = field(default_factory=CameraSampling)
    corruption: Optional[Corruption] = field(default_factory=Corruption)  # None = clean
    clean_prob: float = 0.0        # share of windows left uncorrupted (confidence 1)
    tpose_prob: float = 0.0        # share of windows replaced by the character's T-pose
    #: keypoints placed where the real detector puts them (``mocap_core.data.
    #: detector_placement``) in this share of windows; the rest on the joints.
    placement: Optional[object] = None
    placement_prob: float = 0.0
    #: temporal smoothing of the keypoints before the features (frames; see
    #: ``features.smooth_keypoints``), as the node applies it with ``smooth_sigma``
    smooth: float = 0.0


def scaled_skeleton(skeleton: Skeleton, rng: np.random.Generator, aug: Augmentation,
                    ) -> Skeleton:
    """A symmetric skeleton with randomly scaled bone groups."""
    scale = (1.0 + rng.uniform(-aug.global_scale, aug.global_scale)) * \
        (1.0 + rng.uniform(-aug.bone_scale, aug.bone_scale, NUM_BONE_GROUPS))
    return Skeleton.from_group_lengths(skeleton.group_lengths() * scale)


def make_sample(motion: Motion, start: int, length: int, rng: np.random.Generator,
                aug: Augmentation) -> Dict[str, np.ndarray]:
    """One window as arrays: ``features`` (T, 72), ``root_2d`` (T, 2), ``scale`` (T,), and
    targets in the
    camera frame: ``positions`` (T, J, 3), ``rotations`` (T, J, 4), ``root`` (T, 3),
    ``lengths`` (G,), ``contacts`` (T, 4) float; plus ``keypoints`` (T, 23, 3) pixels and
    ``tpose`` (1.0 for a T-pose window, see :func:`tpose_window`)."""
    rot = motion.rotations[start:start + length]
    root = motion.root_positions[start:start + length]
    contacts = motion.contacts[start:start + length].astype(np.float32)
    skeleton = motion.skeleton
    if rng.random() < aug.flip_prob:
        rot, root = mirror_motion(rot, root)
        contacts = contacts[:, [2, 3, 0, 1]]  # left <-> right heel/toe
    if aug.bone_scale > 0 or aug.global_scale > 0:
        new = scaled_skeleton(skeleton, rng, aug)
        leg = new.bone_lengths()[_LEG].sum() / skeleton.bone_lengths()[_LEG].sum()
        root = root * leg  # the stride and the pelvis height follow the legs
        skeleton = new
    tpose = aug.tpose_prob > 0 and rng.random() < aug.tpose_prob
    if tpose:
        rot, root, contacts = tpose_window(skeleton, rot, root)
    placed = aug.placement is not None and rng.random() < aug.placement_prob
    pts = keypoints_3d(skeleton, rot, root, placement=aug.placement if placed else None)
    forward = _facing(rot[:, 0])
    camera = sample_camera(pts, rng, aug.camera, facing=forward)
    kp = project(camera, pts)
    if aug.corruption is not None and rng.random() >= aug.clean_prob:
        kp = corrupt_keypoints(kp, rng, _confidence_model(), aug.corruption)
    kp_in = smooth_keypoints(kp, aug.smooth) if aug.smooth > 0 else kp
    features, root_2d, scale, _ = lifter_features(kp_in, camera.intrinsics)
    crot, croot = motion_to_camera(rot, root, camera)
    positions = forward_kinematics(skeleton.parents, skeleton.offsets, crot, croot).positions
    return {'features': features, 'root_2d': root_2d.astype(np.float32),
            'scale': scale.astype(np.float32),
            'positions': positions.astype(np.float32), 'rotations': crot.astype(np.float32),
            'root': croot.astype(np.float32),
            'lengths': skeleton.group_lengths().astype(np.float32), 'contacts': contacts,
            'keypoints': kp.astype(np.float32), 'tpose': np.float32(tpose)}


def tpose_window(skeleton: Skeleton, rot: np.ndarray, root: np.ndarray):
    """The character standing still in its T-pose (MotioNet's reference T-pose, §3.2): every
    joint rotation identity, the root turned about the vertical only (the window's first
    facing), feet on the floor; all heel/toe points in contact. Returns (rot, root,
    contacts) shaped like the window's (T, J, 4), (T, 3), (T, 4)."""
    t = len(rot)
    fwd = _facing(rot[:1, 0])
    yaw = np.arctan2(fwd[1], fwd[0])
    q = np.zeros((t, rot.shape[1], 4))
    q[..., 3] = 1.0
    q[:, 0] = [0.0, 0.0, np.sin(yaw / 2), np.cos(yaw / 2)]
    r = np.repeat(np.array([[root[0, 0], root[0, 1], skeleton.rest_root_height()]]), t, axis=0)
    return q, r, np.ones((t, 4), dtype=np.float32)


def _facing(root_quats: np.ndarray) -> np.ndarray:
    """Mean forward (body +x) direction of the root over a window, world xy."""
    return quat_rotate(root_quats, np.array([1.0, 0.0, 0.0])).mean(axis=0)


_MODEL: Optional[ConfidenceModel] = None


def _confidence_model() -> ConfidenceModel:
    global _MODEL
    if _MODEL is None:
        _MODEL = ConfidenceModel.default()
    return _MODEL


class WindowSampler:
    """Draws batches of fixed-length windows, clips weighted by their number of windows."""

    def __init__(self, motions: Sequence[Motion], window: int, seed: int = 0,
                 aug: Optional[Augmentation] = None) -> None:
        self.motions: List[Motion] = [m for m in motions if m.num_frames >= window]
        if not self.motions:
            raise ValueError(f'no clip has {window} frames')
        self.window = window
        self.rng = np.random.default_rng(seed)
        self.aug = aug or Augmentation()
        counts = np.array([m.num_frames - window + 1 for m in self.motions], dtype=np.float64)
        self.weights = counts / counts.sum()

    def batch(self, size: int) -> Dict[str, np.ndarray]:
        """``size`` samples stacked along a new first axis."""
        items = []
        for _ in range(size):
            m = self.motions[self.rng.choice(len(self.motions), p=self.weights)]
            start = int(self.rng.integers(0, m.num_frames - self.window + 1))
            items.append(make_sample(m, start, self.window, self.rng, self.aug))
        return {k: np.stack([it[k] for it in items]) for k in items[0]}


class RenderedWindowSampler:
    """Windows of rendered clips (``mocap data render``): the real detector's keypoints on
    rendered people, with exact targets in the (possibly moving) camera's optical frame.

    Each clip folder's ``data.npz`` gives the detector keypoints, the intrinsics, the exact
    joints (``joints_camera``: the training convention, so the position targets are exact),
    the driving rotations (the root turned into the camera frame per frame), the bone-group
    lengths and the contacts. Frames without a detection stay in (zero confidence), as the
    lifter sees them live.

    Args:
        clip_dirs: rendered clip folders.
        window: frames per window; shorter clips are skipped.
        seed: the sampler's generator.
        keep: optional predicate on the clip id (e.g. the strict split's training clips).
        flip: probability that a window is mirrored left-right (:func:`mirror_rendered_window`):
            the detector's output on the mirrored image, up to the detector's own asymmetry,
            with the mirrored body as its target. Doubles the people, scenes and camera
            paths the renders show.
    """

    def __init__(self, clip_dirs: Sequence, window: int, seed: int = 0,
                 keep=None, flip: float = 0.0) -> None:
        import json
        from pathlib import Path

        from mocap_core.camera import CameraIntrinsics
        from mocap_core.rotations import matrix_to_quat, quat_multiply
        self.window = window
        self.flip = float(flip)
        self.rng = np.random.default_rng(seed)
        self.clips: List[Dict[str, np.ndarray]] = []
        self.widths: List[int] = []
        for d in clip_dirs:
            d = Path(d)
            meta = json.loads((d / 'meta.json').read_text())
            if keep is not None and not keep(meta['clip']):
                continue
            with np.load(d / 'data.npz') as z:
                if len(z['keypoints']) < window:
                    continue
                K, (w, h) = z['K'], (int(x) for x in z['image_size'])
                intr = CameraIntrinsics(w, h, float(K[0, 0]), float(K[1, 1]), float(K[0, 2]),
                                        float(K[1, 2]), approximate=False)
                rot = z['rotations'].copy()
                rot[:, 0] = quat_multiply(matrix_to_quat(z['camera_R']), rot[:, 0])
                feats, root_2d, scale, _ = lifter_features(z['keypoints'], intr)
                self.clips.append({
                    'features': feats, 'root_2d': root_2d.astype(np.float32),
                    'scale': scale.astype(np.float32),
                    'positions': z['joints_camera'].astype(np.float32),
                    'rotations': rot.astype(np.float32),
                    'root': z['joints_camera'][:, 0].astype(np.float32),
                    'lengths': z['bone_lengths'].astype(np.float32),
                    'contacts': z['contacts'].astype(np.float32),
                    'keypoints': z['keypoints'].astype(np.float32)})
                self.widths.append(w)
        if not self.clips:
            raise ValueError(f'no rendered clip has {window} frames')
        counts = np.array([len(c['features']) - window + 1 for c in self.clips], float)
        self.weights = counts / counts.sum()

    def __len__(self) -> int:
        return len(self.clips)

    def sample(self) -> Dict[str, np.ndarray]:
        i = int(self.rng.choice(len(self.clips), p=self.weights))
        c = self.clips[i]
        s = int(self.rng.integers(0, len(c['features']) - self.window + 1))
        out = {k: (v if k == 'lengths' else v[s:s + self.window]) for k, v in c.items()}
        if self.flip > 0 and self.rng.random() < self.flip:
            out = mirror_rendered_window(out, self.widths[i])
        out['tpose'] = np.float32(0.0)
        return out


def mirror_rendered_window(w: Dict[str, np.ndarray], width: int) -> Dict[str, np.ndarray]:
    """A rendered window (:meth:`RenderedWindowSampler.sample`'s keys but ``tpose``) as seen
    in the left-right mirrored image: features mirrored about the principal point with left
    and right keypoints exchanged (:func:`~mocap_lifter.features.mirror_features`); targets in
    the camera optical frame reflected in x (positions and root), joints and contact points
    exchanged left and right, rotations reflected (the same conjugation as
    :func:`~mocap_lifter.features.unmirror_rotations`, which is its own inverse); the
    bone-group lengths and the 2D scale are unchanged (the skeleton is symmetric). The pixel
    keypoints are mirrored about the image's centre column (``width`` pixels)."""
    out = dict(w)
    feats, root_2d = mirror_features(w['features'], w['root_2d'])
    out['features'] = feats.astype(np.float32)
    out['root_2d'] = root_2d.astype(np.float32)
    flip_x = np.array([-1.0, 1.0, 1.0], dtype=np.float32)
    out['positions'] = (w['positions'][:, list(JOINT_MIRROR)] * flip_x).astype(np.float32)
    out['root'] = (w['root'] * flip_x).astype(np.float32)
    out['rotations'] = unmirror_rotations(w['rotations']).astype(np.float32)
    out['contacts'] = w['contacts'][:, list(CONTACT_MIRROR)]
    out['keypoints'] = mirror_keypoints(w['keypoints'], width).astype(np.float32)
    return out


class MixedSampler:
    """Batches mixing projected windows (:class:`WindowSampler`) and rendered windows
    (:class:`RenderedWindowSampler`): each sample is rendered with probability
    ``rendered_fraction``."""

    def __init__(self, projected: WindowSampler, rendered: RenderedWindowSampler,
                 rendered_fraction: float) -> None:
        self.projected, self.rendered = projected, rendered
        self.fraction = float(rendered_fraction)
        self.rng = projected.rng

    @property
    def window(self) -> int:
        return self.projected.window

    def reseed(self, seed: int) -> None:
        self.projected.rng = np.random.default_rng(seed)
        self.rendered.rng = np.random.default_rng(seed + 1)
        self.rng = self.projected.rng

    def batch(self, size: int) -> Dict[str, np.ndarray]:
        n_r = int(self.rng.binomial(size, self.fraction))
        items = [self.rendered.sample() for _ in range(n_r)]
        if size - n_r:
            proj = self.projected.batch(size - n_r)
            items += [{k: v[i] for k, v in proj.items()} for i in range(size - n_r)]
        return {k: np.stack([np.asarray(it[k], dtype=np.float32) for it in items])
                for k in items[0]}
