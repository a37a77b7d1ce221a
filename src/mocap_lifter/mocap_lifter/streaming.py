"""MotioNet's rotation encoder frame by frame, with its intermediate columns kept (no ROS
imports).

Live lifting (:class:`mocap_lifter.online.OnlineLifter`, ``chunk = 1``) emits one frame per
incoming frame. A pass of E_Q over the whole context window (43 frames for the default
network in windowed mode) computes every layer at every frame of the window to use one output
column. E_Q is a stack of temporal convolutions without pooling (:mod:`.model`), so a
column of layer ``l`` depends only on a few columns of layer ``l - 1``. This module keeps the
columns of every layer (batch-norm folded into the convolutions) and, per pushed frame,
computes the one new column of each layer: the expansion at the newest frame ``n``, fusion
block ``b`` (dilation ``d = 2^b``) at ``n - sum of the right reaches so far``, and the shrink
at ``n - lag``, the frame the window pass would emit.

Exactness. The output equals the window pass's output at the same frame (up to float32
summation order, ~1e-6) when

* the windowed network runs with ``latency = lag`` (its default, half the receptive field) or
  the causal network with ``latency = 0``: the emitted column's receptive field then ends at
  the newest frame, so the window pass never reads its right-hand zero padding for it;
* the columns before the segment's first frame are zeros, which is the window pass's
  left-hand padding of each layer's input at the start of a segment;
* the features of the frames in the receptive field are the ones the window pass sees. They
  can change after a frame arrived: a frame without both hips takes the root of an earlier
  frame, or, at the start of a window, of the first later one (:func:`.features.root_keypoint`).
  :meth:`StreamingEncoder.push` is therefore given the features of the whole window at every
  frame, compares them with the ones its columns were built from, and recomputes the columns
  from the first frame that changed (usually none but the newest).

Shapes: B = rows (the person, and their mirror image with the test-time flip), C = channels;
features (B, T, 72) float32 as :func:`.features.lifter_features` makes them (not normalised);
outputs are E_Q's raw per-frame values (B, J * 4 + 1 + 4): quaternion components (not yet
normalised), log depth-times-scale, contact logits, as :class:`.model.RotationEncoder`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import List, Optional, Tuple

import numpy as np
import torch
from torch import nn

from .model import MotioNet, _FusionBlock, _TemporalConv


@dataclass
class _Branch:
    """One temporal convolution of a layer as a matrix over stacked input columns: ``y[c] =
    act(W @ [x[c + o] for o in offsets[j0:j1]] + b)``."""

    weight: torch.Tensor          # (C_out, (j1 - j0) * C_in) float32, batch norm folded in
    bias: torch.Tensor            # (C_out,)
    j0: int                       # its taps: the layer's offsets[j0:j1]
    j1: int


@dataclass
class _Layer:
    """Parallel temporal convolutions over one input, summed, plus the input column
    (``residual``). Every branch's taps are a contiguous range of ``offsets``."""

    branches: List[_Branch]
    offsets: Tuple[int, ...]      # input column offsets of the taps (ascending)
    slope: Optional[float]        # LeakyReLU slope; None: no activation (the shrink)
    residual: bool

    @property
    def right(self) -> int:
        """Columns after ``c`` that column ``c`` reads."""
        return max(0, max(self.offsets))

    @property
    def left(self) -> int:
        """Columns before ``c`` that column ``c`` reads."""
        return max(0, -min(self.offsets))


def _folded(conv: _TemporalConv) -> Tuple[np.ndarray, np.ndarray, int]:
    """(C_out, C_in, K) weight and (C_out,) bias of a temporal convolution with its eval-mode
    batch norm folded in, and its left padding."""
    bn = conv.post[0]
    scale = (bn.weight / torch.sqrt(bn.running_var + bn.eps)).detach()
    w = conv.conv.weight.detach() * scale[:, None, None]
    b = (conv.conv.bias.detach() - bn.running_mean) * scale + bn.bias.detach()
    return w.numpy().astype(np.float64), b.numpy().astype(np.float64), conv.pad[0]


def _slope(conv: _TemporalConv) -> float:
    act = conv.post[1]
    if not isinstance(act, nn.LeakyReLU):
        raise TypeError(f'unexpected activation {type(act).__name__}')
    return float(act.negative_slope)


def _layer(convs: List[_TemporalConv], residual: bool) -> _Layer:
    """Parallel temporal convolutions (one input, summed outputs) as tap matrices."""
    parts = []
    for conv in convs:
        w, b, pad = _folded(conv)
        d = conv.conv.dilation[0]
        parts.append((w, b, [k * d - pad for k in range(w.shape[2])]))
    offsets = sorted({o for _, _, offs in parts for o in offs})
    branches = []
    for w, b, offs in parts:
        j0 = offsets.index(offs[0])
        if offsets[j0:j0 + len(offs)] != offs:
            raise ValueError('a branch whose taps are not contiguous among the layer\'s')
        # (C_out, C_in, K) -> (C_out, K * C_in): tap-major, as the input columns are stacked
        mat = np.ascontiguousarray(w.transpose(0, 2, 1).reshape(w.shape[0], -1))
        branches.append(_Branch(torch.from_numpy(mat.astype(np.float32)),
                                torch.from_numpy(b.astype(np.float32)), j0, j0 + len(offs)))
    slopes = {_slope(c) for c in convs}
    if len(slopes) != 1:
        raise ValueError('branches with different activations')
    return _Layer(branches, tuple(offsets), slopes.pop(), residual)


class StreamingEncoder:
    """E_Q of a :class:`~mocap_lifter.model.MotioNet` one frame at a time (module docstring).

    Args:
        model: the network (eval mode; its weights are copied, later changes are not seen).
        rows: batch rows per frame (2 with the test-time flip).
        keep: frames of features kept for the comparison with the next window (at least the
            receptive field).

    Attributes:
        lag: frames between the newest pushed frame and the column :meth:`push` returns.
        recomputed: pushes whose earlier features had changed, so that columns were redone.
    """

    def __init__(self, model: MotioNet, rows: int = 1, keep: Optional[int] = None) -> None:
        enc = model.e_q
        layers = [_layer([enc.expand], residual=False)]
        for block in enc.blocks:
            if not isinstance(block, _FusionBlock):
                raise TypeError(f'unexpected block {type(block).__name__}')
            layers.append(_layer(list(block.branches), residual=True))
        shrink = enc.shrink
        layers.append(_Layer([_Branch(shrink.weight.detach()[:, :, 0].float().contiguous(),
                                      shrink.bias.detach().float(), 0, 1)], (0,), None,
                             False))
        self.layers = layers
        self.mean = model.feature_mean.detach().numpy().astype(np.float32)
        self.std = model.feature_std.detach().numpy().astype(np.float32)
        self.rows = int(rows)
        # column of layer l computed when frame n arrives: n - shift[l]
        self.shift = list(np.cumsum([0] + [lay.right for lay in layers]))[1:]
        self.lag = int(self.shift[-1])
        self.field = 1 + sum(lay.left + lay.right for lay in layers)
        self.keep = max(int(keep or 0), self.field + 1)
        self.recomputed = 0
        self.reset()

    def reset(self) -> None:
        """A new segment: every column before the next frame is zero."""
        self._n = -1                                   # absolute index of the newest frame
        self._feats: List[np.ndarray] = []             # (rows, 72) normalised, oldest first
        self._cols: List[dict] = [dict() for _ in self.layers]   # absolute index -> (rows, C)

    @property
    def frames(self) -> int:
        """Frames pushed in this segment."""
        return self._n + 1

    def push(self, window: np.ndarray) -> Optional[np.ndarray]:
        """Add the newest frame.

        Args:
            window: (rows, T, 72) features of the last T frames of the segment as the window
                pass would compute them now (T >= 1, the newest last; T at least the receptive
                field once the segment is that long, so that changed features are seen).
        Returns:
            (rows, out) float32 E_Q output of frame ``frames - 1 - lag`` (raw, see module
            docstring), or None while the segment is shorter than ``lag + 1`` frames.
        """
        win = np.asarray(window, dtype=np.float32)
        if win.ndim != 3 or win.shape[0] != self.rows or win.shape[2] != len(self.mean):
            raise ValueError(f'window must have shape ({self.rows}, T, {len(self.mean)}), '
                             f'got {win.shape}')
        win = (win - self.mean) / self.std
        self._n += 1
        n = self._n
        t = win.shape[1]
        if t > n + 1:
            raise ValueError(f'window of {t} frames after {n + 1} pushes in this segment')
        first = n                            # the oldest frame whose features are new
        old = self._feats
        # frames of the window seen before that can still reach an output column
        m = min(t - 1, len(old), self.field - 1)
        for k in range(m):
            i = n - m + k                     # absolute frame
            if not np.array_equal(old[len(old) - m + k], win[:, t - 1 - m + k]):
                first = i
                break
        self._feats = (old[len(old) - m:] if m else []) + [win[:, t - 1 - m + k]
                                                           for k in range(m + 1)]
        self._feats = self._feats[-self.keep:]
        if first < n:
            self.recomputed += 1
        base = n - (len(self._feats) - 1)   # absolute index of self._feats[0]
        # frames changed from `first`; layer l's columns from first - (reads to the right)
        lo = first
        out = None
        for li, lay in enumerate(self.layers):
            hi = n - self.shift[li]
            lo = max(lo - lay.right, 0)
            if hi < lo:
                break
            if li == 0:
                src = lambda j: self._feats[j - base] if j >= base else None  # noqa: E731
            else:
                prev = self._cols[li - 1]
                src = prev.get
            cols = self._compute(lay, src, lo, hi)
            store = self._cols[li]
            for j in range(lo, hi + 1):
                store[j] = cols[:, :, j - lo]
            for j in [j for j in store if j < n - 2 * self.keep]:
                del store[j]
            if li == len(self.layers) - 1 and hi == n - self.lag:
                out = cols[:, :, -1]
        return out

    def _compute(self, lay: _Layer, src, lo: int, hi: int) -> np.ndarray:
        """Columns ``lo..hi`` of a layer from its input columns (``src(j)``: (rows, C) or
        None for a column before the segment, which is zero). Returns (rows, C_out, ncol).

        The products run in torch, not NumPy: torch keeps to the node's thread setting
        (``torch.set_num_threads``), while NumPy's BLAS would start threads of its own whose
        spinning costs more CPU than the product."""
        ncol = hi - lo + 1
        c_in = lay.branches[0].weight.shape[1] // (lay.branches[0].j1 - lay.branches[0].j0)
        # input columns stacked tap-major along the last axis: (rows, ncol, taps * C_in);
        # x @ W^T (torch.nn.functional.linear) is several times faster here than W @ x
        x = np.zeros((self.rows, ncol, len(lay.offsets), c_in), dtype=np.float32)
        for k, o in enumerate(lay.offsets):
            for c in range(ncol):
                j = lo + c + o
                col = src(j) if j >= 0 else None
                if col is not None:
                    x[:, c, k] = col
        xt = torch.from_numpy(x.reshape(self.rows * ncol, len(lay.offsets) * c_in))
        y = None
        for br in lay.branches:
            z = torch.nn.functional.linear(xt[:, br.j0 * c_in:br.j1 * c_in], br.weight,
                                           br.bias)
            if lay.slope is not None:
                z = torch.nn.functional.leaky_relu(z, lay.slope)
            y = z if y is None else y + z
        if lay.residual:
            k0 = lay.offsets.index(0)
            y = y + xt[:, k0 * c_in:(k0 + 1) * c_in]
        return y.numpy().reshape(self.rows, ncol, -1).transpose(0, 2, 1)
