"""DyNet: learned PD gains of the dynamic cycle (neural PhysCap §3.4.1, eq. 7, 25, appendix A).

The network (:class:`DyNet`) sees the target pose q_hat, the current pose q, the velocity
qdot, the mass matrix M (its diagonal, log scale) and the PD error e = d(q_hat, q), all
concatenated (appendix A), and outputs through two fully connected ReLU layers two heads:

    kp = 2 s_g o kp_ini   (s_g = sigmoid(.) in (0, 1))      alpha = gamma s_f   (s_f = tanh(.))

``kp_ini`` are the fixed gains of :class:`~mocap_physics.cycle.PhysicsParams` and gamma = 10
as in the paper. Deviations, stated: the gains are accelerations multiplied by M as in the
cycle (so ``kp_ini`` are the cycle's 400 / 3600 s^-2) and so is alpha: ``alpha = gamma s_f o
diag(M)``, an offset acceleration of at most 10 m/s^2 or rad/s^2 per DoF (10 N m on a toe of
1e-4 kg m^2 would be 1e5 rad/s^2: training diverged with plain newtons); the damping follows
the stiffness
so that every DoF stays critically damped (``kd = kd_ini sqrt(kp / kp_ini)``), and the pose
features are heading invariant (root height, gravity direction in the root frame, joint
quaternions; the root's horizontal position and yaw only enter through e). The output
layers start at zero, so an untrained DyNet *is* the fixed-gain cycle.

Training (``mocap train physics``, :func:`train`) runs a differentiable PyTorch version of
steps 1, 3 and 4 of the cycle: PD with the network's gains (eq. 7), forward dynamics (eq. 13:
with the residual root actuation kept, ``qddot = M^-1 (tau - h) = a_des + M^-1 alpha``, the
GRF cancels out of the motion), the velocity update and the penetration/stick projection
(eq. 15-16) on the active set the QP solver found, then the integration on the Lie group.
M, h and the contact Jacobians come from Pinocchio at the current state as constants per
sub-step (the paper's setting). Loss eq. 25 per frame: ``|d(q_ref, q)|^2 + phi |tau / mg|^2``
with phi = 1e-6. ``q_ref`` is the ground truth while the targets are the ground truth with
lifter-like noise (``reference='groundtruth'``, default: the gains should track the motion,
not the noise), or the target itself (``reference='target'``: eq. 25 literally). Windows of
``window`` frames are unrolled after ``burn_in`` frames run without gradient from the
target, on random clips of the train split.

Command: ``mocap train physics --install`` (1500 steps of one 17-frame window each, validation
every 250 steps on 12 windows of the validation split; the best weights go to
``runs/physics_dynet/dynet.pt`` and, with ``--install``, to the package's
``weights/dynet.pt``, which ``gains_mode: learned`` loads). Measured on this 2-core CPU
while another training ran: about 0.7 s per step, so roughly 20-25 minutes in all.
Evaluate with ``mocap eval physics --dynet runs/physics_dynet/dynet.pt``.
"""

from __future__ import annotations

import csv
import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Optional, Sequence

import numpy as np
import pinocchio as pin
import torch
from torch import nn

from .cycle import PhysicsParams, stick_rows
from .model import PhysicsModel
from .qp import PenetrationQP

WEIGHTS_DIR = Path(__file__).resolve().parents[1] / 'weights'
GAMMA = 10.0
_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


# ---------------------------------------------------------------------------------------------
# Lie-group helpers in torch (x, y, z, w quaternions; Pinocchio's q and v layout), vectorised
# over the ball joints (their blocks are contiguous in q and v: checked by _check_layout)
# ---------------------------------------------------------------------------------------------
def qmul(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    ax, ay, az, aw = a.unbind(-1)
    bx, by, bz, bw = b.unbind(-1)
    return torch.stack([aw * bx + ax * bw + ay * bz - az * by,
                        aw * by - ax * bz + ay * bw + az * bx,
                        aw * bz + ax * by - ay * bx + az * bw,
                        aw * bw - ax * bx - ay * by - az * bz], dim=-1)


def qconj(q: torch.Tensor) -> torch.Tensor:
    return q * torch.tensor([-1.0, -1.0, -1.0, 1.0], dtype=q.dtype)


def qrot(q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    u, w = q[..., :3], q[..., 3:]
    t = 2.0 * torch.cross(u, v, dim=-1)
    return v + w * t + torch.cross(u, t, dim=-1)


def qlog(q: torch.Tensor) -> torch.Tensor:
    """Rotation vector of unit quaternions (..., 4), smooth at the identity."""
    q = torch.where(q[..., 3:] < 0, -q, q)
    u, w = q[..., :3], q[..., 3:]
    n2 = (u * u).sum(-1, keepdim=True)
    small = n2 < 1e-10
    n = torch.sqrt(torch.where(small, torch.ones_like(n2), n2))
    scale = torch.where(small, 2.0 / w * (1.0 - n2 / (3.0 * w * w)),
                        2.0 * torch.atan2(n, w) / n)
    return u * scale


def qexp(r: torch.Tensor) -> torch.Tensor:
    """Unit quaternion of rotation vectors (..., 3), smooth at 0."""
    a2 = (r * r).sum(-1, keepdim=True)
    small = a2 < 1e-10
    a = torch.sqrt(torch.where(small, torch.ones_like(a2), a2))
    s = torch.where(small, 0.5 - a2 / 48.0, torch.sin(0.5 * a) / a)
    c = torch.where(small, 1.0 - a2 / 8.0, torch.cos(0.5 * a))
    return torch.cat([r * s, c], dim=-1)


def _check_layout(model: PhysicsModel) -> None:
    nj = len(model.idx_q) - 1
    if list(model.idx_q[1:]) != [7 + 4 * j for j in range(nj)] or \
            list(model.idx_v[1:]) != [6 + 3 * j for j in range(nj)]:
        raise ValueError('DyNet needs the ball joints contiguous in q and v')


def t_difference(model: PhysicsModel, q0: torch.Tensor, q1: torch.Tensor) -> torch.Tensor:
    """Tangent vector from q0 to q1, as ``PhysicsCycle._difference`` (root: R0^T dp and
    log(q0^-1 q1); ball joints: log(q0^-1 q1))."""
    r0 = qconj(q0[3:7])
    j0 = q0[7:].reshape(-1, 4)
    j1 = q1[7:].reshape(-1, 4)
    return torch.cat([qrot(r0, q1[0:3] - q0[0:3]), qlog(qmul(r0, q1[3:7])),
                      qlog(qmul(qconj(j0), j1)).reshape(-1)])


def t_integrate(model: PhysicsModel, q: torch.Tensor, dv: torch.Tensor) -> torch.Tensor:
    """q (+) dv: root translation p + R dv_lin (first order), rotations q exp(dv_ang),
    renormalised."""
    r = q[3:7]
    rn = qmul(r, qexp(dv[3:6]))
    jn = qmul(q[7:].reshape(-1, 4), qexp(dv[6:].reshape(-1, 3)))
    jn = jn / jn.norm(dim=-1, keepdim=True)
    return torch.cat([q[0:3] + qrot(r, dv[0:3]), rn / rn.norm(), jn.reshape(-1)])


def pose_features(model: PhysicsModel, q: torch.Tensor) -> torch.Tensor:
    """Heading-invariant features of a configuration: root height, gravity direction in the
    root frame, joint quaternions (w >= 0)."""
    up = torch.tensor([0.0, 0.0, 1.0], dtype=q.dtype)
    j = q[7:].reshape(-1, 4)
    j = torch.where(j[:, 3:] < 0, -j, j)
    return torch.cat([q[2:3], qrot(qconj(q[3:7]), up), j.reshape(-1)])


def feature_size(model: PhysicsModel) -> int:
    return 2 * (4 + 4 * (len(model.idx_q) - 1)) + 3 * model.nv


def features(model: PhysicsModel, q_hat: torch.Tensor, q: torch.Tensor, v: torch.Tensor,
             diag_m: torch.Tensor, e: torch.Tensor) -> torch.Tensor:
    """DyNet input (appendix A: all inputs concatenated), with fixed scalings."""
    return torch.cat([pose_features(model, q_hat), pose_features(model, q), 0.1 * v,
                      torch.log(torch.clamp(diag_m, min=1e-6)), 5.0 * e])


# ---------------------------------------------------------------------------------------------
# the network
# ---------------------------------------------------------------------------------------------
class DyNet(nn.Module):
    """Two hidden FC+ReLU layers, a sigmoid gain head and a tanh offset-force head."""

    def __init__(self, in_size: int, nv: int, kp_ini: Sequence[float], kd_ini: Sequence[float],
                 hidden: int = 256, gamma: float = GAMMA) -> None:
        super().__init__()
        self.config = dict(in_size=int(in_size), nv=int(nv), kp_ini=[float(x) for x in kp_ini],
                           kd_ini=[float(x) for x in kd_ini], hidden=int(hidden),
                           gamma=float(gamma))
        self.body = nn.Sequential(nn.Linear(in_size, hidden), nn.ReLU(),
                                  nn.Linear(hidden, hidden), nn.ReLU())
        self.gain_head = nn.Linear(hidden, nv)
        self.force_head = nn.Linear(hidden, nv)
        for head in (self.gain_head, self.force_head):   # start as the fixed-gain cycle
            nn.init.zeros_(head.weight)
            nn.init.zeros_(head.bias)
        self.register_buffer('kp_ini', torch.tensor(kp_ini, dtype=torch.float64))
        self.register_buffer('kd_ini', torch.tensor(kd_ini, dtype=torch.float64))
        self.gamma = float(gamma)

    def forward(self, x: torch.Tensor, diag_m: torch.Tensor):
        """x (..., in_size), diag M (..., nv) -> kp, kd, alpha (..., nv)."""
        hid = self.body(x.to(self.gain_head.weight.dtype))
        s_g = torch.sigmoid(self.gain_head(hid)).to(self.kp_ini.dtype)
        s_f = torch.tanh(self.force_head(hid)).to(self.kp_ini.dtype)
        kp = 2.0 * s_g * self.kp_ini
        kd = self.kd_ini * torch.sqrt(2.0 * s_g)
        return kp, kd, self.gamma * s_f * diag_m

    def save(self, path, extra: Optional[dict] = None) -> None:
        torch.save({'config': self.config, 'state': self.state_dict(), 'extra': extra or {}},
                   str(path))

    @classmethod
    def load(cls, path, map_location='cpu') -> 'DyNet':
        ck = torch.load(str(path), map_location=map_location, weights_only=False)
        net = cls(**ck['config'])
        net.load_state_dict(ck['state'])
        net.eval()
        return net


def make_dynet(model: PhysicsModel, params: PhysicsParams, hidden: int = 256) -> DyNet:
    kp, kd = params.gains(model.nv)
    return DyNet(feature_size(model), model.nv, kp, kd, hidden).double()


class LearnedGains:
    """DyNet for the numpy cycle: ``(q_hat, q, v, diag M, e) -> kp, kd, alpha`` (numpy)."""

    def __init__(self, path, model: PhysicsModel) -> None:
        self.path = str(path)
        self.net = DyNet.load(path).double()
        if self.net.config['nv'] != model.nv or \
                self.net.config['in_size'] != feature_size(model):
            raise ValueError(f'DyNet weights {path} do not fit the skeleton model '
                             f"(nv {self.net.config['nv']} vs {model.nv})")
        _check_layout(model)
        self.model = model

    def __call__(self, q_hat, q, v, diag_m, e):
        with torch.no_grad():
            t = [torch.from_numpy(np.ascontiguousarray(x, dtype=np.float64))
                 for x in (q_hat, q, v, diag_m, e)]
            kp, kd, alpha = self.net(features(self.model, *t), t[3])
        return kp.numpy(), kd.numpy(), alpha.numpy()


# ---------------------------------------------------------------------------------------------
# differentiable rollout
# ---------------------------------------------------------------------------------------------
class Rollout:
    """The cycle's motion update (steps 1, 3, 4) in torch, for training DyNet."""

    def __init__(self, model: PhysicsModel, params: PhysicsParams) -> None:
        _check_layout(model)
        self.m = model
        self.p = params
        self.pen = PenetrationQP(metric='diagonal')
        self.weight = model.weight
        self.reset_anchors()

    def reset_anchors(self) -> None:
        self.anchor = np.zeros((4, 2))
        self.anchored = np.zeros(4, dtype=bool)

    def _constants(self, q: np.ndarray, v: np.ndarray):
        m = self.m
        pin.computeAllTerms(m.model, m.data, q, v)
        pin.updateFramePlacements(m.model, m.data)
        M = np.triu(m.data.M)
        M = M + np.triu(M, 1).T
        Jc = np.array([pin.getFrameJacobian(m.model, m.data, f, _LWA)[:3]
                       for f in m.contact_frame_ids])
        pos = np.array([m.data.oMf[f].translation for f in m.contact_frame_ids])
        return M, m.data.nle.copy(), Jc, pos

    def frame(self, net: Optional[DyNet], q: torch.Tensor, v: torch.Tensor, q_hat: np.ndarray,
              probs: np.ndarray, frame_dt: float):
        """One frame (k sub-steps) from (q, v) towards q_hat; returns (q, v, |tau/mg|^2)."""
        p, m = self.p, self.m
        n_sub = max(int(p.substeps), int(np.ceil(frame_dt / p.max_substep - 1e-9)))
        dt = frame_dt / n_sub
        qh = torch.from_numpy(q_hat)
        kp0, kd0 = p.gains(m.nv)
        kp0, kd0 = torch.from_numpy(kp0), torch.from_numpy(kd0)
        mask = np.asarray(probs) > p.contact_probability_threshold
        if p.foot_stick:     # drag anchors (as the cycle)
            tgt = m.contact_positions(q_hat)[:, :2]
            d = tgt - self.anchor
            dist = np.linalg.norm(d, axis=1)
            far = self.anchored & (dist > p.stick_release)
            self.anchor[far] += d[far] * (1.0 - p.stick_release / dist[far])[:, None]
        tau_reg = torch.zeros((), dtype=torch.float64)
        for _ in range(n_sub):
            qn, vn = q.detach().numpy(), v.detach().numpy()
            M, h, Jc, pos = self._constants(qn, vn)
            Mt = torch.from_numpy(M)
            e = t_difference(m, q, qh)
            dm = torch.from_numpy(np.diag(M).copy())
            if net is not None:
                kp, kd, alpha = net(features(m, qh, q, v, dm, e), dm)
            else:
                kp, kd, alpha = kp0, kd0, torch.zeros(m.nv, dtype=torch.float64)
            a_des = kp * e - kd * v
            tau = Mt @ a_des + alpha + torch.from_numpy(h)
            a = a_des + torch.linalg.solve(Mt, alpha)
            v_new = v + dt * a
            v_new = self._project(v_new, M, Jc, pos, mask, dt)
            q = t_integrate(m, q, v_new * dt)
            v = v_new
            tau_reg = tau_reg + ((tau / self.weight) ** 2).mean() / n_sub
        return q, v, tau_reg

    def _project(self, v_new: torch.Tensor, M, Jc, pos, mask, dt) -> torch.Tensor:
        """Penetration + stick QP (as the cycle), solved in numpy for the active set; the
        projection on that set is differentiable in v."""
        p, m = self.p, self.m
        z, xy = pos[:, 2], pos[:, :2]
        vn = v_new.detach().numpy()
        zdot = Jc[:, 2, :] @ vn
        rows = (z < p.contact_height) | (z + dt * zdot < p.contact_height)
        active = mask & (z < p.contact_height)
        stick = active if (p.foot_stick and p.root_residual >= 1.0) else np.zeros(4, bool)
        new = stick & ~self.anchored
        self.anchor[new] = xy[new]
        self.anchored = stick.copy()
        b_all = np.minimum(-z / dt, p.recovery_speed)
        E_rows, e_vals = [], []
        if stick.any():
            target = p.stick_gain * (self.anchor - xy)
            sp = np.linalg.norm(target, axis=1, keepdims=True)
            target *= np.minimum(1.0, p.stick_speed / np.maximum(sp, 1e-12))
            keep = np.where(rows, np.maximum(zdot, b_all), zdot)
            E, ev = stick_rows(m.contact_feet, Jc, xy, target, stick, keep)
            E_rows, e_vals = list(E), list(ev)
            rows = rows & ~stick
        if not rows.any() and not E_rows:
            return v_new
        A, b = Jc[rows, 2, :], b_all[rows]
        d = np.maximum(np.diag(M), 1e-6)
        E = np.array(E_rows).reshape(-1, m.nv)
        ev = np.array(e_vals)
        res = self.pen.solve(vn, A, b, solve_metric=lambda X: X / d[:, None],
                             scale=m.body_mass, A_eq=E if len(ev) else None,
                             b_eq=ev if len(ev) else None)
        if not res.ok:
            return v_new
        y = res.impulses
        act = np.concatenate([y[:len(b)] > 1e-12, np.ones(len(ev), dtype=bool)])
        if not act.any():
            return v_new
        G = np.concatenate([A, E])[act]
        r = np.concatenate([b, ev])[act]
        Gt = torch.from_numpy(G)
        winv = torch.from_numpy(1.0 / d)
        S = Gt @ (winv[:, None] * Gt.T)
        lam = torch.linalg.solve(S + 1e-12 * torch.eye(len(r), dtype=S.dtype),
                                 torch.from_numpy(r) - Gt @ v_new)
        return v_new + winv * (Gt.T @ lam)


def rollout_loss(rollout: Rollout, net: Optional[DyNet], targets: np.ndarray,
                 refs: np.ndarray, probs: np.ndarray, fps: float, burn_in: int,
                 phi: float = 1e-6):
    """Loss eq. 25 over frames ``burn_in:`` of a window (targets, refs: (T, nq) configs).

    Starts at the first target (lifted out of the floor) at rest; the burn-in frames run
    without gradient. Returns (loss tensor, mean tracking error in the tangent space)."""
    m = rollout.m
    q0 = targets[0].copy()
    low = m.contact_positions(q0)[:, 2].min()
    if low < 0:
        q0[2] -= low
    q = torch.from_numpy(q0)
    v = torch.zeros(m.nv, dtype=torch.float64)
    rollout.reset_anchors()
    loss = torch.zeros((), dtype=torch.float64)
    errs = []
    n = 0
    for t in range(1, len(targets)):
        grad = t > burn_in
        with torch.set_grad_enabled(grad):
            if not grad:
                q, v = q.detach(), v.detach()
            q, v, reg = rollout.frame(net, q, v, targets[t], probs[t], 1.0 / fps)
            if grad:
                d = t_difference(m, q, torch.from_numpy(refs[t]))
                loss = loss + (d ** 2).mean() + phi * reg
                errs.append(float((d.detach() ** 2).mean()))
                n += 1
    return loss / max(n, 1), float(np.mean(errs)) if errs else float('nan')


# ---------------------------------------------------------------------------------------------
# training
# ---------------------------------------------------------------------------------------------
@dataclass
class TrainConfig:
    steps: int = 1500
    lr: float = 1e-4
    window: int = 8                # frames with gradient
    burn_in: int = 8               # frames before them, no gradient
    hidden: int = 256
    reference: str = 'groundtruth'   # or 'target' (eq. 25 literally)
    noise: bool = True               # lifter-like noise on the targets
    phi: float = 1e-6
    val_every: int = 250
    val_windows: int = 12
    seed: int = 0
    grad_clip: float = 1.0
    params: dict = field(default_factory=dict)   # PhysicsParams overrides


def _windows(motions, n: int, length: int, rng) -> list:
    out = []
    for _ in range(n):
        mo = motions[rng.integers(len(motions))]
        if mo.num_frames <= length:
            continue
        s = int(rng.integers(mo.num_frames - length))
        out.append((mo, s))
    return out


def _window_arrays(mo, start: int, length: int, noise: bool, seed: int):
    """(model, targets, refs, probs, fps) of a window of a dataset Motion (world frame)."""
    from .evaluate import dataset_clip, lifter_noise
    clip = dataset_clip(mo)
    sl = slice(start, start + length)
    from dataclasses import replace
    clip = replace(clip, stamps=clip.stamps[sl], rotations=clip.rotations[sl],
                   root_positions=clip.root_positions[sl], contacts=clip.contacts[sl],
                   labels=clip.labels[sl], gt_rotations=clip.gt_rotations[sl],
                   gt_root_positions=clip.gt_root_positions[sl])
    noisy = lifter_noise(clip, seed) if noise else clip
    model = PhysicsModel(clip.skeleton)
    from mocap_core.pose import Pose
    tq = np.array([model.pose_to_q(Pose(clip.skeleton, noisy.rotations[i],
                                        noisy.root_positions[i])) for i in range(length)])
    rq = np.array([model.pose_to_q(Pose(clip.skeleton, clip.gt_rotations[i],
                                        clip.gt_root_positions[i])) for i in range(length)])
    for arr in (tq, rq):
        for i in range(length):
            model.normalize(arr[i])
    return model, tq, rq, noisy.contacts, clip.fps


def train(train_motions, val_motions, run_dir, cfg: TrainConfig = TrainConfig(),
          device: str = 'cpu', log=print) -> Path:
    """Train DyNet; writes ``run_dir``/dynet.pt, log.csv and config.json."""
    if device != 'cpu':
        log('note: the rollout runs Pinocchio on the CPU; training stays on the CPU')
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / 'config.json').write_text(json.dumps(asdict(cfg), indent=1))
    rng = np.random.default_rng(cfg.seed)
    torch.manual_seed(cfg.seed)
    params = PhysicsParams(**cfg.params)
    length = cfg.burn_in + cfg.window + 1
    ref_model = PhysicsModel(train_motions[0].skeleton, params.body_mass)
    net = make_dynet(ref_model, params, cfg.hidden)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    val = _windows(val_motions, cfg.val_windows, length, np.random.default_rng(cfg.seed + 1))

    def validate(use_net: bool) -> float:
        errs = []
        with torch.no_grad():
            for k, (mo, s) in enumerate(val):
                model, tq, rq, pr, fps = _window_arrays(mo, s, length, cfg.noise, 10_000 + k)
                ref = tq if cfg.reference == 'target' else rq
                _, err = rollout_loss(Rollout(model, params), net if use_net else None, tq,
                                      ref, pr, fps, cfg.burn_in, cfg.phi)
                errs.append(err)
        return float(np.mean(errs))

    base = validate(False)
    log(f'validation tracking error of the fixed gains: {base:.3e} (mean squared tangent '
        'error)')
    rows = []
    best = np.inf
    t0 = time.time()
    for step in range(1, cfg.steps + 1):
        (mo, s), = _windows(train_motions, 1, length, rng) or [(train_motions[0], 0)]
        model, tq, rq, pr, fps = _window_arrays(mo, s, length, cfg.noise,
                                                int(rng.integers(1 << 30)))
        ref = tq if cfg.reference == 'target' else rq
        loss, err = rollout_loss(Rollout(model, params), net, tq, ref, pr, fps, cfg.burn_in,
                                 cfg.phi)
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(net.parameters(), cfg.grad_clip)
        opt.step()
        row = {'step': step, 'loss': float(loss.detach()), 'train_err': err, 'val_err': '',
               'seconds': round(time.time() - t0, 1)}
        if step % cfg.val_every == 0 or step == cfg.steps:
            v = validate(True)
            row['val_err'] = v
            log(f'step {step}: loss {row["loss"]:.3e}, validation error {v:.3e} (fixed gains '
                f'{base:.3e}), {time.time() - t0:.0f} s')
            if v < best:
                best = v
                net.save(run_dir / 'dynet.pt', {'val_err': v, 'fixed_val_err': base,
                                                'step': step, 'train': asdict(cfg)})
        rows.append(row)
        if step % 20 == 0 or step == cfg.steps:
            with open(run_dir / 'log.csv', 'w', newline='') as f:
                w = csv.DictWriter(f, fieldnames=list(rows[0]))
                w.writeheader()
                w.writerows(rows)
    if not (run_dir / 'dynet.pt').exists():
        net.save(run_dir / 'dynet.pt', {'fixed_val_err': base, 'train': asdict(cfg)})
    return run_dir / 'dynet.pt'


def main_train(args) -> int:
    """``mocap train physics``."""
    import shutil

    from mocap_core.data.dataset import load_dataset

    cfg = TrainConfig()
    if args.steps:
        cfg.steps = args.steps
    print('loading the dataset (train and validation splits) ...', flush=True)
    tr = load_dataset('train')
    va = load_dataset('validation')
    if args.clips:
        tr = tr[:args.clips]
    print(f'{len(tr)} training clips, {len(va)} validation clips', flush=True)
    path = train(tr, va, args.run_dir, cfg, args.device)
    print(f'weights: {path}')
    if args.install:
        WEIGHTS_DIR.mkdir(exist_ok=True)
        shutil.copy(path, WEIGHTS_DIR / 'dynet.pt')
        print(f"installed {WEIGHTS_DIR / 'dynet.pt'}")
    return 0
