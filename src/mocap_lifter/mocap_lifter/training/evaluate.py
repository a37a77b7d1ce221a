"""Evaluation of the lifter on held-out clips (``mocap eval lifter``; no ROS imports).

Every validation clip is seen by one virtual camera drawn with a seed derived from the clip
name (the same cameras for every model and run), without flip or bone-length augmentation,
and lifted in one pass over the whole clip (the networks are fully convolutional; E_S sees the
whole clip). Two input conditions: ``none`` (clean projected keypoints) and ``motionet``
(the MotioNet-style confidence and displacement corruption used in training).

:func:`evaluate_real` lifts real OpenPose detections (no ground truth): only what needs none
is measured, jitter (joint acceleration), foot skating during predicted contacts and the
bone-length spread, next to the same figures of the ground-truth validation motion.
"""

from __future__ import annotations

import json
import zlib
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import numpy as np
import torch

from mocap_core.data.motion import Motion
from mocap_core.data.synth2d import Corruption
from mocap_core.skeleton import JOINT_INDEX

from ..model import MotioNet
from . import metrics as M
from .samples import Augmentation, make_sample

_FEET = [JOINT_INDEX[n] for n in ('left_ankle', 'left_toe', 'right_ankle', 'right_toe')]


def _clip_seed(name: str) -> int:
    return zlib.crc32(name.encode()) & 0x7FFFFFFF


@torch.no_grad()
def lift(model: MotioNet, features: np.ndarray, root_2d: np.ndarray, scale: np.ndarray,
         device: str = 'cpu', flip: bool = False, output_sigma: float = 0.0,
         output_root_sigma: Optional[float] = None,
         virtual_camera: bool = False) -> Dict[str, np.ndarray]:
    """Run the model on one (T, C) feature sequence -> numpy outputs without the batch axis
    (contacts as probabilities). ``flip``: test-time flip augmentation: the mirrored input is
    lifted too and its positions, root and contacts, mirrored back, averaged in (rotations
    are the unflipped pass's). ``output_sigma`` > 0: the node's output smoothing
    (:mod:`mocap_lifter.output_smoothing`, sigma in frames), applied here to the positions
    and ``output_root_sigma`` (None: ``output_sigma``) to the root (the node smooths the
    rotations and the root; the two agree to the millimetre for the few degrees neighbouring
    frames differ by). ``virtual_camera`` (the node's parameter), and always for weights
    trained in it (``model.cfg.virtual_camera``): the virtual camera's features
    (:func:`~mocap_lifter.features.virtual_camera_window`), the outputs turned back into the
    real camera's frame."""
    rays = None
    if virtual_camera or getattr(model.cfg, 'virtual_camera', False):
        from ..features import ray_rotations, virtual_camera_window
        rays = ray_rotations(root_2d)
        w = virtual_camera_window({'features': features, 'root_2d': root_2d, 'scale': scale})
        features, root_2d, scale = w['features'], w['root_2d'], w['scale']
    def run(f, r):
        out = model(torch.as_tensor(f[None], device=device),
                    torch.as_tensor(r[None], device=device),
                    torch.as_tensor(scale[None], device=device))
        res = {k: v[0].cpu().numpy() for k, v in out.items()}
        res['contacts'] = 1.0 / (1.0 + np.exp(-res['contacts']))
        return res
    res = run(features, root_2d)
    if flip:
        from mocap_core.skeleton import JOINT_MIRROR
        from ..features import mirror_features
        m = run(*mirror_features(features, root_2d))
        pos = m['positions'][:, list(JOINT_MIRROR)] * np.array([-1.0, 1.0, 1.0])
        root = m['root'] * np.array([-1.0, 1.0, 1.0])
        res['positions'] = 0.5 * (res['positions'] + pos)
        res['root'] = 0.5 * (res['root'] + root)
        res['contacts'] = 0.5 * (res['contacts'] + m['contacts'][:, [2, 3, 0, 1]])
    if rays is not None:
        from ..features import turn_root_orientation
        res['positions'] = np.einsum('tij,tkj->tki', rays, res['positions'])
        res['root'] = np.einsum('tij,tj->ti', rays, res['root'])
        res['rotations'] = turn_root_orientation(res['rotations'], rays).astype(
            res['rotations'].dtype)
    root_sigma = output_sigma if output_root_sigma is None else output_root_sigma
    from ..output_smoothing import smooth_along_time
    if output_sigma > 0:
        res['positions'] = smooth_along_time(res['positions'], output_sigma)
    if root_sigma > 0:
        res['root'] = smooth_along_time(res['root'], root_sigma)
    return res


def evaluate(model: MotioNet, motions: Sequence[Motion], noise: str = 'none',
             device: str = 'cpu', max_frames: int = 900, placement=None,
             families: Optional[Sequence[str]] = None, flip: bool = False,
             smooth: float = 0.0, output_sigma: float = 0.0,
             output_root_sigma: Optional[float] = None,
             virtual_camera: bool = False) -> Dict:
    """Metrics over validation clips (frame-weighted means); per-clip rows included.

    ``placement``: a ``DetectorPlacement`` puts the keypoints where the real detector puts them
    (the cross-synthesizer check); None projects the joints. ``families``: a label per clip
    (e.g. the strict split's held-out family) for a per-family summary."""
    if noise not in ('none', 'motionet'):
        raise ValueError("noise must be 'none' or 'motionet'")
    aug = Augmentation(flip_prob=0.0, bone_scale=0.0, global_scale=0.0,
                       corruption=Corruption() if noise == 'motionet' else None,
                       placement=placement, placement_prob=1.0 if placement is not None
                       else 0.0, smooth=smooth)
    rows: List[Dict] = []
    for m in motions:
        n = min(m.num_frames, max_frames)
        rng = np.random.default_rng(_clip_seed(m.name))
        s = make_sample(m, 0, n, rng, aug)
        out = lift(model, s['features'], s['root_2d'], s['scale'], device, flip=flip,
                   virtual_camera=virtual_camera,
                   output_sigma=output_sigma, output_root_sigma=output_root_sigma)
        p, g = out['positions'], s['positions']
        rows.append({
            'clip': m.name, 'frames': n,
            'mpjpe_mm': M.mpjpe_mm(p, g), 'n_mpjpe_mm': M.n_mpjpe_mm(p, g),
            'pa_mpjpe_mm': M.pa_mpjpe_mm(p, g), 'mrpe_mm': M.mrpe_mm(out['root'], s['root']),
            'mble_mm': M.mble_mm(p, g), 'bone_spread_mm': M.bone_length_spread_mm(p),
            'contact_accuracy': M.contact_accuracy(out['contacts'], s['contacts']),
            'accel_error_mm': M.accel_error_mm(p, g),
            'skating_mm': M.foot_skating_mm(p[:, _FEET], out['contacts'] >= 0.5, up_axis=1),
            'skating_gt_mm': M.foot_skating_mm(g[:, _FEET], s['contacts'], up_axis=1),
            **rotation_errors_deg(out['rotations'], s['rotations']),
        })
    frames = np.array([r['frames'] for r in rows], dtype=np.float64)
    summary = {k: _weighted_mean([r[k] for r in rows], frames)
               for k in rows[0] if k not in ('clip', 'frames')}
    out = {'noise': noise, 'clips': len(rows), 'frames': int(frames.sum()),
           'placement': 'detector' if placement is not None else 'joints',
           'summary': summary, 'per_clip': rows}
    if families is not None:
        by: Dict[str, Dict[str, float]] = {}
        for fam in sorted(set(families)):
            idx = [i for i, f in enumerate(families) if f == fam]
            w = frames[idx]
            by[fam] = {'clips': len(idx), 'frames': int(w.sum()),
                       **{k: _weighted_mean([rows[i][k] for i in idx], w)
                          for k in ('mpjpe_mm', 'pa_mpjpe_mm', 'mrpe_mm')}}
            rows_f = [rows[i] for i in idx]
            for r in rows_f:
                r['family'] = fam
        out['by_family'] = by
    return out


@torch.no_grad()
def evaluate_tpmae(model, motions: Sequence[Motion], device: str = 'cpu',
                   max_frames: int = 900) -> Dict:
    """VTM's motion auto-encoder alone (the paper's Table 2): each validation clip's true
    motion (the camera of :func:`evaluate`) is encoded and decoded window by window; the
    decoded rotations and root depth, with the true skeleton and root keypoint, give joint
    positions by FK. Returns frame-weighted MPJPE, PA-MPJPE and MRPE (mm)."""
    from ..vtm import motion_representation

    aug = Augmentation(flip_prob=0.0, bone_scale=0.0, global_scale=0.0, corruption=None)
    rows: List[Dict] = []
    for m in motions:
        n = min(m.num_frames, max_frames)
        s = make_sample(m, 0, n, np.random.default_rng(_clip_seed(m.name)), aug)
        x = motion_representation(torch.as_tensor(s['rotations'][None], device=device),
                                  torch.as_tensor(s['root'][None], device=device),
                                  model.virtual_lengths)
        dec = model.autoencode(model.normalise_motion(x))
        out = model.outputs(dec, torch.as_tensor(s['root_2d'][None], device=device),
                            torch.as_tensor(s['lengths'][None], device=device))
        p, g = out['positions'][0].cpu().numpy(), s['positions']
        rows.append({'clip': m.name, 'frames': n, 'mpjpe_mm': M.mpjpe_mm(p, g),
                     'pa_mpjpe_mm': M.pa_mpjpe_mm(p, g),
                     'mrpe_mm': M.mrpe_mm(out['root'][0].cpu().numpy(), s['root'])})
    frames = np.array([r['frames'] for r in rows], dtype=np.float64)
    return {'clips': len(rows), 'frames': int(frames.sum()),
            'summary': {k: _weighted_mean([r[k] for r in rows], frames)
                        for k in ('mpjpe_mm', 'pa_mpjpe_mm', 'mrpe_mm')}}


def rotation_errors_deg(pred: np.ndarray, gt: np.ndarray) -> Dict[str, float]:
    """Mean geodesic angles (degrees) between predicted and true rotations (T, J, 4):
    ``local_rotation_error_deg`` over the non-root joints (relative to the parent, against
    the common rest pose) and ``root_orientation_error_deg`` (camera frame)."""
    from mocap_core.rotations import quat_angle
    ang = np.degrees(quat_angle(np.asarray(pred, np.float64), np.asarray(gt, np.float64)))
    return {'local_rotation_error_deg': float(ang[:, 1:].mean()),
            'root_orientation_error_deg': float(ang[:, 0].mean())}


def _weighted_mean(values: Sequence[float], weights: np.ndarray) -> float:
    v = np.asarray(values, dtype=np.float64)
    ok = np.isfinite(v)
    return float(np.dot(v[ok], weights[ok]) / weights[ok].sum()) if ok.any() else float('nan')


def baseline_mean_pose(train: Sequence[Motion], motions: Sequence[Motion],
                       noise: str = 'none') -> Dict:
    """A trivial baseline: the mean training pose (in the camera frame of each clip, root at
    the true position), to show what the model adds."""
    from mocap_core.kinematics import forward_kinematics
    from mocap_core.rotations import quat_normalize

    mean_rot = quat_normalize(np.mean(np.concatenate(
        [m.rotations[:, 1:] * np.sign(m.rotations[:, 1:, 3:4] + 1e-12) for m in train]),
        axis=0))
    aug = Augmentation(flip_prob=0.0, bone_scale=0.0, global_scale=0.0,
                       corruption=Corruption() if noise == 'motionet' else None)
    errs, pa, frames = [], [], []
    for m in motions:
        n = min(m.num_frames, 900)
        s = make_sample(m, 0, n, np.random.default_rng(_clip_seed(m.name)), aug)
        rot = np.array(s['rotations'], dtype=np.float64)
        rot[:, 1:] = mean_rot
        p = forward_kinematics(m.skeleton.parents, m.skeleton.offsets, rot, s['root']).positions
        errs.append(M.mpjpe_mm(p, s['positions']))
        pa.append(M.pa_mpjpe_mm(p, s['positions']))
        frames.append(n)
    w = np.array(frames, dtype=np.float64)
    return {'mpjpe_mm': float(np.dot(errs, w) / w.sum()),
            'pa_mpjpe_mm': float(np.dot(pa, w) / w.sum())}


def _largest_person(people: np.ndarray) -> np.ndarray:
    """(P, 23, 3) -> (23, 3): the person with the largest summed confidence (zeros if none)."""
    if len(people) == 0:
        return np.zeros(people.shape[1:])
    return people[int(np.argmax(people[..., 2].sum(axis=-1)))]


def evaluate_real(model: MotioNet, directories: Sequence[Path], fps: float = 30.0,
                  fov: float = 60.0, device: str = 'cpu', flip: bool = False,
                  smooth: float = 0.0, output_sigma: float = 0.0,
                  output_root_sigma: Optional[float] = None,
                  virtual_camera: bool = False) -> Dict:
    """Lift OpenPose JSON folders (one sequence each; the most confident person per frame;
    intrinsics from ``fov`` over the inferred image size, as ``mocap data from-openpose``)
    and measure jitter (mm/s^2), foot skating (mm per frame, camera frame, during predicted
    contact) and bone-length spread (mm)."""
    from mocap_core.camera import CameraIntrinsics
    from mocap_core.data.openpose import (OpenPoseError, infer_image_size,
                                          list_openpose_files, read_openpose_file)

    from ..features import lifter_features

    rows = []
    for d in directories:
        files = list_openpose_files(d)
        kps = []
        for _, f in files:
            try:
                kps.append(_largest_person(read_openpose_file(f)))
            except OpenPoseError:
                kps.append(np.zeros((23, 3)))
        kp = np.stack(kps)
        if smooth > 0:
            from ..features import smooth_keypoints
            kp = smooth_keypoints(kp, smooth)
        w, h = infer_image_size(files)
        feats, root_2d, scale, _ = lifter_features(kp, CameraIntrinsics.from_fov(w, h, fov))
        out = lift(model, feats, root_2d.astype(np.float32), scale.astype(np.float32), device,
                   flip=flip, output_sigma=output_sigma, virtual_camera=virtual_camera,
                   output_root_sigma=output_root_sigma)
        p = out['positions']
        rows.append({'sequence': Path(d).name, 'frames': len(kp),
                     'jitter_mm_s2': M.jitter_mm(p) * fps ** 2,
                     'skating_mm': M.foot_skating_mm(p[:, _FEET], out['contacts'] >= 0.5, 1),
                     'bone_spread_mm': M.bone_length_spread_mm(p),
                     'mean_confidence': float(kp[..., 2].mean())})
    frames = np.array([r['frames'] for r in rows], dtype=np.float64)
    summary = {k: _weighted_mean([r[k] for r in rows], frames)
               for k in ('jitter_mm_s2', 'skating_mm', 'bone_spread_mm')}
    return {'sequences': len(rows), 'frames': int(frames.sum()), 'summary': summary,
            'per_sequence': rows}


def evaluate_rendered(model: MotioNet, clip_dirs: Sequence[Path], inputs: str = 'detector',
                      device: str = 'cpu', flip: bool = False, smooth: float = 0.0,
                      placement=None, output_sigma: float = 0.0,
                      output_root_sigma: Optional[float] = None,
                      virtual_camera: bool = False) -> Dict:
    """The lifter alone on rendered clips (``mocap data render``), against their exact joints
    (camera frame), from one of three inputs of the same frames and cameras:

    * ``detector``: the keypoint node's BlazePose keypoints on the rendered video;
    * ``projected``: the training synthesizer's keypoints (``synth2d.keypoints_3d`` of the
      clip's motion on the rendered body's bone lengths), projected clean by the clip's camera;
    * ``placed``: the same with ``placement`` (where the detector puts each point).

    Differences between the three split the error into what the detector does and what the
    people, cameras and motions do. Frame-weighted means; per-clip rows included."""
    import json as _json

    from mocap_core.camera import CameraIntrinsics, project_pinhole, world_to_optical
    from mocap_core.data.synth2d import keypoints_3d
    from mocap_core.skeleton import Skeleton

    from ..features import lifter_features, smooth_keypoints

    if inputs not in ('detector', 'projected', 'placed'):
        raise ValueError(f'unknown inputs {inputs!r}')
    rows = []
    for d in clip_dirs:
        d = Path(d)
        meta = _json.loads((d / 'meta.json').read_text())
        with np.load(d / 'data.npz') as z:
            a = {k: z[k] for k in z.files}
        K, (w, h) = a['K'], (int(x) for x in a['image_size'])
        intr = CameraIntrinsics(w, h, float(K[0, 0]), float(K[1, 1]), float(K[0, 2]),
                                float(K[1, 2]), approximate=False)
        if inputs == 'detector':
            kp = a['keypoints']
            if kp[..., 2].max() <= 0:
                continue
        else:
            sk = Skeleton.from_group_lengths(a['bone_lengths'])
            pts = keypoints_3d(sk, a['rotations'], a['root_positions'],
                               placement=placement if inputs == 'placed' else None)
            kp = project_pinhole(K, world_to_optical(a['camera_R'], a['camera_position'],
                                                     pts))
        if smooth > 0:
            kp = smooth_keypoints(kp, smooth)
        feats, root_2d, scale, _ = lifter_features(kp, intr)
        out = lift(model, feats, root_2d.astype(np.float32), scale.astype(np.float32), device,
                   flip=flip, output_sigma=output_sigma, virtual_camera=virtual_camera,
                   output_root_sigma=output_root_sigma)
        p, g = out['positions'], a['joints_camera']
        rows.append({'clip': meta['clip'], 'frames': len(p), 'mpjpe_mm': M.mpjpe_mm(p, g),
                     'pa_mpjpe_mm': M.pa_mpjpe_mm(p, g),
                     'mrpe_mm': M.mrpe_mm(out['root'], g[:, 0]), 'mble_mm': M.mble_mm(p, g),
                     'camera': meta['camera']['kind']})
    if not rows:
        raise ValueError('no rendered clip to evaluate')
    frames = np.array([r['frames'] for r in rows], dtype=np.float64)
    summary = {k: _weighted_mean([r[k] for r in rows], frames)
               for k in ('mpjpe_mm', 'pa_mpjpe_mm', 'mrpe_mm', 'mble_mm')}
    summary.update({f'median_{k}': float(np.median([r[k] for r in rows]))
                    for k in ('mpjpe_mm', 'pa_mpjpe_mm')})
    return {'inputs': inputs, 'clips': len(rows), 'frames': int(frames.sum()),
            'summary': summary, 'per_clip': rows}


def groundtruth_plausibility(motions: Sequence[Motion], fps: float = 30.0,
                             max_frames: int = 900) -> Dict[str, float]:
    """Jitter (mm/s^2) and contact-foot skating (mm per frame) of real motion capture, the
    reference for :func:`evaluate_real`."""
    from mocap_core.kinematics import forward_kinematics

    jit, skate, n = [], [], []
    for m in motions:
        k = min(m.num_frames, max_frames)
        p = forward_kinematics(m.skeleton.parents, m.skeleton.offsets, m.rotations[:k],
                               m.root_positions[:k]).positions
        jit.append(M.jitter_mm(p) * fps ** 2)
        skate.append(M.foot_skating_mm(p[:, _FEET], m.contacts[:k].astype(bool), 2))
        n.append(k)
    w = np.array(n, dtype=np.float64)
    return {'jitter_mm_s2': _weighted_mean(jit, w), 'skating_mm': _weighted_mean(skate, w)}


def write_report(results: Sequence[Dict], out_dir: Path, title: str,
                 extra: Dict | None = None, real: Dict | None = None) -> Path:
    """JSON + Markdown report of :func:`evaluate` results."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / 'eval.json').write_text(json.dumps(
        {'results': list(results), 'real': real, **(extra or {})}, indent=1))
    keys = ['mpjpe_mm', 'n_mpjpe_mm', 'pa_mpjpe_mm', 'mrpe_mm', 'mble_mm', 'bone_spread_mm',
            'contact_accuracy', 'accel_error_mm', 'skating_mm', 'skating_gt_mm',
            'local_rotation_error_deg', 'root_orientation_error_deg']
    lines = [f'# {title}', '', '| noise | keypoints | clips | frames | ' + ' | '.join(keys)
             + ' |', '|---|---|---|---|' + '---|' * len(keys)]
    for r in results:
        s = r['summary']
        lines.append(f"| {r['noise']} | {r.get('placement', 'joints')} | {r['clips']} | "
                     f"{r['frames']} | "
                     + ' | '.join(f'{s[k]:.3f}' if 'accuracy' in k else f'{s[k]:.1f}'
                                  for k in keys if k in s) + ' |')
    fams = [r for r in results if r.get('by_family')]
    if fams:
        lines += ['', '## By held-out family (MPJPE / PA-MPJPE / MRPE, mm)', '',
                  '| family | clips | ' + ' | '.join(f"{r['noise']}, {r['placement']}"
                                                    for r in fams) + ' |',
                  '|---|---|' + '---|' * len(fams)]
        for fam, v in fams[0]['by_family'].items():
            lines.append(f"| {fam} | {v['clips']} | " + ' | '.join(
                '{:.1f} / {:.1f} / {:.0f}'.format(r['by_family'][fam]['mpjpe_mm'],
                                                  r['by_family'][fam]['pa_mpjpe_mm'],
                                                  r['by_family'][fam]['mrpe_mm'])
                for r in fams) + ' |')
    if real:
        ref = real.get('groundtruth', {})
        lines += ['', f"## Real OpenPose sequences (no ground truth): {real['sequences']} "
                  f"sequences, {real['frames']} frames", '',
                  '| sequence | frames | mean confidence | jitter (m/s²) | '
                  'foot skating (mm/frame) '
                  '| bone-length spread (mm) |', '|---|---|---|---|---|---|']
        total = {'sequence': 'all (frame-weighted)', 'frames': real['frames'],
                 'mean_confidence': float('nan'), **real['summary']}
        for r in real['per_sequence'] + [total]:
            lines.append(f"| {r['sequence']} | {r['frames']} | {r['mean_confidence']:.2f} | "
                         f"{r['jitter_mm_s2'] / 1000:.2f} | {r['skating_mm']:.1f} | "
                         f"{r['bone_spread_mm']:.1f} |")
        if ref:
            lines += ['', f"Reference, the ground-truth validation motion: jitter "
                      f"{ref['jitter_mm_s2'] / 1000:.2f} m/s², foot skating "
                      f"{ref['skating_mm']:.1f} mm/frame."]
    for k, v in (extra or {}).items():
        lines += ['', f'**{k}**: `{json.dumps(v)}`']
    path = out_dir / 'eval.md'
    path.write_text('\n'.join(lines) + '\n')
    return path
