"""Where a real detector puts the keypoints, relative to the synthesizer's points (no ROS).

The projected training keypoints (:func:`~.synth2d.keypoints_3d`) put each body keypoint on a
skeleton joint (face and feet points at fixed places of the head and feet). A detector does
not: BlazePose's hip points lie outside the skeleton's hip joints, its shoulders above them,
and so on (``../shared/ENVIRONMENT.md``). A :class:`DetectorPlacement` holds, per layout
keypoint, a fixed 3D offset from the synthesizer's point, in the frame of the body segment the
point belongs to, in units of the person's leg length (hip to ankle), plus the spread of the
detector around it (relative to the person's height in the image).

:func:`fit_detector_placement` fits the offsets on rendered clips (``mocap data render``): for
keypoint k in frame f, the detection d differs from the projection of the synthesizer's point
s by approximately ``J_proj(s) R_cam G_seg o_k * leg`` (a first-order expansion of the
projection), so each detection gives two linear equations in ``o_k``; all frames of all clips
are solved together by least squares, robustly (eight reweighting rounds that down-weight
residuals beyond 2.5 robust standard deviations). Views from every side make the 3D offset
observable. ``mocap data fit-placement`` runs it on the rendered *training* clips and writes
``detector_placement.json`` next to this module; training and the cross-synthesizer check
apply it with ``keypoints_3d(..., placement=...)``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Iterable, List, Optional, Tuple, Union

import numpy as np

from ..camera import world_to_optical
from ..kinematics import forward_kinematics
from ..skeleton import JOINT_INDEX, KEYPOINT_NAMES, NUM_KEYPOINTS, PARENTS, Skeleton

#: The shipped placement (fitted on rendered training clips; see the module docstring).
PLACEMENT_PATH = Path(__file__).with_name('detector_placement.json')


def _segment_joint(keypoint: str) -> int:
    """The joint whose global rotation carries keypoint's offset (its body segment)."""
    if keypoint in ('nose', 'left_eye', 'right_eye', 'left_ear', 'right_ear'):
        return JOINT_INDEX['head']
    side = keypoint.split('_')[0]
    if keypoint.endswith(('big_toe', 'small_toe')):
        return JOINT_INDEX[f'{side}_toe']
    if keypoint.endswith('heel'):
        return JOINT_INDEX[f'{side}_ankle']
    return PARENTS[JOINT_INDEX[keypoint]]  # the segment that ends at the joint


#: Per layout keypoint, the joint index whose global rotation orients its offset.
SEGMENT_JOINTS: Tuple[int, ...] = tuple(_segment_joint(k) for k in KEYPOINT_NAMES)


def leg_length(skeleton: Skeleton) -> float:
    """Mean hip-to-ankle length (thigh + shin), metres."""
    b = skeleton.bone_lengths()
    return float(b[JOINT_INDEX['left_knee']] + b[JOINT_INDEX['left_ankle']])


@dataclass
class DetectorPlacement:
    """Per keypoint: ``offsets`` (23, 3) in the segment frame (x forward, y left, z up at
    rest) in leg lengths; ``noise`` (23,) the detector's spread around the placed point
    (robust standard deviation of the 2D residual over the person's image height);
    ``info``: provenance (clips, frames, fit residuals)."""

    offsets: np.ndarray
    noise: np.ndarray
    info: dict

    def apply(self, points: np.ndarray, global_rotations: np.ndarray,
              leg: float) -> np.ndarray:
        """``points`` (..., 23, 3) synthesizer keypoints (world or camera) moved by the
        offsets; ``global_rotations`` (..., 18, 3, 3) in the same frame; ``leg`` metres."""
        R = global_rotations[..., list(SEGMENT_JOINTS), :, :]
        return points + leg * np.einsum('...kij,kj->...ki', R, self.offsets)

    def to_json(self) -> dict:
        return {'keypoints': list(KEYPOINT_NAMES),
                'offsets_leg_lengths': np.round(self.offsets, 5).tolist(),
                'noise_rel_height': np.round(self.noise, 5).tolist(), 'info': self.info}

    def save(self, path: Union[str, Path]) -> None:
        Path(path).write_text(json.dumps(self.to_json(), indent=1) + '\n')

    @classmethod
    def load(cls, path: Union[str, Path] = PLACEMENT_PATH) -> 'DetectorPlacement':
        d = json.loads(Path(path).read_text())
        if d.get('keypoints') != list(KEYPOINT_NAMES):
            raise ValueError(f'{path}: keypoint layout differs from the pipeline\'s')
        return cls(np.asarray(d['offsets_leg_lengths'], dtype=np.float64),
                   np.asarray(d['noise_rel_height'], dtype=np.float64), d.get('info', {}))


def _clip_equations(arrays: Dict[str, np.ndarray], min_confidence: float):
    """Per keypoint: (A (n, 2, 3), r (n, 2), scale (n,)) of one rendered clip."""
    from .synth2d import keypoints_3d
    sk = Skeleton.from_group_lengths(arrays['bone_lengths'])
    rot = arrays['rotations']
    root = arrays['root_positions']
    fk = forward_kinematics(sk.parents, sk.offsets, rot, root)
    G = fk.global_rotations                                   # (F, 18, 3, 3) world
    pts = keypoints_3d(sk, rot, root)                          # (F, 23, 3) world
    Rc, C, K = arrays['camera_R'], arrays['camera_position'], arrays['K']
    pc = world_to_optical(Rc, C, pts)                          # camera frame
    z = pc[..., 2]
    f = np.array([K[0, 0], K[1, 1]])
    uv = pc[..., :2] / z[..., None] * f + K[:2, 2]
    det = arrays['keypoints']
    height_px = np.ptp(uv[..., 1], axis=1)                     # person's image height
    leg = leg_length(sk)
    out = []
    for k in range(NUM_KEYPOINTS):
        ok = (det[:, k, 2] >= min_confidence) & (z[:, k] > 0.1) & (height_px > 20)
        if not ok.any():
            out.append(None)
            continue
        x, y, zz = pc[ok, k, 0], pc[ok, k, 1], z[ok, k]
        Jp = np.zeros((ok.sum(), 2, 3))
        Jp[:, 0, 0] = f[0] / zz
        Jp[:, 0, 2] = -f[0] * x / zz ** 2
        Jp[:, 1, 1] = f[1] / zz
        Jp[:, 1, 2] = -f[1] * y / zz ** 2
        W = np.einsum('fij,fjk->fik', Rc[ok], G[ok, SEGMENT_JOINTS[k]]) * leg
        A = np.einsum('fij,fjk->fik', Jp, W)
        r = det[ok, k, :2] - uv[ok, k]
        out.append((A, r, height_px[ok]))
    return out


def fit_detector_placement(clips: Iterable[Dict[str, np.ndarray]],
                           min_confidence: float = 0.5, rounds: int = 8,
                           info: Optional[dict] = None) -> DetectorPlacement:
    """Fit the offsets on rendered clips' arrays (``render.clip.load_clip``); see the module
    docstring. Keypoints the detector never reports (BlazePose has no small toes) get a zero
    offset and a NaN noise."""
    per_k: List[List[tuple]] = [[] for _ in range(NUM_KEYPOINTS)]
    n_clips = 0
    for arrays in clips:
        n_clips += 1
        for k, eq in enumerate(_clip_equations(arrays, min_confidence)):
            if eq is not None:
                per_k[k].append(eq)
    offsets = np.zeros((NUM_KEYPOINTS, 3))
    noise = np.full(NUM_KEYPOINTS, np.nan)
    residual_before = np.full(NUM_KEYPOINTS, np.nan)
    residual_after = np.full(NUM_KEYPOINTS, np.nan)
    counts = np.zeros(NUM_KEYPOINTS, dtype=int)
    for k in range(NUM_KEYPOINTS):
        if not per_k[k]:
            continue
        A = np.concatenate([e[0] for e in per_k[k]])            # (n, 2, 3)
        r = np.concatenate([e[1] for e in per_k[k]])            # (n, 2)
        h = np.concatenate([e[2] for e in per_k[k]])            # (n,)
        # normalise each equation by the person's image height: every frame counts alike
        An, rn = A / h[:, None, None], r / h[:, None]
        w = np.ones(len(rn))
        o = np.zeros(3)
        for _ in range(rounds):
            sw = np.sqrt(w)[:, None, None]
            o = np.linalg.lstsq((An * sw).reshape(-1, 3), (rn * sw[..., 0]).reshape(-1),
                                rcond=None)[0]
            res = np.linalg.norm(rn - An @ o, axis=1)
            s = 1.4826 * np.median(res) + 1e-9
            w = np.where(res <= 2.5 * s, 1.0, 2.5 * s / res)
        offsets[k] = o
        counts[k] = len(rn)
    # Left and right are mirror images: average each pair (y flips), weighted by detections.
    flip = np.array([1.0, -1.0, 1.0])
    for k, name in enumerate(KEYPOINT_NAMES):
        if name.startswith('left_'):
            m = KEYPOINT_NAMES.index('right_' + name[5:])
            n = counts[k] + counts[m]
            if n:
                avg = (counts[k] * offsets[k] + counts[m] * flip * offsets[m]) / n
                offsets[k], offsets[m] = avg, flip * avg
    for k in range(NUM_KEYPOINTS):
        if not per_k[k]:
            continue
        A = np.concatenate([e[0] for e in per_k[k]])
        r = np.concatenate([e[1] for e in per_k[k]])
        h = np.concatenate([e[2] for e in per_k[k]])
        An, rn = A / h[:, None, None], r / h[:, None]
        res = np.linalg.norm(rn - An @ offsets[k], axis=1)
        noise[k] = 1.4826 * np.median(res)
        residual_before[k] = float(np.median(np.linalg.norm(rn, axis=1)))
        residual_after[k] = float(np.median(res))
    meta = dict(info or {})
    meta.update({'clips': n_clips, 'detections_per_keypoint': counts.tolist(),
                 'median_residual_before_rel_height': np.round(residual_before, 5).tolist(),
                 'median_residual_after_rel_height': np.round(residual_after, 5).tolist(),
                 'min_confidence': min_confidence})
    return DetectorPlacement(offsets, noise, meta)
