"""Evaluation of GMR on held-out clips (``mocap eval gmr``; no ROS imports).

Every validation clip is run at the model's frame rate in three ways:

* ``offline``: one pass of the bidirectional GRU over the whole clip (§3.6: any length);
* ``online``: exactly what the node computes: the motion into frame k from the window of
  ``window`` frames ending ``lookahead`` frames after k (shorter windows at the start of a
  clip, fewer future frames at its end, as the node's start-up and flush);
* ``causal``: the same with ``lookahead = 0``.

Inputs: ``none`` = ground-truth local poses and bone lengths; ``lifter`` = lifter-like noisy
ones (:func:`mocap_global.features.noisy_local_pose`, an assumed noise model, seeded per
clip); ``lifted`` = the shipped lifter's own output for each clip seen from one random camera
(detector placement and corruption; :mod:`.lifted`, seeded apart from training).
Metrics (:mod:`.metrics`): OME, TME and joint motion error per step at the model rate and,
for a 30 fps model, at 10 fps (three 30 fps motions composed, the paper's rate, Table 4);
tilt error of the estimated up direction; drift after 1, 5 and 10 s, RTE and ATE of the
accumulated trajectory. Baselines on the same clips: zero motion, and a constant velocity
equal to each clip's mean ground-truth motion (an oracle: it knows the true average speed and
turn rate).

Static-camera fusion (:class:`mocap_global.online.StaticCameraFusion`): on the validation clips
with a simulated static camera whose root measurements carry lifter-like errors (depth noise
and scale error, see :data:`ROOT_NOISE`), and on the committed ground-truth bags through
:class:`mocap_global.online.OnlineGMR` itself (the node's code), GMR alone vs fused vs the
measurement alone, as ATE (4-DOF aligned) and root jitter.
"""

from __future__ import annotations

import json
import zlib
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np
import torch

from mocap_core.data.motion import Motion, retime
from mocap_core.rotations import (axis_angle_to_matrix, matrix_to_axis_angle, matrix_to_quat,
                                  quat_to_matrix)

from mocap_core.data.gt_bag import read_groundtruth_bag
from ..features import (body_joint_positions, gmr_features, noisy_lengths, noisy_local_pose,
                        _smooth_noise)
from ..model import GMR
from ..online import OnlineGMR, StaticCameraFusion
from ..se3 import compose_steps, relative_motion, up_in_body
from . import metrics as M
from .samples import frame_step

#: The node's default window (frames per GRU pass), used by the online and causal rows.
NODE_WINDOW = 48
DRIFT_SECONDS = (1, 5, 10)
#: Tilt correction (fraction per frame) of the "GMR + tilt correction" rows.
TILT_CORRECTION = 0.05
#: Simulated errors of the camera-frame root (static-camera fusion evaluation): depth error
#: std 0.10 m varying over ~0.5 s plus 0.02 m jitter, a per-clip depth scale error of std 5 %,
#: lateral error 0.02 m (+ 0.01 m jitter), root orientation error 5 deg (+ 2 deg jitter).
ROOT_NOISE = {'depth_m': 0.10, 'depth_jitter_m': 0.02, 'depth_scale': 0.05,
              'lateral_m': 0.02, 'lateral_jitter_m': 0.01, 'orientation_deg': 5.0,
              'orientation_jitter_deg': 2.0, 'correlation_s': 0.5}


def clip_seed(name: str) -> int:
    return zlib.crc32(name.encode()) & 0x7FFFFFFF


# ---------------------------------------------------------------------------------------------
# inference
# ---------------------------------------------------------------------------------------------
@torch.no_grad()
def predict_clip(model: GMR, feats: np.ndarray, lookahead: Optional[int],
                 device: str = 'cpu', batch: int = 256,
                 window: Optional[int] = None) -> Dict[str, np.ndarray]:
    """Network outputs for one clip's (F, C) features as the node would compute them.

    Returns ``axis_angle`` and ``translation`` (F-1, 3): motion i -> i+1, from the window
    ending at frame ``min(F-1, i+1+lookahead)``; ``up`` (F, 3): frame k's up direction from
    the window ending at ``min(F-1, k+lookahead)``. ``lookahead=None``: one pass over the
    whole clip. ``window``: frames per window (default: the model's training window)."""
    f = len(feats)
    x = torch.as_tensor(feats, device=device)
    if lookahead is None:
        out = model(x[None])
        o = {k: v[0].cpu().numpy().astype(np.float64) for k, v in out.items()}
        return {'axis_angle': o['axis_angle'][:-1], 'translation': o['translation'][:-1],
                'up': o['up']}
    w = int(window or model.cfg.window)
    ends = np.arange(min(lookahead, f - 1), f)            # every window the node runs
    starts = np.maximum(0, ends - w + 1)
    lengths = ends - starts + 1
    idx = np.minimum(starts[:, None] + np.arange(w)[None], f - 1)
    res = {'axis_angle': np.zeros((len(ends), w, 3)), 'translation': np.zeros((len(ends), w, 3)),
           'up': np.zeros((len(ends), w, 3))}
    for a in range(0, len(ends), batch):
        sl = slice(a, a + batch)
        out = model(x[torch.as_tensor(idx[sl])], torch.as_tensor(lengths[sl]))
        for k in res:
            res[k][sl] = out[k].cpu().numpy()
    row_of_end = {int(e): r for r, e in enumerate(ends)}
    i = np.arange(f - 1)
    r = np.array([row_of_end[int(min(f - 1, j + 1 + lookahead))] for j in i])
    aa = res['axis_angle'][r, i - starts[r]]
    tr = res['translation'][r, i - starts[r]]
    k = np.arange(f)
    ru = np.array([row_of_end[int(min(f - 1, max(j + lookahead, ends[0])))] for j in k])
    up = res['up'][ru, k - starts[ru]]
    return {'axis_angle': aa, 'translation': tr, 'up': up}


#: clip name -> :class:`~.lifted.LiftedClip` of the validation clips (:func:`lift_validation`)
LIFTED: Dict = {}
#: seed of the validation cameras (the training run's lifted clips use the run's seed, 0)
LIFTED_SEED = 1001


def lift_validation(motions: Sequence[Motion], progress: bool = False) -> None:
    """Lift every clip once (one random camera; cached) for the ``lifted`` input."""
    from .lifted import lift_clips
    todo = [m for m in motions if m.name not in LIFTED]
    if todo:
        for m, c in zip(todo, lift_clips(todo, 1, LIFTED_SEED, progress=progress)):
            LIFTED[m.name] = c


def clip_arrays(m: Motion, fps: float, noise: str, root_input: str = 'none',
                skeleton_input: bool = True, pose_input: str = 'quat') -> Dict:
    """Ground truth and (possibly noisy) input of one clip at the model rate."""
    step = frame_step(m.fps, fps)
    rot = np.asarray(m.rotations[::step], dtype=np.float64)
    root = np.asarray(m.root_positions[::step], dtype=np.float64)
    R = quat_to_matrix(rot[:, 0])
    gl = m.skeleton.group_lengths()
    rot_in, gl_in = rot, gl
    if noise == 'lifter':
        rng = np.random.default_rng(clip_seed(m.name))
        rot_in = noisy_local_pose(rot, rng, fps)
        gl_in = noisy_lengths(gl, rng)
    elif noise == 'lifted':
        if m.name not in LIFTED:
            raise ValueError(f'{m.name}: no lifted poses (lift_validation first)')
        c = LIFTED[m.name]
        rot_in = np.asarray(c.rotations[0][::step], dtype=np.float64)
        gl_in = np.asarray(c.lengths[0], dtype=np.float64)
    elif noise != 'none':
        raise ValueError(f"noise must be 'none', 'lifter' or 'lifted', got {noise!r}")
    up = up_in_body(R)
    feats = gmr_features(rot_in, gl_in, up if root_input == 'up' else None, root_input,
                         skeleton_input, pose_input)
    dR, dT = relative_motion(R, root)
    return {'rot': rot, 'root': root, 'R': R, 'dR': dR, 'dT': dT, 'up': up, 'features': feats,
            'joints': body_joint_positions(m.skeleton.offsets, rot), 'fps': fps}


def _predict_cached(model, c, name, noise, lookahead, device, cache, window=None):
    key = (name, noise, lookahead, window)
    if cache is not None and key in cache:
        return cache[key]
    pred = predict_clip(model, c['features'], lookahead, device, window=window)
    if cache is not None:
        cache[key] = pred
    return pred


def _input_options(model: Optional[GMR]):
    if model is None:
        return 'none', True, 'quat'
    return model.cfg.root_input, model.cfg.skeleton_input, model.cfg.pose_input


def _mean_motion(c: Dict) -> Dict[str, np.ndarray]:
    n = len(c['dR'])
    aa = matrix_to_axis_angle(c['dR']).mean(axis=0)
    return {'axis_angle': np.broadcast_to(aa, (n, 3)).copy(),
            'translation': np.broadcast_to(c['dT'].mean(axis=0), (n, 3)).copy(),
            'up': np.broadcast_to(np.array([0.0, 0.0, 1.0]), (n + 1, 3)).copy()}


def _zero_motion(c: Dict) -> Dict[str, np.ndarray]:
    n = len(c['dR'])
    return {'axis_angle': np.zeros((n, 3)), 'translation': np.zeros((n, 3)),
            'up': np.broadcast_to(np.array([0.0, 0.0, 1.0]), (n + 1, 3)).copy()}


# ---------------------------------------------------------------------------------------------
# metrics over clips
# ---------------------------------------------------------------------------------------------
class _Acc:
    """Sums of per-step errors and lists of drift / trajectory values."""

    def __init__(self) -> None:
        self.sums: Dict[str, float] = {}
        self.counts: Dict[str, int] = {}
        self.lists: Dict[str, List[float]] = {}

    def add_steps(self, key: str, values: np.ndarray) -> None:
        self.sums[key] = self.sums.get(key, 0.0) + float(np.sum(values))
        self.counts[key] = self.counts.get(key, 0) + int(np.size(values))

    def add_list(self, key: str, values) -> None:
        v = np.atleast_1d(np.asarray(values, dtype=np.float64))
        self.lists.setdefault(key, []).extend(v[np.isfinite(v)].tolist())

    def summary(self) -> Dict[str, float]:
        s = {k: self.sums[k] / max(self.counts[k], 1) for k in self.sums}
        for k, v in self.lists.items():
            s[k] = float(np.mean(v)) if v else float('nan')
            s[k + '_count'] = len(v)
        return s


def score_clip(c: Dict, pred: Dict[str, np.ndarray], acc: _Acc, fps: float) -> Dict:
    """Add one clip's errors to ``acc``; returns its per-clip row."""
    dR = axis_angle_to_matrix(pred['axis_angle'])
    dT = pred['translation']
    ome = M.ome_deg(dR, c['dR'])
    tme = M.tme_mm(dT, c['dT'])
    jme = M.jme_mm(dR, dT, c['dR'], c['dT'], c['joints'][1:])
    acc.add_steps('ome_deg', ome)
    acc.add_steps('tme_mm', tme)
    acc.add_steps('jme_mm', jme)
    cos = np.clip(np.sum(pred['up'] * c['up'], axis=-1), -1.0, 1.0)
    acc.add_steps('tilt_deg', np.degrees(np.arccos(cos)))
    row = {'frames': len(c['R']), 'ome_deg': float(ome.mean()), 'tme_mm': float(tme.mean()),
           'jme_mm': float(jme.mean())}
    if round(fps) == 30:                     # the paper's 10 fps: three motions composed
        k = 3
        R10, T10 = compose_steps(dR, dT, k)
        G10R, G10T = compose_steps(c['dR'], c['dT'], k)
        if len(R10):
            j10 = c['joints'][k::k][:len(R10)]
            acc.add_steps('ome10_deg', M.ome_deg(R10, G10R))
            acc.add_steps('tme10_mm', M.tme_mm(T10, G10T))
            acc.add_steps('jme10_mm', M.jme_mm(R10, T10, G10R, G10T, j10))
    f = int(round(fps))
    drift = M.drift_mm(dR, dT, c['R'], c['root'], [s * f for s in DRIFT_SECONDS], f)
    for s in DRIFT_SECONDS:
        acc.add_list(f'drift_{s}s_mm', drift[s * f])
    traj = M.trajectory_errors(dR, dT, c['R'], c['root'])
    acc.add_list('rte_pct', traj['rte_pct'])
    acc.add_list('ate_mm', traj['ate_mm'])
    row.update({k: traj[k] for k in ('rte_pct', 'ate_mm', 'distance_m')})
    return row


def evaluate(model: Optional[GMR], motions: Sequence[Motion], noise: str = 'none',
             lookahead: Optional[int] = 15, device: str = 'cpu', fps: Optional[float] = None,
             predictor: Optional[Callable[[Dict], Dict]] = None,
             cache: Optional[Dict] = None, window: Optional[int] = None) -> Dict:
    """Metrics of the model (or of ``predictor(clip arrays)``, a baseline) over clips.
    ``cache``: a dict that keeps the model's predictions per (clip, noise, look-ahead);
    ``window``: frames per GRU pass of the online modes (default: the training window)."""
    fps = float(fps or model.cfg.fps)
    acc = _Acc()
    rows = []
    for m in motions:
        c = clip_arrays(m, fps, noise, *_input_options(model))
        if len(c['R']) < 3:
            continue
        if predictor is not None:
            pred = predictor(c)
        else:
            pred = _predict_cached(model, c, m.name, noise, lookahead, device, cache, window)
        row = score_clip(c, pred, acc, fps)
        row['clip'] = m.name
        rows.append(row)
    return {'noise': noise, 'lookahead': lookahead, 'fps': fps, 'clips': len(rows),
            'frames': int(sum(r['frames'] for r in rows)), 'summary': acc.summary(),
            'per_clip': rows}


# ---------------------------------------------------------------------------------------------
# static-camera fusion
# ---------------------------------------------------------------------------------------------
def simulate_root_measurement(R: np.ndarray, T: np.ndarray, fps: float,
                              rng: np.random.Generator, noise: Dict = ROOT_NOISE,
                              frame: Optional[tuple] = None,
                              camera_position: Optional[np.ndarray] = None):
    """Root poses (F, 3, 3), (F, 3) as a static camera's lifter would measure them: errors
    of :data:`ROOT_NOISE` with the depth along the line of sight of a camera 4 m away, and
    expressed in a random rigid frame (or ``frame`` = (C, c): x_in = C x + c); the camera at
    ``camera_position`` (world) if given.
    Returns (R_in, T_in)."""
    f = len(T)
    corr = noise['correlation_s'] * fps
    start = T[0]
    yaw = rng.uniform(-np.pi, np.pi)
    cam_pos = start + 4.0 * np.array([np.cos(yaw), np.sin(yaw), 0.0])
    cam_pos[2] = 1.5
    if camera_position is not None:
        cam_pos = np.asarray(camera_position, dtype=np.float64)
    d = T - cam_pos
    d[:, 2] = 0.0
    d /= np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-6)   # viewing directions
    lat = np.stack([-d[:, 1], d[:, 0], np.zeros(f)], axis=-1)
    scale = 1.0 + noise['depth_scale'] * rng.standard_normal()
    depth = np.sum((T - cam_pos) * d, axis=-1)
    dn = (noise['depth_m'] * _smooth_noise(rng, (f,), corr)
          + noise['depth_jitter_m'] * rng.standard_normal(f) + (scale - 1.0) * depth)
    ln = (noise['lateral_m'] * _smooth_noise(rng, (f,), corr)
          + noise['lateral_jitter_m'] * rng.standard_normal(f))
    T_meas = T + dn[:, None] * d + ln[:, None] * lat
    v = (np.radians(noise['orientation_deg']) * _smooth_noise(rng, (f, 3), corr)
         + np.radians(noise['orientation_jitter_deg']) * rng.standard_normal((f, 3)))
    R_meas = R @ axis_angle_to_matrix(v)
    if frame is None:   # a fixed, arbitrary rigid transform of the world
        frame = (axis_angle_to_matrix(rng.normal(size=3)), rng.normal(size=3))
    C, c = frame
    return C @ R_meas, T_meas @ C.T + c


def fuse_sequence(R0, T0, dR, dT, up, R_in, T_in, fusion: Optional[StaticCameraFusion]):
    """Accumulate motions from (R0, T0) with an optional fusion filter (the node's order of
    operations; ``up`` (F, 3) GMR's up estimates): returns world R (F, 3, 3), T (F, 3)."""
    n = len(dR) + 1
    R = np.empty((n, 3, 3))
    T = np.empty((n, 3))
    R[0], T[0] = R0, T0
    if fusion is not None:
        fusion.reset()
        R[0], T[0], _ = fusion.step(R0, T0, R_in[0], T_in[0], up[0], first=True)
    for i in range(1, n):
        Ri = R[i - 1] @ dR[i - 1]
        Ti = R[i - 1] @ dT[i - 1] + T[i - 1]
        if fusion is not None:
            Ri, Ti, _ = fusion.step(Ri, Ti, R_in[i], T_in[i], up[i])
        R[i], T[i] = Ri, Ti
    return R, T


def _jitter_mm(T: np.ndarray) -> float:
    return float(1000 * np.linalg.norm(np.diff(T, 2, axis=0), axis=-1).mean()) \
        if len(T) > 2 else float('nan')


def evaluate_fusion(model: GMR, motions: Sequence[Motion], noise: str, lookahead: int,
                    device: str = 'cpu', min_seconds: float = 3.0,
                    cache: Optional[Dict] = None, window: Optional[int] = None) -> Dict:
    """GMR alone vs fused with a simulated static camera vs the measurement alone, on clips
    of at least ``min_seconds``: ATE (mm, 4-DOF aligned), final error after alignment,
    jitter (mm/frame^2)."""
    fps = model.cfg.fps
    res: Dict[str, List[float]] = {}
    clips = 0
    for m in motions:
        c = clip_arrays(m, fps, noise, *_input_options(model))
        if len(c['R']) < min_seconds * fps:
            continue
        clips += 1
        pred = _predict_cached(model, c, m.name, noise, lookahead, device, cache, window)
        dR = axis_angle_to_matrix(pred['axis_angle'])
        rng = np.random.default_rng(clip_seed(m.name) + 1)
        C = axis_angle_to_matrix(rng.normal(size=3))
        R_in, T_in = simulate_root_measurement(c['R'], c['root'], fps, rng,
                                               frame=(C, rng.normal(size=3)))
        args = (c['R'][0], c['root'][0], dR, pred['translation'], pred['up'], R_in, T_in)
        _, T_gmr = fuse_sequence(*args, None)
        _, T_fused = fuse_sequence(*args, StaticCameraFusion(fps))
        _, T_known = fuse_sequence(*args, StaticCameraFusion(fps, input_up=C[:, 2]))
        for name, T in (('gmr', T_gmr), ('fused', T_fused), ('fused_known_up', T_known),
                        ('measurement', T_in)):
            if name == 'measurement':     # rigid alignment (any rotation) of the camera frame
                T = _rigid_align(T, c['root'])
            res.setdefault(f'{name}_ate_mm', []).append(M.ate_mm(T, c['root']))
            res.setdefault(f'{name}_jitter_mm', []).append(_jitter_mm(T))
    out = {k: float(np.mean(v)) for k, v in res.items()}
    out['clips'] = clips
    return out


def _rigid_align(P: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """P mapped onto Q by the best rotation + translation (Kabsch)."""
    pc, qc = P.mean(0), Q.mean(0)
    u, _, vt = np.linalg.svd((P - pc).T @ (Q - qc))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    R = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return (P - pc) @ R.T + qc


def lifter_poses(keypoints: np.ndarray, intrinsics) -> Optional[tuple]:
    """The shipped MotioNet lifter (windowed) on a keypoint sequence, one pass, with the
    node's virtual camera (``virtual_camera``): (rotations (T, J, 4) with the root in the
    camera frame, root positions (T, 3), bone-group lengths (10,)), or None when the lifter
    or its weights are not installed."""
    try:
        from mocap_lifter.features import lifter_features
        from mocap_lifter.online import DEFAULT_VIRTUAL_CAMERA
        from mocap_lifter.training.evaluate import lift
        from mocap_lifter.weights import default_weights
        from mocap_lifter.weights import load_weights as load_lifter
    except ImportError:
        return None
    path = default_weights('windowed')
    if not path.exists():
        return None
    lifter = load_lifter(path)
    feats, root, scale, _ = lifter_features(keypoints, intrinsics)
    out = lift(lifter, feats, root.astype(np.float32), scale.astype(np.float32),
               virtual_camera=DEFAULT_VIRTUAL_CAMERA)
    return (out['rotations'].astype(np.float64), out['root'].astype(np.float64),
            out['lengths'].astype(np.float64))


def evaluate_bags(model: GMR, bags: Sequence[Path], noise: str, lookahead: int,
                  device: str = 'cpu', window: Optional[int] = None) -> List[Dict]:
    """The node's algorithm (:class:`mocap_global.online.OnlineGMR`) on committed ground-truth bags
    (static camera), at the model's rate (a 30 fps bag is subsampled for a 10 fps
    model): world root ATE (4-DOF aligned) and tilt error of GMR alone and fused with
    the camera-frame root. ``noise``: 'none' (ground truth), 'lifter' (simulated lifter-like
    errors) or 'motionet' (the shipped MotioNet lifter run on the bag's keypoints: its local
    poses, skeleton and camera-frame root; skipped when it is not installed)."""
    from mocap_core.pose import Pose
    from mocap_core.rotations import quat_angle
    from mocap_core.skeleton import Skeleton

    rows = []
    for path in bags:
        b = read_groundtruth_bag(path)
        Rc, tc = b['camera']
        # the bag's rate -> the model's (every third frame for a 10 fps model)
        bag_fps = 1e9 / float(np.median(np.diff(b['stamps'])))
        step = frame_step(round(bag_fps), model.cfg.fps)
        poses = b['poses'][::step]
        stamps = b['stamps'][::step]
        rot_c = np.stack([p.rotations for p in poses])
        root_c = np.stack([p.root_position for p in poses])
        R_cam = quat_to_matrix(rot_c[:, 0])
        Rw = Rc @ R_cam
        Tw = root_c @ Rc.T + tc
        skeletons = [p.skeleton for p in poses]
        row = {'bag': path.name, 'frames': len(poses), 'noise': noise}
        if noise == 'motionet':
            lifted = lifter_poses(b['keypoints'], b['intrinsics'])   # at the bag's rate
            if lifted is None:
                continue
            lifted = (lifted[0][::step], lifted[1][::step], lifted[2])
            row['local_rotation_error_deg'] = float(np.degrees(quat_angle(
                lifted[0][:, 1:], rot_c[:, 1:])).mean())
            rot_c, root_c = lifted[0], lifted[1]
            skeletons = [Skeleton.from_group_lengths(lifted[2])] * len(poses)
        elif noise == 'lifter':
            rng = np.random.default_rng(clip_seed(path.name))
            clean = rot_c
            rot_c = noisy_local_pose(rot_c, rng, model.cfg.fps)
            row['local_rotation_error_deg'] = float(np.degrees(quat_angle(
                rot_c[:, 1:], clean[:, 1:])).mean())
            R_m, T_m = simulate_root_measurement(Rw, Tw, model.cfg.fps, rng,
                                                 frame=(Rc.T, -Rc.T @ tc), camera_position=tc)
            rot_c[:, 0] = matrix_to_quat(R_m)
            root_c = T_m
        up_cam = Rc.T @ np.array([0.0, 0.0, 1.0])       # the camera's up, as if calibrated
        for name, fusion, tilt in (
                ('gmr', None, 0.0), ('gmr_tilt', None, TILT_CORRECTION),
                ('fused', StaticCameraFusion(model.cfg.fps), 0.0),
                ('fused_known_up', StaticCameraFusion(model.cfg.fps, input_up=up_cam), 0.0)):
            online = OnlineGMR(model, lookahead=lookahead, window=window, fusion=fusion,
                               device=device, tilt_correction=tilt)
            frames = []
            for s, sk, r, t in zip(stamps, skeletons, rot_c, root_c):
                out, _ = online.push(s, Pose(sk, r, t))
                frames += out
            frames += online.flush()
            T = np.stack([f.pose.root_position for f in frames])
            R = quat_to_matrix(np.stack([f.pose.rotations[0] for f in frames]))
            cos = np.clip(np.sum(up_in_body(R) * up_in_body(Rw), axis=-1), -1, 1)
            row[f'{name}_ate_mm'] = M.ate_mm(T, Tw)
            row[f'{name}_tilt_deg'] = float(np.degrees(np.arccos(cos)).mean())
            row[f'{name}_jitter_mm'] = _jitter_mm(T)
        row['measurement_ate_mm'] = M.ate_mm(_rigid_align(root_c, Tw), Tw)
        rows.append(row)
    return rows


# ---------------------------------------------------------------------------------------------
# everything, and the report
# ---------------------------------------------------------------------------------------------
#: playback speeds of :func:`evaluate_speeds` (0.5: slow motion, or a gait at half its pace)
PLAYBACK_SPEEDS = (0.5, 0.7, 1.0, 1.4)
#: clips of :func:`evaluate_speeds`: at least 3 s that travel at least this far (m)
SPEED_MIN_TRAVEL_M = 1.5


def _travel_m(root: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(np.asarray(root)[:, :2], axis=0), axis=1).sum())


def evaluate_speeds(model: GMR, motions: Sequence[Motion],
                    noises: Sequence[str] = ('none', 'lifter'),
                    speeds: Sequence[float] = PLAYBACK_SPEEDS, lookahead: int = 15,
                    device: str = 'cpu', window: int = NODE_WINDOW) -> List[Dict]:
    """GMR online on the travelling clips (3 s or more, :data:`SPEED_MIN_TRAVEL_M` or more)
    played slower and faster (:func:`mocap_core.data.motion.retime`), input and truth alike.

    Returns one row per (speed, input): ``clips``, ``rte_pct`` (median over clips),
    ``step_ratio`` (median over clips of the predicted over the true horizontal path of
    the per-frame translations in the body frame: 1 = the right pace, 0 = on the spot) and
    its 10th percentile ``step_ratio_p10``, ``tme_mm`` (mean per step)."""
    clips = [m for m in motions if m.num_frames >= 3 * m.fps
             and _travel_m(m.root_positions) >= SPEED_MIN_TRAVEL_M]
    rows = []
    for speed in speeds:
        for noise in noises:
            rte, ratio, tme = [], [], []
            for m in clips:
                c = clip_arrays(retime(m, speed), float(model.cfg.fps), noise,
                                *_input_options(model))
                p = predict_clip(model, c['features'], lookahead, device, window=window)
                dR = axis_angle_to_matrix(p['axis_angle'])
                rte.append(M.trajectory_errors(dR, p['translation'], c['R'],
                                               c['root'])['rte_pct'])
                truth = np.linalg.norm(c['dT'][:, :2], axis=1).sum()
                ratio.append(np.linalg.norm(p['translation'][:, :2], axis=1).sum()
                             / max(truth, 1e-9))
                tme.append(M.tme_mm(p['translation'], c['dT']).mean())
            rows.append({'speed': float(speed), 'noise': noise, 'clips': len(clips),
                         'rte_pct': float(np.nanmedian(rte)) if rte else float('nan'),
                         'step_ratio': float(np.median(ratio)) if ratio else float('nan'),
                         'step_ratio_p10': float(np.percentile(ratio, 10)) if ratio
                         else float('nan'),
                         'tme_mm': float(np.mean(tme)) if tme else float('nan')})
    return rows


def evaluate_all(model: GMR, motions: Sequence[Motion], noises: Sequence[str] = ('none',),
                 lookahead: int = 15, device: str = 'cpu', bags: Optional[Sequence[Path]] = None,
                 progress: bool = False, window: int = NODE_WINDOW,
                 speeds: Sequence[float] = PLAYBACK_SPEEDS) -> Dict:
    """The full report: model modes x inputs, baselines, fusion, playback speeds
    (:func:`evaluate_speeds`; ``speeds`` empty: none)."""
    def say(msg):
        if progress:
            print(msg, flush=True)

    results = []
    cache: Dict = {}
    if 'lifted' in noises:
        say('lifting the validation clips ...')
        lift_validation(motions, progress)
    for noise in noises:
        for mode, la in (('offline', None), ('online', lookahead), ('causal', 0)):
            say(f'evaluating {mode} (look-ahead {la}), input {noise} ...')
            r = evaluate(model, motions, noise, la, device,
                         cache=cache if mode == 'online' else None, window=window)
            r['mode'] = mode
            results.append(r)
    baselines = {}
    for name, fn in (('zero_motion', _zero_motion), ('constant_velocity_oracle', _mean_motion)):
        r = evaluate(None, motions, 'none', None, device, fps=model.cfg.fps, predictor=fn)
        r['mode'] = name
        baselines[name] = r
    fusion = {}
    for noise in noises:
        say(f'static-camera fusion on validation clips, input {noise} ...')
        fusion[noise] = evaluate_fusion(model, motions, noise, lookahead, device, cache=cache,
                                        window=window)
    bag_rows = []
    if bags:
        for noise in tuple(noises) + ('motionet',):
            say(f'static-camera fusion on {len(bags)} bags, input {noise} ...')
            bag_rows += evaluate_bags(model, bags, noise, lookahead, device, window)
    speed_rows = []
    if speeds:
        say('playback speeds ...')
        speed_rows = evaluate_speeds(model, motions, [n for n in noises if n != 'lifted'],
                                     speeds, lookahead, device, window)
    return {'model': {'config': model.cfg.__dict__, 'info': getattr(model, 'info', {})},
            'lookahead': lookahead, 'window': window, 'results': results, 'baselines': baselines,
            'fusion_validation': fusion, 'fusion_bags': bag_rows,
            'root_noise': ROOT_NOISE, 'speeds': speed_rows}


_COLS = [('ome_deg', 'OME deg'), ('tme_mm', 'TME mm'), ('jme_mm', 'JME mm'),
         ('ome10_deg', 'OME@10fps deg'), ('tme10_mm', 'TME@10fps mm'),
         ('jme10_mm', 'JME@10fps mm'), ('tilt_deg', 'tilt deg'),
         ('drift_1s_mm', 'drift 1 s mm'), ('drift_5s_mm', 'drift 5 s mm'),
         ('drift_10s_mm', 'drift 10 s mm'), ('rte_pct', 'RTE %'), ('ate_mm', 'ATE mm')]


def _fmt(v) -> str:
    if isinstance(v, float):
        if v != v:
            return '-'
        return f'{v:.3f}' if abs(v) < 10 else f'{v:.1f}'
    return str(v)


def write_report(report: Dict, out_dir: Path, title: str) -> Path:
    """``eval.json`` (everything, per clip) and ``eval.md`` (tables)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / 'eval.json').write_text(json.dumps(report, indent=1, default=str))
    cfg = report['model']['config']
    lines = [f'# {title}', '',
             f"Model: {cfg['layers']} x {cfg['hidden']} bidirectional GRU, projection "
             f"{cfg['projection']}, {cfg['fps']:g} fps, training window {cfg['window']}; "
             f"input: pose `{cfg.get('pose_input', 'quat')}`, velocities "
             f"{cfg.get('velocity_input', False)}, bone lengths {cfg.get('skeleton_input', False)}"
             f", root `{cfg['root_input']}`. Online and causal rows: the node's computation with "
             f"windows of {report.get('window')} frames, look-ahead {report['lookahead']} "
             'frames (online) or 0 (causal).', '',
             'Per-step errors at the model rate and at 10 fps (paper Table 4 with ground-truth '
             'input on Human3.6M: OME 0.70 deg, TME 4.78 mm). Drift: root error h seconds '
             'after a ground-truth start (count = starts); RTE: % of the distance travelled; '
             'ATE: 4-DOF aligned.', '',
             '| method | input | clips | ' + ' | '.join(c for _, c in _COLS) + ' |',
             '|---|---|---|' + '---|' * len(_COLS)]
    rows = [(f"GMR {r['mode']}" + (f" (look-ahead {r['lookahead']})"
                                   if r['lookahead'] is not None else ''), r)
            for r in report['results']]
    rows += [(name.replace('_', ' '), r) for name, r in report['baselines'].items()]
    for name, r in rows:
        s = r['summary']
        lines.append(f"| {name} | {r['noise']} | {r['clips']} | "
                     + ' | '.join(_fmt(s.get(k, float('nan'))) for k, _ in _COLS) + ' |')
    s0 = report['results'][0]['summary'] if report['results'] else {}
    counts = ', '.join(f"{k}: {s0.get(k + '_count', 0)}" for k in
                       ('drift_1s_mm', 'drift_5s_mm', 'drift_10s_mm', 'rte_pct'))
    lines += ['', f'Samples: {counts}.', '', '## Static-camera fusion', '',
              'Validation clips of at least 3 s; simulated static camera whose root '
              f"measurement has errors {json.dumps(report['root_noise'])}; ATE after 4-DOF "
              'alignment (the measurement: rigid alignment), jitter = mean |second difference| '
              'of the root (mm/frame^2).', '',
              '| input | clips | GMR ATE mm | fused ATE mm | fused, known up, ATE mm | '
              'measurement ATE mm | GMR jitter | fused jitter | measurement jitter |',
              '|---|---|---|---|---|---|---|---|---|']
    for noise, f in report['fusion_validation'].items():
        lines.append(f"| {noise} | {f['clips']} | {_fmt(f.get('gmr_ate_mm'))} | "
                     f"{_fmt(f.get('fused_ate_mm'))} | {_fmt(f.get('fused_known_up_ate_mm'))} | "
                     f"{_fmt(f.get('measurement_ate_mm'))} | "
                     f"{_fmt(f.get('gmr_jitter_mm'))} | {_fmt(f.get('fused_jitter_mm'))} | "
                     f"{_fmt(f.get('measurement_jitter_mm'))} |")
    if report['fusion_bags']:
        lines += ['', 'Committed ground-truth bags through the node algorithm (OnlineGMR); '
                  'tilt = angle between the world up directions of the estimated and the '
                  'true root orientation (gravity alignment of the world frame).', '',
                  '"fused, known up": the camera\'s up direction given (a calibrated tilt, or '
                  'the floor frame of the physics stage).', '',
                  f'"GMR + tilt": tilt correction {TILT_CORRECTION} per frame (node parameter '
                  '`tilt_correction`).', '',
                  'Input `motionet`: the shipped MotioNet lifter run on the bag\'s keypoints '
                  '(its local poses, skeleton and camera-frame root); "local err" = mean angle '
                  'of its (or the simulated noise\'s) local joint rotation errors.', '',
                  '| bag | input | local err deg | frames | ATE mm: GMR | GMR + tilt | fused | '
                  'fused, known up | measurement | tilt deg: GMR | GMR + tilt | fused | '
                  'fused, known up |',
                  '|---|---|---|---|---|---|---|---|---|---|---|---|---|']
        for r in report['fusion_bags']:
            lines.append(f"| {r['bag']} | {r['noise']} | "
                         f"{_fmt(r.get('local_rotation_error_deg', 0.0))} | {r['frames']} | "
                         + ' | '.join(_fmt(r[f'{k}_ate_mm']) for k in
                                      ('gmr', 'gmr_tilt', 'fused', 'fused_known_up',
                                       'measurement'))
                         + ' | ' + ' | '.join(_fmt(r[f'{k}_tilt_deg']) for k in
                                              ('gmr', 'gmr_tilt', 'fused', 'fused_known_up'))
                         + ' |')
    if report.get('speeds'):
        r0 = report['speeds'][0]
        lines += ['', '## Playback speed', '',
                  f"Online, on the {r0['clips']} validation clips of at least 3 s that travel at "
                  f'least {SPEED_MIN_TRAVEL_M:g} m, played slower or faster at the same frame '
                  'rate (0.5: slow motion, or a gait at half its pace). Step ratio: the '
                  'predicted over the true path of the per-frame translations (1: the right '
                  'pace; 0: on the spot), median and 10th percentile over clips; RTE: median.',
                  '', '| speed | input | step ratio | step ratio p10 | RTE % | TME mm |',
                  '|---|---|---|---|---|---|']
        for r in report['speeds']:
            lines.append(f"| {r['speed']:g} | {r['noise']} | {r['step_ratio']:.2f} | "
                         f"{r['step_ratio_p10']:.2f} | {_fmt(r['rte_pct'])} | "
                         f"{_fmt(r['tme_mm'])} |")
    lines += ['', f"Evaluation time: {report.get('eval_seconds', '-')} s."]
    path = out_dir / 'eval.md'
    path.write_text('\n'.join(lines) + '\n')
    return path
