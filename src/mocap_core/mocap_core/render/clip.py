"""Render one motion clip end to end, and the resumable batch behind ``mocap data render``.

Per clip (:func:`render_clip`), into ``<out>/<split>/<key>/``:

* ``video.mp4`` -- the rendered frames (mp4v, the clip's frame rate);
* ``data.npz`` -- arrays, all float64 unless stated, F frames:

  ``keypoints`` (F, 23, 3) the detector's keypoints (u px, v px, confidence) on the decoded
  video, as the keypoint node publishes them for that file (most confident person;
  confidences 0 when nobody is found);
  ``keypoints_mesh`` (F, 23, 3) Anny's COCO-style mesh keypoints projected (u, v, 1 when in
  front of the camera; the feet points of the layout that Anny's regressor lacks are the
  ground-truth skeleton's); ``joints_world`` / ``joints_camera`` (F, 18, 3) the rendered body's
  pipeline joints (training convention, ``body.to_convention``) in the world (z up, floor
  z = 0) and the camera optical frame; ``joints_rig_world`` (F, 18, 3) the same at the rig's
  own points; ``bone_lengths`` (10,) the body's bone-group lengths (medians over the clip);
  ``K`` (3, 3); ``image_size`` (2,) int width, height; ``camera_R`` (F, 3, 3) world -> optical;
  ``camera_position`` (F, 3); ``contacts`` (F, 4) bool (left_heel, left_toe, right_heel,
  right_toe) from the motion-capture labels; ``view`` (F,) str front / side / back;
  ``rotations`` (F, 18, 4) and ``root_positions`` (F, 3) the driving motion's local rotations
  (x, y, z, w) with this body's pelvis path; ``fps`` ().
* ``meta.json`` -- clip id, split, seed, phenotype and body height, appearance, camera,
  detection rate, 2D error of the detector against the mesh keypoints, timings;
* ``gt_bag/`` -- a ground-truth MCAP bag in the format of ``data/gt_bag.py`` (keypoints are
  the detector's; camera pose per frame);
* ``done`` -- written last: a clip with it is complete and is skipped by a rerun.

Everything is deterministic from ``(seed, clip key)``; the detector is the keypoint node's
(found through the ``mocap.detectors`` entry point) in video mode with the node's defaults.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Dict, Iterator, List, Optional, Sequence, Tuple

import numpy as np

from ..camera import project_pinhole
from ..skeleton import (JOINT_INDEX, KEYPOINT_INDEX, NUM_KEYPOINTS)

#: Bump when the output of :func:`render_clip` changes meaning (old clips are re-rendered).
RENDER_FORMAT = 5

#: Anny's COCO keypoint names -> layout names (the feet points come from the skeleton).
_COCO_TO_LAYOUT = {
    'nose': 'nose', 'left_eye': 'left_eye', 'right_eye': 'right_eye', 'left_ear': 'left_ear',
    'right_ear': 'right_ear', 'left_shoulder': 'left_shoulder',
    'right_shoulder': 'right_shoulder', 'left_elbow': 'left_elbow',
    'right_elbow': 'right_elbow', 'left_wrist': 'left_wrist', 'right_wrist': 'right_wrist',
    'left_hip': 'left_hip', 'right_hip': 'right_hip', 'left_knee': 'left_knee',
    'right_knee': 'right_knee', 'left_ankle': 'left_ankle', 'right_ankle': 'right_ankle',
    'left_big_toe': 'left_big_toe', 'left_small_toe': 'left_small_toe',
    'left_heel': 'left_heel', 'right_big_toe': 'right_big_toe',
    'right_small_toe': 'right_small_toe', 'right_heel': 'right_heel',
}


def clip_seed(seed: int, key: str) -> int:
    """The generator seed of one clip: stable across runs, machines and job order."""
    return int.from_bytes(hashlib.sha256(f'{seed}:{key}'.encode()).digest()[:8], 'little')


def clip_key(clip_id: str) -> str:
    """A file-system-safe directory name for a clip id."""
    safe = ''.join(c if c.isalnum() or c in '-_.' else '_' for c in clip_id)
    return safe[-80:] + '_' + hashlib.sha1(clip_id.encode()).hexdigest()[:8]


@dataclass
class ClipResult:
    key: str
    frames: int
    detected: float
    seconds: float
    skipped: bool = False


@dataclass
class PlacedBody:
    """A body posed along a motion, standing on the floor (pipeline world frame, z up, m).

    Attributes:
        body: the Anny body; regions: per vertex region name.
        scale: body leg length / motion leg length (the motion's path is scaled by it).
        pelvis: (F, 3) the body's pelvis path.
        vertices: (F, V, 3) float32 mesh; joints, joints_rig: (F, 18, 3) (``PosedBody``).
        keypoints_world: (F, 23, 3) the mesh keypoints in the layout (Anny's COCO regressor;
            zeros where ``have`` (23,) is False).
    """

    body: object
    regions: List[str]
    scale: float
    pelvis: np.ndarray
    vertices: np.ndarray
    joints: np.ndarray
    joints_rig: np.ndarray
    keypoints_world: np.ndarray
    have: np.ndarray


def place_body(model, coco, skeleton, global_rotations: np.ndarray, root: np.ndarray,
               contacts: np.ndarray, phenotype, about: Optional[np.ndarray] = None,
               head_details: bool = True) -> PlacedBody:
    """Pose the body of ``phenotype`` along a motion: (F, 18, 3, 3) global rotations and the
    (F, 3) root path of the motion's ``skeleton``. The path is scaled about ``about`` (xy;
    default the origin) by the ratio of the leg lengths, so the body's steps match its legs,
    and the body is lifted so that its soles touch z = 0 in the frames whose (F, 4)
    ``contacts`` has a contact. ``coco``: Anny's COCO keypoint regressor of ``model``.
    ``head_details``: hair, eyebrows, eyes and lips coloured as regions of their own
    (:func:`~mocap_core.render.body.head_detail_regions`); False gives the plain skin-coloured
    head of the renders before session 42."""
    import torch

    from .body import AnnyBody, region_of_vertices

    body = AnnyBody.create(model, phenotype)
    sk_len = skeleton.bone_lengths()
    mocap_leg = sk_len[JOINT_INDEX['left_knee']] + sk_len[JOINT_INDEX['left_ankle']]
    scale = body.leg_length() / mocap_leg
    if about is None:
        pelvis = np.asarray(root, dtype=np.float64) * scale
    else:
        centre = np.array([about[0], about[1], 0.0])
        pelvis = centre + (np.asarray(root, dtype=np.float64) - centre) * scale
    posed = body.pose(global_rotations, pelvis)
    # Level the floor: the soles touch z = 0 in the frames labelled as contacts.
    regions = region_of_vertices(body, head_details)
    foot = np.array([r == 'foot' for r in regions])
    sole = posed.vertices[:, foot, 2].min(axis=1).astype(np.float64)
    stance = np.asarray(contacts, dtype=bool).any(axis=1)
    dz = float(np.median(sole[stance])) if stance.any() else float(np.percentile(sole, 5))
    shift = np.array([0.0, 0.0, -dz])
    with torch.no_grad():
        mesh_kp = coco({'vertices': torch.from_numpy(posed.vertices).double()}).double().numpy()
    mesh_kp = mesh_kp + shift  # a linear blend of the vertices (already in pipeline axes)
    # Mesh keypoints in the layout (Anny's regressor has the 17 COCO body points; the feet
    # points come from the layout's own feet where it lacks them).
    labels = list(coco.labels) if hasattr(coco, 'labels') else []
    kp_world = np.zeros((len(pelvis), NUM_KEYPOINTS, 3))
    have = np.zeros(NUM_KEYPOINTS, dtype=bool)
    for i, name in enumerate(labels):
        lay = _COCO_TO_LAYOUT.get(name)
        if lay is not None:
            kp_world[:, KEYPOINT_INDEX[lay]] = mesh_kp[:, i]
            have[KEYPOINT_INDEX[lay]] = True
    return PlacedBody(body, regions, scale, pelvis + shift, posed.vertices +
                      shift.astype(np.float32), posed.joints + shift, posed.joints_rig + shift,
                      kp_world, have)


def _facing(global_rotations: np.ndarray) -> np.ndarray:
    """(F, 2) horizontal forward direction of the pelvis."""
    f = global_rotations[:, 0, :2, 0]
    return f / np.maximum(np.linalg.norm(f, axis=1, keepdims=True), 1e-9)


class ClipRenderer:
    """Holds the body model and the detector of one worker; renders clips one after another.

    Args:
        detector_factory: ``() -> detector`` with ``detect(bgr) -> (P, 23, 3)``, ``reset()``,
            ``close()`` (the keypoint node's; ``plugins.detector_factory``).
        model: the Anny model (``body.load_anny``); loaded on first use when None.
        head_details: render the head with hair and a face (:func:`place_body`).
    """

    def __init__(self, detector_factory: Callable[[], object], model=None,
                 head_details: bool = True) -> None:
        self._factory = detector_factory
        self._model = model
        self.head_details = head_details
        self._detector = None
        self._coco = None

    def _ensure(self) -> None:
        if self._model is None:
            from .body import load_anny
            self._model = load_anny()
        if self._detector is None:
            self._detector = self._factory()
        if self._coco is None:
            from anny import KeypointsRegressor
            self._coco = KeypointsRegressor.coco(self._model)

    def close(self) -> None:
        if self._detector is not None:
            self._detector.close()
            self._detector = None

    # ------------------------------------------------------------------------------------
    def render(self, motion, clip_id: str, split: str, out_dir: Path, seed: int,
               max_frames: Optional[int] = None, camera_kind: str = '',
               write_bag: bool = True, camera_ranges=None,
               progress: Optional[Callable[[int], None]] = None) -> ClipResult:
        """Render ``motion`` (a processed :class:`~mocap_core.data.motion.Motion`) into
        ``out_dir`` (module docstring). ``camera_ranges``: a
        :class:`~.cameras.CameraRanges` (default ranges when None). Returns what was done."""
        import cv2

        from ..rotations import matrix_to_quat
        from .body import sample_phenotype
        from .cameras import sample_camera_path, view_labels
        from .scene import SceneRenderer, sample_appearance

        self._ensure()
        t0 = time.perf_counter()
        rng = np.random.default_rng(clip_seed(seed, clip_id))
        F = motion.num_frames if max_frames is None else min(motion.num_frames, max_frames)
        start = 0
        if F < motion.num_frames:
            start = int(rng.integers(0, motion.num_frames - F + 1))
        fk = motion.fk()
        G = fk.global_rotations[start:start + F]
        P = fk.positions[start:start + F]
        pheno = sample_phenotype(rng, self._model)
        contacts = np.asarray(motion.contacts[start:start + F], dtype=bool)
        placed = place_body(self._model, self._coco, motion.skeleton, G, P[:, 0], contacts,
                            pheno, head_details=self.head_details)
        body, regions, scale = placed.body, placed.regions, placed.scale
        pelvis, verts, joints, joints_rig = (placed.pelvis, placed.vertices, placed.joints,
                                             placed.joints_rig)
        facing = _facing(G)
        mean_facing = facing.mean(axis=0)
        sample = verts[:, ::997].astype(np.float64)
        from .cameras import CameraRanges
        cam = sample_camera_path(np.concatenate([joints, sample], axis=1), mean_facing, rng,
                                 camera_ranges or CameraRanges(), kind=camera_kind)
        appearance = sample_appearance(rng)
        K = cam.K()
        joints_cam = cam.world_to_camera(joints)
        kp_world, have = placed.keypoints_world, placed.have
        kp_mesh = project_pinhole(K, cam.world_to_camera(kp_world))
        kp_mesh[:, ~have] = 0.0

        out_dir = Path(out_dir)
        tmp = out_dir.with_name(out_dir.name + '.partial')
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        renderer = SceneRenderer(cam.intrinsics.width, cam.intrinsics.height, K, body.faces,
                                 regions, appearance, centre=pelvis.mean(axis=0)[:2])
        writer = cv2.VideoWriter(str(tmp / 'video.mp4'), cv2.VideoWriter_fourcc(*'mp4v'),
                                 float(motion.fps), (cam.intrinsics.width, cam.intrinsics.height))
        keypoints = np.zeros((F, NUM_KEYPOINTS, 3))
        t_render = t_detect = 0.0
        try:
            for f in range(F):
                a = time.perf_counter()
                writer.write(renderer.render(verts[f], cam.R[f], cam.position[f]))
                t_render += time.perf_counter() - a
        finally:
            writer.release()
            renderer.close()
        # The detector sees the decoded video, as the keypoint node does with this file.
        self._detector.reset()
        cap = cv2.VideoCapture(str(tmp / 'video.mp4'))
        try:
            for f in range(F):
                ok, img = cap.read()
                if not ok:
                    raise RuntimeError(f'{tmp / "video.mp4"}: frame {f} cannot be decoded')
                b = time.perf_counter()
                det = np.asarray(self._detector.detect(img), dtype=np.float64)
                t_detect += time.perf_counter() - b
                if det.size:
                    keypoints[f] = det[0]
                if progress is not None:
                    progress(1)
        finally:
            cap.release()
        detected = keypoints[..., 2].max(axis=1) > 0
        err = np.linalg.norm(keypoints[..., :2] - kp_mesh[..., :2], axis=-1)
        body_px = np.ptp(kp_mesh[..., 1], axis=1)
        both = (keypoints[..., 2] > 0.5) & (kp_mesh[..., 2] > 0) & detected[:, None]
        rel = err / np.maximum(body_px, 1.0)[:, None]
        views = view_labels(cam.position, pelvis, facing)
        # The driving motion with this body's pelvis path (rotations as the motion's).
        rot = np.asarray(motion.rotations[start:start + F], dtype=np.float64)
        np.savez_compressed(
            tmp / 'data.npz', keypoints=keypoints, keypoints_mesh=kp_mesh,
            joints_world=joints, joints_camera=joints_cam, joints_rig_world=joints_rig,
            bone_lengths=body.skeleton.group_lengths(), K=K,
            image_size=np.array([cam.intrinsics.width, cam.intrinsics.height]),
            camera_R=cam.R, camera_position=cam.position, contacts=contacts, view=views,
            rotations=rot, root_positions=joints[:, 0], fps=np.array(float(motion.fps)),
            camera_quaternion=matrix_to_quat(np.transpose(cam.R, (0, 2, 1))))
        meta = {
            'format': RENDER_FORMAT, 'clip': clip_id, 'split': split, 'seed': seed,
            'start_frame': start, 'frames': F, 'fps': float(motion.fps),
            'phenotype': pheno, 'body_height_m': body.height(), 'scale': scale,
            'appearance': appearance.to_dict(), 'head_details': self.head_details,
            'camera': cam.describe(),
            'detected_fraction': float(detected.mean()),
            'median_2d_error_rel_height': float(np.median(rel[both])) if both.any() else None,
            'views': {v: int((views == v).sum()) for v in ('front', 'side', 'back')},
            'seconds': {'render': t_render, 'detect': t_detect,
                        'total': time.perf_counter() - t0},
        }
        (tmp / 'meta.json').write_text(json.dumps(meta, indent=1))
        if write_bag:
            from .bag import write_rendered_bag
            write_rendered_bag(tmp, tmp / 'gt_bag')
        (tmp / 'done').write_text(str(RENDER_FORMAT))
        shutil.rmtree(out_dir, ignore_errors=True)
        os.replace(tmp, out_dir)
        return ClipResult(clip_id, F, float(detected.mean()), time.perf_counter() - t0)


def is_done(out_dir: Path) -> bool:
    """True when ``out_dir`` holds a complete clip of the current format."""
    try:
        return (Path(out_dir) / 'done').read_text().strip() == str(RENDER_FORMAT)
    except OSError:
        return False


def iter_done(root: Path, split: Optional[str] = None) -> Iterator[Path]:
    """The complete clip folders under ``root`` (one split or all)."""
    root = Path(root)
    splits: Sequence[Path] = [root / split] if split else sorted(
        p for p in root.iterdir() if p.is_dir()) if root.is_dir() else []
    for s in splits:
        if s.is_dir():
            for d in sorted(s.iterdir()):
                if d.is_dir() and is_done(d):
                    yield d


def load_clip(clip_dir: Path) -> Tuple[Dict[str, np.ndarray], dict]:
    """``(arrays, meta)`` of a rendered clip folder."""
    clip_dir = Path(clip_dir)
    with np.load(clip_dir / 'data.npz') as z:
        arrays = {k: z[k] for k in z.files}
    return arrays, json.loads((clip_dir / 'meta.json').read_text())


__all__: List[str] = ['ClipRenderer', 'ClipResult', 'RENDER_FORMAT', 'clip_key', 'clip_seed',
                      'is_done', 'iter_done', 'load_clip']
