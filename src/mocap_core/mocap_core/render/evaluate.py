"""Scoring the pipeline's outputs on rendered clips against their exact ground truth (no ROS).

``mocap eval video`` runs ``mocap process`` on each rendered test video and hands the output
arrays to :func:`score_clip`; :func:`aggregate` and :func:`report_markdown` make the report.

Metrics (positions in metres in, millimetres out):

* lifter (camera optical frame): MPJPE (pelvis-aligned), PA-MPJPE (per-frame similarity
  alignment), MRPE (pelvis position), MBLE (mean bone-length error against the rendered
  body's bones); where the MPJPE comes from: RA-MPJPE (per-frame rigid alignment, rotation
  and translation, no scale), so that MPJPE - RA-MPJPE is the share of the body's global
  orientation and RA-MPJPE - PA-MPJPE that of its scale, and the orientation error itself
  (the angle of the aligning rotation, degrees);
* jitter: mean joint acceleration magnitude (m/s^2) of the output and of the ground truth,
  and their ratio;
* left/right leg swaps: a frame counts as swapped when the lifter's legs (hip, knee, ankle,
  toe; pelvis-aligned) are closer to the ground truth with left and right exchanged than as
  labelled; frames whose true legs are less than :data:`SWAP_MIN_SEPARATION_M` apart on
  average are ambiguous and not counted;
* the detector's own left/right swaps (:func:`detector_swaps`): its knee and ankle keypoints
  closer to the exact projections with the labels exchanged; the lifter follows its labels,
  so this tells how many of the lifter's swaps it inherits;
* physics (``floor`` frame) and world stage (``world`` frame): root trajectory error: the
  whole clip's pelvis path rigidly aligned (rotation + translation, no scale) to the true
  world path; mean error (mm) and that error over the distance the pelvis travelled (RTE, %;
  only clips travelling at least :data:`RTE_MIN_TRAVEL_M`);
* the same two stages' feet (:func:`foot_scores`), each against its own floor (z = 0 of its
  output frame): the deepest ankle or toe joint below it after the first second (mm), the
  share of frames with one more than 5 mm below, and foot skating: the mean horizontal
  displacement (mm per rendered frame) of an ankle or toe joint while the ground truth says
  that heel or toe is on the floor in both frames and every frame between (a step over
  frames a live run dropped counts as that many frames); and their PA-MPJPE (per-frame similarity
  alignment, so the frame does not matter) and jitter against the lifter's (the world
  stage's against the lifter carried into the true world by the true camera pose: a
  moving camera's frame accelerates);
* the physics stage's floor estimate (:func:`floor_errors`): tilt and height of the
  estimated floor under the person against the true floor, at 1 s and after.

Breakdowns: per frame by view (front / side / back: the person's facing against the
direction to the camera), per clip by motion group, body height, camera kind.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..camera import optical_to_world, project_pinhole
from ..pose_metrics import (alignment_angle_deg, procrustes_align, rotate_about_root,
                            twist_angle_deg)
from ..skeleton import JOINT_INDEX, KEYPOINT_INDEX, PARENTS

#: Frames whose true left and right legs are closer than this (m, mean over knee, ankle,
#: toe) are not scored for swaps.
SWAP_MIN_SEPARATION_M = 0.12
#: Frames whose true left and right knees and ankles are closer in the image than this
#: fraction of the person's image height are not scored for detector swaps.
DETECTOR_SWAP_MIN_SEPARATION = 0.08
#: Detector keypoints below this confidence are not scored for swaps.
DETECTOR_SWAP_MIN_CONFIDENCE = 0.3
#: Clips whose pelvis travels less than this (m) get no RTE percentage.
RTE_MIN_TRAVEL_M = 1.0
#: Frames per piece of the world-frame joint errors (WHAM's and GVHMR's 100).
WORLD_SEGMENT = 100

_LEGS = {side: [JOINT_INDEX[f'{side}_{n}'] for n in ('hip', 'knee', 'ankle', 'toe')]
         for side in ('left', 'right')}
_BONES = [j for j in range(1, len(PARENTS))]


def _labels_swapped(left: np.ndarray, right: np.ndarray, true_left: np.ndarray,
                    true_right: np.ndarray) -> np.ndarray:
    """(F, N, D) estimated and true points of the left and right side -> (F,) True where
    the estimate lies closer to the truth with its left and right labels exchanged."""
    def dist(a, b):
        return np.linalg.norm(a - b, axis=-1).sum(axis=1)
    return dist(left, true_right) + dist(right, true_left) < \
        dist(left, true_left) + dist(right, true_right)


def detector_swaps(gt: Dict[str, np.ndarray]) -> np.ndarray:
    """Per rendered frame: 1 when the detector's left and right knees and ankles are
    labelled the other way round, 0 when not, -1 when not scored (a point missing or below
    :data:`DETECTOR_SWAP_MIN_CONFIDENCE`, or the true legs closer in the image than
    :data:`DETECTOR_SWAP_MIN_SEPARATION` of the person's height). ``gt``: a clip's
    ``data.npz`` arrays (``keypoints`` (F, 23, 3), ``joints_camera`` (F, 18, 3), ``K``)."""
    uv = project_pinhole(gt['K'], gt['joints_camera'])[..., :2]
    kp = np.asarray(gt['keypoints'])
    names = ('knee', 'ankle')
    kl = kp[:, [KEYPOINT_INDEX[f'left_{n}'] for n in names]]
    kr = kp[:, [KEYPOINT_INDEX[f'right_{n}'] for n in names]]
    gl = uv[:, [JOINT_INDEX[f'left_{n}'] for n in names]]
    gr = uv[:, [JOINT_INDEX[f'right_{n}'] for n in names]]
    height = np.ptp(uv[..., 1], axis=1)
    scored = (np.minimum(kl[..., 2].min(1), kr[..., 2].min(1)) > DETECTOR_SWAP_MIN_CONFIDENCE) \
        & (np.linalg.norm(gl - gr, axis=-1).mean(1) > DETECTOR_SWAP_MIN_SEPARATION * height)
    return np.where(scored, _labels_swapped(kl[..., :2], kr[..., :2], gl, gr).astype(int), -1)


def motion_group(clip_id: str) -> str:
    """A readable motion family of a clip id: the Bandai Namco content (``walk``,
    ``dance``, ...), ``cmu`` for CMU clips, else the file stem."""
    name = clip_id.split(':')[-1].split('/')[-1]
    m = re.match(r'dataset-\d+_(.+?)_[a-z-]+_\d+\.bvh$', name)
    if m:
        return m.group(1)
    if 'cmu' in clip_id.lower():
        return 'cmu'
    return re.sub(r'[_-]?\d+$', '', name.rsplit('.', 1)[0]) or name


def camera_pitch_deg(R: np.ndarray) -> np.ndarray:
    """(F,) how far each camera's optical axis points below the horizontal (degrees; negative:
    looking up), from (F, 3, 3) world -> optical-frame rotations (world z up)."""
    R = np.asarray(R, dtype=np.float64)
    return np.degrees(np.arcsin(np.clip(-R[..., 2, 2], -1.0, 1.0)))


#: the classes of :func:`pitch_class`, in report order
PITCH_CLASSES = ('looking up (> 15 deg)', 'level (within 15 deg)', 'looking down 15-35 deg',
                 'looking down >= 35 deg')


def pitch_class(pitch_deg: float) -> str:
    """A clip's camera by how far it looks down (its median :func:`camera_pitch_deg`, degrees;
    negative: up). The body's tilt toward the camera, which the keypoints hardly show, grows
    with the pitch."""
    if pitch_deg <= -15.0:
        return PITCH_CLASSES[0]
    if pitch_deg < 15.0:
        return PITCH_CLASSES[1]
    return PITCH_CLASSES[2] if pitch_deg < 35.0 else PITCH_CLASSES[3]


def height_class(height_m: float) -> str:
    return 'short (< 1.60 m)' if height_m < 1.6 else (
        'medium (1.60-1.75 m)' if height_m < 1.75 else 'tall (>= 1.75 m)')


_FOOT_JOINTS = [JOINT_INDEX[n] for n in ('left_ankle', 'left_toe', 'right_ankle',
                                          'right_toe')]


def _steps_in_contact(joints: np.ndarray, idx: np.ndarray, contacts: np.ndarray
                      ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Horizontal steps (N - 1, 4) m of the ankle and toe joints between consecutive output
    frames, where they count as skating (N - 1, 4): the true contact of the same column (the
    ankle moves with the heel label, the toe joint with the toe's) in every rendered frame from
    the one to the other, and the number of rendered frames (N - 1,) each step spans (1 when
    the outputs follow each other; more where a live run dropped frames, so that skating is
    per rendered frame either way)."""
    feet = np.asarray(joints, dtype=float)[:, _FOOT_JOINTS, :2]
    c = np.asarray(contacts, dtype=bool)
    idx = np.asarray(idx, dtype=int)
    gaps = np.diff(idx)
    ok = (idx[:-1] >= 0) & (idx[1:] < len(c)) & (gaps >= 1)
    # frames out of contact per column before each rendered frame (cumulative)
    off = np.concatenate([np.zeros((1, c.shape[1]), int), np.cumsum(~c, axis=0)])
    a = np.clip(idx[:-1], 0, len(c) - 1)
    b = np.clip(idx[1:], 0, len(c) - 1)
    both = ok[:, None] & ((off[b + 1] - off[a]) == 0)
    return np.linalg.norm(np.diff(feet, axis=0), axis=-1), both, np.maximum(gaps, 1)


def foot_scores(joints: np.ndarray, index: np.ndarray, contacts: np.ndarray,
                fps: float) -> Dict[str, float]:
    """Feet of one stage against its own floor (module docstring).

    Args:
        joints: (N, 18, 3) the stage's joints in its output frame (z up, floor z = 0), m.
        index: (N,) rendered frame of each. contacts: (F, 4) true contacts of the rendered
            frames (left heel, left toe, right heel, right toe). fps: frame rate.
    Returns: ``penetration_after_1s_mm``, ``frames_below_5mm`` (share, after the first
    second), ``skating_mm`` (mm per frame; NaN without contact frames).
    """
    joints = np.asarray(joints, dtype=float)
    idx = np.asarray(index, dtype=int)
    feet = joints[:, _FOOT_JOINTS]                       # (N, 4, 3): ankle, toe, ankle, toe
    depth = np.maximum(0.0, -feet[..., 2].min(axis=1))
    late = idx >= int(round(fps))
    step, both, gaps = _steps_in_contact(joints, idx, contacts)
    spans = np.broadcast_to(gaps[:, None], both.shape)
    return {
        'penetration_after_1s_mm': float(1000 * depth[late].max()) if late.any()
        else float('nan'),
        'frames_below_5mm': float(np.mean(depth[late] > 0.005)) if late.any()
        else float('nan'),
        'skating_mm': float(1000 * step[both].sum() / spans[both].sum()) if both.any()
        else float('nan'),
    }


#: Groups of :func:`skating_by_camera_state`, in report order: what the world stage does with
#: a frame of each (camera_mode auto, fuse_translating on)
CAMERA_STATE_GROUPS = ('static', 'translation measured', 'turning or moving, not measured',
                       'unknown', 'state changes')


def camera_state_group(state: str, translation_known: bool) -> str:
    """The :data:`CAMERA_STATE_GROUPS` entry of a frame's camera-motion estimate: ``static``
    (fused with the static-camera constants), ``translation measured`` (a turning or moving
    camera whose position was measured over the floor: fused towards it),
    ``turning or moving, not measured`` (GMR and the foot lock alone), ``unknown``."""
    if state == 'static':
        return 'static'
    if state == 'unknown':
        return 'unknown'
    return 'translation measured' if translation_known else 'turning or moving, not measured'


def skating_by_camera_state(joints: np.ndarray, index: np.ndarray, contacts: np.ndarray,
                            groups: Sequence[str]) -> Dict[str, List[float]]:
    """A stage's foot skating (as :func:`foot_scores`) split by the camera-motion estimate's
    state of each rendered frame.

    Args:
        joints: (N, 18, 3) the stage's joints in its output frame, m. index: (N,) rendered
            frame of each. contacts: (F, 4) true contacts. groups: (F,) the
            :func:`camera_state_group` of each rendered frame.
    Returns: ``{group: [sum of the displacements (mm), the rendered frames they span]}`` for
    pooling over clips; a step between two frames of different groups counts as ``state
    changes``.
    """
    idx = np.asarray(index, dtype=int)
    step, both, gaps = _steps_in_contact(joints, idx, contacts)
    out: Dict[str, List[float]] = {}
    for k in np.flatnonzero(both.any(axis=1)):
        i, j = idx[k], idx[k + 1]
        if j >= len(groups):
            continue
        g = groups[j] if groups[i] == groups[j] else 'state changes'
        acc = out.setdefault(g, [0.0, 0.0])
        acc[0] += float(1000 * step[k][both[k]].sum())
        acc[1] += float(both[k].sum() * gaps[k])
    return out


def skating_in_world(joints: np.ndarray, index: np.ndarray, quats: np.ndarray,
                     translations: np.ndarray, floor_index: np.ndarray,
                     gt: Dict[str, np.ndarray]) -> Dict[str, float]:
    """A floor-frame stage's foot skating in the true world: its joints mapped by its own
    floor (per frame, ``/mocap/physics/floor``) into the camera and by the true camera pose
    into the world, then scored as :func:`foot_scores` scores skating. The physics output's
    floor frame rides with the camera, so with a moving camera a foot that stands in the
    world moves in it: the skating in the output's own frame is not comparable between
    cameras (nor between modes that carry the body with the camera); this one is.

    Args:
        joints: (N, 18, 3) the stage's joints in its floor frame, m; index: (N,) rendered
            frame of each. quats: (M, 4) x, y, z, w, translations: (M, 3): the floor
            frame's pose in the camera optical frame per floor message, floor_index: (M,)
            the rendered frame of each. gt: the clip's arrays (``camera_R``,
            ``camera_position``, ``contacts``, ``fps``).
    Returns: ``skating_world_mm`` (mm per frame; NaN without frames that have a floor).
    """
    from ..rotations import quat_to_matrix
    idx = np.asarray(index, dtype=int)
    fidx = np.asarray(floor_index, dtype=int)
    by_frame = {int(f): k for k, f in enumerate(fidx)}
    keep = np.array([int(i) in by_frame for i in idx], dtype=bool)
    if keep.sum() < 2:
        return {'skating_world_mm': float('nan')}
    k = np.array([by_frame[int(i)] for i in idx[keep]])
    R_cf = quat_to_matrix(np.asarray(quats, dtype=float)[k])
    t_cf = np.asarray(translations, dtype=float)[k]
    in_camera = np.einsum('fij,fnj->fni', R_cf, np.asarray(joints, dtype=float)[keep]) \
        + t_cf[:, None]
    world = camera_to_world(in_camera, idx[keep], gt)
    return {'skating_world_mm': foot_scores(world, idx[keep], gt['contacts'],
                                            float(gt['fps']))['skating_mm']}


def floor_errors(quats: np.ndarray, translations: np.ndarray, index: np.ndarray,
                 gt: Dict[str, np.ndarray]) -> Dict[str, float]:
    """The physics stage's floor estimate against the true floor (z = 0 of the world).

    Args:
        quats: (N, 4) x, y, z, w and translations: (N, 3): the estimated floor frame's pose
            in the camera optical frame (``/mocap/physics/floor``), per output frame.
        index: (N,) rendered frame of each. gt: the clip's ``data.npz`` arrays
            (``camera_R`` (F, 3, 3) with ``p_camera = R (p_world - camera_position)``,
            ``camera_position`` (F, 3), ``joints_world`` (F, 18, 3), ``fps``).
    Returns: ``floor_tilt_1s_deg`` / ``floor_height_1s_mm``: the angle between the estimated
    and the true floor normal and the height of the estimated floor under the person (true
    pelvis), one second in; ``floor_tilt_deg`` / ``floor_height_mm``: their medians over the
    frames after the first second.
    """
    from ..rotations import quat_to_matrix
    idx = np.asarray(index, dtype=int)
    F = len(gt['joints_world'])
    ok = (idx >= 0) & (idx < F)
    if not ok.any():
        return {}
    idx = idx[ok]
    R_cf = quat_to_matrix(np.asarray(quats, dtype=float)[ok])
    t_cf = np.asarray(translations, dtype=float)[ok]
    R_wc = np.transpose(np.asarray(gt['camera_R'])[idx], (0, 2, 1))
    n = np.einsum('fij,fj->fi', R_wc, R_cf[:, :, 2])
    o = np.einsum('fij,fj->fi', R_wc, t_cf) + np.asarray(gt['camera_position'])[idx]
    pel = np.asarray(gt['joints_world'])[idx, 0]
    nz = np.where(np.abs(n[:, 2]) > 1e-6, n[:, 2], 1e-6)
    z = o[:, 2] - (n[:, 0] * (pel[:, 0] - o[:, 0]) + n[:, 1] * (pel[:, 1] - o[:, 1])) / nz
    tilt = np.degrees(np.arccos(np.clip(n[:, 2], -1.0, 1.0)))
    fps = float(gt['fps'])
    one = int(np.argmin(np.abs(idx - round(fps))))
    late = idx >= round(fps)
    nan = float('nan')
    return {'floor_tilt_1s_deg': float(tilt[one]), 'floor_height_1s_mm': float(1000 * z[one]),
            'floor_tilt_deg': float(np.median(tilt[late])) if late.any() else nan,
            'floor_height_mm': float(1000 * np.median(np.abs(z[late]))) if late.any()
            else nan}


def _rigid_align(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """(F, 3) ``pred`` rigidly (rotation, translation) aligned onto ``gt``."""
    mp, mg = pred.mean(axis=0), gt.mean(axis=0)
    h = (pred - mp).T @ (gt - mg)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(u @ vt))
    r = u @ np.diag([1.0, 1.0, d]) @ vt
    return (pred - mp) @ r + mg


def _rigid_fit(pred: np.ndarray, gt: np.ndarray):
    """(R, t) with ``gt ~ pred @ R + t`` for (N, 3) points (rotation and translation)."""
    mp, mg = pred.mean(axis=0), gt.mean(axis=0)
    u, _, vt = np.linalg.svd((pred - mp).T @ (gt - mg))
    d = np.sign(np.linalg.det(u @ vt))
    r = u @ np.diag([1.0, 1.0, d]) @ vt
    return r, mg - mp @ r


def world_segment_errors(joints: np.ndarray, index: np.ndarray, gt_world: np.ndarray,
                         segment: int = WORLD_SEGMENT) -> Dict[str, float]:
    """WA-MPJPE and W-MPJPE over ``segment``-frame pieces (mm), as WHAM and GVHMR define them:
    each piece of the world output is aligned to the true world joints rigidly, over the
    whole piece (WA) or by its first two frames only (W, so the drift within the piece
    counts). ``joints`` (N, 18, 3) world output at rendered frames ``index`` (N,);
    ``gt_world`` (F, 18, 3). Pieces shorter than half a segment (a clip's tail) are left out
    unless the clip has no full piece."""
    index = np.asarray(index, dtype=int)
    F = len(gt_world)
    ok = (index >= 0) & (index < F)
    joints, index = np.asarray(joints)[ok], index[ok]
    starts = list(range(0, max(F, 1), segment))
    wa, w = [], []
    for s0 in starts:
        m = (index >= s0) & (index < s0 + segment)
        if m.sum() < 2 or (m.sum() < segment // 2 and len(starts) > 1):
            continue
        P, G = joints[m], gt_world[index[m]]
        r, t = _rigid_fit(P.reshape(-1, 3), G.reshape(-1, 3))
        wa.append(np.linalg.norm(P @ r + t - G, axis=-1).mean())
        r, t = _rigid_fit(P[:2].reshape(-1, 3), G[:2].reshape(-1, 3))
        w.append(np.linalg.norm(P @ r + t - G, axis=-1).mean())
    if not wa:
        return {}
    return {'wa_mpjpe100': float(1000 * np.mean(wa)), 'w_mpjpe100': float(1000 * np.mean(w))}


def acceleration(p: np.ndarray, fps: float) -> float:
    """Mean joint acceleration magnitude (m/s^2) of (F, J, 3) positions."""
    if len(p) < 3:
        return float('nan')
    return float(np.linalg.norm(np.diff(p, 2, axis=0), axis=-1).mean() * fps * fps)


@dataclass
class ClipScore:
    """The scores of one clip (see the module docstring); per-frame arrays for pooling."""

    clip: str
    group: str
    height: str
    camera: str
    frames: int
    scored: int
    detected: float
    mpjpe: np.ndarray                 # (scored,) mm per frame
    pa_mpjpe: np.ndarray
    mrpe: np.ndarray
    views: np.ndarray                 # (scored,) str
    swaps: np.ndarray                 # (scored,) 1 swapped, 0 not, -1 ambiguous
    mble: float
    jitter: float
    jitter_gt: float
    root: Dict[str, Dict[str, float]] = field(default_factory=dict)
    #: (frames,) the detector's own swaps per rendered frame (:func:`detector_swaps`) and
    #: the view of every rendered frame
    detector_swaps: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    all_views: np.ndarray = field(default_factory=lambda: np.zeros(0, str))
    #: the world output's skating by the camera-motion state (:func:`skating_by_camera_state`)
    world_skating_by_state: Dict[str, List[float]] = field(default_factory=dict)
    #: (scored,) mm per frame after a rigid alignment (no scale), and the angle (degrees) of
    #: that alignment's rotation: the error of the global orientation
    ra_mpjpe: np.ndarray = field(default_factory=lambda: np.zeros(0))
    orientation_deg: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: (scored,) the body's tilt toward / away from the camera (degrees, the twist about the
    #: optical x axis of that rotation, :func:`~mocap_core.pose_metrics.twist_angle_deg`)
    #: and (scored,) mm per frame with the clip's median tilt taken out (an oracle: how much
    #: of the MPJPE one per-clip angle, such as a camera pitch the 2D cannot show, explains)
    tilt_deg: np.ndarray = field(default_factory=lambda: np.zeros(0))
    tilt_free_mpjpe: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: the rendered floor's texture kind (``render.scene``; what the camera-motion estimate
    #: tracks), '' when unknown
    floor: str = ''
    #: the camera's pitch class (:func:`pitch_class`), '' when the clip has no camera pose
    pitch: str = ''

    def summary(self) -> Dict[str, float]:
        s = self.swaps[self.swaps >= 0]
        out = {'mpjpe': float(np.mean(self.mpjpe)), 'pa_mpjpe': float(np.mean(self.pa_mpjpe)),
               'mrpe': float(np.mean(self.mrpe)), 'mble': self.mble, 'jitter': self.jitter,
               'jitter_gt': self.jitter_gt,
               'jitter_ratio': self.jitter / max(self.jitter_gt, 1e-9),
               'swap_rate': float(s.mean()) if len(s) else float('nan'),
               'detected': self.detected, 'scored': self.scored, 'frames': self.frames}
        if len(self.ra_mpjpe):
            out['ra_mpjpe'] = float(np.mean(self.ra_mpjpe))
            out['orientation_deg'] = float(np.median(self.orientation_deg))
        if len(self.tilt_deg):
            out['tilt_bias_deg'] = float(abs(np.median(self.tilt_deg)))
            out['tilt_free_mpjpe'] = float(np.mean(self.tilt_free_mpjpe))
        for stage, r in self.root.items():
            for k, v in r.items():
                out[f'{stage}_{k}'] = v
        return out


def _paired_with_lifter(stage: np.ndarray, stage_idx: np.ndarray, lifter: np.ndarray,
                        lifter_idx: np.ndarray, G: np.ndarray, fps: float,
                        lifter_world: Optional[np.ndarray] = None,
                        truth_world: Optional[np.ndarray] = None) -> Dict[str, float]:
    """A stage's change from the lifter on the frames both have: ``pa_mpjpe_change`` (mm,
    stage minus lifter PA-MPJPE) and, over the longest run of consecutive frames,
    ``jitter_vs_lifter`` (mean joint acceleration, stage over lifter), ``jitter`` (the
    stage's, m/s^2) and ``jitter_vs_truth`` (stage over the true motion's on the same frames:
    ``G`` in the camera frame, or ``truth_world`` (F, J, 3) with ``lifter_world``).

    PA-MPJPE does not depend on the frame the joints are in; acceleration does not depend
    on a *fixed* rigid frame, but a moving camera's frame accelerates. The physics output
    lives in a floor frame fixed to the camera, like the lifter's; the world output does
    not: for it pass ``lifter_world``, the lifter's joints carried into the true world by
    the true camera pose of each frame, so that both sides are in an inertial frame
    (``jitter_vs_lifter_camera_frame`` keeps the ratio against the camera-frame lifter)."""
    pos = {int(f): i for i, f in enumerate(lifter_idx)}
    both = [(i, pos[int(f)]) for i, f in enumerate(stage_idx) if int(f) in pos]
    if len(both) < 3:
        return {}
    si, li = (np.array(x) for x in zip(*both))
    g = G[stage_idx[si]]
    pa_s = np.linalg.norm(procrustes_align(stage[si], g) - g, axis=-1).mean()
    pa_l = np.linalg.norm(procrustes_align(lifter[li], g) - g, axis=-1).mean()
    out = {'pa_mpjpe_change': float(1000 * (pa_s - pa_l))}
    frames = stage_idx[si]
    breaks = np.flatnonzero(np.diff(frames) != 1) + 1
    runs = np.split(np.arange(len(frames)), breaks)
    run = max(runs, key=len)
    if len(run) >= 10:
        a_s = acceleration(stage[si[run]], fps)
        a_l = acceleration(lifter[li[run]], fps)
        a_g = acceleration(G[frames[run]], fps)
        if lifter_world is not None:
            out['jitter_vs_lifter_camera_frame'] = a_s / max(a_l, 1e-9)
            a_l = acceleration(lifter_world[li[run]], fps)
            a_g = acceleration(truth_world[frames[run]], fps) if truth_world is not None \
                else float('nan')
        out['jitter_vs_lifter'] = a_s / max(a_l, 1e-9)
        out['jitter'] = a_s
        out['jitter_vs_truth'] = a_s / max(a_g, 1e-9)
    return out


#: a body whose up (pelvis -> neck) is further than this from its frame's z axis is down
FALLEN_TILT_DEG = 45.0
#: ... while the true body's is within this of the true world's up
UPRIGHT_TILT_DEG = 30.0


def body_tilt_deg(joints: np.ndarray) -> np.ndarray:
    """(N, 18, 3) joints in a frame with z up -> (N,) angle between the body's up (pelvis
    to neck) and z, degrees."""
    from ..skeleton import JOINT_INDEX
    up = joints[:, JOINT_INDEX['neck']] - joints[:, JOINT_INDEX['pelvis']]
    cos = up[:, 2] / np.maximum(np.linalg.norm(up, axis=-1), 1e-9)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def fallen_share(stage: np.ndarray, truth_world: np.ndarray) -> float:
    """The share of frames in which a stage's body (N, 18, 3), in its own z-up frame (the
    physics floor frame, the world), has fallen over: tilted more than
    :data:`FALLEN_TILT_DEG` from its frame's up while the true body (N, 18, 3, true world)
    stands within :data:`UPRIGHT_TILT_DEG` of upright. Frames where the truth leans are
    not counted as fallen."""
    if not len(stage):
        return float('nan')
    down = (body_tilt_deg(stage) > FALLEN_TILT_DEG) & \
        (body_tilt_deg(truth_world) < UPRIGHT_TILT_DEG)
    return float(down.mean())


def camera_to_world(points: np.ndarray, index: np.ndarray, gt: Dict[str, np.ndarray]
                    ) -> np.ndarray:
    """(N, J, 3) points in the optical frame of rendered frames ``index`` (N,) -> the true
    world frame, with that frame's camera pose (``p_camera = R (p_world - position)``)."""
    return optical_to_world(np.asarray(gt['camera_R'])[index],
                            np.asarray(gt['camera_position'])[index], points)


def score_clip(clip: str, meta: dict, gt: Dict[str, np.ndarray],
               lifter: Optional[np.ndarray], lifter_index: np.ndarray,
               stage_roots: Optional[Dict[str, tuple]] = None) -> ClipScore:
    """Score one clip.

    Args:
        clip: clip id; meta: its ``meta.json``; gt: its ``data.npz`` arrays.
        lifter: (N, 18, 3) the lifter's joints, camera optical frame (None: nothing out).
        lifter_index: (N,) the rendered frame index of each lifter output.
        stage_roots: ``{'physics': (pelvis (M, 3), index (M,)), 'world': ...}`` the stages'
            pelvis paths in their own frames with their frame indices, or
            ``(joints (M, 18, 3), index (M,))``: then the feet are scored too
            (:func:`foot_scores`).
    """
    fps = float(gt['fps'])
    F = len(gt['joints_camera'])
    G = gt['joints_camera']
    if lifter is None or len(lifter) == 0:
        raise ValueError(f'{clip}: the lifter published nothing')
    idx = np.asarray(lifter_index, dtype=int)
    keep = (idx >= 0) & (idx < F)
    P, idx = np.asarray(lifter)[keep], idx[keep]
    g = G[idx]
    pr, gr = P - P[:, :1], g - g[:, :1]
    mpjpe = 1000 * np.linalg.norm(pr - gr, axis=-1).mean(axis=1)
    pa = 1000 * np.linalg.norm(procrustes_align(P, g) - g, axis=-1).mean(axis=1)
    ra = 1000 * np.linalg.norm(procrustes_align(P, g, scale=False) - g, axis=-1).mean(axis=1)
    mrpe = 1000 * np.linalg.norm(P[:, 0] - g[:, 0], axis=-1)
    bl_p = np.linalg.norm(P[:, _BONES] - P[:, [PARENTS[j] for j in _BONES]], axis=-1)
    bl_g = np.linalg.norm(g[:, _BONES] - g[:, [PARENTS[j] for j in _BONES]], axis=-1)
    mble = float(1000 * np.abs(np.median(bl_p, axis=0) - np.median(bl_g, axis=0)).mean())
    L, R = _LEGS['left'], _LEGS['right']
    sep = np.linalg.norm(gr[:, L[1:]] - gr[:, R[1:]], axis=-1).mean(1)
    swaps = np.where(sep < SWAP_MIN_SEPARATION_M, -1,
                     _labels_swapped(pr[:, L], pr[:, R], gr[:, L], gr[:, R]).astype(int))
    contiguous = np.all(np.diff(idx) == 1)
    jit = acceleration(P, fps) if contiguous else float('nan')
    jit_gt = acceleration(g, fps)
    root: Dict[str, Dict[str, float]] = {}
    travel_path = gt['joints_world'][:, 0]
    travel = float(np.linalg.norm(np.diff(travel_path[:, :2], axis=0), axis=-1).sum())
    for stage, (pel, sidx) in (stage_roots or {}).items():
        sidx = np.asarray(sidx, dtype=int)
        pel = np.asarray(pel)
        ok = (sidx >= 0) & (sidx < F)
        if ok.sum() < 3:
            continue
        full = pel if pel.ndim == 3 else None
        pel = pel[:, 0] if pel.ndim == 3 else pel
        est, true = pel[ok], travel_path[sidx[ok]]
        err = float(1000 * np.linalg.norm(_rigid_align(est, true) - true, axis=-1).mean())
        root[stage] = {'root_error': err,
                       # no alignment: meaningful when the stage's frame is the true world
                       # (a known camera pose)
                       'root_error_unaligned': float(1000 * np.linalg.norm(
                           est - true, axis=-1).mean()),
                       # the same split: along the floor and up (the true world is z up)
                       'root_error_unaligned_horizontal': float(1000 * np.linalg.norm(
                           est[:, :2] - true[:, :2], axis=-1).mean()),
                       'root_error_unaligned_vertical': float(1000 * np.abs(
                           est[:, 2] - true[:, 2]).mean()),
                       'rte': 100 * err / 1000 / travel if travel >= RTE_MIN_TRAVEL_M
                       else float('nan')}
        if full is not None:
            g_s = G[sidx[ok]]
            root[stage]['pa_mpjpe'] = float(1000 * np.linalg.norm(
                procrustes_align(full[ok], g_s) - g_s, axis=-1).mean())
            world_lifter = camera_to_world(P, idx, gt) if stage == 'world' \
                and 'camera_R' in gt else None
            if world_lifter is not None:
                # the lifter's own root moved into the true world by the true camera pose:
                # what a known camera pose can give at best from it (the MRPE split as the
                # world root's error is)
                d = world_lifter[:, 0] - gt['joints_world'][idx][:, 0]
                root[stage]['lifter_root_error_horizontal'] = float(
                    1000 * np.linalg.norm(d[:, :2], axis=-1).mean())
                root[stage]['lifter_root_error_vertical'] = float(
                    1000 * np.abs(d[:, 2]).mean())
            root[stage].update(_paired_with_lifter(
                full[ok], sidx[ok], P, idx, G, fps, world_lifter,
                gt.get('joints_world') if world_lifter is not None else None))
            if 'contacts' in gt:
                root[stage].update(foot_scores(full[ok], sidx[ok], gt['contacts'], fps))
            root[stage]['fallen'] = fallen_share(full[ok], gt['joints_world'][sidx[ok]])
            if stage == 'world':
                root[stage].update(world_segment_errors(full[ok], sidx[ok],
                                                        gt['joints_world']))
    height = height_class(float(meta.get('body_height_m', 1.7)))
    tilt = twist_angle_deg(P, g, (1.0, 0.0, 0.0))
    untilted = rotate_about_root(pr, (1.0, 0.0, 0.0), float(np.median(tilt)))
    tilt_free = 1000 * np.linalg.norm(untilted - gr, axis=-1).mean(axis=1)
    return ClipScore(clip, motion_group(clip), height, meta['camera']['kind'], F, len(idx),
                     float(meta.get('detected_fraction', float('nan'))), mpjpe, pa, mrpe,
                     np.asarray(gt['view'])[idx], swaps, mble, jit, jit_gt, root,
                     detector_swaps(gt), np.asarray(gt['view']), ra_mpjpe=ra,
                     orientation_deg=alignment_angle_deg(P, g), tilt_deg=tilt,
                     tilt_free_mpjpe=tilt_free,
                     floor=str((meta.get('appearance') or {}).get('floor', [''])[0]),
                     pitch=pitch_class(float(np.median(camera_pitch_deg(gt['camera_R'][idx]))))
                     if 'camera_R' in gt else '')


# ------------------------------------------------------------------------------------------
def _median(xs: Sequence[float]) -> float:
    xs = [x for x in xs if np.isfinite(x)]
    return float(np.median(xs)) if xs else float('nan')


def aggregate(scores: List[ClipScore]) -> dict:
    """Medians over clips, pooled per-frame means, and the breakdowns."""
    if not scores:
        raise ValueError('no clip scored')
    per = [s.summary() for s in scores]
    keys = sorted({k for p in per for k in p})
    out = {'clips': len(scores), 'frames': int(sum(s.frames for s in scores)),
           'scored_frames': int(sum(s.scored for s in scores)),
           'median': {k: _median([p.get(k, float('nan')) for p in per]) for k in keys}}
    allsw = np.concatenate([s.swaps for s in scores])
    out['pooled'] = {
        'mpjpe': float(np.concatenate([s.mpjpe for s in scores]).mean()),
        'pa_mpjpe': float(np.concatenate([s.pa_mpjpe for s in scores]).mean()),
        'mrpe': float(np.concatenate([s.mrpe for s in scores]).mean()),
        'swap_rate': float((allsw[allsw >= 0]).mean()) if (allsw >= 0).any() else float('nan'),
    }
    for st in ('physics', 'world'):
        # bodies that fell over: the clips with any such frame, and the mean share of frames
        # (a median over clips would hide them: most clips have none)
        f = np.array([p[f'{st}_fallen'] for p in per if np.isfinite(p.get(f'{st}_fallen',
                                                                           np.nan))])
        if len(f):
            out['pooled'][f'{st}_fallen_clips'] = int((f > 0).sum())
            out['pooled'][f'{st}_fallen_clips_10pct'] = int((f > 0.1).sum())
            out['pooled'][f'{st}_fallen'] = float(f.mean())
    views = np.concatenate([s.views for s in scores])
    mp = np.concatenate([s.mpjpe for s in scores])
    pa = np.concatenate([s.pa_mpjpe for s in scores])
    decomposed = all(len(s.ra_mpjpe) == len(s.mpjpe) for s in scores)
    if decomposed:
        ra = np.concatenate([s.ra_mpjpe for s in scores])
        ori = np.concatenate([s.orientation_deg for s in scores])
        out['pooled']['ra_mpjpe'] = float(ra.mean())
        out['pooled']['orientation_deg'] = float(np.median(ori))
    by_view = {}
    for v in ('front', 'side', 'back'):
        m = views == v
        if m.any():
            sw = allsw[m]
            by_view[v] = {'frames': int(m.sum()), 'mpjpe': float(mp[m].mean()),
                          'pa_mpjpe': float(pa[m].mean()),
                          'swap_rate': float((sw[sw >= 0]).mean()) if (sw >= 0).any()
                          else float('nan')}
            if decomposed:
                by_view[v]['ra_mpjpe'] = float(ra[m].mean())
                by_view[v]['orientation_deg'] = float(np.median(ori[m]))
    det = np.concatenate([s.detector_swaps for s in scores])
    det_views = np.concatenate([s.all_views for s in scores])
    out['pooled']['detector_swap_rate'] = float(det[det >= 0].mean()) if (det >= 0).any() \
        else float('nan')
    for v, r in by_view.items():
        d = det[(det_views == v) & (det >= 0)]
        r['detector_swap_rate'] = float(d.mean()) if len(d) else float('nan')
    out['by_view'] = by_view
    pooled: Dict[str, List[float]] = {}
    for sc in scores:
        for g, (total, n) in sc.world_skating_by_state.items():
            acc = pooled.setdefault(g, [0.0, 0.0])
            acc[0] += total
            acc[1] += n
    out['world_skating_by_camera_state'] = {
        g: {'steps': int(pooled[g][1]), 'mm': pooled[g][0] / pooled[g][1]}
        for g in CAMERA_STATE_GROUPS if g in pooled and pooled[g][1] > 0}
    for name, attr in (('by_group', 'group'), ('by_height', 'height'),
                       ('by_camera', 'camera'), ('by_pitch', 'pitch')):
        groups: Dict[str, List[dict]] = {}
        for s, p in zip(scores, per):
            if getattr(s, attr):
                groups.setdefault(getattr(s, attr), []).append(p)
        out[name] = {g: {'clips': len(ps), **{k: _median([p.get(k, float('nan')) for p in ps])
                                              for k in ('mpjpe', 'pa_mpjpe', 'swap_rate',
                                                        'jitter_ratio', 'detected',
                                                        'physics_root_error',
                                                        'world_root_error',
                                                        'physics_penetration_after_1s_mm',
                                                        'world_penetration_after_1s_mm',
                                                        'physics_skating_mm',
                                                        'physics_skating_world_mm',
                                                        'world_skating_mm', 'world_rte',
                                                        'world_wa_mpjpe100',
                                                        'world_w_mpjpe100',
                                                        'camera_rotation_error_deg_s',
                                                        'camera_state_static',
                                                        'camera_state_rotating',
                                                        'camera_state_moving',
                                                        'camera_state_unknown',
                                                        'tilt_bias_deg')}}
                     for g, ps in sorted(groups.items())}
    floors: Dict[str, List[dict]] = {}
    for s, p in zip(scores, per):
        if s.floor and s.camera != 'static':
            floors.setdefault(s.floor, []).append(p)
    out['moving_by_floor'] = {
        g: {'clips': len(ps), **{k: _median([p.get(k, float('nan')) for p in ps])
                                 for k in ('camera_rotation_error_deg_s', 'camera_drift_deg',
                                           'camera_state_unknown', 'world_rte',
                                           'world_skating_mm')}}
        for g, ps in sorted(floors.items())}
    return out


def _f(x: float, fmt: str = '{:.1f}') -> str:
    return fmt.format(x) if x is not None and np.isfinite(x) else '–'


def report_markdown(agg: dict, title: str, setup: Sequence[str]) -> str:
    """The benchmark report (medians over clips first, then the breakdowns)."""
    m, p = agg['median'], agg['pooled']
    lines = [f'# {title}', '', *setup, '',
             f"{agg['clips']} clips, {agg['frames']} frames ({agg['scored_frames']} with a "
             'lifter output).', '', '## Summary (median over clips)', '',
             '| measure | value |', '|---|---|',
             f"| lifter MPJPE | {_f(m.get('mpjpe'))} mm (pooled over frames "
             f"{_f(p['mpjpe'])}) |",
             f"| lifter PA-MPJPE | {_f(m.get('pa_mpjpe'))} mm (pooled {_f(p['pa_mpjpe'])}) |",
             "| ... where the MPJPE comes from: after a rigid alignment (RA-MPJPE: the global "
             f"orientation removed, not the scale) | {_f(m.get('ra_mpjpe'))} mm (pooled "
             f"{_f(p.get('ra_mpjpe', float('nan')))}); orientation error "
             f"{_f(m.get('orientation_deg'))} deg (pooled median "
             f"{_f(p.get('orientation_deg', float('nan')))}) |",
             "| ... the body's tilt toward / away from the camera, per clip (median of the "
             "clips' absolute median tilt; what a camera pitch hides from the 2D) | "
             f"{_f(m.get('tilt_bias_deg'))} deg; MPJPE with each clip's median tilt taken out "
             f"(an oracle): {_f(m.get('tilt_free_mpjpe'))} mm |",
             f"| lifter MRPE (pelvis position) | {_f(m.get('mrpe'))} mm |",
             f"| lifter MBLE (bone lengths) | {_f(m.get('mble'))} mm |",
             f"| left/right leg swaps | {_f(100 * m.get('swap_rate', float('nan')), '{:.2f}')} "
             f"% of frames (pooled {_f(100 * p['swap_rate'], '{:.2f}')} %) |",
             "| ... the detector's own 2D leg swaps (pooled) | "
             f"{_f(100 * p.get('detector_swap_rate', float('nan')), '{:.2f}')} % of frames |",
             f"| jitter: lifter / ground truth | {_f(m.get('jitter'))} / "
             f"{_f(m.get('jitter_gt'))} m/s² (ratio {_f(m.get('jitter_ratio'), '{:.2f}')}×) |",
             f"| physics root trajectory error | {_f(m.get('physics_root_error'))} mm "
             f"(RTE {_f(m.get('physics_rte'))} %) |",
             f"| world root trajectory error | {_f(m.get('world_root_error'))} mm "
             f"(RTE {_f(m.get('world_rte'))} %) |",
             "| world joints, 100-frame pieces aligned whole / by their first two frames "
             f"(WA-MPJPE100 / W-MPJPE100) | {_f(m.get('world_wa_mpjpe100'))} / "
             f"{_f(m.get('world_w_mpjpe100'))} mm |",
             "| world root error against the true world, no alignment (meaningful with a "
             f"known camera pose) | {_f(m.get('world_root_error_unaligned'))} mm "
             f"(along the floor {_f(m.get('world_root_error_unaligned_horizontal'))}, up "
             f"{_f(m.get('world_root_error_unaligned_vertical'))}; the lifter's root moved "
             f"by the true camera pose: {_f(m.get('world_lifter_root_error_horizontal'))} / "
             f"{_f(m.get('world_lifter_root_error_vertical'))}) |",
             "| physics floor estimate against the true floor: tilt / height under the person, "
             f"at 1 s | {_f(m.get('physics_floor_tilt_1s_deg'))} deg / "
             f"{_f(m.get('physics_floor_height_1s_mm'))} mm |",
             "| ... after the first second (median over frames) | "
             f"{_f(m.get('physics_floor_tilt_deg'))} deg / "
             f"{_f(m.get('physics_floor_height_mm'))} mm |",
             *[f"| {st} PA-MPJPE | {_f(m.get(f'{st}_pa_mpjpe'))} mm (change from the lifter "
               f"on the same frames {_f(m.get(f'{st}_pa_mpjpe_change'), '{:+.1f}')} mm; "
               f"jitter {_f(m.get(f'{st}_jitter_vs_lifter'), '{:.2f}')}× the lifter's, "
               f"{_f(m.get(f'{st}_jitter_vs_truth'), '{:.2f}')}× the truth's) |"
               for st in ('physics', 'world')],
             *[f"| {st} feet: deepest ankle/toe joint below its own floor after 1 s / "
               f"frames more than 5 mm below / skating in contact | "
               f"{_f(m.get(f'{st}_penetration_after_1s_mm'))} mm / "
               f"{_f(100 * m.get(f'{st}_frames_below_5mm', float('nan')))} % / "
               f"{_f(m.get(f'{st}_skating_mm'))} mm per frame |" for st in ('physics', 'world')],
             *[f"| {st} body fallen over (tilted more than {FALLEN_TILT_DEG:g} deg from its "
               f"floor's up while the truth stands within {UPRIGHT_TILT_DEG:g}): clips with "
               f"any such frame / with more than 10 % / mean share of frames | "
               f"{p.get(f'{st}_fallen_clips', '-')} / "
               f"{p.get(f'{st}_fallen_clips_10pct', '-')} / "
               f"{_f(100 * p.get(f'{st}_fallen', float('nan')))} % |"
               for st in ('physics', 'world')],
             "| physics feet skating in contact in the true world (its joints mapped by its own "
             "floor and the true camera pose: comparable across cameras; the floor frame rides "
             f"with the camera) | {_f(m.get('physics_skating_world_mm'))} mm per frame |",
             f"| person detected | {_f(100 * m.get('detected', float('nan')))} % of frames |",
             *([f"| live: frames that reached the keypoint output / the world output (the "
                f"rest dropped as the detector fell behind) | "
                f"{_f(100 * m['live_keypoint_share'], '{:.0f}')} % / "
                f"{_f(100 * m.get('live_world_share', float('nan')), '{:.0f}')} % |"]
               if 'live_keypoint_share' in m else []),
             '', '## By view (pooled over frames)', '',
             '| view | frames | MPJPE | RA-MPJPE | PA-MPJPE | orientation error (deg, '
             'median) | leg swaps | detector leg swaps (2D) |',
             '|---|---|---|---|---|---|---|---|']
    for v, r in agg['by_view'].items():
        lines.append(f"| {v} | {r['frames']} | {_f(r['mpjpe'])} | "
                     f"{_f(r.get('ra_mpjpe', float('nan')))} | {_f(r['pa_mpjpe'])} | "
                     f"{_f(r.get('orientation_deg', float('nan')))} | "
                     f"{_f(100 * r['swap_rate'], '{:.2f}')} % | "
                     f"{_f(100 * r.get('detector_swap_rate', float('nan')), '{:.2f}')} % |")
    for name, label in (('by_group', 'motion group'), ('by_height', 'body height'),
                        ('by_camera', 'camera')):
        lines += ['', f'## By {label} (median over clips)', '',
                  f'| {label} | clips | MPJPE | PA-MPJPE | leg swaps | jitter ratio | '
                  'detected | physics root | world root | feet below floor after 1 s, '
                  'physics / world (mm) |',
                  '|---|---|---|---|---|---|---|---|---|---|']
        for g, r in agg[name].items():
            lines.append(
                f"| {g} | {r['clips']} | {_f(r['mpjpe'])} | {_f(r['pa_mpjpe'])} | "
                f"{_f(100 * r['swap_rate'], '{:.2f}')} % | {_f(r['jitter_ratio'], '{:.2f}')} | "
                f"{_f(100 * r['detected'], '{:.0f}')} % | {_f(r['physics_root_error'], '{:.0f}')}"
                f" | {_f(r['world_root_error'], '{:.0f}')} | "
                f"{_f(r.get('physics_penetration_after_1s_mm'))} / "
                f"{_f(r.get('world_penetration_after_1s_mm'))} |")
    if agg.get('by_pitch'):
        lines += ['', '## By how far the camera looks up or down (median over clips)', '',
                  "The body's tilt toward or away from the camera is what the keypoints "
                  "hardly show of the camera's pitch (docs/lifter.md, \"What the keypoints "
                  'cannot tell"); the tilt here is the median of the clips\' absolute median '
                  'tilt.', '',
                  '| camera pitch | clips | MPJPE | PA-MPJPE | tilt (deg) | leg swaps |',
                  '|---|---|---|---|---|---|']
        for g in PITCH_CLASSES:
            r = agg['by_pitch'].get(g)
            if r:
                lines.append(f"| {g} | {r['clips']} | {_f(r['mpjpe'])} | {_f(r['pa_mpjpe'])}"
                             f" | {_f(r.get('tilt_bias_deg', float('nan')))} | "
                             f"{_f(100 * r['swap_rate'], '{:.2f}')} % |")
    cams = agg.get('by_camera', {})
    if any(np.isfinite(r.get(k, float('nan'))) for r in cams.values()
           for k in ('camera_state_static', 'world_root_error')):
        lines += ['', '## World frame and camera motion by camera kind (median over clips)',
                  '', 'RTE: root error after rigid alignment of the whole clip over the '
                  'distance travelled (clips that travel at least '
                  f'{RTE_MIN_TRAVEL_M:g} m). Camera motion: the estimate from the video '
                  'background (`mocap_core.camera_motion`), the share of frames in each '
                  'state and the median error of its frame-to-frame rotation.', '',
                  '| camera | clips | world RTE | world root error (mm) | WA-MPJPE100 / '
                  'W-MPJPE100 (mm) | static | rotating | moving | unknown | rotation error '
                  '(deg/s) |',
                  '|---|---|---|---|---|---|---|---|---|---|']
        for g, r in cams.items():
            lines.append(
                f"| {g} | {r['clips']} | {_f(r.get('world_rte'))} % | "
                f"{_f(r.get('world_root_error'), '{:.0f}')} | "
                f"{_f(r.get('world_wa_mpjpe100'), '{:.0f}')} / "
                f"{_f(r.get('world_w_mpjpe100'), '{:.0f}')} | "
                + ' | '.join(f"{_f(100 * r.get(f'camera_state_{k}', float('nan')), '{:.0f}')} %"
                             for k in ('static', 'rotating', 'moving', 'unknown'))
                + f" | {_f(r.get('camera_rotation_error_deg_s'), '{:.2f}')} |")
    floors = agg.get('moving_by_floor') or {}
    if floors:
        lines += ['', '## Moving cameras by the floor\'s texture (median over clips)', '',
                  'What the camera-motion estimate can track: a floor of straight stripes or '
                  'a smooth gradient has no corners (docs/global.md, "What the camera-motion '
                  'estimate could not see"); its frames are `unknown` unless the walls have '
                  'some. Rotation error over the frames with an estimate; drift: the '
                  'orientation error at the end.', '',
                  '| floor | clips | rotation error (deg/s) | drift (deg) | unknown | world RTE '
                  '| world skating (mm/frame) |', '|---|---|---|---|---|---|---|']
        for g, r in floors.items():
            lines.append(
                f"| {g} | {r['clips']} | {_f(r.get('camera_rotation_error_deg_s'), '{:.2f}')}"
                f" | {_f(r.get('camera_drift_deg'))} | "
                f"{_f(100 * r.get('camera_state_unknown', float('nan')), '{:.0f}')} % | "
                f"{_f(r.get('world_rte'))} % | {_f(r.get('world_skating_mm'))} |")
    by_state = agg.get('world_skating_by_camera_state') or {}
    if by_state:
        lines += ['', '## World skating by the camera-motion estimate (pooled over frames)', '',
                  'What the world stage does with a frame depends on the estimate: static '
                  'frames follow the physics output (static-camera fusion), frames whose '
                  'camera position was measured over the floor are pulled towards it, the '
                  'others are GMR\'s with the foot lock. Ankle and toe joints while the '
                  'ground truth says that heel or toe is on the floor.', '',
                  '| camera-motion estimate | steps | world skating (mm/frame) |',
                  '|---|---|---|']
        for g, r in by_state.items():
            lines.append(f"| {g} | {r['steps']} | {_f(r['mm'])} |")
    return '\n'.join(lines) + '\n'


#: Rows of :func:`comparison_markdown`: (label, median key, format).
COMPARISON_ROWS = (
    ('live: frames that reached the keypoint output (%)', 'live_keypoint_share', 'pct'),
    ('live: frames that reached the world output (%)', 'live_world_share', 'pct'),
    ('lifter MPJPE (mm)', 'mpjpe', '{:.1f}'),
    ('lifter PA-MPJPE (mm)', 'pa_mpjpe', '{:.1f}'),
    ('lifter RA-MPJPE: rigidly aligned, no scale (mm)', 'ra_mpjpe', '{:.1f}'),
    ('lifter global orientation error (deg)', 'orientation_deg', '{:.1f}'),
    ('lifter tilt toward/away from the camera, per clip (deg)', 'tilt_bias_deg', '{:.1f}'),
    ("lifter MPJPE, each clip's median tilt taken out (oracle, mm)", 'tilt_free_mpjpe',
     '{:.1f}'),
    ('lifter MRPE: pelvis position in the camera frame (mm)', 'mrpe', '{:.0f}'),
    ("lifter jitter / the truth's", 'jitter_ratio', '{:.2f}'),
    ('physics PA-MPJPE change from the lifter, same frames (mm)', 'physics_pa_mpjpe_change',
     '{:+.1f}'),
    ('world PA-MPJPE change from the lifter, same frames (mm)', 'world_pa_mpjpe_change',
     '{:+.1f}'),
    ("physics jitter / the lifter's", 'physics_jitter_vs_lifter', '{:.2f}'),
    ("physics jitter / the truth's", 'physics_jitter_vs_truth', '{:.2f}'),
    ("world jitter / the lifter's", 'world_jitter_vs_lifter', '{:.2f}'),
    ("world jitter / the truth's", 'world_jitter_vs_truth', '{:.2f}'),
    ("world jitter / the lifter's, lifter in its moving camera frame",
     'world_jitter_vs_lifter_camera_frame', '{:.2f}'),
    ('physics feet: deepest ankle/toe below its floor after 1 s (mm)',
     'physics_penetration_after_1s_mm', '{:.1f}'),
    ('world feet: deepest ankle/toe below its floor after 1 s (mm)',
     'world_penetration_after_1s_mm', '{:.1f}'),
    ('world frames with a foot joint > 5 mm below the floor (%)', 'world_frames_below_5mm',
     'pct'),
    ('physics skating in contact (mm/frame)', 'physics_skating_mm', '{:.1f}'),
    ('physics skating in contact, in the true world (mm/frame)', 'physics_skating_world_mm',
     '{:.1f}'),
    ('world skating in contact (mm/frame)', 'world_skating_mm', '{:.1f}'),
    ('physics root trajectory error (mm)', 'physics_root_error', '{:.0f}'),
    ('world root trajectory error (mm)', 'world_root_error', '{:.0f}'),
    ('world RTE (%)', 'world_rte', '{:.1f}'),
    ('world joints, 100-frame pieces aligned whole: WA-MPJPE100 (mm)', 'world_wa_mpjpe100',
     '{:.0f}'),
    ('... aligned by their first two frames: W-MPJPE100 (mm)', 'world_w_mpjpe100', '{:.0f}'),
    ('world root error, no alignment (meaningful with a known camera pose, mm)',
     'world_root_error_unaligned', '{:.0f}'),
    ('... along the floor (mm)', 'world_root_error_unaligned_horizontal', '{:.0f}'),
    ('... up (mm)', 'world_root_error_unaligned_vertical', '{:.0f}'),
    ("the lifter's root moved by the true camera pose: error along the floor (mm)",
     'world_lifter_root_error_horizontal', '{:.0f}'),
    ("... up (mm)", 'world_lifter_root_error_vertical', '{:.0f}'),
    ('physics floor at 1 s: tilt (deg)', 'physics_floor_tilt_1s_deg', '{:.1f}'),
    ('physics floor at 1 s: height under the person (mm)', 'physics_floor_height_1s_mm',
     '{:.0f}'),
)


def comparison_markdown(reports: Sequence[Tuple[str, dict]], title: str,
                        setup: Sequence[str] = ()) -> str:
    """One table comparing runs of the video benchmark side by side: ``reports`` are
    ``(name, report.json contents)`` of runs over the same clips; medians over clips."""
    names = [n for n, _ in reports]
    lines = [f'# {title}', '', *setup, '',
             '| measure (median over clips) | ' + ' | '.join(names) + ' |',
             '|---|' + '---|' * len(names)]
    lines.append('| clips scored | ' + ' | '.join(str(r['aggregate']['clips'])
                                                 for _, r in reports) + ' |')
    for label, key, fmt in COMPARISON_ROWS:
        if key.startswith('live_') and not any(key in r['aggregate']['median']
                                               for _, r in reports):
            continue                                    # no live run among them
        cells = []
        for _, r in reports:
            v = r['aggregate']['median'].get(key, float('nan'))
            cells.append(_f(100 * v, '{:.1f}') if fmt == 'pct' else _f(v, fmt))
        lines.append(f'| {label} | ' + ' | '.join(cells) + ' |')
    return '\n'.join(lines) + '\n'
