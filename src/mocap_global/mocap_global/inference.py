"""GMR's forward pass in NumPy, for inference on a CPU (no ROS imports).

The live world stage runs the network once per frame over a window of 48 frames, one person
at a time: a batch of one. For such small problems PyTorch's per-operation overhead, not the
arithmetic, is most of the cost (its fused bidirectional GRU spends about 20 us per cell
step on 128 units). :class:`NumpyGMR` computes the same function with the same float32
weights, the recurrence's element-wise work in NumPy:

* both directions of a bidirectional layer advance together: one batched matrix product
  (two 128 x 384 matrices) and a handful of element-wise operations per time step;
* the input-to-hidden products of all time steps are one product per direction and layer,
  before the recurrence, as in PyTorch's kernel.

Every matrix product runs in PyTorch (on NumPy arrays' memory, no copies): PyTorch keeps to
the process's thread setting (``torch.set_num_threads``, the node's ``threads``), while
NumPy's BLAS starts threads of its own, whose spinning after each product would cost a
second core's time for nothing (measured: CPU time twice the wall time).

It copies the weights of a :class:`~mocap_global.model.GMR` (again when they change) and is
exact to float32 rounding (outputs within about 1e-6 of the PyTorch pass: ``test_gmr.py``).
Measured side by side in ``docs/speed.md``. It covers what the online stage needs: whole
windows (no padding), no test-time augmentation, any batch size.

GRU equations (PyTorch's): ``r = s(W_ir x + b_ir + W_hr h + b_hr)``,
``z = s(W_iz x + b_iz + W_hz h + b_hz)``, ``n = tanh(W_in x + b_in + r * (W_hn h + b_hn))``,
``h' = (1 - z) n + z h``.
"""

from __future__ import annotations

import weakref
from typing import Dict, List, Tuple

import numpy as np
import torch
from scipy.special import expit

from mocap_core.rotations import axis_angle_to_matrix

from .features import pose_dims
from .model import GMR


def _tensor(t: torch.Tensor) -> torch.Tensor:
    return t.detach().to('cpu', torch.float32).contiguous().clone()


def _fingerprint(model: GMR) -> tuple:
    """What changes when the model's tensors are replaced or modified in place (their storage
    and PyTorch's version counters): a cheap test for stale copies."""
    return tuple((t.data_ptr(), t._version) for t in
                 list(model.parameters()) + list(model.buffers()))


class NumpyGMR:
    """A :class:`~mocap_global.model.GMR`'s inference in NumPy (module docstring).

    Args:
        model: the network (a plain :class:`GMR`, not an augmented one). Its weights are
            copied; each call first checks that the model's tensors were not replaced or
            changed in place since (``load_state_dict``, ``set_normalisation``, training) and
            copies them again if they were. Only a weak reference to the model is kept.
    """

    def __init__(self, model: GMR) -> None:
        if not isinstance(model, GMR):
            raise TypeError(f'NumpyGMR needs a plain GMR, got {type(model).__name__}')
        self._model = weakref.ref(model)
        self._load(model)

    def _load(self, model: GMR) -> None:
        """Copy the weights (float32, transposed for ``x @ W``)."""
        self.cfg = model.cfg
        self.hidden = model.gru.fwd[0].hidden_size
        #: per layer: the input-to-hidden weights (transposed) and biases of each direction,
        #: the hidden-to-hidden ones stacked (2, H, 3H), their biases (2, 1, 3H) as an array
        self.layers: List[Tuple] = []
        for f, b in zip(model.gru.fwd, model.gru.bwd):
            self.layers.append((
                (_tensor(f.weight_ih_l0.T), _tensor(f.bias_ih_l0)),
                (_tensor(b.weight_ih_l0.T), _tensor(b.bias_ih_l0)),
                torch.stack([_tensor(f.weight_hh_l0.T), _tensor(b.weight_hh_l0.T)]),
                torch.stack([_tensor(f.bias_hh_l0), _tensor(b.bias_hh_l0)])[:, None].numpy()))
        self.projection = (_tensor(model.projection.weight.T), _tensor(model.projection.bias))
        self.regression = (_tensor(model.regression.weight.T), _tensor(model.regression.bias))
        self.feature_mean = _tensor(model.feature_mean).numpy()
        self.feature_std = _tensor(model.feature_std).numpy()
        self.out_mean = _tensor(model.out_mean).double().numpy()
        self.out_std = _tensor(model.out_std).double().numpy()
        self.pose_dims = pose_dims(self.cfg.pose_input)
        self.velocity_scale = np.float32(10.0 if self.cfg.pose_input == 'quat'
                                         else self.cfg.fps)
        self._loaded = _fingerprint(model)

    def _refresh(self) -> None:
        model = self._model()
        if model is not None and _fingerprint(model) != self._loaded:
            self._load(model)

    @staticmethod
    def _linear(x: np.ndarray, weight_bias: Tuple[torch.Tensor, torch.Tensor]) -> np.ndarray:
        """``x @ W^T + b`` over the last axis of ``x`` (float32)."""
        w, b = weight_bias
        flat = torch.from_numpy(np.ascontiguousarray(x).reshape(-1, x.shape[-1]))
        return torch.addmm(b, flat, w).numpy().reshape(x.shape[:-1] + (w.shape[1],))

    def __call__(self, x: np.ndarray) -> Dict[str, np.ndarray]:
        """``x`` (B, T, C) features (float32; every frame valid) -> ``axis_angle`` (B, T, 3),
        ``translation`` (B, T, 3), ``rotation`` (B, T, 3, 3), ``up`` (B, T, 3), float64: what
        :meth:`GMR.forward` returns, as arrays."""
        self._refresh()
        x = np.asarray(x, dtype=np.float32)
        if x.ndim != 3 or x.shape[-1] != len(self.feature_mean):
            raise ValueError(f'expected (B, T, {len(self.feature_mean)}) features, got '
                             f'{x.shape}')
        h = (x - self.feature_mean) / self.feature_std
        if self.cfg.velocity_input:
            q = x[..., :self.pose_dims]
            d = np.zeros_like(q)
            d[:, :-1] = q[:, 1:] - q[:, :-1]
            h = np.concatenate([h, d * self.velocity_scale], axis=-1)
        for layer in self.layers:
            h = self._bidirectional(h, *layer)
        h = np.maximum(self._linear(h, self.projection), 0.0)
        raw = self._linear(h, self.regression).astype(np.float64)
        motion = raw[..., :6] * self.out_std + self.out_mean
        up = raw[..., 6:].copy()
        up[..., 2] += 1.0
        up /= np.maximum(np.linalg.norm(up, axis=-1, keepdims=True), 1e-6)
        aa = motion[..., :3]
        return {'axis_angle': aa, 'translation': motion[..., 3:],
                'rotation': axis_angle_to_matrix(aa), 'up': up}

    def _bidirectional(self, x: np.ndarray, fwd: Tuple, bwd: Tuple, whh: torch.Tensor,
                       bhh: np.ndarray) -> np.ndarray:
        """One bidirectional GRU layer: (B, T, C) -> (B, T, 2H), forward then backward."""
        H = self.hidden
        B, T = x.shape[:2]
        xt = np.ascontiguousarray(x.transpose(1, 0, 2))         # time-major (T, B, C)
        gi = np.empty((2, T, B, 3 * H), np.float32)             # gates r z n
        gi[0] = self._linear(xt, fwd)
        gi[1] = self._linear(xt, bwd)[::-1]                     # its own time order
        out = np.empty((2, T, B, H), np.float32)
        state = np.zeros((2, B, H), np.float32)
        gh = np.empty((2, B, 3 * H), np.float32)
        gh_t = torch.from_numpy(gh)
        H2 = 2 * H
        for t in range(T):
            torch.bmm(torch.from_numpy(state), whh, out=gh_t)  # (2, B, 3H)
            gh += bhh
            g = gi[:, t]
            rz = expit(g[..., :H2] + gh[..., :H2])
            n = np.tanh(g[..., H2:] + rz[..., :H] * gh[..., H2:])
            state = n + rz[..., H:] * (state - n)
            out[:, t] = state
        return np.concatenate([out[0].transpose(1, 0, 2),
                               out[1, ::-1].transpose(1, 0, 2)], axis=-1)
