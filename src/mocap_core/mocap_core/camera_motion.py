"""Camera motion from the image background (no ROS imports).

The keypoint node sees the frames; the world stage needs to know whether the camera moves, and
how it turns. :class:`CameraMotionEstimator` tracks corner features outside the people's boxes
from frame to frame (OpenCV: ``goodFeaturesToTrack`` and pyramidal Lucas-Kanade with a
forward-backward check) and explains their motion by a pure camera rotation:

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
  rotation is still estimated (from the inliers, mostly the far background) but the camera's
  position is unknown;
* ``unknown``: fewer than ``min_features`` background points could be tracked (a dark or
  texture-less scene, the person fills the image): the rotation is held at its last value.

:attr:`CameraMotionEstimate.state` is the state of the majority of the last
``state_window`` frames (ties go to the more-moving state), :attr:`frame_state` the frame's own.

Conventions: optical frame of REP-103 (x right, y down, z forward). ``orientation`` (x, y, z,
w) is the current camera frame in the camera frame of the first image (``R_0t``: a vector in
the current frame, turned into the first frame), the product of the ``R_rel`` so far.
``angular_velocity`` (rad/s) is expressed in the current camera frame.
Pixel thresholds are for an image ``reference_width`` pixels wide and scale with the width.
"""

from __future__ import annotations

import collections
from dataclasses import dataclass, field
from typing import Deque, List, Optional, Tuple

import cv2
import numpy as np

from .rotations import matrix_to_axis_angle, matrix_to_quat

STATES: Tuple[str, ...] = ('static', 'rotating', 'moving', 'unknown')


@dataclass(frozen=True)
class CameraMotionParams:
    """Parameters of :class:`CameraMotionEstimator` (pixels at ``reference_width``)."""

    max_features: int = 300          # corners kept in the background
    min_features: int = 25           # fewer tracked points: state 'unknown'
    redetect_below: int = 150        # top the corners up when fewer are tracked
    feature_quality: float = 0.005   # goodFeaturesToTrack qualityLevel
    min_distance_px: float = 10.0    # between corners
    person_margin: float = 0.15      # the person's box grows by this fraction per side
    border_px: int = 4               # ignore corners this close to the image border
    max_width: int = 640             # frames wider than this are scaled down first
    static_flow_px: float = 0.25     # median background motion below this: static
    parallax_px: float = 0.6         # median residual of the rotation above this: moving
    parallax_rate_px: float = 0.08   # long-baseline residual per frame above this: moving
    parallax_min_age: int = 8        # frames since the keyframe before the long baseline counts
    parallax_max_age: int = 30       # a new keyframe after this many frames
    ransac_px: float = 1.5           # homography inlier threshold
    fb_error_px: float = 1.0         # forward-backward tracking error bound
    state_window: int = 9            # frames in the majority vote of ``state``
    reference_width: int = 640

    def validate(self) -> None:
        """Raise ValueError naming every parameter that is out of range."""
        bad = [n for n in ('max_features', 'min_features', 'state_window', 'max_width',
                           'reference_width') if getattr(self, n) < 1]
        bad += [n for n in ('static_flow_px', 'parallax_px', 'parallax_rate_px', 'ransac_px',
                            'fb_error_px', 'parallax_min_age', 'parallax_max_age',
                            'min_distance_px', 'feature_quality') if not getattr(self, n) > 0]
        if not 0 <= self.person_margin <= 2:
            bad.append('person_margin')
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
    extra: dict = field(default_factory=dict)


def person_mask(shape: Tuple[int, int], keypoints: Optional[np.ndarray], margin: float,
                border: int, min_confidence: float = 0.2) -> np.ndarray:
    """uint8 mask (H, W), 255 where background corners may be taken.

    Args:
        shape: (H, W) of the image.
        keypoints: (P, J, 3) or (J, 3) u, v (pixels) and confidence per person, or None.
        margin: each person's box of confident keypoints grows by this fraction of its size
            on every side (hair, clothes and limbs beyond the joints).
        border: pixels at the image border that are left out.
    """
    h, w = shape
    mask = np.zeros((h, w), np.uint8)
    mask[border:h - border, border:w - border] = 255
    if keypoints is None:
        return mask
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
        x0, x1 = int(max(0, u0 - pad_u)), int(min(w, u1 + pad_u + 1))
        y0, y1 = int(max(0, v0 - pad_v - 0.1 * bh)), int(min(h, v1 + pad_v + 1))
        if x1 > x0 and y1 > y0:
            mask[y0:y1, x0:x1] = 0
    return mask


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
        self._kf_R0 = np.eye(3)                     # orientation at the keyframe
        self._kf_age = 0                            # frames since the keyframe
        self._scale = 1.0
        self._Kw = self.K.copy()                     # intrinsics at the working size
        self._Kw_inv = np.linalg.inv(self._Kw)
        self._R0 = np.eye(3)
        self._stamp: Optional[float] = None
        self._omega = np.zeros(3)
        self._states: Deque[str] = collections.deque(maxlen=params.state_window)
        self.frames = 0
        self.unknown_frames = 0

    def reset(self) -> None:
        """Forget the tracks and the orientation (a new video, a time jump)."""
        self._prev, self._stamp = None, None
        self._empty_tracks()
        self._R0 = np.eye(3)
        self._omega = np.zeros(3)
        self._states.clear()

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
                **info) -> CameraMotionEstimate:
        """Record the frame: the new orientation ``R0_new`` (projected onto SO(3)), the
        motion into it and the voted state."""
        self._states.append(frame_state)
        R0_new = fit_rotation(np.eye(3), R0_new)      # the nearest rotation: no numeric drift
        R_rel = self._R0.T @ R0_new
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
            angular_velocity=self._omega.copy(), rotation=R_rel, first=first, **info)

    # -- the update ---------------------------------------------------------------------------
    def _add_corners(self, grey: np.ndarray, mask: np.ndarray) -> None:
        """Top the tracks up with new corners (no keyframe position: they join the long
        baseline at the next keyframe)."""
        keep = self._pts.reshape(-1, 2)
        pts = self._detect(grey, mask, keep if len(keep) else None).reshape(-1, 2)
        n = len(pts) - len(keep)
        self._pts = pts.reshape(-1, 1, 2).astype(np.float32)
        self._origin = np.concatenate([self._origin, np.full((n, 2), np.nan)])

    def _new_keyframe(self, R0: np.ndarray) -> None:
        self._origin = self._pts.reshape(-1, 2).astype(np.float64).copy()
        self._kf_R0 = R0.copy()
        self._kf_age = 0

    def _empty_tracks(self) -> None:
        self._pts = np.zeros((0, 1, 2), np.float32)
        self._origin = np.zeros((0, 2))

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
        mask = person_mask(grey.shape[:2], kp, p.person_margin, p.border_px)
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
            nxt, st, _ = cv2.calcOpticalFlowPyrLK(self._prev, grey, prev_pts, None,
                                                  winSize=(21, 21), maxLevel=3)
            back, st2, _ = cv2.calcOpticalFlowPyrLK(grey, self._prev, nxt, None,
                                                    winSize=(21, 21), maxLevel=3)
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
        tracked = len(cur)
        if tracked < p.min_features:
            self._add_corners(grey, mask)
            self._new_keyframe(self._R0)
            return self._result('unknown', self._R0, dt, tracked=tracked)
        flow = float(np.median(np.linalg.norm(cur - prv, axis=1))) / ref
        inl = np.ones(tracked, bool)
        parallax, rate, R0_cur = flow, float('nan'), self._R0
        if flow >= p.static_flow_px:
            R_ff, inl, parallax = self._rotation_between(prv, cur, ref)
            R0_cur = self._R0 @ R_ff
        # the long baseline since the keyframe: less drift, and a translation too slow to
        # show between two frames shows over many
        has = inl & np.isfinite(self._origin[:, 0])
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
        # keep the inliers, top up, renew the keyframe when it is old or thinly tracked
        self._pts, self._origin = self._pts[inl], self._origin[inl]
        if len(self._pts) < p.redetect_below:
            self._add_corners(grey, mask)
        if self._kf_age >= p.parallax_max_age or \
                np.isfinite(self._origin[:, 0]).sum() < max(p.min_features, len(self._pts) // 3):
            self._new_keyframe(R0_cur)
        return self._result(state, R0_cur, dt, tracked=tracked, inliers=int(inl.sum()),
                            flow_px=flow, parallax_px=parallax, parallax_rate_px=rate)


def estimate_video(video: str, K: np.ndarray, fps: float,
                   keypoints: Optional[np.ndarray] = None,
                   params: CameraMotionParams = CameraMotionParams()
                   ) -> List[CameraMotionEstimate]:
    """The camera motion of every frame of a video file (offline evaluation: the keypoint
    node does the same frame by frame).

    Args:
        video: path of the video.
        K: (3, 3) its intrinsics (pixels).
        fps: its frame rate; frame i is stamped i / fps.
        keypoints: (F, 23, 3) or (F, P, 23, 3) the people's keypoints per frame, or None.

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
            out.append(est.update(image, i / fps, kp))
    finally:
        cap.release()
    return out
