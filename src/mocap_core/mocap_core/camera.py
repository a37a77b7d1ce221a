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
