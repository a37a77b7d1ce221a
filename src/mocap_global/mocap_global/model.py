"""The global motion regressor (GMR, §3.3 and Fig. 4; PyTorch, no ROS imports).

Input ``x`` (B, T, C): the per-frame features of :mod:`.features` (C =
:attr:`GMRConfig.num_features`). Temporal encoder: a bidirectional multi-layer GRU
(:class:`BiGRU`, 2H features per frame), then a linear projection to P features with a ReLU.
Motion regression layer: one linear layer per frame with 9 outputs,

* ``dG_i = (dA_i, dT_i)``: the global motion from frame i to frame i + 1 in the body frame
  of frame i (axis-angle in rad, translation in m; eq. 2-4 of :mod:`.se3`), de-normalised by
  fixed output statistics ``out_mean``, ``out_std``; the output at the last frame of a
  sequence has no motion to predict and is ignored;
* ``u_i``: the world's up direction (+z) in the body frame of frame i (unit vector,
  ``R_i^T e_z``), predicted as an offset from (0, 0, 1) and normalised.

The input is normalised by ``feature_mean``, ``feature_std``; with ``velocity_input`` the
forward differences of the local-pose features are appended inside the network.
:meth:`GMRConfig.paper` is the paper's configuration; the choices beyond the paper and their
reasons are in ``docs/global.md``.

Test-time augmentation (``tta``, inference only): the motion is also read off the mirrored
sequence (y -> -y in the root frame, left and right swapped; reflected back: axis-angle
``(-x, y, -z)``, translation and up ``(x, -y, z)``) and off the time-reversed sequence (motion
j of the reversal is ``dG_{n-2-j}^-1``); ``'mirror'``, ``'reverse'`` or ``'both'`` (all four
combinations) average the estimates (arithmetic means of axis-angle and translation), at 2 or
4 times the compute in one batched pass.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional

import numpy as np
import torch
from torch import nn

from mocap_core.rotations import axis_angle_to_matrix
from mocap_core.skeleton import JOINT_MIRROR, JOINT_NAMES, NUM_JOINTS

from .features import num_features, pose_dims


@dataclass
class GMRConfig:
    """Network configuration; the defaults are the shipped CPU model."""

    layers: int = 2
    hidden: int = 128
    projection: int = 128
    root_input: str = 'none'
    fps: float = 30.0
    window: int = 64
    velocity_input: bool = True
    skeleton_input: bool = True
    pose_input: str = 'positions'
    joint_names: List[str] = field(default_factory=lambda: list(JOINT_NAMES))

    @classmethod
    def paper(cls) -> 'GMRConfig':
        """The paper's configuration (§4.1, S5): 4 layers of 2048 units, 2048 projection,
        10 fps, 64-frame windows, local-pose quaternions only. A GPU configuration."""
        return cls(layers=4, hidden=2048, projection=2048, fps=10.0, window=64,
                   velocity_input=False, skeleton_input=False, pose_input='quat')

    @property
    def num_features(self) -> int:
        return num_features(self.root_input, self.skeleton_input, self.pose_input)


#: Test-time augmentations (module docstring).
TTA_MODES = ('none', 'mirror', 'reverse', 'both')
_MIRROR_AXIAL = (-1.0, 1.0, -1.0)     # axis-angle (a pseudo-vector) under y -> -y
_MIRROR_POLAR = (1.0, -1.0, 1.0)      # translations, up vectors, positions under y -> -y


def reverse_padded(x: torch.Tensor, lengths: Optional[torch.Tensor]) -> torch.Tensor:
    """Reverse (B, T, C) sequences in time within their valid ``lengths`` (the padding stays
    at the end); its own inverse. ``lengths=None``: all T frames are valid."""
    if lengths is None:
        return x.flip(1)
    t = torch.arange(x.shape[1], device=x.device)[None]
    n = lengths.to(x.device)[:, None]
    idx = torch.where(t < n, n - 1 - t, t)
    return x.gather(1, idx[..., None].expand(-1, -1, x.shape[-1]))


class BiGRU(nn.Module):
    """A stack of bidirectional GRU layers for padded batches: each layer runs a forward GRU
    on the sequences and a second GRU on the sequences reversed within their lengths, and
    concatenates both. (B, T, C) -> (B, T, 2H). The same as ``nn.GRU(bidirectional=True)`` on
    packed sequences, without the packing (``docs/global.md``)."""

    def __init__(self, inputs: int, hidden: int, layers: int) -> None:
        super().__init__()
        self.fwd = nn.ModuleList(nn.GRU(inputs if i == 0 else 2 * hidden, hidden,
                                        batch_first=True) for i in range(layers))
        self.bwd = nn.ModuleList(nn.GRU(inputs if i == 0 else 2 * hidden, hidden,
                                        batch_first=True) for i in range(layers))

    def forward(self, x: torch.Tensor, lengths: Optional[torch.Tensor] = None) -> torch.Tensor:
        if lengths is not None and not bool((lengths < x.shape[1]).any()):
            lengths = None
        if lengths is None and not torch.is_grad_enabled():
            return self._fused(x)
        for f, b in zip(self.fwd, self.bwd):
            hf, _ = f(x)
            hb, _ = b(reverse_padded(x, lengths))
            x = torch.cat([hf, reverse_padded(hb, lengths)], dim=-1)
        return x

    def _fused(self, x: torch.Tensor) -> torch.Tensor:
        """Inference without padding: the same weights through PyTorch's fused bidirectional
        GRU kernel (what ``nn.GRU(bidirectional=True)`` calls)."""
        from torch import _VF
        weights = []
        for f, b in zip(self.fwd, self.bwd):
            weights += [f.weight_ih_l0, f.weight_hh_l0, f.bias_ih_l0, f.bias_hh_l0,
                        b.weight_ih_l0, b.weight_hh_l0, b.bias_ih_l0, b.bias_hh_l0]
        h0 = x.new_zeros(2 * len(self.fwd), x.shape[0], self.fwd[0].hidden_size)
        out, _ = _VF.gru(x, h0, weights, True, len(self.fwd), 0.0, False, True, True)
        return out


class GMR(nn.Module):
    """Bidirectional GRU encoder + linear projection + motion regression layer."""

    def __init__(self, cfg: Optional[GMRConfig] = None) -> None:
        super().__init__()
        self.cfg = cfg or GMRConfig()
        c = self.cfg
        self.gru = BiGRU(c.num_features + (pose_dims(c.pose_input) if c.velocity_input else 0),
                         c.hidden, c.layers)
        self.projection = nn.Linear(2 * c.hidden, c.projection)
        self.regression = nn.Linear(c.projection, 9)
        with torch.no_grad():
            self.regression.weight.mul_(0.1)
            self.regression.bias.zero_()
        self.register_buffer('feature_mean', torch.zeros(c.num_features))
        self.register_buffer('feature_std', torch.ones(c.num_features))
        self.register_buffer('out_mean', torch.zeros(6))
        self.register_buffer('out_std', torch.ones(6))

    def set_normalisation(self, feature_mean, feature_std, out_mean, out_std) -> None:
        """Input and output statistics (NumPy or tensors); tiny stds are clamped."""
        def t(v):
            return torch.as_tensor(np.asarray(v, dtype=np.float32),
                                   device=self.feature_mean.device)
        self.feature_mean.copy_(t(feature_mean))
        self.feature_std.copy_(torch.clamp(t(feature_std), min=1e-3))
        self.out_mean.copy_(t(out_mean))
        self.out_std.copy_(torch.clamp(t(out_std), min=1e-4))

    def forward(self, x: torch.Tensor, lengths: Optional[torch.Tensor] = None,
                tta: str = 'none') -> Dict[str, torch.Tensor]:
        """``x`` (B, T, C) features; ``lengths`` (B,) valid frames per sequence (the rest is
        padding: the backward GRU starts at each sequence's own end, :class:`BiGRU`);
        ``tta``: test-time augmentation, one of :data:`TTA_MODES` (module docstring).

        Returns ``axis_angle`` (B, T, 3) and ``translation`` (B, T, 3): the motion from
        frame i to i + 1 in the body frame of frame i; ``rotation`` (B, T, 3, 3) its matrix;
        ``up`` (B, T, 3): the world's up direction in the body frame of frame i (unit)."""
        if tta == 'none':
            return self._single(x, lengths)
        if tta not in TTA_MODES:
            raise ValueError(f'tta must be one of {TTA_MODES}, got {tta!r}')
        b, t = x.shape[:2]
        if lengths is None:
            lengths = torch.full((b,), t, dtype=torch.long, device=x.device)
        mirrors = (False, True) if tta in ('mirror', 'both') else (False,)
        reverses = (False, True) if tta in ('reverse', 'both') else (False,)
        views = [(m, r) for r in reverses for m in mirrors]      # (mirrored, reversed)
        xs = []
        for m, r in views:
            v = self.mirror_features(x) if m else x
            xs.append(reverse_padded(v, lengths) if r else v)
        out = self._single(torch.cat(xs), lengths.repeat(len(views)))
        aa = torch.zeros_like(x[..., :3])
        tr = torch.zeros_like(aa)
        up = torch.zeros_like(aa)
        for i, (m, r) in enumerate(views):
            a = out['axis_angle'][i * b:(i + 1) * b]
            d = out['translation'][i * b:(i + 1) * b]
            u = out['up'][i * b:(i + 1) * b]
            if r:   # motion j of the reversed sequence is motion n-2-j inverted
                Rt = out['rotation'][i * b:(i + 1) * b].transpose(-1, -2)
                a, d = -a, -(Rt @ d[..., None])[..., 0]
                a, d = reverse_padded(a, lengths - 1), reverse_padded(d, lengths - 1)
                u = reverse_padded(u, lengths)
            if m:
                a = a * a.new_tensor(_MIRROR_AXIAL)
                d = d * d.new_tensor(_MIRROR_POLAR)
                u = u * u.new_tensor(_MIRROR_POLAR)
            aa, tr, up = aa + a, tr + d, up + u
        aa, tr = aa / len(views), tr / len(views)
        up = up / up.norm(dim=-1, keepdim=True).clamp(min=1e-6)
        return {'axis_angle': aa, 'translation': tr, 'rotation': axis_angle_to_matrix(aa),
                'up': up}

    def mirror_features(self, x: torch.Tensor) -> torch.Tensor:
        """The input features of the left/right mirrored sequence (y -> -y in the root frame,
        left and right joints swapped); the bone-group lengths are symmetric and stay.
        (..., C) -> (..., C)."""
        n = NUM_JOINTS - 1
        d = pose_dims(self.cfg.pose_input)
        k = d // n
        perm = [JOINT_MIRROR[j] - 1 for j in range(1, NUM_JOINTS)]
        pose = x[..., :d].reshape(x.shape[:-1] + (n, k))[..., perm, :]
        sign = _MIRROR_POLAR if k == 3 else _MIRROR_AXIAL + (1.0,)
        parts = [(pose * pose.new_tensor(sign)).reshape(x.shape[:-1] + (d,)), x[..., d:]]
        if self.cfg.root_input == 'up':
            parts[1] = torch.cat([x[..., d:-3], x[..., -3:] * x.new_tensor(_MIRROR_POLAR)], -1)
        return torch.cat(parts, dim=-1)

    def _single(self, x: torch.Tensor,
                lengths: Optional[torch.Tensor] = None) -> Dict[str, torch.Tensor]:
        """One pass of the network (:meth:`forward` without test-time augmentation)."""
        h = (x - self.feature_mean) / self.feature_std
        if self.cfg.velocity_input:
            h = torch.cat([h, self._velocity(x, lengths)], dim=-1)
        h = torch.relu(self.projection(self.gru(h, lengths)))
        raw = self.regression(h)
        motion = raw[..., :6] * self.out_std + self.out_mean
        up = raw[..., 6:] + torch.tensor([0.0, 0.0, 1.0], device=raw.device, dtype=raw.dtype)
        up = up / up.norm(dim=-1, keepdim=True).clamp(min=1e-6)
        aa = motion[..., :3]
        return {'axis_angle': aa, 'translation': motion[..., 3:],
                'rotation': axis_angle_to_matrix(aa), 'up': up}

    def _velocity(self, x: torch.Tensor, lengths: Optional[torch.Tensor]) -> torch.Tensor:
        """Forward differences of the local-pose features, x_{i+1} - x_i (quaternions x 10,
        root-frame joint positions x fps: m/s), zero at the last valid frame of each sequence
        (a window never sees beyond its end)."""
        q = x[..., :pose_dims(self.cfg.pose_input)]
        d = torch.zeros_like(q)
        d[:, :-1] = q[:, 1:] - q[:, :-1]
        if lengths is not None:
            t = torch.arange(x.shape[1], device=x.device)[None]
            d = d * (t < lengths.to(x.device)[:, None] - 1)[..., None].to(d.dtype)
        return d * (10.0 if self.cfg.pose_input == 'quat' else self.cfg.fps)


class Augmented(nn.Module):
    """A :class:`GMR` that always infers with one test-time augmentation: a drop-in model for
    the evaluation and the node (``Augmented(model, 'mirror')(x)`` is
    ``model(x, tta='mirror')``)."""

    def __init__(self, model: GMR, tta: str) -> None:
        super().__init__()
        if tta not in TTA_MODES:
            raise ValueError(f'tta must be one of {TTA_MODES}, got {tta!r}')
        self.model = model
        self.tta = tta
        self.cfg = model.cfg
        self.info = getattr(model, 'info', {})

    def forward(self, x: torch.Tensor,
                lengths: Optional[torch.Tensor] = None) -> Dict[str, torch.Tensor]:
        return self.model(x, lengths, tta=self.tta)


def with_tta(model: GMR, tta: str) -> nn.Module:
    """``model`` itself for ``tta='none'``, else an :class:`Augmented` wrapper."""
    return model if tta == 'none' else Augmented(model, tta)
