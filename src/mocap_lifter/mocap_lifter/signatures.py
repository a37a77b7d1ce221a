"""How well the lifter's held skeleton tells people apart (no ROS imports).

The keypoint node's tracker gives a person who left the picture and came back under a new id
their old id when the lifter's held bone lengths of the two agree
(:meth:`mocap_core.tracking.PersonTracker.set_signature`, ``signature_rename_tolerance``).
That is only worth doing if two estimates of one person agree more closely than estimates of
two different people. This module measures both on rendered clips
(:mod:`mocap_core.render`: one random body per clip, the real detector's keypoints):

* **one person twice**: a clip long enough is cut in two halves, each lifted as its own
  stream, exactly as the node lifts a person who comes back (a new stream, the skeleton held
  after ``skeleton_frames`` frames or at the end of what there is);
* **two people**: the whole-clip estimates of two different clips (different bodies, cameras
  and motions);
* the estimate against the rendered body's true bone lengths.

The distance is :func:`mocap_core.tracking.signature_distance` (median over the bone groups of
the relative difference), the tracker's own.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np

from mocap_core.camera import CameraIntrinsics
from mocap_core.tracking import signature_distance


@dataclass
class ClipSignatures:
    """The lifter's held bone-group lengths (m) of one rendered clip."""

    name: str
    truth: np.ndarray                         # (G,) the rendered body's
    whole: Optional[np.ndarray]               # (G,) lifted over the whole clip
    halves: List[np.ndarray] = field(default_factory=list)   # two (G,) when long enough
    held: bool = False                        # the whole-clip skeleton was held (not partial)
    frames: int = 0


def lift_held_lengths(make_lifter: Callable[[], object], keypoints: np.ndarray,
                      intrinsics: CameraIntrinsics, fps: float) -> tuple:
    """Lift (F, 23, 3) keypoints (pixels + confidence) of one person as the lifter node does
    (one :class:`~mocap_lifter.online.PeopleStreams` stream, id 1, calibrated intrinsics).
    Returns ``((G,) bone-group lengths of the last frame, m, whether the skeleton was
    held)``, or ``(None, False)`` when nothing was lifted."""
    from .intrinsics import StreamIntrinsics
    from .online import PeopleStreams

    si = StreamIntrinsics()
    si.set_camera_info(intrinsics)
    people = PeopleStreams(make_lifter, si)
    last = None
    dt = int(round(1e9 / fps))
    for k, kp in enumerate(np.asarray(keypoints, dtype=np.float64)):
        step = people.push(k * dt, kp[None], np.array([1]))
        last = _last_frame(step, last)
    last = _last_frame(people.flush(), last)
    if last is None:
        return None, False
    return last.pose.skeleton.group_lengths(), bool(last.skeleton_fixed)


def _last_frame(step, last):
    for st in step.steps.values():
        if st.frames:
            last = st.frames[-1]
    return last


def clip_signatures(make_lifter: Callable[[], object], clip_dir: Path,
                    half_frames: int) -> Optional[ClipSignatures]:
    """:class:`ClipSignatures` of one rendered clip (``data.npz`` of ``mocap data render``);
    halves when the clip has at least ``2 * half_frames`` frames. None when BlazePose found
    the person in fewer than half the frames."""
    data = np.load(clip_dir / 'data.npz')
    kp = data['keypoints']
    if np.mean(np.any(kp[..., 2] > 0, axis=-1)) < 0.5:
        return None
    K, (w, h) = data['K'], data['image_size']
    intr = CameraIntrinsics(int(w), int(h), float(K[0, 0]), float(K[1, 1]), float(K[0, 2]),
                            float(K[1, 2]))
    fps = float(data['fps'])
    whole, held = lift_held_lengths(make_lifter, kp, intr, fps)
    out = ClipSignatures(clip_dir.name, np.asarray(data['bone_lengths'], float), whole,
                         held=held, frames=len(kp))
    if len(kp) >= 2 * half_frames:
        mid = len(kp) // 2
        for part in (kp[:mid], kp[mid:]):
            lengths, _ = lift_held_lengths(make_lifter, part, intr, fps)
            if lengths is not None:
                out.halves.append(lengths)
        if len(out.halves) != 2:
            out.halves = []
    return out


def summarise(clips: Sequence[ClipSignatures],
              tolerances: Sequence[float] = (0.01, 0.02, 0.03, 0.04, 0.05, 0.08)) -> Dict:
    """Distances of one person's two halves, of two different people's estimates and of the
    estimates from the truth, and for each tolerance the share of each kind of pair within
    it (a rename accepted)."""
    same = np.array([signature_distance(c.halves[1], c.halves[0]) for c in clips if c.halves])
    est = [c for c in clips if c.whole is not None]
    diff = np.array([signature_distance(a.whole, b.whole)
                     for i, a in enumerate(est) for b in est[i + 1:]])
    truth_diff = np.array([signature_distance(a.truth, b.truth)
                           for i, a in enumerate(est) for b in est[i + 1:]])
    err = np.array([signature_distance(c.whole, c.truth) for c in est])
    # scale taken out (each set of lengths over its sum): the body's proportions only
    unit = lambda x: np.asarray(x) / np.sum(x)                     # noqa: E731
    same_prop = np.array([signature_distance(unit(c.halves[1]), unit(c.halves[0]))
                          for c in clips if c.halves])
    diff_prop = np.array([signature_distance(unit(a.whole), unit(b.whole))
                          for i, a in enumerate(est) for b in est[i + 1:]])
    truth_prop = np.array([signature_distance(unit(a.truth), unit(b.truth))
                           for i, a in enumerate(est) for b in est[i + 1:]])
    # how much the estimates follow the true size: correlation of the summed lengths
    size = (np.corrcoef([c.whole.sum() for c in est], [c.truth.sum() for c in est])[0, 1]
            if len(est) > 2 else float('nan'))

    def q(a: np.ndarray) -> Dict[str, float]:
        if not len(a):
            return {'n': 0}
        return {'n': int(len(a)), 'median': float(np.median(a)),
                'p10': float(np.percentile(a, 10)), 'p90': float(np.percentile(a, 90))}

    return {
        'clips': len(clips), 'lifted': len(est), 'held': sum(c.held for c in est),
        'same_person': q(same), 'different_people': q(diff),
        'different_people_truth': q(truth_diff), 'estimate_vs_truth': q(err),
        'size_correlation': float(size),
        'proportions': {'same_person': q(same_prop), 'different_people': q(diff_prop),
                        'different_people_truth': q(truth_prop)},
        'spread': {'estimate': float(np.median(np.std([c.whole for c in est], axis=0) /
                                               np.mean([c.whole for c in est], axis=0))),
                   'truth': float(np.median(np.std([c.truth for c in est], axis=0) /
                                            np.mean([c.truth for c in est], axis=0)))},
        'tolerances': [{'tolerance': t,
                        'same_accepted': float(np.mean(same <= t)) if len(same) else
                        float('nan'),
                        'different_accepted': float(np.mean(diff <= t)) if len(diff) else
                        float('nan')} for t in tolerances],
    }
