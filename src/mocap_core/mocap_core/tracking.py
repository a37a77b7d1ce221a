"""Several people in 2D keypoints, each with an identity that stays the same (no ROS imports).

:class:`PersonTracker` takes, per frame, the persons a detector found, in any order
((P, 23, 3) keypoints ``u, v`` in pixels and a confidence in [0, 1], the layout of
:data:`mocap_core.skeleton.KEYPOINT_NAMES`), and returns the tracked persons with their ids.

* **Motion model.** A constant-velocity Kalman filter per track on the box of the seen
  keypoints (centre ``cx, cy`` and height ``h`` in pixels, and their rates in px/s); the
  keypoints of the last match, expressed relative to the box (centre and height), ride on the
  predicted box, so that a track can be compared with a candidate keypoint by keypoint.
* **Association.** Similarity = object keypoint similarity (OKS, COCO's definition with one
  tolerance per keypoint, scale = the predicted box height) between the candidate and the
  track's predicted keypoints, plus a smaller share of the boxes' overlap (IoU); one-to-one by
  the Hungarian method (``scipy.optimize.linear_sum_assignment``), gated by
  ``match_threshold``. Candidates that are the same person twice (OKS above
  ``duplicate_oks``) are merged first, the more confident kept.
* **Birth and death with hysteresis.** A new candidate starts a *tentative* track; it gets an
  id only after ``birth_frames`` consecutive matches (a one-frame blip never gets one). A
  confirmed track that is not matched *coasts* on its prediction (not published) for up to
  ``max_lost_s``; matched again in that time it keeps its id (re-identification after a short
  occlusion), and the gate widens with the time lost. After that it is dropped.
* **Appearance.** With the image, :func:`appearance_features` gives each candidate the mean
  colours (CIE Lab) of its torso, upper arms, thighs and shins. A track keeps a running mean
  of its own and of how far its frames fall from it (its *spread*), updated only while it
  overlaps nobody, detected or followed in the last ``max_lost_s`` (a person half hidden by
  another would take the other's colours); a
  candidate's similarity to a track is multiplied by ``exp(-d^2 / (2 sigma^2))`` (d: the
  mean colour distance over the regions both show; sigma: twice the track's spread, at least
  ``appearance_sigma_min``; floored at ``appearance_floor``) where the match is ambiguous (the
  candidate could go to more than one track, or the track take more than one candidate), so
  two people crossing, whose boxes and keypoints coincide for a moment, are told apart by
  their clothes, while a lone person whose colours change at once keeps their id. The scale is
  the track's own because footage differs: on rendered people (flat colours) a person's
  frames fall 2.3 Lab units from their mean (median), on the real tai chi clip 8.4, with
  different rendered people 18-53 apart. A lost track with an appearance is kept for
  ``appearance_max_lost_s`` (longer than ``max_lost_s``), and a new person within
  ``appearance_reid`` sigmas of its colours near where it was lost takes its id back.
* **People in each other's way** (measured on rendered crossings, docs/multi_person.md).
  A candidate whose box overlaps the boxes of more than one person's track counts as
  ambiguous, even when it is the only candidate: the person behind, found alone for a frame,
  must not go to the track of the one in front. A candidate that overlaps two tracks by
  ``MERGED_IOU`` or more, where fewer candidates than those tracks are, is, with the image,
  taken by none. The detector's row there mixes both people, so both tracks coast and their
  clothes tell them apart once they part.
  Colours are sampled only where no nearer person stands (:func:`in_front_of`: the feet lower
  in the image). A new track among others whose colours are still unknown waits for its id
  (at most ``max_lost_s``). Re-identification ranks the lost tracks by distance plus colour
  distance.
* **Signatures.** :meth:`PersonTracker.set_signature` attaches a vector to an id (the 3D
  stages' bone lengths, m); a coasting track only takes a candidate whose signature, when the
  caller gives one, is within ``signature_tolerance`` (relative) of its own.
  The 3D stages know a body's bone lengths only after a while (the lifter holds a skeleton
  after some 3 s), too late to name a new detection, so they also correct a name after the
  fact: a dropped track with a signature is remembered for ``signature_memory_s``, and when
  a track that was given a *new* id later receives its first signatures, it takes back the
  id of the one remembered person whose signature agrees within ``signature_rename_tolerance``
  and, when the tracker sees the image, whose clothes are known for both and within
  ``appearance_reid`` of its sigma, who was last seen before the new track began (a person who
  left the picture and came back). Off by default (``signature_memory_s`` 0): measured on
  rendered bodies, the shipped lifter's held skeletons of two different people are about as
  close as two estimates of one person (``mocap eval signatures``).
  :meth:`PersonTracker.set_signature` returns the id taken back; from then on the person is
  published under it (the stages start the returning body afresh under its old id).
* **Order.** Output rows are ordered by how long each id has been tracked, the longest first:
  row 0 is the *main person* that one-person consumers read.

Ids are positive integers, never reused within one tracker; 0 means "nobody" (a padding row).
Times are seconds (the frame stamps), pixels are image pixels, origin top-left.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from .skeleton import KEYPOINT_INDEX, KEYPOINT_NAMES, NUM_KEYPOINTS

#: Boxes overlap (two people in each other's way) from this IoU on.
OVERLAP_IOU = 0.05
#: A detection whose box overlaps two people's tracks this much could be either of them.
MERGED_IOU = 0.3

#: An occluder's box is widened by this share of its height on every side
#: (:func:`appearance_features`).
OCCLUDER_MARGIN = 0.05

#: Per-keypoint OKS tolerance (COCO's sigmas for the 17 body points; the foot points as the
#: ankles'), in the 23-point layout order.
KEYPOINT_SIGMAS = np.array(
    [0.026, 0.025, 0.025, 0.035, 0.035, 0.079, 0.079, 0.072, 0.072, 0.062, 0.062,
     0.107, 0.107, 0.087, 0.087, 0.089, 0.089, 0.089, 0.089, 0.089, 0.089, 0.089, 0.089])
assert len(KEYPOINT_SIGMAS) == len(KEYPOINT_NAMES) == NUM_KEYPOINTS


@dataclass
class TrackerParams:
    """Tuning of :class:`PersonTracker` (see the module docstring)."""

    #: The most persons tracked at once; further new persons are ignored (the most confident
    #: candidates start tracks first).
    max_persons: int = 4
    #: A keypoint counts as seen at this confidence or above.
    min_confidence: float = 0.3
    #: A candidate needs this many seen keypoints, else it is ignored.
    min_keypoints: int = 6
    #: A candidate whose box of seen keypoints is lower than this (px) is ignored.
    min_height_px: float = 0.0
    #: Consecutive matched frames before a tentative track gets an id.
    birth_frames: int = 3
    #: A confirmed track unmatched for longer than this (s) is dropped.
    max_lost_s: float = 1.0
    #: Least similarity (OKS + 0.3 IoU, in [0, 1.3]) for a candidate to continue a track.
    match_threshold: float = 0.25
    #: Candidates more alike than this (OKS) are one person seen twice.
    duplicate_oks: float = 0.7
    #: Scale factor of the OKS tolerances (1 = COCO's); larger is more forgiving.
    oks_scale: float = 2.0
    #: A new track within this many box heights of a lost track's predicted box takes
    #: that track's id instead of a new one.
    reid_distance: float = 1.0
    #: Relative signature difference (median over entries) beyond which a coasting track
    #: does not take a candidate.
    signature_tolerance: float = 0.08
    #: A dropped track with a signature is remembered this long (s) for renaming: a new id
    #: whose signature, when it arrives, agrees within ``signature_rename_tolerance``
    #: (relative, median over entries) with exactly one remembered person takes that
    #: person's id back (module docstring). 0 (the default) disables renaming: the shipped
    #: lifter's held skeletons barely tell people apart (docs/multi_person.md).
    signature_memory_s: float = 0.0
    signature_rename_tolerance: float = 0.03
    #: Kalman filter: acceleration noise (px/s^2, per px of box height) and measurement
    #: noise (px per px of box height).
    accel_noise: float = 3.0
    measurement_noise: float = 0.05
    #: A coasting track's velocity decays with this time constant (s): a person hidden for a
    #: while is looked for near where they were last, not far along a straight line (their
    #: last velocity is often that of a bad, partial detection).
    coast_velocity_s: float = 0.2
    #: Largest relative change of a track's box height from one frame to the next.
    max_height_change: float = 0.15
    #: Appearance (module docstring). Each track's colour scale sigma is
    #: ``appearance_spread_factor`` x the running mean distance of its own frames from its
    #: mean colours (how much this person's colours vary in this footage), at least
    #: ``appearance_sigma_min``; ``appearance_sigma`` until ``appearance_min_frames`` frames
    #: have measured it. The factor is at least
    #: ``appearance_floor``; a new frame weighs ``appearance_rate`` in a track's running mean.
    appearance_sigma: float = 15.0
    appearance_sigma_min: float = 5.0
    appearance_spread_factor: float = 2.0
    appearance_min_frames: int = 5
    appearance_floor: float = 0.05
    appearance_rate: float = 0.1
    #: A lost track whose appearance is known is kept this long (s, at least
    #: ``max_lost_s``); a new person within ``appearance_reid`` of its sigma in colour, and
    #: within ``reid_distance`` box heights plus ``reid_speed`` box heights per second lost of
    #: where it was last seen, takes its id (a person hidden for a while by another).
    appearance_max_lost_s: float = 3.0
    appearance_reid: float = 1.5
    appearance_reid_recent: float = 4.0
    reid_speed: float = 1.0

    def __post_init__(self) -> None:
        if self.max_persons < 1:
            raise ValueError(f'max_persons must be >= 1, got {self.max_persons}')
        if self.birth_frames < 1:
            raise ValueError(f'birth_frames must be >= 1, got {self.birth_frames}')
        if self.max_lost_s < 0:
            raise ValueError(f'max_lost_s must be >= 0, got {self.max_lost_s}')


def keypoint_box(kp: np.ndarray, min_confidence: float) -> Optional[np.ndarray]:
    """(23, 3) keypoints -> box ``(cx, cy, h, w)`` of the seen keypoints (px), or None when
    fewer than two are seen. ``h`` is at least a third of ``w`` (a person lying down)."""
    seen = kp[:, 2] >= min_confidence
    if np.count_nonzero(seen) < 2:
        return None
    p = kp[seen, :2]
    lo, hi = p.min(axis=0), p.max(axis=0)
    w, h = hi - lo
    h = max(h, w / 3.0, 1.0)
    c = (lo + hi) / 2.0
    return np.array([c[0], c[1], h, max(w, 1.0)])


def box_iou(a: np.ndarray, b: np.ndarray) -> float:
    """IoU of two ``(cx, cy, h, w)`` boxes."""
    ax0, ay0, ax1, ay1 = a[0] - a[3] / 2, a[1] - a[2] / 2, a[0] + a[3] / 2, a[1] + a[2] / 2
    bx0, by0, bx1, by1 = b[0] - b[3] / 2, b[1] - b[2] / 2, b[0] + b[3] / 2, b[1] + b[2] / 2
    iw = max(0.0, min(ax1, bx1) - max(ax0, bx0))
    ih = max(0.0, min(ay1, by1) - max(ay0, by0))
    inter = iw * ih
    union = a[2] * a[3] + b[2] * b[3] - inter
    return float(inter / union) if union > 0 else 0.0


def oks(a: np.ndarray, b: np.ndarray, height: float, min_confidence: float,
        scale: float = 1.0) -> float:
    """Object keypoint similarity of (23, 3) keypoints ``a`` and ``b`` over the keypoints seen
    in both, for a person ``height`` px tall (area ~ 0.5 h^2, as COCO's box area); 0 when
    fewer than 3 keypoints are shared."""
    both = (a[:, 2] >= min_confidence) & (b[:, 2] >= min_confidence)
    if np.count_nonzero(both) < 3:
        return 0.0
    d2 = np.sum((a[both, :2] - b[both, :2]) ** 2, axis=-1)
    area = 0.5 * max(height, 1.0) ** 2
    k = 2.0 * (KEYPOINT_SIGMAS[both] * scale) ** 2
    return float(np.mean(np.exp(-d2 / (2.0 * area * k))))


def signature_distance(sig: np.ndarray, ref: np.ndarray) -> float:
    """How far signature ``sig`` is from ``ref`` (e.g. two estimates of a person's bone-group
    lengths): the median over entries of ``|sig - ref| / |ref|`` (0.03 = 3 %); inf when the
    shapes differ."""
    a, b = np.asarray(sig, dtype=np.float64), np.asarray(ref, dtype=np.float64)
    if a.shape != b.shape or not a.size:
        return float('inf')
    return float(np.median(np.abs(a - b) / np.maximum(np.abs(b), 1e-6)))


class _Kalman:
    """Constant-velocity filter on ``(cx, cy, h)`` (px) and their rates (px/s)."""

    def __init__(self, z: np.ndarray, params: TrackerParams) -> None:
        self.p = params
        self.x = np.concatenate([z, np.zeros(3)])
        h = max(z[2], 1.0)
        self.P = np.diag(np.concatenate([np.full(3, (params.measurement_noise * h) ** 2),
                                         np.full(3, (2.0 * h) ** 2)]))

    def predicted(self, dt: float) -> Tuple[np.ndarray, np.ndarray]:
        F = np.eye(6)
        F[:3, 3:] = np.eye(3) * dt
        h = max(self.x[2], 1.0)
        q = (self.p.accel_noise * h) ** 2
        G = np.concatenate([np.eye(3) * dt * dt / 2.0, np.eye(3) * dt])
        Q = G @ G.T * q
        return F @ self.x, F @ self.P @ F.T + Q

    def predict(self, dt: float) -> None:
        self.x, self.P = self.predicted(dt)
        self.x[2] = max(self.x[2], 1.0)

    def correct(self, z: np.ndarray) -> None:
        H = np.hstack([np.eye(3), np.zeros((3, 3))])
        r = (self.p.measurement_noise * max(z[2], 1.0)) ** 2
        S = H @ self.P @ H.T + np.eye(3) * r
        K = self.P @ H.T @ np.linalg.inv(S)
        self.x = self.x + K @ (z - H @ self.x)
        self.P = (np.eye(6) - K @ H) @ self.P


@dataclass
class _Track:
    id: int                       # 0 while tentative
    kalman: _Kalman
    shape: np.ndarray             # (23, 3): (u - cx) / h, (v - cy) / h, confidence
    width_ratio: float
    keypoints: np.ndarray         # (23, 3) of the last match
    first_s: float
    last_s: float
    hits: int = 1
    row: int = -1
    missed: int = 0               # frames since the last match
    signature: Optional[np.ndarray] = None
    appearance: Optional[np.ndarray] = None   # (R, 3) Lab per region, NaN where unknown
    spread: float = 0.0                       # running mean distance of its frames (Lab)
    looks: int = 0                            # frames that measured ``spread``
    crowded: bool = False                     # its last match overlapped another person
    renamable: bool = False                   # got a new id; may still take an old one back

    def box_at(self, dt: float) -> np.ndarray:
        x, _ = self.kalman.predicted(dt)
        h = max(x[2], 1.0)
        return np.array([x[0], x[1], h, h * self.width_ratio])

    def keypoints_at(self, dt: float) -> np.ndarray:
        b = self.box_at(dt)
        out = self.shape.copy()
        out[:, 0] = b[0] + self.shape[:, 0] * b[2]
        out[:, 1] = b[1] + self.shape[:, 1] * b[2]
        return out


@dataclass
class TrackedPerson:
    """One tracked person of a frame."""

    id: int
    keypoints: np.ndarray         # (23, 3) u px, v px, confidence
    box: np.ndarray               # (4,) cx, cy, h, w of the seen keypoints (px)
    tracked_s: float              # time since the id was first seen (s)
    row: int = -1                 # index of the candidate it was matched to in update()


@dataclass
class TrackerStats:
    """Counters for diagnostics."""

    births: int = 0               # ids given
    deaths: int = 0               # ids dropped after max_lost_s
    reidentified: int = 0         # ids matched again after being lost
    blips: int = 0                # tentative tracks that never got an id
    duplicates: int = 0           # candidates merged as the same person twice
    ignored: int = 0              # candidates too small, too few points, or beyond max_persons
    lost_ids: List[int] = field(default_factory=list)   # ids dropped in the last update
    renamed: int = 0              # new ids that took an old one back by signature


class PersonTracker:
    """See the module docstring."""

    def __init__(self, params: Optional[TrackerParams] = None) -> None:
        self.params = params or TrackerParams()
        self._tracks: List[_Track] = []
        #: dropped tracks with a signature, for renaming (``signature_memory_s``)
        self._ended: List[_Track] = []
        self._next_id = 1
        self._last_s: Optional[float] = None
        self._with_looks = False
        self.stats = TrackerStats()

    # ------------------------------------------------------------------ public
    def reset(self) -> None:
        """Forget every track (a new, unrelated stream); ids keep counting up."""
        self._tracks = []
        self._ended = []
        self._last_s = None

    @property
    def ids(self) -> List[int]:
        """Ids of the confirmed tracks, matched or coasting."""
        return [t.id for t in self._tracks if t.id]

    def set_signature(self, track_id: int, signature: Sequence[float]) -> Optional[int]:
        """Attach a signature to ``track_id`` (e.g. the lifter's bone-group lengths of that
        body, m). When that id was new and the signature names a person dropped earlier
        (module docstring, "Signatures"), the track takes that person's id back: returns
        that id (``track_id`` is retired), else None."""
        sig = np.asarray(signature, dtype=np.float64).ravel()
        if not np.all(np.isfinite(sig)) or not np.all(sig > 0):
            return None
        for t in self._tracks:
            if t.id == track_id and track_id > 0:
                t.signature = sig
                old = self._rename_target(t) if t.renamable else None
                if old is None:
                    return None
                self._ended.remove(old)
                t.id, t.first_s, t.renamable = old.id, old.first_s, False
                if t.appearance is None and old.appearance is not None:
                    t.appearance = old.appearance.copy()
                    t.spread, t.looks = old.spread, old.looks
                self.stats.renamed += 1
                return t.id
        return None

    def _rename_target(self, t: _Track) -> Optional[_Track]:
        """The one remembered dropped person whose id the new track ``t`` takes back by its
        signature (module docstring), or None when none or more than one qualifies."""
        p = self.params
        now = self._last_s if self._last_s is not None else t.last_s
        found = []
        for o in self._ended:
            if o.signature is None or o.last_s >= t.first_s or \
                    now - o.last_s > p.signature_memory_s:
                continue
            if signature_distance(t.signature, o.signature) > p.signature_rename_tolerance:
                continue
            look = appearance_distance(o.appearance, t.appearance)
            if look is None and self._with_looks:
                continue        # with the image, the clothes must have been seen and agree
            if look is not None and look > p.appearance_reid * self._sigma(o):
                continue
            found.append(o)
        return found[0] if len(found) == 1 else None

    def predicted_boxes(self, stamp_s: float) -> Dict[int, np.ndarray]:
        """``{key: (cx, cy, h, w)}`` box of every live track predicted to ``stamp_s``; keys are
        ids for confirmed tracks and negative numbers for tentative ones (for a detector that
        looks where each person is expected)."""
        dt = 0.0 if self._last_s is None else max(0.0, stamp_s - self._last_s)
        return {(t.id if t.id else -(i + 1)): t.box_at(dt) for i, t in enumerate(self._tracks)}

    def update(self, candidates: np.ndarray, stamp_s: float,
               signatures: Optional[Sequence[Optional[np.ndarray]]] = None,
               image: Optional[np.ndarray] = None) -> List[TrackedPerson]:
        """Take this frame's persons (P, 23, 3), in any order, at time ``stamp_s`` (s);
        return the persons with ids, the longest tracked first. ``signatures``: optional,
        one per candidate (None where unknown). ``image``: the (H, W, 3) BGR uint8 frame
        the candidates were found in, for their appearance (module docstring)."""
        p = self.params
        self.stats.lost_ids = []
        cands = np.asarray(candidates, dtype=np.float64).reshape(-1, NUM_KEYPOINTS, 3)
        cands = np.where(np.isfinite(cands), cands, 0.0)
        sigs = list(signatures) if signatures is not None else [None] * len(cands)
        dt = 0.0 if self._last_s is None else stamp_s - self._last_s
        if dt < 0:
            self.reset()
            dt = 0.0
        self._last_s = stamp_s
        self._with_looks = image is not None
        keep, boxes = self._valid(cands)
        cands, sigs = cands[keep], [sigs[i] for i in keep]
        kept = self._merge_duplicates(cands, boxes)
        rows = [keep[k] for k in kept]
        cands, boxes, sigs = cands[kept], [boxes[k] for k in kept], [sigs[k] for k in kept]
        looks = ([appearance_features(image, c, b, p.min_confidence,
                                      in_front_of(b, [boxes[k] for k in range(len(boxes))
                                                      if k != j]))
                  for j, (c, b) in enumerate(zip(cands, boxes))]
                 if image is not None else [None] * len(cands))
        pred_kp = [t.keypoints_at(dt) for t in self._tracks]
        pred_box = [t.box_at(dt) for t in self._tracks]
        # which confirmed tracks (matched or coasting) each candidate's box overlaps: a
        # candidate among several people may show another's colours, and its match is
        # decided by clothes, not by position alone (a person hidden by another in front)
        # (a track lost for longer than max_lost_s is kept for its clothes only: where it
        # is predicted to be means little)
        n = len(cands)
        iou_ct = np.array([[box_iou(b, pb) for pb in pred_box] for b in boxes]).reshape(
            n, len(self._tracks))                            # candidate x track
        iou_cc = np.array([[box_iou(a, b) for b in boxes] for a in boxes]).reshape(n, n)
        recent = [i for i, t in enumerate(self._tracks)
                  if t.id > 0 and stamp_s - t.last_s <= p.max_lost_s]
        near = [{i for i in recent if iou_ct[j, i] >= OVERLAP_IOU} for j in range(n)]
        # candidates at each one's place, itself included
        here = 1 + ((iou_cc >= OVERLAP_IOU) & ~np.eye(n, dtype=bool)).sum(axis=1)
        apart = [int(here[j]) == 1 for j in range(n)]
        # fewer detections than people where two or more people's tracks overlap (the
        # detector found one of two): a detection there could be either
        crowd = [sum(1 for i in near[j] if iou_ct[j, i] >= MERGED_IOU) for j in range(n)]
        merged = [image is not None and crowd[j] > 1 and here[j] < crowd[j] for j in range(n)]
        sim = np.zeros((len(self._tracks), len(cands)))
        for i, t in enumerate(self._tracks):
            lost = stamp_s - t.last_s
            widen = 1.0 + 2.0 * min(lost, p.max_lost_s)   # a longer-lost track gets a wider gate
            for j in range(len(cands)):
                if not self._signature_ok(t, sigs[j]):
                    continue
                sim[i, j] = oks(cands[j], pred_kp[i], pred_box[i][2], p.min_confidence,
                                p.oks_scale * widen) + 0.3 * iou_ct[j, i]
        # Clothes decide only where position and pose do not: a candidate that more than one
        # track could take, or a track that could take more than one candidate (two people
        # crossing). A lone match keeps its similarity, so a person whose colours change at
        # once (a light switched on, the camera's exposure) keeps their id.
        # A track lost for longer than max_lost_s is kept only for its clothes: they decide.
        # people at one place and fewer detections there: a detection could be any of them
        # (its keypoints and colours mix them); it is not taken and the tracks coast
        # through, to be told apart by their clothes once they part (without the image, the
        # motion model is the only cue and it takes the detection). As many detections as
        # people there (two people side by side) are matched as usual; a hidden person's
        # track leaves the recent ones after max_lost_s, so the one in front is not held
        # back for longer.
        sim[:, merged] = 0.0
        plausible = sim >= p.match_threshold
        for i, j in zip(*np.nonzero(plausible)):
            t = self._tracks[i]
            if plausible[:, j].sum() > 1 or plausible[i].sum() > 1 or len(near[j]) > 1 or \
                    stamp_s - t.last_s > p.max_lost_s:
                sim[i, j] *= self._look_factor(t, looks[j])
        # Matching cascade: the tracks seen in the last frame choose first, then the coasting
        # ones, the tentative ones last, so that a long-lost track (whose gate is wide) cannot
        # take a person that a track seen a moment ago explains.
        levels = ([i for i, t in enumerate(self._tracks) if t.id and not t.missed],
                  [i for i, t in enumerate(self._tracks) if t.id and t.missed],
                  [i for i, t in enumerate(self._tracks) if not t.id])
        matches: List[Tuple[int, int]] = []
        free = list(range(len(cands)))
        if sim.size:
            from scipy.optimize import linear_sum_assignment
            for level in levels:
                if not level or not free:
                    continue
                sub = sim[np.ix_(level, free)]
                ti, ci = linear_sum_assignment(-sub)
                got = [(level[r], free[c]) for r, c in zip(ti, ci)
                       if sub[r, c] >= p.match_threshold]
                matches += got
                taken = {c for _, c in got}
                free = [c for c in free if c not in taken]
        matched_t = {r for r, _ in matches}
        matched_c = {c for _, c in matches}
        track_of = {j: i for i, j in matches}
        # a candidate overlapping no other candidate and no other person's track shows its
        # own colours only: only then are they learned
        alone = [apart[j] and not (near[j] - {track_of.get(j, -1)})
                 for j in range(len(cands))]

        ready: List[Tuple[_Track, int]] = []
        for i, j in matches:
            t = self._tracks[i]
            if t.id and t.missed:
                self.stats.reidentified += 1
            t.missed = 0
            t.kalman.predict(dt)
            t.kalman.correct(self._measure(t, cands[j], boxes[j]))
            self._set_shape(t, cands[j], boxes[j])
            t.last_s = stamp_s
            t.row = rows[j]
            t.hits += 1
            t.crowded = bool(near[j] - {i})
            if sigs[j] is not None and t.signature is None:
                t.signature = np.asarray(sigs[j], dtype=np.float64)
            if alone[j]:
                self._learn_look(t, looks[j])
            if not t.id and t.hits >= p.birth_frames:
                ready.append((t, j))
        # the most confident tentative tracks are confirmed first, while there is room (a
        # coasting track keeps its place)
        ready.sort(key=lambda tj: -float(np.sum(cands[tj[1]][:, 2])))
        for t, _ in ready:
            self._confirm(t, stamp_s, matched_t)
        survivors = []
        for i, t in enumerate(self._tracks):
            if t.id < 0:                      # its id was taken over by a re-identified track
                continue
            if i in matched_t:
                survivors.append(t)
                continue
            t.kalman.predict(dt)
            t.kalman.x[3:] *= np.exp(-dt / max(p.coast_velocity_s, 1e-6))
            t.missed += 1
            if not t.id:                      # a tentative track must match every frame
                self.stats.blips += 1
                continue
            if stamp_s - t.last_s > self._keep_s(t):
                self.stats.deaths += 1
                self.stats.lost_ids.append(t.id)
                if t.signature is not None and p.signature_memory_s > 0:
                    self._ended.append(t)
                continue
            survivors.append(t)
        self._tracks = survivors
        self._ended = [t for t in self._ended
                       if stamp_s - t.last_s <= p.signature_memory_s]

        new = [j for j in range(len(cands)) if j not in matched_c and not merged[j]]
        new.sort(key=lambda j: -float(np.sum(cands[j][:, 2])))
        for j in new:
            if len(self._tracks) >= 2 * p.max_persons:
                self.stats.ignored += 1
                continue
            t = _Track(0, _Kalman(boxes[j][:3], p), np.zeros((NUM_KEYPOINTS, 3)), 1.0,
                       cands[j].copy(), stamp_s, stamp_s,
                       signature=None if sigs[j] is None else np.asarray(sigs[j], float))
            self._set_shape(t, cands[j], boxes[j])
            t.row = rows[j]
            t.crowded = bool(near[j])
            if alone[j]:
                self._learn_look(t, looks[j])
            self._tracks.append(t)
            if p.birth_frames <= 1:
                self._confirm(t, stamp_s, set())

        out = [TrackedPerson(t.id, t.keypoints.copy(), self._box_of(t), stamp_s - t.first_s,
                             t.row)
               for t in self._tracks if t.id and t.last_s == stamp_s]
        out.sort(key=lambda q: (-q.tracked_s, q.id))
        return out[:p.max_persons]

    # ------------------------------------------------------------------ helpers
    def _confirm(self, t: _Track, stamp_s: float, matched: set) -> None:
        """Give the tentative track ``t`` an id: a lost person's old one when ``t`` continues
        a coasting track (:meth:`_reid_target`; that track is marked for removal, id -1), else
        a new one while fewer than ``max_persons`` ids are held; otherwise it stays tentative
        (counted as ignored) until someone leaves."""
        if self._with_looks and t.crowded and t.appearance is None and \
                stamp_s - t.first_s <= self.params.max_lost_s:
            return        # among others and its clothes unknown: who it is can wait (a while)
        lost = self._reid_target(t, stamp_s, matched)
        if lost is not None:
            t.id, t.first_s = lost.id, lost.first_s
            if t.signature is None:
                t.signature = lost.signature
            if lost.appearance is not None:      # the person's colours as long known
                look, t.appearance = t.appearance, lost.appearance.copy()
                t.spread, t.looks = lost.spread, lost.looks
                self._learn_look(t, look)
            lost.id = -1
            self.stats.reidentified += 1
        elif sum(1 for o in self._tracks if o.id > 0) < self.params.max_persons:
            t.id = self._next_id
            self._next_id += 1
            t.renamable = self.params.signature_memory_s > 0
            self.stats.births += 1
        else:
            self.stats.ignored += 1

    def _reid_target(self, t: _Track, stamp_s: float, matched: set) -> Optional[_Track]:
        """The lost (coasting, unmatched this frame) track that the tentative track ``t``
        plausibly continues, or None.

        Plausible: a box within ``reid_distance`` box heights of that track's prediction
        (plus ``reid_speed`` per second lost beyond ``max_lost_s``), a height within 0.7-1.4
        of it, a signature that agrees, and colours within ``appearance_reid`` of its sigma
        (``appearance_reid_recent`` while lost for at most ``max_lost_s``: a person coming
        out from behind another still shows some of the other's colours). Of several, the
        one with the lowest distance in box heights plus colour distance in sigmas (two
        people lost at one crossing are told apart by their clothes)."""
        p = self.params
        best, best_key = None, np.inf
        tb = self._box_of(t)
        for i, o in enumerate(self._tracks):
            if o is t or o.id <= 0 or not o.missed or i in matched:
                continue
            lost = stamp_s - o.last_s
            ob = o.box_at(lost)
            d = float(np.hypot(tb[0] - ob[0], tb[1] - ob[1]) / max(ob[2], 1.0))
            look = appearance_distance(o.appearance, t.appearance)
            sigma = self._sigma(o)
            if lost <= p.max_lost_s:
                ok = d < p.reid_distance and (
                    look is None or look <= p.appearance_reid_recent * sigma)
            else:            # kept for its appearance: it must look the same
                ok = look is not None and look <= p.appearance_reid * sigma and \
                    d < p.reid_distance + p.reid_speed * lost
            # (unknown colours count as a fair match: appearance_reid sigmas)
            key = d + (p.appearance_reid if look is None else look / sigma)
            if ok and key < best_key and 0.7 <= tb[2] / max(ob[2], 1.0) <= 1.4 and \
                    self._signature_ok(o, t.signature):
                best, best_key = o, key
        return best

    def _keep_s(self, t: _Track) -> float:
        """How long the lost track ``t`` is kept (s)."""
        p = self.params
        if t.appearance is None:
            return p.max_lost_s
        return max(p.max_lost_s, p.appearance_max_lost_s)

    def _sigma(self, t: _Track) -> float:
        """Track ``t``'s colour scale (Lab units; :class:`TrackerParams`)."""
        p = self.params
        if t.looks < p.appearance_min_frames:
            return p.appearance_sigma
        return max(p.appearance_sigma_min, p.appearance_spread_factor * t.spread)

    def _learn_look(self, t: _Track, look: Optional[np.ndarray]) -> None:
        """Update the running mean colours of ``t`` and the spread of its frames about it."""
        if look is None:
            return
        if not t.id:        # a tentative track: its latest look (a first frame may be wrong)
            t.appearance = look.copy()
            return
        d = appearance_distance(t.appearance, look)
        if d is not None:
            t.looks += 1
            t.spread += (d - t.spread) / min(t.looks, 1.0 / self.params.appearance_rate)
        t.appearance = _blend(t.appearance, look, self.params.appearance_rate)

    def _look_factor(self, t: _Track, look: Optional[np.ndarray]) -> float:
        """The appearance factor of the similarity of track ``t`` and a candidate that looks
        ``look`` (module docstring); 1 when either is unknown."""
        d = appearance_distance(t.appearance, look)
        if d is None:
            return 1.0
        p = self.params
        return max(p.appearance_floor, float(np.exp(-0.5 * (d / self._sigma(t)) ** 2)))

    def _valid(self, cands: np.ndarray) -> Tuple[List[int], List[np.ndarray]]:
        p = self.params
        keep, boxes = [], []
        for j, c in enumerate(cands):
            seen = int(np.count_nonzero(c[:, 2] >= p.min_confidence))
            box = keypoint_box(c, p.min_confidence)
            if seen < p.min_keypoints or box is None or box[2] < p.min_height_px:
                if seen > 0:
                    self.stats.ignored += 1
                continue
            keep.append(j)
            boxes.append(box)
        return keep, boxes

    def _merge_duplicates(self, cands: np.ndarray, boxes: List[np.ndarray]) -> List[int]:
        """Indices of the candidates to keep (the more confident of a pair that is one
        person twice), in input order."""
        p = self.params
        order = np.argsort([-float(np.sum(c[:, 2])) for c in cands], kind='stable')
        kept: List[int] = []
        for j in order:
            if any(oks(cands[j], cands[k], max(boxes[j][2], boxes[k][2]), p.min_confidence)
                   > p.duplicate_oks for k in kept):
                self.stats.duplicates += 1
                continue
            kept.append(int(j))
        kept.sort()
        return kept

    def _signature_ok(self, t: _Track, sig: Optional[np.ndarray]) -> bool:
        if sig is None or t.signature is None or not t.missed:
            return True
        if np.shape(sig) != t.signature.shape:
            return True
        return signature_distance(sig, t.signature) <= self.params.signature_tolerance

    def _measure(self, t: _Track, kp: np.ndarray, box: np.ndarray) -> np.ndarray:
        """The box ``(cx, cy, h)`` that a candidate puts the track at: the track's keypoint
        shape fitted to the candidate's seen keypoints (least squares in centre and height),
        so that a partly hidden person does not drag the box towards the part still seen;
        the candidate's own box when fewer than 4 keypoints are shared or the fit is
        implausible. The height may change by at most ``max_height_change`` per frame (a
        person's size in the image changes slowly; a detection that sees half a person
        does not halve the track)."""
        mc = self.params.min_confidence
        h_prev = max(t.kalman.x[2], 1.0)
        lim = self.params.max_height_change
        z = np.array(box[:3], dtype=np.float64)
        both = (kp[:, 2] >= mc) & (t.shape[:, 2] >= mc)
        if 4 <= np.count_nonzero(both) < 0.9 * np.count_nonzero(t.shape[:, 2] >= mc):
            s = t.shape[both, :2]
            n = len(s)
            A = np.zeros((2 * n, 3))
            A[0::2, 0] = 1.0
            A[1::2, 1] = 1.0
            A[0::2, 2] = s[:, 0]
            A[1::2, 2] = s[:, 1]
            b = kp[both, :2].reshape(-1)
            sol, *_ = np.linalg.lstsq(A, b, rcond=None)
            if np.all(np.isfinite(sol)) and 0.7 * h_prev <= sol[2] <= 1.4 * h_prev:
                z = sol
        if t.hits > 1:
            z[2] = float(np.clip(z[2], h_prev / (1.0 + lim), h_prev * (1.0 + lim)))
        return z

    def _set_shape(self, t: _Track, kp: np.ndarray, box: np.ndarray) -> None:
        x = t.kalman.x
        h = max(x[2], 1.0)
        shape = kp.copy()
        shape[:, 0] = (kp[:, 0] - x[0]) / h
        shape[:, 1] = (kp[:, 1] - x[1]) / h
        seen = kp[:, 2] >= self.params.min_confidence
        # keypoints not seen now keep their last relative place (with their old confidence
        # decayed), so that the next frame can still compare them
        if t.hits > 1:
            old = t.shape
            shape[~seen, :2] = old[~seen, :2]
            shape[~seen, 2] = np.maximum(kp[~seen, 2], 0.5 * old[~seen, 2])
        t.shape = shape
        t.width_ratio = float(box[3] / max(box[2], 1.0))
        t.keypoints = kp.copy()

    @staticmethod
    def _box_of(t: _Track) -> np.ndarray:
        x = t.kalman.x
        h = max(x[2], 1.0)
        return np.array([x[0], x[1], h, h * t.width_ratio])


#: Body regions of :func:`appearance_features`: pairs of layout keypoints whose segment is
#: sampled (several pairs: one region, averaged).
APPEARANCE_REGIONS: Tuple[Tuple[Tuple[str, str], ...], ...] = (
    (('left_shoulder', 'right_hip'), ('right_shoulder', 'left_hip')),     # torso diagonals
    (('left_shoulder', 'left_elbow'), ('right_shoulder', 'right_elbow')),  # upper arms
    (('left_hip', 'left_knee'), ('right_hip', 'right_knee')),              # thighs
    (('left_knee', 'left_ankle'), ('right_knee', 'right_ankle')),          # shins
)
_REGION_INDEX = tuple(tuple((KEYPOINT_INDEX[a], KEYPOINT_INDEX[b]) for a, b in pairs)
                      for pairs in APPEARANCE_REGIONS)


def appearance_features(image: np.ndarray, kp: np.ndarray, box: Optional[np.ndarray] = None,
                        min_confidence: float = 0.3,
                        occluders: Sequence[np.ndarray] = ()) -> Optional[np.ndarray]:
    """(R, 3) mean colour (CIE Lab, L in [0, 100]) of each region of
    :data:`APPEARANCE_REGIONS` of one person, NaN for a region whose keypoints are not seen
    or fall outside the image or behind an occluder; None when no region is seen. Each
    segment is sampled at 1/4, 1/2 and 3/4 of its length with a square patch of side 4 % of
    the person's height.

    Args:
        image: (H, W, 3) uint8 BGR.
        kp: (23, 3) keypoints (u, v px, confidence).
        box: the person's :func:`keypoint_box` (computed when None).
        occluders: boxes ``(cx, cy, h, w)`` (px) of people in front of this one; a patch
            whose centre falls in one (widened by :data:`OCCLUDER_MARGIN` of its height on
            every side: a body is wider than its joints) shows them, and is not sampled.
    """
    import cv2

    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        return None
    if box is None:
        box = keypoint_box(kp, min_confidence)
        if box is None:
            return None
    H, W = img.shape[:2]
    half = max(1, int(round(0.02 * box[2])))
    means = np.full((len(_REGION_INDEX), 3), np.nan)
    bgr = []
    which = []
    for r, pairs in enumerate(_REGION_INDEX):
        samples = []
        for a, b in pairs:
            if kp[a, 2] < min_confidence or kp[b, 2] < min_confidence:
                continue
            for t in (0.25, 0.5, 0.75):
                u, v = (1 - t) * kp[a, :2] + t * kp[b, :2]
                x0, y0 = int(round(u)) - half, int(round(v)) - half
                x1, y1 = x0 + 2 * half + 1, y0 + 2 * half + 1
                if x0 < 0 or y0 < 0 or x1 > W or y1 > H or any(
                        abs(u - o[0]) <= o[3] / 2 + OCCLUDER_MARGIN * o[2] and
                        abs(v - o[1]) <= o[2] * (0.5 + OCCLUDER_MARGIN) for o in occluders):
                    continue
                samples.append(img[y0:y1, x0:x1].reshape(-1, 3).mean(axis=0))
        if samples:
            bgr.append(np.mean(samples, axis=0))
            which.append(r)
    if not which:
        return None
    lab = cv2.cvtColor(np.clip(np.array(bgr, dtype=np.float32)[None] / 255.0, 0.0, 1.0),
                       cv2.COLOR_BGR2LAB)[0]
    means[which] = lab
    return means


def in_front_of(box: np.ndarray, others: Sequence[np.ndarray]) -> List[np.ndarray]:
    """Of the boxes ``(cx, cy, h, w)`` (px) ``others``, those whose
    bottom (the feet, on a floor seen from above its height) is lower in the image by more
    than 3 % of ``box``'s height: the people standing nearer the camera."""
    bottom = box[1] + box[2] / 2
    return [o for o in others if o[1] + o[2] / 2 > bottom + 0.03 * box[2]]


def appearance_distance(a: Optional[np.ndarray], b: Optional[np.ndarray]) -> Optional[float]:
    """Mean colour distance (Lab units) over the regions both appearances show; None when
    either is None or they share no region."""
    if a is None or b is None:
        return None
    both = np.all(np.isfinite(a), axis=1) & np.all(np.isfinite(b), axis=1)
    if not np.any(both):
        return None
    return float(np.mean(np.linalg.norm(a[both] - b[both], axis=1)))


def _blend(old: Optional[np.ndarray], new: Optional[np.ndarray], rate: float
           ) -> Optional[np.ndarray]:
    """Running mean of appearances, region by region (a region not seen keeps its value)."""
    if new is None:
        return old
    if old is None:
        return new.copy()
    out = old.copy()
    seen = np.all(np.isfinite(new), axis=1)
    fresh = seen & ~np.all(np.isfinite(old), axis=1)
    out[fresh] = new[fresh]
    both = seen & ~fresh
    out[both] = (1 - rate) * old[both] + rate * new[both]
    return out
