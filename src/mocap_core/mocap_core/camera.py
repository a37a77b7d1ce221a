"""Pinhole camera intrinsics (no ROS imports). Pixel coordinates: origin top-left, u right,
v down; camera optical frame (REP-103): x right, y down, z forward."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics without distortion: focal lengths and principal point in pixels."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    approximate: bool = False  # True when guessed from the image size and a field of view

    def __post_init__(self) -> None:
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f'image size must be positive, got {self.width}x{self.height}')
        if not (self.fx > 0 and self.fy > 0 and math.isfinite(self.cx)
                and math.isfinite(self.cy)):
            raise ValueError(f'invalid intrinsics fx={self.fx} fy={self.fy} '
                             f'cx={self.cx} cy={self.cy}')

    @classmethod
    def from_fov(cls, width: int, height: int, horizontal_fov_deg: float = 60.0,
                 ) -> 'CameraIntrinsics':
        """Approximate intrinsics: square pixels, principal point at the image centre and the
        given horizontal field of view (degrees)."""
        if not 1.0 < horizontal_fov_deg < 179.0:
            raise ValueError(f'horizontal field of view must be in (1, 179) degrees, '
                             f'got {horizontal_fov_deg}')
        f = 0.5 * width / math.tan(math.radians(horizontal_fov_deg) / 2.0)
        return cls(int(width), int(height), f, f, (width - 1) / 2.0, (height - 1) / 2.0,
                   approximate=True)

    @property
    def K(self) -> np.ndarray:
        """(3, 3) camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def back_project(self, uv: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """Pixels (..., 2) at depths (...) metres -> points (..., 3) in the optical frame:
        X = Z (u - cx) / fx, Y = Z (v - cy) / fy."""
        uv = np.asarray(uv, dtype=np.float64)
        z = np.asarray(depth, dtype=np.float64)
        return np.stack([z * (uv[..., 0] - self.cx) / self.fx,
                         z * (uv[..., 1] - self.cy) / self.fy, z], axis=-1)

    def project(self, points: np.ndarray) -> np.ndarray:
        """Points (..., 3) in the optical frame (z > 0) -> pixels (..., 2)."""
        p = np.asarray(points, dtype=np.float64)
        return np.stack([self.fx * p[..., 0] / p[..., 2] + self.cx,
                         self.fy * p[..., 1] / p[..., 2] + self.cy], axis=-1)


def scale_intrinsics(intr: CameraIntrinsics, width: int, height: int) -> CameraIntrinsics:
    """The same camera at another resolution (a resized image): focal lengths and principal
    point scaled per axis (pixel-centre convention: c' = (c + 0.5) s - 0.5)."""
    sx, sy = width / intr.width, height / intr.height
    return CameraIntrinsics(int(width), int(height), intr.fx * sx, intr.fy * sy,
                            (intr.cx + 0.5) * sx - 0.5, (intr.cy + 0.5) * sy - 0.5,
                            approximate=intr.approximate)


@dataclass(frozen=True)
class CameraCalibration:
    """A camera calibration as ROS stores it (camera_info YAML, sensor_msgs/CameraInfo):
    intrinsics plus the lens distortion model and coefficients (``plumb_bob``:
    k1, k2, p1, p2, k3; ``rational_polynomial``: 8 coefficients; ``equidistant``: 4)."""

    intrinsics: CameraIntrinsics
    distortion_model: str = 'plumb_bob'
    distortion: tuple = ()
    camera_name: str = ''

    @property
    def has_distortion(self) -> bool:
        return any(abs(float(d)) > 0.0 for d in self.distortion)


def _yaml_matrix(data: dict, key: str, rows: int, cols: int, path) -> np.ndarray:
    block = data.get(key)
    if not isinstance(block, dict) or 'data' not in block:
        raise ValueError(f'{path}: missing "{key}: {{rows, cols, data}}"')
    values = np.asarray(block['data'], dtype=np.float64).reshape(-1)
    if rows and cols and values.size != rows * cols:
        raise ValueError(f'{path}: "{key}" has {values.size} values, expected {rows * cols}')
    return values


def read_camera_info_yaml(path) -> CameraCalibration:
    """Read the standard ROS camera_info YAML (written by camera_calibration /
    camera_calibration_parsers)::

        image_width: 640
        image_height: 480
        camera_name: webcam
        camera_matrix: {rows: 3, cols: 3, data: [fx, 0, cx, 0, fy, cy, 0, 0, 1]}
        distortion_model: plumb_bob
        distortion_coefficients: {rows: 1, cols: 5, data: [k1, k2, p1, p2, k3]}
        rectification_matrix: ...   # ignored (monocular)
        projection_matrix: ...      # ignored

    Raises FileNotFoundError for a missing file and ValueError (naming the file) for a file
    that is not such a YAML or holds invalid values.
    """
    import yaml
    from pathlib import Path

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f'calibration file not found: {p}')
    try:
        data = yaml.safe_load(p.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise ValueError(f'{p}: cannot read calibration YAML ({exc})') from None
    if not isinstance(data, dict):
        raise ValueError(f'{p}: not a camera_info YAML (expected a mapping)')
    try:
        width, height = int(data['image_width']), int(data['image_height'])
        k = _yaml_matrix(data, 'camera_matrix', 3, 3, p)
        d = data.get('distortion_coefficients') or {'data': []}
        dist = tuple(float(v) for v in np.asarray(d.get('data') or [], dtype=np.float64))
        intr = CameraIntrinsics(width, height, float(k[0]), float(k[4]), float(k[2]),
                                float(k[5]))
    except KeyError as exc:
        raise ValueError(f'{p}: missing {exc.args[0]!r}') from None
    except (TypeError, ValueError) as exc:
        raise ValueError(f'{p}: invalid calibration ({exc})') from None
    if not all(math.isfinite(v) for v in dist):
        raise ValueError(f'{p}: non-finite distortion coefficients')
    return CameraCalibration(intr, str(data.get('distortion_model') or 'plumb_bob'), dist,
                             str(data.get('camera_name') or ''))


def write_camera_info_yaml(calib: CameraCalibration, path) -> None:
    """Write ``calib`` in the standard camera_info YAML format (see read_camera_info_yaml)."""
    import yaml
    from pathlib import Path

    intr = calib.intrinsics
    k = [float(v) for v in intr.K.reshape(-1)]
    dist = [float(v) for v in calib.distortion]
    data = {
        'image_width': int(intr.width), 'image_height': int(intr.height),
        'camera_name': calib.camera_name or 'camera',
        'camera_matrix': {'rows': 3, 'cols': 3, 'data': k},
        'distortion_model': calib.distortion_model,
        'distortion_coefficients': {'rows': 1, 'cols': len(dist), 'data': dist},
        'rectification_matrix': {'rows': 3, 'cols': 3,
                                 'data': [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]},
        'projection_matrix': {'rows': 3, 'cols': 4,
                              'data': [k[0], 0.0, k[2], 0.0, 0.0, k[4], k[5], 0.0,
                                       0.0, 0.0, 1.0, 0.0]},
    }
    Path(path).write_text(yaml.safe_dump(data, sort_keys=False))


def world_to_optical(R: np.ndarray, position: np.ndarray, points: np.ndarray) -> np.ndarray:
    """World points into a moving camera's optical frame.

    Args:
        R: (F, 3, 3) world-to-optical rotations, one per frame.
        position: (F, 3) camera centres in the world frame, metres.
        points: (F, N, 3) world points, metres.
    Returns:
        (F, N, 3) points in the optical frame (x right, y down, z forward), metres.
    """
    return np.einsum('fij,fkj->fki', np.asarray(R), np.asarray(points) -
                     np.asarray(position)[:, None])


def optical_to_world(R: np.ndarray, position: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The inverse of :func:`world_to_optical`: a moving camera's optical-frame points into
    the world (same arguments; ``points`` (F, N, 3) in the optical frame), metres."""
    return np.einsum('fji,fkj->fki', np.asarray(R), np.asarray(points)) + \
        np.asarray(position)[:, None]


def project_pinhole(K: np.ndarray, points: np.ndarray, min_depth: float = 1e-3
                    ) -> np.ndarray:
    """(..., 3) optical-frame points -> (..., 3) pixels u, v and a visibility flag 1; points
    less than ``min_depth`` metres in front of the camera give (0, 0, 0), the layout's
    missing point. ``K`` is the (3, 3) pinhole matrix (no skew, no distortion)."""
    pc = np.asarray(points, dtype=np.float64)
    z = pc[..., 2:3]
    ok = z > min_depth
    uv = pc[..., :2] / np.where(ok, z, 1.0) * np.asarray(K)[[0, 1], [0, 1]] + \
        np.asarray(K)[:2, 2]
    return np.where(ok, np.concatenate([uv, np.ones_like(z)], axis=-1), 0.0)
