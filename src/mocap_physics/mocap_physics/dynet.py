"""DyNet: learned PD gains of the dynamic cycle (neural PhysCap §3.4.1, eq. 7, appendix A).

Runtime part (no ROS imports, no training code): the network, its input features, its
weights file and the adapter the numpy cycle calls (:class:`LearnedGains`). Training and the
differentiable rollout live in :mod:`mocap_physics.training.train_dynet`.

Input (appendix A: everything concatenated; :func:`features`), for J joints,
nv = 6 + 3 (J - 1) and ``in_size = 17 J + 9`` (315 for the 18-joint skeleton)::

    x = [f(q_hat) (4 J), f(q) (4 J), 0.1 qdot (nv), log diag M(q) (nv), 5 e (nv)]
    f(q) = [root height (1, m), gravity direction in the root frame (3),
            joint quaternions x, y, z, w with w >= 0 (4 (J - 1))]

with e = d(q_hat, q) the cycle's tangent-space PD error (root translation in the root frame,
m; rotation vectors, rad). The features are heading invariant: the root's horizontal
position and yaw enter only through e.

Network: two fully connected ReLU layers of ``hidden`` units, then two heads (nv each)::

    kp = 2 s_g o kp_ini,  kd = kd_ini o sqrt(2 s_g),  alpha = gamma s_f o diag(M)
    s_g = sigmoid(.) in (0, 1),  s_f = tanh(.) in (-1, 1),  gamma = 10

``kp_ini`` / ``kd_ini`` are the fixed gains of :class:`~.cycle_params.PhysicsParams`
(accelerations: s^-2, s^-1, multiplied by M(q) in the cycle), so alpha is an offset
acceleration of at most gamma (m/s^2 or rad/s^2) per DoF, in N or N m once scaled by
diag(M). The heads start at zero: an untrained DyNet is the fixed-gain cycle. Deviations
from the paper and their reasons: ``docs/physics.md``.

Weights file (``DyNet.save``; read with :func:`mocap_core.checkpoint.load_checkpoint`, tensors
and plain data only): ``{'config': {in_size, nv, kp_ini, kd_ini, hidden, gamma}, 'state':
state_dict, 'extra': {...}}``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional, Sequence, Tuple, Union

import numpy as np
import torch
from torch import nn

from mocap_core.checkpoint import WeightsError, load_checkpoint
from mocap_core.rotations import quat_canonical, quat_conjugate, quat_rotate

from .cycle_params import PhysicsParams
from .model import PhysicsModel

#: Where ``mocap train physics --install`` puts ``dynet.pt`` (the default weights of the
#: node's ``gains_mode: learned``).
WEIGHTS_DIR = Path(__file__).resolve().parents[1] / 'weights'
#: gamma of the offset head (appendix A).
GAMMA = 10.0

PathLike = Union[str, Path]


def dynet_sizes(num_joints: int) -> Tuple[int, int]:
    """(in_size, nv) of DyNet for a skeleton of ``num_joints`` joints (root included)."""
    nv = 6 + 3 * (num_joints - 1)
    return 2 * (4 + 4 * (num_joints - 1)) + 3 * nv, nv


def feature_size(model: PhysicsModel) -> int:
    """Length of the DyNet input for ``model`` (module docstring)."""
    return dynet_sizes(len(model.idx_q))[0]


def check_layout(model: PhysicsModel) -> None:
    """Raise ValueError unless the ball joints are contiguous in q and v (blocks of 4 and 3
    after the free flyer's 7 and 6), the layout the vectorised features rely on."""
    nj = len(model.idx_q) - 1
    if list(model.idx_q[1:]) != [7 + 4 * j for j in range(nj)] or \
            list(model.idx_v[1:]) != [6 + 3 * j for j in range(nj)]:
        raise ValueError('DyNet needs the ball joints contiguous in q and v')


def pose_features(q: torch.Tensor) -> torch.Tensor:
    """Heading-invariant features of a configuration q (nq,) -> (4 J,): root height (m),
    gravity direction (up, +z of the floor frame) in the root frame, joint quaternions
    (x, y, z, w; w >= 0)."""
    up = torch.tensor([0.0, 0.0, 1.0], dtype=q.dtype)
    joints = quat_canonical(q[7:].reshape(-1, 4))
    return torch.cat([q[2:3], quat_rotate(quat_conjugate(q[3:7]), up), joints.reshape(-1)])


def features(q_hat: torch.Tensor, q: torch.Tensor, v: torch.Tensor, diag_m: torch.Tensor,
             e: torch.Tensor) -> torch.Tensor:
    """DyNet input (module docstring): q_hat, q (nq,), v, diag_m, e (nv,) -> (in_size,)."""
    return torch.cat([pose_features(q_hat), pose_features(q), 0.1 * v,
                      torch.log(torch.clamp(diag_m, min=1e-6)), 5.0 * e])


class DyNet(nn.Module):
    """Two hidden FC+ReLU layers, a sigmoid gain head and a tanh offset head (module
    docstring).

    Args:
        in_size: input length (:func:`dynet_sizes`).
        nv: DoF count (output length of each head).
        kp_ini, kd_ini: (nv,) the fixed gains, s^-2 and s^-1.
        hidden: width of the hidden layers.
        gamma: scale of the offset head.
    """

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

    def forward(self, x: torch.Tensor, diag_m: torch.Tensor
                ) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """x (..., in_size), diag M (..., nv) -> kp (s^-2), kd (s^-1), alpha (..., nv)."""
        hid = self.body(x.to(self.gain_head.weight.dtype))
        s_g = torch.sigmoid(self.gain_head(hid)).to(self.kp_ini.dtype)
        s_f = torch.tanh(self.force_head(hid)).to(self.kp_ini.dtype)
        kp = 2.0 * s_g * self.kp_ini
        kd = self.kd_ini * torch.sqrt(2.0 * s_g)
        return kp, kd, self.gamma * s_f * diag_m

    def save(self, path: PathLike, extra: Optional[dict] = None) -> None:
        """Write the weights file (module docstring)."""
        torch.save({'config': self.config, 'state': self.state_dict(), 'extra': extra or {}},
                   str(path))

    @classmethod
    def load(cls, path: PathLike, map_location: str = 'cpu') -> 'DyNet':
        """Read a weights file written by :meth:`save` (tensors only, no code execution).

        Raises:
            WeightsError: the file is missing, corrupt, crafted, or its config / state do
                not describe a DyNet (one-line message naming the file).
        """
        ck = load_checkpoint(path, map_location=map_location, required=('config', 'state'))
        config, state = ck['config'], ck['state']
        if not isinstance(config, dict) or not isinstance(state, dict):
            raise WeightsError(f'{path}: not DyNet weights (config and state must be '
                               'dictionaries)')
        try:
            net = cls(**config)
            net.load_state_dict(state)
        except Exception as exc:  # noqa: BLE001 - TypeError, RuntimeError, ValueError, ...
            text = ' '.join(str(exc).split())[:160]
            raise WeightsError(f'{path}: not DyNet weights ({type(exc).__name__}: '
                               f'{text})') from None
        net.eval()
        return net

    def check_fits(self, num_joints: int, path: PathLike = '') -> None:
        """Raise WeightsError unless the network's sizes fit a skeleton of ``num_joints``."""
        in_size, nv = dynet_sizes(num_joints)
        if self.config['nv'] != nv or self.config['in_size'] != in_size:
            raise WeightsError(f'DyNet weights {path} do not fit the {num_joints}-joint '
                               f"skeleton (nv {self.config['nv']} vs {nv}, input "
                               f"{self.config['in_size']} vs {in_size})")


def make_dynet(model: PhysicsModel, params: PhysicsParams, hidden: int = 256) -> DyNet:
    """An untrained DyNet (float64) for ``model`` with ``params``' fixed gains as kp_ini,
    kd_ini: it reproduces the fixed-gain cycle."""
    kp, kd = params.gains(model.nv)
    return DyNet(feature_size(model), model.nv, kp, kd, hidden).double()


class LearnedGains:
    """DyNet for the numpy cycle: ``(q_hat, q, v, diag M, e) -> kp, kd, alpha`` (numpy, nv
    each; inputs q_hat, q (nq,), v, diag M, e (nv,)).

    Args:
        net: a loaded :class:`DyNet` (:meth:`DyNet.load`).
        model: the cycle's model; the network must fit it.
        path: the weights file, for messages.

    Raises:
        ValueError: the network does not fit ``model`` or its layout.
    """

    def __init__(self, net: DyNet, model: PhysicsModel, path: PathLike = '') -> None:
        self.path = str(path)
        self.net = net.double()
        if self.net.config['nv'] != model.nv or \
                self.net.config['in_size'] != feature_size(model):
            raise ValueError(f'DyNet weights {path} do not fit the skeleton model '
                             f"(nv {self.net.config['nv']} vs {model.nv})")
        check_layout(model)
        self.model = model

    def __call__(self, q_hat: np.ndarray, q: np.ndarray, v: np.ndarray, diag_m: np.ndarray,
                 e: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        with torch.no_grad():
            t = [torch.from_numpy(np.ascontiguousarray(x, dtype=np.float64))
                 for x in (q_hat, q, v, diag_m, e)]
            kp, kd, alpha = self.net(features(*t), t[3])
        return kp.numpy(), kd.numpy(), alpha.numpy()


__all__ = ['DyNet', 'LearnedGains', 'make_dynet', 'features', 'pose_features', 'feature_size',
           'dynet_sizes', 'check_layout', 'WEIGHTS_DIR', 'GAMMA']
