"""Training of GMR (``mocap train gmr``; no ROS imports).

Loss (§3.4 eq. 5, supplementary S3 eq. 10, 12-14), per valid motion i -> i + 1 of a window::

    L = w_ori   * ||dR_i - dR*_i||_F^2                      chordal orientation loss (eq. 10)
      + w_trans * ||dT_i - dT*_i||^2                        translation loss (eq. 12)
      + w_joint * mean_j ||dM_i[j] - dM*_i[j]||_1            joint-motion loss (eq. 13)
      + w_smooth * ||dR_i - dR_{i+1}||_F^2                  smoothness loss (eq. 14)
      + w_up    * ||u_i - u*_i||^2                          tilt (up vector), beyond the paper

``dM_i[j] = dR_i p_{i+1}[j] + dT_i``: joint j of frame i + 1 in the body frame of frame i,
with ``p`` the joint positions of the pipeline skeleton's FK in the root frame (in place of the
SMPL mesh offsets of the paper; the ground-truth local pose is used for both sides, so the
term measures the global motion only). Lengths enter the losses in centimetres
(``length_unit`` = 0.01 m) and rotations as matrices; the default weights (:class:`TrainConfig`)
are chosen for these units (``docs/global.md``). Terms are means over valid frames (padding is
masked).

Optimisation: Adam (§4.1), cosine learning-rate decay, gradient clipping. Checkpoints
(``last.pt``: model, optimiser, step, sampler state, elapsed time) make training resumable;
``log.csv`` has the training losses every 50 steps and validation metrics (OME, TME, joint
motion error, tilt) on fixed validation windows; ``loss.png`` is redrawn at every validation.
``--minutes`` fixes the number of steps from the measured speed of the first steps so that a
run fits a time budget.
"""

from __future__ import annotations

import csv
import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Dict, Optional, Sequence

import numpy as np
import torch
from torch import nn

from mocap_core.checkpoint import load_checkpoint
from mocap_core.data.motion import Motion

from ..model import GMR, GMRConfig
from ..weights import save_weights
from .samples import Augmentation, WindowSampler


@dataclass
class TrainConfig:
    """Optimisation settings; the defaults are the shipped CPU configuration."""

    steps: int = 6000
    batch: int = 64
    lr: float = 1e-3
    lr_final: float = 2e-5
    seed: int = 0
    w_ori: float = 1000.0
    w_trans: float = 1.0
    w_joint: float = 1.0
    w_smooth: float = 10.0
    w_up: float = 100.0
    length_unit: float = 0.01
    clip_grad: float = 1.0
    validate_every: int = 500
    checkpoint_every: int = 200
    validation_windows: int = 512
    threads: int = 2
    #: cameras per clip for the lifter's view of the training clips (``augmentation.
    #: lifted_prob`` > 0; :mod:`mocap_global.training.lifted`)
    lifted_cameras: int = 2
    augmentation: Augmentation = field(default_factory=Augmentation)
    model: GMRConfig = field(default_factory=GMRConfig)

    @classmethod
    def from_dict(cls, d: Dict) -> 'TrainConfig':
        d = dict(d)
        model = GMRConfig(**d.pop('model', {}))
        aug = Augmentation(**d.pop('augmentation', {}))
        return cls(model=model, augmentation=aug, **d)

    @classmethod
    def paper(cls) -> 'TrainConfig':
        """The paper's setting (§4.1): 4 x 2048 GRU at 10 fps, batch 32, Adam 5e-5 (GPU)."""
        return cls(batch=32, lr=5e-5, lr_final=5e-5, steps=60000, model=GMRConfig.paper())


def to_torch(batch: Dict[str, np.ndarray], device: str) -> Dict[str, torch.Tensor]:
    return {k: torch.as_tensor(v, device=device) for k, v in batch.items()}


def _masked_mean(x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    m = mask.to(x.dtype)
    return (x * m).sum() / m.sum().clamp(min=1.0)


def losses(out: Dict[str, torch.Tensor], gt: Dict[str, torch.Tensor],
           cfg: TrainConfig) -> Dict[str, torch.Tensor]:
    """The unweighted loss terms of one batch (module docstring)."""
    u = cfg.length_unit
    mm = gt['motion_mask']
    dR = out['rotation'][:, :-1]
    dT = out['translation'][:, :-1]
    ori = _masked_mean(((dR - gt['dR']) ** 2).sum(dim=(-1, -2)), mm)
    trans = _masked_mean((((dT - gt['dT']) / u) ** 2).sum(dim=-1), mm)
    p = gt['joints'][:, 1:]                                     # (B, T-1, J, 3)
    pred = torch.einsum('btik,btjk->btji', dR, p) + dT[:, :, None]
    true = torch.einsum('btik,btjk->btji', gt['dR'], p) + gt['dT'][:, :, None]
    joint = _masked_mean(((pred - true).abs().sum(dim=-1) / u).mean(dim=-1), mm)
    smooth = _masked_mean(((dR[:, 1:] - dR[:, :-1]) ** 2).sum(dim=(-1, -2)),
                          mm[:, 1:] & mm[:, :-1])
    up = _masked_mean(((out['up'] - gt['up']) ** 2).sum(dim=-1), gt['frame_mask'])
    return {'ori': ori, 'trans': trans, 'joint': joint, 'smooth': smooth, 'up': up}


def total_loss(terms: Dict[str, torch.Tensor], cfg: TrainConfig) -> torch.Tensor:
    return (cfg.w_ori * terms['ori'] + cfg.w_trans * terms['trans']
            + cfg.w_joint * terms['joint'] + cfg.w_smooth * terms['smooth']
            + cfg.w_up * terms['up'])


@torch.no_grad()
def batch_metrics(out: Dict[str, torch.Tensor], gt: Dict[str, torch.Tensor]
                  ) -> Dict[str, float]:
    """OME (deg), TME (mm), joint motion error (mm) (S4 eq. 15-17) and tilt error (deg)."""
    from mocap_core.rotations import matrix_to_axis_angle
    mm = gt['motion_mask']
    dR = out['rotation'][:, :-1]
    dT = out['translation'][:, :-1]
    err = gt['dR'] @ dR.transpose(-1, -2)
    ome = torch.rad2deg(matrix_to_axis_angle(err).norm(dim=-1))
    tme = 1000 * (dT - gt['dT']).norm(dim=-1)
    p = gt['joints'][:, 1:]
    pred = torch.einsum('btik,btjk->btji', dR, p) + dT[:, :, None]
    true = torch.einsum('btik,btjk->btji', gt['dR'], p) + gt['dT'][:, :, None]
    jme = 1000 * (pred - true).norm(dim=-1).mean(dim=-1)
    cos = (out['up'] * gt['up']).sum(dim=-1).clamp(-1.0, 1.0)
    tilt = torch.rad2deg(torch.acos(cos))
    return {'ome_deg': float(_masked_mean(ome, mm)), 'tme_mm': float(_masked_mean(tme, mm)),
            'jme_mm': float(_masked_mean(jme, mm)),
            'tilt_deg': float(_masked_mean(tilt, gt['frame_mask']))}


def statistics(sampler: WindowSampler, batches: int = 30, size: int = 64):
    """Input feature and output motion statistics over random (augmented) training windows:
    (feature mean, feature std, motion mean, motion std) with motion = (axis-angle, dT)."""
    from mocap_core.rotations import matrix_to_axis_angle
    feats, motion = [], []
    for _ in range(batches):
        b = sampler.batch(size)
        feats.append(b['features'][b['frame_mask']])
        m = b['motion_mask']
        motion.append(np.concatenate([matrix_to_axis_angle(b['dR'].astype(np.float64))[m],
                                      b['dT'][m]], axis=-1))
    f, m = np.concatenate(feats), np.concatenate(motion)
    return f.mean(0), f.std(0), m.mean(0), m.std(0)


LOG_FIELDS = ['step', 'split', 'loss', 'ori', 'trans', 'joint', 'smooth', 'up', 'ome_deg',
              'tme_mm', 'jme_mm', 'tilt_deg', 'lr', 'seconds']


def train(train_motions: Sequence[Motion], val_motions: Sequence[Motion], run_dir: Path,
          cfg: TrainConfig, device: str = 'cpu', resume: bool = True, progress: bool = True,
          minutes: Optional[float] = None, init: Optional[Path] = None) -> Path:
    """Train, checkpointing to ``run_dir``; returns the path of the final weights
    (``run_dir/gmr.pt``). ``minutes``: fit the run to this time budget (module docstring).
    ``init``: start from these weights (same architecture; fine-tuning) instead of a fresh
    network, unless a checkpoint of the run is resumed."""
    from tqdm import tqdm

    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    mc = cfg.model
    lifted = None
    if cfg.augmentation.lifted_prob > 0:
        from .lifted import lift_clips
        lifted = lift_clips(train_motions, cfg.lifted_cameras, cfg.seed, progress=progress)
    sampler = WindowSampler(train_motions, mc.window, mc.fps, cfg.seed, cfg.augmentation,
                            mc.root_input, mc.skeleton_input, mc.pose_input, lifted=lifted)
    val_sampler = WindowSampler(val_motions, mc.window, mc.fps, 12345, Augmentation.none(),
                                mc.root_input, mc.skeleton_input, mc.pose_input)
    val_batches = [val_sampler.batch(128) for _ in range(max(1, cfg.validation_windows // 128))]
    (run_dir / 'clips.json').write_text(json.dumps(
        {'train': [m.name for m in train_motions],
         'validation': [m.name for m in val_motions]}, indent=0))

    model = GMR(mc).to(device)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    step, elapsed, total = 0, 0.0, cfg.steps
    ckpt = run_dir / 'last.pt'
    calibrate = minutes is not None
    if resume and ckpt.exists():
        state = load_checkpoint(ckpt, device, required=('model', 'optimizer', 'step'))
        model.load_state_dict(state['model'])
        opt.load_state_dict(state['optimizer'])
        step, elapsed = state['step'], state.get('elapsed', 0.0)
        if minutes is not None and state.get('calibrated', False):
            total, calibrate = state['total_steps'], False   # the budget fixed the steps
        else:
            total = cfg.steps
        if 'rng' in state:
            sampler.rng.bit_generator.state = state['rng']
        print(f'resuming from {ckpt} at step {step}/{total}', flush=True)
    elif init is not None:
        from ..weights import load_weights
        start = load_weights(init, device)
        if asdict(start.cfg) != asdict(mc):
            raise ValueError(f'--init {init}: its configuration differs from the run\'s')
        model.load_state_dict(start.state_dict())      # with its normalisation
        print(f'starting from {init}', flush=True)
    else:
        fm, fs, om, os_ = statistics(sampler)
        model.set_normalisation(fm, fs, om, os_)
    (run_dir / 'config.json').write_text(json.dumps(asdict(cfg), indent=1))

    log_path = run_dir / 'log.csv'
    new_log = not log_path.exists() or step == 0
    log = log_path.open('w' if new_log else 'a', newline='')
    writer = csv.DictWriter(log, LOG_FIELDS)
    if new_log:
        writer.writeheader()
    t_start = time.time() - elapsed
    bar = tqdm(total=total, initial=step, disable=not progress, desc='train gmr',
               dynamic_ncols=True)
    calib_from, first_step = None, step
    while step < total:
        lr = cfg.lr_final + 0.5 * (cfg.lr - cfg.lr_final) * (1 + math.cos(math.pi * step / total))
        for g in opt.param_groups:
            g['lr'] = lr
        model.train()
        gt = to_torch(sampler.batch(cfg.batch), device)
        out = model(gt['features'], gt['lengths'])
        terms = losses(out, gt, cfg)
        loss = total_loss(terms, cfg)
        opt.zero_grad()
        loss.backward()
        nn.utils.clip_grad_norm_(model.parameters(), cfg.clip_grad)
        opt.step()
        step += 1
        bar.update(1)
        if calibrate and step == first_step + 10:
            calib_from = time.time()
        if step % 50 == 0:
            writer.writerow(_row(step, 'train', loss, terms, {}, lr, time.time() - t_start))
            bar.set_postfix(loss=f'{loss.item():.3f}',
                            tme=f"{10 * math.sqrt(max(terms['trans'].item(), 0)):.1f}mm")
        if step % cfg.validate_every == 0 or step == total:
            v_terms, v_metrics = validate(model, val_batches, cfg, device)
            writer.writerow(_row(step, 'val', v_terms['loss'], v_terms, v_metrics, lr,
                                 time.time() - t_start))
            log.flush()
            plot_log(log_path, run_dir / 'loss.png')
            bar.write(f"step {step}: val OME {v_metrics['ome_deg']:.3f} deg, TME "
                      f"{v_metrics['tme_mm']:.2f} mm, JME {v_metrics['jme_mm']:.2f} mm, tilt "
                      f"{v_metrics['tilt_deg']:.2f} deg")
        if calibrate and step == first_step + 60 and calib_from is not None:
            per_step = (time.time() - calib_from) / 50
            t_val = _time_validation(model, val_batches, cfg, device)
            budget = minutes * 60 - (time.time() - t_start) - 30
            # every validate_every steps one validation and a PNG (~1 s)
            per_step_all = per_step + (t_val + 1.0) / cfg.validate_every
            total = max(step + 1, step + int(budget / per_step_all))
            calibrate = False
            bar.total = total
            bar.write(f'time budget {minutes:g} min: {per_step * 1000:.0f} ms/step -> '
                      f'{total} steps')
        if step % cfg.checkpoint_every == 0 or step == total:
            state = {'model': model.state_dict(), 'optimizer': opt.state_dict(), 'step': step,
                     'total_steps': total, 'elapsed': time.time() - t_start,
                     'calibrated': minutes is not None and not calibrate,
                     'rng': sampler.rng.bit_generator.state,
                     'config': asdict(cfg)}
            torch.save(state, ckpt.with_suffix('.tmp'))
            ckpt.with_suffix('.tmp').replace(ckpt)
    bar.close()
    log.close()
    v_terms, v_metrics = validate(model, val_batches, cfg, device)
    weights = run_dir / 'gmr.pt'
    save_weights(model, weights, {
        'steps': step, 'train_seconds': round(time.time() - t_start, 1),
        'train_clips': len(train_motions), 'validation_clips': len(val_motions),
        'validation_windows': {k: round(v, 4) for k, v in v_metrics.items()},
        'train_config': asdict(cfg)})
    return weights


def _row(step, split, loss, terms, metrics, lr, seconds) -> Dict:
    def f(v):
        return float(v.detach()) if isinstance(v, torch.Tensor) else float(v)
    row = {'step': step, 'split': split, 'loss': f(loss), 'lr': lr,
           'seconds': round(seconds, 1)}
    for k in ('ori', 'trans', 'joint', 'smooth', 'up'):
        row[k] = f(terms[k]) if k in terms else ''
    for k in ('ome_deg', 'tme_mm', 'jme_mm', 'tilt_deg'):
        row[k] = metrics.get(k, '')
    return row


def _time_validation(model, batches, cfg, device) -> float:
    t = time.time()
    validate(model, batches, cfg, device)
    return time.time() - t


@torch.no_grad()
def validate(model: GMR, batches, cfg: TrainConfig, device: str):
    """Mean loss terms and metrics over fixed validation batches."""
    model.eval()
    terms_acc: Dict[str, float] = {}
    met_acc: Dict[str, float] = {}
    for b in batches:
        gt = to_torch(b, device)
        out = model(gt['features'], gt['lengths'])
        terms = losses(out, gt, cfg)
        terms['loss'] = total_loss(terms, cfg)
        for k, v in terms.items():
            terms_acc[k] = terms_acc.get(k, 0.0) + float(v) / len(batches)
        for k, v in batch_metrics(out, gt).items():
            met_acc[k] = met_acc.get(k, 0.0) + v / len(batches)
    return terms_acc, met_acc


def plot_log(log_path: Path, out: Path) -> None:
    """Loss curves (train and validation) and validation metrics from the CSV log."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    rows = list(csv.DictReader(Path(log_path).open()))
    if not rows:
        return
    fig, axes = plt.subplots(1, 3, figsize=(14, 3.6))
    for split, style in (('train', '-'), ('val', 'o-')):
        r = [x for x in rows if x['split'] == split]
        if not r:
            continue
        s = [int(x['step']) for x in r]
        axes[0].plot(s, [float(x['loss']) for x in r], style, label=f'{split} total')
        axes[0].plot(s, [float(x['joint']) for x in r], style, alpha=0.6,
                     label=f'{split} joint (cm)')
    v = [x for x in rows if x['split'] == 'val' and x['ome_deg']]
    if v:
        s = [int(x['step']) for x in v]
        axes[1].plot(s, [float(x['tme_mm']) for x in v], 'o-', label='TME (mm)')
        axes[1].plot(s, [float(x['jme_mm']) for x in v], 'o-', label='joint ME (mm)')
        axes[2].plot(s, [float(x['ome_deg']) for x in v], 'o-', label='OME (deg)')
        axes[2].plot(s, [float(x['tilt_deg']) for x in v], 'o-', label='tilt (deg)')
    axes[0].set_yscale('log')
    for a, title in zip(axes, ('loss', 'validation: translation', 'validation: orientation')):
        a.set_xlabel('step')
        a.set_title(title, fontsize=9)
        a.legend(fontsize=8)
        a.grid(alpha=0.3)
    axes[1].set_yscale('log')
    axes[2].set_yscale('log')
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    plt.close(fig)
