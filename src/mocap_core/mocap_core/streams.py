"""Ordering of input stamps in a stream (no ROS imports).

Every node receives frames stamped by the camera. Stamps normally increase; when they do not,
two cases are told apart:

* a small step back or a repeated stamp (a duplicate, a late message): the frame is stale and
  dropped;
* a jump back by more than ``restart_after_s`` (a bag played again or looped, a restarted camera
  driver, a clock reset): a new stream starts, and the frame is its first.
"""

from __future__ import annotations

from typing import Literal, Optional

Verdict = Literal['next', 'stale', 'restart']


class StampOrder:
    """Classifies each stamp (nanoseconds) against the last accepted one.

    Args:
        restart_after_s: a stamp this many seconds (or more) before the last accepted one
            starts a new stream; a smaller step back is stale.
    """

    def __init__(self, restart_after_s: float = 1.0) -> None:
        if not restart_after_s > 0:
            raise ValueError(f'restart_after_s must be > 0, got {restart_after_s}')
        self.restart_after_ns = int(round(restart_after_s * 1e9))
        self.last_ns: Optional[int] = None
        self.restarts = 0
        self.stale = 0

    def check(self, stamp_ns: int) -> Verdict:
        """``'next'`` (accepted), ``'stale'`` (drop it) or ``'restart'`` (accepted as the first
        frame of a new stream). Accepted stamps become the last one."""
        stamp_ns = int(stamp_ns)
        if self.last_ns is None or stamp_ns > self.last_ns:
            self.last_ns = stamp_ns
            return 'next'
        if self.last_ns - stamp_ns >= self.restart_after_ns:
            self.last_ns = stamp_ns
            self.restarts += 1
            return 'restart'
        self.stale += 1
        return 'stale'

    def reset(self) -> None:
        """Forget the last stamp (the next one is accepted whatever it is)."""
        self.last_ns = None
