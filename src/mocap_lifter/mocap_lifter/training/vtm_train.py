"""Training of VTM in two stages (``mocap train vtm``; no ROS imports).

Stage ``tpmae`` (§3.2): the two-part motion auto-encoder on motion alone, loss
L^M = L_rec^M + L_s^M (eq. 3-5): smooth-L1 reconstruction of the normalised representation
with relative importance 2.0 for the root, 1.5 for end effectors, 1.0 for the other joints,
and smooth-L1 on its velocities and accelerations (root weighted the same way).

Stage ``tpve`` (§3.3): the two-part visual encoder trained jointly with the pre-trained TPMAE
(``--init`` the stage-1 weights), L = L_ma + L_b + L_pred^V + L_s^V + L^M (eq. 9-13): manifold
alignment (smooth L1 between visual and motion latents), bone ratios, prediction and
smoothness of the motion decoded from the visual latents, and the TPMAE loss.

Both stages add two terms not in the paper (weights in :class:`VTMTrainConfig`): heel/toe
contacts (BCE) and the mean error of the root-relative joint positions of the FK layer
(metres, on the true skeleton).

Training windows are the MotioNet ones (:mod:`.samples`: flip, bone-length and camera
augmentation, the confidence/displacement corruption fitted on real detections, a share of
clean windows), cut to the VTM window (32 frames). Checkpoints (``last.pt``, resumable), a
CSV log and a loss PNG go to the run directory.
"""

from __future__ import annotations

import csv
import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import numpy as np
import torch
from torch import nn

from mocap_core.checkpoint import load_checkpoint
from mocap_core.data.motion import Motion
from mocap_core.skeleton import END_EFFECTORS, NUM_JOINTS

from ..vtm import ROOT_OUT_CHANNELS, VTM, VTMConfig, keypoint_parts, motion_representation
from ..weights import load_vtm, plain_data, save_vtm
from .common import cosine_lr, plot_log, to_torch
from .samples import Augmentation, WindowSampler

F = nn.functional


@dataclass
class VTMTrainConfig:
    """One stage's settings; the defaults are the shipped CPU configuration."""

    stage: str = 'tpmae'           # 'tpmae' (motion only) or 'tpve' (joint training)
    steps: int = 4000
    batch: int = 64
    lr: float = 1e-3
    lr_final: float = 5e-5
    weight_decay: float = 1e-4     # AdamW, as the paper
    seed: int = 0
    w_root: float = 2.0            # relative importance (eq. 4)
    w_end_effector: float = 1.5
    w_smooth: float = 1.0          # L_s (eq. 5, 13)
    w_ma: float = 1.0              # L_ma (eq. 10)
    w_bone: float = 1.0            # L_b (eq. 11), on ratios
    w_contact: float = 0.1         # ours: contacts (BCE)
    w_fk: float = 2.0              # ours: FK joint positions (m)
    clean_fraction: float = 0.3
    init: Optional[str] = None     # stage 2: the stage-1 (TPMAE) weights
    validate_every: int = 250
    checkpoint_every: int = 250
    threads: int = 1
    model: VTMConfig = field(default_factory=VTMConfig)

    @classmethod
    def from_dict(cls, d: Dict) -> 'VTMTrainConfig':
        d = dict(d)
        model = VTMConfig(**d.pop('model', {}))
        return cls(model=model, **d)


def channel_weights(cfg: VTMTrainConfig) -> Dict[str, torch.Tensor]:
    """Relative importance per channel: ``root`` (8,) and ``non_root`` ((J-1)*12,)."""
    non_root = torch.ones(NUM_JOINTS - 1, 12)
    for j in END_EFFECTORS:
        non_root[j - 1] = cfg.w_end_effector
    return {'root': torch.full((len(ROOT_OUT_CHANNELS),), cfg.w_root),
            'non_root': non_root.reshape(-1)}


def split_targets(xn: torch.Tensor) -> Dict[str, torch.Tensor]:
    """Normalised representation (B, T, J*12) -> decoder targets ``root`` (B, T, 8) and
    ``non_root`` (B, T, (J-1)*12)."""
    return {'root': xn[..., list(ROOT_OUT_CHANNELS)], 'non_root': xn[..., 12:]}


def _smooth_l1(a: torch.Tensor, b: torch.Tensor, w: Optional[torch.Tensor] = None):
    if w is not None:
        a, b = a * w, b * w
    return F.smooth_l1_loss(a, b)


def motion_losses(dec: Dict[str, torch.Tensor], target: Dict[str, torch.Tensor],
                  weights: Dict[str, torch.Tensor]) -> Dict[str, torch.Tensor]:
    """Reconstruction (eq. 4 / 12) and smoothness (eq. 5 / 13) of decoded channels."""
    rec = sum(_smooth_l1(dec[k], target[k], weights[k]) for k in ('root', 'non_root'))
    smooth = torch.zeros(())
    for k in ('root', 'non_root'):
        wr = weights[k] if k == 'root' else None
        v, vt = dec[k][:, 1:] - dec[k][:, :-1], target[k][:, 1:] - target[k][:, :-1]
        a, at = v[:, 1:] - v[:, :-1], vt[:, 1:] - vt[:, :-1]
        smooth = smooth + _smooth_l1(v, vt, wr) + _smooth_l1(a, at, wr)
    return {'rec': rec, 'smooth': smooth}


def _fk_error(model: VTM, dec: Dict[str, torch.Tensor], gt: Dict[str, torch.Tensor],
              ) -> torch.Tensor:
    """Mean root-relative joint position error (m) of decoded channels on the true skeleton."""
    out = model.outputs(dec, gt['root_2d'], gt['lengths'])
    p = out['positions'] - out['positions'][:, :, :1]
    g = gt['positions'] - gt['positions'][:, :, :1]
    return (p - g).norm(dim=-1).mean()


def stage_losses(model: VTM, gt: Dict[str, torch.Tensor], cfg: VTMTrainConfig,
                 weights: Dict[str, torch.Tensor]) -> Dict[str, torch.Tensor]:
    """Loss terms (unweighted) of one batch; ``total`` is the weighted sum."""
    x = motion_representation(gt['rotations'], gt['root'], model.virtual_lengths)
    xn = model.normalise_motion(x)
    target = split_targets(xn)
    z_u, z_l = model.encode_motion(xn)
    dec_m = model.decode(z_u, z_l)
    lm = motion_losses(dec_m, target, weights)
    terms = {'rec_m': lm['rec'], 'smooth_m': lm['smooth'],
             'contact_m': F.binary_cross_entropy_with_logits(dec_m['contacts'], gt['contacts']),
             'fk_m': _fk_error(model, dec_m, gt)}
    total = terms['rec_m'] + cfg.w_smooth * terms['smooth_m'] + \
        cfg.w_contact * terms['contact_m'] + cfg.w_fk * terms['fk_m']
    if cfg.stage == 'tpve':
        vz_u, vz_l, ratios = model.encode_visual(gt['features'], gt['root_2d'])
        dec_v = model.decode(vz_u, vz_l)
        lv = motion_losses(dec_v, target, weights)
        true_ratios = gt['lengths'] / model.virtual_lengths
        terms.update(
            ma=_smooth_l1(vz_u, z_u) + _smooth_l1(vz_l, z_l),
            bone=_smooth_l1(ratios, true_ratios),
            rec_v=lv['rec'], smooth_v=lv['smooth'],
            contact_v=F.binary_cross_entropy_with_logits(dec_v['contacts'], gt['contacts']),
            fk_v=_fk_error(model, dec_v, gt),
            bone_mm=1000 * ((ratios - true_ratios) * model.virtual_lengths).abs().mean())
        total = total + cfg.w_ma * terms['ma'] + cfg.w_bone * terms['bone'] + \
            terms['rec_v'] + cfg.w_smooth * terms['smooth_v'] + \
            cfg.w_contact * terms['contact_v'] + cfg.w_fk * terms['fk_v']
    terms['total'] = total
    return terms


def compute_statistics(model: VTM, sampler: WindowSampler, batches: int = 20,
                       size: int = 64) -> None:
    """Set the model's normalisation from random training windows."""
    motion, up, lo = [], [], []
    for _ in range(batches):
        b = sampler.batch(size)
        x = motion_representation(torch.as_tensor(b['rotations']), torch.as_tensor(b['root']),
                                  model.virtual_lengths)
        u, l_ = keypoint_parts(torch.as_tensor(b['features']), torch.as_tensor(b['root_2d']))
        motion.append(x.reshape(-1, x.shape[-1]).numpy())
        up.append(u.reshape(-1, u.shape[-1]).numpy())
        lo.append(l_.reshape(-1, l_.shape[-1]).numpy())
    model.set_statistics(np.concatenate(motion), np.concatenate(up), np.concatenate(lo))


def virtual_skeleton(motions: Sequence[Motion]) -> List[float]:
    """Mean bone-group lengths (m) of the training skeletons (§3.1)."""
    return [float(v) for v in np.mean([m.skeleton.group_lengths() for m in motions], axis=0)]


def train_stage(train_motions: Sequence[Motion], val_motions: Sequence[Motion], run_dir: Path,
                cfg: VTMTrainConfig, device: str = 'cpu', resume: bool = True,
                progress: bool = True) -> Path:
    """Train one stage, checkpointing to ``run_dir``; returns the path of the weights."""
    from tqdm import tqdm

    if cfg.stage not in ('tpmae', 'tpve'):
        raise ValueError(f"stage must be 'tpmae' or 'tpve', got {cfg.stage!r}")
    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    aug = Augmentation(clean_prob=cfg.clean_fraction)
    sampler = WindowSampler(train_motions, cfg.model.window, seed=cfg.seed, aug=aug)
    val_sampler = WindowSampler(val_motions, cfg.model.window, seed=12345, aug=Augmentation())
    val_batches = [val_sampler.batch(cfg.batch) for _ in range(4)]

    step = 0
    ckpt = run_dir / 'last.pt'
    if resume and ckpt.exists():
        state = load_checkpoint(ckpt, map_location=device, required=('model', 'step', 'config'))
        cfg = VTMTrainConfig.from_dict(state['config'])
        model = VTM(cfg.model).to(device)
        model.load_state_dict(state['model'])
        step = state['step']
        sampler.rng = np.random.default_rng(cfg.seed + step)
    elif cfg.init:
        model = load_vtm(Path(cfg.init), device)
        cfg.model = model.cfg
    else:
        cfg.model.virtual_lengths = virtual_skeleton(train_motions)
        model = VTM(cfg.model).to(device)
        compute_statistics(model, sampler)
    (run_dir / 'config.json').write_text(json.dumps(asdict(cfg), indent=1))
    model.train()
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    if resume and ckpt.exists() and 'optimizer' in state:
        opt.load_state_dict(state['optimizer'])
    weights = {k: v.to(device) for k, v in channel_weights(cfg).items()}

    log_path = run_dir / 'log.csv'
    keys = ['total', 'rec_m', 'smooth_m', 'fk_m', 'contact_m', 'ma', 'bone', 'rec_v',
            'smooth_v', 'fk_v', 'contact_v', 'bone_mm']
    new_log = not log_path.exists() or step == 0
    log = log_path.open('w' if new_log else 'a', newline='')
    writer = csv.writer(log)
    if new_log:
        writer.writerow(['step', 'split', 'loss', 'joints_mm', 'root_mm'] + keys +
                        ['lr', 'seconds'])
    t0 = time.time()
    bar = tqdm(total=cfg.steps, initial=step, disable=not progress, desc=f'train vtm {cfg.stage}')
    while step < cfg.steps:
        lr = cosine_lr(step, cfg.steps, cfg.lr, cfg.lr_final)
        for g in opt.param_groups:
            g['lr'] = lr
        model.train()
        gt = to_torch(sampler.batch(cfg.batch), device)
        terms = stage_losses(model, gt, cfg, weights)
        opt.zero_grad()
        terms['total'].backward()
        nn.utils.clip_grad_norm_(model.parameters(), 5.0)
        opt.step()
        step += 1
        bar.update(1)
        if step % 50 == 0:
            writer.writerow(_row(step, 'train', terms, keys, cfg, lr, time.time() - t0))
            bar.set_postfix(loss=f"{terms['total'].item():.4f}",
                            mm=f"{1000 * _joint_term(terms, cfg).item():.0f}")
        if step % cfg.validate_every == 0 or step == cfg.steps:
            v = validate(model, val_batches, cfg, weights, device)
            writer.writerow(_row(step, 'val', v, keys, cfg, lr, time.time() - t0))
            log.flush()
            plot_log(log_path, run_dir / 'loss.png')
        if step % cfg.checkpoint_every == 0 or step == cfg.steps:
            torch.save({'model': model.state_dict(), 'optimizer': opt.state_dict(),
                        'step': step, 'config': plain_data(asdict(cfg))},
                       ckpt.with_suffix('.tmp'))
            ckpt.with_suffix('.tmp').replace(ckpt)
    bar.close()
    log.close()
    out = run_dir / f'vtm_{cfg.stage}.pt'
    save_vtm(model, out, {'stage': cfg.stage, 'steps': step,
                          'train_seconds': round(time.time() - t0, 1)})
    return out


def _joint_term(terms: Dict[str, torch.Tensor], cfg: VTMTrainConfig) -> torch.Tensor:
    """The joint error the stage is about: visual path in stage 2, motion path in stage 1."""
    return terms['fk_v'] if cfg.stage == 'tpve' else terms['fk_m']


def _row(step, split, terms, keys, cfg, lr, seconds) -> List:
    f = lambda k: float(terms[k]) if k in terms else float('nan')  # noqa: E731
    joint = f('fk_v') if cfg.stage == 'tpve' else f('fk_m')
    return [step, split, f('total'), 1000 * joint, float('nan')] + [f(k) for k in keys] + \
        [lr, round(seconds, 1)]


@torch.no_grad()
def validate(model: VTM, batches, cfg: VTMTrainConfig, weights, device: str,
             ) -> Dict[str, float]:
    model.eval()
    acc: Dict[str, float] = {}
    for b in batches:
        gt = to_torch(b, device)
        for k, v in stage_losses(model, gt, cfg, weights).items():
            acc[k] = acc.get(k, 0.0) + float(v) / len(batches)
    return acc
