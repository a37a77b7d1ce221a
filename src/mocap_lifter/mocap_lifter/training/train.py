"""Training of the MotioNet lifter (``mocap train lifter``; no ROS imports).

Losses (MotioNet §3.2, eq. 5-12, weights in :class:`TrainConfig`):

* ``joints``: root-relative joint positions of the FK output vs ground truth (camera frame),
  end effectors weighted ``end_effector_weight`` (eq. 6);
* ``root``: root depth (eq. 8, L1 on Z) and the 3D root position;
* ``skeleton``: bone-group lengths vs the ground-truth skeleton (eq. 5);
* ``contact``: heel/toe contact labels (BCE, eq. 10) and ``contact_velocity``: the velocity of
  the foot joints during labelled contact (eq. 11);
* ``rotation`` (optional): ``1 - |<q, q_gt>|`` per joint (all rotations are against one
  rest pose);
* ``adversarial`` (optional): least-squares GAN on rotation velocities with per-joint
  discriminators (eq. 7);
* ``tpose`` (optional): MotioNet's reference T-pose: a share ``tpose_fraction`` of the
  windows shows the character standing in its T-pose, whose rotations must come out as the
  identity (``1 - |<q, q_T>|`` on those windows only).

Checkpoints (``last.pt``, resumable) and a CSV log are written to the run directory; a loss
curve PNG is drawn at the end (and on every validation).
"""

from __future__ import annotations

import csv
import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import torch
from torch import nn

from mocap_core.checkpoint import WeightsError, load_checkpoint
from mocap_core.data.motion import Motion
from mocap_core.data.synth2d import CameraSampling
from mocap_core.skeleton import END_EFFECTORS, JOINT_INDEX, NUM_JOINTS

from ..features import NUM_FEATURES, virtual_camera_window
from ..model import LifterConfig, MotioNet, RotationDiscriminator
from ..weights import load_weights, plain_data, save_weights
from .common import cosine_lr, plot_log, to_torch
from .samples import Augmentation, MixedSampler, RenderedWindowSampler, WindowSampler

_FOOT_JOINTS = [JOINT_INDEX[n] for n in ('left_ankle', 'left_toe', 'right_ankle', 'right_toe')]


@dataclass
class TrainConfig:
    """Optimisation settings; the defaults are the shipped CPU configuration."""

    steps: int = 6000
    batch: int = 32
    window: int = 64
    lr: float = 1e-3
    lr_final: float = 5e-5
    seed: int = 0
    w_joints: float = 1.0
    w_root: float = 0.2
    w_skeleton: float = 1.0
    w_contact: float = 0.05
    w_contact_velocity: float = 1.0
    w_rotation: float = 0.0
    w_adversarial: float = 0.0
    #: weight of the acceleration term: mean distance between the predicted and true
    #: root-relative joint accelerations (m per frame squared). Penalises jitter directly.
    w_acceleration: float = 0.0
    end_effector_weight: float = 2.0
    clean_fraction: float = 0.25   # share of training windows with clean keypoints
    tpose_fraction: float = 0.0    # share of T-pose windows (reference T-pose loss)
    w_tpose: float = 0.0           # weight of the T-pose loss (identity rotations)
    init: Optional[str] = None     # weights to start from (fine-tuning) instead of random
    #: joints whose rotation outputs are re-initialised after ``init`` (the output rows of
    #: E_Q for them: zero weights, identity bias). For a joint stuck in a bad state that
    #: fine-tuning cannot leave: the sign-invariant rotation loss pulls a rotation that is
    #: about 90 deg off in opposite directions on different frames (docs/lifter.md).
    reset_joints: Tuple[str, ...] = ()
    #: train only the reset joints' output rows (:func:`reset_only_parameters`): the rest of
    #: the network, its batch-norm statistics included, stays exactly as ``init`` left it
    train_reset_only: bool = False
    #: modules left as ``init`` made them (names or name prefixes of ``named_modules``, e.g.
    #: ``e_q.expand``, ``e_q.blocks.0``): their parameters get no gradient and their batch
    #: norm and dropout stay in inference mode
    freeze: Tuple[str, ...] = ()
    #: share of keypoint windows placed where the real detector puts its points
    #: (mocap_core/data/detector_placement.json) instead of on the joints
    placement_fraction: float = 0.0
    #: share of windows taken from rendered clips (real detector on rendered people), and
    #: the folder of the renders (default ~/.cache/mocap/render; its train split is used)
    rendered_fraction: float = 0.0
    renders: Optional[str] = None
    #: probability that a rendered window is mirrored left-right (image, keypoints, targets)
    rendered_flip: float = 0.0
    #: 'committed' trains on the committed training split; 'strict' on the strict one
    #: (whole motion families held out, mocap_core.data.strict_split)
    split: str = 'committed'
    #: projected-keypoint cameras: 'default' (data.synth2d.CameraSampling), 'wide' (the
    #: rendered benchmark's ranges: height 0.2-3.5 m, distance 2-12 m, field of view 35-100
    #: degrees, portrait and landscape images) or 'steep' ('wide', a quarter of the cameras
    #: looking down from 25-65 degrees above the person)
    cameras: str = 'default'
    validate_every: int = 500
    checkpoint_every: int = 250
    threads: int = 2
    model: LifterConfig = field(default_factory=LifterConfig)

    @classmethod
    def from_dict(cls, d: Dict) -> 'TrainConfig':
        d = dict(d)
        model = LifterConfig(**d.pop('model', {}))
        for key in ('reset_joints', 'freeze'):
            if key in d:
                d[key] = tuple(d[key])
        return cls(model=model, **d)


def losses(out: Dict[str, torch.Tensor], gt: Dict[str, torch.Tensor], cfg: TrainConfig,
           disc: Optional[RotationDiscriminator] = None) -> Dict[str, torch.Tensor]:
    """The loss terms (unweighted) for one batch."""
    weights = torch.ones(NUM_JOINTS, device=out['positions'].device)
    weights[list(END_EFFECTORS)] = cfg.end_effector_weight
    p = out['positions'] - out['positions'][:, :, :1]
    g = gt['positions'] - gt['positions'][:, :, :1]
    joints = ((p - g).norm(dim=-1) * weights).mean() / weights.mean()
    # depth error relative to the depth (the 2D scale fixes depth only up to the body size)
    root = ((out['depth'] - gt['root'][..., 2]).abs() / gt['root'][..., 2]).mean() + \
        (out['root'] - gt['root']).norm(dim=-1).mean()
    skeleton = (out['lengths'] - gt['lengths']).abs().mean()
    contact = nn.functional.binary_cross_entropy_with_logits(out['contacts'], gt['contacts'])
    feet = out['positions'][:, :, _FOOT_JOINTS]
    vel = (feet[:, 1:] - feet[:, :-1]).norm(dim=-1)
    both = gt['contacts'][:, 1:] * gt['contacts'][:, :-1]
    contact_velocity = (vel * both).sum() / both.sum().clamp_min(1.0)
    terms = {'joints': joints, 'root': root, 'skeleton': skeleton, 'contact': contact,
             'contact_velocity': contact_velocity}
    dot = (out['rotations'] * gt['rotations']).sum(dim=-1).abs()
    terms['rotation'] = (1.0 - dot).mean()
    # second differences over time of the root-relative joints (m / frame^2)
    acc_p = p[:, 2:] - 2 * p[:, 1:-1] + p[:, :-2]
    acc_g = g[:, 2:] - 2 * g[:, 1:-1] + g[:, :-2]
    terms['acceleration'] = (acc_p - acc_g).norm(dim=-1).mean()
    if 'tpose' in gt:   # T-pose windows: their rotations must come out as the T-pose's
        mask = gt['tpose'].to(dot.dtype)
        terms['tpose'] = ((1.0 - dot).mean(dim=(1, 2)) * mask).sum() / mask.sum().clamp_min(1.0)
    if disc is not None:
        dq = out['rotations'][:, 1:] - out['rotations'][:, :-1]
        terms['adversarial'] = ((1.0 - disc(dq)) ** 2).mean()
    return terms


def total_loss(terms: Dict[str, torch.Tensor], cfg: TrainConfig) -> torch.Tensor:
    return (cfg.w_joints * terms['joints'] + cfg.w_root * terms['root']
            + cfg.w_skeleton * terms['skeleton'] + cfg.w_contact * terms['contact']
            + cfg.w_contact_velocity * terms['contact_velocity']
            + cfg.w_rotation * terms['rotation']
            + cfg.w_acceleration * terms['acceleration']
            + cfg.w_tpose * terms.get('tpose', torch.zeros(()))
            + cfg.w_adversarial * terms.get('adversarial', torch.zeros(())))


def _output_rows(joints: Sequence[str]) -> List[slice]:
    """The rows of E_Q's last 1x1 convolution that give ``joints``' rotations (names of
    :data:`mocap_core.skeleton.JOINT_NAMES`, four rows each). ValueError for an unknown name."""
    from mocap_core.skeleton import JOINT_INDEX
    unknown = [j for j in joints if j not in JOINT_INDEX]
    if unknown:
        raise ValueError(f'reset_joints: unknown joints {unknown}')
    return [slice(4 * JOINT_INDEX[j], 4 * JOINT_INDEX[j] + 4) for j in joints]


def reset_rotation_outputs(model: MotioNet, joints: Sequence[str]) -> None:
    """Re-initialise the rotation outputs of ``joints`` (:func:`_output_rows`): zero weights
    and the identity quaternion (x, y, z, w = 0, 0, 0, 1) as bias, so each starts at the
    rest pose and learns from there. Raises ValueError for an unknown name."""
    shrink = model.e_q.shrink
    with torch.no_grad():
        for rows in _output_rows(joints):
            shrink.weight[rows] = 0.0
            shrink.bias[rows] = torch.tensor([0.0, 0.0, 0.0, 1.0], dtype=shrink.bias.dtype)


def freeze_modules(model: MotioNet, names: Sequence[str]) -> List[nn.Module]:
    """Stop the gradients of the modules named (or prefixed) by ``names`` and return those
    modules (the training loop keeps them in inference mode). Raises ValueError for a name
    that matches no module."""
    mods = dict(model.named_modules())
    out: List[nn.Module] = []
    for name in names:
        hit = [m for n, m in mods.items() if n == name or n.startswith(name + '.')]
        if not hit:
            raise ValueError(f'freeze: no module {name!r} in the network')
        for m in hit:
            for p in m.parameters():
                p.requires_grad_(False)
        out += hit
    return out


def reset_only_parameters(model: MotioNet, joints: Sequence[str]) -> List[torch.Tensor]:
    """Freeze the network except the rotation outputs of ``joints`` (their rows of E_Q's last
    1x1 convolution, as :func:`reset_rotation_outputs`): every other parameter stops
    requiring a gradient, and the gradients of the other rows of that layer are masked to
    zero. Returns the parameters to optimise (that layer's weight and bias); with zero
    gradients Adam leaves the masked rows as they are. Raises ValueError without joints."""
    if not joints:
        raise ValueError('train_reset_only needs reset_joints')
    rows = _output_rows(joints)
    for p in model.parameters():
        p.requires_grad_(False)
    shrink = model.e_q.shrink
    mask = torch.zeros(shrink.bias.shape[0], device=shrink.bias.device)
    for r in rows:
        mask[r] = 1.0
    shrink.weight.requires_grad_(True)
    shrink.bias.requires_grad_(True)
    shrink.weight.register_hook(lambda g: g * mask[:, None, None])
    shrink.bias.register_hook(lambda g: g * mask)
    return [shrink.weight, shrink.bias]


def feature_statistics(sampler: WindowSampler, batches: int = 20, size: int = 32):
    """Per-channel mean and std of the input features over random training windows."""
    feats = np.concatenate([sampler.batch(size)['features'].reshape(-1, NUM_FEATURES)
                            for _ in range(batches)])
    return feats.mean(axis=0), feats.std(axis=0)


def train(train_motions: Sequence[Motion], val_motions: Sequence[Motion], run_dir: Path,
          cfg: TrainConfig, device: str = 'cpu', resume: bool = True,
          progress: bool = True) -> Path:
    """Train, checkpointing to ``run_dir``; returns the path of the final weights."""
    from tqdm import tqdm

    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / 'config.json').write_text(json.dumps(asdict(cfg), indent=1))
    placement = None
    if cfg.placement_fraction > 0:
        from mocap_core.data.detector_placement import PLACEMENT_PATH, DetectorPlacement
        placement = DetectorPlacement.load(PLACEMENT_PATH)
    sampler = WindowSampler(train_motions, cfg.window, seed=cfg.seed,
                            aug=Augmentation(clean_prob=cfg.clean_fraction,
                                             tpose_prob=cfg.tpose_fraction,
                                             placement=placement,
                                             placement_prob=cfg.placement_fraction,
                                             camera=camera_sampling(cfg.cameras)))
    val_sampler = WindowSampler(val_motions, cfg.window, seed=12345, aug=Augmentation())
    val_batches = [val_sampler.batch(cfg.batch) for _ in range(4)]
    rendered_val = None
    if cfg.rendered_fraction > 0:
        sampler, rendered_val = _with_renders(sampler, cfg)
    if cfg.model.virtual_camera:
        val_batches = [virtual_camera_window(b) for b in val_batches]
        if rendered_val is not None:
            rendered_val = [virtual_camera_window(b) for b in rendered_val]

    model = MotioNet(cfg.model).to(device)
    disc = RotationDiscriminator().to(device) if cfg.w_adversarial > 0 else None
    frozen = freeze_modules(model, cfg.freeze)
    params = (reset_only_parameters(model, cfg.reset_joints) if cfg.train_reset_only
              else [p for p in model.parameters() if p.requires_grad])
    opt = torch.optim.Adam(params, lr=cfg.lr)
    opt_d = torch.optim.Adam(disc.parameters(), lr=cfg.lr) if disc is not None else None
    step = 0
    ckpt = run_dir / 'last.pt'
    if resume and ckpt.exists():
        state = load_checkpoint(ckpt, map_location=device,
                                 required=('model', 'optimizer', 'step'))
        model.load_state_dict(state['model'])
        opt.load_state_dict(state['optimizer'])
        if disc is not None and 'disc' in state:
            disc.load_state_dict(state['disc'])
            opt_d.load_state_dict(state['optimizer_d'])
        step = state['step']
        if isinstance(sampler, MixedSampler):
            sampler.reseed(cfg.seed + step)
        else:
            sampler.rng = np.random.default_rng(cfg.seed + step)
    elif cfg.init:
        init = load_weights(Path(cfg.init), device, causal=cfg.model.causal)
        # the same network; the frame of its input may change (virtual_camera)
        if _network_shape(init.cfg) != _network_shape(model.cfg):
            raise ValueError(f'--init weights {cfg.init} have another network configuration: '
                             f'{asdict(init.cfg)} vs {asdict(model.cfg)}')
        model.load_state_dict(init.state_dict())
        reset_rotation_outputs(model, cfg.reset_joints)
    else:
        mean, std = feature_statistics(sampler)
        model.set_normalisation(mean, std)
    real_rotations = _real_rotation_velocities(train_motions) if disc is not None else None

    log_path = run_dir / 'log.csv'
    new_log = not log_path.exists() or step == 0
    log = log_path.open('w' if new_log else 'a', newline='')
    writer = csv.writer(log)
    if new_log:
        writer.writerow(['step', 'split', 'loss', 'joints_mm', 'root_mm', 'skeleton_mm',
                         'contact', 'contact_velocity_mm', 'rotation', 'lr', 'seconds',
                         'acceleration_mm'])
    t0 = time.time()
    bar = tqdm(total=cfg.steps, initial=step, disable=not progress, desc='train lifter')
    while step < cfg.steps:
        lr = cosine_lr(step, cfg.steps, cfg.lr, cfg.lr_final)
        for g in opt.param_groups:
            g['lr'] = lr
        model.train(not cfg.train_reset_only)   # frozen: batch norm and dropout as at init
        for m in frozen:
            m.eval()
        batch = sampler.batch(cfg.batch)
        if cfg.model.virtual_camera:
            batch = virtual_camera_window(batch)
        gt = to_torch(batch, device)
        out = model(gt['features'], gt['root_2d'], gt['scale'])
        terms = losses(out, gt, cfg, disc)
        loss = total_loss(terms, cfg)
        opt.zero_grad()
        loss.backward()
        nn.utils.clip_grad_norm_(model.parameters(), 5.0)
        opt.step()
        if disc is not None:
            _discriminator_step(disc, opt_d, out['rotations'].detach(), real_rotations,
                                sampler.rng, device)
        step += 1
        bar.update(1)
        if step % 50 == 0:
            writer.writerow(_row(step, 'train', loss, terms, lr, time.time() - t0))
            bar.set_postfix(loss=f'{loss.item():.4f}', mm=f"{1000 * terms['joints'].item():.0f}")
        if step % cfg.validate_every == 0 or step == cfg.steps:
            v = validate(model, val_batches, cfg, device)
            writer.writerow(_row(step, 'val', v['loss'], v, lr, time.time() - t0))
            if rendered_val is not None:
                v = validate(model, rendered_val, cfg, device)
                writer.writerow(_row(step, 'val_rendered', v['loss'], v, lr,
                                     time.time() - t0))
            log.flush()
            plot_log(log_path, run_dir / 'loss.png')
        if step % cfg.checkpoint_every == 0 or step == cfg.steps:
            state = {'model': model.state_dict(), 'optimizer': opt.state_dict(), 'step': step,
                     'config': plain_data(asdict(cfg))}
            if disc is not None:
                state.update(disc=disc.state_dict(), optimizer_d=opt_d.state_dict())
            torch.save(state, ckpt.with_suffix('.tmp'))
            ckpt.with_suffix('.tmp').replace(ckpt)
    bar.close()
    log.close()
    weights = run_dir / 'lifter.pt'
    save_weights(model, weights, {'steps': step, 'train_seconds': time.time() - t0})
    return weights


def _network_shape(cfg: LifterConfig) -> Dict:
    """The configuration without what leaves the network's layers as they are."""
    d = asdict(cfg)
    d.pop('virtual_camera', None)
    return d


#: the names of :func:`camera_sampling`
CAMERA_RANGES = ('default', 'wide', 'steep')


def camera_sampling(name: str) -> CameraSampling:
    """The projected-keypoint camera ranges of ``TrainConfig.cameras``."""
    if name == 'default':
        return CameraSampling()
    if name in ('wide', 'steep'):
        return CameraSampling(distance=(2.0, 12.0), height=(0.2, 3.5),
                              horizontal_fov=(35.0, 100.0), roll=(-5.0, 5.0),
                              image_sizes=((640, 480), (480, 640), (1280, 720), (720, 1280),
                                           (1920, 1080), (960, 540)),
                              steep_fraction=0.25 if name == 'steep' else 0.0)
    raise ValueError(f"unknown camera ranges {name!r} (use one of {', '.join(CAMERA_RANGES)})")


def _with_renders(sampler: WindowSampler, cfg: TrainConfig):
    """The training sampler mixed with rendered training windows, and a few fixed batches of
    rendered validation windows (None when no validation clip is rendered)."""
    from pathlib import Path as _P

    from mocap_core.render.batch import DEFAULT_OUT
    from mocap_core.render.clip import iter_done
    root = _P(cfg.renders) if cfg.renders else DEFAULT_OUT
    keep = None
    if cfg.split == 'strict':
        from mocap_core.data.strict_split import family_of
        keep = lambda clip: family_of(clip) is None  # noqa: E731
    train_dirs = list(iter_done(root, 'train'))
    if not train_dirs:
        raise ValueError(f'rendered_fraction > 0 but no rendered training clip under {root} '
                         '(mocap data render --split train)')
    rendered = RenderedWindowSampler(train_dirs, cfg.window, seed=cfg.seed + 7, keep=keep,
                                     flip=cfg.rendered_flip)
    print(f'rendered training clips: {len(rendered)} (of {len(train_dirs)} under {root})',
          flush=True)
    val_dirs = list(iter_done(root, 'validation'))
    batches = None
    if val_dirs:
        rv = RenderedWindowSampler(val_dirs, cfg.window, seed=54321)
        batches = [{k: np.stack([it[k] for it in items]) for k in items[0]}
                   for items in ([rv.sample() for _ in range(cfg.batch)] for _ in range(4))]
    return MixedSampler(sampler, rendered, cfg.rendered_fraction), batches


def _row(step, split, loss, terms, lr, seconds) -> List:
    f = lambda k: float(terms[k]) if k in terms else float('nan')  # noqa: E731
    return [step, split, float(loss), 1000 * f('joints'), 1000 * f('root'),
            1000 * f('skeleton'), f('contact'), 1000 * f('contact_velocity'), f('rotation'),
            lr, round(seconds, 1), 1000 * f('acceleration')]


@torch.no_grad()
def validate(model: MotioNet, batches, cfg: TrainConfig, device: str) -> Dict[str, float]:
    model.eval()
    acc: Dict[str, float] = {}
    for b in batches:
        gt = to_torch(b, device)
        terms = losses(model(gt['features'], gt['root_2d'], gt['scale']), gt, cfg)
        terms['loss'] = total_loss(terms, cfg)
        for k, v in terms.items():
            acc[k] = acc.get(k, 0.0) + float(v) / len(batches)
    return acc


def _real_rotation_velocities(motions: Sequence[Motion]) -> np.ndarray:
    from mocap_core.data.motion import make_continuous
    vel = [np.diff(make_continuous(m.rotations), axis=0) for m in motions]
    return np.concatenate(vel).astype(np.float32)


def _discriminator_step(disc, opt_d, fake_q, real_vel, rng, device) -> None:
    b, t = fake_q.shape[:2]
    idx = rng.integers(0, len(real_vel) - t, b)
    real = torch.as_tensor(np.stack([real_vel[i:i + t - 1] for i in idx]), device=device)
    fake = fake_q[:, 1:] - fake_q[:, :-1]
    loss = (disc(real) - 1).pow(2).mean() + disc(fake).pow(2).mean()
    opt_d.zero_grad()
    loss.backward()
    opt_d.step()


def export_checkpoint(checkpoint: Path, out: Path) -> Path:
    """Write inference weights from a training checkpoint (``last.pt``)."""
    state = load_checkpoint(checkpoint, required=('model', 'config', 'step'))
    try:
        cfg = TrainConfig.from_dict(state['config'])
        model = MotioNet(cfg.model)
        model.load_state_dict(state['model'])
    except (TypeError, ValueError, KeyError, RuntimeError) as exc:
        raise WeightsError(f'{checkpoint}: not a lifter training checkpoint '
                           f'({type(exc).__name__}: {str(exc)[:160]})') from None
    save_weights(model, Path(out), {'steps': state['step'], 'from_checkpoint': True})
    return Path(out)
