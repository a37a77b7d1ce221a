"""Inference weights of the lifter networks: writing, reading, the shipped files (no ROS
imports).

File format (``torch.save`` of a dictionary, read back with
:func:`mocap_core.checkpoint.load_checkpoint`, tensors and plain data only):

* MotioNet: ``{'model': state dict, 'config': LifterConfig fields, 'info': {...}}``;
* VTM: the same with ``'arch': 'vtm'`` and VTMConfig fields.

Floating tensors of the state dict are stored as float16 (:func:`half_state`) and loaded back
as float32 (:func:`load_half_state`).
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import Any, Callable, Dict, Optional, Union

import numpy as np
import torch
from torch import nn

from mocap_core.checkpoint import WeightsError, load_checkpoint, shipped_weights

from .model import LifterConfig, MotioNet
from .vtm import VTM, VTMConfig

#: The architectures :func:`load_weights` reads.
MODELS = ('motionet', 'vtm')

Lifter = Union[MotioNet, VTM]


#: Shipped files that are the default of a (model, mode) other than ``<model>_<mode>.pt``.
#: Windowed MotioNet: stage 9 (session 59), stage 8 (``motionet_windowed_rendered_v6.pt``,
#: opt-in since) fine-tuned in the virtual camera with 45 % of its windows from 250 rendered
#: training clips (the real detector's output; ``finetune_vc_rendered.json``). Through the
#: pipeline on the rendered benchmarks (the real detector on people, motions, scenes and
#: cameras never trained on; median over clips) it reaches MPJPE 67.7 / 68.5 mm and
#: PA-MPJPE 38.5 / 45.1 mm on the usual (58 clips) / travel (37) sets, against 69.4 / 69.5
#: and 39.5 / 46.0 for stage 8; ``weights/README.md`` has the comparison and its cost (the
#: world stage's root error on the travel set).
DEFAULT_FILES = {('motionet', 'windowed'): 'motionet_windowed_rendered_v7.pt'}


def default_weights(mode: str, model: str = 'motionet') -> Path:
    """The shipped default weights of ``model`` in ``mode`` (:data:`DEFAULT_FILES`, else
    ``<model>_<mode>.pt``) from the package share directory (or the source tree when the
    package is not installed through ament)."""
    name = DEFAULT_FILES.get((model, mode), f'{model}_{mode}.pt')
    return shipped_weights('mocap_lifter', name, Path(__file__).resolve().parents[1] / 'weights')


def plain_data(value: Any) -> Any:
    """``value`` with NumPy scalars and arrays turned into Python numbers and lists (inside
    dicts, lists and tuples), so that a saved configuration loads with ``weights_only``."""
    if isinstance(value, dict):
        return {k: plain_data(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(plain_data(v) for v in value)
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    return value


def half_state(model: nn.Module) -> Dict[str, torch.Tensor]:
    """The model's state dict with floating tensors as float16."""
    return {k: (v.half() if v.is_floating_point() else v) for k, v in model.state_dict().items()}


def load_half_state(model: nn.Module, state: Dict[str, torch.Tensor]) -> None:
    """Load a :func:`half_state` dict (floating tensors back to float32)."""
    model.load_state_dict({k: (v.float() if v.is_floating_point() else v)
                           for k, v in state.items()})


def save_weights(model: MotioNet, path: Path, info: Optional[Dict[str, Any]] = None) -> None:
    """Write MotioNet inference weights: float16 state dict, network configuration and
    free-form ``info``."""
    torch.save({'model': half_state(model), 'config': plain_data(asdict(model.cfg)),
                'info': plain_data(info or {})}, path)


def save_vtm(model: VTM, path: Path, info: Optional[Dict[str, Any]] = None) -> None:
    """Write VTM inference weights: float16 state dict, configuration, ``arch: 'vtm'``."""
    torch.save({'arch': 'vtm', 'model': half_state(model),
                'config': plain_data(asdict(model.cfg)), 'info': plain_data(info or {})}, path)


def _build(path: Path, state: Dict[str, Any], make: Callable[[Dict[str, Any]], nn.Module],
           device: str) -> nn.Module:
    """The network of ``state`` (``make(config)``) with its weights, in eval mode; a file
    that does not fit the network is a :class:`WeightsError`."""
    if not isinstance(state['config'], dict) or not isinstance(state['model'], dict):
        raise WeightsError(f'{path}: not lifter weights (config and model must be '
                           'dictionaries)')
    try:
        model = make(state['config']).to(device)
        load_half_state(model, state['model'])
    except (TypeError, ValueError, KeyError, RuntimeError, AttributeError) as exc:
        text = ' '.join(str(exc).split())[:160]
        raise WeightsError(f'{path}: weights do not fit the network ({type(exc).__name__}: '
                           f'{text})') from None
    return model.eval()


def load_vtm(path: Path, device: str = 'cpu') -> VTM:
    """Load weights written by :func:`save_vtm` (eval mode). Raises WeightsError for a file
    that is not VTM weights."""
    state = load_checkpoint(path, map_location=device, required=('model', 'config'))
    if state.get('arch') != 'vtm':
        raise WeightsError(f'{path} holds no VTM weights (arch '
                           f'{state.get("arch", "motionet")!r})')
    return _build(Path(path), state, lambda c: VTM(VTMConfig(**c)), device)


def load_weights(path: Path, device: str = 'cpu', causal: Optional[bool] = None) -> Lifter:
    """Load lifter weights: MotioNet ones written by :func:`save_weights` (``causal``
    overrides the mode: the padding changes, the weights are the same) or VTM ones
    (:func:`save_vtm`; windowed only, ``causal=True`` is an error).

    Returns:
        The network in eval mode (:class:`MotioNet` or :class:`VTM`).
    Raises:
        WeightsError (a ValueError, one-line message): a missing, corrupt or crafted file, or
            one that is not lifter weights.
    """
    path = Path(path)
    state = load_checkpoint(path, map_location=device, required=('model', 'config'))
    if state.get('arch') == 'vtm':
        if causal:
            raise WeightsError(f'{path} holds VTM weights, which are windowed only '
                               '(bounded look-ahead): use mode windowed')
        return _build(path, state, lambda c: VTM(VTMConfig(**c)), device)
    if state.get('arch', 'motionet') != 'motionet':
        raise WeightsError(f"{path}: unknown lifter architecture {state.get('arch')!r}")

    def make(config: Dict[str, Any]) -> MotioNet:
        cfg = LifterConfig(**config)
        if causal is not None:
            cfg.causal = causal
        return MotioNet(cfg)

    return _build(path, state, make, device)


def architecture(model: nn.Module) -> str:
    """'vtm' or 'motionet': the architecture of a loaded lifter network."""
    return 'vtm' if isinstance(model, VTM) else 'motionet'
