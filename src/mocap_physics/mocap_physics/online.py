"""Frame-by-frame physics for the live node, the benchmark and the evaluation (no ROS imports).

:class:`OnlinePhysics` turns a stream of kinematic target poses (stamped, in the input's
frame) and foot-contact probabilities (stamped, arriving before, after or never) into
physics-corrected frames in a floor frame (z up, floor z = 0), one person:

1. **Order** (:meth:`OnlinePhysics.admit`): a motion stamp must be after the previous one,
   else the frame is dropped. A stamp more than ``max(max_frame_gap, 1 s)`` before the newest
   one starts a new stream (a bag played again): the waiting frames are finished first,
   contacts stamped more than 1 s after the new stamp are forgotten, and the cycle
   re-initialises at the time jump.
2. **Contacts by stamp** (:meth:`OnlinePhysics.process`): a waiting motion frame takes the
   contacts with exactly its stamp. Without them, while contacts are expected (a contacts
   publisher exists, ``contacts_expected()``, or contacts already arrived) and no newer
   contacts arrived, it waits up to
   ``contacts_wait_s`` (wall clock, ``clock()``); then it takes the newest older contacts if
   at most ``contacts_max_age_s`` older (stamp time), else none (contact from the kinematics
   only). Frames leave in stamp order.
3. **Floor** (:meth:`OnlinePhysics.step`), given at construction: None (the input already is
   in a floor frame), a fixed :class:`~.floor.FloorFrame` (``p_floor = R p_in + t``), or a
   :class:`~.floor.FloorTracker` fitted to the feet. When the tracker replaces its frame,
   the simulated state is re-expressed in the new one (``PhysicsCycle.change_frame`` with
   ``T_new T_old^-1``).
4. **Camera motion** (optional, per frame: the camera's pose since the first image, as
   :class:`~.camera_rotation.CameraRotations` gives it): where the frame before had one
   too, the simulated state (body, stance anchors, the last target) is carried by the turn
   about the floor's normal and the shift along it that the camera's motion made the world
   take in the floor frame (:func:`~.camera_rotation.camera_step_on_floor`,
   ``PhysicsCycle.change_frame``): the floor frame rides with the camera, and a foot that
   stands in the world keeps standing.
5. **Cycle**: the target, mapped into the floor frame, goes through
   :meth:`~.cycle.PhysicsCycle.step` with the time ``stamp_ns * 1e-9`` s.

What the node logs or counts comes out as :class:`Notice` objects (passed to ``report``) in
the order it happens; the corrected frames are returned as :class:`PhysicsFrame` lists.
"""

from __future__ import annotations

import collections
import time
from dataclasses import dataclass
from typing import Callable, Deque, List, Optional, Tuple, Union

import numpy as np

from mocap_core.pose import Pose
from mocap_core.skeleton import Skeleton

from .cycle import InvalidInput, PhysicsCycle
from .cycle_params import PhysicsParams
from .camera_rotation import camera_step_on_floor
from .floor import FloorFrame, FloorTracker, UprightPrior
from .foot import FLAT_FOOT_UPDATE_DEG, FlatFootEstimator
from .model import SkeletonError
from .results import FrameResult

#: Frame of an input without a frame_id (the lifter's camera optical frame).
DEFAULT_INPUT_FRAME = 'camera_optical_frame'
#: Contacts messages kept for matching (the oldest are forgotten first).
MAX_CONTACTS = 256

#: a camera's pose: (R (3, 3), C (3,) m), its frame into the first image's camera frame
CameraPose = Tuple[np.ndarray, np.ndarray]
FloorSource = Union[None, FloorFrame, FloorTracker]


@dataclass
class Notice:
    """Something the caller should log or count.

    Attributes:
        key: groups repeated notices for rate limiting (e.g. ``'order'``, ``'floor'``).
        text: one line for the log.
        level: ``'info'`` (log, at most once per ``period_s``), ``'warn'`` (log, at most
            once per ``period_s`` and key), ``'problem'`` (an error: count it, show it as
            the diagnostics warning and log it like ``'warn'``) or ``'status'`` (the
            diagnostics warning only).
        dropped: a motion frame was dropped.
        period_s: rate limit of the log, s.
    """

    key: str
    text: str
    level: str = 'warn'
    dropped: bool = False
    period_s: float = 5.0


@dataclass
class PhysicsFrame:
    """One corrected frame.

    Attributes:
        stamp_ns: the input motion's stamp, ns.
        result: the cycle's output, in the floor frame (:class:`~.results.FrameResult`).
        frame_id: frame of the outputs (``frame_id`` argument, else ``floor`` with a floor
            source, else the input's frame, else ``world``).
        input_frame: the input's frame_id (``camera_optical_frame`` when empty).
        floor: the floor frame used, as the transform input frame -> floor frame; None when
            the input already is in a floor frame.
    """

    stamp_ns: int
    result: FrameResult
    frame_id: str
    input_frame: str
    floor: Optional[FloorFrame]


class OnlinePhysics:
    """Streaming physics cycle (module docstring).

    Args:
        params: the cycle's parameters (validated; learned gains are loaded now).
        floor: None, a fixed :class:`FloorFrame` or a :class:`FloorTracker`.
        frame_id: frame_id of the outputs; empty = ``floor`` with a floor source, the
            input's otherwise.
        contacts_wait_s: longest wait (``clock()`` time) of a motion frame for its contacts.
        contacts_max_age_s: oldest (stamp time) contacts used for a frame without its own.
        contacts_expected: None when there is no contacts input at all; else a callable
            saying whether contacts are expected now (a publisher exists).
        report: receives every :class:`Notice` (default: ignored).
        record_time: receives the duration (s) of every cycle step run, failed ones too.
        clock: monotonic clock, s.
        skeleton: the skeleton, when known before the first frame.

    Raises:
        ValueError: bad parameters; ``mocap_core.checkpoint.WeightsError`` for unusable
            learned-gain weights.
    """

    def __init__(self, params: PhysicsParams, floor: FloorSource = None, frame_id: str = '',
                 contacts_wait_s: float = 0.05, contacts_max_age_s: float = 0.1,
                 contacts_expected: Optional[Callable[[], bool]] = None,
                 report: Optional[Callable[[Notice], None]] = None,
                 record_time: Optional[Callable[[float], None]] = None,
                 clock: Callable[[], float] = time.monotonic,
                 skeleton: Optional[Skeleton] = None) -> None:
        self.cycle = PhysicsCycle(skeleton, params)      # validates the parameters
        self.params = self.cycle.params
        self.tracker: Optional[FloorTracker] = floor if isinstance(floor, FloorTracker) else None
        self.floor: Optional[FloorFrame] = floor if isinstance(floor, FloorFrame) else None
        self.frame_id = frame_id
        self.contacts_wait_s = float(contacts_wait_s)
        self.contacts_max_age_s = float(contacts_max_age_s)
        self.contacts_expected = contacts_expected
        self._report = report
        self._record_time = record_time
        self._clock = clock
        #: restart threshold of :meth:`admit`, ns
        self.restart_after_ns = max(self.params.max_frame_gap, 1.0) * 1e9
        #: motion frames waiting for their contacts: (stamp ns, pose, frame_id, arrival,
        #: camera pose or None, whether the camera may move, whether it stands still)
        self.pending: Deque[Tuple[int, Pose, str, float, Optional[CameraPose], bool, bool]] = \
            collections.deque()
        #: the camera pose of the last frame stepped (step 4 of the module docstring)
        self._last_camera: Optional[CameraPose] = None
        #: the camera poses given to :meth:`step` are known ones in a z-up world (a robot's
        #: camera pose, not the estimate) and the floor tracker takes gravity from them
        #: (:meth:`FloorTracker.update` ``world``; the node's floor_from_camera_pose)
        self.floor_gravity = False
        #: the same poses turn each target upright on average in their gravity
        #: (:class:`UprightPrior`; the node's upright_from_camera_pose)
        self.upright: Optional[UprightPrior] = None
        #: frames whose state the camera's motion carried
        self.camera_steps = 0
        #: contact probabilities (4,) by stamp (ns), oldest first
        self.contacts: 'collections.OrderedDict[int, np.ndarray]' = collections.OrderedDict()
        self.last_stamp = -1
        self.last_result: Optional[FrameResult] = None
        #: the input's flat-foot pitch, estimated when ``flat_foot_pitch_deg`` is -1 (until
        #: the estimate is decided; then None and ``flat_foot_estimate`` holds it)
        self.flat_foot: Optional[FlatFootEstimator] = FlatFootEstimator(
            self.params.contact_probability_threshold) \
            if self.params.flat_foot_pitch_deg < 0 else None
        self.flat_foot_estimate: Optional[float] = None

    @property
    def has_floor(self) -> bool:
        """Whether the input is mapped into a floor frame (fixed or estimated)."""
        return self.tracker is not None or self.floor is not None

    def _notify(self, key: str, text: str, level: str = 'warn', dropped: bool = False,
                period_s: float = 5.0) -> None:
        if self._report is not None:
            self._report(Notice(key, text, level, dropped, period_s))

    # -- input -------------------------------------------------------------------------------
    def add_contacts(self, stamp_ns: int, probabilities: np.ndarray) -> List[PhysicsFrame]:
        """Store the contact probabilities (4,) of ``stamp_ns``; returns the frames that can
        go now."""
        self.contacts[int(stamp_ns)] = np.asarray(probabilities, dtype=float)
        while len(self.contacts) > MAX_CONTACTS:
            self.contacts.popitem(last=False)
        return self.process()

    def admit(self, stamp_ns: int) -> Tuple[bool, List[PhysicsFrame]]:
        """Check a motion stamp before its message is decoded (module docstring, 1).

        Returns (accepted, frames finished by a restart). A rejected stamp is reported as a
        dropped frame."""
        frames: List[PhysicsFrame] = []
        stamp = int(stamp_ns)
        newest = self.pending[-1][0] if self.pending else self.last_stamp
        if newest - stamp > self.restart_after_ns:
            # a new stream (e.g. a bag played again): finish the old one, then the cycle
            # re-initialises at the time jump
            frames = self.process(wait=False)
            for old in [s for s in self.contacts if s > stamp + 1_000_000_000]:
                del self.contacts[old]
            self.last_stamp = -1
            self._notify('restart', f'motion stamps jumped back by {(newest - stamp) * 1e-9:.1f}'
                         ' s (a bag restarted?): starting a new stream', period_s=0.0)
        if stamp <= self.last_stamp or (self.pending and stamp <= self.pending[-1][0]):
            self._notify('order', f'motion stamp {stamp} ns is not after the previous one '
                         '(time went backwards or a duplicate): dropped', 'problem',
                         dropped=True)
            return False, frames
        return True, frames

    def add_motion(self, stamp_ns: int, pose: Pose, frame_id: str = '',
                   camera: Optional[CameraPose] = None,
                   camera_moving: bool = False,
                   camera_static: bool = False) -> List[PhysicsFrame]:
        """Queue a target pose (input frame ``frame_id``; ``camera``: the camera's pose of
        this frame, module docstring 4; ``camera_moving``: the camera may move, for the
        cycle's stance drift; ``camera_static``: the camera is known to stand still, so the
        floor window does not restart) and return the frames that can go now (earlier
        ones included). Runs :meth:`admit` first (a no-op when the caller already admitted
        this stamp)."""
        accepted, frames = self.admit(stamp_ns)
        if not accepted:
            return frames
        self.pending.append((int(stamp_ns), pose, frame_id, self._clock(), camera,
                             bool(camera_moving), bool(camera_static)))
        return frames + self.process()

    def _contacts_for(self, stamp: int, waited: float) -> Tuple[bool, Optional[np.ndarray]]:
        """(ready, probabilities) for a motion frame that has waited ``waited`` s."""
        if stamp in self.contacts:
            return True, self.contacts[stamp]
        # contacts are expected while a publisher exists, and also once some have arrived:
        # a publisher that has just gone (a bag player at its end) may still have messages
        # waiting in this node's queue behind the motion it is catching up on
        expecting = self.contacts_expected is not None and (
            bool(self.contacts) or self.contacts_expected())
        if expecting and waited < self.contacts_wait_s and \
                not any(s > stamp for s in self.contacts):
            return False, None
        older = [s for s in self.contacts if s < stamp]
        if older and stamp - max(older) <= self.contacts_max_age_s * 1e9:
            return True, self.contacts[max(older)]
        return True, None

    def process(self, wait: bool = True) -> List[PhysicsFrame]:
        """Step the waiting frames whose contacts are settled (module docstring, 2); with
        ``wait=False`` every waiting frame, with the contacts that are there."""
        frames: List[PhysicsFrame] = []
        while self.pending:
            stamp, pose, frame_id, t_in, camera, moving, static = self.pending[0]
            waited = self._clock() - t_in if wait else float('inf')
            ready, probs = self._contacts_for(stamp, waited)
            if not ready:
                break
            self.pending.popleft()
            out = self.step(stamp, pose, frame_id, probs, camera=camera, camera_moving=moving,
                            camera_static=static)
            if out is not None:
                frames.append(out)
        return frames

    def flush(self) -> List[PhysicsFrame]:
        """End of the input (offline processing): step every waiting frame now, with the
        contacts that arrived (no more waiting for late ones)."""
        return self.process(wait=False)

    # -- one frame ---------------------------------------------------------------------------
    def _update_floor(self, pose: Pose, probs: Optional[np.ndarray],
                      world: Optional[CameraPose] = None, restart: bool = True) -> bool:
        """Feed the tracker (``world``: a known camera pose, z up; ``restart``: the window
        may restart); re-express the state when the floor changed. False when there is no
        floor yet (the frame cannot be simulated)."""
        tracker = self.tracker
        try:
            new, changed = tracker.update(pose, probs, restart=restart) if world is None \
                else tracker.update(pose, probs, world)
        except ValueError as exc:      # no finite contact point: keep the last floor
            new, changed = self.floor, False
            self._notify('floor', f'floor estimate not updated: {exc}')
        if new is None:
            self._notify('floor', 'no floor estimate yet (no valid foot point): frame skipped',
                         'problem', dropped=True)
            return False
        if changed and self.floor is not None:
            delta = new.compose(self.floor.inverse())
            self.cycle.change_frame(delta.rotation, delta.translation)
        if changed and tracker.adopted:
            self._notify('floor_change', 'floor re-estimated: camera height %.3f m, normal %s '
                         '(%d inliers of %d points)' % (
                             tracker.target.height, np.round(tracker.target.normal, 4).tolist(),
                             tracker.fit.inliers, tracker.fit.points), 'info')
        self.floor = new
        return True

    def _update_flat_foot(self, pose: Pose, probabilities: Optional[np.ndarray]) -> None:
        """Feed the flat-foot estimator with a target in the floor frame. Its first estimate
        is decided once: more than ``FLAT_FOOT_UPDATE_DEG`` from the pitch in use, it replaces
        it in the model and the floor tracker; then the estimator stops (each change moves
        the heel points under a standing foot: re-estimating as samples came in made the
        physics output jitter a third more on rendered clips, docs/physics.md)."""
        self.flat_foot.add(pose, probabilities)
        est = self.flat_foot.estimate()
        if est is None:
            return
        samples, self.flat_foot = self.flat_foot.samples, None
        self.flat_foot_estimate = est
        if abs(est - self.cycle.flat_foot_pitch) <= FLAT_FOOT_UPDATE_DEG:
            return
        try:
            self.cycle.set_flat_foot_pitch(est)
        except Exception as exc:  # noqa: BLE001 - keep the model in use
            self._notify('flat_foot', f'flat-foot pitch {est:.1f} deg not applied: {exc}')
            return
        if self.tracker is not None:
            self.tracker.params.flat_foot_pitch_deg = est
        self._notify('flat_foot', f'flat-foot pitch of the input: {est:.1f} deg below the floor '
                     f'({samples} samples); heel points placed for it', 'info')

    def step(self, stamp_ns: int, pose: Pose, frame_id: str = '',
             probabilities: Optional[np.ndarray] = None,
             time_s: Optional[float] = None,
             camera: Optional[CameraPose] = None,
             camera_moving: bool = False,
             camera_static: bool = False) -> Optional[PhysicsFrame]:
        """Run one frame now (module docstring, 3-4), without the ordering and waiting of
        :meth:`add_motion`.

        Args:
            stamp_ns: the frame's stamp, ns.
            pose: the target in the input frame ``frame_id``.
            probabilities: (4,) contact probabilities (``CONTACT_POINT_NAMES`` order) or None.
            time_s: the cycle's time for this frame, s (default ``stamp_ns * 1e-9``; offline
                callers with exact float times pass them here).
            camera: the camera's pose of this frame (R (3, 3), C (3,) m: its frame into the
                first image's camera frame, ``p_first = R p_camera + C``), or None (module
                docstring, 4).
            camera_moving: the camera may move in this frame (only then does the cycle
                follow the stance drift).
            camera_static: the camera-motion estimate says the camera stands still: the
                floor cannot have moved in the camera frame, so the floor window does not
                restart (:class:`~.floor.FloorTracker`).

        Returns:
            The frame, or None when it was dropped (reported as a Notice).
        """
        if probabilities is None and self.contacts_expected is not None:
            self._notify('nocontacts', 'no contact probabilities for this frame: contacts from '
                         'the kinematics only', period_s=10.0)
        input_frame = frame_id or DEFAULT_INPUT_FRAME
        if self.upright is not None and camera is not None:
            pose = self.upright.apply(pose, camera[0])
        if self.tracker is not None and not self._update_floor(
                pose, probabilities, camera if self.floor_gravity else None,
                restart=not camera_static):
            return None
        if self.floor is not None:
            if camera is not None and self._last_camera is not None and \
                    self.last_stamp >= 0 and int(stamp_ns) > self.last_stamp:
                R, t = camera_step_on_floor(self._last_camera, camera, self.floor)
                self.cycle.change_frame(R, t, carry=True)
                self.camera_steps += 1
            self._last_camera = camera
            pose = self.floor.transform_pose(pose)
            out_frame = self.frame_id or 'floor'
        else:
            out_frame = self.frame_id or frame_id or 'world'
        # the flat feet are measured against a floor that has settled: a fitted one (not the
        # provisional floor of the first frames), or the input's own (no floor source)
        if self.flat_foot is not None and (self.tracker is None or self.tracker.ready):
            self._update_flat_foot(pose, probabilities)
        t = stamp_ns * 1e-9 if time_s is None else float(time_s)
        t0 = time.perf_counter()
        try:
            # a camera whose motion is carried leaves no apparent motion to trail
            res = self.cycle.step(pose, t, probabilities, camera_moving=camera_moving,
                                  moving_gains=camera_moving and camera is None)
        except (InvalidInput, SkeletonError) as exc:
            self._notify('skeleton', f'skipping a frame: {exc}', 'problem', dropped=True)
            return None
        except Exception as exc:  # noqa: BLE001 - never die on one frame
            self._notify('step', f'physics step failed ({type(exc).__name__}: {exc}); frame '
                         'skipped', 'problem', dropped=True)
            return None
        finally:
            if self._record_time is not None:
                self._record_time(time.perf_counter() - t0)
        for m in res.messages:
            self._notify(m.split(':')[0], m)
        if res.status not in ('ok', 'first_frame'):
            self._notify('status', f'{res.status}: {"; ".join(res.messages)}'
                         if res.messages else res.status, 'status')
        self.last_stamp = int(stamp_ns)
        self.last_result = res
        return PhysicsFrame(int(stamp_ns), res, out_frame, input_frame, self.floor)


__all__ = ['OnlinePhysics', 'PhysicsFrame', 'Notice', 'FloorSource', 'DEFAULT_INPUT_FRAME']
