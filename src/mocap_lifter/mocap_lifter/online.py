"""Frame-by-frame lifting for the live node (no ROS imports).

:class:`OnlineLifter` keeps a ring buffer of one person's keypoints and, for every pushed
frame, runs the network over the buffer and returns one lifted frame:

* ``causal`` mode: the output for the newest frame, computed from it and the frames before it
  (latency = processing time only);
* ``windowed`` mode: the output for the frame ``latency`` frames back, which sees ``latency``
  future frames (better accuracy, bounded delay of latency / fps seconds).

With ``chunk = 1`` (live), MotioNet runs frame by frame through
:class:`mocap_lifter.streaming.StreamingEncoder`, which keeps every layer's columns and
computes one new column per layer and frame: the same output as a pass over the whole
context window (to float32 rounding) for a small part of its time. It is used when it is
exact: the default look-ahead (half the receptive field) or the causal network, and no
keypoint smoothing; otherwise, and for flushes (whose last frames lack their future), the
window pass runs as before.

``chunk`` > 1 (offline processing) waits for that many frames more and lifts them in one
network pass: the same outputs (MotioNet is purely convolutional, every output's receptive
field lies inside the pass; VTM lifts each frame from the window it would get frame by frame,
:meth:`mocap_lifter.vtm.VTM.lift_frames`) for a fraction of the time per frame, ``chunk - 1``
frames later.

The network's frame rate (``network_rate_hz``): the networks were trained on motion at 30
frames/s and read the frames they get as consecutive. A keypoint node that drops frames (a
busy machine: 13 of 30 frames/s) or a slower camera would show them the motion two or three
times too fast, a 60 frames/s camera at half its pace. So the network is given frames at
that rate:

* a gap of ``m + 1`` periods between two stamps (1.5 periods or more, up to ``max_gap_s``)
  is filled with ``m`` frames linearly interpolated between its ends (the confidence of a
  point the smaller of its two), lifted as context and never returned;
* a frame less than 0.75 periods after the last frame given to the network is not given to
  it: its output is interpolated between the outputs of the network frames before and after
  it (rotations by slerp, root, contacts and depth linearly), or, at the end of a stream, the
  last one's held.

Only the frames received come out, each with its own stamp, in order, and the look-ahead
stays ``latency`` periods of that rate in seconds (measured in docs/lifter.md, "Frames the
lifter never got, and frames it gets too often").

The skeleton (bone lengths) is estimated by E_S over the growing buffer until
``skeleton_frames`` frames were seen, then held for this person. A gap longer than
``max_gap_s``, a stamp going backwards or a change of camera intrinsics resets the buffer
and the skeleton.

:class:`LifterStream` is the node's per-message logic around it: the tracked person's row
of each (P, 23, 3) keypoint message; frames without that person go through the network as
all-unseen keypoints once the person was seen in this segment (before that they are
dropped); stamps jumping back by ``max_gap_s`` or more start a new stream; the intrinsics
come from :class:`mocap_lifter.intrinsics.StreamIntrinsics`, and while its keypoint estimate
is still collecting (the first frames of a stream without camera_info) the frames wait in
arrival order and are lifted once it is fixed.
"""

from __future__ import annotations

import collections
from dataclasses import dataclass, field
from typing import Deque, Dict, List, Optional, Tuple

import numpy as np
import torch

from mocap_core.camera import CameraIntrinsics
from mocap_core.camera_motion import person_boxes
from mocap_core.pose import Pose
from mocap_core.rotations import quat_slerp
from mocap_core.skeleton import NUM_JOINTS, NUM_KEYPOINTS, Skeleton
from mocap_core.streams import StampOrder

from .features import (average_quaternions, lifter_features_and_rays, mirror_features,
                       smooth_keypoints, turn_root_orientation, unmirror_rotations)
from .intrinsics import StreamIntrinsics
from .model import NUM_CONTACTS, MotioNet
from .output_smoothing import FrameSmoother
from .streaming import StreamingEncoder


@dataclass
class LiftedFrame:
    """One lifted frame in the camera optical frame (metres, x, y, z, w quaternions)."""

    stamp_ns: int
    pose: Pose                    # rotations relative to the rest pose; root in camera frame
    contacts: np.ndarray          # (4,) probabilities: left heel, left toe, right heel, right toe
    skeleton_fixed: bool          # True once the skeleton estimate is held
    depth: float                  # root depth, m


def _between_frame(a: LiftedFrame, b: LiftedFrame, stamp_ns: int) -> LiftedFrame:
    """The frame at ``stamp_ns`` between the lifted frames ``a`` and ``b`` (``a`` itself when
    they are one frame): rotations by slerp, root, contacts and depth linearly; ``b``'s
    skeleton."""
    span = b.stamp_ns - a.stamp_ns
    t = 0.0 if span <= 0 else min(max((stamp_ns - a.stamp_ns) / span, 0.0), 1.0)
    rot = quat_slerp(a.pose.rotations, b.pose.rotations, np.full(len(a.pose.rotations), t))
    root = (1.0 - t) * a.pose.root_position + t * b.pose.root_position
    return LiftedFrame(int(stamp_ns), Pose(b.pose.skeleton, rot, root),
                       (1.0 - t) * a.contacts + t * b.contacts, b.skeleton_fixed,
                       float((1.0 - t) * a.depth + t * b.depth))


class OnlineLifter:
    """Ring-buffered inference (module docstring).

    Args:
        model: the network, MotioNet or VTM (its ``cfg.causal`` must match ``mode``; VTM is
            windowed only, its receptive field is its window).
        mode: 'causal' or 'windowed'.
        latency: frames of look-ahead in windowed mode (default: half the receptive field).
        skeleton_frames: frames used to estimate the skeleton before it is held.
        max_gap_s: a larger gap between stamps resets the buffer.
        chunk: frames lifted per network pass (1 = every frame as soon as it can be).
        smooth: Gaussian smoothing of the buffered keypoints along time before the features
            (sigma in frames; 0 = off). Windowed mode has the look-ahead for a centred
            filter; in causal mode the newest frame is smoothed one-sidedly (a lag).
        flip: test-time flip augmentation (MotioNet): the mirrored keypoints are lifted in
            the same pass and the mirrored-back rotations, root and contacts averaged in
            (twice the network time; 42.8 -> 39.9 mm MPJPE on the validation split).
        streaming: lift frame by frame with :class:`~mocap_lifter.streaming.StreamingEncoder`
            where that is exact (module docstring); False: always the window pass.
        output_sigma: Gaussian smoothing of the lifted joint rotations along time (sigma in
            frames; 0 = off): :class:`~mocap_lifter.output_smoothing.FrameSmoother`, which
            delays the output by ``ceil(2 * sigma)`` frames more (:attr:`delay`) for the
            larger of the two sigmas.
        output_root_sigma: the same for the root position (None: ``output_sigma``).
        network_rate_hz: the frame rate the network reads its input at: gaps of 1.5 periods
            or more are filled, frames closer than 0.75 periods thinned (module docstring);
            0 = off (every frame received is given to the network as the next one).
        subject_height: the person's stature in metres (floor to the top of the head), when
            it is known (0 = estimate the size from the keypoints). The estimated skeleton is
            scaled to this stature (:meth:`~mocap_core.skeleton.Skeleton.stature`) and the
            root position by the same factor along its camera ray, so the image projection
            is unchanged: a person of the same image size who is taller stands further
            away (docs/lifter.md, "What the keypoints cannot tell").
        virtual_camera: MotioNet: lift the keypoints as a camera turned to look at the
            person would see them (:func:`~mocap_lifter.features.lifter_features`), and turn
            the pose back into the real camera's frame: a person away from the image centre
            is seen along an oblique ray, which the network's root-relative input does not
            show (docs/lifter.md, "The person's ray").
    """

    def __init__(self, model: MotioNet, mode: str = 'causal', latency: Optional[int] = None,
                 skeleton_frames: int = 90, max_gap_s: float = 1.0,
                 device: str = 'cpu', chunk: int = 1, flip: bool = False,
                 smooth: float = 0.0, streaming: bool = True,
                 output_sigma: float = 0.0, output_root_sigma: Optional[float] = None,
                 subject_height: float = 0.0, network_rate_hz: float = 0.0,
                 virtual_camera: bool = False) -> None:
        if mode not in ('causal', 'windowed'):
            raise ValueError("mode must be 'causal' or 'windowed'")
        if (mode == 'causal') != bool(model.cfg.causal):
            raise ValueError(f'model built for causal={model.cfg.causal} but mode={mode!r}')
        self.model = model.eval()
        self.mode = mode
        rf = model.cfg.receptive_field()
        self.latency = 0 if mode == 'causal' else (rf // 2 if latency is None else int(latency))
        # frames the newest output needs: the receptive field behind it (MotioNet), or one
        # window ending at the newest frame (VTM)
        context_frames = getattr(model, 'context_frames', None)
        self.context = context_frames(self.latency) if context_frames else rf + self.latency
        self.skeleton_frames = max(int(skeleton_frames), 1)
        self.max_gap_ns = int(max_gap_s * 1e9)
        self.device = device
        if int(chunk) < 1:
            raise ValueError(f'chunk must be >= 1, got {chunk}')
        self.chunk = int(chunk)
        self.flip = bool(flip) and getattr(model, 'lift_frames', None) is None
        if smooth < 0:
            raise ValueError(f'smooth must be >= 0, got {smooth}')
        self.smooth = float(smooth)
        root_sigma = output_sigma if output_root_sigma is None else output_root_sigma
        if output_sigma < 0 or root_sigma < 0:
            raise ValueError(f'output_sigma and output_root_sigma must be >= 0, got '
                             f'{output_sigma} and {root_sigma}')
        self._smoother = FrameSmoother(output_sigma, root_sigma=root_sigma) \
            if max(output_sigma, root_sigma) > 0 else None
        if not np.isfinite(subject_height) or subject_height != 0 and not \
                0.5 <= subject_height <= 3.0:
            raise ValueError(f'subject_height must be 0 (estimate) or a stature of 0.5-3 m, '
                             f'got {subject_height}')
        self.subject_height = float(subject_height)
        if virtual_camera and getattr(model, 'lift_frames', None) is not None:
            raise ValueError('virtual_camera is a MotioNet option (VTM lifts in the real '
                             "camera's frame)")
        # weights trained in the virtual camera need it
        self.virtual_camera = bool(virtual_camera) or bool(
            getattr(getattr(model, 'cfg', None), 'virtual_camera', False))
        #: (T, 3, 3) the buffer's virtual cameras (virtual_camera; set with the features)
        self._rays: Optional[np.ndarray] = None
        if not np.isfinite(network_rate_hz) or network_rate_hz < 0:
            raise ValueError(f'network_rate_hz must be >= 0, got {network_rate_hz}')
        self.period_ns = int(round(1e9 / network_rate_hz)) if network_rate_hz > 0 else 0
        #: frames filled in so far (lifted as context, never returned)
        self.filled_frames = 0
        #: frames received but not given to the network so far (outputs interpolated)
        self.thinned_frames = 0
        #: the network's frames before the output smoothing, not yet taken
        #: (:meth:`take_unsmoothed`; not cleared by :meth:`reset`)
        self._unsmoothed: List[LiftedFrame] = []
        self._stream: Optional[StreamingEncoder] = None
        if streaming and self.chunk == 1 and self.smooth == 0 and device == 'cpu' \
                and context_frames is None and isinstance(model, MotioNet):
            enc = StreamingEncoder(model, rows=2 if self.flip else 1)
            if enc.lag == self.latency:
                self._stream = enc
        self.reset()

    @property
    def delay(self) -> int:
        """Frames between a pushed frame and its output: the look-ahead plus the output
        smoothing's radius."""
        return self.latency + (self._smoother.radius if self._smoother is not None else 0)

    @property
    def streaming(self) -> bool:
        """Whether frames are lifted by the streaming encoder (module docstring)."""
        return self._stream is not None

    def reset(self) -> None:
        """Forget the buffer and the skeleton."""
        # one frame more than the context: the root velocity of the oldest frame needs it
        size = max(self.context + self.chunk, self.skeleton_frames)
        self._kp: Deque[np.ndarray] = collections.deque(maxlen=size)
        self._stamps: Deque[int] = collections.deque(maxlen=size)
        self._intr: Optional[CameraIntrinsics] = None
        self.lengths: Optional[torch.Tensor] = None
        self._held_skeleton: Optional[Tuple[torch.Tensor, Skeleton, float]] = None
        self.frames_seen = 0
        self._last_emitted = -1
        self._filled: set = set()          # stamps of the filled-in frames not yet returned
        self._between: List[int] = []      # stamps of thinned frames waiting for an output
        self._last_received = -1           # the newest stamp pushed (thinned ones too)
        self._previous: Optional[LiftedFrame] = None   # the last network frame released
        # chunk > 1: the skeleton estimate after each push (frames_seen -> lengths), so that
        # every frame gets the skeleton it would have got frame by frame
        self._lengths_at: Dict[int, torch.Tensor] = {}
        if self._stream is not None:
            self._stream.reset()
        if self._smoother is not None:
            self._smoother.reset()

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
            dt = stamp_ns - max(self._stamps[-1], self._last_received)
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
        self._last_received = int(stamp_ns)
        if not event and self.period_ns and self._stamps:
            if 4 * (stamp_ns - self._stamps[-1]) < 3 * self.period_ns:
                self._between.append(int(stamp_ns))       # thinned (module docstring)
                self.thinned_frames += 1
                return self._received(frames), event
            frames = self._fill(stamp_ns, kp, intrinsics)
        frames += self._push(stamp_ns, kp, intrinsics)
        return self._received(frames), event

    def _fill(self, stamp_ns: int, kp: np.ndarray, intrinsics: CameraIntrinsics
              ) -> List[LiftedFrame]:
        """Push the frames missing before ``stamp_ns`` (module docstring); returns what they
        released."""
        last, prev = self._stamps[-1], self._kp[-1]
        gap = stamp_ns - last
        missing = int(round(gap / self.period_ns)) - 1
        frames: List[LiftedFrame] = []
        for j in range(1, missing + 1):
            a = j / (missing + 1)
            filled = (1.0 - a) * prev + a * kp
            filled[:, 2] = np.minimum(prev[:, 2], kp[:, 2])
            stamp = last + int(round(a * gap))
            self._filled.add(stamp)
            self.filled_frames += 1
            frames += self._push(stamp, filled, intrinsics)
        return frames

    def _received(self, frames: List[LiftedFrame], end: bool = False) -> List[LiftedFrame]:
        """The frames received, from the network frames ``frames`` released: without the
        filled-in ones, with the thinned ones interpolated between their neighbours (held
        after the last one at the ``end`` of a stream)."""
        if not self._filled and not self._between:
            if frames:
                self._previous = frames[-1]
            return frames
        out: List[LiftedFrame] = []
        for f in frames:
            while self._between and self._between[0] < f.stamp_ns and \
                    self._previous is not None:
                out.append(_between_frame(self._previous, f, self._between.pop(0)))
            if f.stamp_ns in self._filled:
                self._filled.discard(f.stamp_ns)
            else:
                out.append(f)
            self._previous = f
        if end and self._previous is not None:
            while self._between:
                out.append(_between_frame(self._previous, self._previous,
                                          self._between.pop(0)))
        return out

    def _push(self, stamp_ns: int, kp: np.ndarray, intrinsics: CameraIntrinsics
              ) -> List[LiftedFrame]:
        """Add one frame to the buffer; returns the frames it released."""
        frames: List[LiftedFrame] = []
        self._intr = intrinsics
        self._kp.append(kp)
        self._stamps.append(int(stamp_ns))
        self.frames_seen += 1
        streamed = self._stream_push() if self._stream is not None else None
        if self.chunk > 1 and self.lengths is None and self._unlifted() > self.latency:
            # where frame-by-frame lifting would emit a frame (and update the skeleton)
            with torch.no_grad():
                lengths = self._estimate_lengths(*self._features()[:2])
            self._lengths_at[self.frames_seen] = lengths
            if self.frames_seen >= self.skeleton_frames:
                self.lengths = lengths
        if self._unlifted() >= self.latency + self.chunk:
            lifted = self._infer([-self._unlifted() + j for j in range(self.chunk)], streamed)
            self._keep_unsmoothed(lifted)
            frames.extend(lifted if self._smoother is None else self._smoother.push(lifted))
        return frames

    def _keep_unsmoothed(self, frames: List[LiftedFrame]) -> None:
        """Keep the network's frames (before the output smoothing) for
        :meth:`take_unsmoothed`, without the filled-in ones."""
        self._unsmoothed.extend(f for f in frames if f.stamp_ns not in self._filled)

    def take_unsmoothed(self) -> List[LiftedFrame]:
        """The frames the network released since the last call, before the output
        smoothing (so up to its radius earlier than :meth:`push` returns them smoothed): the
        legs swing as the network has them (the smoothing shortens a stride's fast knee
        swing). Without the frames filled in and the thinned ones (``network_rate_hz``);
        with smoothing off, the frames :meth:`push` returns."""
        out, self._unsmoothed = self._unsmoothed, []
        return out

    def pending(self) -> int:
        """Frames received but not yet returned (windowed mode waits for look-ahead, the
        output smoothing for its radius, a thinned frame for its successor); filled-in frames
        are not counted."""
        waiting = self._unlifted() + (self._smoother.pending() if self._smoother else 0)
        return waiting - len(self._filled) + len(self._between)

    def _unlifted(self) -> int:
        """Frames received but not yet through the network."""
        return sum(1 for s in self._stamps if s > self._last_emitted)

    def flush(self) -> List[LiftedFrame]:
        """Return the frames still waiting for look-ahead, computed with the future frames
        that exist (the end of a stream, or before a long pause), and those waiting in the
        output smoothing."""
        n = self._unlifted()
        frames = self._infer([-n + j for j in range(n)]) if n else []
        self._keep_unsmoothed(frames)
        if self._smoother is not None:
            frames = self._smoother.push(frames) + self._smoother.flush()
        return self._received(frames, end=True)

    def _stream_push(self) -> Optional[Tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Give the streaming encoder the newest frame (with the window's features, see
        :meth:`StreamingEncoder.push`). Returns (rows, out) raw E_Q output, (rows, 2)
        canonical root keypoint and (rows,) scale of frame ``latency`` frames back, or None
        while the segment is shorter than that."""
        feats, root_2d, scale = self._features_np()
        n = min(len(feats), self.context)
        f, r = feats[-n:][None], root_2d[-n:][None]
        if self.flip:
            fm, rm = mirror_features(f, r)
            f, r = np.concatenate([f, fm]), np.concatenate([r, rm])
        y = self._stream.push(f)
        if y is None:
            return None
        k = -1 - self._stream.lag
        return y, r[:, k], np.full(len(r), scale[k])

    @torch.no_grad()
    def _infer(self, indices: List[int], streamed=None) -> List[LiftedFrame]:
        """Lift the buffered frames at ``indices`` (negative, from the end, ascending) in one
        network pass over the context they need (``streamed``: the output of
        :meth:`_stream_push` for ``indices == [-1 - latency]``, used instead of the pass)."""
        if streamed is not None and len(indices) == 1 and indices[0] == -1 - self.latency:
            return self._emit_streamed(indices[0], *streamed)
        x, r, sc = self._features()
        fixed = self.lengths is not None
        if self.chunk > 1:
            per_frame = [self._lengths_for(self.frames_seen + i) for i in indices]
            lengths = per_frame[-1][0]
        else:
            if not fixed:
                lengths = self._estimate_lengths(x, r)
                if self.frames_seen >= self.skeleton_frames:
                    self.lengths = lengths
            else:
                lengths = self.lengths
            per_frame = [(lengths, fixed)] * len(indices)
        # the oldest frame to emit needs the context the newest-possible one would
        extra = max(0, -indices[0] - (1 + self.latency))
        ctx = slice(-(self.context + extra), None)
        lift_frames = getattr(self.model, 'lift_frames', None)
        if lift_frames is not None:
            # VTM: each frame from the window it gets frame by frame (ending `latency` frames
            # after it), so chunks and flushes give the frame-by-frame output
            n = min(x.shape[1], self.context + extra)
            out = lift_frames(x[:, ctx], r[:, ctx], lengths, [n + i for i in indices],
                              self.latency)
            rows = list(range(-len(indices), 0))      # the output holds those frames only
        else:
            xs, rs, scs = x[:, ctx], r[:, ctx], sc[:, ctx]
            if self.flip:   # the mirrored input as a second batch row of the same pass
                xm, rm = mirror_features(xs.cpu().numpy(), rs.cpu().numpy())
                xs = torch.cat([xs, torch.as_tensor(xm, device=xs.device)])
                rs = torch.cat([rs, torch.as_tensor(rm, device=rs.device)])
                scs = torch.cat([scs, scs])
                lengths = lengths.expand(2, -1)
            out = self.model(xs, rs, scs, lengths=lengths)
            rows = list(indices)
        skeletons: Dict[int, Tuple[Skeleton, float]] = {}
        rot = out['rotations'][0].cpu().numpy().astype(np.float64)
        root = out['root'][0].cpu().numpy().astype(np.float64)
        contacts = torch.sigmoid(out['contacts'][0]).cpu().numpy().astype(np.float64)
        if self.flip and lift_frames is None:
            rot = average_quaternions(rot, unmirror_rotations(
                out['rotations'][1].cpu().numpy().astype(np.float64)))
            root_m = out['root'][1].cpu().numpy().astype(np.float64) * [-1.0, 1.0, 1.0]
            root = 0.5 * (root + root_m)
            contacts = 0.5 * (contacts + torch.sigmoid(out['contacts'][1]).cpu().numpy()
                              .astype(np.float64)[:, [2, 3, 0, 1]])
        stamps = list(self._stamps)
        frames = []
        for i, k, (lengths_i, fixed_i) in zip(indices, rows, per_frame):
            key = id(lengths_i)
            if key not in skeletons:
                skeletons[key] = self._sized(lengths_i)
            skeleton, size = skeletons[key]
            self._last_emitted = stamps[i]
            rot_k, root_k = self._to_camera(i, rot[k], root[k])
            frames.append(LiftedFrame(stamps[i], Pose(skeleton, rot_k, size * root_k),
                                      contacts[k], fixed_i, float(size * root_k[2])))
        return frames

    def _to_camera(self, index: int, rotations: np.ndarray, root: np.ndarray
                   ) -> Tuple[np.ndarray, np.ndarray]:
        """(J, 4) rotations and (3,) root of the buffer's frame ``index`` in the real
        camera's optical frame: with ``virtual_camera`` the network's pose is in the frame of
        a camera looking at the person (:func:`~mocap_lifter.features.ray_rotations`) and is
        turned back with it; else unchanged."""
        if not self.virtual_camera or self._rays is None:
            return rotations, root
        R = self._rays[index]
        return turn_root_orientation(rotations, R), R @ root

    def _emit_streamed(self, index: int, y: np.ndarray, root_2d: np.ndarray,
                       scale: np.ndarray) -> List[LiftedFrame]:
        """The frame at ``index`` from the streaming encoder's raw output (rows, out): the
        same post-processing as :meth:`MotioNet.forward` and :meth:`_infer`."""
        x = None
        if self.lengths is None:
            x, r, _ = self._features()
            lengths = self._estimate_lengths(x, r)
            if self.frames_seen >= self.skeleton_frames:
                self.lengths = lengths
            fixed = False
        else:
            lengths, fixed = self.lengths, True
        nj = NUM_JOINTS
        y = y.astype(np.float64)
        q = y[:, :nj * 4].reshape(-1, nj, 4)
        q = q / np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), 1e-6)
        depth = np.exp(np.clip(y[:, nj * 4], -5.0, 5.0)) / np.maximum(scale, 1e-4)
        root = np.concatenate([root_2d * depth[:, None], depth[:, None]], axis=1)
        contacts = 1.0 / (1.0 + np.exp(-y[:, nj * 4 + 1:nj * 4 + 1 + NUM_CONTACTS]))
        rot, rt, ct = q[0], root[0], contacts[0]
        if self.flip:
            rot = average_quaternions(rot, unmirror_rotations(q[1]))
            rt = 0.5 * (rt + root[1] * [-1.0, 1.0, 1.0])
            ct = 0.5 * (ct + contacts[1][[2, 3, 0, 1]])
        stamp = self._stamps[index]
        self._last_emitted = stamp
        cached = self._held_skeleton
        if fixed and cached is not None and cached[0] is lengths:
            skeleton, size = cached[1:]               # the held skeleton, built once
        else:
            skeleton, size = self._sized(lengths)
            if fixed:
                self._held_skeleton = (lengths, skeleton, size)
        rot, rt = self._to_camera(index, rot, rt)
        return [LiftedFrame(stamp, Pose(skeleton, rot, size * rt), ct, fixed, float(size * rt[2]))]

    def _sized(self, lengths: torch.Tensor) -> Tuple[Skeleton, float]:
        """The skeleton of (1, G) estimated bone-group lengths, and the factor its root
        position and depth take: with a known ``subject_height`` the skeleton scaled to that
        stature and the factor of that scaling, else the estimate as it is and 1."""
        skeleton = Skeleton.from_group_lengths(lengths[0].cpu().numpy().astype(np.float64))
        if self.subject_height <= 0:
            return skeleton, 1.0
        size = skeleton.size_for_stature(self.subject_height)
        return skeleton.scaled(size), size

    def _features_np(self) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Features over the buffer: (T, C) float32, root keypoint (T, 2), scale (T,)."""
        kp = np.stack(self._kp)
        if self.smooth > 0:
            kp = smooth_keypoints(kp, self.smooth)
        feats, root_2d, scale, _, self._rays = lifter_features_and_rays(
            kp, self._intr, self.virtual_camera)
        return feats, root_2d, scale

    def _features(self):
        """Network inputs over the buffer: features (1, T, C), root keypoint (1, T, 2),
        scale (1, T)."""
        feats, root_2d, scale = self._features_np()
        return (torch.as_tensor(feats[None], device=self.device),
                torch.as_tensor(root_2d[None].astype(np.float32), device=self.device),
                torch.as_tensor(scale[None].astype(np.float32), device=self.device))

    def _estimate_lengths(self, x: torch.Tensor, r: torch.Tensor) -> torch.Tensor:
        """The skeleton estimate over the buffer's features (1, T, C) and root keypoints
        (1, T, 2) -> (1, G) bone-group lengths (E_S of MotioNet, E^B of VTM)."""
        return self.model.estimate_lengths(x, r)

    def _lengths_for(self, frame: int) -> Tuple[torch.Tensor, bool]:
        """chunk > 1: (lengths, held) frame number ``frame`` (0-based, this segment) gets: the
        estimate after the push at which frame-by-frame lifting would have emitted it."""
        push = min(frame + self.latency + 1, self.frames_seen)
        if push in self._lengths_at:
            return self._lengths_at[push], False
        if self.lengths is not None:
            return self.lengths, True
        # a segment shorter than the look-ahead, flushed: the estimate over what exists
        with torch.no_grad():
            lengths = self._estimate_lengths(*self._features()[:2])
        self._lengths_at[push] = lengths
        return lengths, False


@dataclass
class StreamStep:
    """What one keypoint message (or a flush) did, for the node's log and diagnostics."""

    frames: List[LiftedFrame] = field(default_factory=list)   # lifted frames now ready
    #: the network's frames before the output smoothing (OnlineLifter.take_unsmoothed)
    unsmoothed: List[LiftedFrame] = field(default_factory=list)
    resets: List[str] = field(default_factory=list)   # buffer and skeleton resets (reasons)
    errors: List[str] = field(default_factory=list)   # frames the network pass rejected
    jumped_back_s: float = 0.0    # > 0: the stamps jumped back this far, a new stream began
    dropped: str = ''             # why the message was not used ('' = it was)
    nobody: bool = False          # the tracked person is not in the message


class LifterStream:
    """A keypoint stream to lifted frames (module docstring).

    Args:
        lifter: the ring-buffered network.
        intrinsics: the intrinsics of the stream (camera info or approximate).
        person: row of the keypoint messages to track.
        max_gap_s: stamps jumping back by this much or more start a new stream
            (:class:`mocap_core.streams.StampOrder`); a smaller step back is dropped.
        hold_unseen_s: > 0: a keypoint unseen in a frame where the person is (confidence 0)
            and whose last sighting lies inside another person's box in this frame
            (``occluders`` of :meth:`push`: hidden behind someone) takes its last seen
            position and confidence if it was seen at most this long ago (s, stamps); 0, or
            a keypoint the detector dropped with nobody in front of it: it stays unseen
            (zeros in the network's input, as the network was trained on dropped keypoints).
    """

    def __init__(self, lifter: OnlineLifter, intrinsics: StreamIntrinsics, person: int = 0,
                 max_gap_s: float = 1.0, hold_unseen_s: float = 0.0) -> None:
        self.lifter = lifter
        self.intrinsics = intrinsics
        self.person = int(person)
        self.stamps = StampOrder(max(float(max_gap_s), 1e-9))
        if not hold_unseen_s >= 0:
            raise ValueError(f'hold_unseen_s must be >= 0, got {hold_unseen_s}')
        self.hold_unseen_ns = int(round(float(hold_unseen_s) * 1e9))
        self._last_kp = np.zeros((NUM_KEYPOINTS, 3))        # last seen u, v, confidence
        self._last_kp_ns = np.full(NUM_KEYPOINTS, np.iinfo(np.int64).min // 2, np.int64)
        #: keypoints filled in from their last sighting (``hold_unseen_s``)
        self.held_keypoints = 0
        # frames waiting for the intrinsics: (stamp ns, (23, 3) keypoints)
        self._held: Deque[Tuple[int, np.ndarray]] = collections.deque()

    def pending(self) -> int:
        """Frames received but not yet returned (waiting for intrinsics or look-ahead)."""
        return len(self._held) + self.lifter.pending()

    def push(self, stamp_ns: int, people: np.ndarray,
             occluders: Optional[np.ndarray] = None) -> StreamStep:
        """One keypoint message: (P, 23, 3) pixels + confidence, P >= 0 people;
        ``occluders``: (B, 4) boxes (x0, y0, x1, y1 px) of the other people in this frame,
        in front of whom this person's unseen keypoints may be hidden (``hold_unseen_s``;
        None: nobody)."""
        step = StreamStep()
        last = self.stamps.last_ns
        verdict = self.stamps.check(stamp_ns)
        if verdict == 'stale':
            step.dropped = 'keypoint stamp did not advance'
            return step
        if verdict == 'restart':
            step.jumped_back_s = (last - stamp_ns) * 1e-9
            self._release(step, force=True)
            step.frames.extend(self.lifter.flush())
            step.unsmoothed.extend(self.lifter.take_unsmoothed())
            self.lifter.reset()
            step.resets.append('backwards')
            self.intrinsics.restart()
            self._last_kp_ns[:] = np.iinfo(np.int64).min // 2
        kp = self._person(people)
        if kp is not None and self.hold_unseen_ns > 0:
            kp = self._hold_unseen(int(stamp_ns), kp, occluders)
        if kp is None:
            step.nobody = True
            if self.lifter.frames_seen == 0 and not self._held:
                step.dropped = 'nobody seen yet'
                return step
            kp = np.zeros((NUM_KEYPOINTS, 3))
        else:
            self.intrinsics.observe(kp)
        self._held.append((int(stamp_ns), kp))
        self._release(step)
        return step

    def flush(self) -> StreamStep:
        """End of the input or a pause: the frames waiting for intrinsics (the keypoint
        estimate is fixed from the frames seen), then those waiting for look-ahead."""
        step = StreamStep()
        self._release(step, force=True)
        step.frames.extend(self.lifter.flush())
        step.unsmoothed.extend(self.lifter.take_unsmoothed())
        return step

    def _hold_unseen(self, stamp_ns: int, kp: np.ndarray,
                     occluders: Optional[np.ndarray]) -> np.ndarray:
        """(23, 3) keypoints with the unseen ones that someone hides filled from their
        recent sightings (``hold_unseen_s``); the sightings are remembered."""
        kp = np.array(kp, dtype=np.float64, copy=True)
        seen = kp[:, 2] > 0
        self._last_kp[seen] = kp[seen]
        self._last_kp_ns[seen] = stamp_ns
        fill = ~seen & (stamp_ns - self._last_kp_ns <= self.hold_unseen_ns)
        if not fill.any():
            return kp
        boxes = np.zeros((0, 4)) if occluders is None else \
            np.asarray(occluders, dtype=np.float64).reshape(-1, 4)
        u, v = self._last_kp[:, 0:1], self._last_kp[:, 1:2]
        fill &= np.any((u >= boxes[:, 0]) & (u <= boxes[:, 2]) & (v >= boxes[:, 1])
                       & (v <= boxes[:, 3]), axis=1)
        kp[fill] = self._last_kp[fill]
        self.held_keypoints += int(fill.sum())
        return kp

    def _person(self, people: np.ndarray) -> Optional[np.ndarray]:
        """The tracked person's (23, 3) keypoints, or None if absent or all unseen."""
        people = np.asarray(people, dtype=np.float64)
        if people.ndim != 3 or self.person >= len(people) or \
                not np.any(people[self.person, :, 2] > 0):
            return None
        return people[self.person]

    def _release(self, step: StreamStep, force: bool = False) -> None:
        """Lift the held frames once intrinsics are known (``force``: fix the keypoint
        estimate now)."""
        if not self._held:
            return
        if force and not self.intrinsics.freeze():
            step.dropped = f'{len(self._held)} frame(s) without intrinsics'
            self._held.clear()
            return
        intr = self.intrinsics.current
        if intr is None:
            return
        while self._held:
            stamp, kp = self._held.popleft()
            try:
                frames, event = self.lifter.push(stamp, kp, intr)
            except ValueError as exc:   # e.g. a non-finite network output
                step.errors.append(str(exc))
                continue
            if event:
                step.resets.append(event)
            step.frames.extend(frames)
            step.unsmoothed.extend(self.lifter.take_unsmoothed())


@dataclass
class PeopleStep:
    """What one keypoint message (or a flush) did for every person.

    Attributes:
        steps: ``{id: StreamStep}`` of every person's stream that took part.
        ended: ids whose stream ended in this step (unseen for longer than the timeout, or a
            new stream began); their last frames are in ``steps``.
        main: the id of the main person of the message (the row ``person`` of the cloud,
            the one tracked longest), or None when that row holds nobody.
        restarted: > 0 when the stamps jumped back by that many seconds (by ``max_gap_s`` or
            more): every stream ended and a new stream began.
        flushed: on a restart, the last frames of the streams that ended (stamps of the old
            stream: to publish before ``steps``).
    """

    steps: Dict[int, StreamStep] = field(default_factory=dict)
    ended: List[int] = field(default_factory=list)
    main: Optional[int] = None
    restarted: float = 0.0        # > 0: the stamps jumped back this far (s): a new stream
    flushed: Dict[int, StreamStep] = field(default_factory=dict)   # the old stream's last


#: the lifter node's default ``hold_unseen_s`` (s): a keypoint hidden behind someone keeps its
#: last sighting this long (docs/multi_person.md, "Hidden keypoints held")
DEFAULT_HOLD_UNSEEN_S = 0.5
#: the node's default of ``virtual_camera`` (since session 56: rendered MPJPE 72.2 -> 69.4 mm
#: on the usual clips, 77.0 -> 69.7 on the travel clips; docs/lifter.md, "The person's ray")
DEFAULT_VIRTUAL_CAMERA = True

#: margin of a person's box around their confident keypoints, as a fraction of its width and
#: height on each side (the body reaches beyond the joints: head, hands, clothes)
BOX_MARGIN = 0.1


class PeopleStreams:
    """One :class:`LifterStream` per person id (several people in one keypoint stream).

    Each message's rows are routed by their id (``ids`` from the cloud's ``id`` field; an
    older cloud without ids gives ``None``: its rows are persons 1, 2, ... in a stable
    order). A person's stream is created when their id is first seen; while the id is away
    its stream gets the message without them (all-unseen keypoints, so that its windows
    keep their timing); once the id has been away for longer than ``timeout_s`` (message
    stamps) its stream is flushed and ended. All streams share one
    :class:`~mocap_lifter.intrinsics.StreamIntrinsics` (one camera).

    Args:
        make_lifter: returns a new :class:`OnlineLifter` (they share one network).
        intrinsics: the camera's intrinsics.
        person: row of the cloud that is the main person.
        max_gap_s: as :class:`LifterStream`.
        timeout_s: a person unseen this long (s) ends their stream.
        max_persons: the most streams at once; further ids are ignored (counted).
        hold_unseen_s: as :class:`LifterStream`, for every person.
    """

    def __init__(self, make_lifter, intrinsics: StreamIntrinsics, person: int = 0,
                 max_gap_s: float = 1.0, timeout_s: float = 1.0, max_persons: int = 8,
                 hold_unseen_s: float = 0.0) -> None:
        self.hold_unseen_s = float(hold_unseen_s)
        self.make_lifter = make_lifter
        self.intrinsics = intrinsics
        self.person = int(person)
        self.max_gap_s = float(max_gap_s)
        self.timeout_ns = int(float(timeout_s) * 1e9)
        self.max_persons = int(max_persons)
        self.streams: Dict[int, LifterStream] = {}
        self.last_seen: Dict[int, int] = {}
        self.ignored = 0           # rows of ids beyond max_persons
        #: frames filled in / thinned by the lifters of persons who are gone
        self.filled_ended = 0
        self.thinned_ended = 0
        self.held_ended = 0        # keypoints held (hold_unseen_s) by persons who are gone
        self._last_ns: Optional[int] = None

    @staticmethod
    def row_ids(people: np.ndarray, ids: Optional[np.ndarray]) -> np.ndarray:
        """(P,) the id of each row: ``ids``, or 1..P for a cloud without ids (rows with
        nobody in them get 0)."""
        n = len(people)
        if ids is None:
            seen = np.any(np.asarray(people)[..., 2] > 0, axis=-1) if n else np.zeros(0, bool)
            return np.where(seen, np.arange(1, n + 1), 0)
        ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        if len(ids) != n:
            raise ValueError(f'{len(ids)} ids for {n} rows')
        return ids

    def pending(self) -> int:
        return sum(s.pending() for s in self.streams.values())

    def push(self, stamp_ns: int, people: np.ndarray, ids: Optional[np.ndarray] = None
             ) -> PeopleStep:
        """One keypoint message: (P, 23, 3) keypoints and their (P,) ids (or None)."""
        people = np.asarray(people, dtype=np.float64).reshape(-1, NUM_KEYPOINTS, 3)
        rid = self.row_ids(people, ids)
        out = PeopleStep()
        if self.person < len(rid) and rid[self.person] > 0:
            out.main = int(rid[self.person])
        if self._last_ns is not None and stamp_ns <= self._last_ns - int(self.max_gap_s * 1e9):
            # a new stream (a bag looped): every person's stream ends; ids start again
            out.restarted = (self._last_ns - int(stamp_ns)) * 1e-9
            flushed = PeopleStep()
            for pid in list(self.streams):
                self._end(pid, flushed)
            out.flushed, out.ended = flushed.steps, flushed.ended
            self.intrinsics.restart()
            self._last_ns = int(stamp_ns)
        self._last_ns = int(stamp_ns) if self._last_ns is None else max(self._last_ns,
                                                                        int(stamp_ns))
        rows = {}
        for r, pid in enumerate(rid.tolist()):
            if pid > 0 and pid not in rows and np.any(people[r, :, 2] > 0):
                rows[pid] = r
        for pid, r in rows.items():
            if pid not in self.streams:
                if len(self.streams) >= self.max_persons:
                    self.ignored += 1
                    continue
                self.streams[pid] = LifterStream(self.make_lifter(), self.intrinsics, 0,
                                                 self.max_gap_s, self.hold_unseen_s)
            self.last_seen[pid] = int(stamp_ns)
            others = None
            if self.hold_unseen_s > 0 and len(rows) > 1:
                others = np.array(person_boxes(
                    None, people[[q for p_, q in rows.items() if p_ != pid]], BOX_MARGIN),
                    dtype=np.float64).reshape(-1, 4)
            out.steps[pid] = self.streams[pid].push(stamp_ns, people[r:r + 1], others)
        empty = np.zeros((0, NUM_KEYPOINTS, 3))
        for pid in list(self.streams):
            if pid in out.steps:
                continue
            if stamp_ns - self.last_seen[pid] > self.timeout_ns:
                self._end(pid, out)
            else:
                out.steps[pid] = self.streams[pid].push(stamp_ns, empty)
        return out

    def flush(self) -> PeopleStep:
        """End of the input or a pause: every stream's waiting frames (streams stay)."""
        out = PeopleStep()
        for pid, s in self.streams.items():
            out.steps[pid] = s.flush()
        return out

    def rate_counts(self) -> Tuple[int, int]:
        """Frames filled in and thinned (``network_rate_hz``) so far, every person's."""
        live = list(self.streams.values())
        return (self.filled_ended + sum(st.lifter.filled_frames for st in live),
                self.thinned_ended + sum(st.lifter.thinned_frames for st in live))

    def _end(self, pid: int, out: PeopleStep) -> None:
        stream = self.streams.pop(pid)
        step = stream.flush()
        self.filled_ended += stream.lifter.filled_frames
        self.thinned_ended += stream.lifter.thinned_frames
        self.held_ended += stream.held_keypoints
        self.last_seen.pop(pid, None)
        if pid in out.steps:
            out.steps[pid].frames.extend(step.frames)
            out.steps[pid].unsmoothed.extend(step.unsmoothed)
        else:
            out.steps[pid] = step
        out.ended.append(pid)
