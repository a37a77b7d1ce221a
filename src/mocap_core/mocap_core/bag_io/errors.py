"""The one exception of :mod:`mocap_core.bag_io`."""

from __future__ import annotations

__all__ = ['BagError']


class BagError(Exception):
    """A bag cannot be read or written; the message is one line that says what and why."""

    def __init__(self, message: str) -> None:
        super().__init__(' '.join(str(message).split()))
