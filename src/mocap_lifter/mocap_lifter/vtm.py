"""VTM (Hou et al. 2024): a second lifter model, motion priors by cross-modal manifold
alignment, in PyTorch (no ROS imports).

Shapes: B = batch, T = frames, W = the model's window (32 frames), J = 18 joints, G = 10 bone
groups. Frames: rotations and positions in the camera optical frame (x right, y down,
z forward), metres; quaternions x, y, z, w; 6D rotations are the first two matrix columns.

**Scale-invariant virtual skeleton** (§3.1): ``virtual_lengths`` (G,) are the mean bone-group
lengths of the training skeletons. Motion is expressed on it: the rotations are those of the
person, the joint positions those of the virtual skeleton. A person's skeleton is the
virtual one times the **bone ratios** ``b`` (G,) (one per group: left and right share it).

**Motion representation** (§3.1), per frame, normalised per channel with training
statistics:

* root (12 channels): 6D root orientation, root position as its projection x/z, y/z and
  log depth (log z), and the velocities of those three (the paper has x, y, z; reasons in
  ``docs/lifter.md``);
* each non-root joint (12 channels): 6D local rotation, position relative to the root on the
  virtual skeleton (3) and its velocity (3).

The root decoder outputs the root's 6D orientation, log depth and its velocity (8 channels);
the root position is ``z * (root_x, root_y, 1)`` from the canonical root keypoint (as for
MotioNet).

**TPMAE** (§3.2): motion encoders ``enc_m_u`` / ``enc_m_l`` over the upper / lower body joints
(both with the root channels) give latents Z_u (B, 128, W/4) and Z_l (B, 64, W/4); decoders
``dec_u`` / ``dec_l``, an aggregation layer ``aggregate`` (1D convolution) to the non-root
channels, a root decoder ``dec_r`` from Z_u (+) Z_l. Encoders: strided convolutions with
dilated residual blocks, two stride-2 stages (T -> T/4); decoders mirror them with
nearest-neighbour upsampling.

**TPVE** (§3.3), keypoints only (the paper's VTM-w/o_V): keypoint feature extractors
``key_u`` / ``key_l`` (three-layer CNNs over each part's keypoints: root-relative position
scaled by the person's 2D size, confidence, velocity; plus the root keypoint's velocity and
log size), fusion residual blocks ``fuse_u`` / ``fuse_l``, visual encoders ``enc_v_u`` /
``enc_v_l`` (the motion encoders' structure followed by two cross-temporal context
aggregation modules, :class:`CTCA`), and the bone-ratio encoder ``enc_b`` on the fused
features of both parts. At inference the visual latents go through the TPMAE decoders.

Contact head ``contact`` (not in the paper): heel/toe contact logits (B, T, 4) from the
decoded features of both parts.

Inference over any length T (:meth:`VTM.forward`): overlapping windows of W frames (hop
W/2, the last window ends at the last frame), each frame taken from the window where it is
nearest the centre; a sequence shorter than W is padded at the start with its first frame.
The skeleton is the mean of the windows' bone ratios times the virtual skeleton.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import torch
from torch import nn

from mocap_core.keypoint_geometry import JOINT_KEYPOINTS
from mocap_core.rotations import quat_to_rot6d, rot6d_to_quat
from mocap_core.skeleton import (JOINT_INDEX, KEYPOINT_INDEX, NUM_BONE_GROUPS,
                                 NUM_JOINTS, NUM_KEYPOINTS)

from .model import NUM_CONTACTS, fk_layer

#: Upper-body joints (root first): the root is in both parts.
UPPER_JOINTS: Tuple[int, ...] = tuple(JOINT_INDEX[n] for n in (
    'pelvis', 'spine', 'neck', 'head', 'left_shoulder', 'left_elbow', 'left_wrist',
    'right_shoulder', 'right_elbow', 'right_wrist'))
#: Lower-body joints (root first).
LOWER_JOINTS: Tuple[int, ...] = tuple(JOINT_INDEX[n] for n in (
    'pelvis', 'left_hip', 'left_knee', 'left_ankle', 'left_toe',
    'right_hip', 'right_knee', 'right_ankle', 'right_toe'))
#: Upper / lower keypoints of the 23-point layout; the hips (the root keypoint) are in both.
UPPER_KEYPOINTS: Tuple[int, ...] = tuple(KEYPOINT_INDEX[n] for n in (
    'nose', 'left_eye', 'right_eye', 'left_ear', 'right_ear', 'left_shoulder',
    'right_shoulder', 'left_elbow', 'right_elbow', 'left_wrist', 'right_wrist',
    'left_hip', 'right_hip'))
LOWER_KEYPOINTS: Tuple[int, ...] = tuple(KEYPOINT_INDEX[n] for n in (
    'left_hip', 'right_hip', 'left_knee', 'right_knee', 'left_ankle', 'right_ankle',
    'left_big_toe', 'left_small_toe', 'left_heel', 'right_big_toe', 'right_small_toe',
    'right_heel'))

ROOT_CHANNELS = 12      # 6D, position, velocity, log depth, its velocity
JOINT_CHANNELS = 12     # 6D, position, velocity
ROOT_OUT = 8            # 6D, log depth, its velocity
#: The root block's channels the root decoder outputs: 6D, log depth, log-depth velocity.
ROOT_OUT_CHANNELS: Tuple[int, ...] = (0, 1, 2, 3, 4, 5, 8, 11)
NON_ROOT = tuple(j for j in range(NUM_JOINTS) if j != 0)
KEYPOINT_CHANNELS = 5   # x, y, confidence, vx, vy
GLOBAL_KEYPOINT_CHANNELS = 5  # root keypoint velocity x, y, log scale, root keypoint x, y


def part_channels(joints: Sequence[int]) -> List[int]:
    """Channel indices of a body part in the flat (J * 12) motion representation (root
    channels are joint 0's block)."""
    return [12 * j + c for j in joints for c in range(12)]


@dataclass
class VTMConfig:
    """Network size. The paper's latent sizes (128 upper, 64 lower, T/4) and window (32)."""

    window: int = 32
    width: int = 128            # channels of encoders / decoders
    latent_upper: int = 128
    latent_lower: int = 64
    keypoint_width: int = 96    # channels of the keypoint feature extractors
    heads: int = 4              # attention heads of the CTCA modules
    bone_range: float = 0.35    # ratio = 1 + bone_range * tanh(.)
    dropout: float = 0.1
    virtual_lengths: List[float] = field(default_factory=lambda: [0.0] * NUM_BONE_GROUPS)
    causal: bool = False        # VTM is windowed only (bounded look-ahead); kept for the API
    root_from: str = 'decoder'  # 'decoder' (the paper: decoded depth) or 'reprojection'
    root_prior: float = 0.1     # reprojection: weight of the decoded root (m^-2 scale)

    def receptive_field(self) -> int:
        """Frames one inference window spans (the online lifter's context unit)."""
        return self.window

    def to_dict(self) -> Dict:
        return asdict(self)


class _Res(nn.Module):
    """Dilated residual block: x + conv1x1(act(conv3_dil(act(x))))."""

    def __init__(self, c: int, dilation: int = 1, dropout: float = 0.0) -> None:
        super().__init__()
        self.net = nn.Sequential(nn.LeakyReLU(0.2), nn.Conv1d(c, c, 3, padding=dilation,
                                                              dilation=dilation),
                                 nn.LeakyReLU(0.2), nn.Dropout(dropout), nn.Conv1d(c, c, 1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.net(x)


class Encoder(nn.Module):
    """(B, c_in, T) -> (B, latent, T/4): conv, two stages of stride-2 convolution with
    dilated residual blocks, conv to the latent size."""

    def __init__(self, c_in: int, width: int, latent: int, dropout: float = 0.0) -> None:
        super().__init__()
        layers: List[nn.Module] = [nn.Conv1d(c_in, width, 3, padding=1)]
        for _ in range(2):
            layers += [nn.LeakyReLU(0.2), nn.Conv1d(width, width, 4, stride=2, padding=1),
                       _Res(width, 1, dropout), _Res(width, 3, dropout)]
        layers += [nn.LeakyReLU(0.2), nn.Conv1d(width, latent, 3, padding=1)]
        self.net = nn.Sequential(*layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


class Decoder(nn.Module):
    """(B, latent, T/4) -> (B, width, T): the mirror of :class:`Encoder` (nearest-neighbour
    upsampling)."""

    def __init__(self, latent: int, width: int, c_out: Optional[int] = None) -> None:
        super().__init__()
        layers: List[nn.Module] = [nn.Conv1d(latent, width, 3, padding=1)]
        for _ in range(2):
            layers += [_Res(width, 3), _Res(width, 1), nn.Upsample(scale_factor=2),
                       nn.Conv1d(width, width, 3, padding=1)]
        layers += [nn.LeakyReLU(0.2), nn.Conv1d(width, c_out or width, 3, padding=1)]
        self.net = nn.Sequential(*layers)

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        return self.net(z)


class CTCA(nn.Module):
    """Cross-temporal context aggregation (after Guo et al. 2023, as VTM uses it): each latent
    step gathers global context from every step of the window (multi-head self-attention)
    and local context from its neighbours (depth-wise temporal convolution), then a
    position-wise MLP; pre-norm residual branches. (B, C, T') -> (B, C, T')."""

    def __init__(self, c: int, heads: int, dropout: float = 0.0) -> None:
        super().__init__()
        self.norm1 = nn.LayerNorm(c)
        self.attn = nn.MultiheadAttention(c, heads, dropout=dropout, batch_first=True)
        self.norm2 = nn.LayerNorm(c)
        self.local = nn.Conv1d(c, c, 3, padding=1, groups=c)
        self.norm3 = nn.LayerNorm(c)
        self.mlp = nn.Sequential(nn.Linear(c, 2 * c), nn.GELU(), nn.Linear(2 * c, c))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = x.transpose(1, 2)                                   # (B, T', C)
        a = self.norm1(h)
        h = h + self.attn(a, a, a, need_weights=False)[0]
        h = h + self.local(self.norm2(h).transpose(1, 2)).transpose(1, 2)
        h = h + self.mlp(self.norm3(h))
        return h.transpose(1, 2)


class _KeypointCNN(nn.Module):
    """K_u / K_l: three temporal convolutions over one part's keypoint channels."""

    def __init__(self, c_in: int, width: int) -> None:
        super().__init__()
        self.net = nn.Sequential(nn.Conv1d(c_in, width, 3, padding=1), nn.LeakyReLU(0.2),
                                 nn.Conv1d(width, width, 3, padding=1), nn.LeakyReLU(0.2),
                                 nn.Conv1d(width, width, 3, padding=1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


class _VisualEncoder(nn.Module):
    """E^V: the motion encoder's structure followed by two CTCA modules."""

    def __init__(self, c_in: int, cfg: VTMConfig, latent: int) -> None:
        super().__init__()
        self.enc = Encoder(c_in, cfg.width, cfg.width, cfg.dropout)
        self.ctca = nn.Sequential(CTCA(cfg.width, cfg.heads, cfg.dropout),
                                  CTCA(cfg.width, cfg.heads, cfg.dropout))
        self.out = nn.Conv1d(cfg.width, latent, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.out(self.ctca(self.enc(x)))


class _BoneRatioEncoder(nn.Module):
    """E^B: fused visual features of both parts (B, C, T) -> bone ratios (B, G)."""

    def __init__(self, c_in: int, cfg: VTMConfig) -> None:
        super().__init__()
        self.enc = Encoder(c_in, cfg.width // 2, cfg.width // 2, cfg.dropout)
        self.out = nn.Linear(cfg.width // 2, NUM_BONE_GROUPS)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)
        self.bone_range = cfg.bone_range

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.enc(x).mean(dim=-1)
        return 1.0 + self.bone_range * torch.tanh(self.out(h))


def keypoint_parts(features: torch.Tensor, root_2d: torch.Tensor,
                   ) -> Tuple[torch.Tensor, torch.Tensor]:
    """Per-part keypoint inputs from lifter features (B, T, 72) (:mod:`.features`) and the
    canonical root keypoint (B, T, 2): (B, T, 13 * 5 + 5) upper and (B, T, 12 * 5 + 5) lower,
    per keypoint x, y, confidence, vx, vy (scaled root-relative, velocity = difference to the
    previous frame, zero at the first), then the root keypoint velocity, log scale and the
    root keypoint itself."""
    b, t, _ = features.shape
    xy = features[..., :NUM_KEYPOINTS * 2].reshape(b, t, NUM_KEYPOINTS, 2)
    conf = features[..., NUM_KEYPOINTS * 2:NUM_KEYPOINTS * 3].reshape(b, t, NUM_KEYPOINTS, 1)
    vel = torch.zeros_like(xy)
    seen = (conf[:, 1:] > 0) & (conf[:, :-1] > 0)
    vel[:, 1:] = (xy[:, 1:] - xy[:, :-1]) * seen
    per_kp = torch.cat([xy, conf, vel], dim=-1)            # (B, T, 23, 5)
    glob = torch.cat([features[..., NUM_KEYPOINTS * 3:], root_2d], dim=-1)  # (B, T, 5)
    up = torch.cat([per_kp[:, :, list(UPPER_KEYPOINTS)].reshape(b, t, -1), glob], dim=-1)
    lo = torch.cat([per_kp[:, :, list(LOWER_KEYPOINTS)].reshape(b, t, -1), glob], dim=-1)
    return up, lo


# the layout keypoints that are joints place the root by reprojection
_KP_OF_JOINT = [KEYPOINT_INDEX[n] for n in JOINT_KEYPOINTS]
_JOINT_OF_KP = [JOINT_INDEX[n] for n in JOINT_KEYPOINTS]


def reprojection_root(relative: torch.Tensor, features: torch.Tensor, root_2d: torch.Tensor,
                      prior: torch.Tensor, prior_weight: float) -> torch.Tensor:
    """Root position that best reprojects the lifted joints onto the seen keypoints (beyond
    the paper, ``root_from='reprojection'``).

    Per frame, weighted linear least squares for the root (X, Y, Z): for each of the 12
    keypoints that are joints, with canonical image coordinates (u, v), confidence w and
    root-relative joint position p (camera frame), ``X - u Z = u p_z - p_x`` and
    ``Y - v Z = v p_z - p_y`` (pinhole projection), plus ``prior_weight`` times the decoded
    root as a prior (which also decides frames with too few seen keypoints).

    Args:
        relative: (B, T, J, 3) joint positions relative to the root, camera frame, m.
        features: (B, T, 72) lifter features (scaled root-relative keypoints, confidences,
            log scale; :mod:`.features`).
        root_2d: (B, T, 2) canonical root keypoint.
        prior: (B, T, 3) the decoded root, m.
        prior_weight: weight of the prior rows (the keypoint rows have weight = confidence).
    Returns:
        (B, T, 3) root position, camera frame, m.
    """
    b, t = features.shape[:2]
    scale = torch.exp(features[..., NUM_KEYPOINTS * 3 + 2])[..., None, None]
    xy = features[..., :NUM_KEYPOINTS * 2].reshape(b, t, NUM_KEYPOINTS, 2)[:, :, _KP_OF_JOINT]
    uv = xy * scale + root_2d[:, :, None]                                   # (B, T, K, 2)
    w = features[..., NUM_KEYPOINTS * 2:NUM_KEYPOINTS * 3][:, :, _KP_OF_JOINT].clamp(0, 1)
    p = relative[:, :, _JOINT_OF_KP]                                        # (B, T, K, 3)
    zeros = torch.zeros_like(w)
    ones = torch.ones_like(w)
    # rows for x and y: [1, 0, -u] . (X, Y, Z) = u p_z - p_x ; [0, 1, -v] . = v p_z - p_y
    a_x = torch.stack([ones, zeros, -uv[..., 0]], dim=-1)
    a_y = torch.stack([zeros, ones, -uv[..., 1]], dim=-1)
    r_x = uv[..., 0] * p[..., 2] - p[..., 0]
    r_y = uv[..., 1] * p[..., 2] - p[..., 1]
    a = torch.cat([a_x, a_y], dim=2)                                       # (B, T, 2K, 3)
    r = torch.cat([r_x, r_y], dim=2)
    ww = torch.cat([w, w], dim=2)
    eye = torch.eye(3, dtype=a.dtype, device=a.device)
    lhs = (a * ww[..., None]).transpose(-1, -2) @ a + prior_weight * eye
    rhs = ((a * ww[..., None]) * r[..., None]).sum(dim=2) + prior_weight * prior
    return torch.linalg.solve(lhs, rhs[..., None])[..., 0]


def motion_representation(rotations: torch.Tensor, root: torch.Tensor,
                          virtual_lengths: torch.Tensor) -> torch.Tensor:
    """§3.1 representation on the virtual skeleton.

    Args:
        rotations: (B, T, J, 4) x,y,z,w; joint 0 = root orientation in the camera frame,
            others local (relative to the parent, against the rest pose).
        root: (B, T, 3) root position in the camera frame, m (z > 0).
        virtual_lengths: (G,) virtual skeleton bone-group lengths, m.
    Returns:
        (B, T, J * 12) unnormalised: per joint 12 channels (module docstring); joint 0's block
        is 6D, x/z, y/z, log depth, and the velocities of those three.
    """
    b, t = rotations.shape[:2]
    rot6 = quat_to_rot6d(rotations)                                  # (B, T, J, 6)
    lengths = virtual_lengths.to(root).expand(b, -1)
    pos = fk_layer(lengths, rotations, torch.zeros_like(root))       # root-relative
    vel = _velocity(pos)
    # where the root projects (x/z, y/z: the canonical root keypoint) and log depth, then
    # their velocities
    z = root[..., 2:3].clamp_min(0.1)
    place = torch.cat([root[..., :2] / z, torch.log(z)], dim=-1)
    root_block = torch.cat([rot6[:, :, 0], place, _velocity(place)], dim=-1)
    joints = torch.cat([rot6, pos, vel], dim=-1)                      # (B, T, J, 12)
    joints = torch.cat([root_block[:, :, None], joints[:, :, 1:]], dim=2)
    return joints.reshape(b, t, NUM_JOINTS * 12)


def _velocity(x: torch.Tensor) -> torch.Tensor:
    """Difference to the previous frame along dim 1; the first frame repeats the second's."""
    v = torch.zeros_like(x)
    v[:, 1:] = x[:, 1:] - x[:, :-1]
    if x.shape[1] > 1:
        v[:, 0] = v[:, 1]
    return v


class VTM(nn.Module):
    """TPMAE + TPVE + the FK layer (module docstring). :meth:`forward` has the interface of
    :class:`mocap_lifter.model.MotioNet`."""

    def __init__(self, cfg: VTMConfig) -> None:
        super().__init__()
        self.cfg = cfg
        w = cfg.width
        self.register_buffer('virtual_lengths', torch.tensor(cfg.virtual_lengths,
                                                             dtype=torch.float32))
        c_all = NUM_JOINTS * 12
        self.register_buffer('motion_mean', torch.zeros(c_all))
        self.register_buffer('motion_std', torch.ones(c_all))
        c_up = len(UPPER_KEYPOINTS) * KEYPOINT_CHANNELS + GLOBAL_KEYPOINT_CHANNELS
        c_lo = len(LOWER_KEYPOINTS) * KEYPOINT_CHANNELS + GLOBAL_KEYPOINT_CHANNELS
        self.register_buffer('kp_up_mean', torch.zeros(c_up))
        self.register_buffer('kp_up_std', torch.ones(c_up))
        self.register_buffer('kp_lo_mean', torch.zeros(c_lo))
        self.register_buffer('kp_lo_std', torch.ones(c_lo))
        self.up_channels = part_channels(UPPER_JOINTS)
        self.lo_channels = part_channels(LOWER_JOINTS)
        # TPMAE
        self.enc_m_u = Encoder(len(self.up_channels), w, cfg.latent_upper, cfg.dropout)
        self.enc_m_l = Encoder(len(self.lo_channels), w, cfg.latent_lower, cfg.dropout)
        self.dec_u = Decoder(cfg.latent_upper, w)
        self.dec_l = Decoder(cfg.latent_lower, w)
        self.aggregate = nn.Conv1d(2 * w, (NUM_JOINTS - 1) * 12, 3, padding=1)
        self.dec_r = Decoder(cfg.latent_upper + cfg.latent_lower, w, ROOT_OUT)
        self.contact = nn.Conv1d(2 * w, NUM_CONTACTS, 3, padding=1)
        # TPVE
        k = cfg.keypoint_width
        self.key_u = _KeypointCNN(c_up, k)
        self.key_l = _KeypointCNN(c_lo, k)
        self.fuse_u = _Res(k)
        self.fuse_l = _Res(k)
        self.enc_v_u = _VisualEncoder(k, cfg, cfg.latent_upper)
        self.enc_v_l = _VisualEncoder(k, cfg, cfg.latent_lower)
        self.enc_b = _BoneRatioEncoder(2 * k, cfg)

    # -- normalisation ---------------------------------------------------------------------
    def set_statistics(self, motion: np.ndarray, kp_up: np.ndarray, kp_lo: np.ndarray,
                       ) -> None:
        """Per-channel mean and std from training samples: motion representation (N, J*12),
        part keypoint inputs (N, C_up) and (N, C_lo)."""
        for name, x in (('motion', motion), ('kp_up', kp_up), ('kp_lo', kp_lo)):
            getattr(self, f'{name}_mean').copy_(torch.as_tensor(x.mean(0), dtype=torch.float32))
            getattr(self, f'{name}_std').copy_(torch.as_tensor(np.maximum(x.std(0), 1e-3),
                                                               dtype=torch.float32))

    def normalise_motion(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.motion_mean) / self.motion_std

    # -- TPMAE -----------------------------------------------------------------------------
    def encode_motion(self, xn: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
        """Normalised representation (B, T, J*12) -> Z_u (B, 128, T/4), Z_l (B, 64, T/4)."""
        x = xn.transpose(1, 2)
        return self.enc_m_u(x[:, self.up_channels]), self.enc_m_l(x[:, self.lo_channels])

    def decode(self, z_u: torch.Tensor, z_l: torch.Tensor) -> Dict[str, torch.Tensor]:
        """Latents -> ``non_root`` (B, T, (J-1)*12) and ``root`` (B, T, 8) normalised
        channels, ``contacts`` (B, T, 4) logits."""
        h = torch.cat([self.dec_u(z_u), self.dec_l(z_l)], dim=1)
        return {'non_root': self.aggregate(h).transpose(1, 2),
                'root': self.dec_r(torch.cat([z_u, z_l], dim=1)).transpose(1, 2),
                'contacts': self.contact(h).transpose(1, 2)}

    # -- TPVE ------------------------------------------------------------------------------
    def encode_visual(self, features: torch.Tensor, root_2d: torch.Tensor,
                      ) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Lifter features (B, T, 72) and root keypoint (B, T, 2) -> Z~_u, Z~_l and bone
        ratios (B, G)."""
        up, lo = keypoint_parts(features, root_2d)
        up = ((up - self.kp_up_mean) / self.kp_up_std).transpose(1, 2)
        lo = ((lo - self.kp_lo_mean) / self.kp_lo_std).transpose(1, 2)
        v_u = self.fuse_u(self.key_u(up))
        v_l = self.fuse_l(self.key_l(lo))
        return self.enc_v_u(v_u), self.enc_v_l(v_l), self.enc_b(torch.cat([v_u, v_l], dim=1))

    # -- outputs ---------------------------------------------------------------------------
    def root_outputs(self, root_n: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
        """Normalised root decoder output (B, T, 8) -> root quaternion (B, T, 4), log depth
        (B, T)."""
        idx = list(ROOT_OUT_CHANNELS)
        raw = root_n * self.motion_std[idx] + self.motion_mean[idx]
        return rot6d_to_quat(raw[..., :6]), raw[..., 6]

    def joint_rotations(self, non_root_n: torch.Tensor, root_q: torch.Tensor) -> torch.Tensor:
        """Normalised non-root channels (B, T, (J-1)*12) + root quaternions -> (B, T, J, 4)."""
        b, t, _ = non_root_n.shape
        mean = self.motion_mean[12:].reshape(NUM_JOINTS - 1, 12)
        std = self.motion_std[12:].reshape(NUM_JOINTS - 1, 12)
        raw = non_root_n.reshape(b, t, NUM_JOINTS - 1, 12) * std + mean
        return torch.cat([root_q[:, :, None], rot6d_to_quat(raw[..., :6])], dim=2)

    def outputs(self, dec: Dict[str, torch.Tensor], root_2d: torch.Tensor,
                lengths: torch.Tensor, features: Optional[torch.Tensor] = None,
                ) -> Dict[str, torch.Tensor]:
        """Decoded channels -> the MotioNet-style output dict (see :meth:`forward`). With
        ``features`` and ``cfg.root_from == 'reprojection'`` the root is refined by
        :func:`reprojection_root`."""
        root_q, logz = self.root_outputs(dec['root'])
        q = self.joint_rotations(dec['non_root'], root_q)
        depth = torch.exp(logz.clamp(-3.0, 4.0))
        root = torch.cat([root_2d * depth[..., None], depth[..., None]], dim=-1)
        if features is not None and self.cfg.root_from == 'reprojection':
            relative = fk_layer(lengths, q, torch.zeros_like(root))
            root = reprojection_root(relative, features, root_2d, root, self.cfg.root_prior)
            depth = root[..., 2]
        return {'rotations': q, 'depth': depth, 'root': root, 'contacts': dec['contacts'],
                'lengths': lengths, 'positions': fk_layer(lengths, q, root)}

    def window_forward(self, features: torch.Tensor, root_2d: torch.Tensor,
                       lengths: Optional[torch.Tensor] = None) -> Dict[str, torch.Tensor]:
        """One pass over windows of exactly W frames (B, W, ...); adds ``ratios`` (B, G) and
        the visual latents ``z_u``, ``z_l`` and decoded channels ``decoded``."""
        z_u, z_l, ratios = self.encode_visual(features, root_2d)
        dec = self.decode(z_u, z_l)
        if lengths is None:
            lengths = ratios * self.virtual_lengths
        out = self.outputs(dec, root_2d, lengths, features)
        out.update(ratios=ratios, z_u=z_u, z_l=z_l, decoded=dec)
        return out

    def context_frames(self, latency: int) -> int:
        """Frames the online lifter must pass for the output ``latency`` frames before the
        newest: one window ending at the newest frame (that output lies at its centre for
        the default latency W/2)."""
        return max(self.cfg.window, int(latency) + 1)

    def lift_frames(self, features: torch.Tensor, root_2d: torch.Tensor,
                    lengths: torch.Tensor, frames: List[int], latency: int,
                    ) -> Dict[str, torch.Tensor]:
        """Online lifting of several buffered frames in one batched pass, each exactly as
        frame-by-frame lifting computes it: frame ``f`` (index into the buffer (1, T, ...))
        from the window of W frames ending ``latency`` frames after it (or at the buffer's
        end), padded at the start with the buffer's first frame where the buffer begins
        later. Returns the :meth:`forward` outputs for those frames, (1, len(frames), ...)."""
        w = self.cfg.window
        t = features.shape[1]
        wins, rwins, pos = [], [], []
        for f in frames:
            end = min(f + latency, t - 1)
            start = end - w + 1
            lead = max(0, -start)
            idx = torch.cat([torch.zeros(lead, dtype=torch.long),
                             torch.arange(max(start, 0), end + 1)])
            wins.append(features[:, idx])
            rwins.append(root_2d[:, idx])
            pos.append(f - start)
        z_u, z_l, _ = self.encode_visual(torch.cat(wins), torch.cat(rwins))
        dec = self.decode(z_u, z_l)
        rows = torch.arange(len(frames))
        dec = {k: v[rows, torch.tensor(pos)][None] for k, v in dec.items()}
        sel = torch.tensor(frames)
        return self.outputs(dec, root_2d[:, sel], lengths, features[:, sel])

    def estimate_lengths(self, features: torch.Tensor, root_2d: torch.Tensor) -> torch.Tensor:
        """(1, T, 72) lifter features and (1, T, 2) root keypoint -> (1, G) bone-group
        lengths: the mean ratio over the sequence's windows times the virtual skeleton."""
        wins, _ = self._windows(features)
        rwins, _ = self._windows(root_2d)
        _, _, ratios = self.encode_visual(wins, rwins)
        return ratios.mean(dim=0, keepdim=True) * self.virtual_lengths

    def _windows(self, x: torch.Tensor) -> Tuple[torch.Tensor, List[Tuple[int, int, int]]]:
        """(1, T, ...) -> (N, W, ...) windows and, per output frame, (window, position)
        (after padding a short sequence at the start)."""
        w = self.cfg.window
        t = x.shape[1]
        if t < w:
            x = torch.cat([x[:, :1].expand(1, w - t, *x.shape[2:]), x], dim=1)
        n = x.shape[1]
        hop = w // 2
        starts = list(range(0, n - w + 1, hop))
        if starts[-1] != n - w:
            starts.append(n - w)
        wins = torch.cat([x[:, s:s + w] for s in starts], dim=0)
        centre = (w - 1) / 2.0
        pick = []
        for f in range(max(0, n - t), n):
            best = min(range(len(starts)), key=lambda i: abs(f - starts[i] - centre))
            pick.append((best, f - starts[best], f))
        return wins, pick

    def forward(self, features: torch.Tensor, root_2d: torch.Tensor, scale: torch.Tensor,
                lengths: Optional[torch.Tensor] = None) -> Dict[str, torch.Tensor]:
        """Lift a keypoint sequence.

        Args:
            features: (B, T, 72) lifter features (:mod:`.features`).
            root_2d: (B, T, 2) canonical root keypoint.
            scale: (B, T) person scale (unused: the depth comes from the root decoder; kept
                for the MotioNet interface).
            lengths: (B, G) bone-group lengths overriding E^B (a held skeleton).
        Returns:
            ``rotations`` (B, T, J, 4), ``depth`` (B, T) m, ``root`` (B, T, 3) camera frame m,
            ``contacts`` (B, T, 4) logits, ``lengths`` (B, G) m, ``positions`` (B, T, J, 3)
            camera frame m.
        """
        del scale
        b, t, _ = features.shape
        if t == self.cfg.window:
            out = self.window_forward(features, root_2d, lengths)
            return {k: out[k] for k in ('rotations', 'depth', 'root', 'contacts', 'lengths',
                                        'positions')}
        results = [self._forward_one(features[i:i + 1], root_2d[i:i + 1],
                                     None if lengths is None else lengths[i:i + 1])
                   for i in range(b)]
        return {k: torch.cat([r[k] for r in results]) for k in results[0]}

    def _forward_one(self, features, root_2d, lengths) -> Dict[str, torch.Tensor]:
        wins, pick = self._windows(features)
        rwins, _ = self._windows(root_2d)
        z_u, z_l, ratios = self.encode_visual(wins, rwins)
        if lengths is None:
            lengths = ratios.mean(dim=0, keepdim=True) * self.virtual_lengths
        dec = _stitch(self.decode(z_u, z_l), pick)
        return self.outputs(dec, root_2d, lengths, features)

    def autoencode(self, xn: torch.Tensor) -> Dict[str, torch.Tensor]:
        """The TPMAE alone over any length: normalised representation (1, T, J*12) ->
        decoded channels (1, T, ...) (:meth:`decode`), window by window as :meth:`forward`."""
        wins, pick = self._windows(xn)
        return _stitch(self.decode(*self.encode_motion(wins)), pick)


def _stitch(dec: Dict[str, torch.Tensor], pick) -> Dict[str, torch.Tensor]:
    """Per-window outputs (N, W, C) -> (1, T, C): each frame from its (window, position)."""
    wi = torch.tensor([p[0] for p in pick])
    pi = torch.tensor([p[1] for p in pick])
    return {k: v[wi, pi][None] for k, v in dec.items()}
