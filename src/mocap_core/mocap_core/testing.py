"""Helpers for the packages' tests (no ROS imports): damaged and crafted weight files.

A crafted file holds a :class:`CreatesFile` object: unpickled with code execution allowed
(``torch.load(weights_only=False)``), it creates its marker file, so a test can assert that
loading never ran it.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Dict, Union

PathLike = Union[str, Path]


class CreatesFile:
    """Pickles as the call ``open(path, 'w')``: the payload of a crafted weights file."""

    def __init__(self, path: PathLike) -> None:
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, 'w'))


def crafted_weights(path: PathLike, marker: PathLike, key: str = 'model',
                    **entries: Any) -> Path:
    """Write a ``torch.save`` dictionary whose ``key`` holds a :class:`CreatesFile` of
    ``marker`` (plus ``entries``); returns ``path``."""
    import torch

    torch.save({key: CreatesFile(marker), **entries}, str(path))
    return Path(path)


def damaged_weights(good: PathLike, directory: PathLike) -> Dict[str, Path]:
    """``{'truncated': the first half of ``good``, 'random': 4096 random bytes}``, written to
    ``directory``."""
    directory = Path(directory)
    data = Path(good).read_bytes()
    truncated = directory / 'truncated.pt'
    truncated.write_bytes(data[:len(data) // 2])
    noise = directory / 'random.pt'
    noise.write_bytes(os.urandom(4096))
    return {'truncated': truncated, 'random': noise}
