"""Zero-phase smoothing of the lifted frames along time, as a fixed delay (no ROS imports).

The lifter lifts each frame from a window of keypoints, so the detector's frame-to-frame
noise reaches every output frame a little differently: on rendered people seen through the
real detector its joints accelerate 7.8 times as much as the true motion (docs/lifter.md).
:class:`FrameSmoother` averages each frame with its ``radius`` neighbours on either side,
weighted by a Gaussian of the frame offset, with its own width for the joint rotations
(``sigma`` frames) and the root (``root_sigma`` frames, default ``sigma``):

* rotations (J, 4), x, y, z, w: per joint, the weighted sum of the neighbours' quaternions
  within ``ceil(2 sigma)`` frames, brought into the centre frame's hemisphere, normalised (the
  weighted chordal mean; exact to second order for the few degrees that neighbouring frames
  differ by); ``sigma`` 0: the centre frame's own;
* root position (3,), metres, camera optical frame: the weighted mean within
  ``ceil(2 root_sigma)`` frames; the frame's ``depth`` is the smoothed root's z;
* foot contacts, skeleton, ``skeleton_fixed`` and the stamp: the centre frame's own.

Why two widths: on rendered people seen through the real detector most of the output's
jitter is the root's (its depth, from the person's size in the image); the joint rotations
jitter far less, and smoothing them as much as the root flattens a walk's fast knee and hip
swings (the knee's flexion range falls from 0.81 to 0.63 of the truth's on the rendered
travel set at sigma 2; docs/lifter.md, "Output smoothing").

A frame is emitted once ``radius`` later frames have arrived (``radius``: that of the larger
of the two widths), so the output lags the input by ``radius`` frames;
:meth:`FrameSmoother.flush` emits the rest with the window cut at the end (the first frames
likewise use the frames that exist before them). The output depends on
the sequence of frames alone, not on how they were grouped into calls: lifting frame by
frame (live) and in chunks (``mocap process``) give the same frames.
"""

from __future__ import annotations

import collections
import math
from dataclasses import replace
from typing import Deque, Iterable, List, Optional

import numpy as np

from mocap_core.pose import Pose

#: The node's ``output_sigma`` (joint rotations) in windowed mode when the parameter is -1
#: (frames).
DEFAULT_OUTPUT_SIGMA = 1.5
#: The node's ``output_root_sigma`` in windowed mode when the parameter is -1 (frames).
DEFAULT_OUTPUT_ROOT_SIGMA = 3.0


def default_radius(sigma: float) -> int:
    """Frames on each side of the centre frame for ``sigma``: ``ceil(2 * sigma)``."""
    return int(math.ceil(2.0 * float(sigma)))


def smooth_along_time(x: np.ndarray, sigma: float, radius: Optional[int] = None
                      ) -> np.ndarray:
    """The weighted mean of :class:`FrameSmoother` applied to a whole (T, ...) array along
    axis 0 (the window cut at both ends), for batch evaluation of quantities that are averaged
    linearly (root positions; joint positions as an approximation of smoothing the
    rotations)."""
    x = np.asarray(x, dtype=np.float64)
    r = default_radius(sigma) if radius is None else int(radius)
    w = np.exp(-0.5 * (np.arange(-r, r + 1) / float(sigma)) ** 2)
    T = len(x)
    num = np.zeros_like(x)
    den = np.zeros(T)
    for k, wk in zip(range(-r, r + 1), w):
        lo, hi = max(0, -k), min(T, T - k)        # frames i with i + k inside
        if hi <= lo:                              # |k| >= T: no such frame
            continue
        num[lo:hi] += wk * x[lo + k:hi + k]
        den[lo:hi] += wk
    return num / den.reshape((T,) + (1,) * (x.ndim - 1))


class FrameSmoother:
    """Gaussian smoothing of lifted frames (module docstring).

    Args:
        sigma: standard deviation of the Gaussian for the joint rotations, frames (>= 0; 0:
            not smoothed).
        radius: frames on each side of the centre frame (default ``ceil(2 * s)`` of the
            larger width ``s``); the output lags the input by this many frames. Given, it
            bounds both windows.
        root_sigma: standard deviation for the root position, frames (>= 0; None: ``sigma``).
            At least one of the two must be > 0.
    """

    def __init__(self, sigma: float, radius: Optional[int] = None,
                 root_sigma: Optional[float] = None) -> None:
        root_sigma = sigma if root_sigma is None else root_sigma
        if not (sigma >= 0 and root_sigma >= 0 and max(sigma, root_sigma) > 0):
            raise ValueError(f'sigma and root_sigma must be >= 0 and one of them > 0, got '
                             f'{sigma} and {root_sigma}')
        self.sigma = float(sigma)
        self.root_sigma = float(root_sigma)
        widest = max(self.sigma, self.root_sigma)
        self.radius = default_radius(widest) if radius is None else int(radius)
        if self.radius < 1:
            raise ValueError(f'radius must be >= 1, got {self.radius}')
        self._weights = self._kernel(self.sigma)
        self._root_weights = self._kernel(self.root_sigma)
        self.reset()

    def _kernel(self, sigma: float) -> np.ndarray:
        """Gaussian weights (2 radius + 1,) over the offsets -radius .. radius, zero beyond
        ``ceil(2 sigma)`` (sigma 0: the centre frame alone)."""
        k = np.arange(-self.radius, self.radius + 1)
        if sigma <= 0:
            return (k == 0).astype(float)
        return np.where(np.abs(k) <= default_radius(sigma),
                        np.exp(-0.5 * (k / sigma) ** 2), 0.0)

    def reset(self) -> None:
        """Forget every frame (a new segment)."""
        # the frames still needed: up to `radius` already emitted, then those waiting
        self._frames: Deque = collections.deque()
        self._waiting = 0

    def pending(self) -> int:
        """Frames received but not yet emitted."""
        return self._waiting

    def push(self, frames: Iterable) -> List:
        """Add lifted frames (:class:`mocap_lifter.online.LiftedFrame`, in stamp order);
        return those that became ready, smoothed."""
        out = []
        for f in frames:
            self._frames.append(f)
            self._waiting += 1
            if self._waiting > self.radius:
                out.append(self._emit())
        return out

    def flush(self) -> List:
        """Emit every waiting frame (the window cut at the end) and start a new segment."""
        out = []
        while self._waiting:
            out.append(self._emit())
        self.reset()
        return out

    def _emit(self):
        """Smooth and return the oldest waiting frame."""
        n = len(self._frames)
        c = n - self._waiting                        # its index in the deque
        lo, hi = max(0, c - self.radius), min(n, c + self.radius + 1)
        window = slice(lo - c + self.radius, hi - c + self.radius)
        w, w_root = self._weights[window], self._root_weights[window]
        centre = self._frames[c]
        ref = np.asarray(centre.pose.rotations)
        rots = np.stack([np.asarray(self._frames[i].pose.rotations) for i in range(lo, hi)])
        sign = np.where(np.sum(rots * ref, axis=-1, keepdims=True) < 0.0, -1.0, 1.0)
        q = np.tensordot(w, rots * sign, axes=1)
        q /= np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), 1e-12)
        roots = np.stack([np.asarray(self._frames[i].pose.root_position) for i in range(lo, hi)])
        root = w_root @ roots / w_root.sum()
        self._waiting -= 1
        # keep `radius` emitted frames for the next windows
        while len(self._frames) - self._waiting > self.radius:
            self._frames.popleft()
        return replace(centre, pose=Pose(centre.pose.skeleton, q, root), depth=float(root[2]))
