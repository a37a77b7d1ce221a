"""Virtual cameras, 2D keypoints from motion capture, and realistic corruption (no ROS).

Pipeline for one training sample (issue "motion data pipeline", part 4):

1. :func:`keypoints_3d` — the 23 layout points in the world from the FK of a motion. Points
   that motion capture does not have are synthesised from the head and foot geometry
   (:data:`FACE_POINTS`, :data:`FOOT_POINTS`): nose, eyes and ears are fixed points of the
   head joint's frame, scaled by the neck-to-head bone; big and small toes are fixed points of
   the toe joint's frame and heels the skeleton's heel contact points, scaled by the foot
   bone. All of them get confidence 1 before corruption (none is left at confidence 0).
2. :func:`sample_camera` — a random static pinhole camera around the subject (distance,
   height, azimuth, aim jitter, field of view, image size; all in :class:`CameraSampling`),
   re-drawn farther away until every point of the clip is inside the image.
3. :func:`project` — perspective projection to pixels.
4. :func:`corrupt_keypoints` — MotioNet §4 confidence model: per keypoint, confidence 0 with
   probability delta, else a Gaussian (mu, sigma) clipped to (0, 1]; the point moves in a
   uniformly random direction by up to beta (1 - c) (beta relative to the person's height in
   the image); c = 0 points are set to (0, 0). Plus random extra dropped joints and dropped
   (all-zero) frames. The per-keypoint (delta, mu, sigma) are fitted by
   :func:`fit_confidence_model` on real OpenPose detections.
5. :func:`mirror_motion` — left-right flip of the 3D motion (MotioNet §4 augmentation (3)).
6. :func:`canonicalize` — neural PhysCap §3.2 canonical keypoints K^-1 [u, v, 1].

World frame: z up (docs/design.md §3). Camera: optical frame (x right, y down, z forward).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Dict, Optional, Tuple

import numpy as np

from ..camera import CameraIntrinsics
from ..keypoint_geometry import JOINT_KEYPOINTS, canonicalize  # noqa: F401 (re-exported)
from ..kinematics import forward_kinematics
from ..rotations import matrix_to_quat, quat_multiply
from ..skeleton import (JOINT_INDEX, JOINT_MIRROR, KEYPOINT_INDEX, KEYPOINT_MIRROR,
                        KEYPOINT_NAMES, NUM_KEYPOINTS, Skeleton)

#: Face points in the head joint's frame (x forward, y left, z up at rest), in units of the
#: neck-to-head bone length (0.18 m for the default skeleton: nose 10 cm in front of the head
#: centre, eyes 3 cm to each side, ears 7.5 cm to each side).
FACE_POINTS: Dict[str, Tuple[str, Tuple[float, float, float]]] = {
    'nose': ('head', (0.55, 0.0, 0.0)),
    'left_eye': ('head', (0.45, 0.17, 0.15)),
    'right_eye': ('head', (0.45, -0.17, 0.15)),
    'left_ear': ('head', (0.0, 0.42, 0.05)),
    'right_ear': ('head', (0.0, -0.42, 0.05)),
}
#: Toe points in the toe joint's frame, in units of the foot (ankle-to-toe) bone length: the
#: big toe tip ahead of the ball of the foot on the inner side, the small toe on the outer.
FOOT_POINTS: Dict[str, Tuple[str, Tuple[float, float, float]]] = {
    'left_big_toe': ('left_toe', (0.35, -0.08, 0.0)),
    'left_small_toe': ('left_toe', (0.15, 0.30, 0.0)),
    'right_big_toe': ('right_toe', (0.35, 0.08, 0.0)),
    'right_small_toe': ('right_toe', (0.15, -0.30, 0.0)),
}


def keypoints_3d(skeleton: Skeleton, rotations: np.ndarray,
                 root_positions: np.ndarray, placement=None) -> np.ndarray:
    """World positions (F, 23, 3) of the layout keypoints for a motion (module docstring).

    ``placement``: a :class:`~.detector_placement.DetectorPlacement` moves every point to where
    the real detector puts it (cross-synthesizer keypoints); None keeps the joints."""
    fk = forward_kinematics(skeleton.parents, skeleton.offsets, rotations, root_positions)
    pos, rot = fk.positions, fk.global_rotations
    out = np.zeros(pos.shape[:-2] + (NUM_KEYPOINTS, 3))
    for name in JOINT_KEYPOINTS:
        out[..., KEYPOINT_INDEX[name], :] = pos[..., JOINT_INDEX[name], :]
    bone = skeleton.bone_lengths()
    scale = {'head': bone[JOINT_INDEX['head']], 'left_toe': skeleton.foot_length(),
             'right_toe': skeleton.foot_length()}
    for name, (joint, local) in {**FACE_POINTS, **FOOT_POINTS}.items():
        j = JOINT_INDEX[joint]
        out[..., KEYPOINT_INDEX[name], :] = (
            pos[..., j, :] + rot[..., j, :, :] @ (scale[joint] * np.asarray(local)))
    for side in ('left', 'right'):
        j, local = skeleton.contact_points()[f'{side}_heel']
        out[..., KEYPOINT_INDEX[f'{side}_heel'], :] = pos[..., j, :] + rot[..., j, :, :] @ local
    if placement is not None:  # offsets in leg lengths (hip to ankle)
        leg = float(bone[JOINT_INDEX['left_knee']] + bone[JOINT_INDEX['left_ankle']])
        out = placement.apply(out, rot, leg)
    return out


# ---------------------------------------------------------------------------------------------
# Cameras
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class VirtualCamera:
    """A static pinhole camera in the world.

    Attributes:
        intrinsics: pixel intrinsics.
        rotation: (3, 3) world -> camera optical frame (rows: camera x, y, z in the world).
        position: (3,) camera centre in the world, metres.
    """

    intrinsics: CameraIntrinsics
    rotation: np.ndarray
    position: np.ndarray

    def world_to_camera(self, points: np.ndarray) -> np.ndarray:
        """(..., 3) world points -> optical-frame points (metres)."""
        return (np.asarray(points) - self.position) @ self.rotation.T

    def quaternion(self) -> np.ndarray:
        """(4,) x, y, z, w of the world -> camera rotation."""
        return matrix_to_quat(self.rotation)


def look_at(position: np.ndarray, target: np.ndarray, roll: float = 0.0) -> np.ndarray:
    """World -> optical-frame rotation of a camera at ``position`` looking at ``target``
    with the image's up direction as close to world +z as possible, then rolled (rad)."""
    z = np.asarray(target, float) - np.asarray(position, float)
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    if np.linalg.norm(x) < 1e-6:  # looking straight up or down
        x = np.cross(z, [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    r = np.stack([x, y, z])
    c, s = np.cos(roll), np.sin(roll)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]) @ r


@dataclass(frozen=True)
class CameraSampling:
    """Ranges for :func:`sample_camera` (uniform unless stated). Angles in degrees, metres."""

    distance: Tuple[float, float] = (3.0, 8.0)       # horizontal distance to the subject
    height: Tuple[float, float] = (0.4, 2.2)         # camera height above the floor
    azimuth: Tuple[float, float] = (-180.0, 180.0)   # around the subject, 0 = in front
    aim_jitter: float = 0.3                          # aim point offset (m, each axis)
    roll: Tuple[float, float] = (-4.0, 4.0)
    horizontal_fov: Tuple[float, float] = (45.0, 75.0)
    image_sizes: Tuple[Tuple[int, int], ...] = ((1920, 1080), (1280, 720), (1080, 1920),
                                                (640, 480), (720, 1280))
    margin: float = 0.02                             # fraction of the image kept free
    max_tries: int = 30
    #: share of cameras that look down steeply: their height is set by an elevation angle
    #: drawn from ``steep_elevation`` (degrees above the horizontal, seen from the aim point)
    #: instead of ``height``, as a camera on a wall or a ceiling sees a person. 0 (the
    #: default) draws no such camera and leaves the generator's sequence as it was
    steep_fraction: float = 0.0
    steep_elevation: Tuple[float, float] = (25.0, 65.0)


def sample_camera(points: np.ndarray, rng: np.random.Generator,
                  cfg: CameraSampling = CameraSampling(),
                  facing: Optional[np.ndarray] = None) -> VirtualCamera:
    """A random camera that sees every point of ``points`` (F, K, 3) (world, z up).

    The azimuth is measured from ``facing`` (the subject's mean forward direction in the
    world xy plane; default +x). The camera moves back along its ray until all points are
    inside the image with ``cfg.margin`` or ``cfg.max_tries`` draws are used (then it returns
    the last, farthest camera, which keeps the subject in view for any realistic clip).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    centre = pts.mean(axis=0)
    fwd = np.array([1.0, 0.0]) if facing is None else np.asarray(facing, float)[:2]
    fwd = fwd / max(np.linalg.norm(fwd), 1e-9)
    base = np.arctan2(fwd[1], fwd[0])
    w, h = cfg.image_sizes[rng.integers(len(cfg.image_sizes))]
    intr = CameraIntrinsics.from_fov(w, h, rng.uniform(*cfg.horizontal_fov))
    intr = CameraIntrinsics(w, h, intr.fx, intr.fy, intr.cx, intr.cy, approximate=False)
    az = base + np.radians(rng.uniform(*cfg.azimuth))
    dist = rng.uniform(*cfg.distance)
    height = rng.uniform(*cfg.height)
    aim = centre + rng.uniform(-cfg.aim_jitter, cfg.aim_jitter, 3) * np.array([1, 1, 0.5])
    roll = np.radians(rng.uniform(*cfg.roll))
    slope = None
    if cfg.steep_fraction > 0.0 and rng.random() < cfg.steep_fraction:
        slope = np.tan(np.radians(rng.uniform(*cfg.steep_elevation)))
    cam = None
    for _ in range(cfg.max_tries):
        if slope is not None:       # backs away along its line of sight to the aim point
            height = aim[2] + dist * slope
        position = np.array([centre[0] + dist * np.cos(az), centre[1] + dist * np.sin(az),
                             height])
        cam = VirtualCamera(intr, look_at(position, aim, roll), position)
        if in_view(cam, pts, cfg.margin):
            return cam
        dist *= 1.15
    assert cam is not None
    return cam


def in_view(camera: VirtualCamera, points: np.ndarray, margin: float = 0.0) -> bool:
    """True when every point is in front of the camera and inside the image (with margin)."""
    pc = camera.world_to_camera(points)
    if np.any(pc[..., 2] <= 0.1):
        return False
    uv = camera.intrinsics.project(pc)
    w, h = camera.intrinsics.width, camera.intrinsics.height
    mx, my = margin * w, margin * h
    return bool(np.all((uv[..., 0] >= mx) & (uv[..., 0] <= w - 1 - mx)
                       & (uv[..., 1] >= my) & (uv[..., 1] <= h - 1 - my)))


def project(camera: VirtualCamera, points_world: np.ndarray) -> np.ndarray:
    """(..., K, 3) world points -> (..., K, 3) keypoints (u px, v px, confidence 1)."""
    uv = camera.intrinsics.project(camera.world_to_camera(points_world))
    return np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))], axis=-1)


def motion_to_camera(rotations: np.ndarray, root_positions: np.ndarray,
                     camera: VirtualCamera) -> Tuple[np.ndarray, np.ndarray]:
    """Express a world motion in the camera's optical frame: only the root changes.

    Returns (F, J, 4) rotations (root row = camera_q * root_q) and (F, 3) root positions.
    """
    rot = np.array(rotations, dtype=np.float64)
    rot[:, 0] = quat_multiply(camera.quaternion(), rot[:, 0])
    return rot, camera.world_to_camera(root_positions)


# ---------------------------------------------------------------------------------------------
# Confidence model and corruption
# ---------------------------------------------------------------------------------------------
@dataclass
class ConfidenceModel:
    """Per-keypoint confidence distribution (MotioNet §4): P(c = 0) = zero_prob, else
    c ~ N(mean, std) clipped to (0, 1]. Arrays of 23 values in layout order."""

    zero_prob: np.ndarray
    mean: np.ndarray
    std: np.ndarray
    source: str = ''
    frames: int = 0

    def to_json(self, path: str | Path) -> None:
        data = {k: (v.tolist() if isinstance(v, np.ndarray) else v)
                for k, v in asdict(self).items()}
        data['keypoints'] = list(KEYPOINT_NAMES)
        Path(path).write_text(json.dumps(data, indent=1) + '\n')

    @classmethod
    def from_json(cls, path: str | Path) -> 'ConfidenceModel':
        d = json.loads(Path(path).read_text())
        if d.get('keypoints') != list(KEYPOINT_NAMES):
            raise ValueError(f'{path}: confidence model is for another keypoint layout')
        return cls(np.asarray(d['zero_prob']), np.asarray(d['mean']), np.asarray(d['std']),
                   d.get('source', ''), int(d.get('frames', 0)))

    @classmethod
    def default(cls) -> 'ConfidenceModel':
        """The model shipped with the package (fitted on real OpenPose detections; see
        ``confidence_model.json``'s ``source``)."""
        return cls.from_json(Path(__file__).with_name('confidence_model.json'))


def fit_confidence_model(confidences: np.ndarray, source: str = '') -> ConfidenceModel:
    """Fit (delta, mu, sigma) per keypoint from real detector confidences (N, 23)."""
    c = np.asarray(confidences, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] != NUM_KEYPOINTS or len(c) == 0:
        raise ValueError(f'expected (N, {NUM_KEYPOINTS}) confidences, got {c.shape}')
    zero = c <= 0
    mean = np.array([c[~zero[:, k], k].mean() if np.any(~zero[:, k]) else 0.5
                     for k in range(NUM_KEYPOINTS)])
    std = np.array([c[~zero[:, k], k].std() if np.sum(~zero[:, k]) > 1 else 0.1
                    for k in range(NUM_KEYPOINTS)])
    return ConfidenceModel(zero.mean(axis=0), mean, std, source, len(c))


@dataclass(frozen=True)
class Corruption:
    """Settings of :func:`corrupt_keypoints`."""

    beta: float = 0.04              # max displacement at c = 0, fraction of person height (px)
    extra_drop_prob: float = 0.02   # further joints set unseen at random (occlusion bursts)
    drop_frame_prob: float = 0.01   # whole frames with nobody detected
    min_confidence: float = 0.05    # lower clip of the Gaussian part


def corrupt_keypoints(keypoints: np.ndarray, rng: np.random.Generator,
                      model: ConfidenceModel, cfg: Corruption = Corruption()) -> np.ndarray:
    """Corrupt clean (F, 23, 3) pixel keypoints like a real detector (module docstring).

    Returns a new (F, 23, 3) array; unseen points are (0, 0, 0).
    """
    kp = np.array(keypoints, dtype=np.float64)
    f, k = kp.shape[:2]
    conf = np.clip(rng.normal(model.mean, model.std, (f, k)), cfg.min_confidence, 1.0)
    conf[rng.random((f, k)) < model.zero_prob] = 0.0
    conf[rng.random((f, k)) < cfg.extra_drop_prob] = 0.0
    conf[rng.random(f) < cfg.drop_frame_prob] = 0.0
    height = person_height_px(kp)
    angle = rng.uniform(0.0, 2 * np.pi, (f, k))
    radius = rng.uniform(0.0, 1.0, (f, k)) * cfg.beta * height[:, None] * (1.0 - conf)
    kp[..., 0] += radius * np.cos(angle)
    kp[..., 1] += radius * np.sin(angle)
    kp[..., 2] = conf
    kp[conf == 0] = 0.0
    return kp


def person_height_px(keypoints: np.ndarray) -> np.ndarray:
    """(F,) vertical extent of the seen keypoints per frame, pixels (clip median when a frame
    has fewer than two seen points)."""
    kp = np.asarray(keypoints)
    seen = kp[..., 2] > 0
    v = np.where(seen, kp[..., 1], np.nan)
    with np.errstate(all='ignore'):
        h = np.nanmax(v, axis=-1) - np.nanmin(v, axis=-1)
    h = np.where(seen.sum(axis=-1) >= 2, h, np.nan)
    fill = np.nanmedian(h) if np.any(np.isfinite(h)) else 0.0
    return np.where(np.isfinite(h), h, fill)


# ---------------------------------------------------------------------------------------------
# Flip
# ---------------------------------------------------------------------------------------------
def mirror_motion(rotations: np.ndarray, root_positions: np.ndarray,
                  ) -> Tuple[np.ndarray, np.ndarray]:
    """Left-right mirror of a world motion across the world xz plane (y -> -y).

    With a symmetric rest pose, the mirrored motion swaps left and right joints and maps each
    quaternion (x, y, z, w) to (-x, y, -z, w) (reflection S R S with S = diag(1, -1, 1)).
    Returns (F, J, 4) rotations and (F, 3) root positions.
    """
    rot = np.array(rotations, dtype=np.float64)[..., list(JOINT_MIRROR), :]
    rot[..., 0] *= -1.0
    rot[..., 2] *= -1.0
    root = np.array(root_positions, dtype=np.float64)
    root[..., 1] *= -1.0
    return rot, root


def mirror_keypoints(keypoints: np.ndarray, width: int) -> np.ndarray:
    """Mirror (..., 23, 3) pixel keypoints horizontally and swap left/right points."""
    kp = np.array(keypoints, dtype=np.float64)[..., list(KEYPOINT_MIRROR), :]
    seen = kp[..., 2] > 0
    kp[..., 0] = np.where(seen, (width - 1) - kp[..., 0], 0.0)
    return kp
