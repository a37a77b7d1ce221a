"""Camera paths for rendered clips: static, panning, orbiting, hand-held, following (no ROS).

A path is one pinhole intrinsics plus a per-frame pose: ``R`` (F, 3, 3) world -> optical
frame (x right, y down, z forward) and ``position`` (F, 3) the centre, world frame z up,
metres (the convention of :class:`mocap_core.data.synth2d.VirtualCamera`).

Kinds (:data:`CAMERA_KINDS`):

* ``static`` -- a tripod: fixed pose aimed at the clip's centre;
* ``pan`` -- a tripod that turns to follow the person (smoothed, lagging aim);
* ``orbit`` -- moves 60-120 degrees around the person at a fixed distance, aimed at them;
* ``handheld`` -- ``pan`` plus shake: a smoothed random walk of 0.5-2 degrees in rotation and
  1-3 cm in position;
* ``follow`` -- walks with the person, keeping its offset (e.g. behind someone walking away).

The ranges (:class:`CameraRanges`) are wider than the projected-keypoint sampler's
(``data/synth2d.CameraSampling``): heights 0.2-3.5 m, horizontal field of view 35-100 degrees,
portrait and landscape images, and the distance that makes the person 35-90 % of the image
height (1.5-25 m; BlazePose misses most people below ~130 px). A fraction of static / pan
clips aims off the person so that part of the body leaves the image (``partial``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Dict, Tuple

import numpy as np

from ..camera import CameraIntrinsics
from ..data.synth2d import look_at

CAMERA_KINDS: Tuple[str, ...] = ('static', 'pan', 'orbit', 'handheld', 'follow')


@dataclass(frozen=True)
class CameraRanges:
    """Ranges drawn uniformly per clip. Angles in degrees, distances in metres."""

    kind_weights: Tuple[float, ...] = (0.35, 0.2, 0.15, 0.15, 0.15)   # CAMERA_KINDS order
    person_fraction: Tuple[float, float] = (0.35, 0.9)  # body height / image height
    distance: Tuple[float, float] = (1.5, 25.0)         # bounds on the resulting distance
    height: Tuple[float, float] = (0.2, 3.5)
    horizontal_fov: Tuple[float, float] = (35.0, 100.0)
    image_sizes: Tuple[Tuple[int, int], ...] = ((640, 480), (640, 480), (480, 640),
                                                (640, 360), (360, 640), (960, 540))
    roll: Tuple[float, float] = (-5.0, 5.0)
    orbit_degrees: Tuple[float, float] = (60.0, 120.0)
    partial_fraction: float = 0.1
    margin: float = 0.03


@dataclass
class CameraPath:
    """One clip's camera (module docstring). ``kind`` in :data:`CAMERA_KINDS`; ``partial``:
    aimed so that part of the body may leave the image."""

    kind: str
    intrinsics: CameraIntrinsics
    R: np.ndarray
    position: np.ndarray
    partial: bool = False

    def K(self) -> np.ndarray:
        i = self.intrinsics
        return np.array([[i.fx, 0.0, i.cx], [0.0, i.fy, i.cy], [0.0, 0.0, 1.0]])

    def world_to_camera(self, points: np.ndarray) -> np.ndarray:
        """(F, N, 3) world points -> (F, N, 3) optical-frame points."""
        return np.einsum('fij,fnj->fni', self.R, points - self.position[:, None])

    def describe(self) -> Dict:
        i = self.intrinsics
        return {'kind': self.kind, 'partial': self.partial, 'width': i.width,
                'height': i.height, 'fx': i.fx, 'fy': i.fy, 'cx': i.cx, 'cy': i.cy}


def _smooth(x: np.ndarray, frames: float) -> np.ndarray:
    """Forward-backward exponential smoothing along axis 0 (time constant in frames)."""
    if frames <= 0 or len(x) < 2:
        return x.copy()
    a = 1.0 / (1.0 + frames)
    y = x.copy()
    for i in range(1, len(y)):
        y[i] = y[i - 1] + a * (x[i] - y[i - 1])
    for i in range(len(y) - 2, -1, -1):
        y[i] = y[i + 1] + a * (y[i] - y[i + 1])
    return y


def _rotation_about(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(F, 3, 3) rotations by ``angle`` (F,) rad about unit vectors ``axis`` (F, 3)."""
    axis = axis / np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), 1e-12)
    x, y, z = axis[..., 0], axis[..., 1], axis[..., 2]
    c, s = np.cos(angle), np.sin(angle)
    C = 1 - c
    return np.stack([
        np.stack([c + x * x * C, x * y * C - z * s, x * z * C + y * s], -1),
        np.stack([y * x * C + z * s, c + y * y * C, y * z * C - x * s], -1),
        np.stack([z * x * C - y * s, z * y * C + x * s, c + z * z * C], -1)], -2)


def _fits(R, position, intr: CameraIntrinsics, points: np.ndarray, margin: float) -> bool:
    pc = np.einsum('fij,fnj->fni', R, points - position[:, None])
    if np.any(pc[..., 2] <= 0.2):
        return False
    uv = intr.project(pc)
    w, h = intr.width, intr.height
    return bool(np.all((uv[..., 0] >= margin * w) & (uv[..., 0] <= (1 - margin) * w)
                       & (uv[..., 1] >= margin * h) & (uv[..., 1] <= (1 - margin) * h)))


def sample_camera_path(points: np.ndarray, facing: np.ndarray, rng: np.random.Generator,
                       ranges: CameraRanges = CameraRanges(), kind: str = '') -> CameraPath:
    """A camera path for a clip whose body points are ``points`` (F, N, 3) world.

    Args:
        points: what must stay in view (joints and a few mesh points), per frame.
        facing: (2,) the person's mean facing in the world xy plane (azimuth 0 = in front).
        rng: the clip's generator.
        ranges: the sampled ranges.
        kind: force one of :data:`CAMERA_KINDS` ('' draws it with ``ranges.kind_weights``).
    """
    points = np.asarray(points, dtype=np.float64)
    F = len(points)
    if not kind:
        w = np.asarray(ranges.kind_weights, dtype=float)
        kind = CAMERA_KINDS[rng.choice(len(CAMERA_KINDS), p=w / w.sum())]
    if kind not in CAMERA_KINDS:
        raise ValueError(f'unknown camera kind {kind!r}; known: {", ".join(CAMERA_KINDS)}')
    width, height = ranges.image_sizes[rng.integers(len(ranges.image_sizes))]
    hfov = rng.uniform(*ranges.horizontal_fov)
    base = CameraIntrinsics.from_fov(width, height, hfov)
    intr = CameraIntrinsics(width, height, base.fx, base.fy, base.cx, base.cy,
                            approximate=False)
    centre = points.reshape(-1, 3).mean(axis=0)
    track = points.mean(axis=1)                       # (F, 3) per-frame body centre
    f = np.asarray(facing, dtype=float)[:2]
    f = f / max(np.linalg.norm(f), 1e-9)
    azimuth = np.arctan2(f[1], f[0]) + rng.uniform(-np.pi, np.pi)
    cam_height = rng.uniform(*ranges.height)
    roll = np.radians(rng.uniform(*ranges.roll))
    partial = kind in ('static', 'pan') and rng.random() < ranges.partial_fraction
    extent = float(np.ptp(points[..., 2], axis=1).mean())        # body height in the clip
    fraction = rng.uniform(*ranges.person_fraction)
    distance = float(np.clip(intr.fy * extent / (fraction * height), *ranges.distance))
    aim_jitter = rng.uniform(-0.25, 0.25, 3) * np.array([1.0, 1.0, 0.6])
    sweep = np.radians(rng.uniform(*ranges.orbit_degrees)) * rng.choice([-1.0, 1.0])
    shake_deg, shake_m = rng.uniform(0.5, 2.0), rng.uniform(0.01, 0.03)
    shake_rot = _smooth(rng.normal(size=(F, 3)), 4.0)
    shake_pos = _smooth(rng.normal(size=(F, 3)), 6.0)

    def build(dist: float) -> Tuple[np.ndarray, np.ndarray]:
        aim_static = centre + aim_jitter
        aim_track = _smooth(track, 8.0) + aim_jitter
        if kind == 'orbit':
            az = azimuth + sweep * np.linspace(0.0, 1.0, F)
        else:
            az = np.full(F, azimuth)
        if kind == 'follow':
            anchor = _smooth(track, 15.0)
        elif kind == 'orbit':
            anchor = aim_track
        else:
            anchor = np.tile(centre, (F, 1))
        pos = np.stack([anchor[:, 0] + dist * np.cos(az), anchor[:, 1] + dist * np.sin(az),
                        np.full(F, cam_height)], axis=1)
        aim = np.tile(aim_static, (F, 1)) if kind == 'static' else aim_track
        R = np.stack([look_at(p, a, roll) for p, a in zip(pos, aim)])
        if kind == 'handheld':
            scale = np.radians(shake_deg) / max(np.abs(shake_rot).max(), 1e-9)
            angle = np.linalg.norm(shake_rot, axis=1) * scale
            R = np.einsum('fij,fjk->fik', _rotation_about(shake_rot, angle), R)
            pos = pos + shake_pos * (shake_m / max(np.abs(shake_pos).max(), 1e-9))
        return R, pos

    if partial:
        # Aim off the body: shift the aim sideways / vertically by up to 60 % of the view.
        off = rng.uniform(0.3, 0.6) * distance * np.tan(np.radians(hfov) / 2)
        aim_jitter = aim_jitter + np.array([*rng.normal(size=2), 0.0]) * off / np.sqrt(2)
        R, pos = build(distance)
    else:
        for _ in range(40):
            R, pos = build(distance)
            if _fits(R, pos, intr, points, ranges.margin):
                break
            distance *= 1.12
    return CameraPath(kind, intr, R, pos, partial)


def view_labels(camera_position: np.ndarray, pelvis: np.ndarray,
                facing: np.ndarray) -> np.ndarray:
    """Per frame ``'front'``, ``'side'`` or ``'back'``: the angle between the person's facing
    (F, 2) and the direction to the camera in the xy plane (front < 45 deg, back > 135 deg)."""
    to_cam = np.asarray(camera_position)[:, :2] - np.asarray(pelvis)[:, :2]
    f = np.asarray(facing)[:, :2]
    cos = np.sum(to_cam * f, axis=1) / np.maximum(
        np.linalg.norm(to_cam, axis=1) * np.linalg.norm(f, axis=1), 1e-9)
    ang = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return np.where(ang < 45.0, 'front', np.where(ang > 135.0, 'back', 'side'))


def ranges_dict(r: CameraRanges) -> Dict:
    return asdict(r)
