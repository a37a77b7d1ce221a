"""Frame-by-frame GMR for the live node (no ROS imports).

:class:`OnlineGMR` keeps the last ``window`` frames of one person's local poses. When frame
``n`` arrives it emits frame ``k = n - lookahead``: the GRU runs over the window ending at
``n`` (so the motion ``dG_{k-1}`` into frame ``k`` sees ``lookahead + 1`` future frames; the
delay is ``lookahead / fps`` seconds), and the world pose is accumulated,
``G_k = G_{k-1} dG_{k-1}`` (eq. 2-4: ``R_k = R_{k-1} dR_{k-1}``,
``T_k = R_{k-1} dT_{k-1} + T_{k-1}``). ``lookahead = 0`` is the causal option: the newest
frame is emitted at once.

World frame (z up, m; §3.6 adapted): the first pose of a segment is gravity-aligned: its tilt
is the model's estimate of the up direction in the body frame (:mod:`.model`), its heading 0
(facing +x), its root above the origin at the height that puts the lowest foot contact point
on the floor z = 0. With ``tilt_correction`` = a > 0, every accumulated orientation is turned
by the fraction a of the rotation that takes its body-frame up ``R_k^T e_z`` to the
estimated up (pitch and roll only; heading and position are not corrected).

Floor input (``floor_input``, the physics stage's output: z up, floor z = 0): GMR gives the
heading and the horizontal translation (its accumulation is unchanged); the emitted root's
height and tilt are the input's
(one floor for all outputs: the world output's feet are exactly as high above z = 0 as the
physics put them, never below it).

Foot lock (``foot_lock``, with a floor input): a contact point lower than ``lock_height``
above the floor stands; the world root is placed so that the standing points stay where they
touched down (the mean over them of ``anchor - (R p_local)_xy``), and GMR's step moves the
root only while no point stands. The body then moves in the world by its own legs, as the
physics put its feet, and its feet do not skate in the world output; GMR still gives the
heading. A fused frame (a static or turning camera) is not locked: its root follows the
fused position, which follows the input root, whose feet are the physics' own; the lock
would keep GMR's drift instead (measured in docs/global.md). With
``moving_lock_time_constant_s`` > 0, the fused frames of a camera that turns without
walking stay locked, and the locked root is pulled towards the fused one with that time
constant (a walking camera's frames follow the fused root: its path is the person's).
The node leaves the lock off by default since session 53: the foot planting below keeps the
standing feet without moving the root, and the locked root was the world path's noisiest and
least accurate part (docs/global.md, "The foot lock, off").

The network's frame rate (``network_rate_hz``, > 0): GMR reads the frames it gets as
consecutive frames of its training rate (30 frames/s) and predicts the motion from one to
the next. A live pipeline whose keypoint node drops frames (a busy machine delivers 13-25 of
30 frames/s) would show it the motion two or three times too fast. A gap of ``m + 1`` periods
(1.5 periods or more, up to ``max_gap_s``) is therefore filled with ``m`` frames interpolated
between its ends (at most as many as the window holds besides the frames waiting): joint
rotations by slerp, the root linearly, the camera anchor of the frame before the gap or one
interpolated between two anchors of the same kind. They run through the network, the
accumulation, the fusion and the foot lock like received frames, but are never returned:
only the frames received come out, each with its own stamp, and the look-ahead stays
``lookahead`` periods in seconds.

Foot planting (``foot_plant``, with a floor input; :mod:`mocap_core.foot_plant`): the root
lock above moves the root, and only where it locks; a root that follows a fusion, or the
root lock's own compromise when both feet stand, still lets a stance foot slide when the
input's legs step shorter than the root travels (the lifter's stride is short in front and
back views). Every emitted pose therefore has its legs bent, by two-bone inverse kinematics
from the hips, so that the foot points that stand stay where they landed; the root, trunk and
arms are left as they are. A point stands when the lifter's contact probability of that
frame (``contacts``, matched by stamp) is at least ``contact_threshold``, or, without one,
when it is lower than ``lock_height``. What the leg cannot reach slides (measured in
docs/global.md, "Feet planted by the legs").

Treatment changes (``transition_time_constant_s`` > 0): the root comes from one of several
treatments per frame (GMR's accumulation alone, the foot lock, a fusion, the lock pulled
towards a fusion), chosen by the camera-motion estimate of that frame. Their roots differ:
the lock drifts from GMR's accumulation, a fusion pulls towards the input root. Switching
from one to another made the emitted root jump, which is where most of the world output's
excess acceleration was (measured in docs/global.md, "Treatment changes"). When the
treatment changes, the emitted root therefore goes on from the last emitted one at its last
velocity, and the difference to the new treatment's root (horizontal only with a floor
input: the height stays the input's) is carried as an offset that decays, critically damped
from rest, with the time constant (``(o + o t / tau) exp(-t / tau)``: no velocity step).
The treatments' own state (the lock's base, GMR's accumulation, the fusion) is not changed
by it; only what is emitted (pose, velocity, input transform) is. The first frame with a
known camera pose is not such a change: it is placed where the pose says.

The network's own pose (``network_pose`` of :meth:`OnlineGMR.add`, or
:meth:`OnlineGMR.set_network_pose` for a frame already added): the network may read another
local pose of the same frame than the one emitted. The world stage emits the physics output,
whose legs the PD control and the held feet swing less than the lifter's, and GMR steps by
what the legs do: fed the physics output it covers a shorter path than fed the lifter's
(measured in docs/global.md, "What the network reads"). With the lifter's pose of each frame
as the network's input, the heading and the path come from the lifter's legs and the body
that is placed is still the physics output (its height, tilt and feet). A frame without a
network pose uses its own.

Known heights (``measured_height_window_s``, with a floor input and known camera poses): the
input's floor (the physics floor, fitted to the lifter's stance feet) is the world's z = 0,
so the input's height carries that floor's error, and the joints the floor is fitted to lie
above the sole. A known camera pose measures the height too: the measured root
(:attr:`InputAnchor.root`, averaged as for the horizontal position) lies some height above
the input root; the median of that difference over the window's past frames and the
look-ahead frames after it (their own differences, so that a segment's first frames are not
raised by one or two lifter frames), followed with ``measured_height_follow_s`` (a window of
0: the frame's own difference, at once), raises the whole emitted body, and the input frame's
place in the world (``WorldFrame.input_translation``) with it.
The heights are then those of the pose's frame: the feet stand where the lifter's root puts
them, on the floor the lifter was sized by (its ``camera_pose_floor_z``), the joints a few
centimetres above it as real ones are (measured in docs/global.md, "The height from a known
pose").

Segments: a stamp that does not advance or a gap longer than ``max_gap_s`` ends the segment:
the frames waiting for look-ahead are emitted with the future frames that exist, the
accumulation restarts from a new gravity-aligned first pose, and :meth:`push` reports why.
Until ``lookahead + 1`` frames of a segment exist nothing is emitted (:meth:`frames_needed`).

Non-finite network outputs: before a frame's outputs enter the accumulation they are checked.
If the motion into the frame (or the pose accumulated from it) is not finite, the last finite
motion of the segment is used instead (constant velocity; zero motion before the first one);
a non-finite up estimate is replaced by the last finite one (+z before the first). The frame
is still emitted, marked ``held``, and counted in :attr:`OnlineGMR.nonfinite_outputs`; the
accumulated pose stays finite and the following frames use the network again.

Static camera (``fusion``, :class:`StaticCameraFusion`): the input's root trajectory in its
own frame (the camera frame of the lifter, the floor frame of the physics stage) is fixed to
the world when the camera does not move, and each accumulated pose is pulled towards it.

With a floor input, a frame of a camera that stands still (an anchor with ``static=True``, or
no anchors at all: a camera declared static) is pulled with its own, shorter time constants
(0.05 s for the position, 0 for the orientation): with both 0 its pose is the input root moved
rigidly into the world (the input frame does not move, so neither does the transform), and
the feet stay exactly where the input put them. The time constants of the other fused frames
(turning or translating cameras, whose anchors carry the noise of the camera-motion estimate,
and known camera poses) stay longer.

Camera motion (:class:`InputAnchor`, given per frame to :meth:`OnlineGMR.push`): when the
camera only turns, the input root is first turned back into the frame of the camera's first
image (``p_fixed = rotation p_input + translation``) and then fused as for a static camera;
when it translates (or nothing is known), the frame is not fused, and the fusion aligns
itself again (over ``init_s``) once the camera stops translating, since the camera's position
has changed by an unknown amount. Without anchors, a fusion fuses every frame (a camera
declared static).
"""

from __future__ import annotations

import collections
import dataclasses
import math
import weakref
from dataclasses import dataclass, field
from typing import Deque, List, Mapping, Optional, Tuple

import numpy as np
import torch

from mocap_core.foot_plant import FootPlantConfig, FootPlanter
from mocap_core.pose import Pose
from mocap_core.rotations import (axis_angle_to_matrix, matrix_to_axis_angle, matrix_to_quat,
                                  quat_from_two_vectors, quat_slerp, quat_to_matrix)
from mocap_core.skeleton import CONTACT_POINT_NAMES

from .features import features_for
from .inference import NumpyGMR
from .model import GMR
from .se3 import heading_rotation, tilt_rotation, yaw_of

_EZ = np.array([0.0, 0.0, 1.0])


@dataclass
class WorldFrame:
    """One output frame in the world frame (z up, floor z = 0)."""

    stamp_ns: int
    pose: Pose                      # row 0 of the rotations: the root orientation in the world
    linear_velocity: np.ndarray     # (3,) m/s in the root frame (REP-105 twist)
    angular_velocity: np.ndarray    # (3,) rad/s in the root frame
    first: bool                     # first frame of a segment (accumulation (re)started)
    fused: bool                     # the static-camera fusion corrected this frame
    held: bool = False              # the network output was not finite: last motion held
    #: (3, 3) rotation and (3,) translation: the pose of the input frame (the physics floor
    #: frame, or the camera frame when the lifter feeds the stage) in the world, so that
    #: ``p_world = input_rotation @ p_input + input_translation`` holds for the root of this
    #: frame. With a floor input it is a turn about z and a shift along the floor
    #: (translation z = 0: the two floors are one plane; with known heights, z is the raise,
    #: module docstring).
    input_rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    input_translation: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass(frozen=True)
class InputAnchor:
    """Where one frame's input frame sits in a frame fixed to the world (module docstring).

    ``fixed``: the camera has not translated, and ``p_fixed = rotation @ p_input +
    translation`` (rotation (3, 3), translation (3,) m) maps the input frame into the fixed
    frame (the camera, or the floor frame, at the first image). ``fixed=False``: the camera
    translates or its motion is unknown; the input root does not locate the person in the
    world. ``static``: the camera stands still in this frame, so the map is the same as in
    the frame before (no estimate noise in it): fused with the static time constants of
    :class:`StaticCameraFusion`. ``translating``: the camera walks or drives (its position
    measured over the floor); such frames follow the fused root even with
    ``moving_lock_time_constant_s``. ``known``: the map comes from a known camera pose
    (no estimate noise in it, however the camera moves): with a floor input (the physics
    output, already filtered) fused with the static time constants and never locked to
    GMR's feet, so that the world output is the input moved by the known map.
    ``root``: (3,) m, the person's root in the fixed frame as measured apart from the input
    (a known camera pose, or the camera motion estimated from the image, applied to the
    lifter's camera-frame root): its horizontal position
    (x, y) replaces the input root's in the measurement (the height stays the input's there;
    a known pose's height raises the emitted body instead, ``measured_height_window_s``);
    such frames are fused with the fusion's ``measured_position_time_constant_s``."""

    fixed: bool
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    static: bool = False
    translating: bool = False
    known: bool = False
    root: Optional[np.ndarray] = None

    def apply(self, R_in: np.ndarray, T_in: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """An input root pose (R (3, 3), T (3,)) in the fixed frame."""
        T = self.rotation @ T_in + self.translation
        if self.root is not None:
            T = np.array([self.root[0], self.root[1], T[2]])
        return self.rotation @ R_in, T


#: what :class:`OnlineGMR` averages of the measured roots (``measured_root_average``)
MEASURED_ROOT_AVERAGES = ('root', 'offset')


def _anchor_between(a: Optional[InputAnchor], b: Optional[InputAnchor], t: float
                    ) -> Optional[InputAnchor]:
    """The anchor of a frame filled in at fraction ``t`` between frames anchored ``a`` and
    ``b``: interpolated (rotation by slerp, translation linearly) when both are fixed anchors
    of the same kind, else ``a``'s."""
    if a is None or b is None or not (a.fixed and b.fixed) or a.static != b.static \
            or a.translating != b.translating or a.known != b.known:
        return a
    q = quat_slerp(matrix_to_quat(a.rotation), matrix_to_quat(b.rotation), t)
    root = None if a.root is None or b.root is None else (1.0 - t) * a.root + t * b.root
    return InputAnchor(True, quat_to_matrix(q), (1.0 - t) * a.translation + t * b.translation,
                       static=a.static, translating=a.translating, known=a.known, root=root)


class StaticCameraFusion:
    """Complementary filter of the GMR world pose with the input's root pose when the camera
    is static (beyond the paper).

    The input frame (the camera's optical frame, or the physics stage's floor frame) is fixed
    to the world, so the input root trajectory does not drift; GMR's does, but it is smooth.
    The world frame of the fused output is the input frame turned so that z is up:

    * ``input_up`` given (the up direction of the input frame, e.g. (0, 0, 1) for a floor
      frame): the world is the input frame rotated by the minimal rotation taking
      ``input_up`` to +z, and the fusion starts at the first frame (first pose = the
      measurement);
    * ``input_up=None`` (a camera frame of unknown tilt): for the first ``init_s`` seconds
      GMR runs alone while the up direction of the input frame is estimated as the mean of
      ``R_in u_i`` (the measured root orientation times GMR's up estimate in the body frame);
      the heading and origin are then chosen to match the GMR poses of that period (circular
      mean of the heading differences, mean position offset), and held.

    * ``known_world``: the input poses come already in the world frame (a known camera pose
      composed with the camera-frame pose, :class:`InputAnchor`): ``W`` is the identity, the
      fusion starts at the first frame and never needs to align itself again.

    Each new GMR pose ``G = G_prev dG`` is then pulled towards the measurement ``W (R_in,
    T_in)``: the position by ``1 - exp(-dt / position_time_constant_s)`` per frame, the
    orientation (geodesically) by ``1 - exp(-dt / orientation_time_constant_s)``; a frame
    of a camera that stands still (``step(..., static=True)``) by its own
    ``static_position_time_constant_s`` and ``static_orientation_time_constant_s``; a
    frame whose position was measured apart from the input (``step(..., measured=True)``,
    :attr:`InputAnchor.root`) by ``measured_position_time_constant_s`` (the orientation
    as a static frame's). A time constant of 0 takes the measurement as it is.

    ``measured_velocity_correction``: measured frames are fused by an alpha-beta filter
    instead: the position predicted by GMR's step plus a learned velocity correction ``b``
    (m per frame, fixed frame), the residual ``e = T_m - (T + b)`` corrects the position by
    ``alpha e`` and the velocity by ``beta e``, with ``alpha`` from the time constant and
    ``beta = alpha^2 / (2 - alpha)`` (critically damped). GMR's steps are short of a
    walker's (docs/global.md): a first-order pull then trails the person by ``(1 - ratio) v
    tau``; the velocity term takes that lag out. ``b`` restarts at zero with every frame
    that is not measured.
    """

    def __init__(self, fps: float, init_s: float = 1.0, position_time_constant_s: float = 0.15,
                 orientation_time_constant_s: float = 1.0,
                 input_up: Optional[np.ndarray] = None, known_world: bool = False,
                 static_position_time_constant_s: float = 0.05,
                 static_orientation_time_constant_s: float = 0.0,
                 measured_position_time_constant_s: float = 0.15,
                 measured_velocity_correction: bool = False) -> None:
        self.known_world = bool(known_world)
        self.measured_velocity_correction = bool(measured_velocity_correction)
        self.init_frames = max(1, int(round(init_s * fps)))

        def gain(tau: float) -> float:
            return 1.0 if tau <= 0 else 1.0 - math.exp(-1.0 / (fps * tau))
        self.alpha_p = gain(position_time_constant_s)
        self.alpha_r = gain(orientation_time_constant_s)
        self.alpha_p_static = gain(static_position_time_constant_s)
        self.alpha_r_static = gain(static_orientation_time_constant_s)
        self.alpha_p_measured = gain(measured_position_time_constant_s)
        a = self.alpha_p_measured
        self.beta_p_measured = a * a / (2.0 - a)
        self.input_up = None if input_up is None else \
            np.asarray(input_up, dtype=np.float64) / np.linalg.norm(input_up)
        self.reset()

    def reset(self) -> None:
        """A new segment: with a known input up the fused pose starts at the measurement."""
        self._pairs = []
        self.W_R, self.W_t = None, None
        self._realigning = False
        #: (3,) m per frame: the velocity GMR's steps miss (measured_velocity_correction)
        self.velocity_correction = np.zeros(3)
        if self.known_world:
            self.W_R, self.W_t = np.eye(3), np.zeros(3)
        elif self.input_up is not None:
            self.W_R = quat_to_matrix(quat_from_two_vectors(self.input_up, _EZ))
            self.W_t = np.zeros(3)

    def realign(self) -> None:
        """The input frame moved in the world by an unknown amount (a camera that
        translated): estimate its heading and origin again from GMR poses, as at the start
        with an unknown up: over the next ``init_s``, or, with a known input up (a floor
        frame), from the next frame alone, so that the output goes on from where GMR took it
        without a second of GMR alone. A no-op for a ``known_world``."""
        if self.known_world:
            return
        self._pairs: List[Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self.W_R: Optional[np.ndarray] = None
        self.W_t: Optional[np.ndarray] = None
        self._realigning = True

    @property
    def ready(self) -> bool:
        return self.W_R is not None

    def measurement(self, R_in: np.ndarray, T_in: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """The input root pose in the fused world frame."""
        return self.W_R @ R_in, self.W_R @ T_in + self.W_t

    def step(self, R: np.ndarray, T: np.ndarray, R_in: np.ndarray, T_in: np.ndarray,
             up_body: np.ndarray, first: bool = False,
             static: bool = False, measured: bool = False
             ) -> Tuple[np.ndarray, np.ndarray, bool]:
        """GMR pose (R, T), input root pose, GMR's up estimate in the body frame -> fused
        (R, T) and whether the measurement was used. ``first``: the first frame of a
        segment (with a known input up, the fused pose starts at the measurement);
        ``static``: the camera stands still in this frame (the static time constants);
        ``measured``: the position was measured apart from the input (its own time
        constant, the orientation's as ``static`` says)."""
        if self.W_R is None:
            self._pairs.append((R, T, R_in, T_in, up_body))
            need = 1 if self._realigning and self.input_up is not None else self.init_frames
            if len(self._pairs) >= need:
                self._estimate()
            return R, T, False
        Rm, Tm = self.measurement(R_in, T_in)
        if first or not (measured and self.measured_velocity_correction):
            self.velocity_correction = np.zeros(3)
        if first:
            return Rm, Tm, True
        a_p, a_r = (self.alpha_p_static, self.alpha_r_static) if static else \
            (self.alpha_p, self.alpha_r)
        if measured:
            a_p = self.alpha_p_measured
        if measured and self.measured_velocity_correction:
            T = T + self.velocity_correction
            e = Tm - T
            self.velocity_correction = self.velocity_correction + self.beta_p_measured * e
            T = T + a_p * e
        else:
            T = T + a_p * (Tm - T)
        corr = matrix_to_axis_angle(R.T @ Rm)
        R = R @ axis_angle_to_matrix(a_r * corr)
        return R, T, True

    def _estimate(self) -> None:
        g = self.input_up if self.input_up is not None else \
            np.mean([R_in @ u for _, _, R_in, _, u in self._pairs], axis=0)
        W0 = quat_to_matrix(quat_from_two_vectors(g, _EZ))
        d = np.array([yaw_of(R) - yaw_of(W0 @ R_in) for R, _, R_in, _, _ in self._pairs])
        psi = math.atan2(np.mean(np.sin(d)), np.mean(np.cos(d)))
        self.W_R = heading_rotation(psi) @ W0
        self.W_t = np.mean([T - self.W_R @ T_in for _, T, _, T_in, _ in self._pairs], axis=0)
        self._pairs = []


class OnlineGMR:
    """Streaming GMR with accumulation (module docstring).

    Args:
        model: the network.
        lookahead: future frames each emitted frame waits for (0 = causal).
        window: frames the GRU sees per update (default: the model's training window).
        max_gap_s: a larger gap between stamps restarts the accumulation.
        tilt_correction: fraction per frame by which the orientation is pulled towards the
            estimated tilt (0 = the paper's pure accumulation).
        fusion: a :class:`StaticCameraFusion` when the camera is static, else None.
        input_up: up direction of the input frame, for models with ``root_input='up'``.
        chunk: frames emitted per network pass (1 = each frame as soon as its look-ahead has
            arrived); more is faster per frame offline, and the earlier frames of a chunk see
            more than ``lookahead`` future frames.
        floor_input: the input is in a floor frame (z up, floor z = 0: the physics stage's
            output). The world pose then keeps the input's height and tilt (pitch, roll):
            GMR gives the heading and the horizontal translation, physics the vertical, so
            the world output stands on the floor the physics established (module
            docstring).
        foot_lock: with ``floor_input``, hold the contact points that stand on the floor
            (lower than ``lock_height`` m) where they touched down (module docstring).
        heading_smoothing: with ``floor_input``, h > 0 frames: the heading offset between
            the world and the input frame is averaged over the frames k - n .. k + n, n =
            min(h, frames available on both sides) (module docstring, heading); 0: GMR's
            heading of each frame.
        moving_lock_time_constant_s: with ``foot_lock`` and ``floor_input``, > 0: fused
            frames of a camera that turns but does not walk (anchors with ``static`` and
            ``translating`` False) keep the foot lock, and the locked root is pulled towards
            the fused one with this time constant (s); 0: such frames follow the fused root
            (module docstring, foot lock).
        network_rate_hz: > 0: gaps of 1.5 periods of this rate or more are filled with
            interpolated frames that are never returned (module docstring, the network's
            frame rate); 0: every frame is read as the next one.
        foot_plant: with ``floor_input``, the settings of the legs' correction applied to
            every emitted pose (:mod:`mocap_core.foot_plant`; module docstring, foot
            planting); None: off.
        transition_time_constant_s: > 0: when the frame's treatment (GMR alone, foot lock,
            fusion, lock pulled towards the fusion) changes, the emitted root goes on from
            the last one at its velocity and the difference decays with this time constant,
            s (module docstring, treatment changes); 0: the new treatment's root at once.
        contacts: stamp (ns) -> (4,) foot contact probabilities (left heel, left toe, right
            heel, right toe; the lifter's), read when a frame is emitted: a point stands in
            the foot planting when its probability is at least ``contact_threshold``. A frame
            without an entry falls back to the height rule (``lock_height``).
        inference: the network's engine: 'numpy' (:class:`~mocap_global.inference.NumpyGMR`:
            the same function to float32 rounding, about 1.7 times as fast for one window
            on a CPU; used for a plain GMR on the CPU, else PyTorch) or 'torch'.
    """

    def __init__(self, model: GMR, lookahead: int = 15, window: Optional[int] = None,
                 max_gap_s: float = 0.25, tilt_correction: float = 0.0,
                 fusion: Optional[StaticCameraFusion] = None,
                 input_up: Optional[np.ndarray] = None, device: str = 'cpu',
                 chunk: int = 1, floor_input: bool = False, foot_lock: bool = False,
                 lock_height: float = 0.02, heading_smoothing: int = 0,
                 moving_lock_time_constant_s: float = 0.0,
                 network_rate_hz: float = 0.0,
                 foot_plant: Optional[FootPlantConfig] = None,
                 contacts: Optional[Mapping[int, np.ndarray]] = None,
                 contact_threshold: float = 0.5,
                 transition_time_constant_s: float = 0.0,
                 measured_root_half_window: int = 0, inference: str = 'numpy',
                 measured_root_average: str = 'root',
                 measured_height_window_s: Optional[float] = None,
                 measured_height_follow_s: float = 0.2) -> None:
        self.model = model.eval()
        if inference not in INFERENCE_ENGINES:
            raise ValueError(f'inference must be one of {INFERENCE_ENGINES}, got {inference!r}')
        # the NumPy engine, where asked for and possible (a plain GMR on the CPU), else None
        self._numpy = _numpy_engine(model) if (
            inference == 'numpy' and device == 'cpu' and isinstance(model, GMR)) else None
        #: the network's engine in use: 'numpy' (:class:`~mocap_global.inference.NumpyGMR`)
        #: or 'torch'
        self.inference = 'numpy' if self._numpy is not None else 'torch'
        self.cfg = model.cfg
        self.window = int(window or self.cfg.window)
        self.lookahead = int(lookahead)
        self.chunk = int(chunk)
        if self.chunk < 1:
            raise ValueError(f'chunk must be >= 1, got {chunk}')
        if not 0 <= self.lookahead <= self.window - 1 - self.chunk:
            raise ValueError(f'lookahead must be in [0, {self.window - 1 - self.chunk}] for a '
                             f'window of {self.window} frames and chunks of {self.chunk}, '
                             f'got {lookahead}')
        self.max_gap_ns = int(max_gap_s * 1e9)
        self.tilt_correction = float(tilt_correction)
        self.fusion = fusion
        self.floor_input = bool(floor_input)
        self.foot_lock = bool(foot_lock)
        self.lock_height = float(lock_height)
        self.heading_smoothing = int(heading_smoothing)
        self.moving_lock_time_constant_s = float(moving_lock_time_constant_s)
        if not self.moving_lock_time_constant_s >= 0:
            raise ValueError('moving_lock_time_constant_s must be >= 0, got '
                             f'{moving_lock_time_constant_s}')
        self.transition_time_constant_s = float(transition_time_constant_s)
        #: a measured root (InputAnchor.root) is averaged over this many frames before and
        #: after its own (as many on each side as the buffer holds: no delay)
        self.measured_root_half_window = int(measured_root_half_window)
        if self.measured_root_half_window < 0:
            raise ValueError('measured_root_half_window must be >= 0, got '
                             f'{measured_root_half_window}')
        #: what that average is taken of: 'root' (the measured roots themselves) or
        #: 'offset' (their horizontal offsets from the input roots moved by the same maps,
        #: added to this frame's input root: the input's own motion between frames kept)
        if measured_root_average not in MEASURED_ROOT_AVERAGES:
            raise ValueError(f'measured_root_average must be one of {MEASURED_ROOT_AVERAGES}, '
                             f'got {measured_root_average!r}')
        self.measured_root_average = measured_root_average
        #: None: the height stays the input's; else a floor input's heights are raised by
        #: the median, over this window (s; 0: the frame's own), of the measured roots'
        #: height above the input root (known camera poses only; module docstring)
        self.measured_height_window_s = None if measured_height_window_s is None \
            else float(measured_height_window_s)
        if self.measured_height_window_s is not None \
                and not self.measured_height_window_s >= 0:
            raise ValueError('measured_height_window_s must be >= 0 or None, got '
                             f'{measured_height_window_s}')
        #: s: with a window above 0 the raise follows its median with this time constant
        #: (the median steps as samples enter and leave the window)
        self.measured_height_follow_s = float(measured_height_follow_s)
        if not self.measured_height_follow_s >= 0:
            raise ValueError('measured_height_follow_s must be >= 0, got '
                             f'{measured_height_follow_s}')
        #: the height the floor input is raised by now, m (None: not measured yet)
        self.measured_height: Optional[float] = None
        if not self.transition_time_constant_s >= 0:
            raise ValueError('transition_time_constant_s must be >= 0, got '
                             f'{transition_time_constant_s}')
        #: emitted frames whose treatment differed from the frame before (module docstring)
        self.treatment_changes = 0
        if self.heading_smoothing < 0:
            raise ValueError(f'heading_smoothing must be >= 0, got {heading_smoothing}')
        if not (np.isfinite(network_rate_hz) and network_rate_hz >= 0):
            raise ValueError(f'network_rate_hz must be >= 0, got {network_rate_hz}')
        self.period_ns = int(round(1e9 / network_rate_hz)) if network_rate_hz > 0 else 0
        self.planter = FootPlanter(foot_plant) if foot_plant is not None and floor_input \
            else None
        self.contacts = contacts
        self.contact_threshold = float(contact_threshold)
        #: emitted frames whose planting read the contacts (the rest: the height rule)
        self.planted_with_contacts = 0
        self.planted_by_height = 0
        #: frames filled in so far (run through the network, never returned)
        self.filled_frames = 0
        #: frames whose network input was another pose than the emitted one (``network_pose``)
        self.network_pose_frames = 0
        if self.cfg.root_input == 'up' and input_up is None:
            raise ValueError("this model needs the input frame's up direction (input_up)")
        self.input_up = None if input_up is None else np.asarray(input_up, dtype=np.float64)
        self.device = device
        self.joint_names = tuple(self.cfg.joint_names)
        self.segments = 0
        #: Frames whose network output was not finite and was replaced (module docstring).
        self.nonfinite_outputs = 0
        #: Frames not fused because their anchor said the camera translates (or is unknown).
        self.unanchored_frames = 0
        #: Frames fused with a root measured apart from the input (:attr:`InputAnchor.root`).
        self.measured_root_frames = 0
        #: a frame with a known camera pose was fused in this segment (``_fuse``)
        self._known_placed = False
        self.reset()

    # -- state -----------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget the buffer; the next frame starts a new segment (new first pose)."""
        size = self.window
        self._feats: Deque[np.ndarray] = collections.deque(maxlen=size)
        self._poses: Deque[Pose] = collections.deque(maxlen=size)
        self._anchors_in: Deque[Optional[InputAnchor]] = collections.deque(maxlen=size)
        self._stamps: Deque[int] = collections.deque(maxlen=size)
        self._filled: set = set()   # stamps of the filled-in frames not yet emitted
        self._received = 0          # frames of this segment (filled-in ones too)
        self._emitted = 0           # frames of this segment emitted
        self._R: Optional[np.ndarray] = None
        self._T: Optional[np.ndarray] = None
        self._R_out: Optional[np.ndarray] = None     # the last emitted pose
        self._T_out: Optional[np.ndarray] = None
        self._T_gmr_prev: Optional[np.ndarray] = None
        self._treatment: Optional[str] = None        # of the last emitted frame
        self._offset = np.zeros(3)                   # emitted root - treatment's root, m
        self._offset_rate = np.zeros(3)              # its rate of change, m/s
        self._dt_prev = 0.0                          # the last emitted frame's interval, s
        self._placed = False                         # this frame placed by a known pose
        self._T_pub: Optional[np.ndarray] = None     # the last two emitted roots
        self._T_pub_prev: Optional[np.ndarray] = None
        self._standing: dict = {}         # standing contact point -> its xy relative to root
        self._offsets: Deque[float] = collections.deque(maxlen=max(1, self.heading_smoothing))
        self._cache: Optional[Tuple[int, dict]] = None
        self._last_motion: Tuple[np.ndarray, np.ndarray] = (np.zeros(3), np.zeros(3))
        self._last_up = _EZ.copy()
        self.measured_height = None
        self._heights: Deque[Tuple[int, float]] = collections.deque()
        self._height_stamp: Optional[int] = None     # of the last raise
        if self.fusion is not None:
            self.fusion.reset()
        if self.planter is not None:
            self.planter.reset()

    def frames_needed(self) -> int:
        """Frames of a segment before the first output."""
        return self.lookahead + 1

    def pending(self) -> int:
        """Frames received but not yet emitted."""
        return self._received - self._emitted

    # -- input -----------------------------------------------------------------------------
    def check_pose(self, pose: Pose) -> None:
        """Raise ValueError when the pose's joints are not the model's."""
        if tuple(pose.joint_names) != self.joint_names:
            missing = [n for n in self.joint_names if n not in pose.joint_names]
            extra = [n for n in pose.joint_names if n not in self.joint_names]
            raise ValueError(
                f'joint set does not match the GMR model: it needs {len(self.joint_names)} '
                f'joints {list(self.joint_names)} in this order; the motion has '
                f'{len(pose.joint_names)} (missing {missing}, unknown {extra})')

    def push(self, stamp_ns: int, pose: Pose, anchor: Optional[InputAnchor] = None
             ) -> Tuple[List[WorldFrame], str]:
        """Add one frame. Returns (frames, event): the world frames that became ready and ''
        or the reason the accumulation restarted ('backwards', 'gap'); on a restart the frames
        of the previous segment still waiting for look-ahead come first. ``anchor``: the
        camera's motion for the fusion (:class:`InputAnchor`; None: fused as a static
        camera when there is a fusion). The same as :meth:`add` then :meth:`take`."""
        frames, event = self.add(stamp_ns, pose, anchor)
        frames.extend(self.take())
        return frames, event

    def add(self, stamp_ns: int, pose: Pose, anchor: Optional[InputAnchor] = None,
            network_pose: Optional[Pose] = None) -> Tuple[List[WorldFrame], str]:
        """:meth:`push` without the emission of the frames that became ready: returns the
        frames of a segment that a restart ended, and the event. Several people: ``add``
        each person's frame, :func:`prepare_outputs` (one network pass for all), then
        :meth:`take` each. ``network_pose``: the local pose the network reads for this
        frame instead of ``pose``'s (module docstring; the root is not read), e.g. the
        lifter's of the same stamp; None: ``pose``'s. Raises ValueError for a pose (either)
        with other joints or non-finite values."""
        self.check_pose(pose)
        _check_finite(pose)
        if network_pose is not None:
            self.check_pose(network_pose)
            _check_finite(network_pose)
        frames: List[WorldFrame] = []
        event = ''
        if self._stamps:
            dt = int(stamp_ns) - self._stamps[-1]
            if dt <= 0:
                event = 'backwards'
            elif dt > self.max_gap_ns:
                event = 'gap'
        if event:
            frames = self.flush()
            self.reset()
        elif self.period_ns and self._stamps \
                and 2 * (int(stamp_ns) - self._stamps[-1]) >= 3 * self.period_ns:
            self._fill(int(stamp_ns), pose, anchor)
        self._append(int(stamp_ns), pose, anchor, network_pose)
        return frames, event

    def set_network_pose(self, stamp_ns: int, pose: Pose) -> bool:
        """The network reads ``pose``'s local pose for the frame of ``stamp_ns`` added
        before (module docstring: the lifter's pose may come after the physics output of
        the same stamp). Returns False when no frame of the window has that stamp (nothing
        changes). Raises ValueError as :meth:`add`."""
        self.check_pose(pose)
        _check_finite(pose)
        for i in range(len(self._stamps) - 1, -1, -1):
            if self._stamps[i] == stamp_ns:
                self._feats[i] = self._features(pose)
                self.network_pose_frames += 1
                self._cache = None
                return True
            if self._stamps[i] < stamp_ns:
                break
        return False

    def _features(self, pose: Pose) -> np.ndarray:
        """(C,) network input of one frame's pose."""
        up = None
        if self.cfg.root_input == 'up':
            up = quat_to_matrix(pose.rotations[0]).T @ self.input_up
            up = up / np.linalg.norm(up)
        return features_for(self.cfg, pose.rotations[None], pose.skeleton.group_lengths(),
                            None if up is None else up[None])[0]

    def _append(self, stamp_ns: int, pose: Pose, anchor: Optional[InputAnchor],
                network_pose: Optional[Pose] = None) -> None:
        if network_pose is not None:
            self.network_pose_frames += 1
        self._feats.append(self._features(pose if network_pose is None else network_pose))
        self._poses.append(pose)
        self._anchors_in.append(anchor)
        self._stamps.append(stamp_ns)
        self._received += 1
        self._cache = None

    def _fill(self, stamp_ns: int, pose: Pose, anchor: Optional[InputAnchor]) -> None:
        """Add the frames missing before ``stamp_ns`` at the network's rate (module
        docstring): poses and anchors interpolated between the last frame and this one."""
        last, prev, prev_anchor = self._stamps[-1], self._poses[-1], self._anchors_in[-1]
        gap = stamp_ns - last
        # at most what the window holds besides the frames waiting and this one: a frame must
        # not leave the buffer before it is emitted (a long max_gap_s, a long look-ahead)
        missing = min(int(round(gap / self.period_ns)) - 1, self.window - 1 - self.pending())
        for j in range(1, missing + 1):
            a = j / (missing + 1)
            between = Pose(pose.skeleton, quat_slerp(prev.rotations, pose.rotations, a),
                           (1.0 - a) * np.asarray(prev.root_position, dtype=float)
                           + a * np.asarray(pose.root_position, dtype=float))
            stamp = last + int(round(a * gap))
            self._filled.add(stamp)
            self.filled_frames += 1
            self._append(stamp, between, _anchor_between(prev_anchor, anchor, a))

    def _received_only(self, frames: List[WorldFrame]) -> List[WorldFrame]:
        """``frames`` without the filled-in ones."""
        if not self._filled:
            return frames
        out = []
        for f in frames:
            if f.stamp_ns in self._filled:
                self._filled.discard(f.stamp_ns)
            else:
                out.append(f)
        return out

    def ready(self) -> bool:
        """Whether a chunk of frames has its look-ahead (:meth:`take` would emit it)."""
        return self.pending() >= self.lookahead + self.chunk

    def take(self) -> List[WorldFrame]:
        """The chunk of frames that has its look-ahead, or nothing (one network pass, cached,
        serves the whole chunk; :func:`prepare_outputs` may have run it already)."""
        frames = []
        while self.ready():         # several chunks after frames were filled in
            frames += [self._emit() for _ in range(self.chunk)]
        return self._received_only(frames)

    def flush(self) -> List[WorldFrame]:
        """Emit the frames still waiting for look-ahead with the future frames that exist
        (the end of a stream, a long pause, a restart)."""
        frames = []
        while self.pending() > 0:
            frames.append(self._emit())
        return self._received_only(frames)

    # -- inference ---------------------------------------------------------------------------
    @torch.no_grad()
    def _outputs(self) -> dict:
        """Network outputs over the current window (cached until the next push)."""
        if self._cache is None:
            _run_batch([self])
        return self._cache[1]

    def _window(self) -> np.ndarray:
        """(T, C) features of the current window."""
        return np.stack(self._feats)

    def _frame_up(self, out: dict, pos: int) -> Tuple[np.ndarray, bool]:
        """The up estimate of a window position, or the last finite one (module docstring).
        Returns (up (3,), replaced)."""
        up = out['up'][pos]
        if np.all(np.isfinite(up)):
            self._last_up = up
            return up, False
        return self._last_up, True

    def _step(self, aa: np.ndarray, dT: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """``G_k = G_{k-1} dG_{k-1}``: axis-angle ``aa`` (3,) rad and ``dT`` (3,) m in the body
        frame of frame k - 1 -> (R (3, 3), T (3,)) in the world."""
        R = self._R @ axis_angle_to_matrix(aa)          # eq. 3
        T = self._R @ dT + self._T                      # eq. 4
        return R, T

    def _lock_feet(self, k: int, R: np.ndarray, T: np.ndarray, T_gmr: np.ndarray,
                   pose: Pose) -> np.ndarray:
        """The output root position with the feet that stand on the floor held where they
        are (module docstring, foot lock). ``R``, ``T``: the output pose on the floor;
        ``T_gmr``: GMR's own position this frame.

        Differential: the root moves by minus the mean horizontal motion, relative to the
        root, of the points that stand in this frame and stood in the previous one, so that
        they do not move; a point that lands or lifts changes nothing at once (an absolute
        anchor per point made the root jump whenever the set of standing points changed,
        since each point's anchor drifts with the pose's noise)."""
        probe = Pose(pose.skeleton, np.concatenate([matrix_to_quat(R)[None],
                                                    pose.rotations[1:]]), np.zeros(3))
        local = np.array([probe.contact_positions()[n] for n in CONTACT_POINT_NAMES])
        down = local[:, 2] + T[2] < self.lock_height
        if k == 0 or self._T_gmr_prev is None:
            xy = T[:2].copy()
        else:
            held = [c for c in range(len(down)) if down[c] and c in self._standing]
            if held:
                xy = self._T_out[:2] - np.mean([local[c, :2] - self._standing[c]
                                                for c in held], axis=0)
            else:
                xy = self._T_out[:2] + (T_gmr[:2] - self._T_gmr_prev[:2])   # GMR's step
        # the standing points' horizontal positions relative to the root, for the next frame
        self._standing = {c: local[c, :2].copy() for c in range(len(down)) if down[c]}
        self._T_gmr_prev = T_gmr.copy()
        return np.array([xy[0], xy[1], T[2]])

    @staticmethod
    def _on_floor(offset: float, T: np.ndarray, pose: Pose) -> Tuple[np.ndarray, np.ndarray]:
        """The floor-frame input pose turned by the heading ``offset`` (rad) about the
        vertical, at GMR's horizontal position and the input's height: ``R = Rz(offset)
        R_in``, ``T_z = T_in,z``. Turning a pose about the vertical does not change any
        height, so every joint and contact point is as high above z = 0 as in the input."""
        R = heading_rotation(offset) @ quat_to_matrix(pose.rotations[0])
        return R, np.array([T[0], T[1], float(pose.root_position[2])])

    def _heading_offset(self, R: np.ndarray, out: dict, pos: int) -> float:
        """The heading offset (rad) between the world and the input frame at window
        position ``pos``: ``yaw(R) - yaw(R_in)`` of this frame (``R``: GMR's orientation),
        averaged (circular mean) with the offsets of the ``n`` frames before and after it,
        the later ones from GMR's motion over the look-ahead (module docstring, heading)."""
        n = min(self.heading_smoothing, len(self._offsets), len(self._poses) - 1 - pos)
        # the motions into frames pos + 1 .. pos + n, up to the first that is not finite;
        # converted in one call each (this runs for every frame: per-frame conversions cost
        # about 1 ms at n = 7)
        steps = out['axis_angle'][pos:pos + n]
        bad = np.flatnonzero(~np.all(np.isfinite(steps), axis=1))
        ahead = int(bad[0]) if len(bad) else n
        R_in = quat_to_matrix(np.stack([self._poses[p].rotations[0]
                                        for p in range(pos, pos + ahead + 1)]))
        R_k = [R]
        for step in (axis_angle_to_matrix(steps[:ahead]) if ahead else ()):
            R_k.append(R_k[-1] @ step)
        later = yaw_of(np.stack(R_k)) - yaw_of(R_in)
        now = float(later[0])
        values = [now] + list(self._offsets)[len(self._offsets) - n:] + \
            [float(v) for v in later[1:]]
        if self.heading_smoothing > 0:
            self._offsets.append(now)
        if len(values) == 1:
            return now
        return math.atan2(float(np.mean(np.sin(values))), float(np.mean(np.cos(values))))

    def _smoothed_anchor(self, pos: int) -> Optional[InputAnchor]:
        """The anchor of buffer position ``pos`` with its measured root averaged over the
        ``measured_root_half_window`` frames on each side that the buffer holds, in pairs
        (the frames j before and j after, both fixed with a root of the same kind): the mean
        of a steady walk is its middle, no lag. A fixed frame without a root of its own (no
        lifter pose of its stamp) takes the mean of those pairs alone. Pairs are taken
        across frames without a root: for roots moved by the camera-motion estimate that
        is an approximation (across an unmeasured camera step the fixed frame moved by
        that step), measured better than stopping at such a frame (docs/global.md).

        With ``measured_root_average`` 'offset' the average is of each root's offset (the
        horizontal part is what the fusion reads, the height only the known heights) from its
        frame's input root moved by the same anchor, and the result is this
        frame's input root (so moved) plus that mean offset: the measured root's slow part
        (where the person is) with the input's motion from frame to frame (the physics
        body's, whose feet stand where that root puts them)."""
        anchor = self._anchors_in[pos]
        h = min(self.measured_root_half_window, pos, len(self._anchors_in) - 1 - pos)
        if anchor is None or not anchor.fixed or h <= 0:
            return anchor

        offset = self.measured_root_average == 'offset'

        def moved_input(i: int) -> np.ndarray:
            a = self._anchors_in[i]
            return a.rotation @ np.asarray(self._poses[i].root_position, float) + a.translation

        def root(i: int) -> Optional[np.ndarray]:
            a = self._anchors_in[i]
            if a is None or not a.fixed or a.known != anchor.known or a.root is None:
                return None
            if offset:
                # (the height too: only the known heights read it, InputAnchor.apply does not)
                return np.asarray(a.root, float) - moved_input(i)
            return a.root
        own = root(pos)
        roots = [] if own is None else [own]
        for j in range(1, h + 1):
            before, after = root(pos - j), root(pos + j)
            if before is not None and after is not None:
                roots += [before, after]
        if not roots:
            return anchor
        mean = np.mean(roots, axis=0)
        return dataclasses.replace(anchor, root=moved_input(pos) + mean if offset else mean)

    def _fuse(self, R: np.ndarray, T: np.ndarray, pose: Pose, anchor: Optional[InputAnchor],
              up: np.ndarray, first: bool) -> Tuple[np.ndarray, np.ndarray, bool]:
        """The fusion step of one frame (module docstring: static camera, camera motion)."""
        R_in, T_in = quat_to_matrix(pose.rotations[0]), np.asarray(pose.root_position, float)
        if first:
            self._known_placed = False
        if anchor is not None:
            if not anchor.fixed:
                self.unanchored_frames += 1
                if self.fusion.ready or self.fusion._pairs:
                    self.fusion.realign()
                return R, T, False
            R_in, T_in = anchor.apply(R_in, T_in)
            if anchor.known and not self._known_placed:
                # the segment's first frame with a known pose (the ones before it, without
                # one, are GMR's from an arbitrary origin): it is placed where the pose says,
                # not pulled there over the next frames
                first = True
                self._known_placed = True
                self._placed = True
        # no anchors: a camera declared static; a known camera pose moves. Only a floor
        # input (the physics output, already filtered) is taken as it is: a camera-frame
        # root carries the lifter's depth noise
        static = self.floor_input and (anchor.static or anchor.known if anchor is not None
                                       else not self.fusion.known_world)
        measured = anchor is not None and anchor.root is not None
        if measured:
            self.measured_root_frames += 1
        return self.fusion.step(R, T, R_in, T_in, up, first=first, static=static,
                                measured=measured)

    def _emit(self) -> WorldFrame:
        k = self._emitted                               # segment index of the frame
        first_in_buffer = self._received - len(self._stamps)
        pos = k - first_in_buffer                       # its position in the window
        out = self._outputs()
        pose = self._poses[pos]
        up, held = self._frame_up(out, pos)
        lin = np.zeros(3)
        ang = np.zeros(3)
        fused = False
        dt = 0.0
        if k == 0:
            R = tilt_rotation(up)
            T = np.array([0.0, 0.0, 0.0])
            probe = Pose(pose.skeleton, np.concatenate([matrix_to_quat(R)[None],
                                                        pose.rotations[1:]]), T)
            T[2] = -min(p[2] for p in probe.contact_positions().values())
        else:
            aa = out['axis_angle'][pos - 1]
            dT = out['translation'][pos - 1]
            R, T = self._step(aa, dT)
            if np.all(np.isfinite(R)) and np.all(np.isfinite(T)):
                self._last_motion = (aa, dT)
            else:                                       # hold the last finite motion
                held = True
                R, T = self._step(*self._last_motion)
            if self.tilt_correction > 0:
                b = R.T @ _EZ
                corr = matrix_to_axis_angle(quat_to_matrix(quat_from_two_vectors(up, b)))
                R = R @ axis_angle_to_matrix(self.tilt_correction * corr)
            dt = (self._stamps[pos] - self._stamps[pos - 1]) * 1e-9
        self._placed = False
        anchor_s = self._smoothed_anchor(pos)
        if self.fusion is not None:
            R, T, fused = self._fuse(R, T, pose, anchor_s, up, k == 0)
        if k % 64 == 0:
            R = quat_to_matrix(matrix_to_quat(R))       # re-orthonormalise
        T_gmr = T
        self._R, self._T = R, T                         # the accumulation stays GMR's
        treatment = 'fused' if fused else 'gmr'
        if self.floor_input:
            R, T = self._on_floor(self._heading_offset(R, out, pos), T, pose)
            anchor = self._anchors_in[pos]
            turning = anchor is not None and not (anchor.static or anchor.translating
                                                  or anchor.known)
            if self.foot_lock and fused and turning and self.moving_lock_time_constant_s > 0:
                # a turning camera's fused root carries the noise of the estimate of its
                # motion: the feet stay locked (steps follow the fused root while no point
                # stands), and the locked root is pulled towards the fused one
                T_lock = self._lock_feet(k, R, T, T_gmr, pose)
                g = 1.0 - math.exp(-max(dt, 0.0) / self.moving_lock_time_constant_s)
                T = np.array([T_lock[0] + g * (T[0] - T_lock[0]),
                              T_lock[1] + g * (T[1] - T_lock[1]), T[2]])
                treatment = 'lock pulled to fused'
            elif self.foot_lock and fused:
                # the fused root follows the input's, whose feet are the physics' own: no
                # lock (it would keep GMR's drift); it starts afresh when the fusion stops
                self._standing = {}
                self._T_gmr_prev = T_gmr.copy()
            elif self.foot_lock:
                T = self._lock_feet(k, R, T, T_gmr, pose)
                treatment = 'lock'
        lift = self._height_lift(anchor_s, pose, pos) if self.floor_input else 0.0
        T = np.array([T[0], T[1], T[2] + lift])
        self._T_out = T                                 # the treatments' own state
        T = self._continue(k, T, treatment, dt)
        if k > 0 and dt > 0:
            lin = R.T @ (T - self._T_pub_prev) / dt
            ang = matrix_to_axis_angle(self._R_out.T @ R) / dt
        self._R_out = R
        self._emitted += 1
        self.nonfinite_outputs += int(held)
        if k == 0:
            self.segments += 1
        rot = np.array(pose.rotations)
        rot[0] = matrix_to_quat(R)
        R_wi = R @ quat_to_matrix(pose.rotations[0]).T
        t_wi = T - R_wi @ np.asarray(pose.root_position, dtype=float)
        if self.floor_input:        # exact: a turn about z, the floors parallel
            R_wi = heading_rotation(yaw_of(R_wi))
            t_wi[2] = lift              # (0 unless raised to the measured roots' height)
        if self.planter is not None:
            # planted on the input's floor (z = 0 before the lift), then lifted
            planted = self._plant(Pose(pose.skeleton, rot, T - [0.0, 0.0, lift]),
                                  self._stamps[pos], dt)
            out_pose = Pose(pose.skeleton, planted.rotations,
                            np.asarray(planted.root_position, float) + [0.0, 0.0, lift])
        else:
            out_pose = Pose(pose.skeleton, rot, T)
        return WorldFrame(self._stamps[pos], out_pose, lin, ang, k == 0, fused, held, R_wi,
                          t_wi)

    def _height_lift(self, anchor: Optional[InputAnchor], pose: Pose, pos: int) -> float:
        """How far (m) a floor input's heights are raised in the frame at buffer position
        ``pos``: with ``measured_height_window_s`` set, the median of the measured root's
        height (a known camera pose's world, :attr:`InputAnchor.root`; ``anchor`` is this
        frame's, averaged as the horizontal is) above the input root's, over the frames of
        that window before this one and the look-ahead frames after it (their own roots), so
        that a segment's first frames are not raised by one or two of their own (a window of
        0: this frame's alone), followed with ``measured_height_follow_s``; held across
        frames without one, 0 before the first of a segment and without the option (module
        docstring, known heights)."""
        window = self.measured_height_window_s
        if window is None:
            return 0.0

        def above(a: Optional[InputAnchor], p: Pose) -> Optional[float]:
            if a is None or not a.known or a.root is None:
                return None
            d = float(a.root[2]) - float(p.root_position[2])
            return d if math.isfinite(d) else None

        stamp_ns = self._stamps[pos]
        d = above(anchor, pose)
        if d is not None:
            self._heights.append((stamp_ns, d))
        while self._heights and self._heights[0][0] < stamp_ns - window * 1e9:
            self._heights.popleft()
        values = [d for _, d in self._heights]
        for later in range(pos + 1, len(self._anchors_in) if window > 0 else 0):
            d = above(self._anchors_in[later], self._poses[later])
            if d is not None:
                values.append(d)
        if values:
            median = float(np.median(values))
            tau = self.measured_height_follow_s if window > 0 else 0.0
            if self.measured_height is None or self._height_stamp is None or tau <= 0:
                self.measured_height = median
            else:
                # the median steps between samples as they enter and leave: followed smoothly
                dt = max(stamp_ns - self._height_stamp, 0) * 1e-9
                self.measured_height += (1.0 - math.exp(-dt / tau)) * (
                    median - self.measured_height)
            self._height_stamp = stamp_ns
        return 0.0 if self.measured_height is None else self.measured_height

    def _continue(self, k: int, T: np.ndarray, treatment: str, dt: float) -> np.ndarray:
        """The emitted root position (3,) m for the treatment's root ``T`` (module
        docstring, treatment changes); keeps the last two emitted roots."""
        tau = self.transition_time_constant_s
        changed = k > 0 and self._treatment is not None and treatment != self._treatment \
            and not self._placed
        self.treatment_changes += int(changed)
        if k == 0 or tau <= 0 or self._T_pub is None or self._placed:
            # a segment's first frame, or the first frame with a known camera pose, which is
            # placed where the pose says (the frames before it are GMR's from an arbitrary
            # origin): no offset
            self._offset = np.zeros(3)
            self._offset_rate = np.zeros(3)
        elif changed:
            # the last step, scaled to this frame's interval (frames need not be evenly
            # spaced): the root goes on at its velocity
            step = np.zeros(3)
            if self._T_pub_prev is not None and self._dt_prev > 0 and dt > 0:
                step = (self._T_pub - self._T_pub_prev) * (dt / self._dt_prev)
            self._offset = self._T_pub + step - T
            self._offset_rate = np.zeros(3)
            if self.floor_input:
                self._offset[2] = 0.0
        elif dt > 0:
            # critically damped decay, o(t) = (o + (o' + o / tau) t) exp(-t / tau): starting
            # at rest, so that taking the offset up does not change the velocity at once
            e = math.exp(-dt / tau)
            drive = self._offset_rate + self._offset / tau
            self._offset, self._offset_rate = ((self._offset + drive * dt) * e,
                                               (self._offset_rate - drive * dt / tau) * e)
        self._treatment = treatment
        self._dt_prev = dt
        out = T + self._offset
        self._T_pub_prev = None if k == 0 else self._T_pub
        self._T_pub = out
        return out

    def _plant(self, pose: Pose, stamp_ns: int, dt: float) -> Pose:
        """The emitted pose with its legs corrected (module docstring, foot planting)."""
        probs = None if self.contacts is None else self.contacts.get(stamp_ns)
        standing = None
        if probs is not None and len(probs) == len(CONTACT_POINT_NAMES) \
                and np.all(np.isfinite(probs)):
            standing = {n: bool(v >= self.contact_threshold)
                        for n, v in zip(CONTACT_POINT_NAMES, probs)}
            self.planted_with_contacts += 1
        else:
            self.planted_by_height += 1
        return self.planter.apply(pose, dt, standing)


@torch.no_grad()
def _check_finite(pose: Pose) -> None:
    """Raise ValueError when the pose has a non-finite value."""
    if not (np.all(np.isfinite(pose.rotations)) and np.all(np.isfinite(pose.root_position))
            and np.all(np.isfinite(pose.skeleton.offsets))):
        raise ValueError('pose contains NaN or inf')


#: The network engines :class:`OnlineGMR` can run (its ``inference``).
INFERENCE_ENGINES = ('numpy', 'torch')

#: One NumPy copy of each network's weights, shared by the states that run it.
_NUMPY_ENGINES: 'weakref.WeakKeyDictionary[torch.nn.Module, NumpyGMR]' = \
    weakref.WeakKeyDictionary()


def _numpy_engine(model: GMR) -> NumpyGMR:
    engine = _NUMPY_ENGINES.get(model)
    if engine is None:
        engine = _NUMPY_ENGINES[model] = NumpyGMR(model)
    return engine


def prepare_outputs(states: List['OnlineGMR']) -> int:
    """Run the network once for every state in ``states`` that is :meth:`~OnlineGMR.ready`
    and has no outputs for its current window yet (several people: one pass with a batch row
    per person instead of one pass each; a batch of two costs about 1.2 passes of one on a
    CPU). States that share a network, a device, an engine and a window length go into one
    batch; the others get their own passes. The outputs are what each state's own pass
    gives, to the float32 rounding of a batched kernel. Returns the number of passes run."""
    groups: dict = {}
    for st in states:
        if st._cache is None and st.ready():
            key = (id(st.model), st.device, st.inference, len(st._feats))
            groups.setdefault(key, []).append(st)
    for group in groups.values():
        _run_batch(group)
    return len(groups)


@torch.no_grad()
def _run_batch(group: List['OnlineGMR']) -> None:
    """One network pass over the windows of ``group`` (same network, device, engine and
    window length); each state's outputs are cached."""
    x = np.stack([st._window() for st in group])
    if group[0]._numpy is not None:
        arrays = group[0]._numpy(x)
    else:
        out = group[0].model(torch.as_tensor(x, device=group[0].device))
        arrays = {k: v.cpu().numpy().astype(np.float64) for k, v in out.items()}
    for i, st in enumerate(group):
        st._cache = (st._received, {k: v[i] for k, v in arrays.items()})
