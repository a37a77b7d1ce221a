"""DyNet training: a differentiable rollout of the cycle and the training loop (no ROS imports).

``mocap train physics`` (:func:`main_train`) fits the gains of :class:`~mocap_physics.dynet.DyNet`
on the dataset's train split. :class:`Rollout` is a PyTorch version of steps 1, 3 and 4 of
:mod:`mocap_physics.cycle`: PD with the network's gains (eq. 7), forward dynamics (eq. 13;
with the residual root actuation kept the GRF cancels out of the motion)::

    qddot = M^-1 (tau - h) = a_des + M^-1 alpha,   a_des = kp o e - kd o qdot

the velocity update and the penetration/stick projection (eq. 15-16) on the active set the
QP solver found, then the integration on the Lie group. M (nv, nv), h (nv,) and the contact
Jacobians (4, 3, nv) come from Pinocchio at the current state as constants per sub-step.
Loss eq. 25 per frame (:func:`rollout_loss`)::

    L = |d(q_ref, q)|^2 + phi |tau / (m g)|^2,   phi = 1e-6

(means over the nv entries). ``q_ref`` is the ground truth while the targets carry
lifter-like noise (``reference='groundtruth'``, default), or the target itself
(``reference='target'``: eq. 25 literally). Windows of ``window`` frames are unrolled after
``burn_in`` frames run without gradient from the target, on random clips of the train split.
Outputs: ``run_dir``/dynet.pt (best validation error), log.csv, config.json; ``--install``
copies dynet.pt to the package's ``weights/`` (what ``gains_mode: learned`` loads by default).
Figures of past runs: ``docs/physics.md``.
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, List, Optional, Sequence, Tuple

import numpy as np
import pinocchio as pin
import torch

from mocap_core.pose import Pose
from mocap_core.rotations import (axis_angle_to_quat, quat_conjugate, quat_multiply,
                                  quat_rotate, quat_to_axis_angle)

from ..cycle import stick_rows
from ..cycle_params import PhysicsParams
from ..dynet import WEIGHTS_DIR, DyNet, check_layout, features, make_dynet
from ..model import PhysicsModel
from ..qp import PenetrationQP
from .evaluate import dataset_clip, lifter_noise

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


# ---------------------------------------------------------------------------------------------
# Lie-group operations in torch on Pinocchio's q (nq,) and v (nv,) layout (ball joints
# contiguous: check_layout), quaternions x, y, z, w
# ---------------------------------------------------------------------------------------------
def t_difference(q0: torch.Tensor, q1: torch.Tensor) -> torch.Tensor:
    """Tangent vector (nv,) from q0 to q1 (nq,), as ``PhysicsCycle._difference``: root
    R0^T (p1 - p0) (m, root frame) and log(q0^-1 q1), ball joints log(q0^-1 q1) (rad)."""
    r0 = quat_conjugate(q0[3:7])
    j0 = q0[7:].reshape(-1, 4)
    j1 = q1[7:].reshape(-1, 4)
    return torch.cat([quat_rotate(r0, q1[0:3] - q0[0:3]),
                      quat_to_axis_angle(quat_multiply(r0, q1[3:7])),
                      quat_to_axis_angle(quat_multiply(quat_conjugate(j0), j1)).reshape(-1)])


def t_integrate(q: torch.Tensor, dv: torch.Tensor) -> torch.Tensor:
    """q (+) dv for q (nq,), dv (nv,): root translation p + R dv_lin (first order),
    rotations q exp(dv_ang), renormalised."""
    r = q[3:7]
    rn = quat_multiply(r, axis_angle_to_quat(dv[3:6]))
    jn = quat_multiply(q[7:].reshape(-1, 4), axis_angle_to_quat(dv[6:].reshape(-1, 3)))
    jn = jn / jn.norm(dim=-1, keepdim=True)
    return torch.cat([q[0:3] + quat_rotate(r, dv[0:3]), rn / rn.norm(), jn.reshape(-1)])


# ---------------------------------------------------------------------------------------------
# differentiable rollout
# ---------------------------------------------------------------------------------------------
class Rollout:
    """The cycle's motion update (steps 1, 3, 4) in torch, for training DyNet."""

    def __init__(self, model: PhysicsModel, params: PhysicsParams) -> None:
        check_layout(model)
        self.m = model
        self.p = params
        self.pen = PenetrationQP(metric='diagonal')
        self.weight = model.weight
        self.reset_anchors()

    def reset_anchors(self) -> None:
        self.anchor = np.zeros((4, 2))
        self.anchored = np.zeros(4, dtype=bool)

    def _constants(self, q: np.ndarray, v: np.ndarray
                   ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """M (nv, nv), h (nv,), contact Jacobians (4, 3, nv), contact positions (4, 3)."""
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
              probs: np.ndarray, frame_dt: float
              ) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """One frame (k sub-steps, frame_dt s) from (q (nq,), v (nv,)) towards q_hat (nq,)
        with contact probabilities (4,); returns (q, v, mean |tau / m g|^2)."""
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
            e = t_difference(q, qh)
            dm = torch.from_numpy(np.diag(M).copy())
            if net is not None:
                kp, kd, alpha = net(features(qh, q, v, dm, e), dm)
            else:
                kp, kd, alpha = kp0, kd0, torch.zeros(m.nv, dtype=torch.float64)
            a_des = kp * e - kd * v
            tau = Mt @ a_des + alpha + torch.from_numpy(h)
            a = a_des + torch.linalg.solve(Mt, alpha)
            v_new = v + dt * a
            v_new = self._project(v_new, M, Jc, pos, mask, dt)
            q = t_integrate(q, v_new * dt)
            v = v_new
            tau_reg = tau_reg + ((tau / self.weight) ** 2).mean() / n_sub
        return q, v, tau_reg

    def _project(self, v_new: torch.Tensor, M: np.ndarray, Jc: np.ndarray, pos: np.ndarray,
                 mask: np.ndarray, dt: float) -> torch.Tensor:
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
                 phi: float = 1e-6) -> Tuple[torch.Tensor, float]:
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
                d = t_difference(q, torch.from_numpy(refs[t]))
                loss = loss + (d ** 2).mean() + phi * reg
                errs.append(float((d.detach() ** 2).mean()))
                n += 1
    return loss / max(n, 1), float(np.mean(errs)) if errs else float('nan')


# ---------------------------------------------------------------------------------------------
# training
# ---------------------------------------------------------------------------------------------
@dataclass
class TrainConfig:
    """Settings of :func:`train` (``mocap train physics``)."""

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


def _windows(motions: Sequence[Any], n: int, length: int,
             rng: np.random.Generator) -> List[Tuple[Any, int]]:
    """Up to ``n`` random (motion, start frame) windows of ``length`` frames."""
    out = []
    for _ in range(n):
        mo = motions[rng.integers(len(motions))]
        if mo.num_frames <= length:
            continue
        s = int(rng.integers(mo.num_frames - length))
        out.append((mo, s))
    return out


def _window_arrays(mo: Any, start: int, length: int, noise: bool, seed: int
                   ) -> Tuple[PhysicsModel, np.ndarray, np.ndarray, np.ndarray, float]:
    """(model, targets, refs, probs, fps) of a window of a dataset Motion (world frame)."""
    clip = dataset_clip(mo)
    sl = slice(start, start + length)
    clip = replace(clip, stamps=clip.stamps[sl], rotations=clip.rotations[sl],
                   root_positions=clip.root_positions[sl], contacts=clip.contacts[sl],
                   labels=clip.labels[sl], gt_rotations=clip.gt_rotations[sl],
                   gt_root_positions=clip.gt_root_positions[sl])
    noisy = lifter_noise(clip, seed) if noise else clip
    model = PhysicsModel(clip.skeleton)
    tq = np.array([model.pose_to_q(Pose(clip.skeleton, noisy.rotations[i],
                                        noisy.root_positions[i])) for i in range(length)])
    rq = np.array([model.pose_to_q(Pose(clip.skeleton, clip.gt_rotations[i],
                                        clip.gt_root_positions[i])) for i in range(length)])
    for arr in (tq, rq):
        for i in range(length):
            model.normalize(arr[i])
    return model, tq, rq, noisy.contacts, clip.fps


def train(train_motions: Sequence[Any], val_motions: Sequence[Any], run_dir: Path | str,
          cfg: TrainConfig = TrainConfig(), device: str = 'cpu',
          log: Callable[[str], None] = print) -> Path:
    """Train DyNet on :class:`mocap_core.data.motion.Motion` clips (world frame); writes
    ``run_dir``/dynet.pt, log.csv and config.json and returns the weights path."""
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


def main_train(args: argparse.Namespace) -> int:
    """``mocap train physics``."""
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
