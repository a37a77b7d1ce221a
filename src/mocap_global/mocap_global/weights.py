"""GMR inference weights: where the shipped files are, saving and loading (no ROS imports).

A weights file is a ``torch.save`` dictionary::

    {'model': GMR.state_dict(), 'config': asdict(GMRConfig), 'info': {...free-form...}}

It is read with tensors and plain data only (:func:`mocap_core.checkpoint.load_checkpoint`),
so a crafted file cannot run code; a file that is missing, damaged or not GMR weights raises
one :class:`~mocap_core.checkpoint.WeightsError` with a one-line message.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import Any, Dict, Optional, Union

import torch

from mocap_core.checkpoint import WeightsError, load_checkpoint, shipped_weights

from .model import GMR, GMRConfig

#: The package's weights directory in the source tree (training installs here).
WEIGHTS_DIR = Path(__file__).resolve().parents[1] / 'weights'


def weights_name(fps: float) -> str:
    """Shipped weights file of a model rate: ``gmr.pt`` (30 fps), ``gmr_10fps.pt`` ..."""
    return 'gmr.pt' if round(fps) == 30 else f'gmr_{int(round(fps))}fps.pt'


def default_weights() -> Path:
    """The shipped 30 fps weights, from the package share directory (or the source tree)."""
    return shipped_weights('mocap_global', 'gmr.pt', WEIGHTS_DIR)


def save_weights(model: GMR, path: Union[str, Path], info: Optional[Dict[str, Any]] = None
                 ) -> None:
    """Write inference weights: state dict, configuration and free-form ``info`` (plain data:
    numbers, strings, lists, dictionaries)."""
    torch.save({'model': model.state_dict(), 'config': asdict(model.cfg), 'info': info or {}},
               path)


def read_info(path: Union[str, Path]) -> Dict[str, Any]:
    """The ``info`` dictionary of a weights file (training record); raises WeightsError."""
    info = load_checkpoint(path, 'cpu', required=('info',))['info']
    if not isinstance(info, dict):
        raise WeightsError(f'{path}: info is {type(info).__name__}, not a dictionary')
    return info


def load_weights(path: Union[str, Path], device: str = 'cpu') -> GMR:
    """Load :func:`save_weights` output onto ``device``, in eval mode, with the file's
    ``info`` as ``model.info``.

    Raises:
        WeightsError: the file is missing, corrupt, holds more than plain data, or is not
            GMR weights (unknown configuration fields, mismatched tensor shapes).
    """
    state = load_checkpoint(path, device, required=('model', 'config'))
    try:
        cfg = GMRConfig(**state['config'])
        model = GMR(cfg).to(device)
        model.load_state_dict(state['model'])
    except (TypeError, ValueError, KeyError, RuntimeError, AttributeError) as exc:
        text = ' '.join(str(exc).split())[:160]
        raise WeightsError(f'{path}: not GMR weights ({type(exc).__name__}: {text})') from None
    model.eval()
    info = state.get('info', {})
    model.info = info if isinstance(info, dict) else {}
    return model
