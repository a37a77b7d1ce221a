"""Camera motion from the image background (no ROS imports).

The keypoint node sees the frames; the world stage needs to know whether the camera moves, and
how it turns. :class:`CameraMotionEstimator` tracks corner features outside the people's boxes
from frame to frame (OpenCV: ``goodFeaturesToTrack`` and pyramidal Lucas-Kanade with a
forward-backward check) and explains their motion by a pure camera rotation. Three checks
keep what the tracker cannot see out of it (docs/global.md, "What the camera-motion estimate
could not see"):

* a new corner whose window is a straight edge or a smooth gradient (the smaller eigenvalue
  of its structure tensor under ``min_corner_ratio`` of the larger, :func:`corner_ratio`) is
  not tracked: the tracker slides along such an edge (a striped floor), and its flow is not
  the camera's. A scene of such edges only is ``unknown``, not a wrong turn;
* a person the detector missed stays masked with their last box, growing, for
  ``person_hold_frames`` frames: a body taken for background makes a standing camera move;
* a turn from a plane's homography or from the floor that differs from the pure turn of the
  same points by more than a camera's step can explain (``turn_tolerance_deg`` plus
  ``turn_tolerance_per_frame_deg`` per frame of baseline) is not taken (counted in
  ``implausible_turns``).

The rotation:

* the matched pixels are turned into unit bearing vectors ``b = normalise(K^-1 [u, v, 1])``;
* a homography fitted with RANSAC (``cv2.findHomography``) selects the inliers (a rotating
  camera maps the image by ``K R K^-1``, a homography);
* the rotation is the least-squares fit of the inlier bearings (orthogonal Procrustes):
  ``R_rel = argmin sum |b_prev - R b_cur|^2``, so ``R_rel`` takes the current camera frame to
  the previous one;
* what the rotation leaves unexplained (the median reprojection residual of the inliers, in
  pixels) is parallax: the camera translates.

Per frame the evidence gives a state:

* ``static``: the median background motion is below ``static_flow_px``; the rotation is
  taken as the identity (no drift while the camera stands still);
* ``rotating``: the rotation explains the motion (residual below ``parallax_px``), e.g. a
  tripod pan or a hand-held camera held in place;
* ``moving``: the residual shows translation (a camera that walks, drives or orbits); the
  camera's position is unknown. Its rotation cannot be the best pure rotation then: a
  translating camera's flow over the floor takes the step for a turn (0.3-0.6 deg per frame
  on rendered walks). With ``moving_rotation`` 'plane' (the default) the rotation comes,
  until the floor is known (below; with ``plane_with_floor`` also after it, keeping the
  solution whose plane is the floor), from the dominant plane's homography decomposed
  (``cv2.decomposeHomographyMat``): of the solutions that keep the points in front of both
  cameras, the one whose rotation is nearest the best pure rotation. 'homography' keeps
  the pure rotation (docs/global.md);
* ``unknown``: fewer than ``min_features`` background points could be tracked (a dark or
  texture-less scene, the person fills the image): the rotation is held at its last value.

:attr:`CameraMotionEstimate.state` is the state of the majority of the last
``state_window`` frames (ties go to the more-moving state), :attr:`frame_state` the frame's own.

Translation over the floor (beyond rotation). A single camera cannot tell how far it moved,
but the floor can: given the floor plane in the camera frame (its unit up normal ``n`` and the
camera's height ``h`` above it, e.g. from the physics stage's floor, :meth:`set_floor`), a
background point of the previous frame whose ray points down hits the floor at
``X = -h / (n . b) b``. With the rotation ``R_rel`` already known, the camera's displacement
``t`` (previous camera frame, m) is linear in the current bearings ``c = R_rel b_cur``:
``[c]_x t = [c]_x X``. Two points determine it; RANSAC over pairs (angular residual below the
homography threshold) rejects the points that are not on the floor (trees, walls, people's
shadows off the mask). The rotation and the step are then refined together on those points by
OpenCV's perspective-n-point solver (``cv2.solvePnP``), started there (:func:`fit_floor_motion`):
a scene of mostly floor misleads the background rotation, since a plane seen by a translating
camera maps by a homography too. The camera's
position (:attr:`CameraMotionEstimate.position`, in the first camera frame) is the sum of
the steps ``R_0,prev t``; a static frame adds nothing. A frame whose translation cannot be
found (no floor yet, fewer than ``floor_min_points`` floor inliers, an unknown frame) leaves
``translation_known`` False for that frame; the position then resumes from where it was, and
a consumer should treat the jump as unknown (the world stage re-aligns).

Conventions: optical frame of REP-103 (x right, y down, z forward). ``orientation`` (x, y, z,
w) is the current camera frame in the camera frame of the first image (``R_0t``: a vector in
the current frame, turned into the first frame), the product of the ``R_rel`` so far.
``angular_velocity`` (rad/s) is expressed in the current camera frame.
Pixel thresholds are for an image ``reference_width`` pixels wide and scale with the width.
"""

from __future__ import annotations

import collections
from dataclasses import dataclass, field
from typing import Deque, List, Optional, Sequence, Tuple

import cv2
import numpy as np

from .rotations import matrix_to_axis_angle, matrix_to_quat, quat_to_matrix

STATES: Tuple[str, ...] = ('static', 'rotating', 'moving', 'unknown')
#: side of the window over which a new corner's strength is measured (``corner_ratio``),
#: working pixels: the tracker's default window (``CameraMotionParams.track_window``), where
#: ``min_corner_ratio`` was tuned; it stays at 21 when the tracker's window is changed
CORNER_WINDOW = 21
#: values of ``CameraMotionParams.moving_rotation`` (module docstring, ``moving``)
MOVING_ROTATIONS: Tuple[str, ...] = ('plane', 'homography')


@dataclass(frozen=True)
class CameraMotionParams:
    """Parameters of :class:`CameraMotionEstimator` (pixels at ``reference_width``)."""

    max_features: int = 300          # corners kept in the background
    min_features: int = 25           # fewer tracked points: state 'unknown'
    redetect_below: int = 150        # top the corners up when fewer are tracked
    feature_quality: float = 0.005   # goodFeaturesToTrack qualityLevel
    min_distance_px: float = 10.0    # between corners
    turn_tolerance_deg: float = 2.0  # a plane's or the floor's turn may differ from the
    turn_tolerance_per_frame_deg: float = 1.5   # pure turn by this plus this per frame of
    #                                  baseline (a step's parallax; a walking camera: 10-15
    #                                  deg over 25 frames); beyond, it is not taken
    min_corner_ratio: float = 0.05   # smaller / larger eigenvalue of a new corner's window
    #                                  (below: a straight edge, whose motion along itself the
    #                                  tracker cannot see; 0: every corner)
    person_margin: float = 0.15      # the person's box grows by this fraction per side
    person_hold_frames: int = 15     # frames without people that their last boxes stay
    person_hold_growth: float = 0.05  # ... growing by this fraction per side and frame
    border_px: int = 4               # ignore corners this close to the image border
    max_width: int = 640             # frames wider than this are scaled down first
    static_flow_px: float = 0.25     # median background motion below this: static
    parallax_px: float = 0.6         # median residual of the rotation above this: moving
    parallax_rate_px: float = 0.08   # long-baseline residual per frame above this: moving
    parallax_min_age: int = 8        # frames since the keyframe before the long baseline counts
    parallax_max_age: int = 30       # a new keyframe after this many frames
    ransac_px: float = 1.5           # homography inlier threshold
    fb_error_px: float = 1.0         # forward-backward tracking error bound
    track_window: int = 21           # side of the Lucas-Kanade window, working pixels
    track_levels: int = 3            # its pyramid levels above the image (OpenCV maxLevel);
    #                                  15 and 2 take 0.73x the CPU with the same states, but
    #                                  made the travel set's world path worse through the
    #                                  pipeline (docs/speed.md): an option, not the default
    state_window: int = 9            # frames in the majority vote of ``state``
    reference_width: int = 640
    floor_min_points: int = 15       # floor inliers needed for a translation
    floor_max_distance: float = 25.0  # floor points further than this many camera heights
    floor_iterations: int = 64       # RANSAC pairs tried per frame
    floor_max_speed: float = 5.0     # m/s: a faster step is rejected as a failure
    plane_with_floor: bool = False   # 'plane' also once the floor is known: the solution
    plane_floor_max_angle_deg: float = 15.0   # whose normal is within this of the floor's
    floor_rotation: str = 'pnp'      # the floor step's rotation: 'pnp' (refined with the
    #                                  step by solvePnP) or 'given' (the plane's / the pure
    #                                  turn; only the step is fitted). Both opt-in: better
    #                                  camera estimates, not a better world path (docs/global.md)
    moving_rotation: str = 'plane'   # rotation of a 'moving' frame without a floor:
    #                                  'homography' (the turn that best explains the flow)
    #                                  or 'plane' (the dominant plane's homography decomposed)

    def validate(self) -> None:
        """Raise ValueError naming every parameter that is out of range."""
        bad = [n for n in ('max_features', 'min_features', 'state_window', 'max_width',
                           'reference_width', 'floor_min_points', 'floor_iterations')
               if getattr(self, n) < 1]
        if self.track_window < 3 or self.track_levels < 0:
            bad.append('track_window / track_levels')
        bad += [n for n in ('floor_max_distance', 'floor_max_speed', 'turn_tolerance_deg')
                if not getattr(self, n) > 0]
        bad += [n for n in ('turn_tolerance_per_frame_deg',) if getattr(self, n) < 0]
        bad += [n for n in ('static_flow_px', 'parallax_px', 'parallax_rate_px', 'ransac_px',
                            'fb_error_px', 'parallax_min_age', 'parallax_max_age',
                            'min_distance_px', 'feature_quality') if not getattr(self, n) > 0]
        if self.floor_rotation not in ('pnp', 'given'):
            bad.append('floor_rotation')
        if self.moving_rotation not in MOVING_ROTATIONS:
            bad.append('moving_rotation')
        if self.person_hold_frames < 0 or self.person_hold_growth < 0:
            bad.append('person_hold_frames / person_hold_growth')
        if not 0 <= self.person_margin <= 2:
            bad.append('person_margin')
        if not 0 <= self.min_corner_ratio < 1:
            bad.append('min_corner_ratio')
        if self.min_features > self.max_features:
            bad.append('min_features > max_features')
        if bad:
            raise ValueError(f'camera motion parameters out of range: {", ".join(bad)}')


@dataclass
class CameraMotionEstimate:
    """The camera's motion into one frame (module docstring for the conventions)."""

    state: str                        # majority of the last frames, one of STATES
    frame_state: str                  # this frame's own evidence
    orientation: np.ndarray           # (4,) x, y, z, w: current camera frame in the first one
    angular_velocity: np.ndarray      # (3,) rad/s, current camera frame
    rotation: np.ndarray              # (3, 3) R_rel: current camera frame -> previous one
    tracked: int = 0                  # background points tracked into this frame
    inliers: int = 0                  # of them, consistent with one homography
    flow_px: float = float('nan')     # median background motion (reference pixels)
    parallax_px: float = float('nan')  # median residual after the rotation (reference pixels)
    #: median over tracks spanning >= parallax_min_age frames of (residual of the rotation
    #: over the track's span) / span: reference pixels per frame
    parallax_rate_px: float = float('nan')
    first: bool = False               # the first frame (no motion yet)
    #: (3,) m: the camera's position in the first camera frame (module docstring,
    #: translation over the floor); meaningful where ``translation_known``
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    #: (3,) m/s: the camera's velocity in the current camera frame (zero when not known)
    linear_velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    translation_known: bool = False   # this frame's step was measured (or static)
    #: plane or floor turns not taken so far (:meth:`CameraMotionEstimator._plausible`)
    implausible_turns: int = 0
    floor_points: int = 0             # background points whose ray meets the floor
    floor_inliers: int = 0            # of them, consistent with the fitted step
    extra: dict = field(default_factory=dict)


def floor_points(bearings: np.ndarray, normal: np.ndarray, height: float,
                 max_distance: float) -> Tuple[np.ndarray, np.ndarray]:
    """Where rays meet the floor.

    Args:
        bearings: (N, 3) ray directions in the camera frame (any length).
        normal: (3,) the floor's unit up normal in the camera frame.
        height: the camera's height above the floor, m (> 0).
        max_distance: rays meeting the floor further than ``max_distance * height`` from the
            camera (near the horizon: unreliable) do not count.
    Returns:
        (points (N, 3) m in the camera frame, NaN where a ray does not meet the floor;
        mask (N,) of the rays that do).
    """
    b = np.asarray(bearings, dtype=np.float64)
    b = b / np.linalg.norm(b, axis=1, keepdims=True)
    den = b @ np.asarray(normal, dtype=np.float64)
    ok = den < -1.0 / max_distance          # distance = h / -den <= max_distance * h
    s = np.where(ok, -height / np.where(ok, den, -1.0), np.nan)
    return s[:, None] * b, ok


def corner_ratio(grey: np.ndarray, points: np.ndarray, window: int = CORNER_WINDOW
                 ) -> np.ndarray:
    """How well each point's neighbourhood pins down its motion: the smaller over the larger
    eigenvalue of the image's structure tensor (summed Sobel gradient products) over a
    ``window`` x ``window`` square around it, (N,) in [0, 1]. Near 0 on a straight edge or in
    a smooth gradient (the aperture problem: a shift along the edge changes nothing, so a
    tracker slides along it), near 1 on a corner or in isotropic texture. ``grey``: (H, W)
    uint8 image; ``points``: (N, 2) pixels (u, v); windows at the border are moved inside."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    h, w = grey.shape[:2]
    r = window // 2
    if len(pts) == 0 or h <= window or w <= window:
        return np.ones(len(pts))
    g = grey.astype(np.float32)
    ix = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3)
    iy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3)
    x = np.clip(np.round(pts[:, 0]).astype(int), r, w - r - 1)
    y = np.clip(np.round(pts[:, 1]).astype(int), r, h - r - 1)

    def window_sum(image: np.ndarray) -> np.ndarray:
        s = cv2.integral(image.astype(np.float64))
        return (s[y + r + 1, x + r + 1] - s[y - r, x + r + 1] - s[y + r + 1, x - r]
                + s[y - r, x - r])

    a, b, c = window_sum(ix * ix), window_sum(iy * iy), window_sum(ix * iy)
    half = 0.5 * (a + b)
    disc = np.sqrt(np.maximum(half * half - (a * b - c * c), 0.0))
    large = half + disc
    return np.where(large > 1e-9, (half - disc) / np.maximum(large, 1e-9), 0.0)


def _cross_rows(c: np.ndarray) -> np.ndarray:
    """(N, 3) -> (N, 3, 3) cross-product matrices ``[c]_x``."""
    z = np.zeros(len(c))
    return np.stack([np.stack([z, -c[:, 2], c[:, 1]], 1), np.stack([c[:, 2], z, -c[:, 0]], 1),
                     np.stack([-c[:, 1], c[:, 0], z], 1)], 1)


def fit_floor_translation(points: np.ndarray, bearings: np.ndarray, threshold_rad: float,
                          iterations: int = 64, min_inliers: int = 15,
                          rng: Optional[np.random.Generator] = None
                          ) -> Tuple[Optional[np.ndarray], np.ndarray]:
    """The camera's displacement for a known rotation (module docstring): RANSAC over pairs
    of floor points, then least squares over the inliers.

    Args:
        points: (N, 3) m, floor points in the previous camera frame.
        bearings: (N, 3) their directions from the current camera, turned into the previous
            camera frame (``R_rel b_cur``).
        threshold_rad: largest angle between a bearing and ``point - t`` of an inlier.
        iterations: pairs tried.
        min_inliers: fewer inliers: no answer.
        rng: random generator (default: seeded, deterministic).
    Returns:
        (t (3,) m: the current camera centre in the previous camera frame, or None;
        inlier mask (N,)).
    """
    X = np.asarray(points, dtype=np.float64)
    c = np.asarray(bearings, dtype=np.float64)
    n = len(X)
    if n < max(2, min_inliers):
        return None, np.zeros(n, bool)
    c = c / np.linalg.norm(c, axis=1, keepdims=True)
    A = _cross_rows(c)                                  # [c]_x t = [c]_x X
    rhs = np.einsum('nij,nj->ni', A, X)
    rng = rng if rng is not None else np.random.default_rng(0)
    cos_thr = np.cos(threshold_rad)

    def solve(idx: np.ndarray) -> np.ndarray:
        return np.linalg.lstsq(A[idx].reshape(-1, 3), rhs[idx].reshape(-1), rcond=None)[0]

    def inliers(t: np.ndarray) -> np.ndarray:
        d = X - t
        return np.einsum('ni,ni->n', d, c) >= cos_thr * np.linalg.norm(d, axis=1)

    best = np.zeros(n, bool)
    for _ in range(iterations):
        t = solve(rng.choice(n, 2, replace=False))
        inl = inliers(t)
        if inl.sum() > best.sum():
            best = inl
    if best.sum() < min_inliers:
        return None, best
    t = solve(np.nonzero(best)[0])
    inl = inliers(t)
    if inl.sum() < min_inliers:
        return None, inl
    return t, inl


def fit_floor_motion(points: np.ndarray, pixels: np.ndarray, K: np.ndarray,
                     R_guess: np.ndarray, threshold_px: float, iterations: int = 64,
                     min_inliers: int = 15, rng: Optional[np.random.Generator] = None,
                     refine_rotation: bool = True
                     ) -> Tuple[Optional[Tuple[np.ndarray, np.ndarray]], np.ndarray]:
    """The camera's rotation and displacement from floor points of the previous frame and
    where they are seen now (module docstring): the floor points are selected by
    :func:`fit_floor_translation` at the guessed rotation (with a threshold three times
    wider, since the guess is not exact), then rotation and step are refined together by
    OpenCV's iterative perspective-n-point solver (``cv2.solvePnP``) on them, and the
    inliers are chosen again by reprojection error.

    Args:
        points: (N, 3) m, floor points in the previous camera frame.
        pixels: (N, 2) where they are in the current image (the pixels ``K`` belongs to).
        K: (3, 3) intrinsics.
        R_guess: (3, 3) the rotation from the current camera frame to the previous one.
        threshold_px: reprojection error of an inlier, pixels.
        iterations: RANSAC pairs tried.
        min_inliers: fewer inliers: no answer.
        refine_rotation: False: the rotation is ``R_guess`` and only the step is fitted
            (:func:`fit_floor_translation` at the threshold itself, no PnP).
    Returns:
        ((R_rel (3, 3): current camera frame -> previous one, t (3,) m: the current camera
        centre in the previous camera frame) or None; inlier mask (N,)).
    """
    X = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    u = np.ascontiguousarray(pixels, dtype=np.float64).reshape(-1, 2)
    K = np.asarray(K, dtype=np.float64)
    n = len(X)
    if n < max(6, min_inliers):
        return None, np.zeros(n, bool)
    R_guess = np.asarray(R_guess, dtype=np.float64)
    b = np.concatenate([u, np.ones((n, 1))], axis=1) @ np.linalg.inv(K).T
    if not refine_rotation:
        t0, inl = fit_floor_translation(X, b @ R_guess.T, threshold_px / K[0, 0],
                                        iterations, min_inliers, rng)
        return (None if t0 is None else (R_guess.copy(), t0)), inl
    t0, inl = fit_floor_translation(X, b @ R_guess.T, 3.0 * threshold_px / K[0, 0],
                                    iterations, min_inliers, rng)
    if t0 is None:
        return None, inl
    rvec, _ = cv2.Rodrigues(R_guess.T)               # previous camera frame -> current
    tvec = -R_guess.T @ t0
    for _ in range(2):
        try:
            ok, rvec, tvec = cv2.solvePnP(X[inl].reshape(-1, 1, 3), u[inl].reshape(-1, 1, 2),
                                          K, None, rvec, tvec.reshape(3, 1),
                                          useExtrinsicGuess=True, flags=cv2.SOLVEPNP_ITERATIVE)
        except cv2.error:
            return None, np.zeros(n, bool)
        if not ok or not (np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec))):
            return None, np.zeros(n, bool)
        proj, _ = cv2.projectPoints(X.reshape(-1, 1, 3), rvec, tvec, K, None)
        err = np.linalg.norm(proj.reshape(-1, 2) - u, axis=1)
        inl = np.isfinite(err) & (err < threshold_px)
        if inl.sum() < min_inliers:
            return None, inl
    R_cp, _ = cv2.Rodrigues(rvec)
    return (R_cp.T, -R_cp.T @ np.asarray(tvec).ravel()), inl


def person_boxes(shape: Optional[Tuple[int, int]], keypoints: Optional[np.ndarray],
                 margin: float, min_confidence: float = 0.2) -> List[Tuple[int, int, int, int]]:
    """The people's boxes (x0, y0, x1, y1) in pixels, clipped to the image (H, W) =
    ``shape`` (None: image size unknown, not clipped): each person's confident keypoints
    (``keypoints``: (P, J, 3) or (J, 3), u, v, confidence), grown by ``margin`` of the box's
    size on every side (hair, clothes and limbs beyond the joints). A person with fewer than
    two confident keypoints has no box."""
    lo, (h, w) = (0, shape) if shape is not None else (-np.inf, (np.inf, np.inf))
    boxes: List[Tuple[int, int, int, int]] = []
    if keypoints is None:
        return boxes
    kp = np.asarray(keypoints, dtype=np.float64)
    if kp.ndim == 2:
        kp = kp[None]
    for person in kp:
        ok = np.isfinite(person).all(axis=1) & (person[:, 2] >= min_confidence)
        if ok.sum() < 2:
            continue
        (u0, v0), (u1, v1) = person[ok, :2].min(axis=0), person[ok, :2].max(axis=0)
        bw, bh = u1 - u0, v1 - v0
        # the head reaches above the nose and eyes, the feet below the heels
        pad_u, pad_v = margin * bw + 0.1 * bh, margin * bh
        x0, x1 = int(max(lo, u0 - pad_u)), int(min(w, u1 + pad_u + 1))
        y0, y1 = int(max(lo, v0 - pad_v - 0.1 * bh)), int(min(h, v1 + pad_v + 1))
        if x1 > x0 and y1 > y0:
            boxes.append((x0, y0, x1, y1))
    return boxes


def _mask(shape: Tuple[int, int], boxes: Sequence[Tuple[int, int, int, int]],
          border: int) -> np.ndarray:
    h, w = shape
    mask = np.zeros((h, w), np.uint8)
    mask[border:h - border, border:w - border] = 255
    for x0, y0, x1, y1 in boxes:
        mask[y0:y1, x0:x1] = 0
    return mask


def person_mask(shape: Tuple[int, int], keypoints: Optional[np.ndarray], margin: float,
                border: int, min_confidence: float = 0.2) -> np.ndarray:
    """uint8 mask (H, W), 255 where background corners may be taken: the image without the
    ``border`` pixels at its edge and without the people's boxes (:func:`person_boxes`)."""
    return _mask(shape, person_boxes(shape, keypoints, margin, min_confidence), border)


def fit_rotation(b_prev: np.ndarray, b_cur: np.ndarray) -> np.ndarray:
    """The rotation ``R`` (3, 3) minimising ``sum |b_prev - R b_cur|^2`` (orthogonal
    Procrustes / Kabsch, determinant +1). ``b_*``: (N, 3) unit bearing vectors, N >= 2."""
    u, _, vt = np.linalg.svd(b_prev.T @ b_cur)
    d = np.sign(np.linalg.det(u @ vt))
    return u @ np.diag([1.0, 1.0, d]) @ vt


class CameraMotionEstimator:
    """Frame-to-frame camera rotation and motion state from the background (module
    docstring). One instance per camera stream; not thread-safe."""

    def __init__(self, K: np.ndarray, params: CameraMotionParams = CameraMotionParams()
                 ) -> None:
        """``K``: (3, 3) intrinsics of the full-size frames, pixels."""
        params.validate()
        self.params = params
        self.K = np.asarray(K, dtype=np.float64)
        self._prev: Optional[np.ndarray] = None     # previous grey frame (working size)
        self._pts = np.zeros((0, 1, 2), np.float32)  # (N, 1, 2) tracked corners in it
        self._origin = np.zeros((0, 2))             # (N, 2) pixel at the keyframe (or NaN)
        #: (N,) corners that pin their motion down (not on a straight edge): only they
        #: measure turns and parallax; all of them say whether anything moves
        self._strong = np.zeros(0, bool)
        self._kf_R0 = np.eye(3)                     # orientation at the keyframe
        self._kf_age = 0                            # frames since the keyframe
        # 'plane': the rotation last chosen from the keyframe (keeps the decomposition's branch)
        self._kf_plane: Optional[np.ndarray] = None
        self._scale = 1.0
        self._Kw = self.K.copy()                     # intrinsics at the working size
        self._Kw_inv = np.linalg.inv(self._Kw)
        self._R0 = np.eye(3)
        self._stamp: Optional[float] = None
        self._omega = np.zeros(3)
        self._states: Deque[str] = collections.deque(maxlen=params.state_window)
        self._C = np.zeros(3)                        # camera position, first camera frame
        self._v = np.zeros(3)                        # camera velocity, current frame
        self._floor: Optional[Tuple[np.ndarray, float]] = None   # (n in first frame, h)
        self._history: Deque[Tuple[float, np.ndarray]] = collections.deque(maxlen=600)
        self._rng = np.random.default_rng(0)
        self.frames = 0
        self.unknown_frames = 0
        self.translation_frames = 0                 # moving frames with a measured step
        self.implausible_turns = 0                  # plane / floor turns not taken
        self._boxes: List[Tuple[int, int, int, int]] = []   # the people's last boxes
        self._boxes_age = 0                         # frames since they were seen

    def reset(self) -> None:
        """Forget the tracks, the orientation and the position (a new video, a time jump);
        a floor already given is kept (in the camera frame of the next image)."""
        if self._floor is not None:
            self._floor = (self._R0.T @ self._floor[0], self._floor[1])
        self._prev, self._stamp = None, None
        self._empty_tracks()
        self._R0 = np.eye(3)
        self._omega = np.zeros(3)
        self._C = np.zeros(3)
        self._v = np.zeros(3)
        self._history.clear()
        self._states.clear()
        self._boxes, self._boxes_age = [], 0

    def set_floor(self, normal: np.ndarray, height: float,
                  stamp_s: Optional[float] = None) -> bool:
        """Give the floor plane (module docstring, translation over the floor).

        Args:
            normal: (3,) the floor's up normal in the camera frame of the image stamped
                ``stamp_s`` (or of the latest image when None or not among the recent ones).
            height: the camera's height above the floor then, m.
        Returns:
            False (and the floor is ignored) when it is not finite or not plausible (height
            outside 0.05-100 m).
        """
        n = np.asarray(normal, dtype=np.float64)
        norm = float(np.linalg.norm(n)) if np.all(np.isfinite(n)) else 0.0
        if norm < 0.5 or not (np.isfinite(height) and 0.05 <= height <= 100.0):
            return False
        R0 = self._R0
        if stamp_s is not None and self._history:
            t, R = min(self._history, key=lambda e: abs(e[0] - stamp_s))
            if abs(t - stamp_s) < 0.1:
                R0 = R
        self._floor = (R0 @ (n / norm), float(height))
        return True

    @property
    def points(self) -> np.ndarray:
        """(N, 2) the background corners tracked into the last frame, pixels of the full-size
        frame (u, v)."""
        return self._pts.reshape(-1, 2).astype(np.float64) / self._scale

    @property
    def has_floor(self) -> bool:
        """A floor has been given (translations can be measured)."""
        return self._floor is not None

    # -- helpers ------------------------------------------------------------------------------
    def _working(self, image: np.ndarray) -> np.ndarray:
        grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        h, w = grey.shape[:2]
        scale = min(1.0, self.params.max_width / float(w))
        if scale != self._scale or self._prev is None:
            self._scale = scale
            S = np.diag([scale, scale, 1.0])
            self._Kw = S @ self.K
            self._Kw_inv = np.linalg.inv(self._Kw)
        if scale < 1.0:
            grey = cv2.resize(grey, (int(round(w * scale)), int(round(h * scale))),
                              interpolation=cv2.INTER_AREA)
        return grey

    def _detect(self, grey: np.ndarray, mask: np.ndarray,
                keep: Optional[np.ndarray]) -> np.ndarray:
        p = self.params
        if keep is not None and len(keep):
            mask = mask.copy()
            for u, v in keep.reshape(-1, 2):
                cv2.circle(mask, (int(u), int(v)), int(p.min_distance_px), 0, -1)
        want = p.max_features - (0 if keep is None else len(keep))
        new = cv2.goodFeaturesToTrack(grey, maxCorners=max(want, 1),
                                      qualityLevel=p.feature_quality,
                                      minDistance=p.min_distance_px * self._ref(grey),
                                      mask=mask, blockSize=5)
        new = np.zeros((0, 1, 2), np.float32) if new is None else new.astype(np.float32)
        if keep is not None and len(keep):
            return np.concatenate([keep.reshape(-1, 1, 2).astype(np.float32), new])
        return new

    def _ref(self, grey: np.ndarray) -> float:
        """Working pixels per reference pixel."""
        return grey.shape[1] / float(self.params.reference_width)

    def _bearings(self, pts: np.ndarray) -> np.ndarray:
        h = np.concatenate([pts, np.ones((len(pts), 1))], axis=1) @ self._Kw_inv.T
        return h / np.linalg.norm(h, axis=1, keepdims=True)

    def _result(self, frame_state: str, R0_new: np.ndarray, dt: float, first: bool = False,
                step: Optional[np.ndarray] = None, **info) -> CameraMotionEstimate:
        """Record the frame: the new orientation ``R0_new`` (projected onto SO(3)), the
        motion into it (``step``: the camera's displacement in the previous camera frame, m,
        None when not measured) and the voted state."""
        self._states.append(frame_state)
        R0_new = fit_rotation(np.eye(3), R0_new)      # the nearest rotation: no numeric drift
        R_rel = self._R0.T @ R0_new
        known = first or step is not None
        if step is not None:
            self._C = self._C + self._R0 @ step
            self._v = (R_rel.T @ step / dt) if dt > 0 else np.zeros(3)
        else:
            self._v = np.zeros(3)
        if self._stamp is not None:
            self._history.append((self._stamp, R0_new))
        if frame_state != 'unknown':
            self._omega = (matrix_to_axis_angle(R_rel) / dt) if dt > 0 else np.zeros(3)
        else:
            self.unknown_frames += 1
        self._R0 = R0_new
        counts = collections.Counter(self._states)
        # majority; ties go to the state that assumes more motion (the safer one)
        order = {'moving': 0, 'rotating': 1, 'unknown': 2, 'static': 3}
        state = min(counts, key=lambda s: (-counts[s], order[s]))
        return CameraMotionEstimate(
            state=state, frame_state=frame_state, orientation=matrix_to_quat(self._R0),
            angular_velocity=self._omega.copy(), rotation=R_rel, first=first,
            position=self._C.copy(), linear_velocity=self._v.copy(), translation_known=known,
            implausible_turns=self.implausible_turns, **info)

    def _floor_step(self, prv: np.ndarray, cur: np.ndarray, R_ff: np.ndarray, dt: float,
                    ref: float) -> Tuple[Optional[Tuple[np.ndarray, np.ndarray]], int, int]:
        """The camera's motion into this frame over the floor (module docstring): ((R_rel
        current -> previous camera frame, step (3,) m in the previous camera frame) or None,
        floor points, inliers)."""
        p = self.params
        if self._floor is None or len(prv) < p.floor_min_points:
            return None, 0, 0
        n0, h = self._floor
        X, on = floor_points(self._bearings(prv), self._R0.T @ n0, h, p.floor_max_distance)
        if on.sum() < p.floor_min_points:
            return None, int(on.sum()), 0
        motion, inl = fit_floor_motion(X[on], cur[on], self._Kw, R_ff, p.ransac_px * ref,
                                       p.floor_iterations, p.floor_min_points, self._rng,
                                       refine_rotation=p.floor_rotation == 'pnp')
        if motion is not None and dt > 0 and \
                np.linalg.norm(motion[1]) > p.floor_max_speed * dt:
            motion = None
        return motion, int(on.sum()), int(inl.sum())

    # -- the update ---------------------------------------------------------------------------
    def _add_corners(self, grey: np.ndarray, mask: np.ndarray) -> None:
        """Top the tracks up with new corners (no keyframe position: they join the long
        baseline at the next keyframe)."""
        keep = self._pts.reshape(-1, 2)
        pts = self._detect(grey, mask, keep if len(keep) else None).reshape(-1, 2)
        n = len(pts) - len(keep)
        self._pts = pts.reshape(-1, 1, 2).astype(np.float32)
        self._origin = np.concatenate([self._origin, np.full((n, 2), np.nan)])
        strong = np.ones(n, bool)
        if self.params.min_corner_ratio > 0 and n:
            strong = corner_ratio(grey, pts[len(keep):], CORNER_WINDOW) >= \
                self.params.min_corner_ratio
        self._strong = np.concatenate([self._strong, strong])

    def _new_keyframe(self, R0: np.ndarray) -> None:
        self._origin = self._pts.reshape(-1, 2).astype(np.float64).copy()
        self._kf_R0 = R0.copy()
        self._kf_age = 0
        self._kf_plane = None          # the plane rotation last chosen over this keyframe

    def _empty_tracks(self) -> None:
        self._pts = np.zeros((0, 1, 2), np.float32)
        self._origin = np.zeros((0, 2))
        self._strong = np.zeros(0, bool)

    def _project(self, bearings: np.ndarray) -> np.ndarray:
        h = bearings @ self._Kw.T
        return h[:, :2] / h[:, 2:3]

    def _rotation_between(self, a: np.ndarray, b: np.ndarray, ref: float
                          ) -> Tuple[np.ndarray, np.ndarray, float]:
        """The rotation taking frame-b bearings to frame-a bearings from matched pixels
        ``a``, ``b`` (N, 2): (R, inlier mask, median inlier residual in reference pixels)."""
        p = self.params
        inl = np.ones(len(a), bool)
        _, hin = cv2.findHomography(a, b, cv2.RANSAC, p.ransac_px * ref)
        if hin is not None and hin.sum() >= p.min_features:
            inl = hin.ravel().astype(bool)
        R = fit_rotation(self._bearings(a[inl]), self._bearings(b[inl]))
        # the frame-b pixels of the frame-a points if the camera only turned
        resid = np.linalg.norm(self._project(self._bearings(a[inl]) @ R) - b[inl], axis=1)
        return R, inl, float(np.median(resid)) / ref

    def _plane_rotation(self, a: np.ndarray, b: np.ndarray, ref: float,
                        previous: Optional[np.ndarray] = None,
                        floor_normal: Optional[np.ndarray] = None) -> Optional[np.ndarray]:
        """The rotation taking frame-b bearings to frame-a bearings from matched pixels ``a``,
        ``b`` (N, 2) of a camera that turns *and* translates over a floor: the homography of
        the dominant plane (RANSAC) decomposed (``cv2.decomposeHomographyMat``), keeping the
        solutions that put the inliers in front of both cameras
        (``cv2.filterHomographyDecompByVisibleRefpoints`` on normalised points). Two survive
        as a rule (a plane's homography is ambiguous: the other solution's normal lies along
        the camera's step and its step along the true normal); of them the one whose
        rotation is nearest ``previous`` is kept (the one chosen a frame earlier over the
        same keyframe: the two solutions part slowly as the baseline grows), or without it
        the one nearest the best pure rotation of the same inliers: over a short baseline
        the pure rotation's bias from the step is smaller than the wrong solution's error.
        Unlike the normal's direction, this choice does not depend on how the camera is
        pitched (docs/global.md). None (the caller keeps the pure rotation) when it fails."""
        p = self.params
        if len(a) < p.min_features:
            return None
        H, hin = cv2.findHomography(a, b, cv2.RANSAC, p.ransac_px * ref)
        if H is None or hin is None or hin.sum() < p.min_features:
            return None
        try:
            n, Rs, ts, normals = cv2.decomposeHomographyMat(H, self._Kw)
        except cv2.error:
            return None
        inl = hin.ravel().astype(bool)
        try:
            keep = cv2.filterHomographyDecompByVisibleRefpoints(
                Rs, normals, self._normalised(a[inl]), self._normalised(b[inl]))
        except cv2.error:
            keep = None
        idx = list(range(n)) if keep is None else [int(k) for k in np.ravel(keep)]
        if not idx:
            return None
        # H maps a to b: x_b ~ R x_a; we want b_a = R_rel b_b, i.e. R.T
        if floor_normal is not None:
            # the floor known (its normal in frame a): the solution whose plane is the floor,
            # none when the dominant plane is not the floor
            cos = [abs(float(np.ravel(normals[k]) @ floor_normal)) for k in idx]
            k = int(np.argmax(cos))
            if cos[k] < np.cos(np.radians(self.params.plane_floor_max_angle_deg)):
                return None
            return np.asarray(Rs[idx[k]]).T
        near = previous if previous is not None else \
            fit_rotation(self._bearings(a[inl]), self._bearings(b[inl]))
        best = min(idx, key=lambda k: float(np.linalg.norm(matrix_to_axis_angle(
            np.asarray(Rs[k]) @ near))))
        return np.asarray(Rs[best]).T

    def _plausible(self, R0_new: np.ndarray, R0_ref: np.ndarray, frames: int) -> bool:
        """Whether an orientation from a plane or the floor (``R0_new``) lies within what a
        camera's step can make it differ from the pure turn of the same points
        (``R0_ref``) over a baseline of ``frames`` frames: ``turn_tolerance_deg`` plus
        ``turn_tolerance_per_frame_deg`` per frame. Counted in ``implausible_turns`` when
        not."""
        p = self.params
        angle = np.degrees(np.linalg.norm(matrix_to_axis_angle(R0_ref.T @ R0_new)))
        ok = bool(angle <= p.turn_tolerance_deg + p.turn_tolerance_per_frame_deg *
                  max(int(frames), 1))
        if not ok:
            self.implausible_turns += 1
        return ok

    def _normalised(self, pts: np.ndarray) -> np.ndarray:
        """(N, 2) pixels at the working size -> (N, 1, 2) float32 normalised image points."""
        b = self._bearings(pts)
        return (b[:, :2] / b[:, 2:3]).reshape(-1, 1, 2).astype(np.float32)

    def update(self, image: np.ndarray, stamp_s: float,
               keypoints: Optional[np.ndarray] = None) -> CameraMotionEstimate:
        """The camera's motion from the previous frame into this one.

        Args:
            image: (H, W) grey or (H, W, 3) BGR uint8 frame at the size ``K`` belongs to.
            stamp_s: its time (s); a stamp that does not advance resets the estimator.
            keypoints: (P, 23, 3) or (23, 3) the people's keypoints in this frame (u, v
                pixels, confidence), masked out of the background; None: no one.
        """
        p = self.params
        self.frames += 1
        grey = self._working(image)
        kp = None
        if keypoints is not None:
            kp = np.array(keypoints, dtype=np.float64, copy=True)
            kp[..., :2] *= self._scale
        boxes = person_boxes(grey.shape[:2], kp, p.person_margin)
        if boxes:
            self._boxes, self._boxes_age = boxes, 0
        elif self._boxes and self._boxes_age < p.person_hold_frames:
            # the detector missed the people: their last boxes, growing, stay masked (a
            # body taken for background makes a standing camera seem to move)
            self._boxes_age += 1
            grow = p.person_hold_growth * self._boxes_age
            hh, ww = grey.shape[:2]
            boxes = [(max(0, int(x0 - grow * (x1 - x0))), max(0, int(y0 - grow * (y1 - y0))),
                      min(ww, int(x1 + grow * (x1 - x0))), min(hh, int(y1 + grow * (y1 - y0))))
                     for x0, y0, x1, y1 in self._boxes]
        mask = _mask(grey.shape[:2], boxes, p.border_px)
        if self._prev is None or self._stamp is None or not stamp_s > self._stamp or \
                self._prev.shape != grey.shape:
            if self._prev is not None:
                self.reset()
            self._prev, self._stamp = grey, stamp_s
            self._empty_tracks()
            self._add_corners(grey, mask)
            self._new_keyframe(self._R0)
            return self._result('static', self._R0, 0.0, first=True, tracked=0)
        dt = stamp_s - self._stamp
        self._stamp = stamp_s
        ref = self._ref(grey)
        prev_pts = self._pts
        ok = np.zeros(len(prev_pts), bool)
        nxt = prev_pts
        if len(prev_pts) >= p.min_features:
            lk = dict(winSize=(p.track_window, p.track_window), maxLevel=p.track_levels)
            nxt, st, _ = cv2.calcOpticalFlowPyrLK(self._prev, grey, prev_pts, None, **lk)
            back, st2, _ = cv2.calcOpticalFlowPyrLK(grey, self._prev, nxt, None, **lk)
            fb = np.linalg.norm((back - prev_pts).reshape(-1, 2), axis=1)
            ok = (st.ravel() == 1) & (st2.ravel() == 1) & (fb < p.fb_error_px * ref)
            # corners that moved onto a person (or out of the image) are not background
            c = nxt.reshape(-1, 2)
            ok &= (c[:, 0] >= 0) & (c[:, 1] >= 0) & (c[:, 0] < grey.shape[1]) & \
                (c[:, 1] < grey.shape[0])
            ui = np.clip(c[:, 0].astype(int), 0, grey.shape[1] - 1)
            vi = np.clip(c[:, 1].astype(int), 0, grey.shape[0] - 1)
            ok &= mask[vi, ui] > 0
        self._prev = grey
        self._kf_age += 1
        cur, prv = nxt.reshape(-1, 2)[ok].astype(np.float64), prev_pts.reshape(-1, 2)[ok]
        self._pts, self._origin = cur.reshape(-1, 1, 2).astype(np.float32), self._origin[ok]
        self._strong = self._strong[ok]
        strong = self._strong
        tracked = len(cur)
        if tracked < p.min_features:
            self._add_corners(grey, mask)
            self._new_keyframe(self._R0)
            return self._result('unknown', self._R0, dt, tracked=tracked)
        flow = float(np.median(np.linalg.norm(cur - prv, axis=1))) / ref
        if flow >= p.static_flow_px and strong.sum() < p.min_features:
            # something moves, but too few corners say how (a scene of straight edges)
            if len(self._pts) < p.redetect_below:
                self._add_corners(grey, mask)
            self._new_keyframe(self._R0)
            return self._result('unknown', self._R0, dt, tracked=tracked, flow_px=flow)
        inl = np.ones(tracked, bool)
        parallax, rate, R0_cur = flow, float('nan'), self._R0
        R_ff = np.eye(3)                   # the turn since the previous frame
        if flow >= p.static_flow_px:
            R_ff, inl_s, parallax = self._rotation_between(prv[strong], cur[strong], ref)
            inl[strong] = inl_s
            R0_cur = self._R0 @ R_ff
        # the long baseline since the keyframe: less drift, and a translation too slow to
        # show between two frames shows over many
        has = inl & np.isfinite(self._origin[:, 0]) & strong
        if has.sum() >= p.min_features:
            R_kf, kin, res_kf = self._rotation_between(self._origin[has], cur[has], ref)
            rate = res_kf / self._kf_age
            if flow >= p.static_flow_px:
                R0_cur = self._kf_R0 @ R_kf
        if flow < p.static_flow_px:
            state = 'static'
        else:
            state = 'rotating' if parallax < p.parallax_px else 'moving'
        if self._kf_age >= p.parallax_min_age and rate > p.parallax_rate_px:
            state = 'moving'
        if state == 'moving' and p.moving_rotation == 'plane' and \
                (p.plane_with_floor or not self.has_floor):
            # a translating camera: the best pure turn absorbs the parallax of the step, the
            # more the longer the baseline (a walking camera: 10-15 deg over 25 frames)
            # (a decomposition of points that are not on one plane can turn by tens of
            # degrees: a plane rotation further from the pure turn than a step's parallax
            # can explain is not taken)
            R_pure = R0_cur
            R_p = None
            if has.sum() >= p.min_features:
                R_p = self._plane_rotation(
                    self._origin[has], cur[has], ref, self._kf_plane,
                    None if not self.has_floor else self._kf_R0.T @ self._floor[0])
                if R_p is not None and self._plausible(self._kf_R0 @ R_p, R_pure,
                                                       self._kf_age):
                    self._kf_plane = R_p
                    R0_cur = self._kf_R0 @ R_p
                else:
                    R_p = None
            if R_p is None:
                # no plane over the keyframe's baseline: one frame's, or its pure turn
                R_1 = self._plane_rotation(
                    prv[strong], cur[strong], ref,
                    floor_normal=None if not self.has_floor else self._R0.T @ self._floor[0])
                R0_cur = self._R0 @ (R_1 if R_1 is not None and self._plausible(
                    self._R0 @ R_1, self._R0 @ R_ff, 1) else R_ff)
        step: Optional[np.ndarray] = None
        n_floor = n_inl = 0
        if state == 'static':
            step = np.zeros(3)
        else:
            motion, n_floor, n_inl = self._floor_step(
                prv[strong], cur[strong], fit_rotation(np.eye(3), self._R0.T @ R0_cur), dt, ref)
            if motion is not None and not self._plausible(motion[0], R_ff, 1):
                motion = None
            if motion is not None:
                # the floor fixes the rotation too: far background alone confuses a turn
                # with a sideways step less, but a scene of floor only misleads the
                # homography (a translating plane is a homography as well)
                R0_cur, step = self._R0 @ motion[0], motion[1]
                self.translation_frames += 1
        # keep the inliers, top up, renew the keyframe when it is old or thinly tracked
        self._pts, self._origin, self._strong = self._pts[inl], self._origin[inl], strong[inl]
        if len(self._pts) < p.redetect_below:
            self._add_corners(grey, mask)
        if self._kf_age >= p.parallax_max_age or \
                np.isfinite(self._origin[:, 0]).sum() < max(p.min_features, len(self._pts) // 3):
            self._new_keyframe(R0_cur)
        return self._result(state, R0_cur, dt, step=step, tracked=tracked,
                            inliers=int(inl.sum()), flow_px=flow, parallax_px=parallax,
                            parallax_rate_px=rate, floor_points=n_floor, floor_inliers=n_inl)


def estimate_video(video: str, K: np.ndarray, fps: float,
                   keypoints: Optional[np.ndarray] = None,
                   params: CameraMotionParams = CameraMotionParams(),
                   floors: Optional[Sequence[Optional[Tuple[np.ndarray, float, float]]]] = None
                   ) -> List[CameraMotionEstimate]:
    """The camera motion of every frame of a video file (offline evaluation: the keypoint
    node does the same frame by frame).

    Args:
        video: path of the video.
        K: (3, 3) its intrinsics (pixels).
        fps: its frame rate; frame i is stamped i / fps.
        keypoints: (F, 23, 3) or (F, P, 23, 3) the people's keypoints per frame, or None.
        floors: per frame, the floor known when it arrives, or None: (normal (3,) in the
            camera frame of the image stamped ``stamp_s``, camera height m, ``stamp_s``)
            (:meth:`CameraMotionEstimator.set_floor`).

    Raises:
        OSError: the video cannot be opened.
    """
    cap = cv2.VideoCapture(str(video))
    if not cap.isOpened():
        raise OSError(f'cannot open video {video}')
    est = CameraMotionEstimator(K, params)
    out: List[CameraMotionEstimate] = []
    try:
        while True:
            ok, image = cap.read()
            if not ok:
                break
            i = len(out)
            kp = None if keypoints is None or i >= len(keypoints) else keypoints[i]
            if floors is not None and i < len(floors) and floors[i] is not None:
                n, h, t = floors[i]
                est.set_floor(n, h, t)
            out.append(est.update(image, i / fps, kp))
    finally:
        cap.release()
    return out


def rotation_accuracy(estimates: Sequence[CameraMotionEstimate], R: np.ndarray,
                      fps: float) -> Tuple[float, float]:
    """How well the estimates of a clip follow its true camera: ``(rotation error, drift)``.

    Args:
        estimates: one per frame, from the first frame on.
        R: (F, 3, 3) the true world -> camera rotation of each frame.
        fps: the frame rate.

    Returns:
        the median error of the frame-to-frame rotation over the frames with an estimate
        (``frame_state`` not ``unknown``), degrees per second (nan when no such frame), and
        the drift: the accumulated orientation's error at the last frame scored, degrees.
        The frames scored are the first ``min(len(estimates), len(R))``.
    """
    R = np.asarray(R, dtype=np.float64)
    n = min(len(estimates), len(R))
    if n < 1:
        raise ValueError('no frame to score')
    errs = [np.linalg.norm(matrix_to_axis_angle(estimates[i].rotation.T @ (R[i - 1] @ R[i].T)))
            for i in range(1, n) if estimates[i].frame_state != 'unknown']
    error = float(np.degrees(np.median(errs)) * fps) if errs else float('nan')
    mine = quat_to_matrix(estimates[n - 1].orientation)
    drift = float(np.degrees(np.linalg.norm(matrix_to_axis_angle(mine.T @ (R[0] @ R[n - 1].T)))))
    return error, drift
