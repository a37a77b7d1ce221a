"""Loading weight and checkpoint files safely (no ROS imports).

Every ``.pt`` file the project reads goes through :func:`load_checkpoint`: it unpickles with
``torch.load(weights_only=True)``, which accepts tensors, numbers, strings and plain
containers only, so a crafted file cannot run code. Any problem (missing file, truncated or
corrupt archive, a pickle that needs other objects, a file that is not a dictionary) becomes
one :class:`WeightsError` with a one-line message naming the file.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Dict, Iterable, Union


_ANSI = re.compile(r'\x1b\[[0-9;]*m')


class WeightsError(ValueError):
    """A weights or checkpoint file that cannot be used; the message is one line."""


def load_checkpoint(path: Union[str, Path], map_location: Any = 'cpu',
                    required: Iterable[str] = ()) -> Dict[str, Any]:
    """Read a ``torch.save`` dictionary from ``path`` with tensors only (no code execution).

    Args:
        path: the file.
        map_location: device the tensors are loaded to (``torch.load``'s argument).
        required: keys the dictionary must have.

    Returns:
        The saved dictionary.

    Raises:
        WeightsError: the file is missing, unreadable, corrupt, holds something other than
            plain data, is not a dictionary or lacks a required key.
    """
    import pickle
    import warnings

    import torch

    path = Path(path)
    if not path.is_file():
        raise WeightsError(f'weights file not found: {path}')
    try:
        with warnings.catch_warnings():
            # random bytes may look like a pickle of another protocol: torch warns on stderr
            # before it refuses the file; the refusal below is the one line that is said
            warnings.simplefilter('ignore', UserWarning)
            state = torch.load(str(path), map_location=map_location, weights_only=True)
    except Exception as exc:  # noqa: BLE001 - torch raises many types for a damaged file
        text = ' '.join(_ANSI.sub('', str(exc)).split())
        if isinstance(exc, pickle.UnpicklingError) and 'WeightsUnpickler error:' in text:
            # a pickle naming code to run or classes to build, or random bytes: refused by the
            # tensors-only reader before anything in it ran
            detail = text.split('WeightsUnpickler error:')[-1].split('Check the documentation')[0]
            raise WeightsError(f'{path}: not a file of tensors and plain data, refused '
                               f'({detail.strip()[:160]})') from None
        raise WeightsError(f'{path}: not a readable weights file ({type(exc).__name__}: '
                           f'{text[:160]})') from None
    if not isinstance(state, dict):
        raise WeightsError(f'{path}: expected a dictionary of weights, found '
                           f'{type(state).__name__}')
    missing = [k for k in required if k not in state]
    if missing:
        raise WeightsError(f"{path}: not the expected weights (missing {', '.join(missing)})")
    return state


def shipped_weights(package: str, name: str, source_dir: Union[str, Path]) -> Path:
    """A weights file shipped with a package: ``share/<package>/weights/<name>`` when the
    package is installed through ament and has it, else ``<source_dir>/<name>`` (the source
    tree's ``weights`` folder)."""
    try:
        from ament_index_python.packages import get_package_share_directory
        path = Path(get_package_share_directory(package)) / 'weights' / name
        if path.exists():
            return path
    except Exception:  # noqa: BLE001 - not installed through ament: use the source tree
        pass
    return Path(source_dir) / name
