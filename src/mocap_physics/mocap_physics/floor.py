"""The floor frame of the dynamics and its relation to the camera frame (no ROS imports).

The physics cycle runs in a **floor frame**: z up, the floor is the plane z = 0, gravity is
(0, 0, -9.81), x is the camera's viewing direction projected onto the floor, y points left,
and the origin is the point of the floor below the camera centre. Incoming motion in the
camera's optical frame (REP-103: x right, y down, z forward) is mapped into it by a rigid
transform ``T_floor_camera`` (:class:`FloorFrame`)::

    p_floor = R p_camera + t,      R rows = (x_f, y_f, z_f) in camera axes,  t = (0, 0, h)

where z_f = n is the floor's upward unit normal in camera axes and h the camera's height
above the floor (the plane is ``n . p_camera + h = 0``). The inverse maps the outputs back.
The node publishes this transform (geometry_msgs/TransformStamped, header.frame_id = the
camera frame, child_frame_id = the floor frame, i.e. the pose of the floor frame in the
camera frame = ``T_floor_camera^-1``) on ``/mocap/physics/floor``.

Sources of the floor (the node's ``floor_source``):

* ``input``: :meth:`FloorFrame.identity`, the input already is in a floor frame (e.g. the
  ground-truth motion in ``world``);
* ``camera_params``: :meth:`FloorFrame.from_camera_height_pitch`, a level floor below a
  camera of known height and pitch (no roll);
* ``estimate``: :class:`FloorTracker` fits the plane to the foot contact points (heel and
  toe) of the incoming motion while the contact probabilities say they touch the floor, over
  a sliding window (:func:`fit_floor_plane`: RANSAC for the inliers, then a least-squares
  plane through them, regularised towards a prior "up" direction for the rotations that
  the points cannot determine, e.g. a person standing still or walking along a line).
"""

from __future__ import annotations

import collections
from dataclasses import dataclass, field
from typing import Deque, Optional, Sequence, Tuple

import numpy as np

from mocap_core.pose import Pose
from mocap_core.rotations import (axis_angle_to_matrix, matrix_to_quat, quat_multiply,
                                  quat_slerp, quat_to_matrix)

from .foot import contact_positions

#: The camera optical frame's "up" (-y): the prior of the floor normal when nothing better
#: is known (a camera held roughly level).
CAMERA_UP = np.array([0.0, -1.0, 0.0])
_EYE3 = np.eye(3)


@dataclass(frozen=True)
class FloorFrame:
    """Rigid transform from a source frame (camera or world) to the floor frame.

    Attributes:
        rotation: (3, 3) R with ``p_floor = R p_source + translation``.
        translation: (3,) metres.
        source_frame: name of the source frame (for messages and logs).
    """

    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    source_frame: str = 'floor'

    def __post_init__(self) -> None:
        R = np.asarray(self.rotation, dtype=float)
        t = np.asarray(self.translation, dtype=float).reshape(3)
        if R.shape != (3, 3) or not np.abs(R @ R.T - _EYE3).max() <= 1e-6 \
                or np.linalg.det(R) < 0:
            raise ValueError('floor rotation must be a proper 3x3 rotation matrix')
        if not np.all(np.isfinite(t)):
            raise ValueError('floor translation must be finite')
        object.__setattr__(self, 'rotation', R)
        object.__setattr__(self, 'translation', t)

    @classmethod
    def identity(cls, source_frame: str = 'floor') -> 'FloorFrame':
        """The input already is in a floor frame (z up, floor at z = 0)."""
        return cls(source_frame=source_frame)

    @classmethod
    def from_camera_height_pitch(cls, height: float, pitch: float,
                                 source_frame: str = 'camera') -> 'FloorFrame':
        """Camera optical frame -> floor frame for a camera ``height`` metres above the floor,
        pitched down by ``pitch`` radians (0 = optical axis parallel to the floor), no roll.

        The floor origin is the point on the floor below the camera.
        """
        if not np.isfinite(height) or height < 0:
            raise ValueError(f'camera height must be >= 0, got {height}')
        c, s = np.cos(pitch), np.sin(pitch)
        forward = np.array([c, 0.0, -s])      # optical z
        right = np.array([0.0, -1.0, 0.0])    # optical x
        down = np.cross(forward, right)       # optical y
        R = np.stack([right, down, forward], axis=1)
        return cls(R, np.array([0.0, 0.0, float(height)]), source_frame)

    @classmethod
    def from_plane(cls, normal: np.ndarray, offset: float,
                   forward: np.ndarray = np.array([0.0, 0.0, 1.0]),
                   source_frame: str = 'camera') -> 'FloorFrame':
        """Floor frame of the plane ``normal . p + offset = 0`` (source frame), ``normal`` the
        upward normal: z = normal, x = ``forward`` (default: the optical axis) projected onto
        the floor, origin = the foot of the perpendicular from the source origin (the camera
        centre), so ``translation = (0, 0, offset)`` and offset is the camera height."""
        n = np.asarray(normal, dtype=float).reshape(3)
        norm = np.linalg.norm(n)
        if not (np.isfinite(norm) and norm > 1e-9 and np.isfinite(offset)):
            raise ValueError('floor plane must have a finite, non-zero normal and offset')
        n = n / norm
        f = np.asarray(forward, dtype=float).reshape(3)
        x = f - (f @ n) * n
        if np.linalg.norm(x) < 1e-6:    # looking straight down or up: use the camera's x
            x = np.array([1.0, 0.0, 0.0]) - n[0] * n
        x /= np.linalg.norm(x)
        y = np.cross(n, x)
        return cls(np.stack([x, y, n]), np.array([0.0, 0.0, float(offset)]), source_frame)

    # -- use ---------------------------------------------------------------------------------
    def inverse(self) -> 'FloorFrame':
        """The transform from the floor frame back to the source frame."""
        R_inv = self.rotation.T
        return FloorFrame(R_inv, -R_inv @ self.translation, 'floor')

    def compose(self, other: 'FloorFrame') -> 'FloorFrame':
        """``self o other``: first ``other``, then ``self``."""
        return FloorFrame(self.rotation @ other.rotation,
                          self.rotation @ other.translation + self.translation,
                          other.source_frame)

    def transform_points(self, points: np.ndarray) -> np.ndarray:
        return np.asarray(points, dtype=float) @ self.rotation.T + self.translation

    def transform_pose(self, pose: Pose) -> Pose:
        """``pose`` (in the source frame) expressed in the floor frame."""
        rot = np.array(pose.rotations)
        q_frame = matrix_to_quat(self.rotation)
        rot[0] = quat_multiply(q_frame, rot[0])
        return Pose(pose.skeleton, rot, self.transform_points(pose.root_position))

    def quaternion(self) -> np.ndarray:
        """(4,) x, y, z, w rotation of the transform."""
        return matrix_to_quat(self.rotation)

    @property
    def normal(self) -> np.ndarray:
        """The floor's upward normal in source axes."""
        return self.rotation[2].copy()

    @property
    def height(self) -> float:
        """Height of the source origin (the camera centre) above the floor, m."""
        return float(self.translation[2])

    def plane(self) -> Tuple[np.ndarray, float]:
        """(normal, offset) of the floor in the source frame: ``normal . p + offset = 0``."""
        return self.normal, float(self.rotation[2] @ np.zeros(3) + self.translation[2])

    def interpolate(self, other: 'FloorFrame', s: float) -> 'FloorFrame':
        """The frame a fraction ``s`` in [0, 1] of the way from ``self`` (0) to ``other``
        (1): the rotation along the shortest arc (slerp), the translation on a straight
        line; the source frame is ``other``'s."""
        s = float(np.clip(s, 0.0, 1.0))
        if s >= 1.0:
            return other
        rel = other.rotation @ self.rotation.T                # self -> other
        angle = float(np.arccos(np.clip((np.trace(rel) - 1.0) / 2.0, -1.0, 1.0)))
        sin = np.sin(angle)
        if angle < 1e-12:
            R = self.rotation
        elif sin < 1e-6:            # a half turn: the axis is ill-defined here, take slerp
            q = quat_slerp(matrix_to_quat(self.rotation), matrix_to_quat(other.rotation), s)
            R = quat_to_matrix(q)
        else:                       # Rodrigues: a fraction s of the relative turn
            # (written out: it runs every frame of a blend; matrix_to_axis_angle and
            # axis_angle_to_matrix give the same rotation in 0.11 ms against 0.02 here)
            axis = np.array([rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0],
                             rel[1, 0] - rel[0, 1]]) / (2.0 * sin)
            K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                          [-axis[1], axis[0], 0.0]])
            a = s * angle
            R = (np.eye(3) + np.sin(a) * K + (1.0 - np.cos(a)) * (K @ K)) @ self.rotation
        t = (1.0 - s) * self.translation + s * other.translation
        return FloorFrame(R, t, other.source_frame)

    def difference(self, other: 'FloorFrame') -> Tuple[float, float]:
        """(angle between the floor normals in rad, height difference of the source origin
        in m): how much the floor plane itself differs (the in-plane axes may differ)."""
        c = float(np.clip(self.normal @ other.normal, -1.0, 1.0))
        return float(np.arccos(c)), abs(self.height - other.height)


# ---------------------------------------------------------------------------------------------
# plane fitting
# ---------------------------------------------------------------------------------------------
@dataclass
class PlaneFit:
    """A floor plane ``normal . p + offset = 0`` (normal = unit, upward) and how it was found.

    points: number of candidate points; inliers: those within the inlier threshold;
    rms: RMS distance of the inliers, m; extent: (2,) standard deviations of the inliers
    along the plane's two principal in-plane directions, m (small second value = the points
    lie on a line: the prior decided that rotation); prior_angle: angle between the normal and
    the prior, rad; source: 'points' or 'prior' (too few points: the prior through the lowest
    ones).
    """

    normal: np.ndarray
    offset: float
    points: int
    inliers: int
    rms: float
    extent: np.ndarray
    prior_angle: float
    source: str = 'points'

    def frame(self, forward: np.ndarray = np.array([0.0, 0.0, 1.0]),
              source_frame: str = 'camera') -> FloorFrame:
        return FloorFrame.from_plane(self.normal, self.offset, forward, source_frame)


def _unit(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=float).reshape(3)
    n = np.linalg.norm(v)
    if not (np.isfinite(n) and n > 1e-12):
        raise ValueError('direction must be finite and non-zero')
    return v / n


def _regularised_plane(points: np.ndarray, weights: np.ndarray, prior: np.ndarray,
                       prior_weight: float) -> Tuple[np.ndarray, float]:
    """Least-squares plane with a penalty ``prior_weight * sin^2(angle(n, prior))``:
    n = smallest eigenvector of ``C + prior_weight (I - prior prior^T)``, C the weighted
    scatter matrix about the weighted centroid; oriented along the prior."""
    w = weights / weights.sum()
    c = w @ points
    d = points - c
    C = (d * weights[:, None]).T @ d
    A = C + prior_weight * (np.eye(3) - np.outer(prior, prior))
    vals, vecs = np.linalg.eigh(A)
    n = vecs[:, 0]
    if n @ prior < 0:
        n = -n
    return n, float(-n @ c)


def _weighted_quantile(values: np.ndarray, weights: np.ndarray, q: float) -> float:
    """The value below which a fraction ``q`` of the weight lies (the first sorted value whose
    cumulative weight reaches it)."""
    order = np.argsort(values)
    cw = np.cumsum(weights[order])
    k = min(int(np.searchsorted(cw, q * cw[-1])), len(values) - 1)
    return float(values[order][k])


def fit_floor_plane(points: np.ndarray, weights: Optional[np.ndarray] = None,
                    prior: np.ndarray = CAMERA_UP, prior_weight_m: float = 0.25,
                    inlier_threshold: float = 0.025, max_tilt_deg: float = 60.0,
                    iterations: int = 64, min_points: int = 8,
                    offset_quantile: float = 0.25,
                    rng: Optional[np.random.Generator] = None) -> PlaneFit:
    """Robust floor plane through foot contact points (source frame, e.g. camera).

    1. RANSAC: planes through 3 random points (normal within ``max_tilt_deg`` of the prior)
       keep the largest set of points within ``inlier_threshold`` of them (a foot wrongly
       predicted in contact, a detector glitch, a step onto a stair are outliers).
    2. A weighted least-squares plane through the inliers, regularised towards ``prior`` by
       an equivalent in-plane spread of ``prior_weight_m`` (:func:`_regularised_plane`): the
       tilt along a direction in which the points spread much more than that (walking
       several metres: std 1.4 m vs 0.25 m, 30 times the weight of the prior) comes from
       the points; across a direction in which they do not (the two feet of a person walking
       straight, std ~5 cm; both directions for a person standing), from the prior. A foot
       patch cannot give the tilt: a few mm of height difference between heel and toe or
       left and right foot tilt it by degrees. Refined twice with the inliers of the refined
       plane.
    3. The offset puts the ``offset_quantile`` weighted quantile of the inlier heights on
       the floor (default: the lower quartile, as contact labels include heels and toes a
       little above the floor during roll-over, while the floor is where the feet rest).

    Args:
        points: (N, 3) contact point positions. weights: (N,) >= 0 (e.g. probabilities).
        prior: upward direction expected (camera -y by default, or the body's up).
        min_points: fewer points than this: the plane with the prior normal through the
            lowest points (``source='prior'``).
    Raises:
        ValueError: no finite point at all.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    w = np.ones(len(p)) if weights is None else np.asarray(weights, dtype=float).reshape(-1)
    ok = np.all(np.isfinite(p), axis=1) & np.isfinite(w) & (w > 0)
    p, w = p[ok], w[ok]
    prior = _unit(prior)
    if len(p) == 0:
        raise ValueError('no finite contact point to fit a floor to')
    if len(p) < min_points:
        h = p @ prior
        offset = -float(np.percentile(h, 10))
        return PlaneFit(prior.copy(), offset, len(p), len(p),
                        float(np.sqrt(np.mean((h + offset) ** 2))), np.zeros(2), 0.0, 'prior')
    rng = np.random.default_rng(0) if rng is None else rng
    cos_tilt = np.cos(np.radians(max_tilt_deg))
    best_mask, best_score = None, -1.0
    # the prior plane through the median height is always a candidate
    h0 = p @ prior
    cand = [(prior, -float(np.median(h0)))]
    n_pts = len(p)
    for _ in range(iterations):
        i, j, k = rng.choice(n_pts, 3, replace=False)
        n = np.cross(p[j] - p[i], p[k] - p[i])
        norm = np.linalg.norm(n)
        if norm < 1e-6:
            continue
        n = n / norm
        if n @ prior < 0:
            n = -n
        if n @ prior < cos_tilt:
            continue
        cand.append((n, -float(n @ p[i])))
    for n, off in cand:
        mask = np.abs(p @ n + off) <= inlier_threshold
        score = float(w[mask].sum())
        if score > best_score:
            best_score, best_mask = score, mask
    mask = best_mask
    if mask.sum() < 3:
        mask = np.ones(n_pts, dtype=bool)
    n, off = prior, 0.0
    for _ in range(3):
        wi = w[mask]
        lam = float(wi.sum()) * prior_weight_m ** 2
        n, off = _regularised_plane(p[mask], wi, prior, lam)
        new_mask = np.abs(p @ n + off) <= inlier_threshold
        if new_mask.sum() < 3 or np.array_equal(new_mask, mask):
            break
        mask = new_mask
    # offset: weighted quantile of the inlier heights
    off = -_weighted_quantile(p[mask] @ n, w[mask], offset_quantile)
    resid = p[mask] @ n + off
    d = p[mask] - p[mask].mean(axis=0)
    d = d - np.outer(d @ n, n)
    ext = np.sqrt(np.maximum(np.linalg.eigvalsh(d.T @ d / len(d))[::-1][:2], 0.0))
    return PlaneFit(n, off, n_pts, int(mask.sum()), float(np.sqrt(np.mean(resid ** 2))), ext,
                    float(np.arccos(np.clip(n @ prior, -1.0, 1.0))), 'points')


def fit_floor_height(heights: np.ndarray, weights: Optional[np.ndarray] = None,
                     inlier_threshold: float = 0.025, offset_quantile: float = 0.25,
                     iterations: int = 64, rng: Optional[np.random.Generator] = None
                     ) -> Tuple[float, int]:
    """The floor's height along a known up direction from contact point heights (m).

    The one-dimensional counterpart of :func:`fit_floor_plane` when the normal is known (a
    known camera pose gives gravity): the candidate heights (the weighted median and
    ``iterations`` random points) keep the points within ``inlier_threshold`` of them; the
    largest weight of inliers wins, and the height is the ``offset_quantile`` weighted
    quantile of its inliers (the feet rest on the floor, roll-over lifts heels and toes).

    Args:
        heights: (N,) m. weights: (N,) >= 0 (default 1).
    Returns:
        (floor height, inliers).
    Raises:
        ValueError: no finite height with a positive weight.
    """
    h = np.asarray(heights, dtype=float).reshape(-1)
    w = np.ones(len(h)) if weights is None else np.asarray(weights, dtype=float).reshape(-1)
    ok = np.isfinite(h) & np.isfinite(w) & (w > 0)
    h, w = h[ok], w[ok]
    if len(h) == 0:
        raise ValueError('no finite contact point to fit a floor height to')
    rng = np.random.default_rng(0) if rng is None else rng
    cand = [_weighted_quantile(h, w, 0.5)]
    cand += list(h[rng.integers(0, len(h), min(iterations, len(h)))])
    best, best_score = None, -1.0
    for c in cand:
        mask = np.abs(h - c) <= inlier_threshold
        score = float(w[mask].sum())
        if score > best_score:
            best, best_score = mask, score
    return _weighted_quantile(h[best], w[best], offset_quantile), int(best.sum())


def body_up(pose: Pose) -> np.ndarray:
    """The body's up direction in the pose's frame: from the mid-ankles to the neck (a
    standing or walking person's average of it is close to vertical)."""
    names = pose.skeleton.joint_names
    pos = pose.joint_positions()
    ankles = 0.5 * (pos[names.index('left_ankle')] + pos[names.index('right_ankle')])
    return _unit(pos[names.index('neck')] - ankles)


# ---------------------------------------------------------------------------------------------
# online estimate
# ---------------------------------------------------------------------------------------------
class UprightPrior:
    """The target turned upright on average in a known gravity (opt-in: the physics node's
    ``upright_from_camera_pose``).

    A camera's pitch hides how far the person leans toward or away from it, and the lifted
    body leans by a few degrees per clip (docs/lifter.md, "What the keypoints cannot tell").
    With the camera's pose known in a z-up world, each target's body up (:func:`body_up`)
    is moved into that world and averaged over the last ``window`` frames; the whole target
    is turned about its root by the rotation taking that mean to the world's up, at most
    ``max_angle_deg``. A person who bows or leans for longer than the window is turned
    upright too: this is a prior, not a measurement.
    """

    def __init__(self, window: int = 60, max_angle_deg: float = 10.0) -> None:
        if int(window) < 1 or not (np.isfinite(max_angle_deg) and max_angle_deg >= 0):
            raise ValueError(f'bad upright prior: window {window}, max angle {max_angle_deg}')
        self._ups: Deque[np.ndarray] = collections.deque(maxlen=int(window))
        self.max_angle = float(np.radians(max_angle_deg))
        #: the last correction, rad
        self.angle = 0.0

    def apply(self, pose: Pose, R_wc: np.ndarray) -> Pose:
        """``pose`` (camera frame) turned about its root; ``R_wc`` (3, 3): the camera's
        rotation into the z-up world (``p_world = R_wc p_camera + t``)."""
        R_wc = np.asarray(R_wc, dtype=float)
        try:
            up = body_up(pose)
        except ValueError:
            return pose
        if not (np.all(np.isfinite(up)) and np.all(np.isfinite(R_wc))):
            return pose
        self._ups.append(R_wc @ up)
        m = np.mean(np.asarray(self._ups), axis=0)
        n = float(np.linalg.norm(m))
        if n < 1e-9:
            return pose
        m /= n
        axis = np.cross(m, np.array([0.0, 0.0, 1.0]))
        s = float(np.linalg.norm(axis))
        self.angle = min(float(np.arctan2(s, m[2])), self.max_angle)
        if s < 1e-12 or self.angle == 0.0:
            return pose
        C = R_wc.T @ axis_angle_to_matrix(axis / s * self.angle) @ R_wc
        rot = np.array(pose.rotations)
        rot[0] = quat_multiply(matrix_to_quat(C), rot[0])
        return Pose(pose.skeleton, rot, pose.root_position)


@dataclass
class FloorTrackerParams:
    """Parameters of :class:`FloorTracker` (the node exposes them as ROS parameters)."""

    window: int = 300                 # frames of contact points kept (10 s at 30 fps)
    min_frames: int = 15              # frames with a contact before the estimate is 'ready'
    contact_threshold: float = 0.5    # contact probability above which a point is used
    prior: str = 'body'               # 'body' (mean body up) or 'camera' (camera -y)
    prior_weight_m: float = 0.25      # see fit_floor_plane
    inlier_threshold: float = 0.025   # m
    offset_quantile: float = 0.25     # see fit_floor_plane
    update_every: int = 15            # frames between re-fits
    min_change_deg: float = 0.5       # a new fit replaces the frame only when the floor
    min_change_m: float = 0.01        # moved by more than this
    freeze_after: int = 0             # frames after which the frame is fixed (0: never)
    blend_frames: int = 15            # frames over which a new fit is blended in (0: at once)
    flat_foot_pitch_deg: float = 30.0  # the heel points' placement (mocap_physics.foot)
    restart_share: float = 0.3        # when the window's fit explains less than this share of
    restart_frames: int = 30          # the last restart_frames contact frames' points and
    #                                   their own fit twice as much, the older points are
    #                                   forgotten (the camera tilted unseen; 0: never)

    def validate(self) -> None:
        bad = []
        for name in ('window', 'min_frames', 'update_every'):
            if int(getattr(self, name)) < 1:
                bad.append(f'{name}={getattr(self, name)} (>= 1)')
        if not 0 <= int(self.blend_frames) <= int(self.update_every):
            # a new fit restarts the blend from rest: more frames than between two fits
            # would stall and restart it, a jerk at every fit
            bad.append(f'blend_frames={self.blend_frames} (0 to update_every, '
                       f'{self.update_every})')
        if not (np.isfinite(self.flat_foot_pitch_deg) and 0 <= self.flat_foot_pitch_deg <= 60):
            bad.append(f'flat_foot_pitch_deg={self.flat_foot_pitch_deg} (0 to 60)')
        if not 0.0 <= self.restart_share <= 1.0:
            bad.append(f'restart_share={self.restart_share} (0 to 1)')
        if int(self.restart_frames) < 1:
            bad.append(f'restart_frames={self.restart_frames} (>= 1)')
        if self.prior not in ('body', 'camera'):
            bad.append(f"prior={self.prior!r} ('body' or 'camera')")
        for name in ('prior_weight_m', 'inlier_threshold', 'min_change_deg', 'min_change_m'):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                bad.append(f'{name}={v} (>= 0)')
        if not 0.0 <= self.contact_threshold <= 1.0:
            bad.append(f'contact_threshold={self.contact_threshold}')
        if not 0.0 <= self.offset_quantile <= 1.0:
            bad.append(f'offset_quantile={self.offset_quantile}')
        if bad:
            raise ValueError('bad floor parameters: ' + '; '.join(bad))


class FloorTracker:
    """The floor frame of a motion stream in the camera frame, estimated from its feet.

    :meth:`update` takes each incoming pose (camera frame) with its contact probabilities,
    keeps the contact points that are in contact (probability above the threshold) over the
    last ``window`` frames, and re-fits the plane (:func:`fit_floor_plane`) every
    ``update_every`` frames. The first frame gives a provisional floor (the prior direction
    through the lowest foot point) so that the physics can start at once; the frame is
    replaced only when a fit moves the floor by more than ``min_change_deg`` /
    ``min_change_m`` (the caller re-expresses its state in the new frame,
    :meth:`~mocap_physics.cycle.PhysicsCycle.change_frame`), and never after
    ``freeze_after`` frames (when > 0; a blend in progress then still completes).

    A replacement is blended in over ``blend_frames`` frames (a smoothstep in time: the
    rotation along its arc, the translation on a line): everything expressed in the floor
    frame would otherwise jump at each re-fit. A step of a few millimetres every 15 frames was
    most of the physics output's jitter on rendered clips once the lifter's output was
    smooth (docs/physics.md). A new fit during a blend starts a new blend from where the
    frame is. The provisional floor is blended out too: replacing it at once made the
    physics output jitter a third more on rendered clips (one large step early in short
    clips) and did not bring the floor closer one second in.

    Attributes:
        frame: the current :class:`FloorFrame` (None before the first frame).
        target: the frame of the latest fit (``frame`` once a blend is over).
        fit: the :class:`PlaneFit` of ``target``.
        ready: at least ``min_frames`` frames with contacts were seen.
        changes: number of fits that replaced the frame.
        adopted: whether the last :meth:`update` adopted a new fit.
    """

    def __init__(self, params: Optional[FloorTrackerParams] = None,
                 source_frame: str = 'camera') -> None:
        self.params = params if params is not None else FloorTrackerParams()
        self.params.validate()
        self.source_frame = source_frame
        n = self.params.window
        self._points: Deque[np.ndarray] = collections.deque(maxlen=n)
        self._weights: Deque[np.ndarray] = collections.deque(maxlen=n)
        self._up: Deque[np.ndarray] = collections.deque(maxlen=n)
        self._lowest: Deque[np.ndarray] = collections.deque(maxlen=n)
        self.frames = 0
        self.contact_frames = 0
        self.frame: Optional[FloorFrame] = None
        self.target: Optional[FloorFrame] = None
        self.fit: Optional[PlaneFit] = None
        self.changes = 0
        self.restarts = 0
        self._restart_allowed = True
        self.adopted = False
        self._blend: Optional[Tuple[FloorFrame, int]] = None   # (start frame, frames done)
        self._since_fit = 0
        self._rng = np.random.default_rng(0)
        # known gravity (update(..., world=...)): contact heights in the world, the floor's
        # height there (current, target, blend start and frames done)
        self.known = False
        self._z: Deque[np.ndarray] = collections.deque(maxlen=n)
        self._zw: Deque[np.ndarray] = collections.deque(maxlen=n)
        self._z_lowest: Deque[float] = collections.deque(maxlen=n)
        self._z0: Optional[float] = None
        self._z0_target: Optional[float] = None
        self._z0_blend: Optional[Tuple[float, int]] = None

    @property
    def ready(self) -> bool:
        return self.contact_frames >= self.params.min_frames

    def prior(self, last: Optional[int] = None) -> np.ndarray:
        """The up direction for what the feet cannot determine (``last``: the mean body up
        of only the last that many frames)."""
        if self.params.prior == 'body' and self._up:
            ups = list(self._up)[-last:] if last else self._up
            m = np.mean(np.asarray(ups), axis=0)
            if np.linalg.norm(m) > 1e-6:
                return _unit(m)
        return CAMERA_UP.copy()

    def add(self, contact_points: np.ndarray, probabilities: Optional[Sequence[float]],
            up: Optional[np.ndarray] = None) -> None:
        """Record one frame: (4, 3) contact points (source frame) and their probabilities
        (None: unknown, only the lowest point is kept for the provisional floor)."""
        pts = np.asarray(contact_points, dtype=float).reshape(-1, 3)
        if not np.all(np.isfinite(pts)):
            return
        self.frames += 1
        self._since_fit += 1
        if up is not None and np.all(np.isfinite(up)):
            self._up.append(_unit(up))
        prior = self.prior()
        self._lowest.append(pts[np.argmin(pts @ prior)])
        if probabilities is None:
            return
        prob = np.asarray(probabilities, dtype=float).reshape(-1)
        if prob.shape != (len(pts),):
            return
        use = np.isfinite(prob) & (prob > self.params.contact_threshold)
        if use.any():
            self.contact_frames += 1
            self._points.append(pts[use])
            self._weights.append(prob[use])

    def estimate(self) -> Optional[PlaneFit]:
        """A fit of the plane to the points in the window (None before the first frame)."""
        if not self._lowest:
            return None
        prior = self.prior()
        p = self.params
        if self._points:
            pts = np.concatenate(list(self._points))
            w = np.concatenate(list(self._weights))
            fit = fit_floor_plane(pts, w, prior, p.prior_weight_m, p.inlier_threshold,
                                  offset_quantile=p.offset_quantile, rng=self._rng)
            if fit.source == 'points':
                recent = self._restarted(fit)
                return fit if recent is None else recent
        low = np.asarray(self._lowest)
        return fit_floor_plane(low, None, prior, p.prior_weight_m, p.inlier_threshold,
                               min_points=10 ** 9)

    def _restarted(self, fit: PlaneFit) -> Optional[PlaneFit]:
        """The fit of the last ``restart_frames`` contact frames when the window's ``fit``
        explains fewer than ``restart_share`` of those recent points (by weight, within
        ``inlier_threshold``) and their own fit explains at least twice as many; the older
        points are then forgotten (:attr:`restarts` counts it). None otherwise.

        Contact points are kept in the camera frame. A camera that tilts while its motion is
        not known (a scene of straight edges, a texture-less wall) moves the floor in that
        frame: the window then holds several floors, the older ones outnumber the new one,
        and the fit stays on a floor that is no longer there (a hand-held camera pitching
        from 17 to 60 degrees down over eight seconds left the fit 34 degrees off and the
        body falling, docs/physics.md)."""
        p = self.params
        k = int(p.restart_frames)
        if p.restart_share <= 0 or not self._restart_allowed or len(self._points) <= k:
            return None
        pts = np.concatenate(list(self._points)[-k:])
        w = np.concatenate(list(self._weights)[-k:])
        total = float(w.sum())
        if total <= 0:
            return None
        on_fit = float(w[np.abs(pts @ fit.normal + fit.offset) <= p.inlier_threshold].sum())
        if on_fit >= p.restart_share * total:
            return None
        recent = fit_floor_plane(pts, w, self.prior(last=k), p.prior_weight_m, p.inlier_threshold,
                                 offset_quantile=p.offset_quantile, rng=self._rng)
        on_recent = float(w[np.abs(pts @ recent.normal + recent.offset)
                            <= p.inlier_threshold].sum())
        if recent.source != 'points' or on_recent < 2.0 * on_fit:
            return None
        for dq in (self._points, self._weights, self._up, self._lowest):
            while len(dq) > k:
                dq.popleft()
        self.restarts += 1
        return recent

    def update(self, pose: Pose, probabilities: Optional[Sequence[float]],
               world: Optional[Tuple[np.ndarray, np.ndarray]] = None,
               restart: bool = True) -> Tuple[FloorFrame, bool]:
        """Record ``pose`` (source frame) and return (current floor frame, changed).

        ``world``: the source frame's pose (R (3, 3), t (3,) m; ``p_world = R p + t``) in a
        world frame whose z is up (a known camera pose, REP-103): the floor's normal is that z
        and only its height is fitted (:meth:`_update_known`). Once a frame came with one, a
        frame without keeps the last floor. ``restart`` False: a re-fit of this frame does
        not restart the window (:meth:`_restarted`; the camera is known to stand still)."""
        self._restart_allowed = bool(restart)
        if world is not None:
            return self._update_known(pose, probabilities, world)
        if self.known:
            return self.frame, False
        pts = contact_positions(pose, self.params.flat_foot_pitch_deg)
        try:
            up = body_up(pose)
        except ValueError:
            up = None
        self.add(pts, probabilities, up)
        self.adopted = False
        p = self.params
        frozen = p.freeze_after > 0 and self.frames > p.freeze_after and self.frame is not None
        due = self.frame is None or (self._since_fit >= p.update_every) or \
            (self.fit is not None and self.fit.source == 'prior' and self.ready)
        if due and not frozen:
            self._since_fit = 0
            fit = self.estimate()
            new = None if fit is None else fit.frame(source_frame=self.source_frame)
            if new is not None and self.target is not None:
                angle, dh = new.difference(self.target)
                if np.degrees(angle) < p.min_change_deg and dh < p.min_change_m:
                    new = None
            if new is not None:
                self.fit, self.target, self.adopted = fit, new, True
                if self.frame is None or p.blend_frames == 0:
                    changed = self.frame is not None
                    self.frame, self._blend = new, None
                    self.changes += int(changed)
                    return self.frame, changed
                self.changes += 1
                self._blend = (self.frame, 0)
        if self._blend is None:
            return self.frame, False
        start, done = self._blend
        done += 1
        u = done / p.blend_frames
        self.frame = start.interpolate(self.target, u * u * (3.0 - 2.0 * u))
        self._blend = (start, done) if done < p.blend_frames else None
        return self.frame, True

    def _update_known(self, pose: Pose, probabilities: Optional[Sequence[float]],
                      world: Tuple[np.ndarray, np.ndarray]) -> Tuple[FloorFrame, bool]:
        """:meth:`update` with the source frame's pose in a z-up world known.

        The floor is the world's horizontal plane at a height fitted to the contact points,
        each frame's moved into the world by its own pose (:func:`fit_floor_height`, every
        ``update_every`` frames; until the first contacts, the lowest foot points). The floor
        frame follows the camera every frame: its normal is the world's z seen from this
        frame's camera, the camera's height above the floor comes from the pose. Such
        changes are the camera's motion, not a new estimate of the floor: the floor stays
        where it is in the world, so they are not reported as changes (the caller does not
        re-express its state; the camera's turn and horizontal step are the carry's). A new
        height is blended in over ``blend_frames`` (smoothstep), not reported either: the
        body keeps its height above the floor, as the target does. Only the first frame with
        a pose after frames without one is a change (the floor moved from the feet's estimate
        to this one, in the same camera frame)."""
        p = self.params
        R = np.asarray(world[0], dtype=float)
        t = np.asarray(world[1], dtype=float).reshape(3)
        pts = contact_positions(pose, p.flat_foot_pitch_deg)
        if not (np.all(np.isfinite(pts)) and np.all(np.isfinite(R))
                and np.all(np.isfinite(t))):
            return self.frame, False
        switched = not self.known and self.frame is not None
        self.known = True
        z = (pts @ R.T + t)[:, 2]
        self.frames += 1
        self._since_fit += 1
        self._z_lowest.append(float(z.min()))
        if probabilities is not None:
            prob = np.asarray(probabilities, dtype=float).reshape(-1)
            if prob.shape == (len(z),):
                use = np.isfinite(prob) & (prob > p.contact_threshold)
                if use.any():
                    self.contact_frames += 1
                    self._z.append(z[use])
                    self._zw.append(prob[use])
        self.adopted = False
        changed = switched
        frozen = p.freeze_after > 0 and self.frames > p.freeze_after and self._z0 is not None
        due = self._z0 is None or self._since_fit >= p.update_every or \
            (self.fit is not None and self.fit.source == 'prior' and self.ready)
        if due and not frozen:
            self._since_fit = 0
            if self._z:
                z0, inliers = fit_floor_height(np.concatenate(list(self._z)),
                                               np.concatenate(list(self._zw)),
                                               p.inlier_threshold, p.offset_quantile,
                                               rng=self._rng)
                source, points = 'points', int(sum(len(v) for v in self._z))
            else:
                z0 = float(np.percentile(np.asarray(self._z_lowest), 10))
                source, points, inliers = 'prior', len(self._z_lowest), len(self._z_lowest)
            if self._z0 is None:
                self._z0 = self._z0_target = z0
                self.adopted = True
            elif abs(z0 - self._z0_target) >= p.min_change_m:
                self._z0_target = z0
                self._z0_blend = (self._z0, 0) if p.blend_frames > 0 else None
                if p.blend_frames == 0:
                    self._z0 = z0
                self.changes += 1
                self.adopted = True
            if self.adopted:
                self.fit = PlaneFit(R[2].copy(), float(t[2] - z0), points, inliers, 0.0,
                                    np.zeros(2), 0.0, source)
        if self._z0_blend is not None:
            start, done = self._z0_blend
            done += 1
            u = done / p.blend_frames
            self._z0 = start + (self._z0_target - start) * u * u * (3.0 - 2.0 * u)
            self._z0_blend = (start, done) if done < p.blend_frames else None
        up = R[2].copy()                     # the world's z in the source frame: R^T e_z
        self.frame = FloorFrame.from_plane(up, float(t[2] - self._z0),
                                           source_frame=self.source_frame)
        self.target = FloorFrame.from_plane(up, float(t[2] - self._z0_target),
                                            source_frame=self.source_frame)
        return self.frame, changed
