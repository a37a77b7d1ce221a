"""Frame-by-frame lifting for the live node (no ROS imports).

:class:`OnlineLifter` keeps a ring buffer of one person's keypoints and, for every pushed
frame, runs the network over the buffer and returns one lifted frame:

* ``causal`` mode: the output for the newest frame, computed from it and the frames before it
  (latency = processing time only);
* ``windowed`` mode: the output for the frame ``latency`` frames back, which sees ``latency``
  future frames (better accuracy, bounded delay of latency / fps seconds).

The skeleton (bone lengths) is estimated by E_S over the growing buffer until
``skeleton_frames`` frames were seen, then held for this person. A gap longer than
``max_gap_s``, a stamp going backwards or a change of camera intrinsics resets the buffer
and the skeleton.
"""

from __future__ import annotations

import collections
from dataclasses import dataclass
from typing import Deque, List, Optional, Tuple

import numpy as np
import torch

from mocap_core.camera import CameraIntrinsics
from mocap_core.pose import Pose
from mocap_core.skeleton import NUM_KEYPOINTS, Skeleton

from .features import lifter_features
from .model import MotioNet


@dataclass
class LiftedFrame:
    """One lifted frame in the camera optical frame (metres, x, y, z, w quaternions)."""

    stamp_ns: int
    pose: Pose                    # rotations relative to the rest pose; root in camera frame
    contacts: np.ndarray          # (4,) probabilities: left heel, left toe, right heel, right toe
    skeleton_fixed: bool          # True once the skeleton estimate is held
    depth: float                  # root depth, m


class OnlineLifter:
    """Ring-buffered inference (module docstring).

    Args:
        model: the network (its ``cfg.causal`` must match ``mode``).
        mode: 'causal' or 'windowed'.
        latency: frames of look-ahead in windowed mode (default: half the receptive field).
        skeleton_frames: frames used to estimate the skeleton before it is held.
        max_gap_s: a larger gap between stamps resets the buffer.
    """

    def __init__(self, model: MotioNet, mode: str = 'causal', latency: Optional[int] = None,
                 skeleton_frames: int = 90, max_gap_s: float = 1.0,
                 device: str = 'cpu') -> None:
        if mode not in ('causal', 'windowed'):
            raise ValueError("mode must be 'causal' or 'windowed'")
        if (mode == 'causal') != bool(model.cfg.causal):
            raise ValueError(f'model built for causal={model.cfg.causal} but mode={mode!r}')
        self.model = model.eval()
        self.mode = mode
        rf = model.cfg.receptive_field()
        self.latency = 0 if mode == 'causal' else (rf // 2 if latency is None else int(latency))
        self.context = rf + self.latency
        self.skeleton_frames = max(int(skeleton_frames), 1)
        self.max_gap_ns = int(max_gap_s * 1e9)
        self.device = device
        self.reset()

    def reset(self) -> None:
        """Forget the buffer and the skeleton."""
        # one frame more than the context: the root velocity of the oldest frame needs it
        size = max(self.context + 1, self.skeleton_frames)
        self._kp: Deque[np.ndarray] = collections.deque(maxlen=size)
        self._stamps: Deque[int] = collections.deque(maxlen=size)
        self._intr: Optional[CameraIntrinsics] = None
        self.lengths: Optional[torch.Tensor] = None
        self.frames_seen = 0
        self._last_emitted = -1

    def push(self, stamp_ns: int, keypoints: np.ndarray, intrinsics: CameraIntrinsics,
             ) -> Tuple[List[LiftedFrame], str]:
        """Add one frame ((23, 3) pixels + confidence).

        Returns (frames, event): the lifted frames that became ready (none while the
        windowed mode waits for look-ahead, one normally; on a reset, also the frames of the
        previous segment still waiting, so nothing received is lost), and '' or the reason
        of a reset ('gap', 'backwards', 'intrinsics')."""
        kp = np.asarray(keypoints, dtype=np.float64)
        if kp.shape != (NUM_KEYPOINTS, 3):
            raise ValueError(f'keypoints must have shape ({NUM_KEYPOINTS}, 3), got {kp.shape}')
        event = ''
        if self._stamps:
            dt = stamp_ns - self._stamps[-1]
            if dt <= 0:
                event = 'backwards'
            elif dt > self.max_gap_ns:
                event = 'gap'
        if self._intr is not None and intrinsics != self._intr:
            event = event or 'intrinsics'
        frames: List[LiftedFrame] = []
        if event:
            frames = self.flush()
            self.reset()
        self._intr = intrinsics
        self._kp.append(kp)
        self._stamps.append(int(stamp_ns))
        self.frames_seen += 1
        if len(self._kp) > self.latency:
            frames.append(self._infer())
        return frames, event

    def pending(self) -> int:
        """Frames received but not yet returned (windowed mode waits for look-ahead)."""
        return sum(1 for s in self._stamps if s > self._last_emitted)

    def flush(self) -> List[LiftedFrame]:
        """Return the frames still waiting for look-ahead, computed with the future frames
        that exist (the end of a stream, or before a long pause)."""
        frames = []
        while self.pending() > 0:
            offset = self.pending() - 1  # frames after the one to emit
            frames.append(self._infer(index=-1 - offset))
        return frames

    @torch.no_grad()
    def _infer(self, index: Optional[int] = None) -> LiftedFrame:
        kp = np.stack(self._kp)
        feats, root_2d, scale, _ = lifter_features(kp, self._intr)
        x = torch.as_tensor(feats[None], device=self.device)
        r = torch.as_tensor(root_2d[None].astype(np.float32), device=self.device)
        sc = torch.as_tensor(scale[None].astype(np.float32), device=self.device)
        fixed = self.lengths is not None
        if not fixed:
            lengths = self.model.e_s(((x - self.model.feature_mean) / self.model.feature_std)
                                     .transpose(1, 2))
            if self.frames_seen >= self.skeleton_frames:
                self.lengths = lengths
        else:
            lengths = self.lengths
        ctx = slice(-self.context, None)
        out = self.model(x[:, ctx], r[:, ctx], sc[:, ctx], lengths=lengths)
        i = -1 - self.latency if index is None else index
        rot = out['rotations'][0, i].cpu().numpy().astype(np.float64)
        root = out['root'][0, i].cpu().numpy().astype(np.float64)
        contacts = torch.sigmoid(out['contacts'][0, i]).cpu().numpy().astype(np.float64)
        skeleton = Skeleton.from_group_lengths(lengths[0].cpu().numpy().astype(np.float64))
        stamp = list(self._stamps)[i]
        self._last_emitted = stamp
        return LiftedFrame(stamp, Pose(skeleton, rot, root), contacts, fixed,
                           float(out['depth'][0, i]))
