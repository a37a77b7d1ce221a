"""MotioNet (Shi et al. 2020) in PyTorch: E_Q, E_S, the FK layer and the rotation-velocity
discriminators (no ROS imports).

Shapes: B = batch, T = frames, C = channels, J = 18 joints, G = 10 bone groups.

* :class:`RotationEncoder` (E_Q, §3.1 and appendix Table 4): a 1x1 channel expansion, then
  ``fusion_blocks`` information-fusion blocks b = 0, 1, ..., each three parallel temporal
  convolutions with kernel sizes 5, 3 and 1 and dilation 2^b, summed, with a residual, padded
  to keep the sequence length; then a 1x1 shrink to per-frame outputs: J unit quaternions
  (x, y, z, w; joint 0 is the root orientation in the camera frame), the log of depth times
  scale, and heel/toe contact logits. Receptive field ``1 + sum_b 4 * 2^b`` frames.
  ``causal=True`` pads on the left only, so output t never depends on inputs after t;
  otherwise the window is centred.
* :class:`SkeletonEncoder` (E_S): sequential temporal convolutions, adaptive max pooling over
  time, and a 1x1 layer to one length per bone group -- one symmetric skeleton by
  construction (pairs share a length).
* :func:`fk_layer` builds the rest pose from the bone lengths (fixed T-pose directions of
  :mod:`mocap_core.skeleton`) and applies the rotations with the differentiable FK of
  :mod:`mocap_core.kinematics`.
* :class:`RotationDiscriminator` (D): per-joint networks on temporal differences of the
  rotations (two 1x1 convolutions and a linear layer, Table 4).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Dict, Tuple

import numpy as np
import torch
from torch import nn

from mocap_core.kinematics import forward_kinematics
from mocap_core.skeleton import (BONE_GROUP_NAMES, DEFAULT_BONE_GROUP_LENGTHS, JOINT_BONE_GROUP,
                                 NUM_BONE_GROUPS, NUM_JOINTS, PARENTS, REST_DIRECTIONS)

from .features import NUM_FEATURES

NUM_CONTACTS = 4


@dataclass
class LifterConfig:
    """Network size and behaviour (sizes: ``docs/lifter.md``)."""

    channels: int = 256
    fusion_blocks: int = 3
    skeleton_channels: int = 128
    dropout: float = 0.1
    causal: bool = False
    depth_prior: float = 0.5    # metres: typical RMS keypoint distance from the pelvis;
    #                             depth = exp(d) / s with d starting at log(depth_prior)
    bone_range: float = 0.35    # bone length = default * (1 + bone_range * tanh(.))
    #: trained in the virtual camera that looks at the person (features.lifter_features with
    #: virtual_camera, features.virtual_camera_window): its input and output must be too
    virtual_camera: bool = False

    def receptive_field(self) -> int:
        """Frames that influence one output frame."""
        return 1 + sum(4 * (2 ** b) for b in range(self.fusion_blocks))

    def to_dict(self) -> Dict:
        return asdict(self)


class _TemporalConv(nn.Module):
    """Conv1d + BatchNorm + LeakyReLU + Dropout, padded to keep the length (causal or not)."""

    def __init__(self, c_in: int, c_out: int, kernel: int, dilation: int, causal: bool,
                 dropout: float) -> None:
        super().__init__()
        total = (kernel - 1) * dilation
        self.pad = (total, 0) if causal else (total // 2, total - total // 2)
        self.conv = nn.Conv1d(c_in, c_out, kernel, dilation=dilation)
        self.post = nn.Sequential(nn.BatchNorm1d(c_out), nn.LeakyReLU(0.2), nn.Dropout(dropout))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.post(self.conv(nn.functional.pad(x, self.pad)))


class _FusionBlock(nn.Module):
    """Three parallel temporal convolutions (kernels 5, 3, 1) summed, with a residual."""

    def __init__(self, channels: int, dilation: int, causal: bool, dropout: float) -> None:
        super().__init__()
        self.branches = nn.ModuleList(
            [_TemporalConv(channels, channels, k, dilation, causal, dropout) for k in (5, 3, 1)])

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + sum(b(x) for b in self.branches)


class RotationEncoder(nn.Module):
    """E_Q: (B, C, T) features -> quaternions (B, T, J, 4), log depth-times-scale (B, T),
    contact logits (B, T, 4)."""

    def __init__(self, cfg: LifterConfig) -> None:
        super().__init__()
        self.cfg = cfg
        c = cfg.channels
        self.expand = _TemporalConv(NUM_FEATURES, c, 1, 1, cfg.causal, cfg.dropout)
        self.blocks = nn.Sequential(*[_FusionBlock(c, 2 ** b, cfg.causal, cfg.dropout)
                                      for b in range(cfg.fusion_blocks)])
        self.shrink = nn.Conv1d(c, NUM_JOINTS * 4 + 1 + NUM_CONTACTS, 1)
        with torch.no_grad():  # start near the identity rotation
            self.shrink.weight.mul_(0.1)
            bias = torch.zeros(NUM_JOINTS * 4 + 1 + NUM_CONTACTS)
            bias[3:NUM_JOINTS * 4:4] = 1.0
            bias[NUM_JOINTS * 4] = float(np.log(cfg.depth_prior))
            self.shrink.bias.copy_(bias)

    def forward(self, x: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        y = self.shrink(self.blocks(self.expand(x))).transpose(1, 2)  # (B, T, out)
        b, t, _ = y.shape
        q = y[..., :NUM_JOINTS * 4].reshape(b, t, NUM_JOINTS, 4)
        q = q / q.norm(dim=-1, keepdim=True).clamp_min(1e-6)
        log_depth_scale = y[..., NUM_JOINTS * 4]
        contacts = y[..., NUM_JOINTS * 4 + 1:]
        return q, log_depth_scale, contacts


class SkeletonEncoder(nn.Module):
    """E_S: (B, C, T) features -> (B, G) bone-group lengths in metres."""

    def __init__(self, cfg: LifterConfig) -> None:
        super().__init__()
        c = cfg.skeleton_channels
        self.net = nn.Sequential(
            _TemporalConv(NUM_FEATURES, c, 1, 1, False, cfg.dropout),
            _TemporalConv(c, c, 5, 1, False, cfg.dropout),
            _TemporalConv(c, c, 3, 1, False, cfg.dropout),
            _TemporalConv(c, c, 1, 1, False, cfg.dropout))
        self.out = nn.Linear(c, NUM_BONE_GROUPS)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)
        self.register_buffer('default_lengths', torch.tensor(
            [DEFAULT_BONE_GROUP_LENGTHS[g] for g in BONE_GROUP_NAMES], dtype=torch.float32))
        self.bone_range = cfg.bone_range

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.net(x).amax(dim=-1)  # adaptive max pooling over time
        return self.default_lengths * (1.0 + self.bone_range * torch.tanh(self.out(h)))


_GROUP_INDEX = torch.tensor([max(g, 0) for g in JOINT_BONE_GROUP])
_REST_DIRECTIONS = torch.tensor(np.array(REST_DIRECTIONS), dtype=torch.float32)
_ROOT_MASK = torch.tensor([0.0] + [1.0] * (NUM_JOINTS - 1))


def offsets_from_lengths(lengths: torch.Tensor) -> torch.Tensor:
    """(B, G) bone-group lengths -> (B, J, 3) rest offsets (T-pose directions)."""
    directions = _REST_DIRECTIONS.to(lengths)
    per_joint = lengths[:, _GROUP_INDEX.to(lengths.device)] * _ROOT_MASK.to(lengths)
    return directions * per_joint[..., None]


def fk_layer(lengths: torch.Tensor, rotations: torch.Tensor,
             root: torch.Tensor) -> torch.Tensor:
    """Differentiable FK: lengths (B, G), rotations (B, T, J, 4) x,y,z,w, root (B, T, 3)
    -> joint positions (B, T, J, 3)."""
    offsets = offsets_from_lengths(lengths)[:, None]  # (B, 1, J, 3)
    return forward_kinematics(PARENTS, offsets, rotations, root).positions


class MotioNet(nn.Module):
    """E_Q + E_S + FK. ``forward`` takes (B, T, C) features, (B, T, 2) canonical root
    keypoints and (B, T) person scales (:mod:`.features`) and returns a dict of tensors."""

    def __init__(self, cfg: LifterConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.e_q = RotationEncoder(cfg)
        self.e_s = SkeletonEncoder(cfg)
        self.register_buffer('feature_mean', torch.zeros(NUM_FEATURES))
        self.register_buffer('feature_std', torch.ones(NUM_FEATURES))

    def set_normalisation(self, mean: np.ndarray, std: np.ndarray) -> None:
        """Per-channel statistics of the training features (stored with the weights)."""
        self.feature_mean.copy_(torch.as_tensor(mean, dtype=torch.float32))
        self.feature_std.copy_(torch.as_tensor(np.maximum(std, 1e-4), dtype=torch.float32))

    def estimate_lengths(self, features: torch.Tensor, root_2d: torch.Tensor) -> torch.Tensor:
        """E_S over a sequence: (B, T, C) features (and (B, T, 2) root keypoint, unused)
        -> (B, G) bone-group lengths, m."""
        del root_2d
        return self.e_s(((features - self.feature_mean) / self.feature_std).transpose(1, 2))

    def forward(self, features: torch.Tensor, root_2d: torch.Tensor, scale: torch.Tensor,
                lengths: torch.Tensor | None = None) -> Dict[str, torch.Tensor]:
        """Returns ``rotations`` (B, T, J, 4), ``depth`` (B, T) m, ``root`` (B, T, 3) camera
        frame m, ``contacts`` (B, T, 4) logits, ``lengths`` (B, G) m, ``positions``
        (B, T, J, 3) camera frame m. ``lengths`` overrides E_S (a held skeleton)."""
        x = ((features - self.feature_mean) / self.feature_std).transpose(1, 2)
        q, log_depth_scale, contacts = self.e_q(x)
        depth = torch.exp(log_depth_scale.clamp(-5.0, 5.0)) / scale.clamp_min(1e-4)
        if lengths is None:
            lengths = self.e_s(x)
        root = torch.cat([root_2d * depth[..., None], depth[..., None]], dim=-1)
        positions = fk_layer(lengths, q, root)
        return {'rotations': q, 'depth': depth, 'root': root, 'contacts': contacts,
                'lengths': lengths, 'positions': positions}


class RotationDiscriminator(nn.Module):
    """D: one small network per joint on rotation velocities (B, T-1, J, 4) -> (B, J) in
    (0, 1) (Table 4: two 1x1 convolutions 4->16->16 and a linear 16->1, per joint)."""

    def __init__(self) -> None:
        super().__init__()
        self.convs = nn.ModuleList([nn.Sequential(
            nn.Conv1d(4, 16, 1), nn.LeakyReLU(0.2), nn.Conv1d(16, 16, 1), nn.LeakyReLU(0.2))
            for _ in range(NUM_JOINTS)])
        self.heads = nn.ModuleList([nn.Linear(16, 1) for _ in range(NUM_JOINTS)])

    def forward(self, rotation_velocity: torch.Tensor) -> torch.Tensor:
        outs = []
        for j in range(NUM_JOINTS):
            h = self.convs[j](rotation_velocity[:, :, j].transpose(1, 2)).mean(dim=-1)
            outs.append(torch.sigmoid(self.heads[j](h)))
        return torch.cat(outs, dim=-1)
